"""A texture's value at texture coordinates (u, v) (:mod:`reference_impl.textures`, Mitsuba 3's ``bitmap`` and
``checkerboard``), for the material step (:mod:`.material`).

    (u', v', 1)  = to_uv (u, v, 1)
    bitmap       nearest:   texel (wrap(floor(u' W)), wrap(floor(v' H)))
                 bilinear:  x = u' W - 1/2, y = v' H - 1/2, i = floor(x), j = floor(y), a = x - i, b = y - j:
                            (1 - a)(1 - b) T(i, j) + a (1 - b) T(i + 1, j) + (1 - a) b T(i, j + 1) + a b T(i + 1, j + 1)
                 wrap(i) on n texels: repeat  i mod n;  clamp  min(max(i, 0), n - 1);
                                      mirror  m = i mod 2n, m if m < n else 2n - 1 - m
    checkerboard color0 where (u' mod 1 > 1/2) == (v' mod 1 > 1/2), color1 elsewhere
    one number   a bitmap's luminance (Mitsuba's eval_1; :func:`texture_eval_1`)

Row j = 0 is the image's top row. The texels are linear values (an sRGB image is decoded when the tables are built,
:func:`.records.texture_tables`).
"""

from __future__ import annotations

import math

import numpy as np

from numba import njit

from reference_impl.kernels.config import (JIT_BORROW, JIT_NONRT, M_TEXTURE_HALF_TEXEL, M_TEXTURE_NEAREST,
                                           M_TEXTURE_REPEAT_AS_CLAMP, M_TEXTURE_V_FLIPPED)
from reference_impl.textures import BILINEAR, CHECKERBOARD, CLAMP, LUMINANCE, REPEAT

# Texel coordinates are clamped to +-2^52 before they become integers (a coordinate from a huge to_uv): far beyond
# any image, and every wrap mode still gives a texel.
_MAX_COORD = 2.0**52


@njit(**JIT_BORROW)
def wrap_index(i, n, mode):
    """Texel index ``i`` of an axis of ``n`` texels, wrapped by ``mode`` (REPEAT, MIRROR, CLAMP)."""
    if mode == REPEAT:
        return i % n
    if mode == CLAMP:
        return min(max(i, 0), n - 1)
    m = i % (2 * n)
    return m if m < n else 2 * n - 1 - m


@njit(**JIT_BORROW)
def _floor(x):
    return int(math.floor(min(max(x, -_MAX_COORD), _MAX_COORD)))


@njit(**JIT_BORROW)
def wrap_pair(i, n, mode):
    """:func:`wrap_index` of i and of i + 1, with one division: i + 1 wraps to 0 where i is the last of its period
    (REPEAT: n, MIRROR: 2 n)."""
    if mode == CLAMP:
        return min(max(i, 0), n - 1), min(max(i + 1, 0), n - 1)
    period = n if mode == REPEAT else 2 * n
    m = i % period
    m1 = m + 1 if m + 1 < period else 0
    if mode == REPEAT:
        return m, m1
    return (m if m < n else 2 * n - 1 - m), (m1 if m1 < n else 2 * n - 1 - m1)


@njit(**JIT_BORROW)
def _rgb(texels, t):
    return texels[t, 0], texels[t, 1], texels[t, 2]


@njit(**JIT_BORROW)
def _texel(textures, k, i, j, wrap):
    w, h = textures.width[k], textures.height[k]
    return _rgb(textures.texels, textures.offset[k] + wrap_index(j, h, wrap) * w + wrap_index(i, w, wrap))


@njit(**JIT_BORROW)
def _corners(textures, k, i, j, wrap):
    """The rows of ``textures.texels`` of the four texels (i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1) of bitmap
    ``k`` that a bilinear lookup blends, each coordinate wrapped by ``wrap`` (:func:`wrap_pair`)."""
    w, h = textures.width[k], textures.height[k]
    i0, i1 = wrap_pair(i, w, wrap)
    j0, j1 = wrap_pair(j, h, wrap)
    base = textures.offset[k]
    r0, r1 = base + j0 * w, base + j1 * w
    return r0 + i0, r0 + i1, r1 + i0, r1 + i1


