"""Nothing lost: an interrupted ``harness run`` keeps its finished cases and a valid cache, and a second run
resumes, rendering only what is missing; a changed case is run again."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from harness.cli import main
from harness.running import runstate
from harness.running.executors import SerialExecutor
from harness.renderers.groundtruth import Cache
from harness.running.cases import load_suite
from harness.running.schedule import run_suite

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

SCENES = Path(__file__).resolve().parents[2] / "scenes"
HARNESS = Path(sys.executable).parent / "harness"

SUITE = """name = "resume"
[defaults]
spp = 192
ground_truth_spp = 32
film = { width = 32, height = 32 }

[[cases]]
name = "furnace"
scene = "SCENES/furnace.toml"
spp = 4
film = { width = 8, height = 8 }

[[cases]]
name = "cornell-box"
scene = "SCENES/cornell-box.toml"

[[cases]]
name = "soft-shadows"
scene = "SCENES/soft-shadows.toml"

[[cases]]
name = "multi-light"
scene = "SCENES/multi-light.toml"
"""


@pytest.fixture(scope="module", autouse=True)
def _own_ground_truth_cache(tmp_path_factory):
    """A ground-truth cache of this module's own: :func:`_cache_is_intact` looks at every entry of the cache, and the
    run's cache is shared with the other xdist workers (tests/conftest.py), whose writes in flight it would see."""
    previous = os.environ["HARNESS_CACHE_DIR"]
    os.environ["HARNESS_CACHE_DIR"] = str(tmp_path_factory.mktemp("resume-cache"))
    yield
    os.environ["HARNESS_CACHE_DIR"] = previous


def _write_suite(tmp_path: Path, text: str = SUITE) -> Path:
    path = tmp_path / "resume.toml"
    path.write_text(text.replace("SCENES", str(SCENES)))
    return path


def _interrupt(path: Path, out: Path, signum: int, executor: str) -> tuple[subprocess.CompletedProcess, dict]:
    """Start ``harness run``, send ``signum`` as soon as results.json holds a finished case."""
    proc = subprocess.Popen([str(HARNESS), "run", str(path), "--out", str(out), "--no-report", "--executor", executor],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 90
    while not (out / "results.json").exists():
        assert proc.poll() is None and time.monotonic() < deadline, "the run ended before finishing a case"
        time.sleep(0.02)
    proc.send_signal(signum)
    stdout, stderr = proc.communicate(timeout=60)
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr), \
        json.loads((out / "results.json").read_text())


def _cache_is_intact() -> None:
    folder = Cache().folder
    names = [p.name for p in folder.iterdir()] if folder.exists() else []
    assert not [n for n in names if n.startswith(".")], names  # no temporary or half-discarded entry
    for name in names:
        assert Cache().load(name) is not None, f"cache entry {name} does not verify"


def test_sigint_keeps_finished_cases_and_a_rerun_renders_only_the_rest(tmp_path, capfd):
    path, out = _write_suite(tmp_path), tmp_path / "out"
    proc, first = _interrupt(path, out, signal.SIGINT, "local")
    done = len(first["cases"])
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == f"harness: interrupted after {done} of 4 cases; run again to resume"
    assert 1 <= done < 4 and first["complete"] is False
    assert [r["name"] for r in first["cases"]] == ["furnace", "cornell-box", "soft-shadows", "multi-light"][:done]
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no half-written results.json left
    _cache_is_intact()
    exr = {r["name"]: (out / "cases" / r["name"] / "render.exr").stat().st_mtime_ns for r in first["cases"]}

    # the rerun needs no signal and no worker: the command in this process, its cases serially (a process start, a
    # fork server's and a worker's fewer)
    capfd.readouterr()
    code = main(["run", str(path), "--out", str(out), "--no-report", "--executor", "serial"])
    again = capfd.readouterr()
    assert code == 0, again.err
    assert f"resuming: {done} of 4 cases done" in again.err
    second = json.loads((out / "results.json").read_text())
    assert second["complete"] is True and [r["status"] for r in second["cases"]] == ["pass"] * 4
    for before, after in zip(first["cases"], second["cases"]):  # kept as they were, not rendered again
        assert after["resumed"] is True
        assert {k: v for k, v in after.items() if k != "resumed"} == before
        assert (out / "cases" / before["name"] / "render.exr").stat().st_mtime_ns == exr[before["name"]]
    assert not any(r.get("resumed") for r in second["cases"][done:])
    _cache_is_intact()


