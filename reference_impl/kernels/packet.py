"""The packet engine (``engine = "packet"``, the default): the path engine's loop with up to 16 camera paths of
one pixel stepped together, vertex by vertex, so that their rays go to Embree as packets (``rtcIntersect16`` for the
hits past the camera, ``rtcOccluded16`` for the shadow rays) and the processor overlaps the paths' arithmetic.

Each lane is one path of :func:`.path.trace_paths`, with the same helpers, random numbers and order of
floating-point operations, so the same bits (``tests/reference_impl/test_engines.py``); only where the rays go
differs. Per vertex of the packet:

    1. the closest hits of the lanes still alive: the camera packet's (depth 1), or one packet query;
    2. each lane's vertex in lane order (emission, roulette, the indirect ray, the Nd light samples and their
       shadow rays, kept in the packet's shadow buffer);
    3. the shadow rays, 16 per ``rtcOccluded16`` query;
    4. each lane's direct light summed in sample order, then the lane ends or moves to its next vertex.

Scenes with emitters that are not surfaces, and the hemisphere strategies of direct light, run the path engine's
loop (``trace_paths``), which this engine does not repeat.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_INDIRECT, C_LIGHT_SELECT, C_ROULETTE, C_SHADOW,
                                           C_SHADOW_SKIPPED, EMIT_NONE, JIT, RR_OFF, SAMPLER_SOBOL)
from reference_impl.kernels.direct import light_sample, shadow_ray
from reference_impl.kernels.queries import (closest_prims_coherent, closest_prims_packets, now_ns,
                                            occluded_coherent, packet_buffer)
from reference_impl.kernels.sobol import (NOTHING_HELD, FirstHitPairs, first_hit_seeds, held_point, longest_run,
                                          pixel_first_hit_points)
from reference_impl.kernels.surface import surface_hit
from reference_impl.kernels.vertex import emitted, indirect_ray, roulette, shading_point, vertex_rules

PACKET = 16


@njit(**JIT)
def trace_packets(state, scene_ptr, scene, lights, surfaces, cfg, radiance, counters, timing, film_samples):
    """Trace every camera path of ``state`` to its end, up to 16 paths of one pixel at a time (the module
    docstring): the arguments and results of :func:`.path.trace_paths` on a scene without other emitters and with
    a direct strategy that samples points (area, global area, MIS). ``timing[0]`` receives the nanoseconds spent in
    Embree (every packet query timed), ``timing[1]`` the number of rays queried."""
    root, key, origin, direction, o32, d32, beta, pdf_dir, _env_pdf = state
    nd = cfg.shadow_rays
    inv_nd = 1.0 / nd
    sobol = cfg.sampler == SAMPLER_SOBOL
    film_pixel, film_sample = film_samples.pixel, film_samples.sample
    fh = first_hit_seeds(film_samples.seed_key, 0, 1, 1, 1)
    fh_pixel = -1
    size = longest_run(film_samples) * max(cfg.shadow_rays, cfg.indirect_rays) if sobol else 0
    buffers = (np.empty(size), np.empty(size), np.empty(size), np.empty(size), np.empty(size), np.empty(size),
               np.empty(size), np.empty(size))
    lx, ly, _dx, _dy, rx, ry, ix, iy = buffers
    held = FirstHitPairs(NOTHING_HELD, NOTHING_HELD, NOTHING_HELD, NOTHING_HELD)
    indirect_first = vertex_rules(cfg, 1)[2]
    want_rr = indirect_first and cfg.rr != RR_OFF and cfg.rr_depth <= 1

    ts = np.zeros(2, np.int64)
    words, floats, valid = packet_buffer()
    n = len(root)
    first_prim = np.empty(n, np.int32)
    t_start = now_ns(ts)
    closest_prims_packets(scene_ptr, cfg.packet_width, o32, d32, first_prim)
    embree_ns = now_ns(ts) - t_start
    rays = n

    # The packet's lanes: the path's ray, throughput, pdf, key, sums, and what its vertex hands to step 4.
    lane_r = np.empty(PACKET, np.int64)
    lane_si = np.empty(PACKET, np.int64)
    ray = np.empty((PACKET, 7))  # origin, direction, pdf of the direction
    thru = np.empty((PACKET, 3))
    lane_key = np.empty(PACKET, np.uint64)
    rad = np.empty((PACKET, 3))
    alive = np.zeros(PACKET, np.bool_)
    go_on = np.zeros(PACKET, np.bool_)
    nxt = np.empty((PACKET, 10))  # the next vertex's origin, direction, throughput, pdf
    next_key = np.empty(PACKET, np.uint64)
    prim = np.empty(PACKET, np.int32)
    q_o32 = np.empty((PACKET, 3), np.float32)
    q_d32 = np.empty((PACKET, 3), np.float32)
    q_lane = np.empty(PACKET, np.int64)
    q_prim = np.empty(PACKET, np.int32)
    # Shadow rays of one vertex of the packet: slot[lane, j] (-1: none needed), their rays and values.
    slot = np.empty((PACKET, nd), np.int64)
    s_o32 = np.empty((PACKET * nd, 3), np.float32)
    s_d32 = np.empty((PACKET * nd, 3), np.float32)
    s_tfar = np.empty(PACKET * nd, np.float32)
    s_value = np.empty((PACKET * nd, 3))
    s_hit = np.empty(PACKET * nd, np.int32)

    count_back_face = 0
    count_escaped = 0
    count_indirect = 0
    count_light_select = 0
    count_roulette = 0
    count_shadow = 0
    count_shadow_skipped = 0
    g0 = 0
    while g0 < n:
        # One packet: up to 16 consecutive camera samples of one pixel.
        pixel = film_pixel[root[g0]]
        m = 1
        while m < PACKET and g0 + m < n and film_pixel[root[g0 + m]] == pixel:
            m += 1
        if sobol and pixel != fh_pixel:
            fh, fh_pixel, held = pixel_first_hit_points(cfg, film_samples, root[g0], buffers, True, False,
                                                        want_rr, indirect_first)
        for lane in range(m):
            i = g0 + lane
            r = root[i]
            lane_r[lane] = r
            lane_si[lane] = film_sample[r]
            lane_key[lane] = key[i]
            for c in range(3):
                ray[lane, c] = origin[i, c]
                ray[lane, 3 + c] = direction[i, c]
                thru[lane, c] = beta[i, c]
                rad[lane, c] = radiance[r, c]
            ray[lane, 6] = pdf_dir[i]
            alive[lane] = True
            prim[lane] = first_prim[i]
        depth = 1
        live = m
        while live > 0:
            emit, allow_next, allow_indirect = vertex_rules(cfg, depth)
            sob = sobol and depth == 1
            if depth > 1:  # 1. the closest hits of the lanes still alive, one packet query
                q = 0
                for lane in range(m):
                    if alive[lane]:
                        q_lane[q] = lane
                        for c in range(3):
                            q_o32[q, c] = ray[lane, c]
                            q_d32[q, c] = ray[lane, 3 + c]
                        q += 1
                t_start = now_ns(ts)
                closest_prims_coherent(scene_ptr, cfg.packet_width, q_o32, q_d32, q_prim, 0, q, words, floats,
                                       valid)
                embree_ns += now_ns(ts) - t_start
                rays += q
                for a in range(q):
                    prim[q_lane[a]] = q_prim[a]
            ns = 0
            for lane in range(m):  # 2. each lane's vertex, up to its shadow rays
                if not alive[lane]:
                    continue
                go_on[lane] = False
                for j in range(nd):
                    slot[lane, j] = -1
                p = np.int64(prim[lane])
                o0, o1, o2 = ray[lane, 0], ray[lane, 1], ray[lane, 2]
                d0, d1, d2 = ray[lane, 3], ray[lane, 4], ray[lane, 5]
                b0, b1, b2 = thru[lane, 0], thru[lane, 1], thru[lane, 2]
                k = lane_key[lane]
                si = lane_si[lane]
                if p < 0:
                    count_escaped += 1
                    alive[lane] = False
                    continue
                hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
                if emit != EMIT_NONE:
                    e0, e1, e2, w = emitted(cfg, emit, hit, scene, lights, ray[lane, 6])
                    rad[lane, 0] += b0 * e0 * w
                    rad[lane, 1] += b1 * e1 * w
                    rad[lane, 2] += b2 * e2 * w
                if not allow_next:
                    alive[lane] = False
                    continue
                reflects, material, nx0, nx1, nx2, f0, f1, f2, ox0, ox1, ox2 = shading_point(cfg, scene, hit)
                if not reflects:
                    count_back_face += 1
                    alive[lane] = False
                    continue
                x0, x1, x2 = hit.x0, hit.x1, hit.x2
                going = allow_indirect
                if going:
                    going, q0, q1, q2 = roulette(cfg, scene, material, sob,
                                                 held_point(fh.roulette, rx, ry, held.roulette, si), si, k, depth, b0,
                                                 b1, b2)
                    if not going:
                        count_roulette += 1
                if going:
                    going, nk, w0, w1, w2, c0, c1, c2, next_pdf = indirect_ray(
                        cfg, sob, held_point(fh.indirect, ix, iy, held.indirect, si), si, 0, k, depth, nx0, nx1, nx2,
                        f0, f1, f2, q0, q1, q2)
                    if going:
                        count_indirect += 1
                        next_key[lane] = nk
                        nxt[lane, 0], nxt[lane, 1], nxt[lane, 2] = ox0, ox1, ox2
                        nxt[lane, 3], nxt[lane, 4], nxt[lane, 5] = w0, w1, w2
                        nxt[lane, 6], nxt[lane, 7], nxt[lane, 8] = c0, c1, c2
                        nxt[lane, 9] = next_pdf
                    else:
                        count_roulette += 1
                go_on[lane] = going
                for j in range(nd):
                    selected, ltri, y0, y1, y2, pdf_area = light_sample(
                        cfg, sob, held_point(fh.light, lx, ly, held.light, si * nd + j), si, j, k, depth, scene, lights,
                        surfaces)
                    needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = shadow_ray(
                        cfg, scene, x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2, f0, f1, f2, ltri, y0, y1, y2, pdf_area)
                    if selected:
                        count_light_select += 1
                    if not needed:
                        count_shadow_skipped += 1
                        continue
                    count_shadow += 1
                    slot[lane, j] = ns
                    s_o32[ns, 0], s_o32[ns, 1], s_o32[ns, 2] = so0, so1, so2
                    s_d32[ns, 0], s_d32[ns, 1], s_d32[ns, 2] = r0, r1, r2
                    s_tfar[ns] = np.float32(tfar)
                    s_value[ns, 0], s_value[ns, 1], s_value[ns, 2] = v0, v1, v2
                    ns += 1
            if ns > 0:  # 3. the shadow rays, 16 per packet query
                t_start = now_ns(ts)
                occluded_coherent(scene_ptr, cfg.packet_width, s_o32, s_d32, s_tfar, s_hit, 0, ns, words, floats,
                                  valid)
                embree_ns += now_ns(ts) - t_start
                rays += ns
            live = 0
            for lane in range(m):  # 4. direct light in sample order; the lane ends or moves on
                if not alive[lane]:
                    continue
                tot0, tot1, tot2 = 0.0, 0.0, 0.0
                for j in range(nd):
                    s = slot[lane, j]
                    if s >= 0 and s_hit[s] < 0:
                        tot0 += s_value[s, 0]
                        tot1 += s_value[s, 1]
                        tot2 += s_value[s, 2]
                rad[lane, 0] += thru[lane, 0] * (tot0 * inv_nd)
                rad[lane, 1] += thru[lane, 1] * (tot1 * inv_nd)
                rad[lane, 2] += thru[lane, 2] * (tot2 * inv_nd)
                if not go_on[lane]:
                    alive[lane] = False
                    continue
                lane_key[lane] = next_key[lane]
                for c in range(6):
                    ray[lane, c] = nxt[lane, c]
                thru[lane, 0], thru[lane, 1], thru[lane, 2] = nxt[lane, 6], nxt[lane, 7], nxt[lane, 8]
                ray[lane, 6] = nxt[lane, 9]
                live += 1
            depth += 1
        for lane in range(m):
            r = lane_r[lane]
            radiance[r, 0], radiance[r, 1], radiance[r, 2] = rad[lane, 0], rad[lane, 1], rad[lane, 2]
        g0 += m
    counters[C_BACK_FACE] += count_back_face
    counters[C_ESCAPED] += count_escaped
    counters[C_INDIRECT] += count_indirect
    counters[C_LIGHT_SELECT] += count_light_select
    counters[C_ROULETTE] += count_roulette
    counters[C_SHADOW] += count_shadow
    counters[C_SHADOW_SKIPPED] += count_shadow_skipped
    timing[0] += embree_ns
    timing[1] += rays
