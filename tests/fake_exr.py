"""Gaussian pixels and an OpenEXR writer in pure Python, for the fake renderers' scripts (tests/fake_renderers.py,
tests/renderers/test_external_renderer.py), which copy this file beside them (:func:`copy_beside`).

Without numpy and harness.files.imageio a fake renderer starts in about 0.05 CPU-s instead of 0.25 (0.2 with
imageio imported lazily): those imports were most of the ~15 CPU-s that a test run's fake-renderer processes cost
(a py-spy profile). The files are single-part scanline EXRs, uncompressed, float32
channels R, G, B and optionally variance.R/G/B, string attributes for ``metadata``: what
:func:`harness.files.imageio.read_exr` reads (tests/renderers/test_external_renderer.py compares the pixels, the
variance and the header it reads with what was written)."""

from __future__ import annotations

import random
import struct

_FLOAT = 2  # OpenEXR's pixel type FLOAT


def gaussian_image(seed: int, width: int, height: int, mean: float, sd: float) -> list:
    """(height, width, 3) nested lists of mean + sd * N(0, 1), drawn row by row from ``random.Random(seed)``."""
    rng = random.Random(seed)
    return [[[mean + sd * rng.gauss(0.0, 1.0) for _ in range(3)] for _ in range(width)] for _ in range(height)]


def constant_image(value: float, width: int, height: int) -> list:
    return [[[value] * 3 for _ in range(width)] for _ in range(height)]


def _attribute(name: str, kind: str, data: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(data)) + data


def write_exr(path, image: list, variance: list | None = None, metadata: dict | None = None) -> None:
    """Write ``image`` (and ``variance``), (height, width, 3) nested lists, with ``metadata`` (str -> str) as
    string attributes."""
    height, width = len(image), len(image[0])
    planes = {"R": (image, 0), "G": (image, 1), "B": (image, 2)}
    if variance is not None:
        planes |= {"variance.R": (variance, 0), "variance.G": (variance, 1), "variance.B": (variance, 2)}
    names = sorted(planes)  # OpenEXR's order, in the channel list and in each scanline
    channels = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", _FLOAT, 0, 1, 1) for n in names) + b"\0"
    window = struct.pack("<4i", 0, 0, width - 1, height - 1)
    header = (struct.pack("<ii", 20000630, 2) + _attribute("channels", "chlist", channels)
              + _attribute("compression", "compression", b"\0") + _attribute("dataWindow", "box2i", window)
              + _attribute("displayWindow", "box2i", window) + _attribute("lineOrder", "lineOrder", b"\0")
              + _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0))
              + _attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0))
              + _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0))
              + b"".join(_attribute(k, "string", v.encode()) for k, v in (metadata or {}).items()) + b"\0")
    size = 4 * width * len(names)
    start = len(header) + 8 * height
    offsets = struct.pack(f"<{height}Q", *(start + y * (8 + size) for y in range(height)))
    lines = b"".join(struct.pack("<ii", y, size) + b"".join(
        struct.pack(f"<{width}f", *(pixel[c] for pixel in planes[n][0][y])) for n in names for c in [planes[n][1]])
        for y in range(height))
    with open(path, "wb") as f:
        f.write(header + offsets + lines)


def copy_beside(script) -> None:
    """Put this module in the folder of ``script`` (a Path), where the script, run as ``python script``, imports it
    (shutil imported here: the scripts do not need it)."""
    import shutil

    shutil.copyfile(__file__, script.parent / "fake_exr.py")
