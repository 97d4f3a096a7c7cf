"""harness.renderers.import_gltf: glTF 2.0 files read into the scene format (docs/import.md, "glTF 2.0").

The round trip: every canonical scene exported as glTF (``harness export --format gltf``) and imported again gives
the same triangles (float32, glTF's), emission, lights and camera rays, and the materials glTF carries; the
materials it does not are named in ``MATERIAL_LOSSES``. Then files written here with pygltflib, one per element the
importer reads, and one refusal per element it does not.
"""

from __future__ import annotations

import base64
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from harness.core.errors import HarnessError
from harness.renderers.export import (
    carried_texture,
    export_scene,
    exported_material,
    gltf_material,
    gltf_uv_transform,
)
from harness.renderers.import_gltf import import_gltf, uv_matrix
from harness.renderers.imports import write_imported
from harness.scene import load_scene, triangulate
from harness.scene.triangulate import shape_triangles
from harness.scene.kinds.emitters import LUMENS_PER_WATT
from harness.scene.material_arrays import material_row

pygltflib = pytest.importorskip("pygltflib")

SCENES = sorted(Path(__file__).resolve().parents[2].joinpath("scenes").glob("*.toml"))
#: Canonical scenes whose glTF export holds extensions the importer refuses: imported with ``lenient``.
LENIENT = {"principled-grid": "KHR_materials_sheen and KHR_materials_specular (sheen and spec_tint)",
           "plastic-cornell-box": "KHR_materials_specular (the coating's tint)"}
#: What glTF's metallic-roughness model cannot carry of each material type: the import gives the principled material
#: of the glTF factors, so only those are compared.
MATERIAL_LOSSES = {
    "diffuse": "glTF has no Lambertian BRDF: the export's metallic 0, roughness 1 imports as that principled",
    "conductor": "glTF's metal is Schlick's Fresnel of a base colour: imported as principled metallic 1",
    "roughconductor": "as conductor, and Beckmann read as GGX",
    "plastic": "glTF has no coated diffuse: imported as principled metallic 0 with the base colour",
    "roughplastic": "as plastic",
    "twosided": "glTF has one material per side pair: the front material",
    "mask": "the export writes a mask's opacity as base colour alpha, alphaMode BLEND (a textured opacity: its mean)",
    "blendbsdf": "glTF has no blend: the material of the larger weight",
    "normalmap": "compared through its nested material and its map",
    "bumpmap": "glTF has no bump map: the nested material, unperturbed",
    "principled": "sheen and specular extensions refused (lenient: dropped); the rest compared",
    "null": "glTF has no index-matched boundary: the export's transparent material (base colour alpha 0, alphaMode "
            "BLEND) imports as a mask of opacity 0; the media are left out",
}


#: The imported material's parameter that holds glTF's base colour texture, by the imported type.
BASE_PARAMETER = (("dielectric", "specular_transmittance"), ("thindielectric", "specular_transmittance"),
                  ("roughdielectric", "specular_transmittance"))


def corners(geometry) -> np.ndarray:
    return np.asarray(geometry.vertices)[np.asarray(geometry.triangles)]


# ---- the round trip of the canonical scenes ---------------------------------------------------------------------


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_round_trip(path, tmp_path):
    original = load_scene(path)
    export_scene(original, "gltf", tmp_path / "gltf")
    lenient = path.stem in LENIENT
    if lenient:
        with pytest.raises(HarnessError, match=r"/materials/\d+/extensions/KHR_materials_(sheen|specular): "):
            import_gltf(tmp_path / "gltf" / "scene.gltf")
    imported_scene = import_gltf(tmp_path / "gltf" / "scene.gltf", lenient=lenient)
    assert bool(imported_scene.dropped) == lenient
    imported = load_scene(write_imported(imported_scene, tmp_path / "imported"))

    # geometry: the triangles glTF holds (float32, world space), each shape's in order
    a, b = triangulate(original), triangulate(imported)
    np.testing.assert_array_equal(corners(b), np.float32(corners(a)).astype(np.float64))
    np.testing.assert_array_equal(b.light_id, a.light_id)
    np.testing.assert_allclose(b.emission, a.emission, rtol=1e-15, atol=0)
    if len(a.normals) and len(b.normals):  # the smooth triangles' normals (NORMAL, float32; spheres: analytic)
        smooth = a.smooth & b.smooth
        np.testing.assert_allclose(b.normals[smooth], a.normals[smooth], atol=2e-7)
    assert [s.name for s in imported.shapes] == [s.name for s in original.shapes]

    # the camera: the same rays through the film (the resolved field of view, glTF's yfov)
    assert (imported.film.width, imported.film.height, imported.film.filter) == (
        original.film.width, original.film.height, original.film.filter)
    assert imported.max_depth == original.max_depth
    assert type(imported.camera) is type(original.camera)
    fx, fy = np.meshgrid(np.linspace(0, original.film.width, 5), np.linspace(0, original.film.height, 4))
    rays_a = original.camera.generate_rays(fx.ravel(), fy.ravel(), original.film.width, original.film.height)
    rays_b = imported.camera.generate_rays(fx.ravel(), fy.ravel(), original.film.width, original.film.height)
    for x, y in zip(rays_a, rays_b):
        np.testing.assert_allclose(y, x, rtol=1e-12, atol=1e-12)
    for key in ("aperture_radius", "focus_distance"):
        assert getattr(imported.camera, key, None) == getattr(original.camera, key, None)

    # lights: glTF's punctual ones (environments are left out by the export)
    punctual = [e for e in original.emitters if e.type in ("point", "spot", "directional")]
    assert [e.type for e in imported.emitters] == [e.type for e in punctual]
    for x, y in zip(punctual, imported.emitters):
        for key in ("position", "intensity", "direction", "irradiance", "axis", "cutoff_angle", "beam_width"):
            if hasattr(x, key):
                np.testing.assert_allclose(getattr(y, key), getattr(x, key), rtol=1e-12, atol=1e-15, err_msg=key)

    # materials: exact where glTF carries the type, its base colour otherwise
    for x_shape, y_shape in zip(original.shapes, imported.shapes):
        check_material(original.materials[x_shape.material], imported.materials[y_shape.material])


