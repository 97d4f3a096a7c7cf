"""``harness bench``'s row "embree (own rays)": Embree's own rate on the rays the reference traces on a scene.

The reference's queries of a part of the render at the bench's settings are recorded once (at most about
``max_rays``: :func:`reference_impl.replay.record_rays`) and replayed to Embree through the same C API queries, on
the render's threads, once per timed attempt of the bench, between the contenders' renders (so that a change in the
shared machine's load falls on it as on them). What it reports (:func:`reference_impl.replay.rates`):

- ``closest_hit_rays_per_second``: (camera + closest-hit rays) / their replay seconds;
- ``occlusion_rays_per_second``: occlusion rays / their replay seconds;
- ``rays_per_second``: all rays / all replay seconds (the scene's mix; each phase's median over the attempts);
- ``reference_fraction`` = the reference row's rays per second / ``rays_per_second``: how close the renderer comes
  to the speed of its queries alone (1 would mean that everything but Embree costs nothing).

The replay must give the recorded answers (``mismatches`` all 0); otherwise the row is skipped with the counts.
"""

from __future__ import annotations

import math
import time

from reference_impl import replay

from harness.renderers import RenderRequest, get_renderer
from harness.core.errors import HarnessError
from harness.scene import emitter_arrays, material_arrays, triangulate

LABEL = "embree (own rays)"
DEFAULT_MAX_RAYS = replay.DEFAULT_MAX_RAYS


class EmbreeRate:
    """The recorded rays of ``scene`` at ``spp`` (the reference at its defaults, seed ``seed``), ready to replay."""

    def __init__(self, scene, *, spp: int, seed: int = 1, max_rays: int = DEFAULT_MAX_RAYS,
                 settings: dict | None = None):
        if scene.has_media:  # replay.record_rays records the surface path loop's rays, not the volumetric one's
            raise HarnessError(str(scene.path), "the Embree rate replays the rays of the surface path loop; a scene "
                                                "with media or a null material runs the volumetric one")
        reference = get_renderer("reference")
        core = reference.settings_for(scene, RenderRequest(spp=spp, seed=seed, settings=dict(settings or {})))
        start = time.perf_counter()
        self.log = replay.record_rays(triangulate(scene), scene.camera, scene.film, core, emitter_arrays(scene),
                                      material_arrays(scene), max_rays=max_rays)
        self.record_seconds = time.perf_counter() - start
        self.max_rays = max_rays
        self._replay = replay.Replay(self.log)
        self.runs: list[dict] = []

    def warm_up(self) -> None:
        """One untimed replay: loads the query kernels and starts the pool's threads."""
        self._replay.run()

    def measure(self) -> None:
        """One timed replay of every recorded query."""
        self.runs.append(self._replay.run())

    def result(self, reference_rays_per_second: float | None) -> dict:
        """The rates (module docstring), the counts and the check, with ``error`` set where the replay's answers
        differ from the recorded ones; the replay's threads are released."""
        mismatches = self._replay.mismatches()
        self._replay.close()
        log = self.log
        rates = replay.rates(self._replay.counts, self.runs)
        combined = rates["rays_per_second"]
        out = rates | {
            "label": LABEL,
            "threads": self._replay.threads,
            "max_rays": self.max_rays,
            "recorded_rays": log.rays,
            "recorded_paths": log.paths,
            "rays_per_path": log.rays / log.paths if log.paths else math.nan,
            "record_seconds": self.record_seconds,
            "replays": len(self.runs),
            # per timed replay, the wall seconds of all its phases (the reference fraction's interval pairs them
            # with the reference's rounds: harness.studies.bench.embree_fraction_interval)
            "seconds_all": [sum(run[phase][0] for phase in run) for run in self.runs],
            "mismatches": mismatches,
            "reference_rays_per_second": reference_rays_per_second,
            "reference_fraction": (reference_rays_per_second / combined
                                   if reference_rays_per_second and combined > 0 else math.nan),
            "error": None,
        }
        if any(mismatches.values()):
            out["error"] = ("the replay's answers differ from the recorded ones: "
                            + ", ".join(f"{k} {v}" for k, v in mismatches.items() if v))
        elif not log.rays:
            out["error"] = "the render traces no ray"
        return out
