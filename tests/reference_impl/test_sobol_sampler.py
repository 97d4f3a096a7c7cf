"""The stratified sampler (``Settings.sampler = "sobol"``, ``rng.sobol_2d``): what it must be to keep the estimators
unbiased (each point uniform on its own, pairs of dimensions independent) and what it is for (a pixel's points
stratified).

Statistical checks state their false-alarm chance: each chi^2 test runs at alpha = 1e-4 (five of them: < 0.05 %
for the file). The structural checks (nets, bits, bijections) are exact.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from reference_impl import rng
from reference_impl.kernels import rng as k_rng
from reference_impl.kernels import sobol as k_sobol

ALPHA = 1e-4


def _sobol_1_by_direction_numbers(i: int) -> int:
    """Sobol's second dimension the textbook way: direction numbers v_1 = 1/2, v_(k+1) = v_k xor v_k / 2 (the
    primitive polynomial x + 1), XORed for the set bits of the index (Bratley and Fox 1988, 32-bit fixed point)."""
    out, v = 0, 1 << 31
    while i:
        if i & 1:
            out ^= v
        i >>= 1
        v ^= v >> 1
    return out


def test_pascal_matrix_is_sobols_second_dimension():
    idx = np.concatenate([np.arange(300), np.random.default_rng(0).integers(0, 2**32, 2000)]).astype(np.uint64)
    got = rng.reverse_bits32(rng.pascal32(idx)).tolist()
    assert got == [_sobol_1_by_direction_numbers(int(i)) for i in idx]


def test_unscrambled_points_are_scipys_sobol_points():
    """Cross-check with a maintained implementation: scipy.stats.qmc.Sobol (unscrambled) gives the same first 4096
    points of dimensions 0 and 1, in Gray-code order (its point i is our index i xor i/2)."""
    from scipy.stats import qmc

    want = qmc.Sobol(d=2, scramble=False).random_base2(12)
    i = np.arange(4096, dtype=np.uint64)
    gray = i ^ (i >> np.uint64(1))
    np.testing.assert_array_equal(rng.reverse_bits32(gray) * 2.0**-32, want[:, 0])
    np.testing.assert_array_equal(rng.reverse_bits32(rng.pascal32(gray)) * 2.0**-32, want[:, 1])


def test_reverse_bits_is_an_involution_and_reverses():
    x = np.random.default_rng(1).integers(0, 2**32, 5000).astype(np.uint64)
    assert np.array_equal(rng.reverse_bits32(rng.reverse_bits32(x)), x)
    assert rng.reverse_bits32(np.uint64(1)) == 1 << 31 and rng.reverse_bits32(np.uint64(0b110)) == 0b011 << 29


def test_lk_permutation_is_a_bijection_whose_bit_b_depends_only_on_lower_bits():
    """What makes reverse(lk(reverse(x))) a nested uniform scramble: a permutation in which output bit b is a function
    of input bits 0..b only, checked on all 16-bit words for several seeds."""
    x = np.arange(1 << 16, dtype=np.uint64)
    for seed in (0, 1, 0xDEADBEEF, 0x12345678):
        y = rng.lk_permutation(x, np.uint64(seed)) & np.uint64(0xFFFF)
        assert len(np.unique(y)) == 1 << 16  # bijective on the low 16 bits, hence on every low-bit prefix
        high = rng.lk_permutation(x | np.uint64(0xABCD0000), np.uint64(seed)) & np.uint64(0xFFFF)
        assert np.array_equal(high, y)  # bits above 16 do not reach the low 16


@pytest.mark.parametrize("m", range(0, 9))
def test_each_pixels_first_2_to_the_m_points_form_a_0_m_2_net(m):
    """One point in every dyadic box of area 2^-m (all 2^a x 2^(m-a) grids), for 50 pixels, three pairs."""
    n = 1 << m
    keys = rng.pixel_keys(7, np.arange(50))
    for dim in (rng.dimension(0, 0), rng.dimension(1, 4), rng.dimension(1, 9)):
        for key in keys:
            x, y = rng.sobol_2d(np.full(n, key), np.arange(n), n, dim)
            assert x.min() >= 0 and max(x.max(), y.max()) < 1
            for a in range(m + 1):
                cells = (x * (1 << a)).astype(np.int64) * (1 << (m - a)) + (y * (1 << (m - a))).astype(np.int64)
                assert len(np.unique(cells)) == n, (m, a)


def _chi2_uniform_2d(x, y, bins=16):
    counts, _, _ = np.histogram2d(x, y, bins=bins, range=[[0, 1], [0, 1]])
    return stats.chisquare(counts.ravel()).pvalue


@pytest.mark.parametrize("index", [0, 5, 63])
def test_every_point_is_uniform_over_pixels(index):
    """Across 60000 pixels, point ``index`` of a pair is uniform on the unit square (chi^2 on 16 x 16 bins)."""
    keys = rng.pixel_keys(3, np.arange(60000))
    x, y = rng.sobol_2d(keys, np.full(len(keys), index), 64, rng.dimension(1, 4))
    assert _chi2_uniform_2d(x, y) >= ALPHA


def test_pairs_of_dimensions_are_independent():
    """Padding, across pixels: the x of one pair against the x of another, for the same pixel and index, is uniform
    on the square, and the same index in two pixels too."""
    keys = rng.pixel_keys(3, np.arange(60000))
    idx = np.full(len(keys), 9)
    a, _ = rng.sobol_2d(keys, idx, 16, rng.dimension(1, 4))
    b, _ = rng.sobol_2d(keys, idx, 16, rng.dimension(1, 9))
    assert _chi2_uniform_2d(a, b) >= ALPHA
    c, _ = rng.sobol_2d(np.roll(keys, 1), idx, 16, rng.dimension(1, 4))
    assert _chi2_uniform_2d(a, c) >= ALPHA


@pytest.mark.parametrize("n", [16, 64, 100])
def test_pairs_are_unrelated_within_a_pixel(n):
    """Padding, within a pixel: over its n samples, one pair's x says nothing of another's. For independent orders
    of two stratified sets the squared correlation has mean 1 / (n - 1); over 4000 pixels the mean of n r^2 is then
    n / (n - 1) with a standard error of about 0.025, so 1.2 is > 5 standard errors away (false alarm < 1e-6). The
    nested-scramble shuffle of Burley (2020) gave 1.55 at n = 64, Kensler's (2013) hash 1.33: both fail here."""
    pixels = 4000
    keys = np.repeat(rng.pixel_keys(5, np.arange(pixels)), n)
    idx = np.tile(np.arange(n), pixels)
    a = rng.sobol_2d(keys, idx, n, rng.dimension(1, 4))[0].reshape(pixels, n)
    b = rng.sobol_2d(keys, idx, n, rng.dimension(1, 9))[0].reshape(pixels, n)
    a, b = a - a.mean(axis=1, keepdims=True), b - b.mean(axis=1, keepdims=True)
    r = (a * b).sum(axis=1) / np.sqrt((a * a).sum(axis=1) * (b * b).sum(axis=1))
    assert np.mean(n * r**2) < n / (n - 1) + 0.2


