"""``harness bench``'s fresh-process race: ``harness render`` as a user runs it, each render a new process.

For one scene, in each round the reference (at its defaults) and Mitsuba ``llvm_ad_rgb`` (its plain ``path`` or
``volpath`` integrator in one pass, ``--set moments=off``, with its default ``independent`` sampler: the warm race's
``mitsuba llvm_ad_rgb`` row) each run

    python -m harness render SCENE --spp N --seed R --json --quiet --out TMP.exr [--film WxH] [renderer options]

in a new process, the two taking turns (A B A B ...), after one untimed warm-up process each, so that numba's and
Dr.Jit's on-disk kernel caches are filled as for a user's second run. The EXRs go to a temporary folder, removed
afterwards. Per process (:func:`run_once`):

- ``seconds``: the render time the process's JSON reports (the renderer's own clock). The reference's covers the
  render alone: its compiled kernels are loaded from numba's cache before its clock starts, and reported apart as
  ``load_seconds`` (``reference_impl.integrator._load_kernels``). Mitsuba's covers its ``mi.render`` calls: Dr.Jit
  tracing the integrator into a kernel, finding that kernel in its on-disk cache (compiling it with LLVM on a cache
  miss) and running it; the scene's loading (``mi.load_dict``) and the imports are outside it;
- ``wall_seconds``: the process's wall time, from its start to its exit (the interpreter, the imports, the scene, the
  kernels' loading, the render, the EXR and PNG written), as this process's ``time.perf_counter`` sees it;
- ``startup_seconds`` = ``wall_seconds`` - ``seconds``: everything a user waits for that is not the render.

The ratio ``fresh_seconds_vs_llvm_ad_rgb`` = Mitsuba's render seconds / the reference's: 0.5 or more is "within 2x of
Mitsuba's fresh-process time". Its 95 % interval is :func:`harness.judges.efficiency.ratio_interval` over the rounds
(the ratio of the mean seconds, as the warm race's paths/s ratio). A process that fails (an exit code other than 0,
output that is not ``harness render``'s JSON, no exit within :data:`TIMEOUT_SECONDS`) ends its contender's race: a
skipped entry with the reason in one line, not a traceback.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from harness.judges.efficiency import LEVEL, ratio_interval

#: the folder that holds the ``harness`` package, put first on the children's PYTHONPATH: they run this harness
PACKAGE_ROOT = Path(__file__).resolve().parents[2]
#: the most seconds one process may take before it is stopped and its contender skipped
TIMEOUT_SECONDS = 600
REFERENCE, MITSUBA = "reference", "mitsuba llvm_ad_rgb"
#: the ratio's key: Mitsuba's fresh render seconds over the reference's
RATIO = "fresh_seconds_vs_llvm_ad_rgb"


def contenders(spp: int) -> dict[str, list[str]]:
    """Each contender's options of ``harness render`` beyond the scene, spp, seed and output."""
    return {REFERENCE: ["--renderer", "reference"],
            MITSUBA: ["--renderer", "mitsuba", "--mitsuba-variant", "llvm_ad_rgb", "--set", "moments=off",
                      "--set", f"chunk_spp={spp}"]}


def command(scene_path: str | Path, spp: int, seed: int, out: Path, options: Sequence[str],
            film: tuple[int, int] | None = None) -> list[str]:
    """The argv of one fresh render: ``python -m harness render ...`` with this interpreter."""
    argv = [sys.executable, "-m", "harness", "render", str(scene_path), "--spp", str(spp), "--seed", str(seed),
            "--json", "--quiet", "--out", str(out), *options]
    if film is not None:
        argv += ["--film", f"{film[0]}x{film[1]}"]
    return argv


class FreshRunError(Exception):
    """A fresh render that did not give its JSON: the message is one line, the reason."""


def _last_line(text: str) -> str:
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return lines[-1] if lines else "no output"


