"""Shading normals and normal maps through ``harness export``'s glTF and OBJ (docs/external-renderers.md, "Shading
normals and normal maps"), read back with pygltflib and a small OBJ parser of this file: every vertex normal equal
to the scene's (:func:`harness.scene.triangulate.vertex_normals`) to float32 (glTF) or float64 (OBJ), flat shapes
without normals, a normal map's image, sampler and transform those of the scene, glTF's tangent frame Mitsuba's
(s = dp/du made perpendicular to n, t = n x s, computed here from the positions and coordinates read back), and the
bump map, which neither format has, named as a loss."""

from __future__ import annotations

import math
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pygltflib
import pytest
import trimesh
from trimesh.exchange.obj import parse_mtl
from trimesh.resolvers import FilePathResolver

from harness.files.imageio import write_exr
from harness.renderers.export import export_losses, export_scene
from harness.renderers.meshfiles import ply_bytes
from harness.scene import load_scene
from harness.scene.triangulate import shape_triangles, vertex_normals
from test_export_exact import _trs, check_image_and_sampler

ROOT = Path(__file__).resolve().parents[2]


# ---- readers --------------------------------------------------------------------------------------------------------


def _accessor(gltf: pygltflib.GLTF2, folder: Path, index: int) -> np.ndarray:
    """The data of accessor ``index`` (float32 VEC2/3/4 or uint32 SCALAR, tightly packed) from its buffer."""
    accessor = gltf.accessors[index]
    view = gltf.bufferViews[accessor.bufferView]
    data = (folder / gltf.buffers[view.buffer].uri).read_bytes()
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[accessor.type]
    dtype = {pygltflib.FLOAT: "<f4", pygltflib.UNSIGNED_INT: "<u4"}[accessor.componentType]
    values = np.frombuffer(data, dtype=dtype, count=accessor.count * width,
                           offset=view.byteOffset + (accessor.byteOffset or 0))
    return values.reshape(accessor.count, width) if width > 1 else values


def _gltf(scene, folder: Path) -> tuple[pygltflib.GLTF2, list]:
    """The scene exported as glTF into ``folder`` and read back: the document and (shape, node, primitive) per shape."""
    files = export_scene(scene, "gltf", folder)
    gltf = pygltflib.GLTF2().load(str(files[0]))
    nodes = [n for n in gltf.nodes if n.mesh is not None]
    assert len(nodes) == len(scene.shapes)
    return gltf, [(s, n, gltf.meshes[n.mesh].primitives[0]) for s, n in zip(scene.shapes, nodes)]


def _obj_objects(text: str) -> list[dict]:
    """An OBJ file's ``o`` objects in order, each {"v", "vt", "vn": its own lines' values (float64), "faces": (T, 3,
    3) int64 global 1-based (v, vt, vn) indices, 0 where a corner has none}."""
    objects: list[dict] = []
    for line in text.splitlines():
        head, *rest = line.split() or [""]
        if head == "o":
            objects.append({"v": [], "vt": [], "vn": [], "faces": []})
        elif head in ("v", "vt", "vn"):
            objects[-1][head].append([float(x) for x in rest])
        elif head == "f":
            assert len(rest) == 3, line  # triangles only
            objects[-1]["faces"].append([[int(x) if x else 0 for x in (c.split("/") + ["", ""])[:3]] for c in rest])
    for obj in objects:
        obj["faces"] = np.array(obj["faces"], dtype=np.int64).reshape(-1, 3, 3)
    return objects


def _scene_normals(shape) -> np.ndarray | None:
    """The normals the shape is shaded with in the scene: its vertex normals, or None where it is flat (an emitting
    shape is flat, as the reference and scene.json take it)."""
    vertices, triangles = shape_triangles(shape)
    return None if shape.is_emitter else vertex_normals(shape, vertices, triangles)


# ---- Mitsuba's tangent frame, computed here from what a reader gets -------------------------------------------------


