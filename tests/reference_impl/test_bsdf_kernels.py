"""The BSDF kernels (reference_impl/kernels/bsdf.py) and the material table (reference_impl/materials.py).

* every sampled weight equals f |cos| / pdf at the sampled direction (bsdf_eval / bsdf_pdf), and the pdf a sample
  returns is bsdf_pdf's, for every model, distribution, sampling mode and side (to 1e-9 relative);
* the delta BSDFs against closed forms: the conductor's weight at normal incidence is R ((n - 1)^2 + k^2) /
  ((n + 1)^2 + k^2) (Born & Wolf), a mirror's is R; the smooth dielectric reflects with probability
  ((eta - 1) / (eta + 1))^2 at normal incidence, refracts by Snell's law with weight T / eta_it^2 (the radiance
  scaling), and an index-matched one passes everything straight through; "conductor-fresnel-one" and
  "refraction-no-eta2" break these;
* energy: the mean weight (times eta_it^2 on transmissions, which removes the radiance scaling) is at most 1 for
  white materials, within 5 standard errors, and the diffuse one is rho to 5 standard errors;
* reciprocity: f(wo, wi) = f(wi, wo) for the reflections, and f(wo, wi) / eta_o^2 = f(wi, wo) / eta_i^2 for
  transmission through the rough dielectric (radiance BSDFs, Veach 1997, sec. 5.2), eta_x the index of x's side;
* the numerical limits: alpha = 1e-4 and 1, grazing directions, k = 0, an index-matched dielectric give finite,
  non-negative values, pdfs and weights;
* the table's validation: one-line SettingsErrors naming the row.
"""

from __future__ import annotations

import numpy as np
import pytest

try:
    import bsdf_cases as cases
except ImportError:  # tests/ imported as a package
    from tests.reference_impl import bsdf_cases as cases

from reference_impl import Materials, SettingsError
from reference_impl.kernels import bsdf
from reference_impl.kernels.config import MUTANT_BITS
from reference_impl.materials import (BECKMANN, CONDUCTOR, DIELECTRIC, DIFFUSE, GGX, NUM_PARAMS, P_ALPHA, P_IOR,
                                      P_REFLECTANCE, P_TWO_SIDED, PLASTIC, ROUGHCONDUCTOR, ROUGHDIELECTRIC,
                                      THINDIELECTRIC, material_row)

N = 20_000
ROUGH = [(kind, dist, visible, alpha) for kind in (ROUGHCONDUCTOR, ROUGHDIELECTRIC) for dist in (BECKMANN, GGX)
         for visible in (True, False) for alpha in (0.05, 0.3, 1.0)]
COSINES = (0.9, 0.3, 0.05, -0.4, -0.9)


def _rough(kind, dist, visible, alpha, **kw):
    return cases.one(kind, alpha=alpha, distribution=dist, sample_visible=visible, int_ior=1.5, ext_ior=1.0,
                     two_sided=kind == ROUGHCONDUCTOR, **cases.CU, **kw)


@pytest.mark.parametrize("mutant", [0, MUTANT_BITS["microfacet-pdf-no-jacobian"]], ids=["correct", "no-jacobian"])
@pytest.mark.parametrize("case", ROUGH, ids=[f"{k}-{d}-{'vis' if v else 'all'}-{a}" for k, d, v, a in ROUGH])
def test_weight_is_eval_over_pdf(case, mutant):
    materials = _rough(*case)
    for c in COSINES:
        wo = cases.direction(c)
        s = bsdf.sample(materials, 0, wo, cases.uniforms(3, 2000), mutant=mutant)
        ok = s["ok"]
        assert ok.any()
        f, p = bsdf.eval_pdf(materials, 0, wo, s["wi"][ok], mutant=mutant)
        assert np.all(p > 0)
        np.testing.assert_allclose(s["pdf"][ok], p, rtol=1e-9)
        np.testing.assert_allclose(s["weight"][ok], f / p[:, None], rtol=1e-9)
        assert not s["delta"].any()


