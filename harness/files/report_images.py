"""A case's report images: made once, when ``harness run`` judges the case, and formatted by the report.

The images are the ground truth and the render, tone-mapped at one exposure (the ground truth's
:func:`~harness.files.previews.display_exposure`), and three maps of the render against the ground truth (signed
error, relative error, FLIP: :func:`~harness.files.previews.error_images`), each as EXR + sRGB PNG in
``OUT/cases/<case>/images/``; with them the numbers the report shows beside them (``error_maps``: the MSE, the ground
truth's noise floor and their difference, :func:`harness.judges.floor.error_point`, and the maps' means).

:func:`make_report_images` makes them (the run; the report too, for a results.json of an older harness that has
none), :meth:`ReportImages.record` describes them for the case's record in results.json (``report_images``,
docs/results-schema.md), :func:`read_report_images` reads that description back with the files it names, and
:meth:`ReportImages.placed` links (or copies) the files into a report's own folder.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.files import imageio
from harness.files.confined import EXR_MAGIC, Refused, copy_inside, inside, outside_note, read_inside
from harness.files.cases import slug
from harness.files.previews import ImageWriter, ReportImage, display_exposure, error_images
from harness.judges.floor import error_point

__all__ = ["IMAGES_FOLDER", "KEYS", "ReportImages", "make_report_images", "read_report_images"]

#: the folder of a case's report images, in its case folder (``OUT/cases/<case>/images``)
IMAGES_FOLDER = "images"
#: the images, in the order the report shows them
KEYS = ("ground_truth", "render", "error_signed", "error_relative", "flip")
#: the numbers of ``error_maps``
ERROR_MAP_KEYS = ("mse", "floor_mse", "mse_corrected", "mean_signed_error", "mean_relative_error", "flip_map_mean")
#: the largest PNG read back into a page (a film at the harness's limits is far smaller)
_MAX_PNG_BYTES = 64 * 2**20


@dataclass
class ReportImages:
    """A case's report images (``images``, in :data:`KEYS` order, their PNG bytes kept for embedding), the folder
    that holds their files, and ``error_maps`` (:data:`ERROR_MAP_KEYS`; None where not finite)."""

    folder: Path
    images: list[ReportImage]
    error_maps: dict
    root: Path | None = None  # the run folder the files were read in (read back: :func:`read_report_images`)

    def record(self) -> dict:
        """The description results.json keeps in the case's record (``report_images``): the folder as written, the
        numbers, and each image as report.json shows it, with its files' names in the folder."""
        return {"folder": str(self.folder), "error_maps": dict(self.error_maps),
                "images": [dict(im.to_json(), exr=im.exr.name, png=im.png_path.name) for im in self.images]}

    def placed(self, folder: Path) -> ReportImages:
        """These images in ``folder`` (a report's ``report/<case>``): each file copied, read again inside the run
        folder (``root``) and checked as an OpenEXR file or PNG (:func:`harness.files.confined.copy_inside`); never
        a hard link (the report's files are its own); nothing is encoded again."""
        if self.root is None:
            raise ValueError("report images without their run folder; read_report_images reads them")
        imageio.make_folders(folder)
        moved = []
        for im in self.images:
            exr = copy_inside(self.root, im.exr, folder / im.exr.name, kind="exr")
            png = copy_inside(self.root, im.png_path, folder / im.png_path.name, kind="png", data=im.png)
            moved.append(dataclasses.replace(im, exr=exr, png_path=png))
        return ReportImages(Path(folder), moved, dict(self.error_maps))


def make_report_images(folder: Path, *, case: str, renderer: str, spp: int, render: np.ndarray,
                       render_variance: np.ndarray | None, truth: np.ndarray, truth_variance: np.ndarray,
                       truth_source: str, truth_spp: int, flip: tuple[float, np.ndarray] | None = None
                       ) -> ReportImages:
    """Write a case's report images into ``folder`` and return them. ``render``, ``truth`` (the ground truth) and
    their variances are the images as their EXRs hold them (float32); ``truth_source``, ``truth_spp``, ``renderer``
    and ``spp`` go into the descriptions; ``flip``: ``metrics.flip(render, truth, full=True)`` where the caller has
    it (the case's comparison computes it), else it is computed here.

    ``error_maps``: ``mse``, ``floor_mse``, ``mse_corrected`` (:func:`harness.judges.floor.error_point`: the MSE,
    the mean of the ground truth's variance, their difference) and the means of the three maps over their finite
    pixels (``mean_relative_error`` is the case's MAPE)."""
    writer = ImageWriter(folder, {"case": case})
    exposure = display_exposure(truth)
    images = [
        writer.radiance("ground_truth", "Ground truth", truth, truth_variance,
                        description=f"{truth_source}" + (f", {truth_spp} spp" if truth_spp else ""),
                        exposure=exposure),
        writer.radiance("render", "Render", render, render_variance, description=f"{renderer}, {spp} spp",
                        exposure=exposure),
    ]
    images.extend(error_images(writer, render, truth, flip))
    point = error_point(render, truth, truth_variance)
    by_key = {im.key: im for im in images}
    error_maps = {
        "mse": point["mse"], "floor_mse": point["floor_mse"], "mse_corrected": point["mse_corrected"],
        "mean_signed_error": by_key["error_signed"].stats.get("mean"),
        "mean_relative_error": by_key["error_relative"].stats.get("mean"),
        "flip_map_mean": by_key["flip"].stats.get("mean"),
    }
    return ReportImages(Path(folder), images, error_maps)


