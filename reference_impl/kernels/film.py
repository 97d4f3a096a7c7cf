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
def finish_and_accumulate(total, total_sq, p0, values, samples, scale):
    """:func:`finish_samples` and the pixel sums in one pass over the samples: scale each sample (unless
    ``scale`` is 1), count those with a non-finite channel, and add the samples of pixels p0, p0 + 1, ... (``samples``
    consecutive rows each) to their sums and sums of squares, one after the other in sample order (so no
    decomposition of the work can change a bit). Returns the count."""
    nonfinite = 0
    num = values.shape[0] // samples
    for p in range(num):
        a0, a1, a2 = total[p0 + p, 0], total[p0 + p, 1], total[p0 + p, 2]
        b0, b1, b2 = total_sq[p0 + p, 0], total_sq[p0 + p, 1], total_sq[p0 + p, 2]
        for q in range(p * samples, (p + 1) * samples):
            v0, v1, v2 = values[q, 0], values[q, 1], values[q, 2]
            if scale != 1.0:
                v0, v1, v2 = v0 * scale, v1 * scale, v2 * scale
            if not (math.isfinite(v0) and math.isfinite(v1) and math.isfinite(v2)):
                nonfinite += 1
            a0 += v0
            a1 += v1
            a2 += v2
            b0 += v0 * v0
            b1 += v1 * v1
            b2 += v2 * v2
        total[p0 + p, 0], total[p0 + p, 1], total[p0 + p, 2] = a0, a1, a2
        total_sq[p0 + p, 0], total_sq[p0 + p, 1], total_sq[p0 + p, 2] = b0, b1, b2
    return nonfinite


@njit(**JIT)
def unit_samples(p0, p1, s0, s1, pixel, sample):
    """The camera samples of pixels p0 .. p1 - 1, samples s0 .. s1 - 1 of each, pixel by pixel in sample order, into
    ``pixel`` and ``sample`` (np.repeat and np.tile of the ranges, without their allocations)."""
    i = 0
    for p in range(p0, p1):
        for s in range(s0, s1):
            pixel[i] = p
            sample[i] = s
            i += 1
