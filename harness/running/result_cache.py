"""The results cache of ``harness run``: a case's outcome (its record in results.json and every file the case stage
wrote in its folder) kept under a key that is a hash of everything that determines it, so that a run in which
nothing changed answers from the cache instead of rendering (docs/suites.md, "The results cache").

The key of a case (:meth:`CaseCache.key`) is a SHA-256 over

* the case as loaded (every key but ``timeout``: name, scene path, renderer, settings, budget, seed, expect,
  against, film, max_depth, metrics, thresholds, tile, alpha, ground_truth_spp, variant);
* the scene it renders and the scene of its ground truth, after the case's overrides, by their content keys
  (:func:`harness.renderers.groundtruth.scene_digest`: every field of the loaded scene and the bytes of every file
  the loader read);
* for a Mitsuba ground truth (or a Mitsuba test render, which goes through the same cache) the ground-truth
  entry's key and the SHA-256 of the estimate it holds: Mitsuba is not always bit-reproducible
  (docs/robustness.md), so the key names the very image the case was judged against; no entry yet, no key;
* :func:`code_digest`: every file of ``harness/`` and ``reference_impl/`` (paths sorted, names and bytes);
* :func:`environment`: Python, the versions of numpy, numba, llvmlite, embreex (and its libembree4), Mitsuba,
  Dr.Jit, OpenEXR, imageio, Pillow, SciPy, flip-evaluator, matplotlib, the machine (``platform.machine()``, the
  C library, the CPU model and a hash of its feature flags) and the ``NUMBA_*`` variables: bits may depend on
  libm, the compiler and the CPU.

The reference renderer is deterministic (the same seed and settings give the same bits whatever the batch or the
thread count; tests/reference_impl/test_image_checksums.py), so a hit is exactly what a fresh run would give but
the timings, which are the run's that rendered it (``"cached": {"from": <its started time>, "key": ...}``).
Never cached (:func:`not_cacheable`): a time budget (how many samples fit in the seconds is not deterministic), an
external renderer, or one judged against an external renderer (its program can change under the harness, which
cannot digest it), a Mitsuba render outside the ground-truth cache (not bit-reproducible), and any case that
ended in an error (a timeout or a missing library may be passing).

Entries live in ``<cache-dir>/results/`` (:class:`harness.files.entries.EntryStore`: atomic, checked on every
read; a damaged entry is a miss). ``harness run --fresh`` renders every case again and replaces the entries;
``--no-cache`` (or ``HARNESS_RESULTS_CACHE=off``) neither reads nor writes them.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import json
import os
import platform
import sys
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import reference_impl

from harness.core import jsonsafe
from harness.core.errors import HarnessError
from harness.core.options import switched_off
from harness.files import imageio
from harness.files.entries import EntryStore
from harness.renderers import groundtruth
from harness.running import judge
from harness.running.cases import Case

FORMAT = 1
#: ``HARNESS_RESULTS_CACHE=off`` (or 0, no, false): no results cache, as with ``harness run --no-cache``
ENV = "HARNESS_RESULTS_CACHE"
FOLDER = "results"  # under the cache folder, beside groundtruth/
#: the renderers whose code the key digests (the others are programs the harness cannot see into)
DIGESTED_RENDERERS = ("reference", "mitsuba")
#: modes: "use" (read and write), "refresh" (render everything, write over the entries), "off"
MODES = ("use", "refresh", "off")
DISTRIBUTIONS = ("numpy", "numba", "llvmlite", "embreex", "mitsuba", "drjit", "OpenEXR", "imageio", "pillow",
                 "scipy", "flip-evaluator", "matplotlib")
#: record fields that are this run's, not the outcome's
RUN_FIELDS = ("wall_seconds", "definition", "resumed", "cached", "cache_key")


def mode(*, fresh: bool = False, no_cache: bool = False) -> str:
    """The cache mode of a run: "off" with ``no_cache`` or ``$HARNESS_RESULTS_CACHE=off``, "refresh" when
    ``fresh``, else "use"."""
    if no_cache or switched_off(ENV):
        return "off"
    return "refresh" if fresh else "use"


def store_for(cache_dir=None) -> EntryStore:
    """The entries under ``<cache_dir>/results`` (default: the ground-truth cache's folder)."""
    root = Path(cache_dir) if cache_dir is not None else groundtruth.default_cache_dir()
    return EntryStore(root / FOLDER)


def key_of(fields: dict) -> str:
    """SHA-256 of ``fields`` as sorted JSON (values that are not JSON, e.g. paths, as strings)."""
    return hashlib.sha256(json.dumps(fields, sort_keys=True, default=str).encode()).hexdigest()


# ---- what the code and the machine are -------------------------------------------------------------------------


def _package_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.is_file() and "__pycache__" not in p.relative_to(root).parts
                  and p.suffix not in (".pyc", ".pyo"))


