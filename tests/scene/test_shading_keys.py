"""The scene format's shading-normal keys (docs/scene-format.md, "Shading normals"): a mesh's ``face_normals``, the
``normalmap`` and ``bumpmap`` materials around another one, read with Mitsuba 3.9.1's names and defaults, and every
wrong one refused in one line (a HarnessError naming the key, saying what was expected): the key on a shape that is
no mesh, a normal map that is not a raw bitmap, a bump map that is no bitmap, a ``bsdf`` that names nothing or another
map, a map on a sphere or on a mesh without texture coordinates, missing and unknown keys, a ``scale`` that is no
finite number, an emitting mesh whose vertex normals lean off its triangles (Mitsuba turns and samples an area light
by them), and a mesh file with a zero or non-finite vertex normal."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MINIMAL_SCENE, ply_ascii as _ply
from harness.core.errors import HarnessError
from harness.files.imageio import encode_png
from harness.scene import load_scene
from harness.scene.triangulate import triangulate

SHAPE = '\n[[shapes]]\ntype = "{type}"\nmaterial = "{material}"\n{extra}\n'
NORMALS = np.random.default_rng(11).integers(100, 256, size=(3, 4, 3), dtype=np.uint8)  # z >= 100: mostly upward

TEXTURES = """
[textures.nm]
filename = "nm.png"
raw = true

[textures.srgb]
filename = "nm.png"

[textures.height]
filename = "nm.png"
raw = true

