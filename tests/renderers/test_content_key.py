"""The ground-truth key (harness.renderers.groundtruth.scene_digest, the scene's content key of
harness.scene.content_key) is derived from the scene, not listed: a change planted in every field of every scene
dataclass (found with dataclasses.fields, so a field added later is covered without a line here) changes it, but
for the fields it excludes on purpose; so does a change of the bytes of every file the loader read, of any kind, and
a field added to the camera. The resume digest of ``harness run`` holds the same key."""

from __future__ import annotations

import copy
import dataclasses
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from harness.core.errors import HarnessError
from harness.renderers.groundtruth import scene_digest
from harness.running import judge, runstate
from harness.running.cases import Case
from harness.scene import load_scene
from harness.scene import load as scene_load
from harness.scene.model import EMITTER_TYPES, MATERIAL_TYPES, SHAPE_TYPES
from reference_impl.camera import Camera

SKY = Path(__file__).resolve().parents[2] / "scenes" / "textures" / "sky.exr"
PLY = b"""ply
format ascii 1.0
element vertex 3
property float x
property float y
property float z
element face 1
property list uchar int vertex_indices
end_header
0 0 0
1 0 0
0 1 0
3 0 1 2
"""
OBJ = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
# one of every material type and every shape type (a mesh from a PLY and one from an OBJ), regions, a filter and
# fov_axis other than their defaults; the emitters are added by EMITTERS (one environment per scene)
SCENE = """name = "every-kind"
description = "one of each material, shape and emitter type"
regions = ["ball"]

[camera]
origin = [0, 0, 5]
target = [0, 0, 0]
up = [0, 1, 0]
fov = 40
fov_axis = "y"
medium = "air"

[film]
width = 16
height = 12
filter = "tent"

[integrator]
max_depth = 5

[materials.white]
reflectance = [0.8, 0.8, 0.8]
two_sided = true

[materials.mirror]
type = "conductor"

[materials.copper]
type = "roughconductor"
eta = [0.2, 0.9, 1.1]
k = [3.9, 2.4, 2.1]
alpha = 0.3

[materials.glass]
type = "dielectric"

[materials.frosted]
type = "roughdielectric"
alpha = 0.2
distribution = "ggx"

[materials.pane]
type = "thindielectric"

[materials.coat]
type = "plastic"
nonlinear = true

[materials.satin]
type = "roughplastic"
alpha = 0.3
[materials.burley]
type = "principled"
clearcoat = 0.5

[materials.boundary]
type = "null"

[media.air]
sigma_t = 0.01

[media.smoke]
sigma_t = [1.0, 0.5, 0.25]
albedo = 0.9
scale = 2.0
phase = { type = "hg", g = 0.3 }

[[shapes]]
name = "floor"
type = "rectangle"
material = "white"
translate = [0, -1, 0]
rotate = { axis = [1, 0, 0], angle = -90 }
scale = 3

[[shapes]]
name = "box"
type = "cube"
material = "mirror"
translate = [1, 0, 0]
scale = 0.3
interior = "smoke"
exterior = "air"

[[shapes]]
name = "ball"
type = "sphere"
material = "glass"
center = [-1, 0, 0]
radius = 0.4
subdivisions = 2

[[shapes]]
name = "lamp"
type = "rectangle"
material = "white"
emission = [1, 2, 3]
translate = [0, 2, 0]
rotate = { axis = [1, 0, 0], angle = 90 }
flip_normals = true

[[shapes]]
name = "ply"
type = "mesh"
material = "copper"
file = "meshes/triangle.ply"

[[shapes]]
name = "obj"
type = "mesh"
material = "frosted"
file = "meshes/triangle.obj"
translate = [0, 0, 1]
"""
EMITTERS = {
    "envmap": [
        'type = "point"\nposition = [0.3, 1, -0.2]\nintensity = [2, 3, 4]',
        'type = "spot"\nposition = [0, 1, 0]\ntarget = [0.2, 0, 0]\nintensity = [3, 3, 3]\ncutoff_angle = 30',
        'type = "directional"\ndirection = [0.3, -1, 0.2]\nirradiance = [0.5, 0.6, 0.7]',
        'type = "envmap"\nfile = "textures/sky.exr"\nscale = 0.5\nrotate = { axis = [0, 1, 0], angle = 30 }',
    ],
    "constant": ['type = "constant"\nradiance = [0.2, 0.3, 0.4]'],
}
#: the fields the key leaves out on purpose (harness.scene.content_key.EXCLUDED_FIELDS): an emitter's index and name
EXCLUDED = {(kind, name) for kind in ("PointLight", "SpotLight", "DirectionalLight", "ConstantEnvironment",
                                       "EnvironmentMap") for name in ("index", "name")}


