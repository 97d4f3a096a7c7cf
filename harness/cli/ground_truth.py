"""``harness ground-truth SCENE [--out FILE.exr]``: a scene's ground truth, from its closed form or rendered by
Mitsuba in cached chunks, and where it is; with ``--out``, also written as OpenEXR (R, G, B and variance.R/G/B, the
closed form's variance 0) with its PNG preview, for ``harness compare`` by hand.

SIGINT and SIGTERM stop it as they stop ``harness run`` (:mod:`harness.running.runstate`): after the Mitsuba pass
in progress (a second signal: at once), with one line and exit code 130 / 143; the chunks finished are cached, the
private folder of an entry being written is removed."""

from __future__ import annotations

import argparse
import json
import math
import sys

from harness.cli.common import EXIT_OK, SCENE_HELP, check_cost, exr_out_path, path_progress, with_film
from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import parse_set, require_non_negative, require_positive
from harness.files import imageio
from harness.renderers import RenderRequest, get_renderer, groundtruth
from harness.running import executors, runstate
from harness.scene import load_scene, scene_argument


def register(sub, common) -> None:
    """Add ``ground-truth`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("scene", help=SCENE_HELP)
    parser.add_argument("--spp", type=_spp_or_auto, default=1024,
                        help="samples per pixel (default 1024), or auto: enough that the ground truth's variance is at "
                        "most 1/4 of a test render's at --test-spp (pilot renders of both renderers)")
    parser.add_argument("--test-spp", type=options.positive_int, default=64,
                        help="with --spp auto: the test render's spp (default 64, the suites' default case budget)")
    parser.add_argument("--test-renderer", default="reference",
                        help="with --spp auto: the renderer judged against this ground truth (default reference)")
    parser.add_argument("--test-set", action="append", default=[], metavar="KEY=VALUE",
                        help="with --spp auto: a setting of the test renderer (repeatable)")
    parser.add_argument("--seed", type=options.non_negative_int, default=0,
                        help="seed every chunk's seed is derived from (default 0; part of the cache key)")
    parser.add_argument("--chunk-spp", type=options.positive_int, default=256,
                        help="samples per cached chunk (default 256)")
    parser.add_argument("--no-closed-form", action="store_true",
                        help="render with Mitsuba even if the scene has a closed form")
    parser.add_argument("--executor", default=None,
                        help="render the chunks not cached on: local (worker processes on this machine), dask (a Dask "
                        "LocalCluster) or tcp://HOST:PORT (a Dask scheduler whose workers see the cache folder at the "
                        "same path), then merge them here (default: here, one after another); the same image, bit for "
                        "bit")
    parser.add_argument("--workers", type=options.positive_int, default=None,
                        help="with --executor: worker processes of local (default 2) or dask (default 2)")
    parser.set_defaults(func=run)
    sub.add_parser(
        "ground-truth", parents=[parser, common.film(),
                 common.out("also write it to this .exr (R, G, B and variance.R/G/B; the closed form's variance is 0) "
                            "with a .png preview beside it", file=True),
                 common.json(), common.quiet(), common.cache_dir(), common.mitsuba_variant(),
                 common.allow_outside_paths()])


_SPP = options.int_type(1, what="a positive integer or auto")


def _spp_or_auto(text: str) -> int | str:
    """``--spp``: a positive integer or ``auto``."""
    return "auto" if str(text).strip().lower() == "auto" else _SPP(text)


def _compute(args: argparse.Namespace, scene, auto: bool, test_settings: dict, progress):
    """``--spp auto``'s choice (None without it) and the ground truth; ``progress(done, total)`` after every pass."""
    chosen = None
    if auto and not (scene.closed_form and not args.no_closed_form):
        chosen = groundtruth.auto_spp(scene, test_spp=args.test_spp, test_renderer=args.test_renderer,
                                      test_settings=test_settings, variant=args.mitsuba_variant, seed=args.seed)
        args.spp = chosen.spp
        if not args.json:
            print(f"{scene.name}: --spp auto chose {chosen.reason()}")
    elif auto:
        args.spp = 1  # a closed form: nothing to render
    for option, value in (("--spp", args.spp), ("--chunk-spp", args.chunk_spp)):
        check_cost(scene, value, option)  # with a closed form too: a budget no render could meet is a typo
    if args.executor is not None and not (scene.closed_form and not args.no_closed_form):
        _render_chunks(args, scene, progress)
    gt = groundtruth.ground_truth(
        scene, spp=args.spp, seed=args.seed, cache_dir=args.cache_dir, variant=args.mitsuba_variant,
        chunk_spp=args.chunk_spp, use_closed_form=not args.no_closed_form, progress=progress,
    )
    return chosen, gt


