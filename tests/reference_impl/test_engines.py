"""The path loop (one path at a time, Embree's C API from the kernels) and the wavefront estimate the same image, and
the direct Embree queries answer as Embree should.

The path loop is the default and runs every scene; the wavefront is what Ni > 1 needs. They draw their random
numbers for different dimensions (the path loop samples the BSDF door, the wavefront the slides' hemisphere) and
sum in other orders, so their bits differ: every setting and planted fault is rendered by each at its own seed and
the means compared (``engine_agreement.mean_z``: globally and per quadrant, per channel, with the renders' own
variance estimates). A case fails where some |z| > Z_MAX = 4.9 (two-sided 1e-6 per z, 15 z per case, 22 cases: a
false alarm about once in 3,000 draws of the seeds, which are fixed).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import load_small

try:
    from engine_agreement import Z_MAX, mean_z
except ImportError:  # tests/ imported as a package
    from tests.reference_impl.engine_agreement import Z_MAX, mean_z

from harness.scene import triangulate

SPP = 64

CASES = [
    ("cornell-box", {}),
    ("multi-light", {}),
    ("soft-shadows", {}),
    ("furnace", {}),
    ("cornell-box", {"direct": "mis"}),
    ("multi-light", {"direct": "hemisphere-cosine", "shadow_rays": 2}),
    ("multi-light", {"direct": "hemisphere-uniform"}),
    ("cornell-box", {"direct": "global-area", "shadow_rays": 3}),
    ("multi-light", {"light_selection": "uniform", "rr": "off"}),
    ("cornell-box", {"rr": "fixed", "absorption": 0.4, "mutant": "double-emission"}),
    ("furnace", {"mutant": "rr-no-reweight"}),
    ("furnace", {"mutant": "energy-loss-2pct"}),
    ("soft-shadows", {"mutant": "no-ray-offset"}),
    ("soft-shadows", {"mutant": "camera-half-pixel"}),
    ("cornell-box", {"hemisphere": "uniform", "mutant": "cosine-pdf-pi", "rr_depth": 3}),
    ("multi-light", {"direct": "mis", "mutant": "light-pdf-ignored", "max_depth": -1}),
    ("cornell-box", {"mutant": "no-cosine", "max_depth": 2}),
    ("cornell-box", {"max_depth": 1}),
    ("cornell-box", {"sampler": "independent"}),
    ("multi-light", {"sampler": "independent", "direct": "hemisphere-cosine", "shadow_rays": 2}),
    ("cornell-box", {"sampler": "independent", "direct": "global-area", "shadow_rays": 3}),
    ("furnace", {"sampler": "independent", "mutant": "rr-no-reweight"}),
]


def _render(scene, engine, **settings):
    import reference_impl

    values = {"spp": 4, "seed": 11, "max_depth": scene.max_depth, **settings}
    return reference_impl.render(triangulate(scene), scene.camera, scene.film,
                                 reference_impl.Settings(**values, engine=engine))


@pytest.mark.parametrize("name, settings", CASES, ids=[f"{n}-{'-'.join(map(str, s.values())) or 'defaults'}"
                                                       for n, s in CASES])
def test_path_and_wavefront_engines_agree(name, settings):
    scene = load_small(name, 24)
    a = _render(scene, "wavefront", **{"spp": SPP, **settings})
    b = _render(scene, "path", **{"spp": SPP, "seed": 12, **settings})
    assert a.stats["paths"] == b.stats["paths"]
    assert np.all(np.isfinite(a.variance)) and np.all(np.isfinite(b.variance))
    assert mean_z(a, b).max() <= Z_MAX
    assert b.stats["embree_microseconds"] >= 0


def test_the_engines_comparison_can_fail():
    """The same comparison, a planted fault on one side only: the cosine dropped from the estimators."""
    scene = load_small("cornell-box", 24)
    a = _render(scene, "wavefront", spp=SPP)
    b = _render(scene, "path", spp=SPP, seed=12, mutant="no-cosine")
    assert mean_z(a, b).max() > Z_MAX


@pytest.mark.parametrize("engine", ["path", "wavefront"])
@pytest.mark.parametrize("sampler", ["sobol", "independent"])
def test_gaussian_filter_and_odd_batches_give_the_same_bits(engine, sampler):
    scene = load_small("cornell-box", 20)
    scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, filter="gaussian"))
    a = _render(scene, engine, batch_size=37, sampler=sampler)
    b = _render(scene, engine, batch_size=1000, threads=1, sampler=sampler)
    assert a.image.tobytes() == b.image.tobytes()


def test_direct_queries_match_a_brute_force_intersector():
    """Closest hits and occlusion from the C API agree with a float64 brute-force ray/triangle test, except for rays
    that pass within float32 rounding of an edge."""
    from reference_impl.intersect import Intersector

    scene = load_small("cornell-box", 8)
    geometry = triangulate(scene)
    ix = Intersector(geometry)
    rng = np.random.default_rng(5)
    n = 4000
    origins = rng.uniform(-0.95, 0.95, (n, 3))
    directions = rng.normal(size=(n, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    prim = ix.closest_prims(origins.astype(np.float32), directions.astype(np.float32))
    packets = ix.closest_prims_coherent(origins.astype(np.float32), directions.astype(np.float32))
    assert np.array_equal(prim, packets)

    v0, v1, v2 = (geometry.corners[ix.prim_to_tri, k] for k in range(3))
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(directions[:, None, :], e2[None])
    det = np.einsum("tk,ntk->nt", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = origins[:, None, :] - v0[None]
        u = np.einsum("ntk,ntk->nt", s, p) * inv
        q = np.cross(s, e1[None])
        v = np.einsum("nk,ntk->nt", directions, q) * inv
        t = np.einsum("tk,ntk->nt", e2, q) * inv
    margin = 1e-4
    hit = (u > margin) & (v > margin) & (u + v < 1 - margin) & (t > 1e-4)
    near_edge = ((u > -margin) & (v > -margin) & (u + v < 1 + margin) & (t > 0)) & ~hit
    t_hit = np.where(hit, t, np.inf)
    best = np.argmin(t_hit, axis=1)
    clear_miss = ~near_edge.any(axis=1) & ~np.isfinite(t_hit.min(axis=1))
    assert np.all(prim[clear_miss] == -1)  # out through the open front
    clear = ~near_edge.any(axis=1) & np.isfinite(t_hit.min(axis=1))
    assert clear.sum() > 0.75 * n
    same_t = np.isclose(t_hit[np.arange(n), best], t_hit[np.arange(n), np.clip(prim, 0, None)], rtol=1e-5)
    assert np.all((prim[clear] == best[clear]) | same_t[clear])  # coplanar triangles of one rectangle tie

    # Occlusion: the segment to the brute-force hit, shortened, is free; lengthened past it, blocked.
    d_best = t_hit[np.arange(n), best]
    sel = clear & (d_best > 0.05)
    o32, d32 = origins[sel].astype(np.float32), directions[sel].astype(np.float32)
    free = ix.occluders(o32, d32, (d_best[sel] * 0.99).astype(np.float32))
    blocked = ix.occluders(o32, d32, (d_best[sel] * 1.01).astype(np.float32))
    assert np.all(free < 0) and np.all(blocked >= 0)


def test_engine_packet_is_refused_naming_the_engines_that_remain():
    import reference_impl

    with pytest.raises(reference_impl.SettingsError, match=r"^engine: expected one of path, wavefront, got 'packet'$"):
        reference_impl.Settings.from_strings({"engine": "packet"})


def test_the_capability_table_of_the_docs_is_the_core_s():
    """docs/reference-renderer.md shows ``settings.CAPABILITIES`` (strategy x engine) as one table, row for row; every
    resolved value of ``direct``, ``rr``, ``env_sampling`` and ``light_selection`` has its row."""
    from pathlib import Path

    from reference_impl.emitters import ENV_SAMPLINGS
    from reference_impl.settings import CAPABILITIES, DIRECT_STRATEGIES, ROULETTES

    columns = ("path", "wavefront", "glossy", "volpath")
    lines = ["| strategy | `path` | `wavefront` | glossy | media |", "|---|---|---|---|---|"]
    for (key, value), engines in CAPABILITIES.items():
        label = f"`{key} {value}`" if value.startswith(">") else f"`{key} = {value}`"
        lines.append(f"| {label} | " + " | ".join("yes" if c in engines else "no" for c in columns) + " |")
    doc = (Path(__file__).resolve().parents[2] / "docs" / "reference-renderer.md").read_text(encoding="utf-8")
    assert "\n" + "\n".join(lines) + "\n\n" in doc
    rows = {(key, value) for key, value in CAPABILITIES}
    from reference_impl.lights import LIGHT_SELECTIONS

    for key, values in (("direct", DIRECT_STRATEGIES), ("rr", ROULETTES), ("env_sampling", ENV_SAMPLINGS),
                        ("light_selection", LIGHT_SELECTIONS)):
        assert {(key, v) for v in values if v != "auto"} <= rows, key
    assert all(set(engines) <= set(columns) and engines for engines in CAPABILITIES.values())
