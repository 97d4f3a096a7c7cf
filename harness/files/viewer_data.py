r"""A case's data for the report's comparison viewer: its linear HDR images as a small script, and two thumbnails.

The report's page shows each case as a thumbnail and loads the case's full data only when its viewer is opened, by
adding a ``<script src="report/<case>/viewer.js">`` tag (a page opened from ``file://`` may load scripts beside it,
but not read files with ``fetch`` or ``XMLHttpRequest``). Three files per case, made by ``harness run`` when it
judges the case (beside its render, ``OUT/cases/<case>/``) and linked into the report by it:

* ``viewer.js``: ``HarnessViewer.register({...})`` with the render, the ground truth, their standard deviations
  (the square roots of the per-pixel variances of the means), the FLIP map and the verdict's tiles (z, two-sided p,
  tested, failing; :class:`harness.judges.verdict.TileMaps`). Each image is a *plane*: its values, row 0 at the
  top, channels interleaved, as little-endian IEEE half floats (``f16``), in base64, multiplied by a power of two
  :math:`2^k` (``exponent``: ``k``) chosen so that the largest finite magnitude lands in :math:`[2^{13}, 2^{14})`:
  a power of two changes no mantissa bit, so the page decodes exactly the float16 rounding of each value (relative
  error at most :math:`2^{-11}`) over 27 binary orders of magnitude below the peak, without overflow. Standard
  deviations rather than variances halve the orders of magnitude a plane must hold. The tiles' z and p are float32
  (``f32``), their flags bytes (``u8``); a plane that is all zeros (a closed form's variance) is ``{"encoding":
  "zero"}``. See docs/report.md, "The comparison viewer".
* ``thumbnail.png``: the render at the report's display exposure, box-filtered down to at most
  :data:`THUMBNAIL_SIDE` pixels a side (in linear radiance, before tone mapping).
* ``pvalue_thumbnail.png``: at the thumbnail's size, each tile's :math:`-\log_{10} p` (the smallest p over R, G,
  B; ``magma`` from 0 to :data:`PVALUE_TOP`), untested tiles grey, the tiles that fail by themselves outlined in
  cyan.

With them, the histogram of the tested tile-channels' p-values (:func:`p_histogram`), kept in the case's record:
under the null hypothesis the p-values are uniform on (0, 1), so the bars are level; a render that differs piles
them up near 0 (Jung, Hanika and Dachsbacher, "Detecting Bias in Monte Carlo Renderers using Welch's t-test",
JCGT 9(2), 2020, Fig. 6).
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from statistics import NormalDist

import numpy as np

from harness.core.limits import MAX_FILM_PIXELS
from harness.files import imageio
from harness.files.confined import Refused, inside, outside_note, read_inside
from harness.files.previews import colorize
from harness.judges.verdict import TileMaps

__all__ = ["DATA_FILE", "PVALUE_FILE", "THUMBNAIL_FILE", "ViewerData", "encode_plane", "make_viewer_data",
           "p_histogram", "parse_viewer_script", "read_viewer_data", "viewer_script"]

DATA_FILE = "viewer.js"
THUMBNAIL_FILE = "thumbnail.png"
PVALUE_FILE = "pvalue_thumbnail.png"
#: the data format the page's viewer_data.js decodes
FORMAT = 1
#: the longest side of a thumbnail, in pixels
THUMBNAIL_SIDE = 64
#: the top of the p-value map's colour scale, in -log10 p (p = 1e-8: below any tile's Sidak level of a film the
#: harness allows, about alpha / (3 K))
PVALUE_TOP = 8.0
PVALUE_CMAP = "magma"
#: bins of the p-value histogram over [0, 1]
HISTOGRAM_BINS = 20
#: a plane's largest finite magnitude is scaled into [2**PEAK_EXPONENT, 2**(PEAK_EXPONENT + 1))
PEAK_EXPONENT = 13
#: colours of the p-value thumbnail: untested tiles, the outline of a failing tile
UNTESTED_COLOUR = (128, 128, 128)
OUTLINE_COLOUR = (0, 255, 255)


@dataclass
class ViewerData:
    """A case's viewer files in ``folder`` (``data``: viewer.js, ``thumbnail``, ``pvalue``: the p-value thumbnail,
    None where the case has no tiles), the thumbnails' PNG bytes (kept for embedding) and the p-value histogram
    (:func:`p_histogram`, None without tiles)."""

    folder: Path
    data: Path
    thumbnail: Path
    thumbnail_png: bytes
    pvalue: Path | None = None
    pvalue_png: bytes | None = None
    histogram: dict | None = None
    script: str | None = None  # viewer.js as the harness writes it, for :meth:`placed` (read back: re-serialised)

    def record(self) -> dict:
        """What results.json keeps in the case's record (``viewer``): the folder as written, the files' names in it,
        the histogram."""
        return {"folder": str(self.folder), "data": self.data.name, "thumbnail": self.thumbnail.name,
                "pvalue": self.pvalue.name if self.pvalue is not None else None, "p_histogram": self.histogram}

    def to_json(self) -> dict:
        """As report.json shows it: the files' paths and the histogram."""
        return {"data": str(self.data), "thumbnail": str(self.thumbnail),
                "pvalue": str(self.pvalue) if self.pvalue is not None else None, "p_histogram": self.histogram}

    def placed(self, folder: Path) -> ViewerData:
        """These files in ``folder`` (a report's ``report/<case>``), written there: viewer.js as the harness writes
        it from the checked payload (``script``), the thumbnails' checked bytes. Never a link into the run folder."""
        if self.script is None:
            raise ValueError("viewer data read without its checked script; read_viewer_data reads it")
        imageio.make_folders(folder)
        data = imageio.atomic_write_text(folder / DATA_FILE, self.script)
        thumbnail = imageio.atomic_write_bytes(folder / THUMBNAIL_FILE, self.thumbnail_png)
        pvalue = (imageio.atomic_write_bytes(folder / PVALUE_FILE, self.pvalue_png)
                  if self.pvalue_png is not None else None)
        return dataclasses.replace(self, folder=Path(folder), data=data, thumbnail=thumbnail, pvalue=pvalue)


