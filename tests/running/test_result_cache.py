"""The results cache of ``harness run`` (harness/running/result_cache.py, harness/files/entries.py,
harness/studies/study_cache.py): a second run is answered from it with the same results and the same files, bit
for bit; every input of a case's key misses when it changes; time budgets, external renderers and damaged entries
are never served. Every test has its own cache folder (the conftest turns the results cache off elsewhere)."""

from __future__ import annotations

import hashlib
import json
import shutil
import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from fake_renderers import slow_start_renderer

from harness.cli import main
from harness.files.entries import ENTRY_FILE, FILES, EntryStore
from harness.judges.moments import Estimate
from harness.renderers import groundtruth
from harness.renderers.reference import ReferenceRenderer
from harness.running import result_cache
from harness.running.cases import Case, load_suite
from harness.running.schedule import run_suite
from harness.studies.study_cache import cached_suite_studies, studies_key
from harness.studies.suite_studies import StudyOptions

FURNACE = ROOT / "scenes" / "furnace.toml"
#: two tiny cases: the furnace's closed form, and another renderer's seeded render as the ground truth
SUITE = """
[defaults]
spp = 4
film = {{ width = 8, height = 8 }}

[[cases]]
name = "furnace/closed-form"
scene = "{scene}"
seed = {seed}
settings = {settings}

[[cases]]
name = "furnace/against-reference"
scene = "{scene}"
against = {{ renderer = "reference", spp = 8, seed = 3 }}
"""
#: what differs between two runs of the same cases: timings, this run's bookkeeping, the output folder
RUN_KEYS = {"wall_seconds", "seconds", "paths_per_second", "cached", "cache_key", "definition"}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.delenv(result_cache.ENV, raising=False)
    return tmp_path / "cache"


def write_suite(tmp_path: Path, *, seed: int = 0, settings: str = "{}", scene: Path = FURNACE) -> Path:
    path = tmp_path / "suite.toml"
    path.write_text(SUITE.format(scene=scene, seed=seed, settings=settings))
    return path


def run(suite_path: Path, out: Path, cache: Path, mode: str = "use") -> dict:
    return run_suite(load_suite(suite_path), out, cache_dir=cache, results_cache=mode)


def comparable(value, out: Path):
    if isinstance(value, dict):
        return {k: comparable(v, out) for k, v in value.items() if k not in RUN_KEYS}
    if isinstance(value, list):
        return [comparable(v, out) for v in value]
    return value.replace(str(out), "OUT") if isinstance(value, str) else value


def case_files(out: Path) -> dict[str, str]:
    return {p.relative_to(out).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted((out / "cases").rglob("*")) if p.is_file()}


def test_a_second_run_is_answered_from_the_cache_with_the_same_results_and_files(tmp_path, cache, monkeypatch):
    suite = write_suite(tmp_path)
    first = run(suite, tmp_path / "a", cache)
    assert first["summary"]["from_cache"] == 0 and all(isinstance(c["cache_key"], str) for c in first["cases"])

    def no_render(self, scene, request):
        raise AssertionError("a cached case rendered")

    monkeypatch.setattr(ReferenceRenderer, "render", no_render)
    second = run(suite, tmp_path / "b", cache)
    assert second["summary"]["from_cache"] == 2
    assert [c["cached"]["from"] for c in second["cases"]] == [first["started"]] * 2
    assert [c["cache_key"] for c in second["cases"]] == [c["cache_key"] for c in first["cases"]]
    assert comparable(second["cases"], tmp_path / "b") == comparable(first["cases"], tmp_path / "a")
    assert case_files(tmp_path / "b") == case_files(tmp_path / "a")
    on_disk = json.loads((tmp_path / "b" / "results.json").read_text())
    assert Path(on_disk["cases"][0]["render"]["exr"]).parent == tmp_path / "b" / "cases" / "furnace_closed-form"
    assert Path(on_disk["cases"][1]["ground_truth"]["path"]).is_relative_to(tmp_path / "b")


@pytest.mark.parametrize("change", ["scene", "setting", "seed", "code"])
def test_a_changed_input_misses(tmp_path, cache, monkeypatch, change):
    scene = tmp_path / "furnace.toml"
    shutil.copy(FURNACE, scene)
    run(write_suite(tmp_path, scene=scene), tmp_path / "a", cache)
    seed, settings = 0, "{}"
    if change == "scene":
        scene.write_text(scene.read_text().replace("[0.3, 0.5, 0.7]", "[0.3, 0.5, 0.6]"))
    elif change == "setting":
        settings = '{ rr = "fixed" }'
    elif change == "seed":
        seed = 1
    else:
        monkeypatch.setattr(result_cache, "code_digest", lambda: "an edited harness")
    second = run(write_suite(tmp_path, scene=scene, seed=seed, settings=settings), tmp_path / "b", cache)
    hits = [bool(c.get("cached")) for c in second["cases"]]
    # the scene and the code are every case's; the seed and the settings only the first's
    assert hits == ([False, False] if change in ("scene", "code") else [False, True])