@pytest.mark.parametrize("n", [1, 2, 3, 16, 100, 1000])
def test_orders_are_permutations(n):
    for seed in (0, 1, 2**63 + 12345):
        seeds = tuple(rng.mix64(np.array([seed + r], np.uint64)) for r in range(3))
        assert sorted(rng.permutation_element(np.arange(n), n, seeds).tolist()) == list(range(n))


def test_stratification_lowers_the_variance_of_a_pixel_integral():
    """What it is for: the mean of f(x, y) = x y + sin(6 x) over 64 points of a pixel, across 4000 pixels. Scrambled
    nets give variance O(n^-3) for smooth f against sigma^2 / n for independent points; demand a factor 20 at n = 64
    (the measured factor is in the thousands; a broken scramble or shuffle gives about 1)."""
    n, pixels = 64, 4000
    keys = np.repeat(rng.pixel_keys(5, np.arange(pixels)), n)
    x, y = rng.sobol_2d(keys, np.tile(np.arange(n), pixels), n, rng.dimension(1, 4))
    f = lambda u, v: u * v + np.sin(6 * u)  # noqa: E731
    strat = f(x, y).reshape(pixels, n).mean(axis=1)
    u = np.random.default_rng(2).random((2, pixels * n))
    plain = f(u[0], u[1]).reshape(pixels, n).mean(axis=1)
    exact = 0.25 + (1 - np.cos(6)) / 6
    assert abs(strat.mean() - exact) < 5 * strat.std() / np.sqrt(pixels) + 1e-12  # unbiased
    assert strat.var() * 20 < plain.var()


