"""``harness compare --diagnose`` prints why two images differ (a section after the metrics) and ``--json`` holds it
as ``diagnosis``: an image moved down by one row, a light 4 pi too dark, and a correct image."""

from __future__ import annotations

import json
import math

import numpy as np

from harness.cli import main
from harness.files.imageio import write_exr


def _write(path, image, variance):
    write_exr(path, image.astype(np.float32), variance.astype(np.float32))


def _images(tmp_path):
    y, x = np.mgrid[0:24, 0:32] / 24.0
    truth = np.stack([0.2 + x + 0.5 * y**2, 0.3 + 0.5 * x + y, 0.1 + x * y], axis=2)
    rng = np.random.default_rng(11)
    var = 1e-4 * truth
    _write(tmp_path / "gt.exr", truth + np.sqrt(var / 4) * rng.standard_normal(truth.shape), var / 4)
    cases = {"ok": truth, "row": np.roll(truth, 1, axis=0), "dark": truth / (4 * math.pi)}
    for name, image in cases.items():
        v = 1e-4 * image
        _write(tmp_path / f"{name}.exr", image + np.sqrt(v) * rng.standard_normal(truth.shape), v)


def test_compare_diagnose_prints_the_shift_the_scale_and_the_brightest_pixels(tmp_path, capsys):
    _images(tmp_path)
    assert main(["compare", str(tmp_path / "ok.exr"), str(tmp_path / "gt.exr"), "--diagnose"]) == 0
    out = capsys.readouterr().out
    assert "diagnosis: no shift, scale 1 within its interval" in out and "  bright  the brightest 1%" in out
    assert main(["compare", str(tmp_path / "row.exr"), str(tmp_path / "gt.exr"), "--diagnose"]) == 1
    out = capsys.readouterr().out
    assert "diagnosis: moved 1 pixel down" in out
    assert "the test matches the ground truth moved 1 pixel down" in out
    assert main(["compare", str(tmp_path / "dark.exr"), str(tmp_path / "gt.exr"), "--diagnose"]) == 1
    out = capsys.readouterr().out
    assert "diagnosis: no shift, scale about 1/(4 pi)" in out and "test = 0.079" in out


def test_compare_json_holds_the_diagnosis(tmp_path, capsys):
    _images(tmp_path)
    assert main(["compare", str(tmp_path / "row.exr"), str(tmp_path / "gt.exr"), "--diagnose", "--json"]) == 1
    diagnosis = json.loads(capsys.readouterr().out)["diagnosis"]
    assert (diagnosis["shift"]["dx"], diagnosis["shift"]["dy"], diagnosis["shift"]["mirror"]) == (0, 1, "none")
    assert set(diagnosis["scale"]) >= {"scale", "low", "high", "named"} and "share" in diagnosis["bright"]
    assert main(["compare", str(tmp_path / "ok.exr"), str(tmp_path / "gt.exr"), "--json"]) == 0
    assert "diagnosis" not in json.loads(capsys.readouterr().out)  # only when asked for
