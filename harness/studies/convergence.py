"""Convergence: error against samples per pixel and time, the fitted slope, bias detection, and equal-time /
equal-error comparisons read off the curves.

An unbiased Monte Carlo estimator at n samples per pixel has RMSE = c / sqrt(n): a line of slope -1/2 on log-log
axes (-1 for MSE and relMSE). A biased one has RMSE = sqrt(c^2 / n + b^2): it follows the line at first and
flattens towards b. The fit (:func:`fit_convergence`) reports the least-squares slope and the first point from which
the curve stays above the expected line by more than ``k`` times the expected scatter (see docs/report.md).

Errors are measured against a ground truth that has noise of its own (a Mitsuba render): its per-pixel variance F
adds to every expected MSE (E[(t - r)^2] = Var t + Var r + bias^2). :func:`error_point` subtracts it, so the curves
and fits describe the renderer alone; the floor is kept in the results and drawn on the plots.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from harness.core.errors import HarnessError
from harness.judges.floor import error_point
from harness.judges.spectrum import ensemble_spectrum
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.external import ExternalRendererError
from harness.running.budget import render_for_seconds
from reference_impl import Film

#: multiple of the expected scatter a point must exceed (above the fitted line) to count as leaving it
DEFAULT_K = 3.0
#: smallest expected scatter of log(RMSE) assumed at any point (2 %): the model's own imperfection
MIN_SCATTER = 0.02
#: the ladder of a suite report's convergence section (cheap on purpose)
DEFAULT_SPP_LADDER = (1, 2, 4, 8, 16)


# ---- fitting ---------------------------------------------------------------------------------------------------


def _finite_positive(values: Sequence[float | None]) -> np.ndarray:
    return np.array([v is not None and np.isfinite(v) and v > 0 for v in values], dtype=bool)


def fit_convergence(
    spp: Sequence[float],
    error: Sequence[float | None],
    *,
    expected_slope: float = -0.5,
    scatter: float | Sequence[float] | None = None,
    k: float = DEFAULT_K,
    min_scatter: float | None = None,
    min_run: int = 2,
) -> dict[str, Any]:
    """Fit log(error) against log(spp) and look for the point where the curve leaves the expected line.

    ``error`` is RMSE (``expected_slope = -0.5``) or an MSE-like error (``expected_slope = -1``). ``scatter`` is the
    expected standard deviation of log(error) at each point (a number for all points, or one per point; None:
    ``min_scatter``); it is never taken below ``min_scatter`` (default :data:`MIN_SCATTER`, doubled for an MSE-like
    error, whose log scatters twice as much as the log of its root).

    Returns a dict:

    - ``slope``, ``slope_stderr``, ``intercept``: ordinary least squares of log(error) on log(spp) over the usable
      points (finite, positive); ``points``: how many.
    - ``departure_index``, ``departure_spp``: the first point j from which every point i >= j (at least
      ``min_run`` points, so one unlucky last point is not a trend) lies above the expected line by more than
      ``k * sigma_i``. The line has the expected slope and is anchored on the points
      before j (its intercept is the mean of log(error_i) - expected_slope * log(spp_i) over i < j);
      sigma_i combines the point's own scatter with the anchor's. None when there is no such point.
    - ``biased``: whether a departure was found.
    - ``slope_before_departure``: the least-squares slope of the points before it (None with fewer than 2).
    - ``model``: the fit, in MSE terms, of MSE = a / spp + b^2 (a, b >= 0; least squares of the relative
      residuals), as ``{"variance_coefficient": a, "bias": ...}``: the level the curve flattens to, in the error's
      own units (b for RMSE, b^2 for an MSE-like error).
    - ``residuals``, ``thresholds``: per usable point, log(error) minus the anchored line, and k * sigma (both None
      for the first point, which only anchors).
    """
    x_all = np.asarray(spp, dtype=float)
    y_raw = list(error)
    if len(x_all) != len(y_raw):
        raise ValueError(f"spp has {len(x_all)} values but error has {len(y_raw)}")
    usable = _finite_positive(y_raw) & np.isfinite(x_all) & (x_all > 0)
    order = np.argsort(x_all, kind="stable")
    order = order[usable[order]]
    x = np.log(x_all[order])
    y = np.log(np.array([y_raw[i] for i in order], dtype=float))
    n = len(x)
    floor = (MIN_SCATTER if min_scatter is None else float(min_scatter)) * (2.0 if abs(expected_slope) > 0.75 else 1.0)
    if scatter is None:
        sig = np.full(n, floor)
    elif np.ndim(scatter) == 0:
        sig = np.full(n, max(float(scatter), floor))
    else:
        s_all = np.asarray(scatter, dtype=float)
        if len(s_all) != len(x_all):
            raise ValueError(f"scatter has {len(s_all)} values but spp has {len(x_all)}")
        sig = np.maximum(np.nan_to_num(s_all[order], nan=floor), floor)

    out: dict[str, Any] = {
        "expected_slope": expected_slope, "k": k, "min_run": int(min_run), "points": n, "slope": None, "slope_stderr": None,
        "intercept": None, "departure_index": None, "departure_spp": None, "biased": False,
        "slope_before_departure": None, "model": None,
        "spp": [float(v) for v in np.exp(x)], "residuals": [None] * n, "thresholds": [None] * n,
    }
    if n >= 2:
        slope, intercept, stderr = _ols(x, y)
        out.update(slope=slope, slope_stderr=stderr, intercept=intercept)
    if n >= 2:
        departure = None
        for j in range(1, n - max(int(min_run), 1) + 1):
            anchor, anchor_var = _anchor(x, y, sig, j, expected_slope)
            resid = y[j:] - (anchor + expected_slope * x[j:])
            if np.all(resid > k * np.sqrt(sig[j:] ** 2 + anchor_var)):
                departure = j
                break
        for i in range(1, n):
            # each point against the line anchored on the points before it (before the departure, once found)
            anchor, anchor_var = _anchor(x, y, sig, i if departure is None else min(i, departure), expected_slope)
            out["residuals"][i] = float(y[i] - (anchor + expected_slope * x[i]))
            out["thresholds"][i] = float(k * math.sqrt(sig[i] ** 2 + anchor_var))
        if departure is not None:
            out.update(departure_index=departure, departure_spp=float(np.exp(x[departure])), biased=True)
            if departure >= 2:
                out["slope_before_departure"] = _ols(x[:departure], y[:departure])[0]
        elif out["slope"] is not None:
            out["slope_before_departure"] = out["slope"]
        out["model"] = _variance_bias_model(np.exp(x), np.exp(y), expected_slope)
    return out


def _anchor(x: np.ndarray, y: np.ndarray, sig: np.ndarray, j: int, slope: float) -> tuple[float, float]:
    """Intercept of the line of the given slope through the first j points (mean of y - slope x), and its variance."""
    return float(np.mean(y[:j] - slope * x[:j])), float(np.sum(sig[:j] ** 2)) / j**2


def _ols(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float | None]:
    xm, ym = x.mean(), y.mean()
    sxx = float(np.sum((x - xm) ** 2))
    if sxx == 0.0:
        return float("nan"), float(ym), None
    slope = float(np.sum((x - xm) * (y - ym)) / sxx)
    intercept = float(ym - slope * xm)
    stderr = None
    if len(x) > 2:
        resid = y - (intercept + slope * x)
        stderr = float(math.sqrt(np.sum(resid**2) / (len(x) - 2) / sxx))
    return slope, intercept, stderr


def _variance_bias_model(spp: np.ndarray, err: np.ndarray, expected_slope: float) -> dict[str, float]:
    """MSE = a / spp + b^2 fitted to the points with relative weights (non-negative least squares on 2 unknowns)."""
    power = -1.0 / expected_slope  # 2 for RMSE, 1 for an MSE-like error
    mse = err**power
    design = np.stack([1.0 / spp, np.ones_like(spp)], axis=1) / mse[:, None]
    target = np.ones_like(spp)
    best = None
    candidates = []
    sol, *_ = np.linalg.lstsq(design, target, rcond=None)
    candidates.append(sol)
    for col in (0, 1):  # the boundary solutions (one coefficient 0)
        d = design[:, col]
        coef = float(d @ target / (d @ d)) if d @ d > 0 else 0.0
        candidates.append(np.array([coef, 0.0]) if col == 0 else np.array([0.0, coef]))
    for sol in candidates:
        if np.any(sol < 0):
            continue
        cost = float(np.sum((design @ sol - target) ** 2))
        if best is None or cost < best[0]:
            best = (cost, sol)
    a, b2 = (best[1] if best is not None else (0.0, 0.0))
    return {"variance_coefficient": float(a), "bias": float(math.sqrt(max(b2, 0.0)) ** (2.0 / power))}


# ---- reading values off curves ---------------------------------------------------------------------------------


def loglog_interpolate(xs: Sequence[float], ys: Sequence[float], x0: float) -> float | None:
    """y at x0 on the piecewise-linear curve in log-log coordinates through the points (sorted by x); None when x0
    is outside the points' x range (no extrapolation) or the points are unusable."""
    pts = sorted((float(x), float(y)) for x, y in zip(xs, ys)
                 if x is not None and y is not None and x > 0 and y > 0 and np.isfinite(x) and np.isfinite(y))
    if not pts or not (x0 > 0) or x0 < pts[0][0] or x0 > pts[-1][0]:
        return None
    for (xa, ya), (xb, yb) in zip(pts, pts[1:]):
        if xa <= x0 <= xb:
            if xb == xa:
                return ya
            t = (math.log(x0) - math.log(xa)) / (math.log(xb) - math.log(xa))
            return float(math.exp(math.log(ya) + t * (math.log(yb) - math.log(ya))))
    return pts[0][1] if x0 == pts[0][0] else None


