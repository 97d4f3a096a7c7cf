"""The report of a suite run: ``DIR/index.html`` (one self-contained page), ``DIR/report.json`` (every number behind
it), ``DIR/summary.md``, and every image as EXR + PNG under ``DIR/report/``. See docs/report.md."""

from __future__ import annotations

import dataclasses
import json
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from harness.core import jsonsafe
from harness.core.errors import HarnessError
from harness.files.imageio import StagedFolder, WriteError, atomic_write_bytes, atomic_write_text, make_folders
from harness.studies import convergence as conv
from harness.studies import figures
from harness.studies import strategies as studies
from harness.report.html import Raw, badge, details, esc, fmt, image_figure, kv_table, page, plot_figure, pre, table
from harness.files.previews import ImageWriter, ReportImage, display_exposure, error_images
from harness.files.results import read_results

REPORT_SCHEMA = 1


@dataclass
class ReportOptions:
    """What a suite report computes besides its cases. The defaults are cheap (seconds for suites/smoke.toml)."""

    convergence: bool = True
    convergence_spp: tuple[int, ...] = conv.DEFAULT_SPP_LADDER
    #: besides the defaults, convergence curves of these `direct` strategies and (cached) Mitsuba
    convergence_strategies: tuple[str, ...] = ("mis", "hemisphere-cosine", "global-area")
    convergence_mitsuba: bool = True
    shadow_rays: bool = True
    shadow_ray_counts: tuple[int, ...] = studies.SHADOW_RAY_COUNTS
    strategies: bool = True
    render_strategies: bool = True  # render the strategies no case covers
    strategy_spp: int = studies.DEFAULT_STRATEGY_SPP
    k: float = conv.DEFAULT_K
    #: renders shorter than this are repeated for their timing (convergence, shadow rays); strategy renders this
    #: short are redone at 4x the spp
    min_timing_seconds: float = conv.MIN_TIMING_SECONDS
    strategy_min_seconds: float = studies.MIN_STRATEGY_SECONDS
    #: the studies (convergence, strategies) use each scene's smallest case film; the shadow-ray study the largest
    #: not above this many pixels
    max_study_pixels: int = 128 * 128
    cache_dir: str | None = None
    variant: str | None = None
    progress: bool = False


@dataclass
class Reference:
    image: np.ndarray
    variance: np.ndarray | None
    source: str
    spp: int
    path: Path | None = None


@dataclass
class LoadedCase:
    record: dict
    index: int
    slug: str
    case: Any = None  # harness.running.cases.Case
    scene: Any = None
    render: np.ndarray | None = None
    render_variance: np.ndarray | None = None
    gt: Reference | None = None
    images: list[ReportImage] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    summary: dict = field(default_factory=dict)


class _Progress:
    """A tqdm bar on stderr (when enabled) over the report's steps."""

    def __init__(self, enabled: bool, total: int):
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc="report", unit="step", file=sys.stderr, leave=False)

    def add(self, n: int) -> None:
        if self.bar is not None:
            self.bar.total += n
            self.bar.refresh()

    def step(self, description: str = "") -> None:
        if self.bar is not None:
            if description:
                self.bar.set_postfix_str(description[:40], refresh=False)
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


# ---- loading ---------------------------------------------------------------------------------------------------


def load_results(path: str | Path) -> dict:
    """A results.json, checked against its schema (docs/results-schema.md): any malformation is a one-line
    HarnessError naming the file and the JSON path of the bad key (:func:`harness.files.results.read_results`)."""
    return read_results(path)


def _suite_cases(results: dict) -> tuple[dict, str | None]:
    from harness.running.cases import load_suite

    suite_file = results.get("suite_file")
    if not suite_file:
        return {}, "results.json names no suite file"
    try:
        suite = load_suite(suite_file)
    except HarnessError as err:
        return {}, f"suite file not readable now ({err}); settings are taken from results.json"
    return {c.name: c for c in suite.cases}, None


def _existing(*candidates: Path | str | None) -> Path | None:
    for c in candidates:
        if c and Path(c).is_file():
            return Path(c)
    return None


def _case_scene(record: dict, case, shape: tuple[int, int] | None):
    """The scene a case rendered: from the suite's case when the suite file is readable, else from results.json
    (scene path, the render's size, the resolved max_depth)."""
    from harness.running.cases import Case
    from harness.running.judge import case_scene

    if case is None:
        settings = (record.get("render") or {}).get("settings") or {}
        depth = settings.get("max_depth") if isinstance(settings.get("max_depth"), int) else None
        film = {"width": shape[1], "height": shape[0]} if shape else None
        case = Case(name=record["name"], scene=Path(record["scene"]), renderer=record.get("renderer", "reference"),
                    film=film, max_depth=depth)
    scene = case_scene(case)
    if shape and (scene.film.height, scene.film.width) != tuple(shape):
        scene = conv.replace_film(scene, shape[1], shape[0])
    return case, scene


