"""The procedural sky (harness/scene/sky.py): the committed scenes/textures/sky.exr is what the generator makes, bit
for bit; the map is small, smooth, and its sun is where the module says and 1e3-1e4 times as bright as the sky."""

from __future__ import annotations

import math

import numpy as np

from conftest import SCENES
from harness.files.imageio import read_exr
from harness.scene import sky

COMMITTED = SCENES / "textures" / "sky.exr"


def test_the_committed_sky_is_reproduced_bit_for_bit(tmp_path):
    committed = read_exr(COMMITTED).image
    made = sky.sky_image()
    assert made.dtype == committed.dtype == np.float32 and made.shape == committed.shape == (64, 128, 3)
    assert made.view(np.uint32).tobytes() == committed.view(np.uint32).tobytes()
    written = read_exr(sky.write_sky(tmp_path / "sky.exr")).image  # and through the file writer too
    assert written.view(np.uint32).tobytes() == committed.view(np.uint32).tobytes()
    assert COMMITTED.stat().st_size < 100_000


def test_sun_is_a_small_very_bright_disk_where_the_module_says():
    image = sky.sky_image().astype(np.float64)
    luminance = image @ [0.2126, 0.7152, 0.0722]
    sun = luminance > 10
    assert 1 <= sun.sum() <= 12  # a few pixels of 8192
    row, column = np.unravel_index(np.argmax(luminance), luminance.shape)
    height, width = luminance.shape
    direction = sky.map_direction((column + 0.5) / width, row / (height - 1))
    assert math.degrees(math.acos(min(1.0, float(direction @ sky.sun_direction())))) < 3.0
    ratio = luminance.max() / np.median(luminance[~sun & (np.arange(height) < height // 2)[:, None]])
    assert 1e3 <= ratio <= 1e4, ratio
    assert np.all(image > 0) and np.all(np.isfinite(image))
    # smooth: away from the sun, no step between neighbouring pixels is a quarter of the sky's range (the horizon
    # spans several rows)
    sky_only = np.where(sun[..., None], np.nan, image)
    steps = max(np.nanmax(np.abs(np.diff(sky_only, axis=axis))) for axis in (0, 1))
    assert steps < 0.25 * (np.nanmax(sky_only) - np.nanmin(sky_only)), steps


def test_map_direction_is_mitsubas_layout():
    """u = 0: -z, 0.25: +x, 0.5: +z, 0.75: -x; v = 0: +y, 1: -y."""
    for u, v, expected in [(0, 0.5, [0, 0, -1]), (0.25, 0.5, [1, 0, 0]), (0.5, 0.5, [0, 0, 1]),
                           (0.75, 0.5, [-1, 0, 0]), (0.3, 0, [0, 1, 0]), (0.3, 1, [0, -1, 0])]:
        np.testing.assert_allclose(sky.map_direction(u, v), expected, atol=1e-15)
