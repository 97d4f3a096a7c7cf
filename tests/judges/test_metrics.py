"""Tests for harness.judges.metrics: exact values on tiny arrays, identities, NaN handling."""

from __future__ import annotations

import math
import os
import sys

import numpy as np
import pytest
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from harness.judges import metrics


def _pair() -> tuple[np.ndarray, np.ndarray]:
    """A 1x2-pixel test/reference pair whose metrics are worked out by hand below."""
    test = np.array([[[1.0, 2.0, 3.0], [0.0, 0.0, 0.5]]])
    ref = np.array([[[1.0, 1.0, 1.0], [0.0, 1.0, 1.0]]])
    # differences: 0, 1, 2, 0, -1, -0.5
    return test, ref


def _smooth(h: int = 24, w: int = 32, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    base = 0.4 + 0.3 * np.sin(x / 3.0) * np.cos(y / 5.0)
    img = base[..., None] * np.array([1.0, 0.7, 0.5]) + 0.05 * rng.random((h, w, 3))
    img[8:16, 10:20] += 2.0  # HDR values above display white
    return img


# ---------------------------------------------------------------------------
# Point-wise metrics: exact values
# ---------------------------------------------------------------------------


def test_rmse_exact() -> None:
    t, r = _pair()
    # squared differences 0 + 1 + 4 + 0 + 1 + 0.25 = 6.25 over 6 values
    assert metrics.rmse(t, r) == pytest.approx(math.sqrt(6.25 / 6), rel=1e-15)


def test_relmse_exact() -> None:
    t, r = _pair()
    eps = 1e-2
    expected = (0 / (1 + eps) + 1 / (1 + eps) + 4 / (1 + eps) + 0 / (0 + eps) + 1 / (1 + eps) + 0.25 / (1 + eps)) / 6
    assert metrics.relmse(t, r) == pytest.approx(expected, rel=1e-14)
    assert metrics.relmse(t, r, eps=1.0) == pytest.approx((0 + 0.5 + 2 + 0 + 0.5 + 0.125) / 6, rel=1e-14)


def test_mape_exact() -> None:
    t, r = _pair()
    eps = 1e-2
    expected = (0 + 1 / (1 + eps) + 2 / (1 + eps) + 0 / eps + 1 / (1 + eps) + 0.5 / (1 + eps)) / 6
    assert metrics.mape(t, r) == pytest.approx(expected, rel=1e-14)


def test_psnr_exact_on_linear_radiance_with_reference_peak() -> None:
    t = np.array([[[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]]])
    r = np.array([[[1.0, 2.0, 4.0], [0.0, 0.0, 0.0]]])
    # MSE = 1/6, peak = max(reference) = 4
    assert metrics.psnr(t, r) == pytest.approx(10 * math.log10(16 / (1 / 6)), rel=1e-12)
    assert metrics.psnr(t, r, data_range=1.0) == pytest.approx(10 * math.log10(6.0), rel=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_psnr_is_scikit_images_bit_for_bit(seed) -> None:
    """metrics.psnr computes what skimage.metrics.peak_signal_noise_ratio does (it no longer calls it: that module
    imports scipy.stats), on float32 renders of HDR radiance with NaN pixels, with the default and a given peak."""
    rng = np.random.default_rng(seed)
    r = (rng.lognormal(0.0, 1.5, (23 + seed, 31, 3))).astype(np.float32)
    t = (r * rng.normal(1.0, 0.2, r.shape)).astype(np.float32)
    t[seed, 3, 1] = np.nan
    mask = np.all(np.isfinite(t), axis=-1)
    tm, rm = t[mask].astype(np.float64), r[mask].astype(np.float64)
    for peak in (None, 1.0, 123.456):
        theirs = peak_signal_noise_ratio(rm, tm, data_range=float(rm.max()) if peak is None else peak)
        assert metrics.psnr(t, r, data_range=peak) == float(theirs)


def test_psnr_identical_is_inf_and_black_reference_is_nan() -> None:
    img = _smooth()
    assert metrics.psnr(img, img) == math.inf
    black = np.zeros((2, 2, 3))
    assert math.isnan(metrics.psnr(black + 1.0, black))
    assert metrics.psnr(black, black) == math.inf


def test_float32_inputs_are_computed_in_float64() -> None:
    t, r = _pair()
    assert metrics.rmse(t.astype(np.float32), r.astype(np.float32)) == pytest.approx(metrics.rmse(t, r), rel=1e-15)


def test_shape_mismatch_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="shape"):
        metrics.rmse(np.zeros((2, 2, 3)), np.zeros((2, 3, 3)))
    with pytest.raises(ValueError, match=r"\(H, W, C\)"):
        metrics.rmse(np.zeros((2, 3)), np.zeros((2, 3)))


# ---------------------------------------------------------------------------
# Bias
# ---------------------------------------------------------------------------


def test_bias_exact_with_standard_errors() -> None:
    t, r = _pair()
    vt = np.array([[[0.1, 0.2, 0.3], [0.3, 0.2, 0.1]]])
    vr = np.array([[[0.0, 0.2, 0.1], [0.0, 0.0, 0.0]]])
    b = metrics.bias(t, r, vt, vr)
    assert b["per_channel"] == pytest.approx([0.0, 0.0, 0.75])
    assert b["overall"] == pytest.approx(0.25)
    # se_c = sqrt(sum_p (vt + vr)) / N, N = 2
    se = [math.sqrt(0.4) / 2, math.sqrt(0.6) / 2, math.sqrt(0.5) / 2]
    assert b["stderr_per_channel"] == pytest.approx(se, rel=1e-14)
    assert b["stderr"] == pytest.approx(sum(se) / 3, rel=1e-14)


def test_bias_without_variances_has_no_stderr() -> None:
    t, r = _pair()
    b = metrics.bias(t, r)
    assert b["stderr"] is None and b["stderr_per_channel"] is None
    assert metrics.bias(t, r, np.zeros_like(t))["stderr"] is None


# ---------------------------------------------------------------------------
# SSIM
# ---------------------------------------------------------------------------


def test_ssim_identical_is_one() -> None:
    img = _smooth()
    assert metrics.ssim(img, img) == 1.0
    small = img[:5, :6]  # below the 11x11 Gaussian window: uniform 5x5 window
    assert metrics.ssim(small, small) == 1.0


def test_ssim_matches_scikit_image_on_srgb_images() -> None:
    ref = _smooth()
    test = ref * 1.1 + 0.02
    expected = structural_similarity(
        metrics.srgb_encode(ref),
        metrics.srgb_encode(test),
        channel_axis=2,
        data_range=1.0,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
    )
    value, smap = metrics.ssim(test, ref, full=True)
    assert value == pytest.approx(expected, rel=1e-12)
    assert smap.shape == ref.shape
    assert value < 1.0


def test_ssim_of_tiny_images_is_nan() -> None:
    img = np.ones((2, 2, 3))
    assert math.isnan(metrics.ssim(img, img))


def test_srgb_encode_endpoints() -> None:
    enc = metrics.srgb_encode(np.array([-1.0, 0.0, 0.0031308, 1.0, 5.0]))
    assert enc[0] == 0.0 and enc[1] == 0.0 and enc[3] == pytest.approx(1.0) and enc[4] == pytest.approx(1.0)
    assert enc[2] == pytest.approx(12.92 * 0.0031308, rel=1e-3)


# ---------------------------------------------------------------------------
# FLIP
# ---------------------------------------------------------------------------


def test_flip_identical_is_zero_and_different_is_positive() -> None:
    ref = _smooth()
    assert metrics.flip(ref, ref) == 0.0
    value, emap = metrics.flip(ref * 1.2, ref, full=True)
    assert value > 0.0
    assert emap.shape == ref.shape[:2]
    assert np.all((emap >= 0) & (emap <= 1))


def test_flip_mean_is_the_packages_mean() -> None:
    flip_evaluator = metrics.flip_module()

    ref = _smooth().astype(np.float32)
    test = (ref * 0.9).astype(np.float32)
    _, expected, _ = flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False)
    assert metrics.flip(test, ref) == pytest.approx(expected, rel=1e-4)


