"""A small procedural sky for ``envmap`` scenes, made here rather than downloaded: a lat-long radiance map with a
smooth blue-to-white gradient above the horizon, a dim ground below it and a small sun about 6000 times as bright
as the sky (a hard case for an estimator that does not sample the map by its brightness).

The map uses Mitsuba's ``envmap`` layout (docs/scene-format.md, "Emitters"): pixel (row i, column j) of an H x W
map holds the radiance from the local direction at u = (j + 0.5) / W, v = i / (H - 1), with
d = (sin(2 pi u) sin(pi v), cos(pi v), -cos(2 pi u) sin(pi v)): row 0 looks up (+y), the image's centre column
looks along +z, its first and last columns along -z.

``python -m harness.scene.sky [OUT.exr]`` writes it (default ``scenes/textures/sky.exr``, the committed file that
``tests/scene/test_sky.py`` checks this module reproduces bit for bit). It is a module of the scene layer, not a
script, so that tests and the reference's sampling tests can build the same array in memory without a file.

Every value is computed in float64 and rounded to float16 precision (then stored as float32): the low mantissa
bits are zero, so the ZIP-compressed EXR stays small (14 KB at 128 x 64), and a last-bit difference of a
platform's ``sin`` or ``cos`` almost never survives the rounding.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from harness.files.imageio import write_exr

WIDTH, HEIGHT = 128, 64
ZENITH = np.array([0.25, 0.45, 0.9])  # sky radiance straight up
HORIZON = np.array([0.8, 0.85, 0.9])  # sky radiance at the horizon
GROUND = np.array([0.12, 0.1, 0.08])  # below the horizon
HORIZON_BLUR = 0.15  # the ground blends into the sky over |d.y| < this (about 9 degrees up and down, 6 rows)
SUN_ELEVATION_DEG = 30.0
SUN_U = 0.3  # the sun's azimuth as a map coordinate (0.25: +x, 0.5: +z)
SUN_RADIUS_DEG = 2.5  # angular radius of the disk: about one pixel across at 128 x 64
GLOW = np.array([0.9, 0.7, 0.4])  # extra sky radiance toward the sun, falling as cos(angle)^GLOW_EXPONENT
GLOW_EXPONENT = 8
SUN_RADIANCE = np.array([3000.0, 2850.0, 2550.0])
SUPERSAMPLES = 8  # per pixel side: the sun's edge pixels hold the disk's coverage of their footprint

DEFAULT_OUT = Path(__file__).resolve().parents[2] / "scenes" / "textures" / "sky.exr"
#: The stress suite's map of one bright texel (scenes/stress/envmap-spike.toml; :func:`spike_image`).
SPIKE_OUT = Path(__file__).resolve().parents[2] / "scenes" / "stress" / "textures" / "spike.exr"
SPIKE_SHAPE = (16, 32)  # height, width
SPIKE_TEXEL = (5, 9)  # row, column: 60 degrees from +y (v = 5 / 15), azimuth u = 9.5 / 32
SPIKE_RATIO = 1e6


def map_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit directions (..., 3) of the map coordinates u (azimuth, [0, 1)) and v (polar angle / pi, [0, 1]), in
    Mitsuba's ``envmap`` convention (its ``uv_to_direction``)."""
    theta, phi = np.broadcast_arrays(np.pi * np.asarray(v, np.float64), 2.0 * np.pi * np.asarray(u, np.float64))
    sin_theta = np.sin(theta)
    return np.stack([np.sin(phi) * sin_theta, np.cos(theta), -np.cos(phi) * sin_theta], axis=-1)


def sun_direction() -> np.ndarray:
    """The unit direction toward the sun's centre, in the map's frame."""
    elevation = math.radians(SUN_ELEVATION_DEG)
    return map_direction(np.float64(SUN_U), np.float64(0.5 - elevation / math.pi))


