"""``harness bench``: the reference against Mitsuba at equal spp (its parser and its body); the work is in
:mod:`harness.studies.bench`, the method and the latest figures in docs/performance.md."""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from harness.cli.common import EXIT_FAIL, EXIT_OK, film_pixels, with_film
from harness.core import options
from harness.core import jsonsafe
from harness.core.errors import HarnessError
from harness.core.limits import check_render_cost
from harness.core.options import require_positive
from harness.files.imageio import atomic_write_text
from harness.renderers import get_renderer
from harness.scene import load_scene, scene_argument
from harness.studies import bench, scaling

MAX_REPEATS = 1000  # timed renders per contender: more only repeats the measurement


def _targets_text() -> str:
    """The targets ``--check`` tests (:func:`harness.studies.bench.targets`), in words."""
    return "; ".join(t.words for t in bench.targets())


def register(sub, common) -> None:
    """Add ``bench`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("--scene", action="append", help="a scene name (as a suite's scene names it) or a scene "
                        "file (repeatable; default cornell-box, soft-shadows, multi-light)")
    parser.add_argument("--spp", type=options.positive_int, default=64,
                        help="samples per pixel of every render (default 64)")
    parser.add_argument("--repeats", type=options.int_type(1, MAX_REPEATS, f"an integer from 1 to {MAX_REPEATS}"),
                        default=None, help="timed rounds after a warm-up, the contenders taking turns in each "
                                           "(default 3; 5 with --check)")
    parser.add_argument("--ground-truth-spp", type=options.positive_int, default=None,
                        help="spp of the (cached) Mitsuba ground truth (default 4096; with --scaling "
                             f"{scaling.DEFAULT_GT_SPP})")
    parser.add_argument("--renderer", action="append", default=[], metavar="NAME",
                        help="also race this renderer (a renderer file, renderers/NAME.toml or an entry point; "
                             "repeatable) at the same spp, its render time without process start-up "
                             "(docs/external-renderers.md, Timing)")
    parser.add_argument("--no-strategies", action="store_true", help="skip the reference's strategy variations")
    parser.add_argument("--scaling", action="store_true",
                        help="instead of the race over scenes, the scale study: the reference and Mitsuba on a "
                             "generated terrain of each --triangles count, in fresh processes taking turns (load "
                             "time, BVH build, peak RSS and RSS per triangle, render time, paths/s, efficiency "
                             "against a Mitsuba ground truth of --ground-truth-spp; docs/performance.md, \"Scale\")")
    parser.add_argument("--triangles", type=_triangles_option, metavar="N,N,...",
                        help="with --scaling: the terrain sizes in triangles (default "
                             f"{','.join(scaling.count_text(n) for n in scaling.DEFAULT_TRIANGLES)})")
    parser.add_argument("--size", type=options.int_type(1, 8192, "an integer from 1 to 8192"), metavar="PIXELS",
                        help=f"with --scaling: the film's width and height (default {scaling.DEFAULT_SIZE})")
    parser.add_argument("--rounds", type=options.int_type(1, 100, "an integer from 1 to 100"),
                        help=f"with --scaling: rounds of one render each (default {scaling.DEFAULT_ROUNDS})")
    parser.add_argument("--memory", metavar="SIZExSPP", nargs="?", const="1024x256",
                        help="also measure the peak RSS of a SIZE x SIZE render at SPP (default 1024x256)")
    parser.add_argument("--no-embree-rate", action="store_true",
                        help="skip the row 'embree (own rays)': Embree's own rate on the scene's rays, recorded "
                             f"(at most about {bench.embree_rate.DEFAULT_MAX_RAYS // 10**6} M) and replayed")
    parser.add_argument("--fresh", action="store_true",
                        help="also race `harness render` in fresh processes on every scene: the reference and "
                             "Mitsuba llvm_ad_rgb (moments=off), a new process per render, taking turns for "
                             "--repeats rounds after a warm-up process each; their render, start-up and wall "
                             "seconds (the reference's kernel load apart) and fresh_seconds_vs_llvm_ad_rgb, Mitsuba's "
                             "render seconds over the reference's (--check does this on "
                             f"{', '.join(sorted(bench.fresh_scenes()))})")
    parser.add_argument("--check", action="store_true",
                        help=f"also race every scene a target needs ({', '.join(bench.target_scenes())}; without "
                             "--film, " + ", ".join(f"{name} at {w}x{h}" for name, (w, h) in bench.CHECK_FILMS.items())
                             + f"; in fresh processes too on {', '.join(sorted(bench.fresh_scenes()))}), at least "
                             f"{bench.MIN_CHECK_REPEATS} rounds (the default then; "
                             + ", ".join(f"{name} {n}" for name, n in bench.CHECK_ROUNDS.items())
                             + ": their MSE per round is heavy-tailed), and exit 1 when a target's "
                             "interval's lower bound does not clear it, or the machine was busy before the race "
                             f"(its load average over {bench.BUSY_LOAD_PER_CORE:g} per core: not certified): the "
                             f"reference's {_targets_text()} (docs/performance.md)")
    parser.set_defaults(func=run)
    sub.add_parser(
        "bench",
        description="The reference against Mitsuba (llvm_ad_rgb, scalar_rgb) at equal spp: seconds, paths/s, rays/s, "
                    "MSE against ground truth, efficiency 1/(MSE x s) and their ratios. Contenders: the reference at "
                    "its defaults (stratified "
                    "sampler), Mitsuba llvm_ad_rgb and scalar_rgb at theirs (independent sampler), Mitsuba llvm_ad_rgb "
                    "with its ldsampler when spp is a power of 4 (and its stratified, multijitter and orthogonal "
                    "samplers where they draw spp, on the scenes where a target compares with Mitsuba's best sampler; "
                    "there the best one also races the reference at equal time, the reference at the power of two "
                    "of spp that comes nearest the best one's time: not a target), "
                    "Embree's own rate on the rays the reference traces (the row 'embree (own rays)'), "
                    "with --fresh (and --check's fresh target) harness render in fresh processes, "
                    "and the reference's strategy rows (one setting "
                    "changed, e.g. sampler=independent; also rendered at equal time, the spp that takes the "
                    "defaults' time, where the best is decided); --renderer adds any other renderer (e.g. cycles, "
                    "or a renderer file) at the same spp, timed without process start-up. Method and latest "
                    "figures: docs/performance.md.",
        parents=[parser, common.film(), common.out("also write the JSON result to this file (atomically)", file=True),
                 common.json(), common.quiet(), common.cache_dir(), common.allow_outside_paths()])


def _triangles_option(text: str) -> list[int]:
    return scaling.parse_triangles(text)


#: the race's options, which the scale study does not take (each refused with --scaling)
RACE_ONLY = (("scene", "--scene"), ("renderer", "--renderer"), ("check", "--check"), ("memory", "--memory"),
             ("no_strategies", "--no-strategies"), ("no_embree_rate", "--no-embree-rate"), ("film", "--film"),
             ("fresh", "--fresh"))
#: the scale study's options, refused without --scaling
SCALING_ONLY = (("triangles", "--triangles"), ("size", "--size"), ("rounds", "--rounds"))


def _run_scaling(args: argparse.Namespace) -> int:
    """``harness bench --scaling``: the scale study and its table (or JSON)."""
    for attribute, option in RACE_ONLY:
        if getattr(args, attribute, None):
            raise HarnessError(option, "the race's option, not taken by --scaling (the scale study renders its own "
                                       "terrain: --triangles, --size, --spp, --rounds, --ground-truth-spp)")
    if args.repeats is not None:
        raise HarnessError("--repeats", "not taken by --scaling: its rounds are --rounds")
    size = args.size or scaling.DEFAULT_SIZE
    gt_spp = args.ground_truth_spp or scaling.DEFAULT_GT_SPP
    for option, spp in (("--spp", args.spp), ("--ground-truth-spp", gt_spp)):
        check_render_cost(size, size, spp, film_where="--size", spp_where=option, film_keys="--size",
                          spp_name=option)
    say = (lambda text: print(f"  {text}", file=sys.stderr, flush=True)) if not args.quiet else None
    result = scaling.run_scaling(triangles=args.triangles or scaling.DEFAULT_TRIANGLES, size=size, spp=args.spp,
                                 rounds=args.rounds or scaling.DEFAULT_ROUNDS, gt_spp=gt_spp,
                                 cache_dir=args.cache_dir, say=say)
    text = jsonsafe.dumps(result, indent=2, default=float)
    if args.out:
        atomic_write_text(Path(args.out), text)
    print(text if args.json else scaling.format_table(result))
    return EXIT_OK


def _memory_option(text: str) -> tuple[int, int]:
    match = re.fullmatch(r"([0-9]+)[xX]([0-9]+)", text)
    if not match or int(match[1]) < 1 or int(match[2]) < 1:
        raise HarnessError("--memory", f"expected SIZExSPP, e.g. 1024x256, got {text!r}")
    return int(match[1]), int(match[2])


def _check_costs(scene, args: argparse.Namespace) -> None:
    """Refuse renders of ``scene`` at --spp and its ground truth at --ground-truth-spp whose estimates break
    harness/core/limits.py's (absurd even where a closed form makes the ground truth free)."""
    for option, spp in (("--spp", args.spp), ("--ground-truth-spp", args.ground_truth_spp)):
        check_render_cost(scene.film.width, scene.film.height, spp, film_where=f"{scene.path}: film",
                          spp_where=option, film_keys=f"film.width / film.height in {scene.path}", spp_name=option,
                          envmap=scene.envmap_size, envmap_where=scene.envmap_key)


