"""``harness bench``: its figures are computed as documented, and the command works end to end on a small scene.

The timings themselves are measurements, not tests (docs/performance.md); these tests check the arithmetic, the
shape of the result and the command's errors.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, SCENES, load_small
from fake_renderers import slow_start_renderer

from harness.studies import bench
from harness.renderers import external
from harness.renderers.groundtruth import closed_form

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")


def test_mse_subtracts_the_ground_truths_own_noise():
    rng = np.random.default_rng(1)
    truth = np.full((64, 64, 3), 0.5)
    gt_var, render_var = 1e-4, 4e-4
    gt = truth + rng.normal(0.0, math.sqrt(gt_var), truth.shape)
    render = truth + rng.normal(0.0, math.sqrt(render_var), truth.shape)
    mse, raw = bench.mse_against(render, gt, np.full(truth.shape, gt_var))
    # raw estimates Var R + Var G; the corrected one Var R. Their standard errors are about sqrt(2 / N) relative.
    tolerance = 5 * math.sqrt(2.0 / truth.size) * (render_var + gt_var)
    assert abs(raw - (render_var + gt_var)) < tolerance
    assert abs(mse - render_var) < tolerance
    assert bench.mse_against(render, gt, None)[0] == raw


def test_efficiency_and_ratios():
    assert bench.efficiency(0.01, 2.0) == pytest.approx(50.0)
    assert math.isnan(bench.efficiency(0.0, 1.0)) and math.isnan(bench.efficiency(-1e-6, 1.0))
    rows = [
        bench.Row("s", "reference", "reference", {}, 4, 8, 8, efficiency=30.0, paths_per_second=2e6),
        bench.Row("s", "mitsuba llvm_ad_rgb", "mitsuba", {"variant": "llvm_ad_rgb"}, 4, 8, 8, efficiency=60.0,
                  paths_per_second=4e6),
        bench.Row("s", "mitsuba scalar_rgb", "mitsuba", {"variant": "scalar_rgb"}, 4, 8, 8, efficiency=10.0,
                  paths_per_second=1e6),
        bench.Row("s", "mitsuba llvm_ad_rgb ldsampler", "mitsuba", {"variant": "llvm_ad_rgb", "sampler": "ldsampler"},
                  4, 8, 8, efficiency=120.0, paths_per_second=4e6),
    ]
    r = bench.ratios(rows)
    assert r == {"efficiency_vs_llvm_ad_rgb": 0.5, "paths_per_second_vs_llvm_ad_rgb": 0.5,
                 "efficiency_vs_scalar_rgb": 3.0, "paths_per_second_vs_scalar_rgb": 2.0,
                 "efficiency_vs_llvm_ad_rgb_ldsampler": 0.25, "paths_per_second_vs_llvm_ad_rgb_ldsampler": 0.5,
                 "efficiency_vs_mitsuba_best": 0.25}
    assert bench.best_mitsuba(rows).label == "mitsuba llvm_ad_rgb ldsampler"
    block = {"ratios": r, "rows": [bench.row_dict(row) | {"cores_busy": 2.0} for row in rows]}
    targets = bench.check_targets({"cornell-box": block, "veach-mis": {"ratios": {"efficiency_vs_mitsuba_best": 1.0},
                                                                       "rows": []}})
    assert [(t["name"], t["scene"], t["met"]) for t in targets] == [
        ("efficiency_vs_llvm_ad_rgb_ldsampler", "cornell-box", False),
        ("efficiency_vs_mitsuba_best", "cornell-box", False),
        ("efficiency_vs_mitsuba_best", "veach-mis", True),
        ("paths_per_second_vs_llvm_ad_rgb", "cornell-box", False),
        ("cores_busy", "cornell-box", 2.0 >= 0.9 * os.cpu_count()),
        ("embree_fraction", "cornell-box", None),  # no Embree row in these blocks: not measured
        ("embree_fraction", "veach-mis", None)]
    assert not bench.targets_met(targets) and bench.targets_met(targets[2:3])
    nan = {"ratios": {"efficiency_vs_mitsuba_best": math.nan}, "rows": []}
    assert [t["met"] for t in bench.check_targets({"veach-mis": nan})] == [None, None]
    assert not bench.targets_met(bench.check_targets({"veach-mis": nan}))


def test_bench_scene_races_contenders_against_a_closed_form():
    scene = load_small("furnace", 8)
    contenders = [bench.Contender("reference", "reference"),
                  bench.Contender("reference direct=mis", "reference", {"direct": "mis"}),
                  bench.Contender("mitsuba scalar_rgb", "mitsuba", {"moments": "off", "variant": "scalar_rgb"}),
                  bench.Contender("broken", "reference", {"direct": "nonsense"})]
    rows = bench.bench_scene(scene, contenders, spp=4, repeats=2, gt=closed_form(scene))
    ref, off, mitsuba, broken = rows
    for row in (ref, off, mitsuba):
        assert row.error is None and len(row.seconds_all) == 2 and row.seconds > 0
        assert row.mse > 0 and row.efficiency == pytest.approx(1.0 / (row.mse * row.seconds))
        assert row.paths_per_second == pytest.approx(8 * 8 * 4 / row.seconds)
    assert ref.rays_per_second > 0 and ref.embree_share is not None and 0 <= ref.embree_share
    assert mitsuba.rays_per_second is None and mitsuba.variant == "scalar_rgb"
    assert broken.error and "direct" in broken.error
    text = bench.format_table(rows)
    assert "skipped" in text and "mitsuba scalar_rgb" in text


def test_bench_command_writes_json_and_refuses_bad_options(tmp_path, capfd):
    out = tmp_path / "bench.json"
    # --no-embree-rate: the Embree row's replay (1 CPU-s) and its place in the JSON are
    # tests/studies/test_embree_rate.py's (test_the_json_holds_the_embree_rate_and_the_targets)
    proc = subprocess.run(
        [sys.executable, "-m", "harness", "bench", "--scene", str(SCENES / "furnace.toml"), "--spp", "1",
         "--repeats", "1", "--no-strategies", "--no-embree-rate", "--json", "--quiet", "--out", str(out)],
        capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)
    assert json.loads(out.read_text()) == result
    block = result["scenes"]["furnace"]
    assert block["ground_truth"]["source"] == "closed-form"
    labels = [row["label"] for row in block["rows"]]
    assert labels == ["reference", "mitsuba llvm_ad_rgb", "mitsuba scalar_rgb"]  # spp 1: no ldsampler row
    assert [c.label for c in bench.default_contenders(64)][-1] == "mitsuba llvm_ad_rgb ldsampler"
    assert "efficiency_vs_scalar_rgb" in block["ratios"]
    # the refusals: main() in this process (the command's process and its stdout were the run above)
    from harness.cli import main

    for option, value in (("--spp", "0"), ("--repeats", "0"), ("--memory", "big"), ("--scene", "no-such-scene")):
        code = main(["bench", option, value, "--quiet"])
        stderr = capfd.readouterr().err
        assert code == 2 and option in stderr and len(stderr.strip().splitlines()) == 1


def test_peak_memory_is_measured_in_a_child(tmp_path):
    m = bench.peak_memory(SCENES / "furnace.toml", 32, 2)
    assert 50 < m["peak_rss_mib"] < 2048 and m["width"] == 32 and m["seconds"] > 0


def test_the_benchmark_suite_runs():
    """tests/benchmarks (timed only with --benchmark-only) runs each body once, untimed: a change that breaks a
    benchmark (a kernel's signature, a fixture) fails here, in the default run, and not only when someone times."""
    proc = subprocess.run([sys.executable, "-m", "pytest", "tests/studies/benchmarks", "-o", "addopts=", "--benchmark-disable",
                           "-q", "-p", "no:cacheprovider"], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:]
    assert " passed" in proc.stdout and "failed" not in proc.stdout




def test_bench_races_another_renderer_at_equal_spp_without_start_up(tmp_path, capfd, monkeypatch):
    """``harness bench --renderer FILE``: the renderer's row holds the same spp as the others', rendered in one run
    at that spp (not K = 2 runs of spp / 2: the race needs no variance, and for a stratified sampler K runs at
    spp / K are another estimator), its time is the render time alone (0.4 s of "rendering" per render, without
    its 0.8 s start-up), and its ratios to the reference are in the result and the text."""
    # 0.8 s of start-up, 0.1 s per spp of "rendering" at 8x8 (0.4 s per render: well above the scatter of start-up,
    # which a smaller signal drowns in, reading 0 s); no variance channels
    renderer = slow_start_renderer(tmp_path, startup=0.8, per_spp=0.1, noise=0.05)
    scene = load_small("furnace", 8)
    contenders = [bench.Contender("reference", "reference"), bench.Contender("fake", str(renderer))]
    asked = []
    real_render = external.ExternalRenderer.render

    def spy(self, scene, request):
        asked.append((request.spp, request.variance))
        return real_render(self, scene, request)

    monkeypatch.setattr(external.ExternalRenderer, "render", spy)
    # one timed render after the warm-up: the repeats' bookkeeping is
    # test_bench_scene_races_contenders_against_a_closed_form's
    rows = bench.bench_scene(scene, contenders, spp=4, repeats=1, gt=closed_form(scene))
    ref, fake = rows
    assert asked == [(4, False), (4, False)]  # the warm-up and the timed render, one run each
    assert fake.error is None and fake.spp == ref.spp == 4 and len(fake.seconds_all) == 1
    assert fake.time_from.startswith("start-up subtracted (")
    # 0.4 s of rendering; unsubtracted, 0.8 + 0.4 s and the interpreter's start: 1.2 s and more. Between the
    # start-up probes and the timed run the other tests' load can change a run's start by 0.25 s or so, so the
    # upper bound sits at 1.0 s, below the unsubtracted 1.2 s; the lower bound only says that something is left.
    startup = float(fake.time_from.split("(")[1].split(" s ")[0])
    assert startup >= 0.8, fake.time_from  # the sleep alone
    assert all(0.05 < s < 1.0 for s in fake.seconds_all), fake.seconds_all  # unsubtracted: 1.2 s and more
    assert fake.paths_per_second == pytest.approx(8 * 8 * 4 / fake.seconds)
    ratios = bench.contender_ratios(rows, "fake")
    assert ratios["efficiency_vs_reference"] == pytest.approx(fake.efficiency / ref.efficiency)
    assert "fake" in bench.format_table(rows)
    # a missing renderer file: main() in this process, as the other refusals (the command's process is
    # test_bench_command_writes_json_and_refuses_bad_options's), refused before anything is raced
    from harness.cli import main

    def raced(*args, **kwargs):
        raise AssertionError("bench raced before refusing the missing renderer file")

    monkeypatch.setattr(bench, "run_bench", raced)
    capfd.readouterr()
    assert main(["bench", "--renderer", str(tmp_path / "missing.toml"), "--quiet"]) == 2
    stderr = capfd.readouterr().err
    assert "--renderer" in stderr and "missing.toml" in stderr and len(stderr.strip().splitlines()) == 1


def _row(label, renderer, settings, mse, seconds):
    return bench.Row("s", label, renderer, settings, 4, 8, 8, mse_all=list(mse), seconds_all=list(seconds),
                     efficiency=bench.efficiency(float(np.mean(mse)), float(np.median(seconds))),
                     paths_per_second=256 / float(np.median(seconds)))


def test_ratio_intervals_and_the_targets_lower_bound():
    """Each ratio of the race with its interval over the rounds (harness.judges.efficiency.ratio_interval): the
    reference twice as efficient as one contender, its MSE half at the same time; a target is met only when the
    interval's lower bound clears it, and not measured with one round (no bound)."""
    rng = np.random.default_rng(3)
    times = 1.0 + 0.02 * rng.standard_normal(8)
    rows = [_row("reference", "reference", {}, 0.01 * (1 + 0.05 * rng.standard_normal(8)), times),
            _row("mitsuba llvm_ad_rgb", "mitsuba", {"variant": "llvm_ad_rgb"},
                 0.02 * (1 + 0.05 * rng.standard_normal(8)), times[::-1]),
            _row("mitsuba llvm_ad_rgb ldsampler", "mitsuba", {"variant": "llvm_ad_rgb", "sampler": "ldsampler"},
                 0.0105 * (1 + 0.05 * rng.standard_normal(8)), times)]
    intervals = bench.ratio_intervals(rows)
    assert set(intervals) == set(bench.ratios(rows))
    eff = intervals["efficiency_vs_llvm_ad_rgb"]
    assert eff["low"] < 2.0 < eff["high"] and eff["low"] > 1.8 and eff["level"] == 0.95
    paths = intervals["paths_per_second_vs_llvm_ad_rgb"]
    assert paths["low"] < 1.0 < paths["high"]
    block = {"ratios": bench.ratios(rows), "ratio_intervals": intervals,
             "rows": [bench.row_dict(r) | {"cores_busy": 2.0} for r in rows]}
    checked = {t["name"]: t for t in bench.check_targets({"cornell-box": block})}
    ld = checked["efficiency_vs_llvm_ad_rgb_ldsampler"]  # about 1.05: its interval straddles 1, so not met
    assert ld["low"] < 1.0 < ld["high"] and ld["met"] is False and ld["measured"] == intervals[
        "efficiency_vs_llvm_ad_rgb_ldsampler"]["value"]
    one = [dataclasses.replace(r, mse_all=r.mse_all[:1], seconds_all=r.seconds_all[:1]) for r in rows]
    single = {"ratios": bench.ratios(one), "ratio_intervals": bench.ratio_intervals(one), "rows": block["rows"]}
    assert bench.check_targets({"cornell-box": single})[0]["met"] is None
    text = bench.format_report({"spp": 4, "repeats": 8, "scenes": {}, "targets": bench.check_targets(
        {"cornell-box": block}), "machine": {"before": {"load_average": [0.1, 0.2, 0.3], "governors": None},
                                             "after": {"load_average": [1.9, 1.0, 0.5]}, "busy": None}})
    assert "[" in text.splitlines()[0] and "machine: load average [0.1, 0.2, 0.3] -> [1.9, 1.0, 0.5]" in text


def test_a_busy_machine_certifies_nothing_and_check_takes_five_rounds(monkeypatch, capfd):
    """A load average above BUSY_LOAD_PER_CORE per core before the race: the reason says so (figures are kept,
    no target certified); --check with fewer than MIN_CHECK_REPEATS rounds is one line naming --repeats."""
    cores = 2
    assert bench.busy_reason({"load_average": [0.4, 0.3, 0.3], "cpu_count": cores}) is None
    reason = bench.busy_reason({"load_average": [1.7, 1.2, 0.9], "cpu_count": cores})
    assert "busy" in reason and "1.70" in reason and "2 cores" in reason
    assert bench.busy_reason({"load_average": None, "cpu_count": cores}) is None
    state = bench.machine_state()
    assert set(state) == {"load_average", "cpu_count", "governors"} and len(state["load_average"]) == 3
    from harness.cli import main

    code = main(["bench", "--check", "--repeats", "3", "--quiet"])
    err = capfd.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--repeats: --check takes at least 5 rounds" in err, err


class _ScriptedRenderer:
    """A renderer whose renders take ``seconds`` and leave an image of uniform error sqrt(``mse``) over a black
    ground truth; it records each request (or raises ``fail``)."""

    def __init__(self, seconds, mse, log, name, fail=None):
        self.seconds, self.mse, self.log, self.name, self.fail = seconds, mse, log, name, fail

    def render(self, scene, request):
        self.log.append((self.name, request.spp, request.seed, dict(request.settings)))
        if self.fail is not None:
            raise self.fail
        image = np.full((scene.film.height, scene.film.width, 3), math.sqrt(self.mse(request.spp)))
        return type("Out", (), {"image": image, "seconds": self.seconds(request.spp), "spp": request.spp,
                                "info": {}})()


def _equal_time_rows(ref_seconds, best_seconds, spp=64):
    ref = bench.Row("s", "reference", "reference", {}, spp, 8, 8, seconds_all=[ref_seconds] * 3,
                    mse_all=[1e-4] * 3, efficiency=1.0 / (1e-4 * ref_seconds))
    best = bench.Row("s", "mitsuba llvm_ad_rgb multijitter", "mitsuba",
                     {"variant": "llvm_ad_rgb", "sampler": "multijitter", "moments": "off"}, spp, 8, 8,
                     seconds_all=[best_seconds] * 3, mse_all=[1e-4] * 3, efficiency=1.0 / (1e-4 * best_seconds))
    worse = bench.Row("s", "mitsuba llvm_ad_rgb", "mitsuba", {"variant": "llvm_ad_rgb"}, spp, 8, 8,
                      seconds_all=[best_seconds] * 3, mse_all=[1e-3] * 3, efficiency=1.0 / (1e-3 * best_seconds))
    return [ref, best, worse]


def test_equal_time_against_best_renders_the_reference_at_the_best_rows_time(monkeypatch):
    """The reference twice as slow as Mitsuba's best: it renders at 32 spp (64 x 1 / 2), the best row at its 64,
    taking turns with seeds of their own; the ratio is (MSE_best t_best) / (MSE_ref t_ref) from those pairs, with an
    interval. A time ratio that gives a spp that is not a power of two takes the nearest one (30 -> 32)."""
    log = []
    renderers = {"reference": _ScriptedRenderer(lambda spp: spp / 32.0, lambda spp: 4e-4 * 32 / spp,
                                                log, "reference"),
                 "mitsuba": _ScriptedRenderer(lambda spp: 1.0, lambda spp: 1e-4, log, "mitsuba")}
    monkeypatch.setattr(bench, "get_renderer", lambda name: renderers[name])
    scene = load_small("furnace", 8)
    gt = closed_form(scene)
    gt = dataclasses.replace(gt, image=np.zeros_like(gt.image), variance=None)
    lines = []
    out = bench.equal_time_against_best(scene, _equal_time_rows(2.0, 1.0), repeats=3, gt=gt, seed=1,
                                        on_render=lines.append)
    assert out["rendered"] and out["spp"] == 32 and out["mitsuba_spp"] == 64 and out["error"] is None
    assert out["mitsuba"] == "mitsuba llvm_ad_rgb multijitter"
    assert [(name, spp) for name, spp, _seed, _s in log] == [
        ("reference", 32), ("mitsuba", 64), ("mitsuba", 64), ("reference", 32), ("reference", 32), ("mitsuba", 64)]
    assert {seed for _name, _spp, seed, _settings in log} == {8, 9, 10}  # 1 + 2 x 3 + attempt: not the race's
    assert log[1][3]["sampler"] == "multijitter"
    # the reference at 32 spp: MSE 4e-4, 1 s; Mitsuba's best: 1e-4, 1 s -> a quarter of its efficiency
    assert out["ratio"]["value"] == pytest.approx(0.25) and out["ratio"]["low"] == pytest.approx(0.25)
    assert len(lines) == 6 and lines[0] == "furnace: reference at 32 spp (equal time)"
    text = bench.format_equal_time(out)
    assert text.startswith("reference / Mitsuba's best at equal time (the reference at 32 spp against mitsuba "
                           "llvm_ad_rgb multijitter at 64): efficiency 0.25")
    log.clear()
    out = bench.equal_time_against_best(scene, _equal_time_rows(2.1, 1.0), repeats=1, gt=gt)
    assert out["spp"] == 32 and log[0][1] == 32  # s* = 30.5: the nearest power of two


def test_equal_time_against_best_uses_the_race_where_the_times_match_and_says_what_failed(monkeypatch):
    """Times within 1.25 x: the race's own rounds, nothing rendered; no reference or no Mitsuba row: None; a render
    that fails: the error, no ratio."""
    log = []
    monkeypatch.setattr(bench, "get_renderer", lambda name: _ScriptedRenderer(lambda spp: 1.0, lambda spp: 1e-4, log,
                                                                              name))
    scene = load_small("furnace", 8)
    gt = closed_form(scene)
    out = bench.equal_time_against_best(scene, _equal_time_rows(1.1, 1.0), repeats=3, gt=gt)
    assert not out["rendered"] and out["spp"] == 64 and not log
    assert out["ratio"]["value"] == pytest.approx(1.0 / 1.1)
    assert "(both at 64 spp, the race's rounds): efficiency 0.909" in bench.format_equal_time(out)
    out = bench.equal_time_against_best(scene, _equal_time_rows(1.1, 1.0, spp=100), repeats=3, gt=gt)
    assert not out["rendered"] and out["spp"] == 100 and not log  # a race at 100 spp: its rounds, not 128's
    out = bench.equal_time_against_best(scene, _equal_time_rows(1.4, 1.0), repeats=3, gt=gt)
    assert not out["rendered"] and out["spp"] == 64 and not log  # s* = 46 comes to the race's 64
    rows = _equal_time_rows(2.0, 1.0)
    assert bench.equal_time_against_best(scene, rows[:1], repeats=3, gt=gt) is None
    assert bench.equal_time_against_best(scene, rows[1:], repeats=3, gt=gt) is None
    failing = _ScriptedRenderer(lambda spp: 1.0, lambda spp: 1e-4, log, "mitsuba",
                                fail=bench.HarnessError("--set sampler", "no such sampler"))
    monkeypatch.setattr(bench, "get_renderer", lambda name: failing)
    out = bench.equal_time_against_best(scene, rows, repeats=2, gt=gt)
    assert out["ratio"] is None and out["error"] == "--set sampler: no such sampler"
    assert bench.format_equal_time(out).endswith("not measured (--set sampler: no such sampler)")
