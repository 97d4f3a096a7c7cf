"""harness.core.srgb against colour-science, whose ``cctf_encoding(x, function="sRGB")`` the harness used before
(colour-science stays a test dependency for this): the same float64 bits over a dense grid, at and around the
line's limit, for every array length up to 40 (numpy's vectorised power has tails), for a strided view, and the
same 8-bit previews and PNG bytes."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from harness.core import srgb
from harness.files import imageio as hio


def colours(values: np.ndarray) -> np.ndarray:
    # imported here, not at the top: colour-science takes about 2 s to import, which every pytest-xdist worker would
    # pay while collecting this file; only the worker that runs these tests pays it this way
    import colour

    return np.asarray(colour.cctf_encoding(values, function="sRGB"), dtype=np.float64)


def test_the_formula_at_known_points():
    """IEC 61966-2-1's curve: 0 -> 0, 1 -> 1, the line 12.92 L up to 0.0031308, 0.18 -> 0.46135612950044164."""
    values = srgb.encode(np.array([0.0, 0.001, srgb.LINEAR_LIMIT, 0.18, 1.0]))
    assert values[0] == 0.0 and values[1] == 0.001 * 12.92 and values[2] == srgb.LINEAR_LIMIT * 12.92
    assert values[3] == pytest.approx(1.055 * 0.18 ** (1 / 2.4) - 0.055, rel=1e-15)
    assert values[4] == pytest.approx(1.0, abs=1e-15)
    assert abs(values[2] - (1.055 * srgb.LINEAR_LIMIT ** (1 / 2.4) - 0.055)) < 1e-7  # the two pieces meet there


def test_same_bits_as_colour_science_on_a_dense_grid():
    grid = np.linspace(0.0, 1.0, 2_000_001)
    assert np.array_equal(srgb.encode(grid), colours(grid))
    random = np.random.default_rng(7).random(1_000_003)
    assert np.array_equal(srgb.encode(random), colours(random))


def test_same_bits_as_colour_science_at_the_lines_limit_and_outside_0_1():
    limit = srgb.LINEAR_LIMIT
    around = limit + np.arange(-5000, 5001) * np.spacing(limit)  # every float64 within 5000 ulp of the limit
    assert np.array_equal(srgb.encode(around), colours(around))
    odd = np.array([-0.5, -0.0, 0.0, 1.0, 1.5, 1e300, np.inf, np.nan])
    assert np.array_equal(srgb.encode(odd), colours(odd), equal_nan=True)


@pytest.mark.parametrize("length", range(1, 41))
def test_same_bits_as_colour_science_for_every_short_length(length):
    values = np.random.default_rng(length).random(length)
    assert np.array_equal(srgb.encode(values), colours(values))


def test_same_bits_as_colour_science_for_images_and_views():
    image = np.random.default_rng(3).random((37, 29, 3))
    assert np.array_equal(srgb.encode(image), colours(image))
    view = image[::2, 1::3]  # not contiguous: colour-science copies it, srgb.encode does not
    assert np.array_equal(srgb.encode(view), colours(view))


def previous_tonemap(image: np.ndarray, exposure: float) -> np.ndarray:
    """tonemap_srgb8 as it was with colour-science (NaN magenta, +Inf white)."""
    img = image.astype(np.float64)
    nan = np.isnan(img).any(axis=-1)
    pos_inf = np.isposinf(img).any(axis=-1) & ~nan
    with np.errstate(invalid="ignore", over="ignore"):
        scaled = np.clip(np.nan_to_num(img * 2.0 ** float(exposure), nan=0.0), 0.0, 1.0)
    out = np.round(np.clip(colours(scaled), 0.0, 1.0) * 255.0).astype(np.uint8)
    out[pos_inf] = (255, 255, 255)
    out[nan] = (255, 0, 255)
    return out


def hdr_image() -> np.ndarray:
    """A render-like HDR float32 image: a smooth gradient times lognormal noise over 6 stops, dark corners, a few
    NaN and Inf pixels, and every 8-bit code's neighbourhood on one row."""
    rng = np.random.default_rng(11)
    y, x = np.mgrid[0:96, 0:128]
    base = (x / 127.0)[..., None] * np.array([1.0, 0.7, 0.4]) + (y / 95.0)[..., None] * 0.3
    image = (base * rng.lognormal(0.0, 1.0, (96, 128, 3)) * 2.0 ** rng.uniform(-4, 2, (96, 128, 1))).astype(np.float32)
    image[:8, :8] = 0.0
    image[10, 10, 1], image[11, 11, 0], image[12, 12, 2] = np.nan, np.inf, -np.inf
    codes = (np.arange(128) + 0.5) / 256.0  # display values half-way between codes, back to linear
    image[-1] = np.where(codes <= 0.04045, codes / 12.92, ((codes + 0.055) / 1.055) ** 2.4)[:, None]
    return image


@pytest.mark.parametrize("exposure", [-2.0, 0.0, 1.5])
def test_previews_are_the_same_bytes_as_with_colour_science(exposure):
    image = hdr_image()
    old = previous_tonemap(image, exposure)
    new = hio.tonemap_srgb8(image, exposure)
    assert np.array_equal(new, old)
    assert len(np.unique(new)) > 200  # most codes are exercised
    assert hio._png_bytes(image, exposure) == iio.imwrite("<bytes>", old, extension=".png")
