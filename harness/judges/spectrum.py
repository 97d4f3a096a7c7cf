r"""The error spectrum: how an error image's power spreads over spatial frequency, radially averaged, and its
ensemble over independent renders (Celarek, Jakob, Wimmer and Lehtinen 2019).

For an error image :math:`e = T - R` of H x W pixels (one channel), the periodogram

.. math:: P(k) = |\hat e(k)|^2 / (H W), \qquad \hat e(k) = \sum_x e(x)\, e^{-2\pi i\, k \cdot x},

has :math:`E[P(k)] = \sigma^2` at every frequency k for white noise of variance :math:`\sigma^2` (independent
pixels): Monte Carlo noise is flat. Structured error (a bias that varies smoothly, a shifted edge) puts its power at
low frequencies, fireflies (isolated very bright pixels) raise every frequency alike but make the spectrum vary
wildly from render to render. :func:`radial_spectrum` averages P over rings of equal :math:`|k|` (in cycles per
pixel, ring width 1 / min(H, W)), leaving out k = 0, which holds the image's mean error: ``dc`` =
:math:`P(0) = H W \bar e^2`. :func:`ensemble_spectrum` averages over K renders and the three channels.

A ground truth with per-pixel variance V (independent pixels) adds its own white noise: :math:`\bar V` at every
frequency, the spectrum's *floor*, which ``power_corrected`` subtracts.

Sampling error: for real e, P(k) = P(-k), and for white Gaussian noise each P(k) is :math:`\sigma^2` times an
Exp(1) variable (:math:`\chi^2_2 / 2`) independent of the others but its mirror; a ring of m frequencies averages
m / 2 independent ones and K renders K times as many, so its relative standard error is
:math:`\sqrt{2 / (m K)}` (``relative_error``). The channels of a render share their paths and are treated as fully
correlated (no gain from averaging them), so the stated error is conservative for independent channels.

References
----------
.. [1] A. Celarek, W. Jakob, M. Wimmer, J. Lehtinen, "Quantifying the Error of Light Transport Algorithms",
   Computer Graphics Forum 38(4), 2019 (error spectrum ensembles).
.. [2] P. Stoica, R. Moses, "Spectral Analysis of Signals", Prentice Hall 2005, section 2.4 (the periodogram's
   distribution).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["ensemble_spectrum", "radial_spectrum", "ring_index"]


def ring_index(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """For each frequency of an H x W FFT its ring (0: k = 0, then 1, 2, ... by :math:`|k|` in steps of
    1 / min(H, W) cycles per pixel; rings beyond the largest full circle, |k| > 1/2, are left out as -1), and each
    ring's centre frequency (rings 1 ..)."""
    fy = np.fft.fftfreq(height)[:, None]
    fx = np.fft.fftfreq(width)[None, :]
    radius = np.sqrt(fx * fx + fy * fy)
    step = 1.0 / min(height, width)
    rings = np.ceil(radius / step - 1e-9).astype(int)  # (0, step] -> 1, (step, 2 step] -> 2, ...; k = 0 -> 0
    last = int(np.floor(0.5 / step + 1e-9))
    rings[rings > last] = -1
    centres = (np.arange(1, last + 1) - 0.5) * step
    return rings, centres


def radial_spectrum(error: np.ndarray) -> dict:
    r"""The radially averaged periodogram of one error image (H, W) or (H, W, C) per channel: ``power`` (C, rings),
    ``dc`` (C,): :math:`H W \bar e^2`, ``frequency`` (rings,), ``counts`` (frequencies per ring). Non-finite
    pixels count as 0."""
    e = np.nan_to_num(np.asarray(error, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    if e.ndim == 2:
        e = e[..., None]
    height, width, channels = e.shape
    spectrum = np.abs(np.fft.fft2(e, axes=(0, 1))) ** 2 / (height * width)
    rings, centres = ring_index(height, width)
    counts = np.bincount(rings[rings > 0].ravel(), minlength=len(centres) + 1)[1:]
    power = np.empty((channels, len(centres)))
    for c in range(channels):
        sums = np.bincount(rings[rings > 0].ravel(), weights=spectrum[..., c][rings > 0].ravel(),
                           minlength=len(centres) + 1)[1:]
        power[c] = sums / np.maximum(counts, 1)
    return {"power": power, "dc": spectrum[0, 0, :], "frequency": centres, "counts": counts}


def ensemble_spectrum(errors: Sequence[np.ndarray], floor: float | Sequence[float] = 0.0) -> dict:
    """The error spectrum ensemble of K error images (render minus ground truth, (H, W, C) each): the radial
    periodogram averaged over the renders and channels, as JSON-ready lists.

    ``floor``: the ground truth's own white-noise level, the mean of its per-pixel variance (one number, or one per
    channel, averaged). Returns ``frequency`` (cycles per pixel, ring centres), ``counts`` (frequencies per ring),
    ``power`` (mean over renders and channels), ``power_corrected`` (minus the floor), ``relative_error`` (the
    relative standard error of each ring's power for white noise, sqrt(2 / (m K))), ``floor``, ``dc`` (the mean
    over renders and channels of H W times the squared mean error) and ``renders`` K.
    """
    if not errors:
        raise ValueError("ensemble_spectrum needs at least one error image")
    parts = [radial_spectrum(e) for e in errors]
    power = np.mean([p["power"].mean(axis=0) for p in parts], axis=0)
    level = float(np.mean(np.asarray(floor, dtype=np.float64)))
    counts = parts[0]["counts"]
    k = len(parts)
    return {
        "frequency": [float(f) for f in parts[0]["frequency"]],
        "counts": [int(c) for c in counts],
        "power": [float(p) for p in power],
        "power_corrected": [float(p - level) for p in power],
        "relative_error": [float(np.sqrt(2.0 / (max(int(c), 1) * k))) for c in counts],
        "floor": level,
        "dc": float(np.mean([p["dc"].mean() for p in parts])),
        "renders": k,
    }
