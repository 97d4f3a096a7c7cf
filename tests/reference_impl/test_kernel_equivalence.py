"""The compiled kernels (reference_impl/kernels/) repeat the numpy definitions bit for bit.

The chi^2 tests (tests/reference_impl/test_sampling_chi2.py) check the numpy functions of ``rng``, ``sampling``, ``lights`` and
``filters``; the renderer runs their scalar copies in ``kernels``. These tests compare the two on the same inputs,
bit for bit, so the chi^2 tests keep vouching for what the renderer draws. Unlike the benchmarks beside them they are
cheap (about a second, once the kernels are compiled) and run in the default ``pytest`` run.
"""

from __future__ import annotations

import numpy as np
import pytest

try:
    import chi2_cases
except ImportError:  # tests/ imported as a package
    from tests import chi2_cases

from reference_impl.kernels import camera as k_camera
from reference_impl.kernels import config as k_config
from reference_impl.kernels import light_sampling as k_lights
from reference_impl.kernels import records as k_records
from reference_impl.kernels import rng as k_rng
from reference_impl.kernels import surface as k_surface
from reference_impl.kernels import warps as k_warps
from reference_impl import rng, sampling
from reference_impl.filters import make_filter
from reference_impl.lights import LightSampler, TriangleAreaSampler

N = 3000


def _uniforms(seed: int, n: int = N) -> np.ndarray:
    u = np.random.default_rng(seed).random(n)
    u[:6] = [0.0, 0.5, 0.25, 0.75, np.nextafter(1.0, 0.0), 1e-300]  # edges: centre, diagonals, ends
    return u


def _normals(seed: int) -> np.ndarray:
    n = np.random.default_rng(seed).normal(size=(N, 3))
    n[:8] = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0, -1, 0), (1e-9, -1e-9, -1), (1e-8, 1e-8, 1), (0, 1e-7, -1),
             (-3e-3, 1e-3, -1)]
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_random_numbers_match_rng():
    seed = 1234567
    ids = np.concatenate([np.arange(500, dtype=np.uint64), np.random.default_rng(1).integers(0, 2**63, 500, dtype=np.uint64)])
    keys = rng.path_keys(seed, ids)
    seed_key = rng.seed_key(seed)
    assert [k_rng.path_key(seed_key, i) for i in ids] == keys.tolist()
    for depth, purpose, index in ((0, 0, 0), (1, 9, 0), (7, 3, 2), (300, 10, 5), (2**20, 8, 0)):
        want = rng.uniform(keys, rng.dimension(depth, purpose, index))
        salt = np.uint64(k_rng.dim_salt(depth, purpose, index))
        got = np.array([k_rng.uniform(k, salt) for k in keys])
        np.testing.assert_array_equal(got, want)
    for depth, branch in ((1, 0), (3, 2), (70000, 5)):
        want = rng.branch_keys(keys, branch, depth)
        salt = np.uint64(k_rng.branch_salt(branch, depth))
        assert [k_rng.mix64(k ^ salt) for k in keys] == want.tolist()


@pytest.mark.parametrize("kind", ["cosine", "uniform"])
def test_hemisphere_warps_match_sampling(kind):
    u1, u2 = _uniforms(2), _uniforms(3)[::-1].copy()
    warp = sampling.square_to_cosine_hemisphere if kind == "cosine" else sampling.square_to_uniform_hemisphere
    kernel = k_warps.cosine_hemisphere if kind == "cosine" else k_warps.uniform_hemisphere
    np.testing.assert_array_equal(np.array([kernel(a, b) for a, b in zip(u1, u2)]), warp(u1, u2))
    n = _normals(4)
    want_dir, want_cos, want_pdf = sampling.sample_hemisphere(kind, u1, u2, n)
    got = np.array([k_warps.sample_hemisphere(kind == "cosine", a, b, *row) for a, b, row in zip(u1, u2, n)])
    np.testing.assert_array_equal(got[:, :3], want_dir)
    np.testing.assert_array_equal(got[:, 3], want_cos)
    np.testing.assert_array_equal(got[:, 4], want_pdf)
    cos = np.concatenate([want_cos, [-0.5, 0.0]])
    np.testing.assert_array_equal([k_warps.hemisphere_pdf(kind == "cosine", c) for c in cos], sampling.hemisphere_pdf(kind, cos))



