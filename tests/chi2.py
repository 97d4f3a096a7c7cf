"""Chi-square goodness-of-fit tests for sampling routines: does a warp draw from the pdf it claims?

The idea is that of Mitsuba 3's ``ChiSquareTest`` (the code here is written afresh): cut the sample domain into
bins, count where ``n`` samples land, and compare with the counts the routine's *own* pdf predicts,

    expected[bin] = n * integral over the bin of pdf(x) * J(x) dx,

where the integral is computed numerically (Gauss-Legendre or midpoint nodes inside every bin) and ``J`` is the
Jacobian of the parametrisation the bins live in. Bins expecting fewer than ``min_expected`` (5) samples are pooled
into one cell (itself merged into the smallest regular cell if it still expects < 5), so that the chi^2
approximation holds; the statistic sum (O - E)^2 / E over the cells then has
``cells - 1`` degrees of freedom (the total count is fixed), and the p-value is its upper tail.

Besides the p-value, every test reports and checks:

* ``pdf_integral``: the pdf integrated over the whole domain; it must be ~1 (the pdf is normalised and the domain
  covers its support). Expected counts are *not* renormalised, so a wrong normalisation also shows in chi^2.
* ``impossible``: samples that fell in a bin whose expected count is ~0 *and* at which the pdf itself is 0 -- the
  sampler produced a value its pdf calls impossible. This is a hard failure whatever the p-value. (The pointwise
  confirmation keeps a sliver of support that the quadrature nodes of a bin happened to miss from counting.)
* ``out_of_domain``: samples outside the domain (beyond a relative tolerance ``boundary_tol``) or not finite; also a
  hard failure, since the domain must cover the support.

Parametrisations (the Jacobian turns the measure of the sampled space into dx dy of the bins):

* hemisphere / sphere directions in ``(cos theta, phi)`` with ``J = 1`` (d omega = d cos(theta) d phi): use
  :func:`directions_to_cos_phi` and the domain :data:`SPHERE_COS_PHI` (covering the lower hemisphere too, so that a
  direction below the surface is an "impossible" sample rather than an out-of-domain one); ``(phi, z)`` is the same
  with the axes swapped;
* points on a planar region in orthonormal 2D coordinates of its plane with ``J = 1`` (a pdf per unit area);
* ``(theta, phi)`` would need ``J = sin(theta)``: pass ``jacobian=lambda t, p: np.sin(t)``.

Significance: a test passes when ``p >= alpha``. A file running ``m`` such tests should use
:func:`sidak_alpha` (``1 - (1 - 0.01)**(1/m)``, about ``0.01 / m``) so the whole file has a 1 % false-alarm
chance; :data:`FAMILY_ALPHA` is that 1 %.

The bottom of the module defines the *standard set* of chi^2 tests of ``reference_impl``'s warps, light sampling
and pixel filters (:func:`standard_cases`); ``tests/test_sampling_chi2.py`` runs and asserts them, and
:func:`standard_p_values` returns their p-values for any script that wants to quote them
(``python tests/chi2.py`` prints them; from a script: ``sys.path.insert(0, "tests"); import chi2``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy import stats

FAMILY_ALPHA = 0.01
MIN_EXPECTED = 5.0
_MAX_NODES = 20_000_000  # pdf evaluations per test; guards against a res * order too large for memory


def sidak_alpha(num_tests: int, family_alpha: float = FAMILY_ALPHA) -> float:
    """Per-test significance level so that ``num_tests`` independent tests have ``family_alpha`` false alarms."""
    return 1.0 - (1.0 - family_alpha) ** (1.0 / num_tests)


# ---------------------------------------------------------------------------------------------------------- result


@dataclass(frozen=True)
class Chi2Result:
    """The outcome of one goodness-of-fit test. ``passed(alpha)`` applies all checks; ``failures`` says why not."""

    name: str
    statistic: float
    dof: int
    p_value: float
    n_samples: int
    n_bins: int  # bins before pooling
    n_cells: int  # cells entering the statistic, after pooling
    pooled_bins: int  # bins merged into the pooled cell (expected count < min_expected)
    pdf_integral: float  # integral of the pdf over the domain (sum of the probabilities, discrete)
    out_of_domain: int  # samples outside the domain or not finite
    zero_bin_hits: int  # samples in bins whose expected count is ~0
    impossible: int  # of those, samples at which the pdf itself is 0
    observed: np.ndarray = field(repr=False, compare=False, default=None)
    expected: np.ndarray = field(repr=False, compare=False, default=None)

    def failures(self, alpha: float, integral_tol: float = 1e-3) -> list[str]:
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
    """Chi^2 statistic over bins after pooling those expecting < ``min_expected``: (statistic, dof, cells, pooled).

    The low bins are summed into one cell; if that cell still expects fewer than ``min_expected`` it is merged into
    the smallest regular cell. A cell expecting 0 but holding samples gives an infinite statistic.
    """
    observed = np.asarray(observed, float).ravel()
    expected = np.asarray(expected, float).ravel()
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
    return float(stats.chi2.sf(statistic, dof))


def _nodes(quadrature: str, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes in [0, 1] and weights summing to 1 of one bin's quadrature rule."""
    if quadrature == "gauss":
        t, w = np.polynomial.legendre.leggauss(order)
        return 0.5 * (t + 1.0), 0.5 * w
    if quadrature == "midpoint":
        return (np.arange(order) + 0.5) / order, np.full(order, 1.0 / order)
    raise ValueError(f"quadrature must be 'gauss' or 'midpoint', got {quadrature!r}")


