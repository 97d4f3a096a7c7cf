"""The files of a finished run's cases, read back from what ``results.json`` names: a case's folder name
(:func:`slug`), its render and the ground truth it was judged against (:func:`read_case_images`). Used by the
report and the studies, which render nothing to show a case: the ground truth is the file the run recorded
(``ground_truth.path``: the cache entry, or ``OUT/cases/<case>/ground_truth.exr`` for a closed form or another
renderer's image)."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError
from harness.files.confined import inside, outside_note
from harness.files.entries import cache_folders
from harness.files.imageio import read_exr

#: the name of a case's ground-truth file in its folder, where the ground truth is not a cache entry
GROUND_TRUTH_FILE = "ground_truth.exr"


def slug(name: str) -> str:
    """The folder name of a case (``OUT/cases/<slug>``): each run of characters other than A-Z a-z 0-9 . _ -
    replaced by _, leading and trailing _ removed; "case" where nothing (or only "." or "..") is left, so a slug
    never leaves its parent folder. Not injective (``a/b`` and ``a_b`` give ``a_b``): the suite loader refuses a
    suite in which two cases share a slug (ignoring case)."""
    text = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_")
    return text if text not in ("", ".", "..") else "case"


@dataclass
class GroundTruthImage:
    """The image a case was judged against, as read back: pixels, per-pixel variance (zeros where the file has
    none, e.g. a closed form), where it came from (``source``, ``spp``) and its file."""

    image: np.ndarray
    variance: np.ndarray
    source: str
    spp: int
    path: Path | None = None


@dataclass
class CaseImages:
    """A case's render and ground truth read back (None where unavailable; ``problems`` says why)."""

    render: np.ndarray | None = None
    render_variance: np.ndarray | None = None
    ground_truth: GroundTruthImage | None = None
    problems: list[str] = field(default_factory=list)


def cache_entry_image(path: Path | str | None) -> Path | None:
    """The real path of ``path`` where it is the image of a ground-truth cache entry (``<cache>/groundtruth/<key>/
    image.exr`` beside its ``meta.json``, :mod:`harness.renderers.groundtruth`) in one of this process's cache
    folders (:func:`harness.files.entries.cache_folders`: ``$HARNESS_CACHE_DIR`` or the user's, and a
    ``--cache-dir`` given): the one file a case's record may name outside its run folder; else None."""
    if not isinstance(path, (str, Path)) or not str(path) or "\0" in str(path):
        return None
    real = Path(os.path.realpath(path))
    if real.name != "image.exr" or real.parent.parent.name != "groundtruth" or not real.is_file():
        return None
    if real.parent.parent.parent not in cache_folders():
        return None
    return real if (real.parent / "meta.json").is_file() else None


def confined_file(results_dir: Path, what: str, named, default: Path, problems: list[str],
              cache_entry: bool = False) -> Path | None:
    """The file a record names (``named``), where it is one inside the run folder ``results_dir`` (or, with
    ``cache_entry``, a ground-truth cache entry's image), else ``default`` (where harness run writes it) where that
    is a file inside the run folder; None otherwise. A path named outside the run folder that exists is a problem
    of the case (not read)."""
    if cache_entry and cache_entry_image(named) is not None:
        return cache_entry_image(named)
    note = outside_note(what, named, results_dir)
    if note is not None:
        problems.append(note)
    for candidate in (named, default):
        if isinstance(candidate, (str, Path)) and str(candidate) and "\0" not in str(candidate):
            real = inside(results_dir, candidate)
            if real is not None and real.is_file():
                return real
    return None


def read_case_images(record: dict, results_dir: Path) -> CaseImages:
    """The render and ground truth of a case record of ``results_dir/results.json``; problems are noted in the
    result, never raised (an EXR that cannot be read is a problem of its case).

    Paths in results.json are as ``harness run`` was given them; a file that moved with its results folder is
    found under ``results_dir/cases/<slug>/`` (``render.exr``, ``ground_truth.exr``). Only files inside the run
    folder are read (after symlinks, :func:`harness.files.confined.inside`), and for the ground truth the image of
    a ground-truth cache entry (:func:`cache_entry_image`)."""
    out = CaseImages()
    if record.get("status") == "skipped":
        out.problems.append(f"no render: {record.get('reason') or 'the case was skipped'}")
        return out
    if record.get("status") == "error" or not record.get("render"):
        out.problems.append("no render: the case ended in an error")
        return out
    folder = Path(results_dir) / "cases" / slug(str(record.get("name", "")))
    exr_path = confined_file(results_dir, "render.exr", record["render"].get("exr"), folder / "render.exr",
                         out.problems)
    if exr_path is None:
        out.problems.append(f"render EXR not found ({record['render'].get('exr')})")
        return out
    try:
        exr = read_exr(exr_path)
    except HarnessError as err:
        out.problems.append(f"render EXR not readable: {err}")
        return out
    out.render, out.render_variance = exr.image, exr.variance
    gt = record.get("ground_truth") or {}
    gt_path = confined_file(results_dir, "ground_truth.path", gt.get("path"), folder / GROUND_TRUTH_FILE, out.problems,
                        cache_entry=True)
    if gt_path is None:
        named = gt.get("path")
        out.problems.append("ground truth unavailable: " + (f"{named} not found" if named else
                            "results.json names no ground-truth file (a run by an older harness: run the suite "
                            "again)"))
        return out
    try:
        truth = read_exr(gt_path)
    except HarnessError as err:
        out.problems.append(f"ground truth unavailable: {err}")
        return out
    if truth.image.shape != exr.image.shape:
        out.problems.append(f"ground truth is {truth.image.shape[1]}x{truth.image.shape[0]}, render "
                            f"{exr.image.shape[1]}x{exr.image.shape[0]}")
        return out
    variance = truth.variance if truth.variance is not None else np.zeros_like(truth.image)
    out.ground_truth = GroundTruthImage(truth.image, variance, str(gt.get("source") or "ground truth"),
                                        int(gt.get("spp") or 0), gt_path)
    return out
