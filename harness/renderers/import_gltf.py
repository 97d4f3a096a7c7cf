"""A glTF 2.0 file (``.gltf`` or ``.glb``) read into this project's scene format (docs/import.md, "glTF 2.0").

The inverse of :func:`harness.renderers.export.gltf_document`: the default scene's node tree is walked from its roots,
each node's local matrix (``matrix``, column-major, or T R S) multiplied down the tree (glTF 2.0 specification,
3.5.2-3.5.3); every triangle primitive becomes a PLY mesh baked to world space (positions, normals, ``TEXCOORD_0``),
its metallic-roughness material Mitsuba's ``principled`` (or a dielectric where the material is a full
``KHR_materials_transmission``), its emission an area light, the first camera the scene's camera and
``KHR_lights_punctual`` lights point, spot and directional emitters. Whatever the scene format cannot hold is refused
in one line naming the glTF JSON path (``/materials/3/extensions/KHR_x``); with ``lenient`` it is dropped instead and
listed in :attr:`ImportedScene.dropped` and the scene's description. Approximations that are not refusals (the
format's principled is one-sided) are stated in the description too: nothing is changed silently.

The JSON and the GLB container are read here, not with pygltflib: the importer must see every key and extension as
written to refuse what it cannot carry (pygltflib's dataclasses drop unknown properties), and must confine every URI
to the file's folder (pygltflib opens any path a URI names). pygltflib writes the tests' files.
"""

from __future__ import annotations

import base64
import io
import json
import math
import re
import struct
from pathlib import Path, PurePosixPath
from urllib.parse import unquote

import numpy as np

from harness.core.errors import HarnessError, not_regular
from harness.files.imageio import encode_png, exr_bytes
from harness.renderers.imports import ImportedScene, toml_key, toml_table, toml_value
from harness.renderers.meshfiles import MESH_DIR, TEXTURE_DIR, ply_bytes, safe_name
from harness.scene.kinds.emitters import LUMENS_PER_WATT
from harness.scene.mesh_files import confined_path
from reference_impl.textures import srgb_to_linear

#: The extensions this importer reads (docs/import.md); any other in ``extensionsUsed`` or on an element is refused.
SUPPORTED_EXTENSIONS = ("KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_texture_transform",
                        "KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume",
                        "KHR_materials_clearcoat")
#: glTF accessor component types: numpy dtype and the divisor of a normalized integer (glTF 2.0, 3.11).
COMPONENTS = {5120: ("<i1", 127.0), 5121: ("<u1", 255.0), 5122: ("<i2", 32767.0), 5123: ("<u2", 65535.0),
              5125: ("<u4", None), 5126: ("<f4", None)}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
#: glTF sampler constants (WebGL's) as the scene format's ``filter_type`` and ``wrap_mode``
#: (:data:`harness.renderers.export.GLTF_FILTERS`, ``GLTF_WRAPS`` inverted).
FILTERS = {9728: "nearest", 9729: "bilinear"}
WRAPS = {10497: "repeat", 33648: "mirror", 33071: "clamp"}
GLB_MAGIC = b"glTF"
MAX_FILE_BYTES = 1 << 30
#: The film of a file that does not carry one (``asset.extras.film``, as the harness's export writes): this width,
#: the height from the camera's aspect ratio.
DEFAULT_WIDTH = 512
#: Mitsuba's rotation of a look-at frame against glTF's camera: glTF's camera looks down its -z with +x to the image's
#: right, Mitsuba's down +z with +x to the left (:func:`harness.renderers.export.gltf_camera`).
CAMERA_FLIP = np.diag([-1.0, 1.0, -1.0, 1.0])


def import_gltf(path: Path, *, lenient: bool = False) -> ImportedScene:
    """The glTF 2.0 file ``path`` (``.gltf`` JSON or ``.glb`` binary) as an :class:`ImportedScene`.

    Refuses (:class:`HarnessError` naming ``path`` and the JSON path) what the scene format cannot express; with
    ``lenient`` drops it instead and lists it in ``dropped`` and the description."""
    path = Path(path)
    document, glb_blob = read_container(path)
    try:
        return _Importer(path, document, glb_blob, lenient).scene()
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError) as err:
        # a value of the wrong JSON type or a missing required property (the schema's), past the checks above
        raise HarnessError(str(path), f"a malformed glTF document ({type(err).__name__}: {err}); "
                                      "check it with the Khronos glTF validator") from None


# ---- the container --------------------------------------------------------------------------------------------------