def _render_chunks(args: argparse.Namespace, scene, progress) -> None:
    """``--executor``: the chunks the cache lacks rendered as tasks of that executor (each a cache entry, written
    where every worker sees the cache), before ``ground_truth()`` merges them here as it merges its own. A chunk that
    failed there is rendered here by the merge, which says why if it fails again."""
    jobs = groundtruth.missing_chunks(scene, spp=args.spp, seed=args.seed, cache_dir=args.cache_dir,
                                      variant=args.mitsuba_variant, chunk_spp=args.chunk_spp)
    if not jobs:
        return
    executor = executors.make_executor(args.executor, args.workers)
    tasks = [executors.Task(f"chunk:{job.key}", "chunk", job, executors.CHUNK_TIMEOUT) for job in jobs]
    total = math.ceil(args.spp / args.chunk_spp)
    done = total - len(jobs)
    for _task, outcome in executor.run(tasks):
        if outcome[0] == "harness-error":
            raise HarnessError(outcome[1], outcome[2])
        done += 1
        if progress is not None:
            progress(min(args.spp, done * args.chunk_spp), args.spp)


def run(args: argparse.Namespace) -> int:
    """Fetch or render the ground truth; print its source and path (or, with ``--json``, a summary)."""
    auto = args.spp == "auto"
    if not auto:
        require_positive("--spp", args.spp)
        for option, given in (("--test-set", args.test_set), ("--test-renderer", args.test_renderer != "reference"),
                              ("--test-spp", args.test_spp != 64)):
            if given:
                raise HarnessError(option, "applies only with --spp auto")
    require_positive("--chunk-spp", args.chunk_spp)
    require_non_negative("--seed", args.seed)
    if args.workers is not None and args.executor is None:
        raise HarnessError("--workers", "applies only with --executor")
    if args.executor is not None:
        executors.make_executor(args.executor, args.workers)  # a bad --executor or --workers: one line, now
    out = exr_out_path(args.out) if args.out is not None else None
    scene = with_film(load_scene(scene_argument(args.scene)), args.film)
    test_settings = parse_set(args.test_set)
    if auto:
        check_cost(scene, args.test_spp, "--test-spp")
        try:
            renderer = get_renderer(args.test_renderer)
        except HarnessError as err:
            raise HarnessError("--test-renderer", err.message) from None
        check = getattr(renderer, "check", None) if args.test_renderer in ("reference", "mitsuba") else None
        if check is not None:  # its settings checked before any pilot renders
            try:
                check(scene, RenderRequest(spp=args.test_spp, settings=test_settings))
            except HarnessError as err:
                where = err.where.replace("--set ", "--test-set ") if err.where.startswith("--set ") else err.where
                raise HarnessError(where, err.message) from None
    created: list = []  # the cache folders made for it: removed (where empty) when it fails
    if not (scene.closed_form and not args.no_closed_form):  # Mitsuba renders: the cache checked before any
        args.cache_dir = str(runstate.cache_folder(args.cache_dir, groundtruth.default_cache_dir(), created))
    bar, progress = path_progress(args, f"ground truth {scene.name}")
    done = [0, 0]  # samples per pixel done, of how many

    def safe_point(now: int, total: int) -> None:
        done[:] = now, total
        if progress is not None:
            progress(now, total)
        runstate.check()

    try:
        with imageio.removed_on_failure(created), runstate.interruptible():
            chosen, gt = _compute(args, scene, auto, test_settings, safe_point)
            runstate.check()
    except runstate.Interrupted as stop:
        if bar is not None:
            bar.close()
            bar = None
        if isinstance(args.spp, int):  # else --spp auto's pilots were rendering
            chunks = math.ceil(args.spp / args.chunk_spp)
            finished = chunks if done[1] and done[0] >= done[1] else done[0] // args.chunk_spp
            print(f"harness: interrupted after {finished} of {chunks} chunks; run again to resume (finished chunks "
                  "are cached)", file=sys.stderr)
        else:
            print("harness: interrupted during --spp auto's pilot renders", file=sys.stderr)
        return stop.exit_code
    finally:
        if bar is not None:
            bar.close()
    if out is not None:
        metadata = {"renderer": "ground-truth", "scene": str(scene.path), "source": gt.source, "spp": str(gt.spp),
                    "info": json.dumps(gt.info, sort_keys=True, default=str)}
        imageio.write_exr_with_preview(out, gt.image, gt.variance, metadata=metadata)
    summary = {
        "scene": str(scene.path), "width": scene.film.width, "height": scene.film.height, "source": gt.source,
        "spp": gt.spp, "cached": gt.cached, "renders": gt.renders,
        "seconds": gt.seconds, "path": str(gt.path) if gt.path else None, "out": str(out) if out else None,
        "mean_radiance": [float(v) for v in gt.image.astype(float).mean(axis=(0, 1))], "info": gt.info,
        **({"auto": chosen.to_dict()} if chosen is not None else {}),
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    elif gt.source == "closed-form":
        radiance = gt.info.get("radiance", "per pixel (the mean over each pixel's footprint)")
        done = f"wrote {out}" if out is not None else "no render needed"
        print(f"{scene.name}: closed form ({gt.info.get('closed_form')}), radiance {radiance}; {done}")
    else:
        state = "from the cache" if gt.cached else f"rendered in {gt.seconds:.1f} s ({gt.renders} chunk renders)"
        print(f"{scene.name}: Mitsuba {gt.info.get('variant')} {gt.spp} spp, {state}\n{gt.path}"
              + (f"\nwrote {out}" if out is not None else ""))
    return EXIT_OK
