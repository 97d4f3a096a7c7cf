"""The hit point x of a ray and the rays that leave it (:class:`reference_impl.intersect.Intersector`): the surface
record of a hit (:class:`SurfaceHit`), with the distance recomputed in float64, the offset that keeps a ray off the
surface it leaves, and where a shadow ray stops.

    t            = ((v0 - o) . N) / (d . N)      float64, from the triangle's plane (Embree answers in float32);
                                                 0 where that is not a positive number
                 on a sphere (centre c, radius r), the nearer positive root of |o + t d - c| = r, in float64:
                 b = (o - c) . d, k = |o - c|^2 - r^2, q = -(b + sign(b) sqrt(b^2 - k)), roots q and k / q
    x            = o + t d,   cos(theta_out) = -d . N,   on a sphere N = side (x - c) / |x - c|
    (u, v)       = ((p x e2) . N, (e1 x p) . N) / ((e1 x e2) . N),   e1 = v1 - v0, e2 = v2 - v0, p = x - v0:
                 the barycentrics of x, x = (1 - u - v) v0 + u v1 + v v2 (ratios of signed areas; Moeller and
                 Trumbore 1997 find the same u, v along the ray)
    (s, t)       = (1 - u - v) uv_0 + u uv_1 + v uv_2    the texture coordinates, from the corners' (a textured scene);
                 on a sphere Mitsuba's analytic ones, p = to_object x:
                 s = atan2(p_y, p_x) / (2 pi) (+ 1 where negative), t = acos(p_z / |p|) / pi
    offset(p)    = 2^-20 max(|p_x|, |p_y|, |p_z|) + 2^-22 scene size        (a few float32 ulps of p)
    origin       = x + offset(x) N_x                                          (N_x on the side the ray leaves)
    shadow t_max = |y - origin| (1 - 1e-6) - offset(y) / cos(theta_y)         (short of y by y's offset off y's plane)
"""

from __future__ import annotations

import math
from typing import NamedTuple

from numba import njit

from reference_impl.kernels.config import JIT, JIT_BORROW, JIT_NONRT
from reference_impl.kernels.texture import texture_eval
from reference_impl.kernels.warps import dot3, tangent_frame

# Relative offset of ray origins (intersect._OFFSET_REL), repeated so the kernels need no import of Embree.
_OFFSET_REL = 2.0**-20


@njit(**JIT)
def hit_point(o0, o1, o2, d0, d1, d2, n0, n1, n2, v0, v1, v2):
    """Intersector.closest_hit for one ray (origin o, unit direction d) and the triangle it hit (normal N, corner
    v): (t, x, cos(theta_out))."""
    denom = dot3(d0, d1, d2, n0, n1, n2)
    t = dot3(v0 - o0, v1 - o1, v2 - o2, n0, n1, n2) / denom
    if not (math.isfinite(t) and t > 0):
        t = 0.0
    return t, o0 + t * d0, o1 + t * d1, o2 + t * d2, -denom


@njit(**JIT_BORROW)
def sphere_normal(scene, s, x0, x1, x2):
    """The unit front normal of sphere ``s`` (``scene.sphere``: c, r, side) at its point x: side (x - c) / |x - c|."""
    sp = scene.sphere
    m0, m1, m2 = x0 - sp[s, 0], x1 - sp[s, 1], x2 - sp[s, 2]
    k = sp[s, 4] / math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    return m0 * k, m1 * k, m2 * k


@njit(**JIT_BORROW)
def sphere_roots(c0, c1, c2, r, o0, o1, o2, d0, d1, d2):
    """The roots t0 <= t1 of |o + t d - c|^2 = r^2 (unit d) and the discriminant b^2 - k, b = (o - c) . d,
    k = |o - c|^2 - r^2, computed as q = -(b + sign(b) sqrt(max(b^2 - k, 0))), roots q and k / q (no cancellation
    between b and the root; Press et al., Numerical Recipes, 5.6); both 0 where q is. Where the discriminant is
    negative (a miss) the roots are those of the closest approach, t0 = t1 = -b."""
    m0, m1, m2 = o0 - c0, o1 - c1, o2 - c2
    b = dot3(m0, m1, m2, d0, d1, d2)
    k = dot3(m0, m1, m2, m0, m1, m2) - r * r
    disc = b * b - k
    q = -(b + math.copysign(math.sqrt(max(disc, 0.0)), b))
    t1 = k / q if q != 0.0 else 0.0
    return min(q, t1), max(q, t1), disc


