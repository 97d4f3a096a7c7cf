"""Running a suite: its cases as tasks on an executor (:mod:`harness.running.executors`, handed
:func:`harness.running.judge.run_case`), ``results.json`` rewritten atomically after each finished case, and
resuming an earlier run (:mod:`harness.running.runstate`), and the results cache (:mod:`harness.running.result_cache`):
cases whose outcome is cached are answered from it, before the rest are handed to the executor. Schema:
``docs/results-schema.md``."""

from __future__ import annotations

import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from harness.core import jsonsafe, system
from harness.core.errors import HarnessError
from harness.files.imageio import atomic_write_text
from harness.running import executors, judge, result_cache, runstate
from harness.running.cases import Suite, slug


def run_suite(suite: Suite, out_dir: Path, *, cache_dir=None, variant=None,
              on_case: Callable[[int, dict], None] | None = None, executor=None, resume: bool = False,
              on_resume: Callable[[int, int], None] | None = None, timeout: float | None = None,
              results_cache: str = "off", on_start: Callable[[], None] | None = None) -> dict:
    """Run every case on ``executor`` (default: in this process, in order; ``harness.running.executors``), rewriting
    ``results.json`` atomically after each finished case, records in suite order whatever order cases finish in
    (finished cases are never lost). With ``resume``, the finished records of an earlier run of this suite in
    ``out_dir`` whose case definitions are unchanged are kept (``"resumed": true``) and only the rest run
    (``harness.running.runstate``); ``on_resume(kept, total)`` is told how many; ``on_start()`` is called once the
    input is checked (a link planted in ``out_dir``, an earlier results.json), before the first case. A task whose
    worker is killed (past ``timeout``, else the case's own, see ``executors.case_timeout``) or dies makes its case
    an error. Each case runs through :func:`harness.running.judge.run_case`, handed to the executor with the tasks.

    ``results_cache`` (:data:`harness.running.result_cache.MODES`): "use" answers every case whose outcome is
    cached from the cache (``"cached": {"from", "key"}``; its files copied into its folder) and stores the outcome
    of every other cacheable case; "refresh" renders every case and stores them all over the old entries; "off"
    neither reads nor writes."""
    out_dir.mkdir(parents=True, exist_ok=True)
    runstate.refuse_links(out_dir, suite.cases)  # a link planted in out_dir: one line, before the first render
    started = time.time()
    results: dict[str, Any] = {
        "schema": 1, "suite": suite.name, "suite_file": str(suite.path), "description": suite.description,
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started)),
        "host": {"python": platform.python_version(), "machine": platform.machine(), "node": platform.node()},
        "system": system.gather(variant),  # once per run (a few ms): docs/results-schema.md
        "cases": [],
    }
    executor = executor or executors.SerialExecutor()
    results["executor"] = executor.name
    digests = [runstate.case_digest(case, judge.case_scenes) for case in suite.cases]
    records = runstate.reusable(out_dir / "results.json", suite.name, suite.cases, digests) if resume else {}
    if records and on_resume is not None:
        on_resume(len(records), len(suite.cases))

    def write() -> None:
        results["cases"] = [records[i] for i in sorted(records)]
        results["complete"] = len(records) == len(suite.cases)
        results["summary"] = summarise(results["cases"], time.time() - started)
        results["system"]["mitsuba"]["variants_used"] = mitsuba_variants(results["cases"])
        with runstate.no_interrupts():  # a signal waits until the file is renamed into place
            atomic_write_text(out_dir / "results.json", jsonsafe.dumps(results, indent=2))

    todo = [(i, case) for i, case in enumerate(suite.cases) if i not in records]
    cache = result_cache.CaseCache(cache_dir, variant, results_cache, results["started"],
                                   machine={k: results["system"][k] for k in system.MACHINE_KEYS})
    if on_start is not None:
        on_start()
    if cache.reads:
        hits = []
        for index, case in todo:
            runstate.check()
            record = cache.restore(case, out_dir / "cases" / slug(case.name))
            if record is not None:
                record["definition"] = digests[index]
                records[index] = record
                hits.append(index)
        if hits:
            with runstate.no_interrupts():  # written and reported as one step (a signal waits for both)
                write()  # once for them all: a hit costs milliseconds, rewriting results.json after each would not
                for index in hits:
                    if on_case is not None:
                        on_case(index, records[index])
        todo = [(i, case) for i, case in todo if i not in records]
    # what each case folder held before its case runs: the files it writes are the ones that change
    before = {i: result_cache.snapshot(out_dir / "cases" / slug(case.name)) for i, case in todo
              if cache.writes and result_cache.not_cacheable(case) is None}
    tasks = executors.plan(todo, out_dir, run_case=judge.run_case, case_scenes=judge.case_scenes, cache_dir=cache_dir,
                           variant=variant, timeout=timeout, chunks=executor.chunks)
    rendered: set[str] = set()  # chunk tasks that rendered, not yet counted in a case's record
    outcomes = executor.run(tasks)
    try:
        for task, outcome in outcomes:
            if outcome[0] == "failed" and runstate.requested():
                runstate.check()  # a worker that died of the signal that stops the run is not the case's fault
            if outcome[0] == "harness-error":
                raise HarnessError(outcome[1], outcome[2])
            if task.kind != "case":
                if outcome == ("ok", True):
                    rendered.add(task.key)
                continue
            index = int(task.key.split(":")[1])
            case = suite.cases[index]
            if outcome[0] == "ok":
                record = outcome[1]
                mine = rendered.intersection(task.deps)  # its chunks rendered ahead count as its renders
                if mine and "ground_truth" in record:
                    rendered -= mine
                    record["ground_truth"].update(renders=record["ground_truth"]["renders"] + len(mine), cached=False)
            else:  # the worker was killed or died: the suite goes on
                record = dict(judge.case_header(case), status="error", ok=False, reason=outcome[1],
                              wall_seconds=outcome[2] if len(outcome) > 2 else None)
            record["definition"] = digests[index]
            if index in before:
                key = cache.save(case, record, out_dir / "cases" / slug(case.name), before[index])
                if key is not None:
                    record["cache_key"] = key
            records[index] = record
            # written and reported as one step: a signal that lands between the two would stop the run with the
            # case kept in results.json but not counted in "interrupted after N of M cases"
            with runstate.no_interrupts():
                write()
                if on_case is not None:
                    on_case(index, record)
            runstate.check()
    finally:
        outcomes.close()  # stops the workers, whatever ended the loop
    if not todo:  # everything was resumed: still record this run
        write()
    return results


