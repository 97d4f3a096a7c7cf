"""Export a scene in formats other renderers load: Mitsuba 3 XML (with PLY meshes), PLY, OBJ and glTF.

* ``mitsuba-xml``: ``scene.xml`` describing exactly the scene :func:`harness.renderers.mitsuba.scene_to_mitsuba_dict`
  builds (same shapes and placements, BSDFs, area emitters, camera with its clip planes, film and pixel filter,
  ``path`` integrator with the scene's ``max_depth`` and ``rr_depth`` 5), so Mitsuba renders the same image from it.
  Rectangles, cubes and spheres stay Mitsuba's analytic shapes; ``mesh`` shapes become ``meshes/<shape>.ply`` (world
  space, wound to face their front side, loaded with ``face_normals``), and so do spheres in a scene with a material
  that is not diffuse (the reference's icosphere, as the adapter: ``tessellates_spheres``). The sampler's ``sample_count`` and ``seed``
  are the XML parameters ``$spp`` and ``$seed``, so ``mi.load_file(path, spp=64, seed=3)`` (or ``mitsuba -D
  spp=64``) overrides them.
  ``[[emitters]]`` become Mitsuba's emitters of the same names and parameters (:func:`~harness.renderers.mitsuba.
  light_spec`); an envmap's image is written as ``textures/<index>-<name>.exr`` (the pixels the scene holds, float32
  RGB) and named by ``filename``.
* ``ply``: one ``<index>-<name>.ply`` per shape (world-space triangles as the reference core sees them: spheres
  are icospheres). No emitters.
* ``obj``: ``scene.obj`` and its ``.mtl``, one object per shape, diffuse colour = reflectance. No emitters.
* ``gltf``: ``scene.gltf`` with its buffer, one node per shape, a PBR material per shape (base colour =
  reflectance, emissive = emission / its largest channel; the radiance itself is in the node's ``extras``); point,
  spot and directional emitters as ``KHR_lights_punctual`` lights (:func:`gltf_light`); constant and envmap
  emitters cannot be expressed in glTF 2.0 and are left out.

:func:`export_losses` says, one line each, what a format leaves out of a scene (``harness export`` prints them as
warnings).

Meshes are written with trimesh; every file is written atomically (:mod:`harness.files.imageio`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import trimesh
from trimesh.exchange.gltf import export_gltf
from trimesh.exchange.obj import export_obj
from trimesh.visual.material import PBRMaterial

from harness.core.errors import HarnessError
from harness.files.imageio import StagedFolder, atomic_write_bytes, atomic_write_text, exr_bytes, make_folders
from harness.renderers.meshfiles import MESH_DIR, TEXTURE_DIR, ply_bytes, safe_name
from harness.renderers.mitsuba import (
    RR_DEPTH,
    bsdf_dict,
    clip_planes,
    emitter_dict,
    film_dict,
    light_spec,
    path_integrator,
    tessellates_spheres,
)
from harness.scene import Scene
from harness.scene.triangulate import object_to_world, shape_triangles

FORMATS = ("mitsuba-xml", "ply", "obj", "gltf")
#: lumens per watt: a radiometric W/sr (W/m^2) is written to glTF as this many candela (lux), the convention of
#: Blender's glTF importer ("Standard" lighting), which turns the candela back into the same watts
LUMENS_PER_WATT = 683.0
GLTF_LIGHTS = "KHR_lights_punctual"
PUNCTUAL_TYPES = ("point", "spot", "directional")

# Plugin-valued keys of the adapter's dicts and the XML tag of each.
_PLUGIN_TAGS = {"film": "film", "rfilter": "rfilter", "sampler": "sampler", "bsdf": "bsdf", "emitter": "emitter",
                "integrator": "integrator"}
# 3-vector parameters of the emitters and their XML tag (a point transforms with translation, a vector without).
_VECTOR_TAGS = {"position": "point", "direction": "vector"}


def _num(value: float) -> str:
    """Shortest repr that round-trips (the XML holds exactly the adapter's float64 numbers)."""
    return repr(float(value))


def _vec(values) -> str:
    return ", ".join(_num(v) for v in values)


def _plugin_xml(tag: str, spec: dict, indent: str, name: str | None = None, plugin_id: str | None = None) -> list[str]:
    """One Mitsuba plugin dict (``{"type": ..., key: value}``) as XML lines. Values: bool, int, float, str, an
    ``{"type": "rgb", "value": [...]}`` colour, or a nested plugin dict."""
    attrs = f'type={quoteattr(spec["type"])}'
    if name is not None:
        attrs += f" name={quoteattr(name)}"
    if plugin_id is not None:
        attrs += f" id={quoteattr(plugin_id)}"
    lines = [f"{indent}<{tag} {attrs}>"]
    inner = indent + "    "
    for key, value in spec.items():
        if key == "type":
            continue
        if isinstance(value, dict) and value.get("type") == "rgb" and "value" in value:
            lines.append(f'{inner}<rgb name={quoteattr(key)} value="{_vec(value["value"])}"/>')
        elif key == "to_world" and isinstance(value, np.ndarray):
            lines += _matrix_xml(value, inner)
        elif key in _VECTOR_TAGS and isinstance(value, (list, tuple)):
            lines.append(f'{inner}<{_VECTOR_TAGS[key]} name={quoteattr(key)} value="{_vec(value)}"/>')
        elif isinstance(value, dict) and key in _PLUGIN_TAGS:
            lines += _plugin_xml(_PLUGIN_TAGS[key], value, inner)
        elif isinstance(value, bool):
            lines.append(f'{inner}<boolean name={quoteattr(key)} value="{str(value).lower()}"/>')
        elif isinstance(value, (int, np.integer)):
            lines.append(f'{inner}<integer name={quoteattr(key)} value="{int(value)}"/>')
        elif isinstance(value, (float, np.floating)):
            lines.append(f'{inner}<float name={quoteattr(key)} value="{_num(value)}"/>')
        elif isinstance(value, str):
            lines.append(f"{inner}<string name={quoteattr(key)} value={quoteattr(value)}/>")
        else:
            raise TypeError(f"cannot write {key!r} = {value!r} as Mitsuba XML")
    lines.append(f"{indent}</{tag}>")
    return lines


def _matrix_xml(matrix: np.ndarray, indent: str) -> list[str]:
    values = " ".join(_num(v) for v in np.asarray(matrix, dtype=np.float64).ravel())
    return [f'{indent}<transform name="to_world">', f'{indent}    <matrix value="{values}"/>', f"{indent}</transform>"]


def mitsuba_xml(scene: Scene, *, spp: int = 16, seed: int = 0, mesh_dir: str = MESH_DIR,
                texture_dir: str = TEXTURE_DIR) -> tuple[str, dict[str, bytes]]:
    """The scene as Mitsuba 3 XML text, and the PLY and EXR files it refers to (``{relative path: bytes}``).

    ``spp`` and ``seed`` are the defaults of the XML parameters ``$spp`` and ``$seed``.
    """
    near, far = clip_planes(scene)
    camera = scene.camera
    lines = [
        '<?xml version="1.0" encoding="utf-8"?>',
        f"<!-- {scene.name}: exported by rendering-harness (harness export) from {scene.path} -->",
        '<scene version="3.0.0">',
        f'    <default name="spp" value="{int(spp)}"/>',
        f'    <default name="seed" value="{int(seed)}"/>',
    ]
    integrator = path_integrator(scene.max_depth)
    assert integrator["rr_depth"] == RR_DEPTH
    lines += _plugin_xml("integrator", integrator, "    ")
    film = _plugin_xml("film", film_dict(scene), "        ")
    lines += [
        '    <sensor type="perspective">',
        f'        <float name="fov" value="{_num(camera.fov)}"/>',
        f'        <string name="fov_axis" value={quoteattr(camera.fov_axis)}/>',
        f'        <float name="near_clip" value="{_num(near)}"/>',
        f'        <float name="far_clip" value="{_num(far)}"/>',
        '        <transform name="to_world">',
        f'            <lookat origin="{_vec(camera.origin)}" target="{_vec(camera.target)}" up="{_vec(camera.up)}"/>',
        "        </transform>",
        '        <sampler type="independent">',
        '            <integer name="sample_count" value="$spp"/>',
        '            <integer name="seed" value="$seed"/>',
        "        </sampler>",
        *film,
        "    </sensor>",
    ]
    material_key = {}
    for j, (name, material) in enumerate(scene.materials.items()):
        material_key[name] = f"bsdf_{j}"
        lines.append(f"    <!-- material {name} -->")
        lines += _plugin_xml("bsdf", bsdf_dict(material), "    ", plugin_id=f"bsdf_{j}")
    meshes: dict[str, bytes] = {}
    as_mesh = ("mesh", "sphere") if tessellates_spheres(scene) else ("mesh",)
    for shape in scene.shapes:
        key = f"shape_{shape.index}"
        lines.append(f"    <!-- shape {shape.index}: {shape.name} -->")
        if shape.type in as_mesh:
            rel = f"{mesh_dir}/{shape.index}-{safe_name(shape.name)}.ply"
            meshes[rel] = ply_bytes(*shape_triangles(shape))  # world space, wound to face the front side
            lines += [f'    <shape type="ply" id="{key}">',
                      f"        <string name=\"filename\" value={quoteattr(rel)}/>",
                      '        <boolean name="face_normals" value="true"/>']
        else:
            lines.append(f'    <shape type="{shape.type}" id="{key}">')
            lines += _matrix_xml(object_to_world(shape), "        ")
            if shape.flip_normals:
                lines.append('        <boolean name="flip_normals" value="true"/>')
        lines.append(f'        <ref id="{material_key[shape.material]}"/>')
        if shape.is_emitter:
            lines += _plugin_xml("emitter", emitter_dict(shape), "        ")
        lines.append("    </shape>")
    for emitter in scene.emitters:
        lines.append(f"    <!-- emitter {emitter.index}: {emitter.name} -->")
        spec = light_spec(emitter)
        if emitter.type == "envmap":
            rel = f"{texture_dir}/{emitter.index}-{safe_name(emitter.name)}.exr"
            meshes[rel] = exr_bytes(emitter.image)  # the pixels the scene holds, as the adapter's bitmap
            spec = {"type": "envmap", "filename": rel, **{k: v for k, v in spec.items() if k != "type"}}
        lines += _plugin_xml("emitter", spec, "    ", plugin_id=f"emitter_{emitter.index}")
    lines.append("</scene>")
    return "\n".join(lines) + "\n", meshes


def normal_incidence_reflectance(eta, k) -> list[float]:
    """A conductor's Fresnel reflectance at normal incidence, per channel: ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)
    (1 for Mitsuba's perfect mirror eta = 0, k = 1)."""
    eta, k = np.asarray(eta, dtype=np.float64), np.asarray(k, dtype=np.float64)
    return [float(x) for x in ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)]


