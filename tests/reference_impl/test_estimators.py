"""The reference estimators against closed forms and against each other (statistics: harness/judges/mc.py)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import load_small, render_reference
from harness.judges.mc import FALSE_ALARM, image_mean, tile_chi2, z_critical, z_scores

LE = np.array([1.0, 1.0, 1.0])
RHO = np.array([0.3, 0.5, 0.7])


def furnace_radiance(max_depth: int) -> np.ndarray:
    """L = Le sum_{i < max_depth} rho^i, and Le / (1 - rho) unbounded."""
    if max_depth == -1:
        return LE / (1.0 - RHO)
    return LE * sum(RHO**i for i in range(max_depth))


def test_furnace_scene_matches_the_closed_form_constants():
    scene = load_small("furnace", 8)
    assert np.allclose(next(iter(scene.materials.values())).reflectance, RHO)
    assert all(np.allclose(s.emission, LE) for s in scene.shapes)


@pytest.mark.parametrize("max_depth", [1, 2, 3, -1])
@pytest.mark.parametrize("direct", ["area", "mis", "hemisphere-cosine"])
def test_furnace_closed_form(max_depth, direct):
    scene = load_small("furnace", 32)
    result = render_reference(scene, spp=32, seed=7, max_depth=max_depth, direct=direct)
    expected = furnace_radiance(max_depth)
    measured = image_mean(result.image, result.variance)
    z = z_scores(measured, expected)
    print(f"furnace max_depth={max_depth} direct={direct}: mean {np.round(measured.mean, 5)} closed form "
          f"{np.round(expected, 5)} rel. error {np.round(measured.mean / expected - 1, 5)} z {np.round(z, 2)}")
    assert np.all(np.abs(z) < z_critical(FALSE_ALARM, 3)), (z, expected)
    if max_depth == 1:  # emitters seen directly: no randomness at all
        assert np.allclose(result.image, LE, rtol=0, atol=1e-6)


def test_furnace_closed_form_catches_a_wrong_estimator():
    """The same test fails the slides' literal pseudo-code (emission added again at indirect hits)."""
    scene = load_small("furnace", 32)
    result = render_reference(scene, spp=32, seed=7, max_depth=3, mutant="double-emission")
    z = z_scores(image_mean(result.image, result.variance), furnace_radiance(3))
    assert np.all(z > 10 * z_critical(FALSE_ALARM, 3)), z


def test_double_counting_differs_measurably_on_cornell_box():
    """The literal pseudo-code counts direct light twice: its image is brighter by many standard errors, and
    the excess is at least the direct light seen after one bounce (an indirect ray that lands on the light)."""
    scene = load_small("cornell-box", 32)
    correct = render_reference(scene, spp=32, seed=1)
    literal = render_reference(scene, spp=32, seed=2, mutant="double-emission")
    a, b = image_mean(correct.image, correct.variance), image_mean(literal.image, literal.variance)
    z = z_scores(b, a)
    assert np.all(z > 2 * z_critical(FALSE_ALARM, 3)), z
    assert np.all(b.mean > 1.05 * a.mean), (a.mean, b.mean)


DIRECT = ["hemisphere-cosine", "hemisphere-uniform", "global-area", "mis"]


@pytest.mark.parametrize("scene_name", ["soft-shadows", "multi-light"])
@pytest.mark.parametrize("direct", DIRECT)
def test_direct_strategies_share_one_expectation(scene_name, direct):
    """Each direct-light strategy estimates the same image as light sampling ("area"): the difference of the two
    images has mean zero, over the whole image and tile by tile (sum of squared tile z-scores ~ chi^2).

    Hemisphere and global-area sampling find the small lights rarely, so their per-pixel variance estimates are
    noisy and their tile means skewed at low spp: they get 8x the samples and 16x16-pixel tiles (>= 100k samples
    per tile), where the normal approximation holds.
    """
    scene = load_small(scene_name, 32)
    reference = render_reference(scene, spp=64, seed=11)
    other = render_reference(scene, spp=64 * (1 if direct == "mis" else 8), seed=12, direct=direct)
    z = z_scores(image_mean(other.image, other.variance), image_mean(reference.image, reference.variance))
    assert np.all(np.abs(z) < z_critical(FALSE_ALARM, 6)), z
    statistic, dof, p = tile_chi2(other.image - reference.image, other.variance + reference.variance, tile=16)
    assert p > FALSE_ALARM / 2, (statistic, dof, p)


def test_strategy_comparison_can_fail():
    """At the same budget the comparison rejects what a wrong estimator does: the literal pseudo-code's double
    counting, and a 10 % energy loss."""
    scene = load_small("multi-light", 32)
    reference = render_reference(scene, spp=64, seed=11)
    wrong = render_reference(scene, spp=64, seed=12, mutant="double-emission")
    z = z_scores(image_mean(wrong.image, wrong.variance), image_mean(reference.image, reference.variance))
    assert np.all(z > z_critical(FALSE_ALARM, 6)), z
    dimmed = render_reference(scene, spp=64, seed=13)
    z = z_scores(image_mean(dimmed.image * 0.9, dimmed.variance * 0.81), image_mean(reference.image, reference.variance))
    assert np.all(z < -z_critical(FALSE_ALARM, 6)), z


@pytest.mark.parametrize("setting", [
    {"light_selection": "uniform"},
    {"hemisphere": "uniform"},
    {"rr": "fixed", "absorption": 0.3, "rr_depth": 1},
    {"rr": "off"},
    {"shadow_rays": 4},
    {"indirect_rays": 2, "rr_depth": 2},
])
def test_other_settings_share_one_expectation(setting):
    """Light selection, hemisphere pdf, roulette and ray counts change the noise, not the expectation."""
    scene = load_small("multi-light", 24)
    reference = render_reference(scene, spp=48, seed=21)
    other = render_reference(scene, spp=48, seed=22, **setting)
    z = z_scores(image_mean(other.image, other.variance), image_mean(reference.image, reference.variance))
    assert np.all(np.abs(z) < z_critical(FALSE_ALARM, 3)), (setting, z)
