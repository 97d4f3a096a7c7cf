"""Hostile input, part 2 (issue 12; docs/robustness.md): a closed stdout, option values that ``int()`` / ``float()``
would take (``1_000``, ``nan``, ``1e308``), renderer settings whose memory no machine has, unsafe renderer-file
values, files that are not regular files or are huge, radiance that overflows float32, OBJ indices of 0. Each is one
line on stderr naming the file and key or the option, exit code 2 (a closed stdout: exit 141, nothing on stderr)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import MINIMAL_SCENE, ROOT
from test_hostile_input import assert_one_line, cli

import reference_impl
from harness.core import limits
from harness.core.errors import HarnessError
from harness.renderers import RenderRequest
from harness.renderers.external import load_spec
from harness.renderers.mitsuba import MitsubaRenderer
from harness.renderers.reference import ReferenceRenderer
from harness.scene import load_scene
from harness.running.cases import load_suite

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

FURNACE = ROOT / "scenes" / "furnace.toml"
LIGHT = '\n[[shapes]]\nname = "light"\ntype = "rectangle"\nmaterial = "white"\nemission = [1, 1, 1]\n'
# A tiny open scene with a bounded depth (so branching settings have a finite cost) and one light.
SCENE = MINIMAL_SCENE + "\n[integrator]\nmax_depth = 4\n" + LIGHT


def env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT))


@pytest.fixture
def scene(tmp_path) -> Path:
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    return path


@pytest.fixture
def no_render(monkeypatch):
    """A reference render fails the test: a refusal must come before anything is traced or allocated."""
    def refuse(*args, **kwargs):
        raise AssertionError("the reference renderer was started")

    monkeypatch.setattr(reference_impl, "render", refuse)


# ---- item 5: a closed stdout -------------------------------------------------------------------------------------


@pytest.mark.parametrize("argv, unbuffered", [
    (["render", "{scene}", "--spp", "1", "--out", "{tmp}/x.exr", "--json", "--quiet"], True),  # print() raises
    (["ground-truth", str(FURNACE), "--json", "--quiet"], False),  # buffered: only the flush at exit meets the pipe
    (["ground-truth", str(FURNACE), "--quiet"], True),
], ids=["render-json-unbuffered", "ground-truth-json-buffered", "ground-truth-unbuffered"])
def test_a_closed_stdout_ends_quietly_with_141(tmp_path, scene, argv, unbuffered):
    """``harness ... | head -c 10`` where the reader has gone before the harness writes: no BrokenPipeError
    traceback, none at interpreter shutdown either ("Exception ignored ... BrokenPipeError", exit code 120, where
    stdout is buffered); exit code 141 (128 + SIGPIPE, as a shell reports it)."""
    environment = env()
    environment.pop("PYTHONUNBUFFERED", None)
    if unbuffered:
        environment["PYTHONUNBUFFERED"] = "1"
    read, write = os.pipe()
    reader = subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.buffer.read(0)"], stdin=read)
    reader.wait(timeout=60)  # the reader closes early: before a byte is written
    os.close(read)
    args = [a.format(scene=scene, tmp=tmp_path) for a in argv]
    try:
        proc = subprocess.run([sys.executable, "-m", "harness", *args], stdout=write, stderr=subprocess.PIPE,
                              text=True, env=environment, timeout=120)
    finally:
        os.close(write)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""


# ---- item 6: values that crashed inside instead of being refused -----------------------------------------------


def _renderer_file(tmp_path: Path, extra: str, name: str = "r") -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'command = ["{{python}}", "-c", "pass", "{{out}}"]\n{extra}\n')
    return path


def test_renderer_file_timeout_beyond_a_week_is_one_line(tmp_path, scene, capfd):
    path = _renderer_file(tmp_path, "timeout = 1e308")
    assert_one_line(*cli(capfd, "render", scene, "--renderer", path, "--spp", 1, "--out", tmp_path / "x.exr"),
                    f"{path}: timeout:", "at most 604800")
    assert load_spec(_renderer_file(tmp_path, "timeout = 604800")).timeout == 604800


@pytest.mark.parametrize("value", ["1e308", "inf", "nan", "604801", "0", "1_0"])
def test_run_timeout_option_is_bounded(tmp_path, capfd, value):
    assert_one_line(*cli(capfd, "run", tmp_path / "missing.toml", "--timeout", value), "--timeout:",
                    "positive number of seconds")


def test_indirect_rays_beyond_memory_refused_before_allocating(tmp_path, scene, capfd, no_render):
    line = assert_one_line(*cli(capfd, "render", scene, "--spp", 1, "--out", tmp_path / "x.exr",
                                "--set", "indirect_rays=1000000"), "--set indirect_rays:", "of memory")
    assert "lower indirect_rays" in line
    assert not (tmp_path / "x.exr").exists()


def test_shadow_rays_beyond_memory_refused_before_allocating(tmp_path, scene, capfd, no_render, monkeypatch):
    monkeypatch.setattr(limits, "machine_memory", lambda: 16 * 2**30)
    assert_one_line(*cli(capfd, "render", scene, "--spp", 1, "--out", tmp_path / "x.exr",
                         "--set", "shadow_rays=100000000"), "--set shadow_rays:", "of memory", "16.0 GiB")


def test_unbounded_branching_refused(tmp_path, capfd, no_render):
    """The furnace is closed and max_depth = -1: with 2 indirect rays and survival 0.7 every hit spawns 1.4 paths on
    average, which never dies out."""
    line = assert_one_line(*cli(capfd, "render", FURNACE, "--spp", 1, "--out", tmp_path / "x.exr",
                                "--set", "indirect_rays=2"), "--set indirect_rays:", "max_depth")
    assert "never dies out" in line


def test_branching_time_counts_every_ray(tmp_path, scene, capfd, no_render):
    """64 indirect rays per hit, max_depth 4: about 1400 x the rays of a default path; at 10^6 spp on 16 x 16 pixels
    that is days, though the paths alone (the film-and-spp estimate) would take 4 min."""
    assert_one_line(*cli(capfd, "render", scene, "--spp", 10**6, "--out", tmp_path / "x.exr", "--set",
                         "indirect_rays=64", "--set", "batch_size=64"), "--set indirect_rays:", "days",
                    "more than the 24.0 h limit")


def test_moderate_settings_still_render(scene):
    renderer = ReferenceRenderer()
    for settings in ({}, {"indirect_rays": "3", "shadow_rays": "2"}, {"shadow_rays": "64"}, {"threads": "64"}):
        renderer.check(load_scene(scene), RenderRequest(spp=64, seed=0, settings=settings))
    renderer.check(load_scene(FURNACE), RenderRequest(spp=16, settings={"indirect_rays": "3", "max_depth": "4"}))


def test_suite_case_with_absurd_indirect_rays_refused_at_load(tmp_path, scene):
    suite = tmp_path / "suite.toml"
    suite.write_text(f'name = "s"\n[[cases]]\nname = "c"\nscene = "{scene}"\nrenderer = "reference"\nspp = 2\n'
                     'settings = { indirect_rays = 1000000 }\nagainst = { renderer = "reference", spp = 4 }\n')
    with pytest.raises(HarnessError) as info:
        load_suite(suite)
    assert info.value.where == f"{suite}: cases[0].settings.indirect_rays" and "of memory" in info.value.message


@pytest.mark.parametrize("name", ["a/b", "../../x", "", "-x", ".", "a\nb", "x" * 65])
def test_unsafe_renderer_name_refused(tmp_path, name):
    path = _renderer_file(tmp_path, f"name = {json.dumps(name)}")
    with pytest.raises(HarnessError) as info:
        load_spec(path)
    assert info.value.where == f"{path}: name" and "\n" not in str(info.value)


def test_safe_renderer_names_load(tmp_path):
    for name in ("my-renderer", "Mitsuba 3.5 cli", "r_2+x"):
        assert load_spec(_renderer_file(tmp_path, f"name = {json.dumps(name)}")).name == name


# ---- item 8: files that are not regular files, and huge ones --------------------------------------------------

# Each case runs in a child with 4 GiB of address space and an alarm, so a regression (reading /dev/zero forever,
# opening a named pipe that blocks) fails the test instead of eating the machine or hanging it.
_DRIVER = textwrap.dedent("""
    import contextlib, io, json, resource, signal, sys
    resource.setrlimit(resource.RLIMIT_AS, (4 * 2**30, 4 * 2**30))
    from harness.cli import main

    def hang(*_):
        raise TimeoutError("hung")

    signal.signal(signal.SIGALRM, hang)
    results = []
    for argv in json.loads(sys.argv[1]):
        err = io.StringIO()
        signal.alarm(20)
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                code = main(argv)
        except BaseException as exc:
            code = repr(exc)[:200]
        signal.alarm(0)
        results.append([code, err.getvalue()])
    print(json.dumps(results))
