"""Participating media's sampling routines against their own pdfs (issue 38; reference_impl/kernels/phase.py):
Henyey-Greenstein for g in {-0.9, -0.3, 0, 0.3, 0.9} and the isotropic phase function, and free flights in a
homogeneous medium, with the weight test (sample weight = eval / pdf) of each.

Chi-square (:mod:`harness.judges.chi2`), 10^6 samples each from a fixed seed: HG's mu = d . w in 200 bins of
[-1, 1] against 2 pi p(mu) (Gauss-Legendre, 16 nodes a bin: the peak at |g| = 0.9 is 1000 x the floor), and
(mu, phi) about a tilted d in 40 x 20 bins against p (g = 0.3 and isotropic: the azimuth and the frame); free flights
over a segment of length s as 40 bins of [0, s) plus "passed" against p(t) and T(s), and the volumetric loop's
free flights with a per-channel sigma_t (one channel drawn, the density the channels' mean: spectral MIS) against
that mixture, each with its weights' expectations. m = 13 tests at Sidak's alpha
for a 1 % family false alarm; the seeds are fixed, so a tree passes or fails reproducibly. The planted fault of
issue 38, HG with g's sign flipped, and a free-flight pdf without its sigma_t factor are rejected (p < 1e-9): the
tests can fail.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from harness.judges import chi2
from reference_impl.kernels.phase import (INV_FOUR_PI, free_flight_many, free_flight_pdf, hg_pdf, sample_hg_many,
                                          sample_isotropic, transmittance)

N = 1_000_000
M_TESTS = 13
ALPHA = 1 - 0.99 ** (1 / M_TESTS)
GS = (-0.9, -0.3, 0.0, 0.3, 0.9)
D = np.array([0.3, -0.5, 0.8124038404635961])  # a unit travel direction off every axis


def _uniforms(seed: int, n: int = N):
    g = np.random.default_rng(seed)
    return g.random(n), g.random(n)


def _mu_test(g: float, pdf_g: float, seed: int, n: int = N):
    u1, u2 = _uniforms(seed, n)
    w, _pdf = sample_hg_many(g, u1, u2, D)
    return chi2.chi2_test_1d(lambda m: w[:m] @ D, lambda mu: 2 * np.pi * np.array([hg_pdf(pdf_g, x) for x in mu]),
                             (-1.0, 1.0), 200, n, order=16, name=f"HG g = {g}: mu")


@pytest.mark.parametrize("g", GS)
def test_hg_mu_follows_its_pdf(g):
    result = _mu_test(g, g, seed=int(100 + 10 * g))
    print(result.line())
    assert not result.failures(ALPHA), result.failures(ALPHA)


@pytest.mark.parametrize("g", [0.3, None])
def test_directions_follow_their_pdf_about_the_travel_direction(g):
    u1, u2 = _uniforms(7)
    if g is None:
        w = np.array([sample_isotropic(a, b)[:3] for a, b in zip(u1[:N], u2[:N])])
        pdf = lambda c, p: np.full(len(c), INV_FOUR_PI)  # noqa: E731
        local = w
    else:
        w, _pdf = sample_hg_many(g, u1, u2, D)
        local = chi2.to_local(w, D)
        pdf = lambda c, p: np.array([hg_pdf(g, x) for x in c])  # noqa: E731
    cos, phi = chi2.directions_to_cos_phi(local)
    result = chi2.chi2_test(lambda m: (cos[:m], phi[:m]), pdf, chi2.SPHERE_COS_PHI, (40, 20), N,
                            name=f"{'isotropic' if g is None else f'HG g = {g}'}: (mu, phi)")
    print(result.line())
    assert not result.failures(ALPHA), result.failures(ALPHA)


@pytest.mark.parametrize("g", GS)
def test_hg_weight_is_one(g):
    """HG is sampled exactly: the pdf a sample carries is p(w) at its direction, so eval / pdf = 1 (to rounding)."""
    u1, u2 = _uniforms(3, 20_000)
    w, pdf = sample_hg_many(g, u1, u2, D)
    evaluated = np.array([hg_pdf(g, x) if abs(g) >= 1e-3 else INV_FOUR_PI for x in np.clip(w @ D, -1, 1)])
    np.testing.assert_allclose(evaluated / pdf, 1.0, rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, rtol=1e-12)
    # and the pdf integrates to 1 over the sphere (2 pi times its integral in mu, Gauss-Legendre)
    x, wq = np.polynomial.legendre.leggauss(400)
    assert 2 * np.pi * sum(wq[i] * hg_pdf(g, x[i]) for i in range(400)) == pytest.approx(1.0, abs=1e-6)


def _flight_outcomes(sigma_t: float, s: float, t: np.ndarray, bins: int = 40) -> np.ndarray:
    """Bin k of [0, s) for a flight that ends inside the segment, ``bins`` for one that passes it."""
    return np.where(t < s, np.minimum((t / s * bins).astype(np.int64), bins - 1), bins)


def _flight_probabilities(pdf_at, sigma_t: float, s: float, bins: int = 40) -> np.ndarray:
    edges = np.linspace(0.0, s, bins + 1)
    x, wq = np.polynomial.legendre.leggauss(16)
    p = []
    for a, b in zip(edges[:-1], edges[1:]):
        nodes = 0.5 * (b - a) * x + 0.5 * (a + b)
        p.append(0.5 * (b - a) * sum(wq[i] * pdf_at(sigma_t, nodes[i]) for i in range(16)))
    return np.array(p + [transmittance(sigma_t, s)])


@pytest.mark.parametrize("sigma_t, s", [(0.5, 3.0), (4.0, 1.0), (1e-3, 10.0)])
def test_free_flights_follow_their_pdf_and_pass_with_the_transmittance(sigma_t, s):
    u, _ = _uniforms(11)
    t = free_flight_many(sigma_t, u)
    p = _flight_probabilities(free_flight_pdf, sigma_t, s)
    assert p.sum() == pytest.approx(1.0, abs=1e-9)
    result = chi2.chi2_test_discrete(_flight_outcomes(sigma_t, s, t), p, name=f"free flight sigma_t = {sigma_t}")
    print(result.line())
    assert not result.failures(ALPHA), result.failures(ALPHA)
    # the weight test: passing weighs T(s) / P(pass) = 1, scattering at t weighs sigma_t T(t) / p(t) = 1 (x albedo)
    inside = t[t < s][:1000]
    np.testing.assert_allclose([sigma_t * transmittance(sigma_t, x) / free_flight_pdf(sigma_t, x) for x in inside],
                               1.0, rtol=1e-12)


def test_the_tests_reject_a_flipped_g_and_a_pdf_without_sigma_t():
    flipped = _mu_test(0.3, -0.3, seed=5, n=200_000)  # issue 38's planted fault: HG with g's sign flipped
    assert flipped.p_value < 1e-9
    u, _ = _uniforms(12, 200_000)
    t = free_flight_many(4.0, u)
    wrong = _flight_probabilities(lambda st, x: math.exp(-st * x), 4.0, 1.0)  # p(t) without the sigma_t factor
    result = chi2.chi2_test_discrete(_flight_outcomes(4.0, 1.0, t), wrong / wrong.sum())
    assert result.p_value < 1e-9


RGB_SIGMA = (0.5, 2.0, 6.0)
RGB_ALBEDO = (0.9, 0.5, 0.2)


def _rgb_tables():
    from reference_impl.kernels.records import medium_tables
    from reference_impl.media import ISOTROPIC, Media
    media = Media(sigma_t=[RGB_SIGMA], albedo=[RGB_ALBEDO], phase=[ISOTROPIC], g=[0.0], interior=[], exterior=[],
                  transition=[])
    return medium_tables(media, 0)


def _rgb_flights(s: float, seed: int, n: int = N, mutant: int = 0):
    from reference_impl.kernels.volpath import free_flight_rgb_many
    u_c, u_t = _uniforms(seed, n)
    return free_flight_rgb_many(_rgb_tables(), 0, s, u_c, u_t, mutant)


@pytest.mark.parametrize("s", [0.3, 1.0, 4.0])
def test_rgb_free_flights_follow_the_channel_mixture(s):
    """kernels/volpath.free_flight_rgb: p(t) = 1/3 sum_c sigma_c exp(-sigma_c t), P(pass) = 1/3 sum_c T_c(s); the
    weights: a scattering's a_c sigma_c T_c(t) / p(t), a pass's T_c(s) / P(pass), whose expectations are
    a_c (1 - T_c(s)) and T_c(s) (each channel's own medium: the estimator is unbiased per channel)."""
    scatters, t, w = _rgb_flights(s, seed=int(20 + 10 * s))
    mixture = lambda _st, x: sum(sc * math.exp(-sc * x) for sc in RGB_SIGMA) / 3.0  # noqa: E731
    p = _flight_probabilities(mixture, 0.0, s)
    p[-1] = sum(math.exp(-sc * s) for sc in RGB_SIGMA) / 3.0
    assert p.sum() == pytest.approx(1.0, abs=1e-9)
    result = chi2.chi2_test_discrete(_flight_outcomes(0.0, s, np.where(scatters, t, 2 * s)), p,
                                     name=f"rgb free flight s = {s}")
    print(result.line())
    assert not result.failures(ALPHA), result.failures(ALPHA)
    inside = np.flatnonzero(scatters)[:1000]
    for c in range(3):
        expected = [RGB_ALBEDO[c] * RGB_SIGMA[c] * math.exp(-RGB_SIGMA[c] * x) / mixture(0, x) for x in t[inside]]
        np.testing.assert_allclose(w[inside, c], expected, rtol=1e-12)
        tc = math.exp(-RGB_SIGMA[c] * s)
        for mask, mean in ((scatters, RGB_ALBEDO[c] * (1 - tc)), (~scatters, tc)):
            values = np.where(mask, w[:, c], 0.0)
            assert abs(values.mean() - mean) < 5 * values.std() / math.sqrt(len(values)) + 1e-12


def test_rgb_free_flight_faults_move_the_expectation():
    """The planted faults "free-flight-pdf-no-sigma-t" and "albedo-applied-twice" change the scattering weights'
    expectation far beyond its noise (10^6 flights)."""
    from reference_impl.kernels.config import M_ALBEDO_TWICE, M_FLIGHT_PDF_NO_SIGMA_T
    for bit in (M_FLIGHT_PDF_NO_SIGMA_T, M_ALBEDO_TWICE):
        scatters, _t, w = _rgb_flights(1.0, seed=31, mutant=bit)
        values = np.where(scatters, w[:, 2], 0.0)
        truth = RGB_ALBEDO[2] * (1 - math.exp(-RGB_SIGMA[2]))
        assert abs(values.mean() - truth) > 20 * values.std() / math.sqrt(len(values))


@pytest.mark.parametrize("s", [0.3, 4.0])
def test_hero_channel_flights_weigh_each_channel_without_bias(s):
    """kernels/volpath.free_flight_hero, the path loop's free flight: a hero channel c drawn uniformly, t from
    sigma_c exp(-sigma_c t) (the free flight tested above); the path's estimate beta_k / mean_j r_j (one-sample MIS
    over the channels, balance heuristic) has the expectations a_k (1 - T_k(s)) over scatterings and T_k(s) over
    passes, each channel its own medium's; its weights are the formulas of the module docstring; and no channel's
    weight exceeds 3 x its own medium's single-channel weight (a_k for a scattering, 1 for a pass)."""
    from reference_impl.kernels.volpath import free_flight_hero_many
    rng = np.random.default_rng(int(40 + 10 * s))
    c = rng.integers(0, 3, N)
    u = rng.random(N)
    scatters, t, w, q = free_flight_hero_many(_rgb_tables(), 0, s, c, u, 0)
    estimate = w / q.mean(axis=1, keepdims=True)
    sigma, albedo = np.array(RGB_SIGMA), np.array(RGB_ALBEDO)
    for k in range(3):
        tk = math.exp(-sigma[k] * s)
        for mask, mean in ((scatters, albedo[k] * (1 - tk)), (~scatters, tk)):
            values = np.where(mask, estimate[:, k], 0.0)
            assert abs(values.mean() - mean) < 5 * values.std() / math.sqrt(N), (k, values.mean(), mean)
    assert np.all(estimate[scatters] <= 3 * albedo + 1e-12) and np.all(estimate[~scatters] <= 3 + 1e-12)
    i = np.flatnonzero(scatters)[:200]
    hero = sigma[c[i]] * np.exp(-sigma[c[i]] * t[i])  # p_c(t)
    density = sigma * np.exp(-np.outer(t[i], sigma))  # p_k(t)
    np.testing.assert_allclose(w[i], albedo * density / hero[:, None], rtol=1e-12)
    np.testing.assert_allclose(q[i], density / hero[:, None], rtol=1e-12)
