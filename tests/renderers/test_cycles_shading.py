"""Shading normals in the Blender Cycles adapter (renderers/cycles_render.py, docs/cycles.md, "Shading normals"):
smooth shading from the PLY's vertex normals against the leaning plate's closed form (its upper sun alone: the
lower one lights the plate through itself in Cycles, the suite's expected fail), normal and bump maps on a plate
under a sun against Mitsuba 3.9.1's formulas computed here (the plate covers the film and every pixel sees one
value: the map's constant normal, or a ramp's constant gradient), with and without the shadowing term; what
Cycles cannot match is refused in one line. Renders are 16 x 16; everything that needs bpy is skipped without it."""

from __future__ import annotations

import dataclasses
import io
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.files.imageio import read_exr
from harness.renderers.groundtruth import shaded_plate_means
from harness.scene import load_scene
from test_cycles import _one_line_error
from test_cycles_textures import write_scene_json

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "renderers" / "cycles_render.py"
SIZE, SPP = 16, 64
#: the mean |Cycles - closed form| over the image, relative to its mean, that a right shading normal stays below
#: (measured: the leaning plate's upper sun 2.7e-4, its pixels' footprints sampled at 64 spp; the sun-lit plate's
#: normal and bump maps 7e-7 and below: a delta light on a constant image leaves only float rounding) ...
CLOSE = 2e-3
#: ... and that a wrong one exceeds (measured: the leaning plate shaded flat 29 %; Mitsuba's values below differ from
#: those of the plain plate, of the green channel's other sign and of the other shadowing choice by 4.4 % and more)
FAR = 0.03
#: toward the sun of the map scenes (irradiance 1), 24.6 degrees above the plate: low enough that the shadowing term
#: matters (4 % to 9 % here)
SUN = np.array([0.8, 0.35, 0.4]) / np.linalg.norm([0.8, 0.35, 0.4])
RHO = np.array([0.7, 0.6, 0.5])

pytestmark = [pytest.mark.cycles, pytest.mark.slow]


@pytest.fixture(scope="module")
def bpy_present():
    pytest.importorskip("bpy")


def _run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True, timeout=300)


def _export(scene, out: Path, edit=None) -> Path:
    """``scene`` at SIZE x SIZE as scene.json in ``out`` (``edit(document)`` applied)."""
    return write_scene_json(scene, out, SIZE, edit)


def _render(scene_path: Path, *extra) -> np.ndarray:
    out = scene_path.parent / "r.exr"
    proc = _run(scene_path, "--spp", SPP, "--seed", 1, "--out", out, *extra)
    assert proc.returncode == 0, proc.stderr
    return read_exr(out).image


def _relative_error(image: np.ndarray, exact: np.ndarray) -> float:
    """The mean |image - exact| relative to the larger of their means (an exact image of 0 is far from a lit one)."""
    return float(np.abs(image - exact).mean() / max(np.abs(exact).mean(), np.abs(image).mean()))


# ---- smooth shading -------------------------------------------------------------------------------------------------

def _upper_sun_plate():
    scene = load_scene(ROOT / "scenes" / "leaning-plate.toml")
    scene = dataclasses.replace(scene, emitters=tuple(e for e in scene.emitters if e.name == "sun-above"))
    return dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=SIZE, height=SIZE))


def test_vertex_normals_match_the_closed_form(tmp_path, bpy_present):
    """The leaning plate under its upper sun: each pixel rho / pi E (n_s . l) over its footprint, n_s the normalised
    blend of the PLY's vertex normals (harness.renderers.groundtruth.shaded_plate_means)."""
    scene = _upper_sun_plate()
    assert _relative_error(_render(_export(scene, tmp_path)), shaded_plate_means(scene)) < CLOSE


def test_the_plate_shaded_flat_is_far_off(tmp_path, bpy_present):
    """The test above sees the normals: the same scene.json shaded flat is far from the closed form."""
    scene = _upper_sun_plate()

    def flat(document):
        document["shapes"][0]["shading"] = "flat"
    assert _relative_error(_render(_export(scene, tmp_path, flat)), shaded_plate_means(scene)) > FAR


