"""The thin dielectric and the smooth plastic (reference_impl/kernels/bsdf.py) against Mitsuba 3.9.1's own
``thindielectric`` and ``plastic`` plugins (variant scalar_rgb), against their own pdfs, and in the white furnace.

* Mitsuba agreement, over a grid of angles (both sides for the thin sheet, the front for plastic) and parameters
  (int_ior / ext_ior, nonlinear, colours): the thin sheet's two delta lobes through ``BSDF.sample`` (direction,
  weight, the lobe's probability R' = 2 F / (1 + F) and 1 - R'); plastic's ``eval`` and ``pdf`` (its diffuse part),
  its specular lobe through ``sample`` (sample1 = 0) and its diffuse lobe's weight and pdf at the direction Mitsuba
  draws (its cosine warp is Mitsuba's own: the two warps differ, the densities agree). Tolerance 2e-5 relative
  (Mitsuba's float32).
* Chi-square of plastic's sampler against its own pdf (tests/reference_impl/bsdf_cases.py: the specular lobe's samples
  are the cell that expects n P_s, the probability the diffuse pdf leaves off the sphere), and the discrete
  probability of the thin sheet's reflection lobe (a binomial z of the count of reflections against n R').
* Weights: a non-delta sample's weight is f |cos| / pdf and its pdf bsdf_pdf's; a delta lobe's weight is its value
  over its probability (thin: R, T; plastic: R F / P_s).
* The white furnace: the albedo a(wo) = integral of f |cos| d omega + the delta lobes' value, ours (the sampler's
  mean weight, and a Gauss-Legendre quadrature of eval plus the delta parts) against Mitsuba's (the same quadrature of
  its eval, plus its delta samples' weight x pdf); :func:`furnace_rows` prints the table (``pytest -s``).
* The planted faults: "thin-glass-refracts" (the straight-through direction bent by Snell's law) and
  "plastic-no-internal-reflection" (diff = rho) must disagree with Mitsuba.
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
from reference_impl.kernels.config import M_PLASTIC_NO_INTERNAL_REFLECTION, M_THIN_GLASS_REFRACTS
from reference_impl.materials import (P_IOR, P_SPECULAR_WEIGHT, PLASTIC, THINDIELECTRIC,
                                      fresnel_diffuse_reflectance, material_row)

mi = pytest.importorskip("mitsuba")
mi.set_variant("scalar_rgb")

RTOL, ATOL = 2e-5, 1e-6
COSINES = (0.95, 0.6, 0.3, 0.05)
AIR = 1.000277


def _rgb(value):
    return {"type": "rgb", "value": list(value)}


#: (name, Mitsuba's dict, our material_row keywords)
THIN_CASES = [
    ("thin-default", {"type": "thindielectric"}, {}),
    ("thin-water-tinted", {"type": "thindielectric", "int_ior": 1.33, "ext_ior": 1.0,
                           "specular_reflectance": _rgb((0.9, 0.8, 0.7)),
                           "specular_transmittance": _rgb((0.5, 0.6, 0.9))},
     dict(int_ior=1.33, ext_ior=1.0, reflectance=(0.9, 0.8, 0.7), transmittance=(0.5, 0.6, 0.9))),
    ("thin-dense-inverted", {"type": "thindielectric", "int_ior": 1.0, "ext_ior": 2.4}, dict(int_ior=1.0, ext_ior=2.4)),
]
PLASTIC_CASES = [
    ("plastic-default", {"type": "plastic"}, {}),
    ("plastic-coloured", {"type": "plastic", "diffuse_reflectance": _rgb((0.2, 0.5, 0.8)),
                          "specular_reflectance": _rgb((0.9, 0.3, 0.6)), "int_ior": 1.6, "ext_ior": 1.0},
     dict(diffuse=(0.2, 0.5, 0.8), reflectance=(0.9, 0.3, 0.6), int_ior=1.6, ext_ior=1.0)),
    ("plastic-nonlinear", {"type": "plastic", "diffuse_reflectance": _rgb((0.9, 0.5, 0.1)), "nonlinear": True,
                           "int_ior": 1.33}, dict(diffuse=(0.9, 0.5, 0.1), nonlinear=True, int_ior=1.33)),
    ("plastic-white-dense", {"type": "plastic", "diffuse_reflectance": 1.0, "int_ior": 2.5, "ext_ior": 1.0},
     dict(diffuse=1.0, int_ior=2.5, ext_ior=1.0)),
    ("plastic-inverted", {"type": "plastic", "int_ior": 1.0, "ext_ior": 1.5, "nonlinear": True},
     dict(int_ior=1.0, ext_ior=1.5, nonlinear=True)),
]


def _one(kind, kw) -> Materials:
    kw = dict(kw)
    if "int_ior" in kw or kind == THINDIELECTRIC:
        kw.setdefault("ext_ior", AIR)
    return cases.one(kind, **kw)


def _mi_sample(plugin, wo, u_lobe, u=(0.3, 0.7)):
    bs, w = plugin.sample(mi.BSDFContext(), cases.mitsuba_interaction(mi, wo), u_lobe, mi.Point2f(*u))
    return np.array(bs.wo), np.array(w), float(bs.pdf)


def _thin_r(eta, c):
    f = bsdf.fresnel_dielectric(abs(c), eta)[0]
    return 2 * f / (1 + f)


# ------------------------------------------------------------------------------------------- Mitsuba agreement


@pytest.mark.parametrize("name, spec, kw", THIN_CASES, ids=[c[0] for c in THIN_CASES])
def test_thin_dielectric_samples_agree_with_mitsuba(name, spec, kw):
    plugin, materials = mi.load_dict(spec), _one(THINDIELECTRIC, kw)
    for c in COSINES + tuple(-x for x in COSINES):
        wo = cases.direction(c, phi=1.1)
        for u_lobe in (0.0, 1.0 - 1e-7):
            wi_mi, w_mi, p_mi = _mi_sample(plugin, wo, u_lobe)
            s = bsdf.sample(materials, 0, wo, [[u_lobe, 0.3, 0.7]])
            assert s["ok"][0] and s["delta"][0]
            np.testing.assert_allclose(s["wi"][0], wi_mi, rtol=1e-6, atol=1e-7, err_msg=f"{name} {c} {u_lobe}")
            np.testing.assert_allclose(s["weight"][0], w_mi, rtol=RTOL, atol=ATOL, err_msg=f"{name} {c}")
            np.testing.assert_allclose(s["pdf"][0], p_mi, rtol=RTOL, atol=ATOL, err_msg=f"{name} {c}")
        f, p = bsdf.eval_pdf(materials, 0, wo, [-wo, [-wo[0], -wo[1], wo[2]]])
        assert not f.any() and not p.any()  # both lobes are deltas


@pytest.mark.parametrize("name, spec, kw", PLASTIC_CASES, ids=[c[0] for c in PLASTIC_CASES])
def test_plastic_agrees_with_mitsuba(name, spec, kw):
    plugin, materials = mi.load_dict(spec), _one(PLASTIC, kw)
    g = np.random.default_rng(4)
    for c in COSINES:
        wo = cases.direction(c, phi=0.4)
        for ci in (0.9, 0.5, 0.1, -0.4):
            wi = cases.direction(ci, phi=g.uniform(0, 2 * np.pi))
            f_mi, p_mi = cases.mitsuba_eval_pdf(mi, plugin, wo, wi)
            f, p = bsdf.eval_pdf(materials, 0, wo, wi[None])
            np.testing.assert_allclose(f[0], f_mi, rtol=RTOL, atol=ATOL, err_msg=f"{name} eval {c} {ci}")
            np.testing.assert_allclose(p[0], p_mi, rtol=RTOL, atol=ATOL, err_msg=f"{name} pdf {c} {ci}")
        # the specular lobe, and the diffuse lobe at the direction Mitsuba draws
        wi_mi, w_mi, p_mi = _mi_sample(plugin, wo, 0.0)
        s = bsdf.sample(materials, 0, wo, [[0.0, 0.3, 0.7]])
        assert s["ok"][0] and s["delta"][0]
        np.testing.assert_allclose(s["wi"][0], wi_mi, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(s["weight"][0], w_mi, rtol=RTOL, atol=ATOL, err_msg=f"{name} specular {c}")
        np.testing.assert_allclose(s["pdf"][0], p_mi, rtol=RTOL, atol=ATOL)
        wi_mi, w_mi, p_mi = _mi_sample(plugin, wo, 1.0 - 1e-7)
        s = bsdf.sample(materials, 0, wo, [[1.0 - 1e-7, 0.3, 0.7]])
        if s["delta"][0]:  # total internal reflection (eta < 1): the specular lobe's probability is 1
            np.testing.assert_allclose([s["pdf"][0], *s["weight"][0]], [p_mi, *w_mi], rtol=RTOL, atol=ATOL)
            continue
        f, p = bsdf.eval_pdf(materials, 0, wo, wi_mi[None])
        np.testing.assert_allclose(p[0], p_mi, rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(f[0] / p[0], w_mi, rtol=RTOL, atol=ATOL, err_msg=f"{name} diffuse {c}")
    # behind a one-sided plastic: nothing, as Mitsuba
    back = cases.direction(-0.5)
    assert not _mi_sample(plugin, back, 0.0)[1].any()
    assert not bsdf.sample(materials, 0, back, [[0.0, 0.3, 0.7]])["ok"][0]
    assert not bsdf.eval_pdf(materials, 0, back, cases.direction(-0.3)[None])[0].any()


def test_plastic_sampling_weight_and_fdr_are_mitsubas():
    """The specular sampling weight s_mean / (d_mean + s_mean) and F_dr(1 / eta) that Mitsuba's plastic prints."""
    plugin = mi.load_dict(PLASTIC_CASES[1][1])
    text = str(plugin)
    row = material_row(PLASTIC, **PLASTIC_CASES[1][2])
    weight = float(text.split("specular_sampling_weight = ")[1].split(",")[0])
    fdr_int = float(text.split("fdr_int = ")[1].split(",")[0])
    assert row[P_SPECULAR_WEIGHT] == pytest.approx(weight, rel=1e-5)
    assert fresnel_diffuse_reflectance(1 / row[P_IOR]) == pytest.approx(fdr_int, rel=1e-5)
    assert material_row(PLASTIC)[P_IOR] == pytest.approx(1.49 / AIR)  # polypropylene in air, Mitsuba's default


