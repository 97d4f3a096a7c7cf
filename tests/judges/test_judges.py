"""The judges library (harness/judges) on its own: samplers and images written here, no renderer.

Chi-square tests. A correct sampler on a fixed seed must give ``p`` above :data:`CORRECT_P` (0.01; a correct sampler
falls below it on 1 % of seeds, and the seeds here are fixed, so the outcome is reproducible). A planted mistake --
a pdf off by a factor pi, a uniform pdf claimed for a cosine sampler, a normal of the wrong width -- must give
``p < WRONG_P`` (1e-6) and fail. Samples the pdf calls impossible, outside the domain or not finite must be counted
exactly and fail the test whatever the p-value.

Image statistics, on synthetic images whose every pixel is ``mu + sqrt(v) * N(0, 1)`` with a known per-pixel variance
``v``: the tolerance is ``|z| < z_critical(FALSE_ALARM, k)`` for ``k`` channel comparisons (Bonferroni), so a correct
image raises a false alarm with chance at most FALSE_ALARM = 1e-4 per test; the tile omnibus passes at
``p > FALSE_ALARM``. Biases are planted many standard errors beyond those tolerances (stated at each test), so that
missing them would take a deviation of more than 5 standard errors the wrong way (chance < 1e-6).
"""

from __future__ import annotations

import ast
import doctest
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import harness.judges
from harness.judges import chi2, mc

JUDGES = Path(harness.judges.__file__).resolve().parent
CORRECT_P = 0.01  # a correct sampler must pass at least this clearly
WRONG_P = 1e-6  # a planted wrong pdf must be rejected at least this strongly
N = 200_000


def _cosine_warp(u1, u2):
    """Malley's method: a uniform disk point lifted to the hemisphere; pdf cos(theta) / pi about +z."""
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1.0 - u1))])


def _cosine_pdf(c, phi):
    return np.where(c > 0, c / np.pi, 0.0)


def _hemisphere(warp, pdf, seed, n=N, domain=chi2.SPHERE_COS_PHI):
    g = np.random.default_rng(seed)
    return chi2.chi2_test_2d(
        lambda m: chi2.directions_to_cos_phi(warp(g.random(m), g.random(m))), pdf, domain, (32, 32), n
    )


# ---------------------------------------------------------------------------------------- the library stands alone


def test_judges_import_only_numpy_scipy_and_the_standard_library():
    """Pure numerical libraries only; metrics.py's image metrics add the libraries that define them (scikit-image's
    SSIM and PSNR, NVIDIA's FLIP), imported where a metric needs them; of the harness, the error type and the sRGB
    transfer function (numpy only)."""
    allowed = {"numpy", "scipy", "skimage", "flip_evaluator"} | set(sys.stdlib_module_names)
    files = sorted(JUDGES.glob("*.py"))
    assert {f.name for f in files} >= {"__init__.py", "chi2.py", "mc.py"}
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                assert node.level == 0, f"{path.name}: relative import"
                names = [f"{node.module}.{a.name}" for a in node.names]  # from harness.core import srgb
            else:
                continue
            for name in names:
                ok = name.split(".")[0] in allowed or any(name == m or name.startswith(m + ".") for m in
                                                          ("harness.judges", "harness.core.errors", "harness.core.srgb"))
                assert ok, f"{path.name} imports {name}"


@pytest.mark.parametrize("module", [chi2, mc], ids=["chi2", "mc"])
def test_module_docstring_examples_run(module):
    # The usage examples in the module docstrings are doctests: a user's own warp and images, end to end.
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 5 and result.failed == 0


def test_package_reexports_the_main_names():
    for name in harness.judges.__all__:
        source = chi2 if name in chi2.__all__ else mc
        assert getattr(harness.judges, name) is getattr(source, name), name


# ---------------------------------------------------------------------------------------- chi2: correct samplers


def test_correct_cosine_warp_passes():
    r = _hemisphere(_cosine_warp, _cosine_pdf, seed=1)
    print(r.line())
    assert r.p_value > CORRECT_P and r.passed(CORRECT_P)
    assert r.pdf_integral == pytest.approx(1.0, abs=1e-6) and r.out_of_domain == 0 and r.impossible == 0
    # The 16 x 32 bins of the lower hemisphere expect 0 and are pooled (into the smallest cell, adding nothing);
    # every upper bin expects >= 24 samples and stands alone.
    assert (r.n_bins, r.pooled_bins, r.n_cells, r.dof) == (1024, 512, 512, 511)


