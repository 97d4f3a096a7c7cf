"""The numerical-stability stress suite: variants of a scene, rendered and judged (``harness stress``).

The variants (:mod:`harness.scene.variants`) are transformed copies of a loaded :class:`~harness.scene.Scene`:
*invariant* ones (``scale``, ``translate``, ``sliver``) must not change the image, so they are judged against the
untransformed scene's ground truth (cached); *strain* ones (``light-shrink``, ``grazing-camera``,
``light-near-wall``, ``light-edge-on``) change the image and strain the estimator, each judged against Mitsuba's
ground truth of the transformed scene.

Each (variant, renderer) row counts NaN, Inf and negative pixels, gives RMSE and relMSE against the ground truth,
the verdict's global bias z, the fireflies (pixels whose |render - GT| exceeds k standard deviations, see
:func:`fireflies`), the render time and the verdict (:func:`harness.running.compare.compare_images`). Where float32 cannot
represent the variant well enough (:func:`float32_limits`) the row is an *expected* fail and its note says why.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

from harness.core import jsonsafe
from harness.core.errors import HarnessError
from harness.files.imageio import ExrImage
from harness.judges.distributions import normal_sf, student_t_sf
from harness.renderers import RenderRequest, get_renderer, groundtruth
from harness.running.compare import compare_images
from harness.scene.model import Scene
from harness.scene.variants import INVARIANT, parse_variant, scene_size, world_points

#: Default firefly threshold, in standard deviations.
DEFAULT_K = 6.0
#: A variant whose float32 position error (one ulp of its largest coordinate) exceeds this fraction of the scene
#: size is an expected fail: a 64x64 pixel footprint is ~1e-2 of the scene, a shadow-terminator or contact detail
#: ~1e-3 of it, and the reference's ray offsets (64-128 ulps) then exceed ~10 % of the scene size.
ULP_FRACTION_LIMIT = 1e-3
#: Mitsuba 3's ``math::RayEpsilon<float>`` = 1500 * 2^-24: it offsets ray origins by (1 + max|p|) times this.
MITSUBA_RAY_EPSILON = 1500 * 2.0**-24
#: A ray offset above this fraction of the scene size visibly biases a 64x64 render of a scene with contact
#: shadows (measured: the reference fails cornell-box translated by 1e4 with its offset at 2.2 %, passes at 0.2 %).
OFFSET_FRACTION_LIMIT = 1e-2

DEFAULT_VARIANTS = (
    "original",
    *(f"scale=1e{e}" for e in (-4, -3, -2, -1, 1, 2, 3, 4)),
    *(f"translate=1e{e}" for e in (2, 3, 4, 5)),
    "sliver=1e6",
    "light-shrink=1e3",
    "grazing-camera=1",
    "light-near-wall=1e-5",
    "light-edge-on",
)


# ---- float32 limits ----------------------------------------------------------------------------------------------


def reference_offset_rel() -> float:
    """The reference's relative ray offset, read from its kernels (the constant the renders use)."""
    from reference_impl.kernels import surface as kernels  # optional: numba-compiled, slow to import; only the limits read it

    return float(kernels._OFFSET_REL)


def float32_limits(scene: Scene) -> dict:
    """How well float32 (Embree's and Mitsuba's precision) holds the scene: the largest coordinate |p| of any
    vertex or the camera, one float32 ulp there, and the ray offset each renderer uses there (the reference:
    ``kernels._OFFSET_REL`` |p| + 2^-22 max|p|; Mitsuba: ``Interaction::offset_p``, (1 + |p|) * 1500 * 2^-24), all
    also as fractions of the scene size.

    ``expected_fail`` (every renderer) when the ulp exceeds :data:`ULP_FRACTION_LIMIT` of the scene size: no
    float32 renderer can hold the scene. ``mitsuba_expected_fail`` also when Mitsuba's offset exceeds
    :data:`OFFSET_FRACTION_LIMIT` of it (Mitsuba's offset has an absolute part, so it fails small scenes too). The
    reference's offset is its own choice, so a reference fail caused by it is a bug, not expected.
    """
    points = np.concatenate([world_points(scene), np.asarray([scene.camera.origin], float)])
    p = float(np.max(np.abs(points)))
    size = scene_size(scene)
    ulp = float(np.spacing(np.float32(p)))
    offsets = {"reference": reference_offset_rel() * p + 2.0**-22 * p, "mitsuba": (1.0 + p) * MITSUBA_RAY_EPSILON}
    fractions = {name: value / size for name, value in offsets.items()}
    expected_fail = ulp > ULP_FRACTION_LIMIT * size
    return {"max_abs_coordinate": p, "scene_size": size, "ulp": ulp, "ulp_fraction": ulp / size,
            "offset": offsets, "offset_fraction": fractions, "expected_fail": expected_fail,
            "mitsuba_expected_fail": expected_fail or fractions["mitsuba"] > OFFSET_FRACTION_LIMIT}


