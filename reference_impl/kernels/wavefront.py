"""The wavefront engine (``engine = "wavefront"``, and whenever Ni > 1): one bounce of every path of a batch at once,
between batched Embree queries (``integrator._bounce``).

:func:`bounce` takes the closest hits of the current rays and writes the direct-light rays and the next wavefront;
:func:`resolve_shadow` / :func:`resolve_hemisphere` add the direct light once Embree has answered them. Each vertex is
the path engine's vertex (:mod:`.path`), from the same helpers (:mod:`.surface`, :mod:`.vertex`, :mod:`.direct`), so
the two engines give the same bits.
"""

from __future__ import annotations

from numba import njit

from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_HEMI_DIRECT, C_INDIRECT, C_LIGHT_SELECT,
                                           C_ROULETTE, C_SHADOW, C_SHADOW_SKIPPED, CFG_ALLOW_INDIRECT, CFG_ALLOW_NEXT,
                                           CFG_DEPTH, CFG_DIRECT, CFG_EMIT, CFG_HEMI_COSINE, CFG_MUTANTS, CFG_ND,
                                           CFG_NI, CFG_NUM_LIGHTS, CFG_RR, CFG_RR_DEPTH, CFG_SOBOL, CFG_SPP,
                                           CFGF_FIXED_SURVIVAL, CFGF_OFFSET_SCENE, CFGF_SURFACE_PDF,
                                           DIRECT_GLOBAL_AREA, DIRECT_HEMI_COSINE, DIRECT_HEMI_UNIFORM, DIRECT_MIS,
                                           EMIT_NONE, JIT, JIT_INLINE, M_RR_NO_REWEIGHT, RR_OFF)
from reference_impl.kernels.direct import hemisphere_sample, hemisphere_weight, light_sample, shadow_ray
from reference_impl.kernels.rng import INDIRECT_U1, INDIRECT_U2, branch_salt, mix64
from reference_impl.kernels.sobol import first_hit_seeds, pixel_first_hit_seeds, uniform_2d
from reference_impl.kernels.surface import hit_point, offset_origin
from reference_impl.kernels.vertex import continuation, emitted, roulette


