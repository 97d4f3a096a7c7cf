"""``type = "thindielectric"`` and ``type = "plastic"`` (docs/scene-format.md, "Materials"): Mitsuba 3.9.1's names
and defaults, one-line errors naming the key, textures, the core's row, Mitsuba's dict and XML, scene.json and
glTF."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import MINIMAL_SCENE
from harness.core.errors import HarnessError
from harness.renderers.export import export_losses, export_scene
from harness.renderers.mitsuba_spec import bsdf_dict
from harness.renderers.scene_json import scene_json
from harness.scene import load_scene, material_arrays
from reference_impl import materials as core

SHAPE = '\n[[shapes]]\ntype = "rectangle"\nmaterial = "m"\n\n[[shapes]]\ntype = "sphere"\nmaterial = "white"\n' \
        'emission = [1, 1, 1]\ncenter = [0, 0, 3]\nradius = 0.1\n'
CHECKS = '\n[textures.checks]\ntype = "checkerboard"\ncolor0 = [0.9, 0.6, 0.3]\ncolor1 = 0.1\n'


def write(folder, body: str, textures: str = ""):
    path = folder / "scene.toml"
    path.write_text(MINIMAL_SCENE + textures + f"\n[materials.m]\n{body}\n" + SHAPE)
    return path


def material(folder, body: str, textures: str = ""):
    return load_scene(write(folder, body, textures)).materials["m"]


def test_thindielectric_defaults_are_mitsubas(tmp_path):
    got = material(tmp_path, 'type = "thindielectric"')
    assert (got.int_ior, got.ext_ior, got.specular_reflectance, got.specular_transmittance, got.two_sided) == (
        1.5046, 1.000277, (1.0,) * 3, (1.0,) * 3, False)
    assert got.is_dielectric
    got = material(tmp_path, 'type = "thindielectric"\nint_ior = 1.33\next_ior = 1.0\n'
                             'specular_reflectance = 0.5\nspecular_transmittance = [0.2, 0.9, 0.4]')
    assert (got.int_ior, got.ext_ior, got.reflectance) == (1.33, 1.0, (0.5, 0.9, 0.5))


def test_plastic_defaults_are_mitsubas(tmp_path):
    got = material(tmp_path, 'type = "plastic"')
    assert (got.diffuse_reflectance, got.specular_reflectance, got.int_ior, got.ext_ior, got.nonlinear,
            got.two_sided) == ((0.5,) * 3, (1.0,) * 3, 1.49, 1.000277, False, False)
    got = material(tmp_path, 'type = "plastic"\ndiffuse_reflectance = [0.1, 0.9, 0.3]\nspecular_reflectance = 0.5\n'
                             'int_ior = 1.6\next_ior = 1.0\nnonlinear = true\ntwo_sided = true')
    assert (got.diffuse_reflectance, got.nonlinear, got.two_sided, got.reflectance) == (
        (0.1, 0.9, 0.3), True, True, (0.5, 0.9, 0.5))


BAD = [
    ("thin-two-sided", 'type = "thindielectric"\ntwo_sided = true', "two_sided",
     "a thindielectric has no two_sided: a thin sheet is two-sided by nature"),
    ("thin-diffuse", 'type = "thindielectric"\ndiffuse_reflectance = 0.5', "diffuse_reflectance",
     "applies only to materials of type 'plastic' or 'roughplastic', not 'thindielectric'"),
    ("thin-named-ior", 'type = "thindielectric"\nint_ior = "bk7"', "int_ior", "named indices are not supported"),
    ("thin-transmittance", 'type = "thindielectric"\nspecular_transmittance = 1.5', "specular_transmittance",
     "each in [0, 1]"),
    ("plastic-diffuse-above-1", 'type = "plastic"\ndiffuse_reflectance = [0.5, 1.2, 0.5]', "diffuse_reflectance",
     "each in [0, 1], got [0.5, 1.2, 0.5]"),
    ("plastic-nonlinear-number", 'type = "plastic"\nnonlinear = 1', "nonlinear", "expected true or false"),
    ("plastic-dense", 'type = "plastic"\nint_ior = 5\next_ior = 1', "int_ior", "expected int_ior / ext_ior below 3.8"),
    ("plastic-transmittance", 'type = "plastic"\nspecular_transmittance = 1', "specular_transmittance",
     "not 'plastic'"),
    ("plastic-alpha", 'type = "plastic"\nalpha = 0.1', "alpha", "not 'plastic'"),
    ("nonlinear-on-dielectric", 'type = "dielectric"\nnonlinear = true', "nonlinear",
     "applies only to materials of type 'plastic' or 'roughplastic', not 'dielectric'"),
    ("plastic-ior-texture", 'type = "plastic"\nint_ior = { texture = "checks" }', "int_ior",
     "int_ior of a plastic takes no texture (textures drive: diffuse_reflectance, specular_reflectance)"),
]


@pytest.mark.parametrize(("body", "key", "fragment"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_tables_are_one_line_errors(tmp_path, body, key, fragment):
    path = write(tmp_path, body, CHECKS)
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert info.value.where == f"{path}: materials.m.{key}", str(info.value)
    assert fragment in info.value.message and len(str(info.value).splitlines()) == 1, str(info.value)


def test_the_core_rows(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "plastic"\ndiffuse_reflectance = [0.2, 0.4, 0.6]\n'
                                       'specular_reflectance = 0.8\nnonlinear = true'))
    table = material_arrays(scene)
    row = table.params[list(scene.materials).index("m")]
    assert table.kind[list(scene.materials).index("m")] == core.PLASTIC
    assert list(row[core.P_DIFFUSE:core.P_DIFFUSE + 3]) == [0.2, 0.4, 0.6]
    assert list(row[core.P_REFLECTANCE:core.P_REFLECTANCE + 3]) == [0.8] * 3
    assert row[core.P_NONLINEAR] == 1 and row[core.P_IOR] == pytest.approx(1.49 / 1.000277)
    assert row[core.P_SPECULAR_WEIGHT] == pytest.approx(0.8 / (0.8 + 0.4))
    scene = load_scene(write(tmp_path, 'type = "thindielectric"\nspecular_transmittance = 0.7'))
    table = material_arrays(scene)
    row = table.params[list(scene.materials).index("m")]
    assert table.kind[list(scene.materials).index("m")] == core.THINDIELECTRIC
    assert list(row[core.P_TRANSMITTANCE:core.P_TRANSMITTANCE + 3]) == [0.7] * 3


def test_textures_drive_the_plastic_and_the_thin_sheet(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "plastic"\ndiffuse_reflectance = { texture = "checks" }', CHECKS))
    m = list(scene.materials).index("m")
    table = material_arrays(scene)
    assert table.texture[m, list(core.TEXTURE_SLOTS).index("diffuse")] == 0
    # the sampling weight from the texture's mean (Mitsuba's Texture::mean): (0.6 + 0.1) / 2 over the channels
    d_mean = np.mean([(0.9 + 0.1) / 2, (0.6 + 0.1) / 2, (0.3 + 0.1) / 2])
    assert table.params[m, core.P_SPECULAR_WEIGHT] == pytest.approx(1 / (1 + d_mean))
    assert bsdf_dict(scene.materials["m"])["diffuse_reflectance"]["type"] == "checkerboard"
    scene = load_scene(write(tmp_path, 'type = "thindielectric"\nspecular_transmittance = { texture = "checks" }',
                             CHECKS))
    table = material_arrays(scene)
    assert table.texture[list(scene.materials).index("m"), list(core.TEXTURE_SLOTS).index("transmittance")] == 0


def test_mitsuba_dicts(tmp_path):
    thin = material(tmp_path, 'type = "thindielectric"\nint_ior = 1.33')
    assert bsdf_dict(thin) == {"type": "thindielectric", "int_ior": 1.33, "ext_ior": 1.000277,
                               "specular_reflectance": {"type": "rgb", "value": [1.0, 1.0, 1.0]},
                               "specular_transmittance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    plastic = material(tmp_path, 'type = "plastic"\nnonlinear = true\ntwo_sided = true')
    assert bsdf_dict(plastic) == {"type": "twosided", "bsdf": {
        "type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]},
        "specular_reflectance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}, "int_ior": 1.49, "ext_ior": 1.000277,
        "nonlinear": True}}


def test_scene_json_entries(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "plastic"\ndiffuse_reflectance = [0.1, 0.2, 0.3]'))
    entry = scene_json(scene)[0]["materials"]["m"]
    assert entry == {"type": "plastic", "diffuse_reflectance": [0.1, 0.2, 0.3], "specular_reflectance": [1.0] * 3,
                     "int_ior": 1.49, "ext_ior": 1.000277, "nonlinear": False, "two_sided": False}
    scene = load_scene(write(tmp_path, 'type = "thindielectric"'))
    entry = scene_json(scene)[0]["materials"]["m"]
    assert entry == {"type": "thindielectric", "int_ior": 1.5046, "ext_ior": 1.000277,
                     "specular_reflectance": [1.0] * 3, "specular_transmittance": [1.0] * 3}


@pytest.mark.parametrize("body, factors, extensions, double_sided, lost", [
    ('type = "thindielectric"\nspecular_transmittance = [0.9, 0.8, 0.7]', ([0.9, 0.8, 0.7], 0.0, 0.0),
     {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.5046 / 1.000277}},
     True, ["glTF's thin-walled transmission (KHR_materials_volume absent) reflects as one interface"]),
    ('type = "plastic"\ndiffuse_reflectance = [0.2, 0.4, 0.6]\nspecular_reflectance = [1, 0.5, 0.5]\n'
     'int_ior = 1.5\next_ior = 1.0', ([0.2, 0.4, 0.6], 0.0, 0.0),
     {"KHR_materials_ior": {"ior": 1.5}, "KHR_materials_specular": {"specularColorFactor": [1.0, 0.5, 0.5]}}, False,
     ["glTF's single-sided materials are culled from behind", "glTF's dielectric base (metallic 0) has no light"]),
])
def test_gltf_materials_and_losses(tmp_path, body, factors, extensions, double_sided, lost):
    scene = load_scene(write(tmp_path, body))
    document = json.loads(export_scene(scene, "gltf", tmp_path / "gltf")[0].read_text())
    (node,) = [n for n in document["nodes"] if n.get("extras", {}).get("material") == "m"]
    gltf = document["materials"][document["meshes"][node["mesh"]]["primitives"][0]["material"]]
    assert node["extras"]["bsdf"] == json.loads(json.dumps(bsdf_dict(scene.materials["m"])))
    pbr = gltf["pbrMetallicRoughness"]
    colour, metallic, roughness = factors
    np.testing.assert_allclose(pbr["baseColorFactor"], [*colour, 1.0], rtol=1e-12)
    assert (pbr["metallicFactor"], pbr["roughnessFactor"]) == (metallic, roughness)
    assert gltf["extensions"] == extensions and set(extensions) <= set(document["extensionsUsed"])
    assert gltf["doubleSided"] == double_sided
    lines = [line for line in export_losses(scene, "gltf") if "(thindielectric)" in line or "(plastic)" in line]
    assert len(lines) == len(lost) and all(any(line.startswith(p) for line in lines) for p in lost), lines
