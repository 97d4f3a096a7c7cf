"""harness.renderers.import_pbrt: pbrt-v4 scene files read into the scene format (docs/import.md, "pbrt-v4").

Files written here, one per directive and parameter the importer reads, imported, written to a folder, loaded and
checked value by value (camera rays against pbrt's own camera model, triangles, material rows); one refusal per
element it does not read, with its line and column; lenient drops; a Cornell box rendered at 2 spp.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from harness.core.errors import HarnessError
from harness.renderers.import_pbrt import import_pbrt, tokenize
from harness.renderers.imports import write_imported
from harness.renderers.meshfiles import ply_bytes
from harness.scene import load_scene, material_arrays, triangulate


def pbrt(tmp_path: Path, text: str, name: str = "scene.pbrt") -> Path:
    path = tmp_path / "in" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def imported(tmp_path: Path, text: str, **kw):
    result = import_pbrt(pbrt(tmp_path, text), **kw)
    scene = load_scene(write_imported(result, tmp_path / "out"))
    return result, tomllib.loads(result.toml), scene


HEAD = """LookAt 0 1 4  0 1 0  0 1 0
Camera "perspective" "float fov" [ 40 ]
Film "rgb" "integer xresolution" [ 8 ] "integer yresolution" [ 6 ] "string filename" "x.exr"
PixelFilter "box"
WorldBegin
"""

QUAD = """Shape "trianglemesh" "integer indices" [ 0 1 2 0 2 3 ]
  "point3 P" [ -1 0 -1  -1 0 1  1 0 1  1 0 -1 ]
"""

CORNELL = """# a small Cornell box, pbrt-v4
Scale -1 1 1
LookAt 0 1 3.5   0 1 0   0 1 0
Camera "perspective" "float fov" [ 39 ]
Sampler "halton" "integer pixelsamples" 16
Integrator "volpath" "integer maxdepth" [ 4 ]
Film "rgb" "integer xresolution" [ 16 ] "integer yresolution" [ 12 ] "string filename" "cornell.exr"
PixelFilter "box"
WorldBegin
MakeNamedMaterial "white" "string type" "diffuse" "rgb reflectance" [ .73 .73 .73 ]
MakeNamedMaterial "red" "string type" "diffuse" "rgb reflectance" [ .65 .05 .05 ]
MakeNamedMaterial "green" "string type" "diffuse" "rgb reflectance" [ .12 .45 .15 ]
NamedMaterial "white"
Shape "trianglemesh" "integer indices" [ 0 1 2 0 2 3 ]   # floor
  "point3 P" [ -1 0 -1  -1 0 1  1 0 1  1 0 -1 ]
Shape "trianglemesh" "integer indices" [ 0 1 2 0 2 3 ]   # ceiling
  "point3 P" [ -1 2 -1  1 2 -1  1 2 1  -1 2 1 ]
Shape "trianglemesh" "integer indices" [ 0 1 2 0 2 3 ]   # back wall
  "point3 P" [ -1 0 -1  1 0 -1  1 2 -1  -1 2 -1 ]
AttributeBegin
  NamedMaterial "red"
  Shape "trianglemesh" "integer indices" [ 0 1 2 0 2 3 ]
    "point3 P" [ -1 0 -1  -1 2 -1  -1 2 1  -1 0 1 ]
AttributeEnd
AttributeBegin
  NamedMaterial "green"
  Shape "trianglemesh" "integer indices" [ 0 1 2 0 2 3 ]
    "point3 P" [ 1 0 -1  1 0 1  1 2 1  1 2 -1 ]
AttributeEnd
AttributeBegin
  AreaLightSource "diffuse" "rgb L" [ 17 12 4 ]
  Material "diffuse" "rgb reflectance" [ 0 0 0 ]
  Translate 0 1.99 0
  Shape "trianglemesh" "integer indices" [ 0 1 2 0 2 3 ]
    "point3 P" [ -.25 0 -.25  .25 0 -.25  .25 0 .25  -.25 0 .25 ]
AttributeEnd
AttributeBegin
  Material "dielectric" "float eta" 1.5
  Shape "sphere" "float radius" .3
