"""Compiled kernels of the integrator, in numba: whole paths one at a time, or one bounce of a wavefront.

Two engines trace the same estimator to the same bits (``Settings.engine``): :func:`trace_paths` follows each camera
path from its viewing ray to its end in one loop and asks Embree for each hit and shadow ray on the spot, through
Embree's C API (:mod:`reference_impl.embree_c`); the wavefront of ``integrator.py`` alternates between batched queries
(``intersect.py``) and :func:`bounce` / :func:`resolve_shadow`, which loop over every path of a batch once (it is
used with Ni > 1, where paths branch). Both compute exactly what the numpy definitions compute, with the same
random numbers:

* random numbers: :mod:`reference_impl.rng` (``mix64``, ``path_keys``, ``branch_keys``, ``uniform``,
  ``dimension``) -> :func:`mix64`, :func:`dim_salt`, :func:`uniform`, :func:`branch_salt`;
* warps: :mod:`reference_impl.sampling` -> :func:`cosine_hemisphere`, :func:`uniform_hemisphere`,
  :func:`to_world`, :func:`sample_discrete`;
* light sampling: :mod:`reference_impl.lights` -> :func:`_sample_light_point`, :func:`_sample_surface_point`;
* pixel filters: :mod:`reference_impl.filters` -> :func:`_filter_sample` (box and tent).

The numpy functions stay the documented definitions (the chi^2 tests run them); the kernels repeat the same
formulas, operation for operation (same order of floating-point operations wherever the numpy code fixes one), so
the warps and samplers give the numpy functions' bits. (The shading arithmetic has since been reordered for speed,
one division and three products where three divisions were, so images are no longer those of the numpy integrator
of git 5dd5d08; the two engines agree bit for bit: ``tests/reference_impl/test_engines.py``.) The order of numpy's einsum sums and the last bits of sin/cos/sqrt
come from the numpy build, the CPU and libm, so elsewhere the two may differ in last bits (each still deterministic).
``tests/reference_impl/test_kernel_equivalence.py`` checks the warps, light sampling and random numbers against the numpy
functions, bit for bit.

Every kernel is ``nogil`` (the integrator's thread pool runs them concurrently, as it runs Embree queries) and
sequential within a batch, so results never depend on the thread count or the batch size. ``cache=True`` keeps the
compiled code in ``reference_impl/__pycache__``: only the first import on a machine pays the compile time.
IEEE semantics are kept: no ``fastmath`` (no reassociation, no FMA contraction), and ``error_model="numpy"`` so a
division by zero gives inf/NaN as in numpy instead of raising.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl import embree_c
from reference_impl.rng import (_GOLDEN, _LK, _M1, _M2, _PIXEL_SALT, _ROUND_MULTIPLIER, _S11, _S27, _S30, _S31, _TO_UNIT,
                                _TO_UNIT32)

_JIT = dict(cache=True, nogil=True, error_model="numpy")
# Helpers that take arrays are inlined into their callers at numba's level: a call that passes an array increments
# and decrements its reference count atomically, and with two threads sharing the scene's arrays those atomics took
# a quarter of a render's time (perf: NRT_incref / NRT_decref).
_JIT_INLINE = dict(_JIT, inline="always")

_PI = np.pi
_INV_PI = 1.0 / np.pi  # the same constant as sampling.INV_PI
_PI_4 = np.pi / 4
_PI_2 = np.pi / 2
_TWO_PI = 2.0 * np.pi
_HALF_INV_PI = 0.5 * _INV_PI
_U32 = np.uint64(32)
_U40 = np.uint64(40)
_ONE = np.uint64(1)

# Relative offset of ray origins (intersect._OFFSET_REL), repeated so the kernels need no import of Embree.
_OFFSET_REL = 2.0**-20

# Random-number purposes (integrator: rng.dimension(depth, purpose, index)).
FILM_X, FILM_Y = 0, 1
LIGHT_SELECT, LIGHT_TRIANGLE, LIGHT_U1, LIGHT_U2 = 2, 3, 4, 5
DIRECT_DIR_U1, DIRECT_DIR_U2 = 6, 7
ROULETTE = 8
INDIRECT_U1, INDIRECT_U2 = 9, 10

# Counters, in the order of integrator.COUNTERS.
(C_CAMERA, C_SHADOW, C_SHADOW_SKIPPED, C_HEMI_DIRECT, C_INDIRECT, C_ESCAPED, C_BACK_FACE, C_ROULETTE, C_NONFINITE,
 C_LIGHT_SELECT) = range(10)

# Integer configuration of one bounce (the ``cfg`` array of :func:`bounce`).
(CFG_DEPTH, CFG_EMIT, CFG_ALLOW_NEXT, CFG_ALLOW_INDIRECT, CFG_DIRECT, CFG_ND, CFG_NI, CFG_HEMI_COSINE, CFG_RR,
 CFG_RR_DEPTH, CFG_MUTANTS, CFG_NUM_LIGHTS, CFG_SOBOL, CFG_SPP, CFG_SIZE) = range(15)
# The stratified sampler ("sobol") draws the camera sample (depth 0) and the decisions of the first hit (depth 1:
# light sample, roulette, indirect direction); deeper ones are independent. Measured on the Cornell box, 64 spp: the
# first hit gives nearly all of the gain (MSE 5.6e-4 -> 1.5e-4); going on to depth 2 took 3 % more time for 3 % less
# MSE.
# Float configuration (the ``cfg_f`` array).
CFGF_FIXED_SURVIVAL, CFGF_OFFSET_SCENE, CFGF_SURFACE_PDF, CFGF_SIZE = range(4)

EMIT_NONE, EMIT_ALL, EMIT_MIS = 0, 1, 2  # emission at the hit: not counted, counted, counted with the MIS weight
DIRECT_AREA, DIRECT_MIS, DIRECT_GLOBAL_AREA, DIRECT_HEMI_COSINE, DIRECT_HEMI_UNIFORM = range(5)
DIRECT_MODES = {"area": DIRECT_AREA, "mis": DIRECT_MIS, "global-area": DIRECT_GLOBAL_AREA,
                "hemisphere-cosine": DIRECT_HEMI_COSINE, "hemisphere-uniform": DIRECT_HEMI_UNIFORM}
RR_OFF, RR_ALBEDO, RR_FIXED = 0, 1, 2
RR_MODES = {"off": RR_OFF, "albedo": RR_ALBEDO, "fixed": RR_FIXED}
FILTER_BOX, FILTER_TENT, FILTER_GAUSSIAN = 0, 1, 2
FILTER_KINDS = {"box": FILTER_BOX, "tent": FILTER_TENT, "gaussian": FILTER_GAUSSIAN}

# Planted faults (reference_impl/mutants.py) that live in the kernels, as bits of cfg[CFG_MUTANTS]; each place one
# changes is marked with a comment naming it. ("camera-half-pixel" is an argument of camera_paths; "double-emission" is the
# EMIT_ALL mode chosen by the integrator; "energy-loss-2pct" is the scale of finish_samples.)
M_NO_COSINE, M_COSINE_PDF_PI, M_RR_NO_REWEIGHT, M_LIGHT_PDF_IGNORED, M_NO_RAY_OFFSET = 1, 2, 4, 8, 16
MUTANT_BITS = {"no-cosine": M_NO_COSINE, "cosine-pdf-pi": M_COSINE_PDF_PI, "rr-no-reweight": M_RR_NO_REWEIGHT,
               "light-pdf-ignored": M_LIGHT_PDF_IGNORED, "no-ray-offset": M_NO_RAY_OFFSET}


# ---------------------------------------------------------------------------------------------- random numbers


@njit(**_JIT)
def mix64(x):
    """rng.mix64 on one uint64 (wrapping uint64 arithmetic)."""
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


@njit(**_JIT)
def dim_salt(depth, purpose, index):
    """What rng.uniform adds to a key for dimension rng.dimension(depth, purpose, index): (dim + 1) * golden."""
    dim = (np.uint64(depth) << _U40) | (np.uint64(purpose) << _U32) | np.uint64(index)
    return (dim + _ONE) * _GOLDEN


@njit(**_JIT)
def uniform(key, salt):
    """rng.uniform of one key, with ``salt = dim_salt(...)``: a float64 in [0, 1) with 53 random bits."""
    return np.float64(mix64(key + salt) >> _S11) * _TO_UNIT


@njit(**_JIT)
def branch_salt(branch, depth):
    """rng.branch_keys(keys, branch, depth) is mix64(keys ^ branch_salt(branch, depth))."""
    return mix64((np.uint64(depth & 0xFFFF) << _U32) | np.uint64(branch & 0xFFFFFFFF))


@njit(**_JIT)
def path_key(seed_key, path_id):
    """rng.path_keys for one path id, with ``seed_key = mix64(seed ^ golden)``."""
    return mix64((np.uint64(path_id) * _GOLDEN) ^ seed_key)


_LOW32 = np.uint64(0xFFFFFFFF)
_B1, _B2, _B4, _B8, _B16 = (np.uint64(m) for m in (0x55555555, 0x33333333, 0x0F0F0F0F, 0x00FF00FF, 0x0000FFFF))
_SH1, _SH2, _SH4, _SH8, _SH16 = (np.uint64(v) for v in (1, 2, 4, 8, 16))
_LK0, _LK1, _LK2, _LK3 = _LK
_PIXEL_SALT_U = np.uint64(_PIXEL_SALT)
_GOLDEN_1, _GOLDEN_2, _GOLDEN_3 = (np.uint64((r * int(_GOLDEN)) & ((1 << 64) - 1)) for r in (1, 2, 3))


@njit(**_JIT)
def reverse_bits32(x):
    """rng.reverse_bits32 for one word."""
    x = ((x >> _SH1) & _B1) | ((x & _B1) << _SH1)
    x = ((x >> _SH2) & _B2) | ((x & _B2) << _SH2)
    x = ((x >> _SH4) & _B4) | ((x & _B4) << _SH4)
    x = ((x >> _SH8) & _B8) | ((x & _B8) << _SH8)
    return ((x >> _SH16) | (x << _SH16)) & _LOW32


@njit(**_JIT)
def lk_permutation(x, seed):
    """rng.lk_permutation for one word (uint64 arithmetic; only the low 32 bits are kept)."""
    x = (x + seed) & _LOW32
    x ^= x * _LK0
    x ^= x * _LK1
    x ^= x * _LK2
    x ^= x * _LK3
    return x & _LOW32


@njit(**_JIT)
def pascal32(x):
    """rng.pascal32 for one word."""
    x ^= (x >> _SH1) & _B1
    x ^= (x >> _SH2) & _B2
    x ^= (x >> _SH4) & _B4
    x ^= (x >> _SH8) & _B8
    x ^= (x >> _SH16) & _B16
    return x


@njit(**_JIT)
def pixel_key(seed_key, pixel):
    """rng.pixel_keys for one pixel, with ``seed_key = mix64(seed ^ golden)``."""
    return mix64((np.uint64(pixel) * _GOLDEN) ^ seed_key ^ _PIXEL_SALT_U)


@njit(**_JIT)
def sobol_seeds(pix_key, salt, n):
    """rng.sobol_seeds for one pixel and pair (``salt = dim_salt(...)`` of its first dimension), with what the
    order of its n points needs: (n, 2^k - 1, ceil(k/2), floor(k/3), three order seeds, x seed, y seed)."""
    seed = mix64(pix_key + salt)
    k = 0
    while (1 << k) < n:
        k += 1
    w = np.uint64((1 << k) - 1)
    s1 = np.uint64(max((k + 1) // 2, 1))
    s2 = np.uint64(max(k // 3, 1))
    return (np.uint64(n), w, s1, s2, mix64(seed + _GOLDEN_1), mix64(seed + _GOLDEN_2), mix64(seed + _GOLDEN_3),
            seed >> _U32, mix64(seed) & _LOW32)


@njit(**_JIT)
def _order_round(v, q, w, s1, s2):
    """One round of rng.permutation_element."""
    v = (v + q) & w
    v ^= v >> s1
    v = (v * ((q >> _U32) | _ONE)) & w
    v ^= v >> s2
    v = (v * _ROUND_MULTIPLIER) & w
    return v ^ (v >> s1)


@njit(**_JIT)
def sobol_point(seeds, index):
    """rng.sobol_2d for one point, given the pixel's and pair's ``sobol_seeds``."""
    n, w, s1, s2, q0, q1, q2, seed_x, seed_y = seeds
    v = np.uint64(index)
    while True:
        v = _order_round(_order_round(_order_round(v, q0, w, s1, s2), q1, w, s1, s2), q2, w, s1, s2)
        if v < n:
            break
    x = reverse_bits32(lk_permutation(v, seed_x))
    y = reverse_bits32(lk_permutation(pascal32(v), seed_y))
    return np.float64(x) * _TO_UNIT32, np.float64(y) * _TO_UNIT32


@njit(**_JIT)
def uniform_2d(sobol, seeds, index, key, j, depth, purpose_a, purpose_b):
    """The two uniforms of one decision: point ``index`` of the pixel's stratified set (``sobol``, ``seeds`` of
    its pair), or independent numbers of the path key for dimensions (depth, purpose_a / purpose_b, j)."""
    if sobol:
        return sobol_point(seeds, index)
    return uniform(key, dim_salt(depth, purpose_a, j)), uniform(key, dim_salt(depth, purpose_b, j))


@njit(**_JIT)
def first_hit_seeds(seed_key, pixel, spp, nd, ni):
    """The ``sobol_seeds`` of a pixel's first-hit pairs: (light sample, direct-light direction, roulette, indirect
    direction); Np x Nd, Np x Nd, Np and Np x Ni points. (A light sample's choices of light and triangle reuse its
    point's first coordinate: lights.LightSampler.split_uniform.)"""
    pk = pixel_key(seed_key, pixel)
    return (sobol_seeds(pk, dim_salt(1, LIGHT_U1, 0), spp * nd), sobol_seeds(pk, dim_salt(1, DIRECT_DIR_U1, 0), spp * nd),
            sobol_seeds(pk, dim_salt(1, ROULETTE, 0), spp), sobol_seeds(pk, dim_salt(1, INDIRECT_U1, 0), spp * ni))


# ---------------------------------------------------------------------------------------------------- warps


@njit(**_JIT)
def dot3(a0, a1, a2, b0, b1, b2):
    """A dot product of 3-vectors, summed in the order numpy's ``einsum("ij,ij->i")`` uses for rows of three (two
    SIMD lanes: (a0 b0 + a2 b2) + a1 b1), so the kernels reproduce the numpy estimators' bits."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@njit(**_JIT)
def cosine_hemisphere(u1, u2):
    """sampling.square_to_cosine_hemisphere for one pair of uniforms: local (x, y, z)."""
    r = math.sqrt(u1)
    phi = _TWO_PI * u2
    return r * math.cos(phi), r * math.sin(phi), math.sqrt(max(0.0, 1.0 - u1))


@njit(**_JIT)
def uniform_hemisphere(u1, u2):
    """sampling.square_to_uniform_hemisphere for one pair of uniforms."""
    z = u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = _TWO_PI * u2
    return r * math.cos(phi), r * math.sin(phi), z


@njit(**_JIT)
def hemisphere_pdf(cosine, cos_theta):
    """sampling.hemisphere_pdf: cos / pi ("cosine") or 1 / (2 pi) ("uniform") above the surface, else 0."""
    if cos_theta > 0:
        return cos_theta * _INV_PI if cosine else _HALF_INV_PI
    return 0.0


@njit(**_JIT)
def to_world(lx, ly, lz, n0, n1, n2):
    """sampling.to_world for one direction (frame of sampling.coordinate_frame, Duff et al. 2017)."""
    sign = 1.0 if n2 >= 0 else -1.0
    a = -1.0 / (sign + n2)
    b = n0 * n1 * a
    s0 = 1.0 + sign * (n0 * n0) * a
    s1 = sign * b
    s2 = -sign * n0
    t0 = b
    t1 = sign + (n1 * n1) * a
    t2 = -n1
    return (lx * s0 + ly * t0 + lz * n0, lx * s1 + ly * t1 + lz * n1, lx * s2 + ly * t2 + lz * n2)


@njit(**_JIT)
def sample_hemisphere(cosine, u1, u2, n0, n1, n2):
    """sampling.sample_hemisphere for one normal: world direction, cos(theta) and pdf."""
    if cosine:
        lx, ly, lz = cosine_hemisphere(u1, u2)
    else:
        lx, ly, lz = uniform_hemisphere(u1, u2)
    w0, w1, w2 = to_world(lx, ly, lz, n0, n1, n2)
    return w0, w1, w2, lz, hemisphere_pdf(cosine, lz)


@njit(**_JIT_INLINE)
def sample_discrete(cdf, u):
    """sampling.sample_discrete for one uniform: min(searchsorted(cdf, u, side="right"), len(cdf) - 1)."""
    lo = 0
    hi = len(cdf)
    while lo < hi:
        mid = (lo + hi) >> 1
        if cdf[mid] <= u:
            lo = mid + 1
        else:
            hi = mid
    return min(lo, len(cdf) - 1)


@njit(**_JIT_INLINE)
def _point_on_triangle(corners, tri, u1, u2):
    """lights._uniform_point_on for one triangle: c0 + b1 (c1 - c0) + b2 (c2 - c0)."""
    s = math.sqrt(u1)
    b1 = 1.0 - s
    b2 = u2 * s
    p0 = corners[tri, 0, 0] + b1 * (corners[tri, 1, 0] - corners[tri, 0, 0]) + b2 * (corners[tri, 2, 0] - corners[tri, 0, 0])
    p1 = corners[tri, 0, 1] + b1 * (corners[tri, 1, 1] - corners[tri, 0, 1]) + b2 * (corners[tri, 2, 1] - corners[tri, 0, 1])
    p2 = corners[tri, 0, 2] + b1 * (corners[tri, 1, 2] - corners[tri, 0, 2]) + b2 * (corners[tri, 2, 2] - corners[tri, 0, 2])
    return p0, p1, p2


@njit(**_JIT_INLINE)
def _search_within(within_cdf, f, n, u):
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


@njit(**_JIT_INLINE)
def _sample_light_point(lights, num_lights, corners, u_select, u_tri, u1, u2):
    """LightSampler.sample for one set of uniforms: (light k, triangle, point y)."""
    cdf, triangles, first, count, within_cdf, _pmf, _area = lights
    light = sample_discrete(cdf, u_select) if num_lights > 1 else 0
    f = first[light]
    tri = triangles[f + _search_within(within_cdf, f, count[light], u_tri)]
    p0, p1, p2 = _point_on_triangle(corners, tri, u1, u2)
    return light, tri, p0, p1, p2


@njit(**_JIT_INLINE)
def _sample_surface_point(surfaces, corners, u_tri, u1, u2):
    """TriangleAreaSampler.sample for one set of uniforms: (triangle, point y)."""
    triangles, cdf = surfaces
    tri = triangles[sample_discrete(cdf, u_tri)]
    p0, p1, p2 = _point_on_triangle(corners, tri, u1, u2)
    return tri, p0, p1, p2


_BELOW_ONE = np.nextafter(1.0, 0.0)


@njit(**_JIT)
def rescale_within(u, lo, hi):
    """lights.rescale_within for one uniform."""
    return min((u - lo) / (hi - lo), _BELOW_ONE)


@njit(**_JIT_INLINE)
def _split_light_uniform(lights, num_lights, u):
    """LightSampler.split_uniform for one uniform: (u_select, u_tri, u1). (Handing on the light and triangle it
    finds, so that _sample_light_point need not search again, measured 4-6 % slower on multi-light: numba's code
    for the path loop got worse.)"""
    cdf, _triangles, first, count, within_cdf, _pmf, _area = lights
    light = 0
    u_tri = u
    if num_lights > 1:
        light = sample_discrete(cdf, u)
        u_tri = rescale_within(u, cdf[light - 1] if light > 0 else 0.0, cdf[light])
    f = first[light]
    lo = _search_within(within_cdf, f, count[light], u_tri)
    return u, u_tri, rescale_within(u_tri, within_cdf[f + lo - 1] if lo > 0 else 0.0, within_cdf[f + lo])


@njit(**_JIT_INLINE)
def _split_surface_uniform(surfaces, u):
    """TriangleAreaSampler.split_uniform for one uniform: (u_tri, u1)."""
    _triangles, cdf = surfaces
    index = sample_discrete(cdf, u)
    return u, rescale_within(u, cdf[index - 1] if index > 0 else 0.0, cdf[index])


@njit(**_JIT)
def _offset(offset_scene, p0, p1, p2):
    """Intersector.offset for one point."""
    return _OFFSET_REL * max(abs(p0), abs(p1), abs(p2)) + offset_scene


@njit(**_JIT)
def shadow_t_max(seg_len, offset_y, cos_y):
    """Where a shadow ray toward y stops: short of y by y's offset measured off y's plane, i.e. offset / cos_y along
    the ray. (A fixed distance along the ray left y's own triangle within float32 rounding of a grazing ray's end:
    2.6e-4 of the furnace's direct light was lost, a bias the stratified sampler's lower noise made visible.)"""
    return seg_len * (1.0 - 1e-6) - offset_y / cos_y


# ------------------------------------------------------------------------------------------------ pixel filter


@njit(**_JIT)
def _filter_sample(kind, u):
    """PixelFilter.sample_1d of the box and tent filters for one uniform: (offset, weight)."""
    if kind == FILTER_BOX:
        return u - 0.5, 1.0
    x = math.sqrt(2.0 * u) - 1.0 if u < 0.5 else 1.0 - math.sqrt(2.0 * (1.0 - u))
    return x, 1.0


@njit(**_JIT)
def camera_paths(pixel, sample, seed_key, spp, width, height, filter_kind, filter_samples, half_pixel,
                 tan_x, tan_y, frame, eye, sobol, out):
    """The viewing rays of camera samples (pixel, sample) (integrator._trace_camera_paths, Camera.generate_rays).

    Box and tent filter offsets are drawn here (``sobol``: from the pixel's stratified set, index ``sample``); the Gaussian's (a table lookup and exp) come in ``filter_samples``
    (dx, dy, weight per sample, from PixelFilter.sample), so that numpy's exp, not libm's, gives their bits.
    Writes the wavefront ``out`` (root, key, origin, direction, origin32, direction32, beta, pdf_dir): root i for
    sample i, float64 origins and unit directions with their float32 copies for Embree, and the throughput (the
    filter weight in all three channels).
    """
    pre_dx, pre_dy, pre_w = filter_samples
    root, key, origin, direction, o32, d32, beta, pdf_dir = out
    n = len(pixel)
    salt_x = dim_salt(0, FILM_X, 0)
    salt_y = dim_salt(0, FILM_Y, 0)
    seeds_pixel = -1
    seeds = sobol_seeds(_ONE, salt_x, 1)
    for i in range(n):
        k = path_key(seed_key, np.uint64(pixel[i]) * np.uint64(spp) + np.uint64(sample[i]))
        key[i] = k
        if filter_kind == FILTER_GAUSSIAN:
            dx, dy, w = pre_dx[i], pre_dy[i], pre_w[i]
        else:
            if sobol:
                if pixel[i] != seeds_pixel:  # a pixel's samples come together: its seeds once
                    seeds_pixel = pixel[i]
                    seeds = sobol_seeds(pixel_key(seed_key, seeds_pixel), salt_x, spp)
                ux, uy = sobol_point(seeds, sample[i])
            else:
                ux, uy = uniform(k, salt_x), uniform(k, salt_y)
            dx, wx = _filter_sample(filter_kind, ux)
            dy, wy = _filter_sample(filter_kind, uy)
            w = wx * wy
        film_x = np.float64(pixel[i] % width) + 0.5 + dx
        film_y = np.float64(pixel[i] // width) + 0.5 + dy
        if half_pixel:  # mutant "camera-half-pixel"
            film_x, film_y = film_x + 0.5, film_y + 0.5
        l0 = (1.0 - 2.0 * film_x / width) * tan_x
        l1 = (1.0 - 2.0 * film_y / height) * tan_y
        d0 = l0 * frame[0, 0] + l1 * frame[0, 1] + frame[0, 2]
        d1 = l0 * frame[1, 0] + l1 * frame[1, 1] + frame[1, 2]
        d2 = l0 * frame[2, 0] + l1 * frame[2, 1] + frame[2, 2]
        norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        inv_norm = 1.0 / norm
        d0, d1, d2 = d0 * inv_norm, d1 * inv_norm, d2 * inv_norm
        direction[i, 0], direction[i, 1], direction[i, 2] = d0, d1, d2
        d32[i, 0], d32[i, 1], d32[i, 2] = d0, d1, d2
        for c in range(3):
            origin[i, c] = eye[c]
            o32[i, c] = eye[c]
        beta[i, 0], beta[i, 1], beta[i, 2] = w, w, w
        root[i] = i
        pdf_dir[i] = 0.0


# ------------------------------------------------------------------------------------------------------- bounce


@njit(**_JIT)
def bounce(state, prim, scene, lights, surfaces, cfg, cfg_f, radiance, counters, hits, rays, out, film_samples):
    """One bounce of the wavefront (integrator._bounce), given the closest hits ``prim`` of the current rays.

    Adds the emission seen at the hits to ``radiance``, draws the Nd direct-light samples of each reflecting hit
    (the rays they need: shadow rays, or closest-hit rays for hemisphere sampling, with what their results are
    multiplied by) and the next wavefront (Russian roulette, Ni branches, hemisphere sampling). The direct light is
    added by :func:`resolve_shadow` / :func:`resolve_hemisphere` once Embree has answered.

    ``state`` and ``out`` are wavefronts (root, key, origin, direction, origin32, direction32, beta, pdf_dir), the
    current one and room for the next (at least Ni rows per row of ``state``). ``hits`` receives the rows of the
    reflecting hits, in order; ``rays`` (owner hit, origin32, direction32, tfar32, value, aux, direction64) the
    direct-light rays of each hit, in sample order, Nd rows per row of ``state``. ``film_samples`` = (pixel, sample,
    seed_key) of the camera samples (rows of ``root``), for the stratified sampler. Returns how many hits,
    direct-light rays and next paths were written.
    """
    root, key, origin, direction, _o32, _d32, beta, pdf_dir = state
    x_root, x_key, x_origin, x_dir, x_o32, x_d32, x_beta, x_pdf = out
    s_owner, s_o32, s_d32, s_tfar, s_value, s_aux, s_dir = rays
    prim_to_tri, tri_normal, tri_v0, corners, emission, light_id, tri_material, two_sided, f_r_table, albedo_max = scene
    light_pmf, light_area = lights[5], lights[6]
    depth = cfg[CFG_DEPTH]
    emit = cfg[CFG_EMIT]
    allow_next = cfg[CFG_ALLOW_NEXT] != 0
    allow_indirect = cfg[CFG_ALLOW_INDIRECT] != 0
    direct = cfg[CFG_DIRECT]
    nd = cfg[CFG_ND]
    ni = cfg[CFG_NI]
    hemi_cosine = cfg[CFG_HEMI_COSINE] != 0
    rr = cfg[CFG_RR]
    mutants = cfg[CFG_MUTANTS]
    num_lights = cfg[CFG_NUM_LIGHTS]
    fixed_survival = cfg_f[CFGF_FIXED_SURVIVAL]
    offset_scene = cfg_f[CFGF_OFFSET_SCENE]
    surface_pdf = cfg_f[CFGF_SURFACE_PDF]
    no_cosine = (mutants & M_NO_COSINE) != 0
    play_roulette = rr != RR_OFF and depth >= cfg[CFG_RR_DEPTH]
    hemi_direct = direct == DIRECT_HEMI_COSINE or direct == DIRECT_HEMI_UNIFORM
    sob = cfg[CFG_SOBOL] != 0 and depth == 1
    film_pixel, film_sample, seed_key = film_samples
    spp = cfg[CFG_SPP]
    fh = first_hit_seeds(seed_key, 0, 1, 1, 1)
    fh_pixel = -1
    si = 0

    n = len(root)
    m = 0
    s = 0
    n_next = 0

    salt_rr = dim_salt(depth, ROULETTE, 0)
    salt_u1 = dim_salt(depth, INDIRECT_U1, 0)
    salt_u2 = dim_salt(depth, INDIRECT_U2, 0)

    for i in range(n):
        p = prim[i]
        if p < 0:
            counters[C_ESCAPED] += 1
            continue
        tri = prim_to_tri[p]
        nx0, nx1, nx2 = tri_normal[tri, 0], tri_normal[tri, 1], tri_normal[tri, 2]
        o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
        d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
        # Intersector.closest_hit: t recomputed in float64 from the triangle's plane.
        denom = dot3(d0, d1, d2, nx0, nx1, nx2)
        t = dot3(tri_v0[tri, 0] - o0, tri_v0[tri, 1] - o1, tri_v0[tri, 2] - o2, nx0, nx1, nx2) / denom
        if not (math.isfinite(t) and t > 0):
            t = 0.0
        x0, x1, x2 = o0 + t * d0, o1 + t * d1, o2 + t * d2
        cos_out = -dot3(d0, d1, d2, nx0, nx1, nx2)
        front = cos_out > 0
        b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
        r = root[i]

        # Emission Le(x -> Theta) (integrator._bounce and _mis_weight_hemisphere).
        if emit != EMIT_NONE:
            fr = 1.0 if front else 0.0
            e0, e1, e2 = emission[tri, 0] * fr, emission[tri, 1] * fr, emission[tri, 2] * fr
            if emit == EMIT_ALL:
                radiance[r, 0] += b0 * e0
                radiance[r, 1] += b1 * e1
                radiance[r, 2] += b2 * e2
            else:
                light = light_id[tri]
                w = 0.0
                if light >= 0 and cos_out > 0:
                    p_light = nd * (light_pmf[light] / light_area[light]) * (t * t) / cos_out
                    p_hemi = pdf_dir[i]
                    w = p_hemi * p_hemi / (p_hemi * p_hemi + p_light * p_light)
                radiance[r, 0] += b0 * e0 * w
                radiance[r, 1] += b1 * e1 * w
                radiance[r, 2] += b2 * e2 * w

        if not allow_next:
            continue
        material = tri_material[tri]
        if not (front or two_sided[material]):
            counters[C_BACK_FACE] += 1
            continue
        if not front:  # the side Theta leaves from
            nx0, nx1, nx2 = -nx0, -nx1, -nx2
        f0, f1, f2 = f_r_table[material, 0], f_r_table[material, 1], f_r_table[material, 2]
        k = key[i]
        if sob:
            if film_pixel[r] != fh_pixel:
                fh_pixel = film_pixel[r]
                fh = first_hit_seeds(seed_key, fh_pixel, spp, nd, ni)
            si = film_sample[r]
        h = m
        hits[h] = i
        m += 1
        off_x = _offset(offset_scene, x0, x1, x2)
        ox0, ox1, ox2 = x0 + off_x * nx0, x1 + off_x * nx1, x2 + off_x * nx2  # offset_origin(x, normal, ...)

        # Direct light: Nd samples (integrator._direct_light and the one-sample estimators).
        for j in range(nd):
            if hemi_direct:  # _direct_hemisphere_sample: a closest-hit ray, resolved in resolve_hemisphere
                u_a, u_b = uniform_2d(sob, fh[1], si * nd + j, k, j, depth, DIRECT_DIR_U1, DIRECT_DIR_U2)
                w0, w1, w2, cos_theta, pdf = sample_hemisphere(direct == DIRECT_HEMI_COSINE, u_a, u_b, nx0, nx1, nx2)
                counters[C_HEMI_DIRECT] += 1
                s_owner[s] = h
                s_o32[s, 0], s_o32[s, 1], s_o32[s, 2] = ox0, ox1, ox2
                s_d32[s, 0], s_d32[s, 1], s_d32[s, 2] = w0, w1, w2
                s_dir[s, 0], s_dir[s, 1], s_dir[s, 2] = w0, w1, w2
                s_value[s, 0], s_value[s, 1], s_value[s, 2] = f0, f1, f2
                s_aux[s] = cos_theta / pdf if pdf > 0 else -1.0
                s += 1
                continue
            # The stratified sampler draws one 2D point per light sample and reuses its first coordinate for the
            # discrete choices (lights.LightSampler.split_uniform); independent numbers need no reuse.
            if sob:
                u_a, u_b = sobol_point(fh[0], si * nd + j)
            else:
                u_a, u_b = uniform(k, dim_salt(depth, LIGHT_U1, j)), uniform(k, dim_salt(depth, LIGHT_U2, j))
            if direct == DIRECT_GLOBAL_AREA:  # _direct_global_area_sample
                if sob:
                    u_tri, u_a = _split_surface_uniform(surfaces, u_a)
                else:
                    u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                ltri, y0, y1, y2 = _sample_surface_point(surfaces, corners, u_tri, u_a, u_b)
                pdf_area = surface_pdf
            else:  # _direct_area_sample ("area" and "mis")
                if sob:
                    u_select, u_tri, u_a = _split_light_uniform(lights, num_lights, u_a)
                else:  # with one light there is nothing to choose (pdf(k) = 1) and nothing to draw
                    u_select = uniform(k, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
                    u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                if num_lights > 1:
                    counters[C_LIGHT_SELECT] += 1
                light, ltri, y0, y1, y2 = _sample_light_point(lights, num_lights, corners, u_select, u_tri, u_a, u_b)
                if mutants & M_LIGHT_PDF_IGNORED:  # mutant "light-pdf-ignored": pdf(y|k) alone
                    pdf_area = 1.0 / light_area[light]
                else:
                    pdf_area = light_pmf[light] / light_area[light]
            # _shadow_ray_estimate
            l0, l1, l2 = y0 - x0, y1 - x1, y2 - x2
            dist2 = dot3(l0, l1, l2, l0, l1, l2)
            dist = math.sqrt(dist2)
            inv_dist = 1.0 / dist  # one division, three products
            wi0, wi1, wi2 = l0 * inv_dist, l1 * inv_dist, l2 * inv_dist
            cos_x = dot3(nx0, nx1, nx2, wi0, wi1, wi2)
            cos_y = -dot3(tri_normal[ltri, 0], tri_normal[ltri, 1], tri_normal[ltri, 2], wi0, wi1, wi2)
            if not (cos_x > 0 and cos_y > 0 and light_id[ltri] >= 0 and dist2 > 0):
                counters[C_SHADOW_SKIPPED] += 1
                continue
            if mutants & M_NO_RAY_OFFSET:  # mutant "no-ray-offset"
                so0, so1, so2 = x0, x1, x2
            else:
                so0, so1, so2 = ox0, ox1, ox2
            g0, g1, g2 = y0 - so0, y1 - so1, y2 - so2
            seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
            t_max = shadow_t_max(seg_len, _offset(offset_scene, y0, y1, y2), cos_y)
            counters[C_SHADOW] += 1
            s_owner[s] = h
            s_o32[s, 0], s_o32[s, 1], s_o32[s, 2] = so0, so1, so2
            inv_seg = 1.0 / seg_len
            s_d32[s, 0], s_d32[s, 1], s_d32[s, 2] = g0 * inv_seg, g1 * inv_seg, g2 * inv_seg
            s_tfar[s] = max(t_max, 0.0)
            cos_at_x = 1.0 if no_cosine else cos_x  # mutant "no-cosine" (direct light)
            scale = (cos_at_x * cos_y) / (dist2 * pdf_area)  # G(x, y) V / p(y), for V = 1 (one division)
            v0 = emission[ltri, 0] * f0 * scale
            v1 = emission[ltri, 1] * f1 * scale
            v2 = emission[ltri, 2] * f2 * scale
            if direct == DIRECT_MIS:  # _mis_weight_light
                p_light = nd * pdf_area * dist2 / cos_y
                p_hemi = ni * hemisphere_pdf(hemi_cosine, cos_x)
                w = p_light * p_light / (p_light * p_light + p_hemi * p_hemi)
                v0, v1, v2 = v0 * w, v1 * w, v2 * w
            s_value[s, 0], s_value[s, 1], s_value[s, 2] = v0, v1, v2
            s += 1

        # Indirect light (Fig. 5.14), if the next vertex can still add anything.
        if not allow_indirect:
            continue
        if play_roulette:
            survival = albedo_max[material] if rr == RR_ALBEDO else fixed_survival
            u_rr = sobol_point(fh[2], si)[0] if sob else uniform(k, salt_rr)
            if not (u_rr < survival):
                counters[C_ROULETTE] += 1
                continue
            if not (mutants & M_RR_NO_REWEIGHT):  # mutant "rr-no-reweight"
                inv_survival = 1.0 / survival
                b0, b1, b2 = b0 * inv_survival, b1 * inv_survival, b2 * inv_survival
        for branch in range(ni):
            kb = k if ni == 1 else mix64(k ^ branch_salt(branch, depth))
            if sob:
                u_a, u_b = sobol_point(fh[3], si * ni + branch)
            else:
                u_a, u_b = uniform(kb, salt_u1), uniform(kb, salt_u2)
            w0, w1, w2, cos_theta, pdf = sample_hemisphere(hemi_cosine, u_a, u_b, nx0, nx1, nx2)
            if (mutants & M_COSINE_PDF_PI) and hemi_cosine:  # mutant "cosine-pdf-pi"
                pdf = pdf * _PI
            cos_factor = 1.0 if no_cosine else cos_theta  # mutant "no-cosine" (indirect light)
            weight = cos_factor / (pdf * ni)
            c0, c1, c2 = b0 * (f0 * weight), b1 * (f1 * weight), b2 * (f2 * weight)
            carries = (math.isfinite(c0) and math.isfinite(c1) and math.isfinite(c2)) and (c0 > 0 or c1 > 0 or c2 > 0)
            if not carries:
                counters[C_ROULETTE] += 1
                continue
            counters[C_INDIRECT] += 1
            q = n_next
            n_next += 1
            x_root[q] = r
            x_key[q] = kb
            x_origin[q, 0], x_origin[q, 1], x_origin[q, 2] = ox0, ox1, ox2
            x_o32[q, 0], x_o32[q, 1], x_o32[q, 2] = ox0, ox1, ox2
            x_dir[q, 0], x_dir[q, 1], x_dir[q, 2] = w0, w1, w2
            x_d32[q, 0], x_d32[q, 1], x_d32[q, 2] = w0, w1, w2
            x_beta[q, 0], x_beta[q, 1], x_beta[q, 2] = c0, c1, c2
            x_pdf[q] = pdf * ni

    return m, s, n_next


@njit(**_JIT)
def resolve_shadow(root, beta, hits, nd, s_owner, s_value, s_hit, total, radiance):
    """Direct light by shadow rays: each hit's Nd samples (value x V, V = 1 where Embree found no blocker,
    ``s_hit < 0``) summed in sample order, averaged, and added to ``radiance`` weighted by the hit's throughput.
    ``hits`` are the rows of (root, beta) that hit; ``total`` is room for one sum per hit."""
    m = len(hits)
    total[:m] = 0.0
    for q in range(len(s_owner)):
        if s_hit[q] < 0:
            h = s_owner[q]
            total[h, 0] += s_value[q, 0]
            total[h, 1] += s_value[q, 1]
            total[h, 2] += s_value[q, 2]
    _add_direct(root, beta, hits, nd, total, radiance)


@njit(**_JIT)
def resolve_hemisphere(root, beta, hits, nd, s_owner, s_value, s_aux, s_dir, s_prim, prim_to_tri, tri_normal,
                       emission, total, radiance):
    """Direct light by hemisphere sampling: emission Le of what each ray hit (its front side only), times
    f_r cos / p (``s_value`` f_r, ``s_aux`` cos / p or -1 where p = 0), averaged over the Nd samples."""
    m = len(hits)
    total[:m] = 0.0
    for q in range(len(s_owner)):
        p = s_prim[q]
        if p < 0 or s_aux[q] < 0:
            continue
        tri = prim_to_tri[p]
        faces_x = dot3(s_dir[q, 0], s_dir[q, 1], s_dir[q, 2], tri_normal[tri, 0], tri_normal[tri, 1],
                       tri_normal[tri, 2]) < 0
        weight = s_aux[q] * (1.0 if faces_x else 0.0)
        h = s_owner[q]
        total[h, 0] += emission[tri, 0] * s_value[q, 0] * weight
        total[h, 1] += emission[tri, 1] * s_value[q, 1] * weight
        total[h, 2] += emission[tri, 2] * s_value[q, 2] * weight
    _add_direct(root, beta, hits, nd, total, radiance)


@njit(**_JIT_INLINE)
def _add_direct(root, beta, hits, nd, total, radiance):
    inv_nd = 1.0 / nd  # exact for Nd = 1, 2, 4, ...
    for h in range(len(hits)):
        i = hits[h]
        r = root[i]
        radiance[r, 0] += beta[i, 0] * (total[h, 0] * inv_nd)
        radiance[r, 1] += beta[i, 1] * (total[h, 1] * inv_nd)
        radiance[r, 2] += beta[i, 2] * (total[h, 2] * inv_nd)


# ----------------------------------------------------------------------------------------- Embree, called directly


@njit(**_JIT)
def ray_buffer():
    """A 16-byte aligned RTCRayHit (uint32 words) and its float32 view."""
    raw = np.empty(embree_c.RAY_WORDS + 4, np.uint32)
    skip = ((16 - raw.ctypes.data % 16) % 16) // 4
    words = raw[skip:skip + embree_c.RAY_WORDS]
    return words, words.view(np.float32)


@njit(**_JIT_INLINE)
def _set_ray(words, floats, o0, o1, o2, d0, d1, d2, tfar):
    """Fill an RTCRay: float32 origin and direction (rounded as numpy's astype rounds), tnear 0, ``tfar``."""
    floats[0], floats[1], floats[2], floats[3] = o0, o1, o2, 0.0
    floats[4], floats[5], floats[6], floats[7] = d0, d1, d2, 0.0
    floats[embree_c.W_TFAR] = tfar
    words[embree_c.W_MASK] = embree_c.INVALID_ID  # every mask bit
    words[embree_c.W_ID] = 0
    words[embree_c.W_FLAGS] = 0


@njit(**_JIT_INLINE)
def closest_prim(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2):
    """Embree's closest hit of one ray (float32 coordinates): the primitive id, or -1 for a miss."""
    _set_ray(words, floats, o0, o1, o2, d0, d1, d2, np.inf)
    words[embree_c.W_GEOM_ID] = embree_c.INVALID_ID
    embree_c.rtc_intersect1(scene_ptr, words.ctypes.data, 0)
    if words[embree_c.W_GEOM_ID] == embree_c.INVALID_ID:
        return -1
    return np.int64(words[embree_c.W_PRIM_ID])


@njit(**_JIT_INLINE)
def occluded(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2, tfar):
    """Embree's any-hit query on the segment 0 < t < ``tfar``: True where something blocks it (Embree sets tfar
    to -inf)."""
    _set_ray(words, floats, o0, o1, o2, d0, d1, d2, tfar)
    embree_c.rtc_occluded1(scene_ptr, words.ctypes.data, 0)
    return floats[embree_c.W_TFAR] < 0


@njit(**_JIT)
def packet_buffer():
    """A 64-byte aligned RTCRayHit16 (uint32 words), its float32 view, and the 16 lanes' valid flags (int32)."""
    raw = np.empty(embree_c.PACKET_WORDS + 16 + 32, np.uint32)
    skip = ((64 - raw.ctypes.data % 64) % 64) // 4
    words = raw[skip:skip + embree_c.PACKET_WORDS]
    valid = raw[skip + embree_c.PACKET_WORDS:skip + embree_c.PACKET_WORDS + 16].view(np.int32)
    return words, words.view(np.float32), valid


@njit(**_JIT)
def closest_prims_coherent(scene_ptr, o32, d32, out, start, stop, words, floats, valid):
    """Closest hits of rays ``start:stop`` (at most 16) with one packet query: for rays that start together and
    point nearly the same way (one pixel's camera rays), Embree traverses its tree once for all of them. The hits
    are the same as one query per ray (``closest_prim``)."""
    n = stop - start
    for lane in range(embree_c.PACKET):
        if lane < n:
            i = start + lane
            valid[lane] = -1
            floats[lane] = o32[i, 0]
            floats[16 + lane] = o32[i, 1]
            floats[32 + lane] = o32[i, 2]
            floats[64 + lane] = d32[i, 0]
            floats[80 + lane] = d32[i, 1]
            floats[96 + lane] = d32[i, 2]
        else:
            valid[lane] = 0
            floats[lane] = 0.0
            floats[16 + lane] = 0.0
            floats[32 + lane] = 0.0
            floats[64 + lane] = 0.0
            floats[80 + lane] = 0.0
            floats[96 + lane] = 1.0
        floats[48 + lane] = 0.0  # tnear
        floats[112 + lane] = 0.0  # time
        floats[128 + lane] = np.inf  # tfar
        words[144 + lane] = embree_c.INVALID_ID  # mask
        words[160 + lane] = 0  # id
        words[176 + lane] = 0  # flags
        words[embree_c.P_GEOM_ID + lane] = embree_c.INVALID_ID
    embree_c.rtc_intersect16(valid.ctypes.data, scene_ptr, words.ctypes.data, 0)
    for lane in range(n):
        if words[embree_c.P_GEOM_ID + lane] == embree_c.INVALID_ID:
            out[start + lane] = -1
        else:
            out[start + lane] = np.int64(words[embree_c.P_PRIM_ID + lane])


@njit(**_JIT)
def closest_prims_packets(scene_ptr, o32, d32, out):
    """Closest hits of a batch of camera rays, 16 consecutive rays per packet query."""
    words, floats, valid = packet_buffer()
    n = o32.shape[0]
    for start in range(0, n, embree_c.PACKET):
        closest_prims_coherent(scene_ptr, o32, d32, out, start, min(n, start + embree_c.PACKET), words, floats, valid)


@njit(**_JIT)
def closest_prims(scene_ptr, o32, d32, out):
    """Closest hits of a batch of float32 rays (Intersector.closest_prims): primitive ids, -1 for a miss."""
    words, floats = ray_buffer()
    for i in range(o32.shape[0]):
        out[i] = closest_prim(scene_ptr, words, floats, o32[i, 0], o32[i, 1], o32[i, 2], d32[i, 0], d32[i, 1],
                              d32[i, 2])


@njit(**_JIT)
def occluders(scene_ptr, o32, d32, tfar, out):
    """Any-hit queries of a batch (Intersector.occluders): 0 where something blocks the segment, -1 where not."""
    words, floats = ray_buffer()
    for i in range(o32.shape[0]):
        blocked = occluded(scene_ptr, words, floats, o32[i, 0], o32[i, 1], o32[i, 2], d32[i, 0], d32[i, 1],
                           d32[i, 2], tfar[i])
        out[i] = 0 if blocked else -1


@njit(**_JIT_INLINE)
def _now_ns(ts):
    embree_c.clock_gettime(embree_c.CLOCK_MONOTONIC, ts.ctypes.data)
    return ts[0] * 1_000_000_000 + ts[1]


# One query in TIMING_STRIDE is timed (two clock reads); the time in Embree is the sampled time, less the cost of a
# clock read (measured at the start of each call), times the stride.
TIMING_STRIDE = 64


# ------------------------------------------------------------------------------------- whole paths, one at a time


@njit(**_JIT)
def trace_paths(state, scene_ptr, scene, lights, surfaces, cfg, cfg_f, max_depth, radiance, counters, timing,
                film_samples):
    """Trace every camera path of ``state`` (the wavefront ``camera_paths`` wrote) to its end, one path at a time,
    with Ni = 1: the same estimator, random numbers and order of floating-point operations as the wavefront
    (``bounce`` then ``resolve_shadow`` / ``resolve_hemisphere`` at each vertex), so the same bits, but each
    vertex's queries are made on the spot (Embree's C API) instead of in batches, and nothing is written between
    vertices but the path's own few numbers.

    ``cfg`` is the integer configuration of :func:`bounce` without its per-vertex entries (depth, emission mode,
    whether a next vertex and indirect light are needed), which are derived here from ``max_depth`` (-1: unbounded),
    the direct-light mode (MIS) and the planted faults; ``cfg[CFG_EMIT]`` = EMIT_ALL marks the double-emission
    mutant. The camera rays are traced first, 16 consecutive ones (one pixel's samples) per packet query.
    ``timing[0]`` receives the nanoseconds spent in Embree (one query in ``TIMING_STRIDE`` timed), ``timing[1]``
    the number of queries. ``film_samples`` = (pixel, sample, seed_key) of the camera samples, for the stratified
    sampler.
    """
    root, key, origin, direction, o32, d32, beta, pdf_dir = state
    prim_to_tri, tri_normal, tri_v0, corners, emission, light_id, tri_material, two_sided, f_r_table, albedo_max = scene
    light_pmf, light_area = lights[5], lights[6]
    double_emission = cfg[CFG_EMIT] == EMIT_ALL
    direct = cfg[CFG_DIRECT]
    mis = direct == DIRECT_MIS
    nd = cfg[CFG_ND]
    inv_nd = 1.0 / nd  # exact for Nd = 1, 2, 4, ...
    ni = 1
    hemi_cosine = cfg[CFG_HEMI_COSINE] != 0
    rr = cfg[CFG_RR]
    rr_depth = cfg[CFG_RR_DEPTH]
    mutants = cfg[CFG_MUTANTS]
    num_lights = cfg[CFG_NUM_LIGHTS]
    fixed_survival = cfg_f[CFGF_FIXED_SURVIVAL]
    offset_scene = cfg_f[CFGF_OFFSET_SCENE]
    surface_pdf = cfg_f[CFGF_SURFACE_PDF]
    no_cosine = (mutants & M_NO_COSINE) != 0
    hemi_direct = direct == DIRECT_HEMI_COSINE or direct == DIRECT_HEMI_UNIFORM
    sobol = cfg[CFG_SOBOL] != 0
    film_pixel, film_sample, seed_key = film_samples
    spp = cfg[CFG_SPP]
    fh = first_hit_seeds(seed_key, 0, 1, 1, 1)
    fh_pixel = -1
    si = 0
    # The vertex below repeats :func:`bounce` line for line (both must give the same bits). Sharing the light sample
    # and shadow ray through helper functions was measured: numba passes their arrays and 11-value results through
    # calls it does not optimise away, and the Cornell box fell from 4.98 to 3.0-3.3 M paths/s (inline="always" or
    # not). tests/reference_impl/test_engines.py holds the two copies to the same bits.
    words, floats = ray_buffer()
    ts = np.zeros(2, np.int64)
    queries = 0
    sampled_ns = 0
    clock_ns = 1 << 62  # the cheapest of a few back-to-back clock reads: what a timed interval holds besides Embree
    for _ in range(8):
        t_start = _now_ns(ts)
        clock_ns = min(clock_ns, _now_ns(ts) - t_start)
    timed = 0
    # The camera rays first, 16 of one pixel's samples per packet query (the same hits as one query per ray).
    n = len(root)
    first_prim = np.empty(n, np.int32)
    t_start = _now_ns(ts)
    closest_prims_packets(scene_ptr, o32, d32, first_prim)
    packet_ns = _now_ns(ts) - t_start

    count_back_face = 0
    count_escaped = 0
    count_hemi_direct = 0
    count_indirect = 0
    count_light_select = 0
    count_roulette = 0
    count_shadow = 0
    count_shadow_skipped = 0
    for i in range(n):
        r = root[i]
        k = key[i]
        o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
        d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
        b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
        ray_pdf = pdf_dir[i]
        depth = 1
        if sobol:
            if film_pixel[r] != fh_pixel:  # a pixel's samples come together: its seeds once
                fh_pixel = film_pixel[r]
                fh = first_hit_seeds(seed_key, fh_pixel, spp, nd, 1)
            si = film_sample[r]
        rad0, rad1, rad2 = radiance[r, 0], radiance[r, 1], radiance[r, 2]  # summed here, stored once
        while True:
            # The per-vertex configuration (integrator._Context.bounce_config).
            if depth == 1 or double_emission:
                emit = EMIT_ALL
            elif mis:
                emit = EMIT_MIS
            else:
                emit = EMIT_NONE
            allow_next = max_depth == -1 or depth + 1 <= max_depth
            allow_indirect = (max_depth == -1 or depth + 2 <= max_depth) or (mis and allow_next)
            play_roulette = rr != RR_OFF and depth >= rr_depth
            sob = sobol and depth == 1

            if depth == 1:
                p = np.int64(first_prim[i])
            else:
                queries += 1
                if queries % TIMING_STRIDE == 0:
                    t_start = _now_ns(ts)
                    p = closest_prim(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2)
                    sampled_ns += _now_ns(ts) - t_start
                    timed += 1
                else:
                    p = closest_prim(scene_ptr, words, floats, o0, o1, o2, d0, d1, d2)
            if p < 0:
                count_escaped += 1
                break
            tri = prim_to_tri[p]
            nx0, nx1, nx2 = tri_normal[tri, 0], tri_normal[tri, 1], tri_normal[tri, 2]
            denom = dot3(d0, d1, d2, nx0, nx1, nx2)
            t = dot3(tri_v0[tri, 0] - o0, tri_v0[tri, 1] - o1, tri_v0[tri, 2] - o2, nx0, nx1, nx2) / denom
            if not (math.isfinite(t) and t > 0):
                t = 0.0
            x0, x1, x2 = o0 + t * d0, o1 + t * d1, o2 + t * d2
            cos_out = -dot3(d0, d1, d2, nx0, nx1, nx2)
            front = cos_out > 0

            if emit != EMIT_NONE:
                fr = 1.0 if front else 0.0
                e0, e1, e2 = emission[tri, 0] * fr, emission[tri, 1] * fr, emission[tri, 2] * fr
                if emit == EMIT_ALL:
                    rad0 += b0 * e0
                    rad1 += b1 * e1
                    rad2 += b2 * e2
                else:
                    light = light_id[tri]
                    w = 0.0
                    if light >= 0 and cos_out > 0:
                        p_light = nd * (light_pmf[light] / light_area[light]) * (t * t) / cos_out
                        p_hemi = ray_pdf
                        w = p_hemi * p_hemi / (p_hemi * p_hemi + p_light * p_light)
                    rad0 += b0 * e0 * w
                    rad1 += b1 * e1 * w
                    rad2 += b2 * e2 * w

            if not allow_next:
                break
            material = tri_material[tri]
            if not (front or two_sided[material]):
                count_back_face += 1
                break
            if not front:
                nx0, nx1, nx2 = -nx0, -nx1, -nx2
            f0, f1, f2 = f_r_table[material, 0], f_r_table[material, 1], f_r_table[material, 2]
            off_x = _offset(offset_scene, x0, x1, x2)
            ox0, ox1, ox2 = x0 + off_x * nx0, x1 + off_x * nx1, x2 + off_x * nx2

            # Indirect light (Fig. 5.14), if the next vertex can still add anything. Drawn before the direct light's
            # queries (the random numbers are counter-based, so the order of drawing changes nothing), which gives the
            # processor independent arithmetic to overlap instead of a chain broken by every Embree call.
            go_on = allow_indirect
            if go_on and play_roulette:
                survival = albedo_max[material] if rr == RR_ALBEDO else fixed_survival
                u_rr = sobol_point(fh[2], si)[0] if sob else uniform(k, dim_salt(depth, ROULETTE, 0))
                if not (u_rr < survival):
                    count_roulette += 1
                    go_on = False
                elif not (mutants & M_RR_NO_REWEIGHT):
                    inv_survival = 1.0 / survival
                    q0, q1, q2 = b0 * inv_survival, b1 * inv_survival, b2 * inv_survival
                else:
                    q0, q1, q2 = b0, b1, b2
            else:
                q0, q1, q2 = b0, b1, b2
            if go_on:
                u_a, u_b = uniform_2d(sob, fh[3], si, k, 0, depth, INDIRECT_U1, INDIRECT_U2)
                w0, w1, w2, cos_theta, pdf = sample_hemisphere(hemi_cosine, u_a, u_b, nx0, nx1, nx2)
                if (mutants & M_COSINE_PDF_PI) and hemi_cosine:
                    pdf = pdf * _PI
                cos_factor = 1.0 if no_cosine else cos_theta
                weight = cos_factor / (pdf * ni)
                c0, c1, c2 = q0 * (f0 * weight), q1 * (f1 * weight), q2 * (f2 * weight)
                carries = (math.isfinite(c0) and math.isfinite(c1) and math.isfinite(c2)) and (c0 > 0 or c1 > 0 or c2 > 0)
                if not carries:
                    count_roulette += 1
                    go_on = False
                else:
                    count_indirect += 1

            # Direct light: Nd samples, summed in sample order (resolve_shadow / resolve_hemisphere).
            tot0, tot1, tot2 = 0.0, 0.0, 0.0
            for j in range(nd):
                if hemi_direct:
                    u_a, u_b = uniform_2d(sob, fh[1], si * nd + j, k, j, depth, DIRECT_DIR_U1, DIRECT_DIR_U2)
                    h0, h1, h2, h_cos, h_pdf = sample_hemisphere(direct == DIRECT_HEMI_COSINE, u_a, u_b, nx0, nx1, nx2)
                    count_hemi_direct += 1
                    aux = h_cos / h_pdf if h_pdf > 0 else -1.0
                    queries += 1
                    if queries % TIMING_STRIDE == 0:
                        t_start = _now_ns(ts)
                        hp = closest_prim(scene_ptr, words, floats, ox0, ox1, ox2, h0, h1, h2)
                        sampled_ns += _now_ns(ts) - t_start
                        timed += 1
                    else:
                        hp = closest_prim(scene_ptr, words, floats, ox0, ox1, ox2, h0, h1, h2)
                    if hp < 0 or aux < 0:
                        continue
                    htri = prim_to_tri[hp]
                    faces_x = dot3(h0, h1, h2, tri_normal[htri, 0], tri_normal[htri, 1], tri_normal[htri, 2]) < 0
                    weight = aux * (1.0 if faces_x else 0.0)
                    tot0 += emission[htri, 0] * f0 * weight
                    tot1 += emission[htri, 1] * f1 * weight
                    tot2 += emission[htri, 2] * f2 * weight
                    continue
                if sob:
                    u_a, u_b = sobol_point(fh[0], si * nd + j)
                else:
                    u_a, u_b = uniform(k, dim_salt(depth, LIGHT_U1, j)), uniform(k, dim_salt(depth, LIGHT_U2, j))
                if direct == DIRECT_GLOBAL_AREA:
                    if sob:
                        u_tri, u_a = _split_surface_uniform(surfaces, u_a)
                    else:
                        u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                    ltri, y0, y1, y2 = _sample_surface_point(surfaces, corners, u_tri, u_a, u_b)
                    pdf_area = surface_pdf
                else:
                    if sob:
                        u_select, u_tri, u_a = _split_light_uniform(lights, num_lights, u_a)
                    else:
                        u_select = uniform(k, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
                        u_tri = uniform(k, dim_salt(depth, LIGHT_TRIANGLE, j))
                    if num_lights > 1:
                        count_light_select += 1
                    light, ltri, y0, y1, y2 = _sample_light_point(lights, num_lights, corners, u_select, u_tri, u_a, u_b)
                    if mutants & M_LIGHT_PDF_IGNORED:
                        pdf_area = 1.0 / light_area[light]
                    else:
                        pdf_area = light_pmf[light] / light_area[light]
                l0, l1, l2 = y0 - x0, y1 - x1, y2 - x2
                dist2 = dot3(l0, l1, l2, l0, l1, l2)
                dist = math.sqrt(dist2)
                inv_dist = 1.0 / dist  # one division, three products
                wi0, wi1, wi2 = l0 * inv_dist, l1 * inv_dist, l2 * inv_dist
                cos_x = dot3(nx0, nx1, nx2, wi0, wi1, wi2)
                cos_y = -dot3(tri_normal[ltri, 0], tri_normal[ltri, 1], tri_normal[ltri, 2], wi0, wi1, wi2)
                if not (cos_x > 0 and cos_y > 0 and light_id[ltri] >= 0 and dist2 > 0):
                    count_shadow_skipped += 1
                    continue
                if mutants & M_NO_RAY_OFFSET:
                    so0, so1, so2 = x0, x1, x2
                else:
                    so0, so1, so2 = ox0, ox1, ox2
                g0, g1, g2 = y0 - so0, y1 - so1, y2 - so2
                seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
                t_max = shadow_t_max(seg_len, _offset(offset_scene, y0, y1, y2), cos_y)
                inv_seg = 1.0 / seg_len
                count_shadow += 1
                cos_at_x = 1.0 if no_cosine else cos_x
                scale = (cos_at_x * cos_y) / (dist2 * pdf_area)
                v0 = emission[ltri, 0] * f0 * scale
                v1 = emission[ltri, 1] * f1 * scale
                v2 = emission[ltri, 2] * f2 * scale
                if mis:
                    p_light = nd * pdf_area * dist2 / cos_y
                    p_hemi = ni * hemisphere_pdf(hemi_cosine, cos_x)
                    w = p_light * p_light / (p_light * p_light + p_hemi * p_hemi)
                    v0, v1, v2 = v0 * w, v1 * w, v2 * w
                tfar = np.float32(max(t_max, 0.0))
                queries += 1
                if queries % TIMING_STRIDE == 0:
                    t_start = _now_ns(ts)
                    blocked = occluded(scene_ptr, words, floats, so0, so1, so2, g0 * inv_seg, g1 * inv_seg,
                                       g2 * inv_seg, tfar)
                    sampled_ns += _now_ns(ts) - t_start
                    timed += 1
                else:
                    blocked = occluded(scene_ptr, words, floats, so0, so1, so2, g0 * inv_seg, g1 * inv_seg,
                                       g2 * inv_seg, tfar)
                if not blocked:
                    tot0 += v0
                    tot1 += v1
                    tot2 += v2
            rad0 += b0 * (tot0 * inv_nd)
            rad1 += b1 * (tot1 * inv_nd)
            rad2 += b2 * (tot2 * inv_nd)

            if not go_on:
                break
            o0, o1, o2 = ox0, ox1, ox2
            d0, d1, d2 = w0, w1, w2
            b0, b1, b2 = c0, c1, c2
            ray_pdf = pdf * ni
            depth += 1
        radiance[r, 0], radiance[r, 1], radiance[r, 2] = rad0, rad1, rad2
    counters[C_BACK_FACE] += count_back_face
    counters[C_ESCAPED] += count_escaped
    counters[C_HEMI_DIRECT] += count_hemi_direct
    counters[C_INDIRECT] += count_indirect
    counters[C_LIGHT_SELECT] += count_light_select
    counters[C_ROULETTE] += count_roulette
    counters[C_SHADOW] += count_shadow
    counters[C_SHADOW_SKIPPED] += count_shadow_skipped
    timing[0] += max(sampled_ns - timed * clock_ns, 0) * TIMING_STRIDE + packet_ns
    timing[1] += queries + n


# ------------------------------------------------------------------------------------------------ accumulation


@njit(**_JIT)
def finish_samples(radiance, scale):
    """Scale the camera samples' radiance (mutant "energy-loss-2pct": 0.98, else 1 and skipped) and count the
    samples with a non-finite channel."""
    nonfinite = 0
    for i in range(radiance.shape[0]):
        if scale != 1.0:
            for c in range(3):
                radiance[i, c] *= scale
        if not (math.isfinite(radiance[i, 0]) and math.isfinite(radiance[i, 1]) and math.isfinite(radiance[i, 2])):
            nonfinite += 1
    return nonfinite


@njit(**_JIT)
def accumulate(total, total_sq, p0, values, samples):
    """Add the samples of pixels p0, p0 + 1, ... (``samples`` consecutive rows each) to the pixels' sums and sums of
    squares, one after the other in sample order (so no decomposition of the work can change a bit)."""
    num = values.shape[0] // samples
    for p in range(num):
        for c in range(3):
            a = total[p0 + p, c]
            b = total_sq[p0 + p, c]
            for q in range(p * samples, (p + 1) * samples):
                v = values[q, c]
                a += v
                b += v * v
            total[p0 + p, c] = a
            total_sq[p0 + p, c] = b
