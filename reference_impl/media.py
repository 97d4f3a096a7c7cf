"""The participating media of a scene, as plain arrays the volumetric path loop reads (:mod:`.kernels.volpath`).

Each medium is Mitsuba 3's ``homogeneous`` plugin: an extinction coefficient sigma_t per channel (per unit length,
Mitsuba's ``sigma_t`` times its ``scale``, already multiplied here), a single-scattering albedo per channel
(sigma_s = albedo sigma_t, sigma_a = (1 - albedo) sigma_t) and a phase function, isotropic or Henyey-Greenstein
with asymmetry g (:mod:`.kernels.phase`).

Which medium a ray is in follows Mitsuba's rule (``SurfaceInteraction::target_medium``): a surface is a medium
transition when its shape names an ``interior`` or an ``exterior`` medium; a ray that leaves such a surface along d
is in its exterior medium where d . N > 0 (N the front geometric normal), else in its interior one, -1 (vacuum)
where the shape names none on that side. A ray that leaves a surface that is no transition stays in the medium it
came in. The camera's rays start in ``camera`` (-1: vacuum).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_impl.errors import SettingsError

ISOTROPIC, HG = 0, 1
#: Mitsuba's plugin name of each phase function
PHASE_NAMES = {ISOTROPIC: "isotropic", HG: "hg"}
#: Mitsuba's ``homogeneous`` defaults
DEFAULT_ALBEDO = (0.75, 0.75, 0.75)
DEFAULT_SIGMA_T = 1.0
DEFAULT_SCALE = 1.0
DEFAULT_G = 0.0
#: the largest sigma_t (per unit length) the core takes: a free flight shorter than a ray's offset is meaningless
MAX_SIGMA_T = 1e8


@dataclass(frozen=True, eq=False)
class Media:
    """The media of a scene and the medium transitions of its triangles.

    Attributes
    ----------
    sigma_t : (M, 3) float64
        Extinction per unit length, per channel, >= 0 (Mitsuba's ``sigma_t`` x ``scale``).
    albedo : (M, 3) float64
        Single-scattering albedo per channel, in [0, 1].
    phase : (M,) int64
        :data:`ISOTROPIC` or :data:`HG`.
    g : (M,) float64
        HG's asymmetry in (-1, 1) (0 for isotropic).
    interior : (T,) int64
        Per triangle (``Geometry``'s order, spheres' stand-ins included): the medium on the back side of its front
        normal, -1 for none.
    exterior : (T,) int64
        Per triangle: the medium on the front side, -1 for none.
    transition : (T,) bool
        Per triangle: whether its shape names an interior or an exterior medium (Mitsuba's
        ``is_medium_transition``); a ray leaving it is in ``exterior`` or ``interior`` by its side.
    camera : int
        The medium the camera's rays start in, -1 for none.
    names : tuple of str
        The media's names (messages only).
    """

    sigma_t: np.ndarray
    albedo: np.ndarray
    phase: np.ndarray
    g: np.ndarray
    interior: np.ndarray
    exterior: np.ndarray
    transition: np.ndarray
    camera: int = -1
    names: tuple = ()

    def __post_init__(self) -> None:
        sigma_t = np.ascontiguousarray(self.sigma_t, dtype=np.float64).reshape(-1, 3)
        m = len(sigma_t)
        albedo = np.ascontiguousarray(self.albedo, dtype=np.float64).reshape(-1, 3)
        phase = np.ascontiguousarray(self.phase, dtype=np.int64).reshape(-1)
        g = np.ascontiguousarray(self.g, dtype=np.float64).reshape(-1)
        if albedo.shape != (m, 3) or phase.shape != (m,) or g.shape != (m,):
            raise SettingsError("media", f"expected {m} rows of sigma_t, albedo, phase and g alike")
        if not (np.all(np.isfinite(sigma_t)) and np.all(sigma_t >= 0) and np.all(sigma_t <= MAX_SIGMA_T)):
            raise SettingsError("media.sigma_t", f"expected finite values in [0, {MAX_SIGMA_T:g}]")
        if not (np.all(np.isfinite(albedo)) and np.all((albedo >= 0) & (albedo <= 1))):
            raise SettingsError("media.albedo", "expected values in [0, 1]")
        if not np.all(np.isin(phase, list(PHASE_NAMES))):
            raise SettingsError("media.phase", f"expected {ISOTROPIC} (isotropic) or {HG} (hg)")
        if not (np.all(np.isfinite(g)) and np.all(np.abs(g) < 1)):
            raise SettingsError("media.g", "expected values in (-1, 1)")
        interior = np.ascontiguousarray(self.interior, dtype=np.int64).reshape(-1)
        exterior = np.ascontiguousarray(self.exterior, dtype=np.int64).reshape(-1)
        transition = np.ascontiguousarray(self.transition, dtype=bool).reshape(-1)
        if not (interior.shape == exterior.shape == transition.shape):
            raise SettingsError("media.interior", "expected interior, exterior and transition of one length")
        for key, ids in (("interior", interior), ("exterior", exterior)):
            if ids.size and (ids.min() < -1 or ids.max() >= m):
                raise SettingsError(f"media.{key}", f"expected medium ids in [-1, {m - 1}]")
        if not (isinstance(self.camera, (int, np.integer)) and -1 <= int(self.camera) < m):
            raise SettingsError("media.camera", f"expected a medium id in [-1, {m - 1}]")
        for name, value in (("sigma_t", sigma_t), ("albedo", albedo), ("phase", phase), ("g", g),
                            ("interior", interior), ("exterior", exterior), ("transition", transition)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "camera", int(self.camera))
        object.__setattr__(self, "names", tuple(self.names))

    def __len__(self) -> int:
        return len(self.sigma_t)

    def check_triangles(self, num_triangles: int) -> None:
        """SettingsError unless the transitions cover ``num_triangles`` triangles (the geometry's)."""
        if len(self.interior) != num_triangles:
            raise SettingsError("media.interior", f"expected one entry per triangle ({num_triangles}), "
                                f"got {len(self.interior)}")


__all__ = ["DEFAULT_ALBEDO", "DEFAULT_G", "DEFAULT_SCALE", "DEFAULT_SIGMA_T", "HG", "ISOTROPIC", "MAX_SIGMA_T",
           "Media", "PHASE_NAMES"]
