"""Efficiencies and their ratios with confidence intervals from independent repeats (different seeds).

An estimator's efficiency is 1 / (MSE x time) (Veach 1997, section 2.5). One render gives one MSE and one time, both
noisy (the MSE by the image's own noise, the time by the machine); a ratio of two such numbers can be 2x off without
any real difference. The functions here take each strategy's per-seed MSEs and seconds, compute the ratio of means
and put a confidence interval on it by the delta method on the log scale, with Student's t and the
Welch-Satterthwaite degrees of freedom. Celarek et al. 2019 ("Quantifying the Error of Light Transport Algorithms",
Computer Graphics Forum 38(4)) measure the error of the error in the same way: over independent runs of a renderer,
not from one image. ``tests/judges/test_efficiency.py`` checks the intervals' coverage on draws of known ratio.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.special import stdtrit

#: the confidence level of every interval the strategy tables show
LEVEL = 0.95
#: a strategy whose target equal-time spp is within this factor of the equal-spp budget is taken at the equal-spp
#: renders for the equal-time comparison too (its efficiency, 1 / (MSE x time), corrects what is left)
EQUAL_TIME_TOLERANCE = 1.25
#: a strategy's equal-time spp stays within this factor of the equal-spp budget
MAX_EQUAL_TIME_FACTOR = 16
#: the relative resolution of a float32 image (2^-23): what rounding alone leaves of an exact estimate
FLOAT32_EPS = float(np.finfo(np.float32).eps)

__all__ = ["LEVEL", "EQUAL_TIME_TOLERANCE", "MAX_EQUAL_TIME_FACTOR", "FLOAT32_EPS", "log_mean_product",
           "ratio_interval", "efficiency_interval", "efficiency_ratio", "best_separated", "shown_mse",
           "equal_time_spp", "float_resolution", "zero_variance"]


def log_mean_product(*columns: Sequence[float]) -> tuple[float, float, int]:
    r"""The log of the product of the columns' means, and its variance by the delta method.

    Parameters
    ----------
    columns
        Per-seed samples, one array per factor, all of length n and paired by seed (e.g. a render's MSE and its
        seconds: both come from the same render).

    Returns
    -------
    (g, var_g, n)
        :math:`g = \sum_j \log \bar x_j` and :math:`\mathrm{Var}(g) \approx \nabla g^\top S \nabla g / n` with
        :math:`\nabla g_j = 1 / \bar x_j` and S the sample covariance of the columns (ddof 1; the pairing keeps the
        covariance of MSE and time). var_g is NaN for n < 2; g is NaN when a mean is not positive.
    """
    x = np.asarray(columns, dtype=np.float64).reshape(len(columns), -1)
    n = x.shape[1]
    means = x.mean(axis=1)
    if n == 0 or np.any(~np.isfinite(means)) or np.any(means <= 0):
        return math.nan, math.nan, n
    g = float(np.log(means).sum())
    if n < 2:
        return g, math.nan, n
    grad = 1.0 / means
    cov = np.atleast_2d(np.cov(x, ddof=1))
    return g, float(grad @ cov @ grad) / n, n


def _interval(log_value: float, var: float, dof: float, level: float, seeds: Sequence[int]) -> dict:
    """{value, low, high, level, dof, seeds} of exp(log_value) with the interval exp(log_value +- t * sqrt(var))."""
    value = math.exp(log_value) if math.isfinite(log_value) else None
    if value is None or not (math.isfinite(var) and math.isfinite(dof) and dof > 0):
        return {"value": value, "low": None, "high": None, "level": level, "dof": None, "seeds": list(seeds)}
    half = float(stdtrit(dof, 0.5 + level / 2.0)) * math.sqrt(max(var, 0.0))
    return {"value": value, "low": math.exp(log_value - half), "high": math.exp(log_value + half), "level": level,
            "dof": float(dof), "seeds": list(seeds)}


def ratio_interval(numerator: Sequence[Sequence[float]], denominator: Sequence[Sequence[float]],
                   level: float = LEVEL) -> dict:
    r"""The ratio of the products of means, :math:`\prod_j \bar a_j / \prod_j \bar b_j`, with its confidence interval.

    ``numerator`` and ``denominator`` are each a list of per-seed columns (:func:`log_mean_product`), from
    independent renders (different seeds), so the variances of the two logs add. The interval is
    :math:`\exp(\log r \pm t_{\nu, (1+level)/2} \sqrt{v_a + v_b})` with the Welch-Satterthwaite degrees of freedom
    :math:`\nu = (v_a + v_b)^2 / (v_a^2 / (n_a - 1) + v_b^2 / (n_b - 1))` (the delta method on the log of a ratio of
    means; Welch 1947). Returns {value, low, high, level, dof, seeds: [n_a, n_b]}; low and high are None with fewer
    than 2 seeds on a side.
    """
    ga, va, na = log_mean_product(*numerator)
    gb, vb, nb = log_mean_product(*denominator)
    var = va + vb
    denom = (va**2 / (na - 1) if na > 1 else math.inf) + (vb**2 / (nb - 1) if nb > 1 else math.inf)
    dof = var**2 / denom if denom > 0 else (min(na, nb) - 1 if math.isfinite(var) else math.nan)
    return _interval(ga - gb, var, dof, level, [na, nb])


def efficiency_interval(mse: Sequence[float], seconds: Sequence[float], level: float = LEVEL) -> dict:
    r"""Efficiency :math:`1 / (\overline{MSE} \cdot \bar t)` over a strategy's seeds, with its interval
    (:func:`log_mean_product` on the paired columns, Student's t with n - 1 degrees of freedom)."""
    g, var, n = log_mean_product(mse, seconds)
    return _interval(-g, var, n - 1, level, [n])


def efficiency_ratio(mse: Sequence[float], seconds: Sequence[float], mse_ref: Sequence[float],
                     seconds_ref: Sequence[float], level: float = LEVEL) -> dict:
    """A strategy's efficiency over a reference strategy's (e.g. the default's), each from its own seeds:
    (mean MSE_ref x mean t_ref) / (mean MSE x mean t), with its interval (:func:`ratio_interval`)."""
    return ratio_interval((mse_ref, seconds_ref), (mse, seconds), level)


def best_separated(samples: Mapping[str, tuple[Sequence[float], Sequence[float]]], level: float = LEVEL) -> dict:
    """The strategy of highest efficiency, named only when it is told apart from every other.

    ``samples``: {label: (per-seed MSE, per-seed seconds)}. The leader is the label of highest point efficiency;
    it is the best when, for every other label, the interval of the leader's efficiency over that label's
    (:func:`efficiency_ratio`) lies above 1, each at level 1 - (1 - ``level``) / (k - 1) (Bonferroni over the k - 1
    comparisons, so that all of them hold together at ``level``).

    Returns {best: label | None, leader, level (each comparison's), comparisons: {label: interval}, tied: [labels
    whose interval reaches 1]}.
    """
    points = {}
    for label, (mse, seconds) in samples.items():
        g, _var, _n = log_mean_product(mse, seconds)
        if math.isfinite(g):
            points[label] = -g
    if not points:
        return {"best": None, "leader": None, "level": level, "comparisons": {}, "tied": []}
    leader = max(points, key=points.get)
    others = [k for k in points if k != leader]
    each = 1.0 - (1.0 - level) / max(len(others), 1)
    comparisons = {k: efficiency_ratio(*samples[leader], *samples[k], level=each) for k in others}
    tied = [k for k, c in comparisons.items() if c["low"] is None or c["low"] <= 1.0]
    return {"best": leader if not tied else None, "leader": leader, "level": each, "comparisons": comparisons,
            "tied": tied}


def shown_mse(mse_corrected: float | None, bound: float | None) -> dict:
    """An MSE measured against a noisy ground truth, as a table shows it: {"value": the MSE, or None when it lies
    below ``bound``, "bound": ``bound`` then}. ``bound`` is the ground truth's own variance contribution to the
    measured MSE (``floor_mse`` of :func:`harness.judges.floor.error_point`): an MSE below it is not resolved by
    this ground truth, and one below 0 (the floor subtracted from a smaller measurement) is never a real MSE."""
    if mse_corrected is None or not math.isfinite(mse_corrected):
        return {"value": None, "bound": None}
    limit = bound if bound is not None and math.isfinite(bound) and bound > 0 else 0.0
    if mse_corrected <= 0 or mse_corrected < limit:
        return {"value": None, "bound": limit}
    return {"value": float(mse_corrected), "bound": None}


def equal_time_spp(spp: int, seconds: float, reference_seconds: float, *, step: int = 1,
                   max_factor: float = MAX_EQUAL_TIME_FACTOR, tolerance: float = EQUAL_TIME_TOLERANCE) -> int:
    r"""The spp at which a strategy whose renders at ``spp`` took ``seconds`` (their mean) take the reference
    strategy's ``reference_seconds``: :math:`s^* = spp \cdot t_{ref} / t`, rounded to a multiple of ``step`` (at
    least ``step``), at most ``max_factor`` x ``spp``. Where :math:`s^*` lies within ``tolerance`` x of ``spp``
    (or ``seconds`` is not positive) it is ``spp`` itself: the renders at ``spp`` then serve for the equal-time
    comparison too, the efficiency's 1 / (MSE x time) correcting the rest."""
    target = spp * reference_seconds / seconds if seconds > 0 and reference_seconds > 0 else float(spp)
    equal = max(step, min(int(round(target / step)) * step, int(spp * max_factor)))
    if equal == spp or abs(math.log(target / spp)) <= math.log(tolerance):
        return int(spp)
    return int(equal)


def float_resolution(level: float | None) -> float:
    r"""The squared error rounding alone leaves in a float32 image of mean absolute level L (e.g. the ground
    truth's mean over pixels and channels): :math:`(\epsilon_{32} L)^2`, with :math:`\epsilon_{32} = 2^{-23}`;
    0 where no level is known."""
    if level is None or not math.isfinite(level) or level <= 0:
        return 0.0
    return (FLOAT32_EPS * float(level)) ** 2


def zero_variance(estimates: Sequence[float | None], resolution: float = 0.0) -> bool:
    """Whether an estimator is exact here: every seed's own variance estimate (the mean per-pixel variance of its
    mean; where a render has none, its measured MSE, the ground truth's noise not removed) is at most
    ``resolution`` (:func:`float_resolution`: rounding). Its efficiency 1 / (MSE x time) would be rounding's
    inverse, not a number to rank: a table shows "zero variance" and leaves it out of the ranking."""
    values = list(estimates)
    return bool(values) and all(v is not None and math.isfinite(v) and v <= resolution for v in values)
