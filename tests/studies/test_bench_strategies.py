"""``harness bench``'s reference strategy rows (harness/studies/bench.py): each strategy's efficiency over the
defaults' with an interval over the repeats, at the same spp and at equal time, a best named (at equal time) only
when told apart, no negative MSE in the table, no efficiency for an exact estimator. The rows are planted
(per-repeat MSE and seconds of known law): nothing renders here, but for the one test marked slow."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import load_small

from harness.renderers.groundtruth import closed_form
from harness.studies import bench


def _row(label, mse, seconds, settings=None, floor=1e-4, timed=None):
    """A planted row; ``timed`` = (MSE, seconds, spp) of its equal-time renders (default: its same-spp ones)."""
    row = bench.Row("planted", label, "reference", dict(settings or {}), 64, 32, 32)
    row.mse_all, row.seconds_all = list(mse), list(seconds)
    row.seconds = float(np.median(seconds))
    row.paths_per_second = 32 * 32 * 64 / row.seconds
    row.mse = float(np.mean(mse))
    row.mse_raw = row.mse + floor
    row.efficiency = bench.efficiency(row.mse, row.seconds)
    t_mse, t_seconds, t_spp = timed if timed is not None else (mse, seconds, 64)
    row.equal_time_mse_all, row.equal_time_seconds_all, row.equal_time_spp = list(t_mse), list(t_seconds), t_spp
    row.equal_time_efficiency = bench.efficiency(float(np.mean(t_mse)), float(np.median(t_seconds)))
    return row


def _draws(rng, mse, seconds, n=5, noise=0.05):
    return rng.normal(mse, noise * mse, n), rng.normal(seconds, noise * seconds, n)


def test_bench_names_a_best_strategy_only_when_told_apart():
    rng = np.random.default_rng(3)
    clear = [_row("reference", *_draws(rng, 1.0, 1.0)),
             _row("reference direct=mis", *_draws(rng, 0.2, 1.0), {"direct": "mis"}),
             _row("reference rr=off", *_draws(rng, 1.0, 2.0), {"rr": "off"})]
    verdict = bench.strategy_verdict(clear)
    assert verdict["label"] == "reference direct=mis" and verdict["tied"] == []
    mis = verdict["relative_efficiency"]["equal time"]["reference direct=mis"]
    assert mis["low"] <= 5.0 <= mis["high"] and mis["low"] > 1.0
    line = bench.format_best_strategy(verdict)
    assert line.startswith("best reference strategy at equal time: reference direct=mis (efficiency / the defaults' ")
    assert "[" in line and "told apart from every other" in line
    alike = [_row("reference", *_draws(rng, 1.0, 1.0, noise=0.3)),
             _row("reference rr_depth=5", *_draws(rng, 1.0, 1.0, noise=0.3), {"rr_depth": "5"})]
    verdict = bench.strategy_verdict(alike)
    assert verdict["label"] is None and verdict["leader"] is not None
    assert bench.format_best_strategy(verdict).startswith("best reference strategy at equal time: not told apart at "
                                                          "this budget")


def test_bench_table_shows_an_mse_below_the_ground_truths_noise_as_a_bound():
    row = _row("reference", [-2.1e-05, -1.0e-05, 3e-06], [1.0, 1.0, 1.0], floor=1e-4)
    text = bench.format_table([row])
    assert "< 0.0001" in text and "-2.1e-05" not in text and "-1.0" not in text.replace("-" * 20, "")


def test_bench_decides_the_best_strategy_at_equal_time_and_shows_both_comparisons():
    """rr_depth=1: half the time, 1.5 x the MSE at the same spp (efficiency 4/3 x the defaults'), at equal time
    (128 spp) 0.75 x the MSE in the same time (4/3 x); rr=off: a tenth of the MSE in 4 x the time (2.5 x), at equal
    time (16 spp) 0.4 x the MSE (2.5 x). The decision and the listing say which comparison each number is; the
    result keeps both."""
    rng = np.random.default_rng(5)
    base = _row("reference", *_draws(rng, 1.0, 1.0))
    fast = _row("reference rr_depth=1", *_draws(rng, 1.5, 0.5), {"rr_depth": "1"}, timed=(*_draws(rng, 0.75, 1.0),
                                                                                           128))
    slow = _row("reference rr=off", *_draws(rng, 0.1, 4.0), {"rr": "off"}, timed=(*_draws(rng, 0.4, 1.0), 16))
    verdict = bench.strategy_verdict([base, fast, slow])
    assert verdict["comparison"] == "equal time" and verdict["equal_time_spp"]["reference rr=off"] == 16
    timed, same = verdict["relative_efficiency"]["equal time"], verdict["relative_efficiency"]["same spp"]
    assert timed["reference rr=off"]["low"] <= 2.5 <= timed["reference rr=off"]["high"]
    assert same["reference rr=off"]["low"] <= 2.5 <= same["reference rr=off"]["high"]
    assert timed["reference rr_depth=1"]["low"] <= 4 / 3 <= timed["reference rr_depth=1"]["high"]
    assert verdict["label"] == "reference rr=off"
    text = bench.format_best_strategy(verdict)
    assert text.startswith("best reference strategy at equal time: reference rr=off")
    assert "at equal time (each at the spp that takes the defaults' time)" in text and "rr=off 2.5" in text
    assert "at 16 spp" in text and "efficiency / the defaults' at the same spp" in text
    table = bench.format_table([base, fast, slow])
    assert "eff. same spp" in table and "equal-time spp" in table and "eff. equal time" in table
    assert bench.equal_time_spp(64, 4.0, 1.0) == 16 and bench.equal_time_spp(64, 1.1, 1.0) == 64


def test_a_zero_variance_row_has_no_efficiency_and_is_not_ranked():
    """An exact estimator (white furnace, env_sampling=cosine: every sample the answer): its MSE is float rounding
    (~1e-30), its own variance ~1e-17; 1 / (MSE x s) would read ~1e29. Its row says "zero variance", its efficiency
    is NaN (null in the JSON), and the best is decided among the others."""
    class GroundTruth:
        image = np.full((4, 4, 3), 0.93)
        variance = None

    rng = np.random.default_rng(8)
    base = _row("reference", *_draws(rng, 1.0, 1.0))
    exact = _row("reference env_sampling=cosine", [1e-30] * 5, [1.0] * 5, {"env_sampling": "cosine"})
    exact.variance_all = [2.6e-17] * 5
    exact.zero_variance = bench.is_exact(exact.variance_all, exact.mse_all, GroundTruth)
    assert exact.zero_variance and not bench.is_exact([0.5] * 5, base.mse_all, GroundTruth)
    assert bench.is_exact([], [0.0] * 3, GroundTruth) and not bench.is_exact([], [1e-3] * 3, GroundTruth)
    mis = _row("reference direct=mis", *_draws(rng, 0.2, 1.0), {"direct": "mis"})
    verdict = bench.strategy_verdict([base, exact, mis])
    assert verdict["zero_variance"] == ["reference env_sampling=cosine"]
    assert verdict["label"] == "reference direct=mis" and verdict["tied"] == []
    assert "reference env_sampling=cosine" not in verdict["relative_efficiency"]["equal time"]
    assert "reference env_sampling=cosine" not in verdict["relative_efficiency"]["same spp"]
    text = bench.format_best_strategy(verdict)
    assert "zero variance (exact here: no efficiency, not ranked): reference env_sampling=cosine" in text
    assert "e+2" not in text
    table = bench.format_table([base, dataclasses.replace(exact, efficiency=float("nan"))])
    line = next(t for t in table.splitlines() if "env_sampling=cosine" in t)
    assert line.count("zero variance") == 2 and "e+2" not in line
    assert bench.row_dict(exact)["zero_variance"] is True


@pytest.mark.slow
def test_bench_renders_the_strategy_rows_again_at_the_defaults_time():
    """A tiny furnace: each reference strategy row has an equal-time spp from its own time, and every reference row,
    the defaults included, renders again at it (fresh seeds, in turns): the equal-time ratios come from one
    interleaved phase, not from the race's renders beside this phase's."""
    scene = load_small("furnace", 8)
    contenders = [bench.Contender("reference", "reference"),
                  bench.Contender("reference shadow_rays=4", "reference", {"shadow_rays": "4"})]
    rows = bench.bench_scene(scene, contenders, spp=4, repeats=2, gt=closed_form(scene))
    bench.equal_time_renders(scene, rows, repeats=2, gt=closed_form(scene))
    ref, more = rows
    assert ref.equal_time_spp == 4 and len(ref.equal_time_mse_all) == 2 and ref.equal_time_mse_all != ref.mse_all
    assert more.equal_time_spp == bench.equal_time_spp(4, float(np.mean(more.seconds_all)),
                                                        float(np.mean(ref.seconds_all)))
    assert len(more.equal_time_mse_all) == 2 == len(more.equal_time_seconds_all) and more.equal_time_error is None
    verdict = bench.strategy_verdict(rows)
    assert verdict["comparison"] == "equal time" and "reference shadow_rays=4" in verdict["equal_time_spp"]
