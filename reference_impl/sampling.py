"""Warps from uniform random numbers to the distributions the estimators need, each beside its pdf.

Conventions: directions are returned in a local frame whose +z is the surface normal; the pdf of a direction is
per unit solid angle, the pdf of a point per unit area, the pdf of a discrete choice a probability.
"""

from __future__ import annotations

import math

import numpy as np

INV_PI = 1.0 / np.pi
_HALF_PI = 0.5 * np.pi
# Taylor coefficients of sin and cos to degree 15 and 16: on |a| <= pi/4 the first terms left out are below
# 7e-17 of the value, under half an ulp.
_SIN = tuple(float((-1) ** k / math.factorial(2 * k + 1)) for k in range(1, 8))
_COS = tuple(float((-1) ** k / math.factorial(2 * k)) for k in range(1, 9))


def unit_circle(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cos 2 pi u, sin 2 pi u) for u in [0, 1), without libm. The quarter turn is found from u itself, q = round(4u),
    which leaves the angle a = (4u - q) pi / 2 in [-pi/4, pi/4] (4u - q is exact), where sin a and cos a are their
    Taylor polynomials (Horner's rule in a^2); the quarter turn q rotates (cos a, sin a) exactly. Within an ulp or
    two of libm's, and the same bits on every machine; 2-3x faster than ``sincos`` in the kernels
    (:func:`reference_impl.kernels.warps.unit_circle` is this, operation for operation)."""
    v = 4.0 * np.asarray(u, dtype=np.float64)
    q = np.floor(v + 0.5)
    a = (v - q) * _HALF_PI
    a2 = a * a
    ps = _SIN[6]
    for c in _SIN[5::-1]:
        ps = c + a2 * ps
    sin_a = a + a * (a2 * ps)
    pc = _COS[7]
    for c in _COS[6::-1]:
        pc = c + a2 * pc
    cos_a = 1.0 + a2 * pc
    k = q.astype(np.int64) & 3
    cos_u = np.where(k == 0, cos_a, np.where(k == 1, -sin_a, np.where(k == 2, -cos_a, sin_a)))
    sin_u = np.where(k == 0, sin_a, np.where(k == 1, cos_a, np.where(k == 2, -sin_a, -cos_a)))
    return cos_u, sin_u


def square_to_cosine_hemisphere(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions on the +z hemisphere (Malley's method: a uniform point of the unit disk in polar
    form, r = sqrt(u1), phi = 2 pi u2, lifted to z = sqrt(1 - r^2) = sqrt(1 - u1)). The polar map needs no branch
    and no division, unlike Shirley-Chiu's concentric one; with independent uniforms both give the same density."""
    r = np.sqrt(u1)
    cos_phi, sin_phi = unit_circle(u2)  # phi = 2 pi u2
    return np.stack([r * cos_phi, r * sin_phi, np.sqrt(np.maximum(0.0, 1.0 - u1))], axis=-1)


def cosine_hemisphere_pdf(cos_theta: np.ndarray) -> np.ndarray:
    """p(Psi) = cos(Psi, N_x) / pi on the hemisphere (slides, "Cosine Sampling"), 0 below it."""
    return np.where(cos_theta > 0, cos_theta * INV_PI, 0.0)


def square_to_uniform_hemisphere(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Directions uniform over the +z hemisphere: cos(theta) = u1, phi = 2 pi u2."""
    z = u1
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    cos_phi, sin_phi = unit_circle(u2)  # phi = 2 pi u2
    return np.stack([r * cos_phi, r * sin_phi, z], axis=-1)


def uniform_hemisphere_pdf(cos_theta: np.ndarray) -> np.ndarray:
    """p(Psi) = 1 / (2 pi) on the hemisphere, 0 below it."""
    return np.where(cos_theta > 0, 0.5 * INV_PI, 0.0)


def square_to_uniform_triangle(u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentrics (b1, b2) uniform over a triangle: b1 = 1 - sqrt(u1), b2 = u2 sqrt(u1); pdf = 1 / area."""
    s = np.sqrt(u1)
    return 1.0 - s, u2 * s


def square_to_uniform_disk_concentric(u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Points (x, y) uniform on the unit disk by Shirley and Chiu's concentric map ("A Low Distortion Map Between
    Disk and Square", JGT 2(3), 1997), as Mitsuba's ``square_to_uniform_disk_concentric``: with a = 2 u1 - 1,
    b = 2 u2 - 1, where |a| >= |b| r = a, phi = (pi / 4) b / a, else r = b, phi = pi / 2 - (pi / 4) a / b;
    (x, y) = r (cos phi, sin phi); pdf = 1 / pi per unit area (:func:`uniform_disk_pdf`)."""
    a = 2.0 * np.asarray(u1, dtype=np.float64) - 1.0
    b = 2.0 * np.asarray(u2, dtype=np.float64) - 1.0
    first = np.abs(a) >= np.abs(b)
    r = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(first, 0.25 * np.pi * (b / a), _HALF_PI - 0.25 * np.pi * (a / b))
    phi = np.where(r == 0.0, 0.0, phi)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def uniform_disk_pdf(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """1 / pi inside the unit disk, 0 outside."""
    return np.where(np.asarray(x) ** 2 + np.asarray(y) ** 2 <= 1.0, INV_PI, 0.0)


def sample_discrete(cdf: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Index i with probability cdf[i] - cdf[i-1]; ``cdf`` is the normalised cumulative sum (last entry 1)."""
    idx = np.searchsorted(cdf, u, side="right")
    return np.minimum(idx, len(cdf) - 1)


def coordinate_frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (s, t) with (s, t, n) right-handed orthonormal (Duff et al. 2017, branchless)."""
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    s = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=-1)
    t = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=-1)
    return s, t


def to_world(local: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Rotate local directions (+z = n) into world space."""
    s, t = coordinate_frame(n)
    return local[:, :1] * s + local[:, 1:2] * t + local[:, 2:3] * n


def sample_hemisphere(kind: str, u1: np.ndarray, u2: np.ndarray, n: np.ndarray):
    """World directions about normals ``n`` and their solid-angle pdfs; ``kind`` is "cosine" or "uniform"."""
    if kind == "cosine":
        local = square_to_cosine_hemisphere(u1, u2)
        pdf = cosine_hemisphere_pdf(local[:, 2])
    else:
        local = square_to_uniform_hemisphere(u1, u2)
        pdf = uniform_hemisphere_pdf(local[:, 2])
    return to_world(local, n), local[:, 2], pdf


def hemisphere_pdf(kind: str, cos_theta: np.ndarray) -> np.ndarray:
    return cosine_hemisphere_pdf(cos_theta) if kind == "cosine" else uniform_hemisphere_pdf(cos_theta)
