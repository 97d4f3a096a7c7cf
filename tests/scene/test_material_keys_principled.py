"""``type = "principled"`` (docs/scene-format.md, "Materials"): Mitsuba 3.9.1's names and defaults, eta or
specular (one of them), one-line errors naming the key, textures on every parameter Mitsuba lets a texture drive,
the core's row, Mitsuba's dict and XML (loaded by Mitsuba itself), scene.json and glTF."""

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

SHAPE = '\n[[shapes]]\ntype = "sphere"\nmaterial = "m"\n\n[[shapes]]\ntype = "sphere"\nmaterial = "white"\n' \
        'emission = [1, 1, 1]\ncenter = [0, 0, 3]\nradius = 0.1\n'
TEXTURES = ('\n[textures.checks]\ntype = "checkerboard"\ncolor0 = [0.9, 0.6, 0.3]\ncolor1 = 0.1\n'
            '\n[textures.grey]\ntype = "bitmap"\nfilename = "grey.exr"\n')


def write(folder, body: str, textures: str = ""):
    path = folder / "scene.toml"
    path.write_text(MINIMAL_SCENE + textures + f"\n[materials.m]\n{body}\n" + SHAPE)
    return path


def material(folder, body: str, textures: str = ""):
    return load_scene(write(folder, body, textures)).materials["m"]


def _grey_exr(folder, low=0.2, high=0.6):
    """A 2 x 2 float bitmap (grey.exr) whose luminances run from ``low`` to ``high``."""
    from harness.files.imageio import write_exr
    image = np.full((2, 2, 3), low, dtype=np.float32)
    image[0, 0] = high
    write_exr(folder / "grey.exr", image)


def test_defaults_are_mitsubas(tmp_path):
    got = material(tmp_path, 'type = "principled"').principled
    assert got.base_color == (0.5, 0.5, 0.5) and got.roughness == 0.5 and got.eta == pytest.approx(1.5)
    assert (got.metallic, got.spec_tint, got.anisotropic, got.sheen, got.sheen_tint, got.clearcoat,
            got.clearcoat_gloss, got.spec_trans, got.flatness) == (0.0,) * 9
    assert (got.main_specular_sampling_rate, got.clearcoat_sampling_rate,
            got.diffuse_reflectance_sampling_rate) == (1.0, 1.0, 1.0)
    got = material(tmp_path, 'type = "principled"\nspecular = 0.8').principled
    assert got.eta == pytest.approx(2 / (1 - np.sqrt(0.08 * 0.8)) - 1)
    assert material(tmp_path, 'type = "principled"\neta = 1.0').principled.eta == 1.0
    assert material(tmp_path, 'type = "principled"\neta = 1.0\nspec_trans = 0.3').principled.eta == 1.001
    assert material(tmp_path, 'type = "principled"\nspecular = 0\nspec_trans = 0.3').principled.eta == \
        pytest.approx(core.principled_eta(1e-3))
    assert material(tmp_path, 'type = "principled"\nspecular = 0').principled.eta == 1.0


BAD = [
    ("eta-and-specular", 'type = "principled"\neta = 1.5\nspecular = 0.5', "specular",
     "expected either eta or specular, not both"),
    ("metallic-above-1", 'type = "principled"\nmetallic = 1.2', "metallic", "in [0, 1], got 1.2"),
    ("roughness-negative", 'type = "principled"\nroughness = -0.1', "roughness", "in [0, 1]"),
    ("specular-above-1", 'type = "principled"\nspecular = 2', "specular", "in [0, 1]"),
    ("eta-zero", 'type = "principled"\neta = 0', "eta", "an index of refraction"),
    ("eta-named", 'type = "principled"\neta = "bk7"', "eta", "named indices are not supported"),
    ("base-colour-above-1", 'type = "principled"\nbase_color = [0.5, 1.5, 0.5]', "base_color", "each in [0, 1]"),
    ("rate-zero", 'type = "principled"\nclearcoat_sampling_rate = 0', "clearcoat_sampling_rate", "> 0"),
    ("two-sided", 'type = "principled"\ntwo_sided = true', "two_sided", "a principled has no two_sided"),
    ("alpha", 'type = "principled"\nalpha = 0.2', "alpha", "not 'principled'"),
    ("alpha-u", 'type = "principled"\nalpha_u = 0.2', "alpha_u", "anisotropic roughness"),
    ("reflectance", 'type = "principled"\nreflectance = 0.5', "reflectance", "not 'principled'"),
    ("sheen-on-plastic", 'type = "plastic"\nsheen = 0.5', "sheen", "applies only to materials of type 'principled'"),
    ("eta-texture", 'type = "principled"\neta = { texture = "checks" }', "eta", "eta of a principled takes no texture"),
    ("rate-texture", 'type = "principled"\nclearcoat_sampling_rate = { texture = "checks" }',
     "clearcoat_sampling_rate", "takes no texture"),
    ("metallic-checkerboard", 'type = "principled"\nmetallic = { texture = "checks" }', "metallic",
     "metallic takes a bitmap"),
]


