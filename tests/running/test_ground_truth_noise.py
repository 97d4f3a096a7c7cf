"""A ground truth that does not blunt the test: harness run warns (console, results.json, the page) when the ground
truth's mean variance is more than 1/4 of the test render's, and harness ground-truth --spp auto picks an spp that
keeps it under."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_hostile_input import cli

from conftest import SCENES
from harness.files.results import read_results
from harness.judges.floor import GROUND_TRUTH_SHARE_LIMIT, ground_truth_share, spp_for_share
from harness.renderers import RenderResult, groundtruth
from harness.scene import load_scene

pytestmark = pytest.mark.slow  # renders: outside the inner loop (pytest -m "not slow")


def test_share_is_the_ratio_of_mean_variances_over_finite_pixels():
    test = np.full((4, 4, 3), 2.0)
    truth = np.full((4, 4, 3), 0.5)
    truth[0, 0, 0] = np.nan
    assert ground_truth_share(test, truth) == pytest.approx(0.25)
    assert ground_truth_share(np.zeros((2, 2, 3)), truth[:2, :2]) is None


@pytest.mark.parametrize("spp, share, expected", [
    (1024, 0.25, 1024), (1024, 0.26, 2048), (1024, 1.0, 4096), (1024, 0.01, 1024), (64, 5.3, 2048),
])
def test_spp_for_share_rounds_up_to_a_power_of_two(spp, share, expected):
    assert spp_for_share(spp, share) == expected
    assert share * spp / spp_for_share(spp, share) <= GROUND_TRUTH_SHARE_LIMIT or spp_for_share(spp, share) == spp


SUITE = """
[defaults]
film = { width = 16, height = 16 }
spp = 8

[[cases]]
# the ground truth: the same renderer at the same spp, so its variance is about the test's own (ratio ~ 1)
name = "furnace/blunt"
scene = "furnace"
against = { renderer = "reference", spp = 8, seed = 5 }

[[cases]]
# 64 spp against 8: ratio ~ 1/8, under the limit
name = "furnace/sharp"
scene = "furnace"
against = { renderer = "reference", spp = 64, seed = 5 }

[[cases]]
name = "furnace/closed-form"
scene = "furnace"
"""


def test_run_warns_once_per_case_whose_ground_truth_is_too_noisy(tmp_path, capfd):
    suite = tmp_path / "s.toml"
    suite.write_text(SUITE)
    out = tmp_path / "run"
    code, stdout, stderr = cli(capfd, "run", suite, "--out", out, "--executor", "serial", "--no-studies")
    assert code == 0, stderr
    warnings = [line for line in stderr.splitlines() if line.startswith("warning: ")]
    assert len(warnings) == 1 and warnings[0].startswith("warning: furnace/blunt: the ground truth's mean variance"), \
        stderr
    records = {r["name"]: r for r in read_results(out / "results.json")["cases"]}  # the schema reader takes it
    blunt, sharp = records["furnace/blunt"]["ground_truth_noise"], records["furnace/sharp"]["ground_truth_noise"]
    assert 0.5 < blunt["ratio"] < 2 and blunt["warning"]
    assert blunt["suggested_spp"] == spp_for_share(8, blunt["ratio"]) in (32, 64)  # 8 x ratio ~1 x 4, a power of 2
    assert f"against.spp = {blunt['suggested_spp']} would bring it under 1/4" in warnings[0]
    assert sharp["ratio"] < GROUND_TRUTH_SHARE_LIMIT and sharp["warning"] is None and sharp["suggested_spp"] is None
    assert records["furnace/closed-form"]["ground_truth_noise"]["ratio"] == 0.0
    page = (out / "index.html").read_text()
    assert page.count("Ground truth too noisy: the ground truth&#x27;s mean variance") == 1


def test_a_results_file_with_a_bad_noise_field_is_one_line(tmp_path, capfd):
    suite = tmp_path / "s.toml"
    suite.write_text(SUITE.split("[[cases]]\n# 64")[0])
    out = tmp_path / "run"
    assert cli(capfd, "run", suite, "--out", out, "--executor", "serial", "--no-studies", "--no-report")[0] == 0
    doc = json.loads((out / "results.json").read_text())
    doc["cases"][0]["ground_truth_noise"]["suggested_spp"] = 0
    (out / "results.json").write_text(json.dumps(doc))
    code, _, stderr = cli(capfd, "report", out / "results.json")
    assert code == 2 and "cases[0].ground_truth_noise.suggested_spp: expected an integer >= 1 or null" in stderr


class _Fake:
    """A renderer whose variance of the mean is ``per_sample / spp`` everywhere."""

    def __init__(self, name, per_sample):
        self.name, self.per_sample = name, per_sample

    def render(self, scene, request):
        shape = (scene.film.height, scene.film.width, 3)
        return RenderResult(self.name, np.zeros(shape, np.float32),
                            np.full(shape, self.per_sample / request.spp, np.float32), 0.0, request.spp, {}, {}, {})


def test_auto_spp_is_four_times_the_test_spp_times_the_per_sample_ratio(monkeypatch):
    fakes = {"reference": _Fake("reference", 0.02), "mitsuba": _Fake("mitsuba", 0.06)}
    monkeypatch.setattr(groundtruth, "get_renderer", lambda name: fakes[name])
    monkeypatch.setattr(groundtruth, "choose_variant", lambda variant: "scalar_rgb")
    chosen = groundtruth.auto_spp(load_scene(SCENES / "cornell-box.toml"), test_spp=64)
    assert chosen.ratio == pytest.approx(3.0, rel=1e-6)
    assert chosen.spp == 1024  # 4 x 64 x 3 = 768 -> 1024
    assert "4 x 64 (test spp) x 3" in chosen.reason() and "768" in chosen.reason()


def test_ground_truth_spp_auto_renders_what_it_chose(tmp_path, capfd):
    text = (SCENES / "cornell-box.toml").read_text().replace("width = 256", "width = 16").replace("height = 256",
                                                                                                   "height = 16")
    scene = tmp_path / "small.toml"
    scene.write_text(text)
    code, stdout, stderr = cli(capfd, "ground-truth", scene, "--spp", "auto", "--test-spp", 16, "--json")
    assert code == 0, stderr
    summary = json.loads(stdout)
    auto = summary["auto"]
    assert summary["spp"] == auto["spp"] >= 16 and auto["spp"] & (auto["spp"] - 1) == 0
    assert auto["spp"] >= 4 * 16 * auto["ratio"] > auto["spp"] / 2 or auto["spp"] == 16
