"""4x4 transforms (row-major, applied to column vectors: p' = M p, the same matrices as Mitsuba's Transform4f) and
Mitsuba's unit shapes in object space, front side = cross(v1 - v0, v2 - v0): the rectangle [-1, 1]^2 at z = 0 facing
+z, the cube [-1, 1]^3 and the sphere facing outward."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np


# --------------------------------------------------------------------------------------------------------------------
# 4x4 transforms (row-major, applied to column vectors: p' = M p), the same matrices as Mitsuba's Transform4f.


def translate_matrix(offset) -> np.ndarray:
    """The 4x4 matrix that moves points by ``offset`` (3 numbers)."""
    matrix = np.eye(4)
    matrix[:3, 3] = np.asarray(offset, dtype=np.float64)
    return matrix


def scale_matrix(factors) -> np.ndarray:
    """The 4x4 matrix that scales by one number or by 3 per-axis factors."""
    return np.diag([*np.broadcast_to(np.asarray(factors, dtype=np.float64), (3,)), 1.0])


def rotate_matrix(axis, angle_degrees: float) -> np.ndarray:
    """Right-handed rotation by ``angle_degrees`` about ``axis`` (normalised here), Rodrigues' formula.

    Matches Mitsuba's ``Transform4f.rotate(axis / |axis|, angle)`` (Mitsuba itself does not normalise the axis).
    ``axis`` must not be the zero vector.
    """
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    theta = math.radians(angle_degrees)
    cos, sin = math.cos(theta), math.sin(theta)
    cross_matrix = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    matrix = np.eye(4)
    matrix[:3, :3] = cos * np.eye(3) + sin * cross_matrix + (1.0 - cos) * np.outer(k, k)
    return matrix


def frame_to_world(origin, axis) -> np.ndarray:
    """A 4x4 rigid transform whose local +z is the unit vector ``axis`` and whose origin is ``origin``; the other
    two axes by Duff et al. (2017), Mitsuba's ``coordinate_system`` (any choice gives a spot light the same cone)."""
    x, y, z = (float(v) for v in axis)
    sign = math.copysign(1.0, z)
    a = -1.0 / (sign + z)
    b = x * y * a
    s = np.array([1.0 + sign * x * x * a, sign * b, -sign * x])
    t = np.array([b, sign + y * y * a, -y])
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = s, t, (x, y, z), origin
    return matrix + 0.0  # no -0.0 entries


def is_similarity(linear: np.ndarray, tolerance: float = 1e-6) -> bool:
    """True if the 3x3 matrix is a rotation (or reflection) times a uniform scale."""
    with np.errstate(all="ignore"):
        gram = linear.T @ linear
        scale2 = np.trace(gram) / 3.0
        if not (np.isfinite(scale2) and scale2 > 0):
            return False
        return bool(np.max(np.abs(gram / scale2 - np.eye(3))) <= tolerance)


# --------------------------------------------------------------------------------------------------------------------
# Unit shapes in object space, front side = cross(v1 - v0, v2 - v0).


def unit_rectangle() -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's rectangle: [-1, 1]^2 at z = 0, two triangles facing +z."""
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    return vertices, triangles


def unit_cube() -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's cube: [-1, 1]^3, 12 triangles facing outward, each face with its own 4 vertices."""
    identity = np.eye(3)
    vertices, triangles = [], []
    for axis in range(3):
        for sign in (1.0, -1.0):
            normal = sign * identity[axis]
            # Tangents u, v with cross(u, v) = normal.
            u, v = identity[(axis + 1) % 3], identity[(axis + 2) % 3]
            if sign < 0:
                u, v = v, u
            first = len(vertices)
            vertices += [normal - u - v, normal + u - v, normal + u + v, normal - u + v]
            triangles += [[first, first + 1, first + 2], [first, first + 2, first + 3]]
    return np.array(vertices), np.array(triangles)


def rectangle_uv(vertices: np.ndarray) -> np.ndarray:
    """Mitsuba's texture coordinates of points (x, y, 0) of the unit rectangle: ((x + 1) / 2, (y + 1) / 2)."""
    return np.stack([(vertices[:, 0] + 1.0) / 2.0, (vertices[:, 1] + 1.0) / 2.0], axis=1)


