"""Where a suite's work runs: in this process, on a pool of local worker processes, or on a Dask cluster.

A suite run is a list of ``Task``s, each a case or one chunk of a Mitsuba ground truth (``groundtruth.ChunkJob``).
What runs a case, and what gives its scenes, are handed in by the caller (:func:`plan`'s ``run_case`` and
``case_scenes``; :func:`harness.running.schedule.run_suite` hands in :mod:`harness.running.judge`'s): this module
imports nothing from the modules that call it. They must be module-level functions, so that worker processes and
Dask can unpickle them by name. A case's missing chunks come just before it, deduplicated by cache key, so two
workers never render the same chunk; a case depends on the chunks of its ground truth and, when it runs,
``ground_truth()`` finds them cached and merges them exactly (``harness.judges.moments``), giving the same image as a
serial run, bit for bit.

Executors (``harness run --executor``):

``serial``       every task in this process, one after another; no isolation (a crash ends the run).
``local``        a pool of ``workers`` processes on this machine (the default; two by default). Each task runs in a
                 worker; a task that runs past its timeout has its worker killed and is recorded as "timed out
                 after X s"; a worker that dies (a segfault, ``os._exit``) fails its task with the signal or exit
                 code. Dead workers are replaced and the run goes on.
``dask``         a ``distributed.LocalCluster`` (processes, ``workers`` x 1 thread), or ``tcp://HOST:PORT``: an
                 existing Dask scheduler. Workers must see the ground-truth cache and the output folder at the same
                 paths (one machine, or a shared file system). A worker that dies is retried by Dask, then the
                 task fails with Dask's reason; per-task timeouts are not enforced on Dask. Before Dask is
                 handed an address, :func:`check_scheduler` connects with a plain socket and reads the peer's
                 answer to Dask's handshake (:data:`CONNECT_TIMEOUT` seconds, at most :data:`HANDSHAKE_LIMIT`
                 bytes): a peer that is not a Dask scheduler is one line, not Dask's own reading of its bytes.

Every executor yields ``(task, outcome)`` as tasks finish; ``outcome`` is ``("ok", value)``,
``("harness-error", where, message)`` (a user error: the run stops with exit code 2) or ``("failed", reason)``.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import pickle
import re
import signal
import socket
import struct
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from multiprocessing import connection
from pathlib import Path
from typing import Any

import msgpack

from harness.core.errors import HarnessError
from harness.core.text import short
from harness.renderers import groundtruth
from harness.running import runstate

CHUNK_TIMEOUT = 600.0  # seconds for one Mitsuba ground-truth chunk (256 spp by default)
SPP_CASE_TIMEOUT = 600.0  # seconds for a case with an spp budget
MIN_SECONDS_TIMEOUT, SECONDS_FACTOR = 120.0, 20.0  # a case with a seconds budget: max(120 s, 20 x the budget)
#: local worker processes by default: two (one where the machine has one core), measured in docs/robustness.md
#: ("Executors"): one worker's single-threaded parts (numba compiling a path loop, a verdict) leave a core idle
DEFAULT_WORKERS = min(2, os.cpu_count() or 1)
#: seconds a Dask scheduler named by ``--executor tcp://HOST:PORT`` has to accept the connection and answer Dask's
#: handshake (:func:`check_scheduler`), and Dask's own connection timeout after it
CONNECT_TIMEOUT = 10.0
#: the most bytes read from a peer for its handshake (a scheduler's is about 60 bytes)
HANDSHAKE_LIMIT = 4096
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
    group: str = ""  # a case's scene: the local executor runs two cases of one scene side by side only when nothing
    #                  else is ready (they would compile the same kernels, one waiting for the other)


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
    """The tasks of a run: the cases in suite order, each depending on its missing ground-truth chunks, which come just
    before it (once each: a chunk two cases need comes before the first). Workers take the first task that is ready, so
    a case starts as soon as its chunks are done while other workers render the chunks of the next cases: a case's
    single-threaded parts (numba compiling its path loop, its verdict) overlap Mitsuba's renders. ``run_case(case,
    out_dir, cache_dir=, variant=)`` runs a case (in a worker: a module-level function) and ``case_scenes(case)`` gives
    (the scene it renders, the scene of its ground truth), to find the chunks."""
    cache_dir = str(cache_dir if cache_dir is not None else groundtruth.default_cache_dir())  # here, not by workers
    tasks: list[Task] = []
    planned: set[str] = set()
    for index, case in cases:
        deps = []
        if chunks:
            for job in _chunk_jobs(case, cache_dir, variant, case_scenes):
                key = f"chunk:{job.key}"
                if key not in planned:
                    planned.add(key)
                    tasks.append(Task(key, "chunk", job, max(CHUNK_TIMEOUT, timeout or 0.0)))
                deps.append(key)
        tasks.append(Task(f"case:{index}", "case", (case, str(out_dir), cache_dir, variant),
                          case_timeout(case, timeout), tuple(dict.fromkeys(deps)), run_case, str(case.scene)))
    return tasks


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


def _next_ready(pending: Sequence[Task], done: set[str], busy: set[str]) -> Task | None:
    """The first pending task whose dependencies are done and whose group no running task has; else the first
    whose dependencies are done; else None."""
    first = None
    for task in pending:
        if all(d in done for d in task.deps):
            if task.group not in busy:
                return task
            first = first or task
    return first


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
                    ready = _next_ready(pending, done, {t.group for t, _, _ in running.values() if t.group})
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

    def __init__(self, address: str | None = None, workers: int = 2, threads: int = 1,
                 timeout: float | None = None):
        self.address = address
        self.workers = workers
        self.threads = threads
        self.timeout = CONNECT_TIMEOUT if timeout is None else timeout  # seconds to connect to ``address``
        self._checked = False

    def check(self) -> None:
        """:func:`check_scheduler` on ``address`` (once), so that a run can refuse a peer that is not a Dask
        scheduler before it writes anything; SIGINT / SIGTERM stop the wait at once."""
        if self.address is not None and not self._checked:
            with runstate.waiting():  # only waiting for the peer: SIGINT / SIGTERM stop the run at once
                check_scheduler(self.address, self.timeout)
            self._checked = True

    def run(self, tasks: Sequence[Task]) -> Iterator[tuple[Task, tuple]]:
        self.check()
        from distributed import Client, LocalCluster, as_completed  # optional: heavy, only the dask executor uses it

        cluster = None
        if self.address is not None:
            client = _connect(Client, self.address, self.timeout)
        else:
            try:
                cluster = LocalCluster(n_workers=self.workers, threads_per_worker=self.threads, processes=True,
                                       dashboard_address=None)
                client = Client(cluster)
            except OSError as err:
                if cluster is not None:
                    cluster.close()
                raise HarnessError("--executor", f"cannot start a Dask LocalCluster: {err}") from None
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


class _Deadline(KeyboardInterrupt):
    """Raised in the main thread by SIGALRM past the connection's deadline (:func:`_within`). A KeyboardInterrupt,
    because that is what makes Dask's ``distributed.utils.sync`` cancel the connection it waits for."""