def test_unit_circle_is_cos_and_sin_of_two_pi_u():
    """sampling.unit_circle (the warps' cos 2 pi u, sin 2 pi u without libm) is within 1e-15 of numpy's cos and sin,
    on the unit circle, at the quarter turns exactly, and the kernels' unit_circle gives its bits, signs of zero too."""
    u = np.concatenate([np.random.default_rng(3).random(100_000), np.arange(16) / 16, [np.nextafter(1.0, 0.0), 5e-324,
                        0.125 - 1e-17, 0.375 + 1e-17, np.nextafter(0.5, 0.0), np.nextafter(0.25, 1.0)]])
    c, s = sampling.unit_circle(u)
    assert np.abs(c - np.cos(2 * np.pi * u)).max() < 1e-15 and np.abs(s - np.sin(2 * np.pi * u)).max() < 1e-15
    assert np.abs(c * c + s * s - 1.0).max() < 5e-16
    quarters = np.array([0.0, 0.25, 0.5, 0.75])
    np.testing.assert_array_equal(np.stack(sampling.unit_circle(quarters)), [[1, 0, -1, 0], [0, 1, 0, -1]])
    got = np.array([k_warps.unit_circle(float(x)) for x in u])
    assert got[:, 0].tobytes() == c.tobytes() and got[:, 1].tobytes() == s.tobytes()

def test_discrete_sampling_matches_searchsorted():
    cdf = np.cumsum(np.random.default_rng(5).random(17))
    cdf /= cdf[-1]
    u = np.concatenate([_uniforms(6), cdf[:-1], [1.0]])
    np.testing.assert_array_equal([k_warps.sample_discrete(cdf, x) for x in u], sampling.sample_discrete(cdf, u))


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
@pytest.mark.parametrize("selection", ["power", "uniform"])
def test_light_points_match_light_sampler(selection):
    lights = chi2_cases.four_lights()
    lights[1] = (chi2_cases.fan_light(), lights[1][1])  # a light of several unequal triangles
    geometry, _ = chi2_cases.light_geometry(lights)
    sampler = LightSampler(geometry, selection)
    u = [_uniforms(10 + i) for i in range(4)]
    light, points = sampler.sample(*u)
    assert sampler.count.tolist() == [1, 4, 4, 1] and sampler.parallelogram.tolist() == [False] * 9 + [True]  # a quad
    tables = k_records.light_tables(sampler)
    got = [k_lights.sample_light_point(tables, sampler.num_lights, *args) for args in zip(*u)]
    np.testing.assert_array_equal([g[0] for g in got], light)
    np.testing.assert_array_equal([g[1] for g in got], points.triangle)
    np.testing.assert_array_equal(np.array([g[2:] for g in got]), points.position)
    np.testing.assert_array_equal(sampler.pmf[light] / sampler.area[light], points.pdf_area)  # the kernel's pdf


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_surface_points_match_triangle_area_sampler():
    geometry, _ = chi2_cases.light_geometry(chi2_cases.four_lights())
    sampler = TriangleAreaSampler(geometry, np.flatnonzero(geometry.area > 0))
    u = [_uniforms(20 + i) for i in range(3)]
    points = sampler.sample(*u)
    tables = k_records.surface_tables(sampler)
    got = [k_lights.sample_surface_point(tables, geometry.corners, *args) for args in zip(*u)]
    np.testing.assert_array_equal([g[0] for g in got], points.triangle)
    np.testing.assert_array_equal(np.array([g[1:] for g in got]), points.position)


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
@pytest.mark.parametrize("selection", ["power", "uniform"])
def test_sample_reuse_matches_split_uniform(selection):
    """The stratified sampler's reuse of one uniform for light, triangle and point (and for triangle and point in
    global area sampling): kernels = lights.*.split_uniform, bit for bit."""
    lights = chi2_cases.four_lights()
    lights[1] = (chi2_cases.fan_light(), lights[1][1])
    geometry, _ = chi2_cases.light_geometry(lights)
    sampler = LightSampler(geometry, selection)
    tables = k_records.light_tables(sampler)
    u = _uniforms(40)
    want = sampler.split_uniform(u)
    got = np.array([k_lights.split_light_uniform(tables, sampler.num_lights, a) for a in u])
    for i in range(3):
        np.testing.assert_array_equal(got[:, i], want[i])
    assert np.all((want[2] >= 0) & (want[2] < 1))
    # The path loop's split (kernels.emitters.split_light_piece_all): the same light and point coordinate, and
    # the piece the light's table gives for its u_tri, found once; an emitter past the area lights has no piece.
    from reference_impl.kernels import emitters as k_emitters

    for a, u_select, u_tri, u1 in zip(u, *want):
        light, piece, got_u1 = k_emitters.split_light_piece_all(tables, sampler.num_lights, sampler.num_area, a)
        f = sampler.first[light]
        assert (light, got_u1) == (k_lights.sample_light_point(tables, sampler.num_lights, u_select, u_tri, u1,
                                                               0.5)[0], u1)
        assert piece == f + k_lights.search_within(sampler.within_cdf, f, sampler.count[light], u_tri)
    with_emitter = LightSampler(geometry, selection, extra_power=np.array([1.0]))  # light 4: a point light, say
    light, piece, got_u1 = k_emitters.split_light_piece_all(k_records.light_tables(with_emitter),
                                                            with_emitter.num_lights, with_emitter.num_area, 0.9999999)
    assert (light, piece) == (with_emitter.num_area, -1) and 0 <= got_u1 < 1
    surfaces = TriangleAreaSampler(geometry, np.flatnonzero(geometry.area > 0))
    want = surfaces.split_uniform(u)
    got = np.array([k_lights.split_surface_uniform(k_records.surface_tables(surfaces), a) for a in u])
    np.testing.assert_array_equal(got[:, 0], want[0])
    np.testing.assert_array_equal(got[:, 1], want[1])


