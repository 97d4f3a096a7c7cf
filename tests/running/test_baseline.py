"""Baselines: the statistical regression rules (false alarms and power on synthetic noise), and the gate end to end
(`harness baseline save`, `harness run --baseline`) on a 16 x 16 furnace (closed form: no Mitsuba)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from scipy import stats

from harness.running import baseline, tolerances
from harness.cli import main

FURNACE = ROOT / "scenes" / "furnace.toml"
SUITE = f"""
name = "tiny"
[defaults]
spp = 16
film = {{ width = 16, height = 16 }}

[[cases]]
name = "furnace/reference"
scene = "{FURNACE}"
SETTINGS

[[cases]]
name = "furnace/mutant"
scene = "{FURNACE}"
settings = {{ mutant = "double-emission" }}
expect = "fail"
"""


PINNED = "settings = { rr_depth = 5 }"  # explicit, so that a change of the renderer's defaults moves nothing here
NOISIER = 'settings = { rr_depth = 5, direct = "hemisphere-uniform" }'  # unbiased, ~3.8x the relMSE at 16 spp


def write_suite(path: Path, settings: str = PINNED, extra: str = "", top: str = "") -> Path:
    path.write_text(top + SUITE.replace("SETTINGS", settings) + extra)
    return path


def cli(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


# ---- the rules on synthetic images -----------------------------------------------------------------------------


def _noisy(rng, reference: np.ndarray, sigma: float):
    """A Monte Carlo-like estimate: skewed noise (a centred exponential, as from few light paths), its variance."""
    noise = sigma * (rng.exponential(1.0, reference.shape) - 1.0)
    return reference + noise, np.full(reference.shape, sigma**2)


def _entry(image, variance, reference) -> dict:
    return {"statistics": baseline.image_statistics(image, variance, reference), "metrics": {},
            "render": {"seconds": 1.0, "paths_per_second": 1.0}}


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_noise_rules_false_alarm_rate_is_at_most_alpha():
    """Two independent renders of the same quality: the case's checks (rmse, relmse, mape, bias; Bonferroni) flag a
    regression with probability <= alpha. With alpha = 0.05 over n = 400 seeded trials, the count of false alarms
    exceeds the Binomial(400, 0.05) quantile at 1 - 1e-4 with probability < 1e-4 if the rule holds its level."""
    rng = np.random.default_rng(20261126)
    reference = rng.uniform(0.2, 2.0, (32, 32, 3))
    tolerance = dict(tolerances.DEFAULTS, alpha=0.05)
    trials, alarms = 400, 0
    for _ in range(trials):
        base = _entry(*_noisy(rng, reference, 0.3), reference)
        new = _entry(*_noisy(rng, reference, 0.3), reference)
        alarms += bool(baseline.compare(base, new, tolerance)["regressions"])
    assert alarms <= stats.binom.isf(1e-4, trials, 0.05), alarms


def test_noise_rules_catch_more_noise_and_a_bias():
    """A 1.5x noise level (2.25x MSE) at 32 x 32: log ratio 0.81 against a spread of ~0.06, a miss has probability
    < 1e-12; a 2 % bias at 8 standard errors of the mean likewise. Both are caught in every seeded trial."""
    rng = np.random.default_rng(7)
    reference = rng.uniform(0.2, 2.0, (32, 32, 3))
    for _ in range(20):
        base = _entry(*_noisy(rng, reference, 0.3), reference)
        noisier = baseline.compare(base, _entry(*_noisy(rng, reference, 0.45), reference), tolerances.DEFAULTS)
        assert any(r.startswith("baseline: relmse") for r in noisier["regressions"]), noisier
        image, variance = _noisy(rng, reference, 0.3)
        shift = 8 * 0.3 / np.sqrt(32 * 32)  # 8 standard errors of a channel mean
        biased = baseline.compare(base, _entry(image + shift, variance, reference), tolerances.DEFAULTS)
        assert any("bias in" in r for r in biased["regressions"]), biased


def test_identical_render_never_regresses_and_factors_override():
    rng = np.random.default_rng(3)
    reference = rng.uniform(0.2, 2.0, (16, 16, 3))
    image, variance = _noisy(rng, reference, 0.3)
    entry = _entry(image, variance, reference)
    assert baseline.compare(entry, entry, tolerances.DEFAULTS)["regressions"] == []
    worse = _entry(reference + 1.08 * (image - reference), variance, reference)  # relMSE x 1.17
    tight = tolerances.option_tolerances(["relmse=1.10", "rmse=off", "mape=off", "bias=off"], tolerances.DEFAULTS)
    reasons = baseline.compare(entry, worse, tight)["regressions"]
    assert len(reasons) == 1 and reasons[0].startswith("baseline: relmse") and "> 1.1 x" in reasons[0]
    # A bias that shrinks towards the reference is a fix, not a regression.
    fixed = _entry(image - 0.5 * (image.mean(axis=(0, 1)) - reference.mean(axis=(0, 1))), variance, reference)
    assert not [r for r in baseline.compare(entry, fixed, tolerances.DEFAULTS)["regressions"] if "bias" in r]


@pytest.mark.parametrize("item,where", [
    ("relmse=0.9", "factor >= 1"), ("relmse", "KEY=VALUE"), ("nosie=2", "unknown baseline tolerance"),
    ("alpha=2", "probability"), ("seconds=auto", "'auto'"), ("psnr=x", "expected a number"),
])
def test_bad_tolerances_are_one_line_errors(item, where):
    from harness.core.errors import HarnessError

    with pytest.raises(HarnessError) as info:
        tolerances.option_tolerances([item], tolerances.DEFAULTS)
    assert "--baseline-tolerance" in str(info.value) and where in str(info.value)


# ---- the gate end to end ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def saved_once(tmp_path_factory) -> Path:
    """A folder with the tiny suite, its baseline (base.json) and the run it was saved from (run0/), made once for
    the module (the same renders, seeded, in every test)."""
    folder = tmp_path_factory.mktemp("saved")
    suite = write_suite(folder / "tiny.toml")
    assert main(["baseline", "save", str(suite), "--out", str(folder / "base.json"),
                 "--run-out", str(folder / "run0"), "--quiet"]) == 0
    return folder


@pytest.fixture
def saved(tmp_path, saved_once):
    """The suite and its baseline, copied into the test's own folder (with run0/) for it to use and change."""
    shutil.copytree(saved_once, tmp_path, dirs_exist_ok=True)
    return tmp_path / "tiny.toml", tmp_path / "base.json"


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_save_then_gate(tmp_path, capsys, saved):
    suite, base = saved
    doc = json.loads(base.read_text())
    assert doc["schema"] == baseline.SCHEMA and doc["suite"] == "tiny" and set(doc["cases"]) == {
        "furnace/reference", "furnace/mutant"}
    entry = doc["cases"]["furnace/reference"]
    assert entry["statistics"]["relmse"]["value"] == pytest.approx(entry["metrics"]["relmse"], rel=1e-9)
    assert doc["tools"]["mitsuba"] and entry["render"]["paths_per_second"] > 0

    # Unchanged: bit-identical renders, every ratio 1.
    code, out, err = cli(capsys, "run", suite, "--baseline", base, "--out", tmp_path / "same", "--executor", "serial",
                         "--no-report", "--quiet")
    assert code == 0, out + err
    assert "1 cases compared, 0 regressed" in out
    record = json.loads((tmp_path / "same" / "results.json").read_text())["cases"][0]
    assert all(c["ok"] and c["value"] == c["baseline"] for c in record["baseline"]["checks"])

    # A changed setting, unbiased but 3.8x the relMSE: the verdict passes, the baseline does not.
    changed = write_suite(tmp_path / "changed.toml", NOISIER)
    code, out, err = cli(capsys, "run", changed, "--baseline", base, "--out", tmp_path / "changed",
                         "--executor", "serial", "--no-report", "--quiet")
    assert code == 1, out + err
    results = json.loads((tmp_path / "changed" / "results.json").read_text())
    record = results["cases"][0]
    assert record["status"] == "pass" and record["ok"] is False
    assert record["reason"].startswith("baseline: ") and "baseline: relmse " in record["reason"]
    assert record["baseline"]["changed"]["settings"]["now"] == {"rr_depth": "5", "direct": "hemisphere-uniform",
                                                            "replicates": "2"}
    assert results["summary"]["unexpected"] == ["furnace/reference"]
    assert results["baseline"]["regressed"] == ["furnace/reference"]

    # The suite's [baseline] table, and the option on top of it, override the rule.
    loose = write_suite(tmp_path / "loose.toml", NOISIER,
                        extra="\n[baseline]\nrelmse = 20.0\nrmse = 20.0\nmape = 20.0\n")
    code, out, err = cli(capsys, "run", loose, "--baseline", base, "--out", tmp_path / "loose", "--executor", "serial",
                         "--no-report", "--quiet")
    assert code == 0, out + err
    code, out, err = cli(capsys, "run", loose, "--baseline", base, "--baseline-tolerance", "relmse=1.5",
                         "--out", tmp_path / "loose", "--executor", "serial", "--no-report", "--quiet")
    assert code == 1 and "> 1.5 x" in out  # the resumed record is judged again, against the new tolerance


