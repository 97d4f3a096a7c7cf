"""The report of a suite run. It formats (and renders nothing): the run's results.json, its cases' report images (made
by ``harness run`` when it judged each case, :mod:`harness.files.report_images`; for a run by an older harness made
here from the EXRs of its cases: each render and the ground truth it was judged against, from the files results.json
names) and its studies (``studies/studies.json`` with their images and plots, computed by ``harness run``:
:mod:`harness.studies.suite_studies`). It writes ``DIR/index.html`` (one self-contained page, from the Jinja2
templates in ``harness/report/templates``), ``DIR/report.json`` (every number behind it), ``DIR/summary.md``, and
every image as EXR + PNG under ``DIR/report/``. See docs/report.md."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np
from markupsafe import escape

from harness.core import jsonsafe
from harness.core.progress import Progress
from harness.core.system import MACHINE_KEYS, machine_differences, machine_line
from harness.files.cases import GroundTruthImage, read_case_images, slug
from harness.files.imageio import StagedFolder, WriteError, atomic_write_bytes, atomic_write_text, make_folders
from harness.files.previews import ReportImage
from harness.files.report_images import make_report_images, read_report_images
from harness.files.results import read_results
from harness.files.studies import read_studies, read_study_file, studies_folder
from harness.files.viewer_data import ViewerData
from harness.judges.efficiency import shown_mse
from harness.report import labels, viewer
from harness.report.html import data_uri, figure_view, fmt, legend_view, render, static_script
from harness.report import repeats
from harness.report.notes import case_notes
from harness.report.power import power_json, power_view
from harness.report.reproduce import reproduce
from harness.studies import figures

REPORT_SCHEMA = 1

#: the studies' sections: (key in studies.json and report.json, page anchor, heading, nav label, harness run flag)
STUDY_SECTIONS = (
    ("convergence", "convergence", "Convergence", "convergence", "--no-convergence"),
    ("shadow_rays", "shadow-rays", "Noise against shadow rays", "shadow rays", "--no-shadow-rays"),
    ("strategies", "strategies", "Sampling strategies", "strategies", "--no-strategies"),
)
#: how to get the studies, where a report has none
HOW_TO_STUDY = ("`harness run SUITE` computes the studies after its cases (see its --no-convergence, "
                "--no-shadow-rays, --no-strategies and --convergence-spp options), or `harness report RESULTS.json "
                "--studies` computes them now, before formatting")


@dataclass
class ReportOptions:
    """Which sections of the run's studies the page shows. The report computes none of them: ``harness run``
    does (:class:`harness.studies.suite_studies.StudyOptions`), and the report formats what it wrote."""

    convergence: bool = True
    shadow_rays: bool = True
    strategies: bool = True
    progress: bool = False
    calibration: Path | None = None  # a calibration.json whose power table the definitions show (harness.report.power)


@dataclass
class ReportCase:
    """A case of the run as the report shows it: its record, render and ground truth read back, its images."""

    record: dict
    index: int
    slug: str
    render: np.ndarray | None = None
    render_variance: np.ndarray | None = None
    gt: GroundTruthImage | None = None
    images: list[ReportImage] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    summary: dict = field(default_factory=dict)
    viewer: ViewerData | None = None
    verdict_maps: list[tuple[str, str]] = field(default_factory=list)  # (label, link from the page)


def load_results(path: str | Path) -> dict:
    """A results.json, checked against its schema (docs/results-schema.md): any malformation is a one-line
    HarnessError naming the file and the JSON path of the bad key (:func:`harness.files.results.read_results`)."""
    return read_results(path)


# ---- the report ------------------------------------------------------------------------------------------------


def write_suite_report(results: str | Path | dict, out_dir: str | Path | None = None,
                       options: ReportOptions | None = None, *, studies_dir: str | Path | None = None) -> dict:
    """Write the report of a suite run. ``results``: the path of a results.json (checked against its schema:
    harness.files.results) or its content (then ``out_dir`` is required). ``studies_dir``: where the run's studies
    are (default: ``studies/`` beside results.json, :func:`harness.files.studies.studies_folder`). Returns
    {"index", "report_json", "summary", "seconds"}.

    Everything is written into a staging folder and moved into ``out_dir`` at the end
    (:class:`harness.files.imageio.StagedFolder`): a report that fails (bad results, a full disk) leaves the folder as
    it was, an old report included. A write that fails is a :class:`harness.files.imageio.WriteError`, never a note in a
    section."""
    options = options or ReportOptions()
    start = time.perf_counter()
    power = power_view(options.calibration)  # a bad --calibration: one line, before anything is written
    if isinstance(results, dict):
        if out_dir is None:
            raise ValueError("out_dir is required when results are given as a dict")
        results_path = None
        results_dir = Path(out_dir)
    else:
        results_path = Path(results)
        results_dir = results_path.parent
    out = Path(out_dir) if out_dir is not None else results_dir
    studies = Path(studies_dir) if studies_dir is not None else studies_folder(results_dir)
    with StagedFolder(out, "--out") as stage:  # first: an unwritable --out is named before any work
        if results_path is not None:
            results = load_results(results_path)
        page_html, doc, summary_md = _suite_report(results, results_path, results_dir, studies, stage.root, options,
                                                   start, power)
        atomic_write_text(stage.root / "report.json", jsonsafe.dumps(doc, stage.relocate, indent=2))
        atomic_write_text(stage.root / "summary.md", stage.relocate(summary_md))
        atomic_write_text(stage.root / "index.html", stage.relocate(page_html).replace(str(escape(stage.root)),
                                                                                       str(escape(out))))
        stage.commit(last=("index.html",))  # the page last: whoever opens it finds every file it names
    return {"index": out / "index.html", "report_json": out / "report.json", "summary": out / "summary.md",
            "seconds": time.perf_counter() - start}


def _suite_report(results: dict, results_path: Path | None, results_dir: Path, studies_dir: Path, out: Path,
                  options: ReportOptions, start: float, power: dict | None = None) -> tuple[str, dict, str]:
    """The report's images written under ``out`` (the cases' maps, copies of the studies' files); returns the page,
    report.json's content and summary.md."""
    records = results.get("cases", [])
    progress = Progress(options.progress, len(records), "report")
    timings: dict[str, float] = {}
    try:
        t0 = time.perf_counter()
        items, used = [], set()
        for index, record in enumerate(records):
            name = slug(str(record.get("name", f"case-{index}")))
            if name in used:
                name = f"{name}-{index}"
            used.add(name)
            item = ReportCase(record=record, index=index, slug=name)
            try:
                _case_images(item, results_dir, out)
            except WriteError:
                raise
            except Exception as err:  # noqa: BLE001 - a broken case is reported in its section
                item.problems.append(f"{type(err).__name__}: {err}".splitlines()[0])
            items.append(item)
            progress.step(str(record.get("name", "")))
        timings["cases"] = time.perf_counter() - t0
    finally:
        progress.close()

    wanted = [s for s in STUDY_SECTIONS if getattr(options, s[0])]
    studies, why = read_studies(studies_dir) if wanted else (None, None)
    _add_study_problems(items, studies)
    sections_json: dict[str, Any] = {}
    sections_html = []
    for key, anchor, heading, _, flag in wanted:
        sections_json[key], html = _study_section(key, anchor, heading, flag, studies, why, studies_dir, out)
        sections_html.append(html)
    if studies is not None:
        spent = studies.get("timings") if isinstance(studies.get("timings"), dict) else {}
        timings.update({k: spent[k] for k, *_ in wanted if isinstance(spent.get(k), (int, float))})
        if isinstance(spent.get("total"), (int, float)):
            timings["studies"] = spent["total"]
    timings["total"] = time.perf_counter() - start
    notes = [studies["note"]] if studies is not None and isinstance(studies.get("note"), str) else []
    doc = _report_json(results, results_path, items, sections_json, options, studies, why, studies_dir, timings,
                       notes)
    power = power or power_view(None)
    doc["power"] = power_json(power)
    page_html = _suite_html(results, results_path, items, wanted, sections_html, notes, power)
    return page_html, doc, _summary_md(results, items, sections_json)


