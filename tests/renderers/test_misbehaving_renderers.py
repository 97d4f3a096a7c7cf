"""External renderers that misbehave on purpose (harness/renderers/external.py, harness/renderers/processes.py):
endless output, terminal controls in their errors, children left behind, a harness killed under them, and renderer
files that must be refused before anything runs."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import pytest

from fake_exr import copy_beside
from harness.cli import main
from harness.core.errors import HarnessError
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.external import ExternalRendererError, load_spec
from harness.renderers.processes import WATCHDOG_OF_THIS_PROCESS
from harness.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
FURNACE = ROOT / "scenes" / "furnace.toml"

# One fake renderer, its misbehaviour chosen by --mode; it imports neither numpy nor the harness (tests/fake_exr.py).
# It reports its render time (<out>.json), so a render is its runs alone, with no start-up probes.
FAKE = r'''
import os, subprocess, sys, time
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
mode, out, w, h = args["--mode"], args["--out"], int(args["--width"]), int(args["--height"])
if mode == "flood":  # --mb MB to stdout and to stderr, then one last line and a failure
    block = b"x" * (1 << 20)
    for _ in range(int(args["--mb"])):
        sys.stdout.buffer.write(block)
        sys.stderr.buffer.write(block)
    sys.stderr.buffer.write(b"\nfatal: the last line\n")
    sys.exit(4)
if mode == "escapes":  # clear the screen, set the title, ring the bell, reverse the text after it
    sys.stderr.buffer.write("\x1b[2J\x1b]0;owned\x07 evil \u202etxt.exe \u2066x\u2069\u200f\r\n".encode())
    sys.exit(2)
from fake_exr import constant_image, write_exr
if mode in ("orphan", "hang"):  # a child that outlives this process, in its group; pids in --pidfile
    child = subprocess.Popen(["sleep", "60"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    open(args["--pidfile"] + ".tmp", "w").write(f"{os.getpid()} {child.pid}")
    os.replace(args["--pidfile"] + ".tmp", args["--pidfile"])
    if mode == "hang":
        time.sleep(60)
value = float("nan") if mode == "nan" else 0.5
write_exr(out, constant_image(value, w, h), constant_image(0.01, w, h))
open(out + ".json", "w").write('{"render_seconds": 0.001}')
'''


def _renderer_file(folder: Path, mode: str, *extra: str, timeout: float = 60) -> Path:
    script = folder / "misbehaving.py"
    script.write_text(FAKE)
    copy_beside(script)
    command = ["{python}", str(script), "--mode", mode, "--out", "{out}", "--width", "{width}", "--height",
               "{height}", *extra]
    path = folder / f"{mode}.toml"
    path.write_text(f"command = {json.dumps(command)}\ntimeout = {timeout}\n")
    return path


@pytest.fixture()
def small_scene():
    import dataclasses

    from reference_impl import Film

    return dataclasses.replace(load_scene(FURNACE), film=Film(4, 3, "box"))


def _gone(pid: int) -> bool:
    """True once ``pid`` no longer runs (a zombie waiting for its reaper counts as gone)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except (OSError, IndexError):
        return True


