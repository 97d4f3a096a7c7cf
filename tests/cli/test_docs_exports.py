"""The ``harness export`` commands docs/external-renderers.md and docs/scene-json.md print, run as printed (from a
folder whose ``scenes`` is the checkout's), each ending with exit 0 and the files its comment names."""

from __future__ import annotations

import shlex

import pytest

from conftest import ROOT
from harness.cli import main
from test_new_user import shell_blocks

DOCS = [ROOT / "docs" / "external-renderers.md", ROOT / "docs" / "scene-json.md"]
COMMANDS = [command for doc in DOCS for block in shell_blocks(doc.read_text(encoding="utf-8")) for command in block
            if command.startswith("harness export ")]


def test_the_docs_print_export_commands():
    assert len(COMMANDS) >= 7 and any("textured-cornell-box" in c for c in COMMANDS)


@pytest.mark.slow
@pytest.mark.parametrize("command", COMMANDS)
def test_an_export_command_of_the_docs_runs_as_printed(command, tmp_path, monkeypatch, capfd):
    (tmp_path / "scenes").symlink_to(ROOT / "scenes")
    monkeypatch.chdir(tmp_path)
    argv = shlex.split(command.split("  #", 1)[0])[1:]
    assert main(argv) == 0, capfd.readouterr().err
    out = tmp_path / argv[argv.index("--out") + 1]
    names = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}
    main_file = {"mitsuba-xml": "scene.xml", "json": "scene.json", "obj": "scene.obj", "gltf": "scene.gltf"}.get(
        argv[argv.index("--format") + 1])
    assert names and (main_file is None or main_file in names), names
    if "textured" in command:
        assert any(name.startswith("textures/") and name.endswith(".png") for name in names), names
