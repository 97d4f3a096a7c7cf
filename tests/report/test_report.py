"""Reports: the files of a suite report, a self-contained and escaped page, the numbers in report.json, the
convergence fit and equal-time / equal-error reading on synthetic curves, the CLI, and the page in a headless browser.

The suites here are tiny (8x8 and 16x16 films, a few spp) and need no Mitsuba: the furnace has a closed form and the
soft-shadows case compares against a reference render.
"""

from __future__ import annotations

import dataclasses
import html
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

import harness.report
from harness.report import viewer as report_viewer
from harness.studies.convergence import (
    equal_error,
    equal_time,
    fit_convergence,
    loglog_interpolate,
    parse_ladder,
    time_to_error,
)

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

EVIL = "<script>alert('x')</script> & \"quotes\""

SUITE = f'''
name = "tiny <b>report</b>"
description = "a tiny suite for report tests <img src=x onerror=alert(1)>"

[defaults]
spp = 4
film = {{ width = 8, height = 8 }}

[[cases]]
name = "furnace/reference"
scene = "SCENES/furnace.toml"

[[cases]]
name = {json.dumps(EVIL)}
scene = "SCENES/furnace.toml"
settings = {{ direct = "mis" }}

[[cases]]
name = "soft-shadows/vs-reference"
scene = "SCENES/soft-shadows.toml"
film = {{ width = 16, height = 16 }}
against = {{ renderer = "reference", spp = 64, seed = 99 }}
'''


def fast_options(**overrides):
    from harness.studies.suite_studies import StudyOptions

    values = dict(convergence_spp=(1, 2, 4, 8), strategy_spp=4, min_timing_seconds=0.0, strategy_min_seconds=0.0)
    values.update(overrides)
    return StudyOptions(**values)


@pytest.fixture(scope="module")
def report_dir(tmp_path_factory) -> Path:
    """A tiny suite run, its studies and its report (written once for the module)."""
    from harness.report import write_suite_report
    from harness.running.cases import load_suite
    from harness.running.schedule import run_suite
    from harness.studies.suite_studies import write_suite_studies

    folder = tmp_path_factory.mktemp("report")
    suite_path = folder / "tiny.toml"
    suite_path.write_text(SUITE.replace("SCENES", str(ROOT / "scenes")))
    out = folder / "out"
    results = run_suite(load_suite(suite_path), out)
    write_suite_studies(results, out, fast_options())
    write_suite_report(out / "results.json", out)
    return out


# ---- files and page ----------------------------------------------------------------------------------------------


def test_report_files_exist(report_dir):
    for name in ("index.html", "report.json", "summary.md", "results.json"):
        assert (report_dir / name).is_file(), name
    summary = (report_dir / "summary.md").read_text()
    assert "cases as expected" in summary and "Best strategy" in summary


def test_page_is_self_contained(report_dir):
    page = (report_dir / "index.html").read_text()
    # the package's own scripts, inline: summary.js (the table's filters and sorting), then the comparison viewer's
    static = Path(harness.report.__file__).parent / "static"
    scripts = re.findall(r"<script[^>]*>(.*?)</script>", page, re.S | re.I)
    assert scripts == [(static / name).read_text() for name in ("summary.js", *report_viewer.SCRIPTS)]
    # the viewer loads each case's data from a file of the report, beside the page
    sources = re.findall(r'data-viewer-src="([^"]*)"', page)
    assert len(sources) == 3 and all(s.startswith("report/") and (report_dir / s).is_file() for s in sources)
    lowered = re.sub(r"<script>.*?</script>", "", page, flags=re.S).lower()
    for bad in ('src="http', "src='http", 'href="http', "href='http", "url(http", "@import", "<link", "<script",
                "<iframe", 'src="//', 'href="//'):
        assert bad not in lowered, bad
    sources = re.findall(r'<img[^>]*\ssrc="([^"]*)"', page)
    assert len(sources) >= 6 + 14  # each case's two thumbnails; the studies' plots and shadow-ray images
    assert all(s.startswith("data:image/png;base64,") for s in sources)
    # links only to anchors in the page and to the report's own files beside it
    for href in re.findall(r'href="([^"]*)"', page):
        assert href.startswith("#") or href.startswith("report/"), href
        if href.startswith("report/"):
            assert (report_dir / html.unescape(href)).is_file(), href


def test_page_escapes_every_string(report_dir):
    page = (report_dir / "index.html").read_text()
    assert "<script>alert" not in page and "<img src=x" not in page and "<b>report</b>" not in page
    assert html.escape(EVIL, quote=True) in page
    assert "&lt;b&gt;report&lt;/b&gt;" in page


