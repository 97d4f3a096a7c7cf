"""Embree's own rate on a render's own rays: the rays the reference traces, recorded once, then sent to Embree again
through the same C API queries, in compiled loops that do nothing else, on the render's number of threads.

:func:`record_rays` traces a part of a render (the scene's settings and spp, all samples of whole pixels spread over
the film, until ``max_rays`` are recorded) and keeps every query: the camera rays in the batches that went to Embree
in packets of 16 (``rtcIntersect16``), the closest-hit rays past the camera (indirect rays, and hemisphere sampling's
direct-light rays), the occlusion rays with their tfar (shadow rays), each with Embree's answer. The path loop writes
its own (:mod:`reference_impl.kernels.record`), one query per ray (``rtcIntersect1``, ``rtcOccluded1``); the blocks
(:mod:`reference_impl.kernels.blocks` on a Lambertian scene lit by area lights, :mod:`reference_impl.kernels.
path_blocks` on a glossy one) write theirs with the size of each call that sent them in packets (``rtcIntersect16``,
``rtcOccluded16``: ``RayLog.packets``);
a render the wavefront traces (Ni > 1, or ``engine = wavefront``) has its rays taken from the wavefront's batched
queries.

:class:`Replay` sends them again as the render sent them (``kernels.queries.closest_prims_packets``,
``closest_prims``, ``occluders``; after the blocks, ``kernels.blocks.closest_groups`` and ``occluded_groups``, the
same packets: a loop that fills the rays' structure and calls Embree), each kind of query split into one contiguous
share per thread of a thread pool (whole calls of the render's), timed with ``time.perf_counter`` (monotonic) from
the first share's start to the last one's end; :meth:`Replay.mismatches` compares the answers with the recorded
ones, so that the replay is the same work.

    closest-hit rate = (camera + closest-hit rays) / (their replay seconds)
    occlusion rate   = occlusion rays / their replay seconds
    combined rate    = all rays / all replay seconds                 (the scene's mix of queries)

The combined rate is what the renderer's rays per second would be if tracing cost nothing but Embree's queries,
issued as the renderer issues them: one ray at a time or in the render's packets.
"""

from __future__ import annotations

import statistics
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from reference_impl import integrator
from reference_impl.camera import Camera, Film
from reference_impl.emitters import Emitters
from reference_impl.geometry import Geometry
from reference_impl.materials import Materials
from reference_impl.settings import Settings

PHASES = ("camera", "closest", "occlusion")
DEFAULT_MAX_RAYS = 2_000_000
ROOM_PER_PATH = 4  # closest-hit and occlusion queries per camera path the path loop's record first has room for


@dataclass
class RayLog:
    """The recorded queries of a part of a render (see the module docstring).

    camera    list of (o32 (n, 3), d32 (n, 3), prim (n,) int32): one entry per batch of camera rays, as traced in
              packets of 16 consecutive rays
    closest   list of (o64, d64, prim int32): closest-hit rays past the camera (-1: a miss), in float64 as the
              sphere tests take them (Embree's query rounds them to float32; the wavefront's are float32 already)
    occlusion list of (o64, d64, tfar32 (n,), blocked (n,) int8 1/0): occlusion rays
    closest_groups, occlusion_groups
              where ``packets``: lists of int64 arrays, one per entry of ``closest`` / ``occlusion``, the number of
              rays each of the render's calls sent in packets of ``packet_width`` (kernels.records.RayRecord)
    packets   whether the render sent the rays past the camera in packets (the blocks), not one per query
    paths     camera paths traced; ``stats`` their counters (integrator.COUNTERS)
    """

    scene_pointer: int = 0
    packet_width: int = 16
    spheres: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # tested beside Embree (kernels.queries)
    sphere_base: int = 0
    threads: int = 1
    camera: list = field(default_factory=list)
    closest: list = field(default_factory=list)
    occlusion: list = field(default_factory=list)
    closest_groups: list = field(default_factory=list)
    occlusion_groups: list = field(default_factory=list)
    packets: bool = False
    paths: int = 0
    stats: dict = field(default_factory=dict)
    owner: object = field(default=None, repr=False)  # keeps the Embree scene alive

    def count(self, phase: str) -> int:
        return sum(len(entry[0]) for entry in getattr(self, phase))

    @property
    def rays(self) -> int:
        return sum(self.count(phase) for phase in PHASES)


