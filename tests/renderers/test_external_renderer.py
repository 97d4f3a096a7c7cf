"""External renderers (harness/renderers/external.py): renderer files, lookup by path / name / entry point, the
repeated-seed variance, every failure mode, and the whole path a new user takes (export, command template, suite,
report, baseline) with a small Mitsuba-XML renderer, whose planted 3 % energy loss must fail the suite."""

from __future__ import annotations

import importlib.metadata
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from fake_exr import copy_beside, gaussian_image
from harness.cli import main
from harness.core.errors import HarnessError
from harness.renderers import RenderRequest, get_renderer, renderer_names
from harness.renderers import external
from harness.renderers.external import ExternalRendererError, combine_repeats, load_spec
from harness.scene import load_scene

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "mitsuba_xml_renderer.py"

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

# A fake renderer for the failure modes: no Mitsuba, fast. Pixel values N(0.5, 0.1^2) seeded by --seed
# (fake_exr.gaussian_image). It reports its render time (<out>.json), so a render is its runs alone: no three 1-spp
# probe runs to measure its start-up (the start-up path is _timed_renderer's, below). Neither numpy nor the harness
# (tests/fake_exr.py): a run is the interpreter's start.
FAKE = r'''
import os, subprocess, sys, time
start = time.perf_counter()
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
mode, out = args["--mode"], args["--out"]
w, h = int(args["--width"]), int(args["--height"])
if mode == "exit3":
    print("loading scene\nfatal: out of unobtainium", file=sys.stderr)
    sys.exit(3)
if mode == "hang":
    child = subprocess.Popen(["sleep", "60"])
    open(args["--pidfile"], "w").write(str(child.pid))
    time.sleep(60)
if mode == "noexr":
    sys.exit(0)
if mode == "garbage":
    open(out, "wb").write(b"not an exr")
    sys.exit(0)
from fake_exr import constant_image, gaussian_image, write_exr

if mode == "wrongsize":
    w += 1
image = gaussian_image(int(args["--seed"]), w, h, 0.5, 0.1)
write_exr(out, image, constant_image(0.01 / int(args["--spp"]), w, h) if mode == "variance" else None)
open(out + ".json", "w").write('{"render_seconds": %r}' % (time.perf_counter() - start))
'''


def _renderer_file(folder: Path, name: str, mode: str, timeout: float = 60, repeats: int = 4, extra=()) -> Path:
    script = folder / "fake_renderer.py"
    script.write_text(FAKE)
    copy_beside(script)
    path = folder / f"{name}.toml"
    command = ["{python}", str(script), "--mode", mode, "--out", "{out}", "--seed", "{seed}", "--spp", "{spp}",
               "--width", "{width}", "--height", "{height}", *extra]
    path.write_text(f"command = {json.dumps(command)}\ntimeout = {timeout}\nrepeats = {repeats}\n")
    return path


@pytest.fixture()
def small_scene():
    import dataclasses

    from reference_impl import Film

    scene = load_scene(ROOT / "scenes" / "furnace.toml")
    return dataclasses.replace(scene, film=Film(6, 4, "box"))


# ---- renderer files ----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("text, key", [
    ("", "command"),
    ("command = []", "command"),
    ("command = 'render {out}'", "command"),
    ("command = ['render', '{scene}', '{out}']", "command"),
    ("command = ['render', '{scene_xml}']", "command"),
    ("command = ['r', '{out}']\ntimeout = -1", "timeout"),
    ("command = ['r', '{out}']\nrepeats = 1", "repeats"),
    ("command = ['r', '{out}']\nrepeat = 4", "repeat"),
    ("command = ['r', '{out}'", None),
])
def test_bad_renderer_file_is_one_line_user_error(tmp_path, text, key):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(HarnessError) as info:
        load_spec(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path))
    if key:
        assert info.value.where == f"{path}: {key}"


