"""Leftovers of issue 12 (hostile input, docs/robustness.md): ``render`` on a full disk leaves no EXR without its
preview; ``run`` on a full disk leaves no empty folders it made (and keeps finished cases); results.json is strict
JSON (non-finite numbers as null) that the harness's own reader takes back; an empty ``--out`` is refused by every
command that has one."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import pytest
from test_hostile_input import SCENE, assert_one_line, cli, listing
from test_hostile_results import disk  # noqa: F401 - a fixture (a disk that fills up)

from harness.running.executors import SerialExecutor
from harness.files.results import read_results
from harness.running.cases import load_suite
from harness.running.schedule import run_suite

SUITE = """
name = "two"
[defaults]
spp = 2
# 8 x the test's samples: the ground truth's noise under 1/4 of the test's, so harness run warns of nothing
against = { renderer = "reference", spp = 16 }

[[cases]]
name = "a"
scene = "scene.toml"

[[cases]]
name = "b"
scene = "scene.toml"
seed = 3
"""


@pytest.fixture
def folder(tmp_path) -> Path:
    """tmp/scene.toml (a valid 16 x 16 scene) and tmp/two.toml (a suite of two cases of it)."""
    (tmp_path / "scene.toml").write_text(SCENE)
    (tmp_path / "two.toml").write_text(SUITE)
    return tmp_path


# ---- 1. render: the EXR and its preview, both or neither ----------------------------------------------------------


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_render_whose_preview_cannot_be_written_leaves_no_exr(folder, disk, capfd):  # noqa: F811
    out = folder / "out"
    out.mkdir()
    disk.fill(name=".png")  # the EXR is written, its preview is not
    assert_one_line(*cli(capfd, "render", folder / "scene.toml", "--spp", 2, "--out", out / "x.exr", "--quiet"),
                    f"{out / 'x.png'}: cannot write: No space left on device")
    assert listing(out) == []  # no x.exr, no temporary file


def test_render_that_fails_keeps_the_old_exr_and_preview(folder, disk, capfd):  # noqa: F811
    out = folder / "out"
    out.mkdir()
    argv = ("render", folder / "scene.toml", "--spp", 2, "--out", out / "x.exr", "--quiet")
    assert cli(capfd, *argv)[0] == 0
    old = {p.name: p.read_bytes() for p in out.iterdir()}
    assert sorted(old) == ["x.exr", "x.png"]
    disk.fill(name=".png")
    assert_one_line(*cli(capfd, *argv[:4], "--seed", 5, *argv[4:]), "x.png", "No space left on device")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == old  # the old pair, whole
    disk.full = False
    assert cli(capfd, *argv[:4], "--seed", 5, *argv[4:])[0] == 0
    assert all((out / name).read_bytes() != old[name] for name in old)  # the new pair, whole


# ---- 2. run: no empty folder left by a run that failed, finished cases kept ----------------------------------------


def run_argv(folder: Path, out: Path) -> tuple:
    return ("run", folder / "two.toml", "--out", out, "--executor", "serial", "--quiet", "--no-report")


def test_run_on_a_full_disk_leaves_no_folder_it_made(folder, disk, capfd):  # noqa: F811
    out = folder / "new" / "run"
    disk.fill(name=".render.")  # the first case's render cannot be written
    assert_one_line(*cli(capfd, *run_argv(folder, out)), "render.", "No space left on device")
    assert listing(folder) == ["scene.toml", "two.toml"]  # no new/, no run/cases/a/


def test_run_on_a_full_disk_keeps_folders_it_did_not_make(folder, disk, capfd):  # noqa: F811
    out = folder / "run"
    (out / "cases" / "b").mkdir(parents=True)  # made by the user (or an earlier run), empty
    disk.fill(name=".render.")
    assert_one_line(*cli(capfd, *run_argv(folder, out)), "No space left on device")
    assert listing(out) == ["cases", "cases/b"]  # cases/a, made by this run, is gone


def test_run_that_fails_after_a_case_keeps_it_and_resumes(folder, disk, capfd):  # noqa: F811
    out = folder / "run"
    disk.fill(name=str(out / "cases" / "b"))  # case a is written, case b's render is not
    assert_one_line(*cli(capfd, *run_argv(folder, out)), "No space left on device")
    # the closed form judged against is kept beside the render
    assert listing(out) == ["cases", *case_files("cases/a"), "results.json"]
    assert [r["name"] for r in read_results(out / "results.json")["cases"]] == ["a"]
    disk.full = False
    code, stdout, err = cli(capfd, *run_argv(folder, out))
    assert code == 0 and "resuming: 1 of 2 cases done" in err, err
    assert listing(out / "cases") == [*case_files("a"), *case_files("b")]


def case_files(case: str) -> list[str]:
    """Every file harness run writes for a case judged against a closed form, as listing() names them: the case's
    folder, its render, the closed form judged against, the verdict maps, the report images, the viewer's files."""
    from harness.files import viewer_data

    return sorted([case, *(f"{case}/{name}" for name in (
        "failing.exr", "ground_truth.exr", "pvalue.exr", "render.exr", "render.png", viewer_data.DATA_FILE,
        viewer_data.THUMBNAIL_FILE, viewer_data.PVALUE_FILE)), *images(case)])


