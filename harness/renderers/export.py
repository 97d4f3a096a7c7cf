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
* Textures (glTF and OBJ): an 8-bit sRGB bitmap on a material's base colour parameter is a PNG image
  (``textures/texture-<name>.png``): glTF's ``baseColorTexture`` with its sampler and ``KHR_texture_transform``,
  MTL's ``map_Kd``; every shape gets texture coordinates (glTF ``TEXCOORD_0``, OBJ ``vt`` with v flipped). What
  they cannot say (checkerboards, float or raw bitmaps, other parameters, shear, MTL's filter and wrap, spheres'
  analytic coordinates) :func:`export_losses` names.
* Shading normals (glTF and OBJ): a smooth-shaded shape (:func:`smooth_normals`: a mesh with vertex normals, its
  file's or the angle-weighted ones Mitsuba computes) has its world-space vertex normals, glTF's ``NORMAL`` (float32)
  and OBJ's ``vn`` (faces ``v/vt/vn`` or ``v//vn``); flat shapes have none (glTF's readers then shade flat). A
  ``normalmap`` material's 8-bit map is glTF's ``normalTexture`` (the codes the scene holds, its sampler and
  transform as a base colour texture's) with ``NORMAL`` and ``TANGENT`` = Mitsuba's frame at every corner (s =
  dp/du made perpendicular to n, w = +1 so that glTF's bitangent cross(n, s) w is Mitsuba's t = n x s:
  :func:`corner_frames`), and MTL's ``norm`` (the codes with the green inverted for OBJ's v up: :func:`green_up`).
  A ``bumpmap`` has neither form, and Mitsuba's shadow terminator and flip of invalid normals neither format:
  :func:`export_losses` names them.

:func:`export_losses` says, one line each, what a format leaves out of a scene (``harness export`` prints them as
warnings).

