"""``harness report RESULTS.json``: the HTML report of a suite run (index.html, report.json, summary.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from harness.cli.common import EXIT_OK
from harness.core import options
from harness.core.options import require_positive
from harness.report import ReportOptions, write_suite_report
from harness.studies.convergence import parse_ladder


def register(sub, common) -> None:
    """Add ``report`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("results", help="a results.json written by harness run")
    parser.add_argument("--convergence-spp", default="1,2,4,8,16", type=options.spp_ladder,
                        help="spp ladder of each scene's convergence (default 1,2,4,8,16)")
    parser.add_argument("--strategy-spp", type=options.positive_int, default=16,
                        help="spp of strategy renders no case covers (default 16)")
    parser.add_argument("--no-convergence", action="store_true", help="leave out the convergence section")
    parser.add_argument("--no-shadow-rays", action="store_true", help="leave out the shadow-ray study")
    parser.add_argument("--no-strategies", action="store_true", help="leave out the strategy comparison")
    parser.add_argument("--no-strategy-renders", action="store_true",
                        help="compare only strategies the suite's cases cover")
    parser.set_defaults(func=run)
    sub.add_parser(
        "report", help="write the HTML report of a suite run (index.html, report.json, summary.md)",
        parents=[parser, common.out("output folder (default: the results file's folder)"), common.quiet(),
                 common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def report_options(args: argparse.Namespace, **overrides) -> ReportOptions:
    """The report's options from a command's ``--cache-dir``, ``--mitsuba-variant`` and ``--quiet``."""
    return ReportOptions(cache_dir=getattr(args, "cache_dir", None), variant=getattr(args, "mitsuba_variant", None),
                         progress=not args.quiet and sys.stderr.isatty(), **overrides)


def run(args: argparse.Namespace) -> int:
    """Write the report into ``--out`` (default: beside the results file)."""
    require_positive("--strategy-spp", args.strategy_spp)
    results = Path(args.results)
    out = Path(args.out) if args.out else results.parent
    chosen = report_options(
        args, convergence=not args.no_convergence, shadow_rays=not args.no_shadow_rays,
        strategies=not args.no_strategies, render_strategies=not args.no_strategy_renders,
        convergence_spp=tuple(parse_ladder(args.convergence_spp, "--convergence-spp")),
        strategy_spp=args.strategy_spp,
    )
    paths = write_suite_report(results, out, chosen)
    print(f"wrote {paths['index']}, {paths['report_json']} and {paths['summary']} in {paths['seconds']:.1f} s")
    return EXIT_OK
