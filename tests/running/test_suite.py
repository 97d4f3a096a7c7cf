"""Suites: loading with one-line errors, running as a gate, results.json, and the cache on a second run."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from conftest import ROOT

from harness.cli import main
from harness.core.errors import HarnessError
from harness.files.imageio import read_exr
from harness.files.results import read_results
from harness.running.cases import load_suite
from harness.running.schedule import run_suite
from reference_impl.mutants import ALL_MUTANTS, MEDIA_MUTANTS, TREE_MUTANTS

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

SUITES = ROOT / "suites"


def run_cli(capfd, *args):
    """``harness ARGS`` in this process: (exit code, stdout, stderr) as the file descriptors saw them (library chatter
    too). The process boundary itself (``python -m harness``, its exit codes, a closed stdout) is tested in
    tests/cli; here each run saves a process start and, for ``harness run``, a fork server's."""
    code = main([str(a) for a in args])
    out, err = capfd.readouterr()
    return code, out, err


def write_suite(tmp_path: Path, body: str, name: str = "s.toml") -> Path:
    path = tmp_path / name
    path.write_text(body.replace("SCENES", str(ROOT / "scenes")))
    return path


def test_repository_suites_load():
    smoke = load_suite(SUITES / "smoke.toml")
    canonical = load_suite(SUITES / "canonical.toml")
    assert len(smoke.cases) >= 5
    names = {c.scene.stem for c in canonical.cases}
    reference_scenes = {c.scene.stem for c in canonical.cases if c.renderer == "reference"}
    emitter_scenes = {"white-furnace", "white-furnace-albedo-1", "point-spot", "sun-sky", "envmap"}
    glossy_scenes = {"veach-mis", "cornell-box-specular", "underwater", "white-furnace-mirror",
                     "white-furnace-glass", "white-furnace-rough", "textured-cornell-box"}
    emitter_scenes |= {"textured-furnace", "leaning-plate"}
    glossy_scenes |= {"smooth-twins"}
    lambertian_mapped = {"mapped-plates"}
    camera_scenes = {"focused-plane", "orthographic-floor", "depth-of-field"}  # their cases: the camera's
    material_scenes = {"thin-glass-window", "plastic-cornell-box", "cutout-leaf", "principled-grid",
                       "material-balls-furnace", "material-balls"}  # their reference case and planted fault
    # the media scenes: their reference case and the media's planted faults; every media strategy, the stress variants
    # and the studies are suites/media.toml's (below), which the 10-minute budget leaves out of this one
    media_scenes = {"fog-box", "media-slab", "medium-furnace", "hg-cloud", "medium-emitter", "glass-medium"}
    assert reference_scenes == ({"cornell-box", "furnace", "soft-shadows", "multi-light"} | emitter_scenes
                                | glossy_scenes | lambertian_mapped | camera_scenes | material_scenes | media_scenes)
    assert names == reference_scenes
    # A glossy scene's strategies (direct = auto is mis there) on every glossy scene.
    for scene in glossy_scenes:
        seen = {c.settings.get("direct") for c in canonical.cases if c.scene.stem == scene and c.renderer == "reference"}
        assert None in seen and {"area", "bsdf"} <= seen, (scene, seen)
    # Every strategy of the reference appears on every Lambertian scene it renders (white-furnace-albedo-1: its
    # rho = 1 cases).
    # (issue 36's camera and material scenes have their reference case and planted faults here; the material scenes'
    # strategy rows and studies are suites/materials.toml's, below, which the 10-minute budget leaves out of this one)
    for scene in (reference_scenes - {"white-furnace-albedo-1"} - glossy_scenes - camera_scenes - material_scenes
                  - media_scenes):
        settings = [c.settings for c in canonical.cases if c.scene.stem == scene and c.renderer == "reference"]
        seen = {(k, v) for s in settings for k, v in s.items()}
        for pair in [("direct", "hemisphere-cosine"), ("direct", "hemisphere-uniform"), ("direct", "global-area"),
                     ("direct", "mis"), ("light_selection", "uniform"), ("hemisphere", "uniform"), ("rr", "fixed"),
                     ("rr", "off")]:
            one_light = scene in {"furnace", "white-furnace", "envmap", "textured-furnace",
                                  "mapped-plates"}  # uniform = by power
            # textured-furnace with direct = hemisphere-cosine: every sample is rho L exactly, its only noise the
            # pixel footprint's (1e-6 of the value), finer than the reference's icosphere approximates the analytic
            # sphere of the closed form (a facet moves a hit's texture coordinates by up to 3e-4 tan(theta) texels)
            exact = scene == "textured-furnace" and pair == ("direct", "hemisphere-cosine")
            assert pair in seen or exact or (one_light and pair == ("light_selection", "uniform")), (scene, pair)
    for scene in emitter_scenes - {"white-furnace-albedo-1", "textured-furnace", "leaning-plate"}:  # (suns alone)
        seen = {c.settings.get("env_sampling") for c in canonical.cases if c.scene.stem == scene}
        assert scene in {"point-spot"} or {"uniform", "cosine"} <= seen, (scene, seen)
    # Every planted fault is a case the verdict must fail: in the canonical suite, the light tree's in
    # suites/many-lights.toml (kept out of the canonical run's 10 minutes).
    mutant_cases = {c.settings.get("mutant") for c in canonical.cases if c.expect == "fail"}
    assert set(ALL_MUTANTS) - set(TREE_MUTANTS) <= mutant_cases
    many = load_suite(SUITES / "many-lights.toml")
    assert set(TREE_MUTANTS) <= {c.settings.get("mutant") for c in many.cases if c.expect == "fail"}
    assert {c.settings.get("light_selection", "power") for c in many.cases if c.expect == "pass"} == {
        "power", "uniform", "tree"}
    # The media suite: every media scene's reference case, each media strategy, each planted fault of the media.
    media = load_suite(SUITES / "media.toml")
    assert media_scenes <= {c.scene.stem for c in media.cases if c.name.endswith("/reference")}
    media_settings = {(k, v) for c in media.cases if c.expect == "pass" for k, v in c.settings.items()}
    assert {("medium_direct", "light"), ("medium_direct", "phase"), ("transmittance", "track")} <= media_settings
    assert set(MEDIA_MUTANTS) <= {c.settings.get("mutant") for c in media.cases if c.expect == "fail"}
    # The material scenes' direct-light strategies: light samples alone and BSDF samples alone beside the default,
    # against the canonical reference case's ground truth (the same film, spp and ground-truth spp).
    materials = load_suite(SUITES / "materials.toml")
    for scene in material_scenes:
        (reference,) = [c for c in canonical.cases if c.scene.stem == scene and c.name.endswith("/reference")]
        rows = [c for c in materials.cases if c.scene.stem == scene]
        assert {c.settings.get("direct") for c in rows} == {None, "area", "bsdf"}, scene
        assert {(c.spp, c.ground_truth_spp, c.film) for c in rows} == {
            (reference.spp, reference.ground_truth_spp, reference.film)}, scene


