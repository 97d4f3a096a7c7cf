"""``harness.renderers.import_mitsuba`` on hand-written Mitsuba 3 XML: each element the scene format can express is
imported with its values exactly (shapegroups and instances flattened, ``default`` parameters resolved, ``include``
followed inside the scene's folder), and each it cannot is refused in one line naming the file, the line and column
and the element (or, ``lenient``, dropped and listed). The round trip of the canonical scenes:
test_import_mitsuba_roundtrip.py."""

from __future__ import annotations

import struct
import tomllib
import zlib
from pathlib import Path

import numpy as np
import pytest

from harness.core.errors import HarnessError
from harness.files.imageio import encode_png, exr_bytes
from harness.renderers.import_mitsuba import import_mitsuba, line_column
from harness.renderers.importers import import_scene
from harness.renderers.imports import write_imported
from harness.renderers.meshfiles import ply_bytes
from harness.scene import load_scene, triangulate
from harness.scene.triangulate import shape_triangles

mi = pytest.importorskip("mitsuba")

SENSOR = """
  <sensor type="perspective">
    <float name="fov" value="45.5"/>
    <string name="fov_axis" value="y"/>
    <transform name="to_world">
      <lookat origin="0.1, 0.2, 5" target="0, 0.30000000000000004, 0" up="0, 1, 0"/>
    </transform>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    <film type="hdrfilm">
      <integer name="width" value="8"/><integer name="height" value="6"/>
      <rfilter type="tent"/><boolean name="sample_border" value="true"/>
    </film>
  </sensor>"""


def scene_text(body: str, sensor: str = SENSOR) -> str:
    return f'<?xml version="1.0"?>\n<scene version="3.0.0">{sensor}\n{body}\n</scene>\n'


def write(folder: Path, body: str, name: str = "scene.xml", sensor: str = SENSOR) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(scene_text(body, sensor))
    return path


def imported(folder: Path, body: str, sensor: str = SENSOR, lenient: bool = False):
    """The scene imported, written beside and loaded: (its TOML as a dict, the loaded scene, the import)."""
    result = import_mitsuba(write(folder, body, sensor=sensor), lenient=lenient)
    scene = load_scene(write_imported(result, folder / "out"))
    return tomllib.loads(result.toml), scene, result


# ---- what is imported ------------------------------------------------------------------------------------------


def test_the_sensor_film_and_integrator_keep_their_values(tmp_path):
    body = '<default name="depth" value="5"/><integrator type="path"><integer name="max_depth" value="$depth"/>' \
           '<integer name="rr_depth" value="3"/></integrator>'
    doc, scene, _ = imported(tmp_path, body)
    assert doc["camera"] == {"type": "perspective", "fov": 45.5, "fov_axis": "y", "origin": [0.1, 0.2, 5.0],
                             "target": [0.0, 0.30000000000000004, 0.0], "up": [0.0, 1.0, 0.0]}
    assert doc["film"] == {"filter": "tent", "width": 8, "height": 6}
    assert scene.max_depth == 5 and scene.camera.target == (0.0, 0.30000000000000004, 0.0)


def test_a_thin_lens_and_an_orthographic_sensor(tmp_path):
    thin = SENSOR.replace('type="perspective"', 'type="thinlens"').replace(
        '<string name="fov_axis" value="y"/>',
        '<float name="aperture_radius" value="0.25"/><float name="focus_distance" value="4.5"/>')
    doc, scene, _ = imported(tmp_path / "thin", "", sensor=thin)
    assert doc["camera"]["aperture_radius"] == 0.25 and doc["camera"]["focus_distance"] == 4.5
    ortho = SENSOR.replace('type="perspective"', 'type="orthographic"').replace(
        '<float name="fov" value="45.5"/>\n    <string name="fov_axis" value="y"/>', "").replace(
        "<lookat", '<scale x="2" y="3"/><lookat')
    doc, scene, _ = imported(tmp_path / "ortho", "", sensor=ortho)
    assert doc["camera"]["type"] == "orthographic" and doc["camera"]["scale"] == [2.0, 3.0, 1.0]


