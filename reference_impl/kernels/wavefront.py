"""The wavefront engine (``engine = "wavefront"``, and whenever Ni > 1): one bounce of every path of a batch at once,
between batched Embree queries (``integrator._bounce``).

:func:`bounce` takes the closest hits of the current rays and writes the direct-light rays and the next wavefront;
:func:`resolve_shadow` / :func:`resolve_hemisphere` add the direct light once Embree has answered them.
"""

from __future__ import annotations

import math

from numba import njit

from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_HEMI_DIRECT, C_INDIRECT, C_LIGHT_SELECT, C_ROULETTE,
                                           C_SHADOW, C_SHADOW_SKIPPED, CFG_ALLOW_INDIRECT, CFG_ALLOW_NEXT, CFG_DEPTH,
                                           CFG_DIRECT, CFG_EMIT, CFG_HEMI_COSINE, CFG_MUTANTS, CFG_ND, CFG_NI,
                                           CFG_NUM_LIGHTS, CFG_RR, CFG_RR_DEPTH, CFG_SOBOL, CFG_SPP, CFGF_FIXED_SURVIVAL,
                                           CFGF_OFFSET_SCENE, CFGF_SURFACE_PDF, DIRECT_GLOBAL_AREA, DIRECT_HEMI_COSINE,
                                           DIRECT_HEMI_UNIFORM, DIRECT_MIS, EMIT_ALL, EMIT_NONE, JIT, JIT_INLINE,
                                           M_COSINE_PDF_PI, M_LIGHT_PDF_IGNORED, M_NO_COSINE, M_NO_RAY_OFFSET,
                                           M_RR_NO_REWEIGHT, RR_ALBEDO, RR_OFF)
from reference_impl.kernels.light_sampling import (sample_light_point, sample_surface_point, split_light_uniform,
                                                   split_surface_uniform)
from reference_impl.kernels.rng import (DIRECT_DIR_U1, DIRECT_DIR_U2, INDIRECT_U1, INDIRECT_U2, LIGHT_SELECT,
                                        LIGHT_TRIANGLE, LIGHT_U1, LIGHT_U2, ROULETTE, branch_salt, dim_salt, mix64,
                                        uniform)
