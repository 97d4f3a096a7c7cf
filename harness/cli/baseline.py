"""``harness baseline save SUITE --out FILE``: a suite's metrics as a baseline that ``harness run --baseline``
gates on (docs/ci.md)."""

from __future__ import annotations

import argparse

from harness.cli.common import SUITE_HELP, Parser
from harness.core import options
from harness.running.baseline import save_command


def register(sub, common) -> None:
    """Add ``baseline`` (and its ``save``) to the subparsers ``sub``."""
    bl = sub.add_parser("baseline", help="save a suite's metrics as a baseline that harness run --baseline gates on")
    bl_sub = bl.add_subparsers(dest="baseline_command", required=True, parser_class=Parser)
    save = common.own()
    save.add_argument("suite", help=SUITE_HELP)
    save.add_argument("--from", dest="from_results", metavar="RESULTS.json",
                      help="take this earlier run of the suite instead of running it")
    save.add_argument("--run-out", type=options.out_folder, help="output folder of the run (default reports/<suite name>-baseline)")
    save.add_argument("--allow-unexpected", action="store_true",
                      help="write the baseline even if some cases did not end as expected")
    save.set_defaults(func=run)
    bl_sub.add_parser(
        "save", help="run the suite (or take --from RESULTS.json) and write its baseline",
        parents=[save, common.out("the baseline file to write (JSON)", required=True, metavar="FILE", file=True), common.quiet(),
                 common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """``baseline save``: run the suite (or read ``--from``) and write the baseline; exit 1 when some case did not
    end as expected (unless ``--allow-unexpected``)."""
    return save_command(args)