MATERIALS = """
  <bsdf type="diffuse" id="matte"><rgb name="reflectance" value="0.1, 0.2, 0.30000000000000004"/></bsdf>
  <bsdf type="diffuse" id="grey"><float name="reflectance" value="0.25"/></bsdf>
  <bsdf type="conductor" id="gold"><rgb name="eta" value="0.2, 0.9, 1.1"/><rgb name="k" value="3.9, 2.4, 2.1"/></bsdf>
  <bsdf type="roughconductor" id="brushed"><float name="alpha" value="0.3"/><string name="distribution" value="ggx"/>
    <string name="material" value="none"/></bsdf>
  <bsdf type="dielectric" id="glass"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1.0"/></bsdf>
  <bsdf type="roughdielectric" id="frosted"><float name="int_ior" value="1.33"/><float name="alpha" value="0.2"/>
  </bsdf>
  <bsdf type="thindielectric" id="pane"><float name="int_ior" value="1.52"/></bsdf>
  <bsdf type="plastic" id="shiny"><rgb name="diffuse_reflectance" value="0.5, 0.1, 0.1"/>
    <boolean name="nonlinear" value="true"/></bsdf>
  <bsdf type="roughplastic" id="satin"><float name="alpha" value="0.15"/></bsdf>
  <bsdf type="principled" id="disney"><rgb name="base_color" value="0.8, 0.5, 0.2"/>
    <float name="metallic" value="0.4"/><float name="roughness" value="0.35"/></bsdf>
  <bsdf type="twosided" id="both"><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf></bsdf>
  <bsdf type="twosided" id="front-back"><ref name="bsdf_0" id="matte"/><ref name="bsdf_1" id="grey"/></bsdf>
  <bsdf type="blendbsdf" id="mix"><float name="weight" value="0.3"/><ref id="matte"/><ref id="gold"/></bsdf>
  <bsdf type="mask" id="cutout"><texture type="bitmap" name="opacity"><string name="filename" value="a.png"/>
    <boolean name="raw" value="true"/></texture><ref id="matte"/></bsdf>
  <bsdf type="normalmap" id="bumpy"><texture type="bitmap" name="normalmap"><string name="filename" value="n.png"/>
    <boolean name="raw" value="true"/></texture><ref id="grey"/></bsdf>
  <bsdf type="bumpmap" id="ridged"><texture type="bitmap" name="height"><string name="filename" value="a.png"/>
    <boolean name="raw" value="true"/></texture><float name="scale" value="0.2"/><ref id="grey"/></bsdf>
  <bsdf type="diffuse" id="checked"><texture type="checkerboard" name="reflectance">
    <rgb name="color0" value="0.9, 0.9, 0.9"/><float name="color1" value="0.1"/>
    <transform name="to_uv"><scale x="4" y="2"/><translate x="0.5"/></transform></texture></bsdf>
"""


def test_every_material_type_keeps_mitsuba_s_names_and_values(tmp_path):
    tmp_path.mkdir(exist_ok=True)
    (tmp_path / "a.png").write_bytes(encode_png(np.full((4, 4, 3), 200, np.uint8)))
    (tmp_path / "n.png").write_bytes(encode_png(np.full((4, 4, 3), [128, 128, 255], np.uint8)))
    shapes = "".join(f'<shape type="rectangle"><ref id="{name}"/></shape>' for name in (
        "matte", "grey", "gold", "brushed", "glass", "frosted", "pane", "shiny", "satin", "disney", "both",
        "front-back", "mix", "cutout", "bumpy", "ridged", "checked"))
    doc, scene, result = imported(tmp_path, MATERIALS + shapes)
    m = doc["materials"]
    assert m["matte"] == {"type": "diffuse", "reflectance": [0.1, 0.2, 0.30000000000000004]}
    assert m["grey"] == {"type": "diffuse", "reflectance": [0.25, 0.25, 0.25]}
    assert m["gold"] == {"type": "conductor", "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.1]}
    assert m["brushed"] == {"type": "roughconductor", "alpha": 0.3, "distribution": "ggx", "material": "none"}
    assert m["pane"] == {"type": "thindielectric", "int_ior": 1.52}
    assert m["shiny"]["nonlinear"] is True and m["satin"] == {"type": "roughplastic", "alpha": 0.15}
    assert m["disney"] == {"type": "principled", "base_color": [0.8, 0.5, 0.2], "metallic": 0.4, "roughness": 0.35}
    assert m["both"] == {"type": "diffuse", "reflectance": [0.7, 0.7, 0.7], "two_sided": True}
    assert m["front-back"] == {"type": "twosided", "bsdf": ["matte", "grey"]}
    assert m["mix"] == {"type": "blendbsdf", "weight": 0.3, "bsdf": ["matte", "gold"]}
    assert m["cutout"]["type"] == "mask" and m["cutout"]["bsdf"] == "matte"
    assert m["bumpy"] == {"type": "normalmap", "normalmap": {"texture": "n"}, "bsdf": "grey"}
    assert m["ridged"] == {"type": "bumpmap", "texture": {"texture": "a"}, "scale": 0.2, "bsdf": "grey"}
    checker = doc["textures"][m["checked"]["reflectance"]["texture"]]
    assert checker["color1"] == 0.1 and checker["to_uv"] == [[4.0, 0.0, 0.5], [0.0, 2.0, 0.0],
                                                                          [0.0, 0.0, 1.0]]
    assert m["cutout"]["opacity"] == {"texture": "a"}  # one table per distinct texture
    assert result.files["textures/a.png"] == (tmp_path / "a.png").read_bytes()
    assert list(scene.materials)[:3] == ["matte", "grey", "gold"]


def test_shapes_meshes_and_instances_keep_their_placement(tmp_path):
    tmp_path.mkdir(exist_ok=True)
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]], np.float64)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    (tmp_path / "m.ply").write_bytes(ply_bytes(vertices, faces))
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    body = """
  <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.8, 0.8, 0.8"/></bsdf>
  <shape type="sphere" id="ball"><point name="center" value="0, 1, 0"/><float name="radius" value="0.5"/>
    <ref id="white"/></shape>
  <shape type="cube" id="box"><transform name="to_world"><scale value="0.25"/><translate x="1"/></transform>
    <ref id="white"/></shape>
  <shape type="ply" id="plate"><string name="filename" value="m.ply"/><boolean name="face_normals" value="true"/>
    <transform name="to_world"><translate z="2"/></transform><ref id="white"/></shape>
  <shape type="obj" id="tri"><string name="filename" value="m.obj"/><ref id="white"/></shape>
  <shape type="rectangle" id="light"><boolean name="flip_normals" value="true"/>
    <emitter type="area"><rgb name="radiance" value="5, 4, 3"/></emitter></shape>
  <shape type="shapegroup" id="group">
    <shape type="rectangle" id="part"><transform name="to_world"><translate x="1"/></transform>
      <ref id="white"/></shape>
    <shape type="ply" id="mesh"><string name="filename" value="m.ply"/><ref id="white"/></shape>
  </shape>
  <shape type="instance" id="first"><ref id="group"/><transform name="to_world"><translate y="3"/></transform></shape>
  <shape type="instance" id="second"><ref id="group"/><transform name="to_world"><rotate z="1" angle="90"/>
    </transform></shape>
"""
    doc, scene, result = imported(tmp_path, body)
    shapes = {s["name"]: s for s in doc["shapes"]}
    assert shapes["ball"]["center"] == [0.0, 1.0, 0.0] and shapes["ball"]["radius"] == 0.5
    assert shapes["box"]["to_world"] == [[0.25, 0, 0, 1], [0, 0.25, 0, 0], [0, 0, 0.25, 0], [0, 0, 0, 1]]
    assert shapes["plate"]["type"] == "mesh" and shapes["plate"]["face_normals"] is True
    assert result.files[shapes["plate"]["file"]] == (tmp_path / "m.ply").read_bytes()  # a PLY is copied
    assert shapes["tri"]["file"].endswith(".ply")  # an OBJ: the mesh Mitsuba reads, as PLY
    assert shapes["light"]["emission"] == [5.0, 4.0, 3.0] and shapes["light"]["flip_normals"] is True
    assert shapes["light"]["material"] == "default-diffuse"  # Mitsuba's BSDF of a shape without one
    assert doc["materials"]["default-diffuse"] == {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]}
    assert [s["name"] for s in doc["shapes"]][-4:] == ["first-part", "first-mesh", "second-part", "second-mesh"]
    assert shapes["first-part"]["to_world"] == [[1, 0, 0, 1], [0, 1, 0, 3], [0, 0, 1, 0], [0, 0, 0, 1]]
    assert shapes["first-mesh"]["to_world"] == [[1, 0, 0, 0], [0, 1, 0, 3], [0, 0, 1, 0], [0, 0, 0, 1]]
    # the triangles where Mitsuba puts them: the OBJ's as Mitsuba reads them
    mesh = mi.load_dict({"type": "obj", "filename": str(tmp_path / "m.obj")})
    geometry = triangulate(scene)
    tri = next(s for s in scene.shapes if s.name == "tri")
    assert tri.type == "mesh"
    positions = np.array(mesh.vertex_positions_buffer()).reshape(-1, 3)
    assert any(np.array_equal(np.asarray(geometry.vertices)[i:i + 3], positions)
               for i in range(len(geometry.vertices) - 2))