def time_to_error(times: Sequence[float], errors: Sequence[float], target: float) -> float | None:
    """The time at which the curve (points ordered by time) first reaches ``target`` error, interpolated in
    log-log; None when it never does within the points, or ``target`` is above the first point's error."""
    pts = sorted((float(t), float(e)) for t, e in zip(times, errors)
                 if t is not None and e is not None and t > 0 and e > 0 and np.isfinite(t) and np.isfinite(e))
    if not pts or not (target > 0) or target > pts[0][1]:
        return None
    if pts[0][1] == target:
        return pts[0][0]
    for (ta, ea), (tb, eb) in zip(pts, pts[1:]):
        if (ea - target) * (eb - target) <= 0 and ea != eb:
            s = (math.log(target) - math.log(ea)) / (math.log(eb) - math.log(ea))
            return float(math.exp(math.log(ta) + s * (math.log(tb) - math.log(ta))))
    return None


def _loglog_line(xs: Sequence[float], ys: Sequence[float]) -> tuple[float, float] | None:
    """Least-squares (slope, intercept) of log y on log x over the usable points; None with fewer than 2."""
    pts = [(math.log(x), math.log(y)) for x, y in zip(xs, ys)
           if x is not None and y is not None and x > 0 and y > 0 and math.isfinite(x) and math.isfinite(y)]
    if len(pts) < 2:
        return None
    slope, intercept, _ = _ols(np.array([p[0] for p in pts]), np.array([p[1] for p in pts]))
    return (slope, intercept) if math.isfinite(slope) else None


