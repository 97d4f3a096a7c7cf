"""``harness bench``'s Embree row and its targets: the recorded rays are the render's, their replay gives the recorded
answers at a positive rate, and ``--check`` exits 1 exactly when a target is not met (on fake rows: no real race).

Rates are measurements, not tests (docs/performance.md); these tests check the counts, the answers and the shape."""

from __future__ import annotations

import json
import math
import os
import re
import shlex

import numpy as np
import pytest
from conftest import load_small, render_reference

from harness.cli import main
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.groundtruth import GroundTruth
from harness.scene import emitter_arrays, material_arrays, triangulate
from harness.studies import bench, embree_rate, fresh_race
from reference_impl import replay

pytestmark = pytest.mark.slow  # renders: outside the inner loop (pytest -m "not slow")


def _record(scene, spp, max_rays=10**9, **extra):
    request = RenderRequest(spp=spp, seed=3, settings={k: str(v) for k, v in extra.items()})
    settings = get_renderer("reference").settings_for(scene, request)
    return replay.record_rays(triangulate(scene), scene.camera, scene.film, settings, emitter_arrays(scene),
                              material_arrays(scene), max_rays=max_rays)


@pytest.mark.parametrize("name, room, settings, packets", [
    ("cornell-box", None, {}, True), ("cornell-box", 0, {}, True), ("cornell-box-specular", 0, {}, True),
    ("veach-mis", None, {}, True), ("soft-shadows", None, {"direct": "hemisphere-cosine"}, False)])
def test_the_recorded_rays_are_the_renders_and_replay_to_the_same_hits(name, room, settings, packets, monkeypatch):
    """The whole film recorded: as many camera, closest-hit and occlusion queries as the render's counters say (the
    scenes the blocks trace, kernels/blocks.py and kernels/path_blocks.py, through their record, with the size of
    each call that sent rays in packets, so that the replay sends the same packets; hemisphere sampling through the
    path loop's, one query per ray; with no room at first, every batch is traced again with room for its queries;
    veach-mis, whose shadow rays end just short of spherical lights: the sphere tests see the float64 rays the
    render asked, not float32 copies); replayed on 1 and 2 threads, every answer equals the recorded one, at a
    positive rate."""
    if room is not None:
        monkeypatch.setattr(replay, "ROOM_PER_PATH", room)
    scene = load_small(name, 12)
    log = _record(scene, 4, **settings)
    stats = render_reference(scene, 4, seed=3, **settings).stats
    assert log.packets == packets
    if packets:  # every recorded ray in exactly one call, each call of 1 .. 4096 x Nd rays
        for groups, phase in ((log.closest_groups, log.closest), (log.occlusion_groups, log.occlusion)):
            assert [int(g.sum()) for g in groups] == [len(e[0]) for e in phase]
            assert all(np.all((g >= 1) & (g <= 4096)) for g in groups)
        assert sum(len(g) for g in log.closest_groups) < log.count("closest") / 8  # packets, not single rays
    else:
        assert log.closest_groups == log.occlusion_groups == []
    assert log.paths == 12 * 12 * 4
    assert log.count("camera") == stats["camera_rays"] == log.paths
    assert log.count("closest") == stats["indirect_rays"] + stats["hemisphere_direct_rays"] > 0
    assert log.count("occlusion") == stats["shadow_rays"]
    assert any(np.any(e[2] < 0) for e in log.closest) or any(np.any(e[2] < 0) for e in log.camera)  # misses too
    if "direct" not in settings:  # (hemisphere sampling's direct light: no shadow ray)
        assert any(np.any(e[3] == 1) for e in log.occlusion) and any(np.any(e[3] == 0) for e in log.occlusion)
    for threads in (1, 2):
        out = replay.replay_rays(log, threads=threads, repeats=1)
        assert out["mismatches"] == {"camera": 0, "closest": 0, "occlusion": 0}
        assert out["rays"] == {phase: log.count(phase) for phase in replay.PHASES}
        assert out["threads"] == threads
        for key in ("closest_hit_rays_per_second", "occlusion_rays_per_second", "rays_per_second"):
            if key != "occlusion_rays_per_second" or log.count("occlusion"):
                assert out[key] > 0 and math.isfinite(out[key])
        total = sum(out["rays"].values()) / sum(out["seconds"].values())
        assert out["rays_per_second"] == pytest.approx(total)


