"""The shape types of ``[[shapes]]`` (Mitsuba's shape plugins of the same names, docs/scene-format.md, "Shapes"), one
:class:`ShapeKind` each in :data:`SHAPES`: the keys of its type alone and their reading, its triangles in object space
and its placement, how Mitsuba takes it and its scene.json entry."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from harness.scene.model import SHAPE_TYPES, Shape
from harness.scene.primitives import (cube_uv, rectangle_uv, scale_matrix, translate_matrix, unit_cube, unit_rectangle,
                                      unit_sphere)

DEFAULT_SUBDIVISIONS = 3  # icosphere with 1280 triangles
MAX_SUBDIVISIONS = 7  # 327 680 triangles


@dataclass(frozen=True)
class ShapeKind:
    """One shape type.

    Attributes
    ----------
    name : str
        The ``type`` value (Mitsuba's plugin name; a mesh is Mitsuba's ``ply`` or ``obj``).
    keys : tuple of str
        The keys of this type alone (the keys every shape takes are :data:`harness.scene.load.SHAPE_KEYS`).
    read : callable
        ``read(reader, table, key) -> dict``: the :class:`~harness.scene.model.Shape` fields of those keys, read with
        the scene reader's typed readers (``reader``: :class:`harness.scene.load._SceneReader`).
    object_mesh : callable
        ``object_mesh(shape) -> (vertices, triangles)``: its triangles in object space, facing its front side.
    analytic : bool
        Mitsuba has it as a plugin of the same name placed by a ``to_world`` (otherwise: its triangles).
    keeps_front_when_mirrored : bool
        Mitsuba keeps its front side under a mirroring placement (it transforms the normals by the inverse
        transpose); the others swap sides with the winding (docs/scene-format.md, "Orientation").
    similarity_only : bool
        Its placement may only rotate, scale uniformly and translate (Mitsuba's sphere).
    sphere : callable, optional
        ``sphere(shape) -> (centre, radius)`` in world space, for a type that is a sphere exactly.
    json : callable
        ``json(shape) -> dict``: the parameters of its type in the scene.json entry.
    object_uv : callable, optional
        ``object_uv(shape, vertices) -> (V, 2) or None``: Mitsuba's texture coordinates at the vertices of its
        ``object_mesh`` (None: a mesh file without them); None where they are analytic (a sphere's,
        :attr:`sphere`).
    """

    name: str
    keys: tuple[str, ...]
    read: Callable[[Any, dict, str], dict]
    object_mesh: Callable[[Shape], tuple[np.ndarray, np.ndarray]]
    analytic: bool = True
    keeps_front_when_mirrored: bool = False
    similarity_only: bool = False
    sphere: Callable[[Shape], tuple[np.ndarray, float]] | None = None
    json: Callable[[Shape], dict] = lambda shape: {}
    object_uv: Callable[[Shape, np.ndarray], np.ndarray | None] | None = None

    def object_to_world(self, shape: Shape) -> np.ndarray:
        """The full 4x4 object-to-world matrix of ``shape`` (a sphere's: to_world @ T(center) @ S(radius))."""
        if self.sphere is None:
            return shape.to_world
        return shape.to_world @ translate_matrix(shape.center) @ scale_matrix(shape.radius)


def _read_sphere(reader, table: dict, key: str) -> dict[str, Any]:
    center = reader.vector3(table.get("center", [0.0, 0.0, 0.0]), f"{key}.center")
    radius = reader.number(table.get("radius", 1.0), f"{key}.radius", "a finite number > 0")
    if radius <= 0:
        raise reader.expected(f"{key}.radius", "a finite number > 0", table["radius"])
    what = f"an integer from 0 to {MAX_SUBDIVISIONS}"
    subdivisions = reader.integer(table.get("subdivisions", DEFAULT_SUBDIVISIONS), f"{key}.subdivisions", what)
    if not 0 <= subdivisions <= MAX_SUBDIVISIONS:
        raise reader.expected(f"{key}.subdivisions", what, subdivisions)
    return {"center": center, "radius": radius, "subdivisions": subdivisions}


def _world_sphere(shape: Shape) -> tuple[np.ndarray, float]:
    matrix = SHAPES["sphere"].object_to_world(shape)
    return matrix[:3, 3], float(np.linalg.norm(matrix[:3, 0]))


def _sphere_json(shape: Shape) -> dict:
    centre, radius = _world_sphere(shape)
    return {"center": np.asarray(centre, dtype=np.float64).tolist(), "radius": radius,
            "subdivisions": int(shape.subdivisions)}


#: Every shape type by its name, in :data:`harness.scene.model.SHAPE_TYPES`'s order.
SHAPES: dict[str, ShapeKind] = {kind.name: kind for kind in (
    ShapeKind("rectangle", (), lambda reader, table, key: {}, lambda shape: unit_rectangle(),
              keeps_front_when_mirrored=True, object_uv=lambda shape, vertices: rectangle_uv(vertices)),
    ShapeKind("cube", (), lambda reader, table, key: {}, lambda shape: unit_cube(), keeps_front_when_mirrored=True,
              object_uv=lambda shape, vertices: cube_uv(vertices)),
    ShapeKind("sphere", ("center", "radius", "subdivisions"), _read_sphere,
              lambda shape: unit_sphere(shape.subdivisions), similarity_only=True,
              sphere=_world_sphere, json=_sphere_json),
    ShapeKind("mesh", ("file", "flip_tex_coords", "face_normals"), lambda reader, table, key: reader.mesh(table, key),
              lambda shape: (shape.mesh_vertices, shape.mesh_triangles), analytic=False,
              object_uv=lambda shape, vertices: shape.mesh_uv),
)}
assert tuple(SHAPES) == SHAPE_TYPES
#: The keys of one type alone, the mesh's first (the order in which a misplaced one is reported).
ONE_TYPE_KEYS = tuple(dict.fromkeys(key for kind in reversed(SHAPES.values()) for key in kind.keys))
