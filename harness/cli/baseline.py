"""``harness baseline save SUITE --out FILE``: a suite's metrics as a baseline that ``harness run --baseline``
gates on (docs/ci.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from harness.cli.common import SUITE_HELP, Parser
from harness.core import options
from harness.core.errors import HarnessError
from harness.files.imageio import removed_on_failure
from harness.running import runstate
from harness.running.baseline import build, read_suite_results, save
from harness.running.cases import load_suite
from harness.running.schedule import run_suite


def register(sub, common) -> None:
    """Add ``baseline`` (and its ``save``) to the subparsers ``sub``."""
    bl = sub.add_parser("baseline")
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
    suite = load_suite(args.suite, args.cache_dir)
    if not args.out.strip():
        raise HarnessError("--out", "expected a file name, got an empty string")
    out = Path(args.out)
    if out.is_dir():
        raise HarnessError("--out", f"{str(out)!r} is a folder; expected a file name, e.g. baseline.json")
    if not out.parent.is_dir():
        raise HarnessError("--out", f"folder {str(out.parent)!r} does not exist")
    runstate.probe_writable(out.parent, "--out")  # before the run, not after it
    if args.from_results:
        results = read_suite_results(args.from_results, suite)
        source = str(args.from_results)
        run_dir = Path(args.from_results).parent
    else:
        created: list[Path] = []  # removed (where empty) when the run fails
        run_dir = runstate.output_folder(args.run_out, Path("reports") / f"{suite.name}-baseline", "--run-out",
                                         created=created)

        def on_case(index: int, record: dict) -> None:
            if not args.quiet:
                mark = "ok " if record["ok"] else "BAD"
                print(f"[{index + 1}/{len(suite.cases)}] {mark} {record['name']}: {record['status']}", file=sys.stderr)

        with removed_on_failure(created), runstate.locked(run_dir, "--run-out"):
            results = run_suite(suite, run_dir, cache_dir=args.cache_dir, variant=args.mitsuba_variant,
                                on_case=on_case)
        source = f"run {run_dir / 'results.json'}"
    unexpected = [r["name"] for r in results["cases"] if not r.get("ok")]
    if unexpected and not args.allow_unexpected:
        print(f"baseline not written: {len(unexpected)} cases not as expected ({', '.join(unexpected)}); a baseline "
              "is a known-good state (--allow-unexpected writes it anyway)", file=sys.stderr)
        return 1
    try:
        doc, notes = build(suite, results, cache_dir=args.cache_dir, variant=args.mitsuba_variant, source=source,
                           run_dir=run_dir if args.from_results else None)
    except (KeyError, TypeError, AttributeError, IndexError) as err:
        if not args.from_results:
            raise
        # a results.json edited by hand: what build() reads may be missing or of another type
        raise HarnessError(f"--from {args.from_results}", f"not a results.json written by harness run "
                           f"({type(err).__name__}: {err})") from None
    save(doc, out)
    for note in notes:
        print(f"  {note}", file=sys.stderr)
    print(f"{suite.name}: baseline of {len(doc['cases'])}/{len(suite.cases)} cases written to {out}")
    return 0
