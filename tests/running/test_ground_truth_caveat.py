"""A Mitsuba ground truth known not to be the scene's expected image says so (docs/mitsuba.md, "Known
differences"): a cut-out (mask) with a point, spot or directional light, whose light Mitsuba's path loses through
the holes. The case's record carries ``ground_truth_caveat``, harness run prints it as a warning and the report
shows it; a mask under area lights alone, or a point light without a mask, has none."""

from __future__ import annotations

import shutil

from conftest import SCENES

from harness.renderers.groundtruth import mitsuba_caveat
from harness.report.notes import case_notes
from harness.scene import load_scene

POINT = '\n[[emitters]]\ntype = "point"\nposition = [0.0, 1.0, 1.5]\nintensity = [1.0, 1.0, 1.0]\n'
SUN = '\n[[emitters]]\ntype = "directional"\ndirection = [0.0, 0.0, -1.0]\nirradiance = [1.0, 1.0, 1.0]\n'


def _scene(tmp_path, extra: str, name: str = "cutout-leaf"):
    text = (SCENES / f"{name}.toml").read_text() + extra
    if not (tmp_path / "textures").exists():  # copied: a scene's files are not followed through links
        shutil.copytree(SCENES / "textures", tmp_path / "textures")
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return load_scene(path)


def test_a_mask_under_a_delta_light_has_a_caveat(tmp_path):
    caveat = mitsuba_caveat(_scene(tmp_path, POINT + SUN))
    assert caveat is not None and "a directional light, a point light" in caveat and "leaf" in caveat
    assert "\n" not in caveat


def test_a_mask_under_area_lights_or_a_point_light_without_a_mask_has_none(tmp_path):
    assert mitsuba_caveat(load_scene(SCENES / "cutout-leaf.toml")) is None  # its light is a rectangle
    assert mitsuba_caveat(load_scene(SCENES / "point-spot.toml")) is None  # no mask


def test_the_report_shows_the_caveat():
    notes = case_notes({"ground_truth_caveat": "Mitsuba's path loses ..."})
    assert notes == ["Ground truth not the expected image: Mitsuba's path loses ..."]
    assert case_notes({}) == []
