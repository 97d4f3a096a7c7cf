"""The white furnace's closed form (harness/renderers/groundtruth.py, ``closed_form = "white-furnace"``): a diffuse
sphere of albedo rho under a constant environment L, covering every pixel's filter footprint, is rho * L everywhere
(max_depth >= 2 or -1) and 0 at max_depth = 1; scenes whose geometry differs are refused on one line; Mitsuba agrees
with it by the verdict, and the same verdict catches a closed form 1 % off.

False alarms: each verdict here runs at ALPHA = 1e-4 (the family-wise false-alarm probability of harness.judges.verdict,
with the variances' spp - 1 degrees of freedom), so the two tests that must pass fail a correct Mitsuba with
probability at most 2e-4 together. Power: Mitsuba's per-sample relative standard deviation on this sphere is 0.253
(measured: 0.2530 at 16 x 16 / 1024 spp, scalar_rgb; 0.2535 at 64 x 64 / 4096 spp, llvm_ad_rgb), so a 1 % error over
N = 16 x 16 pixels at n = SPP samples has a global-bias z of 0.01 sqrt(N n) / 0.253 = 10.1 (+- 1), against the
sub-test's critical |z| of 4.39 (alpha / 3, Sidak over 3 channels): the global-bias sub-test alone misses it with
probability Phi(4.39 - 10.1) = 6e-9.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import norm
from conftest import SCENES
from test_hostile_input import assert_one_line, cli

from harness.core.errors import HarnessError
from harness.judges.verdict import verdict
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.groundtruth import closed_form, ground_truth, sphere_coverage_problem
from harness.renderers.mitsuba import MitsubaRenderer
from harness.scene import load_scene
from reference_impl import Film

VARIANT = "scalar_rgb"
ALPHA = 1e-4
SPP = 256
# The global-bias sub-test's critical |z|: level ALPHA / 3, Sidak over 3 channels, two-sided (4.39)
GLOBAL_CRITICAL_Z = float(norm.isf((1 - (1 - ALPHA / 3) ** (1 / 3)) / 2))
L = np.array([0.5, 1.0, 2.0])
SCENE_RHO = {"white-furnace": 0.8, "white-furnace-albedo-1": 1.0}


def furnace(name: str = "white-furnace", size: int | None = None, filter_: str = "box", **overrides):
    scene = load_scene(SCENES / f"{name}.toml")
    if size is not None:
        scene = dataclasses.replace(scene, film=Film(size, size, filter_))
    return dataclasses.replace(scene, **overrides)


def with_file(tmp_path, edit, name: str = "white-furnace"):
    """The scene file with ``edit(text)`` applied, loaded."""
    path = tmp_path / f"{name}.toml"
    path.write_text(edit((SCENES / f"{name}.toml").read_text()))
    return load_scene(path)


# --------------------------------------------------------------------------------------------------------------------
# The closed form


@pytest.mark.parametrize("name", sorted(SCENE_RHO))
@pytest.mark.parametrize("max_depth", [1, 2, 5, -1])
def test_white_furnace_closed_form(name, max_depth, monkeypatch, tmp_path):
    monkeypatch.setattr(MitsubaRenderer, "render", lambda *a: pytest.fail("the closed form must not render"))
    scene = furnace(name, max_depth=max_depth)
    result = ground_truth(scene, cache_dir=tmp_path / "cache")
    expected = np.zeros(3) if max_depth == 1 else SCENE_RHO[name] * L
    assert result.source == "closed-form" and result.renders == 0 and result.spp == 0
    assert result.image.shape == (64, 64, 3) and np.all(result.image == result.image[0, 0])
    np.testing.assert_allclose(result.image[0, 0], expected, rtol=1e-7)
    assert not np.any(result.variance)
    assert result.info == {"closed_form": "white-furnace", "radiance": pytest.approx(list(expected))}
    assert not (tmp_path / "cache").exists()


GLOSSY_BALLS = {
    # [materials.grey] replaced by -> (max_depth, the closed form's pixel as a multiple of L)
    "mirror": ('type = "conductor"', [(-1, 1.0), (2, 1.0), (1, 0.0)]),
    "tinted-mirror": ('type = "conductor"\nmaterial = "none"\nspecular_reflectance = [0.5, 0.25, 1]',
                      [(-1, np.array([0.5, 0.25, 1.0])), (3, np.array([0.5, 0.25, 1.0]))]),
    "glass": ('type = "dielectric"', [(-1, 1.0)]),
    "water": ('type = "dielectric"\nint_ior = 1.33\next_ior = 1', [(-1, 1.0)]),
}


def glossy_ball(tmp_path, body: str):
    return with_file(tmp_path, lambda t: t.replace("reflectance = [0.8, 0.8, 0.8]", body))


@pytest.mark.parametrize("case", sorted(GLOSSY_BALLS))
def test_white_furnace_of_a_mirror_and_of_glass(case, tmp_path):
    body, expectations = GLOSSY_BALLS[case]
    scene = glossy_ball(tmp_path, body)
    for max_depth, factor in expectations:
        result = closed_form(dataclasses.replace(scene, max_depth=max_depth))
        np.testing.assert_allclose(result.image, np.broadcast_to(factor * L, result.image.shape), rtol=1e-7)


GLOSSY_REFUSED = {
    "glass-bounded": ('type = "dielectric"', 5, "a smooth one (type dielectric) with specular_reflectance"),
    "tinted-glass": ('type = "dielectric"\nspecular_transmittance = 0.5', -1, "at max_depth = -1"),
    "rough-glass": ('type = "roughdielectric"', -1, "this scene has a roughdielectric at max_depth = -1"),
    "copper": ('type = "conductor"\neta = [0.2, 0.9, 1.1]\nk = [3.9, 2.4, 2.1]', -1,
               "this scene has a conductor with eta / k (Fresnel < 1)"),
    "rough-mirror": ('type = "roughconductor"', -1, "needs a perfect mirror"),
    "plastic": ('type = "plastic"', -1, "the white-furnace closed form has no plastic sphere"),
    "roughplastic": ('type = "roughplastic"', -1, "the white-furnace closed form has no roughplastic sphere"),
    "principled": ('type = "principled"', -1, "the white-furnace closed form has no principled sphere"),
    "tinted-thin-glass": ('type = "thindielectric"\nspecular_reflectance = 0.5', -1,
                          "this scene has a thindielectric at max_depth = -1"),
}


@pytest.mark.parametrize("case", sorted(GLOSSY_REFUSED))
def test_white_furnace_refuses_glossy_balls_without_a_closed_form(case, tmp_path):
    body, max_depth, fragment = GLOSSY_REFUSED[case]
    scene = dataclasses.replace(glossy_ball(tmp_path, body), max_depth=max_depth)
    with pytest.raises(HarnessError) as info:
        closed_form(scene)
    assert info.value.where == f"{scene.path}: closed_form"
    assert fragment in info.value.message and "\n" not in str(info.value), info.value.message


def test_the_furnace_closed_form_refuses_glossy_materials(tmp_path):
    path = tmp_path / "furnace.toml"
    path.write_text((SCENES / "furnace.toml").read_text().replace("reflectance = [", 'type = "conductor"\n#['))
    with pytest.raises(HarnessError, match="holds for diffuse materials alone; this scene also has conductor"):
        closed_form(load_scene(path))


@pytest.mark.parametrize("filter_", ["box", "tent", "gaussian"])
def test_the_canonical_framing_covers_every_filter_footprint(filter_):
    assert sphere_coverage_problem(furnace(filter_=filter_, size=64)) is None
    assert sphere_coverage_problem(furnace(filter_=filter_, size=32)) is None  # the smoke suite's film
    # the filter's reach is in pixels, so the fewer the pixels the wider the footprint; the box reaches none
    assert (sphere_coverage_problem(furnace(filter_=filter_, size=1)) is None) == (filter_ == "box")


REFUSED = {
    # edit of the scene file -> a fragment of the one-line refusal
    "no-environment": (lambda t: t.split("[[emitters]]")[0], "has none"),
    "point-too": (lambda t: t + '\n[[emitters]]\ntype = "point"\nposition = [0, 2, 0]\nintensity = [1, 1, 1]\n',
                   "has constant, point"),
    "second-shape": (lambda t: t + '\n[[shapes]]\ntype = "sphere"\nmaterial = "grey"\nradius = 0.1\n'
                                   'center = [0, 0, 1.5]\n', "has sphere, sphere"),
    "emitting-sphere": (lambda t: t.replace('material = "grey"\n', 'material = "grey"\nemission = [1, 1, 1]\n'),
                        "has sphere (emitting)"),
    "cube": (lambda t: t.replace('type = "sphere"\ncenter = [0.0, 0.0, 0.0]\nradius = 1.0\nsubdivisions = 4\n',
                                 'type = "cube"\n'), "has cube"),
    "fov-too-wide": (lambda t: t.replace("fov = 24.0", "fov = 29.0"), "20.09 degrees"),
    "sphere-off-centre": (lambda t: t.replace("center = [0.0, 0.0, 0.0]", "center = [0.3, 0.0, 0.0]"),
                          "angular radius"),
    "placed-off-centre": (lambda t: t.replace('material = "grey"\n', 'material = "grey"\ntranslate = [0, -0.3, 0]\n'),
                          "angular radius"),
    "camera-inside": (lambda t: t.replace("origin = [0.0, 0.0, 3.0]", "origin = [0.0, 0.0, 0.5]"),
                      "the camera is inside the sphere"),
    # the analytic sphere would cover the film, the reference's icosahedron (inscribed radius 0.795) does not
    "coarse-icosphere": (lambda t: t.replace("subdivisions = 4", "subdivisions = 0"), "angular radius 15.36"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_white_furnace_refuses_other_geometry(case, tmp_path, monkeypatch):
    monkeypatch.setattr(MitsubaRenderer, "render", lambda *a: pytest.fail("must not render"))
    edit, fragment = REFUSED[case]
    scene = with_file(tmp_path, edit)
    with pytest.raises(HarnessError) as info:
        ground_truth(scene, cache_dir=tmp_path / "cache")
    assert info.value.where == f"{scene.path}: closed_form"
    assert "white-furnace closed form" in info.value.message and fragment in info.value.message, info.value.message
    assert "\n" not in str(info.value)


def test_the_filter_reach_counts(tmp_path):
    """At 8 x 8 with fov 22.6 the film's own corners are inside the sphere (box), but the Gaussian filter's
    footprint reaches 1.5 pixels past them, outside (tan 0.2 x 5.5 / 4 x sqrt 2 > tan 19.45 deg)."""
    scene = furnace(size=8, camera=dataclasses.replace(furnace().camera, fov=22.6))
    assert sphere_coverage_problem(scene) is None
    gaussian = dataclasses.replace(scene, film=Film(8, 8, "gaussian"))
    assert "with the gaussian filter's reach" in sphere_coverage_problem(gaussian)
    with pytest.raises(HarnessError, match="cover every pixel's filter footprint"):
        closed_form(gaussian)


def test_the_furnace_closed_form_still_refuses_emitters():
    with pytest.raises(HarnessError, match="the furnace closed form holds for emitting shapes alone"):
        closed_form(furnace(closed_form="furnace"))


def test_ground_truth_cli_refuses_on_one_line(tmp_path, capfd):
    edit, _ = REFUSED["fov-too-wide"]
    path = tmp_path / "wide.toml"
    path.write_text(edit((SCENES / "white-furnace.toml").read_text()))
    assert_one_line(*cli(capfd, "ground-truth", path, "--cache-dir", tmp_path / "cache"), f"{path}: closed_form",
                    "white-furnace closed form needs the sphere to cover")
    assert not (tmp_path / "cache").exists()


# --------------------------------------------------------------------------------------------------------------------
# Mitsuba against it


def mitsuba(scene, spp: int, seed: int):
    return get_renderer("mitsuba").render(scene, RenderRequest(spp=spp, seed=seed, settings={"variant": VARIANT}))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SCENE_RHO))
def test_mitsuba_matches_the_closed_form_and_the_verdict_catches_one_percent(name):
    scene = furnace(name, size=16)
    result = mitsuba(scene, SPP, seed=11 + sorted(SCENE_RHO).index(name))
    expected = closed_form(scene)
    good = verdict(result.image, result.variance, expected.image, expected.variance, alpha=ALPHA, test_dof=SPP - 1)
    planted = verdict(result.image, result.variance, expected.image * 0.99, expected.variance, alpha=ALPHA,
                      test_dof=SPP - 1)
    print(f"{name}: right closed form {good.verdict} (global z {np.round(good.global_bias['z'], 2)}; {good.reason}); "
          f"0.99 x it {planted.verdict} (global z {np.round(planted.global_bias['z'], 2)})")
    assert good.passed, good.reason
    assert not planted.passed and min(planted.global_bias["z"]) > GLOBAL_CRITICAL_Z, planted.reason


@pytest.mark.slow
def test_mitsuba_at_max_depth_1_is_black():
    """Camera rays only: the sphere does not emit, and it hides the environment from every pixel."""
    scene = furnace(size=16, max_depth=1)
    result = mitsuba(scene, 4, seed=12)
    expected = closed_form(scene)
    assert not np.any(expected.image) and not np.any(result.image) and not np.any(result.variance)
    assert verdict(result.image, result.variance, expected.image, expected.variance, alpha=ALPHA).passed


def test_scene_files_say_what_the_closed_form_gives():
    for name, rho in SCENE_RHO.items():
        text = (SCENES / f"{name}.toml").read_text()
        values = ", ".join(f"{v:.1f}" for v in rho * L)
        assert f"[{values}]" in text, name
        assert f"reflectance = [{rho:.1f}, {rho:.1f}, {rho:.1f}]" in text
