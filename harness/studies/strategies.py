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
from harness.judges.floor import error_point
from harness.renderers import RenderRequest, get_renderer
from harness.studies import figures
from harness.studies.regions import region_variances
from harness.studies.convergence import MIN_TIMING_SECONDS, fit_convergence, timed_render
from reference_impl import Settings

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
#: the same on scenes with a material that is not diffuse (the glossy engine: no hemisphere or global-area
#: strategies, no hemisphere setting, no cosine sampling of an environment; direct = bsdf, rr = pbrt and throughput
#: beside)
GLOSSY_STRATEGIES: dict[str, tuple[str, ...]] = {
    "direct": ("area", "bsdf", "mis"),
    "light_selection": ("power", "uniform"),
    "rr": ("pbrt", "albedo", "fixed", "throughput", "off"),
    "env_sampling": ("importance", "uniform"),
}
FALLBACK_DEFAULTS = {"direct": "area", "light_selection": "power", "hemisphere": "cosine", "rr": "albedo",
                     "env_sampling": "importance"}
#: strategy keys that change nothing on a scene without an environment (constant or envmap emitter)
ENVIRONMENT_KEYS = ("env_sampling",)
#: settings that only parameterise a strategy (they may accompany it in a case)
STRATEGY_PARAMETERS = ("absorption", "rr_depth")
DEFAULT_STRATEGY_SPP = 16
#: a strategy render shorter than this is redone at 4x the spp (up to MAX_STRATEGY_SPP): shorter times are noise
MIN_STRATEGY_SECONDS = 0.05
MAX_STRATEGY_SPP = 1024
#: strategies whose efficiency is within this factor of the best are listed with it: timings on a shared machine
#: and variance estimates scatter by about this much, so they are not told apart
TIE_FACTOR = 1.25


def strategy_defaults(glossy: bool = False) -> dict[str, str]:
    """The reference renderer's default choice of each strategy key (read from its Settings) on a Lambertian-only
    scene, or on one with a material that is not diffuse (``glossy``: direct = auto resolves to "mis" there, rr =
    auto to "pbrt")."""
    try:
        settings = Settings.from_strings({})
        resolved = dict(settings.as_dict(), direct=settings.resolved_direct(glossy), rr=settings.resolved_rr(glossy))
        return {k: str(resolved.get(k, v)) for k, v in FALLBACK_DEFAULTS.items()}
    except Exception:  # noqa: BLE001 - fall back to the documented defaults
        return dict(FALLBACK_DEFAULTS, direct="mis", rr="pbrt") if glossy else dict(FALLBACK_DEFAULTS)


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


def strategy_choices(defaults: dict[str, str], environment: bool, glossy: bool = False) -> list[tuple[str, str]]:
    """Every (key, value) of :data:`STRATEGIES` (:data:`GLOSSY_STRATEGIES` on a scene with a material that is not
    diffuse) but the defaults: the rows of a strategy table besides "default" (the environment's keys only where
    the scene has an environment)."""
    return [(k, v) for k, values in (GLOSSY_STRATEGIES if glossy else STRATEGIES).items() for v in values
            if v != defaults.get(k) and (environment or k not in ENVIRONMENT_KEYS)]


def strategy_label(key: str, value: str) -> str:
    return f"{key}={value}"


