"""The camera types of ``[camera]`` (Mitsuba's sensor plugins of the same names and parameters, docs/scene-format.md,
"[camera]"), one :class:`CameraKind` each in :data:`CAMERAS`: its keys and their reading into the core's camera
(:mod:`reference_impl.camera`, whose defaults are the model's), its Mitsuba sensor and its scene.json entry.

Every type is placed by Mitsuba's ``look_at(origin, target, up)``: those keys and ``type`` are every type's
(:data:`CAMERA_KEYS`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from reference_impl.camera import DEFAULT_FOCUS_DISTANCE, Camera, Film, OrthographicCamera, ThinLensCamera

from harness.scene.kinds.mitsuba_values import LookAt, xyz

DEFAULT_TYPE = "perspective"
DEFAULT_FOV_AXIS = Camera.fov_axis  # the core's default: "x", as in Mitsuba
LOOK_AT_KEYS = ("origin", "target", "up")
#: The keys every camera type takes: its look-at and its type.
CAMERA_KEYS = (*LOOK_AT_KEYS, "type")


@dataclass(frozen=True)
class CameraKind:
    """One camera type.

    Attributes
    ----------
    name : str
        The ``type`` value (Mitsuba's sensor plugin).
    model : type
        Its record in the core (:class:`reference_impl.camera.Camera` ...), which the scene holds.
    keys : tuple of str
        The keys of this type alone (the keys every type takes are :data:`CAMERA_KEYS`).
    read : callable
        ``read(reader, table, look_at) -> camera``: the core's record of the ``[camera]`` table, given its
        ``(origin, target, up)`` already read, with the scene reader's typed readers (``reader``:
        :class:`harness.scene.load._SceneReader`); a bad value is its HarnessError.
    parameters : callable
        ``parameters(camera) -> dict``: its Mitsuba sensor's own parameters (the look-at, clip planes, sampler and
        film aside).
    json : callable
        ``json(camera, film) -> dict``: its own parameters in the scene.json entry.
    """

    name: str
    model: type
    keys: tuple[str, ...]
    read: Callable[[Any, dict, tuple], Any]
    parameters: Callable[[Any], dict]
    json: Callable[[Any, Film], dict]

    def to_mitsuba(self, camera, near_clip: float, far_clip: float) -> dict:
        """Mitsuba's sensor of ``camera`` without its sampler and film: its parameters, the clip planes (the
        scene's, :func:`harness.renderers.mitsuba_spec.clip_planes`) and its look-at (an orthographic camera's
        with its ``scale`` after it: ``to_world = look_at @ scale``)."""
        scale = xyz(camera.scale) if isinstance(camera, OrthographicCamera) else None
        return {"type": self.name, **self.parameters(camera), "near_clip": near_clip, "far_clip": far_clip,
                "to_world": LookAt(xyz(camera.origin), xyz(camera.target), xyz(camera.up), scale)}

    def to_scene_json(self, camera, film: Film) -> dict:
        """The scene.json entry of ``camera`` but its clip planes: type, look-at, its parameters and the
        camera-to-world matrix (:func:`camera_to_world`)."""
        return {"type": self.name, "origin": _floats(camera.origin), "target": _floats(camera.target),
                "up": _floats(camera.up), **self.json(camera, film), "to_world": _floats(camera_to_world(camera))}


def read_camera(reader, document: dict):
    """The required ``[camera]`` table: its type (default perspective), its look-at and that type's keys.

    Parameters
    ----------
    reader : harness.scene.load._SceneReader
        The scene reader (its typed readers and errors).
    document : dict
        The parsed scene file.

    Returns
    -------
    reference_impl.camera.Camera
        Or the record of another type (:attr:`CameraKind.model`).
    """
    table = reader.required_table(document, "camera")
    reader.check_keys(table, ALL_CAMERA_KEYS, "camera")
    kind = CAMERAS[reader.choice(table.get("type", DEFAULT_TYPE), "camera.type", tuple(CAMERAS))]
    for name in table:
        if name not in CAMERA_KEYS and name not in kind.keys:
            owners = " or ".join(repr(t) for t, other in CAMERAS.items() if name in other.keys)
            raise reader.error(f"camera.{name}", f"key {name!r} applies only to cameras of type {owners}, "
                                                 f"not {kind.name!r}")
    look_at = tuple(reader.vector3(reader.require(table, key, "camera", "a list of 3 numbers"), f"camera.{key}")
                    for key in LOOK_AT_KEYS)
    return kind.read(reader, table, look_at)


def camera_kind(camera) -> CameraKind:
    """The entry of :data:`CAMERAS` whose record ``camera`` is."""
    return CAMERA_MODELS[type(camera)]


def camera_to_world(camera) -> np.ndarray:
    """The 4x4 camera-to-world matrix of Mitsuba's ``look_at``: columns +x (image left), +y (up), +z (forward)
    and the eye."""
    to_world = np.eye(4)
    to_world[:3, :3] = camera.frame()
    to_world[:3, 3] = camera.origin
    return to_world


def _floats(values) -> list:
    return np.asarray(values, dtype=np.float64).tolist()


# ---- perspective ---------------------------------------------------------------------------------------------------


def _read_perspective(reader, table: dict, look_at: tuple) -> Camera:
    fov = reader.number(reader.require(table, "fov", "camera", "degrees"), "camera.fov", "degrees in (0, 180)")
    fov_axis = reader.string(table.get("fov_axis", DEFAULT_FOV_AXIS), "camera.fov_axis")
    return reader.settings(lambda: Camera(*look_at, fov, fov_axis))


def _perspective_parameters(camera: Camera) -> dict:
    return {"fov": float(camera.fov), "fov_axis": camera.fov_axis}


def _perspective_json(camera: Camera, film: Film) -> dict:
    """Mitsuba's ``fov`` / ``fov_axis``, the full angles they resolve to on ``film`` and its aspect ratio."""
    tan_x, tan_y = camera.tan_half_fov(film.width, film.height)
    return {"fov": float(camera.fov), "fov_axis": camera.fov_axis,
            "fov_x": math.degrees(2 * math.atan(tan_x)), "fov_y": math.degrees(2 * math.atan(tan_y)),
            "aspect": film.width / film.height}


