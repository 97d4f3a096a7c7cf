"""The volumetric path loop (pbrt-v4's ``VolPathIntegrator``, Mitsuba 3's ``volpath``): the path loop of
:mod:`.path` extended from the rendering equation to the volume rendering equation, for scenes with homogeneous
media (:mod:`reference_impl.media`) or ``null`` boundaries.

Along a ray in medium m (extinction sigma_t per channel c, albedo a) toward the closest surface at distance s:

* a free flight (:func:`.phase.free_flight`) with the extinction of the path's hero channel c, drawn uniformly once
  per path: p_c(t) = sigma_c exp(-sigma_c t) for t < s, P_c(pass) = exp(-sigma_c s). The path's estimate is
  one-sample MIS over the three channels' sampling of its free flights with the balance heuristic (Mitsuba's volpath
  draws its channel so, and weights by the hero's density alone; pbrt-v4's spectral MIS divides by the mean, as here):
  f / mean_k p_k(path) = beta / mean_k r_k, beta = f / p_c(path) and r_k = p_k(path) / p_c(path) (every other
  decision's density is the same for every channel), so a channel of small extinction carries no weight larger than
  3 x its own. A scattering at t < s multiplies beta_k by a_k sigma_k exp(-sigma_k t) / p_c(t) and r_k by
  sigma_k exp(-sigma_k t) / p_c(t); a pass both by exp(-sigma_k s) / P_c(pass); with one sigma_t for all channels
  the weights are the albedo and 1. With the planted fault "free-flight-pdf-no-sigma-t" p_k(t) = exp(-sigma_k t);
  with "albedo-applied-twice" the scattering weight has a_k^2.
* at a scattering point x: direct light by ``medium_direct``: "light" and "mis", Nd light samples (light k with
  pdf(k), a point or an emitter's own sample: :func:`.direct.light_connection`), each times the phase function
  p(d, wi) and the shadow ray's transmittance (below), weighted with "mis" by the power heuristic against the phase
  function's density; "phase", only the delta lights' own samples. Then the next direction from the phase function
  (isotropic or Henyey-Greenstein, :mod:`.phase`, weight 1; with "hg-g-flipped" both with -g), Russian roulette.
* at a surface: emission and the BSDF as in the path loop (``direct``: "area", "mis" or "bsdf"; the BSDF door,
  :func:`.path.connect`, :func:`.path.next_ray`, the geometric frame), the shadow rays with their transmittance. A
  ``null`` surface is no vertex: the ray crosses it unchanged (with "null-boundary-as-bounce" it counts as one).
  Leaving a surface that is a medium transition, the ray is in its exterior medium if it leaves along N, else its
  interior one (``reference_impl.media``).
* emission met by a ray counts in full after the camera or a delta bounce, not at all where the vertex it left drew a
  light sample that finds it ("area", "light"), with the power heuristic where both did ("mis"; the light samples'
  density of that direction at the vertex it left, the distance from that vertex across every null boundary).

A shadow ray's transmittance (``transmittance``): it crosses null surfaces (any other surface blocks it), through
each medium a segment of length s at a time: "ratio", exp(-sigma_c s) per channel (ratio tracking whose control
extinction is the medium's own, exact for a homogeneous medium); "track", a free flight over the segment, its channel drawn
uniformly and its density the channels' mean (one-sample MIS over the channels within the shadow ray): 0 where it
stops inside, else exp(-sigma_c s) / (1/3 sum_k exp(-sigma_k s)). With "nee-no-transmittance" every segment passes
with 1.

Path lengths follow Mitsuba's volpath: a vertex (a surface that is not null, or a scattering point) i draws light
samples and scatters when i < max_depth, and its emission counts when i <= max_depth. Random numbers are hashes
``uniform(key, dim_salt(depth, PURPOSE, j))``, except with ``sampler = sobol`` (the film samples, and) the first
vertex's: each pixel's Np (hero channel, first free flight) pairs of the camera ray, Np x Nd light samples (one 2D
point whose first coordinate also picks the light and its piece, as the path loop's), Np phase or BSDF directions and
Np (lobe, roulette) pairs are stratified sets (:func:`.sobol.volpath_first_vertex_seeds`), computed ahead for the
pixel's run of samples; a shadow ray's "track" flights, the emitters' own samples and every later vertex keep hashes.
(Measured at 64 spp over 8 seeds, docs/performance.md: on fog-box the first free flight gives all of the gain, MSE
5.09e-3 -> 8.6e-4; on medium-emitter the flight 2.1x, with the light samples and directions 2.65x; on hg-cloud the
phase direction 1.17x.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.emitters import DIRECTIONAL, POINT, SPOT
from reference_impl.kernels.bsdf import chooses_lobe, is_delta
from reference_impl.kernels.config import (C_ESCAPED, C_INDIRECT, C_LIGHT_SELECT, C_ROULETTE, C_SHADOW,
                                           C_SHADOW_SKIPPED, DIRECT_BSDF, DIRECT_MIS, HEMI_UNIFORM, JIT, JIT_BORROW,
                                           M_ALBEDO_TWICE, M_FLIGHT_PDF_NO_SIGMA_T, M_HG_G_FLIPPED,
                                           M_LIGHT_PDF_IGNORED, M_NEE_NO_TRANSMITTANCE, M_NULL_AS_BOUNCE,
                                           MEDIUM_LIGHT, MEDIUM_MIS, MEDIUM_PHASE, RR_ALBEDO, RR_OFF, RR_PBRT,
                                           RR_THROUGHPUT, SAMPLER_SOBOL, TR_TRACK)
from reference_impl.kernels.direct import (connection_ray, emitter_connection, light_connection, light_piece,
                                           power_weight)
from reference_impl.kernels.emitters import env_light_pdf, env_radiance, split_light_piece_all
from reference_impl.kernels.light_sampling import light_density
from reference_impl.kernels.material import material_at
from reference_impl.kernels.path import RR_THROUGHPUT_CAP, connect, next_ray
from reference_impl.kernels.phase import hg_pdf, sample_hg, sample_isotropic, INV_FOUR_PI
from reference_impl.kernels.queries import TIMING_STRIDE, closest_prim_timed, now_ns, ray_buffer
from reference_impl.kernels.rng import dim_salt, uniform
from reference_impl.kernels.shading import geometric_frame
from reference_impl.kernels.sobol import (NOTHING_HELD, VolpathFirstVertexPairs, ahead, held_point, longest_run,
                                          pair_point, pixel_run, volpath_first_vertex_seeds)
from reference_impl.kernels.surface import emission_at, offset_origin, origin_offset, shadow_t_max, surface_hit
from reference_impl.kernels.warps import dot3, sample_discrete
from reference_impl.materials import DIELECTRIC, NULL, P_TWO_SIDED, ROUGHDIELECTRIC, ROW_SIZE, THINDIELECTRIC
from reference_impl.media import HG
from reference_impl.rng import (BSDF_LOBE, BSDF_U1, BSDF_U2, COMPLEMENT_U1, COMPLEMENT_U2, FLIGHT, FLIGHT_CHANNEL,
                                LIGHT_SELECT, LIGHT_TRIANGLE, LIGHT_U1, LIGHT_U2, PHASE_U1, PHASE_U2, ROULETTE, TRACK,
                                TRACK_CHANNEL)

MAX_VERTICES = 1 << 16
#: null boundaries one ray may cross before it is given up (a closed set of null shapes cannot hold more)
MAX_CROSSINGS = 1 << 10
EMIT_FULL, EMIT_NONE, EMIT_MIS = 0, 1, 2  # how emission found by the next ray counts (module docstring)


@njit(**JIT_BORROW)
def channel_transmittance(sigma, s):
    """exp(-sigma s), 1 where sigma = 0 (also over an infinite s)."""
    if sigma == 0.0:
        return 1.0
    return math.exp(-sigma * s)


@njit(**JIT_BORROW)
def flight_distance(media, m, c, u_t):
    """Medium m's extinction per channel and a free flight's distance drawn with channel c's, t = -log(1 - u_t) /
    sigma_c (:func:`.phase.free_flight`; inf where sigma_c = 0): (sigma_0, sigma_1, sigma_2, t)."""
    s0, s1, s2 = media.sigma_t[m, 0], media.sigma_t[m, 1], media.sigma_t[m, 2]
    sc = s0 if c == 0 else (s1 if c == 1 else s2)
    t = np.inf
    if sc > 0.0:
        t = -math.log1p(-u_t) / sc
    return s0, s1, s2, t


@njit(**JIT_BORROW)
def free_flight_rgb(media, m, s, u_c, u_t, mutant):
    """A free flight in medium m over a segment of length s (inf: unbounded), the channel drawn by u_c and the
    distance by u_t (module docstring): (whether it scatters before s, t, the weight per channel: a scattering's
    sigma_s T / p(t) or a pass's T / P(pass))."""
    s0, s1, s2, t = flight_distance(media, m, min(int(u_c * 3.0), 2), u_t)
    if t < s:
        tr0, tr1, tr2 = channel_transmittance(s0, t), channel_transmittance(s1, t), channel_transmittance(s2, t)
        if mutant & M_FLIGHT_PDF_NO_SIGMA_T:  # planted fault "free-flight-pdf-no-sigma-t"
            pdf = (tr0 + tr1 + tr2) / 3.0
        else:
            pdf = (s0 * tr0 + s1 * tr1 + s2 * tr2) / 3.0
        a0, a1, a2 = media.albedo[m, 0], media.albedo[m, 1], media.albedo[m, 2]
        if mutant & M_ALBEDO_TWICE:  # planted fault "albedo-applied-twice"
            a0, a1, a2 = a0 * a0, a1 * a1, a2 * a2
        inv = 1.0 / pdf
        return True, t, a0 * s0 * tr0 * inv, a1 * s1 * tr1 * inv, a2 * s2 * tr2 * inv
    tr0, tr1, tr2 = channel_transmittance(s0, s), channel_transmittance(s1, s), channel_transmittance(s2, s)
    passes = (tr0 + tr1 + tr2) / 3.0
    if not passes > 0.0:
        return False, s, 0.0, 0.0, 0.0
    inv = 1.0 / passes
    return False, s, tr0 * inv, tr1 * inv, tr2 * inv


@njit(**JIT_BORROW)
def free_flight_hero(media, m, s, c, u_t, mutant):
    """A free flight of a path whose hero channel is c (module docstring): t drawn with sigma_c over a segment of
    length s (inf: unbounded): (whether it scatters before s, t, the throughput's factors per channel k, a scattering's
    a_k sigma_k T_k(t) / p_c(t) or a pass's T_k(s) / P_c(pass), and the factors of the ratios r_k = p_k / p_c of the
    path's densities, sigma_k T_k(t) / (sigma_c T_c(t)) or T_k(s) / T_c(s))."""
    s0, s1, s2, t = flight_distance(media, m, c, u_t)
    if t < s:
        tr0, tr1, tr2 = channel_transmittance(s0, t), channel_transmittance(s1, t), channel_transmittance(s2, t)
        p0, p1, p2 = s0 * tr0, s1 * tr1, s2 * tr2
        if mutant & M_FLIGHT_PDF_NO_SIGMA_T:  # planted fault "free-flight-pdf-no-sigma-t"
            p0, p1, p2 = tr0, tr1, tr2
        pc = p0 if c == 0 else (p1 if c == 1 else p2)
        a0, a1, a2 = media.albedo[m, 0], media.albedo[m, 1], media.albedo[m, 2]
        if mutant & M_ALBEDO_TWICE:  # planted fault "albedo-applied-twice"
            a0, a1, a2 = a0 * a0, a1 * a1, a2 * a2
        inv = 1.0 / pc
        return (True, t, a0 * s0 * tr0 * inv, a1 * s1 * tr1 * inv, a2 * s2 * tr2 * inv, p0 * inv, p1 * inv,
                p2 * inv)
    tr0, tr1, tr2 = channel_transmittance(s0, s), channel_transmittance(s1, s), channel_transmittance(s2, s)
    pc = tr0 if c == 0 else (tr1 if c == 1 else tr2)
    inv = 1.0 / pc
    return False, s, tr0 * inv, tr1 * inv, tr2 * inv, tr0 * inv, tr1 * inv, tr2 * inv


@njit(**JIT_BORROW)
def phase_eval(media, m, mutant, d0, d1, d2, w0, w1, w2):
    """The phase function of medium m (its value is its density) for light travelling along d scattered into w."""
    if media.phase[m] == HG:
        g = media.g[m]
        if mutant & M_HG_G_FLIPPED:  # planted fault "hg-g-flipped"
            g = -g
        return hg_pdf(g, dot3(d0, d1, d2, w0, w1, w2))
    return INV_FOUR_PI


@njit(**JIT_BORROW)
def phase_sample(media, m, mutant, u1, u2, d0, d1, d2):
    """A direction w from the phase function of medium m about the travel direction d: (w, p(w))."""
    if media.phase[m] == HG:
        g = media.g[m]
        if mutant & M_HG_G_FLIPPED:  # planted fault "hg-g-flipped"
            g = -g
        return sample_hg(g, u1, u2, d0, d1, d2)
    return sample_isotropic(u1, u2)


@njit(**JIT_BORROW)
def target_medium(media, tri, current, w0, w1, w2, n0, n1, n2):
    """The medium a ray leaving triangle ``tri`` (front normal N) along w is in: its exterior where w . N > 0, else
    its interior, where the triangle is a medium transition; ``current`` where it is not."""
    if not media.transition[tri]:
        return current
    return media.exterior[tri] if dot3(w0, w1, w2, n0, n1, n2) > 0 else media.interior[tri]


@njit(**JIT_BORROW)
def shadow_transmittance(cfg, scene_ptr, words, floats, ts, queries, sampled_ns, scene, materials, media, spheres,
                         sphere_base, medium, ray, key, depth, j):
    """The transmittance (per channel) of shadow ray ``ray`` (origin, unit direction, t_max) that starts in
    ``medium``: 0 where a surface other than a null one blocks it, else the product over its segments in media
    (module docstring; ``transmittance``'s strategy). (T0, T1, T2, queries, sampled_ns)."""
    o0, o1, o2, r0, r1, r2, remaining = ray
    mutant = cfg.mutant
    tr0, tr1, tr2 = 1.0, 1.0, 1.0
    for crossing in range(MAX_CROSSINGS):
        p = np.int64(-1)
        if scene_ptr != 0:
            p, queries, sampled_ns = closest_prim_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1, o2,
                                                        r0, r1, r2, spheres, sphere_base)
        th = np.inf
        if p >= 0:
            hit = surface_hit(scene, p, o0, o1, o2, r0, r1, r2)
            th = hit.t
        seg = min(th, remaining)
        if medium >= 0 and not (mutant & M_NEE_NO_TRANSMITTANCE):  # planted fault "nee-no-transmittance"
            if cfg.transmittance == TR_TRACK:
                idx = (j << 16) | crossing
                scatters, _t, w0, w1, w2 = free_flight_rgb(media, medium, seg,
                                                           uniform(key, dim_salt(depth, TRACK_CHANNEL, idx)),
                                                           uniform(key, dim_salt(depth, TRACK, idx)), 0)
                if scatters:
                    return 0.0, 0.0, 0.0, queries, sampled_ns
                tr0, tr1, tr2 = tr0 * w0, tr1 * w1, tr2 * w2
            else:
                tr0 *= channel_transmittance(media.sigma_t[medium, 0], seg)
                tr1 *= channel_transmittance(media.sigma_t[medium, 1], seg)
                tr2 *= channel_transmittance(media.sigma_t[medium, 2], seg)
            if not (tr0 > 0.0 or tr1 > 0.0 or tr2 > 0.0):
                return 0.0, 0.0, 0.0, queries, sampled_ns
        if not th < remaining:
            return tr0, tr1, tr2, queries, sampled_ns
        if materials.kind[hit.material] != NULL:
            return 0.0, 0.0, 0.0, queries, sampled_ns
        tri = hit.tri
        medium = target_medium(media, tri, medium, r0, r1, r2, hit.n0, hit.n1, hit.n2)
        side = 1.0 if dot3(r0, r1, r2, hit.n0, hit.n1, hit.n2) > 0 else -1.0
        o0, o1, o2 = offset_origin(cfg.offset_scene, hit.x0, hit.x1, hit.x2, side * hit.n0, side * hit.n1,
                                   side * hit.n2)
        remaining -= th
    return 0.0, 0.0, 0.0, queries, sampled_ns


