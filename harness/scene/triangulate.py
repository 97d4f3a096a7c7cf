"""Turn a :class:`Scene` into the flat triangle arrays of :class:`reference_impl.geometry.Geometry`.

Orientation rules (see ``docs/scene-format.md``, "Orientation"): every triangle is wound so that
``cross(v1 - v0, v2 - v0)`` points to its front side, the side a one-sided material reflects on and a light emits
from. Unit shapes are those of Mitsuba: the rectangle [-1, 1]^2 at z = 0 facing +z, the cube [-1, 1]^3 and the
sphere facing outward.

Under a mirroring placement (negative determinant) we follow what Mitsuba 3 does (checked by rendering with
Mitsuba 3.9.1): its rectangle and cube keep their front side (their normals are transformed by the inverse
transpose), so their winding is reversed there; its sphere and meshes without vertex normals (or with
``face_normals = true``) swap sides, which is just the winding as transformed. ``flip_normals`` reverses the
winding once more.
"""

from __future__ import annotations


import numpy as np

from reference_impl.errors import SettingsError
from reference_impl.geometry import Geometry

from harness.core.errors import HarnessError
from harness.scene.kinds.shapes import SHAPES
from harness.scene.model import Scene, Shape
from harness.scene.primitives import (  # noqa: F401 (the transforms and unit shapes, importable from here)
    frame_to_world,
    icosphere,
    is_similarity,
    rotate_matrix,
    scale_matrix,
    translate_matrix,
    unit_cube,
    unit_rectangle,
    unit_sphere,
)

# --------------------------------------------------------------------------------------------------------------------
# Shapes to world-space triangles.


def object_to_world(shape: Shape) -> np.ndarray:
    """The full 4x4 object-to-world matrix of a shape (for spheres: to_world @ T(center) @ S(radius))."""
    return SHAPES[shape.type].object_to_world(shape)


def object_mesh(shape: Shape) -> tuple[np.ndarray, np.ndarray]:
    """The shape's vertices and triangles in object space (before ``object_to_world``)."""
    return SHAPES[shape.type].object_mesh(shape)


def reverses_winding(shape: Shape) -> bool:
    """True if the shape's transformed triangles must be wound the other way round to face its front side."""
    mirrored = np.linalg.det(object_to_world(shape)[:3, :3]) < 0
    return bool(mirrored and SHAPES[shape.type].keeps_front_when_mirrored) != bool(shape.flip_normals)


def shape_triangles(shape: Shape) -> tuple[np.ndarray, np.ndarray]:
    """World-space vertices (V, 3) and triangles (T, 3) of one shape, wound to face its front side."""
    vertices, triangles = object_mesh(shape)
    matrix = object_to_world(shape)
    with np.errstate(all="ignore"):
        world = vertices @ matrix[:3, :3].T + matrix[:3, 3]
    triangles = np.array(triangles, dtype=np.int64)
    if reverses_winding(shape):
        triangles = triangles[:, [0, 2, 1]]
    return world, triangles


def vertex_uv(shape: Shape) -> np.ndarray | None:
    """Mitsuba's texture coordinates at the vertices of :func:`shape_triangles` (V, 2), or None for a shape whose
    coordinates are analytic (a sphere's) or that has none (a mesh file without them)."""
    kind = SHAPES[shape.type]
    if kind.object_uv is None:
        return None
    return kind.object_uv(shape, np.asarray(object_mesh(shape)[0], dtype=np.float64))


