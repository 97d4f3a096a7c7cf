"""The numerical-stability stress suite: variants of a scene, rendered and judged (``harness stress``).

Two groups of variants, all generated in memory from a loaded :class:`~harness.scene.Scene`:

* **invariant** variants must not change the image, so they are judged against the *untransformed* scene's
  ground truth (cached):

  - ``scale=s``: every shape and the camera's origin and target scaled by ``s`` about the origin
    (p' = s p); emitted radiance unchanged. A pinhole image depends on directions only, so it is the same image.
  - ``translate=d``: everything moved by the vector d (1, 1, 1) / sqrt(3) (length d).
  - ``sliver=a``: every non-emitting rectangle re-triangulated into a fan with sliver triangles of aspect ``a``
    (longest edge / shortest altitude); the surface, hence the image, is unchanged.

* **strain** variants change the image and strain the estimator; each is judged against Mitsuba's ground truth of
  the *transformed* scene:

  - ``light-shrink=f``: every light's area divided by ``f`` about its centre, its radiance multiplied by ``f``
    (same power).
  - ``grazing-camera=e``: the camera moved onto the largest non-emitting surface, ``e`` degrees above it, looking
    at its centre along it.
  - ``light-near-wall=g``: every light moved along its normal until it sits ``g`` times the scene size in front of
    the surface behind it.
  - ``light-edge-on``: the camera moved into the plane of the first light, looking at its centre.

Each (variant, renderer) row counts NaN, Inf and negative pixels, gives RMSE and relMSE against the ground truth,
the verdict's global bias z, the fireflies (pixels whose |render - GT| exceeds k standard deviations, see
:func:`fireflies`), the render time and the verdict (:func:`harness.compare.compare_images`). Where float32 cannot
represent the variant well enough (:func:`float32_limits`) the row is an *expected* fail and its note says why.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from harness.errors import HarnessError
from harness.options import require_non_negative, require_positive
from harness.scene.model import Scene, Shape
from harness.scene.triangulate import (
    object_to_world,
    scale_matrix,
    shape_triangles,
    translate_matrix,
    unit_rectangle,
)

INVARIANT, STRAIN = "invariant", "strain"
#: Default firefly threshold, in standard deviations.
DEFAULT_K = 6.0
#: Direction of the translation variants (unit vector): no axis is spared.
TRANSLATE_DIRECTION = np.ones(3) / math.sqrt(3.0)
#: A variant whose float32 position error (one ulp of its largest coordinate) exceeds this fraction of the scene
#: size is an expected fail: a 64x64 pixel footprint is ~1e-2 of the scene, a shadow-terminator or contact detail
#: ~1e-3 of it, and the reference's ray offsets (64-128 ulps) then exceed ~10 % of the scene size.
ULP_FRACTION_LIMIT = 1e-3
#: Mitsuba 3's ``math::RayEpsilon<float>`` = 1500 * 2^-24: it offsets ray origins by (1 + max|p|) times this.
MITSUBA_RAY_EPSILON = 1500 * 2.0**-24
#: A ray offset above this fraction of the scene size visibly biases a 64x64 render of a scene with contact
#: shadows (measured: the reference fails cornell-box translated by 1e4 with its offset at 2.2 %, passes at 0.2 %).
OFFSET_FRACTION_LIMIT = 1e-2

DEFAULT_VARIANTS = (
    "original",
    *(f"scale=1e{e}" for e in (-4, -3, -2, -1, 1, 2, 3, 4)),
    *(f"translate=1e{e}" for e in (2, 3, 4, 5)),
    "sliver=1e6",
    "light-shrink=1e3",
    "grazing-camera=1",
    "light-near-wall=1e-5",
    "light-edge-on",
)


# ---- variants --------------------------------------------------------------------------------------------------


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
        """The transformed scene."""
        return _APPLY[self.kind](scene, self.value)

    @property
    def judged_against_original(self) -> bool:
        """True when the image must not change, so the untransformed scene's ground truth is the reference."""
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
}
_NEEDS_VALUE = ("scale", "translate")
_NO_VALUE = ("original", "light-edge-on")


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
    if kind == "scale" and value <= 0:
        raise HarnessError(where, f"expected a positive scale factor, got {value:g}")
    if kind in ("sliver", "light-shrink") and value < 1:
        raise HarnessError(where, f"expected a factor >= 1, got {value:g}")
    if kind == "grazing-camera" and not 0 < value < 90:
        raise HarnessError(where, f"expected an elevation in degrees in (0, 90), got {value:g}")
    if kind == "light-near-wall" and not 0 < value < 1:
        raise HarnessError(where, f"expected a gap in (0, 1) of the scene size, got {value:g}")
    name = f"{kind}={_number(value)}"
    return Variant(name, kind, value, group, template.format(v=_number(value)))


