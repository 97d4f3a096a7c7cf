"""Embree queries from compiled code, through Embree 4's C API (:mod:`reference_impl.embree_c`): ray buffers, one
ray's closest hit or occlusion, 16-ray packets, the batch queries of the wavefront, and the clock that times them.

Rays go to Embree in float32 (origins and directions rounded as numpy's ``astype`` rounds), tnear 0; a shadow ray
is an occlusion (any-hit) query on 0 < t < tfar, which Embree answers by setting tfar to -inf.

Embree holds the triangles only. The scene's analytic spheres (``spheres``: per sphere its centre and radius, the
first four columns of :attr:`.records.SceneTables.sphere`; None compiles the tests out) are tested here, in float64, after Embree's query: the
nearer root 0 < t of |o + t d - c| = r (:func:`sphere_nearest`) wins where it is nearer than Embree's triangle, and
the hit is primitive ``base`` + s (``base``: the number of Embree's primitives; ``prim_to_tri`` maps it to the
sphere's first triangle). One test per sphere and query, a few nanoseconds each: on the scenes measured, faster than
Embree's own sphere primitive (a second acceleration structure to traverse: 91 against 51 ns a ray on envmap, whose
icosphere's 5120 triangles took 73) and decided in float64.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl import embree_c
from reference_impl.kernels.config import JIT, JIT_BORROW, JIT_INLINE
from reference_impl.kernels.surface import sphere_roots

# One query in TIMING_STRIDE is timed (two clock reads); the time in Embree is the sampled time, less the cost of a
# clock read (measured at the start of each call), times the stride.
TIMING_STRIDE = 64


@njit(**JIT)
def ray_buffer():
    """A 16-byte aligned RTCRayHit (uint32 words) and its float32 view."""
    raw = np.empty(embree_c.RAY_WORDS + 4, np.uint32)
    skip = ((16 - raw.ctypes.data % 16) % 16) // 4
    words = raw[skip:skip + embree_c.RAY_WORDS]
    return words, words.view(np.float32)


@njit(**JIT_INLINE)
def _set_ray(words, floats, o0, o1, o2, d0, d1, d2, tfar):
    """Fill an RTCRay: float32 origin and direction (rounded as numpy's astype rounds), tnear 0, ``tfar``."""
    floats[0], floats[1], floats[2], floats[3] = o0, o1, o2, 0.0
    floats[4], floats[5], floats[6], floats[7] = d0, d1, d2, 0.0
    floats[embree_c.W_TFAR] = tfar
    words[embree_c.W_MASK] = embree_c.INVALID_ID  # every mask bit
    words[embree_c.W_ID] = 0
    words[embree_c.W_FLAGS] = 0


@njit(**JIT)
def sphere_nearest(spheres, o0, o1, o2, d0, d1, d2, t_max):
    """The sphere (a row of ``spheres``: c, r) whose nearer root 0 < t < ``t_max`` of |o + t d - c| = r is the
    nearest (unit d), and that t; (-1, t_max) where none is. The roots are :func:`.surface.sphere_roots`', which
    :func:`.surface.sphere_hit_point` takes too."""
    best = -1
    for s in range(spheres.shape[0]):
        t0, t1, disc = sphere_roots(spheres[s, 0], spheres[s, 1], spheres[s, 2], spheres[s, 3], o0, o1, o2, d0, d1,
                                    d2)
        if disc < 0.0:
            continue
        t = t0 if t0 > 0.0 else t1
        if 0.0 < t < t_max:
            best, t_max = s, t
    return best, t_max


@njit(**JIT_INLINE)
def closest_prim(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, spheres, base):
    """The closest hit of one ray: Embree's triangle (float32 coordinates) or, nearer, a sphere (float64,
    :func:`sphere_nearest`, primitive ``base`` + s); -1 for a miss."""
    _set_ray(words, floats, o0, o1, o2, d0, d1, d2, np.inf)
    words[embree_c.W_GEOM_ID] = embree_c.INVALID_ID
    embree_c.rtc_intersect1(scene_ptr, words.ctypes.data, 0)
    p = np.int64(-1)
    if words[embree_c.W_GEOM_ID] != embree_c.INVALID_ID:
        p = np.int64(words[embree_c.W_PRIM_ID])
    if spheres is not None and spheres.shape[0] > 0:
        t_max = np.float64(floats[embree_c.W_TFAR]) if p >= 0 else np.inf
        s, _t = sphere_nearest(spheres, o0, o1, o2, d0, d1, d2, t_max)
        if s >= 0:
            p = np.int64(base + s)
    return p


@njit(**JIT_INLINE)
def closest_prim_within(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, tfar, spheres, base):
    """:func:`closest_prim` on the segment 0 < t < ``tfar`` only (a shadow ray that must know what it met: the
    cut-outs' transmittance, :mod:`.cutout`); -1 where nothing is met."""
    _set_ray(words, floats, o0, o1, o2, d0, d1, d2, tfar)
    words[embree_c.W_GEOM_ID] = embree_c.INVALID_ID
    embree_c.rtc_intersect1(scene_ptr, words.ctypes.data, 0)
    p = np.int64(-1)
    t_max = np.float64(tfar)
    if words[embree_c.W_GEOM_ID] != embree_c.INVALID_ID:
        p = np.int64(words[embree_c.W_PRIM_ID])
        t_max = np.float64(floats[embree_c.W_TFAR])
    if spheres is not None and spheres.shape[0] > 0:
        s, _t = sphere_nearest(spheres, o0, o1, o2, d0, d1, d2, t_max)
        if s >= 0:
            p = np.int64(base + s)
    return p


@njit(**JIT_INLINE)
def occluded(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, tfar, spheres):
    """Whether anything blocks the segment 0 < t < ``tfar``: a sphere (float64, :func:`sphere_nearest`), or
    Embree's any-hit query (it sets tfar to -inf)."""
    if spheres is not None and spheres.shape[0] > 0 and sphere_nearest(spheres, o0, o1, o2, d0, d1, d2,
                                                                           np.float64(tfar))[0] >= 0:
        return True
    _set_ray(words, floats, o0, o1, o2, d0, d1, d2, tfar)
    embree_c.rtc_occluded1(scene_ptr, words.ctypes.data, 0)
    return floats[embree_c.W_TFAR] < 0


@njit(**JIT)
def packet_buffer():
    """A 64-byte aligned RTCRayHit16 (uint32 words; room for a packet of any width), its float32 view, and the 16
    lanes' valid flags (int32)."""
    raw = np.empty(embree_c.PACKET_WORDS + 16 + 32, np.uint32)
    skip = ((64 - raw.ctypes.data % 64) % 64) // 4
    words = raw[skip:skip + embree_c.PACKET_WORDS]
    valid = raw[skip + embree_c.PACKET_WORDS:skip + embree_c.PACKET_WORDS + 16].view(np.int32)
    return words, words.view(np.float32), valid


@njit(**JIT_INLINE)
def packet_lane(words, floats, valid, width, lane, o0, o1, o2, d0, d1, d2, tfar):
    """Fill lane ``lane`` of a packet of ``width`` rays (RTCRayHit4/8/16: field f of lane l at word f * width + l,
    :func:`packet_buffer`) as :func:`_set_ray` fills one ray: float32 origin and direction (rounded as numpy's
    astype rounds), tnear 0, ``tfar``, every mask bit; the lane valid."""
    valid[lane] = -1
    floats[lane], floats[width + lane], floats[2 * width + lane] = o0, o1, o2
    floats[3 * width + lane] = 0.0  # tnear
    floats[4 * width + lane], floats[5 * width + lane], floats[6 * width + lane] = d0, d1, d2
    floats[7 * width + lane] = 0.0  # time
    floats[8 * width + lane] = tfar
    words[9 * width + lane] = embree_c.INVALID_ID  # mask
    words[10 * width + lane] = 0  # id
    words[11 * width + lane] = 0  # flags


@njit(**JIT_INLINE)
def packet_rest(words, floats, valid, width, m):
    """Lanes m, ..., width - 1 of a packet invalid (a unit direction, all else 0), after lanes 0 .. m - 1 were
    filled with :func:`packet_lane`."""
    for lane in range(m, width):
        packet_lane(words, floats, valid, width, lane, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
        valid[lane] = 0


@njit(**JIT_INLINE)
def _query_arguments(flags):
    """An RTCIntersectArguments (:data:`.embree_c.ARGUMENT_WORDS`) with the query ``flags`` and every feature on."""
    args = np.zeros(embree_c.ARGUMENT_WORDS, np.uint32)
    args[0] = flags
    args[1] = embree_c.FEATURE_FLAG_ALL
    return args


@njit(**JIT_INLINE)
def coherent_arguments():
    """:func:`_query_arguments` with ``RTC_RAY_QUERY_FLAG_COHERENT``: Embree's traversal for a packet of rays that
    travel together. The closest hit does not depend on the order the tree is traversed in, but for hits at the same
    distance (a ray through an edge shared by two triangles), of which the first found is kept: the 215 pinned images
    are unchanged by it. What it buys: docs/performance.md, "Issue 39: light samples drawn first, camera packets
    marked coherent"."""
    return _query_arguments(embree_c.QUERY_FLAG_COHERENT)


@njit(**JIT_INLINE)
def incoherent_arguments():
    """:func:`_query_arguments` with no query flag (``RTC_RAY_QUERY_FLAG_INCOHERENT``): Embree's traversal for a
    packet of rays that need not travel together (the next vertices of several paths), the one it takes when given
    none."""
    return _query_arguments(0)


@njit(**JIT_INLINE)
def intersect_packet(scene_ptr, width, words, floats, valid, m, out, at, spheres, base, args):
    """Closest hits of the m rays a packet of ``width`` holds (:func:`packet_lane`, :func:`packet_rest`), one query
    (``rtcIntersect16``, ``8`` or ``4``, with the RTCIntersectArguments ``args``), then the spheres lane by lane
    (from the float32 rays the packet holds): out[at + lane] = the primitive id, -1 for a miss. The hits of one
    query per ray (:func:`closest_prim`) of the same float32 rays."""
    geom, prim = embree_c.P_GEOM_ID * width, embree_c.P_PRIM_ID * width
    for lane in range(width):
        words[geom + lane] = embree_c.INVALID_ID
    if width == 16:
        embree_c.rtc_intersect16(valid.ctypes.data, scene_ptr, words.ctypes.data, args.ctypes.data)
    elif width == 8:
        embree_c.rtc_intersect8(valid.ctypes.data, scene_ptr, words.ctypes.data, args.ctypes.data)
    else:
        embree_c.rtc_intersect4(valid.ctypes.data, scene_ptr, words.ctypes.data, args.ctypes.data)
    for lane in range(m):
        if words[geom + lane] == embree_c.INVALID_ID:
            out[at + lane] = -1
        else:
            out[at + lane] = np.int64(words[prim + lane])
    if spheres is not None and spheres.shape[0] > 0:
        for lane in range(m):
            t_max = np.float64(floats[8 * width + lane]) if out[at + lane] >= 0 else np.inf
            s, _t = sphere_nearest(spheres, np.float64(floats[lane]), np.float64(floats[width + lane]),
                                   np.float64(floats[2 * width + lane]), np.float64(floats[4 * width + lane]),
                                   np.float64(floats[5 * width + lane]), np.float64(floats[6 * width + lane]), t_max)
            if s >= 0:
                out[at + lane] = base + s


@njit(**JIT)
def closest_prims_coherent(scene_ptr, width, o32, d32, out, start, stop, words, floats, valid, spheres, base):
    """Closest hits of rays ``start:stop``, ``width`` per packet query (:func:`intersect_packet`; one query per ray
    where ``width`` is 1): for rays that start together and point nearly the same way (one pixel's camera rays),
    Embree traverses its tree once for a packet, told that they do (:func:`coherent_arguments`). The same hits as one
    query per ray (:func:`closest_prim`)."""
    if width == 1:
        for i in range(start, stop):
            out[i] = closest_prim(scene_ptr, words, floats, np.float64(o32[i, 0]), np.float64(o32[i, 1]),
                                  np.float64(o32[i, 2]), np.float64(d32[i, 0]), np.float64(d32[i, 1]),
                                  np.float64(d32[i, 2]), spheres, base)
        return
    hits = np.empty(embree_c.PACKET, np.int64)
    args = coherent_arguments()
    for s0 in range(start, stop, width):
        m = min(width, stop - s0)
        for lane in range(m):
            i = s0 + lane
            packet_lane(words, floats, valid, width, lane, o32[i, 0], o32[i, 1], o32[i, 2], d32[i, 0], d32[i, 1],
                        d32[i, 2], np.inf)
        packet_rest(words, floats, valid, width, m)
        intersect_packet(scene_ptr, width, words, floats, valid, m, hits, 0, spheres, base, args)
        for lane in range(m):
            out[s0 + lane] = hits[lane]


@njit(**JIT)
def closest_prims_packets(scene_ptr, width, o32, d32, out, spheres, base):
    """Closest hits of a batch of camera rays, ``width`` consecutive rays per packet query."""
    words, floats, valid = packet_buffer()
    closest_prims_coherent(scene_ptr, width, o32, d32, out, 0, o32.shape[0], words, floats, valid, spheres, base)


@njit(**JIT)
def closest_prims(scene_ptr, o32, d32, out, spheres, base):
    """Closest hits of a batch of float32 rays (Intersector.closest_prims): primitive ids, -1 for a miss."""
    words, floats = ray_buffer()
    for i in range(o32.shape[0]):
        out[i] = closest_prim(scene_ptr, words, floats, np.float64(o32[i, 0]), np.float64(o32[i, 1]),
                              np.float64(o32[i, 2]), np.float64(d32[i, 0]), np.float64(d32[i, 1]),
                              np.float64(d32[i, 2]), spheres, base)


@njit(**JIT)
def occluders(scene_ptr, o32, d32, tfar, out, spheres):
    """Any-hit queries of a batch (Intersector.occluders): 0 where something blocks the segment, -1 where not."""
    words, floats = ray_buffer()
    for i in range(o32.shape[0]):
        blocked = occluded(scene_ptr, words, floats, np.float64(o32[i, 0]), np.float64(o32[i, 1]),
                           np.float64(o32[i, 2]), np.float64(d32[i, 0]), np.float64(d32[i, 1]), np.float64(d32[i, 2]),
                           np.float64(tfar[i]), spheres)
        out[i] = 0 if blocked else -1


@njit(**JIT_INLINE)
def now_ns(ts):
    """CLOCK_MONOTONIC in nanoseconds (``ts``: room for a struct timespec, two int64)."""
    embree_c.clock_gettime(embree_c.CLOCK_MONOTONIC, ts.ctypes.data)
    return ts[0] * 1_000_000_000 + ts[1]


@njit(**JIT_BORROW)
def closest_prim_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1, o2, d0, d1, d2, spheres, base):
    """:func:`closest_prim`, counted, and timed when it is query number TIMING_STRIDE, 2 TIMING_STRIDE, ...:
    (primitive, queries, sampled_ns) with the count and the sampled nanoseconds brought up to date."""
    queries += 1
    if queries % TIMING_STRIDE == 0:
        t_start = now_ns(ts)
        p = closest_prim(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, spheres, base)
        return p, queries, sampled_ns + (now_ns(ts) - t_start)
    return closest_prim(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, spheres, base), queries, sampled_ns


@njit(**JIT_BORROW)
def occluded_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1, o2, d0, d1, d2, tfar, spheres):
    """:func:`occluded`, counted and timed as :func:`closest_prim_timed`: (blocked, queries, sampled_ns)."""
    queries += 1
    if queries % TIMING_STRIDE == 0:
        t_start = now_ns(ts)
        blocked = occluded(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, tfar, spheres)
        return blocked, queries, sampled_ns + (now_ns(ts) - t_start)
    return occluded(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, tfar, spheres), queries, sampled_ns



@njit(**JIT_BORROW)
def closest_prim_within_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1, o2, d0, d1, d2, tfar,
                              spheres, base):
    """:func:`closest_prim_within`, counted and timed as :func:`closest_prim_timed`: (primitive, queries,
    sampled_ns)."""
    queries += 1
    if queries % TIMING_STRIDE == 0:
        t_start = now_ns(ts)
        p = closest_prim_within(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, tfar, spheres, base)
        return p, queries, sampled_ns + (now_ns(ts) - t_start)
    return (closest_prim_within(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, tfar, spheres, base), queries,
            sampled_ns)
