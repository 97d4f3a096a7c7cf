"""The reference skips work a scene does not need, and its counters (``harness render --json`` stats) show it.

Each test builds a scene where some work is provably useless and checks that the matching counter is exactly zero,
and (where it could fail silently) that the same counter is non-zero in a scene that needs the work.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import load_small, render_reference


def _with_shapes(scene, shapes):
    return dataclasses.replace(scene, shapes=shapes)


def _flip_light(scene):
    """The Cornell box without its ceiling, its light raised above the walls and turned to face up: nothing is
    above the light."""
    shapes = []
    for s in scene.shapes:
        if s.is_emitter:
            to_world = s.to_world.copy()
            to_world[1, 3] = 1.5
            s = dataclasses.replace(s, flip_normals=not s.flip_normals, to_world=to_world)
        if s.name != "ceiling":
            shapes.append(s)
    return _with_shapes(scene, shapes)


def test_one_light_means_no_light_selection_draws_and_several_lights_do_draw():
    one = render_reference(load_small("cornell-box", 16), spp=2)
    assert one.stats["light_selections"] == 0
    several = render_reference(load_small("multi-light", 16), spp=2)
    # Every area light sample draws a light k first: each becomes a shadow ray or a skipped one.
    assert several.stats["light_selections"] == several.stats["shadow_rays"] + several.stats["shadow_rays_skipped"] > 0


def test_no_shadow_ray_toward_a_light_that_faces_away():
    normal = render_reference(load_small("cornell-box", 16), spp=2, max_depth=2)
    assert normal.stats["shadow_rays"] > 0
    away = render_reference(_flip_light(load_small("cornell-box", 16)), spp=2, max_depth=2)
    # Every hit point is below the light, which emits upward: the cosine at the light is negative for each sample.
    assert away.stats["shadow_rays"] == 0
    assert away.stats["shadow_rays_skipped"] > 0


def test_no_shadow_ray_from_a_back_face():
    """Seen from outside, the Cornell box's one-sided walls show their backs: black, no light sample, no ray."""
    scene = load_small("cornell-box", 16)
    # Put the camera behind the back wall (z = -1), looking at it from outside the box.
    camera = dataclasses.replace(scene.camera, origin=np.array([0.0, 0.0, -3.9]), target=np.array([0.0, 0.0, 0.0]))
    outside = dataclasses.replace(scene, camera=camera)
    result = render_reference(outside, spp=2, max_depth=3)
    assert result.stats["back_face_absorbed"] > 0
    assert result.stats["shadow_rays"] == result.stats["shadow_rays_skipped"] == 0
    assert result.stats["indirect_rays"] == 0


def test_shadow_rays_are_occlusion_queries(monkeypatch):
    """Shadow rays go to Embree's any-hit query; only camera and indirect rays use closest-hit queries. Counted on
    the wavefront engine, whose queries go through the Intersector (the path loop calls rtcOccluded1 for its shadow
    rays: kernels/path.py)."""
    from reference_impl import integrator, intersect

    counted = {"closest": 0, "occluded": 0}
    closest, occluders = intersect.Intersector.closest_prims, intersect.Intersector.occluders

    def count_closest(self, origins, directions):
        counted["closest"] += len(origins)
        return closest(self, origins, directions)

    def count_occluders(self, origins, directions, tfar):
        counted["occluded"] += len(origins)
        return occluders(self, origins, directions, tfar)

    coherent = intersect.Intersector.closest_prims_coherent

    def count_coherent(self, origins, directions):  # camera rays, in packets
        counted["closest"] += len(origins)
        return coherent(self, origins, directions)

    monkeypatch.setattr(intersect.Intersector, "closest_prims", count_closest)
    monkeypatch.setattr(intersect.Intersector, "closest_prims_coherent", count_coherent)
    monkeypatch.setattr(intersect.Intersector, "occluders", count_occluders)
    # the render's queries alone, not those of the warm batch that loads the kernels before the clock (its
    # counters are dropped: reference_impl.integrator._load_kernels)
    monkeypatch.setattr(integrator, "_load_kernels", lambda *args: None)
    result = render_reference(load_small("cornell-box", 16), spp=2, engine="wavefront")
    assert counted["occluded"] == result.stats["shadow_rays"] > 0
    assert counted["closest"] == result.stats["camera_rays"] + result.stats["indirect_rays"]


@pytest.mark.parametrize("max_depth", [1, 2])
def test_no_indirect_rays_when_max_depth_at_most_2(max_depth):
    result = render_reference(load_small("cornell-box", 16), spp=2, max_depth=max_depth)
    assert result.stats["indirect_rays"] == 0
    if max_depth == 1:  # emitters seen directly: no light samples either
        assert result.stats["shadow_rays"] == result.stats["shadow_rays_skipped"] == 0
    deeper = render_reference(load_small("cornell-box", 16), spp=2, max_depth=3)
    assert deeper.stats["indirect_rays"] > 0


def test_no_lights_black_at_once():
    scene = load_small("cornell-box", 16)
    dark = _with_shapes(scene, [s for s in scene.shapes if not s.is_emitter])
    result = render_reference(dark, spp=4)
    assert not np.any(result.image)
    assert result.stats["camera_rays"] == result.stats["shadow_rays"] == result.stats["indirect_rays"] == 0


@pytest.mark.parametrize("rr", ["albedo", "off"])
def test_paths_that_cannot_carry_light_end(rr):
    """Black surfaces reflect nothing: no path continues from them, whatever the roulette mode."""
    scene = load_small("cornell-box", 16)
    black = {name: dataclasses.replace(m, reflectance=(0.0, 0.0, 0.0)) for name, m in scene.materials.items()}
    result = render_reference(dataclasses.replace(scene, materials=black), spp=2, rr=rr)
    assert result.stats["indirect_rays"] == 0
    assert result.stats["roulette_terminated"] > 0
    # The light is still seen directly; everything else is black.
    assert np.count_nonzero(np.any(result.image > 0, axis=2)) > 0