def test_correct_normal_sampler_passes():
    g = np.random.default_rng(2)
    r = chi2.chi2_test_1d(lambda n: g.normal(size=n), stats.norm.pdf, (-8.0, 8.0), 160, N, name="numpy normal")
    print(r.line())
    assert r.p_value > CORRECT_P and r.passed(CORRECT_P)
    assert r.pooled_bins > 0  # the far tails expect < 5 samples


def test_correct_sphere_sampler_in_theta_phi_needs_the_jacobian():
    def uniform_sphere(n, g=np.random.default_rng(3)):
        d = g.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.arccos(np.clip(d[:, 2], -1, 1)), np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)

    pdf = lambda t, p: np.full_like(t, 1 / (4 * np.pi))  # noqa: E731  (per steradian)
    domain = ((0.0, np.pi), (0.0, 2 * np.pi))
    right = chi2.chi2_test_2d(uniform_sphere, pdf, domain, (24, 24), N, jacobian=lambda t, p: np.sin(t))
    assert right.passed(CORRECT_P) and right.p_value > CORRECT_P, right.line()
    wrong = chi2.chi2_test_2d(uniform_sphere, pdf, domain, (24, 24), N)  # d omega taken for d theta d phi
    assert not wrong.passed(CORRECT_P)


def test_sampler_may_return_an_array_and_pdf_a_scalar():
    g = np.random.default_rng(4)
    r = chi2.chi2_test(lambda n: g.random((n, 2)), lambda x, y: 1.0, ((0, 1), (0, 1)), 16, N, quadrature="midpoint")
    assert r.passed(CORRECT_P) and r.pdf_integral == pytest.approx(1.0)


def test_discrete_correct_and_wrong():
    p = np.array([0.1, 0.2, 0.3, 0.4])
    g = np.random.default_rng(5)
    choices = g.choice(4, size=N, p=p)
    assert chi2.chi2_test_discrete(choices, p).p_value > CORRECT_P
    wrong = chi2.chi2_test_discrete(choices, [0.1, 0.2, 0.32, 0.38])
    assert wrong.p_value < WRONG_P and not wrong.passed(CORRECT_P)


# ---------------------------------------------------------------------------------------- chi2: planted mistakes


def test_rejects_pdf_missing_its_one_over_pi():
    r = _hemisphere(_cosine_warp, lambda c, phi: np.where(c > 0, c, 0.0), seed=6)
    print(r.line())
    assert r.pdf_integral == pytest.approx(np.pi, rel=1e-6)
    assert r.p_value < WRONG_P and any("integrates" in f for f in r.failures(CORRECT_P))


def test_rejects_uniform_pdf_for_a_cosine_sampler():
    r = _hemisphere(_cosine_warp, lambda c, phi: np.where(c > 0, 1 / (2 * np.pi), 0.0), seed=7)
    print(r.line())
    assert r.pdf_integral == pytest.approx(1.0, abs=1e-9)  # normalised, merely the wrong shape
    assert r.p_value < WRONG_P and not r.passed(CORRECT_P)


def test_rejects_normal_of_the_wrong_width():
    g = np.random.default_rng(8)
    r = chi2.chi2_test_1d(lambda n: g.normal(scale=1.03, size=n), stats.norm.pdf, (-8.0, 8.0), 160, N)
    assert r.p_value < WRONG_P


def test_flags_samples_where_the_pdf_is_zero():
    def below(u1, u2):  # every 50th direction mirrored below the surface
        d = _cosine_warp(u1, u2)
        d[::50, 2] *= -1
        return d

    r = _hemisphere(below, _cosine_pdf, seed=9)
    assert r.impossible == N // 50 and r.zero_bin_hits == N // 50 and r.out_of_domain == 0
    assert any("pdf is 0" in f for f in r.failures(CORRECT_P))


