"""The stratified sampler in the kernels (``sampler = sobol``): :mod:`reference_impl.rng`'s ``sobol_2d`` for one
point of one pixel and pair of dimensions, bit for bit.

Point i of the n points of a pixel and pair (docs/reference-renderer.md, "The stratified sampler"):

    i' = pi(i)                      a random permutation of [0, n): three rounds of v += q, v ^= v >> ceil(k/2),
                                    v *= (q >> 32) | 1, v ^= v >> floor(k/3), v *= 0x297A2D39, v ^= v >> ceil(k/2)
                                    on k bits (2^k >= n), cycle-walked below n (Kensler, Pixar TM 13-01, 2013)
    x = nus(reverse(i'), s_x)       Sobol's dimension 0, Owen-scrambled: nus(v, s) = reverse(lk(reverse(v), s))
    y = nus(sobol_1(i'), s_y)       dimension 1: sobol_1(i') = reverse(pascal32(i'))   (Burley, JCGT 9(4) 2020, list. 3)

with every seed a hash of (seed, pixel, the pair's first dimension). For n = 2^m the points form a (0, m, 2)-net.
The camera sample (depth 0) and the first hit's decisions (depth 1; in the volumetric path loop the first vertex's,
:func:`volpath_first_vertex_seeds`) use it; deeper vertices draw independent numbers
(:mod:`reference_impl.kernels.rng`). (Measured on the Cornell box at 64 spp: the first hit gives nearly all of the
gain, MSE 5.6e-4 -> 1.5e-4; going on to depth 2 took 3 % more time for 3 % less MSE.)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from reference_impl.kernels.config import JIT, JIT_BORROW
from reference_impl.kernels.rng import dim_salt, mix64, pixel_key, uniform
from reference_impl.rng import (_GOLDEN, _LK, _ROUND_MULTIPLIER, _TO_UNIT32, BSDF_LOBE, BSDF_U1, DIRECT_DIR_U1,
                                FLIGHT_CHANNEL, INDIRECT_U1, LIGHT_U1, ROULETTE)

_U32 = np.uint64(32)
_ONE = np.uint64(1)
_LOW32 = np.uint64(0xFFFFFFFF)
_B1, _B2, _B4, _B8, _B16 = (np.uint64(m) for m in (0x55555555, 0x33333333, 0x0F0F0F0F, 0x00FF00FF, 0x0000FFFF))
_SH1, _SH2, _SH4, _SH8, _SH16 = (np.uint64(v) for v in (1, 2, 4, 8, 16))
_LK0, _LK1, _LK2, _LK3 = _LK
_GOLDEN_1, _GOLDEN_2, _GOLDEN_3 = (np.uint64((r * int(_GOLDEN)) & ((1 << 64) - 1)) for r in (1, 2, 3))


class FirstHitPairs(NamedTuple):
    """One entry per pair of dimensions a pixel's first hit draws from its stratified sets in the wavefront: the
    pair's seeds (:func:`first_hit_seeds`)."""

    light: tuple  # the light sample's point (its first coordinate also picks the light and the piece); Np x Nd
    direction: tuple  # hemisphere sampling's direct-light direction; Np x Nd
    roulette: tuple  # Russian roulette (the first coordinate); Np
    indirect: tuple  # the indirect ray's direction; Np x Ni


class PathFirstHitPairs(NamedTuple):
    """One entry per pair of dimensions a pixel's first hit draws from its stratified sets in the path loop
    (:func:`path_first_hit_seeds`): the pair's seeds, or the (base, count) of its points computed ahead
    (:func:`ahead`)."""

    light: tuple  # the light sample's point (its first coordinate also picks the light and the piece); Np x Nd
    direction: tuple  # hemisphere sampling's direct-light direction; Np x Nd
    bsdf: tuple  # the BSDF sample's direction; Np
    lobe_roulette: tuple  # the BSDF's lobe (x) and Russian roulette (y); Np


class VolpathFirstVertexPairs(NamedTuple):
    """One entry per pair of dimensions a pixel's first vertex draws from its stratified sets in the volumetric path
    loop (:func:`volpath_first_vertex_seeds`): the (base, count) of its points computed ahead, or the pair's seeds."""

    flight: tuple  # the path's hero channel (x) and its first free flight's distance (y); Np
    light: tuple  # the light sample's point (its first coordinate also picks the light and the piece); Np x Nd
    direction: tuple  # the phase function's or the BSDF's direction, whichever the first vertex is; Np
    lobe_roulette: tuple  # the BSDF's lobe (x) and Russian roulette (y, also at a scattering point); Np


NOTHING_HELD = (np.int64(0), np.int64(0))  # (base, count) of the points of a pair computed ahead: none


