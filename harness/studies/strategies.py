"""Studies of a suite run besides its cases: noise against the number of shadow rays (the slides' Figure 5.9)
and the efficiency of every sampling strategy of the reference renderer."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from harness.files.imageio import tonemap_srgb8
from harness.files.previews import ImageWriter, ReportImage, display_exposure
from harness.judges.efficiency import (EQUAL_TIME_TOLERANCE, LEVEL, MAX_EQUAL_TIME_FACTOR, best_separated,
                                       efficiency_interval, efficiency_ratio, equal_time_spp, float_resolution,
                                       ratio_interval, shown_mse, zero_variance)
from harness.judges.floor import error_point
from harness.renderers import RenderRequest, get_renderer
from harness.studies import figures
from harness.studies.regions import region_variances
from harness.studies.convergence import MIN_TIMING_SECONDS, fit_convergence, timed_render
from reference_impl import Settings
from reference_impl.settings import AUTO_DIRECT, AUTO_RR

SHADOW_RAY_COUNTS = (1, 4, 9, 16, 36, 64, 100)
#: the penumbra: pixels whose ground truth lies strictly between these fractions of the fully lit level
PENUMBRA_LOW, PENUMBRA_HIGH = 0.05, 0.95
#: shapes that cast the shadow (by name); without one, the fully lit level is a percentile of the ground truth
OCCLUDER_NAMES = ("occluder",)
FULLY_LIT_PERCENTILE = 99.0
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709

#: the strategy settings of the reference renderer, each choice of each key
STRATEGIES: dict[str, tuple[str, ...]] = {
    "direct": ("area", "hemisphere-cosine", "hemisphere-uniform", "global-area", "mis"),
    "light_selection": ("power", "uniform"),
    "hemisphere": ("cosine", "uniform"),
    "rr": ("albedo", "fixed", "off"),
    "env_sampling": ("importance", "uniform", "cosine"),  # rows only on scenes with an environment
}
#: the same on scenes with a material that is not diffuse (the path loop there: no hemisphere or global-area
#: strategies, no hemisphere setting, no cosine sampling of an environment; direct = bsdf, rr = pbrt and throughput
#: beside)
GLOSSY_STRATEGIES: dict[str, tuple[str, ...]] = {
    "direct": ("area", "bsdf", "mis"),
    "light_selection": ("power", "uniform"),
    "rr": ("pbrt", "albedo", "fixed", "throughput", "off"),
    "env_sampling": ("importance", "uniform"),
}
#: the same on scenes with participating media or a null material (the volumetric path loop: the glossy scenes' rows and
#: the media's own, ``medium_direct`` and ``transmittance``)
MEDIA_STRATEGIES: dict[str, tuple[str, ...]] = dict(GLOSSY_STRATEGIES, medium_direct=("mis", "light", "phase"),
                                                   transmittance=("ratio", "track"))
#: light_selection = "tree" is a row on scenes with at least this many emissive shapes (on fewer, a tree's choice
#: differs little from power's and its table row would cost the canonical run a compilation for nothing)
MANY_LIGHTS = 8
#: the rows a scene with MANY_LIGHTS area lights adds
MANY_LIGHT_STRATEGIES: dict[str, tuple[str, ...]] = {"light_selection": ("tree",)}
FALLBACK_DEFAULTS = {"direct": "area", "light_selection": "power", "hemisphere": "cosine", "rr": "albedo",
                     "env_sampling": "importance", "medium_direct": "mis", "transmittance": "ratio"}
#: strategy keys that change nothing on a scene without an environment (constant or envmap emitter)
ENVIRONMENT_KEYS = ("env_sampling",)
#: settings that only parameterise a strategy (they may accompany it in a case)
STRATEGY_PARAMETERS = ("absorption", "rr_depth")
DEFAULT_STRATEGY_SPP = 16
#: a strategy render shorter than this is redone at 2x the spp (up to MAX_STRATEGY_SPP): shorter times are noise
MIN_STRATEGY_SECONDS = 0.05
MAX_STRATEGY_SPP = 1024
#: independent renders (seeds) of each strategy at each budget: their spread gives the intervals
STRATEGY_REPEATS = 4


def strategy_defaults(glossy: bool = False) -> dict[str, str]:
    """The reference renderer's default choice of each strategy key (read from its Settings) on a Lambertian-only
    scene, or on one with a material that is not diffuse (``glossy``: direct = auto resolves to "mis" there, rr =
    auto to "pbrt")."""
    try:
        settings = Settings.from_strings({})
        resolved = settings.resolved(glossy).as_dict()
        return {k: str(resolved.get(k, v)) for k, v in FALLBACK_DEFAULTS.items()}
    except Exception:  # noqa: BLE001 - fall back to the documented defaults
        return dict(FALLBACK_DEFAULTS, direct=AUTO_DIRECT[glossy], rr=AUTO_RR[glossy])


def luminance(image: np.ndarray) -> np.ndarray:
    return np.asarray(image, dtype=np.float64) @ LUMINANCE


# ---- noise against shadow rays -----------------------------------------------------------------------------------


def penumbra_mask(scene, gt_image: np.ndarray, *, seed: int = 900_001) -> tuple[np.ndarray, dict, dict]:
    """The penumbra of ``scene`` from its ground truth: pixels strictly between PENUMBRA_LOW and PENUMBRA_HIGH of
    the fully lit level.

    Where the scene has a shape named "occluder", the fully lit level is per pixel: the same scene rendered without
    the occluder (reference renderer, 4 spp x 16 shadow rays: the unoccluded light is smooth, so this is accurate to
    a few per cent), and pixels that see the occluder itself (found by a render in which only the occluder emits)
    are left out. Otherwise it is the 99th percentile of the ground truth's luminance.

    Returns (mask (H, W) bool, a JSON description, {"unoccluded": image or None, "receiver": mask or None}).
    """
    lum = luminance(gt_image)
    occluders = [s for s in scene.shapes if s.name in OCCLUDER_NAMES]
    info: dict[str, Any] = {"low": PENUMBRA_LOW, "high": PENUMBRA_HIGH}
    extra: dict[str, Any] = {"unoccluded": None, "receiver": None}
    if occluders:
        renderer = get_renderer("reference")
        open_scene = dataclasses.replace(scene, shapes=[s for s in scene.shapes if s.name not in OCCLUDER_NAMES])
        lit = renderer.render(open_scene, RenderRequest(spp=4, seed=seed, settings={"shadow_rays": "16"}))
        shapes = [dataclasses.replace(s, emission=(1.0, 1.0, 1.0) if s.name in OCCLUDER_NAMES else None)
                  for s in scene.shapes]
        marker = renderer.render(dataclasses.replace(scene, shapes=shapes, max_depth=1),
                                 RenderRequest(spp=16, seed=seed + 1, settings={}))
        receiver = ~np.any(np.asarray(marker.image) > 0, axis=-1)
        full = luminance(lit.image)
        with np.errstate(invalid="ignore", divide="ignore"):
            mask = receiver & (full > 0) & (lum > PENUMBRA_LOW * full) & (lum < PENUMBRA_HIGH * full)
        info.update(method="per-pixel", fully_lit="the scene without its occluder, reference renderer, 4 spp x 16 "
                    "shadow rays", occluder_pixels=int((~receiver).sum()))
        extra.update(unoccluded=np.asarray(lit.image), receiver=receiver)
    else:
        level = float(np.percentile(lum[np.isfinite(lum)], FULLY_LIT_PERCENTILE)) if np.isfinite(lum).any() else 0.0
        mask = (lum > PENUMBRA_LOW * level) & (lum < PENUMBRA_HIGH * level)
        info.update(method="global", fully_lit=f"the {FULLY_LIT_PERCENTILE:g}th percentile of the ground truth's "
                    "luminance", level=level)
    info["pixels"] = int(mask.sum())
    info["fraction"] = float(mask.mean())
    return mask, info, extra


def shadow_ray_study(scene, gt, writer: ImageWriter, *, counts: Sequence[int] = SHADOW_RAY_COUNTS, seed: int = 500_000,
                     min_timing_seconds: float = MIN_TIMING_SECONDS,
                     progress: Callable[[str], None] | None = None) -> tuple[dict, list[ReportImage], dict]:
    """Render ``scene`` at 1 spp with each number of shadow rays; RMSE in the penumbra and over the image, and time.

    Returns (JSON results, the images written (the renders, the ground truth, the mask), {"panel": png, "curves":
    png}).
    """
    renderer = get_renderer("reference")
    mask, mask_info, extra = penumbra_mask(scene, gt.image)
    exposure = display_exposure(gt.image)
    images = [writer.radiance("ground_truth", "Ground truth", gt.image, gt.variance,
                              description=f"{gt.source}, {gt.spp} spp" if gt.spp else str(gt.source),
                              exposure=exposure),
              writer.mask("penumbra_mask", "Penumbra mask", mask,
                          description=f"{mask_info['pixels']} pixels: ground truth strictly between "
                                      f"{PENUMBRA_LOW:.0%} and {PENUMBRA_HIGH:.0%} of the fully lit level")]
    if extra["unoccluded"] is not None:
        images.append(writer.radiance("fully_lit", "Fully lit level", extra["unoccluded"], exposure=exposure,
                                      description="the scene without its occluder (defines the fully lit level)"))
    rows, tiles = [], []
    renderer.render(scene, RenderRequest(spp=1, seed=seed - 1, settings={"shadow_rays": "1"}))  # untimed warm-up
    for index, n in enumerate(counts):
        result, secs, repeats = timed_render(renderer, scene,
                                             RenderRequest(spp=1, seed=seed + index, settings={"shadow_rays": str(n)}),
                                             min_timing_seconds)
        images.append(writer.radiance(f"shadow_rays_{n}", f"{n} shadow ray{'s' if n != 1 else ''}", result.image,
                                      result.variance, description=f"1 viewing ray per pixel, {n} shadow rays",
                                      exposure=exposure))
        tiles.append((f"{n} shadow ray{'s' if n != 1 else ''}", tonemap_srgb8(result.image, exposure)))
        rows.append({
            "shadow_rays": int(n), "spp": 1, "seed": seed + index, "seconds": secs, "timing_repeats": repeats,
            "rays": dict(result.rays),
            "penumbra": error_point(result.image, gt.image, gt.variance, mask),
            "image": error_point(result.image, gt.image, gt.variance),
        })
        if progress is not None:
            progress(f"shadow rays {n}")
    tiles.append(("ground truth", tonemap_srgb8(gt.image, exposure)))
    fit = fit_convergence([r["shadow_rays"] for r in rows], [r["penumbra"]["rmse_corrected"] for r in rows],
                          expected_slope=-0.5, scatter=[r["penumbra"]["scatter_log_rmse"] for r in rows])
    study = {"scene": str(scene.path), "film": [scene.film.width, scene.film.height], "counts": list(counts),
             "penumbra": mask_info, "rows": rows, "fit": fit}
    plots = {"panel": figures.panel_figure(tiles, columns=4, title="1 viewing ray per pixel, N shadow rays"),
             "curves": figures.shadow_rays_figure(study)}
    return study, images, plots


# ---- strategies --------------------------------------------------------------------------------------------------


def classify(settings: dict[str, str], defaults: dict[str, str]) -> tuple[str, str] | None | str:
    """("key", "value") when ``settings`` change exactly one strategy key from its default (other keys only
    STRATEGY_PARAMETERS); "default" when they change none; None otherwise (mutants, other settings, several keys)."""
    extra = [k for k in settings if k not in STRATEGIES and k not in STRATEGY_PARAMETERS]
    if extra:
        return None
    changed = [(k, settings[k]) for k in STRATEGIES if k in settings and settings[k] != defaults.get(k)]
    if not changed:
        return "default" if not any(k in settings for k in STRATEGY_PARAMETERS) else None
    return changed[0] if len(changed) == 1 else None


def mean_variance(variance: np.ndarray | None) -> float | None:
    """The mean over pixels and channels of a render's per-pixel variance (of the mean): its expected MSE if it is
    unbiased. None when there is none (e.g. 1 spp)."""
    if variance is None:
        return None
    v = np.asarray(variance, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else None


def image_level(image: np.ndarray | None) -> float | None:
    """The mean absolute value of an image's finite pixels and channels (the scale of its float32 rounding,
    :func:`harness.judges.efficiency.float_resolution`); None for none."""
    if image is None:
        return None
    values = np.abs(np.asarray(image, dtype=np.float64))
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if finite.size else None


def strategy_choices(defaults: dict[str, str], environment: bool, glossy: bool = False,
                     many_lights: bool = False, media: bool = False) -> list[tuple[str, str]]:
    """Every (key, value) of :data:`STRATEGIES` (:data:`GLOSSY_STRATEGIES` on a scene with a material that is not
    diffuse, :data:`MEDIA_STRATEGIES` on one with ``media``) but the defaults: the rows of a strategy table besides
    "default" (the environment's keys only where the scene has an environment; :data:`MANY_LIGHT_STRATEGIES` where it
    has :data:`MANY_LIGHTS` area lights or more, ``many_lights``)."""
    table = MEDIA_STRATEGIES if media else (GLOSSY_STRATEGIES if glossy else STRATEGIES)
    if many_lights:
        table = {k: v + MANY_LIGHT_STRATEGIES.get(k, ()) for k, v in table.items()}
    return [(k, v) for k, values in table.items() for v in values
            if v != defaults.get(k) and (environment or k not in ENVIRONMENT_KEYS)]


def strategy_label(key: str, value: str) -> str:
    return f"{key}={value}"


def strategy_rows(scene_name: str, case_rows: list[dict], render: Callable[[dict[str, str], int, int], dict] | None,
                  bounded: bool, defaults: dict[str, str], environment: bool = False, glossy: bool = False,
                  many_lights: bool = False, media: bool = False, *,
                  spp: int = DEFAULT_STRATEGY_SPP, repeats: int = STRATEGY_REPEATS,
                  min_seconds: float = MIN_STRATEGY_SECONDS, spp_step: int = 1, level: float = LEVEL) -> dict:
    """Assemble a scene's strategy table: every strategy at equal spp and at equal time, ``repeats`` seeds each.

    ``render(settings, spp, index)`` renders the strategy ``settings`` once at exactly ``spp`` (a new seed each call;
    ``index`` counts the repeats) and measures it: {"mse", "floor_mse", "variance", "seconds", "pixels", "spp",
    "film", "variance_regions"} (variance: :func:`mean_variance` of the render). The equal-spp budget is ``spp``,
    doubled (up to MAX_STRATEGY_SPP) while the default's render takes under ``min_seconds``; each strategy's
    equal-time budget is the spp at which its time per path gives the default's time (a multiple of ``spp_step``),
    the equal-spp renders again where that is within :data:`EQUAL_TIME_TOLERANCE`. Every ratio to the default and
    every efficiency carries a ``level`` interval over the seeds (:mod:`harness.judges.efficiency`); "best" names a
    strategy only when its efficiency is told apart from every other's (:func:`best_separated`).

    ``render`` None: the rows are the suite's cases ``case_rows`` (each {"case", "settings", "mse", "floor_mse",
    "variance", "seconds", "pixels", "spp", "film"}), one render each at its own spp: shown, never ranked.
    ``bounded``: the scene's max_depth is finite (rr=off allowed). ``environment``: the scene has a constant or
    envmap emitter (the :data:`ENVIRONMENT_KEYS` rows apply). ``glossy``: a material of the scene is not diffuse
    (the rows of :data:`GLOSSY_STRATEGIES`). ``many_lights``: it has :data:`MANY_LIGHTS` area lights or more.
    ``media``: it has participating media or a null material (the rows of :data:`MEDIA_STRATEGIES`).
    """
    wanted: list[Any] = ["default"] + [(k, v) for k, v in strategy_choices(defaults, environment, glossy, many_lights,
                                                                            media)]
    if render is None:
        return _case_table(scene_name, case_rows, wanted, bounded, defaults)
    rows: list[dict] = []
    budget = spp
    try:
        first = render({}, budget, 0)
        while first["seconds"] < min_seconds and budget * 2 <= MAX_STRATEGY_SPP:
            budget *= 2
            first = render({}, budget, 0)
        base = [first] + [render({}, budget, i) for i in range(1, repeats)]
    except Exception as err:  # noqa: BLE001 - without the default nothing compares
        return {"scene": scene_name, "rows": [], "error": f"the default failed: {type(err).__name__}: {err}"[:300]}
    base_seconds = float(np.mean([m["seconds"] for m in base]))
    for kind in wanted:
        if kind == ("rr", "off") and not bounded:
            rows.append(_row_head(kind, skipped="max_depth is unbounded: rr=off would never end a path"))
            continue
        settings = {} if kind == "default" else {kind[0]: kind[1]}
        try:
            at_spp = base if kind == "default" else [render(settings, budget, i) for i in range(repeats)]
            equal = equal_time_spp(budget, float(np.mean([m["seconds"] for m in at_spp])), base_seconds,
                                   step=spp_step, max_factor=MAX_EQUAL_TIME_FACTOR, tolerance=EQUAL_TIME_TOLERANCE)
            at_time = at_spp if equal == budget else [render(settings, equal, i) for i in range(repeats)]
        except Exception as err:  # noqa: BLE001 - one strategy's failure is reported in its row
            rows.append(_row_head(kind, skipped=f"render failed: {type(err).__name__}: {err}".splitlines()[0][:300]))
            continue
        rows.append(dict(_row_head(kind), is_default=kind == "default", case=None, source="rendered",
                         settings=settings, film=at_spp[0]["film"], pixels=at_spp[0]["pixels"], spp=budget,
                         equal_spp=_budget(at_spp), equal_time=_budget(at_time)))
    return _compare(scene_name, rows, level, repeats)


def _row_head(kind: Any, skipped: str | None = None) -> dict:
    """A strategy row's label and strategy ("default", or ("key", "value")), and why it was skipped, if it was."""
    head = {"label": "default" if kind == "default" else strategy_label(*kind),
            "strategy": None if kind == "default" else list(kind)}
    return dict(head, skipped=skipped) if skipped is not None else head


