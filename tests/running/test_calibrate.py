"""harness calibrate: false alarms, the power table (calibration.json, calibration.md, the printed table) and its
options, on the furnace (a closed form: no Mitsuba render) at 32 x 32 and a few seeds."""

from __future__ import annotations

import json

import pytest
from test_hostile_input import assert_one_line, cli

from harness.running import calibrate
from harness.running.cases import load_suite

pytestmark = pytest.mark.slow  # renders: outside the inner loop (pytest -m "not slow")

SUITE = """
[[cases]]
name = "furnace/reference"
scene = "furnace"
film = { width = 32, height = 32 }
spp = 8

[[cases]]
name = "furnace/mutant"
scene = "furnace"
film = { width = 32, height = 32 }
spp = 8
settings = { mutant = "double-emission" }
expect = "fail"
"""


@pytest.fixture
def suite(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(SUITE)
    return path


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """One calibration (3 seeds at 0.5, 1 and 2 x the budget) for the tests that read it: (folder, its stdout)."""
    folder = tmp_path_factory.mktemp("calibrated")
    suite = folder / "s.toml"
    suite.write_text(SUITE)
    out = folder / "cal"
    with pytest.MonkeyPatch.context():
        from harness.cli import main
        import contextlib
        import io

        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            code = main(["calibrate", str(suite), "--seeds", "3", "--budgets", "0.5,2", "--region-size", "8",
                         "--out", str(out), "--quiet"])
    assert code == 0
    return out, printed.getvalue()


def test_calibrate_measures_power_at_each_budget(calibrated):
    out, stdout = calibrated
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["power"]["budgets"] == [0.5, 1.0, 2.0] and doc["power"]["region_size"] == 8
    row, fault = doc["cases"]
    assert row["false_alarms"] + row["passes"] == 3 and fault["caught"] is True
    region = row["power"]["region"]
    aligned, off = region["aligned"], region["off_grid"]
    assert region["size"] == 8 and aligned["y"] % 8 == 0 and aligned["x"] % 8 == 0
    assert (off["y"], off["x"]) == (aligned["y"] + 4, aligned["x"] + 4)
    budgets = row["power"]["budgets"]
    assert [b["spp"] for b in budgets] == [4, 8, 16] and all(b["runs"] == 3 for b in budgets)
    for b in budgets:
        for plant in calibrate.PLANTS:
            summary = b[plant]
            assert summary["value"] is not None and 0 < summary["value"] < 1, (plant, summary)
            assert len(b["seeds"]) == 3 and all(s[plant]["size"] for s in b["seeds"])
    # four times the samples halve the noise: the bias caught at 4x the spp is smaller (each seed's threshold is
    # ~ z sigma / sqrt(N); at 3 seeds the quantile is their largest)
    assert budgets[2]["bias"]["value"] < budgets[0]["bias"]["value"]
    # the runs' details name each seed's thresholds at the suite's budget
    assert set(row["runs_detail"][0]) >= {"bias", "region_aligned", "region_off_grid"}
    md = (out / "calibration.md").read_text()
    assert "## Power" in md and "| furnace/reference | 0.5x | 4 |" in md
    assert "power: the smallest error the verdict catches in 90% of 3 seeds" in stdout
    assert stdout.count("furnace/reference  ") == 3  # the table's rows


def report_with(calibration, tmp_path, capfd) -> tuple[str, dict, object]:
    """A run of the furnace case (no fault) whose report reads ``calibration``: its page's definitions section, its
    report.json and its folder."""
    suite = tmp_path / "run.toml"
    suite.write_text(SUITE.split("[[cases]]\nname = \"furnace/mutant\"")[0])
    run = tmp_path / "run"
    code, _, stderr = cli(capfd, "run", suite, "--out", run, "--executor", "serial", "--no-studies", "--calibration",
                          calibration)
    assert code == 0, stderr
    page = (run / "index.html").read_text()
    return page[page.index('<section id="definitions">'):], json.loads((run / "report.json").read_text()), run


def test_the_report_shows_the_power_table_in_its_definitions(tmp_path, calibrated, capfd):
    out, _ = calibrated
    definitions, report, run = report_with(out / "calibration.json", tmp_path, capfd)
    assert "Validation power" in definitions and "<td>furnace/reference</td><td>0.5x</td><td>4</td>" in definitions
    power = report["power"]
    assert len(power["rows"]) == 3 and power["suite"] == "s"
    # without a calibration the section says how to measure it
    code, _, _ = cli(capfd, "report", run / "results.json", "--out", tmp_path / "plain")
    assert code == 0 and "not measured for this page: `harness calibrate SUITE" in (tmp_path / "plain" /
                                                                                    "index.html").read_text()


def test_a_bad_calibration_file_is_one_line_before_the_run(tmp_path, suite, capfd):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"suite": "s", "seeds": 3, "cases": [{"case": "x", "expect": "pass",
                                                                     "power": {"budgets": [{"factor": -1}]}}]}))
    assert_one_line(*cli(capfd, "run", suite, "--out", tmp_path / "run", "--calibration", bad),
                    f"--calibration: {bad}: cases[0].power.budgets[0].runs: missing; expected an integer >= 0")
    assert not (tmp_path / "run").exists()
    assert_one_line(*cli(capfd, "report", tmp_path / "missing.json", "--calibration", tmp_path / "none.json"),
                    "no such")


def test_no_power_counts_false_alarms_only(tmp_path, suite, capfd):
    out = tmp_path / "cal"
    code, stdout, _ = cli(capfd, "calibrate", suite, "--seeds", 2, "--cases", "furnace/reference", "--no-power",
                          "--out", out, "--quiet")
    assert code == 0
    doc = json.loads((out / "calibration.json").read_text())
    assert "power" not in doc and "power" not in doc["cases"][0] and "power:" not in stdout


@pytest.mark.parametrize("budgets, fragment", [
    ("0", "expected comma-separated positive numbers"), ("2,1", "strictly increasing"), ("100", "at most 64"),
    ("nan", "finite"), ("", "expected comma-separated positive numbers"),
])
def test_bad_budgets_are_one_line(tmp_path, suite, capfd, budgets, fragment):
    assert_one_line(*cli(capfd, "calibrate", suite, "--budgets", budgets, "--out", tmp_path / "cal"), "--budgets",
                    fragment)
    assert not (tmp_path / "cal").exists()


def test_budget_factors_scale_spp_or_seconds():
    suite_case = load_suite(calibrate.Path(__file__).parents[2] / "suites" / "smoke.toml").cases[0]
    assert calibrate.with_budget(suite_case, 0.5).spp == round(suite_case.spp / 2)
    assert calibrate.with_budget(suite_case, 0.01).spp == 2  # the verdict's least
    timed = calibrate.dataclasses.replace(suite_case, spp=None, seconds=2.0)
    assert calibrate.with_budget(timed, 4).seconds == 8.0
