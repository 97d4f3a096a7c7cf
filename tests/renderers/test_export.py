"""``harness export``: every canonical scene in every format loads back with the same triangles, and the Mitsuba XML
renders what the Mitsuba adapter's scene dict renders (same seed: the same image up to float32 rounding)."""

from __future__ import annotations

import dataclasses
import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import trimesh

from harness.cli import main
from harness.renderers.export import FORMATS, export_scene
from harness.scene import load_scene
from harness.scene.triangulate import shape_triangles, triangle_areas
from reference_impl import Film

ROOT = Path(__file__).resolve().parents[2]
CANONICAL = sorted(p.stem for p in (ROOT / "scenes").glob("*.toml"))

MESH_SCENE = """
name = "mesh-mix"
[camera]
origin = [0.0, 0.5, 3.0]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 45.0
[film]
width = 20
height = 14
filter = "gaussian"
[integrator]
max_depth = 4
[materials.grey]
reflectance = [0.6, 0.5, 0.4]
[materials.leaf]
reflectance = [0.2, 0.7, 0.3]
two_sided = true
[[shapes]]
name = "floor"
type = "rectangle"
material = "grey"
rotate = { axis = [1.0, 0.0, 0.0], angle = -90.0 }
scale = [3.0, 3.0, 3.0]
translate = [0.0, -1.0, 0.0]
[[shapes]]
name = "light"
type = "rectangle"
material = "grey"
rotate = { axis = [1.0, 0.0, 0.0], angle = 90.0 }
scale = [0.5, 0.5, 0.5]
translate = [0.0, 1.5, 0.0]
emission = [8.0, 7.0, 6.0]
[[shapes]]
name = "tetra"
type = "mesh"
material = "leaf"
file = "tetra.ply"
translate = [0.3, -0.5, 0.0]
[[shapes]]
name = "ball"
type = "sphere"
material = "grey"
center = [-0.6, -0.6, 0.2]
radius = 0.35
flip_normals = false
"""


@pytest.fixture(scope="module")
def mesh_scene(tmp_path_factory) -> Path:
    """A scene with a PLY mesh, a two-sided material, a sphere and a Gaussian filter (what the canonical scenes lack)."""
    folder = tmp_path_factory.mktemp("mesh-scene")
    tetra = trimesh.Trimesh(vertices=[[0, 0, 0], [0.6, 0, 0], [0, 0.6, 0], [0, 0, 0.6]],
                            faces=[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], process=False)
    (folder / "tetra.ply").write_bytes(tetra.export(file_type="ply"))
    (folder / "mesh-mix.toml").write_text(MESH_SCENE)
    return folder / "mesh-mix.toml"


def _scene_files(name: str, mesh_scene: Path) -> Path:
    return mesh_scene if name == "mesh-mix" else ROOT / "scenes" / f"{name}.toml"


def _area(vertices, faces) -> float:
    return float(triangle_areas(np.asarray(vertices, np.float64), np.asarray(faces, np.int64)).sum())


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("name", CANONICAL + ["mesh-mix"])
def test_export_loads_back_with_the_same_triangles(name, fmt, mesh_scene, tmp_path):
    scene = load_scene(_scene_files(name, mesh_scene))
    files = export_scene(scene, fmt, tmp_path)
    assert all(f.is_file() and f.stat().st_size > 0 for f in files)
    per_shape = [shape_triangles(s) for s in scene.shapes]
    if fmt == "mitsuba-xml":
        root = ET.parse(files[0]).getroot()
        shapes = root.findall("shape")
        as_mesh = ("mesh",)  # spheres stay analytic in every scene
        assert [s.get("type") for s in shapes] == [("ply" if s.type in as_mesh else s.type) for s in scene.shapes]
        assert len(root.findall("bsdf")) == len(scene.materials)
        assert len(root.findall("shape/emitter")) == len(scene.lights)
        for shape, xml_shape, (v, t) in zip(scene.shapes, shapes, per_shape):
            if shape.type in as_mesh:
                loaded = trimesh.load(tmp_path / xml_shape.find("string").get("value"), process=False)
                assert len(loaded.faces) == len(t)
                # float32 vertices: an ulp at |p| ~ 7 is 5e-7, 1.6e-5 of veach-mis's smallest sphere (r = 0.03)
                np.testing.assert_allclose(_area(loaded.vertices, loaded.faces), _area(v, t), rtol=1e-5)
        return
    if fmt == "json":
        document = json.loads(files[0].read_text())
        assert [s["name"] for s in document["shapes"]] == [s.name for s in scene.shapes]
        for entry, (v, t) in zip(document["shapes"], per_shape):
            loaded = trimesh.load(tmp_path / entry["mesh"], process=False)
            np.testing.assert_array_equal(loaded.vertices, np.float32(v))  # float32 in the PLY: v rounded once
            np.testing.assert_array_equal(loaded.faces, t)
        return
    if fmt == "ply":
        assert len(files) == len(scene.shapes)
        for f, (v, t) in zip(files, per_shape):
            loaded = trimesh.load(f, process=False)
            assert (len(loaded.vertices), len(loaded.faces)) == (len(v), len(t))
            np.testing.assert_allclose(loaded.vertices, v, rtol=1e-7, atol=1e-7 * np.abs(v).max())  # float32
            np.testing.assert_array_equal(loaded.faces, t)  # winding (the front side) kept
        return
    loaded = trimesh.load(files[0], process=False)  # textures: a textured sphere's seam vertices are repeated
    meshes = list(loaded.geometry.values()) if isinstance(loaded, trimesh.Scene) else [loaded]
    assert sum(len(m.faces) for m in meshes) == sum(len(t) for _, t in per_shape)
    total = sum(_area(v, t) for v, t in per_shape)
    # obj stores vertices as decimal text (~1e-8 relative), gltf as float32
    np.testing.assert_allclose(sum(_area(m.vertices, m.faces) for m in meshes), total, rtol=1e-6)
    if fmt == "gltf":
        assert len(meshes) == len(scene.shapes)