def sphere_uv(points: np.ndarray) -> np.ndarray:
    """Mitsuba's analytic texture coordinates (``sphere.cpp``) at points p of a sphere in its own space, (N, 2):
    u = atan2(p_y, p_x) / (2 pi) mod 1, v = acos(p_z / |p|) / pi (the reference's kernel computes the same,
    ``reference_impl.kernels.surface.texture_coordinates``)."""
    points = np.asarray(points, dtype=np.float64)
    u = (np.arctan2(points[:, 1], points[:, 0]) / (2.0 * math.pi)) % 1.0
    v = np.arccos(np.clip(points[:, 2] / np.linalg.norm(points, axis=1), -1.0, 1.0)) / math.pi
    return np.stack([u, v], axis=1)


#: Mitsuba 3.9.1's cube (``cube.cpp``): per face (its outward normal), the texture coordinates (u, v) of a point
#: (x, y, z) of it, as (coefficient of x, y, z and constant) for u and for v; every corner of a face takes (0, 0),
#: (1, 0), (1, 1) or (0, 1) (measured by tracing Mitsuba's own cube).
CUBE_UV = {
    (1, 0, 0): ((0, 0.5, 0, 0.5), (0, 0, -0.5, 0.5)), (-1, 0, 0): ((0, 0.5, 0, 0.5), (0, 0, 0.5, 0.5)),
    (0, 1, 0): ((-0.5, 0, 0, 0.5), (0, 0, -0.5, 0.5)), (0, -1, 0): ((0, 0, 0.5, 0.5), (0.5, 0, 0, 0.5)),
    (0, 0, 1): ((0, 0.5, 0, 0.5), (0.5, 0, 0, 0.5)), (0, 0, -1): ((0, -0.5, 0, 0.5), (0.5, 0, 0, 0.5)),
}


