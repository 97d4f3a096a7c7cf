"""Image-error metrics between a test image and the expected image (the ground truth).

Every function takes ``(test, expected)``: arrays of shape (H, W, C), linear
radiance (the harness's images are (H, W, 3) float32; see
:mod:`harness.files.imageio`).  Arithmetic is done in float64.

Non-finite values.  A renderer may write NaN or Inf.  No metric raises on them:
each one uses only the pixels whose every channel is finite in *both* images
(:func:`finite_mask`); :func:`count_nonfinite` counts the others so that a
caller can report them.  Point-wise metrics simply leave those pixels out.  The
windowed metrics (SSIM, FLIP) need a full image, so a non-finite pixel is given
the expected image's value (no error there, and no NaN spreading into its
neighbours' windows) and is then left out of the mean of the error map.  If no
pixel is finite in both images the metrics return NaN.

References
----------
.. [1] F. Rousselle, C. Knaus, M. Zwicker, "Adaptive sampling and reconstruction
       using greedy error minimization", ACM Trans. Graph. 30(6), 2011
       (relative MSE, as used throughout the Monte Carlo denoising literature).
.. [2] Z. Wang, A. C. Bovik, H. R. Sheikh, E. P. Simoncelli, "Image quality
       assessment: from error visibility to structural similarity", IEEE Trans.
       Image Process. 13(4), 2004.
.. [3] P. Andersson, J. Nilsson, T. Akenine-Möller, M. Oskarsson, K. Åström,
       M. D. Fairchild, "FLIP: A difference evaluator for alternating images",
       Proc. ACM Comput. Graph. Interact. Tech. 3(2), 2020; and P. Andersson,
       J. Nilsson, P. Shirley, T. Akenine-Möller, "Visualizing errors in
       rendered high dynamic range images", Eurographics short papers, 2021
       (HDR-FLIP).
.. [4] IEC 61966-2-1:1999, the sRGB transfer function.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from harness.core import srgb

__all__ = [
    "MAPE_EPS",
    "RELMSE_EPS",
    "bias",
    "count_nonfinite",
    "finite_mask",
    "flip",
    "mape",
    "psnr",
    "relmse",
    "rmse",
    "srgb_encode",
    "ssim",
]

#: epsilon in relMSE's denominator (r^2 + eps), the value common in the denoising literature [1].
RELMSE_EPS = 1e-2
#: epsilon in MAPE's denominator (|r| + eps).
MAPE_EPS = 1e-2


# ---------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------


def _check_image(name: str, array: object) -> np.ndarray:
    arr = np.asarray(array)
    if arr.ndim != 3 or arr.shape[0] < 1 or arr.shape[1] < 1 or arr.shape[2] < 1:
        raise ValueError(f"{name} must have shape (H, W, C) with H, W, C >= 1, got {arr.shape}")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"{name} must be a real numeric array, got dtype {arr.dtype}")
    return arr.astype(np.float64)


def _pair(test: object, expected: object) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """float64 copies of both images and the (H, W) mask of pixels finite in both."""
    t = _check_image("test", test)
    r = _check_image("expected", expected)
    if t.shape != r.shape:
        raise ValueError(f"test has shape {t.shape} but expected has shape {r.shape}")
    mask = np.all(np.isfinite(t), axis=-1) & np.all(np.isfinite(r), axis=-1)
    return t, r, mask


def _filled(t: np.ndarray, r: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Full images for windowed metrics: a pixel not finite in both gets the expected image's value
    (0 where the expected image itself is not finite), so it has no error and spreads no NaN."""
    m = mask[..., None]
    r_full = np.where(m, r, 0.0)
    return np.where(m, t, r_full), r_full


def finite_mask(test: np.ndarray, expected: np.ndarray) -> np.ndarray:
    """(H, W) boolean mask of the pixels whose every channel is finite in both images.

    These are the pixels every metric in this module is computed on.
    """
    return _pair(test, expected)[2]


def count_nonfinite(image: np.ndarray) -> int:
    """Number of pixels of an (H, W, C) image with at least one NaN or infinite channel."""
    arr = _check_image("image", image)
    return int(np.count_nonzero(~np.all(np.isfinite(arr), axis=-1)))


