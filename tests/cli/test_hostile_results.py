"""Hostile input about results (issue 12): a malformed results.json (report, baseline --from, resume), metrics that
are undefined in ``harness compare``, user strings in summary.md, a full disk under every command that writes, and
an edited ground-truth cache meta.json.

The results.json used here is a real one: a tiny suite (two furnace cases, 8 x 8 pixels, 2 spp, closed form) run
once for the module.
"""

from __future__ import annotations

import builtins
import copy
import errno
import io
import json
import os
import random
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT
from test_groundtruth import assert_same, entries, gt, hidden, renders, small  # noqa: F401 - renders: a fixture
from test_hostile_input import assert_one_line, cli, listing

from harness.files import imageio
from harness.core.errors import HarnessError
from harness.renderers.groundtruth import Cache
from harness.judges.moments import Estimate
from harness.files.results import format_path, read_results

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

SUITE = """
name = "tiny"
[defaults]
spp = 2
film = { width = 8, height = 8 }

[[cases]]
name = "furnace/a"
scene = "SCENES/furnace.toml"

[[cases]]
name = "furnace/b"
scene = "SCENES/furnace.toml"
seed = 7
"""

NO_STUDIES = ("--quiet", "--no-convergence", "--no-shadow-rays", "--no-strategies")


@pytest.fixture(scope="module")
def real(tmp_path_factory) -> dict:
    """{"suite": the suite file, "dir": the run's folder, "doc": its results.json parsed, "text": as written}."""
    from harness.running.executors import SerialExecutor
    from harness.running.cases import load_suite
    from harness.running.schedule import run_suite

    folder = tmp_path_factory.mktemp("real")
    suite = folder / "tiny.toml"
    suite.write_text(SUITE.replace("SCENES", str(ROOT / "scenes")))
    run_suite(load_suite(suite), folder / "run", executor=SerialExecutor())
    text = (folder / "run" / "results.json").read_text()
    return {"suite": suite, "dir": folder / "run", "doc": json.loads(text), "text": text}


