"""Export a scene in formats other renderers load: Mitsuba 3 XML (with PLY meshes), scene.json, PLY, OBJ and glTF.

* ``mitsuba-xml``: ``scene.xml``, the scene's Mitsuba plugins that the adapter renders
  (:func:`harness.renderers.mitsuba_spec.scene_spec`: shapes and placements, BSDFs, emitters, camera with its clip
  planes, film and pixel filter, ``path`` integrator) written as XML (:mod:`harness.renderers.mitsuba_xml`), so
  Mitsuba renders the same image from it. Shapes that the adapter passes as triangles become
  ``meshes/<index>-<name>.ply`` (world space, wound to face their front side, loaded with ``face_normals``), an
  envmap's pixels ``textures/<index>-<name>.exr`` (float32 RGB), each named by ``filename``. The sampler's
  ``sample_count`` and ``seed`` are the XML parameters ``$spp`` and ``$seed``, so ``mi.load_file(path, spp=64,
  seed=3)`` (or ``mitsuba -D spp=64``) overrides them.
* ``json``: ``scene.json``, the resolved scene for renderers without a TOML parser
  (:func:`harness.renderers.scene_json.scene_json`, docs/scene-json.md), with ``meshes/<index>-<name>.ply`` for
  every shape and ``textures/<index>-<name>.exr`` for every environment map.
* ``ply``: one ``<index>-<name>.ply`` per shape (world-space triangles as the reference core sees them: spheres
  are icospheres). No emitters.
* ``obj``: ``scene.obj`` and ``scene.mtl`` (:func:`obj_text`), one object per shape, ``Kd`` = reflectance and
  ``Ke`` = an emitting shape's radiance as full-precision numbers, no other term. No other emitters.
* ``gltf``: ``scene.gltf`` with its buffer ``scene.bin`` (:func:`gltf_document`): one node per shape, a PBR
  material per material and emission with exact float factors (base colour = reflectance; emissive factor =
  emission / its largest channel and ``KHR_materials_emissive_strength`` = that channel), the camera
  (:func:`gltf_camera`), point, spot and directional emitters as ``KHR_lights_punctual`` lights
  (:func:`gltf_light`), film, filter, ``max_depth`` and ``rr_depth`` in ``asset.extras``; constant and envmap
  emitters cannot be expressed in glTF 2.0 and are left out.

:func:`export_losses` says, one line each, what a format leaves out of a scene (``harness export`` prints them as
warnings).

PLY meshes are written with trimesh, glTF and OBJ by this module; every file is written atomically
(:mod:`harness.files.imageio`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError
from harness.core.jsonsafe import plain
from harness.files.imageio import StagedFolder, atomic_write_bytes, atomic_write_text, make_folders
from harness.renderers.meshfiles import ply_bytes, safe_name
from harness.renderers.mitsuba_spec import RR_DEPTH, Parameter, bsdf_dict, clip_planes, scene_spec
from harness.renderers.mitsuba_xml import spec_xml
from harness.renderers.scene_json import FILTERS, scene_json
from harness.scene import Scene
from harness.scene.kinds.cameras import camera_to_world
from harness.scene.kinds.emitters import EMITTERS
from harness.scene.kinds.materials import GLTF_LOSSES, MATERIALS
from harness.scene.triangulate import shape_triangles

FORMATS = ("mitsuba-xml", "json", "ply", "obj", "gltf")
GLTF_LIGHTS = "KHR_lights_punctual"
GLTF_EMISSIVE_STRENGTH = "KHR_materials_emissive_strength"


def mitsuba_xml(scene: Scene, *, spp: int = 16, seed: int = 0) -> tuple[str, dict[str, bytes]]:
    """The scene as Mitsuba 3 XML text, and the PLY and EXR files it refers to (``{relative path: bytes}``).

    The scene's Mitsuba plugins (:func:`harness.renderers.mitsuba_spec.scene_spec`, what the adapter renders)
    written by :func:`harness.renderers.mitsuba_xml.spec_xml`; ``spp`` and ``seed`` are the defaults of the XML
    parameters ``$spp`` and ``$seed``.
    """
    spec = scene_spec(scene, spp=Parameter("spp", int(spp)), seed=Parameter("seed", int(seed)))
    return spec_xml(spec, f"{scene.name}: exported by rendering-harness (harness export) from {scene.path}")


def gltf_material(material) -> tuple[dict, dict]:
    """The glTF 2.0 metallic-roughness factors of a material (the keys of ``pbrMetallicRoughness``) and its
    glTF extensions (docs/external-renderers.md, "glTF materials"): its type's
    (:meth:`harness.scene.kinds.materials.MaterialKind.to_gltf`)."""
    return MATERIALS[material.type].to_gltf(material)


def gltf_light(emitter) -> tuple[dict, dict]:
    """A point, spot or directional emitter as a ``KHR_lights_punctual`` light and the node that places it (its
    type's, :meth:`harness.scene.kinds.emitters.EmitterKind.to_gltf`)."""
    light, placement = EMITTERS[emitter.type].to_gltf(emitter)
    return light, {"name": safe_name(emitter.name), **placement}


def _in_gltf(emitter) -> bool:
    """Whether glTF 2.0 has a light for the emitter's type (``KHR_lights_punctual``: point, spot, directional)."""
    return EMITTERS[emitter.type].gltf is not None


def _unique(name: str, taken: set[str]) -> str:
    """``name``, or ``name-2``, ``name-3``, ... if it is taken; the result is added to ``taken``."""
    out, n = name, 1
    while out in taken:
        n += 1
        out = f"{name}-{n}"
    taken.add(out)
    return out


def gltf_camera(scene: Scene) -> tuple[dict, dict]:
    """The scene's camera as a glTF perspective camera and the node that places it.

    ``yfov`` = the resolved vertical field of view (radians; Mitsuba's ``fov`` / ``fov_axis`` for this film),
    ``aspectRatio`` = width / height, ``znear`` / ``zfar`` = the clip planes. The node's ``matrix`` (column-major)
    is Mitsuba's camera-to-world matrix with its x and z columns negated: a glTF camera looks down its -z with +x
    to the image's right, Mitsuba's looks down +z with +x to the image's left, so both see the same image.
    """
    camera, film = scene.camera, scene.film
    _tan_x, tan_y = camera.tan_half_fov(film.width, film.height)
    near, far = clip_planes(scene)
    to_world = camera_to_world(camera) @ np.diag([-1.0, 1.0, -1.0, 1.0])  # negate the x and z columns
    gltf = {"name": "camera", "type": "perspective",
            "perspective": {"yfov": 2.0 * math.atan(tan_y), "aspectRatio": film.width / film.height,
                            "znear": float(near), "zfar": float(far)}}
    return gltf, {"name": "camera", "camera": 0, "matrix": [float(x) + 0.0 for x in to_world.T.ravel()]}


def gltf_render_settings(scene: Scene) -> dict:
    """What glTF has no place for, kept under ``asset.extras``: the film (size and pixel filter, as in scene.json),
    ``max_depth`` (Mitsuba's meaning, docs/scene-json.md) and ``rr_depth``."""
    return {"film": {"width": int(scene.film.width), "height": int(scene.film.height),
                     "filter": dict(FILTERS[scene.film.filter])},
            "max_depth": int(scene.max_depth), "rr_depth": RR_DEPTH}


def _gltf_shape_material(shape, material) -> dict:
    """The glTF material of one shape: :func:`gltf_material`'s factors as full float64 numbers, and for an emitting
    shape ``emissiveFactor`` = emission / its largest channel with ``KHR_materials_emissive_strength`` = that
    channel (factor x strength = the radiance)."""
    factors, extensions = gltf_material(material)
    entry: dict = {"name": safe_name(shape.material), "pbrMetallicRoughness": plain(factors),
                   "doubleSided": MATERIALS[material.type].gltf_double_sided(material)}
    extensions = dict(extensions)
    if shape.is_emitter:
        emission = np.asarray(shape.emission, dtype=np.float64)
        peak = float(emission.max())
        if peak > 0:
            entry["emissiveFactor"] = [float(x) for x in emission / peak]
            extensions[GLTF_EMISSIVE_STRENGTH] = {"emissiveStrength": peak}
    if extensions:
        entry["extensions"] = extensions
    return entry


def gltf_document(scene: Scene, buffer_name: str = "scene.bin") -> tuple[dict, bytes]:
    """The scene as a glTF 2.0 document (a JSON-ready dict) and its binary buffer (``buffer_name``).

    One node and mesh per shape (world-space triangles as the core triangulates them: float32 positions, uint32
    indices, wound so that the front side is counter-clockwise), one material per scene material and emission
    (:func:`_gltf_shape_material`), the camera (:func:`gltf_camera`), the punctual emitters as
    ``KHR_lights_punctual`` lights (:func:`gltf_light`) and the render settings in ``asset.extras``
    (:func:`gltf_render_settings`). Each mesh node's ``extras`` holds its material's name and reflectance, the
    Mitsuba plugin dict of a non-diffuse material (``bsdf``) and an emitting shape's ``emission``.
    """
    chunks: list[bytes] = []
    views: list[dict] = []
    accessors: list[dict] = []

    def accessor(data: np.ndarray, target: int, component: int, kind: str, **bounds) -> int:
        raw = data.tobytes()
        views.append({"buffer": 0, "byteOffset": sum(map(len, chunks)), "byteLength": len(raw), "target": target})
        chunks.append(raw + b"\0" * (-len(raw) % 4))  # every view starts on a 4-byte boundary
        accessors.append({"bufferView": len(views) - 1, "componentType": component, "count": int(len(data)),
                          "type": kind, **bounds})
        return len(accessors) - 1

    materials: list[dict] = []
    material_index: dict[tuple, int] = {}
    nodes: list[dict] = []
    meshes: list[dict] = []
    used: list[str] = []
    taken: set[str] = set()
    for shape in scene.shapes:
        vertices, triangles = shape_triangles(shape)
        positions = np.asarray(vertices, dtype="<f4")
        position = accessor(positions, 34962, 5126, "VEC3",  # ARRAY_BUFFER, FLOAT
                            min=[float(x) for x in positions.min(axis=0)],
                            max=[float(x) for x in positions.max(axis=0)])
        indices = accessor(np.asarray(triangles, dtype="<u4").ravel(), 34963, 5125, "SCALAR")  # UNSIGNED_INT
        material = scene.materials[shape.material]
        key = (shape.material, tuple(shape.emission) if shape.is_emitter else None)
        if key not in material_index:
            material_index[key] = len(materials)
            materials.append(_gltf_shape_material(shape, material))
            used += [e for e in materials[-1].get("extensions", {}) if e not in used]
        name = _unique(safe_name(shape.name), taken)
        meshes.append({"name": name, "primitives": [
            {"attributes": {"POSITION": position}, "indices": indices, "mode": 4, "material": material_index[key]}]})
        extras: dict = {"material": shape.material, "reflectance": [float(x) for x in material.reflectance]}
        if not material.is_diffuse:
            extras["bsdf"] = plain(bsdf_dict(material))  # Mitsuba's plugin and parameters, for a reader wanting all
        if shape.is_emitter:
            extras["emission"] = [float(x) for x in shape.emission]
        nodes.append({"name": name, "mesh": len(meshes) - 1, "extras": extras})
    camera, camera_node = gltf_camera(scene)
    nodes.append(camera_node)
    lights = []
    for emitter in scene.emitters:
        if _in_gltf(emitter):
            light, node = gltf_light(emitter)
            node["extensions"] = {GLTF_LIGHTS: {"light": len(lights)}}
            lights.append(light)
            nodes.append(node)
    document: dict = {
        "asset": {"version": "2.0", "generator": "rendering-harness (harness export)",
                  "extras": gltf_render_settings(scene)},
        "scene": 0, "scenes": [{"name": scene.name, "nodes": list(range(len(nodes)))}],
        "nodes": nodes, "cameras": [camera],
    }
    if meshes:
        document.update(meshes=meshes, materials=materials, accessors=accessors, bufferViews=views,
                        buffers=[{"uri": buffer_name, "byteLength": sum(map(len, chunks))}])
    if lights:
        document["extensions"] = {GLTF_LIGHTS: {"lights": lights}}
        used.append(GLTF_LIGHTS)
    if used:
        document["extensionsUsed"] = used
    return document, b"".join(chunks)


def _mtl_number(value: float) -> str:
    return repr(float(value) + 0.0)


def obj_text(scene: Scene, mtl_name: str = "scene.mtl") -> tuple[str, str]:
    """The scene as OBJ text and its MTL text, holding only what the scene says.

    OBJ: one ``o`` object per shape (world-space triangles as the core triangulates them, counter-clockwise seen
    from the front side; vertices with the shortest repr that round-trips, so a reader gets the float64 values),
    ``usemtl`` naming its material. MTL: one ``newmtl`` per scene material (and per emitting shape) with ``Kd``
    (the diffuse reflectance; for other materials the glTF base colour, :func:`gltf_material`) and, for an
    emitting shape, ``Ke`` = its radiance (W m^-2 sr^-1, from the front side; a common extension, which Blender's
    OBJ importer reads as emission colour Ke / its largest channel and strength = that channel). No other term
    (no ``Ka``, ``Ks``, ``Ns``, ``illum``): a reader's defaults decide those (docs/external-renderers.md).
    """
    obj = [f"# {scene.name}: exported by rendering-harness (harness export)", f"mtllib {mtl_name}"]
    mtl = [f"# {scene.name}: materials exported by rendering-harness (harness export)"]
    names: dict[tuple, str] = {}
    taken_mtl: set[str] = set()
    taken_obj: set[str] = set()
    offset = 1
    for shape in scene.shapes:
        material = scene.materials[shape.material]
        key = (shape.material, tuple(shape.emission) if shape.is_emitter else None)
        if key not in names:
            base = safe_name(shape.material) + (f"-emit-{safe_name(shape.name)}" if shape.is_emitter else "")
            names[key] = _unique(base, taken_mtl)
            factors, _ = gltf_material(material)
            mtl += ["", f"newmtl {names[key]}", "Kd " + " ".join(map(_mtl_number, factors["baseColorFactor"][:3]))]
            if shape.is_emitter:
                mtl.append("Ke " + " ".join(map(_mtl_number, shape.emission)))
        vertices, triangles = shape_triangles(shape)
        obj += ["", f"o {_unique(safe_name(shape.name), taken_obj)}", f"usemtl {names[key]}"]
        obj += [f"v {_mtl_number(x)} {_mtl_number(y)} {_mtl_number(z)}" for x, y, z in np.asarray(vertices, np.float64)]
        obj += [f"f {a + offset} {b + offset} {c + offset}" for a, b, c in np.asarray(triangles, np.int64)]
        offset += len(vertices)
    return "\n".join(obj) + "\n", "\n".join(mtl) + "\n"


def export_losses(scene: Scene, fmt: str) -> list[str]:
    """What ``fmt`` cannot express of ``scene``, one line each (empty: nothing is lost beyond what
    docs/external-renderers.md lists for every scene)."""
    def names(emitters) -> str:
        return ", ".join(f"{e.name} ({e.type})" for e in emitters)

    losses = []
    if fmt in ("ply", "obj") and scene.emitters:
        losses.append(f"{fmt} has no lights: left out emitters {names(scene.emitters)}")
    glossy = [m for m in scene.materials.values() if not m.is_diffuse]
    if fmt == "obj" and glossy:
        losses.append("OBJ's MTL holds diffuse colours (Kd) and emission (Ke) only: materials " + ", ".join(
            f"{m.name} ({m.type})" for m in glossy) + " written with Kd = their glTF base colour")
    if fmt == "gltf":
        lost = [e for e in scene.emitters if not _in_gltf(e)]
        if lost:
            losses.append(f"glTF 2.0 has no environment light: left out {names(lost)} (KHR_lights_punctual has "
                          "point, spot and directional lights only)")
        losses += _gltf_material_losses(glossy)
    return losses


def _gltf_material_losses(glossy) -> list[str]:
    """What glTF's metallic-roughness model and its extensions cannot say exactly of the non-diffuse materials: one
    line per loss of :data:`harness.scene.kinds.materials.GLTF_LOSSES` that some of them have (their type's
    ``gltf_losses``)."""
    losses = []
    for loss, message in GLTF_LOSSES.items():
        materials = [m for m in glossy if loss in MATERIALS[m.type].gltf_losses(m)]
        if materials:
            losses.append(message.format(materials=", ".join(f"{m.name} ({m.type})" for m in materials)))
    return losses


def scene_files(scene: Scene, fmt: str, *, spp: int = 16, seed: int = 0) -> dict[str, bytes]:
    """The files of ``scene`` in format ``fmt`` (one of :data:`FORMATS`), ``{relative path: bytes}``, the main file
    first (``spp`` and ``seed``: the defaults of the Mitsuba XML's ``$spp`` and ``$seed``)."""
    if fmt not in FORMATS:
        raise HarnessError("--format", f"expected one of {', '.join(FORMATS)}, got {fmt!r}")
    if fmt in ("gltf", "obj") and scene.used_textures:
        raise HarnessError(str(scene.path), f"the {fmt} export does not carry textures yet (textures: "
                                            f"{', '.join(t.name for t in scene.used_textures)}): export it as "
                                            "mitsuba-xml or json")
    files: dict[str, bytes] = {}
    if fmt == "mitsuba-xml":
        text, meshes = mitsuba_xml(scene, spp=spp, seed=seed)
        files["scene.xml"] = text.encode("utf-8")
        files.update(meshes)
    elif fmt == "json":
        document, extra = scene_json(scene)
        files["scene.json"] = (json.dumps(document, indent=1, allow_nan=False) + "\n").encode("utf-8")
        files.update(extra)
    elif fmt == "ply":
        for shape in scene.shapes:
            files[f"{shape.index}-{safe_name(shape.name)}.ply"] = ply_bytes(*shape_triangles(shape))
    elif fmt == "obj":
        obj, mtl = obj_text(scene, mtl_name="scene.mtl")
        files["scene.obj"] = obj.encode("utf-8")
        files["scene.mtl"] = mtl.encode("utf-8")
    else:
        document, buffer = gltf_document(scene, buffer_name="scene.bin")
        files["scene.gltf"] = json.dumps(document, separators=(",", ":"), allow_nan=False).encode("utf-8")
        if buffer:
            files["scene.bin"] = buffer
    return files


def export_scene(scene: Scene, fmt: str, out_dir: str | Path, *, spp: int = 16, seed: int = 0) -> list[Path]:
    """Write ``scene`` in format ``fmt`` (one of :data:`FORMATS`, :func:`scene_files`) into the folder ``out_dir``
    (created if needed); returns the files written, the main file first. The files are written into a staging
    folder and moved into place together (:class:`harness.files.imageio.StagedFolder`): a failed write (a full
    disk) leaves ``out_dir`` as it was, and no folder made for it."""
    out_dir = Path(out_dir)
    files = scene_files(scene, fmt, spp=spp, seed=seed)
    with StagedFolder(out_dir, "--out") as stage:
        for rel, data in files.items():
            path = stage.root / rel
            make_folders(path.parent)
            if isinstance(data, str):
                atomic_write_text(path, data)
            else:
                atomic_write_bytes(path, data)
        stage.commit(last=tuple(rel.split("/")[0] for rel in list(files)[:1]))  # the main file last
    return [out_dir / rel for rel in files]
