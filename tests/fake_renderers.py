"""A fake external renderer for timing tests: it sleeps for its "start-up", then for its "rendering" (in proportion
to spp x pixels), and writes 0.5 + Gaussian noise of standard deviation ``noise / sqrt(spp)`` (the furnace's closed
form at 8 x 8 and depth 2 is 0.5) without variance channels, so the harness runs it ``repeats`` times. It imports
neither numpy nor the harness (tests/fake_exr.py): its start-up is the sleep and the interpreter's."""

from __future__ import annotations

import json
from pathlib import Path

from fake_exr import copy_beside

SCRIPT = r'''
import sys, time
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
time.sleep(float(args["--startup"]))
from fake_exr import gaussian_image, write_exr
w, h, spp = int(args["--width"]), int(args["--height"]), int(args["--spp"])
if spp < int(args["--min-spp"]):
    sys.exit(f"fake: error: --spp: expected at least {args['--min-spp']}, got {spp}")
start = time.perf_counter()
time.sleep(float(args["--per-spp"]) * spp * w * h / 64)
write_exr(args["--out"], gaussian_image(int(args["--seed"]), w, h, 0.5, float(args["--noise"]) / spp**0.5))
if args["--own-time"] == "1":
    open(args["--out"] + ".json", "w").write('{"render_seconds": %r}' % (time.perf_counter() - start))
'''


def slow_start_renderer(folder: Path, *, startup: float, per_spp: float, noise: float, repeats: int = 2,
                        min_spp: int = 1, own_time: bool = False) -> Path:
    """Write the fake renderer's script and its renderer file into ``folder``; returns the renderer file.
    ``per_spp``: seconds per spp at 8 x 8 pixels; ``min_spp``: it exits 1 with an error below this spp;
    ``own_time``: it reports its render time in ``<out>.json``."""
    script = folder / "fake.py"
    script.write_text(SCRIPT)
    copy_beside(script)
    path = folder / "fake.toml"
    command = ["{python}", str(script), "--out", "{out}", "--seed", "{seed}", "--spp", "{spp}", "--width", "{width}",
               "--height", "{height}", "--startup", str(startup), "--per-spp", str(per_spp), "--noise", str(noise),
               "--min-spp", str(min_spp), "--own-time", "1" if own_time else "0"]
    path.write_text(f"command = {json.dumps(command)}\nrepeats = {repeats}\n")
    return path
