"""Counter-based random numbers in the kernels: :mod:`reference_impl.rng` for one key at a time, bit for bit.

Every uniform is a hash of (seed, path key, dimension): SplitMix64's finalizer (Steele, Lea, Flood 2014)

    mix64(x) = m3(m2(m1(x))),  m1: x ^= x >> 30, x *= 0xBF58476D1CE4E5B9;  m2: x ^= x >> 27, x *= 0x94D049BB133111EB;
               m3: x ^= x >> 31                                                  (wrapping uint64 arithmetic)
    path key   k = mix64(path_id * golden ^ mix64(seed ^ golden)),  path_id = pixel * spp + sample
    uniform    u(k, dim) = (mix64(k + (dim + 1) * golden) >> 11) * 2^-53      (53 random bits in [0, 1))
    dimension  dim = depth << 40 | purpose << 32 | index   (index: which of the Nd / Ni samples)
    branch     k_b = mix64(k ^ mix64((depth & 0xFFFF) << 32 | b))   (the b-th of Ni indirect rays)

so no generator state passes between batches or threads (docs/reference-renderer.md, "Determinism"). The purposes
(what a dimension decides: FILM_X ... INDIRECT_U2) are :mod:`reference_impl.rng`'s.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl.kernels.config import JIT
from reference_impl.rng import _GOLDEN, _M1, _M2, _PIXEL_SALT, _S11, _S27, _S30, _S31, _TO_UNIT

_U32 = np.uint64(32)
_U40 = np.uint64(40)
_ONE = np.uint64(1)
_PIXEL_SALT_U = np.uint64(_PIXEL_SALT)


@njit(**JIT)
def mix64(x):
    """rng.mix64 on one uint64 (wrapping uint64 arithmetic)."""
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


@njit(**JIT)
def dim_salt(depth, purpose, index):
    """What rng.uniform adds to a key for dimension rng.dimension(depth, purpose, index): (dim + 1) * golden."""
    dim = (np.uint64(depth) << _U40) | (np.uint64(purpose) << _U32) | np.uint64(index)
    return (dim + _ONE) * _GOLDEN


@njit(**JIT)
def uniform(key, salt):
    """rng.uniform of one key, with ``salt = dim_salt(...)``: a float64 in [0, 1) with 53 random bits."""
    return np.float64(mix64(key + salt) >> _S11) * _TO_UNIT


@njit(**JIT)
def branch_salt(branch, depth):
    """rng.branch_keys(keys, branch, depth) is mix64(keys ^ branch_salt(branch, depth))."""
    return mix64((np.uint64(depth & 0xFFFF) << _U32) | np.uint64(branch & 0xFFFFFFFF))


@njit(**JIT)
def path_key(seed_key, path_id):
    """rng.path_keys for one path id, with the render's ``seed_key`` (:func:`reference_impl.rng.seed_key`)."""
    return mix64((np.uint64(path_id) * _GOLDEN) ^ seed_key)


@njit(**JIT)
def pixel_key(seed_key, pixel):
    """rng.pixel_keys for one pixel, with the render's ``seed_key`` (:func:`reference_impl.rng.seed_key`)."""
    return mix64((np.uint64(pixel) * _GOLDEN) ^ seed_key ^ _PIXEL_SALT_U)
