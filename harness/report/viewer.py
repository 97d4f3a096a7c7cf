"""The report's comparison viewer, on the Python side: the package's scripts and style that the page inlines
(``static/viewer_*.js``, ``static/viewer.css``), each case's viewer files placed into the report (made by ``harness
run``: :mod:`harness.files.viewer_data`; for a run by an older harness made here from the case's EXRs), the view
of a case's thumbnails and p-value histogram for the templates, and the same page for a pair of EXR files
(``harness view``). See docs/report.md, "The comparison viewer"."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError
from harness.files import imageio
from harness.files.cases import GroundTruthImage
from harness.files.confined import first_inside
from harness.files.previews import ReportImage, display_exposure
from harness.files.viewer_data import PVALUE_TOP, THUMBNAIL_SIDE, ViewerData, make_viewer_data, read_viewer_data
from harness.judges import metrics
from harness.judges.verdict import ImageError, TileMaps, verdict
from harness.report.html import data_uri, render, static_script, static_style

#: the viewer's scripts, in the order the page runs them (each may use those before it)
SCRIPTS = ("viewer_data.js", "viewer_tonemap.js", "viewer_colormaps.js", "viewer_maps.js", "viewer_canvas.js",
           "viewer_probe.js", "viewer_ui.js")
STYLE = "viewer.css"
#: magma at 9 evenly spaced points (matplotlib's; tests/report/test_viewer.py checks them): the p-value legend
MAGMA_STOPS = "#000004, #1d1147, #51127c, #832681, #b73779, #e75263, #fc8961, #fec488, #fcfdbf"
#: the CSS width of a case's thumbnails in the page
THUMBNAIL_WIDTH = 2 * THUMBNAIL_SIDE
#: the p-value histogram's drawing, in SVG units
HISTOGRAM_BOX = {"width": 230, "height": 96, "left": 30, "right": 222, "top": 8, "bottom": 74}


def assets() -> dict:
    """The viewer's scripts (markup for inline ``<script>`` elements, in order) and style, for the templates."""
    return {"scripts": [static_script(name) for name in SCRIPTS], "style": static_style(STYLE)}


def histogram_view(histogram: dict | None) -> dict | None:
    """The p-value histogram (:func:`harness.files.viewer_data.p_histogram`) as SVG geometry for the templates: the
    bars as one path (``bars``) but the first (p < 1/bins, ``low``), drawn apart, the level a uniform histogram would
    have (``tested / bins``), the axes' labels. One path, not a rectangle per bar: the page has a histogram per
    case, and each value a template writes is escaped."""
    if not isinstance(histogram, dict):
        return None
    counts = [c for c in histogram.get("counts") or [] if isinstance(c, int) and not isinstance(c, bool)]
    tested = histogram.get("tested")
    if not counts or not isinstance(tested, int) or tested < 1:
        return None
    box = HISTOGRAM_BOX
    expected = tested / len(counts)
    top = max(max(counts), expected * 1.5, 1)
    width = (box["right"] - box["left"]) / len(counts)
    height = box["bottom"] - box["top"]

    def y(value: float) -> float:
        return round(box["bottom"] - height * value / top, 2)

    def bar(i: int, count: int) -> str:
        left = round(box["left"] + i * width + 0.5, 2)
        return f"M{left} {box['bottom']}V{y(count)}H{round(left + width - 1, 2)}V{box['bottom']}Z"

    return {"box": box, "low": bar(0, counts[0]), "bars": "".join(bar(i, c) for i, c in enumerate(counts) if i),
            "counts": ", ".join(map(str, counts)), "expected_y": y(expected), "expected": round(expected, 1),
            "top": int(top), "tested": tested, "failing": histogram.get("failing"), "bins": len(counts),
            "near_zero": counts[0]}