def write_results(folder: Path, doc=None, raw: str | bytes | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "results.json"
    if raw is None:
        raw = json.dumps(doc, indent=1)
    path.write_bytes(raw.encode() if isinstance(raw, str) else raw)
    return path


# --------------------------------------------------------------------------------------------------------------------
# 1. A malformed results.json: one line naming the file and the JSON path, exit 2, nothing written.


def test_a_real_results_json_passes_the_check(real, tmp_path):
    assert read_results(real["dir"] / "results.json") == real["doc"]
    errored = copy.deepcopy(real["doc"])  # a case that ended in an error has no metrics, verdict or render
    record = errored["cases"][0]
    for key in ("metrics", "verdict", "thresholds", "thresholds_broken", "render", "ground_truth"):
        record.pop(key)
    record.update(status="error", ok=False, reason="worker died: killed by SIGSEGV", wall_seconds=None)
    read_results(write_results(tmp_path, errored))


def _set(doc, path, value):
    target = doc
    for part in path[:-1]:
        target = target[part]
    target[path[-1]] = value


HAND_PICKED = {
    # name: (how the real document is changed, what the one line says after "FILE: ")
    "metrics-is-a-number": (lambda d: _set(d, ("cases", 0, "metrics"), -1),
                            "cases[0].metrics: expected an object, got -1"),
    "name-is-a-list": (lambda d: _set(d, ("cases", 1, "name"), ["furnace/b"]),
                       "cases[1].name: expected a non-empty string, got a list of 1"),
    "missing-key": (lambda d: d["cases"][0].pop("status"), "cases[0].status: missing; expected one of"),
    "missing-summary": (lambda d: d.pop("summary"), "summary: missing; expected an object"),
    "spp-is-a-string": (lambda d: _set(d, ("cases", 0, "render", "spp"), "2"),
                        'cases[0].render.spp: expected an integer >= 0, got "2"'),
    "bias-not-three": (lambda d: _set(d, ("cases", 0, "verdict", "global_bias", "z"), [1, 2]),
                       "cases[0].verdict.global_bias.z: expected a list of 3, got a list of 2"),
    "bad-status": (lambda d: _set(d, ("cases", 0, "status"), "passed"),
                   'cases[0].status: expected one of "pass", "fail", "error", "skipped", got "passed"'),
    "bool-for-int": (lambda d: _set(d, ("summary", "cases"), True), "summary.cases: expected an integer >= 0, got true"),
    "schema-2": (lambda d: _set(d, ("schema",), 2), "schema: expected 1 (the schema this harness reads), got 2"),
    "image-file-is-a-path": (lambda d: _set(d, ("cases", 0, "report_images", "images", 2, "png"), "../../x.png"),
                             'cases[0].report_images.images[2].png: expected a file name (no folder), got '
                             '"../../x.png"'),
    "viewer-file-is-a-path": (lambda d: _set(d, ("cases", 1, "viewer", "data"), "../../x.js"),
                              'cases[1].viewer.data: expected a file name (no folder), got "../../x.js"'),
    "viewer-histogram-counts": (lambda d: _set(d, ("cases", 0, "viewer", "p_histogram", "counts"), [1, -2]),
                                "cases[0].viewer.p_histogram.counts[1]: expected an integer >= 0, got -2"),
    "odd-key": (lambda d: _set(d, ("cases", 0, "settings"), {"a\nb": 3}),
                'cases[0].settings["a\\nb"]: expected a string, got 3'),
}

HAND_PICKED_TEXT = {
    # name: (the file's bytes from the real text, what the line says after "FILE: ")
    "nan": (lambda t: t.replace('"ssim": 1.0', '"ssim": NaN', 1), "cases[0].metrics.ssim: expected a number or "
            "null, got NaN (not JSON"),
    "infinity": (lambda t: re.sub(r'"seconds": [0-9.e-]+', '"seconds": -Infinity', t, count=1),
                 "-Infinity (not JSON"),
    "overflowing-float": (lambda t: t.replace('"tile": 8', '"tile": 1e999', 1),
                          "cases[0].verdict.tile: expected an integer >= 1, got 1e999"),
    "5000-digits": (lambda t: t.replace('"seed": 7', '"seed": ' + "9" * 5000, 1),
                    "cases[1].seed: expected an integer >= 0, got an integer of 5000 digits"),
    "nested-thousands-deep": (lambda t: "[" * 50_000 + "]" * 50_000, "nested too deeply"),
    "nested-in-a-free-key": (lambda t: t.replace('"info": {', '"info": {"x": ' + "[" * 500 + "]" * 500 + ",", 1),
                             "cases[0].render.info.x[0][0][0]"),
    "top-level-list": (lambda t: "[" + t + "]", "expected a results.json of harness run (a JSON object), got a list"),
    "top-level-string": (lambda t: '"results"', "got \"results\""),
    "not-json": (lambda t: t[: len(t) // 2], "not JSON"),
    "empty": (lambda t: "", "line 1, column 1: not JSON"),
    "not-utf8": (lambda t: b"\xff\xfe" + t.encode("utf-16-le"), "cannot read"),
}


@pytest.mark.parametrize("name", list(HAND_PICKED) + list(HAND_PICKED_TEXT))
def test_malformed_results_are_one_line_and_write_nothing(name, real, tmp_path, capfd):
    folder = tmp_path / "in"
    if name in HAND_PICKED:
        change, expected = HAND_PICKED[name]
        doc = copy.deepcopy(real["doc"])
        change(doc)
        path = write_results(folder, doc)
    else:
        change, expected = HAND_PICKED_TEXT[name]
        path = write_results(folder, raw=change(real["text"]))
    before = listing(folder)
    line = assert_one_line(*cli(capfd, "report", path, *NO_STUDIES), f"{path}: ")
    assert expected in line
    assert listing(folder) == before  # no report folder, no index.html
    assert_one_line(*cli(capfd, "report", path, "--out", tmp_path / "new" / "out", *NO_STUDIES), expected)
    assert not (tmp_path / "new").exists()


def _paths(value, path=()):
    """Every JSON path of ``value``, parents first."""
    yield path
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _paths(item, path + (key,))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from _paths(item, path + (index,))


RAW = "@@raw@@"
WRONG_VALUES = [-1, 2.5, True, None, "x", [], [1, "a"], {}, {"k": [None]}]
WRONG_TEXTS = ["NaN", "Infinity", "-Infinity", "1e400", "9" * 4400, "[" * 60 + "]" * 60]


def _variants(doc: dict, count: int, seed: int = 12):
    """``count`` malformed versions of ``doc`` (text, path changed, how), deterministic: a value at a random path
    replaced by one of the wrong values or texts, or a key deleted."""
    rng = random.Random(seed)
    paths = [p for p in _paths(doc) if p]
    for _ in range(count):
        path = rng.choice(paths)
        variant = copy.deepcopy(doc)
        how = rng.choice(["value", "value", "text", "delete"])
        if how == "delete" and isinstance(path[-1], str):
            parent = variant
            for part in path[:-1]:
                parent = parent[part]
            del parent[path[-1]]
            yield json.dumps(variant), path, "delete"
        elif how == "text":
            text = rng.choice(WRONG_TEXTS)
            _set(variant, path, RAW)
            yield json.dumps(variant).replace(json.dumps(RAW), text), path, f"text {text[:12]}"
        else:
            value = rng.choice(WRONG_VALUES)
            _set(variant, path, value)
            yield json.dumps(variant), path, f"value {value!r}"


def test_hundreds_of_malformed_results_are_one_line_or_a_report(real, tmp_path, capfd):
    """300 edits of a real results.json: each is refused in one line naming the file and the JSON path of the
    edit, or is still a results.json (null where null is allowed, a free key such as render.settings edited, an
    optional key dropped). Every tenth refused one also goes through ``harness report`` (exit 2, nothing written),
    and the first accepted ones get their report (the parser and a report take their time)."""
    refused, reported = 0, 0
    for index, (text, path, how) in enumerate(_variants(real["doc"], 300)):
        folder = tmp_path / f"v{index}"
        results = write_results(folder, raw=text)
        try:
            read_results(results)
        except HarnessError as err:
            refused += 1
            line = f"harness: error: {err}"
            assert "\n" not in line, (how, path, line)
            at = f"harness: error: {results}: "
            assert line.startswith(at + format_path(path)) or (  # a dropped key of a one-of ({spp} or {seconds})
                how == "delete" and line.startswith(at + format_path(path[:-1]) + ": expected")), (how, path, line)
            if refused % 10 == 1:
                assert assert_one_line(*cli(capfd, "report", results, "--out", folder / "report", *NO_STUDIES)) == line
                assert listing(folder) == ["results.json"], (how, path)
            continue
        if reported < 4:
            reported += 1
            code, out, err = cli(capfd, "report", results, "--out", folder / "report", *NO_STUDIES)
            assert code == 0 and "Traceback" not in err, (how, path, out, err)
            assert (folder / "report" / "index.html").is_file(), (how, path)
    assert refused >= 240 and reported == 4, refused  # most edits break the schema


def test_baseline_from_a_malformed_results_is_one_line(real, tmp_path, capfd):
    doc = copy.deepcopy(real["doc"])
    doc["cases"][0]["metrics"] = -1
    path = write_results(tmp_path / "in", doc)
    line = assert_one_line(*cli(capfd, "baseline", "save", real["suite"], "--from", path, "--out",
                                tmp_path / "base.json"), f"--from {path}: cases[0].metrics: expected an object")
    assert "got -1" in line and not (tmp_path / "base.json").exists()


@pytest.mark.parametrize("corruption", ["metrics", "deep", "not-json"])
def test_resuming_from_a_corrupt_results_json_is_one_line(corruption, real, tmp_path, capfd):
    """``harness run`` resumes from DIR/results.json: a corrupt one is refused (pointing at --fresh) before any
    case runs, and left as it was; --fresh runs every case."""
    out = tmp_path / "run"
    doc = copy.deepcopy(real["doc"])
    doc["cases"][0]["metrics"] = -1
    text = {"metrics": json.dumps(doc), "deep": '{"suite": "tiny", "cases": ' + "[" * 5000 + "]" * 5000 + "}",
            "not-json": real["text"][:100]}[corruption]
    path = write_results(out, raw=text)
    line = assert_one_line(*cli(capfd, "run", real["suite"], "--out", out, "--executor", "serial", "--quiet",
                                "--no-report"), f"{path}", "--fresh")
    assert {"metrics": "cases[0].metrics", "deep": "nested too deeply", "not-json": "not JSON"}[corruption] in line
    assert path.read_text() == text and listing(out) == ["results.json"]
    if corruption == "metrics":  # --fresh ignores it
        code, _, err = cli(capfd, "run", real["suite"], "--out", out, "--executor", "serial", "--quiet", "--no-report",
                           "--fresh")
        assert code == 0, err
        assert read_results(path)["summary"]["resumed"] == 0


# --------------------------------------------------------------------------------------------------------------------
# 2. harness compare: undefined metrics are printed as such, the verdict stays right.


def _exr(path: Path, value: float, variance: float = 0.0) -> Path:
    image = np.full((8, 8, 3), value, np.float32)
    imageio.write_exr(path, image, np.full_like(image, variance))
    return path


@pytest.mark.parametrize("test,reference,verdict,undefined", [
    (-np.inf, 1.0, "fail", ["rmse", "relmse", "mape", "psnr", "ssim", "flip"]),  # no finite test pixel
    (np.nan, 1.0, "fail", ["rmse", "relmse", "mape", "psnr", "ssim", "flip"]),
    (np.inf, 0.0, "fail", ["rmse", "relmse", "mape", "psnr", "ssim", "flip"]),
    (1.0, 0.0, "fail", ["psnr"]),  # an all-zero reference: PSNR has no peak
    (0.5, 0.5, "pass", ["psnr"]),  # identical images: PSNR is infinite
])
def test_compare_prints_undefined_metrics(test, reference, verdict, undefined, tmp_path, capfd):
    t = _exr(tmp_path / "t.exr", test, 0.01)
    r = _exr(tmp_path / "r.exr", reference, 0.0)
    code, out, err = cli(capfd, "compare", t, r)
    assert code == (0 if verdict == "pass" else 1) and err == "", (out, err)
    lines = out.splitlines()
    assert lines[0].startswith(f"verdict: {verdict}")
    shown = {line.split()[0]: line.split(None, 1)[1] for line in lines[1:] if line.startswith("  ")}  # the metrics
    assert sorted(k for k, v in shown.items() if v.startswith("undefined")) == sorted(undefined), out
    for key, value in shown.items():
        if key not in undefined:
            float(value)
    code, out, err = cli(capfd, "compare", t, r, "--json")
    report = json.loads(out)
    assert code == (0 if verdict == "pass" else 1) and report["verdict"]["verdict"] == verdict
    assert sorted(k for k, v in report["metrics"].items() if v is None) == sorted(undefined)
    if not np.isfinite(test):
        assert "non-finite pixels" in report["verdict"]["reason"]


# --------------------------------------------------------------------------------------------------------------------
# 3. summary.md: user strings cannot inject HTML or Markdown, nor break its tables.

EVIL_SUITE = "<script>alert('suite')</script> & `code` | pipe"
EVIL_CASE = "<img src=x onerror=alert(1)> | **bold** [link](javascript:alert(2)) `tick`\nnext line # h"


def _unescaped_pipes(line: str) -> int:
    return len(re.findall(r"(?<!\\)\|", line))


def test_summary_md_escapes_every_user_string(real, tmp_path):
    from harness.report import ReportOptions, write_suite_report

    doc = copy.deepcopy(real["doc"])
    doc["suite"] = EVIL_SUITE
    doc["cases"][0]["name"] = EVIL_CASE
    doc["summary"]["unexpected"] = [EVIL_CASE]
    path = write_results(tmp_path / "in", doc)
    options = ReportOptions(convergence=False, shadow_rays=False, strategies=False)
    summary = Path(write_suite_report(path, tmp_path / "out", options)["summary"]).read_text()
    for raw in ("<script", "<img", "</", "onerror=alert(1)>", "`code`", "`tick`", "**bold**", "[link]"):
        assert raw not in summary, raw
    assert "&lt;script&gt;alert('suite')&lt;/script&gt; &amp; \\`code\\` \\| pipe" in summary
    rows = [line for line in summary.splitlines() if line.startswith("| ")]
    assert len(rows) == 3 and all(_unescaped_pipes(row) == 8 for row in rows), rows  # header + 2 cases, 7 columns
    assert not any(line.startswith("next line") for line in summary.splitlines())


# --------------------------------------------------------------------------------------------------------------------
# 4. A full disk: one line, a non-zero exit, nothing half-written, no empty folder left.


class Disk:
    """A disk that fills up under ``root``: opening a file there for writing raises ENOSPC (after ``after``
    successful opens, for files whose path contains ``name``), and with ``folders`` so does making a folder. A hard
    link made there fails too (a new directory entry needs room), so a report that links the run's images falls back
    to copying them, and each copy is an open that counts."""

    def __init__(self, monkeypatch, root: Path):
        self.root = str(root)
        self.name = ""
        self.after = 0
        self.folders = False
        self.full = False
        real_open, real_mkdir, real_link = io.open, os.mkdir, os.link

        def fake_open(file, mode="r", *args, **kwargs):
            handle = real_open(file, mode, *args, **kwargs)
            if self.full and any(c in mode for c in "wax+"):
                where = os.readlink(f"/proc/self/fd/{handle.fileno()}")  # as created (tempfile names it itself)
                if where.startswith(self.root) and self.name in where:
                    if self.after <= 0:
                        handle.close()  # created, like a file whose first write finds the disk full
                        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), where)
                    self.after -= 1
            return handle

        def fake_mkdir(path, *args, **kwargs):
            if self.full and self.folders and os.path.abspath(os.fspath(path)).startswith(self.root):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), os.fspath(path))
            return real_mkdir(path, *args, **kwargs)

        def fake_link(source, dest, *args, **kwargs):
            if self.full and os.path.abspath(os.fspath(dest)).startswith(self.root):
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), os.fspath(dest))
            return real_link(source, dest, *args, **kwargs)

        monkeypatch.setattr(io, "open", fake_open)
        monkeypatch.setattr(os, "link", fake_link)
        monkeypatch.setattr(builtins, "open", fake_open)
        monkeypatch.setattr(os, "mkdir", fake_mkdir)

    def fill(self, *, name: str = "", after: int = 0, folders: bool = False) -> None:
        self.full, self.name, self.after, self.folders = True, name, after, folders