# -------------------------------------------------------------------------------- samplers against their pdfs


@pytest.mark.parametrize("kw, c", [(dict(diffuse=(0.2, 0.5, 0.8)), 0.7), (dict(diffuse=0.3, int_ior=2.0), 0.1),
                                   (dict(diffuse=0.9, reflectance=0.2, two_sided=True), -0.5)],
                         ids=["front", "grazing-dense", "two-sided-behind"])
def test_plastic_sampler_matches_its_pdf(kw, c):
    materials = _one(PLASTIC, kw)
    wo = cases.direction(c)
    result = cases.bsdf_chi2(materials, wo, seed=31, name=f"plastic {kw} cos {c}", n=40_000)
    print(result.line())
    ps = _plastic_ps(materials, wo)
    assert result.impossible == 0 and result.p_value >= 1e-3, result.line()
    assert result.pdf_integral == pytest.approx(1 - ps, abs=2e-3)


def _plastic_ps(materials, wo):
    return float(bsdf.sample(materials, 0, wo, [[0.0, 0.5, 0.5]])["pdf"][0])


@pytest.mark.parametrize("name, spec, kw", THIN_CASES, ids=[c[0] for c in THIN_CASES])
def test_thin_dielectric_lobe_probability(name, spec, kw):
    materials = _one(THINDIELECTRIC, kw)
    n = 20_000
    for c in (0.9, 0.2, -0.6):
        wo = cases.direction(c)
        s = bsdf.sample(materials, 0, wo, cases.uniforms(5, n))
        reflected = s["wi"][:, 2] * wo[2] > 0
        r = _thin_r(materials.params[0, P_IOR], c)
        if r < 1:
            z = (reflected.sum() - n * r) / np.sqrt(n * r * (1 - r))
            assert abs(z) < 4, (c, reflected.mean(), r)
        else:  # total internal reflection at the first interface (eta < 1): the sheet is a mirror
            assert reflected.all()
        np.testing.assert_allclose(s["pdf"], np.where(reflected, r, 1 - r), rtol=1e-12)
        np.testing.assert_allclose(s["wi"][~reflected], np.broadcast_to(-wo, s["wi"][~reflected].shape), atol=1e-15)


