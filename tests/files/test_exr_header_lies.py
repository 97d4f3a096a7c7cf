"""EXR headers that lie (docs/robustness.md, "Hostile input"): a count attribute (``spp``, ``variance_dof``) holding
a number no count can be, and a multi-part file whose later part claims an absurd size, are refused on the headers,
before any pixel is read, with one line naming the file and the attribute or part."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from harness.cli import main
from harness.core.errors import HarnessError
from harness.files import imageio as hio

ONES = np.ones((8, 8, 3), np.float32)
WINDOW = b"dataWindow\x00box2i\x00"


def _pair(tmp_path: Path, **metadata: str) -> tuple[Path, Path]:
    """A test image with ``metadata`` and a plain ground truth of 16 spp, both with variance channels."""
    test = hio.write_exr(tmp_path / "test.exr", ONES, 0.01 * ONES, metadata=metadata)
    truth = hio.write_exr(tmp_path / "truth.exr", ONES, 0.01 * ONES, metadata={"spp": "16"})
    return test, truth


def _parts(path: Path, channel_counts: tuple[int, ...], sizes: tuple[int, ...] | None = None) -> Path:
    """A multi-part scanline EXR: part i holds R, G, B and channel_counts[i] - 3 more channels, sizes[i] pixels
    square (8 by default)."""
    parts = []
    for index, count in enumerate(channel_counts):
        side = 8 if sizes is None else sizes[index]
        plane = np.ones((side, side), np.float32)
        channels = {name: plane for name in ("R", "G", "B")[:count]}
        channels.update({f"extra{k}": plane for k in range(count - 3)})
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, "name": f"part{index}",
                  "displayWindow": (np.zeros(2, np.int32), np.full(2, max(sizes or (8,)) - 1, np.int32))}
        parts.append(OpenEXR.Part(header, channels, f"part{index}"))
    OpenEXR.File(parts).write(str(path))
    return path


def _claim(data: bytes, occurrence: int, x_max: int, y_max: int) -> bytes:
    """``data`` with the dataWindow of the header ``occurrence`` (0: part 0's) patched to end at (x_max, y_max), as
    tests/cli/fuzz.py's ``_patch_window`` does for part 0; the pixel data stays as it was."""
    start = -1
    for _ in range(occurrence + 1):
        start = data.index(WINDOW, start + 1)
    start += len(WINDOW) + 4
    x_min, y_min = struct.unpack("<2i", data[start:start + 8])
    return data[:start] + struct.pack("<4i", x_min, y_min, x_max, y_max) + data[start + 16:]


def _spy_on_opens(monkeypatch) -> list[dict]:
    """The options of every OpenEXR open the reader makes from now on (``header_only``: no pixel read)."""
    opened: list[dict] = []
    real = hio._open_exr
    monkeypatch.setattr(hio, "_open_exr", lambda p, **options: opened.append(options) or real(p, **options))
    return opened


def _one_line(code: int, out: str, err: str, *fragments: str) -> str:
    assert code == 2, (code, out, err)
    assert "Traceback" not in err and err.count("\n") == 1, err
    for fragment in fragments:
        assert fragment in err, (fragment, err)
    return err


@pytest.mark.parametrize("key", ["variance_dof", "spp"])
@pytest.mark.parametrize("command", ["compare", "view"])
def test_a_400_digit_count_is_one_line_in_compare_and_view(tmp_path, capfd, key, command):
    """A 400-digit count overflowed the verdict's float conversion (OverflowError traceback in both commands)."""
    test, truth = _pair(tmp_path, **{key: "9" * 400})
    extra = ["--no-tev", "--out", str(tmp_path / "page")] if command == "view" else []
    code = main([command, str(test), str(truth), *extra])
    out, err = capfd.readouterr()
    _one_line(code, out, err, str(test), f"header attribute {key} = '999", "expected a count from 0 to 2^53")
    assert not (tmp_path / "page").exists()


@pytest.mark.parametrize("value", ["9" * 400, "1e400", "inf", "-inf", "nan", "-1", str(2**53 + 2), "1e300"])
def test_a_count_attribute_outside_its_range_is_refused_before_the_pixels(tmp_path, monkeypatch, value):
    path = hio.write_exr(tmp_path / "a.exr", ONES, ONES, metadata={"variance_dof": value})
    opened = _spy_on_opens(monkeypatch)
    with pytest.raises(HarnessError) as caught:
        hio.read_exr(path)
    assert caught.value.where == str(path)
    assert caught.value.message.startswith("header attribute variance_dof = ")
    assert opened == [{"header_only": True}]  # refused on the header: no pixel was read


@pytest.mark.parametrize("value", ["16", "0", str(2**53), " 64 ", "not a number", ""])
def test_a_count_attribute_within_its_range_or_no_number_is_read(tmp_path, value):
    """Sane counts read as before; text that is no number is left to the reader (compare ignores it, as before)."""
    path = hio.write_exr(tmp_path / "a.exr", ONES, ONES, metadata={"spp": value, "variance_dof": value})
    assert hio.read_exr(path).metadata["spp"] == value


def test_a_compare_with_sane_counts_still_judges(tmp_path, capfd):
    test, truth = _pair(tmp_path, variance_dof="63")
    assert main(["compare", str(test), str(truth)]) in (0, 1)
    assert capfd.readouterr().err == ""


def test_a_later_part_claiming_100000_squared_is_refused_on_its_header(tmp_path, monkeypatch):
    """Only part 0's header was checked: part 1 claiming 100000 x 100000 made the reader allocate 37 GiB."""
    path = tmp_path / "parts.exr"
    path.write_bytes(_claim(_parts(path, (3, 3)).read_bytes(), 1, 99999, 99999))
    opened = _spy_on_opens(monkeypatch)
    with pytest.raises(HarnessError) as caught:
        hio.read_exr(path)
    assert caught.value.where == str(path)
    assert caught.value.message.startswith("part 1: data window is 100000 x 100000 pixels")
    assert "\n" not in str(caught.value)
    assert opened == [{"header_only": True}]


def test_a_later_part_beyond_max_pixels_is_refused(tmp_path):
    """``max_pixels`` (an envmap's limit) holds for every part, not part 0 alone."""
    path = _parts(tmp_path / "parts.exr", (3, 3), sizes=(4, 8))
    with pytest.raises(HarnessError, match=r"part 1: is 8 x 8 = 64 pixels; expected at most 20$"):
        hio.read_exr(path, max_pixels=20)


def test_parts_that_together_claim_too_many_channels_are_refused(tmp_path):
    path = _parts(tmp_path / "parts.exr", (40, 40))
    with pytest.raises(HarnessError, match=r"has 2 parts claiming 128 pixels and 80 channels in all"):
        hio.read_exr(path)


def test_a_sane_multi_part_file_reads_its_first_part(tmp_path):
    got = hio.read_exr(_parts(tmp_path / "parts.exr", (3, 5)))
    np.testing.assert_array_equal(got.image, ONES)
    assert got.variance is None
