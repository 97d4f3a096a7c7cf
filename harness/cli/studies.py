"""The studies' flags of a suite run from the command line: ``harness run`` computes the studies after its suite
(before the report), ``harness report --studies`` before formatting; the report itself only formats them. The flags
(``--convergence-spp``, ``--strategy-spp``, ``--strategy-repeats``, ``--no-convergence``, ``--no-shadow-rays``,
``--no-strategies``, ``--no-strategy-renders``) mean the same on both commands. Computing the studies is
:mod:`harness.cli.study_compute` (it imports the renderers, which ``harness report`` without ``--studies`` does not
need)."""

from __future__ import annotations

import argparse
from pathlib import Path

from harness.core import options
from harness.core.errors import HarnessError
from harness.report import ReportOptions

#: the flags that change what the studies compute (not which sections the report shows)
COMPUTING_FLAGS = (("convergence_spp", "--convergence-spp"), ("strategy_spp", "--strategy-spp"),
                   ("strategy_repeats", "--strategy-repeats"), ("no_strategy_renders", "--no-strategy-renders"))
DEFAULT_CONVERGENCE_SPP = "1,2,4,8,16"
DEFAULT_STRATEGY_SPP = 16
#: independent seeds of each strategy at each budget (harness.studies.strategies.STRATEGY_REPEATS, which this
#: module does not import: harness report imports no renderer); an interval needs at least 2
DEFAULT_STRATEGY_REPEATS = 4
MIN_STRATEGY_REPEATS, MAX_STRATEGY_REPEATS = 2, 100


def progress(args: argparse.Namespace) -> bool:
    """Whether the studies and the report show progress (not ``--quiet``): a bar on a terminal, else a line now and
    then (:class:`harness.core.progress.Progress`)."""
    return not getattr(args, "quiet", False)


def report_options(args: argparse.Namespace) -> ReportOptions:
    """The report's options: which studies' sections the page shows."""
    return ReportOptions(convergence=not args.no_convergence, shadow_rays=not args.no_shadow_rays,
                         strategies=not args.no_strategies, progress=progress(args),
                         calibration=Path(args.calibration) if getattr(args, "calibration", None) else None)


def check_report_flags(args: argparse.Namespace) -> None:
    """``harness report``: a flag that changes what the studies compute applies only with ``--studies``."""
    if args.studies:
        return
    for dest, flag in COMPUTING_FLAGS:
        if getattr(args, dest, None) not in (None, False):
            raise HarnessError(flag, "applies only with --studies (harness report formats the studies harness run "
                                     "computed; --studies computes them again first)")


def add_flags(parser: argparse.ArgumentParser, command: str) -> None:
    """The flags of the studies, the same on ``run`` and ``report``. On ``report`` the --no-... flags leave a section
    out of the page (and, with --studies, its study out of the computing); the others apply only with --studies."""
    with_studies = " (with --studies)" if command == "report" else ""
    parser.add_argument("--convergence-spp", default=None if command == "report" else DEFAULT_CONVERGENCE_SPP,
                        type=options.spp_ladder,
                        help=f"spp ladder of each scene's convergence study{with_studies} (default 1,2,4,8,16)")
    parser.add_argument("--strategy-spp", type=options.positive_int,
                        default=None if command == "report" else DEFAULT_STRATEGY_SPP,
                        help=f"spp of strategy renders no case covers{with_studies} (default 16)")
    parser.add_argument("--strategy-repeats", metavar="N",
                        default=None if command == "report" else DEFAULT_STRATEGY_REPEATS,
                        type=options.int_type(MIN_STRATEGY_REPEATS, MAX_STRATEGY_REPEATS,
                                              f"an integer from {MIN_STRATEGY_REPEATS} to {MAX_STRATEGY_REPEATS}"),
                        help=f"independent seeds of each strategy at each budget (equal spp, equal time): their "
                             f"spread gives the strategy table's intervals{with_studies} (default "
                             f"{DEFAULT_STRATEGY_REPEATS}; {MIN_STRATEGY_REPEATS} to {MAX_STRATEGY_REPEATS})")
    leave, also = ("leave out", " (with --studies: and do not compute it)") if command == "report" else ("skip", "")
    parser.add_argument("--no-convergence", action="store_true",
                        help=f"{leave} the convergence {'section' if command == 'report' else 'study'}{also}")
    parser.add_argument("--no-shadow-rays", action="store_true", help=f"{leave} the shadow-ray study{also}")
    parser.add_argument("--no-strategies", action="store_true", help=f"{leave} the strategy comparison{also}")
    parser.add_argument("--no-strategy-renders", action="store_true",
                        help=f"compare only strategies the suite's cases cover{with_studies}")
    parser.add_argument("--calibration", type=options.path_type("a calibration.json"), metavar="FILE",
                        help="a calibration.json of harness calibrate: the page's definitions show its power table")
