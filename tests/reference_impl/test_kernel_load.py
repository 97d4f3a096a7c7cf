"""A render loads every compiled kernel it calls before its clock starts (``reference_impl.integrator._load_kernels``):
``RenderOutput.seconds`` is the render alone and ``load_seconds`` the load, for every engine."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import types
from pathlib import Path

import pytest
from conftest import load_small, render_reference

from reference_impl import integrator

ROOT = Path(__file__).resolve().parents[2]


def test_the_load_is_timed_apart_from_the_render(monkeypatch):
    """A loader that takes 100 s (on a clock the test moves) shows in ``load_seconds``, not in ``seconds``: were the
    load inside the timed region, ``seconds`` would hold the 100 s."""
    offset = [0.0]
    clock = types.SimpleNamespace(perf_counter=lambda: time.perf_counter() + offset[0])
    monkeypatch.setattr(integrator, "time", clock)
    real = integrator._load_kernels

    def slow_load(*args):
        real(*args)
        offset[0] += 100.0

    monkeypatch.setattr(integrator, "_load_kernels", slow_load)
    scene = load_small("soft-shadows", 8)
    result = render_reference(scene, spp=4, seed=1)
    assert result.load_seconds >= 100.0
    assert result.seconds < 100.0


def test_the_warm_step_changes_no_bit_and_no_counter(monkeypatch):
    """Without the warm step (its loader a no-op, the kernels already loaded by a first render) the image, the
    variance and every counter are the same: the warm batch's counters are dropped, its buffers never read."""
    scene = load_small("cornell-box", 12)
    warm = render_reference(scene, spp=4, seed=2)
    monkeypatch.setattr(integrator, "_load_kernels", lambda *args: None)
    cold = render_reference(scene, spp=4, seed=2)
    assert warm.image.tobytes() == cold.image.tobytes()
    assert warm.variance.tobytes() == cold.variance.tobytes()
    drop = "embree_microseconds"  # a time, not a count
    assert {k: v for k, v in warm.stats.items() if k != drop} == {k: v for k, v in cold.stats.items() if k != drop}


_FRESH = """
import dataclasses, json, sys
from numba.core.registry import CPUDispatcher
from harness.renderers import RenderRequest, get_renderer
from harness.scene import load_scene
from reference_impl import integrator

def loaded():
    # every specialisation of every kernel loaded in this process so far
    return sum(len(value.overloads) for name, module in list(sys.modules.items()) if name.startswith("reference_impl")
               for value in vars(module).values() if isinstance(value, CPUDispatcher))

real, after_warm = integrator._load_kernels, []
def counting(*args):
    real(*args)
    after_warm.append(loaded())
integrator._load_kernels = counting
out = []
for name, settings in json.loads(sys.argv[1]):
    scene = load_scene(f"scenes/{name}.toml")
    scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=16, height=16))
    before = loaded()
    after_warm.clear()
    get_renderer("reference").render(scene, RenderRequest(spp=4, seed=1, settings=settings))
    out.append({"case": [name, settings], "before": before, "after_warm": after_warm[-1] if after_warm else before,
                "after": loaded()})
print(json.dumps(out))
"""


@pytest.mark.slow
def test_a_fresh_process_loads_nothing_inside_the_clock():
    """In a fresh process, each engine's first render (the path loop, the volumetric loop, the wavefront with one
    and with two indirect rays) loads its kernels in the warm step, and none after it: the number of loaded
    specialisations of ``reference_impl``'s kernels after the render equals that after the warm step."""
    cases = [["soft-shadows", {}], ["fog-box", {}], ["multi-light", {"engine": "wavefront"}],
             ["cornell-box", {"indirect_rays": "2"}]]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", _FRESH, json.dumps(cases)], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    counts = json.loads(proc.stdout.strip().splitlines()[-1])
    assert counts[0]["after_warm"] > counts[0]["before"]  # the first render's warm step loaded the kernels
    for row in counts:
        assert row["after"] == row["after_warm"], row
