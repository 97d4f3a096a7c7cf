"""``type = "roughplastic"`` (docs/scene-format.md, "Materials"): Mitsuba 3.9.1's names and defaults, one-line errors
naming the key, textures (diffuse_reflectance, specular_reflectance; alpha refused: Mitsuba's roughplastic takes a
number), the core's row and table, Mitsuba's dict and XML, scene.json and glTF."""

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
from reference_impl.kernels.bsdf import roughplastic_luts

SHAPE = '\n[[shapes]]\ntype = "rectangle"\nmaterial = "m"\n\n[[shapes]]\ntype = "sphere"\nmaterial = "white"\n' \
        'emission = [1, 1, 1]\ncenter = [0, 0, 3]\nradius = 0.1\n'
CHECKS = '\n[textures.checks]\ntype = "checkerboard"\ncolor0 = [0.9, 0.6, 0.3]\ncolor1 = 0.1\n'


def write(folder, body: str, textures: str = ""):
    path = folder / "scene.toml"
    path.write_text(MINIMAL_SCENE + textures + f"\n[materials.m]\n{body}\n" + SHAPE)
    return path


def material(folder, body: str, textures: str = ""):
    return load_scene(write(folder, body, textures)).materials["m"]


def test_defaults_are_mitsubas(tmp_path):
    got = material(tmp_path, 'type = "roughplastic"')
    assert (got.diffuse_reflectance, got.specular_reflectance, got.int_ior, got.ext_ior, got.nonlinear,
            got.two_sided, got.alpha, got.distribution, got.sample_visible) == (
        (0.5,) * 3, (1.0,) * 3, 1.49, 1.000277, False, False, 0.1, "beckmann", True)
    assert got.is_rough and not got.is_dielectric and not got.is_conductor
    got = material(tmp_path, 'type = "roughplastic"\ndiffuse_reflectance = [0.1, 0.9, 0.3]\n'
                             'specular_reflectance = 0.5\nint_ior = 5\next_ior = 1.0\nnonlinear = true\n'
                             'two_sided = true\nalpha = 0.3\ndistribution = "ggx"\nsample_visible = false')
    assert (got.diffuse_reflectance, got.nonlinear, got.two_sided, got.reflectance, got.int_ior, got.alpha,
            got.distribution, got.sample_visible) == (
        (0.1, 0.9, 0.3), True, True, (0.5, 0.9, 0.5), 5.0, 0.3, "ggx", False)


BAD = [
    ("alpha-texture", 'type = "roughplastic"\nalpha = { texture = "checks" }', "alpha",
     "alpha of a roughplastic takes no texture: Mitsuba's roughplastic takes a number"),
    ("alpha-zero", 'type = "roughplastic"\nalpha = 0', "alpha", "expected a finite number in [0.0001, 1]"),
    ("alpha-string", 'type = "roughplastic"\nalpha = "rough"', "alpha", "expected a finite number in [0.0001, 1]"),
    ("distribution", 'type = "roughplastic"\ndistribution = "phong"', "distribution", "beckmann"),
    ("sample-visible", 'type = "roughplastic"\nsample_visible = "yes"', "sample_visible", "expected true or false"),
    ("index-matched", 'type = "roughplastic"\nint_ior = 1.2\next_ior = 1.2', "int_ior",
     "expected int_ior != ext_ior for a roughplastic"),
    ("named-ior", 'type = "roughplastic"\nint_ior = "polypropylene"', "int_ior", "named indices are not supported"),
    ("ior-range", 'type = "roughplastic"\next_ior = 0', "ext_ior", "an index of refraction"),
    ("diffuse-above-1", 'type = "roughplastic"\ndiffuse_reflectance = [0.5, 1.2, 0.5]', "diffuse_reflectance",
     "each in [0, 1], got [0.5, 1.2, 0.5]"),
    ("specular-above-1", 'type = "roughplastic"\nspecular_reflectance = 2', "specular_reflectance", "each in [0, 1]"),
    ("nonlinear-number", 'type = "roughplastic"\nnonlinear = 1', "nonlinear", "expected true or false"),
    ("transmittance", 'type = "roughplastic"\nspecular_transmittance = 1', "specular_transmittance",
     "not 'roughplastic'"),
    ("anisotropic", 'type = "roughplastic"\nalpha_u = 0.1', "alpha_u", "anisotropic roughness"),
    ("eta-key", 'type = "roughplastic"\neta = 1.5', "eta", "not 'roughplastic'"),
    ("ior-texture", 'type = "roughplastic"\nint_ior = { texture = "checks" }', "int_ior",
     "int_ior of a roughplastic takes no texture (textures drive: diffuse_reflectance, specular_reflectance)"),
]


