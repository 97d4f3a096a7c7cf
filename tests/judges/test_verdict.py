"""Tests for harness.judges.verdict and harness.running.compare: false-alarm rate, power on planted faults, edge cases, files.

Rates are measured over SEEDS independent simulations.  A test with false-alarm probability alpha fails k of
SEEDS runs with k ~ Binomial(SEEDS, alpha); we require k / SEEDS <= alpha + 3 sd, sd = sqrt(alpha (1 - alpha) / SEEDS)
(for alpha = 0.01, SEEDS = 200: 0.0311, i.e. at most 6 failures; a correct test exceeds that with probability
~0.5 %).  The seeds are fixed, so the outcome is reproducible.

Simulation: truth R (64 x 64, a smooth gradient plus a bright square with sharp edges).  Each pixel of a render is
the mean of m samples drawn from N(R, m sigma^2), so its estimate has standard deviation sigma, and its variance
(of the mean) is the sample variance / m, estimated from those m samples.  Noise: sigma = 5 % of R per pixel in the
test image, 2 % in a noisy reference.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from conftest import fuzz_examples
from harness.running.compare import compare_files, compare_images
from harness.core.errors import HarnessError
from harness.files.imageio import ExrImage, write_exr
from harness.judges.verdict import Verdict, _to_normal, tile_z_scores, verdict

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

SEEDS = 200
ALPHA = 0.01
TEST_NOISE = 0.05
REF_NOISE = 0.02


def _max_failures(alpha: float, runs: int = SEEDS) -> int:
    """alpha + 3 binomial standard deviations, as a count of runs."""
    return math.floor(runs * (alpha + 3 * math.sqrt(alpha * (1 - alpha) / runs)))


def _truth(h: int = 64, w: int = 64) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    base = 0.5 + 0.3 * np.sin(2 * np.pi * x / w) * np.cos(np.pi * y / h)
    img = base[..., None] * np.array([1.0, 0.8, 0.6])
    img[20:44, 16:40] += 1.5  # sharp edges, for the shift fault
    return img


TRUTH = _truth()


def _render(mean: np.ndarray, rel_sigma: float, m: int, rng: np.random.Generator, correlated: bool = False):
    """Per pixel: m samples of N(mean, m sigma^2); returns (sample mean, sample variance / m)."""
    sd = rel_sigma * mean * np.sqrt(m)
    shape = mean.shape[:2] + (1,) + (m,) if correlated else mean.shape + (m,)
    samples = rng.standard_normal(shape)
    if correlated:  # one draw per pixel, broadcast over the channels
        samples = mean[..., None] + sd[..., None] * samples
    else:  # mean + sd z, computed in place (the same numbers, without two temporaries of the samples' size)
        samples *= sd[..., None]
        samples += mean[..., None]
    # np.mean and np.var(ddof=1) as numpy computes them (sum / m; sum of squared deviations from that mean / (m - 1)),
    # the mean summed once instead of twice
    mu = samples.sum(axis=-1, keepdims=True) / m
    samples -= mu
    samples *= samples
    return mu[..., 0], samples.sum(axis=-1) / (m - 1) / m


def _run(seed: int, m: int = 16, *, noisy_ref: bool = False, correlated: bool = False, fault=None, **kw) -> Verdict:
    rng = np.random.default_rng(seed)
    expected = TRUTH if fault is None else fault(TRUTH)
    t, vt = _render(expected, TEST_NOISE, m, rng, correlated)
    if noisy_ref:
        r, vr = _render(TRUTH, REF_NOISE, m, rng, correlated)
    else:
        r, vr = TRUTH, np.zeros_like(TRUTH)
    return verdict(t, vt, r, vr, **kw)


def _rates(verdicts: list[Verdict]) -> dict[str, int]:
    thr = verdicts[0].threshold
    return {
        "fail": sum(v.verdict == "fail" for v in verdicts),
        "global_bias": sum(v.global_bias["p_value"] < thr for v in verdicts),
        "omnibus": sum(v.omnibus["p_value"] < thr for v in verdicts),
        "max_z": sum(v.max_z["p_value"] < thr for v in verdicts),
    }


def _naive_pixel_test(t, vt, r, vr, alpha: float) -> bool:
    """The trap: one z per pixel and channel, max |z| Šidák-corrected. True = fail."""
    z = np.abs(t - r) / np.sqrt(vt + vr)
    p = 1.0 - (1.0 - 2.0 * stats.norm.sf(z.max())) ** z.size
    return bool(p < alpha)


# ---------------------------------------------------------------------------
# Quiet: a correct renderer passes at the nominal rate
# ---------------------------------------------------------------------------


def test_omnibus_is_calibrated_with_variances_of_one_degree_of_freedom() -> None:
    """Two replicates per pixel (the reference in a suite): each pixel's variance has one degree of freedom, and
    the tiles' Welch-Satterthwaite dof must be estimated from sum_p sigma_p^4 / nu_p, which v_p^2 / nu_p
    over-states threefold at nu = 1 (E[v^2] = sigma^4 (1 + 2 / nu)): the t correction then over-corrects and the
    omnibus statistic falls to 0.93 of its dof. With v_p^2 / (nu_p + 2) (unbiased for sigma_p^4 / nu_p) its mean
    over 200 renders is 1 within 4.5 standard errors (each render's statistic / dof has sd ~ sqrt(2 / 64))."""
    rng = np.random.default_rng(20261203)
    h = w = 64
    truth = np.ones((h, w, 3)) * np.linspace(0.5, 2.0, w)[None, :, None]
    sigma = 0.05 * truth * (1 + 3 * (np.arange(h)[:, None, None] % 16 < 4))  # uneven variances within tiles
    ratios = []
    for _ in range(200):
        reps = truth + sigma * math.sqrt(2) * rng.standard_normal((2, h, w, 1))  # two replicate means
        out = verdict(reps.mean(0), reps.var(0, ddof=1) / 2, truth, np.zeros_like(truth), tile=8, alpha=0.001,
                      test_dof=1).to_dict()
        ratios.append(np.mean(np.divide(out["omnibus"]["statistic"], out["omnibus"]["dof"])))
    se = np.std(ratios, ddof=1) / math.sqrt(len(ratios))
    assert abs(np.mean(ratios) - 1.0) < 4.5 * se, (np.mean(ratios), se)


def test_a_variance_estimate_near_zero_by_chance_does_not_raise_false_alarms() -> None:
    """The canonical soft-shadows case failed 2 of 10 correct renders this way: a tile whose variance is one
    bright edge pixel's (an emitter's silhouette), estimated from two replicates (one degree of freedom), beside a
    ground truth of small but precise variance (8192 spp). One time in twenty the estimate falls below 0.4 % of
    its mean; pooled into one Satterthwaite figure, the ground truth then looks dominant, the tile's dof large and
    its z normal, though it is nearly Cauchy: max |z| of 7 at p = 6e-10. With the smaller of the two images' own
    dof (Scheffé 1970) the level holds: at most ``_max_failures(alpha)`` of 60 renders fail (each render has 256
    such tiles per channel, the rest of the tile exact as a black background; the pooled figure fails every
    render). (Where the tile's other pixels are noisy, an estimate that falls below their sum fools the test
    image's own dof too; that takes a fall P(chi2(1) < x) ~ 0.8 sqrt(x) times rarer, x their share: no false
    alarm in 40 soft-shadows and 20 veach-mis seeds.)"""
    rng = np.random.default_rng(20261204)
    h = w = 64
    tile = 4
    edge = np.zeros((h, w, 1), dtype=bool)
    edge[::tile, ::tile] = True  # one edge pixel per tile
    sigma = np.where(edge, 1.0, 0.0)  # sd of a pixel's mean
    truth = np.full((h, w, 3), 0.5)
    gt_var = np.where(edge, 0.02, 0.0) * np.ones(3)  # the ground truth's share: 2 % of an edge pixel's variance
    alpha, seeds, fails = 0.01, 60, 0
    for _ in range(seeds):
        reps = truth + sigma * math.sqrt(2) * rng.standard_normal((2, h, w, 3))  # two replicate means
        gt = truth + np.sqrt(gt_var) * rng.standard_normal((h, w, 3))
        out = verdict(reps.mean(0), reps.var(0, ddof=1) / 2, gt, gt_var, tile=tile, alpha=alpha, test_dof=1,
                      expected_dof=8191)
        fails += not out.passed
    assert fails <= _max_failures(alpha, seeds), fails


@pytest.mark.parametrize("noisy_ref", [False, True], ids=["exact-reference", "noisy-reference"])
def test_false_alarm_rate_is_at_most_alpha(noisy_ref: bool) -> None:
    verdicts = [_run(seed, noisy_ref=noisy_ref) for seed in range(SEEDS)]
    rates = _rates(verdicts)
    print(f"\nquiet ({'noisy' if noisy_ref else 'exact'} reference, m=16): {rates} of {SEEDS}")
    assert rates["fail"] <= _max_failures(ALPHA)


def test_each_subtest_holds_its_level() -> None:
    # At alpha = 0.3 each sub-test is held to 0.1: enough failures to see a mis-calibrated sub-test.
    verdicts = [_run(seed, alpha=0.3) for seed in range(SEEDS)]
    rates = _rates(verdicts)
    print(f"\nsub-test rates at alpha/3 = 0.1 (m=16): {rates} of {SEEDS}")
    for name in ("global_bias", "omnibus", "max_z"):
        assert rates[name] <= _max_failures(0.1), name
    assert rates["fail"] <= _max_failures(0.3)


def test_correlated_channels_keep_the_rate_where_a_pooled_chi2_does_not() -> None:
    # In a render, R, G and B of a pixel come from the same paths.  Per-channel omnibus tests
    # (Bonferroni over channels) stay valid; one chi^2 over all tiles *and* channels does not.
    verdicts = [_run(seed, correlated=True, alpha=0.3) for seed in range(SEEDS)]
    rates = _rates(verdicts)
    pooled = sum(
        stats.chi2.sf(sum(v.omnibus["statistic"]), sum(v.omnibus["dof"])) < v.threshold for v in verdicts
    )
    print(f"\ncorrelated channels at alpha/3 = 0.1: {rates}; pooled chi2 would fail {pooled} of {SEEDS}")
    for name in ("global_bias", "omnibus", "max_z"):
        assert rates[name] <= _max_failures(0.1), name
    assert pooled > _max_failures(0.1)


# ---------------------------------------------------------------------------
# Heavy tails: variances from m = 4 samples
# ---------------------------------------------------------------------------


def test_few_samples_tiles_stay_near_nominal_while_a_per_pixel_test_does_not() -> None:
    m = 4
    tiled, tiled_dof, naive = 0, 0, 0
    for seed in range(SEEDS):
        rng = np.random.default_rng(seed)
        t, vt = _render(TRUTH, TEST_NOISE, m, rng)
        r, vr = TRUTH, np.zeros_like(TRUTH)
        tiled += verdict(t, vt, r, vr, alpha=ALPHA).verdict == "fail"
        tiled_dof += verdict(t, vt, r, vr, alpha=ALPHA, test_dof=m - 1).verdict == "fail"
        naive += _naive_pixel_test(t, vt, r, vr, ALPHA)
    print(f"\nm=4: tiled fails {tiled}, tiled with dof=3 fails {tiled_dof}, naive per-pixel fails {naive} of {SEEDS}")
    assert tiled <= _max_failures(ALPHA)
    assert tiled_dof <= _max_failures(ALPHA)
    assert naive >= SEEDS // 2


def test_few_samples_with_dof_hold_each_subtest_level() -> None:
    m = 4
    verdicts = [_run(seed, m, alpha=0.3, test_dof=m - 1) for seed in range(SEEDS)]
    rates = _rates(verdicts)
    print(f"\nm=4 with dof at alpha/3 = 0.1: {rates} of {SEEDS}")
    for name in ("global_bias", "omnibus", "max_z"):
        assert rates[name] <= _max_failures(0.1), name


def test_t_to_normal_conversion() -> None:
    # t = 2 on 10 dof has upper tail 0.036694; the normal quantile of that tail is 1.79041
    assert _to_normal(np.array([2.0, -2.0]), np.array([10.0, 10.0])) == pytest.approx([1.79041, -1.79041], abs=1e-5)
    assert _to_normal(np.array([3.0]), np.array([np.inf]))[0] == 3.0
    assert 7.5 < _to_normal(np.array([1e3]), np.array([5.0]))[0] < 8  # tail ~1e-14
    assert 37 < _to_normal(np.array([1e300]), np.array([5.0]))[0] < 38  # tail underflows: the largest finite z


# ---------------------------------------------------------------------------
# Sharp: planted faults fail
# ---------------------------------------------------------------------------


def _region_5pc(img: np.ndarray) -> np.ndarray:
    out = img.copy()
    out[24:32, 40:48] *= 1.05  # one 8x8 region, on the tile grid
    return out


FAULTS = {
    "energy-loss-2pc": (lambda img: 0.98 * img, "global_bias"),
    "shift-1px": (lambda img: np.roll(img, 1, axis=1), "max_z"),
    "region-5pc": (_region_5pc, "max_z"),
}


@pytest.mark.parametrize("name", list(FAULTS))
@pytest.mark.parametrize("noisy_ref", [False, True], ids=["exact-reference", "noisy-reference"])
def test_planted_fault_fails(name: str, noisy_ref: bool) -> None:
    fault, subtest = FAULTS[name]
    for seed in range(5):
        v = _run(1000 + seed, fault=fault, noisy_ref=noisy_ref)
        print(
            f"\n{name} ({'noisy' if noisy_ref else 'exact'} ref, seed {seed}): global z = "
            f"{[round(z, 1) for z in v.global_bias['z']]} p = {v.global_bias['p_value']:.2g}; omnibus chi2 = "
            f"{[round(s) for s in v.omnibus['statistic']]} on {v.omnibus['dof']} p = {v.omnibus['p_value']:.2g}; "
            f"max |z| = {v.max_z['statistic']:.1f} of {v.max_z['count']} p = {v.max_z['p_value']:.2g}"
        )
        assert v.verdict == "fail", v.reason
        assert getattr(v, subtest)["p_value"] < v.threshold, v.reason
        if name == "region-5pc":
            assert (v.worst_tile["y"], v.worst_tile["x"]) == (24, 40)


# ---------------------------------------------------------------------------
# Zero-variance tiles, partial tiles, non-finite pixels
# ---------------------------------------------------------------------------


def test_zero_variance_identical_passes_and_differing_fails() -> None:
    r = TRUTH.astype(np.float32)
    zero = np.zeros_like(r)
    v = verdict(r.copy(), zero, r, zero)
    assert v.verdict == "pass", v.reason
    assert v.zero_variance == {"tiles": 8 * 8 * 3, "differing": 0}
    # float32 rounding (one ulp) is not a difference
    v = verdict(np.nextafter(r, np.float32(np.inf)), zero, r, zero)
    assert v.verdict == "pass", v.reason

    t = r.copy()
    t[37, 50, 2] *= 1.0001
    v = verdict(t, zero, r, zero)
    assert v.verdict == "fail"
    assert "zero-variance tile differs" in v.reason
    assert v.zero_variance["differing"] == 1
    assert (v.worst_tile["y"], v.worst_tile["x"], v.worst_tile["channel"]) == (32, 48, "B")
    assert v.worst_tile["z"] == math.inf


def test_zero_variance_tiles_beside_noisy_ones() -> None:
    rng = np.random.default_rng(5)
    t, vt = _render(TRUTH, TEST_NOISE, 16, rng)
    t[:8, :] = TRUTH[:8, :]  # the top row of tiles is exact in both images
    vt[:8, :] = 0
    v = verdict(t, vt, TRUTH, np.zeros_like(TRUTH))
    assert v.verdict == "pass", v.reason
    assert v.zero_variance["tiles"] == 8 * 3
    assert v.max_z["count"] == 7 * 8 * 3
    t[3, 3, 0] += 1e-3
    assert "zero-variance tile differs" in verdict(t, vt, TRUTH, np.zeros_like(TRUTH)).reason


def test_partial_tiles_at_the_borders_count() -> None:
    rng = np.random.default_rng(6)
    truth = TRUTH[:21, :19]
    t, vt = _render(truth, TEST_NOISE, 16, rng)
    zero = np.zeros_like(truth)
    assert tile_z_scores(t, vt, truth, zero, 8).shape == (3, 3, 3)
    v = verdict(t, vt, truth, zero)
    assert v.verdict == "pass", v.reason
    assert v.max_z["count"] == 3 * 3 * 3
    assert v.omnibus["dof"] == [9, 9, 9]
    t2 = t.copy()
    t2[16:, 16:] *= 1.5  # only the 5x3-pixel corner tile is wrong
    v = verdict(t2, vt, truth, zero)
    assert v.verdict == "fail"
    assert (v.worst_tile["row"], v.worst_tile["col"]) == (2, 2)
    assert (v.worst_tile["height"], v.worst_tile["width"], v.worst_tile["pixels"]) == (5, 3, 15)


def test_nonfinite_test_pixels_fail_but_statistics_are_computed() -> None:
    rng = np.random.default_rng(7)
    t, vt = _render(TRUTH, TEST_NOISE, 16, rng)
    t[10, 10, 1] = np.nan
    vt[10, 10, 1] = np.nan
    t[50, 3, :] = np.inf
    v = verdict(t, vt, TRUTH, np.zeros_like(TRUTH))
    assert v.verdict == "fail"
    assert v.nonfinite_pixels == 2
    assert v.reason.startswith("2 non-finite pixels")
    assert v.max_z["p_value"] > v.threshold and v.global_bias["p_value"] > v.threshold


def test_missing_or_invalid_inputs_raise_clear_errors() -> None:
    r = TRUTH
    zero = np.zeros_like(r)
    with pytest.raises(ValueError, match="^test image: has no variance"):
        verdict(r, None, r, zero)
    with pytest.raises(ValueError, match="^ground truth image: has no variance"):
        verdict(r, zero, r, None)
    bad = r.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="^ground truth image: 1 non-finite"):
        verdict(r, zero, bad, zero)
    with pytest.raises(ValueError, match="^render.exr: 1 non-finite"):
        verdict(r, zero, bad, zero, names=("test.exr", "render.exr"))
    nan_var = zero.copy()
    nan_var[1, 1, 1] = np.nan
    with pytest.raises(ValueError, match="^test image: variance is NaN.*2 spp"):
        verdict(r, nan_var, r, zero)
    with pytest.raises(ValueError, match="negative"):
        verdict(r, zero - 1.0, r, zero)
    with pytest.raises(ValueError, match="tile"):
        verdict(r, zero, r, zero, tile=0)
    with pytest.raises(ValueError, match="alpha"):
        verdict(r, zero, r, zero, alpha=1.5)


