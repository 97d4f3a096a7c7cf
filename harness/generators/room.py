"""``room``: a furnished room of about a million triangles (at ``detail = 7``), textured, smooth-shaded, with glossy
and glass objects.

A 6 x 5 x 2.8 room (z up) of rectangles: a wood floor (a procedural plank texture), wallpapered back and left walls,
white others and ceiling. In it, each a PLY mesh with area-weighted vertex normals (shaded smooth) and texture
coordinates: a sofa of four rounded boxes and two cushions (a fabric texture), a table (a principled top with the
plank texture, roughness 0.35, on four legs), a glass vase on it (``dielectric``, index 1.5), a gold kettle beside it
(``roughconductor``, GGX alpha 0.12, Mitsuba 3.9.1's RGB Au), a glass ball on the floor and a rug (a height field
of pile, a rug texture). Light: a 1 x 0.6 panel in the ceiling and the bulb of a floor lamp (an emitting sphere).

Triangles (the meshes' and the rectangles'): T(d) = 2 x 20 x 4^d (vase, kettle) + 20 x 4^(d-1) (glass ball)
+ 7 x 20 x 4^(d-2) (sofa's four parts, two cushions, table top) + 4 x 20 x 4^(d-4) (legs) + 2 (2^(d+1))^2 (rug)
+ 14 (seven rectangles): 1,016,846 at d = 7, 15,902 at the tests' d = 4 (:func:`triangle_count`). Two lights.
"""

from __future__ import annotations

import numpy as np

from harness.generators import meshes, textures
from harness.generators.scenefile import SceneFiles, table, value

DEFAULTS = {"detail": 7, "seed": 1}
LIMITS = {"detail": (4, 8), "seed": (0, 2**31 - 1)}
DESCRIPTION = ("a furnished room: ~1 M triangles at detail=7 (smooth meshes, textures), glass and glossy objects, "
               "a ceiling panel and a lamp bulb")


def triangle_count(detail: int) -> int:
    """The scene's triangles at ``detail`` (its meshes' and its rectangles'; the lamp's sphere is analytic)."""
    d = detail
    return 2 * 20 * 4 ** d + 20 * 4 ** (d - 1) + 7 * 20 * 4 ** (d - 2) + 4 * 20 * 4 ** (d - 4) \
        + 2 * (2 ** (d + 1)) ** 2 + 14


def _box(subdivisions: int, half, center, exponent: float = 6.0):
    v, t, n, uv = meshes.deformed_sphere(subdivisions, meshes.superellipsoid(half, exponent))
    return v + np.asarray(center, np.float64), t, n, uv


def _vase(subdivisions: int, center):
    """A vase: the sphere's direction d to (d_x rho, d_y rho, 0.18 d_z), rho = 0.06 + 0.05 (1 - z^2)(1 + 0.6 z)
    + 0.02 z^2 (z = d_z: a belly below the middle, a neck, a flared lip)."""
    def radius(d):
        z = d[:, 2]
        rho = 0.06 + 0.05 * (1 - z * z) * (1 + 0.6 * z) + 0.02 * z * z
        return np.stack([d[:, 0] * rho, d[:, 1] * rho, 0.18 * z], axis=1)
    v, t, n, uv = meshes.deformed_sphere(subdivisions, radius)
    return v + np.asarray(center, np.float64), t, n, uv


def _rug(rng: np.random.Generator, detail: int):
    """The rug: (2^(d+1) + 1)^2 vertices over x in [-1.5, 0.9], y in [-0.6, 1.0] at height 4 mm plus 3 mm of pile
    noise, facing +z; u along x, v = 1 - (y's fraction)."""
    n = 2 ** (detail + 1) + 1
    params, triangles = meshes.grid(n, n)
    pile = textures.value_noise(rng, n, 16, octaves=3).ravel()
    vertices = np.stack([-1.5 + 2.4 * params[:, 0], -0.6 + 1.6 * params[:, 1], 0.004 + 0.003 * pile], axis=1)
    uv = np.stack([params[:, 0], 1.0 - params[:, 1]], axis=1)
    return vertices, triangles, meshes.vertex_normals(vertices, triangles), uv


def _rectangle(name: str, material: str, translate, scale, rotate=None, **extra) -> str:
    entry = {"name": name, "type": "rectangle", "material": material, "translate": list(translate),
             "scale": list(scale)}
    if rotate is not None:
        entry["rotate"] = {"axis": rotate[0], "angle": rotate[1]}
    entry.update(extra)
    return table("[[shapes]]", entry)


