"""The path loop (reference_impl/kernels/path.py) on scenes with materials that are not Lambertian, and its BSDF
strategies (``direct = bsdf``, ``rr = throughput``, MIS against the BSDF's pdf) on Lambertian ones.

Closed forms first (a perfect mirror ball and a smooth glass ball in a constant environment: every pixel is exactly
L at max_depth = -1, for every direct strategy), then the strategies against each other in expectation (the
harness's verdict at a false-alarm probability ALPHA per test, both renders' variances added; ``sampler =
independent``, whose reported variance is exact), determinism, and the planted fault "mis-weights-not-one" caught.
Scenes are built in memory (tests/reference_impl/emitter_scenes.py) and their material tables as arrays.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from emitter_scenes import constant, sphere_scene, with_emitters

import reference_impl
from harness.judges.mc import FALSE_ALARM
from harness.judges.verdict import verdict
from harness.renderers import RenderRequest
from harness.renderers.reference import ReferenceRenderer
from harness.scene import emitter_arrays, triangulate
from harness.scene.model import Material, Scene, Shape
from harness.scene.triangulate import rotate_matrix, scale_matrix, translate_matrix
from harness.studies import strategies
from reference_impl import Camera, Film, Materials, Settings
from reference_impl.errors import SettingsError
from reference_impl.materials import CONDUCTOR, DIELECTRIC, ROUGHCONDUCTOR, ROUGHDIELECTRIC, is_glossy, material_row

ALPHA = FALSE_ALARM  # 1e-4 per verdict
SKY = (1.0, 0.5, 0.25)
CU_ETA, CU_K = (0.2004, 0.9240, 1.1022), (3.9129, 2.4528, 2.1421)  # Mitsuba 3's "Cu"


def _table(geometry, rows: dict[int, tuple[int, dict]]) -> Materials:
    """The geometry's Lambertian table with rows replaced: {material index: (kind, {column: value})}."""
    base = Materials.diffuse(geometry.reflectance, geometry.two_sided)
    kind, params = base.kind.copy(), base.params.copy()
    for m, (k, values) in rows.items():
        kind[m] = k
        params[m, :] = 0.0
        params[m, 0:3] = 1.0  # specular_reflectance
        params[m, 9:12] = 1.0  # specular_transmittance
        for column, value in values.items():
            params[m, column] = value
    return Materials(kind, params)


MIRROR = (CONDUCTOR, {17: 1.0})
GLASS = (DIELECTRIC, {15: 1.5046 / 1.000277})


def _render(scene: Scene, materials_rows=None, spp=4, **settings):
    geometry = triangulate(scene)
    materials = _table(geometry, materials_rows) if materials_rows is not None else None
    s = Settings(spp=spp, max_depth=settings.pop("max_depth", scene.max_depth), threads=settings.pop("threads", 1),
                 **settings)
    return reference_impl.render(geometry, scene.camera, scene.film, s, emitters=emitter_arrays(scene),
                                 materials=materials)


def _verdict(a, b, label):
    v = verdict(a.image, a.variance, b.image, b.variance, alpha=ALPHA, tile=4)
    print(f"{label}: verdict {v.verdict}: global z {np.round(v.global_bias['z'], 2)}, max |z| "
          f"{v.max_z['statistic']:.3g}, omnibus p {v.omnibus['p_value']:.3g}; mean ratio "
          f"{float(a.image.mean() / b.image.mean()):.4f}")
    return v


# ------------------------------------------------------------------------------------------------ closed forms


@pytest.mark.parametrize("direct", ["auto", "area", "bsdf", "mis"])
@pytest.mark.parametrize("name, rows", [("mirror", MIRROR), ("glass", GLASS)])
def test_a_mirror_and_a_glass_ball_in_a_constant_environment_show_exactly_L(name, rows, direct):
    """Energy is conserved by a perfect mirror (Fresnel 1) and by a smooth dielectric (R + T = 1, the eta^2 of the
    way in undone on the way out): every pixel, ball or sky, is L, whatever the strategy, to float32 rounding."""
    scene = with_emitters(sphere_scene(size=8, max_depth=-1), constant(SKY))
    out = _render(scene, {0: rows}, spp=4, direct=direct)
    error = float(np.max(np.abs(out.image / np.array(SKY, np.float32) - 1)))
    print(f"{name}, direct={direct} (resolved {out.settings.direct}): max relative error {error:.2e}, "
          f"{out.stats['indirect_rays']} BSDF rays")
    assert out.settings.direct == ("mis" if direct == "auto" else direct)
    assert error < 1e-6
    assert out.stats["indirect_rays"] >= 8 * 8 * 4 * 0.5  # the ball is hit: the test is not of the sky alone


