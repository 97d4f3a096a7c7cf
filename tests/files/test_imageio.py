"""Tests for harness.files.imageio: EXR round trips, error handling, atomic writes, PNG previews."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from harness.files import imageio as hio
from harness.core.errors import HarnessError


def _image(h: int = 7, w: int = 11, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    # Values that are not representable in half and span many magnitudes.
    return (rng.random((h, w, 3)) * 10.0 ** rng.integers(-6, 6, (h, w, 3))).astype(np.float32)


def _write_raw_exr(path: Path, channels: dict[str, np.ndarray], **header: object) -> Path:
    hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, **header}
    OpenEXR.File(hdr, channels).write(str(path))
    return path


def _assert_one_line_naming(err: HarnessError, path: Path) -> str:
    msg = str(err)
    assert str(path) in msg
    assert "\n" not in msg and "\r" not in msg
    assert err.where == str(path)
    return msg


def _leftovers(folder: Path, keep: set[str]) -> list[str]:
    return sorted(set(os.listdir(folder)) - keep)


# ---------------------------------------------------------------------------
# EXR round trips
# ---------------------------------------------------------------------------


def test_round_trip_image_and_variance_exact(tmp_path: Path) -> None:
    img = _image()
    var = _image(seed=1)
    out = hio.write_exr(tmp_path / "a.exr", img, var)
    assert out == tmp_path / "a.exr"
    got = hio.read_exr(out)
    assert got.image.dtype == np.float32 and got.image.shape == img.shape
    assert got.variance is not None and got.variance.dtype == np.float32
    np.testing.assert_array_equal(got.image, img)
    np.testing.assert_array_equal(got.variance, var)


def test_round_trip_without_variance(tmp_path: Path) -> None:
    img = _image(3, 4)
    got = hio.read_exr(hio.write_exr(tmp_path / "a.exr", img))
    assert got.variance is None
    np.testing.assert_array_equal(got.image, img)


def test_float64_input_is_written_as_float32(tmp_path: Path) -> None:
    img = _image().astype(np.float64) / 3.0
    got = hio.read_exr(hio.write_exr(tmp_path / "a.exr", img))
    np.testing.assert_array_equal(got.image, img.astype(np.float32))


def test_non_finite_values_are_written_as_they_are(tmp_path: Path) -> None:
    img = np.ones((2, 3, 3), np.float32)
    img[0, 0, 0] = np.nan
    img[0, 1, 1] = np.inf
    img[1, 2, 2] = -np.inf
    got = hio.read_exr(hio.write_exr(tmp_path / "a.exr", img)).image
    assert np.isnan(got[0, 0, 0]) and got[0, 1, 1] == np.inf and got[1, 2, 2] == -np.inf
    assert np.isfinite(got).sum() == img.size - 3


def test_metadata_round_trip(tmp_path: Path) -> None:
    meta = {
        "renderer": "mitsuba 3.5.2",
        "spp": "1024",
        "settings": '{"max_depth": 8, "integrator": "path", "name": "héllo ✓"}',
        "empty": "",
    }
    got = hio.read_exr(hio.write_exr(tmp_path / "a.exr", _image(), metadata=meta))
    assert got.metadata == meta


def test_channel_names_in_written_file(tmp_path: Path) -> None:
    path = hio.write_exr(tmp_path / "a.exr", _image(), _image(seed=2))
    with OpenEXR.File(str(path), separate_channels=True) as f:
        names = set(f.channels())
        header = dict(f.header())
        types = {name: ch.type() for name, ch in f.channels().items()}
    assert names == {"R", "G", "B", "variance.R", "variance.G", "variance.B"}
    assert all(t == OpenEXR.FLOAT for t in types.values())
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION
    assert header["type"] == OpenEXR.scanlineimage


def test_channels_hold_the_right_planes(tmp_path: Path) -> None:
    img = np.zeros((2, 2, 3), np.float32)
    img[..., 0], img[..., 1], img[..., 2] = 1.0, 2.0, 3.0
    path = hio.write_exr(tmp_path / "a.exr", img, img * 10)
    with OpenEXR.File(str(path), separate_channels=True) as f:
        ch = {name: c.pixels.copy() for name, c in f.channels().items()}
    assert (ch["R"] == 1).all() and (ch["G"] == 2).all() and (ch["B"] == 3).all()
    assert (ch["variance.R"] == 10).all() and (ch["variance.B"] == 30).all()


def test_top_row_stays_top(tmp_path: Path) -> None:
    img = np.zeros((4, 5, 3), np.float32)
    img[0, :, :] = 1.0  # bright top row
    img[:, 0, 1] = 2.0  # left column marked in G
    path = hio.write_exr(tmp_path / "a.exr", img)
    with OpenEXR.File(str(path), separate_channels=True) as f:
        r = f.channels()["R"].pixels
        assert f.header()["lineOrder"] == OpenEXR.INCREASING_Y
    assert (r[0] == 1).all() and (r[1:] == 0).all()
    got = hio.read_exr(path).image
    assert (got[0, :, 0] == 1).all() and (got[1:, :, 0] == 0).all()
    assert (got[:, 0, 1] == 2).all() and (got[:, 1:, 1][1:] == 0).all()


def test_non_square_shape_preserved(tmp_path: Path) -> None:
    img = _image(3, 17)
    got = hio.read_exr(hio.write_exr(tmp_path / "a.exr", img))
    assert got.image.shape == (3, 17, 3)


def test_read_rgba_file_ignores_extra_channels(tmp_path: Path) -> None:
    img = _image(5, 6)
    path = _write_raw_exr(
        tmp_path / "rgba.exr",
        {
            "R": img[..., 0].copy(),
            "G": img[..., 1].copy(),
            "B": img[..., 2].copy(),
            "A": np.ones((5, 6), np.float32),
        },
        generatedBy="some renderer",
    )
    got = hio.read_exr(path)
    np.testing.assert_array_equal(got.image, img)
    assert got.variance is None
    assert got.metadata == {"generatedBy": "some renderer"}


def test_read_half_channels(tmp_path: Path) -> None:
    img = (_image(4, 4) % 1000.0).astype(np.float16)
    path = _write_raw_exr(
        tmp_path / "half.exr",
        {"R": img[..., 0].copy(), "G": img[..., 1].copy(), "B": img[..., 2].copy(),
         "A": np.ones((4, 4), np.float16)},
    )
    with OpenEXR.File(str(path), separate_channels=True) as f:
        assert f.channels()["R"].type() == OpenEXR.HALF
    got = hio.read_exr(path)
    assert got.image.dtype == np.float32
    np.testing.assert_array_equal(got.image, img.astype(np.float32))


def test_read_half_variance(tmp_path: Path) -> None:
    img = np.full((2, 3), 0.5, np.float16)
    chans = {n: img for n in ("R", "G", "B", "variance.R", "variance.G", "variance.B")}
    got = hio.read_exr(_write_raw_exr(tmp_path / "hv.exr", chans))
    assert got.variance is not None and got.variance.dtype == np.float32
    assert (got.variance == 0.5).all()


# ---------------------------------------------------------------------------
# EXR read errors
# ---------------------------------------------------------------------------


def test_truncated_file(tmp_path: Path) -> None:
    path = hio.write_exr(tmp_path / "t.exr", _image(64, 80), _image(64, 80, seed=3))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    _assert_one_line_naming(info.value, path)


@pytest.mark.parametrize("keep", [1, 3, 10, 100])
def test_file_cut_very_short(tmp_path: Path, keep: int) -> None:
    path = hio.write_exr(tmp_path / "t.exr", _image())
    path.write_bytes(path.read_bytes()[:keep])
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    _assert_one_line_naming(info.value, path)


def test_corrupted_pixel_data(tmp_path: Path) -> None:
    # A smooth (compressible) image, so the damaged bytes sit inside a deflate
    # stream and break it.  (Damage to incompressible data, which ZIP stores
    # raw, cannot be detected: EXR has no pixel checksums.)
    yy, xx = np.mgrid[0:64, 0:80].astype(np.float32)
    smooth = np.stack([xx / 80, yy / 64, np.full_like(xx, 0.5)], axis=-1)
    path = hio.write_exr(tmp_path / "c.exr", smooth)
    data = bytearray(path.read_bytes())
    for i in range(len(data) // 2, len(data) // 2 + 64):
        data[i] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    _assert_one_line_naming(info.value, path)


def test_garbage_bytes(tmp_path: Path) -> None:
    path = tmp_path / "garbage.exr"
    path.write_bytes(os.urandom(4096))
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    _assert_one_line_naming(info.value, path)


def test_garbage_after_valid_magic(tmp_path: Path) -> None:
    path = tmp_path / "garbage.exr"
    path.write_bytes(b"\x76\x2f\x31\x01" + b"\x00\xff" * 500)
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    _assert_one_line_naming(info.value, path)


def test_empty_file(tmp_path: Path) -> None:
    path = tmp_path / "empty.exr"
    path.write_bytes(b"")
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    _assert_one_line_naming(info.value, path)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.exr"
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    msg = _assert_one_line_naming(info.value, path)
    assert "no such file" in msg


def test_folder_instead_of_file(tmp_path: Path) -> None:
    with pytest.raises(HarnessError) as info:
        hio.read_exr(tmp_path)
    _assert_one_line_naming(info.value, tmp_path)


def test_file_without_rgb(tmp_path: Path) -> None:
    z = np.ones((3, 3), np.float32)
    path = _write_raw_exr(tmp_path / "depth.exr", {"Z": z, "Y": z})
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    msg = _assert_one_line_naming(info.value, path)
    assert "R, G, B" in msg and "Z" in msg


def test_file_missing_one_of_rgb(tmp_path: Path) -> None:
    z = np.ones((3, 3), np.float32)
    path = _write_raw_exr(tmp_path / "rg.exr", {"R": z, "G": z})
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    assert "missing B" in _assert_one_line_naming(info.value, path)


def test_partial_variance_channels(tmp_path: Path) -> None:
    z = np.ones((3, 3), np.float32)
    path = _write_raw_exr(tmp_path / "pv.exr", {"R": z, "G": z, "B": z, "variance.R": z})
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    assert "variance.G" in _assert_one_line_naming(info.value, path)


def test_uint_rgb_channels_rejected(tmp_path: Path) -> None:
    u = np.ones((3, 3), np.uint32)
    path = _write_raw_exr(tmp_path / "u.exr", {"R": u, "G": u, "B": u})
    with pytest.raises(HarnessError) as info:
        hio.read_exr(path)
    _assert_one_line_naming(info.value, path)


# ---------------------------------------------------------------------------
# Programmer errors
# ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "shape", [(4, 4), (4, 4, 4), (4, 4, 1), (0, 4, 3), (4, 0, 3), (2, 4, 4, 3)]
)
def test_bad_image_shape(tmp_path: Path, shape: tuple[int, ...]) -> None:
    with pytest.raises(ValueError):
        hio.write_exr(tmp_path / "a.exr", np.zeros(shape, np.float32))
    assert os.listdir(tmp_path) == []


def test_variance_shape_must_match(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        hio.write_exr(tmp_path / "a.exr", _image(4, 4), _image(4, 5))
    assert os.listdir(tmp_path) == []


def test_bad_metadata(tmp_path: Path) -> None:
    with pytest.raises(TypeError):
        hio.write_exr(tmp_path / "a.exr", _image(), metadata={"spp": 64})  # type: ignore[dict-item]
    with pytest.raises(ValueError):
        hio.write_exr(tmp_path / "a.exr", _image(), metadata={"channels": "x"})
    with pytest.raises(ValueError):
        hio.write_exr(tmp_path / "a.exr", _image(), metadata={"": "x"})
    assert os.listdir(tmp_path) == []


# ---------------------------------------------------------------------------
# Write errors and atomicity
# ---------------------------------------------------------------------------


def test_write_into_missing_folder(tmp_path: Path) -> None:
    path = tmp_path / "no" / "such" / "dir" / "a.exr"
    with pytest.raises(HarnessError) as info:
        hio.write_exr(path, _image())
    msg = _assert_one_line_naming(info.value, path)
    assert "cannot write" in msg
    assert os.listdir(tmp_path) == []


def test_write_under_a_regular_file(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("x")
    path = tmp_path / "file" / "a.exr"
    with pytest.raises(HarnessError) as info:
        hio.write_exr(path, _image())
    assert "cannot write" in _assert_one_line_naming(info.value, path)
    assert os.listdir(tmp_path) == ["file"]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                    reason="root ignores directory permissions")
@pytest.mark.parametrize("writer", ["exr", "png", "text"])
def test_write_into_read_only_folder(tmp_path: Path, writer: str) -> None:
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    path = folder / "a.out"
    try:
        with pytest.raises(HarnessError) as info:
            if writer == "exr":
                hio.write_exr(path, _image())
            elif writer == "png":
                hio.write_png_preview(path, _image())
            else:
                hio.atomic_write_text(path, "hello")
        assert "cannot write" in _assert_one_line_naming(info.value, path)
        assert os.listdir(folder) == []
    finally:
        folder.chmod(stat.S_IRWXU)


def test_permission_denied_when_creating_temp_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Runs even as root (where a read-only folder is still writable).
    def denied(*args: object, **kwargs: object) -> None:
        raise PermissionError(13, "Permission denied", str(tmp_path / ".a.exr.xyz.exr"))

    monkeypatch.setattr(hio.tempfile, "NamedTemporaryFile", denied)
    path = tmp_path / "a.exr"
    with pytest.raises(HarnessError) as info:
        hio.write_exr(path, _image())
    msg = _assert_one_line_naming(info.value, path)
    assert msg == f"{path}: cannot write: Permission denied"
    assert os.listdir(tmp_path) == []


def test_destination_is_a_folder(tmp_path: Path) -> None:
    (tmp_path / "a.exr").mkdir()
    with pytest.raises(HarnessError) as info:
        hio.write_exr(tmp_path / "a.exr", _image())
    _assert_one_line_naming(info.value, tmp_path / "a.exr")
    assert os.listdir(tmp_path) == ["a.exr"]


def test_failed_replace_keeps_old_content(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "a.exr"
    old = _image(seed=10)
    hio.write_exr(path, old, metadata={"gen": "old"})
    old_bytes = path.read_bytes()

    def failing_replace(src: str, dst: str) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(hio.os, "replace", failing_replace)
    with pytest.raises(HarnessError) as info:
        hio.write_exr(path, _image(seed=11), metadata={"gen": "new"})
    assert "No space left on device" in _assert_one_line_naming(info.value, path)
    monkeypatch.undo()

    assert path.read_bytes() == old_bytes
    assert os.listdir(tmp_path) == ["a.exr"]
    got = hio.read_exr(path)
    np.testing.assert_array_equal(got.image, old)
    assert got.metadata == {"gen": "old"}


def test_failure_inside_the_write_keeps_old_content(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "r.json"
    hio.atomic_write_text(path, "old")
    monkeypatch.setenv("HARNESS_FSYNC", "on")  # the test suite turns fsync off (tests/conftest.py)

    def failing_fsync(fd: int) -> None:
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(hio.os, "fsync", failing_fsync)
    with pytest.raises(HarnessError):
        hio.atomic_write_text(path, "new content")
    with pytest.raises(HarnessError):
        hio.write_png_preview(tmp_path / "p.png", _image())
    monkeypatch.undo()
    assert path.read_text() == "old"
    assert os.listdir(tmp_path) == ["r.json"]


def test_non_oserror_failure_propagates_and_cleans_up(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "a.bin"
    hio.atomic_write_bytes(path, b"old")

    class Boom(Exception):
        pass

    def boom(src: str, dst: str) -> None:
        raise Boom()

    monkeypatch.setattr(hio.os, "replace", boom)
    with pytest.raises(Boom):
        hio.atomic_write_bytes(path, b"new")
    monkeypatch.undo()
    assert path.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["a.bin"]


def test_overwrite_replaces_content(tmp_path: Path) -> None:
    path = tmp_path / "a.exr"
    hio.write_exr(path, _image(seed=1), _image(seed=2))
    new = _image(seed=3)
    hio.write_exr(path, new)
    got = hio.read_exr(path)
    np.testing.assert_array_equal(got.image, new)
    assert got.variance is None
    assert os.listdir(tmp_path) == ["a.exr"]


def test_atomic_write_text_and_bytes(tmp_path: Path) -> None:
    p = hio.atomic_write_text(tmp_path / "r.json", '{"a": "é"}\n')
    assert p == tmp_path / "r.json"
    assert p.read_bytes() == '{"a": "é"}\n'.encode()
    hio.atomic_write_bytes(p, b"\x00\x01")
    assert p.read_bytes() == b"\x00\x01"
    assert os.listdir(tmp_path) == ["r.json"]
    with pytest.raises(TypeError):
        hio.atomic_write_bytes(p, "text")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        hio.atomic_write_text(p, b"bytes")  # type: ignore[arg-type]


def test_new_file_gets_normal_permissions(tmp_path: Path) -> None:
    mask = os.umask(0o022)
    os.umask(mask)
    p = hio.atomic_write_text(tmp_path / "a.txt", "x")
    # NamedTemporaryFile creates 0600 files; the result must not stay private.
    assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~hio._current_umask()


def test_overwrite_keeps_existing_permissions(tmp_path: Path) -> None:
    p = tmp_path / "a.txt"
    p.write_text("x")
    p.chmod(0o640)
    hio.atomic_write_text(p, "y")
    assert stat.S_IMODE(p.stat().st_mode) == 0o640


# ---------------------------------------------------------------------------
# PNG previews
# ---------------------------------------------------------------------------


def _read_png(path: Path) -> np.ndarray:
    import imageio.v3 as iio

    return iio.imread(path)


def test_preview_path() -> None:
    assert hio.preview_path("out/foo.exr") == Path("out/foo.png")
    assert hio.preview_path(Path("/a/b.c/img.exr")) == Path("/a/b.c/img.png")


def test_png_written_with_shape_and_dtype(tmp_path: Path) -> None:
    img = _image(6, 9)
    p = hio.write_png_preview(tmp_path / "p.png", img)
    assert p == tmp_path / "p.png"
    px = _read_png(p)
    assert px.shape == (6, 9, 3) and px.dtype == np.uint8
    assert os.listdir(tmp_path) == ["p.png"]


def test_png_srgb_values(tmp_path: Path) -> None:
    img = np.zeros((2, 4, 3), np.float32)
    img[0, 0] = 0.5
    img[0, 1] = 1.0
    img[0, 2] = 7.0  # clipped
    img[0, 3] = -1.0  # clipped
    img[1, 0] = 0.25  # with exposure +1 -> 0.5
    px = _read_png(hio.write_png_preview(tmp_path / "p.png", img))
    assert abs(int(px[0, 0, 0]) - 188) <= 1
    assert (px[0, 1] == 255).all() and (px[0, 2] == 255).all()
    assert (px[0, 3] == 0).all() and (px[1, 1] == 0).all()
    px2 = _read_png(hio.write_png_preview(tmp_path / "q.png", img, exposure=1.0))
    assert abs(int(px2[1, 0, 0]) - 188) <= 1


def test_png_top_row_stays_top(tmp_path: Path) -> None:
    img = np.zeros((3, 2, 3), np.float32)
    img[0] = 1.0
    px = _read_png(hio.write_png_preview(tmp_path / "p.png", img))
    assert (px[0] == 255).all() and (px[1:] == 0).all()


def test_png_nan_magenta_inf_white(tmp_path: Path) -> None:
    img = np.full((2, 3, 3), 0.2, np.float32)
    img[0, 0, 1] = np.nan  # one NaN channel is enough
    img[0, 1, 0] = np.inf
    img[0, 2, 2] = -np.inf
    img[1, 0] = [np.nan, np.inf, 0.0]  # NaN wins
    px = _read_png(hio.write_png_preview(tmp_path / "p.png", img))
    assert px[0, 0].tolist() == [255, 0, 255]
    assert px[1, 0].tolist() == [255, 0, 255]
    assert px[0, 1].tolist() == [255, 255, 255]
    assert px[0, 2, 2] == 0 and px[0, 2, 0] == px[1, 1, 0]


def test_png_bad_shape(tmp_path: Path) -> None:
    with pytest.raises(ValueError):
        hio.write_png_preview(tmp_path / "p.png", np.zeros((4, 4)))
    assert os.listdir(tmp_path) == []


def test_png_missing_folder(tmp_path: Path) -> None:
    path = tmp_path / "missing" / "p.png"
    with pytest.raises(HarnessError) as info:
        hio.write_png_preview(path, _image())
    assert "cannot write" in _assert_one_line_naming(info.value, path)


def test_make_folders_takes_a_folder_another_process_made_meanwhile(tmp_path, monkeypatch):
    """Two workers filling one ground-truth cache: one saw no folder, the other made it, and the first then found
    it "not a folder" (a WriteError that failed a CI run, test_two_processes_fill_the_same_entries)."""
    target = tmp_path / "cache" / "groundtruth"
    real_is_dir = Path.is_dir
    first = []

    def racing_is_dir(self):
        if self == target and not first:  # the other process creates it just after this look
            first.append(True)
            target.mkdir(parents=True)
            return False
        return real_is_dir(self)

    monkeypatch.setattr(Path, "is_dir", racing_is_dir)
    assert hio.make_folders(target) == []
    assert real_is_dir(target)


def test_exr_files_alone_do_not_import_the_png_encoder(tmp_path: Path) -> None:
    """A process that only writes and reads EXR files (an external renderer, a worker) does not import the imageio
    package (about 70 ms of its start, docs/performance.md); a PNG preview then loads it."""
    import subprocess
    import sys

    script = ("import sys\nimport numpy as np\n"
              "from harness.files.imageio import read_exr, write_exr, write_png_preview\npath = sys.argv[1]\nwrite_exr(path + '.exr', np.ones((2, 3, 3), np.float32))\n"
              "assert read_exr(path + '.exr').image.shape == (2, 3, 3)\nbefore = 'imageio' in sys.modules\n"
              "write_png_preview(path + '.png', np.ones((2, 3, 3), np.float32))\n"
              "print(before, 'imageio' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", script, str(tmp_path / "a")], capture_output=True, text=True,
                          timeout=120, check=True)
    assert done.stdout.split() == ["False", "True"]


@pytest.mark.parametrize("setting, synced", [(None, True), ("on", True), ("off", False), (" False ", False)])
def test_writes_are_fsynced_unless_the_setting_is_off(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, setting,
                                                      synced) -> None:
    """Each file and its folder are fsynced by default; ``HARNESS_FSYNC=off`` (the test suite's setting) skips that
    and the write is still whole, with no temporary file left."""
    if setting is None:
        monkeypatch.delenv("HARNESS_FSYNC", raising=False)
    else:
        monkeypatch.setenv("HARNESS_FSYNC", setting)
    calls: list[int] = []
    real = os.fsync
    monkeypatch.setattr(hio.os, "fsync", lambda fd: (calls.append(fd), real(fd))[1])
    hio.atomic_write_text(tmp_path / "a.txt", "whole")
    hio.write_exr(tmp_path / "b.exr", _image())
    assert (len(calls) >= 4) == synced and (not calls) == (not synced)
    assert (tmp_path / "a.txt").read_text() == "whole" and hio.read_exr(tmp_path / "b.exr").image.shape == (7, 11, 3)
    assert sorted(os.listdir(tmp_path)) == ["a.txt", "b.exr"]
