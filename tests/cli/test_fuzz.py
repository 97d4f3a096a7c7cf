"""The fuzzer of tests/cli/fuzz.py (docs/robustness.md, "Fuzzing"): its verdicts on planted outcomes, a few real
loader inputs, replaying a saved failure; bugs it found, fixed; and, under HARNESS_FUZZ=long, the long run itself
(10,000 inputs through every loader and command)."""

from __future__ import annotations

import json
import math
import os
import random
import signal
import subprocess
import sys
import time
import tomllib
from collections import Counter
from pathlib import Path

import pytest
from conftest import FUZZ_LONG, ROOT

import fuzz
from tomltext import to_toml
from harness import cli
from harness.running import baseline
from harness.core.errors import HarnessError
from harness.running.cases import load_suite
from harness.running.executors import make_executor
from harness.scene import load_scene

FURNACE = ROOT / "scenes" / "furnace.toml"


def planted_main(argv: list[str]) -> int:
    """Stands in for harness.cli.main in the children: each first argument plants one outcome."""
    what = argv[0]
    if what == "ok":
        print("done")
        return 0
    if what == "verdict-fail":
        return 1
    if what == "error":
        print("harness: error: x.toml: spp: expected a positive integer", file=sys.stderr)
        return 2
    if what == "messy":
        print("harness: error: first line\nsecond line", file=sys.stderr)
        return 2
    if what == "printed-traceback":
        print("Traceback (most recent call last):\n  ...\nValueError: x", file=sys.stderr)
        return 1
    if what == "traceback":
        raise ZeroDivisionError("planted")
    if what == "memory":
        return len(bytearray(8 * 2**30))  # beyond the address-space cap: MemoryError
    if what == "hang":
        time.sleep(60)
    if what == "crash":
        os.kill(os.getpid(), signal.SIGSEGV)
    return 7


PLANTED = {"ok": "pass", "verdict-fail": "pass", "error": "error", "messy": "messy",
           "printed-traceback": "traceback", "traceback": "traceback", "memory": "traceback", "hang": "hang",
           "crash": "crash", "odd-exit": "messy"}


@pytest.fixture(scope="module")
def light_assets(tmp_path_factory) -> fuzz.Assets:
    assets = fuzz.Assets(tmp_path_factory.mktemp("fuzz-assets"))
    assets.build(run=False)
    return assets


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_verdicts_on_planted_outcomes(tmp_path, light_assets, monkeypatch):
    """Each outcome is told apart, including a bad input accepted (silent) and a hang (killed in time)."""
    monkeypatch.setattr(cli, "main", planted_main)
    inputs = [fuzz.Input("planted", i, ["cli", what]) for i, what in enumerate(PLANTED)]
    inputs.append(fuzz.Input("planted", len(inputs), ["cli", "ok"], bad=["--spp '-1'"]))
    runner = fuzz.Runner(tmp_path / "out", light_assets, fuzz.Limits(timeout=1.5, memory_gib=2), jobs=2)
    start = time.monotonic()
    records = {r.inp.index: r for r in runner.run(inputs)}
    assert time.monotonic() - start < 30
    outcomes = {inputs[i].call[1] + ("-bad" if inputs[i].bad else ""): r.outcome for i, r in records.items()}
    assert outcomes == {**PLANTED, "ok-bad": "silent"}
    assert "ZeroDivisionError: planted" in records[list(PLANTED).index("traceback")].detail
    saved = sorted(p.name for p in (tmp_path / "out" / "failures").iterdir())
    assert saved == sorted(inputs[i].id for i, r in records.items() if r.outcome in fuzz.FAILURES)
    summary = fuzz.summarize(list(records.values()), 1.0, {})
    assert summary["total"]["inputs"] == len(inputs) and summary["total"]["silent"] == 1
    assert "planted" in fuzz.format_table(summary)


