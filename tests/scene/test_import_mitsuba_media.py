"""``harness import`` of Mitsuba 3 XML with participating media (issue 38; docs/import.md): a ``homogeneous`` medium
with its ``isotropic`` or ``hg`` phase, a shape's ``interior`` / ``exterior``, the sensor's ``medium`` and the
``null`` BSDF come back as the scene format's keys; ``heterogeneous`` is refused in one line naming the element.
A media scene exported as XML and imported back holds the same media (the content key of its media, named alike)."""

from __future__ import annotations

import dataclasses

import pytest

from conftest import MINIMAL_SCENE
from harness.cli import main
from harness.core.errors import HarnessError
from harness.renderers.export import export_scene
from harness.renderers.importers import import_scene
from harness.renderers.imports import write_imported
from harness.scene import load_scene, media_arrays
from harness.scene.content_key import content_key

pytest.importorskip("mitsuba")

SCENE = MINIMAL_SCENE.replace("fov = 40\n", 'fov = 40\nmedium = "air"\n') + """
[materials.boundary]
type = "null"

[media.air]
sigma_t = [0.01, 0.02, 0.03]
albedo = 0.9

[media.smoke]
sigma_t = [1.0, 0.5, 0.25]
albedo = [0.9, 0.8, 0.7]
scale = 2.0
phase = { type = "hg", g = -0.3 }

[[shapes]]
name = "box"
type = "cube"
material = "boundary"
interior = "smoke"
exterior = "air"

[[shapes]]
name = "floor"
type = "rectangle"
material = "white"
translate = [0, -1, 0]
"""

HETEROGENEOUS = """<scene version="3.0.0">
    <medium type="heterogeneous" id="smoke">
        <volume name="sigma_t" type="constvolume">
            <float name="value" value="1.0"/>
        </volume>
    </medium>
</scene>
"""


def renamed(scene):
    """The scene's media and transitions as the content key sees them, with the import's names for them."""
    names = dict(zip(scene.media, ("medium_0", "medium_1")))
    media = {names[n]: dataclasses.replace(m, name=names[n]) for n, m in scene.media.items()}
    sides = [(names.get(s.interior), names.get(s.exterior)) for s in scene.shapes]
    return media, names.get(scene.camera_medium), sides


def test_a_media_scene_round_trips(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    original = load_scene(path)
    export_scene(original, "mitsuba-xml", tmp_path / "xml")
    imported = import_scene(tmp_path / "xml" / "scene.xml")
    assert imported.dropped == []
    back = load_scene(write_imported(imported, tmp_path / "imported"))
    assert list(back.media) == ["medium_0", "medium_1"] and back.camera_medium == "medium_0"
    assert back.materials["bsdf_1"].type == "null"
    assert content_key(renamed(original)) == content_key((back.media, back.camera_medium,
                                                          [(s.interior, s.exterior) for s in back.shapes]))
    a, b = media_arrays(original), media_arrays(back)
    for field in ("sigma_t", "albedo", "phase", "g", "interior", "exterior", "transition"):
        assert (getattr(a, field) == getattr(b, field)).all(), field
    assert a.camera == b.camera == 0


def test_heterogeneous_is_refused_in_one_line(tmp_path):
    path = tmp_path / "smoke.xml"
    path.write_text(HETEROGENEOUS)
    with pytest.raises(HarnessError) as info:
        import_scene(path)
    assert str(info.value) == (f"{path}:2:6: <medium type='heterogeneous' id='smoke'>: expected a homogeneous "
                               "medium: heterogeneous media are not supported yet")


def test_heterogeneous_through_the_cli(tmp_path, capfd):
    path = tmp_path / "smoke.xml"
    path.write_text(HETEROGENEOUS)
    code = main(["import", str(path), "--out", str(tmp_path / "out")])
    out, err = capfd.readouterr()
    assert code == 2 and out == "" and len(err.splitlines()) == 1, (code, out, err)
    assert "<medium type='heterogeneous' id='smoke'>" in err and "not supported yet" in err
    assert not (tmp_path / "out").exists()


def test_an_unknown_phase_is_refused(tmp_path):
    path = tmp_path / "rayleigh.xml"
    path.write_text('<scene version="3.0.0">\n<medium type="homogeneous" id="m">\n'
                    '<phase type="rayleigh"/>\n</medium>\n</scene>\n')
    with pytest.raises(HarnessError, match=r"<phase type='rayleigh'>: expected a phase function of type isotropic, "
                                           r"hg"):
        import_scene(path)
