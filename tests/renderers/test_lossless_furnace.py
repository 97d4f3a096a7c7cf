"""The lossless furnace's closed form (harness/renderers/groundtruth.py, ``closed_form = "lossless-furnace"``): a
perfect mirror or a smooth dielectric (every specular_* = 1) under a constant environment L, paths unbounded, is L
in every pixel whatever the geometry; other scenes are refused on one line naming ``closed_form``; Mitsuba agrees
with it by the verdict on both scenes.

False alarms: each Mitsuba verdict runs at ALPHA = 1e-4; the mirror's every sample is exactly L (no variance at
all), the glass's paths are random (Fresnel's choice of reflection or refraction, Mitsuba's roulette after depth 5)
but every one carries exactly L, so both images are L to rounding and the verdict's zero-variance rule applies.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import SCENES
from test_hostile_input import assert_one_line, cli

from harness.core.errors import HarnessError
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.groundtruth import closed_form, ground_truth
from harness.renderers.mitsuba import MitsubaRenderer
from harness.scene import load_scene
from reference_impl import Film

L = np.array([0.5, 1.0, 2.0])
SCENES_LOSSLESS = ("white-furnace-mirror", "white-furnace-glass")


def furnace(name: str, size: int | None = None, **overrides):
    scene = load_scene(SCENES / f"{name}.toml")
    if size is not None:
        scene = dataclasses.replace(scene, film=Film(size, size, "box"))
    return dataclasses.replace(scene, **overrides)


@pytest.mark.parametrize("name", SCENES_LOSSLESS)
def test_every_pixel_is_the_environment(name, monkeypatch, tmp_path):
    monkeypatch.setattr(MitsubaRenderer, "render", lambda *a: pytest.fail("the closed form must not render"))
    result = ground_truth(furnace(name), cache_dir=tmp_path / "cache")
    assert result.source == "closed-form" and result.renders == 0
    assert result.image.shape == (64, 64, 3) and np.all(result.image == result.image[0, 0])
    np.testing.assert_array_equal(result.image[0, 0], L.astype(np.float32))
    assert not np.any(result.variance)


def test_bounded_paths_are_refused():
    with pytest.raises(HarnessError, match="closed_form.*max_depth = -1"):
        closed_form(furnace("white-furnace-mirror", max_depth=8))


def test_a_lossy_material_is_refused(tmp_path):
    text = (SCENES / "white-furnace-glass.toml").read_text().replace("ext_ior = 1.0\n",
                                                                     "ext_ior = 1.0\nspecular_transmittance = 0.9\n")
    path = tmp_path / "glass.toml"
    path.write_text(text)
    with pytest.raises(HarnessError, match="closed_form.*lossless and specular.*'ball' is dielectric"):
        closed_form(load_scene(path))
    rough = load_scene(SCENES / "white-furnace-rough.toml")
    with pytest.raises(HarnessError, match="closed_form.*'ball' is roughconductor"):
        closed_form(dataclasses.replace(rough, closed_form="lossless-furnace"))


def test_a_scene_without_its_constant_environment_is_refused(tmp_path, capfd):
    text = (SCENES / "white-furnace-mirror.toml").read_text().replace('type = "constant"', 'type = "directional"\ndirection = [0, 0, -1]\nirradiance = [1, 1, 1]').replace("radiance = [0.5, 1.0, 2.0]\n", "")
    path = tmp_path / "m.toml"
    path.write_text(text)
    assert_one_line(*cli(capfd, "ground-truth", path, "--cache-dir", tmp_path / "c"), f"{path}: closed_form",
                    "a constant environment; this scene has directional")
    assert not (tmp_path / "c").exists()


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES_LOSSLESS)
def test_mitsuba_agrees(name):
    scene = furnace(name, size=16)
    out = get_renderer("mitsuba").render(scene, RenderRequest(spp=16, seed=3, settings={"variant": "scalar_rgb"}))
    # Lossless: every Mitsuba sample carries exactly L, up to float32 rounding of the path's weights.
    np.testing.assert_allclose(out.image, np.broadcast_to(L, out.image.shape), rtol=2e-5)
