"""Convergence with any renderer (docs/report.md): equal-time and equal-error figures are read at most 2x beyond
a curve's measured times ("out of range" further out), and an external renderer run K times per render gets its
per-run spp chosen so that its points land on the ladder, each at the spp its image holds, its times without
process start-up."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from harness.renderers import get_renderer
from harness.scene import load_scene
from harness.studies.convergence import MAX_EXTRAPOLATION, Series, equal_error, equal_time, run_convergence
from reference_impl import Film

ROOT = Path(__file__).resolve().parents[2]

# K = 2 runs per render (no variance channels); pixels 0.5 + N(0, 0.1^2 / spp); start-up 0.2 s of sleep
FAKE = r'''
import sys, time
args = dict(zip(sys.argv[1::2], sys.argv[2::2]))
time.sleep(0.2)
import numpy as np
from harness.files.imageio import write_exr
w, h, spp = int(args["--width"]), int(args["--height"]), int(args["--spp"])
rng = np.random.default_rng(int(args["--seed"]))
write_exr(args["--out"], 0.5 + 0.1 / np.sqrt(spp) * rng.standard_normal((h, w, 3)), None)
'''


def test_comparisons_go_at_most_2x_beyond_a_curve():
    """The issue's RMSE 1.4e+08 came from a line followed far outside its points: a curve measured over 1-4 s is
    read along its line down to 0.5 s and up to 8 s, and no further."""
    times = [1.0, 2.0, 4.0]
    errors = [0.1 / np.sqrt(t) for t in times]
    late = [t * 100 for t in times]  # 100-400 s: the common time (4 s) is 25x below it
    et = equal_time({"short": (times, errors), "late": (late, errors)})
    assert et["time"] == 4.0 and et["errors"]["late"] is None and et["ratio_to_first"]["late"] is None
    assert et["out_of_range"] == {"short": False, "late": True} and et["extrapolated"]["late"] is False
    near = [t * 1.9 for t in times]  # 1.9-7.6 s: 4 s inside; at 0.95 s (= 1.9 / 2) still within reach
    et = equal_time({"near": (near, errors), "short": (times, errors)}, at=1.9 / MAX_EXTRAPOLATION)
    assert et["extrapolated"] == {"near": True, "short": True} and not any(et["out_of_range"].values())
    assert et["errors"]["near"] == pytest.approx(0.1 / np.sqrt(0.5))
    et = equal_time({"near": (near, errors), "short": (times, errors)}, at=0.9)
    assert et["out_of_range"]["near"] and et["errors"]["near"] is None
    steep = [0.1 / t for t in times]  # reaches the other's smallest error (0.05) at 2 s; "flat" never does
    flat = [0.2, 0.19, 0.18]
    ee = equal_error({"steep": (times, steep), "flat": (times, flat)}, target=0.01)
    assert ee["out_of_range"] == {"steep": True, "flat": True} and ee["times"] == {"steep": None, "flat": None}


@pytest.fixture()
def fake_renderer(tmp_path):
    script = tmp_path / "fake.py"
    script.write_text(FAKE)
    path = tmp_path / "fake.toml"
    command = ["{python}", str(script), "--out", "{out}", "--seed", "{seed}", "--spp", "{spp}",
               "--width", "{width}", "--height", "{height}"]
    path.write_text(f"command = {json.dumps(command)}\nrepeats = 2\n")
    return path


@pytest.mark.slow
def test_an_external_renderers_points_land_on_the_ladder(fake_renderer):
    scene = load_scene(ROOT / "scenes" / "furnace.toml")
    scene = dataclasses.replace(scene, film=Film(4, 4, "box"))
    gt = SimpleNamespace(image=np.full((4, 4, 3), 0.5, np.float32), variance=None, source="constant", spp=None)
    result = run_convergence(scene, gt, [Series(str(fake_renderer), {}, "fake")], spp=(1, 2, 4), seed=3,
                             renderer_factory=get_renderer)
    series = result["series"][0]
    # K = 2: rung 1 cannot be reached (it lands at 2, rendered once), 2 is 2 runs x 1 spp, 4 is 2 runs x 2 spp
    assert [p["spp"] for p in series["points"]] == [2, 4]
    assert [p["budget"]["spp"] for p in series["points"]] == [1, 4]
    assert series["time_from"].startswith("start-up subtracted (") and "1x1 film" in series["time_from"]
    # each render is 2 runs of 0.2 s sleep and the script's imports (about 0.5 s of wall time each) and nearly no
    # rendering: what is left is the scatter of process start, well below the 1 s of wall time; timed once
    assert all(p["seconds"] < 0.3 and p["timing_repeats"] == 1 for p in series["points"]), series["points"]
