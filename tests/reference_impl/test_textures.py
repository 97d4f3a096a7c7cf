"""The reference's texture lookups (reference_impl.textures, kernels/texture.py) against Mitsuba 3.9.1's own texture
objects, to float32 precision: bitmaps (nearest and bilinear, every wrap mode, at texel centres, edges, corners and
far outside [0, 1], 8-bit sRGB and raw, float, to_uv) and checkerboards; and each planted fault of the textures
changes the lookup where it should."""

from __future__ import annotations

import numpy as np
import pytest

from reference_impl.kernels import config, records, texture
from reference_impl.textures import Bitmap, Checkerboard, Textures, srgb_to_linear

mi = pytest.importorskip("mitsuba")

# Mitsuba evaluates in float32: its uv are rounded to float32 and its bilinear weights are float32 products. An
# error of a few float32 ulps of the values (<= 1) is its rounding, not a difference of the lookup.
ATOL = 4e-6


@pytest.fixture(scope="module", autouse=True)
def _variant():
    mi.set_variant("scalar_rgb")


def _mitsuba_texture(plugin: dict):
    return mi.load_dict(plugin)


def _mitsuba_eval(tex, uv) -> np.ndarray:
    si = mi.SurfaceInteraction3f()
    out = np.empty((len(uv), 3))
    for n, (u, v) in enumerate(uv):
        si.uv = mi.Point2f(float(u), float(v))
        out[n] = np.array(tex.eval(si), dtype=np.float64)
    return out


def _points(width: int, height: int, seed: int = 0, random: int = 400) -> np.ndarray:
    """Texel centres, texel edges and corners (inside and one period out), and ``random`` random points in
    [-2.5, 2.5]^2."""
    g = np.random.default_rng(seed)
    centres = np.stack(np.meshgrid((np.arange(width) + 0.5) / width, (np.arange(height) + 0.5) / height),
                       axis=-1).reshape(-1, 2)
    edges = np.stack(np.meshgrid(np.arange(-1, width + 2) / width, np.arange(-1, height + 2) / height),
                     axis=-1).reshape(-1, 2)
    shifted = centres + g.integers(-2, 3, size=centres.shape)
    return np.concatenate([centres, edges, shifted, g.uniform(-2.5, 2.5, size=(random, 2))])


def _reference(item, uv, mutant: int = 0, srgb_as_linear: bool = False) -> np.ndarray:
    tables = records.texture_tables(Textures((item,)), srgb_as_linear)
    return texture.evaluate(tables, 0, uv, mutant)


IMAGE8 = np.random.default_rng(7).integers(0, 256, size=(5, 7, 3), dtype=np.uint8)
IMAGE32 = np.random.default_rng(8).uniform(0.0, 3.0, size=(6, 4, 3)).astype(np.float32)


@pytest.mark.parametrize("filter_type", ["bilinear", "nearest"])
@pytest.mark.parametrize("wrap_mode", ["repeat", "mirror", "clamp"])
@pytest.mark.parametrize("raw", [False, True])
def test_an_8_bit_bitmap_is_looked_up_as_mitsuba_looks_it_up(filter_type, wrap_mode, raw):
    uv = _points(7, 5)
    tex = _mitsuba_texture({"type": "bitmap", "bitmap": mi.Bitmap(IMAGE8.copy()), "filter_type": filter_type,
                            "wrap_mode": wrap_mode, "raw": raw})
    ours = _reference(Bitmap(IMAGE8, filter_type, wrap_mode, srgb=not raw), uv)
    np.testing.assert_allclose(ours, _mitsuba_eval(tex, uv), rtol=0, atol=ATOL)


@pytest.mark.parametrize("filter_type", ["bilinear", "nearest"])
@pytest.mark.parametrize("wrap_mode", ["repeat", "mirror", "clamp"])
def test_a_float_bitmap_is_looked_up_as_mitsuba_looks_it_up(filter_type, wrap_mode):
    uv = _points(4, 6, seed=1)
    tex = _mitsuba_texture({"type": "bitmap", "bitmap": mi.Bitmap(IMAGE32.copy()), "filter_type": filter_type,
                            "wrap_mode": wrap_mode})
    ours = _reference(Bitmap(IMAGE32.astype(np.float64), filter_type, wrap_mode), uv)
    np.testing.assert_allclose(ours, _mitsuba_eval(tex, uv), rtol=2e-6, atol=ATOL)


def test_to_uv_maps_the_coordinates_before_the_lookup_as_mitsubas_does():
    to_uv = np.array([[1.3, 0.4, 0.25], [-0.2, 0.7, 0.6], [0.0, 0.0, 1.0]])
    uv = _points(7, 5, seed=2)
    tex = _mitsuba_texture({"type": "bitmap", "bitmap": mi.Bitmap(IMAGE8.copy()),
                            "to_uv": mi.ScalarTransform3f(to_uv.tolist())})
    ours = _reference(Bitmap(IMAGE8, srgb=True, to_uv=to_uv), uv)
    np.testing.assert_allclose(ours, _mitsuba_eval(tex, uv), rtol=0, atol=ATOL)


