"""Where a suite's work runs: in this process, on a pool of local worker processes, or on a Dask cluster.

A suite run is a list of ``Task``s, each a case or one chunk of a Mitsuba ground truth (``groundtruth.ChunkJob``).
What runs a case, and what gives its scenes, are handed in by the caller (:func:`plan`'s ``run_case`` and
``case_scenes``; :func:`harness.running.schedule.run_suite` hands in :mod:`harness.running.judge`'s): this module
imports nothing from the modules that call it. They must be module-level functions, so that worker processes and
Dask can unpickle them by name. Chunk tasks come first and are deduplicated by cache key, so two workers never render
the same chunk; a case depends on the chunks of its ground truth and, when it runs, ``ground_truth()`` finds them
cached and merges them exactly (``harness.judges.moments``), giving the same image as a serial run, bit for bit.

Executors (``harness run --executor``):

``serial``       every task in this process, one after another; no isolation (a crash ends the run).
``local``        a pool of ``workers`` processes on this machine (the default). Each task runs in a worker; a task
                 that runs past its timeout has its worker killed and is recorded as "timed out after X s"; a
                 worker that dies (a segfault, ``os._exit``) fails its task with the signal or exit code. Dead
                 workers are replaced and the run goes on.
``dask``         a ``distributed.LocalCluster`` (processes, ``workers`` x 1 thread), or ``tcp://HOST:PORT``: an
                 existing Dask scheduler. Workers must see the ground-truth cache and the output folder at the same
                 paths (one machine, or a shared file system). A worker that dies is retried by Dask, then the
                 task fails with Dask's reason; per-task timeouts are not enforced on Dask.

Every executor yields ``(task, outcome)`` as tasks finish; ``outcome`` is ``("ok", value)``,
``("harness-error", where, message)`` (a user error: the run stops with exit code 2) or ``("failed", reason)``.
"""

from __future__ import annotations

import multiprocessing
import re
import signal
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from multiprocessing import connection
from pathlib import Path
from typing import Any

from harness.core.errors import HarnessError
from harness.renderers import groundtruth
from harness.running import runstate

CHUNK_TIMEOUT = 600.0  # seconds for one Mitsuba ground-truth chunk (256 spp by default)
SPP_CASE_TIMEOUT = 600.0  # seconds for a case with an spp budget
MIN_SECONDS_TIMEOUT, SECONDS_FACTOR = 120.0, 20.0  # a case with a seconds budget: max(120 s, 20 x the budget)
DEFAULT_WORKERS = 1  # measured in docs/robustness.md ("Executors")
#: Modules the local workers' fork server imports once; the modules of the tasks' ``run_case`` functions are added.
PRELOAD = ["harness.renderers", "harness.renderers.groundtruth"]


@dataclass(frozen=True)
class Task:
    key: str  # unique within a run: "case:<index>" or "chunk:<cache key>"
    kind: str  # "case" | "chunk"
    payload: Any  # (Case, out_dir, cache_dir, variant) for a case, a groundtruth.ChunkJob for a chunk
    timeout: float
    deps: tuple[str, ...] = ()  # keys of tasks that must finish first (whatever their outcome)
    run_case: Callable[..., Any] | None = None  # a case's: run_case(case, out_dir, cache_dir=, variant=) -> record


def case_timeout(case, override: float | None = None) -> float:
    """``--timeout``, else the case's ``timeout`` key, else 600 s for an spp budget and max(120 s, 20 x seconds)
    for a seconds budget (a time budget is only approximately kept: a chunk in flight is finished)."""
    if override is not None:
        return override
    if case.timeout is not None:
        return case.timeout
    if case.seconds is not None:
        return max(MIN_SECONDS_TIMEOUT, SECONDS_FACTOR * case.seconds)
    return SPP_CASE_TIMEOUT


def run_task(task: Task):
    """Run one task wherever this is called; never raises for a failure of the work itself."""
    try:
        if task.kind == "chunk":
            return ("ok", task.payload.run())
        case, out_dir, cache_dir, variant = task.payload
        return ("ok", task.run_case(case, Path(out_dir), cache_dir=cache_dir, variant=variant))
    except HarnessError as err:
        return ("harness-error", err.where, err.message)
    except Exception as err:  # a chunk that fails: the case that needs it renders it again and reports why
        return ("failed", f"{type(err).__name__}: {err}".splitlines()[0])


def _run_after(task: Task, _deps: list):
    """Dask wrapper: ``_deps`` are the futures of the task's dependencies (Dask waits for them)."""
    return run_task(task)


