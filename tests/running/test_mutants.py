"""The verdict is sharp: every planted fault of reference_impl/mutants.py fails at the canonical suite's budget,
on the scene the canonical suite runs it on, while the same case without the fault passes."""

from __future__ import annotations

import dataclasses

import pytest
from conftest import ROOT

from harness.running.cases import load_suite
from harness.running.judge import run_case
from reference_impl.mutants import ALL_MUTANTS

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

CANONICAL = load_suite(ROOT / "suites" / "canonical.toml")
#: The ground truth here has at most this many spp (the suite gives some scenes up to 32768, so that its noise does
#: not blunt the verdict): a fault caught against a noisier ground truth is caught against the suite's, and the
#: test run renders each scene's ground truth in seconds.
TEST_GROUND_TRUTH_SPP = 1024
MUTANT_CASES = {c.settings["mutant"]: dataclasses.replace(c, ground_truth_spp=min(c.ground_truth_spp,
                                                                                   TEST_GROUND_TRUTH_SPP))
                for c in CANONICAL.cases if "mutant" in c.settings}


def test_every_mutant_has_a_canonical_case():
    assert set(MUTANT_CASES) == set(ALL_MUTANTS)
    assert all(case.expect == "fail" for case in MUTANT_CASES.values())


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("gt-cache")


@pytest.mark.parametrize("mutant", sorted(ALL_MUTANTS))
def test_mutant_is_caught_at_the_suite_budget(mutant, cache_dir, tmp_path):
    case = MUTANT_CASES[mutant]
    record = run_case(case, tmp_path, cache_dir=cache_dir)
    verdict = record["verdict"]
    print(f"{case.name}: verdict {verdict['verdict']}: {record['reason']}")
    assert record["status"] == "fail" and verdict["verdict"] == "fail", record.get("reason")


@pytest.mark.parametrize("scene", sorted({c.scene.stem for c in MUTANT_CASES.values()}))
def test_the_same_cases_without_a_fault_pass(scene, cache_dir, tmp_path):
    case = next(c for c in MUTANT_CASES.values() if c.scene.stem == scene)
    clean = dataclasses.replace(case, name=f"{scene}/clean", settings={}, expect="pass")
    record = run_case(clean, tmp_path, cache_dir=cache_dir)
    assert record["status"] == "pass", record.get("reason")