@njit(**JIT_NONRT)
def sphere_hit_point(scene, s, o0, o1, o2, d0, d1, d2):
    """Where a ray (origin o, unit direction d) that a query found on sphere ``s`` (:func:`.queries.sphere_nearest`,
    from the float32 copy of a batch's or packet's ray) meets it, in float64 from o itself: the nearer root t > 0 of
    |o + t d - c|^2 = r^2 (the closest approach where the float64 ray just misses; 0 where no root is positive;
    :func:`sphere_roots`): (t, x, N, cos(theta_out) = -d . N)."""
    sp = scene.sphere
    t0, t1, _disc = sphere_roots(sp[s, 0], sp[s, 1], sp[s, 2], sp[s, 3], o0, o1, o2, d0, d1, d2)
    t = t0 if t0 > 0.0 else (t1 if t1 > 0.0 else 0.0)
    x0, x1, x2 = o0 + t * d0, o1 + t * d1, o2 + t * d2
    n0, n1, n2 = sphere_normal(scene, s, x0, x1, x2)
    return t, x0, x1, x2, n0, n1, n2, -dot3(d0, d1, d2, n0, n1, n2)


@njit(**JIT_BORROW)
def normal_at(scene, tri, y0, y1, y2):
    """The unit front normal at a point y of triangle ``tri``: the triangle's, or where it stands in for a sphere
    (``scene.sphere_of``), the sphere's at y."""
    if scene.sphere_of.shape[0] > 0 and scene.sphere_of[tri] >= 0:
        return sphere_normal(scene, scene.sphere_of[tri], y0, y1, y2)
    n = scene.normal
    return n[tri, 0], n[tri, 1], n[tri, 2]


@njit(**JIT_BORROW)
def hit_at(scene, tri, o0, o1, o2, d0, d1, d2):
    """:func:`hit_point` on triangle ``tri``, or on the sphere it stands in for: (t, x, N, cos(theta_out))."""
    if scene.sphere_of.shape[0] > 0 and scene.sphere_of[tri] >= 0:
        return sphere_hit_point(scene, scene.sphere_of[tri], o0, o1, o2, d0, d1, d2)
    n, c = scene.normal, scene.corner0
    n0, n1, n2 = n[tri, 0], n[tri, 1], n[tri, 2]
    t, x0, x1, x2, cos_out = hit_point(o0, o1, o2, d0, d1, d2, n0, n1, n2, c[tri, 0], c[tri, 1], c[tri, 2])
    return t, x0, x1, x2, n0, n1, n2, cos_out


class SurfaceHit(NamedTuple):
    """What a ray found: the surface record of one hit, built by :func:`surface_hit` (pbrt's SurfaceInteraction).
    The material step (:func:`.material.material_at`) and the BSDF read it; the shading frame is where a shading
    normal would go, the texture coordinates where a texture is looked up.

    Attributes
    ----------
    tri : int
        The triangle hit (on a sphere, the sphere's first triangle: its material, emission and light).
    material : int
        Its material (a row of the material tables).
    t : float
        The distance along the unit direction, float64 from the triangle's plane (:func:`hit_point`).
    x0, x1, x2 : float
        The hit point x = o + t d.
    n0, n1, n2 : float
        The unit geometric normal N of the triangle's front side (never flipped); on a sphere its normal at x.
    cos_out : float
        cos(theta_out) = -d . N: > 0 where the ray came from the front.
    u, v : float
        The barycentrics of x (:func:`barycentrics`); 0 on a sphere.
    tex_u, tex_v : float
        The texture coordinates at x (:func:`texture_coordinates`); 0 in a scene without textures.
    ss0, ss1, ss2, st0, st1, st2, sn0, sn1, sn2 : float
        The shading frame (s, t, n): the geometric frame, n = N and s, t the tangents of
        :func:`.warps.tangent_frame` (the BSDF's local x and y axes).
    """

    tri: int
    material: int
    t: float
    x0: float
    x1: float
    x2: float
    n0: float
    n1: float
    n2: float
    cos_out: float
    u: float
    v: float
    tex_u: float
    tex_v: float
    ss0: float
    ss1: float
    ss2: float
    st0: float
    st1: float
    st2: float
    sn0: float
    sn1: float
    sn2: float