def plan(cases: Sequence[tuple[int, Any]], out_dir: Path, *, run_case: Callable[..., Any],
         case_scenes: Callable[[Any], tuple], cache_dir=None, variant=None, timeout: float | None = None,
         chunks: bool = True) -> list[Task]:
    """The tasks of a run: the missing ground-truth chunks of the ``(index, case)`` pairs (once each), then the
    cases in suite order, each depending on its chunks. ``run_case(case, out_dir, cache_dir=, variant=)`` runs a
    case (in a worker: a module-level function) and ``case_scenes(case)`` gives (the scene it renders, the scene
    of its ground truth), to find the chunks."""
    cache_dir = str(cache_dir if cache_dir is not None else groundtruth.default_cache_dir())  # here, not by workers
    chunk_tasks: dict[str, Task] = {}
    case_tasks = []
    for index, case in cases:
        deps = []
        if chunks:
            for job in _chunk_jobs(case, cache_dir, variant, case_scenes):
                key = f"chunk:{job.key}"
                chunk_tasks.setdefault(key, Task(key, "chunk", job, max(CHUNK_TIMEOUT, timeout or 0.0)))
                deps.append(key)
        case_tasks.append(Task(f"case:{index}", "case", (case, str(out_dir), cache_dir, variant),
                               case_timeout(case, timeout), tuple(dict.fromkeys(deps)), run_case))
    return [*chunk_tasks.values(), *case_tasks]


def _chunk_jobs(case, cache_dir, variant, case_scenes: Callable[[Any], tuple]) -> list:
    """The Mitsuba ground-truth chunks a case will need that are not cached yet (the renders ``ground_truth_for``
    and ``render_with_budget`` make through the cache). A scene that cannot be loaded needs none here: the case
    itself reports it."""
    try:
        scene, gt_scene = case_scenes(case)  # a stress variant may be judged on the plain scene
    except HarnessError:
        return []
    needs = []  # (scene, spp, seed, variant)
    kind = case.against.kind
    if kind == "mitsuba" or (kind == "ground-truth" and not gt_scene.closed_form):
        needs.append((gt_scene, case.ground_truth_spp, 0, variant))
    elif kind == "renderer" and case.against.renderer == "mitsuba":
        needs.append((gt_scene, case.against.spp, case.against.seed, case.against.settings.get("variant", variant)))
    settings = dict(case.settings)
    if case.renderer == "mitsuba" and case.spp is not None and set(settings) <= {"variant"}:
        needs.append((scene, case.spp, case.seed, settings.get("variant", variant)))
    jobs = []
    for needed, spp, seed, var in needs:
        try:
            jobs += groundtruth.missing_chunks(needed, spp=spp, seed=seed, cache_dir=cache_dir, variant=var)
        except HarnessError:  # a variant not usable here (no GPU): the case itself says so, skipped or an error
            continue
    return jobs


# ---- executors -------------------------------------------------------------------------------------------------


class SerialExecutor:
    """Every task in this process, in order."""

    name = "serial"
    chunks = False  # ground_truth() renders the chunks itself, in order: planning them would only cost time

    def run(self, tasks: Sequence[Task]) -> Iterator[tuple[Task, tuple]]:
        for task in tasks:
            runstate.check()
            yield task, run_task(task)


class _Worker:
    def __init__(self, ctx, initializer):
        self.conn, child = ctx.Pipe()
        self.process = ctx.Process(target=_worker_main, args=(child, initializer), daemon=True)
        self.process.start()
        child.close()

    def stop(self, grace: float = 1.0) -> None:
        """SIGTERM (the worker unwinds: a cache entry being written removes its temporary folder), then SIGKILL
        after ``grace`` seconds (a worker stuck in native code)."""
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(grace)
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5)
        self.conn.close()

    def death(self) -> str:
        self.process.join(5)
        code = self.process.exitcode
        if code is not None and code < 0:
            try:
                return f"worker died: killed by {signal.Signals(-code).name}"
            except ValueError:
                return f"worker died: killed by signal {-code}"
        return f"worker died: exit code {code}"


def _worker_main(conn, initializer) -> None:
    # Ctrl-C reaches the whole process group: the parent decides, and kills the workers when it stops.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    if initializer is not None:
        initializer()
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        conn.send(run_task(task))


def _exit_on_sigterm(signum, _frame):
    raise SystemExit(128 + signum)  # unwinds through finally blocks, unlike the default action


def _preload(tasks: Sequence[Task]) -> list[str]:
    """:data:`PRELOAD` and the modules of the tasks' ``run_case`` functions."""
    modules = {getattr(t.run_case, "__module__", None) for t in tasks if t.run_case is not None}
    return [*PRELOAD, *sorted(m for m in modules if m and m not in PRELOAD)]


