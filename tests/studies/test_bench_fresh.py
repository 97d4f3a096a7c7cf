"""``harness bench``'s fresh-process race (:mod:`harness.studies.fresh_race`) and issue 39's targets: the embree
fraction with its interval, the fresh ratio, efficiency against Mitsuba's best on every canonical scene. The processes
are faked (their figures chosen), but for the failures of :func:`run_once`, which run a real (tiny) process; the
timings themselves are measurements, not tests (docs/performance.md)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.studies import bench, fresh_race

pytestmark = pytest.mark.slow  # starts processes: outside the inner loop (pytest -m "not slow")


def _fake_run(seconds: dict[str, list[float]], calls: list):
    """A ``run(argv)`` that records each argv and answers the next of ``seconds[label]`` (the warm-up's included),
    with a wall time of 1 s more and a kernel load for the reference."""
    left = {label: list(values) for label, values in seconds.items()}

    def run(argv):
        label = fresh_race.MITSUBA if "mitsuba" in argv else fresh_race.REFERENCE
        calls.append((label, list(argv)))
        render = left[label].pop(0)
        return {"seconds": render, "load_seconds": 0.4 if label == fresh_race.REFERENCE else None,
                "wall_seconds": render + 1.0, "startup_seconds": 1.0}

    return run


def test_the_fresh_race_takes_turns_after_a_warm_up_and_its_ratio():
    """A warm-up process each, then the rounds A B A B; each round's figures kept, the medians and Mitsuba's seconds
    over the reference's with its interval; the command is ``harness render`` with ``--json`` and the film."""
    calls: list = []
    noise = [1.0, 1.02, 0.98, 1.01, 0.99]
    run = _fake_run({fresh_race.REFERENCE: [9.0] + [0.1 * n for n in noise],
                     fresh_race.MITSUBA: [9.0] + [0.08 * n for n in noise[::-1]]}, calls)
    result = fresh_race.fresh_race(Path("scenes/soft-shadows.toml"), spp=64, rounds=5, film=(32, 16), run=run)
    assert [label for label, _ in calls] == [fresh_race.REFERENCE, fresh_race.MITSUBA] * 6
    argv = calls[0][1]
    assert argv[:5] == [sys.executable, "-m", "harness", "render", "scenes/soft-shadows.toml"]
    assert {"--json", "--quiet"} <= set(argv) and argv[argv.index("--film") + 1] == "32x16"
    assert argv[argv.index("--spp") + 1] == "64" and argv[argv.index("--seed") + 1] == "1"  # the warm-up's
    mitsuba_argv = calls[1][1]
    assert "--mitsuba-variant" in mitsuba_argv and "moments=off" in mitsuba_argv
    folders = {Path(a[a.index("--out") + 1]).parent for _, a in calls}
    assert len(folders) == 1 and not next(iter(folders)).exists()  # the temporary EXRs' folder is removed
    ref, mitsuba = (result["contenders"][k] for k in (fresh_race.REFERENCE, fresh_race.MITSUBA))
    assert ref["seconds_all"] == pytest.approx([0.1 * n for n in noise])  # the warm-up's 9 s left out
    assert ref["seconds"] == pytest.approx(0.1) and ref["load_seconds"] == 0.4 and mitsuba["load_seconds"] is None
    assert ref["startup_seconds"] == 1.0 and ref["wall_seconds"] == pytest.approx(1.1)
    assert result["ratios"][fresh_race.RATIO] == pytest.approx(0.8)
    interval = result["ratio_intervals"][fresh_race.RATIO]
    assert interval["low"] < 0.8 < interval["high"] and interval["low"] > 0.7
    text = fresh_race.format_fresh(result)
    assert "fresh processes (harness render at 32x16, 64 spp, median of 5 rounds" in text
    assert "reference" in text and "0.400" in text and f"{fresh_race.RATIO} (Mitsuba's" in text


def test_a_failed_fresh_run_is_a_skipped_row_in_one_line(tmp_path):
    """A process that exits 1, or prints no JSON: FreshRunError with the reason in one line; in the race the
    contender is skipped with it ("round N: ..."), no ratio, and the target on it is not measured."""
    with pytest.raises(fresh_race.FreshRunError, match=r"^exit code 1: boom$"):
        fresh_race.run_once([sys.executable, "-c", "import sys; print('x', file=sys.stderr); sys.exit('boom')"])
    with pytest.raises(fresh_race.FreshRunError, match="not harness render's JSON: hello"):
        fresh_race.run_once([sys.executable, "-c", "print('hello')"])
    with pytest.raises(fresh_race.FreshRunError, match="no exit within 0.5 s"):
        fresh_race.run_once([sys.executable, "-c", "import time; time.sleep(30)"], timeout=0.5)
    answers = {"calls": 0}

    def run(argv):
        if "mitsuba" in argv:
            answers["calls"] += 1
            if answers["calls"] == 2:
                raise fresh_race.FreshRunError("exit code 1: harness: render failed: mitsuba: no LLVM")
        return {"seconds": 0.1, "load_seconds": None, "wall_seconds": 1.1, "startup_seconds": 1.0}

    result = fresh_race.fresh_race("scenes/soft-shadows.toml", spp=4, rounds=3, run=run)
    assert result["contenders"][fresh_race.MITSUBA]["error"] == (
        "round 1: exit code 1: harness: render failed: mitsuba: no LLVM")
    assert answers["calls"] == 2 and len(result["contenders"][fresh_race.REFERENCE]["seconds_all"]) == 3
    assert result["ratios"] == {} and result["ratio_intervals"] == {}
    text = fresh_race.format_fresh(result)
    assert "skipped: round 1: exit code 1" in text and "not measured" in text
    checked = bench.check_targets({"soft-shadows": {"ratios": {}, "rows": [], "fresh": result}})
    fresh = next(t for t in checked if t["name"] == fresh_race.RATIO)
    assert fresh["measured"] is None and fresh["met"] is None


def test_the_fresh_target_can_fail_and_pass():
    """``fresh_seconds_vs_llvm_ad_rgb`` >= 0.5 on soft-shadows by its interval's lower bound: Mitsuba 4x faster
    fails it, Mitsuba 1.5x faster passes it."""
    for mitsuba, met in ((0.025, False), (0.067, True)):
        noise = [1.0, 1.01, 0.99, 1.02, 0.98]
        run = _fake_run({fresh_race.REFERENCE: [1.0] + [0.1 * n for n in noise],
                         fresh_race.MITSUBA: [1.0] + [mitsuba * n for n in noise]}, [])
        result = fresh_race.fresh_race("scenes/soft-shadows.toml", spp=64, rounds=5, run=run)
        checked = bench.check_targets({"soft-shadows": {"ratios": {}, "rows": [], "fresh": result}})
        fresh = next(t for t in checked if t["name"] == fresh_race.RATIO)
        assert fresh["minimum"] == 0.5 and fresh["met"] is met, fresh
        assert fresh["low"] is not None


def _reference_row(seconds):
    return bench.Row("s", "reference", "reference", {}, 4, 8, 8, seconds_all=list(seconds),
                     seconds=float(np.median(seconds)), rays_per_path=3.0, rays_per_second=3.0 * 256 / np.median(seconds))


def test_the_embree_fraction_has_an_interval_over_the_rounds_and_its_target_can_fail():
    """fraction = (R / t_ref) / (E / t_embree): the reference's 768 rays per render at 0.01 s against Embree's 1536
    recorded rays replayed in 0.01 s is 0.5, and its interval pairs the rounds' seconds; below 0.6 is not met, a
    faster reference is; a scene without the Embree row (or with it skipped) has the target not measured."""
    rng = np.random.default_rng(5)
    ref_seconds = 0.01 * (1 + 0.02 * rng.standard_normal(6))
    embree = {"error": None, "recorded_rays": 1536, "seconds_all": list(0.01 * (1 + 0.02 * rng.standard_normal(6))),
              "reference_fraction": 0.5}
    interval = bench.embree_fraction_interval(_reference_row(ref_seconds), embree)
    assert interval["value"] == pytest.approx(0.5 * np.mean(embree["seconds_all"]) / np.mean(ref_seconds))
    assert interval["low"] < interval["value"] < interval["high"] and interval["high"] < 0.6
    block = {"ratios": {}, "rows": [], "embree_rate": dict(embree, fraction_interval=interval)}
    checked = [t for t in bench.check_targets({"soft-shadows": block}) if t["name"] == bench.EMBREE_FRACTION]
    assert len(checked) == 1 and checked[0]["met"] is False and checked[0]["minimum"] == 0.6
    fast = bench.embree_fraction_interval(_reference_row(ref_seconds / 1.5), embree)
    block = {"ratios": {}, "rows": [], "embree_rate": dict(embree, fraction_interval=fast)}
    assert [t["met"] for t in bench.check_targets({"soft-shadows": block})
            if t["name"] == bench.EMBREE_FRACTION] == [True]
    # one round: no bound, not met; rounds that do not pair: no interval; a skipped row: not measured
    one = bench.embree_fraction_interval(_reference_row(ref_seconds[:1]), dict(embree, seconds_all=[0.01]))
    assert one["low"] is None
    assert bench.embree_fraction_interval(_reference_row(ref_seconds[:3]), embree) is None
    skipped = {"ratios": {}, "rows": [], "embree_rate": {"error": "the replay's answers differ"}}
    assert [t["met"] for t in bench.check_targets({"soft-shadows": skipped})
            if t["name"] == bench.EMBREE_FRACTION] == [None]
    # fog-box: the volumetric loop's rays are not recorded, so no Embree target there
    assert "fog-box" not in next(t for t in bench.targets() if t.measure == bench.EMBREE_FRACTION).scenes


def test_issue_39s_targets_cover_every_canonical_scene():
    """Efficiency against Mitsuba's best sampler on all eight canonical scenes, which race the extra samplers; the
    older targets kept; --check's scenes in order; the fog box at its smaller --check film."""
    names = {t.measure: t for t in bench.targets()}
    assert names["efficiency_vs_mitsuba_best"].scenes == bench.CANONICAL_SCENES
    assert bench.best_sampler_scenes() == set(bench.CANONICAL_SCENES)
    assert names["efficiency_vs_llvm_ad_rgb_ldsampler"].scenes == ("cornell-box", "soft-shadows", "multi-light")
    assert names["paths_per_second_vs_llvm_ad_rgb"].minimum == 0.8
    assert names[fresh_race.RATIO].scenes == ("soft-shadows",) and bench.fresh_scenes() == {"soft-shadows"}
    assert bench.target_scenes() == list(bench.CANONICAL_SCENES)
    assert bench.CHECK_FILMS == {"fog-box": (64, 64)}
    for name in bench.CANONICAL_SCENES:  # every canonical scene is a scene file
        assert (bench.ROOT / "scenes" / f"{name}.toml").is_file()


def test_the_fresh_race_is_in_the_json_and_the_text(monkeypatch, capsys, tmp_path):
    """``harness bench --fresh``: every scene benched gets ``fresh`` in its JSON block and its lines in the text
    (processes faked); without --fresh none."""
    from harness.cli import main
    from harness.renderers.groundtruth import GroundTruth

    def fake_bench_scene(scene, contenders, *, spp, repeats, gt, seed=1, on_render=None, between=None):
        return [bench.Row(scene.name, c.label, c.renderer, dict(c.settings), spp, scene.film.width, scene.film.height,
                          seconds=1.0, seconds_all=[1.0], paths_per_second=1.0, cores_busy=1.0, mse=1.0,
                          efficiency=1.0) for c in contenders]

    monkeypatch.setattr(bench, "bench_scene", fake_bench_scene)
    monkeypatch.setattr(bench, "ground_truth", lambda scene, **kw: GroundTruth(
        np.zeros((scene.film.height, scene.film.width, 3)), None, "closed-form", 0))
    calls: list = []
    monkeypatch.setattr(fresh_race, "run_once", _fake_run({fresh_race.REFERENCE: [0.1] * 3,
                                                           fresh_race.MITSUBA: [0.05] * 3}, calls))
    assert main(["bench", "--scene", "furnace", "--spp", "4", "--repeats", "2", "--no-strategies", "--quiet",
                 "--no-embree-rate", "--fresh", "--json"]) == 0
    block = json.loads(capsys.readouterr().out)["scenes"]["furnace"]
    assert block["fresh"]["ratios"][fresh_race.RATIO] == pytest.approx(0.5) and len(calls) == 6
    monkeypatch.setattr(fresh_race, "run_once", _fake_run({fresh_race.REFERENCE: [0.1] * 2,
                                                           fresh_race.MITSUBA: [0.05] * 2}, calls))
    assert main(["bench", "--scene", "furnace", "--spp", "4", "--repeats", "1", "--no-strategies", "--quiet",
                 "--no-embree-rate", "--fresh"]) == 0  # the text
    assert "fresh processes (harness render, 4 spp" in capsys.readouterr().out
    assert main(["bench", "--scene", "furnace", "--spp", "4", "--repeats", "1", "--no-strategies", "--quiet",
                 "--no-embree-rate", "--json"]) == 0
    assert "fresh" not in json.loads(capsys.readouterr().out)["scenes"]["furnace"]
    assert main(["bench", "--scaling", "--fresh", "--quiet"]) == 2  # the race's option
    assert "--fresh" in capsys.readouterr().err
