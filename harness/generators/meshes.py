"""Meshes for the generated scenes, made from formulas: binary PLY bytes, parametric surfaces and their normals.

Every function here is deterministic (numpy only, no random stream: the generators pass their own seeded ones).
"""

from __future__ import annotations

import numpy as np

from harness.scene.primitives import icosphere


def ply_binary(vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray | None = None,
               uv: np.ndarray | None = None) -> bytes:
    """A little-endian binary PLY: ``x y z`` (and ``nx ny nz``, ``u v``) as float32 per vertex, each face a
    ``uchar`` count 3 and three ``int`` indices (the layout of PLY 1.0, Turk 1994; read by trimesh and by Mitsuba's
    ``ply``, whose ``u``, ``v`` are Mitsuba's texture coordinates: v = 0 the image's top row).

    Written with numpy structured arrays, not trimesh: a million faces in well under a second, the same bytes on
    every run."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else []) + (["u", "v"] if uv is not None
                                                                                       else [])
    columns = [vertices] + [np.asarray(c, np.float64).reshape(len(vertices), -1) for c in (normals, uv)
                            if c is not None]
    vertex = np.empty(len(vertices), dtype=[(n, "<f4") for n in names])
    for name, value in zip(names, np.hstack(columns).T):
        vertex[name] = value
    face = np.empty(len(triangles), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face["n"] = 3
    face["i"] = triangles
    header = ["ply", "format binary_little_endian 1.0", "comment made by harness.generators (no third-party asset)",
              f"element vertex {len(vertices)}"] + [f"property float {n}" for n in names]
    header += [f"element face {len(triangles)}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(header) + "\n").encode() + vertex.tobytes() + face.tobytes()


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals: the normalised sum of the (unnormalised) cross products of the triangles at
    each vertex (Gouraud's average, weighted by area as ``cross`` is)."""
    corners = vertices[triangles]
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    fallback = np.tile([0.0, 0.0, 1.0], (len(vertices), 1))
    return np.where(length > 0, normals / np.where(length > 0, length, 1.0), fallback)


def grid(nu: int, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """An nu x nv grid of parameters (u, v) in [0, 1]^2 (u fastest) and its 2 (nu - 1)(nv - 1) triangles, wound
    counter-clockwise in (u, v)."""
    u, v = np.meshgrid(np.linspace(0.0, 1.0, nu), np.linspace(0.0, 1.0, nv), indexing="xy")
    params = np.stack([u.ravel(), v.ravel()], axis=1)
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="xy")
    a = (j * nu + i).ravel()
    b, c, d = a + 1, a + nu, a + nu + 1
    triangles = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]).astype(np.int64)
    return params, triangles


def deformed_sphere(subdivisions: int, radius) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A closed smooth surface: the icosphere of ``subdivisions`` (20 4^s triangles, facing outward) with each unit
    direction d moved to ``radius(d)`` (an (N, 3) array of the point for each direction), its area-weighted vertex
    normals and the spherical texture coordinates (u = atan2(y, x) / 2 pi + 1/2, v = acos(z) / pi)."""
    directions, triangles = icosphere(subdivisions)
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    vertices = radius(directions)
    normals = vertex_normals(vertices, triangles)
    uv = np.stack([np.arctan2(directions[:, 1], directions[:, 0]) / (2 * np.pi) + 0.5,
                   np.arccos(np.clip(directions[:, 2], -1.0, 1.0)) / np.pi], axis=1)
    return vertices, triangles, normals, uv


def superellipsoid(half: tuple[float, float, float], exponent: float):
    """The map of :func:`deformed_sphere` onto a superellipsoid of half-sizes ``half``: each direction d scaled so
    that sum |x_i / h_i|^e = 1 (Barr 1981, the rounded box of e > 2; e = 2 the ellipsoid)."""
    h = np.asarray(half, dtype=np.float64)

    def radius(d: np.ndarray) -> np.ndarray:
        scale = np.sum(np.abs(d / h) ** exponent, axis=1) ** (-1.0 / exponent)
        return d * scale[:, None]

    return radius


def merge(*parts: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """Meshes (vertices, triangles, normals, uv) joined into one, the indices of each offset past the ones before."""
    vertices, triangles, normals, uvs, offset = [], [], [], [], 0
    for v, t, n, uv in parts:
        vertices.append(v)
        triangles.append(t + offset)
        normals.append(n)
        uvs.append(uv)
        offset += len(v)
    return tuple(np.concatenate(x) for x in (vertices, triangles, normals, uvs))


def placed(mesh: tuple[np.ndarray, ...], matrix: np.ndarray) -> tuple[np.ndarray, ...]:
    """A mesh (vertices, triangles, normals, uv) under a 4x4 affine ``matrix``: the points by it, the normals by its
    inverse transpose, renormalised."""
    v, t, n, uv = mesh
    linear = matrix[:3, :3]
    vertices = v @ linear.T + matrix[:3, 3]
    normals = n @ np.linalg.inv(linear)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return vertices, t, normals, uv


def affine(scale=(1.0, 1.0, 1.0), translate=(0.0, 0.0, 0.0), rotate_z: float = 0.0) -> np.ndarray:
    """The 4x4 matrix Translate(translate) Rotate_z(rotate_z degrees) Scale(scale) (scale first)."""
    c, s = np.cos(np.radians(rotate_z)), np.sin(np.radians(rotate_z))
    m = np.eye(4)
    m[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.diag(np.asarray(scale, np.float64))
    m[:3, 3] = translate
    return m
