"""Hostile input to suites and runs (issue 12, docs/robustness.md): every problem a run would only meet halfway
through (a name too long for a folder, a variant that breaks the scene, one sample per pixel, an unwritable or busy
output folder) is one line and exit code 2 before the first render; case folders cannot escape OUT or collide."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from test_hostile_input import SCENE, assert_one_line, cli

from harness.running import runstate
from harness.core.errors import HarnessError
from harness.running.cases import load_suite, slug
from harness.scene.variants import parse_variant

UNWRITABLE = Path("/proc")  # a folder that exists and takes no new file, even for root
needs_proc = pytest.mark.skipif(not UNWRITABLE.is_dir(), reason="no /proc on this system")
CASE = '[[cases]]\nscene = "scene.toml"\nspp = 2\nagainst = { renderer = "reference", spp = 2 }\n'


@pytest.fixture
def folder(tmp_path) -> Path:
    """tmp/scene.toml: a valid tiny scene (16 x 16, one light)."""
    (tmp_path / "scene.toml").write_text(SCENE)
    return tmp_path


@pytest.fixture
def no_render(monkeypatch) -> list:
    """Every case that starts to run is recorded here and fails: the checks under test must come first."""
    started = []

    def run_case(case, *args, **kwargs):
        started.append(case.name)
        raise AssertionError(f"case {case.name!r} ran")

    monkeypatch.setattr("harness.running.judge.run_case", run_case)
    monkeypatch.setattr("harness.running.calibrate.run_case", run_case)
    return started


def write_suite(folder: Path, body: str, name: str = "s.toml") -> Path:
    path = folder / name
    path.write_text(body)
    return path


def refused(path: Path, *fragments: str) -> str:
    """load_suite(path) raises one line that starts with the file and holds every fragment."""
    with pytest.raises(HarnessError) as info:
        load_suite(path)
    text = str(info.value)
    assert "\n" not in text and text.startswith(f"{path}: "), text
    for fragment in fragments:
        assert fragment in text, (fragment, text)
    return text


# ---- item 3: a scene path too long for the file system ----------------------------------------------------------


def test_scene_path_too_long_is_one_line_naming_the_key(folder, capfd, no_render):
    suite = write_suite(folder, f'[[cases]]\nscene = "{"a" * 3000}"\n')
    line = assert_one_line(*cli(capfd, "run", suite, "--out", folder / "out", "--executor", "serial"),
                           f"{suite}: cases[0].scene:", "File name too long")
    assert len(line) < 400
    assert not (folder / "out").exists() and no_render == []


def test_renderer_path_too_long_is_one_line_naming_the_key(folder):
    refused(write_suite(folder, f'[[cases]]\nscene = "scene.toml"\nrenderer = "{"r" * 3000}.toml"\n'),
            "cases[0].renderer:", "File name too long")


# ---- item 4 and 14: unwritable output folders, found before anything runs ----------------------------------------


@needs_proc
def test_calibrate_out_that_cannot_be_created(folder, capfd, no_render):
    suite = write_suite(folder, CASE)
    assert_one_line(*cli(capfd, "calibrate", suite, "--out", UNWRITABLE / "harness-x", "--seeds", 2), "--out",
                    "cannot create")
    assert no_render == []


@needs_proc
def test_calibrate_out_that_exists_but_takes_no_file(folder, capfd, no_render):
    suite = write_suite(folder, CASE)
    assert_one_line(*cli(capfd, "calibrate", suite, "--out", UNWRITABLE, "--seeds", 2), "--out", "cannot write")
    assert no_render == []


@needs_proc
def test_run_out_that_exists_but_takes_no_file_is_refused_before_the_first_render(folder, capfd, no_render):
    suite = write_suite(folder, CASE)
    assert_one_line(*cli(capfd, "run", suite, "--out", UNWRITABLE, "--executor", "serial", "--no-report"),
                    "--out", "cannot write in the folder '/proc'")
    assert no_render == []


def test_run_out_whose_cases_folder_is_a_file(folder, capfd, no_render):
    out = folder / "out"
    out.mkdir()
    (out / "cases").write_text("not a folder")
    assert_one_line(*cli(capfd, "run", write_suite(folder, CASE), "--out", out, "--executor", "serial"),
                    "--out", "cases' is not a folder")
    assert no_render == []


@needs_proc
def test_baseline_save_out_in_a_folder_that_takes_no_file(folder, capfd, no_render):
    assert_one_line(*cli(capfd, "baseline", "save", write_suite(folder, CASE), "--out", UNWRITABLE / "b.json",
                         "--run-out", folder / "run"), "--out", "cannot write")
    assert no_render == [] and not (folder / "run").exists()


# ---- item 7: errors a run met only at run time ---------------------------------------------------------------------


@pytest.mark.parametrize("body,fragment", [
    (f'name = "{"n" * 300}"', "cases[0].name: expected at most 200 characters, got 300"),
    ('variant = "translate=1e300"', "cases[0].variant: expected a value from -1e+06 to 1e+06"),
    ('variant = "scale=1e-300"', "cases[0].variant: expected a value from 1e-06 to 1e+06"),
    ('variant = "light-shrink=1e300"', "cases[0].variant: expected a value from 1 to 1e+09"),
    ('variant = "sliver"', "cases[0].variant: on "),  # the scene has no rectangle to cut: found at load now
    ("spp = 1", "cases[0].spp: expected >= 2"),
    ("ground_truth_spp = 1", "cases[0].ground_truth_spp: expected >= 2"),
])
def test_run_time_errors_are_refused_when_the_suite_loads(folder, capfd, no_render, body, fragment):
    suite = write_suite(folder, f'[defaults]\nspp = 2\n[[cases]]\nname = "ok"\nscene = "scene.toml"\n'
                                f'[[cases]]\nscene = "scene.toml"\n{body}\n')
    line = assert_one_line(*cli(capfd, "run", suite, "--out", folder / "out", "--executor", "serial"),
                           f"{suite}: {fragment.replace('cases[0]', 'cases[1]')}")
    assert len(line) < 400
    assert no_render == [] and not (folder / "out").exists()


def test_every_case_with_one_sample_per_pixel_is_refused(folder):
    case = CASE.replace("spp = 2\n", "", 1)
    refused(write_suite(folder, '[defaults]\nspp = 1\n' + case.replace("[[cases]]", '[[cases]]\nname = "a"')
                        + case.replace("[[cases]]", '[[cases]]\nname = "b"')),
            "cases[0].spp: expected >= 2 (the verdict needs each pixel's sample variance")


@pytest.mark.parametrize("name,fragment", [
    ("a\\nb", "control or format characters, got '\\n'"),
    ("a\\u0000b", "control or format characters"),
    ("evil\\u202etxt", "U+202E"),
    ("   ", "expected a non-empty name"),
])
def test_unsafe_case_names(folder, name, fragment):
    refused(write_suite(folder, f'[[cases]]\nname = "{name}"\nscene = "scene.toml"\n'), "cases[0].name:", fragment)


def test_variant_values_must_be_within_bounds():
    for text in ("translate=1e300", "translate=-1e7", "scale=1e7", "scale=1e-7", "sliver=1e10", "light-shrink=1e10"):
        with pytest.raises(HarnessError, match="^--variant: expected a value from"):
            parse_variant(text, "--variant")
    assert parse_variant("translate=-1e6").value == -1e6 and parse_variant("scale=1e-6").value == 1e-6


def test_stress_command_refuses_bad_variant_and_empty_out_before_rendering(folder, capfd, monkeypatch):
    def run_stress(*args, **kwargs):
        raise AssertionError("rendered")

    monkeypatch.setattr("harness.studies.stress.run_stress", run_stress)
    assert_one_line(*cli(capfd, "stress", folder / "scene.toml", "--variant", "translate=1e300"), "--variant")
    assert_one_line(*cli(capfd, "stress", folder / "scene.toml", "--out", ""), "--out", "empty")


# ---- item 9: accepted in silence ---------------------------------------------------------------------------------


@pytest.mark.parametrize("table,fragment", [
    ("baseline = 3", "baseline: expected a table [baseline], got 3"),
    ("[baseline]\nrelmse_ = 1.1", "baseline.relmse_: unknown baseline tolerance; did you mean 'relmse'?"),
    ("[baseline]\nrelmse = nan", "baseline.relmse: expected a finite number"),
    ("[baseline]\nrelmse = -1", "baseline.relmse: expected a factor >= 1"),
    ("[baseline]\nbias = inf", "baseline.bias: expected a finite number"),
    ("[baseline]\nseconds = 1" + "0" * 400, "baseline.seconds: expected a finite number"),
])
def test_broken_baseline_table_is_refused_without_baseline_option(folder, table, fragment):
    refused(write_suite(folder, f"{table}\n{CASE}" if table.startswith("baseline") else f"{CASE}{table}\n"),
            fragment)


def test_good_baseline_table_still_loads(folder):
    suite = load_suite(write_suite(folder, f"{CASE}[baseline]\nrelmse = 1.1\nbias = \"off\"\nseconds = 1.5\n"))
    assert suite.baseline == {"relmse": 1.1, "bias": "off", "seconds": 1.5}


@pytest.mark.parametrize("thresholds,fragment", [
    ("{rmse = -1}", "cases[0].thresholds.rmse: expected an upper bound >= 0"),
    ("{bias = -0.5}", "cases[0].thresholds.bias: expected an upper bound >= 0"),
    ("{ssim = 1.5}", "cases[0].thresholds.ssim: expected a lower bound <= 1"),
    ("{relmse = nan}", "cases[0].thresholds.relmse: expected a finite number"),  # these three were refused already
    ("{psnr = inf}", "cases[0].thresholds.psnr: expected a finite number"),
    ("{rmsee = 1}", "cases[0].thresholds.rmsee: unknown metric; did you mean 'rmse'?"),
])
def test_thresholds_no_render_can_meet_are_refused(folder, thresholds, fragment):
    refused(write_suite(folder, f"{CASE}thresholds = {thresholds}\n"), fragment)


def test_thresholds_that_can_be_met_still_load(folder):
    suite = load_suite(write_suite(folder, f"{CASE}thresholds = {{rmse = 0, psnr = -3, ssim = 1, relmse = 0.5}}\n"))
    assert suite.cases[0].thresholds == {"rmse": 0.0, "psnr": -3.0, "ssim": 1.0, "relmse": 0.5}


def test_calibrate_cases_matching_nothing_is_refused(folder, capfd, no_render):
    suite = write_suite(folder, CASE.replace("[[cases]]\n", '[[cases]]\nname = "furnace/reference"\n'))
    assert_one_line(*cli(capfd, "calibrate", suite, "--cases", "[[", "--out", folder / "cal"), "--cases", "'[['",
                    "matches no case", "furnace/reference")
    assert_one_line(*cli(capfd, "calibrate", suite, "--cases", "furnace/*", "--cases", "nope*", "--out",
                         folder / "cal"), "--cases", "'nope*'")
    assert no_render == [] and not (folder / "cal").exists()


@pytest.mark.parametrize("command", [
    ("run", "SUITE", "--out", "", "--executor", "serial"),
    ("calibrate", "SUITE", "--out", ""),
    ("baseline", "save", "SUITE", "--out", ""),
    ("baseline", "save", "SUITE", "--out", "OUT/b.json", "--run-out", ""),
])
def test_empty_out_is_refused(folder, capfd, no_render, monkeypatch, command):
    monkeypatch.chdir(folder)  # where the defaults (reports/...) would go
    suite = write_suite(folder, CASE)
    argv = [str(suite) if a == "SUITE" else a.replace("OUT", str(folder)) for a in command]
    assert_one_line(*cli(capfd, *argv), "--run-out" if "--run-out" in argv else "--out", "empty string")
    assert no_render == [] and not (folder / "reports").exists()


# ---- item 10: case folders cannot escape OUT or collide ------------------------------------------------------------


@pytest.mark.parametrize("name", [".", ".."])
def test_dot_names_are_refused(folder, name):
    refused(write_suite(folder, f'[[cases]]\nname = "{name}"\nscene = "scene.toml"\n'), "cases[0].name:",
            f"not {name!r}")


def test_names_that_share_a_folder_are_refused_naming_both(folder):
    for first, second in (("a/b", "a_b"), ("a b", "a?b"), ("Cornell", "cornell"), ("x", "/x/")):
        refused(write_suite(folder, f'[[cases]]\nname = "{first}"\nscene = "scene.toml"\n'
                                           f'[[cases]]\nname = "{second}"\nscene = "scene.toml"\n'),
                       "cases[1].name:", repr(second), f"cases[0].name {first!r}", "cases/")


def test_slug_never_leaves_its_folder():
    for name in (".", "..", "./", "/..", "", "///", "..\\"):
        assert slug(name) not in ("", ".", ".."), name
        assert "/" not in slug(name)
    assert slug("cornell-box/reference") == "cornell-box_reference"  # unchanged for ordinary names
    assert slug("...") == "..."


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_repository_suites_have_distinct_case_folders():
    root = Path(__file__).resolve().parents[2]
    for path in sorted((root / "suites").glob("*.toml")):
        cases = load_suite(path).cases
        assert len({slug(c.name).casefold() for c in cases}) == len(cases), path


# ---- item 12: one run per output folder ----------------------------------------------------------------------------

HOLDER = textwrap.dedent("""\
    import fcntl, os, sys
    fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    os.write(fd, str(os.getpid()).encode())
    print("locked", flush=True)
    sys.stdin.read()
