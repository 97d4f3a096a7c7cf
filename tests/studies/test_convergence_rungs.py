"""Every point of a convergence curve holds the spp its rung is labelled with: an external renderer without
variance channels runs its program once per render in the study (it needs no variance of its own), not K times
at rung / K spp; a renderer whose image holds another count all the same is flagged, not silently relabelled."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fake_renderers import slow_start_renderer
from harness.renderers import RenderRequest, RenderResult, get_renderer
from harness.scene import load_scene
from harness.studies.convergence import Series, run_convergence
from reference_impl import Film

ROOT = Path(__file__).resolve().parents[2]


def _furnace(size: int = 4):
    scene = load_scene(ROOT / "scenes" / "furnace.toml")
    scene = dataclasses.replace(scene, film=Film(size, size, "box"), max_depth=2)
    gt = SimpleNamespace(image=np.full((size, size, 3), 0.5, np.float32), variance=None, source="constant", spp=None)
    return scene, gt


@pytest.mark.slow
def test_a_renderer_without_variance_gets_every_rung_at_its_label(tmp_path):
    """The fake writes no variance channels (so a render that needs a variance runs it K = 4 times); every rung of
    the ladder 1, 2, 4, 8 is one run at the rung's spp, and every point says so."""
    fake = slow_start_renderer(tmp_path, startup=0.0, per_spp=0.0, noise=0.1, repeats=4, own_time=True)
    scene, gt = _furnace()
    result = run_convergence(scene, gt, [Series(str(fake), {}, "fake")], spp=(1, 2, 4, 8), seed=3,
                             renderer_factory=get_renderer, warmup=False)
    (series,) = result["series"]
    assert [p["budget"]["spp"] for p in series["points"]] == [1, 2, 4, 8]
    assert [p["spp"] for p in series["points"]] == [1, 2, 4, 8]
    assert all(p["on_rung"] for p in series["points"]) and series["warnings"] == []
    assert all(len(p["seeds"]) == 1 for p in series["points"])


class _RoundsUp:
    """A renderer whose sampler rounds the spp up to a square (as some stratified samplers do)."""

    name = "rounds-up"

    def render(self, scene, request: RenderRequest) -> RenderResult:
        spp = int(np.ceil(np.sqrt(request.spp))) ** 2
        rng = np.random.default_rng(request.seed)
        h, w = scene.film.height, scene.film.width
        image = (0.5 + 0.1 / np.sqrt(spp) * rng.standard_normal((h, w, 3))).astype(np.float32)
        return RenderResult(renderer=self.name, image=image, variance=None, seconds=0.001 * spp, spp=spp,
                            rays={}, stats={}, settings={"spp": request.spp})


def test_a_point_off_its_rung_is_flagged_and_warned():
    """The 2-spp and 8-spp rungs of a renderer that rounds to squares hold 4 and 9 spp: those points sit at the
    spp their images hold, are marked ``on_rung`` False, and the series names them in ``warnings``."""
    scene, gt = _furnace()
    result = run_convergence(scene, gt, [Series("rounds-up", {}, "rounds")], spp=(1, 2, 4, 8), seed=1,
                             renderer_factory=lambda name: _RoundsUp(), warmup=False, min_timing_seconds=0.0)
    (series,) = result["series"]
    by_rung = {p["budget"]["spp"]: p for p in series["points"]}
    assert {n: (p["spp"], p["on_rung"]) for n, p in by_rung.items()} == {
        1: (1, True), 2: (4, False), 4: (4, True), 8: (9, False)}
    assert len(series["warnings"]) == 2
    assert "the 2-spp rung was rendered at 4 spp" in series["warnings"][0]
    assert "the 8-spp rung was rendered at 9 spp" in series["warnings"][1]
