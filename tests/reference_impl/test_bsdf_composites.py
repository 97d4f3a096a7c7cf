"""The materials made of others (reference_impl/kernels/composite.py, the material step's resolution in
reference_impl/kernels/material.py) against Mitsuba 3.9.1's own ``blendbsdf``, ``mask`` and ``twosided`` plugins
(variant scalar_rgb), against their own pdfs, and in the white furnace.

* Mitsuba agreement of eval and pdf over a grid of directions (both sides of the surface) for blends, masks and
  twosided pairs of diffuse, rough conductor and plastic materials, nested in each other; the mask's hole through
  ``sample`` (its direction -wo, probability 1 - opacity, weight 1); Mitsuba's blend sample weight against our
  eval / pdf at the direction it drew. Tolerance 2e-5 relative (Mitsuba's float32).
* Chi-square of each composite's sampler against its own pdf (tests/reference_impl/bsdf_cases.py; the hole and the
  other delta lobes are the cell of what the pdf leaves off the sphere), alpha = 1e-3 per case; the weight test:
  a non-delta sample's weight is f |cos| / pdf and its pdf the door's.
* The material step: a blend's material is its second with probability w (binomial z over 200 000 uniforms, |z| < 5),
  a twosided's the front one exactly where wo is in front.
* The white furnace: the albedo of each composite by quadrature of eval plus its delta parts, ours against
  Mitsuba's, and the sampler's mean weight within 5 standard errors.
"""

from __future__ import annotations

import numpy as np
import pytest

try:
    import bsdf_cases as cases
except ImportError:  # tests/ imported as a package
    from tests.reference_impl import bsdf_cases as cases

from reference_impl import Materials, SettingsError
from reference_impl.kernels import composite
from reference_impl.kernels.material import resolve_nested
from reference_impl.kernels.records import material_tables
from reference_impl.materials import (BLENDBSDF, DIELECTRIC, DIFFUSE, GGX, MASK, PLASTIC, ROUGHCONDUCTOR, TWOSIDED,
                                      material_row)

mi = pytest.importorskip("mitsuba")
mi.set_variant("scalar_rgb")

RTOL, ATOL = 2e-5, 1e-6

#: the leaves: (our kind, material_row keywords, Mitsuba's dict)
LEAVES = {
    "white": (DIFFUSE, dict(reflectance=(0.8, 0.7, 0.6)), {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.7, 0.6]}}),
    "rough": (ROUGHCONDUCTOR, dict(alpha=0.3, distribution=GGX, eta=(0.2, 0.9, 1.1), k=(3.9, 2.4, 2.1)),
              {"type": "roughconductor", "alpha": 0.3, "distribution": "ggx",
               "eta": {"type": "rgb", "value": [0.2, 0.9, 1.1]}, "k": {"type": "rgb", "value": [3.9, 2.4, 2.1]}}),
    "plastic": (PLASTIC, dict(diffuse=(0.2, 0.5, 0.3), int_ior=1.49, ext_ior=1.000277),
                {"type": "plastic", "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.3]},
                 "int_ior": 1.49, "ext_ior": 1.000277}),
}


def _table(top_kind, weight, names, inner=None):
    """Row 0 the composite over the leaves ``names`` (rows 1, 2, ...), or over row 3 ``inner`` = (kind, weight,
    names) where names[j] is "inner"."""
    leaves = [n for n in names if n != "inner"] + (list(inner[2]) if inner else [])
    rows = {n: j + 1 for j, n in enumerate(dict.fromkeys(leaves))}
    count = len(rows) + 1
    if inner:
        rows["inner"] = count
        count += 1
    kinds, params = [top_kind], [material_row(top_kind, weight=weight, nested=tuple(rows[n] for n in names))]
    for n in dict.fromkeys(leaves):
        kind, kw, _ = LEAVES[n]
        kinds.append(kind)
        params.append(material_row(kind, **kw))
    if inner:
        kinds.append(inner[0])
        params.append(material_row(inner[0], weight=inner[1], nested=tuple(rows[n] for n in inner[2])))
    return Materials(np.array(kinds), np.array(params))


def _mitsuba(kind, weight, names, inner=None):
    def spec(n):
        if n == "inner":
            return _mitsuba(*inner)
        return LEAVES[n][2]
    if kind == BLENDBSDF:
        return {"type": "blendbsdf", "weight": weight, "bsdf_0": spec(names[0]), "bsdf_1": spec(names[1])}
    if kind == MASK:
        return {"type": "mask", "opacity": weight, "bsdf": spec(names[0])}
    return {"type": "twosided", "bsdf_0": spec(names[0]), "bsdf_1": spec(names[1])}


