"""Which lights ``LightSampler`` samples as one parallelogram, and what such a piece returns.

A light of exactly two triangles that share a diagonal and form a planar parallelogram (the same emission, normals
within 1e-9, |o0 + o1 - (s1 + s2)| <= 1e-9 x the longest edge) is one entry of the within-light table, sampled as
y = p0 + u1 e1 + u2 e2 (``lights.parallelogram_frame``); every other light keeps one entry per triangle. The density
of the points is the chi-square tests' (``light_rectangle_points``, ``light_parallelogram_points*`` in
``chi2_cases.py``); the kernels' bits are ``test_kernel_equivalence.py``'s.
"""

from __future__ import annotations

import numpy as np
import pytest

try:
    import chi2_cases as cases
except ImportError:  # tests/ imported as a package
    from tests import chi2_cases as cases

from reference_impl.geometry import Geometry
from reference_impl.lights import LightSampler

SQUARE = np.array([[0.0, 0.0, 2.0], [1.5, 0.0, 2.0], [1.5, 0.8, 2.0], [0.0, 0.8, 2.0]])


def _one_light(vertices, triangles, emission=None) -> LightSampler:
    """A LightSampler over one light made of ``triangles`` (rows of vertex indices), emission 1 unless given per
    triangle."""
    triangles = np.asarray(triangles)
    t = len(triangles)
    emission = np.ones((t, 3)) if emission is None else np.asarray(emission, float)
    geometry = Geometry(vertices=np.asarray(vertices, float), triangles=triangles, material=np.zeros(t, int),
                        reflectance=np.array([[0.5, 0.5, 0.5]]), two_sided=np.array([False]), emission=emission,
                        light_id=np.zeros(t, int))
    return LightSampler(geometry, "power")


def _pieces(sampler: LightSampler) -> list[bool]:
    assert sampler.num_lights == 1 and sampler.first.tolist() == [0]
    return sampler.parallelogram[: sampler.count[0]].tolist()


def _barycentric(corners: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(b0, b1, b2) of points p in their triangles' planes (the normal equations of p - c0 = b1 e1 + b2 e2)."""
    e1, e2, d = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], p - corners[:, 0]
    g11, g12, g22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    r1, r2 = (e1 * d).sum(1), (e2 * d).sum(1)
    det = g11 * g22 - g12 * g12
    b1, b2 = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
    return np.column_stack([1.0 - b1 - b2, b1, b2])


def test_a_rectangle_light_is_one_parallelogram():
    sampler = _one_light(SQUARE, [[0, 1, 2], [0, 2, 3]])  # Mitsuba's rectangle: the diagonal 0-2
    assert _pieces(sampler) == [True]
    assert sampler.within_cdf.tolist() == [1.0]
    assert sampler.triangles.tolist() == [0] and sampler.other.tolist() == [1]
    # p0 = the corner of triangle 0 off the diagonal, the edges to the shared corners in its winding.
    np.testing.assert_array_equal(sampler.frames[0], [SQUARE[1], SQUARE[2] - SQUARE[1], SQUARE[0] - SQUARE[1]])
    assert sampler.area[0] == pytest.approx(1.2, rel=1e-15)


def test_a_parallelogram_light_returns_the_triangle_each_point_lies_in():
    light = cases.parallelogram_light()
    geometry, _ = cases.light_geometry([(light, (4.0, 3.0, 2.0))])
    sampler = LightSampler(geometry, "power")
    assert sampler.count.tolist() == [1] and sampler.parallelogram.tolist() == [True]
    g = np.random.default_rng(3)
    u1, u2 = g.random(20_000), g.random(20_000)
    u1[:4], u2[:4] = [0.0, np.nextafter(1.0, 0.0), 0.5, 0.25], [np.nextafter(1.0, 0.0), 0.0, 0.5, 0.75]
    k, pts = sampler.sample(np.zeros_like(u1), np.zeros_like(u1), u1, u2)
    assert np.all(k == 0) and np.all(geometry.light_id[pts.triangle] == 0)
    assert set(pts.triangle.tolist()) == set(np.flatnonzero(geometry.light_id == 0).tolist())  # both halves
    b = _barycentric(geometry.corners[pts.triangle], pts.position)
    assert np.all(b >= -1e-12)  # in the triangle it names, whose normal and emission the estimators then read
    np.testing.assert_array_equal(pts.normal, geometry.normal[pts.triangle])
    np.testing.assert_array_equal(pts.pdf_area, 1.0 / sampler.area[0])


def test_a_quad_of_duplicated_vertices_is_one_parallelogram():
    # The shared corners are equal positions of distinct vertices (a mesh without shared indices), and the
    # parallelogram is skewed.
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.2, 0.1], [1.3, 1.0, 0.5]])
    v = np.vstack([v, v[0] + v[2] - v[1]])
    sampler = _one_light(np.vstack([v[[0, 1, 2]], v[[0, 2, 3]]]), [[0, 1, 2], [3, 4, 5]])
    assert _pieces(sampler) == [True]


