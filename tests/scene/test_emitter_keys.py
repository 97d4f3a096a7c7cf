"""[[emitters]] in the scene format (docs/scene-format.md, "Emitters"): each type loads with Mitsuba's parameters and
defaults, and every bad value is a one-line HarnessError naming the file and the key."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import MINIMAL_SCENE
from test_hostile_input import assert_one_line, cli
from harness.core.errors import HarnessError
from harness.files.imageio import write_exr
from harness.scene import load_scene
from harness.scene import load as scene_load
from harness.scene.load import frame_to_world
from harness.scene.model import ConstantEnvironment, DirectionalLight, EnvironmentMap, PointLight, SpotLight
from harness.scene.triangulate import rotate_matrix
from harness.scene.variants import parse_variant

MAP = np.arange(4 * 3 * 3, dtype=np.float32).reshape(3, 4, 3) / 10 + 0.1  # 4 x 3 pixels, all distinct, > 0


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A scene folder with EXR files good and bad, for envmap entries (each test writes its own scene.toml)."""
    tmp_path = tmp_path_factory.mktemp("emitters") / "scene"
    tmp_path.mkdir()
    maps = tmp_path / "maps"
    maps.mkdir()
    write_exr(maps / "good.exr", MAP)
    for name, (row, column, value) in {"nan": (1, 2, np.nan), "negative": (2, 0, -0.5), "inf": (0, 3, np.inf)}.items():
        bad = MAP.copy()
        bad[row, column, 1] = value
        write_exr(maps / f"{name}.exr", bad)
    write_exr(maps / "narrow.exr", MAP[:, :1])
    write_exr(maps / "short.exr", MAP[:2])
    write_exr(maps / "black.exr", np.zeros_like(MAP))
    (maps / "garbage.exr").write_bytes(b"not an image at all")
    write_exr(tmp_path.parent / "outside.exr", MAP)
    return tmp_path


def write(folder: Path, *emitters: str, extra: str = "") -> Path:
    """MINIMAL_SCENE plus one [[emitters]] entry per body (TOML lines)."""
    text = MINIMAL_SCENE + extra + "".join(f"\n[[emitters]]\n{body}\n" for body in emitters)
    path = folder / "scene.toml"
    path.write_text(text)
    return path


def load(folder: Path, *emitters: str, **kwargs):
    return load_scene(write(folder, *emitters, **kwargs))


# --------------------------------------------------------------------------------------------------------------------
# Good scenes


def test_point(folder):
    (light,) = load(folder, 'type = "point"\nposition = [1, 2, 3]\nintensity = [4, 5, 6]\nname = "bulb"').emitters
    assert isinstance(light, PointLight) and light.type == "point"
    assert (light.index, light.name, light.position, light.intensity) == (0, "bulb", (1.0, 2.0, 3.0), (4.0, 5.0, 6.0))


@pytest.mark.parametrize(("cutoff", "beam"), [(None, None), (40, None), (30, 10), (30, 30)])
def test_spot_angles_and_mitsubas_defaults(folder, cutoff, beam):
    body = 'type = "spot"\nposition = [0, 2, 0]\ntarget = [1, 0, 0]\nintensity = [1, 1, 1]'
    body += f"\ncutoff_angle = {cutoff}" if cutoff is not None else ""
    body += f"\nbeam_width = {beam}" if beam is not None else ""
    (light,) = load(folder, body).emitters
    assert isinstance(light, SpotLight)
    expected_cutoff = 20.0 if cutoff is None else cutoff
    assert light.cutoff_angle == expected_cutoff
    assert light.beam_width == (0.75 * expected_cutoff if beam is None else beam)  # Mitsuba: 3/4 of the cutoff


def test_spot_frame_from_position_and_target(folder):
    (light,) = load(folder, 'type = "spot"\nposition = [0, 2, 0]\ntarget = [1, 0, 0]\nintensity = [1, 1, 1]').emitters
    np.testing.assert_allclose(light.position, [0, 2, 0])
    np.testing.assert_allclose(light.axis, np.array([1, -2, 0]) / math.sqrt(5), atol=1e-15)
    linear = light.to_world[:3, :3]
    np.testing.assert_allclose(linear.T @ linear, np.eye(3), atol=1e-15)
    assert np.linalg.det(linear) == pytest.approx(1.0)
    np.testing.assert_array_equal(light.to_world[3], [0, 0, 0, 1])


