"""harness calibrate's false-alarm sweep (--films, --spp, --replicates): calibration.json's ``sweep``, calibration.md,
the printed table and the report's, the options' one-line errors and the cost check, on the furnace (a closed form:
no Mitsuba render) at 32 x 32 and two seeds."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import re
import shlex

import pytest
from conftest import ROOT
from test_calibrate import SUITE, report_with, suite  # noqa: F401 - suite: the fixture writing SUITE
from test_hostile_input import assert_one_line, cli

from harness.cli import build_parser, main
from harness.cli.calibrate import _sweep_options
from harness.files.imageio import read_exr
from harness.files.calibration import read_calibration
from harness.report.power import power_json, power_view
from harness.running import calibrate
from harness.running.cases import load_suite

SWEEP = ("--films", "scene,half", "--spp", "4,8", "--replicates", "1,2")


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    """One sweep (2 films x 2 spp x 2 replicates, 2 seeds) for the tests that read it: (folder, stdout, stderr)."""
    folder = tmp_path_factory.mktemp("swept")
    suite = folder / "s.toml"
    suite.write_text(SUITE)
    out = folder / "cal"
    printed, progress = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(progress):
        code = main(["calibrate", str(suite), "--seeds", "2", *SWEEP, "--out", str(out)])
    assert code == 0, progress.getvalue()
    return out, printed.getvalue(), progress.getvalue()


@pytest.mark.slow
def test_the_sweep_counts_false_alarms_at_every_configuration(swept):
    out, stdout, stderr = swept
    doc = json.loads((out / "calibration.json").read_text())
    assert "power" not in doc and doc["seeds"] == 2
    sweep = doc["sweep"]
    assert sweep["films"] == ["scene", "half"] and sweep["spp"] == [4, 8] and sweep["replicates"] == [1, 2]
    assert sweep["skipped"] == ["furnace/mutant (expect = fail)"]  # expect-fail cases are not swept
    (case,) = sweep["cases"]
    configs = case["configs"]
    assert [(c["film"], c["spp"], c["replicates"]) for c in configs] == [
        ([w, w], spp, r) for w in (32, 16) for spp in (4, 8) for r in (1, 2)]
    for c in configs:
        assert c["runs"] == 2 and c["errors"] == 0 and c["alpha"] == 0.001
        assert c["ground_truth_source"] == "closed-form" and c["ground_truth_spp"] is None
        assert [d["seed"] for d in c["runs_detail"]] == [0, 1]
        for run in c["runs_detail"]:
            assert run["status"] in ("pass", "fail") and len(run["reason"]) <= 200
            assert all(0 <= run[k] <= 1 for k in ("global_bias_p", "omnibus_p", "max_z_p"))
        assert c["false_alarms"] == sum(d["status"] == "fail" for d in c["runs_detail"])
        assert c["p_value_of_count"] == 1.0 or c["false_alarms"] > 0
    total = sweep["total"]
    assert total["runs"] == 16 and total["expected"] == pytest.approx(0.016)
    assert total["false_alarms"] == sum(c["false_alarms"] for c in configs) == doc["cases"][0]["false_alarms"]
    # the render of the last configuration (the case's folder is each run's): 16 x 16, two replicates (1 dof)
    (render_file,) = out.glob("cases/*/render.exr")
    render = read_exr(render_file)
    assert render.image.shape == (16, 16, 3) and render.metadata["spp"] == "8"
    assert render.metadata.get("variance_dof") == "1"
    # calibration.md and the printed summary: one table, then the totals
    md = (out / "calibration.md").read_text()
    last = configs[-1]
    assert "## False-alarm sweep" in md
    assert "| case | film | spp | replicates | GT spp | false alarms | p of count |" in md
    assert f"| furnace/reference | 16x16 | 8 | 2 | closed form | {last['false_alarms']}/2 |" in md
    totals = (f"16 correct renders, {total['false_alarms']} false alarms, 0.016 expected at alpha; "
              f"P(>= {total['false_alarms']}) = ")
    assert totals in md and totals in stdout
    assert re.search(r"^case +film +spp +replicates +GT spp +false alarms +p of count$", stdout, re.M)
    assert len(re.findall(r"^furnace/reference +\d+x\d+ ", stdout, re.M)) == 8
    assert "skipped: furnace/mutant (expect = fail)" in stdout
    # one progress line per render
    assert "  furnace/reference 32x32 4 spp R=1 seed 0\n" in stderr
    assert "  furnace/reference 16x16 8 spp R=2 seed 1\n" in stderr
    assert stderr.count(" seed ") == 16


@pytest.mark.slow
def test_the_report_reads_a_sweep_and_shows_its_table(swept, tmp_path, capfd):
    out, _, _ = swept
    doc = read_calibration(out / "calibration.json")
    view = power_view(out / "calibration.json")
    assert view["rows"] == [] and "false-alarm sweep" in view["note"]
    assert len(view["sweep"]["rows"]) == 8 and view["sweep"]["total"].startswith("16 correct renders")
    assert power_json(view)["sweep"]["headers"][0] == "case"
    definitions, report, run = report_with(out / "calibration.json", tmp_path, capfd)
    assert "False-alarm sweep" in definitions and "<td>furnace/reference</td><td>16x16</td><td>8</td>" in definitions
    assert report["power"]["sweep"]["total"] == view["sweep"]["total"]
    # a sweep of the wrong shape is one line naming its JSON path
    bad = tmp_path / "bad.json"
    broken = dict(doc, sweep=dict(doc["sweep"], total={"runs": -1}))
    bad.write_text(json.dumps(broken))
    assert_one_line(*cli(capfd, "report", run / "results.json", "--calibration", bad, "--out", tmp_path / "r"),
                    "sweep.total")


@pytest.mark.parametrize("argv, fragments", [
    (("--films", "scene,quarter"), ("--films", "scene, half, double or WxH", "'quarter'")),
    (("--films", "4x4"), ("--films", "from 8")),
    (("--spp", "1,4"), ("--spp", ">= 2")),
    (("--replicates", "0"), ("--replicates", "positive integers")),
    (("--spp", "8,4"), ("--spp", "strictly increasing")),
    (("--budgets", "1,2", "--spp", "8"), ("--budgets", "--spp", "sweep")),
    (("--region-size", "8", "--films", "half"), ("--region-size", "--films")),
    (("--ground-truth-spp", "64"), ("--ground-truth-spp", "--films, --spp or --replicates")),
    (("--ground-truth-spp", "1", "--spp", "8"), ("--ground-truth-spp", ">= 2")),
])
def test_bad_sweep_options_are_one_line(tmp_path, suite, capfd, argv, fragments):
    assert_one_line(*cli(capfd, "calibrate", suite, *argv, "--out", tmp_path / "cal"), *fragments)
    assert not (tmp_path / "cal").exists()


def test_replicates_are_the_reference_renderers_only(tmp_path, capfd):
    path = tmp_path / "m.toml"
    path.write_text('[[cases]]\nname = "furnace/other"\nscene = "furnace"\nrenderer = "mitsuba"\nspp = 8\n')
    assert_one_line(*cli(capfd, "calibrate", path, "--replicates", "1", "--out", tmp_path / "cal"), "--replicates",
                    "reference renderer", "'furnace/other'")
    assert not (tmp_path / "cal").exists()
    case = load_suite(path).cases[0]
    own = dataclasses.replace(case, settings={"replicates": "2"})  # the case's own value is no change
    assert len(calibrate.sweep_configs(own, calibrate.SweepOptions(replicates=(2,)))) == 1
    assert calibrate.sweep_configs(case, calibrate.SweepOptions(spp=(4,)))[0].settings == case.settings


def test_a_sweep_over_the_time_limit_is_refused(tmp_path, suite, capfd):
    assert_one_line(*cli(capfd, "calibrate", suite, "--films", "8192x8192", "--spp", "100000", "--out",
                         tmp_path / "cal"), "--seeds", "limit", "--films or --spp")
    assert not (tmp_path / "cal").exists()


def test_sweep_configurations_are_the_product_of_the_options(suite):
    case = load_suite(suite).cases[0]  # 32 x 32 at 8 spp; the suite gives the reference two replicates
    assert case.settings["replicates"] == "2"
    options = calibrate.SweepOptions(films=("scene", "half", "double", (40, 24)), spp=(16, 64), replicates=(1, 2, 4),
                                     ground_truth_spp=4096)
    configs = calibrate.sweep_configs(case, options)
    assert len(configs) == 4 * 2 * 3
    assert [(c.film["width"], c.film["height"]) for c in configs[::6]] == [(32, 32), (16, 16), (64, 64), (40, 24)]
    assert [c.settings["replicates"] for c in configs[:3]] == ["1", "2", "4"]  # 1 set explicitly too
    assert {c.ground_truth_spp for c in configs} == {4096} and {c.spp for c in configs} == {16, 64}
    assert calibrate.config_label(configs[1]) == "furnace/reference 32x32 16 spp R=2"
    # an option left out keeps the case's own; a configuration that comes twice is swept once
    tiny = dataclasses.replace(case, film={"width": 8, "height": 8}, spp=None, seconds=2.0)
    kept = calibrate.sweep_configs(tiny, calibrate.SweepOptions(films=("scene", "half")))
    assert len(kept) == 1 and kept[0].seconds == 2.0 and kept[0].settings == case.settings
    assert calibrate.sweep_configs(tiny, calibrate.SweepOptions(spp=(4,)))[0].seconds is None


@pytest.mark.parametrize(("index", "names", "configs"), [
    (0, ["point-spot/reference"], 27),
    (1, ["point-spot/reference", "veach-mis/reference"], 36),
])
def test_the_sweep_commands_of_the_docs_parse_and_plan(index, names, configs):
    """docs/verdict.md's sweep commands, as printed: their options parse, and each plans its configurations of
    each case within the cost limit (nothing rendered)."""
    text = (ROOT / "docs" / "verdict.md").read_text(encoding="utf-8")
    found = re.findall(r"^(harness calibrate [^\n]*\\\n[^\n]*--films[^\n]*)$", text, re.M)
    command = found[index].replace("\\\n", " ")
    argv = shlex.split(command)[1:]
    args = build_parser().parse_args(argv)
    options = _sweep_options(args)
    suite = load_suite(ROOT / args.suite)
    cases = calibrate.select_cases(suite, args.cases)
    assert [c.name for c in cases] == names
    assert all(len(calibrate.sweep_configs(case, options)) == configs for case in cases)
    calibrate.check_cost(cases, args.seeds, sweep_options=options)