def test_emitters_keep_their_values(tmp_path):
    tmp_path.mkdir(exist_ok=True)
    (tmp_path / "sky.exr").write_bytes(exr_bytes(np.full((8, 16, 3), 0.5, np.float32)))
    body = """
  <emitter type="point" id="bulb"><point name="position" value="1, 2, 3"/>
    <rgb name="intensity" value="10, 10, 10"/></emitter>
  <emitter type="point" id="moved"><transform name="to_world"><translate x="4"/></transform>
    <rgb name="intensity" value="1, 2, 3"/></emitter>
  <emitter type="spot" id="spot"><transform name="to_world"><lookat origin="0, 3, 0" target="0, 0, 0" up="0, 0, 1"/>
    </transform><rgb name="intensity" value="5, 5, 5"/><float name="cutoff_angle" value="30"/>
    <float name="beam_width" value="20"/></emitter>
  <emitter type="directional" id="sun"><vector name="direction" value="0, -1, -1"/>
    <rgb name="irradiance" value="3, 3, 3"/></emitter>
  <emitter type="constant" id="sky"><rgb name="radiance" value="0.1, 0.2, 0.4"/></emitter>
  <shape type="rectangle"><bsdf type="diffuse"/></shape>
"""
    doc, scene, result = imported(tmp_path, body)
    envmap = '<emitter type="envmap" id="map"><string name="filename" value="sky.exr"/>' \
             '<float name="scale" value="2"/>' \
             '</emitter>'
    map_doc, map_scene, map_result = imported(tmp_path, envmap)
    e = {x["name"]: x for x in doc["emitters"]}
    assert e["bulb"] == {"type": "point", "name": "bulb", "position": [1.0, 2.0, 3.0], "intensity": [10.0] * 3}
    assert e["moved"]["position"] == [4.0, 0.0, 0.0]
    assert e["spot"]["cutoff_angle"] == 30.0 and e["spot"]["beam_width"] == 20.0 and len(e["spot"]["to_world"]) == 4
    assert e["sun"]["direction"] == [0.0, -1.0, -1.0] and e["sky"]["radiance"] == [0.1, 0.2, 0.4]
    assert [x.type for x in scene.emitters] == ["point", "point", "spot", "directional", "constant"]
    assert scene.shapes[0].material == "shape0-bsdf" and doc["materials"]["shape0-bsdf"]["reflectance"] == [0.5] * 3
    e = map_doc["emitters"][0]
    assert e["scale"] == 2.0 and map_result.files[e["file"]] == (tmp_path / "sky.exr").read_bytes()
    assert map_scene.emitters[0].type == "envmap"


