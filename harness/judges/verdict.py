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
Where the variance ratios of adjacent tiles (the less certain image's to the
other's) are far more dispersed than their dof say (:func:`_dispersion_dof`:
fewer than :data:`DISPERSED_DOF`; a tile drew a rare sample or drew none), the
tile's dof are capped by that dispersion (docs/verdict.md, "Variance estimates
more dispersed than their dof").

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

from harness.judges.distributions import chi2_sf, normal_isf, normal_sf, student_t_sf

__all__ = ["CHANNELS", "ROUNDING_RTOL", "SUBTESTS", "ImageError", "TileMaps", "Verdict", "tile_z_scores", "verdict"]

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
#: A tile's degrees of freedom are capped by those its neighbourhood's variance ratios show (``_dispersion_dof``)
#: where these are fewer than this: estimates that split by factors of 100 between adjacent tiles (a tile drew a rare
#: sample or drew none), not the smooth change of two renderers' relative efficiency across an image
#: (docs/verdict.md, "Variance estimates more dispersed than their dof").
DISPERSED_DOF = 2.0


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
    ``variance_floor``: ``neighbourhood`` (its radius in tiles), ``tiles``
    (tile-channels where the neighbourhood raised either image's variance) and
    ``dispersed`` (tested tile-channels whose dof the dispersion of their
    neighbourhood's variance ratios capped, :data:`DISPERSED_DOF`).
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


def _box(arrays: tuple[np.ndarray, ...], radius: int, guide: np.ndarray, factor: float,
         inside: bool = False) -> list[np.ndarray]:
    """Sums of each of ``arrays`` over the (2 radius + 1)^2 tiles around each tile, per channel, counting only the
    tiles whose ``guide`` lies within ``factor`` of the centre tile's (either way). The window is centred on the
    tile and cut at the grid's edges, or with ``inside`` shifted to lie inside the grid (as many tiles at an edge or
    a corner as in the middle, where the grid is that large)."""
    h, w = guide.shape[:2]
    size = 2 * radius + 1

    def starts(length):
        return np.clip(np.arange(length) - radius, 0, max(length - size, 0)) if inside else np.arange(length) - radius

    row0, col0 = starts(h), starts(w)
    out = [np.zeros(guide.shape) for _ in arrays]
    with np.errstate(invalid="ignore"):
        for dy in range(size):
            rows = row0 + dy
            row_ok = (rows >= 0) & (rows < h)
            rows = np.clip(rows, 0, h - 1)
            for dx in range(size):
                cols = col0 + dx
                ok = row_ok[:, None] & ((cols >= 0) & (cols < w))[None, :]
                cols = np.clip(cols, 0, w - 1)
                g = guide[rows][:, cols]
                alike = ok[..., None] & (g * factor >= guide) & (g <= guide * factor)  # NaN: False
                for total, x in zip(out, arrays):
                    total += np.where(alike, x[rows][:, cols], 0.0)
    return out


def _guide(other_sum: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The other image's variance per pixel of each tile, :math:`W_k / n_k`, which says which tiles are alike
    (:func:`_box`); NaN where it has none (nothing to scale, and like no other tile)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        guide = np.where(n > 0, other_sum / n, 0.0)
    return np.where(guide > 0, guide, np.nan)


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
    guide = _guide(other_sum, n)
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


def _dispersion_dof(v_sum: np.ndarray, other_sum: np.ndarray, n: np.ndarray,
                    radius: int) -> tuple[np.ndarray, np.ndarray]:
    r"""The degrees of freedom one image's tile variances show across each tile's neighbourhood, and how many tiles
    of that window are alike (k).

    If a tile's variance estimate is :math:`V_k = \sigma_k^2 \chi^2_\nu / \nu`, its ratio to the other image's,
    :math:`r_k = V_k / W_k` (the other image as the shape), has :math:`E(r) = \rho` and
    :math:`E[(r_a - r_b)^2] = 2 \mathrm{Var}(r) = 4 \rho^2 / \nu` for two tiles a, b of the same ratio
    :math:`\rho`. Over the adjacent pairs (a tile and its right or lower neighbour, alike by the guide of
    :func:`_neighbourhood_floor`) in the (2 radius + 1)^2 window around each tile, shifted to lie inside the grid,

    .. math:: \nu_d = 4 \sum r_a r_b / \sum (r_a - r_b)^2

    (method of moments; adjacent pairs so that a smooth change of the two estimators' relative efficiency across the
    image does not count as dispersion). inf where no pair differs, the other image has no variance, or ``radius``
    is 0 (k = 1 then). Welch's dof take each pixel's estimate to be :math:`\chi^2` with its nominal dof; where a renderer's
    variance rides on rare, large samples, a tile drew one or none and its ratio is 100 times above or below its
    neighbour's, and :math:`\nu_d` falls below one."""
    if radius <= 0:
        return np.full(v_sum.shape, np.inf), np.ones(v_sum.shape)
    guide = _guide(other_sum, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(np.isfinite(guide), v_sum / other_sum, 0.0)
    squares, products = np.zeros(v_sum.shape), np.zeros(v_sum.shape)
    with np.errstate(invalid="ignore"):
        for first, second in (((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
                              ((slice(None, -1), slice(None)), (slice(1, None), slice(None)))):
            a, b, ga, gb = ratio[first], ratio[second], guide[first], guide[second]
            alike = (ga * GUIDE_FACTOR >= gb) & (gb * GUIDE_FACTOR >= ga)  # NaN: False
            squares[first] += np.where(alike, (a - b) ** 2, 0.0)
            products[first] += np.where(alike, a * b, 0.0)
    sum_squares, sum_products, alike = _box((squares, products, np.ones_like(v_sum)), radius, guide, GUIDE_FACTOR,
                                            inside=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sum_squares > 0, 4.0 * sum_products / sum_squares, np.inf), np.maximum(alike, 1.0)


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


class ImageError(ValueError):
    """A problem in one image's own arrays (``image``: the image as ``verdict``'s ``names`` name it; ``message``:
    what is wrong), ``"<image>: <message>"`` as text; a caller that took the image from a file turns it into that
    file's one-line error."""

    def __init__(self, image: str, message: str):
        super().__init__(f"{image}: {message}" if image else message)
        self.image, self.message = image, message


def _image_error(name: str, message: str) -> ImageError:
    """A problem in one image's own arrays, the image named as ``verdict``'s ``names`` name it."""
    return ImageError(name, message)


def _check_variance(name: str, variance: np.ndarray, image_ok: np.ndarray) -> None:
    """Raise where ``variance`` is NaN, infinite or negative at a pixel of ``image_ok``, naming the image ``name``."""
    bad = ~(np.isfinite(variance) & (variance >= 0)) & image_ok[..., None]
    if bad.any():
        pixels = int(np.count_nonzero(bad.any(axis=-1)))
        raise _image_error(
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
# The verdict's parts, in the order verdict() calls them
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _Pixels:
    r"""The per-pixel terms of the test, over the finite test pixels (0 at the others).

    ``mask``: the finite test pixels, broadcast to (H, W, 3); ``diff``: :math:`\Delta_p = T_p - R_p`; ``vt``, ``vr``:
    :math:`V^T_p`, :math:`V^R_p`; ``v_raw``: :math:`V^T_p + V^R_p`; ``scale``: :math:`\max(|T_p|, |R_p|)`; ``v_eff``:
    :math:`v_p`, ``v_raw`` plus the rounding floor; ``welch_t``, ``welch_r``: each image's
    :math:`(V_p)^2 / (\nu_p + 2)`; ``t``, ``r``: the two images as given; ``nonfinite``: the count of test pixels with
    a non-finite channel."""

    mask: np.ndarray
    diff: np.ndarray
    vt: np.ndarray
    vr: np.ndarray
    v_raw: np.ndarray
    scale: np.ndarray
    v_eff: np.ndarray
    welch_t: np.ndarray
    welch_r: np.ndarray
    t: np.ndarray
    r: np.ndarray
    nonfinite: int


@dataclass(frozen=True, eq=False)
class _Tiles:
    r"""The per-tile sums the sub-tests use, arrays of shape (ceil(H/tile), ceil(W/tile), 3).

    ``n``: the tile's finite test pixels; ``d_sum``: :math:`n D = \sum_p \Delta_p`; ``v_sum``: :math:`n^2 S^2`, the
    tile's :math:`\sum_p v_p` raised by the neighbourhood floor; ``v_raw_sum``: :math:`\sum_p (V^T_p + V^R_p)`;
    ``dof``: the tile's :math:`\nu = \min(\nu_T, \nu_R)`; ``zero``: tiles with pixels and no variance at all;
    ``noisy``: tiles with pixels and some variance; ``sparse``: noisy tiles too sparse to judge; ``tested``: the
    noisy tiles the sub-tests use (not sparse); ``differing``: zero-variance tiles whose images differ beyond
    rounding; ``raised``: tiles where the floor raised either image's variance; ``dispersed``: tiles whose dof the
    dispersion of their neighbourhood's variances capped; ``mean_sum``: the larger of the two
    images' tile sums, :math:`M`. ``image_dof``: per channel, :math:`\min(\nu_T, \nu_R)` over the whole image."""

    n: np.ndarray
    d_sum: np.ndarray
    v_sum: np.ndarray
    v_raw_sum: np.ndarray
    dof: np.ndarray
    zero: np.ndarray
    noisy: np.ndarray
    sparse: np.ndarray
    tested: np.ndarray
    differing: np.ndarray
    raised: np.ndarray
    dispersed: np.ndarray
    mean_sum: np.ndarray
    image_dof: np.ndarray


def _require_variances(test_variance: np.ndarray | None, expected_variance: np.ndarray | None,
                       names: tuple[str, str]) -> None:
    """Raise ``ValueError`` naming the image (by ``names``) that has no variance."""
    if test_variance is None or expected_variance is None:
        which = names[0] if test_variance is None else names[1]
        raise _image_error(
            which,
            "has no variance channels (variance.R, variance.G, variance.B); the statistical verdict needs the "
            "variance of each pixel's estimate (harness render writes them; use zeros for an exact reference)",
        )


def _check_parameters(tile: object, alpha: object, neighbourhood: object) -> tuple[int, float]:
    """``tile`` (an integer >= 1) and ``alpha`` (in (0, 1)) as int and float, ``neighbourhood`` checked (an integer
    >= 0); ``ValueError`` otherwise."""
    if not isinstance(tile, (int, np.integer)) or isinstance(tile, bool) or tile < 1:
        raise ValueError(f"tile must be a positive integer, got {tile!r}")
    if not (0.0 < float(alpha) < 1.0):
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if not isinstance(neighbourhood, (int, np.integer)) or isinstance(neighbourhood, bool) or neighbourhood < 0:
        raise ValueError(f"neighbourhood must be an integer >= 0, got {neighbourhood!r}")
    return int(tile), float(alpha)


def _checked_images(test: np.ndarray, test_variance: np.ndarray, expected: np.ndarray,
                    expected_variance: np.ndarray, test_dof: object, expected_dof: object,
                    names: tuple[str, str]) -> tuple[np.ndarray, ...]:
    """The images as float64 arrays, checked: ``(t, vt, r, vr, nu_t, nu_r)``, ``nu`` each pixel's degrees of
    freedom (inf: exact).

    Raises ``ValueError``, in this order, where ``test`` is not (H, W, 3), another array not of its shape, an
    expected pixel not finite, a variance NaN, infinite or negative at a pixel whose value is finite (every expected
    pixel), or a dof not > 0; an error in an image's own values begins with its name in ``names``."""
    test_name, expected_name = names
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
        raise _image_error(
            expected_name,
            f"{int(expected_bad.sum())} non-finite (NaN/Inf) pixels; a reference must be finite everywhere",
        )
    _check_variance(expected_name, vr, np.ones(expected_bad.shape, dtype=bool))
    _check_variance(test_name, vt, np.all(np.isfinite(t), axis=-1))
    return t, vt, r, vr, _dof_array("test_dof", test_dof, t.shape), _dof_array("expected_dof", expected_dof, t.shape)


def _pixel_terms(t: np.ndarray, vt: np.ndarray, r: np.ndarray, vr: np.ndarray, nu_t: np.ndarray,
                 nu_r: np.ndarray, rtol: float) -> _Pixels:
    r"""The per-pixel terms of the test (:class:`_Pixels`), over the pixels whose test value is finite:

    .. math:: \Delta_p = T_p - R_p, \qquad
              v_p = V^T_p + V^R_p + \left(\mathrm{rtol} \, \max(|T_p|, |R_p|)\right)^2, \qquad
              w_p = \frac{(V_p)^2}{\nu_p + 2}

    the last for each image: the estimate of :math:`\sigma_p^4 / \nu_p` in Welch's form of Satterthwaite's formula
    (Welch 1947, Satterthwaite 1946: the module's [1]), since :math:`E[V^2] = \sigma^4 (1 + 2 / \nu)`; the rounding
    floor is exact (:math:`\nu = \infty`)."""
    ok = np.all(np.isfinite(t), axis=-1)
    m = np.broadcast_to(ok[..., None], t.shape)
    vt = np.where(m, vt, 0.0)
    vr = vr * m
    v_raw = vt + vr
    scale = np.where(m, np.maximum(np.abs(np.where(m, t, 0.0)), np.abs(r)), 0.0)
    return _Pixels(mask=m, diff=np.where(m, t - r, 0.0), vt=vt, vr=vr, v_raw=v_raw, scale=scale,
                   v_eff=v_raw + (rtol * scale) ** 2, welch_t=vt**2 / (nu_t + 2), welch_r=vr**2 / (nu_r + 2),
                   t=t, r=r, nonfinite=int(np.count_nonzero(~ok)))


def _floored(v_sum: np.ndarray, welch_sum: np.ndarray, other_sum: np.ndarray, n: np.ndarray, radius: int,
             less_certain: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    r"""One image's tile variances under the neighbourhood floor: ``(floor, raised, dof, capped)``.

    With :math:`\hat V_j` the floor of :func:`_neighbourhood_floor` (``floor``), the tile's variance is raised to it
    where

    .. math:: \hat V_j > \mathrm{FLOOR\_RATIO} \cdot V_j

    (``raised``, :data:`FLOOR_RATIO`); the tile's degrees of freedom (``dof``) are then the neighbourhood's Welch
    dof, else its own, :math:`\nu = (\sum_p v_p)^2 / \sum_p w_p - 2` (:func:`_welch_dof`). Where this image's
    estimate is the ``less_certain`` of the two and the dispersion of the neighbourhood's variance ratios shows
    fewer than :data:`DISPERSED_DOF` (:func:`_dispersion_dof`, :math:`\nu_d`), the dof are at most
    :math:`\nu_d` (an unraised tile's own estimate) or :math:`k \nu_d` (a raised one's: the neighbourhood's k alike
    tiles pooled; ``capped``: where that lowered them)."""
    floor, nb_dof = _neighbourhood_floor(v_sum, welch_sum, other_sum, n, radius)
    raised = floor > FLOOR_RATIO * v_sum
    dof = np.where(raised, nb_dof, _welch_dof(v_sum, welch_sum))
    if not less_certain.any():  # the other image's variances are measured, not this one's
        return floor, raised, dof, less_certain
    dispersed, alike = _dispersion_dof(v_sum, other_sum, n, radius)
    capped = less_certain & (dispersed < DISPERSED_DOF)
    cap = np.where(raised, alike * dispersed, dispersed)
    capped &= cap < dof
    return floor, raised, np.where(capped, cap, dof), capped


def _differing_tiles(pixels: _Pixels, zero: np.ndarray, rtol: float, tile: int) -> np.ndarray:
    r"""The zero-variance tiles (``zero``) whose images differ: some pixel p with :math:`V^T_p + V^R_p = 0` and

    .. math:: |T_p - R_p| > \mathrm{rtol} \cdot \max(|T_p|, |R_p|)."""
    bad_pixel = pixels.mask & (pixels.v_raw == 0) & (np.abs(pixels.diff) > rtol * pixels.scale)
    return zero & (_tile_sum(bad_pixel.astype(np.float64), tile) > 0)


def _tile_statistics(pixels: _Pixels, tile: int, rtol: float, neighbourhood: int, test_spp: float | None,
                     expected_spp: float | None) -> _Tiles:
    r"""The tiles of :class:`_Tiles`: per tile and channel

    .. math:: n D = \sum_p \Delta_p, \qquad n^2 S^2 = \sum_p v_p + (\hat V^T - V^T)[\mathrm{raised}_T]
              + (\hat V^R - V^R)[\mathrm{raised}_R], \qquad \nu = \min(\nu_T, \nu_R)

    each image's variance raised to its neighbourhood floor where :func:`_floored` says (the other image giving the
    shape), :math:`\nu` the smaller of the two images' Welch dof (the conservative solution of the Behrens-Fisher
    problem, Scheffé 1970: the module's [3]); the noisy tiles too sparse to judge (:func:`_sparse_tiles`, each
    image's variance with its floor) left out of ``tested``; the zero-variance tiles that differ
    (:func:`_differing_tiles`)."""
    p = pixels
    n = _tile_sum(p.mask.astype(np.float64), tile)
    vt_sum, vr_sum = _tile_sum(p.vt, tile), _tile_sum(p.vr, tile)
    wt_sum, wr_sum = _tile_sum(p.welch_t, tile), _tile_sum(p.welch_r, tile)
    v_raw_sum = vt_sum + vr_sum  # only its sign is used: zero exactly where every variance is
    # the dispersion of a tile's variances is measured on the less certain image, the other one giving the shape
    test_less_certain = _welch_dof(vt_sum, wt_sum) <= _welch_dof(vr_sum, wr_sum)
    floor_t, raised_t, dof_t, capped_t = _floored(vt_sum, wt_sum, vr_sum, n, neighbourhood, test_less_certain)
    floor_r, raised_r, dof_r, capped_r = _floored(vr_sum, wr_sum, vt_sum, n, neighbourhood, ~test_less_certain)
    v_sum = (_tile_sum(p.v_eff, tile) + np.where(raised_t, floor_t - vt_sum, 0.0)
             + np.where(raised_r, floor_r - vr_sum, 0.0))
    zero = (n > 0) & (v_raw_sum == 0)
    noisy = (n > 0) & (v_raw_sum > 0)
    mean_sum = np.maximum(np.abs(_tile_sum(np.where(p.mask, p.t, 0.0), tile)), np.abs(_tile_sum(p.r * p.mask, tile)))
    sparse = noisy & _sparse_tiles(mean_sum, np.maximum(vt_sum, np.where(raised_t, floor_t, 0.0)),
                                   np.maximum(vr_sum, np.where(raised_r, floor_r, 0.0)), test_spp, expected_spp)
    image_dof = np.minimum(_welch_dof(p.vt.sum(axis=(0, 1)), p.welch_t.sum(axis=(0, 1))),
                           _welch_dof(p.vr.sum(axis=(0, 1)), p.welch_r.sum(axis=(0, 1))))
    return _Tiles(n=n, d_sum=_tile_sum(p.diff, tile), v_sum=v_sum, v_raw_sum=v_raw_sum,
                  dof=np.minimum(dof_t, dof_r), zero=zero, noisy=noisy, sparse=sparse, tested=noisy & ~sparse,
                  differing=_differing_tiles(p, zero, rtol, tile), raised=raised_t | raised_r,
                  dispersed=capped_t | capped_r, mean_sum=mean_sum,
                  image_dof=image_dof)


def _tile_z(tiles: _Tiles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Welch's statistic of each tested tile and its value on the normal scale: ``(z, dof, z_normal)``,

    .. math:: z = D / S = \frac{\sum_p \Delta_p}{\sqrt{n^2 S^2}}, \qquad
              z_{\mathrm{normal}} = \operatorname{sign}(z) \, \Phi^{-1}\!\left(1 - F_{t,\nu}(-|z|)\right)

    (Welch 1947: the module's [1]; :func:`_to_normal`: the normal quantile of equal tail probability under
    Student's t with the tile's :math:`\nu`). Untested tiles: z = 0, dof = inf."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(tiles.tested, tiles.d_sum / np.sqrt(tiles.v_sum), 0.0)
        dof = np.where(tiles.tested, tiles.dof, np.inf)
    return z, dof, np.where(tiles.tested, _to_normal(z, dof), 0.0)


def _global_bias(tiles: _Tiles) -> dict:
    r"""Sub-test 1, the global bias: per channel c, over the tiles not left out as sparse,

    .. math:: z_c = \frac{\sum_p \Delta_{pc}}{\sqrt{\sum_p v_{pc}}}, \qquad
              p_c = 2 \Phi(-|z_c|), \qquad p = 1 - (1 - \min_c p_c)^{C}

    (the variances as the neighbourhood floor left them; :math:`z_c` referred to Student's t with the image-wide
    :math:`\min(\nu_T, \nu_R)` first, :func:`_to_normal`; Šidák 1967, the module's [2], over the C channels with
    noise in a tested tile). Returns :attr:`Verdict.global_bias`."""
    npix = np.where(tiles.sparse, 0.0, tiles.n).sum(axis=(0, 1))  # per channel: the judged and the exact tiles
    g_d = np.where(tiles.sparse, 0.0, tiles.d_sum).sum(axis=(0, 1))
    g_vraw = np.where(tiles.tested, tiles.v_raw_sum, 0.0).sum(axis=(0, 1))
    g_v = np.where(tiles.sparse, 0.0, tiles.v_sum).sum(axis=(0, 1))
    active = g_vraw > 0
    g_z, g_dof, g_p = np.zeros(3), np.full(3, np.inf), np.ones(3)
    for c in range(3):
        if active[c]:
            g_z[c] = g_d[c] / np.sqrt(g_v[c])
            g_dof[c] = tiles.image_dof[c]
            zc = float(_to_normal(np.array([g_z[c]]), np.array([g_dof[c]]))[0])
            g_p[c] = 2.0 * normal_sf(abs(zc))
    n_active = int(active.sum())
    return {
        "difference": [float(x / k) if k else float("nan") for x, k in zip(g_d, npix)],
        "stderr": [float(np.sqrt(x) / k) if k else float("nan") for x, k in zip(g_v, npix)],
        "z": [float(x) for x in g_z],
        "dof": [None if not np.isfinite(x) else float(x) for x in g_dof],
        "p_values": [float(x) for x in g_p],
        "channels": n_active,
        "p_value": float(_sidak(float(g_p.min()), n_active) if n_active else 1.0),
    }


def _omnibus(z_normal: np.ndarray, tested: np.ndarray) -> dict:
    r"""Sub-test 2, the omnibus chi-square: per channel c, over its :math:`k_c` tested tiles,

    .. math:: X_c = \sum_{\mathrm{tiles}} z_{\mathrm{normal}}^2 \sim \chi^2(k_c), \qquad
              p = \min(1, C \min_c P(\chi^2(k_c) \ge X_c))

    (Bonferroni over the C channels with a tested tile). Returns :attr:`Verdict.omnibus`."""
    o_stat = np.array([float(np.sum(z_normal[..., c][tested[..., c]] ** 2)) for c in range(3)])
    o_dof = np.array([int(tested[..., c].sum()) for c in range(3)])
    o_p = np.array([float(chi2_sf(o_stat[c], o_dof[c])) if o_dof[c] > 0 else 1.0 for c in range(3)])
    o_active = int(np.count_nonzero(o_dof))
    return {
        "statistic": [float(x) for x in o_stat],
        "dof": [int(x) for x in o_dof],
        "p_values": [float(x) for x in o_p],
        "p_value": float(min(1.0, o_active * float(o_p.min())) if o_active else 1.0),
    }


def _max_z(z_normal: np.ndarray, tested: np.ndarray) -> tuple[dict, int]:
    r"""Sub-test 3, the largest tile: over the K tested tile-channels,

    .. math:: p = 1 - \left(1 - 2 \Phi(-\max |z_{\mathrm{normal}}|)\right)^K

    (Šidák 1967: the module's [2]). Returns :attr:`Verdict.max_z` and the flat index of that tile-channel (-1
    where none is tested)."""
    count = int(tested.sum())
    if not count:
        return {"statistic": 0.0, "count": 0, "p_value": 1.0}, -1
    abs_z = np.where(tested, np.abs(z_normal), -1.0)
    flat = int(np.argmax(abs_z))
    zmax = float(abs_z.flat[flat])
    return {"statistic": zmax, "count": count, "p_value": float(_sidak(float(2.0 * normal_sf(zmax)), count))}, flat


def _describe_tile(tiles: _Tiles, index: tuple[int, int, int], tile: int, shape: tuple[int, int], z_value: float,
                   z_normal: float, dof_value: float) -> dict:
    r"""One tile-channel as :attr:`Verdict.worst_tile` holds it: its place and size in pixels, its channel,
    :math:`D = \sum_p \Delta_p / n`, :math:`S = \sqrt{n^2 S^2} / n`, z and dof (None where exact)."""
    i, j, c = index
    y, x = i * tile, j * tile
    n_ij = float(tiles.n[i, j, c])
    return {
        "row": i,
        "col": j,
        "y": y,
        "x": x,
        "height": min(tile, shape[0] - y),
        "width": min(tile, shape[1] - x),
        "channel": CHANNELS[c],
        "pixels": int(n_ij),
        "difference": float(tiles.d_sum[i, j, c] / n_ij),
        "stderr": float(np.sqrt(tiles.v_sum[i, j, c]) / n_ij),
        "z": z_value,
        "z_normal": z_normal,
        "dof": None if not np.isfinite(dof_value) else float(dof_value),
    }


def _worst_tile(tiles: _Tiles, z: np.ndarray, z_normal: np.ndarray, dof: np.ndarray, flat: int, tile: int,
                shape: tuple[int, int]) -> dict | None:
    r""":attr:`Verdict.worst_tile`: the first differing zero-variance tile-channel (z = ±inf, S = 0, the sign of its
    D), else the tested one of largest :math:`|z_{\mathrm{normal}}|` (``flat``, from :func:`_max_z`); None if there
    is neither."""
    if tiles.differing.any():
        first = tuple(int(k) for k in np.argwhere(tiles.differing)[0])
        sign = float(np.sign(tiles.d_sum[first])) or 1.0
        worst = _describe_tile(tiles, first, tile, shape, sign * float("inf"), sign * float("inf"), float("inf"))
        worst["stderr"] = 0.0
        return worst
    if flat < 0:
        return None
    idx = tuple(int(k) for k in np.unravel_index(flat, z.shape))
    return _describe_tile(tiles, idx, tile, shape, float(z[idx]), float(z_normal[idx]), float(dof[idx]))


def _tile_maps(tiles: _Tiles, z_normal: np.ndarray, threshold: float) -> TileMaps:
    r""":class:`TileMaps`: per tested tile :math:`p = 2 \Phi(-|z_{\mathrm{normal}}|)` (1 where untested, 0 where a
    zero-variance tile differs); failing where a zero-variance tile differs or a tested tile's Šidák-corrected
    :math:`1 - (1 - p)^K` is below ``threshold`` (K the tested tile-channels)."""
    count = int(tiles.tested.sum())
    tile_p = np.where(tiles.tested, 2.0 * normal_sf(np.abs(z_normal)), 1.0)
    tile_p = np.where(tiles.differing, 0.0, tile_p)
    with np.errstate(divide="ignore"):  # p = 1 (log1p(-1) = -inf) gives 1, as it should
        sidak = -np.expm1(count * np.log1p(-tile_p)) if count else np.ones_like(tile_p)
    return TileMaps(z=z_normal, p=tile_p, tested=tiles.tested,
                    failing=tiles.differing | (tiles.tested & (sidak < threshold)))


def _sparse_summary(tiles: _Tiles) -> dict:
    r""":attr:`Verdict.sparse`: :data:`MIN_SAMPLES`, the count of sparse tile-channels and their share of the noisy
    tiles' brightness, :math:`\sum_{\mathrm{sparse}} M / \sum_{\mathrm{noisy}} M` (0 without brightness)."""
    bright = float(np.where(tiles.noisy, tiles.mean_sum, 0.0).sum())
    share = float(np.where(tiles.sparse, tiles.mean_sum, 0.0).sum()) / bright if bright > 0 else 0.0
    return {"min_samples": MIN_SAMPLES, "tiles": int(tiles.sparse.sum()), "share": share}


def _failures(global_bias: dict, omnibus: dict, max_z: dict, zero_variance: dict, worst: dict | None,
              sparse: dict, nonfinite: int, threshold: float, test_name: str) -> list[str]:
    """Every cause of a fail, one phrase each: nothing left to judge (every noisy tile sparse), non-finite test
    pixels, a differing zero-variance tile, and each sub-test with p < ``threshold`` (alpha / 3, Bonferroni over
    the three)."""
    failures: list[str] = []
    if sparse["tiles"] and not max_z["count"]:
        failures.append(f"too few samples to judge: each of the {sparse['tiles']} noisy tile-channels holds fewer "
                        f"than {MIN_SAMPLES:g} effective samples (render more samples per pixel)")
    if nonfinite:
        failures.append(f"{nonfinite} non-finite pixels in the {test_name}")
    if zero_variance["differing"]:
        assert worst is not None
        failures.append(
            f"zero-variance tile differs ({zero_variance['differing']} tile-channels; first at y={worst['y']}, "
            f"x={worst['x']}, channel {worst['channel']}, mean difference {worst['difference']:.3g})"
        )
    if global_bias["p_value"] < threshold:
        c = int(np.argmin(global_bias["p_values"]))
        failures.append(
            f"global bias: z = {global_bias['z'][c]:.2f} in {CHANNELS[c]} (mean difference "
            f"{global_bias['difference'][c]:.3g} +- {global_bias['stderr'][c]:.2g}), p = "
            f"{_fmt_p(global_bias['p_value'])} < {_fmt_p(threshold)}"
        )
    if omnibus["p_value"] < threshold:
        c = int(np.argmin(omnibus["p_values"]))
        failures.append(
            f"omnibus: chi2 = {omnibus['statistic'][c]:.1f} on {omnibus['dof'][c]} tiles in {CHANNELS[c]}, p = "
            f"{_fmt_p(omnibus['p_value'])} < {_fmt_p(threshold)}"
        )
    if max_z["p_value"] < threshold and worst is not None:
        failures.append(
            f"max |z| = {max_z['statistic']:.2f} at tile y={worst['y']}, x={worst['x']} in {worst['channel']} "
            f"(of {max_z['count']}), p = {_fmt_p(max_z['p_value'])} < {_fmt_p(threshold)}"
        )
    return failures


def _decision(failures: list[str], global_bias: dict, omnibus: dict, max_z: dict, zero_variance: dict,
              sparse: dict, threshold: float) -> tuple[str, str]:
    """``("fail", the failures joined)`` if there is any, else ``("pass", the smallest sub-test p-value)``; on a
    pass the exact zero-variance tiles, and where some tiles are tested, the sparse ones left out, are added."""
    if failures:
        outcome, reason = "fail", "; ".join(failures)
    else:
        ps = {"global bias": global_bias["p_value"], "omnibus": omnibus["p_value"], "max |z|": max_z["p_value"]}
        smallest = min(ps, key=ps.__getitem__)
        outcome = "pass"
        reason = (f"every sub-test has p >= alpha/3 = {_fmt_p(threshold)} (smallest: {smallest} p = "
                  f"{_fmt_p(ps[smallest])})")
        if zero_variance["tiles"]:
            reason += f"; {zero_variance['tiles']} zero-variance tile-channels match exactly"
    if sparse["tiles"] and max_z["count"]:
        reason += (f"; {sparse['tiles']} tile-channels ({100 * sparse['share']:.2g} % of the brightness) not judged: "
                   f"fewer than {MIN_SAMPLES:g} effective samples")
    return outcome, reason


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
        expected pixel raises ``ValueError``.
    test_variance, expected_variance : (H, W, 3) arrays
        Variance of each pixel's estimate (of the mean); zeros for an exact
        (closed-form) image.  None raises ``ValueError``: the verdict
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
        :math:`\nu = \min(\nu_T, \nu_R)` (Scheffé 1970), each image's from
        Welch's form of Satterthwaite's formula (Welch 1947),
        :math:`\nu = (\sum_p v_p)^2 / \sum_p (v_p^2 / (\nu_p + 2)) - 2`.
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
        raised to it, with their Welch dof; the same window, shifted inside the grid, measures the dispersion of
        the tiles' variance ratios (``_dispersion_dof``), which caps a tile's dof where it shows fewer than
        :data:`DISPERSED_DOF`.
    test_spp, expected_spp : float, optional
        Samples per pixel of each image. With both, a tile is left out of the sub-tests where the other image's
        variance brought to this one's spp predicts fewer than :data:`MIN_SAMPLES` effective samples
        (``_sparse_tiles``); without, only each image's own variance says so.

    Returns
    -------
    Verdict
        See :class:`Verdict`.

    Raises
    ------
    ValueError
        Where an image's own arrays cannot be judged: a variance missing (None), NaN, infinite or negative at a pixel
        whose value is finite, or a non-finite expected pixel (the message begins with the image's name in
        ``names``, e.g. ``"ground truth image: 1 non-finite (NaN/Inf) pixels; ..."``); arrays not all of one (H, W,
        3) shape; a ``tile``, ``alpha``, ``neighbourhood``, ``test_dof`` or ``expected_dof`` out of its range.

    Notes
    -----
    With :math:`\Delta = T - R` and :math:`v = V^T + V^R` (plus the rounding
    floor), per channel c: global :math:`z_c = \sum_p \Delta_{pc} / \sqrt{\sum_p v_{pc}}`,
    :math:`p = 1 - (1 - \min_c 2\Phi(-|z_c|))^{C}`; omnibus
    :math:`X_c = \sum_{tiles} z^2 \sim \chi^2(k_c)`, :math:`p = \min(1, C \min_c p_c)`;
    max :math:`p = 1 - (1 - 2\Phi(-\max|z|))^K`.  Fail if any p < alpha / 3,
    if a zero-variance tile differs, or if a test pixel is not finite.
    """
    _require_variances(test_variance, expected_variance, names)
    tile, alpha = _check_parameters(tile, alpha, neighbourhood)
    t, vt, r, vr, nu_t, nu_r = _checked_images(test, test_variance, expected, expected_variance, test_dof,
                                               expected_dof, names)
    pixels = _pixel_terms(t, vt, r, vr, nu_t, nu_r, rtol)
    tiles = _tile_statistics(pixels, tile, rtol, neighbourhood, test_spp, expected_spp)
    z, dof, z_normal = _tile_z(tiles)
    max_z, flat = _max_z(z_normal, tiles.tested)
    worst = _worst_tile(tiles, z, z_normal, dof, flat, tile, t.shape[:2])
    threshold = alpha / len(SUBTESTS)
    global_bias, omnibus = _global_bias(tiles), _omnibus(z_normal, tiles.tested)
    zero_variance = {"tiles": int(tiles.zero.sum()), "differing": int(tiles.differing.sum())}
    sparse = _sparse_summary(tiles)
    failures = _failures(global_bias, omnibus, max_z, zero_variance, worst, sparse, pixels.nonfinite, threshold,
                         names[0])
    outcome, reason = _decision(failures, global_bias, omnibus, max_z, zero_variance, sparse, threshold)
    return Verdict(
        verdict=outcome,
        reason=reason,
        alpha=alpha,
        threshold=threshold,
        tile=tile,
        nonfinite_pixels=pixels.nonfinite,
        global_bias=global_bias,
        omnibus=omnibus,
        max_z=max_z,
        zero_variance=zero_variance,
        worst_tile=worst,
        variance_dof={"test": _dof_summary(test_dof), "ground_truth": _dof_summary(expected_dof)},
        variance_floor={"neighbourhood": int(neighbourhood), "tiles": int((tiles.raised & tiles.tested).sum()),
                        "dispersed": int((tiles.dispersed & tiles.tested).sum())},
        sparse=sparse,
        tiles=_tile_maps(tiles, z_normal, threshold),
    )
