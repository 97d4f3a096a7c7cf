"""Convergence with any renderer (docs/report.md): equal-time and equal-error figures are read at most 2x beyond
a curve's measured times ("out of range" further out), and an external renderer without variance channels runs
once per render, so that its points land on the ladder at their labels, its times without process start-up."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fake_renderers import slow_start_renderer
from harness.renderers import get_renderer
from harness.report import write_suite_report
from harness.running.cases import load_suite
from harness.running.schedule import run_suite
from harness.studies import suite_studies
from harness.studies.suite_studies import StudyOptions, write_suite_studies
from harness.scene import load_scene
from harness.studies.convergence import MAX_EXTRAPOLATION, Series, equal_error, equal_time, run_convergence
from reference_impl import Film

ROOT = Path(__file__).resolve().parents[2]



def test_comparisons_go_at_most_2x_beyond_a_curve():
    """The issue's RMSE 1.4e+08 came from a line followed far outside its points: a curve measured over 1-4 s is
    read along its line down to 0.5 s and up to 8 s, and no further."""
    times = [1.0, 2.0, 4.0]
    errors = [0.1 / np.sqrt(t) for t in times]
    late = [t * 100 for t in times]  # 100-400 s: the common time (4 s) is 25x below it
    et = equal_time({"short": (times, errors), "late": (late, errors)})
    assert et["time"] == 4.0 and et["errors"]["late"] is None and et["ratio_to_first"]["late"] is None
    assert et["out_of_range"] == {"short": False, "late": True} and et["extrapolated"]["late"] is False
    near = [t * 1.9 for t in times]  # 1.9-7.6 s: 4 s inside; at 0.95 s (= 1.9 / 2) still within reach
    et = equal_time({"near": (near, errors), "short": (times, errors)}, at=1.9 / MAX_EXTRAPOLATION)
    assert et["extrapolated"] == {"near": True, "short": True} and not any(et["out_of_range"].values())
    assert et["errors"]["near"] == pytest.approx(0.1 / np.sqrt(0.5))
    et = equal_time({"near": (near, errors), "short": (times, errors)}, at=0.9)
    assert et["out_of_range"]["near"] and et["errors"]["near"] is None
    steep = [0.1 / t for t in times]  # reaches the other's smallest error (0.05) at 2 s; "flat" never does
    flat = [0.2, 0.19, 0.18]
    ee = equal_error({"steep": (times, steep), "flat": (times, flat)}, target=0.01)
    assert ee["out_of_range"] == {"steep": True, "flat": True} and ee["times"] == {"steep": None, "flat": None}


@pytest.fixture()
def fake_renderer(tmp_path):
    # K = 2 runs per render (no variance channels); pixels 0.5 + N(0, 0.1^2 / spp); start-up 0.6 s of sleep (and
    # the script's imports), and 0.02 s per spp of "rendering" at 8x8 pixels
    return slow_start_renderer(tmp_path, startup=0.6, per_spp=0.02, noise=0.1)


@pytest.mark.slow
def test_an_external_renderers_points_land_on_the_ladder(fake_renderer):
    scene = load_scene(ROOT / "scenes" / "furnace.toml")
    scene = dataclasses.replace(scene, film=Film(4, 4, "box"))
    gt = SimpleNamespace(image=np.full((4, 4, 3), 0.5, np.float32), variance=None, source="constant", spp=None)
    # no warm-up render (a run of 0.6 s); the suite's studies below (and the refusing renderer's test) go through
    # the warm-up and land on the same points
    result = run_convergence(scene, gt, [Series(str(fake_renderer), {}, "fake")], spp=(1, 2, 4), seed=3,
                             renderer_factory=get_renderer, warmup=False)
    series = result["series"][0]
    # one run per render (the study uses no variance of the render's own): every rung at its own spp
    assert [p["spp"] for p in series["points"]] == [1, 2, 4]
    assert [p["budget"]["spp"] for p in series["points"]] == [1, 2, 4]
    assert series["time_from"].startswith("start-up subtracted (") and "1x1 film" in series["time_from"]
    # each render is a run of 0.6 s sleep and the interpreter's start (about 0.65 s of wall time; 0.9 s when the
    # script imported numpy and the harness) and at most 0.08 s of rendering: what is left is that and the scatter
    # of process start on a loaded machine (0.5 s), below the 0.65 s or more of wall time a render that subtracted
    # nothing would read; timed once
    assert all(p["seconds"] < 0.6 and p["timing_repeats"] == 1 for p in series["points"]), series["points"]


def test_rungs_a_renderer_refuses_are_left_out_and_named(tmp_path):
    """A renderer that exits with an error below 2 spp per run (as the Cycles adapter) gets the points it
    can render, and the study names the rungs it refused; one that refuses every rung is named with its reason."""
    scene = load_scene(ROOT / "scenes" / "furnace.toml")
    scene = dataclasses.replace(scene, film=Film(8, 8, "box"), max_depth=2)
    gt = SimpleNamespace(image=np.full((8, 8, 3), 0.5, np.float32), variance=np.zeros((8, 8, 3), np.float32),
                         source="closed form", spp=None)
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    picky = slow_start_renderer(tmp_path / "a", startup=0.0, per_spp=0.0, noise=0.1, min_spp=2, own_time=True)
    refuses = slow_start_renderer(tmp_path / "b", startup=0.0, per_spp=0.0, noise=0.1, min_spp=100, own_time=True)
    result = run_convergence(scene, gt, [Series(str(picky), {}, "picky"), Series(str(refuses), {}, "refuses")],
                             spp=(1, 2, 4, 8), k=3.0, warmup=True, renderer_factory=get_renderer)
    (series,) = result["series"]  # one run per render: rung 1 refused, the others at their spp
    assert series["label"] == "picky" and [p["spp"] for p in series["points"]] == [2, 4, 8]
    assert [k["spp"] for k in series["skipped"]] == [1]
    assert "expected at least 2, got 1" in series["skipped"][0]["reason"]
    (failed,) = result["failed_series"]
    assert failed["label"] == "refuses" and "expected at least 100" in failed["error"]


@pytest.fixture()
def no_plots(monkeypatch):
    """The studies' plots are not drawn (matplotlib, about a second a plot, in forked processes): they are drawn from
    the curves after every render, and tests/report/test_report.py's studies draw them."""
    monkeypatch.setattr(suite_studies._Plots, "draw", lambda self: None)