def test_an_include_inside_the_folder_is_followed(tmp_path):
    write(tmp_path, '<bsdf type="diffuse" id="red"><rgb name="reflectance" value="0.9, 0.1, 0.1"/></bsdf>',
          name="parts/materials.xml", sensor="")
    doc, _, _ = imported(tmp_path, '<include filename="parts/materials.xml"/>'
                                   '<shape type="rectangle"><ref id="red"/></shape>')
    assert doc["materials"]["red"]["reflectance"] == [0.9, 0.1, 0.1]


def test_the_dispatch_takes_xml_gltf_glb_and_pbrt(tmp_path):
    expected = r"expected a Mitsuba 3 \.xml, a glTF 2\.0 \.gltf or \.glb, or a pbrt-v4 \.pbrt file"
    with pytest.raises(HarnessError, match=expected):
        import_scene(tmp_path / "scene.obj")


def test_line_and_column_are_mitsuba_s(tmp_path):
    path = write(tmp_path, '<shape type="rectangle">\n  <bsdf type="diffuse"/></shape>')
    state = mi.parser.parse_file(mi.parser.ParserConfig("scalar_rgb"), str(path))
    data = path.read_bytes()
    for node in state.nodes[1:]:
        line, col = line_column(data, node.offset)
        assert mi.parser.file_location(state, node).endswith(f"(line {line}, col {col})")


# ---- what is refused ----------------------------------------------------------------------------------------------

REFUSED = [
    ('<bsdf type="hair" id="x"/>', "<bsdf type='hair' id='x'>", "expected a bsdf of type"),
    ('<bsdf type="roughconductor" id="x"><float name="alpha_u" value="0.1"/></bsdf>',
     "<bsdf type='roughconductor' id='x'> property 'alpha_u'", "expected one of the roughconductor properties"),
    ('<bsdf type="diffuse" id="x"><spectrum name="reflectance" value="400:0.1, 700:0.5"/></bsdf>',
     "<bsdf type='diffuse' id='x'> property 'reflectance'", "a spectrum is not taken"),
    ('<shape type="disk"/>', "<shape type='disk'>", "expected a shape of type"),
    ('<emitter type="sunsky"/>', "<emitter type='sunsky'>", "expected an emitter of type"),
    ('<integrator type="direct"/>', "<integrator type='direct'>", "expected Mitsuba's path integrator"),
    (SENSOR.strip(), "<sensor type='perspective'>", "expected one sensor (the scene format has one sensor), got a "
                                                    "second"),
    ('<shape type="rectangle"><emitter type="area"><float name="sampling_weight" value="2"/></emitter></shape>',
     "<emitter type='area'> property 'sampling_weight'", "expected radiance only"),
    ('<bsdf type="diffuse" id="x"><texture type="bitmap" name="reflectance"><string name="filename" value="a.bmp"/>'
     '</texture></bsdf>', "<texture type='bitmap'> property 'filename'", "expected a .png, .jpg, .jpeg, .exr file"),
]


@pytest.mark.parametrize("body, element, expected", REFUSED, ids=[r[1].split("'")[1] for r in REFUSED])
def test_an_element_the_format_cannot_express_is_refused_in_one_line(tmp_path, body, element, expected):
    (tmp_path / "a.bmp").write_bytes(b"BM")
    path = write(tmp_path, body)
    with pytest.raises(HarnessError) as caught:
        import_mitsuba(path)
    message = str(caught.value)
    assert "\n" not in message and element in message and expected in message
    text = path.read_text()
    tag = element.split()[0][1:]
    offset = text.rindex(f"<{tag} type=\"{element.split(chr(39))[1]}\"") + 1  # the last: the sensor's second
    line, col = line_column(text.encode(), offset)
    assert message.startswith(f"{path}:{line}:{col}: {element}"), message


