"""The camera samples' end: the energy-loss planted fault, the non-finite counter, and each pixel's sum and sum of
squares formed in sample order (``radiance = radiance / #samples`` of Fig. 5.16, and the variance of that mean).
"""

from __future__ import annotations

import math

from numba import njit

from reference_impl.kernels.config import JIT


@njit(**JIT)
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


@njit(**JIT)
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