def test_fresh_renders_again_and_replaces_the_entries(tmp_path, cache, monkeypatch):
    suite = write_suite(tmp_path)
    first = run(suite, tmp_path / "a", cache)
    assert result_cache.mode(fresh=True) == "refresh" and result_cache.mode() == "use"
    assert result_cache.mode(no_cache=True) == "off"
    monkeypatch.setenv(result_cache.ENV, "off")
    assert result_cache.mode() == "off"
    monkeypatch.delenv(result_cache.ENV)
    again = run(suite, tmp_path / "b", cache, mode="refresh")
    assert again["summary"]["from_cache"] == 0
    assert comparable(again["cases"], tmp_path / "b") == comparable(first["cases"], tmp_path / "a")
    third = run(suite, tmp_path / "c", cache)
    assert [c["cached"]["from"] for c in third["cases"]] == [again["started"]] * 2  # the refreshed entries
    off = run(suite, tmp_path / "d", cache, mode="off")
    assert off["summary"]["from_cache"] == 0 and not any("cache_key" in c for c in off["cases"])


def test_the_command_line_says_how_many_came_from_the_cache(tmp_path, cache, capsys):
    suite = write_suite(tmp_path)
    common = ["--cache-dir", str(cache), "--executor", "serial", "--no-report", "--quiet"]
    assert main(["run", str(suite), "--out", str(tmp_path / "a"), *common]) == 0
    assert "; 0 cases from the cache;" in capsys.readouterr().out
    assert main(["run", str(suite), "--out", str(tmp_path / "b"), *common]) == 0
    assert "; 0 Mitsuba renders; 2 cases from the cache;" in capsys.readouterr().out
    assert main(["run", str(suite), "--out", str(tmp_path / "b"), "--fresh", *common]) == 0
    assert "; 0 cases from the cache;" in capsys.readouterr().out
    assert main(["run", str(suite), "--out", str(tmp_path / "c"), "--no-cache", *common]) == 0
    assert "; 0 cases from the cache;" in capsys.readouterr().out


def test_time_budgets_and_external_renderers_are_never_cached(tmp_path, cache):
    # it reports its render time: no 1-spp runs to measure its start-up (the timing is not what is tested here)
    renderer = slow_start_renderer(tmp_path, startup=0.0, per_spp=0.0, noise=0.01, repeats=2, own_time=True)
    suite = tmp_path / "suite.toml"
    suite.write_text(f"""
[defaults]
film = {{ width = 8, height = 8 }}

[[cases]]
name = "seconds"
scene = "{FURNACE}"
seconds = 0.05
chunk_spp = 1

[[cases]]
name = "external"
scene = "{FURNACE}"
renderer = "{renderer}"
spp = 4
max_depth = 2

[[cases]]
name = "against-external"
scene = "{FURNACE}"
spp = 4
max_depth = 2
against = {{ renderer = "{renderer}", spp = 4 }}
""")
    for out in ("a", "b"):
        results = run(suite, tmp_path / out, cache)
        assert [c["status"] for c in results["cases"]] != ["error"] * 3
        assert results["summary"]["from_cache"] == 0 and not any("cache_key" in c for c in results["cases"])
    assert not (cache / result_cache.FOLDER).exists() or not any((cache / result_cache.FOLDER).iterdir())
    cases = load_suite(suite).cases
    assert all(result_cache.not_cacheable(c) for c in cases)
    assert result_cache.not_cacheable(Case("m", FURNACE, renderer="mitsuba", settings={"sampler": "stratified"}))


