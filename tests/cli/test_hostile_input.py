"""Hostile input (docs/robustness.md): every bad scene, suite, option or EXR file ends in one line on stderr naming
the file and the key or option, exit code 2, no traceback and nothing written; mesh paths stay in the scene's
folder; a renderer's bad image fails its case only; every string of a scene or suite is escaped in the report; the
suite loader survives fuzzing."""

from __future__ import annotations

import copy
import html
import math
import os
import random
import re
import struct
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import MINIMAL_SCENE, ROOT, fuzz_examples
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tomltext import to_toml, toml_string

from harness.files import imageio
from harness.core import limits
from harness.cli import main
from harness.core.errors import HarnessError
from harness.renderers import RenderResult
from harness.renderers.validate import BadRenderError, validate_result
from harness.scene import load_scene
from harness.running.cases import Suite, load_suite

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

SCENE = MINIMAL_SCENE.replace('name = "minimal"', 'name = "tiny"') + """
[[shapes]]
name = "light"
type = "rectangle"
material = "white"
emission = [1, 1, 1]
"""
TRIANGLE = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def mesh_shape(file: str, extra: str = "") -> str:
    return f'\n[[shapes]]\ntype = "mesh"\nmaterial = "white"\nfile = "{file}"\n{extra}\n'


def cli(capfd, *argv) -> tuple[int, str, str]:
    """Run the CLI in this process; stdout and stderr as the file descriptors saw them (library chatter too)."""
    code = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    return code, out, err


