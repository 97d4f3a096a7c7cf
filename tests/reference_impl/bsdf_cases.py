"""Fixtures of the BSDF tests: materials by name, and a chi^2 test of a BSDF sampler against its own pdf.

The chi^2 test (:func:`bsdf_chi2`) bins the sampled directions wi in two charts of the sphere, each a
``(g, phi)`` grid about an axis: chart 0 holds the samples on wo's side of the surface (reflection), binned about
the mirror direction of wo (about the normal for the diffuse BSDF); chart 1 those on the other side
(transmission), about the smooth refraction direction (about -wo when there is none). In a chart ``cos`` of the
angle to the axis is ``c = sign(g) (1 - (1 - |g|)^4)``, so bins are narrow near the axis, where a narrow lobe
(alpha = 0.05) lies, and ``d omega = dc dphi = 4 (1 - |g|)^3 dg dphi``. A third cell counts the samples that failed
(``ok`` False); it expects ``n (1 - integral of the pdf)``, the mass that the pdf does not put on any direction (a
microfacet sample below the horizon); the samples off a delta lobe (plastic's coating) join it, since the pdf of
the other lobes leaves exactly the delta lobe's probability off the sphere. The expected counts integrate the pdf
over every bin (midpoint rule, which is robust at the horizon, where the pdf jumps to 0); Pearson's statistic over the cells after pooling those expecting
fewer than 5 (:func:`harness.judges.chi2.pooled_statistic`) gives the p-value. Samples at which the pdf is 0 or
that are not unit vectors are counted as ``impossible``, a hard failure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from harness.judges.chi2 import bin_integrals, pooled_statistic
from reference_impl.kernels import bsdf
from reference_impl.materials import (BECKMANN, COMPOSITES, DIFFUSE, GGX, ROUGHCONDUCTOR,
                                      P_IOR, ROUGHDIELECTRIC, Materials, material_row)

CU = dict(eta=(0.2004, 0.9240, 1.1022), k=(3.9129, 2.4528, 2.1421))  # Mitsuba 3's "Cu"
RES = (48, 24)  # bins of (g, phi) per chart
ORDER = 12  # midpoint nodes per bin and axis (the horizon cuts lobes at grazing incidence)
N_SAMPLES = 100_000


def one(kind: int, **kw) -> Materials:
    """A table of one material."""
    return Materials(np.array([kind]), material_row(kind, **kw)[None])


def direction(cos_theta: float, phi: float = 0.3) -> np.ndarray:
    """The unit direction at polar cosine ``cos_theta`` and azimuth ``phi`` (local frame)."""
    s = np.sqrt(max(0.0, 1.0 - cos_theta * cos_theta))
    return np.array([s * np.cos(phi), s * np.sin(phi), cos_theta])


def mitsuba_interaction(mi, wo):
    """A Mitsuba surface interaction at the origin of the local frame (normal and shading frame +z) seen from
    ``wo`` (Mitsuba's ``si.wi``), for calling a BSDF object of Mitsuba (``mi``: the module, its variant set)."""
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*wo)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.n = mi.Normal3f(0, 0, 1)
    return si


def mitsuba_eval_pdf(mi, plugin, wo, wi):
    """Mitsuba's BSDF ``plugin``: its eval (f |cos theta_i|, per channel) and pdf of (wo, wi), local directions."""
    si, ctx = mitsuba_interaction(mi, wo), mi.BSDFContext()
    return np.array(plugin.eval(ctx, si, mi.Vector3f(*wi))), float(plugin.pdf(ctx, si, mi.Vector3f(*wi)))


def uniforms(seed: int, n: int) -> np.ndarray:
    return np.random.default_rng(seed).random((n, 3))


def _frame(axis):
    axis = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(axis, helper)
    t1 /= np.linalg.norm(t1)
    return axis, t1, np.cross(axis, t1)


