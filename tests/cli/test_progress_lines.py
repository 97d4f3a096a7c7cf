"""Progress where stderr is no terminal (a file, a CI log): the studies and the report print a line now and then
instead of nothing; ``--quiet`` prints none."""

from __future__ import annotations

import argparse
import io
import sys

from harness.cli import studies
from harness.core.progress import Progress


class _Clock:
    """A clock that moves only when told."""

    def __init__(self):
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_lines_where_stderr_is_no_terminal():
    """Off a terminal, a step that ends ``interval`` seconds after the last line prints one line naming itself and
    how far the task is; steps in between print nothing (a log gets a line every few seconds at most)."""
    out, clock = io.StringIO(), _Clock()
    progress = Progress(True, 3, "studies", stream=out, interval=10.0, clock=clock)
    clock.now = 12.0
    progress.step("convergence cornell-box 16 spp")
    clock.now = 13.0
    progress.step("convergence cornell-box 32 spp")
    progress.add(1)
    clock.now = 30.0
    progress.step("strategy rr=off")
    progress.close()
    assert out.getvalue().splitlines() == ["studies: [1/3] convergence cornell-box 16 spp (12 s)",
                                           "studies: [3/4] strategy rr=off (30 s)"]


def test_quiet_prints_nothing():
    out, clock = io.StringIO(), _Clock()
    progress = Progress(False, 2, "studies", stream=out, interval=0.0, clock=clock)
    clock.now = 100.0
    progress.step("x")
    progress.close()
    assert out.getvalue() == ""


def test_studies_show_progress_off_a_terminal(monkeypatch):
    """``harness run`` and ``harness report`` ask for progress unless ``--quiet``, whether or not stderr is a
    terminal (the bar or the lines are Progress's choice)."""
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert studies.progress(argparse.Namespace(quiet=False)) is True
    assert studies.progress(argparse.Namespace(quiet=True)) is False


def test_run_counts_cases_in_the_order_they_end(tmp_path, capfd):
    """With two workers cases end out of order; each line's [k/N] counts the cases ended so far, so the lines read
    1, 2, 3 whatever the order."""
    from test_hostile_input import SCENE, cli

    (tmp_path / "scene.toml").write_text(SCENE)
    case = '[[cases]]\nname = "c{}"\nscene = "scene.toml"\nspp = {}\nagainst = {{ renderer = "reference", spp = 2 }}\n'
    (tmp_path / "s.toml").write_text("".join(case.format(i, spp) for i, spp in enumerate((64, 2, 2))))
    code, _out, err = cli(capfd, "run", tmp_path / "s.toml", "--out", tmp_path / "out", "--no-report",
                          "--workers", "2")
    assert code == 0, err
    counts = [line.split("]")[0] for line in err.splitlines() if line.startswith("[")]
    assert counts == ["[1/3", "[2/3", "[3/3"], err
