"""What a new user and a renderer author trip over first on the command line: the README's commands end with the
exit codes they promise, scene names work where a suite takes them, options are taken by their whole name only,
``harness compare`` says which image is the ground truth, ``harness run`` says what it will run, a render whose
time was all start-up has no rate, and ``--film`` is on every command that renders or exports a scene."""

from __future__ import annotations

import argparse
import json
import re
import shlex
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, SCENES
from fake_exr import copy_beside

import harness.cli.bench
import harness.cli.render
import harness.cli.run
from harness.cli import build_parser, main
from harness.files.imageio import read_exr, write_exr
from harness.renderers import RenderResult
from harness.running.cases import load_suite

FURNACE = SCENES / "furnace.toml"
FURNACE_RADIANCE = (1 / 0.7, 2.0, 1 / 0.3)  # scenes/furnace.toml: Le / (1 - rho)


def cli(capfd, *argv) -> tuple[int, str, str]:
    """``harness ARGV`` in this process: (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    return code, out, err


def one_line(code: int, out: str, err: str) -> str:
    """The one line of a user error (exit code 2, nothing on stdout)."""
    assert code == 2 and out == "" and len(err.splitlines()) == 1, (code, out, err)
    return err.strip()


def parsers() -> dict[str, argparse.ArgumentParser]:
    """Every command's parser by name (``baseline save`` included)."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    found = dict(sub.choices)
    nested = next(a for a in found["baseline"]._actions if isinstance(a, argparse._SubParsersAction))
    found["baseline save"] = nested.choices["save"]
    return found


# ---- README and docs: every exit code a doc promises is checked --------------------------------------------------

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
PROMISE = re.compile(r"^\s*exit (\d+)\b")
#: the shell blocks of the docs that test_the_readme_by_hand_path_ends_as_it_promises runs, by a line each holds
RUN_BLOCKS = {"README.md": ["> good.toml"]}


def shell_blocks(text: str) -> list[list[str]]:
    """The ```bash blocks of a Markdown text, each as its commands (continuation lines joined)."""
    blocks = []
    for block in re.findall(r"^```bash\n(.*?)^```", text, re.M | re.S):
        commands, pending = [], ""
        for line in block.splitlines():
            pending += line.strip() if pending else line
            if pending.endswith("\\"):
                pending = pending[:-1].rstrip() + " "
                continue
            if pending.strip():
                commands.append(pending)
            pending = ""
        blocks.append(commands)
    return blocks


def promised_exit(command: str) -> int | None:
    """The exit code a command's trailing comment promises (``# exit 1: ...``), or None."""
    match = PROMISE.search(command.split("  #", 1)[1]) if "  #" in command else None
    return int(match[1]) if match else None


def test_every_exit_code_a_doc_promises_is_run_by_a_test():
    """A command whose comment promises an exit code sits in a block that the test below runs line by line: the
    README's by-hand path promised exit 1 and ended in exit 2 because no test ran it (its test ran a suite of its
    own, with a ``name``)."""
    unchecked = []
    for path in DOCS:
        keys = RUN_BLOCKS.get(path.name, [])
        for block in shell_blocks(path.read_text(encoding="utf-8")):
            run = any(key in command for key in keys for command in block)
            unchecked += [f"{path.name}: {c.strip()}" for c in block if promised_exit(c) is not None and not run]
    assert not unchecked, unchecked
    assert shell_blocks("```bash\na \\\n  b  # exit 1\nc\n```\n") == [["a b  # exit 1", "c"]]
    assert promised_exit("harness run x  # exit 1: fails") == 1 and promised_exit("sed 's#a#b#' x") is None


# A stand-in for renderers/mitsuba-scalar-cli.toml: the furnace's radiance (times 1 - --energy-loss) plus Gaussian
# noise, with variance channels and its own render time, so that nothing else is run or measured.
STAND_IN = r'''
import random, sys
from fake_exr import write_exr
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
w, h, loss, rng = int(args["--width"]), int(args["--height"]), float(args.get("--energy-loss", 0)), random.Random(
    int(args["--seed"]))
sd = 0.02
image = [[[c * (1 - loss) + sd * rng.gauss(0, 1) for c in RADIANCE] for _ in range(w)] for _ in range(h)]
write_exr(args["--out"], image, [[[sd * sd] * 3 for _ in range(w)] for _ in range(h)],
          {"render_seconds": "0.001", "variance_dof": "1000"})
'''


