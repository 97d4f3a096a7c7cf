"""The wavefront engine (``engine = "wavefront"``, and whenever Ni > 1): one bounce of every path of a batch at once,
between batched Embree queries (``integrator._bounce``).

:func:`bounce` takes the closest hits of the current rays and writes the direct-light rays and the next wavefront;
:func:`resolve_shadow` / :func:`resolve_hemisphere` add the direct light once Embree has answered them. Each vertex is
built from the Lambertian helpers (:mod:`.surface`, :mod:`.vertex`, :mod:`.direct`): the same estimator as the path
loop's (:mod:`.path`) on Lambertian scenes, with random numbers of its own (the slides' hemisphere for the indirect
rays), so the two agree in expectation, not in bits.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_HEMI_DIRECT, C_INDIRECT, C_LIGHT_SELECT,
                                           C_ROULETTE, C_SHADOW, C_SHADOW_SKIPPED, DIRECT_GLOBAL_AREA,
                                           DIRECT_HEMI_COSINE, DIRECT_HEMI_UNIFORM, DIRECT_MIS, EMIT_MIS, EMIT_NONE,
                                           JIT, JIT_INLINE, SAMPLER_SOBOL)
from reference_impl.kernels.direct import (complement_sample, hemisphere_sample, hemisphere_weight, light_sample,
                                           light_sample_all, shadow_ray)
from reference_impl.kernels.emitters import env_light_pdf, env_radiance
from reference_impl.kernels.sobol import first_hit_seeds, pixel_first_hit_seeds, spot_point
from reference_impl.kernels.surface import hit_at, surface_hit
from reference_impl.kernels.vertex import emitted, indirect_ray, roulette, shading_point, vertex_rules
from reference_impl.materials import NUM_PARAMS


@njit(**JIT)
def bounce(state, prim, scene, lights, surfaces, materials, cfg, radiance, counters, hits, rays, out, film_samples,
           emitters, crays):
    """One bounce of the wavefront (integrator._bounce), given the closest hits ``prim`` of the current rays.

    Adds the emission seen at the hits to ``radiance``, draws the Nd direct-light samples of each reflecting hit
    (the rays they need: shadow rays, or closest-hit rays for hemisphere sampling, with what their results are
    multiplied by) and the next wavefront (Russian roulette, Ni branches, hemisphere sampling). The direct light is
    added by :func:`resolve_shadow` / :func:`resolve_hemisphere` once Embree has answered.

    ``cfg`` is the render's :class:`.config.KernelConfig` with the ``depth`` of the hits. ``state`` and ``out`` are
    wavefronts (root, key, origin, direction, origin32, direction32, beta, pdf_dir), the current one and room for
    the next (at least Ni rows per row of ``state``). ``hits`` receives the rows of the reflecting hits, in order;
    ``rays`` (owner hit, origin32, direction32, tfar32, value, aux, direction64) the direct-light rays of each hit,
    in sample order, Nd rows per row of ``state``. ``film_samples`` (:class:`.records.FilmSamples`): the camera
    samples (rows of ``root``), for the stratified sampler. ``emitters``: the emitters that are not surfaces, or
    None (every branch for them compiled out); ``crays`` (owner hit, origin32, direction32, tfar32, value) receives
    the shadow rays of the emitters the direct strategy cannot find (:func:`.direct.complement_sample`). Returns
    how many hits, direct-light rays, next paths and complement rays were written.
    """
    root, key, origin, direction, _o32, _d32, beta, pdf_dir, env_pdf = state
    x_root, x_key, x_origin, x_dir, x_o32, x_d32, x_beta, x_pdf, x_env = out
    c_owner, c_o32, c_d32, c_tfar, c_value = crays
    s_owner, s_o32, s_d32, s_tfar, s_value, s_aux, s_dir = rays
    depth = cfg.depth
    emit, allow_next, allow_indirect = vertex_rules(cfg, depth)
    nd = cfg.shadow_rays
    ni = cfg.indirect_rays
    hemi_direct = cfg.direct == DIRECT_HEMI_COSINE or cfg.direct == DIRECT_HEMI_UNIFORM
    sob = cfg.sampler == SAMPLER_SOBOL and depth == 1
    fh = first_hit_seeds(film_samples.seed_key, 0, 1, 1, 1)
    fh_pixel = -1
    si = 0

    row = np.empty(NUM_PARAMS)  # the material step's parameters at the current hit
    n = len(root)
    m = 0
    s = 0
    n_next = 0
    c = 0
    for i in range(n):
        p = prim[i]
        if p < 0:
            counters[C_ESCAPED] += 1
            if emitters is not None:
                if emit != EMIT_NONE and cfg.env_light >= 0:  # the environment, seen by an escaping ray
                    e0, e1, e2 = env_radiance(cfg, emitters, direction[i, 0], direction[i, 1], direction[i, 2])
                    w = 1.0
                    if emit == EMIT_MIS:
                        ray_pdf, p_env = pdf_dir[i], env_pdf[i]
                        w = ray_pdf * ray_pdf / (ray_pdf * ray_pdf + p_env * p_env)
                    r = root[i]
                    radiance[r, 0] += beta[i, 0] * e0 * w
                    radiance[r, 1] += beta[i, 1] * e1 * w
                    radiance[r, 2] += beta[i, 2] * e2 * w
            continue
        hit = surface_hit(scene, p, origin[i, 0], origin[i, 1], origin[i, 2], direction[i, 0], direction[i, 1],
                          direction[i, 2])
        b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
        r = root[i]
        if emit != EMIT_NONE:
            e0, e1, e2, w = emitted(cfg, emit, hit, scene, lights, pdf_dir[i])
            radiance[r, 0] += b0 * e0 * w
            radiance[r, 1] += b1 * e1 * w
            radiance[r, 2] += b2 * e2 * w

        if not allow_next:
            continue
        reflects, albedo, nx0, nx1, nx2, f0, f1, f2, ox0, ox1, ox2 = shading_point(cfg, materials, hit, row)
        if not reflects:
            counters[C_BACK_FACE] += 1
            continue
        x0, x1, x2 = hit.x0, hit.x1, hit.x2
        k = key[i]
        if sob:
            fh, fh_pixel, si = pixel_first_hit_seeds(cfg, fh, fh_pixel, film_samples, r)
        h = m
        hits[h] = i
        m += 1

        # Direct light: the rays of Nd samples, resolved by resolve_shadow / resolve_hemisphere.
        for j in range(nd):
            if hemi_direct:  # a closest-hit ray
                w0, w1, w2, ratio = hemisphere_sample(cfg, sob, spot_point(fh.direction), si, j, k, depth, nx0, nx1,
                                                      nx2)
                counters[C_HEMI_DIRECT] += 1
                s_owner[s] = h
                s_o32[s, 0], s_o32[s, 1], s_o32[s, 2] = ox0, ox1, ox2
                s_d32[s, 0], s_d32[s, 1], s_d32[s, 2] = w0, w1, w2
                s_dir[s, 0], s_dir[s, 1], s_dir[s, 2] = w0, w1, w2
                s_value[s, 0], s_value[s, 1], s_value[s, 2] = f0, f1, f2
                s_aux[s] = ratio
                s += 1
                continue
            if emitters is None:
                selected, ltri, y0, y1, y2, pdf_area = light_sample(cfg, sob, spot_point(fh.light), si, j, k, depth,
                                                                    scene, lights, surfaces)
                needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = shadow_ray(
                    cfg, scene, x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2, f0, f1, f2, ltri, y0, y1, y2, pdf_area)
            else:
                selected, needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = light_sample_all(
                    cfg, sob, spot_point(fh.light), si, j, k, depth, scene, lights, surfaces, emitters, x0, x1, x2, nx0,
                    nx1, nx2, ox0, ox1, ox2, f0, f1, f2)
            if selected:
                counters[C_LIGHT_SELECT] += 1
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
        if emitters is not None:
            if hemi_direct or cfg.direct == DIRECT_GLOBAL_AREA:  # what the strategy cannot find (resolve_complement)
                for e in range(len(emitters.kind)):
                    is_complement, needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = complement_sample(
                        cfg, emitters, e, k, depth, x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2, f0, f1, f2)
                    if not is_complement:
                        continue
                    if not needed:
                        counters[C_SHADOW_SKIPPED] += 1
                        continue
                    counters[C_SHADOW] += 1
                    c_owner[c] = h
                    c_o32[c, 0], c_o32[c, 1], c_o32[c, 2] = so0, so1, so2
                    c_d32[c, 0], c_d32[c, 1], c_d32[c, 2] = r0, r1, r2
                    c_tfar[c] = tfar
                    c_value[c, 0], c_value[c, 1], c_value[c, 2] = v0, v1, v2
                    c += 1

        # Indirect light (Fig. 5.14), if the next vertex can still add anything.
        if not allow_indirect:
            continue
        alive, b0, b1, b2 = roulette(cfg, albedo, sob, spot_point(fh.roulette), si, k, depth, b0, b1, b2)
        if not alive:
            counters[C_ROULETTE] += 1
            continue
        for branch in range(ni):
            carries, kb, w0, w1, w2, c0, c1, c2, next_pdf = indirect_ray(cfg, sob, spot_point(fh.indirect), si, branch,
                                                                         k, depth, nx0, nx1, nx2, f0, f1, f2, b0, b1,
                                                                         b2)
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
            if emitters is not None:
                p_env = 0.0
                if cfg.direct == DIRECT_MIS and cfg.env_light >= 0:  # for the MIS weight should the ray escape
                    p_env = env_light_pdf(cfg, lights, emitters, w0, w1, w2, nx0, nx1, nx2)
                x_env[q] = p_env

    return m, s, n_next, c


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
def resolve_hemisphere(root, beta, hits, nd, s_owner, s_value, s_aux, s_o32, s_dir, s_prim, scene, total, radiance,
                       cfg, emitters):
    """Direct light by hemisphere sampling: emission Le of what each ray hit (its front side only: the normal where
    the ray from ``s_o32`` meets it, :func:`.surface.hit_at`), or the environment's where it escaped, times
    f_r cos / p (``s_value`` f_r, ``s_aux`` cos / p or -1 where p = 0), averaged over the Nd samples."""
    prim_to_tri, emission = scene.prim_to_tri, scene.emission
    m = len(hits)
    total[:m] = 0.0
    for q in range(len(s_owner)):
        p = s_prim[q]
        if p < 0 or s_aux[q] < 0:
            if emitters is not None:
                if p < 0 and s_aux[q] >= 0 and cfg.env_light >= 0:  # the environment, found by Psi
                    le0, le1, le2 = env_radiance(cfg, emitters, s_dir[q, 0], s_dir[q, 1], s_dir[q, 2])
                    h = s_owner[q]
                    total[h, 0] += le0 * s_value[q, 0] * s_aux[q]
                    total[h, 1] += le1 * s_value[q, 1] * s_aux[q]
                    total[h, 2] += le2 * s_value[q, 2] * s_aux[q]
            continue
        tri = prim_to_tri[p]
        if scene.sphere_of.shape[0] > 0 and scene.sphere_of[tri] >= 0:  # a sphere: its normal where the ray meets it
            _t, _x0, _x1, _x2, m0, m1, m2, _c = hit_at(scene, tri, np.float64(s_o32[q, 0]), np.float64(s_o32[q, 1]),
                                                      np.float64(s_o32[q, 2]), s_dir[q, 0], s_dir[q, 1], s_dir[q, 2])
        else:
            m0, m1, m2 = scene.normal[tri, 0], scene.normal[tri, 1], scene.normal[tri, 2]
        weight = hemisphere_weight(s_aux[q], s_dir[q, 0], s_dir[q, 1], s_dir[q, 2], m0, m1, m2)
        h = s_owner[q]
        total[h, 0] += emission[tri, 0] * s_value[q, 0] * weight
        total[h, 1] += emission[tri, 1] * s_value[q, 1] * weight
        total[h, 2] += emission[tri, 2] * s_value[q, 2] * weight
    _add_direct(root, beta, hits, nd, total, radiance)


@njit(**JIT)
def resolve_complement(root, beta, hits, c_owner, c_value, c_hit, total, radiance):
    """The emitters the direct strategy cannot find (:func:`.direct.complement_sample`): each hit's complement
    samples (value x V, V = 1 where ``c_hit < 0``) summed in order and added to ``radiance``, weighted by the hit's
    throughput (after the strategy's own estimate, as the path loop adds them)."""
    m = len(hits)
    total[:m] = 0.0
    for q in range(len(c_owner)):
        if c_hit[q] < 0:
            h = c_owner[q]
            total[h, 0] += c_value[q, 0]
            total[h, 1] += c_value[q, 1]
            total[h, 2] += c_value[q, 2]
    for h in range(m):
        i = hits[h]
        r = root[i]
        radiance[r, 0] += beta[i, 0] * total[h, 0]
        radiance[r, 1] += beta[i, 1] * total[h, 1]
        radiance[r, 2] += beta[i, 2] * total[h, 2]


@njit(**JIT_INLINE)
def _add_direct(root, beta, hits, nd, total, radiance):
    inv_nd = 1.0 / nd  # exact for Nd = 1, 2, 4, ...
    for h in range(len(hits)):
        i = hits[h]
        r = root[i]
        radiance[r, 0] += beta[i, 0] * (total[h, 0] * inv_nd)
        radiance[r, 1] += beta[i, 1] * (total[h, 1] * inv_nd)
        radiance[r, 2] += beta[i, 2] * (total[h, 2] * inv_nd)
