"""Stress variants of a scene: transformed copies, made in memory from a loaded :class:`~harness.scene.Scene`
(``variant = "scale=1e3"`` in a suite case, ``harness stress --variant``; the study is :mod:`harness.studies.stress`).

Two groups:

* **invariant** variants must not change the image, so they are judged against the *untransformed* scene's
  ground truth:

  - ``scale=s``: every shape and the camera's origin and target scaled by ``s`` about the origin
    (p' = s p); emitted radiance unchanged. A pinhole image depends on directions only, so it is the same image.
    Point and spot lights move with the scene and their intensity is multiplied by s^2 (their irradiance falls as
    1 / r^2); directional lights and environments, infinitely far, are unchanged.
  - ``translate=d``: everything moved by the vector d (1, 1, 1) / sqrt(3) (length d), point and spot lights too.
  - ``sliver=a``: every non-emitting rectangle re-triangulated into a fan with sliver triangles of aspect ``a``
    (longest edge / shortest altitude); the surface, hence the image, is unchanged.

* **strain** variants change the image and strain the estimator; each is judged against the ground truth of the
  *transformed* scene:

  - ``light-shrink=f``: every light's area divided by ``f`` about its centre, its radiance multiplied by ``f``
    (same power).
  - ``grazing-camera=e``: the camera moved onto the largest non-emitting surface, ``e`` degrees above it, looking
    at its centre along it.
  - ``light-near-wall=g``: every light moved along its normal until it sits ``g`` times the scene size in front of
    the surface behind it.
  - ``light-edge-on``: the camera moved into the plane of the first light, looking at its centre.
  - ``medium-density=f``: every medium's extinction (its ``scale``) multiplied by ``f`` (1e-6 .. 1e6: a medium that
    all but vanishes, or one so dense that light barely enters it).
  - ``hg-g=g``: every medium's phase function Henyey-Greenstein with asymmetry ``g`` (-0.999 .. 0.999: scattering
    that is almost a straight line forward or a reflection back).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from harness.core.errors import HarnessError
from harness.scene.kinds.cameras import camera_kind
from harness.scene.kinds.emitters import EMITTERS
from harness.scene.model import Scene, Shape
from harness.scene.primitives import rectangle_uv
from harness.scene.triangulate import (
    object_to_world,
    scale_matrix,
    shape_triangles,
    translate_matrix,
    triangulate,
    unit_rectangle,
)
from reference_impl import SettingsError

INVARIANT, STRAIN = "invariant", "strain"
#: Direction of the translation variants (unit vector): no axis is spared.
TRANSLATE_DIRECTION = np.ones(3) / math.sqrt(3.0)


@dataclass(frozen=True)
class Variant:
    """One variant: ``name`` as written (``scale=1e3``), ``kind`` (the part before ``=``), its ``value``, its
    ``group`` (:data:`INVARIANT` or :data:`STRAIN`) and what it does (``description``)."""

    name: str
    kind: str
    value: float | None
    group: str
    description: str

    def apply(self, scene: Scene) -> Scene:
        """The transformed scene; a HarnessError naming the scene file where the variant does not apply or makes
        an invalid camera (one that looks at its own origin, say)."""
        try:
            return _APPLY[self.kind](scene, self.value)
        except SettingsError as err:
            raise HarnessError(str(scene.path), f"variant {self.name}: gives an invalid scene: {err.key}: "
                               f"{err.message}") from None

    @property
    def judged_against_original(self) -> bool:
        """True when the image must not change, so the untransformed scene's ground truth is the one to judge against."""
        return self.group == INVARIANT