def write_scene(folder: Path, environment: str) -> Path:
    """The scene SCENE with the emitters of EMITTERS[environment], its meshes and its map, in ``folder``."""
    (folder / "meshes").mkdir(parents=True)
    (folder / "textures").mkdir()
    (folder / "meshes" / "triangle.ply").write_bytes(PLY)
    (folder / "meshes" / "triangle.obj").write_bytes(OBJ)
    shutil.copyfile(SKY, folder / "textures" / "sky.exr")
    emitters = "".join(f"\n[[emitters]]\n{body}\n" for body in EMITTERS[environment])
    path = folder / "scene.toml"
    path.write_text(SCENE + emitters)
    return path


@pytest.fixture(params=list(EMITTERS))
def scene(tmp_path, request):
    return load_scene(write_scene(tmp_path / "scene", request.param))


# ---- every field of every dataclass ----------------------------------------------------------------------------


def dataclass_sites(value, path=()):
    """(path, instance) of every dataclass instance inside ``value`` (``value`` first); a path is a tuple of steps
    ("field", name), ("key", key) or ("index", i)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        yield path, value
        for field in dataclasses.fields(value):
            yield from dataclass_sites(getattr(value, field.name), (*path, ("field", field.name)))
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from dataclass_sites(item, (*path, ("key", key)))
    elif isinstance(value, (list, tuple)):
        for index, item in enumerate(value):
            yield from dataclass_sites(item, (*path, ("index", index)))


def replaced(value, path, new):
    """``value`` with the part at ``path`` replaced by ``new``: copies, nothing validated (a dataclass's field is
    set on a shallow copy), so that any value can be planted anywhere."""
    if not path:
        return new
    (kind, step), rest = path[0], path[1:]
    if kind == "field":
        changed = copy.copy(value)
        object.__setattr__(changed, step, replaced(getattr(value, step), rest, new))
        return changed
    items = dict(value) if kind == "key" else list(value)
    items[step] = replaced(value[step], rest, new)
    return items if kind == "key" or isinstance(value, list) else type(value)(items)


def planted(value, folder: Path, annotation: str = ""):
    """A value other than ``value``, of its kind where it has one: a number, a flag, a string, an array, a file of
    the same name with other bytes, a sequence or mapping one item shorter (or longer, when empty), a dataclass with
    every field planted; for None, a value of the field's ``annotation`` (a file, an array, a vector, a string)."""
    if value is None:
        if "Path" in annotation:
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "planted").write_bytes(b"planted")
            return folder / "planted"
        if "ndarray" in annotation:
            return np.ones((1, 3))
        return (1.0, 1.0, 1.0) if "Vector3" in annotation or "tuple" in annotation else "planted"
    if isinstance(value, bool):
        return not value
    if isinstance(value, (int, float)):
        return value + 1 if isinstance(value, int) else value + 0.5
    if isinstance(value, str):
        return value + "~"
    if isinstance(value, np.ndarray):
        changed = np.array(value, copy=True)
        changed.flat[0] += 1
        return changed
    if isinstance(value, Path):
        folder.mkdir(parents=True, exist_ok=True)
        other = folder / value.name
        other.write_bytes(value.read_bytes() + b"\n")
        return other
    if isinstance(value, dict):
        return dict(list(value.items())[:-1]) if value else {"planted": "planted"}
    if isinstance(value, (list, tuple)):
        if not value:
            return type(value)(["planted"])
        if isinstance(value[0], (int, float, str)):
            return type(value)([planted(value[0], folder), *value[1:]])
        return type(value)(value[:-1])
    if dataclasses.is_dataclass(value):
        for field in dataclasses.fields(value):
            value = replaced(value, (("field", field.name),),
                             planted(getattr(value, field.name), folder / field.name, str(field.type)))
        return value
    raise AssertionError(f"no planted value for a {type(value).__name__}")


