"""Per-pixel Monte Carlo estimates as sample moments, so that independent chunks of samples merge exactly.

A chunk of n samples per pixel is summarised by its mean and the variance of that mean, or equivalently by the
sums S1 = sum x and S2 = sum x^2 (per pixel and channel). Sums of independent chunks add, so merging is exact
(order-independent up to float64 addition), and the merged estimate is the one all samples together would give:

    mean = S1 / N,    sample variance s^2 = (S2 - S1^2 / N) / (N - 1),    variance of the mean = s^2 / N.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Estimate:
    """n samples per pixel: their mean (H, W, 3) and the variance of that mean (H, W, 3)."""

    mean: np.ndarray
    variance: np.ndarray
    n: int

    def sums(self) -> tuple[np.ndarray, np.ndarray]:
        """(S1, S2) in float64, inverting the formulas above."""
        mean = self.mean.astype(np.float64)
        s1 = self.n * mean
        if self.n > 1:
            s2 = self.variance.astype(np.float64) * self.n * (self.n - 1) + s1 * s1 / self.n
        else:
            s2 = s1 * s1
        return s1, s2

    @classmethod
    def from_sums(cls, s1: np.ndarray, s2: np.ndarray, n: int) -> "Estimate":
        mean = s1 / n
        if n > 1:
            variance = np.maximum(s2 - s1 * s1 / n, 0.0) / (n - 1) / n
        else:
            variance = np.full_like(mean, np.nan)
        return cls(mean, variance, n)


def merge(estimates: Iterable[Estimate]) -> Estimate:
    """The estimate of all samples of independent chunks together."""
    estimates = list(estimates)
    if not estimates:
        raise ValueError("nothing to merge")
    if len(estimates) == 1:
        return estimates[0]
    s1 = np.zeros(estimates[0].mean.shape)
    s2 = np.zeros(estimates[0].mean.shape)
    n = 0
    for est in estimates:
        a, b = est.sums()
        s1 += a
        s2 += b
        n += est.n
    return Estimate.from_sums(s1, s2, n)
