"""``harness generate NAME[?key=value&...] --out DIR`` and ``harness generate --list``: one of the project's
generated scenes (:mod:`harness.generators`, docs/generated-scenes.md) written where the user asks.

``--out`` must be missing, empty, or a folder this command wrote before (it holds ``generated.json``): such a
folder is replaced whole. Anything else is refused in one line, and nothing is written. The scene is written into a
temporary folder beside ``--out`` and renamed into place, so ``--out`` is never half-written.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from pathlib import Path

from harness.cli.common import EXIT_OK
from harness.core.errors import HarnessError
from harness.generators import GENERATORS, PREFIX, parse_spec, scene_file_name
from harness.generators.scenefile import MANIFEST


def register(sub, common) -> None:
    """Add ``generate`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("name", nargs="?", metavar="NAME",
                        help="the scene: " + ", ".join(GENERATORS) + "; parameters as NAME?key=value&key=value "
                        "(see --list)")
    parser.add_argument("--list", action="store_true", help="list the generated scenes and their parameters")
    parser.set_defaults(func=run)
    sub.add_parser("generate", parents=[parser, common.out(
        "output folder: missing, empty, or one harness generate wrote before (replaced whole)")])


def run(args: argparse.Namespace) -> int:
    """List the generators, or write one scene into ``--out`` and print what was written."""
    if args.list:
        for name, generator in GENERATORS.items():
            params = "&".join(f"{k}={v}" for k, v in generator.defaults.items())
            print(f"{name}: {generator.description} (defaults: {params})")
        return EXIT_OK
    if args.name is None:
        raise HarnessError("NAME", f"expected a scene to generate ({', '.join(GENERATORS)}) or --list")
    if args.out is None:
        raise HarnessError("--out", "expected the folder to write the scene into")
    spec = args.name[len(PREFIX):] if args.name.startswith(PREFIX) else args.name
    generator, params = parse_spec(spec, "NAME")
    out = Path(args.out)
    check_out(out)
    start = time.perf_counter()
    scratch = make_scratch(out)
    try:
        try:
            generator(scratch, **params)
        except HarnessError as err:  # parameters the generator cannot meet together
            raise HarnessError("NAME", err.message) from None
        replace(scratch, out)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    manifest = json.loads((out / MANIFEST).read_text())
    counts = manifest["counts"]
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    shown = ", ".join(f"{k}={v}" for k, v in manifest["params"].items())
    print(f"wrote {out / scene_file_name(generator.name)}: {generator.name} ({shown}): {counts['triangles']:,} triangles, "
          f"{counts['lights']:,} lights, {counts['shapes']:,} shapes, {len(manifest['files']) + 2} files "
          f"({size / 2**20:.1f} MiB) in {time.perf_counter() - start:.1f} s")
    return EXIT_OK


def check_out(out: Path) -> None:
    """Refuse an ``--out`` that is not a folder, or a non-empty folder without ``generated.json``."""
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise HarnessError("--out", f"expected a folder, got {str(out)!r}, which is not one")
    if out.is_dir() and any(out.iterdir()) and not (out / MANIFEST).is_file():
        raise HarnessError("--out", f"{str(out)!r} is not empty and was not written by harness generate (no "
                                    f"{MANIFEST}); expected a missing or empty folder, or one it wrote")


def make_scratch(out: Path) -> Path:
    """A temporary folder beside ``out`` (on its file system, for the rename)."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        return Path(tempfile.mkdtemp(prefix=f".{out.name}.generating-", dir=out.parent))
    except OSError as err:
        raise HarnessError("--out", f"cannot write beside {str(out)!r}: {err.strerror or err}") from None


def replace(scratch: Path, out: Path) -> None:
    """Move the finished ``scratch`` folder to ``out``, an earlier output moved aside first and removed after."""
    old = None
    try:
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=out.parent))
            os.rename(out, old / "folder")
        os.rename(scratch, out)
    except OSError as err:
        raise HarnessError("--out", f"cannot write {str(out)!r}: {err.strerror or err}") from None
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