def check_material(x, y):
    """The imported material ``y`` against the original ``x``: the identity for the types glTF carries (principled's
    base colour, metallic, roughness, eta, spec_trans; the dielectrics), the base colour for the others
    (:data:`MATERIAL_LOSSES`)."""
    if x.perturbation is not None and x.perturbation.type == "normalmap":
        assert y.perturbation is not None and y.perturbation.type == "normalmap"
        np.testing.assert_array_equal(y.perturbation.texture.image, x.perturbation.texture.image)
    if x.type in ("dielectric", "thindielectric") or (x.type == "roughdielectric" and x.distribution == "ggx"):
        assert y.type == x.type
        assert y.int_ior / y.ext_ior == pytest.approx(x.int_ior / x.ext_ior, rel=1e-15)
        assert y.specular_transmittance == x.specular_transmittance
        if x.type == "roughdielectric":
            assert y.alpha == pytest.approx(x.alpha, rel=1e-15)
        return
    carried = carried_texture(x)
    if carried is not None:  # the base colour's 8-bit sRGB bitmap: its codes, sampler and transform
        y_texture = dict(y.textures)[dict(BASE_PARAMETER).get(y.type, "base_color")]
        np.testing.assert_array_equal(y_texture.image, carried.image)
        assert (y_texture.filter_type, y_texture.wrap_mode, y_texture.raw) == (
            carried.filter_type, carried.wrap_mode, False)
        np.testing.assert_allclose(y_texture.to_uv, carried.to_uv, rtol=1e-12, atol=1e-12)
    assert x.type in MATERIAL_LOSSES
    factors, _ = gltf_material(exported_material(x))
    if x.type == "principled" and x.principled.spec_trans == 1 and x.principled.metallic == 0:
        # glTF's full transmission is the importer's dielectric: the principled glass's Burley lobes are lost
        assert y.type == ("dielectric" if x.principled.roughness == 0 else "roughdielectric")
        assert (y.int_ior, y.ext_ior) == (x.principled.eta, 1.0)
        assert y.alpha == pytest.approx(max(1e-4, x.principled.roughness ** 2), rel=1e-15)
        return
    assert y.type in ("principled", "mask")
    p = y.principled if y.type == "principled" else y.nested[0].principled
    if x.type == "principled" and not x.textures:
        assert p.base_color == x.principled.base_color
        assert (p.metallic, p.roughness, p.spec_trans) == (x.principled.metallic, x.principled.roughness,
                                                          x.principled.spec_trans)
        assert p.eta == pytest.approx(x.principled.eta, rel=1e-15)
        assert p.clearcoat == x.principled.clearcoat
        if p.clearcoat > 0:  # KHR_materials_clearcoat's roughness sqrt(alpha_cc) back to the gloss
            assert p.clearcoat_gloss == pytest.approx(x.principled.clearcoat_gloss, rel=1e-12, abs=1e-12)
        return
    if not y.textures:
        assert list(p.base_color) == factors["baseColorFactor"][:3]
    assert (p.metallic, p.roughness) == (factors["metallicFactor"], factors["roughnessFactor"])


PRINCIPLED_SCENE = """
[camera]
origin = [0, 0, 5]
target = [0, 0, 0]
up = [0, 1, 0]
fov = 40

[film]
width = 32
height = 24

[materials.ball]
type = "principled"
base_color = [0.8, 0.3, 0.1]
metallic = 0.25
roughness = 0.4
eta = 1.7
spec_trans = 0.3

[materials.glass]
type = "roughdielectric"
distribution = "ggx"
alpha = 0.09
int_ior = 1.5
ext_ior = 1.0

[[shapes]]
type = "sphere"
material = "ball"

[[shapes]]
type = "rectangle"
material = "glass"
translate = [0, 0, 2]
"""


