"""One vertex x_i of a path in the wavefront, besides its direct light (:mod:`.direct`): which terms it adds, the
emission it shows, Russian roulette and the indirect ray (Fig. 5.14, 5.16; eq. 5.2).

    L(x -> Theta) = Le(x -> Theta) [i = 1 only] + L_direct + L_indirect,
    <L_indirect>  = 1/Ni sum L_r(r(x, Psi_j) -> -Psi_j) f_r cos(Psi_j, N_x) / p(Psi_j)             (Fig. 5.14)

The indirect estimate recurses on L_r, so emission is counted at the viewing ray's hit alone (or, with MIS, at every
hit, weighted by the power heuristic against the light samples; with the planted fault "double-emission", at every
hit unweighted: the pseudo-code's computeRadiance taken literally). An environment's radiance, seen by a ray that
escapes, counts by the same rule (:mod:`.emitters`, in the engines). Path lengths follow Mitsuba's max_depth: x_i adds
direct light only when i + 1 <= max_depth, and an indirect ray only when the next vertex can still add something
(i + 2 <= max_depth; with MIS, i + 1 <= max_depth); -1 is unbounded. Russian roulette (from vertex ``rr_depth`` on)
lets a path go on with probability q and divides what survives by q (Fig. 5.16, ``estimatedRadiance /
(1 - absorption)``); q = the material's largest reflectance ("albedo") or 1 - absorption ("fixed"). The throughput
of the next ray: beta' = beta f_r cos(Psi, N_x) / (p(Psi) Ni q).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import (DIRECT_MIS, EMIT_ALL, EMIT_MIS, EMIT_NONE, HEMI_COSINE, JIT_BORROW,
                                           M_COSINE_PDF_PI, M_DOUBLE_EMISSION, M_NO_COSINE, M_RR_NO_REWEIGHT,
                                           RR_ALBEDO, RR_OFF)
from reference_impl.kernels.rng import branch_salt, dim_salt, mix64, uniform
from reference_impl.kernels.material import material_at
from reference_impl.kernels.sobol import pair_point, uniform_2d
from reference_impl.kernels.surface import offset_origin
from reference_impl.kernels.warps import PI, sample_hemisphere
from reference_impl.materials import P_REFLECTANCE, P_TWO_SIDED
from reference_impl.rng import INDIRECT_U1, INDIRECT_U2, ROULETTE


@njit(**JIT_BORROW)
def vertex_rules(cfg, depth):
    """What vertex ``depth`` (the viewing ray's hit is 1) adds: (how its emission counts, whether a next vertex can
    count, i.e. direct light is wanted, whether an indirect ray is wanted)."""
    mis = cfg.direct == DIRECT_MIS
    if depth == 1 or (cfg.mutant & M_DOUBLE_EMISSION):  # mutant "double-emission": Le at every hit
        emit = EMIT_ALL
    elif mis:
        emit = EMIT_MIS
    else:
        emit = EMIT_NONE
    max_depth = cfg.max_depth
    allow_next = max_depth == -1 or depth + 1 <= max_depth
    allow_indirect = (max_depth == -1 or depth + 2 <= max_depth) or (mis and allow_next)
    return emit, allow_next, allow_indirect


@njit(**JIT_BORROW)
def emitted(cfg, emit, hit, scene, lights, p_hemi):
    """Le(x -> Theta) of the triangle ``hit`` found (:class:`.surface.SurfaceHit`; its front side only) and the
    weight it counts with: 1, or with EMIT_MIS the power heuristic's weight of the ray (density p_hemi = Ni p(Psi))
    that found it at distance t against the Nd light samples that could have drawn the same point
    (``_mis_weight_hemisphere``): p_h^2 / (p_h^2 + p_l^2), p_l = Nd pdf(k) / A_k t^2 / cos(theta_out)."""
    emission, light_id = scene.emission, scene.light_id
    light_pmf, light_area = lights.pmf, lights.area
    tri, t, cos_out = hit.tri, hit.t, hit.cos_out
    fr = 1.0 if cos_out > 0 else 0.0
    e0, e1, e2 = emission[tri, 0] * fr, emission[tri, 1] * fr, emission[tri, 2] * fr
    w = 1.0  # exact: b Le w = b Le
    if emit == EMIT_MIS:
        light = light_id[tri]
        w = 0.0
        if light >= 0 and cos_out > 0:
            p_light = cfg.shadow_rays * (light_pmf[light] / light_area[light]) * (t * t) / cos_out
            w = p_hemi * p_hemi / (p_hemi * p_hemi + p_light * p_light)
    return e0, e1, e2, w


@njit(**JIT_BORROW)
def shading_point(cfg, materials, hit, row):
    """What the light leaving x toward Theta depends on, at the hit ``hit`` (:class:`.surface.SurfaceHit`), its
    diffuse material's parameters from the material step (:func:`.material.material_at`, written into ``row``):
    (whether x reflects at all, which it does not on the back of a one-sided surface, its largest albedo
    max_c rho_c (the survival probability of ``rr = "albedo"``), N turned to the side Theta leaves from, Lambert's
    f_r = rho / pi, and the offset origin of the rays that leave x)."""
    material_at(materials, hit, row, cfg.mutant)  # a diffuse kind: these engines run Lambertian scenes only
    front = hit.cos_out > 0
    n0, n1, n2, x0, x1, x2 = hit.n0, hit.n1, hit.n2, hit.x0, hit.x1, hit.x2
    if not (front or row[P_TWO_SIDED] != 0.0):
        return False, 0.0, n0, n1, n2, 0.0, 0.0, 0.0, x0, x1, x2
    if not front:  # the side Theta leaves from
        n0, n1, n2 = -n0, -n1, -n2
    ox0, ox1, ox2 = offset_origin(cfg.offset_scene, x0, x1, x2, n0, n1, n2)
    r0, r1, r2 = row[P_REFLECTANCE], row[P_REFLECTANCE + 1], row[P_REFLECTANCE + 2]
    return True, max(r0, r1, r2), n0, n1, n2, r0 / np.pi, r1 / np.pi, r2 / np.pi, ox0, ox1, ox2


@njit(**JIT_BORROW)
def roulette(cfg, albedo, sob, seeds, index, key, depth, b0, b1, b2):
    """Russian roulette at vertex ``depth``, where it is played: (whether the path goes on, its throughput divided
    by the survival probability q, unless the planted fault "rr-no-reweight" is on); q = ``albedo`` (the material's
    largest, :func:`shading_point`) or 1 - absorption. The uniform is point ``index`` of the pixel's set ``seeds``
    (``sob``) or the path's own."""
    if not (cfg.rr != RR_OFF and depth >= cfg.rr_depth):
        return True, b0, b1, b2
    survival = albedo if cfg.rr == RR_ALBEDO else cfg.survival
    u_rr = pair_point(seeds, index)[0] if sob else uniform(key, dim_salt(depth, ROULETTE, 0))
    if not (u_rr < survival):
        return False, b0, b1, b2
    if cfg.mutant & M_RR_NO_REWEIGHT:  # mutant "rr-no-reweight"
        return True, b0, b1, b2
    inv_survival = 1.0 / survival
    return True, b0 * inv_survival, b1 * inv_survival, b2 * inv_survival