def bin_integrals(
    pdf_fn: Callable[..., np.ndarray],
    domain: Sequence[tuple[float, float]],
    res: Sequence[int],
    jacobian: Callable[..., np.ndarray] | None = None,
    quadrature: str = "gauss",
    order: int = 6,
) -> np.ndarray:
    """Integral of ``pdf_fn * jacobian`` over every bin of a regular grid on ``domain`` (shape ``res``).

    ``pdf_fn`` (and ``jacobian``) take one coordinate array per axis. Each bin gets a tensor product of ``order``
    nodes per axis: Gauss-Legendre for smooth pdfs (exact for polynomials of degree < 2 * order), midpoint for pdfs
    with discontinuities inside bins (error O(1 / order) per cut).
    """
    d = len(domain)
    t, w = _nodes(quadrature, order)
    pts, widths = [], []
    for (lo, hi), r in zip(domain, res):
        h = (hi - lo) / r
        edges = lo + h * np.arange(r)
        pts.append((edges[:, None] + h * t[None, :]).ravel())  # (r * order,)
        widths.append(h)
    if np.prod([len(p) for p in pts], dtype=float) > _MAX_NODES:
        raise ValueError("res * order too large; lower the quadrature order or the resolution")
    grid = np.meshgrid(*pts, indexing="ij")
    flat = [g.ravel() for g in grid]
    f = np.asarray(pdf_fn(*flat), float)
    if jacobian is not None:
        f = f * np.asarray(jacobian(*flat), float)
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
        cols = [a.ravel()] if d == 1 and a.ndim == 1 else [a[:, i] for i in range(a.shape[1])]
    if len(cols) != d:
        raise ValueError(f"expected {d} coordinate arrays from the sampler, got {len(cols)}")
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
    """Chi^2 test of a continuous sampler on a box ``domain`` of any dimension (see :func:`chi2_test_2d`)."""
    d = len(domain)
    res = (int(res),) * d if np.isscalar(res) else tuple(int(r) for r in res)
    cols = _as_columns(sample_fn(n_samples), d)
    n = len(cols[0])
    ok = np.ones(n, bool)
    idx = np.zeros(n, np.int64)
    for (lo, hi), r, c in zip(domain, res, cols):
        tol = boundary_tol * (hi - lo)
        ok &= np.isfinite(c) & (c >= lo - tol) & (c <= hi + tol)
        i = np.floor((np.nan_to_num(c) - lo) / (hi - lo) * r).astype(np.int64)
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
        p = np.asarray(pdf_fn(*pts), float)
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
    sample_fn : n -> (x, y) arrays or an (n, 2) array
        Draws ``n`` samples and expresses them in the coordinates the bins live in.
    pdf_fn : (x, y) -> density
        The routine's own pdf, in its own measure (solid angle, area, ...), evaluated at parameter points.
    domain : ((x0, x1), (y0, y1))
        The box that is binned; it must cover the pdf's support.
    res : bins per axis (int or (nx, ny)).
    n_samples : how many samples to draw.
    jacobian : (x, y) -> d(measure) / (dx dy), default 1.
    quadrature, order : "gauss" (smooth pdfs, default order 6) or "midpoint" (pdfs with edges inside bins).
    min_expected : bins expecting fewer samples are pooled (default 5).
    boundary_tol : samples this far (relative to the domain size) outside the domain are clamped into it.
    zero_tol : a bin whose probability is <= this counts as expecting ~0 samples.
    name : label of the result.
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
    """Chi^2 test of a sampler of an interval ``domain = (a, b)`` against its pdf (arguments as in 2D)."""
    return chi2_test(sample_fn, pdf_fn, (tuple(domain),), res, n_samples, **kwargs)


