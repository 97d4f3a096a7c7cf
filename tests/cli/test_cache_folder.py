"""The cache folder (``--cache-dir``, ``HARNESS_CACHE_DIR``) is checked before anything renders, a killed writer's
private folders in it are swept, ``harness ground-truth`` stops on SIGTERM / SIGINT as ``harness run`` does, and
``HARNESS_ALLOW_OUTSIDE_PATHS`` is read strictly (harness/running/runstate.py ``cache_folder``,
harness/files/entries.py ``sweep_stale``, harness/cli/ground_truth.py, harness/core/options.py ``env_switch``)."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import MINIMAL_SCENE, SCENES
from test_hostile_input import assert_one_line, cli

from harness.core.errors import HarnessError
from harness.files import entries
from harness.scene import load_scene

# `harness ground-truth` with Mitsuba replaced by a renderer that takes PASSES passes of SLEEP seconds each (its
# progress reported after every pass, as Mitsuba's is) and a fixed variant: no Mitsuba import, no probe.
DRIVER = r"""
import os, sys, time
import numpy as np
from harness.renderers import groundtruth
from harness.renderers.base import RenderResult

PASSES, SLEEP = int(os.environ["FAKE_PASSES"]), float(os.environ["FAKE_SLEEP"])

class Slow:
    name = "mitsuba"
    def render(self, scene, request):
        shape = (scene.film.height, scene.film.width, 3)
        for index in range(PASSES):
            time.sleep(SLEEP)
            if request.progress is not None:
                request.progress(index + 1, PASSES)
        return RenderResult(renderer="mitsuba", image=np.ones(shape, np.float32),
                            variance=np.full(shape, 0.01, np.float32), seconds=SLEEP * PASSES, spp=request.spp,
                            rays={}, stats={}, settings={}, info={"variant": "scalar_rgb"})

groundtruth.get_renderer = lambda name: Slow()
groundtruth.choose_variant = lambda variant=None: "scalar_rgb"
from harness.cli import main
sys.exit(main(sys.argv[1:]))
"""


def _ground_truth(cache: Path, *args: str, passes: int = 1, sleep: float = 0.0, **kwargs) -> subprocess.Popen:
    """The driver's ``harness ground-truth`` of the furnace, rendered (not its closed form) into ``cache``."""
    env = {**os.environ, "FAKE_PASSES": str(passes), "FAKE_SLEEP": str(sleep), "HARNESS_CACHE_DIR": str(cache)}
    return subprocess.Popen([sys.executable, "-c", DRIVER, "ground-truth", str(SCENES / "furnace.toml"),
                             "--no-closed-form", "--quiet", *args], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kwargs)


def _private(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(entries.PRIVATE_PREFIXES)) \
        if folder.is_dir() else []


# ---- SIGTERM / SIGINT to ground-truth (item 12) -----------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_stops_ground_truth_with_one_line(tmp_path, signum):
    """Stopped in its second chunk: exit 128 + the signal, one line, the first chunk cached, no private folder."""
    cache = tmp_path / "cache"
    chunks = cache / "groundtruth"
    proc = _ground_truth(cache, "--spp", "3", "--chunk-spp", "1", passes=20, sleep=0.05)
    deadline = time.monotonic() + 60
    while not (chunks.is_dir() and [p for p in chunks.iterdir() if not p.name.startswith(".")]):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    time.sleep(0.3)  # inside the second chunk's render
    proc.send_signal(signum)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + signum, (proc.returncode, err)
    assert err.splitlines() == ["harness: interrupted after 1 of 3 chunks; run again to resume (finished chunks are "
                                "cached)"], err
    assert _private(chunks) == [] and len(list(chunks.iterdir())) == 1


