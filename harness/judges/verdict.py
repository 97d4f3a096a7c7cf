r"""The statistical pass/fail verdict: is a test render consistent with the expected image (the ground truth),
given both images' noise?

Both images are Monte Carlo estimates (or the expected image is exact): per pixel p
and channel c an estimate :math:`T_{pc}` with the variance of that estimate
(of the mean, not of one sample) :math:`V^T_{pc}`, and likewise R, V^R.  Under
the null hypothesis "same expected image", :math:`T - R` has mean 0 and
variance :math:`V^T + V^R` at every pixel, pixels being independent.

Pixels are pooled into ``tile`` x ``tile`` tiles (per channel; partial tiles at
the right and bottom borders count, with their n pixels).  For a tile

.. math:: D = \frac{1}{n}\sum_p (T_p - R_p), \qquad
          S^2 = \frac{1}{n^2}\sum_p (V^T_p + V^R_p), \qquad z = D / S

(Welch's statistic).  Three sub-tests, each over all channels:

1. *global bias*: z of the image-wide mean difference per channel (catches a
   small uniform energy error); two-sided, Šidák-combined over the channels.
2. *omnibus*: per channel, :math:`\sum z^2` over the tiles ~ :math:`\chi^2(k)`
   (catches many small local errors); Bonferroni-combined over the channels.
3. *max |z|*: the largest tile |z| over tiles and channels, Šidák-corrected
   for their number K (catches one strong local error).

The verdict fails if any sub-test's p-value is below alpha / 3 (Bonferroni
over the sub-tests), so a correct renderer fails with probability <= alpha.
Tiles where both variances are zero are compared exactly instead (up to float
rounding); any non-finite test pixel fails the verdict.  ``docs/verdict.md``
explains the choices, the false-alarm rate, the power and the assumptions.

When the variances are themselves estimated from few samples, the degrees of
freedom of each pixel's variance estimate (spp - 1) may be given: a tile's z
is then referred to Student's t and converted to the normal quantile of equal
tail probability before the sub-tests.  Its degrees of freedom are the smaller
of the two images' own (the conservative solution of the Behrens-Fisher
problem [3]), each image's from Welch's form of Satterthwaite's formula [1]
over the tile's pixels, nu = (sum_p v_p)^2 / sum_p v_p^2 / (nu_p + 2) - 2 (the
plug-in v_p^2 / nu_p over-states sigma_p^4 / nu_p by 1 + 2 / nu_p, threefold
for the one degree of freedom of two replicates; the - 2 gives back nu_p where
one pixel dominates).  Pooling the two images' variances into one
Satterthwaite figure is not safe with estimates of one degree of freedom: one
that falls near 0 by chance (a chi-square(1) is below 0.4 % of its mean one
time in twenty) makes the other image look dominant and its many degrees of
freedom make the tile's z look normal, while it is nearly Cauchy.  Without
them, variances are taken as exact (z ~ N(0, 1)).

Before z is formed, each image's variance in a tile is raised to what its
neighbourhood says (:func:`_neighbourhood_floor`) where it is more than
:data:`FLOOR_RATIO` below that: the other image's variance in the tile times
the ratio of the two images' variances over the 5 x 5 tiles around it whose
other image's variance is alike (within :data:`GUIDE_FACTOR`).  Where a
renderer's variance is carried by rare, large samples, most tiles of a render
hold none of them and their own variance estimate is far below its mean; the
floor keeps those tiles' z near their true scale (docs/verdict.md,
"Heavy-tailed estimators"). A tile whose estimate, in either image, holds
fewer than :data:`MIN_SAMPLES` effective samples (:func:`_sparse_tiles`) is
left out of the three sub-tests and counted: its mean is a count of a few
rare samples, not normal (docs/verdict.md, "Tiles too sparse to judge").

References
----------
.. [1] B. L. Welch, "The generalization of 'Student's' problem when several
       different population variances are involved", Biometrika 34, 1947;
       F. E. Satterthwaite, "An approximate distribution of estimates of
       variance components", Biometrics Bulletin 2(6), 1946.
.. [2] Z. Šidák, "Rectangular confidence regions for the means of multivariate
       normal distributions", J. Amer. Statist. Assoc. 62, 1967 (the
       correction is valid for two-sided tests of correlated normal z's).
.. [3] H. Scheffé, "Practical solutions of the Behrens-Fisher problem",
       J. Amer. Statist. Assoc. 65(332), 1970 (the test with min(nu_1, nu_2)
       degrees of freedom keeps its level whatever the variances' ratio).
"""

from __future__ import annotations

import dataclasses
from dataclasses import asdict, dataclass, field

import numpy as np

from harness.core.errors import HarnessError
from harness.judges.distributions import chi2_sf, normal_isf, normal_sf, student_t_sf