def gltf_material(material) -> tuple[dict, dict]:
    """The glTF 2.0 metallic-roughness factors of a material (keyword arguments of trimesh's PBRMaterial) and its
    glTF extensions (docs/external-renderers.md, "glTF materials").

    Diffuse: base colour = reflectance, metallic 0, roughness 1. Conductors: metallic 1, base colour = the normal-
    incidence Fresnel reflectance times specular_reflectance (exact for a perfect mirror; glTF's Schlick Fresnel
    approximates the others). Dielectrics: metallic 0, base colour = specular_transmittance,
    ``KHR_materials_transmission`` 1, ``KHR_materials_ior`` = int_ior / ext_ior (glTF's outside is index 1, so the
    relative index keeps the interface), ``KHR_materials_volume`` (a solid that refracts, not a thin wall).
    Roughness: 0 for smooth types, sqrt(alpha) for rough ones (glTF's GGX alpha is roughness^2: exact for ggx).
    """
    if material.is_diffuse:
        return {"baseColorFactor": [*material.reflectance, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}, {}
    roughness = math.sqrt(material.alpha) if material.is_rough else 0.0
    if material.is_conductor:
        f0 = normal_incidence_reflectance(material.eta, material.k)
        colour = [min(1.0, f * r) for f, r in zip(f0, material.specular_reflectance)]
        return {"baseColorFactor": [*colour, 1.0], "metallicFactor": 1.0, "roughnessFactor": roughness}, {}
    extensions = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                  "KHR_materials_ior": {"ior": float(material.int_ior / material.ext_ior)},
                  "KHR_materials_volume": {"thicknessFactor": 1.0}}
    return {"baseColorFactor": [*material.specular_transmittance, 1.0], "metallicFactor": 0.0,
            "roughnessFactor": roughness}, extensions