def chi2_test_discrete(
    samples: np.ndarray, probabilities: np.ndarray, *, name: str = "", min_expected: float = MIN_EXPECTED
) -> Chi2Result:
    """Chi^2 test of discrete choices ``samples`` (ints in 0 .. K-1) against ``probabilities`` (length K).

    Choices outside 0 .. K-1 are out of domain; choices of a zero-probability outcome are impossible.
    """
    samples = np.asarray(samples).ravel()
    p = np.asarray(probabilities, float).ravel()
    k = len(p)
    ok = (samples >= 0) & (samples < k)
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

SPHERE_COS_PHI = ((-1.0, 1.0), (0.0, 2.0 * np.pi))  # (cos theta, phi), J = 1
HEMISPHERE_COS_PHI = ((0.0, 1.0), (0.0, 2.0 * np.pi))


def directions_to_cos_phi(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cos theta, phi in [0, 2 pi)) of directions ``d`` (n, 3) about +z; need not be exactly unit length."""
    d = np.asarray(d, float)
    norm = np.linalg.norm(d, axis=1)
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * np.pi)
    return d[:, 2] / norm, phi


def cos_phi_to_directions(c: np.ndarray, phi: np.ndarray) -> np.ndarray:
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    return np.stack([s * np.cos(phi), s * np.sin(phi), c], axis=-1)


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An (s, t, n) frame for one unit vector ``n`` built by Gram-Schmidt, independent of the code under test."""
    n = np.asarray(n, float) / np.linalg.norm(n)
    helper = np.eye(3)[int(np.argmin(np.abs(n)))]
    s = helper - n * (helper @ n)
    s /= np.linalg.norm(s)
    return s, np.cross(n, s), n


def to_local(d: np.ndarray, n: np.ndarray) -> np.ndarray:
    """World directions ``d`` (m, 3) in the frame :func:`orthonormal_basis` builds about ``n``."""
    s, t, nn = orthonormal_basis(n)
    return np.stack([d @ s, d @ t, d @ nn], axis=-1)


# ------------------------------------------------------------------------------ standard set (reference_impl)
#
# Each case draws its uniforms from a fixed seed, so the p-values are reproducible numbers, not a lottery.

N_SAMPLES = 1_000_000
HEMI_RES = (64, 64)  # over SPHERE_COS_PHI: 32 bins of cos theta per hemisphere


def _uniforms(seed: int, n: int, k: int) -> list[np.ndarray]:
    g = np.random.default_rng(seed)
    return [g.random(n) for _ in range(k)]


def _warp_case(name: str, kind: str, seed: int) -> Chi2Result:
    from reference_impl import sampling

    warp = sampling.square_to_cosine_hemisphere if kind == "cosine" else sampling.square_to_uniform_hemisphere
    return chi2_test_2d(
        lambda n: directions_to_cos_phi(warp(*_uniforms(seed, n, 2))),
        lambda c, phi: sampling.hemisphere_pdf(kind, c), SPHERE_COS_PHI, HEMI_RES, N_SAMPLES, name=name,
    )


