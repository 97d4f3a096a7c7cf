"""A seeded heightfield terrain of any triangle count, as a binary PLY and a scene file: the scale study's scene
(:mod:`harness.studies.scaling`, ``harness bench --scaling``).

The height over the square [-1, 1]^2 is a sum of K seeded plane waves (a "spectral synthesis" terrain, as in
Fournier, Fussell and Carpenter's random fractal surfaces, with the 1/f amplitudes of fractional Brownian motion),

    h(x, y) = sum_k a_k sin(2 pi f_k (d_k . (x, y)) + phi_k),   a_k = A / f_k,

with frequencies f_k spread geometrically from 1 to :data:`TOP_FREQUENCY` cycles over the square, directions d_k
uniform on the circle and phases phi_k uniform on [0, 2 pi), all drawn from ``numpy.random.default_rng(seed)``. The
vertex normals are the surface's own, exact and smooth: n = normalize(-dh/dx, -dh/dy, 1), with
dh/dx = sum_k a_k 2 pi f_k d_kx cos(...). The grid has nx x ny cells of two triangles each (nx = ceil(sqrt(C)),
ny = ceil(C / nx), C = ceil(N / 2) cells); the triangles are listed row by row and the first N kept, so that the
mesh has exactly N triangles (an odd N, or C not nx x ny, leaves a notch in the far row, the last one listed).
Everything is float32 in the file (Mitsuba's own precision); the bytes depend only on (N, seed) and this module.

The scene: the terrain (diffuse grey, or a rough plastic with ``material = "glossy"``) seen from above and in
front, lit by a directional sun and a constant blue sky, ``max_depth = 3`` (direct light and one bounce).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError
from harness.files.imageio import atomic_write_bytes, atomic_write_text
from harness.generators.meshes import ply_binary

#: waves summed, the highest frequency (cycles over the square's side of 2) and the relief's amplitude A
WAVES, TOP_FREQUENCY, AMPLITUDE = 24, 48.0, 0.05
MATERIALS = ("diffuse", "glossy")


@dataclass(frozen=True)
class Terrain:
    """A written terrain: its scene file, its mesh file, its triangle and vertex counts."""

    scene: Path
    mesh: Path
    triangles: int
    vertices: int


def waves(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The K waves of seed ``seed``: amplitudes a_k, frequencies f_k, unit directions d_k (K, 2), phases phi_k."""
    rng = np.random.default_rng(seed)
    freq = np.geomspace(1.0, TOP_FREQUENCY, WAVES) * rng.uniform(0.8, 1.25, WAVES)
    angle = rng.uniform(0.0, 2.0 * math.pi, WAVES)
    phase = rng.uniform(0.0, 2.0 * math.pi, WAVES)
    return AMPLITUDE / freq, freq, np.stack([np.cos(angle), np.sin(angle)], axis=1), phase


def grid_shape(triangles: int) -> tuple[int, int]:
    """(nx, ny) cells of the grid that holds ``triangles`` (see the module docstring)."""
    cells = -(-triangles // 2)
    nx = math.isqrt(cells)
    nx += nx * nx < cells
    return nx, -(-cells // nx)


def heightfield(triangles: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (V, 3), vertex normals (V, 3), triangles (N, 3)) of the terrain, float32 and int32, the triangles
    counter-clockwise seen from above (+z)."""
    if triangles < 1:
        raise ValueError(f"a terrain needs at least one triangle, got {triangles}")
    nx, ny = grid_shape(triangles)
    xs = np.linspace(-1.0, 1.0, nx + 1)
    ys = np.linspace(-1.0, 1.0, ny + 1)
    x, y = np.meshgrid(xs, ys)  # (ny + 1, nx + 1): row j is y = ys[j]
    x, y = x.ravel(), y.ravel()
    amp, freq, direction, phase = waves(seed)
    h = np.zeros_like(x)
    dx = np.zeros_like(x)
    dy = np.zeros_like(x)
    for a, f, d, p in zip(amp, freq, direction, phase):  # K passes over the vertices, not a loop over them
        arg = 2.0 * math.pi * f * (d[0] * x + d[1] * y) + p
        h += a * np.sin(arg)
        slope = a * 2.0 * math.pi * f * np.cos(arg)
        dx += slope * d[0]
        dy += slope * d[1]
    normals = np.stack([-dx, -dy, np.ones_like(x)], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    vertices = np.stack([x, y, h], axis=1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))  # cell (i, j), row by row
    v00 = (j * (nx + 1) + i).ravel()
    v10, v01 = v00 + 1, v00 + nx + 1
    v11 = v01 + 1
    tris = np.stack([np.stack([v00, v10, v11], axis=1), np.stack([v00, v11, v01], axis=1)], axis=1).reshape(-1, 3)
    return vertices.astype(np.float32), normals.astype(np.float32), tris[:triangles].astype(np.int32)


def scene_text(mesh_name: str, triangles: int, seed: int, size: int, material: str) -> str:
    """The scene file of the terrain (``mesh_name`` beside it) on a ``size`` x ``size`` film."""
    surface = ('[materials.ground]\nreflectance = [0.45, 0.42, 0.36]\n' if material == "diffuse" else
               '[materials.ground]\ntype = "roughplastic"\ndistribution = "ggx"\nalpha = 0.3\n'
               'diffuse_reflectance = [0.45, 0.42, 0.36]\n')
    return f'''name = "terrain-{triangles}"
description = """
A heightfield terrain of {triangles} triangles (seed {seed}, harness/studies/terrain.py) under a sun and a blue sky, \
{material}: the scale study's scene (harness bench --scaling)."""

[camera]
origin = [0.0, -1.9, 1.9]
target = [0.0, 0.05, -0.05]
up = [0.0, 0.0, 1.0]
fov = 50.0
fov_axis = "x"

[film]
width = {size}
height = {size}
filter = "box"

[integrator]
max_depth = 3

{surface}
[[shapes]]
name = "terrain"
type = "mesh"
file = "{mesh_name}"
material = "ground"

[[emitters]]
name = "sun"
type = "directional"
direction = [-0.5, 0.6, -0.55]
irradiance = [3.0, 2.85, 2.5]

[[emitters]]
name = "sky"
type = "constant"
radiance = [0.1, 0.13, 0.2]
'''


def write_terrain(folder: Path, triangles: int, *, seed: int = 1, size: int = 256,
                  material: str = "diffuse") -> Terrain:
    """Write ``terrain-N-sSEED.ply`` and ``terrain-N-sSEED-SIZE.toml`` (its scene) into ``folder`` (made if
    missing), each atomically (the same bytes for the same arguments). A HarnessError names the folder or file it
    cannot write."""
    if material not in MATERIALS:
        raise HarnessError("material", f"expected one of {', '.join(MATERIALS)}, got {material!r}")
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise HarnessError(str(folder), f"cannot make the terrain folder: {err.strerror or err}") from None
    stem = f"terrain-{triangles}-s{seed}"
    mesh = folder / f"{stem}.ply"
    vertices, normals, tris = heightfield(triangles, seed)
    atomic_write_bytes(mesh, ply_binary(vertices, tris, normals))
    scene = folder / f"{stem}-{size}-{material}.toml"
    atomic_write_text(scene, scene_text(mesh.name, triangles, seed, size, material))
    return Terrain(scene, mesh, triangles, len(vertices))
