"""A ``calibration.json`` (written by ``harness calibrate``): its power table as text (:func:`power_table`, printed
by ``harness calibrate``, in calibration.md and in the report), and the file read back for the report
(``harness report --calibration FILE``), checked like results.json (:mod:`harness.files.results`): a malformed file
is one line naming it and the JSON path of the bad key. Only what the report shows is checked; other keys are
scanned (no NaN, no absurd nesting). A false-alarm sweep (``harness calibrate --films/--spp/--replicates``) holds
its configurations under ``sweep``: :func:`sweep_table` and :func:`sweep_total_line` are its text."""

from __future__ import annotations

from pathlib import Path

from harness.core.errors import HarnessError, read_user_text
from harness.files.results import (COUNT, NAME, NUMBER, POSITIVE, STR, ListOf, Nullable, Obj, Scalar, check_spec,
                                   parse)

__all__ = ["PLANTS", "POWER_HEADERS", "SWEEP_HEADERS", "power_caption", "power_table", "read_calibration",
           "sweep_table", "sweep_total_line"]

#: the planted errors, as calibration.json names them (harness.running.calibrate)
PLANTS = ("bias", "region_aligned", "region_off_grid")

_SIZE = Nullable(Scalar("a number >= 0", lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)
                        and v >= 0))
QUANTILE = Obj({"value": _SIZE, "interval": ListOf(_SIZE, 2), "runs": COUNT, "false_alarms": COUNT,
                "not_caught": COUNT})
BUDGET = Obj({"factor": POSITIVE, "runs": COUNT, "false_alarms": COUNT, "seconds": Nullable(NUMBER),
              "bias": QUANTILE, "region_aligned": QUANTILE, "region_off_grid": QUANTILE},
             {"spp": Nullable(COUNT), "seconds_budget": POSITIVE})
POWER = Obj({"budgets": ListOf(BUDGET)})
CASE = Obj({"case": NAME, "expect": STR}, {"power": POWER, "runs": COUNT, "false_alarms": COUNT})
_P = Scalar("a probability from 0 to 1", lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)
           and 0 <= v <= 1)
SWEEP_CONFIG = Obj({"film": ListOf(COUNT, 2), "runs": COUNT, "false_alarms": COUNT, "alpha": _P,
                    "p_value_of_count": _P},
                   {"spp": Nullable(COUNT), "seconds": Nullable(POSITIVE), "replicates": Nullable(COUNT),
                    "ground_truth_spp": Nullable(COUNT), "ground_truth_source": Nullable(STR), "errors": COUNT})
SWEEP = Obj({"cases": ListOf(Obj({"case": NAME, "configs": ListOf(SWEEP_CONFIG)})),
             "total": Obj({"runs": COUNT, "false_alarms": COUNT, "expected": Nullable(NUMBER), "p_value": _P})},
            {"skipped": ListOf(STR)})
CALIBRATION = Obj({"suite": STR, "seeds": COUNT, "cases": ListOf(CASE)},
                  {"power": Obj({"quantile": POSITIVE, "precision": POSITIVE, "confidence": POSITIVE,
                                 "region_size": COUNT, "method": STR}),
                   "sweep": SWEEP})


def read_calibration(path: str | Path, where: str = "--calibration") -> dict:
    """The checked content of a calibration.json; a one-line HarnessError at ``where`` (and the file, and the JSON
    path of the first bad key) when it is missing, unreadable, not JSON or not a calibration."""
    label = f"{where}: {path}"
    text = read_user_text(path, missing="no such calibration file (harness calibrate writes DIR/calibration.json)",
                          where=label)
    doc = parse(text, label)
    if not isinstance(doc, dict):
        raise HarnessError(label, "expected a calibration.json of harness calibrate (a JSON object)")
    check_spec(CALIBRATION, doc, label)
    return doc


# ---- the power table ------------------------------------------------------------------------------------------


