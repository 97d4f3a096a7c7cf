"""The paths of a scene with a material that is not diffuse, traced as :func:`.path.trace_paths` traces them, bit for
bit, in blocks of :data:`.blocks.BLOCK` camera paths that go from vertex to vertex together, so that Embree is asked
for their rays in packets (:func:`.blocks.closest_packets`, :func:`.blocks.occluded_packets`), as :mod:`.blocks`
does on a Lambertian scene lit by area lights alone (which it draws its light samples for ahead).

The scenes (``integrator._Context.path_blocks``): every BSDF kind, direct light ``area``, ``mis`` or ``bsdf``, area
lights (spheres, textured ones, a light tree), emitters that are not surfaces (point, spot, directional lights, an
environment), shading normals; not masks or nested materials, whose holes and choices the path loop resolves with
queries of its own. (The kernel also traces a Lambertian scene as the path loop does, ``other_kinds`` None; the
integrator leaves those to the path loop, whose hemisphere and global-area strategies they also run.) Per block, at
each depth, over the block's paths still going (in their order):

1. what the path loop does at the vertex x before its queries (the same functions): the emission x shows the ray
   that found it, or the environment an escaping ray sees (weighted with ``mis`` by the power heuristic against the
   light samples' density at the previous vertex), the material step and the shading frame, the Nd light
   connections through the BSDF door and, with ``direct = bsdf``, the delta emitters' own samples (each kept with
   its shadow ray where it needs one), and the next ray (the BSDF's sample and Russian roulette, written into the
   path's slot with what the next vertex's MIS weight needs: the sample's pdf, whether it was off a delta lobe,
   x itself, N on the side the ray left and, for the light tree, N at x). The stratified sampler's points of a
   pixel's first hits are computed ahead for the pixel's run of samples, as the path loop computes them;
2. the block's shadow rays, in the order they were made, as packets of occlusion queries;
3. per path, in the path loop's order: radiance += beta (the sum of its unblocked light samples, in j order) / Nd,
   then += beta (the sum of its unblocked own samples);
4. the closest hits of the next rays of the paths that go on, as packets.

Each path's radiance is summed in the order the path loop sums it, from the same numbers; a packet answers as one
query per ray does, the spheres tested on the same float64 rays; so the image is the path loop's, bit for bit
(tests/reference_impl/test_path_blocks.py). What the blocks buy: docs/performance.md, "Issue 39: the path loop's
scenes in blocks, and the replay in the render's packets".
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl import embree_c
from reference_impl.kernels.blocks import BLOCK, next_queries, shadow_queries
from reference_impl.kernels.bsdf import chooses_lobe, is_delta
from reference_impl.emitters import DIRECTIONAL, POINT, SPOT
from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_INDIRECT, C_LIGHT_SELECT, C_ROULETTE,
                                           C_SHADOW, C_SHADOW_SKIPPED, DIRECT_BSDF, DIRECT_MIS, HEMI_UNIFORM, JIT,
                                           M_DOUBLE_EMISSION, M_LIGHT_PDF_IGNORED, M_SHADING_NORMAL_SIDE,
                                           RR_OFF, SAMPLER_SOBOL)
from reference_impl.kernels.direct import (connection_ray, emission_weight, emitter_connection, light_choice,
                                           light_connection, power_weight, tree_choice)
from reference_impl.kernels.emitters import env_light_pdf, env_radiance
from reference_impl.kernels.material import material_at
from reference_impl.kernels.path import MAX_VERTICES, connect, next_ray
from reference_impl.kernels.queries import closest_prims_packets, incoherent_arguments, now_ns, packet_buffer
from reference_impl.kernels.record import record_camera
from reference_impl.kernels.rng import dim_salt, uniform
from reference_impl.kernels.shading import geometric_frame, shading_frame, uv_aligned
from reference_impl.kernels.sobol import (NOTHING_HELD, PathFirstHitPairs, ahead, held_point, longest_run,
                                          pair_point, path_first_hit_seeds, pixel_run)
from reference_impl.kernels.surface import emission_at, offset_origin, surface_hit
from reference_impl.kernels.warps import dot3
from reference_impl.materials import (DIELECTRIC, DIFFUSE, P_ANISOTROPIC, P_METALLIC, P_SPEC_TRANS, P_TWO_SIDED,
                                      PRINCIPLED, ROUGHDIELECTRIC, ROW_SIZE, THINDIELECTRIC)
from reference_impl.rng import BSDF_LOBE, BSDF_U1, BSDF_U2, COMPLEMENT_U1, COMPLEMENT_U2


@njit(**JIT)
def trace_path_blocks(state, scene_ptr, scene, lights, materials, cfg, radiance, counters, timing, film_samples,
                      emitters, other_kinds, textures=None, shading=None, spheres=None, later=None, tree=None,
                      record=None):
    """Trace every camera path of ``state`` (the wavefront's ``camera_paths`` wrote them) as :func:`.path.trace_paths`
    traces it, on a scene this runs for (module docstring): each path's radiance written to ``radiance[root]`` (the
    path loop's sum, which starts at 0: the buffer need not be zeroed), the same counters and timing. ``emitters``,
    ``other_kinds``, ``textures``, ``shading``, ``spheres``, ``later``, ``tree`` as :func:`.path.trace_paths` takes
    them (None compiles their branches out); ``record`` as :func:`.blocks.trace_blocks` takes it."""
    root, key, origin, direction, o32, d32, beta, _pdf_dir, _env_pdf = state
    light_id = scene.light_id
    sphere_base = scene.prim_to_tri.shape[0] - scene.sphere.shape[0]
    light_pmf = lights.pmf
    nd = cfg.shadow_rays
    inv_nd = 1.0 / nd
    direct = cfg.direct
    mutant = cfg.mutant
    max_depth = cfg.max_depth
    num_lights = cfg.num_lights
    mis = direct == DIRECT_MIS
    light_points = direct != DIRECT_BSDF  # area or mis: light k with pdf(k), then a point on it
    double_emission = (mutant & M_DOUBLE_EMISSION) != 0
    finds_emission = mis or direct == DIRECT_BSDF
    # the delta emitters, each with its own sample once per hit, where the strategy (bsdf) cannot find them
    own = 0
    if emitters is not None:
        if direct == DIRECT_BSDF:
            own = len(emitters.kind)
    uniform_diffuse = cfg.hemisphere == HEMI_UNIFORM
    sobol = cfg.sampler == SAMPLER_SOBOL
    film_pixel, film_sample, seed_key = film_samples.pixel, film_samples.sample, film_samples.seed_key
    fh = path_first_hit_seeds(seed_key, 0, 1, 1)
    fh_pixel = -1
    si = 0
    run = longest_run(film_samples) * nd if sobol else 0
    lx, ly = np.empty(run), np.empty(run)
    bx, by = np.empty(run), np.empty(run)
    cx, cy = np.empty(run), np.empty(run)
    held = PathFirstHitPairs(NOTHING_HELD, NOTHING_HELD, NOTHING_HELD, NOTHING_HELD)
    next_ray_drawn = finds_emission or max_depth == -1 or max_depth >= 3
    first_roulette = cfg.rr != RR_OFF and cfg.rr_depth <= 1
    row = np.empty(ROW_SIZE)
    ts = np.zeros(2, np.int64)
    n = len(root)
    first_prim = np.full(n, -1, np.int32)
    embree_ns = 0
    queries = 0
    if scene_ptr != 0:
        t_start = now_ns(ts)
        closest_prims_packets(scene_ptr, cfg.packet_width, o32, d32, first_prim, spheres, sphere_base)
        embree_ns += now_ns(ts) - t_start
        if record is not None:
            record_camera(record, o32, d32, first_prim)
    width = cfg.packet_width
    words, floats, valid = packet_buffer()
    args = incoherent_arguments()
    hits = np.empty(embree_c.PACKET, np.int64)
    # the block's paths, by slot: the ray that finds the next vertex and what it hit, the throughput (b_beta at this
    # vertex, n_beta past it), the radiance so far, eta^2, whether it reached its light connections, and what the
    # next vertex's MIS weight needs (the ray's pdf, whether it was off a delta lobe, the vertex it left, N there)
    size = min(BLOCK, n)
    active, going_next = np.empty(size, np.int64), np.empty(size, np.int64)
    prim = np.empty(size, np.int64)
    o, d = np.empty((size, 3)), np.empty((size, 3))
    b_beta, n_beta, rad = np.empty((size, 3)), np.empty((size, 3)), np.empty((size, 3))
    eta, lit = np.empty(size), np.zeros(size, np.bool_)
    prev_delta, prev_pdf = np.empty(size, np.bool_), np.empty(size)
    px, qn, pn = np.empty((size, 3)), np.empty((size, 3)), np.empty((size, 3))
    # the block's shadow rays at one depth, in the order they were made
    rays = size * (nd + own)
    s_origin, s_direction = np.empty((rays, 3)), np.empty((rays, 3))
    s_own = np.zeros(rays, np.bool_)  # an emitter's own sample (summed apart from the light samples)
    s_tfar = np.empty(rays, np.float32)
    s_blocked = np.zeros(rays, np.bool_)
    s_value = np.empty((rays, 3))
    s_owner = np.empty(rays, np.int64)
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
            prev_delta[b] = True  # the camera ray: what it finds, no light sample could have found
            prev_pdf[b] = 0.0
            px[b, 0], px[b, 1], px[b, 2] = 0.0, 0.0, 0.0
            qn[b, 0], qn[b, 1], qn[b, 2] = 0.0, 0.0, 0.0
            pn[b, 0], pn[b, 1], pn[b, 2] = 0.0, 0.0, 1.0  # N on the side the ray left (env_light_pdf)
        depth = 1
        while m > 0:
            sob = sobol and depth == 1
            # 1. each vertex's work before its queries: emission, the material step, the connections, the next ray
            s = 0
            going = 0
            for a in range(m):
                b = active[a]
                i = i0 + b
                r = root[i]
                k = key[i]
                lit[b] = False
                if sob:
                    if film_pixel[r] != fh_pixel:  # a pixel's samples come together: its seeds and points once
                        fh_pixel = film_pixel[r]
                        fh = path_first_hit_seeds(seed_key, fh_pixel, cfg.spp, nd)
                        first, m_run = film_sample[r], pixel_run(film_pixel, film_sample, r)
                        held = PathFirstHitPairs(ahead(fh.light, first * nd, m_run * nd, lx, ly, True), NOTHING_HELD,
                                                 ahead(fh.bsdf, first, m_run, bx, by, next_ray_drawn),
                                                 ahead(fh.lobe_roulette, first, m_run, cx, cy, next_ray_drawn))
                    si = film_sample[r]
                p = prim[b]
                if p < 0 and emitters is None:
                    count_escaped += 1
                    continue
                if depth == 1:  # the camera ray, from the batch's state
                    o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
                    d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
                    b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
                else:
                    o0, o1, o2 = o[b, 0], o[b, 1], o[b, 2]
                    d0, d1, d2 = d[b, 0], d[b, 1], d[b, 2]
                    b0, b1, b2 = b_beta[b, 0], b_beta[b, 1], b_beta[b, 2]
                was_delta = prev_delta[b]
                counts = was_delta or finds_emission or double_emission  # emission found here counts
                weighted = mis and not (was_delta or double_emission)  # ... with the MIS weight
                if p < 0:
                    count_escaped += 1
                    if emitters is not None:
                        if cfg.env_light >= 0 and counts:  # the environment, seen by the escaping ray
                            e0, e1, e2 = env_radiance(cfg, emitters, d0, d1, d2)
                            w = 1.0
                            if weighted:
                                p_env = env_light_pdf(cfg, lights, emitters, d0, d1, d2, pn[b, 0], pn[b, 1], pn[b, 2])
                                w = power_weight(mutant, prev_pdf[b], p_env, False) if p_env > 0 else 1.0
                            rad[b, 0] += b0 * e0 * w
                            rad[b, 1] += b1 * e1 * w
                            rad[b, 2] += b2 * e2 * w
                    continue
                hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
                tri, t, cos_out = hit.tri, hit.t, hit.cos_out
                if counts:
                    light = light_id[tri]
                    if light >= 0 and cos_out > 0:
                        w = 1.0
                        if weighted:  # pdf(k) (the tree's at the vertex the ray left) and the light's density
                            w = emission_weight(lights, tree, light, nd, prev_pdf[b], (px[b, 0], px[b, 1], px[b, 2]),
                                                (qn[b, 0], qn[b, 1], qn[b, 2]), hit, t, cos_out, mutant)
                        le0, le1, le2 = emission_at(scene, textures, tri, hit.x0, hit.x1, hit.x2, mutant)
                        rad[b, 0] += b0 * le0 * w
                        rad[b, 1] += b1 * le1 * w
                        rad[b, 2] += b2 * le2 * w
                if not (max_depth == -1 or depth + 1 <= max_depth) or depth >= MAX_VERTICES:
                    continue
                kind = material_at(materials, hit, row, mutant)  # the material step: the BSDF's kind and parameters
                if other_kinds is None:
                    kind = DIFFUSE  # what the table says, known to the compiler
                transmits = kind == DIELECTRIC or kind == ROUGHDIELECTRIC or kind == THINDIELECTRIC
                if kind == PRINCIPLED:  # light crosses it where its transmission lobe has a weight at x
                    transmits = (1.0 - row[P_METALLIC]) * row[P_SPEC_TRANS] > 0
                lobed = chooses_lobe(kind, transmits)
                if not (cos_out > 0 or row[P_TWO_SIDED] != 0 or transmits):
                    count_back_face += 1  # the back of a one-sided surface: black
                    continue
                x0, x1, x2 = hit.x0, hit.x1, hit.x2
                nx0, nx1, nx2 = hit.n0, hit.n1, hit.n2
                side = 1.0 if cos_out > 0 else -1.0  # the side of wo
                ns0, ns1, ns2 = side * nx0, side * nx1, side * nx2
                ox0, ox1, ox2 = offset_origin(cfg.offset_scene, x0, x1, x2, ns0, ns1, ns2)
                wo0, wo1, wo2 = -d0, -d1, -d2
                if shading is None:
                    sf = geometric_frame(hit)
                else:
                    sf = shading_frame(scene, materials, hit, row, wo0, wo1, wo2, mutant)
                    if kind == PRINCIPLED and row[P_ANISOTROPIC] != 0.0:  # its lobe's axes along dp/du, n x dp/du
                        sf = uv_aligned(scene, hit, sf)
                lo0, lo1 = dot3(sf.s0, sf.s1, sf.s2, wo0, wo1, wo2), dot3(sf.t0, sf.t1, sf.t2, wo0, wo1, wo2)
                lo2 = dot3(sf.n0, sf.n1, sf.n2, wo0, wo1, wo2) if sf.differs else cos_out
                delta_bsdf = is_delta(kind)
                # Direct light (none at a delta BSDF): Nd connections, each with its shadow ray
                if not delta_bsdf:
                    lit[b] = True
                    front_only = not transmits and not (sf.differs and (mutant & M_SHADING_NORMAL_SIDE) != 0)
                    points = nd if light_points else 0
                    for j in range(points + own):
                        if j >= points:  # an emitter's own sample (pdf(k) = 1): the delta lights alone
                            if emitters is None:
                                continue
                            e = j - points
                            ekind = emitters.kind[e]
                            if not (ekind == POINT or ekind == SPOT or ekind == DIRECTIONAL):
                                continue
                            u1 = uniform(k, dim_salt(depth, COMPLEMENT_U1, e))
                            u2 = uniform(k, dim_salt(depth, COMPLEMENT_U2, e))
                            conn = emitter_connection(cfg, emitters, e, 1.0, u1, u2, x0, x1, x2, ns0, ns1, ns2,
                                                      front_only)
                        else:
                            u_a, u_b = 0.0, 0.0
                            if sob:  # one 2D point: its first coordinate picks the light and the piece too
                                u_a, u_b = pair_point(held_point(fh.light, lx, ly, held.light, si * nd + j),
                                                      si * nd + j)
                            if tree is not None:  # pdf(k | x) from the light tree (kernels/light_tree.py)
                                sel, pdf_select, piece, u1, u2 = tree_choice(cfg, lights, tree, sob, u_a, u_b, k,
                                                                             depth, j, x0, x1, x2, nx0, nx1, nx2,
                                                                             mutant)
                                if sel < 0:  # nothing in the tree can light x
                                    continue
                            else:
                                sel, piece, u1, u2 = light_choice(cfg, lights, sob, u_a, u_b, k, depth, j)
                                pdf_select = light_pmf[sel]
                        if j < points:
                            if num_lights > 1:
                                count_light_select += 1
                            if mutant & M_LIGHT_PDF_IGNORED:  # mutant "light-pdf-ignored": pdf(y|k) alone
                                pdf_select = 1.0
                            conn = light_connection(cfg, scene, textures, lights, emitters, sel, piece, pdf_select, u1,
                                                    u2, x0, x1, x2, ns0, ns1, ns2, front_only)
                        needed, cos_x, v0, v1, v2 = connect(mutant, kind, row, uniform_diffuse, mis and j < points,
                                                            conn, transmits, side, nx0, nx1, nx2, sf, lo0, lo1, lo2,
                                                            later)
                        if not needed:
                            count_shadow_skipped += 1
                            continue
                        count_shadow += 1
                        so0, so1, so2, r0, r1, r2, tfar = connection_ray(cfg, conn, cos_x, not front_only, x0, x1, x2,
                                                                         nx0, nx1, nx2, ox0, ox1, ox2)
                        s_origin[s, 0], s_origin[s, 1], s_origin[s, 2] = so0, so1, so2
                        s_direction[s, 0], s_direction[s, 1], s_direction[s, 2] = r0, r1, r2
                        s_tfar[s] = np.float32(tfar)
                        s_value[s, 0], s_value[s, 1], s_value[s, 2] = v0, v1, v2
                        s_owner[s] = b
                        s_own[s] = j >= points
                        s += 1
                # The next ray, sampled from the BSDF, then Russian roulette, where the next vertex can add more than
                # direct light (max_depth) or the BSDF has a delta lobe
                wanted = finds_emission or max_depth == -1 or depth + 2 <= max_depth
                if not (wanted or delta_bsdf):
                    continue
                if sob:
                    bu1, bu2 = pair_point(held_point(fh.bsdf, bx, by, held.bsdf, si), si)
                    u_lobe, u_rr = 0.0, -1.0
                    if lobed or first_roulette:  # only they read the pair
                        u_lobe, u_rr = pair_point(held_point(fh.lobe_roulette, cx, cy, held.lobe_roulette, si), si)
                else:
                    u_lobe = uniform(k, dim_salt(depth, BSDF_LOBE, 0)) if lobed else 0.0  # only they read it
                    bu1 = uniform(k, dim_salt(depth, BSDF_U1, 0))
                    bu2 = uniform(k, dim_salt(depth, BSDF_U2, 0))
                    u_rr = -1.0  # drawn by next_ray only where roulette is played
                (go_on, cut, w0, w1, w2, m0, m1, m2, pn0, pn1, pn2, nb0, nb1, nb2, eta2, pdf,
                 delta) = next_ray(cfg, kind, row, uniform_diffuse, wanted, u_lobe, bu1, bu2, u_rr, k, depth,
                                   (lo0, lo1, lo2), (b0, b1, b2), eta[b], sf, (nx0, nx1, nx2), side, (x0, x1, x2),
                                   (ox0, ox1, ox2), later)
                count_roulette += cut
                if go_on:  # the path's next ray in its slot, the slot the next depth's active one number ``going``
                    count_indirect += 1
                    d[b, 0], d[b, 1], d[b, 2] = w0, w1, w2
                    o[b, 0], o[b, 1], o[b, 2] = m0, m1, m2
                    n_beta[b, 0], n_beta[b, 1], n_beta[b, 2] = nb0, nb1, nb2
                    eta[b] = eta2
                    prev_delta[b] = delta
                    prev_pdf[b] = pdf
                    px[b, 0], px[b, 1], px[b, 2] = x0, x1, x2
                    if emitters is not None:
                        pn[b, 0], pn[b, 1], pn[b, 2] = pn0, pn1, pn2
                    if tree is not None:
                        qn[b, 0], qn[b, 1], qn[b, 2] = nx0, nx1, nx2
                    going_next[going] = b
                    going += 1
            # 2. the shadow rays
            if s > 0 and scene_ptr != 0:
                embree_ns += shadow_queries(scene_ptr, width, s_origin, s_direction, s_tfar, s, s_blocked, words,
                                            floats, valid, spheres, record, ts)
            # 3. each path's direct light, its connections summed in j order as the path loop sums them (with its
            # throughput at this vertex: b_beta; n_beta holds the one past it)
            q = 0
            for a in range(m):
                b = active[a]
                if lit[b]:
                    tot0, tot1, tot2 = 0.0, 0.0, 0.0
                    ct0, ct1, ct2 = 0.0, 0.0, 0.0
                    while q < s and s_owner[q] == b:
                        if scene_ptr == 0 or not s_blocked[q]:
                            if own > 0 and s_own[q]:
                                ct0 += s_value[q, 0]
                                ct1 += s_value[q, 1]
                                ct2 += s_value[q, 2]
                            else:
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
                    if own > 0:
                        rad[b, 0] += b0 * ct0
                        rad[b, 1] += b1 * ct1
                        rad[b, 2] += b2 * ct2
            # the paths that go on, with their throughput past this vertex
            m = going
            active, going_next = going_next, active
            b_beta, n_beta = n_beta, b_beta
            queries += s
            # 4. the next vertices
            if m > 0:
                if scene_ptr != 0:
                    embree_ns += next_queries(scene_ptr, width, active, m, o, d, prim, words, floats, valid, args,
                                              hits, spheres, sphere_base, record, ts)
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


__all__ = ["trace_path_blocks"]
