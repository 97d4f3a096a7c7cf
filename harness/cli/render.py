"""``harness render SCENE --spp N --out FILE.exr``: one render to OpenEXR (R, G, B and variance), with a PNG
preview beside it."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from harness.cli.common import EXIT_FAIL, EXIT_OK, SCENE_HELP, check_cost, exr_out_path, path_progress, with_film
from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import parse_set, require_non_negative, require_positive
from harness.files import imageio
from harness.renderers import RenderRequest, get_renderer, renderer_names
from harness.renderers.external import ExternalRendererError, variance_metadata
from harness.renderers.validate import BadRenderError, validate_result
from harness.scene import load_scene, scene_argument


def register(sub, common) -> None:
    """Add ``render`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("scene", help=SCENE_HELP)
    parser.add_argument("--renderer", default="reference", help=f"one of: {', '.join(renderer_names())}, or the "
                        "path of a renderer file (.toml, docs/external-renderers.md)")
    parser.add_argument("--spp", type=options.positive_int, required=True, help="viewing rays (samples) per pixel, Np")
    parser.add_argument("--seed", type=options.non_negative_int, default=0,
                        help="seed of every random stream (default 0)")
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="a renderer setting, e.g. direct=global-area, shadow_rays=4, rr=off, max_depth=3, sampler=independent "
             "(repeatable; see docs/reference-renderer.md)",
    )
    parser.add_argument("--max-depth", type=options.non_negative_int, metavar="N",
                        help="the scene's max_depth replaced, as a suite case's max_depth does")
    parser.set_defaults(func=run)
    sub.add_parser(
        "render", parents=[parser, common.film(),
                 common.out("output .exr (R, G, B and variance.R/G/B); a .png preview is written beside it", file=True,
                            required=True),
                 common.json("print one JSON object with timings and counters"), common.quiet(),
                 common.mitsuba_variant(), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """Render, check what the renderer returned, write the EXR and its preview; exit 1 when the render failed."""
    out = exr_out_path(args.out)
    require_positive("--spp", args.spp)
    require_non_negative("--seed", args.seed)
    scene = with_film(load_scene(scene_argument(args.scene)), args.film)
    if args.max_depth is not None:
        scene = dataclasses.replace(scene, max_depth=args.max_depth)
    check_cost(scene, args.spp, "--spp")
    renderer = get_renderer(args.renderer)
    settings = parse_set(args.set)
    if args.mitsuba_variant:
        if renderer.name != "mitsuba":
            raise HarnessError("--mitsuba-variant", "applies to --renderer mitsuba only")
        settings["variant"] = args.mitsuba_variant
    bar, progress = path_progress(args, f"{renderer.name} {scene.name}")
    try:
        result = renderer.render(scene, RenderRequest(spp=args.spp, seed=args.seed, settings=settings, progress=progress))
        validate_result(result, scene.film.width, scene.film.height, for_verdict=False)
    except (ExternalRendererError, BadRenderError) as err:  # the renderer failed, not the user's input: exit 1
        print(f"harness: render failed: {renderer.name}: {err}", file=sys.stderr)
        return EXIT_FAIL
    except HarnessError:
        raise
    except Exception as err:  # a crash inside the renderer: one line (HARNESS_DEBUG=1 shows the traceback)
        if os.environ.get("HARNESS_DEBUG"):
            raise
        print(f"harness: render failed: {renderer.name}: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
              " (HARNESS_DEBUG=1 shows the traceback)", file=sys.stderr)
        return EXIT_FAIL
    finally:
        if bar is not None:
            bar.close()
    metadata = {
        "renderer": result.renderer,
        "scene": str(scene.path),
        **variance_metadata(result),
        "seed": str(args.seed),
        "settings": json.dumps(result.settings, sort_keys=True),
    }
    _, preview = imageio.write_exr_with_preview(out, result.image, result.variance, metadata=metadata)  # or neither
    summary = _summary(result, scene, out, preview, args.seed)
    if args.json:
        print(json.dumps(summary, indent=2, sort_keys=False))
    else:
        loaded = (f"; kernels loaded in {result.load_seconds:.2f} s before the clock"
                  if result.load_seconds is not None else "")
        print(
            f"{result.renderer}: {scene.name} {scene.film.width}x{scene.film.height}, {result.spp} spp in "
            f"{result.seconds:.2f} s{loaded} ({_rates_text(summary)}); {summary['nonfinite_pixels']} non-finite "
            f"pixels\n"
            f"wrote {out} and {preview}"
        )
    return EXIT_OK


#: the shortest render time a rate is computed from: the resolution of the clocks render times are measured with
CLOCK_RESOLUTION = max(time.get_clock_info(name).resolution for name in ("perf_counter", "monotonic"))


def _rates_text(summary: dict) -> str:
    """The rates of the human line, or why there are none (a command-line renderer whose time was all start-up)."""
    if summary["paths_per_second"] is None:
        return "paths/s and rays/s n/a: no render time left once the start-up was subtracted"
    return f"{summary['paths_per_second'] / 1e6:.3f} M paths/s, {summary['rays_per_second'] / 1e6:.2f} M rays/s"


def _summary(result, scene, out: Path, preview: Path, seed: int) -> dict:
    """What ``--json`` prints: the render's timings (``seconds``, the render alone; ``load_seconds``, what the
    renderer loaded before its clock started, the reference's compiled kernels, null where a renderer does not
    say), counters and files. The rates are None (null) where the render
    time is not above :data:`CLOCK_RESOLUTION` (all of an external renderer's time was its start-up): a rate divided
    by nothing is no measurement."""
    total_rays = sum(result.rays.values())
    seconds = result.seconds if result.seconds > CLOCK_RESOLUTION else None
    return {
        "renderer": result.renderer,
        "scene": str(scene.path),
        "width": scene.film.width,
        "height": scene.film.height,
        "spp": result.spp,
        "seed": seed,
        "seconds": result.seconds,
        "load_seconds": result.load_seconds,
        "paths": result.paths,
        "paths_per_second": result.paths / seconds if seconds else None,
        "rays": dict(result.rays, total=total_rays),
        "rays_per_second": total_rays / seconds if seconds else None,
        "nonfinite_pixels": result.nonfinite_pixels,
        "mean_radiance": [float(v) for v in np.mean(result.image.astype(np.float64), axis=(0, 1))],
        "settings": result.settings,
        "stats": result.stats,
        "info": result.info,
        "out": str(out),
        "preview": str(preview),
        "host": {"python": platform.python_version(), "cpus": os.cpu_count()},
    }