def power_caption(result: dict) -> str:
    """One line saying what the power table holds and how it was measured."""
    p = result.get("power") or {}
    return (f"power: the smallest error the verdict catches in {_pct(p.get('quantile'))} of {result.get('seeds')} "
            f"seeds (in brackets: {_pct(p.get('confidence'))} interval; b: render x (1 - b); d: one "
            f"{p.get('region_size')}x{p.get('region_size')} region of median brightness x (1 + d), on the tile grid / "
            f"half a tile off; exact: caught by the exact comparison of noiseless tiles); each seed's threshold by "
            f"bisection to {_pct(p.get('precision'))}")


POWER_HEADERS = ("case", "budget", "spp", "render s", "false alarms", "bias b", "region on grid d",
                 "region off grid d")


def power_table(result: dict) -> list[tuple[str, ...]]:
    """The power table's rows (as text): one per expect-pass case and budget factor, :data:`POWER_HEADERS`."""
    rows = []
    for row in result.get("cases", []):
        for b in (row.get("power") or {}).get("budgets", []):
            spp = b.get("spp")
            rows.append((row["case"], f"{b['factor']:g}x", "–" if spp is None else str(spp),
                         "–" if b.get("seconds") is None else f"{b['seconds']:.3g}", f"{b['false_alarms']}/{b['runs']}",
                         *(_size(b[plant]) for plant in PLANTS)))
    return rows


def _size(summary: dict) -> str:
    """A quantile and its interval as percentages: ``0.21% [0.19, 0.24]`` ("–" for an end beyond the seeds); "not
    caught" where fewer than the quantile's fraction of the seeds were caught at any size tried."""
    value = summary.get("value")
    if value is None:
        return "not caught"
    low, high = summary.get("interval") or [None, None]
    caught_by = summary.get("caught_by") or {}
    exact = caught_by.get("other", 0) * 2 > sum(caught_by.values())  # noiseless tiles compared exactly
    return (f"{_pct(value, 3)} [{_pct(low, 3, unit='')}, {'–' if high is None else _pct(high, 3, unit='')}]"
            + (" exact" if exact else ""))


def _pct(value, digits: int = 2, unit: str = "%") -> str:
    if not isinstance(value, (int, float)):
        return "–"
    return f"{100.0 * value:.{digits}g}{unit}"


# ---- the false-alarm sweep ------------------------------------------------------------------------------------

SWEEP_HEADERS = ("case", "film", "spp", "replicates", "GT spp", "false alarms", "p of count")


def sweep_table(result: dict) -> list[tuple[str, ...]]:
    """The sweep's rows (as text): one per case and configuration, :data:`SWEEP_HEADERS`; none without a sweep."""
    rows = []
    for case in (result.get("sweep") or {}).get("cases", []):
        for c in case["configs"]:
            budget = (f"{c['seconds']:g} s" if c.get("seconds") is not None else
                      "–" if c.get("spp") is None else str(c["spp"]))
            truth = ("closed form" if c.get("ground_truth_source") == "closed-form" else
                     "–" if c.get("ground_truth_spp") is None else str(c["ground_truth_spp"]))
            alarms = f"{c['false_alarms']}/{c['runs']}" + (f" ({c['errors']} errors)" if c.get("errors") else "")
            rows.append((case["case"], f"{c['film'][0]}x{c['film'][1]}", budget,
                         "–" if c.get("replicates") is None else str(c["replicates"]), truth, alarms,
                         f"{c['p_value_of_count']:.3g}"))
    return rows


def sweep_total_line(result: dict) -> str:
    """The sweep's totals in one line: correct renders, false alarms, how many alpha leads one to expect and the
    probability of at least that many; empty without a sweep."""
    total = (result.get("sweep") or {}).get("total")
    if not total:
        return ""
    expected = total.get("expected")
    return (f"{total['runs']} correct renders, {total['false_alarms']} false alarms, "
            f"{'–' if expected is None else f'{expected:.3g}'} expected at alpha; "
            f"P(>= {total['false_alarms']}) = {total['p_value']:.3g}")
