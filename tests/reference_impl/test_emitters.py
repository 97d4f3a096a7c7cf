"""The reference renderer's emitters that are not shapes (point, spot, directional, constant and map environments)
against closed forms and against each other; the planted faults of reference_impl/mutants.py's EMITTER_MUTANTS,
each caught by the verdict; numerical limits; the two engines agree, and each gives the same bits whatever the batch
size or thread count.

Every statistical check is the harness's verdict (harness/judges/verdict.py) at a false-alarm probability
ALPHA = FALSE_ALARM (1e-4) per test, against a closed form (zero variance) or an independent render of the same scene
(its variance added). A closed form integrates the exact radiance over each pixel of the box filter with 8 x 8
Gauss-Legendre nodes: its error is far below the renders' noise. The renders are seeded: a given tree passes or
fails reproducibly. Each test prints what the verdict found (``pytest -s``).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from conftest import render_reference
try:
    from engine_agreement import Z_MAX, mean_z
except ImportError:  # tests/ imported as a package
    from tests.reference_impl.engine_agreement import Z_MAX, mean_z
from emitter_scenes import (RHO, constant, directional, envmap, envmap_on_plane, open_box_scene, plane_normal,
                            plane_scene, point, point_on_plane, sphere_scene, spot, spot_on_plane, sun_sky_map,
                            with_emitters)

import reference_impl
from harness.judges.mc import FALSE_ALARM
from harness.judges.verdict import verdict
from harness.renderers.reference import _complement_rays
from harness.scene import emitter_arrays, triangulate
from harness.scene.triangulate import rotate_matrix
from reference_impl import Camera
from reference_impl.emitters import environment_radiance

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


# ------------------------------------------------------------------------------------------------- spot light

SPOT = spot((0.2, 0.1, 1.5), (0.0, -0.1, 0.0), (6.0, 5.0, 4.0), cutoff_angle=30.0, beam_width=12.0)


def test_spot_light_above_a_plane_matches_the_closed_form():
    """rho / pi I s(theta) cos / r^2, s Mitsuba's falloff: a lit disk, full within 12 degrees, fading to 30."""
    scene = with_emitters(plane_scene(12, half=3.0), SPOT)
    result = render_reference(scene, spp=16, seed=6)
    expected = spot_on_plane(scene, SPOT)
    assert 0 < np.mean(expected[..., 0] == 0) < 0.8, "the cone's edge is in view"
    assert _verdict(result, expected, label="spot light").passed


def test_spot_falloff_that_ignores_beam_width_is_caught():
    scene = with_emitters(plane_scene(12, half=3.0), SPOT)
    result = render_reference(scene, spp=16, seed=6, mutant="spot-ignores-beam-width")
    assert not _verdict(result, spot_on_plane(scene, SPOT), label="spot-ignores-beam-width").passed


# ------------------------------------------------------------------------------------------- envmap

SKY = sun_sky_map(32, 16, sun_uv=(0.3, 0.3), sun=200.0)


@functools.cache
def _sky_on_plane(tilt: float) -> np.ndarray:
    """The closed form of a plane tilted by ``tilt`` under envmap(SKY, scale=0.5)."""
    return envmap_on_plane(envmap(SKY, scale=0.5), plane_normal("y", tilt), n=512)
# Strategies that do not sample the sun by its brightness find it rarely (1 % of their directions): at a few spp
# their samples are too skewed for the normal approximation, and they get 32x the samples.
ENVMAP_CASES = [({}, 16), ({"env_sampling": "uniform"}, 512), ({"env_sampling": "cosine"}, 512),
                ({"direct": "mis"}, 16), ({"direct": "mis", "env_sampling": "uniform"}, 512),
                ({"direct": "hemisphere-cosine"}, 512), ({"direct": "global-area"}, 16),
                ({"sampler": "independent"}, 16)]


@pytest.mark.parametrize("settings, spp", ENVMAP_CASES,
                         ids=lambda s: "-".join(s.values()) or "defaults" if isinstance(s, dict) else str(s))
