"""The repository's own files: what a merge can leave behind unseen."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
# git's markers: seven of a kind at the start of a line ("=======" alone on its line)
CONFLICT = re.compile(r"^(<{7} |>{7} |={7}$)", re.MULTILINE)
TEXT = (".py", ".md", ".toml", ".txt", ".html", ".js", ".css", ".cfg", ".yml", ".yaml", ".json", ".xml")


def conflict_markers(text: str) -> list[int]:
    """The 1-based numbers of the lines of ``text`` that start with a merge-conflict marker."""
    return [text.count("\n", 0, m.start()) + 1 for m in CONFLICT.finditer(text)]


def test_the_marker_pattern_finds_what_git_writes():
    merged = "a\n<<<<<<< HEAD\nours\n=======\ntheirs\n>>>>>>> branch\nb\n"
    assert conflict_markers(merged) == [2, 4, 6]
    assert conflict_markers("a\n========\n| x |\n|===|\n") == []  # a heading underline or a table is not one


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="not a git checkout")
def test_no_tracked_file_holds_a_merge_conflict_marker():
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    found = {}
    for name in files.decode().split("\0"):
        if name.endswith(TEXT) and (ROOT / name).is_file():
            lines = conflict_markers((ROOT / name).read_text(encoding="utf-8", errors="replace"))
            if lines:
                found[name] = lines
    assert not found, f"merge-conflict markers (file: lines): {found}"