@pytest.mark.slow
def test_the_readme_by_hand_path_ends_as_it_promises(tmp_path, monkeypatch, capfd):
    """The README's "same path by hand" lines, run as printed from a folder that holds a checkout's ``scenes/`` and
    ``renderers/`` in small: ``cornell-box`` is the furnace (a closed form: no Mitsuba ground truth) and
    ``mitsuba-scalar-cli`` a stand-in program (no Mitsuba); the cases run in this process and the studies are
    left out (neither decides an exit code). Each line ends with the exit code its comment promises
    (0 where it promises none); the faulty run used to end in exit 2 ("baseline of suite 'good', not of 'faulty'")."""
    (tmp_path / "scenes").mkdir()
    shutil.copyfile(FURNACE, tmp_path / "scenes" / "cornell-box.toml")
    (tmp_path / "renderers").mkdir()
    script = tmp_path / "stand_in.py"
    script.write_text(STAND_IN.replace("RADIANCE", repr(FURNACE_RADIANCE)))
    copy_beside(script)
    command = ["{python}", "{here}/../stand_in.py", "--out", "{out}", "--seed", "{seed}", "--width", "{width}",
               "--height", "{height}", "--variant", "scalar_rgb"]
    (tmp_path / "renderers" / "mitsuba-scalar-cli.toml").write_text(f"command = {json.dumps(command)}\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path / "cache"))
    # what changes no exit code, at a tenth of the cost: the cases in this process (not a pool's), no studies
    executors = harness.cli.run.executors
    monkeypatch.setattr(executors, "make_executor", lambda *a: executors.SerialExecutor())
    monkeypatch.setattr(harness.cli.run.study_compute, "write_studies", lambda *a, **k: None)
    block = next(b for b in shell_blocks((ROOT / "README.md").read_text(encoding="utf-8"))
                 if any(key in c for key in RUN_BLOCKS["README.md"] for c in b))
    ran = []
    for line in block:
        words = shlex.split(line, comments=True)
        if words[0] == "harness":
            code = main(words[1:])
            out, err = capfd.readouterr()
        else:
            done = subprocess.run(["bash", "-c", line], cwd=tmp_path, capture_output=True, text=True, timeout=60)
            code, out, err = done.returncode, done.stdout, done.stderr
        promised = promised_exit(line)
        assert code == (promised or 0), (line, code, out[-2000:], err[-2000:])
        ran.append((words[:2], code))
    assert [code for _, code in ran] == [0, 0, 0, 0, 0, 0, 1]
    assert (tmp_path / "run" / "index.html").is_file()  # the promise after "exit 0"
    assert load_suite(tmp_path / "faulty.toml").name == load_suite(tmp_path / "good.toml").name == "mine"


# ---- options by their whole name only -----------------------------------------------------------------------------


def test_no_parser_takes_an_option_by_a_prefix_of_its_name():
    for name, parser in parsers().items():
        assert parser.allow_abbrev is False, name


@pytest.mark.parametrize("argv, line", [
    (["render", FURNACE, "--sp", "4"], "harness: error: --sp: unknown option of harness render; did you mean '--spp'?"),
    (["render", FURNACE, "--spp", "4", "--out", "x.exr", "--spx=4"],
     "harness: error: --spx: unknown option of harness render; did you mean '--spp'?"),
    (["compare", "a.exr", "b.exr", "--til", "4"],
     "harness: error: --til: unknown option of harness compare; did you mean '--tile'?"),
    (["baseline", "save", "s.toml", "--fro", "r.json"],
     "harness: error: --fro: unknown option of harness baseline save; did you mean '--from'?"),
    (["--hep"], "harness: error: --hep: unknown option of harness; did you mean '--help'?"),
])
def test_a_prefix_of_an_option_is_an_unknown_option_that_names_itself(capfd, argv, line):
    """``--sp 4`` used to be ``--spp 4``; an unknown option was "unrecognized arguments" at the end of the usage,
    or hidden behind a required option it was a typo of."""
    assert one_line(*cli(capfd, *argv)) == line


# ---- scene names on the command line -------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_command_takes_a_scene_by_the_name_a_suite_takes(tmp_path, monkeypatch, capfd):
    monkeypatch.chdir(tmp_path)  # no scenes/ here: the checkout's canonical scene
    code, out, err = cli(capfd, "render", "furnace", "--spp", "1", "--film", "4x4", "--out", tmp_path / "f.exr",
                         "--json", "--quiet")
    assert code == 0, err
    assert json.loads(out)["scene"] == str(FURNACE)
    code, out, err = cli(capfd, "export", "furnace", "--format", "json", "--out", tmp_path / "x")
    assert code == 0 and "furnace: json" in out, err
    (tmp_path / "scenes").mkdir()  # a scenes/NAME.toml in the current folder comes first, as for a suite
    (tmp_path / "scenes" / "furnace.toml").write_text(FURNACE.read_text().replace('name = "furnace"', 'name = "mine"'))
    code, out, err = cli(capfd, "ground-truth", "furnace", "--json")
    assert code == 0 and json.loads(out)["scene"] == "scenes/furnace.toml", err


@pytest.mark.parametrize("argv, where", [
    (["render", "furnac", "--spp", "1", "--out", "x.exr"], "scene"),
    (["ground-truth", "furnac"], "scene"),
    (["export", "furnac", "--format", "json", "--out", "x"], "scene"),
    (["convergence", "furnac"], "scene"),
    (["stress", "furnac"], "scene"),
    (["bench", "--scene", "furnac"], "--scene"),
])
def test_a_near_miss_of_a_scene_name_gets_a_did_you_mean(tmp_path, monkeypatch, capfd, argv, where):
    monkeypatch.chdir(tmp_path)
    line = one_line(*cli(capfd, *argv))
    assert line.startswith(f"harness: error: {where}: no scene 'furnac' (looked for ") and line.endswith(
        "; did you mean 'furnace'?"), line
    assert not (tmp_path / "x").exists()


def test_a_suite_resolves_a_scene_name_in_the_same_place(tmp_path):
    """One resolver (harness.scene.find_scene): the suite's error has the same did-you-mean."""
    (tmp_path / "s.toml").write_text('[[cases]]\nscene = "furnac"\n')
    with pytest.raises(Exception, match=r"cases\[0\]\.scene: no scene 'furnac' .*did you mean 'furnace'\?"):
        load_suite(tmp_path / "s.toml")


# ---- harness compare: which image is the ground truth ------------------------------------------------------------


def _exr(path: Path, variance: float, spp: int, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    image = (np.full((8, 8, 3), 0.5) + rng.normal(0.0, variance**0.5, (8, 8, 3))).astype(np.float32)
    write_exr(path, image, np.full((8, 8, 3), variance, np.float32), metadata={"spp": str(spp)})
    return path


def test_compare_names_the_ground_truth_and_warns_when_it_is_the_noisier(tmp_path, capfd):
    test = _exr(tmp_path / "test.exr", 1e-2, 16, 1)
    truth = _exr(tmp_path / "truth.exr", 1e-4, 1024, 2)
    code, out, err = cli(capfd, "compare", test, truth)
    assert code == 0 and err == "", err
    assert f"ground truth: {truth} (1024 spp, mean variance 0.0001)" in out.splitlines(), out
    assert f"test image:   {test} (16 spp, mean variance 0.01)" in out.splitlines(), out
    code, out, err = cli(capfd, "compare", truth, test, "--json")  # swapped: it still passes, but not silently
    images = json.loads(out)["images"]
    assert images["ground_truth"] == {"path": str(test), "spp": 16, "renderer": None, "source": None,
                                      "mean_variance": pytest.approx(1e-2)}
    assert images["test"]["spp"] == 1024 and images["warning"].startswith(f"the ground truth {test} is noisier")
    assert err.splitlines() == [f"harness: warning: {images['warning']}"], err
    assert "mean variance 0.01 against 0.0001" in err and "swapped" in err


# ---- harness run: what it will run, and how to skip the studies -------------------------------------------------

SUITE = 'name = "tiny"\n[defaults]\nfilm = { width = 4, height = 4 }\nspp = 2\n[[cases]]\nscene = "furnace"\n'


@pytest.mark.slow
def test_run_says_at_the_start_what_will_run_and_how_to_skip_the_studies(tmp_path, monkeypatch, capfd):
    monkeypatch.setattr(harness.cli.run, "_write_report", lambda *a, **k: None)  # the studies: not this test's cost
    (tmp_path / "s.toml").write_text(SUITE)
    argv = ["run", tmp_path / "s.toml", "--executor", "serial", "--cache-dir", tmp_path / "cache", "--no-cache"]
    code, out, err = cli(capfd, *argv, "--out", tmp_path / "a")
    assert code == 0, err
    assert err.splitlines()[0] == ("tiny: 1 case, then the studies of their scenes (convergence, shadow rays, "
                                   "strategies; they can take longer than the cases: --no-studies skips them) and "
                                   "the report"), err
    code, out, err = cli(capfd, *argv, "--out", tmp_path / "b", "--no-strategies", "--no-convergence")
    assert code == 0 and "(shadow rays; they can take" in err.splitlines()[0], err
    code, out, err = cli(capfd, *argv, "--out", tmp_path / "c", "--no-studies")
    assert code == 0 and err.splitlines()[0] == "tiny: 1 case, then the report; no studies (--no-studies)", err
    code, out, err = cli(capfd, *argv, "--out", tmp_path / "d", "--quiet")
    assert code == 0 and err == "", err
    (tmp_path / "e").mkdir()  # a user error found by the run itself is still the only line: the plan comes after
    (tmp_path / "e" / "results.json").write_text("{")
    line = one_line(*cli(capfd, *argv, "--out", tmp_path / "e"))
    assert line.startswith(f"harness: error: {tmp_path / 'e' / 'results.json'}"), line


# ---- harness render: no rate without render time -------------------------------------------------------------------


class _AllStartUp:
    """A renderer whose measured time was all start-up: nothing left once it is subtracted."""

    name = "all-start-up"

    def __init__(self, seconds: float):
        self.seconds = seconds

    def render(self, scene, request):
        w, h = scene.film.width, scene.film.height
        return RenderResult(renderer=self.name, image=np.ones((h, w, 3), np.float32),
                            variance=np.full((h, w, 3), 1e-3, np.float32), seconds=self.seconds, spp=request.spp,
                            rays={"camera": w * h * request.spp}, stats={}, settings={})


@pytest.mark.parametrize("seconds", [0.0, 1e-12])
def test_render_has_no_rate_when_no_render_time_is_left(tmp_path, monkeypatch, capfd, seconds):
    monkeypatch.setattr(harness.cli.render, "get_renderer", lambda name: _AllStartUp(seconds))
    argv = ["render", FURNACE, "--spp", "16", "--film", "8x8", "--out", tmp_path / "r.exr", "--quiet"]
    code, out, err = cli(capfd, *argv)
    assert code == 0, err
    assert "16 spp in 0.00 s (paths/s and rays/s n/a: no render time left once the start-up was subtracted)" in out
    assert "M paths/s" not in out
    code, out, err = cli(capfd, *argv, "--json")
    summary = json.loads(out)
    assert summary["paths_per_second"] is None and summary["rays_per_second"] is None and summary["paths"] == 1024


# ---- --film on ground-truth, bench and export ---------------------------------------------------------------------

FILM_COMMANDS = ["render", "ground-truth", "bench", "export"]


def test_film_is_one_option_on_every_command_that_renders_or_exports_a_scene():
    found = parsers()
    actions = {name: next(a for a in found[name]._actions if "--film" in a.option_strings) for name in FILM_COMMANDS}
    kinds = {(a.type, a.help, a.metavar, a.default) for a in actions.values()}
    assert len(kinds) == 1, kinds
    assert next(iter(kinds))[2] == "WxH"


def test_ground_truth_and_export_take_film(tmp_path, capfd):
    code, out, err = cli(capfd, "ground-truth", FURNACE, "--film", "6x3", "--json", "--out", tmp_path / "gt.exr")
    assert code == 0, err
    summary = json.loads(out)
    assert (summary["width"], summary["height"]) == (6, 3)
    assert read_exr(tmp_path / "gt.exr").image.shape == (3, 6, 3)
    code, out, err = cli(capfd, "export", FURNACE, "--film", "5x7", "--format", "json", "--out", tmp_path / "x")
    assert code == 0, err
    film = json.loads((tmp_path / "x" / "scene.json").read_text())["film"]
    assert (film["width"], film["height"]) == (5, 7)


def test_bench_takes_film_into_its_cost_check_and_its_renders(tmp_path, monkeypatch, capfd):
    line = one_line(*cli(capfd, "bench", "--scene", "furnace", "--film", "16384x16384", "--quiet"))
    assert line.startswith("harness: error: --film: expected at most 67108864 pixels"), line
    asked = {}

    class Stop(Exception):
        pass

    def run_bench(**kwargs):
        asked.update(kwargs)
        raise Stop

    monkeypatch.setattr(harness.cli.bench.bench, "run_bench", run_bench)
    with pytest.raises(Stop):
        main(["bench", "--scene", "furnace", "--film", "8x4", "--quiet", "--no-embree-rate"])
    assert asked["film"] == (8, 4) and [Path(p).resolve() for p in asked["scenes"]] == [FURNACE.resolve()]
