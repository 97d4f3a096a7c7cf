"""Statistics for Monte Carlo tests: tolerances come from the estimator's own variance and a stated false-alarm rate.

A render returns per-pixel means and the variance of each mean. Pixels are independent, so the image mean of a
channel has standard error sqrt(sum_p var_p) / P, and by the central limit theorem (over P * spp samples) the
z-score of a deviation from the truth is standard normal. Tests reject at |z| > z_crit(alpha / m), two-sided, with
m the number of comparisons in the test (Bonferroni), so the whole test raises a false alarm with probability at
most alpha.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

# Probability that a correct renderer fails a single test function (over all its comparisons).
FALSE_ALARM = 1e-4
# float32 storage of each pixel: a relative error of 2**-24 per value, far below any Monte Carlo tolerance here.
FLOAT32_REL = 2.0**-22


def z_critical(alpha: float, comparisons: int) -> float:
    """Two-sided Bonferroni critical value: P(|Z| > z) = alpha / comparisons."""
    return float(stats.norm.isf(alpha / (2 * comparisons)))


@dataclass
class ImageMean:
    """Channel means of an image in float64 and their standard errors."""

    mean: np.ndarray  # (3,)
    stderr: np.ndarray  # (3,)


def image_mean(image: np.ndarray, variance: np.ndarray) -> ImageMean:
    pixels = image.shape[0] * image.shape[1]
    mean = image.astype(np.float64).reshape(-1, 3).sum(axis=0) / pixels
    stderr = np.sqrt(variance.astype(np.float64).reshape(-1, 3).sum(axis=0)) / pixels
    return ImageMean(mean, stderr)


def z_scores(a: ImageMean, expected: np.ndarray | ImageMean) -> np.ndarray:
    """z of a against a constant (exact) or against another independent estimate."""
    if isinstance(expected, ImageMean):
        diff = a.mean - expected.mean
        se = np.sqrt(a.stderr**2 + expected.stderr**2)
        scale = np.maximum(np.abs(a.mean), np.abs(expected.mean))
    else:
        diff = a.mean - np.asarray(expected, float)
        se = a.stderr
        scale = np.abs(np.asarray(expected, float))
    # Zero-variance estimators (e.g. max_depth = 1) are compared up to float32 rounding.
    return diff / np.maximum(se, FLOAT32_REL * scale + 1e-300)


def tile_chi2(diff: np.ndarray, var: np.ndarray, tile: int) -> tuple[float, int, float]:
    """Pool a difference image into tile x tile blocks; sum of squared tile z-scores ~ chi^2(#tiles).

    Returns (statistic, degrees of freedom, p-value). Tiles whose variance is zero and whose difference is zero are
    left out (nothing to test there).
    """
    h, w = diff.shape[:2]
    h2, w2 = h - h % tile, w - w % tile
    d = diff[:h2, :w2].astype(np.float64).reshape(h2 // tile, tile, w2 // tile, tile, 3).sum(axis=(1, 3))
    v = var[:h2, :w2].astype(np.float64).reshape(h2 // tile, tile, w2 // tile, tile, 3).sum(axis=(1, 3))
    ok = v > 0
    z2 = d[ok] ** 2 / v[ok]
    dof = int(ok.sum())
    statistic = float(z2.sum())
    return statistic, dof, float(stats.chi2.sf(statistic, dof))