@njit(**JIT_BORROW)
def barycentrics(corners, tri, x0, x1, x2, n0, n1, n2):
    """The barycentrics (u, v) of a point x of triangle ``tri`` (corners v0, v1, v2; unit normal N):

        u = ((p x e2) . N) / ((e1 x e2) . N),  v = ((e1 x p) . N) / ((e1 x e2) . N),
        e1 = v1 - v0, e2 = v2 - v0, p = x - v0,

    so that x = (1 - u - v) v0 + u v1 + v v2 for x in the triangle's plane (the signed areas of the triangles x v2 v0
    and x v0 v1 over the triangle's; a distance of x off the plane changes neither). Moeller and Trumbore (1997)
    compute the same u, v where the ray meets the plane; Embree reports them in float32, but the queries read only
    its primitive id."""
    c00, c01, c02 = corners[tri, 0, 0], corners[tri, 0, 1], corners[tri, 0, 2]
    e10, e11, e12 = corners[tri, 1, 0] - c00, corners[tri, 1, 1] - c01, corners[tri, 1, 2] - c02
    e20, e21, e22 = corners[tri, 2, 0] - c00, corners[tri, 2, 1] - c01, corners[tri, 2, 2] - c02
    p0, p1, p2 = x0 - c00, x1 - c01, x2 - c02
    area = dot3(e11 * e22 - e12 * e21, e12 * e20 - e10 * e22, e10 * e21 - e11 * e20, n0, n1, n2)
    u = dot3(p1 * e22 - p2 * e21, p2 * e20 - p0 * e22, p0 * e21 - p1 * e20, n0, n1, n2) / area
    v = dot3(e11 * p2 - e12 * p1, e12 * p0 - e10 * p2, e10 * p1 - e11 * p0, n0, n1, n2) / area
    return u, v


@njit(**JIT_NONRT)
def texture_coordinates(scene, tri, u, v, x0, x1, x2):
    """The texture coordinates (s, t) of point x of triangle ``tri`` (barycentrics u, v): the corners' interpolated,
    or on a sphere (``scene.sphere_of``) Mitsuba's analytic ones at the direction of x from its centre
    (``sphere.cpp``: u from the azimuth about local z, v from the polar angle)."""
    sphere = scene.sphere_of[tri] if scene.sphere_of.shape[0] > 0 else -1
    if sphere >= 0:
        m = scene.sphere_to_object[sphere]
        p0 = m[0, 0] * x0 + m[0, 1] * x1 + m[0, 2] * x2 + m[0, 3]
        p1 = m[1, 0] * x0 + m[1, 1] * x1 + m[1, 2] * x2 + m[1, 3]
        p2 = m[2, 0] * x0 + m[2, 1] * x1 + m[2, 2] * x2 + m[2, 3]
        phi = math.atan2(p1, p0)
        if phi < 0.0:
            phi += 2.0 * math.pi
        r = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        return phi / (2.0 * math.pi), math.acos(min(1.0, max(-1.0, p2 / r))) / math.pi
    uv = scene.uv
    w = 1.0 - u - v
    return (w * uv[tri, 0, 0] + u * uv[tri, 1, 0] + v * uv[tri, 2, 0],
            w * uv[tri, 0, 1] + u * uv[tri, 1, 1] + v * uv[tri, 2, 1])


