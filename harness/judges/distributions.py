"""Tail probabilities and quantiles of the normal, Student's t and chi-square distributions: the p-values of the
verdict (:mod:`harness.judges.verdict`), the chi-square tests (:mod:`harness.judges.chi2`, :mod:`harness.judges.mc`)
and the baselines' bounds, straight from :mod:`scipy.special`.

``scipy.stats`` computes these with the same ``scipy.special`` functions, but importing it took 0.86 s (cold) of
every process that judged an image, against 0.1-0.2 s for ``scipy.special``; the functions here give
``scipy.stats``' numbers bit for bit, its answers at the edges of the support and for invalid parameters included
(tests/judges/test_distributions.py). ``scipy.special`` is imported when a function is first called, so that a
command that computes no p-value pays nothing.
"""

from __future__ import annotations

import numpy as np

__all__ = ["chi2_sf", "normal_isf", "normal_sf", "student_t_sf"]


def normal_sf(x):
    r"""Upper tail of the standard normal: :math:`P(Z > x) = \Phi(-x)`, as ``scipy.stats.norm.sf(x)``.

    Parameters
    ----------
    x : float or array_like
        Points.

    Returns
    -------
    numpy.float64 or numpy.ndarray
        :math:`\Phi(-x) = \tfrac12 \operatorname{erfc}(x / \sqrt 2)`; 1 at -inf, 0 at +inf, NaN for NaN.

    References
    ----------
    .. [1] ``scipy.special.ndtr``, the normal CDF :math:`\Phi`.
    """
    from scipy import special  # optional: 0.1-0.2 s; only a p-value needs it (scipy.stats: 0.8-1.1 s)

    return special.ndtr(-np.asarray(x, dtype=np.float64))


def normal_isf(p):
    r"""The standard normal's upper quantile: the ``z`` with :math:`P(Z > z) = p`, as ``scipy.stats.norm.isf(p)``.

    Parameters
    ----------
    p : float or array_like
        Upper tail probabilities.

    Returns
    -------
    numpy.float64 or numpy.ndarray
        :math:`-\Phi^{-1}(p)`; +inf at p = 0, -inf at p = 1, NaN outside [0, 1] and for NaN.

    References
    ----------
    .. [1] ``scipy.special.ndtri``, the inverse of the normal CDF.
    """
    from scipy import special  # optional: 0.1-0.2 s; only a quantile needs it (scipy.stats: 0.8-1.1 s)

    return -special.ndtri(np.asarray(p, dtype=np.float64))


def student_t_sf(x, dof):
    r"""Upper tail of Student's t with ``dof`` degrees of freedom: :math:`P(T_\nu > x)`, as
    ``scipy.stats.t.sf(x, dof)``.

    Parameters
    ----------
    x : float or array_like
        Points.
    dof : float or array_like
        Degrees of freedom :math:`\nu` (real, > 0; inf is the normal), broadcast against ``x``.

    Returns
    -------
    numpy.float64 or numpy.ndarray
        :math:`F_\nu(-x)`, by symmetry of the t distribution, where :math:`F_\nu` is its CDF; NaN where
        :math:`\nu \le 0` or either argument is NaN.

    References
    ----------
    .. [1] ``scipy.special.stdtr``, Student's t CDF (Boost.Math's incomplete beta function in SciPy 1.17).
    """
    from scipy import special  # optional: 0.1-0.2 s; only a p-value needs it (scipy.stats: 0.8-1.1 s)

    return special.stdtr(np.asarray(dof, dtype=np.float64), -np.asarray(x, dtype=np.float64))


def chi2_sf(x, dof):
    r"""Upper tail of the chi-square distribution with ``dof`` degrees of freedom: :math:`P(X > x)`, as
    ``scipy.stats.chi2.sf(x, dof)``.

    Parameters
    ----------
    x : float or array_like
        Points.
    dof : float or array_like
        Degrees of freedom :math:`k` (real, > 0), broadcast against ``x``.

    Returns
    -------
    numpy.float64 or numpy.ndarray
        :math:`Q(k/2, x/2)`, the regularised upper incomplete gamma function; 1 for :math:`x \le 0` (the support
        starts at 0), 0 at +inf, NaN where :math:`k \le 0` or either argument is NaN.

    References
    ----------
    .. [1] ``scipy.special.chdtrc``, the chi-square distribution's complemented CDF.
    """
    from scipy import special  # optional: 0.1-0.2 s; only a p-value needs it (scipy.stats: 0.8-1.1 s)

    x = np.asarray(x, dtype=np.float64)
    dof = np.asarray(dof, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        tail = special.chdtrc(dof, np.maximum(x, 0.0))  # chdtrc is NaN below 0, where the tail is 1
        return np.where(dof > 0, tail, np.nan)[()]
