"""The generated scenes' texture images, 8-bit sRGB PNGs made from formulas and a seeded random stream (no
third-party asset): value noise (random lattice values, bilinearly interpolated, summed over octaves: Perlin 1985's
value-noise variant) shaped into wood, fabric, a rug, wallpaper, bark and grass.
"""

from __future__ import annotations

import numpy as np

from harness.files.imageio import encode_png


def value_noise(rng: np.random.Generator, size: int, cells: int, octaves: int = 4) -> np.ndarray:
    """(size, size) float64 in [0, 1]: sum over octaves o of 2^-o times a tileable lattice of (cells 2^o)^2 uniform
    values, bilinearly interpolated at the texel centres, normalised to [0, 1]."""
    total = np.zeros((size, size))
    weight = 0.0
    for o in range(octaves):
        n = cells * 2 ** o
        lattice = rng.random((n, n))
        x = (np.arange(size) + 0.5) / size * n - 0.5
        i0 = np.floor(x).astype(int)
        f = x - i0
        a, b = i0 % n, (i0 + 1) % n
        rows = lattice[a] * (1 - f)[:, None] + lattice[b] * f[:, None]
        layer = rows[:, a] * (1 - f)[None, :] + rows[:, b] * f[None, :]
        total += layer * 0.5 ** o
        weight += 0.5 ** o
    total /= weight
    return (total - total.min()) / max(total.max() - total.min(), 1e-12)


def _codes(rgb: np.ndarray) -> bytes:
    """(H, W, 3) linear-ish values in [0, 1] as PNG bytes of 8-bit codes (round half to even of 255 x)."""
    return encode_png(np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8))


def _tint(t: np.ndarray, dark, light) -> np.ndarray:
    return np.asarray(dark)[None, None, :] * (1 - t[..., None]) + np.asarray(light)[None, None, :] * t[..., None]


def wood(rng: np.random.Generator, size: int = 256) -> bytes:
    """Floor planks: 8 planks across, each its own shade, grain rings sin(40 (v + 0.3 noise)) along them and a dark
    gap between planks."""
    v, u = (np.mgrid[0:size, 0:size] + 0.5) / size
    plank = np.floor(u * 8).astype(int)
    shade = rng.uniform(0.75, 1.1, 8)[plank]
    grain = 0.5 + 0.5 * np.sin(40 * (v + 0.3 * value_noise(rng, size, 4)) + plank * 1.7)
    t = np.clip((0.35 + 0.45 * grain) * shade, 0, 1)
    t = np.where(np.abs(u * 8 - np.rint(u * 8)) < 0.03, 0.05, t)
    return _codes(_tint(t, (0.25, 0.12, 0.05), (0.75, 0.5, 0.28)))


def fabric(rng: np.random.Generator, size: int = 128) -> bytes:
    """A woven fabric: a fine weave of threads (sin of 64 u times sin of 64 v) over a slow colour noise."""
    v, u = (np.mgrid[0:size, 0:size] + 0.5) / size
    weave = 0.5 + 0.25 * np.sin(2 * np.pi * 32 * u) * np.sin(2 * np.pi * 32 * v)
    t = np.clip(0.6 * weave + 0.4 * value_noise(rng, size, 4), 0, 1)
    return _codes(_tint(t, (0.12, 0.18, 0.35), (0.3, 0.45, 0.7)))


def rug(rng: np.random.Generator, size: int = 256) -> bytes:
    """A rug: a border, a diamond lattice inside it in three colours, and a pile noise over all."""
    v, u = (np.mgrid[0:size, 0:size] + 0.5) / size
    x, y = np.abs(u - 0.5), np.abs(v - 0.5)
    border = np.maximum(x, y) > 0.42
    diamond = (np.floor((u + v) * 6) + np.floor((u - v) * 6)) % 3
    palette = np.array([[0.55, 0.08, 0.06], [0.85, 0.65, 0.3], [0.1, 0.2, 0.3], [0.2, 0.05, 0.04]])
    rgb = palette[np.where(border, 3, diamond.astype(int))]
    return _codes(rgb * (0.8 + 0.2 * value_noise(rng, size, 16))[..., None])


def wallpaper(rng: np.random.Generator, size: int = 128) -> bytes:
    """Wallpaper: vertical stripes in two creams and a faint noise."""
    v, u = (np.mgrid[0:size, 0:size] + 0.5) / size
    stripe = (np.floor(u * 12) % 2)[..., None]
    rgb = np.array([0.78, 0.74, 0.62]) * (1 - stripe) + np.array([0.7, 0.72, 0.66]) * stripe
    return _codes(rgb * (0.92 + 0.08 * value_noise(rng, size, 8))[..., None])


def bark(rng: np.random.Generator, size: int = 64) -> bytes:
    """Bark: vertical furrows, noise stretched along the trunk (v)."""
    v, u = (np.mgrid[0:size, 0:size] + 0.5) / size
    furrow = 0.5 + 0.5 * np.sin(2 * np.pi * 6 * u + 3 * value_noise(rng, size, 2))
    return _codes(_tint(np.clip(furrow, 0, 1), (0.12, 0.08, 0.05), (0.4, 0.3, 0.2)))


def grass(rng: np.random.Generator, size: int = 256) -> bytes:
    """Forest floor: moss green and leaf-litter brown mixed by a noise."""
    t = value_noise(rng, size, 8, octaves=5)
    return _codes(_tint(t, (0.18, 0.13, 0.06), (0.16, 0.32, 0.08)))


def leaf_opacity(size: int = 64) -> bytes:
    """A leaf's opacity, 0 or 1 (white inside (x / 0.45)^2 + (y / w(x))^2 < 1, w(x) = 0.22 (1 - x / 0.45)^0.4
    (1 + x / 0.45)^0.8, texel coordinates in [-0.5, 0.5], black along the midrib): what the ``mask`` of the leaf
    cards reads raw."""
    v, u = (np.mgrid[0:size, 0:size] + 0.5) / size
    x, y = u - 0.5, 0.5 - v
    t = np.clip(x / 0.45, -1.0, 1.0)
    inside = (np.abs(x) < 0.45) & (np.abs(y) < 0.22 * (1 - t) ** 0.4 * (1 + t) ** 0.8)
    opaque = inside & ~((np.abs(y) < 0.015) & (x > -0.35))
    return encode_png(np.repeat((opaque * 255).astype(np.uint8)[..., None], 3, axis=2))
