"""Phase functions and free-flight distances of a homogeneous medium (issue 38: the volumetric path tracer's
sampling routines, tested against their own pdfs before the path loop takes them).

Directions are travel directions: d the direction the light travelled before the scattering, w after it, and
mu = d . w the cosine of the scattering angle (mu = 1: straight on).

    isotropic   p(w) = 1 / (4 pi);  mu = 1 - 2 u1, phi = 2 pi u2
    HG          p(w) = (1 - g^2) / (4 pi (1 + g^2 - 2 g mu)^(3/2))   (Henyey and Greenstein 1941)
                mu = (1 + g^2 - ((1 - g^2) / (1 - g + 2 g u1))^2) / (2 g), phi = 2 pi u2   (|g| >= 1e-3;
                isotropic below: the formula's cancellation)
                g > 0 scatters forward. Mitsuba's ``hg`` and pbrt-v4's ``HenyeyGreenstein`` write the same
                function of cos = wi . wo with wi pointing back along d (cos = -mu, "+ 2 g cos").
    free flight in a medium of extinction sigma_t: t = -log(1 - u) / sigma_t, p(t) = sigma_t exp(-sigma_t t); over
                a segment of length s, P(t >= s) = exp(-sigma_t s), the transmittance T(s) (Beer-Lambert), so a
                sample that passes the segment has weight T(s) / P(t >= s) = 1 and one that scatters at t has
                sigma_s T(t) / p(t) = albedo.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import JIT
from reference_impl.kernels.warps import to_world, unit_circle

INV_FOUR_PI = 1.0 / (4.0 * math.pi)
#: below this |g| HG is sampled as isotropic (the inverse cdf divides by 2 g)
HG_ISOTROPIC_BELOW = 1e-3


@njit(**JIT)
def hg_pdf(g, mu):
    """p(w) of Henyey-Greenstein with asymmetry g at mu = d . w (module docstring), per steradian."""
    denom = 1.0 + g * g - 2.0 * g * mu
    return INV_FOUR_PI * (1.0 - g * g) / (denom * math.sqrt(denom))


@njit(**JIT)
def hg_mu(g, u1):
    """The cosine mu of an HG sample from one uniform (the inverse of its cdf in mu); isotropic where
    |g| < HG_ISOTROPIC_BELOW."""
    if abs(g) < HG_ISOTROPIC_BELOW:
        return 1.0 - 2.0 * u1
    s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u1)
    return min(1.0, max(-1.0, (1.0 + g * g - s * s) / (2.0 * g)))


@njit(**JIT)
def sample_hg(g, u1, u2, d0, d1, d2):
    """A direction w after scattering of light travelling along the unit d, from HG with asymmetry g: (w, p(w))."""
    mu = hg_mu(g, u1)
    sin_t = math.sqrt(max(0.0, 1.0 - mu * mu))
    cos_phi, sin_phi = unit_circle(u2)
    w0, w1, w2 = to_world(sin_t * cos_phi, sin_t * sin_phi, mu, d0, d1, d2)
    return w0, w1, w2, hg_pdf(g, mu) if abs(g) >= HG_ISOTROPIC_BELOW else INV_FOUR_PI


@njit(**JIT)
def sample_isotropic(u1, u2):
    """A uniform direction on the sphere: (w, 1 / (4 pi))."""
    mu = 1.0 - 2.0 * u1
    sin_t = math.sqrt(max(0.0, 1.0 - mu * mu))
    cos_phi, sin_phi = unit_circle(u2)
    return sin_t * cos_phi, sin_t * sin_phi, mu, INV_FOUR_PI


@njit(**JIT)
def free_flight(sigma_t, u):
    """A distance to the next interaction in a homogeneous medium: t = -log(1 - u) / sigma_t (inf for sigma_t 0)."""
    if not sigma_t > 0.0:
        return np.inf
    return -math.log1p(-u) / sigma_t


@njit(**JIT)
def free_flight_pdf(sigma_t, t):
    """p(t) = sigma_t exp(-sigma_t t), t >= 0."""
    return sigma_t * math.exp(-sigma_t * t) if t >= 0.0 else 0.0


@njit(**JIT)
def transmittance(sigma_t, s):
    """T(s) = exp(-sigma_t s): the chance a free flight passes a segment of length s."""
    return math.exp(-sigma_t * s)


@njit(**JIT)
def sample_hg_many(g, u1, u2, d):
    """:func:`sample_hg` for each (u1[i], u2[i]) about the one direction d (tests): (w (n, 3), pdf (n,))."""
    n = len(u1)
    w = np.empty((n, 3))
    pdf = np.empty(n)
    for i in range(n):
        w[i, 0], w[i, 1], w[i, 2], pdf[i] = sample_hg(g, u1[i], u2[i], d[0], d[1], d[2])
    return w, pdf


@njit(**JIT)
def free_flight_many(sigma_t, u):
    """:func:`free_flight` for each u[i] (tests)."""
    out = np.empty(len(u))
    for i in range(len(u)):
        out[i] = free_flight(sigma_t, u[i])
    return out


__all__ = ["HG_ISOTROPIC_BELOW", "INV_FOUR_PI", "free_flight", "free_flight_many", "free_flight_pdf", "hg_mu",
           "hg_pdf", "sample_hg", "sample_hg_many", "sample_isotropic", "transmittance"]
