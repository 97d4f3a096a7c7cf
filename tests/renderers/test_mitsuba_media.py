"""Participating media in Mitsuba 3.9.1 (``volpath``), from the harness's spec alone: the spec of a media scene loads
in ``scalar_rgb`` and renders the closed form of scenes/media-slab.toml, the XML export loads back in Mitsuba as the
same scene, and the fog box's camera medium reaches Mitsuba.

The slab: every camera ray through it crosses thickness d = 1 of a medium with sigma_t = 1 and albedo 0 in front of
a constant environment L = 1, so its pixels are L exp(-sigma_t d) = exp(-1) (Beer-Lambert; PBRT 4th ed., 11.2).
Mitsuba's volpath estimates the transmittance by free-flight sampling (a distance t with density sigma_t
exp(-sigma_t t); the path goes on where t > d, else it meets the medium, whose albedo 0 ends it), so each sample is
1 with probability exp(-1) and 0 otherwise: the mean of the slab's N samples has the binomial standard deviation
sqrt(p (1 - p) / N), and the test allows 5 of them. The environment's pixels are 1 exactly.
"""

from __future__ import annotations

import math
import shlex

import numpy as np
import pytest

from conftest import ROOT, SCENES
from harness.cli import main
from harness.files.imageio import read_exr
from test_new_user import shell_blocks
from harness.renderers.export import export_scene
from harness.renderers.mitsuba import import_mitsuba, load_dict_form
from harness.renderers.mitsuba_spec import scene_spec
from harness.scene import load_scene

SPP = 256


@pytest.fixture(scope="module")
def mi():
    return import_mitsuba("scalar_rgb")