# ---- encoding ----------------------------------------------------------------------------------------------------


def encode_plane(values: np.ndarray, encoding: str = "f16") -> dict:
    r"""An image (H, W) or (H, W, C) as a plane of the viewer's data: ``{"encoding", "channels", "exponent",
    "data"}`` (module docstring). ``encoding``: ``f16`` (scaled by 2**exponent), ``f32`` or ``u8``; any all-zero
    array is ``{"encoding": "zero", "channels"}``.

    Notes
    -----
    For ``f16`` the exponent is :math:`k = 13 - \lfloor\log_2 m\rfloor` for the largest finite magnitude :math:`m`,
    so :math:`m 2^k \in [2^{13}, 2^{14})`, below float16's largest finite value 65504; values as small as
    :math:`m 2^{-27}` stay in float16's normal range (smallest normal :math:`2^{-14}`). Non-finite values stay
    non-finite (float16 has NaN and infinities)."""
    array = np.asarray(values)
    channels = 1 if array.ndim == 2 else int(array.shape[-1])
    if array.size and not np.any(array):
        return {"encoding": "zero", "channels": channels}
    if encoding == "u8":
        raw = np.ascontiguousarray(array, dtype=np.uint8).tobytes()
        return {"encoding": "u8", "channels": channels, "data": base64.b64encode(raw).decode("ascii")}
    if encoding == "f32":
        raw = np.ascontiguousarray(array, dtype="<f4").tobytes()
        return {"encoding": "f32", "channels": channels, "data": base64.b64encode(raw).decode("ascii")}
    if encoding != "f16":
        raise ValueError(f"unknown plane encoding {encoding!r}")
    wide = np.asarray(array, dtype=np.float64)
    finite = np.abs(wide[np.isfinite(wide)])
    peak = float(finite.max()) if finite.size else 0.0
    exponent = PEAK_EXPONENT - math.floor(math.log2(peak)) if peak > 0 else 0
    with np.errstate(over="ignore", invalid="ignore"):
        raw = np.ascontiguousarray(np.ldexp(wide, exponent), dtype="<f2").tobytes()
    return {"encoding": "f16", "channels": channels, "exponent": int(exponent),
            "data": base64.b64encode(raw).decode("ascii")}


#: characters a JSON text may hold that must not reach a script as they are: none can end a <script> element or
#: start markup where the file is read as HTML by mistake
_SCRIPT_SAFE = str.maketrans({"<": "\\u003c", ">": "\\u003e", "&": "\\u0026"})


#: what a viewer.js holds around its JSON payload
_SCRIPT_HEAD = ("/* A case's data for the report's comparison viewer (harness.files.viewer_data; docs/report.md). */\n"
                "HarnessViewer.register(")
_SCRIPT_TAIL = ");\n"