@pytest.mark.slow
def test_stale_private_folders_are_swept_at_the_next_ground_truth(tmp_path):
    """A private folder whose writer is gone (its pid dead on this host, or older than 6 h) is removed by the next
    command that uses the cache; one of a live writer, or of another host and recent, is kept."""
    chunks = tmp_path / "cache" / "groundtruth"
    chunks.mkdir(parents=True)
    gone = subprocess.Popen(["true"])
    gone.wait()
    host = entries.private_name(".tmp-").split("-")[1]
    stale = [f".tmp-{host}-{gone.pid}-{'a' * 32}", f".bad-{host}-{gone.pid}-{'b' * 32}", ".tmp-" + "c" * 32]
    kept = [f".tmp-{host}-{os.getpid()}-{'d' * 32}", f".tmp-elsewhere-{gone.pid}-{'e' * 32}", ".tmp-" + "f" * 32]
    for name in stale + kept:
        (chunks / name / "files").mkdir(parents=True)
        (chunks / name / "files" / "estimate.npz").write_bytes(b"half")
    old = time.time() - 7 * 3600
    os.utime(chunks / stale[2], (old, old))
    proc = _ground_truth(tmp_path / "cache", "--spp", "1")
    _out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert _private(chunks) == sorted(kept)


def test_sweep_keeps_what_is_not_a_private_folder(tmp_path):
    (tmp_path / "0123abcd").mkdir()  # an entry
    (tmp_path / ".tmp-notafolder").write_text("x")
    (tmp_path / ".tmp-link").symlink_to(tmp_path / "0123abcd")
    assert entries.sweep_stale(tmp_path) == [] and entries.sweep_stale(tmp_path / "missing") == []
    assert sorted(p.name for p in tmp_path.iterdir()) == [".tmp-link", ".tmp-notafolder", "0123abcd"]


# ---- a cache folder's path (item 13) ----------------------------------------------------------------------------


@pytest.mark.slow
def test_a_300_byte_cache_dir_is_one_line(tmp_path):
    long = tmp_path / ("c" * 300)
    proc = _ground_truth(long, "--spp", "1")
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 2 and out == "", (out, err)
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("harness: error: HARNESS_CACHE_DIR: expected a folder path"), err
    assert "a name of 300 bytes" in lines[0]


# ---- an unusable cache folder found before the first render (item 14) ------------------------------------------


SUITE = """name = "tiny"
[defaults]
spp = 4
film = {{ width = 8, height = 8 }}
[[cases]]
name = "furnace/reference"
scene = "{scene}"
"""