def hemisphere_world_sampler(kind: str, normal: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """``sample_hemisphere`` about one ``normal`` (repeated), returned in the local frame of that normal."""
    from reference_impl.sampling import sample_hemisphere

    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    world, _, _ = sample_hemisphere(kind, u1, u2, np.repeat(normal[None, :], len(u1), axis=0))
    return to_local(world, normal)


HEMISPHERE_NORMALS = {
    "a": (0.3, -0.5, 0.81),
    "b": (-0.6, 0.7, -0.2),
    "c": (0.02, -0.03, -0.95),  # near -z, the branch Duff et al.'s frame switches on
}


def _world_case(name: str, kind: str, normal, seed: int) -> Chi2Result:
    from reference_impl.sampling import hemisphere_pdf

    return chi2_test_2d(
        lambda n: directions_to_cos_phi(hemisphere_world_sampler(kind, normal, *_uniforms(seed, n, 2))),
        lambda c, phi: hemisphere_pdf(kind, c), SPHERE_COS_PHI, HEMI_RES, N_SAMPLES, name=name,
    )


# The integrator's random dimensions for the indirect direction and the film offset (reference_impl.integrator).
INDIRECT_U1, INDIRECT_U2, FILM_X, FILM_Y = 9, 10, 0, 1


def keyed_uniforms(seed: int, n: int, dims: Sequence[int], branch: int | None = None, depth: int = 0):
    """Uniforms from ``reference_impl.rng``: path keys for path ids 0 .. n-1, optionally a branch's keys."""
    from reference_impl import rng

    keys = rng.path_keys(seed, np.arange(n, dtype=np.uint64))
    if branch is not None:
        keys = rng.branch_keys(keys, branch, depth)
    return [rng.uniform(keys, d) for d in dims]


def _keyed_hemisphere_case(name: str, seed: int) -> Chi2Result:
    from reference_impl import rng
    from reference_impl.sampling import hemisphere_pdf

    depth = 2
    dims = (rng.dimension(depth, INDIRECT_U1), rng.dimension(depth, INDIRECT_U2))
    normal = HEMISPHERE_NORMALS["a"]
    return chi2_test_2d(
        lambda n: directions_to_cos_phi(
            hemisphere_world_sampler("cosine", normal, *keyed_uniforms(seed, n, dims, branch=1, depth=depth))
        ),
        lambda c, phi: hemisphere_pdf("cosine", c), SPHERE_COS_PHI, HEMI_RES, N_SAMPLES, name=name,
    )


def _keyed_square_case(name: str, seed: int) -> Chi2Result:
    """The pair of film dimensions straight: (u_x, u_y) must be uniform on the unit square."""
    from reference_impl import rng

    dims = (rng.dimension(0, FILM_X), rng.dimension(0, FILM_Y))
    return chi2_test_2d(
        lambda n: keyed_uniforms(seed, n, dims), lambda x, y: np.ones_like(x), ((0, 1), (0, 1)), (64, 64),
        N_SAMPLES, name=name, order=1,
    )


# A skewed triangle in the plane (no axis-aligned or 45-degree edges, so no edge runs along bin nodes).
TRIANGLE_2D = np.array([[0.13, 0.21], [1.37, 0.52], [0.46, 1.19]])


def triangle_pdf(tri: np.ndarray, tol: float = 1e-12) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """1 / area inside the 2D triangle ``tri`` (3, 2), 0 outside."""
    a, b, c = tri
    e1, e2 = b - a, c - a
    det = e1[0] * e2[1] - e1[1] * e2[0]
    area = 0.5 * abs(det)

    def pdf(x, y):
        px, py = x - a[0], y - a[1]
        b1 = (px * e2[1] - py * e2[0]) / det
        b2 = (e1[0] * py - e1[1] * px) / det
        inside = (b1 >= -tol) & (b2 >= -tol) & (b1 + b2 <= 1 + tol)
        return np.where(inside, 1.0 / area, 0.0)

    return pdf


def bbox(points: np.ndarray) -> tuple[tuple[float, float], ...]:
    return tuple((float(lo), float(hi)) for lo, hi in zip(points.min(axis=0), points.max(axis=0)))


def triangle_sampler(tri: np.ndarray, warp: Callable | None = None, seed: int = 0):
    """Points A + b1 (B - A) + b2 (C - A) of a 2D triangle from ``warp`` (default square_to_uniform_triangle)."""
    from reference_impl.sampling import square_to_uniform_triangle

    warp = warp or square_to_uniform_triangle

    def sample(n):
        b1, b2 = warp(*_uniforms(seed, n, 2))
        p = tri[0] + b1[:, None] * (tri[1] - tri[0]) + b2[:, None] * (tri[2] - tri[0])
        return p[:, 0], p[:, 1]

    return sample


def _triangle_case(name: str, seed: int) -> Chi2Result:
    return chi2_test_2d(
        triangle_sampler(TRIANGLE_2D, seed=seed), triangle_pdf(TRIANGLE_2D), bbox(TRIANGLE_2D), (48, 48),
        N_SAMPLES, name=name, quadrature="midpoint", order=24,
    )


def rotation(axis, angle: float) -> np.ndarray:
    """Rodrigues rotation matrix about ``axis`` by ``angle`` radians."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


@dataclass(frozen=True)
class PlanarLight:
    """A light polygon given in 2D plane coordinates, placed in 3D by ``origin + R @ (x, y, 0)``."""

    polygon: np.ndarray  # (m, 2) convex, counter-clockwise
    triangles: np.ndarray  # (t, 3) indices into polygon
    R: np.ndarray
    origin: np.ndarray

    def vertices3d(self) -> np.ndarray:
        p = np.column_stack([self.polygon, np.zeros(len(self.polygon))])
        return self.origin + p @ self.R.T

    def to_plane(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, out-of-plane offset) of 3D points."""
        q = (pts - self.origin) @ self.R
        return q[:, 0], q[:, 1], q[:, 2]

    def triangle_areas(self) -> np.ndarray:
        """Areas of the triangles, from the 2D polygon (independently of Geometry.area)."""
        a, b, c = (self.polygon[self.triangles[:, i]] for i in range(3))
        return 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))

    def area(self) -> float:
        x, y = self.polygon[:, 0], self.polygon[:, 1]
        return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))

    def inside(self, x: np.ndarray, y: np.ndarray, tol: float = 1e-12) -> np.ndarray:
        ok = np.ones(np.shape(x), bool)
        m = len(self.polygon)
        for i in range(m):
            a, b = self.polygon[i], self.polygon[(i + 1) % m]
            ok &= (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]) >= -tol
        return ok