@pytest.mark.parametrize("hemisphere", ["cosine", "uniform"])
@pytest.mark.parametrize("two_sided, cos_o", [(False, 0.6), (True, -0.4)], ids=["front", "two-sided-behind"])
def test_the_diffuse_weight_is_eval_over_pdf(hemisphere, two_sided, cos_o):
    """The diffuse kind, both of its samplers (``hemisphere``): weight = f |cos| / pdf, the pdf the one
    bsdf_pdf gives, wi on wo's side."""
    materials = cases.one(DIFFUSE, reflectance=(0.3, 0.5, 0.9), two_sided=two_sided)
    wo = cases.direction(cos_o)
    s = bsdf.sample(materials, 0, wo, cases.uniforms(12, 2000), hemisphere=hemisphere)
    ok = s["ok"]
    assert ok.mean() > 0.99
    f, p = bsdf.eval_pdf(materials, 0, wo, s["wi"][ok], hemisphere=hemisphere)
    assert np.all(p > 0) and np.all(s["wi"][ok][:, 2] * cos_o > 0)
    np.testing.assert_allclose(s["pdf"][ok], p, rtol=1e-12)
    np.testing.assert_allclose(s["weight"][ok], f / p[:, None], rtol=1e-12)


def test_no_jacobian_mutant_changes_the_pdf_only_by_the_jacobian():
    materials = _rough(ROUGHCONDUCTOR, GGX, True, 0.3)
    wo = cases.direction(0.6)
    s = bsdf.sample(materials, 0, wo, cases.uniforms(4, 1000))
    ok = s["ok"]
    wi = s["wi"][ok]
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1)[:, None]
    p_bad = bsdf.eval_pdf(materials, 0, wo, wi, mutant=MUTANT_BITS["microfacet-pdf-no-jacobian"])[1]
    np.testing.assert_allclose(p_bad, s["pdf"][ok] * 4 * (wi * h).sum(1), rtol=1e-9)


def test_diffuse_weight_and_sides():
    materials = Materials.diffuse([[0.2, 0.5, 0.8], [0.2, 0.5, 0.8]], [False, True])
    for m, back_ok in ((0, False), (1, True)):
        s = bsdf.sample(materials, m, cases.direction(-0.5), cases.uniforms(5, 100))
        assert s["ok"].all() == back_ok and s["ok"].any() == back_ok
        if back_ok:
            assert np.all(s["wi"][:, 2] < 0)
            np.testing.assert_array_equal(s["weight"], np.broadcast_to([0.2, 0.5, 0.8], (100, 3)))
    s = bsdf.sample(materials, 0, cases.direction(0.5), cases.uniforms(5, 100))
    np.testing.assert_array_equal(s["weight"], np.broadcast_to([0.2, 0.5, 0.8], (100, 3)))
    f, p = bsdf.eval_pdf(materials, 0, cases.direction(0.5), [cases.direction(-0.3), cases.direction(0.25)])
    np.testing.assert_allclose(f, [[0, 0, 0], np.array([0.2, 0.5, 0.8]) * 0.25 / np.pi])
    np.testing.assert_allclose(p, [0, 0.25 / np.pi])
    assert Materials.diffuse([[0.5] * 3], [False]).all_diffuse


def _normal_incidence_conductor(eta, k):
    return ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2)


@pytest.mark.parametrize("mutant", ["", "conductor-fresnel-one"])
def test_conductor_against_normal_incidence_fresnel(mutant):
    bit = MUTANT_BITS.get(mutant, 0)
    cu = cases.one(CONDUCTOR, reflectance=(0.9, 0.8, 0.7), **cases.CU)
    s = bsdf.sample(cu, 0, [0, 0, 1.0], [[0.5, 0.5, 0.5]], mutant=bit)
    expect = np.array([0.9, 0.8, 0.7]) * _normal_incidence_conductor(np.array(cases.CU["eta"]),
                                                                      np.array(cases.CU["k"]))
    assert s["ok"][0] and s["delta"][0] and s["pdf"][0] == 1.0
    np.testing.assert_allclose(s["wi"][0], [0, 0, 1.0])
    matches = np.allclose(s["weight"][0], expect, rtol=1e-12)
    assert matches == (mutant == ""), (s["weight"][0], expect)
    # the rough conductor's Fresnel term at normal incidence: alpha -> 1e-4 concentrates f |cos| / pdf at F
    rough = cases.one(ROUGHCONDUCTOR, alpha=1e-4, **cases.CU)
    w = bsdf.sample(rough, 0, [0, 0, 1.0], cases.uniforms(6, 50), mutant=bit)["weight"]
    f0 = _normal_incidence_conductor(np.array(cases.CU["eta"]), np.array(cases.CU["k"]))
    assert np.allclose(w, f0, rtol=1e-6) == (mutant == "")
    mirror = cases.one(CONDUCTOR, reflectance=0.6, mirror=True)
    s = bsdf.sample(mirror, 0, cases.direction(0.3), [[0.1, 0.2, 0.3]], mutant=bit)
    np.testing.assert_allclose(s["weight"][0], 0.6)
    np.testing.assert_allclose(s["wi"][0], cases.direction(0.3, phi=0.3 + np.pi), atol=1e-15)


