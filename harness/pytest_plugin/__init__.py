"""A pytest plugin (entry point ``pytest11: harness``): a renderer's own test-suite asserts agreement with ground
truth in one line.

.. code-block:: python

    def test_my_renderer_matches_ground_truth(render_check):
        render_check(MyRenderer(), "scenes/cornell-box.toml", spp=64, resolution=32)

``render_check(renderer, scene, spp=64, seed=0, settings=None, alpha=1e-3, resolution=None, tile=8,
ground_truth_spp=1024)`` loads the scene (a path or a :class:`harness.scene.Scene`), gets its ground truth through
:func:`harness.renderers.groundtruth.ground_truth` (the closed form, or Mitsuba through the cache: rendered once, then read),
renders with ``renderer`` (a registered name such as ``"reference"``, or any object with a
``render(scene, request) -> RenderResult`` method, see :mod:`harness.renderers.base`), and runs the statistical
verdict (:mod:`harness.judges.verdict`): a correct renderer fails with probability at most ``alpha``.  On a fail it raises
``AssertionError`` with one paragraph: the verdict's reason, the global-bias z per channel, the worst tile, and the
EXR files of the render and the reference written to the test's ``tmp_path``.  On a pass it returns the comparison
(:func:`harness.running.compare.compare_images`'s dict, plus ``"files"``).

Options: ``--harness-cache-dir DIR`` (default ``$HARNESS_CACHE_DIR``, else the user cache), also the ini key
``harness_cache_dir``.  This module imports nothing heavy: the fixture loads the harness
(:mod:`harness.pytest_plugin.check`) when a test uses it, so installing the harness costs other pytest runs nothing.
"""

from __future__ import annotations

from pathlib import Path

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("harness", "rendering harness (render_check fixture)")
    group.addoption("--harness-cache-dir", default=None, metavar="DIR",
                    help="ground-truth cache folder for render_check (default: $HARNESS_CACHE_DIR or the user cache)")
    parser.addini("harness_cache_dir", "ground-truth cache folder for render_check", default="")


def _cache_dir(config: pytest.Config) -> str | None:
    return config.getoption("harness_cache_dir") or config.getini("harness_cache_dir") or None


@pytest.fixture
def render_check(request: pytest.FixtureRequest, tmp_path: Path):
    """``render_check(renderer, scene, spp=64, seed=0, settings=None, alpha=1e-3, resolution=None)``: assert that a
    render agrees with the scene's ground truth (statistical verdict); see :mod:`harness.pytest_plugin`."""
    from harness.pytest_plugin.check import RenderCheck  # optional: the harness loads only when a test uses the fixture

    return RenderCheck(_cache_dir(request.config), tmp_path)
