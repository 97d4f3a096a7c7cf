"""The stress suite's emitter limits (suites/stress.toml, scenes/stress/; docs/stress.md, "Emitter limits"): a point
light 1e-4 above a plane, a spot with a 0.1 degree cutoff, an envmap whose single bright texel is 1e6 times the rest,
a directional light at grazing incidence. Every case the suite has for them renders (reference, its own settings,
8 spp) with no NaN, Inf or negative pixel; the spot, where Mitsuba's float32 falloff breaks down (an expected fail
in the suite), is judged against its closed form instead, and the grazing light is exact.

Monte Carlo check: the spot's verdict at alpha = FALSE_ALARM (1e-4), seeded, so the outcome is reproducible.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import ROOT, render_reference
from harness.files.imageio import read_exr
from harness.judges.mc import FALSE_ALARM
from harness.judges.verdict import verdict
from harness.running.cases import load_suite, with_case_overrides
from harness.scene import load_scene, sky

STRESS_SCENES = ROOT / "scenes" / "stress"
LIMITS = ("point-near-plane", "spot-narrow", "envmap-spike", "directional-grazing")
TEXTURE_LIMITS = ("texture-one-texel", "texture-fine-checker", "texture-degenerate-uv")  # docs/stress.md
SHADING_LIMITS = ("normals-flipping", "normalmap-grazing")  # docs/stress.md, "Shading-normal limits"
RHO = 0.6  # every limit scene's plane


def _limit_cases():
    suite = load_suite(ROOT / "suites" / "stress.toml")
    return [c for c in suite.cases if c.scene.resolve().parent == STRESS_SCENES.resolve()]


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_the_suite_has_each_limit_under_the_default_strategy_and_mis():
    seen = {(c.scene.stem, c.settings.get("direct", "default")) for c in _limit_cases()}
    # the glossy limits' default is already mis (direct = auto); they add the strategy each one strains
    glossy = {("glossy-alpha-limits", "default"), ("glossy-alpha-limits", "bsdf"),
              ("dielectric-index-matched", "default"), ("glossy-grazing", "default"), ("glossy-grazing", "area"),
              ("conductor-k-zero", "default")}
    assert seen == {(name, direct) for name in LIMITS + TEXTURE_LIMITS + SHADING_LIMITS
                    for direct in ("default", "mis")} | glossy
    # Only the spot is an expected fail (Mitsuba's float32 falloff, docs/stress.md); every case is the reference's.
    assert {c.scene.stem for c in _limit_cases() if c.expect == "fail"} == {"spot-narrow"}
    assert {c.renderer for c in _limit_cases()} == {"reference"}


@pytest.mark.parametrize("case", _limit_cases(), ids=lambda c: c.name)
def test_limit_renders_have_no_nan_inf_or_negative_pixel(case):
    scene = with_case_overrides(load_scene(case.scene), case)
    assert (scene.film.width, scene.film.height) == (16, 16)
    result = render_reference(scene, spp=8, seed=5, **case.settings)
    assert np.all(np.isfinite(result.image)), case.name
    assert np.all(result.image >= 0), case.name
    assert np.all(np.nan_to_num(result.variance, nan=0.0) >= 0) and not np.any(np.isinf(result.variance))
    assert result.stats["nonfinite_samples"] == 0
    assert result.image.max() > 0  # the extreme light is not lost
    print(f"{case.name}: pixels in [{result.image.min():.3g}, {result.image.max():.3g}]")


def _spot_closed_form(scene, nodes: int = 32) -> np.ndarray:
    """rho / pi I s(theta) cos / r^2 averaged over each pixel's footprint (Gauss-Legendre, nodes^2 per pixel): the
    camera looks straight down at the plane z = 0, so a box-filtered pixel covers a square of it; the spot is at
    height h above the origin, aimed straight down, so the image is symmetric and its orientation does not matter."""
    (spot,) = scene.emitters
    h = float(spot.position[2])
    size = scene.film.width
    half = float(scene.camera.origin[2]) * math.tan(math.radians(scene.camera.fov) / 2)
    x, w = np.polynomial.legendre.leggauss(nodes)
    pixel = 2 * half / size
    edges = -half + pixel * np.arange(size)
    coords = edges[:, None] + pixel * (x[None, :] + 1) / 2  # (size, nodes)
    px, py = coords[None, :, None, :], coords[:, None, :, None]  # (row, col, node_y, node_x)
    r2 = px * px + py * py + h * h
    theta = np.degrees(np.arctan2(np.sqrt(px * px + py * py), h))
    c, b = spot.cutoff_angle, spot.beam_width
    falloff = np.where(theta <= b, 1.0, np.clip((c - theta) / (c - b), 0.0, 1.0))
    value = RHO / np.pi * falloff * (h / np.sqrt(r2)) / r2
    mean = np.einsum("ijkl,k,l->ij", value, w / 2, w / 2)
    return mean[..., None] * np.asarray(spot.intensity, float)


def test_the_narrow_spot_matches_its_closed_form():
    """Where Mitsuba's ground truth is 3.2 % dark (suites/stress.toml's expected fail), the reference is right."""
    scene = load_scene(STRESS_SCENES / "spot-narrow.toml")
    expected = _spot_closed_form(scene)
    # the centre pixels: inside the beam but for their outer corners (0.053 degrees off the axis)
    assert expected.max() == pytest.approx(RHO / np.pi * 1e3, rel=1e-3)
    assert _spot_verdict(scene, expected).passed
    # the planted fault of a falloff that ignores beam_width (1 out to the cutoff) is caught at this scale
    assert not _spot_verdict(scene, expected, mutant="spot-ignores-beam-width").passed


def _spot_verdict(scene, expected, **settings):
    result = render_reference(scene, spp=16, seed=12, **settings)
    v = verdict(result.image, result.variance, expected.astype(np.float32), np.zeros_like(expected, np.float32),
                alpha=FALSE_ALARM, tile=4)
    print(f"spot-narrow {settings}: verdict {v.verdict}, global z {np.round(v.global_bias['z'], 2)}, max |z| "
          f"{v.max_z['statistic']:.3g}; rel. error of the mean {result.image.mean() / expected.mean() - 1:.2e}")
    return v


def test_the_grazing_directional_light_is_exact():
    """cos = 1e-7 on every pixel, and the sun parallel to the plane adds exactly nothing."""
    scene = load_scene(STRESS_SCENES / "directional-grazing.toml")
    result = render_reference(scene, spp=2, seed=12)
    np.testing.assert_allclose(result.image, RHO / np.pi * 1e-7, rtol=1e-5)


def test_the_spike_map_is_what_the_generator_makes():
    committed = read_exr(STRESS_SCENES / "textures" / "spike.exr").image
    made = sky.spike_image()
    assert made.view(np.uint32).tobytes() == committed.view(np.uint32).tobytes()
    assert committed.max() / np.median(committed) == 1e6 and np.sum(committed > 1) == 3  # one texel, 3 channels
    assert (STRESS_SCENES / "textures" / "spike.exr").stat().st_size < 20_000
