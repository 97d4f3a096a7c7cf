r"""Why a render disagrees with its ground truth: the mistakes a renderer author makes first, each measured.

A failing verdict says *that* two images differ; these statistics say *how*, in terms an author can act on:

* :func:`best_shift`: the integer shift (dx, dy), within a small window, and the mirror (horizontal or vertical
  flip) that bring the test closest to the ground truth: a camera off by a row, an image written upside down, a
  camera whose +x is the image's right.
* :func:`scale_factor`: the one global factor s with test ~ s x ground truth, with its confidence interval, and
  :func:`named_factor`, which names it when it is 1 or a factor of pi (pi, 2 pi, 4 pi and their inverses: a light
  whose power was divided by the sphere's 4 pi steradians, a BSDF missing its 1 / pi).
* :func:`bright_share`: whether the squared difference sits in the brightest pixels (the light, its reflections):
  a light's or a highlight's mistake rather than the indirect light's.

:func:`diagnose` runs all of them. Arrays in, numbers out: images are (H, W, 3) linear radiance, variances the
variance of each pixel's estimate (of the mean), as everywhere in :mod:`harness.judges`.

Examples
--------
A ground truth, and a test that is it moved down by one row (with noise):

>>> import numpy as np
>>> from harness.judges.diagnose import best_shift, scale_factor, named_factor
>>> y, x = np.mgrid[0:32, 0:32] / 32.0
>>> truth = np.repeat((0.2 + x + 0.5 * y ** 2)[..., None], 3, axis=2)
>>> rng = np.random.default_rng(1)
>>> test = np.roll(truth, 1, axis=0) + 0.01 * rng.standard_normal(truth.shape)
>>> found = best_shift(test, truth)
>>> (found["dx"], found["dy"], found["mirror"], found["significant"])
(0, 1, 'none', True)
>>> s = scale_factor(4 * np.pi * truth, truth, np.full(truth.shape, 1e-4), np.zeros(truth.shape))
>>> named_factor(s["scale"], s["low"], s["high"])
'4 pi'
"""

from __future__ import annotations

import math

import numpy as np

from harness.judges.distributions import normal_isf

__all__ = ["MIRRORS", "NAMED_FACTORS", "best_shift", "bright_share", "diagnose", "luminance", "named_factor",
           "scale_factor"]

#: the mirrors :func:`best_shift` tries: none, left-right (columns reversed), top-bottom (rows reversed)
MIRRORS = ("none", "horizontal", "vertical")
#: the factors :func:`named_factor` names: (name, value); a light or a BSDF off by one of these is a convention
#: mistake (radiance against intensity or power, a missing 1 / pi), not a bug in the sampling
NAMED_FACTORS = (("1", 1.0), ("pi", math.pi), ("2 pi", 2 * math.pi), ("4 pi", 4 * math.pi),
                 ("1/pi", 1 / math.pi), ("1/(2 pi)", 1 / (2 * math.pi)), ("1/(4 pi)", 1 / (4 * math.pi)))
#: relative distance within which a factor of pi is named ("about 4 pi") although the interval misses it
NAMED_TOLERANCE = 0.02
#: the median of |X Y| for independent standard normals X, Y (the product's standard deviation is 1): the MAD of
#: a product of two independent centred normals is this times its standard deviation (numerical integration of
#: P(|XY| < t) = integral of (2 Phi(t / y) - 1) 2 phi(y) dy over y > 0)
PRODUCT_MAD = 0.36517
#: Rec. 709 luminance weights of linear RGB (ITU-R BT.709-6, item 3.3)
REC709 = (0.2126, 0.7152, 0.0722)


