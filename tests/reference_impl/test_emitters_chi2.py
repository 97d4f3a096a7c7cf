"""Chi-square tests of the emitters' sampling routines (reference_impl/emitters.py) against their own pdfs, and the
kernels' twins (reference_impl/kernels/emitters.py) against the numpy definitions.

* envmap importance sampling (``sample_envmap`` vs ``envmap_pdf``) on a procedural map with a sharp sun (one texel
  10^4 times the sky) and on a rotated one, binned in the map's (u, v) with the Jacobian
  d omega = 2 pi^2 sin(pi v) du dv, the bins aligned with the cells of the bilinear interpolation (so the pdf is
  constant inside each bin and its integral exact), at one and at two bins per cell and axis;
* ``sample_environment`` with "uniform", "cosine" (about non-axis normals) and "importance" on a constant
  environment (uniform), in (cos theta, phi) about the normal;
* light selection by power and uniformly over area lights and emitters of every kind (``LightSampler.select``).

Spot lights have no sampling routine: they are delta lights, connected deterministically (their falloff and power
are checked against closed forms below, the estimator in test_emitters.py).

Significance: each test of the family fails when p < alpha = 1 - (1 - 0.01)^(1/m) (Sidak) for the m = FAMILY
tests, so the file has a 1 % chance of a false alarm; the seeds are fixed. ``test_rejects_*`` feed deliberately
wrong pdfs and require rejection (p < 1e-9 or a hard failure): they prove the tests can fail. Each test prints
``chi2 <name>: p = <value>`` (``pytest -s``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from emitter_scenes import sun_sky_map

from harness.judges.chi2 import (SPHERE_COS_PHI, chi2_test_2d, chi2_test_discrete, directions_to_cos_phi,
                                 orthonormal_basis, sidak_alpha, to_local)
from harness.scene.triangulate import rotate_matrix
from reference_impl import Constant, Directional, EnvMap, Point, Settings, Spot
from reference_impl import emitters as em
from reference_impl.geometry import Geometry
from reference_impl.lights import LightSampler

pytestmark = pytest.mark.slow  # 10^6 samples a test: outside the inner loop (pytest -m "not slow")

N = 1_000_000
FAMILY = 9
ALPHA = sidak_alpha(FAMILY)
REJECT_P = 1e-9


def _report(result):
    print(result.line())
    return result


def _uniforms(seed: int, n: int):
    g = np.random.default_rng(seed)
    return g.random(n), g.random(n)


def _sun_map(to_world=None) -> em.Emitters:
    image = sun_sky_map(32, 16, sun_uv=(0.3, 0.3), sun=1e4)
    return em.Emitters([EnvMap(image=image, to_world=np.eye(4) if to_world is None else to_world, scale=1.0)])


ROTATION = rotate_matrix((0.3, 1.0, -0.4), 70.0)


# The samples of one map and seed, drawn once in a process: the wrong-pdf tests judge the same samples as the
# "envmap sun, cells" case (a fixed seed gives the same samples anyway; read-only, so no test can change another's).
_ENVMAP_SAMPLES: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}


def _envmap_uv_test(emitters: em.Emitters, seed: int, per_cell: int, name: str, pdf=None):
    """Samples of ``sample_envmap`` as (u', v) of the map, u' = u - 1/(2W) wrapped (cells start at texel centres),
    against ``pdf`` (default envmap_pdf) times the Jacobian 2 pi^2 sin(pi v)."""
    rows, cols = emitters.env_cell_pdf.shape
    to_local = emitters.to_local[emitters.env]
    to_world = emitters.to_world[emitters.env]
    pdf = pdf or em.envmap_pdf

    def sample(n):
        key = (seed, n, emitters.env_image.tobytes(), to_world.tobytes())
        if key not in _ENVMAP_SAMPLES:
            world, _pdf = em.sample_envmap(emitters, *_uniforms(seed, n))
            local = world @ to_local.T
            local /= np.linalg.norm(local, axis=1, keepdims=True)
            u, v = em.direction_to_uv(local)
            u = np.mod(u - 0.5 / cols, 1.0)
            u.flags.writeable = v.flags.writeable = False
            _ENVMAP_SAMPLES[key] = (u, v)
        return _ENVMAP_SAMPLES[key]

    def pdf_uv(us, v):
        u = np.mod(us + 0.5 / cols, 1.0)
        world = em.uv_to_direction(u, v) @ to_world.T
        world /= np.linalg.norm(world, axis=1, keepdims=True)
        return pdf(emitters, world)

    return chi2_test_2d(sample, pdf_uv, ((0.0, 1.0), (0.0, 1.0)), (cols * per_cell, rows * per_cell), N,
                        jacobian=lambda u, v: 2.0 * np.pi**2 * np.sin(np.pi * v), name=name)


def _direction_test(emitters, strategy: str, normal, seed: int, name: str):
    normal = np.asarray(normal, float) / np.linalg.norm(normal)

    def sample(n):
        u1, u2 = _uniforms(seed, n)
        world, _pdf = em.sample_environment(emitters, strategy, u1, u2, np.tile(normal, (n, 1)))
        return directions_to_cos_phi(to_local(world, normal))

    def pdf(c, phi):
        local = np.column_stack([np.sqrt(np.maximum(0, 1 - c * c)) * np.cos(phi),
                                 np.sqrt(np.maximum(0, 1 - c * c)) * np.sin(phi), c])
        s, t, _n = orthonormal_basis(normal)  # the frame to_local uses
        world = local[:, :1] * s + local[:, 1:2] * t + local[:, 2:3] * normal
        return em.environment_pdf(emitters, strategy, world, np.tile(normal, (len(c), 1)))

    return chi2_test_2d(sample, pdf, SPHERE_COS_PHI, (64, 64), N, name=name)


def _all_kinds_sampler(selection: str):
    """A LightSampler over two area lights and a point, a spot, a directional light and an envmap."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [4, 0, 0], [2, 3, 0]], float)
    geometry = Geometry(vertices=vertices, triangles=np.array([[0, 1, 2], [3, 4, 5]]), material=np.zeros(2, int),
                        reflectance=np.array([[0.5, 0.5, 0.5]]), two_sided=np.array([False]),
                        emission=np.array([[1.0, 1.0, 1.0], [0.5, 0.2, 0.1]]), light_id=np.array([0, 1]))
    emitters = em.Emitters([Point((0, 0, 1), (3.0, 3.0, 3.0)),
                            Spot(np.eye(4), (10.0, 10.0, 10.0), cutoff_angle=30.0, beam_width=10.0),
                            Directional((0, 0, -1), (0.2, 0.2, 0.2)),
                            EnvMap(sun_sky_map(), np.eye(4), scale=0.01)])
    radius = em.scene_radius(vertices)
    return LightSampler(geometry, selection, emitters.powers(radius)), emitters, radius


# ------------------------------------------------------------------------------------------------ the family


def test_family_size():
    assert len(CASES) == FAMILY


CASES = {
    "envmap sun, cells": lambda: _envmap_uv_test(_sun_map(), 1, 1, "envmap importance, sun, bins = cells"),
    "envmap sun, 2 bins per cell": lambda: _envmap_uv_test(_sun_map(), 2, 2, "envmap importance, sun, 2x2 per cell"),
    "envmap rotated": lambda: _envmap_uv_test(_sun_map(ROTATION), 3, 1, "envmap importance, rotated map"),
    "uniform": lambda: _direction_test(_sun_map(), "uniform", (0.3, -0.5, 0.81), 4, "env uniform"),
    "cosine": lambda: _direction_test(_sun_map(), "cosine", (-0.6, 0.7, -0.2), 5, "env cosine"),
    "cosine near -z": lambda: _direction_test(_sun_map(), "cosine", (0.02, -0.03, -0.95), 6, "env cosine, -z"),
    "constant importance": lambda: _direction_test(em.Emitters([Constant((1.0, 1.0, 1.0))]), "importance",
                                                   (0.0, 0.0, 1.0), 7, "constant env importance (= uniform)"),
    "selection power": lambda: _selection_test("power", 8),
    "selection uniform": lambda: _selection_test("uniform", 9),
}


def _selection_test(selection: str, seed: int):
    sampler, _emitters, _radius = _all_kinds_sampler(selection)
    light, rest = sampler.select(np.random.default_rng(seed).random(N))
    assert np.all((rest >= 0) & (rest < 1))
    return chi2_test_discrete(light, sampler.pdf_select(np.arange(sampler.num_lights)),
                              name=f"light selection {selection}, area lights and every emitter kind")


@pytest.mark.parametrize("name", [n for n in CASES])
def test_chi2(name):
    result = _report(CASES[name]())
    failures = result.failures(ALPHA)
    assert not failures, f"{name}: " + "; ".join(failures)


# ------------------------------------------------------------------------------------------- they can fail


def test_rejects_an_envmap_pdf_without_sin_theta():
    def wrong(emitters, world):
        local = world @ emitters.to_local[emitters.env].T
        return em.envmap_pdf(emitters, world) * np.sqrt(local[:, 0] ** 2 + local[:, 2] ** 2)

    result = _report(_envmap_uv_test(_sun_map(), 1, 1, "envmap pdf without sin theta (wrong)", pdf=wrong))
    assert result.failures(ALPHA) and (result.p_value < REJECT_P or result.pdf_integral < 0.999)


def test_rejects_a_mirrored_envmap_pdf():
    def mirrored(emitters, world):
        local = world @ emitters.to_local[emitters.env].T
        flipped = local * np.array([-1.0, 1.0, 1.0])  # u -> 1 - u
        return em.envmap_pdf(emitters, flipped @ emitters.to_world[emitters.env].T)

    result = _report(_envmap_uv_test(_sun_map(), 1, 1, "envmap pdf mirrored in u (wrong)", pdf=mirrored))
    assert result.p_value < REJECT_P


# ------------------------------------------------------------------------------- powers and closed forms


def test_selection_by_power_gives_each_kind_its_power():
    """pdf(k) proportional to pi A lum(Le) (area), 4 pi lum(I) (point), lum(I) 2 pi (1 - (sin c - sin b)/(c - b))
    (spot), lum(E) pi R^2 (directional), pi R^2 int lum(L) dw (envmap)."""
    sampler, emitters, radius = _all_kinds_sampler("power")
    lum = np.array([0.2126, 0.7152, 0.0722])
    c, b = math.radians(30.0), math.radians(10.0)
    # int L dw of the envmap from its cells' mean corners times their solid angles: within 1 % of the integral of
    # the bilinear radiance itself (by quadrature) on this map with a sharp sun.
    np.testing.assert_allclose(emitters.env_integral, _quadrature_env_integral(emitters), rtol=1e-2)
    expected = np.array([np.pi * 0.5 * 1.0, np.pi * 3.0 * (np.array([0.5, 0.2, 0.1]) @ lum), 4 * np.pi * 3.0,
                         10.0 * 2 * np.pi * (1 - (math.sin(c) - math.sin(b)) / (c - b)), 0.2 * np.pi * radius**2,
                         np.pi * radius**2 * (emitters.env_integral @ lum)])
    np.testing.assert_allclose(sampler.pmf, expected / expected.sum(), rtol=1e-12)
    uniform, _e, _r = _all_kinds_sampler("uniform")
    np.testing.assert_allclose(uniform.pmf, np.full(6, 1 / 6))


def _quadrature_env_integral(emitters: em.Emitters, n: int = 800) -> np.ndarray:
    """int L dw of the envmap by a midpoint rule in (u, v) over the bilinear radiance (not the cell means)."""
    u = (np.arange(2 * n) + 0.5) / (2 * n)
    v = (np.arange(n) + 0.5) / n
    uu, vv = np.meshgrid(u, v)
    world = em.uv_to_direction(uu.ravel(), vv.ravel())
    radiance = em.environment_radiance(emitters, world)
    weight = 2 * np.pi**2 * np.sin(np.pi * vv.ravel()) / (2 * n * n)
    return radiance.T @ weight


def test_spot_falloff_and_its_solid_angle():
    """Mitsuba's falloff: 1 within beam_width, linear in the angle to 0 at cutoff_angle; its integral over the
    sphere is the closed form spot_solid_angle (midpoint rule in theta)."""
    emitters = em.Emitters([Spot(np.eye(4), (1.0, 1.0, 1.0), cutoff_angle=30.0, beam_width=10.0)])
    theta = np.radians(np.array([0.0, 5.0, 10.0, 20.0, 25.0, 29.9, 30.0, 45.0, 170.0]))
    local = np.column_stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)]) * 2.5  # not unit: normalised
    s = em.spot_falloff(emitters.spot[0], local)
    np.testing.assert_allclose(s, [1, 1, 1, 0.5, 0.25, 0.005, 0, 0, 0], atol=1e-9)
    t = (np.arange(200_000) + 0.5) * (np.pi / 200_000)
    dirs = np.column_stack([np.sin(t), np.zeros_like(t), np.cos(t)])
    integral = 2 * np.pi * np.sum(em.spot_falloff(emitters.spot[0], dirs) * np.sin(t)) * (np.pi / 200_000)
    assert integral == pytest.approx(em.spot_solid_angle(math.radians(30.0), math.radians(10.0)), rel=1e-6)
    assert em.spot_solid_angle(0.5, 0.5) == pytest.approx(2 * np.pi * (1 - math.cos(0.5)))