def read_container(path: Path) -> tuple[dict, bytes | None]:
    """The JSON document and a GLB's BIN chunk (None for a ``.gltf``): GLB per glTF 2.0, 4.4 (a 12-byte header
    ``glTF``, version 2, length; then chunks of length, type, data: JSON first, BIN optional second)."""
    irregular = not_regular(path)  # a named pipe would block the read
    if irregular is not None:
        raise irregular
    try:
        data = path.read_bytes()
    except OSError as err:
        raise HarnessError(str(path), f"cannot read: {err.strerror or err}") from None
    if len(data) > MAX_FILE_BYTES:
        raise HarnessError(str(path), f"expected a glTF file of at most 1 GiB, got {len(data)} bytes")
    blob = None
    if data[:4] == GLB_MAGIC:
        if len(data) < 20:
            raise HarnessError(str(path), "a GLB file shorter than its header")
        version, length = struct.unpack_from("<II", data, 4)
        if version != 2 or length > len(data):
            raise HarnessError(str(path), f"expected a GLB of version 2 and length {len(data)}, got version "
                                          f"{version}, length {length}")
        chunks, offset = [], 12
        while offset + 8 <= length:
            size, kind = struct.unpack_from("<I4s", data, offset)
            if offset + 8 + size > length:
                raise HarnessError(str(path), f"GLB chunk {len(chunks)} runs past the file's end")
            chunks.append((kind, data[offset + 8:offset + 8 + size]))
            offset += 8 + size + (-size % 4)
        if not chunks or chunks[0][0] != b"JSON":
            raise HarnessError(str(path), "expected a GLB whose first chunk is JSON")
        text = chunks[0][1]
        blob = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == b"BIN\0" else None
    else:
        text = data
    try:
        document = json.loads(text.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as err:
        raise HarnessError(str(path), f"expected glTF JSON: {err}") from None
    if not isinstance(document, dict):
        raise HarnessError(str(path), "expected a JSON object at the top level")
    version = str(document.get("asset", {}).get("version", ""))
    if not version.startswith("2."):
        raise HarnessError(f"{path}: /asset/version", f"expected glTF 2.x, got {version!r}")
    return document, blob


# ---- transforms -----------------------------------------------------------------------------------------------------


def quaternion_matrix(q) -> np.ndarray:
    """The 3x3 rotation of a unit quaternion [x, y, z, w] (glTF's order, 3.5.2)."""
    x, y, z, w = (float(v) for v in q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def local_matrix(node: dict) -> np.ndarray:
    """A node's local 4x4 matrix: ``matrix`` (16 numbers, column-major) or T R S (glTF 2.0, 3.5.2: M = T * R * S;
    translation [0, 0, 0], rotation [0, 0, 0, 1] and scale [1, 1, 1] by default)."""
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
    out = np.eye(4)
    out[:3, :3] = quaternion_matrix(node.get("rotation", [0, 0, 0, 1])) @ np.diag(
        np.asarray(node.get("scale", [1, 1, 1]), np.float64))
    out[:3, 3] = node.get("translation", [0, 0, 0])
    return out


def uv_matrix(transform: dict) -> np.ndarray:
    """``KHR_texture_transform``'s offset, rotation, scale as the scene format's ``to_uv`` (3x3): T(offset) R(r)
    S(scale) with R(r) = [[cos r, sin r], [-sin r, cos r]] on (u, v), the inverse of
    :func:`harness.renderers.export.gltf_uv_transform` (which names the extension's rotation convention)."""
    su, sv = (float(x) for x in transform.get("scale", [1.0, 1.0]))
    r = float(transform.get("rotation", 0.0))
    tu, tv = (float(x) for x in transform.get("offset", [0.0, 0.0]))
    c, s = math.cos(r), math.sin(r)
    return np.array([[c * su, s * sv, tu], [-s * su, c * sv, tv], [0.0, 0.0, 1.0]])


# ---- the importer ---------------------------------------------------------------------------------------------------


class _Importer:
    """One file's import: the document, its buffers, and the scene's tables as they are built."""

    def __init__(self, path: Path, document: dict, glb_blob: bytes | None, lenient: bool) -> None:
        self.path, self.doc, self.glb_blob, self.lenient = path, document, glb_blob, lenient
        self.folder = path.resolve().parent
        self.dropped: list[str] = []
        self.notes: list[str] = []
        self.files: dict[str, bytes] = {}
        self.buffers: dict[int, bytes] = {}
        self.textures: dict[str, dict] = {}
        self.materials: dict[str, dict] = {}
        self.material_names: dict[int | None, dict] = {}
        self.shapes: list[dict] = []
        self.emitters: list[dict] = []
        self.camera: dict | None = None
        self.texture_names: dict[tuple, str] = {}
        self.images: dict[int, tuple[str, bytes]] = {}
        self.film: dict = {}

    # -- refusals --

    def refuse(self, where: str, message: str) -> None:
        """Refuse the element at JSON path ``where``: raise, or with ``lenient`` record it as dropped."""
        if not self.lenient:
            raise HarnessError(f"{self.path}: {where}", message)
        self.dropped.append(f"{self.path}: {where}: {message} (dropped)")  # the strict line, as the other importers

    def fail(self, where: str, message: str) -> HarnessError:
        """An error no leniency drops (a broken file, or a scene without what the format requires)."""
        return HarnessError(f"{self.path}: {where}", message)

    def check_extensions(self, element: dict, where: str) -> dict:
        """An element's extensions this importer reads; any other is refused (or dropped)."""
        out = {}
        for name, value in (element.get("extensions") or {}).items():
            if name in SUPPORTED_EXTENSIONS:
                out[name] = value
            else:
                self.refuse(f"{where}/extensions/{name}", f"an extension the scene format has no counterpart for "
                                                          f"(read: {', '.join(SUPPORTED_EXTENSIONS)})")
        return out

    def item(self, array: str, index, where: str) -> dict:
        """``/array/index`` of the document, or an error naming ``where``."""
        items = self.doc.get(array) or []
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items):
            raise self.fail(where, f"expected an index into /{array} (0 .. {len(items) - 1}), got {index!r}")
        return items[index]

    # -- the document --

    def scene(self) -> ImportedScene:
        """Walk the document and return the scene file's text and files."""
        doc = self.doc
        for name in doc.get("extensionsRequired") or []:
            if name not in SUPPORTED_EXTENSIONS:
                raise self.fail(f"/extensionsRequired/{name}", "a required extension this importer does not read "
                                                                f"(read: {', '.join(SUPPORTED_EXTENSIONS)})")
        for key in ("animations", "skins"):
            if doc.get(key):
                self.refuse(f"/{key}", f"{key} are not part of the scene format (a still scene)")
        self.check_extensions(doc, "")
        scenes = doc.get("scenes") or []
        index = doc.get("scene", 0)
        if not scenes:
            raise self.fail("/scenes", "expected a scene to import; the file has none")
        self.check_extensions(self.item("scenes", index, "/scene"), f"/scenes/{index}")
        roots = self.item("scenes", index, "/scene").get("nodes") or []
        for root in roots:
            self.walk(root, np.eye(4), set())
        if self.camera is None:
            raise self.fail("/cameras", "expected a node of the scene with a camera (the scene format needs one)")
        return ImportedScene(toml=self.text(), files=self.files, dropped=list(self.dropped), source=self.path)

    def walk(self, index: int, parent: np.ndarray, seen: set) -> None:
        """Node ``index`` and its children, their world matrices multiplied down the tree (parent @ local)."""
        where = f"/nodes/{index}"
        node = self.item("nodes", index, where)
        if index in seen:
            raise self.fail(where, "a node reached twice (the node hierarchy must be a forest)")
        seen.add(index)
        for key in ("skin", "weights"):
            if key in node:
                self.refuse(f"{where}/{key}", f"{'skinning' if key == 'skin' else 'morph target weights'} are not "
                                              "part of the scene format")
        world = parent @ local_matrix(node)
        extensions = self.check_extensions(node, where)
        if "mesh" in node:
            self.mesh(node["mesh"], world, node.get("name"), f"{where}/mesh")
        if "camera" in node:
            self.place_camera(node["camera"], world, f"{where}/camera")
        light = extensions.get("KHR_lights_punctual")
        if light is not None:
            self.light(light.get("light"), world, node.get("name"), f"{where}/extensions/KHR_lights_punctual")
        for child in node.get("children") or []:
            self.walk(child, world, seen)

    # -- buffers and accessors --

    def uri_bytes(self, uri: str, where: str) -> bytes:
        """The bytes of a URI: a ``data:`` URI (base64), or a relative path inside the file's folder; a remote URL,
        an absolute path and a path leaving the folder are refused (glTF 2.0, 3.3.2: URIs are relative to the file)."""
        if uri.startswith("data:"):
            head, _, payload = uri.partition(",")
            if not head.endswith(";base64"):
                raise self.fail(where, "expected a base64 data URI")
            try:
                return base64.b64decode(payload, validate=True)
            except ValueError as err:
                raise self.fail(where, f"a data URI that is not base64: {err}") from None
        if re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", uri) or uri.startswith(("/", "\\")):
            raise self.fail(where, f"expected a data URI or a relative path inside {self.folder}, got {uri!r}")
        try:  # inside the file's folder after symlinks, a regular file (a named pipe would block the read)
            target = confined_path(self.folder, str(PurePosixPath(unquote(uri))), "URI", where, outside_hint="")
        except HarnessError as err:
            raise self.fail(where, err.message) from None
        try:
            return target.read_bytes()
        except OSError as err:
            raise self.fail(where, f"cannot read {uri!r}: {err.strerror or err}") from None

    def buffer(self, index: int, where: str) -> bytes:
        """Buffer ``index``'s bytes: its URI's, or the GLB's BIN chunk for a buffer without a URI."""
        if index not in self.buffers:
            entry = self.item("buffers", index, where)
            if "uri" in entry:
                data = self.uri_bytes(entry["uri"], f"/buffers/{index}/uri")
            elif self.glb_blob is not None and index == 0:
                data = self.glb_blob
            else:
                raise self.fail(f"/buffers/{index}", "a buffer without a URI outside a GLB's first buffer")
            if len(data) < int(entry.get("byteLength", 0)):
                raise self.fail(f"/buffers/{index}/byteLength", f"the buffer holds {len(data)} bytes, fewer than "
                                                                f"its byteLength {entry.get('byteLength')}")
            self.buffers[index] = data
        return self.buffers[index]

    def view_bytes(self, index: int, where: str) -> tuple[bytes, int | None]:
        """A buffer view's bytes and its byteStride."""
        view = self.item("bufferViews", index, where)
        self.check_extensions(view, f"/bufferViews/{index}")
        data = self.buffer(view.get("buffer"), f"/bufferViews/{index}/buffer")
        start, length = int(view.get("byteOffset", 0)), int(view["byteLength"])
        if start + length > len(data):
            raise self.fail(f"/bufferViews/{index}", "runs past the end of its buffer")
        return data[start:start + length], view.get("byteStride")

    def accessor(self, index: int, where: str) -> np.ndarray | None:
        """An accessor's values, (count, width) float64 (normalized integers divided to [0, 1] or [-1, 1]); None
        for a sparse accessor that is refused leniently."""
        entry = self.item("accessors", index, where)
        here = f"/accessors/{index}"
        self.check_extensions(entry, here)
        if "sparse" in entry:
            self.refuse(f"{here}/sparse", "sparse accessors are not read")
            return None
        if entry.get("componentType") not in COMPONENTS or entry.get("type") not in WIDTHS:
            raise self.fail(here, f"an accessor of componentType {entry.get('componentType')} and type "
                                  f"{entry.get('type')!r}")
        dtype, divisor = COMPONENTS[entry["componentType"]]
        width, count = WIDTHS[entry["type"]], int(entry["count"])
        if "bufferView" not in entry:
            return np.zeros((count, width))
        data, stride = self.view_bytes(entry["bufferView"], f"{here}/bufferView")
        item = np.dtype(dtype).itemsize * width
        stride = stride or item
        start = int(entry.get("byteOffset", 0))
        if count and start + stride * (count - 1) + item > len(data):
            raise self.fail(here, "its elements run past the end of its buffer view")
        if count == 0:
            return np.zeros((0, width))
        values = np.ndarray((count, width), dtype, data, start, (stride, np.dtype(dtype).itemsize))  # strided view
        out = values.astype(np.float64)
        if entry.get("normalized") and divisor is not None:
            out = np.maximum(out / divisor, -1.0)
        return out

    # -- meshes --

    def mesh(self, index: int, world: np.ndarray, node_name: str | None, where: str) -> None:
        """Every primitive of mesh ``index`` as a world-space PLY shape (:meth:`primitive`)."""
        mesh = self.item("meshes", index, where)
        if "weights" in mesh:
            self.refuse(f"/meshes/{index}/weights", "morph target weights are not part of the scene format")
        self.check_extensions(mesh, f"/meshes/{index}")
        for p, primitive in enumerate(mesh.get("primitives") or []):
            name = node_name or mesh.get("name") or f"mesh{index}"
            if len(mesh["primitives"]) > 1:
                name = f"{name}-{p}"
            self.primitive(primitive, world, name, f"/meshes/{index}/primitives/{p}")

    def primitive(self, primitive: dict, world: np.ndarray, name: str, where: str) -> None:
        """One triangle primitive: positions p' = M p, normals n' = normalize(M^-T n), ``TEXCOORD_0`` as they are
        (glTF's UV origin is the image's top left with v down, Mitsuba's too: docs/scene-format.md, "Textures"),
        the winding reversed where det M < 0 (glTF 2.0, 3.7.2.1: a negative determinant makes clockwise the front),
        so the PLY's counter-clockwise side is the front; written with ``face_normals`` where NORMAL is absent
        (the specification's flat shading)."""
        mode = primitive.get("mode", 4)
        if mode != 4:
            self.refuse(f"{where}/mode", f"expected triangles (mode 4), got mode {mode}: points, lines, strips and "
                                         "fans are not read")
            return
        if primitive.get("targets"):
            self.refuse(f"{where}/targets", "morph targets are not part of the scene format")
        self.check_extensions(primitive, where)
        attributes = primitive.get("attributes") or {}
        for key in attributes:
            if key not in ("POSITION", "NORMAL", "TEXCOORD_0", "TANGENT"):
                self.refuse(f"{where}/attributes/{key}", "an attribute the scene format has no place for "
                                                         "(read: POSITION, NORMAL, TEXCOORD_0; TANGENT replaced by "
                                                         "Mitsuba's frame from the texture coordinates)")
        if "POSITION" not in attributes:
            raise self.fail(f"{where}/attributes", "a primitive without POSITION")
        positions = self.accessor(attributes["POSITION"], f"{where}/attributes/POSITION")
        if positions is None:
            return
        if "indices" in primitive:
            indices = self.accessor(primitive["indices"], f"{where}/indices")
            if indices is None:
                return
            triangles = indices.astype(np.int64).reshape(-1, 3)
        else:
            triangles = np.arange(len(positions) - len(positions) % 3, dtype=np.int64).reshape(-1, 3)
        if len(triangles) == 0:
            self.notes.append(f"{where}: a primitive without triangles, left out")
            return
        if triangles.min() < 0 or triangles.max() >= len(positions):
            raise self.fail(f"{where}/indices", f"indices outside 0 .. {len(positions) - 1}")
        linear = world[:3, :3]
        vertices = positions @ linear.T + world[:3, 3]
        if np.linalg.det(linear) < 0:
            triangles = triangles[:, ::-1].copy()
        normals = uv = None
        if "NORMAL" in attributes:
            normals = self.accessor(attributes["NORMAL"], f"{where}/attributes/NORMAL")
            if normals is not None:
                with np.errstate(all="ignore"):
                    normals = normals @ np.linalg.inv(linear)
                    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        if "TEXCOORD_0" in attributes:
            uv = self.accessor(attributes["TEXCOORD_0"], f"{where}/attributes/TEXCOORD_0")
        material = self.material(primitive.get("material"), f"{where}/material")
        if material["textured"] and uv is None:
            raise self.fail(f"{where}/attributes", "a textured material on a primitive without TEXCOORD_0")
        shape_name = self.unique_shape_name(name)
        rel = f"{MESH_DIR}/{len(self.shapes)}-{safe_name(shape_name)}.ply"
        self.files[rel] = ply_bytes(vertices, triangles, uv, normals)
        shape = {"name": shape_name, "type": "mesh", "file": rel, "material": material["name"]}
        if material["emission"] is not None and normals is not None:
            self.notes.append(f"{where}/attributes/NORMAL: an emitting shape shades flat (the format's lights are "
                              "flat: Mitsuba turns and samples an area light by its vertex normals)")
        if normals is None or material["emission"] is not None:
            shape["face_normals"] = True
        if material["emission"] is not None:
            shape["emission"] = material["emission"]
        self.shapes.append(shape)

    def unique_shape_name(self, name: str) -> str:
        taken = {s["name"] for s in self.shapes}
        out, n = name, 1
        while out in taken:
            n += 1
            out = f"{name}-{n}"
        return out

    # -- textures --

    def image(self, index: int, where: str) -> tuple[str, bytes]:
        """Image ``index``'s file suffix and bytes (its URI's or its buffer view's; PNG or JPEG)."""
        if index not in self.images:
            entry = self.item("images", index, where)
            here = f"/images/{index}"
            self.check_extensions(entry, here)
            if "uri" in entry:
                data = self.uri_bytes(entry["uri"], f"{here}/uri")
            elif "bufferView" in entry:
                data = self.view_bytes(entry["bufferView"], f"{here}/bufferView")[0]
            else:
                raise self.fail(here, "an image without uri or bufferView")
            if data[:8] == b"\x89PNG\r\n\x1a\n":
                suffix = "png"
            elif data[:3] == b"\xff\xd8\xff":
                suffix = "jpg"
            else:
                raise self.fail(here, "expected a PNG or JPEG image (the formats glTF 2.0 defines)")
            self.images[index] = (suffix, data)
        return self.images[index]

    def texture(self, info: dict, where: str, *, raw: bool, factor=None, channel: int | None = None,
                threshold: float | None = None) -> str | None:
        """A ``textureInfo`` as a ``[textures.NAME]`` bitmap, its name (None where refused leniently).

        The image's file as it is where it is read as it is (``raw`` false: sRGB codes, glTF's base colour and
        emissive textures; ``raw`` true: code / 255, glTF's data textures); otherwise a file made from its codes
        (exact, since the scene format decodes each texel before filtering, as Mitsuba): one ``channel`` as a grey
        8-bit PNG (glTF's roughness is G, metallic B, alpha A), a ``factor`` other than 1 multiplied in as a float
        EXR (glTF multiplies factor and texture, glTF 2.0 3.9.2), a ``threshold`` (alphaMode MASK) as 0 / 255.
        The sampler's filter and wrap, ``KHR_texture_transform`` as ``to_uv`` (:func:`uv_matrix`)."""
        extensions = self.check_extensions(info, where)
        if int(info.get("texCoord", 0)) != 0:
            self.refuse(f"{where}/texCoord", "only TEXCOORD_0 is read (the scene format has one set of texture "
                                             "coordinates)")
            return None
        texture_index = info.get("index")
        texture = self.item("textures", texture_index, f"{where}/index")
        here = f"/textures/{texture_index}"
        self.check_extensions(texture, here)
        if "source" not in texture:
            raise self.fail(here, "a texture without source")
        entry: dict = {}
        sampler_index = texture.get("sampler")
        if sampler_index is not None:
            entry.update(self.sampler(sampler_index))
        transform = extensions.get("KHR_texture_transform")
        if transform:
            if int(transform.get("texCoord", 0)) != 0:
                self.refuse(f"{where}/extensions/KHR_texture_transform/texCoord", "only TEXCOORD_0 is read")
                return None
            matrix = uv_matrix(transform)
            if not np.array_equal(matrix, np.eye(3)):
                entry["to_uv"] = [[float(x) + 0.0 for x in row] for row in matrix]
        key = (texture_index, raw, None if factor is None else tuple(np.atleast_1d(factor)), channel, threshold,
               json.dumps(entry, sort_keys=True))
        if key in self.texture_names:
            return self.texture_names[key]
        suffix, data = self.image(texture["source"], f"{here}/source")
        image_name = safe_name((self.doc.get("images") or [])[texture["source"]].get("name") or
                               texture.get("name") or f"image{texture['source']}")
        name = safe_name(f"{image_name}-{len(self.textures)}")
        plain = channel is None and threshold is None and (factor is None or np.all(np.asarray(factor) == 1.0))
        if plain:
            rel = f"{TEXTURE_DIR}/{name}.{suffix}"
            self.files[rel] = data
            entry["raw"] = raw
        else:
            rel, entry["raw"] = self.derived_image(data, name, raw, factor, channel, threshold)
        self.textures[name] = {"filename": rel, **entry}
        self.texture_names[key] = name
        return name

    def derived_image(self, data: bytes, name: str, raw: bool, factor, channel, threshold) -> tuple[str, bool]:
        """An image made from another's codes (:meth:`texture`): its file and whether it is raw."""
        from PIL import Image  # optional: Pillow decodes images only where a factor or a channel needs their codes

        with Image.open(io.BytesIO(data)) as opened:
            codes = np.asarray(opened.convert("RGBA"), np.uint8)
        if threshold is not None:  # alphaMode MASK: 1 where the alpha reaches the cutoff, else 0
            alpha = codes[..., 3] / 255.0 * (1.0 if factor is None else float(np.asarray(factor).ravel()[0]))
            grey = np.where(alpha >= threshold, 255, 0).astype(np.uint8)
            rel = f"{TEXTURE_DIR}/{name}.png"
            self.files[rel] = encode_png(np.repeat(grey[..., None], 3, axis=2))
            return rel, True
        if channel is not None:
            codes = np.repeat(codes[..., channel:channel + 1], 3, axis=2)
        else:
            codes = codes[..., :3]
        if factor is None or np.all(np.asarray(factor) == 1.0):
            rel = f"{TEXTURE_DIR}/{name}.png"
            self.files[rel] = encode_png(np.ascontiguousarray(codes))
            return rel, raw
        factor = np.broadcast_to(np.asarray(factor, np.float64), (3,))
        linear = (codes / 255.0 if raw else srgb_to_linear(codes)) * factor
        rel = f"{TEXTURE_DIR}/{name}.exr"
        self.files[rel] = exr_bytes(linear.astype(np.float32))
        return rel, False

    def sampler(self, index: int) -> dict:
        """A sampler as ``filter_type`` / ``wrap_mode`` (:data:`FILTERS`, :data:`WRAPS`): magFilter gives the
        filter (minFilter must agree or be absent: the format has no mipmaps); wrapS must equal wrapT (the format
        has one wrap mode)."""
        where = f"/samplers/{index}"
        sampler = self.item("samplers", index, where)
        self.check_extensions(sampler, where)
        out = {}
        mag, mini = sampler.get("magFilter"), sampler.get("minFilter")
        if mag is not None:
            if mag not in FILTERS:
                raise self.fail(f"{where}/magFilter", f"expected 9728 or 9729, got {mag!r}")
            out["filter_type"] = FILTERS[mag]
        if mini is not None and mini != mag:
            self.refuse(f"{where}/minFilter", f"expected the magFilter's value {mag} (the scene format's one "
                                              f"filter, no mipmaps), got {mini}")
        wrap_s, wrap_t = sampler.get("wrapS", 10497), sampler.get("wrapT", 10497)
        if wrap_s != wrap_t:
            self.refuse(f"{where}/wrapT", f"expected wrapT = wrapS = {wrap_s} (the scene format has one wrap mode "
                                          f"for both axes), got {wrap_t}")
        if wrap_s not in WRAPS:
            raise self.fail(f"{where}/wrapS", f"expected 10497, 33648 or 33071, got {wrap_s!r}")
        out["wrap_mode"] = WRAPS[wrap_s]
        return out

    # -- materials --

    def material(self, index: int | None, where: str) -> dict:
        """The scene material of glTF material ``index`` (None: glTF's default material, 3.9.6): its ``name``, the
        ``emission`` the shape carries (:meth:`emission`) and whether it is ``textured`` (its shapes need
        TEXCOORD_0)."""
        if index in self.material_names:
            return self.material_names[index]
        textures_before = len(self.texture_names)
        entry = {} if index is None else self.item("materials", index, where)
        here = "/materials/default" if index is None else f"/materials/{index}"
        extensions = self.check_extensions(entry, here)
        base_name = self.unique_material_name(safe_name(entry.get("name") or
                                                        ("default" if index is None else f"material{index}")))
        emission = self.emission(entry, extensions, here)
        inner = self.surface(entry, extensions, here, base_name)
        name = inner
        normal = entry.get("normalTexture")
        if normal is not None:
            name = self.normal_map(normal, name, f"{here}/normalTexture", base_name)
        if entry.get("doubleSided") and self.materials[inner]["type"] == "principled":
            self.notes.append(f"{here}/doubleSided: the format's principled is one-sided (Mitsuba's: black from "
                              "behind); written one-sided")
        if entry.get("occlusionTexture") is not None:
            self.refuse(f"{here}/occlusionTexture", "ambient occlusion is a rasteriser's stand-in for indirect light, "
                                                    "which a path tracer computes")
        name = self.alpha(entry, name, here, base_name, emission is not None)
        self.material_names[index] = {"name": name, "emission": emission,
                                      "textured": len(self.texture_names) > textures_before}
        return self.material_names[index]

    def unique_material_name(self, name: str) -> str:
        out, n = name, 1
        while out in self.materials:
            n += 1
            out = f"{name}-{n}"
        self.materials[out] = {}
        return out

    def surface(self, entry: dict, extensions: dict, here: str, name: str) -> str:
        """``pbrMetallicRoughness`` (+ transmission, ior, volume) as the scene's material ``name``.

        A full transmission (``KHR_materials_transmission`` factor 1, no texture, metallic 0) is a dielectric of
        ``int_ior`` = ior (glTF's outside is vacuum: ``ext_ior`` 1) and ``specular_transmittance`` = the base
        colour (glTF tints transmitted light by it): with ``KHR_materials_volume`` a solid (``dielectric``, or
        ``roughdielectric`` GGX of alpha = roughness^2), without it a thin wall (``thindielectric``, smooth only).
        Anything else is Mitsuba's ``principled``: ``base_color`` = base colour, ``metallic``, ``roughness`` as they
        are (both glTF's and Mitsuba's principled have GGX alpha = roughness^2, glTF 2.0 Appendix B and
        principled.cpp: the identity), ``eta`` = ior (glTF's dielectric F0 = ((ior - 1) / (ior + 1))^2, principled's
        eta the same interface), ``spec_trans`` = the transmission factor."""
        pbr = entry.get("pbrMetallicRoughness") or {}
        where = f"{here}/pbrMetallicRoughness"
        self.check_extensions(pbr, where)
        colour = [float(x) for x in pbr.get("baseColorFactor", [1, 1, 1, 1])]
        metallic = float(pbr.get("metallicFactor", 1.0))
        roughness = float(pbr.get("roughnessFactor", 1.0))
        transmission = extensions.get("KHR_materials_transmission")
        volume = extensions.get("KHR_materials_volume")
        ior = float((extensions.get("KHR_materials_ior") or {}).get("ior", 1.5))
        if ior < 1.0:
            self.refuse(f"{here}/extensions/KHR_materials_ior/ior", f"expected an index >= 1, got {ior}")
            ior = 1.5
        if volume is not None:
            for key in ("attenuationDistance", "attenuationColor", "thicknessTexture"):
                if key in volume:
                    self.refuse(f"{here}/extensions/KHR_materials_volume/{key}", "a participating medium (absorption) "
                                                                                 "is not part of the scene format")
        base_texture = pbr.get("baseColorTexture")
        out: dict
        factor = float((transmission or {}).get("transmissionFactor", 0.0))
        if (transmission is not None and factor == 1.0 and "transmissionTexture" not in transmission
                and metallic == 0.0 and "metallicRoughnessTexture" not in pbr
                and (volume is not None or roughness == 0)):
            colour3 = colour[:3]
            out = {"int_ior": ior, "ext_ior": 1.0}
            if volume is None:
                out = {"type": "thindielectric", **out}
            elif roughness == 0.0:
                out = {"type": "dielectric", **out}
            else:
                out = {"type": "roughdielectric", **out, "distribution": "ggx", "alpha": max(1e-4, roughness ** 2)}
                if roughness ** 2 < 1e-4:
                    self.notes.append(f"{where}/roughnessFactor: alpha = roughness^2 below the format's 1e-4, "
                                      "written as 1e-4")
            if base_texture is not None:
                texture = self.texture(base_texture, f"{where}/baseColorTexture", raw=False, factor=colour3)
                if texture is not None:
                    out["specular_transmittance"] = {"texture": texture}
            elif colour3 != [1.0, 1.0, 1.0]:
                out["specular_transmittance"] = colour3
            self.materials[name] = out
            return name
        out = {"type": "principled"}
        if base_texture is not None:
            texture = self.texture(base_texture, f"{where}/baseColorTexture", raw=False, factor=colour[:3])
            out["base_color"] = {"texture": texture} if texture is not None else colour[:3]
        else:
            out["base_color"] = colour[:3]
        mr = pbr.get("metallicRoughnessTexture")
        out["metallic"], out["roughness"] = metallic, roughness
        if mr is not None:  # glTF 2.0, 3.9.2: roughness in G, metalness in B (linear)
            for key, channel, value in (("roughness", 1, roughness), ("metallic", 2, metallic)):
                texture = self.texture(mr, f"{where}/metallicRoughnessTexture", raw=True, factor=value,
                                       channel=channel)
                if texture is not None:
                    out[key] = {"texture": texture}
        if ior != 1.5:
            out["eta"] = ior
        clearcoat = extensions.get("KHR_materials_clearcoat")
        if clearcoat is not None:
            out.update(self.clearcoat(clearcoat, f"{here}/extensions/KHR_materials_clearcoat"))
        if transmission is not None and factor > 0:
            if "transmissionTexture" in transmission:
                self.refuse(f"{here}/extensions/KHR_materials_transmission/transmissionTexture",
                            "a transmission texture on a partly transmitting material (read as its factor)")
            out["spec_trans"] = factor
        self.materials[name] = out
        return name

    def clearcoat(self, coat: dict, where: str) -> dict:
        """``KHR_materials_clearcoat`` as principled's ``clearcoat`` and ``clearcoat_gloss``: clearcoat = the factor;
        the coat's GGX alpha = roughness^2 (the extension's) read as principled's GTR1 alpha = 0.1 (1 - gloss) +
        0.001 gloss (principled.cpp), so gloss = (0.1 - roughness^2) / 0.099, the inverse of the harness's export;
        a roughness outside [sqrt(0.001), sqrt(0.1)] (no gloss in [0, 1] gives it), a coat texture or normal
        texture is refused. The lobes differ (GTR1 against GGX; Schlick from 0.04 both): an approximation."""
        for key in ("clearcoatTexture", "clearcoatRoughnessTexture", "clearcoatNormalTexture"):
            if key in coat:
                self.refuse(f"{where}/{key}", "a clear coat texture (the factors are read)")
        factor = float(coat.get("clearcoatFactor", 0.0))
        if factor == 0.0:
            return {}
        alpha = float(coat.get("clearcoatRoughnessFactor", 0.0)) ** 2
        gloss = (0.1 - alpha) / 0.099
        if not -1e-12 <= gloss <= 1.0 + 1e-12:
            self.refuse(f"{where}/clearcoatRoughnessFactor", f"a coat roughness outside [{math.sqrt(0.001):.4g}, "
                                                             f"{math.sqrt(0.1):.4g}] (principled's clear coat "
                                                             "alpha runs from 0.001 to 0.1)")
            gloss = min(max(gloss, 0.0), 1.0)
        self.notes.append(f"{where}: GGX coat of alpha {alpha:.6g} as principled's GTR1 clear coat of gloss "
                          f"{gloss:.6g}")
        return {"clearcoat": factor, "clearcoat_gloss": min(max(gloss, 0.0), 1.0)}

    def emission(self, entry: dict, extensions: dict, here: str):
        """``emissiveFactor`` x ``KHR_materials_emissive_strength`` (default 1) as the shape's radiance Le (the
        harness's export writes the radiance so: factor = Le / its largest channel, strength = that channel); an
        ``emissiveTexture`` (sRGB) times both as a textured emission; None where it is black."""
        strength = float((extensions.get("KHR_materials_emissive_strength") or {}).get("emissiveStrength", 1.0))
        factor = np.asarray(entry.get("emissiveFactor", [0, 0, 0]), np.float64) * strength
        texture = entry.get("emissiveTexture")
        if not np.any(factor > 0):
            return None
        if texture is not None:
            name = self.texture(texture, f"{here}/emissiveTexture", raw=False, factor=factor)
            if name is not None:
                return {"texture": name}
        return [float(x) for x in factor]

    def normal_map(self, info: dict, bsdf: str, where: str, base: str) -> str:
        """``normalTexture`` as a ``normalmap`` around ``bsdf``: the map raw (n = 2 rgb - 1, glTF's and Mitsuba's),
        tangent frame Mitsuba's from the texture coordinates (the harness's export writes TANGENT so; another
        file's TANGENT is replaced by it). ``scale`` (glTF: n = normalize((2 rgb - 1) * (scale, scale, 1)), linear in
        the codes) other than 1 is refused: the format's normalmap has no scale."""
        scale = float(info.get("scale", 1.0))
        if scale != 1.0:
            self.refuse(f"{where}/scale", f"a normal map scale other than 1 (got {scale}): the format's normalmap "
                                          "has none (dropped: the map read at scale 1)")
        texture = self.texture(info, where, raw=True)
        if texture is None:
            return bsdf
        name = self.unique_material_name(f"{base}-normalmap")
        self.materials[name] = {"type": "normalmap", "normalmap": {"texture": texture}, "bsdf": bsdf}
        return name

    def alpha(self, entry: dict, bsdf: str, here: str, base: str, emits: bool) -> str:
        """``alphaMode`` as a ``mask`` around ``bsdf``: OPAQUE none (alpha ignored, as glTF); BLEND opacity = alpha
        (Mitsuba's mask lets light through with probability 1 - opacity: glTF's blending in expectation); MASK
        opacity = 1 where alpha >= alphaCutoff (default 0.5), else 0: exact for a constant alpha; a texture's alpha
        is cut per texel (a 0 / 255 raw map read with the texture's sampler, so a bilinear lookup blends the cut
        between texels where glTF cuts the filtered alpha: docs/import.md)."""
        mode = entry.get("alphaMode", "OPAQUE")
        if mode == "OPAQUE":
            return bsdf
        pbr = entry.get("pbrMetallicRoughness") or {}
        alpha = float(pbr.get("baseColorFactor", [1, 1, 1, 1])[3])
        texture = pbr.get("baseColorTexture")
        where = f"{here}/alphaMode"
        if mode not in ("MASK", "BLEND"):
            raise self.fail(where, f"expected OPAQUE, MASK or BLEND, got {mode!r}")
        if emits:
            self.refuse(where, "a cut-out light: the format's mask may not hold an emitter")
            return bsdf
        cutoff = float(entry.get("alphaCutoff", 0.5)) if mode == "MASK" else None
        if texture is not None:
            name = self.texture(texture, f"{here}/pbrMetallicRoughness/baseColorTexture", raw=True, factor=alpha,
                                channel=3 if cutoff is None else None, threshold=cutoff)
            opacity = {"texture": name} if name is not None else alpha
            if name is not None and cutoff is not None and self.textures[name].get("filter_type") != "nearest":
                self.notes.append(f"{where}: MASK of a texture's alpha cut per texel (cutoff {cutoff:g}) and read "
                                  "bilinearly: glTF cuts the filtered alpha, a sharp edge; the mask's edge is a "
                                  "texel wide and partly transparent")
        else:
            opacity = alpha if cutoff is None else (1.0 if alpha >= cutoff else 0.0)
        if texture is None and opacity == 1.0:
            return bsdf
        name = self.unique_material_name(f"{base}-mask")
        self.materials[name] = {"type": "mask", "opacity": opacity, "bsdf": bsdf}
        return name

    # -- camera and lights --

    def place_camera(self, index: int, world: np.ndarray, where: str) -> None:
        """The first camera met: origin = the node's world position, looking down its -z with +y up (Mitsuba's
        look-at frame is glTF's with x and z negated, :data:`CAMERA_FLIP`); perspective ``yfov`` as ``fov`` with
        ``fov_axis = "y"``; orthographic ``xmag`` / ``ymag`` as ``scale`` = [xmag, ymag W / H, 1] (the film spans
        x in [-s_x, s_x], y in [-s_y H / W, s_y H / W]); a thin lens where the camera's ``extras`` hold the harness
        export's ``aperture_radius`` and ``focus_distance``. The film: ``asset.extras.film`` where the harness wrote
        it, else :data:`DEFAULT_WIDTH` wide and high by the aspect ratio."""
        camera = self.item("cameras", index, where)
        if self.camera is not None:
            self.refuse(where, "a second camera (the scene format has one; the first met is kept)")
            return
        here = f"/cameras/{index}"
        self.check_extensions(camera, here)
        frame = world @ CAMERA_FLIP
        origin = frame[:3, 3]
        forward = frame[:3, 2] / np.linalg.norm(frame[:3, 2])
        up = frame[:3, 1] / np.linalg.norm(frame[:3, 1])
        extras = (self.doc.get("asset") or {}).get("extras") or {}
        film = dict(extras.get("film") or {})
        kind = camera.get("type")
        aspect = None
        if kind == "perspective":
            aspect = (camera.get("perspective") or {}).get("aspectRatio")
        elif kind == "orthographic":
            o = camera.get("orthographic") or {}
            aspect = float(o["xmag"]) / float(o["ymag"])
        else:
            raise self.fail(f"{here}/type", f"expected perspective or orthographic, got {kind!r}")
        width = int(film.get("width", DEFAULT_WIDTH))
        if "height" in film:
            height = int(film["height"])
        elif aspect:
            height = max(1, round(width / float(aspect)))
            self.notes.append(f"{here}: the film {width} x {height} (glTF has no film; its aspect ratio {aspect})")
        else:
            height = width
            self.notes.append(f"{here}: the film {width} x {height} (glTF has no film, and no aspect ratio here)")
        out = {"origin": [float(x) for x in origin], "target": [float(x) for x in origin + forward],
               "up": [float(x) for x in up]}
        if kind == "perspective":
            p = camera["perspective"]
            lens = camera.get("extras") or {}
            if "aperture_radius" in lens:
                out = {"type": "thinlens", **out, "aperture_radius": float(lens["aperture_radius"]),
                       "focus_distance": float(lens.get("focus_distance", 10000.0))}
            out.update(fov=math.degrees(float(p["yfov"])), fov_axis="y")
            if aspect and abs(float(aspect) - width / height) > 1e-6 * float(aspect):
                self.notes.append(f"{here}/perspective/aspectRatio: {aspect} differs from the film's "
                                  f"{width} / {height}; the film's is used with yfov")
        else:
            o = camera["orthographic"]
            out = {"type": "orthographic", **out,
                   "scale": [float(o["xmag"]), float(o["ymag"]) * width / height, 1.0]}
        self.camera = out
        self.film = {"width": width, "height": height}
        if isinstance(film.get("filter"), dict) and film["filter"].get("type") in ("box", "tent", "gaussian"):
            self.film["filter"] = film["filter"]["type"]

    def light(self, index, world: np.ndarray, node_name: str | None, where: str) -> None:
        """A ``KHR_lights_punctual`` light as an emitter: radiometric = color x intensity / :data:`LUMENS_PER_WATT`
        (candela to W/sr for point and spot, lux to W/m^2 for directional: the export's conversion inverted); the
        position is the node's world origin, the direction its world -z (the extension's convention); a spot's
        ``outerConeAngle`` is ``cutoff_angle`` and ``innerConeAngle`` ``beam_width`` (degrees; glTF's falloff
        between them is smooth, Mitsuba's linear in the angle). A finite ``range`` is refused: Mitsuba's lights reach
        everywhere."""
        lights = ((self.doc.get("extensions") or {}).get("KHR_lights_punctual") or {}).get("lights") or []
        if not isinstance(index, int) or not 0 <= index < len(lights):
            raise self.fail(f"{where}/light", f"expected an index into the file's KHR_lights_punctual lights, "
                                              f"got {index!r}")
        light = lights[index]
        here = f"/extensions/KHR_lights_punctual/lights/{index}"
        if "range" in light:
            self.refuse(f"{here}/range", "a light of finite range (the format's lights reach everywhere)")
        rgb = np.asarray(light.get("color", [1, 1, 1]), np.float64) * float(light.get("intensity", 1.0)) \
            / LUMENS_PER_WATT
        if not np.any(rgb > 0):
            self.notes.append(f"{here}: a black light, left out")
            return
        position = [float(x) for x in world[:3, 3]]
        axis = -world[:3, 2] / np.linalg.norm(world[:3, 2])
        name = light.get("name") or node_name or f"light{index}"
        taken = {e["name"] for e in self.emitters}
        out_name, n = name, 1
        while out_name in taken:
            n += 1
            out_name = f"{name}-{n}"
        kind = light.get("type")
        entry: dict = {"name": out_name, "type": kind}
        if kind == "point":
            entry.update(position=position, intensity=[float(x) for x in rgb])
        elif kind == "spot":
            spot = light.get("spot") or {}
            outer = float(spot.get("outerConeAngle", math.pi / 4))
            inner = float(spot.get("innerConeAngle", 0.0))
            entry.update(position=position, target=[float(p + a) for p, a in zip(position, axis)],
                         intensity=[float(x) for x in rgb], cutoff_angle=math.degrees(outer))
            if inner > 0:
                entry["beam_width"] = math.degrees(inner)
            else:
                self.refuse(f"{here}/spot/innerConeAngle", "a beam width of 0 (the format's spot needs one > 0)")
                return
        elif kind == "directional":
            entry.update(direction=[float(x) for x in axis], irradiance=[float(x) for x in rgb])
        else:
            raise self.fail(f"{here}/type", f"expected point, spot or directional, got {kind!r}")
        self.emitters.append(entry)

    # -- the text --

    def text(self) -> str:
        """The scene file's TOML text."""
        extras = (self.doc.get("asset") or {}).get("extras") or {}
        stem = self.path.stem
        lines = [f"{stem}: imported from {self.path.name} (glTF 2.0) by harness import"]
        lines += [f"approximated: {n}" for n in self.notes]
        lines += [f"dropped: {d}" for d in self.dropped]
        out = [f"name = {toml_value(stem)}", f"description = {toml_value('; '.join(lines))}"]
        out += toml_table("camera", self.camera)
        out += toml_table("film", {"width": self.film["width"], "height": self.film["height"],
                                   "filter": self.film.get("filter", "box")})
        if isinstance(extras.get("max_depth"), int) and not isinstance(extras.get("max_depth"), bool):
            out += toml_table("integrator", {"max_depth": extras["max_depth"]})
        for name, entry in self.textures.items():
            out += toml_table(f"textures.{toml_key(name)}", entry)
        for name, entry in self.materials.items():
            out += toml_table(f"materials.{toml_key(name)}", entry)
        for shape in self.shapes:
            out += toml_table("[[shapes]]", shape)
        for emitter in self.emitters:
            out += toml_table("[[emitters]]", emitter)
        return "\n".join(out) + "\n"