def test_vertex_normals_are_stored_as_given(tmp_path, bpy_present):
    """Blender keeps the free custom normals as float (normals_split_custom_set_from_vertices would quantise them)."""
    code = (f"import sys, numpy as np, bpy; sys.path.insert(0, {str(SCRIPT.parent)!r}); import cycles_render as c\n"
            "rng = np.random.default_rng(3); n = rng.normal(size=(4, 3)); n[:, 2] = np.abs(n[:, 2]) + 0.1\n"
            "n /= np.linalg.norm(n, axis=1, keepdims=True)\n"
            "mesh = bpy.data.meshes.new('m'); mesh.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [],"
            " [(0, 1, 2), (0, 2, 3)]); mesh.update(); c.set_vertex_normals(mesh, n, 'm')\n"
            "out = np.empty(12, np.float32); mesh.vertex_normals.foreach_get('vector', out)\n"
            "print(np.abs(out.reshape(4, 3) - n.astype(np.float32)).max())\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert float(proc.stdout.split()[-1]) == 0.0


# ---- normal and bump maps on a sun-lit plate ------------------------------------------------------------------------

def _png(codes: np.ndarray) -> bytes:
    from PIL import Image  # noqa: PLC0415 - only where a map is written

    buffer = io.BytesIO()
    Image.fromarray(np.asarray(codes, np.uint8)).save(buffer, format="PNG")
    return buffer.getvalue()


def _plate_scene(folder: Path, texture: str, material: str, codes: np.ndarray,
                 shape: str = 'type = "rectangle"\nscale = 4.0'):
    """A diffuse 8 x 8 plate (z = 0, u along +x, v along +y: Mitsuba's rectangle) covering the film of a camera 3
    above it, under one sun, with ``material`` (a [materials.mapped] table's body) on the texture ``codes``;
    ``shape``: the plate's type and placement."""
    (folder / "textures").mkdir(parents=True, exist_ok=True)
    (folder / "textures" / "map.png").write_bytes(_png(codes))
    (folder / "plate.toml").write_text(f"""name = "mapped-plate"
description = "a sun-lit mapped plate covering the film"
[camera]
origin = [0.0, 0.0, 3.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 40.0
[film]
width = {SIZE}
height = {SIZE}
filter = "box"
[integrator]
max_depth = 2
[textures.map]
type = "bitmap"
filename = "textures/map.png"
raw = true
{texture}
[materials.base]
reflectance = {RHO.tolist()}
[materials.mapped]
{material}
bsdf = "base"
[[shapes]]
name = "plate"
material = "mapped"
{shape}
[[emitters]]
name = "sun"
type = "directional"
direction = {(-SUN).tolist()}
irradiance = [1.0, 1.0, 1.0]
""", encoding="utf-8")
    return load_scene(folder / "plate.toml")


def _mitsuba_value(normal, shadowing: bool) -> np.ndarray:
    """Mitsuba's normalmap / bumpmap around a diffuse BSDF lit by SUN (irradiance 1), its perturbed normal
    ``normal`` (world): rho / pi max(0, n' . l) G(l), G = 2 / (1 + sqrt(1 + a^2 tan^2 theta(l))), a^2 =
    min(tan^2 theta(n') / 8, 1), both angles from the plate's normal (docs/mitsuba.md, "normalmap")."""
    n = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    value = RHO / math.pi * max(0.0, float(n @ SUN))
    if shadowing:
        a2 = min(0.125 * (1.0 - n[2] ** 2) / n[2] ** 2, 1.0)
        value = value * 2.0 / (1.0 + math.sqrt(1.0 + a2 * (1.0 - SUN[2] ** 2) / SUN[2] ** 2))
    return value


NORMALS = {"toward-x": (200, 128, 220), "toward-y": (128, 60, 210), "toward-both": (90, 170, 200)}


@pytest.mark.parametrize("shadowing", [True, False])
@pytest.mark.parametrize("texel", list(NORMALS))
def test_normal_map_matches_mitsuba(tmp_path, bpy_present, texel, shadowing):
    """A constant normal map: n = 2 rgb - 1 in the frame (s, t, n) = (x, y, z) of the plate (s from dp/du, t = n x s:
    green along +v, Mitsuba's v, which the texture's rows run along from the top)."""
    code = np.array(NORMALS[texel])
    scene = _plate_scene(tmp_path, "", f'type = "normalmap"\nnormalmap = {{ texture = "map" }}\n'
                                       f"use_shadowing_function = {str(shadowing).lower()}",
                         np.broadcast_to(code, (4, 4, 3)))
    normal = 2.0 * code / 255.0 - 1.0
    exact = np.broadcast_to(_mitsuba_value(normal, shadowing), (SIZE, SIZE, 3))
    image = _render(_export(scene, tmp_path))
    assert _relative_error(image, exact) < CLOSE
    # the test can tell: the green channel's sign (where it is not 128), the shadowing term and the plain plate are
    # each far off
    others = [_mitsuba_value(normal, not shadowing), _mitsuba_value((0, 0, 1), shadowing)]
    if abs(normal[1]) > 0.1:
        others.append(_mitsuba_value(normal * (1, -1, 1), shadowing))
    for other in others:
        assert _relative_error(image, np.broadcast_to(other, (SIZE, SIZE, 3))) > FAR


#: a ramp of 8 texels falling in u (codes 252, 216, ..., 0: f = 36 (7 - k) / 255), the same in each of its 2 rows
RAMP = np.repeat(np.repeat((252 - np.arange(8) * 36)[None, :, None], 2, axis=0), 3, axis=2)


@pytest.mark.parametrize("shadowing", [True, False])
def test_bump_map_matches_mitsuba(tmp_path, bpy_present, shadowing):
    """A ramp in u under clamp: the film sees u in [0.36, 0.64], where the bilinear lookup's gradient is W (f[i+1] -
    f[i]) = -8 x 36 / 255 per unit of u; Mitsuba: dp/du' = dp/du + n (scale df/du - n . dp/du), dp/du = (8, 0, 0)
    on the 8 x 8 plate, so n = normalize(-scale df/du / 8, 0, 1), 29.5 degrees toward +x."""
    scale = 4.0
    scene = _plate_scene(tmp_path, 'wrap_mode = "clamp"',
                         f'type = "bumpmap"\ntexture = {{ texture = "map" }}\nscale = {scale}\n'
                         f"use_shadowing_function = {str(shadowing).lower()}", RAMP)
    slope = -8 * 36 / 255
    normal = np.array([-scale * slope / 8.0, 0.0, 1.0])
    exact = np.broadcast_to(_mitsuba_value(normal, shadowing), (SIZE, SIZE, 3))
    image = _render(_export(scene, tmp_path))
    assert _relative_error(image, exact) < CLOSE
    for other in (_mitsuba_value(normal * (-1, 1, 1), shadowing), _mitsuba_value((0, 0, 1), shadowing),
                  _mitsuba_value(normal, not shadowing)):
        assert _relative_error(image, np.broadcast_to(other, (SIZE, SIZE, 3))) > FAR


def test_a_nearest_bump_map_changes_nothing(tmp_path, bpy_present):
    """Mitsuba's gradient of the nearest filter is 0: the plain diffuse plate."""
    scene = _plate_scene(tmp_path, 'wrap_mode = "clamp"\nfilter_type = "nearest"',
                         'type = "bumpmap"\ntexture = { texture = "map" }\nscale = 4.0', RAMP)
    exact = np.broadcast_to(_mitsuba_value((0, 0, 1), True), (SIZE, SIZE, 3))
    assert _relative_error(_render(_export(scene, tmp_path)), exact) < CLOSE


# ---- refusals -------------------------------------------------------------------------------------------------------

def _refused(tmp_path: Path, scene, edit, *words: str) -> None:
    path = _export(scene, tmp_path, edit)
    _one_line_error(_run(path, "--spp", 4, "--out", tmp_path / "x.exr"), *words)
    assert not (tmp_path / "x.exr").exists()


def _mapped_plates():
    return load_scene(ROOT / "scenes" / "mapped-plates.toml")


def test_a_map_around_a_glossy_material_is_refused(tmp_path, bpy_present):
    def edit(document):
        document["materials"]["normal-mapped"]["bsdf"] = {
            "type": "roughconductor", "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.2], "alpha": 0.2,
            "distribution": "ggx", "specular_reflectance": [1.0, 1.0, 1.0], "two_sided": False}
    _refused(tmp_path, _mapped_plates(), edit, "materials.normal-mapped.bsdf.type", "'roughconductor'", "diffuse")


def test_normal_map_texels_below_the_surface_are_refused(tmp_path, bpy_present):
    scene = _plate_scene(tmp_path / "scene", "", 'type = "normalmap"\nnormalmap = { texture = "map" }',
                         np.broadcast_to(np.array([128, 128, 100]), (4, 4, 3)))
    _refused(tmp_path, scene, None, "materials.mapped.normalmap", "'map'", "below the surface")


def test_a_map_without_mesh_coordinates_is_refused(tmp_path, bpy_present):
    def edit(document):
        document["shapes"][0]["uv"] = "analytic"
    _refused(tmp_path, _mapped_plates(), edit, "shapes[0] (normal-plate)", "uv = 'analytic'")


def test_a_map_on_a_sphere_is_refused(tmp_path, bpy_present):
    """The reference and Mitsuba take a map on a sphere (its analytic tangents); this adapter builds a map's frame
    from a mesh's texture coordinates, which a sphere's icosphere does not carry."""
    scene = _plate_scene(tmp_path / "scene", "", 'type = "normalmap"\nnormalmap = { texture = "map" }',
                         np.full((4, 4, 3), 200), shape='type = "sphere"')
    _refused(tmp_path, scene, None, "shapes[0] (plate)", "a normalmap on a sphere")


def test_a_smooth_dielectric_is_refused(tmp_path, bpy_present):
    def edit(document):
        document["materials"]["copper"] = {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0,
                                           "specular_reflectance": [1.0, 1.0, 1.0],
                                           "specular_transmittance": [1.0, 1.0, 1.0]}
    _refused(tmp_path, load_scene(ROOT / "scenes" / "smooth-twins.toml"), edit, "materials.copper.type",
             "'dielectric'", "smooth-shaded")


def test_smooth_shading_without_normals_in_the_mesh_is_refused(tmp_path, bpy_present):
    def edit(document):
        document["shapes"][3]["shading"] = "smooth"  # the floor: a rectangle, its PLY without nx, ny, nz
    _refused(tmp_path, load_scene(ROOT / "scenes" / "smooth-twins.toml"), edit, "shapes[3] (floor)", "nx, ny, nz")