def test_cli_reports_missing_renderer_file_in_one_line(tmp_path, capsys):
    code = main(["render", str(ROOT / "scenes" / "furnace.toml"), "--renderer", str(tmp_path / "nope.toml"),
                 "--spp", "1", "--out", str(tmp_path / "x.exr")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "nope.toml" in err and "--renderer" in err
    assert not (tmp_path / "x.exr").exists()


def test_renderer_lookup_by_path_name_and_entry_point(tmp_path, monkeypatch):
    assert isinstance(get_renderer(str(ROOT / "renderers" / "mitsuba-scalar-cli.toml")), external.ExternalRenderer)
    assert "mitsuba-scalar-cli" in renderer_names()  # renderers/NAME.toml of this checkout
    assert get_renderer("mitsuba-scalar-cli").name == "mitsuba-scalar-cli"
    (tmp_path / "renderers").mkdir()
    _renderer_file(tmp_path / "renderers", "my-fake", "variance")
    monkeypatch.chdir(tmp_path)  # ./renderers/NAME.toml
    assert get_renderer("my-fake").spec.path == (tmp_path / "renderers" / "my-fake.toml").resolve()
    point = importlib.metadata.EntryPoint(name="toy", value="harness.renderers.reference:ReferenceRenderer",
                                          group=external.ENTRY_POINT_GROUP)
    monkeypatch.setattr(external, "entry_points", lambda: {"toy": point})
    assert "toy" in renderer_names()
    assert type(get_renderer("toy")).__name__ == "ReferenceRenderer"
    with pytest.raises(HarnessError, match="my-fake, reference, toy or the path"):
        get_renderer("nonesuch")


# ---- variance from repeated seeds -----------------------------------------------------------------------------------


def test_repeats_give_unbiased_variance_with_k_minus_1_dof():
    """Normal pixels: (mean - mu) / sqrt(var) is exactly t(K-1) distributed. Over n = 12288 pixel-channels the
    count of |t| > t_0.975(K-1) is Binomial(n, 0.05); accepted within 5 standard deviations (false alarm < 1e-6).
    Taking the variance as exact (normal quantile 1.96) would exceed the 5 % by ~9 points: this test would fail."""
    rng = np.random.default_rng(20261126)
    k, mu, sigma, shape = 4, 2.0, 0.3, (64, 64, 3)
    mean, var, dof = combine_repeats([mu + sigma * rng.standard_normal(shape) for _ in range(k)])
    assert dof == k - 1
    t = (mean - mu) / np.sqrt(var)
    n = t.size
    hits = int(np.count_nonzero(np.abs(t) > stats.t.ppf(0.975, dof)))
    assert abs(hits - 0.05 * n) < 5 * np.sqrt(n * 0.05 * 0.95), hits
    assert np.count_nonzero(np.abs(t) > 1.96) > 0.05 * n + 5 * np.sqrt(n * 0.05 * 0.95)  # why dof matters
    # E[var] = sigma^2 / K; sd of the mean of var: sqrt(2 / (K-1)) sigma^2 / K / sqrt(n); 5 sd
    assert abs(var.mean() - sigma**2 / k) < 5 * np.sqrt(2 / (k - 1)) * sigma**2 / k / np.sqrt(n)


def test_verdict_with_repeat_variance_keeps_its_false_alarm_rate():
    """300 null images (K = 4 repeats, dof 3) judged at alpha = 0.05 against the exact mean, with 2x2 tiles (so a
    tile's pooled variance has only ~12 dof and the t-correction matters): false alarms are Binomial(300, <= 0.05);
    accepted up to 15 + 5 sd = 33 (false alarm of this test < 1e-6). Without the dof (variance taken as exact)
    the same verdict fires far more often (about 250 of 300), which the second count shows. With 8x8 tiles the
    pooled variance has ~190 dof and both are calibrated."""
    from harness.judges.verdict import verdict

    rng = np.random.default_rng(7)
    k, mu, trials = 4, 1.0, 300
    alarms = naive_alarms = 0
    for _ in range(trials):
        mean, var, dof = combine_repeats([mu + 0.2 * rng.standard_normal((32, 32, 3)) for _ in range(k)])
        ref, ref_var = np.full_like(mean, mu), np.zeros_like(mean)
        alarms += not verdict(mean, var, ref, ref_var, tile=2, alpha=0.05, test_dof=dof).passed
        naive_alarms += not verdict(mean, var, ref, ref_var, tile=2, alpha=0.05).passed
    assert alarms <= 0.05 * trials + 5 * np.sqrt(trials * 0.05 * 0.95), alarms
    assert naive_alarms > 0.05 * trials + 5 * np.sqrt(trials * 0.05 * 0.95), naive_alarms


def test_fake_renderer_repeats_and_variance_channels(tmp_path, small_scene):
    runs = get_renderer(str(_renderer_file(tmp_path, "novar", "plain"))).render(
        small_scene, RenderRequest(spp=3, seed=11))
    assert runs.spp == 12 and runs.info["runs"] == 4 and runs.info["variance_dof"] == 3
    assert len(set(runs.info["seeds"])) == 4 and runs.info["seeds"][0] == 11
    # what the fake renderer drew for each seed (and wrote as float32)
    images = [np.array(gaussian_image(seed, 6, 4, 0.5, 0.1), np.float32).astype(np.float64)
              for seed in runs.info["seeds"]]
    mean, var, _ = combine_repeats(images)
    np.testing.assert_allclose(runs.image, mean, rtol=1e-6)
    np.testing.assert_allclose(runs.variance, var, rtol=1e-5)
    one = get_renderer(str(_renderer_file(tmp_path, "var", "variance"))).render(
        small_scene, RenderRequest(spp=5, seed=2))
    assert one.spp == 5 and one.info["runs"] == 1 and one.info["variance_dof"] == 4
    np.testing.assert_allclose(one.variance, 0.002, rtol=1e-6)
    with pytest.raises(HarnessError, match="--set x"):
        get_renderer(str(tmp_path / "var.toml")).render(small_scene, RenderRequest(spp=1, settings={"x": "1"}))


def test_seeds_handed_to_the_command_fit_a_signed_32_bit_integer(tmp_path, small_scene):
    """Cycles (and most C programs) take a signed 32-bit seed: every ``{seed}`` is in 0 .. 2^31 - 1, the repeat
    seeds included (unfolded, ``repeat_seed(1, 3)`` was 4155639228), and a large ``--seed`` is folded too."""
    assert external.pass_seed(1, 3) > external.MAX_SEED  # the case the fold is for
    seeds = [external.repeat_seed(s, i) for s in range(200) for i in range(1, 8)]
    assert all(0 <= s <= external.MAX_SEED for s in seeds) and len(set(seeds)) == len(seeds)
    runs = get_renderer(str(_renderer_file(tmp_path, "novar", "plain"))).render(
        small_scene, RenderRequest(spp=1, seed=2**32 + 5))
    assert runs.info["seeds"][0] == (2**32 + 5) % 2**31
    assert all(0 <= s <= external.MAX_SEED for s in runs.info["seeds"])


# ---- failures -------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("mode, message", [
    ("exit3", "exited with code 3: loading scene | fatal: out of unobtainium"),
    ("noexr", "wrote no EXR"),
    ("garbage", "unreadable EXR: not an OpenEXR file"),
    ("wrongsize", "wrote a 7x4 EXR; expected 6x4"),
])
def test_failed_runs_raise_with_the_reason(tmp_path, small_scene, mode, message):
    renderer = get_renderer(str(_renderer_file(tmp_path, mode, mode)))
    with pytest.raises(ExternalRendererError, match="renderer") as info:
        renderer.render(small_scene, RenderRequest(spp=1))
    assert message in str(info.value) and "\n" not in str(info.value)