def _usable(values) -> list[float]:
    return [float(v) for v in values if v is not None and np.isfinite(v) and v > 0]


#: a curve's own line is followed at most this factor beyond its measured times (below the shortest, above the
#: longest); further out a comparison says "out of range" rather than trust a line that far
MAX_EXTRAPOLATION = 2.0


def _within_reach(ts: Sequence[float], t: float) -> bool:
    """Whether time ``t`` lies within :data:`MAX_EXTRAPOLATION` of the curve's measured times."""
    usable = _usable(ts)
    return bool(usable) and min(usable) / MAX_EXTRAPOLATION <= t <= max(usable) * MAX_EXTRAPOLATION


def equal_time(curves: dict[str, tuple[Sequence[float], Sequence[float]]], at: float | None = None) -> dict:
    """The error each curve (label -> (times, errors)) reaches at the same time: ``at``, or by default the longest
    time every curve covers (the smallest of the curves' last times). Read off each curve by log-log interpolation;
    where a curve does not reach that time (no common range), along its own least-squares line in log-log,
    flagged in ``extrapolated``, but never further than :data:`MAX_EXTRAPOLATION` times beyond its measured
    times: there the error is None, flagged in ``out_of_range``. Ratios are to the first curve's error."""
    if not curves:
        return {"time": None, "errors": {}, "ratio_to_first": {}, "extrapolated": {}, "out_of_range": {}}
    if at is None:
        ends = [max(_usable(ts)) for ts, _ in curves.values() if _usable(ts)]
        if len(ends) != len(curves):
            return {"time": None, "errors": {k: None for k in curves}, "ratio_to_first": {k: None for k in curves},
                    "extrapolated": {k: False for k in curves}, "out_of_range": {k: False for k in curves},
                    "note": "a curve has no usable times"}
        at = min(ends)
    errors, extrapolated, out_of_range = {}, {}, {}
    for label, (ts, es) in curves.items():
        value = loglog_interpolate(ts, es, at)
        extrapolated[label] = out_of_range[label] = False
        if value is None:
            line = _loglog_line(ts, es)
            if line is not None and not _within_reach(ts, at):
                out_of_range[label] = True
            elif line is not None:
                value = float(math.exp(line[1] + line[0] * math.log(at)))
                extrapolated[label] = True
        errors[label] = value
    first = next(iter(errors.values()), None)
    ratios = {label: (e / first if e is not None and first else None) for label, e in errors.items()}
    return {"time": float(at), "errors": errors, "ratio_to_first": ratios, "extrapolated": extrapolated,
            "out_of_range": out_of_range}