@pytest.fixture
def suite(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(SUITE.format(scene=SCENES / "furnace.toml"))
    return path


def _unusable(tmp_path: Path, kind: str) -> Path:
    """A cache folder that cannot be used: a file, /dev/null, /proc (no one writes there, root included), a FIFO,
    a dangling link."""
    if kind == "file":
        path = tmp_path / "file"
        path.write_text("x")
    elif kind == "dev-null":
        path = Path(os.devnull)
    elif kind == "proc":
        path = Path("/proc")
    elif kind == "fifo":
        path = tmp_path / "fifo"
        os.mkfifo(path)
    else:
        path = tmp_path / "dangling"
        path.symlink_to(tmp_path / "nowhere" / "cache")
    return path


@pytest.mark.parametrize("kind", ["file", "dev-null", "proc", "fifo", "dangling-link"])
@pytest.mark.parametrize("given", ["--cache-dir", "HARNESS_CACHE_DIR"])
def test_run_refuses_an_unusable_cache_folder_before_rendering(tmp_path, suite, capfd, monkeypatch, kind, given):
    import harness.cli.run as run_command

    rendered = []
    monkeypatch.setattr(run_command, "run_suite", lambda *a, **k: rendered.append(1) or pytest.fail("rendered"))
    cache = _unusable(tmp_path, kind)
    argv = ["run", suite, "--out", tmp_path / "out", "--quiet", "--no-report"]
    if given == "--cache-dir":
        argv += ["--cache-dir", cache]
    else:
        monkeypatch.setenv("HARNESS_CACHE_DIR", str(cache))
    line = assert_one_line(*cli(capfd, *argv))
    assert line.startswith(f"harness: error: {given}: ") and str(cache) in line, line
    assert rendered == [] and not (tmp_path / "out").exists()


@pytest.mark.slow
def test_run_refuses_a_read_only_cache_folder_before_rendering(tmp_path, suite):
    """A read-only mount (root ignores permission bits): the run in a private mount namespace (``unshare``), the
    cache folder bound read-only there."""
    cache = tmp_path / "ro"
    cache.mkdir()
    unshare = shutil.which("unshare")
    try:
        usable = unshare and subprocess.run([unshare, "-rm", "sh", "-c", f"mount --bind {cache} {cache} && mount -o "
                                             f"remount,bind,ro {cache} {cache}"], capture_output=True,
                                            timeout=30).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        usable = False
    if not usable:
        pytest.skip("no unshare -rm with bind mounts here: no read-only folder for root")
    command = (f"mount --bind {cache} {cache} && mount -o remount,bind,ro {cache} {cache} && exec {sys.executable} "
               f"-m harness run {suite} --out {tmp_path / 'out'} --quiet --no-report --cache-dir {cache}")
    start = time.monotonic()
    done = subprocess.run([unshare, "-rm", "sh", "-c", command], capture_output=True, text=True, timeout=300)
    lines = done.stderr.splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith(f"harness: error: --cache-dir: cannot write in the folder {str(cache)!r}"), lines[0]
    assert "Read-only file system" in lines[0] and not (tmp_path / "out").exists()
    assert time.monotonic() - start < 60


def test_an_empty_cache_dir_option_is_refused(tmp_path, suite, capfd):
    line = assert_one_line(*cli(capfd, "run", suite, "--out", tmp_path / "out", "--cache-dir", "", "--no-report"))
    assert line == "harness: error: --cache-dir: expected a folder path, got an empty string"


# ---- HARNESS_ALLOW_OUTSIDE_PATHS read by one rule (nit) --------------------------------------------------------


# conftest's minimal scene with a glowing triangle from a mesh file outside the scene's folder
OUTSIDE_SCENE = MINIMAL_SCENE + """
[[shapes]]
type = "mesh"
file = "../outside/tri.obj"
material = "white"
emission = [1, 1, 1]
"""


@pytest.fixture
def outside_scene(tmp_path) -> Path:
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "scene").mkdir()
    path = tmp_path / "scene" / "s.toml"
    path.write_text(OUTSIDE_SCENE)
    return path


@pytest.mark.parametrize("value, allowed", [("1", True), ("on", True), ("YES", True), (" true ", True),
                                            ("0", False), ("off", False), ("no", False), ("false", False),
                                            ("", False)])
def test_allow_outside_paths_takes_the_on_off_words(outside_scene, monkeypatch, value, allowed):
    monkeypatch.setenv("HARNESS_ALLOW_OUTSIDE_PATHS", value)
    if allowed:
        assert load_scene(outside_scene).shapes[0].file is not None
    else:
        with pytest.raises(HarnessError, match="outside"):
            load_scene(outside_scene)


@pytest.mark.parametrize("value", ["2", "maybe", "y", "enabled"])
def test_allow_outside_paths_refuses_another_value_in_one_line(outside_scene, tmp_path, monkeypatch, capfd, value):
    monkeypatch.setenv("HARNESS_ALLOW_OUTSIDE_PATHS", value)
    line = assert_one_line(*cli(capfd, "export", outside_scene, "--format", "obj", "--out", tmp_path / "x"))
    expected = "harness: error: HARNESS_ALLOW_OUTSIDE_PATHS: expected one of 1, on, yes, true (on) or "
    assert line.startswith(expected), line
    assert repr(value) in line and not (tmp_path / "x").exists()


def test_host_name_in_private_names_has_no_dash():
    name = entries.private_name(".tmp-")
    host, pid, rest = name[len(".tmp-"):].split("-")
    assert pid == str(os.getpid()) and len(rest) == 32 and host and "-" not in host
    assert socket.gethostname()  # the machine has a name to put there