def test_principled_and_dielectric_round_trip_exactly(tmp_path):
    """Export then import is the identity for a principled material glTF carries (base colour, metallic, roughness:
    both GGX alpha = roughness^2; eta as KHR_materials_ior; spec_trans as KHR_materials_transmission) and a GGX
    dielectric in vacuum: the core's rows are equal."""
    (tmp_path / "scene.toml").write_text(PRINCIPLED_SCENE)
    original = load_scene(tmp_path / "scene.toml")
    export_scene(original, "gltf", tmp_path / "gltf")
    imported = load_scene(write_imported(import_gltf(tmp_path / "gltf" / "scene.gltf"), tmp_path / "imported"))
    for name in ("ball", "glass"):
        np.testing.assert_array_equal(material_row(imported.materials[name]), material_row(original.materials[name]))


# ---- files written here -------------------------------------------------------------------------------------------


class Doc:
    """A glTF document built here: its JSON (a dict) and its binary buffer; :meth:`save` writes it with pygltflib."""

    QUAD = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    QUAD_UV = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)

    def __init__(self) -> None:
        self.blob = bytearray()
        self.json: dict = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": []}], "nodes": [],
                           "meshes": [], "accessors": [], "bufferViews": [], "materials": [],
                           "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.5,
                                                                                "znear": 0.01}}]}
        self.node({"camera": 0, "translation": [0, 0, 5]})

    def node(self, node: dict, root: bool = True) -> int:
        self.json["nodes"].append(node)
        if root:
            self.json["scenes"][0]["nodes"].append(len(self.json["nodes"]) - 1)
        return len(self.json["nodes"]) - 1

    def accessor(self, data: np.ndarray, component: int, kind: str) -> int:
        raw = np.ascontiguousarray(data).tobytes()
        self.json["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(raw)})
        self.blob += raw + b"\0" * (-len(raw) % 4)
        self.json["accessors"].append({"bufferView": len(self.json["bufferViews"]) - 1, "componentType": component,
                                       "count": len(data), "type": kind})
        return len(self.json["accessors"]) - 1

    def quad(self, material: dict | None = None, node: dict | None = None, *, normals=True, uv=True,
             root: bool = True, **primitive) -> int:
        """A 2 x 2 square in z = 0 facing +z, as a mesh, its node (returned) and its material."""
        attributes = {"POSITION": self.accessor(self.QUAD, 5126, "VEC3")}
        if normals:
            attributes["NORMAL"] = self.accessor(np.tile(np.float32([0, 0, 1]), (4, 1)), 5126, "VEC3")
        if uv:
            attributes["TEXCOORD_0"] = self.accessor(self.QUAD_UV, 5126, "VEC2")
        prim = {"attributes": attributes, "indices": self.accessor(np.uint16([0, 1, 2, 0, 2, 3]), 5123, "SCALAR"),
                **primitive}
        if material is not None:
            self.json["materials"].append(material)
            prim["material"] = len(self.json["materials"]) - 1
        self.json["meshes"].append({"name": f"quad{len(self.json['meshes'])}", "primitives": [prim]})
        return self.node({"mesh": len(self.json["meshes"]) - 1, **(node or {})}, root)

    def image(self, codes: np.ndarray, sampler: dict | None = None) -> int:
        """A PNG texture of ``codes`` (an embedded data URI), its index."""
        from harness.files.imageio import encode_png
        uri = "data:image/png;base64," + base64.b64encode(encode_png(codes)).decode()
        self.json.setdefault("images", []).append({"uri": uri})
        texture = {"source": len(self.json["images"]) - 1}
        if sampler is not None:
            self.json.setdefault("samplers", []).append(sampler)
            texture["sampler"] = len(self.json["samplers"]) - 1
        self.json.setdefault("textures", []).append(texture)
        return len(self.json["textures"]) - 1

    def extension(self, name: str) -> None:
        used = self.json.setdefault("extensionsUsed", [])
        if name not in used:
            used.append(name)

    def save(self, path: Path, container: str = "gltf") -> Path:
        """Write the document: ``glb`` (the buffer in the BIN chunk), ``gltf`` (an external ``.bin`` beside it) or
        ``embedded`` (the buffer as a data URI), through pygltflib."""
        path.parent.mkdir(parents=True, exist_ok=True)
        document = json.loads(json.dumps(self.json))
        blob = bytes(self.blob)
        if container == "glb":
            document["buffers"] = [{"byteLength": len(blob)}]
        elif container == "embedded":
            document["buffers"] = [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                                    + base64.b64encode(blob).decode()}]
        else:
            document["buffers"] = [{"byteLength": len(blob), "uri": path.stem + ".bin"}]
            (path.parent / (path.stem + ".bin")).write_bytes(blob)
        gltf = pygltflib.GLTF2.from_json(json.dumps(document))
        if container == "glb":
            gltf.set_binary_blob(blob)
            gltf.save_binary(str(path))
        else:
            gltf.save_json(str(path))
        return path


def imported(doc: Doc, tmp_path: Path, container: str = "gltf", *, lenient: bool = False):
    """``doc`` written, imported and loaded: (ImportedScene, Scene, the scene file's TOML as a dict)."""
    suffix = ".glb" if container == "glb" else ".gltf"
    source = doc.save(tmp_path / f"in{suffix}", container)
    result = import_gltf(source, lenient=lenient)
    scene = load_scene(write_imported(result, tmp_path / "out"))
    return result, scene, tomllib.loads(result.toml)