def equal_error(curves: dict[str, tuple[Sequence[float], Sequence[float]]], target: float | None = None) -> dict:
    """The time each curve (label -> (times, errors)) needs to reach the same error: ``target``, or by default the
    smallest error every curve reaches (the largest of the curves' smallest errors). Read off each curve by
    log-log interpolation at its first crossing; a curve already below the target at its first point, or never
    reaching it, is extrapolated along its own least-squares line in log-log (flagged in ``extrapolated``), but
    only to a time within :data:`MAX_EXTRAPOLATION` times of its measured times (beyond: None, flagged in
    ``out_of_range``). Speed-ups are the first curve's time divided by each curve's."""
    if not curves:
        return {"error": None, "times": {}, "speedup_vs_first": {}, "extrapolated": {}, "out_of_range": {}}
    if target is None:
        lows = [min(_usable(es)) for _, es in curves.values() if _usable(es)]
        if len(lows) != len(curves):
            return {"error": None, "times": {k: None for k in curves}, "speedup_vs_first": {k: None for k in curves},
                    "extrapolated": {k: False for k in curves}, "out_of_range": {k: False for k in curves},
                    "note": "a curve has no usable errors"}
        target = max(lows)
    times, extrapolated, out_of_range = {}, {}, {}
    for label, (ts, es) in curves.items():
        value = time_to_error(ts, es, target)
        extrapolated[label] = out_of_range[label] = False
        if value is None:
            line = _loglog_line(ts, es)
            if line is not None and line[0] < 0:
                value = float(math.exp((math.log(target) - line[1]) / line[0]))
                extrapolated[label] = True
                if not _within_reach(ts, value):
                    value, extrapolated[label], out_of_range[label] = None, False, True
        times[label] = value
    first = next(iter(times.values()), None)
    speedups = {label: (first / t if t and first is not None else None) for label, t in times.items()}
    return {"error": float(target), "times": times, "speedup_vs_first": speedups, "extrapolated": extrapolated,
            "out_of_range": out_of_range}