def mitsuba_frames(corners: np.ndarray, corner_uv: np.ndarray, corner_normals: np.ndarray) -> tuple[np.ndarray, ...]:
    """Mitsuba's (s, t) at each triangle's corners (T, 3, 3) from the corners' positions, texture coordinates and
    shading normals: dp/du from the triangle's edges and coordinates, s = normalize(dp/du - n (n . dp/du)), t = n x s
    (docs/mitsuba.md, "Shading normals, normal maps and bump maps"); and dp/dv (T, 3)."""
    p = np.asarray(corners, np.float64)
    c = np.asarray(corner_uv, np.float64)
    n = np.asarray(corner_normals, np.float64)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    du1, dv1 = c[:, 1, 0] - c[:, 0, 0], c[:, 1, 1] - c[:, 0, 1]
    du2, dv2 = c[:, 2, 0] - c[:, 0, 0], c[:, 2, 1] - c[:, 0, 1]
    det = du1 * dv2 - dv1 * du2
    assert np.all(det != 0)
    dpdu = (dv2[:, None] * e1 - dv1[:, None] * e2) / det[:, None]
    dpdv = (-du2[:, None] * e1 + du1[:, None] * e2) / det[:, None]
    s = dpdu[:, None] - n * np.sum(n * dpdu[:, None], axis=-1, keepdims=True)
    s /= np.linalg.norm(s, axis=-1, keepdims=True)
    return s, np.cross(n, s), dpdv


def check_gltf_frame(gltf, folder: Path, primitive, corner_normals: np.ndarray, label: str) -> dict[str, float]:
    """A normal-mapped primitive's NORMAL and TANGENT against Mitsuba's frame (``corner_normals``: the scene's shading
    normal at each triangle's corners, (T, 3, 3)); returns the largest differences."""
    indices = _accessor(gltf, folder, primitive.indices).reshape(-1, 3)
    corners = _accessor(gltf, folder, primitive.attributes.POSITION)[indices]
    uv = _accessor(gltf, folder, primitive.attributes.TEXCOORD_0)[indices]
    assert primitive.attributes.NORMAL is not None and primitive.attributes.TANGENT is not None, label
    normals = _accessor(gltf, folder, primitive.attributes.NORMAL)[indices]
    tangents = _accessor(gltf, folder, primitive.attributes.TANGENT)[indices]
    # NORMAL at every corner: the scene's shading normal (the vertex normal, or a flat shape's facet normal) to
    # float32. glTF ignores TANGENT without NORMAL, so a flat normal-mapped shape needs them too. Catches a corner
    # that took another triangle's normal when the vertices were split, or the facet normal of a smooth shape.
    np.testing.assert_array_equal(normals, np.float32(corner_normals), err_msg=label)
    # w = +1 everywhere: glTF's bitangent cross(NORMAL, TANGENT) w is then Mitsuba's t = n x s, and the green of the
    # map (+y) leans the normal the way it does in Mitsuba. Catches w = -1 (glTF readers would invert the green, the
    # counterpart of the reference's planted fault "normalmap-green-inverted").
    assert np.all(tangents[..., 3] == 1.0), label
    s, t, dpdv = mitsuba_frames(corners, uv, corner_normals)
    # TANGENT = s at every corner (computed here from the float32 positions and coordinates read back, hence the
    # tolerance). Catches a tangent from v instead of u, an unnormalised or un-orthogonalised dp/du, one vertex's
    # tangent shared by triangles whose dp/du differ.
    tangent_error = float(np.abs(tangents[..., :3] - s).max())
    assert tangent_error < 2e-6, (label, tangent_error)
    bitangent = np.cross(normals.astype(np.float64), tangents[..., :3].astype(np.float64)) * tangents[..., 3:]
    bitangent_error = float(np.abs(bitangent - t).max())
    assert bitangent_error < 2e-6, (label, bitangent_error)
    assert np.abs(np.linalg.norm(tangents[..., :3], axis=-1) - 1.0).max() < 1e-6  # glTF wants unit tangents
    return {"normal": float(np.abs(normals - corner_normals).max()), "tangent": tangent_error,
            "bitangent": bitangent_error, "green_along_v": float(np.sign(np.sum(bitangent * dpdv[:, None], -1)).min())}


def check_normal_texture(gltf, folder: Path, info, texture) -> None:
    """A ``normalTexture``: texCoord 0, glTF's default scale (n = normalize(2 rgb - 1), as Mitsuba's), the scene's
    codes bit for bit (catches an sRGB encoding, a flipped green or row order, a rounding through floats), the
    sampler (filter and wrap mode) and ``to_uv`` as KHR_texture_transform (the same matrix)."""
    assert info is not None and info.texCoord == 0 and info.scale in (None, 1.0)
    image = check_image_and_sampler(gltf, folder, info, texture)
    transform = (info.extensions or {}).get("KHR_texture_transform")
    if np.array_equal(texture.to_uv, np.eye(3)):
        assert transform is None
    else:
        np.testing.assert_allclose(_trs(transform), texture.to_uv, rtol=0, atol=1e-15 * np.abs(texture.to_uv).max())
        assert "KHR_texture_transform" in gltf.extensionsUsed
    assert gltf.asset.extras["textures"][texture.name]["filename"] == image.uri


