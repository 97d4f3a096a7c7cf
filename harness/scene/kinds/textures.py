"""The texture types of a ``[textures.NAME]`` table (Mitsuba's texture plugins of the same names and parameters,
docs/scene-format.md, "Textures"), one :class:`TextureKind` each in :data:`TEXTURES`: its keys and their reading, its
Mitsuba plugin and its scene.json entry (the core's object is the model's
:attr:`~harness.scene.model.Texture.core`); and the reading of a material parameter that takes
``{ texture = "NAME" }`` in place of a value (:func:`texture_reference`)."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from harness.core.errors import HarnessError, read_user_bytes
from harness.files.imageio import exr_size, read_exr
from harness.scene.kinds.mitsuba_values import ImageFile, UVTransform, rgb
from harness.scene.model import FILTER_TYPES, TEXTURE_TYPES, WRAP_MODES, Texture

DEFAULT_TYPE = "bitmap"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr")
# A texture is held as (H, W, 3) texels, float64 in the reference's tables (24 B per texel) and again in Mitsuba:
# 4096 x 4096 at most (384 MiB as float64), and 256 MiB of file.
MAX_TEXTURE_PIXELS = 2**24
MAX_TEXTURE_BYTES = 2**28
TO_UV_KEYS = ("translate", "scale", "rotate")
TEXTURE_DIR = "textures"  # where an export writes the texture files (beside its meshes)


@dataclass(frozen=True)
class TextureKind:
    """One texture type.

    Attributes
    ----------
    name : str
        The ``type`` value (Mitsuba's plugin name).
    keys : tuple of str
        The keys its table may hold.
    read : callable
        ``read(reader, entry, key) -> dict``: the :class:`~harness.scene.model.Texture` fields of its keys but
        ``name``, ``type`` and ``to_uv``.
    parameters : callable
        ``parameters(texture, path)``: its Mitsuba plugin's parameters, every one written out; ``path`` is the
        file's name in an export.
    json : callable
        ``json(texture, path)``: its parameters in the scene.json entry.
    """

    name: str
    keys: tuple[str, ...]
    read: Callable[[Any, dict, str], dict]
    parameters: Callable[[Texture, str], dict]
    json: Callable[[Texture, str], dict]

    def to_mitsuba(self, texture: Texture) -> dict:
        """Mitsuba's dict of ``texture``: its plugin, ``to_uv`` and every parameter written out."""
        return {"type": self.name, **self.parameters(texture, export_path(texture)),
                "to_uv": UVTransform(np.asarray(texture.to_uv, dtype=np.float64))}

    def to_scene_json(self, texture: Texture) -> dict:
        """The scene.json entry of ``texture``."""
        return {"type": self.name, **self.json(texture, export_path(texture)),
                "to_uv": np.asarray(texture.to_uv, dtype=np.float64).tolist()}


def export_path(texture: Texture) -> str:
    """The file a bitmap's pixels become in an export, or "" for a texture without one:
    ``textures/texture-<name>.png`` for an 8-bit image (a JPEG's decoded codes too: the pixels the scene holds, not
    the file's bytes), ``.exr`` for a float one."""
    if texture.image is None:
        return ""
    suffix = ".png" if texture.image.dtype == np.uint8 else ".exr"
    return f"{TEXTURE_DIR}/texture-{_safe(texture.name)}{suffix}"


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)[:64] or "texture"


def read_texture(reader, name: str, entry: Any) -> Texture:
    """One ``[textures.NAME]`` table: its type (default bitmap), that type's parameters and ``to_uv``."""
    key = reader.join("textures", name)
    entry = reader.table(entry, key)
    reader.check_keys(entry, TEXTURE_KEYS, key)
    kind = TEXTURES[reader.choice(entry.get("type", DEFAULT_TYPE), f"{key}.type", TEXTURE_TYPES)]
    for item in entry:
        if item not in kind.keys:
            owners = " or ".join(repr(t) for t, other in TEXTURES.items() if item in other.keys)
            raise reader.error(f"{key}.{item}", f"key {item!r} applies only to textures of type {owners}, "
                                                f"not {kind.name!r}")
    to_uv = read_to_uv(reader, entry.get("to_uv"), f"{key}.to_uv")
    return Texture(name, kind.name, to_uv, **kind.read(reader, entry, key))


