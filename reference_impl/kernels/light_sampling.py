"""Points on the lights and on all surfaces: :mod:`reference_impl.lights` for one sample, bit for bit.

    light k          pdf(k) = pi A_k lum(Le_k) / sum_j pi A_j lum(Le_j)  ("power"), or 1 / N_L ("uniform")  (Fig. 5.10)
    piece i of k     pdf(i | k) = A_i / A_k, so a point y uniform over k: pdf(y | k) = 1 / A_k            (Fig. 5.8)
    point on i       y = o + a e1 + b e2 of the piece's frame (o, e1, e2):
                       triangle (c0, c1 - c0, c2 - c0)   a = 1 - sqrt(u1), b = u2 sqrt(u1)
                       parallelogram (p0, e1, e2)        a = u1, b = u2      (a rectangle light as one piece)
                     or on a sphere (frame (c, (r, 0, 0), 0)), uniform over its area 4 pi r^2:
                       y = c + r (sqrt(1 - z^2) cos phi, sqrt(1 - z^2) sin phi, z),  z = 1 - 2 u1, phi = 2 pi u2
                       (Archimedes: z uniform on [-1, 1] is area-uniform; Mitsuba's square_to_uniform_sphere)
    sphere's cone    from x outside an outward sphere light (``lights.cone``; lights.cone_points):
                       1 - cos theta = u1 (1 - cos theta_max), phi = 2 pi u2, y the sphere's nearer point along
                       the direction (theta, phi) about c - x, p(w) = 1 / (2 pi (1 - cos theta_max))
    global area      t with pdf A_t / A_scene over every surface: p(y) = 1 / A_scene                      (Fig. 5.13)
                     y = c0 + b1 (c1 - c0) + b2 (c2 - c0), b1 = 1 - sqrt(u1), b2 = u2 sqrt(u1), or on a sphere
                     as above

The pieces of a light are its triangles, or the one parallelogram its two triangles form
(lights.parallelogram_frame). The stratified sampler draws one 2D point per light sample and reuses its first
coordinate for the discrete choices: what is left of u1 inside k's interval of the cdf picks the piece, and what is
left of that is the point's first coordinate (``split_light_uniform``, pbrt-v4's sample reuse;
``lights.LightSampler.split_uniform``); on a parallelogram the point is then the 2D point itself, still stratified.
"""

from __future__ import annotations

import math

from numba import njit

from reference_impl.kernels.config import JIT, JIT_INLINE, M_SPHERE_POINTS_THETA
from reference_impl.kernels.surface import normal_at
from reference_impl.kernels.warps import HALF_INV_PI, dot3, rescale_within, sample_discrete, to_world, unit_circle


@njit(**JIT_INLINE)
def point_on_triangle(corners, tri, u1, u2):
    """lights._uniform_point_on for one triangle: c0 + b1 (c1 - c0) + b2 (c2 - c0) (global area sampling)."""
    s = math.sqrt(u1)
    b1 = 1.0 - s
    b2 = u2 * s
    p0 = corners[tri, 0, 0] + b1 * (corners[tri, 1, 0] - corners[tri, 0, 0]) + b2 * (corners[tri, 2, 0] - corners[tri, 0, 0])
    p1 = corners[tri, 0, 1] + b1 * (corners[tri, 1, 1] - corners[tri, 0, 1]) + b2 * (corners[tri, 2, 1] - corners[tri, 0, 1])
    p2 = corners[tri, 0, 2] + b1 * (corners[tri, 1, 2] - corners[tri, 0, 2]) + b2 * (corners[tri, 2, 2] - corners[tri, 0, 2])
    return p0, p1, p2


@njit(**JIT)
def point_on_sphere(c0, c1, c2, r, u1, u2):
    """A uniform point of the sphere (centre c, radius r) from (u1, u2): c + r (sqrt(1 - z^2) cos phi,
    sqrt(1 - z^2) sin phi, z), z = 1 - 2 u1, phi = 2 pi u2 (lights.sphere_points)."""
    z = 1.0 - 2.0 * u1
    rho = math.sqrt(max(0.0, 1.0 - z * z))
    cos_phi, sin_phi = unit_circle(u2)
    return c0 + r * (rho * cos_phi), c1 + r * (rho * sin_phi), c2 + r * z


@njit(**JIT)
def sphere_cone(c0, c1, c2, r, x0, x1, x2):
    """lights.sphere_cone for one sphere and point: (D^2, sin^2 theta_max, 1 - cos theta_max), the last 0 where x
    is not outside the sphere."""
    w0, w1, w2 = c0 - x0, c1 - x1, c2 - x2
    d2 = w0 * w0 + w1 * w1 + w2 * w2
    s2 = (r * r) / d2 if d2 > 0.0 else 2.0
    if not s2 < 1.0:
        return d2, s2, 0.0
    cos_max = math.sqrt(1.0 - s2)
    return d2, s2, s2 / (1.0 + cos_max)


