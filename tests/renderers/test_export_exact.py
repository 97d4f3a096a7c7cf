"""Exports that other renderers read exactly: each format read back with a reader of its own (glTF with pygltflib,
OBJ/MTL and PLY with trimesh, scene.json with ``json``) holds every colour of the scene to float32 precision, the
camera (glTF: the same image corners), the emission (glTF: factor x strength = the radiance; MTL: ``Ke``) and the
render settings; and the ``{scene_json}`` / ``{scene_gltf}`` / ``{mesh_dir}`` placeholders hand a renderer the
case's resolved scene (a suite's film, depth and stress variant applied)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pygltflib
import pytest
import trimesh
from trimesh.exchange.obj import parse_mtl
from trimesh.resolvers import FilePathResolver

from harness.files.imageio import read_exr, write_exr
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.export import (exported_material, GLTF_FILTERS, GLTF_WRAPS, export_losses, export_scene, gltf_uv_transform,
                                      sphere_corner_uv)
from harness.renderers.meshfiles import safe_name
from harness.scene.kinds.textures import export_path
from harness.renderers.mitsuba_spec import RR_DEPTH, bsdf_dict, clip_planes
from harness.renderers.scene_json import FILTERS
from harness.running.cases import load_suite
from harness.running.judge import case_scene
from harness.scene import load_scene
from harness.scene.kinds.composites import stand_in
from harness.scene.kinds.materials import normal_incidence_reflectance
from harness.scene.kinds.shapes import SHAPES
from harness.scene.triangulate import shape_triangles, vertex_uv
from reference_impl.camera import OrthographicCamera, ThinLensCamera
from reference_impl.textures import srgb_to_linear
from reference_impl import Film

ROOT = Path(__file__).resolve().parents[2]
CANONICAL = sorted(p.stem for p in (ROOT / "scenes").glob("*.toml"))
#: trimesh's glTF and OBJ writers stored 0.885809 (the Cornell box's white) as 226 / 255
EIGHT_BIT_WHITE = round(0.885809 * 255) / 255


def same32(read, scene_value) -> bool:
    """Every number read back equals the scene's once both are rounded to float32."""
    read, scene_value = np.asarray(read, dtype=np.float64), np.asarray(scene_value, dtype=np.float64)
    return read.shape == scene_value.shape and bool(np.all(np.float32(read) == np.float32(scene_value)))


def test_the_colour_check_rejects_eight_bit_colours():
    """The check every colour goes through fails the value trimesh used to write."""
    assert f"{EIGHT_BIT_WHITE:.5f}" == "0.88627"
    assert not same32([EIGHT_BIT_WHITE], [0.885809])
    assert not same32([math.nextafter(np.float32(0.885809), 1.0) + 1e-7], [0.885809])
    assert same32([0.885809], [0.885809])


def base_texture(material):
    """The texture of the parameter a material's glTF base colour comes from, or None."""
    if material.is_diffuse:
        return material.texture("reflectance")
    if material.type in ("plastic", "principled"):
        return material.texture("diffuse_reflectance" if material.type == "plastic" else "base_color")
    return material.texture("specular_reflectance" if material.is_conductor else "specular_transmittance")


def carried(texture) -> bool:
    """Whether glTF's baseColorTexture and MTL's map_Kd hold the texture: an 8-bit sRGB bitmap."""
    return texture is not None and texture.type == "bitmap" and texture.image.dtype == np.uint8 and not texture.raw


def normal_maps(scene) -> set[str]:
    """The textures glTF's normalTexture and MTL's norm hold: 8-bit normal maps (test_export_shading.py checks them)."""
    return {m.perturbation.texture.name for m in scene.materials.values() if m.perturbation is not None
            and m.perturbation.type == "normalmap" and m.perturbation.texture.image.dtype == np.uint8}


def texture_mean(texture) -> list[float]:
    """What an export writes for a texture it cannot carry: its mean value (docs/external-renderers.md)."""
    if texture.type == "checkerboard":
        return [(a + b) / 2 for a, b in zip(texture.color0, texture.color1)]
    image = texture.image
    linear = (image / 255.0 if texture.raw else srgb_to_linear(image)) if image.dtype == np.uint8 else image
    return list(np.asarray(linear, np.float64).reshape(-1, 3).mean(axis=0))


def expected_base_colour(material) -> list[float]:
    """The glTF base colour factor of a material (docs/external-renderers.md, "glTF materials"), computed here: the
    texture's parameter white where the format carries the texture (it multiplies the factor), else its mean."""
    if material.nested:  # a material made of others: glTF's and OBJ's stand-in (harness/scene/kinds/composites.py)
        return expected_base_colour(stand_in(material))
    texture = base_texture(material)
    colour = None if texture is None else ([1.0, 1.0, 1.0] if carried(texture) else texture_mean(texture))
    if material.is_diffuse:
        return list(colour or material.reflectance)
    if material.is_conductor:
        f0 = normal_incidence_reflectance(material.eta, material.k)
        return [min(1.0, f * r) for f, r in zip(f0, colour or material.specular_reflectance)]
    if material.type in ("plastic", "roughplastic"):
        return list(colour or material.diffuse_reflectance)
    if material.type == "principled":
        return list(colour or material.principled.base_color)
    return list(colour or material.specular_transmittance)


