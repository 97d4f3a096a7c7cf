"""The strategy table (harness/studies/strategies.py, strategy_rows; its page, harness/report/build.py): every
strategy at equal spp and at equal time, several seeds each, ratios with intervals, "best" only when told apart,
and no negative MSE shown. The renders are planted (a function of known MSE and cost): nothing renders here."""

from __future__ import annotations

import re

import numpy as np
import pytest

from harness.report.build import _best_line, _strategies
from harness.studies.strategies import strategy_rows

DEFAULTS = {"direct": "area", "light_selection": "power", "hemisphere": "cosine", "rr": "albedo",
            "env_sampling": "importance"}


class Planted:
    """render(settings, spp, index) of a strategy whose MSE is ``variance / spp`` (x gamma noise) and whose render
    takes ``cost x spp`` ms (x normal noise); every call is recorded."""

    def __init__(self, variance: dict, cost: dict, noise: float = 0.02, floor: float = 1e-6, seed: int = 0):
        self.variance, self.cost, self.noise, self.floor = variance, cost, noise, floor
        self.rng = np.random.default_rng(seed)
        self.calls: list[tuple[str, int]] = []

    def __call__(self, settings: dict, spp: int, index: int) -> dict:
        label = "default" if not settings else "{}={}".format(*next(iter(settings.items())))
        self.calls.append((label, spp))
        shape = 1.0 / self.noise**2
        var = self.variance.get(label, 1.0) / spp * self.rng.gamma(shape, 1.0 / shape)
        seconds = self.cost.get(label, 1.0) * spp * 1e-3 * self.rng.normal(1.0, self.noise)
        # the measured MSE: the render's own variance plus the ground truth's floor, which the table subtracts
        return {"mse": var + self.floor, "floor_mse": self.floor, "variance": var, "seconds": seconds, "pixels": 100,
                "spp": spp, "film": [10, 10], "variance_regions": {}}


def _table(planted: Planted, **kwargs) -> dict:
    return strategy_rows("planted", [], planted, True, DEFAULTS, spp=16, repeats=4, min_seconds=0.0, spp_step=2,
                         **kwargs)


def _rows(table: dict) -> dict:
    return {r["label"]: r for r in table["rows"] if "skipped" not in r}


def test_equal_spp_rows_are_at_one_spp_and_equal_time_rows_at_the_defaults_time():
    planted = Planted({"direct=mis": 0.5}, {"rr=off": 3.0, "hemisphere=uniform": 0.5})
    table = _table(planted)
    rows = _rows(table)
    assert len(rows) == 9
    assert {r["equal_spp"]["spp"] for r in rows.values()} == {16} == {r["spp"] for r in rows.values()}
    assert all(r["equal_spp"]["seeds"] == 4 == r["equal_time"]["seeds"] for r in rows.values())
    # each strategy's equal-spp renders really were at 16 spp
    for label in rows:
        assert [spp for name, spp in planted.calls if name == label][:4] == [16] * 4
    # equal time: the costly strategy at fewer spp, the cheap one at more, so that their times match the default's
    assert rows["rr=off"]["equal_time_spp"] == 6 and rows["hemisphere=uniform"]["equal_time_spp"] == 32
    base = rows["default"]["equal_time_seconds"]
    for row in rows.values():
        assert row["equal_time_seconds"] == pytest.approx(base, rel=0.25)
    assert table["equal_spp"] == 16 and table["comparison"] == "repeats"
    # the rate between a row's two budgets, with its interval: the planted MSE falls as 1 / spp
    slope = rows["hemisphere=uniform"]["mse_slope"]
    assert slope["low"] <= -1.0 <= slope["high"] and rows["default"]["mse_slope"] is None


def test_every_ratio_to_the_default_carries_an_interval_that_holds_the_planted_one():
    table = _table(Planted({"direct=mis": 0.5}, {"direct=mis": 1.25}, noise=0.05))
    mis = _rows(table)["direct=mis"]
    for key in ("relative_mse_interval", "relative_time_interval", "relative_efficiency_interval",
                "efficiency_interval", "relative_mse_equal_time"):
        interval = mis[key]
        assert interval["low"] is not None and interval["low"] <= interval["value"] <= interval["high"], key
    truth = 1.0 / (0.5 * 1.25)
    assert mis["relative_efficiency_interval"]["low"] <= truth <= mis["relative_efficiency_interval"]["high"]
    assert mis["relative_mse_interval"]["low"] <= 0.5 <= mis["relative_mse_interval"]["high"]


def test_best_is_named_only_when_its_interval_separates_from_every_other():
    clear = _table(Planted({"direct=mis": 0.1}, {}, noise=0.02))  # 10 x the default's efficiency
    assert clear["best"] == "direct=mis" and clear["near_best"] == []
    assert clear["best_interval"]["low"] > 1.0
    assert _best_line(clear).startswith("Best: direct=mis (efficiency at equal time")
    alike = _table(Planted({}, {}, noise=0.2))  # every strategy the same estimator
    assert alike["best"] is None and alike["leader"] is not None
    assert _best_line(alike).startswith("Best: not told apart at this budget")


def _page(table: dict, tmp_path) -> str:
    section = {"defaults": DEFAULTS, "strategy_spp": 16, "strategy_repeats": 4, "scenes": [table]}
    _, html = _strategies(section, tmp_path, tmp_path)
    return str(html)


