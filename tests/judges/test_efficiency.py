"""Efficiencies and their ratios with confidence intervals over seeds (harness/judges/efficiency.py): the intervals
cover the true ratio at their stated level on synthetic draws of known ratio, "best" only where the intervals
separate, and an MSE below the ground truth's noise is never shown as a number."""

from __future__ import annotations

import math

import numpy as np
import pytest

from harness.judges.efficiency import (best_separated, efficiency_interval, efficiency_ratio, equal_time_spp,
                                       float_resolution, ratio_interval, shown_mse, zero_variance)

#: draws per coverage check; the count of intervals that cover the truth is Binomial(DRAWS, level)
DRAWS = 300
LEVEL = 0.95


def _binomial_band(draws: int, level: float, sigmas: float = 3.0) -> tuple[float, float]:
    """The coverage counts a correct interval gives with probability ~0.997: draws x level +- 3 binomial sd
    (sqrt(draws x level x (1 - level)) = 3.77 for 300 draws at 95 %: 273.7 .. 296.3 of 300)."""
    mean, sd = draws * level, math.sqrt(draws * level * (1 - level))
    return mean - sigmas * sd, mean + sigmas * sd


def _strategy(rng, n, mse_mean, mse_shape, seconds_mean, seconds_cv):
    """Per-seed MSE (gamma, as a mean of squared errors is) and seconds (normal: timing noise) of one strategy."""
    return rng.gamma(mse_shape, mse_mean / mse_shape, n), rng.normal(seconds_mean, seconds_cv * seconds_mean, n)


@pytest.mark.parametrize("seeds", [4, 6])
def test_efficiency_ratio_interval_covers_the_true_ratio_at_its_level(seeds):
    rng = np.random.default_rng(33)
    truth = (1.0 * 3.0) / (2.0 * 1.0)  # (MSE_ref x t_ref) / (MSE x t)
    hits = 0
    for _ in range(DRAWS):
        mse, sec = _strategy(rng, seeds, 2.0, 8.0, 1.0, 0.15)
        mse_ref, sec_ref = _strategy(rng, seeds, 1.0, 20.0, 3.0, 0.10)
        r = efficiency_ratio(mse, sec, mse_ref, sec_ref, LEVEL)
        hits += r["low"] <= truth <= r["high"]
    low, high = _binomial_band(DRAWS, LEVEL)
    assert low <= hits <= high, f"{hits} of {DRAWS} intervals cover the true ratio (expected {low:.0f}..{high:.0f})"


def test_efficiency_interval_and_mse_ratio_cover_their_truths():
    rng = np.random.default_rng(7)
    hits_e = hits_r = 0
    for _ in range(DRAWS):
        mse, sec = _strategy(rng, 5, 0.5, 10.0, 2.0, 0.2)
        e = efficiency_interval(mse, sec, LEVEL)
        hits_e += e["low"] <= 1.0 / (0.5 * 2.0) <= e["high"]
        other, _ = _strategy(rng, 5, 0.25, 10.0, 1.0, 0.2)
        r = ratio_interval((mse,), (other,), LEVEL)
        hits_r += r["low"] <= 2.0 <= r["high"]
    low, high = _binomial_band(DRAWS, LEVEL)
    assert low <= hits_e <= high and low <= hits_r <= high, (hits_e, hits_r)


def test_interval_of_one_seed_is_no_interval():
    r = efficiency_ratio([1.0], [1.0], [2.0], [1.0])
    assert r["value"] == pytest.approx(2.0) and r["low"] is None and r["high"] is None


def test_best_is_named_only_when_its_interval_separates():
    rng = np.random.default_rng(1)
    clear = {"default": _strategy(rng, 6, 1.0, 50.0, 1.0, 0.03),
             "fast": _strategy(rng, 6, 0.2, 50.0, 1.0, 0.03),   # 5 x the default's efficiency
             "slow": _strategy(rng, 6, 1.0, 50.0, 3.0, 0.03)}
    decision = best_separated(clear)
    assert decision["best"] == "fast" and decision["tied"] == []
    assert all(c["low"] > 1.0 for c in decision["comparisons"].values())
    tied = {"default": _strategy(rng, 6, 1.0, 8.0, 1.0, 0.2),
            "twin": _strategy(rng, 6, 1.0, 8.0, 1.0, 0.2)}  # the same estimator under another name
    decision = best_separated(tied)
    assert decision["best"] is None and decision["leader"] in tied and len(decision["tied"]) == 1


@pytest.mark.parametrize("corrected, floor, value, bound", [
    (-2.1e-05, 1e-05, None, 1e-05),   # the floor subtracted from a smaller measurement
    (5e-06, 1e-05, None, 1e-05),      # positive, but below what the ground truth resolves
    (3e-05, 1e-05, 3e-05, None),
    (-1e-06, 0.0, None, 0.0),         # a closed form (no floor): still never negative
])
def test_mse_below_the_ground_truths_noise_is_a_bound_never_negative(corrected, floor, value, bound):
    shown = shown_mse(corrected, floor)
    assert shown == {"value": value, "bound": bound}


def test_the_equal_time_budget_is_the_spp_that_takes_the_reference_time():
    assert equal_time_spp(16, 3.0, 1.0, step=2) == 6  # 16 / 3 = 5.3, a multiple of 2
    assert equal_time_spp(16, 0.5, 1.0) == 32 and equal_time_spp(16, 0.01, 1.0) == 256  # at most 16 x
    assert equal_time_spp(16, 1.2, 1.0) == 16  # within 1.25 x: the same-spp renders serve
    assert equal_time_spp(16, 0.0, 1.0) == 16 and equal_time_spp(1, 100.0, 1.0) == 1


def test_zero_variance_is_every_seed_at_most_float32_rounding():
    cut = float_resolution(0.93)
    assert cut == pytest.approx((2.0**-23 * 0.93) ** 2) and float_resolution(None) == 0.0
    assert zero_variance([2.6e-17, 0.0, 1e-30], cut) and zero_variance([0.0, 0.0])
    assert not zero_variance([2.6e-17, 1e-6], cut) and not zero_variance([], cut)
    assert not zero_variance([None, 0.0], cut) and not zero_variance([1e-20])
