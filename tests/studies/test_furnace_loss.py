"""The rough conductor's energy loss by roughness (harness/studies/furnace_loss.py): the furnace with alpha and the
distribution replaced; reference and Mitsuba agree within the z-score of a 1e-4 two-sided false alarm (3.9); a
lossless limit keeps everything; bad input is one line and exit 2."""

from __future__ import annotations

import dataclasses

import pytest
from conftest import SCENES

from harness.scene import load_scene
from harness.studies.furnace_loss import energy_loss_table, format_table, main, with_roughness
from reference_impl import Film


def small():
    scene = load_scene(SCENES / "white-furnace-rough.toml")
    return dataclasses.replace(scene, film=Film(8, 8, "box"))


def test_with_roughness_changes_only_alpha_and_distribution():
    scene = with_roughness(small(), 0.3, "beckmann")
    (material,) = scene.materials.values()
    assert (material.alpha, material.distribution, material.type) == (0.3, "beckmann", "roughconductor")


@pytest.mark.slow
def test_reference_and_mitsuba_lose_the_same_energy():
    rows = energy_loss_table(small(), alphas=(1.0,), distributions=("ggx",), spp=64, mitsuba_variant="scalar_rgb")
    (row,) = rows
    assert 0.2 < row["reference"] < 0.5 and abs(row["z"]) < 3.9, row
    assert "| ggx | 1 |" in format_table(rows)


@pytest.mark.parametrize("argv, fragment", [
    (["--scene", str(SCENES / "cornell-box.toml")], "expected a white furnace"),
    (["--scene", str(SCENES / "white-furnace.toml")], "one rough material"),
    (["--alphas", "0.1,x"], "--alphas: expected comma-separated numbers"),
    (["--alphas", "2"], "--alphas: expected roughnesses in (0, 1]"),
    (["--distributions", "phong"], "--distributions: expected ggx or beckmann, got 'phong'"),
    (["--spp", "0"], "--spp: expected a positive integer"),
    (["--sizee", "4"], "--sizee: unknown option of python -m harness.studies.furnace_loss; did you mean '--size'?"),
])
def test_bad_input_is_one_line(capsys, argv, fragment):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and fragment in captured.err, captured.err