def _shape_signature(shape) -> str:
    """What Mitsuba made of one shape: its type, bounding box, area, BSDF and emitter (addresses, ids and a bitmap's
    name dropped, which is its file's name in the XML and empty in the dict; -0 printed as 0)."""
    emitter = shape.emitter()
    text = f"{type(shape).__name__} {shape.bbox()} {shape.surface_area()} {shape.bsdf()} {emitter if emitter else ''}"
    text = re.sub(r"(?<![\d.])-0(?![\d.])", "0", text)
    return re.sub(r"0x[0-9a-f]+|id = \"[^\"]*\"|name = \"[^\"]*\"", "", text)


@pytest.mark.parametrize("name", CANONICAL + ["mesh-mix"])
def test_mitsuba_xml_renders_like_the_adapter(name, mesh_scene, tmp_path):
    """The XML scene is the adapter's dict: the same camera, film, integrator and (as a multiset: Mitsuba's XML
    loader may order shapes differently from run to run) the same shapes, BSDFs and emitters; and its renders agree
    with the dict's by the statistical verdict (K = 8 seeded renders each, variance of the mean from the runs with
    K - 1 dof, false-alarm probability alpha = 1e-3)."""
    from harness.renderers.external import combine_repeats
    from harness.renderers.mitsuba import scene_to_mitsuba_dict
    from harness.judges.verdict import verdict

    scene = load_scene(_scene_files(name, mesh_scene))
    scene = dataclasses.replace(scene, film=Film(20, 14, scene.film.filter))
    export_scene(scene, "mitsuba-xml", tmp_path, spp=4, seed=0)
    import mitsuba as mi

    previous = mi.variant()
    try:
        mi.set_variant("scalar_rgb")
        from_xml = mi.load_file(str(tmp_path / "scene.xml"))
        from_dict = mi.load_dict(scene_to_mitsuba_dict(scene, "scalar_rgb", spp=4))
        assert str(from_xml.sensors()[0]) == str(from_dict.sensors()[0])
        assert str(from_xml.integrator()) == str(from_dict.integrator())
        assert sorted(map(_shape_signature, from_xml.shapes())) == sorted(map(_shape_signature, from_dict.shapes()))
        # the $spp / $seed parameters override the defaults written into the file
        assert mi.load_file(str(tmp_path / "scene.xml"), spp=7).sensors()[0].sampler().sample_count() == 7
        k = 8
        xml_runs = [np.array(mi.render(from_xml, seed=100 + i, spp=8), np.float64) for i in range(k)]
        dict_runs = [np.array(mi.render(from_dict, seed=200 + i, spp=8), np.float64) for i in range(k)]
    finally:
        if previous and previous != "scalar_rgb":
            mi.set_variant(previous)
    test, test_var, dof = combine_repeats(xml_runs)
    ref, ref_var, _ = combine_repeats(dict_runs)
    assert test.shape == (14, 20, 3) and test.max() > 0
    outcome = verdict(test, test_var, ref, ref_var, tile=4, alpha=1e-3, test_dof=dof, expected_dof=dof)
    assert outcome.passed, outcome.reason


def test_export_cli(tmp_path, capsys):
    out = tmp_path / "cornell"
    assert main(["export", str(ROOT / "scenes" / "cornell-box.toml"), "--format", "mitsuba-xml", "--out", str(out)]) == 0
    assert "cornell-box: mitsuba-xml, 8 shapes" in capsys.readouterr().out
    assert (out / "scene.xml").is_file()
    assert main(["export", str(ROOT / "scenes" / "cornell-box.toml"), "--format", "fbx", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--format" in err and "mitsuba-xml" in err
