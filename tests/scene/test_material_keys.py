"""[materials.NAME] types of issue 15 (docs/scene-format.md, "Materials"): each of Mitsuba's BSDF plugins loads with
Mitsuba 3.9.1's parameter names and defaults, and every bad key, value or type is a one-line HarnessError naming the
file and the key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import reference_impl
from conftest import MINIMAL_SCENE
from reference_impl import materials as core
from test_hostile_input import assert_one_line, cli
from harness.core.errors import HarnessError
from harness.renderers import RenderRequest, get_renderer
from harness.scene import load_scene, material_arrays, triangulate
from harness.scene.load import CU_ETA, CU_K
from harness.scene.model import Material

SHAPE = '\n[[shapes]]\ntype = "rectangle"\nmaterial = "m"\n\n[[shapes]]\ntype = "sphere"\nmaterial = "white"\n' \
        'emission = [1, 1, 1]\ncenter = [0, 0, 3]\nradius = 0.1\n'


def write(folder: Path, body: str) -> Path:
    """MINIMAL_SCENE plus [materials.m] with ``body`` (TOML lines) and a rectangle using it."""
    path = folder / "scene.toml"
    path.write_text(MINIMAL_SCENE + f"\n[materials.m]\n{body}\n" + SHAPE)
    return path


def material(folder: Path, body: str) -> Material:
    return load_scene(write(folder, body)).materials["m"]


# --------------------------------------------------------------------------------------------------------------------
# Good tables: Mitsuba's defaults


def test_diffuse_is_the_default_type_and_unchanged(tmp_path):
    got = material(tmp_path, "reflectance = [0.5, 0.25, 0]\ntwo_sided = true")
    assert got == Material("m", (0.5, 0.25, 0.0), True) and got.type == "diffuse" and got.is_diffuse
    assert material(tmp_path, 'type = "diffuse"\nreflectance = [0.5, 0.25, 0]') == Material("m", (0.5, 0.25, 0.0))


def test_conductor_defaults_are_mitsubas_perfect_mirror(tmp_path):
    """Mitsuba 3.9.1's conductor without eta, k or material is material "none": eta 0, k 1 (Fresnel 1)."""
    got = material(tmp_path, 'type = "conductor"')
    assert (got.type, got.eta, got.k, got.specular_reflectance, got.two_sided) == (
        "conductor", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (1.0, 1.0, 1.0), False)
    assert got.mirror and got.is_conductor and not got.is_rough
    assert material(tmp_path, 'type = "conductor"\nmaterial = "none"') == got
    assert got.reflectance == (1.0, 1.0, 1.0)


def test_conductor_with_eta_and_k(tmp_path):
    got = material(tmp_path, f'type = "conductor"\neta = {list(CU_ETA)}\nk = {list(CU_K)}\n'
                             'specular_reflectance = 0.5\ntwo_sided = true')
    assert (got.eta, got.k, got.specular_reflectance, got.two_sided) == (CU_ETA, CU_K, (0.5,) * 3, True)
    assert not got.mirror and got.reflectance == (0.5, 0.5, 0.5)
    # Mitsuba's defaults one at a time: eta 0, k 1; k = 0 (a real index) is allowed
    assert material(tmp_path, 'type = "conductor"\neta = 1.5\nk = 0').k == (0.0, 0.0, 0.0)
    assert material(tmp_path, 'type = "conductor"\neta = 1.5').k == (1.0, 1.0, 1.0)
    assert material(tmp_path, 'type = "conductor"\nk = [2, 3, 4]').eta == (0.0, 0.0, 0.0)


def test_roughconductor_defaults(tmp_path):
    got = material(tmp_path, 'type = "roughconductor"')
    assert (got.alpha, got.distribution, got.sample_visible, got.mirror) == (0.1, "beckmann", True, True)
    got = material(tmp_path, 'type = "roughconductor"\nalpha = 1e-4\ndistribution = "ggx"\nsample_visible = false')
    assert (got.alpha, got.distribution, got.sample_visible, got.is_rough) == (1e-4, "ggx", False, True)
    assert material(tmp_path, 'type = "roughconductor"\nalpha = 1').alpha == 1.0


