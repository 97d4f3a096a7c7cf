r"""Chi-square goodness-of-fit tests for sampling routines: does a warp draw from the pdf it claims?

The idea is that of Mitsuba 3's ``mitsuba.chi2.ChiSquareTest`` (the code here is written afresh, in plain numpy
and scipy): cut the sample domain into bins, count where ``n`` samples land, and compare those counts with the ones
the routine's *own* pdf predicts,

.. math::

    E_b = n \int_{\text{bin } b} p(x)\, J(x)\, dx, \qquad
    X^2 = \sum_{\text{cells } c} \frac{(O_c - E_c)^2}{E_c} \;\sim\; \chi^2_{k - 1},

where the integral is computed numerically (Gauss-Legendre or midpoint nodes inside every bin), ``J`` is the
Jacobian of the parametrisation the bins live in, and the ``k`` cells are the bins after pooling: bins expecting
fewer than ``min_expected`` (5) samples are summed into one cell (itself merged into the smallest regular cell if it
still expects < 5), so that the chi^2 approximation of the multinomial holds. The total count is fixed, so ``X^2``
has ``k - 1`` degrees of freedom, and the p-value is its upper tail ``P(chi^2_{k-1} >= X^2)``.

Besides the p-value, every test reports and :meth:`Chi2Result.failures` checks:

* ``pdf_integral``: the pdf integrated over the whole domain; it must be ~1 (the pdf is normalised and the domain
  covers its support). Expected counts are *not* renormalised, so a wrong normalisation also shows in chi^2.
* ``impossible``: samples that fell in a bin whose expected count is ~0 *and* at which the pdf itself is 0 -- the
  sampler produced a value its pdf calls impossible. This is a hard failure whatever the p-value. (The pointwise
  confirmation keeps a sliver of support that the quadrature nodes of a bin happened to miss from counting.)
* ``out_of_domain``: samples outside the domain (beyond a relative tolerance ``boundary_tol``) or not finite; also a
  hard failure, since the domain must cover the support.

Parametrisations (the Jacobian turns the measure of the sampled space into ``dx dy`` of the bins):

* hemisphere / sphere directions in ``(cos theta, phi)`` with ``J = 1`` (``d omega = d cos(theta) d phi``): use
  :func:`directions_to_cos_phi` and the domain :data:`SPHERE_COS_PHI` (covering the lower hemisphere too, so that a
  direction below the surface is an "impossible" sample rather than an out-of-domain one); ``(phi, z)`` is the same
  with the axes swapped;
* points on a planar region in orthonormal 2D coordinates of its plane with ``J = 1`` (a pdf per unit area);
* ``(theta, phi)`` would need ``J = sin(theta)``: pass ``jacobian=lambda t, p: np.sin(t)``.

Significance: a test passes when ``p >= alpha``. A file running ``m`` such tests should use :func:`sidak_alpha`
(``1 - (1 - 0.01)**(1/m)``, about ``0.01 / m``) so that the whole file has a 1 % false-alarm chance;
:data:`FAMILY_ALPHA` is that 1 %. With the samples drawn from a fixed seed the p-value is a reproducible number.

References
----------
.. [1] W. Jakob et al., "Mitsuba 3 renderer", 2022, https://mitsuba-renderer.org -- the ``mitsuba.chi2`` module
   (``ChiSquareTest``, used by its test suite on BSDFs, phase functions and warps), whose binning and
   integrating design this module follows.
.. [2] K. Pearson, "On the criterion that a given system of deviations from the probable in the case of a
   correlated system of variables is such that it can be reasonably supposed to have arisen from random sampling",
   Philosophical Magazine 50 (1900), 157-175.
.. [3] W. G. Cochran, "Some methods for strengthening the common chi^2 tests", Biometrics 10 (1954), 417-451 (the
   rule of thumb of at least 5 expected counts per cell).
.. [4] Z. Sidak, "Rectangular confidence regions for the means of multivariate normal distributions", Journal of the
   American Statistical Association 62 (1967), 626-633.

Examples
--------
A cosine-weighted hemisphere warp of your own, checked against its pdf ``cos(theta) / pi``:

>>> import numpy as np
>>> from harness.judges.chi2 import SPHERE_COS_PHI, chi2_test_2d, directions_to_cos_phi
>>> def my_cosine_warp(u1, u2):  # (n,) uniforms -> (n, 3) directions about +z
...     r, phi = np.sqrt(u1), 2 * np.pi * u2
...     return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)])
>>> rng = np.random.default_rng(1)
>>> result = chi2_test_2d(
...     lambda n: directions_to_cos_phi(my_cosine_warp(rng.random(n), rng.random(n))),
...     lambda cos_theta, phi: np.where(cos_theta > 0, cos_theta / np.pi, 0.0),
...     SPHERE_COS_PHI, res=(64, 64), n_samples=1_000_000, name="my cosine warp")
>>> result.passed(alpha=0.01), result.failures(alpha=0.01)
(True, [])

Claiming the uniform pdf ``1 / (2 pi)`` for the same warp is rejected (``p`` is 0 to double precision).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from harness.judges.distributions import chi2_sf

__all__ = [
    "FAMILY_ALPHA",
    "MIN_EXPECTED",
    "SPHERE_COS_PHI",
    "HEMISPHERE_COS_PHI",
    "Chi2Result",
    "sidak_alpha",
    "pooled_statistic",
    "bin_integrals",
    "chi2_test",
    "chi2_test_2d",
    "chi2_test_1d",
    "chi2_test_discrete",
    "directions_to_cos_phi",
    "cos_phi_to_directions",
    "orthonormal_basis",
    "to_local",
]

#: Chance that a correct sampler fails at least one test of a family (a test file) when each test uses
#: :func:`sidak_alpha` of the family's size.
FAMILY_ALPHA = 0.01
#: Bins expecting fewer samples than this are pooled (Cochran's rule of thumb).
MIN_EXPECTED = 5.0
_MAX_NODES = 20_000_000  # pdf evaluations per test; guards against a res * order too large for memory

#: ``(cos theta, phi)`` over the whole sphere, ``J = 1``. Use it for hemisphere samplers too, so that a direction
#: below the surface counts as an impossible sample (pdf 0) rather than an out-of-domain one.
SPHERE_COS_PHI = ((-1.0, 1.0), (0.0, 2.0 * np.pi))
#: ``(cos theta, phi)`` over the upper hemisphere only, ``J = 1``; a direction below it is out of domain.
HEMISPHERE_COS_PHI = ((0.0, 1.0), (0.0, 2.0 * np.pi))


def sidak_alpha(num_tests: int, family_alpha: float = FAMILY_ALPHA) -> float:
    """Per-test significance level so that ``num_tests`` independent tests raise a false alarm with ``family_alpha``.

    Parameters
    ----------
    num_tests : int
        How many tests share the family's false-alarm budget (at least 1).
    family_alpha : float, optional
        The chance, in (0, 1), that a correct implementation fails at least one of them (default 1 %).

    Returns
    -------
    float
        ``1 - (1 - family_alpha) ** (1 / num_tests)``, slightly above ``family_alpha / num_tests`` (Bonferroni).

    Notes
    -----
    Sidak's correction [4]_ is exact for independent tests: ``P(no false alarm) = (1 - alpha) ** m``.
    """
    if not (isinstance(num_tests, (int, np.integer)) and num_tests >= 1):
        raise ValueError(f"num_tests must be an integer >= 1, got {num_tests!r}")
    if not 0.0 < family_alpha < 1.0:
        raise ValueError(f"family_alpha must lie in (0, 1), got {family_alpha!r}")
    return 1.0 - (1.0 - family_alpha) ** (1.0 / num_tests)


# ---------------------------------------------------------------------------------------------------------- result


@dataclass(frozen=True)
class Chi2Result:
    """The outcome of one goodness-of-fit test.

    :meth:`passed` applies every check (the p-value, the hard failures and the pdf's normalisation);
    :meth:`failures` says in words why a test did not pass; :meth:`line` is a one-line summary.

    Attributes
    ----------
    name : str
        Label given to the test.
    statistic, dof, p_value : float, int, float
        Pearson's ``X^2`` over the pooled cells, its degrees of freedom (cells - 1) and ``P(chi^2_dof >= X^2)``
        (nan when no degree of freedom is left).
    n_samples, n_bins, n_cells, pooled_bins : int
        Samples drawn; bins before pooling; cells entering the statistic after pooling; bins merged into the pooled
        cell (expected count < ``min_expected``).
    pdf_integral : float
        Integral of the pdf over the domain (the sum of the probabilities for a discrete test); ~1 when correct.
    out_of_domain : int
        Samples outside the domain or not finite (hard failure).
    zero_bin_hits, impossible : int
        Samples in bins whose expected count is ~0, and of those the samples at which the pdf itself is 0 (hard
        failure).
    observed, expected : numpy.ndarray
        Counts per bin and ``n`` times each bin's probability, in the shape of the bin grid.
    """

    name: str
    statistic: float
    dof: int
    p_value: float
    n_samples: int
    n_bins: int
    n_cells: int
    pooled_bins: int
    pdf_integral: float
    out_of_domain: int
    zero_bin_hits: int
    impossible: int
    observed: np.ndarray = field(repr=False, compare=False, default=None)
    expected: np.ndarray = field(repr=False, compare=False, default=None)

    def failures(self, alpha: float, integral_tol: float = 1e-3) -> list[str]:
        """Why the test fails at significance ``alpha``; empty when it passes.

        Parameters
        ----------
        alpha : float
            Significance level: the test fails when ``p < alpha`` (see :func:`sidak_alpha`).
        integral_tol : float, optional
            Allowed ``|pdf_integral - 1|``; the default 1e-3 is well above the quadrature's error for smooth pdfs.

        Returns
        -------
        list of str
            One sentence per failed check.
        """
        out = []
        if self.out_of_domain:
            out.append(f"{self.out_of_domain} samples outside the domain or not finite")
        if self.impossible:
            out.append(f"{self.impossible} samples where the pdf is 0 (in bins expecting ~0)")
        if not abs(self.pdf_integral - 1.0) <= integral_tol:
            out.append(f"pdf integrates to {self.pdf_integral:.6g}, not 1 (tolerance {integral_tol:g})")
        if self.dof < 1:
            out.append("no degrees of freedom left after pooling")
        elif not self.p_value >= alpha:
            out.append(f"p = {self.p_value:.3g} < alpha = {alpha:.3g} (chi2 = {self.statistic:.6g}, dof = {self.dof})")
        return out

    def passed(self, alpha: float, integral_tol: float = 1e-3) -> bool:
        """True when :meth:`failures` finds nothing."""
        return not self.failures(alpha, integral_tol)

    def line(self) -> str:
        """``chi2 <name>: p = <value>`` plus the statistic, dof and pdf integral."""
        return (
            f"chi2 {self.name}: p = {self.p_value:.6g} (chi2 = {self.statistic:.6g}, dof = {self.dof}, "
            f"pdf integral = {self.pdf_integral:.6f}, n = {self.n_samples})"
        )


# -------------------------------------------------------------------------------------------------------- core


def pooled_statistic(
    observed: np.ndarray, expected: np.ndarray, min_expected: float = MIN_EXPECTED
) -> tuple[float, int, int, int]:
    """Pearson's statistic over bins after pooling those that expect too few samples.

    Parameters
    ----------
    observed, expected : array_like
        Counts and expected counts per bin (any shape, the same size).
    min_expected : float, optional
        Bins expecting fewer samples are summed into one cell; if that cell still expects fewer than
        ``min_expected`` it is merged into the smallest regular cell.

    Returns
    -------
    statistic : float
        ``sum (O - E)^2 / E`` over the cells; infinite when a cell expecting 0 holds samples.
    dof : int
        ``cells - 1`` (the total count is fixed).
    cells : int
        Cells entering the statistic (cells with ``O = E = 0`` are dropped).
    pooled : int
        Bins merged into the pooled cell.
    """
    observed = np.asarray(observed, float).ravel()
    expected = np.asarray(expected, float).ravel()
    if observed.shape != expected.shape:
        raise ValueError(f"observed has {observed.size} bins, expected {expected.size}")
    low = expected < min_expected
    obs = observed[~low]
    exp = expected[~low]
    pooled = int(np.count_nonzero(low))
    if pooled:
        po, pe = observed[low].sum(), expected[low].sum()
        if pe >= min_expected or len(exp) == 0:
            obs, exp = np.append(obs, po), np.append(exp, pe)
        else:
            i = int(np.argmin(exp))
            obs, exp = obs.copy(), exp.copy()
            obs[i] += po
            exp[i] += pe
    keep = (exp > 0) | (obs > 0)
    obs, exp = obs[keep], exp[keep]
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.where(exp > 0, (obs - exp) ** 2 / exp, np.inf)
    return float(terms.sum()), len(obs) - 1, len(obs), pooled


def _p_value(statistic: float, dof: int) -> float:
    if dof < 1:
        return float("nan")
    return float(chi2_sf(statistic, dof))


def _nodes(quadrature: str, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes in [0, 1] and weights summing to 1 of one bin's quadrature rule."""
    if not (isinstance(order, (int, np.integer)) and order >= 1):
        raise ValueError(f"order must be an integer >= 1, got {order!r}")
    if quadrature == "gauss":
        t, w = np.polynomial.legendre.leggauss(order)
        return 0.5 * (t + 1.0), 0.5 * w
    if quadrature == "midpoint":
        return (np.arange(order) + 0.5) / order, np.full(order, 1.0 / order)
    raise ValueError(f"quadrature must be 'gauss' or 'midpoint', got {quadrature!r}")


def _check_grid(domain: Sequence[tuple[float, float]], res: Sequence[int]) -> None:
    if len(domain) != len(res):
        raise ValueError(f"domain has {len(domain)} axes but res has {len(res)}")
    if not 1 <= len(domain) <= 6:
        raise ValueError(f"domain must have 1 to 6 axes, got {len(domain)}")
    for axis, ((lo, hi), r) in enumerate(zip(domain, res)):
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise ValueError(f"domain axis {axis} must be finite (lo, hi) with lo < hi, got ({lo!r}, {hi!r})")
        if r < 1:
            raise ValueError(f"res must be >= 1 on every axis, got {r!r} on axis {axis}")


def bin_integrals(
    pdf_fn: Callable[..., np.ndarray],
    domain: Sequence[tuple[float, float]],
    res: Sequence[int],
    jacobian: Callable[..., np.ndarray] | None = None,
    quadrature: str = "gauss",
    order: int = 6,
    open_grid: bool = False,
) -> np.ndarray:
    """Integral of ``pdf_fn * jacobian`` over every bin of a regular grid on a box.

    Parameters
    ----------
    pdf_fn : callable
        ``pdf_fn(x0, x1, ...)`` with one flat coordinate array per axis; returns the density at those points.
    domain : sequence of (lo, hi)
        The box, one interval per axis (1 to 6 axes).
    res : sequence of int
        Bins per axis.
    jacobian : callable, optional
        ``jacobian(x0, x1, ...)``: the density of the pdf's measure per unit ``dx0 dx1 ...`` (default 1).
    quadrature : {"gauss", "midpoint"}, optional
        Gauss-Legendre (for smooth pdfs) or the midpoint rule (for pdfs with edges inside bins).
    order : int, optional
        Nodes per axis inside every bin (a tensor product over the axes).
    open_grid : bool, optional
        If true, ``pdf_fn`` and ``jacobian`` get the nodes as an open grid (``numpy.meshgrid(..., sparse=True)``:
        axis ``i``'s ``res[i] * order`` nodes along dimension ``i``, length 1 along the others) and must return
        arrays that broadcast to the full grid's shape. A density that is a product of per-axis factors, or that
        maps each axis separately first (a chart of the sphere), then computes those on the distinct node values
        only; the nodes, weights and the integral are those of the flat call, value for value.

    Returns
    -------
    numpy.ndarray
        Shape ``res``: each bin's probability, ``integral over the bin of pdf(x) J(x) dx``.

    Notes
    -----
    With ``q`` nodes ``t_j`` and weights ``w_j`` on [0, 1] and a bin ``[a, a + h]`` per axis, the integral is
    ``prod(h) * sum_j prod(w_j) f(a + h t_j)``. Gauss-Legendre is exact for polynomials of degree < 2 q; the midpoint
    rule's error at a discontinuity is O(1 / q) of the bin's mass.
    """
    d = len(domain)
    res = tuple(int(r) for r in res)
    _check_grid(domain, res)
    t, w = _nodes(quadrature, order)
    pts, widths = [], []
    for (lo, hi), r in zip(domain, res):
        h = (hi - lo) / r
        edges = lo + h * np.arange(r)
        pts.append((edges[:, None] + h * t[None, :]).ravel())  # (r * order,)
        widths.append(h)
    if np.prod([len(p) for p in pts], dtype=float) > _MAX_NODES:
        raise ValueError("res * order too large; lower the quadrature order or the resolution")
    if open_grid:  # (r0 q, 1, ...), (1, r1 q, ...), ...: the caller broadcasts
        args = np.meshgrid(*pts, indexing="ij", sparse=True)
        shape = tuple(len(p) for p in pts)
    else:
        args = [g.ravel() for g in np.meshgrid(*pts, indexing="ij")]
        shape = args[0].shape
    f = np.broadcast_to(np.asarray(pdf_fn(*args), float), shape)
    if jacobian is not None:
        f = f * np.asarray(jacobian(*args), float)
    f = f.reshape([x for r in res for x in (r, order)])
    # Contract the node axes with the weights: (r0, q, r1, q, ...) -> (r0, r1, ...).
    letters = "abcdefghijkl"
    spec_in = "".join(letters[2 * i] + letters[2 * i + 1] for i in range(d))
    spec_w = ",".join(letters[2 * i + 1] for i in range(d))
    spec_out = "".join(letters[2 * i] for i in range(d))
    integ = np.einsum(f"{spec_in},{spec_w}->{spec_out}", f, *([w] * d))
    return integ * float(np.prod(widths))


def _as_columns(samples, d: int) -> list[np.ndarray]:
    if isinstance(samples, (tuple, list)):
        cols = [np.asarray(c, float).ravel() for c in samples]
    else:
        a = np.asarray(samples, float)
        if d == 1 and a.ndim == 1:
            cols = [a.ravel()]
        elif a.ndim == 2:
            cols = [a[:, i] for i in range(a.shape[1])]
        else:
            raise ValueError(f"expected {d} coordinate arrays or an (n, {d}) array from the sampler, got {a.shape}")
    if len(cols) != d:
        raise ValueError(f"expected {d} coordinate arrays from the sampler, got {len(cols)}")
    if len({len(c) for c in cols}) != 1:
        raise ValueError(f"the sampler's coordinate arrays differ in length: {[len(c) for c in cols]}")
    return cols


def chi2_test(
    sample_fn: Callable[[int], object],
    pdf_fn: Callable[..., np.ndarray],
    domain: Sequence[tuple[float, float]],
    res: int | Sequence[int],
    n_samples: int,
    *,
    name: str = "",
    jacobian: Callable[..., np.ndarray] | None = None,
    quadrature: str = "gauss",
    order: int = 6,
    min_expected: float = MIN_EXPECTED,
    boundary_tol: float = 1e-9,
    zero_tol: float = 1e-12,
) -> Chi2Result:
    """Chi^2 test of a sampler of a continuous box ``domain`` (1 to 6 axes) against its own pdf.

    Parameters
    ----------
    sample_fn : callable
        ``sample_fn(n)`` draws ``n`` samples and returns them in the coordinates the bins live in: a tuple/list of
        one array per axis, or an ``(n, d)`` array (a plain ``(n,)`` array in 1D).
    pdf_fn : callable
        ``pdf_fn(x0, x1, ...)``: the routine's own pdf, in its own measure (solid angle, area, ...), at parameter
        points given as one flat array per axis.
    domain : sequence of (lo, hi)
        The box that is binned; it must cover the pdf's support.
    res : int or sequence of int
        Bins per axis (an int: the same on every axis).
    n_samples : int
        How many samples to draw.
    name : str, optional
        Label of the result.
    jacobian : callable, optional
        ``jacobian(x0, x1, ...)``: d(measure) / (dx0 dx1 ...), default 1 (see the module's parametrisations).
    quadrature : {"gauss", "midpoint"}, optional
        Per-bin quadrature of the pdf: Gauss-Legendre for smooth pdfs, midpoint for pdfs with edges inside bins.
    order : int, optional
        Quadrature nodes per axis and bin (default 6).
    min_expected : float, optional
        Bins expecting fewer samples are pooled (default 5).
    boundary_tol : float, optional
        Samples within this distance (relative to the domain's size) outside the domain are clamped into the edge
        bins; farther ones are out of domain.
    zero_tol : float, optional
        A bin whose probability is <= this counts as expecting ~0 samples; a sample there at which the pdf is 0 is
        impossible.

    Returns
    -------
    Chi2Result
        Call ``result.passed(alpha)`` or ``result.failures(alpha)``.

    Notes
    -----
    ``E_b = n * integral over bin b of pdf * J`` (:func:`bin_integrals`) is not renormalised, so a pdf that does not
    integrate to 1 shows both in ``pdf_integral`` and in the statistic; :func:`pooled_statistic` gives
    ``X^2 = sum (O - E)^2 / E`` and the p-value is ``P(chi^2_{cells - 1} >= X^2)``. The approach is that of
    Mitsuba 3's ``mitsuba.chi2.ChiSquareTest`` [1]_ (references in the module docstring).
    """
    d = len(domain)
    res = (int(res),) * d if np.isscalar(res) else tuple(int(r) for r in res)
    _check_grid(domain, res)
    if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 1):
        raise ValueError(f"n_samples must be an integer >= 1, got {n_samples!r}")
    cols = _as_columns(sample_fn(n_samples), d)
    n = len(cols[0])
    ok = np.ones(n, bool)
    idx = np.zeros(n, np.int64)
    for (lo, hi), r, c in zip(domain, res, cols):
        tol = boundary_tol * (hi - lo)
        ok &= np.isfinite(c) & (c >= lo - tol) & (c <= hi + tol)
        with np.errstate(over="ignore"):  # clipped, and masked by ``ok``, where c is far outside or not finite
            i = np.floor(np.clip((np.nan_to_num(c) - lo) / (hi - lo) * r, -1.0, r)).astype(np.int64)
        idx = idx * r + np.clip(i, 0, r - 1)
    observed = np.bincount(idx[ok], minlength=int(np.prod(res))).reshape(res).astype(float)
    prob = bin_integrals(pdf_fn, domain, res, jacobian, quadrature, order)
    expected = n * prob
    zero = prob.ravel() <= zero_tol
    in_zero = ok & zero[idx]
    zero_bin_hits = int(np.count_nonzero(in_zero))
    impossible = 0
    if zero_bin_hits:
        pts = [c[in_zero] for c in cols]
        p = np.broadcast_to(np.asarray(pdf_fn(*pts), float), pts[0].shape)
        if jacobian is not None:
            p = p * np.asarray(jacobian(*pts), float)
        impossible = int(np.count_nonzero(~(p > 0)))
    statistic, dof, cells, pooled = pooled_statistic(observed, expected, min_expected)
    return Chi2Result(
        name=name, statistic=statistic, dof=dof, p_value=_p_value(statistic, dof), n_samples=n,
        n_bins=int(np.prod(res)), n_cells=cells, pooled_bins=pooled, pdf_integral=float(prob.sum()),
        out_of_domain=int(n - np.count_nonzero(ok)), zero_bin_hits=zero_bin_hits, impossible=impossible,
        observed=observed, expected=expected,
    )