def kind_of(instance) -> str:
    return type(instance).__name__


def test_a_change_of_every_field_of_every_scene_dataclass_changes_the_key(scene, tmp_path):
    base = scene_digest(scene)
    keys = {base: "the scene as loaded"}
    excluded_seen, missed = set(), []
    count = 0
    for path, instance in list(dataclass_sites(scene)):
        for field in dataclasses.fields(instance):
            label = f"{'/'.join(str(step) for _, step in path) or 'scene'} ({kind_of(instance)}).{field.name}"
            count += 1
            new = planted(getattr(instance, field.name), tmp_path / f"planted-{count}", str(field.type))
            key = scene_digest(replaced(scene, (*path, ("field", field.name)), new))
            if (kind_of(instance), field.name) in EXCLUDED:
                assert key == base, f"{label} is excluded from the key, yet changed it"
                excluded_seen.add((kind_of(instance), field.name))
            elif key in keys:
                missed.append(f"{label} (the key of {keys[key]})")
            else:
                keys[key] = label
    assert not missed, f"{len(missed)} of {count} changes left the key as it was: {'; '.join(missed)}"
    # the scenes hold one of every kind, so every dataclass of the model was planted in
    kinds = {kind_of(instance) for _, instance in dataclass_sites(scene)}
    assert {"Scene", "Camera", "Film", "Material", "Shape", "Medium"} <= kinds
    assert {m.type for m in scene.materials.values()} == set(MATERIAL_TYPES)
    assert {s.type for s in scene.shapes} == set(SHAPE_TYPES)
    assert {s.file.suffix for s in scene.shapes if s.file} == {".ply", ".obj"}
    assert {e.type for e in scene.emitters} in ({"point", "spot", "directional", "envmap"}, {"constant"})
    assert excluded_seen == {(kind_of(e), name) for e in scene.emitters for name in ("index", "name")}


def test_the_two_scenes_hold_every_emitter_type(tmp_path):
    kinds = set()
    for environment in EMITTERS:
        kinds |= {e.type for e in load_scene(write_scene(tmp_path / environment, environment)).emitters}
    assert kinds == set(EMITTER_TYPES)


def test_the_exclusions_are_the_documented_ones():
    from harness.scene import content_key  # the module itself: the tests above go through scene_digest

    assert {(kind.__name__, name) for kind, names in content_key.EXCLUDED_FIELDS.items() for name in names} == EXCLUDED


# ---- every file the loader read --------------------------------------------------------------------------------


def test_the_loader_records_every_file_it_reads(tmp_path):
    path = write_scene(tmp_path / "scene", "envmap")
    scene = load_scene(path)
    assert scene.files == (path, *(tmp_path / "scene" / name for name in
                                   ("meshes/triangle.ply", "meshes/triangle.obj", "textures/sky.exr")))


def test_every_file_opened_while_loading_is_recorded(tmp_path, monkeypatch):
    path = write_scene(tmp_path / "scene", "envmap")
    opened: list[Path] = []
    real_open = os.open

    def recording_open(name, *args, **kwargs):
        opened.append(Path(name).resolve())
        return real_open(name, *args, **kwargs)

    monkeypatch.setattr(os, "open", recording_open)
    scene = load_scene(path)
    monkeypatch.undo()
    inside = {p for p in opened if p.is_relative_to(tmp_path.resolve())}
    assert inside and inside <= {Path(p).resolve() for p in scene.files}


