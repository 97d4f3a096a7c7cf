"""The hit point x of a ray and the rays that leave it (:class:`reference_impl.intersect.Intersector`): the distance
recomputed in float64, the offset that keeps a ray off the surface it leaves, and where a shadow ray stops.

    t            = ((v0 - o) . N) / (d . N)      float64, from the triangle's plane (Embree answers in float32);
                                                 0 where that is not a positive number
    x            = o + t d,   cos(theta_out) = -d . N
    offset(p)    = 2^-20 max(|p_x|, |p_y|, |p_z|) + 2^-22 scene size        (a few float32 ulps of p)
    origin       = x + offset(x) N_x                                          (N_x on the side the ray leaves)
    shadow t_max = |y - origin| (1 - 1e-6) - offset(y) / cos(theta_y)         (short of y by y's offset off y's plane)
"""

from __future__ import annotations

import math

from numba import njit

from reference_impl.kernels.config import JIT, JIT_BORROW
from reference_impl.kernels.warps import dot3

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
def surface_hit(scene, p, o0, o1, o2, d0, d1, d2):
    """The hit of a ray on primitive p: (its triangle, the triangle's normal N, t, x, cos(theta_out))."""
    prim_to_tri, tri_normal, tri_v0 = scene.prim_to_tri, scene.normal, scene.corner0
    tri = prim_to_tri[p]
    n0, n1, n2 = tri_normal[tri, 0], tri_normal[tri, 1], tri_normal[tri, 2]
    t, x0, x1, x2, cos_out = hit_point(o0, o1, o2, d0, d1, d2, n0, n1, n2, tri_v0[tri, 0], tri_v0[tri, 1], tri_v0[tri, 2])
    return tri, n0, n1, n2, t, x0, x1, x2, cos_out


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
