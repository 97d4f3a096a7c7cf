"""The pytest plugin: registered as a pytest11 entry point, its render_check fixture passes the reference renderer
on a 16 x 16 furnace (closed form) and catches a planted 2 % energy loss with a one-paragraph explanation.

Error rates: the verdict fails a correct render with probability <= alpha = 1e-3 (docs/verdict.md). The 2 %
energy-loss mutant lowers the furnace's radiance by 2 % (R: 1.4286 -> 1.400, a shift of 0.029); at 64 spp on
16 x 16 pixels the image mean of R has a standard error of ~0.0007 (measured 0.0014 at 16 spp with rr_depth = 1,
0.0004 with rr_depth = 5), so the expected global-bias z is ~40 against a threshold of ~3.9: a miss has
probability < 1e-100.
"""

from __future__ import annotations

import re
from importlib.metadata import entry_points
from pathlib import Path

import pytest

from conftest import ROOT

pytest_plugins = ["pytester"]

FURNACE = ROOT / "scenes" / "furnace.toml"

TESTS = f'''
from pathlib import Path

import pytest

SCENE = r"{FURNACE}"


def test_reference_agrees(render_check):
    out = render_check("reference", SCENE, spp=16, resolution=16)
    assert out["verdict"]["verdict"] == "pass" and Path(out["files"]["render"]).is_file()


def test_any_object_with_render(render_check):
    from harness.renderers import get_renderer
    from harness.scene import load_scene

    class Wrapped:
        name = "wrapped"

        def render(self, scene, request):
            return get_renderer("reference").render(scene, request)

    render_check(Wrapped(), load_scene(Path(SCENE)), spp=16, seed=3, resolution=(16, 16))


def test_mutant_is_caught(render_check):
    render_check("reference", SCENE, spp=64, resolution=16, settings={{"mutant": "energy-loss-2pct"}})


def test_cache_option(render_check, request):
    assert render_check.cache_dir == request.config.getoption("harness_cache_dir")
'''


def test_entry_point_registered():
    assert any(ep.value == "harness.pytest_plugin" for ep in entry_points(group="pytest11"))


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_render_check_passes_and_fails(pytester):
    pytester.makepyfile(test_render=TESTS)
    cache = pytester.path / "cache"
    result = pytester.runpytest_inprocess("-q", "-p", "no:cacheprovider", "--harness-cache-dir", str(cache))
    result.assert_outcomes(passed=3, failed=1)
    text = result.stdout.str()
    assert "render_check: reference on furnace (16x16, 64 spp, seed 0, settings {'mutant': 'energy-loss-2pct'})" in text
    assert "disagrees with the ground truth" in text and "global bias: z = -" in text
    assert "Global bias z: R -" in text and "worst tile at x=" in text
    images = re.search(r"Images: (\S+) \(render\), (\S+) \(ground truth\)", text)
    assert images and all(Path(p).is_file() for p in images.groups()), "the images the message names exist"
