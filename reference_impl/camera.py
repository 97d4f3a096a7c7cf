"""The pinhole camera and the film: primary rays through the pixel filter h (slides, Fig. 5.16 ``computeImage``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from reference_impl.errors import SettingsError
from reference_impl.filters import PixelFilter, make_filter

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
class Camera:
    """A perspective camera with Mitsuba's ``look_at`` frame and ``fov`` / ``fov_axis`` meaning.

    Camera space: +x = left = normalize(up x forward), +y = up, +z = forward; the image's left edge looks toward
    camera +x and its top edge toward camera +y (Mitsuba's perspective sensor).
    """

    origin: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]
    fov: float
    fov_axis: str = "x"

    def __post_init__(self) -> None:
        if self.fov_axis not in FOV_AXES:
            raise SettingsError("camera.fov_axis", f"expected one of {', '.join(FOV_AXES)}, got {self.fov_axis!r}")
        if not (0.0 < float(self.fov) < 180.0):
            raise SettingsError("camera.fov", f"expected degrees in (0, 180), got {self.fov!r}")
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

    def generate_rays(self, film_x: np.ndarray, film_y: np.ndarray, width: int, height: int):
        """World-space origins and unit directions of viewing rays through film points.

        ``film_x`` in [0, width] grows to the right, ``film_y`` in [0, height] grows downward (pixel (i, j) covers
        [i, i+1] x [j, j+1]).
        """
        tan_x, tan_y = self.tan_half_fov(width, height)
        local = np.empty((len(film_x), 3))
        local[:, 0] = (1.0 - 2.0 * film_x / width) * tan_x
        local[:, 1] = (1.0 - 2.0 * film_y / height) * tan_y
        local[:, 2] = 1.0
        directions = local @ self.frame().T
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        origins = np.broadcast_to(np.asarray(self.origin, float), directions.shape)
        return origins, directions
