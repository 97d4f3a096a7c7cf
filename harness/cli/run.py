"""``harness run SUITE``: every case of a suite rendered and judged, results.json and the report written; exit 0
when every case ends as expected, 1 when not."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from harness.cli.common import EXIT_FAIL, EXIT_OK, SUITE_HELP, progress_bar
from harness.cli import studies, study_compute
from harness.core import options
from harness.core.errors import HarnessError
from harness.renderers import groundtruth
from harness.renderers.mitsuba import check_user_libllvm
from harness.report import write_suite_report
from harness.running import baseline, executors, junit, result_cache, runstate
from harness.files import imageio
from harness.files.calibration import read_calibration
from harness.running.cases import load_suite
from harness.running.schedule import run_suite


def register(sub, common) -> None:
    """Add ``run`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("suite", help=SUITE_HELP)
    parser.add_argument("--no-report", action="store_true",
                        help="do not write the studies or the report (studies/, index.html, report.json)")
    parser.add_argument("--executor", default="local", help="where cases run: local (a process pool, the default), "
                        "serial (in this process), dask (a Dask LocalCluster) or tcp://HOST:PORT (a Dask scheduler, "
                        "which has 10 s to answer Dask's handshake)")
    parser.add_argument("--workers", type=options.positive_int,
                        help="worker processes of local (default 2; 1 on a one-core machine) or dask (default 2)")
    parser.add_argument("--timeout", type=options.seconds,
                        help="seconds before a case's worker is killed (default: the case's "
                        "timeout key, else 600 s for an spp budget, max(120 s, 20 x the budget) for a seconds budget)")
    parser.add_argument("--fresh", action="store_true", help="render and measure everything again: ignore an earlier "
                        "results.json in --out (default: resume, keeping the cases it finished) and the results "
                        "cache (default: a case or study whose inputs, code and machine are unchanged is answered "
                        "from <cache-dir>/results/, timings and all); what it renders replaces the cache's entries "
                        "(docs/suites.md, \"The results cache\")")
    parser.add_argument("--no-cache", action="store_true", help="neither read nor write the results cache "
                        "(HARNESS_RESULTS_CACHE=off does the same); the ground-truth cache is used as always")
    parser.add_argument("--baseline", metavar="FILE", help="also fail a case whose metrics regressed against this "
                        "baseline (harness baseline save; docs/ci.md)")
    parser.add_argument("--baseline-tolerance", action="append", default=[], metavar="KEY=VALUE",
                        help="override a baseline rule, e.g. relmse=1.10 (10 %% worse allowed), seconds=1.5, "
                        "bias=off (repeatable; docs/ci.md)")
    parser.add_argument("--junit", metavar="FILE", type=options.out_file, help="also write JUnit XML of the run for CI (docs/ci.md)")
    parser.add_argument("--no-studies", action="store_true", help="compute no study (convergence, shadow rays, "
                        "strategies) after the suite; the report then says how to get them")
    studies.add_flags(parser, "run")
    parser.set_defaults(func=run)
    sub.add_parser(
        "run", parents=[parser, common.out("output folder (default reports/<suite name>)"), common.quiet(),
                 common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """Run the suite into ``--out`` (resuming an earlier run there unless ``--fresh``), print the summary, gate on
    ``--baseline``, write JUnit XML and the report."""
    suite = load_suite(args.suite, args.cache_dir)
    cache_mode = result_cache.mode(fresh=args.fresh, no_cache=args.no_cache)
    executor = executors.make_executor(args.executor, args.workers)  # checked before anything is written
    if args.timeout is not None and not args.timeout > 0:
        raise HarnessError("--timeout", f"expected a positive number of seconds, got {args.timeout}")
    gate = _baseline_gate(args, suite)  # --baseline / --junit checked before anything runs (harness/running/baseline.py)
    if getattr(args, "calibration", None) and not args.no_report:
        read_calibration(args.calibration)  # a bad --calibration: one line now, not after the suite
    if gate is not None and gate.warning():
        print(gate.warning(), file=sys.stderr)
    created: list[Path] = []  # the folders made for the run: removed (where empty) when it fails
    with imageio.removed_on_failure(created):
        # the cache folder checked (a real write) and swept of what killed writers left, before anything renders
        args.cache_dir = str(runstate.cache_folder(args.cache_dir, groundtruth.default_cache_dir(), created))
        check_user_libllvm()  # a DRJIT_LIBLLVM_PATH no Mitsuba render could use: one line before anything is written
        out = runstate.output_folder(args.out, Path("reports") / suite.name, created=created)  # before any render
    if gate is not None:
        gate.cache_dir = args.cache_dir
    # a second run into the same folder stops at the lock (one line naming the holder's pid)
    with imageio.removed_on_failure(created), runstate.locked(out):
        bar = progress_bar(args, suite.name, "case", total=len(suite.cases), leave=True)

        finished = [0]  # cases ended so far: the progress lines count them in the order they end

        def on_case(index: int, record: dict) -> None:
            finished[0] += 1
            if gate is not None:
                gate.check(suite.cases[index], record)
            warnings = [(record.get("ground_truth_noise") or {}).get("warning"), record.get("ground_truth_caveat")]
            for warning in filter(None, warnings):  # once per case; above the bar where there is one
                line = f"warning: {record['name']}: {warning}"
                if bar is not None:
                    bar.write(line, file=sys.stderr)
                else:
                    print(line, file=sys.stderr)
            if bar is not None:
                bar.set_postfix_str(f"{record['name']}: {record['status']}")
                bar.update(1)
            elif not args.quiet:
                mark = "ok " if record["ok"] else "BAD"
                print(f"[{finished[0]}/{len(suite.cases)}] {mark} {record['name']}: {record['status']}"
                      + (f" ({record['reason']})" if record.get("reason") else ""), file=sys.stderr)

        done = [0]

        def on_start() -> None:
            if args.quiet:
                return
            if bar is not None:  # above the bar
                bar.write(plan(args, suite), file=sys.stderr)
            else:
                print(plan(args, suite), file=sys.stderr, flush=True)

        def on_resume(kept: int, total: int) -> None:
            done[0] = kept
            print(f"resuming: {kept} of {total} cases done", file=sys.stderr)

        def on_each(index: int, record: dict) -> None:
            done[0] += 1
            on_case(index, record)

        try:
            with runstate.interruptible():
                if isinstance(executor, executors.DaskExecutor):
                    executor.check()  # a tcp:// peer that is no Dask scheduler: one line before anything is written
                results = run_suite(suite, out, cache_dir=args.cache_dir, variant=args.mitsuba_variant,
                                    on_case=on_each, executor=executor, resume=not args.fresh, on_resume=on_resume,
                                    timeout=args.timeout, results_cache=cache_mode, on_start=on_start)
        except runstate.Interrupted as stop:
            if bar is not None:
                bar.close()
                bar = None
            print(f"harness: interrupted after {done[0]} of {len(suite.cases)} cases; run again to resume",
                  file=sys.stderr)
            return stop.exit_code
        finally:
            if bar is not None:
                bar.close()
        baseline_lines = gate.finish(results, out) if gate is not None else []
        summary = results["summary"]
        print(f"{suite.name}: {summary['ok']}/{summary['cases']} cases as expected "
              f"({summary['passed']} passed, {summary['failed']} failed, {summary['errors']} errors"
              f"{', ' + str(summary['skipped']) + ' skipped' if summary.get('skipped') else ''}) in "
              f"{summary['wall_seconds']:.1f} s; {summary['mitsuba_renders']} Mitsuba renders; "
              f"{summary['from_cache']} cases from the cache; {out / 'results.json'}")
        for name in summary["unexpected"]:
            record = next(r for r in results["cases"] if r["name"] == name)
            print(f"  unexpected: {name}: {record['status']} (expected {record['expect']}) {record.get('reason', '')}")
        for line in baseline_lines:
            print(line)
        if args.junit:
            print(f"junit: {junit.write(results, args.junit)}")
        if not args.no_report:
            _write_report(args, out, cache_mode)
    return EXIT_OK if not summary["unexpected"] else EXIT_FAIL


def plan(args: argparse.Namespace, suite) -> str:
    """The line ``harness run`` starts with: how many cases, which studies follow them (they can take longer than
    the cases) and the flag that skips them."""
    count = len(suite.cases)
    cases = f"{suite.name}: {count} case{'' if count == 1 else 's'}"
    if args.no_report:
        return f"{cases}; no studies and no report (--no-report)"
    if args.no_studies:
        return f"{cases}, then the report; no studies (--no-studies)"
    names = [name for name, off in (("convergence", args.no_convergence), ("shadow rays", args.no_shadow_rays),
                                    ("strategies", args.no_strategies)) if not off]
    if not names:
        return f"{cases}, then the report; no studies"
    return (f"{cases}, then the studies of their scenes ({', '.join(names)}; they can take longer than the cases: "
            "--no-studies skips them) and the report")


def _baseline_gate(args: argparse.Namespace, suite) -> baseline.Gate | None:
    """The run's baseline gate (None without --baseline); bad --baseline, --baseline-tolerance or --junit input
    is a one-line error before anything runs."""
    gate = None
    if args.baseline:
        gate = baseline.Gate(args.baseline, suite, tolerance_options=args.baseline_tolerance,
                             cache_dir=args.cache_dir, variant=args.mitsuba_variant)
    elif args.baseline_tolerance:
        raise HarnessError("--baseline-tolerance", "applies only with --baseline FILE")
    if args.junit:
        junit.check_writable(args.junit)
    return gate


def _write_report(args: argparse.Namespace, out: Path, cache_mode: str = "off") -> None:
    """The studies and the report of a finished run (DIR/studies/, DIR/index.html, report.json, summary.md). A
    study or report that fails in its own code is one line on stderr and leaves the run's exit code alone; one
    that cannot be written (a full disk) is a WriteError: one line and exit code 2, the old files (if any) left as
    they were. The studies come from the results cache where ``cache_mode`` allows and their inputs are cached."""
    if not args.no_studies:
        study_compute.write_studies(args, out / "results.json", out / "studies", cache=cache_mode)
    try:
        paths = write_suite_report(out / "results.json", out, studies.report_options(args))
        print(f"report: {paths['index']} ({paths['seconds']:.1f} s)")
    except (KeyboardInterrupt, imageio.WriteError):
        raise
    except Exception as err:  # noqa: BLE001 - the gate's result stands whatever happens to its report
        reason = " ".join(str(err).split()) or type(err).__name__
        print(f"harness: report not written: {type(err).__name__}: {reason}"[:400], file=sys.stderr)