def test_missing_case_is_reported_not_failed_and_from_results(tmp_path, capsys, saved):
    suite, base = saved
    extra = '\n[[cases]]\nname = "furnace/seed-9"\nscene = "' + str(FURNACE) + '"\nseed = 9\n'
    grown = write_suite(tmp_path / "grown.toml", extra=extra)
    code, out, err = cli(capsys, "run", grown, "--baseline", base, "--out", tmp_path / "grown", "--executor", "serial",
                         "--no-report", "--quiet")
    assert code == 0, out + err
    assert "not in the baseline (reported, not failed): furnace/seed-9" in out
    # --from takes that run: the same entries as a fresh save, plus the new case.
    code, out, err = cli(capsys, "baseline", "save", grown, "--out", tmp_path / "from.json",
                         "--from", tmp_path / "grown" / "results.json")
    assert code == 0, err
    doc = json.loads((tmp_path / "from.json").read_text())
    old = json.loads(base.read_text())
    assert set(doc["cases"]) == {"furnace/reference", "furnace/mutant", "furnace/seed-9"}
    assert doc["cases"]["furnace/reference"]["statistics"] == old["cases"]["furnace/reference"]["statistics"]


def test_save_refuses_a_run_not_as_expected(tmp_path, capsys):
    suite = write_suite(tmp_path / "bad.toml", 'settings = { mutant = "double-emission" }')
    code, out, err = cli(capsys, "baseline", "save", suite, "--out", tmp_path / "base.json", "--run-out",
                         tmp_path / "run", "--quiet")
    assert code == 1 and "baseline not written" in err and not (tmp_path / "base.json").exists()


