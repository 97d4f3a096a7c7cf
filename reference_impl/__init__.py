"""An independent Monte Carlo path tracer: the stochastic global-illumination algorithm of the slides (Fig. 5.16).

Pure core: plain arrays in (:class:`Geometry`, :class:`Camera`, :class:`Film`, :class:`Settings`), arrays and
counters out (:class:`RenderOutput`). It imports neither ``harness`` nor ``mitsuba``.
"""

from reference_impl.camera import Camera, Film
from reference_impl.errors import SettingsError
from reference_impl.geometry import Geometry
from reference_impl.integrator import RenderOutput, render
from reference_impl.settings import Settings

__all__ = ["Camera", "Film", "Geometry", "RenderOutput", "Settings", "SettingsError", "render"]