def test_report_json_holds_the_numbers(report_dir):
    report = json.loads((report_dir / "report.json").read_text())
    results = json.loads((report_dir / "results.json").read_text())
    assert report["schema"] == 1 and report["kind"] == "suite-report"
    assert [c["name"] for c in report["cases"]] == [c["name"] for c in results["cases"]]
    for case, record in zip(report["cases"], results["cases"]):
        assert case["metrics"] == record["metrics"]
        assert case["verdict"]["verdict"] == record["verdict"]["verdict"]
        assert case["problems"] == []
        keys = {im["key"] for im in case["images"]}
        assert keys == {"ground_truth", "render", "error_signed", "error_relative", "flip"}
        # the relative-error map's mean is the case's MAPE
        assert case["error_maps"]["mean_relative_error"] == pytest.approx(record["metrics"]["mape"], rel=1e-4)
        signed = next(im for im in case["images"] if im["key"] == "error_signed")
        assert signed["legend"]["vmin"] == -signed["legend"]["vmax"] > -np.inf
    conv = report["convergence"]
    assert len(conv["scenes"]) == 2
    for scene in conv["scenes"]:
        series = scene["result"]["series"][0]
        assert [p["spp"] for p in series["points"]] == [1, 2, 4, 8]
        seeds = [s for p in series["points"] for s in p["seeds"]]
        assert len(seeds) == len(set(seeds))
        assert series["fit_rmse"]["slope"] is not None and -1.5 < series["fit_rmse"]["slope"] < 0
    shadow = report["shadow_rays"]
    assert [r["shadow_rays"] for r in shadow["rows"]] == [1, 4, 9, 16, 36, 64, 100]
    assert shadow["penumbra"]["pixels"] > 0 and shadow["penumbra"]["method"] == "per-pixel"
    assert all(r["penumbra"]["rmse"] > 0 and r["seconds"] > 0 for r in shadow["rows"])
    strategies = {s["scene"]: s for s in report["strategies"]["scenes"]}
    assert set(strategies) == {"furnace", "soft-shadows"}
    furnace = {r["label"]: r for r in strategies["furnace"]["rows"]}
    # every row rendered alike by the studies (not the cases' own spp), several seeds at each budget
    assert furnace["direct=mis"]["case"] is None and furnace["direct=mis"]["equal_spp"]["seeds"] >= 2
    assert "skipped" in furnace["rr=off"]  # unbounded max_depth
    assert furnace["default"]["relative_efficiency"] == pytest.approx(1.0)
    assert strategies["furnace"]["best"] is None or strategies["furnace"]["best"] in furnace


def test_every_image_has_exr_and_png(report_dir):
    from harness.files.imageio import read_exr

    report = json.loads((report_dir / "report.json").read_text())
    images = [im for case in report["cases"] for im in case["images"]]
    assert images
    for im in images:
        assert Path(im["png"]).is_file() and Path(im["exr"]).is_file()
        assert Path(im["png"]).with_suffix(".exr") == Path(im["exr"])
        exr = read_exr(im["exr"])
        assert exr.image.shape[2] == 3 and np.isfinite(exr.image).all()
    shadow_dir = report_dir / "report" / "shadow-rays"
    for n in (1, 4, 9, 16, 36, 64, 100):
        assert (shadow_dir / f"shadow_rays_{n}.exr").is_file() and (shadow_dir / f"shadow_rays_{n}.png").is_file()


def test_signed_error_exr_holds_the_difference(report_dir):
    from harness.files.imageio import read_exr

    folder = report_dir / "report" / "furnace_reference"
    render = read_exr(folder / "render.exr").image.astype(np.float64)
    truth = read_exr(folder / "ground_truth.exr").image.astype(np.float64)
    signed = read_exr(folder / "error_signed.exr").image[..., 0]
    np.testing.assert_allclose(signed, (render - truth).mean(axis=-1), rtol=1e-5, atol=1e-6)


# ---- convergence fit and interpolation ---------------------------------------------------------------------------

SPP = 2.0 ** np.arange(0, 13)


def test_fit_unbiased_sequence_has_slope_minus_half():
    fit = fit_convergence(SPP, 0.3 / np.sqrt(SPP))
    assert fit["slope"] == pytest.approx(-0.5, abs=1e-9)
    assert not fit["biased"] and fit["departure_spp"] is None
    assert fit["model"]["bias"] == pytest.approx(0.0, abs=1e-6)
    # relMSE-like errors: slope -1
    mse = fit_convergence(SPP, 0.09 / SPP, expected_slope=-1.0)
    assert mse["slope"] == pytest.approx(-1.0, abs=1e-9) and not mse["biased"]


def test_fit_noisy_unbiased_sequences_are_rarely_flagged():
    rng = np.random.default_rng(7)
    flagged, slopes = 0, []
    for _ in range(200):
        noisy = 0.3 / np.sqrt(SPP) * np.exp(rng.normal(0.0, 0.02, SPP.size))
        fit = fit_convergence(SPP, noisy, scatter=0.02)
        flagged += fit["biased"]
        slopes.append(fit["slope"])
    assert flagged <= 2
    assert np.mean(slopes) == pytest.approx(-0.5, abs=0.005)