def _number(value: float) -> str:
    """1e3 for 1000, 1e-4 for 0.0001, else %g."""
    if value > 0:
        exponent = round(math.log10(value))
        if value == 10.0**exponent and abs(exponent) >= 2:
            return f"1e{exponent}"
    return f"{value:g}"


# ---- scene transforms --------------------------------------------------------------------------------------------


def transform_scene(scene: Scene, matrix: np.ndarray) -> Scene:
    """Every shape and the camera (origin, target) moved by the 4x4 similarity ``matrix`` (uniform positive scale,
    translation); the camera's up vector and fov are unchanged, so the image is unchanged."""
    matrix = np.asarray(matrix, dtype=np.float64)
    shapes = [dataclasses.replace(s, to_world=matrix @ s.to_world) for s in scene.shapes]
    cam = scene.camera

    def point(p):
        return tuple(float(x) for x in matrix[:3, :3] @ np.asarray(p, float) + matrix[:3, 3])

    camera = dataclasses.replace(cam, origin=point(cam.origin), target=point(cam.target))
    return dataclasses.replace(scene, shapes=shapes, camera=camera)


def scaled(scene: Scene, factor: float) -> Scene:
    """Scene and camera scaled about the origin by ``factor``; radiance unchanged."""
    return transform_scene(scene, scale_matrix(factor))


def translated(scene: Scene, distance: float) -> Scene:
    """Scene and camera moved by ``distance`` along :data:`TRANSLATE_DIRECTION`."""
    return transform_scene(scene, translate_matrix(distance * TRANSLATE_DIRECTION))


def _world_points(scene: Scene) -> np.ndarray:
    points = [shape_triangles(s)[0] for s in scene.shapes]
    return np.concatenate(points) if points else np.zeros((0, 3))


def scene_size(scene: Scene) -> float:
    """The largest side of the bounding box of every shape."""
    points = _world_points(scene)
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
                                        mesh_triangles=triangles[:, [0, 2, 1]] if mirrored else triangles.copy())
            replaced += 1
        shapes.append(shape)
    if not replaced:
        raise HarnessError(str(scene.path), "variant sliver: the scene has no non-emitting rectangle to cut")
    return dataclasses.replace(scene, shapes=shapes)


_APPLY: dict[str, Callable[[Scene, float | None], Scene]] = {
    "original": lambda scene, _v: scene,
    "scale": scaled,
    "translate": translated,
    "sliver": sliver_walls,
    "light-shrink": shrink_lights,
    "grazing-camera": grazing_camera,
    "light-near-wall": light_near_wall,
    "light-edge-on": lambda scene, _v: light_edge_on(scene),
}


# ---- float32 limits ----------------------------------------------------------------------------------------------


def reference_offset_rel() -> float:
    """The reference's relative ray offset, read from its kernels (the constant the renders use)."""
    from reference_impl.kernels import surface as kernels

    return float(kernels._OFFSET_REL)