def limits_note(limits: dict, renderer: str) -> str:
    """``|p| 5.8e3: ulp 0.024%, ray offset 2.2% of size`` (and why a fail is expected, where it is)."""
    offset = limits["offset_fraction"].get(renderer)
    text = f"|p| {limits['max_abs_coordinate']:.2g}: f32 ulp {100 * limits['ulp_fraction']:.2g}%"
    if offset is not None:
        text += f", ray offset {100 * offset:.2g}%"
    text += f" of size {limits['scene_size']:.3g}"
    if limits["expected_fail"]:
        text += f"; expected: ulp > {100 * ULP_FRACTION_LIMIT:g}% of size, float32 cannot hold the scene"
    elif renderer == "mitsuba" and limits["mitsuba_expected_fail"]:
        text += f"; expected: Mitsuba's offset (1+|p|)*1500*2^-24 > {100 * OFFSET_FRACTION_LIMIT:g}% of size"
    return text


def expected_verdict(limits: dict, renderer: str) -> str:
    if limits["expected_fail"] or (renderer == "mitsuba" and limits["mitsuba_expected_fail"]):
        return "fail"
    return "pass"


# ---- per-image statistics ----------------------------------------------------------------------------------------


def pixel_counts(image: np.ndarray) -> dict[str, int]:
    """Pixels with a NaN channel, with an infinite channel, and with a finite negative channel."""
    image = np.asarray(image)
    return {
        "nan": int(np.count_nonzero(np.any(np.isnan(image), axis=2))),
        "inf": int(np.count_nonzero(np.any(np.isinf(image), axis=2))),
        "negative": int(np.count_nonzero(np.any(np.isfinite(image) & (image < 0), axis=2))),
    }


def fireflies(image, variance, reference, reference_variance, k: float = DEFAULT_K, dof: int | None = None) -> dict:
    """Outlier pixels: ``count`` (fireflies) where some channel has render - reference > k sqrt(V_render +
    V_reference), ``dark`` where some channel has reference - render > k sqrt(...) (each V the variance of the
    pixel's estimate); finite pixels only; a difference with zero variance counts.

    ``expected`` is the count a correct, normally distributed render would have on one side by chance:
    pixels * channels * Q(k), with Q the upper tail of Student's t with ``dof`` (spp - 1) degrees of freedom (the
    variance is estimated) or of the normal when ``dof`` is None. Real fireflies are heavy-tailed outliers, far
    more frequent than that; so are dark outliers, in pixels whose rare bright paths were not drawn (their sample
    variance underestimates the true one): the untransformed scene's row is the baseline to compare with.
    """
    t = np.asarray(image, np.float64)
    r = np.asarray(reference, np.float64)
    sigma = np.sqrt(np.asarray(variance, np.float64) + np.asarray(reference_variance, np.float64))
    diff = t - r
    with np.errstate(invalid="ignore"):
        usable = np.isfinite(diff) & np.isfinite(sigma)
        bright = usable & (diff > k * sigma)
        dark = usable & (-diff > k * sigma)
    tail = normal_sf(k) if dof is None else student_t_sf(k, dof)
    return {"count": int(np.count_nonzero(np.any(bright, axis=2))), "dark": int(np.count_nonzero(np.any(dark, axis=2))),
            "k": float(k), "expected": float(t.shape[0] * t.shape[1] * t.shape[2] * tail)}


def undersampled_light(scene: Scene, reference: np.ndarray, reference_variance: np.ndarray, reference_spp: int,
                       spp: int) -> dict | None:
    """The pixel most likely to miss a directly seen light: coverage c = reference / Le (the fraction of the pixel
    that sees the light, estimated from the ground truth, in the channel of the brightest emission), and
    P(no camera sample of ``spp`` hits it) = (1 - c)^spp. Only pixels that look like a partly covered light count:
    c > 1e-3 and a per-sample variance (reference_variance * reference_spp) of at least half the Bernoulli variance
    Le^2 c (1 - c). When P is not small the pixel is a rare event: its sample variance misses the light and the
    verdict's normal approximation fails there. None when no such pixel is seen (or the reference is exact)."""
    emissions = [np.asarray(s.emission, float) for s in scene.lights]
    if not emissions:
        return None
    brightest = np.max(emissions, axis=0)
    channel = int(np.argmax(brightest))
    coverage = np.asarray(reference, np.float64)[..., channel] / brightest[channel]
    per_sample = np.asarray(reference_variance, np.float64)[..., channel] * max(reference_spp, 0)
    bernoulli = brightest[channel] ** 2 * coverage * (1.0 - coverage)
    seen = (coverage > 1e-3) & (coverage < 1.0) & (per_sample >= 0.5 * bernoulli)
    if not np.any(seen):
        return None
    p_miss = np.where(seen, (1.0 - np.clip(coverage, 0.0, 1.0)) ** spp, 0.0)
    y, x = np.unravel_index(int(np.argmax(p_miss)), p_miss.shape)
    return {"pixel": [int(y), int(x)], "coverage": float(coverage[y, x]), "p_miss": float(p_miss[y, x])}


