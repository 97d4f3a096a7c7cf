"""Notes the page writes on a case beyond its outcome: warnings the run recorded in the case's record
(docs/report.md, "Per case")."""

from __future__ import annotations

from typing import Any


def case_notes(record: dict[str, Any]) -> list[str]:
    """Warnings to show on a case: a ground truth whose own noise is more than 1/4 of the test render's
    (``ground_truth_noise.warning``, docs/results-schema.md), which blunts the verdict, and a Mitsuba ground truth
    known not to be the scene's expected image (``ground_truth_caveat``)."""
    notes = []
    noise = record.get("ground_truth_noise")
    warning = noise.get("warning") if isinstance(noise, dict) else None
    if isinstance(warning, str) and warning:
        notes.append(f"Ground truth too noisy: {warning}")
    caveat = record.get("ground_truth_caveat")
    if isinstance(caveat, str) and caveat:
        notes.append(f"Ground truth not the expected image: {caveat}")
    return notes
