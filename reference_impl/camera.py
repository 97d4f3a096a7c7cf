"""The cameras and the film: primary rays through the pixel filter h (slides, Fig. 5.16 ``computeImage``), from a
pinhole (Mitsuba's ``perspective``), a thin lens (``thinlens``) or an orthographic camera (``orthographic``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from reference_impl.errors import SettingsError
from reference_impl.filters import PixelFilter, make_filter
from reference_impl.sampling import square_to_uniform_disk_concentric

FOV_AXES = ("x", "y", "smaller", "larger")


@dataclass(frozen=True)
class Film:
    """Image size in pixels and the reconstruction filter h ("box" | "tent" | "gaussian", Mitsuba's kernels).

    Row 0 of the image is its top.
    """

    width: int
    height: int
    filter: str = "box"

    def __post_init__(self) -> None:
        for key in ("width", "height"):
            value = getattr(self, key)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                raise SettingsError(f"film.{key}", f"expected a positive integer, got {value!r}")
        make_filter(self.filter)  # validates the name

    @property
    def pixel_filter(self) -> PixelFilter:
        return make_filter(self.filter)


@dataclass(frozen=True)
class LookAt:
    """A camera placed by Mitsuba's ``look_at(origin, target, up)``: every camera type's frame.

    Camera space: +x = left = normalize(up x forward), +y = up, +z = forward; the image's left edge looks toward
    camera +x and its top edge toward camera +y (Mitsuba's sensors).
    """

    origin: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]

    def __post_init__(self) -> None:
        forward = np.asarray(self.target, float) - np.asarray(self.origin, float)
        if not np.all(np.isfinite(forward)) or np.linalg.norm(forward) == 0:
            raise SettingsError("camera.target", "expected a finite point different from camera.origin")
        up = np.asarray(self.up, float)
        if np.linalg.norm(np.cross(up, forward)) <= 1e-9 * np.linalg.norm(up) * np.linalg.norm(forward):
            raise SettingsError("camera.up", "expected a vector not parallel to the view direction (target - origin)")

    def frame(self) -> np.ndarray:
        """(3, 3) matrix whose columns are camera +x (left), +y (up), +z (forward) in world space."""
        forward = np.asarray(self.target, float) - np.asarray(self.origin, float)
        forward /= np.linalg.norm(forward)
        left = np.cross(np.asarray(self.up, float), forward)
        left /= np.linalg.norm(left)
        new_up = np.cross(forward, left)
        return np.stack([left, new_up, forward], axis=1)


@dataclass(frozen=True)
class Camera(LookAt):
    """A perspective camera (Mitsuba's ``perspective`` sensor) with its ``fov`` / ``fov_axis`` meaning."""

    fov: float = 0.0
    fov_axis: str = "x"

    def __post_init__(self) -> None:
        if self.fov_axis not in FOV_AXES:
            raise SettingsError("camera.fov_axis", f"expected one of {', '.join(FOV_AXES)}, got {self.fov_axis!r}")
        if not (0.0 < float(self.fov) < 180.0):
            raise SettingsError("camera.fov", f"expected degrees in (0, 180), got {self.fov!r}")
        super().__post_init__()

    def tan_half_fov(self, width: int, height: int) -> tuple[float, float]:
        """tan(fov_x / 2), tan(fov_y / 2) for a film of this size (Mitsuba's ``fov_axis`` rules)."""
        aspect = width / height
        axis = self.fov_axis
        if axis == "smaller":
            axis = "y" if aspect > 1 else "x"
        elif axis == "larger":
            axis = "x" if aspect > 1 else "y"
        t = math.tan(math.radians(float(self.fov)) / 2)
        if axis == "x":
            return t, t / aspect
        return t * aspect, t

    def film_directions(self, film_x: np.ndarray, film_y: np.ndarray, width: int, height: int) -> np.ndarray:
        """Camera-space directions l = ((1 - 2 p_x / W) tan_x, (1 - 2 p_y / H) tan_y, 1) through film points (not
        normalised: l_z = 1)."""
        tan_x, tan_y = self.tan_half_fov(width, height)
        local = np.empty((len(film_x), 3))
        local[:, 0] = (1.0 - 2.0 * np.asarray(film_x, float) / width) * tan_x
        local[:, 1] = (1.0 - 2.0 * np.asarray(film_y, float) / height) * tan_y
        local[:, 2] = 1.0
        return local

    def generate_rays(self, film_x: np.ndarray, film_y: np.ndarray, width: int, height: int, lens=None):
        """World-space origins and unit directions of viewing rays through film points.

        ``film_x`` in [0, width] grows to the right, ``film_y`` in [0, height] grows downward (pixel (i, j) covers
        [i, i+1] x [j, j+1]). ``lens``: a thin lens's aperture uniforms, ignored by the pinhole.
        """
        directions = self.film_directions(film_x, film_y, width, height) @ self.frame().T
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        origins = np.broadcast_to(np.asarray(self.origin, float), directions.shape)
        return origins, directions


#: Mitsuba 3.9.1's thin lens focuses at its ``far_clip`` unless told, and its default ``far_clip`` is 10^4.
DEFAULT_FOCUS_DISTANCE = 1e4


@dataclass(frozen=True)
class ThinLensCamera(Camera):
    """A thin-lens camera (Mitsuba's ``thinlens`` sensor): the perspective camera's film and frame, its rays leaving
    a disk of radius ``aperture_radius`` about the eye (in the plane z_cam = 0) and meeting again on the plane of
    focus z_cam = ``focus_distance``, measured along the camera's axis (Mitsuba's meaning).

    For a film point whose pinhole direction is l = (l_x, l_y, 1) (:meth:`film_directions`) and an aperture point
    a = r (d_x, d_y, 0), (d_x, d_y) uniform on the unit disk (Shirley and Chiu's concentric map, as Mitsuba's):
    origin a, direction normalize(f l - a), f = ``focus_distance``. The weight is 1 (Mitsuba's).
    """

    aperture_radius: float = field(default=0.0, kw_only=True)
    focus_distance: float = field(default=DEFAULT_FOCUS_DISTANCE, kw_only=True)

    def __post_init__(self) -> None:
        radius, focus = float(self.aperture_radius), float(self.focus_distance)
        if not (math.isfinite(radius) and radius >= 0.0):
            raise SettingsError("camera.aperture_radius",
                                f"expected a finite number >= 0, got {self.aperture_radius!r}")
        if not (math.isfinite(focus) and focus > 0.0):
            raise SettingsError("camera.focus_distance", f"expected a finite number > 0, got {self.focus_distance!r}")
        super().__post_init__()

    def generate_rays(self, film_x: np.ndarray, film_y: np.ndarray, width: int, height: int, lens=None):
        """As :meth:`Camera.generate_rays`, through the aperture points of ``lens`` = (u1, u2), uniforms mapped to
        the disk by :func:`reference_impl.sampling.square_to_uniform_disk_concentric`; ``lens`` None: through the
        lens's centre (the pinhole's rays)."""
        if lens is None:
            return super().generate_rays(film_x, film_y, width, height)
        local = self.film_directions(film_x, film_y, width, height) * float(self.focus_distance)
        aperture = np.zeros_like(local)
        aperture[:, :2] = square_to_uniform_disk_concentric(*lens) * float(self.aperture_radius)
        frame = self.frame()
        directions = (local - aperture) @ frame.T
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        return np.asarray(self.origin, float) + aperture @ frame.T, directions


@dataclass(frozen=True)
class OrthographicCamera(LookAt):
    """An orthographic camera (Mitsuba's ``orthographic`` sensor): every ray along the camera's forward axis, from
    the film's point on the plane through the eye.

    Before ``to_world``'s scale the film spans camera x in [-1, 1] and y in [-1 / aspect, 1 / aspect] (aspect = W /
    H; the image's left edge toward camera +x, its top toward +y); ``scale`` = (s_x, s_y, s_z), Mitsuba's
    ``to_world = look_at(origin, target, up) @ scale(s)``, sizes it: film point (p_x, p_y) starts at camera
    ((1 - 2 p_x / W) s_x, (1 - 2 p_y / H) s_y / aspect, 0). Mitsuba starts it ``near_clip`` s_z further along the
    axis, which changes nothing for a scene in front of the near plane. The weight is 1.
    """

    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        scale = np.asarray(self.scale, float)
        if scale.shape != (3,) or not (np.all(np.isfinite(scale)) and np.all(scale > 0)):
            raise SettingsError("camera.scale", f"expected three finite factors > 0, got {self.scale!r}")
        super().__post_init__()

    def extent(self, width: int, height: int) -> tuple[float, float]:
        """Half the film's width and height in scene units: (s_x, s_y H / W)."""
        return float(self.scale[0]), float(self.scale[1]) * height / width

    def generate_rays(self, film_x: np.ndarray, film_y: np.ndarray, width: int, height: int, lens=None):
        """World-space origins and unit directions (all the camera's forward) of the rays through film points
        (``film_x``, ``film_y`` as for :meth:`Camera.generate_rays`; ``lens`` ignored)."""
        half_x, half_y = self.extent(width, height)
        local = np.zeros((len(film_x), 3))
        local[:, 0] = (1.0 - 2.0 * np.asarray(film_x, float) / width) * half_x
        local[:, 1] = (1.0 - 2.0 * np.asarray(film_y, float) / height) * half_y
        frame = self.frame()
        origins = np.asarray(self.origin, float) + local @ frame.T
        directions = np.broadcast_to(frame[:, 2], origins.shape).copy()
        return origins, directions


#: Every camera record of the core.
CAMERA_TYPES = (Camera, ThinLensCamera, OrthographicCamera)