def test_timeout_kills_the_process_group(tmp_path, small_scene):
    pidfile = tmp_path / "child.pid"
    renderer = get_renderer(str(_renderer_file(tmp_path, "hang", "hang", timeout=2, extra=("--pidfile", str(pidfile)))))
    start = time.perf_counter()
    with pytest.raises(ExternalRendererError, match="timed out after 2 s"):
        renderer.render(small_scene, RenderRequest(spp=1))
    assert time.perf_counter() - start < 20
    child = int(pidfile.read_text())
    deadline = time.time() + 5
    while time.time() < deadline:  # the grandchild (sleep 60) went with its group; allow for reaping
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            break
        status = Path(f"/proc/{child}/stat")
        if status.exists() and status.read_text().split()[2] == "Z":
            break
        time.sleep(0.05)
    else:
        pytest.fail(f"child {child} of the timed-out renderer still runs")


def test_suite_records_a_failing_renderer_as_error_and_goes_on(tmp_path):
    from harness.running.cases import load_suite
    from harness.running.schedule import run_suite

    _renderer_file(tmp_path, "broken", "exit3")
    _renderer_file(tmp_path, "fine", "variance")
    (tmp_path / "suite.toml").write_text(
        f'[defaults]\nfilm = {{ width = 8, height = 8 }}\nspp = 4\nagainst = "closed-form"\n'
        f'[[cases]]\nname = "broken"\nscene = "{ROOT / "scenes" / "furnace.toml"}"\nrenderer = "broken.toml"\n'
        f'[[cases]]\nname = "fine"\nscene = "{ROOT / "scenes" / "furnace.toml"}"\nrenderer = "fine.toml"\n'
        'expect = "fail"\n')
    suite = load_suite(tmp_path / "suite.toml")
    assert suite.cases[0].renderer == str((tmp_path / "broken.toml").resolve())  # relative to the suite's folder
    results = run_suite(suite, tmp_path / "out")
    broken, fine = results["cases"]
    assert broken["status"] == "error" and not broken["ok"]
    assert broken["reason"].startswith("ExternalRendererError: renderer 'broken' exited with code 3")
    assert fine["status"] == "fail" and fine["ok"]  # 0.5 is not the furnace's radiance: the verdict fails it
    (tmp_path / "bad.toml").write_text('[[cases]]\nscene = "furnace"\nrenderer = "missing.toml"\n')
    with pytest.raises(HarnessError, match="cases\\[0\\].renderer: no renderer file 'missing.toml'"):
        load_suite(tmp_path / "bad.toml")


