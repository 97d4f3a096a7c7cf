"""The scene format's textures (docs/scene-format.md, "Textures"): ``[textures.NAME]`` and ``{ texture = "NAME" }``
read as Mitsuba means them, every wrong one refused in one line naming the key, the texture files read through the
scene folder's confinement and held in the content key, and the texture coordinates of every shape kind as
Mitsuba 3.9.1 makes them (its own loaders and ray queries)."""

from __future__ import annotations

import dataclasses

import imageio.v3 as iio
import numpy as np
import pytest

from conftest import MINIMAL_SCENE
from harness.core.errors import HarnessError
from harness.scene import load_scene
from harness.scene.content_key import content_key
from harness.scene.primitives import cube_uv, rectangle_uv, unit_cube
from harness.scene.triangulate import object_to_world, triangulate
from reference_impl.kernels import records, surface

IMAGE = np.random.default_rng(35).integers(0, 256, size=(4, 6, 3), dtype=np.uint8)
SHAPE = '\n[[shapes]]\ntype = "{type}"\nmaterial = "{material}"\n{extra}'


def _write(folder, body: str, image: np.ndarray | None = IMAGE, name: str = "tex.png"):
    if image is not None:
        iio.imwrite(folder / name, image)
    path = folder / "scene.toml"
    path.write_text(MINIMAL_SCENE + body)
    return path


TEXTURED = """
[textures.t]
type = "bitmap"
filename = "tex.png"
filter_type = "nearest"
wrap_mode = "mirror"
to_uv = { translate = [0.25, 0.5], scale = [2.0, 3.0], rotate = 30.0 }

[textures.c]
type = "checkerboard"
color0 = 0.9
color1 = [0.1, 0.2, 0.3]

[materials.m]
reflectance = { texture = "t" }

[materials.glass]
type = "dielectric"
specular_transmittance = { texture = "c" }
""" + SHAPE.format(type="rectangle", material="m", extra="") + SHAPE.format(type="cube", material="glass", extra="")


def test_textures_are_read_with_mitsubas_names_and_defaults(tmp_path):
    scene = load_scene(_write(tmp_path, TEXTURED))
    bitmap, checker = scene.textures["t"], scene.textures["c"]
    assert (bitmap.type, bitmap.filter_type, bitmap.wrap_mode, bitmap.raw) == ("bitmap", "nearest", "mirror", False)
    np.testing.assert_array_equal(bitmap.image, IMAGE)
    angle = np.radians(30.0)
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    np.testing.assert_allclose(bitmap.to_uv, np.array([[1, 0, 0.25], [0, 1, 0.5], [0, 0, 1]]) @ rotation
                               @ np.diag([2.0, 3.0, 1.0]), atol=1e-15)
    assert (checker.color0, checker.color1) == ((0.9, 0.9, 0.9), (0.1, 0.2, 0.3))
    np.testing.assert_array_equal(checker.to_uv, np.eye(3))
    assert scene.materials["m"].textures == (("reflectance", bitmap),)
    assert scene.materials["glass"].textures == (("specular_transmittance", checker),)
    assert scene.materials["glass"].specular_transmittance == (0.9, 0.9, 0.9)  # the bound: the largest value
    assert tmp_path / "tex.png" in scene.files


def test_the_content_key_holds_the_texture_files_bytes(tmp_path):
    path = _write(tmp_path, TEXTURED)
    before = content_key(load_scene(path))
    changed = IMAGE.copy()
    changed[0, 0, 0] ^= 1
    iio.imwrite(tmp_path / "tex.png", changed)
    assert content_key(load_scene(path)) != before


