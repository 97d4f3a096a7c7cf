r"""The verdict's tiles as two OpenEXR maps at film resolution, beside a case's render (``cases/<case>/``) or where
``harness compare --maps DIR`` writes them:

* ``pvalue.exr``: each pixel holds its tile's two-sided p-value :math:`p = 2\Phi(-|z|)` per channel R, G, B
  (:class:`harness.judges.verdict.TileMaps`, ``p``; ``z`` on the normal scale), 1 where a tile is not tested (no
  noise in it), 0 for a zero-variance tile that differs. Under the null hypothesis the tested tiles' p-values are
  uniform on (0, 1); a tile that stands out is dark.
* ``failing.exr``: 1 in the tile-channels that fail the verdict by themselves (``TileMaps.failing``: their
  Šidák-corrected p-value :math:`1 - (1 - p)^K` is below alpha / 3, the max-|z| sub-test's level), else 0.

Both carry header attributes saying what they are (``verdict_map``, ``description``, ``tile``, ``alpha``,
``threshold``, ``tested_tiles``, ``failing_tiles``), and are written atomically (:func:`harness.files.imageio.write_exr`).
Mitsuba's own render tests write such maps only on failure; the harness writes them for every judged case, since
the report's viewer shows them for all.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from harness.files.imageio import write_exr
from harness.judges.verdict import TileMaps

__all__ = ["FAILING_FILE", "PVALUE_FILE", "tile_map_pixels", "write_verdict_maps"]

PVALUE_FILE = "pvalue.exr"
FAILING_FILE = "failing.exr"


def tile_map_pixels(values: np.ndarray, tile: int, height: int, width: int) -> np.ndarray:
    """A per-tile map (ceil(H/tile), ceil(W/tile), C) spread over the pixels of each tile: (height, width, C),
    partial tiles at the right and bottom borders cut to the film."""
    values = np.asarray(values)
    return np.repeat(np.repeat(values, tile, axis=0), tile, axis=1)[:height, :width]


def write_verdict_maps(folder: str | Path, tiles: TileMaps, *, tile: int, alpha: float, threshold: float,
                       height: int, width: int, metadata: Mapping[str, str] | None = None) -> dict[str, Path]:
    """Write ``pvalue.exr`` and ``failing.exr`` into ``folder`` (which must exist) from the verdict's ``tiles``;
    returns ``{"pvalue": path, "failing": path}``. ``metadata``: further header attributes (e.g. the case's
    name). A file that cannot be written is a HarnessError naming it (nothing half-written is left)."""
    folder = Path(folder)
    common = {**dict(metadata or {}), "tile": str(int(tile)), "alpha": repr(float(alpha)),
              "threshold": repr(float(threshold)), "tested_tiles": str(int(np.count_nonzero(tiles.tested))),
              "failing_tiles": str(int(np.count_nonzero(tiles.failing)))}
    p = tile_map_pixels(np.asarray(tiles.p, np.float32), tile, height, width)
    failing = tile_map_pixels(np.asarray(tiles.failing, np.float32), tile, height, width)
    pvalue_path = write_exr(folder / PVALUE_FILE, p, metadata={
        **common, "verdict_map": "pvalue",
        "description": f"two-sided p-value 2 Phi(-|z|) of each {tile} x {tile} tile's Welch z, per channel; "
                       "1 where a tile is not tested, 0 where a zero-variance tile differs"})
    failing_path = write_exr(folder / FAILING_FILE, failing, metadata={
        **common, "verdict_map": "failing",
        "description": f"1 in the {tile} x {tile} tile-channels that fail the verdict by themselves (Sidak-corrected "
                       f"p below alpha / 3 = {threshold:.3g}, or a differing zero-variance tile), else 0"})
    return {"pvalue": pvalue_path, "failing": failing_path}