def test_a_checkerboard_is_mitsubas_also_on_its_squares_edges():
    to_uv = np.array([[4.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]])
    g = np.random.default_rng(3)
    uv = np.concatenate([g.uniform(-2, 2, size=(300, 2)), np.stack(np.meshgrid(np.arange(-4, 5) / 4,
                                                                               np.arange(-4, 5) / 4), -1).reshape(-1, 2)])
    for matrix in (None, to_uv):
        plugin = {"type": "checkerboard", "color0": {"type": "rgb", "value": [0.9, 0.5, 0.1]},
                  "color1": {"type": "rgb", "value": [0.05, 0.2, 0.7]}}
        if matrix is not None:
            plugin["to_uv"] = mi.ScalarTransform3f(matrix.tolist())
        ours = _reference(Checkerboard((0.9, 0.5, 0.1), (0.05, 0.2, 0.7), matrix), uv)
        np.testing.assert_allclose(ours, _mitsuba_eval(_mitsuba_texture(plugin), uv), rtol=0, atol=1e-7)


def test_srgb_decoding_is_mitsubas_for_every_8_bit_code():
    codes = np.arange(256, dtype=np.uint8)
    image = np.repeat(codes[None, :, None], 3, axis=2)
    tex = _mitsuba_texture({"type": "bitmap", "bitmap": mi.Bitmap(image.copy()), "filter_type": "nearest"})
    mitsuba = _mitsuba_eval(tex, np.stack([(codes + 0.5) / 256, np.full(256, 0.5)], axis=1))[:, 0]
    np.testing.assert_allclose(srgb_to_linear(codes), mitsuba, rtol=0, atol=5e-7)  # float32: 3.9e-7 at code 193


def _shifted_by(mutant: str, item, uv) -> np.ndarray:
    """|lookup with the planted fault - lookup without| at ``uv``."""
    fault = config.MUTANT_BITS.get(mutant, 0)
    return np.abs(_reference(item, uv, fault, mutant == "texture-srgb-as-linear") - _reference(item, uv))


@pytest.mark.parametrize("mutant", ["texture-v-flipped", "texture-srgb-as-linear", "texture-nearest-not-bilinear",
                                    "texture-half-texel-shift", "texture-repeat-as-clamp"])
def test_each_planted_fault_of_the_textures_changes_the_lookup(mutant):
    uv = _points(7, 5, seed=4)
    change = _shifted_by(mutant, Bitmap(IMAGE8, srgb=True), uv)
    assert change.max() > 0.05
    inside = np.all((uv > 0.2) & (uv < 0.8), axis=1)
    if mutant == "texture-repeat-as-clamp":  # only near and beyond the edges
        assert change[inside].max() == 0.0


def test_a_planted_fault_of_the_textures_leaves_what_it_does_not_concern():
    uv = _points(7, 5, seed=5)
    nearest = Bitmap(IMAGE8, "nearest", srgb=True)
    for mutant in ("texture-nearest-not-bilinear", "texture-half-texel-shift"):
        assert _shifted_by(mutant, nearest, uv).max() == 0.0
    assert _shifted_by("texture-repeat-as-clamp", Bitmap(IMAGE8, wrap_mode="mirror"), uv).max() == 0.0
    assert _shifted_by("texture-srgb-as-linear", Bitmap(IMAGE8, srgb=False), uv).max() == 0.0


def test_mitsubas_checkerboard_as_one_number_swaps_its_colours():
    """Mitsuba 3.9.1's checkerboard ``eval_1`` gives color1 where its ``eval`` gives color0 (and the other way
    round): the scene format refuses a checkerboard on a one-number parameter (harness.scene.kinds.materials) rather
    than follow either. If this fails, Mitsuba changed, and the refusal can go."""
    plugin = {"type": "checkerboard", "color0": {"type": "rgb", "value": [0.9, 0.5, 0.1]},
              "color1": {"type": "rgb", "value": [0.05, 0.2, 0.7]}}
    tex = _mitsuba_texture(plugin)
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(0.25, 0.25)  # color0's square
    assert np.allclose(np.array(tex.eval(si)), [0.9, 0.5, 0.1], atol=1e-6)
    assert float(tex.eval_1(si)) == pytest.approx((0.05 + 0.2 + 0.7) / 3, abs=1e-6)


@pytest.mark.parametrize("item", ["bitmap-srgb", "bitmap-raw"])
def test_a_texture_as_one_number_is_mitsubas_eval_1(item):
    uv = _points(7, 5, seed=6)
    raw = item == "bitmap-raw"
    ours_item = Bitmap(IMAGE8, srgb=not raw)
    plugin = {"type": "bitmap", "bitmap": mi.Bitmap(IMAGE8.copy()), "raw": raw}
    tex = _mitsuba_texture(plugin)
    si = mi.SurfaceInteraction3f()
    mitsuba = []
    for u, v in uv:
        si.uv = mi.Point2f(float(u), float(v))
        mitsuba.append(float(tex.eval_1(si)))
    tables = records.texture_tables(Textures((ours_item,)))
    ours = [texture.texture_eval_1(tables, 0, u, v, 0) for u, v in uv]
    np.testing.assert_allclose(ours, mitsuba, rtol=0, atol=ATOL)
    low, high = Textures((ours_item,)).scalar_range(0)
    assert low - 1e-12 <= min(ours) and max(ours) <= high + 1e-12
