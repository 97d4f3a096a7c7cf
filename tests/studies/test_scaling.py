"""``harness bench --scaling``: the terrain generator, the option's parsing and refusals, and the command end to end
at tiny sizes, and the commands docs/performance.md ("Scale") prints, run as printed or at tiny sizes.

The figures themselves are measurements, not tests (docs/performance.md, "Scale")."""

from __future__ import annotations

import json
import math
import shlex
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT
from test_new_user import shell_blocks

from harness.cli import main
from harness.core.errors import HarnessError
from harness.core.memory import peak_rss_bytes
from harness.scene import load_scene, triangulate
from harness.studies import scaling, terrain

DOC = ROOT / "docs" / "performance.md"
DOC_COMMANDS = [c for block in shell_blocks(DOC.read_text(encoding="utf-8")) for c in block
                if c.startswith("harness bench --scaling")]
#: what a docs command of the full sizes runs as in the test: its sizes replaced by tiny ones
TINY = {"--triangles": "2k,8k", "--size": "16", "--spp": "4", "--rounds": "1"}


@pytest.mark.parametrize("count", [1, 2, 7, 2000, 2001, 12345])
def test_the_terrain_has_the_triangles_asked_and_unit_normals(count):
    vertices, normals, triangles = terrain.heightfield(count, seed=3)
    assert triangles.shape == (count, 3) and triangles.dtype == np.int32
    assert 0 <= triangles.min() and triangles.max() < len(vertices)
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6) and np.all(normals[:, 2] > 0)
    # counter-clockwise from above: every face's normal points up, as the vertex normals do
    corners = vertices[triangles].astype(np.float64)
    face = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert np.all(face[:, 2] > 0)


def test_the_terrain_is_deterministic_and_loads_with_its_count(tmp_path):
    a = terrain.write_terrain(tmp_path / "a", 5000, seed=2, size=8)
    b = terrain.write_terrain(tmp_path / "b", 5000, seed=2, size=8)
    c = terrain.write_terrain(tmp_path / "c", 5000, seed=3, size=8)
    assert a.mesh.read_bytes() == b.mesh.read_bytes() != c.mesh.read_bytes()
    assert a.scene.read_text() == b.scene.read_text()
    scene = load_scene(a.scene)
    geometry = triangulate(scene)
    assert len(geometry.triangles) == 5000 == a.triangles and len(geometry.vertices) == a.vertices
    assert geometry.has_shading_normals and scene.film.width == 8
    glossy = terrain.write_terrain(tmp_path / "a", 5000, seed=2, size=8, material="glossy")
    assert load_scene(glossy.scene).has_glossy_materials and not list(tmp_path.rglob("*.tmp*"))


@pytest.mark.parametrize("text, counts", [("10k,100k,1M,10M", [10_000, 100_000, 1_000_000, 10_000_000]),
                                          ("2.5M", [2_500_000]), (" 7 , 1K", [7, 1000])])
def test_triangle_counts_are_read(text, counts):
    assert scaling.parse_triangles(text) == counts
    assert [scaling.parse_triangles(scaling.count_text(n))[0] for n in counts] == counts


@pytest.mark.parametrize("text", ["0", "", "1.5", "10G", "1k5", "-3", "101M", "1k,1000", "1,,2", "1e6"])
def test_bad_triangle_counts_name_the_option(text):
    with pytest.raises(HarnessError) as err:
        scaling.parse_triangles(text)
    assert err.value.where == "--triangles"


def test_the_peak_rss_is_the_process_own():
    """A fresh child reports its own peak, not its parent's (ru_maxrss is kept across execve on Linux)."""
    ballast = np.ones(300 * 2**20 // 8)  # 300 MiB touched in this process
    code = "from harness.core.memory import peak_rss_bytes; print(peak_rss_bytes())"
    child = int(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                               check=True).stdout)
    assert peak_rss_bytes() > 300 * 2**20 > child > 1 * 2**20
    del ballast