@pytest.fixture
def disk(monkeypatch, tmp_path):
    return Disk(monkeypatch, tmp_path)


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_report_that_cannot_write_index_html_exits_2_and_leaves_nothing(real, tmp_path, disk, capfd):
    folder = tmp_path / "in"
    path = write_results(folder, raw=real["text"])
    disk.fill(name="index.html")
    assert_one_line(*cli(capfd, "report", path, *NO_STUDIES), "index.html: cannot write: No space left on device")
    assert listing(folder) == ["results.json"]  # no report/ folder, no staging folder
    assert_one_line(*cli(capfd, "report", path, "--out", tmp_path / "a" / "b", *NO_STUDIES), "No space left")
    assert not (tmp_path / "a").exists()


@pytest.mark.parametrize("fail", [{"after": 3}, {"after": 9}, {"name": "index.html"}], ids=["4th", "10th", "index"])
def test_a_failed_report_keeps_the_old_one(fail, real, tmp_path, disk, capfd):
    folder = tmp_path / "in"
    shutil.copytree(real["dir"] / "cases", folder / "cases")  # the report reads only files in the run folder
    text = real["text"].replace(str(real["dir"]), str(folder))
    path = write_results(folder, raw=text)
    assert cli(capfd, "report", path, *NO_STUDIES)[0] == 0
    old = _files(folder)
    assert "index.html" in old and any(name.startswith("report/") for name in old)
    doc = json.loads(text)  # a new report that differs from the old one in every case's images
    doc["description"] = "the second report"
    for key, inner in (("render", "exr"), ("report_images", "folder")):  # the run's images of the other case
        doc["cases"][0][key][inner], doc["cases"][1][key][inner] = (doc["cases"][1][key][inner],
                                                                    doc["cases"][0][key][inner])
    write_results(folder, doc)
    old["results.json"] = path.read_bytes()
    disk.fill(**fail)  # a file of the new report cannot be written
    assert_one_line(*cli(capfd, "report", path, *NO_STUDIES), "No space left on device")
    assert _files(folder) == old  # every file of the old report, byte for byte
    assert sorted(p.name for p in folder.iterdir()) == ["cases", "index.html", "report", "report.json",
                                                        "results.json", "summary.md"]  # and no staging folder
    disk.full = False
    assert cli(capfd, "report", path, *NO_STUDIES)[0] == 0  # the new report, whole
    new = _files(folder)
    assert sorted(new) == sorted(old) and all(new[name] != old[name] for name in ("index.html", "report.json",
                                                                                   "report/furnace_a/render.exr"))