def test_plane_under_an_envmap_matches_the_closed_form(settings, spp):
    """An unoccluded diffuse plane under a sky with a sun: rho / pi int L max(0, n . w) dw at every point."""
    sky = envmap(SKY, scale=0.5)
    scene = with_emitters(plane_scene(8, normal_up="y", tilt=30.0), sky)
    result = render_reference(scene, spp=spp, seed=7, **settings)
    expected = np.broadcast_to(_sky_on_plane(30.0), result.image.shape)
    assert _verdict(result, expected, label=f"envmap {settings}").passed


def test_envmap_pdf_without_sin_theta_is_caught():
    sky = envmap(SKY, scale=0.5)
    scene = with_emitters(plane_scene(8, normal_up="y", tilt=30.0), sky)
    result = render_reference(scene, spp=16, seed=7, mutant="envmap-pdf-no-sin")
    expected = np.broadcast_to(_sky_on_plane(30.0), result.image.shape)
    assert not _verdict(result, expected, label="envmap-pdf-no-sin").passed


def test_envmap_mirrored_in_u_is_caught():
    """A plane tilted toward the sun (at u = 0.3, toward +x): mirrored, the sun sets behind it."""
    sky = envmap(SKY, scale=0.5)
    scene = with_emitters(plane_scene(8, normal_up="y", tilt=40.0), sky)
    expected = np.broadcast_to(_sky_on_plane(40.0), (8, 8, 3))
    assert _verdict(render_reference(scene, spp=16, seed=8), expected, label="envmap, tilted plane").passed
    result = render_reference(scene, spp=16, seed=8, mutant="envmap-mirrored-u")
    assert not _verdict(result, expected, label="envmap-mirrored-u").passed


