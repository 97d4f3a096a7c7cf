"""Warps of uniforms to directions and discrete choices: :mod:`reference_impl.sampling` for one sample, bit for bit.

    cosine hemisphere    (sqrt(u1) cos 2 pi u2, sqrt(u1) sin 2 pi u2, sqrt(1 - u1)),  p(Psi) = cos(Psi, N_x) / pi
    uniform hemisphere   (r cos 2 pi u2, r sin 2 pi u2, u1), r = sqrt(1 - u1^2),      p(Psi) = 1 / (2 pi)
    to world             the orthonormal frame of N_x of Duff et al., "Building an Orthonormal Basis, Revisited"
                         (JCGT 6(1), 2017)
    discrete choice      the i with cdf[i-1] <= u < cdf[i] (numpy's searchsorted, side="right")
    concentric disk      Shirley and Chiu's map of the square to the unit disk, p = 1 / pi (a thin lens's aperture)

The slides' cosine sampling (p = cos / pi) and the indirect estimator it gives (Fig. 5.14); the hemisphere sampling
of direct light (Fig. 5.12) uses the same warps.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import JIT, JIT_INLINE
from reference_impl.sampling import _COS, _HALF_PI, _SIN

PI = np.pi
INV_PI = 1.0 / np.pi  # the same constant as sampling.INV_PI
TWO_PI = 2.0 * np.pi
HALF_INV_PI = 0.5 * INV_PI
_BELOW_ONE = np.nextafter(1.0, 0.0)
HALF_PI = _HALF_PI
_S0, _S1, _S2, _S3, _S4, _S5, _S6 = _SIN
_C0, _C1, _C2, _C3, _C4, _C5, _C6, _C7 = _COS


@njit(**JIT)
def dot3(a0, a1, a2, b0, b1, b2):
    """A dot product of 3-vectors, summed in the order numpy's ``einsum("ij,ij->i")`` uses for rows of three (two
    SIMD lanes: (a0 b0 + a2 b2) + a1 b1), so the kernels reproduce the numpy estimators' bits."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@njit(**JIT)
def unit_circle(u):
    """sampling.unit_circle for one uniform: (cos 2 pi u, sin 2 pi u) from the quarter turn round(4u) and Taylor
    polynomials of the angle left, in [-pi/4, pi/4]. (libm's ``sincos`` was 7 % of a Cornell box render.)"""
    v = 4.0 * u
    q = math.floor(v + 0.5)
    a = (v - q) * HALF_PI
    a2 = a * a
    ps = _S6
    ps = _S5 + a2 * ps
    ps = _S4 + a2 * ps
    ps = _S3 + a2 * ps
    ps = _S2 + a2 * ps
    ps = _S1 + a2 * ps
    ps = _S0 + a2 * ps
    sin_a = a + a * (a2 * ps)
    pc = _C7
    pc = _C6 + a2 * pc
    pc = _C5 + a2 * pc
    pc = _C4 + a2 * pc
    pc = _C3 + a2 * pc
    pc = _C2 + a2 * pc
    pc = _C1 + a2 * pc
    pc = _C0 + a2 * pc
    cos_a = 1.0 + a2 * pc
    k = np.int64(q)
    odd = (k & 1) == 1  # a quarter or three quarters: cos and sin swap (selects, not branches: q is random)
    x = sin_a if odd else cos_a
    y = cos_a if odd else sin_a
    return x * (1.0 - 2.0 * (((k + 1) >> 1) & 1)), y * (1.0 - 2.0 * ((k >> 1) & 1))


@njit(**JIT)
def concentric_disk(u1, u2):
    """sampling.square_to_uniform_disk_concentric for one pair of uniforms: (x, y) uniform on the unit disk."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    if a == 0.0 and b == 0.0:
        return 0.0, 0.0
    if abs(a) >= abs(b):
        r, phi = a, 0.25 * PI * (b / a)
    else:
        r, phi = b, HALF_PI - 0.25 * PI * (a / b)
    return r * math.cos(phi), r * math.sin(phi)


@njit(**JIT)
def cosine_hemisphere(u1, u2):
    """sampling.square_to_cosine_hemisphere for one pair of uniforms: local (x, y, z)."""
    r = math.sqrt(u1)
    cos_phi, sin_phi = unit_circle(u2)  # phi = 2 pi u2
    return r * cos_phi, r * sin_phi, math.sqrt(max(0.0, 1.0 - u1))


@njit(**JIT)
def uniform_hemisphere(u1, u2):
    """sampling.square_to_uniform_hemisphere for one pair of uniforms."""
    z = u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    cos_phi, sin_phi = unit_circle(u2)  # phi = 2 pi u2
    return r * cos_phi, r * sin_phi, z


@njit(**JIT)
def hemisphere_pdf(cosine, cos_theta):
    """sampling.hemisphere_pdf: cos / pi ("cosine") or 1 / (2 pi) ("uniform") above the surface, else 0."""
    if cos_theta > 0:
        return cos_theta * INV_PI if cosine else HALF_INV_PI
    return 0.0


@njit(**JIT)
def tangent_frame(n0, n1, n2):
    """The tangents s, t of the orthonormal frame (s, t, N) of a unit normal N, :func:`to_world`'s (Duff et al.
    2017): with sign = +1 for N_z >= 0 else -1, a = -1 / (sign + N_z), b = N_x N_y a,
    s = (1 + sign N_x^2 a, sign b, -sign N_x), t = (b, sign + N_y^2 a, -N_y)."""
    sign = 1.0 if n2 >= 0 else -1.0
    a = -1.0 / (sign + n2)
    b = n0 * n1 * a
    return 1.0 + sign * (n0 * n0) * a, sign * b, -sign * n0, b, sign + (n1 * n1) * a, -n1


@njit(**JIT)
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


@njit(**JIT)
def sample_hemisphere(cosine, u1, u2, n0, n1, n2):
    """sampling.sample_hemisphere for one normal: world direction, cos(theta) and pdf."""
    if cosine:
        lx, ly, lz = cosine_hemisphere(u1, u2)
    else:
        lx, ly, lz = uniform_hemisphere(u1, u2)
    w0, w1, w2 = to_world(lx, ly, lz, n0, n1, n2)
    return w0, w1, w2, lz, hemisphere_pdf(cosine, lz)


@njit(**JIT_INLINE)
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


@njit(**JIT)
def rescale_within(u, lo, hi):
    """lights.rescale_within for one uniform."""
    return min((u - lo) / (hi - lo), _BELOW_ONE)