@pytest.mark.parametrize("damage", ["file", "entry.json", "truncated", "missing file"])
def test_a_damaged_entry_is_a_miss_and_is_rendered_again(tmp_path, cache, damage):
    suite = write_suite(tmp_path)
    first = run(suite, tmp_path / "a", cache)
    folder = cache / result_cache.FOLDER / first["cases"][0]["cache_key"]
    render = folder / FILES / "render.exr"
    if damage == "file":
        data = bytearray(render.read_bytes())
        data[len(data) // 2] ^= 0xFF
        render.write_bytes(bytes(data))
    elif damage == "entry.json":
        doc = json.loads((folder / ENTRY_FILE).read_text())
        doc["meta"]["record"]["ok"] = not doc["meta"]["record"]["ok"]  # an edit: its checksum no longer holds
        (folder / ENTRY_FILE).write_text(json.dumps(doc))
    elif damage == "truncated":
        (folder / ENTRY_FILE).write_text((folder / ENTRY_FILE).read_text()[:50])
    else:
        render.unlink()
    second = run(suite, tmp_path / "b", cache)
    assert [bool(c.get("cached")) for c in second["cases"]] == [False, True]
    assert comparable(second["cases"], tmp_path / "b") == comparable(first["cases"], tmp_path / "a")
    assert case_files(tmp_path / "b") == case_files(tmp_path / "a")
    third = run(suite, tmp_path / "c", cache)  # the damaged entry was replaced by the second run's
    assert third["summary"]["from_cache"] == 2


def test_a_mitsuba_ground_truth_is_in_the_key_by_its_content(tmp_path, cache):
    """No ground-truth entry, no key (the case renders it); an entry of other pixels under the same ground-truth
    key (a Mitsuba render that did not reproduce) is another case key."""
    case = Case("c", ROOT / "scenes" / "cornell-box.toml", spp=4, film={"width": 8, "height": 8},
                ground_truth_spp=16)
    keys = result_cache.CaseCache(cache)
    assert keys.key(case) is None
    scene = result_cache.judge.case_scene(case, for_ground_truth=True)
    gt_key = groundtruth.entry_key(scene, spp=16)
    found = []
    for value in (0.5, 0.25):
        shutil.rmtree(groundtruth.Cache(cache).entry(gt_key), ignore_errors=True)
        image = np.full((8, 8, 3), value)
        groundtruth.Cache(cache).store(gt_key, Estimate(image, image * 0.01, 16), {"spp": 16})
        found.append(keys.key(case))
    assert None not in found and found[0].key != found[1].key
    assert found[0].ground_truth_path == str(groundtruth.Cache(cache).entry(gt_key) / "image.exr")


def test_concurrent_stores_of_one_key_leave_one_valid_entry(tmp_path):
    store = EntryStore(tmp_path / "results")
    sources = []
    for i in range(8):
        source = tmp_path / f"file-{i}"
        source.write_bytes(b"same bytes " * 1000)
        sources.append(source)
    threads = [threading.Thread(target=store.store, args=("k", {"n": i}, {"a/b.bin": sources[i]}),
                                kwargs={"replace": i % 2 == 0}) for i in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    entry = store.load("k")
    assert entry is not None and store.read_files(entry) == {"a/b.bin": b"same bytes " * 1000}
    assert sorted(p.name for p in (tmp_path / "results").iterdir()) == ["k"]  # no temporary folder left
    assert store.load("absent") is None


def test_studies_come_from_the_cache_and_say_when_they_were_measured(tmp_path, cache):
    suite = write_suite(tmp_path)
    results = run(suite, tmp_path / "a", cache)
    options = StudyOptions(convergence=True, convergence_spp=(1, 2), convergence_strategies=(),
                           glossy_convergence_strategies=(), convergence_mitsuba=False, shadow_rays=False,
                           strategies=False, min_timing_seconds=0.0, cache_dir=str(cache))
    first = cached_suite_studies(results, tmp_path / "a", options, results_file=tmp_path / "a" / "results.json")
    assert first["key"] is not None and "cached" not in first
    second_results = run(suite, tmp_path / "b", cache)
    second = cached_suite_studies(second_results, tmp_path / "b", options,
                                  results_file=tmp_path / "b" / "results.json")
    assert second["cached"]["from"] == results["started"] and second["key"] == first["key"]
    doc = json.loads((tmp_path / "b" / "studies" / "studies.json").read_text())
    assert doc["cached"]["from"] == results["started"] and f"measured {results['started']}, cached" in doc["note"]
    assert doc["started"] == second_results["started"]
    before = json.loads((tmp_path / "a" / "studies" / "studies.json").read_text())
    assert doc["convergence"] == before["convergence"]

    def files(out):
        return {p.relative_to(out).as_posix(): p.read_bytes() for p in (out / "studies").rglob("*")
                if p.is_file() and p.name != "studies.json"}

    assert files(tmp_path / "b") == files(tmp_path / "a") and files(tmp_path / "a")
    fresh = cached_suite_studies(second_results, tmp_path / "b", options, mode="refresh")
    assert "cached" not in fresh
    other = StudyOptions(**{**options.__dict__, "convergence_spp": (1, 4)})
    assert studies_key(second_results, other) != first["key"]
    keyless = dict(second_results, cases=[dict(second_results["cases"][0], cache_key=None)])
    assert studies_key(keyless, options) is None


def test_concurrent_runs_share_the_cache_without_damage(tmp_path, cache):
    suite = write_suite(tmp_path)
    outcomes = {}

    def one(name, mode):
        outcomes[name] = run(suite, tmp_path / name, cache, mode)

    threads = [threading.Thread(target=one, args=(f"run{i}", "refresh" if i % 2 else "use")) for i in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(outcomes) == 4
    last = run(suite, tmp_path / "last", cache)
    assert last["summary"]["from_cache"] == 2
    for name, results in outcomes.items():
        assert comparable(results["cases"], tmp_path / name) == comparable(last["cases"], tmp_path / "last")
        assert case_files(tmp_path / name) == case_files(tmp_path / "last")
    leftovers = [p.name for p in (cache / result_cache.FOLDER).iterdir() if p.name.startswith(".")]
    assert leftovers == []