[textures.checker]
type = "checkerboard"
color0 = 0.2
color1 = 0.7
"""


QUAD = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
QUAD_FACES = [(0, 1, 2), (0, 2, 3)]
QUAD_UV = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
UP = [(0.0, 0.0, 1.0)] * 4
LEANING = [(0.5, 0.0, 1.0), (-0.5, 0.0, 1.0), (0.0, 0.5, 1.0), (0.0, -0.5, 1.0)]
ROOF = QUAD + np.array([0.0, 0.0, 1.0]) * [[0.0], [0.4], [0.0], [0.4]]  # folded along its diagonal 0-2
MESHES = {
    "uv.ply": _ply(QUAD, QUAD_FACES, uv=QUAD_UV),
    "bare.ply": _ply(QUAD, QUAD_FACES),
    "flat-normals.ply": _ply(QUAD, QUAD_FACES, normals=UP),
    "leaning.ply": _ply(QUAD, QUAD_FACES, normals=LEANING),
    "roof.ply": _ply(ROOF, QUAD_FACES),
    "zero-normal.ply": _ply(QUAD, QUAD_FACES, normals=[(0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0),
                                                       (0.0, 0.0, 1.0)]),
    "nan-normal.ply": _ply(QUAD, QUAD_FACES, normals=[(0.0, 0.0, 1.0), (0.0, float("nan"), 1.0), (0.0, 0.0, 1.0),
                                                      (0.0, 0.0, 1.0)]),
    "inf-normal.ply": _ply(QUAD, QUAD_FACES, normals=[(0.0, 0.0, 1.0), (0.0, 0.0, float("inf")), (0.0, 0.0, 1.0),
                                                      (0.0, 0.0, 1.0)]),
}


def _write(folder, body: str):
    (folder / "nm.png").write_bytes(encode_png(NORMALS))
    for name, text in MESHES.items():
        (folder / name).write_text(text)
    path = folder / "scene.toml"
    path.write_text(MINIMAL_SCENE + TEXTURES + body)
    return path


def _map(kind: str = "normalmap", texture: str = "nm", extra: str = "", name: str = "m", bsdf: str = "white") -> str:
    key = "normalmap" if kind == "normalmap" else "texture"
    return f'\n[materials.{name}]\ntype = "{kind}"\n{key} = {{ texture = "{texture}" }}\nbsdf = "{bsdf}"\n{extra}\n'


MAPPED_RECTANGLE = SHAPE.format(type="rectangle", material="m", extra="")
LIGHT = 'emission = [5.0, 5.0, 5.0]'


# ---- what is read ---------------------------------------------------------------------------------------------------


def test_a_normal_map_and_a_bump_map_are_read_with_mitsubas_names_and_defaults(tmp_path):
    body = (_map("normalmap", "nm", name="n") + _map("bumpmap", "height", name="b",
                                                     extra="scale = 0.25\nflip_invalid_normals = false\n"
                                                           "use_shadowing_function = false")
            + SHAPE.format(type="rectangle", material="n", extra="") + SHAPE.format(type="cube", material="b",
                                                                                    extra=""))
    scene = load_scene(_write(tmp_path, body))
    n, b = scene.materials["n"].perturbation, scene.materials["b"].perturbation
    assert (n.type, n.texture.name, n.bsdf, n.scale, n.flip_invalid_normals, n.use_shadowing_function) == (
        "normalmap", "nm", "white", 1.0, True, True)
    assert (b.type, b.texture.name, b.bsdf, b.scale, b.flip_invalid_normals, b.use_shadowing_function) == (
        "bumpmap", "height", "white", 0.25, False, False)
    assert scene.materials["n"].reflectance == scene.materials["white"].reflectance  # the nested material's
    assert scene.materials["white"].perturbation is None


def test_a_bump_maps_height_may_be_an_srgb_bitmap(tmp_path):
    scene = load_scene(_write(tmp_path, _map("bumpmap", "srgb") + MAPPED_RECTANGLE))
    assert scene.materials["m"].perturbation.texture.raw is False


@pytest.mark.parametrize("face_normals", [False, True])
def test_face_normals_on_a_mesh_is_read_and_drops_the_files_normals(tmp_path, face_normals):
    body = SHAPE.format(type="mesh", material="white",
                        extra=f'file = "leaning.ply"\nface_normals = {str(face_normals).lower()}')
    scene = load_scene(_write(tmp_path, body))
    shape = scene.shapes[0]
    assert shape.face_normals is face_normals
    assert (shape.mesh_normals is None) is face_normals
    geometry = triangulate(scene)
    assert geometry.has_shading_normals is not face_normals


@pytest.mark.parametrize("mesh", ["flat-normals.ply", "bare.ply"])
def test_a_planar_emitting_mesh_is_accepted_with_its_vertex_normals(tmp_path, mesh):
    body = SHAPE.format(type="mesh", material="white", extra=f'file = "{mesh}"\n{LIGHT}')
    scene = load_scene(_write(tmp_path, body))
    assert scene.shapes[0].is_emitter and not scene.shapes[0].face_normals


@pytest.mark.parametrize("mesh", ["leaning.ply", "roof.ply"])
def test_an_emitting_mesh_with_leaning_normals_is_accepted_with_face_normals(tmp_path, mesh):
    body = SHAPE.format(type="mesh", material="white", extra=f'file = "{mesh}"\n{LIGHT}\nface_normals = true')
    assert load_scene(_write(tmp_path, body)).shapes[0].face_normals


@pytest.mark.parametrize("mesh", ["zero-normal.ply", "nan-normal.ply", "inf-normal.ply"])
def test_a_mesh_with_a_broken_vertex_normal_is_accepted_with_face_normals(tmp_path, mesh):
    body = SHAPE.format(type="mesh", material="white", extra=f'file = "{mesh}"\nface_normals = true')
    assert load_scene(_write(tmp_path, body)).shapes[0].mesh_normals is None


# ---- what is refused ------------------------------------------------------------------------------------------------

REFUSALS = [
    ("face-normals-on-rectangle", SHAPE.format(type="rectangle", material="white", extra="face_normals = true"),
     "shapes[0].face_normals", "applies only to shapes of type 'mesh', not 'rectangle'"),
    ("face-normals-on-cube", SHAPE.format(type="cube", material="white", extra="face_normals = false"),
     "shapes[0].face_normals", "applies only to shapes of type 'mesh', not 'cube'"),
    ("face-normals-on-sphere", SHAPE.format(type="sphere", material="white", extra="face_normals = true"),
     "shapes[0].face_normals", "applies only to shapes of type 'mesh', not 'sphere'"),
    ("face-normals-not-boolean", SHAPE.format(type="mesh", material="white", extra='file = "bare.ply"\n'
                                                                                   'face_normals = 1'),
     "shapes[0].face_normals", "expected true or false"),
    ("normalmap-not-raw", _map("normalmap", "srgb") + MAPPED_RECTANGLE,
     "materials.m.normalmap", "texture 'srgb' is a bitmap without raw = true"),
    ("normalmap-checkerboard", _map("normalmap", "checker") + MAPPED_RECTANGLE,
     "materials.m.normalmap", "texture 'checker' is a checkerboard: a normal map takes a bitmap with raw = true"),
    ("bumpmap-checkerboard", _map("bumpmap", "checker") + MAPPED_RECTANGLE,
     "materials.m.texture", "texture 'checker' is a checkerboard: a bump map takes a bitmap"),
    ("unknown-texture", _map("normalmap", "nope") + MAPPED_RECTANGLE,
     "materials.m.normalmap.texture", "unknown texture 'nope'"),
    ("texture-not-a-table", '\n[materials.m]\ntype = "normalmap"\nnormalmap = "nm"\nbsdf = "white"\n'
                            + MAPPED_RECTANGLE,
     "materials.m.normalmap", 'expected { texture = "NAME" } (a [textures] table)'),
    ("unknown-bsdf", _map(bsdf="nope") + MAPPED_RECTANGLE, "materials.m.bsdf", "unknown material 'nope'"),
    ("bsdf-names-a-normalmap", _map(name="inner") + _map(bsdf="inner") + MAPPED_RECTANGLE,
     "materials.m.bsdf", "material 'inner' is a normalmap or bumpmap: a normalmap perturbs a material that perturbs"),
    ("bsdf-names-a-bumpmap", _map("bumpmap", "height", name="inner") + _map(bsdf="inner") + MAPPED_RECTANGLE,
     "materials.m.bsdf", "material 'inner' is a normalmap or bumpmap"),
    ("bumpmap-bsdf-names-a-normalmap", _map(name="inner") + _map("bumpmap", "height", bsdf="inner")
     + MAPPED_RECTANGLE, "materials.m.bsdf", "a bumpmap perturbs a material that perturbs none"),
    ("bsdf-names-itself", _map(bsdf="m") + MAPPED_RECTANGLE, "materials.m.bsdf", "is a normalmap or bumpmap"),
    ("bsdf-not-a-string", '\n[materials.m]\ntype = "normalmap"\nnormalmap = { texture = "nm" }\nbsdf = 3\n'
                          + MAPPED_RECTANGLE, "materials.m.bsdf", "expected"),
    ("normalmap-on-mesh-without-uv", _map() + SHAPE.format(type="mesh", material="m", extra='file = "bare.ply"'),
     "shapes[0].material", "has no texture coordinates"),
    ("bumpmap-on-mesh-without-uv", _map("bumpmap", "height")
     + SHAPE.format(type="mesh", material="m", extra='file = "flat-normals.ply"'),
     "shapes[0].material", "has no texture coordinates"),
    ("missing-normalmap", '\n[materials.m]\ntype = "normalmap"\nbsdf = "white"\n' + MAPPED_RECTANGLE,
     "materials.m.normalmap", "missing required key 'normalmap'"),
    ("missing-bumpmap-texture", '\n[materials.m]\ntype = "bumpmap"\nbsdf = "white"\n' + MAPPED_RECTANGLE,
     "materials.m.texture", "missing required key 'texture'"),
    ("missing-bsdf", '\n[materials.m]\ntype = "normalmap"\nnormalmap = { texture = "nm" }\n' + MAPPED_RECTANGLE,
     "materials.m.bsdf", "missing required key 'bsdf'"),
    ("scale-on-normalmap", _map(extra="scale = 2.0") + MAPPED_RECTANGLE,
     "materials.m.scale", "a normalmap takes the keys type, bsdf, flip_invalid_normals, use_shadowing_function, "
                          "normalmap; got 'scale'"),
    ("unknown-key-on-normalmap", _map(extra="flip_invalid_normal = false") + MAPPED_RECTANGLE,
     "materials.m.flip_invalid_normal", "got 'flip_invalid_normal'"),
    ("reflectance-on-bumpmap", _map("bumpmap", "height", extra="reflectance = [0.5, 0.5, 0.5]") + MAPPED_RECTANGLE,
     "materials.m.reflectance", "a bumpmap takes the keys type, bsdf, flip_invalid_normals, use_shadowing_function, "
                                "texture, scale; got 'reflectance'"),
    ("scale-a-string", _map("bumpmap", "height", extra='scale = "big"') + MAPPED_RECTANGLE,
     "materials.m.scale", "expected a finite number, got"),
    ("scale-infinite", _map("bumpmap", "height", extra="scale = inf") + MAPPED_RECTANGLE,
     "materials.m.scale", "expected a finite number, got"),
    ("scale-nan", _map("bumpmap", "height", extra="scale = nan") + MAPPED_RECTANGLE,
     "materials.m.scale", "expected a finite number, got"),
    ("scale-a-boolean", _map("bumpmap", "height", extra="scale = true") + MAPPED_RECTANGLE,
     "materials.m.scale", "expected a finite number, got"),
    ("flip-not-boolean", _map(extra='flip_invalid_normals = "yes"') + MAPPED_RECTANGLE,
     "materials.m.flip_invalid_normals", "expected true or false"),
    ("shadowing-not-boolean", _map(extra="use_shadowing_function = 0") + MAPPED_RECTANGLE,
     "materials.m.use_shadowing_function", "expected true or false"),
    ("emitting-mesh-leaning-file-normals", SHAPE.format(type="mesh", material="white",
                                                        extra=f'file = "leaning.ply"\n{LIGHT}'),
     "shapes[0].face_normals", "emits light and its vertex normals lean off its triangles' normals"),
    ("emitting-mesh-leaning-own-normals", SHAPE.format(type="mesh", material="white",
                                                       extra=f'file = "roof.ply"\n{LIGHT}'),
     "shapes[0].face_normals", "expected face_normals = true on it"),
    ("zero-vertex-normal", SHAPE.format(type="mesh", material="white", extra='file = "zero-normal.ply"'),
     "shapes[0].file", "has a vertex normal that is zero or not finite (or set face_normals = true"),
    ("nan-vertex-normal", SHAPE.format(type="mesh", material="white", extra='file = "nan-normal.ply"'),
     "shapes[0].file", "has a vertex normal that is zero or not finite"),
    ("inf-vertex-normal", SHAPE.format(type="mesh", material="white", extra='file = "inf-normal.ply"'),
     "shapes[0].file", "has a vertex normal that is zero or not finite"),
]


@pytest.mark.parametrize("body,key,message", [r[1:] for r in REFUSALS], ids=[r[0] for r in REFUSALS])
def test_a_wrong_shading_key_is_refused_in_one_line_naming_it(tmp_path, body, key, message):
    with pytest.raises(HarnessError) as err:
        load_scene(_write(tmp_path, body))
    assert err.value.where.endswith(key) and message in err.value.message, (err.value.where, err.value.message)
    assert "\n" not in str(err.value)
