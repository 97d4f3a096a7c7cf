"""[camera] in the scene format (docs/scene-format.md, "[camera]"): the optional ``type`` (Mitsuba's sensor plugin:
``perspective``, the default, ``thinlens``, ``orthographic``), refused in one line when unknown, each type's keys and
their one-line refusals, and the camera registry (harness.scene.kinds.cameras.CAMERAS) as the Mitsuba spec, its XML
and scene.json use it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import MINIMAL_SCENE
from harness.core.errors import HarnessError
from harness.renderers.mitsuba_spec import scene_spec
from harness.renderers.scene_json import camera_json
from harness.scene import load_scene
from harness.scene.content_key import content_key
from harness.scene.variants import scaled
from harness.renderers.mitsuba_xml import spec_xml
from harness.scene.kinds.cameras import ALL_CAMERA_KEYS, CAMERA_KEYS, CAMERAS, camera_kind
from reference_impl.camera import OrthographicCamera, ThinLensCamera

TYPED = MINIMAL_SCENE.replace("fov = 40", 'fov = 40\ntype = "perspective"')


def write(folder: Path, text: str, name: str = "scene.toml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def test_the_type_perspective_is_the_default(tmp_path):
    plain = load_scene(write(tmp_path, MINIMAL_SCENE, "plain.toml"))
    typed = load_scene(write(tmp_path, TYPED, "typed.toml"))
    assert typed.camera == plain.camera
    assert camera_kind(typed.camera) is CAMERAS["perspective"]
    assert scene_spec(typed).plugins["sensor"] == scene_spec(plain).plugins["sensor"]
    assert camera_json(typed) == camera_json(plain)
    # the key of the loaded scene differs by the scene file's bytes alone
    assert content_key(typed) != content_key(plain)


@pytest.mark.parametrize("value", ['"fisheye"', '"spherical"', "3", '["perspective"]'])
def test_an_unknown_type_is_one_line_naming_the_file_the_key_and_the_types(tmp_path, value):
    path = write(tmp_path, MINIMAL_SCENE.replace("fov = 40", f"fov = 40\ntype = {value}"))
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert str(info.value) == (f"{path}: camera.type: expected one of perspective, thinlens, orthographic, "
                               f"got {value}")


def test_a_near_miss_of_a_type_gets_a_hint(tmp_path):
    path = write(tmp_path, MINIMAL_SCENE.replace("fov = 40", 'fov = 40\ntype = "Perspective"'))
    with pytest.raises(HarnessError, match="did you mean 'perspective'") as info:
        load_scene(path)
    assert "\n" not in str(info.value)


def test_an_unknown_key_lists_the_type_among_the_keys(tmp_path):
    path = write(tmp_path, MINIMAL_SCENE.replace("fov = 40", "fov = 40\nzoom = 2"))
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert str(info.value) == (f"{path}: camera.zoom: unknown key 'zoom'; expected one of: origin, target, up, fov, "
                               "fov_axis, aperture_radius, focus_distance, scale, type, medium")


def test_every_entry_holds_its_plugin_and_its_scene_json_entry(tmp_path):
    scene = load_scene(write(tmp_path, MINIMAL_SCENE))
    assert set(ALL_CAMERA_KEYS) == set(CAMERA_KEYS).union(*(kind.keys for kind in CAMERAS.values()))
    for name, kind in CAMERAS.items():
        assert kind.name == name
        assert not set(kind.keys) & set(CAMERA_KEYS)
    sensor = scene_spec(scene).plugins["sensor"]
    kind = camera_kind(scene.camera)
    assert sensor["type"] == kind.name == camera_json(scene)["type"]
    assert {"fov": 40.0, "fov_axis": "x"}.items() <= sensor.items()
    assert {"near_clip", "far_clip", "to_world", "sampler", "film"} <= set(sensor)


LENS = MINIMAL_SCENE.replace("fov = 40", 'fov = 40\ntype = "thinlens"\naperture_radius = 0.2\nfocus_distance = 4.5')
ORTHO = MINIMAL_SCENE.replace("fov = 40", 'type = "orthographic"\nscale = [2.0, 3.0, 1.0]')


def test_a_thin_lens_is_read_with_mitsubas_keys_and_defaults(tmp_path):
    scene = load_scene(write(tmp_path, LENS))
    assert isinstance(scene.camera, ThinLensCamera)
    assert (scene.camera.aperture_radius, scene.camera.focus_distance, scene.camera.fov) == (0.2, 4.5, 40.0)
    default = load_scene(write(tmp_path, LENS.replace("focus_distance = 4.5", ""), "default.toml"))
    assert default.camera.focus_distance == 1e4  # Mitsuba 3.9.1's default: its default far_clip
    sensor = scene_spec(scene).plugins["sensor"]
    assert sensor["type"] == "thinlens" and sensor["aperture_radius"] == 0.2 and sensor["focus_distance"] == 4.5
    entry = camera_json(scene)
    assert entry["type"] == "thinlens" and entry["aperture_radius"] == 0.2 and entry["focus_distance"] == 4.5
    assert entry["fov_x"] == pytest.approx(40.0)


def test_an_orthographic_camera_takes_its_extent_from_its_scale(tmp_path):
    scene = load_scene(write(tmp_path, ORTHO))
    assert isinstance(scene.camera, OrthographicCamera) and scene.camera.scale == (2.0, 3.0, 1.0)
    assert load_scene(write(tmp_path, ORTHO.replace("scale = [2.0, 3.0, 1.0]", "scale = 1.5"), "one.toml")
                      ).camera.scale == (1.5, 1.5, 1.5)
    sensor = scene_spec(scene).plugins["sensor"]
    assert sensor["type"] == "orthographic" and sensor["to_world"].scale == (2.0, 3.0, 1.0)
    assert "fov" not in sensor
    entry = camera_json(scene)
    assert entry["scale"] == [2.0, 3.0, 1.0] and entry["half_width"] == 2.0 and entry["half_height"] == 3.0
    xml = spec_xml(scene_spec(scene), "")[0]
    assert '<scale value="2.0, 3.0, 1.0"/>' in xml and xml.index("<scale") < xml.index("<lookat")


@pytest.mark.parametrize("text, line", [
    (LENS.replace("aperture_radius = 0.2\n", ""),
     "camera.aperture_radius: missing required key 'aperture_radius' (a number >= 0 (scene units))"),
    (LENS.replace("aperture_radius = 0.2", "aperture_radius = -1"),
     "camera.aperture_radius: expected a finite number >= 0, got -1.0"),
    (LENS.replace("focus_distance = 4.5", 'focus_distance = "far"'),
     "camera.focus_distance: expected a finite number > 0 (scene units), got \"far\""),
    (LENS.replace("focus_distance = 4.5", "focus_distance = 0"),
     "camera.focus_distance: expected a finite number > 0, got 0.0"),
    (ORTHO.replace("scale = [2.0, 3.0, 1.0]", "scale = [2.0, 0.0, 1.0]"),
     "camera.scale: expected three finite factors > 0, got (2.0, 0.0, 1.0)"),
    (ORTHO.replace("scale = [2.0, 3.0, 1.0]", "scale = [2.0, 3.0]"),
     "camera.scale: expected a finite number or a list of 3 finite numbers, got [2.0, 3.0]"),
    (ORTHO + "", None),
    (ORTHO.replace('type = "orthographic"', 'type = "orthographic"\nfov = 30'),
     "camera.fov: key 'fov' applies only to cameras of type 'perspective' or 'thinlens', not 'orthographic'"),
    (MINIMAL_SCENE.replace("fov = 40", "fov = 40\nscale = 2"),
     "camera.scale: key 'scale' applies only to cameras of type 'orthographic', not 'perspective'"),
    (MINIMAL_SCENE.replace("fov = 40", "fov = 40\naperture_radius = 0.1"),
     "camera.aperture_radius: key 'aperture_radius' applies only to cameras of type 'thinlens', not 'perspective'"),
])
def test_a_bad_thin_lens_or_orthographic_key_is_one_line(tmp_path, text, line):
    path = write(tmp_path, text)
    if line is None:
        load_scene(path)
        return
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert str(info.value) == f"{path}: {line}"


@pytest.mark.parametrize("text", [LENS, ORTHO], ids=["thinlens", "orthographic"])
def test_a_scene_scaled_by_the_stress_suite_keeps_its_image(tmp_path, text):
    """The stress suite's ``scale`` variant scales a lens's aperture and focus and an orthographic film's extent with
    the scene, so every ray is the scaled ray: the same directions from scaled origins."""
    scene = load_scene(write(tmp_path, text))
    big = scaled(scene, 3.0)
    fx, fy = np.array([0.5, 7.25, 16.0]), np.array([0.0, 9.5, 16.0])
    lens = (np.array([0.1, 0.5, 0.9]), np.array([0.7, 0.2, 0.5]))
    origins, directions = scene.camera.generate_rays(fx, fy, 16, 16, lens=lens)
    big_origins, big_directions = big.camera.generate_rays(fx, fy, 16, 16, lens=lens)
    np.testing.assert_allclose(big_origins, 3.0 * origins, atol=1e-12)
    np.testing.assert_allclose(big_directions, directions, atol=1e-12)