def _trimesh_scene(scene: Scene):
    """A trimesh.Scene with one named, coloured mesh per shape (world space, as the core triangulates it)."""
    out = trimesh.Scene()
    for shape in scene.shapes:
        vertices, triangles = shape_triangles(shape)
        material = scene.materials[shape.material]
        emission = np.asarray(shape.emission if shape.is_emitter else (0.0, 0.0, 0.0), dtype=np.float64)
        peak = float(emission.max())
        factors, _extensions = gltf_material(material)  # trimesh writes no extensions: _add_gltf_materials does
        pbr = PBRMaterial(name=safe_name(shape.material),
                          emissiveFactor=(emission / peak).tolist() if peak > 0 else None,
                          doubleSided=material.two_sided or material.is_dielectric, **factors)
        mesh = trimesh.Trimesh(vertices=vertices, faces=triangles, process=False, validate=False,
                               visual=trimesh.visual.TextureVisuals(material=pbr))
        mesh.metadata["name"] = shape.name
        extras = {"material": shape.material, "reflectance": list(material.reflectance)}
        if not material.is_diffuse:
            extras["bsdf"] = bsdf_dict(material)  # Mitsuba's plugin and parameters, for a reader that wants all
        if shape.is_emitter:
            extras["emission"] = [float(x) for x in shape.emission]
        out.add_geometry(mesh, node_name=safe_name(shape.name), geom_name=safe_name(shape.name),
                         metadata=extras)
    return out


