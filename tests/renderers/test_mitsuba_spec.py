"""One Mitsuba description of a scene (harness/renderers/mitsuba_spec.py) in two forms: ``mi.load_dict``'s
(``harness.renderers.mitsuba.load_dict_form``) and XML (``harness.renderers.mitsuba_xml.spec_xml``). A spec made by
hand with every kind of value the forms know is written as the XML elements Mitsuba's format names, and loads in
Mitsuba as the same scene from both forms."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from harness.renderers.mitsuba import import_mitsuba, load_dict_form
from harness.renderers.mitsuba_spec import (
    ImageFile,
    LookAt,
    MeshFile,
    MitsubaSpec,
    Parameter,
    Point,
    Vector,
)
from harness.renderers.mitsuba_xml import spec_xml

PLACE = np.array([[1.0, 0, 0, 0.1], [0, 0, 1.0, -1.0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])
TETRA = MeshFile("tetra", "meshes/1-tetra.ply", np.array([[0, 0, 0], [0.6, 0, 0], [0, 0.6, 0], [0, 0, 0.6]], float),
                 np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
SKY = ImageFile("textures/3-sky.exr", np.linspace(0.1, 2.0, 4 * 8 * 3, dtype=np.float32).reshape(4, 8, 3))


def every_kind() -> MitsubaSpec:
    """A small scene holding each kind of value: scalars, colours, a reference, nested plugins, a matrix, a look-at,
    a point, a vector, parameters, a mesh and an image."""
    return MitsubaSpec({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3, "rr_depth": 5},
        "sensor": {"type": "perspective", "fov": 40.0, "fov_axis": "x", "near_clip": 0.01, "far_clip": 100.0,
                   "to_world": LookAt((0.0, 0.5, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
                   "sampler": {"type": "independent", "sample_count": Parameter("spp", 4),
                               "seed": Parameter("seed", 2)},
                   "film": {"type": "hdrfilm", "width": 6, "height": 4, "rfilter": {"type": "box"},
                            "pixel_format": "rgb", "sample_border": False}},
        "bsdf_0": {"type": "twosided",
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.7, 0.3]}}},
        "shape_0": {"type": "rectangle", "to_world": PLACE, "flip_normals": True,
                    "bsdf": {"type": "ref", "id": "bsdf_0"},
                    "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [4.0, 3.0, 2.0]}}},
        "shape_1": {"type": "ply", "filename": TETRA, "face_normals": True, "bsdf": {"type": "ref", "id": "bsdf_0"}},
        "emitter_0": {"type": "point", "position": Point((0.3, 1.0, -0.2)),
                      "intensity": {"type": "rgb", "value": [2.0, 3.0, 4.0]}},
        "emitter_1": {"type": "directional", "direction": Vector((0.3, -1.0, 0.2)),
                      "irradiance": {"type": "rgb", "value": [0.5, 0.6, 0.7]}},
        "emitter_3": {"type": "envmap", "filename": SKY, "scale": 0.5, "to_world": np.eye(4)},
    }, {"shape_1": "shape 1: tetra"})


def test_the_xml_writes_each_kind_of_value_as_mitsubas_element():
    text, files = spec_xml(every_kind(), "a test")
    assert list(files) == [TETRA.path, SKY.path]
    assert text.startswith('<?xml version="1.0" encoding="utf-8"?>\n<!-- a test -->\n<scene version="3.0.0">\n')
    assert "    <!-- shape 1: tetra -->\n    <shape type=\"ply\" id=\"shape_1\">\n" in text
    root = ET.fromstring(text.split("\n", 1)[1])
    assert [(d.get("name"), d.get("value")) for d in root.findall("default")] == [("spp", "4"), ("seed", "2")]
    assert root.find("sensor/sampler/integer[@name='sample_count']").get("value") == "$spp"
    assert root.find("sensor/transform[@name='to_world']/lookat").get("origin") == "0.0, 0.5, 3.0"
    assert root.find("sensor/film/boolean[@name='sample_border']").get("value") == "false"
    assert root.find("sensor/film/rfilter").get("type") == "box"
    assert root.find("bsdf[@id='bsdf_0']/bsdf/rgb[@name='reflectance']").get("value") == "0.2, 0.7, 0.3"
    matrix = root.find("shape[@id='shape_0']/transform[@name='to_world']/matrix").get("value")
    assert np.array_equal(np.array(matrix.split(), float).reshape(4, 4), PLACE)
    assert [r.attrib for r in root.findall("shape/ref")] == [{"id": "bsdf_0"}] * 2
    assert root.find("shape[@id='shape_1']/string[@name='filename']").get("value") == TETRA.path
    assert root.find("emitter[@id='emitter_0']/point[@name='position']").get("value") == "0.3, 1.0, -0.2"
    assert root.find("emitter[@id='emitter_1']/vector[@name='direction']").get("value") == "0.3, -1.0, 0.2"
    assert root.find("emitter[@id='emitter_3']/float[@name='scale']").get("value") == "0.5"


def test_a_value_neither_form_knows_is_refused():
    spec = MitsubaSpec({"type": "scene", "integrator": {"type": "path", "max_depth": {1, 2}}})
    with pytest.raises(TypeError, match="max_depth"):
        spec_xml(spec, "a test")


def _described(objects) -> list[str]:
    """Mitsuba's own description of each emitter, without addresses and file names, sorted."""
    return sorted(re.sub(r"0x[0-9a-f]+|\s*filename = \"[^\"]*\",?", "", str(o)) for o in objects)


def _shapes(scene) -> list[str]:
    """What Mitsuba made of each shape (a PLY's name and class aside): bounding box, area, BSDF, emitter; sorted (the
    XML loader may order shapes differently)."""
    return sorted(re.sub(r"0x[0-9a-f]+", "", f"{s.bbox()} {s.surface_area()} {s.bsdf()} {s.emitter() or ''}")
                  for s in scene.shapes())


def test_both_forms_load_as_the_same_scene(tmp_path):
    mi = import_mitsuba("scalar_rgb")
    text, files = spec_xml(every_kind(), "a test")
    (tmp_path / "scene.xml").write_text(text)
    for path, data in files.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_bytes(data)
    from_xml = mi.load_file(str(tmp_path / "scene.xml"))
    from_dict = mi.load_dict(load_dict_form(mi, every_kind()))
    assert str(from_xml.sensors()[0]) == str(from_dict.sensors()[0])
    assert from_xml.sensors()[0].sampler().sample_count() == 4
    assert str(from_xml.integrator()) == str(from_dict.integrator())
    assert _shapes(from_xml) == _shapes(from_dict)
    assert _described(from_xml.emitters()) == _described(from_dict.emitters())
    assert len(from_dict.emitters()) == 4
    xml_image = np.array(mi.render(from_xml, seed=1, spp=4))
    dict_image = np.array(mi.render(from_dict, seed=1, spp=4))
    assert xml_image.shape == (4, 6, 3) and np.all(np.isfinite(xml_image)) and dict_image.max() > 0