@pytest.mark.parametrize("body,where", [
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nspp = 4\nseconds = 1\n', "cases[0]"),
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nsppp = 4\n', "did you mean 'spp'"),
    ('[[cases]]\nscene = "nope"\n', "cases[0].scene"),
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nrenderer = "blender"\n', "cases[0].renderer"),
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nexpect = "maybe"\n', "cases[0].expect"),
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nstudies = "no"\n', "cases[0].studies"),
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nagainst = "oracle"\n', "cases[0].against"),
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nthresholds = { rmse = "low" }\n', "cases[0].thresholds.rmse"),
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nspp = -3\n', "cases[0].spp"),
    ('[defaults]\nfilm = { width = 0 }\n[[cases]]\nscene = "SCENES/furnace.toml"\n', "film.width"),
    ('[[cases]]\nscene = "SCENES/furnace.toml"\n[[cases]]\nname = "b"\nscene = "SCENES/furnace.toml"\n'
     'settings = { sampler = "halton" }\n', "cases[1].settings.sampler"),  # refused before case 0 runs
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nrenderer = "mitsuba"\nspp = 8\nsettings = { sampler = "ldsampler" }\n',
     "cases[0].settings.sampler"),  # Mitsuba would round 8 to 16
    ('[[cases]]\nscene = "SCENES/furnace.toml"\nagainst = { renderer = "reference", spp = 4, settings = { rr = "maybe" } }\n',
     "cases[0].against.settings.rr"),
    ('name = "x"\n', "cases"),
    ('[[cases]\n', "invalid TOML"),
])
def test_bad_suites_are_one_line_errors(tmp_path, capfd, body, where):
    path = write_suite(tmp_path, body)
    with pytest.raises(HarnessError) as info:
        load_suite(path)
    assert str(path) in str(info.value) and where in str(info.value)
    code, stdout, stderr = run_cli(capfd, "run", str(path), "--out", str(tmp_path / "out"))
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr
    assert not (tmp_path / "out" / "results.json").exists()