def test_compare_images_raises_the_verdicts_image_errors_as_harness_errors() -> None:
    """compare_images (and harness compare through it) turns the verdict's ValueError about an image's own arrays
    into the HarnessError naming that image, with the same text; a bad tile stays a ValueError."""
    zero = np.zeros_like(TRUTH)
    bad, nan_var = TRUTH.copy(), zero.copy()
    bad[0, 0, 0] = np.nan
    nan_var[1, 1, 1] = np.nan
    for test, expected, where in ((ExrImage(TRUTH, None), ExrImage(TRUTH, zero), "test image"),
                                  (ExrImage(TRUTH, zero), ExrImage(bad, zero), "ground truth image"),
                                  (ExrImage(TRUTH, nan_var), ExrImage(TRUTH, zero), "test image"),
                                  (ExrImage(TRUTH, zero), ExrImage(TRUTH, zero - 1.0), "ground truth image")):
        with pytest.raises(ValueError) as raw:
            verdict(test.image, test.variance, expected.image, expected.variance)
        with pytest.raises(HarnessError) as info:
            compare_images(test, expected)
        assert info.value.where == where and str(info.value) == str(raw.value)
    with pytest.raises(ValueError, match="tile"):
        compare_images(ExrImage(TRUTH, zero), ExrImage(TRUTH, zero), tile=0)