# ------------------------------------------------------------------------------------------------- the weights


@pytest.mark.parametrize("name, spec, kw", PLASTIC_CASES, ids=[c[0] for c in PLASTIC_CASES])
def test_plastic_weight_is_eval_over_pdf(name, spec, kw):
    materials = _one(PLASTIC, kw)
    row = materials.params[0]
    for c in COSINES:
        wo = cases.direction(c)
        s = bsdf.sample(materials, 0, wo, cases.uniforms(6, 2000))
        smooth = s["ok"] & ~s["delta"]
        f, p = bsdf.eval_pdf(materials, 0, wo, s["wi"][smooth])
        np.testing.assert_allclose(s["pdf"][smooth], p, rtol=1e-12)
        np.testing.assert_allclose(s["weight"][smooth], f / p[:, None], rtol=1e-12)
        f_o = bsdf.fresnel_dielectric(c, row[P_IOR])[0]
        ps = f_o * row[P_SPECULAR_WEIGHT] / (f_o * row[P_SPECULAR_WEIGHT] + (1 - f_o) * (1 - row[P_SPECULAR_WEIGHT]))
        spec_lobe = s["delta"]
        assert spec_lobe.any() and (smooth.any() or ps == 1.0)
        np.testing.assert_allclose(s["pdf"][spec_lobe], ps, rtol=1e-12)
        np.testing.assert_allclose(s["weight"][spec_lobe], np.broadcast_to(row[0:3] * f_o / ps, (spec_lobe.sum(), 3)),
                                   rtol=1e-12)