def chi2_test_2d(
    sample_fn: Callable[[int], object],
    pdf_fn: Callable[[np.ndarray, np.ndarray], np.ndarray],
    domain: tuple[tuple[float, float], tuple[float, float]],
    res: int | tuple[int, int],
    n_samples: int,
    **kwargs,
) -> Chi2Result:
    """Chi^2 test of a sampler of a continuous 2D parameter domain against its pdf.

    Parameters
    ----------
    sample_fn : callable
        ``sample_fn(n)`` returns ``(x, y)`` arrays or an ``(n, 2)`` array, in the coordinates the bins live in.
    pdf_fn : callable
        ``pdf_fn(x, y)``: the routine's own pdf, in its own measure (solid angle, area, ...).
    domain : ((x0, x1), (y0, y1))
        The box that is binned; it must cover the pdf's support.
    res : int or (int, int)
        Bins per axis.
    n_samples : int
        How many samples to draw.
    **kwargs
        ``name``, ``jacobian``, ``quadrature``, ``order``, ``min_expected``, ``boundary_tol``, ``zero_tol`` as in
        :func:`chi2_test`.

    Returns
    -------
    Chi2Result
    """
    return chi2_test(sample_fn, pdf_fn, domain, res, n_samples, **kwargs)


def chi2_test_1d(
    sample_fn: Callable[[int], np.ndarray],
    pdf_fn: Callable[[np.ndarray], np.ndarray],
    domain: tuple[float, float],
    res: int,
    n_samples: int,
    **kwargs,
) -> Chi2Result:
    """Chi^2 test of a sampler of an interval ``domain = (a, b)`` against its pdf.

    Parameters
    ----------
    sample_fn : callable
        ``sample_fn(n)`` returns an ``(n,)`` array.
    pdf_fn : callable
        ``pdf_fn(x)``: the density on the interval.
    domain : (float, float)
        The interval that is binned.
    res : int
        Number of bins.
    n_samples : int
        How many samples to draw.
    **kwargs
        As in :func:`chi2_test`.

    Returns
    -------
    Chi2Result
    """
    return chi2_test(sample_fn, pdf_fn, (tuple(domain),), res, n_samples, **kwargs)