class _Recorder:
    """An Intersector that keeps a copy of every batched query and its answer (the wavefront's queries)."""

    def __init__(self, inner, log: RayLog):
        self._inner, self._log = inner, log

    def __getattr__(self, name):
        return getattr(self._inner, name)

    def closest_prims_coherent(self, origins, directions):
        prim = self._inner.closest_prims_coherent(origins, directions)
        self._log.camera.append((origins.copy(), directions.copy(), prim.copy()))
        return prim

    def closest_prims(self, origins, directions):
        prim = self._inner.closest_prims(origins, directions)
        self._log.closest.append((origins.copy(), directions.copy(), prim.copy()))
        return prim

    def occluders(self, origins, directions, tfar):
        hit = self._inner.occluders(origins, directions, tfar)
        self._log.occlusion.append((origins.copy(), directions.copy(), tfar.copy(), (hit >= 0).astype(np.int8)))
        return hit


def _spread(n: int) -> list[int]:
    """0 .. n-1 in bit-reversed (van der Corput) order: any prefix is spread evenly over the range."""
    bits = max(1, (n - 1).bit_length())
    return sorted(range(n), key=lambda i: int(format(i, f"0{bits}b")[::-1], 2))


def _trace_path_recorded(ctx, pixel, sample, stats, log: RayLog) -> None:
    """Trace camera samples with the path loop, keeping its queries; a batch whose queries overflow the buffers
    is traced again with room for all of them (the same rays)."""
    from reference_impl.kernels import records  # optional: numba-compiled, loaded only to trace

    n = len(pixel)
    room = (ROOM_PER_PATH * n, ROOM_PER_PATH * n)
    while True:
        record = records.ray_record(n, *room)
        attempt = dict.fromkeys(stats, 0)
        integrator._trace_camera_paths(ctx, pixel, sample, attempt, record)
        closest, occlusion = int(record.counts[records.COUNT_CLOSEST]), int(record.counts[records.COUNT_OCCLUSION])
        if closest <= room[0] and occlusion <= room[1]:
            break
        room = (max(room[0], closest), max(room[1], occlusion))
    for key, value in attempt.items():
        stats[key] += value
    log.camera.append((record.camera_origin, record.camera_direction, record.camera_prim))
    log.closest.append((record.closest_origin[:closest], record.closest_direction[:closest],
                        record.closest_prim[:closest]))
    log.occlusion.append((record.occlusion_origin[:occlusion], record.occlusion_direction[:occlusion],
                          record.occlusion_tfar[:occlusion], record.occlusion_blocked[:occlusion]))
    if log.packets:
        log.closest_groups.append(record.closest_groups[:int(record.counts[records.COUNT_CLOSEST_GROUPS])])
        log.occlusion_groups.append(record.occlusion_groups[:int(record.counts[records.COUNT_OCCLUSION_GROUPS])])