def _budget(measurements: list[dict]) -> dict:
    """The per-seed numbers of a strategy's renders at one budget: the MSE the efficiency uses (the render's own
    variance estimate where it has one: the expected MSE of an unbiased estimator, free of the ground truth's
    noise; else the measured MSE minus the ground truth's floor), the measured MSE, seconds, seconds per megapixel,
    each region's mean variance, and whether the estimator is exact here (``zero_variance``: every seed's own
    variance at most the float32 rounding of the ground truth's level ``level``,
    :func:`harness.judges.efficiency.zero_variance`)."""
    def estimate(m):
        v = m.get("variance")
        return v if v is not None and math.isfinite(v) and v > 0 else m["mse"] - (m.get("floor_mse") or 0.0)

    def own(m):  # the seed's own variance: the render's estimate, else its measured MSE (the floor in it)
        v = m.get("variance")
        return v if v is not None else m["mse"]

    levels = [m["level"] for m in measurements if m.get("level") is not None]
    resolution = float_resolution(float(np.mean(levels)) if levels else None)

    return {"spp": int(measurements[0]["spp"]), "seeds": len(measurements),
            "mse": [float(estimate(m)) for m in measurements],
            "mse_source": "render variance" if all(m.get("variance") for m in measurements) else "measured",
            "mse_measured": [float(m["mse"] - (m.get("floor_mse") or 0.0)) for m in measurements],
            "floor_mse": float(np.mean([m.get("floor_mse") or 0.0 for m in measurements])),
            "seconds": [float(m["seconds"]) for m in measurements],
            "seconds_per_megapixel": [float(m["seconds"]) / m["pixels"] * 1e6 for m in measurements],
            "variance_regions": [m.get("variance_regions") or {} for m in measurements],
            "zero_variance": zero_variance([own(m) for m in measurements], resolution)}


