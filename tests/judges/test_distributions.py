"""harness.judges.distributions against scipy.stats, whose numbers the verdict, the chi-square tests and the
baselines used before: the same float64 bits over the ranges they are called on, far tails, the edges of the
support and invalid parameters included."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from harness.judges import distributions as dist


def same(ours, theirs) -> bool:
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    return ours.shape == theirs.shape and ours.dtype == theirs.dtype == np.float64 and \
        np.array_equal(ours, theirs, equal_nan=True)


EDGES = np.array([-np.inf, np.inf, np.nan, -0.0, 0.0, 1e-300, 1e300])


def test_normal_sf_is_scipy_stats_norm_sf():
    x = np.concatenate([np.linspace(-40.0, 40.0, 400_001), EDGES])  # z-scores; 2 Phi(-|z|) of 40 is 7e-350
    assert same(dist.normal_sf(x), stats.norm.sf(x))
    assert all(same(dist.normal_sf(v), stats.norm.sf(v)) for v in (0.3, 7.0, 38.5, np.inf))  # scalars stay scalars
    assert 0.0 < float(dist.normal_sf(37.0)) < 1e-298  # the far tail is not rounded to 0


def test_normal_isf_is_scipy_stats_norm_isf():
    p = np.concatenate([np.logspace(-323.5, 0.0, 300_001), 1.0 - np.logspace(-17, -1, 1001),
                        [np.finfo(float).tiny, 5e-324, 0.0, 1.0, -0.1, 1.1, np.nan]])
    assert same(dist.normal_isf(p), stats.norm.isf(p))
    assert all(same(dist.normal_isf(v), stats.norm.isf(v)) for v in (1e-3 / 6, 0.5, np.finfo(float).tiny))


@pytest.mark.parametrize("dof", [1.0, 1.5, 2.0, 3.0, 4.7, 7.0, 15.0, 63.0, 255.0, 1023.0, 4095.0, 1e5, 1e8, np.inf])
def test_student_t_sf_is_scipy_stats_t_sf(dof):
    """Welch's degrees of freedom of a tile are real numbers >= 1 (estimated variances), large for many samples."""
    x = np.concatenate([np.linspace(0.0, 60.0, 60_001), np.logspace(2, 300, 300), -np.linspace(0, 10, 101), EDGES])
    assert same(dist.student_t_sf(x, dof), stats.t.sf(x, dof))
    assert same(dist.student_t_sf(3.0, dof), stats.t.sf(3.0, dof))


def test_student_t_sf_with_arrays_of_dof_and_invalid_dof():
    rng = np.random.default_rng(5)
    x = rng.uniform(0, 30, 100_000)
    dof = 1.0 + rng.lognormal(3.0, 2.0, 100_000)
    assert same(dist.student_t_sf(x, dof), stats.t.sf(x, dof))
    bad = np.array([0.0, -1.0, np.nan, -np.inf])
    assert same(dist.student_t_sf(np.full(4, 2.0), bad), stats.t.sf(np.full(4, 2.0), bad))


@pytest.mark.parametrize("dof", [1, 2, 3, 10, 47, 64, 255, 1024, 3072, 12288, 49152])
def test_chi2_sf_is_scipy_stats_chi2_sf(dof):
    """Degrees of freedom: a tile count of one channel (up to 49152 on a 2048 x 1536 film in 8 x 8 tiles), a
    chi-square test's bins; statistics from 0 to far beyond the mean, where the tail underflows."""
    spread = np.sqrt(2.0 * dof)
    x = np.concatenate([np.linspace(0.0, dof + 60.0 * spread, 50_001), np.linspace(0.0, 4.0 * dof + 200, 20_001),
                        np.logspace(-10, 6, 1601), [-1.0, -1e-300, -0.0], EDGES])
    assert same(dist.chi2_sf(x, dof), stats.chi2.sf(x, dof))
    assert same(dist.chi2_sf(float(dof), dof), stats.chi2.sf(float(dof), dof))


def test_chi2_sf_with_real_and_invalid_dof():
    rng = np.random.default_rng(9)
    dof = rng.uniform(0.5, 500.0, 50_000)
    x = rng.uniform(0.0, 3.0, 50_000) * dof
    assert same(dist.chi2_sf(x, dof), stats.chi2.sf(x, dof))
    bad = np.array([0.0, -2.0, np.nan])
    assert same(dist.chi2_sf(np.full(3, 1.0), bad), stats.chi2.sf(np.full(3, 1.0), bad))