def test_a_saved_failure_replays(tmp_path, light_assets, monkeypatch, capsys):
    monkeypatch.setattr(cli, "main", planted_main)
    inp = fuzz.Input("planted", 0, ["cli", "traceback"], files={"scene.toml": b"x = 1"})
    fuzz.Runner(tmp_path / "out", light_assets, fuzz.Limits(timeout=5)).run([inp])
    folder = tmp_path / "out" / "failures" / inp.id
    assert (folder / "input" / "scene.toml").read_bytes() == b"x = 1"
    assert "-m harness traceback" in (folder / "replay.sh").read_text()
    assert json.loads((folder / "outcome.json").read_text())["outcome"] == "traceback"
    with pytest.raises(ZeroDivisionError, match="planted"):  # in this process: the traceback shows
        fuzz.main(["--replay", str(folder)])


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_loader_inputs_are_reproducible_and_classified(tmp_path, light_assets):
    """A few real inputs of the loaders (no renders): the same seed makes the same inputs, each ends in an
    outcome, loaders never hang or crash, and inputs made of valid parts load."""
    first = [fuzz.generate(8, entry, i, light_assets) for entry in ("load_scene", "load_suite") for i in range(7)]
    again = [fuzz.generate(8, entry, i, light_assets) for entry in ("load_scene", "load_suite") for i in range(7)]
    assert [(i.call, i.files, i.bad) for i in first] == [(i.call, i.files, i.bad) for i in again]
    specs = [i for i in (fuzz.generate(8, "renderer_file", k, light_assets) for k in range(6)) if i.call[0] != "cli"]
    records = fuzz.Runner(tmp_path / "out", light_assets, fuzz.Limits(timeout=20)).run(first + specs)
    assert len(records) == len(first) + len(specs)
    seen = {(r.inp.entry, r.outcome) for r in records}
    for entry in ("load_scene", "load_suite"):
        assert (entry, "pass") in seen and (entry, "error") in seen, seen
    assert not any(r.outcome in ("crash", "hang") for r in records), [(r.inp.id, r.detail) for r in records]
    assert all(r.outcome == "pass" for r in records if r.inp.valid and not r.inp.bad), [
        (r.inp.id, r.detail) for r in records if r.inp.valid]


def emitter_oracle_cases(assets: fuzz.Assets):
    """Every [[emitters]] slot of the fuzzer's emitter scenes with every value its tables hold: (scene, path, value,
    should load)."""
    for base in ("lights.toml", "sky.toml"):
        doc = tomllib.loads(assets.texts[base])
        for slot, path in fuzz._scene_slots(doc):
            if path[0] != "emitters":
                continue
            for value in fuzz.SCENE_BAD.get(slot, []):
                yield base, path, value, False
            for value in fuzz.SCENE_VALID.get(slot, []):
                yield base, path, value, True


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_the_scene_oracle_knows_which_emitter_values_are_bad(tmp_path, light_assets):
    """Each bad value of an [[emitters]] key is refused by the loader on one line naming the scene and each valid
    one loads, in the scenes the fuzzer mutates; so are the edits that depend on the entry (a spot's target on its
    position, a second environment, ...) and a required key deleted (the oracle's "silent" would be a false alarm
    otherwise, or a real bad input would pass unnoticed)."""
    for name, data in light_assets.scene_files().items():
        (tmp_path / name).write_bytes(data)
    (tmp_path / "scene.toml").write_text("")
    checked = {True: 0, False: 0}
    for base, path, value, good in emitter_oracle_cases(light_assets):
        doc = tomllib.loads(light_assets.texts[base])
        fuzz._set_path(doc, path, value)
        (tmp_path / "scene.toml").write_text(to_toml(doc))
        try:
            load_scene(tmp_path / "scene.toml")
            loaded = True
        except HarnessError as err:
            loaded = False
            assert str(err).startswith(f"{tmp_path / 'scene.toml'}: emitters[{path[1]}]") and "\n" not in str(err)
        assert loaded == good, (base, path, value)
        checked[good] += 1
    rng = random.Random(3)
    for base in ("lights.toml", "sky.toml"):
        for _ in range(24):  # the entry-dependent edits, every kind several times
            doc = tomllib.loads(light_assets.texts[base])
            reason = fuzz._emitter_special(rng, doc)
            (tmp_path / "scene.toml").write_text(to_toml(doc))
            with pytest.raises(HarnessError, match=r"emitters\["):
                load_scene(tmp_path / "scene.toml")
            checked[False] += 1
            assert reason
    assert checked[True] >= 20 and checked[False] >= 250, checked


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_scene_documents_with_emitters_are_marked_as_the_loader_finds_them(tmp_path, light_assets):
    """Generated documents of the emitter scenes: every one marked bad is refused (nothing silent), every one built
    from valid parts loads."""
    for name, data in light_assets.scene_files().items():
        (tmp_path / name).write_bytes(data)
    (tmp_path.parent / "outside.exr").write_bytes(light_assets.envmaps["sky.exr"])
    rng = random.Random(5)
    outcomes = Counter()
    for index in range(200):
        text, bad, valid, outside = fuzz.scene_document(rng, light_assets, rng.choice(["lights.toml", "sky.toml"]))
        path = tmp_path / "scene.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        try:
            load_scene(path, allow_outside_paths=False)
            loaded = True
        except HarnessError as err:
            loaded = False
            assert "\n" not in str(err), err
        if bad:
            assert not loaded, (index, bad)
        if valid:
            assert loaded, (index, text)
        outcomes["bad" if bad else "valid" if valid else "unknown", loaded] += 1
    assert outcomes["bad", False] >= 60 and outcomes["valid", True] >= 20, outcomes


