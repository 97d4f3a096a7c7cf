"""Rendering a case's test image within its budget: ``spp`` samples at once, or chunks of ``chunk_spp`` until
``seconds`` of render time are spent (merged exactly, :mod:`harness.judges.moments`). A Mitsuba render of an spp
budget goes through the ground-truth cache (:mod:`harness.renderers.cached`)."""

from __future__ import annotations

import dataclasses
import itertools
import time

import numpy as np

from harness.judges.moments import Estimate, merge
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.cached import cached_mitsuba_render
from harness.running.cases import Case


def render_with_budget(case: Case, scene, variant: str | None, progress=None, cache_dir=None):
    """Render a case's test image within its budget: spp at once, or chunks of chunk_spp until ``seconds``."""
    renderer = get_renderer(case.renderer)
    settings = dict(case.settings)
    if case.renderer == "mitsuba" and variant and "variant" not in settings:
        settings["variant"] = variant
    if case.renderer == "mitsuba" and case.spp is not None and set(settings) <= {"variant"}:
        return _cached_mitsuba_render(case, scene, settings.get("variant"), cache_dir, progress)
    if case.spp is not None:
        return renderer.render(scene, RenderRequest(spp=case.spp, seed=case.seed, settings=settings, progress=progress))
    seeds = (case.seed + 7919 * index for index in itertools.count())
    return render_for_seconds(renderer, scene, case.seconds, case.chunk_spp, seeds, settings, progress)


def render_for_seconds(renderer, scene, seconds: float, chunk_spp: int, seeds, settings: dict[str, str],
                       progress=None):
    """Render chunks of ``chunk_spp`` (seeds drawn from the iterator ``seeds``) until ``seconds`` of render time
    are spent, and merge them exactly (``harness.judges.moments``) into one RenderResult with the summed time and rays;
    ``info["seeds"]`` lists the seeds used. The chunks also stop after :func:`wall_limit` seconds of wall time: an
    external renderer's render time excludes its process start-up, and a chunk too small to time reads 0 s, so
    render time alone might never be spent."""
    chunks, results, used, spent = [], [], [], 0.0
    wall_start, limit = time.perf_counter(), wall_limit(seconds)
    while spent < seconds and (not results or time.perf_counter() - wall_start < limit):
        seed = next(seeds)
        result = renderer.render(scene, RenderRequest(spp=chunk_spp, seed=seed, settings=dict(settings)))
        spent += result.seconds
        results.append(result)
        used.append(seed)
        chunks.append(Estimate(result.image, result.variance, result.spp))
        if progress is not None:
            progress(min(spent, seconds), seconds)
    merged = merge(chunks)
    first = results[0]
    return dataclasses.replace(
        first, image=merged.mean.astype(np.float32), variance=merged.variance.astype(np.float32),
        seconds=spent, spp=merged.n,
        rays={k: sum(r.rays.get(k, 0) for r in results) for k in first.rays},
        stats={k: sum(r.stats.get(k, 0) for r in results) for k in first.stats},
        info=dict(first.info, chunks=len(results), seeds=used, **_merged_dof(results)),
    )


def _merged_dof(results) -> dict:
    """``variance_dof`` of the merged chunks where a chunk's variance has other than spp - 1 degrees of freedom
    (replicates), else nothing (spp - 1 of the whole). The merge (:func:`harness.judges.moments.merge`) pools the
    chunks' variances, each weighted n (n - 1), with the spread of their means (K - 1 dof, weight n); for K chunks
    of n samples whose variances have nu degrees of freedom, Welch and Satterthwaite's approximation gives
    (N - 1)^2 / (K (n - 1)^2 / nu + K - 1), which is N - 1 when nu = n - 1 and nu when K = 1."""
    if all(r.info.get("variance_dof") is None for r in results):
        return {}
    total = sum(r.spp for r in results)
    within = sum((r.spp - 1) ** 2 / max(r.info.get("variance_dof") or r.spp - 1, 1) for r in results)
    dof = (total - 1) ** 2 / (within + len(results) - 1)
    return {"variance_dof": max(1, int(dof))}


def wall_limit(seconds: float) -> float:
    """The wall time after which a time budget of ``seconds`` stops rendering chunks, whatever render time they
    reported: 10 x the budget + 60 s (far above any in-process renderer's overhead)."""
    return 10.0 * float(seconds) + 60.0


def _cached_mitsuba_render(case: Case, scene, variant: str | None, cache_dir, progress):
    """A Mitsuba test render through the ground-truth cache, so a suite's second run renders nothing."""
    return cached_mitsuba_render(scene, case.spp, case.seed, variant, cache_dir, progress)
