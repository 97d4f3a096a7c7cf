"""Links planted in a run's output folder (issue 32): a symbolic link at ``OUT/.lock`` is neither written through nor
removed by ``run``, ``calibrate`` or ``baseline save --run-out``."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from test_hostile_input import SCENE, assert_one_line, cli, listing

from harness.core.errors import HarnessError
from harness.running import runstate

SUITE = """
name = "two"
[defaults]
spp = 2
against = { renderer = "reference", spp = 16 }

[[cases]]
name = "a"
scene = "scene.toml"

[[cases]]
name = "b"
scene = "scene.toml"
seed = 3
"""
VICTIM = "the victim's own bytes\n"


@pytest.fixture
def folder(tmp_path) -> Path:
    """tmp/scene.toml (a valid 16 x 16 scene), tmp/two.toml (a suite of two cases), tmp/victim.txt and the empty
    folder tmp/outside: what a planted link points at."""
    (tmp_path / "scene.toml").write_text(SCENE)
    (tmp_path / "two.toml").write_text(SUITE)
    (tmp_path / "victim.txt").write_text(VICTIM)
    (tmp_path / "outside").mkdir()
    return tmp_path


def untouched(folder: Path) -> None:
    """The victim file keeps its bytes and the outside folder stays empty."""
    assert (folder / "victim.txt").read_text() == VICTIM
    assert listing(folder / "outside") == []


# ---- item 2: OUT/.lock ---------------------------------------------------------------------------------------------


COMMANDS = {
    "run": ("run", "{suite}", "--out", "{out}", "--executor", "serial", "--quiet", "--no-report"),
    "calibrate": ("calibrate", "{suite}", "--out", "{out}", "--seeds", "1", "--no-power", "--quiet"),
    "baseline": ("baseline", "save", "{suite}", "--run-out", "{out}", "--out", "{base}", "--quiet"),
}


@pytest.mark.slow  # on a harness that follows the link the suite renders
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_link_at_the_lock_is_neither_followed_nor_removed(folder, capfd, command):
    out = folder / "out"
    out.mkdir()
    (out / ".lock").symlink_to(folder / "victim.txt")
    argv = [a.format(suite=folder / "two.toml", out=out, base=folder / "base.json") for a in COMMANDS[command]]
    assert_one_line(*cli(capfd, *argv), f"{out / '.lock'}", "symbolic link", "victim.txt")
    untouched(folder)
    assert (out / ".lock").is_symlink()  # the link the harness did not make is left where it was
    assert listing(out) == [".lock"] and not (folder / "base.json").exists()


def test_a_hard_link_or_a_pipe_at_the_lock_is_refused(folder):
    out = folder / "out"
    out.mkdir()
    os.link(folder / "victim.txt", out / ".lock")  # truncating it to write a pid would truncate the victim
    with pytest.raises(HarnessError, match="hard link"):
        with runstate.locked(out):
            pass
    untouched(folder)
    (out / ".lock").unlink()
    os.mkfifo(out / ".lock")
    with pytest.raises(HarnessError, match="named pipe"):
        with runstate.locked(out):
            pass
    assert sorted(p.name for p in out.iterdir()) == [".lock"]


def test_a_lock_that_became_a_link_is_not_removed(folder):
    """Only the lock file the run made is removed at its end: a link put in its place (here: to the lock file
    itself, moved aside) stays."""
    out = folder / "out"
    out.mkdir()
    with runstate.locked(out):
        (out / ".lock").rename(out / "moved")
        (out / ".lock").symlink_to(out / "moved")
    assert (out / ".lock").is_symlink() and (out / "moved").read_text().strip() == str(os.getpid())