def float32_limits(scene: Scene) -> dict:
    """How well float32 (Embree's and Mitsuba's precision) holds the scene: the largest coordinate |p| of any
    vertex or the camera, one float32 ulp there, and the ray offset each renderer uses there (the reference:
    ``kernels._OFFSET_REL`` |p| + 2^-22 max|p|; Mitsuba: ``Interaction::offset_p``, (1 + |p|) * 1500 * 2^-24), all
    also as fractions of the scene size.

    ``expected_fail`` (every renderer) when the ulp exceeds :data:`ULP_FRACTION_LIMIT` of the scene size: no
    float32 renderer can hold the scene. ``mitsuba_expected_fail`` also when Mitsuba's offset exceeds
    :data:`OFFSET_FRACTION_LIMIT` of it (Mitsuba's offset has an absolute part, so it fails small scenes too). The
    reference's offset is its own choice, so a reference fail caused by it is a bug, not expected.
    """
    points = np.concatenate([_world_points(scene), np.asarray([scene.camera.origin], float)])
    p = float(np.max(np.abs(points)))
    size = scene_size(scene)
    ulp = float(np.spacing(np.float32(p)))
    offsets = {"reference": reference_offset_rel() * p + 2.0**-22 * p, "mitsuba": (1.0 + p) * MITSUBA_RAY_EPSILON}
    fractions = {name: value / size for name, value in offsets.items()}
    expected_fail = ulp > ULP_FRACTION_LIMIT * size
    return {"max_abs_coordinate": p, "scene_size": size, "ulp": ulp, "ulp_fraction": ulp / size,
            "offset": offsets, "offset_fraction": fractions, "expected_fail": expected_fail,
            "mitsuba_expected_fail": expected_fail or fractions["mitsuba"] > OFFSET_FRACTION_LIMIT}


def limits_note(limits: dict, renderer: str) -> str:
    """``|p| 5.8e3: ulp 0.024%, ray offset 2.2% of size`` (and why a fail is expected, where it is)."""
    offset = limits["offset_fraction"].get(renderer)
    text = f"|p| {limits['max_abs_coordinate']:.2g}: f32 ulp {100 * limits['ulp_fraction']:.2g}%"
    if offset is not None:
        text += f", ray offset {100 * offset:.2g}%"
    text += f" of size {limits['scene_size']:.3g}"
    if limits["expected_fail"]:
        text += f"; expected: ulp > {100 * ULP_FRACTION_LIMIT:g}% of size, float32 cannot hold the scene"
    elif renderer == "mitsuba" and limits["mitsuba_expected_fail"]:
        text += f"; expected: Mitsuba's offset (1+|p|)*1500*2^-24 > {100 * OFFSET_FRACTION_LIMIT:g}% of size"
    return text


def expected_verdict(limits: dict, renderer: str) -> str:
    if limits["expected_fail"] or (renderer == "mitsuba" and limits["mitsuba_expected_fail"]):
        return "fail"
    return "pass"


# ---- per-image statistics ----------------------------------------------------------------------------------------


def pixel_counts(image: np.ndarray) -> dict[str, int]:
    """Pixels with a NaN channel, with an infinite channel, and with a finite negative channel."""
    image = np.asarray(image)
    return {
        "nan": int(np.count_nonzero(np.any(np.isnan(image), axis=2))),
        "inf": int(np.count_nonzero(np.any(np.isinf(image), axis=2))),
        "negative": int(np.count_nonzero(np.any(np.isfinite(image) & (image < 0), axis=2))),
    }


def fireflies(image, variance, reference, reference_variance, k: float = DEFAULT_K, dof: int | None = None) -> dict:
    """Outlier pixels: ``count`` (fireflies) where some channel has render - reference > k sqrt(V_render +
    V_reference), ``dark`` where some channel has reference - render > k sqrt(...) (each V the variance of the
    pixel's estimate); finite pixels only; a difference with zero variance counts.

    ``expected`` is the count a correct, normally distributed render would have on one side by chance:
    pixels * channels * Q(k), with Q the upper tail of Student's t with ``dof`` (spp - 1) degrees of freedom (the
    variance is estimated) or of the normal when ``dof`` is None. Real fireflies are heavy-tailed outliers, far
    more frequent than that; so are dark outliers, in pixels whose rare bright paths were not drawn (their sample
    variance underestimates the true one): the untransformed scene's row is the baseline to compare with.
    """
    t = np.asarray(image, np.float64)
    r = np.asarray(reference, np.float64)
    sigma = np.sqrt(np.asarray(variance, np.float64) + np.asarray(reference_variance, np.float64))
    diff = t - r
    with np.errstate(invalid="ignore"):
        usable = np.isfinite(diff) & np.isfinite(sigma)
        bright = usable & (diff > k * sigma)
        dark = usable & (-diff > k * sigma)
    tail = stats.norm.sf(k) if dof is None else stats.t.sf(k, dof)
    return {"count": int(np.count_nonzero(np.any(bright, axis=2))), "dark": int(np.count_nonzero(np.any(dark, axis=2))),
            "k": float(k), "expected": float(t.shape[0] * t.shape[1] * t.shape[2] * tail)}


