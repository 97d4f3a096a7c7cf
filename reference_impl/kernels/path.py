"""The path engine (``engine = "path"``, the default with Ni = 1): each camera path from its viewing ray to its end in
one compiled loop, with the vertex's Embree queries made on the spot (:mod:`reference_impl.kernels.queries`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_HEMI_DIRECT, C_INDIRECT, C_LIGHT_SELECT, C_ROULETTE,
                                           C_SHADOW, C_SHADOW_SKIPPED, CFG_DIRECT, CFG_EMIT, CFG_HEMI_COSINE,
                                           CFG_MUTANTS, CFG_ND, CFG_NUM_LIGHTS, CFG_RR, CFG_RR_DEPTH, CFG_SOBOL, CFG_SPP,
                                           CFGF_FIXED_SURVIVAL, CFGF_OFFSET_SCENE, CFGF_SURFACE_PDF, DIRECT_GLOBAL_AREA,
                                           DIRECT_HEMI_COSINE, DIRECT_HEMI_UNIFORM, DIRECT_MIS, EMIT_ALL, EMIT_MIS,
                                           EMIT_NONE, JIT, M_COSINE_PDF_PI, M_LIGHT_PDF_IGNORED, M_NO_COSINE,
                                           M_NO_RAY_OFFSET, M_RR_NO_REWEIGHT, RR_ALBEDO, RR_OFF)
from reference_impl.kernels.light_sampling import (sample_light_point, sample_surface_point, split_light_uniform,
                                                   split_surface_uniform)
from reference_impl.kernels.queries import TIMING_STRIDE, closest_prim, closest_prims_packets, now_ns, occluded, ray_buffer
from reference_impl.kernels.rng import (DIRECT_DIR_U1, DIRECT_DIR_U2, INDIRECT_U1, INDIRECT_U2, LIGHT_SELECT,
                                        LIGHT_TRIANGLE, LIGHT_U1, LIGHT_U2, ROULETTE, dim_salt, uniform)
from reference_impl.kernels.sobol import first_hit_seeds, sobol_point, uniform_2d
from reference_impl.kernels.surface import origin_offset, shadow_t_max
from reference_impl.kernels.warps import PI, dot3, hemisphere_pdf, sample_hemisphere


@njit(**JIT)
def trace_paths(state, scene_ptr, scene, lights, surfaces, cfg, cfg_f, max_depth, radiance, counters, timing,
                film_samples):
    """Trace every camera path of ``state`` (the wavefront ``camera_paths`` wrote) to its end, one path at a time,
    with Ni = 1: the same estimator, random numbers and order of floating-point operations as the wavefront
    (``bounce`` then ``resolve_shadow`` / ``resolve_hemisphere`` at each vertex), so the same bits, but each
    vertex's queries are made on the spot (Embree's C API) instead of in batches, and nothing is written between
    vertices but the path's own few numbers.

    ``cfg`` is the integer configuration of :func:`bounce` without its per-vertex entries (depth, emission mode,
    whether a next vertex and indirect light are needed), which are derived here from ``max_depth`` (-1: unbounded),
    the direct-light mode (MIS) and the planted faults; ``cfg[CFG_EMIT]`` = EMIT_ALL marks the double-emission
    mutant. The camera rays are traced first, 16 consecutive ones (one pixel's samples) per packet query.
    ``timing[0]`` receives the nanoseconds spent in Embree (one query in ``TIMING_STRIDE`` timed), ``timing[1]``
    the number of queries. ``film_samples`` = (pixel, sample, seed_key) of the camera samples, for the stratified
    sampler.
    """
    root, key, origin, direction, o32, d32, beta, pdf_dir = state
    prim_to_tri, tri_normal, tri_v0, corners, emission, light_id, tri_material, two_sided, f_r_table, albedo_max = scene
    light_pmf, light_area = lights[5], lights[6]
    double_emission = cfg[CFG_EMIT] == EMIT_ALL
    direct = cfg[CFG_DIRECT]
    mis = direct == DIRECT_MIS
    nd = cfg[CFG_ND]
    inv_nd = 1.0 / nd  # exact for Nd = 1, 2, 4, ...
    ni = 1
    hemi_cosine = cfg[CFG_HEMI_COSINE] != 0
    rr = cfg[CFG_RR]
    rr_depth = cfg[CFG_RR_DEPTH]
    mutants = cfg[CFG_MUTANTS]
    num_lights = cfg[CFG_NUM_LIGHTS]
    fixed_survival = cfg_f[CFGF_FIXED_SURVIVAL]
    offset_scene = cfg_f[CFGF_OFFSET_SCENE]
    surface_pdf = cfg_f[CFGF_SURFACE_PDF]
    no_cosine = (mutants & M_NO_COSINE) != 0
    hemi_direct = direct == DIRECT_HEMI_COSINE or direct == DIRECT_HEMI_UNIFORM
    sobol = cfg[CFG_SOBOL] != 0
    film_pixel, film_sample, seed_key = film_samples
    spp = cfg[CFG_SPP]
    fh = first_hit_seeds(seed_key, 0, 1, 1, 1)
    fh_pixel = -1
    si = 0
    # The vertex below repeats :func:`bounce` line for line (both must give the same bits). Sharing the light sample
    # and shadow ray through helper functions was measured: numba passes their arrays and 11-value results through
    # calls it does not optimise away, and the Cornell box fell from 4.98 to 3.0-3.3 M paths/s (inline="always" or
    # not). tests/test_engines.py holds the two copies to the same bits.
    words, floats = ray_buffer()
    ts = np.zeros(2, np.int64)
    queries = 0
    sampled_ns = 0
    clock_ns = 1 << 62  # the cheapest of a few back-to-back clock reads: what a timed interval holds besides Embree
    for _ in range(8):
        t_start = now_ns(ts)
        clock_ns = min(clock_ns, now_ns(ts) - t_start)
    timed = 0
    # The camera rays first, 16 of one pixel's samples per packet query (the same hits as one query per ray).
    n = len(root)
    first_prim = np.empty(n, np.int32)
    t_start = now_ns(ts)
    closest_prims_packets(scene_ptr, o32, d32, first_prim)
    packet_ns = now_ns(ts) - t_start

    count_back_face = 0
    count_escaped = 0
    count_hemi_direct = 0
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
        ray_pdf = pdf_dir[i]
        depth = 1
        if sobol:
            if film_pixel[r] != fh_pixel:  # a pixel's samples come together: its seeds once
                fh_pixel = film_pixel[r]
                fh = first_hit_seeds(seed_key, fh_pixel, spp, nd, 1)
            si = film_sample[r]
        rad0, rad1, rad2 = radiance[r, 0], radiance[r, 1], radiance[r, 2]  # summed here, stored once
        while True:
            # The per-vertex configuration (integrator._Context.bounce_config).
            if depth == 1 or double_emission:
                emit = EMIT_ALL
            elif mis:
                emit = EMIT_MIS
            else:
                emit = EMIT_NONE
            allow_next = max_depth == -1 or depth + 1 <= max_depth
            allow_indirect = (max_depth == -1 or depth + 2 <= max_depth) or (mis and allow_next)
            play_roulette = rr != RR_OFF and depth >= rr_depth
            sob = sobol and depth == 1

            if depth == 1:
                p = np.int64(first_prim[i])
            else:
                queries += 1
                if queries % TIMING_STRIDE == 0:
                    t_start = now_ns(ts)
                    p = closest_prim(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2)
                    sampled_ns += now_ns(ts) - t_start
                    timed += 1
                else:
                    p = closest_prim(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2)
            if p < 0:
                count_escaped += 1
                break
            tri = prim_to_tri[p]
            nx0, nx1, nx2 = tri_normal[tri, 0], tri_normal[tri, 1], tri_normal[tri, 2]
            denom = dot3(d0, d1, d2, nx0, nx1, nx2)
            t = dot3(tri_v0[tri, 0] - o0, tri_v0[tri, 1] - o1, tri_v0[tri, 2] - o2, nx0, nx1, nx2) / denom
            if not (math.isfinite(t) and t > 0):
                t = 0.0
            x0, x1, x2 = o0 + t * d0, o1 + t * d1, o2 + t * d2
            cos_out = -dot3(d0, d1, d2, nx0, nx1, nx2)
            front = cos_out > 0

            if emit != EMIT_NONE:
                fr = 1.0 if front else 0.0
                e0, e1, e2 = emission[tri, 0] * fr, emission[tri, 1] * fr, emission[tri, 2] * fr
                if emit == EMIT_ALL:
                    rad0 += b0 * e0
                    rad1 += b1 * e1
                    rad2 += b2 * e2
                else:
                    light = light_id[tri]
                    w = 0.0
                    if light >= 0 and cos_out > 0:
                        p_light = nd * (light_pmf[light] / light_area[light]) * (t * t) / cos_out
                        p_hemi = ray_pdf
                        w = p_hemi * p_hemi / (p_hemi * p_hemi + p_light * p_light)
                    rad0 += b0 * e0 * w
                    rad1 += b1 * e1 * w
                    rad2 += b2 * e2 * w

            if not allow_next:
                break
            material = tri_material[tri]
            if not (front or two_sided[material]):
                count_back_face += 1
                break
            if not front:
                nx0, nx1, nx2 = -nx0, -nx1, -nx2
            f0, f1, f2 = f_r_table[material, 0], f_r_table[material, 1], f_r_table[material, 2]
            off_x = origin_offset(offset_scene, x0, x1, x2)
            ox0, ox1, ox2 = x0 + off_x * nx0, x1 + off_x * nx1, x2 + off_x * nx2

            # Indirect light (Fig. 5.14), if the next vertex can still add anything. Drawn before the direct light's
            # queries (the random numbers are counter-based, so the order of drawing changes nothing), which gives the
            # processor independent arithmetic to overlap instead of a chain broken by every Embree call.
            go_on = allow_indirect
            if go_on and play_roulette:
                survival = albedo_max[material] if rr == RR_ALBEDO else fixed_survival
                u_rr = sobol_point(fh[2], si)[0] if sob else uniform(k, dim_salt(depth, ROULETTE, 0))
                if not (u_rr < survival):
                    count_roulette += 1
                    go_on = False
                elif not (mutants & M_RR_NO_REWEIGHT):
                    inv_survival = 1.0 / survival
                    q0, q1, q2 = b0 * inv_survival, b1 * inv_survival, b2 * inv_survival
                else:
                    q0, q1, q2 = b0, b1, b2
            else:
                q0, q1, q2 = b0, b1, b2
            if go_on:
                u_a, u_b = uniform_2d(sob, fh[3], si, k, 0, depth, INDIRECT_U1, INDIRECT_U2)
                w0, w1, w2, cos_theta, pdf = sample_hemisphere(hemi_cosine, u_a, u_b, nx0, nx1, nx2)
                if (mutants & M_COSINE_PDF_PI) and hemi_cosine:
                    pdf = pdf * PI
                cos_factor = 1.0 if no_cosine else cos_theta
                weight = cos_factor / (pdf * ni)
                c0, c1, c2 = q0 * (f0 * weight), q1 * (f1 * weight), q2 * (f2 * weight)
                carries = (math.isfinite(c0) and math.isfinite(c1) and math.isfinite(c2)) and (c0 > 0 or c1 > 0 or c2 > 0)
                if not carries:
                    count_roulette += 1
                    go_on = False
                else:
                    count_indirect += 1

            # Direct light: Nd samples, summed in sample order (resolve_shadow / resolve_hemisphere).
            tot0, tot1, tot2 = 0.0, 0.0, 0.0
            for j in range(nd):
                if hemi_direct:
                    u_a, u_b = uniform_2d(sob, fh[1], si * nd + j, k, j, depth, DIRECT_DIR_U1, DIRECT_DIR_U2)
                    h0, h1, h2, h_cos, h_pdf = sample_hemisphere(direct == DIRECT_HEMI_COSINE, u_a, u_b, nx0, nx1, nx2)
                    count_hemi_direct += 1
                    aux = h_cos / h_pdf if h_pdf > 0 else -1.0
                    queries += 1
                    if queries % TIMING_STRIDE == 0:
                        t_start = now_ns(ts)
                        hp = closest_prim(scene_ptr, words, floats, ox0, ox1, ox2, h0, h1, h2)
                        sampled_ns += now_ns(ts) - t_start
                        timed += 1
                    else:
                        hp = closest_prim(scene_ptr, words, floats, ox0, ox1, ox2, h0, h1, h2)
                    if hp < 0 or aux < 0:
                        continue
                    htri = prim_to_tri[hp]
                    faces_x = dot3(h0, h1, h2, tri_normal[htri, 0], tri_normal[htri, 1], tri_normal[htri, 2]) < 0
                    weight = aux * (1.0 if faces_x else 0.0)
                    tot0 += emission[htri, 0] * f0 * weight
                    tot1 += emission[htri, 1] * f1 * weight
                    tot2 += emission[htri, 2] * f2 * weight
                    continue
                if sob:
                    u_a, u_b = sobol_point(fh[0], si * nd + j)
                else:
                    u_a, u_b = uniform(k, dim_salt(depth, LIGHT_U1, j)), uniform(k, dim_salt(depth, LIGHT_U2, j))
                if direct == DIRECT_GLOBAL_AREA:
                    if sob:
                        u_tri, u_a = split_surface_uniform(surfaces, u_a)
                    else:
                        u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                    ltri, y0, y1, y2 = sample_surface_point(surfaces, corners, u_tri, u_a, u_b)
                    pdf_area = surface_pdf
                else:
                    if sob:
                        u_select, u_tri, u_a = split_light_uniform(lights, num_lights, u_a)
                    else:
                        u_select = uniform(k, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
                        u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                    if num_lights > 1:
                        count_light_select += 1
                    light, ltri, y0, y1, y2 = sample_light_point(lights, num_lights, corners, u_select, u_tri, u_a, u_b)
                    if mutants & M_LIGHT_PDF_IGNORED:
                        pdf_area = 1.0 / light_area[light]
                    else:
                        pdf_area = light_pmf[light] / light_area[light]
                l0, l1, l2 = y0 - x0, y1 - x1, y2 - x2
                dist2 = dot3(l0, l1, l2, l0, l1, l2)
                dist = math.sqrt(dist2)
                inv_dist = 1.0 / dist  # one division, three products
                wi0, wi1, wi2 = l0 * inv_dist, l1 * inv_dist, l2 * inv_dist
                cos_x = dot3(nx0, nx1, nx2, wi0, wi1, wi2)
                cos_y = -dot3(tri_normal[ltri, 0], tri_normal[ltri, 1], tri_normal[ltri, 2], wi0, wi1, wi2)
                if not (cos_x > 0 and cos_y > 0 and light_id[ltri] >= 0 and dist2 > 0):
                    count_shadow_skipped += 1
                    continue
                if mutants & M_NO_RAY_OFFSET:
                    so0, so1, so2 = x0, x1, x2
                else:
                    so0, so1, so2 = ox0, ox1, ox2
                g0, g1, g2 = y0 - so0, y1 - so1, y2 - so2
                seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
                t_max = shadow_t_max(seg_len, origin_offset(offset_scene, y0, y1, y2), cos_y)
                inv_seg = 1.0 / seg_len
                count_shadow += 1
                cos_at_x = 1.0 if no_cosine else cos_x
                scale = (cos_at_x * cos_y) / (dist2 * pdf_area)
                v0 = emission[ltri, 0] * f0 * scale
                v1 = emission[ltri, 1] * f1 * scale
                v2 = emission[ltri, 2] * f2 * scale
                if mis:
                    p_light = nd * pdf_area * dist2 / cos_y
                    p_hemi = ni * hemisphere_pdf(hemi_cosine, cos_x)
                    w = p_light * p_light / (p_light * p_light + p_hemi * p_hemi)
                    v0, v1, v2 = v0 * w, v1 * w, v2 * w
                tfar = np.float32(max(t_max, 0.0))
                queries += 1
                if queries % TIMING_STRIDE == 0:
                    t_start = now_ns(ts)
                    blocked = occluded(scene_ptr, words, floats, so0, so1, so2, g0 * inv_seg, g1 * inv_seg,
                                       g2 * inv_seg, tfar)
                    sampled_ns += now_ns(ts) - t_start
                    timed += 1
                else:
                    blocked = occluded(scene_ptr, words, floats, so0, so1, so2, g0 * inv_seg, g1 * inv_seg,
                                       g2 * inv_seg, tfar)
                if not blocked:
                    tot0 += v0
                    tot1 += v1
                    tot2 += v2
            rad0 += b0 * (tot0 * inv_nd)
            rad1 += b1 * (tot1 * inv_nd)
            rad2 += b2 * (tot2 * inv_nd)

            if not go_on:
                break
            o0, o1, o2 = ox0, ox1, ox2
            d0, d1, d2 = w0, w1, w2
            b0, b1, b2 = c0, c1, c2
            ray_pdf = pdf * ni
            depth += 1
        radiance[r, 0], radiance[r, 1], radiance[r, 2] = rad0, rad1, rad2
    counters[C_BACK_FACE] += count_back_face
    counters[C_ESCAPED] += count_escaped
    counters[C_HEMI_DIRECT] += count_hemi_direct
    counters[C_INDIRECT] += count_indirect
    counters[C_LIGHT_SELECT] += count_light_select
    counters[C_ROULETTE] += count_roulette
    counters[C_SHADOW] += count_shadow
    counters[C_SHADOW_SKIPPED] += count_shadow_skipped
    timing[0] += max(sampled_ns - timed * clock_ns, 0) * TIMING_STRIDE + packet_ns
    timing[1] += queries + n
