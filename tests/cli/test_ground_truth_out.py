"""``harness ground-truth SCENE --out FILE.exr``: the ground truth as OpenEXR with its variance channels, closed
form included (variance 0), for ``harness compare`` by hand; a bad ``--out`` is one line before any work."""

from __future__ import annotations

import numpy as np
from conftest import SCENES
from test_hostile_input import assert_one_line, cli

from harness.files.imageio import read_exr
from harness.renderers.groundtruth import closed_form
from harness.scene import load_scene


def test_the_closed_form_is_written_with_zero_variance(tmp_path, capfd):
    out = tmp_path / "gt.exr"
    code, stdout, _ = cli(capfd, "ground-truth", SCENES / "furnace.toml", "--out", out, "--cache-dir", tmp_path / "c")
    assert code == 0 and f"wrote {out}" in stdout
    exr = read_exr(out)
    expected = closed_form(load_scene(SCENES / "furnace.toml"))
    np.testing.assert_array_equal(exr.image, expected.image)
    assert exr.variance is not None and not np.any(exr.variance)
    assert (tmp_path / "gt.png").is_file() and not (tmp_path / "c").exists()


def test_a_mitsuba_ground_truth_is_written_with_its_variance(tmp_path, capfd):
    out = tmp_path / "gt.exr"
    code, _, _ = cli(capfd, "ground-truth", SCENES / "soft-shadows.toml", "--spp", "4", "--chunk-spp", "4",
                     "--out", out, "--cache-dir", tmp_path / "c", "--mitsuba-variant", "scalar_rgb", "--quiet")
    assert code == 0
    exr = read_exr(out)
    scene = load_scene(SCENES / "soft-shadows.toml")
    assert exr.image.shape == (scene.film.height, scene.film.width, 3) and np.all(np.isfinite(exr.image)) and exr.image.mean() > 0
    assert exr.variance is not None and exr.variance.max() > 0


def test_a_bad_out_is_one_line_before_any_work(tmp_path, capfd):
    assert_one_line(*cli(capfd, "ground-truth", SCENES / "furnace.toml", "--out", tmp_path / "gt.png"),
                    "--out: expected a file name ending in .exr")
    assert_one_line(*cli(capfd, "ground-truth", SCENES / "furnace.toml", "--out", tmp_path / "no" / "gt.exr"),
                    "--out: folder", "does not exist")
    assert list(tmp_path.iterdir()) == []