def images(case: str) -> list[str]:
    """The report images harness run writes for a case (harness.files.report_images), as listing() names them."""
    from harness.files.report_images import KEYS

    return [f"{case}/images", *sorted(f"{case}/images/{key}.{kind}" for key in KEYS for kind in ("exr", "png"))]


# ---- 3. results.json: strict JSON, non-finite numbers as null ------------------------------------------------------


def test_results_json_writes_non_finite_numbers_as_null(folder, monkeypatch):
    from harness.running import judge as judge_module

    real_run_case = judge_module.run_case

    def run_case(case, *args, **kwargs):  # a record as a renderer's odd output could make it
        record = real_run_case(case, *args, **kwargs)
        record["metrics"].update(rmse=math.nan, relmse=math.inf, psnr=-math.inf)
        record["render"]["info"]["odd"] = [math.nan, 1.0]
        return record

    monkeypatch.setattr(judge_module, "run_case", run_case)
    run_suite(load_suite(folder / "two.toml"), folder / "run", executor=SerialExecutor())
    text = (folder / "run" / "results.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    json.loads(text, parse_constant=lambda literal: pytest.fail(f"{literal} in results.json"))
    doc = read_results(folder / "run" / "results.json")  # the harness's own strict reader takes it back
    for record in doc["cases"]:
        assert {k: record["metrics"][k] for k in ("rmse", "relmse", "psnr")} == dict.fromkeys(
            ("rmse", "relmse", "psnr"))
        assert record["render"]["info"]["odd"] == [None, 1.0]


def test_baseline_file_writes_non_finite_numbers_as_null(tmp_path):
    from harness.running import baseline

    doc = {"schema": baseline.SCHEMA, "version": baseline.VERSION, "suite": "s", "cases": {
        "a": {"statistics": {"mse": {"value": math.nan, "rel_se": None}, "mean": [math.inf, 0.5, 1.0]}}}}
    path = baseline.save(doc, tmp_path / "base.json")  # a ValueError (allow_nan=False, nothing cleaned) before
    assert json.loads(path.read_text())["cases"]["a"]["statistics"] == {"mse": {"value": None, "rel_se": None},
                                                              "mean": [None, 0.5, 1.0]}


# ---- 4. an empty --out, for every command that has one ------------------------------------------------------------


@pytest.mark.parametrize("command", [
    ("render", "SCENE", "--spp", "2"),
    ("report", "DIR/results.json"),
    ("convergence", "SCENE", "--spp", "2"),
    ("export", "SCENE", "--format", "obj"),
    ("import", "DIR/scene.xml"),
    ("bench", "--scene", "SCENE"),
    ("stress", "SCENE"),
    ("run", "SUITE", "--executor", "serial"),
    ("calibrate", "SUITE"),
    ("baseline", "save", "SUITE"),
], ids=lambda command: command[0])
def test_empty_out_is_refused_by_every_command(command, folder, capfd, monkeypatch):
    monkeypatch.chdir(folder)  # where the defaults (reports/..., the results file's folder) would go
    before = listing(folder)
    swap = {"SCENE": str(folder / "scene.toml"), "SUITE": str(folder / "two.toml"), "DIR": str(folder)}
    argv = [swap.get(a, a.replace("DIR", str(folder))) for a in command]
    assert_one_line(*cli(capfd, *argv, "--out", ""), "--out: expected a ", "path, got an empty string")
    assert listing(folder) == before


def test_output_path_types_take_any_other_path():
    from harness.core import options

    assert options.out_file("x.exr") == "x.exr" and options.out_folder("./a b/") == "./a b/"
    for convert, what in ((options.out_file, "a file path"), (options.out_folder, "a folder path")):
        for text in ("", "  "):
            with pytest.raises(argparse.ArgumentTypeError, match=f"^expected {what}, got an empty string$"):
                convert(text)
