"""Chi-square tests: reference_impl's warps, light sampling and pixel filters draw from the pdfs they claim.

Every sampling routine is run on ~10^6 uniforms from a fixed seed (``numpy.random.default_rng``; one hemisphere test
and one unit-square test use the project's counter-based ``reference_impl.rng`` streams instead) and its samples
are binned and compared with the routine's *own* pdf integrated over the bins (the library :mod:`harness.judges.chi2`;
the cases and fixtures are in ``tests/reference_impl/chi2_cases.py``):

* ``square_to_cosine_hemisphere`` / ``square_to_uniform_hemisphere`` vs their pdfs, in (cos theta, phi);
* ``sample_hemisphere`` about non-axis normals (world frame), mapped back to each normal's local frame;
* ``square_to_uniform_triangle`` on a skewed triangle vs 1 / area;
* ``LightSampler.sample`` points on a rotated 0.7 x 0.3 rectangle light and a skewed parallelogram light (each
  one piece: y = p0 + u1 e1 + u2 e2) and on a fan of unequal triangles vs ``pdf_area`` (on the fan and the
  parallelogram also with one uniform reused for piece and point, ``split_uniform``), and the fan's triangle choice
  vs area / A;
* ``LightSampler`` light selection ("power", "uniform") among 4 lights vs ``pdf_select``;
* ``TriangleAreaSampler`` (global area sampling) choosing triangles in proportion to their areas;
* ``PixelFilter.sample_1d`` ("tent", "gaussian") vs ``pdf_1d``.

Significance: each chi^2 test of the standard set fails when p < alpha with
alpha = 1 - (1 - 0.01)^(1/m) (Sidak, ~ 0.01 / m) for the m = len(cases.STANDARD_NAMES) = 27 tests, so the whole
file has a 1 % chance of a false alarm; the seeds are fixed, so a given tree passes or fails reproducibly. A test
also fails hard, whatever p, if a sample lands where the pdf is 0, outside the binned domain, or if the pdf does not
integrate to 1 (within 1e-3, the quadrature's accuracy).
The ``test_rejects_*`` tests feed deliberately wrong samplers to the same machinery and require rejection
(p < 1e-9, or a hard failure): they prove the tests can fail, and are not part of the m above.

Each test prints ``chi2 <name>: p = <value>`` (see them with ``pytest -s``); ``cases.standard_p_values()`` returns
the standard set's p-values to any other script.
"""

from __future__ import annotations

import numpy as np
import pytest

try:
    import chi2_cases as cases
except ImportError:  # tests/ imported as a package
    from tests import chi2_cases as cases

from harness.judges import chi2
from reference_impl import sampling
from reference_impl.filters import make_filter
from reference_impl.lights import LightSampler

ALPHA = cases.STANDARD_ALPHA
REJECT_P = 1e-9  # a deliberately wrong sampler must be rejected at least this strongly
N_WRONG = 200_000  # samples for the wrong samplers (the effects are large)


def _report(result: chi2.Chi2Result) -> chi2.Chi2Result:
    print(result.line())
    return result


# ------------------------------------------------------------------------------------------- the standard set


def test_family_alpha():
    m = 27
    assert len(cases.STANDARD_NAMES) == m
    assert ALPHA == pytest.approx(1 - 0.99 ** (1 / m))
    assert 0.01 / m <= ALPHA <= 0.0101 / m


@pytest.mark.parametrize("name", cases.STANDARD_NAMES)
def test_chi2_standard(name):
    result = _report(cases.standard_cases()[name]())
    assert result.n_samples >= 10**6
    failures = result.failures(ALPHA)
    assert not failures, f"{name}: " + "; ".join(failures)


# ----------------------------------------------------------------------------------------- frames and warps