# ---- smooth shading -------------------------------------------------------------------------------------------------


def test_gltf_carries_the_vertex_normals_of_smooth_shapes(tmp_path):
    scene = load_scene(ROOT / "scenes" / "smooth-twins.toml")
    gltf, shapes = _gltf(scene, tmp_path)
    smooth = []
    for shape, _node, primitive in shapes:
        want = _scene_normals(shape)
        if want is None:
            # flat (the face_normals egg, the floor, the light): no NORMAL, so glTF's readers MUST shade flat with
            # the facets' own normals, Mitsuba's face normals. Catches normals written for a face_normals mesh.
            assert primitive.attributes.NORMAL is None and primitive.attributes.TANGENT is None, shape.name
            continue
        smooth.append(shape.name)
        normals = _accessor(gltf, tmp_path, primitive.attributes.NORMAL)
        positions = _accessor(gltf, tmp_path, primitive.attributes.POSITION)
        vertices, triangles = shape_triangles(shape)
        # one normal per vertex in POSITION's order, the vertices and triangles unchanged
        np.testing.assert_array_equal(positions, np.float32(vertices))
        np.testing.assert_array_equal(_accessor(gltf, tmp_path, primitive.indices).reshape(-1, 3), triangles)
        # the scene's world-space normals to float32. Catches object-space normals (the eggs are turned 30 degrees),
        # a lost flip_normals, area-weighted normals where Mitsuba's are angle-weighted (1e-2 apart), reordering
        np.testing.assert_array_equal(normals, np.float32(want), err_msg=shape.name)
        assert np.abs(np.linalg.norm(normals, axis=1) - 1.0).max() < 1e-6  # glTF wants unit normals
        assert primitive.attributes.TANGENT is None  # no normal map, no tangents
    assert smooth == ["smooth-egg", "computed-egg"]
    # the two sources of the normals, computed here without the harness: the file's own normals turned 30 degrees
    # about z (the PLY's float32), and trimesh's angle-weighted normals of the bare egg's triangles. Catches
    # vertex_normals itself ignoring the file's normals or weighting by area.
    by_name = {s.name: (s, p) for s, _n, p in shapes}
    turn = math.radians(30.0)
    rotation = np.array([[math.cos(turn), -math.sin(turn), 0], [math.sin(turn), math.cos(turn), 0], [0, 0, 1]])
    file_normals = trimesh.load(ROOT / "scenes" / "meshes" / "blob.ply", process=False).vertex_normals @ rotation.T
    read = _accessor(gltf, tmp_path, by_name["smooth-egg"][1].attributes.NORMAL)
    assert np.abs(read - file_normals).max() < 1e-6
    vertices, triangles = shape_triangles(by_name["computed-egg"][0])
    computed = trimesh.Trimesh(vertices, triangles, process=False).vertex_normals
    assert np.abs(_accessor(gltf, tmp_path, by_name["computed-egg"][1].attributes.NORMAL) - computed).max() < 1e-6
    # and the smooth normals are not the facets': the largest angle between a vertex normal and its facets' is
    # degrees, so flat shading would show
    facets = trimesh.Trimesh(vertices, triangles, process=False).face_normals
    assert np.degrees(np.arccos(np.clip(np.sum(computed[triangles] * facets[:, None], -1), -1, 1))).max() > 5.0