@pytest.mark.parametrize("name", ["scene.toml", "meshes/triangle.ply", "meshes/triangle.obj", "textures/sky.exr"])
def test_a_change_of_the_bytes_of_every_file_kind_changes_the_key(tmp_path, name):
    scene = load_scene(write_scene(tmp_path / "scene", "envmap"))
    base = scene_digest(scene)
    file = tmp_path / "scene" / name
    original = file.read_bytes()
    file.write_bytes(original[:-1] + bytes([original[-1] ^ 1]))  # one bit of the last byte
    assert scene_digest(scene) != base, name
    file.write_bytes(original)
    assert scene_digest(scene) == base


def test_a_file_of_a_kind_no_code_lists_changes_the_key(tmp_path, monkeypatch):
    """A loader that reads one more kind of file (a texture, say) through the reader's file_path: the key holds its
    bytes with nothing written for the kind."""
    folder = tmp_path / "scene"
    path = write_scene(folder, "constant")
    (folder / "textures" / "albedo.png").write_bytes(b"\x89PNG one")
    reader_scene = scene_load._SceneReader.scene

    def scene_with_a_texture(self, document, path):
        self.file_path("textures/albedo.png", "materials.white.texture", "texture")
        return reader_scene(self, document, path)

    monkeypatch.setattr(scene_load._SceneReader, "scene", scene_with_a_texture)
    scene = load_scene(path)
    base = scene_digest(scene)
    (folder / "textures" / "albedo.png").write_bytes(b"\x89PNG two")
    assert scene_digest(scene) != base, "the texture's bytes changed, the key did not"
    assert scene_digest(load_scene(path)) == scene_digest(scene)


def test_an_unreadable_recorded_file_is_one_error_naming_it(tmp_path, monkeypatch):
    folder = tmp_path / "scene"
    scene = load_scene(write_scene(folder, "envmap"))
    (folder / "textures" / "sky.exr").unlink()
    with pytest.raises(HarnessError, match="content key") as error:
        scene_digest(scene)
    assert error.value.where == str((folder / "textures" / "sky.exr").resolve())
    os.mkfifo(folder / "textures" / "sky.exr")  # a named pipe in its place is refused, not waited on
    with pytest.raises(HarnessError, match="not a regular file"):
        scene_digest(scene)


# ---- a field added to the camera -------------------------------------------------------------------------------


def test_a_field_added_to_the_camera_enters_the_key(scene):
    """A camera with one more field (an aperture, say): its value changes the key, with nothing written for it."""
    wider = dataclasses.make_dataclass("Camera", [("aperture", float, dataclasses.field(default=0.0))],
                                       bases=(Camera,), frozen=True)
    given = {field.name: getattr(scene.camera, field.name) for field in dataclasses.fields(Camera)}
    pinhole = dataclasses.replace(scene, camera=wider(**given, aperture=0.0))
    lens = dataclasses.replace(scene, camera=wider(**given, aperture=0.05))
    assert scene_digest(pinhole) != scene_digest(lens), "the camera's aperture changed, the key did not"
    assert scene_digest(pinhole) == scene_digest(dataclasses.replace(scene, camera=wider(**given, aperture=0.0)))


def test_a_value_without_a_rule_is_refused(scene):
    with pytest.raises(TypeError, match=r"Scene\.regions.*set"):
        scene_digest(dataclasses.replace(scene, regions={"ball"}))


# ---- the resume digest of harness run --------------------------------------------------------------------------


def test_the_resume_digest_holds_the_files_a_scene_names(tmp_path):
    folder = tmp_path / "scene"
    case = Case(name="every-kind", scene=write_scene(folder, "envmap"))
    base = runstate.case_digest(case, judge.case_scenes)
    mesh = folder / "meshes" / "triangle.ply"
    mesh.write_bytes(PLY.replace(b"1 0 0\n", b"2 0 0\n"))
    assert runstate.case_digest(case, judge.case_scenes) != base
    mesh.write_bytes(PLY)
    assert runstate.case_digest(case, judge.case_scenes) == base