REFUSALS = [
    ("unknown-texture", '[materials.m]\nreflectance = { texture = "nope" }\n', "materials.m.reflectance.texture",
     "unknown texture 'nope'"),
    ("no-texture-there", '[textures.t]\nfilename = "tex.png"\n[materials.m]\ntype = "conductor"\n'
                         'eta = { texture = "t" }\n', "materials.m.eta", "eta of a conductor takes no texture"),
    ("above-one", '[textures.t]\ntype = "checkerboard"\ncolor0 = 1.5\n[materials.m]\nreflectance = { texture = "t" }\n',
     "materials.m.reflectance", "values up to 1.5"),
    ("missing-file", '[textures.t]\nfilename = "nope.png"\n', "textures.t.filename", "no such"),
    ("suffix", '[textures.t]\nfilename = "tex.gif"\n', "textures.t.filename", ".png, .jpg, .jpeg or .exr"),
    ("filter", '[textures.t]\nfilename = "tex.png"\nfilter_type = "cubic"\n', "textures.t.filter_type", "bilinear"),
    ("wrap", '[textures.t]\nfilename = "tex.png"\nwrap_mode = "black"\n', "textures.t.wrap_mode", "repeat"),
    ("to-uv-shape", '[textures.t]\nfilename = "tex.png"\nto_uv = [[1, 0], [0, 1]]\n', "textures.t.to_uv", "3x3"),
    ("to-uv-projective", '[textures.t]\nfilename = "tex.png"\nto_uv = [[1, 0, 0], [0, 1, 0], [0, 1, 1]]\n',
     "textures.t.to_uv", "the last row [0, 0, 1]"),
    ("other-types-key", '[textures.t]\nfilename = "tex.png"\ncolor0 = 0.5\n', "textures.t.color0",
     "applies only to textures of type 'checkerboard'"),
    ("unknown-key", '[textures.t]\nfilename = "tex.png"\nfilter = "nearest"\n', "textures.t", "filter"),
    ("mesh-without-uv", '[textures.t]\nfilename = "tex.png"\n[materials.m]\nreflectance = { texture = "t" }\n'
                        + SHAPE.format(type="mesh", material="m", extra='file = "tri.ply"'),
     "shapes[0].material", "has no texture coordinates"),
    ("outside", '[textures.t]\nfilename = "../outside.png"\n', "textures.t.filename", "outside"),
]