def strategy_rows(scene_name: str, case_rows: list[dict], render: Callable[[dict[str, str]], dict] | None,
                  bounded: bool, defaults: dict[str, str], retime: Callable[[dict], dict] | None = None,
                  environment: bool = False, glossy: bool = False) -> dict:
    """Assemble a scene's strategy table.

    ``case_rows``: measurements from the suite's cases of this scene, each {"case", "settings", "mse", "floor_mse",
    "variance", "seconds", "pixels", "spp", "film"} (variance: :func:`mean_variance` of the render).
    ``render(settings)`` measures a strategy no case covers (same keys, no "case"); None: leave it out.
    ``bounded``: the scene's max_depth is finite (rr=off allowed). ``retime(row)``: the case row chosen for a
    strategy with its time measured again under the report's conditions (see :func:`time_per_path`).
    ``environment``: the scene has a constant or envmap emitter (the :data:`ENVIRONMENT_KEYS` rows apply).
    ``glossy``: a material of the scene is not diffuse (the rows of :data:`GLOSSY_STRATEGIES`).
    """
    by_strategy: dict[Any, dict] = {}
    for row in case_rows:
        kind = classify(row["settings"], defaults)
        if kind is None:
            continue
        current = by_strategy.get(kind)
        if current is None or len(row["settings"]) < len(current["settings"]):
            by_strategy[kind] = row
    wanted: list[Any] = ["default"] + [(k, v) for k, v in strategy_choices(defaults, environment, glossy)]
    rows = []
    for kind in wanted:
        label = "default" if kind == "default" else strategy_label(*kind)
        if kind != "default" and kind == ("rr", "off") and not bounded:
            rows.append({"label": label, "strategy": list(kind), "skipped": "max_depth is unbounded: rr=off would "
                         "never end a path"})
            continue
        row = by_strategy.get(kind)
        if row is not None and retime is not None:
            try:
                row = retime(row)
            except Exception as err:  # noqa: BLE001 - keep the case's own time
                row = dict(row, timing=f"the case's own (re-timing failed: {type(err).__name__}: {err})"[:200])
        if row is None:
            if render is None:
                rows.append({"label": label, "strategy": None if kind == "default" else list(kind),
                             "skipped": "no case and rendering disabled"})
                continue
            settings = {} if kind == "default" else {kind[0]: kind[1]}
            try:
                row = render(settings)
            except Exception as err:  # noqa: BLE001 - one strategy's failure is reported in its row
                rows.append({"label": label, "strategy": None if kind == "default" else list(kind),
                             "skipped": f"render failed: {type(err).__name__}: {err}".splitlines()[0]})
                continue
        row = dict(row, label=label, is_default=kind == "default",
                   strategy=None if kind == "default" else list(kind))
        rows.append(row)
    for row in rows:
        if "skipped" in row:
            continue
        row["mse_corrected"] = row["mse"] - row.get("floor_mse", 0.0)
        # The estimator's MSE: its own variance estimate where the render has one (precise, and free of the ground
        # truth's noise; every strategy is unbiased, as the suite's verdicts check), else the measured MSE.
        variance = row.get("variance")
        estimate = variance if variance is not None and math.isfinite(variance) and variance > 0 else row["mse_corrected"]
        row["mse_estimate"] = estimate
        row["mse_source"] = "render variance" if estimate is variance else "measured"
        row["seconds_per_megapixel"] = row["seconds"] / row["pixels"] * 1e6
        row["efficiency"] = (1.0 / (estimate * row["seconds_per_megapixel"])
                             if estimate > 0 and row["seconds"] > 0 else None)
    default = next((r for r in rows if r.get("is_default") and r.get("efficiency")), None)
    for row in rows:
        if "skipped" in row:
            continue
        row["relative_efficiency"] = (row["efficiency"] / default["efficiency"]
                                      if default is not None and row.get("efficiency") else None)
        row["relative_mse"] = (row["mse_estimate"] / default["mse_estimate"]
                               if default is not None and default["mse_estimate"] > 0 else None)
        row["relative_time"] = (row["seconds_per_megapixel"] / default["seconds_per_megapixel"]
                                if default is not None else None)
    measured = [r for r in rows if r.get("relative_efficiency")]
    best = max(measured, key=lambda r: r["relative_efficiency"]) if measured else None
    near = [r["label"] for r in measured if best and r["relative_efficiency"] * TIE_FACTOR >= best["relative_efficiency"]]
    table = {"scene": scene_name, "rows": rows, "best": best["label"] if best else None,
             "best_relative_efficiency": best["relative_efficiency"] if best else None,
             "near_best": near, "tie_factor": TIE_FACTOR}
    regions = _region_efficiencies(rows, default)
    if regions:
        table["regions"] = regions
    return table


