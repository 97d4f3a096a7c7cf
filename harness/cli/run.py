"""``harness run SUITE``: every case of a suite rendered and judged, results.json and the report written; exit 0
when every case ends as expected, 1 when not."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import harness.report
from harness.cli.common import EXIT_FAIL, EXIT_OK, SUITE_HELP, progress_bar
from harness.cli.report import report_options
from harness.core import options
from harness.core.errors import HarnessError
from harness.files.imageio import WriteError
from harness.running import baseline, executors, junit, runstate
from harness.running.suite import load_suite, run_suite


def register(sub, common) -> None:
    """Add ``run`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("suite", help=SUITE_HELP)
    parser.add_argument("--no-report", action="store_true", help="do not write the report (index.html, report.json)")
    parser.add_argument("--executor", default="local", help="where cases run: local (a process pool, the default), "
                        "serial (in this process), dask (a Dask LocalCluster) or tcp://HOST:PORT (a Dask scheduler)")
    parser.add_argument("--workers", type=options.positive_int,
                        help="worker processes of local (default 1) or dask (default 2)")
    parser.add_argument("--timeout", type=options.seconds,
                        help="seconds before a case's worker is killed (default: the case's "
                        "timeout key, else 600 s for an spp budget, max(120 s, 20 x the budget) for a seconds budget)")
    parser.add_argument("--fresh", action="store_true", help="ignore an earlier results.json in --out: run every "
                        "case (default: resume, keeping the cases it finished)")
    parser.add_argument("--baseline", metavar="FILE", help="also fail a case whose metrics regressed against this "
                        "baseline (harness baseline save; docs/ci.md)")
    parser.add_argument("--baseline-tolerance", action="append", default=[], metavar="KEY=VALUE",
                        help="override a baseline rule, e.g. relmse=1.10 (10 %% worse allowed), seconds=1.5, "
                        "bias=off (repeatable; docs/ci.md)")
    parser.add_argument("--junit", metavar="FILE", help="also write JUnit XML of the run for CI (docs/ci.md)")
    parser.set_defaults(func=run)
    sub.add_parser(
        "run", help="run a suite: exit 0 when every case is as expected, 1 when not, 2 on bad input",
        parents=[parser, common.out("output folder (default reports/<suite name>)"), common.quiet(),
                 common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """Run the suite into ``--out`` (resuming an earlier run there unless ``--fresh``), print the summary, gate on
    ``--baseline``, write JUnit XML and the report."""
    suite = load_suite(args.suite)
    executor = executors.make_executor(args.executor, args.workers)  # checked before anything is written
    if args.timeout is not None and not args.timeout > 0:
        raise HarnessError("--timeout", f"expected a positive number of seconds, got {args.timeout}")
    gate = _baseline_gate(args, suite)  # --baseline / --junit checked before anything runs (harness/running/baseline.py)
    out = runstate.output_folder(args.out, Path("reports") / suite.name)  # created and written to before any render
    with runstate.locked(out):  # a second run into the same folder stops here (one line naming the holder's pid)
        bar = progress_bar(args, suite.name, "case", total=len(suite.cases), leave=True)

        def on_case(index: int, record: dict) -> None:
            if gate is not None:
                gate.check(suite.cases[index], record)
            if bar is not None:
                bar.set_postfix_str(f"{record['name']}: {record['status']}")
                bar.update(1)
            elif not args.quiet:
                mark = "ok " if record["ok"] else "BAD"
                print(f"[{index + 1}/{len(suite.cases)}] {mark} {record['name']}: {record['status']}"
                      + (f" ({record['reason']})" if record.get("reason") else ""), file=sys.stderr)

        done = [0]

        def on_resume(kept: int, total: int) -> None:
            done[0] = kept
            print(f"resuming: {kept} of {total} cases done", file=sys.stderr)

        def on_each(index: int, record: dict) -> None:
            done[0] += 1
            on_case(index, record)

        try:
            with runstate.interruptible():
                results = run_suite(suite, out, cache_dir=args.cache_dir, variant=args.mitsuba_variant,
                                    on_case=on_each, executor=executor, resume=not args.fresh, on_resume=on_resume,
                                    timeout=args.timeout)
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
              f"({summary['passed']} passed, {summary['failed']} failed, {summary['errors']} errors) in "
              f"{summary['wall_seconds']:.1f} s; {summary['mitsuba_renders']} Mitsuba renders; {out / 'results.json'}")
        for name in summary["unexpected"]:
            record = next(r for r in results["cases"] if r["name"] == name)
            print(f"  unexpected: {name}: {record['status']} (expected {record['expect']}) {record.get('reason', '')}")
        for line in baseline_lines:
            print(line)
        if args.junit:
            print(f"junit: {junit.write(results, args.junit)}")
        if not args.no_report:
            _write_report(args, out)
    return EXIT_OK if not summary["unexpected"] else EXIT_FAIL


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


def _write_report(args: argparse.Namespace, out: Path) -> None:
    """The report of a finished run (DIR/index.html, report.json, summary.md). A report that fails in its own
    code is one line on stderr and leaves the run's exit code alone; one that cannot be written (a full disk) is a
    WriteError: one line and exit code 2, the old report (if any) left as it was."""
    try:
        paths = harness.report.write_suite_report(out / "results.json", out, report_options(args))
        print(f"report: {paths['index']} ({paths['seconds']:.1f} s)")
    except (KeyboardInterrupt, WriteError):
        raise
    except Exception as err:  # noqa: BLE001 - the gate's result stands whatever happens to its report
        reason = " ".join(str(err).split()) or type(err).__name__
        print(f"harness: report not written: {type(err).__name__}: {reason}"[:400], file=sys.stderr)

