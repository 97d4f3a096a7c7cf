"""Emitters that are not surfaces: point, spot and directional lights (delta lights) and environments, with their
radiance, power and the direction samplers of the environments, each beside its pdf (Mitsuba 3's plugins of the same
names and parameters: ``point``, ``spot``, ``directional``, ``constant``, ``envmap``).

The integrator's light k runs over the area lights first (k < N_A, :class:`reference_impl.lights.LightSampler`), then
over these emitters, in the order given (k = N_A + e). At most one environment (as in Mitsuba).

What a light sample of each kind brings to a point x with normal N_x (f_r the BRDF, pdf(k) the selection pdf):

=============== ===================================================== ============================================
kind            direct-light sample, one shadow ray                   power Phi_k (selection by power)
=============== ===================================================== ============================================
point           I f_r cos(x) / (r^2 pdf(k)), toward p (delta)         4 pi lum(I)
spot            I s(theta) f_r cos(x) / (r^2 pdf(k)) (delta)          2 pi lum(I) (1 - (sin c - sin b) / (c - b))
directional     E f_r cos(x) / pdf(k), along -direction to infinity   lum(E) pi R^2
constant        L f_r cos(x) / (pdf(k) p(w)), w ~ env_sampling         pi R^2 4 pi lum(L)
envmap          L(w) f_r cos(x) / (pdf(k) p(w)), w ~ env_sampling      pi R^2 sum_cells lum(L_cell) Omega_cell
=============== ===================================================== ============================================

with s the spot's falloff (1 up to ``beam_width`` b, linear in the angle down to 0 at ``cutoff_angle`` c, Mitsuba's
``spot.cpp``), R the radius of the scene's bounding sphere (half the diagonal of its bounding box), and lum the
Rec. 709 luminance. The infinite lights' power is what crosses the disk of radius R that the scene presents to each
direction: pi R^2 E for a directional light, pi R^2 int L dw for an environment (pbrt-v4, section 12.5,
``DistantLight::Phi`` and ``UniformInfiniteLight::Phi``). The spot's is I times the integral of its falloff over the
sphere, 2 pi int_0^c s(theta) sin(theta) d theta, in closed form.

Environment directions (``Settings.env_sampling``):

* ``importance``: an envmap by the piecewise-constant distribution over the cells of its bilinear interpolation (below);
  a constant environment uniformly over the sphere (its radiance is the same everywhere);
* ``uniform``: uniformly over the sphere, p(w) = 1 / (4 pi);
* ``cosine``: about N_x, p(w) = cos(w, N_x) / pi.

**The envmap** (Mitsuba 3.9's ``envmap.cpp``, read from its source). A direction d, taken to the map's frame
(v = to_world^-1 d), has u = atan2(v_x, -v_z) / (2 pi) wrapped into [0, 1) and v = acos(v_y) / pi (y up: v = 0 is
+y). The radiance is the bilinear interpolation of the texels, times ``scale``: texel column j sits at
u = (j + 1/2) / W (periodic in u), texel row i at v = i / (H - 1) (clamped in v; "align corners"). Images narrower
than 2 or lower than 3 texels are padded by repeating their last column / row, as Mitsuba's ``Bitmap::pad_to``.

So the radiance is bilinear on W x (H - 1) cells whose corners are texel centres. Importance sampling picks cell
(i, j) with probability P_ij proportional to the mean luminance of its four corners times the solid angle of the cell
(2 pi / W)(cos theta_i - cos theta_i+1), then a uniform point (u, v) in it: a density p(u, v) = P_ij W (H - 1) in the
unit square, which is > 0 wherever the interpolated radiance is > 0, and, with d omega = 2 pi^2 sin(theta) du dv
(theta = pi v, phi = 2 pi u), the density per solid angle

    p(w) = p(u, v) / (2 pi^2 sin theta)            (pbrt-v4 section 12.5.2; 0 where sin theta = 0).

The direction of (u, v) in the map's frame is (sin phi sin theta, cos theta, -cos phi sin theta) (Mitsuba's
``uv_to_direction``), taken to the world by ``to_world``. (Mitsuba itself samples the bilinear interpolant of
lum(texel) sin(theta_texel), a different distribution with the same support; only the expectations must agree.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from reference_impl.errors import SettingsError
from reference_impl.lights import rescale_within
from reference_impl.sampling import sample_discrete, sample_hemisphere

POINT, SPOT, DIRECTIONAL, ENV_CONSTANT, ENV_MAP = range(5)
KINDS = {"point": POINT, "spot": SPOT, "directional": DIRECTIONAL, "constant": ENV_CONSTANT, "envmap": ENV_MAP}
DELTA_KINDS = (POINT, SPOT, DIRECTIONAL)
ENV_KINDS = (ENV_CONSTANT, ENV_MAP)
ENV_SAMPLINGS = ("importance", "uniform", "cosine")
#: Mitsuba's ``spot`` defaults: a cutoff of 20 degrees, a beam width of 3/4 of the cutoff.
DEFAULT_CUTOFF_ANGLE = 20.0
BEAM_WIDTH_FRACTION = 0.75
DEFAULT_BEAM_WIDTH = BEAM_WIDTH_FRACTION * DEFAULT_CUTOFF_ANGLE
DEFAULT_SCALE = 1.0  # an envmap's

# Luminance weights of linear sRGB / Rec. 709 primaries (the same as lights._LUMINANCE).
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
INV_FOUR_PI = 1.0 / (4.0 * np.pi)
_INV_TWO_PI_SQ = 1.0 / (2.0 * np.pi * np.pi)


# ------------------------------------------------------------------------------------------------------- records


@dataclass(frozen=True)
class Point:
    """A point light: radiant intensity ``intensity`` I (W/sr, RGB) at ``position``."""

    position: tuple
    intensity: tuple


@dataclass(frozen=True, eq=False)
class Spot:
    """A spot light (Mitsuba's ``spot``): ``to_world`` (4x4 or 3x4) places it, origin = position, local +z = the
    cone's axis; I (W/sr) along the axis; angles in degrees, ``beam_width`` <= ``cutoff_angle``."""

    to_world: np.ndarray
    intensity: tuple
    cutoff_angle: float = DEFAULT_CUTOFF_ANGLE
    beam_width: float = DEFAULT_BEAM_WIDTH


@dataclass(frozen=True)
class Directional:
    """A directional light: irradiance E (W/m^2, RGB) on a surface facing it, light travelling along ``direction``."""

    direction: tuple
    irradiance: tuple


@dataclass(frozen=True)
class Constant:
    """A constant environment: radiance L from every direction."""

    radiance: tuple


@dataclass(frozen=True, eq=False)
class EnvMap:
    """A lat-long environment map: ``image`` (H, W, 3) linear RGB, times ``scale``, placed by ``to_world`` (a
    rotation: world from the map's frame)."""

    image: np.ndarray
    to_world: np.ndarray
    scale: float = DEFAULT_SCALE


def _vector3(key: str, value, positive: bool = False, nonnegative: bool = False) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise SettingsError(key, f"expected 3 finite numbers, got {value!r}")
    if nonnegative and np.any(v < 0):
        raise SettingsError(key, f"expected non-negative values, got {value!r}")
    if positive and not np.any(v > 0):
        raise SettingsError(key, f"expected a value > 0 in some channel, got {value!r}")
    return v


def _linear(key: str, matrix) -> np.ndarray:
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape not in ((4, 4), (3, 4), (3, 3)) or not np.all(np.isfinite(m)):
        raise SettingsError(key, f"expected a finite 4x4 matrix, got shape {m.shape}")
    linear = m[:3, :3]
    if abs(np.linalg.det(linear)) < 1e-300:
        raise SettingsError(key, "expected an invertible transform")
    return linear


# ------------------------------------------------------------------------------------------------------ emitters


class Emitters:
    """The emitters of a scene that are not surfaces, as the flat arrays the integrator takes.

    Parameters
    ----------
    records : sequence of :class:`Point`, :class:`Spot`, :class:`Directional`, :class:`Constant`, :class:`EnvMap`
        In the scene's order; at most one environment (:class:`Constant` or :class:`EnvMap`).

    Attributes (E = number of emitters)
    -----------------------------------
    kind (E,) int64               POINT, SPOT, DIRECTIONAL, ENV_CONSTANT, ENV_MAP
    position (E, 3)               point / spot: where it is
    direction (E, 3)              directional: the unit direction light travels
    intensity (E, 3)              I (point, spot), E (directional), L (constant), (scale,) * 3 (envmap)
    to_local, to_world (E, 3, 3)  spot, envmap: the linear part of to_world^-1 and of to_world (identity otherwise)
    spot (E, 4)                   spot: cos(cutoff), cutoff (radians), cos(beam_width), 1 / (cutoff - beam) (rad)
    env                           index of the environment in 0..E-1, or -1
    env_image (H, W, 3) float64   the envmap's texels, padded as Mitsuba (a 1x1x3 zero image without an envmap)
    env_cell_pdf (H-1, W)         p(u, v) of each cell (density in the unit square)
    env_row_cdf (H-1,)            the marginal cdf of the cell rows
    env_col_cdf (H-1, W)          each row's conditional cdf of the cells
    env_integral (3,)             int L dw over the sphere (RGB; for the envmap from the cells' mean corners)
    """

    def __init__(self, records=()):
        records = tuple(records)
        n = len(records)
        self.kind = np.zeros(n, np.int64)
        self.position = np.zeros((n, 3))
        self.direction = np.zeros((n, 3))
        self.intensity = np.zeros((n, 3))
        self.to_local = np.tile(np.eye(3), (n, 1, 1))
        self.to_world = np.tile(np.eye(3), (n, 1, 1))
        self.spot = np.zeros((n, 4))
        self.env = -1
        image = None
        for e, record in enumerate(records):
            where = f"emitters[{e}]"
            if isinstance(record, Point):
                self.kind[e] = POINT
                self.position[e] = _vector3(f"{where}.position", record.position)
                self.intensity[e] = _vector3(f"{where}.intensity", record.intensity, positive=True, nonnegative=True)
            elif isinstance(record, Spot):
                self.kind[e] = SPOT
                linear = _linear(f"{where}.to_world", record.to_world)
                self.position[e] = np.asarray(record.to_world, dtype=np.float64)[:3, 3]
                self.to_world[e] = linear
                self.to_local[e] = np.linalg.inv(linear)
                self.intensity[e] = _vector3(f"{where}.intensity", record.intensity, positive=True, nonnegative=True)
                cutoff, beam = float(record.cutoff_angle), float(record.beam_width)
                if not (0.0 < cutoff <= 180.0):
                    raise SettingsError(f"{where}.cutoff_angle", f"expected degrees in (0, 180], got {cutoff!r}")
                if not (0.0 <= beam <= cutoff):
                    raise SettingsError(f"{where}.beam_width", f"expected degrees in [0, cutoff_angle], got {beam!r}")
                c, b = math.radians(cutoff), math.radians(beam)
                # Mitsuba's spot.cpp: 1 / (cutoff - beam) is inf for beam = cutoff, where it is never used.
                inv_transition = 1.0 / (c - b) if c > b else math.inf
                self.spot[e] = (math.cos(c), c, math.cos(b), inv_transition)
            elif isinstance(record, Directional):
                self.kind[e] = DIRECTIONAL
                d = _vector3(f"{where}.direction", record.direction)
                norm = np.linalg.norm(d)
                if norm == 0:
                    raise SettingsError(f"{where}.direction", "expected a non-zero vector")
                self.direction[e] = d / norm
                self.intensity[e] = _vector3(f"{where}.irradiance", record.irradiance, positive=True,
                                             nonnegative=True)
            elif isinstance(record, (Constant, EnvMap)):
                if self.env >= 0:
                    raise SettingsError(where, "expected at most one environment (constant or envmap) per scene")
                self.env = e
                if isinstance(record, Constant):
                    self.kind[e] = ENV_CONSTANT
                    self.intensity[e] = _vector3(f"{where}.radiance", record.radiance, positive=True,
                                                 nonnegative=True)
                else:
                    self.kind[e] = ENV_MAP
                    scale = float(record.scale)
                    if not (math.isfinite(scale) and scale > 0):
                        raise SettingsError(f"{where}.scale", f"expected a positive number, got {record.scale!r}")
                    self.intensity[e] = scale
                    linear = _linear(f"{where}.to_world", record.to_world)
                    self.to_world[e] = linear
                    self.to_local[e] = np.linalg.inv(linear)
                    image = _envmap_image(f"{where}.image", record.image)
            else:
                raise SettingsError(where, f"expected an emitter record, got {type(record).__name__}")
        self.env_image = image if image is not None else np.zeros((3, 2, 3))
        self.env_cell_pdf, self.env_row_cdf, self.env_col_cdf, self.env_integral = self._env_distribution()

    def __len__(self) -> int:
        return len(self.kind)

    @property
    def env_kind(self) -> int:
        return int(self.kind[self.env]) if self.env >= 0 else -1

    def _env_distribution(self):
        """The envmap's cell distribution (see the module docstring) and int L dw of the environment."""
        image = self.env_image
        h, w = image.shape[:2]
        lum = image @ _LUMINANCE  # (H, W)
        corners = 0.25 * (lum[:-1] + lum[1:] + np.roll(lum[:-1], -1, axis=1) + np.roll(lum[1:], -1, axis=1))
        theta = np.pi * np.arange(h) / (h - 1)
        band = np.maximum(np.cos(theta[:-1]) - np.cos(theta[1:]), 0.0)  # (H-1,): solid angle / (2 pi / W)
        weight = corners * band[:, None]
        total = weight.sum()
        if not total > 0:  # a black map: uniform over the sphere (it emits nothing anyway)
            weight = np.broadcast_to(band[:, None], (h - 1, w)).copy()
            total = weight.sum()
        cell_pdf = weight / total * (w * (h - 1))
        rows = weight.sum(axis=1)
        row_cdf = np.cumsum(rows) / total
        row_cdf[-1] = 1.0
        col_cdf = np.cumsum(weight, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            col_cdf = np.where(rows[:, None] > 0, col_cdf / rows[:, None], (np.arange(w) + 1.0) / w)
        col_cdf[:, -1] = 1.0
        if self.env_kind == ENV_MAP:
            cell_rgb = 0.25 * (image[:-1] + image[1:] + np.roll(image[:-1], -1, axis=1)
                               + np.roll(image[1:], -1, axis=1))
            integral = (2.0 * np.pi / w) * np.einsum("ijc,i->c", cell_rgb, band) * self.intensity[self.env]
        elif self.env_kind == ENV_CONSTANT:
            integral = 4.0 * np.pi * self.intensity[self.env]
        else:
            integral = np.zeros(3)
        return cell_pdf, row_cdf, col_cdf, integral

    def powers(self, scene_radius: float) -> np.ndarray:
        """Phi_e of each emitter (luminance; the module docstring's table), for light selection by power."""
        disk = np.pi * scene_radius**2
        lum = self.intensity @ _LUMINANCE
        power = np.zeros(len(self))
        for e, kind in enumerate(self.kind):
            if kind == POINT:
                power[e] = 4.0 * np.pi * lum[e]
            elif kind == SPOT:
                power[e] = lum[e] * spot_solid_angle(self.spot[e, 1], math.acos(min(1.0, self.spot[e, 2])))
            elif kind == DIRECTIONAL:
                power[e] = lum[e] * disk
            else:
                power[e] = disk * float(self.env_integral @ _LUMINANCE)
        return power


def _envmap_image(key: str, image) -> np.ndarray:
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
        raise SettingsError(key, f"expected an (H, W, 3) image, got shape {img.shape}")
    if not np.all(np.isfinite(img)) or np.any(img < 0):
        raise SettingsError(key, "expected finite, non-negative radiance in every texel")
    # Mitsuba's Bitmap::pad_to((2, 3)): at least 2 columns and 3 rows, the last column / row repeated.
    if img.shape[1] < 2:
        img = np.concatenate([img, np.repeat(img[:, -1:], 2 - img.shape[1], axis=1)], axis=1)
    if img.shape[0] < 3:
        img = np.concatenate([img, np.repeat(img[-1:], 3 - img.shape[0], axis=0)], axis=0)
    return np.ascontiguousarray(img)


def spot_solid_angle(cutoff: float, beam: float) -> float:
    """int over the sphere of the spot's falloff: 2 pi int_0^c s(theta) sin(theta) d theta
    = 2 pi (1 - (sin c - sin b) / (c - b)), and 2 pi (1 - cos c) for b = c (radians)."""
    if cutoff - beam <= 1e-12:
        return 2.0 * np.pi * (1.0 - math.cos(cutoff))
    return 2.0 * np.pi * (1.0 - (math.sin(cutoff) - math.sin(beam)) / (cutoff - beam))


def scene_radius(vertices: np.ndarray) -> float:
    """Radius of the bounding sphere of the scene's bounding box (Mitsuba's ``bbox().bounding_sphere()``)."""
    if len(vertices) == 0:
        return 0.0
    return 0.5 * float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))


