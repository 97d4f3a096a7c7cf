"""The verdict's tile maps as EXR (harness.files.verdict_maps): they agree with the verdict they come from."""

from __future__ import annotations

import json
import math

import numpy as np
import OpenEXR
import pytest

from harness.files.imageio import ExrImage, read_exr, write_exr
from harness.files.verdict_maps import FAILING_FILE, PVALUE_FILE, tile_map_pixels, write_verdict_maps
from harness.running.compare import compare_images


def _noisy(seed: int, h: int = 37, w: int = 45, sigma: float = 0.05):
    """A flat image of mean 1 with Gaussian noise of known variance, as a render with its variance of the mean."""
    rng = np.random.default_rng(seed)
    image = (1.0 + sigma * rng.standard_normal((h, w, 3))).astype(np.float32)
    return ExrImage(image, np.full((h, w, 3), sigma**2, np.float32), {})


def _judged(tmp_path, test: ExrImage, expected: ExrImage, tile: int = 8, alpha: float = 1e-3):
    maps: dict = {}
    report = compare_images(test, expected, tile=tile, alpha=alpha, maps=maps)
    v = report["verdict"]
    written = write_verdict_maps(tmp_path, maps["tiles"], tile=v["tile"], alpha=v["alpha"], threshold=v["threshold"],
                                 height=report["height"], width=report["width"], metadata={"case": "c"})
    return report, maps["tiles"], written


def test_a_planted_error_is_the_failing_tile_and_p_is_the_worst_tiles(tmp_path):
    test, truth = _noisy(1), _noisy(2)
    test.image[17:19, 26:29, 1] += 0.6  # inside tile row 2, column 3, green only
    report, tiles, written = _judged(tmp_path, test, truth)
    v = report["verdict"]
    assert v["verdict"] == "fail" and (v["worst_tile"]["row"], v["worst_tile"]["col"]) == (2, 3)
    assert set(written) == {"pvalue", "failing"} and written["pvalue"].name == PVALUE_FILE
    p, failing = read_exr(written["pvalue"]), read_exr(written["failing"])
    assert p.image.shape == failing.image.shape == (37, 45, 3) and p.variance is None
    # the failing map is 1 exactly on that tile's pixels, in green
    expected = np.zeros((37, 45, 3), np.float32)
    expected[16:24, 24:32, 1] = 1
    assert np.array_equal(failing.image, expected)
    # the p of the worst tile is 2 Phi(-|z|) of the verdict's worst tile, on each of its pixels
    worst = v["worst_tile"]
    want = math.erfc(abs(worst["z_normal"]) / math.sqrt(2))
    block = p.image[worst["y"]:worst["y"] + worst["height"], worst["x"]:worst["x"] + worst["width"], 1]
    assert np.allclose(block, want, rtol=1e-5, atol=1e-30)
    assert float(p.image.min()) == pytest.approx(want, rel=1e-5, abs=1e-30)
    # the smallest p is the worst tile's; p is in [0, 1]
    assert 0 <= p.image.min() and p.image.max() <= 1
    # the header says what the maps are
    header = OpenEXR.File(str(written["failing"])).header()
    assert header["verdict_map"] == "failing" and header["tile"] == "8" and float(header["alpha"]) == 1e-3
    assert float(header["threshold"]) == pytest.approx(v["threshold"]) and header["failing_tiles"] == "1"
    assert header["case"] == "c" and "alpha / 3" in header["description"]
    assert OpenEXR.File(str(written["pvalue"])).header()["verdict_map"] == "pvalue"


def test_a_correct_render_has_no_failing_tile_and_untested_tiles_are_1(tmp_path):
    test, truth = _noisy(3), _noisy(4)
    test.variance[:8, :8] = 0  # a tile without noise on both sides: not tested
    truth.variance[:8, :8] = 0
    truth.image[:8, :8] = test.image[:8, :8]
    report, tiles, written = _judged(tmp_path, test, truth)
    assert report["verdict"]["verdict"] == "pass"
    assert not read_exr(written["failing"]).image.any()
    p = read_exr(written["pvalue"]).image
    assert np.all(p[:8, :8] == 1) and p[8:, 8:].max() < 1
    assert np.array_equal(tile_map_pixels(tiles.p, 8, 37, 45).astype(np.float32), p)


def test_harness_compare_writes_the_same_maps(tmp_path, capfd):
    from harness.cli import main

    test, truth = _noisy(5, 16, 16), _noisy(6, 16, 16)
    test.image[0:4, 0:4] += 0.5
    write_exr(tmp_path / "t.exr", test.image, test.variance)
    write_exr(tmp_path / "g.exr", truth.image, truth.variance)
    out = tmp_path / "maps" / "deeper"
    assert main(["compare", str(tmp_path / "t.exr"), str(tmp_path / "g.exr"), "--tile", "4", "--maps", str(out),
                 "--json"]) == 1
    report = json.loads(capfd.readouterr().out)
    assert report["verdict_maps"] == {"pvalue": str(out / PVALUE_FILE), "failing": str(out / FAILING_FILE)}
    failing = read_exr(out / FAILING_FILE).image
    assert failing[:4, :4].all() and not failing[4:].any() and not failing[:, 4:].any()