def _load_case(item: ReportCase, results_dir: Path) -> None:
    """Read a case's render and ground truth back (into ``item``), from the files results.json names."""
    images = read_case_images(item.record, results_dir)
    item.render, item.render_variance, item.gt = images.render, images.render_variance, images.ground_truth
    item.problems.extend(images.problems)


def _case_images(item: ReportCase, results_dir: Path, out: Path) -> None:
    """The case's images in ``out/report/<case>`` and their numbers: those ``harness run`` made when it judged the
    case (``report_images`` in its record, :mod:`harness.files.report_images`), checked and copied from inside the
    run folder; for a run by an older harness (or images gone missing or refused), made here from the case's EXRs as
    the run makes them."""
    folder = out / "report" / item.slug
    stored = read_report_images(item.record, results_dir, item.problems)
    if stored is not None:
        placed = stored.placed(folder)
    else:
        _load_case(item, results_dir)
        if item.render is None or item.gt is None:
            return
        gt = item.gt
        placed = make_report_images(folder, case=item.record["name"], renderer=item.record.get("renderer"),
                                    spp=(item.record.get("render") or {}).get("spp"), render=item.render,
                                    render_variance=item.render_variance, truth=gt.image, truth_variance=gt.variance,
                                    truth_source=gt.source, truth_spp=gt.spp)
    item.images.extend(placed.images)
    item.summary = dict(placed.error_maps)
    _case_viewer(item, results_dir, out)


def _case_viewer(item: ReportCase, results_dir: Path, out: Path) -> None:
    """The case's comparison-viewer files (and its verdict maps) in ``out/report/<case>``: those ``harness run``
    made (``viewer`` in its record), checked and copied from inside the run folder (viewer.js parsed and written
    again); for a run by an older harness (or files refused), made here from the case's EXRs
    (:func:`harness.report.viewer.make_case_viewer`)."""
    folder = out / "report" / item.slug
    run_folder = slug(str(item.record.get("name", "")))
    item.verdict_maps = viewer.place_verdict_maps(item.record, results_dir, folder, run_folder,
                                                  f"report/{item.slug}/", item.problems)
    placed = viewer.place_case_viewer(item.record, results_dir, folder, run_folder, item.problems)
    if placed is None:
        if item.render is None:
            _load_case(item, results_dir)
        if item.render is None or item.gt is None:
            return
        placed = viewer.make_case_viewer(folder, item.record, item.render, item.render_variance, item.gt,
                                         item.images)
    item.viewer = placed


def _add_study_problems(items: list[ReportCase], studies: dict | None) -> None:
    """The problems the studies had with a case (its scene not readable, ...) added to the case's own."""
    cases = studies.get("cases") if studies is not None else None
    if not isinstance(cases, list):
        return
    for item, entry in zip(items, cases):
        if isinstance(entry, dict) and entry.get("name") == item.record.get("name"):
            item.problems.extend(p for p in entry.get("problems") or [] if isinstance(p, str)
                                 and p not in item.problems)


# ---- the studies' sections ---------------------------------------------------------------------------------------