def test_a_glossy_spheres_icosphere_carries_the_spheres_normals_and_a_diffuse_ones_none(tmp_path):
    """The icosphere every export carries for a sphere: where its material is not diffuse (cornell-box-specular's
    mirror and glass balls) glTF ``NORMAL`` and OBJ ``vn`` are the sphere's analytic normals at its vertices, each
    vertex's direction from the centre (so a reader's mirror ball shows no facets); a diffuse sphere (the white
    furnace's) carries none. Catches normals left off a glossy sphere, or put on a diffuse one."""
    glossy = load_scene(ROOT / "scenes" / "cornell-box-specular.toml")
    gltf, shapes = _gltf(glossy, tmp_path / "gltf")
    balls = [(shape, primitive) for shape, _node, primitive in shapes if shape.type == "sphere"]
    assert len(balls) == 2
    for shape, primitive in balls:
        vertices, _triangles = shape_triangles(shape)
        radial = (vertices - np.asarray(shape.center)) / np.linalg.norm(vertices - np.asarray(shape.center), axis=1,
                                                                         keepdims=True)
        np.testing.assert_allclose(_accessor(gltf, tmp_path / "gltf", primitive.attributes.NORMAL), radial,
                                   rtol=0, atol=1e-7, err_msg=shape.name)
    text = export_scene(glossy, "obj", tmp_path / "obj")[0].read_text()
    for shape, obj in zip(glossy.shapes, _obj_objects(text)):
        if shape.type == "sphere":
            vertices = np.array(obj["v"])
            radial = (vertices - np.asarray(shape.center))
            np.testing.assert_allclose(np.array(obj["vn"]), radial / np.linalg.norm(radial, axis=1, keepdims=True),
                                       rtol=0, atol=1e-6, err_msg=shape.name)
    diffuse = load_scene(ROOT / "scenes" / "white-furnace.toml")
    _gltf_doc, [(_shape, _node, primitive)] = _gltf(diffuse, tmp_path / "diffuse")
    assert primitive.attributes.NORMAL is None


def test_obj_carries_the_vertex_normals_of_smooth_shapes(tmp_path):
    scene = load_scene(ROOT / "scenes" / "smooth-twins.toml")
    files = export_scene(scene, "obj", tmp_path)
    text = files[0].read_text()
    objects = _obj_objects(text)
    assert len(objects) == len(scene.shapes)
    v_start = vn_start = 1
    for shape, obj in zip(scene.shapes, objects):
        vertices, triangles = shape_triangles(shape)
        want = _scene_normals(shape)
        faces = obj["faces"]
        # the geometry as it was: each corner's v the triangle's vertex, float64 exact
        np.testing.assert_array_equal(faces[..., 0] - v_start, triangles)
        np.testing.assert_array_equal(np.array(obj["v"]), vertices)
        assert np.all(faces[..., 1] == 0)  # no textures in this scene: faces v//vn or v
        if want is None:
            # flat: no vn and faces without them, as the OBJ export has always written flat shapes (a reader decides:
            # most shade such a face flat; Mitsuba's OBJ loader computes smooth normals unless face_normals = true)
            assert obj["vn"] == [] and np.all(faces[..., 2] == 0), shape.name
        else:
            # one vn per vertex, each corner's vn the one of its own vertex: the scene's normal as full-precision
            # decimals (float64 exact). Catches a vn index offset by another object's normals, a corner pointing at
            # another vertex's normal, object-space or rounded normals
            assert len(obj["vn"]) == len(vertices)
            np.testing.assert_array_equal(faces[..., 2] - vn_start, triangles)
            np.testing.assert_array_equal(np.array(obj["vn"])[faces[..., 2] - vn_start], want[triangles])
            vn_start += len(obj["vn"])
        v_start += len(vertices)
    # trimesh reads the file (the faces mix v//vn and v) with the same triangles
    loaded = trimesh.load(files[0], process=False, force="scene")
    assert sum(len(g.faces) for g in loaded.geometry.values()) == sum(len(shape_triangles(s)[1]) for s in scene.shapes)


# ---- normal and bump maps -------------------------------------------------------------------------------------------