@pytest.mark.parametrize("name, spec, kw", THIN_CASES, ids=[c[0] for c in THIN_CASES])
def test_thin_dielectric_weights_are_lobe_values_over_probabilities(name, spec, kw):
    materials = _one(THINDIELECTRIC, kw)
    row = materials.params[0]
    for c in (0.8, -0.3):
        wo = cases.direction(c)
        s = bsdf.sample(materials, 0, wo, cases.uniforms(7, 2000))
        reflected = s["wi"][:, 2] * wo[2] > 0
        r = _thin_r(row[P_IOR], c)
        # value R r' (T (1 - r')) over probability r' (1 - r'): the colour alone, and the mean weight x pdf is the
        # lobes' sum R r' + T (1 - r')
        np.testing.assert_allclose(s["weight"][reflected], np.broadcast_to(row[0:3], (reflected.sum(), 3)))
        np.testing.assert_allclose(s["weight"][~reflected], np.broadcast_to(row[9:12], ((~reflected).sum(), 3)))
        assert bsdf.sample_eta(THINDIELECTRIC, row, wo[2], -wo[2]) == 1.0
        assert s["delta"].all() and r > 0


def test_is_delta():
    assert bsdf.is_delta(THINDIELECTRIC) and not bsdf.is_delta(PLASTIC)


# --------------------------------------------------------------------------------------------- white furnace

NODES, WEIGHTS = np.polynomial.legendre.leggauss(96)
CI = 0.5 * (NODES + 1.0)  # cos theta_i on (0, 1)
QW = 0.5 * WEIGHTS * 2 * np.pi  # d omega = d cos d phi; the plastic's eval does not depend on phi


def _albedo_ours(materials, wo, mutant=0):
    """delta lobes' value (weight x probability) + the quadrature of eval over the hemisphere of wo."""
    delta, lobes = np.zeros(3), set()
    for u_lobe in (0.0, 1.0 - 1e-12):
        s = bsdf.sample(materials, 0, wo, [[u_lobe, 0.5, 0.5]], mutant=mutant)
        lobe = bool(s["wi"][0, 2] * wo[2] > 0)  # each delta lobe once (one of probability 1 is drawn by both)
        if s["ok"][0] and s["delta"][0] and lobe not in lobes:
            delta += s["weight"][0] * s["pdf"][0]
            lobes.add(lobe)
    side = np.sign(wo[2])
    wi = np.stack([np.sqrt(1 - CI**2), np.zeros_like(CI), side * CI], axis=1)
    f, _ = bsdf.eval_pdf(materials, 0, wo, wi, mutant=mutant)
    return delta + QW @ f


def _albedo_mitsuba(plugin, wo, thin):
    delta, lobes = np.zeros(3), set()
    for u_lobe in ((0.0, 1.0 - 1e-7) if thin else (0.0,)):
        wi, w, p = _mi_sample(plugin, wo, u_lobe)
        if bool(wi[2] * wo[2] > 0) not in lobes:
            delta += w * p
            lobes.add(bool(wi[2] * wo[2] > 0))
    wi = np.stack([np.sqrt(1 - CI**2), np.zeros_like(CI), np.sign(wo[2]) * CI], axis=1)
    f = np.array([cases.mitsuba_eval_pdf(mi, plugin, wo, d)[0] for d in wi]) if not thin else np.zeros((len(CI), 3))
    return delta + QW @ f