def _study_section(key: str, anchor: str, heading: str, flag: str, studies: dict | None, why: str | None,
                   studies_dir: Path, out: Path) -> tuple[Any, Any]:
    """(report.json's section, its HTML) from the studies; where they do not hold it, None and a section that says
    how to get it."""
    if studies is None:
        return None, _missing(anchor, heading, f"Not computed: this run's studies are not there ({why}). "
                                               f"{HOW_TO_STUDY}.")
    section = studies.get(key)
    if section is None:
        return None, _missing(anchor, heading, f"Not computed by this run (harness run {flag}). {HOW_TO_STUDY}.")
    try:
        return FORMATTERS[key](section, studies_dir, out)
    except WriteError:
        raise
    except Exception as err:  # noqa: BLE001 - a malformed section of a hand-edited studies.json
        reason = " ".join(f"{type(err).__name__}: {err}".split())[:200]
        return None, _missing(anchor, heading, f"studies.json's {key} section could not be read ({reason}). "
                                               f"{HOW_TO_STUDY}.")


def _missing(anchor: str, heading: str, why: str):
    return render("missing_section.html.j2", anchor=anchor, heading=heading, why=why)


def _copy_study_file(studies_dir: Path, relative: Any, out: Path) -> tuple[Path | None, str | None, bytes | None]:
    """A file the studies wrote, copied into the report (``out/report/<relative>``): (its path there, its link
    from the page, its bytes); (None, None, None) when studies.json names no such file in the studies' folder (in
    the run folder, a PNG or OpenEXR file: :func:`harness.files.studies.read_study_file`)."""
    data = read_study_file(studies_dir, relative)
    if data is None:
        return None, None, None
    parts = PurePosixPath(relative).parts
    dest = out / "report" / Path(*parts)
    make_folders(dest.parent)
    atomic_write_bytes(dest, data)
    return dest, "report/" + "/".join(parts), data


def _convergence(section: dict, studies_dir: Path, out: Path) -> tuple[dict, Any]:
    scenes, views = [], []
    for entry in section["scenes"]:
        entry = dict(entry)
        view = {"scene_name": entry.get("scene_name"), "case": entry.get("case"), "error": entry.get("error"),
                "plot": entry.get("plot"), "plot_uri": None, "result": entry.get("result")}
        if not entry.get("error"):
            dest, _, png = _copy_study_file(studies_dir, entry.get("plot"), out)
            entry["plot"] = str(dest) if dest else None
            view["plot_uri"] = data_uri(png) if png else None
        scenes.append(entry)
        views.append(view)
    html = render("convergence.html.j2",
                  section={"spp_ladder": section["spp_ladder"], "k": section["k"], "scenes": views})
    return dict(section, scenes=scenes), html


def _shadow_rays(study: dict, studies_dir: Path, out: Path) -> tuple[dict, Any]:
    if study.get("skipped") or study.get("error"):
        reason = study.get("skipped") or study.get("error")
        return study, render("shadow_rays.html.j2", study={"ok": False, "reason": reason})
    plots, plot_uris = {}, {}
    for key, relative in (study.get("plots") or {}).items():
        dest, _, png = _copy_study_file(studies_dir, relative, out)
        plots[key] = str(dest) if dest else None
        plot_uris[key] = data_uri(png) if png else None
    images, views = [], []
    for image in study.get("images") or []:
        exr, exr_link, _ = _copy_study_file(studies_dir, image.get("exr"), out)
        png, png_link, data = _copy_study_file(studies_dir, image.get("png"), out)
        images.append(dict(image, exr=str(exr) if exr else None, png=str(png) if png else None))
        if data is not None:
            views.append({"uri": data_uri(data), "title": image.get("title"), "description": image.get("description"),
                          "legend": legend_view(image.get("legend")), "width": 160, "pixelated": True,
                          "links": {"exr": exr_link, "png": png_link} if exr_link else None})
    view = {"ok": True, "data": study, "scene_name": Path(str(study["scene"])).stem, "plots": plot_uris,
            "figures": views}
    return dict(study, plots=plots, images=images), render("shadow_rays.html.j2", study=view)


def interval_text(interval: dict | None, digits: int = 3) -> str:
    """A ratio or efficiency with its confidence interval, "1.33 [0.99, 1.80]"; the default's own ratio "1
    (reference)"; the value alone where there is no interval (fewer than 2 seeds, or a bare number from an older
    harness); '–' for none."""
    if isinstance(interval, (int, float)) and not isinstance(interval, bool):
        return fmt(float(interval), digits)
    if not isinstance(interval, dict) or interval.get("value") is None:
        return "–"
    if interval.get("reference"):
        return "1 (reference)"
    text = fmt(interval["value"], digits)
    if interval.get("low") is not None and interval.get("high") is not None:
        text += f" [{fmt(interval['low'], digits)}, {fmt(interval['high'], digits)}]"
    return text


def mse_text(row: dict) -> str:
    """A row's measured MSE with the ground truth's noise removed: the number, or "< bound" (its value) where it
    lies below the ground truth's own variance contribution (:func:`harness.judges.efficiency.shown_mse`; a row of an
    older harness, which kept a negative number, is judged here): never a negative MSE."""
    if "mse_bound" in row:
        value, bound = row.get("mse_corrected"), row.get("mse_bound")
    else:
        shown = shown_mse(row.get("mse_corrected"), row.get("floor_mse"))
        value, bound = shown["value"], shown["bound"]
    if bound is not None:
        return f"< {fmt(bound, 2)} (bound)" if bound > 0 else "< bound (0)"
    return fmt(value)


#: the efficiency cell of an exact estimator (every seed's variance at most float32 rounding)
ZERO_VARIANCE = "zero variance"


