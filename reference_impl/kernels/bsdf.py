"""STUB (helper B's placeholder for helper A's kernels/bsdf.py; replaced on merge): diffuse, perfect mirror and
smooth dielectric only, local frame z = the front normal; wo toward the previous vertex."""

from __future__ import annotations

import math

from numba import njit

from reference_impl.kernels.config import JIT_BORROW
from reference_impl.kernels.warps import INV_PI, cosine_hemisphere
from reference_impl.materials import CONDUCTOR, DIELECTRIC, DIFFUSE, P_IOR, P_TWO_SIDED


@njit(**JIT_BORROW)
def is_delta(kind):
    return kind == CONDUCTOR or kind == DIELECTRIC


@njit(**JIT_BORROW)
def bsdf_eval(kind, params, m, mutant, wox, woy, woz, wix, wiy, wiz):
    k = kind[m]
    if k == DIFFUSE:
        if woz * wiz <= 0:
            return 0.0, 0.0, 0.0
        if woz < 0 and params[m, P_TWO_SIDED] == 0:
            return 0.0, 0.0, 0.0
        c = abs(wiz) * INV_PI
        return params[m, 0] * c, params[m, 1] * c, params[m, 2] * c
    return 0.0, 0.0, 0.0


@njit(**JIT_BORROW)
def bsdf_pdf(kind, params, m, mutant, wox, woy, woz, wix, wiy, wiz):
    k = kind[m]
    if k == DIFFUSE:
        if woz * wiz <= 0 or (woz < 0 and params[m, P_TWO_SIDED] == 0):
            return 0.0
        return abs(wiz) * INV_PI
    return 0.0


@njit(**JIT_BORROW)
def _fresnel(cos_i, eta):
    """Unpolarized dielectric Fresnel reflectance, cos_i the cosine on the incident side (sign: which side)."""
    if cos_i < 0:
        eta = 1.0 / eta
        cos_i = -cos_i
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0, 0.0
    cos_t = math.sqrt(1.0 - sin2_t)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp), cos_t


@njit(**JIT_BORROW)
def bsdf_sample(kind, params, m, mutant, wox, woy, woz, u_lobe, u1, u2):
    k = kind[m]
    if k == DIFFUSE:
        if woz == 0 or (woz < 0 and params[m, P_TWO_SIDED] == 0):
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        x, y, z = cosine_hemisphere(u1, u2)
        if woz < 0:
            z = -z
        pdf = abs(z) * INV_PI
        if not pdf > 0:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        return True, x, y, z, params[m, 0], params[m, 1], params[m, 2], pdf, False
    if k == CONDUCTOR:  # perfect mirror only (the stub)
        if woz <= 0 and params[m, P_TWO_SIDED] == 0:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        return True, -wox, -woy, woz, params[m, 0], params[m, 1], params[m, 2], 1.0, True
    if k == DIELECTRIC:
        eta = params[m, P_IOR]
        f, cos_t = _fresnel(woz, eta)
        if u_lobe < f:
            return True, -wox, -woy, woz, params[m, 0], params[m, 1], params[m, 2], f, True
        eta_ti = eta if woz > 0 else 1.0 / eta  # n_t / n_i
        scale = 1.0 / eta_ti
        z = -cos_t if woz > 0 else cos_t
        s2 = scale * scale  # radiance scaling 1 / eta_ti^2
        return (True, -wox * scale, -woy * scale, z, params[m, 9] * s2, params[m, 10] * s2, params[m, 11] * s2,
                1.0 - f, True)
    return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