def _wait_gone(pids, seconds: float) -> list[int]:
    """The pids of ``pids`` still running after ``seconds``."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and not all(_gone(p) for p in pids):
        time.sleep(0.02)
    return [p for p in pids if not _gone(p)]


def _kill_quietly(pids) -> None:
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


# ---- item 11: output is never held whole --------------------------------------------------------------------------


@pytest.mark.slow
def test_a_flood_of_output_is_not_held_in_memory(tmp_path, small_scene):
    """32 MB on stdout and 32 MB on stderr: stdout is discarded and only the end of stderr kept, so the harness's
    Python allocations peak far below the output (on 9c53ef3, communicate() held all of both: ~100 MB)."""
    renderer = get_renderer(str(_renderer_file(tmp_path, "flood", "--mb", "32")))
    tracemalloc.start()
    try:
        with pytest.raises(ExternalRendererError) as info:
            renderer.render(small_scene, RenderRequest(spp=1))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 4 << 20, f"peak of {peak / 2**20:.1f} MiB while reading the renderer's output"
    message = str(info.value)
    assert "exited with code 4" in message and message.endswith("fatal: the last line") and len(message) < 500


# ---- item 16: a renderer's text reaches the terminal escaped ----------------------------------------------------


@pytest.mark.slow
def test_terminal_controls_in_stderr_are_escaped(tmp_path, capsys):
    """The error line `harness render` prints quotes the renderer's stderr with ESC, BEL, CR and the bidirectional
    overrides, isolates and marks written as escapes: nothing that clears the screen, sets the title or reverses
    the text after it."""
    code = main(["render", str(FURNACE), "--renderer", str(_renderer_file(tmp_path, "escapes")), "--spp", "1",
                 "--film", "4x3", "--out", str(tmp_path / "x.exr"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1, err
    for raw in ("\x1b", "\x07", "\r", "\u202e", "\u2066", "\u2069", "\u200f"):
        assert raw not in err, f"{raw!r} reached the terminal: {err!r}"
    assert r"\x1b[2J\x1b]0;owned\x07 evil \u202etxt.exe \u2066x\u2069\u200f" in err


def test_external_renderer_errors_escape_what_they_quote():
    err = ExternalRendererError("renderer 'r' exited with code 1: \x1b[31mred\x9b\u202e\u2028done")
    assert str(err) == r"renderer 'r' exited with code 1: \x1b[31mred\x9b\u202e\u2028done"
    assert str(ExternalRendererError(str(err))) == str(err)  # escaping twice changes nothing (a pickled error)


# ---- item 17: no process of a renderer outlives its run, nor the harness ---------------------------------------


@pytest.mark.slow
def test_a_child_left_behind_is_killed_after_the_run(tmp_path, small_scene):
    """The renderer succeeds but leaves a `sleep 60` behind in its group: after the render the group is gone."""
    pidfile = tmp_path / "pids"
    renderer = get_renderer(str(_renderer_file(tmp_path, "orphan", "--pidfile", str(pidfile))))
    result = renderer.render(small_scene, RenderRequest(spp=2))
    assert result.image.shape == (3, 4, 3)
    pids = [int(p) for p in pidfile.read_text().split()]
    left = _wait_gone(pids, 2.0)
    _kill_quietly(left)
    assert not left, f"processes {left} of the renderer outlived its run"


HARNESS = r'''
import sys
from harness.renderers import RenderRequest, get_renderer
from harness.scene import load_scene
import dataclasses
from reference_impl import Film
scene = load_scene(sys.argv[1])
scene = dataclasses.replace(scene, film=Film(4, 3, "box"))
get_renderer(sys.argv[2]).render(scene, RenderRequest(spp=2))
'''


@pytest.mark.slow
def test_a_harness_killed_outright_takes_its_renderer_and_its_children_along(tmp_path):
    """A harness process renders with a renderer that hangs with a child; SIGKILL the harness (no code of it runs):
    the renderer and its child die within two seconds (the watchdog sees the harness's pipe close)."""
    pidfile = tmp_path / "pids"
    renderer = _renderer_file(tmp_path, "hang", "--pidfile", str(pidfile))
    assert_killing_the_harness_kills(renderer, pidfile)


def assert_killing_the_harness_kills(renderer: Path, pidfile: Path) -> None:
    """Render the furnace in a harness process with ``renderer`` (which writes its pid and its child's to
    ``pidfile``, then hangs), SIGKILL the harness once both run: both are gone within two seconds."""
    harness = subprocess.Popen([sys.executable, "-c", HARNESS, str(FURNACE), str(renderer)],
                               env=dict(os.environ, PYTHONPATH=str(ROOT)), stdout=subprocess.DEVNULL)
    pids: list[int] = []
    try:
        deadline = time.monotonic() + 60
        while not pidfile.exists() and harness.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert pidfile.exists(), f"the renderer never started (harness exit {harness.poll()})"
        pids = [int(p) for p in pidfile.read_text().split()]
        assert len(pids) == 2 and not any(_gone(p) for p in pids)  # both run while the harness does
        harness.kill()
        harness.wait()
        left = _wait_gone(pids, 2.0)
        assert not left, f"processes {left} of the renderer outlived the harness killed by SIGKILL"
    finally:
        harness.kill()
        harness.wait()
        _kill_quietly(pids)


@pytest.mark.slow
def test_a_watchdog_that_died_is_started_again(tmp_path, small_scene):
    """Someone kills the harness's watchdog: the next run starts another (and still kills what it leaves)."""
    renderer = get_renderer(str(_renderer_file(tmp_path, "orphan", "--pidfile", str(tmp_path / "pids"))))
    renderer.render(small_scene, RenderRequest(spp=2))
    first = WATCHDOG_OF_THIS_PROCESS.pid()
    assert first is not None and not _gone(first)
    os.kill(first, signal.SIGKILL)
    assert not _wait_gone([first], 2.0)
    renderer.render(small_scene, RenderRequest(spp=2))
    second = WATCHDOG_OF_THIS_PROCESS.pid()
    assert second not in (None, first) and not _gone(second)
    assert not _wait_gone([int(p) for p in (tmp_path / "pids").read_text().split()], 2.0)


# ---- item 20 and the nits: renderer files refused on load, a NaN render refused ----------------------------------


def _cli(capsys, tmp_path, renderer: Path) -> tuple[int, str]:
    """`harness render` of the furnace at 4x3 with ``renderer``: its exit code and what it printed on stderr."""
    code = main(["render", str(FURNACE), "--renderer", str(renderer), "--spp", "1", "--film", "4x3",
                 "--out", str(tmp_path / "x.exr"), "--quiet"])
    return code, capsys.readouterr().err


def test_a_nul_in_the_command_is_refused_on_load(tmp_path, capsys):
    path = tmp_path / "nul.toml"
    path.write_text('command = ["{python}", "a\\u0000b", "{out}"]\n')
    code, err = _cli(capsys, tmp_path, path)
    assert code == 2 and err.count("\n") == 1, err
    assert f"{path}: command: argument 1 holds a NUL character" in err and not (tmp_path / "x.exr").exists()


def test_an_unknown_placeholder_error_quotes_a_long_argument_short(tmp_path):
    path = tmp_path / "long.toml"
    path.write_text(f'command = ["r", "{{out}}", "{"y" * 10_000}{{nope}}"]\n')
    with pytest.raises(HarnessError, match="unknown placeholder") as info:
        load_spec(path)
    assert len(str(info.value)) < len(str(path)) + 400, len(str(info.value))


@pytest.mark.parametrize("timeout", ["5e-324", "0.5", "0"])
def test_a_timeout_below_one_second_is_refused(tmp_path, timeout):
    path = tmp_path / "quick.toml"
    path.write_text(f'command = ["r", "{{out}}"]\ntimeout = {timeout}\n')
    with pytest.raises(HarnessError, match="expected a number of seconds of at least 1 ") as info:
        load_spec(path)
    assert info.value.where == f"{path}: timeout"


@pytest.mark.slow
def test_harness_render_fails_a_render_that_is_nan_everywhere(tmp_path, capsys):
    code, err = _cli(capsys, tmp_path, _renderer_file(tmp_path, "nan"))
    assert code == 1 and err.count("\n") == 1, err
    assert "render failed" in err and "NaN or infinite at every one of its 12 pixels" in err
    assert not (tmp_path / "x.exr").exists()
