"""Turn a :class:`Scene`'s emitters that are not shapes (``Scene.emitters``: point, spot, directional, constant,
envmap) into the core's :class:`reference_impl.Emitters` (the arrays the reference renderer takes beside the
triangles of :func:`harness.scene.triangulate`)."""

from __future__ import annotations

import numpy as np

import reference_impl
from reference_impl.errors import SettingsError

from harness.core.errors import HarnessError
from harness.scene.model import (ConstantEnvironment, DirectionalLight, Emitter, EnvironmentMap, PointLight, Scene,
                                 SpotLight)


def core_record(emitter: Emitter):
    """The core's record of one emitter of the scene model (same parameters, Mitsuba's meaning)."""
    if isinstance(emitter, PointLight):
        return reference_impl.Point(position=emitter.position, intensity=emitter.intensity)
    if isinstance(emitter, SpotLight):
        return reference_impl.Spot(to_world=np.asarray(emitter.to_world, dtype=np.float64),
                                   intensity=emitter.intensity, cutoff_angle=emitter.cutoff_angle,
                                   beam_width=emitter.beam_width)
    if isinstance(emitter, DirectionalLight):
        return reference_impl.Directional(direction=emitter.direction, irradiance=emitter.irradiance)
    if isinstance(emitter, ConstantEnvironment):
        return reference_impl.Constant(radiance=emitter.radiance)
    if isinstance(emitter, EnvironmentMap):
        return reference_impl.EnvMap(image=emitter.image, to_world=np.asarray(emitter.to_world, dtype=np.float64),
                                     scale=emitter.scale)
    raise TypeError(f"not an emitter of the scene model: {type(emitter).__name__}")


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
