"""Paths on a Lambertian scene lit by area lights alone, traced as :func:`.path.trace_paths` traces them, bit for
bit, in blocks of :data:`BLOCK` camera paths that go from vertex to vertex together, so that Embree is asked for
their rays in packets: the next vertices' closest hits ``cfg.packet_width`` at a time (``rtcIntersect16``, ``8`` or
``4``), and each vertex's shadow rays likewise (``rtcOccluded16``, ...).

Per block, at each depth, over the block's paths still going (in their order):

1. what depends on nothing at the hit: the Nd light samples (light k with pdf(k) and a point y on it with p(y):
   :func:`.direct.light_choice`, :func:`.direct.area_light_point`) and the BSDF's local direction of the next ray
   (:func:`.bsdf.diffuse_direction`), from the pixel's points at the first hit with the stratified sampler (computed
   ahead here, a pixel at a time), else from the path's hashes. The points and the directions are worked out in
   loops of their own, where one sample's square roots, divisions and polynomials need not wait for another's;
2. what the path loop does at the vertex x before its queries: the emission x shows the ray that found it (the camera
   ray: weight 1; with ``direct = area`` no later one counts), the material step, the next ray (the BSDF's sample
   and Russian roulette, :func:`.path.ray_after_sample`, written into the path's slot), and the Nd light
   connections (Le G f |cos_x| / p through the BSDF door, :func:`.path.connect`), each kept with its shadow ray
   (:func:`.direct.connection_ray`) where it needs one;
3. the block's shadow rays, in the order they were made, as packets of occlusion queries (:func:`occluded_packets`;
   one query per ray where the processor has no packets);
4. per path, in the path loop's order: radiance += beta (the sum of its unblocked connections, in j order) / Nd;
5. the closest hits of the next rays of the paths that go on, as packets (:func:`closest_packets`, Embree's traversal
   for incoherent rays).

A block holds thousands of paths so that its packets stay full at the depths where roulette has ended most of them.
A replay of the recorded rays (:mod:`reference_impl.replay`) sends them as the blocks sent them:
:func:`closest_groups`, :func:`occluded_groups`.

Each path's radiance is summed in the order the path loop sums it, from the same numbers, and a packet answers as
one query per ray does (the same float32 ray, :func:`.queries.packet_lane`), so the image is the path loop's, bit for
bit (tests/reference_impl/test_blocks.py). What the blocks buy: docs/performance.md, "Issue 39: paths in blocks".
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl import embree_c
from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_INDIRECT, C_LIGHT_SELECT, C_ROULETTE,
                                           C_SHADOW, C_SHADOW_SKIPPED, HEMI_UNIFORM, JIT, M_DOUBLE_EMISSION,
                                           M_LIGHT_PDF_IGNORED, RR_OFF, SAMPLER_SOBOL)
from reference_impl.kernels.direct import area_light_point, connection_ray, light_choice, point_connection
from reference_impl.kernels.material import material_at
from reference_impl.kernels.bsdf import diffuse_direction, diffuse_sample
from reference_impl.kernels.path import MAX_VERTICES, connect, ray_after_sample
from reference_impl.kernels.queries import (closest_prim, closest_prims_packets, incoherent_arguments,
                                            intersect_packet, now_ns, occluded, packet_buffer, packet_lane,
                                            packet_rest, sphere_nearest)
from reference_impl.kernels.record import record_camera, record_closest, record_group, record_occluded
from reference_impl.kernels.rng import dim_salt, uniform
from reference_impl.kernels.shading import geometric_frame
from reference_impl.kernels.sobol import (NOTHING_HELD, ahead, held_point, longest_run, pair_point,
                                          path_first_hit_seeds, pixel_run)
from reference_impl.kernels.surface import emission_at, offset_origin, surface_hit
from reference_impl.kernels.warps import dot3
from reference_impl.materials import DIFFUSE, P_TWO_SIDED, ROW_SIZE
from reference_impl.rng import BSDF_U1, BSDF_U2

#: camera paths per block: they go from vertex to vertex together, their rays kept until the block's packets
BLOCK = 4096


@njit(**JIT)
def occluded_packets(scene_ptr, width, origin, direction, tfar, count, blocked, words, floats, valid, spheres=None):
    """Whether something blocks each of the shadow rays 0 .. count - 1 (float64 origins and unit directions, float32
    ``tfar``), ``width`` rays per occlusion query (Embree sets a blocked lane's tfar to -inf), into ``blocked``; and
    the scene's ``spheres`` (None: none) tested on each float64 ray, as :func:`.queries.occluded` tests them, where
    Embree found nothing."""
    if width == 1:
        for s in range(count):
            blocked[s] = occluded(scene_ptr, words, floats, origin[s, 0], origin[s, 1], origin[s, 2], direction[s, 0],
                                  direction[s, 1], direction[s, 2], np.float64(tfar[s]), spheres)
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
    if spheres is not None and spheres.shape[0] > 0:
        for s in range(count):
            if not blocked[s]:
                blocked[s] = sphere_nearest(spheres, origin[s, 0], origin[s, 1], origin[s, 2], direction[s, 0],
                                            direction[s, 1], direction[s, 2], np.float64(tfar[s]))[0] >= 0


@njit(**JIT)
def closest_packets(scene_ptr, width, active, count, origin, direction, prim, words, floats, valid, args, hits,
                    spheres=None, base=0):
    """The closest hits of the rays of slots ``active[0:count]`` (float64 origins and unit directions, sent as float32
    as one query per ray sends them), ``width`` rays per query (one query per ray where ``width`` is 1), into
    ``prim`` by slot (-1: a miss); the scene's ``spheres`` (None: none) tested on each float64 ray, nearer than
    Embree's triangle, as :func:`.queries.closest_prim` tests them (primitive ``base`` + s)."""
    if width == 1:
        for a in range(count):
            b = active[a]
            prim[b] = closest_prim(scene_ptr, words, floats, origin[b, 0], origin[b, 1], origin[b, 2], direction[b, 0],
                                   direction[b, 1], direction[b, 2], spheres, base)
        return
    for a0 in range(0, count, width):
        m = min(width, count - a0)
        for lane in range(m):
            b = active[a0 + lane]
            packet_lane(words, floats, valid, width, lane, origin[b, 0], origin[b, 1], origin[b, 2], direction[b, 0],
                        direction[b, 1], direction[b, 2], np.inf)
        packet_rest(words, floats, valid, width, m)
        intersect_packet(scene_ptr, width, words, floats, valid, m, hits, 0, None, 0, args)
        for lane in range(m):
            b = active[a0 + lane]
            p = hits[lane]
            if spheres is not None and spheres.shape[0] > 0:
                t_max = np.float64(floats[8 * width + lane]) if p >= 0 else np.inf
                sph, _t = sphere_nearest(spheres, origin[b, 0], origin[b, 1], origin[b, 2], direction[b, 0],
                                         direction[b, 1], direction[b, 2], t_max)
                if sph >= 0:
                    p = base + sph
            prim[b] = p


@njit(**JIT)
def shadow_queries(scene_ptr, width, origin, direction, tfar, count, blocked, words, floats, valid, spheres, record,
                   ts):
    """A block's shadow rays 0 .. count - 1 at one depth, as :func:`occluded_packets` asks them, recorded where
    ``record`` is given (:mod:`.record`: each ray and answer, and the call's size); the nanoseconds it took."""
    t_start = now_ns(ts)
    occluded_packets(scene_ptr, width, origin, direction, tfar, count, blocked, words, floats, valid, spheres)
    ns = now_ns(ts) - t_start
    if record is not None:
        for q in range(count):
            record_occluded(record, origin[q, 0], origin[q, 1], origin[q, 2], direction[q, 0], direction[q, 1],
                            direction[q, 2], tfar[q], blocked[q])
        record_group(record, True, count)
    return ns


@njit(**JIT)
def next_queries(scene_ptr, width, active, count, origin, direction, prim, words, floats, valid, args, hits, spheres,
                 base, record, ts):
    """The next vertices of a block's paths that go on (slots ``active[0:count]``), as :func:`closest_packets` asks
    them, recorded where ``record`` is given; the nanoseconds it took."""
    t_start = now_ns(ts)
    closest_packets(scene_ptr, width, active, count, origin, direction, prim, words, floats, valid, args, hits,
                    spheres, base)
    ns = now_ns(ts) - t_start
    if record is not None:
        for a in range(count):
            b = active[a]
            record_closest(record, origin[b, 0], origin[b, 1], origin[b, 2], direction[b, 0], direction[b, 1],
                           direction[b, 2], prim[b])
        record_group(record, False, count)
    return ns


@njit(**JIT)
def closest_groups(scene_ptr, width, origin, direction, sizes, out, spheres, base):
    """The closest hits of recorded rays (float64, in the order the blocks sent them) sent again as they sent them:
    ``sizes[g]`` consecutive rays per call of :func:`closest_packets` (the scene's ``spheres`` tested as there);
    into ``out`` (-1: a miss)."""
    words, floats, valid = packet_buffer()
    args = incoherent_arguments()
    hits = np.empty(embree_c.PACKET, np.int64)
    active = np.arange(len(out))
    a = 0
    for g in range(len(sizes)):
        closest_packets(scene_ptr, width, active[a:], sizes[g], origin, direction, out, words, floats, valid, args,
                        hits, spheres, base)
        a += sizes[g]


@njit(**JIT)
def occluded_groups(scene_ptr, width, origin, direction, tfar, sizes, out, spheres):
    """Whether something blocks each recorded shadow ray (in the order the blocks sent them), sent again as they
    sent them: ``sizes[g]`` consecutive rays per call of :func:`occluded_packets` (the scene's ``spheres`` tested as
    there); into ``out`` (0: blocked, -1: not, as :func:`.queries.occluders` answers)."""
    words, floats, valid = packet_buffer()
    blocked = np.zeros(len(out), np.bool_)
    a = 0
    for g in range(len(sizes)):
        b = a + sizes[g]
        occluded_packets(scene_ptr, width, origin[a:b], direction[a:b], tfar[a:b], sizes[g], blocked[a:b], words,
                         floats, valid, spheres)
        a = b
    for i in range(len(out)):
        out[i] = 0 if blocked[i] else -1


@njit(**JIT)
def trace_blocks(state, scene_ptr, scene, lights, materials, cfg, radiance, counters, timing, film_samples,
                 record=None):
    """Trace every camera path of ``state`` (the wavefront's ``camera_paths`` wrote them) as :func:`.path.trace_paths`
    traces it, on a scene this runs for (``integrator._Context.blocks``: every material diffuse, ``direct = area``,
    area lights alone, no textured light, shading normal, sphere, mask, nested material or light tree):
    each path's radiance written to ``radiance[root]`` (the path loop's sum, which starts at 0: the buffer need not
    be zeroed), the same counters and timing. ``record``: None in a render (compiled out), or buffers that receive
    every query's ray and answer in the order they were sent, and each call's count of packed rays
    (:mod:`.record`, for :mod:`reference_impl.replay`)."""
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
    double_emission = (mutant & M_DOUBLE_EMISSION) != 0
    first_roulette = cfg.rr != RR_OFF and cfg.rr_depth <= 1
    # whether a first hit draws its next ray (the path loop's ``next_ray_drawn``; diffuse: never a delta lobe)
    next_ray_drawn = max_depth == -1 or max_depth >= 3
    film_pixel, film_sample, seed_key = film_samples.pixel, film_samples.sample, film_samples.seed_key
    fh = path_first_hit_seeds(seed_key, 0, 1, 1)
    fh_pixel = -1
    run = longest_run(film_samples) if sobol else 0
    lx, ly = np.empty(run * nd), np.empty(run * nd)
    bx, by = np.empty(run), np.empty(run)
    cx, cy = np.empty(run), np.empty(run)
    held_light, held_bsdf, held_rr = NOTHING_HELD, NOTHING_HELD, NOTHING_HELD
    row = np.empty(ROW_SIZE)
    ts = np.zeros(2, np.int64)
    n = len(root)
    first_prim = np.full(n, -1, np.int32)
    embree_ns = 0
    queries = 0
    if scene_ptr != 0:
        t_start = now_ns(ts)
        closest_prims_packets(scene_ptr, cfg.packet_width, o32, d32, first_prim, None, 0)
        embree_ns += now_ns(ts) - t_start
        if record is not None:
            record_camera(record, o32, d32, first_prim)
    width = cfg.packet_width
    words, floats, valid = packet_buffer()
    args = incoherent_arguments()
    hits = np.empty(embree_c.PACKET, np.int64)
    # the block's paths, by slot: where they are (the ray that finds the next vertex and what it hit), their weight,
    # their radiance so far; the next ray each draws; whether it reached its light connections
    size = min(BLOCK, n)
    active, going_next = np.empty(size, np.int64), np.empty(size, np.int64)
    prim = np.empty(size, np.int64)
    o, d = np.empty((size, 3)), np.empty((size, 3))
    b_beta, rad, eta = np.empty((size, 3)), np.empty((size, 3)), np.empty(size)
    n_beta, lit = np.empty((size, 3)), np.zeros(size, np.bool_)
    # the BSDF's local direction of each path's next ray (its uniforms, its row), and its roulette number (-1: drawn
    # where played)
    f_rr, dir_at = np.empty(size), np.empty(size, np.int64)
    g_u1, g_u2, g_l = np.empty(size), np.empty(size), np.empty((size, 3))
    # the block's shadow rays at one depth, in the order they were made
    rays = size * nd
    s_origin, s_direction = np.empty((rays, 3)), np.empty((rays, 3))
    s_tfar = np.empty(rays, np.float32)
    s_blocked = np.zeros(rays, np.bool_)
    s_value = np.empty((rays, 3))
    s_owner = np.empty(rays, np.int64)
    # the block's light samples at one depth, Nd a path: the triangle y lies in, y, p(y)
    y_tri, y, y_pdf = np.empty(rays, np.int64), np.empty((rays, 3)), np.empty(rays)
    # ... and the choices they are drawn from: their row, light k, its piece, pdf(k), u1, u2
    l_at, l_sel, l_piece = np.empty(rays, np.int64), np.empty(rays, np.int64), np.empty(rays, np.int64)
    l_pdf, l_u1, l_u2 = np.empty(rays), np.empty(rays), np.empty(rays)
    count_back_face = 0
    count_escaped = 0
    count_indirect = 0
    count_light_select = 0
    count_roulette = 0
    count_shadow = 0
    count_shadow_skipped = 0
    for i0 in range(0, n, BLOCK):
        m = min(n, i0 + BLOCK) - i0
        for b in range(m):
            active[b] = b
            prim[b] = first_prim[i0 + b]
            rad[b, 0], rad[b, 1], rad[b, 2] = 0.0, 0.0, 0.0
            eta[b] = 1.0
        depth = 1
        while m > 0:
            sob = sobol and depth == 1
            lights_drawn = max_depth == -1 or depth + 1 <= max_depth
            draws_next = max_depth == -1 or depth + 2 <= max_depth  # the next vertex can add more than direct light
            # 1. the light samples of the paths whose vertex will draw them (and a pixel's first-hit points)
            dn = 0
            ln = 0
            for a in range(m):
                b = active[a]
                i = i0 + b
                si = 0
                if sob:
                    r = root[i]
                    if film_pixel[r] != fh_pixel:  # a pixel's samples come together: its seeds and points once
                        fh_pixel = film_pixel[r]
                        fh = path_first_hit_seeds(seed_key, fh_pixel, cfg.spp, nd)
                        first, m_run = film_sample[r], pixel_run(film_pixel, film_sample, r)
                        held_light = ahead(fh.light, first * nd, m_run * nd, lx, ly, True)
                        held_bsdf = ahead(fh.bsdf, first, m_run, bx, by, next_ray_drawn)
                        held_rr = ahead(fh.lobe_roulette, first, m_run, cx, cy, next_ray_drawn and first_roulette)
                    si = film_sample[r]
                if prim[b] < 0 or not lights_drawn:
                    continue
                # the BSDF's local direction for the next ray, and the roulette's number where it is drawn ahead
                if draws_next:
                    u_rr = -1.0  # drawn by next_ray only where roulette is played
                    if sob:
                        bu1, bu2 = pair_point(held_point(fh.bsdf, bx, by, held_bsdf, si), si)
                        if first_roulette:
                            _lobe, u_rr = pair_point(held_point(fh.lobe_roulette, cx, cy, held_rr, si), si)
                    else:
                        bu1 = uniform(key[i], dim_salt(depth, BSDF_U1, 0))
                        bu2 = uniform(key[i], dim_salt(depth, BSDF_U2, 0))
                    f_rr[b] = u_rr
                    g_u1[dn], g_u2[dn] = bu1, bu2
                    dir_at[b] = dn
                    dn += 1
                for j in range(nd):
                    u_a, u_b = 0.0, 0.0
                    if sob:  # one 2D point: its first coordinate picks the light and the piece too
                        u_a, u_b = pair_point(held_point(fh.light, lx, ly, held_light, si * nd + j), si * nd + j)
                    sel, piece, u1, u2 = light_choice(cfg, lights, sob, u_a, u_b, key[i], depth, j)
                    pdf_select = light_pmf[sel]
                    if mutant & M_LIGHT_PDF_IGNORED:  # mutant "light-pdf-ignored": pdf(y|k) alone
                        pdf_select = 1.0
                    l_at[ln], l_sel[ln], l_piece[ln], l_pdf[ln], l_u1[ln], l_u2[ln] = b * nd + j, sel, piece, \
                        pdf_select, u1, u2
                    ln += 1
            # the points on the lights and the BSDF's local directions, in loops of their own: one path's chains
            # need not wait for another's
            for t in range(ln):
                c = l_at[t]
                y_tri[c], y[c, 0], y[c, 1], y[c, 2], y_pdf[c] = area_light_point(cfg, scene, lights, l_sel[t],
                                                                                 l_piece[t], l_pdf[t], l_u1[t],
                                                                                 l_u2[t])
            for t in range(dn):
                g_l[t, 0], g_l[t, 1], g_l[t, 2] = diffuse_direction(uniform_diffuse, g_u1[t], g_u2[t])
            # 2. each vertex's work before its queries: emission, the material step, the next ray, the connections
            s = 0
            going = 0
            for a in range(m):
                b = active[a]
                i = i0 + b
                lit[b] = False
                p = prim[b]
                if p < 0:
                    count_escaped += 1
                    continue
                k = key[i]
                if depth == 1:  # the camera ray, from the batch's state
                    o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
                    d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
                    b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
                else:
                    o0, o1, o2 = o[b, 0], o[b, 1], o[b, 2]
                    d0, d1, d2 = d[b, 0], d[b, 1], d[b, 2]
                    b0, b1, b2 = b_beta[b, 0], b_beta[b, 1], b_beta[b, 2]
                hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
                tri, cos_out = hit.tri, hit.cos_out
                if depth == 1 or double_emission:  # what the camera ray finds, no light sample could have found
                    light = light_id[tri]
                    if light >= 0 and cos_out > 0:
                        le0, le1, le2 = emission_at(scene, None, tri, hit.x0, hit.x1, hit.x2, mutant)
                        rad[b, 0] += b0 * le0
                        rad[b, 1] += b1 * le1
                        rad[b, 2] += b2 * le2
                if not lights_drawn or depth >= MAX_VERTICES:
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
                # the next ray (drawn before the connections, as the path loop draws it on a Lambertian scene)
                if draws_next:
                    t = dir_at[b]
                    sample = diffuse_sample(row, uniform_diffuse, lo2, g_l[t, 0], g_l[t, 1], g_l[t, 2])
                    (go_on, was_cut, w0, w1, w2, m0, m1, m2, _pn0, _pn1, _pn2, nb0, nb1, nb2, eta2, _pdf,
                     _delta) = ray_after_sample(cfg, kind, row, uniform_diffuse, True, sample, f_rr[b], k, depth,
                                                (lo0, lo1, lo2), (b0, b1, b2), eta[b], sf, (nx0, nx1, nx2), side,
                                                (x0, x1, x2), (ox0, ox1, ox2))
                    count_roulette += was_cut
                    if go_on:  # the path's next ray in its slot, the slot the next depth's active one number ``going``
                        count_indirect += 1
                        d[b, 0], d[b, 1], d[b, 2] = w0, w1, w2
                        o[b, 0], o[b, 1], o[b, 2] = m0, m1, m2
                        n_beta[b, 0], n_beta[b, 1], n_beta[b, 2] = nb0, nb1, nb2
                        eta[b] = eta2
                        going_next[going] = b
                        going += 1
                for j in range(nd):
                    if num_lights > 1:
                        count_light_select += 1
                    c = b * nd + j
                    conn = point_connection(cfg, scene, None, y_tri[c], y[c, 0], y[c, 1], y[c, 2], y_pdf[c], x0, x1,
                                            x2)
                    needed, cos_x, v0, v1, v2 = connect(mutant, kind, row, uniform_diffuse, False, conn, False, side,
                                                        nx0, nx1, nx2, sf, lo0, lo1, lo2, None)
                    if not needed:
                        count_shadow_skipped += 1
                        continue
                    count_shadow += 1
                    so0, so1, so2, r0, r1, r2, tfar = connection_ray(cfg, conn, cos_x, False, x0, x1, x2, nx0, nx1,
                                                                     nx2, ox0, ox1, ox2)
                    s_origin[s, 0], s_origin[s, 1], s_origin[s, 2] = so0, so1, so2
                    s_direction[s, 0], s_direction[s, 1], s_direction[s, 2] = r0, r1, r2
                    s_tfar[s] = np.float32(tfar)
                    s_value[s, 0], s_value[s, 1], s_value[s, 2] = v0, v1, v2
                    s_owner[s] = b
                    s += 1
            # 3. the shadow rays
            if s > 0 and scene_ptr != 0:
                embree_ns += shadow_queries(scene_ptr, width, s_origin, s_direction, s_tfar, s, s_blocked, words,
                                            floats, valid, None, record, ts)
            # 4. each path's direct light, its connections summed in j order as the path loop sums them (with its
            # throughput at this vertex: b_beta; n_beta holds the one past it)
            q = 0
            for a in range(m):
                b = active[a]
                if lit[b]:
                    tot0, tot1, tot2 = 0.0, 0.0, 0.0
                    while q < s and s_owner[q] == b:
                        if scene_ptr == 0 or not s_blocked[q]:
                            tot0 += s_value[q, 0]
                            tot1 += s_value[q, 1]
                            tot2 += s_value[q, 2]
                        q += 1
                    if depth == 1:
                        b0, b1, b2 = beta[i0 + b, 0], beta[i0 + b, 1], beta[i0 + b, 2]
                    else:
                        b0, b1, b2 = b_beta[b, 0], b_beta[b, 1], b_beta[b, 2]
                    rad[b, 0] += b0 * (tot0 * inv_nd)
                    rad[b, 1] += b1 * (tot1 * inv_nd)
                    rad[b, 2] += b2 * (tot2 * inv_nd)
            # the paths that go on, with their throughput past this vertex
            m = going
            active, going_next = going_next, active
            b_beta, n_beta = n_beta, b_beta
            queries += s
            # 5. the next vertices
            if m > 0:
                if scene_ptr != 0:
                    embree_ns += next_queries(scene_ptr, width, active, m, o, d, prim, words, floats, valid, args,
                                              hits, None, 0, record, ts)
                    queries += m
                else:
                    for a in range(m):
                        prim[active[a]] = -1
            depth += 1
        for b in range(min(n, i0 + BLOCK) - i0):
            r = root[i0 + b]
            radiance[r, 0], radiance[r, 1], radiance[r, 2] = rad[b, 0], rad[b, 1], rad[b, 2]
    counters[C_BACK_FACE] += count_back_face
    counters[C_ESCAPED] += count_escaped
    counters[C_INDIRECT] += count_indirect
    counters[C_LIGHT_SELECT] += count_light_select
    counters[C_ROULETTE] += count_roulette
    counters[C_SHADOW] += count_shadow
    counters[C_SHADOW_SKIPPED] += count_shadow_skipped
    timing[0] += embree_ns
    timing[1] += queries + n


__all__ = ["BLOCK", "closest_groups", "closest_packets", "next_queries", "occluded_groups", "occluded_packets",
           "shadow_queries", "trace_blocks"]