def test_run_whose_report_cannot_be_written_exits_2(real, tmp_path, disk, capfd):
    out = tmp_path / "run"
    disk.fill(name=".staging-")  # the run's results.json is written, the studies' first image is not
    # a short ladder, no strategy or shadow-ray rows: the studies are still computed and written first, in 1.5 s not 4
    code, stdout, err = cli(capfd, "run", real["suite"], "--out", out, "--executor", "serial", "--quiet",
                            "--convergence-spp", "1,2", "--no-strategies", "--no-shadow-rays")
    assert code == 2 and "Traceback" not in err, err
    assert err.splitlines() == [err.strip()] and "No space left on device" in err and str(out) in err
    assert "tiny: 2/2 cases as expected" in stdout  # the suite's outcome is still printed
    assert read_results(out / "results.json")["complete"]
    assert sorted(p.name for p in out.iterdir()) == ["cases", "results.json"]  # no report, no staging folder


@pytest.mark.parametrize("folders", [False, True], ids=["files", "files-and-folders"])
def test_export_on_a_full_disk_leaves_no_folder(folders, tmp_path, disk, capfd):
    disk.fill(folders=folders)
    assert_one_line(*cli(capfd, "export", ROOT / "scenes" / "cornell-box.toml", "--format", "mitsuba-xml", "--out",
                         tmp_path / "new" / "export"), "No space left on device")
    assert listing(tmp_path) == []


