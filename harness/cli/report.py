"""``harness report RESULTS.json``: the HTML report of a suite run (index.html, report.json, summary.md),
formatted from results.json, the case EXRs and the studies the run computed (``--studies`` computes them first)."""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

from harness.cli import studies
from harness.cli.common import EXIT_OK
from harness.files.studies import studies_folder
from harness.report import write_suite_report

#: What computes the studies (``--studies``), imported by name only then: it imports the renderers and the suite
#: runner, which formatting a report does not need (docs/architecture.md, "Modules loaded by name").
STUDY_COMPUTE = "harness.cli.study_compute"


def register(sub, common) -> None:
    """Add ``report`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("results", help="a results.json written by harness run")
    parser.add_argument("--studies", action="store_true",
                        help="compute the run's studies first (they render and time, as harness run does after its "
                        "suite), into --out's studies/; without it the report formats the studies the run wrote")
    studies.add_flags(parser, "report")
    parser.set_defaults(func=run)
    sub.add_parser(
        "report", parents=[parser, common.out("output folder (default: the results file's folder)"), common.quiet(),
                 common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """Write the report into ``--out`` (default: beside the results file); with ``--studies`` compute the studies
    into ``--out``'s studies/ first."""
    studies.check_report_flags(args)
    results = Path(args.results)
    out = Path(args.out) if args.out else results.parent
    studies_dir = studies_folder(out) if args.studies else None  # None: the studies beside results.json
    if args.studies:
        importlib.import_module(STUDY_COMPUTE).write_studies(args, results, studies_dir)
    paths = write_suite_report(results, out, studies.report_options(args), studies_dir=studies_dir)
    print(f"wrote {paths['index']}, {paths['report_json']} and {paths['summary']} in {paths['seconds']:.1f} s")
    return EXIT_OK
