"""The ``harness`` command line: one module per command, each with ``register(sub, common)`` (its subparser) and
``run(args) -> int`` (its body); the options they share are declared once in :mod:`harness.cli.common`."""

from __future__ import annotations

import argparse
import sys

from harness.cli import (
    baseline,
    bench,
    calibrate,
    common,
    compare,
    convergence,
    export,
    ground_truth,
    render,
    report,
    run,
    stress,
    view,
)

#: The commands in the order ``harness --help`` lists them.
COMMANDS = (render, ground_truth, compare, run, baseline, report, view, convergence, calibrate, export, bench, stress)


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command."""
    parser = common.Parser(prog="harness", description="Validation and benchmark harness for Monte Carlo renderers.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=common.Parser)
    shared = common.Common()
    for command in COMMANDS:
        command.register(sub, shared)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The ``harness`` command: its exit code. A closed stdout or stderr (``harness ... | head -c 10``) ends the
    command quietly with :data:`~harness.cli.common.EXIT_BROKEN_PIPE` (the Python documentation's recipe for
    SIGPIPE)."""
    try:
        try:
            return common.dispatch(build_parser, argv)
        finally:  # also after --help's SystemExit: a closed pipe shows here, not at interpreter shutdown
            sys.stdout.flush()
    except BrokenPipeError as err:
        return common.quiet_broken_pipe(err)


if __name__ == "__main__":
    sys.exit(main())
