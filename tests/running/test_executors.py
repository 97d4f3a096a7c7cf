"""Executors: a hung or crashing renderer fails only its case; a Dask cluster gives the same results as a local run;
ground-truth chunks are planned once per cache key."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

import flaky_renderers
from harness.running import executors, judge
from harness.cli import main
from harness.running.cases import load_suite
from harness.running.schedule import run_suite

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"


def _suite(tmp_path: Path, body: str, name: str = "exec") -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'name = "{name}"\n' + body.replace("SCENES", str(SCENES)))
    return path


def test_hang_segfault_and_exit_fail_only_their_case(tmp_path, monkeypatch):
    from harness import renderers

    for cls in (flaky_renderers.HangRenderer, flaky_renderers.SegfaultRenderer, flaky_renderers.ExitRenderer):
        monkeypatch.setitem(renderers._RENDERERS, cls.name, cls)
    path = _suite(tmp_path, """
[defaults]
spp = 4
film = { width = 16, height = 16 }
against = "closed-form"

[[cases]]
name = "hang"
scene = "SCENES/furnace.toml"
renderer = "test-hang"
timeout = 2

[[cases]]
name = "segfault"
scene = "SCENES/furnace.toml"
renderer = "test-segfault"

[[cases]]
name = "exit"
scene = "SCENES/furnace.toml"
renderer = "test-exit"

[[cases]]
name = "fine"
scene = "SCENES/furnace.toml"
""")
    executor = executors.LocalExecutor(workers=2, initializer=flaky_renderers.register)
    start = time.monotonic()
    results = run_suite(load_suite(path), tmp_path / "out", executor=executor)
    elapsed = time.monotonic() - start
    by_name = {r["name"]: r for r in results["cases"]}
    assert [r["name"] for r in results["cases"]] == ["hang", "segfault", "exit", "fine"]  # suite order
    assert by_name["hang"]["status"] == "error" and by_name["hang"]["reason"] == "timed out after 2 s"
    assert by_name["hang"]["wall_seconds"] >= 2
    assert by_name["segfault"]["status"] == "error"
    assert by_name["segfault"]["reason"] == "worker died: killed by SIGSEGV"
    assert by_name["exit"]["status"] == "error" and by_name["exit"]["reason"] == "worker died: exit code 3"
    assert by_name["fine"]["status"] == "pass", by_name["fine"].get("reason")
    assert elapsed < 60  # the hang was cut at its timeout, not waited for
    on_disk = json.loads((tmp_path / "out" / "results.json").read_text())
    assert [r["status"] for r in on_disk["cases"]] == ["error", "error", "error", "pass"]
    assert on_disk["complete"] is True and on_disk["executor"] == "local"


def test_ground_truth_chunks_are_planned_once_per_key(tmp_path):
    path = _suite(tmp_path, """
[defaults]
spp = 4
ground_truth_spp = 600
film = { width = 8, height = 8 }

[[cases]]
name = "a"
scene = "SCENES/cornell-box.toml"

[[cases]]
name = "b"
scene = "SCENES/cornell-box.toml"
seed = 5

[[cases]]
name = "closed"
scene = "SCENES/furnace.toml"
""")
    suite = load_suite(path)
    tasks = executors.plan(list(enumerate(suite.cases)), tmp_path, run_case=judge.run_case,
                           case_scenes=judge.case_scenes, cache_dir=tmp_path / "cache")
    chunks = [t for t in tasks if t.kind == "chunk"]
    cases = [t for t in tasks if t.kind == "case"]
    assert [c.payload.count for c in chunks] == [256, 256, 88]  # 600 spp in chunks of 256, once for both cases
    assert tasks[:4] == [*chunks, cases[0]]  # a case's chunks just before it, then the cases in suite order
    assert [t.key for t in cases] == ["case:0", "case:1", "case:2"]
    assert [t.group for t in cases] == [str(c.scene) for c in suite.cases]
    assert cases[0].deps == cases[1].deps == tuple(t.key for t in chunks)
    assert cases[2].deps == ()  # a closed form needs no chunk


def test_bad_executor_is_one_line(tmp_path, capsys):
    path = _suite(tmp_path, '[[cases]]\nscene = "SCENES/furnace.toml"\n')
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--executor", "spark"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["harness: error: --executor: expected serial, local, dask or tcp://HOST:PORT, got 'spark'"]
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2
    assert "--workers" in capsys.readouterr().err
    assert main(["run", str(path), "--out", str(tmp_path / "o"), "--timeout", "-1"]) == 2
    assert "--timeout" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # nothing written


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _comparable(record: dict) -> dict:
    return {k: record.get(k) for k in ("name", "status", "ok", "reason", "metrics", "verdict", "thresholds_broken")}


@pytest.mark.slow
def test_dask_cluster_on_loopback_matches_local_run(tmp_path):
    """A scheduler and two workers on 127.0.0.1; the suite renders its ground-truth chunks there (fresh cache),
    then the same suite runs serially in this process from that cache: same statuses, verdicts and metrics, bit
    for bit (the reference is seeded; both read the same ground truth)."""
    bin_dir = Path(sys.executable).parent
    cache = tmp_path / "cache"
    env = dict(os.environ, HARNESS_CACHE_DIR=str(cache))
    path = _suite(tmp_path, """