def _has_points(values) -> bool:
    return any(v is not None and np.isfinite(v) and v > 0 for v in values)


# ---- measuring -------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Series:
    """One curve: a renderer with its settings."""

    renderer: str
    settings: dict[str, str] = field(default_factory=dict)
    label: str = ""

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        extra = " ".join(f"{k}={v}" for k, v in self.settings.items())
        return f"{self.renderer} {extra}".strip()


def parse_ladder(text: str, option: str, kind=int) -> list:
    """'1,2,4,8' -> [1, 2, 4, 8]; one-line HarnessError naming ``option`` otherwise."""
    values = []
    for item in str(text).split(","):
        item = item.strip()
        if not item:
            continue
        try:
            value = kind(item)
        except ValueError:
            what = "integers" if kind is int else "numbers"
            raise HarnessError(option, f"expected comma-separated positive {what}, got {item!r}") from None
        if not value > 0 or (isinstance(value, float) and not math.isfinite(value)):
            raise HarnessError(option, f"expected positive values, got {item!r}")
        values.append(value)
    if not values:
        raise HarnessError(option, "expected at least one value")
    return sorted(set(values))


#: renders shorter than this are repeated (same seed) until this much time is spent, and timed by their mean
MIN_TIMING_SECONDS = 0.05
MAX_TIMING_REPEATS = 50


def timed_render(renderer, scene, request, min_seconds: float = MIN_TIMING_SECONDS):
    """Render once; if that took less than ``min_seconds``, render again with the same request until the total
    does, so that a tiny render's time is not lost in scheduler noise. Returns (result of the first render, mean
    seconds per render, number of renders). A renderer whose ``cheap_to_repeat`` is False (an external renderer:
    every render restarts its process) renders once."""
    result = renderer.render(scene, request)
    total, count = float(result.seconds), 1
    repeat = getattr(renderer, "cheap_to_repeat", True)
    while repeat and total < min_seconds and count < MAX_TIMING_REPEATS:
        total += float(renderer.render(scene, request).seconds)
        count += 1
    return result, total / count, count