def test_flags_samples_outside_the_domain_or_not_finite():
    def broken(n, g=np.random.default_rng(10)):
        x = g.random(n)
        x[:7] = [np.nan, np.inf, -np.inf, -0.5, 1.5, 1e300, -1e300]
        x[7] = 1.0 + 1e-12  # within boundary_tol: clamped into the last bin, not out of domain
        return x

    r = chi2.chi2_test_1d(broken, lambda x: np.ones_like(x), (0.0, 1.0), 20, 10_000)
    assert r.out_of_domain == 7 and r.observed.sum() == 10_000 - 7
    assert r.failures(CORRECT_P)[0] == "7 samples outside the domain or not finite"
    # Upper hemisphere only: a direction below it is out of the domain (not "impossible").
    r = _hemisphere(lambda u1, u2: -_cosine_warp(u1, u2), _cosine_pdf, seed=11, n=1000, domain=chi2.HEMISPHERE_COS_PHI)
    assert r.out_of_domain == 1000 and not r.passed(CORRECT_P)


def test_discrete_flags_out_of_range_non_integer_and_impossible_choices():
    samples = np.array([0, 1, 1, 2, 3, -1, 4] * 100 + [0.5, np.nan])
    r = chi2.chi2_test_discrete(samples, [0.5, 0.5, 0.0, 0.0])
    assert r.out_of_domain == 200 + 2 and r.impossible == 200 and not r.passed(CORRECT_P)


def test_no_degrees_of_freedom_is_a_failure():
    r = chi2.chi2_test_discrete(np.zeros(100, int), [1.0])
    assert r.dof == 0 and np.isnan(r.p_value) and "no degrees of freedom left after pooling" in r.failures(0.01)


# ---------------------------------------------------------------------------------------- chi2: the pieces


def test_pooled_statistic_by_hand():
    stat, dof, cells, pooled = chi2.pooled_statistic([10, 12, 1, 2, 3], [11.0, 11.0, 2.0, 2.0, 2.0])
    assert (pooled, cells, dof) == (3, 3, 2)  # three bins of 2 pool into one cell expecting 6
    assert stat == pytest.approx(1 / 11 + 1 / 11 + 0)
    # A pool too small to stand alone joins the smallest regular cell, so a sample where none is expected does not
    # make the statistic infinite (chi2_test counts it as impossible instead) ...
    assert chi2.pooled_statistic([5, 5, 1], [5.0, 5.0, 0.0])[:3] == (pytest.approx(1 / 5), 1, 2)
    # ... unless nothing is pooled.
    assert chi2.pooled_statistic([5, 1], [6.0, 0.0], min_expected=0.0)[0] == np.inf


def test_bin_integrals_are_exact_for_polynomials_with_gauss():
    # integral of 3 x^2 over [a, b] = b^3 - a^3; degree 2 < 2 * order for order >= 2.
    prob = chi2.bin_integrals(lambda x: 3 * x**2, ((0.0, 1.0),), (10,), order=2)
    edges = np.linspace(0, 1, 11)
    np.testing.assert_allclose(prob, edges[1:] ** 3 - edges[:-1] ** 3, rtol=1e-13)


def test_sidak_alpha():
    assert chi2.sidak_alpha(1) == pytest.approx(chi2.FAMILY_ALPHA)
    m = 20
    assert (1 - chi2.sidak_alpha(m)) ** m == pytest.approx(1 - chi2.FAMILY_ALPHA)
    assert chi2.FAMILY_ALPHA / m < chi2.sidak_alpha(m) < 1.01 * chi2.FAMILY_ALPHA / m


