"""The emitter types of ``[[emitters]]``, the emitters that are not shapes (Mitsuba's plugins of the same names and
parameters, docs/scene-format.md, "Emitters"), one :class:`EmitterKind` each in :data:`EMITTERS`: its keys and their
reading, its record of the core (:mod:`reference_impl.emitters`, whose defaults are the model's), its Mitsuba
plugin, its scene.json entry, its glTF light where glTF has one, and how a similarity transform of the scene moves
it."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

import reference_impl
from reference_impl.emitters import BEAM_WIDTH_FRACTION, DEFAULT_CUTOFF_ANGLE, DEFAULT_SCALE

from harness.scene.kinds.mitsuba_values import ImageFile, Point, Vector, matrix, rgb, xyz
from harness.scene.model import (EMITTER_TYPES, ConstantEnvironment, DirectionalLight, Emitter, EnvironmentMap,
                                 PointLight, SpotLight)
from harness.scene.primitives import frame_to_world, is_similarity

ENVMAP_SUFFIXES = (".exr",)
MAX_CUTOFF_ANGLE = 90.0
MIN_ENVMAP_SIZE = (2, 3)  # width, height: Mitsuba pads smaller maps (repeating edges), which would move the texels
ORTHONORMAL_TOLERANCE = 1e-5  # an envmap's to_world: |M^T M - I| at most this (entries typed with 6 digits pass)
#: lumens per watt: a radiometric W/sr (W/m^2) is written to glTF as this many candela (lux), the convention of
#: Blender's glTF importer ("Standard" lighting), which turns the candela back into the same watts
LUMENS_PER_WATT = 683.0


@dataclass(frozen=True)
class EmitterKind:
    """One emitter type.

    Attributes
    ----------
    name : str
        The ``type`` value (Mitsuba's plugin name).
    model : type
        Its record in the scene model (:class:`~harness.scene.model.PointLight` ...).
    keys : tuple of str
        The keys its table may hold.
    read : callable
        ``read(reader, index, name, table, key) -> Emitter``: the entry ``table`` at key path ``key``, read with the
        scene reader's typed readers (``reader``: :class:`harness.scene.load._SceneReader`).
    to_core : callable
        ``to_core(emitter)``: the core's record (:class:`reference_impl.Point` ...), same parameters.
    parameters : callable
        ``parameters(emitter, texture) -> dict``: its Mitsuba plugin's parameters; ``texture`` is the path of the
        file its image becomes in an export (textured types only).
    json : callable
        ``json(emitter, texture) -> dict``: its parameters in the scene.json entry (plain numbers; matrices 4x4
        row-major).
    environment : bool
        Seen by escaping rays (at most one per scene, as in Mitsuba).
    textured : bool
        It holds an image (``emitter.image``), written as a file beside an exported scene.
    moved : callable
        ``moved(emitter, matrix, area)``: the emitter under the similarity ``matrix`` that scales areas by ``area``
        (intensities scale with it, so the image stays the same); infinitely far ones are unchanged.
    gltf : callable or None
        ``gltf(emitter) -> (rgb, dict, dict)``: a ``KHR_lights_punctual`` type's W/sr (W/m^2), the light's keys
        beyond name, type, color and intensity, and its node's placement (``translation``, ``rotation``); None for
        a type glTF 2.0 has no light for (an environment).
    """

    name: str
    model: type
    keys: tuple[str, ...]
    read: Callable[..., Emitter]
    to_core: Callable[[Emitter], Any]
    parameters: Callable[[Emitter, str | None], dict]
    json: Callable[[Emitter, str | None], dict]
    environment: bool = False
    textured: bool = False
    moved: Callable[[Emitter, np.ndarray, float], Emitter] = lambda emitter, _matrix, _area: emitter
    gltf: Callable[[Emitter], tuple[Any, dict, dict]] | None = None

    def to_mitsuba(self, emitter: Emitter, texture: str | None = None) -> dict:
        """Mitsuba's plugin of ``emitter`` (docs/mitsuba.md, "Emitters"): its parameters written out, colours as
        ``rgb``, an envmap's pixels as an :class:`~harness.scene.kinds.mitsuba_values.ImageFile` at ``texture``."""
        return {"type": self.name, **self.parameters(emitter, texture)}

    def to_scene_json(self, emitter: Emitter, texture: str | None = None) -> dict:
        """The scene.json entry of ``emitter``: index, name, type and its parameters; ``texture`` names its image."""
        return {"index": emitter.index, "name": emitter.name, "type": self.name, **self.json(emitter, texture)}

    def to_gltf(self, emitter: Emitter) -> tuple[dict, dict]:
        """``emitter`` as a ``KHR_lights_punctual`` light and its node's placement (the node's name aside).

        Intensity: candela (point, spot) or lux (directional) = :data:`LUMENS_PER_WATT` x the largest channel of
        the RGB W/sr (W/m^2), colour = the RGB divided by that channel. glTF lights have no size and fall off with
        1/r^2, as Mitsuba's. Only for types with a glTF light (``gltf`` not None).
        """
        radiometric, keys, placement = self.gltf(emitter)
        color, intensity = _gltf_colour(radiometric)
        return {"name": emitter.name, "type": self.name, "color": color, "intensity": intensity, **keys}, placement


def read_emitters(reader, document: dict) -> tuple[Emitter, ...]:
    """``[[emitters]]``: each entry (:func:`read_emitter`), names unique, at most one environment."""
    entries = reader.array(document.get("emitters", []), "emitters", "an array of tables ([[emitters]])")
    emitters: list[Emitter] = []
    for index, entry in enumerate(entries):
        emitter = read_emitter(reader, index, entry)
        for other in emitters:
            if other.name == emitter.name:
                message = f"duplicate emitter name {emitter.name!r} (also emitters[{other.index}])"
                raise reader.error(f"emitters[{index}].name", message)
            if EMITTERS[emitter.type].environment and EMITTERS[other.type].environment:
                raise reader.error(f"emitters[{index}].type", (
                    f"a second environment emitter ({emitter.type!r}; emitters[{other.index}] is a {other.type!r}); "
                    "expected at most one constant or envmap per scene, as in Mitsuba"))
        emitters.append(emitter)
    return tuple(emitters)


def read_emitter(reader, index: int, entry: Any) -> Emitter:
    """Entry ``index`` of ``[[emitters]]``: its type, its name (default ``emitter<index>``) and that type's keys."""
    key = f"emitters[{index}]"
    table = reader.table(entry, key)
    reader.check_keys(table, EMITTER_KEYS, key)
    kind = EMITTERS[reader.choice(reader.require(table, "type", key, "an emitter type"), f"{key}.type",
                                  tuple(EMITTERS))]
    for name in table:
        if name not in kind.keys:
            owners = " or ".join(repr(t) for t, other in EMITTERS.items() if name in other.keys)
            message = f"key {name!r} applies only to emitters of type {owners}, not {kind.name!r}"
            raise reader.error(f"{key}.{name}", message)
    name = reader.string(table.get("name", f"emitter{index}"), f"{key}.name")
    return kind.read(reader, index, name, table, key)


# ---- reading -------------------------------------------------------------------------------------------------------


def _colour(reader, table: dict, name: str, key: str, unit: str) -> tuple[float, float, float]:
    """A required [r, g, b] of an emitter: finite, >= 0, not all 0, at most MAX_EMISSION (as shapes' emission)."""
    return reader.emission(reader.require(table, name, key, f"[r, g, b] in {unit}"), f"{key}.{name}")


def _direction(reader, value: Any, key: str) -> tuple[float, float, float]:
    """A non-zero vector, normalised."""
    what = "a list of 3 finite numbers, not all 0"
    vector = np.array(reader.vector3(value, key, what), dtype=np.float64)
    with np.errstate(all="ignore"):
        length = float(np.linalg.norm(vector))
    if not (0.0 < length < math.inf):
        raise reader.expected(key, what, value)
    return tuple(float(x) for x in vector / length)


def _read_point(reader, index: int, name: str, table: dict, key: str) -> PointLight:
    position = reader.vector3(reader.require(table, "position", key, "a point"), f"{key}.position")
    return PointLight(index, name, position, _colour(reader, table, "intensity", key, "W/sr"))


def _read_directional(reader, index: int, name: str, table: dict, key: str) -> DirectionalLight:
    direction = _direction(reader, reader.require(table, "direction", key, "the direction light travels"),
                           f"{key}.direction")
    return DirectionalLight(index, name, direction, _colour(reader, table, "irradiance", key, "W/m^2"))


def _read_constant(reader, index: int, name: str, table: dict, key: str) -> ConstantEnvironment:
    return ConstantEnvironment(index, name, _colour(reader, table, "radiance", key, "W/(m^2 sr)"))


def _read_spot(reader, index: int, name: str, table: dict, key: str) -> SpotLight:
    if "to_world" in table:
        given = [k for k in ("position", "target") if k in table]
        if given:
            raise reader.error(f"{key}.to_world",
                               f"expected either to_world or position / target, not both (found {', '.join(given)})")
        to_world = reader.matrix4(table["to_world"], f"{key}.to_world")
        if not is_similarity(to_world[:3, :3]):
            raise reader.error(f"{key}.to_world", (
                "expected a rotation, a uniform scale and a translation (the spot's cone is the local +z axis; "
                "a non-uniform scale, a shear or a zero scale would distort or lose it)"))
    else:
        what = "a point, or give to_world"
        position = reader.vector3(reader.require(table, "position", key, what), f"{key}.position")
        target = reader.vector3(reader.require(table, "target", key, "a point the cone's axis passes through"),
                                f"{key}.target")
        with np.errstate(all="ignore"):
            axis = np.subtract(target, position)
            length = float(np.linalg.norm(axis))
        if not (0.0 < length < math.inf):
            raise reader.error(f"{key}.target", f"expected a point other than position (the cone's axis runs from "
                                                f"position to target), got {reader.show(table['target'])}")
        to_world = frame_to_world(position, axis / length)
    intensity = _colour(reader, table, "intensity", key, "W/sr")
    what = f"an angle in degrees in (0, {MAX_CUTOFF_ANGLE:g}]"
    cutoff = reader.number(table.get("cutoff_angle", DEFAULT_CUTOFF_ANGLE), f"{key}.cutoff_angle", what)
    if not 0.0 < cutoff <= MAX_CUTOFF_ANGLE:
        raise reader.expected(f"{key}.cutoff_angle", what, table["cutoff_angle"])
    what = f"an angle in degrees in (0, cutoff_angle = {cutoff:g}]"
    beam = reader.number(table.get("beam_width", BEAM_WIDTH_FRACTION * cutoff), f"{key}.beam_width", what)
    if not 0.0 < beam <= cutoff:
        raise reader.expected(f"{key}.beam_width", what, table["beam_width"])
    return SpotLight(index, name, to_world, intensity, cutoff, beam)


def _read_envmap(reader, index: int, name: str, table: dict, key: str) -> EnvironmentMap:
    file_key = f"{key}.file"
    file_name = reader.string(reader.require(table, "file", key, "an OpenEXR lat-long image"), file_key)
    if not file_name.lower().endswith(ENVMAP_SUFFIXES):
        raise reader.expected(file_key, "an .exr file name (OpenEXR, linear RGB)", file_name)
    path, image = reader.envmap_image(file_name, file_key)
    what = "a finite number > 0"
    scale = reader.number(table.get("scale", DEFAULT_SCALE), f"{key}.scale", what)
    if scale <= 0:
        raise reader.expected(f"{key}.scale", what, table["scale"])
    _check_envmap_pixels(reader, image, file_name, file_key, scale, f"{key}.scale")
    image.setflags(write=False)
    if "to_world" in table:
        if "rotate" in table:
            raise reader.error(f"{key}.to_world", "expected either to_world or rotate, not both")
        to_world = reader.matrix4(table["to_world"], f"{key}.to_world")
        linear = to_world[:3, :3]
        if np.any(to_world[:3, 3] != 0):
            raise reader.error(f"{key}.to_world", (
                "expected no translation (last column [0, 0, 0, 1]): an environment map is infinitely far, "
                "Mitsuba ignores it"))
        with np.errstate(all="ignore"):
            deviation = float(np.max(np.abs(linear.T @ linear - np.eye(3))))
            determinant = float(np.linalg.det(linear)) if math.isfinite(deviation) else math.nan
        if not (deviation <= ORTHONORMAL_TOLERANCE and determinant > 0):
            raise reader.error(f"{key}.to_world", (
                f"expected a rotation (orthonormal within {ORTHONORMAL_TOLERANCE:g}, determinant +1)"
                .replace("e-0", "e-") + ": Mitsuba maps directions with it without normalising them, so a "
                "scale or shear would move the map"))
    else:
        to_world = reader.rotation(table.get("rotate", []), f"{key}.rotate")
    return EnvironmentMap(index, name, path, image, to_world, scale)


def _check_envmap_pixels(reader, image: np.ndarray, name: str, key: str, scale: float, scale_key: str) -> None:
    """Refuse maps too small for Mitsuba's mapping and pixels that are not finite radiances >= 0."""
    height, width = image.shape[:2]
    if width < MIN_ENVMAP_SIZE[0] or height < MIN_ENVMAP_SIZE[1]:
        raise reader.error(key, (
            f"envmap file {name!r} is {width} x {height} pixels; expected at least {MIN_ENVMAP_SIZE[0]} x "
            f"{MIN_ENVMAP_SIZE[1]} (Mitsuba pads smaller maps by repeating their edges)"))
    bad = ~np.isfinite(image) | (image < 0)
    if bad.any():
        row, column, channel = (int(i) for i in np.argwhere(bad)[0])
        value = float(image[row, column, channel])
        count = int(bad.sum())
        raise reader.error(key, (
            f"envmap file {name!r} has {count} bad value{'s' if count > 1 else ''}, the first at row {row}, "
            f"column {column}: {'RGB'[channel]} = {reader.show(value)}; expected finite radiances >= 0"))
    peak = float(image.max())
    if peak == 0:
        raise reader.error(key, f"envmap file {name!r} is black (every pixel 0); expected some emission")
    if peak * scale > reader.max_emission:
        where = scale_key if scale != 1.0 else key
        raise reader.error(where, (
            f"envmap file {name!r} times scale {scale:g} reaches {peak * scale:.3g}; expected radiances of at "
            f"most {reader.max_emission:g}".replace("e+", "e")))


# ---- the core's records, Mitsuba's parameters and scene.json's ----------------------------------------------------


def _numbers(values) -> list:
    return np.asarray(values, dtype=np.float64).tolist()


def _moved_point(emitter: PointLight, to_world: np.ndarray, area: float) -> PointLight:
    position = tuple(float(x) for x in to_world[:3, :3] @ np.asarray(emitter.position, float) + to_world[:3, 3])
    return dataclasses.replace(emitter, position=position, intensity=tuple(float(i) * area for i in emitter.intensity))


def _moved_spot(emitter: SpotLight, to_world: np.ndarray, area: float) -> SpotLight:
    return dataclasses.replace(emitter, to_world=to_world @ emitter.to_world,
                               intensity=tuple(float(i) * area for i in emitter.intensity))


def _envmap_image(emitter: EnvironmentMap, texture: str | None) -> ImageFile:
    return ImageFile(texture, emitter.image)


def _gltf_colour(rgb_values) -> tuple[list[float], float]:
    """glTF's (color in [0, 1], intensity): color = rgb / its largest channel, intensity = that channel times
    :data:`LUMENS_PER_WATT`."""
    values = np.asarray(rgb_values, dtype=np.float64)
    peak = float(values.max())
    return [float(x) for x in values / peak], LUMENS_PER_WATT * peak


def _rotation_from_minus_z(direction) -> list[float]:
    """The unit quaternion [x, y, z, w] (glTF's order) that turns -z, where a glTF light points, into the unit
    vector ``direction``."""
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    q = np.array([d[1], -d[0], 0.0, 1.0 - d[2]])  # [cross(-z, d), 1 + dot(-z, d)], normalised below
    length = float(np.linalg.norm(q))
    if length == 0.0:  # d = +z exactly: half a turn about x
        return [1.0, 0.0, 0.0, 0.0]
    return [float(x) + 0.0 for x in q / length]


def _gltf_point(emitter: PointLight) -> tuple[Any, dict, dict]:
    return emitter.intensity, {}, {"translation": [float(x) for x in emitter.position]}


def _gltf_spot(emitter: SpotLight) -> tuple[Any, dict, dict]:
    """``outerConeAngle`` = ``cutoff_angle``, ``innerConeAngle`` = ``beam_width`` (radians; glTF wants inner <
    outer, so inner is a hair smaller when they are equal); glTF's falloff between them is left to the viewer (the
    spec's sample code fades with the square of a ramp in cos), not Mitsuba's ramp linear in the angle."""
    outer = math.radians(emitter.cutoff_angle)
    inner = min(math.radians(emitter.beam_width), math.nextafter(outer, 0.0))
    placement = {"translation": [float(x) for x in emitter.position],
                 "rotation": _rotation_from_minus_z(emitter.axis)}
    return emitter.intensity, {"spot": {"innerConeAngle": inner, "outerConeAngle": outer}}, placement


def _gltf_directional(emitter: DirectionalLight) -> tuple[Any, dict, dict]:
    return emitter.irradiance, {}, {"rotation": _rotation_from_minus_z(emitter.direction)}


#: Every emitter type by its name, in :data:`harness.scene.model.EMITTER_TYPES`'s order.
EMITTERS: dict[str, EmitterKind] = {kind.name: kind for kind in (
    EmitterKind(
        "point", PointLight, ("name", "type", "position", "intensity"), _read_point,
        to_core=lambda e: reference_impl.Point(position=e.position, intensity=e.intensity),
        parameters=lambda e, _t: {"position": Point(xyz(e.position)), "intensity": rgb(e.intensity)},
        json=lambda e, _t: {"position": _numbers(e.position), "intensity": _numbers(e.intensity)},
        moved=_moved_point, gltf=_gltf_point),
    EmitterKind(
        "spot", SpotLight,
        ("name", "type", "position", "target", "to_world", "intensity", "cutoff_angle", "beam_width"), _read_spot,
        to_core=lambda e: reference_impl.Spot(to_world=matrix(e.to_world), intensity=e.intensity,
                                              cutoff_angle=e.cutoff_angle, beam_width=e.beam_width),
        parameters=lambda e, _t: {"to_world": matrix(e.to_world), "intensity": rgb(e.intensity),
                                  "cutoff_angle": float(e.cutoff_angle), "beam_width": float(e.beam_width)},
        json=lambda e, _t: {"to_world": _numbers(e.to_world), "position": _numbers(e.position),
                            "axis": _numbers(e.axis), "intensity": _numbers(e.intensity),
                            "cutoff_angle": float(e.cutoff_angle), "beam_width": float(e.beam_width)},
        moved=_moved_spot, gltf=_gltf_spot),
    EmitterKind(
        "directional", DirectionalLight, ("name", "type", "direction", "irradiance"), _read_directional,
        to_core=lambda e: reference_impl.Directional(direction=e.direction, irradiance=e.irradiance),
        parameters=lambda e, _t: {"direction": Vector(xyz(e.direction)), "irradiance": rgb(e.irradiance)},
        json=lambda e, _t: {"direction": _numbers(e.direction), "irradiance": _numbers(e.irradiance)},
        gltf=_gltf_directional),
    EmitterKind(
        "constant", ConstantEnvironment, ("name", "type", "radiance"), _read_constant,
        to_core=lambda e: reference_impl.Constant(radiance=e.radiance),
        parameters=lambda e, _t: {"radiance": rgb(e.radiance)},
        json=lambda e, _t: {"radiance": _numbers(e.radiance)}, environment=True),
    EmitterKind(
        "envmap", EnvironmentMap, ("name", "type", "file", "scale", "to_world", "rotate"), _read_envmap,
        to_core=lambda e: reference_impl.EnvMap(image=e.image, to_world=matrix(e.to_world), scale=e.scale),
        parameters=lambda e, texture: {"filename": _envmap_image(e, texture), "scale": float(e.scale),
                                       "to_world": matrix(e.to_world)},
        json=lambda e, texture: {"filename": texture, "scale": float(e.scale), "to_world": _numbers(e.to_world),
                                 "width": int(e.image.shape[1]), "height": int(e.image.shape[0])},
        environment=True, textured=True),
)}
assert tuple(EMITTERS) == EMITTER_TYPES
#: Every key of any type, for did-you-mean hints.
EMITTER_KEYS = tuple(dict.fromkeys(key for kind in EMITTERS.values() for key in kind.keys))