def test_dielectric_defaults_are_mitsubas_bk7_in_air(tmp_path):
    got = material(tmp_path, 'type = "dielectric"')
    assert (got.int_ior, got.ext_ior, got.specular_reflectance, got.specular_transmittance) == (
        1.5046, 1.000277, (1.0,) * 3, (1.0,) * 3)
    assert got.is_dielectric and not got.two_sided and not got.mirror
    got = material(tmp_path, 'type = "dielectric"\nint_ior = 1.33\next_ior = 1.33\n'
                             'specular_reflectance = [0.2, 0.3, 0.4]\nspecular_transmittance = [0.5, 0.1, 0]')
    assert (got.int_ior, got.ext_ior) == (1.33, 1.33)  # index-matched: invisible, allowed
    assert got.reflectance == (0.5, 0.3, 0.4)  # the larger of the two per channel


def test_roughdielectric(tmp_path):
    got = material(tmp_path, 'type = "roughdielectric"\nalpha = 0.3\ndistribution = "ggx"\nint_ior = 1.0\n'
                             'ext_ior = 1.5')
    assert (got.alpha, got.distribution, got.sample_visible, got.int_ior, got.ext_ior) == (
        0.3, "ggx", True, 1.0, 1.5)


# --------------------------------------------------------------------------------------------------------------------
# Errors: one line each, naming the file and the key