@pytest.mark.parametrize(("body", "key", "fragment"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_tables_are_one_line_errors(tmp_path, body, key, fragment):
    path = write(tmp_path, body, TEXTURES)
    _grey_exr(tmp_path)
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert info.value.where == f"{path}: materials.m.{key}", str(info.value)
    assert fragment in info.value.message and len(str(info.value).splitlines()) == 1, str(info.value)


def test_a_bitmap_above_1_on_a_weight_is_refused(tmp_path):
    _grey_exr(tmp_path, 0.2, 1.6)
    with pytest.raises(HarnessError) as info:
        load_scene(write(tmp_path, 'type = "principled"\nsheen = { texture = "grey" }', TEXTURES))
    assert "sheen takes values in [0, 1]" in info.value.message and len(str(info.value).splitlines()) == 1


BODY = ('type = "principled"\nbase_color = [0.8, 0.4, 0.2]\nroughness = 0.3\nmetallic = 0.25\nspecular = 0.6\n'
        'spec_tint = 0.5\nanisotropic = 0.4\nsheen = 0.7\nsheen_tint = 0.2\nclearcoat = 0.9\nclearcoat_gloss = 0.6\n'
        'spec_trans = 0.35\nflatness = 0.1\nmain_specular_sampling_rate = 2\nclearcoat_sampling_rate = 0.5\n'
        'diffuse_reflectance_sampling_rate = 1.5')


def test_the_core_row(tmp_path):
    scene = load_scene(write(tmp_path, BODY))
    m = list(scene.materials).index("m")
    table = material_arrays(scene)
    assert table.kind[m] == core.PRINCIPLED
    expected = core.material_row(core.PRINCIPLED, base_color=(0.8, 0.4, 0.2), roughness=0.3, metallic=0.25,
                                 specular=0.6, spec_tint=0.5, anisotropic=0.4, sheen=0.7, sheen_tint=0.2,
                                 clearcoat=0.9, clearcoat_gloss=0.6, spec_trans=0.35, flatness=0.1,
                                 main_specular_sampling_rate=2.0, clearcoat_sampling_rate=0.5,
                                 diffuse_reflectance_sampling_rate=1.5)
    np.testing.assert_array_equal(table.params[m], expected)
    assert table.params[m, core.P_METALLIC] == 0.25 and table.params[m, core.P_SPEC_TRANS] == 0.35


def test_textures_drive_every_parameter_mitsuba_lets_them(tmp_path):
    _grey_exr(tmp_path)
    items = ("base_color",) + core.PRINCIPLED_UNIT
    body = 'type = "principled"\n' + "\n".join(
        f'{item} = {{ texture = "{"checks" if item == "base_color" else "grey"}" }}' for item in items)
    scene = load_scene(write(tmp_path, body, TEXTURES))
    m = list(scene.materials).index("m")
    table = material_arrays(scene)
    slots = list(core.TEXTURE_SLOTS)
    assert table.texture[m, slots.index("reflectance")] >= 0
    for item in core.PRINCIPLED_UNIT:
        assert table.texture[m, slots.index(item)] >= 0, item
    spec = bsdf_dict(scene.materials["m"])
    assert spec["base_color"]["type"] == "checkerboard"
    assert all(spec[item]["type"] == "bitmap" for item in core.PRINCIPLED_UNIT)
    assert scene_json(scene)[0]["materials"]["m"]["metallic"] == {"texture": "grey"}


def test_mitsuba_dict_loads_in_mitsuba_as_the_same_material(tmp_path):
    """Every parameter written out, the index as eta; Mitsuba's object evaluates as our row does."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from reference_impl.kernels import bsdf
    scene = load_scene(write(tmp_path, BODY))
    spec = bsdf_dict(scene.materials["m"])
    assert spec["type"] == "principled" and "specular" not in spec
    assert spec["eta"] == pytest.approx(core.principled_eta(0.6))
    plugin = mi.load_dict(spec)
    materials = core.Materials(np.array([core.PRINCIPLED]), material_arrays(scene).params[[1]])
    for wo, wi in (([0.3, 0.1, 0.9], [-0.2, -0.3, 0.8]), ([0.5, 0.0, 0.7], [-0.3, 0.2, -0.9])):
        wo, wi = np.array(wo) / np.linalg.norm(wo), np.array(wi) / np.linalg.norm(wi)
        si = mi.SurfaceInteraction3f()
        si.wi, si.sh_frame = mi.Vector3f(*wo), mi.Frame3f(mi.Vector3f(0, 0, 1))
        f_mi = np.array(plugin.eval(mi.BSDFContext(), si, mi.Vector3f(*wi)))
        f, _ = bsdf.eval_pdf(materials, 0, wo, wi[None])
        np.testing.assert_allclose(f[0], f_mi, rtol=2e-5, atol=1e-6)
        assert f_mi.any()


def test_scene_json_entry(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "principled"\nbase_color = [0.1, 0.2, 0.3]\neta = 1.4'))
    entry = scene_json(scene)[0]["materials"]["m"]
    assert entry == {"type": "principled", "base_color": [0.1, 0.2, 0.3], "roughness": 0.5, "metallic": 0.0,
                     "spec_tint": 0.0, "anisotropic": 0.0, "sheen": 0.0, "sheen_tint": 0.0, "clearcoat": 0.0,
                     "clearcoat_gloss": 0.0, "spec_trans": 0.0, "flatness": 0.0, "eta": 1.4,
                     "main_specular_sampling_rate": 1.0, "clearcoat_sampling_rate": 1.0,
                     "diffuse_reflectance_sampling_rate": 1.0}


def test_gltf_material_and_losses(tmp_path):
    scene = load_scene(write(tmp_path, BODY))
    document = json.loads(export_scene(scene, "gltf", tmp_path / "gltf")[0].read_text())
    (node,) = [n for n in document["nodes"] if n.get("extras", {}).get("material") == "m"]
    gltf = document["materials"][document["meshes"][node["mesh"]]["primitives"][0]["material"]]
    pbr = gltf["pbrMetallicRoughness"]
    np.testing.assert_allclose(pbr["baseColorFactor"], [0.8, 0.4, 0.2, 1.0], rtol=1e-12)
    assert (pbr["metallicFactor"], pbr["roughnessFactor"]) == (0.25, 0.3)
    ext = gltf["extensions"]
    assert ext["KHR_materials_ior"]["ior"] == pytest.approx(core.principled_eta(0.6))
    assert ext["KHR_materials_transmission"] == {"transmissionFactor": 0.35}
    assert ext["KHR_materials_clearcoat"]["clearcoatFactor"] == 0.9
    assert ext["KHR_materials_clearcoat"]["clearcoatRoughnessFactor"] == pytest.approx(np.sqrt(0.1 * 0.4 + 0.0006))
    assert "KHR_materials_sheen" in ext and "KHR_materials_specular" in ext
    assert set(ext) <= set(document["extensionsUsed"]) and gltf["doubleSided"] is True
    lines = [line for line in export_losses(scene, "gltf") if "(principled)" in line]
    assert len(lines) == 1 and lines[0].startswith("glTF's metallic-roughness model is not Burley's"), lines
    opaque = load_scene(write(tmp_path, 'type = "principled"'))
    lines = [line for line in export_losses(opaque, "gltf") if "(principled)" in line]
    assert any(line.startswith("glTF's single-sided materials are culled") for line in lines), lines
