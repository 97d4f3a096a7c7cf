"""`harness render`: output contract, determinism, and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import OpenEXR
import pytest
from conftest import SCENES, load_small, render_reference
from harness.judges.mc import FALSE_ALARM, image_mean, z_critical, z_scores

from harness.cli import main

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")


def run_cli(*args, cwd=None):
    proc = subprocess.run([sys.executable, "-m", "harness", *args], capture_output=True, text=True, cwd=cwd)
    return proc.returncode, proc.stdout, proc.stderr


def cli(capfd, *args):
    """``harness ARGS`` in this process: (exit code, stdout, stderr) as the file descriptors saw them. The refusals
    below come from the same ``main()`` a process runs; the process itself (its stdout holding only the JSON, a
    closed stdout) is tested by test_render_writes_exr_with_variance_png_and_json and tests/cli/test_hostile_cli.py."""
    code = main([str(a) for a in args])
    out, err = capfd.readouterr()
    return code, out, err


def test_render_writes_exr_with_variance_png_and_json(tmp_path):
    out = tmp_path / "furnace.exr"
    code, stdout, stderr = run_cli("render", str(SCENES / "furnace.toml"), "--spp", "4", "--seed", "3",
                                   "--set", "max_depth=3", "--out", str(out), "--json")
    assert code == 0, stderr
    summary = json.loads(stdout)
    for key in ("renderer", "spp", "seconds", "load_seconds", "paths_per_second", "rays", "nonfinite_pixels",
                "settings"):
        assert key in summary
    assert summary["renderer"] == "reference" and summary["spp"] == 4 and summary["nonfinite_pixels"] == 0
    assert set(summary["rays"]) >= {"camera", "shadow", "indirect"}
    assert summary["rays"]["camera"] == 64 * 64 * 4
    assert summary["settings"]["max_depth"] == 3 and summary["settings"]["seed"] == 3
    assert summary["seconds"] > 0 and summary["paths_per_second"] > 0
    assert summary["load_seconds"] > 0  # a fresh process loads the kernels, before the clock
    with OpenEXR.File(str(out), separate_channels=True) as exr:
        channels = exr.channels()
        assert set(channels) == {"R", "G", "B", "variance.R", "variance.G", "variance.B"}
        assert all(c.pixels.dtype == np.float32 and c.pixels.shape == (64, 64) for c in channels.values())
        red = channels["R"].pixels.copy()
        var_red = channels["variance.R"].pixels.copy()
    assert (tmp_path / "furnace.png").is_file()
    # Furnace, max_depth 3: L = 1 + rho + rho^2 in every pixel (red rho = 0.3); the variance is of the mean. Light
    # sampling inside the analytic sphere has no variance (G / p(y) is one number there), so the tolerance adds the
    # float32 image's rounding, 4 ulps of the value.
    se = np.sqrt(var_red.astype(float).sum()) / red.size
    rounding = 4 * np.finfo(np.float32).eps * 1.39
    assert abs(red.astype(float).mean() - 1.39) < z_critical(FALSE_ALARM, 1) * se + rounding


def test_variance_channel_is_variance_of_the_mean():
    """Quadrupling spp divides the reported variance by about 4 (it is of the pixel mean, not of one sample)."""
    scene = load_small("soft-shadows", 16)
    low = render_reference(scene, spp=16, seed=1)
    high = render_reference(scene, spp=64, seed=2)
    ratio = high.variance.astype(float).sum() / low.variance.astype(float).sum()
    assert 0.2 < ratio < 0.3, ratio


def test_same_seed_same_bytes_whatever_batch_size_or_threads():
    scene = load_small("cornell-box", 24)
    base = render_reference(scene, spp=8, seed=5)
    for settings in ({"batch_size": 1000, "threads": 1}, {"batch_size": 37, "threads": 2}, {"threads": 2}):
        other = render_reference(scene, spp=8, seed=5, **settings)
        assert other.image.tobytes() == base.image.tobytes(), settings
        assert other.variance.tobytes() == base.variance.tobytes(), settings


def test_same_seed_same_bytes_with_branching_indirect_rays():
    scene = load_small("multi-light", 12)
    base = render_reference(scene, spp=4, seed=5, indirect_rays=3)
    other = render_reference(scene, spp=4, seed=5, indirect_rays=3, batch_size=50, threads=2)
    assert other.image.tobytes() == base.image.tobytes()


def test_different_seeds_give_different_noise_same_expectation():
    scene = load_small("cornell-box", 24)
    a = render_reference(scene, spp=8, seed=1)
    b = render_reference(scene, spp=8, seed=2)
    differs = np.any(a.image != b.image, axis=2)
    assert differs.mean() > 0.9
    z = z_scores(image_mean(a.image, a.variance), image_mean(b.image, b.variance))
    assert np.all(np.abs(z) < z_critical(FALSE_ALARM, 3)), z


def test_same_seed_same_file_bytes(tmp_path):
    paths = []
    for name in ("a.exr", "b.exr"):
        assert main(["render", str(SCENES / "soft-shadows.toml"), "--spp", "2", "--out", str(tmp_path / name), "--quiet"]) == 0
        paths.append(tmp_path / name)
    assert paths[0].read_bytes() == paths[1].read_bytes()


@pytest.mark.parametrize("args,names", [
    (["--set", "direct=sphere"], "--set direct"),
    (["--set", "shadow_ray=4"], "did you mean 'shadow_rays'"),
    (["--set", "nokeyvalue"], "--set"),
    (["--spp", "0"], "--spp"),
    (["--renderer", "nope"], "--renderer"),
    (["--set", "max_depth=-1", "--set", "rr=off"], "--set rr"),
])
def test_bad_options_get_one_line_and_exit_2(tmp_path, capfd, args, names):
    out = tmp_path / "x.exr"
    argv = ["render", str(SCENES / "furnace.toml"), "--out", str(out)]
    if "--spp" not in args:
        argv += ["--spp", "1"]
    code, stdout, stderr = cli(capfd, *argv, *args)
    assert code == 2
    assert len(stderr.strip().splitlines()) == 1, stderr
    assert names in stderr and "Traceback" not in stderr
    assert not out.exists() and not list(tmp_path.iterdir())


def test_bad_scene_and_output_get_one_line_and_exit_2(tmp_path, capfd):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[camera]\norigin = [0, 0]\n')
    code, _, stderr = cli(capfd, "render", str(bad), "--spp", "1", "--out", str(tmp_path / "x.exr"))
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and str(bad) in stderr
    code, _, stderr = cli(capfd, "render", str(SCENES / "furnace.toml"), "--spp", "1", "--out", str(tmp_path / "no" / "x.exr"))
    assert code == 2 and "--out" in stderr and len(stderr.strip().splitlines()) == 1
    code, _, stderr = cli(capfd, "render", str(tmp_path / "missing.toml"), "--spp", "1", "--out", str(tmp_path / "x.exr"))
    assert code == 2 and "missing.toml" in stderr
    assert not (tmp_path / "x.exr").exists()


def test_scene_without_lights_renders_black_with_no_shadow_rays():
    scene = load_small("cornell-box", 8)
    dark = type(scene)(**{**scene.__dict__, "shapes": [s for s in scene.shapes if s.emission is None]})
    result = render_reference(dark, spp=2)
    assert not np.any(result.image)
    assert sum(result.rays.values()) == 0 and not np.any(result.variance)
