"""harness.scene.triangulate's icosphere against trimesh.creation.icosphere, which the harness used before (trimesh
stays installed: meshes are read with it): the same vertex and face arrays, bit for bit, at every level a scene may
ask for, so that every image stays bit-identical (tests/reference_impl/test_image_checksums.py)."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import trimesh

import harness.scene.triangulate  # noqa: F401  (the package's ``triangulate`` function hides the module's name)
from harness.scene.load import MAX_SUBDIVISIONS

triangulate = sys.modules["harness.scene.triangulate"]


@pytest.mark.parametrize("level", range(MAX_SUBDIVISIONS + 1))
def test_icosphere_is_trimeshs_bit_for_bit(level):
    vertices, triangles = triangulate.icosphere(level)
    theirs = trimesh.creation.icosphere(subdivisions=level, radius=1.0)
    assert vertices.dtype == np.float64 and triangles.dtype == np.int64
    assert np.array_equal(vertices, np.asarray(theirs.vertices, dtype=np.float64))
    assert np.array_equal(triangles, np.asarray(theirs.faces, dtype=np.int64))
    assert vertices.tobytes() == np.ascontiguousarray(theirs.vertices, dtype=np.float64).tobytes()  # -0.0 too


def test_unit_sphere_is_the_icosphere_divided_by_its_norms():
    vertices, triangles = triangulate.unit_sphere(4)
    raw, raw_triangles = triangulate.icosphere(4)
    assert np.array_equal(vertices, raw / np.linalg.norm(raw, axis=1, keepdims=True))
    assert np.array_equal(triangles, raw_triangles)
    assert not vertices.flags.writeable and not triangles.flags.writeable
    assert np.allclose(np.linalg.norm(vertices, axis=1), 1.0, rtol=0, atol=4e-16)


@pytest.mark.parametrize("level", [0, 1, 3])
def test_icosphere_is_a_closed_outward_sphere(level):
    """Counts (Euler: V - E + F = 2), every edge in two triangles in opposite directions, outward winding."""
    vertices, triangles = triangulate.unit_sphere(level)
    assert len(triangles) == 20 * 4**level and len(vertices) == 10 * 4**level + 2
    directed = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert len({tuple(e) for e in directed.tolist()}) == len(directed)  # no directed edge twice
    assert {tuple(e) for e in directed.tolist()} == {tuple(e) for e in directed[:, ::-1].tolist()}  # each reversed
    v0, v1, v2 = (vertices[triangles[:, k]] for k in range(3))
    assert (np.einsum("ij,ij->i", np.cross(v1 - v0, v2 - v0), v0 + v1 + v2) > 0).all()