# --------------------------------------------------------------------------------- radiance and the spot's falloff


def spot_falloff(spot: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Mitsuba's ``falloff_curve``: ``local`` (n, 3) directions from the light in its frame (not necessarily unit);
    1 within the beam, (cutoff - theta) / (cutoff - beam) out to the cutoff, 0 beyond."""
    cos_cutoff, cutoff, cos_beam, inv_transition = spot
    cos_theta = local[:, 2] / np.linalg.norm(local, axis=1)
    with np.errstate(invalid="ignore"):
        ramp = (cutoff - np.arccos(np.clip(cos_theta, -1.0, 1.0))) * inv_transition
    beam = np.where(cos_theta >= cos_beam, 1.0, ramp)
    return np.where(cos_theta > cos_cutoff, beam, 0.0)


def direction_to_uv(local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's ``direction_to_uv`` on unit directions of the map's frame: u = atan2(x, -z) / (2 pi) in [0, 1),
    v = acos(y) / pi."""
    u = np.arctan2(local[:, 0], -local[:, 2]) * (0.5 / np.pi)
    u = np.where(u < 0, u + 1.0, u)
    u = np.where(u >= 1.0, 0.0, u)
    v = np.arccos(np.clip(local[:, 1], -1.0, 1.0)) * (1.0 / np.pi)
    return u, v


def uv_to_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Mitsuba's ``uv_to_direction``: (sin phi sin theta, cos theta, -cos phi sin theta), phi = 2 pi u, theta = pi v."""
    theta = np.pi * v
    phi = 2.0 * np.pi * u
    s = np.sin(theta)
    return np.stack([np.sin(phi) * s, np.cos(theta), -np.cos(phi) * s], axis=-1)


def envmap_lookup(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Mitsuba's bilinear lookup at (u, v): texel column j at u = (j + 1/2) / W, periodic; row i at v = i / (H - 1),
    clamped. (H, W, 3) -> (n, 3)."""
    h, w = image.shape[:2]
    x = u * w - 0.5
    x0 = np.floor(x)
    fx = x - x0
    c0 = x0.astype(np.int64) % w
    c1 = (c0 + 1) % w
    y = np.clip(v, 0.0, 1.0) * (h - 1)
    y0 = np.minimum(np.floor(y), h - 1)
    fy = y - y0
    r0 = y0.astype(np.int64)
    r1 = np.minimum(r0 + 1, h - 1)
    fx, fy = fx[:, None], fy[:, None]
    top = (1.0 - fx) * image[r0, c0] + fx * image[r0, c1]
    bottom = (1.0 - fx) * image[r1, c0] + fx * image[r1, c1]
    return (1.0 - fy) * top + fy * bottom


def environment_radiance(emitters: Emitters, directions: np.ndarray) -> np.ndarray:
    """L of the environment seen along world ``directions`` (n, 3) (unit): the direction a ray leaves the scene."""
    e = emitters.env
    if e < 0:
        return np.zeros((len(directions), 3))
    if emitters.kind[e] == ENV_CONSTANT:
        return np.broadcast_to(emitters.intensity[e], (len(directions), 3)).copy()
    local = directions @ emitters.to_local[e].T
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    u, v = direction_to_uv(local)
    return envmap_lookup(emitters.env_image, u, v) * emitters.intensity[e]


# ---------------------------------------------------------------------------------- environment direction samplers


def square_to_uniform_sphere(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Directions uniform over the sphere: z = 1 - 2 u1, phi = 2 pi u2; p = 1 / (4 pi)."""
    z = 1.0 - 2.0 * u1
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def sample_envmap(emitters: Emitters, u1: np.ndarray, u2: np.ndarray):
    """Importance sampling of the envmap: (world directions (n, 3), their pdf per solid angle (n,)). u1 picks the
    row of cells (then, rescaled, v within it), u2 the cell in the row (then u within it)."""
    e = emitters.env
    rows, cols = emitters.env_cell_pdf.shape
    i = sample_discrete(emitters.env_row_cdf, u1)
    fv = rescale_within(u1, np.where(i > 0, emitters.env_row_cdf[i - 1], 0.0), emitters.env_row_cdf[i])
    j = np.empty(len(u2), np.int64)
    for row in np.flatnonzero(np.bincount(i)):  # sample_discrete in each chosen row's cdf (not an (n, W) gather)
        here = i == row
        j[here] = sample_discrete(emitters.env_col_cdf[row], u2[here])
    lo = np.where(j > 0, emitters.env_col_cdf[i, j - 1], 0.0)
    fu = rescale_within(u2, lo, emitters.env_col_cdf[i, j])
    v = (i + fv) / rows
    u = (j + fu) / cols + 0.5 / cols
    u = np.where(u >= 1.0, u - 1.0, u)
    sin_theta = np.sin(np.pi * v)
    with np.errstate(divide="ignore"):
        pdf = np.where(sin_theta > 0, emitters.env_cell_pdf[i, j] * _INV_TWO_PI_SQ / sin_theta, 0.0)
    local = uv_to_direction(u, v)
    world = local @ emitters.to_world[e].T
    world /= np.linalg.norm(world, axis=1, keepdims=True)
    return world, pdf


def envmap_pdf(emitters: Emitters, directions: np.ndarray) -> np.ndarray:
    """The solid-angle pdf of :func:`sample_envmap` at world ``directions`` (n, 3) (unit)."""
    e = emitters.env
    rows, cols = emitters.env_cell_pdf.shape
    local = directions @ emitters.to_local[e].T
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    u, v = direction_to_uv(local)
    shifted = u - 0.5 / cols
    shifted = np.where(shifted < 0, shifted + 1.0, shifted)
    j = np.minimum((shifted * cols).astype(np.int64), cols - 1)
    i = np.minimum((v * rows).astype(np.int64), rows - 1)
    sin_theta = np.sqrt(local[:, 0] ** 2 + local[:, 2] ** 2)
    with np.errstate(divide="ignore"):
        return np.where(sin_theta > 0, emitters.env_cell_pdf[i, j] * _INV_TWO_PI_SQ / sin_theta, 0.0)


def sample_environment(emitters: Emitters, strategy: str, u1: np.ndarray, u2: np.ndarray, normals: np.ndarray):
    """Directions toward the environment drawn by ``strategy`` (``Settings.env_sampling``) at points of ``normals``
    (n, 3): (world directions, pdf per solid angle)."""
    if strategy == "cosine":
        w, _cos, pdf = sample_hemisphere("cosine", u1, u2, normals)
        return w, pdf
    if strategy == "importance" and emitters.env_kind == ENV_MAP:
        return sample_envmap(emitters, u1, u2)
    return square_to_uniform_sphere(u1, u2), np.full(len(u1), INV_FOUR_PI)


def environment_pdf(emitters: Emitters, strategy: str, directions: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """The pdf of :func:`sample_environment` at world ``directions`` seen from points of ``normals``."""
    if strategy == "cosine":
        cos = np.sum(directions * normals, axis=1)
        return np.where(cos > 0, cos / np.pi, 0.0)
    if strategy == "importance" and emitters.env_kind == ENV_MAP:
        return envmap_pdf(emitters, directions)
    return np.full(len(directions), INV_FOUR_PI)
