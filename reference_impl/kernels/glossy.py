"""The glossy engine: each camera path to its end in one compiled loop, for scenes with a material that is not
Lambertian (conductors, dielectrics, rough or smooth: :mod:`.bsdf`), and for ``direct = "bsdf"`` on any scene.

At each vertex x (its surface record, :class:`.surface.SurfaceHit`: front geometric normal N; the BSDF's local frame
is the shading frame, z = N, never flipped; wo toward the previous vertex; the BSDF's kind and parameters from the
material step, :func:`.material.material_at`) the path adds

* emission Le(x -> wo) of an area light's front side, met by the ray that found x, weighted by w_b:
  1 at the camera hit or after a delta bounce (no light sample could have found it) or with ``direct = bsdf``;
  0 with ``direct = area``; with ``direct = mis`` the power heuristic (Veach 1997, ch. 9)
  w_b = p_b^2 / (p_b^2 + p_l^2), p_b the BSDF's solid-angle pdf of that ray at the previous vertex and
  p_l = Nd pdf(k) / A_k |x - y|^2 / cos_y the light samples' density of the same direction;
  the environment met by an escaping ray likewise, with p_l = Nd pdf(k_env) p_env(w);
* direct light (``area``, ``mis``; none at a delta BSDF): Nd light samples, light k with pdf(k) and a point on it
  (or an emitter's own sample: :mod:`.emitters`), on either side of x (light can arrive through a rough
  dielectric), each Le G V f|cos_x| / p, f|cos_x| = :func:`.bsdf.bsdf_eval`, weighted with ``mis`` by
  w_l = p_l^2 / (p_l^2 + p_b^2) (delta lights: 1). With ``bsdf`` the delta lights (point, spot, directional), which
  no ray can find, get their own sample as if each were the only light (pdf(k) = 1).
* the next ray: :func:`.bsdf.bsdf_sample`, beta *= its weight f|cos|/p (eta^2 radiance scaling included), then
  Russian roulette from ``rr_depth`` on: "throughput" q = min(max(beta) eta^2, 0.95) (Mitsuba's; eta the product of
  the relative indices of the refractions so far), "pbrt" q = min(max(beta) eta^2, 1) (pbrt-v4's PathIntegrator;
  a path of throughput 1 is never cut, so furnaces of glass or mirrors stay exact), "albedo" q = min(1, max channel of the weight), "fixed" q = 1 - alpha.

Path lengths as the other engines (Mitsuba's max_depth): emission of vertex i counts for i <= max_depth, direct
light at x_i when i + 1 <= max_depth, the next ray when its vertex can still add something. A path is cut after
MAX_VERTICES vertices whatever max_depth says (a closed perfect mirror, whose weight is 1, would never end).

Random numbers past the camera are independent hashes ``uniform(key, dim_salt(depth, PURPOSE, j))``, except at
the first hit with ``sampler = sobol``: there, as in the Lambertian engines, each pixel's light samples, BSDF
directions and (BSDF lobe, roulette) pairs are stratified point sets (:func:`.sobol.glossy_first_hit_seeds`),
computed ahead for the pixel's run of samples, the light sample's choices of light and piece reusing its point's
first coordinate (:func:`.emitters.split_light_piece_all`). (Stratifying vertices 1-16 too took 4 % off the MSE of
cornell-box-specular, 2.275e-3 -> 2.189e-3 at 64 spp over 10 seeds, for 12 % more time: not kept.)
Rays leave x from its origin offset along +N or -N, the
side the new direction leaves (a refraction from the other side).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.emitters import DIRECTIONAL, POINT, SPOT
from reference_impl.kernels.bsdf import bsdf_eval, bsdf_pdf, bsdf_sample, is_delta, sample_eta
from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_INDIRECT, C_LIGHT_SELECT, C_ROULETTE,
                                           C_SHADOW, C_SHADOW_SKIPPED, DIRECT_AREA, DIRECT_BSDF, DIRECT_MIS, JIT,
                                           JIT_BORROW, M_MIS_WEIGHTS_NOT_ONE, M_RR_NO_REWEIGHT, RR_ALBEDO, RR_OFF,
                                           RR_PBRT, RR_THROUGHPUT, SAMPLER_SOBOL)
from reference_impl.kernels.emitters import emitter_direction, env_light_pdf, env_radiance, split_light_piece_all
from reference_impl.kernels.light_sampling import point_on_light, search_within, toward_light_point
from reference_impl.kernels.material import material_at
from reference_impl.kernels.queries import (TIMING_STRIDE, closest_prim_timed, closest_prims_packets, now_ns,
                                            occluded_timed, ray_buffer)
from reference_impl.kernels.record import record_camera, record_closest, record_occluded
from reference_impl.kernels.rng import dim_salt, uniform
from reference_impl.kernels.sobol import (NOTHING_HELD, GlossyFirstHitPairs, ahead, glossy_first_hit_seeds, held_point,
                                          longest_run, pair_point, pixel_run)
from reference_impl.kernels.surface import offset_origin, origin_offset, shadow_t_max, surface_hit
from reference_impl.kernels.warps import dot3, sample_discrete
from reference_impl.materials import DIELECTRIC, NUM_PARAMS, P_TWO_SIDED, ROUGHDIELECTRIC
from reference_impl.rng import BSDF_LOBE, BSDF_U1, BSDF_U2, LIGHT_SELECT, LIGHT_TRIANGLE, LIGHT_U1, LIGHT_U2, ROULETTE

MAX_VERTICES = 1 << 16
RR_THROUGHPUT_CAP = 0.95  # Mitsuba's path integrator


@njit(**JIT_BORROW)
def power_weight(mutant, p_self, p_other, light_side):
    """The power heuristic's weight p_self^2 / (p_self^2 + p_other^2); with the planted fault
    "mis-weights-not-one", the light samples' (``light_side``) is the balance heuristic's p_self / (p_self + p_other)."""
    if light_side and mutant & M_MIS_WEIGHTS_NOT_ONE:  # mutant "mis-weights-not-one"
        return p_self / (p_self + p_other)
    return p_self * p_self / (p_self * p_self + p_other * p_other)


@njit(**JIT_BORROW)
def light_piece(cfg, lights, light, u_tri):
    """The piece (a row of the light tables) of area light k = ``light`` that u_tri picks within k's cdf; -1 for
    an emitter that is not a surface."""
    if light >= cfg.num_area_lights:
        return -1
    f = lights.first[light]
    return f + search_within(lights.within_cdf, f, lights.count[light], u_tri)


@njit(**JIT_BORROW)
def light_connection_on(cfg, scene, lights, emitters, light, piece, pdf_select, u1, u2, x0, x1, x2, n0, n1, n2):
    """Light sample of light k = ``light`` (chosen with ``pdf_select``) at its ``piece`` (:func:`light_piece`; not
    used for an emitter) from x (front normal N), either side of x: (whether it needs a shadow ray, unit direction
    wi from x, what it carries without f|cos_x|: Le G / (p cos_x), the light samples' solid-angle density p_l of wi
    (Nd included; 0 for delta lights), and the shadow ray's end: the point y (or, for ``inf_ray``, none), cos_y (1
    for an emitter that is not a surface))."""
    nothing = (False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False, 0.0, 0.0, 0.0, 1.0, 0.0)
    if light < cfg.num_area_lights:
        emission, light_area = scene.emission, lights.area
        tri, y0, y1, y2 = point_on_light(lights, piece, u1, u2)
        wi0, wi1, wi2, dist2, cos_y = toward_light_point(scene, tri, y0, y1, y2, x0, x1, x2)
        if not (dist2 > 0 and cos_y > 0):
            return nothing
        pdf_area = pdf_select / light_area[light]
        scale = cos_y / (dist2 * pdf_area)
        p_l = cfg.shadow_rays * pdf_area * dist2 / cos_y
        return (True, wi0, wi1, wi2, emission[tri, 0] * scale, emission[tri, 1] * scale, emission[tri, 2] * scale,
                p_l, False, y0, y1, y2, cos_y, origin_offset(cfg.offset_scene, y0, y1, y2))
    if emitters is not None:
        return _emitter_connection(cfg, emitters, light - cfg.num_area_lights, pdf_select, u1, u2, x0, x1, x2, n0,
                                   n1, n2)
    return nothing


@njit(**JIT_BORROW)
def _emitter_connection(cfg, emitters, e, pdf_select, u1, u2, x0, x1, x2, n0, n1, n2):
    """:func:`light_connection_on` for emitter e, which is not a surface, from the light door
    (:func:`.emitters.emitter_direction`)."""
    nothing = (False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False, 0.0, 0.0, 0.0, 1.0, 0.0)
    ok, k, wi0, wi1, wi2, dist2, falloff, pdf, le0, le1, le2, p0, p1, p2 = emitter_direction(
        cfg, emitters, e, u1, u2, x0, x1, x2, n0, n1, n2, False)  # light may arrive from either side
    if not ok:
        return nothing
    if k == POINT or k == SPOT:
        scale = falloff / (dist2 * pdf_select)
        return True, wi0, wi1, wi2, le0 * scale, le1 * scale, le2 * scale, 0.0, False, p0, p1, p2, 1.0, 0.0
    if k == DIRECTIONAL:
        scale = 1.0 / pdf_select
        return True, wi0, wi1, wi2, le0 * scale, le1 * scale, le2 * scale, 0.0, True, 0.0, 0.0, 0.0, 1.0, 0.0
    scale = 1.0 / (pdf_select * pdf)
    return (True, wi0, wi1, wi2, le0 * scale, le1 * scale, le2 * scale, cfg.shadow_rays * pdf_select * pdf, True, 0.0,
            0.0, 0.0, 1.0, 0.0)


@njit(**JIT)
def trace_glossy(state, scene_ptr, scene, lights, materials, cfg, radiance, counters, timing, emitters, film_samples,
                 record=None):
    """Trace every camera path of ``state`` (the wavefront ``camera_paths`` wrote) to its end, one at a time
    (module docstring). ``scene``, ``lights``, ``emitters`` (or None) as for :func:`.path.trace_paths`;
    ``materials`` (:class:`.records.MaterialTables`), indexed by the scene's material ids.
    ``timing`` and ``film_samples`` (:class:`.records.FilmSamples`) as for trace_paths.
    ``record``: None in a render (compiled out), or buffers that receive every query's ray and answer
    (:mod:`.record`, for :mod:`reference_impl.replay`)."""
    root, key, origin, direction, o32, d32, beta, _pdf_dir, _env_pdf = state
    emission, light_id = scene.emission, scene.light_id
    light_cdf, light_pmf, light_area = lights.cdf, lights.pmf, lights.area
    nd = cfg.shadow_rays
    inv_nd = 1.0 / nd
    direct = cfg.direct
    mutant = cfg.mutant
    max_depth = cfg.max_depth
    num_lights = cfg.num_lights
    sobol = cfg.sampler == SAMPLER_SOBOL
    film_pixel, film_sample, seed_key = film_samples.pixel, film_samples.sample, film_samples.seed_key
    # The first hit's points of each pixel's run of samples, computed ahead (kernels.sobol.sobol_points).
    fh = glossy_first_hit_seeds(seed_key, 0, 1, 1)
    fh_pixel = -1
    si = 0
    size = longest_run(film_samples) * nd if sobol else 0
    lx, ly = np.empty(size), np.empty(size)
    bx, by = np.empty(size), np.empty(size)
    cx, cy = np.empty(size), np.empty(size)
    held = GlossyFirstHitPairs(NOTHING_HELD, NOTHING_HELD, NOTHING_HELD)
    # the first hits' BSDF and roulette points are computed ahead only where a first hit's next ray can be drawn
    # without a delta lobe (else the few a delta material draws come from their seeds, the same points)
    next_ray_drawn = direct != DIRECT_AREA or max_depth == -1 or max_depth >= 3
    row = np.empty(NUM_PARAMS)  # the material step's parameters at the current vertex
    words, floats = ray_buffer()
    ts = np.zeros(2, np.int64)
    queries = 0
    sampled_ns = 0
    clock_ns = 1 << 62
    for _ in range(8):
        t_start = now_ns(ts)
        clock_ns = min(clock_ns, now_ns(ts) - t_start)
    n = len(root)
    first_prim = np.full(n, -1, np.int32)
    packet_ns = 0
    if scene_ptr != 0:
        t_start = now_ns(ts)
        closest_prims_packets(scene_ptr, cfg.packet_width, o32, d32, first_prim)
        packet_ns = now_ns(ts) - t_start
        if record is not None:
            record_camera(record, o32, d32, first_prim)

    count_back_face = 0
    count_escaped = 0
    count_indirect = 0
    count_light_select = 0
    count_roulette = 0
    count_shadow = 0
    count_shadow_skipped = 0
    for i in range(n):
        r = root[i]
        k = key[i]
        o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
        d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
        b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
        rad0, rad1, rad2 = radiance[r, 0], radiance[r, 1], radiance[r, 2]
        depth = 1
        prev_delta = True  # the camera ray: what it finds, no light sample could have found
        prev_pdf = 0.0  # the BSDF's solid-angle pdf of the ray that reached this vertex
        pn0, pn1, pn2 = 0.0, 0.0, 1.0  # the previous vertex's normal on the side the ray left (env_light_pdf)
        eta2 = 1.0  # product of the relative ior^2 of the refractions so far (rr = "throughput")
        if sobol:
            if film_pixel[r] != fh_pixel:  # a pixel's samples come together: its seeds and points once
                fh_pixel = film_pixel[r]
                fh = glossy_first_hit_seeds(seed_key, fh_pixel, cfg.spp, nd)
                first, m_run = film_sample[r], pixel_run(film_pixel, film_sample, r)
                held = GlossyFirstHitPairs(ahead(fh.light, first * nd, m_run * nd, lx, ly, True),
                                           ahead(fh.bsdf, first, m_run, bx, by, next_ray_drawn),
                                           ahead(fh.lobe_roulette, first, m_run, cx, cy, next_ray_drawn))
            si = film_sample[r]
        while True:
            sob = sobol and depth == 1
            if depth == 1:
                p = np.int64(first_prim[i])
            elif scene_ptr != 0:
                p, queries, sampled_ns = closest_prim_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1,
                                                            o2, d0, d1, d2)
                if record is not None:
                    record_closest(record, o0, o1, o2, d0, d1, d2, p)
            else:
                p = -1
            if p < 0:
                count_escaped += 1
                if emitters is not None:
                    if cfg.env_light >= 0 and (direct != DIRECT_AREA or prev_delta):
                        e0, e1, e2 = env_radiance(cfg, emitters, d0, d1, d2)
                        w = 1.0
                        if direct == DIRECT_MIS and not prev_delta:
                            p_env = env_light_pdf(cfg, lights, emitters, d0, d1, d2, pn0, pn1, pn2)
                            w = power_weight(mutant, prev_pdf, p_env, False) if p_env > 0 else 1.0
                        rad0 += b0 * e0 * w
                        rad1 += b1 * e1 * w
                        rad2 += b2 * e2 * w
                break
            hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
            tri, t, cos_out = hit.tri, hit.t, hit.cos_out
            light = light_id[tri]
            if light >= 0 and cos_out > 0 and (direct != DIRECT_AREA or prev_delta):
                w = 1.0
                if direct == DIRECT_MIS and not prev_delta:
                    p_light = nd * (light_pmf[light] / light_area[light]) * (t * t) / cos_out
                    w = power_weight(mutant, prev_pdf, p_light, False)
                rad0 += b0 * emission[tri, 0] * w
                rad1 += b1 * emission[tri, 1] * w
                rad2 += b2 * emission[tri, 2] * w
            if not (max_depth == -1 or depth + 1 <= max_depth) or depth >= MAX_VERTICES:
                break
            kind = material_at(materials, hit, row)  # the material step: the BSDF's kind and parameters at x
            x0, x1, x2 = hit.x0, hit.x1, hit.x2
            nx0, nx1, nx2 = hit.n0, hit.n1, hit.n2
            # The BSDF's local frame: the shading frame's tangents s, t and the normal N (the shading normal is N).
            s0, s1, s2, t0, t1, t2 = hit.ss0, hit.ss1, hit.ss2, hit.st0, hit.st1, hit.st2
            wo0, wo1, wo2 = -d0, -d1, -d2
            lo0, lo1, lo2 = dot3(s0, s1, s2, wo0, wo1, wo2), dot3(t0, t1, t2, wo0, wo1, wo2), cos_out
            delta_bsdf = is_delta(kind)

            # Direct light: Nd light samples (none at a delta BSDF); with direct = bsdf the delta lights alone.
            if not delta_bsdf:
                tot0, tot1, tot2 = 0.0, 0.0, 0.0
                samples = nd if direct != DIRECT_BSDF else 0
                if emitters is not None:
                    if direct == DIRECT_BSDF:
                        samples = len(emitters.kind)
                for j in range(samples):
                    if direct != DIRECT_BSDF:
                        if sob:  # one 2D point: its first coordinate picks the light and the piece too
                            u_a, u2 = pair_point(held_point(fh.light, lx, ly, held.light, si * nd + j), si * nd + j)
                            sel, piece, u1 = split_light_piece_all(lights, num_lights, cfg.num_area_lights, u_a)
                        else:
                            u_sel = uniform(k, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
                            u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                            u1 = uniform(k, dim_salt(depth, LIGHT_U1, j))
                            u2 = uniform(k, dim_salt(depth, LIGHT_U2, j))
                            sel = sample_discrete(light_cdf, u_sel) if num_lights > 1 else 0
                            piece = light_piece(cfg, lights, sel, u_tri)
                        pdf_select = light_pmf[sel]
                        if num_lights > 1:
                            count_light_select += 1
                    else:  # a delta light's own sample (its uniforms are not used)
                        sel = -1
                        if emitters is not None:
                            ekind = emitters.kind[j]
                            if ekind == POINT or ekind == SPOT or ekind == DIRECTIONAL:
                                sel = cfg.num_area_lights + j
                        if sel < 0:
                            continue
                        pdf_select, piece, u1, u2 = 1.0, -1, 0.0, 0.0
                    (needed, wi0, wi1, wi2, v0, v1, v2, p_l, inf_ray, y0, y1, y2, cos_y,
                     y_offset) = light_connection_on(cfg, scene, lights, emitters, sel, piece, pdf_select, u1, u2,
                                                     x0, x1, x2, nx0, nx1, nx2)
                    cos_x = dot3(nx0, nx1, nx2, wi0, wi1, wi2)
                    if not (needed and cos_x != 0):
                        count_shadow_skipped += 1
                        continue
                    li0, li1, li2 = dot3(s0, s1, s2, wi0, wi1, wi2), dot3(t0, t1, t2, wi0, wi1, wi2), cos_x
                    f0, f1, f2 = bsdf_eval(kind, row, mutant, lo0, lo1, lo2, li0, li1, li2)
                    if not (f0 > 0 or f1 > 0 or f2 > 0):
                        count_shadow_skipped += 1
                        continue
                    w = 1.0
                    if direct == DIRECT_MIS and p_l > 0:
                        p_b = bsdf_pdf(kind, row, mutant, lo0, lo1, lo2, li0, li1, li2)
                        w = power_weight(mutant, p_l, p_b, True)
                    side = 1.0 if cos_x > 0 else -1.0
                    so0, so1, so2 = offset_origin(cfg.offset_scene, x0, x1, x2, side * nx0, side * nx1, side * nx2)
                    if inf_ray:
                        r0, r1, r2, tfar = wi0, wi1, wi2, np.inf
                    else:
                        g0, g1, g2 = y0 - so0, y1 - so1, y2 - so2
                        seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
                        inv_seg = 1.0 / seg_len
                        r0, r1, r2 = g0 * inv_seg, g1 * inv_seg, g2 * inv_seg
                        tfar = max(shadow_t_max(seg_len, y_offset, cos_y), 0.0)
                    count_shadow += 1
                    blocked = False
                    if scene_ptr != 0:
                        blocked, queries, sampled_ns = occluded_timed(scene_ptr, words, floats, ts, queries,
                                                                      sampled_ns, so0, so1, so2, r0, r1, r2,
                                                                      np.float32(tfar))
                        if record is not None:
                            record_occluded(record, so0, so1, so2, r0, r1, r2, np.float32(tfar), blocked)
                    if not blocked:
                        tot0 += v0 * f0 * w
                        tot1 += v1 * f1 * w
                        tot2 += v2 * f2 * w
                if direct != DIRECT_BSDF:
                    tot0, tot1, tot2 = tot0 * inv_nd, tot1 * inv_nd, tot2 * inv_nd
                rad0 += b0 * tot0
                rad1 += b1 * tot1
                rad2 += b2 * tot2

            if direct == DIRECT_AREA and not (max_depth == -1 or depth + 2 <= max_depth) and not delta_bsdf:
                # its vertex would add direct light only, which max_depth forbids, and no sample of this BSDF is a
                # delta bounce: the next ray is not drawn (a one-sided surface seen from behind is counted as below)
                if cos_out < 0 and row[P_TWO_SIDED] == 0 and not (kind == DIELECTRIC or kind == ROUGHDIELECTRIC):
                    count_back_face += 1
                break

            # The next ray, sampled from the BSDF.
            if sob:
                u1, u2 = pair_point(held_point(fh.bsdf, bx, by, held.bsdf, si), si)
                u_lobe, u_rr = pair_point(held_point(fh.lobe_roulette, cx, cy, held.lobe_roulette, si), si)
            else:
                u_lobe = uniform(k, dim_salt(depth, BSDF_LOBE, 0))
                u1 = uniform(k, dim_salt(depth, BSDF_U1, 0))
                u2 = uniform(k, dim_salt(depth, BSDF_U2, 0))
                u_rr = -1.0  # drawn below only where roulette is played
            ok, li0, li1, li2, w0, w1, w2, pdf, delta = bsdf_sample(kind, row, mutant, lo0, lo1, lo2, u_lobe, u1, u2)
            if not ok:
                if cos_out < 0 and row[P_TWO_SIDED] == 0 and not (kind == DIELECTRIC or kind == ROUGHDIELECTRIC):
                    count_back_face += 1
                break
            if direct == DIRECT_AREA and not delta and not (max_depth == -1 or depth + 2 <= max_depth):
                break  # its vertex would add direct light only, which max_depth forbids
            nb0, nb1, nb2 = b0 * w0, b1 * w1, b2 * w2
            eta_rel = sample_eta(kind, row, lo2, li2)
            eta2 *= eta_rel * eta_rel
            if cfg.rr != RR_OFF and depth >= cfg.rr_depth:
                if cfg.rr == RR_THROUGHPUT:
                    q = min(max(nb0, nb1, nb2) * eta2, RR_THROUGHPUT_CAP)
                elif cfg.rr == RR_PBRT:
                    q = min(max(nb0, nb1, nb2) * eta2, 1.0)
                elif cfg.rr == RR_ALBEDO:
                    q = min(max(w0, w1, w2), 1.0)
                else:
                    q = cfg.survival
                if not sob:
                    u_rr = uniform(k, dim_salt(depth, ROULETTE, 0))
                if not (u_rr < q):
                    count_roulette += 1
                    break
                if not (mutant & M_RR_NO_REWEIGHT):  # mutant "rr-no-reweight": survivors not divided by q
                    inv_q = 1.0 / q
                    nb0, nb1, nb2 = nb0 * inv_q, nb1 * inv_q, nb2 * inv_q
            if not ((math.isfinite(nb0) and math.isfinite(nb1) and math.isfinite(nb2))
                    and (nb0 > 0 or nb1 > 0 or nb2 > 0)):
                count_roulette += 1
                break
            count_indirect += 1
            wn0 = li0 * s0 + li1 * t0 + li2 * nx0
            wn1 = li0 * s1 + li1 * t1 + li2 * nx1
            wn2 = li0 * s2 + li1 * t2 + li2 * nx2
            inv_len = 1.0 / math.sqrt(wn0 * wn0 + wn1 * wn1 + wn2 * wn2)
            d0, d1, d2 = wn0 * inv_len, wn1 * inv_len, wn2 * inv_len
            side = 1.0 if li2 > 0 else -1.0
            pn0, pn1, pn2 = side * nx0, side * nx1, side * nx2
            o0, o1, o2 = offset_origin(cfg.offset_scene, x0, x1, x2, pn0, pn1, pn2)
            b0, b1, b2 = nb0, nb1, nb2
            prev_delta = delta
            prev_pdf = pdf
            depth += 1
        radiance[r, 0], radiance[r, 1], radiance[r, 2] = rad0, rad1, rad2
    counters[C_BACK_FACE] += count_back_face
    counters[C_ESCAPED] += count_escaped
    counters[C_INDIRECT] += count_indirect
    counters[C_LIGHT_SELECT] += count_light_select
    counters[C_ROULETTE] += count_roulette
    counters[C_SHADOW] += count_shadow
    counters[C_SHADOW_SKIPPED] += count_shadow_skipped
    timed = queries // TIMING_STRIDE
    timing[0] += max(sampled_ns - timed * clock_ns, 0) * TIMING_STRIDE + packet_ns
    timing[1] += queries + n


__all__ = ["MAX_VERTICES", "light_connection_on", "light_piece", "power_weight", "trace_glossy"]