def test_a_film_crop_and_a_filter_the_reference_has_not_are_refused(tmp_path):
    crop = SENSOR.replace('<integer name="width" value="8"/>', '<integer name="width" value="8"/>'
                                                                '<integer name="crop_width" value="4"/>')
    with pytest.raises(HarnessError, match="property 'crop_width'"):
        import_mitsuba(write(tmp_path, "", sensor=crop))
    with pytest.raises(HarnessError, match="<rfilter type='mitchell'>"):
        import_mitsuba(write(tmp_path, "", sensor=SENSOR.replace("tent", "mitchell")))
    with pytest.raises(HarnessError, match="property 'sample_border': expected true"):
        import_mitsuba(write(tmp_path, "", sensor=SENSOR.replace('value="true"', 'value="false"')))
    lenient = import_mitsuba(write(tmp_path, "", sensor=SENSOR.replace('value="true"', 'value="false"')), lenient=True)
    assert len(lenient.dropped) == 1 and "property 'sample_border'" in lenient.dropped[0]
    assert tomllib.loads(lenient.toml)["film"]["filter"] == "tent"  # the film kept, with the reference's border
    matrix = SENSOR.replace('<lookat origin="0.1, 0.2, 5" target="0, 0.30000000000000004, 0" up="0, 1, 0"/>',
                            '<translate z="5"/>')
    with pytest.raises(HarnessError, match="property 'to_world': expected a <lookat>"):
        import_mitsuba(write(tmp_path, "", sensor=matrix))
    with pytest.raises(HarnessError, match="property 'to_world': expected a <lookat> with origin, target and up"):
        sensor = '<default name="z" value="5"/>' + SENSOR.replace("0.2, 5", "0.2, $z")
        import_mitsuba(write(tmp_path, "", sensor=sensor))
    with pytest.raises(HarnessError, match=r"<sensor type='perspective'>: expected fov \(without it"):
        import_mitsuba(write(tmp_path, "", sensor=SENSOR.replace('<float name="fov" value="45.5"/>', "")))


def test_what_mitsuba_s_parser_refuses_is_its_one_line(tmp_path):
    path = write(tmp_path, '<bsdf type="diffuse"><rgb name="reflectance" value="$nothing"/></bsdf>')
    with pytest.raises(HarnessError) as caught:
        import_mitsuba(path)
    assert str(caught.value).startswith(f"{path}: Error while loading {path} (line ") and "\n" not in str(caught.value)
    assert "undefined parameter: $nothing" in str(caught.value)


def test_an_include_outside_the_folder_is_refused(tmp_path):
    write(tmp_path, '<bsdf type="diffuse" id="red"/>', name="outside.xml", sensor="")
    path = write(tmp_path / "scene", '<include filename="../outside.xml"/>')
    with pytest.raises(HarnessError) as caught:
        import_mitsuba(path)
    line, col = line_column(path.read_bytes(), path.read_bytes().index(b"<include") + 1)
    assert str(caught.value).startswith(f"{path}:{line}:{col}: <include filename='../outside.xml'>: include file "
                                        f"'../outside.xml' resolves to ")
    assert str(caught.value).endswith("outside the scene's folder " + repr(str(path.parent.resolve())) +
                                      "; expected a file inside it (an include outside it is not followed)")


def test_lenient_drops_and_lists_what_it_cannot_express(tmp_path):
    body = """
  <bsdf type="hair" id="fur"/>
  <bsdf type="diffuse" id="ok"/>
  <shape type="rectangle" id="furry"><ref id="fur"/></shape>
  <shape type="rectangle" id="plain"><ref id="ok"/></shape>
  <emitter type="sunsky"/>"""
    doc, scene, result = imported(tmp_path, body, lenient=True)
    assert [s.name for s in scene.shapes] == ["plain"] and list(scene.materials) == ["ok"]
    assert len(result.dropped) == 3
    assert "<bsdf type='hair' id='fur'>: expected a bsdf of type" in result.dropped[0]
    assert "<shape type='rectangle' id='furry'>: expected a bsdf the scene format has: its <bsdf type='hair' " \
           "id='fur'> was dropped" in result.dropped[1]
    assert "<emitter type='sunsky'>" in result.dropped[2]
    assert all(line in doc["description"] for line in result.dropped)


def test_ids_with_odd_characters_are_kept_as_names(tmp_path):
    name = 'odd "name" é😀 \\ x'
    xml = name.replace('"', "&quot;")
    body = f'<bsdf type="diffuse" id="{xml}"/><shape type="rectangle" id="{xml} 2"><ref id="{xml}"/></shape>'
    doc, scene, _ = imported(tmp_path, body)
    assert list(scene.materials) == [name] and scene.shapes[0].name == f"{name} 2"


def test_lenient_leaves_out_a_property_and_keeps_its_element(tmp_path):
    body = '<bsdf type="diffuse" id="a"><spectrum name="reflectance" value="400:0.1, 700:0.5"/></bsdf>' \
           '<bsdf type="roughconductor" id="b"><float name="alpha_u" value="0.1"/><float name="alpha" value="0.2"/>' \
           '</bsdf><shape type="rectangle"><ref id="a"/></shape><shape type="cube"><ref id="b"/></shape>'
    doc, scene, result = imported(tmp_path, body, lenient=True)
    assert len(scene.shapes) == 2 and [line.split(": ")[1] for line in result.dropped] == [
        "<bsdf type='diffuse' id='a'> property 'reflectance'", "<bsdf type='roughconductor' id='b'> property 'alpha_u'"]
    assert doc["materials"]["a"]["reflectance"] == [0.5] * 3  # Mitsuba's default, and listed
    assert doc["materials"]["b"] == {"type": "roughconductor", "alpha": 0.2}