def viewer_script(payload: dict) -> str:
    """The text of a ``viewer.js``: one call ``HarnessViewer.register(<payload as JSON>)``. The JSON is ASCII, with
    ``<``, ``>`` and ``&`` escaped (``\\u003c`` ...), so a case name from a suite file stays a string."""
    text = json.dumps(payload, ensure_ascii=True, allow_nan=False, separators=(",", ":")).translate(_SCRIPT_SAFE)
    return f"{_SCRIPT_HEAD}{text}{_SCRIPT_TAIL}"


def critical_z(threshold: float | None, count: int) -> float | None:
    r"""The |z| beyond which one of ``count`` tested tile-channels fails by itself: its Šidák-corrected p-value
    :math:`1 - (1 - p)^K` is below ``threshold`` where :math:`p < p^* = 1 - (1 - t)^{1/K}`, i.e.
    :math:`|z| > \Phi^{-1}(1 - p^*/2)` (docs/verdict.md, the max-|z| sub-test). None without a threshold or a tile."""
    if not threshold or count < 1 or not 0 < threshold < 1:
        return None
    level = -math.expm1(math.log1p(-threshold) / count)
    return -NormalDist().inv_cdf(level / 2) if level > 0 else None


def _tiles_payload(tiles: TileMaps, tile: int, alpha: float | None, threshold: float | None, recomputed: bool
                   ) -> dict:
    tested = np.asarray(tiles.tested, bool)
    return {"size": int(tile), "rows": int(tested.shape[0]), "cols": int(tested.shape[1]),
            "z": encode_plane(np.nan_to_num(np.asarray(tiles.z, np.float64), nan=0.0, posinf=1e30, neginf=-1e30),
                              "f32"),
            "p": encode_plane(np.asarray(tiles.p, np.float64), "f32"),
            "tested": encode_plane(tested, "u8"), "failing": encode_plane(np.asarray(tiles.failing, bool), "u8"),
            "alpha": alpha, "threshold": threshold, "count": int(tested.sum()),
            "z_critical": critical_z(threshold, int(tested.sum())), "recomputed": bool(recomputed)}


def p_histogram(tiles: TileMaps, bins: int = HISTOGRAM_BINS) -> dict:
    """The histogram of the tested tile-channels' two-sided p-values on [0, 1]: ``{"bins", "counts", "tested",
    "failing"}`` (``failing``: tiles with a failing channel). Under the null hypothesis each bin expects
    ``tested / bins``."""
    tested = np.asarray(tiles.tested, bool)
    p = np.asarray(tiles.p, np.float64)[tested]
    counts, _ = np.histogram(np.clip(p, 0.0, 1.0), bins=bins, range=(0.0, 1.0))
    return {"bins": int(bins), "counts": [int(c) for c in counts], "tested": int(tested.sum()),
            "failing": int(np.asarray(tiles.failing, bool).any(axis=-1).sum())}


# ---- thumbnails --------------------------------------------------------------------------------------------------


def _factor(height: int, width: int) -> int:
    return max(1, math.ceil(max(height, width) / THUMBNAIL_SIDE))


def render_thumbnail(render: np.ndarray, exposure: float) -> bytes:
    """The render box-filtered by the smallest integer factor that brings its longest side to at most
    :data:`THUMBNAIL_SIDE` (averaging linear radiance, non-finite pixels left out), tone-mapped as the previews
    are (sRGB, clipped, ``exposure`` stops): PNG bytes."""
    image = np.asarray(render, np.float64)
    h, w = image.shape[:2]
    f = _factor(h, w)
    if f > 1:
        padded = np.full((math.ceil(h / f) * f, math.ceil(w / f) * f, 3), np.nan)
        padded[:h, :w] = np.where(np.isfinite(image), image, np.nan)
        blocks = padded.reshape(padded.shape[0] // f, f, padded.shape[1] // f, f, 3)
        counts = np.isfinite(blocks).sum(axis=(1, 3))
        sums = np.nansum(blocks, axis=(1, 3))
        image = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)
    return imageio.encode_png(imageio.tonemap_srgb8(image.astype(np.float32), exposure))


