"""harness convergence --repeats K: E[MSE] over K independent renders of a renderer whose variance is known matches
its expectation within a tolerance derived from K, the spread of the K MSEs is that of their known distribution,
and the page, JSON and plot carry them with the error spectrum ensemble.

Fake renderer: every pixel and channel of the truth plus independent N(0, s^2 / spp) noise, its variance
s^2 / spp reported; an exact ground truth (variance 0). One render's MSE over P = 3 x 32 x 32 values is then
(s^2 / spp) chi^2_P / P: mean s^2 / spp, standard deviation (s^2 / spp) sqrt(2 / P); the mean of K has standard
deviation (s^2 / spp) sqrt(2 / (P K)), and the sample variance of the K MSEs over their variance is
chi^2_{K-1} / (K - 1)."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats
from test_hostile_input import cli

from conftest import SCENES, load_small
from harness.renderers import RenderResult
from harness.studies.convergence import run_convergence, Series

pytestmark = pytest.mark.slow  # renders: outside the inner loop (pytest -m "not slow")

S2 = 0.04  # per-sample variance of the fake renderer
K = 16
LADDER = (1, 4, 16)
FALSE_ALARM = 1e-4  # per test, Bonferroni over its comparisons


class _Known:
    """Truth + N(0, S2 / spp) per pixel and channel, seeded; reports its exact variance."""

    name = "known"

    def __init__(self, truth):
        self.truth = truth

    def render(self, scene, request):
        rng = np.random.default_rng(request.seed)
        sd = math.sqrt(S2 / request.spp)
        image = self.truth + sd * rng.standard_normal(self.truth.shape)
        return RenderResult("known", image.astype(np.float32), np.full(self.truth.shape, sd * sd, np.float32),
                            0.001 * request.spp, request.spp, {}, {}, {})


def test_expected_mse_over_repeats_matches_the_renderers_variance():
    scene = load_small("furnace", 32)
    truth = np.full((32, 32, 3), 0.5)
    gt = SimpleNamespace(image=truth, variance=np.zeros_like(truth), source="exact", spp=0, path=None)
    result = run_convergence(scene, gt, [Series("known")], spp=LADDER, repeats=K, spectrum=True, warmup=False,
                             renderer_factory=lambda name: _Known(truth), min_timing_seconds=0.0)
    points = result["series"][0]["points"]
    assert result["repeats"] == K and [p["spp"] for p in points] == list(LADDER)
    values = 3 * 32 * 32
    comparisons = 2 * len(LADDER)
    z = stats.norm.isf(FALSE_ALARM / 2 / comparisons)
    low = stats.chi2.ppf(FALSE_ALARM / 2 / comparisons, K - 1) / (K - 1)
    high = stats.chi2.isf(FALSE_ALARM / 2 / comparisons, K - 1) / (K - 1)
    seeds = set()
    for p in points:
        expected = S2 / p["spp"]
        spread = p["repeats"]
        assert spread["k"] == K and len(spread["mse_corrected"]) == K and len(p["seeds"]) == K
        seeds.update(p["seeds"])
        assert abs(p["mse_corrected"] - expected) <= z * expected * math.sqrt(2 / (values * K)), p
        assert p["mse_corrected"] == pytest.approx(np.mean(spread["mse_corrected"]))
        sd_one = expected * math.sqrt(2 / values)  # the standard deviation of one render's MSE
        assert low <= (spread["mse_corrected_std"] / sd_one) ** 2 <= high, (spread["mse_corrected_std"], sd_one)
        band = spread["mse_corrected_band"]
        assert band[0] <= p["mse_corrected"] <= band[1]
        # white noise at the render's own variance: its spectrum's level is that variance
        spectrum = p["spectrum"]
        assert spectrum["renders"] == K and spectrum["render_variance"] == pytest.approx(expected, rel=1e-6)
        assert abs(np.mean(spectrum["power"]) / expected - 1) < 0.05
    assert len(seeds) == K * len(LADDER)  # every render its own seed
    # an unbiased renderer: RMSE of E[MSE] falls with slope -1/2
    assert abs(result["series"][0]["fit_rmse"]["slope"] + 0.5) < 0.02


def test_convergence_repeats_writes_the_spread_and_the_spectrum(tmp_path, capfd):
    out = tmp_path / "conv"
    code, stdout, stderr = cli(capfd, "convergence", SCENES / "furnace.toml", "--film", "16x16", "--spp", "2,8", "--repeats", 3,
                               "--out", out, "--quiet")
    assert code == 0, stderr
    doc = json.loads((out / "convergence.json").read_text())
    point = doc["series"][0]["points"][1]
    assert doc["repeats"] == 3 and point["repeats"]["k"] == 3 and len(point["seeds"]) == 3
    assert len(point["spectrum"]["power"]) == 8 and point["spectrum"]["floor"] == 0.0  # closed form: no floor
    assert "8 spp: E[MSE]" in stdout and "over 3 runs (sd" in stdout and "error spectrum" in stdout
    page = (out / "index.html").read_text()
    assert "Error of the error" in page and "Error spectrum ensemble" in page
    assert (out / "spectrum.png").stat().st_size > 1000


def test_repeats_out_of_range_is_one_line(tmp_path, capfd):
    code, out, err = cli(capfd, "convergence", SCENES / "furnace.toml", "--repeats", 0, "--out", tmp_path / "c")
    assert code == 2 and err.startswith("harness: error: --repeats:") and len(err.splitlines()) == 1
