"""Every material type of the scene format as Mitsuba 3 sees it (issue 15): the adapter's BSDF dicts load in
scalar_rgb with exactly the scene's parameters, render a tiny scene, and the Mitsuba XML export gives the same BSDFs;
Lambertian materials keep the dicts they had before."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from conftest import MINIMAL_SCENE
import harness.renderers.mitsuba as mts
from harness.renderers.export import export_losses, export_scene
from harness.renderers.mitsuba_spec import bsdf_dict
from harness.scene import load_scene
from harness.scene.load import CU_ETA, CU_K
from harness.scene.model import Material

MATERIALS = {
    "diffuse": 'reflectance = [0.2, 0.4, 0.6]',
    "diffuse-two-sided": 'reflectance = [0.2, 0.4, 0.6]\ntwo_sided = true',
    "mirror": 'type = "conductor"',
    "mirror-tinted-two-sided": 'type = "conductor"\nmaterial = "none"\nspecular_reflectance = [0.9, 0.5, 0.1]\n'
                               'two_sided = true',
    "copper": f'type = "conductor"\neta = {list(CU_ETA)}\nk = {list(CU_K)}',
    "real-index": 'type = "conductor"\neta = 1.5\nk = 0',
    "rough-beckmann": 'type = "roughconductor"\neta = [0.2, 0.9, 1.1]\nk = [3.9, 2.4, 2.1]\nalpha = 0.3',
    "rough-ggx-two-sided": 'type = "roughconductor"\nalpha = 0.05\ndistribution = "ggx"\nsample_visible = false\n'
                           'two_sided = true\nspecular_reflectance = 0.5',
    "glass": 'type = "dielectric"',
    "water-tinted": 'type = "dielectric"\nint_ior = 1.33\next_ior = 1.0\nspecular_reflectance = [1, 0.5, 0.5]\n'
                    'specular_transmittance = [0.5, 1, 0.5]',
    "rough-glass": 'type = "roughdielectric"\nalpha = 0.2',
    "rough-glass-ggx": 'type = "roughdielectric"\nalpha = 1\ndistribution = "ggx"\nsample_visible = false\n'
                       'int_ior = 1.0\next_ior = 1.5',
    "thin-glass": 'type = "thindielectric"',
    "thin-glass-tinted": 'type = "thindielectric"\nint_ior = 1.33\next_ior = 1.0\nspecular_reflectance = 0.5\n'
                         'specular_transmittance = [0.9, 0.6, 0.3]',
    "plastic": 'type = "plastic"',
    "plastic-nonlinear-two-sided": 'type = "plastic"\ndiffuse_reflectance = [0.7, 0.2, 0.1]\nnonlinear = true\n'
                                   'specular_reflectance = [1, 0.8, 0.6]\nint_ior = 1.6\ntwo_sided = true',
    "principled": 'type = "principled"',
    "principled-all": 'type = "principled"\nbase_color = [0.8, 0.4, 0.2]\nmetallic = 0.3\nspecular = 0.7\n'
                      'roughness = 0.4\nanisotropic = 0.5\nsheen = 0.4\nclearcoat = 0.6\nspec_trans = 0.3',

}
BODY = """
[[shapes]]
type = "sphere"
material = "m"
radius = 0.8

[[shapes]]
type = "rectangle"
material = "m"
translate = [0, 0, -1]
scale = 3