@njit(**JIT)
def point_in_cone(c0, c1, c2, r, x0, x1, x2, d2, s2, one_minus, u1, u2):
    """lights.cone_points for one sphere seen from x outside it (``d2``, ``s2``, ``one_minus``: its
    :func:`sphere_cone`): the point y."""
    h = u1 * one_minus  # 1 - cos theta
    cos_t = 1.0 - h
    sin2 = h * (2.0 - h)
    sin_t = math.sqrt(max(0.0, sin2))
    cos_phi, sin_phi = unit_circle(u2)  # phi = 2 pi u2
    d = math.sqrt(d2)
    a0, a1, a2 = (c0 - x0) / d, (c1 - x1) / d, (c2 - x2) / d
    w0, w1, w2 = to_world(sin_t * cos_phi, sin_t * sin_phi, cos_t, a0, a1, a2)
    t = d * (cos_t - math.sqrt(max(0.0, s2 - sin2)))
    m0, m1, m2 = x0 + t * w0 - c0, x1 + t * w1 - c1, x2 + t * w2 - c2
    scale = r / math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    return c0 + m0 * scale, c1 + m1 * scale, c2 + m2 * scale


@njit(**JIT_INLINE)
def drawn_by_cone(lights, light, mutant):
    """Whether area light k's points are drawn by its cone from a point outside it: a sphere whose emission faces
    outward (``lights.cone``), unless the planted fault "sphere-points-uniform-theta" is planted (a fault of the area
    sampler, which then draws every sphere light)."""
    return lights.cone[light, 3] > 0.0 and not mutant & M_SPHERE_POINTS_THETA


@njit(**JIT_INLINE)
def cone_pdf(lights, light, x0, x1, x2, mutant):
    """The solid-angle density at x of area light k's points drawn by its cone, 1 / (2 pi (1 - cos theta_max))
    (:func:`point_in_cone`), or 0 where k is not a sphere drawn that way from x (drawn by area)."""
    if not drawn_by_cone(lights, light, mutant):
        return 0.0
    cone = lights.cone
    _d2, _s2, one_minus = sphere_cone(cone[light, 0], cone[light, 1], cone[light, 2], cone[light, 3], x0, x1, x2)
    return HALF_INV_PI / one_minus if one_minus > 0.0 else 0.0


@njit(**JIT_INLINE)
def light_density(lights, light, nd, pmf_k, x0, x1, x2, t, cos_out, mutant):
    """The Nd light samples' density, per unit solid angle at x, of the direction toward a point of area light k
    (chosen with ``pmf_k``) that a ray from x found at distance t, cos_out there: Nd pdf(k) / (2 pi (1 - cos
    theta_max)) where k is a sphere drawn by its cone from x (:func:`cone_pdf`), else Nd pdf(k) / A_k t^2 / cos_out.
    The MIS weight of emission that a BSDF or phase ray finds (the path loop's and the volumetric loop's)."""
    p_cone = cone_pdf(lights, light, x0, x1, x2, mutant)
    if p_cone > 0.0:
        return nd * pmf_k * p_cone
    return nd * (pmf_k / lights.area[light]) * (t * t) / cos_out


@njit(**JIT_INLINE)
def point_on_light(lights, entry, u1, u2):
    """LightSampler.point_on_entry for one entry of the light table: (the triangle y lies in, y). Both warps are
    computed and the entry's flag selects one (no branch between the two): a triangle's barycentrics
    (1 - sqrt(u1), u2 sqrt(u1)) or a parallelogram's (u1, u2); y = o + a e1 + b e2 of the entry's frame. A sphere's
    entry (``lights.sphere``) is a uniform point of it (:func:`point_on_sphere`)."""
    triangles, frames, parallelogram, other = lights.triangles, lights.frames, lights.parallelogram, lights.other
    if lights.sphere[entry]:  # a whole sphere: frame (c, (r, 0, 0), 0)
        y0, y1, y2 = point_on_sphere(frames[entry, 0, 0], frames[entry, 0, 1], frames[entry, 0, 2],
                                     frames[entry, 1, 0], u1, u2)
        return triangles[entry], y0, y1, y2
    s = math.sqrt(u1)
    par = parallelogram[entry]
    a = u1 if par else 1.0 - s
    b = u2 if par else u2 * s
    p0 = frames[entry, 0, 0] + a * frames[entry, 1, 0] + b * frames[entry, 2, 0]
    p1 = frames[entry, 0, 1] + a * frames[entry, 1, 1] + b * frames[entry, 2, 1]
    p2 = frames[entry, 0, 2] + a * frames[entry, 1, 2] + b * frames[entry, 2, 2]
    tri = other[entry] if a + b > 1.0 else triangles[entry]
    return tri, p0, p1, p2