def test_marginal_bytes_and_the_table():
    def row(n, contender, peak, seconds=1.0):
        spread = {"median": peak, "low": peak, "high": peak}
        timed = {"median": seconds, "low": seconds, "high": seconds}
        return {"triangles": n, "contender": contender, "error": None, "load_seconds": timed,
                "bvh_seconds": timed if contender == "reference" else {"median": None}, "render_seconds": timed,
                "peak_rss": spread, "rss_per_triangle": spread, "paths_per_second": 1e6, "mse": 0.01,
                "efficiency": 100.0}
    result = {"size": 8, "spp": 4, "rounds": 1, "ground_truth_spp": 16, "mitsuba_variant": "llvm_ad_rgb",
              "date": "today", "load_average_before": [1.0], "load_average_after": [1.0],
              "rows": [row(1000, "reference", 1e8), row(1000, "mitsuba", 2e8), row(3000, "reference", 1.1e8),
                       row(3000, "mitsuba", 2e8 + 4000)], "ratios": {"1000": {"efficiency": 1.0}}}
    assert scaling.marginal_bytes(result) == {"reference": [(1000, 3000, 5000.0)], "mitsuba": [(1000, 3000, 2.0)]}
    text = scaling.format_table(result)
    assert all(column in text for column in scaling.COLUMNS) and "1k->3k 5000 B" in text


def _run(capfd, argv: list[str]) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capfd.readouterr()
    return code, out, err


@pytest.mark.slow
def test_the_scale_study_runs_at_tiny_sizes(tmp_path, capfd):
    """Both renderers in fresh processes, every column of the table, the JSON's rows and ratios."""
    out = tmp_path / "scale.json"
    code, text, err = _run(capfd, ["bench", "--scaling", "--triangles", "2k,8k", "--size", "16", "--spp", "4",
                                   "--rounds", "1", "--cache-dir", str(tmp_path / "cache"), "--out", str(out)])
    assert code == 0, err
    assert all(column in text for column in scaling.COLUMNS), text
    assert "terrain 8k: mitsuba round 1/1" in err  # progress on the terminal
    result = json.loads(out.read_text())
    assert [(r["triangles"], r["contender"]) for r in result["rows"]] == [
        (2000, "reference"), (2000, "mitsuba"), (8000, "reference"), (8000, "mitsuba")]
    for row in result["rows"]:
        assert row["error"] is None and row["render_seconds"]["median"] > 0 and row["mse"] > 0
        assert math.isfinite(row["efficiency"]) and 50 * 2**20 < row["peak_rss"]["median"] < 8 * 2**30
    reference = result["rows"][2]
    assert reference["rounds"][0]["triangles"] == 8000 and reference["bvh_seconds"]["median"] >= 0
    assert result["ratios"]["8000"]["efficiency"] > 0 and (tmp_path / "cache" / "terrains").is_dir()


@pytest.mark.parametrize("argv, option", [
    (["--scaling", "--triangles", "0"], "--triangles"),
    (["--scaling", "--triangles", "10G"], "--triangles"),
    (["--scaling", "--size", "0"], "--size"),
    (["--scaling", "--rounds", "0"], "--rounds"),
    (["--scaling", "--spp", "0"], "--spp"),
    (["--scaling", "--scene", "furnace"], "--scene"),
    (["--scaling", "--repeats", "2"], "--repeats"),
    (["--scaling", "--check"], "--check"),
    (["--scaling", "--size", "8192", "--spp", "100000000"], "--spp"),
    (["--triangles", "1k"], "--triangles"),
    (["--rounds", "2", "--scene", "furnace"], "--rounds"),
    (["--scaling", "--out", "no/such/folder/x.json"], "--out"),
])
def test_bad_options_exit_2_in_one_line(argv, option, capfd):
    code, out, err = _run(capfd, ["bench", *argv, "--quiet"])
    lines = err.splitlines()
    assert code == 2 and out == "" and len(lines) == 1, (code, out, err)
    assert lines[0].startswith(f"harness: error: {option}"), lines[0]


def test_the_docs_print_scale_commands():
    assert DOC_COMMANDS and any("--triangles 10k,100k,1M,10M" in c for c in DOC_COMMANDS)


@pytest.mark.slow
@pytest.mark.parametrize("command", DOC_COMMANDS)
def test_a_scale_command_of_the_docs_runs(command, tmp_path, monkeypatch, capfd):
    """Each ``harness bench --scaling`` line of docs/performance.md: as printed where it is already tiny, else (the
    command that made the table, an hour of two cores) with its sizes replaced by :data:`TINY`."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path / "cache"))
    argv = shlex.split(command, comments=True)[1:]
    for option, value in TINY.items():  # a no-op for a command printed at these sizes
        if option in argv:
            argv[argv.index(option) + 1] = value
        else:
            argv += [option, value]
    code, out, err = _run(capfd, argv)
    assert code == 0, (command, err)
    assert "triangles" in out or (tmp_path / "scale.json").is_file()
