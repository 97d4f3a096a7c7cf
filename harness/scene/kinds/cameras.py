"""The camera types of ``[camera]`` (Mitsuba's sensor plugins of the same names and parameters, docs/scene-format.md,
"[camera]"), one :class:`CameraKind` each in :data:`CAMERAS`: its keys and their reading into the core's camera
(:mod:`reference_impl.camera`, whose defaults are the model's), its Mitsuba sensor and its scene.json entry.

Every type is placed by Mitsuba's ``look_at(origin, target, up)``: those keys and ``type`` are every type's
(:data:`CAMERA_KEYS`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from reference_impl.camera import DEFAULT_FOCUS_DISTANCE, Camera, Film, OrthographicCamera, ThinLensCamera

from harness.scene.kinds.mitsuba_values import LookAt, xyz

DEFAULT_TYPE = "perspective"
DEFAULT_FOV_AXIS = Camera.fov_axis  # the core's default: "x", as in Mitsuba
LOOK_AT_KEYS = ("origin", "target", "up")
#: The keys every camera type takes: its look-at, its type and the medium it sits in (``medium``, a name of
#: ``[media]``, read by the scene's loader: harness.scene.load).
CAMERA_KEYS = (*LOOK_AT_KEYS, "type", "medium")


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
    gltf : callable
        ``gltf(camera, film, near, far) -> dict``: its glTF camera (``type`` and that type's object; what glTF has
        no place for under ``extras``), without the node that places it.
    scale : callable
        ``scale(camera) -> (s_x, s_y, s_z) or None``: the scale its Mitsuba ``to_world`` applies before the
        look-at (an orthographic film's extent), None for none.
    scaled : callable
        ``scaled(camera, s) -> camera``: the camera of the scene scaled by s about any point, its look-at already
        moved (what else a uniform scale changes: a lens and its focus, an orthographic film's extent).
    """

    name: str
    model: type
    keys: tuple[str, ...]
    read: Callable[[Any, dict, tuple], Any]
    parameters: Callable[[Any], dict]
    json: Callable[[Any, Film], dict]
    gltf: Callable[[Any, Film, float, float], dict]
    scale: Callable[[Any], tuple | None] = lambda camera: None
    scaled: Callable[[Any, float], Any] = lambda camera, s: camera

    def to_mitsuba(self, camera, near_clip: float, far_clip: float) -> dict:
        """Mitsuba's sensor of ``camera`` without its sampler and film: its parameters, the clip planes (the
        scene's, :func:`harness.renderers.mitsuba_spec.clip_planes`) and its look-at, after its :attr:`scale`
        where it has one (``to_world = look_at @ scale``)."""
        scale = self.scale(camera)
        return {"type": self.name, **self.parameters(camera), "near_clip": near_clip, "far_clip": far_clip,
                "to_world": LookAt(xyz(camera.origin), xyz(camera.target), xyz(camera.up),
                                   None if scale is None else xyz(scale))}

    def moved(self, camera, point: Callable, s: float):
        """``camera`` in the scene moved by a similarity (uniform scale ``s``): its origin and target through
        ``point``, then :attr:`scaled`; up and the field of view unchanged, so the image is unchanged."""
        return self.scaled(dataclasses.replace(camera, origin=point(camera.origin), target=point(camera.target)), s)

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


def _read_fov(reader, table: dict) -> tuple[float, str]:
    """``fov`` (required) and ``fov_axis``: the perspective and thin-lens cameras' field of view."""
    fov = reader.number(reader.require(table, "fov", "camera", "degrees"), "camera.fov", "degrees in (0, 180)")
    return fov, reader.string(table.get("fov_axis", DEFAULT_FOV_AXIS), "camera.fov_axis")


def _read_perspective(reader, table: dict, look_at: tuple) -> Camera:
    fov, fov_axis = _read_fov(reader, table)
    return reader.settings(lambda: Camera(*look_at, fov, fov_axis))


def _perspective_parameters(camera: Camera) -> dict:
    return {"fov": float(camera.fov), "fov_axis": camera.fov_axis}