def test_gltf_carries_the_normal_map_and_names_the_bump_map(tmp_path):
    scene = load_scene(ROOT / "scenes" / "mapped-plates.toml")
    gltf, shapes = _gltf(scene, tmp_path)
    kinds = {}
    for shape, node, primitive in shapes:
        material = scene.materials[shape.material]
        p = material.perturbation
        entry = gltf.materials[primitive.material]
        kinds[shape.name] = None if p is None else p.type
        if p is not None:  # the map's Mitsuba keys for a reader that wants them (its texture in asset.extras)
            expected = {"type": p.type, "flip_invalid_normals": True, "use_shadowing_function": True,
                        ("normalmap" if p.type == "normalmap" else "texture"): {"texture": p.texture.name}}
            if p.type == "bumpmap":
                expected["scale"] = 0.2
            assert node.extras["perturbation"] == expected
        if p is None or p.type == "bumpmap":
            # no normal map: no normalTexture, and a flat rectangle keeps no NORMAL and no TANGENT
            assert entry.normalTexture is None, shape.name
            assert primitive.attributes.NORMAL is None and primitive.attributes.TANGENT is None, shape.name
            continue
        check_normal_texture(gltf, tmp_path, entry.normalTexture, p.texture)
        # the file in scenes/ holds the same codes (the scene reads it raw, as glTF reads a normal texture)
        np.testing.assert_array_equal(iio.imread(ROOT / "scenes" / "textures" / "bumps-normal.png")[..., :3],
                                      p.texture.image)
        vertices, triangles = shape_triangles(shape)
        facet = np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                         vertices[triangles[:, 2]] - vertices[triangles[:, 0]])
        facet /= np.linalg.norm(facet, axis=1, keepdims=True)
        errors = check_gltf_frame(gltf, tmp_path, primitive, np.repeat(facet[:, None], 3, axis=1), shape.name)
        # the plate's frame is (x, y, z): s = +x (u grows with x), t = +y (v grows with y: the image's top row at
        # y = -1), so the map's green (+y) leans the normal toward the light at +y, as in Mitsuba
        tangents = _accessor(gltf, tmp_path, primitive.attributes.TANGENT)
        np.testing.assert_array_equal(tangents, np.tile([1.0, 0.0, 0.0, 1.0], (len(tangents), 1)))
        assert errors["green_along_v"] == 1.0
        # the plate's vertices are not split (its two triangles share their frame)
        np.testing.assert_array_equal(_accessor(gltf, tmp_path, primitive.attributes.POSITION), np.float32(vertices))
    assert kinds == {"normal-plate": "normalmap", "bump-plate": "bumpmap", "light": None}
    assert [t.name for t in gltf.textures] == ["bumps"]  # the bump map's height is no glTF texture
    losses = export_losses(scene, "gltf")
    # the bump map, which glTF has no form for, named with its material and scale (catches it dropped silently)
    assert sum("no bump map" in line and "ridges (bump-mapped, scale 0.2)" in line for line in losses) == 1, losses
    # Mitsuba's shadow terminator and flip of invalid normals, which glTF has not, named for the normal map
    assert sum("shadow terminator" in line and "bumps (normal-mapped)" in line for line in losses) == 1, losses


def test_obj_carries_the_normal_map_as_norm_and_names_the_bump_map(tmp_path):
    scene = load_scene(ROOT / "scenes" / "mapped-plates.toml")
    files = export_scene(scene, "obj", tmp_path)
    assert [f.relative_to(tmp_path).as_posix() for f in files] == ["scene.obj", "scene.mtl",
                                                                    "textures/texture-bumps-green-up.png"]
    materials = parse_mtl((tmp_path / "scene.mtl").read_text(), resolver=FilePathResolver(str(tmp_path)))
    codes = scene.textures["bumps"].image
    assert materials["normal-mapped"]["norm"] == ["textures/texture-bumps-green-up.png"]
    # the green inverted, red and blue as they are: 255 - G is exactly -y of y = 2 G / 255 - 1, the normal a reader
    # whose bitangent runs along OBJ's v (up) needs to see Mitsuba's; catches the codes written as they are (the
    # normal mirrored toward -y), or a rounding through floats
    written = iio.imread(tmp_path / "textures" / "texture-bumps-green-up.png")
    np.testing.assert_array_equal(written[..., [0, 2]], codes[..., [0, 2]])
    np.testing.assert_array_equal(written[..., 1], 255 - codes[..., 1])
    np.testing.assert_allclose(2.0 * written[..., 1] / 255 - 1, -(2.0 * codes[..., 1] / 255 - 1), rtol=0, atol=1e-15)
    # no MTL bump anywhere: three.js, assimp and tinyobjloader read it as a height, Blender as a normal map
    assert not any(key in m for m in materials.values() for key in ("bump", "map_bump", "map_kn")), materials
    # the reader's bitangent (along vt's v, up) is -t on the plate, Mitsuba's t = n x s = +y: so the inverted green
    objects = _obj_objects(files[0].read_text())
    plate = objects[[s.name for s in scene.shapes].index("normal-plate")]
    vertices, triangles = shape_triangles(scene.shapes[0])
    vt = np.array(plate["vt"])[plate["faces"][..., 1] - plate["faces"][..., 1].min()]
    s, t, _dpdv = mitsuba_frames(vertices[triangles], np.stack([vt[..., 0], 1 - vt[..., 1]], -1),
                                 np.tile([0.0, 0.0, 1.0], (len(triangles), 3, 1)))
    _s, _t, dpdv_obj = mitsuba_frames(vertices[triangles], vt, np.tile([0.0, 0.0, 1.0], (len(triangles), 3, 1)))
    assert np.all(np.sum(t * dpdv_obj[:, None], axis=-1) < 0)
    assert all(obj["vn"] == [] for obj in objects)  # every shape here is flat
    losses = export_losses(scene, "obj")
    assert sum("no bump map" in line and "ridges (bump-mapped, scale 0.2)" in line for line in losses) == 1, losses
    assert sum("OBJ has no tangents" in line and "bumps (normal-mapped)" in line for line in losses) == 1, losses
    assert not any("have mirrored" in line for line in losses)  # the plate's coordinates are not mirrored