@njit(**JIT)
def bounce(state, prim, scene, lights, surfaces, cfg, cfg_f, radiance, counters, hits, rays, out, film_samples):
    """One bounce of the wavefront (integrator._bounce), given the closest hits ``prim`` of the current rays.

    Adds the emission seen at the hits to ``radiance``, draws the Nd direct-light samples of each reflecting hit
    (the rays they need: shadow rays, or closest-hit rays for hemisphere sampling, with what their results are
    multiplied by) and the next wavefront (Russian roulette, Ni branches, hemisphere sampling). The direct light is
    added by :func:`resolve_shadow` / :func:`resolve_hemisphere` once Embree has answered.

    ``state`` and ``out`` are wavefronts (root, key, origin, direction, origin32, direction32, beta, pdf_dir), the
    current one and room for the next (at least Ni rows per row of ``state``). ``hits`` receives the rows of the
    reflecting hits, in order; ``rays`` (owner hit, origin32, direction32, tfar32, value, aux, direction64) the
    direct-light rays of each hit, in sample order, Nd rows per row of ``state``. ``film_samples`` = (pixel, sample,
    seed_key) of the camera samples (rows of ``root``), for the stratified sampler. Returns how many hits,
    direct-light rays and next paths were written.
    """
    root, key, origin, direction, _o32, _d32, beta, pdf_dir = state
    x_root, x_key, x_origin, x_dir, x_o32, x_d32, x_beta, x_pdf = out
    s_owner, s_o32, s_d32, s_tfar, s_value, s_aux, s_dir = rays
    prim_to_tri, tri_normal, tri_v0, corners, emission, light_id, tri_material, two_sided, f_r_table, albedo_max = scene
    light_pmf, light_area = lights[5], lights[6]
    depth = cfg[CFG_DEPTH]
    emit = cfg[CFG_EMIT]
    allow_next = cfg[CFG_ALLOW_NEXT] != 0
    allow_indirect = cfg[CFG_ALLOW_INDIRECT] != 0
    direct = cfg[CFG_DIRECT]
    mis = direct == DIRECT_MIS
    nd = cfg[CFG_ND]
    ni = cfg[CFG_NI]
    hemi_cosine = cfg[CFG_HEMI_COSINE] != 0
    rr = cfg[CFG_RR]
    mutants = cfg[CFG_MUTANTS]
    reweight = (mutants & M_RR_NO_REWEIGHT) == 0
    num_lights = cfg[CFG_NUM_LIGHTS]
    selects = direct != DIRECT_GLOBAL_AREA and num_lights > 1  # each area sample chooses a light
    fixed_survival = cfg_f[CFGF_FIXED_SURVIVAL]
    offset_scene = cfg_f[CFGF_OFFSET_SCENE]
    surface_pdf = cfg_f[CFGF_SURFACE_PDF]
    play_roulette = rr != RR_OFF and depth >= cfg[CFG_RR_DEPTH]
    hemi_direct = direct == DIRECT_HEMI_COSINE or direct == DIRECT_HEMI_UNIFORM
    sob = cfg[CFG_SOBOL] != 0 and depth == 1
    film_pixel, film_sample, seed_key = film_samples
    spp = cfg[CFG_SPP]
    fh = first_hit_seeds(seed_key, 0, 1, 1, 1)
    fh_pixel = -1
    si = 0

    n = len(root)
    m = 0
    s = 0
    n_next = 0
    for i in range(n):
        p = prim[i]
        if p < 0:
            counters[C_ESCAPED] += 1
            continue
        tri = prim_to_tri[p]
        nx0, nx1, nx2 = tri_normal[tri, 0], tri_normal[tri, 1], tri_normal[tri, 2]
        o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
        d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
        t, x0, x1, x2, cos_out = hit_point(o0, o1, o2, d0, d1, d2, nx0, nx1, nx2, tri_v0[tri, 0], tri_v0[tri, 1],
                                           tri_v0[tri, 2])
        front = cos_out > 0
        b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
        r = root[i]
        if emit != EMIT_NONE:
            e0, e1, e2, w = emitted(emit, front, tri, emission, light_id, light_pmf, light_area, nd, t, cos_out,
                                    pdf_dir[i])
            radiance[r, 0] += b0 * e0 * w
            radiance[r, 1] += b1 * e1 * w
            radiance[r, 2] += b2 * e2 * w

        if not allow_next:
            continue
        material = tri_material[tri]
        if not (front or two_sided[material]):
            counters[C_BACK_FACE] += 1
            continue
        if not front:  # the side Theta leaves from
            nx0, nx1, nx2 = -nx0, -nx1, -nx2
        f0, f1, f2 = f_r_table[material, 0], f_r_table[material, 1], f_r_table[material, 2]
        k = key[i]
        if sob:
            fh, fh_pixel, si = pixel_first_hit_seeds(fh, fh_pixel, film_pixel, film_sample, r, seed_key, spp, nd, ni)
        h = m
        hits[h] = i
        m += 1
        ox0, ox1, ox2 = offset_origin(offset_scene, x0, x1, x2, nx0, nx1, nx2)

        # Direct light: the rays of Nd samples, resolved by resolve_shadow / resolve_hemisphere.
        for j in range(nd):
            if hemi_direct:  # a closest-hit ray
                w0, w1, w2, ratio = hemisphere_sample(direct, sob, fh[1], si * nd + j, k, depth, j, nx0, nx1, nx2)
                counters[C_HEMI_DIRECT] += 1
                s_owner[s] = h
                s_o32[s, 0], s_o32[s, 1], s_o32[s, 2] = ox0, ox1, ox2
                s_d32[s, 0], s_d32[s, 1], s_d32[s, 2] = w0, w1, w2
                s_dir[s, 0], s_dir[s, 1], s_dir[s, 2] = w0, w1, w2
                s_value[s, 0], s_value[s, 1], s_value[s, 2] = f0, f1, f2
                s_aux[s] = ratio
                s += 1
                continue
            ltri, y0, y1, y2, pdf_area = light_sample(direct, sob, fh[0], si * nd + j, k, depth, j, lights,
                                                      num_lights, surfaces, corners, surface_pdf, mutants)
            if selects:
                counters[C_LIGHT_SELECT] += 1
            needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = shadow_ray(
                x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2, y0, y1, y2, tri_normal[ltri, 0], tri_normal[ltri, 1],
                tri_normal[ltri, 2], light_id[ltri] >= 0, emission[ltri, 0], emission[ltri, 1], emission[ltri, 2],
                f0, f1, f2, pdf_area, offset_scene, mis, nd, ni, hemi_cosine, mutants)
            if not needed:
                counters[C_SHADOW_SKIPPED] += 1
                continue
            counters[C_SHADOW] += 1
            s_owner[s] = h
            s_o32[s, 0], s_o32[s, 1], s_o32[s, 2] = so0, so1, so2
            s_d32[s, 0], s_d32[s, 1], s_d32[s, 2] = r0, r1, r2
            s_tfar[s] = tfar
            s_value[s, 0], s_value[s, 1], s_value[s, 2] = v0, v1, v2
            s += 1

        # Indirect light (Fig. 5.14), if the next vertex can still add anything.
        if not allow_indirect:
            continue
        if play_roulette:
            alive, b0, b1, b2 = roulette(rr, albedo_max[material], fixed_survival, sob, fh[2], si, k, depth, reweight,
                                         b0, b1, b2)
            if not alive:
                counters[C_ROULETTE] += 1
                continue
        for branch in range(ni):
            kb = k if ni == 1 else mix64(k ^ branch_salt(branch, depth))
            u_a, u_b = uniform_2d(sob, fh[3], si * ni + branch, kb, 0, depth, INDIRECT_U1, INDIRECT_U2)
            carries, w0, w1, w2, c0, c1, c2, next_pdf = continuation(hemi_cosine, mutants, ni, u_a, u_b, nx0, nx1,
                                                                     nx2, f0, f1, f2, b0, b1, b2)
            if not carries:
                counters[C_ROULETTE] += 1
                continue
            counters[C_INDIRECT] += 1
            q = n_next
            n_next += 1
            x_root[q] = r
            x_key[q] = kb
            x_origin[q, 0], x_origin[q, 1], x_origin[q, 2] = ox0, ox1, ox2
            x_o32[q, 0], x_o32[q, 1], x_o32[q, 2] = ox0, ox1, ox2
            x_dir[q, 0], x_dir[q, 1], x_dir[q, 2] = w0, w1, w2
            x_d32[q, 0], x_d32[q, 1], x_d32[q, 2] = w0, w1, w2
            x_beta[q, 0], x_beta[q, 1], x_beta[q, 2] = c0, c1, c2
            x_pdf[q] = next_pdf

    return m, s, n_next