@pytest.mark.parametrize("axis", [[0, 0, 1], [0, 0, -1], [1e-9, 0, -1], [0.3, -0.4, 0.5], [1, 0, 0]])
def test_frame_to_world_is_a_rotation_onto_the_axis(axis):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    matrix = frame_to_world([1, 2, 3], axis)
    np.testing.assert_allclose(matrix[:3, 2], axis, atol=1e-15)
    np.testing.assert_allclose(matrix[:3, :3].T @ matrix[:3, :3], np.eye(3), atol=1e-12)
    assert np.linalg.det(matrix[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_array_equal(matrix[:3, 3], [1, 2, 3])


def test_spot_from_to_world(folder):
    matrix = "[[0, 0, 2, 1], [0, 2, 0, 2], [-2, 0, 0, 3], [0, 0, 0, 1]]"  # scale 2, +z onto +x, at (1, 2, 3)
    (light,) = load(folder, f'type = "spot"\nto_world = {matrix}\nintensity = [1, 1, 1]').emitters
    np.testing.assert_allclose(light.position, [1, 2, 3])
    np.testing.assert_allclose(light.axis, [1, 0, 0])


def test_directional_is_normalised(folder):
    (light,) = load(folder, 'type = "directional"\ndirection = [0, -3, 4]\nirradiance = [1, 2, 3]').emitters
    assert isinstance(light, DirectionalLight)
    assert light.direction == pytest.approx((0.0, -0.6, 0.8)) and light.irradiance == (1.0, 2.0, 3.0)


def test_constant(folder):
    (light,) = load(folder, 'type = "constant"\nradiance = [0.5, 1, 2]').emitters
    assert isinstance(light, ConstantEnvironment) and light.radiance == (0.5, 1.0, 2.0)


def test_envmap_reads_its_file_relative_to_the_scene(folder):
    (light,) = load(folder, 'type = "envmap"\nfile = "maps/good.exr"').emitters
    assert isinstance(light, EnvironmentMap)
    assert light.file == (folder / "maps" / "good.exr").resolve() and light.scale == 1.0
    assert light.image.dtype == np.float32 and light.image.shape == (3, 4, 3)
    np.testing.assert_array_equal(light.image, MAP)  # row 0 = the file's top row
    assert not light.image.flags.writeable
    np.testing.assert_array_equal(light.to_world, np.eye(4))


def test_envmap_rotate_and_to_world(folder):
    body = 'type = "envmap"\nfile = "maps/good.exr"\nscale = 2.5\nrotate = [{ axis = [0, 1, 0], angle = 30 }, ' \
           '{ axis = [1, 0, 0], angle = -20 }]'
    (light,) = load(folder, body).emitters
    assert light.scale == 2.5
    np.testing.assert_allclose(light.to_world, rotate_matrix([0, 1, 0], 30) @ rotate_matrix([1, 0, 0], -20))
    (light,) = load(folder, 'type = "envmap"\nfile = "maps/good.exr"\n'
                            'to_world = [[0, 0, 1, 0], [0, 1, 0, 0], [-1, 0, 0, 0], [0, 0, 0, 1]]').emitters
    np.testing.assert_array_equal(light.to_world, rotate_matrix([0, 1, 0], 90).round(15))


def test_envmap_outside_the_folder_when_allowed(folder):
    path = write(folder, 'type = "envmap"\nfile = "../outside.exr"')
    (light,) = load_scene(path, allow_outside_paths=True).emitters
    np.testing.assert_array_equal(light.image, MAP)


def test_every_type_together_in_file_order_beside_shapes(folder):
    shape = '\n[[shapes]]\ntype = "rectangle"\nmaterial = "white"\nemission = [1, 1, 1]\n'
    scene = load(folder, 'type = "directional"\ndirection = [0, -1, 0]\nirradiance = [1, 1, 1]',
                 'type = "point"\nposition = [0, 1, 0]\nintensity = [1, 1, 1]',
                 'type = "envmap"\nfile = "maps/good.exr"',
                 'type = "spot"\nposition = [0, 1, 0]\ntarget = [0, 0, 0]\nintensity = [1, 1, 1]', extra=shape)
    assert [e.type for e in scene.emitters] == ["directional", "point", "envmap", "spot"]
    assert [e.index for e in scene.emitters] == [0, 1, 2, 3]
    assert [e.name for e in scene.emitters] == ["emitter0", "emitter1", "emitter2", "emitter3"]
    assert len(scene.lights) == 1  # emitting shapes stay shapes


def test_no_light_at_all_is_accepted_as_before(folder):
    """A scene without any light loads (black), with or without shapes, as it did before [[emitters]] existed."""
    assert load(folder).emitters == () and load(folder).lights == []
    scene = load(folder, extra='\n[[shapes]]\ntype = "rectangle"\nmaterial = "white"\n')
    assert scene.emitters == () and scene.lights == []


# --------------------------------------------------------------------------------------------------------------------
# Errors: one line each, naming the file and the key

POINT = 'type = "point"\nposition = [0, 1, 0]\nintensity = [1, 1, 1]'
SPOT = 'type = "spot"\nposition = [0, 1, 0]\ntarget = [0, 0, 0]\nintensity = [1, 1, 1]'
ENVMAP = 'type = "envmap"\nfile = "maps/good.exr"'

BAD = [
    # (id, [[emitters]] bodies, key, fragment of the message)
    ("typo", ['type = "point"\nposition = [0, 1, 0]\nintensty = [1, 1, 1]'], "emitters[0].intensty",
     "did you mean 'intensity'?"),
    ("other-type-key", [POINT + "\nradiance = [1, 1, 1]"], "emitters[0].radiance",
     "applies only to emitters of type 'constant', not 'point'"),
    ("shared-key", ['type = "constant"\nradiance = [1, 1, 1]\nto_world = []'], "emitters[0].to_world",
     "of type 'spot' or 'envmap'"),
    ("no-type", ['position = [0, 1, 0]'], "emitters[0].type", "missing required key 'type'"),
    ("bad-type", ['type = "area"'], "emitters[0].type", "expected one of point, spot, directional, constant, envmap"),
    ("type-hint", ['type = "spott"'], "emitters[0].type", "did you mean 'spot'?"),
    ("not-a-table", None, "emitters[0]", "expected a table"),
    ("not-an-array", None, "emitters", "expected an array of tables ([[emitters]])"),
    ("name-type", [POINT + "\nname = 3"], "emitters[0].name", "expected a string"),
    ("duplicate-name", [POINT + '\nname = "a"', SPOT + '\nname = "a"'], "emitters[1].name",
     "duplicate emitter name 'a' (also emitters[0])"),
    ("point-no-position", ['type = "point"\nintensity = [1, 1, 1]'], "emitters[0].position", "missing required key"),
    ("point-no-intensity", ['type = "point"\nposition = [0, 1, 0]'], "emitters[0].intensity",
     "missing required key 'intensity' ([r, g, b] in W/sr)"),
    ("position-nan", ['type = "point"\nposition = [0, nan, 0]\nintensity = [1, 1, 1]'], "emitters[0].position",
     "expected a list of 3 finite numbers"),
    ("intensity-negative", ['type = "point"\nposition = [0, 1, 0]\nintensity = [1, -1, 1]'],
     "emitters[0].intensity", ">= 0, not all 0"),
    ("intensity-zero", ['type = "point"\nposition = [0, 1, 0]\nintensity = [0, 0, 0]'], "emitters[0].intensity",
     "not all 0"),
    ("intensity-inf", ['type = "point"\nposition = [0, 1, 0]\nintensity = [1, inf, 1]'], "emitters[0].intensity",
     "finite"),
    ("intensity-huge", ['type = "point"\nposition = [0, 1, 0]\nintensity = [1e13, 1, 1]'],
     "emitters[0].intensity", "at most 1e12"),
    ("intensity-scalar", ['type = "point"\nposition = [0, 1, 0]\nintensity = 1'], "emitters[0].intensity",
     "got 1"),
    ("spot-target-is-position", ['type = "spot"\nposition = [1, 1, 1]\ntarget = [1, 1, 1]\nintensity = [1, 1, 1]'],
     "emitters[0].target", "expected a point other than position"),
    ("spot-no-target", ['type = "spot"\nposition = [1, 1, 1]\nintensity = [1, 1, 1]'], "emitters[0].target",
     "missing required key 'target'"),
    ("spot-no-position", ['type = "spot"\ntarget = [1, 1, 1]\nintensity = [1, 1, 1]'], "emitters[0].position",
     "or give to_world"),
    ("spot-to-world-and-position", [SPOT + "\nto_world = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"],
     "emitters[0].to_world", "not both (found position, target)"),
    ("spot-to-world-shear", ['type = "spot"\nintensity = [1, 1, 1]\n'
                             'to_world = [[1, 0, 0, 0], [0, 2, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]'],
     "emitters[0].to_world", "a uniform scale"),
    ("spot-to-world-singular", ['type = "spot"\nintensity = [1, 1, 1]\n'
                                'to_world = [[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]]'],
     "emitters[0].to_world", "a zero scale"),
    ("cutoff-zero", [SPOT + "\ncutoff_angle = 0"], "emitters[0].cutoff_angle", "expected an angle in degrees in (0, 90]"),
    ("cutoff-wide", [SPOT + "\ncutoff_angle = 90.5"], "emitters[0].cutoff_angle", "(0, 90]"),
    ("cutoff-string", [SPOT + '\ncutoff_angle = "20"'], "emitters[0].cutoff_angle", "(0, 90]"),
    ("beam-zero", [SPOT + "\nbeam_width = 0"], "emitters[0].beam_width", "in (0, cutoff_angle = 20]"),
    ("beam-wider-than-default-cutoff", [SPOT + "\nbeam_width = 25"], "emitters[0].beam_width",
     "in (0, cutoff_angle = 20], got 25"),
    ("beam-wider-than-cutoff", [SPOT + "\ncutoff_angle = 10\nbeam_width = 10.5"], "emitters[0].beam_width",
     "cutoff_angle = 10]"),
    ("direction-zero", ['type = "directional"\ndirection = [0, 0, 0]\nirradiance = [1, 1, 1]'],
     "emitters[0].direction", "not all 0"),
    ("direction-overflow", ['type = "directional"\ndirection = [1e308, 1e308, 0]\nirradiance = [1, 1, 1]'],
     "emitters[0].direction", "not all 0"),
    ("no-irradiance", ['type = "directional"\ndirection = [0, -1, 0]'], "emitters[0].irradiance",
     "missing required key 'irradiance'"),
    ("radiance-negative", ['type = "constant"\nradiance = [-1, 1, 1]'], "emitters[0].radiance", ">= 0"),
    ("two-environments", ['type = "constant"\nradiance = [1, 1, 1]', ENVMAP], "emitters[1].type",
     "a second environment emitter ('envmap'; emitters[0] is a 'constant')"),
    ("two-constants", ['type = "constant"\nradiance = [1, 1, 1]', POINT, 'type = "constant"\nradiance = [1, 1, 1]'],
     "emitters[2].type", "expected at most one constant or envmap per scene"),
    ("envmap-no-file", ['type = "envmap"'], "emitters[0].file", "missing required key 'file'"),
    ("envmap-png", ['type = "envmap"\nfile = "maps/sky.png"'], "emitters[0].file", "expected an .exr file name"),
    ("envmap-missing", ['type = "envmap"\nfile = "maps/none.exr"'], "emitters[0].file", "no such envmap file"),
    ("envmap-outside", ['type = "envmap"\nfile = "../outside.exr"'], "emitters[0].file",
     "outside the scene's folder"),
    ("envmap-folder", ['type = "envmap"\nfile = "maps/.exr/.."'], "emitters[0].file", "expected an .exr file name"),
    ("envmap-garbage", ['type = "envmap"\nfile = "maps/garbage.exr"'], "emitters[0].file",
     "envmap file 'maps/garbage.exr': not an OpenEXR file"),
    ("envmap-nan", ['type = "envmap"\nfile = "maps/nan.exr"'], "emitters[0].file",
     "1 bad value, the first at row 1, column 2: G = nan; expected finite radiances >= 0"),
    ("envmap-negative", ['type = "envmap"\nfile = "maps/negative.exr"'], "emitters[0].file", "G = -0.5"),
    ("envmap-inf", ['type = "envmap"\nfile = "maps/inf.exr"'], "emitters[0].file", "G = inf"),
    ("envmap-narrow", ['type = "envmap"\nfile = "maps/narrow.exr"'], "emitters[0].file",
     "is 1 x 3 pixels; expected at least 2 x 3"),
    ("envmap-short", ['type = "envmap"\nfile = "maps/short.exr"'], "emitters[0].file", "is 4 x 2 pixels"),
    ("envmap-black", ['type = "envmap"\nfile = "maps/black.exr"'], "emitters[0].file", "is black"),
    ("envmap-scale-zero", [ENVMAP + "\nscale = 0"], "emitters[0].scale", "expected a finite number > 0"),
    ("envmap-scale-list", [ENVMAP + "\nscale = [1, 1, 1]"], "emitters[0].scale", "expected a finite number > 0"),
    ("envmap-scale-huge", [ENVMAP + "\nscale = 1e12"], "emitters[0].scale", "expected radiances of at most 1e12"),
    ("envmap-translated", [ENVMAP + "\nto_world = [[1, 0, 0, 0], [0, 1, 0, 5], [0, 0, 1, 0], [0, 0, 0, 1]]"],
     "emitters[0].to_world", "expected no translation"),
    ("envmap-scaled", [ENVMAP + "\nto_world = [[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]"],
     "emitters[0].to_world", "expected a rotation (orthonormal"),
    ("envmap-mirrored", [ENVMAP + "\nto_world = [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"],
     "emitters[0].to_world", "determinant +1"),
    ("envmap-to-world-and-rotate", [ENVMAP + "\nrotate = { axis = [0, 1, 0], angle = 3 }\n"
                                    "to_world = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]"],
     "emitters[0].to_world", "either to_world or rotate, not both"),
    ("envmap-rotate-axis", [ENVMAP + "\nrotate = { axis = [0, 0, 0], angle = 3 }"], "emitters[0].rotate.axis",
     "not all 0"),
    ("envmap-rotate-key", [ENVMAP + "\nrotate = { axis = [0, 1, 0], angel = 3 }"], "emitters[0].rotate.angel",
     "did you mean 'angle'?"),
]


@pytest.mark.parametrize(("bodies", "key", "fragment"), [case[1:] for case in BAD], ids=[case[0] for case in BAD])
def test_bad_emitters_are_one_line_errors(folder, bodies, key, fragment):
    if bodies is None:  # the two cases that are not [[emitters]] tables
        path = folder / "scene.toml"
        path.write_text(("emitters = [1]\n" if key == "emitters[0]" else "emitters = 3\n") + MINIMAL_SCENE)
    else:
        path = write(folder, *bodies)
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    err = info.value
    assert err.where == f"{path}: {key}", str(err)
    assert fragment in err.message, str(err)
    assert len(str(err).splitlines()) == 1


def test_envmap_size_limit_is_checked_before_reading_pixels(folder, monkeypatch):
    monkeypatch.setattr(scene_load, "MAX_ENVMAP_PIXELS", 11)  # the 4 x 3 map has 12
    path = write(folder, ENVMAP)
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert info.value.where == f"{path}: emitters[0].file"
    assert info.value.message == "envmap file 'maps/good.exr': is 4 x 3 = 12 pixels; expected at most 11"


def test_the_default_size_limit_is_an_8k_map():
    assert scene_load.MAX_ENVMAP_PIXELS == 8192 * 4096


# --------------------------------------------------------------------------------------------------------------------
# Stress variants (harness/scene/variants.py)


def test_scale_and_translate_variants_keep_what_point_and_spot_lights_give(folder):
    """scale=s moves point and spot lights with the scene and multiplies their intensity by s^2, so the irradiance
    I cos / r^2 at a scaled point is unchanged; infinitely far emitters stay as they are."""
    scene = load(folder, POINT, SPOT, 'type = "directional"\ndirection = [0, -1, 0]\nirradiance = [1, 1, 1]', ENVMAP)
    lit = np.array([0.3, 0.0, 0.4])

    def irradiance(point_light, at):
        offset = np.asarray(point_light.position) - at
        return np.asarray(point_light.intensity) * offset[1] / np.linalg.norm(offset) ** 3

    for name, factor in [("scale=1e3", 1e3), ("scale=0.01", 0.01), ("translate=5", 1.0)]:
        variant = parse_variant(name).apply(scene)
        point, spot, directional, envmap = variant.emitters
        shift = 5 / math.sqrt(3) * np.ones(3) if name.startswith("translate") else np.zeros(3)
        np.testing.assert_allclose(irradiance(point, factor * lit + shift), irradiance(scene.emitters[0], lit),
                                   rtol=1e-12)
        np.testing.assert_allclose(spot.position, factor * scene.emitters[1].position + shift, rtol=1e-12)
        np.testing.assert_allclose(spot.axis, scene.emitters[1].axis, atol=1e-15)
        np.testing.assert_allclose(spot.intensity, np.asarray(scene.emitters[1].intensity) * factor**2, rtol=1e-12)
        assert (spot.cutoff_angle, spot.beam_width) == (scene.emitters[1].cutoff_angle, scene.emitters[1].beam_width)
        assert directional == scene.emitters[2] and envmap is scene.emitters[3]


@pytest.mark.parametrize(("body", "fragment"), [
    ('type = "point"\nposition = [0, 1, 0]\nintensty = [1, 1, 1]', "emitters[0].intensty: unknown key"),
    ('type = "envmap"\nfile = "maps/nan.exr"', "emitters[0].file: envmap file 'maps/nan.exr' has 1 bad value"),
    ('type = "envmap"\nfile = "/dev/zero.exr/.."', "emitters[0].file: expected an .exr file name"),
    ('type = "envmap"\nfile = "maps"', "emitters[0].file: expected an .exr file name"),
])
def test_the_command_line_prints_one_line_and_writes_nothing(folder, capfd, body, fragment):
    path = write(folder, body)
    out = folder / "out.exr"
    code, stdout, stderr = cli(capfd, "render", path, "--spp", "1", "--out", out)
    assert_one_line(code, stdout, stderr, f"{path}: {fragment}")
    assert not out.exists()