def test_plan_shares_the_inputs_by_weight():
    jobs = fuzz.plan(10_000)
    assert len(jobs) == 10_000 and len(set(jobs)) == 10_000
    counts = {name: sum(1 for n, _ in jobs if n == name) for name in fuzz.GENERATORS}
    assert counts == {name: weight for name, (_, weight) in fuzz.GENERATORS.items()}
    assert {n for n, _ in fuzz.plan(20, ["compare", "cli"])} == {"compare", "cli"}


# --------------------------------------------------------------------------------------------------------------------
# Bugs the fuzzer found (each test fails on d95b870).


def one_line_error(capfd, *argv) -> str:
    code = cli.main([str(a) for a in argv])
    out, err = capfd.readouterr()
    lines = err.splitlines()
    assert code == 2 and out == "" and len(lines) == 1 and lines[0].startswith("harness: error: "), (code, out, err)
    return lines[0]


def test_an_error_quoting_a_line_break_stays_one_line(capfd):
    line = one_line_error(capfd, "bench", "a\nb", "c\u2028d")
    assert "a\\nb c\\u2028d" in line


def test_run_timeout_must_be_finite(tmp_path, capfd):
    """--timeout inf was accepted, and the local executor's deadline arithmetic raised OverflowError."""
    suite = tmp_path / "s.toml"
    suite.write_text(f'[[cases]]\nscene = "{FURNACE}"\nspp = 2\nfilm = {{ width = 4, height = 4 }}\n')
    line = one_line_error(capfd, "run", suite, "--timeout", "inf", "--executor", "serial", "--out", tmp_path / "o")
    assert "--timeout: expected a positive number of seconds" in line and "inf" in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("spec", ["tcp://:x", "tcp://host:0", "tcp://host:123456", "tcp://host:", ""])
def test_executor_addresses_are_checked(spec):
    """A malformed tcp:// address was a ValueError from Dask's parser mid-run; an empty --executor meant local."""
    with pytest.raises(HarnessError, match="--executor: expected serial, local, dask or tcp://HOST:PORT"):
        make_executor(spec)
    assert type(make_executor("tcp://127.0.0.1:8786")).__name__ == "DaskExecutor"


@pytest.mark.parametrize("k", ["nan", "0", "-1", "inf"])
def test_convergence_k_is_checked(tmp_path, capfd, k):
    """--k nan was accepted (it flags no bias at all), 0 and negatives too."""
    line = one_line_error(capfd, "convergence", FURNACE, "--spp", "1", "--film", "4x4", "--k", k,
                          "--out", tmp_path / "o", "--quiet")
    assert line.startswith("harness: error: --k: expected a positive")
    assert not (tmp_path / "o").exists()


def test_convergence_time_ladder_is_limited(tmp_path, capfd):
    """--seconds 1e300 was accepted: each rung renders until its time is spent, so it ran for ever (a hang)."""
    line = one_line_error(capfd, "convergence", FURNACE, "--spp", "1", "--seconds", "1e300", "--film", "4x4",
                          "--out", tmp_path / "o", "--quiet")
    assert line.startswith("harness: error: --seconds: expected a time budget of at most 24.0 h")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", [["render", FURNACE, "--spp", "1"], ["export", FURNACE, "--format", "ply"]])
@pytest.mark.parametrize("out", ["x" * 300 + ".exr", "a/" + "y" * 250 + "/b", "a\0b"])
def test_an_output_path_the_file_system_refuses_is_one_line(tmp_path, capfd, monkeypatch, command, out):
    """``--out`` with a 300-byte name was ``OSError: [Errno 36] File name too long`` (render after the render,
    export as it staged its folder); a NUL was ``ValueError: embedded null byte``."""
    monkeypatch.chdir(tmp_path)
    line = one_line_error(capfd, *command, "--out", out, "--quiet")
    assert line.startswith("harness: error: --out: expected a ")
    assert list(tmp_path.iterdir()) == []


