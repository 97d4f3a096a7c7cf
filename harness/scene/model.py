"""The in-memory form of a scene file (see ``docs/scene-format.md``): plain, validated, immutable records.

:func:`harness.scene.load_scene` builds these from a TOML file; :func:`harness.scene.triangulate` turns them into the
flat triangle arrays of :class:`reference_impl.geometry.Geometry`; renderer adapters read them directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from reference_impl.camera import Camera, Film

SHAPE_TYPES = ("rectangle", "cube", "sphere", "mesh")

Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class Material:
    """A Lambertian BRDF f_r = reflectance / pi (Mitsuba's ``diffuse``).

    ``two_sided = False`` reflects on the front side of a surface only (the back side is black), like Mitsuba's
    ``diffuse``; ``True`` reflects on both sides (Mitsuba's ``twosided`` wrapper).
    """

    name: str
    reflectance: Vector3
    two_sided: bool = False


@dataclass(frozen=True, eq=False)
class Shape:
    """One ``[[shapes]]`` entry.

    Attributes
    ----------
    index : int
        Position in the file's ``shapes`` array (0-based); error messages call it ``shapes[index]``.
    name : str
        The ``name`` key, or ``"shape<index>"`` when absent.
    type : str
        One of :data:`SHAPE_TYPES`.
    material : str
        Name of a key of :attr:`Scene.materials`.
    to_world : (4, 4) float64
        The placement, row-major, applied to column vectors (p' = M p): either the file's ``to_world`` or
        Translate @ Rotate @ Scale built from ``translate`` / ``rotate`` / ``scale`` (identity if none is given).
        For spheres it does *not* include ``center`` / ``radius``: the sphere's object-to-world matrix is
        ``to_world @ translate(center) @ scale(radius)``, as in Mitsuba.
    emission : (r, g, b) or None
        Radiance emitted from the front side; None for shapes that do not emit.
    flip_normals : bool
        Mitsuba's ``flip_normals``: swap the front and back sides.
    file : Path or None
        Meshes only: the absolute path of the PLY / OBJ file.
    center, radius, subdivisions :
        Spheres only (other shapes keep the defaults): the sphere in its own space, and the number of icosphere
        subdivisions used when triangulating it.
    mesh_vertices, mesh_triangles : ndarray or None
        Meshes only: the file's vertices (V, 3) and triangles (T, 3) in object space, as read at load time.
    """

    index: int
    name: str
    type: str
    material: str
    to_world: np.ndarray
    emission: Vector3 | None = None
    flip_normals: bool = False
    file: Path | None = None
    center: Vector3 = (0.0, 0.0, 0.0)
    radius: float = 1.0
    subdivisions: int = 3
    mesh_vertices: np.ndarray | None = None
    mesh_triangles: np.ndarray | None = None

    @property
    def is_emitter(self) -> bool:
        """True if the shape is an area light."""
        return self.emission is not None


@dataclass(frozen=True, eq=False)
class Scene:
    """A whole scene file.

    ``materials`` keeps the file's order (``Geometry.material`` indexes materials in that order); ``shapes`` keeps
    the file's order (light ids number the emissive shapes in that order). ``path`` is the scene file's path as it
    was given to :func:`load_scene`. ``closed_form`` names a known analytic solution of the scene ("furnace"), or
    None.
    """

    name: str
    description: str
    camera: Camera
    film: Film
    max_depth: int
    materials: dict[str, Material]
    shapes: list[Shape]
    path: Path
    closed_form: str | None = None

    @property
    def lights(self) -> list[Shape]:
        """The emissive shapes, in light-id order (light k is ``lights[k]``)."""
        return [shape for shape in self.shapes if shape.is_emitter]
