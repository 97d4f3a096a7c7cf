"""Recording the rays an engine traces, for :mod:`reference_impl.replay`: each query's ray and Embree's answer,
written into buffers the caller sized (:class:`.records.RayRecord`).

The camera rays of the batch and their hits take exactly one row per camera ray; the closest-hit rays past the
camera and the occlusion rays (with their tfar and whether they were blocked) one row per query, while there is
room. ``counts`` counts the closest-hit and occlusion queries made, also those that did not fit: a count above a
buffer's length tells the caller to size it up and trace the batch again (the rays are the same every time). An
engine that sends its rays in packets (:mod:`.blocks`) also records how many consecutive rays each of its calls sent
(:func:`record_group`), so that a replay sends the same packets.

An engine takes ``record=None`` in a render, which numba's branch pruning compiles out (``if record is not None``
is decided from the argument's type), so recording costs a render nothing.
"""

from __future__ import annotations

from numba import njit

from reference_impl.kernels.config import JIT_INLINE
from reference_impl.kernels.records import COUNT_CLOSEST, COUNT_CLOSEST_GROUPS, COUNT_OCCLUSION, COUNT_OCCLUSION_GROUPS


@njit(**JIT_INLINE)
def record_camera(record, o32, d32, prim):
    """The batch's camera rays (float32) and their closest hits ``prim``."""
    cam_o, cam_d, cam_prim = record.camera_origin, record.camera_direction, record.camera_prim
    for i in range(len(prim)):
        cam_o[i, 0], cam_o[i, 1], cam_o[i, 2] = o32[i, 0], o32[i, 1], o32[i, 2]
        cam_d[i, 0], cam_d[i, 1], cam_d[i, 2] = d32[i, 0], d32[i, 1], d32[i, 2]
        cam_prim[i] = prim[i]


@njit(**JIT_INLINE)
def record_closest(record, o0, o1, o2, d0, d1, d2, prim):
    """One closest-hit query past the camera: its float64 ray (as the sphere tests take it; Embree's query rounds it
    to float32) and its hit."""
    o, d, out, counts = record.closest_origin, record.closest_direction, record.closest_prim, record.counts
    q = counts[COUNT_CLOSEST]
    if q < len(out):
        o[q, 0], o[q, 1], o[q, 2] = o0, o1, o2
        d[q, 0], d[q, 1], d[q, 2] = d0, d1, d2
        out[q] = prim
    counts[COUNT_CLOSEST] = q + 1


@njit(**JIT_INLINE)
def record_occluded(record, o0, o1, o2, d0, d1, d2, tfar, blocked):
    """One occlusion query: its float64 ray, its float32 ``tfar`` and whether it was blocked."""
    o, d, t, out = record.occlusion_origin, record.occlusion_direction, record.occlusion_tfar, record.occlusion_blocked
    counts = record.counts
    q = counts[COUNT_OCCLUSION]
    if q < len(out):
        o[q, 0], o[q, 1], o[q, 2] = o0, o1, o2
        d[q, 0], d[q, 1], d[q, 2] = d0, d1, d2
        t[q] = tfar
        out[q] = 1 if blocked else 0
    counts[COUNT_OCCLUSION] = q + 1


@njit(**JIT_INLINE)
def record_group(record, occlusion, count):
    """One call that sent the last ``count`` recorded closest-hit (``occlusion`` False) or occlusion rays as packets
    (their first packet starting at the first of them)."""
    groups = record.occlusion_groups if occlusion else record.closest_groups
    at = COUNT_OCCLUSION_GROUPS if occlusion else COUNT_CLOSEST_GROUPS
    g = record.counts[at]
    if g < len(groups):
        groups[g] = count
    record.counts[at] = g + 1