def _strategy_row_view(row: dict, best: Any) -> dict:
    if "skipped" in row:
        return {"label": row["label"], "skipped": row["skipped"]}
    view = dict({k: row.get(k) for k in ("mse_estimate", "seconds_per_megapixel", "efficiency")},
                label=row["label"], skipped=None, best=row["label"] == best, seconds=row["seconds"],
                mse_measured=mse_text(row))
    if "equal_spp" not in row:  # one render per strategy (the suite's cases alone, or an older harness): unranked
        source = f"case {row['case']}" if row.get("case") else f"rendered ({row.get('spp')} spp)"
        view.update(film_spp=f"{row['film'][0]}x{row['film'][1]}, {row['spp']} spp", source=source,
                    relative_mse="–", relative_time="–", relative_mse_equal_time="–", equal_time_spp="–",
                    mse_slope="–",
                    efficiency_text=fmt(row.get("efficiency")), relative_efficiency="–")
        if row.get("zero_variance"):
            view.update(efficiency_text=ZERO_VARIANCE)
        return view
    view.update(film_spp=f"{row['film'][0]}x{row['film'][1]}, {row['spp']} spp",
                source=f"rendered, {row['equal_spp']['seeds']} seeds per budget",
                relative_mse=interval_text(row.get("relative_mse_interval")),
                relative_time=interval_text(row.get("relative_time_interval")),
                equal_time_spp=row.get("equal_time_spp"),
                seconds_per_megapixel=row.get("equal_time_seconds_per_megapixel", row.get("seconds_per_megapixel")),
                mse_slope=interval_text(row.get("mse_slope")) if row.get("mse_slope") else "–",
                relative_mse_equal_time=interval_text(row.get("relative_mse_equal_time")),
                efficiency_text=interval_text(row.get("efficiency_interval"), 4),
                relative_efficiency=interval_text(row.get("relative_efficiency_interval")))
    if row.get("zero_variance"):  # an exact estimator: 1 / (MSE x time) would be rounding's inverse, not ranked
        view.update(efficiency_text=ZERO_VARIANCE, relative_efficiency=ZERO_VARIANCE)
    return view


def _best_line(entry: dict) -> str:
    """What the table says about the best strategy: named with its interval where told apart, else why not. Rows of
    zero variance are left out of the ranking and, exact, come first: a noisy row is then the best only "among the
    others"."""
    zero = entry.get("zero_variance") or []
    if not zero:
        return _best_named(entry)
    named = _best_named(entry).removeprefix("Best: ")
    return (f"Best: zero variance (exact here; no efficiency, not ranked): {', '.join(zero)}. Among the others: "
            f"{named}")


def _best_named(entry: dict) -> str:
    if entry.get("comparison") == "cases":
        return "Not ranked: " + str(entry.get("unranked"))
    if entry.get("comparison") is None:
        return ("Not ranked: a table of an older harness (one render per strategy, at different spp, no intervals); "
                "run the studies again (harness report --studies)")
    if entry.get("best"):
        return (f"Best: {entry['best']} (efficiency at equal time {interval_text(entry.get('best_interval'))} x the "
                f"default; told apart from every other strategy at {fmt(100 * entry['level'], 3)} % jointly)")
    if entry.get("leader"):
        tied = [n for n in entry.get("near_best") or [] if n != entry["leader"]]
        return (f"Best: not told apart at this budget (highest efficiency: {entry['leader']}; its interval over "
                f"{', '.join(tied)} reaches 1)")
    return "Best: none measured"


def _strategies(section: dict, studies_dir: Path, out: Path) -> tuple[dict, Any]:
    scenes, views = [], []
    for entry in section["scenes"]:
        entry = dict(entry)
        view: dict[str, Any] = {"data": entry, "near": "", "rows": [], "plot_uri": None}
        if not entry.get("error"):
            dest, _, png = _copy_study_file(studies_dir, entry.get("plot"), out)
            view["plot_uri"] = data_uri(png) if png else None
            view["best_line"] = _best_line(entry)
            view["region_rows"] = _region_views(entry)
            view["rows"] = [_strategy_row_view(r, entry.get("best")) for r in entry["rows"]]
            entry["plot"] = str(dest) if dest else None
        scenes.append(entry)
        views.append(view)
    defaults = " ".join(f"{k}={v}" for k, v in section["defaults"].items())
    html = render("strategies.html.j2", section=section, defaults=defaults, scenes=views)
    return dict(section, scenes=scenes), html


def _region_views(entry: dict) -> list[dict]:
    """The region table's rows: per row label, each region's efficiency / default with its interval, and whether
    it is that region's best (told apart: :func:`harness.judges.efficiency.best_separated`)."""
    regions = entry.get("regions") or {}
    out = []
    for row in entry.get("rows") or []:
        if "skipped" in row:
            continue
        cells = []
        for name in regions.get("names", []):
            interval = (regions.get("intervals") or {}).get(name, {}).get(row["label"])
            value = regions["relative_efficiency"][name].get(row["label"])
            text = interval_text(interval) if interval else fmt(value)
            ranked = entry.get("comparison") == "repeats"  # an older harness's region best had no interval
            cells.append({"text": text, "best": ranked and regions["best"].get(name) == row["label"]})
        out.append({"label": row["label"], "cells": cells})
    return out


FORMATTERS = {"convergence": _convergence, "shadow_rays": _shadow_rays, "strategies": _strategies}


# ---- report.json -----------------------------------------------------------------------------------------------


def _variant(record: dict) -> dict:
    render = record.get("render") or {}
    info = render.get("info") or {}
    gt = record.get("ground_truth") or {}
    return {"render": info.get("variant") or (render.get("settings") or {}).get("variant")
            if record.get("renderer") == "mitsuba" else None,
            "ground_truth": gt.get("variant")}