def test_envmap_lookup_is_mitsubas_bilinear_interpolation():
    """Texel column j at u = (j + 1/2) / W (periodic), row i at v = i / (H - 1) (clamped): at those points the
    lookup is the texel itself; halfway between two columns, their mean (across the seam too)."""
    image = np.random.default_rng(3).random((5, 6, 3))
    i, j = np.meshgrid(np.arange(5), np.arange(6), indexing="ij")
    u, v = ((j + 0.5) / 6).ravel(), (i / 4).ravel()
    np.testing.assert_allclose(em.envmap_lookup(image, u, v), image.reshape(-1, 3), atol=1e-12)
    seam = em.envmap_lookup(image, np.array([0.0, 1.0 - 1e-12]), np.array([0.5, 0.5]))
    np.testing.assert_allclose(seam, 0.5 * (image[2, 0] + image[2, 5])[None].repeat(2, 0), atol=1e-9)
    # v = 0 is +y (up) of the map's frame, u = 0 looks along -z, u = 1/4 along +x (Mitsuba's uv_to_direction).
    np.testing.assert_allclose(em.uv_to_direction(np.array([0.0, 0.25, 0.5]), np.array([0.5, 0.5, 0.5])),
                               [[0, 0, -1], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(em.uv_to_direction(np.array([0.0]), np.array([0.0])), [[0, 1, 0]], atol=1e-12)
    # Too small an image is padded as Mitsuba's Bitmap::pad_to((2, 3)).
    assert em.Emitters([EnvMap(np.ones((1, 1, 3)), np.eye(4))]).env_image.shape == (3, 2, 3)


# ------------------------------------------------------------------------ the kernels repeat the definitions


def _kernel_inputs(emitters: em.Emitters, env_sampling: str, mutant: str = ""):
    from reference_impl.kernels import config, records  # optional: numba-compiled, as the renders import it

    cfg = config.kernel_config(Settings(env_sampling=env_sampling, max_depth=2, mutant=mutant).resolved(False),
                               len(emitters), 0.0, 0.0, num_area_lights=0, env_light=emitters.env)
    return cfg, records.emitter_tables(emitters)


@pytest.mark.parametrize("strategy", ["importance", "uniform", "cosine"])
def test_kernels_repeat_the_environment_samplers(strategy):
    from reference_impl.kernels import emitters as kem  # optional: numba-compiled

    emitters = _sun_map(ROTATION)
    cfg, tables = _kernel_inputs(emitters, strategy)
    g = np.random.default_rng(12)
    n = 2000
    u1, u2 = g.random(n), g.random(n)
    normals = g.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    world, pdf = em.sample_environment(emitters, strategy, u1, u2, normals)
    radiance = em.environment_radiance(emitters, world)
    pdf_again = em.environment_pdf(emitters, strategy, world, normals)
    # every sample through the kernels, then each quantity compared elementwise at once (same tolerances)
    sampled = np.array([kem.env_sample(cfg, tables, u1[k], u2[k], *normals[k]) for k in range(n)])
    np.testing.assert_allclose(sampled, np.column_stack([world, pdf]), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(np.array([kem.env_radiance(cfg, tables, *world[k]) for k in range(n)]), radiance,
                               rtol=1e-9)
    np.testing.assert_allclose(np.array([kem.env_pdf(cfg, tables, *world[k], *normals[k]) for k in range(n)]),
                               pdf_again, rtol=1e-12)
    # The pdf a light sample used and the one an escaping ray recomputes agree (up to cell boundaries).
    agree = np.isclose(pdf, pdf_again, rtol=1e-9)
    assert agree.mean() > 0.999


def test_kernels_repeat_the_spot_falloff():
    from reference_impl.kernels import emitters as kem  # optional: numba-compiled

    emitters = em.Emitters([Spot(np.eye(4), (1.0, 1.0, 1.0), cutoff_angle=30.0, beam_width=10.0)])
    cfg, tables = _kernel_inputs(emitters, "importance")
    local = np.random.default_rng(13).normal(size=(2000, 3)) + np.array([0, 0, 2.0])
    expected = em.spot_falloff(emitters.spot[0], local)
    got = np.array([kem.spot_falloff(cfg, tables[6], 0, *d) for d in local])
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)
    assert 0 < np.mean(expected == 1) < 1 and 0 < np.mean(expected == 0) < 1  # every part of the curve was seen
