"""The emitters that are not surfaces in the kernels (:mod:`reference_impl.emitters` for one sample): the
environment's radiance and directions, the spot's falloff, the light door of each kind (:func:`emitter_direction`:
direction, distance, falloff, density and emission, for every engine) and the wavefront's light sample with its
shadow ray (:func:`emitter_sample`; the path loop's is :func:`.direct.emitter_connection`).

    point        v = I f_r cos(x) / (r^2 pdf(k)),            ray toward p, stops short of it
    spot         v = I s(theta) f_r cos(x) / (r^2 pdf(k)),    s: 1 within beam_width, linear to 0 at cutoff_angle
    directional  v = E f_r cos(x) / pdf(k),                    ray along -direction, to infinity
    environment  v = L(w) f_r cos(x) / (pdf(k) p(w)),          w ~ p(w) (Settings.env_sampling), to infinity
                 times the power heuristic's p_l^2 / (p_l^2 + p_h^2) with direct = "mis":
                 p_l = Nd pdf(k) p(w), p_h = Ni p_hemisphere(w)

Delta lights are connected deterministically (pdf(y | k) is a delta: no other strategy can find them, so no MIS
weight). An escaping ray that counts the environment with the MIS weight uses :func:`env_light_pdf`, the density
with which a light sample at the ray's origin would have drawn its direction. The emitter tables are those of
:mod:`.config` (``emitters``); the environment is emitter ``cfg.env_light - cfg.num_area_lights``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.emitters import DIRECTIONAL, ENV_MAP, POINT, SPOT
from reference_impl.kernels.config import (DIRECT_MIS, ENV_COSINE, ENV_IMPORTANCE, HEMI_COSINE, JIT, JIT_BORROW,
                                           M_DIRECTIONAL_REVERSED, M_ENVMAP_MIRRORED_U, M_ENVMAP_PDF_NO_SIN,
                                           M_NO_COSINE, M_NO_RAY_OFFSET, M_POINT_NO_INVERSE_SQUARE,
                                           M_SPOT_IGNORES_BEAM_WIDTH)
from reference_impl.kernels.light_sampling import search_within
from reference_impl.kernels.surface import shadow_t_max
from reference_impl.kernels.warps import (PI, TWO_PI, dot3, hemisphere_pdf, rescale_within, sample_discrete,
                                          sample_hemisphere)

INV_PI = 1.0 / np.pi
INV_TWO_PI = 0.5 / np.pi
INV_FOUR_PI = 1.0 / (4.0 * np.pi)  # emitters.INV_FOUR_PI
INV_TWO_PI_SQ = 1.0 / (2.0 * np.pi * np.pi)  # emitters._INV_TWO_PI_SQ


@njit(**JIT)
def mat_vec(m, e, d0, d1, d2):
    """(m[e] @ d), one 3x3 matrix of a (E, 3, 3) table."""
    return (m[e, 0, 0] * d0 + m[e, 0, 1] * d1 + m[e, 0, 2] * d2,
            m[e, 1, 0] * d0 + m[e, 1, 1] * d1 + m[e, 1, 2] * d2,
            m[e, 2, 0] * d0 + m[e, 2, 1] * d1 + m[e, 2, 2] * d2)


@njit(**JIT)
def normalized(x, y, z):
    inv = 1.0 / math.sqrt(x * x + y * y + z * z)
    return x * inv, y * inv, z * inv


@njit(**JIT)
def uniform_sphere(u1, u2):
    """emitters.square_to_uniform_sphere for one pair of uniforms."""
    z = 1.0 - 2.0 * u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = TWO_PI * u2
    return r * math.cos(phi), r * math.sin(phi), z


@njit(**JIT)
def direction_to_uv(x, y, z):
    """emitters.direction_to_uv for one unit direction of the map's frame."""
    u = math.atan2(x, -z) * INV_TWO_PI
    if u < 0:
        u += 1.0
    if u >= 1.0:
        u = 0.0
    v = math.acos(min(1.0, max(-1.0, y))) * INV_PI
    return u, v


