"""Errors of a render against a ground truth that has noise of its own, with that noise (the floor) removed.

A ground truth rendered by Monte Carlo (Mitsuba at many spp) has per-pixel variance V of its own, which adds to the
expected squared error of any render against it: E[(render - gt)^2] = Var(render) + V + bias^2. :func:`error_point`
measures MSE and relMSE and subtracts the mean of V (resp. V / (gt^2 + eps)), so that errors, curves and fits
describe the render alone (docs/report.md, "Errors with the ground truth's noise removed"). A closed form has no
floor (V = 0).
"""

from __future__ import annotations

import math

import numpy as np

from harness.judges.metrics import RELMSE_EPS

#: the most of the test render's variance a ground truth's own variance may be: beyond it the verdict's noise is
#: more than 1.25 x the test's alone, and the ground truth, not the test's budget, limits what it can see
GROUND_TRUTH_SHARE_LIMIT = 0.25

__all__ = ["GROUND_TRUTH_SHARE_LIMIT", "error_point", "ground_truth_share", "spp_for_share"]


def error_point(image: np.ndarray, expected: np.ndarray, expected_variance: np.ndarray | None,
                mask: np.ndarray | None = None) -> dict[str, float | None]:
    """MSE and relMSE of ``image`` against ``expected`` (the ground truth) over the pixels finite in both (and in
    ``mask``), with the ground truth's own noise floor (``expected_variance``; None: none) subtracted, and the
    expected scatter of log(RMSE) and log(relMSE).

    Returns ``mse``, ``relmse`` (raw), ``floor_mse``, ``floor_relmse`` (the mean of the ground truth's variance, plain
    and relative: what its noise adds to the expected errors), ``mse_corrected``, ``relmse_corrected`` (raw minus
    floor; may be <= 0 when the render is much less noisy than the ground truth), ``rmse``, ``rmse_corrected`` (None
    when the corrected MSE is not positive), ``scatter_log_rmse``, ``scatter_log_relmse`` (from the squared errors'
    own spread: the relative standard deviation of their mean is sqrt(sum e^4 / (sum e^2)^2 - 1/N)), ``pixels``.
    """
    t = np.asarray(image, dtype=np.float64)
    r = np.asarray(expected, dtype=np.float64)
    ok = np.all(np.isfinite(t), axis=-1) & np.all(np.isfinite(r), axis=-1)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    out: dict[str, float | None] = {"pixels": int(ok.sum())}
    if not ok.any():
        return dict(out, mse=None, relmse=None, floor_mse=None, floor_relmse=None, mse_corrected=None,
                    relmse_corrected=None, rmse=None, rmse_corrected=None, scatter_log_rmse=None,
                    scatter_log_relmse=None)
    e2 = (t[ok] - r[ok]) ** 2
    w = 1.0 / (r[ok] ** 2 + RELMSE_EPS)
    mse, relmse = float(e2.mean()), float((e2 * w).mean())
    if expected_variance is not None:
        v = np.nan_to_num(np.asarray(expected_variance, dtype=np.float64)[ok], nan=0.0, posinf=0.0)
        floor, floor_rel = float(v.mean()), float((v * w).mean())
    else:
        floor, floor_rel = 0.0, 0.0
    mse_c, relmse_c = mse - floor, relmse - floor_rel

    def scatter(values: np.ndarray, total: float, corrected: float) -> float | None:
        s1 = float(values.sum())
        if s1 <= 0 or corrected <= 0:
            return None
        rel = math.sqrt(max(float((values**2).sum()) / s1**2 - 1.0 / values.size, 0.0))
        return 0.5 * rel * total / corrected

    s_rmse = scatter(e2, mse, mse_c)
    s_rel = scatter(e2 * w, relmse, relmse_c)
    return dict(
        out, mse=mse, relmse=relmse, floor_mse=floor, floor_relmse=floor_rel, mse_corrected=mse_c,
        relmse_corrected=relmse_c, rmse=math.sqrt(mse), rmse_corrected=math.sqrt(mse_c) if mse_c > 0 else None,
        scatter_log_rmse=s_rmse, scatter_log_relmse=None if s_rel is None else 2.0 * s_rel,
    )


def ground_truth_share(test_variance: np.ndarray, expected_variance: np.ndarray) -> float | None:
    r"""The ground truth's mean per-pixel variance over the test render's, :math:`\bar V_{gt} / \bar V_T`, over the
    pixels and channels where both are finite; None where the test's is 0 (a noiseless test: no ratio).

    Notes
    -----
    The verdict divides each difference by :math:`\sqrt{V_T + V_{gt}}`: a ground truth with variance r V_T makes
    every z smaller by :math:`\sqrt{1 + r}` than the test's own noise allows, so an error the test's budget could
    reveal is hidden. At r <= 1/4 (:data:`GROUND_TRUTH_SHARE_LIMIT`) the loss is at most 1 - 1/sqrt(1.25) = 11 %
    of every z.
    """
    t = np.asarray(test_variance, dtype=np.float64)
    g = np.asarray(expected_variance, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(g)
    if not ok.any():
        return None
    test_mean, truth_mean = float(t[ok].mean()), float(g[ok].mean())
    return truth_mean / test_mean if test_mean > 0 else None


def spp_for_share(spp: int, share: float, limit: float = GROUND_TRUTH_SHARE_LIMIT) -> int:
    """The spp that brings a ground truth rendered at ``spp`` with variance ratio ``share`` to at most ``limit``
    (its variance falls as 1 / spp), rounded up to a power of two; at least ``spp``."""
    need = max(float(spp), spp * share / limit)
    return max(int(spp), 1 << max(0, math.ceil(math.log2(need) - 1e-12)))