def test_calibrate_seeds_are_limited_by_their_cost(tmp_path, capfd):
    """``calibrate --seeds 1e30`` was accepted (exit 0 under the fuzzer's time limit only: it rendered for ever)."""
    suite = tmp_path / "s.toml"
    suite.write_text(f'[[cases]]\nname = "c"\nscene = "{FURNACE}"\nspp = 64\nfilm = {{ width = 256, height = 256 }}\n')
    line = one_line_error(capfd, "calibrate", suite, "--seeds", "100000", "--out", tmp_path / "o", "--quiet")
    assert line.startswith("harness: error: --seeds: ") and "more than the 24.0 h limit" in line
    assert not (tmp_path / "o").exists()
    line = one_line_error(capfd, "calibrate", suite, "--seeds", "9" * 30, "--out", tmp_path / "o", "--quiet")
    assert line == "harness: error: --seeds: expected a number of seeds from 1 to 100000, got " + "9" * 30


def test_an_empty_seconds_ladder_is_refused(tmp_path, capfd):
    """``convergence --spp 2 --seconds ''`` ran the spp ladder and ignored the empty time ladder in silence."""
    line = one_line_error(capfd, "convergence", FURNACE, "--spp", "2", "--seconds", "", "--film", "4x4",
                          "--out", tmp_path / "o", "--quiet")
    assert line.startswith("harness: error: --seconds: expected comma-separated positive numbers")
    assert not (tmp_path / "o").exists()


def test_export_spp_is_limited_by_its_cost(tmp_path, capfd):
    """``export --spp 1e30`` wrote that number into the Mitsuba XML as the scene's default $spp, in silence."""
    line = one_line_error(capfd, "export", FURNACE, "--format", "mitsuba-xml", "--spp", "9" * 30,
                          "--out", tmp_path / "o")
    assert line.startswith("harness: error: --spp: ") and "limit" in line
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("option", ["--ground-truth-spp", "--chunk-spp"])
def test_convergence_unused_spp_options_are_checked(tmp_path, capfd, option):
    """``convergence --ground-truth-spp 1e13`` on the furnace (closed form: no ground truth rendered), and
    ``--chunk-spp 1e13`` without a --seconds ladder, were accepted in silence."""
    line = one_line_error(capfd, "convergence", FURNACE, "--spp", "2", option, "1" + "0" * 13,
                          "--film", "4x4", "--out", tmp_path / "o", "--quiet")
    assert line.startswith(f"harness: error: {option}: ") and "limit" in line
    assert not (tmp_path / "o").exists()


def test_ground_truth_chunk_spp_is_checked_on_a_closed_form_scene(tmp_path, capfd):
    """``ground-truth --chunk-spp 1e30`` on the furnace (closed form: nothing rendered) was accepted in silence."""
    line = one_line_error(capfd, "ground-truth", FURNACE, "--spp", "4", "--chunk-spp", "9" * 30,
                          "--cache-dir", tmp_path / "c", "--quiet")
    assert line.startswith("harness: error: --chunk-spp: ") and "limit" in line


def test_bench_memory_may_not_be_empty(capfd):
    """``bench --memory ''`` was read as no --memory at all (exit 0, no memory measured)."""
    line = one_line_error(capfd, "bench", "--scene", FURNACE, "--memory", "", "--spp", "1", "--quiet")
    assert line.startswith("harness: error: --memory: expected SIZExSPP")


def test_an_unused_ground_truth_spp_is_checked_too(tmp_path):
    """``ground_truth_spp = 10**12`` on a closed-form scene (where no ground truth is rendered) was accepted."""
    suite = tmp_path / "s.toml"
    suite.write_text(f'[[cases]]\nname = "c"\nscene = "{FURNACE}"\nground_truth_spp = 1000000000000\n')
    with pytest.raises(HarnessError, match=r"cases\[0\]\.ground_truth_spp: .*limit"):
        load_suite(suite)


def test_default_settings_every_case_replaces_are_checked_too(tmp_path):
    """``[defaults.settings] direct = "nope"`` loaded silently when every case had settings of its own (a case's
    settings replace the defaults' whole): found by the fuzzer, seed 7."""
    suite = tmp_path / "s.toml"
    suite.write_text(f'[defaults.settings]\ndirect = "nope"\n[[cases]]\nname = "c"\nscene = "{FURNACE}"\n'
                     'settings = { rr_depth = 5 }\n')
    with pytest.raises(HarnessError, match=r"defaults\.settings\.direct: expected one of"):
        load_suite(suite)