def chart_axes(materials: Materials, wo: np.ndarray):
    """The axes of chart 0 (reflection side) and chart 1 (transmission side) for ``wo``."""
    kind = int(materials.kind[0])
    side = 1.0 if wo[2] > 0 else -1.0
    if kind == DIFFUSE:
        return np.array([0.0, 0.0, side]), np.array([0.0, 0.0, -side])
    refl = np.array([-wo[0], -wo[1], wo[2]])
    if kind in COMPOSITES:  # their transmission, a mask's hole, is straight through
        return refl, -wo
    eta = materials.params[0, P_IOR]
    eta_ti = 1.0 / eta if wo[2] > 0 else eta
    c2 = 1.0 - (1.0 - wo[2] ** 2) * eta_ti ** 2
    if c2 > 0:
        trans = np.array([-eta_ti * wo[0], -eta_ti * wo[1], -side * np.sqrt(c2)])
    else:
        trans = -wo
    return refl, trans


def _to_chart(d, frame):
    axis, t1, t2 = frame
    c = np.clip(d @ axis, -1.0, 1.0)
    g = np.sign(c) * (1.0 - (1.0 - np.abs(c)) ** 0.25)
    phi = np.mod(np.arctan2(d @ t2, d @ t1), 2 * np.pi)
    return g, phi


def _from_chart(g, phi, frame):
    """Directions (..., 3) at chart coordinates ``g``, ``phi`` (arrays that broadcast: flat, or an open grid)."""
    axis, t1, t2 = frame
    c = np.sign(g) * (1.0 - (1.0 - np.abs(g)) ** 4)
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    sc, ss = s * np.cos(phi), s * np.sin(phi)
    d = np.empty((3,) + np.broadcast_shapes(np.shape(c), sc.shape))
    for k in range(3):  # c axis + s cos(phi) t1 + s sin(phi) t2, one component at a time (no (..., 3) temporaries)
        np.multiply(c, axis[k], out=d[k])
        d[k] += sc * t1[k]
        d[k] += ss * t2[k]
    return np.moveaxis(d, 0, -1)


@dataclass(frozen=True)
class BsdfChi2:
    """The outcome of :func:`bsdf_chi2`."""

    name: str
    p_value: float
    statistic: float
    dof: int
    pdf_integral: float  # the pdf integrated over the sphere (both charts)
    fail_fraction: float  # fraction of the samples with ok False or off a delta lobe
    impossible: int  # samples at which the pdf is 0 or wi is not a unit vector

    def line(self) -> str:
        return (f"chi2 {self.name}: p = {self.p_value:.4g} (X2 = {self.statistic:.1f}, dof {self.dof}, "
                f"pdf integral {self.pdf_integral:.5f}, failed {self.fail_fraction:.4f}, impossible {self.impossible})")