def test_envmap_seen_directly_against_an_independent_render():
    """Camera rays that escape show the map itself (here the sky toward +x, u ~ 1/4, and the plane below); the
    mirrored map is caught against an unmutated render at 4x the samples."""
    sky = envmap(SKY, scale=0.5)
    camera = Camera(origin=(0.0, 1.0, 0.0), target=(1.0, 1.2, 0.0), up=(0.0, 1.0, 0.0), fov=60.0)
    scene = with_emitters(plane_scene(12, normal_up="y", camera=camera, max_depth=3), sky)
    truth = render_reference(scene, spp=64, seed=9)
    same = render_reference(scene, spp=16, seed=10)
    assert _verdict(same, truth.image, truth.variance, label="envmap in view, two seeds").passed
    mirrored = render_reference(scene, spp=16, seed=10, mutant="envmap-mirrored-u")
    assert not _verdict(mirrored, truth.image, truth.variance, label="envmap in view, envmap-mirrored-u").passed


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_envmap_orientation_and_interpolation_are_mitsubas():
    """Mitsuba 3 renders the map seen directly (max_depth 1, no geometry) as the closed form of emitters.py's mapping
    and bilinear lookup integrated over each pixel; the map mirrored in u is rejected by the same verdict."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(0)
    image = (sun_sky_map(32, 16, sun=20.0) * (0.5 + rng.random((16, 32, 3)))).astype(np.float32)
    rotation = rotate_matrix((0.2, 1.0, 0.3), 35.0)
    camera = Camera(origin=(0.0, 0.0, 0.0), target=(1.0, 0.4, 0.2), up=(0.0, 1.0, 0.0), fov=70.0)
    size, renders, spp = 12, 6, 128
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 1},
        "sensor": {"type": "perspective", "fov": camera.fov, "fov_axis": "x",
                   "to_world": mi.ScalarTransform4f().look_at(origin=list(camera.origin), target=list(camera.target),
                                                               up=list(camera.up)),
                   "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "sky": {"type": "envmap", "bitmap": mi.Bitmap(image), "to_world": mi.ScalarTransform4f(rotation.tolist()),
                "scale": 1.5}})
    frames = np.stack([np.array(mi.render(scene, seed=s)) for s in range(renders)])
    mean, var = frames.mean(axis=0), frames.var(axis=0, ddof=1) / renders
    expected = _envmap_in_view(camera, size, image, rotation)
    v = verdict(mean, var, expected.astype(np.float32), np.zeros_like(mean), alpha=ALPHA, tile=4, test_dof=renders - 1)
    print(f"Mitsuba's envmap vs emitters.py: {v.verdict}, max |z| {v.max_z['statistic']:.3g}")
    assert v.passed
    mirrored = _envmap_in_view(camera, size, image[:, ::-1], rotation)
    assert not verdict(mean, var, mirrored.astype(np.float32), np.zeros_like(mean), alpha=ALPHA, tile=4,
                       test_dof=renders - 1).passed


def _envmap_in_view(camera, size: int, image, rotation, nodes: int = 12) -> np.ndarray:
    """The map seen through each pixel (box filter), integrated with Gauss-Legendre nodes: (size, size, 3)."""
    emitters = reference_impl.Emitters([reference_impl.EnvMap(image, rotation, 1.5)])
    g, w = np.polynomial.legendre.leggauss(nodes)
    g, w = 0.5 * (g + 1.0), 0.5 * w
    gx, gy = np.meshgrid(g, g)
    px, py = np.meshgrid(np.arange(size), np.arange(size))
    _o, d = camera.generate_rays((px[..., None] + gx.ravel()).ravel(), (py[..., None] + gy.ravel()).ravel(), size,
                                 size)
    radiance = environment_radiance(emitters, d).reshape(size, size, -1, 3)
    return np.einsum("hwnc,n->hwc", radiance, np.outer(w, w).ravel())


# ----------------------------------------------------------------------------------------- numerical limits

LIMIT_STRATEGIES = [{}, {"direct": "mis"}, {"direct": "hemisphere-cosine"}, {"direct": "global-area"}]


def _limit_scenes():
    bright = np.ones((16, 32, 3), np.float32)
    bright[5, 9] = 1e6
    return {
        "point light 1e-4 above the plane": with_emitters(plane_scene(8, half=2.0, max_depth=3),
                                                          point((0.01, 0.02, 1e-4), (1.0, 1.0, 1.0))),
        "spot with a 0.1 degree cutoff": with_emitters(plane_scene(8, half=2.0, max_depth=3),
                                                       spot((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (1e3, 1e3, 1e3),
                                                            cutoff_angle=0.1, beam_width=0.05)),
        "envmap with one texel 1e6 times the rest": with_emitters(plane_scene(8, normal_up="y", max_depth=3),
                                                                  envmap(bright)),
        "directional light at grazing incidence": with_emitters(plane_scene(8, max_depth=3),
                                                                directional((1.0, 0.0, -1e-7), (1.0, 1.0, 1.0)),
                                                                directional((0.0, 1.0, 0.0), (1.0, 1.0, 1.0))),
    }


@pytest.mark.parametrize("settings", LIMIT_STRATEGIES, ids=lambda s: "-".join(s.values()) or "defaults")
@pytest.mark.parametrize("name", list(_limit_scenes()))
def test_numerical_limits_give_finite_non_negative_pixels(name, settings):
    scene = _limit_scenes()[name]
    result = render_reference(scene, spp=8, seed=11, **settings)
    _finite_nonnegative(result)
    print(f"{name} {settings}: pixels in [{result.image.min():.3g}, {result.image.max():.3g}]")


def test_the_limits_still_light_the_scene():
    """The extreme lights are not lost: the point light 1e-4 above the plane gives the closed form right below it,
    so does the spot of a 0.1 degree cutoff inside its beam, and the grazing directional light E cos (cos = 1e-7)."""
    scene = with_emitters(plane_scene(1, half=2.0, camera=Camera((0.01, 0.02, 1.0), (0.01, 0.02, 0.0), (0, 1, 0),
                                                                 1e-3)),
                          point((0.01, 0.02, 1e-4), (1.0, 1.0, 1.0)))
    result = render_reference(scene, spp=16, seed=12)
    expected = point_on_plane(scene, (0.01, 0.02, 1e-4), (1.0, 1.0, 1.0))
    assert expected[0, 0, 0] == pytest.approx(RHO / np.pi / 1e-8, rel=1e-2)  # the footprint is 1.7e-5 wide
    assert _verdict(result, expected, label="point light 1e-4 above the plane").passed
    narrow = spot((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (1e3, 1e3, 1e3), cutoff_angle=0.1, beam_width=0.05)
    scene = with_emitters(plane_scene(1, half=2.0, camera=Camera((0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0, 1, 0), 0.02)),
                          narrow)
    result = render_reference(scene, spp=16, seed=12)
    assert _verdict(result, spot_on_plane(scene, narrow), label="spot with a 0.1 degree cutoff").passed
    assert result.image[0, 0, 0] == pytest.approx(RHO / np.pi * 1e3, rel=1e-6)
    grazing = with_emitters(plane_scene(2), directional((1.0, 0.0, -1e-7), (1.0, 1.0, 1.0)))
    result = render_reference(grazing, spp=1, seed=12)
    np.testing.assert_allclose(result.image, RHO / np.pi * 1e-7, rtol=1e-5)


# -------------------------------------------------------------------------------------- engines and batches


def _core_render(scene, **settings):
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
                {"direct": "mis", "env_sampling": "cosine", "max_depth": -1},
                {"sampler": "independent", "direct": "mis"}]


@pytest.mark.parametrize("settings", ENGINE_CASES, ids=lambda s: "-".join(map(str, s.values())) or "defaults")
def test_path_loop_and_wavefront_agree_with_emitters(settings):
    """The two engines draw different numbers: their means agree within Z_MAX (engine_agreement: 15 z per case,
    two-sided 1e-6 each; 8 cases)."""
    scene = _mixed_scene()
    a = _core_render(scene, engine="wavefront", **{"spp": 64, **settings})
    b = _core_render(scene, engine="path", **{"spp": 64, "seed": 5, **settings})
    assert mean_z(a, b).max() <= Z_MAX
    assert a.image.max() > 0


def test_batch_size_and_threads_do_not_change_a_bit_with_emitters():
    scene = _mixed_scene()
    for engine in ("path", "wavefront"):
        base = _core_render(scene, threads=1, engine=engine)
        for settings in ({"batch_size": 37, "threads": 2}, {"batch_size": 1000, "threads": 1}):
            other = _core_render(scene, engine=engine, **settings)
            assert other.image.tobytes() == base.image.tobytes(), (engine, settings)


def test_a_scene_with_only_emitters_that_are_not_shapes_renders():
    """No emissive shape at all: the lights come from the emitters (the render is not taken for black)."""
    scene = with_emitters(plane_scene(8), directional(SUN, IRRADIANCE))
    assert not scene.lights
    assert render_reference(scene, spp=1, seed=0).image.min() > 0


def test_a_scene_of_nothing_but_an_envmap_shows_the_map():
    """No shape at all: every viewing ray escapes and shows the map (the closed form over each pixel)."""
    camera = Camera(origin=(0.0, 0.0, 0.0), target=(1.0, 0.4, 0.2), up=(0.0, 1.0, 0.0), fov=70.0)
    scene = dataclasses.replace(with_emitters(plane_scene(8, camera=camera), envmap(SKY, scale=1.5)), shapes=[])
    expected = _envmap_in_view(camera, 8, SKY, np.eye(4))
    for engine in ("path", "wavefront"):
        result = render_reference(scene, spp=16, seed=13, engine=engine)
        assert result.stats["escaped_rays"] == 8 * 8 * 16
        assert _verdict(result, expected, label=f"envmap alone, {engine}").passed


def test_empty_emitters_render_the_scene_as_before():
    scene = plane_scene(8)
    assert emitter_arrays(scene) is None
    assert emitter_arrays(dataclasses.replace(scene, emitters=())) is None


def test_the_cost_check_counts_the_rays_toward_what_a_strategy_cannot_find():
    scene = _mixed_scene()  # a point, a spot, a directional light and an envmap
    rays = {direct: _complement_rays(scene, reference_impl.Settings(direct=direct))
            for direct in ("area", "mis", "hemisphere-cosine", "hemisphere-uniform", "global-area")}
    assert rays == {"area": 0, "mis": 0, "hemisphere-cosine": 3, "hemisphere-uniform": 3, "global-area": 4}


def _mitsuba_emitter(mi, emitter):
    """The Mitsuba 3 dict of one emitter of the scene model (the meaning the scene format gives its parameters)."""
    rgb = lambda value: {"type": "rgb", "value": list(map(float, value))}  # noqa: E731
    if emitter.type == "point":
        return {"type": "point", "position": list(emitter.position), "intensity": rgb(emitter.intensity)}
    if emitter.type == "spot":
        return {"type": "spot", "to_world": mi.ScalarTransform4f(np.asarray(emitter.to_world).tolist()),
                "intensity": rgb(emitter.intensity), "cutoff_angle": emitter.cutoff_angle,
                "beam_width": emitter.beam_width}
    if emitter.type == "directional":
        return {"type": "directional", "direction": list(emitter.direction), "irradiance": rgb(emitter.irradiance)}
    if emitter.type == "constant":
        return {"type": "constant", "radiance": rgb(emitter.radiance)}
    return {"type": "envmap", "bitmap": mi.Bitmap(np.asarray(emitter.image, np.float32)),
            "to_world": mi.ScalarTransform4f(np.asarray(emitter.to_world).tolist()), "scale": emitter.scale}


@pytest.mark.parametrize("light", [point(LIGHT_AT, INTENSITY), SPOT, directional(SUN, IRRADIANCE), constant(L_SKY),
                                   envmap(SKY, to_world=rotate_matrix((1, 0, 0), 90.0), scale=0.5)],
                         ids=["point", "spot", "directional", "constant", "envmap"])
def test_lights_on_a_plane_agree_with_mitsuba(light):
    """Mitsuba 3's point, spot, directional, constant and envmap plugins with the same parameters light the same
    plane the same (verdict of the reference against the mean of Mitsuba renders, each render's noise estimated
    across them; the envmap turned so that its sky, +y of the map, is the plane's +z)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    scene = with_emitters(plane_scene(12, half=3.0), light)
    camera = scene.camera
    mitsuba_scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": camera.fov, "fov_axis": "x",
                   "to_world": mi.ScalarTransform4f().look_at(origin=list(camera.origin), target=list(camera.target),
                                                               up=list(camera.up)),
                   "film": {"type": "hdrfilm", "width": 12, "height": 12, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": 32}},
        "plane": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(3.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [RHO, RHO, RHO]}}},
        "light": _mitsuba_emitter(mi, light)})
    renders = 6
    frames = np.stack([np.array(mi.render(mitsuba_scene, seed=s)) for s in range(renders)])
    mean, var = frames.mean(axis=0), frames.var(axis=0, ddof=1) / renders
    ours = render_reference(scene, spp=64, seed=14)
    if light.type == "directional":  # both exact, up to float32 rounding (Mitsuba computes in float32)
        error = float(np.max(np.abs(ours.image / mean - 1)))
        print(f"directional light vs Mitsuba: largest relative difference {error:.2e}")
        assert error < 1e-5
        return
    v = verdict(ours.image, ours.variance, mean.astype(np.float32), var.astype(np.float32), alpha=ALPHA, tile=4,
                expected_dof=renders - 1)
    print(f"{light.type} light vs Mitsuba: {v.verdict}, global z {np.round(v.global_bias['z'], 2)}, "
          f"max |z| {v.max_z['statistic']:.3g}")
    assert v.passed