def test_smoke_suite_gates_and_second_run_renders_nothing(tmp_path, capfd):
    cache = tmp_path / "cache"
    out = tmp_path / "out"
    # the studies (30 s of timed renders here) are the report tests' part (tests/report/test_report.py)
    code, stdout, stderr = run_cli(capfd, "run", SUITES / "smoke.toml", "--out", out, "--quiet", "--no-convergence",
                                   "--no-strategies", "--no-shadow-rays", "--cache-dir", cache)
    assert code == 0, stdout + stderr
    first = json.loads((out / "results.json").read_text())
    assert first["summary"]["ok"] == first["summary"]["cases"]
    assert first["summary"]["mitsuba_renders"] > 0
    for case in first["cases"]:
        assert case["status"] in ("pass", "fail") and case["ok"]
        assert {"rmse", "relmse", "psnr", "ssim", "flip", "bias"} <= set(case["metrics"])
        assert case["verdict"]["verdict"] in ("pass", "fail")
        assert case["render"]["seconds"] > 0 and Path(case["render"]["exr"]).is_file()
        assert "cached" in case["ground_truth"]
    # the second run checks the cache and the verdicts only: the first one's studies and report are enough, and
    # its executor (the default, a local worker); this one renders in this process, whose kernels are loaded
    code, stdout, _ = run_cli(capfd, "run", SUITES / "smoke.toml", "--out", out, "--quiet", "--fresh",
                              "--no-report", "--cache-dir", cache, "--executor", "serial")
    assert code == 0
    second = json.loads((out / "results.json").read_text())
    assert second["summary"]["mitsuba_renders"] == 0, second["summary"]
    assert all(c["ground_truth"]["cached"] or c["ground_truth"]["source"] == "closed-form" for c in second["cases"])
    assert "0 Mitsuba renders" in stdout
    assert [c["verdict"]["verdict"] for c in first["cases"]] == [c["verdict"]["verdict"] for c in second["cases"]]


def test_a_failing_case_makes_the_run_exit_1(tmp_path, capfd):
    path = write_suite(tmp_path, '''
[[cases]]
name = "furnace/energy-loss"
scene = "SCENES/furnace.toml"
settings = { mutant = "energy-loss-2pct" }
spp = 16
film = { width = 16, height = 16 }
''')
    # in this process (serial): the default executor's fork server and worker are the smoke run's to start
    code, stdout, _ = run_cli(capfd, "run", path, "--out", tmp_path / "out", "--quiet", "--no-report", "--executor",
                              "serial")
    assert code == 1
    assert "unexpected: furnace/energy-loss" in stdout
    record = json.loads((tmp_path / "out" / "results.json").read_text())["cases"][0]
    assert record["status"] == "fail" and record["verdict"]["verdict"] == "fail"
    # the verdict's tile maps beside the render, named in the record, and read back by the schema check
    folder = tmp_path / "out" / "cases" / "furnace_energy-loss"
    assert record["verdict_maps"] == {"pvalue": str(folder / "pvalue.exr"), "failing": str(folder / "failing.exr")}
    read_results(tmp_path / "out" / "results.json")
    p = read_exr(folder / "pvalue.exr").image
    worst = record["verdict"]["worst_tile"]
    assert p.shape == (16, 16, 3)
    assert p[worst["y"], worst["x"], "RGB".index(worst["channel"])] == pytest.approx(
        math.erfc(abs(worst["z_normal"]) / math.sqrt(2)), rel=1e-5)