def expected_extras_bsdf(material) -> dict:
    """A node's extras.bsdf: the Mitsuba plugin dict as JSON, each textured parameter ``{"texture": NAME}``."""
    spec = bsdf_dict(material)
    inner = spec["bsdf"] if spec["type"] == "twosided" and not material.nested else spec
    for item, texture in material.textures:
        inner[item] = {"texture": texture.name}
    return json.loads(json.dumps(spec))


def expected_uv(shape, triangles) -> np.ndarray:
    """Mitsuba's texture coordinates at the corners of a shape's triangles (T, 3, 2) as an export writes them: the
    vertices' (0 for a mesh without them), a sphere's analytic ones at its icosphere's vertices."""
    if SHAPES[shape.type].sphere is not None:
        return sphere_corner_uv(shape, triangles)
    uv = vertex_uv(shape)
    return (np.zeros((int(np.max(triangles)) + 1, 2)) if uv is None else uv)[triangles]


def check_sphere_uv(shape, corners: np.ndarray) -> None:
    """A sphere's corner coordinates: Mitsuba's analytic ones (u modulo 1) but at the poles, and no triangle's u
    spans the seam."""
    vertices, triangles = shape_triangles(shape)
    to_object = np.linalg.inv(SHAPES[shape.type].object_to_world(shape))
    points = (vertices @ to_object[:3, :3].T + to_object[:3, 3])[triangles]
    radius = np.linalg.norm(points, axis=-1)
    away = np.hypot(points[..., 0], points[..., 1]) > 1e-6 * radius
    u = (np.arctan2(points[..., 1], points[..., 0]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(points[..., 2] / radius, -1, 1)) / np.pi
    np.testing.assert_allclose(np.asarray(corners[..., 1], np.float64), v, atol=1e-6)
    np.testing.assert_allclose((np.asarray(corners[..., 0], np.float64) % 1.0)[away], u[away], atol=1e-6)
    assert np.ptp(corners[..., 0], axis=1).max() < 0.5  # no facet runs the texture's whole width across the seam


# ---- glTF -----------------------------------------------------------------------------------------------------------


def _accessor(gltf: pygltflib.GLTF2, folder: Path, index: int) -> np.ndarray:
    """The data of accessor ``index`` (float32 VEC3 or uint32 SCALAR, tightly packed) from its external buffer."""
    accessor = gltf.accessors[index]
    view = gltf.bufferViews[accessor.bufferView]
    data = (folder / gltf.buffers[view.buffer].uri).read_bytes()
    start = view.byteOffset + (accessor.byteOffset or 0)
    dtype, width = {(pygltflib.FLOAT, "VEC3"): ("<f4", 3), (pygltflib.FLOAT, "VEC2"): ("<f4", 2),
                    (pygltflib.UNSIGNED_INT, "SCALAR"): ("<u4", 1)}[(accessor.componentType, accessor.type)]
    values = np.frombuffer(data, dtype=dtype, count=accessor.count * width, offset=start)
    return values.reshape(accessor.count, width) if width > 1 else values


def _gltf_ndc(node_matrix, camera, directions) -> np.ndarray:
    """Where world directions seen from a glTF camera land in its normalised image coordinates (x right, y up, the
    image's edges at +-1), as the glTF specification's projection matrix puts them."""
    rotation = np.asarray(node_matrix, dtype=np.float64).reshape(4, 4).T[:3, :3]
    local = directions @ rotation  # rotation^T d for each row d
    tan_y = math.tan(camera.yfov / 2)
    depth = -local[:, 2]  # glTF cameras look down their -z
    return np.stack([local[:, 0] / depth / (camera.aspectRatio * tan_y), local[:, 1] / depth / tan_y], axis=1)


def check_gltf_perspective(scene, camera, camera_node):
    """A perspective (or thin-lens) glTF camera: its frustum and the same four image corners as the scene's."""
    film = scene.film
    if isinstance(scene.camera, ThinLensCamera):  # a thin lens's two numbers in the camera's extras
        assert camera.extras == {"aperture_radius": scene.camera.aperture_radius,
                                 "focus_distance": scene.camera.focus_distance}
    _tan_x, tan_y = scene.camera.tan_half_fov(film.width, film.height)
    perspective = camera.perspective
    assert camera.type == "perspective" and perspective.yfov == pytest.approx(2 * math.atan(tan_y), rel=1e-15)
    assert perspective.aspectRatio == film.width / film.height
    assert (perspective.znear, perspective.zfar) == clip_planes(scene)
    placement = np.array(camera_node.matrix).reshape(4, 4).T
    np.testing.assert_array_equal(placement[:3, 3], scene.camera.origin)
    forward = np.subtract(scene.camera.target, scene.camera.origin)
    np.testing.assert_allclose(-placement[:3, 2], forward / np.linalg.norm(forward), atol=1e-15)
    np.testing.assert_allclose(placement[:3, :3].T @ placement[:3, :3], np.eye(3), atol=1e-15)  # a rotation
    assert np.dot(placement[:3, 1], scene.camera.up) > 0  # the image's up
    corners_x = np.array([0.0, film.width, 0.0, film.width, film.width / 2])
    corners_y = np.array([0.0, 0.0, film.height, film.height, film.height / 2])
    _origins, directions = scene.camera.generate_rays(corners_x, corners_y, film.width, film.height)
    want = np.stack([2 * corners_x / film.width - 1, 1 - 2 * corners_y / film.height], axis=1)
    np.testing.assert_allclose(_gltf_ndc(camera_node.matrix, perspective, directions), want, atol=1e-12)
    mitsuba_to_world = np.eye(4)  # the planted fault: Mitsuba's matrix as it is would mirror the image left-right
    mitsuba_to_world[:3, :3] = scene.camera.frame()
    wrong = _gltf_ndc(mitsuba_to_world.T.ravel(), perspective, directions)
    assert not np.allclose(wrong, want, atol=1e-6)


@pytest.mark.parametrize("name", CANONICAL)
def test_gltf_reads_back_exactly(name, tmp_path):
    scene = load_scene(ROOT / "scenes" / f"{name}.toml")
    files = export_scene(scene, "gltf", tmp_path)
    gltf = pygltflib.GLTF2().load(str(files[0]))
    check_gltf_textures(scene, gltf, tmp_path)
    mesh_nodes = [n for n in gltf.nodes if n.mesh is not None]
    assert [n.extras["material"] for n in mesh_nodes] == [s.material for s in scene.shapes]
    for shape, node in zip(scene.shapes, mesh_nodes):
        material = scene.materials[shape.material]
        (primitive,) = gltf.meshes[node.mesh].primitives
        entry = gltf.materials[primitive.material]
        pbr = entry.pbrMetallicRoughness
        alpha = exported_material(material).weight if material.type == "mask" else 1.0  # a mask's opacity
        alpha = 0.0 if material.type == "null" else alpha  # a null boundary: transparent
        assert same32(pbr.baseColorFactor, [*expected_base_colour(material), alpha]), (shape.name, pbr.baseColorFactor)
        assert same32(node.extras["reflectance"], material.reflectance)
        assert (node.extras.get("bsdf") is None) == material.is_diffuse
        if not material.is_diffuse:
            assert node.extras["bsdf"] == expected_extras_bsdf(material)
        assert node.extras.get("textures", {}) == {item: texture.name for item, texture in material.textures}
        strength = entry.extensions.get("KHR_materials_emissive_strength", {}).get("emissiveStrength")
        if shape.is_emitter:
            assert max(entry.emissiveFactor) == 1.0 and strength == max(shape.emission)
            assert same32(np.array(entry.emissiveFactor) * strength, shape.emission), (shape.name, strength)
            assert same32(node.extras["emission"], shape.emission)
        else:
            assert strength is None and (entry.emissiveFactor or [0, 0, 0]) == [0, 0, 0]
        vertices, triangles = shape_triangles(shape)
        positions = _accessor(gltf, tmp_path, primitive.attributes.POSITION)
        indices = _accessor(gltf, tmp_path, primitive.indices).reshape(-1, 3)
        if scene.used_textures and SHAPES[shape.type].sphere is not None:  # seam and pole vertices repeated
            np.testing.assert_array_equal(positions[indices], np.float32(vertices)[triangles])
        else:
            np.testing.assert_array_equal(positions, np.float32(vertices))
            np.testing.assert_array_equal(indices, triangles)
        if not scene.used_textures:
            assert primitive.attributes.TEXCOORD_0 is None
            continue
        uv = _accessor(gltf, tmp_path, primitive.attributes.TEXCOORD_0)[indices]  # float32, the corners'
        if SHAPES[shape.type].sphere is not None:
            check_sphere_uv(shape, uv)
        np.testing.assert_array_equal(uv, np.float32(expected_uv(shape, triangles)))  # no flip: v down in both
    if any(s.is_emitter for s in scene.shapes):
        assert "KHR_materials_emissive_strength" in gltf.extensionsUsed
    # the camera: its frustum, and the same four image corners as the scene's camera
    (camera,) = gltf.cameras
    (camera_node,) = [n for n in gltf.nodes if n.camera is not None]
    film = scene.film
    if isinstance(scene.camera, OrthographicCamera):  # glTF's orthographic camera: its half width and height
        half_x, half_y = scene.camera.extent(film.width, film.height)
        assert camera.type == "orthographic" and (camera.orthographic.xmag, camera.orthographic.ymag) == (half_x,
                                                                                                          half_y)
        assert (camera.orthographic.znear, camera.orthographic.zfar) == clip_planes(scene)
    else:
        check_gltf_perspective(scene, camera, camera_node)
    # the render settings
    extras = dict(gltf.asset.extras)
    textures = extras.pop("textures", None)
    assert extras == {"film": {"width": film.width, "height": film.height, "filter": FILTERS[film.filter]},
                      "max_depth": scene.max_depth, "rr_depth": RR_DEPTH}
    assert (textures is None) == (not scene.used_textures)
    for texture in scene.used_textures:  # the scene.json entries, a file named only where it was written
        entry = dict(textures[texture.name])
        assert ("filename" in entry) == (carried(texture) or texture.name in normal_maps(scene))
        np.testing.assert_array_equal(entry.pop("to_uv"), texture.to_uv)
        if "filename" in entry:
            np.testing.assert_array_equal(iio.imread(tmp_path / entry.pop("filename")), texture.image)
        assert entry.pop("type") == texture.type
        for parameter, value in entry.items():
            assert _equal(value, getattr(texture, parameter)), (texture.name, parameter, value)


def _trs(transform: dict) -> np.ndarray:
    """KHR_texture_transform's matrix T(offset) R(rotation) S(scale), its rotation as the extension's example, sample
    model and readers take it (R(r) = [[cos r, sin r], [-sin r, cos r]], KhronosGroup/glTF#1563)."""
    (tu, tv), (su, sv) = transform.get("offset", [0, 0]), transform.get("scale", [1, 1])
    r = transform.get("rotation", 0)
    return (np.array([[1, 0, tu], [0, 1, tv], [0, 0, 1.0]])
            @ np.array([[math.cos(r), math.sin(r), 0], [-math.sin(r), math.cos(r), 0], [0, 0, 1]])
            @ np.diag([su, sv, 1.0]))


def check_image_and_sampler(gltf: pygltflib.GLTF2, folder: Path, info, texture):
    """glTF texture ``info``'s image (a PNG holding the scene's codes, bit for bit) and sampler (filter and wrap
    mode) against the scene's ``texture``; returns the image."""
    entry = gltf.textures[info.index]
    image = gltf.images[entry.source]
    assert image.uri.endswith(".png") and image.mimeType == "image/png"
    np.testing.assert_array_equal(iio.imread(folder / image.uri), texture.image)
    sampler = gltf.samplers[entry.sampler]
    assert (sampler.magFilter, sampler.minFilter) == (GLTF_FILTERS[texture.filter_type],) * 2
    assert (sampler.wrapS, sampler.wrapT) == (GLTF_WRAPS[texture.wrap_mode],) * 2
    return image


def check_gltf_textures(scene, gltf: pygltflib.GLTF2, folder: Path) -> None:
    """Every base colour texture glTF carries: its image (the scene's codes, bit for bit), its sampler (filter and
    wrap mode) and to_uv (KHR_texture_transform, the same matrix); every material's other textures nowhere."""
    mesh_nodes = [n for n in gltf.nodes if n.mesh is not None]
    for shape, node in zip(scene.shapes, mesh_nodes):
        material = scene.materials[shape.material]
        (primitive,) = gltf.meshes[node.mesh].primitives
        info = gltf.materials[primitive.material].pbrMetallicRoughness.baseColorTexture
        texture = base_texture(material)
        if not carried(texture):
            assert info is None
            continue
        assert info.texCoord == 0 and primitive.attributes.TEXCOORD_0 is not None
        check_image_and_sampler(gltf, folder, info, texture)
        transform = (info.extensions or {}).get("KHR_texture_transform")
        if np.array_equal(texture.to_uv, np.eye(3)):
            assert transform is None
        elif gltf_uv_transform(texture.to_uv) is None:  # a shear: left out, a loss
            assert transform is None
            assert any("no shear" in line and texture.name in line for line in export_losses(scene, "gltf"))
        else:
            np.testing.assert_allclose(_trs(transform), texture.to_uv, rtol=0, atol=1e-15 * np.abs(texture.to_uv).max())
            assert "KHR_texture_transform" in gltf.extensionsUsed
    assert len(gltf.textures or []) == len({t.name for m in scene.materials.values()
                                            for t in [base_texture(m)] if carried(t)} | normal_maps(scene))


# ---- OBJ / MTL ------------------------------------------------------------------------------------------------------


def _usemtl_of_objects(text: str) -> list[str]:
    """The material each ``o`` object of an OBJ file uses (its first ``usemtl``)."""
    names = []
    for line in text.splitlines():
        if line.startswith("o "):
            names.append(None)
        elif line.startswith("usemtl ") and names and names[-1] is None:
            names[-1] = line.split(None, 1)[1]
    return names


@pytest.mark.parametrize("name", CANONICAL)
def test_obj_and_mtl_read_back_exactly(name, tmp_path):
    scene = load_scene(ROOT / "scenes" / f"{name}.toml")
    files = export_scene(scene, "obj", tmp_path)
    images = sorted({export_path(t) for m in scene.materials.values() for t in [base_texture(m)] if carried(t)})
    norms = [f"textures/texture-{n}-green-up.png" for n in normal_maps(scene)]  # MTL's norm
    written = [f.relative_to(tmp_path).as_posix() for f in files]
    assert written[:2] == ["scene.obj", "scene.mtl"] and sorted(written[2:]) == sorted(images + norms)
    materials = parse_mtl((tmp_path / "scene.mtl").read_text(), resolver=FilePathResolver(str(tmp_path)))
    uses = _usemtl_of_objects(files[0].read_text())
    assert len(uses) == len(scene.shapes)
    for shape, mtl_name in zip(scene.shapes, uses):
        entry = materials[mtl_name]
        # nothing the scene does not say: no Ks, Ka, Ns
        assert set(entry) <= {"name", "kd", "diffuse", "ke", "image", "norm"}, entry
        assert same32(entry["kd"], expected_base_colour(scene.materials[shape.material])), (shape.name, entry["kd"])
        texture = base_texture(scene.materials[shape.material])
        assert ("image" in entry) == carried(texture)
        if carried(texture):  # map_Kd: the scene's codes, bit for bit
            assert entry["image"].info["file_path"] == export_path(texture)
            np.testing.assert_array_equal(np.asarray(entry["image"].convert("RGB")), texture.image)
        if shape.is_emitter:
            assert same32([float(x) for x in entry["ke"]], shape.emission)
        else:
            assert "ke" not in entry
    # the geometry, per material group as trimesh loads it: the core's triangles, float64 exact
    # trimesh (4.x) drops the uv of every object but the first with maintain_order when faces are v/vt; without
    # it the faces keep their order all the same
    loaded = trimesh.load(files[0], process=False, maintain_order=not scene.used_textures, force="scene")
    groups = {mesh.visual.material.name: mesh for mesh in loaded.geometry.values()}
    assert sorted(groups) == sorted(set(uses))
    for mtl_name, mesh in groups.items():
        shapes = [s for s, used in zip(scene.shapes, uses) if used == mtl_name]
        want = np.concatenate([np.asarray(shape_triangles(s)[0])[shape_triangles(s)[1]] for s in shapes])
        np.testing.assert_array_equal(mesh.vertices[mesh.faces], want)
        if not scene.used_textures:
            assert getattr(mesh.visual, "uv", None) is None
            continue
        # vt = (u', 1 - v') of Mitsuba's (u, v) mapped by the map_Kd texture's to_uv: OBJ's v points up
        texture = base_texture(scene.materials[shapes[0].material])
        to_uv = texture.to_uv if carried(texture) else np.eye(3)
        corners = np.concatenate([expected_uv(s, shape_triangles(s)[1]) for s in shapes])
        for shape, part in zip(shapes, np.split(mesh.visual.uv[mesh.faces], np.cumsum(
                [len(shape_triangles(s)[1]) for s in shapes])[:-1])):
            if SHAPES[shape.type].sphere is not None and np.array_equal(to_uv, np.eye(3)):
                check_sphere_uv(shape, np.stack([part[..., 0], 1.0 - part[..., 1]], axis=-1))
        mapped = corners if np.array_equal(to_uv, np.eye(3)) else corners @ to_uv[:2, :2].T + to_uv[:2, 2]
        np.testing.assert_array_equal(mesh.visual.uv[mesh.faces], np.stack([mapped[..., 0], 1.0 - mapped[..., 1]],
                                                                             axis=-1))


# ---- textures the canonical scenes lack ------------------------------------------------------------------------------

TEXTURED = """
name = "textured-mix"
[camera]
origin = [0.0, 0.0, 4.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 40.0
[film]
width = 8
height = 6
[textures.turned]
filename = "codes.png"
filter_type = "nearest"
wrap_mode = "mirror"
to_uv = { translate = [0.25, -0.5], rotate = 30.0, scale = [2.0, -3.0] }
[textures.edge]
filename = "codes.png"
wrap_mode = "clamp"
to_uv = [[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
[textures.float]
filename = "float.exr"
[textures.raw]
filename = "codes.png"
raw = true
[textures.checks]
type = "checkerboard"
color0 = [0.9, 0.5, 0.1]
color1 = [0.1, 0.2, 0.3]
[materials.turned]
reflectance = { texture = "turned" }
[materials.edge]
reflectance = { texture = "edge" }
[materials.float]
reflectance = { texture = "float" }
[materials.raw]
reflectance = { texture = "raw" }
[materials.mirror]
type = "conductor"
specular_reflectance = { texture = "turned" }
[materials.glass]
type = "dielectric"
specular_reflectance = { texture = "checks" }
[[shapes]]
name = "a"
type = "rectangle"
material = "turned"
[[shapes]]
name = "b"
type = "cube"
material = "edge"
scale = 0.3
[[shapes]]
name = "c"
type = "rectangle"
material = "float"
translate = [0.0, 0.0, -1.0]
[[shapes]]
name = "d"
type = "rectangle"
material = "raw"
translate = [0.0, 0.0, -2.0]
[[shapes]]
name = "e"
type = "cube"
material = "mirror"
translate = [1.0, 0.0, 0.0]
scale = 0.2
[[shapes]]
name = "f"
type = "rectangle"
material = "glass"
translate = [0.0, 1.0, 0.0]
"""


@pytest.fixture(scope="module")
def textured_mix(tmp_path_factory) -> Path:
    """A scene with what the canonical scenes' textures lack: a rotated, mirrored and translated to_uv with nearest
    filtering and mirror wrapping (on a diffuse and on a mirror conductor: glTF's base colour texture of a metal), a
    clamped texture with a shear, an EXR, a raw PNG and a checkerboard on a dielectric's specular_reflectance."""
    folder = tmp_path_factory.mktemp("textured-mix")
    codes = np.random.default_rng(5).integers(0, 256, size=(3, 5, 3), dtype=np.uint8)
    iio.imwrite(folder / "codes.png", codes)
    write_exr(folder / "float.exr", np.linspace(0.0, 1.0, 4 * 3 * 3, dtype=np.float32).reshape(4, 3, 3))
    (folder / "textured-mix.toml").write_text(TEXTURED)
    return folder / "textured-mix.toml"


def test_gltf_and_obj_carry_the_textures_they_can_and_name_the_rest(textured_mix, tmp_path):
    scene = load_scene(textured_mix)
    assert gltf_uv_transform(scene.textures["turned"].to_uv)["rotation"] == pytest.approx(-math.radians(30.0))
    assert gltf_uv_transform(scene.textures["edge"].to_uv) is None  # a shear
    files = export_scene(scene, "gltf", tmp_path / "gltf")
    gltf = pygltflib.GLTF2().load(str(files[0]))
    check_gltf_textures(scene, gltf, tmp_path / "gltf")
    assert [f.relative_to(tmp_path / "gltf").as_posix() for f in files] == [
        "scene.gltf", "scene.bin", "textures/texture-turned.png", "textures/texture-edge.png"]
    for shape, node in zip(scene.shapes, [n for n in gltf.nodes if n.mesh is not None]):
        material = scene.materials[shape.material]
        (primitive,) = gltf.meshes[node.mesh].primitives
        pbr = gltf.materials[primitive.material].pbrMetallicRoughness
        assert same32(pbr.baseColorFactor, [*expected_base_colour(material), 1.0]), shape.name
        json.dumps(node.extras, allow_nan=False)  # JSON values only: each texture by name
    gltf_losses = export_losses(scene, "gltf")
    for words in (["base colour only", "checks (glass.specular_reflectance)"], ["KHR_texture_transform", "edge"],
                  ["float (EXR)", "float (float.reflectance)"], ["raw texture raw (raw.reflectance)"]):
        assert sum(all(w in line for w in words) for line in gltf_losses) == 1, (words, gltf_losses)
    assert not any("analytic sphere" in line for line in gltf_losses)
    furnace = load_scene(ROOT / "scenes" / "textured-furnace.toml")  # a textured sphere: its icosphere's uv
    for fmt in ("gltf", "obj"):
        assert sum("has no analytic sphere" in line and " ball " in line for line in export_losses(furnace, fmt)) == 1
    # OBJ: map_Kd for the sRGB PNGs, to_uv applied to vt (a shear too), the sampler named as a loss
    test_files = export_scene(scene, "obj", tmp_path / "obj")
    assert [f.relative_to(tmp_path / "obj").as_posix() for f in test_files] == [
        "scene.obj", "scene.mtl", "textures/texture-turned.png", "textures/texture-edge.png"]
    mtl = (tmp_path / "obj" / "scene.mtl").read_text()
    assert mtl.count("map_Kd textures/texture-turned.png") == 2 and mtl.count("map_Kd ") == 3
    text = test_files[0].read_text()
    vt = np.array([[float(x) for x in line.split()[1:]] for line in text.splitlines() if line.startswith("vt ")])
    edge = scene.textures["edge"].to_uv
    (b,) = [s for s in scene.shapes if s.name == "b"]
    start = sum(len(shape_triangles(s)[0]) for s in scene.shapes[:1])
    uv = vertex_uv(b) @ edge[:2, :2].T + edge[:2, 2]
    np.testing.assert_array_equal(vt[start:start + len(uv)], np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1))
    obj_losses = export_losses(scene, "obj")
    assert any("MTL has no filter or wrap mode" in line and "turned (nearest, mirror)" in line
               and "edge (bilinear, clamp)" in line for line in obj_losses), obj_losses
    assert not any("shear" in line for line in obj_losses)