def _rotation_from_minus_z(direction) -> list[float]:
    """The unit quaternion [x, y, z, w] (glTF's order) that turns -z, where a glTF light points, into the unit
    vector ``direction``."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    q = np.array([d[1], -d[0], 0.0, 1.0 - d[2]])  # [cross(-z, d), 1 + dot(-z, d)], normalised below
    length = float(np.linalg.norm(q))
    if length == 0.0:  # d = +z exactly: half a turn about x
        return [1.0, 0.0, 0.0, 0.0]
    return [float(x) + 0.0 for x in q / length]


def _gltf_colour(rgb) -> tuple[list[float], float]:
    """glTF's (color in [0, 1], intensity): color = rgb / its largest channel, intensity = that channel times
    :data:`LUMENS_PER_WATT`."""
    rgb = np.asarray(rgb, dtype=np.float64)
    peak = float(rgb.max())
    return [float(x) for x in rgb / peak], LUMENS_PER_WATT * peak


def gltf_light(emitter) -> tuple[dict, dict]:
    """A point, spot or directional emitter as a ``KHR_lights_punctual`` light and the node that places it.

    Intensity: candela (point, spot) or lux (directional) = :data:`LUMENS_PER_WATT` x the largest channel of the
    RGB W/sr (W/m^2), colour = the RGB divided by that channel. Spot: ``outerConeAngle`` = ``cutoff_angle``,
    ``innerConeAngle`` = ``beam_width`` (radians; glTF wants inner < outer, so inner is a hair smaller when they are
    equal); glTF's falloff between them is left to the viewer (the spec's sample code fades with the square of a
    ramp in cos), not Mitsuba's ramp linear in the angle. glTF lights have no size and fall off with 1/r^2, as
    Mitsuba's.
    """
    color, intensity = _gltf_colour(getattr(emitter, {"point": "intensity", "spot": "intensity",
                                                       "directional": "irradiance"}[emitter.type]))
    light = {"name": emitter.name, "type": emitter.type, "color": color, "intensity": intensity}
    node: dict = {"name": safe_name(emitter.name)}
    if emitter.type == "point":
        node["translation"] = [float(x) for x in emitter.position]
    elif emitter.type == "spot":
        outer = math.radians(emitter.cutoff_angle)
        inner = min(math.radians(emitter.beam_width), math.nextafter(outer, 0.0))
        light["spot"] = {"innerConeAngle": inner, "outerConeAngle": outer}
        node["translation"] = [float(x) for x in emitter.position]
        node["rotation"] = _rotation_from_minus_z(emitter.axis)
    else:
        node["rotation"] = _rotation_from_minus_z(emitter.direction)
    return light, node


def _add_gltf_lights(text: bytes, scene: Scene) -> bytes:
    """trimesh's glTF JSON with the scene's punctual emitters added as ``KHR_lights_punctual`` lights."""
    emitters = [e for e in scene.emitters if e.type in PUNCTUAL_TYPES]
    if not emitters:
        return text
    document = json.loads(text)
    lights = []
    nodes = document.setdefault("nodes", [])
    scenes = document.setdefault("scenes", [{"nodes": []}])
    roots = scenes[document.get("scene", 0)].setdefault("nodes", [])
    for emitter in emitters:
        light, node = gltf_light(emitter)
        node["extensions"] = {GLTF_LIGHTS: {"light": len(lights)}}
        lights.append(light)
        roots.append(len(nodes))
        nodes.append(node)
    document.setdefault("extensions", {})[GLTF_LIGHTS] = {"lights": lights}
    used = document.setdefault("extensionsUsed", [])
    if GLTF_LIGHTS not in used:
        used.append(GLTF_LIGHTS)
    return json.dumps(document, separators=(",", ":")).encode("utf-8")


def _add_gltf_materials(text: bytes, scene: Scene) -> bytes:
    """trimesh's glTF JSON with the non-diffuse materials as :func:`gltf_material` says (found through each node's
    ``extras.material``): their factors exact (trimesh rounds colours to 8 bits) and their extensions added.
    Lambertian materials stay as trimesh wrote them."""
    if not scene.has_glossy_materials:
        return text
    document = json.loads(text)
    used = document.get("extensionsUsed", [])
    for node in document.get("nodes", []):
        material = scene.materials.get(node.get("extras", {}).get("material"))
        if material is None or material.is_diffuse or "mesh" not in node:
            continue
        factors, extensions = gltf_material(material)
        for primitive in document["meshes"][node["mesh"]].get("primitives", []):
            if "material" in primitive:
                entry = document["materials"][primitive["material"]]
                entry.setdefault("pbrMetallicRoughness", {}).update(factors)
                if extensions:
                    entry.setdefault("extensions", {}).update(extensions)
        used += [extension for extension in extensions if extension not in used]
    if used:
        document["extensionsUsed"] = used
    return json.dumps(document, separators=(",", ":")).encode("utf-8")


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
        losses.append("OBJ's MTL has diffuse colours only: materials " + ", ".join(
            f"{m.name} ({m.type})" for m in glossy) + " written with the colour of their glTF base colour")
    if fmt == "gltf":
        lost = [e for e in scene.emitters if e.type not in PUNCTUAL_TYPES]
        if lost:
            losses.append(f"glTF 2.0 has no environment light: left out {names(lost)} (KHR_lights_punctual has "
                          "point, spot and directional lights only)")
        losses += _gltf_material_losses(glossy)
    return losses


def _gltf_material_losses(glossy) -> list[str]:
    """What glTF's metallic-roughness model and its extensions cannot say exactly of the non-diffuse materials."""
    def listed(materials) -> str:
        return ", ".join(f"{m.name} ({m.type})" for m in materials)

    losses = []
    metals = [m for m in glossy if m.is_conductor and not (m.mirror and m.specular_reflectance == (1.0, 1.0, 1.0))]
    if metals:
        losses.append(f"glTF metals have Schlick's Fresnel from a base colour: {listed(metals)} written with base "
                      "colour = normal-incidence reflectance x specular_reflectance (eta, k in the node's extras)")
    beckmann = [m for m in glossy if m.is_rough and m.distribution == "beckmann"]
    if beckmann:
        losses.append(f"glTF's microfacets are GGX: {listed(beckmann)} (beckmann) written with roughness sqrt(alpha)")
    tinted = [m for m in glossy if m.is_dielectric and m.specular_reflectance != (1.0, 1.0, 1.0)]
    if tinted:
        losses.append(f"glTF's transmission has no reflection tint: specular_reflectance of {listed(tinted)} left out")
    sided = [m for m in glossy if m.is_conductor and not m.two_sided]
    if sided:
        losses.append(f"glTF's single-sided materials are culled from behind, not black: {listed(sided)}")
    return losses