# kind: (group, default value, description template)
_KINDS: dict[str, tuple[str, float | None, str]] = {
    "original": (INVARIANT, None, "the scene as loaded"),
    "scale": (INVARIANT, None, "scene and camera scaled by {v} about the origin"),
    "translate": (INVARIANT, None, "scene and camera moved by {v} along (1,1,1)/sqrt(3)"),
    "sliver": (INVARIANT, 1e6, "non-emitting rectangles cut into slivers of aspect {v}"),
    "light-shrink": (STRAIN, 1e3, "light area / {v}, radiance x {v} (same power)"),
    "grazing-camera": (STRAIN, 1.0, "camera {v} deg above the largest surface, looking along it"),
    "light-near-wall": (STRAIN, 1e-5, "light {v} x scene size in front of the wall behind it"),
    "light-edge-on": (STRAIN, None, "camera in the plane of the light"),
    "medium-density": (STRAIN, 1e3, "every medium's extinction x {v}"),
    "hg-g": (STRAIN, 0.99, "every medium's phase Henyey-Greenstein with g = {v}"),
}
_NEEDS_VALUE = ("scale", "translate")
_NO_VALUE = ("original", "light-edge-on")
#: The values a variant accepts (inclusive), beyond the open ranges parse_variant checks. A scale or translation
#: past 1e6 puts any scene of ordinary size where float32 (one ulp at |p| = 1e6 is 0.06) holds no detail, so its
#: row only repeats the expected fail of translate=1e5. Factors past 1e9 test nothing more: a sliver's short side
#: is then 2e-9 of its rectangle, far below float32's resolution (1.2e-7), and a light of 1e-9 its area is missed
#: by every camera sample of any practical budget.
BOUNDS: dict[str, tuple[float, float]] = {
    "scale": (1e-6, 1e6), "translate": (-1e6, 1e6), "sliver": (1.0, 1e9), "light-shrink": (1.0, 1e9),
    "medium-density": (1e-6, 1e6), "hg-g": (-0.999, 0.999),
}
#: The largest coordinate a transformed scene may have: float32 squares of larger ones (squared distances in
#: ray-triangle tests) overflow.
MAX_COORDINATE = float(np.sqrt(np.finfo(np.float32).max))


def variant_kinds() -> list[str]:
    return list(_KINDS)


def parse_variant(text: str, where: str = "variant") -> Variant:
    """A :class:`Variant` from ``KIND`` or ``KIND=VALUE`` (e.g. ``scale=1e-4``); bad text is a HarnessError naming
    ``where``."""
    if not isinstance(text, str):
        raise HarnessError(where, f"expected a string like 'scale=1e3', got {text!r}")
    kind, sep, raw = text.strip().partition("=")
    kind = kind.strip()
    if kind not in _KINDS:
        raise HarnessError(where, f"unknown variant {kind!r}; expected one of {', '.join(_KINDS)}")
    group, default, template = _KINDS[kind]
    if kind in _NO_VALUE:
        if sep:
            raise HarnessError(where, f"variant {kind!r} takes no value, got {text!r}")
        return Variant(kind, kind, None, group, template)
    if not sep:
        if kind in _NEEDS_VALUE:
            raise HarnessError(where, f"variant {kind!r} needs a value, e.g. '{kind}=1e3'")
        value = float(default)
    else:
        try:
            value = float(raw)
        except ValueError:
            raise HarnessError(where, f"expected a number after '{kind}=', got {raw.strip()!r}") from None
    if not math.isfinite(value):
        raise HarnessError(where, f"expected a finite number after '{kind}=', got {raw.strip()!r}")
    if kind in ("scale", "medium-density") and value <= 0:
        raise HarnessError(where, f"expected a positive scale factor, got {value:g}")
    if kind in ("sliver", "light-shrink") and value < 1:
        raise HarnessError(where, f"expected a factor >= 1, got {value:g}")
    low, high = BOUNDS.get(kind, (-math.inf, math.inf))
    if not low <= value <= high:
        raise HarnessError(where, f"expected a value from {low:g} to {high:g} after '{kind}=', got {value:g}")
    if kind == "grazing-camera" and not 0 < value < 90:
        raise HarnessError(where, f"expected an elevation in degrees in (0, 90), got {value:g}")
    if kind == "light-near-wall" and not 0 < value < 1:
        raise HarnessError(where, f"expected a gap in (0, 1) of the scene size, got {value:g}")
    name = f"{kind}={_number(value)}"
    return Variant(name, kind, value, group, template.format(v=_number(value)))


def check_variant_scene(scene: Scene) -> Scene:
    """``scene`` (a variant's result) if a renderer can take it: every triangle's vertices finite and within
    :data:`MAX_COORDINATE`, radiance finite (the reference core's geometry checks), camera likewise; else a
    HarnessError (without a location: the caller names the variant)."""
    try:
        geometry = triangulate(scene)
    except SettingsError as err:
        raise HarnessError("", f"gives an invalid scene: {err.key}: {err.message}") from None
    camera = np.asarray([scene.camera.origin, scene.camera.target], float)
    largest = float(np.max(np.abs(np.concatenate([np.asarray(geometry.vertices, float).reshape(-1, 3), camera]))))
    if not largest <= MAX_COORDINATE:
        raise HarnessError("", f"gives coordinates up to {largest:.3g}; expected at most {MAX_COORDINATE:.3g} "
                           "(beyond it float32 squared distances overflow)")
    return scene