def test_thresholds_fail_a_case(tmp_path):
    path = write_suite(tmp_path, '''
[[cases]]
scene = "SCENES/furnace.toml"
spp = 4
film = { width = 16, height = 16 }
thresholds = { rmse = 1e-9 }
''')
    suite = load_suite(path)
    results = run_suite(suite, tmp_path / "out")
    case = results["cases"][0]
    assert case["status"] == "fail" and case["thresholds_broken"] and "rmse" in case["reason"]


def test_time_budget_merges_chunks(tmp_path):
    path = write_suite(tmp_path, '''
[[cases]]
scene = "SCENES/furnace.toml"
seconds = 0.3
chunk_spp = 2
film = { width = 16, height = 16 }
''')
    results = run_suite(load_suite(path), tmp_path / "out")
    case = results["cases"][0]
    assert case["status"] == "pass", case.get("reason")
    assert case["render"]["spp"] >= 2 and case["render"]["spp"] % 2 == 0
    assert case["render"]["seconds"] >= 0.3


def test_a_crashing_renderer_fails_its_case_and_the_suite_goes_on(tmp_path, monkeypatch):
    from harness import renderers

    class Broken:
        name = "broken"

        def render(self, scene, request):
            raise RuntimeError("segfault simulated")

    monkeypatch.setitem(renderers._RENDERERS, "broken", Broken)
    path = write_suite(tmp_path, '''
[defaults]
spp = 4
film = { width = 8, height = 8 }
[[cases]]
name = "crashes"
scene = "SCENES/furnace.toml"
renderer = "broken"
[[cases]]
name = "works"
scene = "SCENES/furnace.toml"
''')
    results = run_suite(load_suite(path), tmp_path / "out")
    crashed, worked = results["cases"]
    assert crashed["status"] == "error" and "segfault simulated" in crashed["reason"] and not crashed["ok"]
    assert worked["status"] == "pass"
    saved = json.loads((tmp_path / "out" / "results.json").read_text())
    assert saved["summary"]["errors"] == 1 and saved["summary"]["unexpected"] == ["crashes"]


def test_compare_cli(tmp_path, capfd):
    """`harness compare` judges a render against a reference: exit 0 on pass, 1 on fail, JSON on request. In this
    process (the commands' subprocess paths are covered by tests/cli): four process starts fewer."""
    scene = str(ROOT / "scenes" / "furnace.toml")
    for name, seed, extra in (("a", 1, []), ("b", 2, []), ("bad", 3, ["--set", "mutant=energy-loss-2pct"])):
        assert main(["render", scene, "--spp", "8", "--seed", str(seed), "--out", str(tmp_path / f"{name}.exr"),
                     "--quiet", *extra]) == 0
    capfd.readouterr()
    assert main(["compare", str(tmp_path / "a.exr"), str(tmp_path / "b.exr"), "--json"]) == 0
    report = json.loads(capfd.readouterr().out)
    assert report["verdict"]["verdict"] == "pass" and "rmse" in report["metrics"]
    assert main(["compare", str(tmp_path / "bad.exr"), str(tmp_path / "b.exr")]) == 1
    assert "verdict: fail" in capfd.readouterr().out
    code, stdout, stderr = run_cli(capfd, "compare", str(tmp_path / "missing.exr"), str(tmp_path / "b.exr"))
    assert code == 2 and "missing.exr" in stderr and len(stderr.strip().splitlines()) == 1


def test_a_suite_anywhere_names_canonical_scenes_by_name(tmp_path, monkeypatch):
    """A user's suite outside the checkout, run from another folder, still finds ``scene = "furnace"``."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "mine.toml").write_text('[[cases]]\nscene = "furnace"\n')
    suite = load_suite(tmp_path / "mine.toml")
    assert suite.cases[0].scene.resolve() == (ROOT / "scenes" / "furnace.toml").resolve()
    (tmp_path / "bad.toml").write_text('[[cases]]\nscene = "furnaces"\n')
    with pytest.raises(HarnessError) as err:
        load_suite(tmp_path / "bad.toml")
    assert "furnaces" in str(err.value)