@njit(**JIT)
def envmap_lookup(image, u, v):
    """emitters.envmap_lookup at one (u, v): Mitsuba's bilinear interpolation, periodic in u, clamped in v."""
    h, w = image.shape[0], image.shape[1]
    x = u * w - 0.5
    x0 = math.floor(x)
    fx = x - x0
    c0 = int(x0)
    if c0 < 0:
        c0 += w
    c1 = c0 + 1
    if c1 >= w:
        c1 -= w
    y = min(max(v, 0.0), 1.0) * (h - 1)
    y0 = min(math.floor(y), h - 1)
    fy = y - y0
    r0 = int(y0)
    r1 = min(r0 + 1, h - 1)
    gx, gy = 1.0 - fx, 1.0 - fy
    l0 = gy * (gx * image[r0, c0, 0] + fx * image[r0, c1, 0]) + fy * (gx * image[r1, c0, 0] + fx * image[r1, c1, 0])
    l1 = gy * (gx * image[r0, c0, 1] + fx * image[r0, c1, 1]) + fy * (gx * image[r1, c0, 1] + fx * image[r1, c1, 1])
    l2 = gy * (gx * image[r0, c0, 2] + fx * image[r0, c1, 2]) + fy * (gx * image[r1, c0, 2] + fx * image[r1, c1, 2])
    return l0, l1, l2


@njit(**JIT_BORROW)
def env_radiance(cfg, emitters, d0, d1, d2):
    """L of the environment along the world direction d (unit), the way a ray leaves the scene
    (emitters.environment_radiance)."""
    kind, intensity, to_local, image = emitters.kind, emitters.intensity, emitters.to_local, emitters.env_image
    e = cfg.env_light - cfg.num_area_lights
    if kind[e] != ENV_MAP:
        return intensity[e, 0], intensity[e, 1], intensity[e, 2]
    lx, ly, lz = mat_vec(to_local, e, d0, d1, d2)
    lx, ly, lz = normalized(lx, ly, lz)
    u, v = direction_to_uv(lx, ly, lz)
    if cfg.mutant & M_ENVMAP_MIRRORED_U:  # mutant "envmap-mirrored-u"
        u = 1.0 - u
        if u >= 1.0:
            u -= 1.0
    l0, l1, l2 = envmap_lookup(image, u, v)
    s = intensity[e, 0]
    return l0 * s, l1 * s, l2 * s


@njit(**JIT_BORROW)
def env_sample(cfg, emitters, u1, u2, n0, n1, n2):
    """A direction toward the environment by ``cfg.env_sampling`` from a point of normal N (emitters.
    sample_environment): (w, p(w) per solid angle; 0 where the sample is void)."""
    if cfg.env_sampling == ENV_COSINE:
        w0, w1, w2, _cos, pdf = sample_hemisphere(True, u1, u2, n0, n1, n2)
        return w0, w1, w2, pdf
    kind = emitters.kind
    e = cfg.env_light - cfg.num_area_lights
    if cfg.env_sampling == ENV_IMPORTANCE and kind[e] == ENV_MAP:
        to_world, cell_pdf = emitters.to_world, emitters.env_cell_pdf
        row_cdf, col_cdf = emitters.env_row_cdf, emitters.env_col_cdf
        rows, cols = cell_pdf.shape[0], cell_pdf.shape[1]
        i = sample_discrete(row_cdf, u1)
        fv = rescale_within(u1, row_cdf[i - 1] if i > 0 else 0.0, row_cdf[i])
        j = sample_discrete(col_cdf[i], u2)
        fu = rescale_within(u2, col_cdf[i, j - 1] if j > 0 else 0.0, col_cdf[i, j])
        v = (i + fv) / rows
        u = (j + fu) / cols + 0.5 / cols
        if u >= 1.0:
            u = u - 1.0
        theta = PI * v
        phi = TWO_PI * u
        sin_theta = math.sin(theta)
        if cfg.mutant & M_ENVMAP_PDF_NO_SIN:  # mutant "envmap-pdf-no-sin"
            pdf = cell_pdf[i, j] * INV_TWO_PI_SQ
        else:
            pdf = cell_pdf[i, j] * INV_TWO_PI_SQ / sin_theta if sin_theta > 0 else 0.0
        w0, w1, w2 = mat_vec(to_world, e, math.sin(phi) * sin_theta, math.cos(theta), -math.cos(phi) * sin_theta)
        w0, w1, w2 = normalized(w0, w1, w2)
        return w0, w1, w2, pdf
    w0, w1, w2 = uniform_sphere(u1, u2)
    return w0, w1, w2, INV_FOUR_PI