@pytest.mark.parametrize("folders", [False, True], ids=["files", "files-and-folders"])
def test_import_on_a_full_disk_leaves_no_folder(folders, tmp_path, disk, capfd):
    pytest.importorskip("mitsuba")
    assert cli(capfd, "export", ROOT / "scenes" / "cutout-leaf.toml", "--format", "mitsuba-xml", "--out",
               tmp_path / "in")[0] == 0
    before = listing(tmp_path)
    disk.fill(folders=folders)
    assert_one_line(*cli(capfd, "import", tmp_path / "in" / "scene.xml", "--out", tmp_path / "new" / "imported"),
                    "No space left on device")
    assert listing(tmp_path) == before


@pytest.mark.parametrize("folders", [False, True], ids=["files", "files-and-folders"])
def test_report_on_a_full_disk_leaves_no_folder(folders, real, tmp_path, disk, capfd):
    path = write_results(tmp_path / "in", raw=real["text"])
    disk.fill(folders=folders)
    assert_one_line(*cli(capfd, "report", path, "--out", tmp_path / "new" / "report", *NO_STUDIES),
                    "No space left on device")
    assert listing(tmp_path) == ["in", "in/results.json"]


def test_ground_truth_on_a_full_disk_leaves_no_cache_folder(tmp_path, disk, capfd):
    scene = tmp_path / "scene.toml"
    scene.write_text((ROOT / "scenes" / "soft-shadows.toml").read_text().replace("width = ", "width = 8 #")
                     .replace("height = ", "height = 8 #"))
    cache = tmp_path / "cache" / "new"
    disk.fill(name=str(cache), after=1)  # the cache folder's write probe passes, the entry's files do not
    assert_one_line(*cli(capfd, "ground-truth", scene, "--spp", 2, "--chunk-spp", 2, "--mitsuba-variant",
                         "scalar_rgb", "--cache-dir", cache, "--quiet"),
                    f"{cache}: cannot write the ground-truth cache: No space left on device")
    assert listing(tmp_path) == ["scene.toml"]