# ---- what the canonical scenes lack: a smooth normal-mapped mesh, a transformed map, a cube, a float map -----------

MAPPED = """
name = "mapped-mix"
[camera]
origin = [0.0, -4.0, 3.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 40.0
[film]
width = 8
height = 6
[textures.turned]
filename = "normals.png"
raw = true
filter_type = "nearest"
wrap_mode = "mirror"
to_uv = { translate = [0.25, -0.5], rotate = 30.0, scale = [2.0, 3.0] }
[textures.plain]
filename = "normals.png"
raw = true
[textures.float]
filename = "normals.exr"
raw = true
[materials.grey]
reflectance = [0.5, 0.5, 0.5]
[materials.turned]
type = "normalmap"
normalmap = { texture = "turned" }
bsdf = "grey"
use_shadowing_function = false
flip_invalid_normals = false
[materials.plain]
type = "normalmap"
normalmap = { texture = "plain" }
bsdf = "grey"
[materials.float]
type = "normalmap"
normalmap = { texture = "float" }
bsdf = "grey"
[[shapes]]
name = "dome"
type = "mesh"
file = "dome.ply"
material = "turned"
rotate = { axis = [0.0, 0.0, 1.0], angle = 20.0 }
[[shapes]]
name = "box"
type = "cube"
material = "plain"
translate = [1.5, 0.0, 0.0]
scale = 0.3
[[shapes]]
name = "sheet"
type = "rectangle"
material = "float"
translate = [-1.5, 0.0, 0.0]
"""


@pytest.fixture(scope="module")
def mapped_mix(tmp_path_factory) -> Path:
    """A smooth dome (a 4 x 4 grid on a paraboloid with bent texture coordinates, so each triangle has its own
    dp/du, and no normals in the file: Mitsuba's angle-weighted ones) under a normal map with a rotated, scaled and
    translated to_uv, nearest filtering and mirror wrapping, without the shadow terminator; a normal-mapped cube
    (flat, its faces' coordinates mirrored in Mitsuba's sense); a rectangle with a float (EXR) normal map."""
    folder = tmp_path_factory.mktemp("mapped-mix")
    x, y = np.meshgrid(np.linspace(-1, 1, 5), np.linspace(-1, 1, 5))
    x, y = x.ravel(), y.ravel()
    vertices = np.stack([x, y, 0.4 * (2 - x * x - y * y)], axis=1)
    uv = np.stack([(x + 1) / 2 + 0.1 * y * y, (y + 1) / 2 + 0.05 * x], axis=1)
    quads = [(r * 5 + c, r * 5 + c + 1, r * 5 + c + 6, r * 5 + c + 5) for r in range(4) for c in range(4)]
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    (folder / "dome.ply").write_bytes(ply_bytes(vertices, triangles, uv))
    codes = np.random.default_rng(7).integers(0, 256, size=(6, 5, 3), dtype=np.uint8)
    codes[..., 2] = np.maximum(codes[..., 2], 140)  # normals facing out
    iio.imwrite(folder / "normals.png", codes)
    write_exr(folder / "normals.exr", np.full((4, 4, 3), (0.5, 0.6, 1.0), dtype=np.float32))
    (folder / "mapped-mix.toml").write_text(MAPPED)
    return folder / "mapped-mix.toml"