def luminance(image: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance Y = 0.2126 R + 0.7152 G + 0.0722 B of a linear (H, W, 3) image (ITU-R BT.709-6)."""
    return np.asarray(image, dtype=np.float64) @ np.asarray(REC709)


def _finite(*arrays: np.ndarray | None) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """A (H, W, 3) mask of the entries finite in every given array, and the arrays with the others set to 0."""
    given = [np.asarray(a, dtype=np.float64) for a in arrays if a is not None]
    ok = np.all([np.isfinite(a) for a in given], axis=0)
    return ok, [None if a is None else np.where(ok, np.asarray(a, dtype=np.float64), 0.0) for a in arrays]


def _mirrored(image: np.ndarray, mirror: str) -> np.ndarray:
    return {"none": image, "horizontal": image[:, ::-1], "vertical": image[::-1, :]}[mirror]


def best_shift(test: np.ndarray, expected: np.ndarray, variance: np.ndarray | None = None, *, max_shift: int = 4,
               alpha: float = 0.001, tile: int = 8) -> dict:
    r"""The integer shift and mirror of the ground truth that the test matches best.

    Every candidate (mirror m in :data:`MIRRORS`, dx and dy in -``max_shift`` .. ``max_shift``) is scored by the mean
    weighted squared difference :math:`\bar e_c = \mathrm{mean}_p \sum_{ch} w (T[y, x] - G_m[y - dy, x - dx])^2`
    over the same central crop (``max_shift`` pixels in from every edge; less on a small image), so every candidate
    sees the same pixels: (dx, dy) > 0 means the test shows the ground truth moved right and down. ``variance`` (the
    test's plus the ground truth's, (H, W, 3)) gives the weights w = 1 / its mean over the pixel's ``tile`` x
    ``tile`` block (so that a bright light's noise does not drown the rest of the image); without it w = 1. The
    best candidate counts
    (``significant``) only when it beats the identity by more than the pixels' noise: the paired difference
    :math:`d_p = e_{id,p} - e_{c,p}` has :math:`z = \bar d / (\hat\sigma_d / \sqrt{n})` above the normal quantile
    at ``alpha`` / (number of candidates) (Bonferroni over the candidates tried, one-sided). Where the ground truth
    is flat and the test right, :math:`d_p = (c - b)(2a - b - c)` per channel (a the test's noise, b and c the
    ground truth's at the two pixels), a product of two independent normals, whose median absolute deviation is
    :data:`PRODUCT_MAD` times its standard deviation; :math:`\hat\sigma_d` = MAD(d) / :data:`PRODUCT_MAD`, which
    a few pixels at a moved edge (huge d) do not inflate as they inflate the sample standard deviation.

    Returns ``dx``, ``dy``, ``mirror``, ``mse`` (the chosen candidate's), ``mse_identity``, ``z`` (the best other
    candidate's; None when none beats the identity), ``significant``, ``candidates`` and ``max_shift`` (the window
    used); where the best is not significant, (0, 0, "none") with the identity's ``mse``.
    """
    ok, (t, g, v) = _finite(test, expected, variance)
    ok_pixel = np.all(ok, axis=2)
    h, w = t.shape[:2]
    m = max(0, min(int(max_shift), (min(h, w) - 1) // 3))
    crop = (slice(m, h - m), slice(m, w - m))
    target, valid = t[crop], ok_pixel[crop]
    weight = np.ones_like(target)
    if v is not None:
        noise = _tile_means(np.maximum(v, 0.0), ok, tile)
        positive = noise[ok & (noise > 0)]
        if positive.size:
            weight = 1.0 / np.maximum(noise, 1e-3 * float(positive.mean()))[crop]
    n = int(valid.sum())

    def errors(mirror: str, dx: int, dy: int) -> tuple[np.ndarray, np.ndarray]:
        moved = _mirrored(g, mirror)[m - dy:h - m - dy, m - dx:w - m - dx]
        moved_ok = _mirrored(ok_pixel, mirror)[m - dy:h - m - dy, m - dx:w - m - dx]
        return np.sum(weight * (target - moved) ** 2, axis=2), moved_ok & valid

    identity, _ = errors("none", 0, 0)
    best = ("none", 0, 0, float(identity[valid].mean()) if n else math.nan)
    count = 0
    for mirror in MIRRORS:
        for dy in range(-m, m + 1):
            for dx in range(-m, m + 1):
                count += 1
                e, use = errors(mirror, dx, dy)
                score = float(e[use].mean()) if use.any() else math.inf
                if score < best[3]:
                    best = (mirror, dx, dy, score)
    mirror, dx, dy, mse = best
    out = {"dx": 0, "dy": 0, "mirror": "none", "mse": best[3], "mse_identity": float(identity[valid].mean()) if n
           else None, "z": None, "significant": False, "candidates": count, "max_shift": m}
    if (mirror, dx, dy) == ("none", 0, 0) or n < 2:
        return out
    e, use = errors(mirror, dx, dy)
    d = (identity - e)[use]
    sd = float(np.median(np.abs(d - np.median(d)))) / PRODUCT_MAD
    z = math.inf if sd == 0.0 and d.mean() > 0 else (float(d.mean()) / (sd / math.sqrt(d.size)) if sd > 0 else 0.0)
    critical = float(normal_isf(alpha / count))
    out.update(z=z, mse=mse)
    if z > critical:
        out.update(dx=dx, dy=dy, mirror=mirror, significant=True)
    else:
        out["mse"] = out["mse_identity"]
    return out


def _tile_sums(values: np.ndarray, tile: int) -> np.ndarray:
    """Sums of a (H, W, 3) array over tile x tile blocks (the last ones partial), per channel: (tiles, 3)."""
    h, w = values.shape[:2]
    ph, pw = -h % tile, -w % tile
    padded = np.pad(values, ((0, ph), (0, pw), (0, 0)))
    blocks = padded.reshape((h + ph) // tile, tile, (w + pw) // tile, tile, 3)
    return blocks.sum(axis=(1, 3)).reshape(-1, 3)


def _tile_means(values: np.ndarray, ok: np.ndarray, tile: int) -> np.ndarray:
    """Per-pixel value of the mean of ``values`` over the finite entries of its tile (per channel)."""
    h, w = values.shape[:2]
    ph, pw = -h % tile, -w % tile
    sums = np.pad(np.where(ok, values, 0.0), ((0, ph), (0, pw), (0, 0)))
    counts = np.pad(ok.astype(np.float64), ((0, ph), (0, pw), (0, 0)))
    shape = ((h + ph) // tile, tile, (w + pw) // tile, tile, 3)
    mean = sums.reshape(shape).sum(axis=(1, 3)) / np.maximum(counts.reshape(shape).sum(axis=(1, 3)), 1.0)
    return np.repeat(np.repeat(mean, tile, axis=0), tile, axis=1)[:h, :w]


def scale_factor(test: np.ndarray, expected: np.ndarray, test_variance: np.ndarray | None = None,
                 expected_variance: np.ndarray | None = None, *, tile: int = 8, level: float = 0.99) -> dict:
    r"""The global factor s with test ~ s x ground truth, by weighted least squares, and its confidence interval.

    With T, G the images and :math:`V_T, V_G` their variances, per pixel and channel i,

    .. math::

        \hat s = \frac{\sum_i w_i T_i G_i}{\sum_i w_i (G_i^2 - V_{G,i})}, \qquad
        w_i = 1 / \overline{(V_T + \hat s^2 V_G)}_{\mathrm{tile}(i)},

    the least-squares slope through the origin (Draper and Smith, "Applied Regression Analysis", 3rd ed., 1998,
    section 3.1), its denominator corrected for the ground truth's own noise (E[G^2] = G_true^2 + V_G: without it
    a noisy ground truth pulls s towards 0, the errors-in-variables attenuation). The weights are the inverse of
    the variances averaged over each ``tile`` x ``tile`` block: a pixel's own variance estimate correlates with its
    value and would bias s; the tile's mean hardly does. Where no variance is given, or all are 0, the weights are 1.
    Two passes: the first weights with s = 1.

    Its standard deviation is the larger of two estimates: from the variances by the delta method,
    :math:`\mathrm{sd}^2 = \sum_i w_i^2 G_i^2 (V_{T,i} + \hat s^2 V_{G,i}) / D^2` (D the denominator above), and from
    the tiles' residuals as for a ratio estimator, :math:`\mathrm{sd}^2 = \frac{K}{K - 1} \sum_k (N_k - \hat s D_k)^2
    / D^2` over the K tiles' numerators and denominators (Cochran, "Sampling Techniques", 3rd ed., 1977, section
    6.3), which also holds when the variances are wrong or the image is not a scaled ground truth at all. The
    interval is :math:`\hat s \pm z\, \mathrm{sd}` at the two-sided ``level``.

    Returns ``scale``, ``low``, ``high``, ``sd``, ``sd_variances`` (None without variances), ``sd_tiles``,
    ``level`` and ``pixels``; ``scale`` None where the ground truth is 0 everywhere.
    """
    ok, (t, g, vt, vg) = _finite(test, expected, test_variance, expected_variance)
    vt = np.zeros_like(t) if vt is None else np.maximum(vt, 0.0)
    vg = np.zeros_like(g) if vg is None else np.maximum(vg, 0.0)
    has_variance = test_variance is not None or expected_variance is not None
    out = {"scale": None, "low": None, "high": None, "sd": None, "sd_variances": None, "sd_tiles": None,
           "level": level, "pixels": int(np.all(ok, axis=2).sum())}
    s = 1.0
    for _ in range(2):
        noise = _tile_means(vt + s * s * vg, ok, tile)
        positive = noise[ok & (noise > 0)]
        if has_variance and positive.size:
            weight = np.where(ok, 1.0 / np.maximum(noise, 1e-3 * float(positive.mean())), 0.0)
        else:
            weight = ok.astype(np.float64)
        numerator = weight * t * g
        denominator = weight * (g * g - vg)
        total = float(denominator.sum())
        if not total > 0:
            return out
        s = float(numerator.sum()) / total
    delta = math.sqrt(float(np.sum(weight**2 * g * g * (vt + s * s * vg)))) / total if has_variance else None
    n_k, d_k = _tile_sums(numerator, tile).ravel(), _tile_sums(denominator, tile).ravel()
    k = n_k.size
    tiles = math.sqrt(k / (k - 1) * float(np.sum((n_k - s * d_k) ** 2))) / total if k > 1 else None
    sd = max(v for v in (delta, tiles, 0.0) if v is not None)
    z = float(normal_isf((1.0 - level) / 2.0))
    out.update(scale=s, low=s - z * sd, high=s + z * sd, sd=sd, sd_variances=delta, sd_tiles=tiles)
    return out


def named_factor(scale: float | None, low: float | None, high: float | None,
                 tolerance: float = NAMED_TOLERANCE) -> str | None:
    """The name in :data:`NAMED_FACTORS` of the factor the interval [``low``, ``high``] holds ("1", "pi", "4 pi",
    "1/(4 pi)", ...): the one nearest to ``scale`` (in log) among those inside it; a factor of pi also when it lies
    within ``tolerance`` (relative) of the interval (then it is "about" it). "1" only when the interval holds 1
    itself. None when no factor fits."""
    if scale is None or low is None or high is None or not scale > 0:
        return None
    fits = [(abs(math.log(value / scale)), name) for name, value in NAMED_FACTORS
            if low <= value <= high or (name != "1" and low * (1 - tolerance) <= value <= high * (1 + tolerance))]
    return min(fits)[1] if fits else None


def bright_share(test: np.ndarray, expected: np.ndarray, test_variance: np.ndarray | None = None,
                 expected_variance: np.ndarray | None = None, top: float = 0.01) -> dict:
    r"""How much of the squared difference lies in the brightest pixels of the ground truth.

    The pixels whose ground-truth luminance (:func:`luminance`) is in the top ``top`` fraction (at least one) hold
    ``share`` = :math:`\sum_{top} e_p / \sum_p e_p` of the squared difference :math:`e_p = \sum_{ch} (T - G)^2`.
    Noise alone puts the share :math:`\sum_{top} v_p / \sum_p v_p` of the variances there (``noise_share``, with
    :math:`v_p = \sum_{ch} V_T + V_G`; without variances, the pixels' own share, ``top``). The difference is
    ``concentrated`` in them when ``share`` >= 1/2 and at least twice ``noise_share``.

    Returns ``share``, ``noise_share``, ``pixels`` (how many are in the top), ``top`` and ``concentrated``.
    """
    ok, (t, g, vt, vg) = _finite(test, expected, test_variance, expected_variance)
    pixel_ok = np.all(ok, axis=2)
    e = np.sum((t - g) ** 2, axis=2)[pixel_ok]
    lum = luminance(g)[pixel_ok]
    out = {"share": None, "noise_share": None, "pixels": 0, "top": top, "concentrated": False}
    if not lum.size:
        return out
    count = max(1, int(round(top * lum.size)))
    brightest = np.argsort(lum, kind="stable")[-count:]
    total = float(e.sum())
    share = float(e[brightest].sum()) / total if total > 0 else None
    noise_share = count / lum.size
    if test_variance is not None or expected_variance is not None:
        v = np.sum((np.zeros_like(t) if vt is None else vt) + (np.zeros_like(g) if vg is None else vg), axis=2)
        v = v[pixel_ok]
        if float(v.sum()) > 0:
            noise_share = float(v[brightest].sum()) / float(v.sum())
    out.update(share=share, noise_share=noise_share, pixels=count,
               concentrated=bool(share is not None and share >= 0.5 and share >= 2 * noise_share))
    return out


def diagnose(test: np.ndarray, expected: np.ndarray, test_variance: np.ndarray | None = None,
             expected_variance: np.ndarray | None = None, *, max_shift: int = 4, level: float = 0.99) -> dict:
    """:func:`best_shift`, :func:`scale_factor` with :func:`named_factor` and :func:`bright_share` of ``test``
    against ``expected`` (its ground truth), as one JSON-ready dict: ``shift``, ``scale`` (with ``named``: the factor
    its interval holds, or None) and ``bright``. The shift is searched on the test divided by its scale factor: a
    test 4 pi too bright would otherwise match best a ground truth moved towards its brighter side."""
    scale = scale_factor(test, expected, test_variance, expected_variance, level=level)
    scale["named"] = named_factor(scale["scale"], scale["low"], scale["high"])
    noise = None
    if test_variance is not None or expected_variance is not None:
        noise = sum(np.asarray(v, dtype=np.float64) for v in (test_variance, expected_variance) if v is not None)
    factor = scale["scale"] if scale["scale"] is not None and scale["scale"] > 0 else 1.0
    shift = best_shift(np.asarray(test, dtype=np.float64) / factor, expected, noise, max_shift=max_shift)
    return {"shift": shift, "scale": scale,
            "bright": bright_share(test, expected, test_variance, expected_variance)}