def shape_uv(shape: Shape, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The texture coordinates at the corners of the shape's ``triangles`` (as :func:`shape_triangles` wound them),
    (T, 3, 2), and for a sphere the inverse of its object-to-world matrix (its coordinates are analytic, the corners'
    0), else None. A shape without coordinates (a mesh) has 0 everywhere."""
    if SHAPES[shape.type].sphere is not None:
        return np.zeros((len(triangles), 3, 2)), np.linalg.inv(object_to_world(shape))
    uv = vertex_uv(shape)
    return (np.zeros((len(triangles), 3, 2)) if uv is None else uv[triangles]), None


def vertex_normals(shape: Shape, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray | None:
    """The unit vertex normals (V, 3) of the shape's world ``vertices`` and ``triangles`` (:func:`shape_triangles`),
    as Mitsuba 3.9.1 gives a mesh (``mesh.cpp``, docs/mitsuba.md "Shading normals"), or None where it shades flat
    (``face_normals = true``, rectangles, cubes, spheres).

    The file's normals: normalize(M^-T n), negated by ``flip_normals``. A file without normals: angle-weighted
    normals of the triangles as wound (Thuermer and Wuethrich 1998), N_v = normalize(sum_f alpha_f(v) N_f), alpha_f(v)
    the triangle's interior angle at v, degenerate triangles skipped, (1, 0, 0) where the sum is zero."""
    if shape.type != "mesh" or shape.face_normals:
        return None
    if shape.mesh_normals is not None:
        with np.errstate(all="ignore"):
            normals = shape.mesh_normals @ np.linalg.inv(object_to_world(shape)[:3, :3])
        normals = -normals if shape.flip_normals else normals
    else:
        normals = np.zeros_like(vertices)
        corners = vertices[triangles]
        with np.errstate(all="ignore"):
            face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
            length = np.linalg.norm(face, axis=1)
            good = length > 0
            face = face[good] / length[good, None]
            for i in range(3):
                a = corners[good, (i + 1) % 3] - corners[good, i]
                b = corners[good, (i + 2) % 3] - corners[good, i]
                cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
                angle = np.arccos(np.clip(np.nan_to_num(cos), -1.0, 1.0))
                np.add.at(normals, triangles[good, i], angle[:, None] * face)
    length = np.linalg.norm(normals, axis=1)
    zero = ~(length > 0) | ~np.isfinite(length)
    normals[zero] = (1.0, 0.0, 0.0)
    length[zero] = 1.0
    return normals / length[:, None]


def exported_normals(scene: Scene, shape: Shape, vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray | None:
    """The unit vertex normals (V, 3) a shape's triangles are written with where they leave the harness (scene.json's
    PLY ``nx, ny, nz``, glTF ``NORMAL``, OBJ ``vn``): :func:`vertex_normals`, and for a sphere whose material is not
    diffuse its analytic normal at each icosphere vertex (the vertex's direction from the centre, toward the front
    side), so that a mirror or glass ball taken as its mesh shows no facets; None for a shape shaded flat, a diffuse
    sphere and every emitting shape (lights are flat). A diffuse sphere stays flat: its facets change its shading
    little, and radial normals on them darken it (directions the shading hemisphere admits below a facet's plane
    enter the sphere: the white furnace 1.5e-4 dark, in the reference once and in Cycles, where the flat icosphere is
    exact)."""
    if shape.is_emitter:
        return None
    sphere = SHAPES[shape.type].sphere
    if sphere is None:
        return vertex_normals(shape, vertices, triangles)
    if scene.materials[shape.material].is_diffuse:
        return None
    center = object_to_world(shape)[:3, 3]
    radial = vertices - center
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    corners = vertices[triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    inward = float(np.sum(np.einsum("ij,ij->i", face, corners.mean(axis=1) - center))) < 0  # as Geometry's
    return -radial if inward else radial


#: The largest angle (radians) between a corner's vertex normal and its triangle's normal at which a light is still
#: shaded flat (its vertex normals those of its planar pieces, up to the file's rounding).
FLAT_ANGLE = 1e-4


def emitter_shades_flat(shape: Shape) -> bool:
    """Whether the shape's vertex normals (:func:`vertex_normals`) are its triangles' own normals at every corner
    (within :data:`FLAT_ANGLE`), or it has none: an area light the reference shades flat."""
    if shape.type != "mesh" or shape.face_normals:  # no vertex normals (vertex_normals): nothing to triangulate
        return True
    vertices, triangles = shape_triangles(shape)
    normals = vertex_normals(shape, vertices, triangles)
    if normals is None:
        return True
    corners = vertices[triangles]
    with np.errstate(all="ignore"):
        face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        face /= np.linalg.norm(face, axis=1, keepdims=True)
    good = np.all(np.isfinite(face), axis=1)
    cos = np.einsum("tij,tj->ti", normals[triangles[good]], face[good])
    return bool(np.all(cos >= np.cos(FLAT_ANGLE)))


def triangle_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area of each triangle."""
    corners = vertices[triangles]
    with np.errstate(all="ignore"):
        return 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)


def _joined(parts: list[np.ndarray], empty):
    """The shapes' arrays end to end: ``np.concatenate(parts)``, the one array itself where there is one (every
    part is an array made here, so nothing else holds it; a scene of one 10 M-triangle mesh saves a copy of each
    table, 0.7 GiB of its corners' normals alone), ``empty`` where there is none."""
    if not parts:
        return empty
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def triangulate(scene: Scene) -> Geometry:
    """All shapes of ``scene`` as one :class:`Geometry`.

    Materials are numbered in the order ``scene.materials`` defines them; emissive shapes become lights 0 .. N_L - 1
    in shape order, and all triangles of one emissive shape share its light id and emission.
    """
    material_index = {name: i for i, name in enumerate(scene.materials)}
    used = scene.used_textures
    texture_index = {id(texture): k for k, texture in enumerate(used)}
    textured = bool(used)
    # texture coordinates where a hit reads them: a texture, or an anisotropic lobe's frame (dp/du)
    coordinates = textured or any(m.needs_coordinates for m in scene.materials.values())
    emission_texture = []
    all_vertices, all_triangles, material, emission, light_id = [], [], [], [], []
    uv, sphere_of, sphere_to_object = [], [], []
    normals = []
    vertex_count = 0
    next_light = 0
    for shape in scene.shapes:
        vertices, triangles = shape_triangles(shape)
        count = len(triangles)
        all_vertices.append(vertices)
        all_triangles.append(triangles + vertex_count if vertex_count else triangles)  # a fresh array either way
        vertex_count += len(vertices)
        material.append(np.full(count, material_index[shape.material]))
        shading = None if shape.is_emitter else vertex_normals(shape, vertices, triangles)  # lights: flat (load)
        normals.append(np.zeros((count, 3, 3)) if shading is None else shading[triangles])
        corners_uv, sphere = shape_uv(shape, triangles)
        if coordinates:
            uv.append(corners_uv)
        if sphere is not None:
            sphere_to_object.append(sphere)
        sphere_of.append(np.full(count, len(sphere_to_object) - 1 if sphere is not None else -1))
        emission_texture.append(np.full(count, texture_index.get(id(shape.emission_texture), -1)))
        if shape.is_emitter:
            emission.append(np.tile(np.asarray(shape.emission, dtype=np.float64), (count, 1)))
            light_id.append(np.full(count, next_light))
            next_light += 1
        else:
            emission.append(np.zeros((count, 3)))
            light_id.append(np.full(count, -1))

    materials = list(scene.materials.values())
    try:
        return Geometry(
            vertices=_joined(all_vertices, np.zeros((0, 3))),
            triangles=_joined(all_triangles, np.zeros((0, 3), dtype=np.int64)),
            material=_joined(material, np.zeros(0, dtype=np.int64)),
            reflectance=np.array([m.reflectance for m in materials], dtype=np.float64).reshape(-1, 3),
            two_sided=np.array([m.two_sided for m in materials], dtype=bool),
            emission=_joined(emission, np.zeros((0, 3))),
            light_id=_joined(light_id, np.zeros(0, dtype=np.int64)),
            uv=_joined(uv, None),
            sphere_of=_joined(sphere_of, None) if sphere_to_object else None,
            sphere_to_object=np.array(sphere_to_object).reshape(-1, 4, 4) if sphere_to_object else None,
            emission_texture=_joined(emission_texture, None) if textured else None,
            normals=_joined(normals, None) if any(np.any(n) for n in normals) else None,
        )
    except SettingsError as err:
        raise HarnessError(str(scene.path), f"cannot triangulate the scene: {err}") from err