@njit(**JIT_BORROW)
def env_pdf(cfg, emitters, d0, d1, d2, n0, n1, n2):
    """The density of :func:`env_sample` at the world direction d from a point of normal N (emitters.
    environment_pdf)."""
    if cfg.env_sampling == ENV_COSINE:
        return hemisphere_pdf(True, dot3(n0, n1, n2, d0, d1, d2))
    kind = emitters.kind
    e = cfg.env_light - cfg.num_area_lights
    if cfg.env_sampling == ENV_IMPORTANCE and kind[e] == ENV_MAP:
        to_local, cell_pdf = emitters.to_local, emitters.env_cell_pdf
        rows, cols = cell_pdf.shape[0], cell_pdf.shape[1]
        lx, ly, lz = mat_vec(to_local, e, d0, d1, d2)
        lx, ly, lz = normalized(lx, ly, lz)
        u, v = direction_to_uv(lx, ly, lz)
        shifted = u - 0.5 / cols
        if shifted < 0:
            shifted += 1.0
        j = min(int(shifted * cols), cols - 1)
        i = min(int(v * rows), rows - 1)
        if cfg.mutant & M_ENVMAP_PDF_NO_SIN:  # mutant "envmap-pdf-no-sin"
            return cell_pdf[i, j] * INV_TWO_PI_SQ
        sin_theta = math.sqrt(lx * lx + lz * lz)
        return cell_pdf[i, j] * INV_TWO_PI_SQ / sin_theta if sin_theta > 0 else 0.0
    return INV_FOUR_PI


@njit(**JIT_BORROW)
def env_light_pdf(cfg, lights, emitters, d0, d1, d2, n0, n1, n2):
    """Nd pdf(k_env) p(w): the density with which the light samples at a point of normal N draw direction w of the
    environment (the MIS weight of a ray that escapes along w; a density of directions, as Ni p(Psi))."""
    return cfg.shadow_rays * lights.pmf[cfg.env_light] * env_pdf(cfg, emitters, d0, d1, d2, n0, n1, n2)


@njit(**JIT)
def spot_falloff(cfg, spot, e, l0, l1, l2):
    """emitters.spot_falloff for one direction l from the light in its frame (not necessarily unit)."""
    cos_theta = l2 / math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
    if not (cos_theta > spot[e, 0]):
        return 0.0
    if cfg.mutant & M_SPOT_IGNORES_BEAM_WIDTH:  # mutant "spot-ignores-beam-width"
        return 1.0
    if cos_theta >= spot[e, 2]:
        return 1.0
    return (spot[e, 1] - math.acos(min(1.0, max(-1.0, cos_theta)))) * spot[e, 3]


