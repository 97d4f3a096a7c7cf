"""Spheres in Mitsuba: analytic in every scene, the sphere the reference traces too (reference_impl/intersect.py),
so a mirror or glass ball shows no facets in either; the icosphere of ``subdivisions`` is only what the exports
and Cycles get, with the sphere's normals at its vertices where its material is not diffuse
(harness.scene.triangulate.exported_normals)."""

from __future__ import annotations

import numpy as np
from conftest import SCENES

from harness.renderers.mitsuba import scene_to_mitsuba_dict
from harness.scene import load_scene
from harness.scene.triangulate import exported_normals, shape_triangles, triangulate


def test_lambertian_spheres_stay_analytic():
    scene = load_scene(SCENES / "white-furnace.toml")
    assert scene_to_mitsuba_dict(scene, "scalar_rgb")["shape_0"]["type"] == "sphere"


def test_glossy_scenes_keep_analytic_spheres():
    scene = load_scene(SCENES / "white-furnace-mirror.toml")
    assert scene_to_mitsuba_dict(scene, "scalar_rgb")["shape_0"]["type"] == "sphere"


def test_the_core_knows_each_sphere():
    scene = load_scene(SCENES / "cornell-box-specular.toml")
    geometry = triangulate(scene)
    spheres = [s for s in scene.shapes if s.type == "sphere"]
    assert geometry.num_spheres == len(spheres) == 2
    for k, shape in enumerate(spheres):
        np.testing.assert_allclose(geometry.sphere_center[k], shape.center, rtol=0, atol=1e-15)
        assert abs(geometry.sphere_radius[k] - shape.radius) <= 1e-14 * shape.radius
        assert not geometry.sphere_inward[k]
    furnace = triangulate(load_scene(SCENES / "furnace.toml"))  # flip_normals: the inside is the front
    assert furnace.sphere_inward.tolist() == [True]


def test_exported_sphere_normals_are_the_spheres_where_its_material_is_not_diffuse():
    scene = load_scene(SCENES / "white-furnace-mirror.toml")
    shape = scene.shapes[0]
    vertices, triangles = shape_triangles(shape)
    normals = exported_normals(scene, shape, vertices, triangles)
    np.testing.assert_allclose(normals, vertices / np.linalg.norm(vertices, axis=1, keepdims=True), atol=1e-15)
    furnace = load_scene(SCENES / "furnace.toml")
    assert exported_normals(furnace, furnace.shapes[0], *shape_triangles(furnace.shapes[0])) is None  # a light: flat
    diffuse = load_scene(SCENES / "white-furnace.toml")
    assert exported_normals(diffuse, diffuse.shapes[0], *shape_triangles(diffuse.shapes[0])) is None  # flat
