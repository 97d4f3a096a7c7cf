"""The stochastic global-illumination algorithm of the slides (Fig. 5.16), traced as a wavefront.

For each pixel, Np viewing rays through the pixel filter h (``computeImage``). At each hit x, the radiance toward
the previous vertex is estimated from the equations, not from the pseudo-code taken literally:

    L(x -> Theta)   = Le(x -> Theta) + L_r(x -> Theta)                          (only at the viewing ray's hit)
    L_r(x -> Theta) = L_direct(x -> Theta) + L_indirect(x -> Theta)              (eq. 5.2)
    <L_direct>      = 1/Nd sum Le(y_i) f_r G(x, y_i) V(x, y_i) / (pdf(k) pdf(y_i | k))   (eq. 5.3, Fig. 5.10)
    <L_indirect>    = 1/Ni sum L_r(r(x, Psi_i) -> -Psi_i) f_r cos(Psi_i, N_x) / p(Psi_i)  (Fig. 5.14)

The indirect estimate recurses on L_r, the *reflected* radiance at the next hit: emission met by an indirect ray is
already in L_direct and is not added again (the literal pseudo-code's ``computeRadiance`` adds Le(y) there, which
counts direct light twice; it survives only as the mutant "double-emission"). Russian roulette divides survivors
by their survival probability (Fig. 5.16, ``estimatedRadiance / (1 - absorption)``).

All paths of a batch advance one bounce at a time (a wavefront): every ray query is one batched Embree call and every
estimator is a few numpy expressions over all paths; there is no Python loop over rays.
"""

from __future__ import annotations

import dataclasses
import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from reference_impl import rng
from reference_impl.camera import Camera, Film
from reference_impl.errors import SettingsError
from reference_impl.geometry import Geometry
from reference_impl.intersect import Intersector, offset_origin
from reference_impl.lights import LightSampler, TriangleAreaSampler
from reference_impl.sampling import INV_PI, hemisphere_pdf, sample_hemisphere
from reference_impl.settings import Settings

# What each random dimension is for (see rng.dimension).
_FILM_X, _FILM_Y = 0, 1
_LIGHT_SELECT, _LIGHT_TRIANGLE, _LIGHT_U1, _LIGHT_U2 = 2, 3, 4, 5
_DIRECT_DIR_U1, _DIRECT_DIR_U2 = 6, 7
_ROULETTE = 8
_INDIRECT_U1, _INDIRECT_U2 = 9, 10

COUNTERS = (
    "camera_rays",  # viewing rays traced
    "shadow_rays",  # occlusion (any-hit) queries toward sampled light points
    "shadow_rays_skipped",  # light samples needing no ray: light faces away, point behind x, or not on a light
    "hemisphere_direct_rays",  # closest-hit rays cast for direct light by hemisphere sampling (Fig. 5.12)
    "indirect_rays",  # closest-hit rays cast for the indirect estimate
    "escaped_rays",  # rays that left the scene
    "back_face_absorbed",  # hits on the back of one-sided surfaces (black, end of path)
    "roulette_terminated",  # paths ended by Russian roulette (including zero-albedo surfaces)
    "nonfinite_samples",  # camera samples whose radiance is NaN or infinite
)


@dataclass
class RenderOutput:
    """What a render returns: the pixel estimates, their variances, and counters.

    image    (H, W, 3) float32: mean of the Np weighted samples of each pixel.
    variance (H, W, 3) float32: variance of that mean (sample variance / Np); NaN when Np = 1.
    stats    counters (see ``COUNTERS``) plus ``paths`` (camera paths traced).
    seconds  wall time of the render alone (no scene loading, no file writing).
    """

    image: np.ndarray
    variance: np.ndarray
    stats: dict[str, int]
    seconds: float
    settings: Settings = field(repr=False, default=None)