def srgb_encode(image: np.ndarray) -> np.ndarray:
    """Linear radiance -> display sRGB in [0, 1]: ``srgb.encode(clip(image, 0, 1))``.

    The sRGB transfer function [4] (:func:`harness.core.srgb.encode`), applied at exposure 0
    (as the harness's PNG previews are), float64 out.
    """
    clipped = np.clip(np.asarray(image, dtype=np.float64), 0.0, 1.0)
    return srgb.encode(clipped)


# ---------------------------------------------------------------------------
# Point-wise metrics
# ---------------------------------------------------------------------------


def rmse(test: np.ndarray, expected: np.ndarray) -> float:
    r"""Root-mean-square error.

    .. math:: \mathrm{RMSE} = \sqrt{\tfrac{1}{NC} \sum_{p,c} (t_{pc} - r_{pc})^2}

    over the N pixels finite in both images and the C channels.
    """
    t, r, mask = _pair(test, expected)
    if not mask.any():
        return float("nan")
    return float(np.sqrt(np.mean((t[mask] - r[mask]) ** 2)))


def relmse(test: np.ndarray, expected: np.ndarray, eps: float = RELMSE_EPS) -> float:
    r"""Relative mean squared error [1].

    .. math:: \mathrm{relMSE} = \tfrac{1}{NC} \sum_{p,c} \frac{(t_{pc} - r_{pc})^2}{r_{pc}^2 + \varepsilon}

    with :math:`\varepsilon = 10^{-2}` by default (it keeps black pixels from
    dominating), over the pixels finite in both images.
    """
    t, r, mask = _pair(test, expected)
    if not mask.any():
        return float("nan")
    tm, rm = t[mask], r[mask]
    return float(np.mean((tm - rm) ** 2 / (rm**2 + eps)))


def mape(test: np.ndarray, expected: np.ndarray, eps: float = MAPE_EPS) -> float:
    r"""Mean absolute percentage (relative) error, as a fraction.

    .. math:: \mathrm{MAPE} = \tfrac{1}{NC} \sum_{p,c} \frac{|t_{pc} - r_{pc}|}{|r_{pc}| + \varepsilon}

    with :math:`\varepsilon = 10^{-2}` by default, over the pixels finite in both images.
    """
    t, r, mask = _pair(test, expected)
    if not mask.any():
        return float("nan")
    tm, rm = t[mask], r[mask]
    return float(np.mean(np.abs(tm - rm) / (np.abs(rm) + eps)))


def psnr(test: np.ndarray, expected: np.ndarray, data_range: float | None = None) -> float:
    r"""Peak signal-to-noise ratio on linear radiance, in dB.

    .. math:: \mathrm{PSNR} = 10 \log_{10} \frac{P^2}{\mathrm{MSE}}

    on the pixels finite in both images, as
    :func:`skimage.metrics.peak_signal_noise_ratio` computes it (the same
    float64 operations, so the same bits; tests/judges/test_metrics.py checks
    it; importing that module would import scipy.stats, 0.86 s, for a
    logarithm).  The peak P (``data_range``) defaults to the maximum
    of the expected image over those pixels: the images are HDR, so there is no
    fixed white level.  A single very bright pixel (a visible light source)
    therefore raises the PSNR of the whole image; compare PSNRs only between
    renders of the same scene.  Returns ``inf`` for identical images and NaN
    when the images differ but the peak is <= 0 (a black expected image).
    """
    t, r, mask = _pair(test, expected)
    if not mask.any():
        return float("nan")
    tm, rm = t[mask], r[mask]
    mse = float(np.mean((tm - rm) ** 2))
    if mse == 0.0:
        return float("inf")
    peak = float(rm.max()) if data_range is None else float(data_range)
    if not peak > 0.0:
        return float("nan")
    return float(10 * np.log10(peak**2 / mse))


# ---------------------------------------------------------------------------
# Windowed metrics
# ---------------------------------------------------------------------------

_SSIM_SIGMA = 1.5
_SSIM_GAUSSIAN_WIN = 11  # skimage's window for sigma = 1.5, truncate = 3.5