def _normals_for_frames() -> np.ndarray:
    g = np.random.default_rng(11)
    rnd = g.normal(size=(100_000, 3))
    special = [
        (0, 0, -1), (0, 0, 1), (1, 0, 0), (0, 1, 0), (1, 0, -0.0), (0, -1, -0.0),
        (1e-9, -1e-9, -1), (1e-5, 2e-5, -1), (-3e-3, 1e-3, -1), (1e-12, 0, -1), (0.0, 1e-7, -1),
        (1e-8, 1e-8, 1),
    ]
    # Around -z: tiny random tilts on both sides of the branch z >= 0.
    near = np.column_stack([g.normal(scale=1e-4, size=(1000, 2)), -np.ones(1000)])
    n = np.vstack([rnd, np.array(special, float), near])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_coordinate_frame_is_right_handed_orthonormal():
    n = _normals_for_frames()
    s, t = sampling.coordinate_frame(n)
    dot = lambda a, b: np.sum(a * b, axis=1)  # noqa: E731
    tol = 1e-12
    assert np.all(np.isfinite(s)) and np.all(np.isfinite(t))
    np.testing.assert_allclose(dot(s, s), 1, atol=tol)
    np.testing.assert_allclose(dot(t, t), 1, atol=tol)
    for a, b in ((s, t), (s, n), (t, n)):
        np.testing.assert_allclose(dot(a, b), 0, atol=tol)
    np.testing.assert_allclose(np.cross(s, t), n, atol=tol)  # (s, t, n) right-handed
    # to_world sends the local +z to n and keeps lengths.
    local = np.tile([0.0, 0.0, 1.0], (len(n), 1))
    np.testing.assert_allclose(sampling.to_world(local, n), n, atol=tol)


@pytest.mark.parametrize("kind", ["cosine", "uniform"])
def test_sample_hemisphere_is_consistent_for_random_normals(kind):
    n = _normals_for_frames()
    g = np.random.default_rng(12)
    u1, u2 = g.random(len(n)), g.random(len(n))
    w, cos_theta, pdf = sampling.sample_hemisphere(kind, u1, u2, n)
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1, atol=1e-12)
    np.testing.assert_allclose(np.sum(w * n, axis=1), cos_theta, atol=1e-12)  # reported cos is the real one
    assert np.all(cos_theta >= 0)
    np.testing.assert_array_equal(pdf, sampling.hemisphere_pdf(kind, cos_theta))


# ------------------------------------------------------------------------------------------------------ lights


def test_rectangle_light_points_lie_on_the_light():
    light = cases.rectangle_light()
    geom, _ = cases.light_geometry([(light, (4.0, 3.0, 2.0))])
    sampler = LightSampler(geom, "power")
    g = np.random.default_rng(13)
    k, pts = sampler.sample(*(g.random(100_000) for _ in range(4)))
    assert np.all(k == 0) and np.all(geom.light_id[pts.triangle] == 0)
    x, y, z = light.to_plane(pts.position)
    assert np.max(np.abs(z)) < 1e-12
    assert np.all(light.inside(x, y, tol=1e-12))
    np.testing.assert_allclose(pts.pdf_area, 1.0 / 0.21, rtol=1e-12)  # pdf(y | k) = 1 / A, A = 0.7 * 0.3


@pytest.mark.parametrize("selection", ["power", "uniform"])
def test_light_selection_pmf_by_direct_computation(selection):
    lights = cases.four_lights()
    areas = np.array([light.area() for light, _ in lights])
    lum = np.array([np.dot(cases.LUMINANCE, le) for _, le in lights])
    want = np.pi * areas * lum if selection == "power" else np.ones(len(lights))
    want = want / want.sum()
    sampler, k, tri = cases.light_selection_samples(selection, seed=14, n=10_000)
    np.testing.assert_allclose(sampler.pdf_select(np.arange(4)), want, rtol=1e-12)
    np.testing.assert_allclose(sampler.area, areas, rtol=1e-12)
    np.testing.assert_allclose(sampler.pdf_area(np.arange(4)), want / areas, rtol=1e-12)
    assert np.all(sampler.geometry.light_id[tri] == k)  # the point lies on the chosen light
    if selection == "power":
        assert want.max() / want.min() > 5  # the lights really differ in power


# ----------------------------------------------------------------------------------------------------- filters


def test_filter_weights():
    g = np.random.default_rng(15)
    u = g.random(10**6)
    _, w_tent = make_filter("tent").sample_1d(u)
    np.testing.assert_array_equal(w_tent, 1.0)  # sampled exactly: weights 1
    _, w = make_filter("gaussian").sample_1d(u)
    assert np.all(np.isfinite(w)) and np.all(w > 0)
    mean, sem = w.mean(), w.std(ddof=1) / np.sqrt(len(w))
    # E[w] = integral h / integral h = 1; tolerance 5 standard errors of the sample mean (false alarm ~6e-7).
    print(f"gaussian filter weights: E[w] = {mean:.7f} +- {sem:.2g} (tolerance {5 * sem:.2g})")
    assert abs(mean - 1.0) <= 5 * sem


