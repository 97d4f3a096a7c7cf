"""The paths of scenes with materials that are not diffuse, traced in blocks that go from vertex to vertex together,
their rays in packets (kernels/path_blocks.py), give the path loop's image bit for bit, with the same variance and
counters, whatever the materials, lights, emitters, shading normals, direct-light strategy, depth, roulette,
sampler, threads and planted faults; and the scenes it does not run (masks, nested materials, media, Lambertian
scenes) keep their engine."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import load_small, render_spied, same_as_path_loop

KERNEL = ("path_blocks", "trace_path_blocks")  # the kernel the blocks run


def _render(scene, spp, blocks, monkeypatch, seed=3, **settings):
    return render_spied(scene, spp, blocks, monkeypatch, KERNEL, seed, **settings)


def _same(scene, spp, monkeypatch, **settings):
    return same_as_path_loop(scene, spp, monkeypatch, KERNEL, **settings)


CASES = [
    # a mirror and glass (delta lobes: no light sample there), analytic spheres, max_depth 8
    ("cornell-box-specular", None, {}),
    ("cornell-box-specular", None, {"sampler": "independent", "threads": 1, "batch_size": 1000}),
    ("cornell-box-specular", None, {"rr_depth": 1}),  # the first hit's roulette number from the pixel's points
    ("cornell-box-specular", None, {"rr": "pbrt", "shadow_rays": 2}),
    ("cornell-box-specular", None, {"direct": "bsdf"}),  # emission found by the BSDF's rays alone
    ("cornell-box-specular", None, {"direct": "mis", "replicates": 3}),
    ("cornell-box-specular", -1, {}),  # unbounded: roulette alone ends the paths
    # rough conductors, sphere lights drawn by their cone, MIS
    ("veach-mis", None, {}),
    ("veach-mis", None, {"direct": "area", "light_selection": "uniform", "shadow_rays": 3}),
    ("veach-mis", None, {"sampler": "independent", "rr": "off"}),
    # a rough plastic floor, 64 lights, chosen by a light tree (pdf(k | x) at each vertex)
    ("lamp-grid", None, {}),
    ("lamp-grid", None, {"light_selection": "tree"}),
    ("lamp-grid", 5, {"light_selection": "tree", "sampler": "independent", "rr_depth": 1}),
    # a textured light, bitmap and procedural textures, a rough conductor
    ("textured-cornell-box", None, {}),
    # the other kinds: plastics, principled (anisotropic: its frame along dp/du; an environment), thin glass
    ("plastic-cornell-box", None, {}),
    ("principled-grid", None, {}),
    ("thin-glass-window", None, {}),
    # emitters that are not surfaces: point and spot lights (with direct = bsdf their own samples), environments
    ("glossy-point-spot", None, {}),
    ("glossy-point-spot", None, {"direct": "bsdf"}),
    ("white-furnace-rough", None, {}),
    ("white-furnace-mirror", None, {"direct": "mis", "sampler": "independent"}),
    # shading normals: vertex normals
    ("smooth-twins", None, {}),
]


def _scene(name, width=24):
    """A canonical scene, or point-spot with its first material a rough conductor (veach-mis's plate0): delta lights
    on a glossy scene."""
    if name != "glossy-point-spot":
        return load_small(name, width)
    scene = load_small("point-spot", width)
    first = next(iter(scene.materials))
    return dataclasses.replace(scene, materials=dict(scene.materials,
                                                     **{first: load_small("veach-mis", 8).materials["plate0"]}))


@pytest.mark.parametrize("name, max_depth, settings", CASES)
def test_paths_in_blocks_give_the_path_loops_bits(name, max_depth, settings, monkeypatch):
    scene = _scene(name)
    if max_depth is not None:
        scene = dataclasses.replace(scene, max_depth=max_depth)
    result = _same(scene, 16, monkeypatch, **settings)
    assert result.stats["indirect_rays"] > 0


@pytest.mark.parametrize("name, mutant", [
    ("cornell-box-specular", "double-emission"),
    ("cornell-box-specular", "refraction-no-eta2"),
    ("cornell-box-specular", "rr-no-reweight"),
    ("veach-mis", "conductor-fresnel-one"),
    ("veach-mis", "mis-weights-not-one"),
    ("veach-mis", "sphere-cone-pdf-area"),
    ("veach-mis", "microfacet-pdf-no-jacobian"),
    ("veach-mis", "light-pdf-ignored"),
    ("lamp-grid", "light-tree-pmf-at-hit"),  # (with light_selection = tree, below)
    ("lamp-grid", "no-cosine"),
    ("textured-cornell-box", "texture-v-flipped"),
    ("glossy-point-spot", "point-no-inverse-square"),
    ("principled-grid", "principled-clearcoat-pdf-jacobian"),
    ("smooth-twins", "normals-not-renormalised"),
])
def test_planted_faults_change_both_ways_alike(name, mutant, monkeypatch):
    scene = _scene(name)
    settings = {"light_selection": "tree"} if name == "lamp-grid" else {}
    faulty = _same(scene, 16, monkeypatch, mutant=mutant, **settings)
    clean, _ = _render(scene, 16, True, monkeypatch, **settings)
    assert not np.array_equal(faulty.image, clean.image)


@pytest.mark.parametrize("name, settings", [
    ("cutout-leaf", {}),  # a mask
    ("material-balls", {}),  # a blend, a twosided of two, a mask
    ("soft-shadows", {"direct": "hemisphere-cosine"}),
    ("fog-box", {}),  # media: the volumetric path loop
    ("cornell-box", {}),  # Lambertian, area lights: kernels/blocks.py
    ("point-spot", {}),  # Lambertian with emitters, normal maps: the path loop
    ("mapped-plates", {}),
])
def test_other_scenes_keep_their_engine(name, settings, monkeypatch):
    scene = load_small(name, 8)
    _result, ran = _render(scene, 2, True, monkeypatch, **settings)
    assert not ran