def test_verdict_to_dict_is_json() -> None:
    v = _run(0)
    d = v.to_dict()
    assert set(d) >= {"verdict", "reason", "alpha", "tile", "global_bias", "omnibus", "max_z", "worst_tile"}
    json.dumps(d, allow_nan=False)
    assert "\n" not in d["reason"]


# ---------------------------------------------------------------------------
# compare_images / compare_files
# ---------------------------------------------------------------------------


def _exr_pair(tmp_path: Path, fault=None, spp: int = 16) -> tuple[Path, Path]:
    rng = np.random.default_rng(11)
    t, vt = _render(TRUTH if fault is None else fault(TRUTH), TEST_NOISE, spp, rng)
    r, vr = _render(TRUTH, REF_NOISE, spp, rng)
    tp = write_exr(tmp_path / "test.exr", t, vt, {"spp": str(spp), "renderer": "test"})
    rp = write_exr(tmp_path / "ref.exr", r, vr, {"spp": str(spp), "renderer": "reference"})
    return tp, rp


def test_compare_files_pass_and_fail(tmp_path: Path) -> None:
    tp, rp = _exr_pair(tmp_path)
    result = compare_files(tp, rp)
    json.dumps(result, allow_nan=False)
    assert set(result) == {
        "width", "height", "pixels", "nonfinite_pixels", "metric_pixels", "metric_note",
        "metrics", "bias", "conventions", "verdict", "images",
    }
    assert set(result["metrics"]) == {"rmse", "relmse", "mape", "psnr", "ssim", "flip"}
    assert result["verdict"]["verdict"] == "pass", result["verdict"]["reason"]
    assert result["verdict"]["variance_dof"] == {"test": 15, "ground_truth": 15}
    assert result["nonfinite_pixels"] == {"test": 0, "ground_truth": 0}

    tp, rp = _exr_pair(tmp_path, fault=lambda img: 0.98 * img)
    result = compare_files(tp, rp, tile=8, alpha=0.01)
    assert result["verdict"]["verdict"] == "fail"
    assert "global bias" in result["verdict"]["reason"]
    assert result["bias"]["overall"] < -3 * result["bias"]["stderr"]