[[emitters]]
type = "constant"
radiance = [1, 1, 1]
"""


def scene_with(folder: Path, body: str):
    path = folder / "scene.toml"
    path.write_text(MINIMAL_SCENE.replace("width = 16\nheight = 16", "width = 4\nheight = 4")
                    + f"\n[materials.m]\n{body}\n" + BODY)
    return load_scene(path)


@pytest.fixture(scope="module")
def mi():
    return mts.import_mitsuba("scalar_rgb")


def bsdf_text(bsdf) -> str:
    return re.sub(r"0x[0-9a-f]+", "", str(bsdf))


def test_lambertian_dicts_are_what_they_were():
    assert bsdf_dict(Material("a", (0.2, 0.4, 0.6))) == {
        "type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.4, 0.6]}}
    assert bsdf_dict(Material("a", (0.2, 0.4, 0.6), True)) == {
        "type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.4, 0.6]}}}


@pytest.mark.parametrize("name", list(MATERIALS))
def test_every_material_loads_and_renders_in_mitsuba(mi, tmp_path, name):
    scene = scene_with(tmp_path, MATERIALS[name])
    material = scene.materials["m"]
    spec = bsdf_dict(material)
    assert (spec["type"] == "twosided") == material.two_sided
    loaded = mi.load_dict(mts.scene_to_mitsuba_dict(scene, "scalar_rgb", spp=2))
    params = mi.traverse(loaded)
    prefix = "bsdf_1.brdf_0." if material.two_sided else "bsdf_1."

    def value(key):
        return np.ravel(np.array(params[prefix + key], dtype=np.float64))

    text = bsdf_text(loaded.shapes()[0].bsdf())
    if material.is_diffuse:
        np.testing.assert_allclose(value("reflectance.value"), material.reflectance, rtol=1e-6)
    elif material.type == "principled":
        p = material.principled
        np.testing.assert_allclose(value("base_color.value"), p.base_color, rtol=1e-6)
        assert float(value("eta")[0]) == pytest.approx(p.eta, rel=1e-6)
        for item in ("roughness", "metallic", "anisotropic", "sheen", "clearcoat", "spec_trans"):
            assert float(value(f"{item}.value")[0]) == pytest.approx(getattr(p, item), rel=1e-6), item
    else:
        np.testing.assert_allclose(value("specular_reflectance.value") * np.ones(3), material.specular_reflectance,
                                   rtol=1e-6)
    if material.is_conductor:
        np.testing.assert_allclose(value("eta.value") * np.ones(3), material.eta, rtol=1e-6)
        np.testing.assert_allclose(value("k.value") * np.ones(3), material.k, rtol=1e-6)
    if material.is_dielectric:
        assert float(value("eta")[0]) == pytest.approx(material.int_ior / material.ext_ior, rel=1e-6)
        np.testing.assert_allclose(value("specular_transmittance.value") * np.ones(3),
                                   material.specular_transmittance, rtol=1e-6)
        assert "TwoSided" not in text
    if material.type == "plastic":
        np.testing.assert_allclose(value("diffuse_reflectance.value") * np.ones(3), material.diffuse_reflectance,
                                   rtol=1e-6)
        assert float(value("eta")[0]) == pytest.approx(material.int_ior / material.ext_ior, rel=1e-6)
        assert f"nonlinear = {int(material.nonlinear)}" in text
    if material.is_rough:
        assert float(value("alpha.value")[0]) == pytest.approx(material.alpha, rel=1e-6)
        assert f"distribution = {material.distribution}" in text
        assert f"sample_visible = {int(material.sample_visible)}" in text
    image = np.array(mi.render(loaded, spp=2), dtype=np.float64)
    assert image.shape == (4, 4, 3) and np.all(np.isfinite(image)) and np.all(image >= 0) and image.max() > 0


@pytest.mark.parametrize("name", list(MATERIALS))
def test_the_mitsuba_xml_export_has_the_same_bsdfs(mi, tmp_path, name):
    scene = scene_with(tmp_path, MATERIALS[name])
    export_scene(scene, "mitsuba-xml", tmp_path / "xml", spp=2, seed=0)
    from_xml = mi.load_file(str(tmp_path / "xml" / "scene.xml"))
    from_dict = mi.load_dict(mts.scene_to_mitsuba_dict(scene, "scalar_rgb", spp=2))
    assert sorted(bsdf_text(s.bsdf()) for s in from_xml.shapes()) == \
        sorted(bsdf_text(s.bsdf()) for s in from_dict.shapes())
    xml_params, dict_params = mi.traverse(from_xml), mi.traverse(from_dict)
    keys = [k for k in dict_params.keys() if k.startswith("bsdf_")]
    assert keys and keys == [k for k in xml_params.keys() if k.startswith("bsdf_")]
    for key in keys:
        np.testing.assert_array_equal(np.array(xml_params[key]), np.array(dict_params[key]), err_msg=key)


def test_the_refusal_of_named_conductors_quotes_mitsubas_copper(mi):
    """The numbers the loader's message offers for Cu are what Mitsuba 3 itself uses for material = "Cu" in RGB."""
    params = mi.traverse(mi.load_dict({"type": "conductor", "material": "Cu"}))
    np.testing.assert_allclose(np.array(params["eta.value"]), CU_ETA, rtol=1e-5)
    np.testing.assert_allclose(np.array(params["k.value"]), CU_K, rtol=1e-5)