# ---- the whole path, as a new user takes it --------------------------------------------------------------------------

SUITE = """
name = "{name}"
[defaults]
film = {{ width = 32, height = 32 }}
spp = 16                  # per run; the renderer writes no variance, so 4 runs (repeats) with distinct seeds
ground_truth_spp = 512
[[cases]]
name = "cornell-box/mine"
scene = "{scene}"
renderer = "{renderer}"
"""


def test_bring_your_renderer_end_to_end(tmp_path, capsys, monkeypatch):
    """export -> command template -> suite -> report -> baseline, with examples/mitsuba_xml_renderer.py (Mitsuba
    scalar_rgb on the exported XML); then the same renderer with a planted 3 % energy loss fails the suite.

    The good run passes unless the verdict false-alarms (probability alpha = 1e-3 per case); the planted loss is
    caught by a wide margin (omnibus p ~ 1e-14 at these sizes). Seeds are fixed, so the outcome is reproducible."""
    # each renderer's start-up is measured with one probe run, not the median of three (a Mitsuba process each, 0.5
    # CPU-s): the render times are not looked at here (test_start_up_is_measured_and_subtracted's are)
    monkeypatch.setattr(external, "STARTUP_PROBES", 1)
    scene = ROOT / "scenes" / "cornell-box.toml"
    # 1. export: the scene as Mitsuba XML, and the example renderer renders it as it stands
    assert main(["export", str(scene), "--format", "mitsuba-xml", "--out", str(tmp_path / "xml")]) == 0
    subprocess.run([sys.executable, str(EXAMPLE), str(tmp_path / "xml" / "scene.xml"), "--spp", "1",
                    "--out", str(tmp_path / "direct.exr")], check=True, timeout=120)
    from harness.files.imageio import read_exr

    direct = read_exr(tmp_path / "direct.exr")
    assert direct.image.shape == (256, 256, 3) and direct.variance is None and direct.image.mean() > 0.05
    # 2. the command template: renderers/mitsuba-scalar-cli.toml (a name), and a faulty copy beside the suite
    lossy = tmp_path / "lossy.toml"
    lossy.write_text((ROOT / "renderers" / "mitsuba-scalar-cli.toml").read_text()
                     .replace("{here}/../examples", str(EXAMPLE.parent))
                     .replace('"scalar_rgb"]', '"scalar_rgb", "--energy-loss", "0.03"]'))
    (tmp_path / "good.toml").write_text(SUITE.format(name="byor", scene=scene, renderer="mitsuba-scalar-cli"))
    (tmp_path / "faulty.toml").write_text(SUITE.format(name="byor", scene=scene, renderer="lossy.toml"))
    # 3. the suite, 4. its report
    out = tmp_path / "run"
    assert main(["run", str(tmp_path / "good.toml"), "--out", str(out), "--executor", "serial", "--quiet",
                 "--no-report"]) == 0
    good = json.loads((out / "results.json").read_text())["cases"][0]
    assert good["status"] == "pass" and good["render"]["spp"] == 64
    assert good["verdict"]["variance_dof"]["test"] == 3.0  # K - 1 from the 4 runs
    assert main(["report", str(out / "results.json"), "--no-convergence", "--no-shadow-rays", "--no-strategies",
                 "--quiet"]) == 0
    assert "cornell-box/mine" in (out / "index.html").read_text()
    # 5. the baseline of the good run; the faulty renderer, run against it, fails the suite (caught by the verdict)
    assert main(["baseline", "save", str(tmp_path / "good.toml"), "--from", str(out / "results.json"),
                 "--out", str(tmp_path / "baseline.json")]) == 0
    capsys.readouterr()
    code = main(["run", str(tmp_path / "faulty.toml"), "--out", str(tmp_path / "faulty"), "--executor", "serial",
                 "--no-report", "--baseline", str(tmp_path / "baseline.json")])
    printed = capsys.readouterr()
    assert code == 1, printed
    bad = json.loads((tmp_path / "faulty" / "results.json").read_text())["cases"][0]
    assert bad["status"] == "fail" and not bad["ok"]
    assert "baseline" in printed.out and isinstance(bad.get("baseline"), dict)  # the baseline gate ran
    print(f"good: {good['status']} ({good['verdict']['reason']}); global z {good['verdict']['global_bias']['z']}")
    print(f"3% loss: {bad['status']} ({bad['reason']}); global z {bad['verdict']['global_bias']['z']}")


