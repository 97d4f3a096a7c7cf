"""The analytic sphere in the core: the queries' float64 sphere test (``kernels.queries.sphere_nearest``) and hit
(``intersect.sphere_distance``, ``kernels.surface.sphere_hit_point``), a sphere light sampled uniformly in area
(``lights.sphere_points``, ``kernels.light_sampling.point_on_sphere``) and global area sampling's sphere entry. The
densities are the chi-square tests' (``light_sphere_points*``, ``global_area_sphere_choice`` in ``chi2_cases.py``);
here the kernels' bits, a planted wrong warp the chi-square test must reject, and the weight Le G / p(y) against
the irradiance a sphere gives in closed form."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

try:
    import chi2_cases as cases
except ImportError:  # tests/ imported as a package
    from tests import chi2_cases as cases

from harness.judges.chi2 import chi2_test_2d
from reference_impl.intersect import Intersector
from reference_impl.kernels import light_sampling as k_lights
from reference_impl.kernels import records as k_records
from reference_impl.kernels import surface as k_surface
from reference_impl.lights import LightSampler, TriangleAreaSampler, front_normals

C, R = cases.SPHERE_CENTER, cases.SPHERE_RADIUS


def test_a_sphere_light_is_one_piece_of_area_4_pi_r2():
    sampler = LightSampler(cases.sphere_geometry(), "power")
    assert sampler.count.tolist() == [1] and sampler.sphere.tolist() == [True]
    assert sampler.area[0] == pytest.approx(4 * np.pi * R * R, rel=1e-15)
    assert sampler.pdf_area(np.zeros(1, np.int64))[0] == pytest.approx(1 / (4 * np.pi * R * R), rel=1e-15)
    _k, points = sampler.sample(*np.random.default_rng(1).random((4, 1000)))
    assert np.allclose(np.linalg.norm(points.position - C, axis=1), R, rtol=0, atol=1e-15)
    np.testing.assert_allclose(points.normal, (points.position - C) / R, atol=1e-14)  # outward: the front side
    inward = LightSampler(cases.sphere_geometry(inward=True), "power")
    _k, inside = inward.sample(*np.random.default_rng(1).random((4, 1000)))
    np.testing.assert_allclose(inside.normal, (C - inside.position) / R, atol=1e-14)


def test_the_kernels_draw_the_same_sphere_points():
    geometry = cases.sphere_geometry(floor=True)
    lights = LightSampler(geometry, "power")
    u = np.random.default_rng(2).random((4, 2000))
    light, points = lights.sample(*u)
    tables = k_records.light_tables(lights)
    got = [k_lights.sample_light_point(tables, lights.num_lights, *args) for args in zip(*u)]
    np.testing.assert_array_equal([g[1] for g in got], points.triangle)
    assert np.array([g[2:] for g in got]).tobytes() == points.position.tobytes()
    surfaces = TriangleAreaSampler(geometry, np.flatnonzero(geometry.area > 0))
    spoints = surfaces.sample(*u[:3])
    stables = k_records.surface_tables(surfaces)
    got = [k_lights.sample_surface_point(stables, geometry.corners, *args) for args in zip(*u[:3])]
    np.testing.assert_array_equal([g[0] for g in got], spoints.triangle)
    assert np.array([g[1:] for g in got]).tobytes() == spoints.position.tobytes()
    scene = k_records.scene_tables(geometry, Intersector(geometry).prim_to_tri)
    normals = np.array([k_surface.normal_at(scene, t, *y) for t, y in zip(spoints.triangle, spoints.position)])
    np.testing.assert_array_equal(normals, front_normals(geometry, spoints.triangle, spoints.position))


def test_the_chi2_test_rejects_points_uniform_in_the_polar_angle():
    """The classic wrong warp, z = cos(pi u1) (uniform in theta, crowding the poles): the chi-square test of
    ``light_sphere_points`` must reject it at its own level."""
    g = np.random.default_rng(5)

    def sample(n):
        return np.cos(np.pi * g.random(n)), 2 * np.pi * g.random(n)

    result = chi2_test_2d(sample, lambda z, phi: np.full(len(z), 1 / (4 * np.pi)), [(-1.0, 1.0), (0.0, 2 * np.pi)],
                          (24, 48), cases.N_SAMPLES, name="planted", quadrature="midpoint", order=4)
    assert result.p_value < cases.STANDARD_ALPHA


@pytest.mark.parametrize("distance", [1.5, 4.0])
def test_light_samples_weigh_to_the_irradiance_of_a_sphere(distance):
    """E at a point x facing the sphere's centre from ``distance`` r is pi Le (r / d)^2 (a sphere of radiance Le
    subtends a cap of sin(alpha) = r / d, all above x's horizon): the mean of Le cos_x cos_y / (|y - x|^2 p(y)) over
    the sphere's light samples (cos_y > 0: the visible cap; a convex surface hides the rest from x), with p(y) =
    pdf_area. Tolerance: 4.9 standard errors (two-sided 1e-6)."""
    sampler = LightSampler(cases.sphere_geometry(), "power")
    x = C + np.array([0.0, 0.0, distance * R])
    n_x = np.array([0.0, 0.0, -1.0])
    _k, pts = sampler.sample(*np.random.default_rng(7).random((4, 400_000)))
    to_y = pts.position - x
    d2 = np.einsum("ij,ij->i", to_y, to_y)
    wi = to_y / np.sqrt(d2)[:, None]
    cos_x, cos_y = wi @ n_x, -np.einsum("ij,ij->i", pts.normal, wi)
    weight = np.where((cos_x > 0) & (cos_y > 0), cos_x * cos_y / (d2 * pts.pdf_area), 0.0)
    want = np.pi / distance**2
    z = stats.norm.isf(0.5e-6)
    assert abs(weight.mean() - want) < z * weight.std() / np.sqrt(len(weight)), (weight.mean(), want)


def test_rays_hit_the_analytic_sphere_in_float64():
    """Rays from outside, from inside and along chords, through the queries' sphere test: the hit is the nearer root
    of |o + t d - c| = r to float64 precision (|x - c| = r within 1e-12 of the rays' scale, about 5: the root of a
    grazing ray is ill-conditioned, a few hundred ulps; Embree's float32 t would be off by 1e-7), reported on the
    sphere's first triangle, and a floor below it keeps its own triangles."""
    geometry = cases.sphere_geometry(floor=True)
    ix = Intersector(geometry)
    g = np.random.default_rng(3)
    n = 20_000
    targets = C + R * (g.random((n, 3)) - 0.5)  # inside the sphere
    outside = C + np.array([0.0, 0.0, 5.0]) + g.normal(size=(n, 3))
    inside = C + 0.5 * R * (g.random((n, 3)) - 0.5)
    for origins in (outside, inside):
        d = targets - origins if origins is outside else g.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        tri, t = ix.closest_hit(origins, d)
        on = tri == 0
        assert on.mean() > 0.9
        x = origins[on] + t[on, None] * d[on]
        assert np.abs(np.linalg.norm(x - C, axis=1) - R).max() <= 1e-12
        m = x - C
        if origins is outside:  # the near side: the ray comes from the front
            assert np.all(np.einsum("ij,ij->i", m, d[on]) < 0)
        else:
            assert np.all(np.einsum("ij,ij->i", m, d[on]) > 0)
    tri, t = ix.closest_hit(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, -1.0]]))
    assert tri[0] == len(geometry.triangles) - 2 or tri[0] == len(geometry.triangles) - 1  # the floor
    scene = k_records.scene_tables(geometry, ix.prim_to_tri)
    p = len(ix.prim_to_tri) - 1  # the sphere's primitive
    t64, x0, x1, x2, n0, n1, n2, cos_out = k_surface.sphere_hit_point(scene, 0, *outside[0], *(C - outside[0]) /
                                                                       np.linalg.norm(C - outside[0]))
    assert ix.prim_to_tri[p] == 0 and cos_out > 0.999999
    assert abs(np.linalg.norm(np.array([x0, x1, x2]) - C) - R) <= 1e-12
