"""Embree 4's C API, for compiled code: the scene is built through ctypes, and numba kernels call ``rtcIntersect1`` and
``rtcOccluded1`` themselves, one ray at a time, without a pass through Python or numpy between queries.

The library is the ``libembree4`` that the embreex wheel ships (``embreex.libs``); embreex's own Python API calls the
same two functions once per ray in a Cython loop, so the queries are Embree's either way. Calling them from the
kernels lets a path be traced from its camera ray to its end in one loop (``kernels.path.trace_paths``), which removes the
wavefront's memory traffic: docs/performance.md. The symbols are made visible to LLVM with
``load_library_permanently``, so kernels that call them can be cached by numba (the call goes by symbol name, not by an
address baked into the machine code).

Ray layouts (Embree 4, ``rtcore_ray.h``), as 32-bit words: ``RTCRay`` is org x, y, z, tnear, dir x, y, z, time, tfar,
mask, id, flags (48 bytes); ``RTCRayHit`` is that ray followed by ``RTCHit``: Ng x, y, z, u, v, primID, geomID,
instID... The structures must be 16-byte aligned (:func:`ray_buffer`).
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os

import embreex
import llvmlite.binding as llvm
import numpy as np
from numba import types

INVALID_ID = 0xFFFFFFFF  # RTC_INVALID_GEOMETRY_ID
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
RAY_WORDS = 32  # room for an RTCRayHit (at most 96 bytes with instance ids), in uint32 words
# Word offsets in a ray buffer.
W_TFAR, W_MASK, W_ID, W_FLAGS = 8, 9, 10, 11
W_PRIM_ID, W_GEOM_ID = 12 + 5, 12 + 6
# RTCRayHit16: field f of lane l at word 16 f + l; the ray's 12 fields, then the hit's (primID, geomID 6th and 7th).
PACKET = 16  # the widest packet (RTCRayHit16): a packet of width w has field f of lane l at word f * w + l
PACKET_WORDS = 16 * 24  # up to 12 ray fields and 12 hit fields
P_PRIM_ID, P_GEOM_ID = 12 + 5, 12 + 6  # fields of the hit, after the ray's 12
# RTCIntersectArguments (Embree 4, rtcore.h): flags, feature_mask (uint32 each), then the context, filter and
# intersect pointers (null: none), with room to spare for a build that adds a field; as uint32 words.
ARGUMENT_WORDS = 16
QUERY_FLAG_COHERENT = 1 << 16  # RTC_RAY_QUERY_FLAG_COHERENT: Embree's traversal for rays that travel together
FEATURE_FLAG_ALL = 0xFFFFFFFF  # RTC_FEATURE_FLAG_ALL, what rtcInitIntersectArguments sets


@functools.cache
def library_path() -> str:
    """The libembree4 shared library inside the installed embreex wheel."""
    here = os.path.dirname(embreex.__file__)
    found = sorted(glob.glob(os.path.join(here, "..", "embreex.libs", "libembree4*.so*")))
    found += sorted(glob.glob(os.path.join(here, "libembree4*.so*")))
    if not found:
        raise ImportError(f"no libembree4 shared library next to embreex ({here})")
    return os.path.realpath(found[0])


@functools.cache
def library() -> ctypes.CDLL:
    """The library, loaded once, with the signatures this module uses; its symbols also made visible to LLVM."""
    path = library_path()
    llvm.load_library_permanently(path)
    lib = ctypes.CDLL(path)
    vp = ctypes.c_void_p
    signatures = {
        "rtcNewDevice": (vp, [ctypes.c_char_p]),
        "rtcNewScene": (vp, [vp]),
        "rtcNewGeometry": (vp, [vp, ctypes.c_int]),
        "rtcSetNewGeometryBuffer": (vp, [vp, ctypes.c_int, ctypes.c_uint, ctypes.c_int, ctypes.c_size_t,
                                         ctypes.c_size_t]),
        "rtcCommitGeometry": (None, [vp]),
        "rtcAttachGeometry": (ctypes.c_uint, [vp, vp]),
        "rtcReleaseGeometry": (None, [vp]),
        "rtcCommitScene": (None, [vp]),
        "rtcReleaseScene": (None, [vp]),
        "rtcReleaseDevice": (None, [vp]),
        "rtcGetDeviceError": (ctypes.c_int, [vp]),
    }
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = restype, argtypes
    return lib


_DEVICE_PROPERTY_VERSION = 0  # RTC_DEVICE_PROPERTY_VERSION (rtcore_device.h): major * 10000 + minor * 100 + patch
# RTC_DEVICE_PROPERTY_NATIVE_RAY{4,8,16}_SUPPORTED: whether packets of that width run on the processor's own vector
# width (else Embree emulates them: 16-wide packets on an AVX2 processor took 1.3-1.4x the time of one query per ray)
_NATIVE_WIDTH_PROPERTIES = ((16, 34), (8, 33), (4, 32))


@functools.cache
def device_version() -> str:
    """The Embree library's own version, as a device reports it (``rtcGetDeviceProperty(device,
    RTC_DEVICE_PROPERTY_VERSION)`` = major * 10000 + minor * 100 + patch), e.g. "4.4.0"; a device is made and
    released for it (about 0.3 ms)."""
    lib = library()
    get = lib.rtcGetDeviceProperty
    get.restype, get.argtypes = ctypes.c_ssize_t, [ctypes.c_void_p, ctypes.c_int]
    device = lib.rtcNewDevice(None)
    if not device:
        raise RuntimeError("Embree: rtcNewDevice failed")
    try:
        number = int(get(device, _DEVICE_PROPERTY_VERSION))
    finally:
        lib.rtcReleaseDevice(device)
    return f"{number // 10000}.{number // 100 % 100}.{number % 100}"


def native_packet_width(device) -> int:
    """The widest packet (16, 8 or 4 rays) that ``device`` traces natively, 1 if none: the packet width the kernels
    use (``rtcIntersect{4,8,16}``, ``rtcOccluded{4,8,16}``)."""
    get = library().rtcGetDeviceProperty
    get.restype, get.argtypes = ctypes.c_ssize_t, [ctypes.c_void_p, ctypes.c_int]
    for width, prop in _NATIVE_WIDTH_PROPERTIES:
        if get(device, prop) == 1:
            return width
    return 1


library()  # before any kernel that calls Embree is compiled or loaded from numba's cache

# void rtcIntersect1(RTCScene, RTCRayHit*, RTCIntersectArguments*); void rtcOccluded1(RTCScene, RTCRay*, ...);
# pointers passed as integers (the same registers on x86-64 and aarch64).
rtc_intersect1 = types.ExternalFunction("rtcIntersect1", types.void(types.uintp, types.uintp, types.uintp))
rtc_occluded1 = types.ExternalFunction("rtcOccluded1", types.void(types.uintp, types.uintp, types.uintp))
# void rtcIntersect16(const int* valid, RTCScene, RTCRayHit16*, RTCIntersectArguments*): 16 rays at once, for the
# camera rays of one pixel's samples, which travel together (structure of arrays, 64-byte aligned).
rtc_intersect16 = types.ExternalFunction("rtcIntersect16",
                                         types.void(types.uintp, types.uintp, types.uintp, types.uintp))
# The same for packets of 8 and 4 rays (RTCRayHit8 / RTCRayHit4: the same layout, 8 or 4 lanes per field).
rtc_intersect8 = types.ExternalFunction("rtcIntersect8", types.void(types.uintp, types.uintp, types.uintp, types.uintp))
rtc_intersect4 = types.ExternalFunction("rtcIntersect4", types.void(types.uintp, types.uintp, types.uintp, types.uintp))
# void rtcOccluded16(const int* valid, RTCScene, RTCRay16*, RTCOccludedArguments*), and its 8- and 4-ray forms:
# shadow rays in packets (RTCRay16: the ray fields of RTCRayHit16; a blocked lane's tfar set to -inf).
rtc_occluded16 = types.ExternalFunction("rtcOccluded16", types.void(types.uintp, types.uintp, types.uintp, types.uintp))
rtc_occluded8 = types.ExternalFunction("rtcOccluded8", types.void(types.uintp, types.uintp, types.uintp, types.uintp))
rtc_occluded4 = types.ExternalFunction("rtcOccluded4", types.void(types.uintp, types.uintp, types.uintp, types.uintp))
# int clock_gettime(clockid_t, struct timespec*): samples of the time spent in queries.
clock_gettime = types.ExternalFunction("clock_gettime", types.int32(types.int32, types.uintp))
CLOCK_MONOTONIC = 1


class TriangleScene:
    """A committed Embree scene of one triangle mesh (which may have no triangles: a scene of spheres alone, which
    the queries test themselves, :mod:`reference_impl.kernels.queries`). ``pointer`` is the RTCScene handle the
    kernels take.

    Primitive ids are the rows of ``triangles``. Embree copies the vertices and indices, so the arrays may go away.
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray):
        lib = library()
        self._lib = lib
        self._device = lib.rtcNewDevice(None)
        if not self._device:
            raise RuntimeError("Embree: rtcNewDevice failed")
        self._scene = lib.rtcNewScene(self._device)
        v = np.ascontiguousarray(vertices, dtype=np.float32)
        t = np.ascontiguousarray(triangles, dtype=np.uint32)
        if len(t):
            geometry = lib.rtcNewGeometry(self._device, _GEOMETRY_TYPE_TRIANGLE)
            vb = lib.rtcSetNewGeometryBuffer(geometry, _BUFFER_TYPE_VERTEX, 0, _FORMAT_FLOAT3, 12, max(len(v), 1))
            ib = lib.rtcSetNewGeometryBuffer(geometry, _BUFFER_TYPE_INDEX, 0, _FORMAT_UINT3, 12, len(t))
            if not vb or not ib:
                raise RuntimeError(f"Embree: cannot allocate geometry buffers (error "
                                   f"{lib.rtcGetDeviceError(self._device)})")
            ctypes.memmove(vb, v.ctypes.data, v.nbytes)
            ctypes.memmove(ib, t.ctypes.data, t.nbytes)
            lib.rtcCommitGeometry(geometry)
            lib.rtcAttachGeometry(self._scene, geometry)
            lib.rtcReleaseGeometry(geometry)
        lib.rtcCommitScene(self._scene)
        error = lib.rtcGetDeviceError(self._device)
        if error:
            raise RuntimeError(f"Embree: scene build failed (error {error})")
        self.pointer = int(self._scene)
        self.packet_width = native_packet_width(self._device)

    def __del__(self):
        lib = getattr(self, "_lib", None)
        if lib is None:
            return
        if getattr(self, "_scene", None):
            lib.rtcReleaseScene(self._scene)
            self._scene = None
        if getattr(self, "_device", None):
            lib.rtcReleaseDevice(self._device)
            self._device = None
