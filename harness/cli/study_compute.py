"""Computing the studies of a suite run from the command line (``harness run`` after its suite, ``harness report
--studies`` before formatting), with the flags of :mod:`harness.cli.studies`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from harness.cli.studies import (DEFAULT_CONVERGENCE_SPP, DEFAULT_STRATEGY_REPEATS, DEFAULT_STRATEGY_SPP,
                                 MAX_STRATEGY_REPEATS, MIN_STRATEGY_REPEATS, progress)
from harness.core.errors import HarnessError
from harness.core.options import require_positive
from harness.files.imageio import WriteError
from harness.files.results import read_results
from harness.studies.convergence import parse_ladder
from harness.studies.study_cache import cached_suite_studies
from harness.studies.suite_studies import StudyOptions, write_suite_studies


def study_options(args: argparse.Namespace) -> StudyOptions:
    """The studies' options from a command's flags (unset flags: the defaults)."""
    spp = getattr(args, "strategy_spp", None)
    spp = DEFAULT_STRATEGY_SPP if spp is None else spp
    require_positive("--strategy-spp", spp)
    repeats = getattr(args, "strategy_repeats", None)
    repeats = DEFAULT_STRATEGY_REPEATS if repeats is None else repeats
    if not MIN_STRATEGY_REPEATS <= repeats <= MAX_STRATEGY_REPEATS:  # a caller past the parser
        raise HarnessError("--strategy-repeats", f"expected an integer from {MIN_STRATEGY_REPEATS} to "
                                                 f"{MAX_STRATEGY_REPEATS}, got {repeats}")
    ladder = getattr(args, "convergence_spp", None) or DEFAULT_CONVERGENCE_SPP
    return StudyOptions(
        convergence=not args.no_convergence, shadow_rays=not args.no_shadow_rays, strategies=not args.no_strategies,
        render_strategies=not args.no_strategy_renders,
        convergence_spp=tuple(parse_ladder(ladder, "--convergence-spp")), strategy_spp=spp,
        strategy_repeats=repeats,
        cache_dir=getattr(args, "cache_dir", None), variant=getattr(args, "mitsuba_variant", None),
        progress=progress(args))


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
