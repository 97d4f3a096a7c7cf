"""suites/real-scale.toml's budgets keep every ground truth's noise under 1/4 of its test render's (docs/suites.md,
"A ground truth that does not blunt the test"), checked from the budgets and each case's measured per-sample
variance ratio k (ground_truth_noise.ratio x ground_truth_spp / spp of a run's record), read from the file with
tomllib: nothing is generated or loaded here."""

from __future__ import annotations

import tomllib

from conftest import ROOT
from harness.judges.floor import GROUND_TRUTH_SHARE_LIMIT

SUITE = ROOT / "suites" / "real-scale.toml"

#: k of each case, measured by `harness run suites/real-scale.toml` with an empty cache (2026-12-06, llvm_ad_rgb, at
#: the budgets of the file). A new case needs its k: run it and read ground_truth_noise in results.json.
PER_SAMPLE_RATIO = {
    "room/reference": 0.508,
    "city/light-selection-power": 1.26,
    "city/light-selection-uniform": 0.265,
    "city/light-selection-tree": 10.5,  # its variance per sample is a tenth of power's: 64 spp (2026-12-06, main)
    "forest/reference": 3.24,
}


def cases() -> list[dict]:
    document = tomllib.loads(SUITE.read_text(encoding="utf-8"))
    defaults = document.get("defaults", {})
    return [{**defaults, **case} for case in document["cases"]]


def test_every_case_has_a_measured_ratio():
    assert sorted(c["name"] for c in cases()) == sorted(PER_SAMPLE_RATIO)


def test_every_ground_truth_is_under_a_quarter_of_its_test():
    for case in cases():
        share = PER_SAMPLE_RATIO[case["name"]] * case["spp"] / case["ground_truth_spp"]
        assert share <= GROUND_TRUTH_SHARE_LIMIT, (case["name"], share)


def test_only_the_many_light_scene_has_studies():
    for case in cases():
        assert case.get("studies", True) == case["scene"].startswith("generated:city"), case["name"]
