"""Counter-based random numbers: every uniform is a hash of (seed, path key, dimension), or (the stratified
sampler, at the bottom) a point of a scrambled Sobol set seeded by (seed, pixel, pair of dimensions).

No generator state is carried between batches or threads, so an image depends only on the seed and the settings,
never on the batch size or the thread count. The mixer is SplitMix64's finalizer (Steele, Lea, Flood 2014), applied
twice: once to form a per-path key, once per dimension.
"""

from __future__ import annotations

import numpy as np

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TO_UNIT = 2.0**-53
_MASK = (1 << 64) - 1


def mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finalizer: a bijection on uint64 with full avalanche."""
    x = np.asarray(x, dtype=np.uint64)
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


def _mix64_int(x: int) -> int:
    """:func:`mix64` on one Python int (no numpy scalar overflow warnings)."""
    x &= _MASK
    x = ((x ^ (x >> 30)) * int(_M1)) & _MASK
    x = ((x ^ (x >> 27)) * int(_M2)) & _MASK
    return x ^ (x >> 31)


def seed_key(seed: int) -> np.uint64:
    """The key of a render's seed, from which every path and pixel key is derived.

    Parameters
    ----------
    seed : int
        The render's seed (``Settings.seed``, or a replicate's ``Settings.replicate_seed``).

    Returns
    -------
    numpy.uint64
        ``mix64(seed ^ golden)``, golden = 0x9E3779B97F4A7C15 (2^64 / phi, SplitMix64's increment; Steele, Lea and
        Flood 2014): what the kernels derive every path and pixel key from (their ``FilmSamples.seed_key``).
    """
    return np.uint64(_mix64_int(seed ^ int(_GOLDEN)))


def path_keys(seed: int, path_ids: np.ndarray) -> np.ndarray:
    """Keys of camera paths: ``path_ids`` are unique per (pixel, sample), e.g. pixel * spp + sample."""
    return mix64((np.asarray(path_ids, dtype=np.uint64) * _GOLDEN) ^ seed_key(seed))


def branch_keys(keys: np.ndarray, branch: int, depth: int) -> np.ndarray:
    """Keys of the ``branch``-th child of each path at ``depth`` (the slides' Ni indirect rays)."""
    salt = np.uint64(_mix64_int(((depth & 0xFFFF) << 32) | (branch & 0xFFFFFFFF)))
    return mix64(keys ^ salt)


def uniform(keys: np.ndarray, dim: int) -> np.ndarray:
    """One float64 uniform in [0, 1) per key for dimension ``dim`` (any non-negative int < 2**63)."""
    x = mix64(keys + np.uint64(((dim + 1) * int(_GOLDEN)) & _MASK))
    return (x >> _S11).astype(np.float64) * _TO_UNIT


# What a dimension decides (its ``purpose``), for the integrator and the kernels alike.
FILM_X, FILM_Y = 0, 1
LIGHT_SELECT, LIGHT_TRIANGLE, LIGHT_U1, LIGHT_U2 = 2, 3, 4, 5
DIRECT_DIR_U1, DIRECT_DIR_U2 = 6, 7
ROULETTE = 8
INDIRECT_U1, INDIRECT_U2 = 9, 10
COMPLEMENT_U1, COMPLEMENT_U2 = 11, 12  # an environment's direction where the direct strategy cannot find it
BSDF_LOBE, BSDF_U1, BSDF_U2 = 13, 14, 15  # the path loop's BSDF sample: which lobe, then the direction
LENS_U1, LENS_U2 = 16, 17  # a thin lens's aperture point (at depth 0, with the film's)
BLEND = 18  # the material step's choice among a blendbsdf's materials (kernels/material.py)
MASK_PASS = 19  # whether a ray passes a mask's hole, index: the how-manieth mask the ray meets (kernels/path.py)
# the volumetric path loop's (kernels/volpath.py); index: the how-manieth null boundary the ray has crossed (free
# flights), or light sample j's crossing (delta tracking of a shadow ray: (j << 16) | crossing)
FLIGHT_CHANNEL, FLIGHT = 20, 21  # a free flight's channel, then its distance
PHASE_U1, PHASE_U2 = 22, 23  # a direction from the phase function
TRACK_CHANNEL, TRACK = 24, 25  # a shadow ray's free flight with transmittance = "track"


def dimension(depth: int, purpose: int, index: int = 0) -> int:
    """The dimension number of one decision: path depth, what it is for, and which of Nd / Ni samples."""
    return (depth << 40) | (purpose << 32) | index


# ------------------------------------------------------------------------------------ the stratified sampler
#
# A pixel's Np camera samples (and its Np x Nd light samples, Np x Ni indirect directions) can be drawn as one
# stratified point set instead of independent points: for each pair of dimensions, the first n points of Sobol's
# (0, 2)-sequence (dimensions 0 and 1: a (0, m, 2)-net in base 2 when n = 2^m), randomized by a nested uniform
# ("Owen") scramble (Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4), 2020; Owen, "Randomly permuted
# (t, m, s)-nets and (t, s)-sequences", 1995), and taken in an order given by a random permutation of [0, n), so that
# pairs are independent of each other within the pixel ("padding"; Kensler, "Correlated Multi-Jittered Sampling",
# Pixar TM 13-01, 2013, for the permutation). Everything is seeded by the pixel and the pair. Each point is uniform on
# [0, 1)^2 on its own and the pairs are independent, so every estimator stays unbiased; the n points of one pixel
# and pair are not independent of each other (that is the stratification). scipy.stats.qmc.Sobol makes the same
# points (tests/reference_impl/test_sobol_sampler.py checks it), but as whole arrays from Python with one scramble per generator;
# the kernels need any point of any (pixel, pair) on the spot, inside the compiled path loop, hence this code.

_LOW32 = 0xFFFFFFFF
_BIT_MASKS = ((1, 0x55555555), (2, 0x33333333), (4, 0x0F0F0F0F), (8, 0x00FF00FF))
# Constants of the Laine-Karras style permutation, from Burley (2020), listing 2.
_LK = tuple(np.uint64(c) for c in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6))
_PIXEL_SALT = 0xD1B54A32D192ED03
_TO_UNIT32 = 2.0**-32
_ROUND_MULTIPLIER = np.uint64(0x297A2D39)