@dataclass
class _PathState:
    """The active paths of a wavefront, one row each, sorted by root."""

    root: np.ndarray  # (n,) index of the camera sample this path belongs to
    key: np.ndarray  # (n,) uint64 random-stream key
    origin: np.ndarray  # (n, 3)
    direction: np.ndarray  # (n, 3) unit
    beta: np.ndarray  # (n, 3) throughput: product of weights f cos / p / Ni / q so far
    pdf_dir: np.ndarray | None  # (n,) Ni * p(Psi) of the ray that reached the next vertex (MIS only)

    def __len__(self) -> int:
        return len(self.root)

    def take(self, idx: np.ndarray) -> "_PathState":
        return _PathState(
            self.root[idx], self.key[idx], self.origin[idx], self.direction[idx], self.beta[idx],
            None if self.pdf_dir is None else self.pdf_dir[idx],
        )


class _Context:
    """Everything shared by all batches of one render (read-only once built)."""

    def __init__(self, geometry: Geometry, camera: Camera, film: Film, settings: Settings):
        if settings.max_depth is None:
            raise SettingsError("max_depth", "expected the scene's max_depth to be resolved before rendering")
        self.max_depth = settings.resolved_max_depth(settings.max_depth)
        self.geometry = geometry
        self.camera = camera
        self.film = film
        self.filter = film.pixel_filter
        self.settings = settings
        self.intersector = Intersector(geometry)
        self.has_lights = geometry.num_lights > 0
        self.lights = LightSampler(geometry, settings.light_selection) if self.has_lights else None
        usable = np.flatnonzero(geometry.area > 0)
        self.all_surfaces = TriangleAreaSampler(geometry, usable) if len(usable) else None
        self.mis = settings.direct == "mis"
        self.mutant = settings.mutant  # a planted fault (reference_impl/mutants.py), "" in every real render
        self.double_emission = settings.mutant == "double-emission"
        self.reflectance = geometry.reflectance / np.pi  # f_r of each material
        self.split_cap = 4 * settings.batch_size

    def depth_allows(self, path_length: int) -> bool:
        """Whether paths of this many segments are counted (Mitsuba's max_depth)."""
        return self.max_depth == -1 or path_length <= self.max_depth


