"""A baseline's tolerances: a suite file's ``[baseline]`` table and ``--baseline-tolerance KEY=VALUE``, parsed and
checked (what each one means: :mod:`harness.running.baseline`, ``docs/ci.md``). Read when a suite loads
(:func:`harness.running.cases.load_suite`), so a broken table is an error with or without ``--baseline``."""

from __future__ import annotations

import math
from typing import Any

from harness.core.errors import HarnessError
from harness.core.limits import float_or_inf
from harness.core.text import hint, short, toml_key

DEFAULT_ALPHA = 1e-3
NOISE_METRICS = ("rmse", "relmse", "mape")  # image means of a per-pixel error: statistical by default
FACTOR_METRICS = ("rmse", "relmse", "mape", "flip")  # lower is better: new <= factor x baseline
TOLERANCE_KEYS = (*FACTOR_METRICS, "psnr", "ssim", "bias", "seconds", "paths_per_second", "alpha")
DEFAULTS: dict[str, float | str] = {
    "rmse": "auto", "relmse": "auto", "mape": "auto", "bias": "auto", "flip": "off", "psnr": "off", "ssim": "off",
    "seconds": "off", "paths_per_second": "off", "alpha": DEFAULT_ALPHA,
}


def parse_tolerance(where: str, key: str, value: Any) -> float | str:
    """One tolerance value, checked: a number (its meaning: :mod:`harness.running.baseline`), "auto" or "off"."""
    label = f"{where}{' ' if where.startswith('--') else '.'}{key if where.startswith('--') else toml_key(key)}"
    if key not in TOLERANCE_KEYS:
        raise HarnessError(label, f"unknown baseline tolerance{hint(key, TOLERANCE_KEYS)}; expected one of "
                           f"{', '.join(TOLERANCE_KEYS)}")
    if value is False or (isinstance(value, str) and value.strip().lower() == "off"):
        return "off"
    if isinstance(value, str) and value.strip().lower() == "auto":
        if key not in (*NOISE_METRICS, "bias"):
            raise HarnessError(label, f"'auto' (a statistical rule) exists only for {', '.join(NOISE_METRICS)} and "
                               "bias; give a number or 'off'")
        return "auto"
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise HarnessError(label, f"expected a number, 'auto' or 'off', got {short(value)}") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float_or_inf(value)):
        raise HarnessError(label, f"expected a finite number, 'auto' or 'off', got {short(value)}")
    value = float(value)
    if key == "alpha" and not 0 < value < 1:
        raise HarnessError(label, f"expected a probability in (0, 1), got {value}")
    if key in (*FACTOR_METRICS, "seconds", "paths_per_second") and value < 1:
        raise HarnessError(label, f"expected a factor >= 1 (1.10 = 10 % worse allowed), got {value}")
    if key in ("psnr", "ssim") and value < 0:
        raise HarnessError(label, f"expected the drop allowed, >= 0, got {value}")
    if key == "bias" and value <= 0:
        raise HarnessError(label, f"expected a positive |z| bound, got {value}")
    return value


def check_table(label: str, table: Any) -> dict[str, float | str]:
    """A suite file's ``[baseline]`` table, checked (``label`` names the file): its tolerances, parsed. Called when
    the suite loads, so a broken table is an error whether or not the run has ``--baseline``."""
    if not isinstance(table, dict):
        raise HarnessError(f"{label}: baseline", f"expected a table [baseline], got {short(table)}")
    return {key: parse_tolerance(f"{label}: baseline", key, value) for key, value in table.items()}


def suite_tolerances(suite) -> dict[str, float | str]:
    """The suite file's ``[baseline]`` table (checked), on top of the defaults."""
    return {**DEFAULTS, **check_table(str(suite.path), suite.baseline)}


def option_tolerances(items: list[str], base: dict[str, float | str]) -> dict[str, float | str]:
    """``--baseline-tolerance KEY=VALUE`` items on top of ``base``."""
    out = dict(base)
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise HarnessError("--baseline-tolerance", f"expected KEY=VALUE (e.g. relmse=1.10), got {item!r}")
        key = key.strip()
        out[key] = parse_tolerance("--baseline-tolerance", key, value.strip())
    return out