def _perspective_json(camera: Camera, film: Film) -> dict:
    """Mitsuba's ``fov`` / ``fov_axis``, the full angles they resolve to on ``film`` and its aspect ratio."""
    tan_x, tan_y = camera.tan_half_fov(film.width, film.height)
    return {"fov": float(camera.fov), "fov_axis": camera.fov_axis,
            "fov_x": math.degrees(2 * math.atan(tan_x)), "fov_y": math.degrees(2 * math.atan(tan_y)),
            "aspect": film.width / film.height}


def _perspective_gltf(camera: Camera, film: Film, near: float, far: float) -> dict:
    """glTF's perspective camera: ``yfov`` the resolved vertical field of view (radians; Mitsuba's ``fov`` /
    ``fov_axis`` for this film), ``aspectRatio`` width / height."""
    _tan_x, tan_y = camera.tan_half_fov(film.width, film.height)
    return {"type": "perspective", "perspective": {"yfov": 2.0 * math.atan(tan_y),
                                                   "aspectRatio": film.width / film.height, "znear": float(near),
                                                   "zfar": float(far)}}


# ---- thinlens ------------------------------------------------------------------------------------------------------


def _read_thinlens(reader, table: dict, look_at: tuple) -> ThinLensCamera:
    """The perspective keys, ``aperture_radius`` (required, as in Mitsuba; >= 0) and ``focus_distance`` (> 0; Mitsuba's
    default, its default far_clip 10^4)."""
    fov, fov_axis = _read_fov(reader, table)
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


def _thinlens_gltf(camera: ThinLensCamera, film: Film, near: float, far: float) -> dict:
    """The perspective camera, the lens's ``aperture_radius`` and ``focus_distance`` (along the axis) under
    ``extras``: glTF has no depth of field."""
    return {**_perspective_gltf(camera, film, near, far),
            "extras": {"aperture_radius": float(camera.aperture_radius),
                       "focus_distance": float(camera.focus_distance)}}


def _thinlens_scaled(camera: ThinLensCamera, s: float) -> ThinLensCamera:
    return dataclasses.replace(camera, aperture_radius=camera.aperture_radius * s,
                               focus_distance=camera.focus_distance * s)


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


def _orthographic_gltf(camera: OrthographicCamera, film: Film, near: float, far: float) -> dict:
    """glTF's orthographic camera: ``xmag`` / ``ymag`` half the film's width and height in scene units."""
    half_x, half_y = camera.extent(film.width, film.height)
    return {"type": "orthographic", "orthographic": {"xmag": half_x, "ymag": half_y, "znear": float(near),
                                                     "zfar": float(far)}}


def _orthographic_scaled(camera: OrthographicCamera, s: float) -> OrthographicCamera:
    return dataclasses.replace(camera, scale=tuple(float(x) * s for x in camera.scale))


#: Every camera type by its name.
CAMERAS: dict[str, CameraKind] = {kind.name: kind for kind in (
    CameraKind("perspective", Camera, ("fov", "fov_axis"), _read_perspective, _perspective_parameters,
               _perspective_json, _perspective_gltf),
    CameraKind("thinlens", ThinLensCamera, ("fov", "fov_axis", "aperture_radius", "focus_distance"), _read_thinlens,
               _thinlens_parameters, _thinlens_json, _thinlens_gltf, scaled=_thinlens_scaled),
    CameraKind("orthographic", OrthographicCamera, ("scale",), _read_orthographic, lambda camera: {},
               _orthographic_json, _orthographic_gltf, scale=lambda camera: camera.scale,
               scaled=_orthographic_scaled),
)}
CAMERA_MODELS = {kind.model: kind for kind in CAMERAS.values()}
#: The keys a ``[camera]`` table may hold, in the order a refusal lists them.
ALL_CAMERA_KEYS = (*LOOK_AT_KEYS, *dict.fromkeys(key for kind in CAMERAS.values() for key in kind.keys), "type",
                   "medium")