@contextlib.contextmanager
def _within(seconds: float):
    """Raise ``_Deadline`` in the block after ``seconds`` (a SIGALRM timer; in the main thread only, elsewhere
    nothing is bounded)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def alarm(_signum, _frame):
        raise _Deadline

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, signal.SIG_DFL if previous is None else previous)  # None: not set from Python


def _connect(client_type, address: str, timeout: float):
    """Dask's ``client_type`` (``distributed.Client``) connected to ``address`` within ``timeout`` seconds in all:
    Dask's own timeout leaves out its handshake, which a peer that answered :func:`check_scheduler` could still
    withhold from this second connection. Any failure is a one-line HarnessError at ``--executor``."""
    try:
        with runstate.waiting(), _within(timeout):
            return client_type(address, timeout=f"{timeout}s")
    except _Deadline:
        raise HarnessError("--executor", f"cannot reach the Dask scheduler {address}: it answered the handshake but "
                           f"Dask did not connect within {timeout:g} s") from None
    except Exception as err:  # noqa: BLE001 - whatever Dask raises on connecting is the peer's doing
        reason = str(err) if isinstance(err, OSError) else f"{type(err).__name__}: {err}"
        raise HarnessError("--executor", f"cannot reach the Dask scheduler {address}: {reason[:300]}") from None


class _NotDask(Exception):
    """The peer's answer is not Dask's handshake; the message says what came instead."""


def check_scheduler(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """A one-line HarnessError at ``--executor`` unless the peer at ``address`` (``tcp://HOST:PORT``) accepts a
    connection and answers Dask's handshake within ``timeout`` seconds.

    It is read with a plain socket, at most :data:`HANDSHAKE_LIMIT` bytes, and decoded with msgpack alone (no
    pickle), because Dask trusts its peer: it reads a message's length from its first 8 bytes and allocates that
    much (3 EiB for an HTTP server's answer), and waits for the handshake without a time limit. Like Dask's client,
    it writes its own handshake first and then reads the scheduler's: 8 bytes of length, then the frame count and
    each frame's length (8 bytes each, native order, as Dask's ``struct.pack("Q", ...)``), then the frames, the
    first a msgpack map with ``compression``, ``python`` and ``pickle-protocol``."""
    host, port = _host_port(address)
    expected = "expected a Dask scheduler's handshake"
    deadline = time.monotonic() + timeout
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except TimeoutError:
        raise HarnessError("--executor", f"cannot reach the Dask scheduler {address}: no connection within "
                           f"{timeout:g} s") from None
    except OSError as err:
        raise HarnessError("--executor", f"cannot reach the Dask scheduler {address}: {err.strerror or err}") \
            from None
    received = bytearray()
    try:
        with sock:
            sock.sendall(_dask_message(_HANDSHAKE))
            _read_handshake(sock, received, deadline)
    except _NotDask as err:
        raise HarnessError("--executor", f"{address} {err}; {expected}") from None
    except TimeoutError:
        said = f"sent only {short(bytes(received[:40]))}" if received else "sent nothing"
        raise HarnessError("--executor", f"{address} {said} within {timeout:g} s; {expected}") from None
    except OSError as err:  # reset by the peer
        raise HarnessError("--executor", f"{address} closed the connection {_so_far(received)} "
                           f"({err.strerror or err}); {expected}") from None


#: this side's handshake, as Dask's ``Comm.handshake_info`` (no compression: the connection only says hello)
_HANDSHAKE = {"compression": None, "python": tuple(sys.version_info[:3]), "pickle-protocol": pickle.HIGHEST_PROTOCOL}
_HANDSHAKE_KEYS = ("compression", "python", "pickle-protocol")


def _dask_message(message: dict) -> bytes:
    """``message`` as Dask writes it on TCP: total length, frame count, frame length, the msgpack frame."""
    frame = msgpack.packb(message, use_bin_type=True)
    body = struct.pack("=QQ", 1, len(frame)) + frame
    return struct.pack("=Q", len(body)) + body


def _read_handshake(sock: socket.socket, received: bytearray, deadline: float) -> None:
    """Read and check the peer's handshake into ``received``; raise ``_NotDask`` saying what came instead."""
    _read(sock, received, 8, deadline)
    (total,) = struct.unpack("=Q", received[:8])
    if not 16 <= total <= HANDSHAKE_LIMIT - 8:
        sock.settimeout(0.0)
        try:
            received += sock.recv(32)  # what is already there, for the message
        except OSError:
            pass
        raise _NotDask(f"answered {short(bytes(received[:40]))}, whose first 8 bytes claim a message of {total} "
                       f"bytes (a handshake has 16 to {HANDSHAKE_LIMIT - 8})")
    _read(sock, received, 8 + total, deadline)
    body = bytes(received[8:])
    (count,) = struct.unpack_from("=Q", body)
    if not 1 <= count <= (total - 8) // 8:
        raise _NotDask(f"answered {short(body[:40])}: {count} frames in a message of {total} bytes")
    lengths = struct.unpack_from(f"={count}Q", body, 8)
    start = 8 + 8 * count
    if start + sum(lengths) != total:
        raise _NotDask(f"answered a message of {total} bytes whose frame lengths add up to {start + sum(lengths)}")
    try:
        message = msgpack.unpackb(body[start:start + lengths[0]], raw=False)
    except (ValueError, msgpack.UnpackException) as err:
        raise _NotDask(f"answered {short(body[start:start + 40])}, which is not msgpack ({err})") from None
    if not isinstance(message, dict) or not all(key in message for key in _HANDSHAKE_KEYS):
        got = f"a map of {short(list(message), 120)}" if isinstance(message, dict) else type(message).__name__
        raise _NotDask(f"answered msgpack ({got}), not a handshake (a map of {', '.join(_HANDSHAKE_KEYS)})")


def _read(sock: socket.socket, received: bytearray, count: int, deadline: float) -> None:
    """Read from ``sock`` into ``received`` until it holds ``count`` bytes; TimeoutError past ``deadline``,
    ``_NotDask`` where the peer closes the connection first."""
    while len(received) < count:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError
        sock.settimeout(left)
        chunk = sock.recv(count - len(received))
        if not chunk:
            raise _NotDask(f"closed the connection {_so_far(received)}")
        received += chunk


def _so_far(received: bytearray) -> str:
    """What a peer that closed the connection had sent, for the message."""
    return f"after sending {short(bytes(received[:40]))}" if received else "before sending anything"


def _host_port(address: str) -> tuple[str, int]:
    """(host, port) of ``tcp://HOST:PORT`` (an IPv6 host in brackets: without them)."""
    host, _, port = address.removeprefix("tcp://").rpartition(":")
    return host.removeprefix("[").removesuffix("]"), int(port)


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