@pytest.mark.parametrize("change,where", [
    ("name", "baseline of suite 'tiny', not of 'other'"),
    ("spp", "case 'furnace/reference' was saved for another content"),
    ("json", "not a baseline file"),
    ("missing", "no such baseline file"),
    ("tolerance", "--baseline-tolerance"),
    ("suite-table", "baseline.relmse"),
    ("junit", "--junit"),
])
def test_bad_baselines_are_one_line_errors(tmp_path, capsys, saved, change, where):
    suite, base = saved
    args = ["--baseline", base]
    if change == "name":
        suite = write_suite(tmp_path / "other.toml")
        suite.write_text(suite.read_text().replace('name = "tiny"', 'name = "other"'))
    elif change == "spp":
        suite = write_suite(tmp_path / "spp.toml", PINNED + "\nspp = 32")
    elif change == "json":
        (tmp_path / "broken.json").write_text("{ not json")
        args = ["--baseline", tmp_path / "broken.json"]
    elif change == "missing":
        args = ["--baseline", tmp_path / "nope.json"]
    elif change == "tolerance":
        args = ["--baseline-tolerance", "relmse=1.1"]  # without --baseline
    elif change == "suite-table":
        suite = write_suite(tmp_path / "table.toml", extra="\n[baseline]\nrelmse = 0.5\n")
    elif change == "junit":
        (tmp_path / "a-file").write_text("")
        args += ["--junit", tmp_path / "a-file" / "junit.xml"]  # its folder cannot be created
    out_dir = tmp_path / "out"
    code, out, err = cli(capsys, "run", suite, *args, "--out", out_dir, "--executor", "serial", "--no-report")
    assert code == 2, out + err
    assert len(err.strip().splitlines()) == 1 and where in err and "Traceback" not in err
    assert not (out_dir / "results.json").exists()


@pytest.mark.slow
def test_a_baseline_of_another_machine_is_flagged(tmp_path, capsys, saved):
    """The baseline keeps the system block of the run it was made from; a baseline made elsewhere is a one-line
    warning before the run, a note after it and ``baseline.other_machine`` in results.json (the report shows it)."""
    suite, base = saved
    doc = json.loads(base.read_text())
    run0 = json.loads((tmp_path / "run0" / "results.json").read_text())
    assert doc["system"] == run0["system"] and doc["system"]["node"] and doc["system"]["logical_cores"] >= 1
    code, out, err = cli(capsys, "run", suite, "--baseline", base, "--out", tmp_path / "same", "--executor", "serial",
                         "--no-report", "--quiet")
    assert code == 0 and "another machine" not in out + err
    assert json.loads((tmp_path / "same" / "results.json").read_text())["baseline"]["other_machine"] == []
    doc["system"].update(node="build-box-7", cpu="Some Other CPU")
    other = tmp_path / "other.json"
    other.write_text(json.dumps(doc))
    code, out, err = cli(capsys, "run", suite, "--baseline", other, "--out", tmp_path / "other", "--executor",
                         "serial", "--no-report", "--quiet")
    assert code == 0, out + err
    warning = [line for line in err.splitlines() if "another machine" in line]
    assert len(warning) == 1 and warning[0].startswith("harness: warning: baseline ") and "build-box-7 ->" in warning[0]
    assert "cpu Some Other CPU ->" in warning[0]
    results = json.loads((tmp_path / "other" / "results.json").read_text())
    assert results["baseline"]["other_machine"][0].startswith("node build-box-7 -> ")
    # a baseline saved by an older harness has no system block: its tools' node is compared
    del doc["system"]
    doc["tools"]["node"] = "old-box"
    other.write_text(json.dumps(doc))
    assert baseline.Gate(other, baseline_suite(suite)).other_machine[0].startswith("node old-box -> ")


def baseline_suite(path):
    from harness.running.cases import load_suite

    return load_suite(path)
