"""Pixel reconstruction filters h with Mitsuba's kernels and radii, and samplers for them.

Viewing rays are placed by *filter importance sampling*: an offset x from the pixel centre is drawn with a pdf
proportional to h, and the sample's weight is h(x) / (pdf(x) * integral(h)), so the pixel estimate
(1/Np) sum_i w_i L_i is unbiased for integral h(x) L(c + x) dx / integral h (slides, Fig. 5.16 ``computeImage``:
"pick sample point p within support of h; radiance += rad(ray) * h(p)"). Box and tent are sampled exactly (w = 1);
the Gaussian through a fine piecewise-constant table, with w = h / (pdf * integral h) correcting the rest.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from reference_impl.errors import SettingsError

FILTERS = ("box", "tent", "gaussian")
_GAUSS_STDDEV = 0.5  # Mitsuba's default
_GAUSS_RADIUS = 4 * _GAUSS_STDDEV  # Mitsuba cuts off after 4 standard deviations
_TABLE_BINS = 1024


@dataclass(frozen=True, eq=False)
class PixelFilter:
    """A separable filter h(x, y) = h1(x) h1(y) with support [-radius, radius]^2."""

    name: str
    radius: float

    def eval_1d(self, x: np.ndarray) -> np.ndarray:
        """h1(x): box 1 on [-1/2, 1/2]; tent max(0, 1 - |x|); Gaussian max(0, exp(-x^2/(2 s^2)) - exp(-r^2/(2 s^2)))."""
        x = np.asarray(x, float)
        if self.name == "box":
            return (np.abs(x) <= 0.5).astype(float)
        if self.name == "tent":
            return np.maximum(0.0, 1.0 - np.abs(x) / self.radius)
        alpha = -1.0 / (2.0 * _GAUSS_STDDEV**2)
        return np.maximum(0.0, np.exp(alpha * x * x) - np.exp(alpha * self.radius**2))

    def sample_1d(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Offsets x distributed as h1 and their weights h1(x) / (pdf(x) integral h1), from uniforms u in [0, 1)."""
        u = np.asarray(u, float)
        if self.name == "box":
            return u - 0.5, np.ones_like(u)
        if self.name == "tent":
            x = np.where(u < 0.5, np.sqrt(2.0 * u) - 1.0, 1.0 - np.sqrt(2.0 * (1.0 - u)))
            return x, np.ones_like(u)
        edges, cdf, density, integral = _gaussian_table()
        bins = np.minimum(np.searchsorted(cdf, u, side="right") - 1, _TABLE_BINS - 1)
        width = edges[1] - edges[0]
        within = (u - cdf[bins]) / (cdf[bins + 1] - cdf[bins])
        x = edges[bins] + np.clip(within, 0.0, 1.0) * width
        pdf = density[bins]
        return x, self.eval_1d(x) / (pdf * integral)

    def pdf_1d(self, x: np.ndarray) -> np.ndarray:
        """The density that :meth:`sample_1d` draws offsets from."""
        x = np.asarray(x, float)
        if self.name == "box":
            return (np.abs(x) <= 0.5).astype(float)
        if self.name == "tent":
            return np.maximum(0.0, 1.0 - np.abs(x))
        edges, _, density, _ = _gaussian_table()
        bins = np.clip(((x - edges[0]) / (edges[1] - edges[0])).astype(int), 0, _TABLE_BINS - 1)
        return np.where(np.abs(x) <= self.radius, density[bins], 0.0)

    def sample(self, u1: np.ndarray, u2: np.ndarray):
        """2D offsets (dx, dy) from the pixel centre and their weights."""
        dx, wx = self.sample_1d(u1)
        dy, wy = self.sample_1d(u2)
        return dx, dy, wx * wy


@lru_cache(maxsize=None)
def _gaussian_table():
    edges = np.linspace(-_GAUSS_RADIUS, _GAUSS_RADIUS, _TABLE_BINS + 1)
    fine = 16
    xs = edges[:-1, None] + (np.arange(fine) + 0.5)[None, :] / fine * (edges[1] - edges[0])
    filt = PixelFilter("gaussian", _GAUSS_RADIUS)
    mean_h = filt.eval_1d(xs).mean(axis=1)
    width = edges[1] - edges[0]
    integral = float(mean_h.sum() * width)
    density = mean_h / integral
    cdf = np.concatenate([[0.0], np.cumsum(density * width)])
    cdf /= cdf[-1]
    return edges, cdf, density, integral


def make_filter(name: str) -> PixelFilter:
    if name == "box":
        return PixelFilter("box", 0.5)
    if name == "tent":
        return PixelFilter("tent", 1.0)
    if name == "gaussian":
        return PixelFilter("gaussian", _GAUSS_RADIUS)
    raise SettingsError("film.filter", f"expected one of {', '.join(FILTERS)}, got {name!r}")
