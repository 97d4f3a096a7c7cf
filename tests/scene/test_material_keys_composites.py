"""``type = "blendbsdf"``, ``"mask"`` and ``"twosided"`` (docs/scene-format.md, "Materials made of materials"):
Mitsuba 3.9.1's names and defaults, one-line errors naming the key, a texture as the weight or opacity, the core's
rows, Mitsuba's dict and XML, scene.json and glTF's stand-ins."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import MINIMAL_SCENE
from harness.core.errors import HarnessError
from harness.renderers.export import export_losses, mitsuba_xml
from harness.renderers.mitsuba_spec import bsdf_dict
from harness.renderers.scene_json import scene_json
from harness.scene import load_scene, material_arrays
from reference_impl import materials as core

NESTED = '''
[materials.rough]
type = "roughconductor"
alpha = 0.3

[materials.glass]
type = "dielectric"
'''
SHAPES = '\n[[shapes]]\ntype = "rectangle"\nmaterial = "m"\n\n[[shapes]]\ntype = "sphere"\nmaterial = "white"\n' \
         'emission = [1, 1, 1]\ncenter = [0, 0, 3]\nradius = 0.1\n'
TEXTURES = '''
[textures.checks]
type = "checkerboard"
color0 = 0.9
color1 = 0.1

[textures.leaf]
filename = "leaf.png"
'''


def write(folder, body: str, extra: str = ""):
    path = folder / "scene.toml"
    path.write_text(MINIMAL_SCENE + TEXTURES + NESTED + extra + f"\n[materials.m]\n{body}\n" + SHAPES)
    if not (folder / "leaf.png").exists():
        from harness.files.imageio import encode_png
        codes = np.zeros((4, 4, 3), np.uint8)
        codes[1:3, 1:3] = 255
        (folder / "leaf.png").write_bytes(encode_png(codes))
    return path


def material(folder, body: str, extra: str = ""):
    return load_scene(write(folder, body, extra)).materials["m"]


def test_defaults_and_nesting(tmp_path):
    blend = material(tmp_path, 'type = "blendbsdf"\nbsdf = ["white", "rough"]')
    assert (blend.weight, [m.name for m in blend.nested]) == (0.5, ["white", "rough"])
    assert blend.reflectance == (1.0, 1.0, 1.0)  # the larger of white's 0.8 and the mirror-like conductor's 1
    mask = material(tmp_path, 'type = "mask"\nbsdf = "white"\nopacity = 0.25')
    assert (mask.weight, [m.name for m in mask.nested]) == (0.25, ["white"])
    sides = material(tmp_path, 'type = "twosided"\nbsdf = "rough"')
    assert [m.name for m in sides.nested] == ["rough", "rough"]
    inner = '\n[materials.mix]\ntype = "blendbsdf"\nweight = 0.2\nbsdf = ["white", "rough"]\n'
    sides = material(tmp_path, 'type = "twosided"\nbsdf = ["mix", "white"]', inner)
    assert sides.nested[0].nested[1].name == "rough"


BAD = [
    ("blend-one-name", 'type = "blendbsdf"\nbsdf = "white"', "bsdf", 'expected a list of two material names'),
    ("blend-three", 'type = "blendbsdf"\nbsdf = ["white", "rough", "white"]', "bsdf", "two material names"),
    ("blend-unknown", 'type = "blendbsdf"\nbsdf = ["white", "velvet"]', "bsdf", "unknown material 'velvet'"),
    ("blend-weight", 'type = "blendbsdf"\nbsdf = ["white", "rough"]\nweight = 1.5', "weight",
     "expected a number in [0, 1]"),
    ("blend-missing", 'type = "blendbsdf"\nweight = 0.5', "bsdf", "missing required key 'bsdf'"),
    ("blend-alpha", 'type = "blendbsdf"\nbsdf = ["white", "rough"]\nalpha = 0.1', "alpha",
     "a blendbsdf takes the keys type, weight, bsdf"),
    ("mask-itself", 'type = "mask"\nbsdf = "m"', "bsdf", "contains 'm'"),
    ("mask-checkerboard", 'type = "mask"\nbsdf = "white"\nopacity = { texture = "checks" }', "opacity",
     "takes a bitmap"),
    ("mask-two", 'type = "mask"\nbsdf = ["white", "rough"]', "bsdf", 'expected a material name'),
    ("twosided-glass", 'type = "twosided"\nbsdf = "glass"', "bsdf", "transmits light"),
    ("twosided-weight", 'type = "twosided"\nbsdf = "white"\nweight = 0.5', "weight", "a twosided takes the keys"),
]


@pytest.mark.parametrize(("body", "key", "fragment"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_tables_are_one_line_errors(tmp_path, body, key, fragment):
    path = write(tmp_path, body)
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert info.value.where == f"{path}: materials.m.{key}", str(info.value)
    assert fragment in info.value.message and len(str(info.value).splitlines()) == 1, str(info.value)


def test_a_nested_mask_and_a_cycle_are_refused(tmp_path):
    extra = '\n[materials.hole]\ntype = "mask"\nbsdf = "white"\n'
    path = write(tmp_path, 'type = "blendbsdf"\nbsdf = ["white", "hole"]', extra)
    with pytest.raises(HarnessError, match="is a mask: a mask is a shape's own material"):
        load_scene(path)
    extra = '\n[materials.a]\ntype = "blendbsdf"\nbsdf = ["white", "m"]\n'
    with pytest.raises(HarnessError, match="expected materials that do not contain the material itself"):
        load_scene(write(tmp_path, 'type = "blendbsdf"\nbsdf = ["white", "a"]', extra))


def test_a_mask_on_a_light_is_refused(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(MINIMAL_SCENE + '\n[materials.m]\ntype = "mask"\nbsdf = "white"\n\n[[shapes]]\ntype = '
                    '"rectangle"\nmaterial = "m"\nemission = [1, 1, 1]\n')
    with pytest.raises(HarnessError) as info:
        load_scene(path)
    assert info.value.where == f"{path}: shapes[0].material" and "is a mask" in info.value.message


def test_the_core_rows_name_the_nested_rows(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "blendbsdf"\nweight = 0.3\nbsdf = ["rough", "white"]'))
    names = list(scene.materials)
    table = material_arrays(scene)
    m = names.index("m")
    assert table.kind[m] == core.BLENDBSDF and table.params[m, core.P_WEIGHT] == 0.3
    assert (table.params[m, core.P_NESTED], table.params[m, core.P_NESTED + 1]) == (names.index("rough"),
                                                                                   names.index("white"))
    scene = load_scene(write(tmp_path, 'type = "mask"\nbsdf = "white"\nopacity = { texture = "leaf" }'))
    table = material_arrays(scene)
    m = list(scene.materials).index("m")
    assert table.kind[m] == core.MASK and table.texture[m, list(core.TEXTURE_SLOTS).index("weight")] == 0
    assert table.params[m, core.P_WEIGHT] == 1.0  # the texture's largest value: a bound


def test_mitsuba_dicts_and_xml(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "mask"\nopacity = 0.4\nbsdf = "rough"'))
    assert bsdf_dict(scene.materials["m"]) == {"type": "mask", "opacity": 0.4,
                                               "bsdf": bsdf_dict(scene.materials["rough"])}
    blend = material(tmp_path, 'type = "blendbsdf"\nbsdf = ["white", "rough"]')
    assert bsdf_dict(blend) == {"type": "blendbsdf", "weight": 0.5, "bsdf_0": bsdf_dict(blend.nested[0]),
                                "bsdf_1": bsdf_dict(blend.nested[1])}
    sides = material(tmp_path, 'type = "twosided"\nbsdf = ["white", "rough"]')
    assert bsdf_dict(sides)["type"] == "twosided" and bsdf_dict(sides)["bsdf_1"]["type"] == "roughconductor"
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    text, files = mitsuba_xml(load_scene(write(tmp_path, 'type = "blendbsdf"\nweight = 0.3\nbsdf = ["white", '
                                                         '"rough"]')))
    assert '<bsdf type="blendbsdf"' in text
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "scene.xml").write_text(text)
    for name, data in files.items():
        (tmp_path / "x" / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "x" / name).write_bytes(data)
    loaded = mi.load_file(str(tmp_path / "x" / "scene.xml"))
    assert "BlendBSDF" in str(loaded.shapes()[0].bsdf()) or "BlendBSDF" in str(loaded.shapes()[1].bsdf())


def test_scene_json_and_gltf_losses(tmp_path):
    scene = load_scene(write(tmp_path, 'type = "blendbsdf"\nweight = 0.3\nbsdf = ["white", "rough"]'))
    assert scene_json(scene)[0]["materials"]["m"] == {"type": "blendbsdf", "weight": 0.3, "bsdf": ["white", "rough"]}
    assert any("blend" in line for line in export_losses(scene, "gltf"))
    scene = load_scene(write(tmp_path, 'type = "mask"\nopacity = { texture = "leaf" }\nbsdf = "white"'))
    assert scene_json(scene)[0]["materials"]["m"] == {"type": "mask", "opacity": {"texture": "leaf"},
                                                      "bsdf": "white"}
    scene = load_scene(write(tmp_path, 'type = "twosided"\nbsdf = "white"'))
    assert scene_json(scene)[0]["materials"]["m"] == {"type": "twosided", "bsdf": "white"}
