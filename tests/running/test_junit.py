"""JUnit XML: parses, has the structure GitLab and Jenkins read, maps each outcome as docs/ci.md says."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from conftest import ROOT

from harness.running import junit
from harness.cli import main


def _record(name, status, expect, ok, reason="", **extra):
    verdict = {"verdict": status, "global_bias": {"z": [0.1, -2.0, 0.5], "p_value": 0.2},
               "omnibus": {"p_value": 0.4}, "max_z": {"statistic": 2.5, "p_value": 0.3},
               "worst_tile": {"y": 8, "x": 0, "channel": "G", "z": 2.5}}
    record = {"name": name, "scene": "scenes/furnace.toml", "status": status, "expect": expect, "ok": ok,
              "reason": reason, "wall_seconds": 1.25, "metrics": {"relmse": 0.01, "rmse": 0.1}}
    if status != "error":
        record["verdict"] = verdict
    record.update(extra)
    return record


RESULTS = {
    "suite": "demo", "suite_file": "suites/demo.toml", "started": "2026-11-26T05:00:00+0000", "host": {"node": "ci"},
    "cases": [
        _record("a/pass", "pass", "pass", True),
        _record("b/verdict-fail", "fail", "pass", False, "global bias: z = 9.1 in G <&> \x1b[31m"),
        _record("c/baseline", "pass", "pass", False, "baseline: relmse 0.0123 > 1.1 x 0.01",
                baseline={"compared": True, "regressions": ["baseline: relmse 0.0123 > 1.1 x 0.01"],
                          "checks": [{"metric": "relmse", "baseline": 0.01, "value": 0.0123, "ok": False}]}),
        _record("d/mutant-caught", "fail", "fail", True, "omnibus: chi2 = 400"),
        _record("e/mutant-missed", "pass", "fail", False),
        _record("f/error", "error", "pass", False, "RuntimeError: boom", traceback="Traceback ...\x00\nRuntimeError"),
    ],
}


def test_junit_structure_and_mapping(tmp_path):
    path = junit.write(RESULTS, tmp_path / "junit.xml")
    root = ET.parse(path).getroot()  # well-formed despite the control characters in the input
    assert root.tag == "testsuites"
    (suite,) = root.findall("testsuite")
    cases = suite.findall("testcase")
    assert suite.get("name") == "demo" and suite.get("tests") == "6" == str(len(cases))
    assert suite.get("failures") == "3" and suite.get("errors") == "1" and suite.get("skipped") == "0"
    assert float(suite.get("time")) == 7.5 and suite.get("timestamp") == "2026-11-26T05:00:00"
    for case in cases:
        assert case.get("name") and case.get("classname") == "demo.furnace" and float(case.get("time")) == 1.25
    by_name = {c.get("name"): c for c in cases}
    kinds = {n: [(e.tag, e.get("type")) for e in c if e.tag in ("failure", "error", "skipped")]
             for n, c in by_name.items()}
    assert kinds == {
        "a/pass": [], "d/mutant-caught": [],
        "b/verdict-fail": [("failure", "verdict")], "c/baseline": [("failure", "baseline")],
        "e/mutant-missed": [("failure", "planted-fault-not-caught")], "f/error": [("error", "RuntimeError")],
    }
    assert by_name["c/baseline"].find("failure").get("message") == "baseline: relmse 0.0123 > 1.1 x 0.01"
    assert "failed as expected" in by_name["d/mutant-caught"].find("system-out").text
    props = {p.get("name"): p.get("value") for p in by_name["a/pass"].find("properties")}
    assert props["global_bias.z.G"] == "-2" and props["verdict"] == "pass" and props["max_z.p"] == "0.3"
    assert {p.get("name"): p.get("value") for p in by_name["c/baseline"].find("properties")}[
        "baseline.relmse.ratio"] == "1.23"


def test_run_writes_junit(tmp_path, capsys):
    suite = tmp_path / "s.toml"
    suite.write_text(f'name = "j"\n[[cases]]\nname = "furnace/reference"\nscene = "{ROOT / "scenes" / "furnace.toml"}"\n'
                     'spp = 4\nfilm = {{ width = 8, height = 8 }}\n'.replace("{{", "{").replace("}}", "}"))
    code = main(["run", str(suite), "--out", str(tmp_path / "out"), "--junit", str(tmp_path / "j.xml"),
                 "--executor", "serial", "--no-report", "--quiet"])
    out, err = capsys.readouterr()
    assert code == 0, out + err
    root = ET.parse(tmp_path / "j.xml").getroot()
    (case,) = root.iter("testcase")
    assert case.get("name") == "furnace/reference" and not case.findall("failure") and float(case.get("time")) > 0


def test_unwritable_junit_folder_is_refused_before_the_run(tmp_path, capsys):
    """A folder that exists but takes no files (/proc; root ignores permission bits) is found out by a real write
    before any case runs: one line, exit 2, no results.json."""
    if not Path("/proc").is_dir():
        pytest.skip("no /proc on this system")
    code = main(["run", str(ROOT / "suites" / "smoke.toml"), "--out", str(tmp_path / "out"), "--junit",
                 "/proc/j.xml", "--no-report", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--junit" in err[0]
    assert not (tmp_path / "out" / "results.json").exists()