# ---- running -----------------------------------------------------------------------------------------------------


def run_stress(
    scene: Scene,
    renderers: list[str],
    *,
    variants: list[str] | None = None,
    spp: int = 64,
    seed: int = 0,
    ground_truth_spp: int = 1024,
    k: float = DEFAULT_K,
    alpha: float = 0.001,
    cache_dir=None,
    mitsuba_variant: str | None = None,
    settings: dict[str, str] | None = None,
    on_row: Callable[[dict], None] | None = None,
) -> dict:
    """Render every variant with every renderer and judge it; returns ``{"scene", "film", "spp", "k", "alpha",
    "ground_truth": {...}, "rows": [...], "ok"}`` (see ``docs/stress.md``). ``ok`` is True when every invariant
    variant of the reference ends as expected (passes, or fails where float32 limits make that expected).
    ``settings`` are the reference renderer's ``--set`` values (Mitsuba takes none)."""
    parsed = [parse_variant(v, "--variant") for v in (variants or DEFAULT_VARIANTS)]
    engines = {name: get_renderer(name) for name in renderers}
    gt_cache: dict[str, groundtruth.GroundTruth] = {}

    def truth(target: Scene, key: str):
        if key not in gt_cache:  # the untransformed scene may use its closed form; a strained one may not
            gt_cache[key] = groundtruth.ground_truth(target, spp=ground_truth_spp, cache_dir=cache_dir,
                                                     variant=mitsuba_variant, use_closed_form=key == "original")
        return gt_cache[key]

    rows = []
    for variant in parsed:
        try:
            transformed = variant.apply(scene)
        except HarnessError as err:  # a variant this scene cannot have (no light, no rectangle): a skipped row
            for name in engines:
                row = {"variant": variant.name, "group": variant.group, "renderer": name, "against": "-",
                       "expect": "pass", "note": str(err), "verdict": "skipped", "ok": True}
                rows.append(row)
                if on_row is not None:
                    on_row(row)
            continue
        limits = float32_limits(transformed)
        geometric = variant.kind in ("original", "scale", "translate")
        gt = truth(scene, "original") if variant.judged_against_original else truth(transformed, variant.name)
        for name, engine in engines.items():
            if name == "mitsuba":
                chosen = {"variant": mitsuba_variant} if mitsuba_variant else {}
            else:
                chosen = dict(settings or {})
            row = {"variant": variant.name, "group": variant.group, "renderer": name,
                   "against": "original" if variant.judged_against_original else "own ground truth",
                   "expect": expected_verdict(limits, name),
                   "note": limits_note(limits, name) if geometric or limits["expected_fail"] else variant.description,
                   "float32": limits}
            expect = row["expect"]
            start = time.perf_counter()
            try:
                result = engine.render(transformed, RenderRequest(spp=spp, seed=seed + 7919, settings=chosen))
                row.update(_judge(result, gt, k, alpha))
                light = undersampled_light(transformed, gt.image, gt.variance, gt.spp, spp)
                row["undersampled_light"] = light
                if row["verdict"] == "fail" and light is not None and light["p_miss"] > 0.01 \
                        and _near_tile(light["pixel"], row.get("worst_tile")):
                    row["note"] += (f"; pixel {tuple(light['pixel'])} sees a light over {100 * light['coverage']:.2g}%"
                                    f" of its area: P(no sample hits it at {spp} spp) = {light['p_miss']:.2g}")
            except Exception as err:  # noqa: BLE001 - a renderer that breaks on a variant is a row, not a crash
                reason = " ".join(f"{type(err).__name__}: {err}".split())[:300]
                row.update(verdict="error", reason=reason, seconds=time.perf_counter() - start)
            row["ok"] = row["verdict"] == expect or (expect == "fail" and row["verdict"] in ("pass", "error"))
            if expect == "fail" and row["verdict"] == "pass":
                row["note"] = "passed despite: " + row["note"]
            rows.append(row)
            if on_row is not None:
                on_row(row)
    original_gt = gt_cache.get("original") or truth(scene, "original")
    ok = all(r["ok"] for r in rows if r["renderer"] == "reference" and r["group"] == INVARIANT)
    return {
        "scene": str(scene.path), "name": scene.name, "film": [scene.film.width, scene.film.height],
        "spp": spp, "seed": seed, "k": k, "alpha": alpha, "settings": dict(settings or {}),
        "ground_truth": {"spp": ground_truth_spp, "source": original_gt.source,
                         "variant": original_gt.info.get("variant"),
                         "mitsuba": original_gt.info.get("mitsuba")},
        "renderers": list(renderers), "rows": rows, "ok": ok,
    }