def _number(value: float) -> str:
    """1e3 for 1000, 1e-4 for 0.0001, else %g."""
    if value > 0:
        exponent = round(math.log10(value))
        if value == 10.0**exponent and abs(exponent) >= 2:
            return f"1e{exponent}"
    return f"{value:g}"


# ---- scene transforms --------------------------------------------------------------------------------------------


def transform_scene(scene: Scene, matrix: np.ndarray) -> Scene:
    """Every shape, point and spot light and the camera (origin, target) moved by the 4x4 similarity ``matrix``
    (uniform positive scale s, translation), the lights' intensities times s^2, the media's ``scale`` divided by s; the camera's up
    vector and fov are unchanged, a thin lens's aperture and focus distance and an orthographic film's extent scaled by s, so the image
    is unchanged."""
    matrix = np.asarray(matrix, dtype=np.float64)
    shapes = [dataclasses.replace(s, to_world=matrix @ s.to_world) for s in scene.shapes]
    cam = scene.camera
    area = float(abs(np.linalg.det(matrix[:3, :3]))) ** (2.0 / 3.0)  # s^2

    def point(p):
        return tuple(float(x) for x in matrix[:3, :3] @ np.asarray(p, float) + matrix[:3, 3])

    camera = camera_kind(cam).moved(cam, point, area ** 0.5)
    # a medium's optical depth sigma_t x length is unchanged where its scale divides by s
    media = {name: dataclasses.replace(m, scale=m.scale / area ** 0.5) for name, m in scene.media.items()}
    return dataclasses.replace(scene, shapes=shapes, camera=camera, media=media,
                               emitters=tuple(EMITTERS[e.type].moved(e, matrix, area) for e in scene.emitters))


def scaled(scene: Scene, factor: float) -> Scene:
    """Scene and camera scaled about the origin by ``factor``; radiance unchanged."""
    return transform_scene(scene, scale_matrix(factor))


def translated(scene: Scene, distance: float) -> Scene:
    """Scene and camera moved by ``distance`` along :data:`TRANSLATE_DIRECTION`."""
    return transform_scene(scene, translate_matrix(distance * TRANSLATE_DIRECTION))


def world_points(scene: Scene) -> np.ndarray:
    points = [shape_triangles(s)[0] for s in scene.shapes]
    return np.concatenate(points) if points else np.zeros((0, 3))


def scene_size(scene: Scene) -> float:
    """The largest side of the bounding box of every shape."""
    points = world_points(scene)
    return float(np.max(points.max(axis=0) - points.min(axis=0))) if len(points) else 1.0


def _surface(shape: Shape) -> tuple[np.ndarray, np.ndarray, float]:
    """Area-weighted centroid, the unit normal of the largest triangle (front side) and the area of a shape."""
    vertices, triangles = shape_triangles(shape)
    corners = vertices[triangles]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    if not np.any(area > 0):
        raise HarnessError(f"shapes[{shape.index}]", f"shape {shape.name!r} has no area")
    centroid = (area[:, None] * corners.mean(axis=1)).sum(axis=0) / area.sum()
    normal = cross[np.argmax(area)] / (2 * area.max())
    return centroid, normal, float(area.sum())


def shrink_lights(scene: Scene, factor: float) -> Scene:
    """Every light's area divided by ``factor`` (uniform scale 1/sqrt(factor) about its centre), its radiance
    multiplied by ``factor``: the same power Le * A * pi."""
    linear = 1.0 / math.sqrt(factor)
    shapes = []
    for shape in scene.shapes:
        if shape.is_emitter:
            centre = _surface(shape)[0]
            about = translate_matrix(centre) @ scale_matrix(linear) @ translate_matrix(-centre)
            shape = dataclasses.replace(shape, to_world=about @ shape.to_world,
                                        emission=tuple(float(e) * factor for e in shape.emission))
        shapes.append(shape)
    if not any(s.is_emitter for s in scene.shapes):
        raise HarnessError(str(scene.path), "variant light-shrink: the scene has no light")
    return dataclasses.replace(scene, shapes=shapes)