def pvalue_thumbnail(tiles: TileMaps, tile: int, height: int, width: int) -> bytes:
    r"""The tiles' :math:`-\log_{10} p` at the thumbnail's size (PNG bytes): the smallest p over the channels a
    tile tests, ``magma`` on [0, :data:`PVALUE_TOP`]; grey where no channel is tested; a cyan outline around each
    tile with a failing channel."""
    f = _factor(height, width)
    p = np.where(np.asarray(tiles.tested, bool), np.asarray(tiles.p, np.float64), np.inf).min(axis=-1)
    tested = np.isfinite(p)
    with np.errstate(divide="ignore"):
        level = -np.log10(np.clip(np.where(tested, p, 1.0), 1e-300, 1.0))
    colours = colorize(level, PVALUE_CMAP, 0.0, PVALUE_TOP)
    colours[~tested] = UNTESTED_COLOUR
    ys = (np.arange(math.ceil(height / f)) * f) // tile
    xs = (np.arange(math.ceil(width / f)) * f) // tile
    pixels = colours[ys[:, None], xs[None, :]].copy()
    failing = np.asarray(tiles.failing, bool).any(axis=-1)[ys[:, None], xs[None, :]]
    edge = np.zeros(failing.shape, bool)
    edge[0, :] = edge[-1, :] = True
    edge[:, 0] = edge[:, -1] = True
    edge[1:, :] |= ys[1:, None] != ys[:-1, None]
    edge[:-1, :] |= ys[:-1, None] != ys[1:, None]
    edge[:, 1:] |= xs[None, 1:] != xs[None, :-1]
    edge[:, :-1] |= xs[None, :-1] != xs[None, 1:]
    pixels[failing & edge] = OUTLINE_COLOUR
    return imageio.encode_png(pixels)


# ---- making and reading ------------------------------------------------------------------------------------------


def make_viewer_data(folder: Path, *, name: str, render: np.ndarray, render_variance: np.ndarray | None,
                     truth: np.ndarray | None, truth_variance: np.ndarray | None, flip: np.ndarray | None,
                     tiles: TileMaps | None, tile: int | None, alpha: float | None = None,
                     threshold: float | None = None, exposure: float = 0.0, labels: dict | None = None,
                     recomputed: bool = False, note: str | None = None) -> ViewerData:
    """Write a case's viewer files into ``folder`` (which must exist) and return them.

    Parameters
    ----------
    render, truth : (H, W, 3) arrays
        The render and the ground truth as their EXRs hold them (``truth`` None: one image alone, ``harness view``).
    render_variance, truth_variance : (H, W, 3) arrays or None
        Per-pixel variances of the means (stored as their square roots).
    flip : (H, W) array or None
        The HDR-FLIP map of the render against the ground truth.
    tiles : TileMaps or None
        The verdict's tiles (``tile`` pixels a side), with the verdict's ``alpha`` and per-test ``threshold``;
        ``recomputed``: they were computed again for this file (a run by an older harness), not by the run.
    exposure : float
        The display exposure the page starts at (stops).
    labels : dict
        ``{"render": str, "truth": str}``, what each image is (shown in the viewer).
    """
    folder = Path(folder)
    render = np.asarray(render, np.float32)
    h, w = render.shape[:2]
    planes = {"render": encode_plane(render)}
    if render_variance is not None:
        planes["render_sd"] = encode_plane(np.sqrt(np.maximum(np.asarray(render_variance, np.float64), 0.0)))
    if truth is not None:
        planes["truth"] = encode_plane(np.asarray(truth, np.float32))
        if truth_variance is not None:
            planes["truth_sd"] = encode_plane(np.sqrt(np.maximum(np.asarray(truth_variance, np.float64), 0.0)))
    if flip is not None:
        planes["flip"] = encode_plane(np.asarray(flip, np.float32))
    payload = {"format": FORMAT, "name": str(name), "width": int(w), "height": int(h), "exposure": float(exposure),
               "labels": {k: str(v) for k, v in (labels or {}).items()}, "planes": planes,
               "tiles": (_tiles_payload(tiles, tile, alpha, threshold, recomputed)
                         if tiles is not None and tile else None),
               "note": note}
    data = imageio.atomic_write_text(folder / DATA_FILE, viewer_script(payload))
    thumb_png = render_thumbnail(render, exposure)
    thumbnail = imageio.atomic_write_bytes(folder / THUMBNAIL_FILE, thumb_png)
    pvalue = pvalue_png = histogram = None
    if tiles is not None and tile:
        pvalue_png = pvalue_thumbnail(tiles, tile, h, w)
        pvalue = imageio.atomic_write_bytes(folder / PVALUE_FILE, pvalue_png)
        histogram = p_histogram(tiles)
    return ViewerData(folder, data, thumbnail, thumb_png, pvalue, pvalue_png, histogram)