def export_scene(scene: Scene, fmt: str, out_dir: str | Path, *, spp: int = 16, seed: int = 0) -> list[Path]:
    """Write ``scene`` in format ``fmt`` (one of :data:`FORMATS`) into the folder ``out_dir`` (created if needed);
    returns the files written, the main file first. The files are written into a staging folder and moved into
    place together (:class:`harness.files.imageio.StagedFolder`): a failed write (a full disk) leaves ``out_dir`` as it
    was, and no folder made for it."""
    if fmt not in FORMATS:
        raise HarnessError("--format", f"expected one of {', '.join(FORMATS)}, got {fmt!r}")
    out_dir = Path(out_dir)
    files: dict[str, bytes] = {}
    if fmt == "mitsuba-xml":
        text, meshes = mitsuba_xml(scene, spp=spp, seed=seed)
        files["scene.xml"] = text.encode("utf-8")
        files.update(meshes)
    elif fmt == "ply":
        for shape in scene.shapes:
            files[f"{shape.index}-{safe_name(shape.name)}.ply"] = ply_bytes(*shape_triangles(shape))
    elif fmt == "obj":
        text, extra = export_obj(_trimesh_scene(scene), include_normals=False, include_texture=True,
                                 return_texture=True, mtl_name="scene.mtl")
        files["scene.obj"] = text.encode("utf-8")
        files.update({name: data for name, data in extra.items()})
    else:
        parts = export_gltf(_trimesh_scene(scene), include_normals=False, merge_buffers=True)
        main = next(name for name in parts if name.endswith(".gltf"))
        files["scene.gltf"] = _add_gltf_materials(_add_gltf_lights(parts[main], scene), scene)
        files.update({name: data for name, data in parts.items() if name != main})
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
