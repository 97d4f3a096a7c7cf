"""The renderer protocol and what every renderer returns."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from harness.scene import Scene


@dataclass(frozen=True)
class RenderRequest:
    """What to render: samples per pixel, seed, renderer-specific ``key=value`` settings, a progress callback
    ``progress(done, total)``, and whether the caller uses the render's variance (``variance``): a caller that
    measures the image against a ground truth alone (the convergence study) says False, so that a renderer that
    repeats its program only to estimate a variance (an external renderer without variance channels) runs it once
    and its image holds exactly ``spp`` samples per pixel."""

    spp: int
    seed: int = 0
    settings: dict[str, str] = field(default_factory=dict)
    progress: Callable[[int, int], None] | None = None
    variance: bool = True


@dataclass
class RenderResult:
    """A rendered image and what it cost.

    image     (H, W, 3) float32 linear radiance, row 0 at the top.
    variance  (H, W, 3) float32 variance of each pixel's estimate (of the mean, not of one sample), or None.
    seconds   render time alone.
    load_seconds  time spent before the clock started loading what the render runs (the reference's compiled
              kernels: ``reference_impl.RenderOutput.load_seconds``), or None where the renderer does not say.
    rays      {"camera": .., "shadow": .., "indirect": ..} ray counts where the renderer knows them.
    stats     further counters.
    settings  every setting actually used, resolved (JSON-serialisable).
    """

    renderer: str
    image: np.ndarray
    variance: np.ndarray | None
    seconds: float
    spp: int
    rays: dict[str, int]
    stats: dict[str, int]
    settings: dict
    info: dict = field(default_factory=dict)
    load_seconds: float | None = None

    @property
    def paths(self) -> int:
        return self.image.shape[0] * self.image.shape[1] * self.spp

    @property
    def nonfinite_pixels(self) -> int:
        return int(np.count_nonzero(~np.all(np.isfinite(self.image), axis=2)))


class Renderer(Protocol):
    name: str

    def render(self, scene: Scene, request: RenderRequest) -> RenderResult: ...