# The lookups are called, not inlined (JIT_NONRT): a scene without textures never reaches them, and inlined at each of
# their call sites in the path loop they made every render 2-7 % slower (4 paired rounds, docs/performance.md).
@njit(**JIT_NONRT)
def texture_eval(textures, k, u, v, mutant):
    """Texture ``k`` of ``textures`` (:class:`.records.TextureTables`) at (u, v): its RGB value. ``mutant``: the
    render's planted-fault bits (:mod:`.config`)."""
    a = textures.to_uv[k]
    tu = a[0, 0] * u + a[0, 1] * v + a[0, 2]
    tv = a[1, 0] * u + a[1, 1] * v + a[1, 2]
    if mutant & M_TEXTURE_V_FLIPPED:  # planted fault "texture-v-flipped"
        tv = 1.0 - tv
    if textures.kind[k] == CHECKERBOARD:
        c = 0 if ((tu - math.floor(tu)) > 0.5) == ((tv - math.floor(tv)) > 0.5) else 1
        col = textures.colors[k, c]
        return col[0], col[1], col[2]
    wrap = textures.wrap[k]
    if wrap == REPEAT and mutant & M_TEXTURE_REPEAT_AS_CLAMP:  # planted fault "texture-repeat-as-clamp"
        wrap = CLAMP
    x = tu * textures.width[k]
    y = tv * textures.height[k]
    if textures.filter[k] != BILINEAR or mutant & M_TEXTURE_NEAREST:  # planted fault "texture-nearest-not-bilinear"
        return _texel(textures, k, _floor(x), _floor(y), wrap)
    if not mutant & M_TEXTURE_HALF_TEXEL:  # planted fault "texture-half-texel-shift": no - 1/2
        x -= 0.5
        y -= 0.5
    i, j = _floor(x), _floor(y)
    fa, fb = x - i, y - j
    t00, t10, t01, t11 = _corners(textures, k, i, j, wrap)
    texels = textures.texels
    r00, g00, b00 = _rgb(texels, t00)
    r10, g10, b10 = _rgb(texels, t10)
    r01, g01, b01 = _rgb(texels, t01)
    r11, g11, b11 = _rgb(texels, t11)
    w00, w10, w01, w11 = (1.0 - fa) * (1.0 - fb), fa * (1.0 - fb), (1.0 - fa) * fb, fa * fb
    return (w00 * r00 + w10 * r10 + w01 * r01 + w11 * r11, w00 * g00 + w10 * g10 + w01 * g01 + w11 * g11,
            w00 * b00 + w10 * b10 + w01 * b01 + w11 * b11)


@njit(**JIT_NONRT)
def texture_eval_1(textures, k, u, v, mutant):
    """Texture ``k`` at (u, v) as one number, Mitsuba's ``eval_1`` (a one-channel parameter such as ``alpha``): a
    bitmap's luminance 0.212671 r + 0.715160 g + 0.072169 b; a checkerboard's colour's mean (r + g + b) / 3 (its
    colours are ``rgb`` textures, whose ``eval_1`` is the mean; Mitsuba 3.9.1's own swaps the two colours, which the
    scene format refuses)."""
    r, g, b = texture_eval(textures, k, u, v, mutant)
    if textures.kind[k] == CHECKERBOARD:
        return (r + g + b) / 3.0
    return LUMINANCE[0] * r + LUMINANCE[1] * g + LUMINANCE[2] * b