def _compare(scene_name: str, rows: list[dict], level: float, repeats: int) -> dict:
    """Each row's numbers and intervals against the default's (see :func:`strategy_rows`), and the best. A row
    whose estimator is exact here (``zero_variance`` at either budget: one exact at the equal-time spp and not at
    the other, where float32 accumulation leaves a variance, would rank by rounding's inverse) has no efficiency, no
    MSE ratio and no place in the ranking; ratios to an exact default are none."""
    default = next((r for r in rows if r.get("is_default")), None)
    d_spp, d_time = default["equal_spp"], default["equal_time"]
    d_zero = d_spp["zero_variance"] or d_time["zero_variance"]
    none = {"value": None, "low": None, "high": None, "level": level, "dof": None, "seeds": []}
    samples = {}
    for row in rows:
        if "skipped" in row:
            continue
        s, t = row["equal_spp"], row["equal_time"]
        row["zero_variance"] = zero = s["zero_variance"] or t["zero_variance"]
        measured = shown_mse(float(np.mean(s["mse_measured"])), s["floor_mse"])
        row.update(mse_estimate=float(np.mean(s["mse"])), mse_source=s["mse_source"], mse_corrected=measured["value"],
                   mse_bound=measured["bound"], seconds=float(np.mean(s["seconds"])),
                   seconds_per_megapixel=float(np.mean(s["seconds_per_megapixel"])),
                   equal_time_spp=t["spp"], equal_time_seconds=float(np.mean(t["seconds"])),
                   equal_time_seconds_per_megapixel=float(np.mean(t["seconds_per_megapixel"])),
                   equal_time_mse=float(np.mean(t["mse"])), mse_slope=_slope(s, t, level))
        row["efficiency_interval"] = efficiency_interval(t["mse"], t["seconds_per_megapixel"], level)
        row["efficiency"] = row["efficiency_interval"]["value"]
        if row is default:
            one = {"value": 1.0, "low": None, "high": None, "level": level, "dof": None, "seeds": [], "reference": True}
            row.update(relative_mse_interval=one, relative_time_interval=one, relative_mse_equal_time=one,
                       relative_efficiency_interval=one)
        else:
            row.update(relative_mse_interval=ratio_interval((s["mse"],), (d_spp["mse"],), level),
                       relative_time_interval=ratio_interval((s["seconds_per_megapixel"],),
                                                             (d_spp["seconds_per_megapixel"],), level),
                       relative_mse_equal_time=ratio_interval((t["mse"],), (d_time["mse"],), level),
                       relative_efficiency_interval=efficiency_ratio(t["mse"], t["seconds_per_megapixel"],
                                                                     d_time["mse"], d_time["seconds_per_megapixel"],
                                                                     level))
        if zero or (d_zero and row is not default):
            row.update(relative_mse_interval=dict(none), relative_mse_equal_time=dict(none),
                       relative_efficiency_interval=dict(none))
        if zero:
            row.update(efficiency_interval=dict(none), efficiency=None, mse_slope=None)
        row["relative_mse"] = row["relative_mse_interval"]["value"]
        row["relative_time"] = row["relative_time_interval"]["value"]
        row["relative_efficiency"] = row["relative_efficiency_interval"]["value"]
        if row["efficiency"] is not None:
            samples[row["label"]] = (t["mse"], t["seconds_per_megapixel"])
    decision = best_separated(samples, level)
    leader = next((r for r in rows if r["label"] == decision["leader"]), None)
    table = {"scene": scene_name, "rows": rows, "comparison": "repeats", "repeats": repeats, "level": level,
             "equal_spp": d_spp["spp"], "equal_time_seconds": float(np.mean(d_time["seconds"])),
             "equal_time_tolerance": EQUAL_TIME_TOLERANCE,
             "best": decision["best"], "leader": decision["leader"],
             "best_relative_efficiency": leader["relative_efficiency"] if decision["best"] and leader else None,
             "best_interval": leader["relative_efficiency_interval"] if decision["best"] and leader else None,
             "near_best": [decision["leader"]] + decision["tied"] if decision["leader"] and decision["tied"] else [],
             "separation": {"level": decision["level"], "leader_over": decision["comparisons"]},
             "zero_variance": [r["label"] for r in rows if r.get("zero_variance")]}
    regions = _region_efficiencies(rows, default, level)
    if regions:
        table["regions"] = regions
    return table


