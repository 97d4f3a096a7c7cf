"""What every scene export shares: file-name-safe shape names, the folders meshes and maps go in, PLY bytes."""

from __future__ import annotations

import re

import numpy as np

MESH_DIR = "meshes"
TEXTURE_DIR = "textures"


def safe_name(name: str) -> str:
    """A file-name-safe form of a shape name."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "shape"


def ply_bytes(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray | None = None,
              normals: np.ndarray | None = None) -> bytes:
    """A binary PLY of the triangles, written by trimesh without merging or reordering: vertices as float32 (the
    float64 positions rounded to nearest), faces as int32; with ``uv`` ((V, 2) texture coordinates, Mitsuba's
    convention: v = 0 the image's top row) also the vertex properties ``s``, ``t`` (float64), which Mitsuba's
    ``ply`` reads as they are; with ``normals`` ((V, 3) vertex normals) ``nx``, ``ny``, ``nz``."""
    import trimesh  # optional: 0.6 s (scipy, networkx) at every command's start; only mesh files need it
    mesh = trimesh.Trimesh(vertices=np.asarray(vertices, np.float64), faces=np.asarray(triangles, np.int64),
                           vertex_normals=None if normals is None else np.asarray(normals, np.float64),
                           process=False, validate=False)
    if uv is not None:
        mesh.visual = trimesh.visual.TextureVisuals(uv=np.asarray(uv, np.float64))
        if normals is not None:  # the visual's assignment empties trimesh's cache, where the normals live
            mesh.vertex_normals = np.asarray(normals, np.float64)
    return mesh.export(file_type="ply", encoding="binary", vertex_normal=normals is not None)