def test_compare_images_identical_is_json_with_nulls_for_infinities() -> None:
    zero = np.zeros_like(TRUTH, dtype=np.float32)
    img = ExrImage(TRUTH.astype(np.float32), zero)
    result = compare_images(img, img)
    json.dumps(result, allow_nan=False)
    assert result["metrics"]["psnr"] is None  # infinite
    assert result["metrics"]["ssim"] == 1.0 and result["metrics"]["flip"] == 0.0
    assert result["verdict"]["verdict"] == "pass"


def test_compare_files_size_mismatch_names_both_files_and_sizes(tmp_path: Path) -> None:
    a = write_exr(tmp_path / "a.exr", TRUTH, np.zeros_like(TRUTH))
    b = write_exr(tmp_path / "b.exr", TRUTH[:32, :48], np.zeros_like(TRUTH[:32, :48]))
    with pytest.raises(HarnessError) as info:
        compare_files(a, b)
    msg = str(info.value)
    assert str(a) in msg and str(b) in msg and "64x64" in msg and "48x32" in msg


def test_compare_files_missing_variance_is_a_clear_error(tmp_path: Path) -> None:
    a = write_exr(tmp_path / "a.exr", TRUTH, np.zeros_like(TRUTH))
    b = write_exr(tmp_path / "b.exr", TRUTH)
    with pytest.raises(HarnessError, match="variance") as info:
        compare_files(a, b)
    assert str(b) in str(info.value)