""")


@pytest.fixture
def holder(folder):
    """Another process holding folder/out/.lock (as a running harness run would) until its stdin closes."""
    out = folder / "out"
    out.mkdir()
    proc = subprocess.Popen([sys.executable, "-c", HOLDER, str(out / ".lock")], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "locked"
    yield out, proc
    if proc.poll() is None:
        proc.kill()
    proc.wait()


def test_second_run_into_a_busy_folder_names_the_holder(folder, holder, capfd, no_render):
    out, proc = holder
    assert_one_line(*cli(capfd, "run", write_suite(folder, CASE), "--out", out, "--executor", "serial"),
                    "--out", "in use by another harness run", f"process {proc.pid}")
    assert_one_line(*cli(capfd, "calibrate", write_suite(folder, CASE), "--out", out), f"process {proc.pid}")
    assert no_render == [] and not (out / "results.json").exists()


def test_lock_of_a_killed_process_blocks_nothing(holder):
    out, proc = holder
    with pytest.raises(HarnessError, match=f"process {proc.pid}"):
        with runstate.locked(out):
            pass
    proc.kill()  # the kernel drops its lock; the file stays behind, with its pid
    proc.wait()
    assert (out / ".lock").read_text() == str(proc.pid)
    with runstate.locked(out):
        assert (out / ".lock").read_text().strip() == str(os.getpid())
        with runstate.locked(out):  # re-entrant within a process
            pass
        assert (out / ".lock").exists()
    assert not (out / ".lock").exists()  # removed by its holder at the end


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_lock_is_exclusive_between_processes(tmp_path):
    """While this process holds the lock, a second process's run into the folder stops at once, naming us."""
    out = tmp_path / "out"
    code = ("import sys; from harness.running import runstate\n"
            "try:\n    with runstate.locked(runstate.output_folder(sys.argv[1], None)): pass\n"
            "except Exception as err:\n    print(err); sys.exit(2)\n")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    with runstate.locked(runstate.output_folder(str(out), None)):
        busy = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, env=env)
    free = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, env=env)
    assert busy.returncode == 2 and f"process {os.getpid()}" in busy.stdout, busy
    assert free.returncode == 0, free


@pytest.mark.parametrize("value", ["1e308", "10" + "0" * 400, "700000"])
def test_case_timeout_beyond_a_week_is_refused(tmp_path, value):
    """A case's ``timeout`` of 1e308 s overflowed the OS's timeout at run time; at most a week, refused at load."""
    path = tmp_path / "s.toml"
    path.write_text(f'name = "s"\n[[cases]]\nscene = "cornell-box"\ntimeout = {value}\n')
    with pytest.raises(HarnessError, match=r"cases\[0\]\.timeout: expected (at most 604800 seconds \(a week\)|a finite number)"):
        load_suite(path)