def light_geometry(lights: Sequence[tuple[PlanarLight, Sequence[float]]], floor: bool = True):
    """A :class:`reference_impl.geometry.Geometry` of the given (light, radiance) pairs plus a grey floor.

    Triangles of different lights are interleaved in the arrays (and the floor put first), so that the light
    sampler's grouping by ``light_id`` is exercised. Returns the geometry and, per triangle, its row in its light's
    ``triangles`` (-1 for the floor).
    """
    from reference_impl.geometry import Geometry

    verts, tris, emission, light_id, local = [], [], [], [], []
    if floor:
        verts += [[-5, -5, -1], [5, -5, -1], [5, 5, -1]]
        tris.append([0, 1, 2])
        emission.append([0, 0, 0])
        light_id.append(-1)
        local.append(-1)
    per_light = []
    for k, (light, le) in enumerate(lights):
        base = len(verts)
        verts += light.vertices3d().tolist()
        per_light.append([(list(base + t), list(le), k) for t in light.triangles])
    for j in range(max(len(p) for p in per_light)):  # round robin over the lights
        for p in per_light:
            if j < len(p):
                tris.append(p[j][0])
                emission.append(p[j][1])
                light_id.append(p[j][2])
                local.append(j)
    t = len(tris)
    geometry = Geometry(
        vertices=np.array(verts, float), triangles=np.array(tris), material=np.zeros(t, int),
        reflectance=np.array([[0.5, 0.5, 0.5]]), two_sided=np.array([False]), emission=np.array(emission, float),
        light_id=np.array(light_id),
    )
    return geometry, np.array(local)


def rectangle_light() -> PlanarLight:
    """A 0.7 x 0.3 rectangle (the unit square scaled), two triangles, tilted and rotated in 3D."""
    poly = np.array([[0.0, 0.0], [0.7, 0.0], [0.7, 0.3], [0.0, 0.3]])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    return PlanarLight(poly, tris, rotation([0.4, -1.0, 0.7], 1.1), np.array([0.2, 1.5, 0.9]))


def fan_light() -> PlanarLight:
    """A convex hexagon on an ellipse, fanned from one vertex into 4 triangles of very unequal areas."""
    ang = np.radians([0.0, 17.0, 103.0, 148.0, 236.0, 322.0])
    poly = np.column_stack([0.8 * np.cos(ang), 0.45 * np.sin(ang)])
    tris = np.array([[0, i, i + 1] for i in range(1, len(poly) - 1)])
    return PlanarLight(poly, tris, rotation([-0.3, 0.2, 1.0], 2.3), np.array([-0.4, 0.1, 2.0]))