@njit(**JIT_BORROW)
def indirect_ray(cfg, sob, seeds, index, branch, key, depth, n0, n1, n2, f0, f1, f2, b0, b1, b2):
    """Indirect ray ``branch`` of Ni from x (Fig. 5.14), for the camera sample ``index`` of its pixel: (whether it
    can carry light, its key, its direction Psi, its throughput beta f_r cos / (p Ni), and Ni p(Psi) for the MIS
    weight at the next hit). A ray whose throughput is zero or not finite is not traced."""
    ni = cfg.indirect_rays
    hemi_cosine = cfg.hemisphere == HEMI_COSINE
    kb = key if ni == 1 else mix64(key ^ branch_salt(branch, depth))
    u_a, u_b = uniform_2d(sob, seeds, index * ni + branch, kb, 0, depth, INDIRECT_U1, INDIRECT_U2)
    w0, w1, w2, cos_theta, pdf = sample_hemisphere(hemi_cosine, u_a, u_b, n0, n1, n2)
    if (cfg.mutant & M_COSINE_PDF_PI) and hemi_cosine:  # mutant "cosine-pdf-pi"
        pdf = pdf * PI
    cos_factor = 1.0 if cfg.mutant & M_NO_COSINE else cos_theta  # mutant "no-cosine" (indirect light)
    weight = cos_factor / (pdf * ni)
    c0, c1, c2 = b0 * (f0 * weight), b1 * (f1 * weight), b2 * (f2 * weight)
    carries = (math.isfinite(c0) and math.isfinite(c1) and math.isfinite(c2)) and (c0 > 0 or c1 > 0 or c2 > 0)
    return carries, kb, w0, w1, w2, c0, c1, c2, pdf * ni