__all__ = ["CHANNELS", "ROUNDING_RTOL", "SUBTESTS", "TileMaps", "Verdict", "tile_z_scores", "verdict"]

CHANNELS: tuple[str, str, str] = ("R", "G", "B")
#: Relative tolerance for values that carry no Monte Carlo noise: ~16 float32 ulps.
ROUNDING_RTOL = 1e-6
#: The sub-tests combined by Bonferroni.
SUBTESTS: tuple[str, str, str] = ("global_bias", "omnibus", "max_z")
#: Radius in tiles of the neighbourhood whose variances floor each tile's (``_neighbourhood_floor``):
#: 2 is the 5 x 5 tiles around it (docs/verdict.md, "Heavy-tailed estimators: the neighbourhood floor").
NEIGHBOURHOOD = 2
#: A tile's variance is raised to its neighbourhood's only where it is more than this factor below it: ordinary
#: sampling noise of a variance estimate stays within it, a tile that drew none of the rare samples falls far below.
FLOOR_RATIO = 4.0
#: The neighbourhood counts the tiles whose other image's variance per pixel is within this factor of the tile's:
#: the same kind of place (not the quiet sky beside a noisy ground, 1e4 apart), while the rare samples' tiles and
#: their neighbours, whose ground truth varies smoothly (up to 200 x across point-spot's floor), stay in.
GUIDE_FACTOR = 300.0
#: A tile is judged only where each image's estimate of it holds at least this many effective samples,
#: :math:`M^2 / S^2` (``_sparse_tiles``); below it the tile's mean is a count of a few rare samples, not normal.
MIN_SAMPLES = 10.0


@dataclass(frozen=True, eq=False)
class TileMaps:
    r"""The verdict's tiles as maps, one value per tile and channel (arrays of shape (ceil(H/tile), ceil(W/tile), 3)).

    ``z``: the tile's z on the normal scale (``z_normal``: Student's t converted where dof are given; 0 where the
    tile is not tested). ``p``: its two-sided p-value :math:`2\Phi(-|z|)` (1 where not tested; 0 for a differing
    zero-variance tile). ``tested``: tiles with noise (those the three sub-tests use). ``failing``: tiles that fail
    the verdict by themselves: their Šidák-corrected p-value :math:`1 - (1 - p)^K` (K tested tile-channels) is below
    alpha / 3, the max-|z| sub-test's level, or they are zero-variance tiles that differ. Under the null the p-values
    of the tested tiles are uniform on (0, 1) (Jung, Hanika and Dachsbacher, JCGT 2020, show their histogram)."""

    z: np.ndarray
    p: np.ndarray
    tested: np.ndarray
    failing: np.ndarray


@dataclass(frozen=True)
class Verdict:
    """The outcome of :func:`verdict`; :meth:`to_dict` gives plain Python types.

    ``verdict``: ``"pass"`` or ``"fail"``; ``reason``: one line saying why.
    ``alpha``: family-wise false-alarm probability; ``threshold`` = alpha / 3,
    the level each sub-test is held to; ``tile``: tile side in pixels.
    ``nonfinite_pixels``: test pixels with a NaN/Inf channel (left out of the
    statistics; any makes the verdict fail).
    ``global_bias``: ``difference``, ``stderr``, ``z``, ``dof``, ``p_values``
    per channel, ``channels`` tested, ``p_value`` (Šidák over channels).
    ``omnibus``: ``statistic``, ``dof`` (tiles), ``p_values`` per channel and
    ``p_value`` (Bonferroni over channels).
    ``max_z``: ``statistic`` (largest |z|, normal scale), ``count`` (K tiles
    x channels), ``p_value`` (Šidák over K).
    ``zero_variance``: ``tiles`` (tile-channels with both variances zero) and
    ``differing`` (those not equal up to rounding).
    ``worst_tile``: the tile-channel with the largest |z| (a differing
    zero-variance tile, z = inf, first): ``row``, ``col`` (tile indices),
    ``y``, ``x``, ``height``, ``width`` (pixels), ``channel``, ``difference``
    (D), ``stderr`` (S), ``z`` (D / S), ``z_normal`` (the value the sub-tests
    use), ``dof``; None if there is no tile.
    ``variance_dof``: the degrees of freedom of the variance estimates used
    (None: taken as exact).
    ``variance_floor``: ``neighbourhood`` (its radius in tiles) and ``tiles``
    (tile-channels where the neighbourhood raised either image's variance).
    ``sparse``: ``min_samples`` (:data:`MIN_SAMPLES`), ``tiles`` (noisy tile-channels left out of the sub-tests:
    fewer effective samples than that) and ``share`` (their part of the noisy tiles' summed brightness).
    """

    verdict: str
    reason: str
    alpha: float
    threshold: float
    tile: int
    nonfinite_pixels: int
    global_bias: dict
    omnibus: dict
    max_z: dict
    zero_variance: dict
    worst_tile: dict | None
    variance_dof: dict = field(default_factory=dict)
    variance_floor: dict = field(default_factory=dict)
    sparse: dict = field(default_factory=dict)
    #: the tiles as maps (:class:`TileMaps`); not part of :meth:`to_dict`
    tiles: TileMaps | None = field(default=None, compare=False, repr=False)

    @property
    def passed(self) -> bool:
        return self.verdict == "pass"

    def to_dict(self) -> dict:
        out = asdict(dataclasses.replace(self, tiles=None))
        out.pop("tiles")
        return out


