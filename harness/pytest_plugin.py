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
``harness_cache_dir``.  This module imports nothing heavy until the fixture is used, so installing the harness
costs other pytest runs nothing.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("harness", "rendering harness (render_check fixture)")
    group.addoption("--harness-cache-dir", default=None, metavar="DIR",
                    help="ground-truth cache folder for render_check (default: $HARNESS_CACHE_DIR or the user cache)")
    parser.addini("harness_cache_dir", "ground-truth cache folder for render_check", default="")


def _cache_dir(config: pytest.Config) -> str | None:
    return config.getoption("harness_cache_dir") or config.getini("harness_cache_dir") or None


def _scene(scene, resolution):
    from harness.scene import Scene, load_scene
    from reference_impl import Film

    if not isinstance(scene, Scene):
        scene = load_scene(Path(scene))
    if resolution is not None:
        width, height = (resolution, resolution) if isinstance(resolution, int) else tuple(resolution)
        scene = dataclasses.replace(scene, film=Film(int(width), int(height), scene.film.filter))
    return scene


def _renderer(renderer):
    from harness.renderers import get_renderer

    if isinstance(renderer, str):
        return get_renderer(renderer)
    if not callable(getattr(renderer, "render", None)):
        raise TypeError(f"render_check: renderer must be a registered name or have a render(scene, request) method, "
                        f"got {renderer!r}")
    return renderer


def _explain(label: str, comparison: dict, files: dict[str, Path]) -> str:
    v = comparison["verdict"]
    z = v["global_bias"].get("z") or []
    zs = ", ".join(f"{c} {x:.2f}" if x is not None else f"{c} n/a" for c, x in zip("RGB", z))
    worst = v.get("worst_tile")
    where = "no tile"
    if worst:
        where = (f"worst tile at x={worst['x']}, y={worst['y']} ({worst['width']}x{worst['height']} px) in "
                 f"{worst['channel']}: z = {worst['z_normal']:.2f}, mean difference {worst['difference']:.4g} "
                 f"+- {worst['stderr']:.2g}")
    m = comparison["metrics"]
    relmse = f"{m['relmse']:.4g}" if m.get("relmse") is not None else "n/a"
    return (f"{label} disagrees with the ground truth (false-alarm probability {v['alpha']:g}): {v['reason']}. "
            f"Global bias z: {zs}; omnibus p = {v['omnibus']['p_value']:.3g}; max |z| = "
            f"{v['max_z']['statistic']:.2f} over {v['max_z']['count']} tile-channels; {where}; relMSE {relmse}. "
            f"Images: {files['render']} (render), {files['reference']} (reference), PNG previews beside them.")


class RenderCheck:
    """The callable the ``render_check`` fixture returns (see the module docstring)."""

    def __init__(self, cache_dir: str | None, tmp_path: Path):
        self.cache_dir = cache_dir
        self.tmp_path = tmp_path
        self.calls = 0

    def __call__(self, renderer, scene, spp: int = 64, seed: int = 0, settings: dict | None = None,
                 alpha: float = 1e-3, resolution=None, tile: int = 8, ground_truth_spp: int = 1024) -> dict:
        from harness.renderers import groundtruth
        from harness.files import imageio
        from harness.running.compare import compare_images
        from harness.renderers import RenderRequest

        __tracebackhide__ = True
        scene = _scene(scene, resolution)
        impl = _renderer(renderer)
        gt = groundtruth.ground_truth(scene, spp=ground_truth_spp, cache_dir=self.cache_dir)
        request = RenderRequest(spp=spp, seed=seed, settings={k: str(v) for k, v in (settings or {}).items()})
        result = impl.render(scene, request)
        if result.variance is None:
            raise AssertionError(f"render_check: {getattr(impl, 'name', impl)!r} returned no variance; the verdict "
                                 "needs each pixel's variance of the mean (RenderResult.variance)")
        self.calls += 1
        folder = self.tmp_path / f"render_check-{self.calls}"
        folder.mkdir(parents=True, exist_ok=True)
        files = {"render": folder / "render.exr", "reference": folder / "reference.exr"}
        imageio.write_exr(files["render"], result.image, result.variance, metadata={"spp": str(result.spp)})
        imageio.write_exr(files["reference"], gt.image, gt.variance, metadata={"spp": str(gt.spp)})
        for key in files:
            image = result.image if key == "render" else gt.image
            imageio.write_png_preview(imageio.preview_path(files[key]), image)
        gt_meta = {"spp": str(gt.spp)} if gt.spp else {}
        comparison = compare_images(imageio.ExrImage(result.image, result.variance, {"spp": str(result.spp)}),
                                    imageio.ExrImage(gt.image, gt.variance, gt_meta), tile=tile, alpha=alpha)
        comparison["files"] = {k: str(v) for k, v in files.items()}
        comparison["ground_truth"] = {"source": gt.source, "spp": gt.spp, "cached": gt.cached}
        if comparison["verdict"]["verdict"] != "pass":
            name = getattr(impl, "name", type(impl).__name__)
            extra = f", settings {dict(request.settings)}" if request.settings else ""
            label = (f"render_check: {name} on {Path(str(scene.path)).stem} ({scene.film.width}x{scene.film.height}, "
                     f"{spp} spp, seed {seed}{extra}) against {gt.source}")
            raise AssertionError(_explain(label, comparison, files))
        return comparison


@pytest.fixture
def render_check(request: pytest.FixtureRequest, tmp_path: Path) -> RenderCheck:
    """``render_check(renderer, scene, spp=64, seed=0, settings=None, alpha=1e-3, resolution=None)``: assert that a
    render agrees with the scene's ground truth (statistical verdict); see :mod:`harness.pytest_plugin`."""
    return RenderCheck(_cache_dir(request.config), tmp_path)
