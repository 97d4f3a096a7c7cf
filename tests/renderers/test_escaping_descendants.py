"""Descendants of an external renderer that leave its process group (a child started in a session of its own, a
daemon's double fork) are killed after its run too, and when the harness is killed outright
(harness/renderers/processes.py: the supervisor, a child subreaper)."""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

import pytest

from fake_exr import copy_beside
from harness.cli import main
from harness.renderers import RenderRequest, get_renderer, processes
from harness.renderers.external import ExternalRendererError
from harness.renderers.processes import CommandStartError, CommandTimeout, run_group
from test_misbehaving_renderers import FURNACE, _kill_quietly, _wait_gone, assert_killing_the_harness_kills, small_scene

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the supervisor runs on Linux only")
assert small_scene  # a fixture, used by name

# A fake renderer that leaves a process behind out of its group (--escape), then writes its EXR, fails or hangs
# (--then). The pids that must not outlive the run go to --pidfile: its own, and the escaped process's, written by
# the escaped process itself once it runs (so that the renderer goes on only after it has left the group).
ESCAPER = r'''
import os, subprocess, sys, time
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
out, pidfile, then, me = args["--out"], args["--pidfile"], args["--then"], str(os.getpid())
SLEEPER = ("import os, sys, time; open(sys.argv[1] + '.tmp', 'w').write(sys.argv[2] + ' ' + str(os.getpid()));"
           "os.replace(sys.argv[1] + '.tmp', sys.argv[1]); time.sleep(30)")
if args["--escape"] == "setsid":  # a child in a session of its own
    subprocess.Popen([sys.executable, "-c", SLEEPER, pidfile, me], start_new_session=True,
                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
elif os.fork() == 0:  # a daemon: fork, setsid, fork, the middle one exits
    os.setsid()
    if os.fork() == 0:
        os.execv(sys.executable, [sys.executable, "-c", SLEEPER, pidfile, me])
    os._exit(0)
while not os.path.exists(pidfile):
    time.sleep(0.005)
if then == "hang":
    time.sleep(60)
if then == "fail":
    sys.stderr.write("fatal: gave up\n")
    sys.exit(5)
from fake_exr import constant_image, write_exr
w, h = int(args["--width"]), int(args["--height"])
write_exr(out, constant_image(0.5, w, h), constant_image(0.01, w, h))
open(out + ".json", "w").write('{"render_seconds": 0.001}')
'''


def _escaper(folder: Path, escape: str, then: str, timeout: float = 60) -> tuple[Path, Path]:
    """A renderer file for ESCAPER and the file where its pids will be."""
    script = folder / "escaper.py"
    script.write_text(ESCAPER)
    copy_beside(script)
    pidfile = folder / f"pids-{escape}-{then}"
    command = ["{python}", str(script), "--escape", escape, "--then", then, "--pidfile", str(pidfile),
               "--out", "{out}", "--width", "{width}", "--height", "{height}"]
    path = folder / f"{escape}-{then}.toml"
    path.write_text(f"command = {json.dumps(command)}\ntimeout = {timeout}\nrepeats = 2\n")
    return path, pidfile


def _escaper_argv(folder: Path, escape: str, then: str) -> tuple[list[str], Path]:
    """ESCAPER's command line, for :func:`run_group` itself, and the file where its pids will be."""
    path, pidfile = _escaper(folder, escape, then)
    values = {"{python}": sys.executable, "{out}": str(folder / "x.exr"), "{width}": "4", "{height}": "3"}
    return [values.get(arg, arg) for arg in json.loads(path.read_text().split("\n")[0].split("=", 1)[1])], pidfile


def _assert_gone(pidfile: Path) -> None:
    """Every pid in ``pidfile`` is gone within a second (each one left is killed, then reported)."""
    assert pidfile.exists(), "the renderer never wrote its pids"
    pids = [int(p) for p in pidfile.read_text().split()]
    assert len(pids) == 2 and min(pids) > 1, pids
    left = _wait_gone(pids, 1.0)
    _kill_quietly(left)
    assert not left, f"processes {left} of the renderer outlived its run"


@pytest.mark.slow
@pytest.mark.parametrize("escape", ["setsid", "daemon"])
def test_a_descendant_out_of_the_group_is_killed_after_a_run_that_succeeds(tmp_path, small_scene, escape):
    """A child in a session of its own, and a double-forked daemon (re-parented to init where no subreaper
    catches it), are gone once the render returns."""
    path, pidfile = _escaper(tmp_path, escape, "ok")
    result = get_renderer(str(path)).render(small_scene, RenderRequest(spp=2))
    assert result.image.shape == (3, 4, 3)
    _assert_gone(pidfile)