def test_baseline_save_on_a_full_disk_is_one_line(real, tmp_path, disk, capfd):
    shutil.copytree(real["dir"] / "cases", tmp_path / "in" / "cases")  # --from reads renders in its folder only
    path = write_results(tmp_path / "in", raw=real["text"])
    before = listing(tmp_path)
    disk.fill(name="base.json")
    assert_one_line(*cli(capfd, "baseline", "save", real["suite"], "--from", path, "--out", tmp_path / "base.json"),
                    "base.json: cannot write: No space left on device")
    assert listing(tmp_path) == before


def test_staged_folder_replaces_an_old_folder_whole(tmp_path):
    target = tmp_path / "out"
    (target / "report" / "old-case").mkdir(parents=True)
    (target / "keep.txt").write_text("kept")
    (target / "index.html").write_text("old")
    with imageio.StagedFolder(target, "--out") as stage:
        imageio.make_folders(stage.root / "report" / "new-case")
        imageio.atomic_write_text(stage.root / "index.html", "new")
        stage.commit(last=("index.html",))
    assert listing(target) == ["index.html", "keep.txt", "report", "report/new-case"]
    assert (target / "index.html").read_text() == "new"
    with pytest.raises(HarnessError, match=r"^--out: boom$"), imageio.StagedFolder(target, "--out") as stage:
        imageio.atomic_write_text(stage.root / "index.html", "newer")
        raise HarnessError("--out", "boom")
    assert listing(target) == ["index.html", "keep.txt", "report", "report/new-case"]
    assert (target / "index.html").read_text() == "new"


