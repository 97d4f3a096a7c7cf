"""The ``harness`` command line: one module per command, each with ``register(sub, common)`` (its subparser) and
``run(args) -> int`` (its body); the options they share are declared once in :mod:`harness.cli.common`.

A command's module is imported by name (:func:`importlib.import_module`) only when that command runs: ``harness
report`` does not pay for the modules of ``harness run`` (the renderers, numba, the executors), and ``harness
--help`` imports none. :data:`COMMANDS` is the table of those modules; tests/test_architecture.py reads it as this
module's imports (docs/architecture.md, "Modules loaded by name")."""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Any

from harness.cli import common

#: The commands in the order ``harness --help`` lists them: (name, the module that registers and runs it, its line
#: of help in that list).
COMMANDS = (
    ("render", "harness.cli.render", "render a scene to an OpenEXR file (plus a PNG preview)"),
    ("ground-truth", "harness.cli.ground_truth",
     "render (or fetch from the cache) a scene's ground truth and print where it is"),
    ("compare", "harness.cli.compare",
     "metrics and a statistical verdict for a render against its ground truth (exit 1 on fail)"),
    ("run", "harness.cli.run", "run a suite: exit 0 when every case is as expected, 1 when not, 2 on bad input"),
    ("baseline", "harness.cli.baseline", "save a suite's metrics as a baseline that harness run --baseline gates on"),
    ("report", "harness.cli.report", "write the HTML report of a suite run (index.html, report.json, summary.md)"),
    ("view", "harness.cli.view", "show one or two EXR images in tev, or in the report's comparison viewer"),
    ("convergence", "harness.cli.convergence",
     "error against spp and time for one or more renderers/settings, with the fitted slope, bias detection and "
     "equal-time / equal-error comparisons"),
    ("calibrate", "harness.cli.calibrate", "false alarms of the verdict over many seeds, and how planted faults fail"),
    ("export", "harness.cli.export",
     "write a scene as Mitsuba 3 XML (+ PLY meshes), scene.json (+ PLY meshes; docs/scene-json.md), PLY, OBJ or glTF "
     "for other renderers (docs/external-renderers.md)"),
    ("import", "harness.cli.import_scene",
     "read a Mitsuba 3 XML, glTF 2.0 or pbrt-v4 scene into this project's scene format (TOML + PLY + textures)"),
    ("generate", "harness.cli.generate",
     "write one of the project's generated scenes (a ~1 M-triangle room, a city of thousands of lights, a ~10 "
     "M-triangle forest; docs/generated-scenes.md) into a folder, or --list them"),
    ("bench", "harness.cli.bench",
     "the reference against Mitsuba (llvm_ad_rgb, scalar_rgb) at equal spp: seconds, paths/s, rays/s, MSE against "
     "ground truth, efficiency 1/(MSE x s) and their ratios"),
    ("stress", "harness.cli.stress",
     "numerical-stability stress table: scaled, translated and strained variants of a scene, per renderer (exit 0 "
     "when every invariant variant of the reference ends as expected)"),
)


class _Subparsers:
    """What a command's ``register`` gets as ``sub``: the subparsers' ``add_parser`` with the command's line of help
    from :data:`COMMANDS` (the one place it is written)."""

    def __init__(self, sub: Any, help: str):
        self._sub, self._help = sub, help

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        return self._sub.add_parser(name, help=self._help, **kwargs)


def build_parser(running: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``running`` (the first word of the command line), only that command's
    module is imported and registered, every other command is a name and its line of help (enough for ``harness
    --help`` and for the did-you-mean of a misspelt command)."""
    parser = common.Parser(prog="harness", description="Validation and benchmark harness for Monte Carlo renderers.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=common.Parser)
    shared = common.Common()
    for name, module, help in COMMANDS:
        if running is None or running == name:
            importlib.import_module(module).register(_Subparsers(sub, help), shared)
        else:
            sub.add_parser(name, help=help)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The ``harness`` command: its exit code. A closed stdout or stderr (``harness ... | head -c 10``) ends the
    command quietly with :data:`~harness.cli.common.EXIT_BROKEN_PIPE` (the Python documentation's recipe for
    SIGPIPE)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    running = str(argv[0]) if argv else ""
    try:
        try:
            return common.dispatch(lambda: build_parser(running), argv)
        finally:  # also after --help's SystemExit: a closed pipe shows here, not at interpreter shutdown
            sys.stdout.flush()
    except BrokenPipeError as err:
        return common.quiet_broken_pipe(err)


if __name__ == "__main__":
    sys.exit(main())
