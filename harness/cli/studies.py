"""The studies of a suite run from the command line: ``harness run`` computes them after its suite (before the
report), ``harness report --studies`` before formatting; the report itself only formats them. The flags
(``--convergence-spp``, ``--strategy-spp``, ``--no-convergence``, ``--no-shadow-rays``, ``--no-strategies``,
``--no-strategy-renders``) mean the same on both commands."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import require_positive
from harness.files.imageio import WriteError
from harness.files.results import read_results
from harness.report import ReportOptions
from harness.studies.convergence import parse_ladder
from harness.studies.study_cache import cached_suite_studies
from harness.studies.suite_studies import StudyOptions, write_suite_studies

#: the flags that change what the studies compute (not which sections the report shows)
COMPUTING_FLAGS = (("convergence_spp", "--convergence-spp"), ("strategy_spp", "--strategy-spp"),
                   ("no_strategy_renders", "--no-strategy-renders"))
DEFAULT_CONVERGENCE_SPP = "1,2,4,8,16"
DEFAULT_STRATEGY_SPP = 16


def _progress(args: argparse.Namespace) -> bool:
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


def study_options(args: argparse.Namespace) -> StudyOptions:
    """The studies' options from a command's flags (unset flags: the defaults)."""
    spp = getattr(args, "strategy_spp", None)
    spp = DEFAULT_STRATEGY_SPP if spp is None else spp
    require_positive("--strategy-spp", spp)
    ladder = getattr(args, "convergence_spp", None) or DEFAULT_CONVERGENCE_SPP
    return StudyOptions(
        convergence=not args.no_convergence, shadow_rays=not args.no_shadow_rays, strategies=not args.no_strategies,
        render_strategies=not args.no_strategy_renders,
        convergence_spp=tuple(parse_ladder(ladder, "--convergence-spp")), strategy_spp=spp,
        cache_dir=getattr(args, "cache_dir", None), variant=getattr(args, "mitsuba_variant", None),
        progress=_progress(args))


def report_options(args: argparse.Namespace) -> ReportOptions:
    """The report's options: which studies' sections the page shows."""
    return ReportOptions(convergence=not args.no_convergence, shadow_rays=not args.no_shadow_rays,
                         strategies=not args.no_strategies, progress=_progress(args),
                         calibration=Path(args.calibration) if getattr(args, "calibration", None) else None)


def check_report_flags(args: argparse.Namespace) -> None:
    """``harness report``: a flag that changes what the studies compute applies only with ``--studies``."""
    if args.studies:
        return
    for dest, flag in COMPUTING_FLAGS:
        if getattr(args, dest, None) not in (None, False):
            raise HarnessError(flag, "applies only with --studies (harness report formats the studies harness run "
                                     "computed; --studies computes them again first)")


def write_studies(args: argparse.Namespace, results_path: Path, out_dir: Path, cache: str = "off") -> Path | None:
    """Compute the studies of the run ``results_path`` into ``out_dir`` and print where they are; ``cache`` (a mode
    of :mod:`harness.running.result_cache`; ``harness run`` passes its own) lets them come from the results cache,
    and the line says so ("measured <date>, cached"). A study that
    fails in its own code is one line on stderr (``harness: studies not written: ...``) and None (the report then
    says how to get them); one that cannot be written (a full disk) is a WriteError (one line and exit code 2)."""
    try:
        results = read_results(results_path)
        if cache == "off":
            paths = write_suite_studies(results, results_path.parent, study_options(args), out_dir=out_dir,
                                        results_file=results_path)
        else:
            paths = cached_suite_studies(results, results_path.parent, study_options(args), mode=cache,
                                         out_dir=out_dir, results_file=results_path)
    except (KeyboardInterrupt, WriteError, HarnessError):
        raise
    except Exception as err:  # noqa: BLE001 - the run's result and its report stand without the studies
        reason = " ".join(str(err).split()) or type(err).__name__
        print(f"harness: studies not written: {type(err).__name__}: {reason}"[:400], file=sys.stderr)
        return None
    cached = f"; measured {paths['cached']['from']}, cached" if paths.get("cached") else ""
    print(f"studies: {paths['studies_json']} ({paths['seconds']:.1f} s{cached})")
    return paths["folder"]


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
    leave, also = ("leave out", " (with --studies: and do not compute it)") if command == "report" else ("skip", "")
    parser.add_argument("--no-convergence", action="store_true",
                        help=f"{leave} the convergence {'section' if command == 'report' else 'study'}{also}")
    parser.add_argument("--no-shadow-rays", action="store_true", help=f"{leave} the shadow-ray study{also}")
    parser.add_argument("--no-strategies", action="store_true", help=f"{leave} the strategy comparison{also}")
    parser.add_argument("--no-strategy-renders", action="store_true",
                        help=f"compare only strategies the suite's cases cover{with_studies}")
    parser.add_argument("--calibration", type=options.path_type("a calibration.json"), metavar="FILE",
                        help="a calibration.json of harness calibrate: the page's definitions show its power table")
