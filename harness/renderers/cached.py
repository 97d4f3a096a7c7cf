"""Mitsuba behind the ground-truth cache (:mod:`harness.renderers.groundtruth`): a Mitsuba render already made
(same scene, spp, seed, variant) is read back, not made again, so a suite's, a report's or a study's second run
performs no Mitsuba render."""

from __future__ import annotations

from harness.core.errors import HarnessError
from harness.renderers import groundtruth
from harness.renderers.base import RenderResult


def cached_mitsuba_render(scene, spp: int, seed: int, variant: str | None, cache_dir, progress=None, chunk_spp=None):
    """A Mitsuba render of ``spp`` samples through the ground-truth cache, as a RenderResult. Its ``seconds`` is
    the time the render took when it was made (from the cache entry's metadata)."""
    gt = groundtruth.ground_truth(scene, spp=spp, seed=seed, cache_dir=cache_dir, variant=variant,
                                  use_closed_form=False, progress=progress,
                                  chunk_spp=chunk_spp or groundtruth.DEFAULT_CHUNK_SPP)
    info = dict(gt.info.get("info", {}), cached=gt.cached, mitsuba_renders=gt.renders)
    width, height = scene.film.width, scene.film.height
    return RenderResult(
        renderer="mitsuba", image=gt.image, variance=gt.variance,
        seconds=float(gt.info.get("render_seconds", gt.seconds)),
        spp=gt.spp, rays={"camera": width * height * gt.spp}, stats={"mitsuba_renders": gt.renders},
        settings={"spp": gt.spp, "seed": seed, "variant": gt.info.get("variant")}, info=info,
    )


class CachedMitsubaRenderer:
    """:func:`cached_mitsuba_render` behind the renderer protocol (``render(scene, request)``), for reports and
    studies; it takes no settings but ``variant``."""

    name = "mitsuba"

    def __init__(self, cache_dir=None, variant: str | None = None):
        self.cache_dir = cache_dir
        self.variant = variant

    def render(self, scene, request):
        variant = request.settings.get("variant", self.variant)
        if set(request.settings) - {"variant"}:
            raise HarnessError("--set", "cached Mitsuba renders take no settings but the variant")
        return cached_mitsuba_render(scene, request.spp, request.seed, variant, self.cache_dir, request.progress,
                                     chunk_spp=request.spp)
