"""The canonical scenes' texture images, made here from integer formulas (no third-party asset): 8-bit sRGB PNGs
and a float EXR whose texels differ from their neighbours in every channel, so that a texture read upside down, shifted by half a
texel, filtered nearest for bilinear, wrapped by clamping for repeating, or decoded as linear changes the image.

* ``tiles.png`` (64 x 32): the textured furnace's sphere (scenes/textured-furnace.toml), each texel a colour of its
  own, code = 40 + (a i + b j + c i j + d) mod 181 per channel (row i, column j);
* ``wall.png`` (32 x 32): the textured Cornell box's left wall (scenes/textured-cornell-box.toml), a gradient from
  top to bottom in red, across in green, and blue stripes four texels wide, so that no flip or shift maps it onto
  itself;
* ``leaf.png`` (64 x 64): the cut-out leaf's opacity, 0 or 1 (:func:`leaf`);
* ``glow.exr`` (8 x 4, float32): the textured Cornell box's light, its radiance 0.4 to 1.6 times the Cornell box
  light's in a pattern of sevenths.

and the stress suite's (``scenes/stress/textures``): ``one-texel.png`` (1 x 1), ``fine-checker.png`` (2048 x 2048
single-texel squares) and a copy of ``tiles.png``. ``python -m harness.scene.texture_images [FOLDER]`` writes them all (default
``scenes/textures`` and ``scenes/stress/textures``, the committed files that ``tests/scene/test_texture_images.py``
checks this module reproduces pixel for pixel).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from harness.files.imageio import atomic_write_bytes, encode_png, exr_bytes

DEFAULT_FOLDER = Path(__file__).resolve().parents[2] / "scenes" / "textures"


def tiles() -> np.ndarray:
    """(32, 64, 3) uint8: code = 40 + (a i + b j + c i j + d) mod 181, (a, b, c, d) per channel."""
    i, j = np.meshgrid(np.arange(32), np.arange(64), indexing="ij")
    channels = [40 + (a * i + b * j + c * i * j + d) % 181 for a, b, c, d in ((37, 59, 11, 0), (83, 23, 7, 90),
                                                                              (17, 71, 13, 45))]
    return np.stack(channels, axis=-1).astype(np.uint8)


def wall() -> np.ndarray:
    """(32, 32, 3) uint8: red 40 + 6 i (top to bottom), green 230 - 5 j (left to right), blue 200 on stripes of
    columns j // 4 odd, 50 between them."""
    i, j = np.meshgrid(np.arange(32), np.arange(32), indexing="ij")
    return np.stack([40 + 6 * i, 230 - 5 * j, np.where((j // 4) % 2 == 1, 200, 50)], axis=-1).astype(np.uint8)


def glow() -> np.ndarray:
    """(4, 8, 3) float32 radiance: the Cornell box light's, (18.387, 13.9873, 6.75357), times 0.4 + 1.2 k / 6 with
    k = (3 i + 5 j) mod 7 (row i, column j): 0.4 to 1.6 of it, each texel unlike its neighbours."""
    i, j = np.meshgrid(np.arange(4), np.arange(8), indexing="ij")
    factor = 0.4 + 1.2 * ((3 * i + 5 * j) % 7) / 6.0
    return (factor[..., None] * np.array([18.387, 13.9873, 6.75357])).astype(np.float32)


def one_texel() -> np.ndarray:
    """(1, 1, 3) uint8: one texel, (200, 120, 40) (the stress suite's 1 x 1 texture, which Mitsuba pads to 2 x 2)."""
    return np.array([[[200, 120, 40]]], dtype=np.uint8)


def fine_checker() -> np.ndarray:
    """(2048, 2048, 3) uint8: a checkerboard of single texels, 255 and 0 (the stress suite's large texture, seen
    minified thousands of texels to a pixel: its mean is 1/2 in linear values only when the codes are decoded before
    filtering; 24 KB as a PNG)."""
    i, j = np.meshgrid(np.arange(2048), np.arange(2048), indexing="ij")
    return np.repeat((((i + j) % 2) * 255).astype(np.uint8)[..., None], 3, axis=2)


def _height(size: int) -> np.ndarray:
    """(size, size) float64 in [0, 1]: the mapped plates' height field, h = (2 + sin(2 pi (2 u + v)) + cos(2 pi 3 v)
    sin(2 pi u)) / 4 at the texel centres (u across, v down): lopsided in u and v, so that no flip maps it onto
    itself."""
    v, u = (np.mgrid[0:size, 0:size] + 0.5) / size
    return (2.0 + np.sin(2 * np.pi * (2 * u + v)) + np.cos(2 * np.pi * 3 * v) * np.sin(2 * np.pi * u)) / 4.0


def bumps_normal() -> np.ndarray:
    """(64, 64, 3) uint8: a tangent-space normal map (raw: rgb = (n + 1) / 2 in codes) of :func:`_height`,
    n = normalize(-0.1 dh/du, -0.1 dh/dv, 1) from central differences: normals leaning up to 36 degrees, toward
    +u and +v alike."""
    size = 64
    h = _height(size)
    dh_du = (np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)) * size / 2.0
    dh_dv = (np.roll(h, -1, axis=0) - np.roll(h, 1, axis=0)) * size / 2.0
    n = np.stack([-0.1 * dh_du, -0.1 * dh_dv, np.ones_like(h)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.clip(np.rint((n + 1.0) / 2.0 * 255.0), 0, 255).astype(np.uint8)


def ridges() -> np.ndarray:
    """(64, 64, 3) uint8 grey: :func:`_height` as codes 255 h (the bump map's height, read raw)."""
    return np.repeat(np.rint(_height(64) * 255.0).astype(np.uint8)[..., None], 3, axis=2)


def leaf() -> np.ndarray:
    """(64, 64, 3) uint8, black (0) or white (255): the cut-out leaf's opacity (scenes/cutout-leaf.toml). White
    inside a leaf, (x / 0.42)^2 + (y / a(x))^2 < 1 with a(x) = 0.24 (1 - x / 0.42)^0.35 (1 + x / 0.42)^0.9 in texel
    units scaled to [-0.5, 0.5] (a rounded base at the left, a pointed tip at the right), but black along the
    midrib (|y| < 0.012 from x = -0.3), along four veins leaving it at 40 degrees toward the tip on the upper side
    only, and in two round bites near the lower edge: lopsided in u and v, so that no flip maps it onto itself."""
    v, u = (np.mgrid[0:64, 0:64] + 0.5) / 64.0
    x, y = u - 0.5, 0.5 - v
    t = np.clip(x / 0.42, -1.0, 1.0)
    half_width = 0.24 * (1.0 - t) ** 0.35 * (1.0 + t) ** 0.9
    inside = (np.abs(x) < 0.42) & (np.abs(y) < half_width)
    holes = (np.abs(y) < 0.012) & (x > -0.3)
    for x0 in (-0.22, -0.08, 0.06, 0.18):
        along = (x - x0) * np.cos(np.radians(40)) + y * np.sin(np.radians(40))
        across = -(x - x0) * np.sin(np.radians(40)) + y * np.cos(np.radians(40))
        holes |= (np.abs(across) < 0.011) & (along > 0) & (y > 0)
    for cx, cy, r in ((-0.05, -0.13, 0.05), (0.17, -0.07, 0.035)):
        holes |= (x - cx) ** 2 + (y - cy) ** 2 < r * r
    opaque = inside & ~holes
    return np.repeat((opaque * 255).astype(np.uint8)[..., None], 3, axis=2)


IMAGES = {"tiles.png": tiles, "wall.png": wall, "glow.exr": glow, "bumps-normal.png": bumps_normal,
          "ridges.png": ridges, "leaf.png": leaf}
def grazing_normals() -> np.ndarray:
    """(4, 4, 3) uint8: a raw tangent-space normal map whose normals lean 80 to 98 degrees from the surface's, in
    azimuths 45 degrees apart (a lean past 90 points below the surface: the flip of invalid normals), rgb = (n + 1) / 2
    in codes; the stress suite's grazing normal map."""
    i, j = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    lean = np.radians(80.0 + 6.0 * ((i + 2 * j) % 4))
    azimuth = np.radians(45.0 * ((3 * i + j) % 8))
    n = np.stack([np.sin(lean) * np.cos(azimuth), np.sin(lean) * np.sin(azimuth), np.cos(lean)], axis=-1)
    return np.clip(np.rint((n + 1.0) / 2.0 * 255.0), 0, 255).astype(np.uint8)


#: The stress suite's texture images (scenes/stress/textures).
STRESS_IMAGES = {"one-texel.png": one_texel, "fine-checker.png": fine_checker, "tiles.png": tiles,
                 "grazing-normals.png": grazing_normals}
STRESS_FOLDER = DEFAULT_FOLDER.parent / "stress" / "textures"


def main(argv: list[str]) -> int:
    if len(argv) > 1:
        print("usage: python -m harness.scene.texture_images [FOLDER]  (default: scenes/textures)", file=sys.stderr)
        return 2
    folders = [(Path(argv[0]), IMAGES), (Path(argv[0]), STRESS_IMAGES)] if argv else \
        [(DEFAULT_FOLDER, IMAGES), (STRESS_FOLDER, STRESS_IMAGES)]
    for folder, images in folders:
        for name, make in images.items():
            image = make()
            atomic_write_bytes(folder / name, encode_png(image) if name.endswith(".png") else exr_bytes(image))
            print(f"wrote {folder / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