def rotation_y(degrees: float) -> list[float]:
    half = math.radians(degrees) / 2
    return [0.0, math.sin(half), 0.0, math.cos(half)]


def test_node_hierarchy_matrix_and_trs(tmp_path):
    """A TRS parent (translate, rotate 90 degrees about y, scale 2) over a child with a column-major matrix
    (translate +1 in x): world = parent @ child, and the vertices are baked to world space."""
    doc = Doc()
    child = doc.quad({}, {"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1]}, root=False)
    doc.node({"translation": [0, 3, 0], "rotation": rotation_y(90), "scale": [2, 2, 2], "children": [child]})
    _, scene, _ = imported(doc, tmp_path)
    geometry = triangulate(scene)
    rot = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], np.float64)
    expected = (Doc.QUAD.astype(np.float64) + [1, 0, 0]) @ (2 * rot).T + [0, 3, 0]
    np.testing.assert_allclose(np.asarray(geometry.vertices), expected[[0, 1, 2, 3]], atol=1e-6)
    normal = np.cross(*(corners(geometry)[0, 1:] - corners(geometry)[0, :1]))
    np.testing.assert_allclose(normal / np.linalg.norm(normal), [1, 0, 0], atol=1e-6)


def test_mirroring_node_keeps_the_front_side(tmp_path):
    """det < 0 (scale -1 in x): glTF's front is then clockwise; the PLY is rewound so the front still faces +z."""
    doc = Doc()
    doc.quad({}, {"scale": [-1, 1, 1]})
    _, scene, _ = imported(doc, tmp_path)
    c = corners(triangulate(scene))
    normals = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    assert np.all(normals[:, 2] > 0)


def test_interleaved_accessors_and_a_short_buffer(tmp_path):
    """POSITION and NORMAL interleaved in one view (byteStride 24, NORMAL at byteOffset 12); then a view shorter
    than its accessor's elements is refused naming the accessor."""
    doc = Doc()
    doc.quad({}, normals=False)
    interleaved = np.concatenate([Doc.QUAD, np.tile(np.float32([0, 0, 1]), (4, 1))], axis=1)
    position = doc.accessor(interleaved, 5126, "VEC3")
    doc.json["bufferViews"][-1]["byteStride"] = 24
    doc.json["accessors"].append({**doc.json["accessors"][position], "byteOffset": 12})
    attributes = doc.json["meshes"][0]["primitives"][0]["attributes"]
    attributes.update(POSITION=position, NORMAL=len(doc.json["accessors"]) - 1)
    _, scene, _ = imported(doc, tmp_path)
    geometry = triangulate(scene)
    np.testing.assert_array_equal(geometry.vertices, Doc.QUAD)
    np.testing.assert_array_equal(geometry.normals, np.tile([0.0, 0.0, 1.0], (2, 3, 1)))
    doc.json["accessors"][-1]["count"] = 5
    with pytest.raises(HarnessError, match=r"/accessors/\d+: its elements run past the end of its buffer view"):
        imported(doc, tmp_path / "short")