def chi2_test_discrete(
    samples: np.ndarray, probabilities: np.ndarray, *, name: str = "", min_expected: float = MIN_EXPECTED
) -> Chi2Result:
    """Chi^2 test of discrete choices against the probabilities they should follow.

    Parameters
    ----------
    samples : array_like of int
        The choices, outcomes ``0 .. K-1``.
    probabilities : array_like of float
        ``K`` probabilities (non-negative; they should sum to 1, which ``pdf_integral`` reports).
    name : str, optional
        Label of the result.
    min_expected : float, optional
        Outcomes expecting fewer samples are pooled (default 5).

    Returns
    -------
    Chi2Result
        ``out_of_domain`` counts choices outside ``0 .. K-1`` or not integers; ``impossible`` counts choices of a
        zero-probability outcome.
    """
    samples = np.asarray(samples).ravel()
    p = np.asarray(probabilities, float).ravel()
    if p.size == 0 or not np.all(np.isfinite(p)) or np.any(p < 0):
        raise ValueError("probabilities must be a non-empty array of finite values >= 0")
    if samples.dtype.kind not in "iub" and not np.issubdtype(samples.dtype, np.floating):
        raise ValueError(f"samples must be integers, got dtype {samples.dtype}")
    k = len(p)
    with np.errstate(invalid="ignore"):
        ok = (samples >= 0) & (samples < k) & (np.floor(samples) == samples)
    observed = np.bincount(samples[ok].astype(np.int64), minlength=k).astype(float)
    n = len(samples)
    expected = n * p
    impossible = int(observed[p <= 0].sum())
    statistic, dof, cells, pooled = pooled_statistic(observed, expected, min_expected)
    return Chi2Result(
        name=name, statistic=statistic, dof=dof, p_value=_p_value(statistic, dof), n_samples=n, n_bins=k,
        n_cells=cells, pooled_bins=pooled, pdf_integral=float(p.sum()), out_of_domain=int(n - np.count_nonzero(ok)),
        zero_bin_hits=impossible, impossible=impossible, observed=observed, expected=expected,
    )


