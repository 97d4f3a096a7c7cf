"""``harness compare TEST GROUND_TRUTH``: image metrics and the statistical verdict of a render against its
ground truth (exit 1 on fail)."""

from __future__ import annotations

import argparse
import json
import sys

from harness.cli.common import EXIT_FAIL, EXIT_OK, one_line
from harness.core import options
from harness.core.errors import HarnessError
from harness.files import imageio
from harness.files.verdict_maps import write_verdict_maps
from harness.running.compare import compare_files

MAX_TILE = 1024  # the verdict pads the image to whole tiles: a larger tile only costs memory


def register(sub, common) -> None:
    """Add ``compare`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("test", help="the render to judge (.exr with variance.R/G/B channels)")
    parser.add_argument("ground_truth", metavar="ground-truth",
                        help="the ground truth (.exr; variance channels optional for a closed form)")
    parser.add_argument("--tile", type=options.parse_int, default=8,
                        help=f"tile size in pixels for the verdict, 1 to {MAX_TILE} (default 8)")
    parser.add_argument("--alpha", type=options.probability, default=0.001,
                        help="false-alarm probability of the verdict (default 0.001)")
    parser.add_argument("--maps", metavar="DIR", help="also write the verdict's tile maps into DIR: pvalue.exr (each "
                        "tile's two-sided p per channel) and failing.exr (1 in tiles that fail by themselves), as "
                        "harness run writes beside each case")
    parser.add_argument("--diagnose", action="store_true",
                        help="also say why the images differ: the best integer shift (up to 4 pixels) and mirror, the "
                        "global scale factor with its 99 %% interval (named when it is 1, pi, 2 pi or 4 pi, or their "
                        "inverse) and the share of the squared difference in the brightest 1 %% of pixels (with "
                        "--json: its \"diagnosis\" section)")
    parser.set_defaults(func=run)
    sub.add_parser("compare", parents=[parser, common.json()])


def run(args: argparse.Namespace) -> int:
    """Print the verdict and the metrics; exit 0 on pass, 1 on fail."""
    if not 1 <= args.tile <= MAX_TILE:
        raise HarnessError("--tile", f"expected an integer from 1 to {MAX_TILE} (pixels per tile side), got {args.tile}")
    if not 0 < args.alpha < 1:
        raise HarnessError("--alpha", f"expected a false-alarm probability in (0, 1), got {args.alpha}")
    maps: dict | None = {} if args.maps else None
    report = compare_files(args.test, args.ground_truth, tile=args.tile, alpha=args.alpha, maps=maps,
                           diagnose=args.diagnose)
    if maps is not None and maps.get("tiles") is not None:
        v = report["verdict"]
        with imageio.removed_on_failure(imageio.make_folders(args.maps, where="--maps")):  # no empty folder left
            written = write_verdict_maps(args.maps, maps["tiles"], tile=v["tile"], alpha=v["alpha"],
                                         threshold=v["threshold"], height=report["height"], width=report["width"],
                                         metadata={"test": str(args.test), "ground_truth": str(args.ground_truth)})
        report["verdict_maps"] = {key: str(path) for key, path in written.items()}
    if args.json:
        print(json.dumps(report, indent=2, default=float))
    else:
        m = report["metrics"]
        v = report["verdict"]
        print(f"verdict: {v['verdict']}" + (f" ({v.get('reason')})" if v.get("reason") else ""))
        # a metric that is not a finite number is None (null in --json): PSNR of identical images or of an all-zero
        # ground truth, every metric when no pixel is finite in both images
        why = " (no pixel is finite in both images)" if not report.get("metric_pixels") else ""
        for key in ("rmse", "relmse", "mape", "psnr", "ssim", "flip"):
            if key in m:
                print(f"  {key:7s} {m[key]:.6g}" if m[key] is not None else f"  {key:7s} undefined{why}")
        for key, label in (("test", "test image:  "), ("ground_truth", "ground truth:")):
            print(f"{label} {_facts_text(report['images'][key])}")
        if "diagnosis" in report:
            for line in diagnosis_lines(report["diagnosis"]):
                print(line)
        if "verdict_maps" in report:
            print(f"wrote {report['verdict_maps']['pvalue']} and {report['verdict_maps']['failing']}")
    if report["images"]["warning"]:
        print(f"harness: warning: {one_line(report['images']['warning'])}", file=sys.stderr)
    return EXIT_OK if report["verdict"]["verdict"] == "pass" else EXIT_FAIL


def diagnosis_lines(diagnosis: dict) -> list[str]:
    """The ``--diagnose`` section: a headline, then the shift, the scale and the brightest pixels, a line each."""
    shift, scale, bright = diagnosis["shift"], diagnosis["scale"], diagnosis["bright"]
    moved = shift["significant"]
    named = scale.get("named")
    headline = []
    if not moved:
        headline.append("no shift")
    if named == "1":
        headline.append("scale 1 within its interval")
    elif named:
        headline.append(f"scale about {named}")
    elif scale["scale"] is not None:
        headline.append(f"scale {scale['scale']:.4g}")
    if moved:
        headline.insert(0, _shift_words(shift))
    lines = ["diagnosis: " + ", ".join(headline)]
    if moved:
        lines.append(f"  shift   the test matches the ground truth {_shift_words(shift)} (z = {shift['z']:.3g} against "
                     f"the image as it is; mean weighted squared difference {shift['mse']:.4g}, as it is "
                     f"{shift['mse_identity']:.4g})")
    else:
        lines.append(f"  shift   none: no shift of up to {shift['max_shift']} pixels and no mirror fits better "
                     "than the image as it is (beyond its noise)")
    if scale["scale"] is None:
        lines.append("  scale   undefined (the ground truth is 0 everywhere)")
    else:
        interval = f"{scale['level']:.0%} interval {scale['low']:.4g} .. {scale['high']:.4g}"
        what = {None: "no factor of pi", "1": "1 lies within it"}.get(named, f"about {named}")
        lines.append(f"  scale   test = {scale['scale']:.4g} x ground truth ({interval}): {what}")
    if bright["share"] is not None:
        where = "concentrated there" if bright["concentrated"] else "not concentrated there"
        lines.append(f"  bright  the brightest {bright['top']:.0%} of the ground truth's pixels ({bright['pixels']}) "
                     f"hold {bright['share']:.0%} of the squared difference (noise alone would put "
                     f"{bright['noise_share']:.0%} there): {where}")
    return lines


def _shift_words(shift: dict) -> str:
    """How the test shows the ground truth: "moved 1 pixel down", "mirrored left-right", ..."""
    parts = []
    if shift["mirror"] != "none":
        parts.append("mirrored " + {"horizontal": "left-right", "vertical": "top-bottom"}[shift["mirror"]])
    steps = [f"{abs(d)} pixel{'s' if abs(d) != 1 else ''} {more if d > 0 else less}"
             for d, more, less in ((shift["dx"], "right", "left"), (shift["dy"], "down", "up")) if d]
    if steps:
        parts.append("moved " + " and ".join(steps))
    return " and ".join(parts)


def _facts_text(facts: dict) -> str:
    """One image's line: its path, spp and mean variance, as far as its file says."""
    spp = f"{facts['spp']} spp" if facts["spp"] is not None else "spp not recorded"
    variance = (f"mean variance {facts['mean_variance']:.3g}" if facts["mean_variance"] is not None
                else "no variance channels")
    return f"{facts['path']} ({spp}, {variance})"
