"""``forest``: an instanced forest of about ten million triangles (at the defaults), its leaves cut out of cards by
an alpha ``mask``.

``variants`` tree models, each two PLY files: a trunk (a tapered cylinder of 16 sides and 8 rings, 256 triangles,
smooth-shaded, a bark texture) and a crown of ``leaves`` leaf cards (squares of side 0.3 to 0.4, 2 triangles each,
centred uniformly in an ellipsoid of radii 1.6, 1.6, 1.8 around the trunk's upper part, facing uniformly random
directions, shaded flat). The scene format has no instances: each of the ``trees`` trees is two shapes naming its
model's two files with their own placement (a translation on a 2.5-unit spacing, a turn about z, a scale 0.8 to
1.2), so the files are written once and the loader reads each once (harness.scene.load keeps a file's triangles for
every shape that names it again). The crowns' material is Mitsuba's ``mask`` with a leaf's opacity
(``textures/leaf.png``, 0 or 1, read raw) around a ``twosided`` of a dark green front and a lighter back. The ground
is a grass-and-litter texture; an overcast sky (``constant``) lights it. ``max_depth = -1`` (Mitsuba counts a hole
in a mask as a bounce, the reference does not: unbounded, the two estimate the same image).

No sun: Mitsuba's ``path`` stops a shadow ray at a mask, holes and all, and reaches the light beyond a hole only by
the mask's null lobe; a delta light (``directional``, ``point``, ``spot``) is never reached that way, so its light
through the leaves' holes is missing from Mitsuba's image (a 9-tree forest lit by a sun alone: the reference's
mean 1.49 times Mitsuba's, global z = 45; by the sky alone 0.999, and with the leaves unmasked 0.997, both pass).
The reference's shadow rays carry 1 - opacity through each mask (reference_impl/kernels/cutout.py): the expected
image.

Triangles: trees x (2 leaves + 256) + 2: 10,000,002 at the defaults (1,000 trees of 4,872 leaves); lights: the
sky.
"""

from __future__ import annotations

import math

import numpy as np

from harness.generators import meshes, textures
from harness.generators.scenefile import SceneFiles, table, value

DEFAULTS = {"trees": 1000, "leaves": 4872, "variants": 3, "seed": 1}
LIMITS = {"trees": (1, 100000), "leaves": (1, 1000000), "variants": (1, 16), "seed": (0, 2**31 - 1)}
DESCRIPTION = ("an instanced forest: 10 M triangles at the defaults (1,000 trees of 4,872 alpha-masked leaf cards, "
               "3 tree models), an overcast sky")
SIDES, RINGS = 16, 8
TRUNK_TRIANGLES = 2 * SIDES * RINGS
SPACING = 2.5


def triangle_count(trees: int, leaves: int) -> int:
    return trees * (2 * leaves + TRUNK_TRIANGLES) + 2