AttributeEnd
"""


def pbrt_directions(world_from_camera, fov, px, py, w, h):
    """pbrt-v4's perspective camera: raster (px, py) through the screen window, fov on the shorter axis."""
    aspect = w / h
    sx0, sy1 = (-aspect, 1.0) if aspect > 1 else (-1.0, 1 / aspect)
    sx = sx0 + (px / w) * 2 * -sx0
    sy = sy1 - (py / h) * 2 * sy1
    t = math.tan(math.radians(fov) / 2)
    d = np.stack([sx * t, sy * t, np.ones_like(sx)], axis=-1) @ world_from_camera[:3, :3].T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


# ---- the tokenizer ----------------------------------------------------------------------------------------------------


def test_tokens_carry_their_line_and_column():
    tokens = tokenize('Shape "sphere" # a comment "x"\n  "float radius" [ 2.5 ]\n', "f")
    assert [(t.text, t.line, t.col, t.quoted) for t in tokens] == [
        ("Shape", 1, 1, False), ("sphere", 1, 7, True), ("float radius", 2, 3, True), ("[", 2, 18, False),
        ("2.5", 2, 20, False), ("]", 2, 24, False)]


def test_an_unterminated_string_is_one_line():
    with pytest.raises(HarnessError, match=r"^f:2:3: an unterminated string$"):
        tokenize('Shape\n  "sphere\n', "f")


# ---- the Cornell box ---------------------------------------------------------------------------------------------------


def test_a_cornell_box_imports_value_by_value_and_renders(tmp_path):
    result, doc, scene = imported(tmp_path, CORNELL)
    assert result.dropped == []
    assert doc["integrator"] == {"max_depth": 5}  # pbrt's maxdepth counts bounces; Mitsuba's the vertices: +1
    assert doc["film"] == {"width": 16, "height": 12, "filter": "box"}
    assert "the world mirrored" not in doc["description"]  # Scale -1 1 1 makes pbrt's camera Mitsuba's
    assert doc["camera"]["fov_axis"] == "smaller" and doc["camera"]["fov"] == 39
    # the camera's rays are pbrt's: world_from_camera = (Scale(-1, 1, 1) LookAt)^-1
    eye, d = np.array([0, 1, 3.5]), np.array([0, 0, -1.0])
    right = np.cross([0, 1, 0], d)
    frame = np.eye(4)
    frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = right, np.cross(d, right), d, eye
    world_from_camera = frame @ np.diag([-1.0, 1, 1, 1])
    px, py = np.array([0.5, 3.25, 16.0, 0.0]), np.array([0.5, 9.0, 12.0, 0.0])
    origins, directions = scene.camera.generate_rays(px, py, 16, 12)
    np.testing.assert_allclose(origins, np.broadcast_to(eye, origins.shape), atol=1e-12)
    np.testing.assert_allclose(directions, pbrt_directions(world_from_camera, 39, px, py, 16, 12), atol=1e-12)
    geometry = triangulate(scene)
    corners = np.asarray(geometry.vertices)[np.asarray(geometry.triangles)]
    floor = corners[:2]
    np.testing.assert_array_equal(floor[0], [[-1, 0, -1], [-1, 0, 1], [1, 0, 1]])
    light = [s for s in scene.shapes if s.emission is not None]
    assert len(light) == 1 and list(light[0].emission) == [17, 12, 4]
    assert doc["shapes"][5]["face_normals"] is True
    assert doc["shapes"][6] == {"name": "shape6", "material": "material4", "type": "sphere",
                                "center": [0.0, 0.0, 0.0], "radius": 0.3}
    assert doc["materials"]["white"] == {"type": "diffuse", "reflectance": [0.73, 0.73, 0.73], "two_sided": True}
    assert doc["materials"]["material4"] == {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}
    assert material_arrays(scene) is not None
    assert "Sampler \"halton\": not read" in doc["description"]

    from harness.renderers import get_renderer
    from harness.renderers.base import RenderRequest
    image = get_renderer("reference").render(scene, RenderRequest(spp=2, seed=0)).image
    image = np.asarray(image)
    assert image.shape[:2] == (12, 16) and np.isfinite(image).all() and image.max() > 0