#: the largest viewer.js read back: every plane of the largest film the harness renders, in base64 (13 channels of
#: half floats, 4/3 bytes a byte), and its tiles
MAX_SCRIPT_BYTES = MAX_FILM_PIXELS * 36 + 2**20
#: the largest thumbnail read back into a page
_MAX_PNG_BYTES = 4 * 2**20
#: the planes a payload may hold, with their channels and encodings (encode_plane: images as f16, tiles f32 / u8)
_IMAGE_PLANES = {"render": 3, "render_sd": 3, "truth": 3, "truth_sd": 3, "flip": 1}
_BYTES = {"f16": 2, "f32": 4, "u8": 1}


def read_viewer_data(record: dict, results_dir: Path, case_folder: str,
                     notes: list[str] | None = None) -> ViewerData | None:
    """The viewer files a case's record describes (``viewer``), read and checked; None where it describes none (a
    run by an older harness, a case that ended in an error) or a file is missing or not what its name says (the
    report then makes them again). The folder is looked for where the record says, then in
    ``results_dir/cases/<case_folder>`` (a results folder that moved); only inside the run folder ``results_dir``
    (:mod:`harness.files.confined`). viewer.js is parsed (:func:`parse_viewer_script`) and written again
    (``script``), never used as it was found. ``notes``: why a file there was not used (outside the run folder, not
    a PNG, not a viewer.js of the harness), for the report."""
    entry = record.get("viewer")
    if record.get("status") == "error" or not isinstance(entry, dict):
        return None
    names = [entry.get("data"), entry.get("thumbnail")] + ([entry["pvalue"]] if entry.get("pvalue") else [])
    if not all(isinstance(n, str) and n and "/" not in n and "\\" not in n and not n.startswith(".") for n in names):
        return None
    histogram = entry.get("p_histogram") if isinstance(entry.get("p_histogram"), dict) else None
    for candidate in (entry.get("folder"), Path(results_dir) / "cases" / case_folder):
        if not isinstance(candidate, (str, Path)) or not str(candidate):
            continue
        note = outside_note("viewer.folder", candidate, results_dir)
        if note is not None or inside(results_dir, candidate) is None:  # a note where something is there
            _note(notes, note)
            continue
        found = _read_folder(Path(candidate), entry, results_dir, notes)
        if found is not None:
            script, thumb, pvalue_png = found
            folder = Path(candidate)
            pvalue = folder / entry["pvalue"] if entry.get("pvalue") else None
            return ViewerData(folder, folder / entry["data"], folder / entry["thumbnail"], thumb, pvalue,
                              pvalue_png, histogram, script)
    return None


def _read_folder(folder: Path, entry: dict, root: Path, notes: list[str] | None
                 ) -> tuple[str, bytes, bytes | None] | None:
    """(viewer.js written again, the thumbnail, the p-value thumbnail) of the viewer files in ``folder``, each read
    inside the run folder ``root`` and checked; None where one is missing or refused (a note but for a missing
    file)."""
    what = f"viewer files in {str(folder)!r}"
    try:
        thumb = read_inside(root, folder / entry["thumbnail"], kind="png", limit=_MAX_PNG_BYTES)
        pvalue_png = (read_inside(root, folder / entry["pvalue"], kind="png", limit=_MAX_PNG_BYTES)
                      if entry.get("pvalue") else None)
        raw = read_inside(root, folder / entry["data"], limit=MAX_SCRIPT_BYTES)
    except Refused as why:
        if str(why) != "not found":
            _note(notes, f"{what}: {why}: not used")
        return None
    try:
        payload = parse_viewer_script(raw)
    except ValueError as why:
        _note(notes, f"{what}: {entry['data']} is not a viewer.js of the harness ({why}): not used")
        return None
    return viewer_script(payload), thumb, pvalue_png


def _note(notes: list[str] | None, note: str | None) -> None:
    if notes is not None and note is not None and note not in notes:
        notes.append(note)


def _refuse_constant(text: str) -> None:
    raise ValueError(f"{text} is not JSON")


def parse_viewer_script(raw: bytes) -> dict:
    """The payload of a viewer.js (its bytes) checked: exactly the text :func:`viewer_script` writes around strict
    JSON (no NaN or Infinity), the payload's keys and types, each plane's encoding, channels and size for the
    film. Returns the payload rebuilt from the keys it knows (for :func:`viewer_script` to write again); a
    ValueError saying what is wrong otherwise."""
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError:
        raise ValueError("not ASCII text") from None
    if not text.startswith(_SCRIPT_HEAD) or not text.endswith(_SCRIPT_TAIL):
        raise ValueError("not the one call HarnessViewer.register(JSON) the harness writes")
    try:
        doc = json.loads(text[len(_SCRIPT_HEAD):-len(_SCRIPT_TAIL)], parse_constant=_refuse_constant)
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None
    except ValueError as err:
        raise ValueError(f"not JSON: {' '.join(str(err).split())[:80]}") from None
    return _payload(doc)