# ---------------------------------------------------------------------------
# Helpers
# ---------------------------------------------------------------------------


def _tile_sum(x: np.ndarray, tile: int) -> np.ndarray:
    """(H, W, C) -> (ceil(H/tile), ceil(W/tile), C) sums over tiles; partial tiles at the borders."""
    h, w, c = x.shape
    th, tw = -(-h // tile), -(-w // tile)
    if (th * tile, tw * tile) != (h, w):
        padded = np.zeros((th * tile, tw * tile, c), dtype=x.dtype)
        padded[:h, :w] = x
        x = padded
    return x.reshape(th, tile, tw, tile, c).sum(axis=(1, 3))


def _box(arrays: tuple[np.ndarray, ...], radius: int, guide: np.ndarray, factor: float) -> list[np.ndarray]:
    """Sums of each of ``arrays`` over the (2 radius + 1)^2 tiles around each tile (those inside the grid), per
    channel, counting only the tiles whose ``guide`` lies within ``factor`` of the centre tile's (either way)."""
    h, w = guide.shape[:2]

    def pad(x, fill):
        padded = np.full((h + 2 * radius, w + 2 * radius) + x.shape[2:], fill)
        padded[radius:radius + h, radius:radius + w] = x
        return padded

    padded, padded_guide = [pad(x, 0.0) for x in arrays], pad(guide, np.nan)
    out = [np.zeros(guide.shape) for _ in arrays]
    with np.errstate(invalid="ignore"):
        for dy in range(2 * radius + 1):
            for dx in range(2 * radius + 1):
                g = padded_guide[dy:dy + h, dx:dx + w]
                alike = (g * factor >= guide) & (g <= guide * factor)  # NaN (outside the grid): False
                for total, x in zip(out, padded):
                    total += np.where(alike, x[dy:dy + h, dx:dx + w], 0.0)
    return out


def _neighbourhood_floor(v_sum: np.ndarray, welch_sum: np.ndarray, other_sum: np.ndarray, n: np.ndarray,
                         radius: int) -> tuple[np.ndarray, np.ndarray]:
    r"""One image's variance in each tile as its neighbourhood says it may be, and that estimate's Welch dof.

    N(j): the tiles within ``radius`` tiles of tile j, inside the grid, whose other image's variance per pixel
    :math:`W_k / n_k` (``other_sum``, ``n``) lies within :data:`GUIDE_FACTOR` of tile j's (the same kind of place:
    not the quiet sky beside a noisy ground); :math:`V_N = \sum_{k \in N(j)} V_k` (``v_sum``), likewise
    :math:`W_N`. The estimate is

    .. math:: \hat V_j = W_j \, V_N / W_N,

    the other image's variance in the tile times the neighbourhood's ratio of the two; its dof Welch's over the
    neighbourhood's pixels (``welch_sum``: their :math:`\sum_p v_p^2 / (\nu_p + 2)`). A tile alike no other
    within the radius (a small light among black pixels) takes the ratio over the whole image. 0 (and inf) where
    the other image has no variance (an exact one) or ``radius`` is 0.

    An estimator whose variance is carried by rare, large samples (a path that reaches a point light from close by,
    a caustic) draws them in only some tiles of a render: in the others the tile's variance estimate is far below
    its mean, and its z far too large although the images agree. The neighbourhood holds up to (2 radius + 1)^2
    times the samples."""
    if radius <= 0:
        return np.zeros_like(v_sum), np.full(v_sum.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        guide = np.where(n > 0, other_sum / n, 0.0)
    guide = np.where(guide > 0, guide, np.nan)  # no variance: nothing to scale, and like no other tile
    nb_v, nb_w, nb_welch, alike = _box((v_sum, other_sum, welch_sum, np.ones_like(v_sum)), radius, guide,
                                       GUIDE_FACTOR)
    # a tile alike no other around it (a small light among black pixels) takes the image's ratio of the two
    counted = np.isfinite(guide)
    lone = alike <= 1
    nb_v, nb_w, nb_welch = (np.where(lone, np.where(counted, x, 0.0).sum(axis=(0, 1)), nb)
                            for x, nb in ((v_sum, nb_v), (other_sum, nb_w), (welch_sum, nb_welch)))
    with np.errstate(divide="ignore", invalid="ignore"):
        floor = np.where(nb_w > 0, other_sum * nb_v / nb_w, 0.0)
    return floor, _welch_dof(nb_v, nb_welch)


def _sparse_tiles(mean_sum: np.ndarray, vt_sum: np.ndarray, vr_sum: np.ndarray, test_spp: float | None,
                  expected_spp: float | None) -> np.ndarray:
    r"""The tiles too sparse to judge: where either image's estimate of the tile holds fewer than
    :data:`MIN_SAMPLES` effective samples,

    .. math:: n_{\mathrm{eff}} = M^2 / \max(V_X, \; V_Y \, n_Y / n_X),

    M the larger of the two images' tile sums, :math:`V_X` an image's tile variance (its floor applied),
    :math:`V_Y n_Y / n_X` the other image's variance brought to this image's spp n (where both spp are known): what
    the other's estimator predicts for it. For a non-negative estimator :math:`M^2 / V` is the Kish effective
    sample size, :math:`n / \mathrm{CV}^2`; where a tile's value comes from a few rare, large samples it is about
    their expected number (a Bernoulli event of probability q in n samples: :math:`n q / (1 - q)`), and a
    render that drew none of them has a variance estimate near 0 and a mean too low, whatever floor is put under
    it. Such a tile's z is not normal at any budget the render could not resolve; it is left out of the three
    sub-tests (counted in ``Verdict.sparse``) rather than judged on a normal tail it does not have."""
    vt_eff, vr_eff = vt_sum, vr_sum
    if test_spp and expected_spp:
        vt_eff = np.maximum(vt_sum, vr_sum * (expected_spp / test_spp))
        vr_eff = np.maximum(vr_sum, vt_sum * (test_spp / expected_spp))
    worst = np.maximum(vt_eff, vr_eff)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (worst > 0) & (mean_sum**2 < MIN_SAMPLES * worst)


def _to_normal(z: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """The normal quantile with the same tail probability as ``z`` under Student's t(dof).

    dof = inf leaves z as it is.  Computed from the upper tail so that large
    |z| keep their precision.
    """
    z = np.asarray(z, dtype=np.float64)
    dof = np.broadcast_to(np.asarray(dof, dtype=np.float64), z.shape)
    out = z.copy()
    finite = np.isfinite(dof) & np.isfinite(z)
    if finite.any():
        tail = student_t_sf(np.abs(z[finite]), dof[finite])
        converted = normal_isf(tail)
        # Where the t tail underflows to 0 the normal quantile is inf; report the largest finite one instead
        # (about 37.5: "at least this many standard deviations"), which is just as decisive and keeps sums finite.
        converted = np.where(np.isfinite(converted), converted, float(normal_isf(np.finfo(float).tiny)))
        out[finite] = np.sign(z[finite]) * converted
    return out


def _sidak(p_min: float, count: int) -> float:
    """P(min of ``count`` p-values <= p_min) under independence: 1 - (1 - p_min)^count."""
    if count <= 0:
        return 1.0
    if p_min >= 1.0:
        return 1.0
    return float(-np.expm1(count * np.log1p(-p_min)))


def _welch_dof(v_sum: np.ndarray, w_sum: np.ndarray) -> np.ndarray:
    """Welch's degrees of freedom of a sum of variance estimates, ``(sum v)^2 / sum v^2 / (nu + 2) - 2`` (given
    both sums); inf where the sum has no estimated part (``w_sum`` = 0: exact variances, or none)."""
    v_sum = np.asarray(v_sum, dtype=np.float64)
    w_sum = np.asarray(w_sum, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(w_sum > 0, v_sum**2 / w_sum - 2.0, np.inf)


def _dof_array(name: str, dof: object, shape: tuple[int, ...]) -> np.ndarray:
    """Per-pixel degrees of freedom of a variance estimate; None means exact (inf)."""
    if dof is None:
        return np.full(shape, np.inf)
    arr = np.asarray(dof, dtype=np.float64)
    if arr.ndim == 2:
        arr = arr[..., None]
    try:
        arr = np.broadcast_to(arr, shape)
    except ValueError:
        raise ValueError(f"{name} must be a scalar or broadcast to {shape}, got shape {arr.shape}") from None
    if np.any(~(arr > 0)):
        raise ValueError(f"{name} must be > 0 (spp - 1 for a sample variance), got min {arr.min()}")
    return arr


def _check_variance(name: str, variance: np.ndarray, image_ok: np.ndarray) -> None:
    bad = ~(np.isfinite(variance) & (variance >= 0)) & image_ok[..., None]
    if bad.any():
        pixels = int(np.count_nonzero(bad.any(axis=-1)))
        raise HarnessError(
            name,
            f"variance is NaN, infinite or negative at {pixels} pixels with a finite value; expected the "
            "variance of each pixel's estimate, >= 0 (one sample per pixel gives no variance: render >= 2 spp)",
        )


def _dof_summary(dof: object) -> float | dict | None:
    if dof is None:
        return None
    arr = np.asarray(dof, dtype=np.float64)
    return float(arr) if arr.ndim == 0 else {"min": float(arr.min()), "max": float(arr.max())}


def _fmt_p(p: float) -> str:
    return f"{p:.3g}"


# ---------------------------------------------------------------------------
# Tile statistics
# ---------------------------------------------------------------------------


def tile_z_scores(
    test: np.ndarray,
    test_variance: np.ndarray,
    expected: np.ndarray,
    expected_variance: np.ndarray,
    tile: int = 8,
) -> np.ndarray:
    r"""Welch z of every tile and channel: :math:`z = D / S` with D, S as in the module docstring.

    Returns an array of shape (ceil(H/tile), ceil(W/tile), 3); NaN for tiles
    with zero variance in both images (or with no finite test pixel).  A
    diagnostic view of what :func:`verdict` tests (without its rounding floor).
    """
    t = np.asarray(test, dtype=np.float64)
    r = np.asarray(expected, dtype=np.float64)
    ok = np.all(np.isfinite(t), axis=-1)[..., None]
    d = _tile_sum(np.where(ok, t - r, 0.0), tile)
    v_pix = np.asarray(test_variance, np.float64) + np.asarray(expected_variance, np.float64)
    v = _tile_sum(np.where(ok, v_pix, 0.0), tile)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(v > 0, d / np.sqrt(v), np.nan)


# ---------------------------------------------------------------------------
# The verdict
# ---------------------------------------------------------------------------


def verdict(
    test: np.ndarray,
    test_variance: np.ndarray | None,
    expected: np.ndarray,
    expected_variance: np.ndarray | None,
    *,
    tile: int = 8,
    alpha: float = 0.01,
    test_dof: float | np.ndarray | None = None,
    expected_dof: float | np.ndarray | None = None,
    rtol: float = ROUNDING_RTOL,
    names: tuple[str, str] = ("test image", "ground truth image"),
    neighbourhood: int = NEIGHBOURHOOD,
    test_spp: float | None = None,
    expected_spp: float | None = None,
) -> Verdict:
    r"""Decide whether ``test`` and ``expected`` (the ground truth) estimate the same image.

    Parameters
    ----------
    test, expected : (H, W, 3) arrays
        Per-pixel estimates (linear radiance).  Non-finite test pixels make the
        verdict fail and are left out of the statistics; a non-finite
        expected pixel raises :class:`HarnessError`.
    test_variance, expected_variance : (H, W, 3) arrays
        Variance of each pixel's estimate (of the mean); zeros for an exact
        (closed-form) image.  None raises :class:`HarnessError`: the verdict
        needs the variance channels.
    tile : int
        Tile side in pixels (default 8).
    alpha : float
        Family-wise false-alarm probability (default 0.01): each of the three
        sub-tests is held to alpha / 3.
    test_dof, expected_dof : float or array, optional
        Degrees of freedom of each pixel's variance estimate (spp - 1 for the
        sample variance of spp samples).  None: the variance is taken as exact.
        With them each tile's z is referred to Student's t with
        Welch-Satterthwaite degrees of freedom
        :math:`\nu = (\sum_p v_p)^2 / \sum_p (v_p^2 / \nu_p)`.
    rtol : float
        Values that carry no noise are equal if they agree to ``rtol``
        relatively (default 1e-6, ~16 float32 ulps).  Zero-variance tiles are
        compared pixel by pixel: :math:`|T_p - R_p| \le rtol \cdot \max(|T_p|, |R_p|)`.
        In other tiles each pixel's variance gets a rounding floor
        :math:`(rtol \cdot \max(|T_p|, |R_p|))^2`.
    names : (str, str)
        How error messages name the two images (e.g. their file paths).
    neighbourhood : int
        Radius in tiles of the variance floor (default :data:`NEIGHBOURHOOD`; 0: none): each image's variance in a
        tile more than :data:`FLOOR_RATIO` below what the tiles within that radius say (``_neighbourhood_floor``) is
        raised to it, with their Welch dof.
    test_spp, expected_spp : float, optional
        Samples per pixel of each image. With both, a tile is left out of the sub-tests where the other image's
        variance brought to this one's spp predicts fewer than :data:`MIN_SAMPLES` effective samples
        (``_sparse_tiles``); without, only each image's own variance says so.

    Returns
    -------
    Verdict
        See :class:`Verdict`.

    Notes
    -----
    With :math:`\Delta = T - R` and :math:`v = V^T + V^R` (plus the rounding
    floor), per channel c: global :math:`z_c = \sum_p \Delta_{pc} / \sqrt{\sum_p v_{pc}}`,
    :math:`p = 1 - (1 - \min_c 2\Phi(-|z_c|))^{C}`; omnibus
    :math:`X_c = \sum_{tiles} z^2 \sim \chi^2(k_c)`, :math:`p = \min(1, C \min_c p_c)`;
    max :math:`p = 1 - (1 - 2\Phi(-\max|z|))^K`.  Fail if any p < alpha / 3,
    if a zero-variance tile differs, or if a test pixel is not finite.
    """
    test_name, expected_name = names
    if test_variance is None or expected_variance is None:
        which = test_name if test_variance is None else expected_name
        raise HarnessError(
            which,
            "has no variance channels (variance.R, variance.G, variance.B); the statistical verdict needs the "
            "variance of each pixel's estimate (harness render writes them; use zeros for an exact reference)",
        )
    if not isinstance(tile, (int, np.integer)) or isinstance(tile, bool) or tile < 1:
        raise ValueError(f"tile must be a positive integer, got {tile!r}")
    if not (0.0 < float(alpha) < 1.0):
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if not isinstance(neighbourhood, (int, np.integer)) or isinstance(neighbourhood, bool) or neighbourhood < 0:
        raise ValueError(f"neighbourhood must be an integer >= 0, got {neighbourhood!r}")
    tile = int(tile)
    alpha = float(alpha)
    t = np.asarray(test, dtype=np.float64)
    r = np.asarray(expected, dtype=np.float64)
    vt = np.asarray(test_variance, dtype=np.float64)
    vr = np.asarray(expected_variance, dtype=np.float64)
    if t.ndim != 3 or t.shape[2] != 3 or t.shape[0] < 1 or t.shape[1] < 1:
        raise ValueError(f"test must have shape (H, W, 3), got {t.shape}")
    for label, arr in (("test_variance", vt), ("expected", r), ("expected_variance", vr)):
        if arr.shape != t.shape:
            raise ValueError(f"{label} has shape {arr.shape}, expected {t.shape} like test")

    expected_bad = ~np.all(np.isfinite(r), axis=-1)
    if expected_bad.any():
        raise HarnessError(
            expected_name,
            f"{int(expected_bad.sum())} non-finite (NaN/Inf) pixels; a reference must be finite everywhere",
        )
    _check_variance(expected_name, vr, np.ones(expected_bad.shape, dtype=bool))
    ok = np.all(np.isfinite(t), axis=-1)
    nonfinite = int(np.count_nonzero(~ok))
    _check_variance(test_name, vt, ok)
    nu_t = _dof_array("test_dof", test_dof, t.shape)
    nu_r = _dof_array("expected_dof", expected_dof, t.shape)

    m = np.broadcast_to(ok[..., None], t.shape)
    diff = np.where(m, t - r, 0.0)
    vt = np.where(m, vt, 0.0)
    vr = vr * m
    v_raw = vt + vr
    scale = np.where(m, np.maximum(np.abs(np.where(m, t, 0.0)), np.abs(r)), 0.0)
    v_eff = v_raw + (rtol * scale) ** 2
    # sum_p sigma_p^4 / nu_p of each image, estimated (Welch's nu_p + 2); the rounding floor has nu = inf
    welch_t = vt**2 / (nu_t + 2)
    welch_r = vr**2 / (nu_r + 2)

    # --- tiles -------------------------------------------------------------
    n = _tile_sum(m.astype(np.float64), tile)
    d_sum = _tile_sum(diff, tile)
    vt_sum = _tile_sum(vt, tile)
    vr_sum = _tile_sum(vr, tile)
    v_raw_sum = vt_sum + vr_sum  # only its sign is used: zero exactly where every variance is
    v_sum = _tile_sum(v_eff, tile)
    wt_sum, wr_sum = _tile_sum(welch_t, tile), _tile_sum(welch_r, tile)
    # each image's variance in a tile raised to what its neighbourhood says (the other image giving the shape) where
    # it is more than FLOOR_RATIO below that; a raised tile takes the neighbourhood's Welch dof for that image
    floor_t, nb_dof_t = _neighbourhood_floor(vt_sum, wt_sum, vr_sum, n, neighbourhood)
    floor_r, nb_dof_r = _neighbourhood_floor(vr_sum, wr_sum, vt_sum, n, neighbourhood)
    raised_t, raised_r = floor_t > FLOOR_RATIO * vt_sum, floor_r > FLOOR_RATIO * vr_sum
    v_sum = v_sum + np.where(raised_t, floor_t - vt_sum, 0.0) + np.where(raised_r, floor_r - vr_sum, 0.0)
    dof_t = np.where(raised_t, nb_dof_t, _welch_dof(vt_sum, wt_sum))
    dof_r = np.where(raised_r, nb_dof_r, _welch_dof(vr_sum, wr_sum))
    dof_tiles = np.minimum(dof_t, dof_r)
    wider = raised_t | raised_r
    zero_tiles = (n > 0) & (v_raw_sum == 0)
    noisy = (n > 0) & (v_raw_sum > 0)
    # tiles whose estimate holds too few effective samples to be normal are left out of the sub-tests
    mean_sum = np.maximum(np.abs(_tile_sum(np.where(m, t, 0.0), tile)), np.abs(_tile_sum(r * m, tile)))
    sparse = noisy & _sparse_tiles(mean_sum, np.maximum(vt_sum, np.where(raised_t, floor_t, 0.0)),
                                   np.maximum(vr_sum, np.where(raised_r, floor_r, 0.0)), test_spp, expected_spp)
    random_tiles = noisy & ~sparse
    bad_pixel = m & (v_raw == 0) & (np.abs(diff) > rtol * scale)
    differing = zero_tiles & (_tile_sum(bad_pixel.astype(np.float64), tile) > 0)

    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(random_tiles, d_sum / np.sqrt(v_sum), 0.0)
        dof = np.where(random_tiles, dof_tiles, np.inf)
    z_norm = np.where(random_tiles, _to_normal(z, dof), 0.0)

    # --- 1. global bias ----------------------------------------------------
    npix = np.where(sparse, 0.0, n).sum(axis=(0, 1))  # per channel: the pixels of the judged and the exact tiles
    g_d = np.where(sparse, 0.0, d_sum).sum(axis=(0, 1))  # the judged tiles' (and the exact ones')
    g_vraw = np.where(random_tiles, v_raw_sum, 0.0).sum(axis=(0, 1))
    g_v = np.where(sparse, 0.0, v_sum).sum(axis=(0, 1))  # the tiles' variances, raised where their neighbourhood says
    g_nu = np.minimum(_welch_dof(vt.sum(axis=(0, 1)), welch_t.sum(axis=(0, 1))),
                      _welch_dof(vr.sum(axis=(0, 1)), welch_r.sum(axis=(0, 1))))
    g_active = g_vraw > 0
    g_z = np.zeros(3)
    g_dof = np.full(3, np.inf)
    g_p = np.ones(3)
    for c in range(3):
        if g_active[c]:
            g_z[c] = g_d[c] / np.sqrt(g_v[c])
            g_dof[c] = g_nu[c]
            zc = float(_to_normal(np.array([g_z[c]]), np.array([g_dof[c]]))[0])
            g_p[c] = 2.0 * normal_sf(abs(zc))
    n_active = int(g_active.sum())
    g_pvalue = _sidak(float(g_p.min()), n_active) if n_active else 1.0
    g_worst = int(np.argmin(g_p)) if n_active else 0
    global_bias = {
        "difference": [float(x / k) if k else float("nan") for x, k in zip(g_d, npix)],
        "stderr": [float(np.sqrt(x) / k) if k else float("nan") for x, k in zip(g_v, npix)],
        "z": [float(x) for x in g_z],
        "dof": [None if not np.isfinite(x) else float(x) for x in g_dof],
        "p_values": [float(x) for x in g_p],
        "channels": n_active,
        "p_value": float(g_pvalue),
    }

    # --- 2. omnibus chi-square per channel -----------------------------------
    o_stat = np.array([float(np.sum(z_norm[..., c][random_tiles[..., c]] ** 2)) for c in range(3)])
    o_dof = np.array([int(random_tiles[..., c].sum()) for c in range(3)])
    o_p = np.array([float(chi2_sf(o_stat[c], o_dof[c])) if o_dof[c] > 0 else 1.0 for c in range(3)])
    o_active = int(np.count_nonzero(o_dof))
    o_pvalue = min(1.0, o_active * float(o_p.min())) if o_active else 1.0
    omnibus = {
        "statistic": [float(x) for x in o_stat],
        "dof": [int(x) for x in o_dof],
        "p_values": [float(x) for x in o_p],
        "p_value": float(o_pvalue),
    }

    # --- 3. max |z| ----------------------------------------------------------
    count = int(random_tiles.sum())
    abs_z = np.where(random_tiles, np.abs(z_norm), -1.0)
    if count:
        flat = int(np.argmax(abs_z))
        zmax = float(abs_z.flat[flat])
        m_pvalue = _sidak(float(2.0 * normal_sf(zmax)), count)
    else:
        flat, zmax, m_pvalue = -1, 0.0, 1.0
    max_z = {"statistic": zmax, "count": count, "p_value": float(m_pvalue)}

    # --- worst tile ----------------------------------------------------------
    h, w = t.shape[:2]

    def describe(index: tuple[int, int, int], z_value: float, z_normal: float, dof_value: float) -> dict:
        i, j, c = index
        y, x = i * tile, j * tile
        n_ij = float(n[i, j, c])
        return {
            "row": i,
            "col": j,
            "y": y,
            "x": x,
            "height": min(tile, h - y),
            "width": min(tile, w - x),
            "channel": CHANNELS[c],
            "pixels": int(n_ij),
            "difference": float(d_sum[i, j, c] / n_ij),
            "stderr": float(np.sqrt(v_sum[i, j, c]) / n_ij),
            "z": z_value,
            "z_normal": z_normal,
            "dof": None if not np.isfinite(dof_value) else float(dof_value),
        }

    n_differing = int(differing.sum())
    if n_differing:
        first = tuple(int(k) for k in np.argwhere(differing)[0])
        sign = float(np.sign(d_sum[first])) or 1.0
        worst = describe(first, sign * float("inf"), sign * float("inf"), float("inf"))
        worst["stderr"] = 0.0
    elif count:
        idx = tuple(int(k) for k in np.unravel_index(flat, z.shape))
        worst = describe(idx, float(z[idx]), float(z_norm[idx]), float(dof[idx]))
    else:
        worst = None
    zero_variance = {"tiles": int(zero_tiles.sum()), "differing": n_differing}

    # --- decision ------------------------------------------------------------
    threshold = alpha / len(SUBTESTS)
    tile_p = np.where(random_tiles, 2.0 * normal_sf(np.abs(z_norm)), 1.0)
    tile_p = np.where(differing, 0.0, tile_p)
    with np.errstate(divide="ignore"):  # p = 1 (log1p(-1) = -inf) gives 1, as it should
        sidak = -np.expm1(count * np.log1p(-tile_p)) if count else np.ones_like(tile_p)
    tiles = TileMaps(z=z_norm, p=tile_p, tested=random_tiles,
                     failing=differing | (random_tiles & (sidak < threshold)))
    failures: list[str] = []
    n_sparse = int(sparse.sum())
    if n_sparse and not count:
        failures.append(f"too few samples to judge: each of the {n_sparse} noisy tile-channels holds fewer than "
                        f"{MIN_SAMPLES:g} effective samples (render more samples per pixel)")
    if nonfinite:
        failures.append(f"{nonfinite} non-finite pixels in the {test_name}")
    if n_differing:
        assert worst is not None
        failures.append(
            f"zero-variance tile differs ({n_differing} tile-channels; first at y={worst['y']}, x={worst['x']}, "
            f"channel {worst['channel']}, mean difference {worst['difference']:.3g})"
        )
    if g_pvalue < threshold:
        c = g_worst
        failures.append(
            f"global bias: z = {g_z[c]:.2f} in {CHANNELS[c]} (mean difference {global_bias['difference'][c]:.3g} "
            f"+- {global_bias['stderr'][c]:.2g}), p = {_fmt_p(g_pvalue)} < {_fmt_p(threshold)}"
        )
    if o_pvalue < threshold:
        c = int(np.argmin(o_p))
        failures.append(
            f"omnibus: chi2 = {o_stat[c]:.1f} on {o_dof[c]} tiles in {CHANNELS[c]}, p = {_fmt_p(o_pvalue)} "
            f"< {_fmt_p(threshold)}"
        )
    if m_pvalue < threshold and worst is not None:
        failures.append(
            f"max |z| = {zmax:.2f} at tile y={worst['y']}, x={worst['x']} in {worst['channel']} "
            f"(of {count}), p = {_fmt_p(m_pvalue)} < {_fmt_p(threshold)}"
        )
    if failures:
        outcome, reason = "fail", "; ".join(failures)
    else:
        ps = {"global bias": g_pvalue, "omnibus": o_pvalue, "max |z|": m_pvalue}
        smallest = min(ps, key=ps.__getitem__)
        outcome = "pass"
        reason = (
            f"every sub-test has p >= alpha/3 = {_fmt_p(threshold)} (smallest: {smallest} p = "
            f"{_fmt_p(ps[smallest])})"
        )
        if zero_variance["tiles"]:
            reason += f"; {zero_variance['tiles']} zero-variance tile-channels match exactly"
    bright = float(np.where(noisy, mean_sum, 0.0).sum())
    share = float(np.where(sparse, mean_sum, 0.0).sum()) / bright if bright > 0 else 0.0
    if n_sparse and count:
        reason += (f"; {n_sparse} tile-channels ({100 * share:.2g} % of the brightness) not judged: fewer than "
                   f"{MIN_SAMPLES:g} effective samples")

    return Verdict(
        verdict=outcome,
        reason=reason,
        alpha=alpha,
        threshold=threshold,
        tile=tile,
        nonfinite_pixels=nonfinite,
        global_bias=global_bias,
        omnibus=omnibus,
        max_z=max_z,
        zero_variance=zero_variance,
        worst_tile=worst,
        variance_dof={"test": _dof_summary(test_dof), "ground_truth": _dof_summary(expected_dof)},
        variance_floor={"neighbourhood": int(neighbourhood), "tiles": int((wider & random_tiles).sum())},
        sparse={"min_samples": MIN_SAMPLES, "tiles": n_sparse, "share": share},
        tiles=tiles,
    )