def slab_pixels(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The slab's 16 x 16 pixels in the middle of the 32 x 32 film, and the others."""
    inside = np.zeros(image.shape[:2], dtype=bool)
    inside[8:24, 8:24] = True
    return image[inside], image[~inside]


def test_the_slab_renders_beer_lambert_in_mitsuba(mi):
    scene = load_scene(SCENES / "media-slab.toml")
    spec = scene_spec(scene, spp=SPP)
    assert spec.plugins["integrator"]["type"] == "volpath"
    image = np.asarray(mi.render(mi.load_dict(load_dict_form(mi, spec)), seed=1), dtype=np.float64)
    slab, environment = slab_pixels(image)
    expected = math.exp(-1.0)
    n = slab.shape[0] * SPP
    sigma = math.sqrt(expected * (1 - expected) / n)
    assert abs(slab.mean() - expected) < 5 * sigma, (slab.mean(), expected, sigma)
    assert np.all(slab[:, 0] == slab[:, 1]) and np.all(slab[:, 1] == slab[:, 2])  # one medium for all channels
    np.testing.assert_array_equal(environment, 1.0)


def test_the_xml_export_loads_back_as_the_same_scene(mi, tmp_path):
    """``harness export --format mitsuba-xml`` of the slab renders in Mitsuba as the spec does (same seed, same
    samples)."""
    scene = load_scene(SCENES / "media-slab.toml")
    export_scene(scene, "mitsuba-xml", tmp_path / "slab", spp=16)
    text = (tmp_path / "slab" / "scene.xml").read_text()
    assert '<integrator type="volpath">' in text and '<bsdf type="null" id="bsdf_0">' in text
    assert '<ref name="interior" id="medium_0"/>' in text and '<medium type="homogeneous" id="medium_0">' in text
    from_xml = np.asarray(mi.render(mi.load_file(str(tmp_path / "slab" / "scene.xml")), seed=3))
    from_dict = np.asarray(mi.render(mi.load_dict(load_dict_form(mi, scene_spec(scene, spp=16))), seed=3))
    np.testing.assert_array_equal(from_xml, from_dict)


def test_the_camera_medium_reaches_mitsuba(mi, tmp_path):
    """The fog box (a small film): the sensor's medium is the fog, from the dict and from the XML alike, and the
    fog darkens the box against the same scene without it (transmittance about 0.4 to the back wall)."""
    fog = load_scene(SCENES / "fog-box.toml")
    spec = scene_spec(fog, spp=8)
    spec.plugins["sensor"]["film"].update(width=16, height=16)
    assert spec.plugins["sensor"]["medium"] == {"type": "ref", "id": "medium_0"}
    fogged = np.asarray(mi.render(mi.load_dict(load_dict_form(mi, spec)), seed=1))
    del spec.plugins["sensor"]["medium"]
    clear = np.asarray(mi.render(mi.load_dict(load_dict_form(mi, spec)), seed=1))
    ratio = fogged[6:10, 6:10].mean() / clear[6:10, 6:10].mean()
    assert 0.4 < ratio < 0.9, ratio  # attenuated, partly made up by the light the fog scatters in
    export_scene(fog, "mitsuba-xml", tmp_path / "fog", spp=1)
    assert '<ref name="medium" id="medium_0"/>' in (tmp_path / "fog" / "scene.xml").read_text()
    from_xml = np.asarray(mi.render(mi.load_file(str(tmp_path / "fog" / "scene.xml")), seed=2))
    from_dict = np.asarray(mi.render(mi.load_dict(load_dict_form(mi, scene_spec(fog, spp=1))), seed=2))
    # the same paths: the XML's decimal numbers differ from the dict's float64 in their last bits only
    np.testing.assert_allclose(from_xml, from_dict, rtol=5e-3, atol=1e-5)


DOC_COMMANDS = [command for block in shell_blocks((ROOT / "docs" / "mitsuba.md").read_text(encoding="utf-8"))
                for command in block if command.startswith("harness ground-truth media-slab")]


def test_the_docs_print_the_slab_command():
    assert DOC_COMMANDS == ["harness ground-truth media-slab --no-closed-form --spp 1024 --out slab.exr"]


@pytest.mark.slow  # Mitsuba's llvm variant
@pytest.mark.parametrize("command", DOC_COMMANDS)
def test_the_slab_command_of_the_docs_gives_its_figures(command, tmp_path, monkeypatch, capfd):
    """docs/mitsuba.md's measurement, run as printed: the slab's mean 0.369129 (1.3 binomial standard deviations
    from exp(-1)), the environment exactly 1."""
    monkeypatch.chdir(tmp_path)
    assert main(shlex.split(command)[1:]) == 0, capfd.readouterr().err
    slab, environment = slab_pixels(read_exr(tmp_path / "slab.exr").image.astype(np.float64))
    assert slab.mean() == pytest.approx(0.369129, abs=1e-6)
    assert abs(slab.mean() - math.exp(-1.0)) < 5 * math.sqrt(math.exp(-1) * (1 - math.exp(-1)) / (256 * 1024))
    np.testing.assert_array_equal(environment, 1.0)


def test_the_second_estimator_is_volpathmis_and_a_wrong_name_is_one_line(capfd, tmp_path):
    """``--set integrator=volpathmis`` swaps the scene's integrator for Mitsuba's spectral-MIS volumetric path tracer
    (docs/mitsuba.md, "volpathmis"), and it renders the absorbing slab like volpath (its environment pixels exactly 1,
    the slab's near exp(-1)); a name that is none of INTEGRATORS is one line naming the setting, exit 2."""
    from harness.renderers import RenderRequest, get_renderer
    from harness.renderers.mitsuba import INTEGRATORS, parse_settings

    scene = load_scene(SCENES / "media-slab.toml")
    assert parse_settings(scene, {"integrator": "volpathmis"}).integrator == "volpathmis" and "volpathmis" in INTEGRATORS
    out = get_renderer("mitsuba").render(scene, RenderRequest(spp=64, seed=1, settings={
        "integrator": "volpathmis", "variant": "scalar_rgb"}))
    slab, environment = slab_pixels(out.image.astype(np.float64))
    np.testing.assert_array_equal(environment, 1.0)
    assert abs(slab.mean() - math.exp(-1.0)) < 5 * math.sqrt(math.exp(-1) * (1 - math.exp(-1)) / slab.size / 64)
    code = main(["render", str(SCENES / "media-slab.toml"), "--renderer", "mitsuba", "--spp", "1",
                 "--set", "integrator=volpathmiss", "--out", str(tmp_path / "x.exr")])
    err = capfd.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--set integrator: expected one of path, volpath, volpathmis" in err