def test_conductor_fresnel_grazing_limit_and_k_zero():
    assert bsdf.fresnel_conductor(0.0, 0.2, 3.9) == pytest.approx(1.0)
    # k = 0: the conductor formula is the dielectric's Fresnel term
    for c in (1.0, 0.7, 0.2, 0.01):
        assert bsdf.fresnel_conductor(c, 1.5, 0.0) == pytest.approx(bsdf.fresnel_dielectric(c, 1.5)[0], rel=1e-12)


@pytest.mark.parametrize("mutant", ["", "refraction-no-eta2"])
def test_dielectric_against_closed_forms(mutant):
    bit = MUTANT_BITS.get(mutant, 0)
    eta = 1.5
    glass = cases.one(DIELECTRIC, reflectance=0.9, transmittance=(0.8, 0.7, 0.6), int_ior=eta, ext_ior=1.0)
    r0 = ((eta - 1) / (eta + 1)) ** 2
    refl = bsdf.sample(glass, 0, [0, 0, 1.0], [[r0 * 0.999, 0.5, 0.5]], mutant=bit)
    trans = bsdf.sample(glass, 0, [0, 0, 1.0], [[r0 * 1.001, 0.5, 0.5]], mutant=bit)
    assert refl["delta"][0] and trans["delta"][0]
    np.testing.assert_allclose(refl["wi"][0], [0, 0, 1.0])
    np.testing.assert_allclose(trans["wi"][0], [0, 0, -1.0])
    np.testing.assert_allclose([refl["pdf"][0], trans["pdf"][0]], [r0, 1 - r0], rtol=1e-12)
    np.testing.assert_allclose(refl["weight"][0], 0.9)
    expect_t = np.array([0.8, 0.7, 0.6]) / eta ** 2
    assert np.allclose(trans["weight"][0], expect_t, rtol=1e-12) == (mutant == "")
    # oblique, from inside: Snell's law and the weight T eta^2
    wo = cases.direction(-0.9)
    s = bsdf.sample(glass, 0, wo, [[0.999, 0.5, 0.5]], mutant=bit)
    wi = s["wi"][0]
    assert wi[2] > 0
    np.testing.assert_allclose(np.hypot(wi[0], wi[1]), eta * np.hypot(wo[0], wo[1]), rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(wi), 1.0, rtol=1e-12)
    assert np.allclose(s["weight"][0], np.array([0.8, 0.7, 0.6]) * eta ** 2, rtol=1e-12) == (mutant == "")
    # beyond the critical angle: total internal reflection whatever u_lobe
    s = bsdf.sample(glass, 0, cases.direction(-0.5), [[0.999, 0.5, 0.5]], mutant=bit)
    assert s["wi"][0][2] < 0 and s["pdf"][0] == 1.0


def test_index_matched_dielectric_is_invisible():
    clear = cases.one(DIELECTRIC, int_ior=1.33, ext_ior=1.33)
    for c in (0.9, 0.05, -0.3):
        wo = cases.direction(c)
        s = bsdf.sample(clear, 0, wo, cases.uniforms(7, 100))
        assert s["ok"].all() and s["delta"].all()
        np.testing.assert_allclose(s["wi"], np.broadcast_to(-wo, (100, 3)), atol=1e-15)
        np.testing.assert_array_equal(s["weight"], 1.0)
    assert bsdf.fresnel_dielectric(0.7, 1.0)[0] == 0.0


@pytest.mark.parametrize("case", ROUGH[::2], ids=[f"{k}-{d}-{'vis' if v else 'all'}-{a}" for k, d, v, a in ROUGH[::2]])
def test_energy_bound(case):
    materials = _rough(*case, reflectance=1.0)
    for c in (0.9, 0.05, -0.7):
        wo = cases.direction(c)
        s = bsdf.sample(materials, 0, wo, cases.uniforms(8, N))
        w = s["weight"][:, 0].copy()
        trans = s["ok"] & (s["wi"][:, 2] * wo[2] < 0)
        eta_it = np.where(wo[2] > 0, 1.5, 1 / 1.5)
        w[trans] *= eta_it ** 2
        mean, se = w.mean(), w.std() / np.sqrt(N)
        assert mean <= 1.0 + 5 * se + 1e-12, (c, mean, se)


