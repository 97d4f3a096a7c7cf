"""The resolved scene as JSON (``scene.json``): everything a renderer needs, with no TOML parser and no Mitsuba.

The document (``docs/scene-json.md`` describes every key) holds the case's scene as the harness judges it: the
suite's film, depth and stress variant applied, every default filled in, every placement a 4x4 matrix, every shape
also as a world-space PLY mesh (``meshes/<index>-<name>.ply``, wound to face its front side), every environment map
as an OpenEXR file (``textures/<index>-<name>.exr``). Numbers are float64 written with the shortest repr that
round-trips (``json`` does that), so a reader gets exactly the values the harness holds.

Conventions (Mitsuba 3's; the ground truth follows them): radiance in W m^-2 sr^-1, intensity in W sr^-1,
irradiance in W m^-2, angles in degrees; emitting shapes emit from their front side only; a BSDF that is not
``two_sided`` is black from behind; ``max_depth`` counts path vertices after the camera (1: emitters seen directly,
2: direct light, -1: unbounded), Russian roulette from depth ``rr_depth`` on.
"""

from __future__ import annotations

import numpy as np

from harness.files.imageio import encode_png, exr_bytes
from harness.renderers.meshfiles import MESH_DIR, TEXTURE_DIR, ply_bytes, safe_name
from harness.renderers.mitsuba_spec import RR_DEPTH, clip_planes
from harness.scene import Scene
from harness.scene.kinds.cameras import camera_kind
from harness.scene.kinds.emitters import EMITTERS
from harness.scene.kinds.media import MEDIA
from harness.scene.kinds.composites import ALL_MATERIALS
from harness.scene.kinds.shapes import SHAPES
from harness.scene.kinds.textures import TEXTURES, export_path
from harness.scene.triangulate import exported_normals, object_to_world, shape_triangles, vertex_uv

FORMAT = "rendering-harness scene"
VERSION = 1
#: the pixel filters' radii in pixels and their parameters, as Mitsuba's (``box`` covers one pixel)
FILTERS = {"box": {"type": "box", "radius": 0.5},
           "tent": {"type": "tent", "radius": 1.0},
           "gaussian": {"type": "gaussian", "stddev": 0.5, "radius": 2.0}}


def _floats(values) -> list:
    return np.asarray(values, dtype=np.float64).tolist()


def camera_json(scene: Scene) -> dict:
    """The camera's entry (of :data:`harness.scene.kinds.cameras.CAMERAS`): its type, look-at, its parameters (a
    perspective camera's: Mitsuba's ``fov`` / ``fov_axis``, the resolved full angles and the aspect ratio), the
    camera-to-world matrix (columns: +x = image left, +y = image up, +z = forward, origin) and the clip planes."""
    near, far = clip_planes(scene)
    return {**camera_kind(scene.camera).to_scene_json(scene.camera, scene.film),
            "near_clip": float(near), "far_clip": float(far), "medium": scene.camera_medium}


def material_json(material) -> dict:
    """One material with every parameter of its Mitsuba plugin (``two_sided`` for diffuse, conductors and the
    plastics)."""
    return ALL_MATERIALS[material.type].to_scene_json(material)


def texture_json(scene: Scene, files: dict) -> dict:
    """Every texture a material takes, by name (its type's entry, a bitmap's pixels as ``textures/texture-<name>``
    .png or .exr, added to ``files``)."""
    out = {}
    for texture in scene.used_textures:
        out[texture.name] = TEXTURES[texture.type].to_scene_json(texture)
        if texture.image is not None:
            path = export_path(texture)
            files[path] = encode_png(texture.image) if texture.image.dtype == np.uint8 else exr_bytes(texture.image)
    return out


def emitter_json(emitter, texture: str | None = None) -> dict:
    """One ``[[emitters]]`` entry with its Mitsuba parameters (plain numbers; matrices 4x4 row-major)."""
    return EMITTERS[emitter.type].to_scene_json(emitter, texture)


def scene_json(scene: Scene, *, mesh_dir: str = MESH_DIR, texture_dir: str = TEXTURE_DIR) -> tuple[dict, dict]:
    """The scene as a JSON-ready dict and the files it names (``{relative path: bytes}``: PLY meshes, EXR maps).

    Every shape has ``mesh`` (its world-space triangles; a sphere's icosphere, for a renderer without analytic
    spheres, with the sphere's normals at its vertices where its material is not diffuse) and, for rectangles,
    cubes and spheres, ``to_world``: the object-to-world matrix of Mitsuba's analytic shape (a sphere's includes its
    centre and radius), which the reference and the ground truth trace. ``spheres_as_meshes`` is false (kept for
    readers of earlier files).
    """
    files: dict[str, bytes] = {}
    shapes = []
    textured = bool(scene.used_textures)
    for shape in scene.shapes:
        rel = f"{mesh_dir}/{shape.index}-{safe_name(shape.name)}.ply"
        vertices, triangles = shape_triangles(shape)
        uv = vertex_uv(shape) if textured else None
        normals = exported_normals(scene, shape, vertices, triangles)
        files[rel] = ply_bytes(vertices, triangles, uv, normals)
        entry: dict = {"index": shape.index, "name": shape.name, "type": shape.type, "material": shape.material,
                       "emission": (None if shape.emission is None else _floats(shape.emission)
                                    if shape.emission_texture is None else {"texture": shape.emission_texture.name}),
                       "mesh": rel, "triangles": int(len(triangles)),
                       # smooth: the PLY's nx, ny, nz are the shading normals (Mitsuba's vertex normals)
                       "shading": "flat" if normals is None else "smooth",
                       # Mitsuba's medium transition: the media behind and in front of its front side, or null
                       "interior": shape.interior, "exterior": shape.exterior}
        if textured:
            entry["uv"] = "analytic" if SHAPES[shape.type].sphere is not None else ("mesh" if uv is not None
                                                                                     else None)
        kind = SHAPES[shape.type]
        if kind.analytic:
            entry["to_world"] = _floats(object_to_world(shape))
            entry["flip_normals"] = bool(shape.flip_normals)
        entry.update(kind.json(shape))
        shapes.append(entry)
    emitters = []
    for emitter in scene.emitters:
        texture = None
        if EMITTERS[emitter.type].textured:
            texture = f"{texture_dir}/{emitter.index}-{safe_name(emitter.name)}.exr"
            files[texture] = exr_bytes(emitter.image)
        emitters.append(emitter_json(emitter, texture))
    document = {
        "format": FORMAT, "version": VERSION,
        "name": scene.name, "source": str(scene.path),
        "units": {"radiance": "W m^-2 sr^-1", "intensity": "W sr^-1", "irradiance": "W m^-2", "angles": "degrees"},
        "camera": camera_json(scene),
        "film": {"width": int(scene.film.width), "height": int(scene.film.height),
                 "filter": dict(FILTERS[scene.film.filter])},
        "integrator": {"type": "path", "max_depth": int(scene.max_depth), "rr_depth": RR_DEPTH},
        "spheres_as_meshes": False,
        "closed_form": scene.closed_form,
        "textures": texture_json(scene, files),
        "materials": {name: material_json(m) for name, m in scene.materials.items()},
        "shapes": shapes,
        "emitters": emitters,
        "regions": list(scene.regions),
    }
    if scene.media:  # absent from a scene without media
        document["media"] = {name: MEDIA[m.type].to_scene_json(m) for name, m in scene.media.items()}
    return document, files