def bsdf_chi2(materials: Materials, wo: np.ndarray, seed: int, *, name: str = "", mutant: int = 0,
              pdf_mutant: int | None = None, n: int = N_SAMPLES, hemisphere: str = "cosine", door=None) -> BsdfChi2:
    """Chi^2 of material 0's sampler for ``wo`` against its pdf (``pdf_mutant``: the mutant bits the pdf is
    evaluated with, default ``mutant``; ``hemisphere``: the diffuse kind's sampling, both sides alike; ``door``: the
    module whose ``sample`` and ``pdf`` are tested, default :mod:`reference_impl.kernels.bsdf`, e.g.
    :mod:`reference_impl.kernels.composite`, whose functions take no ``hemisphere``)."""
    pdf_mutant = mutant if pdf_mutant is None else pdf_mutant
    if door is not None:
        class bsdf:  # noqa: N801 - the door under test, spelt as the default's module
            sample = staticmethod(lambda mat, m, wo_, u, mutant=0, hemisphere="": door.sample(mat, m, wo_, u, mutant))
            pdf = staticmethod(lambda mat, m, wo_, wi, mutant=0, hemisphere="": door.pdf(mat, m, wo_, wi, mutant))
    else:
        from reference_impl.kernels import bsdf
    s = bsdf.sample(materials, 0, wo, uniforms(seed, n), mutant=mutant, hemisphere=hemisphere)
    ok = s["ok"] & ~s["delta"]  # a delta lobe's samples: the cell of what the pdf leaves off the sphere
    wi = s["wi"][ok]
    same = wi[:, 2] * wo[2] > 0
    frames = [_frame(a) for a in chart_axes(materials, wo)]
    domain = ((-1.0, 1.0), (0.0, 2.0 * np.pi))
    observed, expected = [], []
    integral = 0.0
    for chart, frame in enumerate(frames):
        want_same = chart == 0

        def pdf(g, phi, frame=frame, want_same=want_same):  # g (m, 1), phi (1, k): an open grid
            d = _from_chart(g, phi, frame)
            keep = (d[..., 2] * wo[2] > 0) == want_same  # the pdf counts on this chart's side only
            p = np.zeros(keep.shape)
            p[keep] = bsdf.pdf(materials, 0, wo, d[keep], mutant=pdf_mutant, hemisphere=hemisphere)
            return p

        probs = bin_integrals(pdf, domain, RES, jacobian=lambda g, phi: 4.0 * (1.0 - np.abs(g)) ** 3,
                              quadrature="midpoint", order=ORDER, open_grid=True)
        integral += probs.sum()
        g, phi = _to_chart(wi[same == want_same], frame)
        counts, _, _ = np.histogram2d(g, phi, bins=RES, range=domain)
        observed.append(counts.ravel())
        expected.append(n * probs.ravel())
    fails = n - int(ok.sum())
    observed.append(np.array([fails], float))
    expected.append(np.array([max(0.0, n * (1.0 - integral))]))
    statistic, dof, _, _ = pooled_statistic(np.concatenate(observed), np.concatenate(expected))
    p_value = float(stats.chi2.sf(statistic, dof)) if dof >= 1 else float("nan")
    pdf_at = bsdf.pdf(materials, 0, wo, wi, mutant=pdf_mutant, hemisphere=hemisphere)
    impossible = int(np.count_nonzero(~(pdf_at > 0)) + np.count_nonzero(np.abs(np.linalg.norm(wi, axis=1) - 1) > 1e-9))
    return BsdfChi2(name, p_value, statistic, dof, float(integral), fails / n, impossible)


# ------------------------------------------------------------------------------------------- the standard set

ALPHAS = (0.05, 0.3, 1.0)
DISTRIBUTIONS = {"beckmann": BECKMANN, "ggx": GGX}


def standard_cases():
    """(name, materials, wo) of every chi^2 case of tests/reference_impl/test_bsdf_chi2.py."""
    cases = [("diffuse cos 0.7", one(DIFFUSE, reflectance=(0.5, 0.6, 0.7)), direction(0.7)),
             ("diffuse grazing cos 0.05", one(DIFFUSE, reflectance=0.8), direction(0.05)),
             ("diffuse two-sided from behind", one(DIFFUSE, reflectance=0.8, two_sided=True), direction(-0.5))]
    for dname, dist in DISTRIBUTIONS.items():
        for visible in (True, False):
            for alpha in ALPHAS:
                tag = f"{dname} {'visible' if visible else 'all normals'} alpha {alpha}"
                for c in (0.9, 0.05):
                    cases.append((f"roughconductor {tag} cos {c}",
                                  one(ROUGHCONDUCTOR, alpha=alpha, distribution=dist, sample_visible=visible, **CU),
                                  direction(c)))
                for c, where in ((0.8, "outside"), (0.05, "outside grazing"), (-0.8, "inside"),
                                 (-0.5, "inside")):
                    cases.append((f"roughdielectric {tag} {where} cos {c}",
                                  one(ROUGHDIELECTRIC, alpha=alpha, distribution=dist, sample_visible=visible,
                                      int_ior=1.5, ext_ior=1.0), direction(c)))
    cases.append(("roughconductor two-sided from behind",
                  one(ROUGHCONDUCTOR, alpha=0.3, two_sided=True, **CU), direction(-0.6)))
    return cases


if __name__ == "__main__":
    for i, (name, mats, wo) in enumerate(standard_cases()):
        print(bsdf_chi2(mats, wo, seed=1000 + i, name=name).line())