def test_diffuse_albedo():
    materials = Materials.diffuse([[0.3, 0.6, 0.9]], [False])
    w = bsdf.sample(materials, 0, cases.direction(0.4), cases.uniforms(9, N))["weight"]
    np.testing.assert_allclose(w.mean(0), [0.3, 0.6, 0.9])


def _random_pairs(seed, n, same_side):
    g = np.random.default_rng(seed)
    a = g.normal(size=(n, 3))
    b = g.normal(size=(n, 3))
    a /= np.linalg.norm(a, axis=1)[:, None]
    b /= np.linalg.norm(b, axis=1)[:, None]
    b[:, 2] = np.abs(b[:, 2]) * np.sign(a[:, 2]) * (1 if same_side else -1)
    return a, b


@pytest.mark.parametrize("case", ROUGH + [(DIFFUSE, 0, True, 0.1)],
                         ids=[f"{k}-{d}-{'vis' if v else 'all'}-{a}" for k, d, v, a in ROUGH] + ["diffuse"])
def test_reciprocity(case):
    materials = _rough(*case) if case[0] != DIFFUSE else Materials.diffuse([[0.5, 0.5, 0.5]], [True])
    for same in (True, False):
        if not same and case[0] != ROUGHDIELECTRIC:
            continue
        wo, wi = _random_pairs(10, 1000, same)
        f_oi = np.array([bsdf.eval_pdf(materials, 0, o, i[None])[0][0] for o, i in zip(wo, wi)])
        f_io = np.array([bsdf.eval_pdf(materials, 0, i, o[None])[0][0] for o, i in zip(wo, wi)])
        f_oi /= np.abs(wi[:, 2])[:, None]
        f_io /= np.abs(wo[:, 2])[:, None]
        if not same:
            eta_o2 = np.where(wo[:, 2] > 0, 1.0, 1.5 ** 2)[:, None]
            eta_i2 = np.where(wi[:, 2] > 0, 1.0, 1.5 ** 2)[:, None]
            f_oi, f_io = f_oi * eta_i2, f_io * eta_o2
        assert np.count_nonzero(f_oi[:, 0]) >= 10
        np.testing.assert_allclose(f_oi, f_io, rtol=1e-9, atol=1e-300)


@pytest.mark.parametrize("kind", [DIFFUSE, CONDUCTOR, ROUGHCONDUCTOR, DIELECTRIC, ROUGHDIELECTRIC, THINDIELECTRIC,
                                  PLASTIC])