@pytest.mark.parametrize("body,key,message", [r[1:] for r in REFUSALS], ids=[r[0] for r in REFUSALS])
def test_a_wrong_texture_is_refused_in_one_line_naming_its_key(tmp_path, body, key, message):
    folder = tmp_path / "scene"
    folder.mkdir()
    iio.imwrite(tmp_path / "outside.png", IMAGE)
    (folder / "tri.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                    "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                    "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    with pytest.raises(HarnessError) as err:
        load_scene(_write(folder, body))
    assert key in err.value.where and message in err.value.message, (err.value.where, err.value.message)
    assert "\n" not in str(err.value)


def test_a_textured_sphere_in_a_glossy_scene_is_the_analytic_sphere_in_both_renderers(tmp_path):
    """Once refused (Mitsuba got a glossy scene's spheres as icospheres, without texture coordinates): the reference
    and Mitsuba both trace the analytic sphere now, so its texture coordinates exist in both."""
    from harness.renderers.mitsuba import scene_to_mitsuba_dict

    folder = tmp_path / "scene"
    folder.mkdir()
    body = ('[textures.t]\nfilename = "tex.png"\n[materials.m]\nreflectance = { texture = "t" }\n'
            '[materials.mirror]\ntype = "conductor"\n' + SHAPE.format(type="sphere", material="m", extra=""))
    scene = load_scene(_write(folder, body))
    assert triangulate(scene).num_spheres == 1
    plugins = scene_to_mitsuba_dict(scene, "scalar_rgb")
    shape = plugins["shape_0"]
    assert shape["type"] == "sphere" and "bitmap" in repr(plugins[shape["bsdf"]["id"]])


@pytest.mark.parametrize("case", ["sixteen-bit", "corrupt", "gif-named-png", "too-large"])
def test_an_image_that_is_no_8_bit_png_or_jpeg_is_refused_in_one_line(tmp_path, case, monkeypatch):
    body = '[textures.t]\nfilename = "tex.png"\n'
    if case == "sixteen-bit":
        iio.imwrite(tmp_path / "tex.png", IMAGE[..., 0].astype(np.uint16) * 257)  # a 16-bit grey PNG
        expected = "expected an 8-bit image"
    elif case == "corrupt":
        (tmp_path / "tex.png").write_bytes(b"\x89PNG\r\n\x1a\nnot a png at all")
        expected = "cannot read the texture file"
    elif case == "gif-named-png":
        iio.imwrite(tmp_path / "tex.png", IMAGE, extension=".gif")
        expected = "expected PNG or JPEG"
    else:
        import harness.scene.kinds.textures as kinds

        monkeypatch.setattr(kinds, "MAX_TEXTURE_PIXELS", 20)  # 6 x 4 = 24 pixels
        iio.imwrite(tmp_path / "tex.png", IMAGE)
        expected = "expected at most 20 pixels"
    path = tmp_path / "scene.toml"
    path.write_text(MINIMAL_SCENE + body)
    with pytest.raises(HarnessError) as err:
        load_scene(path)
    assert err.value.where.endswith("textures.t.filename") and expected in err.value.message, err.value.message


# ---- texture coordinates as Mitsuba makes them ------------------------------------------------------------------


@pytest.fixture()
def mi():
    mitsuba = pytest.importorskip("mitsuba")
    mitsuba.set_variant("scalar_rgb")
    return mitsuba


def _mesh_corner_uv(mi, plugin: dict) -> np.ndarray:
    """(T, 3, 2): Mitsuba's texture coordinates at the corners of each face of a mesh it loaded itself."""
    mesh = mi.load_dict(plugin)
    params = mi.traverse(mesh)
    uv = np.array(params["vertex_texcoords"], dtype=np.float64).reshape(-1, 2)
    faces = np.array(params["faces"], dtype=np.int64).reshape(-1, 3)
    positions = np.array(params["vertex_positions"], dtype=np.float64).reshape(-1, 3)
    return positions[faces], uv[faces]


MESH_UV = np.array([[0.1, 0.2], [0.9, 0.25], [0.7, 0.8], [0.15, 0.95]])


@pytest.mark.parametrize("kind", ["ply-uv", "ply-st", "ply-texture-uv", "obj", "obj-unflipped"])
def test_a_mesh_files_texture_coordinates_are_mitsubas(tmp_path, mi, kind):
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.2], [0, 1, 0]], dtype=np.float64)
    faces = [[0, 1, 2], [0, 2, 3]]
    extra, plugin = "", {}
    if kind.startswith("ply"):
        names = {"ply-uv": ("u", "v"), "ply-st": ("s", "t"), "ply-texture-uv": ("texture_u", "texture_v")}[kind]
        header = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                  f"property float {names[0]}\nproperty float {names[1]}\nelement face 2\n"
                  "property list uchar int vertex_indices\nend_header\n")
        body = "".join(f"{p[0]} {p[1]} {p[2]} {t[0]} {t[1]}\n" for p, t in zip(vertices, MESH_UV))
        (tmp_path / "m.ply").write_text(header + body + "".join(f"3 {a} {b} {c}\n" for a, b, c in faces))
        name, plugin = "m.ply", {"type": "ply"}
    else:
        lines = [f"v {p[0]} {p[1]} {p[2]}" for p in vertices] + [f"vt {t[0]} {t[1]}" for t in MESH_UV]
        lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
        (tmp_path / "m.obj").write_text("\n".join(lines) + "\n")
        name, plugin = "m.obj", {"type": "obj"}
        if kind == "obj-unflipped":
            extra, plugin["flip_tex_coords"] = "flip_tex_coords = false", False
    path = _write(tmp_path, '[textures.t]\nfilename = "tex.png"\n[materials.m]\nreflectance = { texture = "t" }\n'
                  + SHAPE.format(type="mesh", material="m", extra=f'file = "{name}"\n{extra}'))
    scene = load_scene(path)
    geometry = triangulate(scene)
    corners, uv = _mesh_corner_uv(mi, {**plugin, "filename": str(tmp_path / name)})
    # the same triangles, corner for corner (Mitsuba keeps the file's order here), the same coordinates
    np.testing.assert_allclose(geometry.corners, corners, atol=1e-6)
    np.testing.assert_allclose(geometry.uv, uv, atol=1e-6)


def test_a_cubes_texture_coordinates_are_mitsubas(mi):
    params = mi.traverse(mi.load_dict({"type": "cube"}))
    positions = np.array(params["vertex_positions"], dtype=np.float64).reshape(-1, 3)
    normals = np.array(params["vertex_normals"], dtype=np.float64).reshape(-1, 3)
    texcoords = np.array(params["vertex_texcoords"], dtype=np.float64).reshape(-1, 2)
    vertices, _ = unit_cube()
    ours = cube_uv(vertices)
    for face in range(6):
        normal = vertices[4 * face:4 * face + 4].mean(axis=0)
        for p, uv in zip(vertices[4 * face:4 * face + 4], ours[4 * face:4 * face + 4]):
            match = np.flatnonzero(np.all(np.abs(positions - p) < 1e-6, axis=1)
                                   & np.all(np.abs(normals - normal) < 1e-6, axis=1))
            assert len(match) == 1
            np.testing.assert_allclose(texcoords[match[0]], uv, atol=1e-7)