@njit(**JIT_INLINE)
def light_point(lights, light, u_tri, u1, u2):
    """A point of light k = ``light``: its piece from u_tri (within k's cdf), the point on it from (u1, u2):
    (the triangle y lies in, y)."""
    first, count, within_cdf = lights.first, lights.count, lights.within_cdf
    f = first[light]
    return point_on_light(lights, f + search_within(within_cdf, f, count[light], u_tri), u1, u2)


@njit(**JIT_INLINE)
def toward_light_point(scene, tri, y0, y1, y2, x0, x1, x2):
    """The light door's geometry for a point y on triangle ``tri`` of a light seen from x: (the unit direction wi
    from x toward y, |y - x|^2, cos theta_y = -N_y . wi, positive where y's front side faces x; N_y the triangle's
    normal, or the sphere's at y, :func:`.surface.normal_at`). Every engine's light sample on an area light (and
    global area sampling's point) goes through it."""
    l0, l1, l2 = y0 - x0, y1 - x1, y2 - x2
    dist2 = dot3(l0, l1, l2, l0, l1, l2)
    inv_dist = 1.0 / math.sqrt(dist2)  # one division, three products
    wi0, wi1, wi2 = l0 * inv_dist, l1 * inv_dist, l2 * inv_dist
    m0, m1, m2 = normal_at(scene, tri, y0, y1, y2)
    cos_y = -dot3(m0, m1, m2, wi0, wi1, wi2)
    return wi0, wi1, wi2, dist2, cos_y


@njit(**JIT_INLINE)
def search_within(within_cdf, f, n, u):
    """lights._search_within for one uniform: the i < n with within_cdf[f + i - 1] <= u < within_cdf[f + i]."""
    lo = 0
    hi = n - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if within_cdf[f + mid] <= u:
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit(**JIT_INLINE)
def sample_light_point(lights, num_lights, u_select, u_tri, u1, u2):
    """LightSampler.sample for one set of uniforms: (light k, triangle, point y)."""
    light = sample_discrete(lights.cdf, u_select) if num_lights > 1 else 0
    tri, p0, p1, p2 = light_point(lights, light, u_tri, u1, u2)
    return light, tri, p0, p1, p2


@njit(**JIT_INLINE)
def sample_surface_point(surfaces, corners, u_tri, u1, u2):
    """TriangleAreaSampler.sample for one set of uniforms: (triangle, point y); on an entry that is a whole sphere
    (``surfaces.sphere``: its centre and radius) a uniform point of it."""
    triangles, cdf = surfaces.triangles, surfaces.cdf
    i = sample_discrete(cdf, u_tri)
    tri = triangles[i]
    if surfaces.sphere.shape[0] > 0 and surfaces.sphere[i, 3] > 0.0:  # empty: no sphere in the scene
        sp = surfaces.sphere
        p0, p1, p2 = point_on_sphere(sp[i, 0], sp[i, 1], sp[i, 2], sp[i, 3], u1, u2)
        return tri, p0, p1, p2
    p0, p1, p2 = point_on_triangle(corners, tri, u1, u2)
    return tri, p0, p1, p2


@njit(**JIT_INLINE)
def split_light_uniform(lights, num_lights, u):
    """LightSampler.split_uniform for one uniform: (u_select, u_tri, u1). (Handing on the light and triangle it
    finds, so that sample_light_point need not search again, measured 4-6 % slower on multi-light: numba's code
    for the path loop got worse.)"""
    cdf, first, count, within_cdf = lights.cdf, lights.first, lights.count, lights.within_cdf
    light = 0
    u_tri = u
    if num_lights > 1:
        light = sample_discrete(cdf, u)
        u_tri = rescale_within(u, cdf[light - 1] if light > 0 else 0.0, cdf[light])
    f = first[light]
    lo = search_within(within_cdf, f, count[light], u_tri)
    return u, u_tri, rescale_within(u_tri, within_cdf[f + lo - 1] if lo > 0 else 0.0, within_cdf[f + lo])


@njit(**JIT_INLINE)
def split_surface_uniform(surfaces, u):
    """TriangleAreaSampler.split_uniform for one uniform: (u_tri, u1)."""
    cdf = surfaces.cdf
    index = sample_discrete(cdf, u)
    return u, rescale_within(u, cdf[index - 1] if index > 0 else 0.0, cdf[index])