def case_view(viewer: ViewerData | None, *, key: str, slot: str, link_base: str, images: list[ReportImage],
              verdict_maps: list[tuple[str, str]], autoopen: bool = False) -> dict | None:
    """A case's thumbnails, histogram, viewer button and file links, for ``case_viewer.html.j2``; None where the
    case has no viewer data (it ended in an error, or its images could not be read). ``autoopen``: the viewer
    opens when the page loads (``harness view``)."""
    if viewer is None:
        return None
    files = [(f"{im.title} {kind}", link_base + getattr(im, attr).name) for im in images
             for kind, attr in (("EXR", "exr"), ("PNG", "png_path")) if getattr(im, attr) is not None]
    files += verdict_maps
    return {"key": key, "slot": slot, "src": link_base + viewer.data.name, "thumb_uri": data_uri(viewer.thumbnail_png),
            "pvalue_uri": data_uri(viewer.pvalue_png) if viewer.pvalue_png else None, "width": THUMBNAIL_WIDTH,
            "pvalue_legend": {"stops": MAGMA_STOPS, "vmin": "p = 1", "mid": f"1e-{PVALUE_TOP / 2:g}",
                              "vmax": f"1e-{PVALUE_TOP:g}"},
            "histogram": histogram_view(viewer.histogram), "files": files, "autoopen": autoopen,
            "images": [{"title": im.title, "description": im.description} for im in images]}


# ---- a case's viewer files in the report ---------------------------------------------------------------------------


def place_case_viewer(record: dict, results_dir: Path, folder: Path, case_folder: str,
                      notes: list[str] | None = None) -> ViewerData | None:
    """The viewer files ``harness run`` made for the case (``viewer`` in its record), checked and copied into
    ``folder`` (``report/<case>``): viewer.js parsed and written again by the harness
    (:func:`harness.files.viewer_data.read_viewer_data`), nothing from the run folder shipped as a script. None where
    the record names none that are there and sound (``notes`` says why, where it is not a plain absence)."""
    stored = read_viewer_data(record, results_dir, case_folder, notes)
    return stored.placed(folder) if stored is not None else None


def place_verdict_maps(record: dict, results_dir: Path, folder: Path, case_folder: str,
                       link_base: str, notes: list[str] | None = None) -> list[tuple[str, str]]:
    """The case's ``pvalue.exr`` and ``failing.exr`` (``verdict_maps`` in its record, or beside its render in
    ``results_dir/cases/<case>``) copied into ``folder``: [(label, link from the page)]. Only an OpenEXR file inside
    the run folder is copied (:func:`harness.files.confined.first_inside`); a path outside it is a note."""
    names = record.get("verdict_maps") if isinstance(record.get("verdict_maps"), dict) else {}
    placed = []
    for key in ("pvalue", "failing"):
        candidates = [names.get(key), Path(results_dir) / "cases" / case_folder / f"{key}.exr"]
        found = first_inside(results_dir, candidates, kind="exr", what=f"verdict_maps.{key}", notes=notes)
        if found is None:
            continue
        imageio.make_folders(folder)
        imageio.atomic_write_bytes(folder / f"{key}.exr", found[1])
        placed.append((f"{key}.exr", f"{link_base}{key}.exr"))
    return placed


def _dof(value) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def tiles_again(render: np.ndarray, render_variance: np.ndarray | None, truth: GroundTruthImage,
                record_verdict: dict | None, spp: object = None) -> TileMaps | None:
    """The verdict's tiles computed again from a case's images (for a run by an older harness, which kept none),
    with the tile, alpha and variance degrees of freedom its record names, the render's ``spp`` and the ground
    truth's (which tiles are too sparse to judge; per-pixel degrees of freedom,
    ``{"min", "max"}``, are taken as exact: the tiles' z then differ a little from the run's). None without a
    render variance or a verdict. The verdict's ``ImageError`` about an image's own arrays (a NaN variance, a
    non-finite ground truth) is raised as the HarnessError naming that image."""
    if render_variance is None or not isinstance(record_verdict, dict) or not record_verdict.get("tile"):
        return None
    dof = record_verdict.get("variance_dof") if isinstance(record_verdict.get("variance_dof"), dict) else {}
    names = ("test image", "ground truth image")
    try:
        outcome = verdict(render, render_variance, truth.image, truth.variance, tile=int(record_verdict["tile"]),
                          alpha=float(record_verdict.get("alpha") or 0.001), test_dof=_dof(dof.get("test")),
                          expected_dof=_dof(dof.get("ground_truth", dof.get("reference"))), test_spp=_dof(spp),
                          expected_spp=float(truth.spp) if truth.spp and truth.source != "closed-form" else None,
                          names=names)
    except ImageError as err:
        if not err.image:
            raise
        raise HarnessError(err.image, err.message) from None
    return outcome.tiles