PLY meshes are written with trimesh, glTF and OBJ by this module; every file is written atomically
(:mod:`harness.files.imageio`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from reference_impl.materials import TEXTURE_SLOTS as CORE_TEXTURE_SLOTS
from reference_impl.sampling import coordinate_frame

from harness.core.errors import HarnessError
from harness.core.jsonsafe import plain
from harness.files.imageio import StagedFolder, atomic_write_bytes, atomic_write_text, encode_png, make_folders
from harness.renderers.meshfiles import ply_bytes, safe_name
from harness.renderers.mitsuba_spec import RR_DEPTH, Parameter, bsdf_dict, clip_planes, scene_spec
from harness.renderers.mitsuba_xml import spec_xml
from harness.renderers.scene_json import FILTERS, scene_json
from harness.scene import Scene
from harness.scene.kinds.cameras import camera_kind, camera_to_world
from harness.scene.kinds.emitters import EMITTERS
from harness.scene.kinds.composites import ALL_MATERIALS
from harness.scene.kinds.materials import GLTF_LOSSES
from harness.scene.kinds.materials import TEXTURE_SLOTS as HARNESS_TEXTURE_SLOTS
from harness.scene.kinds.perturbations import PERTURBATIONS
from harness.scene.kinds.shapes import SHAPES
from harness.scene.kinds.textures import TEXTURES, export_path
from harness.scene.primitives import sphere_uv
from harness.scene.triangulate import exported_normals, object_mesh, shape_triangles, vertex_uv

FORMATS = ("mitsuba-xml", "json", "ply", "obj", "gltf")
GLTF_LIGHTS = "KHR_lights_punctual"
GLTF_EMISSIVE_STRENGTH = "KHR_materials_emissive_strength"
GLTF_TEXTURE_TRANSFORM = "KHR_texture_transform"
#: glTF sampler constants (WebGL's): a bitmap's filter_type as magFilter and minFilter (no mipmaps: Mitsuba has none),
#: its wrap_mode as wrapS and wrapT (MIRRORED_REPEAT reflects the texel index at each edge, as Mitsuba's mirror)
GLTF_FILTERS = {"bilinear": 9729, "nearest": 9728}  # LINEAR, NEAREST
GLTF_WRAPS = {"repeat": 10497, "mirror": 33648, "clamp": 33071}  # REPEAT, MIRRORED_REPEAT, CLAMP_TO_EDGE
WHITE = (1.0, 1.0, 1.0)


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
    return ALL_MATERIALS[material.type].to_gltf(material)


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


# ---- textures in glTF and OBJ ---------------------------------------------------------------------------------------


def base_colour_parameter(material) -> str:
    """The parameter glTF's base colour (and OBJ's ``Kd``) is made from: its type's ``gltf_base`` (a diffuse
    material's ``reflectance``, a conductor's ``specular_reflectance``, a dielectric's ``specular_transmittance``, a
    plastic's and a rough plastic's ``diffuse_reflectance``)."""
    return ALL_MATERIALS[material.type].gltf_base


def image_texture(texture) -> bool:
    """Whether glTF's base colour texture and MTL's ``map_Kd`` carry ``texture`` exactly: an 8-bit bitmap of sRGB
    codes (not ``raw``), written as the PNG of the codes the scene holds. A checkerboard (procedural), a float (EXR)
    bitmap and a raw one (code / 255, where both formats decode sRGB) are not."""
    return texture.type == "bitmap" and texture.image.dtype == np.uint8 and not texture.raw


def carried_texture(material):
    """The texture glTF's ``baseColorTexture`` and MTL's ``map_Kd`` hold for ``material``: that of its base colour
    parameter (:func:`base_colour_parameter`) when :func:`image_texture`, else None."""
    texture = material.texture(base_colour_parameter(material))
    return texture if texture is not None and image_texture(texture) else None


def exported_material(material):
    """``material`` as glTF's factors and MTL's ``Kd`` see it: the parameter of :func:`carried_texture` white (the
    format multiplies its factor by the texture), every other textured parameter its texture's mean
    (:attr:`~harness.scene.model.Texture.mean_value`, a loss :func:`export_losses` names)."""
    carried = carried_texture(material)
    changes = {COMPOSITE_FIELDS.get(item, item): (WHITE if texture is carried else texture.scalar_mean
                                                  if len(texture_slot_columns(item)) == 1 else texture.mean_value)
               for item, texture in material.textures}
    if changes and material.principled is not None:  # a principled material's parameters are its own record's
        return dataclasses.replace(material, textures=(), principled=dataclasses.replace(material.principled, **changes))
    return dataclasses.replace(material, textures=(), **changes) if changes else material


#: The field of a composite's textured parameter (a blend's weight and a mask's opacity are its ``weight``).
COMPOSITE_FIELDS = {"opacity": "weight"}


def texture_slot_columns(item: str) -> range:
    """The core's columns of the textured parameter ``item`` (one for a one-number parameter, three for a colour)."""
    column, channels = CORE_TEXTURE_SLOTS[HARNESS_TEXTURE_SLOTS[item]]
    return range(column, column + channels)


def gltf_uv_transform(to_uv) -> dict | None:
    """``to_uv`` as ``KHR_texture_transform``'s offset, rotation and scale ({} for the identity; None for a map with
    shear, which the extension cannot say).

    The extension's matrix is T(offset) R(rotation) S(scale) with R(r) = [[cos r, sin r], [-sin r, cos r]] acting on
    (u, v) (v down): the rotation as its example, sample model (TextureTransformTest) and readers (Blender, Babylon.js)
    take it; the GLSL listing of the specification has its transpose (KhronosGroup/glTF#1563). So the linear part's
    columns are scale_u (cos r, -sin r) and scale_v (sin r, cos r): r = atan2(-m10, m00), scale_u = |column 0| and
    scale_v the second column's length along (sin r, cos r), negative for a mirrored map.
    """
    matrix = np.asarray(to_uv, dtype=np.float64)
    if np.array_equal(matrix, np.eye(3)):
        return {}
    (a, b, tu), (c, d, tv) = matrix[:2]
    scale_u = math.hypot(a, c)
    if scale_u == 0.0 or abs(a * b + c * d) > 1e-12 * scale_u * math.hypot(b, d):
        return None  # a shear (the columns are not perpendicular) or a degenerate map
    rotation = math.atan2(-c, a) + 0.0
    sin, cos = math.sin(rotation), math.cos(rotation)
    scale_v = b * sin + d * cos
    rebuilt = np.array([[cos * scale_u, sin * scale_v], [-sin * scale_u, cos * scale_v]])
    if not np.allclose(rebuilt, [[a, b], [c, d]], rtol=0.0, atol=1e-12 * max(scale_u, abs(scale_v))):
        return None
    return {"offset": [float(tu) + 0.0, float(tv) + 0.0], "rotation": rotation, "scale": [scale_u, float(scale_v)]}


def gltf_sampler(texture) -> dict:
    """A bitmap's filter and wrap mode as a glTF sampler (:data:`GLTF_FILTERS`, :data:`GLTF_WRAPS`)."""
    filt, wrap = GLTF_FILTERS[texture.filter_type], GLTF_WRAPS[texture.wrap_mode]
    return {"magFilter": filt, "minFilter": filt, "wrapS": wrap, "wrapT": wrap}


def sphere_corner_uv(shape, triangles: np.ndarray) -> np.ndarray:
    """Mitsuba's analytic texture coordinates of a sphere at the corners of its icosphere's ``triangles``, (T, 3, 2):
    at each vertex p (object space) u = atan2(p_y, p_x) / (2 pi) mod 1, v = acos(p_z / |p|) / pi; a triangle across
    the seam (its u spanning more than 1/2) gets u + 1 at its corners below 1/2 (so that its u runs on, as the
    sphere's does modulo 1), and a corner at a pole (where u is undefined) the mean u of its triangle's other two."""
    points = np.asarray(object_mesh(shape)[0], dtype=np.float64)
    u, v = sphere_uv(points).T
    pole = (np.hypot(points[:, 0], points[:, 1]) <= 1e-12 * np.linalg.norm(points, axis=1))[triangles]
    cu, cv = u[triangles], v[triangles]
    span = np.where(pole, -np.inf, cu).max(axis=1) - np.where(pole, np.inf, cu).min(axis=1)
    cu = np.where((span > 0.5)[:, None] & (cu < 0.5) & ~pole, cu + 1.0, cu)
    others = np.where(pole, 0.0, cu).sum(axis=1) / np.maximum((~pole).sum(axis=1), 1)
    return np.stack([np.where(pole, others[:, None], cu), cv], axis=-1)


def textured_mesh(shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A shape's triangles with texture coordinates, (vertices, triangles, uv): :func:`shape_triangles` and Mitsuba's
    coordinates at its vertices (:func:`harness.scene.triangulate.vertex_uv`; 0 for a mesh without them, as the
    reference takes them); a sphere's from :func:`sphere_corner_uv`, its vertices repeated where a seam or pole
    corner needs other coordinates (the same triangles)."""
    vertices, triangles = shape_triangles(shape)
    if SHAPES[shape.type].sphere is None:
        uv = vertex_uv(shape)
        return vertices, triangles, np.zeros((len(vertices), 2)) if uv is None else np.asarray(uv, np.float64)
    corners = sphere_corner_uv(shape, triangles)
    keys = np.concatenate([triangles.reshape(-1, 1).astype(np.float64), corners.reshape(-1, 2)], axis=1)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    return vertices[unique[:, 0].astype(np.int64)], np.reshape(inverse, (-1, 3)), unique[:, 1:]


def mapped_uv(uv: np.ndarray, to_uv) -> np.ndarray:
    """Texture coordinates mapped by a texture's ``to_uv`` ((u', v', 1) = to_uv (u, v, 1)); unchanged by the
    identity."""
    matrix = np.asarray(to_uv, dtype=np.float64)
    if np.array_equal(matrix, np.eye(3)):
        return uv
    return uv @ matrix[:2, :2].T + matrix[:2, 2]


# ---- shading normals and normal maps in glTF and OBJ ---------------------------------------------------------------


def smooth_normals(scene: Scene, shape, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray | None:
    """The world-space unit vertex normals a smooth-shaded shape is written with (glTF ``NORMAL``, OBJ ``vn``):
    :func:`harness.scene.triangulate.exported_normals` of its ``vertices`` and ``triangles`` (those of
    :func:`shape_triangles`; a mesh's file normals or the angle-weighted ones Mitsuba computes, the analytic normals
    at the icosphere's vertices of a sphere that is not diffuse), or None for a shape shaded flat (``face_normals =
    true``, rectangles, cubes, diffuse spheres, and every emitting shape, as scene.json takes them), which both
    formats leave without normals: glTF's readers then MUST shade flat."""
    return exported_normals(scene, shape, vertices, triangles)


def normal_map(material):
    """The tangent-space normal map of a ``normalmap`` material (its perturbation's texture), else None (a
    ``bumpmap``'s height is no normal map: neither format has a bump map, :func:`export_losses`)."""
    p = material.perturbation
    return p.texture if p is not None and p.type == "normalmap" else None


def carried_normal_map(material):
    """The normal map glTF's ``normalTexture`` holds for ``material``: an 8-bit bitmap (raw, as a ``normalmap``
    takes it: n = 2 code / 255 - 1, which glTF's normal textures are too, never sRGB-decoded), written as the PNG of
    the codes the scene holds; a float (EXR) one is not (a loss)."""
    texture = normal_map(material)
    return texture if texture is not None and texture.image is not None and texture.image.dtype == np.uint8 else None


def corner_frames(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray,
                  normals: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's shading frame at the corners of each triangle, (normals, tangents), each (T, 3, 3): n = the corner's
    vertex normal (``normals``, (V, 3)), or the triangle's own normal as wound where the shape is flat (None); the
    tangent s = normalize(dp/du - n (n . dp/du)), dp/du the triangle's from its corners and its (untransformed)
    texture coordinates ``uv`` (V, 2) (dp/du = (dv_2 e_1 - dv_1 e_2) / (du_1 dv_2 - dv_1 du_2), e_i = p_i - p_0:
    :func:`reference_impl.kernels.shading.position_derivatives`), or the core's tangent of n where the coordinates
    are degenerate (:func:`reference_impl.sampling.coordinate_frame`). The bitangent is t = n x s (so glTF's
    ``TANGENT`` w is +1)."""
    corners = np.asarray(vertices, np.float64)[triangles]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    with np.errstate(all="ignore"):
        face = np.cross(e1, e2)
        face /= np.linalg.norm(face, axis=1, keepdims=True)
        n = (np.repeat(face[:, None, :], 3, axis=1) if normals is None
             else np.asarray(normals, np.float64)[triangles])
        n = np.where(np.isfinite(n), n, 0.0)
        c = np.asarray(uv, np.float64)[triangles]
        du1, dv1 = c[:, 1, 0] - c[:, 0, 0], c[:, 1, 1] - c[:, 0, 1]
        du2, dv2 = c[:, 2, 0] - c[:, 0, 0], c[:, 2, 1] - c[:, 0, 1]
        det = du1 * dv2 - dv1 * du2
        dpdu = (dv2[:, None] * e1 - dv1[:, None] * e2) / det[:, None]
        s = dpdu[:, None, :] - n * np.einsum("tcj,tj->tc", n, dpdu)[..., None]
        length = np.linalg.norm(s, axis=-1, keepdims=True)
        s = s / length
    bad = ~((det != 0.0)[:, None] & (length[..., 0] > 0) & np.all(np.isfinite(s), axis=-1))
    if np.any(bad):
        s[bad] = coordinate_frame(n[bad])[0]
    return n, s


def split_corners(triangles: np.ndarray, count: int, *corner_values: np.ndarray) -> tuple[np.ndarray, ...]:
    """Vertices for per-corner values (each (T, 3, k)): a vertex keeps its index and takes the values of its first
    corner; a corner whose values (as float32, what glTF stores) differ from those gets a vertex of its own, appended
    after the ``count`` vertices (one per distinct vertex and values). Returns (source, triangles, used, values...):
    ``source`` the original index of every output vertex, the triangles re-indexed, ``used`` whether a triangle uses
    the vertex (a mesh file may hold others: their values are 0), each value per output vertex. Shapes whose corners
    agree (a rectangle's) keep their vertices and triangles as they are."""
    flat = np.asarray(triangles, np.int64).ravel()
    values = [np.asarray(v, np.float64).reshape(len(flat), -1) for v in corner_values]
    key = np.concatenate([np.float32(v).astype(np.float64) for v in values], axis=1)
    _, first = np.unique(flat, return_index=True)  # each used vertex's first corner
    owner = np.full(count, -1, np.int64)
    owner[flat[first]] = first
    same = np.all(key == key[owner[flat]], axis=1)
    source, corner_of, index = np.arange(count, dtype=np.int64), owner, flat.copy()
    extra = np.flatnonzero(~same)
    if len(extra):
        keys = np.concatenate([flat[extra, None].astype(np.float64), key[extra]], axis=1)
        _, pick, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        source = np.concatenate([source, flat[extra[pick]]])
        corner_of = np.concatenate([owner, extra[pick]])
        index[extra] = count + np.reshape(inverse, -1)
    used = corner_of >= 0
    out = [np.where(used[:, None], v[np.maximum(corner_of, 0)], 0.0) for v in values]
    return (source, index.reshape(-1, 3), used, *out)


def normal_mapped_mesh(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray,
                       normals: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """A normal-mapped shape's mesh for glTF: (vertices, triangles, uv, normals, tangents), the normals and tangents
    Mitsuba's frame at every corner (:func:`corner_frames`), vertices repeated where two corners of one vertex need
    different ones (:func:`split_corners`: a smooth mesh's, whose triangles have their own dp/du). A vertex no
    triangle uses gets its vertex normal (or +z) and the core's tangent of it."""
    corner_n, corner_s = corner_frames(vertices, triangles, uv, normals)
    source, triangles, used, n, s = split_corners(triangles, len(vertices), corner_n, corner_s)
    if not np.all(used):
        n[~used] = (0.0, 0.0, 1.0) if normals is None else np.asarray(normals, np.float64)[source[~used]]
        s[~used] = coordinate_frame(n[~used])[0]
    return np.asarray(vertices)[source], triangles, np.asarray(uv)[source], n, s


def gltf_camera(scene: Scene) -> tuple[dict, dict]:
    """The scene's camera as a glTF camera (its type's form, :attr:`harness.scene.kinds.cameras.CameraKind.gltf`:
    perspective with ``yfov`` and ``aspectRatio``, a thin lens's two numbers under ``extras``, or orthographic
    with ``xmag`` / ``ymag``; ``znear`` / ``zfar`` the clip planes) and the node that places it.

    The node's ``matrix`` (column-major) is Mitsuba's camera-to-world matrix of the look-at (without an
    orthographic scale) with its x and z columns negated: a glTF camera looks down its -z with +x to the image's
    right, Mitsuba's looks down +z with +x to the image's left, so both see the same image.
    """
    camera = scene.camera
    near, far = clip_planes(scene)
    to_world = camera_to_world(camera) @ np.diag([-1.0, 1.0, -1.0, 1.0])  # negate the x and z columns
    gltf = {"name": "camera", **camera_kind(camera).gltf(camera, scene.film, near, far)}
    return gltf, {"name": "camera", "camera": 0, "matrix": [float(x) + 0.0 for x in to_world.T.ravel()]}


def gltf_render_settings(scene: Scene) -> dict:
    """What glTF has no place for, kept under ``asset.extras``: the film (size and pixel filter, as in scene.json),
    ``max_depth`` (Mitsuba's meaning, docs/scene-json.md) and ``rr_depth``."""
    return {"film": {"width": int(scene.film.width), "height": int(scene.film.height),
                     "filter": dict(FILTERS[scene.film.filter])},
            "max_depth": int(scene.max_depth), "rr_depth": RR_DEPTH}


def _gltf_shape_material(shape, material, base_texture: dict | None = None,
                         normal_texture: dict | None = None) -> dict:
    """The glTF material of one shape: :func:`gltf_material`'s factors as full float64 numbers (of
    :func:`exported_material`: a texture glTF carries is ``base_texture``, the ``baseColorTexture`` whose texels the
    factor multiplies), a normal map's ``normalTexture`` (``normal_texture``; glTF's default scale 1: n =
    normalize(2 rgb - 1), as Mitsuba's), and for an emitting shape ``emissiveFactor`` = emission / its largest
    channel with ``KHR_materials_emissive_strength`` = that channel (factor x strength = the radiance)."""
    factors, extensions = gltf_material(exported_material(material))
    factors = plain(factors)
    if base_texture is not None:
        factors["baseColorTexture"] = base_texture
    entry: dict = {"name": safe_name(shape.material), "pbrMetallicRoughness": factors,
                   "doubleSided": ALL_MATERIALS[material.type].gltf_double_sided(material)}
    if normal_texture is not None:
        entry["normalTexture"] = normal_texture
    if material.type in ("mask", "null"):  # its opacity is the base colour's alpha (composites._gltf), blended
        entry["alphaMode"] = "BLEND"
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


def _extras_bsdf(material) -> dict:
    """A material's Mitsuba plugin dict as JSON values, each textured parameter as ``{"texture": NAME}`` (as in
    scene.json; the texture itself is in ``asset.extras.textures``)."""
    spec = bsdf_dict(material)
    inner = spec["bsdf"] if spec.get("type") == "twosided" and not material.nested else spec
    for item, texture in material.textures:
        inner[item] = {"texture": texture.name}
    return plain(spec)


def _extras_perturbation(material) -> dict:
    """A ``normalmap`` or ``bumpmap`` material's keys as in scene.json (its texture by name, ``scale``,
    ``flip_invalid_normals``, ``use_shadowing_function``), without the ``bsdf`` it wraps (the node's material)."""
    entry = PERTURBATIONS[material.perturbation.type].to_scene_json(material, {})
    entry.pop("bsdf", None)
    return plain(entry)


def gltf_document(scene: Scene, buffer_name: str = "scene.bin",
                  files: dict[str, bytes] | None = None) -> tuple[dict, bytes]:
    """The scene as a glTF 2.0 document (a JSON-ready dict) and its binary buffer (``buffer_name``).

    One node and mesh per shape (world-space triangles as the core triangulates them: float32 positions, uint32
    indices, wound so that the front side is counter-clockwise), one material per scene material and emission
    (:func:`_gltf_shape_material`), the camera (:func:`gltf_camera`), the punctual emitters as
    ``KHR_lights_punctual`` lights (:func:`gltf_light`) and the render settings in ``asset.extras``
    (:func:`gltf_render_settings`). Each mesh node's ``extras`` holds its material's name and reflectance, the
    Mitsuba plugin dict of a non-diffuse material (``bsdf``) and an emitting shape's ``emission``.

    A scene with textures: every primitive has ``TEXCOORD_0`` (float32; Mitsuba's (u, v), whose origin is the
    image's top left with v down, as glTF's: :func:`textured_mesh`), each base colour texture glTF carries
    (:func:`carried_texture`) is a ``baseColorTexture`` (texCoord 0) of an image ``textures/texture-<name>.png``
    (the codes the scene holds, added to ``files``) with its sampler (:func:`gltf_sampler`) and ``to_uv`` as
    ``KHR_texture_transform`` (:func:`gltf_uv_transform`); ``asset.extras.textures`` holds every texture's
    scene.json entry and the nodes' ``extras.textures`` the textured parameters' texture names.

    Shading normals: a smooth-shaded shape's ``NORMAL`` = its world-space vertex normals (float32,
    :func:`smooth_normals`); a flat one has none (glTF's readers MUST then shade flat: the facets' normals, as
    Mitsuba's). A ``normalmap`` material with an 8-bit map (:func:`carried_normal_map`) has a ``normalTexture``
    (its image, sampler and ``KHR_texture_transform`` as a ``baseColorTexture``'s: glTF reads it raw, n =
    normalize(2 rgb - 1)) and its shapes ``NORMAL`` and ``TANGENT`` at every corner (:func:`normal_mapped_mesh`:
    Mitsuba's n and s, w = +1; glTF ignores TANGENT without NORMAL, so a flat shape's are its facets' normals). A
    node's ``extras.perturbation`` holds a normalmap's or bumpmap's keys as in scene.json.
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
    textured = bool(scene.used_textures)
    images: list[dict] = []
    samplers: list[dict] = []
    textures: list[dict] = []
    texture_index: dict[str, int] = {}

    def texture_info(texture) -> dict:
        """The ``baseColorTexture`` or ``normalTexture`` of a texture glTF carries: its image, sampler and
        transform."""
        if texture.name not in texture_index:
            path = export_path(texture)
            if files is not None:
                files[path] = encode_png(texture.image)
            images.append({"name": safe_name(texture.name), "uri": path, "mimeType": "image/png"})
            samplers.append(gltf_sampler(texture))
            textures.append({"name": safe_name(texture.name), "sampler": len(samplers) - 1, "source": len(images) - 1})
            texture_index[texture.name] = len(textures) - 1
        info: dict = {"index": texture_index[texture.name], "texCoord": 0}
        transform = gltf_uv_transform(texture.to_uv)
        if transform:
            info["extensions"] = {GLTF_TEXTURE_TRANSFORM: transform}
            if GLTF_TEXTURE_TRANSFORM not in used:
                used.append(GLTF_TEXTURE_TRANSFORM)
        return info

    for shape in scene.shapes:
        material = scene.materials[shape.material]
        if textured:
            vertices, triangles, uv = textured_mesh(shape)
        else:
            (vertices, triangles), uv = shape_triangles(shape), None
        normals, tangents = smooth_normals(scene, shape, vertices, triangles), None
        normal_texture = carried_normal_map(material)
        if normal_texture is not None:  # a normal map: Mitsuba's frame at every corner (uv: the scene is textured)
            vertices, triangles, uv, normals, tangents = normal_mapped_mesh(vertices, triangles, uv, normals)
        positions = np.asarray(vertices, dtype="<f4")
        position = accessor(positions, 34962, 5126, "VEC3",  # ARRAY_BUFFER, FLOAT
                            min=[float(x) for x in positions.min(axis=0)],
                            max=[float(x) for x in positions.max(axis=0)])
        attributes = {"POSITION": position}
        if normals is not None:
            attributes["NORMAL"] = accessor(np.asarray(normals, dtype="<f4"), 34962, 5126, "VEC3")
        if tangents is not None:  # w = +1: glTF's bitangent cross(NORMAL, TANGENT) w is Mitsuba's t = n x s
            tangent4 = np.concatenate([tangents, np.ones((len(tangents), 1))], axis=1)
            attributes["TANGENT"] = accessor(np.asarray(tangent4, dtype="<f4"), 34962, 5126, "VEC4")
        if uv is not None:
            attributes["TEXCOORD_0"] = accessor(np.asarray(uv, dtype="<f4"), 34962, 5126, "VEC2")
        indices = accessor(np.asarray(triangles, dtype="<u4").ravel(), 34963, 5125, "SCALAR")  # UNSIGNED_INT
        key = (shape.material, tuple(shape.emission) if shape.is_emitter else None)
        if key not in material_index:
            material_index[key] = len(materials)
            carried = carried_texture(material)
            materials.append(_gltf_shape_material(
                shape, material, None if carried is None else texture_info(carried),
                None if normal_texture is None else texture_info(normal_texture)))
            used += [e for e in materials[-1].get("extensions", {}) if e not in used]
        name = _unique(safe_name(shape.name), taken)
        meshes.append({"name": name, "primitives": [
            {"attributes": attributes, "indices": indices, "mode": 4, "material": material_index[key]}]})
        extras: dict = {"material": shape.material, "reflectance": [float(x) for x in material.reflectance]}
        if not material.is_diffuse:
            extras["bsdf"] = _extras_bsdf(material)  # Mitsuba's plugin and parameters, for a reader wanting all
        if material.textures:
            extras["textures"] = {item: texture.name for item, texture in material.textures}
        if material.perturbation is not None:  # the normalmap's or bumpmap's scene.json keys but its bsdf
            extras["perturbation"] = _extras_perturbation(material)
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
    settings = gltf_render_settings(scene)
    if textured:
        settings["textures"] = {t.name: _texture_extras(t, t.name in texture_index) for t in scene.used_textures}
    document: dict = {
        "asset": {"version": "2.0", "generator": "rendering-harness (harness export)", "extras": settings},
        "scene": 0, "scenes": [{"name": scene.name, "nodes": list(range(len(nodes)))}],
        "nodes": nodes, "cameras": [camera],
    }
    if meshes:
        document.update(meshes=meshes, materials=materials, accessors=accessors, bufferViews=views,
                        buffers=[{"uri": buffer_name, "byteLength": sum(map(len, chunks))}])
    if textures:
        document.update(textures=textures, images=images, samplers=samplers)
    if lights:
        document["extensions"] = {GLTF_LIGHTS: {"lights": lights}}
        used.append(GLTF_LIGHTS)
    if used:
        document["extensionsUsed"] = used
    return document, b"".join(chunks)


def _texture_extras(texture, written: bool) -> dict:
    """A texture's scene.json entry (docs/scene-json.md), its ``filename`` only where the export wrote the file."""
    entry = TEXTURES[texture.type].to_scene_json(texture)
    if not written:
        entry.pop("filename", None)
    return plain(entry)


def _mtl_number(value: float) -> str:
    return repr(float(value) + 0.0)


def obj_text(scene: Scene, mtl_name: str = "scene.mtl", files: dict[str, bytes] | None = None) -> tuple[str, str]:
    """The scene as OBJ text and its MTL text, holding only what the scene says.

    OBJ: one ``o`` object per shape (world-space triangles as the core triangulates them, counter-clockwise seen
    from the front side; vertices with the shortest repr that round-trips, so a reader gets the float64 values),
    ``usemtl`` naming its material. MTL: one ``newmtl`` per scene material (and per emitting shape) with ``Kd``
    (the diffuse reflectance; for other materials the glTF base colour, :func:`gltf_material`) and, for an
    emitting shape, ``Ke`` = its radiance (W m^-2 sr^-1, from the front side; a common extension, which Blender's
    OBJ importer reads as emission colour Ke / its largest channel and strength = that channel). No other term
    (no ``Ka``, ``Ks``, ``Ns``, ``illum``): a reader's defaults decide those (docs/external-renderers.md).

    A scene with textures: every vertex has a ``vt`` = (u, 1 - v) (OBJ's v points up; Mitsuba's OBJ loader flips it
    back) of Mitsuba's coordinates (:func:`textured_mesh`) mapped by the ``to_uv`` of the texture the shape's
    ``map_Kd`` shows, faces ``v/vt``; a base colour texture MTL carries (:func:`carried_texture`) is ``map_Kd
    textures/texture-<name>.png`` (the codes the scene holds, added to ``files``) with ``Kd`` its factor (1 for a
    diffuse material: MTL multiplies the two).

    Shading normals: a smooth-shaded shape (:func:`smooth_normals`) has one ``vn`` per vertex (its world-space
    vertex normal, full precision) and faces ``v/vt/vn`` (``v//vn`` without textures); a flat one has no ``vn``, as
    before. A normal map MTL can hold (:func:`obj_normal_map`) is ``norm textures/texture-<name>-green-up.png`` (the
    codes with the green inverted, :func:`green_up`; the extension three.js, assimp and tinyobjloader read).
    """
    obj = [f"# {scene.name}: exported by rendering-harness (harness export)", f"mtllib {mtl_name}"]
    mtl = [f"# {scene.name}: materials exported by rendering-harness (harness export)"]
    names: dict[tuple, str] = {}
    taken_mtl: set[str] = set()
    taken_obj: set[str] = set()
    textured = bool(scene.used_textures)
    offset = normal_offset = 1
    for shape in scene.shapes:
        material = scene.materials[shape.material]
        carried = carried_texture(material)
        key = (shape.material, tuple(shape.emission) if shape.is_emitter else None)
        if key not in names:
            base = safe_name(shape.material) + (f"-emit-{safe_name(shape.name)}" if shape.is_emitter else "")
            names[key] = _unique(base, taken_mtl)
            factors, _ = gltf_material(exported_material(material))
            mtl += ["", f"newmtl {names[key]}", "Kd " + " ".join(map(_mtl_number, factors["baseColorFactor"][:3]))]
            if carried is not None:
                path = export_path(carried)
                if files is not None:
                    files[path] = encode_png(carried.image)
                mtl.append(f"map_Kd {path}")
            normal = obj_normal_map(material)
            if normal is not None:
                path = obj_normal_map_path(normal)
                if files is not None:
                    files[path] = encode_png(green_up(normal.image))
                mtl.append(f"norm {path}")
            if shape.is_emitter:
                mtl.append("Ke " + " ".join(map(_mtl_number, shape.emission)))
        if textured:
            vertices, triangles, uv = textured_mesh(shape)
            if carried is not None:
                uv = mapped_uv(uv, carried.to_uv)
        else:
            (vertices, triangles), uv = shape_triangles(shape), None
        normals = smooth_normals(scene, shape, vertices, triangles)
        obj += ["", f"o {_unique(safe_name(shape.name), taken_obj)}", f"usemtl {names[key]}"]
        obj += [f"v {_mtl_number(x)} {_mtl_number(y)} {_mtl_number(z)}" for x, y, z in np.asarray(vertices, np.float64)]
        if uv is not None:
            obj += [f"vt {_mtl_number(u)} {_mtl_number(1.0 - v)}" for u, v in np.asarray(uv, np.float64)]
        if normals is not None:
            obj += [f"vn {_mtl_number(x)} {_mtl_number(y)} {_mtl_number(z)}" for x, y, z in normals]
        corners = np.asarray(triangles, np.int64) + offset  # v and vt: one each per vertex
        if normals is None:
            form = "{0}" if uv is None else "{0}/{0}"
            normal_index = corners
        else:
            form = "{0}//{1}" if uv is None else "{0}/{0}/{1}"
            normal_index = np.asarray(triangles, np.int64) + normal_offset
            normal_offset += len(normals)
        obj += ["f " + " ".join(form.format(a, n) for a, n in zip(row, rown))
                for row, rown in zip(corners, normal_index)]
        offset += len(vertices)
    return "\n".join(obj) + "\n", "\n".join(mtl) + "\n"


def obj_normal_map(material):
    """The normal map MTL's ``norm`` holds for ``material``: its 8-bit normal map (:func:`carried_normal_map`) where
    the reader's tangent frame, which it derives from the ``vt`` (OBJ has no tangents), runs along Mitsuba's: the
    map's ``to_uv`` is the one the ``vt`` are mapped by (the ``map_Kd`` texture's, else the identity) and it only
    scales (by positive factors) and translates, so dp/du' keeps the direction of Mitsuba's dp/du. Else None (a
    loss, :func:`export_losses`)."""
    texture = carried_normal_map(material)
    if texture is None:
        return None
    carried = carried_texture(material)
    to_uv = np.asarray(texture.to_uv, np.float64)
    if not np.array_equal(to_uv, np.eye(3) if carried is None else np.asarray(carried.to_uv, np.float64)):
        return None
    (a, b), (c, d) = to_uv[:2, :2]
    return texture if b == 0.0 and c == 0.0 and a > 0.0 and d > 0.0 else None


def obj_normal_map_path(texture) -> str:
    """The file of MTL's ``norm``: ``textures/texture-<name>-green-up.png`` (:func:`green_up` of the codes)."""
    return export_path(texture).removesuffix(".png") + "-green-up.png"


def green_up(codes: np.ndarray) -> np.ndarray:
    """A normal map's 8-bit codes with the green channel inverted (255 - G: y = 2 G / 255 - 1 becomes -y), for an
    OBJ reader, whose bitangent follows the ``vt``'s v, which points up (OpenGL's convention: three.js derives it so,
    MikkTSpace picks its sign so): on a triangle whose coordinates Mitsuba sees unmirrored ((dp/du x dp/dv) . n > 0,
    v down: rectangles, a mesh's own), Mitsuba's t = n x s points along its +v, toward the image's bottom, and such
    a reader's bitangent the other way. On a mirrored triangle (a cube's faces) the two agree, and the inversion
    is wrong there (a loss naming the shapes)."""
    out = np.array(codes, copy=True)
    out[..., 1] = 255 - out[..., 1]
    return out


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
    if scene.media and fmt in ("ply", "obj", "gltf"):
        losses.append(f"{fmt} has no participating media: left out media " + ", ".join(
            f"{m.name} ({m.type})" for m in scene.media.values()))
    if fmt == "gltf":
        lost = [e for e in scene.emitters if not _in_gltf(e)]
        if lost:
            losses.append(f"glTF 2.0 has no environment light: left out {names(lost)} (KHR_lights_punctual has "
                          "point, spot and directional lights only)")
        losses += _gltf_material_losses(glossy)
    if fmt in ("gltf", "obj"):
        losses += _texture_losses(scene, fmt)
        losses += _shading_losses(scene, fmt)
    return losses


def _uv_handedness(shape) -> np.ndarray:
    """The sign of each triangle's du_1 dv_2 - dv_1 du_2 in Mitsuba's (untransformed) coordinates
    (:func:`textured_mesh`): +1 where (dp/du x dp/dv) . n > 0 (unmirrored, v down), -1 mirrored, 0 degenerate."""
    _vertices, triangles, uv = textured_mesh(shape)
    c = np.asarray(uv, np.float64)[triangles]
    return np.sign((c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1])
                   - (c[:, 1, 1] - c[:, 0, 1]) * (c[:, 2, 0] - c[:, 0, 0]))


class _Lost:
    """The items of each kind of loss an export names, in the order first met, each once."""

    def __init__(self) -> None:
        self.items: dict[str, list[str]] = {}

    def add(self, kind: str, text: str) -> None:
        items = self.items.setdefault(kind, [])
        if text not in items:
            items.append(text)

    def lines(self, messages: dict[str, str]) -> list[str]:
        """One line per kind met: its message with the items in place of ``{}``."""
        return [messages[kind].format(", ".join(items)) for kind, items in self.items.items()]


def _shading_losses(scene: Scene, fmt: str) -> list[str]:
    """What glTF (``fmt`` "gltf") or OBJ/MTL ("obj") cannot say exactly of the scene's normal and bump maps, one line
    per kind of loss naming the textures, materials and shapes (docs/external-renderers.md, "Shading normals").
    (A ``bumpmap`` entry for :data:`harness.scene.kinds.materials.GLTF_LOSSES` would serve glTF's first line.)"""
    gltf = fmt == "gltf"
    where = "glTF" if gltf else "MTL"
    lost = _Lost()
    add = lost.add

    for material in scene.materials.values():
        p = material.perturbation
        if p is None:
            continue
        label = f"{p.texture.name} ({material.name})"
        if p.type == "bumpmap":
            add("bump", f"{p.texture.name} ({material.name}, scale {float(p.scale)!r})")
            continue
        if p.flip_invalid_normals or p.use_shadowing_function:
            add("terminator", label)
        if carried_normal_map(material) is None:
            add("float", label)
        elif gltf and gltf_uv_transform(p.texture.to_uv) is None:
            add("shear", label)
        elif not gltf and obj_normal_map(material) is None:
            add("to_uv", label)
        elif not gltf:
            add("frame", label)
            if (p.texture.filter_type, p.texture.wrap_mode) != ("bilinear", "repeat"):
                add("sampler", f"{p.texture.name} ({p.texture.filter_type}, {p.texture.wrap_mode})")
    for shape in scene.shapes:
        material = scene.materials[shape.material]
        if (obj_normal_map(material) if not gltf else carried_normal_map(material)) is None:
            continue
        if gltf and smooth_normals(scene, shape, *shape_triangles(shape)) is not None:
            add("interpolated", shape.name)
        if not gltf and np.any(_uv_handedness(shape) <= 0):
            add("mirrored", shape.name)
    messages = {
        "bump": f"{where} has no bump map: bump map(s) {{}} left out (the material is written as the one it "
                "wraps, unperturbed" + (")" if gltf else "; MTL's bump is a height to three.js, assimp and "
                                        "tinyobjloader but a normal map to Blender, with no common scale)"),
        "terminator": f"{where} has no shadow terminator and no flip of invalid normals: normal map(s) {{}} shade "
                      "without Mitsuba's use_shadowing_function (Estevez's G) and flip_invalid_normals",
        "float": f"{where}'s normal map here is an 8-bit PNG: float (EXR) normal map(s) {{}} left out",
        "shear": "KHR_texture_transform has no shear: to_uv of normal map(s) {} left out (read at Mitsuba's "
                 "untransformed coordinates)",
        "to_uv": "MTL has no texture transform of its own: normal map(s) {} left out (their to_uv is not the "
                 "scale and offset the vt carry)",
        "frame": "OBJ has no tangents: normal map(s) {} written as MTL norm (read by three.js, assimp and "
                 "tinyobjloader; Blender reads normal maps from map_Bump only) with the green channel inverted "
                 "(textures/*-green-up.png) for a reader whose bitangent follows vt's v, up; the reader derives "
                 "the tangent frame from the vt, Mitsuba's (s = dp/du made perpendicular to n, t = n x s) on a "
                 "flat, unmirrored triangle where its bitangent is n x s up to sign (MikkTSpace's) and its "
                 "tangent not averaged with other triangles'",
        "sampler": "MTL has no filter or wrap mode: normal map {} is filtered and wrapped as the reader's default",
        "mirrored": "the inverted green of MTL's norm gives Mitsuba's normal only where the texture coordinates "
                    "are unmirrored: shape(s) {} have mirrored or degenerate triangles, on which a reader sees the "
                    "map's green inverted against Mitsuba's",
        "interpolated": "glTF interpolates TANGENT across a triangle: the smooth-shaded normal-mapped shape(s) {} "
                        "carry Mitsuba's tangent at each corner (vertices split between triangles), where Mitsuba "
                        "makes the triangle's dp/du perpendicular to the interpolated normal in between",
    }
    return lost.lines(messages)


def _texture_losses(scene: Scene, fmt: str) -> list[str]:
    """What glTF (``fmt`` "gltf") or OBJ/MTL ("obj") cannot say exactly of the scene's textures, one line per kind of
    loss naming the textures (and materials, shapes) it applies to (docs/external-renderers.md)."""
    gltf = fmt == "gltf"
    where = "glTF" if gltf else "MTL"
    slot = "baseColorTexture" if gltf else "map_Kd"
    lost = _Lost()
    add = lost.add

    for material in scene.materials.values():
        base = base_colour_parameter(material)
        for item, texture in material.textures:
            label = f"{texture.name} ({material.name}.{item})"
            if item != base:
                add("parameter", label)
            elif texture.type == "checkerboard":
                add("checkerboard", label)
            elif texture.image.dtype != np.uint8:
                add("float", label)
            elif texture.raw:
                add("raw", label)
            elif gltf and gltf_uv_transform(texture.to_uv) is None:
                add("shear", texture.name)
            elif not gltf and (texture.filter_type, texture.wrap_mode) != ("bilinear", "repeat"):
                add("sampler", f"{texture.name} ({texture.filter_type}, {texture.wrap_mode})")
    carried = {m.name for m in scene.materials.values() if carried_texture(m) is not None}
    spheres = [s.name for s in scene.shapes if s.material in carried and SHAPES[s.type].sphere is not None]
    messages = {
        "checkerboard": f"{where} has no procedural textures: checkerboard {{}} written as the mean colour "
                        "(color0 + color1) / 2 of each",
        "float": f"{where}'s {slot} here is an 8-bit sRGB PNG: float (EXR) texture {{}} written as the mean "
                 "value of each",
        "raw": f"{where}'s {slot} is decoded as sRGB: raw texture {{}} (code / 255) written as the "
               "mean value of each",
        "parameter": f"{where} has a texture for the base colour only: {{}} left out",
        "shear": "KHR_texture_transform has no shear: to_uv of {} left out (the texture is read at Mitsuba's "
                 "untransformed coordinates)",
        "sampler": "MTL has no filter or wrap mode: texture {} is filtered and wrapped as the reader's default "
                   "(usually bilinear, repeat)",
    }
    losses = lost.lines(messages)
    glowing = [f"{s.name} ({s.emission_texture.name})" for s in scene.shapes
               if getattr(s, "emission_texture", None) is not None]
    if glowing:
        losses.append(f"the {fmt} export carries no emission texture: light(s) {', '.join(glowing)} written with "
                      "the texture's mean radiance")
    if spheres:
        losses.append(f"{'glTF' if gltf else 'OBJ'} has no analytic sphere: the textured icosphere(s) "
                      f"{', '.join(spheres)} carry Mitsuba's texture coordinates at their vertices (seam and poles "
                      "split), interpolated across each facet where Mitsuba's are exact at every point; a wrap mode "
                      "other than repeat differs on the facets across the seam")
    return losses


def _gltf_material_losses(glossy) -> list[str]:
    """What glTF's metallic-roughness model and its extensions cannot say exactly of the non-diffuse materials: one
    line per loss of :data:`harness.scene.kinds.materials.GLTF_LOSSES` that some of them have (their type's
    ``gltf_losses``)."""
    losses = []
    for loss, message in GLTF_LOSSES.items():
        materials = [m for m in glossy if loss in ALL_MATERIALS[m.type].gltf_losses(m)]
        if materials:
            losses.append(message.format(materials=", ".join(f"{m.name} ({m.type})" for m in materials)))
    return losses


def scene_files(scene: Scene, fmt: str, *, spp: int = 16, seed: int = 0) -> dict[str, bytes]:
    """The files of ``scene`` in format ``fmt`` (one of :data:`FORMATS`), ``{relative path: bytes}``, the main file
    first (``spp`` and ``seed``: the defaults of the Mitsuba XML's ``$spp`` and ``$seed``)."""
    if fmt not in FORMATS:
        raise HarnessError("--format", f"expected one of {', '.join(FORMATS)}, got {fmt!r}")
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
        textures: dict[str, bytes] = {}
        obj, mtl = obj_text(scene, mtl_name="scene.mtl", files=textures)
        files["scene.obj"] = obj.encode("utf-8")
        files["scene.mtl"] = mtl.encode("utf-8")
        files.update(textures)
    else:
        textures = {}
        document, buffer = gltf_document(scene, buffer_name="scene.bin", files=textures)
        files["scene.gltf"] = json.dumps(document, separators=(",", ":"), allow_nan=False).encode("utf-8")
        if buffer:
            files["scene.bin"] = buffer
        files.update(textures)
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
