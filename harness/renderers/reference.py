"""Adapter: a :class:`~harness.scene.Scene` to the reference core's arrays, and its output to a RenderResult."""

from __future__ import annotations

import dataclasses
import re

import reference_impl
from harness.core.errors import HarnessError
from harness.core.limits import check_reference_cost
from harness.renderers.base import RenderRequest, RenderResult
from harness.scene import Scene, emitter_arrays, material_arrays, media_arrays, triangulate
from harness.scene.kinds.emitters import EMITTERS


class ReferenceRenderer:
    """The project's own path tracer (``reference_impl``), the slides' algorithm."""

    name = "reference"

    def settings_for(self, scene: Scene, request: RenderRequest) -> reference_impl.Settings:
        """Resolved core settings: defaults, then ``--set`` values, then spp, seed and the scene's max_depth."""
        values = dict(request.settings)
        for key in ("spp", "seed"):
            if key in values:
                raise HarnessError(f"--set {key}", f"give {key} with --{key}, not --set")
        _check_integer_texts(values)
        try:
            settings = reference_impl.Settings.from_strings(values)
            settings = dataclasses.replace(settings, spp=request.spp, seed=request.seed)
            settings = settings.resolved(scene.has_glossy_materials)  # every reader sees the run ones
            if settings.max_depth is None:
                settings = dataclasses.replace(settings, max_depth=scene.max_depth)
            settings.resolved_max_depth(settings.max_depth)
        except reference_impl.SettingsError as err:
            raise HarnessError(f"--set {err.key}", err.message) from None
        _check_cost(scene, settings)
        return settings

    def check(self, scene: Scene, request: RenderRequest) -> None:
        """Refuse bad ``--set`` values before any work (HarnessError at ``--set KEY``)."""
        self.settings_for(scene, request)

    #: the arrays of the last scene rendered by any ReferenceRenderer of this process (scene, geometry, emitters,
    #: materials, media): renders of one scene object in a row (the studies render each scene hundreds of times, each through
    #: a renderer of its own) triangulate it once
    _prepared: tuple | None = None

    def _arrays(self, scene: Scene) -> tuple:
        prepared = ReferenceRenderer._prepared
        if prepared is None or prepared[0] is not scene:
            # None on Lambertian-only scenes: the engines they always ran
            geometry = triangulate(scene)
            prepared = ReferenceRenderer._prepared = (scene, geometry, emitter_arrays(scene), material_arrays(scene),
                                                      media_arrays(scene, geometry))
        return prepared[1:]

    def render(self, scene: Scene, request: RenderRequest) -> RenderResult:
        settings = self.settings_for(scene, request)
        geometry, emitters, materials, media = self._arrays(scene)
        extra = {} if materials is None else {"materials": materials}
        if media is not None:
            extra["media"] = media
        try:
            out = reference_impl.render(geometry, scene.camera, scene.film, settings, progress=request.progress,
                                        emitters=emitters, **extra)
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
            info=_info(settings, geometry, out),
            load_seconds=out.load_seconds,
        )


def _info(settings: reference_impl.Settings, geometry, out) -> dict:
    """The render's ``info``: threads and triangles, and with replicates (``--set replicates``) their number and
    ``variance_dof`` = R - 1, which tells the verdict how many degrees of freedom the variance has (written to the
    EXR by ``variance_metadata``)."""
    info = {"threads": settings.worker_threads(), "triangles": int(len(geometry.triangles))}
    replicates = len(settings.replicate_sizes())
    if replicates > 1:
        info.update(replicates=replicates, variance_dof=out.variance_dof)
    return info


_PLAIN_INTEGER = re.compile(r"-?[0-9]+")
#: settings that shape the work per camera sample, the first non-default of which a cost refusal names
COST_SETTINGS = ("indirect_rays", "shadow_rays", "max_depth", "batch_size", "threads")


def _check_integer_texts(values: dict) -> None:
    """Refuse ``--set KEY=VALUE`` text for an integer setting that is not plain decimal digits (``int()`` takes
    ``1_000`` and other scripts' digits too)."""
    defaults = reference_impl.Settings()
    for key, text in values.items():
        default = getattr(defaults, key, None)
        integer = key == "max_depth" or (isinstance(default, int) and not isinstance(default, bool))
        if not integer or not isinstance(text, str):
            continue
        if key == "max_depth" and text.strip().lower() in ("", "none", "scene"):
            continue
        if not _PLAIN_INTEGER.fullmatch(text.strip()):
            raise HarnessError(f"--set {key}", f"expected an integer in plain decimal digits, got {text!r}")


def _survival(scene: Scene, settings: reference_impl.Settings) -> float:
    """The largest probability that Russian roulette lets a path go on (1.0 without roulette)."""
    if settings.rr == "off":
        return 1.0
    if settings.rr == "fixed":
        return 1.0 - settings.absorption
    if settings.rr == "throughput":
        return 0.95  # Mitsuba's cap (kernels/path.py)
    # "albedo" and "pbrt" (whose survival, min(1, throughput), falls as fast as the reflectances multiply)
    return max((max(m.reflectance) for m in scene.materials.values()), default=0.0)


def _complement_rays(scene: Scene, settings: reference_impl.Settings) -> int:
    """Shadow rays per hit for the emitters the direct strategy cannot find (docs/reference-renderer.md, "What a
    strategy cannot find"): delta lights under hemisphere sampling, and the environment too under global area."""
    finds_environment = {"hemisphere-cosine": True, "hemisphere-uniform": True, "global-area": False}
    if settings.direct not in finds_environment:
        return 0
    return sum(1 for e in scene.emitters
               if not (finds_environment[settings.direct] and EMITTERS[e.type].environment))


def _check_cost(scene: Scene, settings: reference_impl.Settings) -> None:
    """Refuse settings whose memory or time estimate (harness.core.limits.reference_cost) is absurd, before anything is
    allocated: one line at ``--set KEY`` for the first setting of COST_SETTINGS that is not its default."""
    defaults = reference_impl.Settings()
    changed = [key for key in COST_SETTINGS if getattr(settings, key) != getattr(defaults, key)
               and not (key == "max_depth" and settings.max_depth == scene.max_depth)]
    where = f"--set {changed[0]}" if changed else "--spp"
    shown = ", ".join(f"{key} = {getattr(settings, key)}" for key in COST_SETTINGS[:3])
    check_reference_cost(
        scene.film.width, scene.film.height, settings.spp, where=where, settings_text=shown,
        lower=f"{', '.join(changed)}, --spp or the film" if changed else "--spp or the film",
        shadow_rays=settings.shadow_rays + _complement_rays(scene, settings), indirect_rays=settings.indirect_rays,
        max_depth=settings.max_depth,
        survival=_survival(scene, settings), rr_depth=settings.rr_depth, mis=settings.direct in ("mis", "bsdf"),
        hemisphere_direct=settings.direct in ("hemisphere-cosine", "hemisphere-uniform"),
        batch_size=settings.batch_size, threads=settings.worker_threads(), envmap=scene.envmap_size)