""")


def test_files_that_are_not_regular_files_are_refused(tmp_path, scene, capfd):
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    suite = tmp_path / "suite.toml"
    suite.write_text(f'name = "s"\n[[cases]]\nname = "c"\nscene = "{FURNACE}"\nrenderer = "reference"\nspp = 2\n')
    cases = {
        "scene /dev/zero": ["render", "/dev/zero", "--spp", "1", "--out", str(tmp_path / "x.exr")],
        "scene /dev/urandom": ["render", "/dev/urandom", "--spp", "1", "--out", str(tmp_path / "x.exr")],
        "scene fifo": ["render", str(fifo), "--spp", "1", "--out", str(tmp_path / "x.exr")],
        "suite /dev/zero": ["run", "/dev/zero", "--out", str(tmp_path / "o")],
        "baseline /dev/zero": ["run", str(suite), "--executor", "serial", "--out", str(tmp_path / "o"),
                               "--baseline", "/dev/zero"],
        "results /dev/zero": ["report", "/dev/zero", "--out", str(tmp_path / "r")],
        "exr fifo": ["compare", str(fifo), str(fifo)],
    }
    proc = subprocess.run([sys.executable, "-c", _DRIVER, json.dumps(list(cases.values()))], capture_output=True,
                          text=True, env=env(), timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for (label, argv), (code, err) in zip(cases.items(), json.loads(proc.stdout)):
        assert code == 2, (label, code, err)
        lines = err.splitlines()
        assert len(lines) == 1 and "not a regular file" in lines[0], (label, err)
    assert not (tmp_path / "o").exists() and not (tmp_path / "r").exists()


def test_huge_text_file_refused(tmp_path, capfd):
    path = tmp_path / "huge.toml"
    with path.open("wb") as f:
        f.truncate(64 * 2**20 + 1)  # sparse: costs no disk
    assert_one_line(*cli(capfd, "render", path, "--spp", 1, "--out", tmp_path / "x.exr"), str(path), "64 MiB")
    assert_one_line(*cli(capfd, "run", path), str(path), "64 MiB")


def test_mesh_that_is_not_a_regular_file(tmp_path, capfd):
    (tmp_path / "dev.obj").symlink_to("/dev/zero")
    path = tmp_path / "scene.toml"
    path.write_text(SCENE + '\n[[shapes]]\ntype = "mesh"\nmaterial = "white"\nfile = "dev.obj"\n')
    with pytest.raises(HarnessError) as info:
        load_scene(path, allow_outside_paths=True)
    assert info.value.where == f"{path}: shapes[1].file" and "not a regular file" in info.value.message


# ---- item 9: accepted in silence -----------------------------------------------------------------------------


@pytest.mark.parametrize("emission", ["[1e308, 1e308, 1e308]", "[1, 1, 2e12]"])
def test_emission_that_overflows_float32_refused(tmp_path, emission):
    path = tmp_path / "scene.toml"
    path.write_text(MINIMAL_SCENE + LIGHT.replace("[1, 1, 1]", emission))
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert info.value.where == f"{path}: shapes[0].emission" and "at most 1e12" in info.value.message
    path.write_text(MINIMAL_SCENE + LIGHT.replace("[1, 1, 1]", "[1e12, 0, 0]"))
    assert load_scene(path).shapes[0].emission == (1e12, 0.0, 0.0)


@pytest.mark.parametrize("option, value", [("--spp", 0), ("--spp", -1), ("--spp", "1e13"), ("--spp", 10**13),
                                           ("--chunk-spp", 0), ("--spp", "1_000")])
def test_ground_truth_options_checked_before_the_closed_form_answers(capfd, option, value):
    assert_one_line(*cli(capfd, "ground-truth", FURNACE, option, value, "--quiet"), f"{option}:")


@pytest.mark.parametrize("extra, key, fragment", [
    ("repeats = 1000000000", "repeats", "from 2 to 1000"),
    ('name = ""', "name", "expected 1 to 64"),
])
def test_renderer_file_values_bounded(tmp_path, extra, key, fragment):
    path = _renderer_file(tmp_path, extra)
    with pytest.raises(HarnessError) as info:
        load_spec(path)
    assert info.value.where == f"{path}: {key}" and fragment in info.value.message


@pytest.mark.parametrize("faces, fragment", [
    ("f 0 1 2", "index 0"),
    ("f 1/0 2 3", "index 0"),
    ("f 1 2 3 0", "index 0"),
    ("f 1 2 x", "integer indices"),
    ("f 1 2 -4", "v -4"),
])
def test_obj_face_indices_are_checked(tmp_path, faces, fragment):
    (tmp_path / "m.obj").write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\n{faces}\n")
    path = tmp_path / "scene.toml"
    path.write_text(MINIMAL_SCENE + '\n[[shapes]]\ntype = "mesh"\nmaterial = "white"\nfile = "m.obj"\n')
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert info.value.where == f"{path}: shapes[0].file" and fragment in info.value.message, str(info.value)
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 -1//1\n")  # relative: fine
    shape = load_scene(path).shapes[0]
    assert shape.mesh_vertices[shape.mesh_triangles[0]].tolist() == [[0, 0, 0], [1, 0, 0], [0, 1, 0]]


# Every integer and float option of every command, given a value int() / float() would take but the option must
# not. The positional file does not exist: the old code took the value and then failed on the file (naming it).
MISSING = "missing.toml"
INT_OPTIONS = [
    ("render", MISSING, "--spp"), ("render", MISSING, "--seed"),
    ("ground-truth", MISSING, "--spp"), ("ground-truth", MISSING, "--seed"), ("ground-truth", MISSING, "--chunk-spp"),
    ("compare", "missing.exr", "--tile"), ("run", MISSING, "--workers"), ("report", "missing.json", "--strategy-spp"),
    ("convergence", MISSING, "--chunk-spp"), ("convergence", MISSING, "--ground-truth-spp"),
    ("convergence", MISSING, "--seed"), ("calibrate", MISSING, "--seeds"), ("calibrate", MISSING, "--region-size"),
    ("convergence", MISSING, "--repeats"), ("ground-truth", MISSING, "--test-spp"),
    ("bench", None, "--spp"), ("bench", None, "--repeats"), ("bench", None, "--ground-truth-spp"),
    ("export", MISSING, "--spp"), ("export", MISSING, "--seed"),
    ("stress", MISSING, "--spp"), ("stress", MISSING, "--seed"), ("stress", MISSING, "--ground-truth-spp"),
]
FLOAT_OPTIONS = [("compare", "missing.exr", "--alpha"), ("convergence", MISSING, "--k"), ("stress", MISSING, "--k"),
                 ("stress", MISSING, "--alpha"), ("run", MISSING, "--timeout")]


def _argv(tmp_path: Path, command: str, positional: str | None, option: str, value: str) -> list:
    argv = [command] + ([str(tmp_path / positional)] if positional else ["--scene", str(tmp_path / MISSING)])
    if command == "compare":
        argv.append(str(tmp_path / "missing.exr"))
    if command == "export":
        argv += ["--format", "obj", "--out", str(tmp_path / "e")]
    return argv + [option, value]


@pytest.mark.parametrize("value", ["1_000", "1e3", " 4", "٣"])
@pytest.mark.parametrize("command, positional, option", INT_OPTIONS, ids=[f"{c} {o}" for c, _, o in INT_OPTIONS])
def test_integer_options_take_plain_decimal_digits_only(tmp_path, capfd, command, positional, option, value):
    assert_one_line(*cli(capfd, *_argv(tmp_path, command, positional, option, value)), f"{option}: ",
                    "plain decimal digits")


@pytest.mark.parametrize("command, positional, option", INT_OPTIONS, ids=[f"{c} {o}" for c, _, o in INT_OPTIONS])
def test_integer_options_refuse_negative_values(tmp_path, capfd, command, positional, option):
    assert_one_line(*cli(capfd, *_argv(tmp_path, command, positional, option, "-1")), f"{option}: ")


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e999", "1_0", "0x10"])
@pytest.mark.parametrize("command, positional, option", FLOAT_OPTIONS, ids=[f"{c} {o}" for c, _, o in FLOAT_OPTIONS])
def test_float_options_take_finite_numbers_only(tmp_path, capfd, command, positional, option, value):
    assert_one_line(*cli(capfd, *_argv(tmp_path, command, positional, option, value)), f"{option}: ")


@pytest.mark.parametrize("option, value", [("--spp", "4,2,1"), ("--spp", "1,2,2"), ("--spp", "1,2_0"),
                                           ("--seconds", "1,0.5"), ("--seconds", "0.5,nan"), ("--film", "٣x3")])
def test_convergence_ladders_strictly_increasing(tmp_path, capfd, option, value):
    assert_one_line(*cli(capfd, "convergence", tmp_path / MISSING, option, value), f"{option}: ")


def test_report_ladder_strictly_increasing(tmp_path, capfd):
    assert_one_line(*cli(capfd, "report", tmp_path / "missing.json", "--convergence-spp", "16,4"),
                    "--convergence-spp: ", "strictly increasing")


@pytest.mark.parametrize("renderer, key", [(ReferenceRenderer, "shadow_rays"), (ReferenceRenderer, "max_depth"),
                                           (MitsubaRenderer, "chunk_spp"), (MitsubaRenderer, "max_depth")])
def test_integer_settings_take_plain_decimal_digits_only(scene, renderer, key):
    with pytest.raises(HarnessError) as info:
        renderer().check(load_scene(scene), RenderRequest(spp=4, settings={key: "1_0"}))
    assert info.value.where == f"--set {key}" and "plain decimal digits" in info.value.message


def test_option_messages_name_the_option_alone(tmp_path, capfd):
    """argparse's "harness render: argument --spp: ..." becomes "--spp: ..." like every other option error."""
    line = assert_one_line(*cli(capfd, "render", tmp_path / MISSING, "--spp", "x", "--out", tmp_path / "x.exr"))
    assert line == "harness: error: --spp: expected a positive integer in plain decimal digits, got 'x'"