# ---- scene.json -----------------------------------------------------------------------------------------------------


def _equal(read, value) -> bool:
    if isinstance(value, str) or value is None or isinstance(value, bool):
        return read == value
    return bool(np.array_equal(np.asarray(read, dtype=np.float64), np.asarray(value, dtype=np.float64)))


@pytest.mark.parametrize("name", CANONICAL)
def test_scene_json_reads_back_exactly(name, tmp_path):
    scene = load_scene(ROOT / "scenes" / f"{name}.toml")
    files = export_scene(scene, "json", tmp_path)
    document = json.loads(files[0].read_text())
    camera, film = document["camera"], scene.film
    to_world = np.array(camera["to_world"])
    np.testing.assert_array_equal(to_world[:3, :3], scene.camera.frame())
    np.testing.assert_array_equal(to_world[:3, 3], scene.camera.origin)
    np.testing.assert_array_equal(to_world[3], [0, 0, 0, 1])
    if isinstance(scene.camera, OrthographicCamera):
        half_x, half_y = scene.camera.extent(film.width, film.height)
        assert (camera["half_width"], camera["half_height"]) == (half_x, half_y)
        assert camera["scale"] == list(scene.camera.scale)
        return
    tan_x, tan_y = scene.camera.tan_half_fov(film.width, film.height)
    assert camera["fov_x"] == pytest.approx(math.degrees(2 * math.atan(tan_x)), rel=1e-15)
    assert camera["fov_y"] == pytest.approx(math.degrees(2 * math.atan(tan_y)), rel=1e-15)
    assert (camera["fov"], camera["fov_axis"], camera["aspect"]) == (scene.camera.fov, scene.camera.fov_axis,
                                                                     film.width / film.height)
    assert (camera["near_clip"], camera["far_clip"]) == clip_planes(scene)
    assert document["film"] == {"width": film.width, "height": film.height, "filter": FILTERS[film.filter]}
    assert document["integrator"] == {"type": "path", "max_depth": scene.max_depth, "rr_depth": RR_DEPTH}
    assert set(document["materials"]) == set(scene.materials)
    for key, entry in document["materials"].items():
        material = scene.materials[key]
        if material.perturbation is not None:  # a normalmap or bumpmap around the material its bsdf names
            p = material.perturbation
            texture_key = "normalmap" if p.type == "normalmap" else "texture"
            assert (entry["type"], entry[texture_key], entry["flip_invalid_normals"],
                    entry["use_shadowing_function"]) == (p.type, {"texture": p.texture.name},
                                                         p.flip_invalid_normals, p.use_shadowing_function)
            assert entry.get("scale", 1.0) == p.scale
            assert entry["bsdf"] == document["materials"][p.bsdf]
            continue
        if material.nested:  # a material made of others: its weight or opacity and its materials' names
            names = [m.name for m in material.nested]
            assert entry["bsdf"] in (names, names[0]) and entry["type"] == material.type, (key, entry)
            texture = material.textures[0][1] if material.textures else None
            for item in ("weight", "opacity"):
                if item in entry:
                    assert entry[item] == ({"texture": texture.name} if texture else material.weight), (key, entry)
            continue
        assert entry["type"] == material.type and (len(entry) > 2 or entry == {"type": "null"})
        for parameter, value in entry.items():
            texture = material.texture(parameter)
            if texture is not None:
                assert value == {"texture": texture.name}, (key, parameter, value)
            elif material.principled is not None and parameter != "type":  # principled's record
                assert _equal(value, getattr(material.principled, parameter)), (key, parameter, value)
            else:
                assert _equal(value, getattr(material, parameter)), (key, parameter, value)
    assert set(document.get("textures", {})) == {t.name for t in scene.used_textures}
    for texture in scene.used_textures:
        entry = document["textures"][texture.name]
        np.testing.assert_array_equal(entry.pop("to_uv"), texture.to_uv)
        if texture.type == "bitmap":
            path = tmp_path / entry.pop("filename")
            image = iio.imread(path) if path.suffix == ".png" else read_exr(path).image
            np.testing.assert_array_equal(image, texture.image)  # the pixels the scene holds, bit for bit
        for parameter, value in entry.items():
            assert _equal(value, getattr(texture, parameter)), (texture.name, parameter, value)
    assert len(document["emitters"]) == len(scene.emitters)
    for entry, emitter in zip(document["emitters"], scene.emitters):
        for parameter, value in entry.items():
            if parameter == "filename":
                image = read_exr(tmp_path / value).image
                np.testing.assert_array_equal(image, np.float32(emitter.image))
            elif parameter in ("width", "height"):
                assert emitter.image.shape[:2] == (entry["height"], entry["width"])
            else:
                assert _equal(value, getattr(emitter, parameter)), (emitter.name, parameter, value)
    check_scene_json_media(scene, document)
    assert len(document["shapes"]) == len(scene.shapes)
    for entry, shape in zip(document["shapes"], scene.shapes):
        assert (entry["name"], entry["material"]) == (shape.name, shape.material)
        glow = getattr(shape, "emission_texture", None)  # a textured light: its texture by name
        assert entry["emission"] == {"texture": glow.name} if glow is not None else _equal(entry["emission"],
                                                                                         shape.emission)
        vertices, triangles = shape_triangles(shape)
        mesh = trimesh.load(tmp_path / entry["mesh"], process=False)
        np.testing.assert_array_equal(mesh.vertices, np.float32(vertices))
        np.testing.assert_array_equal(mesh.faces, triangles)  # the winding: the front side is counter-clockwise
        assert entry["triangles"] == len(triangles)
        uv = vertex_uv(shape)
        if scene.used_textures and uv is not None:  # Mitsuba's coordinates, as the PLY's s, t
            assert entry["uv"] == "mesh"
            np.testing.assert_array_equal(mesh.visual.uv, uv)