@njit(**JIT_BORROW)
def roulette(cfg, depth, key, b0, b1, b2, eta2, q_albedo, u_rr):
    """Russian roulette at a vertex of depth ``depth`` (the path loop's rules; ``q_albedo``: the survival of
    ``rr = albedo`` at this vertex) with the uniform u_rr, or where it is negative a hash of ``key``: (survives,
    b / q)."""
    if cfg.rr == RR_OFF or depth < cfg.rr_depth:
        return True, b0, b1, b2
    if cfg.rr == RR_THROUGHPUT:
        q = min(max(b0, b1, b2) * eta2, RR_THROUGHPUT_CAP)
    elif cfg.rr == RR_PBRT:
        q = min(max(b0, b1, b2) * eta2, 1.0)
    elif cfg.rr == RR_ALBEDO:
        q = min(q_albedo, 1.0)
    else:
        q = cfg.survival
    if u_rr < 0:
        u_rr = uniform(key, dim_salt(depth, ROULETTE, 0))
    if not (u_rr < q):
        return False, 0.0, 0.0, 0.0
    inv_q = 1.0 / q
    return True, b0 * inv_q, b1 * inv_q, b2 * inv_q


@njit(**JIT_BORROW)
def choose_light(cfg, lights, key, depth, j, u_a=-1.0, u_b=0.0):
    """Light sample j's light k (pdf(k) from the light table), its piece and the two uniforms of its point: from the
    stratified 2D point (u_a, u_b), whose first coordinate also picks the light and the piece
    (:func:`.emitters.split_light_piece_all`), or where u_a is negative from the path's hashes."""
    if u_a >= 0:
        sel, piece, u1 = split_light_piece_all(lights, cfg.num_lights, cfg.num_area_lights, u_a)
        return sel, piece, u1, u_b
    num_lights = cfg.num_lights
    u_sel = uniform(key, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
    sel = sample_discrete(lights.cdf, u_sel) if num_lights > 1 else 0
    piece = light_piece(cfg, lights, sel, uniform(key, dim_salt(depth, LIGHT_TRIANGLE, j)))
    return sel, piece, uniform(key, dim_salt(depth, LIGHT_U1, j)), uniform(key, dim_salt(depth, LIGHT_U2, j))


@njit(**JIT_BORROW)
def medium_ray(cfg, conn, x0, x1, x2):
    """The shadow ray of connection ``conn`` from a point x in a medium: from x itself (no surface to leave), to
    short of y as :func:`.direct.connection_ray` stops it, or unbounded."""
    if conn.inf_ray:
        return x0, x1, x2, conn.wi0, conn.wi1, conn.wi2, np.inf
    g0, g1, g2 = conn.y0 - x0, conn.y1 - x1, conn.y2 - x2
    seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
    y_offset = origin_offset(cfg.offset_scene, conn.y0, conn.y1, conn.y2) if conn.on_surface else 0.0
    return x0, x1, x2, conn.wi0, conn.wi1, conn.wi2, max(shadow_t_max(seg_len, y_offset, conn.cos_y), 0.0)


@njit(**JIT)
def trace_volpaths(state, scene_ptr, scene, lights, materials, cfg, radiance, counters, timing, film_samples, emitters,
                   media, spheres=None, later=None):
    """Trace every camera path of ``state`` (the wavefront's ``camera_paths`` wrote them) to its end through the
    scene's media (module docstring), adding each path's radiance to ``radiance[root]``. The tables as the path loop
    takes them (:func:`.path.trace_paths`; ``emitters``, ``spheres`` and ``later`` None compile their branches out);
    ``media`` the :class:`.records.MediumTables`. ``timing`` as the path loop's; ``film_samples``
    (:class:`.records.FilmSamples`): the camera samples, for the stratified sampler."""
    root, key, origin, direction, _o32, _d32, beta, _pdf_dir, _env_pdf = state
    light_id, light_pmf = scene.light_id, lights.pmf
    sphere_base = scene.prim_to_tri.shape[0] - scene.sphere.shape[0]
    nd = cfg.shadow_rays
    inv_nd = 1.0 / nd
    mutant = cfg.mutant
    max_depth = cfg.max_depth
    surface_mis = cfg.direct == DIRECT_MIS
    surface_lights = cfg.direct != DIRECT_BSDF  # light samples at surfaces ("area", "mis")
    medium_lights = cfg.medium_direct != MEDIUM_PHASE
    surface_emit = EMIT_MIS if surface_mis else (EMIT_FULL if cfg.direct == DIRECT_BSDF else EMIT_NONE)
    medium_emit = EMIT_MIS if cfg.medium_direct == MEDIUM_MIS else (
        EMIT_FULL if cfg.medium_direct == MEDIUM_PHASE else EMIT_NONE)
    uniform_diffuse = cfg.hemisphere == HEMI_UNIFORM
    sobol = cfg.sampler == SAMPLER_SOBOL
    film_pixel, film_sample, seed_key = film_samples.pixel, film_samples.sample, film_samples.seed_key
    # The first vertex's points of each pixel's run of samples, computed ahead (kernels.sobol.sobol_points); the
    # (lobe, roulette) pair only where roulette is played at the first vertex (a lobed BSDF's few from the seeds)
    fv = volpath_first_vertex_seeds(seed_key, 0, 1, 1)
    fv_pixel = -1
    si = 0
    run = longest_run(film_samples) if sobol else 0
    fx, fy = np.empty(run), np.empty(run)
    lx, ly = np.empty(run * nd), np.empty(run * nd)
    wx, wy = np.empty(run), np.empty(run)
    cx, cy = np.empty(run), np.empty(run)
    held = VolpathFirstVertexPairs(NOTHING_HELD, NOTHING_HELD, NOTHING_HELD, NOTHING_HELD)
    first_roulette = cfg.rr != RR_OFF and cfg.rr_depth <= 1
    lights_drawn = medium_lights or surface_lights
    row = np.empty(ROW_SIZE)
    words, floats = ray_buffer()
    ts = np.zeros(2, np.int64)
    queries = 0
    sampled_ns = 0
    clock_ns = 1 << 62
    for _ in range(8):
        t_start = now_ns(ts)
        clock_ns = min(clock_ns, now_ns(ts) - t_start)
    count_escaped = 0
    count_indirect = 0
    count_light_select = 0
    count_roulette = 0
    count_shadow = 0
    count_shadow_skipped = 0
    n = len(root)
    for i in range(n):
        r = root[i]
        k = key[i]
        o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
        d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
        b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
        rad0, rad1, rad2 = radiance[r, 0], radiance[r, 1], radiance[r, 2]
        medium = media.camera
        u_flight = -1.0  # the camera ray's first free flight's uniform (sobol), or none: hashes
        if sobol:
            if film_pixel[r] != fv_pixel:  # a pixel's samples come together: its seeds and points once
                fv_pixel = film_pixel[r]
                fv = volpath_first_vertex_seeds(seed_key, fv_pixel, cfg.spp, nd)
                first, m_run = film_sample[r], pixel_run(film_pixel, film_sample, r)
                held = VolpathFirstVertexPairs(ahead(fv.flight, first, m_run, fx, fy, True),
                                               ahead(fv.light, first * nd, m_run * nd, lx, ly, lights_drawn),
                                               ahead(fv.direction, first, m_run, wx, wy, True),
                                               ahead(fv.lobe_roulette, first, m_run, cx, cy, first_roulette))
            si = film_sample[r]
            u_c, u_flight = pair_point(held_point(fv.flight, fx, fy, held.flight, si), si)
            hero = min(int(u_c * 3.0), 2)  # the channel free flights follow
        else:
            hero = min(int(uniform(k, dim_salt(0, FLIGHT_CHANNEL, 0)) * 3.0), 2)  # the channel free flights follow
        r0, r1, r2 = 1.0, 1.0, 1.0  # the path's densities per channel over the hero's: p_k / p_hero
        depth = 1  # the vertex the current ray will find (the camera is 0)
        emit = EMIT_FULL  # how emission this ray finds counts
        prev_pdf = 0.0  # the density of the current ray's direction at the vertex it left (MIS)
        pn0, pn1, pn2 = 0.0, 0.0, 1.0  # that vertex's normal on the side the ray left (env_light_pdf)
        t_acc = 0.0  # the distance from that vertex to the current ray's origin (across null boundaries)
        px0, px1, px2 = 0.0, 0.0, 0.0  # that vertex (a sphere light's cone from it: light_density)
        crossings = 0  # null boundaries the current ray has crossed
        eta2 = 1.0
        while True:
            p = np.int64(-1)
            if scene_ptr != 0:
                p, queries, sampled_ns = closest_prim_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1,
                                                            o2, d0, d1, d2, spheres, sphere_base)
            t_hit = np.inf
            if p >= 0:
                hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
                t_hit = hit.t
            sob = sobol and depth == 1  # the first vertex's numbers from the pixel's stratified sets
            if medium >= 0:
                if u_flight >= 0 and depth == 1:  # the camera ray's first free flight
                    u_t = u_flight
                    u_flight = -1.0
                else:
                    u_t = uniform(k, dim_salt(depth, FLIGHT, crossings))
                scatters, t, w0, w1, w2, q0, q1, q2 = free_flight_hero(media, medium, t_hit, hero, u_t, mutant)
                # b is the throughput over the mean of the channels' densities (one-sample MIS over the hero)
                rm = (r0 + r1 + r2) / 3.0
                r0, r1, r2 = r0 * q0, r1 * q1, r2 * q2
                ratio = 3.0 * rm / (r0 + r1 + r2)
                b0, b1, b2 = b0 * w0 * ratio, b1 * w1 * ratio, b2 * w2 * ratio
                if not (b0 > 0 or b1 > 0 or b2 > 0):
                    count_roulette += 1
                    break
                if scatters:
                    # a scattering point x: a vertex of the path
                    if not (max_depth == -1 or depth + 1 <= max_depth) or depth >= MAX_VERTICES:
                        break
                    x0, x1, x2 = o0 + t * d0, o1 + t * d1, o2 + t * d2
                    if medium_lights:
                        tot0, tot1, tot2 = 0.0, 0.0, 0.0
                        for j in range(nd):
                            u_a, u_b = -1.0, 0.0  # the pixel's stratified point (sob), else hashes
                            if sob:
                                u_a, u_b = pair_point(held_point(fv.light, lx, ly, held.light, si * nd + j), si * nd + j)
                            sel, piece, u1, u2 = choose_light(cfg, lights, k, depth, j, u_a, u_b)
                            if cfg.num_lights > 1:
                                count_light_select += 1
                            pdf_select = 1.0 if mutant & M_LIGHT_PDF_IGNORED else light_pmf[sel]
                            conn = light_connection(cfg, scene, None, lights, emitters, sel, piece, pdf_select, u1,
                                                    u2, x0, x1, x2, d0, d1, d2, False)
                            if not conn.needed:
                                count_shadow_skipped += 1
                                continue
                            f = phase_eval(media, medium, mutant, d0, d1, d2, conn.wi0, conn.wi1, conn.wi2)
                            w = 1.0
                            if cfg.medium_direct == MEDIUM_MIS and conn.p_l > 0:
                                w = power_weight(mutant, conn.p_l, f, True)
                            count_shadow += 1
                            tr0, tr1, tr2, queries, sampled_ns = shadow_transmittance(
                                cfg, scene_ptr, words, floats, ts, queries, sampled_ns, scene, materials, media,
                                spheres, sphere_base, medium, medium_ray(cfg, conn, x0, x1, x2), k, depth, j)
                            tot0 += conn.v0 * f * w * tr0
                            tot1 += conn.v1 * f * w * tr1
                            tot2 += conn.v2 * f * w * tr2
                        rad0 += b0 * tot0 * inv_nd
                        rad1 += b1 * tot1 * inv_nd
                        rad2 += b2 * tot2 * inv_nd
                    elif emitters is not None:  # "phase": the delta lights, each its own sample
                        for e in range(len(emitters.kind)):
                            ek = emitters.kind[e]
                            if not (ek == POINT or ek == SPOT or ek == DIRECTIONAL):
                                continue
                            conn = emitter_connection(cfg, emitters, e, 1.0, 0.0, 0.0, x0, x1, x2, d0, d1, d2, False)
                            if not conn.needed:
                                continue
                            f = phase_eval(media, medium, mutant, d0, d1, d2, conn.wi0, conn.wi1, conn.wi2)
                            count_shadow += 1
                            tr0, tr1, tr2, queries, sampled_ns = shadow_transmittance(
                                cfg, scene_ptr, words, floats, ts, queries, sampled_ns, scene, materials, media,
                                spheres, sphere_base, medium, medium_ray(cfg, conn, x0, x1, x2), k, depth, nd + e)
                            rad0 += b0 * conn.v0 * f * tr0
                            rad1 += b1 * conn.v1 * f * tr1
                            rad2 += b2 * conn.v2 * f * tr2
                    if sob:
                        pu1, pu2 = pair_point(held_point(fv.direction, wx, wy, held.direction, si), si)
                    else:
                        pu1, pu2 = uniform(k, dim_salt(depth, PHASE_U1, 0)), uniform(k, dim_salt(depth, PHASE_U2, 0))
                    n0, n1, n2, pdf = phase_sample(media, medium, mutant, pu1, pu2, d0, d1, d2)
                    a = media.albedo[medium]
                    u_rr = -1.0
                    if sob and first_roulette:
                        _u_lobe, u_rr = pair_point(held_point(fv.lobe_roulette, cx, cy, held.lobe_roulette, si), si)
                    alive, b0, b1, b2 = roulette(cfg, depth, k, b0, b1, b2, eta2, max(a[0], a[1], a[2]), u_rr)
                    if not alive:
                        count_roulette += 1
                        break
                    count_indirect += 1
                    o0, o1, o2 = x0, x1, x2
                    d0, d1, d2 = n0, n1, n2
                    emit = medium_emit
                    prev_pdf = pdf
                    pn0, pn1, pn2 = n0, n1, n2
                    px0, px1, px2 = x0, x1, x2
                    t_acc = 0.0
                    crossings = 0
                    depth += 1
                    continue
            if p < 0:
                count_escaped += 1
                if emitters is not None:
                    if cfg.env_light >= 0 and emit != EMIT_NONE:
                        e0, e1, e2 = env_radiance(cfg, emitters, d0, d1, d2)
                        w = 1.0
                        if emit == EMIT_MIS:
                            p_env = env_light_pdf(cfg, lights, emitters, d0, d1, d2, pn0, pn1, pn2)
                            w = power_weight(mutant, prev_pdf, p_env, False) if p_env > 0 else 1.0
                        rad0 += b0 * e0 * w
                        rad1 += b1 * e1 * w
                        rad2 += b2 * e2 * w
                break
            tri, cos_out = hit.tri, hit.cos_out
            t_total = t_acc + hit.t
            if emit != EMIT_NONE:
                light = light_id[tri]
                if light >= 0 and cos_out > 0:
                    w = 1.0
                    if emit == EMIT_MIS:
                        p_light = light_density(lights, light, nd, light_pmf[light], px0, px1, px2, t_total, cos_out,
                                                mutant)
                        w = power_weight(mutant, prev_pdf, p_light, False)
                    le0, le1, le2 = emission_at(scene, None, tri, hit.x0, hit.x1, hit.x2, mutant)
                    rad0 += b0 * le0 * w
                    rad1 += b1 * le1 * w
                    rad2 += b2 * le2 * w
            nx0, nx1, nx2 = hit.n0, hit.n1, hit.n2
            if materials.kind[hit.material] == NULL:  # an index-matched boundary: crossed, no vertex (no material step)
                medium = target_medium(media, tri, medium, d0, d1, d2, nx0, nx1, nx2)
                side = 1.0 if dot3(d0, d1, d2, nx0, nx1, nx2) > 0 else -1.0
                o0, o1, o2 = offset_origin(cfg.offset_scene, hit.x0, hit.x1, hit.x2, side * nx0, side * nx1,
                                           side * nx2)
                t_acc = t_total
                crossings += 1
                if mutant & M_NULL_AS_BOUNCE:  # planted fault "null-boundary-as-bounce"
                    depth += 1
                    if not (max_depth == -1 or depth <= max_depth):
                        break
                if crossings >= MAX_CROSSINGS:
                    break
                continue
            if not (max_depth == -1 or depth + 1 <= max_depth) or depth >= MAX_VERTICES:
                break
            kind = material_at(materials, hit, row, mutant)  # the material step: the BSDF's kind and parameters
            transmits = kind == DIELECTRIC or kind == ROUGHDIELECTRIC or kind == THINDIELECTRIC
            if not (cos_out > 0 or row[P_TWO_SIDED] != 0 or transmits):  # the back of a one-sided surface: black
                break
            x0, x1, x2 = hit.x0, hit.x1, hit.x2
            side = 1.0 if cos_out > 0 else -1.0
            ns0, ns1, ns2 = side * nx0, side * nx1, side * nx2
            ox0, ox1, ox2 = offset_origin(cfg.offset_scene, x0, x1, x2, ns0, ns1, ns2)
            sf = geometric_frame(hit)
            wo0, wo1, wo2 = -d0, -d1, -d2
            lo0 = dot3(sf.s0, sf.s1, sf.s2, wo0, wo1, wo2)
            lo1 = dot3(sf.t0, sf.t1, sf.t2, wo0, wo1, wo2)
            lo2 = cos_out
            delta_bsdf = is_delta(kind)
            front_only = not transmits
            if not delta_bsdf:
                own = 0
                if emitters is not None:
                    if not surface_lights:
                        own = len(emitters.kind)
                points = nd if surface_lights else 0
                tot0, tot1, tot2 = 0.0, 0.0, 0.0
                for j in range(points + own):
                    if j < points:
                        u_a, u_b = -1.0, 0.0  # as at a scattering point
                        if sob:
                            u_a, u_b = pair_point(held_point(fv.light, lx, ly, held.light, si * nd + j), si * nd + j)
                        sel, piece, u1, u2 = choose_light(cfg, lights, k, depth, j, u_a, u_b)
                        if cfg.num_lights > 1:
                            count_light_select += 1
                        pdf_select = 1.0 if mutant & M_LIGHT_PDF_IGNORED else light_pmf[sel]
                        conn = light_connection(cfg, scene, None, lights, emitters, sel, piece, pdf_select, u1, u2,
                                                x0, x1, x2, ns0, ns1, ns2, front_only)
                        scale = inv_nd
                    elif emitters is not None:
                        e = j - points
                        ek = emitters.kind[e]
                        if not (ek == POINT or ek == SPOT or ek == DIRECTIONAL):
                            continue
                        conn = emitter_connection(cfg, emitters, e, 1.0, uniform(k, dim_salt(depth, COMPLEMENT_U1, e)),
                                                  uniform(k, dim_salt(depth, COMPLEMENT_U2, e)), x0, x1, x2, ns0, ns1,
                                                  ns2, front_only)
                        scale = 1.0
                    else:
                        continue
                    needed, cos_x, v0, v1, v2 = connect(mutant, kind, row, uniform_diffuse, surface_mis and j < points, conn,
                                                        transmits, side, nx0, nx1, nx2, sf, lo0, lo1, lo2, later)
                    if not needed:
                        count_shadow_skipped += 1
                        continue
                    count_shadow += 1
                    ray = connection_ray(cfg, conn, cos_x, transmits, x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2)
                    shadow_medium = target_medium(media, tri, medium, conn.wi0, conn.wi1, conn.wi2, nx0, nx1, nx2)
                    tr0, tr1, tr2, queries, sampled_ns = shadow_transmittance(
                        cfg, scene_ptr, words, floats, ts, queries, sampled_ns, scene, materials, media, spheres,
                        sphere_base, shadow_medium, ray, k, depth, j)
                    tot0 += v0 * tr0 * scale
                    tot1 += v1 * tr1 * scale
                    tot2 += v2 * tr2 * scale
                rad0 += b0 * tot0
                rad1 += b1 * tot1
                rad2 += b2 * tot2
            u_rr = -1.0  # drawn by next_ray where roulette is played
            if sob:
                u_lobe = 0.0
                if chooses_lobe(kind, transmits) or first_roulette:  # only they read the pair
                    u_lobe, u_rr = pair_point(held_point(fv.lobe_roulette, cx, cy, held.lobe_roulette, si), si)
                bu1, bu2 = pair_point(held_point(fv.direction, wx, wy, held.direction, si), si)
            else:
                u_lobe = uniform(k, dim_salt(depth, BSDF_LOBE, 0))
                bu1 = uniform(k, dim_salt(depth, BSDF_U1, 0))
                bu2 = uniform(k, dim_salt(depth, BSDF_U2, 0))
            (go_on, cut, n0, n1, n2, m0, m1, m2, qn0, qn1, qn2, nb0, nb1, nb2, eta2, pdf,
             delta) = next_ray(cfg, kind, row, uniform_diffuse, True, u_lobe, bu1, bu2, u_rr, k, depth, (lo0, lo1, lo2),
                               (b0, b1, b2), eta2, sf, (nx0, nx1, nx2), side, (x0, x1, x2), (ox0, ox1, ox2), later)
            count_roulette += cut
            if not go_on:
                break
            count_indirect += 1
            medium = target_medium(media, tri, medium, n0, n1, n2, nx0, nx1, nx2)
            d0, d1, d2 = n0, n1, n2
            o0, o1, o2 = m0, m1, m2
            b0, b1, b2 = nb0, nb1, nb2
            emit = EMIT_FULL if delta else surface_emit
            prev_pdf = pdf
            pn0, pn1, pn2 = qn0, qn1, qn2
            px0, px1, px2 = x0, x1, x2
            t_acc = 0.0
            crossings = 0
            depth += 1
        radiance[r, 0], radiance[r, 1], radiance[r, 2] = rad0, rad1, rad2
    counters[C_ESCAPED] += count_escaped
    counters[C_INDIRECT] += count_indirect
    counters[C_LIGHT_SELECT] += count_light_select
    counters[C_ROULETTE] += count_roulette
    counters[C_SHADOW] += count_shadow
    counters[C_SHADOW_SKIPPED] += count_shadow_skipped
    timed = queries // TIMING_STRIDE
    timing[0] += max(sampled_ns - timed * clock_ns, 0) * TIMING_STRIDE
    timing[1] += queries





