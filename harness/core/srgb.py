"""The sRGB transfer function: linear values in [0, 1] to the display values of an sRGB image.

Written here rather than imported from colour-science: importing ``colour`` took 0.7-1.9 s of every harness process
(it loads matplotlib's pyplot for its plotting module) for this two-line formula, which the PNG previews
(:func:`harness.files.imageio.tonemap_srgb8`) and the display metrics (:func:`harness.judges.metrics.srgb_encode`)
are the only users of. tests/core/test_srgb.py checks that it gives colour-science's ``cctf_encoding(x,
function="sRGB")`` bit for bit.
"""

from __future__ import annotations

import numpy as np

__all__ = ["encode"]

#: The linear value below which the curve is a straight line (IEC 61966-2-1, section 5.2).
LINEAR_LIMIT = 0.0031308


def encode(linear: np.ndarray) -> np.ndarray:
    r"""The sRGB transfer function (the inverse of the sRGB EOTF) of linear values in [0, 1], float64.

    Parameters
    ----------
    linear : array_like
        Linear values, expected in [0, 1] (callers clip; see Notes for what happens outside).

    Returns
    -------
    numpy.ndarray
        The encoded values V, float64, of the same shape.

    Notes
    -----
    .. math::

        V = \begin{cases} 12.92\,L & L \le 0.0031308 \\ 1.055\,L^{1/2.4} - 0.055 & L > 0.0031308 \end{cases}

    Both branches are evaluated over the whole array and the first is kept where it applies, so the power runs on
    the same contiguous array (and through the same vectorised ``numpy.power`` loop) as colour-science's, whose
    results these are bit for bit. Above 1 the curve goes on past 1; below 0 the line gives negative values; NaN
    stays NaN.

    References
    ----------
    .. [1] IEC 61966-2-1:1999, "Multimedia systems and equipment - Colour measurement and management - Part 2-1:
           Colour management - Default RGB colour space - sRGB", section 5.2 (the encoding of R, G and B).
    """
    values = np.asarray(linear, dtype=np.float64)
    with np.errstate(invalid="ignore"):  # a negative value's power is NaN in the branch np.where drops
        curve = 1.055 * np.power(values, 1 / 2.4) - 0.055
    return np.where(values <= LINEAR_LIMIT, values * 12.92, curve)
