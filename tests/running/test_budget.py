"""Time budgets (harness/running/budget.py): chunks until the render time is spent, and a wall-time limit for a
renderer whose chunks read 0 s (an external renderer whose render time, start-up excluded, is below what can be
timed), which would otherwise never spend its budget."""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np

from harness.renderers.base import RenderResult
from harness.running import budget


class ZeroTime:
    """A renderer whose every chunk reports 0 s of render time."""

    name = "zero"

    def __init__(self):
        self.calls = 0

    def render(self, scene, request):
        self.calls += 1
        image = np.full((2, 2, 3), 0.5, np.float32)
        return RenderResult("zero", image, np.full_like(image, 0.01), 0.0, request.spp, {"camera": 4}, {}, {})


def test_a_budget_that_render_time_never_spends_stops_at_the_wall_limit(monkeypatch):
    monkeypatch.setattr(budget, "wall_limit", lambda seconds: 0.05)
    renderer = ZeroTime()
    merged = budget.render_for_seconds(renderer, SimpleNamespace(), 1.0, 2, itertools.count(), {})
    assert renderer.calls >= 1 and merged.spp == 2 * renderer.calls and merged.seconds == 0.0


def test_the_wall_limit_is_far_above_the_budget():
    assert budget.wall_limit(0.5) == 65.0 and budget.wall_limit(100) == 1060.0