def test_a_plain_look_at_mirrors_the_world_and_keeps_pbrts_image(tmp_path):
    result, doc, scene = imported(tmp_path, HEAD + 'Material "diffuse"\n' + QUAD +
                                  'LightSource "point" "rgb I" [ 1 2 3 ] "point3 from" [ 0.5 1 0 ]\n')
    assert "the world mirrored through x = 0" in doc["description"]
    frame = np.linalg.inv(np.array([[1, 0, 0, 0], [0, 1, 0, -1], [0, 0, 1, -4], [0, 0, 0, 1.0]]))
    frame = np.eye(4)
    eye, d = np.array([0, 1, 4.0]), np.array([0, 0, -1.0])
    right = np.cross([0, 1, 0], d)
    frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = right, np.cross(d, right), d, eye
    px, py = np.array([0.0, 2.5, 8.0]), np.array([0.0, 1.5, 6.0])
    _, directions = scene.camera.generate_rays(px, py, 8, 6)
    expected = pbrt_directions(frame, 40, px, py, 8, 6) * [-1, 1, 1]  # in the mirrored world
    np.testing.assert_allclose(directions, expected, atol=1e-12)
    assert doc["emitters"] == [{"type": "point", "position": [-0.5, 1.0, 0.0], "intensity": [1.0, 2.0, 3.0]}]
    corners = np.asarray(triangulate(scene).vertices)[np.asarray(triangulate(scene).triangles)]
    # pbrt's first triangle (-1 0 -1)(-1 0 1)(1 0 1) faces +y; mirrored and rewound it still does
    n = np.cross(corners[0, 1] - corners[0, 0], corners[0, 2] - corners[0, 0])
    assert n[1] > 0


# ---- directives and parameters -----------------------------------------------------------------------------------


def test_transforms_compose_as_pbrts_ctm(tmp_path):
    text = HEAD + ('AttributeBegin\nTranslate 1 2 3\nRotate 90 0 0 1\nScale 2 2 2\nMaterial "diffuse"\n'
                   'Shape "sphere" "float radius" 0.5\nAttributeEnd\n'
                   'AttributeBegin\nConcatTransform [1 0 0 0 0 1 0 0 0 0 1 0 5 0 0 1]\nCoordinateSystem "here"\n'
                   'AttributeEnd\nAttributeBegin\nCoordSysTransform "here"\nShape "sphere"\nAttributeEnd\n'
                   'AttributeBegin\nTransform [1 0 0 0 0 1 0 0 0 0 1 0 0 7 0 1]\nIdentity\nShape "sphere"\nAttributeEnd\n')
    _, doc, _ = imported(tmp_path, text)
    spheres = doc["shapes"]
    np.testing.assert_allclose(spheres[0]["center"], [-1, 2, 3], atol=1e-12)  # mirrored x
    assert spheres[0]["radius"] == pytest.approx(1.0)
    np.testing.assert_allclose(spheres[1]["center"], [-5, 0, 0], atol=1e-12)
    np.testing.assert_allclose(spheres[2]["center"], [0, 0, 0], atol=1e-12)


def test_a_thin_lens_and_an_orthographic_camera(tmp_path):
    _, doc, _ = imported(tmp_path, HEAD.replace('"float fov" [ 40 ]', '"float fov" 30 "float lensradius" 0.1 '
                                                '"float focaldistance" 3') + QUAD)
    assert doc["camera"]["type"] == "thinlens"
    assert (doc["camera"]["aperture_radius"], doc["camera"]["focus_distance"]) == (0.1, 3)
    _, doc, scene = imported(tmp_path, HEAD.replace('"perspective" "float fov" [ 40 ]',
                                                    '"orthographic"') + QUAD)
    assert doc["camera"]["scale"] == [8 / 6, 8 / 6, 1.0]  # pbrt's window [-4/3, 4/3] x [-1, 1]
    origins, _ = scene.camera.generate_rays(np.array([0.0]), np.array([0.0]), 8, 6)
    # pbrt's raster (0, 0) is screen (-4/3, 1): camera (-4/3, 1, 0); the LookAt's camera +x is world -x, so world
    # (4/3, 2, 4), mirrored through x = 0
    np.testing.assert_allclose(origins[0], [-4 / 3, 2.0, 4.0], atol=1e-12)