@njit(**JIT)
def reverse_bits32(x):
    """rng.reverse_bits32 for one word."""
    x = ((x >> _SH1) & _B1) | ((x & _B1) << _SH1)
    x = ((x >> _SH2) & _B2) | ((x & _B2) << _SH2)
    x = ((x >> _SH4) & _B4) | ((x & _B4) << _SH4)
    x = ((x >> _SH8) & _B8) | ((x & _B8) << _SH8)
    return ((x >> _SH16) | (x << _SH16)) & _LOW32


@njit(**JIT)
def lk_permutation(x, seed):
    """rng.lk_permutation for one word (uint64 arithmetic; only the low 32 bits are kept)."""
    x = (x + seed) & _LOW32
    x ^= x * _LK0
    x ^= x * _LK1
    x ^= x * _LK2
    x ^= x * _LK3
    return x & _LOW32


@njit(**JIT)
def pascal32(x):
    """rng.pascal32 for one word."""
    x ^= (x >> _SH1) & _B1
    x ^= (x >> _SH2) & _B2
    x ^= (x >> _SH4) & _B4
    x ^= (x >> _SH8) & _B8
    x ^= (x >> _SH16) & _B16
    return x


@njit(**JIT)
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


@njit(**JIT)
def _order_round(v, q, w, s1, s2):
    """One round of rng.permutation_element."""
    v = (v + q) & w
    v ^= v >> s1
    v = (v * ((q >> _U32) | _ONE)) & w
    v ^= v >> s2
    v = (v * _ROUND_MULTIPLIER) & w
    return v ^ (v >> s1)


@njit(**JIT)
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


@njit(**JIT)
def sobol_points(seeds, first, count, xs, ys, at):
    """:func:`sobol_point` for the indices first, ..., first + count - 1, written to xs[at:at + count] and
    ys[at:at + count]: the same bits. The points are independent of each other, so the loop is written for the
    processor to overlap them (and for LLVM to vectorise it: 4 points per AVX2 instruction here), the cycle-walk
    that n < 2^k needs taken in a second pass only where a point left [0, n). (One point at a time, where each
    waits for the last, took 25 ns; in this loop 5 ns: ``sobol_point``'s 130 operations are a chain of
    multiplications.)"""
    n, w, s1, s2, q0, q1, q2, seed_x, seed_y = seeds
    walk = False
    for i in range(count):
        v = np.uint64(first + i)
        v = _order_round(_order_round(_order_round(v, q0, w, s1, s2), q1, w, s1, s2), q2, w, s1, s2)
        walk |= v >= n
        x = reverse_bits32(lk_permutation(v, seed_x))
        y = reverse_bits32(lk_permutation(pascal32(v), seed_y))
        xs[at + i] = np.float64(x) * _TO_UNIT32
        ys[at + i] = np.float64(y) * _TO_UNIT32
    if walk:
        for i in range(count):
            xs[at + i], ys[at + i] = sobol_point(seeds, first + i)


@njit(**JIT_BORROW)
def pair_point(points, index):
    """Point ``index`` of a pixel's set for one pair: ``points`` = (seeds, x, y, held): the point itself where
    ``held`` (computed ahead, :func:`held_point`), else computed on the spot from the pair's seeds. The same bits
    either way."""
    seeds, x, y, held = points
    if held:
        return x, y
    return sobol_point(seeds, index)


@njit(**JIT_BORROW)
def spot_point(seeds):
    """A point set of which :func:`pair_point` computes each point on the spot."""
    return seeds, 0.0, 0.0, False


@njit(**JIT_BORROW)
def held_point(seeds, xs, ys, held, index):
    """The point set for :func:`pair_point`'s ``index`` with the point itself where xs, ys hold it (``held`` =
    (base, count) of the points :func:`ahead` computed there), else with the seeds alone."""
    base, count = held
    o = np.int64(index) - base
    if o >= 0 and o < count:
        return seeds, xs[o], ys[o], True
    return seeds, 0.0, 0.0, False


@njit(**JIT_BORROW)
def uniform_2d(sobol, points, index, key, j, depth, purpose_a, purpose_b):
    """The two uniforms of one decision: point ``index`` of the pixel's stratified set (``sobol``, ``points`` of
    its pair, :func:`pair_point`), or independent numbers of the path key for dimensions (depth, purpose_a /
    purpose_b, j)."""
    if sobol:
        return pair_point(points, index)
    return uniform(key, dim_salt(depth, purpose_a, j)), uniform(key, dim_salt(depth, purpose_b, j))