def test_fit_flags_a_biased_sequence_where_it_flattens():
    c, b = 0.3, 0.01  # variance and bias terms equal at spp = (c / b)^2 = 900
    fit = fit_convergence(SPP, np.sqrt(c**2 / SPP + b**2))
    assert fit["biased"]
    assert 64 <= fit["departure_spp"] <= 900
    assert fit["slope"] > -0.45  # flatter than -1/2 over the whole ladder
    assert fit["model"]["bias"] == pytest.approx(b, rel=1e-3)
    assert fit["model"]["variance_coefficient"] == pytest.approx(c**2, rel=1e-3)
    # every point from the departure on lies above its threshold
    j = fit["spp"].index(fit["departure_spp"])
    assert all(r > t for r, t in zip(fit["residuals"][j:], fit["thresholds"][j:]))
    # a larger expected scatter moves the departure later
    later = fit_convergence(SPP, np.sqrt(c**2 / SPP + b**2), scatter=0.1)
    assert later["departure_spp"] > fit["departure_spp"]


def test_fit_ignores_unusable_points():
    errors = list(0.3 / np.sqrt(SPP))
    errors[3] = None
    errors[5] = float("nan")
    fit = fit_convergence(SPP, errors)
    assert fit["points"] == SPP.size - 2 and fit["slope"] == pytest.approx(-0.5)


def test_equal_time_and_equal_error_on_synthetic_curves():
    # error = a / sqrt(t): power laws are straight in log-log, so interpolation is exact
    times = [0.1, 0.2, 0.4, 0.8, 1.6]
    fast = [0.1 / np.sqrt(t) for t in times]
    slow = [0.3 / np.sqrt(t) for t in times]
    assert loglog_interpolate(times, fast, 0.3) == pytest.approx(0.1 / np.sqrt(0.3))
    assert loglog_interpolate(times, fast, 5.0) is None
    assert time_to_error(times, slow, 0.5) == pytest.approx((0.3 / 0.5) ** 2)
    assert time_to_error(times, slow, 10.0) is None
    et = equal_time({"fast": (times, fast), "slow": (times, slow)}, at=0.5)
    assert et["errors"]["fast"] == pytest.approx(0.1 / np.sqrt(0.5))
    assert et["ratio_to_first"]["slow"] == pytest.approx(3.0)
    assert not any(et["extrapolated"].values())
    ee = equal_error({"fast": (times, fast), "slow": (times, slow)}, target=0.3)
    assert ee["times"]["slow"] == pytest.approx(1.0)
    assert ee["times"]["fast"] == pytest.approx(1 / 9)
    assert ee["speedup_vs_first"]["slow"] == pytest.approx(1 / 9)
    assert not any(ee["extrapolated"].values())
    ee = equal_error({"fast": (times, fast), "slow": (times, slow)}, target=0.35)
    assert ee["times"]["slow"] == pytest.approx((0.3 / 0.35) ** 2)
    assert ee["times"]["fast"] == pytest.approx((0.1 / 0.35) ** 2)  # above fast's first point: along its own line
    assert ee["extrapolated"] == {"fast": True, "slow": False} and not any(ee["out_of_range"].values())
    ee = equal_error({"fast": (times, fast), "slow": (times, slow)}, target=0.5)
    assert ee["times"]["slow"] == pytest.approx(0.36)
    # fast's line reaches 0.5 at 0.04 s, 2.5x below its shortest time: out of range, not extrapolated
    assert ee["times"]["fast"] is None and ee["speedup_vs_first"]["fast"] is None
    assert ee["out_of_range"] == {"fast": True, "slow": False} and ee["extrapolated"] == {"fast": False, "slow": False}
    # defaults: the longest common time, and the smallest error every curve reaches
    shifted = [t * 2 for t in times]
    et = equal_time({"a": (times, fast), "b": (shifted, slow)})
    assert et["time"] == pytest.approx(1.6)
    ee = equal_error({"a": (times, fast), "b": (shifted, slow)})
    assert ee["error"] == pytest.approx(max(min(fast), min(slow)))
    assert ee["times"]["b"] == pytest.approx(3.2)


def test_parse_ladder():
    assert parse_ladder("8, 1,2,2,4", "--spp") == [1, 2, 4, 8]
    assert parse_ladder("0.5,1", "--seconds", float) == [0.5, 1.0]
    from harness.core.errors import HarnessError

    for bad in ("1,x", "0,1", ""):
        with pytest.raises(HarnessError):
            parse_ladder(bad, "--spp")


# ---- command line ------------------------------------------------------------------------------------------------


def run_cli(capfd, *args):
    """``harness ARGS`` in this process: (exit code, stdout, stderr) as the file descriptors saw them. What only a
    process shows (stdout holding the JSON alone) is test_convergence_json_is_alone_on_stdout's; a process here
    would spend its time importing trimesh, matplotlib and the harness again (2-3 s a run)."""
    from harness.cli import main

    code = main([str(a) for a in args])
    out, err = capfd.readouterr()
    return code, out, err


