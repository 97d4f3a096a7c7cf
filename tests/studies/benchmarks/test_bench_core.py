"""Benchmarks of the reference renderer's core (pytest-benchmark): primary rays, shadow rays, one bounce, a frame.

Not part of the default test run: ``pyproject.toml`` passes ``--benchmark-skip``, which skips every test that uses
the ``benchmark`` fixture. Run them with

    .venv/bin/pytest tests/benchmarks --benchmark-only            # all benchmarks, nothing else
    .venv/bin/pytest tests/benchmarks --benchmark-only -k frame   # only the whole frames

Where git has the last revision with the numpy integrator (``tests/benchmarks/_baseline.py``; another one with
``REFERENCE_BASELINE_REV=<rev>``), the "frame" and "bounce" groups also time it, so the speed ratio of the kernels
is measured in the same run. Each benchmark reports rays or paths per second in ``extra_info``
(``--benchmark-json out.json`` keeps them). On a shared machine compare only numbers from one run.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _baseline import ROOT, convert_inputs, load_baseline  # noqa: E402

N_RAYS = 1 << 16  # camera paths per batch in the ray and bounce benchmarks (256 x 256 pixels, 1 sample)


def _scene(name: str):
    from harness.scene import load_scene, triangulate

    scene = load_scene(ROOT / "scenes" / f"{name}.toml")
    return scene, triangulate(scene)


@pytest.fixture(scope="module")
def cornell():
    """A one-thread context for the Cornell box, its first wavefront (camera rays) and their closest hits."""
    from reference_impl import Film, Settings, integrator
    from reference_impl.kernels import camera, records

    scene, geometry = _scene("cornell-box")
    settings = Settings(spp=1, seed=0, max_depth=scene.max_depth, threads=1)
    ctx = integrator._Context(geometry, scene.camera, Film(256, 256, "box"), settings)
    pixel = np.arange(N_RAYS, dtype=np.int64)
    sample = np.zeros(N_RAYS, np.int64)
    integrator._trace_camera_paths(ctx, pixel, sample, dict.fromkeys(integrator.COUNTERS, 0) | {integrator.EMBREE_MICROSECONDS: 0})
    ws = ctx.workspace()
    first = integrator._view(ws.state(0, N_RAYS), N_RAYS)
    film_samples = records.film_samples(pixel, sample, ctx.seed_key)
    camera_args = (film_samples, ctx.config, ctx.camera_record, records.filter_samples(ctx.filter_kind), first)
    camera.camera_paths(*camera_args)
    state = integrator._PathState(*first)
    prim = ctx.intersector.closest_prims(state.origin32, state.direction32)
    return {"ctx": ctx, "ws": ws, "state": state, "prim": prim, "camera_args": camera_args,
            "film_samples": film_samples}


def _per_second(benchmark, count):
    """count / the median time; None when timing is off (``--benchmark-disable`` runs each body once, untimed)."""
    return count / benchmark.stats.stats.median if benchmark.stats is not None else None


def _counters():
    from reference_impl import integrator

    return np.zeros(len(integrator.COUNTERS), np.int64)


def _run_bounce_kernel(c, radiance, counters):
    from reference_impl.kernels import wavefront

    ctx, ws = c["ctx"], c["ws"]
    hits, _, rays = ws.direct(N_RAYS)
    return wavefront.bounce(c["state"].arrays(), c["prim"], ctx.scene_tables, ctx.light_tables, ctx.surface_tables,
                            ctx.material_tables, ctx.config._replace(depth=1), radiance, counters, hits, rays,
                            ws.state(1, N_RAYS), c["film_samples"], ctx.emitter_tables, ws.complement_rays())


@pytest.mark.benchmark(group="primary rays")
def test_primary_rays_camera_kernel(benchmark, cornell):
    from reference_impl.kernels import camera

    benchmark(camera.camera_paths, *cornell["camera_args"])
    benchmark.extra_info["rays_per_second"] = _per_second(benchmark, N_RAYS)


@pytest.mark.benchmark(group="primary rays")
def test_primary_rays_embree_closest_hit(benchmark, cornell):
    state, intersector = cornell["state"], cornell["ctx"].intersector
    benchmark(intersector.closest_prims, state.origin32, state.direction32)
    benchmark.extra_info["rays_per_second"] = _per_second(benchmark, N_RAYS)


@pytest.mark.benchmark(group="shadow rays")
def test_shadow_rays_embree_occluded(benchmark, cornell):
    radiance = np.zeros((N_RAYS, 3))
    _, s, *_ = _run_bounce_kernel(cornell, radiance, _counters())  # (hemisphere?, shadow rays, next rays, complement rays)
    owner, o32, d32, tfar, *_ = cornell["ws"].direct(N_RAYS)[2]
    o32, d32, tfar = o32[:s].copy(), d32[:s].copy(), tfar[:s].copy()
    benchmark(cornell["ctx"].intersector.occluders, o32, d32, tfar)
    benchmark.extra_info["rays"] = int(s)
    benchmark.extra_info["rays_per_second"] = _per_second(benchmark, s)


@pytest.mark.benchmark(group="bounce")
def test_bounce_kernel_only(benchmark, cornell):
    """kernels.wavefront.bounce on the camera rays' hits: emission, light samples and shadow rays, next wavefront."""
    radiance, counters = np.zeros((N_RAYS, 3)), _counters()
    benchmark(_run_bounce_kernel, cornell, radiance, counters)
    benchmark.extra_info["paths_per_second"] = _per_second(benchmark, N_RAYS)