def test_compare_files_with_nan_in_the_test_does_not_crash(tmp_path: Path) -> None:
    rng = np.random.default_rng(12)
    t, vt = _render(TRUTH, TEST_NOISE, 16, rng)
    t[5, 6] = np.nan
    tp = write_exr(tmp_path / "t.exr", t, vt)
    rp = write_exr(tmp_path / "r.exr", TRUTH, np.zeros_like(TRUTH))
    result = compare_files(tp, rp)
    json.dumps(result, allow_nan=False)
    assert result["nonfinite_pixels"] == {"test": 1, "ground_truth": 0}
    assert result["metric_pixels"] == 64 * 64 - 1
    assert result["verdict"]["verdict"] == "fail"
    assert "1 non-finite pixels" in result["verdict"]["reason"]
    assert all(isinstance(result["metrics"][k], float) for k in result["metrics"])


# ---------------------------------------------------------------------------
# Properties
# ---------------------------------------------------------------------------

@settings(max_examples=fuzz_examples(25), deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    scale=st.floats(1e-6, 1e6),
    h=st.integers(1, 20),
    w=st.integers(1, 20),
    tile=st.integers(1, 9),
)
def test_verdict_is_unit_free(seed: int, scale: float, h: int, w: int, tile: int) -> None:
    # Radiance units are arbitrary: scaling both images by k and their variances by k^2 changes no statistic.
    rng = np.random.default_rng(seed)
    r = rng.random((h, w, 3)) + 0.1
    v = (0.05 * r) ** 2 * rng.random((h, w, 3))
    t = r + np.sqrt(v) * rng.standard_normal((h, w, 3))
    a = verdict(t, v, r, np.zeros_like(r), tile=tile)
    b = verdict(t * scale, v * scale**2, r * scale, np.zeros_like(r), tile=tile)
    assert a.verdict == b.verdict
    assert b.max_z["statistic"] == pytest.approx(a.max_z["statistic"], rel=1e-9, abs=1e-12)
    assert b.omnibus["statistic"] == pytest.approx(a.omnibus["statistic"], rel=1e-9, abs=1e-12)
    assert b.global_bias["z"] == pytest.approx(a.global_bias["z"], rel=1e-9, abs=1e-12)
    assert a.max_z["count"] == b.max_z["count"] == 3 * (-(-h // tile)) * (-(-w // tile))


def test_tile_maps_are_the_tiles_the_max_z_test_judges():
    """The verdict's tile maps: p = 2 Phi(-|z|) of the worst tile is the max-|z| test's p before Šidák; a tile is
    marked failing exactly when the max-|z| sub-test fails on it; a planted error lights up its own tile only."""
    rng = np.random.default_rng(5)
    truth = np.full((32, 32, 3), 0.5)
    var = np.full_like(truth, 1e-4)
    test = truth + rng.normal(0.0, 1e-2, truth.shape)
    quiet = verdict(test, var, truth, np.zeros_like(truth), tile=8, alpha=0.01)
    assert quiet.tiles.z.shape == (4, 4, 3) and quiet.tiles.tested.all() and not quiet.tiles.failing.any()
    assert "tiles" not in quiet.to_dict()
    worst = float(quiet.tiles.p.min())
    assert 1 - (1 - worst) ** quiet.max_z["count"] == pytest.approx(quiet.max_z["p_value"], rel=1e-9)
    planted = test.copy()
    planted[8:16, 16:24] += 0.05  # z = 0.05 * 64 / (8 * 1e-2) = 40 in tile (1, 2)
    loud = verdict(planted, var, truth, np.zeros_like(truth), tile=8, alpha=0.01)
    assert loud.verdict == "fail" and "max |z|" in loud.reason
    expected = np.zeros((4, 4, 3), dtype=bool)
    expected[1, 2] = True
    np.testing.assert_array_equal(loud.tiles.failing, expected)