def run_once(argv: Sequence[str], *, timeout: float = TIMEOUT_SECONDS) -> dict:
    """Run one fresh render; {seconds, load_seconds, wall_seconds, startup_seconds}, or FreshRunError saying why
    not (its exit code and the last line of its standard error; a timeout; output that is not the JSON)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(PACKAGE_ROOT), env.get("PYTHONPATH")]))
    start = time.perf_counter()
    try:
        proc = subprocess.run(list(argv), capture_output=True, text=True, env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise FreshRunError(f"no exit within {timeout:g} s") from None
    except OSError as err:
        raise FreshRunError(f"could not start: {err}") from None
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise FreshRunError(f"exit code {proc.returncode}: {_last_line(proc.stderr)}")
    try:
        summary = json.loads(proc.stdout)
        seconds = float(summary["seconds"])
    except (ValueError, KeyError, TypeError):
        raise FreshRunError(f"its output is not harness render's JSON: {_last_line(proc.stdout)}") from None
    load = summary.get("load_seconds")
    return {"seconds": seconds, "load_seconds": float(load) if load is not None else None, "wall_seconds": wall,
            "startup_seconds": wall - seconds}


def _median(values: Sequence[float | None]) -> float | None:
    kept = [v for v in values if v is not None and math.isfinite(v)]
    return statistics.median(kept) if kept else None


def fresh_race(scene_path: str | Path, *, spp: int, rounds: int, film: tuple[int, int] | None = None,
               seed: int = 1, on_render: Callable[[str], None] | None = None,
               run: Callable[..., dict] | None = None, level: float = LEVEL) -> dict:
    """The race of the module docstring on ``scene_path`` (at ``spp``, ``film`` replacing the scene's film where
    given): one warm-up process per contender, then ``rounds`` rounds, the contenders taking turns, seed ``seed`` +
    round. ``run(argv)`` runs one process (default :func:`run_once`, looked up when called: a test's fake).

    Returns {"spp", "rounds", "film", "command" (the reference's argv, its output file named ``OUT.exr``),
    "contenders": {label: {"options", "seconds_all", "load_seconds_all", "wall_seconds_all",
    "startup_seconds_all", "seconds", "load_seconds", "wall_seconds", "startup_seconds" (the medians), "error"}},
    "ratios": {RATIO: median ratio}, "ratio_intervals": {RATIO: interval}}; no ratio where a contender failed."""
    run = run or run_once
    options = contenders(spp)
    entries = {label: {"options": list(opts), "seconds_all": [], "load_seconds_all": [], "wall_seconds_all": [],
                       "startup_seconds_all": [], "error": None} for label, opts in options.items()}
    with tempfile.TemporaryDirectory(prefix="harness-bench-fresh-") as folder:
        for attempt in range(rounds + 1):  # attempt 0: the warm-up
            for label, entry in entries.items():
                if entry["error"]:
                    continue
                out = Path(folder) / f"{label.replace(' ', '-')}-{attempt}.exr"
                try:
                    measured = run(command(scene_path, spp, seed + attempt, out, entry["options"], film))
                except FreshRunError as err:
                    entry["error"] = ("warm-up: " if attempt == 0 else f"round {attempt}: ") + str(err)
                    continue
                if on_render is not None:
                    on_render(f"{Path(scene_path).stem}: {label} in a fresh process"
                              + (" (warm-up)" if attempt == 0 else ""))
                if attempt == 0:
                    continue
                for key in ("seconds", "load_seconds", "wall_seconds", "startup_seconds"):
                    entry[f"{key}_all"].append(measured[key])
    for entry in entries.values():
        for key in ("seconds", "load_seconds", "wall_seconds", "startup_seconds"):
            entry[key] = _median(entry[f"{key}_all"])
    result = {"spp": spp, "rounds": rounds, "film": list(film) if film else None,
              "command": command(scene_path, spp, seed + 1, Path("OUT.exr"), options[REFERENCE], film),
              "contenders": entries, "ratios": {}, "ratio_intervals": {}}
    ref, mitsuba = entries[REFERENCE], entries[MITSUBA]
    if not ref["error"] and not mitsuba["error"] and ref["seconds"] and mitsuba["seconds"] is not None:
        result["ratios"][RATIO] = mitsuba["seconds"] / ref["seconds"]
        result["ratio_intervals"][RATIO] = ratio_interval((mitsuba["seconds_all"],), (ref["seconds_all"],), level)
    return result


def _cell(value: float | None, width: int) -> str:
    return f"{value:{width}.3f}" if value is not None else f"{'n/a':>{width}}"


def format_fresh(fresh: dict) -> str:
    """The lines under a scene's table: per contender the medians of render, start-up and wall seconds (and the
    reference's kernel load), or why it was skipped; then the ratio with its interval."""
    film = f" at {fresh['film'][0]}x{fresh['film'][1]}" if fresh.get("film") else ""
    lines = [f"fresh processes (harness render{film}, {fresh['spp']} spp, median of {fresh['rounds']} rounds after "
             f"a warm-up each, taking turns):",
             f"  {'contender':<22} {'render s':>9} {'start-up s':>10} {'wall s':>8} {'kernel load s':>13}"]
    for label, entry in fresh["contenders"].items():
        if entry.get("error"):
            lines.append(f"  {label:<22} skipped: {entry['error']}")
            continue
        lines.append(f"  {label:<22} {_cell(entry['seconds'], 9)} {_cell(entry['startup_seconds'], 10)} "
                     f"{_cell(entry['wall_seconds'], 8)} {_cell(entry['load_seconds'], 13)}")
    interval = (fresh.get("ratio_intervals") or {}).get(RATIO)
    if interval is not None and interval.get("value") is not None:
        bound = (f" [{interval['low']:.3g}, {interval['high']:.3g}]" if interval.get("low") is not None else "")
        lines.append(f"  {RATIO} (Mitsuba's render s / the reference's, >= 0.5: within 2x): "
                     f"{interval['value']:.3g}{bound}, {interval.get('level', LEVEL):.0%} interval over the rounds")
    elif RATIO in (fresh.get("ratios") or {}):
        lines.append(f"  {RATIO}: {fresh['ratios'][RATIO]:.3g}")
    else:
        lines.append(f"  {RATIO}: not measured")
    return "\n".join(lines)
