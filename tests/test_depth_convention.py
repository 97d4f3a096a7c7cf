"""docs/external-renderers.md's depth-convention command, run exactly as printed: scenes/depth-convention.toml
renders to its closed form 1.75 at its max_depth 3 with the reference renderer, and one bounce less or more (what a
renderer with another convention renders) moves every pixel by a share no noise hides (1.5 and 1.875)."""

from __future__ import annotations

import json
import re
import shlex
import shutil
from pathlib import Path

import pytest

from harness.cli import main
from harness.renderers.groundtruth import closed_form
from harness.scene import load_scene

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "external-renderers.md"


def _doc_command() -> list[str]:
    """The one command in the doc's "Telling a renderer's depth convention" section."""
    text = DOC.read_text(encoding="utf-8")
    section = text.split("### Telling a renderer's depth convention", 1)[1].split("\n### ", 1)[0]
    (block,) = re.findall(r"```console\n(.*?)```", section, flags=re.S)
    (line,) = [ln for ln in block.splitlines() if ln.strip()]
    return shlex.split(line)


def _mean(argv: list[str], capsys) -> float:
    assert main(argv) == 0
    values = json.loads(capsys.readouterr().out)["mean_radiance"]
    assert max(values) - min(values) < 1e-6  # a grey furnace: the channels agree
    return values[0]


@pytest.mark.slow
def test_the_docs_depth_command_tells_the_three_depths_apart(tmp_path, monkeypatch, capsys):
    argv = _doc_command()
    assert argv[0] == "harness" and "scenes/depth-convention.toml" in argv
    (tmp_path / "scenes").mkdir()
    shutil.copy(ROOT / "scenes" / "depth-convention.toml", tmp_path / "scenes")
    monkeypatch.chdir(tmp_path)
    scene = load_scene(ROOT / "scenes" / "depth-convention.toml")
    assert scene.max_depth == 3 and float(closed_form(scene).image.mean()) == pytest.approx(1.75)
    means = {3: _mean(argv[1:], capsys)}
    for depth in (2, 4):
        means[depth] = _mean(argv[1:] + ["--max-depth", str(depth)], capsys)
    for depth, mean in means.items():
        assert mean == pytest.approx(2 - 2 ** (1 - depth), rel=0.01), means
    assert means[2] < 0.9 * means[3] and means[4] > 1.05 * means[3], means  # -14 % and +7 %, the noise 0.1 %
