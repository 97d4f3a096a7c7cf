r"""Statistics for Monte Carlo image tests: tolerances from the estimator's own variance and a stated false-alarm rate.

A render returns per-pixel means ``x_p`` and the variance ``v_p`` of each mean (the sample variance over the pixel's
samples divided by their count). Pixels are independent, so the mean of a channel over the ``P`` pixels of an image
and its standard error are

.. math::

    m = \frac{1}{P} \sum_p x_p, \qquad \mathrm{se}(m) = \frac{1}{P} \sqrt{\sum_p v_p},

and, by the central limit theorem over the ``P * spp`` samples, the z-score of the deviation from the truth,
``z = (m - mu) / se(m)`` (or ``(m_a - m_b) / sqrt(se_a^2 + se_b^2)`` between two independent renders), is standard
normal. A test rejects at ``|z| > z_crit``, two-sided, with ``P(|Z| > z_crit) = alpha / k`` for ``k`` comparisons
(Bonferroni), so the whole test raises a false alarm with probability at most ``alpha``; :func:`z_critical` gives
``z_crit``. :func:`tile_chi2` is the omnibus check of a difference image: tile sums of the difference, each divided
by its standard deviation, squared and summed, follow chi^2 with one degree of freedom per (tile, channel).

Notes
-----
The per-pixel variances are estimates, used as if exact; with many samples per pixel (tens or more) the resulting
z is standard normal to a good approximation. A pixel with zero variance (a deterministic estimator, say
``max_depth = 1``) is compared up to float32 rounding, see :data:`FLOAT32_REL`.

References
----------
.. [1] O. J. Dunn, "Multiple comparisons among means", Journal of the American Statistical Association 56 (1961),
   52-64 (the Bonferroni bound).
.. [2] A. Jung, J. Hanika, C. Dachsbacher, "Detecting bias in Monte Carlo renderers using Welch's t-test", Journal
   of Computer Graphics Techniques 9(2), 2020 -- the same comparison of two renders per pixel region, with the
   variances estimated from the samples.

Examples
--------
Two renders of the same scene by two estimators that should agree (here: synthetic images of one true mean):

>>> import numpy as np
>>> from harness.judges.mc import FALSE_ALARM, image_mean, tile_chi2, z_critical, z_scores
>>> rng = np.random.default_rng(3)
>>> var = np.full((32, 32, 3), 0.01)                  # variance of every pixel mean
>>> a = 0.5 + rng.normal(size=var.shape) * np.sqrt(var)
>>> b = 0.5 + rng.normal(size=var.shape) * np.sqrt(var)
>>> z = z_scores(image_mean(a, var), image_mean(b, var))
>>> bool(np.all(np.abs(z) < z_critical(FALSE_ALARM, 3)))  # 3 comparisons: one per channel
True
>>> statistic, dof, p = tile_chi2(a - b, var + var, tile=8)
>>> dof, bool(p > FALSE_ALARM)
(48, True)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.judges.distributions import chi2_sf, normal_isf

__all__ = ["FALSE_ALARM", "FLOAT32_REL", "ImageMean", "image_mean", "z_critical", "z_scores", "tile_chi2"]

#: Probability that a correct renderer fails a single test function (over all its comparisons).
FALSE_ALARM = 1e-4
#: float32 storage of each pixel: a relative error of 2**-24 per value; this floor on the standard error (4 units in
#: the last place) is far below any Monte Carlo tolerance and only matters for zero-variance estimators.
FLOAT32_REL = 2.0**-22


def z_critical(alpha: float, comparisons: int) -> float:
    """Two-sided Bonferroni critical value.

    Parameters
    ----------
    alpha : float
        Family false-alarm probability, in (0, 1).
    comparisons : int
        Number of z-scores the test checks (at least 1).

    Returns
    -------
    float
        ``z`` with ``P(|Z| > z) = alpha / comparisons`` for a standard normal ``Z``.
    """
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha must lie in (0, 1), got {alpha!r}")
    if not (isinstance(comparisons, (int, np.integer)) and comparisons >= 1):
        raise ValueError(f"comparisons must be an integer >= 1, got {comparisons!r}")
    return float(normal_isf(alpha / (2 * comparisons)))


@dataclass
class ImageMean:
    """Channel means of an image in float64 and their standard errors.

    Attributes
    ----------
    mean : numpy.ndarray, shape (C,)
    stderr : numpy.ndarray, shape (C,)
    """

    mean: np.ndarray
    stderr: np.ndarray


def _check_pair(image: np.ndarray, variance: np.ndarray, what: str) -> None:
    if image.ndim != 3:
        raise ValueError(f"{what} must have shape (height, width, channels), got {image.shape}")
    if image.shape != variance.shape:
        raise ValueError(f"{what} has shape {image.shape} but its variance {variance.shape}")


def image_mean(image: np.ndarray, variance: np.ndarray) -> ImageMean:
    """The mean of every channel over the image, and its standard error.

    Parameters
    ----------
    image : array_like, shape (H, W, C)
        Per-pixel means.
    variance : array_like, shape (H, W, C)
        Variance of each pixel mean (not of a single sample).

    Returns
    -------
    ImageMean
        ``mean = sum_p x_p / P`` and ``stderr = sqrt(sum_p v_p) / P`` per channel, in float64.
    """
    image, variance = np.asarray(image), np.asarray(variance)
    _check_pair(image, variance, "image")
    channels = image.shape[2]
    pixels = image.shape[0] * image.shape[1]
    mean = image.astype(np.float64).reshape(-1, channels).sum(axis=0) / pixels
    stderr = np.sqrt(variance.astype(np.float64).reshape(-1, channels).sum(axis=0)) / pixels
    return ImageMean(mean, stderr)


def z_scores(a: ImageMean, expected: np.ndarray | ImageMean) -> np.ndarray:
    """z-scores of the channel means ``a`` against an exact value or another independent estimate.

    Parameters
    ----------
    a : ImageMean
        The estimate under test.
    expected : array_like or ImageMean
        The exact channel means, or an independent estimate (its standard error then adds in quadrature).

    Returns
    -------
    numpy.ndarray, shape (C,)
        ``(a - mu) / se_a`` or ``(a - b) / sqrt(se_a^2 + se_b^2)``; the standard error is floored at
        ``FLOAT32_REL`` times the larger absolute mean, so that zero-variance estimators are compared up to float32
        rounding.
    """
    if isinstance(expected, ImageMean):
        diff = a.mean - expected.mean
        se = np.sqrt(a.stderr**2 + expected.stderr**2)
        scale = np.maximum(np.abs(a.mean), np.abs(expected.mean))
    else:
        diff = a.mean - np.asarray(expected, float)
        se = a.stderr
        scale = np.abs(np.asarray(expected, float))
    return diff / np.maximum(se, FLOAT32_REL * scale + 1e-300)


def tile_chi2(diff: np.ndarray, var: np.ndarray, tile: int) -> tuple[float, int, float]:
    """Omnibus test of a difference image: pooled into tile x tile blocks, the squared tile z-scores sum to chi^2.

    Parameters
    ----------
    diff : array_like, shape (H, W, C)
        Difference of two images (or of an image and the truth) that should be zero in expectation.
    var : array_like, shape (H, W, C)
        Variance of each pixel of ``diff`` (the sum of both images' variances for independent renders).
    tile : int
        Tile side in pixels; a partial last row or column of tiles is left out.

    Returns
    -------
    statistic : float
        ``sum_t D_t^2 / V_t`` over (tile, channel) pairs, with ``D_t`` and ``V_t`` the tile's sums of ``diff`` and
        ``var``.
    dof : int
        The number of (tile, channel) pairs with ``V_t > 0``.
    p : float
        ``P(chi^2_dof >= statistic)``; nan when no tile has variance (nothing was tested, so a ``p > alpha`` check
        fails).

    Notes
    -----
    Tiles whose summed variance is zero are left out, whatever their difference: z is undefined there. Check such
    regions (a zero-variance estimator) with :func:`z_scores` or an exact comparison. Pooling over tiles makes each
    ``D_t`` close to normal even at low samples per pixel, where a pixel's z-score would not be.
    """
    diff, var = np.asarray(diff), np.asarray(var)
    _check_pair(diff, var, "diff")
    h, w, c = diff.shape
    if not (isinstance(tile, (int, np.integer)) and 1 <= tile <= min(h, w)):
        raise ValueError(f"tile must be an integer from 1 to {min(h, w)} (the image's smaller side), got {tile!r}")
    h2, w2 = h - h % tile, w - w % tile
    d = diff[:h2, :w2].astype(np.float64).reshape(h2 // tile, tile, w2 // tile, tile, c).sum(axis=(1, 3))
    v = var[:h2, :w2].astype(np.float64).reshape(h2 // tile, tile, w2 // tile, tile, c).sum(axis=(1, 3))
    ok = v > 0
    z2 = d[ok] ** 2 / v[ok]
    dof = int(ok.sum())
    statistic = float(z2.sum())
    p = float(chi2_sf(statistic, dof)) if dof else float("nan")
    return statistic, dof, p
