"""The scene as Mitsuba 3 plugins: one nested dict in ``mi.load_dict``'s form, built from the loaded scene.

:func:`harness.renderers.mitsuba_xml.spec_xml` writes it as XML. A plugin is a dict with a ``type``; its properties
are bools, ints, floats, strings, ``{"type": "rgb", "value": [r, g, b]}`` colours, ``{"type": "ref", "id": key}``
references to a top-level plugin, nested plugins, and these neutral values, which each form writes its own way:

* a 4x4 float64 ``numpy`` array: a transform (``to_world``);
* :class:`LookAt`: the camera's look-at transform;
* :class:`Point`, :class:`Vector`: a position and a direction;
* :class:`Parameter`: a value the XML leaves to its reader (``$spp``), with its default;
* :class:`MeshFile`, :class:`ImageFile`: a mesh's triangles and an environment map's pixels, with the file each
  becomes in an export.

Keys: ``bsdf_<j>`` for material j (file order), ``shape_<i>`` for shape i, ``emitter_<k>`` for ``[[emitters]]``
entry k (docs/mitsuba.md, "Scene conversion").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class LookAt:
    """A camera's look-at transform: its eye, the point it looks at and its up direction."""

    origin: tuple[float, ...]
    target: tuple[float, ...]
    up: tuple[float, ...]


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
    """

    name: str
    path: str
    vertices: np.ndarray
    triangles: np.ndarray


@dataclass(frozen=True, eq=False)
class ImageFile:
    """An environment map's pixels (float32 linear RGB, row 0 the top) and the EXR file they become in an export."""

    path: str
    image: np.ndarray


@dataclass(frozen=True)
class MitsubaSpec:
    """The scene as Mitsuba plugins.

    Attributes
    ----------
    plugins : dict
        ``{"type": "scene", key: plugin, ...}``, in ``mi.load_dict``'s form with the neutral values above.
    comments : dict
        What each top-level key stands for in the scene file (``"shape 3: floor"``), for a reader of the XML.
    """

    plugins: dict
    comments: dict = field(default_factory=dict)