def read_to_uv(reader, value: Any, key: str) -> np.ndarray:
    """``to_uv``: a 3x3 matrix (rows; the last 0, 0, 1), or a table ``{translate = [x, y], rotate = degrees,
    scale = s or [s_u, s_v]}`` composed as T R S (scale first, as a shape's placement); the identity if absent."""
    if value is None:
        return np.eye(3)
    if isinstance(value, dict):
        reader.check_keys(value, TO_UV_KEYS, key)
        tu, tv = _pair(reader, value.get("translate", [0.0, 0.0]), f"{key}.translate")
        raw_scale = value.get("scale", 1.0)
        su, sv = (_pair(reader, raw_scale, f"{key}.scale") if isinstance(raw_scale, list)
                  else (reader.number(raw_scale, f"{key}.scale"),) * 2)
        angle = math.radians(reader.number(value.get("rotate", 0.0), f"{key}.rotate", "an angle in degrees"))
        c, s = math.cos(angle), math.sin(angle)
        matrix = np.array([[1.0, 0, tu], [0, 1, tv], [0, 0, 1]]) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) \
            @ np.diag([su, sv, 1.0])
    else:
        what = "a 3x3 matrix (a list of 3 rows of 3 finite numbers, the last row [0, 0, 1]) or a table " \
               "{translate, rotate, scale}"
        rows = value if isinstance(value, list) and len(value) == 3 else None
        if rows is None or not all(isinstance(r, list) and len(r) == 3 for r in rows):
            raise reader.expected(key, what, value)
        matrix = np.array([[reader.number(x, key, what) for x in row] for row in rows], dtype=np.float64)
        if not np.array_equal(matrix[2], (0.0, 0.0, 1.0)):
            raise reader.expected(key, what, value)
    if not np.all(np.isfinite(matrix)):
        raise reader.error(key, "the map overflows (non-finite entries)")
    return matrix + 0.0


def _pair(reader, value: Any, key: str) -> tuple[float, float]:
    what = "a list of 2 finite numbers"
    if not isinstance(value, list) or len(value) != 2:
        raise reader.expected(key, what, value)
    return reader.number(value[0], key, what), reader.number(value[1], key, what)


def texture_reference(reader, value: Any, key: str, textures: dict[str, Texture]) -> Texture | None:
    """The texture a material parameter names (``{ texture = "NAME" }``), or None where ``value`` is no table."""
    if not isinstance(value, dict):
        return None
    reader.check_keys(value, ("texture",), key)
    name = reader.string(reader.require(value, "texture", key, "the name of a [textures] table"), f"{key}.texture")
    if name not in textures:
        defined = ", ".join(repr(t) for t in textures) or "none"
        raise reader.error(f"{key}.texture", f"unknown texture {name!r} (defined in [textures]: {defined})")
    return textures[name]


# ---- bitmap --------------------------------------------------------------------------------------------------------


def _read_bitmap(reader, entry: dict, key: str) -> dict:
    file_key = f"{key}.filename"
    name = reader.string(reader.require(entry, "filename", key, "a PNG, JPEG or EXR file name"), file_key)
    if not name.lower().endswith(IMAGE_SUFFIXES):
        raise reader.expected(file_key, "a .png, .jpg, .jpeg or .exr file name", name)
    path = reader.file_path(name, file_key, "texture")
    try:
        image = read_image(path, name)
    except HarnessError as err:
        raise reader.error(file_key, err.message) from None
    raw = reader.boolean(entry.get("raw", False), f"{key}.raw")
    return {"file": path, "image": image, "raw": raw,
            "filter_type": reader.choice(entry.get("filter_type", "bilinear"), f"{key}.filter_type", FILTER_TYPES),
            "wrap_mode": reader.choice(entry.get("wrap_mode", "repeat"), f"{key}.wrap_mode", WRAP_MODES)}