@njit(**JIT_BORROW)
def surface_hit(scene, p, o0, o1, o2, d0, d1, d2):
    """The :class:`SurfaceHit` of a ray (origin o, unit direction d) on Embree's primitive p."""
    tri_normal, tri_v0 = scene.normal, scene.corner0
    tri = scene.prim_to_tri[p]
    if scene.sphere_of.shape[0] > 0 and scene.sphere_of[tri] >= 0:  # an analytic sphere (empty: none in the scene)
        t, x0, x1, x2, n0, n1, n2, cos_out = sphere_hit_point(scene, scene.sphere_of[tri], o0, o1, o2, d0, d1, d2)
        u, v = 0.0, 0.0
    else:
        n0, n1, n2 = tri_normal[tri, 0], tri_normal[tri, 1], tri_normal[tri, 2]
        t, x0, x1, x2, cos_out = hit_point(o0, o1, o2, d0, d1, d2, n0, n1, n2, tri_v0[tri, 0], tri_v0[tri, 1],
                                           tri_v0[tri, 2])
        u, v = barycentrics(scene.corners, tri, x0, x1, x2, n0, n1, n2)
    tex_u, tex_v = 0.0, 0.0
    if scene.uv.shape[0] > 0:  # a scene with textures
        tex_u, tex_v = texture_coordinates(scene, tri, u, v, x0, x1, x2)
    s0, s1, s2, t0, t1, t2 = tangent_frame(n0, n1, n2)
    return SurfaceHit(tri, scene.material[tri], t, x0, x1, x2, n0, n1, n2, cos_out, u, v, tex_u, tex_v, s0, s1, s2,
                      t0, t1, t2, n0, n1, n2)


@njit(**JIT_BORROW)
def emission_at(scene, textures, tri, x0, x1, x2, mutant):
    """Le of the front side of triangle ``tri`` at its point x: ``scene.emission``'s row, or where the light is
    textured (``scene.emission_texture``) the texture's value at x's texture coordinates (``textures``: the
    materials' :class:`.records.TextureTables`, or None in a scene without textured lights; ``mutant``: the planted
    faults' bits, which the lookup reads); ``scene.emission_texture`` is empty in a scene without them."""
    textured = scene.emission_texture
    if textures is None or textured.shape[0] == 0 or textured[tri] < 0:  # None: compiled out
        e = scene.emission
        return e[tri, 0], e[tri, 1], e[tri, 2]
    return _textured_emission(scene, textures, tri, x0, x1, x2, mutant)


@njit(**JIT_NONRT)
def _textured_emission(scene, textures, tri, x0, x1, x2, mutant):
    """:func:`emission_at` on a textured light (called, not inlined: untextured scenes never come here)."""
    n = scene.normal
    u, v = barycentrics(scene.corners, tri, x0, x1, x2, n[tri, 0], n[tri, 1], n[tri, 2])
    tu, tv = texture_coordinates(scene, tri, u, v, x0, x1, x2)
    return texture_eval(textures, scene.emission_texture[tri], tu, tv, mutant)


@njit(**JIT)
def origin_offset(offset_scene, p0, p1, p2):
    """Intersector.offset for one point."""
    return _OFFSET_REL * max(abs(p0), abs(p1), abs(p2)) + offset_scene


@njit(**JIT)
def offset_origin(offset_scene, x0, x1, x2, n0, n1, n2):
    """intersect.offset_origin for one point: where the rays that leave x along the side of normal N start."""
    off = origin_offset(offset_scene, x0, x1, x2)
    return x0 + off * n0, x1 + off * n1, x2 + off * n2


@njit(**JIT)
def shadow_t_max(seg_len, offset_y, cos_y):
    """Where a shadow ray toward y stops: short of y by y's offset measured off y's plane, i.e. offset / cos_y along
    the ray. (A fixed distance along the ray left y's own triangle within float32 rounding of a grazing ray's end:
    2.6e-4 of the furnace's direct light was lost, a bias the stratified sampler's lower noise made visible.)"""
    return seg_len * (1.0 - 1e-6) - offset_y / cos_y