def test_a_changed_answer_is_found(monkeypatch):
    """The check can fail: one recorded hit changed is one mismatch, and the bench row is skipped, saying so."""
    record = replay.record_rays

    def changed(*args, **kwargs):
        log = record(*args, **kwargs)
        log.closest[0][2][0] = 10**6  # no such primitive
        return log

    monkeypatch.setattr(replay, "record_rays", changed)
    rate = embree_rate.EmbreeRate(load_small("cornell-box", 8), spp=2)
    rate.warm_up()
    out = rate.result(1e6)
    assert out["mismatches"] == {"camera": 0, "closest": 1, "occlusion": 0} and "closest 1" in out["error"]
    assert "skipped: the replay's answers differ" in bench.format_table([], out)


def test_recording_stops_near_its_budget():
    """Runs of whole pixels (all their samples) until max_rays are recorded: past the budget by less than one batch
    (here 12 pixels x 16 samples, at most 1 + 2 x max_depth = 17 queries a path), far fewer than the film's paths."""
    scene = load_small("cornell-box", 64)
    budget = 64 * 200  # batches of max(16, min(batch_size, budget // 64)) // 16 = 12 pixels
    log = _record(scene, 16, max_rays=budget)
    assert budget <= log.rays < budget + 12 * 16 * 17
    assert log.paths % (12 * 16) == 0 and log.paths < 64 * 64 * 16 // 4


def _fake_rows(values: dict[str, tuple[float, float, float]]):
    """A bench_scene that returns a row per contender with (efficiency, paths per second, cores) from ``values``
    (by label; missing: 1, 1, 1) and calls ``between`` as the real one does."""

    def fake(scene, contenders, *, spp, repeats, gt, seed=1, on_render=None, between=None):
        rows = []
        for c in contenders:
            eff, pps, cores = values.get(c.label, (1.0, 1.0, 1.0))
            rows.append(bench.Row(scene.name, c.label, c.renderer, dict(c.settings), spp, scene.film.width,
                                  scene.film.height, seconds=1.0, seconds_all=[1.0] * repeats,
                                  paths_per_second=pps, rays_per_second=5e6 if c.renderer == "reference" else None,
                                  rays_per_path=5e6 / pps if c.renderer == "reference" else None, cores_busy=cores,
                                  mse=1.0 / eff, efficiency=eff))
        for attempt in range(repeats + 1):
            if between is not None:
                between(attempt)
        return rows

    return fake


class _FakeRate:
    """An EmbreeRate without a recording: the reference's fraction of Embree's rate is ``FRACTION`` (its point
    value: no per-round replays, so no interval), and a scene with media is refused as the real one refuses it."""

    FRACTION = 0.8

    def __init__(self, scene, *, spp, max_rays):
        if scene.has_media:
            raise bench.HarnessError(str(scene.path), "the Embree rate replays the rays of the surface path loop")

    def warm_up(self):
        pass

    def measure(self):
        pass

    def result(self, reference_rays_per_second):
        rays = {"camera": 1, "closest": 1, "occlusion": 1}
        return {"label": embree_rate.LABEL, "error": None, "rays": rays, "seconds": dict.fromkeys(rays, 0.1),
                "recorded_rays": 3, "recorded_paths": 1, "rays_per_path": 3.0, "replays": 0, "threads": 2,
                "closest_hit_rays_per_second": 1.0, "occlusion_rays_per_second": 1.0, "rays_per_second": 1.0,
                "cores_busy": 1.0, "seconds_all": [], "reference_fraction": self.FRACTION}


def _fake_fresh(monkeypatch, reference=0.1, mitsuba=0.08):
    """Fresh processes that report ``reference`` and ``mitsuba`` render seconds (harness.studies.fresh_race)."""

    def run(argv):
        seconds = mitsuba if "mitsuba" in argv else reference
        return {"seconds": seconds, "load_seconds": None, "wall_seconds": seconds + 1, "startup_seconds": 1.0}

    monkeypatch.setattr(fresh_race, "run_once", run)


