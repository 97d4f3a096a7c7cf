"""`harness baseline save --from RESULTS.json` reads a results.json that may come from someone else (a downloaded
run folder): the renders it names are read only inside that run folder (issue 32, docs/robustness.md, "Trust")."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from test_baseline import write_suite

from harness.cli import main
from harness.files.imageio import read_exr, write_exr


@pytest.fixture(scope="module")
def run_once(tmp_path_factory):
    """The tiny furnace suite run once into run0/ (closed form: no Mitsuba), for each test to copy."""
    folder = tmp_path_factory.mktemp("from")
    suite = write_suite(folder / "tiny.toml")
    assert main(["run", str(suite), "--out", str(folder / "run0"), "--executor", "serial", "--no-report",
                 "--quiet"]) == 0
    return folder


def _planted(tmp_path, run_once, exr: str):
    """A copy of the run whose first case's render path is ``exr`` (a planted results.json)."""
    shutil.copytree(run_once, tmp_path / "w")
    results = tmp_path / "w" / "run0" / "results.json"
    doc = json.loads(results.read_text())
    doc["cases"][0]["render"]["exr"] = exr
    results.write_text(json.dumps(doc))
    return tmp_path / "w" / "tiny.toml", results


def _secret_exr(tmp_path, run_once):
    """A valid EXR outside the run folder, not the run's render: reading it would bake it into the baseline."""
    outside = tmp_path / "secret"
    outside.mkdir()
    secret = outside / "other.exr"
    render = read_exr(run_once / "run0" / "cases" / "furnace_reference" / "render.exr")
    write_exr(secret, np.full_like(render.image, 1234.5), render.variance)
    return secret


@pytest.mark.slow  # a suite run: outside the inner loop
def test_a_render_path_outside_the_run_folder_is_not_read(tmp_path, run_once, capfd):
    suite, results = _planted(tmp_path, run_once, str(_secret_exr(tmp_path, run_once)))
    code = main(["baseline", "save", str(suite), "--from", str(results), "--out", str(tmp_path / "base.json"),
                 "--quiet"])
    assert code == 0, capfd.readouterr().err
    entry = json.loads((tmp_path / "base.json").read_text())["cases"]["furnace/reference"]
    assert max(entry["statistics"]["mean"]) < 10  # the run's own render (the furnace: about 1), not the planted one


@pytest.mark.slow
def test_without_its_own_render_a_path_outside_is_one_line_not_read(tmp_path, run_once, capfd):
    secret = _secret_exr(tmp_path, run_once)
    suite, results = _planted(tmp_path, run_once, str(secret))
    (results.parent / "cases" / "furnace_reference" / "render.exr").unlink()
    code = main(["baseline", "save", str(suite), "--from", str(results), "--out", str(tmp_path / "base.json"),
                 "--quiet"])
    err = capfd.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "outside the run folder (not read)" in err
    assert not (tmp_path / "base.json").exists()


@pytest.mark.slow
def test_a_moved_run_folder_finds_its_renders_inside(tmp_path, run_once, capfd):
    suite, results = _planted(tmp_path, run_once, str(tmp_path / "gone" / "render.exr"))
    code = main(["baseline", "save", str(suite), "--from", str(results), "--out", str(tmp_path / "base.json"),
                 "--quiet"])
    assert code == 0, capfd.readouterr().err
    assert "furnace/reference" in json.loads((tmp_path / "base.json").read_text())["cases"]