def undersampled_light(scene: Scene, reference: np.ndarray, reference_variance: np.ndarray, reference_spp: int,
                       spp: int) -> dict | None:
    """The pixel most likely to miss a directly seen light: coverage c = reference / Le (the fraction of the pixel
    that sees the light, estimated from the ground truth, in the channel of the brightest emission), and
    P(no camera sample of ``spp`` hits it) = (1 - c)^spp. Only pixels that look like a partly covered light count:
    c > 1e-3 and a per-sample variance (reference_variance * reference_spp) of at least half the Bernoulli variance
    Le^2 c (1 - c). When P is not small the pixel is a rare event: its sample variance misses the light and the
    verdict's normal approximation fails there. None when no such pixel is seen (or the reference is exact)."""
    emissions = [np.asarray(s.emission, float) for s in scene.lights]
    if not emissions:
        return None
    brightest = np.max(emissions, axis=0)
    channel = int(np.argmax(brightest))
    coverage = np.asarray(reference, np.float64)[..., channel] / brightest[channel]
    per_sample = np.asarray(reference_variance, np.float64)[..., channel] * max(reference_spp, 0)
    bernoulli = brightest[channel] ** 2 * coverage * (1.0 - coverage)
    seen = (coverage > 1e-3) & (coverage < 1.0) & (per_sample >= 0.5 * bernoulli)
    if not np.any(seen):
        return None
    p_miss = np.where(seen, (1.0 - np.clip(coverage, 0.0, 1.0)) ** spp, 0.0)
    y, x = np.unravel_index(int(np.argmax(p_miss)), p_miss.shape)
    return {"pixel": [int(y), int(x)], "coverage": float(coverage[y, x]), "p_miss": float(p_miss[y, x])}


# ---- running -----------------------------------------------------------------------------------------------------