def test_object_instances_are_flattened(tmp_path):
    text = HEAD + ('ObjectBegin "ball"\nTranslate 0 1 0\nMaterial "diffuse"\nShape "sphere" "float radius" 0.5\n'
                   'ObjectEnd\nShape "sphere"\n'
                   'AttributeBegin\nTranslate 2 0 0\nObjectInstance "ball"\nAttributeEnd\n'
                   'AttributeBegin\nScale 2 2 2\nObjectInstance "ball"\nAttributeEnd\n')
    _, doc, _ = imported(tmp_path, text)
    centres = [s["center"] for s in doc["shapes"]]
    np.testing.assert_allclose(centres, [[0, 0, 0], [-2, 1, 0], [0, 2, 0]], atol=1e-12)  # x mirrored
    assert [s["radius"] for s in doc["shapes"]] == [1.0, 0.5, pytest.approx(1.0)]


def test_materials(tmp_path):
    text = HEAD + ('Material "conductor" "rgb eta" [ .2 .9 1.1 ] "rgb k" [ 3.9 2.4 2.1 ] "float roughness" 0.04\n'
                   + QUAD + 'Material "conductor" "rgb eta" [ .2 .9 1.1 ] "rgb k" [ 3.9 2.4 2.1 ]\n' + QUAD +
                   'Material "dielectric" "float eta" 1.33 "float roughness" 0.09 "bool remaproughness" false\n'
                   + QUAD + 'Material "diffuse" "spectrum reflectance" [ 0.25 ]\n' + QUAD)
    _, doc, scene = imported(tmp_path, text)
    m = doc["materials"]
    assert m["material0"] == {"type": "roughconductor", "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.1],
                              "two_sided": True, "alpha": pytest.approx(0.2), "distribution": "ggx"}
    assert m["material1"]["type"] == "conductor"
    assert m["material2"] == {"type": "roughdielectric", "int_ior": 1.33, "ext_ior": 1.0, "alpha": 0.09,
                              "distribution": "ggx"}
    assert m["material3"]["reflectance"] == [0.25, 0.25, 0.25]
    assert material_arrays(scene) is not None


def test_an_imagemap_texture_and_uv(tmp_path):
    from harness.files.imageio import encode_png
    (tmp_path / "in" / "tex").mkdir(parents=True)
    (tmp_path / "in" / "tex" / "a.png").write_bytes(encode_png(np.full((2, 2, 3), 128, np.uint8)))
    text = HEAD + ('Texture "wood" "spectrum" "imagemap" "string filename" "tex/a.png" "string filter" "point" '
                   '"string wrap" "clamp" "float uscale" 2\n'
                   'Material "diffuse" "texture reflectance" "wood"\n'
                   'Shape "trianglemesh" "integer indices" [ 0 1 2 ] "point3 P" [ 0 0 0 1 0 0 0 1 0 ] '
                   '"point2 uv" [ 0 0 1 0 0 1 ] "normal N" [ 0 0 1 0 0 1 0 0 1 ]\n')
    result, doc, scene = imported(tmp_path, text)
    assert doc["textures"]["wood"] == {"filename": "textures/wood.png", "filter_type": "nearest",
                                       "wrap_mode": "clamp", "raw": False,
                                       "to_uv": [[2.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, 1.0]]}
    assert result.files["textures/wood.png"] == (tmp_path / "in" / "tex" / "a.png").read_bytes()
    assert doc["materials"]["material0"]["reflectance"] == {"texture": "wood"}


def test_include_and_a_plymesh_inside_the_folder(tmp_path):
    (tmp_path / "in" / "geo").mkdir(parents=True)
    (tmp_path / "in" / "geo" / "tri.ply").write_bytes(
        ply_bytes(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), np.array([[0, 1, 2]])))
    pbrt(tmp_path, 'Shape "plymesh" "string filename" "geo/tri.ply"\n', "geo.pbrt")
    _, doc, scene = imported(tmp_path, HEAD + 'Include "geo.pbrt"\n')
    corners = np.asarray(triangulate(scene).vertices)[np.asarray(triangulate(scene).triangles)]
    np.testing.assert_array_equal(np.sort(corners[0], axis=0), np.sort([[0, 0, 0], [-1, 0, 0], [0, 1, 0]], axis=0))
    n = np.cross(corners[0, 1] - corners[0, 0], corners[0, 2] - corners[0, 0])
    assert n[2] > 0  # pbrt's front (+z) kept through the mirror