#: (name, kind, weight, nested names[, inner])
CASES = [
    ("blend-white-rough-0.3", BLENDBSDF, 0.3, ("white", "rough")),
    ("blend-plastic-rough-0.7", BLENDBSDF, 0.7, ("plastic", "rough")),
    ("blend-weight-0", BLENDBSDF, 0.0, ("white", "rough")),
    ("blend-weight-1", BLENDBSDF, 1.0, ("white", "rough")),
    ("mask-white-0.4", MASK, 0.4, ("white", "white")),
    ("mask-rough-0.75", MASK, 0.75, ("rough", "rough")),
    ("twosided-white-rough", TWOSIDED, 0.5, ("white", "rough")),
    ("twosided-of-a-blend", TWOSIDED, 0.5, ("inner", "white"), (BLENDBSDF, 0.5, ("white", "rough"))),
    ("blend-of-a-twosided", BLENDBSDF, 0.6, ("white", "inner"), (TWOSIDED, 0.5, ("plastic", "rough"))),
]
COSINES = (0.95, 0.6, 0.2, -0.4, -0.9)


def _case(name):
    c = next(c for c in CASES if c[0] == name)
    inner = c[4] if len(c) > 4 else None
    return _table(c[1], c[2], c[3], inner), mi.load_dict(_mitsuba(c[1], c[2], c[3], inner))


def _grid_directions():
    return [cases.direction(c, phi) for c in (0.9, 0.5, 0.1, -0.3, -0.8) for phi in (0.3, 2.0, 4.1)]


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_eval_and_pdf_agree_with_mitsuba(name):
    materials, plugin = _case(name)
    for c in COSINES:
        wo = cases.direction(c, 1.1)
        wi = np.array(_grid_directions())
        f, p = composite.eval_pdf(materials, 0, wo, wi)
        theirs = [cases.mitsuba_eval_pdf(mi, plugin, wo, d) for d in wi]
        np.testing.assert_allclose(f, np.array([t[0] for t in theirs]), rtol=RTOL, atol=ATOL, err_msg=f"{name} {c}")
        np.testing.assert_allclose(p, np.array([t[1] for t in theirs]), rtol=RTOL, atol=ATOL, err_msg=f"{name} {c}")


def _mi_sample(plugin, wo, sample1, sample2=(0.3, 0.7)):
    si, ctx = cases.mitsuba_interaction(mi, wo), mi.BSDFContext()
    bs, weight = plugin.sample(ctx, si, sample1, mi.Point2f(*sample2))
    return np.array(bs.wo), float(bs.pdf), np.array(weight)


def test_mask_hole_is_mitsubas_null_lobe():
    materials, plugin = _case("mask-rough-0.75")
    wo = cases.direction(0.6)
    wi_mi, pdf_mi, w_mi = _mi_sample(plugin, wo, 0.9)
    ours = composite.sample(materials, 0, wo, [[0.9, 0.3, 0.7]])
    assert ours["ok"][0] and ours["delta"][0]
    np.testing.assert_allclose(ours["wi"][0], wi_mi, atol=1e-7)
    np.testing.assert_allclose(ours["pdf"][0], pdf_mi, rtol=1e-6)
    np.testing.assert_allclose(ours["weight"][0], w_mi, rtol=1e-6)


@pytest.mark.parametrize("name", ["blend-white-rough-0.3", "twosided-of-a-blend"])
def test_mitsubas_sample_weight_is_our_eval_over_pdf(name):
    """Blends of materials without delta lobes (with one, Mitsuba mixes the lobe's probability with the other's
    density: the difference the module docstring of kernels/composite.py names)."""
    materials, plugin = _case(name)
    rng = np.random.default_rng(4)
    checked = 0
    for c in (0.8, 0.3, -0.5):
        wo = cases.direction(c)
        for s1, s2a, s2b in rng.random((40, 3)):
            wi, pdf_mi, w_mi = _mi_sample(plugin, wo, s1, (s2a, s2b))
            if not pdf_mi > 0 or np.all(w_mi == 0):
                continue
            f, p = composite.eval_pdf(materials, 0, wo, wi[None])
            np.testing.assert_allclose(pdf_mi, p[0], rtol=5e-5, err_msg=name)
            np.testing.assert_allclose(w_mi, f[0] / p[0], rtol=5e-5, atol=1e-6, err_msg=name)
            checked += 1
    assert checked > 40


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_sampler_chi2_and_weights(name):
    materials, _ = _case(name)
    for c in (0.8, 0.25, -0.6):
        wo = cases.direction(c)
        result = cases.bsdf_chi2(materials, wo, seed=11, name=f"{name} cos {c}", door=composite, n=60_000)
        print(result.line())
        if result.dof == 0:  # one-sided materials seen from behind: no density to test, none sampled
            assert result.pdf_integral == 0 and result.fail_fraction == 1.0 or c2_all_delta(result), result.line()
        else:
            assert result.p_value > 1e-3, result.line()
        assert result.impossible == 0, result.line()
        s = composite.sample(materials, 0, wo, cases.uniforms(5, 4000))
        smooth = s["ok"] & ~s["delta"]
        f, p = composite.eval_pdf(materials, 0, wo, s["wi"][smooth])
        np.testing.assert_allclose(s["pdf"][smooth], p, rtol=1e-12)
        np.testing.assert_allclose(s["weight"][smooth], f / p[:, None], rtol=1e-10, atol=1e-14)


