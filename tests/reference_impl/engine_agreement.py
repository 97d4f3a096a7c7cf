"""Whether two renders of one scene estimate the same image: the z of the difference of their means, globally and per
quadrant, per channel, with the renders' own variance estimates (the sobol sampler's are upper bounds:
conservative). Used where the path loop and the wavefront, which draw different random numbers, must agree."""

from __future__ import annotations

import numpy as np

#: |z| above which two renders disagree: two-sided 1e-6 per z
Z_MAX = 4.9


def mean_z(a, b) -> np.ndarray:
    """|z| of ``a.image - b.image`` (two :class:`reference_impl.RenderOutput`), over the whole film and each
    quadrant, per channel (15 values): (mean_a - mean_b) / sqrt((sum var_a + sum var_b) / n^2)."""
    h, w = a.image.shape[:2]
    regions = [(slice(None), slice(None))] + [(slice(y * h // 2, (y + 1) * h // 2), slice(x * w // 2, (x + 1) * w // 2))
                                              for y in range(2) for x in range(2)]
    zs = []
    for rows, cols in regions:
        ia, ib = a.image[rows, cols].astype(float), b.image[rows, cols].astype(float)
        n = ia.shape[0] * ia.shape[1]
        var = a.variance[rows, cols].astype(float).sum((0, 1)) + b.variance[rows, cols].astype(float).sum((0, 1))
        diff = ia.mean((0, 1)) - ib.mean((0, 1))
        with np.errstate(divide="ignore", invalid="ignore"):
            zs.extend(np.where(var > 0, diff / np.sqrt(var / n ** 2), np.where(diff == 0, 0.0, np.inf)))
    return np.abs(np.array(zs))
