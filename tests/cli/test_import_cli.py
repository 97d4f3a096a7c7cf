"""``harness import FILE --out DIR``: what it prints and writes, its one-line refusals (exit 2, nothing written),
``--lenient``'s warnings, and the commands docs/import.md prints, run as printed."""

from __future__ import annotations

import json
import os
import shlex

import pytest
from conftest import ROOT
from test_new_user import shell_blocks

from harness.cli import main

pytest.importorskip("mitsuba")

DOC_COMMANDS = [command for block in shell_blocks((ROOT / "docs" / "import.md").read_text(encoding="utf-8"))
                for command in block]
SCENE = """<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/><rfilter type="box"/>
    </film>
  </sensor>
  <shape type="rectangle"><bsdf type="diffuse"/></shape>
  BODY
</scene>
"""


def cli(capfd, *argv):
    code = main([str(a) for a in argv])
    out, err = capfd.readouterr()
    return code, out, err


def test_import_writes_the_scene_and_prints_what_it_wrote(tmp_path, capfd):
    source = tmp_path / "scene.xml"
    source.write_text(SCENE.replace("BODY", '<emitter type="constant"/>'))
    code, out, err = cli(capfd, "import", source, "--out", tmp_path / "out", "--json")
    assert code == 0 and err == "", err
    summary = json.loads(out)
    assert summary["scene"] == str(tmp_path / "out" / "scene.toml") and summary["dropped"] == []
    assert (tmp_path / "out" / "scene.toml").is_file()
    code, out, err = cli(capfd, "import", source, "--out", tmp_path / "out")  # replaces, as export does
    assert code == 0 and "0 dropped; scene file" in out


def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capfd):
    source = tmp_path / "scene.xml"
    source.write_text(SCENE.replace("BODY", '<emitter type="sunsky"/>'))
    code, out, err = cli(capfd, "import", source, "--out", tmp_path / "out")
    assert code == 2 and out == "" and err.count("\n") == 1
    assert err.startswith(f"harness: error: {source}:9:4: <emitter type='sunsky'>: expected an emitter of type")
    assert not (tmp_path / "out").exists()
    code, _, err = cli(capfd, "import", tmp_path / "scene.obj", "--out", tmp_path / "out")
    assert code == 2 and "expected a Mitsuba 3 .xml, a glTF 2.0 .gltf or .glb, or a pbrt-v4 .pbrt file" in err
    assert not (tmp_path / "out").exists()


def test_a_value_the_scene_format_refuses_is_one_line_naming_the_scene_it_would_be(tmp_path, capfd):
    source = tmp_path / "scene.xml"
    source.write_text(SCENE.replace("BODY", '<bsdf type="diffuse" id="hot"><rgb name="reflectance" value="2, 0, 0"/>'
                                            '</bsdf><shape type="cube"><ref id="hot"/></shape>'))
    code, out, err = cli(capfd, "import", source, "--out", tmp_path / "out")
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"harness: error: {tmp_path / 'out' / 'scene.toml'}: materials.hot.reflectance")
    assert f"(imported from {source})" in err and not (tmp_path / "out").exists()


def test_lenient_warns_once_per_dropped_element(tmp_path, capfd):
    source = tmp_path / "scene.xml"
    source.write_text(SCENE.replace("BODY", '<emitter type="sunsky"/><shape type="disk"/>'))
    code, out, err = cli(capfd, "import", source, "--out", tmp_path / "out", "--lenient")
    assert code == 0 and "2 dropped" in out
    lines = err.splitlines()
    assert len(lines) == 2 and all(line.startswith(f"harness: warning: dropped {source}:") for line in lines)
    assert "<shape type='disk'>" in lines[1]


def test_the_docs_print_import_commands():
    assert any(c.startswith("harness import ") for c in DOC_COMMANDS)


@pytest.mark.slow
def test_the_commands_of_docs_import_run_as_printed(tmp_path, monkeypatch, capfd):
    (tmp_path / "scenes").symlink_to(ROOT / "scenes")
    monkeypatch.chdir(tmp_path)
    for command in DOC_COMMANDS:
        code, out, err = cli(capfd, *shlex.split(command, comments=True)[1:])
        assert code == 0, (command, err)
    assert (tmp_path / "cornell-imported" / "scene.toml").is_file() and (tmp_path / "imported.exr").is_file()


@pytest.mark.parametrize("name, body, fifo, where", [
    ("scene.xml", None, "scene.xml", "scene.xml"),
    ("scene.gltf", None, "scene.gltf", "scene.gltf"),
    ("scene.pbrt", None, "scene.pbrt", "scene.pbrt"),
    ("scene.xml", '<scene version="3.0.0">\n<include filename="part.xml"/>\n</scene>\n', "part.xml",
     "scene.xml:2:2: <include filename='part.xml'>"),
    ("scene.pbrt", 'WorldBegin\nInclude "part.pbrt"\n', "part.pbrt", "scene.pbrt:2:9"),
    ("scene.gltf", '{"asset": {"version": "2.0"}, "buffers": [{"uri": "part.bin", "byteLength": 12}], '
                   '"bufferViews": [{"buffer": 0, "byteLength": 12}], "accessors": [{"bufferView": 0, '
                   '"componentType": 5126, "count": 1, "type": "VEC3"}], "meshes": [{"primitives": [{"attributes": '
                   '{"POSITION": 0}}]}], "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0}',
     "part.bin", "scene.gltf: /buffers/0/uri"),
])
def test_a_named_pipe_is_refused_before_anything_opens_it(tmp_path, capfd, monkeypatch, name, body, fifo, where):
    """Opening a named pipe waits for a writer: the file itself or one it names is refused in one line instead."""
    monkeypatch.chdir(tmp_path)
    if body is not None:
        (tmp_path / name).write_text(body)
    os.mkfifo(tmp_path / fifo)
    code, out, err = cli(capfd, "import", name, "--out", "out")
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"harness: error: {where}") and "not a regular file (a named pipe)" in err
    assert not (tmp_path / "out").exists()
