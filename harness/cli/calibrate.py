"""``harness calibrate SUITE``: the verdict's false alarms over many seeds, its power (the smallest bias and region
error it catches in 90 % of the seeds, at the suite's budget and at multiples of it) and how the planted faults fail
(calibration.json, calibration.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from harness.cli.common import EXIT_OK, SUITE_HELP
from harness.core import options
from harness.core.options import require_positive
from harness.running import calibrate, runstate
from harness.files import imageio
from harness.files.imageio import atomic_write_text
from harness.running.cases import load_suite


MAX_SEEDS = 100_000  # 100 false alarms expected at alpha = 0.001: more seeds would measure nothing new


def register(sub, common) -> None:
    """Add ``calibrate`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("suite", help=SUITE_HELP)
    parser.add_argument("--seeds", type=options.int_type(1, MAX_SEEDS, what=f"a number of seeds from 1 to {MAX_SEEDS}"),
                        default=50, help=f"seeds per expect=pass case (default 50, at most {MAX_SEEDS})")
    parser.add_argument("--cases", action="append", help="only cases whose name matches this glob (repeatable)")
    parser.add_argument("--budgets", type=options.budget_factors, default="1",
                        help="budget factors at which to measure power, comma-separated, e.g. 0.5,1,2,4 (default 1: "
                        "the case's own spp or seconds; each factor renders --seeds more times)")
    parser.add_argument("--region-size", type=options.int_type(1, 1024, what="a region side from 1 to 1024 pixels"),
                        default=calibrate.DEFAULT_REGION_SIZE,
                        help=f"side of the planted region in pixels (default {calibrate.DEFAULT_REGION_SIZE})")
    parser.add_argument("--no-power", action="store_true", help="count false alarms only; plant no errors")
    parser.set_defaults(func=run)
    sub.add_parser(
        "calibrate", parents=[parser, common.out("output folder (default reports/<suite>-calibration)"), common.quiet(),
                 common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """Calibrate the suite's cases into ``--out``/calibration.json and print the summary."""
    require_positive("--seeds", args.seeds)
    suite = load_suite(args.suite)
    cases = calibrate.select_cases(suite, args.cases)  # a --cases matching no case: one line, before any render
    power_options = calibrate.PowerOptions(enabled=not args.no_power,
                                           budgets=tuple(options.parse_ladder(args.budgets, float)),
                                           region_size=args.region_size)
    calibrate.check_cost(cases, args.seeds, budgets=power_options.factors() if power_options.enabled else (1.0,))
    created: list[Path] = []  # removed (where empty) when the calibration fails
    out = runstate.output_folder(args.out, Path("reports") / f"{suite.name}-calibration", created=created)

    def on_progress(name: str, seed: int) -> None:
        if not args.quiet:
            print(f"  {name} seed {seed}", file=sys.stderr, flush=True)

    with imageio.removed_on_failure(created), runstate.locked(out):
        result = calibrate.calibrate(suite, out, seeds=args.seeds, patterns=args.cases, cache_dir=args.cache_dir,
                                     variant=args.mitsuba_variant, on_progress=on_progress,
                                     power_options=power_options)
        calibrate.write(result, out / "calibration.json")
        atomic_write_text(out / "calibration.md", calibrate.markdown(result))
    for line in calibrate.summary_lines(result):
        print(line)
    print(f"wrote {out / 'calibration.json'} and {out / 'calibration.md'}")
    return EXIT_OK