@pytest.mark.benchmark(group="bounce")
def test_bounce_with_queries(benchmark, cornell):
    """integrator._bounce: closest hits, the kernel, the shadow rays and their resolution."""
    from reference_impl import integrator

    ctx, ws, state = cornell["ctx"], cornell["ws"], cornell["state"]
    radiance, counters, clock = np.zeros((N_RAYS, 3)), _counters(), integrator._Clock()
    benchmark(integrator._bounce, ctx, state, 1, radiance, counters, clock, ws.state(1, N_RAYS), cornell["film_samples"],
              ctx.config)
    benchmark.extra_info["paths_per_second"] = _per_second(benchmark, N_RAYS)


@pytest.mark.benchmark(group="bounce")
def test_bounce_numpy_baseline(benchmark, cornell):
    """The same first bounce by the numpy integrator (git baseline)."""
    baseline = load_baseline()
    if baseline is None:
        pytest.skip("the numpy integrator is not available from git")
    from reference_impl import Film, Settings

    scene, geometry = _scene("cornell-box")
    g, cam, film, settings = convert_inputs(baseline, geometry, scene.camera, Film(256, 256, "box"),
                                            Settings(spp=1, seed=0, max_depth=scene.max_depth, threads=1))
    bi = baseline.integrator
    ctx = bi._Context(g, cam, film, settings)
    state = cornell["state"]
    old_state = bi._PathState(root=np.arange(N_RAYS), key=state.key.copy(), origin=state.origin.copy(),
                              direction=state.direction.copy(), beta=state.beta.copy(), pdf_dir=None)
    radiance = np.zeros((N_RAYS, 3))
    benchmark(bi._bounce, ctx, old_state, 1, radiance, dict.fromkeys(bi.COUNTERS, 0))
    benchmark.extra_info["paths_per_second"] = _per_second(benchmark, N_RAYS)


def _frame_inputs(threads: int):
    from reference_impl import Film, Settings

    scene, geometry = _scene("cornell-box")
    return geometry, scene.camera, Film(64, 64, "box"), Settings(spp=16, seed=0, max_depth=scene.max_depth, threads=threads)


@pytest.mark.benchmark(group="frame")
@pytest.mark.parametrize("threads", [1, 2])
def test_frame_cornell_64px_16spp(benchmark, threads):
    """A whole small frame: the Cornell box, 64 x 64 pixels, 16 spp, max_depth 8."""
    import reference_impl as ri

    inputs = _frame_inputs(threads)
    ri.render(*inputs)  # load the compiled kernels outside the timing
    out = benchmark(ri.render, *inputs)
    benchmark.extra_info["paths_per_second"] = _per_second(benchmark, out.stats["paths"])
    benchmark.extra_info["embree_fraction"] = out.stats["embree_microseconds"] / 1e6 / (out.seconds * threads)


@pytest.mark.benchmark(group="frame")
@pytest.mark.parametrize("threads", [1, 2])
def test_frame_cornell_64px_16spp_numpy_baseline(benchmark, threads):
    baseline = load_baseline()
    if baseline is None:
        pytest.skip("the numpy integrator is not available from git")
    inputs = convert_inputs(baseline, *_frame_inputs(threads))
    out = benchmark(baseline.render, *inputs)
    benchmark.extra_info["paths_per_second"] = _per_second(benchmark, out.stats["paths"])