@pytest.mark.parametrize("container", ["glb", "gltf", "embedded"])
def test_containers_give_the_same_scene(container, tmp_path):
    """.glb (BIN chunk), .gltf with an external .bin beside it, and .gltf with a data URI: one scene."""
    doc = Doc()
    doc.quad({"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1]}})
    result, scene, _ = imported(doc, tmp_path, container)
    reference = import_gltf(Doc.save(doc, tmp_path / "ref.gltf", "embedded"))
    assert result.toml.replace("in:", "ref:").split("\n", 2)[2] == reference.toml.split("\n", 2)[2]
    assert result.files == reference.files
    assert scene.materials["material0"].principled.base_color == (0.2, 0.4, 0.6)


@pytest.mark.parametrize("uri", ["../outside.bin", "/etc/passwd", "https://example.com/a.bin", "file:///a.bin"])
def test_uri_outside_the_folder_is_refused(uri, tmp_path):
    doc = Doc()
    doc.quad({})
    path = doc.save(tmp_path / "in.gltf", "gltf")
    document = json.loads(path.read_text())
    document["buffers"][0]["uri"] = uri
    path.write_text(json.dumps(document))
    (tmp_path.parent / "outside.bin").write_bytes(bytes(doc.blob))
    with pytest.raises(HarnessError, match=r"/buffers/0/uri: (expected a data URI|URI file '\.\./outside\.bin' "
                                           r"resolves to .*, outside the scene's folder .*; expected a file inside "
                                           r"it$)"):
        import_gltf(path)


def test_material_fields(tmp_path):
    """Base colour factor and texture, metallic, roughness (their texture's G and B channels), a normal map,
    emission with KHR_materials_emissive_strength."""
    doc = Doc()
    codes = np.zeros((2, 2, 3), np.uint8)
    codes[..., 1], codes[..., 2] = [[10, 20], [30, 40]], [[200, 150], [100, 50]]
    mr = doc.image(codes)
    base = doc.image(np.full((2, 2, 3), 128, np.uint8))
    normal = doc.image(np.full((2, 2, 3), [128, 128, 255], np.uint8))
    doc.quad({"name": "painted", "pbrMetallicRoughness": {
        "baseColorTexture": {"index": base}, "metallicFactor": 1.0, "roughnessFactor": 1.0,
        "metallicRoughnessTexture": {"index": mr}}, "normalTexture": {"index": normal}})
    doc.quad({"name": "plain", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 0.125, 1],
                                                         "metallicFactor": 0.3, "roughnessFactor": 0.6}})
    doc.quad({"name": "glow", "emissiveFactor": [1.0, 0.5, 0.25],
              "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 8.0}}})
    doc.extension("KHR_materials_emissive_strength")
    _, scene, toml = imported(doc, tmp_path)
    plain = scene.materials["plain"].principled
    assert (plain.base_color, plain.metallic, plain.roughness) == ((0.5, 0.25, 0.125), 0.3, 0.6)
    painted = scene.materials["painted-normalmap"]
    assert painted.perturbation.type == "normalmap" and painted.perturbation.texture.raw
    textures = dict(scene.materials["painted"].textures)
    np.testing.assert_array_equal(textures["roughness"].image[..., 0], codes[..., 1])
    np.testing.assert_array_equal(textures["metallic"].image[..., 0], codes[..., 2])
    assert textures["roughness"].raw and not textures["base_color"].raw
    glow = [s for s in scene.shapes if s.is_emitter]
    assert len(glow) == 1 and tuple(glow[0].emission) == (8.0, 4.0, 2.0)
    assert toml["shapes"][2]["emission"] == [8.0, 4.0, 2.0]


def test_factor_times_texture_is_baked_exactly(tmp_path):
    """A base colour factor other than 1 on a texture: a float EXR of the decoded codes times the factor (the
    format decodes each texel before filtering, so this is glTF's product)."""
    doc = Doc()
    codes = np.array([[[0, 64, 255], [128, 200, 30]]], np.uint8)
    doc.quad({"pbrMetallicRoughness": {"baseColorTexture": {"index": doc.image(codes)},
                                       "baseColorFactor": [0.5, 1.0, 0.25, 1]}})
    _, scene, _ = imported(doc, tmp_path)
    texture = dict(scene.materials["material0"].textures)["base_color"]
    c = codes / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4) * [0.5, 1.0, 0.25]
    np.testing.assert_allclose(texture.image, linear.astype(np.float32), rtol=0, atol=0)


def test_emissive_texture_and_clearcoat(tmp_path):
    """An emissive texture: the PNG as it is at factor x strength 1, a float EXR of the decoded codes times them
    otherwise; KHR_materials_clearcoat as principled's clearcoat, gloss = (0.1 - roughness^2) / 0.099."""
    doc = Doc()
    codes = np.array([[[255, 128, 0]]], np.uint8)
    doc.quad({"name": "sign", "emissiveFactor": [1, 1, 1], "emissiveTexture": {"index": doc.image(codes)}})
    doc.quad({"name": "neon", "emissiveFactor": [1, 0.5, 1], "emissiveTexture": {"index": doc.image(codes)},
              "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}})
    doc.quad({"name": "coated", "extensions": {"KHR_materials_clearcoat": {
        "clearcoatFactor": 0.6, "clearcoatRoughnessFactor": math.sqrt(0.05)}}})
    result, scene, _ = imported(doc, tmp_path)
    sign, neon = (s.emission_texture for s in scene.shapes[:2])
    assert sign.file.suffix == ".png" and not sign.raw
    np.testing.assert_array_equal(sign.image, codes)
    c = codes / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4) * [4.0, 2.0, 4.0]
    np.testing.assert_array_equal(neon.image, linear.astype(np.float32))
    coat = scene.materials["coated"].principled
    assert coat.clearcoat == 0.6 and coat.clearcoat_gloss == pytest.approx(0.05 / 0.099, rel=1e-12)
    assert "clear coat of gloss" in scene.description


def test_a_file_trimesh_writes(tmp_path):
    """Another writer's conventions (trimesh's GLB: node matrices, a PBR material, a primitive without material or
    normals, mesh extras): imported without refusals, the box turned by its node, the ball in glTF's default
    material."""
    trimesh = pytest.importorskip("trimesh")
    scene = trimesh.Scene()
    box = trimesh.creation.box()
    box.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        baseColorFactor=[255, 128, 0, 255], metallicFactor=0.25, roughnessFactor=0.5))
    turn = trimesh.transformations.rotation_matrix(0.5, [0, 1, 0])
    scene.add_geometry(box, node_name="box", transform=turn)
    scene.add_geometry(trimesh.creation.icosphere(), node_name="ball",
                       transform=trimesh.transformations.translation_matrix([2, 0, 0]))
    scene.camera_transform = trimesh.transformations.translation_matrix([0, 0, 6])
    (tmp_path / "tm.glb").write_bytes(scene.export(file_type="glb"))
    result = import_gltf(tmp_path / "tm.glb")
    assert result.dropped == []
    loaded = load_scene(write_imported(result, tmp_path / "out"))
    box_shape = loaded.shapes[0]
    p = loaded.materials[box_shape.material].principled
    assert (p.metallic, p.roughness) == (0.25, 0.5) and p.base_color[0] == 1.0
    vertices, _ = shape_triangles(box_shape)
    np.testing.assert_allclose(vertices, np.float32(box.vertices @ turn[:3, :3].T), atol=1e-6)
    assert loaded.materials[loaded.shapes[1].material].principled.metallic == 1.0  # glTF's default material


