"""``harness stress SCENE``: the numerical-stability stress table (its parser and its body); the variants and the
analysis are in :mod:`harness.studies.stress`, the method in docs/stress.md."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

from harness.cli.common import EXIT_FAIL, EXIT_OK, SCENE_HELP, progress_bar
from harness.core import jsonsafe, options
from harness.core.errors import HarnessError
from harness.core.limits import MAX_FILM_SIDE, check_render_cost, film_problem
from harness.core.options import parse_set, require_non_negative, require_positive
from harness.files.imageio import atomic_write_text
from harness.renderers import RenderRequest, renderer_names
from harness.renderers.reference import ReferenceRenderer
from harness.running.runstate import output_folder
from harness.scene import Scene, load_scene, scene_argument
from harness.scene.variants import parse_variant, variant_kinds
from harness.studies import stress
from reference_impl import Film


def register(sub, common) -> None:
    """Add ``stress`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("scene", help=SCENE_HELP)
    parser.add_argument("--renderer", action="append", help="renderer (repeatable; default: reference and mitsuba)")
    parser.add_argument("--variant", action="append", metavar="KIND[=VALUE]",
                        help=f"a variant (repeatable; default: all of {', '.join(stress.DEFAULT_VARIANTS)}); the "
                             f"kinds: {', '.join(variant_kinds())} (medium-density and hg-g: scenes with media "
                             "only; docs/stress.md)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a reference renderer setting (repeatable), e.g. direct=mis or mutant=double-emission")
    parser.add_argument("--spp", type=options.positive_int, default=64,
                        help="samples per pixel of each render (default 64)")
    parser.add_argument("--seed", type=options.non_negative_int, default=0,
                        help="seed of the renders (default 0)")
    parser.add_argument("--film", default="64x64", type=options.film_size,
                        help="resolution WIDTHxHEIGHT (default 64x64)")
    parser.add_argument("--ground-truth-spp", type=options.positive_int, default=1024,
                        help="Mitsuba ground truth spp (default 1024)")
    parser.add_argument("--k", type=options.positive_number, default=stress.DEFAULT_K,
                        help=f"firefly threshold in standard deviations (default {stress.DEFAULT_K:g})")
    parser.add_argument("--alpha", type=options.probability, default=0.001,
                        help="verdict false-alarm probability (default 0.001)")
    parser.set_defaults(func=run)
    sub.add_parser(
        "stress", parents=[parser, common.out("folder for stress.json and stress.md"), common.json(), common.quiet(),
                 common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def _resolve_scene(text: str) -> Scene:
    """The scene file ``text``, or the scene of that name as a suite names it (:func:`harness.scene.find_scene`)."""
    return load_scene(scene_argument(text))


def _check_costs(width: int, height: int, args) -> None:
    """Refuse a film beyond the scene format's limits, and renders (``--spp``, ``--ground-truth-spp``) whose cost
    estimates break harness/core/limits.py's, before anything renders."""
    if max(width, height) > MAX_FILM_SIDE:
        raise HarnessError("--film", f"expected at most {MAX_FILM_SIDE} pixels per side, got {args.film!r}")
    problem = film_problem(width, height)
    if problem:
        raise HarnessError("--film", problem)
    for option, spp in (("--spp", args.spp), ("--ground-truth-spp", args.ground_truth_spp)):
        check_render_cost(width, height, spp, film_where="--film", spp_where=option, film_keys="--film",
                          spp_name=option)


def run(args: argparse.Namespace) -> int:
    """Render and judge every variant; print the table (or the JSON). Exit 0 when every invariant variant of the
    reference ends as expected, 1 otherwise."""
    for name, value in (("--spp", args.spp), ("--ground-truth-spp", args.ground_truth_spp)):
        require_positive(name, value)
    require_non_negative("--seed", args.seed)
    if not (math.isfinite(args.k) and args.k > 0):
        raise HarnessError("--k", f"expected a positive number of standard deviations, got {args.k}")
    if not 0 < args.alpha < 1:
        raise HarnessError("--alpha", f"expected a probability in (0, 1), got {args.alpha}")
    w, sep, h = args.film.lower().partition("x")
    if not sep or not w.isdigit() or not h.isdigit() or int(w) < 1 or int(h) < 1:
        raise HarnessError("--film", f"expected WIDTHxHEIGHT, e.g. 64x64, got {args.film!r}")
    _check_costs(int(w), int(h), args)
    settings = parse_set(args.set)
    renderers = args.renderer or ["reference", "mitsuba"]
    for name in renderers:
        if name not in renderer_names():
            raise HarnessError("--renderer", f"expected one of {', '.join(renderer_names())}, got {name!r}")
    renderers = list(dict.fromkeys(renderers))
    variants = args.variant or list(stress.DEFAULT_VARIANTS)
    for text in variants:
        parse_variant(text, "--variant")
    scene = _resolve_scene(args.scene)
    scene = dataclasses.replace(scene, film=Film(int(w), int(h), scene.film.filter))
    if settings:
        ReferenceRenderer().settings_for(scene, RenderRequest(spp=args.spp, seed=args.seed, settings=settings))
    # created and written to after every check, before any render: bad input leaves no folder
    out = None if args.out is None else output_folder(args.out, Path(args.out), subfolders=())

    bar = progress_bar(args, f"stress {scene.name}", "render", total=len(variants) * len(renderers))

    def on_row(row: dict) -> None:
        if bar is not None:
            bar.set_postfix_str(f"{row['variant']} {row['renderer']}: {row['verdict']}")
            bar.update(1)

    try:
        result = stress.run_stress(scene, renderers, variants=variants, spp=args.spp, seed=args.seed,
                                   ground_truth_spp=args.ground_truth_spp, k=args.k, alpha=args.alpha,
                                   cache_dir=args.cache_dir, mitsuba_variant=args.mitsuba_variant, settings=settings,
                                   on_row=on_row)
    finally:
        if bar is not None:
            bar.close()
    text = stress.format_table(result)
    if out is not None:
        atomic_write_text(out / "stress.json", jsonsafe.dumps(result, indent=2))
        atomic_write_text(out / "stress.md", f"{stress.summary_line(result)}\n\n"
                          f"{stress.format_table(result, markdown=True)}\n")
    if args.json:
        print(jsonsafe.dumps(result, indent=2))
    else:
        print(text)
        print(stress.summary_line(result))
        if out is not None:
            print(f"wrote {out / 'stress.json'} and {out / 'stress.md'}")
    return EXIT_OK if result["ok"] else EXIT_FAIL