def _load_reference(item: LoadedCase, options: ReportOptions) -> Reference:
    from harness.renderers import groundtruth
    from harness.files.imageio import read_exr
    from harness.running.judge import ground_truth_for

    gt = item.record.get("ground_truth") or {}
    source = gt.get("source")
    if source == "closed-form":
        if item.scene is None:
            raise HarnessError(item.record["name"], "the closed form needs the scene, which is not readable")
        cf = groundtruth.closed_form(item.scene)
        return Reference(cf.image, cf.variance, "closed-form", 0, None)
    path = _existing(gt.get("path"))
    if path is not None:
        exr = read_exr(path)
        variance = exr.variance if exr.variance is not None else np.zeros_like(exr.image)
        return Reference(exr.image, variance, str(source), int(gt.get("spp") or 0), path)
    if item.case is None or item.scene is None:
        raise HarnessError(item.record["name"], "ground truth not found and the suite file is not readable")
    ref = ground_truth_for(item.case, item.scene, options.cache_dir, options.variant)
    variance = ref.variance if ref.variance is not None else np.zeros_like(ref.image)
    return Reference(ref.image, variance, ref.source, int(ref.spp), ref.path)


def _load_case(item: LoadedCase, results_dir: Path, options: ReportOptions) -> None:
    """Read a case's render and ground truth back (into ``item``); problems are noted, never raised."""
    from harness.files.imageio import read_exr
    from harness.running.cases import slug

    record = item.record
    if record.get("status") == "error" or not record.get("render"):
        item.problems.append("no render: the case ended in an error")
        return
    exr_path = _existing(record["render"].get("exr"), results_dir / "cases" / slug(record["name"]) / "render.exr")
    if exr_path is None:
        item.problems.append(f"render EXR not found ({record['render'].get('exr')})")
        return
    exr = read_exr(exr_path)
    item.render, item.render_variance = exr.image, exr.variance
    try:
        item.case, item.scene = _case_scene(record, item.case, exr.image.shape[:2])
    except HarnessError as err:  # the images can still be shown; the studies need the scene
        item.problems.append(f"scene unavailable (paths in results.json are relative to where harness run ran): "
                             f"{err}")
    try:
        item.gt = _load_reference(item, options)
    except HarnessError as err:
        item.problems.append(f"ground truth unavailable: {err}")
        return
    if item.gt.image.shape != item.render.shape:
        item.problems.append(f"ground truth is {item.gt.image.shape[1]}x{item.gt.image.shape[0]}, render "
                             f"{item.render.shape[1]}x{item.render.shape[0]}")
        item.gt = None


def _case_images(item: LoadedCase, out: Path) -> None:
    if item.render is None or item.gt is None:
        return
    writer = ImageWriter(out / "report" / item.slug, {"case": item.record["name"]})
    gt = item.gt
    exposure = display_exposure(gt.image)
    item.images.append(writer.radiance("ground_truth", "Ground truth", gt.image, gt.variance,
                                       description=f"{gt.source}" + (f", {gt.spp} spp" if gt.spp else ""),
                                       exposure=exposure))
    item.images.append(writer.radiance("render", "Render", item.render, item.render_variance,
                                       description=f"{item.record.get('renderer')}, "
                                                   f"{(item.record.get('render') or {}).get('spp')} spp",
                                       exposure=exposure))
    item.images.extend(error_images(writer, item.render, gt.image))
    point = conv.error_point(item.render, gt.image, gt.variance)
    by_key = {im.key: im for im in item.images}
    item.summary = {
        "mse": point["mse"], "floor_mse": point["floor_mse"], "mse_corrected": point["mse_corrected"],
        "mean_signed_error": by_key["error_signed"].stats.get("mean"),
        "mean_relative_error": by_key["error_relative"].stats.get("mean"),
        "flip_map_mean": by_key["flip"].stats.get("mean"),
    }


# ---- the report ------------------------------------------------------------------------------------------------


def write_suite_report(results: str | Path | dict, out_dir: str | Path | None = None,
                       options: ReportOptions | None = None) -> dict:
    """Write the report of a suite run. ``results``: the path of a results.json (checked against its schema:
    harness.files.results) or its content (then ``out_dir`` is required). Returns {"index", "report_json", "summary",
    "seconds"}.

    Everything is written into a staging folder and moved into ``out_dir`` at the end
    (:class:`harness.files.imageio.StagedFolder`): a report that fails (bad results, a full disk) leaves the folder as
    it was, an old report included. A write that fails is a :class:`harness.files.imageio.WriteError`, never a note in a
    section."""
    options = options or ReportOptions()
    start = time.perf_counter()
    if isinstance(results, dict):
        if out_dir is None:
            raise ValueError("out_dir is required when results are given as a dict")
        results_path = None
        results_dir = Path(out_dir)
    else:
        results_path = Path(results)
        results_dir = results_path.parent
    out = Path(out_dir) if out_dir is not None else results_dir
    with StagedFolder(out, "--out") as stage:  # first: an unwritable --out is named before any work
        if results_path is not None:
            results = load_results(results_path)
        page_html, doc, summary_md = _suite_report(results, results_path, results_dir, stage.root, options, start)
        atomic_write_text(stage.root / "report.json", jsonsafe.dumps(_relocate(doc, stage), indent=2))
        atomic_write_text(stage.root / "summary.md", stage.relocate(summary_md))
        atomic_write_text(stage.root / "index.html", stage.relocate(page_html).replace(esc(stage.root), esc(out)))
        stage.commit(last=("index.html",))  # the page last: whoever opens it finds every file it names
    return {"index": out / "index.html", "report_json": out / "report.json", "summary": out / "summary.md",
            "seconds": time.perf_counter() - start}


