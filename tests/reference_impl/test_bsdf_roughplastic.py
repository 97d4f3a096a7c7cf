"""The rough plastic (reference_impl/kernels/bsdf.py, kind ROUGHPLASTIC) against Mitsuba 3.9.1's own
``roughplastic`` plugin (variant scalar_rgb), against its own pdf, and in the white furnace.

* The table (``bsdf.roughplastic_luts``): Mitsuba's external transmittance T(mu) at its 64 cosines and internal reflectance,
  read back from Mitsuba's diffuse component (``BSDFContext.component = 1``: diff / (pi eta^2) T(mu_o) T(mu_i)
  cos theta_i), to 2e-5 relative for eta > 1 (Mitsuba integrates in float32).
* Mitsuba agreement of ``eval`` and ``pdf`` over a grid of angles x alpha in {0.01, 0.1, 0.3, 0.7} x both
  distributions x sample_visible x nonlinear x two sets of indices and colours, to 2e-5 relative + 1e-6 absolute;
  the Beckmann visible-normal pdf to 4e-3 (the exact Smith G1, as the rough conductor's: bsdf.py's "Where this
  differs"). An inverted coating (int_ior < ext_ior: Mitsuba's 128 x 128 quadrature of an integrand with a
  total-internal-reflection edge, in float32) agrees to 1e-3. Directions are given to both as float32 numbers. The sample at Mitsuba's own draws: the glossy lobe
  (sample1 = 0) the same direction for the same (u1, u2), weight and pdf; the diffuse lobe's weight and pdf at the
  direction Mitsuba draws.
* Chi-square of the sampler against its pdf over alpha x distribution x sample_visible x two angles, and a two-sided
  one from behind.
* Weights: every sample's weight is eval / pdf and its pdf bsdf_pdf's.
* The white furnace: the albedo a(wo) = integral of f |cos| d omega, ours (a Gauss-Legendre quadrature of eval over
  the hemisphere, and the sampler's mean weight) against Mitsuba's (the same quadrature of its eval), over alpha x
  int_ior; :func:`furnace_rows` prints the table (``pytest -s``).
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
from reference_impl.materials import (BECKMANN, GGX, LUT_RES, P_INTERNAL_REFLECTANCE, P_LUT, PLASTIC, ROUGHPLASTIC,
                                      ROW_SIZE, NUM_PARAMS, TEXTURE_SLOTS, material_row)
from reference_impl.textures import Bitmap, Textures

mi = pytest.importorskip("mitsuba")
mi.set_variant("scalar_rgb")

RTOL, ATOL = 2e-5, 1e-6
AIR = 1.000277
ALPHAS = (0.01, 0.1, 0.3, 0.7)
DISTS = {"beckmann": BECKMANN, "ggx": GGX}


def _rgb(value):
    return {"type": "rgb", "value": list(value)}


#: (name, Mitsuba's keys, our material_row keywords) of the colours and indices
LOOKS = [("default-ior", {}, {}),
         ("coloured-dense", {"diffuse_reflectance": _rgb((0.2, 0.5, 0.9)), "specular_reflectance": _rgb((0.9, 0.7, 1.0)),
                             "int_ior": 1.9, "ext_ior": 1.0},
          dict(diffuse=(0.2, 0.5, 0.9), reflectance=(0.9, 0.7, 1.0), int_ior=1.9, ext_ior=1.0))]


def _pair(dist, alpha, visible, nonlinear, look_mi, look_kw, **extra):
    spec = {"type": "roughplastic", "distribution": dist, "alpha": alpha, "sample_visible": visible,
            "nonlinear": nonlinear, **look_mi}
    kw = dict(distribution=DISTS[dist], alpha=alpha, sample_visible=visible, nonlinear=nonlinear, **look_kw)
    if "int_ior" not in kw:
        kw["ext_ior"] = AIR
    kw.update(extra)
    spec = {"type": "twosided", "bsdf": spec} if extra.get("two_sided") else spec
    return mi.load_dict(spec), cases.one(ROUGHPLASTIC, **kw)


def _mi_sample(plugin, wo, u_lobe, u):
    bs, w = plugin.sample(mi.BSDFContext(), cases.mitsuba_interaction(mi, wo), u_lobe, mi.Point2f(*u))
    return np.array(bs.wo), np.array(w), float(bs.pdf)


def _mi_diffuse(plugin, wo, wi):
    ctx = mi.BSDFContext()
    ctx.component = 1
    return float(plugin.eval(ctx, cases.mitsuba_interaction(mi, wo), mi.Vector3f(*wi))[0])


# ------------------------------------------------------------------------------------------------- the table


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("alpha, ior", [(0.01, 1.49), (0.1, 1.8), (0.3, 1.33), (0.7, 2.4)])
def test_the_table_is_mitsubas(dist, alpha, ior):
    """T(mu_k) / T(1) from Mitsuba's diffuse component at mu_i = mu_k, mu_o = 1 (exactly the nodes: its lerp reads
    one entry there), and R_i from the absolute value."""
    plugin, materials = _pair(dist, alpha, True, False, {"int_ior": ior, "ext_ior": 1.0}, dict(int_ior=ior,
                                                                                            ext_ior=1.0))
    lut = bsdf.roughplastic_luts(materials)[0]
    top = cases.direction(1.0)
    ref = _mi_diffuse(plugin, top, top)
    for k in range(1, LUT_RES):
        mu = k / (LUT_RES - 1)
        ratio = _mi_diffuse(plugin, cases.direction(mu), top) / ref
        assert lut[k] / lut[-2] == pytest.approx(ratio, rel=RTOL, abs=1e-6), (k, mu)
    # diff / (pi eta^2) T(1)^2 with diff = 0.5 / (1 - R_i)
    ri = 1 - 0.5 * lut[LUT_RES - 1] ** 2 / (np.pi * ior**2 * ref)
    assert lut[LUT_RES] == pytest.approx(ri, rel=RTOL)


def test_the_material_step_appends_the_table():
    materials = cases.one(ROUGHPLASTIC, alpha=0.2)
    from reference_impl.kernels.records import material_tables
    from reference_impl.kernels.material import material_params
    tables = material_tables(materials, lut=bsdf.roughplastic_luts(materials))
    row = np.full(ROW_SIZE, np.nan)
    assert material_params(tables, 0, row) == ROUGHPLASTIC
    np.testing.assert_array_equal(row[:NUM_PARAMS], materials.params[0])
    np.testing.assert_array_equal(row[P_LUT:], tables.lut[0])
    assert 0 < row[P_INTERNAL_REFLECTANCE] < 1
    with pytest.raises(SettingsError, match="a rough plastic needs its table"):
        material_tables(materials)
    short = np.full(NUM_PARAMS, np.nan)  # an engine of Lambertian scenes: the row alone
    material_params(tables, 0, short)
    np.testing.assert_array_equal(short, materials.params[0])


# ------------------------------------------------------------------------------------------- Mitsuba agreement

GRID = [(co, ci, dphi) for co in (0.99, 0.7, 0.3, 0.05) for ci in (0.95, 0.6, 0.2, 0.03)
        for dphi in (np.pi, np.pi + 0.15, 2.0)]


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("alpha", ALPHAS)
def test_eval_and_pdf_agree_with_mitsuba(dist, alpha):
    pdf_rtol = 4e-3 if dist == "beckmann" else RTOL
    for visible in (True, False):
        for nonlinear in (False, True):
            for look, look_mi, look_kw in LOOKS:
                plugin, materials = _pair(dist, alpha, visible, nonlinear, look_mi, look_kw)
                rtol = pdf_rtol if visible else RTOL
                for co, ci, dphi in GRID:
                    wo, wi = _f32(cases.direction(co, 0.4)), _f32(cases.direction(ci, 0.4 + dphi))
                    f_mi, p_mi = cases.mitsuba_eval_pdf(mi, plugin, wo, wi)
                    f, p = bsdf.eval_pdf(materials, 0, wo, wi[None])
                    where = f"{look} visible {visible} nonlinear {nonlinear} at {co}, {ci}, {dphi:.2f}"
                    np.testing.assert_allclose(f[0], f_mi, rtol=RTOL, atol=ATOL, err_msg=f"eval {where}")
                    np.testing.assert_allclose(p[0], p_mi, rtol=rtol, atol=ATOL, err_msg=f"pdf {where}")
                for c in (0.9, 0.4, 0.1):
                    _check_samples(plugin, materials, cases.direction(c, 1.1), visible and dist == "beckmann")


def _f32(d):
    """The direction as Mitsuba's float32 holds it (the narrowest lobe's peak, f ~ 5000 at grazing, moves by 2e-5
    with the rounding of its input)."""
    return d.astype(np.float32).astype(np.float64)


def _check_samples(plugin, materials, wo, fit_pdf):
    """The glossy lobe at sample1 = 0 (Mitsuba's direction for the same u1, u2) and the diffuse lobe (sample1 -> 1)
    at the direction Mitsuba draws."""
    rtol = 4e-3 if fit_pdf else RTOL
    for u in ((0.3, 0.7), (0.8, 0.15)):
        wi_mi, w_mi, p_mi = _mi_sample(plugin, wo, 0.0, u)
        s = bsdf.sample(materials, 0, wo, [[0.0, *u]])
        if not w_mi.any():
            assert not s["ok"][0] or not s["weight"][0].any()
            continue
        assert s["ok"][0] and not s["delta"][0]
        # to 1e-4: Mitsuba's float32 (Beckmann's slope CDF inverted by 3 Newton steps, ours to convergence; the
        # all-normals Beckmann draw's 1 + alpha^2 tan^2 at alpha 0.01)
        np.testing.assert_allclose(s["wi"][0], wi_mi, rtol=0, atol=1e-4)
        f, p = bsdf.eval_pdf(materials, 0, wo, wi_mi[None])
        np.testing.assert_allclose(p[0], p_mi, rtol=rtol, atol=ATOL)
        np.testing.assert_allclose(f[0] / p[0], w_mi, rtol=rtol, atol=ATOL)
        wi_mi, w_mi, p_mi = _mi_sample(plugin, wo, 1.0 - 1e-7, u)
        f, p = bsdf.eval_pdf(materials, 0, wo, wi_mi[None])
        np.testing.assert_allclose(p[0], p_mi, rtol=rtol, atol=ATOL)
        np.testing.assert_allclose(f[0] / p[0], w_mi, rtol=rtol, atol=ATOL)


def test_inverted_coating_agrees_with_mitsuba():
    """int_ior < ext_ior: Mitsuba's tables at 128 x 128 nodes over an integrand with a total-internal-reflection
    edge, in float32: 1e-3."""
    for dist in DISTS:
        for alpha in (0.05, 0.3):
            plugin, materials = _pair(dist, alpha, False, True, {"int_ior": 1.0, "ext_ior": 1.4},
                                      dict(int_ior=1.0, ext_ior=1.4))
            for co, ci, dphi in GRID:
                wo, wi = cases.direction(co, 0.4), cases.direction(ci, 0.4 + dphi)
                f_mi, p_mi = cases.mitsuba_eval_pdf(mi, plugin, wo, wi)
                f, p = bsdf.eval_pdf(materials, 0, wo, wi[None])
                np.testing.assert_allclose(f[0], f_mi, rtol=1e-3, atol=ATOL, err_msg=f"{dist} {alpha} {co} {ci}")
                np.testing.assert_allclose(p[0], p_mi, rtol=1e-3, atol=ATOL, err_msg=f"{dist} {alpha} {co} {ci}")


def test_two_sided_and_one_sided_backs():
    plugin, materials = _pair("ggx", 0.3, True, False, {}, {}, two_sided=True)
    for co, ci in ((-0.7, -0.4), (-0.2, -0.9)):
        wo, wi = cases.direction(co, 0.3), cases.direction(ci, 2.9)
        f_mi, p_mi = cases.mitsuba_eval_pdf(mi, plugin, wo, wi)
        f, p = bsdf.eval_pdf(materials, 0, wo, wi[None])
        np.testing.assert_allclose(f[0], f_mi, rtol=RTOL, atol=ATOL)
        np.testing.assert_allclose(p[0], p_mi, rtol=RTOL, atol=ATOL)
    plugin, materials = _pair("ggx", 0.3, True, False, {}, {})
    back = cases.direction(-0.5)
    assert not _mi_sample(plugin, back, 0.0, (0.3, 0.7))[1].any()
    assert not bsdf.sample(materials, 0, back, [[0.0, 0.3, 0.7]])["ok"][0]
    assert not bsdf.eval_pdf(materials, 0, back, cases.direction(-0.3)[None])[0].any()
    assert not bsdf.eval_pdf(materials, 0, cases.direction(0.5), cases.direction(-0.3)[None])[0].any()
    assert not bsdf.is_delta(ROUGHPLASTIC)


# -------------------------------------------------------------------------------- the sampler against its pdf

CHI2 = [(dist, alpha, visible, c) for dist in DISTS for alpha in (0.05, 0.3, 0.7) for visible in (True, False)
        for c in (0.9, 0.15)]


@pytest.mark.parametrize("dist, alpha, visible, c", CHI2,
                         ids=[f"{d}-{a}-{'visible' if v else 'all'}-cos{c}" for d, a, v, c in CHI2])
def test_sampler_matches_its_pdf(dist, alpha, visible, c):
    materials = cases.one(ROUGHPLASTIC, distribution=DISTS[dist], alpha=alpha, sample_visible=visible,
                          diffuse=(0.3, 0.5, 0.2), reflectance=0.8)
    wo = cases.direction(c)
    result = cases.bsdf_chi2(materials, wo, seed=int(alpha * 100) + 7 * visible + int(c * 10),
                             name=f"roughplastic {dist} alpha {alpha} visible {visible} cos {c}", n=40_000)
    print(result.line())
    assert result.impossible == 0 and result.p_value >= 1e-3, result.line()


def test_sampler_matches_its_pdf_two_sided_from_behind():
    materials = cases.one(ROUGHPLASTIC, alpha=0.2, two_sided=True, int_ior=1.7, ext_ior=1.0)
    result = cases.bsdf_chi2(materials, cases.direction(-0.5), seed=77, name="roughplastic two-sided", n=40_000)
    print(result.line())
    assert result.impossible == 0 and result.p_value >= 1e-3, result.line()


# ------------------------------------------------------------------------------------------------- the weights


@pytest.mark.parametrize("dist", DISTS)
@pytest.mark.parametrize("visible", [True, False])
def test_weight_is_eval_over_pdf(dist, visible):
    for alpha in (0.01, 0.3):
        materials = cases.one(ROUGHPLASTIC, distribution=DISTS[dist], alpha=alpha, sample_visible=visible,
                              diffuse=(0.9, 0.5, 0.1), nonlinear=True)
        for c in (0.95, 0.4, 0.05):
            wo = cases.direction(c)
            s = bsdf.sample(materials, 0, wo, cases.uniforms(6, 2000))
            ok = s["ok"]
            assert ok.mean() > 0.5 and not s["delta"].any()
            f, p = bsdf.eval_pdf(materials, 0, wo, s["wi"][ok])
            np.testing.assert_allclose(s["pdf"][ok], p, rtol=1e-12)
            np.testing.assert_allclose(s["weight"][ok], f / p[:, None], rtol=1e-12)
            assert np.all(s["wi"][ok, 2] > 0) and np.allclose(np.linalg.norm(s["wi"][ok], axis=1), 1.0)


# --------------------------------------------------------------------------------------------- white furnace

NODES, WEIGHTS = np.polynomial.legendre.leggauss(64)
CI = 0.5 * (NODES + 1.0)
PHI = np.pi * (NODES + 1.0)  # azimuth on (0, 2 pi)
QW = np.outer(0.5 * WEIGHTS, np.pi * WEIGHTS).ravel()  # d omega = d cos d phi
G_NODES, G_WEIGHTS = np.polynomial.legendre.leggauss(128)  # the glossy lobe's chart: g on (-1, 1)


def _hemisphere():
    """The diffuse part's nodes and weights: Gauss-Legendre in cos theta and phi."""
    c, phi = np.meshgrid(CI, PHI, indexing="ij")
    s = np.sqrt(1 - c**2)
    return np.stack([(s * np.cos(phi)).ravel(), (s * np.sin(phi)).ravel(), c.ravel()], axis=1), QW


def _glossy_chart(wo):
    """The glossy part's nodes and weights: bsdf_cases' chart about the mirror direction (cos of the angle to it
    c = sign(g) (1 - (1 - |g|)^4), dense near the axis: d omega = 4 (1 - |g|)^3 dg dphi), nodes above the surface."""
    frame = cases._frame(np.array([-wo[0], -wo[1], wo[2]]))
    g, phi = np.meshgrid(G_NODES, PHI, indexing="ij")
    d = cases._from_chart(g.ravel(), phi.ravel(), frame)
    w = np.outer(G_WEIGHTS * 4 * (1 - np.abs(G_NODES)) ** 3, np.pi * WEIGHTS).ravel()
    above = d[:, 2] > 0
    return d[above], w[above]


def _mi_component(plugin, wo, wi, component):
    ctx = mi.BSDFContext()
    ctx.component = component  # 0: the glossy coating, 1: the diffuse base
    si = cases.mitsuba_interaction(mi, wo)
    return np.array([np.array(plugin.eval(ctx, si, mi.Vector3f(*d))) for d in wi])


FURNACE = [(alpha, ior) for alpha in (0.05, 0.3, 0.7) for ior in (1.33, 1.49, 2.0)]


def furnace_rows():
    """(alpha, int_ior, cos theta_o, ours by quadrature, ours by the sampler's mean weight, its standard error,
    Mitsuba's by the same quadrature) for a white base (diffuse_reflectance 1, ggx). The quadrature takes each part
    on its own nodes (ours: the material without its base, and without its coating; Mitsuba's: its components)."""
    hemi, hemi_w = _hemisphere()
    rows = []
    for alpha, ior in FURNACE:
        kw = dict(int_ior=ior, ext_ior=1.0)
        plugin, materials = _pair("ggx", alpha, True, False, {**kw, "diffuse_reflectance": 1.0}, dict(**kw, diffuse=1.0))
        glossy = cases.one(ROUGHPLASTIC, distribution=GGX, alpha=alpha, diffuse=0.0, reflectance=1.0, **kw)
        base = cases.one(ROUGHPLASTIC, distribution=GGX, alpha=alpha, diffuse=1.0, reflectance=0.0, **kw)
        for c in (0.9, 0.5, 0.1):
            wo = cases.direction(c, 0.0)
            lobe, lobe_w = _glossy_chart(wo)
            ours = lobe_w @ bsdf.eval_pdf(glossy, 0, wo, lobe)[0] + hemi_w @ bsdf.eval_pdf(base, 0, wo, hemi)[0]
            theirs = lobe_w @ _mi_component(plugin, wo, lobe, 0) + hemi_w @ _mi_component(plugin, wo, hemi, 1)
            s = bsdf.sample(materials, 0, wo, cases.uniforms(9, 40_000))
            w = np.where(s["ok"][:, None], s["weight"], 0.0)
            rows.append((alpha, ior, c, ours, w.mean(axis=0), w.std(axis=0) / np.sqrt(len(w)), theirs))
    return rows


def test_white_furnace_albedo_agrees_with_mitsuba():
    for alpha, ior, c, ours, sampled, se, theirs in furnace_rows():
        print(f"furnace roughplastic ggx alpha {alpha} int_ior {ior} cos {c:.1f}: ours {ours[0]:.5f} "
              f"(sampled {sampled[0]:.4f} +- {se[0]:.4f}) Mitsuba {theirs[0]:.5f}")
        np.testing.assert_allclose(ours, theirs, rtol=5e-5, atol=1e-6, err_msg=f"{alpha} {ior} {c}")
        assert np.all(np.abs(sampled - ours) <= 5 * se + 1e-4), (alpha, ior, c, sampled, ours, se)


# ------------------------------------------------------------------------------------------------ validation


@pytest.mark.parametrize("kw, words", [
    (dict(alpha=0.0), "alpha > 0"),
    (dict(int_ior=1.2, ext_ior=1.2), "expected int_ior != ext_ior"),
    (dict(diffuse=(0.5, 1.5, 0.5)), "diffuse_reflectance in [0, 1]"),
    (dict(int_ior=-1.0, ext_ior=1.0), "int_ior / ext_ior > 0"),
    (dict(nonlinear=2), None),
])
def test_validation(kw, words):
    if words is None:  # material_row makes the flag a bool: write the bad value into the row
        row = material_row(ROUGHPLASTIC)
        row[6] = 2.0
        words = "expected nonlinear 0 or 1"
    else:
        row = material_row(ROUGHPLASTIC, **kw)
    with pytest.raises(SettingsError) as err:
        Materials(np.array([ROUGHPLASTIC]), row[None])
    assert words in str(err.value) and "materials.params[0]" in str(err.value) and "\n" not in str(err.value)


def test_a_dense_coating_is_no_error_for_the_rough_plastic():
    """The smooth plastic's bound from F_dr's fit does not apply (the rough one integrates its R_i)."""
    with pytest.raises(SettingsError):
        Materials(np.array([PLASTIC]), material_row(PLASTIC, int_ior=5.0, ext_ior=1.0)[None])
    materials = Materials(np.array([ROUGHPLASTIC]), material_row(ROUGHPLASTIC, int_ior=5.0, ext_ior=1.0)[None])
    assert 0 < bsdf.roughplastic_luts(materials)[0, -1] < 1


def test_a_textured_alpha_is_refused():
    bitmap = Bitmap(np.full((2, 2, 3), 0.2))
    texture = np.full((1, len(TEXTURE_SLOTS)), -1)
    texture[0, list(TEXTURE_SLOTS).index("alpha")] = 0
    with pytest.raises(SettingsError, match="Mitsuba's roughplastic takes no texture for it"):
        Materials(np.array([ROUGHPLASTIC]), material_row(ROUGHPLASTIC)[None], texture, Textures((bitmap,)))