def furnace_rows():
    """(name, cos theta_o, ours by quadrature, ours by the sampler's mean weight, Mitsuba's) of every case."""
    rows = []
    for kind, table in ((THINDIELECTRIC, THIN_CASES), (PLASTIC, PLASTIC_CASES)):
        for name, spec, kw in table:
            plugin, materials = mi.load_dict(spec), _one(kind, kw)
            for c in (0.9, 0.5, 0.1) if kind == PLASTIC else (0.9, 0.1, -0.5):
                wo = cases.direction(c)
                sampled = bsdf.sample(materials, 0, wo, cases.uniforms(9, 40_000))
                mean = np.where(sampled["ok"][:, None], sampled["weight"], 0.0).mean(axis=0)
                se = np.where(sampled["ok"][:, None], sampled["weight"], 0.0).std(axis=0) / np.sqrt(40_000)
                rows.append((name, c, _albedo_ours(materials, wo), mean, se,
                             _albedo_mitsuba(plugin, wo, kind == THINDIELECTRIC)))
    return rows


def test_white_furnace_albedo_agrees_with_mitsuba():
    for name, c, ours, sampled, se, theirs in furnace_rows():
        print(f"furnace {name} cos {c:+.2f}: ours {np.round(ours, 5)} (sampled {np.round(sampled, 4)}) "
              f"Mitsuba {np.round(theirs, 5)}")
        np.testing.assert_allclose(ours, theirs, rtol=5e-5, atol=1e-6, err_msg=f"{name} {c}")
        assert np.all(np.abs(sampled - ours) <= 5 * se + 1e-9), (name, c, sampled, ours, se)
    thin = _one(THINDIELECTRIC, {})
    for c in (0.9, 0.1, -0.7):  # a white sheet loses nothing: R' + (1 - R') = 1
        np.testing.assert_allclose(_albedo_ours(thin, cases.direction(c)), 1.0, rtol=1e-12)


# ----------------------------------------------------------------------------------------- the planted faults


def test_thin_glass_refracts_disagrees_with_mitsuba():
    spec, kw = THIN_CASES[0][1:]
    plugin, materials = mi.load_dict(spec), _one(THINDIELECTRIC, kw)
    wo = cases.direction(0.6)
    wi_mi, _, _ = _mi_sample(plugin, wo, 1.0 - 1e-7)
    good = bsdf.sample(materials, 0, wo, [[1.0 - 1e-7, 0.3, 0.7]])["wi"][0]
    bad = bsdf.sample(materials, 0, wo, [[1.0 - 1e-7, 0.3, 0.7]], mutant=M_THIN_GLASS_REFRACTS)["wi"][0]
    np.testing.assert_allclose(good, wi_mi, rtol=1e-6, atol=1e-7)
    assert np.degrees(np.arccos(np.clip(bad @ wi_mi, -1, 1))) > 10  # bent by 17 degrees at 53 degrees' incidence
    assert abs(np.linalg.norm(bad) - 1) < 1e-12 and bad[2] < 0


def test_plastic_no_internal_reflection_disagrees_with_mitsuba():
    spec, kw = PLASTIC_CASES[1][1:]
    plugin, materials = mi.load_dict(spec), _one(PLASTIC, kw)
    wo = cases.direction(0.7)
    theirs = _albedo_mitsuba(plugin, wo, False)
    np.testing.assert_allclose(_albedo_ours(materials, wo), theirs, rtol=5e-5)
    bad = _albedo_ours(materials, wo, mutant=M_PLASTIC_NO_INTERNAL_REFLECTION)
    assert np.all(bad < theirs * 0.8), (bad, theirs)  # the base darker by about 1 - F_dr = 0.35


# ------------------------------------------------------------------------------------------------ validation


@pytest.mark.parametrize("kind, kw, words", [
    (THINDIELECTRIC, dict(transmittance=(0.5, 2.0, 0.5)), "specular_transmittance in [0, 1]"),
    (THINDIELECTRIC, dict(two_sided=True), "two_sided does not apply to a thindielectric"),
    (THINDIELECTRIC, dict(int_ior=-1.0), "int_ior / ext_ior > 0"),
    (PLASTIC, dict(diffuse=(0.5, 1.5, 0.5)), "diffuse_reflectance in [0, 1]"),
    (PLASTIC, dict(int_ior=5.0, ext_ior=1.0), "internal diffuse Fresnel reflectance"),
    (PLASTIC, dict(specular_sampling_weight=1.5), "specular sampling weight in [0, 1]"),
])
def test_validation(kind, kw, words):
    with pytest.raises(SettingsError) as err:
        Materials(np.array([kind]), material_row(kind, **kw)[None])
    assert words in str(err.value) and "materials.params[0]" in str(err.value) and "\n" not in str(err.value)