def _case_json(item: ReportCase) -> dict:
    r = item.record
    render = r.get("render") or {}
    return {
        "name": r.get("name"), "scene": r.get("scene"), "renderer": r.get("renderer"), "status": r.get("status"),
        "expect": r.get("expect"), "ok": r.get("ok"), "reason": r.get("reason"), "settings": r.get("settings"),
        "resolved_settings": render.get("settings"), "mitsuba_variant": _variant(r), "budget": r.get("budget"),
        "seed": r.get("seed"), "against": r.get("against"), "ground_truth": r.get("ground_truth"),
        "metrics": r.get("metrics"), "verdict": r.get("verdict"), "thresholds": r.get("thresholds"),
        "thresholds_broken": r.get("thresholds_broken"),
        "render": {k: render.get(k) for k in ("seconds", "spp", "paths_per_second", "rays", "nonfinite_pixels",
                                             "exr")},
        "wall_seconds": r.get("wall_seconds"),
        "cached": r.get("cached"), "verdict_maps": r.get("verdict_maps"), "reproduce": reproduce(r),
        "error_maps": {k: v for k, v in item.summary.items() if not k.startswith("_")},
        "images": [im.to_json() for im in item.images],
        "viewer": item.viewer.to_json() if item.viewer is not None else None,
        "problems": item.problems,
        "traceback": r.get("traceback"),
    }


def _report_json(results, results_path, items, sections, options, studies, why, studies_dir, timings,
                 notes) -> dict:
    study_options = studies.get("options") if studies is not None and isinstance(studies.get("options"), dict) else {}
    return {
        "schema": REPORT_SCHEMA,
        "kind": "suite-report",
        "generated": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "results_file": str(results_path) if results_path else None,
        "suite": results.get("suite"), "suite_file": results.get("suite_file"),
        "description": results.get("description"), "started": results.get("started"), "host": results.get("host"),
        "system": results.get("system"), "machine_notes": machine_notes(results),
        "summary": results.get("summary"),
        "note": "; ".join(notes) or None,
        "options": dict(study_options, convergence=options.convergence, shadow_rays=options.shadow_rays,
                        strategies=options.strategies),
        "studies": {"file": str(studies_dir / "studies.json") if studies is not None else None, "note": why,
                    "generated": studies.get("generated") if studies is not None else None},
        "definitions": DEFINITIONS,
        "cases": [_case_json(i) for i in items],
        "convergence": sections.get("convergence"),
        "shadow_rays": sections.get("shadow_rays"),
        "strategies": sections.get("strategies"),
        "timings": timings,
    }


DEFINITIONS = {
    "signed_error": "render - ground truth per pixel, mean over R, G, B; colour limits symmetric at the 99th "
                    "percentile of |error|",
    "relative_error": "|render - ground truth| / (|ground truth| + 0.01) per pixel, mean over R, G, B (MAPE's terms)",
    "flip": "HDR-FLIP error map (flip-evaluator), 0..1",
    "mse_corrected": "MSE against the ground truth minus the mean of the ground truth's own per-pixel variance "
                     "(its noise adds that much to the expected MSE)",
    "convergence_fit": "least-squares slope of log(RMSE) against log(spp) (unbiased: -1/2; relMSE: -1); a curve "
                       "leaves the line at the first point from which every point lies above the expected-slope line "
                       "(anchored on the points before it) by more than k times the expected scatter of log(RMSE), "
                       "sqrt(sum e^4 / (sum e^2)^2 - 1/N) / 2, at least 2 %",
    "penumbra": "ground-truth luminance strictly between 5 % and 95 % of the fully lit level: per pixel the scene "
                "rendered without its occluder, leaving out pixels that see the occluder",
    "efficiency": "1 / (MSE x render seconds per megapixel) at equal time, relative to the default settings, with "
                  "its 95 % interval over independent seeds (delta method); MSE is the render's own variance "
                  "estimate (mean per-pixel variance of the mean), else the measured MSE_corrected",
    "equal_time": "the error each curve reaches at the longest time all curves cover (log-log interpolation; "
                  "outside a curve's range, along its log-log least-squares line, flagged as extrapolated, up to 2x "
                  "beyond its measured times; further: out of range)",
    "equal_error": "the time each curve needs to reach the smallest error all curves reach (log-log interpolation; "
                   "outside a curve's range, along its log-log least-squares line, flagged as extrapolated, up to 2x "
                  "beyond its measured times; further: out of range)",
}


# ---- HTML ------------------------------------------------------------------------------------------------------


def _metrics_rows(record: dict) -> list[tuple]:
    m = record.get("metrics") or {}
    rows = []
    for key in ("rmse", "relmse", "mape", "psnr", "ssim", "flip"):
        if key in m:
            rows.append((key, m[key]))
    b = m.get("bias")
    if isinstance(b, dict):
        rows.append(("bias (overall)", b.get("overall")))
        rows.append(("bias stderr", b.get("stderr")))
        rows.append(("bias per channel", ", ".join(fmt(v) for v in b.get("per_channel") or [])))
    return rows


