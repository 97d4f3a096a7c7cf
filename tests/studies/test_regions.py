"""The scene's ``regions`` (harness/studies/regions.py): which pixels belong to each named shape, the variance over
them, and the strategy table's per-region efficiencies; bad ``regions`` values are refused on one line."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SCENES
from test_hostile_input import assert_one_line, cli

from harness.scene import load_scene
from harness.studies.regions import region_masks, region_variances
from harness.studies.strategies import strategy_rows


def test_veach_mis_plates_are_disjoint_bands_from_front_to_back():
    scene = load_scene(SCENES / "veach-mis.toml")
    masks = region_masks(scene)
    assert list(masks) == [f"plate{i}-light{j}" for i in range(4) for j in range(4)]
    total = sum(m.astype(int) for m in masks.values())
    assert total.max() == 1  # one shape per pixel
    rows = [np.flatnonzero(masks[f"plate{i}-light0"].any(axis=1)).mean() for i in range(4)]
    assert rows == sorted(rows, reverse=True)  # the front plate is lowest in the image, the back one highest
    columns = [np.flatnonzero(masks[f"plate0-light{j}"].any(axis=0)).mean() for j in range(4)]
    assert columns == sorted(columns)  # light 0's strip on the left
    assert all(m.sum() > 40 for m in masks.values())


def test_region_variance_is_the_mean_over_the_region():
    mask = np.zeros((2, 2), bool)
    mask[0] = True
    variance = np.arange(12, dtype=np.float32).reshape(2, 2, 3)
    assert region_variances(variance, {"top": mask}) == {"top": pytest.approx(2.5)}
    assert region_variances(None, {"top": mask}) == {"top": None}


def test_each_region_has_its_own_best_strategy():
    variances = {"default": {"smooth": 1.0, "rough": 1.0}, "direct=area": {"smooth": 4.0, "rough": 0.5},
                 "direct=global-area": {"smooth": 0.25, "rough": 8.0}}
    rng = np.random.default_rng(5)

    def render(settings, spp, index):
        label = "default" if not settings else "{}={}".format(*next(iter(settings.items())))
        regions = {k: v * rng.normal(1.0, 0.02) for k, v in variances.get(label, {"smooth": 1, "rough": 1}).items()}
        return {"mse": 1.0, "floor_mse": 0.0, "variance": 1.0, "seconds": rng.normal(1.0, 0.02), "pixels": 100,
                "spp": spp, "film": [10, 10], "variance_regions": regions}

    table = strategy_rows("x", [], render, True, {"direct": "mis"}, spp=16, repeats=4, min_seconds=0.0)
    regions = table["regions"]
    assert regions["best"] == {"smooth": "direct=global-area", "rough": "direct=area"}
    assert regions["relative_efficiency"]["smooth"]["direct=global-area"] == pytest.approx(4.0, rel=0.1)
    assert regions["relative_efficiency"]["rough"]["direct=area"] == pytest.approx(2.0, rel=0.1)
    smooth = regions["intervals"]["smooth"]["direct=global-area"]
    assert smooth["low"] < 4.0 < smooth["high"]


@pytest.mark.parametrize("value, fragment", [
    ('"plate0-light0"', "regions: expected a list of shape names"),
    ('["nope"]', "regions[0]: expected the name of a [[shapes]] entry, got 'nope'"),
    ('["plate0-light0", "plate0-light0"]', "regions: expected each shape once"),
])
def test_bad_regions_are_refused_on_one_line(tmp_path, capfd, value, fragment):
    text = (SCENES / "veach-mis.toml").read_text()
    line = next(t for t in text.splitlines() if t.startswith("regions = "))
    text = text.replace(line, f"regions = {value}")
    path = tmp_path / "v.toml"
    path.write_text(text)
    assert_one_line(*cli(capfd, "render", path, "--spp", "1", "--out", tmp_path / "o.exr"), str(path), fragment)
    assert not (tmp_path / "o.exr").exists()