def _fake_race(monkeypatch, values, *, rate=False):
    """The race's renders faked (``values``), and with ``rate`` the Embree row and the fresh processes too."""
    monkeypatch.setattr(bench, "bench_scene", _fake_rows(values))
    if rate:
        monkeypatch.setattr(embree_rate, "EmbreeRate", _FakeRate)
        _fake_fresh(monkeypatch)
    # an idle machine, whatever the test run's own load (a busy one certifies nothing: test_bench.py)
    monkeypatch.setattr(bench, "machine_state", lambda: {"load_average": [0.0, 0.0, 0.0], "cpu_count": 2,
                                                          "governors": None})
    monkeypatch.setattr(bench, "ground_truth", lambda scene, **kw: GroundTruth(
        np.zeros((scene.film.height, scene.film.width, 3)), None, "closed-form", 0))


def _all_met(cpus):
    good = (10.0, 10.0, float(cpus))
    return {"reference": good, "mitsuba llvm_ad_rgb ldsampler": (1.0, 1.0, 1.0)}


def test_check_exits_1_with_a_target_not_met_and_0_when_all_are_met(monkeypatch, capsys):
    """``--check`` races the eight target scenes (from the default three: veach-mis, cornell-box-specular,
    textured-cornell-box, lamp-grid and fog-box added, with the extra Mitsuba samplers on all; fog-box at its --check
    film), soft-shadows in fresh processes too, prints each target as ``target NAME on SCENE >= X: VALUE (met|NOT
    met)`` and exits 1 when one is not met (the faked rows hold no rounds: their point ratios decide; the lower
    bound's rule is test_bench.py's). Without the Embree row its targets are not measured, so not met."""
    cpus = os.cpu_count() or 1
    check = ["bench", "--check", "--quiet", "--no-strategies", "--repeats", "5"]
    _fake_race(monkeypatch, _all_met(cpus), rate=True)
    assert main(check) == 0
    text = capsys.readouterr().out
    lines = [line for line in text.splitlines() if line.startswith("target ")]
    assert len(lines) == 3 + 8 + 1 + 1 + 7 + 1 and all(line.endswith("(met)") for line in lines), lines
    assert "target efficiency_vs_mitsuba_best on veach-mis >= 1.00: 10.00 (met)" in lines
    assert "target efficiency_vs_mitsuba_best on fog-box >= 1.00: 10.00 (met)" in lines
    assert "target embree_fraction on lamp-grid >= 0.60: 0.80 (met)" in lines
    assert not any("embree_fraction on fog-box" in line for line in lines)
    assert any(line.startswith("target fresh_seconds_vs_llvm_ad_rgb on soft-shadows >= 0.50: 0.80 [")
               and line.endswith("(met)") for line in lines), lines
    assert f"target cores_busy on cornell-box >= {0.9 * cpus:.2f}: {cpus:.2f} (met)" in lines
    assert "mitsuba llvm_ad_rgb stratified" in text and "mitsuba llvm_ad_rgb multijitter" in text
    assert "fog-box: 64x64 (--check's film for it)" in text and "fresh processes (harness render, 64 spp" in text

    # the best sampler beats the reference (multijitter: efficiency 20 > 10), raced on every canonical scene
    _fake_race(monkeypatch, _all_met(cpus) | {"mitsuba llvm_ad_rgb multijitter": (20.0, 1.0, 1.0)}, rate=True)
    assert main(check) == 1
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("target ")]
    assert "target efficiency_vs_mitsuba_best on cornell-box-specular >= 1.00: 0.50 (NOT met)" in lines
    assert sum(line.endswith("(NOT met)") for line in lines) == 8  # on every scene

    # Mitsuba's fresh render 4x faster: the fresh target alone is not met
    _fake_race(monkeypatch, _all_met(cpus), rate=True)
    _fake_fresh(monkeypatch, reference=0.1, mitsuba=0.025)
    assert main(check) == 1
    lines = [line for line in capsys.readouterr().out.splitlines() if line.endswith("(NOT met)")]
    assert len(lines) == 1 and lines[0].startswith("target fresh_seconds_vs_llvm_ad_rgb on soft-shadows"), lines

    # the reference at half of Embree's rate: the Embree targets alone are not met
    _fake_race(monkeypatch, _all_met(cpus), rate=True)
    monkeypatch.setattr(_FakeRate, "FRACTION", 0.5)
    assert main(check) == 1
    lines = [line for line in capsys.readouterr().out.splitlines() if line.endswith("(NOT met)")]
    assert len(lines) == 7 and all(line.startswith("target embree_fraction on ") for line in lines), lines
    monkeypatch.undo()

    # both cores not busy: the cores target alone is not met; --no-embree-rate: its targets not measured
    _fake_race(monkeypatch, _all_met(cpus) | {"reference": (10.0, 10.0, 0.5 * cpus)}, rate=True)
    assert main(check + ["--scene", "cornell-box"]) == 1
    lines = [line for line in capsys.readouterr().out.splitlines() if line.endswith("(NOT met)")]
    assert lines == [f"target cores_busy on cornell-box >= {0.9 * cpus:.2f}: {0.5 * cpus:.2f} (NOT met)"]
    assert main(check + ["--no-embree-rate"]) == 1
    lines = [line for line in capsys.readouterr().out.splitlines() if line.endswith("(NOT met)")]
    assert len(lines) == 1 + 7 and all("not measured" in line for line in lines[1:]), lines