def _verdict_rows(v: dict) -> list[tuple]:
    """The verdict's statistics (the verdict itself is the table's first row, a badge, in the template)."""
    if not v:
        return []
    gb, om, mz = v.get("global_bias") or {}, v.get("omnibus") or {}, v.get("max_z") or {}
    wt, zv = v.get("worst_tile") or {}, v.get("zero_variance") or {}

    def triple(values):
        return ", ".join(fmt(x, 3) for x in values) if isinstance(values, list) else fmt(values)

    rows = [
        ("reason", v.get("reason") or "–"),
        ("alpha / per-test threshold", f"{fmt(v.get('alpha'))} / {fmt(v.get('threshold'))}"),
        ("tile", v.get("tile")),
        ("global bias z (R, G, B)", triple(gb.get("z"))),
        ("global bias difference", triple(gb.get("difference"))),
        ("global bias p", gb.get("p_value")),
        ("omnibus chi2 (R, G, B)", triple(om.get("statistic"))),
        ("omnibus dof", triple(om.get("dof"))),
        ("omnibus p", om.get("p_value")),
        ("max |z| over tiles", f"{fmt(mz.get('statistic'))} of {fmt(mz.get('count'))} tiles"),
        ("max |z| p", mz.get("p_value")),
        ("worst tile", f"y={wt.get('y')}, x={wt.get('x')}, {wt.get('channel')}: z={fmt(wt.get('z'), 3)}" if wt else "–"),
        ("zero-variance tiles (differing)", f"{zv.get('tiles', 0)} ({zv.get('differing', 0)})"),
        ("non-finite pixels", v.get("nonfinite_pixels")),
    ]
    return rows


def _settings_rows(record: dict) -> list[tuple]:
    render = record.get("render") or {}
    gt = record.get("ground_truth") or {}
    variants = _variant(record)
    budget = record.get("budget") or {}
    rows = [
        ("scene", record.get("scene")),
        ("renderer", record.get("renderer")),
        ("Mitsuba variant (render)", variants["render"] or "–"),
        ("settings (suite)", " ".join(f"{k}={v}" for k, v in (record.get("settings") or {}).items()) or "defaults"),
        ("budget", ", ".join(f"{k} {v}" for k, v in budget.items())),
        ("seed", record.get("seed")),
        ("spp rendered", render.get("spp")),
        ("render time [s]", render.get("seconds")),
        ("render time from", (render.get("info") or {}).get("time_from") or "the renderer's own clock"),
        ("paths / s", render.get("paths_per_second")),
        ("rays", ", ".join(f"{k} {v}" for k, v in (render.get("rays") or {}).items())),
        ("compared with", (record.get("against") or {}).get("kind")),
        ("ground truth", f"{gt.get('source')}" + (f", {gt.get('spp')} spp" if gt.get("spp") else "")
         + (", cached" if gt.get("cached") else "")),
        ("Mitsuba variant (ground truth)", variants["ground_truth"] or "–"),
        ("thresholds", ", ".join(f"{k} {v}" for k, v in (record.get("thresholds") or {}).items()) or "–"),
        ("thresholds broken", ", ".join(record.get("thresholds_broken") or []) or "–"),
        ("case wall time [s]", record.get("wall_seconds")),
    ]
    return rows


def _case_view(item: ReportCase) -> dict:
    r = item.record
    resolved = (r.get("render") or {}).get("settings")
    verdict = r.get("verdict") or {}
    return {
        "anchor": f"case-{item.index}", "name": r.get("name"), "status": r.get("status", "?"), "ok": r.get("ok"),
        "expect": r.get("expect"), "reason": r.get("reason"), "problems": item.problems + case_notes(r),
        # the images themselves only where the case has no viewer (its data could not be made): else a thumbnail
        "figures": ([figure_view(im, link_base=f"report/{item.slug}/") for im in item.images]
                    if item.viewer is None else []),
        "viewer": viewer.case_view(item.viewer, key=item.slug, slot=f"viewer-{item.index}",
                                   link_base=f"report/{item.slug}/", images=item.images,
                                   verdict_maps=item.verdict_maps),
        "metrics_rows": _metrics_rows(r), "verdict": verdict.get("verdict", "?"),
        "verdict_rows": _verdict_rows(verdict),
        "settings_rows": _settings_rows(r), "resolved_json": json.dumps(resolved, indent=1) if resolved else None,
        "traceback": r.get("traceback"), "reproduce": reproduce(r),
    }


def _summary_row(item: ReportCase) -> dict:
    r = item.record
    m = r.get("metrics") or {}
    renderer, reason = labels.renderer_label(r.get("renderer")), labels.clip(r.get("reason"))
    return {"anchor": f"case-{item.index}", "name": r.get("name"), "scene": Path(str(r.get("scene"))).stem,
            "renderer": renderer, "renderer_title": labels.title_of(r.get("renderer"), renderer),
            "status": r.get("status", "?"), "expect": r.get("expect"),
            "ok": r.get("ok"), "rmse": m.get("rmse"), "relmse": m.get("relmse"), "flip": m.get("flip"),
            "seconds": (r.get("render") or {}).get("seconds"), "reason": reason,
            "reason_title": labels.title_of(r.get("reason"), reason),
            "sort": {k: _sort_number(v) for k, v in (("rmse", m.get("rmse")), ("relmse", m.get("relmse")),
                                                      ("flip", m.get("flip")),
                                                      ("seconds", (r.get("render") or {}).get("seconds")))}}


