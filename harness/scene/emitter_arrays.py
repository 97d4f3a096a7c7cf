"""Turn a :class:`Scene`'s emitters that are not shapes (``Scene.emitters``: point, spot, directional, constant,
envmap) into the core's :class:`reference_impl.Emitters` (the arrays the reference renderer takes beside the
triangles of :func:`harness.scene.triangulate`)."""

from __future__ import annotations

import reference_impl
from reference_impl.errors import SettingsError

from harness.core.errors import HarnessError
from harness.scene.kinds.emitters import EMITTERS
from harness.scene.model import Emitter, Scene


def core_record(emitter: Emitter):
    """The core's record of one emitter of the scene model (its type's
    :attr:`~harness.scene.kinds.emitters.EmitterKind.to_core`)."""
    return EMITTERS[emitter.type].to_core(emitter)


def emitter_arrays(scene: Scene) -> reference_impl.Emitters | None:
    """``scene.emitters`` as the core's arrays, or None for a scene without them (which then renders exactly as it
    did before such emitters existed)."""
    if not scene.emitters:
        return None
    try:
        return reference_impl.Emitters([core_record(e) for e in scene.emitters])
    except SettingsError as err:
        # The core names the emitter by its position; the file names it by its entry of [[emitters]].
        raise HarnessError(str(scene.path), f"cannot use the emitters: {err.key}: {err.message}") from err