BAD = [
    # (id, [materials.m] body, key, fragment of the message)
    ("unknown-type", 'type = "velvet"', "type", "expected one of diffuse, conductor, roughconductor, dielectric"),
    ("type-hint", 'type = "condutor"', "type", "did you mean 'conductor'?"),
    ("type-number", "type = 3", "type", "got 3"),
    ("typo", 'type = "roughconductor"\nalhpa = 0.2', "alhpa", "did you mean 'alpha'?"),
    ("diffuse-no-reflectance", 'type = "diffuse"', "reflectance", "missing required key 'reflectance'"),
    ("reflectance-on-conductor", 'type = "conductor"\nreflectance = [1, 1, 1]', "reflectance",
     "applies only to materials of type 'diffuse', not 'conductor'"),
    ("alpha-u", 'type = "roughconductor"\nalpha_u = 0.1\nalpha_v = 0.3', "alpha_u",
     "anisotropic roughness (Mitsuba's alpha_u and alpha_v) is not in the reference's microfacet models"),
    ("alpha-v-on-diffuse", 'reflectance = 0.5\nalpha_v = 0.3', "alpha_v", "expected alpha (isotropic)"),
    ("alpha-on-smooth", 'type = "conductor"\nalpha = 0.1', "alpha",
     "applies only to materials of type 'roughconductor' or 'roughdielectric' or 'roughplastic', not 'conductor'"),
    ("eta-on-diffuse", 'reflectance = [1, 1, 1]\neta = 1', "eta",
     "'conductor' or 'roughconductor' or 'principled', not 'diffuse'"),
    ("int-ior-on-conductor", 'type = "conductor"\nint_ior = 1.5', "int_ior", "not 'conductor'"),
    ("transmittance-on-conductor", 'type = "conductor"\nspecular_transmittance = 1', "specular_transmittance",
     "not 'conductor'"),
    ("two-sided-dielectric", 'type = "dielectric"\ntwo_sided = true', "two_sided", "a dielectric has no two_sided"),
    ("two-sided-roughdielectric", 'type = "roughdielectric"\ntwo_sided = false', "two_sided",
     "a roughdielectric has no two_sided"),
    ("two-sided-string", 'type = "conductor"\ntwo_sided = "yes"', "two_sided", "expected true or false"),
    ("named-conductor", 'type = "conductor"\nmaterial = "Cu"', "material",
     "named conductors are not supported; give eta and k (Mitsuba 3.9.1's RGB Cu: eta = [0.201005"),
    ("material-number", 'type = "roughconductor"\nmaterial = 1', "material", 'expected "none"'),
    ("material-and-eta", 'type = "conductor"\nmaterial = "none"\nk = 1', "material",
     'expected either material = "none" or eta / k, not both (found k)'),
    ("eta-negative", 'type = "conductor"\neta = [1, -1, 1]', "eta", "each in [0, 100], got [1, -1, 1]"),
    ("eta-nan", 'type = "conductor"\neta = nan', "eta", "each in [0, 100], got nan"),
    ("eta-two", 'type = "conductor"\neta = [1, 1]', "eta", "a list of 3 numbers"),
    ("eta-string", 'type = "conductor"\neta = "Cu"', "eta", "got \"Cu\""),
    ("k-huge", 'type = "conductor"\nk = 1e3', "k", "each in [0, 100]"),
    ("k-bool", 'type = "conductor"\nk = true', "k", "got true"),
    ("index-zero", 'type = "conductor"\neta = [1, 0, 1]\nk = [1, 0, 1]', "eta",
     "eta and k are both 0 in channel G"),
    ("index-zero-k", 'type = "roughconductor"\nk = [0, 0, 0]', "k", "eta and k are both 0 in channel R"),
    ("spec-above-1", 'type = "conductor"\nspecular_reflectance = [1, 1.5, 1]', "specular_reflectance",
     "each in [0, 1], got [1, 1.5, 1]"),
    ("spec-negative", 'type = "dielectric"\nspecular_transmittance = -0.1', "specular_transmittance",
     "each in [0, 1]"),
    ("spec-table", 'type = "dielectric"\nspecular_reflectance = { r = 1 }', "specular_reflectance", "got {r = 1}"),
    ("alpha-zero", 'type = "roughconductor"\nalpha = 0', "alpha", "in [0.0001, 1] (the microfacets' roughness)"),
    ("alpha-negative", 'type = "roughdielectric"\nalpha = -0.1', "alpha", "in [0.0001, 1]"),
    ("alpha-tiny", 'type = "roughconductor"\nalpha = 1e-5', "alpha", "got 1e-05"),
    ("alpha-big", 'type = "roughconductor"\nalpha = 2', "alpha", "got 2"),
    ("alpha-inf", 'type = "roughconductor"\nalpha = inf', "alpha", "got inf"),
    ("alpha-list", 'type = "roughconductor"\nalpha = [0.1, 0.2]', "alpha", "got [0.1, 0.2]"),
    ("distribution", 'type = "roughconductor"\ndistribution = "phong"', "distribution",
     "expected one of beckmann, ggx, got \"phong\""),
    ("distribution-case", 'type = "roughdielectric"\ndistribution = "GGX"', "distribution", "beckmann, ggx"),
    ("sample-visible", 'type = "roughconductor"\nsample_visible = 1', "sample_visible", "expected true or false"),
    ("ior-zero", 'type = "dielectric"\nint_ior = 0', "int_ior", "in [0.01, 100] (an index of refraction), got 0"),
    ("ior-negative", 'type = "roughdielectric"\next_ior = -1.5', "ext_ior", "got -1.5"),
    ("ior-huge", 'type = "dielectric"\nint_ior = 1e6', "int_ior", "[0.01, 100]"),
    ("ior-nan", 'type = "dielectric"\next_ior = nan', "ext_ior", "got nan"),
    ("ior-named", 'type = "dielectric"\nint_ior = "bk7"', "int_ior", "named indices are not supported"),
    ("rough-index-matched", 'type = "roughdielectric"\nint_ior = 1.33\next_ior = 1.33', "int_ior",
     "expected int_ior != ext_ior for a roughdielectric"),
    ("rough-index-matched-default", 'type = "roughdielectric"\next_ior = 1.5046', "ext_ior", "got both 1.5046"),
    ("ior-list", 'type = "dielectric"\nint_ior = [1.5, 1.5, 1.5]', "int_ior", "an index of refraction"),
]


@pytest.mark.parametrize(("body", "key", "fragment"), [case[1:] for case in BAD], ids=[case[0] for case in BAD])
def test_bad_materials_are_one_line_errors(tmp_path, body, key, fragment):
    path = write(tmp_path, body)
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    err = info.value
    assert err.where == f"{path}: materials.m.{key}", str(err)
    assert fragment in err.message, str(err)
    assert len(str(err).splitlines()) == 1


@pytest.mark.parametrize(("body", "fragment"), [
    ('type = "dielectric"\ntwo_sided = true', "materials.m.two_sided: a dielectric has no two_sided"),
    ('type = "conductor"\nmaterial = "Au"', "materials.m.material: expected \"none\""),
    ('type = "roughconductor"\nalpha = 0', "materials.m.alpha: expected a finite number in [0.0001, 1]"),
])
def test_the_command_line_prints_one_line_and_writes_nothing(tmp_path, capfd, body, fragment):
    path = write(tmp_path, body)
    out = tmp_path / "out.exr"
    code, stdout, stderr = cli(capfd, "render", path, "--spp", "1", "--out", out)
    assert_one_line(code, stdout, stderr, f"{path}: {fragment}")
    assert not out.exists()


