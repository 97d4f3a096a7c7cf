"""The neutral values of a Mitsuba plugin dict (:mod:`harness.renderers.mitsuba_spec`), which ``mi.load_dict``
(:func:`harness.renderers.mitsuba.load_dict_form`) and the XML (:mod:`harness.renderers.mitsuba_xml`) each write their
own way, and the ``rgb`` colour every plugin spells the same."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LookAt:
    """A camera's look-at transform: its eye, the point it looks at and its up direction, and where given a scale
    applied before it (``look_at @ scale``: an orthographic sensor's extent)."""

    origin: tuple[float, ...]
    target: tuple[float, ...]
    up: tuple[float, ...]
    scale: tuple[float, ...] | None = None


@dataclass(frozen=True)
class Point:
    """A position (a light's ``position``): transformed with translation."""

    xyz: tuple[float, ...]


@dataclass(frozen=True)
class Vector:
    """A direction (a light's ``direction``): transformed without translation."""

    xyz: tuple[float, ...]


@dataclass(frozen=True)
class Parameter:
    """A value the XML names as ``$name`` and whose reader may override it; ``default`` where nobody does."""

    name: str
    default: int


@dataclass(frozen=True, eq=False)
class MeshFile:
    """A shape's triangles (world space, wound to face the front side) and the PLY file they become in an export.

    Attributes
    ----------
    name : str
        The shape's name.
    path : str
        The file's path relative to the exported scene file.
    vertices, triangles : numpy.ndarray
        (V, 3) float64 positions and (T, 3) vertex indices.
    uv : numpy.ndarray, optional
        (V, 2) texture coordinates (Mitsuba's: v = 0 the image's top row), for a textured shape.
    normals : numpy.ndarray, optional
        (V, 3) unit vertex normals (world space), for a smooth-shaded shape; None: flat (``face_normals``).
    """

    name: str
    path: str
    vertices: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray | None = None
    normals: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class ImageFile:
    """An image's pixels, row 0 the top, and the file they become in an export: float32 linear RGB (an environment
    map, an EXR texture) an OpenEXR file, uint8 codes (an 8-bit texture) a PNG file. ``mi.load_dict`` gets them as
    the plugin's ``bitmap`` (an ``mi.Bitmap`` of the same pixels: Mitsuba decodes an 8-bit one's sRGB codes as it
    decodes a PNG's)."""

    path: str
    image: np.ndarray


@dataclass(frozen=True, eq=False)
class UVTransform:
    """A texture's ``to_uv``: a 3x3 affine map of the plane (its last row 0, 0, 1)."""

    matrix: np.ndarray

    def as_4x4(self) -> np.ndarray:
        """The map as Mitsuba's XML reads a ``to_uv`` ``<matrix>``: rows and columns 0, 1 and 3 of a 4x4 (a 3x3
        ``<matrix>`` would be read as the linear part of a 4x4, its translation dropped)."""
        out = np.eye(4)
        out[np.ix_([0, 1, 3], [0, 1, 3])] = self.matrix
        return out


def rgb(values) -> dict:
    """Mitsuba's ``rgb`` colour of three numbers."""
    return {"type": "rgb", "value": floats(values)}


def floats(values) -> list[float]:
    """``values`` as a list of Python floats."""
    return [float(x) for x in values]


def xyz(values) -> tuple[float, ...]:
    """``values`` as a tuple of Python floats (a :class:`Point`'s or :class:`Vector`'s)."""
    return tuple(float(x) for x in values)


def matrix(values) -> np.ndarray:
    """A transform as a float64 array."""
    return np.asarray(values, dtype=np.float64)