def sky_radiance(d: np.ndarray) -> np.ndarray:
    """Radiance (..., 3) of the sky and ground, without the sun, toward unit directions ``d`` (..., 3)."""
    y = d[..., 1:2]
    up = np.sqrt(np.clip(y, 0.0, 1.0))
    sky = HORIZON + (ZENITH - HORIZON) * up
    t = np.clip((y + HORIZON_BLUR) / (2.0 * HORIZON_BLUR), 0.0, 1.0)
    blend = t * t * (3.0 - 2.0 * t)  # smoothstep: no kink at the horizon
    glow = np.maximum(d @ sun_direction(), 0.0)[..., None] ** GLOW_EXPONENT * GLOW  # brighter toward the sun
    return GROUND + (sky + glow - GROUND) * blend


def sky_image(width: int = WIDTH, height: int = HEIGHT) -> np.ndarray:
    """The sky as an (height, width, 3) float32 lat-long map (row 0 = up), each pixel the average over its
    footprint (SUPERSAMPLES^2 points, weighted by solid angle) of sky plus sun."""
    if width < 2 or height < 3:
        raise ValueError(f"expected a map of at least 2 x 3 pixels, got {width} x {height}")
    offsets = (np.arange(SUPERSAMPLES) + 0.5) / SUPERSAMPLES - 0.5  # within a pixel, in pixel units
    # Column j covers u in [j, j + 1] / W; row i (centre v = i / (H - 1), Mitsuba's) covers v +- 0.5 / (H - 1).
    u = ((np.arange(width)[:, None] + 0.5 + offsets[None, :]) / width).reshape(-1)
    v = np.clip(((np.arange(height)[:, None] + offsets[None, :]) / (height - 1)).reshape(-1), 0.0, 1.0)
    d = map_direction(u[None, :], v[:, None])  # (H * S, W * S, 3)
    sun = d @ sun_direction() >= math.cos(math.radians(SUN_RADIUS_DEG))
    radiance = sky_radiance(d) + sun[..., None] * SUN_RADIANCE
    weight = np.sin(np.pi * v)[:, None, None] + 1e-12  # solid angle; the poles' rows still get a value
    weighted = (radiance * weight).reshape(height, SUPERSAMPLES, width, SUPERSAMPLES, 3).sum(axis=(1, 3))
    total = np.broadcast_to(weight, d.shape[:2] + (1,)).reshape(height, SUPERSAMPLES, width, SUPERSAMPLES, 1)
    image = weighted / total.sum(axis=(1, 3))
    return image.astype(np.float16).astype(np.float32)


def write_sky(path: str | Path = DEFAULT_OUT, width: int = WIDTH, height: int = HEIGHT) -> Path:
    """Write :func:`sky_image` as an OpenEXR file (float32 RGB, atomically); returns the path."""
    return write_exr(path, sky_image(width, height), metadata={"harness.scene.sky": f"{width}x{height}"})


def spike_image(height: int = SPIKE_SHAPE[0], width: int = SPIKE_SHAPE[1], texel: tuple[int, int] = SPIKE_TEXEL,
                ratio: float = SPIKE_RATIO) -> np.ndarray:
    """A (height, width, 3) float32 map of radiance 1 everywhere but one texel of radiance ``ratio`` (the stress
    suite's numerical limit of an environment map, docs/stress.md)."""
    image = np.ones((height, width, 3), np.float32)
    image[texel] = ratio
    return image


def write_spike(path: str | Path = SPIKE_OUT) -> Path:
    """Write :func:`spike_image` as an OpenEXR file (float32 RGB, atomically); returns the path."""
    return write_exr(path, spike_image(), metadata={"harness.scene.sky": "spike"})


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) > 1 or (args and args[0].startswith("-")):
        print("usage: python -m harness.scene.sky [OUT.exr]  (default: scenes/textures/sky.exr)", file=sys.stderr)
        return 2
    print(write_sky(args[0] if args else DEFAULT_OUT))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