# --------------------------------------------------------------------------------------------------------------------
# The core's material table (harness.scene.material_arrays)

TABLE = MINIMAL_SCENE + """
[materials.copper]
type = "roughconductor"
eta = [0.2, 0.9, 1.1]
k = [3.9, 2.4, 2.1]
alpha = 0.3
distribution = "ggx"
specular_reflectance = 0.5
two_sided = true

[materials.mirror]
type = "conductor"

[materials.glass]
type = "roughdielectric"
int_ior = 1.5
ext_ior = 1.25
alpha = 0.05
sample_visible = false
specular_transmittance = [0.25, 0.5, 1]

[[shapes]]
type = "sphere"
material = "glass"

[[shapes]]
type = "rectangle"
material = "white"
emission = [1, 1, 1]
translate = [0, 0, -2]
"""


def test_the_material_table_holds_every_parameter_in_file_order(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(TABLE)
    scene = load_scene(path)
    table = material_arrays(scene)
    assert list(table.kind) == [core.DIFFUSE, core.ROUGHCONDUCTOR, core.CONDUCTOR, core.ROUGHDIELECTRIC]
    white, copper, mirror, glass = table.params
    assert list(white[core.P_REFLECTANCE:core.P_REFLECTANCE + 3]) == [0.8, 0.8, 0.8] and white[core.P_TWO_SIDED] == 0
    assert list(copper[core.P_REFLECTANCE:core.P_REFLECTANCE + 3]) == [0.5, 0.5, 0.5]
    assert list(copper[core.P_ETA:core.P_ETA + 3]) == [0.2, 0.9, 1.1]
    assert list(copper[core.P_K:core.P_K + 3]) == [3.9, 2.4, 2.1]
    assert (copper[core.P_ALPHA], copper[core.P_DISTRIBUTION], copper[core.P_SAMPLE_VISIBLE],
            copper[core.P_TWO_SIDED], copper[core.P_MIRROR]) == (0.3, core.GGX, 1, 1, 0)
    assert list(mirror[core.P_ETA:core.P_K + 3]) == [0, 0, 0, 1, 1, 1] and mirror[core.P_MIRROR] == 1
    assert list(glass[core.P_TRANSMITTANCE:core.P_TRANSMITTANCE + 3]) == [0.25, 0.5, 1.0]
    assert (glass[core.P_IOR], glass[core.P_ALPHA], glass[core.P_DISTRIBUTION], glass[core.P_SAMPLE_VISIBLE],
            glass[core.P_TWO_SIDED], glass[core.P_MIRROR]) == (1.2, 0.05, core.BECKMANN, 0, 0, 0)
    # Geometry indexes the same order
    geometry = triangulate(scene)
    assert set(geometry.material) == {3, 0} and geometry.reflectance.shape == (4, 3)
    assert np.all((geometry.reflectance >= 0) & (geometry.reflectance <= 1))


def test_lambertian_scenes_hand_the_core_no_table(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(MINIMAL_SCENE + SHAPE.replace('material = "m"', 'material = "white"'))
    assert material_arrays(load_scene(path)) is None


@pytest.mark.parametrize(("text", "passed"), [(TABLE, True), (MINIMAL_SCENE + SHAPE.replace('"m"', '"white"'), False)])
def test_the_reference_renderer_passes_the_table_only_for_glossy_scenes(tmp_path, monkeypatch, text, passed):
    """Lambertian scenes call the core without a materials argument (the geometry's albedos are their table)."""
    calls = []

    def fake_render(geometry, camera, film, settings, progress=None, emitters=None, **kwargs):
        calls.append(kwargs)
        raise reference_impl.SettingsError("x", "stop here")

    monkeypatch.setattr(reference_impl, "render", fake_render)
    path = tmp_path / "scene.toml"
    path.write_text(text)
    with pytest.raises(HarnessError, match="stop here"):
        get_renderer("reference").render(load_scene(path), RenderRequest(spp=1, seed=0))
    (kwargs,) = calls
    assert ("materials" in kwargs) == passed
    if passed:
        assert list(kwargs["materials"].kind) == [core.DIFFUSE, core.ROUGHCONDUCTOR, core.CONDUCTOR,
                                                  core.ROUGHDIELECTRIC]
