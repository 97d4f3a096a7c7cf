"""Calibration of the verdict on a suite: how often a correct render passes (quiet) over many seeds, how small an
error it catches in a correct render (power), and how decisively each planted fault fails (sharp).

    harness calibrate suites/canonical.toml --seeds 50 --cases '*/reference' [--budgets 0.5,1,2,4]

A case with ``expect = "pass"`` is rerun with seeds 0 .. N-1 (its ground truth comes from the cache, rendered
once); with the verdict's alpha = 0.001 about N / 1000 false alarms are expected, and the count is binomial. Into
each of those correct renders errors are then planted and judged by the same verdict against the same ground truth
(:mod:`harness.judges.power`): a uniform relative bias b (the render times 1 - b) and a relative error d in one
16 x 16 region (times 1 + d), on the tile grid where the ground truth has its median brightness and half a tile
off it (the worst placement);
each seed's smallest caught b and d is found by bisection to 2 %, and the size caught in 90 % of the seeds is the
0.9-quantile of those thresholds, with a 90 % distribution-free interval. ``budgets`` repeats the measurement with
the case's budget (spp or seconds) times each factor, so the table reads power against the test render's time.
A case with ``expect = "fail"`` is run once and its statistics are reported.

    harness calibrate suites/canonical.toml --seeds 8 --films scene,half,double --spp 16,64,256 --replicates 1,2,4

is a false-alarm sweep instead (:func:`sweep`): every expect-pass case at every combination of film, spp and the
reference's replicates, each render judged as the suite judges it; no power is measured.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import itertools
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.core import jsonsafe
from harness.core.errors import HarnessError
from harness.files.calibration import (PLANTS, POWER_HEADERS, SWEEP_HEADERS, power_caption, power_table,
                                       sweep_table, sweep_total_line)
from harness.files.imageio import ExrImage, atomic_write_text
from harness.judges import power
from harness.running.budget import render_with_budget
from harness.running.cases import MIN_SPP, Case, Suite
from harness.core.limits import MAX_FILM_SIDE, MAX_SECONDS, film_problem, format_seconds, render_seconds
from harness.core.options import MIN_SWEEP_SIDE
from harness.running.compare import judge
from harness.running.judge import case_scene, case_scenes, ground_truth_for, judged_images, run_case
from harness.running import runstate
from harness.renderers.validate import validate_result

RENDER_OVERHEAD_SECONDS = 0.02  # a case's fixed cost beyond its paths (scene load, verdict, EXR writes): measured >= 0.05
DEFAULT_REGION_SIZE = 16


@dataclass(frozen=True)
class PowerOptions:
    """What ``harness calibrate`` measures of the verdict's power: at each budget factor (1: the case's own budget,
    always measured), the smallest bias and region error caught with probability ``quantile``, each seed's
    threshold found to ``precision`` (relative), in a region of ``region_size`` pixels. ``enabled`` False: false
    alarms only (the calibration of earlier harnesses)."""

    enabled: bool = True
    budgets: tuple[float, ...] = (1.0,)
    region_size: int = DEFAULT_REGION_SIZE
    quantile: float = power.DEFAULT_QUANTILE
    precision: float = power.DEFAULT_PRECISION
    confidence: float = power.DEFAULT_CONFIDENCE

    def factors(self) -> tuple[float, ...]:
        """The budget factors measured: ``budgets`` and 1 (the case's own budget), ascending."""
        return tuple(sorted(set(self.budgets) | {1.0}))


@dataclass(frozen=True)
class SweepOptions:
    """A false-alarm sweep of ``harness calibrate``: every expect-pass case at each combination of ``films``
    (``scene``: the case's own film, ``half``, ``double``, or a (width, height)), ``spp`` and the reference's
    ``replicates``; None keeps the case's own value. ``ground_truth_spp``: the ground truth's spp instead of the
    case's (a sharper ground truth must never make a correct render fail, so a sweep may ask for one)."""

    films: tuple = ("scene",)
    spp: tuple[int, ...] | None = None
    replicates: tuple[int, ...] | None = None
    ground_truth_spp: int | None = None


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


def with_budget(case: Case, factor: float) -> Case:
    """The case with its budget times ``factor``: ``seconds`` scaled, or ``spp`` scaled and rounded (at least
    :data:`MIN_SPP`, the verdict's least)."""
    if factor == 1.0:
        return case
    if case.seconds is not None:
        return dataclasses.replace(case, seconds=case.seconds * factor)
    return dataclasses.replace(case, spp=max(MIN_SPP, int(round(case.spp * factor))))


def check_cost(cases: list[Case], seeds: int, option: str = "--seeds", budgets: tuple[float, ...] = (1.0,),
               sweep_options: SweepOptions | None = None) -> None:
    """Refuse a calibration whose estimated time breaks the 24 h limit of a render (harness/core/limits.py): each
    ``expect = "pass"`` case renders ``seeds`` times at each budget factor (or, with ``sweep_options``, at each of
    its sweep's configurations, :func:`sweep_configs`, and expect-fail cases not at all), each render its budget
    (``seconds``, or its pixels times ``spp`` at the estimate's paths per second) plus
    :data:`RENDER_OVERHEAD_SECONDS`."""
    total = 0.0
    for case in cases:
        if sweep_options is not None:
            variants = sweep_configs(case, sweep_options) if case.expect == "pass" else []
        else:
            variants = [with_budget(case, f) for f in (budgets if case.expect == "pass" else (1.0,))]
        for budget in variants:
            runs = seeds if case.expect == "pass" else 1
            if budget.seconds is not None:
                each = budget.seconds
            else:
                scene = case_scene(budget)
                each = render_seconds(scene.film.width, scene.film.height, budget.spp)
            total += runs * (each + RENDER_OVERHEAD_SECONDS)
    if total > MAX_SECONDS:
        lower = f"{option}, --films or --spp" if sweep_options is not None else option
        raise HarnessError(option, f"{seeds} seeds of {len(cases)} cases need about {format_seconds(total)}, more "
                           f"than the {format_seconds(MAX_SECONDS)} limit; lower {lower} or choose fewer --cases")


# ---- power -----------------------------------------------------------------------------------------------------


def regions_for(truth: ExrImage, case: Case, options: PowerOptions) -> dict[str, power.Region]:
    """The planted regions of a case: the region of typical brightness of its ground truth on the tile grid
    (:func:`harness.judges.power.typical_region`) and the same half a tile off it; the same for every seed."""
    return {"region_aligned": power.typical_region(truth.image, options.region_size, case.tile),
            "region_off_grid": power.typical_region(truth.image, options.region_size, case.tile,
                                                    offset=case.tile // 2)}


def seed_power(test: ExrImage, truth: ExrImage, case: Case, options: PowerOptions,
               guesses: dict[str, float] | None = None,
               regions: dict[str, power.Region] | None = None) -> dict[str, power.Threshold]:
    """One correct render's threshold of each planted error (:data:`PLANTS`), judged by the case's verdict (its
    tile and alpha, the images' degrees of freedom) against its ground truth. ``guesses``: where each search starts
    (default: :func:`harness.judges.power.first_guess`); ``regions``: where the region errors go (default:
    :func:`regions_for`)."""
    guesses = guesses or {}
    regions = regions or regions_for(truth, case, options)

    def judged(image, variance):
        return judge(ExrImage(image, variance, test.metadata), truth, tile=case.tile, alpha=case.alpha)

    out = {}
    for plant in PLANTS:
        region = regions.get(plant)
        if region is None:
            plant_at = lambda size: judged(*power.plant_bias(test.image, test.variance, size))  # noqa: E731
            upper = power.MAX_BIAS
        else:
            plant_at = lambda size, r=region: judged(*power.plant_region(test.image, test.variance, size, r))  # noqa: E731
            upper = power.MAX_REGION_ERROR
        guess = guesses.get(plant) or power.first_guess(test.image, test.variance, truth.variance, region)
        out[plant] = power.smallest_caught(plant_at, guess=guess, upper=upper, precision=options.precision)
    return out


class _BudgetPower:
    """The thresholds of every seed at one budget factor, and their summary."""

    def __init__(self, case: Case, factor: float):
        self.case = with_budget(case, factor)
        self.factor = factor
        self.regions: dict[str, power.Region] | None = None  # from the first ground truth: the same for all seeds
        self.seeds: list[dict] = []
        self.seconds: list[float] = []
        self.errors = 0

    def guesses(self) -> dict[str, float]:
        """Each search starts at the median of the thresholds found so far (they vary little between seeds)."""
        out = {}
        for plant in PLANTS:
            found = [s[plant]["size"] for s in self.seeds if s[plant]["size"]]
            if found:
                out[plant] = statistics.median(found)
        return out

    def add(self, seed: int, test: ExrImage, truth: ExrImage, seconds: float, options: PowerOptions) -> dict:
        self.regions = self.regions or regions_for(truth, self.case, options)
        thresholds = seed_power(test, truth, self.case, options, self.guesses(), self.regions)
        entry = {"seed": seed, "seconds": seconds, **{k: t.to_dict() for k, t in thresholds.items()}}
        self.seeds.append(entry)
        self.seconds.append(seconds)
        return entry

    def summary(self, options: PowerOptions) -> dict:
        row = {"factor": self.factor, "runs": len(self.seeds), "errors": self.errors,
               # the median: a first render's time may hold the renderer's one-off compilation
               "seconds": statistics.median(self.seconds) if self.seconds else None,
               **({"seconds_budget": self.case.seconds} if self.case.seconds is not None else {"spp": self.case.spp})}
        row["false_alarms"] = sum(s["bias"]["size"] == 0.0 for s in self.seeds)
        for plant in PLANTS:
            sizes = [s[plant]["size"] for s in self.seeds]
            summary = power.detection_quantile(sizes, options.quantile, options.confidence)
            caught_by: dict[str, int] = {}
            for s in self.seeds:
                for name in s[plant]["caught_by"]:
                    caught_by[name] = caught_by.get(name, 0) + 1
            summary["caught_by"] = caught_by
            # seeds whose verdict passed again at twice their threshold: the bisection's assumption broken there
            summary["not_monotone"] = sum(s[plant]["caught_at_double"] is False for s in self.seeds)
            summary["verdicts"] = sum(s[plant]["verdicts"] for s in self.seeds)
            row[plant] = summary
        row["seeds"] = self.seeds
        return row


def _render_and_judge(case: Case, truth_gt, variant, cache_dir):
    """A render of ``case`` at its budget and the images the verdict takes (no files written)."""
    scene = case_scenes(case)[0]
    result = render_with_budget(case, scene, variant, cache_dir=cache_dir)
    validate_result(result, scene.film.width, scene.film.height)
    test, truth = judged_images(result, truth_gt)
    return result, test, truth


# ---- the calibration -------------------------------------------------------------------------------------------


def calibrate(suite: Suite, out_dir: Path, *, seeds: int, patterns: list[str] | None, cache_dir=None, variant=None,
              on_progress=None, power_options: PowerOptions | None = None) -> dict:
    """Calibrate the suite's cases (those matching ``patterns``): false alarms of each expect-pass case over
    ``seeds`` seeds and, with ``power_options`` enabled (the default), the verdict's power at each budget factor;
    each expect-fail case once. Returns calibration.json's content (docs/verdict.md, "Power, measured")."""
    from scipy import stats  # optional: 0.9 s; only calibrate's binomial tail (Boost's; scipy.special.bdtr differs)

    options = power_options or PowerOptions()
    cases = select_cases(suite, patterns)
    runstate.refuse_links(out_dir, cases)  # a link planted in out_dir: one line, before the first render
    rows = []
    for case in cases:
        start = time.perf_counter()
        if case.expect == "pass":
            rows.append(_calibrate_pass(case, out_dir, seeds, cache_dir, variant, on_progress, options, stats))
            rows[-1]["seconds"] = time.perf_counter() - start
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
    out = {"suite": suite.name, "seeds": seeds, "cases": rows}
    if options.enabled:
        out["power"] = {"quantile": options.quantile, "precision": options.precision,
                        "confidence": options.confidence, "region_size": options.region_size,
                        "budgets": list(options.factors()), "method": METHOD}
    return out


METHOD = ("into each seed's correct render: a uniform bias b (render x (1 - b), variance x (1 - b)^2) and a relative "
          "error d in one square region (x (1 + d), variance x (1 + d)^2), on the tile grid where the ground truth has "
          "its median brightness and half a tile off it (the worst placement); each judged by the case's verdict against its ground truth. Per "
          "seed the smallest caught size by bracketing and bisection in log(size) to the stated precision (the "
          "bracket's upper end); over the seeds the quantile of those thresholds (the size caught in that fraction "
          "of the seeds) with a distribution-free interval from the order statistics")


def _calibrate_pass(case: Case, out_dir: Path, seeds: int, cache_dir, variant, on_progress, options: PowerOptions,
                    stats) -> dict:
    """An expect-pass case: ``seeds`` runs at its budget through :func:`run_case` (the suite's very outcome:
    verdict and thresholds), and with power, the thresholds of each render, then the other budget factors."""
    verdicts, stats_seen = [], []
    at_budget = _BudgetPower(case, 1.0)
    truth_gt = None
    for seed in range(seeds):
        keep: dict = {}
        record = run_case(dataclasses.replace(case, seed=seed), out_dir, cache_dir=cache_dir, variant=variant,
                          keep=keep)
        verdicts.append(record.get("status"))
        v = record.get("verdict", {})
        seen = {
            "seed": seed, "status": record.get("status"), "reason": record.get("reason", ""),
            "global_bias_p": v.get("global_bias", {}).get("p_value"),
            "omnibus_p": v.get("omnibus", {}).get("p_value"),
            "max_z_p": v.get("max_z", {}).get("p_value"),
        }
        if options.enabled and "test" in keep and keep["test"].variance is not None:
            entry = at_budget.add(seed, keep["test"], keep["ground_truth"], keep["result"].seconds, options)
            seen.update({plant: entry[plant]["size"] for plant in PLANTS})
            truth_gt = truth_gt or keep["gt"]
        elif options.enabled:
            at_budget.errors += 1
        stats_seen.append(seen)
        if on_progress:
            on_progress(case.name, seed)
    failures = sum(s != "pass" for s in verdicts)
    alpha = case.alpha
    row = {
        "case": case.name, "expect": "pass", "runs": seeds, "passes": seeds - failures,
        "false_alarms": failures, "alpha": alpha,
        # P(at least this many false alarms | the verdict's false-alarm rate is alpha)
        "p_value_of_count": _count_p(failures, seeds, alpha, stats),
        "runs_detail": stats_seen,
    }
    if not options.enabled:
        return row
    budgets = []
    for factor in options.factors():
        if factor == 1.0:
            budgets.append(at_budget.summary(options))
            continue
        measured = _BudgetPower(case, factor)
        for seed in range(seeds):
            seeded = dataclasses.replace(measured.case, seed=seed)
            try:
                gt = truth_gt or _ground_truth(seeded, cache_dir, variant)
                result, test, truth = _render_and_judge(seeded, gt, variant, cache_dir)
            except HarnessError:
                raise
            except Exception:  # noqa: BLE001 - a renderer failure loses this seed, as run_case would
                measured.errors += 1
                continue
            truth_gt = truth_gt or gt
            if test.variance is None:
                measured.errors += 1
                continue
            measured.add(seed, test, truth, result.seconds, options)
            if on_progress:
                on_progress(f"{case.name} x{factor:g}", seed)
        budgets.append(measured.summary(options))
    regions = at_budget.regions
    row["power"] = {"region": None if regions is None else {
        "size": regions["region_aligned"].size, "aligned": regions["region_aligned"].to_dict(),
        "off_grid": regions["region_off_grid"].to_dict(),
        "placement": "median ground-truth brightness on the tile grid; off grid: half a tile down and right"},
        "budgets": budgets}
    return row


def _ground_truth(case: Case, cache_dir, variant):
    """The ground truth a case is judged against (:func:`harness.running.judge.ground_truth_for`)."""
    return ground_truth_for(case, case_scenes(case)[1], cache_dir, variant)


# ---- the false-alarm sweep -------------------------------------------------------------------------------------


def sweep_film(case: Case, item, film) -> tuple[int, int]:
    """The (width, height) of one ``--films`` item for a case whose own film is ``film``: ``scene`` that film,
    ``half`` / ``double`` its sides halved / doubled (at least :data:`MIN_SWEEP_SIDE`), a pair itself; a doubled
    film over the film limits is a one-line HarnessError at ``--films``."""
    if isinstance(item, tuple):
        return item
    factor = {"scene": 1.0, "half": 0.5, "double": 2.0}[item]
    width, height = (max(MIN_SWEEP_SIDE, int(side * factor)) for side in (film.width, film.height))
    problem = (f"expected at most {MAX_FILM_SIDE} pixels per side" if max(width, height) > MAX_FILM_SIDE
               else film_problem(width, height))
    if problem:
        raise HarnessError("--films", f"{item} of case {case.name!r}'s {film.width}x{film.height} film is "
                           f"{width}x{height}: {problem}; leave {item} out or choose other --cases")
    return width, height


def check_replicates(case: Case, options: SweepOptions) -> None:
    """Refuse ``--replicates`` for a case whose renderer is not the reference (the setting is the reference's),
    unless the list is just the case's own ``replicates`` setting: one line at ``--replicates``."""
    if options.replicates is None or case.renderer == "reference":
        return
    if [str(r) for r in options.replicates] != [case.settings.get("replicates")]:
        raise HarnessError("--replicates", f"is a setting of the reference renderer; case {case.name!r} renders with "
                           f"{case.renderer!r} (leave --replicates out or choose --cases of the reference)")


def sweep_configs(case: Case, options: SweepOptions) -> list[Case]:
    """The case at each configuration of the sweep (the product of its films, spp and replicates, in that order;
    a configuration that comes twice, such as ``half`` of an 8-pixel film, once): its film set explicitly, its spp
    (its ``seconds`` dropped) and its ``replicates`` setting (1 included: a suite gives the reference two unless
    told) where the sweep gives them, its ground truth's spp where the sweep gives one."""
    check_replicates(case, options)
    film = case_scene(case).film
    films = [sweep_film(case, item, film) for item in options.films]
    spps = options.spp or (None,)
    replicates = options.replicates if options.replicates and case.renderer == "reference" else (None,)
    configs, seen = [], set()
    for (width, height), spp, r in itertools.product(films, spps, replicates):
        changes: dict = {"film": {"width": width, "height": height}}
        if spp is not None:
            changes.update(spp=spp, seconds=None)
        if r is not None:
            changes["settings"] = {**case.settings, "replicates": str(r)}
        if options.ground_truth_spp is not None:
            changes["ground_truth_spp"] = options.ground_truth_spp
        config = dataclasses.replace(case, **changes)
        key = (width, height, config.spp, config.seconds, config.settings.get("replicates"))
        if key not in seen:
            seen.add(key)
            configs.append(config)
    return configs


def config_label(config: Case) -> str:
    """A configuration as the progress lines name it: ``cornell-box/reference 128x128 64 spp R=2``."""
    budget = f"{config.seconds:g} s" if config.seconds is not None else f"{config.spp} spp"
    replicates = config.settings.get("replicates")
    return (f"{config.name} {config.film['width']}x{config.film['height']} {budget}"
            + (f" R={replicates}" if replicates is not None else ""))


def _count_p(failures: int, runs: int, alpha: float, stats) -> float:
    """P(at least ``failures`` false alarms in ``runs`` | each one's probability is ``alpha``)."""
    return float(stats.binom.sf(failures - 1, runs, alpha)) if failures else 1.0


def _sweep_config(config: Case, out_dir: Path, seeds: int, cache_dir, variant, on_progress, stats) -> dict:
    """One configuration of a case: ``seeds`` renders through :func:`run_case` (the suite's very verdict and
    thresholds), their false alarms (status "fail") and errors, and each run's sub-tests' p-values."""
    detail, truth = [], {}
    for seed in range(seeds):
        record = run_case(dataclasses.replace(config, seed=seed), out_dir, cache_dir=cache_dir, variant=variant)
        truth = truth or record.get("ground_truth") or {}
        v = record.get("verdict") or {}
        detail.append({
            "seed": seed, "status": record.get("status"), "reason": str(record.get("reason") or "")[:200],
            "global_bias_p": (v.get("global_bias") or {}).get("p_value"),
            "omnibus_p": (v.get("omnibus") or {}).get("p_value"),
            "max_z_p": (v.get("max_z") or {}).get("p_value"),
        })
        if on_progress:
            on_progress(config_label(config), seed)
    false_alarms = sum(d["status"] == "fail" for d in detail)
    runs = sum(d["status"] in ("pass", "fail") for d in detail)  # an error or a skip judged nothing
    replicates = config.settings.get("replicates")
    return {
        "film": [config.film["width"], config.film["height"]], "spp": config.spp, "seconds": config.seconds,
        "replicates": int(replicates) if replicates is not None and replicates.isdigit() else None,
        # the ground truth's own spp where it has one (a Mitsuba render, another renderer's), None for a closed form
        "ground_truth_spp": (truth.get("spp") or config.ground_truth_spp) if truth.get("source") != "closed-form"
        else None,
        "ground_truth_source": truth.get("source"),
        "runs": runs, "errors": seeds - runs, "false_alarms": false_alarms, "alpha": config.alpha,
        "p_value_of_count": _count_p(false_alarms, runs, config.alpha, stats), "runs_detail": detail,
    }


def sweep(suite: Suite, out_dir: Path, *, seeds: int, patterns: list[str] | None, options: SweepOptions,
          cache_dir=None, variant=None, on_progress=None) -> dict:
    """The false-alarm sweep: each expect-pass case (those matching ``patterns``) at each configuration of
    :func:`sweep_configs`, ``seeds`` renders each (seeds 0 .. N-1), judged as the suite judges it; expect-fail
    cases are skipped (named under ``skipped``). Returns calibration.json's content: per case its runs and false
    alarms over all configurations (``cases``, as an unswept calibration has them) and ``sweep``: each
    configuration's count and the binomial probability of at least that many, and the totals (the probability of
    the total is that of the sum of each configuration's binomial count)."""
    from scipy import stats  # optional: 0.9 s; only calibrate's binomial tail (Boost's; scipy.special.bdtr differs)

    cases = select_cases(suite, patterns)
    runstate.refuse_links(out_dir, cases)  # a link planted in out_dir: one line, before the first render
    passing = [c for c in cases if c.expect == "pass"]
    planned = [(case, sweep_configs(case, options)) for case in passing]  # a bad option: one line, before rendering
    rows, swept, total_pmf = [], [], np.ones(1)
    for case, configs in planned:
        done = [_sweep_config(c, out_dir, seeds, cache_dir, variant, on_progress, stats) for c in configs]
        swept.append({"case": case.name, "renderer": case.renderer, "configs": done})
        runs, alarms = sum(c["runs"] for c in done), sum(c["false_alarms"] for c in done)
        rows.append({"case": case.name, "expect": "pass", "runs": runs, "passes": runs - alarms,
                     "false_alarms": alarms, "errors": sum(c["errors"] for c in done), "alpha": case.alpha,
                     "p_value_of_count": _count_p(alarms, runs, case.alpha, stats)})
        for c in done:  # the total's distribution: the sum of the configurations' binomial counts
            total_pmf = np.convolve(total_pmf, stats.binom.pmf(np.arange(c["runs"] + 1), c["runs"], c["alpha"]))
    runs = sum(r["runs"] for r in rows)
    alarms = sum(r["false_alarms"] for r in rows)
    expected = sum(c["runs"] * c["alpha"] for s in swept for c in s["configs"])
    p_total = min(1.0, float(total_pmf[alarms:].sum())) if alarms else 1.0
    return {"suite": suite.name, "seeds": seeds, "cases": rows, "sweep": {
        "films": ["x".join(map(str, f)) if isinstance(f, tuple) else f for f in options.films],
        "spp": list(options.spp) if options.spp else None,
        "replicates": list(options.replicates) if options.replicates else None,
        "ground_truth_spp": options.ground_truth_spp,
        "skipped": [f"{c.name} (expect = fail)" for c in cases if c.expect != "pass"],
        "cases": swept, "total": {"runs": runs, "false_alarms": alarms, "expected": expected, "p_value": p_total}}}


# ---- output ----------------------------------------------------------------------------------------------------


def summary_lines(result: dict) -> list[str]:
    """What ``harness calibrate`` prints: a line per case (false alarms, or how a fault failed), then the power
    table, or a sweep's table, its skipped cases and its totals."""
    lines = case_lines(result)
    table = power_table(result)
    if table:
        lines += ["", power_caption(result), *_plain_table(table)]
    table = sweep_table(result)
    if "sweep" in result:
        lines += ["", sweep_caption(result), *_plain_table(table, SWEEP_HEADERS), sweep_total_line(result)]
    return lines


def sweep_caption(result: dict) -> str:
    """One line saying what the sweep's table holds, and which cases it skipped."""
    skipped = (result.get("sweep") or {}).get("skipped") or []
    return (f"false-alarm sweep: {result.get('seeds')} seeds per configuration, each render judged as the suite "
            f"judges it (GT spp: the ground truth's)"
            + (f"; skipped: {', '.join(skipped)}" if skipped else ""))


def case_lines(result: dict) -> list[str]:
    """One line per case: an expect-pass case's false alarms, an expect-fail case's statistics."""
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


def _fmt(v, digits: int = 4) -> str:
    return f"{v:.{digits}g}" if isinstance(v, (int, float)) else str(v)


def _plain_table(rows: list[tuple[str, ...]], headers: tuple[str, ...] = POWER_HEADERS) -> list[str]:
    widths = [max(len(str(r[i])) for r in [headers, *rows]) for i in range(len(headers))]
    return ["  ".join(str(cell).ljust(w) for cell, w in zip(r, widths)).rstrip() for r in [headers, *rows]]


def markdown(result: dict) -> str:
    """calibration.md: the false alarms, the faults caught and the power table, as Markdown."""
    per = "configuration of each expect-pass case" if "sweep" in result else "expect-pass case"
    lines = [f"# Calibration: {result.get('suite')}", "", f"{result.get('seeds')} seeds per {per}.", ""]
    lines += [f"- {line}" for line in case_lines(result)]
    table = power_table(result)
    if table:
        lines += ["", "## Power", "", power_caption(result) + ".", "",
                  "| " + " | ".join(POWER_HEADERS) + " |", "|" + "---|" * len(POWER_HEADERS)]
        lines += ["| " + " | ".join(cell.replace("|", "\\|") for cell in r) + " |" for r in table]
        lines += ["", "Method: " + str((result.get("power") or {}).get("method", "")) + "."]
    if "sweep" in result:
        lines += ["", "## False-alarm sweep", "", sweep_caption(result) + ".", "",
                  *_markdown_table(sweep_table(result), SWEEP_HEADERS), "", sweep_total_line(result) + "."]
    return "\n".join(lines) + "\n"


def _markdown_table(rows: list[tuple[str, ...]], headers: tuple[str, ...]) -> list[str]:
    return ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers),
            *("| " + " | ".join(cell.replace("|", "\\|") for cell in r) + " |" for r in rows)]


def write(result: dict, path: Path) -> None:
    atomic_write_text(path, jsonsafe.dumps(result, indent=2))  # strict JSON: NaN / inf as null