def light_point_sampler(geometry, light: PlanarLight, seed: int, selection: str = "power", reuse: bool = False):
    """Points from ``LightSampler(geometry, selection).sample`` in the plane coordinates of ``light``; with ``reuse``,
    from ``sample(*split_uniform(u1), u2)`` (the stratified sampler's one 2D sample per light sample)."""
    from reference_impl.lights import LightSampler

    sampler = LightSampler(geometry, selection)

    def sample(n):
        if reuse:
            u1, u2 = _uniforms(seed, n, 2)
            k, pts = sampler.sample(*sampler.split_uniform(u1), u2)
        else:
            k, pts = sampler.sample(*_uniforms(seed, n, 4))
        x, y, z = light.to_plane(pts.position)
        if np.any(k != 0) or np.max(np.abs(z)) > 1e-9:
            return np.full(n, np.nan), np.full(n, np.nan)  # off the light: every sample out of domain
        return x, y

    def pdf(x, y):
        return np.where(light.inside(x, y), sampler.pdf_area(np.zeros(len(x), np.int64)), 0.0)

    return sampler, sample, pdf


def _light_points_case(name: str, light: PlanarLight, res, quadrature: str, order: int, seed: int,
                       reuse: bool = False) -> Chi2Result:
    geom, _ = light_geometry([(light, (4.0, 3.0, 2.0))])
    _, sample, pdf = light_point_sampler(geom, light, seed, reuse=reuse)
    return chi2_test_2d(sample, pdf, bbox(light.polygon), res, N_SAMPLES, name=name, quadrature=quadrature, order=order)


def fan_triangle_choices(seed: int, n: int = N_SAMPLES, mutate: Callable | None = None) -> np.ndarray:
    """Which triangle of :func:`fan_light` (its row in ``triangles``) ``LightSampler.sample`` picked, n times.
    ``mutate(sampler)`` may corrupt the sampler first (to prove the test can fail)."""
    from reference_impl.lights import LightSampler

    geom, local = light_geometry([(fan_light(), (4.0, 3.0, 2.0))])
    sampler = LightSampler(geom, "power")
    if mutate is not None:
        mutate(sampler)
    _, pts = sampler.sample(*_uniforms(seed, n, 4))
    return local[pts.triangle]


def _fan_choice_case(name: str, seed: int) -> Chi2Result:
    areas = fan_light().triangle_areas()
    return chi2_test_discrete(fan_triangle_choices(seed), areas / areas.sum(), name=name)


def four_lights() -> list[tuple[PlanarLight, tuple[float, float, float]]]:
    """Four lights of different shapes, sizes and radiances (areas span ~40x, powers ~20x)."""
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    two = np.array([[0, 1, 2], [0, 2, 3]])
    return [
        (PlanarLight(np.array([[0.0, 0.0], [0.6, 0.1], [0.2, 0.5]]), np.array([[0, 1, 2]]), rotation([1, 0, 0], 0.3),
                     np.array([0.0, 0.0, 3.0])), (10.0, 10.0, 10.0)),
        (PlanarLight(sq * [1.2, 0.5], two, rotation([0, 1, 0], 2.0), np.array([1.0, 0.0, 2.0])), (1.0, 5.0, 0.2)),
        (fan_light(), (20.0, 0.5, 0.5)),
        (PlanarLight(sq * 0.15, two, rotation([1, 1, 0], 0.7), np.array([-1.0, 1.0, 2.5])), (0.3, 0.3, 30.0)),
    ]


LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709


def light_selection_samples(selection: str, seed: int, n: int = N_SAMPLES):
    """(LightSampler over :func:`four_lights`, chosen light indices, sampled triangles)."""
    from reference_impl.lights import LightSampler

    sampler = LightSampler(light_geometry(four_lights())[0], selection)
    k, pts = sampler.sample(*_uniforms(seed, n, 4))
    return sampler, k, pts.triangle


def _selection_case(name: str, selection: str, seed: int) -> Chi2Result:
    sampler, k, _ = light_selection_samples(selection, seed)
    return chi2_test_discrete(k, sampler.pdf_select(np.arange(sampler.num_lights)), name=name)