def _slope(at_spp: dict, at_time: dict, level: float) -> dict | None:
    """The log-log slope of the mean MSE between a row's two budgets (-1 for an estimator whose MSE falls as
    1 / spp), where their spp differ, with its interval: that of the MSE ratio (:func:`ratio_interval`) over the log
    of the spp ratio. Between close budgets it is wide: the MSE ratio's noise over a small log."""
    if at_spp["spp"] == at_time["spp"]:
        return None
    ratio = ratio_interval((at_time["mse"],), (at_spp["mse"],), level)
    if ratio["value"] is None:
        return None
    span = math.log(at_time["spp"] / at_spp["spp"])
    ends = sorted(math.log(v) / span for v in (ratio["low"], ratio["high"])) if ratio["low"] is not None else [None] * 2
    return dict(ratio, value=math.log(ratio["value"]) / span, low=ends[0], high=ends[1])


def _region_efficiencies(rows: list[dict], default: dict | None, level: float) -> dict | None:
    """Per region (the scene's ``regions``): each row's efficiency 1 / (region variance x seconds per megapixel) at
    equal time, relative to the default's over the same region, with its interval over the seeds, and the best row
    there when it is told apart (:func:`best_separated`). Rows carry per-seed ``variance_regions`` ({region: mean
    variance over its pixels}, :func:`harness.studies.regions.region_variances`)."""
    live = [r for r in rows if "skipped" not in r and not r.get("zero_variance")]
    names = list(dict.fromkeys(n for r in live for m in r["equal_time"]["variance_regions"] for n in m))
    if not names or default is None:
        return None
    out: dict = {"names": names, "relative_efficiency": {}, "intervals": {}, "best": {}, "leader": {}, "level": level}
    for name in names:
        samples = {}
        for row in live:
            t = row["equal_time"]
            values = [m.get(name) for m in t["variance_regions"]]
            if all(v is not None and v > 0 for v in values):
                samples[row["label"]] = (values, t["seconds_per_megapixel"])
        base = samples.get(default["label"])
        intervals = {label: (efficiency_ratio(*sample, *base, level=level) if label != default["label"] else
                             {"value": 1.0, "low": None, "high": None, "level": level, "reference": True})
                     for label, sample in samples.items()} if base else {}
        out["intervals"][name] = intervals
        out["relative_efficiency"][name] = {r["label"]: (intervals.get(r["label"]) or {}).get("value") for r in live}
        decision = best_separated(samples, level)
        out["best"][name], out["leader"][name] = decision["best"], decision["leader"]
    return out