@pytest.mark.slow
def test_a_descendant_out_of_the_group_is_killed_after_a_run_that_fails(tmp_path, small_scene):
    """The renderer fails (exit 5): the error says so, with its stderr, as before; its escaped child is gone."""
    path, pidfile = _escaper(tmp_path, "setsid", "fail")
    with pytest.raises(ExternalRendererError, match=r"exited with code 5: fatal: gave up$"):
        get_renderer(str(path)).render(small_scene, RenderRequest(spp=2))
    _assert_gone(pidfile)


@pytest.mark.slow
def test_a_descendant_out_of_the_group_is_killed_after_a_timeout(tmp_path):
    """The renderer hangs past its timeout: CommandTimeout, and it and its escaped child are gone."""
    argv, pidfile = _escaper_argv(tmp_path, "setsid", "hang")
    start = time.monotonic()
    with pytest.raises(CommandTimeout):
        run_group(argv, tmp_path, 1.5)
    assert time.monotonic() - start < 4
    _assert_gone(pidfile)


@pytest.mark.slow
def test_a_harness_killed_outright_takes_the_escaped_descendants_along(tmp_path):
    """A harness process renders with a renderer that hangs after its child left the group; SIGKILL the harness:
    the renderer and that child die within two seconds (the supervisor sees its control pipe end)."""
    path, pidfile = _escaper(tmp_path, "setsid", "hang")
    assert_killing_the_harness_kills(path, pidfile)


@pytest.mark.slow
def test_a_supervisor_killed_outright_still_has_the_command_killed(tmp_path):
    """Someone kills the supervisor mid-run (SIGKILL): the run ends with its status (-9) and the command's group
    is killed by the harness itself."""
    argv, pidfile = _escaper_argv(tmp_path, "setsid", "hang")
    outcome: list = []
    thread = threading.Thread(target=lambda: outcome.append(run_group(argv, tmp_path, 30)))
    thread.start()
    pids: list[int] = []
    try:
        deadline = time.monotonic() + 30
        while not pidfile.exists() and time.monotonic() < deadline:
            time.sleep(0.02)
        pids = [int(p) for p in pidfile.read_text().split()]
        supervisor = int(Path(f"/proc/{pids[0]}/stat").read_text().rsplit(")", 1)[1].split()[1])
        assert supervisor != os.getpid(), "the command runs without a supervisor"
        os.kill(supervisor, signal.SIGKILL)
        thread.join(10)
        assert outcome and outcome[0][0] == -signal.SIGKILL, outcome
        assert not _wait_gone(pids[:1], 1.0), "the command outlived its killed supervisor"
    finally:
        thread.join(10)
        _kill_quietly(pids)  # the escaped child: init's once its supervisor is gone


@pytest.mark.slow
def test_the_command_s_exit_status_and_stderr_come_through(tmp_path):
    """The supervisor reports the command's status as subprocess does: a code, or -N for a signal N; stderr as the
    command wrote it."""
    code = "import os, signal, sys; sys.stderr.write('last words\\n'); os.kill(os.getpid(), signal.SIGTERM)"
    status, seconds, stderr = run_group([sys.executable, "-c", code], tmp_path, 30)
    assert (status, stderr) == (-signal.SIGTERM, b"last words\n") and 0 < seconds < 10
    assert run_group([sys.executable, "-c", "raise SystemExit(7)"], tmp_path, 30)[0] == 7


@pytest.mark.slow
@pytest.mark.parametrize("command, reason", [("/nonexistent/renderer", "No such file or directory"),
                                             ("no-such-renderer-on-the-path", "No such file or directory"),
                                             ("/", "Permission denied")])
def test_a_command_that_cannot_start_is_still_one_line(tmp_path, capsys, command, reason):
    """A command that cannot be executed: `harness render` prints the OS's reason on one line, exit 1, as when the
    harness ran it directly."""
    path = tmp_path / "missing.toml"
    path.write_text(f'command = ["{command}", "{{out}}"]\n')
    code = main(["render", str(FURNACE), "--renderer", str(path), "--spp", "1", "--film", "4x3",
                 "--out", str(tmp_path / "x.exr"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1, err
    assert f"could not start {command!r}: {reason}" in err, err
    with pytest.raises(CommandStartError, match=reason):
        run_group([command], tmp_path, 30)


@pytest.mark.slow
def test_without_the_supervisor_the_command_s_group_is_still_killed(tmp_path, monkeypatch):
    """Where the supervisor cannot run, the command runs in a session of its own whose group is killed after the
    run: its status, stderr and start errors as under the supervisor."""
    monkeypatch.setattr(processes, "supervised", lambda: False)
    status, _, stderr = run_group(["sh", "-c", "sleep 30 & echo $! >&2; exit 3"], tmp_path, 30)
    assert status == 3
    left = _wait_gone([int(stderr)], 1.0)
    _kill_quietly(left)
    assert not left, "the command's child in its group outlived the run"
    with pytest.raises(CommandStartError, match="No such file or directory"):
        run_group(["/nonexistent/renderer"], tmp_path, 30)
