r"""Baselines: a suite run's per-case metrics saved to a JSON file, and later runs gated against it.

``harness baseline save SUITE --out FILE`` runs the suite (or takes an existing ``--from RESULTS.json``) and writes
the baseline; ``harness run SUITE --baseline FILE`` compares every case with its baseline entry after it ran and
fails (``ok = false``, exit code 1) a case whose metrics got worse than the baseline's by more than chance allows.
``docs/ci.md`` describes the file and the rules; in short:

*Noise metrics* (``rmse``, ``relmse``, ``mape``). Each is an image mean of a per-pixel error
:math:`u_p` (the channel mean of :math:`(t-r)^2`, :math:`(t-r)^2/(r^2+\varepsilon)`, :math:`|t-r|/(|r|+\varepsilon)`).
Pixels are independent estimates, so by the central limit theorem over the P pixels the metric m has relative
standard error :math:`s = \mathrm{sd}(u_p) / (\sqrt{P}\, m)`, estimated from the image itself (heavy-tailed,
firefly-prone pixels widen it, as they should).  Two renders of the same expected quality (e.g. a renderer change
that only reorders its random numbers) then have :math:`\log(m_1/m_0) \approx N(0, s_0^2 + s_1^2)`; the run
regresses when :math:`m_1 / m_0 > \exp(z_{1-a}\sqrt{s_0^2+s_1^2})` (one-sided; for ``rmse`` the square root of
the bound on the MSE).  Both errors share the same ground truth, which correlates them and narrows the true
spread, so the bound is conservative.  An unchanged seeded render is bit-identical: ratio 1, always passes.

*Bias*. The image mean of a channel moves between the baseline's render and the new one by
:math:`z_c = (\bar t_{1c} - \bar t_{0c}) / \sqrt{\sigma_{0c}^2 + \sigma_{1c}^2}` (the ground truth cancels;
:math:`\sigma` from each render's variance channels).  It regresses in channel c when :math:`|z_c| > z_{crit}`
(two-sided, Šidák over the three channels) *and* the new render's mean lies farther from the ground truth than the
baseline's (a fix that removes a bias is not a regression).

*Family*. The statistical checks of a case share the false-alarm probability ``alpha`` (default 1e-3 per case,
Bonferroni over the active checks: a = alpha / k).

*Factors*. A suite's ``[baseline]`` table or ``--baseline-tolerance KEY=VALUE`` replaces a rule by a fixed bound:
``relmse = 1.10`` (10 % worse allowed; also ``rmse``, ``mape``, ``flip``), ``seconds = 1.5`` (render time; and
``paths_per_second = 1.5``: 1.5 x fewer allowed), ``psnr = 0.5`` (dB drop), ``ssim = 0.01`` (drop), ``bias = 4``
(|z| bound of the shift), ``alpha = 1e-4``; ``off`` disables a check, ``auto`` restores the statistical rule.
Time checks are off by default: render time on a shared machine varies by more than any useful bound.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import platform
import time
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from harness.core import jsonsafe, system
from harness.core.errors import HarnessError, read_user_text
from harness.core.text import short
from harness.files.cases import confined_file, slug
from harness.files.imageio import atomic_write_text, read_exr
from harness.files.results import read_results
from harness.judges.distributions import normal_isf
from harness.judges.metrics import MAPE_EPS, RELMSE_EPS
from harness.renderers.groundtruth import scene_digest
from harness.running.judge import case_scene, ground_truth_for
from harness.running.schedule import summarise
from harness.running.tolerances import DEFAULT_ALPHA, NOISE_METRICS, option_tolerances, suite_tolerances

SCHEMA = "rendering-harness/baseline"
VERSION = 1
#: relative slack for values that carry no noise (a bit-identical render, float rounding of JSON round trips)
ROUNDING = 1e-9
CHANNELS = ("R", "G", "B")


# ---- what a baseline holds of a case -------------------------------------------------------------------------


def definition_hash(case) -> str:
    """SHA-256 over the *problem* a case poses: the loaded scene's content (with the case's film and depth), the
    budget, the ground truth it is compared with, and the verdict's tile and alpha. A baseline whose case differs in
    any of these measured another problem: comparing would be meaningless. Not the renderer, its settings or the
    seed: they are the solution under test, whose changes the baseline exists to judge (they are recorded in each
    entry and reported as changed). Not expect, metrics or thresholds either (they judge numbers, not make them)."""
    fields = {
        "scene": scene_digest(case_scene(case)), "spp": case.spp, "seconds": case.seconds,
        "chunk_spp": case.chunk_spp if case.spp is None else None, "against": dataclasses.asdict(case.against),
        "tile": case.tile, "alpha": case.alpha, "ground_truth_spp": case.ground_truth_spp,
    }
    return hashlib.sha256(json.dumps(fields, sort_keys=True, default=str).encode()).hexdigest()


def solution(case) -> dict:
    """What a case renders with: the part of its definition a baseline judges rather than requires equal."""
    return {"renderer": case.renderer, "settings": dict(case.settings), "seed": case.seed}


def image_statistics(test: np.ndarray, test_variance: np.ndarray | None, expected: np.ndarray) -> dict:
    """Per noise metric its value and relative standard error (CLT over pixels) against the ground truth
    ``expected``, and each channel's image mean with its standard error from the variance channels (and the
    ground truth's mean, under the key ``reference_mean``). Uses the pixels finite in both images, like
    :mod:`harness.judges.metrics`."""
    t = np.asarray(test, np.float64)
    r = np.asarray(expected, np.float64)
    mask = np.all(np.isfinite(t), axis=-1) & np.all(np.isfinite(r), axis=-1)
    n = int(mask.sum())
    tm, rm = t[mask], r[mask]
    d = tm - rm
    per_pixel = {
        "mse": np.mean(d**2, axis=1),
        "relmse": np.mean(d**2 / (rm**2 + RELMSE_EPS), axis=1),
        "mape": np.mean(np.abs(d) / (np.abs(rm) + MAPE_EPS), axis=1),
    }
    out: dict[str, Any] = {"pixels": n}
    for name, u in per_pixel.items():
        value = float(u.mean()) if n else float("nan")
        rel_se = float(u.std(ddof=1) / math.sqrt(n) / value) if n > 1 and value > 0 else None
        out[name] = {"value": value, "rel_se": rel_se}
    out["mean"] = [float(x) for x in tm.mean(axis=0)] if n else None
    out["reference_mean"] = [float(x) for x in rm.mean(axis=0)] if n else None
    if test_variance is not None and n:
        v = np.asarray(test_variance, np.float64)[mask]
        out["mean_stderr"] = [float(x) for x in np.sqrt(np.clip(v, 0, None).sum(axis=0)) / n]
    else:
        out["mean_stderr"] = None
    return out


def render_file(record: dict, run_dir: Path | None) -> Path:
    """The render EXR of a finished case's record. ``run_dir`` None: the record is this process's own (``harness
    run --baseline``), its path as written. Otherwise the record comes from a results.json in ``run_dir`` (``baseline
    save --from``), maybe written by someone else: the path it names is read only where it lies inside ``run_dir``
    after symlinks, else where harness run writes it there (``cases/<slug>/render.exr``: a run folder that was moved
    or copied); nothing outside the run folder is read. Neither: a one-line HarnessError."""
    named = record["render"]["exr"]
    if run_dir is None:
        exr = Path(named)
        if not exr.is_file():
            raise HarnessError(str(exr), f"case {record['name']!r}: its render is gone; expected the EXR the run "
                               "wrote")
        return exr
    problems: list[str] = []  # a note where the path it names lies outside the run folder
    written = Path(run_dir) / "cases" / slug(str(record["name"])) / "render.exr"  # where harness run writes it
    exr = confined_file(run_dir, "render.exr", named, written, problems)
    if exr is None:
        why = "names a file outside the run folder (not read)" if problems else "is gone"
        raise HarnessError(short(str(named), 300), f"case {record['name']!r}: its render {why}; expected the EXR "
                           f"harness run wrote inside the run folder {str(run_dir)!r}")
    return exr


def record_statistics(case, record: dict, *, cache_dir=None, variant=None, run_dir: Path | None = None) -> dict:
    """:func:`image_statistics` of a finished case: its render (:func:`render_file`) against its ground truth,
    fetched again through :func:`harness.running.judge.ground_truth_for` (the closed form, or the cache for Mitsuba;
    a ground truth made by another non-Mitsuba renderer is rendered again, seeded, so identical)."""
    test = read_exr(render_file(record, run_dir))
    gt = ground_truth_for(case, case_scene(case, for_ground_truth=True), cache_dir, variant)  # as run_case does
    return image_statistics(test.image, test.variance, gt.image)


def case_entry(case, record: dict, *, cache_dir=None, variant=None, run_dir: Path | None = None) -> dict:
    """What a baseline keeps of one finished case (only cases with a render: status pass or fail)."""
    v = record["verdict"]
    worst = v.get("worst_tile") or {}
    render = record["render"]
    return {
        "definition": definition_hash(case),
        "solution": solution(case),
        "status": record["status"], "expect": record["expect"], "ok": record["ok"],
        "metrics": record.get("metrics", {}),
        "verdict": {
            "verdict": v["verdict"], "global_bias_z": v["global_bias"].get("z"),
            "global_bias_p": v["global_bias"].get("p_value"), "omnibus_statistic": v["omnibus"].get("statistic"),
            "omnibus_dof": v["omnibus"].get("dof"), "omnibus_p": v["omnibus"].get("p_value"),
            "max_z": v["max_z"].get("statistic"), "max_z_p": v["max_z"].get("p_value"),
            "worst_tile": {k: worst.get(k) for k in ("y", "x", "channel", "z")} if worst else None,
        },
        "render": {"seconds": render["seconds"], "spp": render["spp"], "paths_per_second": render["paths_per_second"]},
        "ground_truth": {k: record.get("ground_truth", {}).get(k) for k in ("source", "spp", "variant",
                                                                             "mitsuba_version")},
        "statistics": record_statistics(case, record, cache_dir=cache_dir, variant=variant, run_dir=run_dir),
    }


def tool_versions(results: dict | None = None) -> dict:
    def version(name: str) -> str | None:
        try:
            return metadata.version(name)
        except metadata.PackageNotFoundError:
            return None

    variants = sorted({c.get("ground_truth", {}).get("variant") for c in (results or {}).get("cases", [])} - {None})
    return {
        "harness": version("rendering-harness"), "python": platform.python_version(), "numpy": version("numpy"),
        "numba": version("numba"), "embreex": version("embreex"), "mitsuba": version("mitsuba"),
        "mitsuba_variants": variants, "machine": platform.machine(), "node": platform.node(),
    }


# ---- saving and loading ----------------------------------------------------------------------------------------


def build(suite, results: dict, *, cache_dir=None, variant=None, source: str = "run",
          run_dir: Path | None = None) -> tuple[dict, list[str]]:
    """The baseline document of a finished run of ``suite``, and notes on cases left out (no render); ``run_dir``:
    the folder of a results.json read back (``--from``), whose renders are read only inside it
    (:func:`render_file`)."""
    records = {r["name"]: r for r in results.get("cases", [])}
    cases, notes = {}, []
    for case in suite.cases:
        record = records.get(case.name)
        if record is None:
            notes.append(f"{case.name}: not in the run; left out")
            continue
        if record.get("status") not in ("pass", "fail") or "render" not in record:
            notes.append(f"{case.name}: status {record.get('status')} ({record.get('reason', '')}); left out")
            continue
        cases[case.name] = case_entry(case, record, cache_dir=cache_dir, variant=variant, run_dir=run_dir)
    doc = {
        "schema": SCHEMA, "version": VERSION, "suite": suite.name, "suite_file": str(suite.path),
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "source": source, "tools": tool_versions(results),
        # the machine of the run it was made from (that run's own block; a run by an older harness: this one)
        "system": results.get("system") if isinstance(results.get("system"), dict) else system.gather(variant),
        "cases": cases,
    }
    return doc, notes


def save(doc: dict, path: str | Path) -> Path:
    return atomic_write_text(path, jsonsafe.dumps(doc, indent=2) + "\n")


def load(path: str | Path) -> dict:
    """A baseline file, checked: one-line HarnessError naming the file for anything that is not one."""
    label = str(path)
    text = read_user_text(path, missing="no such baseline file (write one with: harness baseline save SUITE --out FILE)")
    try:
        doc = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as err:  # RecursionError: absurd nesting
        raise HarnessError(label, f"not a baseline file: invalid JSON ({err})") from None
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        raise HarnessError(label, f"not a baseline file: expected \"schema\": \"{SCHEMA}\"")
    if doc.get("version") != VERSION:
        raise HarnessError(label, f"baseline version {doc.get('version')!r}; this harness reads version {VERSION}: "
                           "save a new one")
    if not isinstance(doc.get("cases"), dict) or not isinstance(doc.get("suite"), str):
        raise HarnessError(label, "not a baseline file: expected \"suite\" and a \"cases\" table")
    for key, kind, what in (("tools", dict, "a table of tool versions"), ("created", str, "a time stamp"),
                            ("source", str, "a text"), ("system", dict, "a table of the machine and software")):
        if key in doc and not isinstance(doc[key], kind):
            raise HarnessError(label, f"not a baseline file: {key}: expected {what}, got {short(doc[key])}; "
                               "save the baseline again")
    for name, entry in doc["cases"].items():
        problem = _entry_problem(entry)
        if problem:
            raise HarnessError(label, f"not a baseline file: cases.{name}{problem}; save the baseline again")
    return doc


def _finite(value) -> bool:
    """A JSON number that is finite as a float (an integer beyond float's range is not)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


#: the largest relative standard error a baseline's mean of per-pixel errors can have, with room for rounding: for
#: n >= 2 non-negative values the sample standard deviation is at most sqrt(n) times their mean (equality: one
#: value non-zero), so std / sqrt(n) / mean <= 1; a larger one is a damaged file (and overflowed the noise bound)
MAX_REL_SE = 1.0 + 1e-6


def _entry_problem(entry) -> str | None:
    """What is wrong with one case entry of a baseline file, as ``.KEY: expected ...`` (None: nothing): every
    value :func:`compare` reads must be there with its type, so a damaged file is refused before the run."""
    if not isinstance(entry, dict):
        return f": expected a table, got {type(entry).__name__}"
    if not isinstance(entry.get("definition"), str):
        return ".definition: expected the case's SHA-256 (a string)"
    for key in ("metrics", "statistics", "render", "solution"):
        if not isinstance(entry.get(key), dict):
            return f".{key}: expected a table"
    for key, value in entry["metrics"].items():
        if not (value is None or (isinstance(value, dict) and key == "bias") or _finite(value)):
            return f".metrics.{key}: expected a finite number, got {value!r:.40}"
    statistics = entry["statistics"]
    for key in ("mse", "relmse", "mape"):
        item = statistics.get(key, {})
        if not isinstance(item, dict) or not all(item.get(k) is None or _finite(item.get(k)) for k in ("value",
                                                                                                        "rel_se")):
            return f".statistics.{key}: expected {{value, rel_se}} finite numbers"
        rel_se = item.get("rel_se")
        if rel_se is not None and not 0 <= rel_se <= MAX_REL_SE:
            return (f".statistics.{key}.rel_se: expected a relative standard error from 0 to {MAX_REL_SE:g}, got "
                    f"{rel_se!r:.40}")
    for key in ("mean", "mean_stderr", "reference_mean"):
        value = statistics.get(key)
        if value is not None and not (isinstance(value, list) and len(value) == len(CHANNELS)
                                      and all(_finite(v) for v in value)):
            return f".statistics.{key}: expected {len(CHANNELS)} finite numbers"
    for key in ("seconds", "paths_per_second"):
        if not _finite(entry["render"].get(key)):
            return f".render.{key}: expected a finite number"
    return None


def check_matches(doc: dict, path: str | Path, suite) -> None:
    """A baseline must be for this suite's content: same suite name, and every case it shares with the suite
    defined the same way (:func:`definition_hash`); else a one-line HarnessError naming the file."""
    if doc["suite"] != suite.name:
        raise HarnessError(str(path), f"baseline of suite {doc['suite']!r}, not of {suite.name!r} ({suite.path}); "
                           "save one for this suite with: harness baseline save")
    for case in suite.cases:
        entry = doc["cases"].get(case.name)
        if entry is not None and entry.get("definition") != definition_hash(case):
            raise HarnessError(str(path), f"case {case.name!r} was saved for another content (its scene, film, "
                               "budget, reference or verdict tile/alpha changed since); save the baseline again")


# ---- comparing -------------------------------------------------------------------------------------------------


def _z_one_sided(a: float) -> float:
    return float(normal_isf(a))


def _worse(new: float, bound: float) -> bool:
    return new > bound * (1 + ROUNDING) + 1e-300


def _check(checks: list, ok: bool, reason: str, **fields) -> None:
    """Record one check (``fields`` then ``ok``); a failed one also gets its one-line ``reason``."""
    checks.append({**fields, "ok": ok})
    if not ok:
        checks[-1]["reason"] = f"baseline: {reason}"


def compare(base: dict, new: dict, tolerance: dict[str, float | str]) -> dict:
    """Compare a case's new entry with its baseline entry. Returns ``{"checks": [...], "regressions": [...]}``:
    every check made (metric, rule, values, bound, ok) and a one-line reason per regression."""
    checks: list[dict] = []
    active_stat = [k for k in (*NOISE_METRICS, "bias") if tolerance.get(k) == "auto"]
    a = float(tolerance.get("alpha", DEFAULT_ALPHA)) / max(len(active_stat), 1)
    bs, ns = base["statistics"], new["statistics"]

    for name in NOISE_METRICS:
        rule = tolerance.get(name, "off")
        key = "mse" if name == "rmse" else name
        b, n = bs.get(key, {}), ns.get(key, {})
        if rule == "off" or b.get("value") is None or n.get("value") is None:
            continue
        power = 0.5 if name == "rmse" else 1.0  # rmse = mse ** 0.5
        b_val, n_val = b["value"] ** power, n["value"] ** power
        if rule == "auto":
            spread = math.hypot(b.get("rel_se") or 0.0, n.get("rel_se") or 0.0)
            factor = math.exp(_z_one_sided(a) * spread * power)
            how = f"noise bound, alpha {a:.2g}"
        else:
            factor, how = float(rule), "tolerance"
        _check(checks, not _worse(n_val, factor * b_val), f"{name} {n_val:.4g} > {factor:.3g} x {b_val:.4g} ({how})",
               metric=name, rule=rule if rule != "auto" else "statistical", baseline=b_val, value=n_val, factor=factor)

    rule = tolerance.get("bias", "off")
    if rule != "off" and bs.get("mean") and ns.get("mean"):
        if rule == "auto":
            bound = _z_one_sided(-math.expm1(math.log1p(-a) / 3) / 2)  # Šidák over 3 channels, two-sided
        else:
            bound = float(rule)
        b_se, n_se = bs.get("mean_stderr") or [0.0] * 3, ns.get("mean_stderr") or [0.0] * 3
        truth = ns.get("reference_mean") or bs.get("reference_mean")  # the ground truth's mean
        for c, channel in enumerate(CHANNELS[: len(ns["mean"])]):
            shift = ns["mean"][c] - bs["mean"][c]
            se = math.hypot(b_se[c], n_se[c])
            exact = abs(shift) <= ROUNDING * max(abs(ns["mean"][c]), abs(bs["mean"][c])) + 1e-300
            z = 0.0 if exact else (shift / se if se > 0 else math.copysign(math.inf, shift))
            farther = abs(ns["mean"][c] - truth[c]) > abs(bs["mean"][c] - truth[c])
            _check(checks, abs(z) <= bound or not farther,
                   f"bias in {channel}: mean {bs['mean'][c]:.5g} -> {ns['mean'][c]:.5g} (reference {truth[c]:.5g}), "
                   f"shift z = {z:.2f}, |z| > {bound:.2f}",
                   metric=f"bias.{channel}", rule="statistical" if rule == "auto" else "tolerance",
                   baseline=bs["mean"][c], value=ns["mean"][c], reference=truth[c], z=z, bound=bound)

    for name in ("flip", "psnr", "ssim"):
        rule = tolerance.get(name, "off")
        b_val, n_val = base["metrics"].get(name), new["metrics"].get(name)
        if rule == "off" or b_val is None or n_val is None:
            continue
        if name == "flip":
            ok, text = not _worse(n_val, rule * b_val), f"{name} {n_val:.4g} > {rule:.3g} x {b_val:.4g}"
        else:
            ok = n_val >= b_val - rule - ROUNDING * abs(b_val)
            text = f"{name} {n_val:.4g} < {b_val:.4g} - {rule:.3g}"
        _check(checks, ok, text, metric=name, rule="tolerance", baseline=b_val, value=n_val, tolerance=rule)

    rule = tolerance.get("seconds", "off")
    if rule != "off":
        b_val, n_val = base["render"]["seconds"], new["render"]["seconds"]
        _check(checks, not _worse(n_val, rule * b_val), f"seconds {n_val:.3g} > {rule:.3g} x {b_val:.3g}",
               metric="seconds", rule="tolerance", baseline=b_val, value=n_val, factor=rule)
    rule = tolerance.get("paths_per_second", "off")
    if rule != "off":
        b_val, n_val = base["render"]["paths_per_second"], new["render"]["paths_per_second"]
        _check(checks, n_val * rule * (1 + ROUNDING) >= b_val, f"paths_per_second {n_val:.4g} < {b_val:.4g} / {rule:.3g}",
               metric="paths_per_second", rule="tolerance", baseline=b_val, value=n_val, factor=rule)
    return {"checks": checks, "regressions": [c["reason"] for c in checks if not c["ok"]]}


class Gate:
    """A run's baseline gate: loaded and matched to the suite before the run (bad input: exit 2 before any
    render), then :meth:`check` after each case and :meth:`finish` after the run."""

    def __init__(self, path: str | Path, suite, *, tolerance_options: list[str] | None = None, cache_dir=None,
                 variant=None):
        self.path = Path(path)
        self.suite = suite
        self.doc = load(path)
        check_matches(self.doc, path, suite)
        self.tolerance = option_tolerances(tolerance_options or [], suite_tolerances(suite))
        self.cache_dir, self.variant = cache_dir, variant
        #: what differs between the machine the baseline was made on and this one ([]: the same, or unknown)
        self.other_machine = machine_differences(self.doc, system.gather(variant))
        self.missing: list[str] = []
        self.regressed: list[str] = []
        self.compared: list[str] = []
        self.checked: set[str] = set()

    def warning(self) -> str | None:
        """The one line to print before the run when the baseline was made on another machine, else None."""
        if not self.other_machine:
            return None
        return (f"harness: warning: baseline {self.path} was made on another machine ({'; '.join(self.other_machine)})"
                ": its timings are that machine's, and bits may differ with the CPU")

    def check(self, case, record: dict) -> None:
        """Compare a finished case with its baseline entry; a regression makes it ``ok = false`` with the reason
        (``record["baseline"]`` holds every check, and the outcome before it, so that a record resumed from an
        earlier run is judged afresh against this baseline)."""
        earlier = record.get("baseline")
        if isinstance(earlier, dict) and "ok_before" in earlier:
            record["ok"], record["reason"] = earlier["ok_before"], earlier["reason_before"]
        before = {"ok_before": record.get("ok"), "reason_before": record.get("reason", "")}
        self.checked.add(case.name)
        self._check(case, record)
        record["baseline"].update(before)

    def _check(self, case, record: dict) -> None:
        entry = self.doc["cases"].get(case.name)
        if entry is None:
            self.missing.append(case.name)
            record["baseline"] = {"compared": False, "note": "not in the baseline (not failed)"}
            return
        if case.expect != "pass":
            record["baseline"] = {"compared": False, "note": "expect = fail: judged by its verdict only"}
            return
        if record.get("status") not in ("pass", "fail") or "render" not in record:
            record["baseline"] = {"compared": False, "note": f"status {record.get('status')}: nothing to compare"}
            return
        try:
            new = case_entry(case, record, cache_dir=self.cache_dir, variant=self.variant)
        except HarnessError:
            raise
        except Exception as err:  # noqa: BLE001 - a comparison that cannot be made fails this case only
            record.update(ok=False, reason="; ".join(filter(None, [record.get("reason"), f"baseline: cannot compare: "
                                                                   f"{type(err).__name__}: {err}"])))
            record["baseline"] = {"compared": False, "note": "comparison failed"}
            self.regressed.append(case.name)
            return
        outcome = compare(entry, new, self.tolerance)
        self.compared.append(case.name)
        changed = {k: {"baseline": entry.get("solution", {}).get(k), "now": v} for k, v in new["solution"].items()
                   if entry.get("solution", {}).get(k) != v}
        record["baseline"] = {"compared": True, "file": str(self.path), "changed": changed, **outcome}
        if outcome["regressions"]:
            self.regressed.append(case.name)
            record["ok"] = False
            record["reason"] = "; ".join(filter(None, [record.get("reason"), *outcome["regressions"]]))

    def finish(self, results: dict, out_dir: Path) -> list[str]:
        """Recompute the run's summary with the baseline outcomes, record them in ``results.json`` (rewritten
        atomically) and return the lines to print."""
        by_name = {c.name: c for c in self.suite.cases}
        for record in results["cases"]:  # cases resumed from an earlier run were not seen by check()
            if record["name"] not in self.checked and record["name"] in by_name:
                self.check(by_name[record["name"]], record)
        results["summary"] = summarise(results["cases"], results["summary"]["wall_seconds"])
        base_tools = self.doc.get("tools", {})
        now = tool_versions(results)
        changed = [f"{k} {base_tools.get(k)} -> {now.get(k)}" for k in ("mitsuba", "mitsuba_variants", "numpy")
                   if base_tools.get(k) != now.get(k)]
        results["baseline"] = {"file": str(self.path), "created": self.doc.get("created"),
                               "tolerance": self.tolerance, "compared": self.compared, "regressed": self.regressed,
                               "not_in_baseline": self.missing, "tools_changed": changed,
                               "system": self.doc.get("system"), "other_machine": self.other_machine}
        atomic_write_text(out_dir / "results.json", jsonsafe.dumps(results, indent=2))
        lines = [f"baseline {self.path}: {len(self.compared)} cases compared, {len(self.regressed)} regressed"]
        if self.missing:
            lines.append(f"  not in the baseline (reported, not failed): {', '.join(self.missing)}")
        if changed:
            lines.append(f"  note: tools changed since the baseline: {'; '.join(changed)}")
        if self.other_machine:
            lines.append(f"  note: the baseline was made on another machine: {'; '.join(self.other_machine)}")
        return lines


def machine_differences(doc: dict, now: dict) -> list[str]:
    """What differs between the machine a baseline file was made on (its ``system`` block; a file saved by an
    older harness: the ``node`` of its ``tools``) and ``now`` (:func:`harness.core.system.machine_differences`)."""
    before = doc.get("system")
    if not isinstance(before, dict):
        tools = doc.get("tools") if isinstance(doc.get("tools"), dict) else {}
        before = {"node": tools["node"]} if isinstance(tools.get("node"), str) else None
    return system.machine_differences(before, now)


# ---- a results.json as the source of a baseline ---------------------------------------------------------


def read_suite_results(path: str | Path, suite) -> dict:
    """``path`` (a results.json, given as ``--from``) checked against its schema and against ``suite``: the same
    cases, each run with the renderer, settings, seed and budget the suite defines now."""
    label = str(path)
    results = read_results(path, where=f"--from {label}")  # checked: a malformation names its JSON path
    if results.get("suite") != suite.name:
        raise HarnessError(f"--from {label}", f"results of suite {results.get('suite')!r}, not {suite.name!r}")
    by_name = {c.name: c for c in suite.cases}
    for record in results["cases"]:
        case = by_name.get(record.get("name"))
        if case is None:
            raise HarnessError(f"--from {label}", f"case {record.get('name')!r} is not in {suite.path}")
        budget = {"spp": case.spp} if case.spp is not None else {"seconds": case.seconds}
        same = (record.get("renderer"), record.get("settings"), record.get("seed"), record.get("budget")) == (
            case.renderer, case.settings, case.seed, budget)
        if not same:
            raise HarnessError(f"--from {label}", f"case {case.name!r} was run with another renderer, settings, seed "
                               f"or budget than {suite.path} defines now")
    return results
