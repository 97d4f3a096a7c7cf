"""``harness calibrate SUITE``: the verdict's false alarms over many seeds, its power (the smallest bias and region
error it catches in 90 % of the seeds, at the suite's budget and at multiples of it) and how the planted faults fail
(calibration.json, calibration.md); with ``--films``, ``--spp`` or ``--replicates``, a false-alarm sweep over
those instead."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from harness.cli.common import EXIT_OK, SUITE_HELP
from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import require_positive
from harness.running import calibrate, runstate
from harness.files import imageio
from harness.files.imageio import atomic_write_text
from harness.running.cases import MIN_SPP, load_suite


MAX_SEEDS = 100_000  # 100 false alarms expected at alpha = 0.001: more seeds would measure nothing new


def register(sub, common) -> None:
    """Add ``calibrate`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("suite", help=SUITE_HELP)
    parser.add_argument("--seeds", type=options.int_type(1, MAX_SEEDS, what=f"a number of seeds from 1 to {MAX_SEEDS}"),
                        default=50, help=f"seeds per expect=pass case (default 50, at most {MAX_SEEDS})")
    parser.add_argument("--cases", action="append", help="only cases whose name matches this glob (repeatable)")
    parser.add_argument("--budgets", type=options.budget_factors,
                        help="budget factors at which to measure power, comma-separated, e.g. 0.5,1,2,4 (default 1: "
                        "the case's own spp or seconds; each factor renders --seeds more times; not in a sweep)")
    parser.add_argument("--region-size", type=options.int_type(1, 1024, what="a region side from 1 to 1024 pixels"),
                        help=f"side of the planted region in pixels (default {calibrate.DEFAULT_REGION_SIZE}; not in "
                        "a sweep)")
    parser.add_argument("--no-power", action="store_true", help="count false alarms only; plant no errors")
    sweep = parser.add_argument_group(
        "false-alarm sweep", "any of these renders each expect=pass case at every combination of them (an option "
        "left out: the case's own value), --seeds times each, and counts the verdict's false alarms; no power")
    sweep.add_argument("--films", type=options.film_list, metavar="LIST",
                       help="films, comma-separated: scene (the case's own), half, double (its sides halved / doubled,"
                       f" at least {options.MIN_SWEEP_SIDE} pixels) or WxH, e.g. scene,half,double")
    sweep.add_argument("--spp", type=options.int_list(MIN_SPP, "the verdict needs each pixel's sample variance"),
                       metavar="LIST", help="samples per pixel, comma-separated, increasing, e.g. 16,64,256,1024")
    sweep.add_argument("--replicates", type=options.int_list(1, "one replicate is the plain render"), metavar="LIST",
                       help="the reference renderer's replicates, comma-separated, increasing, e.g. 1,2,4")
    sweep.add_argument("--ground-truth-spp", type=options.int_type(MIN_SPP, what=f"an integer >= {MIN_SPP}"),
                       metavar="N", help="the ground truth's spp in a sweep instead of each case's ground_truth_spp "
                       "(a sharper ground truth must never make a correct render fail)")
    parser.set_defaults(func=run)
    sub.add_parser(
        "calibrate", parents=[parser, common.out("output folder (default reports/<suite>-calibration)"), common.quiet(),
                 common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """Calibrate the suite's cases into ``--out``/calibration.json and print the summary."""
    require_positive("--seeds", args.seeds)
    sweep_options = _sweep_options(args)
    suite = load_suite(args.suite, args.cache_dir)
    cases = calibrate.select_cases(suite, args.cases)  # a --cases matching no case: one line, before any render
    if sweep_options is not None:
        calibrate.check_cost(cases, args.seeds, sweep_options=sweep_options)  # and each case's films and replicates
    else:
        power_options = calibrate.PowerOptions(
            enabled=not args.no_power, budgets=tuple(options.parse_ladder(args.budgets or "1", float)),
            region_size=args.region_size or calibrate.DEFAULT_REGION_SIZE)
        calibrate.check_cost(cases, args.seeds,
                             budgets=power_options.factors() if power_options.enabled else (1.0,))
    created: list[Path] = []  # removed (where empty) when the calibration fails
    out = runstate.output_folder(args.out, Path("reports") / f"{suite.name}-calibration", created=created)

    def on_progress(name: str, seed: int) -> None:
        if not args.quiet:
            print(f"  {name} seed {seed}", file=sys.stderr, flush=True)

    with imageio.removed_on_failure(created), runstate.locked(out):
        if sweep_options is not None:
            result = calibrate.sweep(suite, out, seeds=args.seeds, patterns=args.cases, options=sweep_options,
                                     cache_dir=args.cache_dir, variant=args.mitsuba_variant, on_progress=on_progress)
        else:
            result = calibrate.calibrate(suite, out, seeds=args.seeds, patterns=args.cases, cache_dir=args.cache_dir,
                                         variant=args.mitsuba_variant, on_progress=on_progress,
                                         power_options=power_options)
        calibrate.write(result, out / "calibration.json")
        atomic_write_text(out / "calibration.md", calibrate.markdown(result))
    for line in calibrate.summary_lines(result):
        print(line)
    print(f"wrote {out / 'calibration.json'} and {out / 'calibration.md'}")
    return EXIT_OK


def _sweep_options(args: argparse.Namespace) -> calibrate.SweepOptions | None:
    """The sweep ``--films``, ``--spp`` and ``--replicates`` ask for, or None (the power calibration); the power's
    own options beside them, or ``--ground-truth-spp`` without them, are one line naming the options."""
    given = [name for name, value in (("--films", args.films), ("--spp", args.spp), ("--replicates", args.replicates))
             if value is not None]
    if not given:
        if args.ground_truth_spp is not None:
            raise HarnessError("--ground-truth-spp", "applies to a false-alarm sweep only; add --films, --spp or "
                               "--replicates")
        return None
    for name, value in (("--budgets", args.budgets), ("--region-size", args.region_size)):
        if value is not None:
            raise HarnessError(name, f"measures power, which a false-alarm sweep ({', '.join(given)}) does not; "
                               f"leave {name} out or run the sweep apart")
    return calibrate.SweepOptions(films=args.films or ("scene",), spp=args.spp, replicates=args.replicates,
                                  ground_truth_spp=args.ground_truth_spp)
