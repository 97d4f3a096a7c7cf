"""A suite's ``scene`` naming a Mitsuba 3 XML or glTF 2.0 file: imported on load, kept in the cache by content
(harness/running/imported_scenes.py), judged like any scene."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import ROOT

from harness.cli import main
from harness.core.errors import HarnessError
from harness.renderers.export import export_scene
from harness.running.cases import load_suite
from harness.scene import load_scene, triangulate

pytest.importorskip("mitsuba")


def _suite(tmp_path, scene: str, extra: str = "") -> object:
    path = tmp_path / "suite.toml"
    path.write_text(f'[[cases]]\nscene = "{scene}"\nspp = 64\nfilm = {{ width = 16, height = 16 }}\n{extra}')
    return path


@pytest.mark.parametrize("fmt, name", [("mitsuba-xml", "scene.xml"), ("gltf", "scene.gltf")])
def test_a_foreign_scene_is_imported_once_by_content(tmp_path, fmt, name):
    original = load_scene(ROOT / "scenes" / "cornell-box.toml")
    export_scene(original, fmt, tmp_path / "box")
    cache = tmp_path / "cache"
    suite = load_suite(_suite(tmp_path, f"box/{name}"), cache)
    case = suite.cases[0]
    assert case.name == "scene"  # the source file's stem, not the imported scene.toml's
    assert case.scene.parent.parent == cache / "imports" and case.scene.name == "scene.toml"
    imported = load_scene(case.scene)
    # the same triangles (a mesh's vertices as the float32 the export wrote)
    np.testing.assert_allclose(triangulate(imported).vertices, triangulate(original).vertices, rtol=0, atol=1e-6)
    again = load_suite(_suite(tmp_path, f"box/{name}"), cache).cases[0]
    assert again.scene == case.scene  # the same content: the same folder, so the same caches downstream
    assert len(list((cache / "imports").iterdir())) == 1
    export_scene(load_scene(ROOT / "scenes" / "furnace.toml"), fmt, tmp_path / "box")  # another scene, same path
    changed = load_suite(_suite(tmp_path, f"box/{name}"), cache).cases[0]
    assert changed.scene != case.scene and len(list((cache / "imports").iterdir())) == 2


def test_a_foreign_scene_that_cannot_be_imported_is_one_line_naming_its_element(tmp_path):
    (tmp_path / "bad.xml").write_text('<scene version="3.0.0">\n  <shape type="disk"/>\n</scene>\n')
    with pytest.raises(HarnessError) as err:
        load_suite(_suite(tmp_path, "bad.xml"), tmp_path / "cache")
    assert str(err.value.where).startswith(f"{tmp_path / 'bad.xml'}:2:")
    assert "\n" not in str(err.value)
    assert not (tmp_path / "cache" / "imports").exists()  # nothing kept


def test_harness_run_judges_an_imported_scene(tmp_path, capsys):
    export_scene(load_scene(ROOT / "scenes" / "cornell-box.toml"), "mitsuba-xml", tmp_path / "box")
    suite = _suite(tmp_path, "box/scene.xml", 'ground_truth_spp = 1024\nname = "box-from-xml"\n')
    code = main(["run", str(suite), "--out", str(tmp_path / "out"), "--no-report", "--quiet", "--cache-dir",
                 str(tmp_path / "cache"), "--executor", "serial", "--no-cache"])
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    assert code == 0, capsys.readouterr()
    (record,) = results["cases"]
    assert record["name"] == "box-from-xml" and record["status"] == "pass"
    assert record["scene"].startswith(str(tmp_path / "cache" / "imports"))