# ------------------------------------------------------------------------------------------------ a lit plate


def plate_scene(size=8, light_half=2.0, height=1.0, max_depth=3, material="grey") -> Scene:
    """A one-sided plate of side 2 at the origin facing +z, under a square area light of side 2 ``light_half`` at
    ``height`` facing down, seen obliquely by a box-filtered film."""
    plate = Shape(index=0, name="plate", type="rectangle", material=material, to_world=np.eye(4))
    light = Shape(index=1, name="light", type="rectangle", material="black",
                  to_world=translate_matrix((0, 0, height)) @ rotate_matrix((1, 0, 0), 180) @ scale_matrix(light_half),
                  emission=(1.0, 1.0, 1.0))
    camera = Camera(origin=(0.0, -2.2, 0.6), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), fov=40.0)
    materials = {material: Material(material, (0.6, 0.6, 0.6)), "black": Material("black", (0.0, 0.0, 0.0))}
    return Scene(name="plate", description="", camera=camera, film=Film(size, size, "box"), max_depth=max_depth,
                 materials=materials, shapes=[plate, light], path=Path("plate.toml"))


def test_bsdf_sampling_agrees_with_light_sampling_on_a_lambertian_scene():
    """direct = bsdf on a Lambertian scene (the pure BSDF-sampling estimator); in expectation it is light sampling
    (direct = area)."""
    scene = plate_scene(light_half=0.6)
    area = _render(scene, spp=64, sampler="independent", direct="area")
    bsdf = _render(scene, spp=256, sampler="independent", direct="bsdf")
    assert bsdf.stats["shadow_rays"] == 0 and area.stats["shadow_rays"] > 0
    assert _verdict(bsdf, area, "bsdf vs area, Lambertian plate").verdict == "pass"


ROUGH = {
    "roughconductor": (ROUGHCONDUCTOR, {3: CU_ETA[0], 4: CU_ETA[1], 5: CU_ETA[2], 6: CU_K[0], 7: CU_K[1], 8: CU_K[2],
                                        12: 0.3, 14: 1.0}),
    "roughdielectric": (ROUGHDIELECTRIC, {12: 0.3, 14: 1.0, 15: 1.5}),
}


@pytest.mark.parametrize("name", sorted(ROUGH))
def test_area_bsdf_and_mis_agree_on_a_rough_plate(name):
    """Three estimators of one image: light sampling (which reaches the rough dielectric's far side through
    bsdf_eval), BSDF sampling and their combination. Each against MIS (the lowest variance)."""
    rows = {0: ROUGH[name]}
    scene = plate_scene(light_half=0.6)
    mis = _render(scene, rows, spp=128, sampler="independent", direct="mis")
    assert mis.image.mean() > 0
    for direct, spp in (("area", 128), ("bsdf", 256)):
        other = _render(scene, rows, spp=spp, sampler="independent", direct=direct)
        assert _verdict(other, mis, f"{name}: {direct} vs mis").verdict == "pass"


def test_the_light_through_a_rough_dielectric_is_found_by_light_samples():
    """A rough dielectric plate seen from below its light: light samples cross it (f from bsdf_eval on the far
    side), and agree with BSDF sampling."""
    rows = {0: ROUGH["roughdielectric"]}
    scene = plate_scene(light_half=0.6, max_depth=2)
    scene = dataclasses.replace(scene, camera=Camera(origin=(0.0, -0.6, -2.2), target=(0.0, 0.0, 0.0),
                                                     up=(0.0, 1.0, 0.0), fov=40.0))
    area = _render(scene, rows, spp=128, sampler="independent", direct="area")
    assert area.image.mean() > 0.1 and area.stats["shadow_rays"] > 0
    for direct, spp in (("bsdf", 256), ("mis", 128)):
        other = _render(scene, rows, spp=spp, sampler="independent", direct=direct)
        assert _verdict(area, other, f"roughdielectric from behind: area vs {direct}").verdict == "pass"


# ------------------------------------------------------------------------------------------------ planted fault


def test_mis_weights_that_do_not_sum_to_one_are_caught():
    """The light sample weighted by the balance heuristic, the BSDF sample by the power heuristic: under a light
    large against its distance (p_l / p_b about 0.2 over most of the plate) the weights sum to about 1.13. On the
    Lambertian plate with rr = throughput; the correct MIS passes against light sampling, the planted fault
    fails."""
    scene = plate_scene(size=16, light_half=2.0, max_depth=2)
    common = dict(spp=256, sampler="independent", rr="throughput")
    area = _render(scene, direct="area", **common)
    right = _render(scene, direct="mis", **common)
    wrong = _render(scene, direct="mis", mutant="mis-weights-not-one", **common)
    assert _verdict(right, area, "mis vs area").verdict == "pass"
    assert _verdict(wrong, area, "mutant mis-weights-not-one vs area").verdict == "fail"


