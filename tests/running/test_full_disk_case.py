"""A disk that fills up while ``harness run`` writes a case's files (issue 32): the case's files are staged and moved
into place together, so the run leaves no half-written case folder (a new one is gone, an earlier run's is as it
was, byte for byte), results.json keeps the cases that finished, and running again resumes."""

from __future__ import annotations

from pathlib import Path

import pytest
from test_hostile_input import SCENE, assert_one_line, cli, listing
from test_hostile_leftovers import SUITE, case_files
from test_hostile_results import disk  # noqa: F401 - a fixture (a disk that fills up)

from harness.files.results import read_results

pytestmark = pytest.mark.slow  # renders: outside the inner loop (pytest -m "not slow")


@pytest.fixture
def folder(tmp_path) -> Path:
    """tmp/scene.toml (a valid 16 x 16 scene) and tmp/two.toml (a suite of two cases of it)."""
    (tmp_path / "scene.toml").write_text(SCENE)
    (tmp_path / "two.toml").write_text(SUITE)
    return tmp_path


def run_argv(folder: Path, out: Path) -> tuple:
    return ("run", folder / "two.toml", "--out", out, "--executor", "serial", "--quiet", "--no-report")


def files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("after", [2, 4, 9])  # b's ground truth, a verdict map, a report image fail
def test_a_case_whose_files_fill_the_disk_leaves_no_half_written_folder(folder, disk, capfd, after):  # noqa: F811
    out = folder / "run"
    disk.fill(name=str(out / "cases" / "b"), after=after)  # case a is written whole, b's files only in part
    assert_one_line(*cli(capfd, *run_argv(folder, out)), str(out / "cases" / "b"), "No space left on device")
    assert listing(out) == ["cases", *case_files("cases/a"), "results.json"]  # no cases/b, no staging folder
    results = read_results(out / "results.json")
    assert [r["name"] for r in results["cases"]] == ["a"] and not results["complete"]
    disk.full = False
    code, _, err = cli(capfd, *run_argv(folder, out))
    assert code == 0 and "resuming: 1 of 2 cases done" in err, err
    assert listing(out / "cases") == [*case_files("a"), *case_files("b")]


def test_a_case_run_again_on_a_full_disk_keeps_its_old_files(folder, disk, capfd):  # noqa: F811
    """A changed case renders again over an earlier run's folder: a full disk halfway leaves every old file."""
    out = folder / "run"
    assert cli(capfd, *run_argv(folder, out))[0] == 0
    old, names = files(out), listing(out)
    (folder / "two.toml").write_text(SUITE.replace("seed = 3", "seed = 5"))  # case b changed: it runs again
    disk.fill(name=str(out / "cases" / "b"), after=4)
    code, _, err = cli(capfd, *run_argv(folder, out))
    assert code == 2 and err.splitlines() == ["resuming: 1 of 2 cases done", err.splitlines()[-1]], err
    assert str(out / "cases" / "b") in err and "No space left on device" in err and "Traceback" not in err
    assert files(out) == old  # case b's old files, byte for byte; results.json as it was
    assert listing(out) == names  # and no staging folder
