"""The studies' figures that show images keep every grey level of those images (the slides' Figure 5.9 panel of
noise against shadow rays); only line plots are palette PNGs."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

from harness.studies import figures


def _grey_levels(png: bytes) -> set[int]:
    """The distinct grey values (R == G == B) of a PNG."""
    pixels = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).reshape(-1, 3)
    grey = pixels[(pixels[:, 0] == pixels[:, 1]) & (pixels[:, 1] == pixels[:, 2])]
    return set(np.unique(grey[:, 0]).tolist())


def test_panel_keeps_every_grey_level_of_a_smooth_gradient():
    """A 16 x 16 ramp of all 256 grey levels, drawn as a panel tile the way the shadow-ray study draws its renders
    (uint8 sRGB, nearest-neighbour, upscaled): every one of its levels is in the PNG (a 256-colour palette, shared
    with the titles and their anti-aliasing, dropped most of them and banded the image)."""
    ramp = np.arange(256, dtype=np.uint8).reshape(16, 16)
    tile = np.repeat(ramp[:, :, None], 3, axis=2)
    png = figures.panel_figure([("gradient", tile), ("ground truth", tile)], columns=2, title="gradient")
    levels = _grey_levels(png)
    missing = sorted(set(range(256)) - levels)
    assert not missing, f"{len(missing)} of the gradient's 256 grey levels lost (e.g. {missing[:8]})"


def test_a_colour_panel_keeps_every_colour():
    """A tile of 4096 colours (more than any palette holds) comes back pixel for pixel: full-colour RGB."""
    r, g = np.meshgrid(np.arange(64, dtype=np.uint8) * 4, np.arange(64, dtype=np.uint8) * 4)
    tile = np.stack([r, g, 255 - r], axis=2)
    png = figures.lossless_png(tile)
    back = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))
    assert np.array_equal(back, tile)
    grey = figures.lossless_png(np.repeat(np.arange(256, dtype=np.uint8).reshape(16, 16)[:, :, None], 3, axis=2))
    assert Image.open(io.BytesIO(grey)).mode == "P" and len(_grey_levels(grey)) == 256  # exact palette


def test_line_plots_stay_palette_pngs():
    """A line plot (strategies' bars) is still a palette PNG: the page stays small."""
    png = figures.strategies_figure([{"label": "default", "relative_efficiency": 1.0, "is_default": True},
                                     {"label": "rr=off", "relative_efficiency": 2.0}])
    assert Image.open(io.BytesIO(png)).mode == "P"
