"""Images of a report: tone-mapped renders, error heat maps, and the files behind them (EXR + sRGB PNG).

Heat maps are scalar maps (one value per pixel) coloured through a matplotlib colormap, pixel for pixel (no
resampling): the PNG is what the page shows, the EXR beside it holds the values themselves (the same value in R, G
and B), so every number can be read back.
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.files import imageio
from harness.judges import metrics

#: colormaps (matplotlib names): diverging for signed error (red: render too bright), sequential otherwise
SIGNED_CMAP = "RdBu_r"
RELATIVE_CMAP = "viridis"
FLIP_CMAP = "magma"
#: relative error's epsilon, as MAPE's (harness.judges.metrics.MAPE_EPS): |t - r| / (|r| + eps)
RELATIVE_EPS = 1e-2
#: heat-map limits come from this percentile of the magnitudes, so one firefly does not wash the map out
LIMIT_PERCENTILE = 99.0


@dataclass
class ReportImage:
    """An image of the report: its PNG bytes (what the page embeds), files on disk and what it shows."""

    key: str
    title: str
    png: bytes
    exr: Path | None = None
    png_path: Path | None = None
    description: str = ""
    legend: dict | None = None  # heat maps: {"cmap", "vmin", "vmax", "stops": [css colours], "unit"}
    stats: dict = field(default_factory=dict)

    def data_uri(self) -> str:
        return "data:image/png;base64," + base64.b64encode(self.png).decode("ascii")

    def to_json(self) -> dict:
        return {"key": self.key, "title": self.title, "exr": str(self.exr) if self.exr else None,
                "png": str(self.png_path) if self.png_path else None, "description": self.description,
                "legend": self.legend, "stats": self.stats}


def _cmap(name: str):
    import matplotlib  # optional: heavy matplotlib, loaded to colour a map

    return matplotlib.colormaps[name]


def colorize(values: np.ndarray, cmap: str, vmin: float, vmax: float) -> np.ndarray:
    """Scalar (H, W) -> uint8 RGB through ``cmap`` with limits [vmin, vmax]; non-finite values are magenta."""
    v = np.asarray(values, dtype=np.float64)
    bad = ~np.isfinite(v)
    span = vmax - vmin
    scaled = np.clip((np.nan_to_num(v) - vmin) / span, 0.0, 1.0) if span > 0 else np.full(v.shape, 0.5)
    rgba = _cmap(cmap)(scaled)
    out = np.round(rgba[..., :3] * 255.0).astype(np.uint8)
    out[bad] = (255, 0, 255)
    return out


def css_stops(cmap: str, count: int = 9) -> list[str]:
    """Colours of ``cmap`` at ``count`` evenly spaced positions, as CSS hex strings (for the legend bar)."""
    colours = _cmap(cmap)(np.linspace(0.0, 1.0, count))
    return ["#%02x%02x%02x" % tuple(int(round(c * 255)) for c in rgba[:3]) for rgba in colours]


def robust_limit(values: np.ndarray, percentile: float = LIMIT_PERCENTILE) -> float:
    """The ``percentile`` of |values| over finite values (falls back to the maximum, then to 1)."""
    v = np.abs(np.asarray(values, dtype=np.float64))
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 1.0
    lim = float(np.percentile(v, percentile))
    if not lim > 0:
        lim = float(v.max())
    return lim if lim > 0 else 1.0


def display_exposure(expected: np.ndarray, percentile: float = LIMIT_PERCENTILE) -> float:
    """Exposure (stops) for showing a ground truth and its render side by side: 0 unless the ground truth's
    ``percentile`` of its brightest channel is above 1 (it would clip to white), then just enough to bring it to 1."""
    v = np.asarray(expected, dtype=np.float64).max(axis=-1)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0
    level = float(np.percentile(v, percentile))
    return -float(np.log2(level)) if level > 1.0 else 0.0


def signed_error(test: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """Per pixel, the mean over channels of test - expected (the ground truth; linear radiance)."""
    return (np.asarray(test, np.float64) - np.asarray(expected, np.float64)).mean(axis=-1)


def relative_error(test: np.ndarray, expected: np.ndarray, eps: float = RELATIVE_EPS) -> np.ndarray:
    """Per pixel, the mean over channels of |test - expected| / (|expected| + eps): MAPE's terms, so the map's mean
    over finite pixels is the case's MAPE."""
    t = np.asarray(test, np.float64)
    r = np.asarray(expected, np.float64)
    return (np.abs(t - r) / (np.abs(r) + eps)).mean(axis=-1)


def _scalar_stats(values: np.ndarray) -> dict:
    v = np.asarray(values, dtype=np.float64)
    f = v[np.isfinite(v)]
    if f.size == 0:
        return {"mean": None, "min": None, "max": None, "nonfinite": int(v.size)}
    return {"mean": float(f.mean()), "min": float(f.min()), "max": float(f.max()),
            "nonfinite": int(v.size - f.size)}