def check_scene_json_media(scene, document: dict) -> None:
    """scene.json's media (issue 38): each medium's numbers exactly (sigma_t with scale applied, as float64
    multiplies them), the shapes' interior / exterior and the camera's medium by name; no ``media`` without any."""
    assert document["camera"]["medium"] == scene.camera_medium
    assert [(e["interior"], e["exterior"]) for e in document["shapes"]] == [(s.interior, s.exterior)
                                                                          for s in scene.shapes]
    if not scene.media:
        assert "media" not in document
        return
    assert list(document["media"]) == list(scene.media)
    for name, entry in document["media"].items():
        medium = scene.media[name]
        assert entry["type"] == medium.type
        assert entry["sigma_t"] == [s * medium.scale for s in medium.sigma_t]
        assert entry["albedo"] == list(medium.albedo)
        assert entry["phase"] == ({"type": "hg", "g": medium.g} if medium.phase == "hg" else {"type": "isotropic"})


# ---- the placeholders -----------------------------------------------------------------------------------------------

# A renderer that reads only what the harness hands it: scene.json (its film gives the EXR's size), the glTF's
# asset.extras, the meshes; it records what it saw and which exports its working folder holds.
READER = r'''
import json, os, sys
from pathlib import Path
import numpy as np
from harness.files.imageio import write_exr
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
record = {"cwd": sorted(os.listdir("."))}
if "--json" in args:
    scene = json.loads(Path(args["--json"]).read_text())
    record["json"] = {"film": scene["film"], "max_depth": scene["integrator"]["max_depth"],
                      "camera": scene["camera"]["origin"],
                      "meshes_exist": all((Path(args["--json"]).parent / s["mesh"]).is_file() for s in scene["shapes"])}
    width, height = scene["film"]["width"], scene["film"]["height"]
if "--gltf" in args:
    gltf = json.loads(Path(args["--gltf"]).read_text())
    record["gltf"] = gltf["asset"]["extras"]
    record["gltf_buffer"] = (Path(args["--gltf"]).parent / gltf["buffers"][0]["uri"]).is_file()
if "--meshes" in args:
    record["meshes"] = sorted(os.listdir(args["--meshes"]))
Path(args["--record"]).write_text(json.dumps(record))
write_exr(args["--out"], np.full((height, width, 3), 0.5), np.full((height, width, 3), 0.01))
Path(args["--out"] + ".json").write_text('{"render_seconds": 0.001}')  # its own time: no start-up probe runs
'''