class LocalExecutor:
    """A pool of ``workers`` processes (forked from a clean server process); one task per worker at a time, a deadline
    per task, and a fresh worker for one that was killed or died. ``initializer`` runs in every worker first
    (a module-level function: it must be importable there)."""

    name = "local"
    chunks = True

    def __init__(self, workers: int = DEFAULT_WORKERS, initializer: Callable[[], None] | None = None):
        if workers < 1:
            raise HarnessError("--workers", f"expected a positive integer, got {workers}")
        self.workers = workers
        self.initializer = initializer

    def run(self, tasks: Sequence[Task]) -> Iterator[tuple[Task, tuple]]:
        ctx = multiprocessing.get_context("forkserver")
        # Workers fork from a server that has imported the harness once (2-3 s), so a worker that replaces a killed
        # one starts at once; the server has started no threads, so forking it is safe.
        ctx.set_forkserver_preload(_preload(tasks))
        pending = list(tasks)
        done: set[str] = set()
        idle: list[_Worker] = []
        running: dict[_Worker, tuple[Task, float, float]] = {}  # worker: (task, deadline, start)
        try:
            while pending or running:
                while pending and (idle or len(idle) + len(running) < self.workers):
                    ready = next((t for t in pending if all(d in done for d in t.deps)), None)
                    if ready is None:
                        break
                    pending.remove(ready)
                    worker = None
                    while idle and worker is None:  # a worker that died while idle is replaced
                        candidate = idle.pop()
                        if candidate.process.is_alive():
                            worker = candidate
                        else:
                            candidate.stop()
                    worker = worker or _Worker(ctx, self.initializer)
                    worker.conn.send(ready)
                    now = time.monotonic()
                    running[worker] = (ready, now + ready.timeout, now)
                if not running:  # unreachable unless a dependency is missing: run the rest regardless
                    done.update(d for t in pending for d in t.deps)
                    continue
                wait = max(0.0, min(deadline for _, deadline, _ in running.values()) - time.monotonic())
                with runstate.waiting():
                    connection.wait([w.conn for w in running] + [w.process.sentinel for w in running], timeout=wait)
                for worker, (task, deadline, start) in list(running.items()):
                    outcome = None
                    if worker.conn.poll():
                        try:
                            outcome = worker.conn.recv()
                            idle.append(worker)
                        except (EOFError, OSError):
                            outcome = ("failed", worker.death(), time.monotonic() - start)
                            worker.stop()
                    elif not worker.process.is_alive():
                        outcome = ("failed", worker.death(), time.monotonic() - start)
                        worker.stop()
                    elif time.monotonic() >= deadline:
                        worker.stop()
                        outcome = ("failed", f"timed out after {task.timeout:g} s", time.monotonic() - start)
                    if outcome is not None:
                        del running[worker]
                        done.add(task.key)
                        yield task, outcome
        finally:
            everyone = [*idle, *running]
            for worker in everyone:
                if worker.process.is_alive():
                    worker.process.terminate()
            deadline = time.monotonic() + 3.0
            for worker in everyone:
                worker.process.join(max(0.0, deadline - time.monotonic()))
                worker.stop(grace=0.0)


class DaskExecutor:
    """Tasks on Dask: a LocalCluster of ``workers`` processes x ``threads`` threads, or the scheduler at
    ``address`` (``tcp://HOST:PORT``). Tasks are submitted in order with decreasing priority, so cases start in
    suite order; a case's chunk futures are its arguments, so it waits for them."""

    name = "dask"
    chunks = True

    def __init__(self, address: str | None = None, workers: int = 2, threads: int = 1):
        self.address = address
        self.workers = workers
        self.threads = threads

    def run(self, tasks: Sequence[Task]) -> Iterator[tuple[Task, tuple]]:
        from distributed import Client, LocalCluster, as_completed  # optional: heavy, only the dask executor uses it

        cluster = None
        try:
            if self.address is None:
                cluster = LocalCluster(n_workers=self.workers, threads_per_worker=self.threads, processes=True,
                                       dashboard_address=None)
                client = Client(cluster)
            else:
                client = Client(self.address, timeout="10s")
        except OSError as err:
            if cluster is not None:
                cluster.close()
            raise HarnessError("--executor", f"cannot reach the Dask scheduler {self.address}: {err}") from None
        run_id = uuid.uuid4().hex[:8]
        try:
            futures, owner = {}, {}
            for position, task in enumerate(tasks):
                future = client.submit(_run_after, task, [futures[d] for d in task.deps if d in futures],
                                       key=f"harness-{run_id}-{task.key}", pure=False,
                                       priority=len(tasks) - position)
                futures[task.key] = future
                owner[future.key] = task
            pending = as_completed(list(futures.values()))
            while True:
                with runstate.waiting():
                    future = next(pending, None)
                if future is None:
                    break
                task = owner[future.key]
                try:
                    outcome = future.result()
                except Exception as err:  # the task could not run (KilledWorker after retries, ...)
                    outcome = ("failed", f"{type(err).__name__}: {err}".splitlines()[0])
                yield task, outcome
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


_TCP_ADDRESS = re.compile(r"tcp://(?:[A-Za-z0-9._-]+|\[[0-9A-Fa-f:.]+\]):([0-9]{1,5})")


def make_executor(spec: str | None, workers: int | None = None):
    """The executor named by ``--executor`` (serial, local, dask or tcp://HOST:PORT) with ``--workers``."""
    spec = "local" if spec is None else spec
    if workers is not None and workers < 1:
        raise HarnessError("--workers", f"expected a positive integer, got {workers}")
    if spec == "serial":
        return SerialExecutor()
    if spec == "local":
        return LocalExecutor(workers or DEFAULT_WORKERS)
    if spec == "dask":
        return DaskExecutor(workers=workers or 2)
    address = _TCP_ADDRESS.fullmatch(spec)
    if address and 1 <= int(address.group(1)) <= 65535:  # Dask's own parser raises ValueError on a bad port
        return DaskExecutor(address=spec)
    raise HarnessError("--executor", f"expected serial, local, dask or tcp://HOST:PORT, got {spec!r}")