def test_an_almost_parallelogram_within_the_tolerance_is_one_piece_and_beyond_it_two():
    edge = np.linalg.norm(SQUARE[1] - SQUARE[0])  # 1.5, the longest edge but the diagonal
    for shift, one_piece in ((1e-11, True), (1e-7, False)):
        v = SQUARE.copy()
        v[3, 0] += shift * edge  # in the plane: the normals stay equal
        assert _pieces(_one_light(v, [[0, 1, 2], [0, 2, 3]])) == ([True] if one_piece else [False, False])


def test_a_folded_pair_stays_two_triangles():
    v = SQUARE.copy()
    v[3, 2] += 0.05  # corner 3 out of the plane: the two halves no longer coplanar
    assert _pieces(_one_light(v, [[0, 1, 2], [0, 2, 3]])) == [False, False]


def test_a_planar_pair_that_is_no_parallelogram_stays_two_triangles():
    kite = np.array([[0.0, 0.0, 1.0], [1.0, -0.3, 1.0], [1.6, 0.0, 1.0], [1.0, 0.3, 1.0]])  # diagonal 0-2, not bisected
    assert _pieces(_one_light(kite, [[0, 1, 2], [0, 2, 3]])) == [False, False]
    # Two triangles sharing one corner only, and two sharing none.
    v = np.vstack([SQUARE, SQUARE[2] + [1.0, 0.0, 0.0], SQUARE[2] + [1.0, 1.0, 0.0]])
    assert _pieces(_one_light(v, [[0, 1, 2], [2, 4, 5]])) == [False, False]
    # A trapezoid: the two halves share the diagonal 1-2 but the far corners do not mirror each other.
    assert _pieces(_one_light(v, [[0, 1, 2], [1, 4, 2]])) == [False, False]
    assert _pieces(_one_light(np.vstack([SQUARE, SQUARE + [3.0, 0.0, 0.0]]), [[0, 1, 2], [4, 5, 6]])) == [False,
                                                                                                          False]


def test_a_quad_whose_halves_face_apart_stays_two_triangles():
    assert _pieces(_one_light(SQUARE, [[0, 1, 2], [0, 3, 2]])) == [False, False]  # the second half wound back


def test_a_quad_of_two_emissions_stays_two_triangles():
    assert _pieces(_one_light(SQUARE, [[0, 1, 2], [0, 2, 3]], [[1.0, 1.0, 1.0], [1.0, 1.0, 2.0]])) == [False, False]


def test_a_single_triangle_is_one_triangle_piece():
    sampler = _one_light(SQUARE, [[0, 1, 2]])
    assert _pieces(sampler) == [False]
    assert sampler.triangles.tolist() == [0] and sampler.other.tolist() == [0]
    np.testing.assert_array_equal(sampler.frames[0], [SQUARE[0], SQUARE[1] - SQUARE[0], SQUARE[2] - SQUARE[0]])


def test_a_light_of_four_triangles_stays_per_triangle():
    # A rectangle fanned from its centre, and two rectangles in one light (four triangles, two parallelograms).
    v = np.vstack([SQUARE, SQUARE.mean(axis=0)])
    sampler = _one_light(v, [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    assert _pieces(sampler) == [False] * 4
    np.testing.assert_allclose(sampler.within_cdf, [0.25, 0.5, 0.75, 1.0], rtol=1e-15)
    v = np.vstack([SQUARE, SQUARE + [3.0, 0.0, 0.0]])
    assert _pieces(_one_light(v, [[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])) == [False] * 4


def test_pieces_of_several_lights():
    """The fan (4 triangles), a rectangle and a triangle in one scene: entries in light order, each light's cdf."""
    lights = [(cases.fan_light(), (1.0, 1.0, 1.0)), (cases.rectangle_light(), (2.0, 1.0, 1.0)),
              (cases.four_lights()[0][0], (1.0, 1.0, 3.0))]
    geometry, local = cases.light_geometry(lights)
    sampler = LightSampler(geometry, "uniform")
    assert sampler.first.tolist() == [0, 4, 5] and sampler.count.tolist() == [4, 1, 1]
    assert sampler.parallelogram.tolist() == [False] * 4 + [True, False]
    assert np.all(geometry.light_id[sampler.triangles] == [0, 0, 0, 0, 1, 2])
    assert np.all(geometry.light_id[sampler.other] == [0, 0, 0, 0, 1, 2])
    assert sampler.triangles[4] != sampler.other[4]
    np.testing.assert_allclose(sampler.area, [light.area() for light, _ in lights], rtol=1e-12)


def test_triangle_pieces_keep_the_points_of_the_triangle_warp():
    """A light's triangles, as pieces, give the bits of the triangle warp c0 + b1 (c1 - c0) + b2 (c2 - c0)
    (lights._uniform_point_on, what every light used before parallelograms): scenes without such quads keep their
    images."""
    from reference_impl.lights import _uniform_point_on

    geometry, _ = cases.light_geometry(cases.four_lights()[:1] + [(cases.fan_light(), (1.0, 2.0, 3.0))])
    sampler = LightSampler(geometry, "power")
    assert not sampler.parallelogram.any()
    g = np.random.default_rng(5)
    u = [g.random(5000) for _ in range(4)]
    _, pts = sampler.sample(*u)
    np.testing.assert_array_equal(pts.position, _uniform_point_on(geometry, pts.triangle, u[2], u[3]))
