"""The generated scenes (harness/generators, docs/generated-scenes.md): the same bytes on every run, the counts the
docs give, a suite's ``generated:NAME`` generated once into the cache, ``harness generate``, and every bad name or
parameter one line with exit 2. All at small parameters: nothing here renders."""

from __future__ import annotations

import hashlib
import json
import shlex
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT
from harness.cli import main
from harness.core.errors import HarnessError
from harness.generators import GENERATORS, city, forest, generation_key, parse_spec, room
from harness.generators.meshes import ply_binary
from harness.running.cases import load_suite
from harness.running.generated_scenes import generated_folder
from harness.scene import load_scene
from harness.scene.triangulate import shape_triangles
from test_hostile_input import assert_one_line, cli
from test_new_user import shell_blocks

SMALL = {"room": {"detail": 4}, "city": {"lights": 40, "blocks": 2}, "forest": {"trees": 5, "leaves": 12,
                                                                             "variants": 2}}
DOC = ROOT / "docs" / "generated-scenes.md"


def digests(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def counts(scene) -> tuple[int, int]:
    """(triangles of the meshes and the flat shapes, the spheres left out: analytic; emissive shapes)."""
    triangles = sum(len(shape_triangles(s)[1]) for s in scene.shapes if s.type != "sphere")
    return triangles, sum(s.is_emitter for s in scene.shapes)


@pytest.mark.parametrize("name", list(GENERATORS))
def test_a_generator_writes_the_same_bytes_twice(name, tmp_path):
    first = GENERATORS[name](tmp_path / "a", **SMALL[name])
    second = GENERATORS[name](tmp_path / "b", **SMALL[name])
    assert first.name == second.name == f"{name}.toml"  # the studies and the report name it so
    a, b = digests(tmp_path / "a"), digests(tmp_path / "b")
    assert a == b and len(a) >= 2
    assert any(n.endswith(".png") for n in a) == (name != "city")


@pytest.mark.parametrize("name", list(GENERATORS))
def test_the_counts_are_the_documented_ones(name, tmp_path):
    scene_file = GENERATORS[name](tmp_path / name, **SMALL[name])
    scene = load_scene(scene_file)
    triangles, lights = counts(scene)
    manifest = json.loads((tmp_path / name / "generated.json").read_text())
    assert manifest["counts"]["triangles"] == triangles
    assert manifest["counts"]["shapes"] == len(scene.shapes)
    if name == "room":
        assert triangles == room.triangle_count(4) == 15_902 and lights == 2
        assert room.triangle_count(7) == 1_016_846
        assert scene.materials["glass"].type == "dielectric" and scene.materials["gold"].type == "roughconductor"
        assert any(s.mesh_normals is not None for s in scene.shapes)  # smooth-shaded
        assert len(scene.used_textures) == 4
    elif name == "city":
        assert triangles == city.triangle_count(40, 2) == 2 + 12 * 4 + 80 and lights == 40
        powers = [np.mean(s.emission) * np.prod(np.linalg.norm(s.to_world[:3, :2], axis=0)) for s in scene.shapes
                  if s.is_emitter]
        assert max(powers) / min(powers) > 100  # powers over decades: choosing lights matters
        assert city.triangle_count(4096, 6) == 8_626
        windows = [(s.to_world[:3, 3].round(6).tobytes()) for s in scene.shapes if s.name.startswith("window-")]
        assert len(set(windows)) == len(windows) == 30  # each in a place of its own
    else:
        assert triangles == forest.triangle_count(5, 12) == 5 * (24 + 256) + 2 and [e.type for e in scene.emitters] == ["constant"]
        assert forest.triangle_count(1000, 4872) == 10_000_002
        assert scene.materials["leaf"].type == "mask"
        files = {s.file for s in scene.shapes if s.type == "mesh"}
        assert len(files) <= 4  # 2 variants x (trunk, crown), named by 10 shapes


def test_shapes_naming_one_mesh_file_share_one_parse(tmp_path):
    GENERATORS["forest"](tmp_path, trees=6, leaves=3, variants=1)
    scene = load_scene(tmp_path / "forest.toml")
    crowns = [s for s in scene.shapes if s.name.startswith("crown-")]
    assert len(crowns) == 6 and all(c.mesh_vertices is crowns[0].mesh_vertices for c in crowns)
    assert not crowns[0].mesh_vertices.flags.writeable
    assert scene.files.count(crowns[0].file) == 1


def test_flipped_coordinates_do_not_reach_another_shape_of_the_same_file(tmp_path):
    ply = ply_binary(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]),
                     uv=np.array([[0, 0.25], [1, 0.25], [0, 1]], float))
    (tmp_path / "t.ply").write_bytes(ply)
    (tmp_path / "s.toml").write_text(
        '[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nup = [0, 1, 0]\nfov = 40\n'
        '[film]\nwidth = 4\nheight = 4\n[materials.m]\nreflectance = [0.5, 0.5, 0.5]\n'
        '[[shapes]]\ntype = "mesh"\nfile = "t.ply"\nmaterial = "m"\n'
        '[[shapes]]\ntype = "mesh"\nfile = "t.ply"\nmaterial = "m"\nflip_tex_coords = true\n'
        '[[shapes]]\ntype = "mesh"\nfile = "t.ply"\nmaterial = "m"\n')
    a, b, c = load_scene(tmp_path / "s.toml").shapes
    assert np.allclose(a.mesh_uv[:, 1], [0.25, 0.25, 1.0]) and np.allclose(b.mesh_uv[:, 1], [0.75, 0.75, 0.0])
    assert c.mesh_uv is a.mesh_uv


