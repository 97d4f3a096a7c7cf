"""The white furnace of each material beside Mitsuba (harness/studies/material_furnace.py): the furnace scene with its
sphere's material replaced by a row's tables; a lossless material keeps L; reference and Mitsuba agree within the
z-score of a 1e-4 two-sided false alarm (3.9); bad input is one line and exit 2."""

from __future__ import annotations

import pytest

from harness.studies.material_furnace import ROWS, format_table, furnace_with, main, material_table


def test_every_row_loads_with_its_material_on_the_sphere(tmp_path):
    for name, tables in ROWS:
        scene = furnace_with(tables, tmp_path, 8)
        assert scene.shapes[0].material == "ball" and (scene.film.width, scene.film.height) == (8, 8), name


@pytest.mark.slow
def test_reference_and_mitsuba_keep_the_same_energy():
    rows = [r for r in ROWS if r[0] in ("mask 0.5 of a twosided diffuse", "roughplastic ggx alpha 0.3",
                                        "principled metallic 1 roughness 0.9")]
    table = material_table(rows, spp=32, size=8, mitsuba_variant="scalar_rgb")
    by_name = {r["material"]: r for r in table}
    mask = by_name["mask 0.5 of a twosided diffuse"]  # lossless: L in expectation (its holes are chosen at random)
    assert abs(mask["reference"] - 1.0) < 5 * mask["reference_se"], mask
    assert all(abs(r["z"]) < 3.9 for r in table), table
    assert by_name["principled metallic 1 roughness 0.9"]["reference"] < 0.95  # single scattering loses energy
    assert "| roughplastic ggx alpha 0.3 |" in format_table(table)


@pytest.mark.parametrize("argv, fragment", [
    (["--rows", "velvet*"], "--rows: expected a glob matching a row"),
    (["--spp", "0"], "--spp: expected a positive integer"),
    (["--sise", "4"], "--sise: unknown option of python -m harness.studies.material_furnace; did you mean '--size'?"),
])
def test_bad_input_is_one_line(capsys, argv, fragment):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and fragment in captured.err, captured.err