def test_a_textured_material_needs_texture_coordinates(tmp_path):
    doc = Doc()
    doc.quad({"pbrMetallicRoughness": {"baseColorTexture": {"index": doc.image(np.zeros((1, 1, 3), np.uint8))}}},
             uv=False)
    with pytest.raises(HarnessError, match="/meshes/0/primitives/0/attributes: a textured material on a primitive "
                                           "without TEXCOORD_0"):
        import_gltf(doc.save(tmp_path / "in.gltf"))


def test_an_emitting_shape_shades_flat(tmp_path):
    """The format's lights are flat: an emitting primitive's NORMAL is not used (face_normals), and the description
    says so."""
    doc = Doc()
    doc.quad({"emissiveFactor": [1, 1, 1]})
    _, scene, toml = imported(doc, tmp_path)
    assert toml["shapes"][0]["face_normals"] is True
    assert "/meshes/0/primitives/0/attributes/NORMAL: an emitting shape shades flat" in scene.description


def test_a_malformed_document_is_one_line(tmp_path):
    doc = Doc()
    doc.quad({})
    doc.json["cameras"][0]["perspective"] = {"aspectRatio": 1.0}  # yfov is required
    with pytest.raises(HarnessError, match=r"in.gltf: a malformed glTF document \(KeyError: 'yfov'\)"):
        import_gltf(doc.save(tmp_path / "in.gltf"))


def test_a_required_extension_it_does_not_read_is_refused_even_leniently(tmp_path):
    doc = Doc()
    doc.quad({})
    doc.json["extensionsRequired"] = doc.json["extensionsUsed"] = ["KHR_draco_mesh_compression"]
    with pytest.raises(HarnessError, match="/extensionsRequired/KHR_draco_mesh_compression: a required extension"):
        import_gltf(doc.save(tmp_path / "in.gltf"), lenient=True)


def test_alpha_modes(tmp_path):
    """MASK with a constant alpha: opacity 1 (no mask) or 0 by the cutoff; BLEND: opacity = alpha; MASK with a
    texture's alpha: the texels cut at alphaCutoff (raw 0 / 255)."""
    doc = Doc()
    doc.quad({"name": "cut", "alphaMode": "MASK", "alphaCutoff": 0.6,
              "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.5]}})
    doc.quad({"name": "kept", "alphaMode": "MASK", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.5]}})
    doc.quad({"name": "glass", "alphaMode": "BLEND", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 0.3]}})
    rgba = np.zeros((1, 3, 4), np.uint8)
    rgba[0, :, 3] = [0, 120, 255]
    doc.quad({"name": "leaf", "alphaMode": "MASK", "alphaCutoff": 0.5,
              "pbrMetallicRoughness": {"baseColorTexture": {"index": doc.image(rgba)}}})
    _, scene, _ = imported(doc, tmp_path)
    by_shape = [scene.materials[s.material] for s in scene.shapes]
    assert (by_shape[0].type, by_shape[0].weight) == ("mask", 0.0)
    assert by_shape[1].type == "principled"
    assert (by_shape[2].type, by_shape[2].weight) == ("mask", 0.3)
    opacity = dict(by_shape[3].textures)["opacity"]
    np.testing.assert_array_equal(opacity.image[0, :, 0], [0, 0, 255])


def test_texture_transform_and_sampler(tmp_path):
    """KHR_texture_transform as to_uv (T R S, the export's convention), the sampler's filter and wrap."""
    doc = Doc()
    index = doc.image(np.full((2, 2, 3), 100, np.uint8), {"magFilter": 9728, "minFilter": 9728, "wrapS": 33648,
                                                         "wrapT": 33648})
    transform = {"offset": [0.25, 0.5], "rotation": 0.3, "scale": [2.0, 3.0]}
    doc.quad({"pbrMetallicRoughness": {"baseColorTexture": {
        "index": index, "extensions": {"KHR_texture_transform": transform}}}})
    doc.extension("KHR_texture_transform")
    _, scene, _ = imported(doc, tmp_path)
    texture = dict(scene.materials["material0"].textures)["base_color"]
    assert (texture.filter_type, texture.wrap_mode) == ("nearest", "mirror")
    np.testing.assert_allclose(texture.to_uv, uv_matrix(transform), rtol=1e-15)
    back = gltf_uv_transform(texture.to_uv)
    assert back["offset"] == pytest.approx(transform["offset"]) and back["rotation"] == pytest.approx(0.3)
    assert back["scale"] == pytest.approx(transform["scale"])