def _region_efficiencies(rows: list[dict], default: dict | None) -> dict | None:
    """Per region (the scene's ``regions``): each row's efficiency 1 / (region variance x seconds per megapixel)
    relative to the default's over the same region, and the best row there. Rows carry ``variance_regions``
    ({region: mean variance over its pixels}, :func:`harness.studies.regions.region_variances`)."""
    names = [n for r in rows for n in (r.get("variance_regions") or {})]
    names = list(dict.fromkeys(names))
    if not names:
        return None

    def efficiency(row, name):
        v = (row.get("variance_regions") or {}).get(name)
        return 1.0 / (v * row["seconds_per_megapixel"]) if v and v > 0 and row.get("seconds", 0) > 0 else None

    out: dict = {"names": names, "relative_efficiency": {}, "best": {}}
    for name in names:
        base = efficiency(default, name) if default is not None else None
        values = {}
        for row in rows:
            if "skipped" in row:
                continue
            e = efficiency(row, name)
            values[row["label"]] = e / base if e is not None and base else None
        out["relative_efficiency"][name] = values
        scored = [(v, k) for k, v in values.items() if v]
        out["best"][name] = max(scored)[1] if scored else None
    return out


def _warm_render(scene, settings: dict[str, str], spp: int, seed: int, min_seconds: float):
    """The reference renderer with ``settings``: an untimed 1-spp warm-up, then ``spp``, quadrupled (up to
    MAX_STRATEGY_SPP) while the render takes less than ``min_seconds``."""
    renderer = get_renderer("reference")
    renderer.render(scene, RenderRequest(spp=1, seed=seed + 500_000, settings=dict(settings)))
    while True:
        result = renderer.render(scene, RenderRequest(spp=spp, seed=seed, settings=dict(settings)))
        if result.seconds >= min_seconds or spp * 4 > MAX_STRATEGY_SPP:
            return result
        spp *= 4


def time_per_path(scene, settings: dict[str, str], spp: int, seed: int,
                  min_seconds: float = MIN_STRATEGY_SECONDS) -> tuple[float, int]:
    """Render seconds per path (pixel sample) of the reference renderer with ``settings`` on ``scene``: an untimed
    1-spp warm-up, then ``spp``, quadrupled while the render takes less than ``min_seconds``. Returns (seconds per
    path, spp of the timed render).

    A suite's case times include one-off costs when the case is the first of its kind in the run (compilation,
    acceleration structures: several times the render itself at small films), so the strategy table times every
    row alike with this, and takes only the MSE from the case."""
    result = _warm_render(scene, settings, spp, seed, min_seconds)
    return float(result.seconds) / (result.image.shape[0] * result.image.shape[1] * result.spp), int(result.spp)


def measure_render(scene, gt, settings: dict[str, str], spp: int, seed: int,
                   min_seconds: float = MIN_STRATEGY_SECONDS, masks: dict | None = None) -> dict:
    """Render one strategy and measure it against ``gt`` (for :func:`strategy_rows`): an untimed 1-spp warm-up,
    then ``spp``, quadrupled while the render takes less than ``min_seconds``."""
    result = _warm_render(scene, settings, spp, seed, min_seconds)
    point = error_point(result.image, gt.image, gt.variance)
    h, w = result.image.shape[:2]
    return {"case": None, "source": "rendered", "settings": dict(settings), "mse": point["mse"],
            "variance": mean_variance(result.variance),
            "floor_mse": point["floor_mse"], "seconds": float(result.seconds), "pixels": int(h * w),
            "spp": int(result.spp), "film": [w, h], "seed": seed, "timing": "rendered by the report (warm)",
            "variance_regions": region_variances(result.variance, masks or {})}
