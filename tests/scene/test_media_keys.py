"""Participating media in the scene format (issue 38; docs/scene-format.md, "Participating media"): ``[media.NAME]``
with Mitsuba's ``homogeneous`` keys and defaults, shapes' ``interior`` / ``exterior``, the camera's ``medium``, the
``null`` material; the core's media table (one entry per triangle), the content key, scene.json, the Mitsuba spec
(``volpath``) and the one-line refusals through ``harness export``."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from conftest import MINIMAL_SCENE, SCENES
from harness.cli import main
from harness.renderers.export import export_losses
from harness.renderers.mitsuba_spec import scene_spec
from harness.renderers.scene_json import scene_json
from harness.scene import load_scene, material_arrays, media_arrays, triangulate
from harness.scene.content_key import content_key
from harness.scene.variants import scaled
from reference_impl import materials as core_materials
from reference_impl import media as core_media

SLAB_SHAPE = """
[materials.boundary]
type = "null"

[[shapes]]
name = "slab"
type = "cube"
material = "boundary"
"""


def write(folder, body: str, name: str = "scene.toml"):
    path = folder / name
    path.write_text(MINIMAL_SCENE + body)
    return path


def media_scene(folder, media: str, shape_keys: str = 'interior = "fog"', camera: str = ""):
    """A minimal scene (its camera's table last but one: ``camera`` goes into it) with ``media`` and a null cube."""
    text = MINIMAL_SCENE.replace('fov = 40\n', f'fov = 40\n{camera}\n') + media + SLAB_SHAPE + shape_keys + "\n"
    path = folder / "scene.toml"
    path.write_text(text)
    return path


def test_the_defaults_are_mitsubas(tmp_path):
    scene = load_scene(media_scene(tmp_path, "[media.fog]\n"))
    fog = scene.media["fog"]
    assert fog.type == "homogeneous"
    assert fog.albedo == core_media.DEFAULT_ALBEDO == (0.75, 0.75, 0.75)
    assert fog.sigma_t == (1.0, 1.0, 1.0) and fog.scale == 1.0
    assert fog.phase == "isotropic" and fog.g == 0.0
    assert scene.shapes[0].interior == "fog" and scene.shapes[0].exterior is None
    assert scene.camera_medium is None and scene.has_media


def test_the_canonical_scenes(tmp_path):
    slab = load_scene(SCENES / "media-slab.toml")
    assert slab.media["absorber"].albedo == (0.0, 0.0, 0.0) and slab.media["absorber"].sigma_t == (1.0, 1.0, 1.0)
    assert slab.materials["boundary"].type == "null" and slab.shapes[0].interior == "absorber"
    assert (slab.film.width, slab.film.height) == (32, 32)
    fog = load_scene(SCENES / "fog-box.toml")
    assert fog.camera_medium == "fog" and not any(s.is_medium_transition for s in fog.shapes)
    medium = fog.media["fog"]
    assert medium.albedo == (0.8, 0.8, 0.8) and medium.phase == "isotropic"
    # the back wall, 4.9 from the eye along the axis, at a transmittance of about 0.4
    assert math.exp(-medium.sigma_t[0] * 4.9) == pytest.approx(0.4, abs=0.005)
    cornell = load_scene(SCENES / "cornell-box.toml")
    assert [s.name for s in fog.shapes] == [s.name for s in cornell.shapes]
    assert all(np.array_equal(a.to_world, b.to_world) for a, b in zip(fog.shapes, cornell.shapes))


def test_colours_scale_and_hg(tmp_path):
    scene = load_scene(media_scene(tmp_path, """
[media.fog]
sigma_t = [1.0, 0.5, 0.25]
albedo = [0.9, 0.8, 0.7]
scale = 2.0
phase = { type = "hg", g = 0.3 }
""", 'interior = "fog"\nexterior = "fog"', camera='medium = "fog"'))
    fog = scene.media["fog"]
    assert fog.extinction == (2.0, 1.0, 0.5) and fog.phase == "hg" and fog.g == 0.3
    assert scene.camera_medium == "fog"
    media = media_arrays(scene, triangulate(scene))
    np.testing.assert_array_equal(media.sigma_t, [[2.0, 1.0, 0.5]])
    np.testing.assert_array_equal(media.albedo, [[0.9, 0.8, 0.7]])
    assert list(media.phase) == [core_media.HG] and list(media.g) == [0.3] and media.camera == 0


def test_one_entry_per_triangle_spheres_included(tmp_path):
    """The transitions follow triangulate()'s triangles: a sphere's stand-in triangles carry its media."""
    path = media_scene(tmp_path, "[media.a]\n[media.b]\nalbedo = 0.5\n", 'interior = "a"\n' + """
[[shapes]]
name = "ball"
type = "sphere"
radius = 0.5
subdivisions = 1
material = "boundary"
exterior = "b"

[[shapes]]
name = "floor"
type = "rectangle"
material = "white"
""")
    scene = load_scene(path)
    geometry = triangulate(scene)
    media = media_arrays(scene, geometry)
    assert len(media.interior) == len(geometry.triangles) == 12 + 80 + 2
    assert list(media.interior[:12]) == [0] * 12 and list(media.exterior[:12]) == [-1] * 12
    assert list(media.exterior[12:92]) == [1] * 80 and list(media.interior[12:92]) == [-1] * 80
    assert list(media.transition) == [True] * 92 + [False] * 2
    assert media.names == ("a", "b") and media.camera == -1


def test_no_media_no_table(tmp_path):
    scene = load_scene(write(tmp_path, SLAB_SHAPE))
    assert media_arrays(scene) is None and not scene.media and scene.has_media  # a null material alone


def test_the_null_material_row(tmp_path):
    scene = load_scene(write(tmp_path, SLAB_SHAPE))
    table = material_arrays(scene)
    assert list(table.kind) == [core_materials.DIFFUSE, core_materials.NULL]
    assert not np.any(table.params[1])


@pytest.mark.parametrize("change", [
    lambda text: text.replace("g = 0.3", "g = 0.31"),
    lambda text: text.replace("scale = 2.0", "scale = 2.5"),
    lambda text: text.replace('interior = "fog"', 'exterior = "fog"'),
    lambda text: text.replace('medium = "fog"', ""),
])
def test_the_content_key_covers_the_media(tmp_path, change):
    path = media_scene(tmp_path, '[media.fog]\nscale = 2.0\nphase = { type = "hg", g = 0.3 }\n',
                       camera='medium = "fog"')
    before = load_scene(path)
    other = tmp_path / "other"
    other.mkdir()
    changed = other / "scene.toml"
    changed.write_text(change(path.read_text()))
    assert changed.read_text() != path.read_text()
    after = load_scene(changed)
    assert content_key(before) != content_key(after)
    # and through the model alone, not the file's bytes: g is walked as a field
    assert content_key(before.media) != content_key({"fog": dataclasses.replace(before.media["fog"], g=0.31)})


def test_scene_json_entries(tmp_path):
    scene = load_scene(media_scene(tmp_path, '[media.fog]\nscale = 2.0\nalbedo = 0.5\nphase = { type = "hg", g = 0.3 }\n',
                                   camera='medium = "fog"'))
    document, _ = scene_json(scene)
    assert document["media"] == {"fog": {"type": "homogeneous", "sigma_t": [2.0, 2.0, 2.0],
                                         "albedo": [0.5, 0.5, 0.5], "phase": {"type": "hg", "g": 0.3}}}
    assert document["camera"]["medium"] == "fog"
    assert (document["shapes"][0]["interior"], document["shapes"][0]["exterior"]) == ("fog", None)
    assert document["materials"]["boundary"] == {"type": "null"}
    plain, _ = scene_json(load_scene(SCENES / "cornell-box.toml"))
    assert "media" not in plain and plain["camera"]["medium"] is None
    assert all(s["interior"] is None and s["exterior"] is None for s in plain["shapes"])


def test_the_mitsuba_spec(tmp_path):
    scene = load_scene(media_scene(tmp_path, '[media.fog]\nsigma_t = [1.0, 0.5, 0.25]\nscale = 2.0\n'
                                   'phase = { type = "hg", g = -0.4 }\n', 'interior = "fog"', camera='medium = "fog"'))
    plugins = scene_spec(scene).plugins
    assert plugins["integrator"] == {"type": "volpath", "max_depth": -1, "rr_depth": 5}
    assert plugins["medium_0"] == {"type": "homogeneous", "albedo": {"type": "rgb", "value": [0.75, 0.75, 0.75]},
                                   "sigma_t": {"type": "rgb", "value": [1.0, 0.5, 0.25]}, "scale": 2.0,
                                   "phase": {"type": "hg", "g": -0.4}}
    assert list(plugins).index("medium_0") < list(plugins).index("sensor")  # defined before it is named
    assert plugins["sensor"]["medium"] == {"type": "ref", "id": "medium_0"}
    assert plugins["shape_0"]["interior"] == {"type": "ref", "id": "medium_0"} and "exterior" not in plugins["shape_0"]
    assert plugins["bsdf_1"] == {"type": "null"}
    # a null material alone is volumetric too; a scene with neither keeps path
    assert scene_spec(load_scene(write(tmp_path, SLAB_SHAPE, "null.toml"))).plugins["integrator"]["type"] == "volpath"
    assert scene_spec(load_scene(SCENES / "cornell-box.toml")).plugins["integrator"] == {
        "type": "path", "max_depth": 8, "rr_depth": 5}


def test_exports_that_have_no_media_say_so(tmp_path):
    scene = load_scene(media_scene(tmp_path, "[media.fog]\n"))
    for fmt in ("ply", "obj", "gltf"):
        assert f"{fmt} has no participating media: left out media fog (homogeneous)" in export_losses(scene, fmt)
    assert any("index-matched" in line and "boundary (null)" in line for line in export_losses(scene, "gltf"))
    assert export_losses(scene, "json") == [] and export_losses(scene, "mitsuba-xml") == []


def test_a_scaled_variant_keeps_the_optical_depth(tmp_path):
    scene = load_scene(media_scene(tmp_path, "[media.fog]\nscale = 2.0\n"))
    assert scaled(scene, 4.0).media["fog"].scale == pytest.approx(0.5, rel=1e-12)


# ---- one-line refusals through the CLI ----------------------------------------------------------------------------


@pytest.mark.parametrize("media, shape_keys, camera, key, fragment", [
    ("[media.fog]\n", 'interior = "fgo"', "", "shapes[0].interior",
     "unknown medium 'fgo'; did you mean 'fog'? (defined in [media]: 'fog')"),
    ("[media.fog]\n", 'exterior = "smoke"', "", "shapes[0].exterior", "unknown medium 'smoke'"),
    ("", 'interior = "fog"', "", "shapes[0].interior", "(defined in [media]: none)"),
    ("[media.fog]\n", "", 'medium = "fogg"', "camera.medium", "did you mean 'fog'?"),
    ("[media.fog]\n", "", "medium = 3", "camera.medium", "expected a string, got 3"),
    ('[media.fog]\nphase = { type = "hg", g = 1 }\n', "", "", "media.fog.phase.g",
     "expected a number in (-1, 1) (g > 0 scatters forward), got 1"),
    ('[media.fog]\nphase = { type = "hg", g = -1.0 }\n', "", "", "media.fog.phase.g", "got -1.0"),
    ("[media.fog]\nsigma_t = [1.0, -0.5, 1.0]\n", "", "", "media.fog.sigma_t", "each >= 0 and finite"),
    ("[media.fog]\nsigma_t = -1\n", "", "", "media.fog.sigma_t", "got -1"),
    ("[media.fog]\nsigma_t = inf\n", "", "", "media.fog.sigma_t", "got inf"),
    ("[media.fog]\nsigma_t = 1e7\nscale = 100.0\n", "", "", "media.fog.sigma_t", "expected at most 1e+08"),
    ("[media.fog]\nalbedo = 1.5\n", "", "", "media.fog.albedo", "each in [0, 1], got 1.5"),
    ("[media.fog]\nalbedo = [0.5, 0.5]\n", "", "", "media.fog.albedo", "got [0.5, 0.5]"),
    ("[media.fog]\nscale = 0\n", "", "", "media.fog.scale", "expected a positive number"),
    ('[media.fog]\nphase = { type = "rayleigh" }\n', "", "", "media.fog.phase.type",
     "expected one of isotropic, hg, got \"rayleigh\""),
    ('[media.fog]\nphase = { type = "isotropic", g = 0.5 }\n', "", "", "media.fog.phase.g", "unknown key"),
    ('[media.fog]\ntype = "heterogeneous"\n', "", "", "media.fog.type",
     "medium type 'heterogeneous' is not supported yet"),
    ('[media.fog]\ntype = "homogenous"\n', "", "", "media.fog.type", "did you mean 'homogeneous'?"),
    ("[media.fog]\nsigma_s = 1.0\n", "", "", "media.fog.sigma_s", "unknown key"),
])
def test_bad_media_are_one_line_errors_of_export(tmp_path, capfd, media, shape_keys, camera, key, fragment):
    path = media_scene(tmp_path, media, shape_keys, camera)
    out = tmp_path / "out"
    code = main(["export", str(path), "--format", "json", "--out", str(out)])
    stdout, stderr = capfd.readouterr()
    assert code == 2 and stdout == "" and len(stderr.splitlines()) == 1, (code, stdout, stderr)
    assert stderr.startswith(f"harness: error: {path}: {key}: "), stderr
    assert fragment in stderr, stderr
    assert not out.exists()


def test_the_null_material_takes_no_keys(tmp_path, capfd):
    path = write(tmp_path, SLAB_SHAPE.replace('type = "null"', 'type = "null"\nreflectance = [0.5, 0.5, 0.5]'))
    code = main(["export", str(path), "--format", "json", "--out", str(tmp_path / "out")])
    _, stderr = capfd.readouterr()
    assert code == 2 and f"{path}: materials.boundary.reflectance: key 'reflectance' applies only to materials " \
                          "of type 'diffuse', not 'null'" in stderr, stderr