def test_the_json_holds_the_embree_rate_and_the_targets(monkeypatch, capsys, tmp_path):
    """``scenes.<scene>.embree_rate`` (a real recording and replay of a small Cornell box, the renders faked) and
    ``targets``: one entry per target and scene benched, with the old keys (ratio, minimum, measured, met)."""
    _fake_race(monkeypatch, {})
    small = tmp_path / "small.toml"
    text = (bench.ROOT / "scenes" / "cornell-box.toml").read_text().replace("width = 256", "width = 16")
    small.write_text(text.replace("height = 256", "height = 16"))
    assert main(["bench", "--scene", str(small), "--spp", "4", "--repeats", "2", "--no-strategies", "--quiet",
                 "--json", "--allow-outside-paths"]) == 0
    result = json.loads(capsys.readouterr().out)
    block = result["scenes"]["cornell-box"]
    rate = block["embree_rate"]
    assert rate["label"] == "embree (own rays)" and rate["error"] is None and rate["replays"] == 2
    assert rate["recorded_paths"] == 16 * 16 * 4 and rate["recorded_rays"] == sum(rate["rays"].values())
    assert set(rate["rays"]) == set(rate["seconds"]) == {"camera", "closest", "occlusion"}
    assert rate["mismatches"] == {"camera": 0, "closest": 0, "occlusion": 0}
    assert rate["rays_per_second"] > 0 and rate["reference_rays_per_second"] == 5e6
    assert rate["reference_fraction"] == pytest.approx(5e6 / rate["rays_per_second"])
    targets = result["targets"]
    assert [(t["name"], t["scene"]) for t in targets] == [
        ("efficiency_vs_llvm_ad_rgb_ldsampler", "cornell-box"), ("efficiency_vs_mitsuba_best", "cornell-box"),
        ("paths_per_second_vs_llvm_ad_rgb", "cornell-box"), ("cores_busy", "cornell-box"),
        ("embree_fraction", "cornell-box")]
    # two replays paired with two rounds of the reference: the fraction's interval (test_bench_fresh.py's rule)
    assert len(rate["seconds_all"]) == 2 and rate["fraction_interval"]["low"] is not None
    assert all(set(t) >= {"ratio", "minimum", "measured", "met"} for t in targets)
    assert block["mitsuba_best"] is not None and "efficiency_vs_mitsuba_best" in block["ratios"]
    assert main(["bench", "--scene", str(small), "--spp", "4", "--repeats", "1", "--no-strategies", "--quiet",
                 "--json", "--allow-outside-paths", "--no-embree-rate"]) == 0
    assert "embree_rate" not in json.loads(capsys.readouterr().out)["scenes"]["cornell-box"]


