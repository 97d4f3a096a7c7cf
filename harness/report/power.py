"""The page's power table (in its definitions): the smallest bias and region error the verdict catches in 90 % of
the seeds, from a ``calibration.json`` that ``harness calibrate`` measured (``harness report --calibration FILE``,
``harness run --calibration FILE``); without one, how to measure it (docs/report.md, "Validation power")."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from harness.files.calibration import (POWER_HEADERS, SWEEP_HEADERS, power_caption, power_table, read_calibration,
                                       sweep_table, sweep_total_line)

HOW_TO = ("not measured for this page: `harness calibrate SUITE --seeds 50 [--budgets 0.5,1,2,4]` writes "
          "DIR/calibration.json; `harness report RESULTS.json --calibration DIR/calibration.json` (or `harness run "
          "--calibration ...`) shows it here")


def power_view(path: str | Path | None) -> dict[str, Any]:
    """What the page's power section shows: the table's ``headers`` and ``rows``, its ``caption``, the calibration
    ``file`` and ``suite``, or only a ``note`` saying how to measure it; a false-alarm sweep's table as ``sweep``
    (``headers``, ``rows``, ``total``: its line of totals), None without one. A bad file is a one-line HarnessError
    (``--calibration``) before anything is written."""
    if path is None:
        return {"rows": [], "headers": POWER_HEADERS, "caption": "", "file": None, "suite": None, "note": HOW_TO,
                "sweep": None}
    doc = read_calibration(path)
    rows = power_table(doc)
    sweep = ({"headers": SWEEP_HEADERS, "rows": sweep_table(doc), "total": sweep_total_line(doc)}
             if "sweep" in doc else None)
    note = ("" if rows else "the calibration is a false-alarm sweep: it measured no power" if sweep else
            "the calibration holds no power measurement (run without --no-power)")
    return {"rows": rows, "headers": POWER_HEADERS, "caption": power_caption(doc) if rows else "", "file": str(path),
            "suite": doc.get("suite"), "note": note, "method": (doc.get("power") or {}).get("method"),
            "sweep": sweep}


def power_json(view: dict[str, Any]) -> dict[str, Any]:
    """report.json's ``power``: the same tables as lists."""
    sweep = view.get("sweep")
    return {"file": view["file"], "suite": view["suite"], "caption": view["caption"], "note": view["note"],
            "headers": list(view["headers"]), "rows": [list(r) for r in view["rows"]],
            "sweep": None if sweep is None else {"headers": list(sweep["headers"]),
                                                 "rows": [list(r) for r in sweep["rows"]], "total": sweep["total"]}}