def test_frames_and_direction_round_trip():
    g = np.random.default_rng(12)
    c, phi = g.uniform(-1, 1, 1000), g.uniform(0, 2 * np.pi, 1000)
    d = chi2.cos_phi_to_directions(c, phi)
    c2, phi2 = chi2.directions_to_cos_phi(3.0 * d)  # need not be unit length
    np.testing.assert_allclose(c2, c, atol=1e-12)
    np.testing.assert_allclose(np.cos(phi2 - phi), 1.0, atol=1e-12)
    for n in [(0, 0, 1), (0, 0, -1), (0.3, -0.5, 0.81), (1e-9, 0, -1)]:
        s, t, nn = chi2.orthonormal_basis(n)
        np.testing.assert_allclose(np.array([s, t, nn]) @ np.array([s, t, nn]).T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(np.cross(s, t), nn, atol=1e-12)
        np.testing.assert_allclose(chi2.to_local(np.array([nn]), n), [[0, 0, 1]], atol=1e-12)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: chi2.chi2_test_1d(np.zeros, np.ones_like, (1.0, 1.0), 4, 10), "lo < hi"),
        (lambda: chi2.chi2_test_1d(np.zeros, np.ones_like, (0.0, np.inf), 4, 10), "finite"),
        (lambda: chi2.chi2_test_1d(np.zeros, np.ones_like, (0.0, 1.0), 0, 10), "res"),
        (lambda: chi2.chi2_test_1d(np.zeros, np.ones_like, (0.0, 1.0), 4, 0), "n_samples"),
        (lambda: chi2.chi2_test_1d(np.zeros, np.ones_like, (0.0, 1.0), 4, 10, quadrature="simpson"), "quadrature"),
        (lambda: chi2.chi2_test_1d(np.zeros, np.ones_like, (0.0, 1.0), 4, 10, order=0), "order"),
        (lambda: chi2.chi2_test_2d(lambda n: (np.zeros(n),), np.ones_like, ((0, 1), (0, 1)), 4, 10), "2 coordinate"),
        (lambda: chi2.chi2_test_2d(lambda n: (np.zeros(n), np.zeros(n + 1)), np.ones_like, ((0, 1), (0, 1)), 4, 10),
         "differ in length"),
        (lambda: chi2.chi2_test(np.zeros, np.ones_like, ((0, 1), (0, 1)), (4, 4, 4), 10), "axes"),
        (lambda: chi2.chi2_test_discrete([0, 1], [0.5, -0.5]), "probabilities"),
        (lambda: chi2.chi2_test_discrete(["a"], [1.0]), "integers"),
        (lambda: chi2.sidak_alpha(0), "num_tests"),
        (lambda: chi2.orthonormal_basis((0, 0, 0)), "non-zero"),
        (lambda: chi2.directions_to_cos_phi(np.zeros((4, 2))), r"\(n, 3\)"),
    ],
)
def test_malformed_calls_raise_value_error(call, match):
    with pytest.raises(ValueError, match=match):
        call()


# ---------------------------------------------------------------------------------------- mc: synthetic images


H = W = 32
MU = np.array([0.5, 1.0, 2.0])


def _images(seed: int, bias=0.0):
    """(image, variance): pixel (y, x, c) is MU[c] + bias + sqrt(v) N(0, 1) with v from 0.005 to 0.05 across x."""
    g = np.random.default_rng(seed)
    v = np.broadcast_to(np.linspace(0.005, 0.05, W)[None, :, None] * [1.0, 1.5, 2.0], (H, W, 3)).copy()
    return MU + bias + np.sqrt(v) * g.normal(size=v.shape), v


def _stderr(v):
    return np.sqrt(v.reshape(-1, 3).sum(axis=0)) / (H * W)  # about 0.005 per channel


def test_image_mean_and_its_standard_error():
    image, v = _images(20)
    m = mc.image_mean(image.astype(np.float32), v.astype(np.float32))
    np.testing.assert_allclose(m.mean, image.reshape(-1, 3).mean(axis=0), rtol=1e-6)
    np.testing.assert_allclose(m.stderr, _stderr(v), rtol=1e-6)


def test_z_scores_quiet_at_the_true_mean():
    """Tolerance |z| < z_critical(1e-4, 3) = 4.15 for the 3 channels: a false alarm on 1 in 10^4 seeds."""
    image, v = _images(21)
    z = mc.z_scores(mc.image_mean(image, v), MU)
    assert np.all(np.abs(z) < mc.z_critical(mc.FALSE_ALARM, 3)), z
    other, v2 = _images(22)
    z = mc.z_scores(mc.image_mean(image, v), mc.image_mean(other, v2))  # two independent estimates
    assert np.all(np.abs(z) < mc.z_critical(mc.FALSE_ALARM, 3)), z


def test_z_scores_loud_at_a_biased_mean():
    """A bias of 14 standard errors of one image's mean: z ~ N(14, 1) against the truth and ~ N(9.9, 1) against
    another estimate (the standard error grows by sqrt(2)); z < 4.15 would take a 5.7-sigma deviation."""
    bias = 14 * _stderr(_images(0)[1])
    image, v = _images(23, bias=bias)
    z = mc.z_scores(mc.image_mean(image, v), MU)
    assert np.all(z > mc.z_critical(mc.FALSE_ALARM, 3)), z
    z = mc.z_scores(mc.image_mean(image, v), mc.image_mean(*_images(24)))
    assert np.all(z > mc.z_critical(mc.FALSE_ALARM, 3)), z


