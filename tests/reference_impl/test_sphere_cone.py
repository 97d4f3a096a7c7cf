"""A sphere light seen from outside, drawn by the cone it subtends (``lights.cone_points``,
``kernels.light_sampling.point_in_cone``, ``cone_pdf``; the density's chi-square tests are ``light_sphere_cone*`` in
``chi2_cases.py``): the kernels' bits against the spec, the points on the cap x sees, the weight Le cos_x / p(w)
against the irradiance a sphere gives in closed form, a planted wrong warp the chi-square test must reject, the
density a BSDF ray that finds the sphere is weighed with (MIS) equal to the one the light sample was drawn with, and
where the cone is not used (an x inside, emission facing inward)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

try:
    import chi2_cases as cases
except ImportError:  # tests/ imported as a package
    from tests import chi2_cases as cases

from harness.judges.chi2 import chi2_test_2d
from reference_impl.kernels import light_sampling as k_lights
from reference_impl.kernels import records as k_records
from reference_impl.lights import LightSampler, cone_points, sphere_cone

C, R = cases.SPHERE_CENTER, cases.SPHERE_RADIUS


def _outside(n: int, seed: int, near: float = 1.0001, far: float = 50.0) -> np.ndarray:
    """Points x at |x - c| / r spread between ``near`` and ``far``, in random directions."""
    g = np.random.default_rng(seed)
    d = g.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return C + d * (R * np.exp(g.uniform(np.log(near), np.log(far), n)))[:, None]


def test_the_kernels_draw_the_cone_points_of_the_spec_bit_for_bit():
    n = 4000
    x = _outside(n, 1)
    u1, u2 = np.random.default_rng(2).random((2, n))
    want, _pdf = cone_points(np.repeat(C[None, :], n, axis=0), np.full(n, R), x, u1, u2)
    got = np.empty((n, 3))
    for i in range(n):
        d2, s2, one_minus = k_lights.sphere_cone(*C, R, *x[i])
        got[i] = k_lights.point_in_cone(*C, R, *x[i], d2, s2, one_minus, u1[i], u2[i])
    assert got.tobytes() == want.tobytes()
    geometry = cases.sphere_geometry()
    tables = k_records.light_tables(LightSampler(geometry, "power"))
    c = geometry.sphere_center[0]  # C through the shape's matrix: within an ulp
    assert tables.cone.tolist() == [[*c, R]] and np.allclose(c, C, rtol=0, atol=1e-15)
    dens = np.array([k_lights.cone_pdf(tables, 0, *xi, 0) for xi in x])
    want_pdf = cone_points(np.repeat(c[None, :], n, axis=0), np.full(n, R), x, u1, u2)[1]
    assert dens.tobytes() == want_pdf.tobytes()


def test_cone_points_lie_on_the_cap_that_x_sees():
    """|y - c| = r to float64 precision, y faces x ((y - c) . (x - y) >= 0 up to rounding), and y lies in the cone
    (1 - cos theta <= 1 - cos theta_max), also for a far sphere (sin^2 theta_max = 1e-10, where 1 - cos theta_max
    computed as a difference would have lost every digit)."""
    n = 20_000
    for near, far in ((1.0001, 50.0), (1e5, 1e5 * 1.001)):
        x = _outside(n, 3, near, far)
        u1, u2 = np.random.default_rng(4).random((2, n))
        y, pdf = cone_points(np.repeat(C[None, :], n, axis=0), np.full(n, R), x, u1, u2)
        assert np.abs(np.linalg.norm(y - C, axis=1) - R).max() <= 1e-14
        m = (y - C) / R
        to_x = (x - y) / np.linalg.norm(x - y, axis=1)[:, None]
        assert np.einsum("ij,ij->i", m, to_x).min() >= -1e-6
        _d2, s2, one_minus = sphere_cone(np.repeat(C[None, :], n, axis=0), np.full(n, R), x)
        assert np.allclose(one_minus, 1.0 - np.sqrt(1.0 - s2), rtol=1e-6, atol=1e-16)
        assert np.all(np.isfinite(pdf)) and np.all(pdf > 0)
        for xi, yi, om in zip(x[:200], y[:200], one_minus[:200]):
            h, _phi = cases.cone_coordinates(yi[None, :], xi, C)
            assert h[0] <= om * (1 + 1e-6) + 1e-300


@pytest.mark.parametrize("distance, tilt", [(1.05, 0.0), (1.5, 0.3), (4.0, 0.0), (400.0, 0.5)])
def test_cone_samples_weigh_to_the_irradiance_of_a_sphere(distance, tilt):
    """E at x, distance d from the centre, normal tilted by ``tilt`` from the axis toward c while the whole cap stays
    above x's horizon, is pi Le sin^2 theta_max cos(tilt), sin theta_max = r / d (the projected solid angle of a
    cone). The mean of Le cos_x / p(w) over the cone's samples must give it: the estimator of the path loops'
    connection, Le / (pdf(k) p(w)) times cos_x. Tolerance: 4.9 standard errors (two-sided 1e-6)."""
    n = 400_000
    x = C + np.array([0.0, 0.0, distance * R])
    axis = np.array([0.0, 0.0, -1.0])
    n_x = np.array([math.sin(tilt), 0.0, -math.cos(tilt)])
    assert math.asin(1 / distance) + tilt < math.pi / 2  # the cap is above the horizon
    u1, u2 = np.random.default_rng(7).random((2, n))
    y, pdf = cone_points(np.repeat(C[None, :], n, axis=0), np.full(n, R), np.repeat(x[None, :], n, axis=0), u1, u2)
    wi = (y - x) / np.linalg.norm(y - x, axis=1)[:, None]
    weight = (wi @ n_x) / pdf
    want = math.pi * (1 / distance) ** 2 * math.cos(tilt)
    z = stats.norm.isf(0.5e-6)
    se = weight.std() / math.sqrt(n)
    assert abs(weight.mean() - want) < z * se + 1e-12 * want, (weight.mean(), want)
    assert wi @ axis == pytest.approx(np.ones(n), abs=1.0 - math.sqrt(1 - 1 / distance**2) + 1e-12)


def test_the_chi2_test_rejects_the_cone_uniform_in_the_polar_angle():
    """A wrong warp of the cone, theta uniform in [0, theta_max] (the rim undersampled) with the solid angle's pdf:
    the chi-square test of ``light_sphere_cone`` must reject it (it can fail)."""
    x = C + 1.7 * R * np.array([0.6, -0.8, 0.0])
    one = (C[None, :], np.array([R]), x[None, :])
    _d2, s2, one_minus = sphere_cone(*one)
    density = cone_points(*one, np.array([0.5]), np.array([0.5]))[1][0]
    theta_max = math.asin(math.sqrt(s2[0]))
    g = np.random.default_rng(11)

    def sample(n):
        theta, phi = theta_max * g.random(n), 2 * np.pi * g.random(n)
        return 1.0 - np.cos(theta), phi

    result = chi2_test_2d(sample, lambda h, phi: np.full(len(h), density), [(0.0, one_minus[0]), (0.0, 2 * np.pi)],
                          (24, 48), cases.N_SAMPLES, name="planted", quadrature="midpoint", order=4)
    assert result.p_value < 1e-9


def test_a_bsdf_ray_that_finds_the_sphere_is_weighed_with_the_density_it_was_drawn_with():
    """MIS needs the light samples' density of a direction the same whether the light sample drew it
    (``direct.cone_connection``: p_l = Nd pdf(k) p(w)) or a BSDF ray found it (the path loops: Nd pdf(k) cone_pdf
    at the vertex the ray left): the same float for the same x."""
    geometry = cases.sphere_geometry()
    tables = k_records.light_tables(LightSampler(geometry, "power"))
    for x in _outside(500, 5):
        _d2, _s2, one_minus = k_lights.sphere_cone(*geometry.sphere_center[0], R, *x)
        assert k_lights.cone_pdf(tables, 0, *x, 0) == k_lights.HALF_INV_PI / one_minus


def test_no_cone_from_inside_or_for_a_sphere_that_emits_inward():
    """From x on or inside the sphere there is no cone: cone_pdf is 0 and the light keeps its area samples. A sphere
    whose emission faces inward (the furnace's enclosure) is not in the cone table at all; with the planted fault
    "sphere-points-uniform-theta" (the area sampler's) no sphere is drawn by its cone."""
    tables = k_records.light_tables(LightSampler(cases.sphere_geometry(), "power"))
    g = np.random.default_rng(6)
    for x in C + R * (g.random((200, 3)) - 0.5) * 1.1:
        assert k_lights.cone_pdf(tables, 0, *x, 0) == 0.0
    assert k_lights.cone_pdf(tables, 0, *C, 0) == 0.0
    assert k_lights.sphere_cone(*C, R, *C)[2] == 0.0
    from reference_impl.kernels.config import M_SPHERE_POINTS_THETA
    assert k_lights.cone_pdf(tables, 0, *(C + 3 * R), 0) > 0.0
    assert k_lights.cone_pdf(tables, 0, *(C + 3 * R), M_SPHERE_POINTS_THETA) == 0.0  # that fault draws by area
    inward = LightSampler(cases.sphere_geometry(inward=True), "power")
    assert inward.cone.tolist() == [[0.0, 0.0, 0.0, 0.0]]
    assert k_lights.cone_pdf(k_records.light_tables(inward), 0, *(C + 3 * R), 0) == 0.0