def _sort_number(value: Any) -> str:
    """A number as summary.js sorts it (``data-sort``): its full repr, "" for none or a non-number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
        return ""
    return repr(value)


def machine_notes(results: dict) -> list[str]:
    """Where the run's numbers come from another machine than its own (its ``system`` block): a baseline made
    elsewhere (``baseline.other_machine``), cases answered from a results cache filled elsewhere
    (``cached.machine``)."""
    notes = []
    base = results.get("baseline") if isinstance(results.get("baseline"), dict) else {}
    if base.get("other_machine"):
        notes.append(f"The baseline {base.get('file')} was made on another machine "
                     f"({'; '.join(map(str, base['other_machine']))}): its timings are that machine's.")
    system = results.get("system")
    if isinstance(system, dict):
        here = {k: system.get(k) for k in MACHINE_KEYS}
        others: dict[str, list[str]] = {}
        for record in results.get("cases") or []:
            cached = record.get("cached") if isinstance(record, dict) else None
            machine = cached.get("machine") if isinstance(cached, dict) else None
            differences = machine_differences(machine, here)
            if differences:
                others.setdefault(machine_line(machine).split(" (")[0], []).append(str(record.get("name")))
        for node, names in others.items():
            notes.append(f"{len(names)} cases came from the results cache of another machine ({node}): their "
                         f"timings are that machine's: {', '.join(names)}.")
    return notes


def _system_rows(system: Any) -> list[tuple]:
    """The page's System table, from results.json's ``system`` block (none for a run by an older harness)."""
    if not isinstance(system, dict):
        return []
    mitsuba = system.get("mitsuba") if isinstance(system.get("mitsuba"), dict) else {}
    git = system.get("git")
    if isinstance(git, dict):
        commit = f"{git.get('commit')}" + (" (dirty: the tree had changes)" if git.get("dirty") else "")
    else:
        commit = "– (not a git checkout)"
    used = ", ".join(mitsuba.get("variants_used") or []) or "none"
    return [
        ("machine", system.get("node")), ("CPU", system.get("cpu")), ("logical cores", system.get("logical_cores")),
        ("GPUs", "; ".join(system.get("gpus") or []) or "none"), ("OS", system.get("os")),
        ("Python", system.get("python")), ("numpy", system.get("numpy")), ("numba", system.get("numba")),
        ("embreex / Embree", f"{system.get('embreex') or '–'} / {system.get('embree') or '–'}"),
        ("Mitsuba", f"{mitsuba.get('version') or 'not installed'}; variant asked for: "
                    f"{mitsuba.get('variant') or 'the default choice'}; used: {used}"),
        ("harness commit", commit),
    ]


def _suite_html(results, results_path, items, wanted, sections_html, notes, power) -> str:
    s = results.get("summary") or {}
    host = results.get("host") or {}
    subtitle = (f"suite file {results.get('suite_file')} · started {results.get('started')} · host "
                f"{host.get('node')} ({host.get('machine')}, Python {host.get('python')})"
                + (f" · results {results_path}" if results_path else ""))
    return str(render(
        "suite.html.j2", title=f"Suite report: {results.get('suite', '?')}", subtitle=subtitle,
        description=results.get("description") or "", nav=[(anchor, label) for _, anchor, _, label, _ in wanted],
        s=s, unexpected=", ".join(str(n) for n in s.get("unexpected") or []), notes=notes,
        summary_rows=[_summary_row(i) for i in items], cases=[_case_view(i) for i in items],
        sections=sections_html, definitions=sorted(DEFINITIONS.items()),
        system_rows=_system_rows(results.get("system")), machine_notes=machine_notes(results),
        summary_js=static_script("summary.js"), power=power, viewer=viewer.assets()))


# ---- summary.md ------------------------------------------------------------------------------------------------


#: Markdown's inline punctuation that could start markup (emphasis, code, links, images, strikethrough, headings,
#: table cells), escaped with a backslash; < > & become entities, since Markdown passes HTML through
_MD_PUNCTUATION = "\\`*_[]|~#"
_MD_TABLE = str.maketrans({**{c: "\\" + c for c in _MD_PUNCTUATION}, "<": "&lt;", ">": "&gt;", "&": "&amp;",
                           "\n": " ", "\r": " ", "\t": " ", "\v": " ", "\f": " ", "\x85": " ", "\u2028": " ",
                           "\u2029": " "})


def _md(value: Any) -> str:
    """``str(value)`` as literal text in Markdown that is rendered as HTML (CI step summaries, wikis): no tag,
    entity, emphasis, code span, link or table cell can start in it, and it stays on one line."""
    return str(value).translate(_MD_TABLE)


def _mdf(value: Any, digits: int = 4) -> str:
    """A number (or whatever stands in its place) for summary.md: :func:`fmt`, escaped."""
    return _md(fmt(value, digits))


def _summary_md(results, items, sections) -> str:
    s = results.get("summary") or {}
    lines = [f"# Suite report: {_md(results.get('suite'))}", "",
             f"{_mdf(s.get('ok'))}/{_mdf(s.get('cases'))} cases as expected ({_mdf(s.get('passed'))} passed, "
             f"{_mdf(s.get('failed'))} failed, {_mdf(s.get('errors'))} errors); {_mdf(s.get('mitsuba_renders'))} "
             "Mitsuba renders. Full report: `index.html`; numbers: `report.json`.", ""]
    if s.get("unexpected"):
        lines += ["**Not as expected:** " + ", ".join(_md(n) for n in s["unexpected"]), ""]
    for note in machine_notes(results):  # a baseline or cached cases from another machine
        lines += [f"**Another machine:** {_md(note)}", ""]
    lines += ["| case | status | expect | RMSE | relMSE | FLIP | time [s] |", "|---|---|---|---|---|---|---|"]
    for item in items:
        r = item.record
        m = r.get("metrics") or {}
        lines.append(f"| {_md(r.get('name'))} | {_md(r.get('status'))}{'' if r.get('ok') else ' (unexpected)'} | "
                     f"{_md(r.get('expect'))} | {_mdf(m.get('rmse'))} | {_mdf(m.get('relmse'))} | "
                     f"{_mdf(m.get('flip'))} | {_mdf((r.get('render') or {}).get('seconds'), 3)} |")
    c = sections.get("convergence")
    if c:
        lines += ["", "## Convergence (slope of log RMSE against log spp; -1/2 when unbiased)", ""]
        for e in c["scenes"]:
            if e.get("error"):
                lines.append(f"- {_md(e['scene_name'])}: failed ({_md(e['error'])})")
                continue
            for series in e["result"]["series"]:
                f = series["fit_rmse"]
                flag = (f"flattens from {_mdf(f.get('departure_spp'))} spp (bias?)" if f.get("biased")
                        else "no flattening")
                timing = f"; render time: {_md(series['time_from'])}" if series.get("time_from") else ""
                lines.append(f"- {_md(e['scene_name'])}, {_md(series['label'])}: slope {_mdf(f.get('slope'), 3)}; "
                             f"{flag}{timing}")
    sr = sections.get("shadow_rays")
    if sr and sr.get("rows"):
        lines += ["", "## Noise against shadow rays (spp = 1)", "",
                  "| shadow rays | RMSE penumbra | time [s] |", "|---|---|---|"]
        for r in sr["rows"]:
            lines.append(f"| {_mdf(r['shadow_rays'])} | {_mdf(r['penumbra']['rmse_corrected'])} | "
                         f"{_mdf(r['seconds'], 3)} |")
    st = sections.get("strategies")
    if st:
        lines += ["", "## Best strategy per scene (efficiency at equal time relative to the default, 95 % intervals)",
                  ""]
        for e in st["scenes"]:
            if e.get("error"):
                lines.append(f"- {_md(e['scene'])}: failed ({_md(e['error'])})")
            else:
                lines.append(f"- {_md(e['scene'])}: {_md(_best_line(e))}")
                regions = e.get("regions") or {}
                for name in regions.get("names", []):
                    row = (regions.get("intervals") or {}).get(name) or {}
                    best = regions["best"].get(name) or "not told apart at this budget"
                    lines.append(f"  - {_md(name)}: best {_md(best)}; "
                                 + ", ".join(f"{_md(k)} {_md(interval_text(v))}" for k, v in row.items()))
    return "\n".join(lines) + "\n"


# ---- harness convergence ---------------------------------------------------------------------------------------


def write_convergence_report(result: dict, out_dir: str | Path, *, title: str = "") -> dict:
    """Write a convergence run (:func:`harness.studies.convergence.run_convergence`) as ``DIR/convergence.json``,
    ``DIR/convergence.png``, a self-contained ``DIR/index.html`` and ``DIR/summary.md``, moved into place together
    (:class:`harness.files.imageio.StagedFolder`: a failed write leaves the folder as it was)."""
    out = Path(out_dir)
    name = result.get("scene_name") or Path(str(result.get("scene"))).stem
    title = title or f"Convergence: {name}"
    png = figures.convergence_figure(result, title=title)
    spectrum_png = figures.spectrum_figure(result, title=title)  # None without spectra
    plot = out / "convergence.png"
    with StagedFolder(out, "--out") as stage:
        _write_convergence_files(result, stage.root, title, png, plot, spectrum_png)
        stage.commit(last=("index.html",))
    return {"index": out / "index.html", "report_json": out / "convergence.json", "summary": out / "summary.md",
            "plot": plot, **({"spectrum": out / "spectrum.png"} if spectrum_png else {})}


def _write_convergence_files(result: dict, folder: Path, title: str, png: bytes, plot: Path,
                             spectrum_png: bytes | None = None) -> None:
    """The files of :func:`write_convergence_report` written into ``folder``; ``plot`` is where the plot will be."""
    make_folders(folder)
    atomic_write_bytes(folder / plot.name, png)
    if spectrum_png:
        atomic_write_bytes(folder / "spectrum.png", spectrum_png)
    doc = dict(result, schema=REPORT_SCHEMA, kind="convergence", generated=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
               plot=str(plot), definitions={k: DEFINITIONS[k] for k in ("mse_corrected", "convergence_fit",
                                                                         "equal_time", "equal_error")})
    page = render("convergence_page.html.j2", title=title, subtitle="", result=result,
                  spp_ladder=", ".join(str(n) for n in result["spp_ladder"]),
                  seconds_ladder=", ".join(fmt(s) for s in result.get("seconds_ladder") or []),
                  fit_definition=DEFINITIONS["convergence_fit"], plot_uri=data_uri(png),
                  definitions=sorted(doc["definitions"].items()), repeat_headers=repeats.HEADERS,
                  repeat_rows=repeats.repeat_rows(result),
                  spectrum_uri=data_uri(spectrum_png) if spectrum_png else None)
    atomic_write_text(folder / "index.html", str(page))
    atomic_write_text(folder / "convergence.json", jsonsafe.dumps(doc, indent=2))
    lines = [f"# {_md(title)}", "", "| series | slope (RMSE) | slope (relMSE) | flattens from spp |", "|---|---|---|---|"]
    for s in result["series"]:
        fr, fm = s["fit_rmse"], s["fit_relmse"]
        lines.append(f"| {_md(s['label'])} | {_mdf(fr.get('slope'), 3)} | {_mdf(fm.get('slope'), 3)} | "
                     f"{_mdf(fr.get('departure_spp')) if fr.get('biased') else 'no'} |")
    comp = (result.get("comparisons") or {}).get("rmse_corrected")
    if comp:
        et, ee = comp["equal_time"], comp["equal_error"]
        lines += ["", f"Equal time ({_mdf(et.get('time'))} s): "
                  + ", ".join(f"{_md(k)} RMSE {_mdf(v)}" for k, v in et["errors"].items()),
                  f"Equal error (RMSE {_mdf(ee.get('error'))}): "
                  + ", ".join(f"{_md(k)} {_mdf(v)} s" for k, v in ee["times"].items())]
    atomic_write_text(folder / "summary.md", "\n".join(lines) + "\n")
