"""Calibration of the verdict on a suite: how often a correct render passes (quiet) over many seeds, and how
decisively each planted fault fails (sharp).

    harness calibrate suites/canonical.toml --seeds 50 --cases '*/reference'

A case with ``expect = "pass"`` is rerun with seeds 0 .. N-1 (its ground truth comes from the cache, rendered
once); with the verdict's alpha = 0.01 about N / 100 false alarms are expected, and the count is binomial. A case
with ``expect = "fail"`` is run once and its statistics are reported.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import json
import time
from pathlib import Path


from harness.core import jsonsafe
from harness.core.errors import HarnessError
from harness.files.imageio import atomic_write_text
from harness.running.cases import Case, Suite
from harness.core.limits import MAX_SECONDS, format_seconds, render_seconds
from harness.running.judge import case_scene, run_case

RENDER_OVERHEAD_SECONDS = 0.02  # a case's fixed cost beyond its paths (scene load, verdict, EXR writes): measured >= 0.05


def select_cases(suite: Suite, patterns: list[str] | None) -> list[Case]:
    """The cases whose name matches any of the ``--cases`` globs (every case without any); a pattern that matches
    no case (a typo would calibrate nothing, or less than asked) is a one-line HarnessError at ``--cases``."""
    if not patterns:
        return list(suite.cases)
    for pattern in patterns:
        if not any(fnmatch.fnmatchcase(c.name, pattern) for c in suite.cases):
            names = [c.name for c in suite.cases]
            shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
            raise HarnessError("--cases", f"{pattern[:80]!r} matches no case of {suite.path} (its cases: {shown})")
    return [c for c in suite.cases if any(fnmatch.fnmatchcase(c.name, p) for p in patterns)]


def check_cost(cases: list[Case], seeds: int, option: str = "--seeds") -> None:
    """Refuse a calibration whose estimated time breaks the 24 h limit of a render (harness/core/limits.py): each
    ``expect = "pass"`` case renders ``seeds`` times, each render its budget (``seconds``, or its pixels times
    ``spp`` at the estimate's paths per second) plus :data:`RENDER_OVERHEAD_SECONDS`."""
    total = 0.0
    for case in cases:
        runs = seeds if case.expect == "pass" else 1
        if case.seconds is not None:
            each = case.seconds
        else:
            scene = case_scene(case)
            each = render_seconds(scene.film.width, scene.film.height, case.spp)
        total += runs * (each + RENDER_OVERHEAD_SECONDS)
    if total > MAX_SECONDS:
        raise HarnessError(option, f"{seeds} seeds of {len(cases)} cases need about {format_seconds(total)}, more "
                           f"than the {format_seconds(MAX_SECONDS)} limit; lower {option} or choose fewer --cases")


def calibrate(suite: Suite, out_dir: Path, *, seeds: int, patterns: list[str] | None, cache_dir=None, variant=None,
              on_progress=None) -> dict:
    from scipy import stats  # optional: 0.5 s at every command's start; only its p-values and quantiles need it

    cases = select_cases(suite, patterns)
    rows = []
    for case in cases:
        start = time.perf_counter()
        if case.expect == "pass":
            verdicts, stats_seen = [], []
            for seed in range(seeds):
                record = run_case(dataclasses.replace(case, seed=seed), out_dir, cache_dir=cache_dir, variant=variant)
                verdicts.append(record.get("status"))
                v = record.get("verdict", {})
                stats_seen.append({
                    "seed": seed, "status": record.get("status"), "reason": record.get("reason", ""),
                    "global_bias_p": v.get("global_bias", {}).get("p_value"),
                    "omnibus_p": v.get("omnibus", {}).get("p_value"),
                    "max_z_p": v.get("max_z", {}).get("p_value"),
                })
                if on_progress:
                    on_progress(case.name, seed)
            failures = sum(s != "pass" for s in verdicts)
            alpha = case.alpha
            rows.append({
                "case": case.name, "expect": "pass", "runs": seeds, "passes": seeds - failures,
                "false_alarms": failures, "alpha": alpha,
                # P(at least this many false alarms | the verdict's false-alarm rate is alpha)
                "p_value_of_count": float(stats.binom.sf(failures - 1, seeds, alpha)) if failures else 1.0,
                "runs_detail": stats_seen, "seconds": time.perf_counter() - start,
            })
        else:
            record = run_case(case, out_dir, cache_dir=cache_dir, variant=variant)
            v = record.get("verdict", {})
            rows.append({
                "case": case.name, "expect": case.expect, "status": record.get("status"),
                "caught": record.get("status") == "fail", "reason": record.get("reason", ""),
                "global_bias": v.get("global_bias"), "omnibus": v.get("omnibus"), "max_z": v.get("max_z"),
                "seconds": time.perf_counter() - start,
            })
            if on_progress:
                on_progress(case.name, 0)
    return {"suite": suite.name, "seeds": seeds, "cases": rows}


def summary_lines(result: dict) -> list[str]:
    lines = []
    for row in result["cases"]:
        if row["expect"] == "pass":
            lines.append(f"{row['case']}: {row['passes']}/{row['runs']} pass ({row['false_alarms']} false alarms at "
                         f"alpha = {row['alpha']}; P(>= that many | alpha) = {row['p_value_of_count']:.3g})")
        else:
            gb = row.get("global_bias") or {}
            om = row.get("omnibus") or {}
            mz = row.get("max_z") or {}
            z = max(gb.get("z", [0.0]), key=abs) if gb.get("z") else None
            chi2 = max(om.get("statistic", [0.0])) if om.get("statistic") else None
            lines.append(f"{row['case']}: {'caught' if row['caught'] else 'MISSED'}; global-bias z = {_fmt(z)}, "
                         f"omnibus chi2 = {_fmt(chi2)}, max |z| = {_fmt(mz.get('statistic'))}")
    return lines


def _fmt(v) -> str:
    return f"{v:.4g}" if isinstance(v, (int, float)) else str(v)


def write(result: dict, path: Path) -> None:
    atomic_write_text(path, jsonsafe.dumps(result, indent=2))  # strict JSON: NaN / inf as null