@njit(**JIT_NONRT)
def texture_grad_1(textures, k, u, v, mutant):
    """The gradient (df/du, df/dv) of bitmap ``k``'s one number f (its luminance, :func:`texture_eval_1`) at (u, v),
    Mitsuba 3.9.1's ``eval_1_grad`` (the bump map's): the bilinear lookup's derivative per texel,

        g_x = (1 - b)(f10 - f00) + b (f11 - f01),   g_y = (1 - a)(f01 - f00) + a (f11 - f10),

    with f_ij the luminance of the four texels of :func:`texture_eval` and (a, b) the weights there, taken back
    through to_uv's 2 x 2 part A by its transpose and then scaled by the resolution, (W, H) * (A^T g) (``bitmap.cpp``:
    ``res * df_uv``); (0, 0) with the nearest filter (a step function). That is the exact derivative, A^T ((W, H) * g),
    wherever A is diagonal or W = H; otherwise Mitsuba's order, which the ground truth has, is kept (it differs from
    the derivative of Mitsuba's own lookup: tests/reference_impl/test_shading.py)."""
    a = textures.to_uv[k]
    tu = a[0, 0] * u + a[0, 1] * v + a[0, 2]
    tv = a[1, 0] * u + a[1, 1] * v + a[1, 2]
    if mutant & M_TEXTURE_V_FLIPPED:  # planted fault "texture-v-flipped"
        tv = 1.0 - tv
    if textures.filter[k] != BILINEAR or mutant & M_TEXTURE_NEAREST:
        return 0.0, 0.0
    wrap = textures.wrap[k]
    if wrap == REPEAT and mutant & M_TEXTURE_REPEAT_AS_CLAMP:  # planted fault "texture-repeat-as-clamp"
        wrap = CLAMP
    width, height = textures.width[k], textures.height[k]
    x = tu * width
    y = tv * height
    if not mutant & M_TEXTURE_HALF_TEXEL:  # planted fault "texture-half-texel-shift": no - 1/2
        x -= 0.5
        y -= 0.5
    i, j = _floor(x), _floor(y)
    fa, fb = x - i, y - j
    t00, t10, t01, t11 = _corners(textures, k, i, j, wrap)
    texels = textures.texels
    f00, f10 = _luminance(_rgb(texels, t00)), _luminance(_rgb(texels, t10))
    f01, f11 = _luminance(_rgb(texels, t01)), _luminance(_rgb(texels, t11))
    du = (1.0 - fb) * (f10 - f00) + fb * (f11 - f01)
    dv = (1.0 - fa) * (f01 - f00) + fa * (f11 - f10)
    if mutant & M_TEXTURE_V_FLIPPED:
        dv = -dv
    return width * (a[0, 0] * du + a[1, 0] * dv), height * (a[0, 1] * du + a[1, 1] * dv)


@njit(**JIT_BORROW)
def _luminance(rgb):
    return LUMINANCE[0] * rgb[0] + LUMINANCE[1] * rgb[1] + LUMINANCE[2] * rgb[2]


@njit(cache=True, nogil=True, error_model="numpy")
def _eval_many(textures, k, uv, mutant, out):
    for n in range(uv.shape[0]):
        out[n, 0], out[n, 1], out[n, 2] = texture_eval(textures, k, uv[n, 0], uv[n, 1], mutant)


@njit(cache=True, nogil=True, error_model="numpy")
def _grad_many(textures, k, uv, mutant, out):
    for n in range(uv.shape[0]):
        out[n, 0], out[n, 1] = texture_grad_1(textures, k, uv[n, 0], uv[n, 1], mutant)


def gradient(tables, k: int, uv, mutant: int = 0):
    """:func:`texture_grad_1` of bitmap ``k`` of ``tables`` at the (N, 2) points ``uv``: (N, 2) float64."""
    uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2)
    out = np.empty((len(uv), 2))
    _grad_many(tables, int(k), uv, int(mutant), out)
    return out


def evaluate(tables, k: int, uv, mutant: int = 0):
    """Texture ``k`` of ``tables`` (:class:`.records.TextureTables`) at the (N, 2) points ``uv``: (N, 3) float64
    (for tests and tools; the renders look textures up in the material step)."""
    uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2)
    out = np.empty((len(uv), 3))
    _eval_many(tables, int(k), uv, int(mutant), out)
    return out