def make_case_viewer(folder: Path, record: dict, render: np.ndarray, render_variance: np.ndarray | None,
                     truth: GroundTruthImage, images: list[ReportImage]) -> ViewerData:
    """The case's viewer files made here, as the run makes them (:func:`harness.files.viewer_data.make_viewer_data`),
    for a run by an older harness: the FLIP map from the case's placed ``flip.exr`` (else computed), the tiles
    computed again (:func:`tiles_again`)."""
    flip = None
    flip_image = next((im for im in images if im.key == "flip" and im.exr is not None), None)
    if flip_image is not None:
        flip = imageio.read_exr(flip_image.exr).image[..., 0]
    if flip is None or flip.shape != render.shape[:2]:
        flip = metrics.flip(render, truth.image, full=True)[1]
    v = record.get("verdict") if isinstance(record.get("verdict"), dict) else {}
    spp = (record.get("render") or {}).get("spp")
    tiles = tiles_again(render, render_variance, truth, v, spp)
    imageio.make_folders(folder)
    return make_viewer_data(
        folder, name=str(record.get("name", "")), render=render, render_variance=render_variance, truth=truth.image,
        truth_variance=truth.variance, flip=flip, tiles=tiles, tile=v.get("tile"), alpha=v.get("alpha"),
        threshold=v.get("threshold"), exposure=display_exposure(truth.image), recomputed=True,
        labels={"render": f"{record.get('renderer')}, {spp} spp",
                "truth": f"{truth.source}" + (f", {truth.spp} spp" if truth.spp else "")})


# ---- harness view: the viewer page of one or two EXR files -----------------------------------------------------


def write_view_page(out: Path, *, name: str, render: np.ndarray, render_variance: np.ndarray | None,
                    truth: np.ndarray | None, truth_variance: np.ndarray | None, flip: np.ndarray | None,
                    tiles: TileMaps | None, verdict_dict: dict | None, labels: dict, files: list[str],
                    note: str | None = None) -> Path:
    """Write the viewer's page for one image (``render``) or a pair (``render`` against ``truth``) into the folder
    ``out`` (``index.html``, ``view/viewer.js`` and its thumbnails), all at once
    (:class:`harness.files.imageio.StagedFolder`); returns the page's path. ``verdict_dict``: the verdict of the
    pair (its tile, alpha and threshold go with ``tiles``)."""
    v = verdict_dict or {}
    with imageio.StagedFolder(out, "--out") as stage:
        folder = stage.root / "view"
        imageio.make_folders(folder)
        exposure = display_exposure(truth if truth is not None else render)
        data = make_viewer_data(folder, name=name, render=render, render_variance=render_variance, truth=truth,
                                truth_variance=truth_variance, flip=flip, tiles=tiles, tile=v.get("tile"),
                                alpha=v.get("alpha"), threshold=v.get("threshold"), exposure=exposure,
                                labels=labels, note=note)
        view = case_view(data, key="view", slot="viewer-0", link_base="view/", images=[], verdict_maps=[],
                         autoopen=True)
        page = render_page(name, view, v, files, note)
        imageio.atomic_write_text(stage.root / "index.html", page)
        stage.commit(last=("index.html",))
    return Path(out) / "index.html"


def render_page(name: str, view: dict | None, verdict_dict: dict, files: list[str], note: str | None) -> str:
    """The page of ``harness view`` (``view.html.j2``)."""
    return str(render("view.html.j2", title=f"harness view: {name}", subtitle=" · ".join(files), view=view,
                      verdict=verdict_dict, note=note, generated=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                      viewer=assets()))


__all__ = ["SCRIPTS", "STYLE", "assets", "case_view", "histogram_view", "make_case_viewer", "place_case_viewer",
           "place_verdict_maps", "tiles_again", "write_view_page"]
