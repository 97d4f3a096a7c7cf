"""The comparison viewer's data (harness.files.viewer_data): planes decode to the float16 rounding of every value
over the range a render holds, the script cannot be broken out of by a case name, the p-value histogram and the
thumbnails say what the verdict's tiles say."""

from __future__ import annotations

import base64
import json
import math

import imageio.v3 as iio
import numpy as np
import pytest

from harness.files import viewer_data
from harness.files.imageio import ExrImage
from harness.files.viewer_data import critical_z, encode_plane, make_viewer_data, p_histogram, viewer_script
from harness.judges.verdict import TileMaps
from harness.running.compare import compare_images

PREFIX = "HarnessViewer.register("


def read_script(text: str) -> dict:
    """The payload of a viewer.js (what the page's HarnessViewer.register receives)."""
    start = text.index(PREFIX) + len(PREFIX)
    return json.loads(text[start:text.rindex(");")])


def decode(plane: dict, shape: tuple[int, ...]) -> np.ndarray:
    """A plane decoded as viewer_data.js decodes it."""
    if plane["encoding"] == "zero":
        return np.zeros(shape)
    raw = base64.b64decode(plane["data"])
    kind = {"f16": "<f2", "f32": "<f4", "u8": "u1"}[plane["encoding"]]
    values = np.frombuffer(raw, dtype=kind).astype(np.float64).reshape(shape)
    return np.ldexp(values, -plane["exponent"]) if plane["encoding"] == "f16" else values


def test_a_plane_is_the_float16_rounding_of_each_value_at_any_scale():
    rng = np.random.default_rng(3)
    for peak in (1e-30, 1e-6, 0.3, 1.0, 7e4, 1e9, 3e38):
        values = (peak * rng.random((9, 11, 3))).astype(np.float32)
        values[0, 0, 0] = peak  # the largest magnitude is there
        values[1, 1, 1] = 0.0
        plane = encode_plane(values)
        # the peak lands in [2^13, 2^14): far below float16's largest, 65504, and 27 octaves above its smallest normal
        assert 2**13 <= math.ldexp(float(values.max()), plane["exponent"]) < 2**14
        back = decode(plane, values.shape)
        normal = np.abs(values) >= peak * 2.0**-27
        # a power of two changes no mantissa bit: exactly float16's rounding, relative error <= 2^-11
        want = np.ldexp(np.ldexp(values.astype(np.float64), plane["exponent"]).astype(np.float16).astype(np.float64),
                        -plane["exponent"])
        assert np.array_equal(back, want)
        assert np.all(np.abs(back - values)[normal] <= np.abs(values)[normal] * 2.0**-11)
        assert back[1, 1, 1] == 0


def test_non_finite_values_stay_non_finite_and_zeros_cost_nothing():
    values = np.ones((2, 3, 3), np.float32)
    values[0, 0] = [np.nan, np.inf, -np.inf]
    back = decode(encode_plane(values), values.shape)
    assert np.isnan(back[0, 0, 0]) and back[0, 0, 1] == np.inf and back[0, 0, 2] == -np.inf
    assert np.array_equal(back[1], values[1])
    assert encode_plane(np.zeros((64, 64, 3))) == {"encoding": "zero", "channels": 3}
    p = np.array([[0.25, 1e-300], [1.0, 0.5]])
    assert np.array_equal(decode(encode_plane(p, "f32"), p.shape), p.astype(np.float32).astype(np.float64))


def test_the_script_is_one_register_call_that_no_name_can_break_out_of():
    name = "</script><script>alert(1)</script> & \u2028 \"quotes\""
    text = viewer_script({"name": name, "n": 1})
    assert "<" not in text.split("*/", 1)[1] and ">" not in text.split("*/", 1)[1] and "\u2028" not in text
    assert text.rstrip().endswith(");") and text.count(PREFIX) == 1
    assert read_script(text) == {"name": name, "n": 1}


def _tiles(p: np.ndarray, failing: np.ndarray | None = None) -> TileMaps:
    tested = np.ones(p.shape, bool)
    z = np.zeros(p.shape)
    return TileMaps(z, p, tested, np.zeros(p.shape, bool) if failing is None else failing)


