"""Nothing lost: resuming a suite run from its results.json, and stopping cleanly on SIGINT / SIGTERM.

Resume: every record carries ``definition``, a SHA-256 over the case as loaded (every key but ``timeout``) and the
bytes of its scene file. A later run into the same folder reuses each record of the same suite whose case has the
same name and definition and ended in pass or fail; it runs the rest (missing, changed, or ended in error).

Signals: inside ``interruptible()`` SIGINT and SIGTERM raise ``Interrupted`` at the run's next safe point: at
once while the run waits for worker processes (``waiting()``), else after the task in progress in this process
(``check()``; a second signal raises at once), never inside ``no_interrupts()`` (writing results.json). results.json
is written by an atomic rename anyway, and the ground-truth cache only ever renames finished entries into place, so
an interrupted run leaves both valid.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import signal
from pathlib import Path

from harness.results import read_results

_pending: list[int] = []  # signals received and not raised yet
_critical = 0  # depth of no_interrupts() blocks
_waiting = 0  # depth of waiting() blocks


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived; ``exit_code`` is 128 + the signal number (130, 143)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
        self.exit_code = 128 + signum


def _handler(signum, _frame) -> None:
    _pending.append(signum)
    # Raise now only where that is safe (waiting for workers) or when asked twice; elsewhere (inside an import of
    # a native extension, say: Mitsuba cannot be imported again after a half-done import) at the next check().
    if not _critical and (_waiting or len(_pending) > 1):
        raise Interrupted(signum)


def requested() -> bool:
    """A signal arrived and has not been raised yet."""
    return bool(_pending)


def check() -> None:
    """Raise ``Interrupted`` for a signal that arrived (outside no_interrupts()); a safe point of the run."""
    if _pending and not _critical:
        raise Interrupted(_pending[0])


@contextlib.contextmanager
def interruptible():
    """Within, SIGINT and SIGTERM stop the run: at once inside waiting(), else at the next check() (or at a second
    signal). Main thread only; the previous handlers come back after."""
    previous = {s: signal.signal(s, _handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        _pending.clear()


@contextlib.contextmanager
def waiting():
    """A block that only waits (for worker processes): a signal raises within it at once."""
    global _waiting
    check()
    _waiting += 1
    try:
        yield
    finally:
        _waiting -= 1


@contextlib.contextmanager
def no_interrupts():
    """A signal that arrives within is raised when the block ends, so the block always completes."""
    global _critical
    _critical += 1
    try:
        yield
    finally:
        _critical -= 1
        check()


def case_digest(case) -> str:
    """SHA-256 of what a case's result depends on: its definition (but ``timeout``) and its scene file's bytes."""
    fields = {k: v for k, v in dataclasses.asdict(case).items() if k != "timeout"}
    h = hashlib.sha256(json.dumps(fields, sort_keys=True, default=str).encode())
    try:
        h.update(Path(case.scene).read_bytes())
    except OSError:
        pass  # the case itself reports the unreadable scene
    return h.hexdigest()


def reusable(results_path: Path, suite_name: str, cases, digests: list[str]) -> dict[int, dict]:
    """The records of a previous run at ``results_path`` that this run can keep, by case index: none when there is
    no results.json or it is another suite's. A results.json that is not one (corrupt, edited, another tool's) is a
    one-line HarnessError naming its JSON path, before anything runs: ``--fresh`` ignores it."""
    if not Path(results_path).exists():
        return {}
    previous = read_results(results_path, hint="harness run --fresh ignores it and runs every case")
    if previous["suite"] != suite_name:
        return {}
    by_name = {r["name"]: r for r in previous["cases"]}
    kept = {}
    for index, (case, digest) in enumerate(zip(cases, digests)):
        record = by_name.get(case.name)
        if record and record.get("definition") == digest and record.get("status") in ("pass", "fail"):
            kept[index] = dict(record, resumed=True)
    return kept
