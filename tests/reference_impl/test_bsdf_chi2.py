"""Chi-square tests of every BSDF sampler of reference_impl/kernels/bsdf.py against its own pdf.

The cases (tests/reference_impl/bsdf_cases.py, ``standard_cases``): the diffuse BSDF (front, grazing, two-sided
from behind), and the rough conductor and rough dielectric for Beckmann and GGX, visible-normal and all-normal
sampling, alpha 0.05, 0.3 and 1, at cos theta_o 0.9 and 0.05 (grazing) on the conductor and 0.8, 0.05 (outside)
and -0.8, -0.5 (inside: partly beyond the critical angle) on the dielectric (int_ior 1.5): 76 tests, 1e5 samples
each from a fixed seed. The samples that fail (``ok`` False: below the horizon) are a cell of their own, expecting
the mass the pdf leaves off the sphere (see ``bsdf_cases.bsdf_chi2``).

Significance: Sidak's per-test alpha for the 76 cases (harness.judges.chi2.sidak_alpha), so the file has a 1 %
false-alarm chance; a test also fails if any sample lands where the pdf is 0. The planted faults
"vndf-alpha-squared" (samples drawn with alpha^2) and "microfacet-pdf-no-jacobian" (the pdf without 1 / (4 |wi.h|))
must be rejected with p < 1e-9. Each test prints its line (``pytest -s``); ``python tests/reference_impl/bsdf_cases.py``
prints them all. The full grid takes ~30 s and is marked slow; a subset of 8 runs in the inner loop.
"""

from __future__ import annotations

import numpy as np
import pytest

try:
    import bsdf_cases as cases
except ImportError:  # tests/ imported as a package
    from tests.reference_impl import bsdf_cases as cases

from harness.judges.chi2 import sidak_alpha
from reference_impl.kernels.config import MUTANT_BITS
from reference_impl.materials import BECKMANN, GGX, ROUGHCONDUCTOR, ROUGHDIELECTRIC

CASES = cases.standard_cases()
ALPHA = sidak_alpha(len(CASES))
REJECT_P = 1e-9
FAST = {"diffuse cos 0.7", "diffuse grazing cos 0.05", "roughconductor beckmann visible alpha 0.3 cos 0.9",
        "roughconductor ggx visible alpha 0.05 cos 0.05", "roughdielectric beckmann visible alpha 0.3 outside cos 0.8",
        "roughdielectric ggx visible alpha 1.0 outside grazing cos 0.05",
        "roughdielectric ggx all normals alpha 0.3 inside cos -0.5", "roughconductor two-sided from behind"}
PARAMS = [pytest.param(i, id=name, marks=() if name in FAST else pytest.mark.slow)
          for i, (name, _, _) in enumerate(CASES)]


def test_case_count():
    assert len(CASES) == 76
    assert FAST <= {name for name, _, _ in CASES}


@pytest.mark.parametrize("index", PARAMS)
def test_sampler_matches_its_pdf(index):
    name, materials, wo = CASES[index]
    result = cases.bsdf_chi2(materials, wo, seed=1000 + index, name=name)
    print(result.line())
    assert result.impossible == 0, result.line()
    assert result.pdf_integral <= 1.0 + 1e-3, result.line()
    assert result.p_value >= ALPHA, result.line()


@pytest.mark.parametrize("index", [0, 1, 2], ids=lambda i: CASES[i][0])
def test_the_uniform_diffuse_sampler_matches_its_pdf(index):
    """``hemisphere = uniform``: the diffuse kind's uniform sampler (p = 1 / (2 pi)) against its own pdf, on the three
    diffuse cases, at the same per-test alpha; and the cosine pdf must reject its samples."""
    name, materials, wo = CASES[index]
    result = cases.bsdf_chi2(materials, wo, seed=2000 + index, name=name + " uniform", hemisphere="uniform")
    print(result.line())
    assert result.impossible == 0, result.line()
    assert abs(result.pdf_integral - 1.0) <= 1e-3, result.line()
    assert result.p_value >= ALPHA, result.line()
    s = cases.bsdf.sample(materials, 0, wo, cases.uniforms(2100 + index, 20000), hemisphere="uniform")
    cosine_pdf = cases.bsdf.pdf(materials, 0, wo, s["wi"][s["ok"]])
    uniform_pdf = cases.bsdf.pdf(materials, 0, wo, s["wi"][s["ok"]], hemisphere="uniform")
    assert np.allclose(uniform_pdf, 0.5 / np.pi) and not np.allclose(cosine_pdf, uniform_pdf)


@pytest.mark.parametrize("kind", [ROUGHCONDUCTOR, ROUGHDIELECTRIC], ids=["roughconductor", "roughdielectric"])
@pytest.mark.parametrize("dist", [BECKMANN, GGX], ids=["beckmann", "ggx"])
def test_vndf_alpha_squared_is_rejected(kind, dist):
    materials = cases.one(kind, alpha=0.3, distribution=dist, int_ior=1.5, ext_ior=1.0, **cases.CU)
    result = cases.bsdf_chi2(materials, cases.direction(0.7), seed=7, name="vndf-alpha-squared",
                             mutant=MUTANT_BITS["vndf-alpha-squared"])
    print(result.line())
    assert result.p_value < REJECT_P


@pytest.mark.parametrize("kind", [ROUGHCONDUCTOR, ROUGHDIELECTRIC], ids=["roughconductor", "roughdielectric"])
@pytest.mark.parametrize("visible", [True, False], ids=["visible", "all-normals"])
def test_microfacet_pdf_without_jacobian_is_rejected(kind, visible):
    materials = cases.one(kind, alpha=0.3, sample_visible=visible, int_ior=1.5, ext_ior=1.0, **cases.CU)
    result = cases.bsdf_chi2(materials, cases.direction(0.7), seed=8, name="microfacet-pdf-no-jacobian",
                             mutant=MUTANT_BITS["microfacet-pdf-no-jacobian"])
    print(result.line())
    assert result.p_value < REJECT_P or abs(result.pdf_integral - 1.0) > 0.1