def _relocate(value: Any, stage) -> Any:
    """``value`` (report.json's content) with every staged path replaced by the path it is meant for."""
    if isinstance(value, dict):
        return {k: _relocate(v, stage) for k, v in value.items()}
    if isinstance(value, list):
        return [_relocate(v, stage) for v in value]
    if isinstance(value, str):
        return stage.relocate(value)
    return value


def _suite_report(results: dict, results_path: Path | None, results_dir: Path, out: Path, options: ReportOptions,
                  start: float) -> tuple[str, dict, str]:
    """The report's images and plots written under ``out``; returns the page, report.json's content and
    summary.md."""
    from harness.running.cases import slug

    records = results.get("cases", [])
    suite_cases, suite_note = _suite_cases(results)
    progress = _Progress(options.progress, len(records))
    timings: dict[str, float] = {}
    try:
        t0 = time.perf_counter()
        items, used = [], set()
        for index, record in enumerate(records):
            name = slug(str(record.get("name", f"case-{index}")))
            if name in used:
                name = f"{name}-{index}"
            used.add(name)
            item = LoadedCase(record=record, index=index, slug=name, case=suite_cases.get(record.get("name")))
            try:
                _load_case(item, results_dir, options)
                _case_images(item, out)
            except WriteError:
                raise
            except Exception as err:  # noqa: BLE001 - a broken case is reported in its section
                item.problems.append(f"{type(err).__name__}: {err}".splitlines()[0])
            items.append(item)
            progress.step(str(record.get("name", "")))
        timings["cases"] = time.perf_counter() - t0

        scenes = _scene_bases(items, options)
        sections: dict[str, Any] = {}
        if options.convergence:
            t0 = time.perf_counter()
            sections["convergence"] = _convergence_section(scenes, out, options, progress)
            timings["convergence"] = time.perf_counter() - t0
        if options.shadow_rays:
            t0 = time.perf_counter()
            sections["shadow_rays"] = _shadow_section(items, out, options, progress)
            timings["shadow_rays"] = time.perf_counter() - t0
        if options.strategies:
            t0 = time.perf_counter()
            sections["strategies"] = _strategies_section(items, scenes, out, options, progress)
            timings["strategies"] = time.perf_counter() - t0
    finally:
        progress.close()

    timings["total"] = time.perf_counter() - start
    doc = _report_json(results, results_path, items, sections, options, timings, suite_note)
    page_html = _suite_html(results, results_path, items, sections, options, suite_note)
    return page_html, doc, _summary_md(results, items, sections)


# ---- scenes and studies ----------------------------------------------------------------------------------------


def _scene_key(item: LoadedCase) -> str:
    return str(item.record.get("scene"))


def _scene_bases(items: list[LoadedCase], options: ReportOptions) -> dict[str, LoadedCase]:
    """Per scene, the case whose film and ground truth the studies use: its smallest film among cases with a
    ground truth (reference renderer first, default settings first)."""
    bases: dict[str, LoadedCase] = {}
    ranks: dict[str, tuple] = {}
    for item in items:
        if item.gt is None or item.scene is None:
            continue
        key = _scene_key(item)
        rank = (item.render.shape[0] * item.render.shape[1], item.record.get("renderer") != "reference",
                bool(item.record.get("settings")), item.index)
        if key not in ranks or rank < ranks[key]:
            ranks[key] = rank
            bases[key] = item
    return bases


def _convergence_section(bases: dict[str, LoadedCase], out: Path, options: ReportOptions, progress) -> dict:
    section = {"spp_ladder": list(options.convergence_spp), "k": options.k, "scenes": []}
    progress.add(len(bases) * len(options.convergence_spp) * (1 + len(options.convergence_strategies)
                                                              + int(options.convergence_mitsuba)))
    for key, base in bases.items():
        entry: dict[str, Any] = {"scene": key, "scene_name": Path(key).stem, "case": base.record["name"]}
        try:
            series = [conv.Series("reference", {}, "reference (defaults)")]
            series += [conv.Series("reference", {"direct": d}, f"reference direct={d}")
                       for d in options.convergence_strategies]
            if options.convergence_mitsuba:
                series.append(conv.Series("mitsuba", {}, "mitsuba (path, cached)"))
            from harness.renderers import get_renderer
            from harness.renderers.cached import CachedMitsubaRenderer

            def factory(name: str):
                if name == "mitsuba":
                    return CachedMitsubaRenderer(options.cache_dir, options.variant)
                return get_renderer(name)

            result = conv.run_convergence(base.scene, base.gt, series, spp=options.convergence_spp, seed=10_000,
                                          k=options.k, min_timing_seconds=options.min_timing_seconds,
                                          progress=progress.step, renderer_factory=factory,
                                          warmup=True)
            png = figures.convergence_figure(result, title=f"{Path(key).stem}: convergence")
            folder = out / "report" / "convergence"
            plot = folder / f"{_safe(Path(key).stem)}.png"
            _write_bytes(plot, png)
            entry.update(result=result, plot=str(plot), _png=png)
        except WriteError:
            raise
        except Exception as err:  # noqa: BLE001 - reported in the section
            entry["error"] = f"{type(err).__name__}: {err}".splitlines()[0]
            entry["traceback"] = traceback.format_exc(limit=6)
        section["scenes"].append(entry)
    return section