def grazing_camera(scene: Scene, elevation_degrees: float) -> Scene:
    """The camera on the largest non-emitting shape (the first of equals): at its centre c plus d (cos e w + sin e n),
    looking at c, with n its normal on the camera's side, w the in-plane direction toward the old camera and d the
    shape's extent along w; up = n."""
    candidates = [s for s in scene.shapes if not s.is_emitter]
    if not candidates:
        raise HarnessError(str(scene.path), "variant grazing-camera: the scene has no non-emitting shape")
    surfaces = [_surface(s) for s in candidates]
    index = int(np.argmax([round(area, 9) for _c, _n, area in surfaces]))
    centre, normal, _area = surfaces[index]
    vertices = shape_triangles(candidates[index])[0]
    towards = np.asarray(scene.camera.origin, float) - centre
    if towards @ normal < 0:
        normal = -normal
    in_plane = towards - (towards @ normal) * normal
    if np.linalg.norm(in_plane) < 1e-12 * max(np.linalg.norm(towards), 1e-300):
        in_plane = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    in_plane /= np.linalg.norm(in_plane)
    distance = float(np.max((vertices - centre) @ in_plane))
    e = math.radians(elevation_degrees)
    origin = centre + distance * (math.cos(e) * in_plane + math.sin(e) * normal)
    camera = dataclasses.replace(scene.camera, origin=tuple(map(float, origin)), target=tuple(map(float, centre)),
                                 up=tuple(map(float, normal)))
    return dataclasses.replace(scene, camera=camera)


def light_near_wall(scene: Scene, gap_fraction: float) -> Scene:
    """Every light moved along its normal n so that the first surface behind it (hit by the ray from its centre
    along -n) is ``gap_fraction`` * scene size away."""
    gap = gap_fraction * scene_size(scene)
    blockers = [s for s in scene.shapes if not s.is_emitter]
    corners = np.concatenate([shape_triangles(s)[0][shape_triangles(s)[1]] for s in blockers]) if blockers else None
    shapes, moved = [], 0
    for shape in scene.shapes:
        if shape.is_emitter and corners is not None:
            centre, normal, _ = _surface(shape)
            behind = _ray_triangles(centre, -normal, corners)
            if math.isfinite(behind):
                shape = dataclasses.replace(shape, to_world=translate_matrix(-(behind - gap) * normal) @ shape.to_world)
                moved += 1
        shapes.append(shape)
    if not moved:
        raise HarnessError(str(scene.path), "variant light-near-wall: no light has a surface behind it")
    return dataclasses.replace(scene, shapes=shapes)