def test_mitsubas_defaults_are_the_loaders(mi):
    """With nothing but the type, Mitsuba and the loader agree: conductors eta 0, k 1; alpha 0.1, beckmann, visible
    normals; dielectrics 1.5046 / 1.000277."""
    defaults = {kind: Material("m", (1.0, 1.0, 1.0), type=kind)
                for kind in ("conductor", "roughconductor", "dielectric", "roughdielectric")}
    for kind, material in defaults.items():
        ours = mi.traverse(mi.load_dict(bsdf_dict(material)))
        theirs = mi.traverse(mi.load_dict({"type": kind}))
        for key in theirs.keys():
            np.testing.assert_allclose(np.ravel(np.array(ours[key])) * np.ones(3),
                                       np.ravel(np.array(theirs[key])) * np.ones(3), rtol=1e-7, err_msg=key)
        if material.is_rough:
            for text in (bsdf_text(mi.load_dict(bsdf_dict(material))), bsdf_text(mi.load_dict({"type": kind}))):
                assert "distribution = beckmann" in text and "sample_visible = 1" in text


# --------------------------------------------------------------------------------------------------------------------
# glTF: metallic-roughness and KHR_materials_* where the mapping is exact, the rest said by export_losses

GLTF = {
    # material -> (base colour, metallic, roughness, extensions)
    "diffuse": ([0.2, 0.4, 0.6], 0.0, 1.0, {}),
    "mirror": ([1.0, 1.0, 1.0], 1.0, 0.0, {}),
    "real-index": ([0.04] * 3, 1.0, 0.0, {}),
    "rough-ggx-two-sided": ([0.5] * 3, 1.0, np.sqrt(0.05), {}),
    "glass": ([1.0, 1.0, 1.0], 0.0, 0.0, {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                                          "KHR_materials_ior": {"ior": 1.5046 / 1.000277},
                                          "KHR_materials_volume": {"thicknessFactor": 1.0}}),
    "rough-glass-ggx": ([1.0, 1.0, 1.0], 0.0, 1.0, {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                                                    "KHR_materials_ior": {"ior": 1.0 / 1.5},
                                                    "KHR_materials_volume": {"thicknessFactor": 1.0}}),
}


@pytest.mark.parametrize("name", list(GLTF))
def test_gltf_materials(tmp_path, name):
    scene = scene_with(tmp_path, MATERIALS[name])
    document = json.loads(export_scene(scene, "gltf", tmp_path / "gltf")[0].read_text())
    colour, metallic, roughness, extensions = GLTF[name]
    (material,) = document["materials"]
    pbr = material["pbrMetallicRoughness"]
    np.testing.assert_allclose(pbr["baseColorFactor"], [*colour, 1.0], rtol=1e-12)
    assert pbr["metallicFactor"] == metallic and pbr["roughnessFactor"] == pytest.approx(roughness, rel=1e-12)
    assert material.get("extensions", {}) == extensions
    assert set(extensions) <= set(document.get("extensionsUsed", []))
    assert material["doubleSided"] == (scene.materials["m"].two_sided or scene.materials["m"].is_dielectric)
    extras = [node["extras"] for node in document["nodes"] if "extras" in node]
    assert all(("bsdf" in e) == (name != "diffuse") for e in extras) and extras
    trimesh.load(tmp_path / "gltf" / "scene.gltf", force="scene")  # a file trimesh reads back


def losses(folder: Path, name: str, fmt: str) -> list[str]:
    """export_losses of the material ``name``'s scene but the line about its constant environment."""
    return [line for line in export_losses(scene_with(folder, MATERIALS[name]), fmt) if "emitter0" not in line]


def test_gltf_and_obj_losses_name_what_is_approximate(tmp_path):
    assert losses(tmp_path, "mirror", "gltf") == [
        "glTF's single-sided materials are culled from behind, not black: m (conductor)"]
    assert losses(tmp_path, "glass", "gltf") == []
    assert losses(tmp_path, "diffuse", "gltf") == []
    lines = losses(tmp_path, "rough-beckmann", "gltf")
    assert [line.split(":")[0] for line in lines] == [
        "glTF metals have Schlick's Fresnel from a base colour", "glTF's microfacets are GGX",
        "glTF's single-sided materials are culled from behind, not black"]
    assert losses(tmp_path, "water-tinted", "gltf") == [
        "glTF's transmission has no reflection tint: specular_reflectance of m (dielectric) left out"]
    assert losses(tmp_path, "glass", "obj") == [
        "OBJ's MTL holds diffuse colours (Kd) and emission (Ke) only: materials m (dielectric) written with Kd = "
        "their glTF base colour"]
    assert losses(tmp_path, "diffuse", "obj") == []
    assert losses(tmp_path, "glass", "mitsuba-xml") == []
