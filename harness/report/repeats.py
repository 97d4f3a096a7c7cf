"""The error of the error on a convergence page (``harness convergence --repeats K``): E[MSE] and its spread per
rung, and the error spectrum ensemble's plot (docs/report.md, "Convergence")."""

from __future__ import annotations

from typing import Any

HEADERS = ("series", "rung", "runs", "E[MSE] corrected", "sd", "10 %", "90 %", "spectrum: low / high power")


def repeat_rows(result: dict[str, Any]) -> list[tuple]:
    """One row per series and rung that was rendered more than once: its E[MSE] (ground-truth floor removed), the
    standard deviation and 10-90 % band of the runs' MSE, and the ratio of the error spectrum's power in its lowest
    tenth of frequencies to its upper half (about 1 for white noise)."""
    rows = []
    for series in result.get("series") or []:
        for point in series.get("points") or []:
            spread = point.get("repeats")
            if not isinstance(spread, dict):
                continue
            budget = point.get("budget") or {}
            rung = f"{budget['spp']} spp" if "spp" in budget else f"{budget.get('seconds')} s"
            band = spread.get("mse_corrected_band") or [None, None]
            rows.append((series.get("label"), rung, spread.get("k"), point.get("mse_corrected"),
                         spread.get("mse_corrected_std"), band[0], band[1], _balance(point.get("spectrum"))))
    return rows


def _balance(spectrum: Any) -> float | None:
    power = spectrum.get("power_corrected") if isinstance(spectrum, dict) else None
    if not power:
        return None
    low = power[: max(1, len(power) // 10)]
    high = power[len(power) // 2:] or power
    mean_high = sum(high) / len(high)
    return (sum(low) / len(low)) / mean_high if mean_high > 0 else None