def c2_all_delta(result) -> bool:
    """A sampler whose every sample from behind is a delta lobe (a mask's hole): nothing for the pdf to meet."""
    return result.pdf_integral == 0


def test_material_step_chooses_a_blends_material_by_its_weight():
    materials, _ = _case("blend-white-rough-0.3")
    tables = material_tables(materials, 0)
    u = np.random.default_rng(2).random(200_000)
    second = sum(resolve_nested(tables, 0, True, 0.0, 0.0, x, 0)[0] == 2 for x in u)
    z = (second - 0.3 * len(u)) / np.sqrt(len(u) * 0.3 * 0.7)
    assert abs(z) < 5, z
    sides, _ = _case("twosided-white-rough")
    tables = material_tables(sides, 0)
    assert resolve_nested(tables, 0, True, 0.0, 0.0, 0.5, 0) == (1, True)
    assert resolve_nested(tables, 0, False, 0.0, 0.0, 0.5, 0) == (2, True)


CI, QW = np.polynomial.legendre.leggauss(64)


def _albedo(evaluate, wo, n_phi=64):
    """Integral of f |cos| over the sphere by Gauss-Legendre in cos theta and the midpoint rule in phi."""
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    nodes = np.concatenate([(CI + 1) / 2, -(CI + 1) / 2])  # each hemisphere on its own: f is not smooth at z = 0
    weights = np.concatenate([QW, QW]) / 2
    c, ph = np.meshgrid(nodes, phi, indexing="ij")
    s = np.sqrt(1 - c**2)
    wi = np.stack([s * np.cos(ph), s * np.sin(ph), c], axis=-1).reshape(-1, 3)
    f = evaluate(wo, wi)
    return (np.repeat(weights, n_phi)[:, None] * f).sum(axis=0) * (2 * np.pi / n_phi)


def furnace_rows():
    """(name, cos theta_o, ours by quadrature, ours by the sampler's mean weight and its standard error, Mitsuba's
    by quadrature) of the non-delta composites, and of the masks with their hole's 1 - opacity added."""
    rows = []
    for c in CASES:
        name = c[0]
        materials, plugin = _case(name)
        if PLASTIC in materials.kind:
            continue  # a delta coating: no quadrature sees it
        for cos in (0.9, 0.4, -0.6):
            wo = cases.direction(cos)
            ours = _albedo(lambda o, wi: composite.eval_pdf(materials, 0, o, wi)[0], wo)
            theirs = _albedo(lambda o, wi: np.array([cases.mitsuba_eval_pdf(mi, plugin, o, d)[0] for d in wi]), wo)
            if c[1] == MASK:
                ours, theirs = ours + (1 - c[2]), theirs + (1 - c[2])
            s = composite.sample(materials, 0, wo, cases.uniforms(9, 40_000))
            w = np.where(s["ok"][:, None], s["weight"], 0.0)
            rows.append((name, cos, ours, w.mean(axis=0), w.std(axis=0) / np.sqrt(len(w)), theirs))
    return rows


@pytest.mark.slow
def test_white_furnace_albedo_agrees_with_mitsuba():
    for name, cos, ours, sampled, se, theirs in furnace_rows():
        print(f"furnace {name} cos {cos:+.2f}: ours {np.round(ours, 5)} (sampled {np.round(sampled, 4)}) "
              f"Mitsuba {np.round(theirs, 5)}")
        np.testing.assert_allclose(ours, theirs, rtol=5e-5, atol=2e-6, err_msg=f"{name} {cos}")
        assert np.all(np.abs(sampled - ours) <= 5 * se + 1e-9), (name, cos, sampled, ours, se)


@pytest.mark.parametrize("kinds, rows, words", [
    ([MASK, DIFFUSE], [material_row(MASK, nested=(0, 0)), material_row(DIFFUSE)], "contain the material itself"),
    ([BLENDBSDF, MASK, DIFFUSE], [material_row(BLENDBSDF, nested=(1, 2)), material_row(MASK, nested=(2, 2)),
                                  material_row(DIFFUSE)], "is a mask"),
    ([TWOSIDED, DIELECTRIC], [material_row(TWOSIDED, nested=(1, 1)), material_row(DIELECTRIC)], "transmits"),
    ([BLENDBSDF, DIFFUSE], [material_row(BLENDBSDF, weight=1.5, nested=(1, 1)), material_row(DIFFUSE)],
     "weight in [0, 1]"),
    ([MASK, DIFFUSE], [material_row(MASK, nested=(1, 7)), material_row(DIFFUSE)], "nested material rows"),
])
def test_the_table_refuses_bad_composites(kinds, rows, words):
    with pytest.raises(SettingsError, match=words.replace("[", r"\[").replace("]", r"\]")):
        Materials(np.array(kinds), np.array(rows))