def _shadow_section(items: list[LoadedCase], out: Path, options: ReportOptions, progress) -> dict | None:
    candidates = [i for i in items if i.gt is not None and i.scene is not None
                  and any(s.name in studies.OCCLUDER_NAMES for s in i.scene.shapes)]
    if not candidates:
        return {"skipped": "no scene of the suite has a shape named 'occluder' (as scenes/soft-shadows.toml)"}

    def rank(i: LoadedCase):
        px = i.render.shape[0] * i.render.shape[1]
        return (px <= options.max_study_pixels, px if px <= options.max_study_pixels else -px,
                i.record.get("renderer") == "reference", not i.record.get("settings"))

    base = max(candidates, key=rank)
    progress.add(len(options.shadow_ray_counts))
    writer = ImageWriter(out / "report" / "shadow-rays", {"study": "shadow rays"})
    try:
        study, images, plots = studies.shadow_ray_study(base.scene, base.gt, writer, counts=options.shadow_ray_counts,
                                                        min_timing_seconds=options.min_timing_seconds,
                                                        progress=progress.step)
    except WriteError:
        raise
    except Exception as err:  # noqa: BLE001
        return {"error": f"{type(err).__name__}: {err}".splitlines()[0], "traceback": traceback.format_exc(limit=6)}
    for name, png in plots.items():
        _write_bytes(out / "report" / "shadow-rays" / f"{name}.png", png)
    study.update(case=base.record["name"], _images=images, _plots=plots,
                 plots={k: str(out / "report" / "shadow-rays" / f"{k}.png") for k in plots})
    return study


def _strategies_section(items: list[LoadedCase], bases: dict[str, LoadedCase], out: Path, options: ReportOptions,
                        progress) -> dict:
    defaults = studies.strategy_defaults()
    section: dict[str, Any] = {"defaults": defaults, "strategy_spp": options.strategy_spp, "scenes": []}
    for key, base in bases.items():
        case_rows = []
        for item in items:
            rec = item.record
            if (_scene_key(item) != key or item.gt is None or rec.get("renderer") != "reference"
                    or rec.get("status") not in ("pass", "fail") or (rec.get("against") or {}).get("kind") == "renderer"):
                continue
            mse = ((rec.get("metrics") or {}).get("rmse"))
            mse = mse**2 if isinstance(mse, (int, float)) else item.summary.get("mse")
            if mse is None:
                continue
            h, w = item.render.shape[:2]
            if (h, w) != tuple(base.render.shape[:2]):
                # per-pixel MSE depends on the pixel size (edges, lights): compare strategies at one film only
                continue
            case_rows.append({"case": rec["name"], "source": "case", "settings": dict(rec.get("settings") or {}),
                              "mse": float(mse), "floor_mse": item.summary.get("floor_mse") or 0.0,
                              "variance": studies.mean_variance(item.render_variance),
                              "seconds": float(rec["render"]["seconds"]), "pixels": int(h * w),
                              "spp": int(rec["render"].get("spp") or 0), "film": [w, h],
                              "timing": "the case's own", "_scene": item.scene})
        note = None
        if case_rows and all(studies.classify(r["settings"], defaults) in (None, "default") for r in case_rows) \
                and options.render_strategies:
            # no strategy case: render every row, the default too, so that all are timed alike
            case_rows = []
            note = "no case of this scene covers a strategy: every row, the default too, is rendered alike"
        bounded = base.scene.max_depth != -1
        seeds = iter(range(20_000, 30_000))

        def render(settings, scene=base.scene, gt=base.gt):
            row = studies.measure_render(scene, gt, settings, options.strategy_spp, next(seeds),
                                         min_seconds=options.strategy_min_seconds)
            progress.step("strategy " + " ".join(f"{k}={v}" for k, v in settings.items()))
            return row

        def retime(row):
            if row.get("_scene") is None:
                return row
            per_path, spp = studies.time_per_path(row["_scene"], row["settings"], options.strategy_spp, next(seeds),
                                                  options.strategy_min_seconds)
            progress.step("timing " + str(row.get("case")))
            return dict(row, case_seconds=row["seconds"], seconds=per_path * row["pixels"] * row["spp"],
                        timing=f"measured again by the report ({spp} spp, warm), scaled to the case's spp and film")

        wanted = 1 + sum(len(v) - 1 for v in studies.STRATEGIES.values())
        progress.add(wanted if options.render_strategies else 0)
        try:
            table_ = studies.strategy_rows(Path(key).stem, case_rows, render if options.render_strategies else None,
                                           bounded, defaults, retime=retime if options.render_strategies else None)
            png = figures.strategies_figure(table_["rows"], title=f"{Path(key).stem}: efficiency relative to default")
            folder = out / "report" / "strategies"
            plot = folder / f"{_safe(Path(key).stem)}.png"
            _write_bytes(plot, png)
            table_.update(scene_path=key, film=[base.scene.film.width, base.scene.film.height], plot=str(plot),
                          note=note, _png=png)
        except WriteError:
            raise
        except Exception as err:  # noqa: BLE001
            table_ = {"scene": Path(key).stem, "scene_path": key, "error": f"{type(err).__name__}: {err}".splitlines()[0],
                      "traceback": traceback.format_exc(limit=6)}
        section["scenes"].append(table_)
    return section


