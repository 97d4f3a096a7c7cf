"""The studies of a suite run, besides its cases (docs/report.md): per scene a convergence study (error against spp
and time for the reference renderer's strategies, Mitsuba and every other renderer of the scene's cases), noise
against the number of shadow rays (a scene with an occluder), and the efficiency of every sampling strategy of the
reference renderer (with, beside it, each other renderer's own efficiency: it takes no settings to vary).

They render and time, so ``harness run`` runs them after its suite (``harness report --studies`` too), and
:func:`write_suite_studies` writes what they find into ``OUT/studies/``: ``studies.json`` (every number, paths
relative to that folder), the shadow-ray study's images (EXR + PNG, ``shadow-rays/``) and the plots (PNG,
``convergence/<scene>.png``, ``strategies/<scene>.png``, ``shadow-rays/{panel,curves}.png``), all moved into place
together (:class:`harness.files.imageio.StagedFolder`). The report (:mod:`harness.report`) only formats them.

Each study measures against the ground truth the run recorded for a case (``ground_truth.path`` in results.json,
:func:`harness.files.cases.read_case_images`), at that case's film.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import time
import traceback
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from harness.core import jsonsafe
from harness.core.errors import HarnessError
from harness.core.progress import Progress
from harness.files.cases import GroundTruthImage, read_case_images, slug
from harness.files.imageio import StagedFolder, WriteError, atomic_write_bytes, atomic_write_text, make_folders
from harness.files.previews import ImageWriter
from harness.files.studies import STUDIES_FILE, STUDIES_KIND, STUDIES_SCHEMA, studies_folder
from harness.judges.floor import error_point
from harness.renderers import get_renderer
from harness.renderers.cached import CachedMitsubaRenderer
from harness.running.cases import SUITE_REPLICATES, Case, judged_settings, load_suite
from harness.running.judge import case_scene
from harness.studies import convergence as conv
from harness.studies import figures
from harness.studies import strategies as studies
from harness.studies.regions import region_masks, region_variances
from reference_impl.settings import GLOSSY_DIRECT

#: the sections of studies.json, in the order the report shows them
SECTIONS = ("convergence", "shadow_rays", "strategies")
#: renderers the studies build in; any other renderer of a suite's cases (a renderer file, an entry point) gets
#: its own convergence curve and a line of its own in the strategy and shadow-ray sections
BUILT_IN = ("reference", "mitsuba")
#: why an external renderer has no strategy or shadow-ray rows (docs/report.md, "Other renderers")
NO_SETTINGS = ("takes no settings (the harness cannot change its sampling strategy or shadow rays): the rows vary "
               "the reference renderer's settings")


@dataclass
class StudyOptions:
    """What the studies of a suite run compute. The defaults are cheap (seconds for suites/smoke.toml)."""

    convergence: bool = True
    convergence_spp: tuple[int, ...] = conv.DEFAULT_SPP_LADDER
    #: besides the defaults, convergence curves of these `direct` strategies and (cached) Mitsuba; in scenes with
    #: a material that is not diffuse (direct = area, mis, bsdf there) those of the second tuple
    convergence_strategies: tuple[str, ...] = ("mis", "hemisphere-cosine", "global-area")
    glossy_convergence_strategies: tuple[str, ...] = tuple(d for d in GLOSSY_DIRECT if d != "mis")  # mis: default
    convergence_mitsuba: bool = True
    shadow_rays: bool = True
    shadow_ray_counts: tuple[int, ...] = studies.SHADOW_RAY_COUNTS
    strategies: bool = True
    render_strategies: bool = True  # render the strategies no case covers
    strategy_spp: int = studies.DEFAULT_STRATEGY_SPP
    #: independent renders (seeds) of each strategy at each budget (equal spp, equal time)
    strategy_repeats: int = studies.STRATEGY_REPEATS
    k: float = conv.DEFAULT_K
    #: renders shorter than this are repeated for their timing (convergence, shadow rays); strategy renders this
    #: short are redone at 2x the spp
    min_timing_seconds: float = conv.MIN_TIMING_SECONDS
    strategy_min_seconds: float = studies.MIN_STRATEGY_SECONDS
    #: the studies (convergence, strategies) use each scene's smallest case film; the shadow-ray study the largest
    #: not above this many pixels
    max_study_pixels: int = 128 * 128
    cache_dir: str | None = None
    variant: str | None = None
    progress: bool = False

    def to_json(self) -> dict:
        return {k: v for k, v in dataclasses.asdict(self).items() if k != "progress"}


@dataclass
class StudyCase:
    """A case of the run as the studies use it: its record, render and ground truth read back, its scene."""

    record: dict
    index: int
    case: Any = None  # harness.running.cases.Case, where the suite file is readable
    scene: Any = None
    render: np.ndarray | None = None
    render_variance: np.ndarray | None = None
    gt: GroundTruthImage | None = None
    point: dict = field(default_factory=dict)  # error_point of the render against its ground truth
    problems: list[str] = field(default_factory=list)


def write_suite_studies(results: dict, results_dir: str | Path, options: StudyOptions | None = None, *,
                        out_dir: str | Path | None = None, results_file: str | Path | None = None) -> dict:
    """Compute the studies of a run (``results``: its results.json content, checked; ``results_dir``: its folder,
    where its case files are) and write them into ``out_dir`` (default :func:`studies_folder`), all or nothing.

    Returns {"studies_json", "folder", "seconds"}. A study that fails in its own code is reported in its section;
    a write that fails is a :class:`harness.files.imageio.WriteError` (nothing is left half-written)."""
    options = options or StudyOptions()
    start = time.perf_counter()
    target = Path(out_dir) if out_dir is not None else studies_folder(results_dir)
    with StagedFolder(target, str(target), replace_link=True) as stage:  # a link at studies/ is not followed
        doc = _studies(results, Path(results_dir), stage.root, options)
        doc.update(results_file=str(results_file) if results_file else None,
                   timings=dict(doc["timings"], total=time.perf_counter() - start))
        atomic_write_text(stage.root / STUDIES_FILE, jsonsafe.dumps(_strip_private(doc), indent=2))
        stage.commit(last=(STUDIES_FILE,))  # the file that names the others last
    return {"studies_json": target / STUDIES_FILE, "folder": target, "seconds": time.perf_counter() - start}


class _Plots:
    """The plots of the studies, drawn after every render and timing is done, in parallel processes (matplotlib
    holds the GIL and costs about a second a plot on a shared 2-core machine: a third of the studies' time on
    suites/smoke.toml, drawn one by one between the renders)."""

    def __init__(self):
        self.jobs: list[tuple[Path, dict, Any, tuple, dict]] = []

    def add(self, path: Path, entry: dict, fn, *args, **kwargs) -> None:
        """Draw ``fn(*args, **kwargs)`` (PNG bytes) into ``path`` later; a failure is noted in ``entry``."""
        self.jobs.append((path, entry, fn, _strip_private(args), kwargs))

    def draw(self) -> None:
        """Draw every plot (in up to 2 worker processes; one by one where no process can be started) and write
        it; a plot that fails leaves ``plot`` None and its reason in ``plot_error``."""
        workers = min(2, os.cpu_count() or 1, len(self.jobs))
        results: list = []
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            try:  # fork: the workers need no imports of their own (spawn would pay seconds for matplotlib)
                with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
                    futures = [pool.submit(fn, *args, **kwargs) for _, _, fn, args, kwargs in self.jobs]
                    results = [_outcome(f) for f in futures]
            except OSError:
                results = []
        if len(results) != len(self.jobs):
            results = [_call(fn, *args, **kwargs) for _, _, fn, args, kwargs in self.jobs]
        for (path, entry, *_), (png, error) in zip(self.jobs, results):
            if error is not None:
                entry.update(plot=None, plot_error=error)
            else:
                _write_bytes(path, png)


def _outcome(future) -> tuple[bytes | None, str | None]:
    try:
        return future.result(), None
    except Exception as err:  # noqa: BLE001 - a plot that fails is noted in its section
        return None, f"{type(err).__name__}: {err}".splitlines()[0]


def _call(fn, *args, **kwargs) -> tuple[bytes | None, str | None]:
    try:
        return fn(*args, **kwargs), None
    except Exception as err:  # noqa: BLE001 - a plot that fails is noted in its section
        return None, f"{type(err).__name__}: {err}".splitlines()[0]


def _studies(results: dict, results_dir: Path, out: Path, options: StudyOptions) -> dict:
    records = results.get("cases", [])
    suite_cases, suite_note = _suite_cases(results, options.cache_dir)
    progress = Progress(options.progress, len(records), "studies")
    timings: dict[str, float] = {}
    sections: dict[str, Any] = {}
    plots = _Plots()
    try:
        t0 = time.perf_counter()
        wanted = options.convergence or options.shadow_rays or options.strategies
        studied = [(i, r) for i, r in enumerate(records if wanted else [])
                   if getattr(suite_cases.get(r.get("name")), "studies", True)]  # a case's `studies = false` leaves it out
        items = [_load_case(StudyCase(record=r, index=i, case=suite_cases.get(r.get("name"))), results_dir, progress)
                 for i, r in studied]
        timings["cases"] = time.perf_counter() - t0
        bases = _scene_bases(items)
        if options.convergence:
            t0 = time.perf_counter()
            sections["convergence"] = _convergence_section(bases, out, options, progress, items, plots)
            timings["convergence"] = time.perf_counter() - t0
        if options.shadow_rays:
            t0 = time.perf_counter()
            sections["shadow_rays"] = _shadow_section(items, out, options, progress)
            timings["shadow_rays"] = time.perf_counter() - t0
        if options.strategies:
            t0 = time.perf_counter()
            sections["strategies"] = _strategies_section(items, bases, out, options, progress, plots)
            timings["strategies"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        plots.draw()
        timings["plots"] = time.perf_counter() - t0
    finally:
        progress.close()
    return {
        "schema": STUDIES_SCHEMA, "kind": STUDIES_KIND, "generated": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "suite": results.get("suite"), "suite_file": results.get("suite_file"), "started": results.get("started"),
        "note": suite_note, "options": options.to_json(),
        "cases": [{"name": i.record.get("name"), "problems": i.problems} for i in items],
        **{key: sections.get(key) for key in SECTIONS},
        "timings": timings,
    }


# ---- the cases, their scenes and ground truths ------------------------------------------------------------------


def _suite_cases(results: dict, cache_dir=None) -> tuple[dict, str | None]:
    suite_file = results.get("suite_file")
    if not suite_file:
        return {}, "results.json names no suite file"
    try:
        suite = load_suite(suite_file, cache_dir)
    except HarnessError as err:
        return {}, f"suite file not readable now ({err}); settings are taken from results.json"
    return {c.name: c for c in suite.cases}, None


def _case_scene(record: dict, case, shape: tuple[int, int] | None):
    """The scene a case rendered: from the suite's case when the suite file is readable, else from results.json
    (scene path, the render's size, the resolved max_depth)."""
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


def _load_case(item: StudyCase, results_dir: Path, progress: Progress) -> StudyCase:
    """The case's render and ground truth read back and its scene built (into ``item``); problems are noted, never
    raised."""
    try:
        images = read_case_images(item.record, results_dir)
        if images.render is not None and images.ground_truth is not None:
            try:
                item.case, item.scene = _case_scene(item.record, item.case, images.render.shape[:2])
            except HarnessError as err:
                item.problems.append(f"scene unavailable (paths in results.json are relative to where harness run "
                                     f"ran): {err}")
            item.render, item.render_variance, item.gt = images.render, images.render_variance, images.ground_truth
            item.point = error_point(item.render, item.gt.image, item.gt.variance)
    except Exception as err:  # noqa: BLE001 - a broken case is left out of the studies, and says why
        item.problems.append(f"{type(err).__name__}: {err}".splitlines()[0])
    progress.step(str(item.record.get("name", "")))
    return item


def _scene_key(item: StudyCase) -> str:
    return str(item.record.get("scene"))


def _other_renderers(items: list[StudyCase], key: str) -> list[StudyCase]:
    """The cases of scene ``key`` rendered by a renderer other than the built-in ones, that rendered (one per
    renderer: the first)."""
    seen: dict[str, StudyCase] = {}
    for item in items:
        renderer = item.record.get("renderer")
        if (_scene_key(item) == key and renderer not in BUILT_IN and item.render is not None
                and item.record.get("status") in ("pass", "fail")):
            seen.setdefault(str(renderer), item)
    return list(seen.values())


def renderer_label(name: str) -> str:
    """A renderer's name as the studies show it: a renderer file by its stem."""
    return Path(name).stem if name.endswith(".toml") or "/" in name else name


def _scene_bases(items: list[StudyCase]) -> dict[str, StudyCase]:
    """Per scene, the case whose film and ground truth the studies use: its smallest film among cases with a
    ground truth (reference renderer first, default settings first)."""
    bases: dict[str, StudyCase] = {}
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


# ---- the studies -------------------------------------------------------------------------------------------------


def _convergence_section(bases: dict[str, StudyCase], out: Path, options: StudyOptions, progress,
                         items: list[StudyCase] = (), plots: _Plots | None = None) -> dict:
    section = {"spp_ladder": list(options.convergence_spp), "k": options.k, "scenes": []}
    others = {key: _other_renderers(list(items), key) for key in bases}
    def strategies(base: StudyCase) -> tuple[str, ...]:
        glossy = base.scene is not None and base.scene.has_glossy_materials
        return options.glossy_convergence_strategies if glossy else options.convergence_strategies

    progress.add(sum(len(options.convergence_spp) * (1 + len(strategies(base))
                                                     + int(options.convergence_mitsuba) + len(others[key]))
                     for key, base in bases.items()))

    def factory(name: str):
        if name == "mitsuba":
            return CachedMitsubaRenderer(options.cache_dir, options.variant)
        return get_renderer(name)

    for key, base in bases.items():
        entry: dict[str, Any] = {"scene": key, "scene_name": Path(key).stem, "case": base.record["name"]}
        try:
            series = [conv.Series("reference", {}, "reference (defaults)")]
            series += [conv.Series("reference", {"direct": d}, f"reference direct={d}")
                       for d in strategies(base)]
            if options.convergence_mitsuba:
                series.append(conv.Series("mitsuba", {}, "mitsuba (path, cached)"))
            series += [conv.Series(str(o.record["renderer"]), {}, renderer_label(str(o.record["renderer"])))
                       for o in others[key]]
            result = conv.run_convergence(base.scene, base.gt, series, spp=options.convergence_spp, seed=10_000,
                                          k=options.k, min_timing_seconds=options.min_timing_seconds,
                                          progress=progress.step, renderer_factory=factory, warmup=True)
            plot = f"convergence/{slug(Path(key).stem)}.png"
            entry.update(result=result, plot=plot)
            _plot(plots, out / plot, entry, figures.convergence_figure, result, title=f"{Path(key).stem}: convergence")
        except WriteError:
            raise
        except Exception as err:  # noqa: BLE001 - reported in the section
            entry["error"] = f"{type(err).__name__}: {err}".splitlines()[0]
            entry["traceback"] = traceback.format_exc(limit=6)
        section["scenes"].append(entry)
    return section


def _shadow_section(items: list[StudyCase], out: Path, options: StudyOptions, progress) -> dict:
    candidates = [i for i in items if i.gt is not None and i.scene is not None
                  and any(s.name in studies.OCCLUDER_NAMES for s in i.scene.shapes)]
    if not candidates:
        return {"skipped": "no scene of the suite has a shape named 'occluder' (as scenes/soft-shadows.toml)"}

    def rank(i: StudyCase):
        px = i.render.shape[0] * i.render.shape[1]
        return (px <= options.max_study_pixels, px if px <= options.max_study_pixels else -px,
                i.record.get("renderer") == "reference", not i.record.get("settings"))

    base = max(candidates, key=rank)
    progress.add(len(options.shadow_ray_counts))
    folder = "shadow-rays"
    writer = ImageWriter(out / folder, {"study": "shadow rays"})
    try:
        study, images, plots = studies.shadow_ray_study(base.scene, base.gt, writer, counts=options.shadow_ray_counts,
                                                        min_timing_seconds=options.min_timing_seconds,
                                                        progress=progress.step)
    except WriteError:
        raise
    except Exception as err:  # noqa: BLE001
        return {"error": f"{type(err).__name__}: {err}".splitlines()[0], "traceback": traceback.format_exc(limit=6)}
    for name, png in plots.items():
        _write_bytes(out / folder / f"{name}.png", png)
    other = sorted({renderer_label(str(i.record.get("renderer"))) for i in candidates
                    if i.record.get("renderer") not in BUILT_IN})
    if other:
        study["other_renderers"] = {"renderers": other, "note": f"{', '.join(other)} {NO_SETTINGS}"}
    study.update(case=base.record["name"], plots={k: f"{folder}/{k}.png" for k in plots},
                 images=[dict(im.to_json(), exr=f"{folder}/{im.exr.name}", png=f"{folder}/{im.png_path.name}")
                         for im in images])
    return study


def _case_rows(items: list[StudyCase], key: str, base: StudyCase, masks: dict | None = None) -> list[dict]:
    """The measurements of a scene's reference cases that compared with a ground truth (not another renderer), at
    the base case's film: the strategy table's rows where one covers a strategy."""
    rows = []
    for item in items:
        rec = item.record
        if (_scene_key(item) != key or item.gt is None or rec.get("renderer") != "reference"
                or rec.get("status") not in ("pass", "fail") or (rec.get("against") or {}).get("kind") == "renderer"):
            continue
        mse = (rec.get("metrics") or {}).get("rmse")
        mse = mse**2 if isinstance(mse, (int, float)) else item.point.get("mse")
        if mse is None:
            continue
        h, w = item.render.shape[:2]
        if (h, w) != tuple(base.render.shape[:2]):
            # per-pixel MSE depends on the pixel size (edges, lights): compare strategies at one film only
            continue
        rows.append({"case": rec["name"], "source": "case", "settings": _strategy_settings(rec.get("settings") or {}),
                     "mse": float(mse), "floor_mse": item.point.get("floor_mse") or 0.0,
                     "variance": studies.mean_variance(item.render_variance),
                     "level": studies.image_level(item.gt.image),
                     "seconds": float(rec["render"]["seconds"]), "pixels": int(h * w),
                     "spp": int(rec["render"].get("spp") or 0), "film": [w, h],
                     "timing": "the case's own", "_scene": item.scene,
                     "variance_regions": region_variances(item.render_variance, masks or {})})
    return rows


def _strategy_settings(settings: dict) -> dict:
    """A case's settings as a strategy row names them: without the replicates every suite case of the reference
    has (:func:`harness.running.cases.judged_settings`), which are not a strategy."""
    return {k: v for k, v in settings.items() if not (k == "replicates" and v == str(SUITE_REPLICATES))}


def _strategies_section(items: list[StudyCase], bases: dict[str, StudyCase], out: Path, options: StudyOptions,
                        progress, plots: _Plots | None = None) -> dict:
    defaults = studies.strategy_defaults()
    section: dict[str, Any] = {"defaults": defaults, "strategy_spp": options.strategy_spp,
                               "strategy_repeats": options.strategy_repeats, "scenes": []}
    lambertian_defaults = defaults
    for key, base in bases.items():
        glossy = base.scene.has_glossy_materials  # direct = auto is "mis" there, and the rows are a glossy scene's
        defaults = studies.strategy_defaults(glossy) if glossy else lambertian_defaults
        masks = region_masks(base.scene, tuple(base.render.shape[:2])) if base.scene.regions else {}
        case_rows = _case_rows(items, key, base, masks)
        note = None
        bounded = base.scene.max_depth != -1
        seeds = iter(range(20_000, 40_000))
        warmed: set = set()

        def render(settings, spp, index, scene=base.scene, gt=base.gt, masks=masks):
            # rendered as the suite renders its cases (its replicates); a fresh seed for every render, so that the
            # repeats (and the strategies) are independent
            judged = judged_settings("reference", settings)
            key_ = tuple(sorted(judged.items()))
            row = studies.measure_render(scene, gt, judged, spp, next(seeds), warm_up=key_ not in warmed, masks=masks)
            warmed.add(key_)
            row["settings"] = dict(settings)
            if index == options.strategy_repeats - 1:
                progress.step("strategy " + (" ".join(f"{k}={v}" for k, v in settings.items()) or "default"))
            return row

        environment = any(e.type in ("constant", "envmap") for e in base.scene.emitters)
        many_lights = sum(1 for shape in base.scene.shapes if shape.is_emitter) >= studies.MANY_LIGHTS
        media = base.scene.has_media
        wanted = 1 + len(studies.strategy_choices(defaults, environment, glossy, many_lights, media))
        progress.add(2 * wanted if options.render_strategies else 0)
        try:
            table = studies.strategy_rows(Path(key).stem, case_rows, render if options.render_strategies else None,
                                          bounded, defaults, environment=environment, glossy=glossy,
                                          many_lights=many_lights, media=media, spp=options.strategy_spp, repeats=options.strategy_repeats,
                                          min_seconds=options.strategy_min_seconds,
                                          spp_step=int(judged_settings("reference", {}).get("replicates", 1)))
            plot = f"strategies/{slug(Path(key).stem)}.png"
            _plot(plots, out / plot, table, figures.strategies_figure, table["rows"],
                  title=f"{Path(key).stem}: efficiency relative to default", best=table.get("best"))
            table.update(scene_path=key, film=[base.scene.film.width, base.scene.film.height], plot=plot, note=note)
            others = _other_strategy_rows(items, key, base, table)
            if others:
                table["other_renderers"] = others
            if glossy:
                table.update(defaults=defaults)
        except WriteError:
            raise
        except Exception as err:  # noqa: BLE001
            table = {"scene": Path(key).stem, "scene_path": key,
                     "error": f"{type(err).__name__}: {err}".splitlines()[0], "traceback": traceback.format_exc(limit=6)}
        section["scenes"].append(table)
    return section


def _other_strategy_rows(items: list[StudyCase], key: str, base: StudyCase, table: dict) -> list[dict]:
    """Per other renderer of the scene (:func:`_other_renderers`), its case's own efficiency beside the strategy
    rows: 1 / (mean render variance x render seconds per megapixel, start-up excluded), relative to the default
    row's, where its film is the table's (per-pixel MSE depends on the pixel size); and why it has no rows."""
    default = next((r for r in table["rows"] if r.get("is_default") and r.get("efficiency")), None)
    rows = []
    for item in _other_renderers(items, key):
        rec = item.record
        render = rec.get("render") or {}
        h, w = item.render.shape[:2]
        row = {"renderer": renderer_label(str(rec.get("renderer"))), "case": rec.get("name"), "film": [w, h],
               "spp": render.get("spp"), "seconds": render.get("seconds"),
               "time_from": (render.get("info") or {}).get("time_from"), "note": NO_SETTINGS,
               "mse_estimate": studies.mean_variance(item.render_variance), "seconds_per_megapixel": None,
               "efficiency": None, "relative_efficiency": None}
        seconds = row["seconds"]
        if isinstance(seconds, (int, float)) and seconds > 0:
            row["seconds_per_megapixel"] = seconds / (w * h) * 1e6
            if row["mse_estimate"]:
                row["efficiency"] = 1.0 / (row["mse_estimate"] * row["seconds_per_megapixel"])
        if (h, w) != tuple(base.render.shape[:2]):
            row["note"] += f"; its film ({w}x{h}) is not the table's, so its efficiency is not compared"
        elif default is not None and row["efficiency"]:
            row["relative_efficiency"] = row["efficiency"] / default["efficiency"]
            row["note"] += ("; its efficiency is one render's at its case's spp, beside the default's at equal time: "
                            "no interval, not ranked")
        rows.append(row)
    return rows


def _plot(plots: _Plots | None, path: Path, entry: dict, fn, *args, **kwargs) -> None:
    """Draw a plot into ``path``: later with the others (``plots``), or now."""
    if plots is not None:
        plots.add(path, entry, fn, *args, **kwargs)
    else:
        _write_bytes(path, fn(*args, **kwargs))


def _write_bytes(path: Path, data: bytes) -> None:
    make_folders(path.parent)
    atomic_write_bytes(path, data)


def _strip_private(value: Any) -> Any:
    """``value`` without the keys that start with "_" (objects kept for the studies' own use, e.g. a Scene)."""
    if isinstance(value, dict):
        return {k: _strip_private(v) for k, v in value.items() if not str(k).startswith("_")}
    if isinstance(value, list):
        return [_strip_private(v) for v in value]
    return value
