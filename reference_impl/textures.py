"""The textures of the core: Mitsuba 3's ``bitmap`` and ``checkerboard``, as plain arrays the material step reads
(:mod:`reference_impl.kernels.texture`).

A texture maps a surface's texture coordinates (u, v) to an RGB value. Both kinds first map (u, v) by their
``to_uv``, an affine 3x3 matrix (its last row 0, 0, 1): (u', v', 1) = to_uv (u, v, 1). Then

* a bitmap of W x H texels, row 0 the image's top row, is read at the texel space point (u' W, v' H): ``nearest``
  takes the texel that point falls in, ``bilinear`` weighs the four texels whose centres (i + 1/2, j + 1/2) surround
  it; an index outside the image is wrapped (``repeat``: modulo the size, ``mirror``: reflected at each edge,
  ``clamp``: the nearest edge texel), each axis on its own. An 8-bit image that is not ``raw`` holds sRGB codes,
  decoded to linear values once, before any filtering (:func:`srgb_to_linear`, as Mitsuba decodes when it loads
  it);
* a checkerboard is ``color0`` where u' mod 1 and v' mod 1 are both at most 1/2 or both above 1/2, ``color1``
  elsewhere.

Mitsuba 3.9.1's ``src/textures/bitmap.cpp`` and ``checkerboard.cpp`` define these; tests/reference_impl/test_textures.py
checks every lookup against Mitsuba's own texture objects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_impl.errors import SettingsError

BITMAP, CHECKERBOARD = 0, 1
NEAREST, BILINEAR = 0, 1
FILTERS = {"nearest": NEAREST, "bilinear": BILINEAR}
REPEAT, MIRROR, CLAMP = 0, 1, 2
WRAPS = {"repeat": REPEAT, "mirror": MIRROR, "clamp": CLAMP}
#: The luminance weights of a linear RGB value (Mitsuba's ``luminance``: Rec. 709 primaries), a bitmap's one number.
LUMINANCE = (0.212671, 0.715160, 0.072169)


def srgb_to_linear(codes) -> np.ndarray:
    r"""The sRGB EOTF of 8-bit codes (IEC 61966-2-1): float64 linear values in [0, 1].

    .. math::

        L = \begin{cases} V / 12.92 & V \le 0.04045 \\ ((V + 0.055) / 1.055)^{2.4} & V > 0.04045 \end{cases},
        \quad V = \mathrm{code} / 255
    """
    v = np.asarray(codes, dtype=np.float64) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _affine(to_uv, key: str) -> np.ndarray:
    matrix = np.asarray(to_uv if to_uv is not None else np.eye(3), dtype=np.float64)
    if matrix.shape != (3, 3) or not np.all(np.isfinite(matrix)):
        raise SettingsError(key, "expected a finite 3x3 matrix")
    if not np.array_equal(matrix[2], (0.0, 0.0, 1.0)):
        raise SettingsError(key, "expected an affine map of the plane (last row 0, 0, 1)")
    return matrix


@dataclass(frozen=True, eq=False)
class Bitmap:
    """Mitsuba's ``bitmap`` texture.

    Attributes
    ----------
    image : (H, W, 3) array
        The texels, row 0 the image's top row: 8-bit codes (uint8) or linear values (float).
    filter_type : str
        ``"bilinear"`` or ``"nearest"``.
    wrap_mode : str
        ``"repeat"``, ``"mirror"`` or ``"clamp"``.
    srgb : bool
        The texels are 8-bit sRGB codes, decoded by :func:`srgb_to_linear` (Mitsuba's ``raw = false`` on an 8-bit
        image); False: uint8 codes are taken as code / 255, floats as they are.
    to_uv : (3, 3) array
        The affine map of the texture coordinates.
    """

    image: np.ndarray
    filter_type: str = "bilinear"
    wrap_mode: str = "repeat"
    srgb: bool = False
    to_uv: np.ndarray | None = None

    def __post_init__(self) -> None:
        image = np.asarray(self.image)
        if image.ndim != 3 or image.shape[2] != 3 or image.shape[0] < 1 or image.shape[1] < 1:
            raise SettingsError("texture.image", f"expected an (H, W, 3) array, got {image.shape}")
        if image.dtype != np.uint8:
            image = np.asarray(image, dtype=np.float64)
            if not np.all(np.isfinite(image)) or np.any(image < 0):
                raise SettingsError("texture.image", "expected finite values >= 0")
            if self.srgb:
                raise SettingsError("texture.srgb", "sRGB decoding applies to 8-bit images only")
        if self.filter_type not in FILTERS:
            raise SettingsError("texture.filter_type", f"expected one of {', '.join(FILTERS)}")
        if self.wrap_mode not in WRAPS:
            raise SettingsError("texture.wrap_mode", f"expected one of {', '.join(WRAPS)}")
        object.__setattr__(self, "image", image)
        object.__setattr__(self, "to_uv", _affine(self.to_uv, "texture.to_uv"))

    def linear(self, srgb_as_linear: bool = False) -> np.ndarray:
        """The texels as linear float64 values, (H, W, 3); ``srgb_as_linear``: an sRGB image's codes taken as
        code / 255 (the planted fault "texture-srgb-as-linear")."""
        if self.image.dtype != np.uint8:
            return self.image
        if self.srgb and not srgb_as_linear:
            return srgb_to_linear(self.image)
        return self.image.astype(np.float64) / 255.0

    def values(self) -> np.ndarray:
        """Every value a lookup interpolates between, (N, 3) linear RGB: the texels."""
        return self.linear().reshape(-1, 3)


@dataclass(frozen=True, eq=False)
class Checkerboard:
    """Mitsuba's ``checkerboard`` texture: ``color0`` and ``color1`` (RGB) in squares of 1/2 of the (mapped)
    texture coordinates."""

    color0: tuple = (0.4, 0.4, 0.4)
    color1: tuple = (0.2, 0.2, 0.2)
    to_uv: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ("color0", "color1"):
            colour = np.asarray(getattr(self, name), dtype=np.float64)
            if colour.shape != (3,) or not np.all(np.isfinite(colour)) or np.any(colour < 0):
                raise SettingsError(f"texture.{name}", "expected 3 finite numbers >= 0")
            object.__setattr__(self, name, tuple(float(c) for c in colour))
        object.__setattr__(self, "to_uv", _affine(self.to_uv, "texture.to_uv"))

    def values(self) -> np.ndarray:
        """Every value a lookup takes, (2, 3) linear RGB: ``color0`` and ``color1``."""
        return np.array([self.color0, self.color1])


Texture = Bitmap | Checkerboard


def scalar_values(item: Texture) -> np.ndarray:
    """Every value ``item`` takes as one number (Mitsuba's ``eval_1``, a one-channel parameter such as ``alpha``): a
    bitmap's texels' luminance 0.212671 r + 0.715160 g + 0.072169 b, a checkerboard colour's mean; their least and
    largest bound every lookup."""
    if isinstance(item, Checkerboard):
        return item.values().mean(axis=1)
    return item.values() @ np.array(LUMINANCE)


@dataclass(frozen=True, eq=False)
class Textures:
    """A scene's textures, in the order the materials name them (:attr:`reference_impl.Materials.texture`).

    Attributes
    ----------
    items : tuple of Bitmap or Checkerboard
    """

    items: tuple = ()

    def __post_init__(self) -> None:
        items = tuple(self.items)
        for i, item in enumerate(items):
            if not isinstance(item, (Bitmap, Checkerboard)):
                raise SettingsError(f"textures[{i}]", "expected a Bitmap or a Checkerboard")
        object.__setattr__(self, "items", items)

    def __len__(self) -> int:
        return len(self.items)

    def scalar_range(self, k: int) -> tuple[float, float]:
        """The least and the largest one-number value of texture ``k`` (:func:`scalar_values`), the bounds of every
        lookup."""
        values = scalar_values(self.items[k])
        return float(np.min(values)), float(np.max(values))

    def max_value(self, k: int) -> np.ndarray:
        """The largest value texture ``k`` takes, per channel (a bound of every lookup: filtering interpolates)."""
        return self.items[k].values().max(axis=0)