def trunk(height: float, radius: float) -> tuple[np.ndarray, ...]:
    """A tapered cylinder along +z, radius r (1 - 0.65 z / h), open at both ends, its outward normals (in the file;
    the scene shades it flat, ``face_normals``) and coordinates u around, v up (SIDES x RINGS quads, the seam's
    vertices doubled for the texture)."""
    params, triangles = meshes.grid(SIDES + 1, RINGS + 1)
    angle, z = 2 * np.pi * params[:, 0], height * params[:, 1]
    r = radius * (1 - 0.65 * z / height)
    vertices = np.stack([r * np.cos(angle), r * np.sin(angle), z], axis=1)
    slope = 0.65 * radius / height  # the cone's outward normal leans up by atan(slope)
    normals = np.stack([np.cos(angle), np.sin(angle), np.full_like(z, slope)], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    uv = np.stack([params[:, 0], 1.0 - params[:, 1]], axis=1)
    return vertices, triangles, normals, uv


def crown(rng: np.random.Generator, leaves: int, height: float) -> tuple[np.ndarray, ...]:
    """``leaves`` square cards: centres uniform in the ellipsoid of radii (1.6, 1.6, 1.8) about (0, 0, 0.72 h)
    (a uniform point in the unit ball: a normal vector's direction times U^(1/3)), each spanned by two unit
    vectors orthogonal to a uniformly random normal, side 0.3 to 0.4; coordinates (0, 1), (1, 1), (1, 0), (0, 0)."""
    direction = rng.standard_normal((leaves, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    centres = direction * rng.random((leaves, 1)) ** (1 / 3) * np.array([1.6, 1.6, 1.8]) + [0.0, 0.0, 0.72 * height]
    normal = rng.standard_normal((leaves, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(normal, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(normal, e1)
    half = rng.uniform(0.15, 0.2, (leaves, 1))
    corners = np.stack([centres - half * e1 - half * e2, centres + half * e1 - half * e2,
                        centres + half * e1 + half * e2, centres - half * e1 + half * e2], axis=1)
    vertices = corners.reshape(-1, 3)
    base = 4 * np.arange(leaves)[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    uv = np.tile([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]], (leaves, 1))
    return vertices, triangles, uv


def generate(trees: int = 1000, leaves: int = 4872, variants: int = 3, seed: int = 1) -> SceneFiles:
    """The forest: ``trees`` trees of ``variants`` models of ``leaves`` leaf cards each, from ``seed``."""
    rng = np.random.default_rng(seed)
    files = {"textures/leaf.png": textures.leaf_opacity(), "textures/bark.png": textures.bark(rng),
             "textures/grass.png": textures.grass(rng)}
    heights = []
    for k in range(variants):
        height = float(rng.uniform(3.5, 5.0))
        heights.append(height)
        v, t, n, uv = trunk(height, float(rng.uniform(0.14, 0.2)))
        files[f"meshes/trunk-{k}.ply"] = meshes.ply_binary(v, t, n, uv)
        v, t, uv = crown(rng, leaves, height)
        files[f"meshes/crown-{k}.ply"] = meshes.ply_binary(v, t, None, uv)
    side = math.ceil(math.sqrt(trees))
    extent = side * SPACING / 2.0
    parts = [
        'name = "forest"\n',
        "description = " + value(f"generated by harness.generators.forest (trees={trees}, leaves={leaves}, "
                                 f"variants={variants}, seed={seed}): {triangle_count(trees, leaves):,} "
                                 "triangles, alpha-masked leaves") + "\n",
        table("camera", {"origin": [0.0, -extent - 6.0, 9.0], "target": [0.0, -extent * 0.3, 2.0],
                         "up": [0.0, 0.0, 1.0], "fov": 60.0}),
        table("film", {"width": 64, "height": 48, "filter": "box"}),
        table("integrator", {"max_depth": -1}),
        table("textures.leaf", {"type": "bitmap", "filename": "textures/leaf.png", "raw": True}),
        table("textures.bark", {"type": "bitmap", "filename": "textures/bark.png"}),
        table("textures.grass", {"type": "bitmap", "filename": "textures/grass.png"}),
        table("materials.front", {"reflectance": [0.08, 0.3, 0.06]}),
        table("materials.back", {"reflectance": [0.2, 0.42, 0.1]}),
        table("materials.blade", {"type": "twosided", "bsdf": ["front", "back"]}),
        table("materials.leaf", {"type": "mask", "opacity": {"texture": "leaf"}, "bsdf": "blade"}),
        table("materials.bark", {"reflectance": {"texture": "bark"}}),
        table("materials.ground", {"reflectance": {"texture": "grass"}}),
        table("[[emitters]]", {"name": "sky", "type": "constant", "radiance": [0.95, 1.0, 1.1]}),
        table("[[shapes]]", {"name": "ground", "type": "rectangle", "material": "ground",
                             "scale": [extent + 6.0, extent + 6.0, 1.0]}),
    ]
    for n in range(trees):
        i, j = n % side, n // side
        x = (i - (side - 1) / 2.0) * SPACING + float(rng.uniform(-0.6, 0.6))
        y = (j - (side - 1) / 2.0) * SPACING + float(rng.uniform(-0.6, 0.6))
        k = int(rng.integers(variants))
        place = {"translate": [x, y, 0.0], "rotate": {"axis": [0.0, 0.0, 1.0], "angle": float(rng.uniform(0, 360))},
                 "scale": float(rng.uniform(0.8, 1.2))}
        parts.append(table("[[shapes]]", {"name": f"trunk-{n}", "type": "mesh", "material": "bark",
                                          "file": f"meshes/trunk-{k}.ply", "face_normals": True, **place}))
        parts.append(table("[[shapes]]", {"name": f"crown-{n}", "type": "mesh", "material": "leaf",
                                          "file": f"meshes/crown-{k}.ply", "face_normals": True, **place}))
    counts = {"triangles": triangle_count(trees, leaves), "lights": 1, "shapes": 1 + 2 * trees,
              "mesh_files": 2 * variants}
    return SceneFiles("\n".join(parts), files, counts)
