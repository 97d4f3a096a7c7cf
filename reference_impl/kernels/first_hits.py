"""Paths that end at their first hit (max_depth 2: emission and direct light; or 1), on a Lambertian scene lit by
area lights alone, traced as :func:`.path.trace_paths` traces them, bit for bit, with Embree asked for their shadow
rays 16 at a time.

For each block of :data:`BLOCK` consecutive camera paths of a batch (the camera rays' hits found in packets, as the
path loop finds them):

1. per path that hit something, its Nd light samples: light k with pdf(k) and a point y on it with p(y)
   (:func:`.direct.light_choice`, :func:`.direct.area_light_point`). Nothing in them depends on the hit, so they
   are drawn in a loop of their own, where one sample's division and square root need not wait for its path's hit;
2. per path, what the path loop does at its first hit x before its shadow queries: the emission x shows the camera
   ray (Le(x -> wo), weight 1), the material step, and the Nd light connections to those points (Le G f |cos_x| / p
   through the BSDF door, :func:`.path.connect`), each kept with its shadow ray (:func:`.direct.connection_ray`)
   where it needs one;
3. the block's shadow rays, in the order they were made, as packets of ``cfg.packet_width`` occlusion queries
   (``rtcOccluded16``, ``8`` or ``4``; one query per ray where the processor has no packets);
4. per path, in the path loop's order: radiance = emission + beta (the sum of its unblocked connections, in j
   order) / Nd.

Each path's radiance is summed in the order the path loop sums it, from the same numbers, and a packet answers as
one query per ray does (the same float32 ray, :func:`.queries.packet_lane`), so the image is the path loop's, bit for
bit (tests/reference_impl/test_first_hits.py). What the packets buy: Embree traverses its tree once for up to 16
shadow rays that leave one pixel's hits (docs/performance.md, "Issue 39: shadow rays in packets"; what drawing the
light samples first buys: "Issue 39: light samples drawn first, camera packets marked coherent"). Paths that go on
past their first hit stay in the path loop: its first hits in blocks, the rest as before, took 1.01 x the time on the
Cornell box and 1.05 x on multi-light ("Issue 39: shadow rays in packets").
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl import embree_c
from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_LIGHT_SELECT, C_SHADOW, C_SHADOW_SKIPPED,
                                           HEMI_UNIFORM, JIT, M_LIGHT_PDF_IGNORED, SAMPLER_SOBOL)
from reference_impl.kernels.direct import area_light_point, connection_ray, light_choice, point_connection
from reference_impl.kernels.material import material_at
from reference_impl.kernels.path import connect
from reference_impl.kernels.queries import closest_prims_packets, now_ns, packet_buffer, packet_lane, packet_rest
from reference_impl.kernels.shading import geometric_frame
from reference_impl.kernels.sobol import (NOTHING_HELD, ahead, held_point, longest_run, pair_point,
                                          path_first_hit_seeds, pixel_run)
from reference_impl.kernels.surface import emission_at, offset_origin, surface_hit
from reference_impl.kernels.warps import dot3
from reference_impl.materials import DIFFUSE, P_TWO_SIDED, ROW_SIZE

#: camera paths per block: their shadow rays are kept until the block's packets are queried
BLOCK = 256


@njit(**JIT)
def occluded_packets(scene_ptr, width, origin, direction, tfar, count, blocked, words, floats, valid):
    """Whether something blocks each of the shadow rays 0 .. count - 1 (float64 origins and unit directions, float32
    ``tfar``), ``width`` rays per occlusion query (Embree sets a blocked lane's tfar to -inf), into ``blocked``."""
    if width == 1:
        for s in range(count):
            packet_lane(words, floats, valid, 1, 0, origin[s, 0], origin[s, 1], origin[s, 2], direction[s, 0],
                        direction[s, 1], direction[s, 2], tfar[s])
            embree_c.rtc_occluded1(scene_ptr, words.ctypes.data, 0)
            blocked[s] = floats[8] < 0
        return
    for s0 in range(0, count, width):
        m = min(width, count - s0)
        for lane in range(m):
            s = s0 + lane
            packet_lane(words, floats, valid, width, lane, origin[s, 0], origin[s, 1], origin[s, 2], direction[s, 0],
                        direction[s, 1], direction[s, 2], tfar[s])
        packet_rest(words, floats, valid, width, m)
        if width == 16:
            embree_c.rtc_occluded16(valid.ctypes.data, scene_ptr, words.ctypes.data, 0)
        elif width == 8:
            embree_c.rtc_occluded8(valid.ctypes.data, scene_ptr, words.ctypes.data, 0)
        else:
            embree_c.rtc_occluded4(valid.ctypes.data, scene_ptr, words.ctypes.data, 0)
        for lane in range(m):
            blocked[s0 + lane] = floats[8 * width + lane] < 0


@njit(**JIT)
def trace_first_hits(state, scene_ptr, scene, lights, materials, cfg, radiance, counters, timing, film_samples):
    """Trace every camera path of ``state`` (the wavefront's ``camera_paths`` wrote them) as :func:`.path.trace_paths`
    traces it, on a scene this runs for (``integrator._Context.first_hits``: max_depth 2 or 1, every material
    diffuse, ``direct = area``, area lights alone, no textured light, shading normal, sphere, mask, nested material or
    light tree; not recorded): each path's radiance written to ``radiance[root]`` (the path loop's sum, which starts
    at 0: the buffer need not be zeroed), the same counters and timing."""
    root, key, origin, direction, o32, d32, beta, _pdf_dir, _env_pdf = state
    light_id = scene.light_id
    light_pmf = lights.pmf
    nd = cfg.shadow_rays
    inv_nd = 1.0 / nd
    mutant = cfg.mutant
    max_depth = cfg.max_depth
    num_lights = cfg.num_lights
    uniform_diffuse = cfg.hemisphere == HEMI_UNIFORM
    sobol = cfg.sampler == SAMPLER_SOBOL
    film_pixel, film_sample, seed_key = film_samples.pixel, film_samples.sample, film_samples.seed_key
    fh = path_first_hit_seeds(seed_key, 0, 1, 1)
    fh_pixel = -1
    si = 0
    run = longest_run(film_samples) if sobol else 0
    lx, ly = np.empty(run * nd), np.empty(run * nd)
    held_light = NOTHING_HELD
    row = np.empty(ROW_SIZE)
    ts = np.zeros(2, np.int64)
    n = len(root)
    first_prim = np.full(n, -1, np.int32)
    embree_ns = 0
    if scene_ptr != 0:
        t_start = now_ns(ts)
        closest_prims_packets(scene_ptr, cfg.packet_width, o32, d32, first_prim, None, 0)
        embree_ns += now_ns(ts) - t_start
    words, floats, valid = packet_buffer()
    # the block's paths: their radiance so far, whether they reached their light connections
    rad = np.empty((BLOCK, 3))
    lit = np.zeros(BLOCK, np.bool_)
    # and their shadow rays, in the order they were made
    rays = BLOCK * nd
    s_origin, s_direction = np.empty((rays, 3)), np.empty((rays, 3))
    s_tfar = np.empty(rays, np.float32)
    s_value = np.empty((rays, 3))
    s_owner = np.empty(rays, np.int64)
    s_blocked = np.zeros(rays, np.bool_)
    # the block's light samples, Nd a path: the triangle y lies in, y, p(y)
    y_tri, y, y_pdf = np.empty(rays, np.int64), np.empty((rays, 3)), np.empty(rays)
    count_back_face = 0
    count_escaped = 0
    count_light_select = 0
    count_shadow = 0
    count_shadow_skipped = 0
    for i0 in range(0, n, BLOCK):
        i1 = min(n, i0 + BLOCK)
        s = 0
        # the block's light samples (none for max_depth 1), drawn before its hits: nothing in them depends on x
        for i in range(i0, i1 if max_depth >= 2 else i0):
            r = root[i]
            if sobol:
                if film_pixel[r] != fh_pixel:  # a pixel's samples come together: its seeds and points once
                    fh_pixel = film_pixel[r]
                    fh = path_first_hit_seeds(seed_key, fh_pixel, cfg.spp, nd)
                    first, m_run = film_sample[r], pixel_run(film_pixel, film_sample, r)
                    held_light = ahead(fh.light, first * nd, m_run * nd, lx, ly, True)
                si = film_sample[r]
            if first_prim[i] < 0:
                continue
            for j in range(nd):
                u_a, u_b = 0.0, 0.0
                if sobol:  # one 2D point: its first coordinate picks the light and the piece too
                    u_a, u_b = pair_point(held_point(fh.light, lx, ly, held_light, si * nd + j), si * nd + j)
                sel, piece, u1, u2 = light_choice(cfg, lights, sobol, u_a, u_b, key[i], 1, j)
                pdf_select = light_pmf[sel]
                if mutant & M_LIGHT_PDF_IGNORED:  # mutant "light-pdf-ignored": pdf(y|k) alone
                    pdf_select = 1.0
                c = (i - i0) * nd + j
                y_tri[c], y[c, 0], y[c, 1], y[c, 2], y_pdf[c] = area_light_point(cfg, scene, lights, sel, piece,
                                                                                 pdf_select, u1, u2)
        for i in range(i0, i1):
            b = i - i0
            r = root[i]
            rad0, rad1, rad2 = 0.0, 0.0, 0.0
            lit[b] = False
            p = np.int64(first_prim[i])
            if p < 0:
                count_escaped += 1
                rad[b, 0], rad[b, 1], rad[b, 2] = rad0, rad1, rad2
                continue
            o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
            d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
            b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
            hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
            tri, cos_out = hit.tri, hit.cos_out
            light = light_id[tri]
            if light >= 0 and cos_out > 0:  # the camera ray's hit: no light sample could have found it (weight 1)
                le0, le1, le2 = emission_at(scene, None, tri, hit.x0, hit.x1, hit.x2, mutant)
                rad0 += b0 * le0
                rad1 += b1 * le1
                rad2 += b2 * le2
            rad[b, 0], rad[b, 1], rad[b, 2] = rad0, rad1, rad2
            if max_depth < 2:  # emission only: no light sample
                continue
            material_at(materials, hit, row, mutant)
            kind = DIFFUSE
            if not (cos_out > 0 or row[P_TWO_SIDED] != 0):
                count_back_face += 1  # the back of a one-sided surface: black
                continue
            lit[b] = True
            x0, x1, x2 = hit.x0, hit.x1, hit.x2
            nx0, nx1, nx2 = hit.n0, hit.n1, hit.n2
            side = 1.0 if cos_out > 0 else -1.0
            ns0, ns1, ns2 = side * nx0, side * nx1, side * nx2
            ox0, ox1, ox2 = offset_origin(cfg.offset_scene, x0, x1, x2, ns0, ns1, ns2)
            wo0, wo1, wo2 = -d0, -d1, -d2
            sf = geometric_frame(hit)
            lo0, lo1 = dot3(sf.s0, sf.s1, sf.s2, wo0, wo1, wo2), dot3(sf.t0, sf.t1, sf.t2, wo0, wo1, wo2)
            lo2 = cos_out
            for j in range(nd):
                if num_lights > 1:
                    count_light_select += 1
                c = b * nd + j
                conn = point_connection(cfg, scene, None, y_tri[c], y[c, 0], y[c, 1], y[c, 2], y_pdf[c], x0, x1, x2)
                needed, cos_x, v0, v1, v2 = connect(mutant, kind, row, uniform_diffuse, False, conn, False, side, nx0,
                                                    nx1, nx2, sf, lo0, lo1, lo2, None)
                if not needed:
                    count_shadow_skipped += 1
                    continue
                count_shadow += 1
                so0, so1, so2, r0, r1, r2, tfar = connection_ray(cfg, conn, cos_x, False, x0, x1, x2, nx0, nx1, nx2,
                                                                 ox0, ox1, ox2)
                s_origin[s, 0], s_origin[s, 1], s_origin[s, 2] = so0, so1, so2
                s_direction[s, 0], s_direction[s, 1], s_direction[s, 2] = r0, r1, r2
                s_tfar[s] = np.float32(tfar)
                s_value[s, 0], s_value[s, 1], s_value[s, 2] = v0, v1, v2
                s_owner[s] = i
                s += 1
        if s > 0 and scene_ptr != 0:
            t_start = now_ns(ts)
            occluded_packets(scene_ptr, cfg.packet_width, s_origin, s_direction, s_tfar, s, s_blocked, words, floats,
                             valid)
            embree_ns += now_ns(ts) - t_start
        elif s > 0:
            s_blocked[:s] = False  # nothing can block a ray in a scene without geometry
        # each path's direct light, its connections summed in j order as the path loop sums them
        q = 0
        for i in range(i0, i1):
            b = i - i0
            rad0, rad1, rad2 = rad[b, 0], rad[b, 1], rad[b, 2]
            if lit[b]:
                tot0, tot1, tot2 = 0.0, 0.0, 0.0
                while q < s and s_owner[q] == i:
                    if not s_blocked[q]:
                        tot0 += s_value[q, 0]
                        tot1 += s_value[q, 1]
                        tot2 += s_value[q, 2]
                    q += 1
                b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
                rad0 += b0 * (tot0 * inv_nd)
                rad1 += b1 * (tot1 * inv_nd)
                rad2 += b2 * (tot2 * inv_nd)
            r = root[i]
            radiance[r, 0], radiance[r, 1], radiance[r, 2] = rad0, rad1, rad2
    counters[C_BACK_FACE] += count_back_face
    counters[C_ESCAPED] += count_escaped
    counters[C_LIGHT_SELECT] += count_light_select
    counters[C_SHADOW] += count_shadow
    counters[C_SHADOW_SKIPPED] += count_shadow_skipped
    timing[0] += embree_ns
    timing[1] += count_shadow + n


__all__ = ["BLOCK", "occluded_packets", "trace_first_hits"]
