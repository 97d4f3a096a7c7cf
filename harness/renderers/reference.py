"""Adapter: a :class:`~harness.scene.Scene` to the reference core's arrays, and its output to a RenderResult."""

from __future__ import annotations

import dataclasses

import reference_impl
from harness.errors import HarnessError
from harness.renderers.base import RenderRequest, RenderResult
from harness.scene import Scene, triangulate


class ReferenceRenderer:
    """The project's own path tracer (``reference_impl``), the slides' algorithm."""

    name = "reference"

    def settings_for(self, scene: Scene, request: RenderRequest) -> reference_impl.Settings:
        """Resolved core settings: defaults, then ``--set`` values, then spp, seed and the scene's max_depth."""
        values = dict(request.settings)
        for key in ("spp", "seed"):
            if key in values:
                raise HarnessError(f"--set {key}", f"give {key} with --{key}, not --set")
        try:
            settings = reference_impl.Settings.from_strings(values)
            settings = dataclasses.replace(settings, spp=request.spp, seed=request.seed)
            if settings.max_depth is None:
                settings = dataclasses.replace(settings, max_depth=scene.max_depth)
            settings.resolved_max_depth(settings.max_depth)
        except reference_impl.SettingsError as err:
            raise HarnessError(f"--set {err.key}", err.message) from None
        return settings

    def check(self, scene: Scene, request: RenderRequest) -> None:
        """Refuse bad ``--set`` values before any work (HarnessError at ``--set KEY``)."""
        self.settings_for(scene, request)

    def render(self, scene: Scene, request: RenderRequest) -> RenderResult:
        settings = self.settings_for(scene, request)
        geometry = triangulate(scene)
        try:
            out = reference_impl.render(geometry, scene.camera, scene.film, settings, progress=request.progress)
        except reference_impl.SettingsError as err:
            raise HarnessError(f"{scene.path}: {err.key}", err.message) from None
        stats = dict(out.stats)
        rays = {
            "camera": stats["camera_rays"],
            "shadow": stats["shadow_rays"] + stats["hemisphere_direct_rays"],
            "indirect": stats["indirect_rays"],
        }
        return RenderResult(
            renderer=self.name,
            image=out.image,
            variance=out.variance,
            seconds=out.seconds,
            spp=settings.spp,
            rays=rays,
            stats=stats,
            settings=settings.as_dict(),
            info={"threads": settings.worker_threads(), "triangles": int(len(geometry.triangles))},
        )