def run_convergence(
    scene,
    ground_truth,
    series: Sequence[Series],
    *,
    spp: Sequence[int] = DEFAULT_SPP_LADDER,
    seconds: Sequence[float] = (),
    seed: int = 1,
    chunk_spp: int = 1,
    k: float = DEFAULT_K,
    variant: str | None = None,
    warmup: bool = True,
    min_timing_seconds: float = MIN_TIMING_SECONDS,
    progress: Callable[[str], None] | None = None,
    renderer_factory: Callable[[str], Any] | None = None,
    repeats: int = 1,
    spectrum: bool = False,
) -> dict[str, Any]:
    """Render ``scene`` with each series at every rung of the spp ladder (and of the seconds ladder: chunks of
    ``chunk_spp`` until the time is spent), every render with its own seed, and measure each against ``ground_truth``
    (an object with ``image``, ``variance``, ``source``, ``spp``). Returns a JSON-ready dict: per series the points
    (spp, seconds, seeds, errors), the fits of RMSE and relMSE against spp, and equal-time / equal-error
    comparisons between the series. ``warmup``: one untimed 1-spp render per series first, so that one-off costs
    (compilation, acceleration structures) do not land on the first rung. A rung that renders in less than
    ``min_timing_seconds`` is rendered again (same seed) and timed by the mean (see :func:`timed_render`).
    ``progress(description)`` is called after every rung. ``renderer_factory(name)`` builds each series'
    renderer (default: :func:`harness.renderers.get_renderer`).

    Every render asks for the rung's spp with ``RenderRequest.variance`` False (the errors are measured against the
    ground truth; the render's own variance is not used), so an external renderer without variance channels runs
    its program once per render and its image holds exactly the rung's spp: a point of the ``n``-spp rung is an
    ``n``-spp image, not K runs of n / K (which a stratified sampler converges differently from). A render that
    holds another count all the same (a sampler that rounds it) is kept at the spp its image holds
    (``render.spp``; ``budget.spp`` is the rung), flagged ``on_rung`` False and named in the series' ``warnings``
    (:func:`off_rung`). The series says where its times come from (``time_from``: the renderer's own clock, or its
    wall time less the start-up). A rung an external renderer refuses (it exits with an error, e.g. the Cycles
    adapter at 1 spp, which needs two batches for its variance) is left out and named in the series' ``skipped``;
    a series with no point at all is named in ``failed_series``.

    ``repeats`` K > 1 renders every rung K times with distinct seeds (the error of the error, Celarek et al. 2019):
    the point's errors are then the means over the K runs (E[MSE], the curves and fits use them) and its
    ``repeats`` holds each run's corrected MSE and relMSE with their standard deviation and 10-90 % band
    (:func:`repeat_point`). ``spectrum``: each point also gets the error spectrum ensemble of its runs
    (:func:`harness.judges.spectrum.ensemble_spectrum`, the ground truth's noise floor subtracted)."""
    if not series:
        raise HarnessError("--renderer", "expected at least one renderer")
    seeds = iter(range(seed, seed + 10**9))
    out_series: list[dict] = []
    failed: list[dict] = []  # series with no point at all (every rung refused), and why
    for s in series:
        renderer = (renderer_factory or get_renderer)(s.renderer)
        settings = dict(s.settings)
        if s.renderer == "mitsuba" and variant and "variant" not in settings:
            settings["variant"] = variant
        points = []
        resolved: dict = {}
        time_from = None
        skipped: list[dict] = []  # rungs an external renderer refused (e.g. too few samples for its variance)
        warnings: list[str] = []  # rungs rendered at another spp than their label
        if warmup:
            for n in (1, *spp):  # the smallest spp the renderer takes
                try:
                    renderer.render(scene, RenderRequest(spp=int(n), seed=next(seeds), settings=settings,
                                                         variance=False))
                except ExternalRendererError:
                    continue
                break
        for n in spp:
            results, times, used = [], [], []
            try:
                for index in range(repeats):
                    sd = next(seeds)
                    request = RenderRequest(spp=int(n), seed=sd, settings=settings, variance=False)
                    if index == 0:
                        result, secs, timing_repeats = timed_render(renderer, scene, request, min_timing_seconds)
                    else:  # timed once each: the mean over the K runs is the point's time
                        result = renderer.render(scene, request)
                        secs = float(result.seconds)
                    results.append(result)
                    times.append(secs)
                    used.append(sd)
            except ExternalRendererError as err:
                skipped.append({"spp": int(n), "reason": str(err)})
                if progress is not None:
                    progress(f"{s.name} {n} spp (refused)")
                continue
            result = results[0]
            resolved = result.settings
            time_from = result.info.get("time_from", time_from)
            point = repeat_point(results, ground_truth, spectrum)
            off = off_rung(int(n), [int(r.spp) for r in results])
            if off is not None:
                warnings.append(f"{s.name}: {off}")
            points.append(dict(budget={"spp": int(n)}, spp=int(result.spp), on_rung=off is None,
                               seconds=float(np.mean(times)), timing_repeats=timing_repeats, seeds=used, **point))
            if progress is not None:
                progress(f"{s.name} {n} spp")
        for budget in seconds:
            merged_runs = [render_for_seconds(renderer, scene, budget, chunk_spp, seeds, settings)
                           for _ in range(repeats)]
            merged = merged_runs[0]
            resolved = merged.settings
            point = repeat_point(merged_runs, ground_truth, spectrum)
            points.append(dict(budget={"seconds": float(budget)}, spp=int(merged.spp),
                               seconds=float(np.mean([m.seconds for m in merged_runs])), timing_repeats=1,
                               seeds=[sd for m in merged_runs for sd in m.info["seeds"]], **point))
            if progress is not None:
                progress(f"{s.name} {budget:g} s")
        if not points:
            failed.append({"label": s.name, "renderer": s.renderer,
                           "error": skipped[0]["reason"] if skipped else "no points"})
            continue
        points.sort(key=lambda p: (p["spp"], p["seconds"]))
        fit_rmse = fit_convergence([p["spp"] for p in points], [p["rmse_corrected"] for p in points],
                                   expected_slope=-0.5, scatter=[p["scatter_log_rmse"] for p in points], k=k)
        fit_relmse = fit_convergence([p["spp"] for p in points],
                                     [p["relmse_corrected"] if (p["relmse_corrected"] or 0) > 0 else None
                                      for p in points],
                                     expected_slope=-1.0, scatter=[p["scatter_log_relmse"] for p in points], k=k)
        out_series.append({"label": s.name, "renderer": s.renderer, "settings": dict(s.settings),
                           "resolved_settings": resolved, "points": points, "time_from": time_from,
                           "skipped": skipped, "warnings": warnings,
                           "fit_rmse": fit_rmse, "fit_relmse": fit_relmse})
    return {
        "scene": str(getattr(scene, "path", "")),
        "scene_name": getattr(scene, "name", ""),
        "film": [scene.film.width, scene.film.height],
        "max_depth": scene.max_depth,
        "ground_truth": {"source": ground_truth.source, "spp": ground_truth.spp,
                         "path": str(getattr(ground_truth, "path", None)) if getattr(ground_truth, "path", None)
                         else None},
        "spp_ladder": [int(n) for n in spp], "seconds_ladder": [float(s) for s in seconds], "repeats": int(repeats),
        "k": k, "series": out_series, "failed_series": failed,
        "comparisons": compare_series(out_series),
    }