def test_flip_is_scale_invariant_and_survives_dim_and_black_references() -> None:
    # flip-evaluator ends the process when the reference's luminance is below ~1e-7;
    # metrics.flip normalises by the reference's peak so that never happens.
    ref = _smooth()
    test = ref * 1.2
    base = metrics.flip(test, ref)
    assert metrics.flip(test * 1e-12, ref * 1e-12) == pytest.approx(base, rel=1e-3)
    black = np.zeros_like(ref)
    assert metrics.flip(test, black) > 0.0
    assert metrics.flip(black, black) == 0.0
    assert metrics.flip(ref - 10.0, ref) > 0.0  # negative values are clipped, not fatal


# ---------------------------------------------------------------------------
# Non-finite values
# ---------------------------------------------------------------------------


def test_nonfinite_test_pixels_are_counted_and_left_out() -> None:
    ref = _smooth()
    clean = ref * 1.05
    test = clean.copy()
    test[3, 4, 1] = np.nan
    test[10, 2, :] = np.inf
    test[20, 30, 0] = -np.inf
    assert metrics.count_nonfinite(test) == 3
    mask = metrics.finite_mask(test, ref)
    assert mask.sum() == ref.shape[0] * ref.shape[1] - 3
    # point-wise metrics equal those on the finite pixels alone
    assert metrics.rmse(test, ref) == pytest.approx(np.sqrt(np.mean((clean[mask] - ref[mask]) ** 2)), rel=1e-14)
    for f in (metrics.rmse, metrics.relmse, metrics.mape, metrics.psnr, metrics.ssim, metrics.flip):
        value = f(test, ref)
        assert math.isfinite(value), f.__name__
    b = metrics.bias(test, ref, np.ones_like(ref), np.zeros_like(ref))
    assert b["per_channel"] == pytest.approx(list((clean[mask] - ref[mask]).mean(axis=0)), rel=1e-12)
    assert all(math.isfinite(x) for x in b["stderr_per_channel"])