# --------------------------------------------------------------------------------------------------------------------
# 5. The ground-truth cache: meta.json is covered by its checksum.


def _edit_meta(**changes):
    def edit(entry: Path) -> None:
        path = entry / "meta.json"
        meta = json.loads(path.read_text())
        meta.update(changes)
        path.write_text(json.dumps(meta, indent=2, sort_keys=True))

    return edit


def _edit_spp(entry: Path) -> None:
    path = entry / "meta.json"
    meta = json.loads(path.read_text())
    meta["spp"] = meta["spp"] * 100
    path.write_text(json.dumps(meta, indent=2, sort_keys=True))


def _without_meta_checksum(entry: Path) -> None:
    """As an older harness wrote it: its meta.json has the data files' checksums only."""
    path = entry / "meta.json"
    meta = json.loads(path.read_text())
    del meta["sha256"]["meta.json"]
    path.write_text(json.dumps(meta, indent=2, sort_keys=True))


META_EDITS = {
    "spp": _edit_spp,
    "chunks": _edit_meta(chunks=1000),
    "render-seconds": _edit_meta(render_seconds=1e-9),
    "new-key": _edit_meta(note="looks fine"),
    "no-meta-checksum": _without_meta_checksum,
}


@pytest.mark.parametrize("edit", list(META_EDITS), ids=list(META_EDITS))
def test_cache_load_refuses_an_edited_meta_json(edit, tmp_path):
    cache = Cache(tmp_path)
    estimate = Estimate(np.full((4, 4, 3), 0.5, np.float32), np.full((4, 4, 3), 0.01, np.float32), 8)
    cache.store("k", estimate, {"what": "test", "spp": 8, "chunks": 1, "render_seconds": 2.0})
    assert cache.load("k") is not None
    META_EDITS[edit](cache.entry("k"))
    assert cache.load("k") is None
    assert not cache.entry("k").exists() and not hidden(tmp_path)


def test_cache_entry_under_another_key_is_refused(tmp_path):
    cache = Cache(tmp_path)
    estimate = Estimate(np.full((4, 4, 3), 0.5, np.float32), np.full((4, 4, 3), 0.01, np.float32), 8)
    cache.store("k", estimate, {"spp": 8})
    os.rename(cache.entry("k"), cache.entry("other"))
    assert cache.load("other") is None


@pytest.mark.parametrize("edit", ["spp", "chunks"])
def test_edited_meta_json_is_rendered_again(edit, tmp_path, renders):  # noqa: F811 - renders: the fixture
    scene = small()
    good = gt(scene, tmp_path, spp=4, chunk_spp=2)
    assert renders.calls == 2 and len(entries(tmp_path)) == 3 and good.info["chunks"] == 2
    for entry in entries(tmp_path):  # every chunk and the merged entry
        META_EDITS[edit](entry)
    again = gt(scene, tmp_path, spp=4, chunk_spp=2)
    assert renders.calls == 4 and again.renders == 2 and not again.cached  # detected, rendered again
    assert again.spp == 4 and again.info["spp"] == 4 and again.info["chunks"] == 2
    assert_same(again, good)
    assert len(entries(tmp_path)) == 3 and not hidden(tmp_path)
    third = gt(scene, tmp_path, spp=4, chunk_spp=2)
    assert renders.calls == 4 and third.cached and third.info["chunks"] == 2