@njit(**JIT)
def resolve_shadow(root, beta, hits, nd, s_owner, s_value, s_hit, total, radiance):
    """Direct light by shadow rays: each hit's Nd samples (value x V, V = 1 where Embree found no blocker,
    ``s_hit < 0``) summed in sample order, averaged, and added to ``radiance`` weighted by the hit's throughput.
    ``hits`` are the rows of (root, beta) that hit; ``total`` is room for one sum per hit."""
    m = len(hits)
    total[:m] = 0.0
    for q in range(len(s_owner)):
        if s_hit[q] < 0:
            h = s_owner[q]
            total[h, 0] += s_value[q, 0]
            total[h, 1] += s_value[q, 1]
            total[h, 2] += s_value[q, 2]
    _add_direct(root, beta, hits, nd, total, radiance)


@njit(**JIT)
def resolve_hemisphere(root, beta, hits, nd, s_owner, s_value, s_aux, s_dir, s_prim, prim_to_tri, tri_normal,
                       emission, total, radiance):
    """Direct light by hemisphere sampling: emission Le of what each ray hit (its front side only), times
    f_r cos / p (``s_value`` f_r, ``s_aux`` cos / p or -1 where p = 0), averaged over the Nd samples."""
    m = len(hits)
    total[:m] = 0.0
    for q in range(len(s_owner)):
        p = s_prim[q]
        if p < 0 or s_aux[q] < 0:
            continue
        tri = prim_to_tri[p]
        weight = hemisphere_weight(s_aux[q], s_dir[q, 0], s_dir[q, 1], s_dir[q, 2], tri_normal[tri, 0],
                                   tri_normal[tri, 1], tri_normal[tri, 2])
        h = s_owner[q]
        total[h, 0] += emission[tri, 0] * s_value[q, 0] * weight
        total[h, 1] += emission[tri, 1] * s_value[q, 1] * weight
        total[h, 2] += emission[tri, 2] * s_value[q, 2] * weight
    _add_direct(root, beta, hits, nd, total, radiance)


@njit(**JIT_INLINE)
def _add_direct(root, beta, hits, nd, total, radiance):
    inv_nd = 1.0 / nd  # exact for Nd = 1, 2, 4, ...
    for h in range(len(hits)):
        i = hits[h]
        r = root[i]
        radiance[r, 0] += beta[i, 0] * (total[h, 0] * inv_nd)
        radiance[r, 1] += beta[i, 1] * (total[h, 1] * inv_nd)
        radiance[r, 2] += beta[i, 2] * (total[h, 2] * inv_nd)
