"""An independent Monte Carlo path tracer: the stochastic global-illumination algorithm of the slides (Fig. 5.16).

Pure core: plain arrays in (:class:`Geometry`, :class:`Camera`, :class:`Film`, :class:`Settings`, and the emitters
that are not surfaces, :class:`Emitters` of :class:`Point`, :class:`Spot`, :class:`Directional`, :class:`Constant`,
:class:`EnvMap` records, and the non-Lambertian materials, :class:`Materials`), arrays and
counters out (:class:`RenderOutput`). It imports neither ``harness`` nor ``mitsuba``.
"""

from reference_impl.camera import Camera, Film
from reference_impl.emitters import Constant, Directional, Emitters, EnvMap, Point, Spot
from reference_impl.errors import SettingsError
from reference_impl.geometry import Geometry
from reference_impl.integrator import RenderOutput, render
from reference_impl.materials import Materials
from reference_impl.settings import Settings

__all__ = ["Camera", "Constant", "Directional", "Emitters", "EnvMap", "Film", "Geometry", "Materials", "Point",
           "RenderOutput",
           "Settings", "SettingsError", "Spot", "render"]