def cube_uv(vertices: np.ndarray) -> np.ndarray:
    """The texture coordinates of :func:`unit_cube`'s vertices (each face's four in turn), Mitsuba's (:data:`CUBE_UV`)."""
    out = np.zeros((len(vertices), 2))
    for face in range(len(vertices) // 4):
        corners = vertices[4 * face:4 * face + 4]
        normal = tuple(int(c) for c in np.rint(corners.mean(axis=0)))
        for axis, (a, b, c, d) in enumerate(CUBE_UV[normal]):
            out[4 * face:4 * face + 4, axis] = corners @ (a, b, c) + d
    return out


#: The regular icosahedron the icosphere starts from: its 12 vertices (the cyclic permutations of (0, +-a, +-b), a
#: and b = 1 and the golden ratio scaled onto the unit sphere) and 20 faces wound outward. These are the numbers
#: trimesh ships (its creation.json), to the last bit and in its order (b has only 14 digits there), so that
#: :func:`unit_sphere` gives trimesh.creation.icosphere's triangles (tests/scene/test_icosphere.py compares the two at
#: every level): the mesh the exports and Cycles get for a sphere, which the core traced until it hit the analytic
#: sphere.
ICOSAHEDRON_VERTICES = (
    (-0.5257311121191336, 0.85065080835204, 0.0), (0.5257311121191336, 0.85065080835204, 0.0),
    (-0.5257311121191336, -0.85065080835204, 0.0), (0.5257311121191336, -0.85065080835204, 0.0),
    (0.0, -0.5257311121191336, 0.85065080835204), (0.0, 0.5257311121191336, 0.85065080835204),
    (0.0, -0.5257311121191336, -0.85065080835204), (0.0, 0.5257311121191336, -0.85065080835204),
    (0.85065080835204, 0.0, -0.5257311121191336), (0.85065080835204, 0.0, 0.5257311121191336),
    (-0.85065080835204, 0.0, -0.5257311121191336), (-0.85065080835204, 0.0, 0.5257311121191336),
)
ICOSAHEDRON_TRIANGLES = (
    (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
    (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7),
    (9, 8, 1),
)


def _onto_sphere(vertices: np.ndarray) -> np.ndarray:
    """Each vertex moved along its direction by 1 - |v|: ``v + (v / |v|) (1 - |v|)``, as trimesh does it (not
    ``v / |v|``, which rounds differently). |v| comes from ``np.dot`` with a vector of ones, the reduction trimesh
    uses (through BLAS), so that the sums, and the bits, are the same."""
    length = np.sqrt(np.dot(vertices * vertices, np.ones(3)))
    return vertices + vertices / length[:, None] * (1.0 - length)[:, None]


def _subdivide(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle (a, b, c) split in four at its edges' midpoints m_ab, m_bc, m_ca: (a, m_ab, m_ca),
    (m_ab, b, m_bc), (m_ca, m_bc, c), (m_ab, m_bc, m_ca), in that order, triangle after triangle (the winding is
    kept). An edge shared by two triangles gets one midpoint, ``(v_lo + v_hi) / 2``; the midpoints follow the old
    vertices, ordered by (larger index, smaller index) of their edge (the order trimesh's subdivision gives)."""
    count = len(vertices)
    edges = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)  # (a, b), (b, c), (c, a) of each triangle
    low, high = edges.min(axis=1), edges.max(axis=1)
    _, first, which = np.unique(high * count + low, return_index=True, return_inverse=True)
    midpoints = (vertices[low[first]] + vertices[high[first]]) / 2.0
    ab, bc, ca = (which.reshape(-1, 3) + count).T
    a, b, c = triangles.T
    split = np.stack([a, ab, ca, ab, b, bc, ca, bc, c, ab, bc, ca], axis=1).reshape(-1, 3)
    return np.concatenate([vertices, midpoints]), split


def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """``trimesh.creation.icosphere(subdivisions, radius=1)``'s vertices (float64) and faces (int64), the same
    arrays to the last bit (:func:`unit_sphere` divides the vertices by their norms)."""
    vertices = np.array(ICOSAHEDRON_VERTICES, dtype=np.float64)
    triangles = np.array(ICOSAHEDRON_TRIANGLES, dtype=np.int64)
    if subdivisions <= 0:
        vertices = _onto_sphere(vertices)
    for _ in range(subdivisions):
        vertices, triangles = _subdivide(vertices, triangles)
        vertices = _onto_sphere(vertices)
    return vertices, triangles


@lru_cache(maxsize=None)
def _unit_sphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    vertices, triangles = icosphere(subdivisions)
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)  # exactly on the unit sphere
    vertices.setflags(write=False)
    triangles.setflags(write=False)
    return vertices, triangles


def unit_sphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit sphere as an icosphere (20 * 4**subdivisions triangles) facing outward, vertices on the sphere.

    Parameters
    ----------
    subdivisions : int
        How many times the icosahedron is subdivided (0 to 7 in a scene file).

    Returns
    -------
    vertices : numpy.ndarray
        (10 * 4**subdivisions + 2, 3) float64, read-only, each of norm 1 (to rounding).
    triangles : numpy.ndarray
        (20 * 4**subdivisions, 3) int64, read-only, wound outward.

    Notes
    -----
    Midpoint subdivision of the regular icosahedron (not Loop's scheme: nothing is smoothed): each level splits
    every triangle in four at its edges' midpoints and moves every vertex onto the sphere,
    :math:`v \\leftarrow v + \\hat v (1 - |v|)`; at the end every vertex is divided by its norm. The
    construction, the order of the vertices and triangles and every bit are those of
    ``trimesh.creation.icosphere`` (followed by that division), which the harness called before (importing trimesh
    took 0.6 s of every command that loads a sphere); tests/scene/test_icosphere.py checks them against trimesh for
    every level a scene may ask for.

    References
    ----------
    .. [1] trimesh, ``trimesh.creation.icosphere`` and ``trimesh.remesh.subdivide`` (MIT licence),
           https://github.com/mikedh/trimesh.
    """
    return _unit_sphere(int(subdivisions))
