"""The ground-truth cache key (harness.renderers.groundtruth.scene_digest) holds every field of every material type
(issue 15), and the key of a Lambertian scene is pinned, so that no change of the code makes every cache entry a
miss unnoticed."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from conftest import MINIMAL_SCENE
from harness.renderers.groundtruth import scene_digest
from harness.scene import load_scene

LAMBERTIAN = MINIMAL_SCENE + """
[materials.grey]
reflectance = [0.25, 0.5, 0.75]
two_sided = true

[[shapes]]
type = "sphere"
material = "white"
radius = 0.5

[[shapes]]
type = "rectangle"
material = "grey"
emission = [1, 2, 3]
translate = [0, 0, -1]
"""
# scene_digest of LAMBERTIAN, the scene's content key (harness.scene.content_key); a change of it makes every cached
# ground truth a miss, so it changes only with the key's format (harness.renderers.groundtruth.FORMAT_VERSION; 6 since
# the materials grew the composites', roughplastic's and principled's fields)
LAMBERTIAN_DIGEST = "11075a576d410d965d32a543ef1a519894c18e14b9b247b74490ac65da9bda4d"


def test_the_key_of_a_lambertian_scene_is_pinned(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(LAMBERTIAN)
    assert scene_digest(load_scene(path)) == LAMBERTIAN_DIGEST


GLOSSY = MINIMAL_SCENE + """
[materials.m]
{body}

[[shapes]]
type = "sphere"
material = "m"
radius = 0.5
"""
BODIES = {
    "roughconductor": 'type = "roughconductor"\neta = [0.2, 0.9, 1.1]\nk = [3.9, 2.4, 2.1]\nalpha = 0.3',
    "roughdielectric": 'type = "roughdielectric"\nalpha = 0.3\nspecular_transmittance = 0.5',
    "plastic": 'type = "plastic"\ndiffuse_reflectance = 0.4',
    "roughplastic": 'type = "roughplastic"\ndiffuse_reflectance = 0.4',
}
# every field a material type reads, and a value other than the one in BODIES
CHANGES = {
    "roughconductor": {"alpha": 0.31, "eta": (0.2, 0.9, 1.2), "k": (3.9, 2.5, 2.1), "distribution": "ggx",
                       "sample_visible": False, "specular_reflectance": (1.0, 1.0, 0.9), "two_sided": True,
                       "type": "conductor"},
    "roughdielectric": {"alpha": 0.29, "int_ior": 1.33, "ext_ior": 1.1, "specular_transmittance": (0.5, 0.5, 0.4),
                        "specular_reflectance": (0.9, 1.0, 1.0), "distribution": "ggx", "sample_visible": False,
                        "type": "dielectric"},
    "plastic": {"diffuse_reflectance": (0.4, 0.4, 0.5), "nonlinear": True, "int_ior": 1.5, "ext_ior": 1.1,
                "specular_reflectance": (0.9, 1.0, 1.0), "two_sided": True, "type": "thindielectric"},
    "roughplastic": {"diffuse_reflectance": (0.4, 0.4, 0.5), "nonlinear": True, "int_ior": 1.5, "ext_ior": 1.1,
                     "specular_reflectance": (0.9, 1.0, 1.0), "two_sided": True, "alpha": 0.2,
                     "distribution": "ggx", "sample_visible": False, "type": "plastic"},
}


def test_every_principled_field_is_in_the_key(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(GLOSSY.format(body='type = "principled"'))
    scene = load_scene(path)
    material = scene.materials["m"]
    digests = {scene_digest(scene)}
    fields = dataclasses.fields(material.principled)
    for field in fields:
        value = getattr(material.principled, field.name)
        value = (0.4, 0.5, 0.6) if field.name == "base_color" else value + 0.125
        changed = dataclasses.replace(material, principled=dataclasses.replace(material.principled,
                                                                               **{field.name: value}))
        digests.add(scene_digest(dataclasses.replace(scene, materials={"m": changed})))
    assert len(digests) == 1 + len(fields) == 16


@pytest.mark.parametrize("kind", list(BODIES))
def test_every_material_field_is_in_the_key(tmp_path, kind):
    path = tmp_path / "scene.toml"
    path.write_text(GLOSSY.format(body=BODIES[kind]))
    scene = load_scene(path)
    digests = {scene_digest(scene)}
    for field, value in CHANGES[kind].items():
        changed = dataclasses.replace(scene.materials["m"], **{field: value})
        digests.add(scene_digest(dataclasses.replace(scene, materials={"m": changed})))
    assert len(digests) == 1 + len(CHANGES[kind])


def test_scenes_differing_only_in_alpha_get_different_keys(tmp_path):
    """Through the files, as a user changes a scene: only alpha differs."""
    keys = []
    for alpha in (0.3, 0.30000000000000004):
        path = tmp_path / f"{alpha!r}" / "scene.toml"
        path.parent.mkdir()
        path.write_text(GLOSSY.format(body=BODIES["roughconductor"]).replace("alpha = 0.3", f"alpha = {alpha!r}"))
        keys.append(scene_digest(load_scene(path)))
    assert keys[0] != keys[1]
    # the same content in memory, the file the same: only the loaded alpha differs
    scene = load_scene(path)
    other = dataclasses.replace(scene, materials={"m": dataclasses.replace(scene.materials["m"], alpha=0.3)})
    assert scene_digest(other) != scene_digest(scene)
