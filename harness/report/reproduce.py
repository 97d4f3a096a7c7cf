"""The shell commands that reproduce a case of a run, from its record in results.json: ``harness render`` with the
case's scene, renderer, spp, seed, settings, film and depth, then ``harness compare`` of that render against the
ground truth the case was judged against, with the verdict's tile and alpha. Every word quoted with
:func:`shlex.quote`, so that the lines paste into a POSIX shell as they are. The report shows them in each case's
section (``case_reproduce.html.j2``) and keeps them in report.json (``reproduce``)."""

from __future__ import annotations

import shlex
from typing import Any

__all__ = ["RENDER_FILE", "reproduce"]

#: where the commands write the render (in the current folder)
RENDER_FILE = "render.exr"


def _number(value: Any) -> str:
    return repr(float(value)) if isinstance(value, float) else str(value)


def reproduce(record: dict) -> dict | None:
    """``{"render": [words], "compare": [words] | None, "text": the lines, "notes": [str]}`` for a case record;
    None where no command can be said (no scene or no spp known). ``notes`` say where the commands cannot give
    the run's very bits or numbers."""
    render = record.get("render") if isinstance(record.get("render"), dict) else {}
    budget = record.get("budget") if isinstance(record.get("budget"), dict) else {}
    spp = render.get("spp") or budget.get("spp")
    scene, renderer = record.get("scene"), record.get("renderer")
    if not isinstance(scene, str) or not scene or not isinstance(spp, int) or not isinstance(renderer, str):
        return None
    notes = []
    words = ["harness", "render", scene, "--renderer", renderer, "--spp", str(spp), "--seed", str(record.get("seed", 0))]
    for key, value in (record.get("settings") or {}).items():
        words += ["--set", f"{key}={value}"]
    film = record.get("film")
    if isinstance(film, dict) and isinstance(film.get("width"), int) and isinstance(film.get("height"), int):
        words += ["--film", f"{film['width']}x{film['height']}"]
    if isinstance(record.get("max_depth"), int):
        words += ["--max-depth", str(record["max_depth"])]
    info = render.get("info") if isinstance(render.get("info"), dict) else {}
    if renderer == "mitsuba":
        if isinstance(info.get("variant"), str) and "variant" not in (record.get("settings") or {}):
            words += ["--mitsuba-variant", info["variant"]]
        notes.append("Mitsuba is not bit-reproducible from run to run: the render is another realisation of the "
                     "same image (the run took it from the ground-truth cache).")
    words += ["--out", RENDER_FILE]
    if record.get("variant"):
        notes.append(f"The case renders its scene changed by the stress variant {record['variant']!r}, which "
                     "harness render cannot apply: the command renders the scene as its file holds it.")
    if "seconds" in budget:
        notes.append(f"A time budget: the run rendered {spp} spp in chunks within {budget['seconds']} s; the "
                     "command renders them at once (another realisation, the same expectation).")
    verdict = record.get("verdict") if isinstance(record.get("verdict"), dict) else {}
    gt = record.get("ground_truth") if isinstance(record.get("ground_truth"), dict) else {}
    compare = None
    if isinstance(gt.get("path"), str) and gt["path"] and verdict:
        compare = ["harness", "compare", RENDER_FILE, gt["path"], "--tile", str(verdict.get("tile", 8)),
                   "--alpha", _number(verdict.get("alpha", 0.001))]
        if gt.get("source") == "mitsuba" and isinstance(gt.get("spp"), int) and gt["spp"] >= 2:
            notes.append(f"The run gave the ground truth's variance {gt['spp'] - 1} degrees of freedom (its "
                         f"{gt['spp']} spp); the cache's EXR does not carry its spp, so harness compare takes that "
                         "variance as exact: its p-values may differ a little from the record's.")
    elif not gt.get("path"):
        notes.append("No ground-truth file is recorded for this case (an older run, or the case ended in an "
                     "error): only the render command is given.")
    if not scene.startswith("/"):
        notes.insert(0, f"The scene's path {scene} is relative: run the commands from the folder harness run was "
                        "run in.")
    lines = [shlex.join(words)] + ([shlex.join(compare)] if compare else [])
    return {"render": words, "compare": compare, "text": "\n".join(lines), "notes": notes}
