"""[camera] in the scene format (docs/scene-format.md, "[camera]"): the optional ``type`` (Mitsuba's sensor plugin,
``perspective`` the default and the only one), refused in one line when unknown, and the camera registry
(harness.scene.kinds.cameras.CAMERAS) as the Mitsuba spec and scene.json use it."""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import MINIMAL_SCENE
from harness.core.errors import HarnessError
from harness.renderers.mitsuba_spec import scene_spec
from harness.renderers.scene_json import camera_json
from harness.scene import load_scene
from harness.scene.content_key import content_key
from harness.scene.kinds.cameras import ALL_CAMERA_KEYS, CAMERA_KEYS, CAMERAS, camera_kind

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


@pytest.mark.parametrize("value", ['"thinlens"', '"orthographic"', "3", '["perspective"]'])
def test_an_unknown_type_is_one_line_naming_the_file_the_key_and_the_types(tmp_path, value):
    path = write(tmp_path, MINIMAL_SCENE.replace("fov = 40", f"fov = 40\ntype = {value}"))
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert str(info.value) == f"{path}: camera.type: expected one of perspective, got {value}"


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
                               "fov_axis, type")


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