def test_check_races_the_heavy_tailed_scenes_in_more_rounds(monkeypatch, capsys, tmp_path):
    """``--check`` races veach-mis and lamp-grid in at least CHECK_ROUNDS' rounds (their MSE per round is
    heavy-tailed), every other scene in ``--repeats``; a larger ``--repeats`` wins; without ``--check`` every scene
    takes ``--repeats``. The scene's block and its lines say its own number of rounds."""
    cpus = os.cpu_count() or 1
    seen: dict[str, int] = {}
    fake = _fake_rows(_all_met(cpus))

    def counting(scene, contenders, *, repeats, **kw):
        seen[scene.name] = repeats
        return fake(scene, contenders, repeats=repeats, **kw)

    _fake_race(monkeypatch, _all_met(cpus), rate=True)
    monkeypatch.setattr(bench, "bench_scene", counting)
    out = tmp_path / "check.json"
    assert main(["bench", "--check", "--quiet", "--no-strategies", "--repeats", "5", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert seen == {name: bench.CHECK_ROUNDS.get(name, 5) for name in bench.CANONICAL_SCENES}, seen
    assert seen["veach-mis"] == seen["lamp-grid"] == 20 and seen["cornell-box"] == 5
    assert "veach-mis: 64x64, 64 spp, median of 20 timed renders" in text
    assert "cornell-box: 256x256, 64 spp, median of 5 timed renders" in text
    blocks = json.loads(out.read_text())["scenes"]
    assert blocks["lamp-grid"]["repeats"] == 20 and "repeats" not in blocks["cornell-box"]

    seen.clear()
    assert main(["bench", "--check", "--quiet", "--no-strategies", "--repeats", "30"]) == 0
    capsys.readouterr()
    assert set(seen.values()) == {30}

    seen.clear()
    assert main(["bench", "--scene", "veach-mis", "--quiet", "--no-strategies", "--repeats", "2",
                 "--no-embree-rate"]) == 0
    capsys.readouterr()
    assert seen == {"veach-mis": 2}


def _doc_bench_commands() -> dict[str, str]:
    """Every ``harness bench`` command the README and docs/ print, as {command: the file that prints it first}: the
    lines of their code blocks (comments cut) and the commands quoted inline (a quote may wrap), whitespace joined.
    Left out: ``--scaling`` (test_scaling.py runs those) and the README's synopsis, whose brackets are not a
    command."""
    root = bench.ROOT
    commands: dict[str, str] = {}
    for path in sorted((root / "docs").glob("*.md")) + [root / "README.md"]:
        text = path.read_text()
        for block in re.findall(r"```[a-z]*\n(.*?)```", text, re.S):
            for line in block.splitlines():
                if line.startswith("harness bench"):
                    commands.setdefault(" ".join(line.split("#", 1)[0].split()), path.name)
        for quoted in re.findall(r"`(harness bench[^`]*)`", re.sub(r"```.*?```", "", text, flags=re.S)):
            commands.setdefault(" ".join(quoted.split()), path.name)
    return {c: f for c, f in commands.items() if "--scaling" not in c and "[" not in c}


def test_every_bench_command_the_docs_print_runs_as_printed(monkeypatch, tmp_path, capsys):
    """Each command of :func:`_doc_bench_commands` runs as printed and exits 0: its renders, the strategy rows'
    equal-time renders, the Embree replays, the fresh processes and the child process of ``--memory`` faked, every
    target met, the other renderers (cycles, a renderer file) raced as faked rows like the rest. The list holds the
    ones the docs quote, from docs/performance.md's code block and its sections and from the other docs."""
    commands = _doc_bench_commands()
    for printed in ("harness bench --check --out bench.json", "harness bench --check",
                    "harness bench --scene soft-shadows --repeats 2 --no-strategies --fresh", "harness bench",
                    "harness bench --memory 1024x256 --out bench.json", "harness bench --scene furnace --spp 16 --json",
                    "harness bench --no-embree-rate", "harness bench --renderer cycles --no-strategies",
                    "harness bench --scene veach-mis --scene lamp-grid --repeats 20 --no-strategies",
                    "harness bench --no-strategies --no-embree-rate --scene soft-shadows --scene cornell-box "
                    "--scene multi-light"):
        assert printed in commands, printed
    monkeypatch.chdir(tmp_path)
    memory = []

    def fake_memory(scene_path, size, spp):
        memory.append((size, spp))
        return {"scene": str(scene_path), "width": size, "height": size, "spp": spp, "peak_rss_mib": 512.0,
                "seconds": 1.0, "wall_seconds": 2.0, "paths_per_second": 1e6}

    for command, doc in commands.items():
        _fake_race(monkeypatch, _all_met(os.cpu_count() or 1), rate=True)
        monkeypatch.setattr(bench, "equal_time_renders", lambda *args, **kwargs: None)
        monkeypatch.setattr(bench, "peak_memory", fake_memory)
        assert main(shlex.split(command)[1:]) == 0, f"{doc}: {command}"
        capsys.readouterr()
    assert (1024, 256) in memory
