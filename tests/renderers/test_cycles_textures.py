"""Textures in the Blender Cycles adapter (renderers/cycles_render.py, docs/cycles.md): every filter, wrap mode, raw
and EXR bitmap and a checkerboard under to_uv, on the textured white furnace (a diffuse sphere under a constant sky
at max_depth 2, so each pixel is the texture's mean over its footprint: the closed form
harness.renderers.groundtruth.textured_sphere_means, from the reference's lookups, themselves checked against
Mitsuba 3.9.1's); the same scenes with the wrong filter or wrap handed to Cycles, and the adapter's planted texture
faults, must be far off; what Cycles cannot match is refused in one line. Renders are 16 x 16 at 128 spp; everything
that needs bpy is skipped without it."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.files.imageio import exr_bytes, read_exr
from harness.renderers.groundtruth import textured_sphere_means
from harness.renderers.scene_json import scene_json
from harness.scene import load_scene
from test_cycles import _one_line_error

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "renderers" / "cycles_render.py"
SIZE, SPP = 16, 128
#: the mean |Cycles - closed form| over the image, relative to the image's mean, that a correct lookup stays below
#: (measured at 32 x 32, 256 spp: 0.08 % to 0.95 %, nearest the largest: its texel edges inside pixels are noisy)
CLOSE = 0.025
#: ... and that a wrong one exceeds (measured: v read upside down 52 %, sRGB decoded after filtering 11 %)
FAR = 0.05

pytestmark = [pytest.mark.cycles, pytest.mark.slow]

_OFF = "to_uv = { scale = [2.5, 1.5], translate = [-0.7, -0.3] }"  # u' in [-0.7, 1.8], v' in [-0.3, 1.2]: wraps
VARIANTS = {
    "bilinear-repeat": f'filename = "textures/tiles.png"\n{_OFF}',
    "nearest-repeat": f'filename = "textures/tiles.png"\nfilter_type = "nearest"\n{_OFF}',
    "bilinear-mirror": f'filename = "textures/tiles.png"\nwrap_mode = "mirror"\n{_OFF}',
    "nearest-mirror": f'filename = "textures/tiles.png"\nfilter_type = "nearest"\nwrap_mode = "mirror"\n{_OFF}',
    "bilinear-clamp-rotated": 'filename = "textures/tiles.png"\nwrap_mode = "clamp"\n'
                              'to_uv = { scale = [2.5, 1.5], translate = [-0.7, -0.3], rotate = 20.0 }',
    "nearest-clamp-raw": f'filename = "textures/tiles.png"\nfilter_type = "nearest"\nwrap_mode = "clamp"\nraw = true\n'
                         f'{_OFF}',
    "exr-bilinear": 'filename = "textures/float.exr"\nto_uv = { scale = [1.5, 1.5], translate = [0.2, -0.1], '
                    'rotate = -30.0 }',
    "checkerboard-affine": 'type = "checkerboard"\ncolor0 = [0.9, 0.5, 0.2]\ncolor1 = [0.1, 0.3, 0.7]\n'
                           'to_uv = [[3.0, 1.0, 0.25], [-0.5, 2.0, 0.1], [0.0, 0.0, 1.0]]',
}


@pytest.fixture(scope="module")
def bpy_present():
    pytest.importorskip("bpy")


@pytest.fixture(scope="module")
def scenes(tmp_path_factory) -> Path:
    """textured-furnace.toml with each variant's [textures.tiles], beside tiles.png and a 8 x 12 float EXR."""
    folder = tmp_path_factory.mktemp("textured")
    (folder / "textures").mkdir()
    shutil.copy(ROOT / "scenes" / "textures" / "tiles.png", folder / "textures" / "tiles.png")
    rng = np.random.default_rng(1)
    (folder / "textures" / "float.exr").write_bytes(exr_bytes(rng.random((8, 12, 3)).astype(np.float32)))
    base = (ROOT / "scenes" / "textured-furnace.toml").read_text(encoding="utf-8")
    head, rest = base.split("[textures.tiles]")
    tail = "[materials.tiles]" + rest.split("[materials.tiles]")[1]
    for name, table in VARIANTS.items():
        (folder / f"{name}.toml").write_text(f"{head}[textures.tiles]\n{table}\n\n{tail}", encoding="utf-8")
    return folder