def _global_area_case(name: str, seed: int) -> Chi2Result:
    """``TriangleAreaSampler`` over every triangle of the 4-light scene (floor included): choice vs area / total."""
    from reference_impl.lights import TriangleAreaSampler

    geom, _ = light_geometry(four_lights())
    corners = geom.vertices[geom.triangles]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    pts = TriangleAreaSampler(geom, np.arange(len(areas))).sample(*_uniforms(seed, N_SAMPLES, 3))
    return chi2_test_discrete(pts.triangle, areas / areas.sum(), name=name)


def _filter_case(name: str, filt: str, res: int, quadrature: str, order: int, seed: int) -> Chi2Result:
    from reference_impl.filters import make_filter

    f = make_filter(filt)
    return chi2_test_1d(
        lambda n: f.sample_1d(_uniforms(seed, n, 1)[0])[0], f.pdf_1d, (-f.radius, f.radius), res, N_SAMPLES,
        name=name, quadrature=quadrature, order=order,
    )


def standard_cases() -> dict[str, Callable[[], Chi2Result]]:
    """The standard chi^2 tests of reference_impl, by name; each call runs one test (about 10^6 samples)."""
    cases: dict[str, Callable[[], Chi2Result]] = {
        "cosine_warp": lambda: _warp_case("cosine_warp", "cosine", 101),
        "uniform_warp": lambda: _warp_case("uniform_warp", "uniform", 102),
    }
    for i, (label, normal) in enumerate(HEMISPHERE_NORMALS.items()):
        for j, kind in enumerate(("cosine", "uniform")):
            nm = f"sample_hemisphere_{kind}_n{label}"
            cases[nm] = lambda nm=nm, kind=kind, normal=normal, s=200 + 10 * i + j: _world_case(nm, kind, normal, s)
    cases["keyed_rng_hemisphere_cosine"] = lambda: _keyed_hemisphere_case("keyed_rng_hemisphere_cosine", 301)
    cases["keyed_rng_film_square"] = lambda: _keyed_square_case("keyed_rng_film_square", 302)
    cases["uniform_triangle"] = lambda: _triangle_case("uniform_triangle", 401)
    cases["light_rectangle_points"] = lambda: _light_points_case(
        "light_rectangle_points", rectangle_light(), (56, 24), "gauss", 2, 501
    )
    cases["light_fan_points"] = lambda: _light_points_case(
        "light_fan_points", fan_light(), (48, 32), "midpoint", 24, 502
    )
    cases["light_fan_points_reused_uniform"] = lambda: _light_points_case(
        "light_fan_points_reused_uniform", fan_light(), (48, 32), "midpoint", 24, 504, reuse=True
    )
    cases["light_fan_triangle_choice"] = lambda: _fan_choice_case("light_fan_triangle_choice", 503)
    cases["light_select_power"] = lambda: _selection_case("light_select_power", "power", 601)
    cases["light_select_uniform"] = lambda: _selection_case("light_select_uniform", "uniform", 602)
    cases["global_area_triangle_choice"] = lambda: _global_area_case("global_area_triangle_choice", 603)
    cases["filter_tent"] = lambda: _filter_case("filter_tent", "tent", 100, "gauss", 4, 701)
    cases["filter_gaussian"] = lambda: _filter_case("filter_gaussian", "gaussian", 128, "midpoint", 16, 702)
    return cases


STANDARD_NAMES = tuple(standard_cases())
STANDARD_ALPHA = sidak_alpha(len(STANDARD_NAMES))


def standard_results() -> list[Chi2Result]:
    return [run() for run in standard_cases().values()]


def standard_p_values() -> dict[str, float]:
    """p-value of every test of the standard set, by name (compare each with :data:`STANDARD_ALPHA`)."""
    return {r.name: r.p_value for r in standard_results()}


if __name__ == "__main__":
    print(f"alpha per test = {STANDARD_ALPHA:.3g} (family {FAMILY_ALPHA:g} over {len(STANDARD_NAMES)} tests)")
    for r in standard_results():
        print(r.line(), "ok" if r.passed(STANDARD_ALPHA) else "FAIL: " + "; ".join(r.failures(STANDARD_ALPHA)))