# ---- timing: the renderer's own clock, or the start-up measured and subtracted -----------------------------------

# A renderer that spends --startup seconds starting (imports, scene loading) and --work seconds per spp per 24
# pixels rendering, and reports (--report header | json | none) its render time and --dof.
TIMED = r'''
import json, sys, time
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
time.sleep(float(args["--startup"]))
from fake_exr import constant_image, gaussian_image, write_exr
w, h, spp = int(args["--width"]), int(args["--height"]), int(args["--spp"])
work = float(args["--work"]) * spp * w * h / 24
time.sleep(work)
image = gaussian_image(int(args["--seed"]), w, h, 0.5, 0.1)
own = {"render_seconds": args.get("--claim", str(work)), "variance_dof": args.get("--dof", str(spp - 1))}
write_exr(args["--out"], image, constant_image(0.01 / spp, w, h), own if args["--report"] == "header" else None)
if args["--report"] == "json":
    open(args["--out"] + ".json", "w").write(json.dumps({k: float(v) for k, v in own.items()}))
'''


def _timed_renderer(folder: Path, name: str, report: str, startup: float, work: float, extra=()) -> Path:
    script = folder / "timed_renderer.py"
    script.write_text(TIMED)
    copy_beside(script)
    path = folder / f"{name}.toml"
    command = ["{python}", str(script), "--report", report, "--startup", str(startup), "--work", str(work),
               "--out", "{out}", "--seed", "{seed}", "--spp", "{spp}", "--width", "{width}", "--height", "{height}",
               *extra]
    path.write_text(f"command = {json.dumps(command)}\n")
    return path