@pytest.mark.parametrize("name", ["box", "tent"])
def test_filter_offsets_match_pixel_filter(name):
    u = _uniforms(30)
    x, w = make_filter(name).sample_1d(u)
    got = np.array([k_camera.filter_sample(k_config.FILTER_KINDS[name], a) for a in u])
    np.testing.assert_array_equal(got[:, 0], x)
    np.testing.assert_array_equal(got[:, 1], w)


def test_random_dimensions_and_counters_agree_with_the_integrator():
    from reference_impl import integrator

    purposes = [getattr(rng, name) for name in ("FILM_X", "FILM_Y", "LIGHT_SELECT", "LIGHT_TRIANGLE", "LIGHT_U1",
                                                "LIGHT_U2", "DIRECT_DIR_U1", "DIRECT_DIR_U2", "ROULETTE", "INDIRECT_U1",
                                                "INDIRECT_U2")]
    assert sorted(purposes) == list(range(len(purposes)))  # one dimension each
    order = ("C_CAMERA", "C_SHADOW", "C_SHADOW_SKIPPED", "C_HEMI_DIRECT", "C_INDIRECT", "C_ESCAPED", "C_BACK_FACE",
             "C_ROULETTE", "C_NONFINITE", "C_LIGHT_SELECT")
    assert [getattr(k_config, c) for c in order] == list(range(len(integrator.COUNTERS)))
    assert integrator.COUNTERS[k_config.C_NONFINITE] == "nonfinite_samples" and integrator.COUNTERS[k_config.C_SHADOW] == "shadow_rays"
    assert integrator.COUNTERS[k_config.C_LIGHT_SELECT] == "light_selections"
    from reference_impl.intersect import _OFFSET_REL

    assert k_surface._OFFSET_REL == _OFFSET_REL