@njit(**JIT_BORROW)
def emitter_direction(cfg, emitters, e, u1, u2, x0, x1, x2, n0, n1, n2, front_only):
    """The light door for emitter e, which is not a surface (pbrt-v4's ``Light::SampleLi``, Mitsuba's
    ``sample_direction``), seen from x (normal N; uniforms (u1, u2) for an environment's direction): (whether it
    can send light toward x at all, its kind, the unit direction wi from x toward it, r^2 (the squared distance of a
    point or spot light; 1 otherwise, and with the planted fault "point-no-inverse-square"), the spot's falloff s
    (1 otherwise), p(w) of an environment's direction per solid angle (1 otherwise), what it emits toward x (I or
    E; L(w) of an environment), and its position, for the shadow ray (point and spot)). Each engine forms its
    estimate from these, Le s / (r^2 pdf(k)) times f |cos| (times 1 / p(w) for an environment). Nothing where a
    point light sits at x, outside a spot's cone, where an environment's sample is void, or with ``front_only``
    where the direction is not above x's surface (N . wi <= 0: a surface that reflects on that side only, whose
    engine then needs neither the falloff nor the environment's radiance there)."""
    kind, position, direction, intensity = emitters.kind, emitters.position, emitters.direction, emitters.intensity
    k = kind[e]
    if k == POINT or k == SPOT:
        p0, p1, p2 = position[e, 0], position[e, 1], position[e, 2]
        l0, l1, l2 = p0 - x0, p1 - x1, p2 - x2
        dist2 = dot3(l0, l1, l2, l0, l1, l2)
        if not dist2 > 0:
            return False, k, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, x0, x1, x2
        inv_dist = 1.0 / math.sqrt(dist2)
        wi0, wi1, wi2 = l0 * inv_dist, l1 * inv_dist, l2 * inv_dist
        if front_only and not dot3(n0, n1, n2, wi0, wi1, wi2) > 0:
            return False, k, wi0, wi1, wi2, dist2, 0.0, 1.0, 0.0, 0.0, 0.0, p0, p1, p2
        falloff = 1.0
        if k == SPOT:
            s0, s1, s2 = mat_vec(emitters.to_local, e, -wi0, -wi1, -wi2)
            falloff = spot_falloff(cfg, emitters.spot, e, s0, s1, s2)
            if not falloff > 0:
                return False, k, wi0, wi1, wi2, dist2, 0.0, 1.0, 0.0, 0.0, 0.0, p0, p1, p2
        if k == POINT and cfg.mutant & M_POINT_NO_INVERSE_SQUARE:  # mutant "point-no-inverse-square"
            dist2 = 1.0
        return (True, k, wi0, wi1, wi2, dist2, falloff, 1.0, intensity[e, 0], intensity[e, 1], intensity[e, 2], p0,
                p1, p2)
    if k == DIRECTIONAL:
        sign = 1.0 if cfg.mutant & M_DIRECTIONAL_REVERSED else -1.0  # mutant "directional-reversed"
        r0, r1, r2 = sign * direction[e, 0], sign * direction[e, 1], sign * direction[e, 2]
        ok = not front_only or dot3(n0, n1, n2, r0, r1, r2) > 0
        return ok, k, r0, r1, r2, 1.0, 1.0, 1.0, intensity[e, 0], intensity[e, 1], intensity[e, 2], x0, x1, x2
    r0, r1, r2, pdf = env_sample(cfg, emitters, u1, u2, n0, n1, n2)
    if not pdf > 0 or (front_only and not dot3(n0, n1, n2, r0, r1, r2) > 0):
        return False, k, r0, r1, r2, 1.0, 1.0, pdf, 0.0, 0.0, 0.0, x0, x1, x2
    le0, le1, le2 = env_radiance(cfg, emitters, r0, r1, r2)
    return True, k, r0, r1, r2, 1.0, 1.0, pdf, le0, le1, le2, x0, x1, x2