def test_stress_checks_costs_and_writes_nothing_on_bad_input(tmp_path, capfd):
    """harness stress had no cost check (an absurd --spp, --ground-truth-spp or --film ran for ever), and created
    --out before finding the scene broken."""
    base = ["stress", FURNACE, "--renderer", "reference", "--variant", "original", "--spp", "2", "--film", "4x4"]
    out = tmp_path / "o"
    assert "--ground-truth-spp: 4 x 4 pixels at 100000000000 spp" in one_line_error(
        capfd, *base, "--ground-truth-spp", 10**11, "--out", out)
    assert "--film: expected at most 16384 pixels per side" in one_line_error(capfd, *base, "--film", "99999x2")
    assert "--film: expected at most 67108864 pixels" in one_line_error(capfd, *base, "--film", "10000x10000")
    broken = tmp_path / "broken.toml"
    broken.write_text("[camera")
    assert str(broken) in one_line_error(capfd, "stress", broken, "--renderer", "reference", "--out", out)
    assert not out.exists()


def test_bench_checks_costs_before_rendering(tmp_path, capfd):
    """harness bench had no cost check: --spp 10**13 rendered for ever (found as a hang)."""
    assert "--spp: 256 x 256 pixels at 10000000000000 spp" in one_line_error(
        capfd, "bench", "--scene", "cornell-box", "--spp", 10**13, "--quiet")
    assert "--ground-truth-spp:" in one_line_error(capfd, "bench", "--scene", "furnace", "--ground-truth-spp",
                                                   10**12, "--quiet")
    assert "--memory: 1024 x 1024 pixels at 100000000 spp" in one_line_error(
        capfd, "bench", "--scene", "furnace", "--memory", "1024x100000000", "--quiet")


def baseline_file(tmp_path: Path, entry) -> Path:
    good = {"definition": "0" * 64, "solution": {}, "metrics": {"rmse": 0.1, "psnr": None, "bias": {}},
            "statistics": {"mse": {"value": 0.01, "rel_se": 0.1}, "mean": [1, 1, 1], "mean_stderr": None},
            "render": {"seconds": 0.5, "paths_per_second": 1e6}}
    path = tmp_path / "baseline.json"
    doc = {"schema": baseline.SCHEMA, "version": baseline.VERSION, "suite": "s",
           "cases": {"c": entry(good) if callable(entry) else entry}}
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("entry,fragment", [
    ("x", "cases.c: expected a table, got str"),
    (lambda e: {**e, "definition": 5}, "cases.c.definition: expected the case's SHA-256"),
    (lambda e: {**e, "metrics": {"relmse": "x"}}, "cases.c.metrics.relmse: expected a finite number, got 'x'"),
    # a table where a number belongs was taken for the bias table, and the run compared nothing (fuzzer, seed 7)
    (lambda e: {**e, "metrics": {"relmse": {}}}, "cases.c.metrics.relmse: expected a finite number, got {}"),
    (lambda e: {**e, "statistics": {"mse": {"value": math.nan}}}, "cases.c.statistics.mse: expected"),
    (lambda e: {**e, "statistics": {"mean": [1, 2]}}, "cases.c.statistics.mean: expected 3 finite numbers"),
    # a relative standard error no mean of non-negative errors has: exp() of its noise bound overflowed in the
    # run --baseline gate (OverflowError: math range error; the long fuzz run, seed 0, baseline-00238)
    (lambda e: {**e, "statistics": {"mse": {"value": 0.01, "rel_se": 22201}}},
     "cases.c.statistics.mse.rel_se: expected a relative standard error from 0 to 1"),
    (lambda e: {**e, "statistics": {"mse": {"value": 0.01, "rel_se": -0.5}}},
     "cases.c.statistics.mse.rel_se: expected a relative standard error"),
    (lambda e: {k: v for k, v in e.items() if k != "render"}, "cases.c.render: expected a table"),
    (lambda e: {**e, "render": {"seconds": None}}, "cases.c.render.seconds: expected a finite number"),
    (lambda e: {**e, "render": {"seconds": 10**400}}, "cases.c.render.seconds: expected a finite number"),
])
def test_damaged_baseline_files_are_refused_when_loaded(tmp_path, entry, fragment):
    """A baseline whose case entries were damaged (not tables, metrics not numbers) loaded, then the run with
    --baseline ended in an AttributeError or compared against garbage."""
    assert baseline.load(baseline_file(tmp_path, lambda e: e))["suite"] == "s"
    path = baseline_file(tmp_path, entry)
    with pytest.raises(HarnessError) as err:
        baseline.load(path)
    assert str(err.value).startswith(f"{path}: not a baseline file: {fragment}") and "\n" not in str(err.value)


