"""``harness bench``'s reference strategy rows (harness/studies/bench.py): each strategy's efficiency over the
defaults' with an interval over the repeats, a best named only when told apart, no negative MSE in the table.
The rows are planted (per-repeat MSE and seconds of known law): nothing renders here."""

from __future__ import annotations

import numpy as np

from harness.studies import bench


def _row(label, mse, seconds, settings=None, floor=1e-4):
    row = bench.Row("planted", label, "reference", dict(settings or {}), 64, 32, 32)
    row.mse_all, row.seconds_all = list(mse), list(seconds)
    row.seconds = float(np.median(seconds))
    row.paths_per_second = 32 * 32 * 64 / row.seconds
    row.mse = float(np.mean(mse))
    row.mse_raw = row.mse + floor
    row.efficiency = bench.efficiency(row.mse, row.seconds)
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
    mis = verdict["relative_efficiency"]["reference direct=mis"]
    assert mis["low"] <= 5.0 <= mis["high"] and mis["low"] > 1.0
    line = bench.format_best_strategy(verdict)
    assert line.startswith("best reference strategy: reference direct=mis (efficiency / the defaults' ")
    assert "[" in line and "told apart from every other" in line
    alike = [_row("reference", *_draws(rng, 1.0, 1.0, noise=0.3)),
             _row("reference rr_depth=5", *_draws(rng, 1.0, 1.0, noise=0.3), {"rr_depth": "5"})]
    verdict = bench.strategy_verdict(alike)
    assert verdict["label"] is None and verdict["leader"] is not None
    assert bench.format_best_strategy(verdict).startswith("best reference strategy: not told apart at this budget")


def test_bench_table_shows_an_mse_below_the_ground_truths_noise_as_a_bound():
    row = _row("reference", [-2.1e-05, -1.0e-05, 3e-06], [1.0, 1.0, 1.0], floor=1e-4)
    text = bench.format_table([row])
    assert "< 0.0001" in text and "-2.1e-05" not in text and "-1.0" not in text.replace("-" * 20, "")
