"""The canonical scenes' mesh files are what harness/scene/mesh_assets.py makes, byte for byte, and their normals are
what the scenes' descriptions say."""

from __future__ import annotations

import numpy as np
import pytest

from harness.scene import mesh_assets


@pytest.mark.parametrize("folder,name", [(mesh_assets.DEFAULT_FOLDER, n) for n in sorted(mesh_assets.MESHES)]
                         + [(mesh_assets.STRESS_FOLDER, n) for n in sorted(mesh_assets.STRESS_MESHES)])
def test_the_committed_mesh_is_the_generators(folder, name):
    make = {**mesh_assets.MESHES, **mesh_assets.STRESS_MESHES}[name]
    assert (folder / name).read_bytes() == make()


def test_the_generator_writes_them(tmp_path):
    assert mesh_assets.main([str(tmp_path)]) == 0
    for name, make in {**mesh_assets.MESHES, **mesh_assets.STRESS_MESHES}.items():
        assert (tmp_path / name).read_bytes() == make()


def test_the_egg_normals_are_the_analytic_ones():
    """The egg's file normals are the map's (the inverse transpose of its Jacobian): each is perpendicular to the
    surface's tangents, which finite differences along the unit sphere give."""
    vertices, _triangles, normals = mesh_assets._blob()
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    sphere, _ = mesh_assets.icosphere(2)

    def egg(p):
        k = 1.0 + 0.25 * p[0]
        return np.array([0.7 * p[0] * k, 0.55 * p[1] * k, 0.6 * p[2] * k])

    for p, n in zip(sphere[:40], normals[:40]):
        a = np.cross(p, [1.0, 0.0, 0.0] if abs(p[0]) < 0.9 else [0.0, 1.0, 0.0])
        for tangent in (a, np.cross(p, a)):
            h = 1e-6 * tangent / np.linalg.norm(tangent)
            assert abs(np.dot(egg(p + h) - egg(p - h), n)) < 1e-9
        assert np.dot(n, egg(p) - egg(np.zeros(3))) > 0  # outward