# ------------------------------------------------------------------------------- the tests can fail: wrong samplers


def _wrong_cosine(u1, u2):
    d = sampling.square_to_cosine_hemisphere(u1, u2)
    d[:, 2] = d[:, 2] ** 0.9
    return d


def _hemisphere_test(warp, pdf, name, seed=901):
    return chi2.chi2_test_2d(
        lambda n: chi2.directions_to_cos_phi(warp(*cases._uniforms(seed, n, 2))), pdf, chi2.SPHERE_COS_PHI,
        cases.HEMI_RES, N_WRONG, name=name,
    )


def test_rejects_cosine_warp_with_z_to_the_0_9():
    r = _report(_hemisphere_test(_wrong_cosine, lambda c, p: sampling.cosine_hemisphere_pdf(c), "wrong_cosine_z^0.9"))
    assert r.p_value < REJECT_P and not r.passed(ALPHA)


def test_rejects_uniform_warp_against_cosine_pdf():
    r = _report(_hemisphere_test(
        sampling.square_to_uniform_hemisphere, lambda c, p: sampling.cosine_hemisphere_pdf(c), "wrong_uniform_vs_cosine"
    ))
    assert r.p_value < REJECT_P


def test_rejects_directions_below_the_surface():
    def flipped(u1, u2):  # 1 % of the directions mirrored below the surface
        d = sampling.square_to_cosine_hemisphere(u1, u2)
        d[::100, 2] *= -1
        return d

    r = _report(_hemisphere_test(flipped, lambda c, p: sampling.cosine_hemisphere_pdf(c), "wrong_below_surface"))
    assert r.impossible == N_WRONG // 100
    assert any("pdf is 0" in f for f in r.failures(ALPHA))


def test_rejects_wrongly_normalised_pdf():
    r = _report(_hemisphere_test(
        sampling.square_to_cosine_hemisphere, lambda c, p: sampling.cosine_hemisphere_pdf(c) / 2, "wrong_normalisation"
    ))
    assert r.pdf_integral == pytest.approx(0.5, abs=1e-6)
    assert any("integrates" in f for f in r.failures(ALPHA)) and r.p_value < REJECT_P


def test_rejects_nonuniform_triangle():
    tri = cases.TRIANGLE_2D
    r = _report(chi2.chi2_test_2d(
        cases.triangle_sampler(tri, lambda u1, u2: (1.0 - u1, u2 * u1), seed=902), cases.triangle_pdf(tri),
        cases.bbox(tri), (48, 48), N_WRONG, name="wrong_triangle_b1=1-u1", quadrature="midpoint", order=24,
    ))
    assert r.impossible == 0 and r.p_value < REJECT_P


def test_rejects_points_outside_the_triangle():
    tri = cases.TRIANGLE_2D
    corners = np.vstack([tri, tri[1] + tri[2] - tri[0]])  # the parallelogram u1, u2 covers
    r = _report(chi2.chi2_test_2d(
        cases.triangle_sampler(tri, lambda u1, u2: (u1, u2), seed=903), cases.triangle_pdf(tri), cases.bbox(corners),
        (48, 48), N_WRONG, name="wrong_triangle_parallelogram", quadrature="midpoint", order=24,
    ))
    assert r.impossible > 0.4 * N_WRONG and not r.passed(ALPHA)


def _uniform_triangle_choice(sampler):
    """Corrupt a LightSampler: pick each light's triangles with equal probability instead of by area."""
    cdf = sampler.within_cdf.copy()
    for k in range(sampler.num_lights):
        m = sampler.count[k]
        cdf[sampler.first[k] : sampler.first[k] + m] = np.arange(1, m + 1) / m
    sampler.within_cdf = cdf


def test_rejects_fan_light_with_equal_triangle_probabilities():
    light = cases.fan_light()
    geom, _ = cases.light_geometry([(light, (4.0, 3.0, 2.0))])
    sampler, sample, pdf = cases.light_point_sampler(geom, light, seed=904)
    _uniform_triangle_choice(sampler)
    r = _report(chi2.chi2_test_2d(
        sample, pdf, cases.bbox(light.polygon), (48, 32), N_WRONG, name="wrong_fan_points_equal_triangles",
        quadrature="midpoint", order=24,
    ))
    assert r.p_value < REJECT_P
    areas = light.triangle_areas()
    choice = cases.fan_triangle_choices(905, N_WRONG, mutate=_uniform_triangle_choice)
    r = _report(chi2.chi2_test_discrete(choice, areas / areas.sum(), name="wrong_fan_triangle_choice"))
    assert r.p_value < REJECT_P