def read_report_images(record: dict, results_dir: Path, notes: list[str] | None = None) -> ReportImages | None:
    """The report images a case's record describes (``report_images``), their PNGs read; None where it describes
    none (a run by an older harness, a case that ended in an error) or a file it names is missing or not the kind
    its name says (the report then makes them again from the case's EXRs, :func:`make_report_images`).

    The folder is looked for where the record says (as ``harness run`` was given it), then in
    ``results_dir/cases/<case>/images`` (a results folder that moved); only inside the run folder ``results_dir``
    (:mod:`harness.files.confined`: a folder elsewhere, a file that is not an OpenEXR file or PNG, is not read, and
    ``notes`` says so). The record's file names are names, never paths (the schema checks it; checked here too, for
    records given as a dict)."""
    entry = record.get("report_images")
    if record.get("status") in ("error", "skipped") or not isinstance(entry, dict):
        return None
    specs = entry.get("images")
    if not isinstance(specs, list) or [s.get("key") if isinstance(s, dict) else None for s in specs] != list(KEYS):
        return None
    if not all(_is_name(s.get("exr"), ".exr") and _is_name(s.get("png"), ".png") for s in specs):
        return None
    error_maps = entry.get("error_maps")
    if not isinstance(error_maps, dict):
        return None
    candidates = [entry.get("folder"), Path(results_dir) / "cases" / slug(str(record.get("name", ""))) / IMAGES_FOLDER]
    for candidate in candidates:
        if not isinstance(candidate, (str, Path)) or not str(candidate):
            continue
        note = outside_note("report_images.folder", candidate, results_dir)
        if note is not None or inside(results_dir, candidate) is None:  # a note where something is there
            _note(notes, note)
            continue
        folder = Path(candidate)
        images = _read_images(folder, specs, Path(results_dir), notes)
        if images is not None:
            return ReportImages(folder, images, {k: error_maps.get(k) for k in ERROR_MAP_KEYS}, Path(results_dir))
    return None


def _note(notes: list[str] | None, note: str | None) -> None:
    if notes is not None and note is not None and note not in notes:
        notes.append(note)


def _is_name(value, suffix: str) -> bool:
    """A plain file name ending in ``suffix``: no folder, not hidden."""
    return (isinstance(value, str) and value.endswith(suffix) and not value.startswith(".") and "/" not in value
            and "\\" not in value and "\0" not in value)


def _read_images(folder: Path, specs: list[dict], root: Path, notes: list[str] | None) -> list[ReportImage] | None:
    """The images ``specs`` names in ``folder``, their PNGs read, inside the run folder ``root``; None if a file is
    missing or not an OpenEXR file / PNG (a note, but for a missing file)."""
    images = []
    for spec in specs:
        exr, png = folder / spec["exr"], folder / spec["png"]
        try:
            read_inside(root, exr, kind="exr", head=len(EXR_MAGIC))  # read whole (and checked again) by placed()
        except Refused as why:
            return _refused(notes, exr, why)
        try:
            data = read_inside(root, png, kind="png", limit=_MAX_PNG_BYTES)
        except Refused as why:
            return _refused(notes, png, why)
        legend = spec.get("legend")
        stats = spec.get("stats")
        images.append(ReportImage(str(spec["key"]), str(spec.get("title") or spec["key"]), data, exr, png,
                                  str(spec.get("description") or ""), legend if isinstance(legend, dict) else None,
                                  stats if isinstance(stats, dict) else {}))
    return images


def _refused(notes: list[str] | None, path: Path, why: Refused) -> None:
    """A note for a report image not used, but where it is simply missing (made again from the case's EXRs)."""
    if str(why) != "not found":
        _note(notes, f"report image {str(path)!r}: {why}: not used")