# ---- thinlens ------------------------------------------------------------------------------------------------------


def _read_thinlens(reader, table: dict, look_at: tuple) -> ThinLensCamera:
    """The perspective keys, ``aperture_radius`` (required, as in Mitsuba; >= 0) and ``focus_distance`` (> 0; Mitsuba's
    default, its default far_clip 10^4)."""
    fov = reader.number(reader.require(table, "fov", "camera", "degrees"), "camera.fov", "degrees in (0, 180)")
    fov_axis = reader.string(table.get("fov_axis", DEFAULT_FOV_AXIS), "camera.fov_axis")
    radius = reader.number(reader.require(table, "aperture_radius", "camera", "a number >= 0 (scene units)"),
                           "camera.aperture_radius", "a finite number >= 0 (scene units)")
    focus = reader.number(table.get("focus_distance", DEFAULT_FOCUS_DISTANCE), "camera.focus_distance",
                          "a finite number > 0 (scene units)")
    return reader.settings(lambda: ThinLensCamera(*look_at, fov, fov_axis, aperture_radius=radius,
                                                  focus_distance=focus))


def _thinlens_parameters(camera: ThinLensCamera) -> dict:
    return {**_perspective_parameters(camera), "aperture_radius": float(camera.aperture_radius),
            "focus_distance": float(camera.focus_distance)}


def _thinlens_json(camera: ThinLensCamera, film: Film) -> dict:
    """The perspective entry, ``aperture_radius`` and ``focus_distance`` (along the camera's axis)."""
    return {**_perspective_json(camera, film), "aperture_radius": float(camera.aperture_radius),
            "focus_distance": float(camera.focus_distance)}


# ---- orthographic --------------------------------------------------------------------------------------------------


def _read_orthographic(reader, table: dict, look_at: tuple) -> OrthographicCamera:
    """``scale``: one factor or three (Mitsuba's ``to_world = look_at @ scale``), default 1."""
    scale = reader.scale(table.get("scale", 1.0), "camera.scale")
    return reader.settings(lambda: OrthographicCamera(*look_at, scale=scale))


def _orthographic_json(camera: OrthographicCamera, film: Film) -> dict:
    """``scale``, the half width and height of the film in scene units it gives on ``film``, its aspect ratio."""
    half_x, half_y = camera.extent(film.width, film.height)
    return {"scale": _floats(camera.scale), "half_width": half_x, "half_height": half_y,
            "aspect": film.width / film.height}


#: Every camera type by its name.
CAMERAS: dict[str, CameraKind] = {kind.name: kind for kind in (
    CameraKind("perspective", Camera, ("fov", "fov_axis"), _read_perspective, _perspective_parameters,
               _perspective_json),
    CameraKind("thinlens", ThinLensCamera, ("fov", "fov_axis", "aperture_radius", "focus_distance"), _read_thinlens,
               _thinlens_parameters, _thinlens_json),
    CameraKind("orthographic", OrthographicCamera, ("scale",), _read_orthographic, lambda camera: {},
               _orthographic_json),
)}
CAMERA_MODELS = {kind.model: kind for kind in CAMERAS.values()}
#: The keys a ``[camera]`` table may hold, in the order a refusal lists them.
ALL_CAMERA_KEYS = (*LOOK_AT_KEYS, *dict.fromkeys(key for kind in CAMERAS.values() for key in kind.keys), "type")
