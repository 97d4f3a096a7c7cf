"""The report's strategy section (harness/report/build.py, templates/strategies.html.j2) for a table that compares
one render per strategy at different spp (the suite's cases alone, or a studies.json of an older harness): it is
shown unranked (no "Best"), and an MSE below the ground truth's noise is a bound, never a negative number."""

from __future__ import annotations

import re

from harness.report.build import _strategies

DEFAULTS = {"direct": "area", "light_selection": "power", "hemisphere": "cosine", "rr": "albedo"}


def _row(label, strategy, spp, variance, mse_corrected, case=None):
    """A row as the strategy table wrote it before every row was rendered alike: one render at ``spp``."""
    floor = 1.5e-4
    efficiency = 1.0 / (variance * 20.0 * 64 / spp)
    return {"label": label, "strategy": strategy, "is_default": strategy is None, "case": case,
            "source": "case" if case else "rendered", "settings": {}, "spp": spp, "film": [64, 64], "pixels": 4096,
            "seconds": 0.08 * spp / 64, "mse": mse_corrected + floor, "floor_mse": floor,
            "mse_corrected": mse_corrected, "variance": variance, "mse_estimate": variance,
            "mse_source": "render variance",
            "seconds_per_megapixel": 20.0 * spp / 64, "efficiency": efficiency}


def test_a_table_of_single_renders_at_different_spp_is_unranked_and_shows_no_negative_mse(tmp_path):
    rows = [_row("default", None, 64, 2.6e-4, 1.65e-4),
            _row("rr=off", ["rr", "off"], 256, 2.74e-5, -2.228e-05, case="cornell-box/rr-off"),
            _row("direct=mis", ["direct", "mis"], 256, 3.02e-5, -2.138e-05, case="cornell-box/direct-mis")]
    base = rows[0]["efficiency"]
    for r in rows:
        r["relative_efficiency"] = r["efficiency"] / base
    table = {"scene": "cornell-box", "rows": rows, "best": "rr=off", "best_relative_efficiency": 1.84,
             "near_best": ["rr=off", "direct=mis"], "tie_factor": 1.25, "plot": None}
    section = {"defaults": DEFAULTS, "strategy_spp": 16, "scenes": [table]}
    _, html = _strategies(section, tmp_path, tmp_path)
    html = str(html)
    cells = re.findall(r"<td>([^<]*)</td>", html)
    assert not [c for c in cells if re.fullmatch(r"-\d[\d.e+-]*", c)], "a negative MSE is shown"
    assert sum(c.startswith("&lt; 0.00015") for c in cells) == 2
    assert "Best: <b>" not in html and "Best: rr=off" not in html
    assert "Not ranked" in html