def reverse_bits32(x: np.ndarray) -> np.ndarray:
    """The 32 low bits of each ``x`` in reverse order (as uint64)."""
    x = np.asarray(x, dtype=np.uint64) & np.uint64(_LOW32)
    for shift, mask in _BIT_MASKS:
        s, m = np.uint64(shift), np.uint64(mask)
        x = ((x >> s) & m) | ((x & m) << s)
    return ((x >> np.uint64(16)) | (x << np.uint64(16))) & np.uint64(_LOW32)


def lk_permutation(x: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """A bijection of 32-bit words in which output bit b depends only on input bits <= b (and the seed), so that
    ``reverse(lk(reverse(x)))`` permutes every dyadic interval's halves at random: a nested uniform scramble."""
    x = (np.asarray(x, dtype=np.uint64) + np.asarray(seed, dtype=np.uint64)) & np.uint64(_LOW32)
    for c in _LK:
        x = x ^ (x * c)
    return x & np.uint64(_LOW32)


def pascal32(x: np.ndarray) -> np.ndarray:
    """Sobol's second generator matrix (the Pascal matrix mod 2) applied to the index ``x``, in reversed bit order:
    bit j of the result is the parity of the bits k of x with j a subset of k (Lucas' theorem), in five steps."""
    x = np.asarray(x, dtype=np.uint64)
    for shift, mask in (*_BIT_MASKS, (16, 0x0000FFFF)):
        x = x ^ ((x >> np.uint64(shift)) & np.uint64(mask))
    return x


def permutation_element(i: np.ndarray, n: int, seeds: tuple) -> np.ndarray:
    """Element ``i`` of a random permutation of [0, n) chosen by ``seeds`` (three uint64 arrays or scalars, one per
    round). Each round is a bijection of the k-bit words, 2^k >= n: v += q, v ^= v >> ceil(k/2), v *= (q >> 32) | 1,
    v ^= v >> floor(k/3), v *= 0x297A2D39, v ^= v >> ceil(k/2) (mod 2^k); the result is walked along its cycle until it
    lands below n (Kensler 2013's construction, with rounds of our own: what matters here is that a pixel's order in
    one pair says nothing of its order in another, and with his hash the mean n r^2 between two pairs' values was 1.33
    at n = 64, against 1.02 for independent orders; these rounds give 1.01 (tests/reference_impl/test_sobol_sampler.py))."""
    k = max(int(n) - 1, 0).bit_length()
    w = np.uint64((1 << k) - 1)
    s1, s2 = np.uint64(max((k + 1) // 2, 1)), np.uint64(max(k // 3, 1))
    x = np.array(np.broadcast_to(np.asarray(i, dtype=np.uint64), np.broadcast(i, *seeds).shape))
    q = [np.broadcast_to(np.asarray(sd, dtype=np.uint64), x.shape) for sd in seeds]
    out = x.copy()
    todo = np.ones(x.shape, bool)
    with np.errstate(over="ignore"):
        while todo.any():
            v = x[todo]
            for qr in q:
                qt = qr[todo]
                v = (v + qt) & w
                v ^= v >> s1
                v = (v * ((qt >> np.uint64(32)) | np.uint64(1))) & w
                v ^= v >> s2
                v = (v * _ROUND_MULTIPLIER) & w
                v ^= v >> s1
            x[todo] = v
            done = v < np.uint64(n)
            rows = np.flatnonzero(todo)
            out[rows[done]] = v[done]
            todo[rows[done]] = False
    return out


def pixel_keys(seed: int, pixels: np.ndarray) -> np.ndarray:
    """Keys of pixels for the stratified sampler (one point set per pixel and dimension pair)."""
    return mix64((np.asarray(pixels, dtype=np.uint64) * _GOLDEN) ^ seed_key(seed) ^ np.uint64(_PIXEL_SALT))


def sobol_seeds(pixel_keys: np.ndarray, dim: int) -> tuple:
    """The seeds of each pixel's point set for the dimension pair that starts at ``dim``: three of the order
    (:func:`permutation_element`), then those of the x and y scrambles (32 bits)."""
    with np.errstate(over="ignore"):
        seed = mix64(np.asarray(pixel_keys, dtype=np.uint64) + np.uint64(((dim + 1) * int(_GOLDEN)) & _MASK))
        order = tuple(mix64(seed + np.uint64((r * int(_GOLDEN)) & _MASK)) for r in (1, 2, 3))
    return (*order, seed >> np.uint64(32), mix64(seed) & np.uint64(_LOW32))


def sobol_2d(pixel_keys: np.ndarray, index: np.ndarray, n: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Point ``index`` of the n points (n <= 2**32) of each pixel's scrambled, permuted (0, 2)-sequence set for the
    dimension pair that starts at ``dim`` (a number of :func:`dimension`): two float64 arrays in [0, 1), 32 bits each.

    With the seeds of :func:`sobol_seeds` and nus(v, s) = reverse(lk(reverse(v), s)):
    i' = permutation_element(index, n), x = nus(reverse(i'), s_x), y = nus(sobol_1(i'), s_y), where
    reverse(i') and sobol_1(i') = reverse(pascal32(i')) are Sobol's dimensions 0 and 1 (Burley 2020, listing 3).
    For n = 2^m the n points of one pixel and pair form a (0, m, 2)-net: one point in every dyadic box of area 2^-m.
    """
    q0, q1, q2, seed_x, seed_y = sobol_seeds(pixel_keys, dim)
    shuffled = permutation_element(index, n, (q0, q1, q2))
    x = reverse_bits32(lk_permutation(shuffled, seed_x))
    y = reverse_bits32(lk_permutation(pascal32(shuffled), seed_y))
    return x.astype(np.float64) * _TO_UNIT32, y.astype(np.float64) * _TO_UNIT32