@njit(**JIT)
def first_hit_seeds(seed_key, pixel, spp, nd, ni):
    """The ``sobol_seeds`` of a pixel's first-hit pairs: (light sample, direct-light direction, roulette, indirect
    direction); Np x Nd, Np x Nd, Np and Np x Ni points. (A light sample's choices of light and triangle reuse its
    point's first coordinate: lights.LightSampler.split_uniform.)"""
    pk = pixel_key(seed_key, pixel)
    return FirstHitPairs(sobol_seeds(pk, dim_salt(1, LIGHT_U1, 0), spp * nd),
                         sobol_seeds(pk, dim_salt(1, DIRECT_DIR_U1, 0), spp * nd),
                         sobol_seeds(pk, dim_salt(1, ROULETTE, 0), spp),
                         sobol_seeds(pk, dim_salt(1, INDIRECT_U1, 0), spp * ni))


@njit(**JIT)
def path_first_hit_seeds(seed_key, pixel, spp, nd):
    """The ``sobol_seeds`` of a pixel's first-hit pairs in the path loop: (light sample, hemisphere sampling's
    direct-light direction, BSDF direction, BSDF lobe and roulette); Np x Nd, Np x Nd, Np and Np points. The light sample's choices of light and piece reuse its point's
    first coordinate (as :func:`first_hit_seeds`'); the lobe and the roulette number are the two coordinates of one
    point."""
    pk = pixel_key(seed_key, pixel)
    return PathFirstHitPairs(sobol_seeds(pk, dim_salt(1, LIGHT_U1, 0), spp * nd),
                             sobol_seeds(pk, dim_salt(1, DIRECT_DIR_U1, 0), spp * nd),
                             sobol_seeds(pk, dim_salt(1, BSDF_U1, 0), spp),
                             sobol_seeds(pk, dim_salt(1, BSDF_LOBE, 0), spp))


@njit(**JIT)
def volpath_first_vertex_seeds(seed_key, pixel, spp, nd):
    """The ``sobol_seeds`` of a pixel's first-vertex pairs in the volumetric path loop: (hero channel and first free
    flight, light sample, phase or BSDF direction, BSDF lobe and roulette); Np, Np x Nd, Np and Np points. The first
    vertex is a scattering point or a surface, never both, so the direction and (lobe, roulette) sets serve either
    (each of a pixel's samples takes its own point of each set once; a set per kind of vertex would hand each a
    random subset of its points); the light sample's choices of light and piece reuse its point's first coordinate
    (as :func:`path_first_hit_seeds`')."""
    pk = pixel_key(seed_key, pixel)
    return VolpathFirstVertexPairs(sobol_seeds(pk, dim_salt(1, FLIGHT_CHANNEL, 0), spp),
                                   sobol_seeds(pk, dim_salt(1, LIGHT_U1, 0), spp * nd),
                                   sobol_seeds(pk, dim_salt(1, BSDF_U1, 0), spp),
                                   sobol_seeds(pk, dim_salt(1, BSDF_LOBE, 0), spp))


@njit(**JIT_BORROW)
def pixel_first_hit_seeds(cfg, seeds, seeds_pixel, film_samples, r):
    """The :func:`first_hit_seeds` of camera sample r's pixel, and r's index among the pixel's samples: (seeds,
    their pixel, index). A pixel's samples come together, so its seeds are computed once: ``seeds`` of pixel
    ``seeds_pixel`` are handed back unchanged while the pixel is the same. ``film_samples``: the camera samples
    (:class:`.records.FilmSamples`)."""
    film_pixel, film_sample, seed_key = film_samples.pixel, film_samples.sample, film_samples.seed_key
    if film_pixel[r] != seeds_pixel:
        seeds_pixel = film_pixel[r]
        seeds = first_hit_seeds(seed_key, seeds_pixel, cfg.spp, cfg.shadow_rays, cfg.indirect_rays)
    return seeds, seeds_pixel, film_sample[r]


@njit(**JIT)
def pixel_run(pixel, sample, r):
    """The camera samples r, r + 1, ... (``pixel``, ``sample``: their pixels and sample numbers) of one pixel with
    consecutive sample numbers: how many."""
    m = 1
    while r + m < len(pixel) and pixel[r + m] == pixel[r] and sample[r + m] == sample[r] + m:
        m += 1
    return m


@njit(**JIT)
def longest_run(film_samples):
    """The longest :func:`pixel_run` of the camera samples: what the buffers of points computed ahead must hold."""
    film_pixel, film_sample = film_samples.pixel, film_samples.sample
    longest, r = 0, 0
    while r < len(film_pixel):
        m = pixel_run(film_pixel, film_sample, r)
        longest = max(longest, m)
        r += m
    return longest


@njit(**JIT_BORROW)
def ahead(seeds, first, count, xs, ys, wanted):
    """Points first, ..., first + count - 1 of a pair computed into xs, ys where ``wanted``: (base, count) of
    what xs, ys now hold for :func:`pair_point` ((0, 0): nothing)."""
    if not wanted:
        return np.int64(0), np.int64(0)
    sobol_points(seeds, first, count, xs, ys, 0)
    return np.int64(first), np.int64(count)
