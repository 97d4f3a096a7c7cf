"""Spheres in Mitsuba: analytic in Lambertian scenes (their ground truth unchanged), the reference's icosphere in
scenes with a glossy or glass material, where the facets show in every reflection (harness/renderers/mitsuba.py,
``tessellates_spheres``)."""

from __future__ import annotations

from conftest import SCENES

from harness.renderers.mitsuba import scene_to_mitsuba_dict
from harness.renderers.mitsuba_spec import tessellates_spheres
from harness.scene import load_scene
from harness.scene.triangulate import shape_triangles


def test_lambertian_spheres_stay_analytic():
    scene = load_scene(SCENES / "white-furnace.toml")
    assert not tessellates_spheres(scene)
    assert scene_to_mitsuba_dict(scene, "scalar_rgb")["shape_0"]["type"] == "sphere"


def test_glossy_scenes_get_the_reference_icosphere():
    scene = load_scene(SCENES / "white-furnace-mirror.toml")
    assert tessellates_spheres(scene)
    mesh = scene_to_mitsuba_dict(scene, "scalar_rgb")["shape_0"]
    vertices, triangles = shape_triangles(scene.shapes[0])
    assert mesh.face_count() == len(triangles) == 20 * 4**4 and mesh.vertex_count() == len(vertices)
