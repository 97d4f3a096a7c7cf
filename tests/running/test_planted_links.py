"""Links planted in a run's output folder (issue 32): a symbolic link at ``OUT/.lock`` is neither written through nor
removed by ``run``, ``calibrate`` or ``baseline save --run-out``; links at ``OUT/cases``, a case's folder, its
``images/`` or ``OUT/studies`` are named in one line before the first render, and a link planted during the run is
not followed either (the case folders are made without following links, ``studies/`` replaces a link): nothing is
written outside OUT."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from test_hostile_input import SCENE, assert_one_line, cli, listing
from test_hostile_leftovers import SUITE  # two cases of one small scene, a reference ground truth

from harness.core.errors import HarnessError
from harness.files import imageio
from harness.files.imageio import StagedFolder, WriteError
from harness.running import runstate
from harness.running.cases import load_suite

VICTIM = "the victim's own bytes\n"
NO_STUDIES = ("--no-convergence", "--no-shadow-rays", "--no-strategies")


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


# ---- item 4: links at the folders a run writes ---------------------------------------------------------------------


@pytest.mark.slow  # on a harness that follows the link the suite renders (and computes its studies)
@pytest.mark.parametrize("link", ["cases", "cases/a", "cases/b/images", "studies"])
def test_a_link_where_the_run_writes_is_refused_before_the_first_render(folder, capfd, link):
    out = folder / "out"
    (out / link).parent.mkdir(parents=True, exist_ok=True)
    (out / link).symlink_to(folder / "outside", target_is_directory=True)
    before = listing(out)
    assert_one_line(*cli(capfd, "run", folder / "two.toml", "--out", out, "--executor", "serial", "--quiet",
                         *NO_STUDIES), str(out / link), "symbolic link", "outside")
    untouched(folder)
    assert listing(out) == before  # no results.json, no case folder: nothing ran


@pytest.mark.slow  # on a harness that follows the link the suite renders
@pytest.mark.parametrize("command", ["calibrate", "baseline"])
def test_calibrate_and_baseline_refuse_a_link_at_a_case_folder(folder, capfd, command):
    out = folder / "out"
    (out / "cases").mkdir(parents=True)
    (out / "cases" / "b").symlink_to(folder / "outside", target_is_directory=True)
    argv = [a.format(suite=folder / "two.toml", out=out, base=folder / "base.json") for a in COMMANDS[command]]
    assert_one_line(*cli(capfd, *argv), str(out / "cases" / "b"), "symbolic link")
    untouched(folder)
    assert listing(out) == ["cases", "cases/b"]


@pytest.mark.slow  # renders
@pytest.mark.parametrize("link", ["cases", "cases/b"])
def test_a_link_planted_during_the_run_is_not_followed(folder, capfd, monkeypatch, link):
    """A link planted after the checks, while case a runs, stops the run at case b's first write (one line
    naming it) instead of carrying b's files outside."""
    from harness.running import judge

    out = folder / "out"
    real_run_case = judge.run_case

    def run_case(case, *args, **kwargs):
        record = real_run_case(case, *args, **kwargs)
        if case.name == "a":
            if link == "cases":
                (out / "cases").rename(out / "cases-moved")
            (out / link).symlink_to(folder / "outside", target_is_directory=True)
        return record

    monkeypatch.setattr(judge, "run_case", run_case)
    assert_one_line(*cli(capfd, "run", folder / "two.toml", "--out", out, "--executor", "serial", "--quiet",
                         "--no-report"), str(out / link), "symbolic link")
    untouched(folder)
    assert (out / link).is_symlink()


@pytest.mark.slow  # renders; on a harness that follows the link the studies land outside
def test_a_link_planted_at_studies_during_the_run_is_replaced(folder, capfd, monkeypatch):
    from harness.cli import run as run_command

    out = folder / "out"
    real_run_suite = run_command.run_suite

    def run_suite(*args, **kwargs):
        results = real_run_suite(*args, **kwargs)
        (out / "studies").symlink_to(folder / "outside", target_is_directory=True)  # after the checks
        return results

    monkeypatch.setattr(run_command, "run_suite", run_suite)
    code, _, err = cli(capfd, "run", folder / "two.toml", "--out", out, "--executor", "serial", "--quiet",
                       *NO_STUDIES)
    assert code == 0, err
    untouched(folder)
    assert not (out / "studies").is_symlink() and (out / "studies" / "studies.json").is_file()


@pytest.mark.slow  # renders
def test_links_at_results_json_and_report_files_are_replaced_not_followed(folder, capfd):
    """Files written into OUT (results.json, index.html, a folder of the report) are written beside and renamed over
    what is there: a link at their name is replaced and what it points at is left alone."""
    out = folder / "out"
    out.mkdir()
    for name in ("results.json", "index.html", "summary.md"):
        (out / name).symlink_to(folder / "victim.txt")
    (out / "report").symlink_to(folder / "outside", target_is_directory=True)
    code, _, err = cli(capfd, "run", folder / "two.toml", "--out", out, "--executor", "serial", "--quiet", "--fresh",
                       *NO_STUDIES)
    assert code == 0, err
    untouched(folder)
    for name in ("results.json", "index.html", "summary.md", "report"):
        assert not (out / name).is_symlink(), name


def test_case_folders_are_made_without_following_links(folder):
    out = folder / "out"
    (out / "cases").mkdir(parents=True)
    (out / "cases" / "a").symlink_to(folder / "outside", target_is_directory=True)
    with pytest.raises(WriteError, match="symbolic link"):
        imageio.make_real_folders(out, Path("cases", "a", "images"))
    with pytest.raises(WriteError, match="symbolic link"):
        with imageio.staged_inside(out, Path("cases", "a")):
            raise AssertionError("not reached")
    untouched(folder)
    made = imageio.make_real_folders(out, Path("cases", "b", "images"))
    assert made == [out / "cases" / "b", out / "cases" / "b" / "images"]


def test_the_checks_name_a_link_at_every_folder_of_a_case(folder):
    cases = load_suite(folder / "two.toml").cases
    out = folder / "out"
    (out / "cases" / "b").mkdir(parents=True)
    runstate.refuse_links(out, cases)  # nothing planted
    (out / "cases" / "b" / "images").symlink_to(folder / "outside")
    with pytest.raises(HarnessError, match="images: is a symbolic link"):
        runstate.refuse_links(out, cases)


def test_a_staged_folder_replaces_a_link_at_its_target_when_asked(folder):
    target = folder / "out" / "studies"
    target.parent.mkdir()
    target.symlink_to(folder / "outside", target_is_directory=True)
    with StagedFolder(target, str(target), replace_link=True) as stage:
        (stage.root / "studies.json").write_text("{}")
        stage.commit()
    untouched(folder)
    assert not target.is_symlink() and listing(target) == ["studies.json"]


def test_a_file_written_over_a_link_takes_no_mode_from_its_target(folder):
    out = folder / "out"
    out.mkdir()
    (folder / "victim.txt").chmod(0o4750)  # setuid: not a mode for a results file
    (out / "results.json").symlink_to(folder / "victim.txt")
    imageio.atomic_write_text(out / "results.json", "{}")
    untouched(folder)
    assert not (out / "results.json").is_symlink() and (out / "results.json").stat().st_mode & 0o7000 == 0
