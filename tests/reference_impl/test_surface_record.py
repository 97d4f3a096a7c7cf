"""The surface record of a hit (kernels.surface.SurfaceHit) and the material step (kernels.material.material_at):
what a hit holds, its barycentrics against Moeller and Trumbore's, and that the BSDF reads its parameters from the
material step's answer alone."""

from __future__ import annotations

import numpy as np
import pytest

from reference_impl import Geometry, Materials
from reference_impl.kernels import bsdf, material, records, surface
from reference_impl.materials import CONDUCTOR, DIFFUSE, NUM_PARAMS, P_REFLECTANCE, material_row


def _geometry(seed: int = 3, count: int = 6) -> Geometry:
    """``count`` random triangles, far apart, with two materials."""
    g = np.random.default_rng(seed)
    corners = g.normal(size=(count, 3, 3)) + 10.0 * np.arange(count)[:, None, None]
    return Geometry(vertices=corners.reshape(-1, 3), triangles=np.arange(3 * count).reshape(-1, 3),
                    material=np.arange(count) % 2, reflectance=np.array([[0.5, 0.6, 0.7], [0.2, 0.3, 0.4]]),
                    two_sided=np.array([False, True]), emission=np.zeros((count, 3)),
                    light_id=np.full(count, -1))


def _moeller_trumbore(o, d, c):
    """t, u, v of the ray o + t d on the triangle c (Moeller and Trumbore 1997)."""
    e1, e2 = c[1] - c[0], c[2] - c[0]
    p = np.cross(d, e2)
    inv = 1.0 / np.dot(e1, p)
    s = o - c[0]
    q = np.cross(s, e1)
    return np.dot(e2, q) * inv, np.dot(s, p) * inv, np.dot(d, q) * inv


def test_a_hit_records_its_triangle_point_normal_barycentrics_and_shading_frame():
    geometry = _geometry()
    scene = records.scene_tables(geometry, np.arange(len(geometry.triangles)))
    g = np.random.default_rng(5)
    for tri in range(len(geometry.triangles)):
        c = geometry.corners[tri]
        for _ in range(20):
            w = g.dirichlet(np.ones(3))  # a point inside the triangle
            target = w @ c
            o = target + 3.0 * g.normal(size=3)
            d = (target - o) / np.linalg.norm(target - o)
            hit = surface.surface_hit(scene, tri, *o, *d)
            t, u, v = _moeller_trumbore(o, d, c)
            assert (hit.tri, hit.material) == (tri, geometry.material[tri])
            assert hit.t == pytest.approx(t, rel=1e-12)
            np.testing.assert_array_equal([hit.x0, hit.x1, hit.x2], o + hit.t * d)
            np.testing.assert_array_equal([hit.n0, hit.n1, hit.n2], geometry.normal[tri])
            assert hit.cos_out == pytest.approx(-np.dot(d, geometry.normal[tri]), rel=1e-12)
            np.testing.assert_allclose([hit.u, hit.v], [u, v], rtol=0, atol=1e-12)
            np.testing.assert_allclose([hit.u, hit.v], w[1:], rtol=0, atol=1e-12)
            np.testing.assert_allclose((1 - hit.u - hit.v) * c[0] + hit.u * c[1] + hit.v * c[2],
                                       [hit.x0, hit.x1, hit.x2], rtol=0, atol=1e-12)
            assert (hit.tex_u, hit.tex_v) == (0.0, 0.0)
            s = np.array([hit.ss0, hit.ss1, hit.ss2])
            t_ = np.array([hit.st0, hit.st1, hit.st2])
            n = np.array([hit.sn0, hit.sn1, hit.sn2])
            np.testing.assert_array_equal(n, geometry.normal[tri])  # the shading normal is the geometric one
            np.testing.assert_allclose(np.array([s, t_, n]) @ np.array([s, t_, n]).T, np.eye(3), atol=1e-14)
            np.testing.assert_allclose(np.cross(s, t_), n, atol=1e-14)  # right-handed, as the BSDF's local frame


def test_the_material_step_hands_on_the_materials_row_unchanged():
    geometry = _geometry()
    scene = records.scene_tables(geometry, np.arange(len(geometry.triangles)))
    materials = Materials(np.array([DIFFUSE, CONDUCTOR]),
                          np.array([material_row(DIFFUSE, reflectance=(0.5, 0.6, 0.7)),
                                    material_row(CONDUCTOR, eta=(0.2, 0.9, 1.1), k=(3.9, 2.4, 2.2))]))
    tables = records.material_tables(materials)
    for tri in range(len(geometry.triangles)):
        c = geometry.corners[tri]
        o = c.mean(axis=0) + 2.0 * geometry.normal[tri]
        hit = surface.surface_hit(scene, tri, *o, *(-geometry.normal[tri]))
        row = np.full(NUM_PARAMS, np.nan)
        kind = material.material_at(tables, hit, row, 0)
        m = geometry.material[tri]
        assert kind == materials.kind[m]
        np.testing.assert_array_equal(row, materials.params[m])


def test_the_bsdf_reads_its_parameters_from_the_material_steps_answer():
    """A reflectance the material step would change (a texture) scales the BSDF: nothing else is read."""
    tables = records.material_tables(Materials(np.array([DIFFUSE]), material_row(DIFFUSE, reflectance=0.5)[None]))
    row = np.empty(NUM_PARAMS)
    kind = material.material_params(tables, 0, row)
    wo, wi = (0.0, 0.6, 0.8), (0.0, -0.28, 0.96)
    assert bsdf.bsdf_eval(kind, row, 0, *wo, *wi) == pytest.approx((0.5 * 0.96 / np.pi,) * 3, rel=1e-15)
    row[P_REFLECTANCE:P_REFLECTANCE + 3] = [0.1, 0.2, 0.3]
    assert bsdf.bsdf_eval(kind, row, 0, *wo, *wi) == pytest.approx(tuple(np.array([0.1, 0.2, 0.3]) * 0.96 / np.pi),
                                                                   rel=1e-15)