def test_punctual_lights(tmp_path):
    """Point and spot (candela) and directional (lux) lights: W/sr and W/m^2 = color x intensity / 683, placed by
    their nodes (position, -z)."""
    doc = Doc()
    doc.quad({})
    doc.json["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "point", "color": [1, 0.5, 0.25], "intensity": 683.0},
        {"type": "spot", "intensity": 2 * 683.0, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
        {"type": "directional", "color": [0.5, 0.5, 1], "intensity": 3 * 683.0}]}}
    doc.extension("KHR_lights_punctual")
    doc.node({"translation": [1, 2, 3], "extensions": {"KHR_lights_punctual": {"light": 0}}})
    doc.node({"translation": [0, 4, 0], "rotation": [-math.sqrt(0.5), 0, 0, math.sqrt(0.5)],
              "extensions": {"KHR_lights_punctual": {"light": 1}}})
    doc.node({"rotation": rotation_y(90), "extensions": {"KHR_lights_punctual": {"light": 2}}})
    _, scene, _ = imported(doc, tmp_path)
    point, spot, sun = scene.emitters
    assert tuple(point.position) == (1, 2, 3) and tuple(point.intensity) == (1, 0.5, 0.25)
    np.testing.assert_allclose(spot.position, [0, 4, 0])
    np.testing.assert_allclose(spot.axis, [0, -1, 0], atol=1e-12)
    assert tuple(spot.intensity) == (2, 2, 2)
    assert spot.cutoff_angle == pytest.approx(math.degrees(0.5)) and spot.beam_width == pytest.approx(
        math.degrees(0.2))
    np.testing.assert_allclose(sun.direction, [-1, 0, 0], atol=1e-12)
    assert tuple(sun.irradiance) == (1.5, 1.5, 3.0)
    assert LUMENS_PER_WATT == 683.0


def test_transmission_and_ior(tmp_path):
    """Full transmission with a volume: dielectric (smooth) or roughdielectric (GGX, alpha = roughness^2); without
    a volume a thindielectric; a partial one principled's spec_trans; KHR_materials_ior as eta."""
    doc = Doc()
    for name, roughness, factor, volume in (("glass", 0.0, 1.0, True), ("frosted", 0.5, 1.0, True),
                                            ("pane", 0.0, 1.0, False), ("milky", 0.4, 0.5, False)):
        extensions = {"KHR_materials_transmission": {"transmissionFactor": factor},
                      "KHR_materials_ior": {"ior": 1.33}}
        if volume:
            extensions["KHR_materials_volume"] = {"thicknessFactor": 1.0}
        doc.quad({"name": name, "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": roughness,
                                                          "baseColorFactor": [0.9, 1, 1, 1]},
                  "extensions": extensions})
    for name in ("KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume"):
        doc.extension(name)
    _, scene, _ = imported(doc, tmp_path)
    m = scene.materials
    assert (m["glass"].type, m["glass"].int_ior, m["glass"].ext_ior) == ("dielectric", 1.33, 1.0)
    assert m["glass"].specular_transmittance == (0.9, 1.0, 1.0)
    assert (m["frosted"].type, m["frosted"].distribution, m["frosted"].alpha) == ("roughdielectric", "ggx", 0.25)
    assert m["pane"].type == "thindielectric"
    assert (m["milky"].type, m["milky"].principled.spec_trans, m["milky"].principled.eta) == ("principled", 0.5,
                                                                                              1.33)


def test_cameras(tmp_path):
    """Perspective: yfov as fov with fov_axis y, the film from the aspect ratio; orthographic: scale from xmag /
    ymag; the camera looks down its node's -z."""
    doc = Doc()
    doc.quad({})
    _, scene, toml = imported(doc, tmp_path)
    assert toml["camera"]["fov_axis"] == "y" and toml["camera"]["fov"] == pytest.approx(math.degrees(0.8))
    assert (scene.film.width, scene.film.height) == (512, 341)
    assert tuple(scene.camera.origin) == (0, 0, 5) and tuple(scene.camera.target) == (0, 0, 4)
    doc.json["cameras"] = [{"type": "orthographic", "orthographic": {"xmag": 2.0, "ymag": 1.0, "znear": 0.1,
                                                                     "zfar": 100}}]
    _, scene, _ = imported(doc, tmp_path / "ortho")
    assert scene.camera.extent(scene.film.width, scene.film.height) == pytest.approx((2.0, 1.0))


# ---- refusals -------------------------------------------------------------------------------------------------


def _skin(doc):
    doc.json["skins"] = [{"joints": [0]}]


def _animation(doc):
    doc.json["animations"] = [{"channels": [], "samplers": []}]


def _morph(doc):
    doc.json["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": 0}]


def _lines(doc):
    doc.json["meshes"][0]["primitives"][0]["mode"] = 1


def _sparse(doc):
    doc.json["accessors"][0]["sparse"] = {"count": 1, "indices": {}, "values": {}}


def _unknown_extension(doc):
    doc.json["materials"][0]["extensions"] = {"KHR_materials_sheen": {}}


def _second_uv(doc):
    doc.json["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_1"] = 2