def run(args: argparse.Namespace) -> int:
    """Race the contenders on each scene and print the table (or the JSON); with ``--check``, exit 1 when a
    target is not met."""
    for option, value in (("--spp", args.spp), ("--repeats", args.repeats or bench.DEFAULT_REPEATS),
                          ("--ground-truth-spp", args.ground_truth_spp or bench.DEFAULT_GT_SPP)):
        require_positive(option, value)
    memory = _memory_option(args.memory) if args.memory is not None else None  # "" is refused, not "no --memory"
    if args.out:
        out = Path(args.out)
        if not out.parent.is_dir():
            raise HarnessError("--out", f"folder {str(out.parent)!r} does not exist")
    if args.scaling:
        return _run_scaling(args)
    for attribute, option in SCALING_ONLY:
        if getattr(args, attribute) is not None:
            raise HarnessError(option, "only with --scaling (the scale study)")
    if args.ground_truth_spp is None:
        args.ground_truth_spp = bench.DEFAULT_GT_SPP
    if args.repeats is None:
        args.repeats = bench.MIN_CHECK_REPEATS if args.check else bench.DEFAULT_REPEATS
    if args.check and args.repeats < bench.MIN_CHECK_REPEATS:
        raise HarnessError("--repeats", f"--check takes at least {bench.MIN_CHECK_REPEATS} rounds (each target's "
                                        f"interval comes from them), got {args.repeats}")
    scenes = args.scene or list(bench.BENCH_SCENES)
    if args.check:  # the scenes the targets are checked on, after those asked for
        given = {Path(name).stem for name in scenes}
        scenes = scenes + [name for name in bench.target_scenes() if name not in given]
    resolved = []
    for name in scenes:
        path = scene_argument(name, "--scene")
        if not path.is_file():
            raise HarnessError("--scene", f"expected a scene name or a scene file, got {name!r}")
        resolved.append(str(path))
    films = dict(bench.CHECK_FILMS) if args.check and not args.film else {}
    for path in resolved:  # absurd budgets refused before the first render, as harness render does
        scene = load_scene(path)
        size = films.get(scene.name)
        _check_costs(with_film(scene, args.film or (f"{size[0]}x{size[1]}" if size else None)), args)
    if memory is not None:
        check_render_cost(memory[0], memory[0], memory[1], film_where="--memory", spp_where="--memory",
                          film_keys="SIZE in --memory", spp_name="SPP in --memory")
    for name in args.renderer:  # an unknown name or a bad renderer file: one line before anything renders
        get_renderer(name)
    say = (lambda text: print(f"  {text}", file=sys.stderr, flush=True)) if not args.quiet else None
    result = bench.run_bench(scenes=resolved, spp=args.spp, repeats=args.repeats, gt_spp=args.ground_truth_spp,
                             strategies=not args.no_strategies, cache_dir=args.cache_dir, on_render=say,
                             renderers=tuple(args.renderer), embree=not args.no_embree_rate,
                             film=film_pixels(args.film), films=films,
                             fresh=True if args.fresh else sorted(bench.fresh_scenes()) if args.check else False,
                             rounds=dict(bench.CHECK_ROUNDS) if args.check else {})
    if memory is not None:
        result["memory"] = bench.peak_memory(Path(resolved[0]), memory[0], memory[1])
    text = jsonsafe.dumps(result, indent=2, default=float)  # NaN / inf as null
    if args.out:
        atomic_write_text(Path(args.out), text)
    print(text if args.json else bench.format_report(result))
    if args.check and result["machine"]["busy"]:  # measured and shown, never certified
        print(f"harness bench: not certified: {result['machine']['busy']}", file=sys.stderr)
        return EXIT_FAIL
    if args.check and not bench.targets_met(result["targets"]):
        return EXIT_FAIL
    return EXIT_OK