def _judge(result, gt, k, alpha) -> dict:
    counts = pixel_counts(result.image)
    fly = fireflies(result.image, result.variance, gt.image, gt.variance, k, dof=max(result.spp - 1, 1))
    comparison = compare_images(ExrImage(result.image, result.variance, {"spp": str(result.spp)}),
                                ExrImage(gt.image, gt.variance, {"spp": str(gt.spp)}), alpha=alpha)
    verdict = comparison["verdict"]
    z = [abs(v) for v in verdict["global_bias"].get("z", []) if v is not None]
    return dict(counts, rmse=comparison["metrics"]["rmse"], relmse=comparison["metrics"]["relmse"],
                bias_z=max(z) if z else None, fireflies=fly["count"], dark=fly["dark"], fireflies_expected=fly["expected"],
                seconds=float(result.seconds), verdict=verdict["verdict"], reason=verdict.get("reason", ""),
                worst_tile=verdict.get("worst_tile"))


def _near_tile(pixel, tile: dict | None) -> bool:
    """True if ``pixel`` (y, x) lies in the verdict's worst tile or one pixel around it."""
    if not tile:
        return False
    y, x = pixel
    return (tile["y"] - 1 <= y <= tile["y"] + tile["height"]) and (tile["x"] - 1 <= x <= tile["x"] + tile["width"])


# ---- the table ---------------------------------------------------------------------------------------------------

COLUMNS = ("variant", "renderer", "nan", "inf", "neg", "rmse", "relmse", "bias z", "fireflies", "dark", "s", "verdict",
           "note")


def table_rows(result: dict) -> list[list[str]]:
    """The table's cells, one list per (variant, renderer) row."""
    out = []
    for r in result["rows"]:
        verdict = r["verdict"]
        if r["expect"] == "fail":
            verdict += " (expected fail)" if verdict != "pass" else " (expected fail: passed)"
        if verdict.startswith("error"):
            note = r.get("reason", "")
        elif r["verdict"] == "fail" and r["expect"] == "pass":
            note = f"{r['note']}; {r.get('reason', '')}"
        else:
            note = r["note"]
        out.append([
            r["variant"], r["renderer"], _cell(r.get("nan")), _cell(r.get("inf")), _cell(r.get("negative")),
            _cell(r.get("rmse"), ".3g"), _cell(r.get("relmse"), ".3g"), _cell(r.get("bias_z"), ".2f"),
            _cell(r.get("fireflies")), _cell(r.get("dark")), _cell(r.get("seconds"), ".2f"), verdict, note,
        ])
    return out


def _cell(value, fmt: str = "d") -> str:
    if value is None:
        return "-"
    return format(value, fmt)


def format_table(result: dict, markdown: bool = False) -> str:
    """The stress table as aligned text, or as a Markdown table."""
    rows = table_rows(result)
    if markdown:
        lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
        lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rows]
        return "\n".join(lines)
    widths = [max(len(h), *(len(row[i]) for row in rows)) if rows else len(h) for i, h in enumerate(COLUMNS[:-1])]
    def line(cells):
        return "  ".join(c.ljust(w) for c, w in zip(cells[:-1], widths)) + "  " + cells[-1]
    return "\n".join([line(list(COLUMNS)), *(line(row) for row in rows)])


def summary_line(result: dict) -> str:
    """One line: the firefly rule and what the exit code means."""
    k = result["k"]
    fly = next((r.get("fireflies_expected") for r in result["rows"] if r.get("fireflies_expected") is not None), None)
    chance = f"{fly:.2g}" if fly is not None else "n/a"
    gt = result["ground_truth"]
    source = ("closed form" if gt.get("source") == "closed-form"
              else f"Mitsuba {gt.get('variant')} {gt['spp']} spp")
    return (f"{result['name']} {result['film'][0]}x{result['film'][1]}, {result['spp']} spp, ground truth "
            f"{source}; fireflies: "
            f"render - GT > {k:g} sigma, dark: GT - render > {k:g} sigma (each expected by chance per row: "
            f"{chance}); verdict alpha "
            f"{result['alpha']:g}; reference invariants as expected: {'yes' if result['ok'] else 'NO'}")