# ------------------------------------------------------------------------------------------ parametrisations


def directions_to_cos_phi(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spherical coordinates about +z of directions, for binning in :data:`SPHERE_COS_PHI`.

    Parameters
    ----------
    d : array_like, shape (n, 3)
        Directions; they need not be exactly unit length (each is divided by its norm).

    Returns
    -------
    cos_theta : numpy.ndarray, shape (n,)
        ``d_z / |d|`` (nan for a zero vector, which the test then counts as out of domain).
    phi : numpy.ndarray, shape (n,)
        ``atan2(d_y, d_x)`` wrapped into ``[0, 2 pi)``.
    """
    d = np.asarray(d, float)
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"directions must have shape (n, 3), got {d.shape}")
    norm = np.linalg.norm(d, axis=1)
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * np.pi)
    with np.errstate(divide="ignore", invalid="ignore"):
        return d[:, 2] / norm, phi


def cos_phi_to_directions(c: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit directions ``(sin theta cos phi, sin theta sin phi, cos theta)``, shape ``(..., 3)``; inverse of
    :func:`directions_to_cos_phi` (``cos theta`` is clamped into [-1, 1] for the sine)."""
    c = np.asarray(c, float)
    phi = np.asarray(phi, float)
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    return np.stack([s * np.cos(phi), s * np.sin(phi), c], axis=-1)


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A right-handed orthonormal frame ``(s, t, n)`` about one vector, by Gram-Schmidt.

    Parameters
    ----------
    n : array_like, shape (3,)
        The frame's z axis (normalised here; must not be zero).

    Returns
    -------
    s, t, n : numpy.ndarray, shape (3,)
        ``s`` is the coordinate axis least aligned with ``n`` made orthogonal to it, ``t = n x s``.

    Notes
    -----
    Deliberately simple, so that it is independent of whatever frame construction the code under test uses.
    """
    n = np.asarray(n, float)
    length = np.linalg.norm(n)
    if n.shape != (3,) or not (np.isfinite(length) and length > 0):
        raise ValueError(f"n must be one finite non-zero 3-vector, got {n!r}")
    n = n / length
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    s = helper - n * (helper @ n)
    s /= np.linalg.norm(s)
    return s, np.cross(n, s), n


def to_local(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """World directions ``d`` (m, 3) expressed in the frame :func:`orthonormal_basis` builds about ``n``."""
    s, t, nn = orthonormal_basis(n)
    d = np.asarray(d, float)
    return np.stack([d @ s, d @ t, d @ nn], axis=-1)