@functools.cache
def code_digest() -> str:
    """SHA-256 over every file of the ``harness`` and ``reference_impl`` packages (sorted relative paths, each
    name with the SHA-256 of its bytes; ``__pycache__`` left out): any edit of the code is another key."""
    h = hashlib.sha256()
    for name, root in (("harness", Path(__file__).resolve().parents[1]),
                       ("reference_impl", Path(reference_impl.__file__).resolve().parent)):
        for path in _package_files(root):
            h.update(f"{name}/{path.relative_to(root).as_posix()}\0".encode())
            h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()


def _version(distribution: str) -> str | None:
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return None


def _cpu() -> dict:
    """The CPU's model and a SHA-256 of its feature flags, from /proc/cpuinfo (Linux), else ``platform``."""
    model, flags = None, ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                name, _, value = line.partition(":")
                name = name.strip().lower()
                if model is None and name in ("model name", "cpu model", "hardware", "cpu part"):
                    model = value.strip()
                elif not flags and name in ("flags", "features"):
                    flags = " ".join(sorted(value.split()))
                if model is not None and flags:
                    break
    except OSError:
        pass
    return {"model": model or platform.processor() or None, "flags": hashlib.sha256(flags.encode()).hexdigest()}


def _embree_library() -> str | None:
    from reference_impl import embree_c  # optional: it imports numba (a few tenths of a second), only keys need it
    try:
        return os.path.basename(embree_c.library_path())
    except ImportError:
        return None


@functools.cache
def environment() -> dict:
    """What the bits of a render or a timing may depend on beyond the code: Python, the numeric libraries'
    versions, the Embree library, the machine and CPU, the ``NUMBA_*`` variables."""
    return {
        "python": sys.version, "implementation": platform.python_implementation(),
        "packages": {name: _version(name) for name in DISTRIBUTIONS}, "embree": _embree_library(),
        "machine": platform.machine(), "system": platform.system(), "libc": list(platform.libc_ver()),
        "cpu": _cpu(), "numba_env": {k: v for k, v in sorted(os.environ.items()) if k.startswith("NUMBA_")},
    }


# ---- the cases ----------------------------------------------------------------------------------------------------


def not_cacheable(case: Case) -> str | None:
    """Why ``case``'s outcome is never cached, or None."""
    if case.seconds is not None:
        return "a time budget (the samples that fit in it vary from run to run)"
    if case.renderer not in DIGESTED_RENDERERS:
        return "an external renderer (its program can change under the harness)"
    if case.against.kind == "renderer" and case.against.renderer not in DIGESTED_RENDERERS:
        return "judged against an external renderer (its program can change under the harness)"
    if case.renderer == "mitsuba" and not set(case.settings) <= {"variant"}:
        return "a Mitsuba render outside the ground-truth cache (not bit-reproducible)"
    return None


@dataclass(frozen=True)
class CaseKey:
    key: str
    ground_truth_path: str | None  # the Mitsuba ground truth's entry (as run_case records it), else None