def write_suite(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "s.toml"
    path.write_text(body.replace("SCENES", str(ROOT / "scenes")))
    return path


ONE_CASE = '''
[[cases]]
name = "furnace/tiny"
scene = "SCENES/furnace.toml"
spp = 4
film = { width = 8, height = 8 }
'''


def test_run_writes_the_report_and_report_rewrites_it(tmp_path, capfd, monkeypatch):
    from harness.cli import study_compute
    from harness.studies import suite_studies

    suite = write_suite(tmp_path, ONE_CASE)
    out = tmp_path / "out"
    # a small ladder and no strategy rows: the studies' content is tested elsewhere, here that run writes them; the
    # case in this process (serial), not in a worker that would load the kernels again (1-2 s). Nothing here reads
    # the plots (drawn after the renders, 1.4 CPU-s; the report_dir fixture's are checked) or the times of the
    # convergence renders (repeated to 0.05 s each for their timing: 2.9 CPU-s; the convergence tests time them)
    monkeypatch.setattr(suite_studies._Plots, "draw", lambda self: None)
    options = study_compute.study_options
    monkeypatch.setattr(study_compute, "study_options",
                        lambda args: dataclasses.replace(options(args), min_timing_seconds=0.0))
    code, stdout, stderr = run_cli(capfd, "run", str(suite), "--out", str(out), "--quiet", "--convergence-spp", "1,2,4",
                                   "--no-strategies", "--executor", "serial")
    assert code == 0, stdout + stderr
    assert "report:" in stdout and (out / "index.html").is_file() and (out / "report.json").is_file()
    assert "studies:" in stdout and (out / "studies" / "studies.json").is_file()
    assert json.loads((out / "report.json").read_text())["convergence"]["spp_ladder"] == [1, 2, 4]
    again = tmp_path / "again"
    code, stdout, stderr = run_cli(capfd, "report", str(out / "results.json"), "--out", str(again), "--quiet", "--studies",
                                   "--convergence-spp", "1,2", "--no-strategies", "--no-shadow-rays")
    assert code == 0, stdout + stderr
    report = json.loads((again / "report.json").read_text())
    assert report["strategies"] is None and report["convergence"]["spp_ladder"] == [1, 2]
    assert (again / "studies" / "studies.json").is_file()  # --studies writes them beside the new report


def test_report_of_a_missing_file_is_one_line(tmp_path, capsys):
    from harness.cli import main

    assert main(["report", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "missing.json" in err


@pytest.mark.parametrize("broken", ["report", "studies"])
def test_a_failing_report_does_not_change_the_run_exit_code(broken, tmp_path, monkeypatch, capsys):
    import harness.cli.run
    import harness.cli.study_compute
    from harness.cli import main

    def fail(*args, **kwargs):
        raise RuntimeError("disk on fire\nsecond line")

    if broken == "report":
        monkeypatch.setattr(harness.cli.run, "write_suite_report", fail)
    else:
        monkeypatch.setattr(harness.cli.study_compute, "write_suite_studies", fail)
    suite = write_suite(tmp_path, ONE_CASE)
    code = main(["run", str(suite), "--out", str(tmp_path / "out"), "--quiet", "--executor", "serial"]
                + (["--no-studies"] if broken == "report" else []))
    err = capsys.readouterr().err
    assert code == 0
    assert err.strip().splitlines() == [f"harness: {broken} not written: RuntimeError: disk on fire second line"]
    if broken == "studies":  # the report is written all the same, and says how to get the studies
        assert "Not computed" in (tmp_path / "out" / "index.html").read_text()
        assert not (tmp_path / "out" / "studies").exists()


def test_convergence_command(tmp_path, capfd):
    out = tmp_path / "conv"
    code, stdout, stderr = run_cli(
        capfd, "convergence", str(ROOT / "scenes" / "furnace.toml"), "--film", "8x8", "--spp", "1,2,4,8",
        "--renderer", "reference", "--renderer", "reference", "--set", "hemisphere=uniform", "--out", str(out),
        "--quiet")
    assert code == 0, stdout + stderr
    result = json.loads((out / "convergence.json").read_text())
    assert [s["label"] for s in result["series"]] == ["reference", "reference hemisphere=uniform"]
    assert result["series"][1]["resolved_settings"]["hemisphere"] == "uniform"
    assert set(result["comparisons"]) == {"rmse_corrected", "relmse_corrected"}
    page = (out / "index.html").read_text()
    assert "data:image/png;base64," in page and "<script" not in page
    code, _, stderr = run_cli(capfd, "convergence", str(ROOT / "scenes" / "furnace.toml"), "--spp", "1,two")
    assert code == 2 and "--spp" in stderr and len(stderr.strip().splitlines()) == 1


# ---- a real browser ----------------------------------------------------------------------------------------------

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run", "--hide-scrollbars"]

CHECK_SCRIPT = """
<script>
window.__errors = [];
window.addEventListener("error", function (e) { window.__errors.push(String(e.message || e)); }, true);
window.addEventListener("load", function () {
  var imgs = Array.prototype.slice.call(document.images);
  var ok = imgs.filter(function (im) { return im.complete && im.naturalWidth > 0; }).length;
  var div = document.createElement("div");
  div.id = "img-check";
  div.textContent = "images " + ok + "/" + imgs.length + " errors " + window.__errors.length;
  document.body.appendChild(div);
});
</script>
"""


def _chromium(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    exe = shutil.which("chromium")
    profile = tmp_path / "chromium-profile"
    return subprocess.run([exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args], capture_output=True,
                          text=True, timeout=180)


@pytest.mark.skipif(shutil.which("chromium") is None,
                    reason="chromium not installed (apt-get install -y chromium)")
def test_page_in_a_headless_browser(report_dir, tmp_path):
    import imageio.v3 as iio

    page = report_dir / "index.html"
    # 1. the page as it is: no console errors, no failed loads
    proc = _chromium(tmp_path, "--enable-logging=stderr", "--v=0", "--virtual-time-budget=5000", "--dump-dom",
                     page.as_uri())
    assert proc.returncode == 0, proc.stderr[-2000:]
    console = [line for line in proc.stderr.splitlines()
               if "CONSOLE" in line or "Uncaught" in line or "Failed to load resource" in line
               or "Not allowed to load local resource" in line]
    assert not console, console
    assert "Suite report" in proc.stdout
    # 2. a copy with a check script: every image decoded
    checked = tmp_path / "checked.html"
    checked.write_text(page.read_text().replace("</body>", CHECK_SCRIPT + "</body>"))
    proc = _chromium(tmp_path, "--virtual-time-budget=5000", "--dump-dom", checked.as_uri())
    match = re.search(r'id="img-check">images (\d+)/(\d+) errors (\d+)<', proc.stdout)
    assert match, proc.stdout[-2000:]
    ok, total, errors = map(int, match.groups())
    assert total >= 15 and ok == total and errors == 0
    # 3. a screenshot that is not blank
    shot = tmp_path / "shot.png"
    proc = _chromium(tmp_path, f"--screenshot={shot}", "--window-size=1200,2000", page.as_uri())
    assert shot.is_file(), proc.stderr[-2000:]
    pixels = iio.imread(shot)[..., :3].astype(np.float64)
    assert pixels.shape[:2] == (2000, 1200)
    assert pixels.std() > 20.0  # text, tables and images, not an empty page
    assert (pixels.mean(axis=-1) < 128).mean() > 0.01  # some dark pixels: text was drawn


def test_convergence_json_is_alone_on_stdout(tmp_path):
    """`harness convergence --json` prints one JSON object on stdout (the human summary goes to stderr)."""
    import json as _json
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-m", "harness", "convergence", str(ROOT / "scenes" / "furnace.toml"),
                           "--film", "8x8", "--spp", "1,2", "--seconds", "0.02", "--out", str(tmp_path), "--quiet",
                           "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    result = _json.loads(proc.stdout)
    budgets = [p["budget"] for p in result["series"][0]["points"]]
    assert {"seconds": 0.02} in budgets and "slope" in proc.stderr


def test_studies_made_again_render_no_mitsuba_image(report_dir, monkeypatch, tmp_path):
    """The convergence curves' Mitsuba rungs come from the ground-truth cache the first studies filled."""
    from harness.renderers.mitsuba import MitsubaRenderer
    from harness.studies import suite_studies
    from harness.studies.suite_studies import write_suite_studies

    def no_render(self, scene, request):
        raise AssertionError("Mitsuba rendered although its images are cached")

    monkeypatch.setattr(MitsubaRenderer, "render", no_render)
    # no plots (matplotlib: seconds), which are drawn from the curves after every render; the report_dir fixture's
    # studies draw them
    monkeypatch.setattr(suite_studies._Plots, "draw", lambda self: None)
    results = json.loads((report_dir / "results.json").read_text())
    write_suite_studies(results, report_dir, fast_options(shadow_rays=False, strategies=False), out_dir=tmp_path / "s")
    studies = json.loads((tmp_path / "s" / "studies.json").read_text())
    for scene in studies["convergence"]["scenes"]:
        assert "error" not in scene, scene.get("error")
        assert any(s["renderer"] == "mitsuba" for s in scene["result"]["series"])


# ---- the report only formats: it renders nothing, reads the ground truth results.json names, uses templates --------


def test_a_report_renders_nothing(report_dir, monkeypatch, tmp_path):
    """Every renderer and ground-truth function broken: the report of a run with its studies is still whole (every
    case's images, every study section), read from results.json, the cases' EXRs and studies.json."""
    import harness.renderers.groundtruth as groundtruth
    from harness.renderers.base import Renderer
    from harness.renderers.mitsuba import MitsubaRenderer
    from harness.renderers.reference import ReferenceRenderer
    from harness.report import write_suite_report

    def broken(*args, **kwargs):
        raise AssertionError("the report rendered")

    for cls in (Renderer, ReferenceRenderer, MitsubaRenderer):
        monkeypatch.setattr(cls, "render", broken, raising=False)
    for name in ("ground_truth", "closed_form"):
        monkeypatch.setattr(groundtruth, name, broken)
    write_suite_report(report_dir / "results.json", tmp_path)
    report = json.loads((tmp_path / "report.json").read_text())
    assert all(case["problems"] == [] and len(case["images"]) == 5 for case in report["cases"])
    assert all("error" not in scene for scene in report["convergence"]["scenes"])
    assert "error" not in report["shadow_rays"] and "skipped" not in report["shadow_rays"]
    assert all("error" not in scene for scene in report["strategies"]["scenes"])
    for plot in [s["plot"] for s in report["convergence"]["scenes"] + report["strategies"]["scenes"]]:
        assert Path(plot).is_file() and Path(plot).is_relative_to(tmp_path / "report")  # copied into the report
    page = (tmp_path / "index.html").read_text()
    assert "Not computed" not in page and page.count('<figure class="plot">') == 2 + 2 + 2


def test_the_ground_truth_shown_is_the_file_results_json_names(report_dir):
    """run_case records the ground truth's file for a closed form and another renderer's image too (in the case's
    folder), and the report's ground_truth.exr holds exactly that image."""
    from harness.files.imageio import read_exr

    results = json.loads((report_dir / "results.json").read_text())
    for record in results["cases"]:
        path = Path(record["ground_truth"]["path"])
        assert path == report_dir / "cases" / path.parent.name / "ground_truth.exr"
        shown = read_exr(report_dir / "report" / path.parent.name / "ground_truth.exr").image
        np.testing.assert_array_equal(shown, read_exr(path).image)


def _break_image_making(monkeypatch):
    """Every function that makes a report image (previews, error maps, FLIP, the MSE point) raises."""
    import harness.files.previews as previews
    import harness.files.report_images as report_images
    import harness.judges.metrics as metrics

    def broken(*args, **kwargs):
        raise AssertionError("the report made an image")

    for module, name in ((report_images, "error_images"), (report_images, "error_point"),
                         (report_images, "display_exposure"), (previews, "error_images"), (metrics, "flip")):
        monkeypatch.setattr(module, name, broken)
    for name in ("radiance", "heatmap"):
        monkeypatch.setattr(previews.ImageWriter, name, broken)


def test_the_run_makes_each_case_s_report_images_and_the_report_only_places_them(report_dir, monkeypatch, tmp_path):
    """harness run writes each case's images into cases/<case>/images and describes them in results.json; the report
    of the run makes none (previews, error maps and FLIP broken): it links or copies those files, byte for byte, and
    takes their numbers from results.json."""
    from harness.files.results import read_results
    from harness.report import write_suite_report

    results = read_results(report_dir / "results.json")  # the schema takes the new key
    for record in results["cases"]:
        images = record["report_images"]
        assert Path(images["folder"]) == report_dir / "cases" / Path(images["folder"]).parent.name / "images"
        assert [im["key"] for im in images["images"]] == ["ground_truth", "render", "error_signed",
                                                           "error_relative", "flip"]
    _break_image_making(monkeypatch)
    write_suite_report(report_dir / "results.json", tmp_path)
    report = json.loads((tmp_path / "report.json").read_text())
    for case, record in zip(report["cases"], results["cases"]):
        assert case["problems"] == [] and case["error_maps"] == record["report_images"]["error_maps"]
        stored = {im["key"]: im for im in record["report_images"]["images"]}
        for im in case["images"]:
            assert Path(im["png"]).parent == tmp_path / "report" / Path(im["png"]).parent.name
            assert {k: v for k, v in im.items() if k not in ("exr", "png")} == \
                {k: v for k, v in stored[im["key"]].items() if k not in ("exr", "png")}
            for kind in ("exr", "png"):
                source = Path(record["report_images"]["folder"]) / stored[im["key"]][kind]
                assert Path(im[kind]).read_bytes() == source.read_bytes()
    page = (tmp_path / "index.html").read_text()  # each case's thumbnail and tile p-values, its viewer's data file
    assert page.count('alt="render of ') == page.count("data-viewer-src=") == len(results["cases"])


def test_an_older_results_json_without_report_images_is_reported_as_before(report_dir, tmp_path):
    """A results.json of an older harness (no ``report_images``) or whose images folder is gone: the report makes
    the images from the cases' EXRs itself, the same images and numbers the run made."""
    from harness.report import write_suite_report

    results = json.loads((report_dir / "results.json").read_text())
    old = json.loads(json.dumps(results))
    for record in old["cases"]:
        record.pop("report_images")
    run = tmp_path / "run"
    (report_dir / "results-older.json").write_text(json.dumps(old))  # in the run folder, whose files it names
    write_suite_report(report_dir / "results-older.json", run)
    report = json.loads((run / "report.json").read_text())
    for case, record in zip(report["cases"], results["cases"]):
        assert case["problems"] == [] and case["error_maps"] == record["report_images"]["error_maps"]
        stored = {im["key"]: im for im in record["report_images"]["images"]}
        assert [im["key"] for im in case["images"]] == list(stored)
        for im in case["images"]:
            assert im["stats"] == stored[im["key"]]["stats"] and im["legend"] == stored[im["key"]]["legend"]
            source = Path(record["report_images"]["folder"]) / stored[im["key"]]["png"]
            assert Path(im["png"]).read_bytes() == source.read_bytes()
            assert Path(im["exr"]).stat().st_ino != (source.with_suffix(".exr")).stat().st_ino  # made, not linked
    moved = tmp_path / "moved"  # report_images names a folder that is not there: found in the run folder
    gone = json.loads(json.dumps(results))
    for record in gone["cases"]:
        record["report_images"]["folder"] = str(tmp_path / "nowhere")
    (report_dir / "results-moved.json").write_text(json.dumps(gone))
    write_suite_report(report_dir / "results-moved.json", moved)
    again = json.loads((moved / "report.json").read_text())
    assert [c["error_maps"] for c in again["cases"]] == [c["error_maps"] for c in report["cases"]]
    assert [(len(c["images"]), c["problems"]) for c in again["cases"]] == [(5, [])] * len(again["cases"])


def test_a_run_without_studies_says_how_to_get_them(report_dir, tmp_path):
    from harness.report import write_suite_report

    run = tmp_path / "run"
    shutil.copytree(report_dir, run, ignore=shutil.ignore_patterns("studies"))
    write_suite_report(run / "results.json", run)
    page = (run / "index.html").read_text()
    report = json.loads((run / "report.json").read_text())
    assert report["convergence"] is None and report["shadow_rays"] is None and report["strategies"] is None
    assert report["studies"]["file"] is None and "not found" in report["studies"]["note"]
    for anchor in ("convergence", "shadow-rays", "strategies"):
        section = re.search(f'<section id="{anchor}">(.*?)</section>', page, re.S).group(1)
        assert "Not computed" in section and "harness run SUITE" in section and "--studies" in section


def test_a_run_with_some_studies_off_says_which(report_dir, tmp_path):
    from harness.report import ReportOptions, write_suite_report
    from harness.studies.suite_studies import write_suite_studies

    results = json.loads((report_dir / "results.json").read_text())
    write_suite_studies(results, report_dir, fast_options(convergence=False, shadow_rays=False, strategies=False),
                        out_dir=tmp_path / "studies")
    write_suite_report(report_dir / "results.json", tmp_path, ReportOptions(shadow_rays=False),
                       studies_dir=tmp_path / "studies")
    page = (tmp_path / "index.html").read_text()
    assert 'id="shadow-rays"' not in page  # left out by the report
    assert "Not computed by this run (harness run --no-convergence)" in page
    assert "Not computed by this run (harness run --no-strategies)" in page


def test_a_malformed_or_hostile_studies_json_is_a_note_not_a_crash(report_dir, tmp_path):
    """studies.json is read defensively: bad JSON is a note in each section; a section that does not hold what it
    should is a note in that section; a file named outside the studies' folder is not copied or embedded."""
    from harness.report import write_suite_report

    (tmp_path / "outside.png").write_bytes((report_dir / "studies" / "convergence" / "furnace.png").read_bytes())
    studies = tmp_path / "studies"
    studies.mkdir()
    (studies / "studies.json").write_text("{not json")
    write_suite_report(report_dir / "results.json", tmp_path / "a", studies_dir=studies)
    page = (tmp_path / "a" / "index.html").read_text()
    assert page.count("not valid JSON") == 3
    doc = json.loads((report_dir / "studies" / "studies.json").read_text())
    doc["convergence"]["scenes"][0]["plot"] = "../outside.png"
    doc["strategies"]["scenes"][0]["rows"] = 7
    doc["shadow_rays"]["images"][0]["legend"] = {"stops": ["red;background:url(http://x)"], "vmin": 0, "vmax": 1}
    doc["shadow_rays"]["images"][0]["title"] = EVIL
    (studies / "studies.json").write_text(json.dumps(doc))
    for name in ("shadow-rays",):
        shutil.copytree(report_dir / "studies" / name, studies / name)
    write_suite_report(report_dir / "results.json", tmp_path / "b", studies_dir=studies)
    page = (tmp_path / "b" / "index.html").read_text()
    report = json.loads((tmp_path / "b" / "report.json").read_text())
    assert report["convergence"]["scenes"][0]["plot"] is None and "plot missing (../outside.png)" in page
    assert not (tmp_path / "b" / "outside.png").exists() and report["strategies"] is None
    assert "studies.json&#x27;s strategies section could not be read (TypeError" in page
    assert "url(http" not in page and "<script>alert" not in page and html.escape(EVIL, quote=True) in page


def test_report_flags_that_compute_need_studies(tmp_path, capsys):
    from harness.cli import main

    for flag in (["--convergence-spp", "1,2"], ["--strategy-spp", "4"], ["--no-strategy-renders"]):
        assert main(["report", str(tmp_path / "results.json"), *flag]) == 2
        err = capsys.readouterr().err.strip()
        assert err.splitlines() == [err] and err.startswith(f"harness: error: {flag[0]}: applies only with --studies")


def test_the_report_layer_imports_nothing_that_renders_and_writes_no_html_in_python():
    """harness/report imports only core, judges, files, scene and studies.figures (the plots of study data); its
    HTML comes from the Jinja2 templates (autoescape on), not from Python strings."""
    import ast

    from harness.report import html as report_html

    allowed = ("harness.core", "harness.judges", "harness.files", "harness.scene", "harness.studies.figures",
               "harness.report")
    for path in sorted((ROOT / "harness" / "report").glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [f"{node.module}.{a.name}" for a in node.names] if isinstance(node, ast.ImportFrom)
                     and node.module else [])
            for name in names:
                if name.startswith("harness"):
                    assert name.startswith(allowed), f"{path.name}: {name}"
        source = path.read_text()
        for tag in ("<table", "<section", "<td", "<p ", "<p>", "<figure", "<div"):
            assert tag not in source, f"{path.name} builds HTML in Python ({tag})"
    assert report_html.ENV.autoescape is True
    templates = sorted((ROOT / "harness" / "report" / "templates").glob("*.html.j2"))
    assert len(templates) >= 5 and not any("|safe" in t.read_text() for t in templates)


# ---- start-up ------------------------------------------------------------------------------------------------------

#: what formatting a report never needs: the compiler and Embree of the reference tracer, Mitsuba, Dask, the renderers
#: (importing them was most of `harness report`'s start-up, docs/performance.md, "The harness's own time")
NOT_FOR_A_REPORT = ("numba", "llvmlite", "embreex", "mitsuba", "drjit", "dask", "harness.renderers",
                    "harness.running.schedule", "harness.studies.suite_studies")


def _imported(argv: list[str]) -> tuple[int, list[str]]:
    """Run ``harness ARGV`` in a fresh interpreter: its exit code and which of :data:`NOT_FOR_A_REPORT` it imported."""
    script = ("import json, sys\nfrom harness.cli import main\ntry:\n    code = main(sys.argv[1:])\n"
              "except SystemExit as end:\n    code = end.code\n"
              f"print(json.dumps([code, sorted(m for m in {NOT_FOR_A_REPORT!r} if m in sys.modules)]))")
    done = subprocess.run([sys.executable, "-c", script, *argv], capture_output=True, text=True, timeout=120,
                          check=False)
    return tuple(json.loads(done.stdout.strip().splitlines()[-1]))


def test_harness_report_imports_no_renderer_numba_or_mitsuba(report_dir, tmp_path):
    """``harness report`` (the whole command: its parser, reading results.json, the cases' images and viewer data,
    the page) imports none of them, and neither do ``harness --help`` or ``compare`` and ``view``'s parsers."""
    code, heavy = _imported(["report", str(report_dir / "results.json"), "--out", str(tmp_path), "--quiet"])
    assert code == 0 and (tmp_path / "index.html").is_file()
    assert heavy == []
    for argv in (["--help"], ["compare", "--help"], ["view", "--help"]):
        assert _imported(argv) == (0, []), argv


def test_harness_run_still_imports_what_it_runs():
    """The check above can fail: the command that renders (its module loaded by name) imports the renderers."""
    script = ("import sys\nfrom harness.cli import build_parser\nbuild_parser('run')\n"
              "print('harness.renderers' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.strip() == "True"


def test_a_case_with_studies_false_is_left_out_of_the_studies(report_dir, monkeypatch, tmp_path):
    """``studies = false`` (docs/suites.md): the case's scene gets no study when no other case of it takes part."""
    from harness.studies import suite_studies
    from harness.studies.suite_studies import write_suite_studies

    monkeypatch.setattr(suite_studies._Plots, "draw", lambda self: None)
    results = json.loads((report_dir / "results.json").read_text())
    suite = tmp_path / "tiny.toml"
    suite.write_text(SUITE.replace("SCENES", str(ROOT / "scenes")).replace(
        'name = "soft-shadows/vs-reference"\n', 'name = "soft-shadows/vs-reference"\nstudies = false\n'))
    results["suite_file"] = str(suite)
    write_suite_studies(results, report_dir, fast_options(shadow_rays=False, strategies=False), out_dir=tmp_path / "s")
    studies = json.loads((tmp_path / "s" / "studies.json").read_text())
    assert [s["scene_name"] for s in studies["convergence"]["scenes"]] == ["furnace"]
    assert "soft-shadows/vs-reference" not in [c["name"] for c in studies["cases"]]