@pytest.mark.slow
def test_the_suite_studies_and_report_show_an_external_renderer(tmp_path, no_plots):
    """A suite case rendered by a renderer file gets its own convergence curve, a line of its own beside the
    strategy rows (its efficiency from its case, with why it has no rows), and the report shows both with where
    its render time comes from."""
    # nothing here reads how much start-up was subtracted (the ladder test does): a 0.1 s sleep, not 0.6 s, in each
    # of its 14 runs. Its case's runs render 2 spp each: at 0.02 s per spp (0.04 s a run) the start-up's scatter
    # under a loaded machine left no render time after subtraction once (efficiency None); 0.1 s per spp, 0.2 s a run
    fake_renderer = slow_start_renderer(tmp_path, startup=0.1, per_spp=0.1, noise=0.1)

    suite = tmp_path / "suite.toml"
    suite.write_text(f'''name = "other"
[defaults]
spp = 4
film = {{ width = 8, height = 8 }}
[[cases]]
name = "furnace/reference"
scene = "{ROOT / 'scenes' / 'furnace.toml'}"
[[cases]]
name = "furnace/fake"
scene = "{ROOT / 'scenes' / 'furnace.toml'}"
renderer = "{fake_renderer}"
expect = "fail"
''')
    out = tmp_path / "out"
    results = run_suite(load_suite(suite), out)
    fake = next(c for c in results["cases"] if c["name"] == "furnace/fake")
    assert fake["render"]["info"]["time_from"].startswith("start-up subtracted")
    options = StudyOptions(convergence_spp=(1, 2, 4), convergence_strategies=(), convergence_mitsuba=False,
                           shadow_rays=False, render_strategies=False, min_timing_seconds=0.0,
                           strategy_min_seconds=0.0)
    write_suite_studies(results, out, options)
    studies = json.loads((out / "studies" / "studies.json").read_text())
    series = studies["convergence"]["scenes"][0]["result"]["series"]
    assert [s["label"] for s in series] == ["reference (defaults)", "fake"]
    assert [p["spp"] for p in series[1]["points"]] == [1, 2, 4]
    other = studies["strategies"]["scenes"][0]["other_renderers"]
    assert [o["renderer"] for o in other] == ["fake"] and "takes no settings" in other[0]["note"]
    assert other[0]["efficiency"] > 0 and other[0]["relative_efficiency"] > 0, (other, studies["strategies"])
    write_suite_report(out / "results.json", out)
    page = (out / "index.html").read_text()
    assert "start-up subtracted (" in page and "takes no settings" in page


@pytest.mark.slow
def test_a_glossy_scene_gets_the_glossy_engines_strategy_curves(tmp_path, no_plots):
    """The convergence study's extra curves of a scene with a mirror are a glossy scene's direct strategies
    (area, bsdf), not the Lambertian ones it refuses (hemisphere-cosine failed the whole scene's study before)."""
    suite = tmp_path / "suite.toml"
    suite.write_text(f'''name = "glossy"
[defaults]
spp = 4
film = {{ width = 8, height = 8 }}
[[cases]]
name = "white-furnace-mirror/reference"
scene = "{ROOT / 'scenes' / 'white-furnace-mirror.toml'}"
''')
    out = tmp_path / "out"
    results = run_suite(load_suite(suite), out)
    options = StudyOptions(convergence_spp=(1, 2), convergence_mitsuba=False, shadow_rays=False, strategies=False,
                           min_timing_seconds=0.0)
    write_suite_studies(results, out, options)
    (entry,) = json.loads((out / "studies" / "studies.json").read_text())["convergence"]["scenes"]
    assert "error" not in entry, entry.get("error")
    assert [s["label"] for s in entry["result"]["series"]] == [
        "reference (defaults)", "reference direct=area", "reference direct=bsdf"]