def test_the_p_value_histogram_counts_tested_tile_channels():
    rng = np.random.default_rng(5)
    uniform = _tiles(rng.random((20, 20, 3)))
    uniform.tested[0, 0, :] = False
    h = p_histogram(uniform)
    assert h["bins"] == 20 and sum(h["counts"]) == h["tested"] == 1197 and h["failing"] == 0
    # under the null each bin expects tested / 20 = 60: a chi-square test at the 1e-6 level
    chi2 = sum((c - 1197 / 20) ** 2 / (1197 / 20) for c in h["counts"])
    assert chi2 < 60.0  # the 1 - 1e-6 quantile of chi-square with 19 dof is 57.8
    piled = _tiles(np.full((4, 4, 3), 1e-9), np.ones((4, 4, 3), bool))
    assert p_histogram(piled)["counts"][0] == 48 and p_histogram(piled)["failing"] == 16


def test_the_critical_z_is_the_one_a_tile_fails_beyond():
    from statistics import NormalDist

    threshold, count = 1e-3 / 3, 192
    z = critical_z(threshold, count)
    p = 2 * NormalDist().cdf(-z)
    assert 1 - (1 - p) ** count == pytest.approx(threshold, rel=1e-9)  # Sidak over the tested tile-channels
    assert critical_z(None, 10) is None and critical_z(threshold, 0) is None


def test_made_from_a_verdict_the_files_hold_its_tiles(tmp_path):
    rng = np.random.default_rng(9)
    h, w = 37, 45
    truth = ExrImage(np.ones((h, w, 3), np.float32), np.zeros((h, w, 3), np.float32), {})
    render = (1 + 0.05 * rng.standard_normal((h, w, 3))).astype(np.float32)
    render[17:19, 26:29, 1] += 0.6  # one failing tile: row 2, column 3
    test = ExrImage(render, np.full((h, w, 3), 0.0025, np.float32), {})
    maps: dict = {}
    v = compare_images(test, truth, tile=8, alpha=1e-3, maps=maps)["verdict"]
    tiles = maps["tiles"]
    made = make_viewer_data(tmp_path, name="c", render=render, render_variance=test.variance, truth=truth.image,
                            truth_variance=truth.variance, flip=maps["flip"][1], tiles=tiles, tile=8, alpha=v["alpha"],
                            threshold=v["threshold"], exposure=0.5, labels={"render": "r", "truth": "t"})
    payload = read_script(made.data.read_text())
    assert payload["width"] == w and payload["height"] == h and payload["format"] == viewer_data.FORMAT
    assert payload["planes"]["truth_sd"] == {"encoding": "zero", "channels": 3}  # a closed form: no variance
    sd = decode(payload["planes"]["render_sd"], (h, w, 3))
    assert np.allclose(sd**2, 0.0025, rtol=2.0**-10)
    t = payload["tiles"]
    assert (t["rows"], t["cols"], t["size"]) == (5, 6, 8) and t["count"] == int(tiles.tested.sum())
    assert np.array_equal(decode(t["p"], (5, 6, 3)), tiles.p.astype(np.float32).astype(np.float64))
    assert np.array_equal(decode(t["failing"], (5, 6, 3)) > 0, tiles.failing)
    assert t["z_critical"] == pytest.approx(critical_z(v["threshold"], t["count"]))
    assert made.histogram == p_histogram(tiles) and made.histogram["failing"] == 1
    # the p-value thumbnail: the failing tile outlined in cyan, nothing else
    thumb = iio.imread(made.pvalue)
    assert thumb.shape[:2] == (h, w)
    cyan = np.all(thumb == viewer_data.OUTLINE_COLOUR, axis=-1)
    assert cyan[16, 24:32].all() and cyan[16:24, 24].all() and cyan.sum() == 28
    assert iio.imread(made.thumbnail).shape[:2] == (h, w)
    assert made.record()["data"] == "viewer.js" and made.record()["pvalue"] == viewer_data.PVALUE_FILE


def test_a_large_film_gets_a_small_thumbnail_of_its_mean(tmp_path):
    image = np.zeros((256, 200, 3), np.float32)
    image[:, :100] = 1.0  # left half white
    made = make_viewer_data(tmp_path, name="big", render=image, render_variance=None, truth=None,
                            truth_variance=None, flip=None, tiles=None, tile=None)
    thumb = iio.imread(made.thumbnail)
    assert thumb.shape[:2] == (64, 50)  # a factor of 4
    assert (thumb[:, :25] == 255).all() and (thumb[:, 25:] == 0).all()
    assert made.pvalue is None and made.histogram is None
    assert read_script(made.data.read_text())["tiles"] is None
