"""Tests for harness.judges.power: the search for the smallest caught error, the quantile over seeds, the regions,
and the whole measurement on synthetic renders whose power is known.

Synthetic render: every pixel and channel an independent N(mu, sigma^2) estimate with its exact variance sigma^2,
judged against an exact ground truth mu (variance 0). A uniform bias b planted as T (1 - b), V (1 - b)^2 moves the
global-bias z of channel c to z_c(b) = Z_c - delta(b), delta(b) = sqrt(N) mu / sigma * b / (1 - b), with Z_c the
correct render's own z. The global sub-test fails once some |z_c| exceeds the Sidak critical value z* (three
channels at alpha / 3), so a seed's threshold is delta_i = min_c (Z_c + z*), i.e. b_i = delta_i / (delta_i +
sqrt(N) mu / sigma), exactly; the omnibus and max-|z| sub-tests can only catch it earlier.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from harness.judges import power
from harness.judges.verdict import verdict

ALPHA = 0.001
MU, SIGMA = 1.0, 0.2


def _render(rng: np.random.Generator, size: int = 32, bias: float = 0.0):
    """A synthetic render of a renderer with relative ``bias`` (its expectation mu (1 - bias)) and its variance."""
    mean = MU * (1.0 - bias)
    sigma = SIGMA * (1.0 - bias)
    image = mean + sigma * rng.standard_normal((size, size, 3))
    return image, np.full_like(image, sigma**2)


def _judge(tile: int):
    truth = None

    def judged(image, variance):
        nonlocal truth
        if truth is None or truth.shape != image.shape:
            truth = np.full(image.shape, MU)
        return verdict(image, variance, truth, np.zeros_like(truth), tile=tile, alpha=ALPHA)

    return judged


# ---- the search ------------------------------------------------------------------------------------------------


class _Step:
    """A verdict that fails from ``at`` on (``passed`` False), counting its calls."""

    def __init__(self, at: float):
        self.at, self.calls = at, 0

    def __call__(self, size: float):
        self.calls += 1
        fails = size >= self.at
        return _Outcome(not fails)


class _Outcome:
    threshold = ALPHA / 3

    def __init__(self, passed: bool):
        self.passed = passed
        p = 1.0 if passed else 0.0
        self.global_bias = {"p_value": p}
        self.omnibus = {"p_value": 1.0}
        self.max_z = {"p_value": 1.0}


@pytest.mark.parametrize("at, guess", [(0.0123, 0.5), (0.0123, 1e-5), (0.3, 0.3), (2e-6, 0.01)])
def test_the_search_brackets_a_step_to_its_precision_from_any_guess(at, guess) -> None:
    judge = _Step(at)
    found = power.smallest_caught(judge, guess=guess, upper=1.0, precision=0.02)
    assert at <= found.size <= at * 1.02
    assert found.caught_by == ("global_bias",)
    assert found.caught_at_double is True
    assert found.verdicts == judge.calls < 40


def test_a_false_alarm_has_threshold_zero_and_a_miss_none() -> None:
    assert power.smallest_caught(_Step(0.0), guess=0.1, upper=1.0).size == 0.0
    missed = power.smallest_caught(_Step(5.0), guess=0.1, upper=1.0)
    assert missed.size is None and missed.caught_by == ()


def test_a_size_below_float32_resolution_stops_the_halving() -> None:
    found = power.smallest_caught(_Step(1e-12), guess=0.01, upper=1.0)
    assert 0 < found.size < 2 * power.MIN_SIZE


def test_a_verdict_that_passes_again_at_twice_the_threshold_is_flagged() -> None:
    def window(size):  # fails only between 0.1 and 0.15: not monotone
        return _Outcome(not 0.1 <= size <= 0.15)

    found = power.smallest_caught(window, guess=0.1, upper=1.0)
    assert found.caught_at_double is False


# ---- the quantile ----------------------------------------------------------------------------------------------


def test_the_quantile_is_the_order_statistic_with_its_binomial_interval() -> None:
    sizes = list(range(1, 51))  # 50 seeds, thresholds 1 .. 50
    q = power.detection_quantile(sizes, 0.9, 0.9)
    assert q["value"] == 45 and q["rate"] == 0.9
    # X ~ Bin(50, 0.9) seeds below the true quantile: P(X <= 40) = 0.025 <= 0.05 < P(X <= 41) = 0.058 and
    # P(X <= 47) = 0.888 < 0.95 <= P(X <= 48) = 0.966, so [t_(41), t_(49)] covers it with P(41 <= X < 49) = 0.94
    assert stats.binom.cdf(40, 50, 0.9) <= 0.05 < stats.binom.cdf(41, 50, 0.9)
    assert stats.binom.cdf(47, 50, 0.9) < 0.95 <= stats.binom.cdf(48, 50, 0.9)
    assert q["interval"] == [41, 49]
    q = power.detection_quantile([0.0, None, None, *range(1, 8)], 0.9)
    assert q["false_alarms"] == 1 and q["not_caught"] == 2 and q["value"] is None  # 9 of 10 needed, 9th is inf


# ---- regions ---------------------------------------------------------------------------------------------------


def test_regions_lie_on_the_grid_at_the_centre_and_half_a_tile_off() -> None:
    assert power.centre_region(64, 64, 16, 8) == power.Region(24, 24, 16)
    assert power.centre_region(64, 64, 16, 8, offset=4) == power.Region(28, 28, 16)
    assert power.centre_region(32, 48, 16, 8, offset=4) == power.Region(12, 20, 16)
    assert power.centre_region(12, 40, 16, 8) == power.Region(0, 8, 12)  # cut to the image


def test_the_typical_region_has_the_median_brightness_and_is_never_the_black_part() -> None:
    truth = np.zeros((64, 64, 3))
    truth[:, 32:] = np.arange(32)[None, :, None] + 1.0  # left half black, right half brightening to the right
    region = power.typical_region(truth, 16, 8)
    # 7 x 7 positions; by column: x = 0, 8, 16 black, then brighter; the median (25th of 49) is at x = 24, and of
    # the seven rows there the one nearest the centre (y = 24)
    assert region == power.Region(24, 24, 16) and truth[24:40, 24:40].mean() > 0
    assert power.typical_region(truth, 16, 8, offset=4) == power.Region(28, 28, 16)
    assert power.centre_region(64, 64, 16, 8) == power.Region(24, 24, 16)


def test_planting_scales_the_image_and_its_variance_and_nothing_else() -> None:
    image, variance = np.full((8, 8, 3), 2.0), np.full((8, 8, 3), 0.5)
    biased, v = power.plant_bias(image, variance, 0.1)
    assert np.allclose(biased, 1.8) and np.allclose(v, 0.5 * 0.81)
    region = power.Region(2, 4, 3)
    planted, v = power.plant_region(image, variance, 0.5, region)
    assert np.allclose(planted[2:5, 4:7], 3.0) and np.allclose(v[2:5, 4:7], 0.5 * 2.25)
    assert planted.sum() == pytest.approx(2.0 * 192 + 9 * 3 * 1.0) and np.all(image == 2.0)


# ---- the measurement on renders whose power is known -----------------------------------------------------------


def test_each_seeds_bias_threshold_is_the_global_tests_own() -> None:
    """With tile 2 (256 tiles per channel) the omnibus and max-|z| sub-tests have almost no power against a uniform
    bias (lambda = delta^2 spread over 256 tiles), so each seed's threshold is the global test's b_i above. The
    search reports the bracket's upper end: b_i <= found <= b_i (1 + precision); where another sub-test catches
    first, found is smaller. A planting that forgot the variance's (1 - b)^2, or scaled by (1 + b), moves every
    threshold by far more than the precision."""
    rng = np.random.default_rng(19)
    judge = _judge(tile=2)
    n = 32 * 32
    z_star = stats.norm.isf((1.0 - (1.0 - ALPHA / 3) ** (1.0 / 3)) / 2.0)
    k = math.sqrt(n) * MU / SIGMA
    exact, earlier = 0, 0
    for _ in range(25):
        image, variance = _render(rng)
        z = (image - MU).sum(axis=(0, 1)) / math.sqrt(n * SIGMA**2)
        delta = float(np.min(z + z_star))
        expected = delta / (delta + k)
        found = power.smallest_caught(lambda b: judge(*power.plant_bias(image, variance, b)),
                                      guess=power.first_guess(image, variance, np.zeros_like(variance)), upper=1.0)
        assert found.size <= expected * 1.02 + 1e-12
        if found.size >= expected * (1 - 1e-9):
            exact += 1
            assert "global_bias" in found.caught_by
        else:
            earlier += 1
    # P(another sub-test first) per seed: the omnibus at lambda ~ 25 on 256 dof fails with p < 0.01, so 3 or more of
    # 25 seeds caught earlier has probability < 0.002
    assert earlier <= 2, (exact, earlier)


def test_a_renderer_with_the_found_bias_is_caught_nine_times_in_ten() -> None:
    """The chain end to end: the 0.9-quantile found by planting into correct renders (30 seeds), then fresh renders
    of a renderer that really has that bias (its expectation and noise scaled, not a copy scaled). The true
    detection rate at the empirical quantile t_(27) of 30 is Beta(27, 4)-distributed (mean 0.87, sd 0.06), and 60
    fresh renders add a binomial sd of 0.04: the observed rate lies above 0.87 - 4 x 0.072 = 0.58 but for a 1e-4
    chance. At half that bias the global test's power is about 1 - (1 - Phi(2.45 - 3.82))^3 ~ 0.3 (delta halved from
    z* + 1.2), so the rate there must be lower still: below 0.58 fails only if planting over-states the power."""
    rng = np.random.default_rng(7)
    judge = _judge(tile=8)
    sizes = []
    for _ in range(30):
        image, variance = _render(rng)
        found = power.smallest_caught(lambda b: judge(*power.plant_bias(image, variance, b)),
                                      guess=power.first_guess(image, variance, np.zeros_like(variance)), upper=1.0,
                                      check_double=False)
        sizes.append(found.size)
    b90 = power.detection_quantile(sizes, 0.9)["value"]
    assert b90 is not None

    def rate(bias: float) -> float:
        fresh = np.random.default_rng(8)
        return sum(not judge(*_render(fresh, bias=bias)).passed for _ in range(60)) / 60

    at_b90, at_half = rate(b90), rate(b90 / 2)
    assert at_b90 >= 0.58, (b90, at_b90)
    assert at_half < 0.58, (b90, at_half)


def test_a_region_on_the_grid_is_caught_at_a_smaller_error_than_half_a_tile_off() -> None:
    rng = np.random.default_rng(3)
    judge = _judge(tile=8)
    aligned, off = [], []
    for _ in range(12):
        image, variance = _render(rng)
        for region, sizes in ((power.centre_region(32, 32, 16, 8), aligned),
                              (power.centre_region(32, 32, 16, 8, offset=4), off)):
            found = power.smallest_caught(lambda d, r=region: judge(*power.plant_region(image, variance, d, r)),
                                          guess=power.first_guess(image, variance, np.zeros_like(variance), region),
                                          upper=power.MAX_REGION_ERROR, check_double=False)
            sizes.append(found.size)
    # the same seeds: half a tile off puts at most half of the region's tiles' area in any tile
    assert np.median(aligned) < np.median(off)