def test_numerical_limits_stay_finite(kind):
    variants = [dict(alpha=1e-4), dict(alpha=1.0), dict(alpha=0.3, eta=(1.5, 0.2, 0.0), k=(0.0, 0.0, 0.0)),
                dict(alpha=0.3, int_ior=1.0001, ext_ior=1.0), dict(alpha=0.3, distribution=GGX, sample_visible=False)]
    if kind in (DIELECTRIC, THINDIELECTRIC, PLASTIC):
        variants.append(dict(int_ior=1.0, ext_ior=1.0))
    if kind == PLASTIC:
        variants += [dict(diffuse=0.0, reflectance=0.0), dict(diffuse=1.0, nonlinear=True, int_ior=3.5, ext_ior=1.0)]
    g = np.random.default_rng(11)
    dirs = g.normal(size=(4000, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    dirs[:200, 2] = 1e-9  # grazing
    dirs[200:400, 2] = -1e-9
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    for kw in variants:
        materials = cases.one(kind, **kw)
        for wo in (cases.direction(1e-6), cases.direction(0.5), cases.direction(-1e-6), cases.direction(1.0),
                   cases.direction(-0.99)):
            f, p = bsdf.eval_pdf(materials, 0, wo, dirs)
            assert np.all(np.isfinite(f)) and np.all(f >= 0) and np.all(np.isfinite(p)) and np.all(p >= 0), kw
            s = bsdf.sample(materials, 0, wo, cases.uniforms(12, 4000))
            ok = s["ok"]
            for key in ("wi", "weight", "pdf"):
                assert np.all(np.isfinite(s[key][ok])), (kw, wo, key)
            assert np.all(s["weight"][ok] >= 0) and np.all(s["pdf"][ok] >= 0)


def test_is_delta_and_sample_eta():
    kinds = np.array([DIFFUSE, CONDUCTOR, ROUGHCONDUCTOR, DIELECTRIC, ROUGHDIELECTRIC])
    assert [bsdf.is_delta(k) for k in kinds] == [False, True, False, True, False]
    params = np.array([material_row(k, int_ior=1.5, ext_ior=1.0) for k in kinds])
    assert bsdf.sample_eta(kinds[3], params[3], 0.5, -0.5) == 1.5
    assert bsdf.sample_eta(kinds[4], params[4], -0.5, 0.5) == pytest.approx(1 / 1.5)
    assert bsdf.sample_eta(kinds[4], params[4], 0.5, 0.5) == 1.0
    assert bsdf.sample_eta(kinds[2], params[2], 0.5, -0.5) == 1.0


def test_erfinv():
    import math
    for x in (-3.5, -1.0, -1e-3, 0.0, 0.4, 2.0, 4.0):
        # erf rounds to 1e-16; its inverse cannot do better than that over erf'(x)
        tol = 1e-14 + 4e-16 / (2 / math.sqrt(math.pi) * math.exp(-x * x))
        assert bsdf.erfinv(math.erf(x)) == pytest.approx(x, rel=0, abs=tol)


# ------------------------------------------------------------------------------------------------- validation


def _table(kind, **kw):
    return Materials(np.array([kind]), material_row(kind, **kw)[None])


@pytest.mark.parametrize("kind, kw, words", [
    (DIFFUSE, dict(reflectance=1.2), "reflectance in [0, 1]"),
    (ROUGHCONDUCTOR, dict(alpha=0.0), "alpha > 0"),
    (ROUGHDIELECTRIC, dict(alpha=-1.0), "alpha > 0"),
    (CONDUCTOR, dict(k=(-1.0, 0.0, 0.0)), "k >= 0"),
    (DIELECTRIC, dict(int_ior=-1.5), "int_ior / ext_ior > 0"),
    (DIELECTRIC, dict(two_sided=True), "two_sided does not apply"),
    (ROUGHDIELECTRIC, dict(int_ior=1.2, ext_ior=1.2), "int_ior != ext_ior"),
    (DIELECTRIC, dict(transmittance=(0.5, 2.0, 0.5)), "specular_transmittance in [0, 1]"),
    (ROUGHCONDUCTOR, dict(distribution=2), "distribution 0 or 1"),
])
def test_validation(kind, kw, words):
    with pytest.raises(SettingsError) as err:
        _table(kind, **kw)
    assert words in str(err.value) and "materials.params[0]" in str(err.value)
    assert "\n" not in str(err.value)


def test_validation_shapes_and_kinds():
    with pytest.raises(SettingsError, match="shape"):
        Materials(np.array([DIFFUSE]), np.zeros((1, NUM_PARAMS - 1)))
    with pytest.raises(SettingsError, match="kinds"):
        Materials(np.array([99]), np.zeros((1, NUM_PARAMS)))
    bad = material_row(DIFFUSE)
    bad[P_ALPHA] = np.nan
    with pytest.raises(SettingsError, match="finite"):
        Materials(np.array([DIFFUSE]), bad[None])


def test_table_is_frozen_and_builds_from_geometry_arrays():
    t = Materials.diffuse([[0.1, 0.2, 0.3], [1, 1, 1]], [True, False])
    assert len(t) == 2 and t.all_diffuse
    np.testing.assert_array_equal(t.params[:, P_REFLECTANCE:P_REFLECTANCE + 3], [[0.1, 0.2, 0.3], [1, 1, 1]])
    np.testing.assert_array_equal(t.params[:, P_TWO_SIDED], [1, 0])
    with pytest.raises(ValueError):
        t.params[0, 0] = 0.5
    mixed = Materials(np.array([DIFFUSE, DIELECTRIC]), np.array([material_row(DIFFUSE), material_row(DIELECTRIC)]))
    assert not mixed.all_diffuse
    assert mixed.params[1, P_IOR] == pytest.approx(1.5046 / 1.000277)