@pytest.mark.parametrize(("body", "key", "fragment"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_tables_are_one_line_errors(tmp_path, body, key, fragment):
    path = write(tmp_path, body, CHECKS)
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert info.value.where == f"{path}: materials.m.{key}", str(info.value)
    assert fragment in info.value.message and len(str(info.value).splitlines()) == 1, str(info.value)


def test_the_core_row_and_table(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "roughplastic"\ndiffuse_reflectance = [0.2, 0.4, 0.6]\n'
                                       'specular_reflectance = 0.8\nnonlinear = true\nalpha = 0.25\n'
                                       'distribution = "ggx"\nsample_visible = false'))
    table = material_arrays(scene)
    m = list(scene.materials).index("m")
    row = table.params[m]
    assert table.kind[m] == core.ROUGHPLASTIC
    assert list(row[core.P_DIFFUSE:core.P_DIFFUSE + 3]) == [0.2, 0.4, 0.6]
    assert list(row[core.P_REFLECTANCE:core.P_REFLECTANCE + 3]) == [0.8] * 3
    assert row[core.P_NONLINEAR] == 1 and row[core.P_IOR] == pytest.approx(1.49 / 1.000277)
    assert (row[core.P_ALPHA], row[core.P_DISTRIBUTION], row[core.P_SAMPLE_VISIBLE]) == (0.25, core.GGX, 0)
    assert row[core.P_SPECULAR_WEIGHT] == pytest.approx(0.8 / (0.8 + 0.4))
    luts = roughplastic_luts(table)
    lut = luts[m]
    assert lut.shape == (core.LUT_SIZE,) and np.all((lut > 0) & (lut < 1))  # transmittances and R_i in (0, 1)
    assert not luts[list(scene.materials).index("white")].any()


def test_textures_drive_the_reflectances(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "roughplastic"\ndiffuse_reflectance = { texture = "checks" }\n'
                                       'specular_reflectance = { texture = "checks" }', CHECKS))
    m = list(scene.materials).index("m")
    table = material_arrays(scene)
    assert table.texture[m, list(core.TEXTURE_SLOTS).index("diffuse")] == 0
    assert table.texture[m, list(core.TEXTURE_SLOTS).index("reflectance")] == 0
    assert table.params[m, core.P_SPECULAR_WEIGHT] == pytest.approx(0.5)  # the same texture's mean twice
    spec = bsdf_dict(scene.materials["m"])
    assert spec["diffuse_reflectance"]["type"] == spec["specular_reflectance"]["type"] == "checkerboard"


def test_mitsuba_dict_and_xml(tmp_path):
    got = material(tmp_path, 'type = "roughplastic"\nnonlinear = true\ntwo_sided = true\ndistribution = "ggx"')
    assert bsdf_dict(got) == {"type": "twosided", "bsdf": {
        "type": "roughplastic", "diffuse_reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]},
        "specular_reflectance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}, "int_ior": 1.49, "ext_ior": 1.000277,
        "nonlinear": True, "alpha": 0.1, "distribution": "ggx", "sample_visible": True}}
    from harness.renderers.mitsuba_xml import CATEGORIES
    assert CATEGORIES["roughplastic"] == "bsdf"


def test_mitsuba_loads_the_dict(tmp_path):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    got = material(tmp_path, 'type = "roughplastic"\nalpha = 0.3\ndistribution = "ggx"\nsample_visible = false')
    text = str(mi.load_dict(bsdf_dict(got)))
    assert "RoughPlastic" in text and "alpha = 0.3" in text and "sample_visible = 0" in text


def test_scene_json_entry(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "roughplastic"\ndiffuse_reflectance = [0.1, 0.2, 0.3]'))
    entry = scene_json(scene)[0]["materials"]["m"]
    assert entry == {"type": "roughplastic", "diffuse_reflectance": [0.1, 0.2, 0.3],
                     "specular_reflectance": [1.0] * 3, "int_ior": 1.49, "ext_ior": 1.000277, "nonlinear": False,
                     "alpha": 0.1, "distribution": "beckmann", "sample_visible": True, "two_sided": False}


def test_gltf_material_and_losses(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "roughplastic"\ndiffuse_reflectance = [0.2, 0.4, 0.6]\n'
                                       'int_ior = 1.5\next_ior = 1.0\nalpha = 0.25'))
    document = json.loads(export_scene(scene, "gltf", tmp_path / "gltf")[0].read_text())
    (node,) = [n for n in document["nodes"] if n.get("extras", {}).get("material") == "m"]
    gltf = document["materials"][document["meshes"][node["mesh"]]["primitives"][0]["material"]]
    assert node["extras"]["bsdf"] == json.loads(json.dumps(bsdf_dict(scene.materials["m"])))
    pbr = gltf["pbrMetallicRoughness"]
    np.testing.assert_allclose(pbr["baseColorFactor"], [0.2, 0.4, 0.6, 1.0], rtol=1e-12)
    assert (pbr["metallicFactor"], pbr["roughnessFactor"]) == (0.0, 0.5)
    assert gltf["extensions"] == {"KHR_materials_ior": {"ior": 1.5}} and not gltf["doubleSided"]
    lines = [line for line in export_losses(scene, "gltf") if "(roughplastic)" in line]
    for start in ("glTF's single-sided materials are culled", "glTF's dielectric base (metallic 0) has no light",
                  "glTF's microfacets are GGX"):
        assert any(line.startswith(start) for line in lines), lines
