"""Participating media in the Blender Cycles adapter (renderers/cycles_render.py, docs/cycles.md, "Participating
media"): scene.json's homogeneous media reach Cycles' node tree as Volume Coefficients (sigma_s = albedo sigma_t,
sigma_a = (1 - albedo) sigma_t per channel, Henyey-Greenstein anisotropy g) on a shape's Volume output or the
World's; a null material has no surface shader; an absorbing slab in front of a constant sky renders
exp(-sigma_t d) per channel (Beer-Lambert); what Cycles' volumes cannot say is refused in one line.

The scenes are written as scene.json by hand (a diffuse cube exported by the harness, then made a null boundary
holding a medium), in the form of the media contract (docs/scene-json.md). Renders are 16 x 16; everything that
needs bpy is skipped without it."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.files.imageio import read_exr
from harness.scene import load_scene
from test_cycles import _module, _one_line_error
from test_cycles_textures import write_scene_json

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "renderers" / "cycles_render.py"
SIZE = 16
#: the slab's extinction per channel (three different transmittances) and thickness (a cube of side 1)
SIGMA_T = (1.0, 0.5, 2.0)
#: an orthographic camera (film 2 x 2 scene units, 16 x 16 pixels of 1/8) along -z through a cube of side 1 at the
#: origin (its faces on pixel edges: the middle 8 x 8 pixels) in front of a constant sky of radiance 1
SLAB = """
name = "cycles-media-slab"
[camera]
type = "orthographic"
origin = [0.0, 0.0, 3.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
scale = 1.0
[film]
width = 16
height = 16
filter = "box"
[integrator]
max_depth = -1
[materials.boundary]
reflectance = [0.5, 0.5, 0.5]
[[shapes]]
name = "slab"
type = "cube"
material = "boundary"
scale = 0.5
[[emitters]]
name = "sky"
type = "constant"
radiance = [1.0, 1.0, 1.0]
"""
#: |Cycles - exp(-sigma_t d)| that an exact slab stays below (measured: 3.6e-7, float rounding: an absorbing
#: homogeneous medium's transmittance is evaluated, not sampled, so there is no noise) ...
CLOSE = 1e-4

pytestmark = [pytest.mark.cycles, pytest.mark.slow]


@pytest.fixture(scope="module")
def bpy_present():
    pytest.importorskip("bpy")


def _medium(sigma_t=SIGMA_T, albedo=(0.0, 0.0, 0.0), phase=None) -> dict:
    return {"type": "homogeneous", "sigma_t": list(sigma_t), "albedo": list(albedo),
            "phase": phase or {"type": "isotropic"}}


def _slab(folder: Path, medium: dict | None = None, max_depth: int = -1, **shape) -> Path:
    """The slab as scene.json in ``folder``: a null cube whose interior is ``medium`` (or as ``shape`` says)."""
    toml = folder / "slab.toml"
    toml.write_text(SLAB, encoding="utf-8")

    def edit(document):
        document["materials"]["boundary"] = {"type": "null"}
        document["media"] = {"absorber": medium or _medium()}
        document["camera"]["medium"] = None
        document["shapes"][0].update({"interior": "absorber", "exterior": None, **shape})
        document["integrator"]["max_depth"] = max_depth
    return write_scene_json(load_scene(toml), folder, SIZE, edit)


def _render(scene_path: Path, spp: int = 64) -> np.ndarray:
    out = scene_path.parent / "r.exr"
    proc = subprocess.run([sys.executable, str(SCRIPT), str(scene_path), "--spp", str(spp), "--seed", "1",
                           "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return read_exr(out).image


def _refused(scene_path: Path, *words: str) -> None:
    proc = subprocess.run([sys.executable, str(SCRIPT), str(scene_path), "--spp", "2", "--out",
                           str(scene_path.parent / "r.exr")], capture_output=True, text=True, timeout=300)
    _one_line_error(proc, *words)
    assert not (scene_path.parent / "r.exr").exists()


# ---- the mapping (no bpy) -------------------------------------------------------------------------------------------

def test_coefficients_are_mitsubas_homogeneous_medium():
    module = _module()
    sigma_s, sigma_a, g = module.medium_coefficients(
        _medium((3.0, 2.0, 1.0), (0.95, 0.8, 0.6), {"type": "hg", "g": 0.6}), "media.m")
    assert sigma_s == pytest.approx([2.85, 1.6, 0.6])
    assert sigma_a == pytest.approx([0.15, 0.4, 0.4])
    assert g == 0.6
    assert module.medium_coefficients(_medium(), "media.m")[2] == 0.0  # isotropic


@pytest.mark.parametrize("medium, words", [
    ({"type": "heterogeneous", "sigma_t": [1, 1, 1], "albedo": [0, 0, 0]}, ("media.m.type", "homogeneous")),
    (_medium(phase={"type": "rayleigh"}), ("media.m.phase.type",)),
    (_medium(phase={"type": "hg", "g": 1.0}), ("media.m.phase.g",)),
    (_medium(albedo=(0.5, 1.5, 0.5)), ("media.m", "albedo")),
])
def test_bad_media_are_refused(medium, words):
    module = _module()
    with pytest.raises(module.SceneError) as err:
        module.medium_coefficients(medium, "media.m")
    for word in words:
        assert word in str(err.value)


def _doc(camera=None, shapes=(), materials=None) -> dict:
    return {"media": {"fog": _medium(), "milk": _medium()}, "camera": {"medium": camera},
            "materials": materials or {"glass": {"type": "dielectric"}, "wall": {"type": "diffuse"},
                                       "null": {"type": "null"}},
            "shapes": [{"name": f"s{i}", "material": m, "interior": inside, "exterior": outside}
                       for i, (m, inside, outside) in enumerate(shapes)]}


@pytest.mark.parametrize("doc, world", [
    (_doc(), None),
    (_doc(shapes=[("null", "milk", None)]), None),                       # a medium in a shape
    (_doc(camera="fog", shapes=[("wall", None, None)]), "fog"),         # the camera in fog: the World's volume
    (_doc(camera="fog", shapes=[("glass", "milk", "fog")]), "fog"),     # milk in glass, in fog
    (_doc(camera="milk", shapes=[("null", "milk", None)]), None),       # the camera inside the milk's shape
    (_doc(camera="fog", shapes=[("wall", None, "fog")]), "fog"),        # an opaque shape in fog, empty inside
])
def test_the_worlds_medium(doc, world):
    assert _module().world_medium(doc) == world


@pytest.mark.parametrize("doc, words", [
    (_doc(shapes=[("glass", "milk", "fog")]), ("camera.medium = None", "exterior = 'fog'")),
    (_doc(camera="fog", shapes=[("glass", "milk", "fog"), ("glass", None, "milk")]), ("exteriors",)),
    (_doc(camera="fog", shapes=[("glass", "milk", None)]), ("shapes[0] (s0)", "exterior None")),
    (_doc(camera="fog", shapes=[("glass", "fog", "fog")]), ("shapes[0] (s0).interior = 'fog'",)),
    (_doc(camera="fog", shapes=[("glass", None, "fog")]), ("shapes[0] (s0)", "no interior", "dielectric")),
    (_doc(camera="smoke"), ("camera.medium = 'smoke'",)),
    (_doc(shapes=[("null", "smoke", None)]), ("shapes[0] (s0).interior = 'smoke'",)),
])
def test_what_cycles_volumes_cannot_say_is_refused(doc, words):
    module = _module()
    with pytest.raises(module.SceneError) as err:
        module.world_medium(doc)
    for word in words:
        assert word in str(err.value)


# ---- Cycles -------------------------------------------------------------------------------------------------------

NODES = """
import json, sys, bpy
sys.path.insert(0, {folder!r})
import cycles_render as c
doc = json.load(open({scene!r}))
args = c.parse_args([{scene!r}, "--spp", "2", "--out", "unused.exr"])
c.build_scene(bpy, doc, __import__("pathlib").Path({scene!r}).parent, args)
def volume(tree, output):
    links = output.inputs["Volume"].links
    if not links:
        return None
    node = links[0].from_node
    return {{"node": node.bl_idname, "phase": node.phase,
             "scatter": list(node.inputs["Scatter Coefficients"].default_value),
             "absorption": list(node.inputs["Absorption Coefficients"].default_value),
             "g": node.inputs["Anisotropy"].default_value}}
mat = bpy.data.objects["shape-0"].data.materials[0]
out = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
world = bpy.context.scene.world.node_tree
wout = next(n for n in world.nodes if n.bl_idname == "ShaderNodeOutputWorld")
print(json.dumps({{"surface": bool(out.inputs["Surface"].links), "volume": volume(mat.node_tree, out),
                  "world": volume(world, wout), "sampling": mat.cycles.volume_sampling,
                  "transparent": bpy.context.scene.cycles.transparent_max_bounces,
                  "volume_bounces": bpy.context.scene.cycles.volume_bounces,
                  "biased": bpy.context.scene.cycles.volume_biased}}))
"""


def _nodes(scene_path: Path) -> dict:
    code = NODES.format(folder=str(SCRIPT.parent), scene=str(scene_path))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_the_media_reach_cycles_node_tree(tmp_path, bpy_present):
    """A null cube holding milk in the camera's fog: no surface shader, the milk's coefficients on its Volume
    output, the fog's on the World's, Henyey-Greenstein with Mitsuba's g; unbiased distance sampling, null
    crossings not capped by max_depth."""
    milk = _medium((3.0, 2.0, 1.0), (0.95, 0.8, 0.6), {"type": "hg", "g": -0.3})
    path = _slab(tmp_path, milk, exterior="fog")
    document = json.loads(path.read_text())
    document["media"]["fog"] = _medium((0.2, 0.2, 0.2), (0.8, 0.8, 0.8))
    document["camera"]["medium"] = "fog"
    document["integrator"]["max_depth"] = 6
    path.write_text(json.dumps(document))
    tree = _nodes(path)
    assert tree["surface"] is False
    assert tree["volume"]["node"] == "ShaderNodeVolumeCoefficients"
    assert tree["volume"]["phase"] == "HENYEY_GREENSTEIN"
    assert tree["volume"]["scatter"] == pytest.approx([2.85, 1.6, 0.6])
    assert tree["volume"]["absorption"] == pytest.approx([0.15, 0.4, 0.4])
    assert tree["volume"]["g"] == pytest.approx(-0.3)
    assert tree["world"]["scatter"] == pytest.approx([0.16] * 3)
    assert tree["world"]["absorption"] == pytest.approx([0.04] * 3)
    assert tree["world"]["g"] == 0.0
    assert tree["sampling"] == "DISTANCE"
    assert tree["volume_bounces"] == 4  # max_depth - 2, as every other bounce
    assert tree["transparent"] == 1024
    assert tree["biased"] is False


def test_a_scene_without_media_keeps_its_transparent_bounces(tmp_path, bpy_present):
    """The transparent limit is lifted only where Mitsuba's integrator is volpath (a medium or a null material)."""
    path = _slab(tmp_path, max_depth=6)
    document = json.loads(path.read_text())
    document["materials"]["boundary"] = {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}
    document.pop("media")
    document["shapes"][0]["interior"] = None
    path.write_text(json.dumps(document))
    tree = _nodes(path)
    assert tree["transparent"] == 4 and tree["volume"] is None and tree["world"] is None


@pytest.mark.parametrize("max_depth", [-1, 2])
def test_the_absorbing_slab_is_beer_lambert(tmp_path, bpy_present, max_depth):
    """exp(-sigma_t d) per channel through the slab (d = 1), the sky's 1 around it; at max_depth 2 too (Cycles'
    0 bounces: its two null boundaries are no bounces, as in Mitsuba's volpath)."""
    image = _render(_slab(tmp_path, max_depth=max_depth))
    inside = np.zeros((SIZE, SIZE), bool)
    inside[4:12, 4:12] = True
    expected = np.exp(-np.asarray(SIGMA_T))
    assert np.abs(image[inside] - expected).max() < CLOSE
    assert np.abs(image[~inside] - 1.0).max() < CLOSE
    # the test sees the medium: a slab of the other extinction per channel is far off
    assert np.abs(image[inside] - np.exp(-np.asarray(SIGMA_T[::-1]))).max() > 0.2


@pytest.mark.parametrize("max_depth", [-1, 2])
def test_a_null_shape_without_a_medium_is_invisible(tmp_path, bpy_present, max_depth):
    """A white Transparent BSDF: Cycles counts it as a transparent bounce (measured: black behind it at max_depth 2
    with transparent_max_bounces = max_depth - 2 = 0), so the adapter lifts that limit where Mitsuba uses volpath."""
    image = _render(_slab(tmp_path, max_depth=max_depth, interior=None))
    assert np.abs(image - 1.0).max() < CLOSE


def test_a_medium_outside_the_worlds_is_refused(tmp_path, bpy_present):
    """Milk in a cube whose outside is named fog while the camera is in none: one line, exit 2, no image."""
    path = _slab(tmp_path, exterior="absorber")
    document = json.loads(path.read_text())
    document["media"]["fog"] = _medium()
    document["shapes"][0]["exterior"] = "fog"
    path.write_text(json.dumps(document))
    _refused(path, "camera.medium = None", "exterior = 'fog'")


def test_an_emitting_null_shape_is_refused(tmp_path, bpy_present):
    path = _slab(tmp_path)
    document = json.loads(path.read_text())
    document["shapes"][0]["emission"] = [1.0, 1.0, 1.0]
    path.write_text(json.dumps(document))
    _refused(path, "shapes[0] (slab)", "null")


def test_glass_holds_its_medium_behind_the_glass(tmp_path, bpy_present):
    """A dielectric cube with the medium inside: Glass BSDF on the surface, the medium on the Volume output."""
    path = _slab(tmp_path, _medium((1.0, 1.0, 1.0), (0.5, 0.5, 0.5)))
    document = json.loads(path.read_text())
    document["materials"]["boundary"] = {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0,
                                         "specular_reflectance": [1.0, 1.0, 1.0],
                                         "specular_transmittance": [1.0, 1.0, 1.0]}
    path.write_text(json.dumps(document))
    tree = _nodes(path)
    assert tree["surface"] is True
    assert tree["volume"]["scatter"] == pytest.approx([0.5] * 3)
    assert tree["volume"]["absorption"] == pytest.approx([0.5] * 3)
    assert math.isfinite(tree["volume"]["g"])
