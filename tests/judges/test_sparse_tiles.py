"""The verdict leaves out the tiles too sparse to judge (docs/verdict.md, "Tiles too sparse to judge").

veach-mis at 16 spp failed 6 of 288 correct renders against a 16384-spp ground truth, each at a tile of its small
lights: the ground truth says about one sample in the tile reaches a light (effective samples 0.2-1.4); a render
that drew none has mean 0 and variance 0 there, and its neighbours, the other lights' tiles, drew none either, so
no floor can see what it missed. The model here: a 64 x 64 film whose first tile row holds lights seen through
rare samples (each of a pixel's 16 samples is L = 50 with probability q, else 0; ``per_tile`` the expected hits in
a tile of 64 pixels), black rows below it, and a diffuse rest (1 + N(0, 0.3^2) per sample); the ground truth is
the exact mean plus its own noise at 16384 spp, with its variance."""

from __future__ import annotations

import math

import numpy as np
import pytest

import harness.judges.verdict as verdict_module
from harness.judges.verdict import verdict

H = W = 64
SPP, GT_SPP = 16, 16384
LIGHT_ROWS, BLACK_ROWS = 8, 24  # rows [0, 8) lights, [8, 24) black, the rest diffuse
L = 50.0
SEEDS = 40
ALPHA = 0.001


def _q(per_tile: float) -> float:
    return per_tile / (64 * SPP)


def _render(rng, per_tile: float) -> tuple[np.ndarray, np.ndarray]:
    """A test render: per pixel the mean of SPP samples and its variance (the sample variance over SPP)."""
    image = 1.0 + rng.standard_normal((H, W, 3)) * 0.3 / math.sqrt(SPP)
    variance = np.full((H, W, 3), 0.09 / SPP)
    hits = rng.binomial(SPP, _q(per_tile), size=(LIGHT_ROWS, W, 1)).astype(float)
    mean = hits * L / SPP
    image[:LIGHT_ROWS] = mean
    variance[:LIGHT_ROWS] = (hits * L**2 - SPP * mean**2) / (SPP - 1) / SPP
    image[LIGHT_ROWS:BLACK_ROWS] = variance[LIGHT_ROWS:BLACK_ROWS] = 0.0
    return image, variance


def _ground_truth(rng, per_tile: float) -> tuple[np.ndarray, np.ndarray]:
    q = _q(per_tile)
    image, variance = np.ones((H, W, 3)), np.full((H, W, 3), 0.09 / GT_SPP)
    image[:LIGHT_ROWS], variance[:LIGHT_ROWS] = q * L, q * (1 - q) * L**2 / GT_SPP
    image[LIGHT_ROWS:BLACK_ROWS] = variance[LIGHT_ROWS:BLACK_ROWS] = 0.0
    return image + np.sqrt(variance) * rng.standard_normal((H, W, 3)), variance


def _judge(seed: int, per_tile: float, *, lights_missing: bool = False, region: float = 0.0):
    rng = np.random.default_rng(seed)
    truth, truth_var = _ground_truth(rng, per_tile)
    test, test_var = _render(rng, per_tile)
    if lights_missing:  # a planted fault: the lights never reached
        test[:LIGHT_ROWS] = test_var[:LIGHT_ROWS] = 0.0
    if region:  # a planted fault: one 16 x 16 diffuse region too bright by ``region``
        test[32:48, 32:48] *= 1 + region
        test_var[32:48, 32:48] *= (1 + region) ** 2
    return verdict(test, test_var, truth, truth_var, alpha=ALPHA, test_dof=SPP - 1, expected_dof=GT_SPP - 1,
                   test_spp=SPP, expected_spp=GT_SPP)


def _failures(per_tile: float, **kwargs) -> int:
    return sum(not _judge(seed, per_tile, **kwargs).passed for seed in range(SEEDS))


def test_lights_too_sparse_to_judge_raise_no_false_alarm(monkeypatch) -> None:
    """0.3 expected hits per light tile: at most 2 of 40 correct renders fail (at alpha = 0.001, P(>= 3 of 40)
    ~ 1e-5), their light tiles counted as not judged; without the rule (MIN_SAMPLES 0) 20 or more of 40 fail."""
    assert _failures(0.3) <= 2
    outcome = _judge(0, 0.3)
    assert outcome.sparse["tiles"] >= 8 * 3 and "not judged: fewer than 10 effective samples" in outcome.reason
    monkeypatch.setattr(verdict_module, "MIN_SAMPLES", 0.0)
    assert _failures(0.3) >= 20


@pytest.mark.parametrize("per_tile", [1.0, 30.0])
def test_denser_lights_raise_no_false_alarm(per_tile: float) -> None:
    assert _failures(per_tile) <= 2


def test_lights_dense_enough_are_judged_and_a_missing_light_fails() -> None:
    """At 100 expected hits per tile the light tiles are judged: every render whose lights are missing fails."""
    assert _judge(0, 100.0).sparse["tiles"] == 0
    assert _failures(100.0, lights_missing=True) == SEEDS


def test_a_region_error_beside_sparse_tiles_is_still_caught() -> None:
    """A 16 x 16 diffuse region too bright among sparse lights (0.3 hits per tile) is caught as often as beside
    dense ones (100, no tile sparse), give or take 4 of 40 (3 %: 33 and 30 of 40), and always at 5 %."""
    assert abs(_failures(0.3, region=0.03) - _failures(100.0, region=0.03)) <= 4
    assert _failures(0.3, region=0.05) == SEEDS


def test_a_render_with_nothing_judgeable_fails_and_says_why() -> None:
    """A render whose every noisy tile is sparse is not passed: it fails with 'too few samples to judge'."""
    truth, truth_var = np.full((16, 16, 3), 0.01), np.full((16, 16, 3), 1e-5)
    test, test_var = np.zeros((16, 16, 3)), np.zeros((16, 16, 3))
    test[0, 0], test_var[0, 0] = 2.56, 2.56**2 / 16  # one sample of 41 in 256 pixels x 16 spp: the rest drew none
    outcome = verdict(test, test_var, truth, truth_var, alpha=ALPHA, test_spp=16, expected_spp=16384)
    assert not outcome.passed and outcome.reason.startswith("too few samples to judge")


def test_without_spp_only_each_image_s_own_variance_decides() -> None:
    """Without the images' spp the other image's variance predicts nothing: a black render against a bright,
    sharp ground truth is judged (and fails), whatever the spp would have said."""
    truth, truth_var = np.ones((16, 16, 3)), np.full((16, 16, 3), 1e-6)
    test, test_var = np.zeros((16, 16, 3)), np.zeros((16, 16, 3))
    outcome = verdict(test, test_var, truth, truth_var, alpha=ALPHA)
    assert not outcome.passed and outcome.sparse["tiles"] == 0