def run_stress(
    scene: Scene,
    renderers: list[str],
    *,
    variants: list[str] | None = None,
    spp: int = 64,
    seed: int = 0,
    ground_truth_spp: int = 1024,
    k: float = DEFAULT_K,
    alpha: float = 0.001,
    cache_dir=None,
    mitsuba_variant: str | None = None,
    settings: dict[str, str] | None = None,
    on_row: Callable[[dict], None] | None = None,
) -> dict:
    """Render every variant with every renderer and judge it; returns ``{"scene", "film", "spp", "k", "alpha",
    "ground_truth": {...}, "rows": [...], "ok"}`` (see ``docs/stress.md``). ``ok`` is True when every invariant
    variant of the reference ends as expected (passes, or fails where float32 limits make that expected).
    ``settings`` are the reference renderer's ``--set`` values (Mitsuba takes none)."""
    from harness import groundtruth
    from harness.compare import compare_images
    from harness.imageio import ExrImage
    from harness.renderers import RenderRequest, get_renderer

    parsed = [parse_variant(v, "--variant") for v in (variants or DEFAULT_VARIANTS)]
    engines = {name: get_renderer(name) for name in renderers}
    gt_cache: dict[str, groundtruth.GroundTruth] = {}

    def truth(target: Scene, key: str):
        if key not in gt_cache:  # the untransformed scene may use its closed form; a strained one may not
            gt_cache[key] = groundtruth.ground_truth(target, spp=ground_truth_spp, cache_dir=cache_dir,
                                                     variant=mitsuba_variant, use_closed_form=key == "original")
        return gt_cache[key]

    rows = []
    for variant in parsed:
        try:
            transformed = variant.apply(scene)
        except HarnessError as err:  # a variant this scene cannot have (no light, no rectangle): a skipped row
            for name in engines:
                row = {"variant": variant.name, "group": variant.group, "renderer": name, "against": "-",
                       "expect": "pass", "note": str(err), "verdict": "skipped", "ok": True}
                rows.append(row)
                if on_row is not None:
                    on_row(row)
            continue
        limits = float32_limits(transformed)
        geometric = variant.kind in ("original", "scale", "translate")
        gt = truth(scene, "original") if variant.judged_against_original else truth(transformed, variant.name)
        for name, engine in engines.items():
            if name == "mitsuba":
                chosen = {"variant": mitsuba_variant} if mitsuba_variant else {}
            else:
                chosen = dict(settings or {})
            row = {"variant": variant.name, "group": variant.group, "renderer": name,
                   "against": "original" if variant.judged_against_original else "own ground truth",
                   "expect": expected_verdict(limits, name),
                   "note": limits_note(limits, name) if geometric or limits["expected_fail"] else variant.description,
                   "float32": limits}
            expect = row["expect"]
            start = time.perf_counter()
            try:
                result = engine.render(transformed, RenderRequest(spp=spp, seed=seed + 7919, settings=chosen))
                row.update(_judge(result, gt, k, alpha, compare_images, ExrImage))
                light = undersampled_light(transformed, gt.image, gt.variance, gt.spp, spp)
                row["undersampled_light"] = light
                if row["verdict"] == "fail" and light is not None and light["p_miss"] > 0.01 \
                        and _near_tile(light["pixel"], row.get("worst_tile")):
                    row["note"] += (f"; pixel {tuple(light['pixel'])} sees a light over {100 * light['coverage']:.2g}%"
                                    f" of its area: P(no sample hits it at {spp} spp) = {light['p_miss']:.2g}")
            except Exception as err:  # noqa: BLE001 - a renderer that breaks on a variant is a row, not a crash
                reason = " ".join(f"{type(err).__name__}: {err}".split())[:300]
                row.update(verdict="error", reason=reason, seconds=time.perf_counter() - start)
            row["ok"] = row["verdict"] == expect or (expect == "fail" and row["verdict"] in ("pass", "error"))
            if expect == "fail" and row["verdict"] == "pass":
                row["note"] = "passed despite: " + row["note"]
            rows.append(row)
            if on_row is not None:
                on_row(row)
    original_gt = gt_cache.get("original") or truth(scene, "original")
    ok = all(r["ok"] for r in rows if r["renderer"] == "reference" and r["group"] == INVARIANT)
    return {
        "scene": str(scene.path), "name": scene.name, "film": [scene.film.width, scene.film.height],
        "spp": spp, "seed": seed, "k": k, "alpha": alpha, "settings": dict(settings or {}),
        "ground_truth": {"spp": ground_truth_spp, "source": original_gt.source,
                         "variant": original_gt.info.get("variant"),
                         "mitsuba": original_gt.info.get("mitsuba")},
        "renderers": list(renderers), "rows": rows, "ok": ok,
    }


def _judge(result, gt, k, alpha, compare_images, ExrImage) -> dict:
    counts = pixel_counts(result.image)
    fly = fireflies(result.image, result.variance, gt.image, gt.variance, k, dof=max(result.spp - 1, 1))
    comparison = compare_images(ExrImage(result.image, result.variance, {"spp": str(result.spp)}),
                                ExrImage(gt.image, gt.variance, {"spp": str(gt.spp)}), alpha=alpha)
    verdict = comparison["verdict"]
    z = [abs(v) for v in verdict["global_bias"].get("z", []) if v is not None]
    return dict(counts, rmse=comparison["metrics"]["rmse"], relmse=comparison["metrics"]["relmse"],
                bias_z=max(z) if z else None, fireflies=fly["count"], dark=fly["dark"], fireflies_expected=fly["expected"],
                seconds=float(result.seconds), verdict=verdict["verdict"], reason=verdict.get("reason", ""),
                worst_tile=verdict.get("worst_tile"))


def _near_tile(pixel, tile: dict | None) -> bool:
    """True if ``pixel`` (y, x) lies in the verdict's worst tile or one pixel around it."""
    if not tile:
        return False
    y, x = pixel
    return (tile["y"] - 1 <= y <= tile["y"] + tile["height"]) and (tile["x"] - 1 <= x <= tile["x"] + tile["width"])


# ---- the table ---------------------------------------------------------------------------------------------------

COLUMNS = ("variant", "renderer", "nan", "inf", "neg", "rmse", "relmse", "bias z", "fireflies", "dark", "s", "verdict",
           "note")


