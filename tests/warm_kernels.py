"""Compile the reference renderer's numba kernels into numba's on-disk cache before the tests start.

On a clean clone (CI) numba's cache is empty, and compiling the kernels costs about two CPU-minutes (118 s user on
the shared two-core machine, ``docs/performance.md``, "Test-suite time"). Left to the tests, every pytest-xdist
worker and every ``harness`` subprocess started before the cache is filled compiles the same kernels again. Run by
``tests/conftest.py`` in the controlling process only, when the cache lacks the engines' kernels: one child process
per group below, the groups at once (one per core), so that each kernel is compiled about once and both cores
work. A warm cache makes this a no-op (:func:`cache_is_warm`, a look at the cache folder).

Each group renders tiny films (4 x 4, 1 spp) that reach the kernels of one engine; images are not looked at.

    python tests/warm_kernels.py [GROUP ...]       # compile these groups in this process (default: all)
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (scene, settings) per group. The path loop's Lambertian specialisations (without and with emitters) and the
# volumetric loop's one specialisation (every scene with media) in one group;
# the wavefront, the glossy blocks' specialisations (kernels/path_blocks.py), the path loop's with an environment
# and the blocks (kernels/blocks.py) in the other: about equal compile times, few kernels shared.
GROUPS = {
    "path": [("multi-light", {"direct": "hemisphere-cosine"}),
             ("point-spot", {}), ("envmap", {}), ("sun-sky", {}), ("fog-box", {})],
    "wavefront-glossy": [("cornell-box", {"engine": "wavefront"}),
                         ("multi-light", {"engine": "wavefront", "direct": "hemisphere-cosine"}),
                         ("multi-light", {"engine": "wavefront", "direct": "mis"}),
                         ("cornell-box-specular", {}), ("white-furnace-glass", {}), ("soft-shadows", {})],
}
# the top-level kernels whose cache index files mean the groups have run (numba names them MODULE.FUNCTION-LINE...)
INDEX_PREFIXES = ("path.", "wavefront.", "volpath.", "blocks.", "path_blocks.")


def cache_is_warm() -> bool:
    """Whether numba's cache folder of ``reference_impl.kernels`` holds an index file for each engine's module."""
    from reference_impl import kernels  # imports numba.core.caching: about 0.5 s, in the controlling process only

    folder = kernels._cache_folder(Path(kernels.__file__).resolve().parent)
    names = [p.name for p in folder.glob("*.nbi")] if folder.is_dir() else []
    return all(any(n.startswith(prefix) for n in names) for prefix in INDEX_PREFIXES)


def warm(groups=tuple(GROUPS)) -> None:
    """Render each case of ``groups`` once, in this process, so that numba compiles and caches its kernels."""
    from harness.renderers import RenderRequest, get_renderer
    from harness.scene import load_scene
    from reference_impl import Film

    renderer = get_renderer("reference")
    for group in groups:
        for name, settings in GROUPS[group]:
            scene = load_scene(ROOT / "scenes" / f"{name}.toml")
            scene = dataclasses.replace(scene, film=Film(4, 4, scene.film.filter))
            renderer.render(scene, RenderRequest(spp=1, seed=0, settings=dict(settings)))


def warm_in_parallel() -> float:
    """Run :func:`warm` for every group at once, one child process each; return the seconds it took. A child that
    fails is not an error here: the tests then compile what is missing themselves (and report what fails)."""
    start = time.perf_counter()
    children = [subprocess.Popen([sys.executable, __file__, group], cwd=ROOT, stdout=subprocess.DEVNULL) for group in GROUPS]
    for child in children:
        child.wait()
    return time.perf_counter() - start


if __name__ == "__main__":
    # this folder is on the path as the script's: its reference_impl/ (the tests) would hide the package
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
    warm(tuple(sys.argv[1:]) or tuple(GROUPS))