def generate(detail: int = 7, seed: int = 1) -> SceneFiles:
    """The room at ``detail`` (the vase's and kettle's icosphere subdivisions; the rest follows) from ``seed``."""
    rng = np.random.default_rng(seed)
    d = detail
    files = {
        "textures/wood.png": textures.wood(rng), "textures/fabric.png": textures.fabric(rng),
        "textures/rug.png": textures.rug(rng), "textures/wallpaper.png": textures.wallpaper(rng),
    }
    sofa = meshes.merge(_box(d - 2, (1.0, 0.45, 0.2), (-0.5, 1.9, 0.25)),
                        _box(d - 2, (1.0, 0.12, 0.38), (-0.5, 2.3, 0.6)),
                        _box(d - 2, (0.12, 0.45, 0.3), (-1.62, 1.9, 0.35)),
                        _box(d - 2, (0.12, 0.45, 0.3), (0.62, 1.9, 0.35)))
    cushions = meshes.merge(_box(d - 2, (0.32, 0.1, 0.22), (-0.95, 2.08, 0.66), 2.5),
                            _box(d - 2, (0.32, 0.1, 0.22), (-0.05, 2.08, 0.66), 2.5))
    table_mesh = meshes.merge(_box(d - 2, (0.6, 0.35, 0.025), (-0.3, 0.3, 0.45), 8.0),
                              *[_box(d - 4, (0.03, 0.03, 0.21), (-0.3 + sx * 0.5, 0.3 + sy * 0.27, 0.21), 4.0)
                                for sx in (-1, 1) for sy in (-1, 1)])
    vase = _vase(d, (-0.55, 0.3, 0.475 + 0.18))
    kettle = _box(d, (0.12, 0.12, 0.1), (0.05, 0.22, 0.475 + 0.1), 2.5)
    ball = _box(d - 1, (0.2, 0.2, 0.2), (0.9, -0.4, 0.2), 2.0)
    rug = _rug(rng, d)
    objects = {"sofa": (sofa, "fabric"), "cushions": (cushions, "fabric"), "table": (table_mesh, "tabletop"),
               "vase": (vase, "glass"), "kettle": (kettle, "gold"), "ball": (ball, "glass"), "rug": (rug, "rug")}
    for name, (mesh, _material) in objects.items():
        files[f"meshes/{name}.ply"] = meshes.ply_binary(mesh[0], mesh[1], mesh[2], mesh[3])
    parts = [
        "name = \"room\"\n",
        "description = " + value(f"generated by harness.generators.room (detail={d}, seed={seed}): a furnished room, "
                                 f"{triangle_count(d):,} triangles") + "\n",
        table("camera", {"origin": [2.6, -2.3, 1.5], "target": [-0.6, 0.9, 0.6], "up": [0.0, 0.0, 1.0],
                         "fov": 62.0}),
        table("film", {"width": 64, "height": 48, "filter": "box"}),
        table("integrator", {"max_depth": 10}),
    ]
    for name in ("wood", "fabric", "rug", "wallpaper"):
        parts.append(table(f"textures.{name}", {"type": "bitmap", "filename": f"textures/{name}.png"}))
    materials = {
        "floor": {"reflectance": {"texture": "wood"}},
        "wallpaper": {"reflectance": {"texture": "wallpaper"}},
        "white": {"reflectance": [0.75, 0.75, 0.72]},
        "fabric": {"reflectance": {"texture": "fabric"}},
        "rug": {"reflectance": {"texture": "rug"}},
        "tabletop": {"type": "principled", "base_color": {"texture": "wood"}, "roughness": 0.35},
        "glass": {"type": "dielectric", "int_ior": 1.5},
        "gold": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.12,
                 "eta": [0.1431189, 0.3749570, 1.442479], "k": [3.983160, 2.385721, 1.603215]},
        "lamp": {"reflectance": [0.8, 0.8, 0.8]},
    }
    for name, entries in materials.items():
        parts.append(table(f"materials.{name}", entries))
    parts += [
        _rectangle("floor", "floor", (0.0, 0.0, 0.0), (3.0, 2.5, 1.0)),
        _rectangle("ceiling", "white", (0.0, 0.0, 2.8), (3.0, 2.5, 1.0), ([1.0, 0.0, 0.0], 180.0)),
        _rectangle("back-wall", "wallpaper", (0.0, 2.5, 1.4), (3.0, 1.4, 1.0), ([1.0, 0.0, 0.0], 90.0)),
        _rectangle("front-wall", "white", (0.0, -2.5, 1.4), (3.0, 1.4, 1.0), ([1.0, 0.0, 0.0], -90.0)),
        _rectangle("left-wall", "wallpaper", (-3.0, 0.0, 1.4), (1.4, 2.5, 1.0), ([0.0, 1.0, 0.0], 90.0)),
        _rectangle("right-wall", "white", (3.0, 0.0, 1.4), (1.4, 2.5, 1.0), ([0.0, 1.0, 0.0], -90.0)),
        _rectangle("ceiling-panel", "lamp", (0.0, 0.2, 2.79), (0.5, 0.3, 1.0), ([1.0, 0.0, 0.0], 180.0),
                   emission=[9.0, 8.6, 7.8]),
        table("[[shapes]]", {"name": "lamp-bulb", "type": "sphere", "material": "lamp",
                             "center": [2.1, 1.9, 1.45], "radius": 0.12, "emission": [14.0, 9.5, 5.0]}),
    ]
    for name, (_mesh, material) in objects.items():
        parts.append(table("[[shapes]]", {"name": name, "type": "mesh", "material": material,
                                          "file": f"meshes/{name}.ply"}))
    triangles = sum(len(mesh[1]) for mesh, _ in objects.values()) + 14
    return SceneFiles("\n".join(parts), files, {"triangles": triangles, "lights": 2, "shapes": 15})