def table_rows(result: dict) -> list[list[str]]:
    """The table's cells, one list per (variant, renderer) row."""
    out = []
    for r in result["rows"]:
        verdict = r["verdict"]
        if r["expect"] == "fail":
            verdict += " (expected fail)" if verdict != "pass" else " (expected fail: passed)"
        if verdict.startswith("error"):
            note = r.get("reason", "")
        elif r["verdict"] == "fail" and r["expect"] == "pass":
            note = f"{r['note']}; {r.get('reason', '')}"
        else:
            note = r["note"]
        out.append([
            r["variant"], r["renderer"], _cell(r.get("nan")), _cell(r.get("inf")), _cell(r.get("negative")),
            _cell(r.get("rmse"), ".3g"), _cell(r.get("relmse"), ".3g"), _cell(r.get("bias_z"), ".2f"),
            _cell(r.get("fireflies")), _cell(r.get("dark")), _cell(r.get("seconds"), ".2f"), verdict, note,
        ])
    return out


def _cell(value, fmt: str = "d") -> str:
    if value is None:
        return "-"
    return format(value, fmt)


def format_table(result: dict, markdown: bool = False) -> str:
    """The stress table as aligned text, or as a Markdown table."""
    rows = table_rows(result)
    if markdown:
        lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
        lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rows]
        return "\n".join(lines)
    widths = [max(len(h), *(len(row[i]) for row in rows)) if rows else len(h) for i, h in enumerate(COLUMNS[:-1])]
    def line(cells):
        return "  ".join(c.ljust(w) for c, w in zip(cells[:-1], widths)) + "  " + cells[-1]
    return "\n".join([line(list(COLUMNS)), *(line(row) for row in rows)])


def summary_line(result: dict) -> str:
    """One line: the firefly rule and what the exit code means."""
    k = result["k"]
    fly = next((r.get("fireflies_expected") for r in result["rows"] if r.get("fireflies_expected") is not None), None)
    chance = f"{fly:.2g}" if fly is not None else "n/a"
    gt = result["ground_truth"]
    source = ("closed form" if gt.get("source") == "closed-form"
              else f"Mitsuba {gt.get('variant')} {gt['spp']} spp")
    return (f"{result['name']} {result['film'][0]}x{result['film'][1]}, {result['spp']} spp, ground truth "
            f"{source}; fireflies: "
            f"render - GT > {k:g} sigma, dark: GT - render > {k:g} sigma (each expected by chance per row: "
            f"{chance}); verdict alpha "
            f"{result['alpha']:g}; reference invariants as expected: {'yes' if result['ok'] else 'NO'}")


# ---- the command line ------------------------------------------------------------------------------------------


def add_parser(sub) -> None:
    """``harness stress``: called by :func:`harness.cli.build_parser`."""
    stress = sub.add_parser("stress", help="numerical-stability stress table: scaled, translated and strained "
                            "variants of a scene, per renderer (exit 0 when every invariant variant of the "
                            "reference ends as expected)")
    stress.add_argument("scene", help="scene file or name in scenes/")
    stress.add_argument("--renderer", action="append", help="renderer (repeatable; default: reference and mitsuba)")
    stress.add_argument("--variant", action="append", metavar="KIND[=VALUE]",
                        help=f"a variant (repeatable; default: all of {', '.join(DEFAULT_VARIANTS)})")
    stress.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a reference renderer setting (repeatable), e.g. direct=mis or mutant=double-emission")
    stress.add_argument("--spp", type=int, default=64, help="samples per pixel of each render (default 64)")
    stress.add_argument("--seed", type=int, default=0)
    stress.add_argument("--film", default="64x64", help="resolution WIDTHxHEIGHT (default 64x64)")
    stress.add_argument("--ground-truth-spp", type=int, default=1024, help="Mitsuba ground truth spp (default 1024)")
    stress.add_argument("--k", type=float, default=DEFAULT_K,
                        help=f"firefly threshold in standard deviations (default {DEFAULT_K:g})")
    stress.add_argument("--alpha", type=float, default=0.001, help="verdict false-alarm probability (default 0.001)")
    stress.add_argument("--out", help="folder for stress.json and stress.md")
    stress.add_argument("--cache-dir", help="ground-truth cache folder")
    stress.add_argument("--mitsuba-variant", help="override the Mitsuba variant")
    stress.add_argument("--json", action="store_true", help="print the result as JSON")
    stress.add_argument("--quiet", action="store_true", help="no progress bar")
    stress.set_defaults(func=command)