def _mitsuba_uv(mi, plugin: dict, origins: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's hit points and texture coordinates of rays from ``origins`` toward ``targets``."""
    scene = mi.load_dict({"type": "scene", "shape": plugin})
    points, uvs = [], []
    for o, t in zip(origins, targets):
        d = (t - o) / np.linalg.norm(t - o)
        si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*o), mi.Vector3f(*d)))
        assert si.is_valid()
        points.append(np.array(si.p, dtype=np.float64))
        uvs.append(np.array(si.uv, dtype=np.float64))
    return np.array(points), np.array(uvs)


def test_a_rectangles_and_a_spheres_texture_coordinates_are_mitsubas(tmp_path, mi):
    body = ('[textures.t]\nfilename = "tex.png"\n[materials.m]\nreflectance = { texture = "t" }\n'
            + SHAPE.format(type="rectangle", material="m", extra='translate = [0.5, 0, 0]\nrotate = { axis = [1, 1, 0]'
                                                                 ', angle = 30 }\nscale = [0.7, 1.3, 1]')
            + SHAPE.format(type="sphere", material="m", extra='center = [-1, 0.2, 0]\nradius = 0.6\nsubdivisions = 5\n'
                                                              'rotate = { axis = [0, 1, 1], angle = 70 }'))
    scene = load_scene(_write(tmp_path, body))
    geometry = triangulate(scene)
    tables = records.scene_tables(geometry, np.arange(len(geometry.triangles)), textured=True)
    g = np.random.default_rng(1)
    for index, plugin_type in ((0, "rectangle"), (1, "sphere")):
        shape = scene.shapes[index]
        matrix = object_to_world(shape)
        triangles = np.flatnonzero(np.repeat(np.arange(len(scene.shapes)),
                                             [2, len(geometry.triangles) - 2]) == index)
        picked = g.choice(triangles, size=40)
        weights = g.dirichlet(np.ones(3), size=40)
        points = np.einsum("ij,ijk->ik", weights, geometry.corners[picked])
        if plugin_type == "sphere":  # from the centre outward: Mitsuba's hit is the facet point's direction
            centre = matrix[:3, 3]
            origins, targets = np.repeat(centre[None], 40, axis=0), centre + 2.0 * (points - centre)
            plugin = {"type": "sphere", "to_world": mi.ScalarTransform4f(matrix.tolist())}
        else:
            normal = geometry.normal[picked]
            origins, targets = points + normal, points
            plugin = {"type": "rectangle", "to_world": mi.ScalarTransform4f(matrix.tolist())}
        _, uv = _mitsuba_uv(mi, plugin, origins, targets)
        for n, tri in enumerate(picked):
            ours = surface.texture_coordinates(tables, tri, weights[n, 1], weights[n, 2], *points[n])
            np.testing.assert_allclose(ours, uv[n], atol=2e-6)
    np.testing.assert_array_equal(rectangle_uv(np.array([[-1.0, -1.0, 0], [1.0, 1.0, 0]])), [[0, 0], [1, 1]])


def test_a_sliver_variant_keeps_the_rectangles_texture_coordinates(tmp_path):
    from harness.scene.variants import sliver_walls

    scene = load_scene(_write(tmp_path, '[textures.t]\nfilename = "tex.png"\n[materials.m]\n'
                                        'reflectance = { texture = "t" }\n'
                              + SHAPE.format(type="rectangle", material="m", extra="")))
    sliced = sliver_walls(scene, 50.0)
    geometry = triangulate(sliced)
    local = geometry.corners[..., :2]  # the unit rectangle at the identity: uv = (p + 1) / 2
    np.testing.assert_allclose(geometry.uv, (local + 1.0) / 2.0, atol=1e-12)
    assert dataclasses.replace(sliced.shapes[0]).mesh_uv is not None


# ---- a textured area light ---------------------------------------------------------------------------------------

LIGHT = ('[textures.t]\nfilename = "tex.png"\n'
         + SHAPE.format(type="rectangle", material="white", extra='emission = { texture = "t" }\nscale = 0.5'))