def test_lights(tmp_path):
    text = HEAD + QUAD + (
        'LightSource "spot" "rgb I" [ 5 5 5 ] "point3 from" [ 0 2 0 ] "point3 to" [ 0 0 0 ] "float coneangle" 30 '
        '"float conedelta" 10 "float scale" 2\n'
        'LightSource "distant" "rgb L" [ 1 1 1 ] "point3 from" [ 0 1 0 ] "point3 to" [ 0 0 0 ]\n'
        'LightSource "infinite" "rgb L" [ .1 .2 .3 ]\n')
    _, doc, _ = imported(tmp_path, text)
    spot, sun, sky = doc["emitters"]
    assert spot == {"type": "spot", "position": [0.0, 2.0, 0.0], "target": [0.0, 0.0, 0.0],
                    "intensity": [10.0, 10.0, 10.0], "cutoff_angle": 30.0, "beam_width": 20.0}
    assert sun == {"type": "directional", "direction": [0.0, -1.0, 0.0], "irradiance": [1.0, 1.0, 1.0]}
    assert sky == {"type": "constant", "radiance": [0.1, 0.2, 0.3]}
    assert "smoothstep" in doc["description"]


# ---- refusals ----------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("line, message", [
    ('Shape "disk"', 'scene.pbrt:6:1: Shape "disk": expected trianglemesh, plymesh or sphere'),
    ('Material "coateddiffuse"\nShape "sphere"', 'scene.pbrt:6:1: Material "coateddiffuse": expected diffuse, '
                                                 'conductor or dielectric'),
    ('Material "conductor"\nShape "sphere"', 'scene.pbrt:6:1: Material "conductor": the default metal-Cu spectra'),
    ('LightSource "infinite" "string filename" "sky.exr"', 'scene.pbrt:6:1: LightSource "infinite": an image '
                                                           'infinite light'),
    ('LightSource "point" "float power" 10', 'scene.pbrt:6:1: LightSource "point": "power"'),
    ('AreaLightSource "diffuse" "bool twosided" true', 'scene.pbrt:6:1: AreaLightSource "diffuse": twosided'),
    ('MakeNamedMedium "fog" "string type" "homogeneous"', 'scene.pbrt:6:1: MakeNamedMedium: not imported'),
    ('ActiveTransform StartTime', 'scene.pbrt:6:1: ActiveTransform: not imported'),
    ('Material "diffuse" "spectrum reflectance" "metal-Au-eta"\nShape "sphere"',
     'scene.pbrt:6:20: "spectrum reflectance": a named or sampled spectrum'),
    ('LightSource "point" "blackbody I" 3000',
     'scene.pbrt:6:21: "blackbody I": expected "rgb I" (the scene format is RGB)'),
])
def test_a_refusal_is_one_line_with_its_place(tmp_path, line, message):
    with pytest.raises(HarnessError) as err:
        import_pbrt(pbrt(tmp_path, HEAD + line + "\n"))
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith(str(tmp_path / "in" / "scene.pbrt")[:-len("scene.pbrt")] + message), text


def test_a_file_outside_the_folder_is_refused_even_lenient(tmp_path):
    (tmp_path / "outside.pbrt").write_text("")
    with pytest.raises(HarnessError, match="Include file '../outside.pbrt' resolves to .*, outside the scene's "
                                           "folder .*; expected a file inside it$"):
        import_pbrt(pbrt(tmp_path, HEAD + 'Include "../outside.pbrt"\n'), lenient=True)


def test_lenient_drops_and_lists(tmp_path):
    result, doc, scene = imported(tmp_path, HEAD + 'Shape "disk"\n' + QUAD, lenient=True)
    assert len(result.dropped) == 1 and 'scene.pbrt:6:1: Shape "disk"' in result.dropped[0]
    assert "dropped:" in doc["description"] and len(doc["shapes"]) == 1