def test_mitsuba_s_own_cornell_box_written_as_xml(tmp_path):
    """``mi.cornell_box()`` as Mitsuba's parser writes it: refused for its film (a Gaussian filter without
    sample_border), imported with --lenient, which lists that one difference."""
    path = tmp_path / "cbox.xml"
    mi.set_variant("scalar_rgb")
    mi.parser.write_file(mi.parser.parse_dict(mi.parser.ParserConfig("scalar_rgb"), mi.cornell_box()), str(path))
    with pytest.raises(HarnessError, match=r"<film type='hdrfilm'> property 'sample_border': expected true with the "
                                           r"gaussian filter"):
        import_mitsuba(path)
    result = import_mitsuba(path, lenient=True)
    assert len(result.dropped) == 1
    scene = load_scene(write_imported(result, tmp_path / "out"))
    assert scene.film.filter == "gaussian" and scene.max_depth == 8 and len(scene.shapes) == 8
    assert sum(s.is_emitter for s in scene.shapes) == 1


def serialized_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A Mitsuba ``serialized`` file of one mesh (format 4: header, a zlib stream of flags, name, counts, float32
    positions and uint32 indices, then the offsets' dictionary)."""
    body = struct.pack("<I", 0x1000) + b"mesh\x00" + struct.pack("<QQ", len(vertices), len(faces))
    body += np.asarray(vertices, np.float32).tobytes() + np.asarray(faces, np.uint32).tobytes()
    return struct.pack("<HH", 0x041C, 4) + zlib.compress(body) + struct.pack("<QI", 0, 1)


def test_a_serialized_mesh_is_the_mesh_mitsuba_reads(tmp_path):
    tmp_path.mkdir(exist_ok=True)
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.25]])
    (tmp_path / "m.serialized").write_bytes(serialized_bytes(vertices, [[0, 1, 2], [1, 3, 2]]))
    body = '<shape type="serialized" id="s"><string name="filename" value="m.serialized"/>' \
           '<boolean name="face_normals" value="true"/><transform name="to_world"><translate z="1"/></transform>' \
           '<bsdf type="diffuse"/></shape>'
    doc, scene, result = imported(tmp_path, body)
    shape = doc["shapes"][0]
    assert shape["type"] == "mesh" and shape["face_normals"] is True and shape["to_world"][2][3] == 1.0
    mesh = scene.shapes[0]
    vertices_world, triangles = shape_triangles(mesh)
    assert np.array_equal(vertices_world, vertices + [0, 0, 1]) and triangles.tolist() == [[0, 1, 2], [1, 3, 2]]


# ---- found on third-party files (docs/import.md, "Tried on third-party files"), each written here small -----------


def test_a_bumpmap_takes_its_texture_under_any_name_as_mitsuba_does(tmp_path):
    """Mitsuba's bumpmap takes its one nested texture whatever its name (its docs' scenes name it by the file); the
    import read only ``height`` and refused the rest."""
    (tmp_path / "a.png").write_bytes(encode_png(np.full((4, 4, 3), 200, np.uint8)))
    body = """
  <bsdf type="bumpmap" id="ridged"><float name="scale" value="0.02"/>
    <texture type="bitmap" name="tiles_height"><boolean name="raw" value="true"/>
      <string name="filename" value="a.png"/></texture>
    <bsdf type="diffuse"/></bsdf>
  <shape type="rectangle"><ref id="ridged"/></shape>"""
    doc, scene, _ = imported(tmp_path, body)
    assert doc["materials"]["ridged"]["texture"] == {"texture": "a"} and doc["materials"]["ridged"]["scale"] == 0.02
    two = body.replace("<bsdf type=\"diffuse\"/>", '<texture type="bitmap" name="other"><string name="filename" '
                                                    'value="a.png"/></texture><bsdf type="diffuse"/>')
    with pytest.raises(HarnessError, match="property 'other': expected one nested texture, got a second"):
        import_mitsuba(write(tmp_path, two, name="two.xml"))


def test_a_normalmap_still_takes_only_normalmap(tmp_path):
    """Mitsuba's normalmap reads its texture only as ``normalmap`` (it refuses another name)."""
    (tmp_path / "n.png").write_bytes(encode_png(np.full((4, 4, 3), [128, 128, 255], np.uint8)))
    body = """
  <bsdf type="normalmap" id="bumpy"><texture type="bitmap" name="nm"><string name="filename" value="n.png"/>
    </texture><bsdf type="diffuse"/></bsdf>
  <shape type="rectangle"><ref id="bumpy"/></shape>"""
    with pytest.raises(HarnessError, match="<bsdf type='normalmap' id='bumpy'> property 'nm': expected normalmap"):
        import_mitsuba(write(tmp_path, body))