@pytest.mark.parametrize("key,value", [("tools", None), ("tools", [1]), ("created", 5), ("source", {})])
def test_a_baseline_whose_header_is_damaged_is_refused_when_loaded(tmp_path, key, value):
    """``"tools": null`` loaded, then ``run --baseline`` ended in AttributeError: 'NoneType' object has no attribute
    'get' after every case had run (found by the fuzzer, seed 2)."""
    path = baseline_file(tmp_path, lambda e: e)
    doc = json.loads(path.read_text())
    path.write_text(json.dumps({**doc, key: value}))
    with pytest.raises(HarnessError) as err:
        baseline.load(path)
    assert str(err.value).startswith(f"{path}: not a baseline file: {key}: expected ")


def test_deeply_nested_baseline_and_results_files_are_one_line(tmp_path, capfd):
    """json.loads raises RecursionError (not a JSONDecodeError) on absurd nesting: it was a traceback."""
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(HarnessError, match="not a baseline file: invalid JSON"):
        baseline.load(deep)
    suite = tmp_path / "s.toml"
    suite.write_text(f'name = "s"\n[[cases]]\nname = "c"\nscene = "{FURNACE}"\n')
    assert "--from" in one_line_error(capfd, "baseline", "save", suite, "--out", tmp_path / "b.json", "--from", deep)


@pytest.mark.parametrize("cases", [[5], [{"name": ["x"]}], [{"name": "c", "metrics": 5}],
                                   [{"name": "c", "status": "pass", "render": {}, "ok": True}]])
def test_baseline_save_from_a_damaged_results_file_is_one_line(tmp_path, capfd, cases):
    """baseline save --from a results.json whose records are not tables, have a list as name or no render fields
    was a traceback (AttributeError, TypeError, KeyError), or (metrics not a table) wrote a damaged baseline."""
    suite = tmp_path / "s.toml"
    suite.write_text(f'name = "s"\n[[cases]]\nname = "c"\nscene = "{FURNACE}"\nspp = 2\n')
    results = tmp_path / "results.json"
    results.write_text(json.dumps({"suite": "s", "cases": [dict(c, renderer="reference", settings={}, seed=0,
                                                                 budget={"spp": 2}) if isinstance(c, dict) else c
                                                            for c in cases]}))
    line = one_line_error(capfd, "baseline", "save", suite, "--out", tmp_path / "b.json", "--from", results)
    assert f"--from {results}:" in line
    assert not (tmp_path / "b.json").exists()


# --------------------------------------------------------------------------------------------------------------------
# The long mode


@pytest.mark.skipif(not FUZZ_LONG, reason="the long fuzzing mode runs with HARNESS_FUZZ=long (docs/ci.md)")
def test_long_fuzz(tmp_path):
    """HARNESS_FUZZ=long: 10,000 inputs (HARNESS_FUZZ_INPUTS) through every loader and command; every one ends
    in success or a one-line error, none hangs, none that is certainly bad is accepted. The summary and the
    failing inputs go to HARNESS_FUZZ_OUT (default: a temporary folder)."""
    out = Path(os.environ.get("HARNESS_FUZZ_OUT") or tmp_path / "fuzz")
    # its own process: the children it forks must not inherit thread pools this one started (fuzz.py, top)
    subprocess.run([sys.executable, str(ROOT / "tests" / "cli" / "fuzz.py"), "--out", str(out), "--quiet", "--inputs",
                    os.environ.get("HARNESS_FUZZ_INPUTS", "10000")], check=False, timeout=4 * 3600)
    summary = json.loads((out / "summary.json").read_text())
    print(fuzz.format_table(summary))
    failures = [f"{f['id']} {f['outcome']}: {f['detail'][:200]}" for f in summary["failures"]]
    assert not failures, f"{len(failures)} failing inputs (kept in {out / 'failures'}):\n" + "\n".join(failures[:50])