class ImageWriter:
    """Writes a folder's images as EXR + PNG and returns :class:`ReportImage` objects (PNG bytes kept for embedding)."""

    def __init__(self, folder: Path, metadata: dict[str, str] | None = None):
        self.folder = Path(folder)
        self.metadata = {k: str(v) for k, v in (metadata or {}).items()}

    def _write(self, key: str, pixels: np.ndarray, data: np.ndarray, variance: np.ndarray | None,
               extra_meta: dict[str, str]) -> tuple[bytes, Path, Path]:
        imageio.make_folders(self.folder)  # a failure is a WriteError, which no report section swallows
        exr = self.folder / f"{key}.exr"
        png = self.folder / f"{key}.png"
        meta = dict(self.metadata, **{k: str(v) for k, v in extra_meta.items()})
        imageio.write_exr(exr, data, variance, metadata=meta)
        encoded = imageio.encode_png(pixels)
        imageio.atomic_write_bytes(png, encoded)
        return encoded, exr, png

    def radiance(self, key: str, title: str, image: np.ndarray, variance: np.ndarray | None = None,
                 description: str = "", exposure: float = 0.0) -> ReportImage:
        """A linear RGB image, shown tone-mapped as the harness's previews are (sRGB, clipped) at ``exposure`` stops
        (see :func:`display_exposure`); the EXR holds the linear values."""
        image = np.asarray(image, dtype=np.float32)
        pixels = imageio.tonemap_srgb8(image, exposure)
        encoded, exr, png = self._write(key, pixels, image, variance, {"report_image": key})
        note = f"PNG: sRGB, exposure {exposure:+.2f} stops" if exposure else "PNG: sRGB, exposure 0"
        return ReportImage(key, title, encoded, exr, png, "; ".join(filter(None, [description, note])),
                           stats=dict(_scalar_stats(image.mean(axis=-1)), exposure=float(exposure)))

    def heatmap(self, key: str, title: str, values: np.ndarray, *, cmap: str, vmin: float, vmax: float,
                unit: str = "", description: str = "") -> ReportImage:
        """A scalar map coloured with ``cmap`` on [vmin, vmax]; the EXR holds the values in R, G and B."""
        values = np.asarray(values, dtype=np.float64)
        pixels = colorize(values, cmap, vmin, vmax)
        data = np.repeat(values[..., None], 3, axis=-1).astype(np.float32)
        encoded, exr, png = self._write(key, pixels, data, None,
                                        {"report_image": key, "colormap": cmap, "vmin": f"{vmin:.9g}",
                                         "vmax": f"{vmax:.9g}"})
        legend = {"cmap": cmap, "vmin": float(vmin), "vmax": float(vmax), "stops": css_stops(cmap), "unit": unit}
        return ReportImage(key, title, encoded, exr, png, description, legend=legend, stats=_scalar_stats(values))

    def mask(self, key: str, title: str, mask: np.ndarray, description: str = "") -> ReportImage:
        """A boolean mask: white where true."""
        m = np.asarray(mask, dtype=bool)
        pixels = np.repeat((m * 255).astype(np.uint8)[..., None], 3, axis=-1)
        data = np.repeat(m.astype(np.float32)[..., None], 3, axis=-1)
        encoded, exr, png = self._write(key, pixels, data, None, {"report_image": key})
        return ReportImage(key, title, encoded, exr, png, description, stats={"pixels": int(m.sum())})


def error_images(writer: ImageWriter, test: np.ndarray, expected: np.ndarray,
                 flip: tuple[float, np.ndarray] | None = None) -> list[ReportImage]:
    """Signed error (diverging, symmetric limits), relative error and the FLIP map of ``test`` against ``expected``
    (the ground truth). ``flip``: ``metrics.flip(test, expected, full=True)`` where the caller has it already (the
    case's comparison computes it), else it is computed here."""
    signed = signed_error(test, expected)
    lim = robust_limit(signed)
    rel = relative_error(test, expected)
    rel_lim = robust_limit(rel)
    images = [
        writer.heatmap(
            "error_signed", "Signed error", signed, cmap=SIGNED_CMAP, vmin=-lim, vmax=lim, unit="radiance",
            description=f"render - ground truth, mean over R, G, B; red: render brighter; limits +-{lim:.3g} "
                        f"(the {LIMIT_PERCENTILE:g}th percentile of |error|)"),
        writer.heatmap(
            "error_relative", "Relative error", rel, cmap=RELATIVE_CMAP, vmin=0.0, vmax=rel_lim,
            description=f"|render - ground truth| / (|ground truth| + {RELATIVE_EPS:g}), mean over R, G, B (the map's "
                        f"mean is MAPE); limits 0..{rel_lim:.3g} (the {LIMIT_PERCENTILE:g}th percentile)"),
    ]
    flip_mean, flip_map = flip if flip is not None else metrics.flip(test, expected, full=True)
    images.append(writer.heatmap(
        "flip", "FLIP", flip_map, cmap=FLIP_CMAP, vmin=0.0, vmax=1.0,
        description=f"HDR-FLIP error map (flip-evaluator), 0..1; mean {flip_mean:.4g}"))
    return images