SUITE = """
name = "placeholders"
[defaults]
film = { width = 6, height = 4 }
max_depth = 3
spp = 2
[[cases]]
name = "cornell"
scene = "cornell-box"
renderer = "reader.toml"
variant = "scale=1e2"
"""


def _reader(folder: Path, args: list[str]) -> Path:
    (folder / "reader.py").write_text(READER)
    command = ["{python}", "{here}/reader.py", *args, "--record", str(folder / "record.json"), "--out", "{out}"]
    (folder / "reader.toml").write_text(f"command = {json.dumps(command)}\nrepeats = 2\n")
    return folder / "reader.toml"


@pytest.mark.slow  # starts a process
def test_placeholders_carry_the_suites_film_depth_and_variant(tmp_path):
    _reader(tmp_path, ["--json", "{scene_json}", "--gltf", "{scene_gltf}", "--meshes", "{mesh_dir}"])
    (tmp_path / "suite.toml").write_text(SUITE)
    (case,) = load_suite(tmp_path / "suite.toml").cases
    scene = case_scene(case)
    assert (scene.film.width, scene.film.height, scene.max_depth) == (6, 4, 3)  # the file says 256 x 256, depth 8
    result = get_renderer(str(tmp_path / "reader.toml")).render(scene, RenderRequest(spp=2, seed=1))
    assert result.image.shape == (4, 6, 3)  # the EXR's size came from scene.json's film
    record = json.loads((tmp_path / "record.json").read_text())
    want_film = {"width": 6, "height": 4, "filter": FILTERS["box"]}
    assert record["json"]["film"] == want_film and record["json"]["max_depth"] == 3
    assert record["json"]["camera"] == pytest.approx(np.array(scene.camera.origin), rel=1e-15)
    assert record["json"]["camera"][2] == pytest.approx(390.0)  # the stress variant's camera (scale=1e2)
    assert record["json"]["meshes_exist"] and record["gltf_buffer"]
    assert record["gltf"] == {"film": want_film, "max_depth": 3, "rr_depth": RR_DEPTH}
    assert record["meshes"] == sorted(f"{s.index}-{safe_name(s.name)}.ply" for s in scene.shapes)
    assert record["cwd"] == ["gltf", "json"]  # no Mitsuba XML: the command did not name {scene_xml}