@njit(**JIT)
def free_flight_rgb_many(media, m, s, u_c, u_t, mutant):
    """:func:`free_flight_rgb` for each (u_c[i], u_t[i]) (tests): (scatters (n,), t (n,), weights (n, 3))."""
    n = len(u_c)
    scatters = np.empty(n, np.bool_)
    t = np.empty(n)
    w = np.empty((n, 3))
    for i in range(n):
        scatters[i], t[i], w[i, 0], w[i, 1], w[i, 2] = free_flight_rgb(media, m, s, u_c[i], u_t[i], mutant)
    return scatters, t, w


@njit(**JIT)
def free_flight_hero_many(media, m, s, c, u_t, mutant):
    """:func:`free_flight_hero` for each (c[i], u_t[i]) (tests): (scatters (n,), t (n,), weights (n, 3), ratios
    (n, 3))."""
    n = len(c)
    scatters = np.empty(n, np.bool_)
    t = np.empty(n)
    w = np.empty((n, 3))
    q = np.empty((n, 3))
    for i in range(n):
        (scatters[i], t[i], w[i, 0], w[i, 1], w[i, 2], q[i, 0], q[i, 1],
         q[i, 2]) = free_flight_hero(media, m, s, c[i], u_t[i], mutant)
    return scatters, t, w, q


__all__ = ["MAX_CROSSINGS", "channel_transmittance", "flight_distance", "free_flight_hero", "free_flight_hero_many",
           "free_flight_rgb", "free_flight_rgb_many", "phase_eval", "phase_sample", "shadow_transmittance",
           "target_medium", "trace_volpaths"]