def _case_table(scene_name: str, case_rows: list[dict], wanted: list[Any], bounded: bool,
                defaults: dict[str, str]) -> dict:
    """The strategy table from the suite's cases alone (no renders): one measurement per strategy at the case's own
    spp, shown with its efficiency but neither ranked nor given an interval (no repeats; different spp)."""
    by_strategy: dict[Any, dict] = {}
    for row in case_rows:
        kind = classify(row["settings"], defaults)
        if kind is not None and (kind not in by_strategy or len(row["settings"]) < len(by_strategy[kind]["settings"])):
            by_strategy[kind] = row
    rows = []
    for kind in wanted:
        if kind == ("rr", "off") and not bounded:
            rows.append(_row_head(kind, skipped="max_depth is unbounded: rr=off would never end a path"))
        elif kind not in by_strategy:
            rows.append(_row_head(kind, skipped="no case and rendering disabled"))
        else:
            row = {k: v for k, v in by_strategy[kind].items() if k != "variance_regions"}
            measured = shown_mse(row["mse"] - row.get("floor_mse", 0.0), row.get("floor_mse", 0.0))
            variance = row.get("variance")
            exact = zero_variance([variance if variance is not None else row["mse"]],
                                  float_resolution(row.get("level")))
            estimate = variance if variance is not None and math.isfinite(variance) and variance > 0 else None
            estimate = None if exact else estimate
            spm = row["seconds"] / row["pixels"] * 1e6
            rows.append(dict(row, **_row_head(kind), is_default=kind == "default",
                             mse_corrected=measured["value"], mse_bound=measured["bound"], mse_estimate=estimate,
                             zero_variance=exact,
                             seconds_per_megapixel=spm,
                             efficiency=1.0 / (estimate * spm) if estimate and spm > 0 else None,
                             relative_efficiency=None, relative_mse=None, relative_time=None))
    return {"scene": scene_name, "rows": rows, "comparison": "cases", "best": None, "leader": None,
            "best_relative_efficiency": None, "near_best": [],
            "zero_variance": [r["label"] for r in rows if r.get("zero_variance")],
            "unranked": "the suite's cases only (rendering disabled): one render per strategy at its case's own spp, "
                        "so neither ranked nor compared with the default"}


