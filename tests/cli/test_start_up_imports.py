"""What the everyday commands import, in a fresh interpreter each: none of the libraries whose import alone cost
0.5-0.9 s of every process and that these commands do not need (docs/performance.md, "Imports at every start"):
colour-science (the sRGB curve is harness.core.srgb), trimesh (the icosphere is harness.scene.triangulate's; meshes
still load it), scipy.stats (p-values come from scipy.special through harness.judges.distributions; PSNR is
computed in harness.judges.metrics), and matplotlib where nothing is coloured."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: the heavy libraries watched, and one that the comparison does need (so that the probe is seen to see imports)
WATCHED = ("colour", "trimesh", "networkx", "scipy.stats", "matplotlib", "skimage", "numba")
NEVER = {"colour", "trimesh", "networkx", "scipy.stats"}

pytestmark = pytest.mark.slow


def imported(argv: list[str]) -> tuple[int, set[str]]:
    """Run ``harness ARGV`` in a fresh interpreter: its exit code and which of :data:`WATCHED` it imported."""
    script = ("import json, sys\nfrom harness.cli import main\ntry:\n    code = main(sys.argv[1:])\n"
              "except SystemExit as end:\n    code = end.code\n"
              f"print(json.dumps([code, sorted(m for m in {WATCHED!r} if m in sys.modules)]))")
    done = subprocess.run([sys.executable, "-c", script, *argv], capture_output=True, text=True, timeout=300,
                          check=False, cwd=ROOT)
    assert done.stdout.strip(), done.stderr[-2000:]
    code, modules = json.loads(done.stdout.strip().splitlines()[-1])
    return code, set(modules)


def render(tmp_path: Path, scene: str, name: str, seed: int = 1) -> tuple[Path, set[str]]:
    out = tmp_path / f"{name}.exr"
    code, modules = imported(["render", f"scenes/{scene}.toml", "--spp", "2", "--film", "8x8", "--seed", str(seed),
                              "--out", str(out), "--quiet"])
    assert code == 0 and out.is_file() and out.with_suffix(".png").is_file()
    return out, modules


def test_render_imports_the_tracer_and_no_heavy_library(tmp_path):
    """A scene with a sphere (the furnace) and one without (the Cornell box): numba, and none of the others (the
    PNG preview is tone-mapped without colour-science or matplotlib)."""
    for scene in ("furnace", "cornell-box"):
        _, modules = render(tmp_path, scene, scene)
        assert modules == {"numba"}, scene


def test_compare_imports_scikit_image_but_not_scipy_stats(tmp_path):
    """The verdict's p-values and the metrics: scikit-image for SSIM (seen: the probe works), not scipy.stats,
    matplotlib, numba or colour-science. Its inputs (8 x 8 images with variance channels, as a render writes) are
    written here: only the comparison's process is watched."""
    import numpy as np

    from harness.files.imageio import write_exr

    first, second = tmp_path / "a.exr", tmp_path / "b.exr"
    for path, seed in ((first, 1), (second, 2)):
        rng = np.random.default_rng(seed)
        write_exr(path, 0.5 + 0.05 * rng.standard_normal((8, 8, 3)), np.full((8, 8, 3), 0.05**2))
    code, modules = imported(["compare", str(first), str(second)])
    assert code in (0, 1)
    assert modules == {"skimage"}


def test_a_closed_form_ground_truth_imports_none_of_them(tmp_path):
    out = tmp_path / "gt.exr"
    code, modules = imported(["ground-truth", "scenes/furnace.toml", "--out", str(out), "--quiet"])
    assert code == 0 and out.is_file()
    assert modules == set()


def test_a_suite_case_imports_matplotlib_for_its_maps_and_nothing_else_heavy(tmp_path):
    """One case judged in this process (the serial executor runs it as a worker would): its report images colour
    error maps with matplotlib's colormaps; no colour-science, trimesh or scipy.stats."""
    suite = tmp_path / "one.toml"
    suite.write_text('name = "one"\n[defaults]\nspp = 2\nfilm = { width = 8, height = 8 }\n'
                     '[[cases]]\nname = "furnace/reference"\nscene = "furnace"\n', encoding="utf-8")
    code, modules = imported(["run", str(suite), "--out", str(tmp_path / "run"), "--executor", "serial",
                              "--no-studies", "--no-cache", "--quiet"])
    assert code == 0 and (tmp_path / "run" / "results.json").is_file()
    assert "matplotlib" in modules and "numba" in modules
    assert not modules & NEVER, modules & NEVER
