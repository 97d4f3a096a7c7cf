"""The ``render_check`` fixture's work (:mod:`harness.pytest_plugin`): ground truth, render, verdict, and a
one-paragraph explanation of a fail."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from harness.files import imageio
from harness.renderers import RenderRequest, get_renderer, groundtruth
from harness.running.compare import compare_images
from harness.scene import Scene, load_scene
from reference_impl import Film


def _scene(scene, resolution):
    if not isinstance(scene, Scene):
        scene = load_scene(Path(scene))
    if resolution is not None:
        width, height = (resolution, resolution) if isinstance(resolution, int) else tuple(resolution)
        scene = dataclasses.replace(scene, film=Film(int(width), int(height), scene.film.filter))
    return scene


def _renderer(renderer):
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
            f"Images: {files['render']} (render), {files['ground_truth']} (ground truth), PNG previews beside them.")


class RenderCheck:
    """The callable the ``render_check`` fixture returns (see the module docstring)."""

    def __init__(self, cache_dir: str | None, tmp_path: Path):
        self.cache_dir = cache_dir
        self.tmp_path = tmp_path
        self.calls = 0

    def __call__(self, renderer, scene, spp: int = 64, seed: int = 0, settings: dict | None = None,
                 alpha: float = 1e-3, resolution=None, tile: int = 8, ground_truth_spp: int = 1024) -> dict:
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
        files = {"render": folder / "render.exr", "ground_truth": folder / "ground_truth.exr"}
        imageio.write_exr(files["render"], result.image, result.variance, metadata={"spp": str(result.spp)})
        imageio.write_exr(files["ground_truth"], gt.image, gt.variance, metadata={"spp": str(gt.spp)})
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
