"""The command line: parse, call, print. User errors become one line on stderr and exit code 2."""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

from harness.errors import HarnessError

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line naming the option (and exit code 2)."""

    def error(self, message: str) -> None:  # noqa: D401 - argparse's signature
        raise HarnessError(self.prog, message)


def _parse_set(values: list[str]) -> dict[str, str]:
    settings: dict[str, str] = {}
    for item in values:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise HarnessError("--set", f"expected key=value, got {item!r}")
        settings[key.strip()] = value.strip()
    return settings


def _progress_bar(enabled: bool, description: str):
    """A tqdm bar on stderr fed by ``progress(done, total)`` callbacks, or None when quiet / not a terminal."""
    if not enabled:
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=0, desc=description, unit="path", unit_scale=True, file=sys.stderr, leave=False)

    def progress(done: int, total: int) -> None:
        if bar.total != total:
            bar.total = total
        bar.update(done - bar.n)

    return bar, progress


def cmd_render(args: argparse.Namespace) -> int:
    from harness import imageio
    from harness.renderers import RenderRequest, get_renderer
    from harness.scene import load_scene

    out = Path(args.out)
    if out.suffix.lower() != ".exr":
        raise HarnessError("--out", f"expected a file name ending in .exr, got {args.out!r}")
    if not out.parent.is_dir():
        raise HarnessError("--out", f"folder {str(out.parent)!r} does not exist")
    if not os.access(out.parent, os.W_OK):
        raise HarnessError("--out", f"folder {str(out.parent)!r} is not writable")
    if args.spp < 1:
        raise HarnessError("--spp", f"expected a positive integer, got {args.spp}")
    if args.seed < 0:
        raise HarnessError("--seed", f"expected a non-negative integer, got {args.seed}")
    scene = load_scene(args.scene)
    renderer = get_renderer(args.renderer)
    show = not args.quiet and sys.stderr.isatty()
    bar, progress = _progress_bar(show, f"{renderer.name} {scene.name}")
    try:
        result = renderer.render(
            scene, RenderRequest(spp=args.spp, seed=args.seed, settings=_parse_set(args.set), progress=progress)
        )
    finally:
        if bar is not None:
            bar.close()
    metadata = {
        "renderer": result.renderer,
        "scene": str(scene.path),
        "spp": str(result.spp),
        "seed": str(args.seed),
        "settings": json.dumps(result.settings, sort_keys=True),
    }
    imageio.write_exr(out, result.image, result.variance, metadata=metadata)
    preview = imageio.write_png_preview(imageio.preview_path(out), result.image)
    summary = _render_summary(result, scene, out, preview, args.seed)
    if args.json:
        print(json.dumps(summary, indent=2, sort_keys=False))
    else:
        print(
            f"{result.renderer}: {scene.name} {scene.film.width}x{scene.film.height}, {result.spp} spp in "
            f"{result.seconds:.2f} s ({summary['paths_per_second'] / 1e6:.3f} M paths/s, "
            f"{summary['rays_per_second'] / 1e6:.2f} M rays/s); {summary['nonfinite_pixels']} non-finite pixels\n"
            f"wrote {out} and {preview}"
        )
    return EXIT_OK


def _render_summary(result, scene, out: Path, preview: Path, seed: int) -> dict:
    import numpy as np

    total_rays = sum(result.rays.values())
    seconds = max(result.seconds, 1e-12)
    return {
        "renderer": result.renderer,
        "scene": str(scene.path),
        "width": scene.film.width,
        "height": scene.film.height,
        "spp": result.spp,
        "seed": seed,
        "seconds": result.seconds,
        "paths": result.paths,
        "paths_per_second": result.paths / seconds,
        "rays": dict(result.rays, total=total_rays),
        "rays_per_second": total_rays / seconds,
        "nonfinite_pixels": result.nonfinite_pixels,
        "mean_radiance": [float(v) for v in np.mean(result.image.astype(np.float64), axis=(0, 1))],
        "settings": result.settings,
        "stats": result.stats,
        "info": result.info,
        "out": str(out),
        "preview": str(preview),
        "host": {"python": platform.python_version(), "cpus": os.cpu_count()},
    }


def build_parser() -> argparse.ArgumentParser:
    from harness.renderers import renderer_names

    parser = _Parser(prog="harness", description="Validation and benchmark harness for Monte Carlo renderers.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    render = sub.add_parser("render", help="render a scene to an OpenEXR file (plus a PNG preview)")
    render.add_argument("scene", help="scene file (TOML, see docs/scene-format.md)")
    render.add_argument("--renderer", default="reference", help=f"one of: {', '.join(renderer_names())}")
    render.add_argument("--spp", type=int, required=True, help="viewing rays (samples) per pixel, Np")
    render.add_argument("--seed", type=int, default=0, help="seed of every random stream (default 0)")
    render.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="a renderer setting, e.g. direct=global-area, shadow_rays=4, rr=off, max_depth=3 (repeatable; "
        "see docs/reference-renderer.md)",
    )
    render.add_argument("--out", required=True, help="output .exr (R, G, B and variance.R/G/B); a .png preview is written beside it")
    render.add_argument("--json", action="store_true", help="print one JSON object with timings and counters")
    render.add_argument("--quiet", action="store_true", help="no progress bar")
    render.set_defaults(func=cmd_render)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        return args.func(args)
    except HarnessError as err:
        print(f"harness: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("harness: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