def measure_render(scene, gt, settings: dict[str, str], spp: int, seed: int, *, warm_up: bool = False,
                   masks: dict | None = None) -> dict:
    """Render one strategy of the reference renderer at exactly ``spp`` and measure it against ``gt`` (the
    ``render`` of :func:`strategy_rows`): its MSE, the ground truth's floor, its mean variance (also over each of
    ``masks``' regions) and its render seconds; ``warm_up``: an untimed 1-spp render first (compilation, one-off
    costs of the first render of these settings)."""
    renderer = get_renderer("reference")
    if warm_up:
        renderer.render(scene, RenderRequest(spp=1, seed=seed + 500_000, settings=dict(settings)))
    result = renderer.render(scene, RenderRequest(spp=spp, seed=seed, settings=dict(settings)))
    point = error_point(result.image, gt.image, gt.variance)
    h, w = result.image.shape[:2]
    return {"case": None, "source": "rendered", "settings": dict(settings), "mse": point["mse"],
            "variance": mean_variance(result.variance),
            "floor_mse": point["floor_mse"], "seconds": float(result.seconds), "pixels": int(h * w),
            "spp": int(result.spp), "film": [w, h], "seed": seed, "timing": "rendered by the studies (warm)",
            "variance_regions": region_variances(result.variance, masks or {}),
            "level": image_level(gt.image)}