def test_a_lights_emission_may_be_a_texture_looked_up_at_each_point(tmp_path):
    from reference_impl.kernels import texture
    from harness.scene.material_arrays import material_arrays

    scene = load_scene(_write(tmp_path, LIGHT))
    shape = scene.shapes[0]
    assert shape.emission_texture is scene.textures["t"] and shape.is_emitter
    np.testing.assert_allclose(shape.emission, scene.textures["t"].mean_value)
    geometry = triangulate(scene)
    materials = material_arrays(scene)
    tables = records.scene_tables(geometry, np.arange(len(geometry.triangles)), textured=False)
    texture_tables = records.material_tables(materials).textures
    g = np.random.default_rng(2)
    for _ in range(30):
        tri = int(g.integers(2))
        w = g.dirichlet(np.ones(3))
        x = w @ geometry.corners[tri]
        uv = w @ geometry.uv[tri]
        le = surface.emission_at(tables, texture_tables, tri, *x, 0)
        np.testing.assert_allclose(le, texture.evaluate(texture_tables, 0, uv[None])[0], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("emission,message", [
    ('{ texture = "black" }', "not all 0"), ('{ texture = "nope" }', "unknown texture 'nope'")])
def test_a_lights_texture_that_emits_nothing_or_is_missing_is_refused(tmp_path, emission, message):
    body = ('[textures.black]\ntype = "checkerboard"\ncolor0 = 0\ncolor1 = 0\n'
            + SHAPE.format(type="rectangle", material="white", extra=f"emission = {emission}"))
    with pytest.raises(HarnessError) as err:
        load_scene(_write(tmp_path, body))
    assert "shapes[0].emission" in err.value.where and message in err.value.message


def test_a_checkerboard_brighter_than_1_as_a_lights_emission_is_refused(tmp_path):
    """Mitsuba 3.9.1's checkerboard takes colours in [0, 1] only (scalar_rgb refuses 2.0 as "Invalid RGB reflectance
    value"), also as an area light's radiance: the scene is refused at load, not at its ground truth."""
    body = ('[textures.bright]\ntype = "checkerboard"\ncolor0 = [2.0, 1.5, 1.0]\ncolor1 = 0.1\n'
            + SHAPE.format(type="rectangle", material="white", extra='emission = { texture = "bright" }'))
    with pytest.raises(HarnessError) as err:
        load_scene(_write(tmp_path, body))
    assert "shapes[0].emission" in err.value.where and "colours up to 2" in err.value.message
    assert "\n" not in str(err.value)
    load_scene(_write(tmp_path, body.replace("color0 = [2.0, 1.5, 1.0]", "color0 = [1.0, 0.75, 0.5]")))


def test_the_wavefront_refuses_a_textured_light_in_one_line(tmp_path):
    from reference_impl import Settings, render
    from reference_impl.errors import SettingsError
    from harness.scene.material_arrays import material_arrays

    scene = load_scene(_write(tmp_path, LIGHT))
    with pytest.raises(SettingsError, match="path loop alone"):
        render(triangulate(scene), scene.camera, scene.film, Settings(spp=1, max_depth=2, indirect_rays=2),
               materials=material_arrays(scene))


def test_a_rough_materials_alpha_may_be_a_bitmap_taken_as_its_luminance(tmp_path):
    from harness.scene.material_arrays import material_arrays
    from reference_impl.materials import TEXTURE_SLOTS

    grey = np.full((2, 2, 3), 90, dtype=np.uint8)
    body = ('[textures.t]\nfilename = "tex.png"\n[materials.m]\ntype = "roughconductor"\nalpha = { texture = "t" }\n'
            + SHAPE.format(type="rectangle", material="m", extra=""))
    scene = load_scene(_write(tmp_path, body, image=grey))
    material = scene.materials["m"]
    low, high = scene.textures["t"].scalar_range
    assert material.textures == (("alpha", scene.textures["t"]),) and material.alpha == high == low
    table = material_arrays(scene)
    assert table.texture[list(scene.materials).index("m"), list(TEXTURE_SLOTS).index("alpha")] == 0


@pytest.mark.parametrize("texture,message", [
    ('type = "checkerboard"\ncolor0 = 0.3\ncolor1 = 0.1', "alpha takes a bitmap"),
    ('filename = "tex.png"', "luminances from")])
def test_an_alpha_texture_that_mitsuba_reads_otherwise_or_out_of_range_is_refused(tmp_path, texture, message):
    black = np.zeros((2, 2, 3), dtype=np.uint8)  # luminance 0: alpha must be >= 1e-4
    body = (f'[textures.t]\n{texture}\n[materials.m]\ntype = "roughdielectric"\nalpha = {{ texture = "t" }}\n')
    with pytest.raises(HarnessError) as err:
        load_scene(_write(tmp_path, body, image=black))
    assert err.value.where.endswith("materials.m.alpha") and message in err.value.message, err.value.message
