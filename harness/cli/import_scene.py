"""``harness import FILE --out DIR [--lenient] [--json]``: a Mitsuba 3 XML, glTF 2.0 or pbrt-v4 scene read into
the scene format (TOML + PLY meshes + textures; :mod:`harness.renderers.importers`, docs/import.md).

The imported scene is loaded (:func:`harness.scene.load_scene`) before anything is written, so a file the scene
format cannot hold is refused in one line and ``--out`` is left as it was.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from harness.cli.common import EXIT_OK
from harness.core.errors import HarnessError
from harness.renderers.importers import import_scene
from harness.renderers.imports import ImportedScene, write_imported
from harness.scene import load_scene


def register(sub, common) -> None:
    """Add ``import`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("file",
                        help="the scene to read: Mitsuba 3 XML (.xml), glTF 2.0 (.gltf, .glb) or pbrt-v4 (.pbrt)")
    parser.add_argument("--lenient", action="store_true",
                        help="drop what the scene format cannot express (a warning each) instead of refusing the file")
    parser.set_defaults(func=run)
    sub.add_parser("import", parents=[parser, common.out("output folder (created if needed): scene.toml and the "
                                                         "files it names", required=True),
                                      common.json("print the files written as JSON")])


def run(args: argparse.Namespace) -> int:
    """Import, check that the scene loads, write it into ``--out`` and print what was written."""
    source = Path(args.file)
    imported = import_scene(source, lenient=args.lenient)
    check_loads(imported, Path(args.out))
    scene_file = write_imported(imported, args.out)
    for line in imported.dropped:
        print(f"harness: warning: dropped {line}", file=sys.stderr)
    files = [scene_file] + [Path(args.out) / rel for rel in imported.files]
    if args.json:
        print(json.dumps({"source": str(source), "scene": str(scene_file), "files": [str(f) for f in files],
                          "dropped": imported.dropped}))
    else:
        size = sum(f.stat().st_size for f in files)
        print(f"{source}: {len(files)} files ({size / 1024:.1f} KiB), {len(imported.dropped)} dropped; "
              f"scene file {scene_file}")
    return EXIT_OK


def check_loads(imported: ImportedScene, out: Path) -> None:
    """Load the imported scene from a scratch folder; its first problem as one line naming the file it would be."""
    with tempfile.TemporaryDirectory(prefix="harness-import-") as scratch:
        scene_file = write_imported(imported, Path(scratch) / "scene")
        try:
            load_scene(scene_file, allow_outside_paths=False)
        except HarnessError as err:
            scratch_folder, folder = str(scene_file.parent), str(out)
            raise HarnessError(err.where.replace(scratch_folder, folder),
                               f"{err.message.replace(scratch_folder, folder)} (imported from {imported.source})"
                               ) from None