def summarise(records: list[dict], wall: float) -> dict:
    """The ``summary`` of ``results.json``: counts of the records' outcomes, this run's Mitsuba renders, the wall
    time."""
    return {
        "cases": len(records),
        "ok": sum(r["ok"] for r in records),
        "passed": sum(r.get("status") == "pass" for r in records),
        "failed": sum(r.get("status") == "fail" for r in records),
        "errors": sum(r.get("status") == "error" for r in records),
        "skipped": sum(r.get("status") == "skipped" for r in records),
        "unexpected": [r["name"] for r in records if not r["ok"]],
        "mitsuba_renders": sum(_mitsuba_renders(r) for r in records if not r.get("resumed")),  # by this run
        "resumed": sum(bool(r.get("resumed")) for r in records),
        "ground_truth_cached": sum(bool(r.get("ground_truth", {}).get("cached")) for r in records),
        "from_cache": sum(bool(r.get("cached")) for r in records if not r.get("resumed")),  # by this run
        "wall_seconds": wall,
    }


def mitsuba_variants(records: list[dict]) -> list[str]:
    """The Mitsuba variants the records used: their ground truths' and their Mitsuba renders'."""
    used = set()
    for record in records:
        used.add((record.get("ground_truth") or {}).get("variant"))
        if record.get("renderer") == "mitsuba":
            used.add(((record.get("render") or {}).get("info") or {}).get("variant"))
    return sorted(v for v in used if isinstance(v, str))


def _mitsuba_renders(record: dict) -> int:
    """Mitsuba renders a case performed: for its ground truth, and for its test render if Mitsuba made it."""
    renders = record.get("ground_truth", {}).get("renders", 0)
    render = record.get("render", {})
    if record.get("renderer") == "mitsuba":
        renders += render.get("info", {}).get("mitsuba_renders", 1 if render else 0)
    return renders
