"""Is a renderer's :class:`RenderResult` an image the harness can judge? One pure check, before anything is written.

A renderer that returns a wrong-shaped, non-numeric or entirely non-finite image, or no variance, or a variance that
is negative or NaN where the image is finite, has failed: :func:`validate_result` raises :class:`BadRenderError` (an ordinary exception, not a user error) with
one line saying what is wrong, and ``run_case`` turns it into the case's ``error`` status and reason while the suite
goes on. Some non-finite pixels are not refused here: the verdict counts them and fails the case.
"""

from __future__ import annotations

import math

import numpy as np


class BadRenderError(Exception):
    """A renderer returned an image the harness cannot judge. ``str(err)`` is one line."""


def validate_result(result, width: int, height: int, *, for_verdict: bool = True) -> None:
    """Raise :class:`BadRenderError` unless ``result`` holds an image the harness can compare:

    * ``image``: a real floating-point array of shape (height, width, 3) with at least one finite pixel;
    * ``variance``: a real floating-point array of the same shape, finite and >= 0 at every pixel where the image
      is finite (the verdict needs it; one sample per pixel gives none);
    * ``spp``: an integer >= 1; ``seconds``: a finite number >= 0.

    With ``for_verdict=False`` (``harness render``, which only writes what it got and counts non-finite pixels)
    only the structure is checked: shapes, types, spp, seconds and a finite pixel (an image that is NaN everywhere
    is a failed render there too); the variance may be absent.
    """
    expected = (height, width, 3)
    image = _array(result, "image", expected)
    if not np.isfinite(image).all(axis=-1).any():
        raise BadRenderError(f"the image is NaN or infinite at every one of its {width * height} pixels")
    if not for_verdict:
        if getattr(result, "variance", None) is not None:
            _array(result, "variance", expected)
    elif getattr(result, "variance", None) is None:
        raise BadRenderError("no variance image; the verdict needs the variance of each pixel's estimate")
    else:
        _check_variance(image, _array(result, "variance", expected))
    spp = getattr(result, "spp", None)
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise BadRenderError(f"spp is {spp!r}; expected an integer >= 1")
    seconds = getattr(result, "seconds", None)
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float, np.floating, np.integer)) or not (
            math.isfinite(seconds) and seconds >= 0):
        raise BadRenderError(f"seconds is {seconds!r}; expected a finite number >= 0")


def _check_variance(image: np.ndarray, variance: np.ndarray) -> None:
    finite_pixel = np.isfinite(image).all(axis=-1)
    with np.errstate(invalid="ignore"):
        bad = ~(np.isfinite(variance) & (variance >= 0)) & finite_pixel[..., None]
    if bad.any():
        raise BadRenderError(
            f"the variance is NaN, infinite or negative at {int(np.count_nonzero(bad.any(axis=-1)))} pixels with a "
            "finite value; expected the variance of each pixel's estimate, >= 0 (one sample per pixel gives none: "
            "use spp >= 2)")


def _array(result, name: str, expected: tuple[int, int, int]) -> np.ndarray:
    value = getattr(result, name, None)
    if not isinstance(value, np.ndarray):
        raise BadRenderError(f"the {name} is a {type(value).__name__}; expected a numpy array of shape {expected}")
    if value.shape != expected:
        raise BadRenderError(f"the {name} has shape {value.shape}; expected {expected} (height, width, RGB)")
    if not np.issubdtype(value.dtype, np.floating):
        raise BadRenderError(f"the {name} has dtype {value.dtype}; expected floating point")
    return value