from reference_impl.kernels.sobol import first_hit_seeds, sobol_point, uniform_2d
from reference_impl.kernels.surface import origin_offset, shadow_t_max
from reference_impl.kernels.warps import PI, dot3, hemisphere_pdf, sample_hemisphere


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
    nd = cfg[CFG_ND]
    ni = cfg[CFG_NI]
    hemi_cosine = cfg[CFG_HEMI_COSINE] != 0
    rr = cfg[CFG_RR]
    mutants = cfg[CFG_MUTANTS]
    num_lights = cfg[CFG_NUM_LIGHTS]
    fixed_survival = cfg_f[CFGF_FIXED_SURVIVAL]
    offset_scene = cfg_f[CFGF_OFFSET_SCENE]
    surface_pdf = cfg_f[CFGF_SURFACE_PDF]
    no_cosine = (mutants & M_NO_COSINE) != 0
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

    salt_rr = dim_salt(depth, ROULETTE, 0)
    salt_u1 = dim_salt(depth, INDIRECT_U1, 0)
    salt_u2 = dim_salt(depth, INDIRECT_U2, 0)

    for i in range(n):
        p = prim[i]
        if p < 0:
            counters[C_ESCAPED] += 1
            continue
        tri = prim_to_tri[p]
        nx0, nx1, nx2 = tri_normal[tri, 0], tri_normal[tri, 1], tri_normal[tri, 2]
        o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
        d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
        # Intersector.closest_hit: t recomputed in float64 from the triangle's plane.
        denom = dot3(d0, d1, d2, nx0, nx1, nx2)
        t = dot3(tri_v0[tri, 0] - o0, tri_v0[tri, 1] - o1, tri_v0[tri, 2] - o2, nx0, nx1, nx2) / denom
        if not (math.isfinite(t) and t > 0):
            t = 0.0
        x0, x1, x2 = o0 + t * d0, o1 + t * d1, o2 + t * d2
        cos_out = -dot3(d0, d1, d2, nx0, nx1, nx2)
        front = cos_out > 0
        b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
        r = root[i]

        # Emission Le(x -> Theta) (integrator._bounce and _mis_weight_hemisphere).
        if emit != EMIT_NONE:
            fr = 1.0 if front else 0.0
            e0, e1, e2 = emission[tri, 0] * fr, emission[tri, 1] * fr, emission[tri, 2] * fr
            if emit == EMIT_ALL:
                radiance[r, 0] += b0 * e0
                radiance[r, 1] += b1 * e1
                radiance[r, 2] += b2 * e2
            else:
                light = light_id[tri]
                w = 0.0
                if light >= 0 and cos_out > 0:
                    p_light = nd * (light_pmf[light] / light_area[light]) * (t * t) / cos_out
                    p_hemi = pdf_dir[i]
                    w = p_hemi * p_hemi / (p_hemi * p_hemi + p_light * p_light)
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
            if film_pixel[r] != fh_pixel:
                fh_pixel = film_pixel[r]
                fh = first_hit_seeds(seed_key, fh_pixel, spp, nd, ni)
            si = film_sample[r]
        h = m
        hits[h] = i
        m += 1
        off_x = origin_offset(offset_scene, x0, x1, x2)
        ox0, ox1, ox2 = x0 + off_x * nx0, x1 + off_x * nx1, x2 + off_x * nx2  # offset_origin(x, normal, ...)

        # Direct light: Nd samples (integrator._direct_light and the one-sample estimators).
        for j in range(nd):
            if hemi_direct:  # _direct_hemisphere_sample: a closest-hit ray, resolved in resolve_hemisphere
                u_a, u_b = uniform_2d(sob, fh[1], si * nd + j, k, j, depth, DIRECT_DIR_U1, DIRECT_DIR_U2)
                w0, w1, w2, cos_theta, pdf = sample_hemisphere(direct == DIRECT_HEMI_COSINE, u_a, u_b, nx0, nx1, nx2)
                counters[C_HEMI_DIRECT] += 1
                s_owner[s] = h
                s_o32[s, 0], s_o32[s, 1], s_o32[s, 2] = ox0, ox1, ox2
                s_d32[s, 0], s_d32[s, 1], s_d32[s, 2] = w0, w1, w2
                s_dir[s, 0], s_dir[s, 1], s_dir[s, 2] = w0, w1, w2
                s_value[s, 0], s_value[s, 1], s_value[s, 2] = f0, f1, f2
                s_aux[s] = cos_theta / pdf if pdf > 0 else -1.0
                s += 1
                continue
            # The stratified sampler draws one 2D point per light sample and reuses its first coordinate for the
            # discrete choices (lights.LightSampler.split_uniform); independent numbers need no reuse.
            if sob:
                u_a, u_b = sobol_point(fh[0], si * nd + j)
            else:
                u_a, u_b = uniform(k, dim_salt(depth, LIGHT_U1, j)), uniform(k, dim_salt(depth, LIGHT_U2, j))
            if direct == DIRECT_GLOBAL_AREA:  # _direct_global_area_sample
                if sob:
                    u_tri, u_a = split_surface_uniform(surfaces, u_a)
                else:
                    u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                ltri, y0, y1, y2 = sample_surface_point(surfaces, corners, u_tri, u_a, u_b)
                pdf_area = surface_pdf
            else:  # _direct_area_sample ("area" and "mis")
                if sob:
                    u_select, u_tri, u_a = split_light_uniform(lights, num_lights, u_a)
                else:  # with one light there is nothing to choose (pdf(k) = 1) and nothing to draw
                    u_select = uniform(k, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
                    u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                if num_lights > 1:
                    counters[C_LIGHT_SELECT] += 1
                light, ltri, y0, y1, y2 = sample_light_point(lights, num_lights, corners, u_select, u_tri, u_a, u_b)
                if mutants & M_LIGHT_PDF_IGNORED:  # mutant "light-pdf-ignored": pdf(y|k) alone
                    pdf_area = 1.0 / light_area[light]
                else:
                    pdf_area = light_pmf[light] / light_area[light]
            # _shadow_ray_estimate
            l0, l1, l2 = y0 - x0, y1 - x1, y2 - x2
            dist2 = dot3(l0, l1, l2, l0, l1, l2)
            dist = math.sqrt(dist2)
            inv_dist = 1.0 / dist  # one division, three products
            wi0, wi1, wi2 = l0 * inv_dist, l1 * inv_dist, l2 * inv_dist
            cos_x = dot3(nx0, nx1, nx2, wi0, wi1, wi2)
            cos_y = -dot3(tri_normal[ltri, 0], tri_normal[ltri, 1], tri_normal[ltri, 2], wi0, wi1, wi2)
            if not (cos_x > 0 and cos_y > 0 and light_id[ltri] >= 0 and dist2 > 0):
                counters[C_SHADOW_SKIPPED] += 1
                continue
            if mutants & M_NO_RAY_OFFSET:  # mutant "no-ray-offset"
                so0, so1, so2 = x0, x1, x2
            else:
                so0, so1, so2 = ox0, ox1, ox2
            g0, g1, g2 = y0 - so0, y1 - so1, y2 - so2
            seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
            t_max = shadow_t_max(seg_len, origin_offset(offset_scene, y0, y1, y2), cos_y)
            counters[C_SHADOW] += 1
            s_owner[s] = h
            s_o32[s, 0], s_o32[s, 1], s_o32[s, 2] = so0, so1, so2
            inv_seg = 1.0 / seg_len
            s_d32[s, 0], s_d32[s, 1], s_d32[s, 2] = g0 * inv_seg, g1 * inv_seg, g2 * inv_seg
            s_tfar[s] = max(t_max, 0.0)
            cos_at_x = 1.0 if no_cosine else cos_x  # mutant "no-cosine" (direct light)
            scale = (cos_at_x * cos_y) / (dist2 * pdf_area)  # G(x, y) V / p(y), for V = 1 (one division)
            v0 = emission[ltri, 0] * f0 * scale
            v1 = emission[ltri, 1] * f1 * scale
            v2 = emission[ltri, 2] * f2 * scale
            if direct == DIRECT_MIS:  # _mis_weight_light
                p_light = nd * pdf_area * dist2 / cos_y
                p_hemi = ni * hemisphere_pdf(hemi_cosine, cos_x)
                w = p_light * p_light / (p_light * p_light + p_hemi * p_hemi)
                v0, v1, v2 = v0 * w, v1 * w, v2 * w
            s_value[s, 0], s_value[s, 1], s_value[s, 2] = v0, v1, v2
            s += 1

        # Indirect light (Fig. 5.14), if the next vertex can still add anything.
        if not allow_indirect:
            continue
        if play_roulette:
            survival = albedo_max[material] if rr == RR_ALBEDO else fixed_survival
            u_rr = sobol_point(fh[2], si)[0] if sob else uniform(k, salt_rr)
            if not (u_rr < survival):
                counters[C_ROULETTE] += 1
                continue
            if not (mutants & M_RR_NO_REWEIGHT):  # mutant "rr-no-reweight"
                inv_survival = 1.0 / survival
                b0, b1, b2 = b0 * inv_survival, b1 * inv_survival, b2 * inv_survival
        for branch in range(ni):
            kb = k if ni == 1 else mix64(k ^ branch_salt(branch, depth))
            if sob:
                u_a, u_b = sobol_point(fh[3], si * ni + branch)
            else:
                u_a, u_b = uniform(kb, salt_u1), uniform(kb, salt_u2)
            w0, w1, w2, cos_theta, pdf = sample_hemisphere(hemi_cosine, u_a, u_b, nx0, nx1, nx2)
            if (mutants & M_COSINE_PDF_PI) and hemi_cosine:  # mutant "cosine-pdf-pi"
                pdf = pdf * PI
            cos_factor = 1.0 if no_cosine else cos_theta  # mutant "no-cosine" (indirect light)
            weight = cos_factor / (pdf * ni)
            c0, c1, c2 = b0 * (f0 * weight), b1 * (f1 * weight), b2 * (f2 * weight)
            carries = (math.isfinite(c0) and math.isfinite(c1) and math.isfinite(c2)) and (c0 > 0 or c1 > 0 or c2 > 0)
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
            x_pdf[q] = pdf * ni

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
        faces_x = dot3(s_dir[q, 0], s_dir[q, 1], s_dir[q, 2], tri_normal[tri, 0], tri_normal[tri, 1],
                       tri_normal[tri, 2]) < 0
        weight = s_aux[q] * (1.0 if faces_x else 0.0)
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