def test_nonfinite_pixels_do_not_spread_into_windowed_metrics() -> None:
    ref = _smooth()
    test = ref.copy()
    test[12, 12] = np.nan
    # the NaN pixel gets the reference's value, so an otherwise identical image is perfect
    assert metrics.ssim(test, ref) == 1.0
    assert metrics.flip(test, ref) == 0.0


def test_all_nonfinite_gives_nan_not_an_exception() -> None:
    ref = _smooth(6, 6)
    test = np.full_like(ref, np.nan)
    for f in (metrics.rmse, metrics.relmse, metrics.mape, metrics.psnr, metrics.ssim, metrics.flip):
        assert math.isnan(f(test, ref)), f.__name__
    assert math.isnan(metrics.bias(test, ref)["overall"])


def test_flip_is_loaded_with_sleeping_openmp_threads_and_leaves_the_environment_alone(tmp_path, monkeypatch) -> None:
    """``flip_module`` imports the package while ``OMP_WAIT_POLICY`` is ``passive`` (its OpenMP runtime reads it once,
    at load), keeps a value the user set, and leaves ``os.environ`` as it found it. A stand-in package records what
    it saw at import."""
    (tmp_path / "flip_evaluator.py").write_text("import os\nSEEN = os.environ.get('OMP_WAIT_POLICY')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "flip_evaluator", raising=False)
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    assert metrics.flip_module().SEEN == "passive" and "OMP_WAIT_POLICY" not in os.environ
    monkeypatch.delitem(sys.modules, "flip_evaluator")
    monkeypatch.setenv("OMP_WAIT_POLICY", "active")
    assert metrics.flip_module().SEEN == "active" and os.environ["OMP_WAIT_POLICY"] == "active"