@njit(**JIT_BORROW)
def emitter_sample(cfg, emitters, e, pdf_select, u1, u2, x0, x1, x2, n0, n1, n2, ox0, ox1, ox2, f0, f1, f2):
    """The wavefront's light sample of emitter e (chosen with probability ``pdf_select``) at x (normal N,
    offset origin ox, f_r = f), from :func:`emitter_direction`: (whether it needs a shadow ray, the ray's origin,
    unit direction and t_max, what it carries where nothing blocks it, with its MIS weight). No ray where the light
    is behind x, outside a spot's cone, or brings nothing."""
    ok, k, r0, r1, r2, dist2, falloff, pdf, le0, le1, le2, p0, p1, p2 = emitter_direction(cfg, emitters, e, u1, u2,
                                                                                          x0, x1, x2, n0, n1, n2, True)
    cos_x = dot3(n0, n1, n2, r0, r1, r2)
    if not (ok and cos_x > 0):
        return False, x0, x1, x2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    if cfg.mutant & M_NO_RAY_OFFSET:  # mutant "no-ray-offset"
        so0, so1, so2 = x0, x1, x2
    else:
        so0, so1, so2 = ox0, ox1, ox2
    cos_at_x = 1.0 if cfg.mutant & M_NO_COSINE else cos_x  # mutant "no-cosine" (direct light)
    t_max = np.inf
    if k == POINT or k == SPOT:
        g0, g1, g2 = p0 - so0, p1 - so1, p2 - so2
        seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
        inv_seg = 1.0 / seg_len
        r0, r1, r2 = g0 * inv_seg, g1 * inv_seg, g2 * inv_seg
        t_max = max(shadow_t_max(seg_len, 0.0, 1.0), 0.0)
        scale = (cos_at_x * falloff) / (dist2 * pdf_select)
    elif k == DIRECTIONAL:
        scale = cos_at_x / pdf_select
    else:
        scale = cos_at_x / (pdf_select * pdf)
        if cfg.direct == DIRECT_MIS:  # _mis_weight_light, against the indirect rays that could find w
            p_light = cfg.shadow_rays * pdf_select * pdf
            p_hemi = cfg.indirect_rays * hemisphere_pdf(cfg.hemisphere == HEMI_COSINE, cos_x)
            scale = scale * (p_light * p_light / (p_light * p_light + p_hemi * p_hemi))
    v0, v1, v2 = le0 * f0 * scale, le1 * f1 * scale, le2 * f2 * scale
    if not (v0 > 0 or v1 > 0 or v2 > 0):
        return False, x0, x1, x2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    return True, so0, so1, so2, r0, r1, r2, t_max, v0, v1, v2


@njit(**JIT_BORROW)
def _split_light(lights, num_lights, num_area, u):
    """The choices one uniform u makes among area lights and emitters (pbrt-v4's sample reuse): (light k, what is
    left of u inside k's interval of the cdf, the piece of k that picks (a row of the light tables; -1 for an
    emitter), what is left of that inside the piece's interval)."""
    cdf = lights.cdf
    light = 0
    u_tri = u
    if num_lights > 1:
        light = sample_discrete(cdf, u)
        u_tri = rescale_within(u, cdf[light - 1] if light > 0 else 0.0, cdf[light])
    piece, u1 = piece_within(lights, num_area, light, u_tri)
    return light, u_tri, piece, u1


@njit(**JIT_BORROW)
def piece_within(lights, num_area, light, u_tri):
    """The piece of light k = ``light`` that u_tri picks within k's cdf (a row of the light tables; -1 for an emitter,
    k >= num_area) and what is left of u_tri inside the piece's interval (u_tri itself for an emitter)."""
    if light >= num_area:
        return np.int64(-1), u_tri
    first, count, within_cdf = lights.first, lights.count, lights.within_cdf
    f = first[light]
    lo = search_within(within_cdf, f, count[light], u_tri)
    return np.int64(f + lo), rescale_within(u_tri, within_cdf[f + lo - 1] if lo > 0 else 0.0, within_cdf[f + lo])


@njit(**JIT_BORROW)
def split_light_uniform_all(lights, num_lights, num_area, u):
    """:func:`.light_sampling.split_light_uniform` over area lights and emitters: (light k, u_select, u_tri, u1);
    for an emitter (k >= num_area) u_tri is what is left of u inside k's interval (the first coordinate of its
    direction) and u1 is not used."""
    light, u_tri, _piece, u1 = _split_light(lights, num_lights, num_area, u)
    return light, u, u_tri, u1


@njit(**JIT_BORROW)
def split_light_piece_all(lights, num_lights, num_area, u):
    """:func:`split_light_uniform_all` handing on the piece it finds instead of u_tri: (light k, its piece (the
    row of the light tables; -1 for an emitter), u1, for an emitter what is left of u inside k's interval), so that
    the point need not search k's pieces again (on veach-mis, whose sphere lights have hundreds of triangles, the
    second search cost the path loop on glossy scenes 17 %)."""
    light, _u_tri, piece, u1 = _split_light(lights, num_lights, num_area, u)
    return light, piece, u1


__all__ = ["INV_FOUR_PI", "emitter_direction", "emitter_sample", "env_light_pdf", "env_pdf", "env_radiance", "env_sample",
           "piece_within", "split_light_piece_all", "split_light_uniform_all", "spot_falloff", "uniform_sphere"]