def test_an_ascii_plymesh_with_a_quad_normals_and_uv(tmp_path):
    ply = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
           "property float nx\nproperty float ny\nproperty float nz\nproperty float u\nproperty float v\n"
           "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
           "0 0 0 0 0 -1 0 0\n1 0 0 0 0 -1 1 0\n1 1 0 0 0 -1 1 1\n0 1 0 0 0 -1 0 1\n4 0 1 2 3\n")
    (tmp_path / "in").mkdir(parents=True)
    (tmp_path / "in" / "quad.ply").write_text(ply)
    result, doc, scene = imported(tmp_path, HEAD + 'Shape "plymesh" "string filename" "quad.ply"\n')
    geometry = triangulate(scene)
    corners = np.asarray(geometry.vertices)[np.asarray(geometry.triangles)]
    assert corners.shape == (2, 3, 3)
    # the file's normals face -z: pbrt's front side is theirs, kept through the mirror
    assert all(np.cross(c[1] - c[0], c[2] - c[0])[2] < 0 for c in corners)
    assert "non-planar" not in doc["description"]


# ---- against the same scene written by hand --------------------------------------------------------------------------


HANDMADE_PBRT = """Scale -1 1 1
LookAt 0 1 3   0 1 0   0 1 0
Camera "perspective" "float fov" 50
Film "rgb" "integer xresolution" 12 "integer yresolution" 8
PixelFilter "triangle" "float xradius" 1 "float yradius" 1
Integrator "path" "integer maxdepth" 2
WorldBegin
LightSource "point" "rgb I" [ 3 2 1 ] "point3 from" [ 0 1.5 0 ]
LightSource "distant" "rgb L" [ 0.5 0.5 0.5 ] "point3 from" [ 1 1 0 ] "point3 to" [ 0 0 0 ]
MakeNamedMaterial "floor" "string type" "diffuse" "rgb reflectance" [ 0.6 0.5 0.4 ]
MakeNamedMaterial "metal" "string type" "conductor" "rgb eta" [ 0.2 0.9 1.1 ] "rgb k" [ 3.9 2.4 2.1 ]
  "float roughness" 0.01
NamedMaterial "floor"
Shape "trianglemesh" "integer indices" [ 0 1 2 0 2 3 ] "point3 P" [ -1 0 -1  -1 0 1  1 0 1  1 0 -1 ]
AttributeBegin
  NamedMaterial "metal"
  Translate 0.25 0.5 0
  Shape "sphere" "float radius" 0.5
AttributeEnd
"""

HANDMADE_TOML = """name = "handmade"
[camera]
origin = [0, 1, 3]
target = [0, 1, 2]
up = [0, 1, 0]
fov = 50
fov_axis = "smaller"
[film]
width = 12
height = 8
filter = "tent"
[integrator]
max_depth = 3
[materials.floor]
reflectance = [0.6, 0.5, 0.4]
two_sided = true
[materials.metal]
type = "roughconductor"
eta = [0.2, 0.9, 1.1]
k = [3.9, 2.4, 2.1]
alpha = 0.1
distribution = "ggx"
two_sided = true
[[shapes]]
type = "mesh"
file = "floor.ply"
material = "floor"
face_normals = true
[[shapes]]
type = "sphere"
material = "metal"
center = [0.25, 0.5, 0]
radius = 0.5
[[emitters]]
type = "point"
position = [0, 1.5, 0]
intensity = [3, 2, 1]
[[emitters]]
type = "directional"
direction = [-0.7071067811865475, -0.7071067811865475, 0]
irradiance = [0.5, 0.5, 0.5]
"""


def assert_same_arrays(a, b):
    assert (a is None) == (b is None)
    if a is None:
        return
    for key, value in vars(a).items():
        other = vars(b)[key]
        if isinstance(value, np.ndarray):
            np.testing.assert_array_equal(value, other, err_msg=key)
        elif hasattr(value, "__dict__"):
            assert_same_arrays(value, other)
        else:
            assert value == other, key