def test_z_scores_of_zero_variance_estimates_allow_float32_rounding():
    exact = mc.ImageMean(np.array([1.0, 2.0, 0.0]), np.zeros(3))
    rounded = np.array([1.0, 2.0, 0.0]) * (1 + 2**-24)  # one float32 rounding away
    np.testing.assert_allclose(mc.z_scores(exact, rounded), [-0.25, -0.25, 0.0], atol=1e-6)
    assert abs(mc.z_scores(exact, [1.001, 2.0, 0.0])[0]) > 1e3  # a real difference is not excused


def test_z_critical_is_two_sided_bonferroni():
    z = mc.z_critical(0.01, 5)
    assert 2 * stats.norm.sf(z) * 5 == pytest.approx(0.01)
    with pytest.raises(ValueError, match="alpha"):
        mc.z_critical(0.0, 3)
    with pytest.raises(ValueError, match="comparisons"):
        mc.z_critical(0.01, 0)


def test_tile_chi2_quiet_at_the_right_variance():
    """The omnibus passes at p > FALSE_ALARM = 1e-4 (a false alarm on 1 in 10^4 seeds); 16 tiles x 3 channels."""
    a, va = _images(25)
    b, vb = _images(26)
    statistic, dof, p = mc.tile_chi2(a - b, va + vb, tile=8)
    assert dof == 48 and p > mc.FALSE_ALARM, (statistic, dof, p)


def test_tile_chi2_loud_at_a_local_bias_and_at_an_understated_variance():
    """A bias of 0.3 in one 8 x 8 tile (at x < 8, where the difference's pixel variance is <= 0.061) makes that
    tile's z = 64 * 0.3 / sqrt(sum of its 64 variances) >= 9.7 in every channel, adding ~ 400 to a chi^2(48)
    statistic (mean 48, sd 10) that must stay below ~ 107 for p > 1e-6. Claiming a quarter of the true variance
    multiplies the statistic by 4 (~ 192 on 48 dof, p ~ 1e-18)."""
    a, va = _images(27)
    b, vb = _images(28)
    diff = a - b
    diff[8:16, 0:8] += 0.3
    assert np.all(64 * 0.3 / np.sqrt((va + vb)[8:16, 0:8].sum(axis=(0, 1))) >= 9.7)  # the docstring's bound
    statistic, dof, p = mc.tile_chi2(diff, va + vb, tile=8)
    assert p < WRONG_P, (statistic, dof, p)
    statistic, dof, p = mc.tile_chi2(a - b, (va + vb) / 4, tile=8)
    assert p < WRONG_P, (statistic, dof, p)


def test_tile_chi2_leaves_out_tiles_without_variance_and_partial_tiles():
    diff, var = np.zeros((10, 12, 3)), np.zeros((10, 12, 3))
    var[:4, :4] = 1.0  # one tile of 4 x 4 with variance; the last 2 rows and columns of 4 x 4 tiles are partial
    diff[:4, :4] = 0.25
    diff[8:, :] = 100.0  # in the partial row: left out
    statistic, dof, p = mc.tile_chi2(diff, var, tile=4)
    assert dof == 3 and statistic == pytest.approx(3 * 4.0**2 / 16.0)
    assert np.isnan(mc.tile_chi2(diff, np.zeros_like(var), tile=4)[2])  # nothing tested: a p > alpha check fails


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: mc.image_mean(np.zeros((4, 4, 3)), np.zeros((4, 4, 1))), "variance"),
        (lambda: mc.image_mean(np.zeros((4, 3)), np.zeros((4, 3))), "channels"),
        (lambda: mc.tile_chi2(np.zeros((4, 4, 3)), np.zeros((4, 4, 3)), tile=5), "tile"),
        (lambda: mc.tile_chi2(np.zeros((4, 4, 3)), np.zeros((4, 4, 3)), tile=0), "tile"),
    ],
)
def test_mc_malformed_calls_raise_value_error(call, match):
    with pytest.raises(ValueError, match=match):
        call()