def write_scene_json(scene, out: Path, size: int, edit=None) -> Path:
    """``scene`` at ``size`` x ``size`` as scene.json and its files in ``out`` (``edit(document)`` applied)."""
    scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=size, height=size))
    document, files = scene_json(scene)
    if edit is not None:
        edit(document)
    for rel, data in files.items():
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        (out / rel).write_bytes(data)
    (out / "scene.json").write_text(json.dumps(document), encoding="utf-8")
    return out / "scene.json"


def _export(toml: Path, out: Path, edit=None):
    """The scene at 16 x 16 as scene.json in ``out`` (``edit(document)`` applied), and its closed form."""
    scene = load_scene(toml)
    path = write_scene_json(scene, out, SIZE, edit)
    return path, dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=SIZE, height=SIZE))


def _run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=300)


def _relative_error(scene_path: Path, scene, *extra) -> float:
    out = scene_path.parent / "r.exr"
    proc = _run(scene_path, "--spp", SPP, "--seed", 1, "--out", out, *extra)
    assert proc.returncode == 0, proc.stderr
    image = read_exr(out).image
    exact = textured_sphere_means(scene)
    return float(np.abs(image - exact).mean() / exact.mean())


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_texture_lookup_matches_the_closed_form(tmp_path, scenes, bpy_present, variant):
    path, scene = _export(scenes / f"{variant}.toml", tmp_path)
    assert _relative_error(path, scene) < CLOSE


_SWAPS = {"bilinear-repeat": ("wrap_mode", "mirror"), "bilinear-mirror": ("wrap_mode", "repeat"),
          "nearest-mirror": ("wrap_mode", "clamp"), "bilinear-clamp-rotated": ("wrap_mode", "repeat"),
          "nearest-repeat": ("filter_type", "bilinear")}


@pytest.mark.parametrize("variant", list(_SWAPS))
def test_the_wrong_filter_or_wrap_is_far_off(tmp_path, scenes, bpy_present, variant):
    """The test above can tell the modes apart: the same scene.json with another wrap or filter is far off."""
    key, value = _SWAPS[variant]
    path, scene = _export(scenes / f"{variant}.toml", tmp_path,
                          lambda document: document["textures"]["tiles"].update({key: value}))
    assert _relative_error(path, scene) > FAR


@pytest.mark.parametrize("fault", ["v-unflipped", "srgb-after-filter"])
def test_planted_texture_faults_are_far_off(tmp_path, bpy_present, fault):
    path, scene = _export(ROOT / "scenes" / "textured-furnace.toml", tmp_path)
    assert _relative_error(path, scene, "--texture-fault", fault) > FAR


def _refused(tmp_path: Path, edit, *words: str) -> None:
    path, _ = _export(ROOT / "scenes" / "textured-cornell-box.toml", tmp_path, edit)
    _one_line_error(_run(path, "--spp", 4, "--out", tmp_path / "x.exr"), *words)
    assert not (tmp_path / "x.exr").exists()


def test_a_textured_tint_on_a_fresnel_conductor_is_refused(tmp_path, bpy_present):
    def edit(document):
        document["materials"]["metal"].update(eta=[0.2, 0.9, 1.1], k=[3.9, 2.4, 2.2])
    _refused(tmp_path, edit, "materials.metal.specular_reflectance", "'tint'", "no tint")


def test_different_textures_on_a_dielectric_are_refused(tmp_path, bpy_present):
    def edit(document):
        document["materials"]["metal"] = {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0,
                                          "specular_reflectance": {"texture": "tint"},
                                          "specular_transmittance": {"texture": "floor"}}
    _refused(tmp_path, edit, "materials.metal", "Glass BSDF")


def test_a_texture_on_a_shape_without_coordinates_is_refused(tmp_path, bpy_present):
    def edit(document):
        document["shapes"][1]["uv"] = None
    _refused(tmp_path, edit, "shapes[1] (floor)", "'floor'", "texture coordinates")


@pytest.mark.parametrize("edit, words", [
    (lambda d: d["textures"]["wall"].update(filter_type="bicubic"), ("textures.wall.filter_type", "'bicubic'")),
    (lambda d: d["textures"]["wall"].update(wrap_mode="zero"), ("textures.wall.wrap_mode", "'zero'")),
    (lambda d: d["textures"]["floor"].update(type="noise"), ("textures.floor.type", "'noise'")),
])
def test_unknown_texture_settings_are_refused(tmp_path, bpy_present, edit, words):
    _refused(tmp_path, edit, *words)