def _light_range(doc):
    doc.json["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "point", "range": 5.0}]}}
    doc.node({"extensions": {"KHR_lights_punctual": {"light": 0}}})


def _normal_scale(doc):
    doc.json["materials"][0]["normalTexture"] = {"index": doc.image(np.full((1, 1, 3), 128, np.uint8)),
                                                 "scale": 0.5}


def _occlusion(doc):
    doc.json["materials"][0]["occlusionTexture"] = {"index": doc.image(np.full((1, 1, 3), 128, np.uint8))}


def _wrap(doc):
    doc.json["materials"][0]["pbrMetallicRoughness"] = {"baseColorTexture": {"index": doc.image(
        np.full((1, 1, 3), 128, np.uint8), {"wrapS": 10497, "wrapT": 33071})}}


def _second_camera(doc):
    doc.node({"camera": 0})


REFUSALS = [
    (_skin, "/skins"), (_animation, "/animations"), (_morph, "/meshes/0/primitives/0/targets"),
    (_lines, "/meshes/0/primitives/0/mode"), (_sparse, "/accessors/0/sparse"),
    (_unknown_extension, "/materials/0/extensions/KHR_materials_sheen"),
    (_second_uv, "/meshes/0/primitives/0/attributes/TEXCOORD_1"),
    (_light_range, "/extensions/KHR_lights_punctual/lights/0/range"),
    (_normal_scale, "/materials/0/normalTexture/scale"), (_occlusion, "/materials/0/occlusionTexture"),
    (_wrap, "/samplers/0/wrapT"), (_second_camera, "/nodes/2/camera"),
]


@pytest.mark.parametrize("change, where", REFUSALS, ids=[f.__name__.strip("_") for f, _ in REFUSALS])
def test_refusal_names_the_json_path(change, where, tmp_path):
    doc = Doc()
    doc.quad({"name": "m"})
    change(doc)
    source = doc.save(tmp_path / "in.gltf")
    with pytest.raises(HarnessError) as caught:
        import_gltf(source)
    assert caught.value.where == f"{source}: {where}"
    assert "\n" not in str(caught.value)
    result = import_gltf(source, lenient=True)  # lenient: dropped, listed, and the rest still a scene
    assert f"{source}: {where}: {caught.value.message} (dropped)" in result.dropped  # the strict line, named
    scene = load_scene(write_imported(result, tmp_path / "out"))
    assert f"dropped: {source}: {where}" in scene.description


def test_a_file_without_camera_is_refused_even_leniently(tmp_path):
    doc = Doc()
    doc.quad({})
    doc.json["scenes"][0]["nodes"].remove(0)
    with pytest.raises(HarnessError, match="/cameras: expected a node of the scene with a camera"):
        import_gltf(doc.save(tmp_path / "in.gltf"), lenient=True)


# ---- a render --------------------------------------------------------------------------------------------------------


def test_an_imported_scene_renders(tmp_path):
    """An imported scene (a lit textured quad) renders with the reference renderer at 2 spp."""
    from harness.renderers import get_renderer
    from harness.renderers.base import RenderRequest
    doc = Doc()
    doc.quad({"pbrMetallicRoughness": {"baseColorTexture": {"index": doc.image(np.full((2, 2, 3), 180, np.uint8))},
                                       "metallicFactor": 0.0, "roughnessFactor": 0.7}})
    doc.quad({"emissiveFactor": [1, 1, 1]}, {"translation": [0, 0, 2], "rotation": [1, 0, 0, 0],
                                             "scale": [0.3, 0.3, 0.3]})  # facing the lit quad, small
    _, scene, _ = imported(doc, tmp_path)
    scene = load_scene(tmp_path / "out" / "scene.toml")
    import dataclasses
    scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=24, height=16))
    result = get_renderer("reference").render(scene, RenderRequest(spp=2, seed=0))
    assert result.image.shape == (16, 24, 3) and np.all(np.isfinite(result.image)) and result.image.max() > 0


# ---- found on third-party files (docs/import.md, "Tried on third-party files"), each written here small -----------


def test_a_mask_of_a_texture_s_alpha_says_it_is_approximated(tmp_path):
    """AlphaBlendModeTest's MASK materials cut a texture's alpha read bilinearly: docs/import.md calls that
    approximated, and the description now says so (it said nothing); with ``nearest`` the cut is exact, no note."""
    rgba = np.zeros((1, 3, 4), np.uint8)
    rgba[0, :, 3] = [0, 120, 255]
    for sampler, noted in ((None, True), ({"magFilter": 9728, "minFilter": 9728}, False)):
        doc = Doc()
        doc.quad({"name": "leaf", "alphaMode": "MASK", "alphaCutoff": 0.25,
                  "pbrMetallicRoughness": {"baseColorTexture": {"index": doc.image(rgba, sampler)}}})
        result, _, _ = imported(doc, tmp_path / str(noted))
        description = tomllib.loads(result.toml)["description"]
        assert ("/materials/0/alphaMode: MASK of a texture's alpha cut per texel (cutoff 0.25)" in description) is noted


def test_a_missing_buffer_file_is_named_in_one_line(tmp_path):
    """A .gltf whose .bin is not beside it: the URI named as missing (harness.scene.mesh_files.confined_path)."""
    doc = Doc()
    doc.quad({})
    path = doc.save(tmp_path / "in.gltf", "gltf")
    for name in tmp_path.glob("*.bin"):
        name.unlink()
    with pytest.raises(HarnessError) as caught:
        import_gltf(path)
    assert "/buffers/0/uri: no such URI file: " in str(caught.value) and "\n" not in str(caught.value)
