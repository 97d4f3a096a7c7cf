"""Tests for harness.judges.spectrum: the periodogram of white noise is flat at its variance within the stated
sampling error, a planted low-frequency error shows as excess power at the lowest frequencies (as much as its
amplitude predicts), a uniform bias goes to the DC term, and the floor is subtracted.

Tolerances: each ring's power is compared with its expectation to z times the stated relative error
sqrt(2 / (m K)) (conservative here: the synthetic channels are independent, the statement assumes them fully
correlated), z = 4.2: the two-sided normal quantile for a family-wise false-alarm rate of 1e-3 over the 64 ring
comparisons of a test (Bonferroni)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from harness.judges.spectrum import ensemble_spectrum, radial_spectrum, ring_index

SIZE, K, SIGMA = 64, 8, 0.3
Z = float(stats.norm.isf(1e-3 / 2 / 64))


def _noise(seed: int, shape=(SIZE, SIZE, 3)) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [SIGMA * rng.standard_normal(shape) for _ in range(K)]


def test_rings_hold_every_frequency_up_to_nyquist_once():
    rings, centres = ring_index(SIZE, SIZE)
    assert rings[0, 0] == 0 and len(centres) == SIZE // 2 and centres[0] == pytest.approx(0.5 / SIZE)
    counts = np.bincount(rings[rings > 0])[1:]
    assert counts[0] == 4  # (+-1, 0), (0, +-1)
    # every frequency of radius <= 1/2 is in one ring (the disc's area in frequency cells: ~ pi (N/2)^2)
    assert abs(counts.sum() - np.pi * (SIZE / 2) ** 2) < 2 * np.pi * SIZE / 2


def test_white_noise_is_flat_at_its_variance_within_the_stated_error():
    spec = ensemble_spectrum(_noise(1))
    power = np.array(spec["power"])
    err = np.array(spec["relative_error"])
    assert spec["renders"] == K and spec["floor"] == 0.0
    assert np.all(np.abs(power / SIGMA**2 - 1.0) <= Z * err), np.max(np.abs(power / SIGMA**2 - 1) / err)
    # the stated error is not vacuous: over the upper half the spread is far below 10 %
    assert abs(power[SIZE // 4:].mean() / SIGMA**2 - 1.0) < 0.05


def test_a_scaling_mistake_would_show():
    # the periodogram's normalisation: |FFT|^2 / pixels. Without it the level would be 4096 x the variance.
    single = radial_spectrum(_noise(2)[0][..., 0])
    assert 0.5 * SIGMA**2 < single["power"][0][SIZE // 4:].mean() < 2 * SIGMA**2


def test_a_low_frequency_error_shows_as_excess_power_at_the_lowest_ring_only():
    """A cosine of amplitude A with one period across the image puts A^2 N / 4 at each of its two frequencies
    (+-1, 0): the first ring (4 frequencies) rises by A^2 N / 8 over the noise, the others stay flat."""
    amplitude = 0.1 * SIGMA
    x = np.arange(SIZE)
    pattern = amplitude * np.cos(2 * np.pi * x / SIZE)[None, :, None] * np.ones((SIZE, 1, 3))
    spec = ensemble_spectrum([e + pattern for e in _noise(3)])
    power, err = np.array(spec["power"]), np.array(spec["relative_error"])
    excess = amplitude**2 * SIZE * SIZE / 8
    assert excess > 3 * Z * err[0] * SIGMA**2  # the planted error is well above what the test can resolve
    assert abs(power[0] - (SIGMA**2 + excess)) <= Z * err[0] * (SIGMA**2 + excess)
    assert np.all(np.abs(power[1:] / SIGMA**2 - 1.0) <= Z * err[1:])


def test_a_uniform_bias_is_the_dc_term_and_the_floor_is_subtracted():
    errors = [e + 0.05 for e in _noise(4)]
    spec = ensemble_spectrum(errors, floor=[0.01, 0.02, 0.03])
    # P(0) = N mean(e)^2: mean(e) = 0.05 + noise of sd SIGMA / 64
    assert spec["dc"] == pytest.approx(SIZE * SIZE * 0.05**2, rel=0.5)
    assert spec["floor"] == pytest.approx(0.02)
    assert spec["power_corrected"][5] == pytest.approx(spec["power"][5] - 0.02)
    assert np.all(np.abs(np.array(spec["power"]) / SIGMA**2 - 1) <= Z * np.array(spec["relative_error"]))