def ssim(test: np.ndarray, expected: np.ndarray, *, full: bool = False):
    r"""Mean structural similarity [2] of the sRGB-encoded images.

    .. math:: \mathrm{SSIM}(x, y) = \frac{(2\mu_x\mu_y + C_1)(2\sigma_{xy} + C_2)}
              {(\mu_x^2 + \mu_y^2 + C_1)(\sigma_x^2 + \sigma_y^2 + C_2)}

    SSIM models perceived structure on display values, so both images are first
    encoded with :func:`srgb_encode` (clipped to [0, 1], sRGB transfer
    function), then compared by :func:`skimage.metrics.structural_similarity`
    per channel (``channel_axis=2``, ``data_range=1``) with Wang et al.'s
    settings: an 11x11 Gaussian window of sigma 1.5, population covariances,
    K1 = 0.01, K2 = 0.03.  Images smaller than 11 pixels on a side use a uniform
    window of the largest odd size that fits (at least 3); smaller still gives
    NaN.  The result is the mean of the SSIM map over channels and over the
    pixels finite in both images, excluding a border of half a window (as
    scikit-image's own mean does, so with no non-finite pixels it equals
    scikit-image's value).  Identical images give 1.

    Returns the mean, or ``(mean, map)`` with ``full=True`` (map (H, W, C)).
    """
    from skimage.metrics import structural_similarity  # optional: scikit-image is slow to import

    t, r, mask = _pair(test, expected)
    h, w = mask.shape
    side = min(h, w)
    if side >= _SSIM_GAUSSIAN_WIN:
        kwargs: dict = {"gaussian_weights": True, "sigma": _SSIM_SIGMA}
        win = _SSIM_GAUSSIAN_WIN
    else:
        win = side if side % 2 == 1 else side - 1
        kwargs = {"win_size": win}
    if win < 3 or not mask.any():
        nan_map = np.full(t.shape, np.nan)
        return (float("nan"), nan_map) if full else float("nan")
    tf, rf = _filled(t, r, mask)
    _, smap = structural_similarity(
        srgb_encode(rf),
        srgb_encode(tf),
        channel_axis=2,
        data_range=1.0,
        use_sample_covariance=False,
        full=True,
        **kwargs,
    )
    pad = (win - 1) // 2
    inner = np.zeros_like(mask)
    inner[pad : h - pad, pad : w - pad] = True
    use = mask & inner
    mean = float(np.mean(smap[use])) if use.any() else float("nan")
    return (mean, smap) if full else mean


def flip(test: np.ndarray, expected: np.ndarray, *, full: bool = False):
    r"""Mean HDR-FLIP error [3] (NVIDIA's ``flip-evaluator`` package), in [0, 1].

    Renders are linear HDR radiance, so HDR-FLIP is used: it tone-maps both
    images (ACES) at a range of exposures chosen from the expected image's luminance
    and takes, per pixel, the largest LDR-FLIP error over the exposures.
    (LDR-FLIP on clipped sRGB images would not see errors above display white.)
    Defaults of the package otherwise: 67 pixels per degree.

    Before evaluation: negative values (possible with filters that have
    negative lobes) are clipped to 0, as HDR-FLIP requires; non-finite pixels
    get the expected image's value; both images are divided by the expected image's
    maximum.  HDR-FLIP's automatic exposures make it invariant to that scale,
    and the division keeps the package from failing (it ends the process) when
    the expected image's luminance is below ~1e-7.  A black expected image has no
    exposure range: then the test image is divided by its own maximum and
    evaluated at exposure 0.  Identical images give 0.

    The result is the mean of the error map over the pixels finite in both
    images.  Returns the mean, or ``(mean, map)`` with ``full=True``
    (map (H, W) float64).
    """
    t, r, mask = _pair(test, expected)
    if not mask.any():
        nan_map = np.full(mask.shape, np.nan)
        return (float("nan"), nan_map) if full else float("nan")
    tf, rf = _filled(t, r, mask)
    tf = np.maximum(tf, 0.0)
    rf = np.maximum(rf, 0.0)
    if tf.shape[2] != 3:
        raise ValueError(f"FLIP needs RGB images, got {tf.shape[2]} channels")
    if np.array_equal(tf, rf):
        emap = np.zeros(mask.shape)
    else:
        flip_evaluator = flip_module()
        parameters: dict = {}
        scale = float(rf.max())
        if not scale > 0.0:
            scale = float(tf.max())
            parameters = {"startExposure": 0.0, "stopExposure": 0.0}
        ref32 = np.ascontiguousarray(rf / scale, dtype=np.float32)
        test32 = np.ascontiguousarray(tf / scale, dtype=np.float32)
        result = flip_evaluator.evaluate(
            ref32, test32, "HDR", applyMagma=False, computeMeanError=False, parameters=parameters
        )
        emap = np.asarray(result[0], dtype=np.float64).reshape(mask.shape)
    mean = float(np.mean(emap[mask]))
    return (mean, emap) if full else mean