def render(geometry: Geometry, camera: Camera, film: Film, settings: Settings, progress=None) -> RenderOutput:
    """Render an image with the slides' algorithm (Fig. 5.16).

    ``settings.max_depth`` must be set (the harness fills in the scene's). ``progress``, if given, is called from
    the calling thread as ``progress(done_paths, total_paths)``. The result depends only on the inputs and
    ``settings.seed``: not on ``batch_size`` or ``threads``.
    """
    ctx = _Context(geometry, camera, film, settings)
    width, height, spp = film.width, film.height, settings.spp
    num_pixels = width * height
    threads = settings.worker_threads()
    # Units of work: ranges of whole pixels, all their samples in order, so every pixel's sum is formed in sample
    # order whatever the decomposition. Small enough to keep every thread busy.
    pixels_per_unit = max(1, settings.batch_size // spp)
    pixels_per_unit = min(pixels_per_unit, max(1, math.ceil(num_pixels / (4 * threads))))
    samples_per_chunk = max(1, min(spp, settings.batch_size // pixels_per_unit))
    units = [(p0, min(num_pixels, p0 + pixels_per_unit)) for p0 in range(0, num_pixels, pixels_per_unit)]

    total = np.zeros((num_pixels, 3))
    total_sq = np.zeros((num_pixels, 3))
    stats = dict.fromkeys(COUNTERS, 0)
    start = time.perf_counter()

    def run_unit(unit):
        p0, p1 = unit
        unit_stats = dict.fromkeys(COUNTERS, 0)
        for s0 in range(0, spp, samples_per_chunk):
            s1 = min(spp, s0 + samples_per_chunk)
            pixel = np.repeat(np.arange(p0, p1, dtype=np.int64), s1 - s0)
            sample = np.tile(np.arange(s0, s1, dtype=np.int64), p1 - p0)
            values = _trace_camera_paths(ctx, pixel, sample, unit_stats)
            values = values.reshape(p1 - p0, s1 - s0, 3)
            # Sequential sums (cumsum never reorders), so chunking cannot change a single bit.
            total[p0:p1] = np.cumsum(np.concatenate([total[p0:p1, None], values], axis=1), axis=1)[:, -1]
            total_sq[p0:p1] = np.cumsum(np.concatenate([total_sq[p0:p1, None], values**2], axis=1), axis=1)[:, -1]
        return (p1 - p0) * spp, unit_stats

    done = 0
    if not ctx.has_lights:  # nothing emits: the image is black, exactly, and needs no ray at all
        units = []
        if progress is not None:
            progress(num_pixels * spp, num_pixels * spp)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for paths, unit_stats in pool.map(run_unit, units):
            done += paths
            for k, v in unit_stats.items():
                stats[k] += v
            if progress is not None:
                progress(done, num_pixels * spp)
    seconds = time.perf_counter() - start

    mean = total / spp
    if not ctx.has_lights:
        var_of_mean = np.zeros_like(mean)
    elif spp > 1:
        sample_var = np.maximum(total_sq - total * total / spp, 0.0) / (spp - 1)
        var_of_mean = sample_var / spp
    else:
        var_of_mean = np.full_like(mean, np.nan)
    stats["paths"] = num_pixels * spp
    return RenderOutput(
        image=mean.reshape(height, width, 3).astype(np.float32),
        variance=var_of_mean.reshape(height, width, 3).astype(np.float32),
        stats=stats,
        seconds=seconds,
        settings=settings,
    )


def _trace_camera_paths(ctx: _Context, pixel: np.ndarray, sample: np.ndarray, stats: dict) -> np.ndarray:
    """Radiance estimates (n, 3) of camera samples (pixel, sample): ``rad(ray) * h(p)`` of Fig. 5.16."""
    width, height = ctx.film.width, ctx.film.height
    keys = rng.path_keys(ctx.settings.seed, pixel.astype(np.uint64) * np.uint64(ctx.settings.spp) + sample.astype(np.uint64))
    dx, dy, weight = ctx.filter.sample(rng.uniform(keys, rng.dimension(0, _FILM_X)), rng.uniform(keys, rng.dimension(0, _FILM_Y)))
    film_x = (pixel % width) + 0.5 + dx
    film_y = (pixel // width) + 0.5 + dy
    if ctx.mutant == "camera-half-pixel":
        film_x, film_y = film_x + 0.5, film_y + 0.5
    origins, directions = ctx.camera.generate_rays(film_x, film_y, width, height)
    n = len(pixel)
    stats["camera_rays"] += n
    radiance = np.zeros((n, 3))
    state = _PathState(
        root=np.arange(n), key=keys, origin=np.ascontiguousarray(origins), direction=directions,
        beta=np.repeat(weight[:, None], 3, axis=1), pdf_dir=None,
    )
    _trace(ctx, state, 1, radiance, stats)
    if ctx.mutant == "energy-loss-2pct":
        radiance *= 0.98
    stats["nonfinite_samples"] += int(np.count_nonzero(~np.all(np.isfinite(radiance), axis=1)))
    return radiance


def _trace(ctx: _Context, state: _PathState, depth: int, radiance: np.ndarray, stats: dict) -> None:
    """Advance the wavefront until every path has ended. With Ni > 1 the wavefront grows; it is then split at
    camera-sample boundaries, so each sample's contributions are still summed in the same order."""
    while len(state):
        if len(state) > ctx.split_cap:
            mid = np.searchsorted(state.root, state.root[len(state) // 2])
            if mid == 0:
                mid = np.searchsorted(state.root, state.root[0], side="right")
            if mid < len(state):
                _trace(ctx, state.take(slice(0, mid)), depth, radiance, stats)
                _trace(ctx, state.take(slice(mid, None)), depth, radiance, stats)
                return
        state = _bounce(ctx, state, depth, radiance, stats)
        depth += 1


def _add(ctx: _Context, radiance: np.ndarray, root: np.ndarray, value: np.ndarray) -> None:
    if ctx.settings.indirect_rays == 1:
        radiance[root] += value  # roots are unique when paths never branch
    else:
        np.add.at(radiance, root, value)


def _bounce(ctx: _Context, state: _PathState, depth: int, radiance: np.ndarray, stats: dict) -> _PathState:
    """Find the hits x of the current rays (vertex number ``depth``), add their contributions and return the rays
    of the next wavefront."""
    g = ctx.geometry
    tri, t = ctx.intersector.closest_hit(state.origin, state.direction)
    hit = tri >= 0
    stats["escaped_rays"] += int(np.count_nonzero(~hit))
    if not np.all(hit):
        state = state.take(hit)
        tri, t = tri[hit], t[hit]
    if not len(state):
        return state
    x = state.origin + t[:, None] * state.direction
    normal = g.normal[tri]
    cos_out = -np.einsum("ij,ij->i", state.direction, normal)  # cos between N_x and Theta (toward the eye)
    front = cos_out > 0

    # Emission Le(x -> Theta): only for the viewing ray's hit (eq. 5.2 recurses on L_r), unless MIS weighs the
    # indirect ray as a direct-light sample, or the double-counting mutant is on.
    emitted = g.emission[tri] * front[:, None]
    if depth == 1 or ctx.double_emission:
        _add(ctx, radiance, state.root, state.beta * emitted)
    elif ctx.mis:
        _add(ctx, radiance, state.root, state.beta * emitted * _mis_weight_hemisphere(ctx, state, tri, t, cos_out)[:, None])

    if not ctx.depth_allows(depth + 1):
        return state.take(np.zeros(0, np.int64))
    material = g.material[tri]
    reflects = front | g.two_sided[material]
    stats["back_face_absorbed"] += int(np.count_nonzero(~reflects))
    if not np.all(reflects):
        keep = np.flatnonzero(reflects)
        state, tri, x, normal, front, material = state.take(keep), tri[keep], x[keep], normal[keep], front[keep], material[keep]
    normal = np.where(front[:, None], normal, -normal)  # the side Theta leaves from
    f_r = ctx.reflectance[material]

    if ctx.has_lights:
        _add(ctx, radiance, state.root, state.beta * _direct_light(ctx, x, normal, f_r, state.key, depth, stats))

    # Indirect light (Fig. 5.14): needed if the next vertex can still add anything.
    if not (ctx.depth_allows(depth + 2) or (ctx.mis and ctx.depth_allows(depth + 1))):
        return state.take(np.zeros(0, np.int64))
    beta = state.beta
    key = state.key
    settings = ctx.settings
    if settings.rr != "off" and depth >= settings.rr_depth:
        if settings.rr == "albedo":
            survival = np.max(g.reflectance[material], axis=1)
        else:
            survival = np.full(len(state), 1.0 - settings.absorption)
        alive = rng.uniform(key, rng.dimension(depth, _ROULETTE)) < survival
        stats["roulette_terminated"] += int(np.count_nonzero(~alive))
        keep = np.flatnonzero(alive)
        beta = beta[keep] if ctx.mutant == "rr-no-reweight" else beta[keep] / survival[keep, None]
        key, x, normal, f_r, root = key[keep], x[keep], normal[keep], f_r[keep], state.root[keep]
    else:
        root = state.root
    branches = settings.indirect_rays
    if branches > 1:
        root, x, normal, f_r, beta = (np.repeat(a, branches, axis=0) for a in (root, x, normal, f_r, beta))
        key = np.concatenate([rng.branch_keys(key, b, depth)[:, None] for b in range(branches)], axis=1).reshape(-1)
    u1 = rng.uniform(key, rng.dimension(depth, _INDIRECT_U1))
    u2 = rng.uniform(key, rng.dimension(depth, _INDIRECT_U2))
    direction, cos_theta, pdf = sample_hemisphere(settings.hemisphere, u1, u2, normal)
    if ctx.mutant == "cosine-pdf-pi" and settings.hemisphere == "cosine":
        pdf = pdf * np.pi
    cos_factor = np.ones_like(cos_theta) if ctx.mutant == "no-cosine" else cos_theta
    with np.errstate(divide="ignore", invalid="ignore"):
        beta = beta * (f_r * (cos_factor / (pdf * branches))[:, None])
    carries = np.all(np.isfinite(beta), axis=1) & np.any(beta > 0, axis=1)
    stats["roulette_terminated"] += int(np.count_nonzero(~carries))
    keep = np.flatnonzero(carries)
    origin = offset_origin(x[keep], normal[keep], ctx.intersector.offset(x[keep]))
    stats["indirect_rays"] += len(keep)
    return _PathState(
        root=root[keep], key=key[keep], origin=origin, direction=direction[keep], beta=beta[keep],
        pdf_dir=(pdf[keep] * branches) if ctx.mis else None,
    )


def _direct_light(ctx: _Context, x, normal, f_r, key, depth: int, stats: dict) -> np.ndarray:
    """<L_direct(x -> Theta)> with Nd samples of the chosen strategy: the average of Nd one-sample estimates."""
    strategy = ctx.settings.direct
    nd = ctx.settings.shadow_rays
    total = np.zeros((len(x), 3))
    for j in range(nd):  # one batched query per shadow-ray index; Nd is small and each pass covers all paths
        if strategy in ("area", "mis"):
            total += _direct_area_sample(ctx, x, normal, f_r, key, depth, j, stats)
        elif strategy == "global-area":
            total += _direct_global_area_sample(ctx, x, normal, f_r, key, depth, j, stats)
        else:
            total += _direct_hemisphere_sample(ctx, x, normal, f_r, key, depth, j, stats)
    return total / nd


def _direct_area_sample(ctx, x, normal, f_r, key, depth, j, stats) -> np.ndarray:
    """One sample of eq. 5.3 by light sampling (Fig. 5.10): Le f_r G V / (pdf(k) pdf(y|k))."""
    dim = lambda purpose: rng.dimension(depth, purpose, j)  # noqa: E731
    light, points = ctx.lights.sample(
        rng.uniform(key, dim(_LIGHT_SELECT)), rng.uniform(key, dim(_LIGHT_TRIANGLE)),
        rng.uniform(key, dim(_LIGHT_U1)), rng.uniform(key, dim(_LIGHT_U2)),
    )
    if ctx.mutant == "light-pdf-ignored":
        points = dataclasses.replace(points, pdf_area=1.0 / ctx.lights.area[light])  # pdf(y|k) alone
    mis_weight = None
    if ctx.mis:
        mis_weight = lambda cos_x, cos_y, dist2, pdf_area: _mis_weight_light(ctx, cos_x, cos_y, dist2, pdf_area)  # noqa: E731
    return _shadow_ray_estimate(ctx, x, normal, f_r, points.triangle, points.position, points.normal, points.pdf_area, stats, mis_weight)


def _direct_global_area_sample(ctx, x, normal, f_r, key, depth, j, stats) -> np.ndarray:
    """One sample of eq. 5.3 with y uniform over all surfaces of the scene (Fig. 5.13): pdf(y) = 1 / A_scene.
    Points that are not on a light contribute zero and cost no ray."""
    dim = lambda purpose: rng.dimension(depth, purpose, j)  # noqa: E731
    points = ctx.all_surfaces.sample(
        rng.uniform(key, dim(_LIGHT_TRIANGLE)), rng.uniform(key, dim(_LIGHT_U1)), rng.uniform(key, dim(_LIGHT_U2)),
    )
    return _shadow_ray_estimate(ctx, x, normal, f_r, points.triangle, points.position, points.normal, points.pdf_area, stats)


def _shadow_ray_estimate(ctx, x, normal, f_r, tri, y, normal_y, pdf_area, stats, mis_weight=None) -> np.ndarray:
    """Le(y -> x) f_r G(x, y) V(x, y) / p(y) for sampled points y, with a shadow ray only where it can matter."""
    g = ctx.geometry
    result = np.zeros((len(x), 3))
    to_light = y - x
    dist2 = np.einsum("ij,ij->i", to_light, to_light)
    with np.errstate(divide="ignore", invalid="ignore"):
        wi = to_light / np.sqrt(dist2)[:, None]
    cos_x = np.einsum("ij,ij->i", normal, wi)
    cos_y = -np.einsum("ij,ij->i", normal_y, wi)
    # No ray toward a point that faces away, lies behind x, or does not emit.
    needed = (cos_x > 0) & (cos_y > 0) & (g.light_id[tri] >= 0) & (dist2 > 0)
    stats["shadow_rays_skipped"] += int(np.count_nonzero(~needed))
    idx = np.flatnonzero(needed)
    if not len(idx):
        return result
    xs, ys = x[idx], y[idx]
    if ctx.mutant == "no-ray-offset":
        origin = xs
    else:
        origin = offset_origin(xs, normal[idx], ctx.intersector.offset(xs))
    seg = ys - origin
    seg_len = np.sqrt(np.einsum("ij,ij->i", seg, seg))
    direction = seg / seg_len[:, None]
    t_max = seg_len * (1.0 - 1e-6) - ctx.intersector.offset(ys)
    visible = ~ctx.intersector.occluded(origin, direction, t_max)
    stats["shadow_rays"] += len(idx)
    cos_at_x = 1.0 if ctx.mutant == "no-cosine" else cos_x[idx]
    geometry_term = cos_at_x * cos_y[idx] / dist2[idx]  # G(x, y)
    value = g.emission[tri[idx]] * f_r[idx] * (geometry_term * visible / pdf_area[idx])[:, None]
    if mis_weight is not None:
        value *= mis_weight(cos_x[idx], cos_y[idx], dist2[idx], pdf_area[idx])[:, None]
    result[idx] = value
    return result


def _direct_hemisphere_sample(ctx, x, normal, f_r, key, depth, j, stats) -> np.ndarray:
    """One sample of L_direct by hemisphere sampling (Fig. 5.12): trace a direction Psi from x and take the emission
    Le(r(x, Psi) -> -Psi) of what it hits, weighted by f_r cos(Psi, N_x) / p(Psi)."""
    g = ctx.geometry
    kind = "cosine" if ctx.settings.direct == "hemisphere-cosine" else "uniform"
    dim = lambda purpose: rng.dimension(depth, purpose, j)  # noqa: E731
    direction, cos_theta, pdf = sample_hemisphere(kind, rng.uniform(key, dim(_DIRECT_DIR_U1)), rng.uniform(key, dim(_DIRECT_DIR_U2)), normal)
    origin = offset_origin(x, normal, ctx.intersector.offset(x))
    tri, _ = ctx.intersector.closest_hit(origin, direction)
    stats["hemisphere_direct_rays"] += len(x)
    result = np.zeros((len(x), 3))
    idx = np.flatnonzero((tri >= 0) & (pdf > 0))
    if len(idx):
        th = tri[idx]
        faces_x = np.einsum("ij,ij->i", direction[idx], g.normal[th]) < 0
        weight = cos_theta[idx] / pdf[idx] * faces_x
        result[idx] = g.emission[th] * f_r[idx] * weight[:, None]
    return result


def _mis_weight_light(ctx, cos_x, cos_y, dist2, pdf_area) -> np.ndarray:
    """Power heuristic for a light sample: (Nd p_l)^2 / ((Nd p_l)^2 + (Ni p_b)^2), pdfs per unit solid angle."""
    p_light = ctx.settings.shadow_rays * pdf_area * dist2 / cos_y
    p_hemi = ctx.settings.indirect_rays * hemisphere_pdf(ctx.settings.hemisphere, cos_x)
    return p_light**2 / (p_light**2 + p_hemi**2)


def _mis_weight_hemisphere(ctx, state: _PathState, tri, t, cos_out) -> np.ndarray:
    """Power heuristic for an indirect ray that lands on a light: (Ni p_b)^2 / ((Ni p_b)^2 + (Nd p_l)^2)."""
    light = ctx.geometry.light_id[tri]
    on_light = (light >= 0) & (cos_out > 0)
    weight = np.zeros(len(tri))
    if np.any(on_light):
        p_light = ctx.settings.shadow_rays * ctx.lights.pdf_area(light[on_light]) * t[on_light] ** 2 / cos_out[on_light]
        p_hemi = state.pdf_dir[on_light]
        weight[on_light] = p_hemi**2 / (p_hemi**2 + p_light**2)
    return weight


__all__ = ["COUNTERS", "INV_PI", "RenderOutput", "render"]
