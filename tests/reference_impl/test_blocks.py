"""Paths traced in blocks that go from vertex to vertex together, their rays in packets (kernels/blocks.py), give
the path loop's image bit for bit, with the same variance and counters, whatever the depth, roulette, settings,
threads and planted faults; a packet of occlusion or closest-hit queries answers as one query per ray does; and only
the scenes the path loop would run with its options compiled out take this way."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import load_small, render_spied, same_as_path_loop

KERNEL = ("blocks", "trace_blocks")  # the kernel the blocks run


def _render(scene, spp, blocks, monkeypatch, seed=3, **settings):
    return render_spied(scene, spp, blocks, monkeypatch, KERNEL, seed, **settings)


def _same(scene, spp, monkeypatch, **settings):
    result = same_as_path_loop(scene, spp, monkeypatch, KERNEL, **settings)
    assert result.stats["shadow_rays"] > 0 or scene.max_depth == 1
    return result


CASES = [
    ("soft-shadows", None, {}),
    ("soft-shadows", None, {"sampler": "independent"}),
    ("soft-shadows", None, {"shadow_rays": 3, "threads": 1, "batch_size": 1000}),
    ("soft-shadows", None, {"replicates": 4}),
    ("multi-light", 2, {}),  # eight lights: the choice of light and its pdf
    ("multi-light", 2, {"sampler": "independent", "light_selection": "uniform", "shadow_rays": 2}),
    ("cornell-box", 2, {}),  # light samples behind x (skipped), lights seen directly
    ("cornell-box", 1, {}),  # emission alone: no light sample
    ("textured-reflectance", 2, {}),  # reflectance from textures: the material step's lookups
    # paths that go on past their first hit: the BSDF's sample and roulette at every depth
    ("cornell-box", None, {}),
    ("cornell-box", None, {"sampler": "independent", "threads": 1, "batch_size": 1000}),
    ("cornell-box", None, {"hemisphere": "uniform", "shadow_rays": 2}),
    ("cornell-box", None, {"rr_depth": 1}),  # the first hit's roulette number from the pixel's points
    ("cornell-box", None, {"rr": "fixed", "absorption": 0.4, "rr_depth": 1, "sampler": "independent"}),
    ("cornell-box", None, {"rr": "pbrt"}),
    ("cornell-box", None, {"rr": "throughput", "replicates": 3}),
    ("cornell-box", -1, {}),  # unbounded: roulette alone ends the paths
    ("cornell-box", 4, {"rr": "off"}),
    ("multi-light", None, {"light_selection": "uniform", "shadow_rays": 3}),
    ("textured-reflectance", None, {}),
]


def _textured_reflectance():
    """textured-cornell-box with its light's texture dropped and its rough conductor made white: diffuse walls whose
    reflectance is a bitmap and a checkerboard, lit by a plain area light."""
    scene = load_small("textured-cornell-box", 24)
    shapes = [dataclasses.replace(s, emission_texture=None) if s.emission is not None else s for s in scene.shapes]
    materials = dict(scene.materials, metal=scene.materials["white"])
    return dataclasses.replace(scene, shapes=shapes, materials=materials)


@pytest.mark.parametrize("name, max_depth, settings", CASES)
def test_paths_in_blocks_give_the_path_loops_bits(name, max_depth, settings, monkeypatch):
    scene = _textured_reflectance() if name == "textured-reflectance" else load_small(name, 24)
    if max_depth is not None:
        scene = dataclasses.replace(scene, max_depth=max_depth)
    _same(scene, 16, monkeypatch, **settings)


@pytest.mark.parametrize("mutant", ["light-pdf-ignored", "no-cosine", "no-ray-offset", "camera-half-pixel",
                                    "energy-loss-2pct", "double-emission", "rr-no-reweight", "cosine-pdf-pi"])
def test_planted_faults_change_both_ways_alike(mutant, monkeypatch):
    scene = dataclasses.replace(load_small("multi-light", 24), max_depth=5)  # roulette from depth 3 on
    faulty = _same(scene, 16, monkeypatch, mutant=mutant)
    clean, _ = _render(scene, 16, True, monkeypatch)
    assert not np.array_equal(faulty.image, clean.image)


@pytest.mark.parametrize("name, max_depth, settings", [
    ("soft-shadows", None, {"direct": "mis"}),
    ("soft-shadows", None, {"direct": "hemisphere-cosine"}),
    ("veach-mis", None, {}),  # glossy materials and sphere lights: kernels/path_blocks.py
])
def test_other_scenes_keep_the_path_loop(name, max_depth, settings, monkeypatch):
    scene = load_small(name, 8)
    _result, ran = _render(scene, 2, True, monkeypatch, **settings)
    assert not ran


@pytest.mark.parametrize("with_spheres", [False, True])
def test_a_packet_answers_as_one_query_per_ray(with_spheres):
    """Occlusion and closest-hit packets of 4, 8 and 16 rays give the answers of one query per ray (width 1), also
    with analytic spheres beside Embree's triangles (tested on the float64 rays, as one query per ray tests them)."""
    from reference_impl.embree_c import TriangleScene
    from reference_impl.kernels.blocks import closest_packets, occluded_packets
    from reference_impl.kernels.queries import incoherent_arguments, packet_buffer

    rng = np.random.default_rng(5)
    corners = rng.uniform(-1.0, 1.0, (200, 3, 3))
    scene = TriangleScene(corners.reshape(-1, 3), np.arange(600).reshape(200, 3))
    count = 1000
    origin = rng.uniform(-1.5, 1.5, (count, 3))
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    tfar = rng.uniform(0.0, 3.0, count).astype(np.float32)
    tfar[::7] = np.inf
    spheres, base = None, 0
    if with_spheres:  # three spheres, primitives 200, 201, 202
        spheres, base = np.array([[0.3, 0.2, -0.1, 0.4], [-0.8, 0.5, 0.6, 0.3], [0.5, -0.7, 0.9, 0.25]]), 200
    answers = {}
    for width in (1, 4, 8, 16):
        blocked = np.zeros(count, bool)
        occluded_packets(scene.pointer, width, origin, direction, tfar, count, blocked, *packet_buffer(), spheres)
        answers[width] = blocked
    assert 0.1 < answers[1].mean() < 0.9
    for width in (4, 8, 16):
        assert np.array_equal(answers[width], answers[1])
    # closest hits of the rays of some slots, in an order of their own (the paths that go on)
    slots = rng.permutation(count)[:700]
    hits = {}
    for width in (1, 4, 8, 16):
        prim = np.full(count, -2, np.int64)
        closest_packets(scene.pointer, width, slots, len(slots), origin, direction, prim, *packet_buffer(),
                        incoherent_arguments(), np.empty(16, np.int64), spheres, base)
        hits[width] = prim
    assert np.all(np.delete(hits[1], slots) == -2)
    assert 0.1 < np.mean(hits[1][slots] >= 0) < 0.9
    if with_spheres:  # the spheres are hit, nearer than some triangles
        assert 0.02 < np.mean(hits[1][slots] >= base) < 0.9
    for width in (4, 8, 16):
        assert np.array_equal(hits[width], hits[1])