[defaults]
spp = 8
ground_truth_spp = 300
film = { width = 16, height = 16 }

[[cases]]
name = "furnace"
scene = "SCENES/furnace.toml"

[[cases]]
name = "cornell-box"
scene = "SCENES/cornell-box.toml"

[[cases]]
name = "furnace/mutant"
scene = "SCENES/furnace.toml"
settings = { mutant = "double-emission" }
expect = "fail"
""", name="dask-check")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([str(bin_dir / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for i in range(2):
            procs.append(subprocess.Popen(
                [str(bin_dir / "dask"), "worker", address, "--nthreads", "1", "--no-dashboard", "--no-nanny",
                 "--host", "127.0.0.1", "--name", f"w{i}"], env=env, stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout="20s") as client:
            client.wait_for_workers(2, timeout=30)
        runs = {}
        args = [str(path), "--no-report", "--quiet", "--cache-dir", str(cache)]
        # the command in this process (the Client above already is): the cluster's processes are the ones that count
        assert main(["run", *args, "--out", str(tmp_path / "dask"), "--executor", address]) == 0
        runs["dask"] = json.loads((tmp_path / "dask" / "results.json").read_text())
    finally:
        for proc in procs:  # a worker sent SIGTERM closes gracefully, 1-2 s; nothing here needs that
            proc.kill()
        for proc in procs:
            proc.wait(10)
    assert main(["run", *args, "--out", str(tmp_path / "serial"), "--executor", "serial"]) == 0
    dask_run = runs["dask"]
    local_run = json.loads((tmp_path / "serial" / "results.json").read_text())
    assert [_comparable(r) for r in dask_run["cases"]] == [_comparable(r) for r in local_run["cases"]]
    assert [r["status"] for r in dask_run["cases"]] == ["pass", "pass", "fail"]
    # the Cornell box's ground truth (chunks of 256 + 44 spp) was two tasks on the cluster; the local run read it
    assert dask_run["summary"]["mitsuba_renders"] == 2 and local_run["summary"]["mitsuba_renders"] == 0
    assert dask_run["executor"] == "dask" and local_run["executor"] == "serial"


def _handed_run_case(case, out_dir, *, cache_dir=None, variant=None):
    """A case runner handed to the executors (module-level, as a worker process would need)."""
    return {"name": case.name, "ran_by": "handed", "out": str(out_dir), "variant": variant}


def test_the_case_runner_is_handed_in_not_imported(tmp_path):
    """plan() takes what runs a case and what gives its scenes from its caller, and the executor runs exactly that;
    executors.py imports none of the modules that call it (no circle schedule <-> executors)."""
    import ast

    suite = load_suite(_suite(tmp_path, '[[cases]]\nscene = "SCENES/furnace.toml"\nspp = 2\n'))
    seen = []

    def scenes(case):
        seen.append(case.name)
        return judge.case_scenes(case)

    tasks = executors.plan(list(enumerate(suite.cases)), tmp_path, run_case=_handed_run_case, case_scenes=scenes,
                           cache_dir=tmp_path / "cache", variant="v")
    assert seen == ["furnace"]  # asked for its scenes, to plan its chunks (a closed form: none)
    outcomes = [outcome for _, outcome in executors.SerialExecutor().run(tasks)]
    assert outcomes == [("ok", {"name": "furnace", "ran_by": "handed", "out": str(tmp_path), "variant": "v"})]
    imported = set()
    for node in ast.walk(ast.parse(Path(executors.__file__).read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            imported |= {node.module, *(f"{node.module}.{a.name}" for a in node.names)}
        elif isinstance(node, ast.Import):
            imported |= {a.name for a in node.names}
    callers = {"harness.running.schedule", "harness.running.judge", "harness.running.cases", "harness.running.suite"}
    assert not imported & callers


def test_two_cases_of_one_scene_run_side_by_side_only_when_nothing_else_is_ready():
    """The local executor's choice (_next_ready): the first ready task whose group no running task has, else the
    first ready task; a task waits for its dependencies."""
    task = lambda key, group="", deps=(): executors.Task(key, "case", None, 1.0, deps, None, group)  # noqa: E731
    a1, a2, b1 = task("a1", "scene-a"), task("a2", "scene-a"), task("b1", "scene-b", deps=("chunk",))
    chunk = executors.Task("chunk", "chunk", None, 1.0)
    assert executors._next_ready([a2, chunk, b1], set(), {"scene-a"}) is chunk  # not a second case of scene a
    assert executors._next_ready([a2, b1], set(), {"scene-a"}) is a2  # nothing else ready: side by side after all
    assert executors._next_ready([a2, b1], {"chunk"}, {"scene-a"}) is b1  # b1's chunk done: another scene first
    assert executors._next_ready([b1], set(), set()) is None  # its chunk is not done
    assert executors._next_ready([a1, a2], set(), set()) is a1  # suite order otherwise
