"""Ray origins and ends at a surface point (:class:`reference_impl.intersect.Intersector`): the offset that keeps a
ray off the surface it leaves, and where a shadow ray stops.

    offset(p)    = 2^-20 max(|p_x|, |p_y|, |p_z|) + 2^-22 scene size        (a few float32 ulps of p)
    origin       = x + offset(x) N_x                                          (N_x on the side the ray leaves)
    shadow t_max = |y - origin| (1 - 1e-6) - offset(y) / cos(theta_y)         (short of y by y's offset off y's plane)
"""

from __future__ import annotations

from numba import njit

from reference_impl.kernels.config import JIT

# Relative offset of ray origins (intersect._OFFSET_REL), repeated so the kernels need no import of Embree.
_OFFSET_REL = 2.0**-20


@njit(**JIT)
def origin_offset(offset_scene, p0, p1, p2):
    """Intersector.offset for one point."""
    return _OFFSET_REL * max(abs(p0), abs(p1), abs(p2)) + offset_scene


@njit(**JIT)
def shadow_t_max(seg_len, offset_y, cos_y):
    """Where a shadow ray toward y stops: short of y by y's offset measured off y's plane, i.e. offset / cos_y along
    the ray. (A fixed distance along the ray left y's own triangle within float32 rounding of a grazing ray's end:
    2.6e-4 of the furnace's direct light was lost, a bias the stratified sampler's lower noise made visible.)"""
    return seg_len * (1.0 - 1e-6) - offset_y / cos_y