def _resolve_scene(text: str):
    from pathlib import Path

    from harness.scene import load_scene

    path = Path(text)
    if not path.is_file() and "/" not in text and not text.endswith(".toml"):
        for candidate in (Path("scenes") / f"{text}.toml", Path(__file__).resolve().parent.parent / "scenes" / f"{text}.toml"):
            if candidate.is_file():
                path = candidate
                break
    return load_scene(path)


def command(args) -> int:
    """``harness stress``: 0 when every invariant variant of the reference ends as expected, 1 otherwise."""
    import json
    import sys
    from pathlib import Path

    from harness.imageio import atomic_write_text
    from harness.renderers import renderer_names
    from reference_impl import Film

    for name, value in (("--spp", args.spp), ("--ground-truth-spp", args.ground_truth_spp)):
        require_positive(name, value)
    require_non_negative("--seed", args.seed)
    if not (math.isfinite(args.k) and args.k > 0):
        raise HarnessError("--k", f"expected a positive number of standard deviations, got {args.k}")
    if not 0 < args.alpha < 1:
        raise HarnessError("--alpha", f"expected a probability in (0, 1), got {args.alpha}")
    w, sep, h = args.film.lower().partition("x")
    if not sep or not w.isdigit() or not h.isdigit() or int(w) < 1 or int(h) < 1:
        raise HarnessError("--film", f"expected WIDTHxHEIGHT, e.g. 64x64, got {args.film!r}")
    from harness.cli import _parse_set

    settings = _parse_set(args.set)
    renderers = args.renderer or ["reference", "mitsuba"]
    for name in renderers:
        if name not in renderer_names():
            raise HarnessError("--renderer", f"expected one of {', '.join(renderer_names())}, got {name!r}")
    renderers = list(dict.fromkeys(renderers))
    variants = args.variant or list(DEFAULT_VARIANTS)
    for text in variants:
        parse_variant(text, "--variant")
    out = Path(args.out) if args.out else None
    if out is not None:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise HarnessError("--out", f"cannot create {str(out)!r}: {err.strerror}") from None
    scene = _resolve_scene(args.scene)
    scene = dataclasses.replace(scene, film=Film(int(w), int(h), scene.film.filter))
    if settings:
        from harness.renderers import RenderRequest
        from harness.renderers.reference import ReferenceRenderer

        ReferenceRenderer().settings_for(scene, RenderRequest(spp=args.spp, seed=args.seed, settings=settings))

    bar = None
    if not args.quiet and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=len(variants) * len(renderers), desc=f"stress {scene.name}", unit="render",
                   file=sys.stderr, leave=False)

    def on_row(row: dict) -> None:
        if bar is not None:
            bar.set_postfix_str(f"{row['variant']} {row['renderer']}: {row['verdict']}")
            bar.update(1)

    try:
        result = run_stress(scene, renderers, variants=variants, spp=args.spp, seed=args.seed,
                            ground_truth_spp=args.ground_truth_spp, k=args.k, alpha=args.alpha,
                            cache_dir=args.cache_dir, mitsuba_variant=args.mitsuba_variant, settings=settings,
                            on_row=on_row)
    finally:
        if bar is not None:
            bar.close()
    text = format_table(result)
    if out is not None:
        atomic_write_text(out / "stress.json", json.dumps(_plain(result), indent=2, allow_nan=False))
        atomic_write_text(out / "stress.md", f"{summary_line(result)}\n\n{format_table(result, markdown=True)}\n")
    if args.json:
        print(json.dumps(_plain(result), indent=2, allow_nan=False))
    else:
        print(text)
        print(summary_line(result))
        if out is not None:
            print(f"wrote {out / 'stress.json'} and {out / 'stress.md'}")
    return 0 if result["ok"] else 1


def _plain(value):
    """JSON-ready: numpy scalars to Python, non-finite floats to None."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


__all__ = [
    "DEFAULT_VARIANTS", "Variant", "parse_variant", "variant_kinds", "transform_scene", "scaled", "translated",
    "shrink_lights", "grazing_camera", "light_near_wall", "light_edge_on", "sliver_walls", "sliver_rectangle",
    "triangle_aspects", "float32_limits", "pixel_counts", "fireflies", "run_stress", "format_table", "table_rows",
    "summary_line", "scene_size",
]
