"""harness.judges.diagnose tells apart the mistakes a renderer author hits first, on synthetic images (a smooth
gradient with a small bright "light", and noise of a known variance): an image moved by one row, mirrored, a light
4 pi (or pi, 2 pi) off either way, a light alone too bright, and a correct image ("no shift, scale 1 within its
interval")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from harness.judges.diagnose import best_shift, bright_share, diagnose, named_factor, scale_factor

H, W = 32, 40


def _truth() -> np.ndarray:
    y, x = np.mgrid[0:H, 0:W] / H
    image = np.stack([0.2 + x + 0.5 * y**2, 0.3 + 0.5 * x + y, 0.1 + x * y], axis=2)
    image[6:8, 20:23] += 8.0  # a small light: the brightest 1 %
    return image


def _pair(test_truth: np.ndarray, seed: int, sd: float = 0.01):
    """(test, test variance, ground truth, its variance): noise of variance sd^2 x value (a quarter for the truth)."""
    rng = np.random.default_rng(seed)
    truth = _truth()
    var_t = sd**2 * np.abs(test_truth) + 1e-8
    var_g = sd**2 * truth / 4
    test = test_truth + np.sqrt(var_t) * rng.standard_normal(truth.shape)
    gt = truth + np.sqrt(var_g) * rng.standard_normal(truth.shape)
    return test, var_t, gt, var_g


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_correct_image_has_no_shift_and_scale_1(seed):
    test, vt, gt, vg = _pair(_truth(), seed)
    found = diagnose(test, gt, vt, vg)
    assert not found["shift"]["significant"] and (found["shift"]["dx"], found["shift"]["dy"]) == (0, 0)
    assert found["shift"]["mirror"] == "none"
    assert found["scale"]["low"] <= 1.0 <= found["scale"]["high"] and found["scale"]["named"] == "1"
    assert not found["bright"]["concentrated"]


@pytest.mark.parametrize(("rows", "cols", "dx", "dy"), [(1, 0, 0, 1), (-1, 0, 0, -1), (0, 2, 2, 0), (1, -3, -3, 1)])
def test_a_moved_image_gets_its_shift(rows, cols, dx, dy):
    test, vt, gt, vg = _pair(np.roll(_truth(), (rows, cols), axis=(0, 1)), seed=4)
    shift = diagnose(test, gt, vt, vg)["shift"]
    assert shift["significant"] and (shift["dx"], shift["dy"], shift["mirror"]) == (dx, dy, "none")
    assert shift["mse"] < shift["mse_identity"] / 2


@pytest.mark.parametrize(("flip", "mirror"), [(1, "horizontal"), (0, "vertical")])
def test_a_mirrored_image_gets_its_mirror(flip, mirror):
    test, vt, gt, vg = _pair(np.flip(_truth(), axis=flip), seed=5)
    shift = diagnose(test, gt, vt, vg)["shift"]
    assert shift["significant"] and (shift["mirror"], shift["dx"], shift["dy"]) == (mirror, 0, 0)


@pytest.mark.parametrize(("factor", "name"), [(4 * math.pi, "4 pi"), (1 / (4 * math.pi), "1/(4 pi)"),
                                              (math.pi, "pi"), (2 * math.pi, "2 pi"), (1 / math.pi, "1/pi")])
def test_a_light_off_by_a_factor_of_pi_is_named(factor, name):
    test, vt, gt, vg = _pair(factor * _truth(), seed=6)
    found = diagnose(test, gt, vt, vg)
    scale = found["scale"]
    assert scale["scale"] == pytest.approx(factor, rel=0.01)
    assert scale["named"] == name and not found["shift"]["significant"]


def test_a_factor_near_but_not_of_pi_is_not_named():
    test, vt, gt, vg = _pair(1.1 * _truth(), seed=7)
    scale = scale_factor(test, gt, vt, vg)
    assert scale["low"] > 1.05 and scale["scale"] == pytest.approx(1.1, rel=0.01)
    assert named_factor(scale["scale"], scale["low"], scale["high"]) is None


def test_about_4_pi_is_named_within_two_percent():
    assert named_factor(12.7, 12.69, 12.71) == "4 pi"  # 1 % above 4 pi, a tight interval: "about"
    assert named_factor(13.5, 13.4, 13.6) is None
    assert named_factor(1.01, 1.005, 1.015) is None  # 1 is named only inside the interval


def test_a_difference_in_the_light_is_concentrated_in_the_brightest_pixels():
    bright = _truth()
    bright[6:8, 20:23] *= 1.2  # the light 20 % too bright, the rest right
    test, vt, gt, vg = _pair(bright, seed=8)
    share = bright_share(test, gt, vt, vg)
    assert share["concentrated"] and share["share"] > 0.9 and share["pixels"] == round(0.01 * H * W)
    test, vt, gt, vg = _pair(_truth(), seed=8)
    assert not bright_share(test, gt, vt, vg)["concentrated"]


def test_flat_noise_raises_no_shift():
    """Where the ground truth is flat every shift fits as well as none: noise alone must not pick one."""
    rng = np.random.default_rng(9)
    found = [best_shift(1 + 0.1 * rng.standard_normal((24, 24, 3)), 1 + 0.05 * rng.standard_normal((24, 24, 3)),
                        np.full((24, 24, 3), 0.0125))["significant"] for _ in range(40)]
    assert not any(found)