def snapshot(folder: Path) -> dict[str, tuple]:
    """Every file under ``folder`` (relative POSIX path: inode, mtime, size); {} where there is no folder."""
    found = {}
    root = Path(folder)
    if not root.is_dir():
        return found
    for path in root.rglob("*"):
        try:  # hidden names are the writers' temporary and staging files
            if path.is_file() and not any(p.startswith(".") for p in path.relative_to(root).parts):
                stat = path.stat()
                found[path.relative_to(root).as_posix()] = (stat.st_ino, stat.st_mtime_ns, stat.st_size)
        except OSError:
            continue
    return found


def written_since(folder: Path, before: dict[str, tuple]) -> dict[str, Path]:
    """The files under ``folder`` that are new or changed since the :func:`snapshot` ``before`` (every write of
    the harness is a rename of a new file: a new inode), by relative path."""
    return {name: Path(folder, name) for name, stat in snapshot(folder).items() if before.get(name) != stat}


def _relocated(value, old: str, new: str):
    """``value`` with every string that is the path ``old`` or lies under it moved to ``new``."""
    if isinstance(value, dict):
        return {k: _relocated(v, old, new) for k, v in value.items()}
    if isinstance(value, list):
        return [_relocated(v, old, new) for v in value]
    if isinstance(value, str) and (value == old or value.startswith(old + os.sep)):
        return new + value[len(old):]
    return value