def test_sigterm_stops_with_143_and_valid_results(tmp_path):
    path, out = _write_suite(tmp_path), tmp_path / "out"
    proc, first = _interrupt(path, out, signal.SIGTERM, "serial")
    assert proc.returncode == 143, proc.stderr
    assert "interrupted after" in proc.stderr and 1 <= len(first["cases"]) < 4
    _cache_is_intact()


def _furnace_suite(tmp_path: Path, spp_b: int = 4, name: str = "small") -> Path:
    text = f"""name = "{name}"
[defaults]
film = {{ width = 8, height = 8 }}
spp = 4
[[cases]]
name = "a"
scene = "SCENES/furnace.toml"
[[cases]]
name = "b"
scene = "SCENES/furnace.toml"
spp = {spp_b}
[[cases]]
name = "c"
scene = "SCENES/furnace.toml"
timeout = 30
"""
    path = tmp_path / "small.toml"
    path.write_text(text.replace("SCENES", str(SCENES)))
    return path


def test_resume_reruns_changed_errored_and_foreign_cases(tmp_path):
    out = tmp_path / "out"
    run_suite(load_suite(_furnace_suite(tmp_path)), out, executor=SerialExecutor())
    results = json.loads((out / "results.json").read_text())
    results["cases"][2]["status"] = "error"  # as if its worker had died: it runs again
    (out / "results.json").write_text(json.dumps(results))
    seen = []
    again = run_suite(load_suite(_furnace_suite(tmp_path, spp_b=8)), out, resume=True,
                      on_resume=lambda kept, total: seen.append((kept, total)))
    assert seen == [(1, 3)]
    assert [r.get("resumed", False) for r in again["cases"]] == [True, False, False]  # b changed, c had failed
    assert again["cases"][1]["budget"] == {"spp": 8}
    # the timeout is not part of a case's definition: changing it keeps the case
    path = _furnace_suite(tmp_path, spp_b=8)
    path.write_text(path.read_text().replace("timeout = 30", "timeout = 60"))
    third = run_suite(load_suite(path), out, resume=True)
    assert all(r.get("resumed") for r in third["cases"])
    # another suite writing into the same folder reuses nothing; neither does resume=False (--fresh)
    other = run_suite(load_suite(_furnace_suite(tmp_path, spp_b=8, name="other")), out, resume=True)
    assert not any(r.get("resumed") for r in other["cases"])
    fresh = run_suite(load_suite(_furnace_suite(tmp_path, spp_b=8, name="other")), out, resume=False)
    assert not any(r.get("resumed") for r in fresh["cases"])


def test_signals_stop_the_run_only_at_safe_points():
    before = signal.getsignal(signal.SIGTERM)
    with runstate.interruptible():
        with pytest.raises(runstate.Interrupted) as stop:
            with runstate.no_interrupts():
                with runstate.waiting():  # even while waiting, the results write completes first
                    os.kill(os.getpid(), signal.SIGTERM)
                    time.sleep(0.05)
                finished = True
        assert finished and stop.value.exit_code == 143
    with runstate.interruptible():
        os.kill(os.getpid(), signal.SIGINT)  # in the middle of a task in this process: held until check()
        time.sleep(0.05)
        assert runstate.requested()
        with pytest.raises(runstate.Interrupted) as stop:
            runstate.check()
        assert stop.value.exit_code == 130
    with runstate.interruptible():
        with pytest.raises(runstate.Interrupted):
            with runstate.waiting():
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(5)
                raise AssertionError("not interrupted while waiting")
    assert signal.getsignal(signal.SIGTERM) is before and not runstate.requested()