def test_a_sampler_by_id_and_the_film_s_file_format_are_not_kept(tmp_path):
    """A top-level ``<sampler id=...>`` (a sensor's ``<ref>``) and the film's ``file_format`` are a render's output
    and sampling, as the sensor's own sampler and ``pixel_format`` are: read, not kept, nothing refused."""
    sensor = SENSOR.replace('<sampler type="independent"><integer name="sample_count" value="4"/></sampler>',
                            '<ref id="my_sampler"/>').replace(
        '<rfilter type="tent"/>', '<rfilter type="tent"/><string name="file_format" value="openexr"/>')
    body = '<sampler type="independent" id="my_sampler"><integer name="sample_count" value="16"/></sampler>'
    path = write(tmp_path, body, sensor="")
    path.write_text(path.read_text().replace("<scene version=\"3.0.0\">", "<scene version=\"3.0.0\">" + body)
                    .replace(body + "\n" + body, body).replace("</scene>", sensor + "\n</scene>"))
    result = import_mitsuba(path)
    doc = tomllib.loads(result.toml)
    assert doc["film"] == {"filter": "tent", "width": 8, "height": 6} and result.dropped == []


def test_a_file_found_only_through_a_path_element_is_refused_as_missing(tmp_path):
    """Mitsuba's ``<path>`` adds folders to its resolver (its docs' scenes take textures from ../../common); the
    import reads files inside the scene's folder only, and says which file is missing, one line
    (harness.scene.mesh_files.confined_path)."""
    (tmp_path / "common" / "textures").mkdir(parents=True)
    (tmp_path / "common" / "textures" / "a.png").write_bytes(encode_png(np.full((4, 4, 3), 9, np.uint8)))
    body = """<path value="../common"/>
  <bsdf type="diffuse" id="d"><texture type="bitmap" name="reflectance">
    <string name="filename" value="textures/a.png"/></texture></bsdf>
  <shape type="rectangle"><ref id="d"/></shape>"""
    path = write(tmp_path / "scene", body)
    with pytest.raises(HarnessError) as caught:
        import_mitsuba(path)
    assert str(caught.value).endswith("<texture type='bitmap'> property 'filename': no such bitmap file: "
                                      f"'textures/a.png' (relative to {str(path.parent.resolve())!r})")
    assert "\n" not in str(caught.value)
    result = import_mitsuba(path, lenient=True)  # lenient: the bitmap goes, with its material and their shape
    assert "materials" not in tomllib.loads(result.toml) and "shapes" not in tomllib.loads(result.toml)
    assert len(result.dropped) == 2 and "was dropped" in result.dropped[1]


def test_lenient_drops_a_texture_without_its_file_with_its_element(tmp_path):
    """mitsuba-data's bsdf_blendbsdf.xml: a blendbsdf's ``weight`` bitmap whose file is not in the folder. Lenient
    left out the bitmap's ``filename`` and so the blendbsdf's ``weight`` key, keeping a blendbsdf of the format's
    default weight (a changed value); a plugin without its file now goes with its top-level element and the shapes
    that use it, as any refused plugin."""
    body = """
  <bsdf type="blendbsdf" id="mix">
    <texture name="weight" type="bitmap"><string name="filename" value="textures/gone.jpg"/></texture>
    <bsdf type="diffuse"/><bsdf type="conductor"/></bsdf>
  <bsdf type="diffuse" id="plain"/>
  <shape type="rectangle" id="mixed"><ref id="mix"/></shape>
  <shape type="rectangle" id="kept"><ref id="plain"/></shape>"""
    doc, scene, result = imported(tmp_path, body, lenient=True)
    assert "mix" not in doc["materials"] and [s["name"] for s in doc["shapes"]] == ["kept"]
    assert "<texture type='bitmap'> property 'filename': no such bitmap file: 'textures/gone.jpg'" in result.dropped[0]


def test_an_area_emitter_by_id_is_read_where_a_shape_names_it(tmp_path):
    """mitsuba-data's cbox: the area emitter written at the top level with an id and named by the luminaire's
    ``<ref>``. It was refused at the top level ("an area emitter belongs in a shape") though the shape took it; one
    no shape names is still refused."""
    body = """
  <emitter type="area" id="lamp"><rgb name="radiance" value="18.387, 10.9873, 2.75357"/></emitter>
  <shape type="rectangle" id="luminaire"><ref id="lamp"/></shape>"""
    doc, scene, result = imported(tmp_path, body)
    assert doc["shapes"][0]["emission"] == [18.387, 10.9873, 2.75357] and "emitters" not in doc
    assert result.dropped == []
    alone = '<emitter type="area" id="lamp"><rgb name="radiance" value="1, 1, 1"/></emitter>'
    with pytest.raises(HarnessError, match="<emitter type='area' id='lamp'>: expected an emitter of type point"):
        import_mitsuba(write(tmp_path, alone, name="alone.xml"))


def test_an_include_in_an_included_file_is_relative_to_the_scene_s_folder(tmp_path):
    """Mitsuba resolves every include through its file resolver, whose folder is the scene's, not the including
    file's (mitsuba-data's participating_media scenes): the check before Mitsuba's parser follows the same rule."""
    write(tmp_path, '<include filename="include/preamble.xml"/>', name="include/base.xml", sensor="")
    write(tmp_path, '<bsdf type="diffuse" id="red"><rgb name="reflectance" value="0.5, 0, 0"/></bsdf>',
          name="include/preamble.xml", sensor="")
    doc, _, _ = imported(tmp_path, '<include filename="include/base.xml"/>'
                                   '<shape type="rectangle"><ref id="red"/></shape>')
    assert doc["materials"]["red"]["reflectance"] == [0.5, 0.0, 0.0]


