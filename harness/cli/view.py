"""``harness view A.exr [B.exr]``: the images in tev where a tev instance listens (``--tev HOST:PORT``, default
127.0.0.1:14158; :mod:`harness.files.tev`), else the report's comparison viewer for them, written as a page into a
folder (``--out``, default a new temporary folder) whose path is printed. A peer that answers or closes the
connection is not tev: the page is written then too. With two images the first plays the render and the second the
ground truth: error maps, FLIP and, where both have variance channels, the verdict's tiles (docs/report.md,
"harness view")."""

from __future__ import annotations

import argparse
import sys
import tempfile
import webbrowser
from pathlib import Path

import numpy as np

from harness.cli.common import EXIT_OK
from harness.core import options
from harness.core.errors import HarnessError
from harness.files import tev
from harness.files.imageio import RGB_CHANNELS, VARIANCE_CHANNELS, ExrImage, read_exr
from harness.judges import metrics
from harness.report.viewer import write_view_page
from harness.running.compare import compare_images

#: the verdict's settings for a pair, as ``harness compare``'s defaults
TILE, ALPHA = 8, 0.001
#: seconds to wait for tev to accept the connection
CONNECT_TIMEOUT = 0.5


def register(sub, common) -> None:
    """Add ``view`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("first", metavar="A.exr", help="an image (with two: the render)")
    parser.add_argument("second", metavar="B.exr", nargs="?", help="a second image of the same size, compared with "
                        "the first as its ground truth")
    parser.add_argument("--tev", type=options.host_port, default=tev.DEFAULT_ADDRESS, metavar="HOST:PORT",
                        help="where tev listens (default 127.0.0.1:14158); where nothing does, the page is written")
    parser.add_argument("--no-tev", action="store_true", help="write the page even where tev listens")
    parser.add_argument("--open", action="store_true", help="open the page in a web browser")
    parser.set_defaults(func=run)
    sub.add_parser("view", parents=[parser, common.out("folder for the viewer page (default: a new temporary folder)"),
                            common.quiet()])


def _channels(image: ExrImage):
    """The image's channels for tev: R, G, B and, where it has them, variance.R, G, B."""
    if image.variance is None:
        return image.image, list(RGB_CHANNELS)
    return np.concatenate([image.image, image.variance], axis=-1), list(RGB_CHANNELS + VARIANCE_CHANNELS)


def _to_tev(address: tuple[str, int], images: list[tuple[str, ExrImage]]) -> bool:
    """Send the images to tev at ``address``; False where nothing listens there, the connection breaks, or the peer
    answers or closes the connection (:meth:`harness.files.tev.TevClient.confirm`: not tev)."""
    try:
        client = tev.TevClient(address, timeout=CONNECT_TIMEOUT)
    except OSError:
        return False
    try:
        with client:
            for index, (name, image) in enumerate(images):
                pixels, channels = _channels(image)
                tev.send_image(client, name, pixels, channels, grab_focus=index == 0)
            client.confirm()
    except tev.NotTev as err:
        print(f"harness: {address[0]}:{address[1]} is not tev: it {err}; writing the page instead", file=sys.stderr)
        return False
    except OSError as err:
        print(f"harness: {address[0]}:{address[1]} broke the connection ({err.strerror or err}); writing the page "
              "instead", file=sys.stderr)
        return False
    return True


def _page(args: argparse.Namespace, first: ExrImage, second: ExrImage | None) -> Path:
    """The viewer page of the image(s), written into ``--out`` (default: a new temporary folder)."""
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="harness-view-"))
    flip = tiles = verdict = note = None
    if second is not None:
        flip = metrics.flip(first.image, second.image, full=True)[1]
        if first.variance is None or second.variance is None:
            missing = args.first if first.variance is None else args.second
            note = f"No verdict: {missing} has no variance channels (variance.R, G, B)."
        else:
            maps: dict = {}
            try:
                verdict = compare_images(first, second, tile=TILE, alpha=ALPHA, maps=maps)["verdict"]
                tiles = maps.get("tiles")
            except HarnessError as err:
                note = f"No verdict: {err}"
    name = Path(args.first).name + (f" vs {Path(args.second).name}" if second is not None else "")
    files = [str(args.first)] + ([str(args.second)] if second is not None else [])
    return write_view_page(out, name=name, render=first.image, render_variance=first.variance,
                           truth=None if second is None else second.image,
                           truth_variance=None if second is None else second.variance, flip=flip, tiles=tiles,
                           verdict_dict=verdict, labels={"render": str(args.first), "truth": str(args.second or "")},
                           files=files, note=note)


def run(args: argparse.Namespace) -> int:
    """Send the images to tev, or write the viewer page and print its path."""
    first = read_exr(args.first)
    second = read_exr(args.second) if args.second else None
    if second is not None and second.image.shape != first.image.shape:
        h1, w1 = first.image.shape[:2]
        h2, w2 = second.image.shape[:2]
        raise HarnessError(args.second, f"size {w2}x{h2} differs from {args.first} ({w1}x{h1}); expected images of "
                           "the same size")
    images = [(str(args.first), first)] + ([(str(args.second), second)] if second is not None else [])
    if not args.no_tev and _to_tev(args.tev, images):
        host, port = args.tev
        print(f"sent {' and '.join(name for name, _ in images)} to {host}:{port} (tev sends no acknowledgement)")
        return EXIT_OK
    page = _page(args, first, second)
    print(page)
    if args.open:
        webbrowser.open(page.resolve().as_uri())
    return EXIT_OK
