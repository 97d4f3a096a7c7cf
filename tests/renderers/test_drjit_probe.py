"""A user's ``DRJIT_LIBLLVM_PATH`` is tried in a child process before the harness imports Mitsuba: a library that
aborts Dr.Jit (libLLVM 15), one it cannot load (libLLVM 14, libc, a text file) or no file at all ends the command
with exit code 2 and one line on stderr naming the variable, its value and what was expected; nothing of Dr.Jit's or
LLVM's output reaches the terminal. The answer is cached per file, so it costs one child process, not one a
command (harness/renderers/mitsuba.py, ``check_user_libllvm``)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import SCENES

import harness.renderers.mitsuba as mts
from harness.core.errors import HarnessError

pytestmark = pytest.mark.slow  # starts processes that import Mitsuba

LIBS = Path("/usr/lib/x86_64-linux-gnu")
LIBC = next(iter(sorted(LIBS.glob("libc.so.6"))), None)
BAD = {
    "libllvm-15": LIBS / "libLLVM-15.so",  # Dr.Jit's LLVM backend aborts the process (SIGABRT) on it
    "libllvm-14": LIBS / "libLLVM-14.so",  # too old: Dr.Jit cannot load it
    "libc": LIBC,
    "etc-passwd": Path("/etc/passwd"),
    "missing": None,
}


def _ground_truth(tmp_path: Path, libllvm: str) -> subprocess.CompletedProcess:
    """``harness ground-truth`` of the furnace rendered by Mitsuba (2 spp) with ``DRJIT_LIBLLVM_PATH=libllvm``, a
    fresh probe cache (so the child really runs) and a fresh ground-truth cache."""
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": libllvm, "XDG_CACHE_HOME": str(tmp_path / "xdg"),
           "HARNESS_CACHE_DIR": str(tmp_path / "cache")}
    return subprocess.run([sys.executable, "-m", "harness", "ground-truth", str(SCENES / "furnace.toml"), "--spp",
                           "2", "--no-closed-form", "--out", str(tmp_path / "gt.exr"), "--quiet"],
                          env=env, capture_output=True, text=True, timeout=300, check=False)


@pytest.mark.parametrize("name", sorted(BAD))
def test_a_bad_libllvm_is_one_line_and_exit_2(tmp_path, name):
    path = BAD[name]
    if name == "missing":
        path = tmp_path / "libLLVM-19.so"
    elif path is None or not path.is_file():
        pytest.skip(f"{name}: not on this machine")
    done = _ground_truth(tmp_path, str(path))
    lines = done.stderr.splitlines()
    assert done.returncode == 2, (done.returncode, done.stderr[-3000:])
    assert len(lines) == 1, done.stderr[-3000:]
    assert lines[0].startswith(f"harness: error: DRJIT_LIBLLVM_PATH: {str(path)!r}") or \
        lines[0].startswith(f"harness: error: DRJIT_LIBLLVM_PATH: no file {str(path)!r}"), lines[0]
    assert "expected the path of a libLLVM >= 16" in lines[0]
    assert not (tmp_path / "gt.exr").exists() and not (tmp_path / "cache" / "groundtruth").exists()


def test_the_good_libllvm_still_renders(tmp_path):
    good = next((str(p) for p in sorted(LIBS.glob("libLLVM-*.so"))
                 if (mts.libllvm_version(str(p)) or 0) >= mts.MIN_LLVM_VERSION), None)
    if good is None:
        pytest.skip("no libLLVM >= 16 on this machine")
    done = _ground_truth(tmp_path, good)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "gt.exr").is_file()


def test_run_refuses_a_bad_libllvm_before_writing_anything(tmp_path):
    """``harness run`` checks the variable before its output folder is made (it left ``cases/`` behind)."""
    lib = BAD["libllvm-15"]
    if not lib.is_file():
        pytest.skip("no libLLVM 15 on this machine")
    suite = tmp_path / "tiny.toml"
    suite.write_text(f'name = "tiny"\n[[cases]]\nname = "f"\nscene = "{SCENES / "furnace.toml"}"\nrenderer = '
                     '"mitsuba"\nspp = 2\nagainst = "closed-form"\nfilm = { width = 8, height = 8 }\n')
    env = {**os.environ, "DRJIT_LIBLLVM_PATH": str(lib), "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    done = subprocess.run([sys.executable, "-m", "harness", "run", str(suite), "--out", str(tmp_path / "out"),
                           "--quiet", "--no-report"], env=env, capture_output=True, text=True, timeout=300)
    lines = done.stderr.splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr[-3000:]
    assert lines[0].startswith(f"harness: error: DRJIT_LIBLLVM_PATH: {str(lib)!r}"), lines[0]
    assert not (tmp_path / "out").exists()


def test_the_probe_runs_once_per_file(tmp_path, monkeypatch):
    """A second check of the same file (another command: a fresh process) reads the cached answer."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(mts, "_USER_LIBLLVM_OK", set())
    calls = []
    monkeypatch.setattr(mts, "probe_variant", lambda variant, lib=None, **_: calls.append(lib) or False)
    lib = tmp_path / "libLLVM-15.so"
    lib.write_bytes(b"\x7fELF not really")
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", str(lib))
    for _ in range(2):
        with pytest.raises(HarnessError) as err:
            mts.check_user_libllvm()
        assert err.value.where == "DRJIT_LIBLLVM_PATH" and "its name says LLVM 15" in err.value.message
    assert calls == [str(lib)]
    os.utime(lib, ns=(1, 1))  # another file at the same path (mtime changed): probed again
    with pytest.raises(HarnessError):
        mts.check_user_libllvm()
    assert calls == [str(lib), str(lib)]


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


