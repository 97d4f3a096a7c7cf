"""The reference renderer's emitters that are not shapes (point, spot, directional, constant and map environments)
against closed forms and against each other; the planted faults of reference_impl/mutants.py's EMITTER_MUTANTS,
each caught by the verdict; numerical limits; the same bits whatever the engine, batch size or thread count.

Every statistical check is the harness's verdict (harness/judges/verdict.py) at a false-alarm probability
ALPHA = FALSE_ALARM (1e-4) per test, against a closed form (zero variance) or an independent render of the same scene
(its variance added). A closed form integrates the exact radiance over each pixel of the box filter with 8 x 8
Gauss-Legendre nodes: its error is far below the renders' noise. The renders are seeded: a given tree passes or
fails reproducibly. Each test prints what the verdict found (``pytest -s``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import render_reference
from emitter_scenes import (RHO, constant, directional, envmap, open_box_scene, plane_scene, point, point_on_plane,
                            sphere_scene, spot, sun_sky_map, with_emitters)

from harness.judges.mc import FALSE_ALARM
from harness.judges.verdict import verdict
from harness.scene import emitter_arrays, triangulate

ALPHA = FALSE_ALARM


def _verdict(result, expected, expected_variance=None, label=""):
    """The verdict of a render against an image (a closed form where ``expected_variance`` is None)."""
    var = np.zeros_like(expected) if expected_variance is None else expected_variance
    v = verdict(result.image, result.variance, np.asarray(expected, np.float32), np.asarray(var, np.float32),
                alpha=ALPHA, tile=4)
    print(f"{label}: verdict {v.verdict}: global z {np.round(v.global_bias['z'], 2)}, max |z| "
          f"{v.max_z['statistic']:.3g}, omnibus p {v.omnibus['p_value']:.3g}; rel. error of the mean "
          f"{float(result.image.mean() / np.mean(expected) - 1):.2e}")
    return v


def _finite_nonnegative(result):
    assert np.all(np.isfinite(result.image)) and np.all(np.isfinite(np.nan_to_num(result.variance, nan=0.0)))
    assert np.all(result.image >= 0)
    assert result.stats["nonfinite_samples"] == 0


# ------------------------------------------------------------------------------------------------ point light

LIGHT_AT = (0.3, -0.2, 1.0)
INTENSITY = (2.0, 1.5, 1.0)


def test_point_light_above_a_plane_matches_the_closed_form():
    """rho / pi I cos / r^2 at every point of the plane, over each pixel."""
    scene = with_emitters(plane_scene(8), point(LIGHT_AT, INTENSITY))
    result = render_reference(scene, spp=16, seed=1)
    assert _verdict(result, point_on_plane(scene, LIGHT_AT, INTENSITY), label="point light").passed
    assert result.stats["shadow_rays"] == 8 * 8 * 16 and result.stats["light_selections"] == 0


def test_point_light_without_the_inverse_square_is_caught():
    scene = with_emitters(plane_scene(8), point(LIGHT_AT, INTENSITY))
    result = render_reference(scene, spp=16, seed=1, mutant="point-no-inverse-square")
    assert not _verdict(result, point_on_plane(scene, LIGHT_AT, INTENSITY), label="point-no-inverse-square").passed


# ------------------------------------------------------------------------------------------ directional light

SUN = np.array([0.3, -0.2, -1.0]) / np.linalg.norm([0.3, -0.2, -1.0])
IRRADIANCE = np.array([3.0, 2.0, 1.0])


def test_directional_light_on_a_plane_is_exact():
    """rho E cos / pi everywhere on the plane: one deterministic sample per pixel sample, no noise at all."""
    scene = with_emitters(plane_scene(8), directional(SUN, IRRADIANCE))
    result = render_reference(scene, spp=4, seed=2)
    expected = RHO / np.pi * IRRADIANCE * -SUN[2]
    error = np.max(np.abs(result.image / expected - 1))
    print(f"directional light: largest relative error {error:.2e}")
    assert error < 1e-6


def test_directional_light_reversed_is_caught():
    scene = with_emitters(plane_scene(8), directional(SUN, IRRADIANCE))
    result = render_reference(scene, spp=4, seed=2, mutant="directional-reversed")
    expected = np.broadcast_to(RHO / np.pi * IRRADIANCE * -SUN[2], result.image.shape)
    assert not _verdict(result, expected, label="directional-reversed").passed


# ------------------------------------------------------------------------------ constant environment (furnace)

L_SKY = np.array([0.8, 1.0, 1.2])
FURNACE_CASES = [
    {"direct": "area"}, {"direct": "area", "env_sampling": "uniform"}, {"direct": "area", "env_sampling": "cosine"},
    {"direct": "mis"}, {"direct": "mis", "env_sampling": "cosine", "hemisphere": "uniform"},
    {"direct": "hemisphere-cosine"}, {"direct": "hemisphere-uniform"}, {"direct": "global-area"},
    {"direct": "area", "sampler": "independent"},
]


@pytest.mark.parametrize("max_depth", [2, 3, -1])
@pytest.mark.parametrize("settings", FURNACE_CASES, ids=lambda s: "-".join(s.values()))
def test_convex_sphere_under_a_constant_sky_is_rho_times_l(settings, max_depth):
    """A convex diffuse ball filling the view under constant L: every ray leaving its surface escapes, so every pixel
    is rho L exactly, for every max_depth >= 2 (and 0 for max_depth 1: emitters seen directly only)."""
    scene = with_emitters(sphere_scene(8, max_depth=max_depth), constant(L_SKY))
    result = render_reference(scene, spp=16, seed=3, **settings)
    expected = np.broadcast_to(RHO * L_SKY, result.image.shape)
    assert _verdict(result, expected, label=f"furnace {settings} max_depth={max_depth}").passed


def test_convex_sphere_with_cosine_sky_sampling_has_no_noise():
    """With env_sampling = cosine each light sample is L f_r cos / (cos / pi) = rho L: the render is exact."""
    scene = with_emitters(sphere_scene(8, max_depth=2), constant(L_SKY))
    result = render_reference(scene, spp=4, seed=3, env_sampling="cosine")
    error = np.max(np.abs(result.image / (RHO * L_SKY) - 1))
    print(f"furnace, cosine sky sampling: largest relative error {error:.2e}")
    assert error < 1e-6
    only_emitters = render_reference(scene, spp=4, seed=3, max_depth=1)
    assert np.all(only_emitters.image == 0)


@pytest.mark.parametrize("direct", ["area", "mis", "hemisphere-cosine"])
def test_white_furnace_every_pixel_is_l(direct):
    """rho = 1 under constant L (the white furnace): every pixel is L, whether it sees the ball or the sky
    (here the ball fills only the middle of the view), and L for max_depth 1 where the sky is seen directly."""
    scene = with_emitters(sphere_scene(8, rho=1.0, distance=4.0, max_depth=-1), constant(L_SKY))
    result = render_reference(scene, spp=16, seed=4, direct=direct)
    assert _verdict(result, np.broadcast_to(L_SKY, result.image.shape), label=f"white furnace {direct}").passed


@pytest.mark.parametrize("direct", ["area", "mis", "hemisphere-cosine"])
def test_white_open_box_under_a_constant_sky_is_l(direct):
    """A concave white box (rho = 1, open at the top) under constant L, unbounded depth: light bounces many times
    before it escapes, and every pixel is still L. Counting the sky twice (at an escape after a light sample had
    counted it) or not at all would show."""
    scene = with_emitters(open_box_scene(8), constant(L_SKY))
    result = render_reference(scene, spp=32, seed=5, direct=direct)
    assert _verdict(result, np.broadcast_to(L_SKY, result.image.shape), label=f"open box {direct}").passed


def test_the_sky_counted_again_at_escapes_is_caught():
    """The literal pseudo-code (mutant double-emission) adds the sky at every escape on top of the light samples."""
    scene = with_emitters(open_box_scene(8), constant(L_SKY))
    result = render_reference(scene, spp=32, seed=5, mutant="double-emission")
    assert not _verdict(result, np.broadcast_to(L_SKY, result.image.shape), label="open box double-emission").passed


# -------------------------------------------------------------------------------------- engines and batches


def _core_render(scene, **settings):
    import reference_impl  # numba is imported with the first render

    values = {"spp": 4, "seed": 9, "max_depth": scene.max_depth, **settings}
    return reference_impl.render(triangulate(scene), scene.camera, scene.film, reference_impl.Settings(**values),
                                 emitters=emitter_arrays(scene))


def _mixed_scene():
    """Area light, point, spot and directional lights and an envmap in one scene."""
    scene = with_emitters(open_box_scene(12, rho=0.7, max_depth=5),
                          point((0.2, 0.1, 0.5), (1.0, 1.0, 1.0)),
                          spot((0.0, 0.0, 2.0), (0.0, 0.0, -1.0), (4.0, 3.0, 2.0), 25.0, 12.0),
                          directional((0.2, 0.1, -1.0), (1.0, 1.0, 1.0)),
                          envmap(sun_sky_map(), scale=0.5))
    return scene


ENGINE_CASES = [{}, {"direct": "mis"}, {"direct": "hemisphere-cosine", "shadow_rays": 2},
                {"direct": "global-area"}, {"light_selection": "uniform", "env_sampling": "cosine"},
                {"direct": "mis", "env_sampling": "uniform", "hemisphere": "uniform"},
                {"sampler": "independent", "direct": "mis"}]


@pytest.mark.parametrize("settings", ENGINE_CASES, ids=lambda s: "-".join(map(str, s.values())) or "defaults")
def test_path_engine_and_wavefront_give_the_same_bits_with_emitters(settings):
    scene = _mixed_scene()
    a = _core_render(scene, engine="wavefront", **settings)
    b = _core_render(scene, engine="path", **settings)
    assert a.image.tobytes() == b.image.tobytes()
    assert np.array_equal(a.variance, b.variance, equal_nan=True)
    drop = {"embree_microseconds"}
    assert {k: v for k, v in a.stats.items() if k not in drop} == {k: v for k, v in b.stats.items() if k not in drop}
    assert a.image.max() > 0


def test_batch_size_and_threads_do_not_change_a_bit_with_emitters():
    scene = _mixed_scene()
    base = _core_render(scene, threads=1)
    for settings in ({"batch_size": 37, "threads": 2}, {"batch_size": 1000, "threads": 1},
                     {"batch_size": 37, "engine": "wavefront", "threads": 2}):
        other = _core_render(scene, **settings)
        assert other.image.tobytes() == base.image.tobytes(), settings


def test_a_scene_with_only_emitters_that_are_not_shapes_renders():
    """No emissive shape at all: the lights come from the emitters (the render is not taken for black)."""
    scene = with_emitters(plane_scene(8), directional(SUN, IRRADIANCE))
    assert not scene.lights
    assert render_reference(scene, spp=1, seed=0).image.min() > 0


def test_empty_emitters_render_the_scene_as_before():
    scene = plane_scene(8)
    assert emitter_arrays(scene) is None
    assert emitter_arrays(dataclasses.replace(scene, emitters=())) is None
