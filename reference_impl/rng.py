"""Counter-based random numbers: every uniform is a hash of (seed, path key, dimension).

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


def path_keys(seed: int, path_ids: np.ndarray) -> np.ndarray:
    """Keys of camera paths: ``path_ids`` are unique per (pixel, sample), e.g. pixel * spp + sample."""
    seed_key = np.uint64(_mix64_int(seed ^ int(_GOLDEN)))
    return mix64((np.asarray(path_ids, dtype=np.uint64) * _GOLDEN) ^ seed_key)


def branch_keys(keys: np.ndarray, branch: int, depth: int) -> np.ndarray:
    """Keys of the ``branch``-th child of each path at ``depth`` (the slides' Ni indirect rays)."""
    salt = np.uint64(_mix64_int(((depth & 0xFFFF) << 32) | (branch & 0xFFFFFFFF)))
    return mix64(keys ^ salt)


def uniform(keys: np.ndarray, dim: int) -> np.ndarray:
    """One float64 uniform in [0, 1) per key for dimension ``dim`` (any non-negative int < 2**63)."""
    x = mix64(keys + np.uint64(((dim + 1) * int(_GOLDEN)) & _MASK))
    return (x >> _S11).astype(np.float64) * _TO_UNIT


def dimension(depth: int, purpose: int, index: int = 0) -> int:
    """The dimension number of one decision: path depth, what it is for, and which of Nd / Ni samples."""
    return (depth << 40) | (purpose << 32) | index
