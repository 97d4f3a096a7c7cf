"""Turn a :class:`Scene`'s ``[media.NAME]`` tables and its shapes' ``interior`` / ``exterior`` into the core's
:class:`reference_impl.media.Media`: one row per medium (the file's order) and one entry per triangle of
:func:`harness.scene.triangulate` (spheres' stand-in triangles included, which carry the sphere's media)."""

from __future__ import annotations

import numpy as np

from reference_impl.errors import SettingsError
from reference_impl.media import Media

from harness.core.errors import HarnessError
from harness.scene.kinds.media import MEDIA
from harness.scene.model import Scene
from harness.scene.triangulate import shape_triangles


def media_arrays(scene: Scene, geometry=None) -> Media | None:
    """The core's media of ``scene``, or None for a scene without ``[media]`` (a ``null`` material alone needs
    none: every ray stays in vacuum).

    Parameters
    ----------
    scene : Scene
        The loaded scene.
    geometry : reference_impl.geometry.Geometry, optional
        Its triangulation, whose triangle count the per-triangle arrays must match (checked where given).
    """
    if not scene.media:
        return None
    number = {name: m for m, name in enumerate(scene.media)}
    rows = [MEDIA[medium.type].to_core(medium) for medium in scene.media.values()]
    interior, exterior, transition = [], [], []
    for shape in scene.shapes:
        count = len(shape_triangles(shape)[1])  # the order and count of triangulate()'s triangles
        interior.append(np.full(count, number.get(shape.interior, -1), dtype=np.int64))
        exterior.append(np.full(count, number.get(shape.exterior, -1), dtype=np.int64))
        transition.append(np.full(count, shape.is_medium_transition, dtype=bool))

    def joined(parts, dtype):
        return np.concatenate(parts) if parts else np.zeros(0, dtype=dtype)

    try:
        media = Media(sigma_t=np.array([r["sigma_t"] for r in rows], dtype=np.float64),
                      albedo=np.array([r["albedo"] for r in rows], dtype=np.float64),
                      phase=np.array([r["phase"] for r in rows], dtype=np.int64),
                      g=np.array([r["g"] for r in rows], dtype=np.float64),
                      interior=joined(interior, np.int64), exterior=joined(exterior, np.int64),
                      transition=joined(transition, bool),
                      camera=number.get(scene.camera_medium, -1), names=tuple(scene.media))
        if geometry is not None:
            media.check_triangles(len(geometry.triangles))
    except SettingsError as err:
        raise HarnessError(str(scene.path), f"cannot use the media: {err.key}: {err.message}") from err
    return media