def _safe(name: str) -> str:
    from harness.running.cases import slug

    return slug(name)


def _write_bytes(path: Path, data: bytes) -> None:
    make_folders(path.parent)
    atomic_write_bytes(path, data)


def _strip_private(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _strip_private(v) for k, v in value.items() if not str(k).startswith("_")}
    if isinstance(value, list):
        return [_strip_private(v) for v in value]
    return value


# ---- report.json -----------------------------------------------------------------------------------------------


def _variant(record: dict) -> dict:
    render = record.get("render") or {}
    info = render.get("info") or {}
    gt = record.get("ground_truth") or {}
    return {"render": info.get("variant") or (render.get("settings") or {}).get("variant")
            if record.get("renderer") == "mitsuba" else None,
            "ground_truth": gt.get("variant")}


def _case_json(item: LoadedCase) -> dict:
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
        "error_maps": {k: v for k, v in item.summary.items() if not k.startswith("_")},
        "images": [im.to_json() for im in item.images],
        "problems": item.problems,
        "traceback": r.get("traceback"),
    }


def _report_json(results, results_path, items, sections, options, timings, suite_note) -> dict:
    return _strip_private({
        "schema": REPORT_SCHEMA,
        "kind": "suite-report",
        "generated": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "results_file": str(results_path) if results_path else None,
        "suite": results.get("suite"), "suite_file": results.get("suite_file"),
        "description": results.get("description"), "started": results.get("started"), "host": results.get("host"),
        "summary": results.get("summary"),
        "note": suite_note,
        "options": {k: v for k, v in dataclasses.asdict(options).items() if k not in ("progress",)},
        "definitions": DEFINITIONS,
        "cases": [_case_json(i) for i in items],
        "convergence": sections.get("convergence"),
        "shadow_rays": sections.get("shadow_rays"),
        "strategies": sections.get("strategies"),
        "timings": timings,
    })


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
    "efficiency": "1 / (MSE x render seconds per megapixel), relative to the default settings; MSE is the render's "
                  "own variance estimate (mean per-pixel variance of the mean), else the measured MSE_corrected",
    "equal_time": "the error each curve reaches at the longest time all curves cover (log-log interpolation; "
                  "outside a curve's range, along its log-log least-squares line, flagged as extrapolated)",
    "equal_error": "the time each curve needs to reach the smallest error all curves reach (log-log interpolation; "
                   "outside a curve's range, along its log-log least-squares line, flagged as extrapolated)",
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
    if not v:
        return []
    gb, om, mz = v.get("global_bias") or {}, v.get("omnibus") or {}, v.get("max_z") or {}
    wt, zv = v.get("worst_tile") or {}, v.get("zero_variance") or {}

    def triple(values):
        return ", ".join(fmt(x, 3) for x in values) if isinstance(values, list) else fmt(values)

    rows = [
        ("verdict", Raw(badge(v.get("verdict", "?")))),
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


def _case_html(item: LoadedCase) -> Raw:
    r = item.record
    anchor = f"case-{item.index}"
    parts = [f'<section class="case" id="{esc(anchor)}"><h3>{esc(r.get("name"))} '
             f'{badge(r.get("status", "?"), r.get("ok"))} <span class="muted">expected {esc(r.get("expect"))}</span>'
             f"</h3>"]
    if r.get("reason"):
        parts.append(f'<p class="note">{esc(r.get("reason"))}</p>')
    for problem in item.problems:
        parts.append(f'<p class="warn">{esc(problem)}</p>')
    if item.images:
        base = f"report/{item.slug}/"
        parts.append('<div class="images">' + "".join(image_figure(im, link_base=base) for im in item.images)
                     + "</div>")
    resolved = (r.get("render") or {}).get("settings")
    parts.append('<div class="columns">')
    parts.append("<div><h4>Metrics</h4>" + kv_table(_metrics_rows(r)) + "</div>")
    parts.append("<div><h4>Verdict</h4>" + kv_table(_verdict_rows(r.get("verdict") or {})) + "</div>")
    parts.append("<div><h4>Settings</h4>" + kv_table(_settings_rows(r)) + "</div>")
    parts.append("</div>")
    if resolved:
        parts.append(details("resolved settings (every setting the renderer used)", pre(json.dumps(resolved, indent=1))))
    if r.get("traceback"):
        parts.append(details("traceback", pre(r["traceback"])))
    parts.append("</section>")
    return Raw("".join(str(p) for p in parts))


def _summary_table(items: list[LoadedCase]) -> Raw:
    rows = []
    for item in items:
        r = item.record
        m = r.get("metrics") or {}
        link = Raw(f'<a href="#case-{item.index}">{esc(r.get("name"))}</a>')
        rows.append((link, Path(str(r.get("scene"))).stem, r.get("renderer"), Raw(badge(r.get("status", "?"))),
                     r.get("expect"), Raw("✔" if r.get("ok") else '<b style="color:#c00">✘</b>'), m.get("rmse"),
                     m.get("relmse"), m.get("flip"), (r.get("render") or {}).get("seconds"),
                     (r.get("reason") or "")[:120]))
    return table(["case", "scene", "renderer", "status", "expect", "ok", "RMSE", "relMSE", "FLIP", "time [s]",
                  "reason"], rows, cls="summary")


def convergence_tables(result: dict) -> Raw:
    """Fits per series, the points, and (with several series) equal-time and equal-error comparisons."""
    fit_rows = []
    for s in result["series"]:
        fr, fm = s["fit_rmse"], s["fit_relmse"]
        fit_rows.append((s["label"], fr.get("slope"), fr.get("slope_stderr"), fm.get("slope"),
                         "yes" if fr.get("biased") else "no",
                         fr.get("departure_spp"), (fr.get("model") or {}).get("bias")))
    parts = [table(["series", "slope log RMSE / log spp", "± stderr", "slope log relMSE / log spp",
                    "flattens (bias)", "leaves the -1/2 line at spp", "fitted bias level (RMSE)"], fit_rows)]
    for s in result["series"]:
        rows = [(p["spp"], p["seconds"], p["rmse"], p["rmse_corrected"], p["relmse"], p["relmse_corrected"],
                 p["floor_mse"], ", ".join(str(x) for x in p["seeds"][:4]) + ("…" if len(p["seeds"]) > 4 else ""))
                for p in s["points"]]
        parts.append(details(f"points: {s['label']}", table(
            ["spp", "time [s]", "RMSE", "RMSE (GT noise removed)", "relMSE", "relMSE (GT noise removed)",
             "GT noise floor (MSE)", "seeds"], rows)))
    comp = result.get("comparisons") or {}
    for metric, name in (("rmse_corrected", "RMSE"), ("relmse_corrected", "relMSE")):
        c = comp.get(metric)
        if not c:
            continue
        et, ee = c["equal_time"], c["equal_error"]
        def mark(value, flag):
            return Raw(f"{esc(fmt(value))} <i>(extrapolated)</i>") if flag and value is not None else value

        rows = [(label, mark(et["errors"].get(label), et.get("extrapolated", {}).get(label)),
                 et["ratio_to_first"].get(label),
                 mark(ee["times"].get(label), ee.get("extrapolated", {}).get(label)),
                 ee["speedup_vs_first"].get(label)) for label in et["errors"]]
        parts.append(Raw(f"<p><b>Equal time</b> ({esc(name)} at {esc(fmt(et.get('time')))} s) and <b>equal error</b> "
                         f"(time to {esc(name)} {esc(fmt(ee.get('error')))}), read off the curves in log-log "
                         f"(outside a curve's range: along its own log-log least-squares line, marked "
                         f"extrapolated):</p>"))
        parts.append(table(["series", f"{name} at equal time", "ratio to first", "time to equal error [s]",
                            "speed-up vs first"], rows))
    return Raw("".join(str(p) for p in parts))


def _convergence_html(section: dict) -> Raw:
    parts = ['<section id="convergence"><h2>Convergence</h2>',
             f'<p class="note">Each scene rendered by each series (the reference renderer with its defaults and '
             f"with other direct-light strategies, and Mitsuba through the ground-truth cache) at "
             f'{esc(", ".join(str(n) for n in section["spp_ladder"]))} spp, each render with its own seed, at the film '
             f"of the scene's smallest case, compared with that case's ground truth. The ground truth's own noise is "
             f"subtracted from every MSE (dotted: its level). Dashed: the line of slope -1/2 (RMSE) or -1 (relMSE) "
             f"anchored on the points before any departure; a red ring marks a point from which the curve stays "
             f"more than k = {esc(fmt(section['k']))} expected scatters above it (bias).</p>"]
    for entry in section["scenes"]:
        parts.append(f"<h3>{esc(entry['scene_name'])} <span class=\"muted\">(film and ground truth of case "
                     f"{esc(entry['case'])})</span></h3>")
        if entry.get("error"):
            parts.append(f'<p class="warn">convergence failed: {esc(entry["error"])}</p>')
            continue
        parts.append(plot_figure(_uri(entry["_png"]), f"convergence of {entry['scene_name']}"))
        parts.append(convergence_tables(entry["result"]))
    parts.append("</section>")
    return Raw("".join(str(p) for p in parts))


def _uri(png: bytes) -> str:
    import base64

    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def _shadow_html(study: dict | None) -> Raw:
    parts = ['<section id="shadow-rays"><h2>Noise against shadow rays</h2>']
    if not study or study.get("skipped") or study.get("error"):
        reason = (study or {}).get("skipped") or (study or {}).get("error") or "not run"
        parts.append(f'<p class="warn">{esc(reason)}</p></section>')
        return Raw("".join(parts))
    pen = study["penumbra"]
    parts.append(
        f'<p class="note">{esc(Path(study["scene"]).stem)} at {study["film"][0]}x{study["film"][1]} (film and '
        f"ground truth of case {esc(study['case'])}), one viewing ray per pixel (spp = 1) and N shadow rays, as "
        f"in the slides' Figure 5.9. Penumbra: {pen['pixels']} pixels ({pen['fraction']:.1%}) whose ground truth "
        f"lies strictly between {pen['low']:.0%} and {pen['high']:.0%} of the fully lit level "
        f"({esc(pen.get('fully_lit'))}"
        + (f"; {pen.get('occluder_pixels')} pixels that see the occluder are left out" if pen.get("method") ==
           "per-pixel" else "")
        + "). With one viewing ray per pixel, the variance from where that ray lands in its pixel does not fall "
          "with N: where the radiance varies inside a pixel (shadow edges, the occluder's outline) the error levels "
          "off at large N, however unbiased the direct-light estimate. At a small film a render's time is mostly "
          "fixed per-call cost.</p>")
    parts.append(plot_figure(_uri(study["_plots"]["panel"]), "renders with N shadow rays"))
    parts.append(plot_figure(_uri(study["_plots"]["curves"]), "RMSE and time against shadow rays"))
    rows = [(r["shadow_rays"], r["penumbra"]["rmse"], r["penumbra"]["rmse_corrected"], r["image"]["rmse"],
             r["seconds"], (r.get("rays") or {}).get("shadow")) for r in study["rows"]]
    parts.append(table(["shadow rays", "RMSE penumbra", "RMSE penumbra (GT noise removed)", "RMSE image",
                        "time [s]", "shadow rays traced"], rows))
    fit = study.get("fit") or {}
    parts.append(Raw(f"<p>Fitted slope of log RMSE (penumbra) against log N: {esc(fmt(fit.get('slope')))}"
                     + (f"; leaves the -1/2 line at N = {esc(fmt(fit.get('departure_spp')))}" if fit.get("biased")
                        else "") + ".</p>"))
    figs = "".join(image_figure(im, width=160, link_base="report/shadow-rays/") for im in study["_images"])
    parts.append(details("every image of the study (EXR + PNG)", Raw(f'<div class="images">{figs}</div>')))
    parts.append("</section>")
    return Raw("".join(str(p) for p in parts))


def _strategies_html(section: dict) -> Raw:
    parts = ['<section id="strategies"><h2>Sampling strategies</h2>',
             f'<p class="note">Each strategy of the reference renderer (one setting changed from the defaults '
             f"{esc(' '.join(f'{k}={v}' for k, v in section['defaults'].items()))}): its MSE, render time and "
             f"efficiency = 1 / (MSE x seconds per megapixel), relative to the default. The MSE is the render's own "
             f"variance estimate (the mean of its per-pixel variance of the mean: the expected MSE of an unbiased "
             f"estimator, far less noisy than a difference with a noisy ground truth); the MSE measured against the "
             f"ground truth, its noise removed, is shown beside it as a check (much larger: bias). "
             f"Measurements come from the suite's cases where one covers the strategy (their MSE; their time is "
             f"measured again, warm, and scaled to the case's spp and film, since a run's first case of a kind also "
             f"pays one-off costs); the others are rendered at {esc(section['strategy_spp'])} spp (more while a render "
             f"takes under 0.05 s) at the film of the scene's smallest case. Time is per pixel, so cases at different "
             f"films compare.</p>"]
    for entry in section["scenes"]:
        parts.append(f"<h3>{esc(entry['scene'])}</h3>")
        if entry.get("error"):
            parts.append(f'<p class="warn">{esc(entry["error"])}</p>')
            continue
        if entry.get("note"):
            parts.append(Raw(f'<p class="muted">{esc(entry["note"])}</p>'))
        if entry.get("best"):
            near = [n for n in entry.get("near_best") or [] if n != entry["best"]]
            parts.append(Raw(f"<p>Best: <b>{esc(entry['best'])}</b> (efficiency "
                             f"{esc(fmt(entry['best_relative_efficiency'], 3))} x the default)"
                             + (f"; within {esc(fmt(entry['tie_factor']))} x of it, not told apart by this measurement: "
                                f"{esc(', '.join(near))}" if near else "") + "</p>"))
        rows = []
        for r in entry["rows"]:
            if "skipped" in r:
                rows.append((r["label"], "–", "–", "–", "–", "–", "–", "–", r["skipped"]))
                continue
            if r.get("case"):
                source = f"case {r['case']}"
                if r.get("case_seconds") is not None:
                    source += f"; time measured again (the case's own: {fmt(r['case_seconds'], 3)} s)"
            else:
                source = f"rendered ({r['spp']} spp)"
            rows.append((Raw(f"<b>{esc(r['label'])}</b>") if r["label"] == entry.get("best") else r["label"],
                         r.get("mse_estimate"), r.get("mse_corrected"), r.get("relative_mse"), r["seconds"],
                         r.get("seconds_per_megapixel"), r.get("efficiency"), r.get("relative_efficiency"),
                         f"{r['film'][0]}x{r['film'][1]}, {r['spp']} spp", source))
        parts.append(table(["strategy", "MSE (render variance)", "MSE measured (GT noise removed)", "MSE / default",
                            "time [s]", "s / Mpx", "efficiency", "efficiency / default", "film, spp", "source"], rows))
        parts.append(plot_figure(_uri(entry["_png"]), f"efficiency of the strategies on {entry['scene']}"))
    parts.append("</section>")
    return Raw("".join(str(p) for p in parts))


def _suite_html(results, results_path, items, sections, options, suite_note) -> str:
    s = results.get("summary") or {}
    host = results.get("host") or {}
    nav = ['<a href="#cases">cases</a>']
    for key, label in (("convergence", "convergence"), ("shadow_rays", "shadow rays"), ("strategies", "strategies")):
        if key in sections:
            nav.append(f'<a href="#{key.replace("_", "-")}">{label}</a>')
    nav.append('<a href="#definitions">definitions</a>')
    body: list[Any] = [
        Raw(f"<p>{esc(results.get('description') or '')}</p>"),
        Raw("<nav>" + " ".join(nav) + "</nav>"),
        Raw(f"<p><b>{esc(s.get('ok'))}/{esc(s.get('cases'))}</b> cases as expected ({esc(s.get('passed'))} passed, "
            f"{esc(s.get('failed'))} failed, {esc(s.get('errors'))} errors); {esc(s.get('mitsuba_renders'))} Mitsuba "
            f"renders; suite wall time {esc(fmt(s.get('wall_seconds')))} s.</p>"),
    ]
    if s.get("unexpected"):
        body.append(Raw(f'<p class="warn">Not as expected: {esc(", ".join(s["unexpected"]))}</p>'))
    if suite_note:
        body.append(Raw(f'<p class="warn">{esc(suite_note)}</p>'))
    body.append(Raw('<section id="cases"><h2>Cases</h2>'))
    body.append(_summary_table(items))
    body.extend(_case_html(i) for i in items)
    body.append(Raw("</section>"))
    if "convergence" in sections:
        body.append(_convergence_html(sections["convergence"]))
    if "shadow_rays" in sections:
        body.append(_shadow_html(sections["shadow_rays"]))
    if "strategies" in sections:
        body.append(_strategies_html(sections["strategies"]))
    body.append(Raw('<section id="definitions"><h2>Definitions</h2>'
                    + kv_table(sorted(DEFINITIONS.items())) + "</section>"))
    subtitle = (f"suite file {results.get('suite_file')} · started {results.get('started')} · host "
                f"{host.get('node')} ({host.get('machine')}, Python {host.get('python')})"
                + (f" · results {results_path}" if results_path else ""))
    return page(f"Suite report: {results.get('suite', '?')}", body, subtitle=subtitle)


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
                lines.append(f"- {_md(e['scene_name'])}, {_md(series['label'])}: slope {_mdf(f.get('slope'), 3)}; "
                             f"{flag}")
    sr = sections.get("shadow_rays")
    if sr and sr.get("rows"):
        lines += ["", "## Noise against shadow rays (spp = 1)", "",
                  "| shadow rays | RMSE penumbra | time [s] |", "|---|---|---|"]
        for r in sr["rows"]:
            lines.append(f"| {_mdf(r['shadow_rays'])} | {_mdf(r['penumbra']['rmse_corrected'])} | "
                         f"{_mdf(r['seconds'], 3)} |")
    st = sections.get("strategies")
    if st:
        lines += ["", "## Best strategy per scene (efficiency relative to the default)", ""]
        for e in st["scenes"]:
            if e.get("error"):
                lines.append(f"- {_md(e['scene'])}: failed ({_md(e['error'])})")
            else:
                near = [n for n in e.get("near_best") or [] if n != e.get("best")]
                lines.append(f"- {_md(e['scene'])}: {_md(e.get('best'))} "
                             f"({_mdf(e.get('best_relative_efficiency'), 3)} x the default)"
                             + (f"; within {_mdf(e.get('tie_factor'))} x: {_md(', '.join(near))}" if near else ""))
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
    plot = out / "convergence.png"
    with StagedFolder(out, "--out") as stage:
        _write_convergence_files(result, stage.root, title, png, plot)
        stage.commit(last=("index.html",))
    return {"index": out / "index.html", "report_json": out / "convergence.json", "summary": out / "summary.md",
            "plot": plot}


def _write_convergence_files(result: dict, folder: Path, title: str, png: bytes, plot: Path) -> None:
    """The files of :func:`write_convergence_report` written into ``folder``; ``plot`` is where the plot will be."""
    _write_bytes(folder / plot.name, png)
    gt = result["ground_truth"]
    doc = dict(result, schema=REPORT_SCHEMA, kind="convergence", generated=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
               plot=str(plot), definitions={k: DEFINITIONS[k] for k in ("mse_corrected", "convergence_fit",
                                                                         "equal_time", "equal_error")})
    body = [
        Raw(f'<p class="note">Scene {esc(result.get("scene"))} at {result["film"][0]}x{result["film"][1]}, max_depth '
            f"{esc(result.get('max_depth'))}; ground truth: {esc(gt['source'])}"
            + (f", {esc(gt['spp'])} spp" if gt.get("spp") else "")
            + f". spp ladder {esc(', '.join(str(n) for n in result['spp_ladder']))}"
            + (f"; seconds ladder {esc(', '.join(fmt(s) for s in result['seconds_ladder']))}"
               if result.get("seconds_ladder") else "")
            + f"; every render with its own seed. k = {esc(fmt(result['k']))}. "
            + esc(DEFINITIONS["convergence_fit"]) + ".</p>"),
        plot_figure(_uri(png), "convergence plots"),
        convergence_tables(result),
        Raw('<h2 id="definitions">Definitions</h2>' + kv_table(sorted(doc["definitions"].items()))),
    ]
    atomic_write_text(folder / "index.html", page(title, body))
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
