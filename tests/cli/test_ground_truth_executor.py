"""``harness ground-truth --executor``: a ground truth's chunks rendered on worker processes or a Dask cluster of two
workers, then merged, give the same image as one process, bit for bit."""

from __future__ import annotations

import pytest

from harness.cli import main
from harness.files.imageio import read_exr
from harness.renderers import groundtruth

pytest.importorskip("mitsuba")

# scalar_rgb: its renders of one scene and seed are the same bits every time (llvm_ad_rgb's are not always:
# docs/robustness.md, "Same results everywhere")
COMMON = ["cornell-box", "--film", "16x16", "--spp", "512", "--chunk-spp", "128", "--mitsuba-variant", "scalar_rgb",
          "--quiet"]


def _ground_truth(tmp_path, name, *extra):
    out = tmp_path / f"{name}.exr"
    assert main(["ground-truth", *COMMON, "--cache-dir", str(tmp_path / name), "--out", str(out), *extra]) == 0
    return read_exr(out)


@pytest.mark.parametrize("executor", ["dask", "local"])
def test_chunks_on_two_workers_give_the_same_image_as_one_process(tmp_path, executor, monkeypatch):
    stored = []  # the cache entries this process writes
    store = groundtruth.Cache.store
    monkeypatch.setattr(groundtruth.Cache, "store", lambda self, key, *a: stored.append(key) or store(self, key, *a))
    here = _ground_truth(tmp_path, "here")
    assert len(stored) == 5  # here: four chunks of 128 spp and their merge
    stored.clear()
    there = _ground_truth(tmp_path, executor, "--executor", executor, "--workers", "2")
    assert len(stored) == 1  # there: the merge only, the chunks by the workers
    assert here.image.tobytes() == there.image.tobytes()
    assert here.variance.tobytes() == there.variance.tobytes()
    chunks = [p for p in (tmp_path / executor / "groundtruth").iterdir() if p.is_dir()]
    assert len(chunks) == 5  # four chunks of 128 spp rendered by the workers, and their merge


def test_bad_executor_or_workers_is_one_line(tmp_path, capsys):
    assert main(["ground-truth", *COMMON, "--executor", "spark"]) == 2
    assert capsys.readouterr().err.strip() == ("harness: error: --executor: expected serial, local, dask or "
                                               "tcp://HOST:PORT, got 'spark'")
    assert main(["ground-truth", *COMMON, "--workers", "2"]) == 2
    assert capsys.readouterr().err.strip() == "harness: error: --workers: applies only with --executor"