def test_a_suite_naming_a_generated_scene_generates_it_once(tmp_path):
    suite = tmp_path / "s.toml"
    suite.write_text('[[cases]]\nscene = "generated:city?lights=6&blocks=1"\nspp = 2\n'
                     '[[cases]]\nname = "again"\nscene = "generated:city?blocks=1&lights=6"\nspp = 2\n')
    cache = tmp_path / "cache"
    loaded = load_suite(suite, cache)
    assert loaded.cases[0].name == "city" and loaded.cases[0].scene == loaded.cases[1].scene
    key = generation_key("city", {"lights": 6, "blocks": 1, "seed": 1})
    folder = generated_folder(cache) / f"city-{key}"
    assert loaded.cases[0].scene == folder / "city.toml"
    assert [p.name for p in generated_folder(cache).iterdir()] == [folder.name]  # no scratch folder left
    stamp = (folder / "city.toml").stat().st_mtime_ns
    load_suite(suite, cache)
    assert (folder / "city.toml").stat().st_mtime_ns == stamp  # found, not generated again
    assert generation_key("city", {"lights": 7, "blocks": 1, "seed": 1}) != key


@pytest.mark.parametrize("scene, fragment", [
    ("generated:castle", "unknown generated scene 'castle'; known: room, city, forest"),
    ("generated:rooms", "did you mean 'room'?"),
    ("generated:room?detail=99", "parameter 'detail' of room: expected an integer in [4, 8], got 99"),
    ("generated:room?detail=4.5", "expected an integer, got '4.5'"),
    ("generated:forest?tree=3", "unknown parameter 'tree' of forest; did you mean 'trees'?"),
    ("generated:city?lights", "expected key=value"),
    ("generated:city?lights=1000&blocks=1", "750 windows need more than the 78 window places"),
])
def test_a_bad_generated_scene_in_a_suite_is_one_line(scene, fragment, tmp_path, capfd):
    suite = tmp_path / "s.toml"
    suite.write_text(f'[[cases]]\nscene = "{scene}"\n')
    line = assert_one_line(*cli(capfd, "run", suite, "--out", tmp_path / "run", "--cache-dir", tmp_path / "c"),
                           f"{suite}: cases[0].scene: ", fragment)
    assert len(line) - len(str(suite)) < 200  # the line without the suite's path, whose length is pytest's
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("argv, fragment", [
    (["castle"], "NAME: unknown generated scene 'castle'; known: room, city, forest"),
    (["room?detail=3"], "NAME: parameter 'detail' of room: expected an integer in [4, 8], got 3"),
    (["forest?leaves=-1"], "expected an integer in [1, 1000000], got -1"),
    (["city?colour=red"], "unknown parameter 'colour' of city"),
    ([], "NAME: expected a scene to generate"),
    (["city?lights=1000&blocks=1"], "NAME: 750 windows need more than the 78 window places"),
])
def test_a_bad_generate_command_is_one_line(argv, fragment, tmp_path, capfd):
    assert_one_line(*cli(capfd, "generate", *argv, "--out", tmp_path / "out"), fragment)
    assert not (tmp_path / "out").exists()
    assert list(tmp_path.iterdir()) == []


def test_generate_refuses_a_folder_it_did_not_write_and_replaces_its_own(tmp_path, capfd):
    mine = tmp_path / "mine"
    (mine / "keep").mkdir(parents=True)
    assert_one_line(*cli(capfd, "generate", "city?lights=3&blocks=1", "--out", mine),
                    "--out: ", "is not empty and was not written by harness generate")
    assert (mine / "keep").is_dir()
    out = tmp_path / "out"
    code, stdout, _ = cli(capfd, "generate", "city?lights=3&blocks=1", "--out", out)
    assert code == 0 and "20 triangles, 3 lights" in stdout
    code, stdout, _ = cli(capfd, "generate", "generated:forest?trees=2&leaves=2&variants=1", "--out", out)
    assert code == 0 and "forest" in stdout
    assert json.loads((out / "generated.json").read_text())["generator"] == "forest"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine", "out"]  # the old output and the scratch gone


def test_parse_spec_gives_the_full_parameters():
    generator, params = parse_spec("forest?trees=3", "here")
    assert generator.name == "forest" and params == {"trees": 3, "leaves": 4872, "variants": 3, "seed": 1}
    with pytest.raises(HarnessError):
        parse_spec("forest?trees=true", "here")


def test_the_docs_print_generate_commands():
    commands = [c for block in shell_blocks(DOC.read_text(encoding="utf-8")) for c in block]
    assert "harness generate --list" in commands
    assert any(c.startswith("harness generate ") and "--out" in c for c in commands)


@pytest.mark.parametrize("command", [c for block in shell_blocks(DOC.read_text(encoding="utf-8")) for c in block
                                     if c.startswith("harness generate")])
def test_a_generate_command_of_the_docs_runs_as_printed(command, tmp_path, monkeypatch, capfd):
    monkeypatch.chdir(tmp_path)
    argv = shlex.split(command.split("  #", 1)[0])[1:]
    assert main(argv) == 0, capfd.readouterr().err
    out = capfd.readouterr().out
    if "--list" in argv:
        assert [line.split(":")[0] for line in out.splitlines()] == list(GENERATORS)
    else:
        assert out.startswith("wrote ") and load_scene(tmp_path / argv[argv.index("--out") + 1]
                                                               / f"{argv[1].split('?')[0]}.toml")


def test_the_real_scale_suite_names_the_three_scenes():
    text = (ROOT / "suites" / "real-scale.toml").read_text()
    for name in GENERATORS:
        assert f'scene = "generated:{name}"' in text