def test_an_imported_scene_equals_the_same_scene_written_by_hand(tmp_path):
    from harness.scene import emitter_arrays
    _, _, scene = imported(tmp_path, HANDMADE_PBRT)
    hand = tmp_path / "hand"
    hand.mkdir()
    # the floor's corners in pbrt's order, wound the way pbrt's front side (+y) is the format's
    (hand / "floor.ply").write_bytes(ply_bytes(np.array([[-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, -1.0]]),
                                               np.array([[0, 1, 2], [0, 2, 3]])))
    (hand / "scene.toml").write_text(HANDMADE_TOML)
    expected = load_scene(hand / "scene.toml")
    assert_same_arrays(triangulate(scene), triangulate(expected))
    assert_same_arrays(material_arrays(scene), material_arrays(expected))
    assert_same_arrays(emitter_arrays(scene), emitter_arrays(expected))
    assert (scene.film.width, scene.film.height, scene.film.filter) == (12, 8, "tent")
    fx, fy = np.array([0.0, 3.5, 12.0]), np.array([0.0, 4.25, 8.0])
    for got, want in zip(scene.camera.generate_rays(fx, fy, 12, 8), expected.camera.generate_rays(fx, fy, 12, 8)):
        np.testing.assert_array_equal(got, want)


def test_front_sides_follow_pbrts_rules_and_the_default_depth(tmp_path):
    """Without N: the winding's side, flipped by ReverseOrientation (and by a transform that swaps handedness); with
    N: the normals' side. The emitting quad under ReverseOrientation faces down."""
    text = HEAD + ('AttributeBegin\nAreaLightSource "diffuse" "rgb L" [ 4 4 4 ]\nReverseOrientation\n' + QUAD +
                   'AttributeEnd\n'
                   'AttributeBegin\nScale 1 1 -1\n' + QUAD + 'AttributeEnd\n'
                   'Shape "trianglemesh" "integer indices" [ 0 1 2 ] "point3 P" [ -1 0 -1  -1 0 1  1 0 1 ] '
                   '"normal N" [ 0 -1 0  0 -1 0  0 -1 0 ]\n')
    _, doc, scene = imported(tmp_path, text)
    assert doc["integrator"] == {"max_depth": 6}  # pbrt-v4's default maxdepth 5
    geometry = triangulate(scene)
    corners = np.asarray(geometry.vertices)[np.asarray(geometry.triangles)]
    ny = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 1]
    assert list(np.sign(ny)) == [-1, -1, 1, 1, -1]  # reversed light; Scale z -1 swaps handedness: pbrt keeps +y
    assert np.asarray(geometry.light_id)[:2].tolist() == [0, 0]


# ---- found on third-party files (docs/import.md, "Tried on third-party files"), each written here small -----------


def test_lenient_drops_a_material_or_light_whose_value_is_a_named_spectrum_or_a_blackbody(tmp_path):
    """pbrt-v4-scenes' Cornell boxes name metal spectra ("metal-Ag-eta") and caustic-glass lights a blackbody: the
    element is refused in one line at the parameter (strict), and lenient drops it (the material with its shapes,
    the light) where it stopped the whole file before."""
    text = HEAD + ('Material "conductor" "spectrum eta" [ "metal-Ag-eta" ] "spectrum k" [ "metal-Ag-k" ]\n' + QUAD +
                   'LightSource "spot" "blackbody I" [ 5500 ] "point3 from" [ 0 5 0 ] "point3 to" [ 0 0 0 ]\n'
                   'LightSource "point" "rgb I" [ 1 1 1 ] "point3 from" [ 0 2 0 ]\n'
                   'Material "diffuse"\n' + QUAD)
    with pytest.raises(HarnessError, match=r'scene\.pbrt:6:22: "spectrum eta": a named or sampled spectrum'):
        import_pbrt(pbrt(tmp_path, text))
    result, doc, scene = imported(tmp_path, text, lenient=True)
    assert [line.split(": ", 1)[0].rsplit("/", 1)[-1] for line in result.dropped] == [
        "scene.pbrt:6:22", "scene.pbrt:7:1", "scene.pbrt:9:20"]
    assert result.dropped[0].endswith('Material "conductor" (dropped)')
    assert "its material was refused" in result.dropped[1]
    assert result.dropped[2].endswith('"blackbody I": expected "rgb I" (the scene format is RGB): '
                                      'LightSource "spot" (dropped)')
    assert len(doc["shapes"]) == 1 and [e["type"] for e in doc["emitters"]] == ["point"]