def _need(ok: bool, what: str) -> None:
    if not ok:
        raise ValueError(what)


def _is_int(value, low: int = 0) -> bool:
    return type(value) is int and value >= low


def _is_number(value) -> bool:
    return type(value) in (int, float) and math.isfinite(value)


def _payload(doc) -> dict:
    """The payload of :func:`make_viewer_data` checked and rebuilt from the keys it has."""
    _need(isinstance(doc, dict) and doc.get("format") == FORMAT, f"expected an object of format {FORMAT}")
    width, height = doc.get("width"), doc.get("height")
    _need(_is_int(width, 1) and _is_int(height, 1) and width * height <= MAX_FILM_PIXELS, "width, height")
    _need(isinstance(doc.get("name"), str) and _is_number(doc.get("exposure")), "name, exposure")
    labels = doc.get("labels")
    _need(isinstance(labels, dict) and all(isinstance(v, str) for v in labels.values()), "labels")
    _need(doc.get("note") is None or isinstance(doc.get("note"), str), "note")
    planes = doc.get("planes")
    _need(isinstance(planes, dict) and "render" in planes and set(planes) <= set(_IMAGE_PLANES), "planes")
    pixels = width * height
    checked = {key: _plane(planes[key], key, pixels, channels, ("f16",))
               for key, channels in _IMAGE_PLANES.items() if key in planes}
    return {"format": FORMAT, "name": doc["name"], "width": width, "height": height, "exposure": doc["exposure"],
            "labels": dict(labels), "planes": checked, "tiles": _tiles(doc.get("tiles"), width, height),
            "note": doc.get("note")}


def _plane(plane, key: str, pixels: int, channels: int, encodings: tuple[str, ...]) -> dict:
    """A plane (:func:`encode_plane`) of ``pixels`` x ``channels`` values checked and rebuilt."""
    _need(isinstance(plane, dict) and plane.get("channels") == channels, f"plane {key}: channels")
    encoding = plane.get("encoding")
    if encoding == "zero":
        return {"encoding": "zero", "channels": channels}
    _need(encoding in encodings, f"plane {key}: encoding")
    data = plane.get("data")
    _need(isinstance(data, str), f"plane {key}: data")
    try:
        size = len(base64.b64decode(data, validate=True))
    except ValueError:
        raise ValueError(f"plane {key}: data is not base64") from None
    _need(size == pixels * channels * _BYTES[encoding], f"plane {key}: {size} bytes for the film")
    out = {"encoding": encoding, "channels": channels}
    if encoding == "f16":
        _need(_is_int(plane.get("exponent"), -2000) and plane["exponent"] <= 2000, f"plane {key}: exponent")
        out["exponent"] = plane["exponent"]
    out["data"] = data
    return out


def _tiles(tiles, width: int, height: int) -> dict | None:
    """The verdict's tiles of a payload (:func:`_tiles_payload`) checked and rebuilt; None for none."""
    if tiles is None:
        return None
    _need(isinstance(tiles, dict) and _is_int(tiles.get("size"), 1), "tiles: size")
    size = tiles["size"]
    rows, cols = tiles.get("rows"), tiles.get("cols")
    _need(rows == math.ceil(height / size) and cols == math.ceil(width / size), "tiles: rows, cols")
    _need(_is_int(tiles.get("count")) and isinstance(tiles.get("recomputed"), bool), "tiles: count, recomputed")
    for key in ("alpha", "threshold", "z_critical"):
        _need(tiles.get(key) is None or _is_number(tiles.get(key)), f"tiles: {key}")
    cells = rows * cols
    planes = {key: _plane(tiles.get(key), f"tiles.{key}", cells, 3, (encoding,))
              for key, encoding in (("z", "f32"), ("p", "f32"), ("tested", "u8"), ("failing", "u8"))}
    return {"size": size, "rows": rows, "cols": cols, **planes, "alpha": tiles.get("alpha"),
            "threshold": tiles.get("threshold"), "count": tiles["count"], "z_critical": tiles.get("z_critical"),
            "recomputed": tiles["recomputed"]}