def test_an_mse_below_the_ground_truths_noise_is_shown_as_a_bound_never_negative(tmp_path):
    # a ground truth noisier than the renders: the measured MSE minus the floor is negative for some seeds
    planted = Planted({}, {}, noise=0.05, floor=1.0)
    real = planted.__call__

    def noisy(settings, spp, index):
        m = real(settings, spp, index)
        return dict(m, mse=m["floor_mse"] * (0.9 if index % 2 else 1.01))

    table = strategy_rows("planted", [], noisy, True, DEFAULTS, spp=16, repeats=4, min_seconds=0.0, spp_step=2)
    html = _page(table, tmp_path)
    cells = re.findall(r"<td>([^<]*)</td>", html)
    assert any(c.startswith("&lt; 1 (bound)") for c in cells), cells[:20]
    assert not any(re.fullmatch(r"-\d.*", c) for c in cells), [c for c in cells if c.startswith("-")]
    assert all(r["mse_corrected"] is None and r["mse_bound"] == 1.0 for r in _rows(table).values())


def test_the_page_shows_both_budgets_and_the_intervals(tmp_path):
    table = _table(Planted({"direct=mis": 0.1}, {"rr=off": 3.0}))
    html = _page(table, tmp_path)
    assert "equal spp" in html and "equal time" in html and "Celarek" in html
    assert re.search(r"<td>\d[\d.e+-]* \[\d[\d.e+-]*, \d[\d.e+-]*\]</td>", html)
    assert "Best: direct=mis (efficiency at equal time" in html


def test_a_region_best_is_named_only_when_told_apart():
    rng = np.random.default_rng(6)

    def render(settings, spp, index):  # every strategy alike over the region, with timing noise
        return {"mse": 1.0, "floor_mse": 0.0, "variance": 1.0, "seconds": rng.normal(1.0, 0.2), "pixels": 100,
                "spp": spp, "film": [10, 10], "variance_regions": {"plate": rng.normal(1.0, 0.2)}}

    table = strategy_rows("x", [], render, True, DEFAULTS, spp=16, repeats=4, min_seconds=0.0)
    assert table["regions"]["best"] == {"plate": None} and table["regions"]["leader"]["plate"] is not None


def test_a_zero_variance_strategy_shows_no_efficiency_and_is_left_out_of_the_ranking(tmp_path):
    """An exact estimator (white furnace, env_sampling=cosine: every sample the answer) has an MSE of rounding
    alone; 1 / (MSE x time) would read ~1e29. Its row says "zero variance", its efficiency is null and the best is
    decided among the others."""
    planted = Planted({"direct=mis": 0.1}, {}, noise=0.02)

    def render(settings, spp, index):
        m = planted(settings, spp, index)
        if settings == {"hemisphere": "uniform"}:  # exact: variance below float32 rounding of a level-1 image
            return dict(m, mse=1e-30, floor_mse=0.0, variance=2.6e-17, level=0.93)
        return dict(m, level=0.93)

    table = strategy_rows("planted", [], render, True, DEFAULTS, spp=16, repeats=4, min_seconds=0.0, spp_step=2)
    rows = _rows(table)
    exact = rows["hemisphere=uniform"]
    assert exact["zero_variance"] is True and exact["efficiency"] is None
    assert exact["relative_efficiency_interval"]["value"] is None and exact["relative_mse"] is None
    assert not any(r["zero_variance"] for label, r in rows.items() if label != "hemisphere=uniform")
    assert table["zero_variance"] == ["hemisphere=uniform"] and table["best"] == "direct=mis"
    assert "hemisphere=uniform" not in table["separation"]["leader_over"]
    line = _best_line(table)
    assert line.startswith("Best: zero variance (exact here; no efficiency, not ranked): hemisphere=uniform. "
                           "Among the others: direct=mis (efficiency at equal time"), line
    html = _page(table, tmp_path)
    row_html = re.search(r"<tr><td>hemisphere=uniform</td>(.*?)</tr>", html).group(1)
    assert "zero variance" in row_html and "e+2" not in row_html and "e+1" not in row_html
    # the same row from the suite's cases alone (no renders): no efficiency either
    case = {"case": "c", "settings": {"hemisphere": "uniform"}, "mse": 0.0, "floor_mse": 0.0, "variance": 2.6e-17,
            "level": 0.93, "seconds": 1.0, "pixels": 100, "spp": 16, "film": [10, 10]}
    cases = strategy_rows("planted", [case], None, True, DEFAULTS)
    only = _rows(cases)["hemisphere=uniform"]
    assert only["zero_variance"] is True and only["efficiency"] is None
    assert cases["zero_variance"] == ["hemisphere=uniform"]


def test_a_strategy_exact_at_one_budget_only_is_left_out_of_the_ranking():
    """White furnace, env_sampling=cosine: exact at the equal-time budget (124 spp: variance 5e-17) but not at 256 spp,
    where float32 accumulation leaves a variance of 4e-9; its equal-time efficiency read 7.5e+27 x the default and
    "Best" named it. A row exact at either budget has no efficiency and no place in the ranking."""
    planted = Planted({"direct=mis": 0.1}, {"hemisphere=uniform": 2.0}, noise=0.02)  # equal time: 8 spp

    def render(settings, spp, index):
        m = planted(settings, spp, index)
        if settings == {"hemisphere": "uniform"} and spp != 16:  # exact at the equal-time spp only
            return dict(m, mse=1e-33, floor_mse=0.0, variance=4e-17, level=0.93)
        return dict(m, level=0.93)

    table = strategy_rows("planted", [], render, True, DEFAULTS, spp=16, repeats=4, min_seconds=0.0, spp_step=2)
    exact = _rows(table)["hemisphere=uniform"]
    assert exact["equal_time"]["zero_variance"] and not exact["equal_spp"]["zero_variance"]
    assert exact["zero_variance"] is True and exact["efficiency"] is None
    assert table["best"] == "direct=mis" and "hemisphere=uniform" in table["zero_variance"]