def repeat_point(results: Sequence, ground_truth, spectrum: bool = False) -> dict[str, Any]:
    """The errors of one rung from its K renders (:func:`harness.judges.floor.error_point` each): with K = 1 that
    render's point; with K > 1 the means over the runs (``mse``, ``relmse``, their corrected values: E[MSE], and
    the RMSE of the mean MSE), ``repeats`` = {``k``, each run's ``mse_corrected`` and ``relmse_corrected``, their
    sample standard deviations (``*_std``, ddof 1) and 10-90 % bands (``*_band``, linear quantiles of the K
    values)}, and the expected scatter of log RMSE (log relMSE) from the runs' spread: the relative standard error
    of the mean, std / (mean sqrt K), halved for the root, never below the in-image estimate over sqrt K. With
    ``spectrum``, ``spectrum``: the error spectrum ensemble of the runs (:func:`ensemble_spectrum`, floor: the
    mean of the ground truth's variance per channel) and ``render_variance``, the mean of the renders' own
    variance estimates (where a render without a bias would sit: white noise at that level)."""
    points = [error_point(r.image, ground_truth.image, ground_truth.variance) for r in results]
    k = len(points)
    if k == 1:
        point = dict(points[0])
    else:
        point = {"pixels": points[0]["pixels"]}
        for key in ("mse", "relmse", "floor_mse", "floor_relmse", "mse_corrected", "relmse_corrected"):
            values = [p[key] for p in points if p[key] is not None]
            point[key] = float(np.mean(values)) if len(values) == k else None
        point["rmse"] = math.sqrt(point["mse"]) if point["mse"] is not None else None
        mse_c = point["mse_corrected"]
        point["rmse_corrected"] = math.sqrt(mse_c) if mse_c is not None and mse_c > 0 else None
        spread: dict[str, Any] = {"k": k}
        for key, scatter_key, half in (("mse_corrected", "scatter_log_rmse", 0.5),
                                       ("relmse_corrected", "scatter_log_relmse", 1.0)):
            values = np.array([p[key] for p in points if p[key] is not None], dtype=float)
            spread[key] = [float(v) for v in values]
            std = float(np.std(values, ddof=1)) if len(values) > 1 else None
            spread[f"{key}_std"] = std
            spread[f"{key}_band"] = ([float(np.quantile(values, 0.1)), float(np.quantile(values, 0.9))]
                                     if len(values) else None)
            inner = [p[scatter_key] for p in points if p[scatter_key] is not None]
            mean = point[key]
            between = half * std / (mean * math.sqrt(k)) if std is not None and mean and mean > 0 else None
            within = float(np.mean(inner)) / math.sqrt(k) if inner else None
            candidates = [v for v in (between, within) if v is not None]
            point[scatter_key] = max(candidates) if candidates else None
        point["repeats"] = spread
    if spectrum:
        truth = np.asarray(ground_truth.image, np.float64)
        floor = (np.zeros(3) if ground_truth.variance is None else
                 np.nanmean(np.asarray(ground_truth.variance, np.float64), axis=(0, 1)))
        point["spectrum"] = ensemble_spectrum([np.asarray(r.image, np.float64) - truth for r in results], floor)
        own = [_finite_mean(r.variance) for r in results if r.variance is not None]
        own = [v for v in own if v is not None]  # 1 spp: the reference reports no variance (NaN)
        point["spectrum"]["render_variance"] = float(np.mean(own)) if own else None
    return point