def flip_module():
    """NVIDIA's ``flip_evaluator`` package, imported with its OpenMP threads set to sleep, not spin, while they wait.

    Returns
    -------
    module
        ``flip_evaluator``.

    Notes
    -----
    The package runs on its own copy of GNU OpenMP (``flip_evaluator.libs/libgomp-*.so``), which reads
    ``OMP_WAIT_POLICY`` once, when it is loaded. Its default, threads that spin at every barrier, costs about 0.3 s
    of each evaluation when the other cores are busy (the harness's parallel workers, a parallel test run): a 32 x 32
    image took 0.34 s (0.22 s of CPU) that way and 0.004 s with ``OMP_WAIT_POLICY=passive``, and a 256 x 256 one
    0.84 s against 0.43 s, the same error map (docs/performance.md). So the variable is ``passive`` while the
    package loads, unless the user set it, and is then put back as it was: no other library or child process sees
    it. Imported on first use: a compiled extension, slow to import, that only FLIP needs.
    """
    loaded = sys.modules.get("flip_evaluator")
    if loaded is not None:  # the environment is touched once, at the import, not at every evaluation
        return loaded
    previous = os.environ.get("OMP_WAIT_POLICY")
    if previous is None:
        os.environ["OMP_WAIT_POLICY"] = "passive"
    try:
        import flip_evaluator  # optional: a compiled extension, slow to import; only FLIP needs it
    finally:
        if previous is None:
            os.environ.pop("OMP_WAIT_POLICY", None)
    return flip_evaluator


# ---------------------------------------------------------------------------
# Bias
# ---------------------------------------------------------------------------


def bias(
    test: np.ndarray,
    expected: np.ndarray,
    test_variance: np.ndarray | None = None,
    expected_variance: np.ndarray | None = None,
) -> dict:
    r"""Mean signed difference, per channel and overall, with standard errors.

    Per channel c, over the N pixels finite in both images:

    .. math:: b_c = \tfrac{1}{N} \sum_p (t_{pc} - r_{pc}), \qquad
              \mathrm{se}_c = \tfrac{1}{N} \sqrt{\textstyle\sum_p (V^T_{pc} + V^R_{pc})}

    (pixels are independent estimates; V is each pixel's variance of the mean).
    Overall: :math:`b = \tfrac{1}{C} \sum_c b_c`, with
    :math:`\mathrm{se} = \tfrac{1}{C} \sum_c \mathrm{se}_c` -- the standard error
    if the channels are perfectly correlated and an upper bound otherwise (the
    variance files hold no cross-channel covariance, and in a render the
    channels of a pixel come from the same paths).

    Standard errors are given only when both variances are; otherwise they are
    None.  Returns ``{"per_channel": [..], "overall": b, "stderr_per_channel":
    [..] | None, "stderr": se | None}`` (plain Python floats).
    """
    t, r, mask = _pair(test, expected)
    n = int(mask.sum())
    nch = t.shape[2]
    if n == 0:
        per = [float("nan")] * nch
        out = {"per_channel": per, "overall": float("nan"), "stderr_per_channel": None, "stderr": None}
        if test_variance is not None and expected_variance is not None:
            out["stderr_per_channel"] = [float("nan")] * nch
            out["stderr"] = float("nan")
        return out
    diff = (t[mask] - r[mask]).sum(axis=0) / n
    out = {
        "per_channel": [float(x) for x in diff],
        "overall": float(np.mean(diff)),
        "stderr_per_channel": None,
        "stderr": None,
    }
    if test_variance is not None and expected_variance is not None:
        vt = _check_image("test_variance", test_variance)
        vr = _check_image("expected_variance", expected_variance)
        if vt.shape != t.shape or vr.shape != t.shape:
            raise ValueError(
                f"variances have shapes {vt.shape} and {vr.shape}, expected {t.shape} like the images"
            )
        se = np.sqrt((vt[mask] + vr[mask]).sum(axis=0)) / n
        out["stderr_per_channel"] = [float(x) for x in se]
        out["stderr"] = float(np.mean(se))
    return out