def test_gltf_normal_maps_the_canonical_scenes_lack(mapped_mix, tmp_path):
    scene = load_scene(mapped_mix)
    gltf, shapes = _gltf(scene, tmp_path)
    by_name = {s.name: (s, p) for s, _n, p in shapes}
    # the dome: smooth, its vertices split where two triangles need different tangents, the geometry unchanged
    shape, primitive = by_name["dome"]
    vertices, triangles = shape_triangles(shape)
    normals = vertex_normals(shape, vertices, triangles)
    indices = _accessor(gltf, tmp_path, primitive.indices).reshape(-1, 3)
    positions = _accessor(gltf, tmp_path, primitive.attributes.POSITION)
    np.testing.assert_array_equal(positions[indices], np.float32(vertices)[triangles])
    np.testing.assert_array_equal(positions[: len(vertices)], np.float32(vertices))  # the file's come first
    assert len(positions) > len(vertices)  # split: a vertex's triangles have their own dp/du
    np.testing.assert_array_equal(_accessor(gltf, tmp_path, primitive.attributes.TEXCOORD_0)[indices],
                                  np.float32(shape.mesh_uv[triangles]))  # Mitsuba's own coordinates, untransformed
    check_gltf_frame(gltf, tmp_path, primitive, normals[triangles], "dome")
    material = gltf.materials[primitive.material]
    check_normal_texture(gltf, tmp_path, material.normalTexture, scene.textures["turned"])
    # the cube: flat, each face's corners its facet normal and tangent (the frame of a mirrored face included: w
    # stays +1, the bitangent n x s)
    shape, primitive = by_name["box"]
    vertices, triangles = shape_triangles(shape)
    facet = np.cross(vertices[triangles[:, 1]] - vertices[triangles[:, 0]],
                     vertices[triangles[:, 2]] - vertices[triangles[:, 0]])
    facet /= np.linalg.norm(facet, axis=1, keepdims=True)
    errors = check_gltf_frame(gltf, tmp_path, primitive, np.repeat(facet[:, None], 3, axis=1), "box")
    assert errors["green_along_v"] == -1.0  # on the cube's faces t = n x s runs against dp/dv: mirrored coordinates
    check_normal_texture(gltf, tmp_path, gltf.materials[primitive.material].normalTexture, scene.textures["plain"])
    # the float map: no normalTexture (glTF's images are 8-bit here), a loss
    shape, primitive = by_name["sheet"]
    assert gltf.materials[primitive.material].normalTexture is None and primitive.attributes.TANGENT is None
    losses = export_losses(scene, "gltf")
    assert sum("float (EXR) normal map(s) float (float)" in line for line in losses) == 1, losses
    assert sum("interpolates TANGENT" in line and "dome" in line for line in losses) == 1, losses
    terminator = [line for line in losses if "shadow terminator" in line]
    assert len(terminator) == 1 and "plain (plain)" in terminator[0] and "turned" not in terminator[0]
    assert not any("no shear" in line for line in losses)


def test_obj_normal_maps_the_canonical_scenes_lack(mapped_mix, tmp_path):
    scene = load_scene(mapped_mix)
    files = export_scene(scene, "obj", tmp_path)
    materials = parse_mtl((tmp_path / "scene.mtl").read_text(), resolver=FilePathResolver(str(tmp_path)))
    # the cube's map only: the dome's to_uv turns its coordinates (the reader's tangents would turn with them) and
    # the sheet's is float
    assert "norm" not in materials["turned"] and "norm" not in materials["float"]
    assert materials["plain"]["norm"] == ["textures/texture-plain-green-up.png"]
    assert [f.relative_to(tmp_path).as_posix() for f in files] == ["scene.obj", "scene.mtl",
                                                                    "textures/texture-plain-green-up.png"]
    objects = _obj_objects(files[0].read_text())
    dome = objects[0]
    vertices, triangles = shape_triangles(scene.shapes[0])
    np.testing.assert_array_equal(np.array(dome["vn"])[dome["faces"][..., 2] - 1],
                                  vertex_normals(scene.shapes[0], vertices, triangles)[triangles])
    assert np.all(dome["faces"][..., 1] > 0)  # v/vt/vn
    losses = export_losses(scene, "obj")
    assert sum("left out" in line and "turned (turned)" in line and "to_uv" in line for line in losses) == 1, losses
    assert sum("float (EXR) normal map(s) float (float)" in line for line in losses) == 1, losses
    # the cube's faces are mirrored in Mitsuba's coordinates: there the inverted green is wrong, and said so
    assert sum("have mirrored" in line and "box" in line for line in losses) == 1, losses
