r"""The verdict's power, measured: the smallest planted error it catches in a correct render.

An error is *planted* into a correct render (a copy; the render itself is not changed) and the planted image is
judged by the real verdict against the real ground truth. Two kinds of error:

* a uniform relative **bias** b: the render becomes :math:`T (1 - b)` (an energy loss of b), its variance
  :math:`V_T (1 - b)^2` (what a renderer with that fault would report);
* a relative error d in one **region** of ``size`` x ``size`` pixels: there :math:`T (1 + d)` and
  :math:`V_T (1 + d)^2`, the rest unchanged. The region is one of typical brightness on the verdict's tile grid
  (:func:`typical_region`), and the same half a tile off the grid, the worst placement (:func:`centre_region`).

For one render (one seed) :func:`smallest_caught` finds the smallest size caught, by doubling (or halving) from a
guess until the verdict's outcome changes, then bisecting in log(size) until the bracket's ratio is at most
``1 + precision``; it reports the bracket's upper end (caught), so each seed's threshold is known to ``precision``
(relative) and never under-states it. This assumes the verdict, once it fails at a size, fails at every larger
size: true of the global-bias z (linear in b) and of large sizes, not exactly of the omnibus and max-|z| sums near a
seed's own noise; :func:`smallest_caught` reports whether the verdict still fails at twice the threshold, and the
calibration counts the seeds where it does not.

Over N seeds the thresholds :math:`t_1 \le \dots \le t_N` give the detection rate at any size x, the fraction of
seeds with :math:`t_i \le x`; the smallest size caught with probability q (default 0.9) is the empirical quantile
:math:`t_{(\lceil qN \rceil)}` (:func:`detection_quantile`), with a distribution-free confidence interval
:math:`[t_{(r)}, t_{(s)}]` from the order statistics, :math:`P(r \le X < s) \ge c` for
:math:`X \sim \mathrm{Bin}(N, q)` (David and Nagaraja, *Order Statistics*, 3rd ed., 2003, section 7.1). A seed
whose correct render already fails (a false alarm) has threshold 0; one not caught up to the largest size tried
has threshold infinity.

References
----------
.. [1] H. A. David, H. N. Nagaraja, "Order Statistics", 3rd ed., Wiley 2003, section 7.1 (confidence intervals for
   quantiles).
.. [2] docs/verdict.md, "Power" (the same figures worked out on paper).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["DEFAULT_PRECISION", "DEFAULT_QUANTILE", "MAX_BIAS", "MAX_REGION_ERROR", "Region", "Threshold",
           "centre_region", "detection_quantile", "first_guess", "plant_bias", "plant_region", "smallest_caught",
           "typical_region"]

#: the detection probability the calibration reports the size for
DEFAULT_QUANTILE = 0.9
#: relative width of each seed's bracket when the bisection stops
DEFAULT_PRECISION = 0.02
#: the confidence of the interval around the quantile
DEFAULT_CONFIDENCE = 0.9
#: the largest bias tried: b = 1 makes the render black
MAX_BIAS = 1.0
#: the largest region error tried (x 1001): beyond it a region error is "not caught"
MAX_REGION_ERROR = 1000.0
#: the smallest size searched: below float32's resolution (2^-24 ~ 6e-8) nothing can be planted
MIN_SIZE = 1e-7
#: the verdict's sub-tests, in the order its result holds them
SUBTESTS = ("global_bias", "omnibus", "max_z")


@dataclass(frozen=True)
class Region:
    """A square of ``size`` pixels with its top-left corner at row ``y``, column ``x``."""

    y: int
    x: int
    size: int

    @property
    def slices(self) -> tuple[slice, slice]:
        return slice(self.y, self.y + self.size), slice(self.x, self.x + self.size)

    def to_dict(self) -> dict:
        return {"y": self.y, "x": self.x, "size": self.size}


def centre_region(height: int, width: int, size: int, tile: int, offset: int = 0) -> Region:
    """The ``size`` x ``size`` region nearest the image's centre whose corner lies on the verdict's tile grid, moved
    by ``offset`` pixels down and right (``tile // 2``: the worst placement for a region twice the tile's side,
    see Notes), kept inside the image; ``size`` is cut to the image's shorter side.

    Notes
    -----
    Along one axis a region of 2t pixels at offset o from a grid of tiles of side t covers one tile wholly and two
    partly, t - o and o pixels; the largest tile z (the max-|z| sub-test) scales with the largest covered fraction,
    max(t - o, o) / t, and the omnibus with the sum of squared fractions, both smallest at o = t / 2. With t = 8
    and a 16 x 16 region that is an offset of (4, 4): one tile wholly inside, four half, four a quarter.
    """
    size = max(1, min(int(size), int(height), int(width)))

    def corner(extent: int) -> int:
        start = max(0, (extent - size) // 2) // tile * tile
        return max(0, min(start + int(offset), extent - size))

    return Region(corner(height), corner(width), size)


def typical_region(truth: np.ndarray, size: int, tile: int, offset: int = 0) -> Region:
    """The ``size`` x ``size`` region of typical brightness: among the positions on the verdict's tile grid (corner
    at multiples of ``tile``, wholly inside the image) the one whose mean ``truth`` (over its pixels and channels)
    is the median of all of them (the lower median; ties: nearest the image's centre), moved by ``offset`` pixels
    down and right (``tile // 2``: the worst placement, :func:`centre_region`), kept inside the image.

    Notes
    -----
    A region at a fixed place can fall where the image is black (the umbra on soft-shadows): a relative error of
    a zero radiance is zero, never caught, and says nothing of the verdict. The median region is a typical part of
    the image, chosen from the ground truth alone, so the same for every seed.
    """
    t = np.nan_to_num(np.asarray(truth, np.float64))
    height, width = t.shape[:2]
    size = max(1, min(int(size), height, width))
    centre = centre_region(height, width, size, tile)
    candidates = []
    for y in range(0, height - size + 1, tile):
        for x in range(0, width - size + 1, tile):
            distance = (y - centre.y) ** 2 + (x - centre.x) ** 2
            candidates.append((float(t[y:y + size, x:x + size].mean()), distance, y, x))
    if not candidates:
        return centre_region(height, width, size, tile, offset)
    by_mean = sorted(candidates)
    median = by_mean[(len(by_mean) - 1) // 2][0]
    _, _, y, x = min((c for c in candidates if c[0] == median), key=lambda c: c[1])
    return Region(min(y + int(offset), height - size), min(x + int(offset), width - size), size)


def plant_bias(image: np.ndarray, variance: np.ndarray, b: float) -> tuple[np.ndarray, np.ndarray]:
    """The render with a uniform relative bias ``b``: :math:`T (1 - b)`, :math:`V (1 - b)^2` (float64 copies)."""
    scale = 1.0 - float(b)
    return np.asarray(image, np.float64) * scale, np.asarray(variance, np.float64) * scale * scale


def plant_region(image: np.ndarray, variance: np.ndarray, d: float, region: Region) -> tuple[np.ndarray, np.ndarray]:
    """The render with the relative error ``d`` in ``region``: there :math:`T (1 + d)`, :math:`V (1 + d)^2`."""
    out, var = np.array(image, np.float64), np.array(variance, np.float64)
    rows, cols = region.slices
    out[rows, cols] *= 1.0 + float(d)
    var[rows, cols] *= (1.0 + float(d)) ** 2
    return out, var


def first_guess(image: np.ndarray, variance: np.ndarray, expected_variance: np.ndarray,
                region: Region | None = None, z: float = 4.0) -> float:
    r"""Where to start the search: the relative error that moves the mean of the image (or of ``region``) by ``z``
    standard errors in its most sensitive channel, :math:`z \sqrt{\sum (V_T + V_R)} / |\sum T|`. Only a start: the
    search brackets the threshold from there whatever the guess."""
    t = np.asarray(image, np.float64)
    v = np.asarray(variance, np.float64) + np.asarray(expected_variance, np.float64)
    if region is not None:
        rows, cols = region.slices
        t, v = t[rows, cols], v[rows, cols]
    finite = np.isfinite(t) & np.isfinite(v)
    sums = np.abs(np.where(finite, t, 0.0).sum(axis=(0, 1)))
    noise = np.sqrt(np.where(finite, v, 0.0).sum(axis=(0, 1)))
    with np.errstate(divide="ignore", invalid="ignore"):
        guesses = np.where(sums > 0, z * noise / sums, np.inf)
    guess = float(np.min(guesses)) if guesses.size else math.inf
    return guess if math.isfinite(guess) and guess > 0 else 0.01


@dataclass(frozen=True)
class Threshold:
    """One seed's smallest caught size: ``size`` (0.0: the correct render already fails, a false alarm; None: not
    caught up to the largest size tried), the ``verdicts`` the search took, the sub-tests that fail at ``size``
    (``caught_by``) and whether the verdict still fails at twice ``size`` (``caught_at_double``; None where not
    checked)."""

    size: float | None
    verdicts: int
    caught_by: tuple[str, ...] = ()
    caught_at_double: bool | None = None

    def to_dict(self) -> dict:
        return {"size": self.size, "verdicts": self.verdicts, "caught_by": list(self.caught_by),
                "caught_at_double": self.caught_at_double}


def failing_subtests(outcome) -> tuple[str, ...]:
    """The sub-tests of a :class:`harness.judges.verdict.Verdict` whose p-value is below its threshold (and
    ``"other"`` for a failure none of them explains: a differing zero-variance tile, a non-finite pixel)."""
    names = tuple(name for name in SUBTESTS if getattr(outcome, name)["p_value"] < outcome.threshold)
    return names if names or outcome.passed else ("other",)


def smallest_caught(judge: Callable[[float], object], *, guess: float, upper: float,
                    precision: float = DEFAULT_PRECISION, check_double: bool = True) -> Threshold:
    """The smallest planted size at which ``judge(size)`` (a :class:`harness.judges.verdict.Verdict` of the render
    with that error planted) fails, to a relative ``precision``: 0.0 if the render fails unplanted, None if it
    passes at ``upper``. Brackets from ``guess`` by doubling or halving (down to :data:`MIN_SIZE`), then bisects in
    log(size) until hi / lo <= 1 + precision, and returns hi (the smallest size seen failing)."""
    count = 0

    def fails(size: float):
        nonlocal count
        count += 1
        outcome = judge(size)
        return (not outcome.passed), outcome

    failed, outcome = fails(0.0)
    if failed:
        return Threshold(0.0, count, failing_subtests(outcome))
    size = min(max(float(guess), MIN_SIZE), upper)
    failed, outcome = fails(size)
    if failed:
        hi, hi_outcome, lo = size, outcome, size / 2.0
        while lo >= MIN_SIZE:
            failed, outcome = fails(lo)
            if not failed:
                break
            hi, hi_outcome, lo = lo, outcome, lo / 2.0
        if lo < MIN_SIZE:  # caught at the resolution of float32: no smaller size is meaningful
            return Threshold(hi, count, failing_subtests(hi_outcome))
    else:
        lo, hi = size, None
        while hi is None:
            if lo >= upper:
                return Threshold(None, count)
            trial = min(lo * 2.0, upper)
            failed, outcome = fails(trial)
            if failed:
                hi, hi_outcome = trial, outcome
            else:
                lo = trial
    while hi / lo > 1.0 + precision:
        mid = math.sqrt(lo * hi)
        failed, outcome = fails(mid)
        if failed:
            hi, hi_outcome = mid, outcome
        else:
            lo = mid
    double = None
    if check_double and hi < upper:
        double, _ = fails(min(2.0 * hi, upper))
    return Threshold(hi, count, failing_subtests(hi_outcome), double)


def detection_quantile(sizes: Sequence[float | None], quantile: float = DEFAULT_QUANTILE,
                       confidence: float = DEFAULT_CONFIDENCE) -> dict:
    r"""The smallest size caught with probability ``quantile`` from each seed's threshold (``None``: not caught,
    infinity), with a distribution-free ``confidence`` interval.

    Returns ``value`` (:math:`t_{(\lceil qN \rceil)}`: at least a fraction q of the seeds are caught there),
    ``interval`` ([:math:`t_{(r)}`, :math:`t_{(s)}`], None for an end beyond the seeds: more seeds needed),
    ``median``, ``runs`` N, ``false_alarms`` (thresholds 0), ``not_caught`` (None) and ``rate`` (the detection
    rate at ``value``). A None ``value``: fewer than a fraction q of the seeds were caught at any size tried.
    """
    from scipy import stats  # optional: 0.9 s; only calibrate's binomial quantiles (scipy.special.bdtr differs)

    values = sorted(math.inf if s is None else float(s) for s in sizes)
    n = len(values)
    if n == 0:
        return {"value": None, "interval": [None, None], "median": None, "runs": 0, "false_alarms": 0,
                "not_caught": 0, "rate": None, "quantile": quantile, "confidence": confidence}
    k = max(1, math.ceil(quantile * n - 1e-9))
    tail = (1.0 - confidence) / 2.0
    cdf = stats.binom.cdf(np.arange(n + 1), n, quantile)
    below = [i for i in range(n + 1) if cdf[i] <= tail]  # X <= r - 1 has probability <= tail
    r = (below[-1] + 1) if below else 0  # 1-based order statistic; 0: no lower end from these seeds
    s = int(np.searchsorted(cdf, 1.0 - tail)) + 1  # X <= s - 1 has probability >= 1 - tail

    def order(i: int) -> float | None:
        if i < 1 or i > n or not math.isfinite(values[i - 1]):
            return None
        return values[i - 1]

    value = order(k)
    finite = [v for v in values if math.isfinite(v)]
    return {
        "value": value, "interval": [order(r) if r >= 1 else 0.0, order(s)],
        "median": float(np.median(values)) if math.isfinite(float(np.median(values))) else None,
        "runs": n, "false_alarms": sum(v == 0.0 for v in values), "not_caught": n - len(finite),
        "rate": (sum(v <= value for v in values) / n) if value is not None else None,
        "quantile": quantile, "confidence": confidence,
    }