def assert_one_line(code: int, out: str, err: str, *fragments: str) -> str:
    """Exit code 2, nothing on stdout, exactly one line on stderr that holds every fragment."""
    assert code == 2, (code, out, err)
    assert out == "", out
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("harness: error: "), err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture
def scene_folder(tmp_path) -> Path:
    """tmp/sub: a valid tiny scene, meshes inside; tmp/outside: a mesh outside; sub/link.obj points outside."""
    sub, outside = tmp_path / "sub", tmp_path / "outside"
    sub.mkdir()
    outside.mkdir()
    (sub / "scene.toml").write_text(SCENE)
    (sub / "tri.obj").write_text(TRIANGLE)
    (outside / "tri.obj").write_text(TRIANGLE)
    (sub / "link.obj").symlink_to(outside / "tri.obj")
    (sub / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    (sub / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    (sub / "garbage.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\n"
                                      b"property float x\nend_header\n\x00\x01")
    return sub


# --------------------------------------------------------------------------------------------------------------------
# Scenes through `harness render`: one line naming the file and key, exit 2, nothing written.

BAD_SCENES = {
    "malformed-toml": (lambda s: s.replace("[camera]", "[camera"), "line 3, column 8", "malformed TOML"),
    "unknown-key": (lambda s: s.replace("fov = 40", "fvo = 40"), "camera.fvo", "did you mean 'fov'"),
    "wrong-type": (lambda s: s.replace("fov = 40", 'fov = "40"'), "camera.fov", "expected degrees"),
    "nan-fov": (lambda s: s.replace("fov = 40", "fov = nan"), "camera.fov", "got nan"),
    "fov-180": (lambda s: s.replace("fov = 40", "fov = 180"), "camera.fov", "(0, 180)"),
    "up-parallel": (lambda s: s.replace("up = [0, 1, 0]", "up = [0, 0, -3]"), "camera.up", "parallel"),
    "negative-emission": (lambda s: s.replace("emission = [1, 1, 1]", "emission = [-1, 1, 1]"),
                          "shapes[0].emission", ">= 0"),
    "inf-emission": (lambda s: s.replace("emission = [1, 1, 1]", "emission = [inf, 1, 1]"),
                     "shapes[0].emission", "finite"),
    "reflectance-above-1": (lambda s: s.replace("0.8, 0.8, 0.8", "1.2, 0.8, 0.8"), "materials.white.reflectance", "[0, 1]"),
    "nan-reflectance": (lambda s: s.replace("0.8, 0.8, 0.8", "0.8, nan, 0.8"), "materials.white.reflectance", "[0, 1]"),
    "unknown-material-type": (lambda s: s.replace("reflectance = [0.8", 'type = "velvet"\nreflectance = [0.8'),
                              "materials.white.type", "expected one of diffuse, conductor"),
    "reflectance-of-a-mirror": (lambda s: s.replace("reflectance = [0.8", 'type = "conductor"\nreflectance = [0.8'),
                                "materials.white.reflectance", "applies only to materials of type 'diffuse'"),
    "two-sided-glass": (lambda s: s.replace("reflectance = [0.8, 0.8, 0.8]", 'type = "dielectric"\ntwo_sided = true'),
                        "materials.white.two_sided", "a dielectric has no two_sided"),
    "alpha-zero": (lambda s: s.replace("reflectance = [0.8, 0.8, 0.8]", 'type = "roughconductor"\nalpha = 0'),
                   "materials.white.alpha", "[0.0001, 1]"),
    "ior-negative": (lambda s: s.replace("reflectance = [0.8, 0.8, 0.8]", 'type = "dielectric"\nint_ior = -1.5'),
                     "materials.white.int_ior", "an index of refraction"),
    "named-conductor": (lambda s: s.replace("reflectance = [0.8, 0.8, 0.8]", 'type = "conductor"\nmaterial = "Au"'),
                        "materials.white.material", "named conductors are not supported"),
    "zero-area-light": (lambda s: s + "scale = [1, 0, 1]\n", "shapes[0].scale", "light needs positive area"),
    "zero-width": (lambda s: s.replace("width = 16", "width = 0"), "film.width", "positive integer"),
    "huge-width": (lambda s: s.replace("width = 16", "width = 16385"), "film.width", "of memory"),
    "too-many-pixels": (lambda s: s.replace("width = 16", "width = 16384").replace("height = 16", "height = 8192"),
                        "film", "GiB of memory"),
    "missing-mesh": (lambda s: s + mesh_shape("missing.obj"), "shapes[1].file", "no such mesh file"),
    "nan-vertex": (lambda s: s + mesh_shape("nan.obj"), "shapes[1].file", "non-finite vertex"),
    "garbage-mesh": (lambda s: s + mesh_shape("garbage.ply"), "shapes[1].file", "cannot read the mesh file"),
    "zero-area-mesh-light": (lambda s: s + mesh_shape("flat.obj", "emission = [1, 1, 1]"), "shapes[1]",
                             "zero-area light"),
    "mesh-up-and-out": (lambda s: s + mesh_shape("../outside/tri.obj"), "shapes[1].file", "outside the scene's"),
    "mesh-absolute": (lambda s: s + mesh_shape("ABS"), "shapes[1].file", "outside the scene's"),
    "mesh-symlink-out": (lambda s: s + mesh_shape("link.obj"), "shapes[1].file", "outside the scene's"),
}


@pytest.mark.parametrize("case", sorted(BAD_SCENES))
def test_bad_scene_is_one_line_and_writes_nothing(scene_folder, capfd, case):
    edit, key, fragment = BAD_SCENES[case]
    path = scene_folder / "bad.toml"
    text = edit(SCENE).replace("ABS", str(scene_folder.parent / "outside" / "tri.obj"))
    path.write_text(text)
    out = scene_folder / "out"
    out.mkdir()
    line = assert_one_line(*cli(capfd, "render", path, "--spp", 2, "--out", out / "x.exr"), fragment)
    assert line.startswith(f"harness: error: {path}: {key}"), line
    assert listing(out) == []


def test_outside_mesh_error_names_the_resolved_path(scene_folder, capfd):
    path = scene_folder / "bad.toml"
    path.write_text(SCENE + mesh_shape("link.obj"))
    line = assert_one_line(*cli(capfd, "render", path, "--spp", 2, "--out", scene_folder / "x.exr"))
    assert str(scene_folder.parent / "outside" / "tri.obj") in line and "--allow-outside-paths" in line


def test_allow_outside_paths_flag_and_keyword(scene_folder, capfd, monkeypatch):
    monkeypatch.delenv("HARNESS_ALLOW_OUTSIDE_PATHS", raising=False)
    path = scene_folder / "out.toml"
    path.write_text(SCENE + mesh_shape("../outside/tri.obj"))
    with pytest.raises(HarnessError):
        load_scene(path)
    scene = load_scene(path, allow_outside_paths=True)
    assert scene.shapes[1].file == (scene_folder.parent / "outside" / "tri.obj").resolve()
    code, out, err = cli(capfd, "render", path, "--spp", 2, "--out", scene_folder / "x.exr", "--quiet",
                         "--allow-outside-paths")
    assert code == 0, err
    assert (scene_folder / "x.exr").is_file()
    assert "HARNESS_ALLOW_OUTSIDE_PATHS" not in os.environ  # the flag lasts for its command only
    from harness.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for command in ("render", "ground-truth", "run", "report", "convergence", "calibrate"):
        assert "--allow-outside-paths" in sub.choices[command].format_help(), command


def test_meshes_inside_the_folder_still_load(scene_folder):
    path = scene_folder / "in.toml"
    path.write_text(SCENE + mesh_shape("tri.obj") + mesh_shape("./tri.obj").replace('type = "mesh"', 'type = "mesh"\nname = "again"'))
    assert len(load_scene(path, allow_outside_paths=False).shapes) == 3


# --------------------------------------------------------------------------------------------------------------------
# Absurd budgets: refused with a memory and a time estimate, naming what to lower.


def test_memory_and_time_estimates_follow_the_formula():
    assert limits.BYTES_PER_PIXEL == 168
    assert limits.memory_bytes(256, 256) == 256 * 256 * 168
    assert limits.render_seconds(1000, 1000, 100) == pytest.approx(100.0)


def test_absurd_spp_refused_with_estimates(scene_folder, capfd):
    out = scene_folder / "out"
    out.mkdir()
    line = assert_one_line(*cli(capfd, "render", scene_folder / "scene.toml", "--spp", 10**10, "--out",
                                out / "x.exr"), "--spp:", "KiB of memory", "days", "paths at 1 M paths/s")
    assert "lower --spp" in line
    assert listing(out) == []


def test_film_beyond_memory_refused_naming_the_film(scene_folder, capfd, monkeypatch):
    monkeypatch.setattr(limits, "machine_memory", lambda: 2 * 2**30)  # a 2 GiB machine, whatever this one has
    path = scene_folder / "big.toml"
    path.write_text(SCENE.replace("width = 16", "width = 4096").replace("height = 16", "height = 4096"))
    line = assert_one_line(*cli(capfd, "render", path, "--spp", 1, "--out", scene_folder / "x.exr"),
                           f"{path}: film:", "2.6 GiB of memory", "2.0 GiB", "lower film.width / film.height")
    assert "paths at 1 M paths/s" in line


def test_ground_truth_refuses_absurd_spp_even_with_a_closed_form(scene_folder, capfd):
    assert_one_line(*cli(capfd, "ground-truth", scene_folder / "scene.toml", "--spp", 10**12), "--spp:", "years")
    # the closed form needs no render, but a budget no render could meet is still a typo (issue 12)
    assert_one_line(*cli(capfd, "ground-truth", ROOT / "scenes" / "furnace.toml", "--spp", 10**12), "--spp:", "years")
    code, out, err = cli(capfd, "ground-truth", ROOT / "scenes" / "furnace.toml", "--spp", 10**6, "--quiet")
    assert code == 0 and "closed form" in out, err
    assert_one_line(*cli(capfd, "ground-truth", scene_folder / "scene.toml", "--seed", -1), "--seed")


@pytest.mark.parametrize("body,fragment", [
    ("spp = 100000000000000000000", "cases[0].spp: 16 x 16 pixels at 100000000000000000000 spp"),
    ("seconds = 1e9", "cases[0].seconds: expected a time budget of at most 24.0 h"),
    ("film = { width = 100000, height = 16 }", "cases[0].film: expected at most 16384 pixels per side"),
    ("film = { width = 16384, height = 16384 }", "cases[0].film: expected at most 67108864 pixels"),
    ("ground_truth_spp = 1000000000000\nagainst = \"mitsuba\"", "cases[0].ground_truth_spp:"),
    ("tile = 5000", "cases[0].tile: expected a tile side from 1 to 1024"),
])
def test_suite_budgets_refused_before_anything_runs(scene_folder, capfd, body, fragment):
    suite = scene_folder / "s.toml"
    suite.write_text(f'[[cases]]\nname = "c"\nscene = "scene.toml"\n{body}\n')
    out = scene_folder / "run"
    line = assert_one_line(*cli(capfd, "run", suite, "--out", out, "--quiet"), fragment)
    assert line.startswith(f"harness: error: {suite}: ")
    assert not out.exists()


def test_suite_naming_a_scene_with_an_outside_mesh(scene_folder, capfd):
    (scene_folder / "out.toml").write_text(SCENE + mesh_shape("../outside/tri.obj"))
    suite = scene_folder.parent / "s.toml"  # suites may name scenes anywhere; the scene's own meshes may not leave
    suite.write_text('[[cases]]\nscene = "sub/out.toml"\n')
    assert_one_line(*cli(capfd, "run", suite, "--out", scene_folder / "run"),
                    f"{scene_folder / 'out.toml'}: shapes[1].file", "outside the scene's folder")
    assert not (scene_folder / "run").exists()


@pytest.mark.parametrize("body,fragment", [
    ('scene = "nope.toml"', "cases[0].scene: no scene 'nope.toml'"),
    ('scene = "scene.toml"\nrenderer = "refrence"', "did you mean 'reference'"),
    ('scene = "scene.toml"\nagainst = "grund-truth"', "did you mean 'ground-truth'"),
    ('scene = "scene.toml"\nexpect = "maybe"', "cases[0].expect"),
    ('scene = "scene.toml"\nmetrics = ["rsme"]', "did you mean 'rmse'"),
    ('scene = "scene.toml"\nalpha = nan', "cases[0].alpha"),
])
def test_bad_suite_is_one_line(scene_folder, capfd, body, fragment):
    suite = scene_folder / "s.toml"
    suite.write_text(f"[[cases]]\n{body}\n")
    assert_one_line(*cli(capfd, "run", suite, "--out", scene_folder / "run"), f"{suite}: ", fragment)
    assert not (scene_folder / "run").exists()


def test_repository_suites_and_scenes_still_load():
    for path in sorted((ROOT / "scenes").glob("*.toml")):
        load_scene(path, allow_outside_paths=False)
    for path in sorted((ROOT / "suites").glob("*.toml")):
        assert isinstance(load_suite(path), Suite)


# --------------------------------------------------------------------------------------------------------------------
# EXR files through `harness compare`.


@pytest.fixture(scope="module")
def exr_pair(tmp_path_factory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("exr")
    rng = np.random.default_rng(7)
    paths = []
    for name in ("a", "b"):
        image = (1 + 0.1 * rng.standard_normal((16, 16, 3))).astype(np.float32)
        paths.append(imageio.write_exr(folder / f"{name}.exr", image, np.full_like(image, 0.01),
                                       metadata={"spp": "16"}))
    return paths[0], paths[1]


def test_intact_pair_compares(exr_pair, capfd):
    code, out, err = cli(capfd, "compare", *exr_pair)
    assert code in (0, 1) and err == "" and out.startswith("verdict:")


def test_truncated_exr_at_every_offset_is_one_line(exr_pair, tmp_path, capfd):
    data = exr_pair[0].read_bytes()
    offsets = sorted({0, 3, 4, 8, 40, 120, 300, len(data) // 2, len(data) - 200, len(data) - 100, len(data) - 1})
    for offset in offsets:
        path = tmp_path / f"t{offset}.exr"
        path.write_bytes(data[:offset])
        assert_one_line(*cli(capfd, "compare", path, exr_pair[1]), f"{path}: ")


def test_corrupted_exr_bytes_never_escape(exr_pair, tmp_path, capfd):
    """Random byte edits (seeded): every file is read or refused in one line, with no library chatter on stdout or
    stderr. A changed byte may land where it changes nothing the reader checks (metadata, padding)."""
    data = exr_pair[0].read_bytes()
    rng = random.Random(11)
    refused = 0
    for index in range(60):
        broken = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            broken[rng.randrange(len(broken))] = rng.randrange(256)
        path = tmp_path / f"c{index}.exr"
        path.write_bytes(bytes(broken))
        code, out, err = cli(capfd, "compare", path, exr_pair[1])
        if code == 2:
            assert_one_line(code, out, err, f"{path}: ")
            refused += 1
        else:
            assert code in (0, 1) and err == "", err
    assert refused >= 30


def _patch_data_window(data: bytes, x_max: int, y_max: int) -> bytes:
    start = data.index(b"dataWindow\x00box2i\x00") + len(b"dataWindow\x00box2i\x00") + 4
    x_min, y_min, _, _ = struct.unpack("<4i", data[start:start + 16])
    return data[:start] + struct.pack("<4i", x_min, y_min, x_max, y_max) + data[start + 16:]


def test_exr_header_claiming_a_huge_image_is_refused_before_reading(exr_pair, tmp_path, capfd):
    path = tmp_path / "huge.exr"
    path.write_bytes(_patch_data_window(exr_pair[0].read_bytes(), 200000, 200000))
    assert_one_line(*cli(capfd, "compare", path, exr_pair[1]), "data window is 200001 x 200001 pixels", "TiB")


def test_exr_content_problems(exr_pair, tmp_path, capfd):
    import OpenEXR

    ones = np.ones((16, 16), np.float32)
    OpenEXR.File({"type": OpenEXR.scanlineimage}, {"Y": ones}).write(str(tmp_path / "y.exr"))
    OpenEXR.File({"type": OpenEXR.scanlineimage}, {"R": ones, "G": ones, "B": ones.astype(np.uint32)}).write(
        str(tmp_path / "uint.exr"))
    imageio.write_exr(tmp_path / "big.exr", np.ones((32, 16, 3)), np.ones((32, 16, 3)))
    nan = np.ones((16, 16, 3))
    nan[2, 3, 1] = np.nan
    imageio.write_exr(tmp_path / "nan.exr", nan, np.ones((16, 16, 3)))
    imageio.write_exr(tmp_path / "novar.exr", np.ones((16, 16, 3)))
    a, b = exr_pair
    assert_one_line(*cli(capfd, "compare", tmp_path / "y.exr", b), "missing R, G, B (found: Y)")
    assert_one_line(*cli(capfd, "compare", tmp_path / "uint.exr", b), "expected HALF or FLOAT")
    assert_one_line(*cli(capfd, "compare", a, tmp_path / "big.exr"), "size 16x16 differs", "16x32")
    assert_one_line(*cli(capfd, "compare", a, tmp_path / "nan.exr"), "1 non-finite", "reference must be finite")
    assert_one_line(*cli(capfd, "compare", a, tmp_path / "novar.exr"), "no variance channels")
    assert_one_line(*cli(capfd, "compare", a, tmp_path), "is a folder")
    assert_one_line(*cli(capfd, "compare", a, tmp_path / "none.exr"), "no such file")


@pytest.mark.parametrize("option,value,fragment", [
    ("--tile", 0, "--tile: expected an integer from 1 to 1024"),
    ("--tile", 100000, "--tile: expected an integer from 1 to 1024"),
    ("--alpha", 0, "--alpha: expected a false-alarm probability"),
    ("--alpha", "nan", "--alpha: expected a false-alarm probability"),
    ("--alpha", 2, "--alpha: expected a false-alarm probability"),
])
def test_compare_options(exr_pair, capfd, option, value, fragment):
    assert_one_line(*cli(capfd, "compare", *exr_pair, option, value), fragment)


# --------------------------------------------------------------------------------------------------------------------
# Unwritable outputs: one line, exit 2, nothing half-written.


def test_unwritable_outputs(scene_folder, capfd, tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    before = listing(tmp_path)
    assert_one_line(*cli(capfd, "render", scene_folder / "scene.toml", "--spp", 2, "--out", blocker / "x.exr"),
                    "--out")
    assert_one_line(*cli(capfd, "render", scene_folder / "scene.toml", "--spp", 2, "--out", tmp_path / "no" / "x.exr"),
                    "--out", "does not exist")
    suite = tmp_path / "s.toml"
    suite.write_text('[[cases]]\nscene = "sub/scene.toml"\nspp = 2\nagainst = { renderer = "reference", spp = 2 }\n')
    assert_one_line(*cli(capfd, "run", suite, "--out", blocker, "--quiet"), "--out")
    assert_one_line(*cli(capfd, "ground-truth", scene_folder / "scene.toml", "--spp", 2, "--cache-dir", blocker),
                    str(blocker))
    results = tmp_path / "results.json"
    results.write_text('{"suite": "s", "cases": []}')
    assert_one_line(*cli(capfd, "report", results, "--out", blocker, "--no-convergence", "--no-shadow-rays",
                         "--no-strategies"), "--out")
    assert listing(tmp_path) == sorted(before + ["results.json", "s.toml"])
    assert blocker.read_text() == "not a folder"


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores folder permissions")
def test_read_only_folder(scene_folder, capfd, tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        assert_one_line(*cli(capfd, "render", scene_folder / "scene.toml", "--spp", 2, "--out", folder / "x.exr"),
                        "--out", "not writable")
        assert listing(folder) == []
    finally:
        folder.chmod(0o700)


# --------------------------------------------------------------------------------------------------------------------
# A renderer's bad image fails its case only.


def result_with(**changes) -> RenderResult:
    values = dict(renderer="fake", image=np.ones((4, 6, 3), np.float32), variance=np.full((4, 6, 3), 0.1, np.float32),
                  seconds=0.5, spp=8, rays={}, stats={}, settings={})
    values.update(changes)
    return RenderResult(**values)


def test_validate_result_accepts_a_good_image_and_some_nan_pixels():
    validate_result(result_with(), 6, 4)
    image = np.ones((4, 6, 3), np.float32)
    image[1, 2] = np.nan
    variance = np.full((4, 6, 3), 0.1, np.float32)
    variance[1, 2] = np.nan  # no variance where the image is not finite: the verdict counts the pixel and fails
    validate_result(result_with(image=image, variance=variance), 6, 4)


@pytest.mark.parametrize("changes,fragment", [
    ({"image": np.ones((6, 4, 3), np.float32)}, "shape (6, 4, 3); expected (4, 6, 3)"),
    ({"image": np.ones((4, 6), np.float32)}, "shape (4, 6)"),
    ({"image": [[1.0]]}, "image is a list"),
    ({"image": np.ones((4, 6, 3), np.int32)}, "dtype int32"),
    ({"image": np.full((4, 6, 3), np.nan, np.float32)}, "NaN or infinite at every one of its 24 pixels"),
    ({"variance": None}, "no variance"),
    ({"variance": np.full((4, 6, 3), -0.1, np.float32)}, "negative at 24 pixels"),
    ({"variance": np.full((4, 6, 3), np.nan, np.float32)}, "use spp >= 2"),
    ({"variance": np.ones((4, 5, 3), np.float32)}, "variance has shape"),
    ({"spp": 0}, "spp is 0"),
    ({"seconds": math.nan}, "seconds is nan"),
])
def test_validate_result_refuses(changes, fragment):
    with pytest.raises(BadRenderError) as info:
        validate_result(result_with(**changes), 6, 4)
    assert fragment in str(info.value) and "\n" not in str(info.value)


class _BadRenderer:
    """Renders with the reference, then spoils the result one way (or crashes)."""

    def __init__(self, how: str):
        self.name, self.how = f"bad-{how}", how

    def render(self, scene, request):
        from harness.renderers import get_renderer

        if self.how == "crash":
            raise RuntimeError("the renderer fell over <script>alert(1)</script>")
        result = get_renderer("reference").render(scene, request)
        if self.how == "shape":
            result.image = result.image[:, :-1]
        elif self.how == "nan":
            result.image = np.full_like(result.image, np.nan)
        elif self.how == "negative-variance":
            result.variance = -np.abs(result.variance) - 1
        return result


BAD_HOWS = ("crash", "shape", "nan", "negative-variance")


@pytest.fixture(scope="module")
def bad_run(tmp_path_factory):
    """A suite whose cases use misbehaving renderers, a good case last; its run and its report."""
    from harness import renderers
    from harness.report import ReportOptions, write_suite_report
    from harness.running.schedule import run_suite

    folder = tmp_path_factory.mktemp("bad-run")
    evil = "<script>alert(\"x\")</script> & 'quotes'"
    scene_file = "evil<u>\"q'.toml"  # the report shows scene file names
    (folder / scene_file).write_text(SCENE.replace('name = "tiny"', f"name = {toml_string(evil)}"))
    scene = toml_string(scene_file)
    cases = "".join(f'[[cases]]\nname = "{how}"\nscene = {scene}\nrenderer = "bad-{how}"\n' for how in BAD_HOWS)
    cases += f'[[cases]]\nname = {toml_string(evil)}\nscene = {scene}\n'
    (folder / "s.toml").write_text('name = "evil <i>suite</i>"\n[defaults]\nspp = 8\n'
                                   'against = { renderer = "reference", spp = 16, seed = 5 }\n' + cases)
    mp = pytest.MonkeyPatch()
    for how in BAD_HOWS:
        mp.setitem(renderers._RENDERERS, f"bad-{how}", lambda how=how: _BadRenderer(how))
    try:
        suite = load_suite(folder / "s.toml")
        results = run_suite(suite, folder / "out")
    finally:
        mp.undo()
    options = ReportOptions(convergence=False, shadow_rays=False, strategies=False)
    write_suite_report(folder / "out" / "results.json", folder / "out", options)
    return results, folder / "out", evil


def test_bad_renderers_fail_their_cases_and_the_suite_goes_on(bad_run):
    results, out, _ = bad_run
    records = {r["name"]: r for r in results["cases"]}
    assert len(records) == 5
    reasons = {how: records[how]["reason"] for how in BAD_HOWS}
    assert all(records[how]["status"] == "error" and not records[how]["ok"] for how in BAD_HOWS), reasons
    assert "fell over" in reasons["crash"]
    assert "BadRenderError" in reasons["shape"] and "shape" in reasons["shape"]
    assert "every one of its 256 pixels" in reasons["nan"]
    assert "negative" in reasons["negative-variance"]
    good = next(r for name, r in records.items() if name not in BAD_HOWS)
    assert good["status"] == "pass"
    assert not any((out / "cases" / how / "render.exr").exists() for how in ("shape", "nan", "negative-variance"))


def test_report_escapes_scene_suite_and_case_strings(bad_run):
    _, out, evil = bad_run
    page = (out / "index.html").read_text()
    # the page's scripts are the package's own: the summary table's and the comparison viewer's (harness/report/static)
    scripts = re.findall(r"<script>(.*?)</script>", page, re.S)
    assert page.count("<script") == len(scripts) == 8 and not any("alert(" in script for script in scripts)
    assert "<script>alert" not in page and "<u>" not in page and "<i>suite</i>" not in page
    assert html.escape(evil, quote=True) in page  # a case name
    assert html.escape("evil<u>\"q'", quote=True) in page  # the scene file's name
    assert "evil &lt;i&gt;suite&lt;/i&gt;" in page  # the suite's name
    assert "fell over &lt;script&gt;" in page  # a renderer's error message


# --------------------------------------------------------------------------------------------------------------------
# No shell: every external command is an argument list.


def test_no_shell_anywhere():
    pattern = re.compile(r"shell\s*=\s*True|os\.system\(|os\.popen\(|subprocess\.getoutput|subprocess\.getstatusoutput")
    offenders = [f"{p.relative_to(ROOT)}:{n}" for folder in ("harness", "reference_impl")
                 for p in sorted((ROOT / folder).rglob("*.py"))
                 for n, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert offenders == []


# --------------------------------------------------------------------------------------------------------------------
# Fuzzing the suite loader: every input ends in a Suite or one line naming the file.

SUITE_SEEDS = {
    "smoke": (ROOT / "suites" / "smoke.toml").read_text(),
    "small": '''
name = "small"
description = "every kind of key"
[defaults]
spp = 8
ground_truth_spp = 64
film = { width = 16, height = 16 }
metrics = ["rmse", "psnr", "bias"]
thresholds = { rmse = 0.5, psnr = 10 }
[[cases]]
name = "a"
scene = "furnace"
settings = { direct = "mis", shadow_rays = 2, two_sided = true }
alpha = 0.01
tile = 4
[[cases]]
name = "b"
scene = "../scenes/cornell-box.toml"
seconds = 0.5
chunk_spp = 2
seed = 3
max_depth = 3
expect = "fail"
against = { renderer = "reference", spp = 32, seed = 9, settings = { rr = "off" } }
[[cases]]
name = "c"
scene = "soft-shadows"
renderer = "mitsuba"
against = "closed-form"
''',
}
SUITE_KEY_NAMES = ["name", "description", "defaults", "cases", "scene", "renderer", "settings", "spp", "seconds",
                   "chunk_spp", "seed", "against", "film", "metrics", "thresholds", "expect", "alpha", "tile",
                   "ground_truth_spp", "max_depth", "width", "height", "rmse", "psnr", "direct", "sped", "casez"]
SUITE_WORDS = ["pass", "fail", "maybe", "ground-truth", "closed-form", "mitsuba", "reference", "refrence", "furnace",
               "cornell-box", "nope", "../scenes/furnace.toml", "/etc/passwd", "rmse", "flip", "mis", "", "\u00e9\u6f22",
               "<script>", "a\nb"]

suite_scalars = st.one_of(
    st.booleans(), st.integers(-3, 70000), st.integers(), st.floats(),
    st.sampled_from([0, -1, 1, 2**31, 2**63 - 1, 10**30, 10**400, -(10**400), 1e308, -0.0, 1e-300, 16384, 16385]),
    st.text(st.characters(exclude_categories=["Cs"]), max_size=8), st.sampled_from(SUITE_WORDS),
)
suite_values = st.recursive(
    suite_scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.sampled_from(SUITE_KEY_NAMES), inner, max_size=3),
    max_leaves=8,
)


def _entries(node) -> list[tuple]:
    pairs = []
    for key, child in node.items() if isinstance(node, dict) else enumerate(node):
        pairs.append((node, key))
        if isinstance(child, (dict, list)):
            pairs += _entries(child)
    return pairs


def mutate_suite(document: dict, data) -> None:
    """One random edit: replace a value (anything, or a bad enum), delete an entry, or add an entry (an unknown key,
    a known key in the wrong place)."""
    rng = data.draw(st.randoms(use_true_random=False))
    pairs = _entries(document)
    action = data.draw(st.sampled_from(["replace", "replace", "enum", "delete", "add"]))
    if action != "add" and pairs:
        container, key = rng.choice(pairs)
        if action == "delete":
            del container[key]
        elif action == "enum":
            container[key] = data.draw(st.sampled_from(SUITE_WORDS))
        else:
            container[key] = data.draw(suite_values)
        return
    containers = [document] + [c[k] for c, k in pairs if isinstance(c[k], (dict, list))]
    container = rng.choice(containers)
    if isinstance(container, dict):
        key = data.draw(st.sampled_from(SUITE_KEY_NAMES) | st.text(st.characters(exclude_categories=["Cs"]),
                                                                      max_size=6))
        container[key] = data.draw(suite_values)
    else:
        container.append(data.draw(suite_values))


def named_files(path: Path) -> list[str]:
    """The files a suite's error may name: the suite, and every file a string of it names the way the loader
    looks for scenes and renderer files (beside the suite, as given, or a scene name in scenes/), e.g. a suite
    whose case names /etc/passwd as its scene gets "/etc/passwd: line 1, column 5: malformed TOML ..."."""
    names = [str(path)]
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError):
        return names
    for container, key in _entries(document):
        value = container[key]
        if isinstance(value, str) and value:
            names += [value, str(path.parent / value), str(path.parent.parent / "scenes" / f"{value}.toml"),
                      str(ROOT / "scenes" / f"{value}.toml")]
    return names


def load_or_one_line(path: Path) -> None:
    """load_suite returns a Suite or raises a HarnessError of one line naming this suite or a file it names (a
    scene, a renderer file)."""
    try:
        assert isinstance(load_suite(path), Suite)
    except HarnessError as err:
        text = str(err)
        assert len(text.splitlines()) == 1, text
        assert any(text.startswith(f"{name}: ") for name in named_files(path)), text
        assert len(text) < 2000, text


def test_suite_error_may_name_the_scene_file_it_names(suite_fuzz_folder):
    """A scene the suite names that is not a scene file is named by its own path (this made the fuzz test flaky:
    a generated case named /etc/passwd as its scene)."""
    path = suite_fuzz_folder / "passwd.toml"
    path.write_text('[[cases]]\nname = "a"\nscene = "/etc/passwd"\n')
    with pytest.raises(HarnessError, match="^/etc/passwd: "):
        load_suite(path)
    load_or_one_line(path)


@pytest.fixture(scope="module")
def suite_fuzz_folder(tmp_path_factory) -> Path:
    """tmp/suites/ for the fuzzed files, tmp/scenes/ with the canonical scenes (suites name them by name)."""
    root = tmp_path_factory.mktemp("suite-fuzz")
    (root / "suites").mkdir()
    (root / "scenes").mkdir()
    for scene in (ROOT / "scenes").glob("*.toml"):
        (root / "scenes" / scene.name).write_text(scene.read_text())
    return root / "suites"


@settings(max_examples=fuzz_examples(300), deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(data=st.data(), seed=st.sampled_from(sorted(SUITE_SEEDS)))
def test_fuzz_suite_documents(suite_fuzz_folder, data, seed):
    document = copy.deepcopy(tomllib.loads(SUITE_SEEDS[seed]))
    for _ in range(data.draw(st.integers(1, 3))):
        mutate_suite(document, data)
    path = suite_fuzz_folder / "mutated.toml"
    path.write_text(to_toml(document))
    load_or_one_line(path)


@settings(max_examples=fuzz_examples(100), deadline=None)
@given(data=st.data(), seed=st.sampled_from(sorted(SUITE_SEEDS)))
def test_fuzz_suite_text(suite_fuzz_folder, data, seed):
    """Broken TOML syntax and stray characters anywhere in the text."""
    text = SUITE_SEEDS[seed]
    for _ in range(data.draw(st.integers(1, 3))):
        start = data.draw(st.integers(0, len(text)))
        end = data.draw(st.integers(start, min(len(text), start + 20)))
        text = text[:start] + data.draw(st.text(alphabet='[]{}=",.#-+0123456789 \nabcxyz\u00e9', max_size=10)) \
            + text[end:]
    path = suite_fuzz_folder / "edited.toml"
    path.write_bytes(text.encode("utf-8"))
    load_or_one_line(path)


def test_fuzz_suite_special_inputs(suite_fuzz_folder):
    """Inputs a generator rarely makes: bytes that are not UTF-8, huge integers, deep nesting, a folder."""
    specials = [b"\xff\xfe[[cases]]", b"name = 1" + b"0" * 5000, b"a = " + b"[" * 2000 + b"]" * 2000,
                b"[[cases]]\nscene = \"furnace\"\nspp = " + b"9" * 400, b"[[cases]]\nscene = \"furnace\"\nalpha = "
                + b"9" * 400, b"[[cases]]\nscene = \"furnace\"\nseconds = " + b"9" * 400,
                b"[[cases]]\nscene = \"furnace\"\nthresholds = { rmse = " + b"9" * 400 + b" }",
                b"[[cases]]\nscene = \"furnace\"\nfilm = { width = " + b"9" * 400 + b" }", b"", b"cases = []"]
    for index, data in enumerate(specials):
        path = suite_fuzz_folder / f"special{index}.toml"
        path.write_bytes(data)
        load_or_one_line(path)
    with pytest.raises(HarnessError):
        load_suite(suite_fuzz_folder)


def test_fuzz_suite_through_the_cli(suite_fuzz_folder):
    """A few broken suites (seeded random edits of the smoke suite that the loader refuses) through the real entry
    point: exit 2, one line, no traceback, nothing written."""
    rng = random.Random(5)
    base = SUITE_SEEDS["small"]
    broken = []
    while len(broken) < 2:
        position = rng.randrange(len(base))
        text = base[:position] + rng.choice(["]", "=", '"', "x = ", "spp = -1\n", "\u00e9", "[[cases]]\n"]) + \
            base[position:]
        path = suite_fuzz_folder / f"cli{len(broken)}.toml"
        path.write_text(text)
        try:
            load_suite(path)
        except HarnessError:
            broken.append(path)
    out = suite_fuzz_folder.parent / "cli-out"
    for path in broken:
        proc = subprocess.run([sys.executable, "-m", "harness", "run", str(path), "--out", str(out)],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert proc.stdout == "" and "Traceback" not in proc.stderr
        assert len(proc.stderr.splitlines()) == 1 and proc.stderr.startswith(f"harness: error: {path}"), proc.stderr
        assert not out.exists()


@pytest.mark.parametrize("how", ["crash", "shape"])
def test_render_command_with_a_bad_renderer_fails_in_one_line_and_writes_nothing(how, tmp_path, monkeypatch, capsys):
    """``harness render`` checks what an in-process renderer returns before writing: a wrong-shaped image or a crash
    inside the renderer is a failed render (exit 1, one line), not a traceback."""
    from harness import cli, renderers

    monkeypatch.setitem(renderers._RENDERERS, f"bad-{how}", lambda: _BadRenderer(how))
    out = tmp_path / "x.exr"
    args = ["render", str(ROOT / "scenes" / "furnace.toml"), "--renderer", f"bad-{how}", "--spp", "2", "--out", str(out),
            "--quiet"]
    monkeypatch.delenv("HARNESS_DEBUG", raising=False)
    assert cli.main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "render failed" in err[0] and ("shape" if how == "shape" else "fell over") in err[0]
    assert not out.exists()


def test_suite_comparing_against_a_one_sample_reference_is_refused(tmp_path):
    """A reference render of one sample per pixel has no variance to judge with: the loader says so, naming the key,
    before anything runs (it used to stop the run half-way with a message naming no file)."""
    suite = tmp_path / "s.toml"
    suite.write_text('[[cases]]\nscene = "furnace"\nagainst = { renderer = "reference", spp = 1 }\n')
    with pytest.raises(HarnessError) as err:
        load_suite(suite)
    assert err.value.where.endswith("cases[0].against.spp") and str(suite) in err.value.where


@pytest.mark.parametrize("data", [b'command = ["x"]\nn = 1' + b"0" * 5000, b'a = ' + b"[" * 2000 + b"]" * 2000,
                                  b"\xff\xfe command", b"command = [", b""])
def test_hostile_renderer_files_are_one_line_errors(capfd, tmp_path, data):
    """Renderer TOML files get the suite files' treatment: an integer beyond Python's digit limit, absurd nesting,
    bytes that are not UTF-8 or broken TOML are one line naming the file (the first two were a traceback)."""
    path = tmp_path / "renderer.toml"
    path.write_bytes(data)
    out = tmp_path / "out.exr"
    assert_one_line(*cli(capfd, "render", ROOT / "scenes" / "furnace.toml", "--renderer", path, "--spp", "2", "--out", out),
                    str(path))
    assert not out.exists()