# a probe that writes its pid beside the libLLVM it was given (as an argument, or in the variable) and never answers
HANGING_PROBE = ("import os, sys, time\nlib = sys.argv[2] if len(sys.argv) > 2 else os.environ['DRJIT_LIBLLVM_PATH']\n"
                 "open(lib + '.pid', 'w').write(str(os.getpid()))\ntime.sleep(600)\n")


def test_a_probe_that_hangs_is_false_at_its_timeout_and_killed(tmp_path, monkeypatch):
    """A probe that never answers is a failed probe once its timeout passes, and nothing of it is left running."""
    monkeypatch.setattr(mts, "_PROBE_SCRIPT", HANGING_PROBE)
    lib = str(tmp_path / "libLLVM-99.so")
    start = time.perf_counter()
    assert mts.probe_variant("llvm_ad_rgb", lib, timeout=2.0) is False
    assert time.perf_counter() - start < 30
    pid = int(Path(lib + ".pid").read_text())
    assert not _alive(pid)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_killed_harness_leaves_no_probe_behind(tmp_path):
    """A harness killed outright (SIGKILL: a test's timeout, the OOM killer) while its probe runs takes the probe
    with it, rather than leaving it to init (docs/mitsuba.md)."""
    lib = str(tmp_path / "libLLVM-99.so")
    parent = subprocess.Popen([sys.executable, "-c", "import sys\nimport harness.renderers.mitsuba as m\n"
                               f"m._PROBE_SCRIPT = {HANGING_PROBE!r}\nm.probe_variant('llvm_ad_rgb', sys.argv[1])\n",
                               lib])
    try:
        deadline = time.monotonic() + 60
        while not Path(lib + ".pid").exists() or not Path(lib + ".pid").read_text():
            assert time.monotonic() < deadline and parent.poll() is None, "the probe did not start"
            time.sleep(0.05)
        pid = int(Path(lib + ".pid").read_text())
        assert _alive(pid)
    finally:
        parent.kill()
        parent.wait()
    deadline = time.monotonic() + 30
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    alive = _alive(pid)
    if alive:
        os.kill(pid, 9)
    assert not alive, "the probe outlived the harness that started it"
