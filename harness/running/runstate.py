"""Nothing lost: resuming a suite run from its results.json, and stopping cleanly on SIGINT / SIGTERM.

Resume: every record carries ``definition``, a SHA-256 over the case as loaded (every key but ``timeout``) and the
bytes of its scene file. A later run into the same folder reuses each record of the same suite whose case has the
same name and definition and ended in pass or fail; it runs the rest (missing, changed, or ended in error).

Signals: inside ``interruptible()`` SIGINT and SIGTERM raise ``Interrupted`` at the run's next safe point: at
once while the run waits for worker processes (``waiting()``), else after the task in progress in this process
(``check()``; a second signal raises at once), never inside ``no_interrupts()`` (writing results.json). results.json
is written by an atomic rename anyway, and the ground-truth cache only ever renames finished entries into place, so
an interrupted run leaves both valid.

Output folders: :func:`output_folder` checks an ``--out`` before anything runs (not empty, created, a real file
written and removed in it), :func:`refuse_links` names a symbolic link planted where the run writes inside it, and
:func:`locked` holds ``OUT/.lock`` (``fcntl.flock``, exclusive) for a run, so a second run into the same folder
stops at once with one line naming the process that holds it. The kernel drops the lock when its process dies, so
a lock file left by a killed run blocks nothing; the lock file is opened without following a link, and anything at
``OUT/.lock`` that is not a lock file is refused, never written through or removed. :func:`cache_folder` checks
the cache folder (``--cache-dir``, ``$HARNESS_CACHE_DIR``) the same way before the first render, and sweeps the
private folders killed writers left in it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import hashlib
import json
import os
import signal
import stat
import tempfile
from pathlib import Path

from harness.core.errors import HarnessError, file_kind
from harness.core.options import path_problem
from harness.core.text import short
from harness.files.cases import cache_entry_image, slug
from harness.files.confined import inside
from harness.files.entries import sweep_stale, use_cache_folder
from harness.files.imageio import link_target, make_folders, remove_folders
from harness.files.report_images import IMAGES_FOLDER
from harness.files.results import read_results
from harness.scene.content_key import content_key

_pending: list[int] = []  # signals received and not raised yet
_critical = 0  # depth of no_interrupts() blocks
_waiting = 0  # depth of waiting() blocks
LOCK_NAME = ".lock"
_locks: dict[str, list[int]] = {}  # real path of a folder this process has locked: [file descriptor, depth]


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


def case_digest(case, case_scenes) -> str:
    """SHA-256 of what a case's result depends on: its definition (but ``timeout``) and the content keys
    (:func:`harness.scene.content_key.content_key`: every field, the bytes of every file the loader read) of the
    scenes ``case_scenes(case)`` gives, the one it renders and the one of its ground truth. A case whose scenes do
    not load has its definition alone: it reports why when it runs, and a case that ended in an error is never kept."""
    fields = {k: v for k, v in dataclasses.asdict(case).items() if k != "timeout"}
    try:
        render_scene, gt_scene = case_scenes(case)
        key = content_key(render_scene)  # most cases judge against the very scene they render: keyed once
        fields["scenes"] = [key, key if gt_scene is render_scene else content_key(gt_scene)]
    except (HarnessError, OSError, ValueError):
        fields["scenes"] = None
    return hashlib.sha256(json.dumps(fields, sort_keys=True, default=str).encode()).hexdigest()


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
        if (record and record.get("definition") == digest and record.get("status") in ("pass", "fail")
                and stays_inside(record, Path(results_path).parent)):
            kept[index] = dict(record, resumed=True)
    return kept


def recorded_paths(record: dict) -> list:
    """The paths a case record names (its render, verdict maps, report images' and viewer's folders), as found:
    anything results.json holds there, for :func:`stays_inside` to judge. The ground truth is apart (it may be a
    cache entry)."""
    def get(*keys):
        value = record
        for key in keys:
            value = value.get(key) if isinstance(value, dict) else None
        return value
    return [get("render", "exr"), get("verdict_maps", "pvalue"), get("verdict_maps", "failing"),
            get("report_images", "folder"), get("viewer", "folder")]


def stays_inside(record: dict, out_dir: Path) -> bool:
    """Every path a record names lies inside the run folder ``out_dir`` after symlinks (its ground truth: there or
    a ground-truth cache entry's image), so that a results.json planted in ``--out`` cannot make the run keep a
    record whose files the report would then look for elsewhere: such a record is not resumed (its case runs
    again)."""
    named = [p for p in recorded_paths(record) if p is not None]
    if not all(isinstance(p, str) and p and "\0" not in p and inside(out_dir, p) is not None for p in named):
        return False
    truth = (record.get("ground_truth") or {}).get("path")
    return (truth is None or (isinstance(truth, str) and "\0" not in truth and truth != ""
                              and (inside(out_dir, truth) is not None or cache_entry_image(truth) is not None)))


# ---- output folders ----------------------------------------------------------------------------------------------


def output_folder(value: str | None, default: Path, option: str = "--out", subfolders: tuple[str, ...] = ("cases",),
                  created: list[Path] | None = None) -> Path:
    """The output folder an option names (``default`` when it is not given), created and found writable by a
    real write (root ignores permission bits; /proc refuses everyone), or a one-line HarnessError at ``option``;
    so are those of ``subfolders`` that exist (``cases``: each case's render). An empty value is refused rather
    than read as "not given". The folders made for it are added to ``created`` (for
    :func:`harness.files.imageio.removed_on_failure`); a folder that fails the checks is not left behind."""
    if value is not None and not value.strip():
        raise HarnessError(option, "expected a folder path, got an empty string")
    folder = Path(value) if value is not None else default
    made = make_folders(folder, option)
    try:
        probe_writable(folder, option)
        for name in subfolders:
            sub = folder / name
            if sub.is_symlink():  # not even probed: the probe would write through it
                raise HarnessError(option, f"{str(sub)!r} {_link_refused(sub)}")
            if sub.exists():
                if not sub.is_dir():
                    raise HarnessError(option, f"{str(sub)!r} is not a folder; expected a folder the run writes in")
                probe_writable(sub, option)
    except HarnessError:
        remove_folders(made)
        raise
    if created is not None:
        created.extend(made)
    return folder


def _link_refused(path: Path) -> str:
    """What is said of a symbolic link where the run would write (``--out``'s folders)."""
    return (f"is a symbolic link (to {link_target(path)!r}); the run writes only inside its output folder and "
            "follows no link there: remove it")


def refuse_links(folder: Path, cases) -> None:
    """A one-line HarnessError naming the first symbolic link found where a run writes inside ``folder`` (its
    ``cases/``, each of ``cases``' folder and its ``images/``, ``studies/``), before anything runs: a link planted
    there would carry the run's files outside its folder. (The writers follow no link there either:
    :func:`harness.files.imageio.make_real_folders`; this names the link before the first render.)"""
    names = ["cases"]
    for case in cases:
        names += [f"cases/{slug(case.name)}", f"cases/{slug(case.name)}/{IMAGES_FOLDER}"]
    for name in [*names, "studies"]:
        path = Path(folder) / name
        if path.is_symlink():
            raise HarnessError(str(path), _link_refused(path))


CACHE_ENV = "HARNESS_CACHE_DIR"
#: the caches under a cache folder: Mitsuba ground truths (harness/renderers/groundtruth.py), run results
CACHE_SUBFOLDERS = ("groundtruth", "results")


def cache_folder(value: str | None, default: Path, created: list[Path] | None = None) -> Path:
    """The cache folder of a command: ``value`` (``--cache-dir``) if given, else ``default`` (``$HARNESS_CACHE_DIR``
    or the user cache folder, :func:`harness.renderers.groundtruth.default_cache_dir`), checked before anything
    renders as :func:`output_folder` checks ``--out`` (a path the file system takes, created, a real file written
    and removed in it and in those of :data:`CACHE_SUBFOLDERS` that exist), or a one-line HarnessError naming
    ``--cache-dir`` or ``HARNESS_CACHE_DIR``. The folders made for it are added to ``created`` (for
    :func:`harness.files.imageio.removed_on_failure`). The private folders that killed writers left in its caches
    are removed (:func:`harness.files.entries.sweep_stale`)."""
    if value is not None:
        where, text = "--cache-dir", value
    elif os.environ.get(CACHE_ENV):
        where, text = CACHE_ENV, os.environ[CACHE_ENV]
    else:
        where, text = "cache folder (the default; choose one with --cache-dir or HARNESS_CACHE_DIR)", str(default)
    problem = path_problem(text) if text.strip() else None
    if problem:
        raise HarnessError(where, f"expected a folder path, got {short(text)}: {problem}")
    folder = output_folder(text, Path(text), option=where, subfolders=CACHE_SUBFOLDERS, created=created)
    for name in CACHE_SUBFOLDERS:
        sweep_stale(folder / name)
    use_cache_folder(folder)  # its ground truths may be named by this run's records (files.cases.cache_entry_image)
    return folder


def probe_writable(folder: Path, option: str) -> None:
    """Create and remove a file in ``folder``, as an atomic write will (a temporary file renamed into place)."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".write-probe-"):
            pass
    except OSError as err:
        raise HarnessError(option, f"cannot write in the folder {str(folder)!r}: {err.strerror or err}") from None


@contextlib.contextmanager
def locked(folder: Path, option: str = "--out"):
    """Hold ``folder/.lock`` (exclusive ``flock``, the holder's pid written in it) within the block; another
    process's lock is a one-line HarnessError at ``option`` naming its pid. Re-entrant within one process. The
    file is removed when the block ends (while still locked, so a run waiting on it sees that and takes a new one)."""
    key = os.path.realpath(folder)
    if key in _locks:
        _locks[key][1] += 1
        try:
            yield
        finally:
            _locks[key][1] -= 1
        return
    path = Path(folder) / LOCK_NAME
    fd = _acquire(path, option)
    _locks[key] = [fd, 1]
    try:
        yield
    finally:
        del _locks[key]
        try:
            if _same_file(fd, path):
                path.unlink()
        except OSError:
            pass  # a lock file left behind blocks nothing: the lock goes with the descriptor
        os.close(fd)


def _acquire(path: Path, option: str) -> int:
    """An open descriptor of ``path`` locked by this process, with this process's pid written in it. ``path`` is
    opened without following a symbolic link, and anything there that is not a lock file (a link, a folder, a
    device, a file with a second name: writing the pid would truncate what it names) is a one-line HarnessError at
    ``option``: it is neither written through nor removed."""
    while True:
        _refuse_odd_lock(path, option, _lstat(path))
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
        except OSError as err:
            if err.errno == errno.ELOOP:  # a link planted since the look above
                _refuse_odd_lock(path, option, _lstat(path))
            raise HarnessError(option, f"cannot create the lock file {str(path)!r}: {err.strerror or err}") from None
        try:
            _refuse_odd_lock(path, option, os.fstat(fd))
        except HarnessError:
            os.close(fd)
            raise
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            holder = _holder(fd)
            os.close(fd)
            if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN):
                raise HarnessError(option, f"{str(path.parent)!r} is in use by another harness run ({holder}, "
                                   f"holding {LOCK_NAME}); wait for it to end or choose another folder") from None
            raise HarnessError(option, f"cannot lock {str(path)!r}: {err.strerror or err}") from None
        if _same_file(fd, path):
            break
        os.close(fd)  # its holder removed it while we waited for the lock: lock the file there now
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return fd


def _refuse_odd_lock(path: Path, option: str, found: os.stat_result | None) -> None:
    """A one-line HarnessError at ``option`` when ``found`` (what is at ``path``: its lstat, or the opened file's
    fstat; None: nothing there) is not a lock file the harness could have made: a regular file with one name (or
    none left: its holder removed it as the run ended, and the caller looks again)."""
    if found is None or (stat.S_ISREG(found.st_mode) and found.st_nlink <= 1):
        return
    if stat.S_ISLNK(found.st_mode):
        what = f"a symbolic link (to {link_target(path)!r})"
    elif stat.S_ISREG(found.st_mode):
        what = f"a file with {found.st_nlink} names (a hard link)"
    else:
        what = f"not a regular file ({file_kind(found.st_mode)})"
    raise HarnessError(option, f"{str(path)!r} is {what}, not a lock file of the harness; nothing is written "
                       "through it: remove it")


def _lstat(path: Path) -> os.stat_result | None:
    """What is at ``path`` itself (a link, not what it names), or None when nothing is."""
    try:
        return os.stat(path, follow_symlinks=False)
    except OSError:
        return None


def _same_file(fd: int, path: Path) -> bool:
    """Whether ``path`` itself (not what a link there names) is the file open at ``fd``."""
    try:
        here, there = os.fstat(fd), os.stat(path, follow_symlinks=False)
    except OSError:
        return False
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


def _holder(fd: int) -> str:
    """"process 1234" as the lock file says, or what is known."""
    try:
        text = os.pread(fd, 64, 0).decode("ascii", "replace").strip()
    except OSError:
        text = ""
    return f"process {int(text)}" if text.isdigit() else "a process that has not written its pid yet"