def _ray_triangles(origin: np.ndarray, direction: np.ndarray, corners: np.ndarray) -> float:
    """Distance to the nearest of (T, 3, 3) triangles along the ray (Moller-Trumbore, float64), inf if none."""
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = origin - corners[:, 0]
        u = np.einsum("ij,ij->i", s, p) * inv
        q = np.cross(s, e1)
        v = (q @ direction) * inv
        t = np.einsum("ij,ij->i", e2, q) * inv
        ok = (np.abs(det) > 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return float(t[ok].min()) if np.any(ok) else math.inf


def light_edge_on(scene: Scene) -> Scene:
    """The camera moved into the plane of the first light (its old position projected onto that plane), looking
    at the light's centre."""
    lights = scene.lights
    if not lights:
        raise HarnessError(str(scene.path), "variant light-edge-on: the scene has no light")
    centre, normal, _ = _surface(lights[0])
    towards = np.asarray(scene.camera.origin, float) - centre
    in_plane = towards - (towards @ normal) * normal
    if np.linalg.norm(in_plane) < 1e-9 * max(np.linalg.norm(towards), 1e-300):
        raise HarnessError(str(scene.path), "variant light-edge-on: the camera looks straight at the light")
    origin = centre + in_plane
    up = np.asarray(scene.camera.up, float)
    if np.linalg.norm(np.cross(up, in_plane)) < 1e-3 * np.linalg.norm(up) * np.linalg.norm(in_plane):
        up = normal
    camera = dataclasses.replace(scene.camera, origin=tuple(map(float, origin)), target=tuple(map(float, centre)),
                                 up=tuple(map(float, up)))
    return dataclasses.replace(scene, camera=camera)


def sliver_rectangle(aspect: float) -> tuple[np.ndarray, np.ndarray]:
    """The unit rectangle ([-1, 1]^2, z = 0, facing +z) as 8 triangles: each of its two triangles (a, b, c) becomes
    a fan from a over b, b + h (c - b), m, m + h (c - b), c (m the midpoint of bc) with h = 2 / aspect, so two
    triangles of each fan are slivers of aspect (longest edge / shortest altitude) ~``aspect``."""
    vertices, triangles = unit_rectangle()
    h = 2.0 / aspect
    out_v, out_t = [], []
    for a, b, c in triangles:
        pa, pb, pc = vertices[a], vertices[b], vertices[c]
        pm = 0.5 * (pb + pc)
        fan = [pb, pb + h * (pc - pb), pm, pm + h * (pc - pb), pc]
        first = len(out_v)
        out_v += [pa, *fan]
        out_t += [[first, first + i, first + i + 1] for i in range(1, len(fan))]
    return np.array(out_v), np.array(out_t, dtype=np.int64)


def triangle_aspects(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Longest edge / shortest altitude = longest edge^2 / (2 area) of each triangle."""
    c = vertices[triangles]
    edges = np.stack([c[:, 1] - c[:, 0], c[:, 2] - c[:, 1], c[:, 0] - c[:, 2]], axis=1)
    longest = np.max(np.linalg.norm(edges, axis=2), axis=1)
    double_area = np.linalg.norm(np.cross(edges[:, 0], -edges[:, 2]), axis=1)
    return longest**2 / double_area


def sliver_walls(scene: Scene, aspect: float) -> Scene:
    """Every non-emitting rectangle replaced by a mesh of the same surface cut into slivers
    (:func:`sliver_rectangle`). The front side is kept: a rectangle under a mirroring placement keeps its front
    side (Mitsuba's rule), a mesh swaps it, so the mesh is wound the other way there."""
    vertices, triangles = sliver_rectangle(aspect)
    shapes, replaced = [], 0
    for shape in scene.shapes:
        if shape.type == "rectangle" and not shape.is_emitter:
            mirrored = np.linalg.det(object_to_world(shape)[:3, :3]) < 0
            shape = dataclasses.replace(shape, type="mesh", mesh_vertices=vertices.copy(),
                                        mesh_triangles=triangles[:, [0, 2, 1]] if mirrored else triangles.copy(),
                                        mesh_uv=rectangle_uv(vertices),  # the rectangle's texture coordinates
                                        face_normals=True)  # flat, as the rectangle
            replaced += 1
        shapes.append(shape)
    if not replaced:
        raise HarnessError(str(scene.path), "variant sliver: the scene has no non-emitting rectangle to cut")
    return dataclasses.replace(scene, shapes=shapes)


def denser_media(scene: Scene, factor: float) -> Scene:
    """Every medium's ``scale`` multiplied by ``factor`` (its extinction, sigma_t x scale, with it); HarnessError on
    a scene without media."""
    if not scene.media:
        raise HarnessError(str(scene.path), "variant medium-density: the scene has no [media]")
    media = {name: dataclasses.replace(m, scale=m.scale * factor) for name, m in scene.media.items()}
    return dataclasses.replace(scene, media=media)


def hg_media(scene: Scene, g: float) -> Scene:
    """Every medium's phase function Henyey-Greenstein with asymmetry ``g``; HarnessError on a scene without
    media."""
    if not scene.media:
        raise HarnessError(str(scene.path), "variant hg-g: the scene has no [media]")
    return dataclasses.replace(scene, media={name: dataclasses.replace(m, phase="hg", g=g)
                                             for name, m in scene.media.items()})


_APPLY: dict[str, Callable[[Scene, float | None], Scene]] = {
    "original": lambda scene, _v: scene,
    "scale": scaled,
    "translate": translated,
    "sliver": sliver_walls,
    "light-shrink": shrink_lights,
    "grazing-camera": grazing_camera,
    "light-near-wall": light_near_wall,
    "light-edge-on": lambda scene, _v: light_edge_on(scene),
    "medium-density": denser_media,
    "hg-g": hg_media,
}
