"""The light connections of many light samples at once, one array per coordinate: for sample q (a point y on a
light's triangle of unit front normal N_y, drawn with density p(y) per unit area) seen from the vertex x of its
path (its shadow rays leaving from o):

    l     = y - x,   r^2 = l . l,   wi = l / sqrt(r^2),   cos_y = -N_y . wi
    scale = cos_y / (r^2 p(y))                          (Le G / (p cos_x) = Le scale: :func:`.direct.point_connection`)
    g     = y - o,   |g| = sqrt(g . g),   d = g / |g|
    t_max = max(|g| (1 - 1e-6) - offset(y) / cos_y, 0)  (the shadow ray: :func:`.direct.connection_ray`)

Each number is computed by the same operations in the same order as those one-sample functions compute it (the
same bits: division and square root are correctly rounded in every lane). Up to :data:`CHUNK` samples go through
one call, their numbers in the rows of one scratch buffer (:func:`scratch`), one row per coordinate, each
:data:`CHUNK` long: rows a constant distance apart are what lets LLVM see that the loop's stores do not overlap its
loads, so it vectorises it and the square roots and divisions of eight samples go together (separate arrays, or
one buffer with rows a run-time distance apart, leave it scalar: their overlap it would have to test at run time).
One sample at a time, each waited for its own chain (docs/performance.md, "Issue 39: the light connections in
arrays of coordinates"). Samples whose connection brings nothing (r^2 = 0, cos_y <= 0) get numbers nobody reads.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import JIT, JIT_BORROW
from reference_impl.kernels.surface import origin_offset, shadow_t_max
from reference_impl.kernels.warps import dot3

#: samples per call of :func:`point_connections`: the length of a row of its scratch buffer (23 rows: 23.5 KB)
CHUNK = 128
# the scratch buffer's rows: what a sample is given (y, N_y, p(y), x, o) ...
Y0, Y1, Y2, M0, M1, M2, PDF, X0, X1, X2, O0, O1, O2 = range(13)
# ... and what it gets: r^2, cos_y, scale, wi, the shadow ray's direction d and t_max
DIST2, COS_Y, SCALE, W0, W1, W2, R0, R1, R2, TFAR = range(13, 23)
ROWS = 23


@njit(**JIT)
def scratch():
    """A scratch buffer for :func:`point_connections`: :data:`ROWS` rows of :data:`CHUNK` numbers, row k at
    ``k * CHUNK``."""
    return np.empty(ROWS * CHUNK)


@njit(**JIT_BORROW)
def point_connections(w, count, offset_scene):
    """The connections (module docstring) of samples 0 .. count - 1 (count <= :data:`CHUNK`) of the scratch buffer
    ``w``: from its rows Y*, M*, PDF, X*, O* into its rows DIST2, COS_Y, SCALE, W* (wi), R* (d) and TFAR; offsets
    with the scene's ``offset_scene`` (:func:`.surface.origin_offset`). cos_x = N_x . wi is the BSDF door's
    (:func:`.path.connect`)."""
    for q in range(count):
        y0, y1, y2 = w[Y0 * CHUNK + q], w[Y1 * CHUNK + q], w[Y2 * CHUNK + q]
        l0, l1, l2 = y0 - w[X0 * CHUNK + q], y1 - w[X1 * CHUNK + q], y2 - w[X2 * CHUNK + q]
        d2 = dot3(l0, l1, l2, l0, l1, l2)
        inv_dist = 1.0 / math.sqrt(d2)
        wi0, wi1, wi2 = l0 * inv_dist, l1 * inv_dist, l2 * inv_dist
        cy = -dot3(w[M0 * CHUNK + q], w[M1 * CHUNK + q], w[M2 * CHUNK + q], wi0, wi1, wi2)
        w[DIST2 * CHUNK + q] = d2
        w[COS_Y * CHUNK + q] = cy
        w[SCALE * CHUNK + q] = cy / (d2 * w[PDF * CHUNK + q])
        w[W0 * CHUNK + q], w[W1 * CHUNK + q], w[W2 * CHUNK + q] = wi0, wi1, wi2
        g0, g1, g2 = y0 - w[O0 * CHUNK + q], y1 - w[O1 * CHUNK + q], y2 - w[O2 * CHUNK + q]
        seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
        inv_seg = 1.0 / seg_len
        w[R0 * CHUNK + q], w[R1 * CHUNK + q], w[R2 * CHUNK + q] = g0 * inv_seg, g1 * inv_seg, g2 * inv_seg
        w[TFAR * CHUNK + q] = max(shadow_t_max(seg_len, origin_offset(offset_scene, y0, y1, y2), cy), 0.0)


__all__ = ["CHUNK", "ROWS", "point_connections", "scratch"]