def _finite_mean(values) -> float | None:
    v = np.asarray(values, np.float64)
    ok = np.isfinite(v)
    return float(v[ok].mean()) if ok.any() else None


def spectrum_balance(spectrum: dict) -> tuple[float | None, float | None]:
    """Where an error spectrum's power lies: the mean corrected power of its lowest tenth of rings (at least one)
    and of its upper half. Equal for white noise; the first far above the second for structured (low-frequency)
    error."""
    power = spectrum.get("power_corrected") or []
    if not power:
        return None, None
    low = power[: max(1, len(power) // 10)]
    high = power[len(power) // 2:] or power
    return float(np.mean(low)), float(np.mean(high))


def off_rung(rung: int, rendered: Sequence[int]) -> str | None:
    """Why a point of the ``rung``-spp rung is not at its label: None when every render of it (``rendered``, their
    ``RenderResult.spp``) holds exactly ``rung`` samples per pixel, else a sentence saying what they held (a
    renderer whose sampler rounds the count, or one that repeats runs although asked for no variance). Such a
    point is kept at the spp it holds, flagged (``on_rung`` False) and named in the series' ``warnings``."""
    wrong = sorted({n for n in rendered if n != rung})
    if not wrong:
        return None
    return (f"the {rung}-spp rung was rendered at {', '.join(str(n) for n in wrong)} spp per pixel; the point sits "
            f"at the spp its image holds, not at its label")


def compare_series(series: list[dict]) -> dict:
    """Equal-time and equal-error comparisons of the series' corrected RMSE and relMSE against render time."""
    if len(series) < 2:
        return {}
    out = {}
    for metric in ("rmse_corrected", "relmse_corrected"):
        curves = {s["label"]: ([p["seconds"] for p in s["points"]], [p[metric] for p in s["points"]])
                  for s in series}
        if len(curves) < len(series):  # duplicate labels: make them unique
            curves = {f"{i}: {s['label']}": ([p["seconds"] for p in s["points"]], [p[metric] for p in s["points"]])
                      for i, s in enumerate(series)}
        out[metric] = {"equal_time": equal_time(curves), "equal_error": equal_error(curves)}
    return out


def replace_film(scene, width: int | None, height: int | None):
    """The scene at another resolution (same filter)."""
    if not width and not height:
        return scene
    film = Film(width or scene.film.width, height or scene.film.height, scene.film.filter)
    return dataclasses.replace(scene, film=film)


def timed(fn, *args, **kwargs):
    start = time.perf_counter()
    value = fn(*args, **kwargs)
    return value, time.perf_counter() - start