def test_kernel_matches_rng_bit_for_bit():
    seed = 99
    pixels = np.concatenate([np.arange(200), np.random.default_rng(4).integers(0, 2**40, 200)])
    keys = rng.pixel_keys(seed, pixels)
    seed_key = rng.seed_key(seed)
    assert [k_rng.pixel_key(seed_key, int(p)) for p in pixels] == keys.tolist()
    for n in (1, 7, 64, 1000, 2**32):
        index = np.random.default_rng(6).integers(0, n, len(keys))
        for depth, purpose in ((0, 0), (1, 2), (1, 4), (1, 9)):
            want_x, want_y = rng.sobol_2d(keys, index, n, rng.dimension(depth, purpose))
            salt = np.uint64(k_rng.dim_salt(depth, purpose, 0))
            seeds = [tuple(np.uint64(v) for v in k_sobol.sobol_seeds(np.uint64(k), salt, n)) for k in keys]  # as the kernels type them
            got = np.array([k_sobol.sobol_point(sd, np.uint64(i)) for sd, i in zip(seeds, index)])
            np.testing.assert_array_equal(got[:, 0], want_x)
            np.testing.assert_array_equal(got[:, 1], want_y)



@pytest.mark.parametrize("n", [1, 6, 64, 1000])
def test_points_computed_ahead_are_the_points_one_at_a_time(n):
    """kernels.sobol.sobol_points (a pixel's run of points in one loop, the cycle-walk of n < 2^k in a second pass)
    writes the bits sobol_point gives for each index, and only xs[at:at + count]; pair_point and held_point hand
    back a held point or compute it on the spot, the same bits."""
    seeds = tuple(np.uint64(v) for v in k_sobol.sobol_seeds(np.uint64(12345), np.uint64(k_rng.dim_salt(1, 2, 0)), n))
    first, count, at = (n // 3, n - n // 3, 5)
    xs, ys = np.full(count + 10, -1.0), np.full(count + 10, -1.0)
    k_sobol.sobol_points(seeds, first, count, xs, ys, at)
    want = np.array([k_sobol.sobol_point(seeds, first + i) for i in range(count)])
    np.testing.assert_array_equal(xs[at:at + count], want[:, 0])
    np.testing.assert_array_equal(ys[at:at + count], want[:, 1])
    assert (xs[:at] == -1).all() and (xs[at + count:] == -1).all()
    xs, ys = xs[at:], ys[at:]  # point first + o at o
    held = (np.int64(first), np.int64(count))
    for index in (first, first + count - 1, 0 if first > 0 else n + 3):
        points = (seeds, *k_sobol.held_point(seeds, xs, ys, held, index)[1:])  # the seeds as the kernels type them
        assert points[3] == (first <= index < first + count)
        assert k_sobol.pair_point(points, index) == k_sobol.sobol_point(seeds, index)
    assert k_sobol.pair_point((seeds, *k_sobol.spot_point(seeds)[1:]), 2) == k_sobol.sobol_point(seeds, 2)

def test_settings_refuse_more_points_than_the_sequence_holds():
    from reference_impl import Settings
    from reference_impl.errors import SettingsError

    with pytest.raises(SettingsError, match="spp"):
        Settings(spp=1 << 31, shadow_rays=2)
    Settings(spp=1 << 31, shadow_rays=2, sampler="independent")
    with pytest.raises(SettingsError, match="sampler"):
        Settings(sampler="halton")


# ------------------------------------------------------------------------------------------- in the renderer


def _seed_spread(scene, seeds: int, **settings):
    """Images of ``seeds`` seeds: their mean, the variance of one image's pixels estimated from the spread across
    seeds (exact for any sampler: the seeds are independent), and the mean variance the renders reported."""
    from conftest import render_reference

    images, reported = [], []
    for seed in range(seeds):
        result = render_reference(scene, seed=seed, **settings)
        images.append(result.image.astype(np.float64))
        reported.append(result.variance.astype(np.float64))
    stack = np.stack(images)
    return stack.mean(axis=0), stack.var(axis=0, ddof=1), np.mean(reported, axis=0)


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
@pytest.mark.parametrize("settings", [{"max_depth": 3}, {"max_depth": 4, "indirect_rays": 3, "shadow_rays": 2},
                                      {"max_depth": 3, "rr": "throughput", "rr_depth": 1, "shadow_rays": 2},
                                      {"max_depth": 4, "direct": "bsdf"}],
                         ids=["depth-3", "depth-4-Ni3-Nd2", "glossy-engine-Nd2", "glossy-engine-bsdf"])
def test_sobol_renders_are_unbiased_on_the_furnace(settings):
    """The furnace's closed form (tests/reference_impl/test_estimators.py) against the mean of 24 seeds, each pixel's variance from
    the spread across seeds (honest for a stratified sampler, whose own variance is only an upper bound): the
    image-wide mean per channel, Student's t with 23 degrees of freedom, false alarm 1e-3 over the three channels.
    Light sampling inside the analytic sphere has no variance at all (from a point of a sphere, every point y of it
    has cos_x cos_y / |x - y|^2 = 1 / (4 r^2): G / p(y) is one number), so where the spread is 0 the tolerance is
    the float32 image's rounding, 4 ulps of the value."""
    from conftest import load_small
    from test_estimators import furnace_radiance

    seeds = 24
    scene = load_small("furnace", 8)
    mean, spread, _ = _seed_spread(scene, seeds, spp=16, **settings)
    want = furnace_radiance(settings["max_depth"])
    got = mean.reshape(-1, 3).mean(axis=0)
    se = np.sqrt(spread.reshape(-1, 3).sum(axis=0) / mean.shape[0] ** 2 / mean.shape[1] ** 2 / seeds)
    t_crit = stats.t.ppf(1 - 1e-3 / 6, seeds - 1)
    assert np.all(np.abs(got - want) < t_crit * se + 4 * np.finfo(np.float32).eps * want), (got, want, se)



def test_reported_variance_is_an_upper_bound_with_sobol_and_right_without():
    """The variance a render reports (sample variance / Np) against the true variance of its pixels, measured across
    24 seeds on the soft-shadows scene: about equal for the independent sampler (measured 0.99), larger for sobol
    (3.6: its samples are stratified, so the true variance is smaller). Each ratio is a mean over 1728
    pixel-channels of a 23-dof estimate: its standard error is a few %, so the bounds (0.85..1.15, and > 1.15) hold
    with a false-alarm chance < 1e-6. (Not the Cornell box: its light touches the ceiling, where G(x, y)^2 / p(y)
    has no finite integral; sample variances there are heavy-tailed and measured 1.38 for independent samples.)"""
    from conftest import load_small

    scene = load_small("soft-shadows", 24)
    _, spread_i, reported_i = _seed_spread(scene, 24, spp=16, sampler="independent")
    _, spread_s, reported_s = _seed_spread(scene, 24, spp=16, sampler="sobol")
    lit = reported_i > 0
    ratio_i = reported_i[lit].mean() / spread_i[lit].mean()
    ratio_s = reported_s[lit].mean() / spread_s[lit].mean()
    print(f"reported / true variance: independent {ratio_i:.3f}, sobol {ratio_s:.3f}; "
          f"true variance sobol / independent {spread_s[lit].mean() / spread_i[lit].mean():.3f}")
    assert 0.85 < ratio_i < 1.15
    assert ratio_s > 1.15
    assert spread_s[lit].mean() < spread_i[lit].mean()