def test_roulette_survivors_not_reweighted_are_caught_under_the_pbrt_roulette():
    """The default roulette of glossy scenes (rr = auto: pbrt-v4's, q = min(1, max(beta) eta^2)) against the
    planted fault "rr-no-reweight" (survivors not divided by q): on the Lambertian plate of reflectance 0.5, lit from
    above, paths that reach depth 3 carry the second bounce; without the 1/q the image is darker. Both against
    rr = off (no roulette, the same estimator otherwise)."""
    scene = plate_scene(size=16, light_half=2.0, max_depth=5)
    common = dict(spp=256, sampler="independent", direct="mis", rr_depth=1)
    off = _render(scene, rr="off", **common)
    right = _render(scene, rr="pbrt", **common)
    wrong = _render(scene, rr="pbrt", mutant="rr-no-reweight", **common)
    assert _verdict(right, off, "pbrt roulette vs none").verdict == "pass"
    assert _verdict(wrong, off, "mutant rr-no-reweight vs none").verdict == "fail"


# ------------------------------------------------------------------------------------------------ determinism, errors


def test_the_image_depends_on_neither_the_thread_count_nor_the_batch_size():
    scene = with_emitters(sphere_scene(size=8, max_depth=-1), constant(SKY))
    rows = {0: (DIELECTRIC, {15: 1.33, 0: 0.9, 1: 0.9, 2: 0.9})}
    one = _render(scene, rows, spp=8, threads=1)
    two = _render(scene, rows, spp=8, threads=2, batch_size=37)
    again = _render(scene, rows, spp=8, threads=1)
    other_seed = _render(scene, rows, spp=8, threads=1, seed=1)
    assert np.array_equal(one.image, two.image) and np.array_equal(one.image, again.image)
    assert not np.array_equal(one.image, other_seed.image)


@pytest.mark.parametrize("settings, key", [({"direct": "hemisphere-cosine"}, "direct"),
                                           ({"direct": "global-area"}, "direct"),
                                           ({"indirect_rays": 2}, "indirect_rays")])
def test_what_a_glossy_scene_does_not_take_is_refused(settings, key):
    scene = with_emitters(sphere_scene(size=4, max_depth=-1), constant(SKY))
    with pytest.raises(SettingsError) as err:
        _render(scene, {0: MIRROR}, spp=1, **settings)
    assert err.value.key == key


def test_auto_resolves_to_area_without_a_glossy_material_and_to_mis_with_one():
    s = Settings()
    assert s.direct == "auto" and s.rr == "auto"
    assert (s.resolved(False).direct, s.resolved(True).direct) == ("area", "mis")
    assert (s.resolved(False).rr, s.resolved(True).rr) == ("albedo", "pbrt")
    assert Settings(direct="bsdf").resolved(False).direct == "bsdf"
    assert Settings(rr="throughput").resolved(True).rr == "throughput"
    given = Settings(direct="mis", rr="fixed")
    assert given.resolved(False) is given and given.resolved(True) is given


def test_the_glossy_rule_reads_the_material_table():
    assert not is_glossy(None)
    assert not is_glossy(Materials.diffuse([[0.5] * 3], [False]))
    assert is_glossy(Materials(np.array([CONDUCTOR]), material_row(CONDUCTOR)[None]))


def test_the_harness_reads_the_resolved_strategy():
    """The adapter resolves direct = auto before anything reads it ("area" on a Lambertian scene: the settings a
    result records are those of before); the strategy tables' defaults and rows follow the scene's kind."""
    settings = ReferenceRenderer().settings_for(plate_scene(), RenderRequest(spp=1, seed=0, settings={}))
    assert settings.direct == "area" and settings.rr == "albedo"
    assert strategies.strategy_defaults()["direct"] == "area"
    assert strategies.strategy_defaults(glossy=True)["direct"] == "mis"
    assert strategies.strategy_defaults(glossy=True)["rr"] == "pbrt"
    glossy_rows = strategies.strategy_choices(strategies.strategy_defaults(glossy=True), True, glossy=True)
    assert ("direct", "bsdf") in glossy_rows and ("direct", "area") in glossy_rows
    assert ("rr", "throughput") in glossy_rows and ("rr", "albedo") in glossy_rows
    assert not any(k == "hemisphere" for k, _ in glossy_rows)
    assert ("direct", "bsdf") not in strategies.strategy_choices(strategies.strategy_defaults(), True)
