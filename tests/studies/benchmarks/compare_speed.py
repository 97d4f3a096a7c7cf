"""Old (numpy integrator, from git) vs new (compiled kernels) render speed, in one process, alternating.

    .venv/bin/python tests/benchmarks/compare_speed.py [--scene cornell-box] [--size 256] [--spp 64]
        [--threads 2] [--reps 3] [--profile] [--rev REV]

Prints paths/s of each render, the fraction of the workers' time spent inside Embree queries, whether the images
are identical, and the median of the per-repetition speed ratios. On a shared machine only ratios measured in the
same run mean anything. ``--profile`` adds a cProfile of one batch of camera paths (one thread) for each.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _baseline import ROOT, baseline_rev, convert_inputs, load_baseline  # noqa: E402

import reference_impl as ri  # noqa: E402
from harness.scene import load_scene, triangulate  # noqa: E402
from reference_impl import integrator  # noqa: E402


class _EmbreeTimer:
    """Wraps an embreex scene and sums the seconds spent in ``run`` (the baseline has no counter of its own)."""

    seconds = 0.0
    lock = threading.Lock()

    def __init__(self, scene):
        self._scene = scene

    def run(self, *args, **kwargs):
        t = time.perf_counter()
        try:
            return self._scene.run(*args, **kwargs)
        finally:
            dt = time.perf_counter() - t
            with _EmbreeTimer.lock:
                _EmbreeTimer.seconds += dt


def _instrument(baseline):
    cls = baseline.intersect.Intersector
    if getattr(cls, "_timed", False):
        return
    init = cls.__init__

    def timed_init(self, geometry):
        init(self, geometry)
        if self._embree is not None:
            self._embree = _EmbreeTimer(self._embree)

    cls.__init__ = timed_init
    cls._timed = True


def _profile(trace, ctx, n, spp, counters) -> str:
    num_pixels = ctx.film.width * ctx.film.height
    pixels = np.unique(np.linspace(0, num_pixels - 1, max(1, n // spp)).astype(np.int64))  # spread over the image
    pixel = np.repeat(pixels, spp)
    sample = np.tile(np.arange(spp, dtype=np.int64), len(pixels))
    trace(ctx, pixel, sample, dict(counters))  # warm
    prof = cProfile.Profile()
    prof.enable()
    trace(ctx, pixel, sample, dict(counters))
    prof.disable()
    out = io.StringIO()
    pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(14)
    return out.getvalue()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="cornell-box")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--rev", default=None, help="git revision of the numpy integrator (default: %(default)s -> "
                    f"{baseline_rev()})")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="extra settings")
    args = ap.parse_args(argv)

    baseline = load_baseline(args.rev)
    if baseline is None:
        print(f"cannot load the numpy integrator from git revision {args.rev or baseline_rev()}", file=sys.stderr)
        return 2
    importlib_intersect = __import__(f"{baseline.__name__}.intersect", fromlist=["x"])
    baseline.intersect = importlib_intersect
    _instrument(baseline)

    scene = load_scene(ROOT / "scenes" / f"{args.scene}.toml")
    geometry = triangulate(scene)
    film = ri.Film(args.size, args.size, scene.film.filter)
    extra = dict(kv.split("=", 1) for kv in args.set)
    settings = ri.Settings.from_strings(extra, ri.Settings(spp=args.spp, seed=0, max_depth=scene.max_depth,
                                                           threads=args.threads))
    old_inputs = convert_inputs(baseline, geometry, scene.camera, film, settings)
    ri.render(geometry, scene.camera, ri.Film(8, 8), settings)  # load (or compile) the kernels
    print(f"scene {args.scene} {args.size}x{args.size}, spp {args.spp}, threads {args.threads}, "
          f"baseline {args.rev or baseline_rev()}, cpus {os.cpu_count()}, load {os.getloadavg()}")

    ratios = []
    for rep in range(args.reps):
        _EmbreeTimer.seconds = 0.0
        old = baseline.render(*old_inputs)
        old_pps = old.stats["paths"] / old.seconds
        old_embree = _EmbreeTimer.seconds / (old.seconds * args.threads)
        new = ri.render(geometry, scene.camera, film, settings)
        new_pps = new.stats["paths"] / new.seconds
        new_embree = new.stats[integrator.EMBREE_MICROSECONDS] / 1e6 / (new.seconds * args.threads)
        same = old.image.tobytes() == new.image.tobytes() and old.variance.tobytes() == new.variance.tobytes()
        ratios.append(new_pps / old_pps)
        print(f"rep {rep}: numpy {old.seconds:6.2f} s {old_pps / 1e6:6.3f} M paths/s (Embree {old_embree:5.1%}) | "
              f"kernels {new.seconds:6.2f} s {new_pps / 1e6:6.3f} M paths/s (Embree {new_embree:5.1%}) | "
              f"ratio {new_pps / old_pps:5.2f} | identical image and variance: {same}", flush=True)
    if ratios:
        print(f"median speed ratio kernels / numpy: {np.median(ratios):.2f}  (load after: {os.getloadavg()})")

    if args.profile:
        n = min(1 << 16, args.size * args.size * args.spp)
        one = ri.Settings.from_strings({"threads": "1"}, settings)
        ctx_new = integrator._Context(geometry, scene.camera, film, one)
        counters = dict.fromkeys(integrator.COUNTERS, 0)
        counters[integrator.EMBREE_MICROSECONDS] = 0
        print("\n=== kernels: cProfile of one batch of", n, "camera paths (pixels spread over the image), one thread ===")
        print(_profile(integrator._trace_camera_paths, ctx_new, n, args.spp, counters))
        g, cam, f, s = convert_inputs(baseline, geometry, scene.camera, film, one)
        ctx_old = baseline.integrator._Context(g, cam, f, s)
        print("=== numpy: cProfile of one batch of", n, "camera paths (pixels spread over the image), one thread ===")
        print(_profile(baseline.integrator._trace_camera_paths, ctx_old, n, args.spp,
                       dict.fromkeys(baseline.integrator.COUNTERS, 0)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