def test_rejects_parallelogram_sampled_as_its_first_triangle():
    """The parallelogram's frame with the triangle warp (its flag cleared): every point in the half a + b <= 1, at
    twice the density."""
    light = cases.parallelogram_light()
    geom, _ = cases.light_geometry([(light, (4.0, 3.0, 2.0))])
    sampler, sample, pdf = cases.light_point_sampler(geom, light, seed=907)
    assert sampler.parallelogram.tolist() == [True]
    sampler.parallelogram = np.zeros(1, bool)
    r = _report(chi2.chi2_test_2d(
        sample, pdf, cases.bbox(light.polygon), (48, 32), N_WRONG, name="wrong_parallelogram_triangle_warp",
        quadrature="midpoint", order=24,
    ))
    assert r.impossible == 0 and r.p_value < REJECT_P


def test_rejects_uniform_selection_against_power_pmf():
    power, _, _ = cases.light_selection_samples("power", seed=906, n=10)
    _, k, _ = cases.light_selection_samples("uniform", seed=906, n=N_WRONG)
    r = _report(chi2.chi2_test_discrete(k, power.pdf_select(np.arange(4)), name="wrong_selection_uniform_vs_power"))
    assert r.p_value < REJECT_P


def test_rejects_tent_offsets_against_gaussian_pdf():
    tent, gauss = make_filter("tent"), make_filter("gaussian")
    u = np.random.default_rng(907)
    r = _report(chi2.chi2_test_1d(
        lambda n: tent.sample_1d(u.random(n))[0], gauss.pdf_1d, (-gauss.radius, gauss.radius), 128, N_WRONG,
        name="wrong_filter_tent_vs_gaussian", quadrature="midpoint", order=16,
    ))
    assert r.p_value < REJECT_P


# ------------------------------------------------------------------------------------------- the helper itself


def test_pooling_and_dof():
    observed = np.array([100, 98, 103, 2, 1, 0, 3])
    expected = np.array([100.0, 100.0, 100.0, 2.0, 1.5, 0.0, 1.5])  # pool: 5 expected, 6 observed
    stat, dof, cells, pooled = chi2.pooled_statistic(observed, expected)
    assert (cells, pooled, dof) == (4, 4, 3)
    assert stat == pytest.approx(0 + 4 / 100 + 9 / 100 + 1 / 5)
    # A pool too small to stand alone joins the smallest regular cell.
    stat, dof, cells, pooled = chi2.pooled_statistic(np.array([50, 60, 1]), np.array([55.0, 55.0, 1.0]))
    assert (cells, dof) == (2, 1) and stat == pytest.approx(25 / 56 + 25 / 55)


def test_discrete_out_of_range_and_impossible():
    r = chi2.chi2_test_discrete(np.array([0, 1, 1, 2, 3, -1] * 100), [0.5, 0.5, 0.0, 0.0])
    assert r.out_of_domain == 100 and r.impossible == 200 and not r.passed(ALPHA)


def test_bin_integrals_with_jacobian():
    # Uniform density on the unit sphere in (theta, phi): J = sin(theta); the bins sum to 1.
    prob = chi2.bin_integrals(
        lambda t, p: np.full_like(t, 1 / (4 * np.pi)), ((0, np.pi), (0, 2 * np.pi)), (16, 8),
        jacobian=lambda t, p: np.sin(t),
    )
    assert prob.shape == (16, 8) and prob.sum() == pytest.approx(1, abs=1e-12)
    edges = np.linspace(0, np.pi, 17)
    np.testing.assert_allclose(prob.sum(axis=1), (np.cos(edges[:-1]) - np.cos(edges[1:])) / 2, atol=1e-13)


def test_standard_p_values_are_quotable():
    # Only the cheap part: the names and the function exist (the values themselves come from test_chi2_standard).
    assert callable(cases.standard_p_values) and set(cases.standard_cases()) == set(cases.STANDARD_NAMES)