@pytest.mark.parametrize("report", ["header", "json"])
def test_render_time_and_dof_reported_by_the_renderer(tmp_path, small_scene, report):
    """A renderer that reports ``render_seconds`` and ``variance_dof`` (EXR header or ``<out>.json``) is taken at
    its word: 0.5 s of start-up are in the run's wall time only."""
    result = get_renderer(str(_timed_renderer(tmp_path, "own", report, 0.5, 0.01, ("--dof", "7")))).render(
        small_scene, RenderRequest(spp=3, seed=1))
    assert result.info["time_from"] == "renderer" and result.info["startup_seconds"] is None
    assert result.seconds == pytest.approx(0.03) and result.info["wall_seconds"] > 0.5
    assert result.info["variance_dof"] == 7 and result.spp == 3


def test_start_up_is_measured_and_subtracted(tmp_path, small_scene, monkeypatch):
    """Without a reported time, the start-up (1.5 s of sleep plus the script's imports) is measured with 1-spp runs
    on a 1x1 film and subtracted: what is left is the 0.4 s of rendering (4 spp x 0.1 s at 6x4 pixels), and a render
    that subtracted nothing would read 1.9 s and more. The bound sits halfway, at 1.15 s: the scatter of process
    start on a loaded machine (the imports of one run against the median of three probes) reached 0.48 s under a
    parallel test run, which a start-up of 0.5 s could not tell from no subtraction at all."""
    renderer = get_renderer(str(_timed_renderer(tmp_path, "quiet", "none", 1.5, 0.1)))
    result = renderer.render(small_scene, RenderRequest(spp=4, seed=1))
    assert result.info["time_from"].startswith("start-up subtracted (") and "1x1 film" in result.info["time_from"]
    startup = result.info["startup_seconds"]
    assert startup > 1.5 and result.info["wall_seconds"] > 1.9
    assert result.seconds == pytest.approx(max(0.0, result.info["wall_seconds"] - startup), abs=1e-9)
    assert 0.05 < result.seconds < 1.15, (result.seconds, startup, result.info["wall_seconds"])
    assert result.info["variance_dof"] == 3  # spp - 1: nothing reported
    # measured once per renderer file and scene: asked again (the file loaded anew), it runs nothing. (Not a second
    # render: 2 s of sleep, and one that fell below the start-up under load would re-measure it, rightly; that path
    # is test_a_start_up_measured_too_long_is_measured_again's.)
    def ran(*args, **kwargs):
        raise AssertionError("the start-up was measured again")

    monkeypatch.setattr(external, "_run", ran)
    assert get_renderer(str(tmp_path / "quiet.toml")).startup_seconds(small_scene)[0] == startup


@pytest.mark.parametrize("extra, message", [
    (("--claim", "-1"), "reported render_seconds = '-1'; expected a non-negative number"),
    (("--claim", "soon"), "reported render_seconds = 'soon'"),
    (("--dof", "2.5"), "reported variance_dof = '2.5'; expected a positive integer"),
])
def test_bad_reported_values_fail_the_run_in_one_line(tmp_path, small_scene, extra, message):
    renderer = get_renderer(str(_timed_renderer(tmp_path, "liar", "header", 0.0, 0.0, extra)))
    with pytest.raises(ExternalRendererError) as info:
        renderer.render(small_scene, RenderRequest(spp=2, seed=1))
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_start_up_measured_too_long_is_measured_again(tmp_path, small_scene, monkeypatch):
    """A run that takes less than the start-up measured proves the probes were slowed (the machine's load): the
    start-up is measured once more and the smaller kept, instead of every later render reading 0 s."""
    # 0.3 s per spp of rendering: a signal above the scatter of start-up, which 0.05 s drowned in (it read 0 s)
    renderer = get_renderer(str(_timed_renderer(tmp_path, "slowprobe", "none", 0.3, 0.3)))
    monkeypatch.setitem(external._STARTUP, (renderer.spec, str(small_scene.path), small_scene.name,
                                            small_scene.max_depth, (6, 4)), (5.0, "a slowed probe"))
    result = renderer.render(small_scene, RenderRequest(spp=2, seed=1))
    assert "measured twice (5 s," in result.info["time_from"] and result.info["startup_seconds"] < 5.0
    assert 0.0 < result.seconds < result.info["wall_seconds"]