def read_image(path, name: str) -> np.ndarray:
    """The texels of an image file: (H, W, 3) uint8 codes of an 8-bit PNG or JPEG (grey replicated, alpha dropped,
    a palette expanded), float32 linear RGB of an OpenEXR file. HarnessError (its message alone is used) for a file
    that is not such an image or is larger than :data:`MAX_TEXTURE_PIXELS`."""
    if str(name).lower().endswith(".exr"):
        width, height = exr_size(path, max_pixels=MAX_TEXTURE_PIXELS)
        if width * height > MAX_TEXTURE_PIXELS:
            raise HarnessError(str(path), _too_large(name, width, height))
        image = np.asarray(read_exr(path, max_pixels=MAX_TEXTURE_PIXELS).image, dtype=np.float32)
        if not np.all(np.isfinite(image)) or np.any(image < 0):
            raise HarnessError(str(path), f"texture file {name!r} has pixels that are negative or not finite")
        return image
    data = read_user_bytes(path, missing="no such texture file", limit=MAX_TEXTURE_BYTES)
    from PIL import Image  # optional: ~12 ms of every process's start; only an 8-bit texture's scene needs it

    try:
        with Image.open(io.BytesIO(data)) as picture:
            width, height = picture.size
            if width * height > MAX_TEXTURE_PIXELS:
                raise HarnessError(str(path), _too_large(name, width, height))
            if picture.format not in ("PNG", "JPEG"):
                raise HarnessError(str(path), f"texture file {name!r} is a {picture.format} image; expected PNG or "
                                              "JPEG")
            if picture.mode not in ("1", "L", "LA", "P", "PA", "RGB", "RGBA"):
                raise HarnessError(str(path), f"texture file {name!r} has {picture.mode} pixels; expected an 8-bit "
                                              "image (grey, RGB or RGBA) or an OpenEXR file")
            image = np.asarray(picture.convert("RGB"), dtype=np.uint8)
    except HarnessError:
        raise
    except Exception as err:  # Pillow raises many kinds of exceptions for broken files
        reason = " ".join(str(err).split()) or type(err).__name__
        raise HarnessError(str(path), f"cannot read the texture file {name!r}: {reason[:200]}") from None
    return np.ascontiguousarray(image.reshape(height, width, 3))


def _too_large(name: str, width: int, height: int) -> str:
    return (f"texture file {name!r} is {width} x {height} pixels; expected at most {MAX_TEXTURE_PIXELS} pixels "
            "(4096 x 4096)")


def _bitmap_parameters(texture: Texture, path: str) -> dict:
    return {"filename": ImageFile(path, texture.image), "filter_type": texture.filter_type,
            "wrap_mode": texture.wrap_mode, "raw": bool(texture.raw)}


def _bitmap_json(texture: Texture, path: str) -> dict:
    return {"filename": path, "filter_type": texture.filter_type, "wrap_mode": texture.wrap_mode,
            "raw": bool(texture.raw)}


# ---- checkerboard --------------------------------------------------------------------------------------------------


def _read_checkerboard(reader, entry: dict, key: str) -> dict:
    what = "a number or a list of 3 numbers, each >= 0"
    colours = {}
    for item, default in (("color0", Texture.color0), ("color1", Texture.color1)):
        colours[item] = reader.colour_or_number(entry.get(item, list(default)), f"{key}.{item}", what)
        if min(colours[item]) < 0:
            raise reader.expected(f"{key}.{item}", what, entry[item])
    return colours


TEXTURES: dict[str, TextureKind] = {kind.name: kind for kind in (
    TextureKind("bitmap", ("type", "filename", "filter_type", "wrap_mode", "raw", "to_uv"), _read_bitmap,
                _bitmap_parameters, _bitmap_json),
    TextureKind("checkerboard", ("type", "color0", "color1", "to_uv"), _read_checkerboard,
                lambda t, path: {"color0": rgb(t.color0), "color1": rgb(t.color1)},
                lambda t, path: {"color0": list(map(float, t.color0)), "color1": list(map(float, t.color1))}),
)}
assert tuple(TEXTURES) == TEXTURE_TYPES
#: Every key of any type, for did-you-mean hints.
TEXTURE_KEYS = tuple(dict.fromkeys(key for kind in TEXTURES.values() for key in kind.keys))
