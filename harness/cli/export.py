"""``harness export SCENE --format mitsuba-xml|json|ply|obj|gltf --out DIR``: a scene in formats other renderers
load (:mod:`harness.renderers.export`; ``json`` is scene.json, docs/scene-json.md)."""

from __future__ import annotations

import argparse
import json
import sys

from harness.cli.common import EXIT_OK, SCENE_HELP, check_cost, with_film
from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import require_non_negative, require_positive
from harness.renderers.export import FORMATS, export_losses, export_scene
from harness.scene import load_scene, scene_argument


def register(sub, common) -> None:
    """Add ``export`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("scene", help=SCENE_HELP)
    parser.add_argument("--format", required=True, help=f"one of: {', '.join(FORMATS)}")
    parser.add_argument("--spp", type=options.positive_int, default=16,
                        help="mitsuba-xml: default of the $spp parameter (default 16)")
    parser.add_argument("--seed", type=options.non_negative_int, default=0,
                        help="mitsuba-xml: default of the $seed parameter (default 0)")
    parser.set_defaults(func=run)
    sub.add_parser(
        "export", parents=[parser, common.film(), common.out("output folder (created if needed)", required=True),
                 common.json("print the files written as JSON"), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """Write the scene's files into ``--out`` and print what was written."""
    if args.format not in FORMATS:
        raise HarnessError("--format", f"expected one of {', '.join(FORMATS)}, got {args.format!r}")
    require_positive("--spp", args.spp)
    require_non_negative("--seed", args.seed)
    scene = with_film(load_scene(scene_argument(args.scene)), args.film)
    check_cost(scene, args.spp, "--spp")  # the $spp an exported Mitsuba scene renders at by default
    files = export_scene(scene, args.format, args.out, spp=args.spp, seed=args.seed)
    for loss in export_losses(scene, args.format):
        print(f"harness: warning: {loss}", file=sys.stderr)
    if args.json:
        print(json.dumps({"scene": str(scene.path), "format": args.format, "files": [str(f) for f in files]}))
    else:
        size = sum(f.stat().st_size for f in files)
        print(f"{scene.name}: {args.format}, {len(scene.shapes)} shapes, {len(files)} files ({size / 1024:.1f} KiB); "
              f"main file {files[0]}")
    return EXIT_OK