def record_rays(geometry: Geometry, camera: Camera, film: Film, settings: Settings, emitters: Emitters | None = None,
                materials: Materials | None = None, *, max_rays: int = DEFAULT_MAX_RAYS) -> RayLog:
    """Record the queries of a part of the render ``render(geometry, camera, film, settings, emitters=emitters,
    materials=materials)`` would make: all ``settings.spp`` samples of runs of consecutive pixels, the runs taken in
    an order that spreads them over the film, until at least ``max_rays`` queries are recorded (or the whole film
    is). The rays are those of the render (same settings, seed and pixels). Single-threaded: the threads count
    only in the replay (``log.threads`` = the render's)."""
    ctx = integrator._Context(geometry, camera, film, settings, emitters, materials)
    settings = ctx.settings
    log = RayLog(scene_pointer=ctx.intersector.scene_pointer, packet_width=ctx.intersector.packet_width,
                 spheres=ctx.intersector.spheres, sphere_base=ctx.intersector.sphere_base,
                 threads=settings.worker_threads(),
                 stats=dict.fromkeys(integrator.COUNTERS, 0) | {integrator.EMBREE_MICROSECONDS: 0},
                 owner=ctx.intersector, packets=ctx.blocks or ctx.path_blocks)
    if not ctx.has_lights or log.scene_pointer == 0:  # the render traces no ray at all
        return log
    if ctx.engine != "path":  # the wavefront's rays, from its batched queries
        ctx.intersector = _Recorder(ctx.intersector, log)
    spp = settings.spp
    num_pixels = film.width * film.height
    batch = max(spp, min(settings.batch_size, max_rays // 64))  # paths per batch: a few dozen batches at most
    pixels_per_run = max(1, min(num_pixels, batch // spp))
    samples_per_batch = max(1, min(spp, batch))
    runs = [(p0, min(num_pixels, p0 + pixels_per_run)) for p0 in range(0, num_pixels, pixels_per_run)]
    for index in _spread(len(runs)):
        p0, p1 = runs[index]
        for s0 in range(0, spp, samples_per_batch):
            s1 = min(spp, s0 + samples_per_batch)
            pixel = np.repeat(np.arange(p0, p1, dtype=np.int64), s1 - s0)
            sample = np.tile(np.arange(s0, s1, dtype=np.int64), p1 - p0)
            if ctx.engine == "path":
                _trace_path_recorded(ctx, pixel, sample, log.stats, log)
            else:
                integrator._trace_camera_paths(ctx, pixel, sample, log.stats)
            log.paths += len(pixel)
        if log.rays >= max_rays:
            break
    return log


def _shares(sizes: list[int], parts: int) -> list[list[int]]:
    """Consecutive entries of ``sizes`` grouped into at most ``parts`` groups of about equal sums (indices)."""
    total = sum(sizes)
    groups: list[list[int]] = [[] for _ in range(parts)]
    done = 0
    for index, size in enumerate(sizes):
        groups[min(parts - 1, done * parts // max(total, 1))].append(index)
        done += size
    return [g for g in groups if g]


class Replay:
    """The queries of ``log`` sent to Embree again on ``threads`` worker threads (a thread pool, as the render's).
    :meth:`run` replays every query once and returns the time of each phase; :meth:`mismatches` compares the
    answers of the last run with the recorded ones."""

    def __init__(self, log: RayLog, threads: int | None = None):
        from reference_impl.kernels import blocks, queries  # optional: numba-compiled, loaded only to trace

        self._queries = queries
        self._blocks = blocks
        self.log = log
        self.threads = threads or log.threads
        self.counts = {phase: log.count(phase) for phase in PHASES}

        def joined(entries, columns):
            if not entries:
                return tuple(np.empty((0, 3) if c < 2 else 0, dt) for c, dt in enumerate(columns))
            return tuple(np.ascontiguousarray(np.concatenate([e[c] for e in entries]), dtype=dt)
                         for c, dt in enumerate(columns))

        self._closest = joined(log.closest, (np.float64, np.float64, np.int32))
        self._occlusion = joined(log.occlusion, (np.float64, np.float64, np.float32, np.int8))
        self._camera_out = [np.full(len(e[2]), -1, np.int32) for e in log.camera]
        self._closest_out = np.full(self.counts["closest"], -1, np.int32)
        self._occlusion_out = np.full(self.counts["occlusion"], -1, np.int32)
        self._camera_shares = _shares([len(e[2]) for e in log.camera], self.threads)
        if log.packets:  # whole calls of the render's per share: (first ray, end, the calls' sizes)
            self._closest_shares = self._group_shares(log.closest_groups)
            self._occlusion_shares = self._group_shares(log.occlusion_groups)
        else:
            self._closest_shares = self._ranges(self.counts["closest"])
            self._occlusion_shares = self._ranges(self.counts["occlusion"])
        self._pool = ThreadPoolExecutor(max_workers=self.threads)

    def _ranges(self, n: int) -> list[tuple[int, int]]:
        bounds = np.linspace(0, n, self.threads + 1).astype(np.int64)
        return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]

    def _group_shares(self, groups: list) -> list[tuple[int, int, np.ndarray]]:
        sizes = np.concatenate(groups).astype(np.int64) if groups else np.zeros(0, np.int64)
        starts = np.concatenate(([0], np.cumsum(sizes)))
        return [(int(starts[g[0]]), int(starts[g[-1] + 1]), np.ascontiguousarray(sizes[g[0]:g[-1] + 1]))
                for g in _shares(sizes.tolist(), self.threads)]

    def _camera(self, share):
        ptr, log = self.log.scene_pointer, self.log
        for index in share:
            o, d, _ = log.camera[index]
            self._queries.closest_prims_packets(ptr, log.packet_width, o, d, self._camera_out[index], log.spheres,
                                                log.sphere_base)

    def _closest_share(self, share):
        o, d, _ = self._closest
        if self.log.packets:
            a, b, sizes = share
            self._blocks.closest_groups(self.log.scene_pointer, self.log.packet_width, o[a:b], d[a:b], sizes,
                                        self._closest_out[a:b], self.log.spheres, self.log.sphere_base)
            return
        a, b = share
        self._queries.closest_prims(self.log.scene_pointer, o[a:b], d[a:b], self._closest_out[a:b], self.log.spheres,
                                    self.log.sphere_base)

    def _occlusion_share(self, share):
        o, d, t, _ = self._occlusion
        if self.log.packets:
            a, b, sizes = share
            self._blocks.occluded_groups(self.log.scene_pointer, self.log.packet_width, o[a:b], d[a:b], t[a:b], sizes,
                                         self._occlusion_out[a:b], self.log.spheres)
            return
        a, b = share
        self._queries.occluders(self.log.scene_pointer, o[a:b], d[a:b], t[a:b], self._occlusion_out[a:b],
                                self.log.spheres)

    def run(self) -> dict[str, tuple[float, float]]:
        """Replay every recorded query once, phase by phase: {phase: (wall seconds, process CPU seconds)}."""
        out = {}
        for phase, work, shares in (("camera", self._camera, self._camera_shares),
                                    ("closest", self._closest_share, self._closest_shares),
                                    ("occlusion", self._occlusion_share, self._occlusion_shares)):
            if not shares:
                out[phase] = (0.0, 0.0)
                continue
            cpu0, wall0 = time.process_time(), time.perf_counter()
            for _ in self._pool.map(work, shares):
                pass
            out[phase] = (time.perf_counter() - wall0, time.process_time() - cpu0)
        return out

    def mismatches(self) -> dict[str, int]:
        """Queries of the last :meth:`run` whose answer differs from the recorded one, per phase."""
        camera = sum(int(np.count_nonzero(out != entry[2])) for out, entry in zip(self._camera_out, self.log.camera))
        closest = int(np.count_nonzero(self._closest_out != self._closest[2]))
        occlusion = int(np.count_nonzero((self._occlusion_out >= 0) != (self._occlusion[3] == 1)))
        return {"camera": camera, "closest": closest, "occlusion": occlusion}

    def close(self) -> None:
        self._pool.shutdown()


def rates(counts: dict[str, int], runs: list[dict[str, tuple[float, float]]]) -> dict:
    """Rays per second of the replays ``runs`` (:meth:`Replay.run`'s results) of ``counts`` rays per phase: each
    phase's median wall time, and the rates of the module docstring; ``cores_busy`` = CPU time / wall time over all
    the runs."""
    seconds = {phase: statistics.median(run[phase][0] for run in runs) if runs else float("nan") for phase in PHASES}
    wall = sum(w for run in runs for w, _ in run.values())
    cpu = sum(c for run in runs for _, c in run.values())

    def per_second(rays: int, secs: float) -> float:
        return rays / secs if secs > 0 else float("nan")

    closest = counts["camera"] + counts["closest"]
    return {
        "rays": dict(counts),
        "seconds": seconds,
        "closest_hit_rays_per_second": per_second(closest, seconds["camera"] + seconds["closest"]),
        "occlusion_rays_per_second": per_second(counts["occlusion"], seconds["occlusion"]),
        "rays_per_second": per_second(sum(counts.values()), sum(seconds.values())),
        "cores_busy": cpu / wall if wall > 0 else float("nan"),
    }


def replay_rays(log: RayLog, threads: int | None = None, repeats: int = 3) -> dict:
    """Replay ``log`` once untimed (loads the kernels, starts the threads), then ``repeats`` times: :func:`rates`,
    with ``threads`` and ``mismatches`` (per phase, after the last run; all 0 when the replay is the same work)."""
    replay = Replay(log, threads)
    try:
        replay.run()
        runs = [replay.run() for _ in range(repeats)]
        return rates(replay.counts, runs) | {"threads": replay.threads, "mismatches": replay.mismatches()}
    finally:
        replay.close()


__all__ = ["DEFAULT_MAX_RAYS", "PHASES", "RayLog", "Replay", "rates", "record_rays", "replay_rays"]