def test_an_envmap_s_translation_is_left_out_as_mitsuba_ignores_it(tmp_path):
    """mitsuba-data's matpreview.xml places its envmap with a translation (z = 8.87): Mitsuba turns only directions
    by an envmap's to_world, and the scene format refuses a translation there, so the import wrote a scene its own
    loader refused; the rotation is kept exactly, the translation left out."""
    (tmp_path / "sky.exr").write_bytes(exr_bytes(np.full((8, 16, 3), 0.5, np.float32)))
    body = ('<emitter type="envmap" id="map"><string name="filename" value="sky.exr"/>'
            '<transform name="to_world"><rotate y="1" angle="90"/><translate z="8.87"/></transform></emitter>')
    doc, scene, result = imported(tmp_path, body)
    m = np.array(doc["emitters"][0]["to_world"])
    expected = np.array(mi.ScalarTransform4d.rotate([0, 1, 0], 90).matrix)
    np.testing.assert_array_equal(m[:3, :3], expected[:3, :3])
    assert list(m[:, 3]) == [0.0, 0.0, 0.0, 1.0] and result.dropped == []
    assert scene.emitters[0].type == "envmap"


def test_a_named_index_or_conductor_is_refused_at_its_property(tmp_path):
    """mitsuba-data's docs scenes name indices and conductors ("bk7", "air", "Au"): the import wrote the names,
    which the scene format's loader refused afterwards, so even lenient stopped; now the property is refused at
    its element (lenient: left out, Mitsuba's default written)."""
    body = """
  <bsdf type="dielectric" id="glass"><string name="int_ior" value="bk7"/><string name="ext_ior" value="air"/></bsdf>
  <bsdf type="conductor" id="gold"><string name="material" value="Au"/></bsdf>
  <bsdf type="conductor" id="mirror"><string name="material" value="none"/></bsdf>
  <shape type="rectangle"><ref id="glass"/></shape><shape type="cube"><ref id="gold"/></shape>
  <shape type="sphere"><ref id="mirror"/></shape>"""
    with pytest.raises(HarnessError, match="<bsdf type='dielectric' id='glass'> property 'int_ior': a named index "
                                           "'bk7': Mitsuba's tables are not imported"):
        import_mitsuba(write(tmp_path, body))
    doc, scene, result = imported(tmp_path / "lenient", body, lenient=True)
    assert [line.split("property ")[1].split(":")[0] for line in result.dropped] == ["'int_ior'", "'ext_ior'",
                                                                                     "'material'"]
    assert doc["materials"]["glass"] == {"type": "dielectric"} and doc["materials"]["gold"] == {"type": "conductor"}
    assert doc["materials"]["mirror"]["material"] == "none"


def test_a_sensor_placement_it_cannot_read_is_refused_even_leniently(tmp_path):
    """mitsuba-data's veach_mis.xml writes ``<scale x="-1"/>`` twice before its ``<lookat>``: lenient left the
    placement out, which left no camera, and the line said "expected a sensor with a film"; it names why now."""
    sensor = SENSOR.replace('<lookat', '<scale x="-1"/><scale x="-1"/><lookat')
    with pytest.raises(HarnessError, match="<sensor type='perspective'> property 'to_world': expected a <lookat>"):
        import_mitsuba(write(tmp_path, "", sensor=sensor), lenient=True)


def test_a_refused_sensor_is_named_when_lenient_has_no_camera_left(tmp_path):
    """mitsuba-data's test scenes' sensors have no ``fov`` (Mitsuba's default is a focal length along the diagonal):
    lenient dropped the sensor and then said only "expected a sensor with a film"; the line now names the sensor's
    refusal."""
    sensor = SENSOR.replace('<float name="fov" value="45.5"/>', "")
    with pytest.raises(HarnessError) as caught:
        import_mitsuba(write(tmp_path, "", sensor=sensor), lenient=True)
    assert "expected a sensor with a film (the scene format needs a camera); its sensor was refused: " in str(
        caught.value) and "<sensor type='perspective'>" in str(caught.value) and "\n" not in str(caught.value)


def test_a_checkerboard_on_a_one_number_parameter_is_refused_at_its_property(tmp_path):
    """mitsuba-data's bsdf_roughconductor_textured_carbon.xml drives a roughness with a checkerboard: the import
    wrote it, the loader refused it, and lenient stopped; it is refused at the property now (lenient: left out)."""
    body = """
  <bsdf type="roughconductor" id="carbon"><texture type="checkerboard" name="alpha"/></bsdf>
  <shape type="rectangle"><ref id="carbon"/></shape>"""
    with pytest.raises(HarnessError, match="<bsdf type='roughconductor' id='carbon'> property 'alpha': a "
                                           "checkerboard texture: alpha takes a bitmap"):
        import_mitsuba(write(tmp_path, body))
    doc, _, result = imported(tmp_path / "lenient", body, lenient=True)
    assert "alpha" not in doc["materials"]["carbon"] and len(result.dropped) == 1