def test_lenient_drops_a_material_whose_texture_was_dropped(tmp_path):
    """killeroo-gold's floor names a "scale" texture, which the import refuses: lenient dropped the texture and then
    stopped at the material that names it ("no such spectrum texture"); now the material goes with its shapes."""
    text = HEAD + ('Texture "half" "spectrum" "scale" "float scale" [ 0.5 ]\n'
                   'Material "diffuse" "texture reflectance" [ "half" ]\n' + QUAD +
                   'Material "diffuse"\n' + QUAD)
    result, doc, scene = imported(tmp_path, text, lenient=True)
    assert 'Texture "half" "spectrum" "scale"' in result.dropped[0]
    assert ("\"texture reflectance\": the texture 'half' was refused: Material \"diffuse\" (dropped)"
            in result.dropped[1])
    assert "its material was refused" in result.dropped[2] and len(doc["shapes"]) == 1
    with pytest.raises(HarnessError, match="no such spectrum texture 'nothing'"):
        import_pbrt(pbrt(tmp_path, HEAD + 'Material "diffuse" "texture reflectance" [ "nothing" ]\n' + QUAD),
                    lenient=True)


def test_an_explicit_default_gaussian_filter_is_read_as_no_pixel_filter(tmp_path):
    """sssdragon and ganesha write pbrt-v4's default filter out (``PixelFilter "gaussian"``): the format's
    gaussian, approximated and noted, as for no PixelFilter; another radius or sigma stays refused."""
    for line in ('PixelFilter "gaussian"', 'PixelFilter "gaussian" "float xradius" 1.5 "float sigma" 0.5'):
        _, doc, _ = imported(tmp_path, HEAD.replace('PixelFilter "box"', line) + QUAD)
        assert doc["film"]["filter"] == "gaussian"
        assert "pbrt-v4's Gaussian (radius 1.5, sigma 0.5) read as the format's gaussian" in doc["description"]
    with pytest.raises(HarnessError, match='PixelFilter "gaussian": expected box of radius 0.5'):
        import_pbrt(pbrt(tmp_path, HEAD.replace('PixelFilter "box"', 'PixelFilter "gaussian" "float sigma" 1') +
                         QUAD))


@pytest.mark.parametrize("body, message", [
    (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
     b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n",
     "its header declares 3 vertex elements but the file holds 2 (truncated, or a header that lies)"),
    (b"ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
     b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 2 0\n"
     b"5 0 1 2 3 4\n", "a face of 5 vertices (pbrt reads triangles and quads)"),
    (b"OFF\n3 1 0\n", "expected a PLY file starting with 'ply'"),
])
def test_a_bad_plymesh_is_one_line_from_the_harness_s_one_mesh_reader(tmp_path, body, message):
    """plymesh reads through harness.scene.mesh_files.read_mesh (the loader's reader): its refusals, one line."""
    (tmp_path / "in").mkdir(parents=True)
    (tmp_path / "in" / "bad.ply").write_bytes(body)
    with pytest.raises(HarnessError) as caught:
        import_pbrt(pbrt(tmp_path, HEAD + 'Shape "plymesh" "string filename" "bad.ply"\n'), lenient=True)
    assert str(caught.value).endswith(f"scene.pbrt:6:1: Shape \"plymesh\": 'bad.ply': {message}")
    assert "\n" not in str(caught.value)


def test_a_binary_plymesh_of_quads_is_read_as_the_loader_reads_it(tmp_path):
    """A binary PLY of quads (pbrt-v4-scenes' meshes) gives the loader's triangles (trimesh's split) and a
    non-planar quad is counted in the description."""
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0.5]], np.float32)
    header = (b"ply\nformat binary_little_endian 1.0\nelement vertex 6\nproperty float x\nproperty float y\n"
              b"property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n")
    faces = b"".join(bytes([4]) + np.array(q, "<i4").tobytes() for q in ([0, 1, 2, 3], [1, 4, 5, 2]))
    (tmp_path / "in").mkdir(parents=True)
    (tmp_path / "in" / "quads.ply").write_bytes(header + points.astype("<f4").tobytes() + faces)
    result, doc, scene = imported(tmp_path, HEAD + 'Scale -1 1 1\nShape "plymesh" "string filename" "quads.ply"\n')
    geometry = triangulate(scene)
    assert np.asarray(geometry.triangles).shape == (4, 3)
    assert "1 non-planar quads" in doc["description"]