@pytest.mark.slow  # starts a process
def test_only_the_formats_a_command_names_are_written(tmp_path):
    _reader(tmp_path, ["--json", "{scene_json}"])
    scene = dataclasses.replace(load_scene(ROOT / "scenes" / "furnace.toml"), film=Film(3, 2, "box"))
    get_renderer(str(tmp_path / "reader.toml")).render(scene, RenderRequest(spp=1))
    record = json.loads((tmp_path / "record.json").read_text())
    assert record["cwd"] == ["json"] and "gltf" not in record and record["json"]["film"]["width"] == 3


# ---- the reader in docs/scene-json.md ----------------------------------------------------------------------------


def test_the_reader_in_scene_json_md(tmp_path):
    """The Python reader the documentation gives reads an exported scene as the harness holds it: every mesh (float32
    vertices, the front side's winding), every material and emission, and the camera rays through the corners."""
    text = (ROOT / "docs" / "scene-json.md").read_text()
    (code,) = [block.split("```")[0] for block in text.split("```python\n")[1:]]
    namespace: dict = {}
    exec(compile(code, "docs/scene-json.md", "exec"), namespace)
    scene = load_scene(ROOT / "scenes" / "veach-mis.toml")
    scene = dataclasses.replace(scene, film=Film(7, 5, "box"))
    export_scene(scene, "json", tmp_path)
    document, shapes = namespace["load"](tmp_path / "scene.json")
    assert len(shapes) == len(scene.shapes)
    for (vertices, triangles, material, emission), shape in zip(shapes, scene.shapes):
        want_vertices, want_triangles = shape_triangles(shape)
        np.testing.assert_array_equal(vertices, np.float32(want_vertices))
        np.testing.assert_array_equal(triangles, want_triangles)
        assert material["type"] == scene.materials[shape.material].type
        assert _equal(emission, shape.emission)
    x = np.array([0.0, 7.0, 0.0, 7.0, 3.5, 1.25])
    y = np.array([0.0, 0.0, 5.0, 5.0, 2.5, 4.0])
    origins, directions = scene.camera.generate_rays(x, y, 7, 5)
    for i in range(len(x)):
        origin, direction = namespace["camera_ray"](document, x[i], y[i])
        np.testing.assert_allclose(origin, origins[i], rtol=0, atol=0)
        np.testing.assert_allclose(direction, directions[i], rtol=0, atol=1e-15)
