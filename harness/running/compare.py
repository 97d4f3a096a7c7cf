"""Compare a test render with the expected image (its ground truth): every image metric plus the statistical
verdict, as a JSON-ready dict.

:func:`compare_images` works on :class:`harness.files.imageio.ExrImage` values,
:func:`compare_files` reads two EXR files first.  Metrics are described in
:mod:`harness.judges.metrics`, the verdict in :mod:`harness.judges.verdict` and
``docs/verdict.md``.

The returned dict holds only str, int, float, bool, None, lists and dicts,
and no NaN or infinity: those are written as None (``null``), e.g. the PSNR of
identical images (infinite) or the z of a differing zero-variance tile.
``json.dumps(result, allow_nan=False)`` therefore works.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from harness.core.errors import HarnessError
from harness.core.jsonsafe import plain
from harness.files.imageio import ExrImage, read_exr
from harness.judges import metrics
from harness.judges.diagnose import diagnose as diagnose_images
from harness.judges.verdict import ImageError, verdict

__all__ = ["compare_files", "compare_images", "image_facts", "judge", "swapped_warning"]


def _variance_dof(image: ExrImage) -> int | None:
    """The ``variance_dof`` metadata if present (external renderers' repeated runs: K - 1), else spp - 1 from the
    file's ``spp`` metadata (what ``harness render`` writes), if present and >= 2."""
    raw = image.metadata.get("variance_dof") if image.metadata else None
    try:
        if raw is not None and int(str(raw).strip()) >= 1:
            return int(str(raw).strip())
    except ValueError:
        pass
    spp = _spp(image)
    return spp - 1 if spp is not None and spp >= 2 else None


def _spp(image: ExrImage) -> int | None:
    """The file's ``spp`` metadata (samples per pixel) if present and >= 1, else None."""
    try:
        spp = int(str((image.metadata or {}).get("spp")).strip())
    except ValueError:
        return None
    return spp if spp >= 1 else None


def _size(image: np.ndarray) -> str:
    return f"{image.shape[1]}x{image.shape[0]}"


def _compare(test: ExrImage, expected: ExrImage, tile: int, alpha: float, names: tuple[str, str],
             maps: dict | None = None, diagnose: bool = False) -> dict:
    test_name, expected_name = names
    if test.image.shape != expected.image.shape:
        raise HarnessError(
            test_name,
            f"size {_size(test.image)} differs from the reference {expected_name} ({_size(expected.image)}); "
            "expected images of the same size",
        )
    # The verdict first: it checks that both variances exist and the expected image is finite.
    outcome = judge(test, expected, tile=tile, alpha=alpha, names=names)
    t, r = test.image, expected.image
    h, w = t.shape[:2]
    mask = metrics.finite_mask(t, r)
    used = int(mask.sum())
    nonfinite = {"test": metrics.count_nonfinite(t), "ground_truth": metrics.count_nonfinite(r)}
    finite_expected = r[mask]
    psnr_peak = float(finite_expected.max()) if finite_expected.size else float("nan")
    flip_mean, flip_map = metrics.flip(t, r, full=True)
    if maps is not None:
        maps["flip"] = (flip_mean, flip_map)
        maps["tiles"] = outcome.tiles
    result = {
        "width": w,
        "height": h,
        "pixels": h * w,
        "nonfinite_pixels": nonfinite,
        "metric_pixels": used,
        "metric_note": f"metrics use only the {used} of {h * w} pixels finite in both images",
        "metrics": {
            "rmse": metrics.rmse(t, r),
            "relmse": metrics.relmse(t, r),
            "mape": metrics.mape(t, r),
            "psnr": metrics.psnr(t, r),
            "ssim": metrics.ssim(t, r),
            "flip": flip_mean,
        },
        "bias": metrics.bias(t, r, test.variance, expected.variance),
        "conventions": {
            "relmse_eps": metrics.RELMSE_EPS,
            "mape_eps": metrics.MAPE_EPS,
            "psnr": "linear radiance, data_range = max of the reference",
            "psnr_data_range": psnr_peak,
            "ssim": "sRGB-encoded images clipped to [0, 1], 11x11 Gaussian window (sigma 1.5), mean over channels",
            "flip": "HDR-FLIP (flip-evaluator) on linear radiance, mean of the error map",
        },
        "verdict": outcome.to_dict(),
    }
    if diagnose:
        result["diagnosis"] = diagnose_images(t, r, test.variance, expected.variance)
    return plain(result)


def judge(test: ExrImage, expected: ExrImage, *, tile: int = 8, alpha: float = 0.01,
          names: tuple[str, str] = ("test image", "ground truth image")):
    """The statistical verdict alone (:func:`harness.judges.verdict.verdict`) of ``test`` against ``expected``, with
    the degrees of freedom of each variance taken from the images' metadata as :func:`compare_images` takes them
    (``variance_dof``, else ``spp`` - 1): what a case is judged by, without the metrics (``harness calibrate``
    judges thousands of planted images with it). Returns the :class:`harness.judges.verdict.Verdict`.

    The verdict's :class:`~harness.judges.verdict.ImageError` about an image's own arrays (a variance missing, NaN,
    infinite or negative, a non-finite ground truth) is raised as the :class:`HarnessError` naming that image
    (``names``), with its text."""
    try:
        return verdict(test.image, test.variance, expected.image, expected.variance, tile=tile, alpha=alpha,
                       test_dof=_variance_dof(test), expected_dof=_variance_dof(expected), names=names,
                       test_spp=_spp(test), expected_spp=_spp(expected))
    except ImageError as err:
        if not err.image:
            raise
        raise HarnessError(err.image, err.message) from None


def compare_images(test: ExrImage, expected: ExrImage, *, tile: int = 8, alpha: float = 0.01,
                   maps: dict | None = None, diagnose: bool = False) -> dict:
    """Every metric of ``test`` against ``expected`` (the ground truth), the statistical verdict and the statistics
    behind it.

    Both images need variance channels (the verdict's input; zeros for an
    exact ground truth), else :class:`HarnessError`.  If a file's metadata has
    ``spp`` (as ``harness render`` writes), spp - 1 is taken as the degrees of
    freedom of its variance estimates (see :func:`harness.judges.verdict.verdict`).

    Returns a dict with keys ``width``, ``height``, ``pixels``,
    ``nonfinite_pixels`` (``{"test": n, "ground_truth": n}``), ``metric_pixels``
    and ``metric_note`` (metrics use only pixels finite in both images),
    ``metrics`` (``rmse``, ``relmse``, ``mape``, ``psnr``, ``ssim``, ``flip``),
    ``bias`` (see :func:`harness.judges.metrics.bias`), ``conventions`` (how each
    metric was computed) and ``verdict`` (:meth:`harness.judges.verdict.Verdict.to_dict`:
    ``verdict`` "pass"/"fail", ``reason``, ``alpha``, ``threshold``, ``tile``,
    ``nonfinite_pixels``, ``global_bias``, ``omnibus``, ``max_z``,
    ``zero_variance``, ``worst_tile``, ``variance_dof``).  Non-finite floats
    are None.

    ``maps``: where given, a dict that receives the per-pixel maps computed on the way, for a caller that shows
    them: ``"flip"``, the ``(mean, map)`` of :func:`harness.judges.metrics.flip` with ``full=True`` (FLIP is the
    slowest metric; ``harness run`` draws the case's FLIP map from it instead of computing it again), and ``"tiles"``,
    the verdict's :class:`harness.judges.verdict.TileMaps` (per-tile z, two-sided p, tested, failing: the maps of
    :mod:`harness.files.verdict_maps`).

    ``diagnose``: also ``diagnosis``, why the images differ (:func:`harness.judges.diagnose.diagnose`: the best
    integer shift and mirror, the global scale factor with its interval and the factor of pi it may be, and the
    share of the squared difference in the brightest pixels).

    Raises :class:`HarnessError` if the sizes differ, a variance is missing or
    invalid, or the expected image has non-finite pixels.
    """
    return _compare(test, expected, tile, alpha, ("test image", "ground truth image"), maps, diagnose)


def image_facts(image: ExrImage, path: str | os.PathLike[str]) -> dict:
    """What an EXR file says of itself, to tell which of two is the ground truth: its ``path``, ``spp`` (its
    ``spp`` attribute, as ``harness render`` and ``harness ground-truth`` write it; None without one), ``renderer``
    and ``source`` attributes, and ``mean_variance``, the mean of its variance channels over their finite values
    (None without variance channels)."""
    raw = image.metadata.get("spp") if image.metadata else None
    spp = int(raw.strip()) if isinstance(raw, str) and raw.strip().isdigit() and len(raw.strip()) < 19 else None
    mean_variance = None
    if image.variance is not None:
        finite = image.variance[np.isfinite(image.variance)].astype(np.float64)
        mean_variance = float(finite.mean()) if finite.size else None
    return {"path": str(path), "spp": spp, "renderer": (image.metadata or {}).get("renderer"),
            "source": (image.metadata or {}).get("source"), "mean_variance": mean_variance}


def swapped_warning(test: dict, ground_truth: dict) -> str | None:
    """A warning when the image given as the ground truth is noisier than the test image (its mean variance the
    larger): likelier the two files swapped than a ground truth worth judging against; None otherwise."""
    mine, theirs = ground_truth["mean_variance"], test["mean_variance"]
    if mine is None or theirs is None or not mine > theirs:
        return None
    return (f"the ground truth {ground_truth['path']} is noisier than the test image {test['path']} (mean variance "
            f"{mine:.3g} against {theirs:.3g}): are they swapped? harness compare takes TEST, then GROUND_TRUTH")


def compare_files(
    test_path: str | os.PathLike[str], expected_path: str | os.PathLike[str], **kw: Any
) -> dict:
    """:func:`compare_images` on two EXR files read with :func:`harness.files.imageio.read_exr`.

    Keyword arguments (``tile``, ``alpha``, ``maps``, ``diagnose``) are passed on. The result also holds ``images``:
    each file's :func:`image_facts` (``test``, ``ground_truth``) and ``warning``, :func:`swapped_warning` (or None).
    Errors name the files: a size mismatch raises ``HarnessError`` naming both files and both sizes; a file without
    variance channels raises one naming that file.
    """
    test = read_exr(test_path)
    expected = read_exr(expected_path)
    tile = kw.pop("tile", 8)
    alpha = kw.pop("alpha", 0.01)
    maps = kw.pop("maps", None)
    diagnose = bool(kw.pop("diagnose", False))
    if kw:
        raise TypeError(f"unexpected keyword arguments: {', '.join(sorted(kw))}")
    result = _compare(test, expected, tile, alpha, (str(test_path), str(expected_path)), maps, diagnose)
    facts = {"test": image_facts(test, test_path), "ground_truth": image_facts(expected, expected_path)}
    facts["warning"] = swapped_warning(facts["test"], facts["ground_truth"])
    return {**result, "images": plain(facts)}