class CaseCache:
    """The results cache of one run: ``cache_dir`` and ``variant`` as the run's cases get them, ``mode`` one of
    :data:`MODES`, ``started`` the run's start and ``machine`` its machine (:data:`harness.core.system.MACHINE_KEYS`
    of its system block), both recorded with the entries it stores and given back in a hit's ``cached``."""

    def __init__(self, cache_dir=None, variant: str | None = None, mode: str = "use", started: str = "",
                 machine: dict | None = None):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        # resolved as executors.plan resolves it for the cases, so that paths into it read as a fresh run's
        self.cache_dir = str(cache_dir if cache_dir is not None else groundtruth.default_cache_dir())
        self.variant = variant
        self.mode = mode
        self.started = started
        self.machine = machine
        self.store = store_for(self.cache_dir)

    @property
    def reads(self) -> bool:
        return self.mode == "use"

    @property
    def writes(self) -> bool:
        return self.mode != "off"

    def _entry(self, scene, spp: int, seed: int, variant: str | None) -> tuple[str, str] | None:
        """(key, estimate SHA-256) of the ground-truth entry ``run_case`` reads for these arguments; None when it
        is not cached (yet)."""
        key = groundtruth.entry_key(scene, spp=spp, seed=seed, variant=variant)
        checksum = groundtruth.entry_checksum(key, self.cache_dir)
        return None if checksum is None else (key, checksum)

    def key(self, case: Case) -> CaseKey | None:
        """The case's key (module docstring), or None: never cached, its scene or a Mitsuba library unusable (the
        case reports that itself), or its Mitsuba ground truth not in the ground-truth cache yet."""
        if not_cacheable(case) is not None:
            return None
        try:
            scene, gt_scene = judge.case_scenes(case)
            fields = {
                "format": FORMAT, "kind": "case",
                "case": {k: v for k, v in dataclasses.asdict(case).items() if k != "timeout"},
                "scene": groundtruth.scene_digest(scene), "ground_truth_scene": groundtruth.scene_digest(gt_scene),
                "code": code_digest(), "environment": environment(),
            }
            gt_path = None
            against, variant = case.against, self.variant
            need = None
            if against.kind == "mitsuba" or (against.kind == "ground-truth" and not gt_scene.closed_form):
                need = (gt_scene, case.ground_truth_spp, 0, variant)
            elif against.kind == "renderer" and against.renderer == "mitsuba":
                need = (gt_scene, against.spp, against.seed, against.settings.get("variant", variant))
            if need is not None:
                entry = self._entry(*need)
                if entry is None:
                    return None
                fields["ground_truth"] = entry
                gt_path = str(groundtruth.Cache(self.cache_dir).entry(entry[0]) / "image.exr")
            if case.renderer == "mitsuba":  # through the ground-truth cache (not_cacheable refuses the others)
                entry = self._entry(scene, case.spp, case.seed, case.settings.get("variant", variant))
                if entry is None:
                    return None
                fields["test_render"] = entry
        except (HarnessError, OSError, ValueError):  # the case itself reports what is wrong
            return None
        return CaseKey(key_of(fields), gt_path)

    def restore(self, case: Case, folder: Path) -> dict | None:
        """The case's record from the cache, its files written into ``folder`` (the case's folder of this run),
        or None on a miss (no key, no entry, a damaged one)."""
        if not self.reads:
            return None
        start = time.perf_counter()
        key = self.key(case)
        entry = self.store.load(key.key) if key is not None else None
        if entry is None:
            return None
        try:
            record = self._outcome(entry.meta, case, key, folder)
        except (TypeError, AttributeError, ValueError, KeyError):  # an entry of another shape: damaged
            record = None
        if record is None or not self._copy_out(entry, folder):
            self.store.discard(key.key)
            return None
        cached = {"from": entry.meta.get("started"), "key": key.key}
        if isinstance(entry.meta.get("machine"), dict):  # the machine that rendered it (its timings are that one's)
            cached["machine"] = entry.meta["machine"]
        record.update(cache_key=key.key, cached=cached, wall_seconds=time.perf_counter() - start)
        return record

    def _copy_out(self, entry, folder: Path) -> bool:
        """Write the entry's files into the case's ``folder`` (``OUT/cases/<slug>``) as a run writes them: staged and
        moved into place together, no link inside OUT followed (:func:`harness.files.imageio.staged_inside`);
        False when the entry is damaged (nothing written)."""
        folder = Path(folder)
        with imageio.staged_inside(folder.parents[1], Path(*folder.parts[-2:])) as stage:
            if self.store.copy_out(entry, stage.root) is None:
                return False
            stage.commit()
        return True

    @staticmethod
    def _outcome(meta: dict, case: Case, key: CaseKey, folder: Path) -> dict | None:
        """The record an entry holds, moved to this run's case folder and with what a run that renders nothing
        (every Mitsuba render in the ground-truth cache) records about its renders; None when it is not one."""
        record, old_folder = meta.get("record"), meta.get("folder")
        if not isinstance(record, dict) or record.get("name") != case.name or \
                record.get("status") not in ("pass", "fail") or not isinstance(old_folder, str):
            return None
        record = _relocated(copy.deepcopy(record), old_folder, str(folder))
        gt = record.get("ground_truth")
        if isinstance(gt, dict):
            gt["renders"] = 0  # (schedule counts the chunks of a Mitsuba test render rendered ahead here too)
            if gt.get("source") == "mitsuba":
                gt.update(cached=True, seconds=0.0, path=key.ground_truth_path)
        info = (record.get("render") or {}).get("info")
        if record.get("renderer") == "mitsuba" and isinstance(info, dict) and "mitsuba_renders" in info:
            info.update(cached=True, mitsuba_renders=0)
        return record

    def save(self, case: Case, record: dict, folder: Path, before: dict[str, tuple]) -> str | None:
        """Store the outcome of a case this run rendered (``record``; the files written in ``folder`` since the
        :func:`snapshot` ``before``); returns its key, or None when it is not cached. A write that fails is not
        an error: the run goes on without that entry."""
        if not self.writes or record.get("status") not in ("pass", "fail") or record.get("resumed"):
            return None
        key = self.key(case)  # again: the case may have put its ground truth into the cache
        if key is None:
            return None
        outcome = json.loads(jsonsafe.dumps({k: v for k, v in record.items() if k not in RUN_FIELDS}))
        meta = {"kind": "case", "case": case.name, "record": outcome, "folder": str(folder), "started": self.started}
        if self.machine is not None:
            meta["machine"] = self.machine
        self.store.store(key.key, meta, written_since(folder, before), replace=self.mode == "refresh")
        return key.key
