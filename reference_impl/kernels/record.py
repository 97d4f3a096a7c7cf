"""Recording the rays an engine traces, for :mod:`reference_impl.replay`: each query's float32 ray and Embree's answer,
written into buffers the caller sized.

A record is the tuple (cam_o, cam_d, cam_prim, o, d, prim, s_o, s_d, s_tfar, s_blocked, counts): the camera rays of
the batch and their hits (exactly one row per camera ray), then the closest-hit rays past the camera and their
hits, then the occlusion rays with their tfar and whether they were blocked (1) or not (0). ``counts[0]`` and
``counts[1]`` count the closest-hit and occlusion queries made, also those that did not fit: a count above a
buffer's length tells the caller to size it up and trace the batch again (the rays are the same every time).

An engine takes ``record=None`` in a render, which numba's branch pruning compiles out (``if record is not None``
is decided from the argument's type), so recording costs a render nothing.
"""

from __future__ import annotations

from numba import njit

from reference_impl.kernels.config import JIT_INLINE


@njit(**JIT_INLINE)
def record_camera(record, o32, d32, prim):
    """The batch's camera rays (float32) and their closest hits ``prim``."""
    cam_o, cam_d, cam_prim = record[0], record[1], record[2]
    for i in range(len(prim)):
        cam_o[i, 0], cam_o[i, 1], cam_o[i, 2] = o32[i, 0], o32[i, 1], o32[i, 2]
        cam_d[i, 0], cam_d[i, 1], cam_d[i, 2] = d32[i, 0], d32[i, 1], d32[i, 2]
        cam_prim[i] = prim[i]


@njit(**JIT_INLINE)
def record_closest(record, o0, o1, o2, d0, d1, d2, prim):
    """One closest-hit query past the camera: its ray, rounded to float32 as the query rounds it, and its hit."""
    o, d, out, counts = record[3], record[4], record[5], record[10]
    q = counts[0]
    if q < len(out):
        o[q, 0], o[q, 1], o[q, 2] = o0, o1, o2
        d[q, 0], d[q, 1], d[q, 2] = d0, d1, d2
        out[q] = prim
    counts[0] = q + 1


@njit(**JIT_INLINE)
def record_occluded(record, o0, o1, o2, d0, d1, d2, tfar, blocked):
    """One occlusion query: its ray, its float32 ``tfar`` and whether it was blocked."""
    o, d, t, out, counts = record[6], record[7], record[8], record[9], record[10]
    q = counts[1]
    if q < len(out):
        o[q, 0], o[q, 1], o[q, 2] = o0, o1, o2
        d[q, 0], d[q, 1], d[q, 2] = d0, d1, d2
        t[q] = tfar
        out[q] = 1 if blocked else 0
    counts[1] = q + 1
