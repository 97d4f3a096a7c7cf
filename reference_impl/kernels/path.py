"""The path engine (``engine = "path"``, the default with Ni = 1): each camera path from its viewing ray to its end in
one compiled loop, with the vertex's Embree queries made on the spot (:mod:`.queries`).

Each vertex is the wavefront's vertex (:mod:`.wavefront`), from the same helpers: the hit point (:mod:`.surface`),
emission, roulette and the indirect ray (:mod:`.vertex`), the direct light (:mod:`.direct`); what differs is only
where the rays go (a query now, not a buffer for the next batched query) and where the sums are kept (in registers,
stored once per path). So the two engines give the same bits (``tests/test_engines.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_HEMI_DIRECT, C_INDIRECT, C_LIGHT_SELECT,
                                           C_ROULETTE, C_SHADOW, C_SHADOW_SKIPPED, DIRECT_GLOBAL_AREA,
                                           DIRECT_HEMI_COSINE, DIRECT_HEMI_UNIFORM, EMIT_MIS, EMIT_NONE, JIT, RR_OFF,
                                           SAMPLER_SOBOL)
from reference_impl.kernels.direct import (complement_sample, hemisphere_sample, hemisphere_weight, light_sample,
                                           light_sample_all, shadow_ray)
from reference_impl.kernels.emitters import env_light_pdf, env_radiance
from reference_impl.kernels.queries import (TIMING_STRIDE, closest_prim_timed, closest_prims_packets, now_ns,
                                            occluded_timed, ray_buffer)
from reference_impl.kernels.sobol import (NOTHING_HELD, FirstHitPairs, first_hit_seeds, held_point, longest_run,
                                          pixel_first_hit_points)
from reference_impl.kernels.surface import surface_hit
from reference_impl.kernels.vertex import emitted, indirect_ray, roulette, shading_point, vertex_rules
from reference_impl.materials import NUM_PARAMS


@njit(**JIT)
def trace_paths(state, scene_ptr, scene, lights, surfaces, materials, cfg, radiance, counters, timing, film_samples,
                emitters):
    """Trace every camera path of ``state`` (the wavefront ``camera_paths`` wrote) to its end, one path at a time,
    with Ni = 1: the same estimator, random numbers and order of floating-point operations as the wavefront
    (``bounce`` then ``resolve_shadow`` / ``resolve_hemisphere`` at each vertex), so the same bits, but each
    vertex's queries are made on the spot (Embree's C API) instead of in batches, and nothing is written between
    vertices but the path's own few numbers.

    ``cfg`` is the render's :class:`.config.KernelConfig` (its ``depth`` is not used: each vertex knows its own).
    The camera rays are traced first, 16 consecutive ones (one pixel's samples) per packet query. ``timing[0]``
    receives the nanoseconds spent in Embree (one query in ``TIMING_STRIDE`` timed), ``timing[1]`` the number of
    queries. ``scene``, ``lights``, ``surfaces`` and ``emitters``: the scene's tables (:mod:`.records`);
    ``film_samples`` (:class:`.records.FilmSamples`): the camera samples, for the stratified sampler.
    ``emitters``: the tables of the emitters that are not surfaces, or None, which compiles every
    branch for them out (``if emitters is not None`` is decided by numba from the argument's type).
    """
    root, key, origin, direction, o32, d32, beta, pdf_dir, _env_pdf = state
    prim_to_tri, tri_normal, emission = scene.prim_to_tri, scene.normal, scene.emission
    nd = cfg.shadow_rays
    inv_nd = 1.0 / nd  # exact for Nd = 1, 2, 4, ...
    hemi_direct = cfg.direct == DIRECT_HEMI_COSINE or cfg.direct == DIRECT_HEMI_UNIFORM
    sobol = cfg.sampler == SAMPLER_SOBOL
    # The first hit's points of each pixel, computed ahead for its samples here, for the pairs these settings draw.
    fh = first_hit_seeds(film_samples.seed_key, 0, 1, 1, 1)
    fh_pixel = -1
    si = 0
    size = longest_run(film_samples) * max(cfg.shadow_rays, cfg.indirect_rays) if sobol else 0
    buffers = (np.empty(size), np.empty(size), np.empty(size), np.empty(size), np.empty(size), np.empty(size),
               np.empty(size), np.empty(size))
    lx, ly, dx, dy, rx, ry, ix, iy = buffers
    held = FirstHitPairs(NOTHING_HELD, NOTHING_HELD, NOTHING_HELD, NOTHING_HELD)
    indirect_first = vertex_rules(cfg, 1)[2]
    want_rr = indirect_first and cfg.rr != RR_OFF and cfg.rr_depth <= 1
    words, floats = ray_buffer()
    row = np.empty(NUM_PARAMS)  # the material step's parameters at the current vertex
    ts = np.zeros(2, np.int64)
    queries = 0
    sampled_ns = 0
    clock_ns = 1 << 62  # the cheapest of a few back-to-back clock reads: what a timed interval holds besides Embree
    for _ in range(8):
        t_start = now_ns(ts)
        clock_ns = min(clock_ns, now_ns(ts) - t_start)
    # The camera rays first, 16 of one pixel's samples per packet query (the same hits as one query per ray).
    n = len(root)
    first_prim = np.empty(n, np.int32)
    t_start = now_ns(ts)
    closest_prims_packets(scene_ptr, cfg.packet_width, o32, d32, first_prim)
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
            if film_samples.pixel[r] != fh_pixel:
                fh, fh_pixel, held = pixel_first_hit_points(cfg, film_samples, r, buffers, not hemi_direct,
                                                            hemi_direct, want_rr, indirect_first)
            si = film_samples.sample[r]
        rad0, rad1, rad2 = radiance[r, 0], radiance[r, 1], radiance[r, 2]  # summed here, stored once
        if emitters is not None:
            nx0, nx1, nx2 = 0.0, 0.0, 1.0  # the previous vertex's normal, for the escape's MIS weight
        while True:
            emit, allow_next, allow_indirect = vertex_rules(cfg, depth)
            sob = sobol and depth == 1
            if depth == 1:
                p = np.int64(first_prim[i])
            else:
                p, queries, sampled_ns = closest_prim_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1,
                                                            o2, d0, d1, d2)
            if p < 0:
                count_escaped += 1
                if emitters is not None:
                    if emit != EMIT_NONE and cfg.env_light >= 0:  # the environment, seen by an escaping ray
                        e0, e1, e2 = env_radiance(cfg, emitters, d0, d1, d2)
                        w = 1.0
                        if emit == EMIT_MIS:  # _mis_weight_hemisphere, against the light samples at the origin
                            p_env = env_light_pdf(cfg, lights, emitters, d0, d1, d2, nx0, nx1, nx2)
                            w = ray_pdf * ray_pdf / (ray_pdf * ray_pdf + p_env * p_env)
                        rad0 += b0 * e0 * w
                        rad1 += b1 * e1 * w
                        rad2 += b2 * e2 * w
                break
            hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
            if emit != EMIT_NONE:
                e0, e1, e2, w = emitted(cfg, emit, hit, scene, lights, ray_pdf)
                rad0 += b0 * e0 * w
                rad1 += b1 * e1 * w
                rad2 += b2 * e2 * w

            if not allow_next:
                break
            reflects, albedo, nx0, nx1, nx2, f0, f1, f2, ox0, ox1, ox2 = shading_point(cfg, materials, hit, row)
            if not reflects:
                count_back_face += 1
                break
            x0, x1, x2 = hit.x0, hit.x1, hit.x2

            # Indirect light, if the next vertex can still add anything. Drawn before the direct light's queries (the
            # random numbers are counter-based, so the order of drawing changes nothing), which gives the processor
            # independent arithmetic to overlap instead of a chain broken by every Embree call.
            go_on = allow_indirect
            if go_on:
                go_on, q0, q1, q2 = roulette(cfg, albedo, sob,
                                             held_point(fh.roulette, rx, ry, held.roulette, si), si, k, depth, b0, b1,
                                             b2)
                if not go_on:
                    count_roulette += 1
            if go_on:
                go_on, next_key, w0, w1, w2, c0, c1, c2, next_pdf = indirect_ray(
                    cfg, sob, held_point(fh.indirect, ix, iy, held.indirect, si), si, 0, k, depth, nx0, nx1, nx2,
                    f0, f1, f2, q0, q1, q2)
                if go_on:
                    count_indirect += 1
                else:
                    count_roulette += 1

            # Direct light: Nd samples, summed in sample order (resolve_shadow / resolve_hemisphere).
            tot0, tot1, tot2 = 0.0, 0.0, 0.0
            for j in range(nd):
                if hemi_direct:
                    h0, h1, h2, ratio = hemisphere_sample(
                        cfg, sob, held_point(fh.direction, dx, dy, held.direction, si * nd + j), si, j, k, depth, nx0,
                        nx1, nx2)
                    count_hemi_direct += 1
                    hp, queries, sampled_ns = closest_prim_timed(scene_ptr, words, floats, ts, queries, sampled_ns,
                                                                 ox0, ox1, ox2, h0, h1, h2)
                    if hp < 0 or ratio < 0:
                        if emitters is not None:
                            if hp < 0 and ratio >= 0 and cfg.env_light >= 0:  # the environment, found by Psi
                                le0, le1, le2 = env_radiance(cfg, emitters, h0, h1, h2)
                                tot0 += le0 * f0 * ratio
                                tot1 += le1 * f1 * ratio
                                tot2 += le2 * f2 * ratio
                        continue
                    htri = prim_to_tri[hp]
                    weight = hemisphere_weight(ratio, h0, h1, h2, tri_normal[htri, 0], tri_normal[htri, 1],
                                               tri_normal[htri, 2])
                    tot0 += emission[htri, 0] * f0 * weight
                    tot1 += emission[htri, 1] * f1 * weight
                    tot2 += emission[htri, 2] * f2 * weight
                    continue
                if emitters is None:
                    selected, ltri, y0, y1, y2, pdf_area = light_sample(
                        cfg, sob, held_point(fh.light, lx, ly, held.light, si * nd + j), si, j, k, depth, scene, lights,
                        surfaces)
                    needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = shadow_ray(
                        cfg, scene, x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2, f0, f1, f2, ltri, y0, y1, y2, pdf_area)
                else:
                    selected, needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = light_sample_all(
                        cfg, sob, held_point(fh.light, lx, ly, held.light, si * nd + j), si, j, k, depth, scene, lights,
                        surfaces, emitters, x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2, f0, f1, f2)
                if selected:
                    count_light_select += 1
                if not needed:
                    count_shadow_skipped += 1
                    continue
                count_shadow += 1
                blocked, queries, sampled_ns = occluded_timed(scene_ptr, words, floats, ts, queries, sampled_ns, so0,
                                                              so1, so2, r0, r1, r2, np.float32(tfar))
                if not blocked:
                    tot0 += v0
                    tot1 += v1
                    tot2 += v2
            rad0 += b0 * (tot0 * inv_nd)
            rad1 += b1 * (tot1 * inv_nd)
            rad2 += b2 * (tot2 * inv_nd)
            if emitters is not None:
                if hemi_direct or cfg.direct == DIRECT_GLOBAL_AREA:  # what the strategy cannot find (resolve_complement)
                    ct0, ct1, ct2 = 0.0, 0.0, 0.0
                    for e in range(len(emitters.kind)):
                        is_complement, needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = complement_sample(
                            cfg, emitters, e, k, depth, x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2, f0, f1, f2)
                        if not is_complement:
                            continue
                        if not needed:
                            count_shadow_skipped += 1
                            continue
                        count_shadow += 1
                        blocked, queries, sampled_ns = occluded_timed(scene_ptr, words, floats, ts, queries,
                                                                      sampled_ns, so0, so1, so2, r0, r1, r2,
                                                                      np.float32(tfar))
                        if not blocked:
                            ct0 += v0
                            ct1 += v1
                            ct2 += v2
                    rad0 += b0 * ct0
                    rad1 += b1 * ct1
                    rad2 += b2 * ct2

            if not go_on:
                break
            k = next_key
            o0, o1, o2 = ox0, ox1, ox2
            d0, d1, d2 = w0, w1, w2
            b0, b1, b2 = c0, c1, c2
            ray_pdf = next_pdf
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
    timed = queries // TIMING_STRIDE  # the queries closest_prim_timed / occluded_timed timed
    timing[0] += max(sampled_ns - timed * clock_ns, 0) * TIMING_STRIDE + packet_ns
    timing[1] += queries + n
