"""The report as an instrument: the System block (provenance) and machines flagged, the summary table's filters and
sorting (summary.js; the table is plain HTML without it), and each case's command that reproduces it, run here."""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

from harness.cli import main
from harness.core import system
from harness.files.results import read_results
from harness.report import write_suite_report
from harness.running import result_cache
from harness.running.cases import load_suite
from harness.running.schedule import run_suite

pytestmark = pytest.mark.slow  # renders: outside the inner loop (pytest -m "not slow")

SUITE = """
name = "nav"
[defaults]
spp = 4
film = { width = 8, height = 8 }

[[cases]]
name = "furnace/closed-form"
scene = "SCENES/furnace.toml"
settings = { direct = "mis", rr_depth = "3" }
film = { width = 12, height = 10 }
max_depth = 4
seed = 8

[[cases]]
name = "furnace/mutant"
scene = "SCENES/furnace.toml"
settings = { mutant = "double-emission" }
expect = "fail"

[[cases]]
name = "furnace/unexpected"
scene = "SCENES/furnace.toml"
settings = { mutant = "double-emission" }
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("nav")
    suite = folder / "nav.toml"
    suite.write_text(SUITE.replace("SCENES", str(ROOT / "scenes")))
    out = folder / "out"
    run_suite(load_suite(suite), out)
    write_suite_report(out / "results.json", out)
    return out


def test_the_system_block_is_in_results_report_and_page(run_dir):
    results = read_results(run_dir / "results.json")  # the schema check takes it
    block = results["system"]
    assert block["logical_cores"] >= 1 and block["python"] == sys.version.split()[0] and block["os"]
    assert block["numpy"] and block["embreex"] and block["embree"].count(".") == 2  # the library's own version
    assert set(block["mitsuba"]) == {"version", "variant", "variants_used"} and block["mitsuba"]["variants_used"] == []
    assert block["git"] is None or len(block["git"]["commit"]) == 40
    assert 0 <= block["seconds"] < 0.5
    report = json.loads((run_dir / "report.json").read_text())
    assert report["system"] == block and report["machine_notes"] == []
    page = (run_dir / "index.html").read_text()
    assert '<section id="system"><h2>System</h2>' in page and page.index('id="system"') < page.index('id="cases"')
    assert block["cpu"] in page


def test_gathering_is_cheap_and_imports_no_mitsuba():
    code = ("import sys, time; from harness.core import system; t = time.perf_counter(); b = system.gather(); "
            "print(time.perf_counter() - t, 'mitsuba' in sys.modules, 'drjit' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=ROOT).stdout.split()
    assert float(out[0]) < 0.5 and out[1:] == ["False", "False"]
    a = system.gather()
    assert system.machine_differences(a, dict(a)) == []
    assert system.machine_differences(a, dict(a, node="elsewhere")) == [f"node {a['node']} -> elsewhere"]
    assert system.machine_differences(None, a) == []


def test_summary_table_has_stable_hooks_and_works_without_script(run_dir):
    page = (run_dir / "index.html").read_text()
    for name in ("all", "failures", "errors", "unexpected"):
        assert f'data-filter="{name}"' in page
    assert re.search(r"<div class=\"filters\" data-filters hidden>", page)  # shown by the script only
    statuses = re.findall(r'<tr data-status="(\w+)" data-ok="(\w+)">', page)
    assert statuses == [("pass", "true"), ("fail", "true"), ("fail", "false")]
    assert page.count('<th data-sort-type="number">') == 4
    # without the script the table is the same plain table: every row and cell is there
    plain = re.sub(r"<script>.*?</script>", "", page, flags=re.S)
    assert plain.count("<tr data-status=") == 3 and "furnace/unexpected" in plain


def _command(words: list[str]) -> list[str]:
    assert words[0] == "harness"
    return words[1:]


def test_the_printed_commands_reproduce_the_case(run_dir, tmp_path, monkeypatch, capfd):
    report = json.loads((run_dir / "report.json").read_text())
    records = {r["name"]: r for r in read_results(run_dir / "results.json")["cases"]}
    page = (run_dir / "index.html").read_text()
    monkeypatch.chdir(tmp_path)
    for case in report["cases"]:
        record = records[case["name"]]
        text = case["reproduce"]["text"]
        render_line, compare_line = text.splitlines()
        assert render_line.startswith("harness render ") and compare_line.startswith("harness compare render.exr ")
        assert shlex.split(render_line) == case["reproduce"]["render"]
        assert f"--tile {record['verdict']['tile']} --alpha {record['verdict']['alpha']!r}" in compare_line
        assert main(_command(shlex.split(render_line)) + ["--quiet"]) == 0
        capfd.readouterr()
        code = main(_command(shlex.split(compare_line)) + ["--json"])
        verdict = json.loads(capfd.readouterr().out)["verdict"]
        assert code == (0 if record["verdict"]["verdict"] == "pass" else 1)
        assert verdict == record["verdict"], case["name"]  # the same statistics, bit for bit
        assert (tmp_path / "render.exr").read_bytes()  # where the command says
        # the page shows the lines (escaped) in the case's section
        assert shlex.quote(record["ground_truth"]["path"]) in page
    first = report["cases"][0]["reproduce"]["render"]
    assert first[first.index("--film") + 1] == "12x10" and first[first.index("--max-depth") + 1] == "4"
    assert first[first.index("--seed") + 1] == "8" and "direct=mis" in first and "rr_depth=3" in first
    assert page.count('<div class="reproduce"><h4>Reproduce</h4>') == 3


def test_cases_from_the_cache_of_another_machine_are_flagged(tmp_path, monkeypatch):
    monkeypatch.delenv(result_cache.ENV, raising=False)
    suite_path = tmp_path / "nav.toml"
    suite_path.write_text(SUITE.replace("SCENES", str(ROOT / "scenes")))
    suite, cache = load_suite(suite_path), tmp_path / "cache"
    real = system.gather

    def elsewhere(variant=None):
        return dict(real(variant), node="other-box", cpu="Other CPU")

    monkeypatch.setattr(system, "gather", elsewhere)
    run_suite(suite, tmp_path / "first", cache_dir=cache, results_cache="use")
    monkeypatch.setattr(system, "gather", real)
    results = run_suite(suite, tmp_path / "second", cache_dir=cache, results_cache="use")
    assert results["summary"]["from_cache"] == 3
    assert all(r["cached"]["machine"]["node"] == "other-box" for r in results["cases"])
    read_results(tmp_path / "second" / "results.json")
    write_suite_report(tmp_path / "second" / "results.json", tmp_path / "second")
    report = json.loads((tmp_path / "second" / "report.json").read_text())
    assert report["machine_notes"] == ["3 cases came from the results cache of another machine (other-box): their "
                                       "timings are that machine's: furnace/closed-form, furnace/mutant, "
                                       "furnace/unexpected."]
    assert "results cache of another machine (other-box)" in (tmp_path / "second" / "index.html").read_text()
    assert "**Another machine:** 3 cases came from the results cache" in (tmp_path / "second" / "summary.md").read_text()
    # the same machine: no note
    results = run_suite(suite, tmp_path / "third", cache_dir=tmp_path / "cache2", results_cache="use")
    results = run_suite(suite, tmp_path / "fourth", cache_dir=tmp_path / "cache2", results_cache="use")
    write_suite_report(tmp_path / "fourth" / "results.json", tmp_path / "fourth")
    assert json.loads((tmp_path / "fourth" / "report.json").read_text())["machine_notes"] == []


BROWSER_CHECK = """
<script>
window.addEventListener("load", function () {
  function visible() {
    return Array.prototype.filter.call(document.querySelectorAll("tr[data-status]"), function (r) {
      return !r.hidden; }).map(function (r) { return r.cells[0].textContent; }).join(",");
  }
  var out = [];
  document.querySelector('[data-filter="failures"]').click(); out.push("failures=" + visible());
  document.querySelector('[data-filter="unexpected"]').click(); out.push("unexpected=" + visible());
  document.querySelector('[data-filter="errors"]').click(); out.push("errors=" + visible());
  document.querySelector('[data-filter="all"]').click(); out.push("all=" + visible());
  var time = document.querySelectorAll("table.summary thead th")[9];
  time.click(); var up = visible(); time.click(); var down = visible();
  out.push("sorted=" + (up.split(",").reverse().join(",") === down));
  out.push("bar=" + !document.querySelector("[data-filters]").hidden);
  var div = document.createElement("div"); div.id = "nav-check"; div.textContent = out.join(";");
  document.body.appendChild(div);
});
</script>
"""


@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium not installed (apt-get install -y chromium)")
def test_filters_and_sorting_in_a_headless_browser(run_dir, tmp_path):
    checked = tmp_path / "checked.html"
    checked.write_text((run_dir / "index.html").read_text().replace("</body>", BROWSER_CHECK + "</body>"))
    proc = subprocess.run(["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                           "--disable-background-networking", f"--user-data-dir={tmp_path / 'profile'}",
                           "--virtual-time-budget=5000", "--dump-dom", checked.as_uri()],
                          capture_output=True, text=True, timeout=180)
    match = re.search(r'id="nav-check">([^<]*)<', proc.stdout)
    assert match, proc.stderr[-2000:]
    found = dict(item.split("=", 1) for item in match.group(1).split(";"))
    assert found == {"failures": "furnace/mutant,furnace/unexpected", "unexpected": "furnace/unexpected",
                     "errors": "", "all": "furnace/closed-form,furnace/mutant,furnace/unexpected",
                     "sorted": "true", "bar": "true"}
