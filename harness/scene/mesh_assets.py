"""The canonical scenes' mesh files, made here from formulas (no third-party asset), as ASCII PLY:

* ``leaning-plate.ply``: a 4 x 4 unit plate (z = 0, facing +z) of 5 x 5 vertices whose vertex normals lean toward +x
  by 10 to 50 degrees across it (and toward +y by up to 15): the leaning-plate scene, where a sun below the plate's
  plane but above its shading normals' horizon must not light it (scenes/leaning-plate.toml);
* ``blob.ply``: an egg-shaped closed mesh of 320 triangles (an icosphere of 2 subdivisions, stretched and bent) with
  the egg's analytic normals in the file, shaded smooth by them and flat (``face_normals = true``) beside it
  (scenes/smooth-twins.toml);
* ``blob-bare.ply``: the same triangles without normals (their normals the angle-weighted ones Mitsuba computes);

and the stress suite's (``scenes/stress/meshes``): ``flipping-normals.ply``, a plate whose vertex normals turn from leaning
100 degrees one way to 100 degrees the other across each triangle (past the plate's plane), so that their blend passes
through zero and behind the plate.
``python -m harness.scene.mesh_assets [FOLDER]`` writes them (default: ``scenes/meshes`` and ``scenes/stress/meshes``, the
committed files that ``tests/scene/test_mesh_assets.py`` checks this module reproduces byte for byte).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from harness.files.imageio import atomic_write_bytes
from harness.scene.primitives import icosphere

DEFAULT_FOLDER = Path(__file__).resolve().parents[2] / "scenes" / "meshes"
STRESS_FOLDER = DEFAULT_FOLDER.parent / "stress" / "meshes"


def ply_text(vertices: np.ndarray, triangles: np.ndarray, normals: np.ndarray | None = None,
             uv: np.ndarray | None = None) -> bytes:
    """An ASCII PLY of the triangles (and vertex normals ``nx, ny, nz``, texture coordinates ``u, v``), each number
    with 9 significant digits (a NaN as ``nan``)."""
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals is not None else []) + (["u", "v"] if uv is not None
                                                                                       else [])
    lines = ["ply", "format ascii 1.0", f"element vertex {len(vertices)}"]
    lines += [f"property float {p}" for p in props]
    lines += [f"element face {len(triangles)}", "property list uchar int vertex_indices", "end_header"]
    columns = np.hstack([np.asarray(c, dtype=np.float64).reshape(len(vertices), -1)
                         for c in (vertices, normals, uv) if c is not None])
    lines += [" ".join(f"{x:.9g}" for x in row) for row in columns]
    lines += ["3 " + " ".join(str(int(i)) for i in tri) for tri in triangles]
    return ("\n".join(lines) + "\n").encode()


def _grid(n: int, half: float) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid of vertices over [-half, half]^2 at z = 0 and its triangles, facing +z."""
    xs = np.linspace(-half, half, n)
    x, y = np.meshgrid(xs, xs, indexing="xy")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    triangles = []
    for j in range(n - 1):
        for i in range(n - 1):
            a, b, c, d = j * n + i, j * n + i + 1, (j + 1) * n + i, (j + 1) * n + i + 1
            triangles += [(a, b, d), (a, d, c)]
    return vertices, np.array(triangles, dtype=np.int64)


def leaning_plate() -> bytes:
    """The leaning plate: 5 x 5 vertices over [-2, 2]^2, normal (sin a cos b, sin b, cos a cos b) with
    a = 10 + 10 (x + 2) degrees toward +x and b = 7.5 y degrees toward +y."""
    vertices, triangles = _grid(5, 2.0)
    a = np.radians(10.0 + 10.0 * (vertices[:, 0] + 2.0))
    b = np.radians(7.5 * vertices[:, 1])
    normals = np.stack([np.sin(a) * np.cos(b), np.sin(b), np.cos(a) * np.cos(b)], axis=1)
    return ply_text(vertices, triangles, normals)


def _blob() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The egg: the unit icosphere of 2 subdivisions through p -> (0.7 x, 0.55 y, 0.6 z) (1 + 0.25 x), lifted to
    stand on z = 0, with the analytic normals of that map (the inverse transpose of its Jacobian)."""
    sphere, triangles = icosphere(2)
    x, y, z = sphere.T
    k = 1.0 + 0.25 * x
    vertices = np.stack([0.7 * x * k, 0.55 * y * k, 0.6 * z * k], axis=1)
    vertices[:, 2] -= vertices[:, 2].min()
    normals = np.empty_like(vertices)
    for i, (px, py, pz) in enumerate(sphere):
        kk = 1.0 + 0.25 * px
        jac = np.array([[0.7 * (kk + 0.25 * px), 0.0, 0.0],
                        [0.55 * 0.25 * py, 0.55 * kk, 0.0],
                        [0.6 * 0.25 * pz, 0.0, 0.6 * kk]])
        n = np.linalg.solve(jac.T, sphere[i])
        normals[i] = n / np.linalg.norm(n)
    return vertices, np.asarray(triangles, dtype=np.int64), normals


def blob() -> bytes:
    vertices, triangles, normals = _blob()
    return ply_text(vertices, triangles, normals)


def blob_bare() -> bytes:
    vertices, triangles, _normals = _blob()
    return ply_text(vertices, triangles)


def flipping_normals() -> bytes:
    """The stress plate: 3 x 3 vertices over [-1, 1]^2, normals leaning +-100 degrees toward x, alternating by
    vertex (past the plate's plane, to its back), so that inside each triangle their blend shrinks, passes through
    zero and turns to the back side."""
    vertices, triangles = _grid(3, 1.0)
    sign = np.where((np.arange(9) % 2) == 0, 1.0, -1.0)
    a = np.radians(100.0) * sign
    normals = np.stack([np.sin(a), np.zeros(9), np.cos(a)], axis=1)
    return ply_text(vertices, triangles, normals)


MESHES = {"leaning-plate.ply": leaning_plate, "blob.ply": blob, "blob-bare.ply": blob_bare}
#: The stress suite's meshes (scenes/stress/meshes).
STRESS_MESHES = {"flipping-normals.ply": flipping_normals}


def main(argv: list[str]) -> int:
    if len(argv) > 1:
        print("usage: python -m harness.scene.mesh_assets [FOLDER]  (default: scenes/meshes)", file=sys.stderr)
        return 2
    folders = [(Path(argv[0]), MESHES), (Path(argv[0]), STRESS_MESHES)] if argv else \
        [(DEFAULT_FOLDER, MESHES), (STRESS_FOLDER, STRESS_MESHES)]
    for folder, meshes in folders:
        for name, make in meshes.items():
            atomic_write_bytes(folder / name, make())
            print(f"wrote {folder / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
