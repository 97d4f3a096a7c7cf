"""The regions of a scene's image that its strategy table measures apart (the scene's ``regions`` key): the pixels
whose viewing ray through the pixel centre first hits each named shape.

Veach's MIS scene (``scenes/veach-mis.toml``) names its four plates: light sampling and BSDF sampling each lose on
some of them and win on others, which one mean over the whole image hides (Veach 1997, Fig. 9.2)."""

from __future__ import annotations

import numpy as np

from harness.scene.model import Scene
from harness.scene.triangulate import shape_triangles, triangulate
from reference_impl.intersect import Intersector


def region_masks(scene: Scene, shape: tuple[int, int] | None = None) -> dict[str, np.ndarray]:
    """{shape name: (H, W) bool} for each of ``scene.regions``: the pixels whose centre ray first hits that shape
    (at the scene's film, or ``shape`` = (H, W)). Empty when the scene names no region."""
    if not scene.regions:
        return {}
    height, width = shape if shape is not None else (scene.film.height, scene.film.width)
    owner = np.concatenate([np.full(len(shape_triangles(s)[1]), s.index) for s in scene.shapes]) \
        if scene.shapes else np.zeros(0, np.int64)
    jj, ii = np.mgrid[0:height, 0:width]
    origins, directions = scene.camera.generate_rays(ii.ravel() + 0.5, jj.ravel() + 0.5, width, height)
    tri, _t = Intersector(triangulate(scene)).closest_hit(origins, directions)
    hit_shape = np.where(tri >= 0, owner[np.maximum(tri, 0)], -1).reshape(height, width)
    index = {s.name: s.index for s in scene.shapes}
    return {name: hit_shape == index[name] for name in scene.regions}


def region_variances(variance: np.ndarray | None, masks: dict[str, np.ndarray]) -> dict[str, float | None]:
    """The mean of a render's per-pixel variance (of the mean) over each region's pixels and channels: the
    region's expected MSE for an unbiased render. None for a region without finite values."""
    out: dict[str, float | None] = {}
    for name, mask in masks.items():
        if variance is None or variance.shape[:2] != mask.shape:
            out[name] = None
            continue
        v = np.asarray(variance, dtype=np.float64)[mask]
        v = v[np.isfinite(v)]
        out[name] = float(v.mean()) if v.size else None
    return out
