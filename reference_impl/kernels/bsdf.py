r"""BSDF kernels: evaluation, pdf and sampling of the materials of :mod:`reference_impl.materials`.

The physics is Mitsuba 3.9.1's (src/bsdfs/diffuse.cpp, conductor.cpp, roughconductor.cpp, dielectric.cpp,
roughdielectric.cpp, thindielectric.cpp, plastic.cpp, roughplastic.cpp, principled.cpp with principledhelpers.h,
twosided.cpp; include/mitsuba/render/microfacet.h, fresnel.h), written afresh for scalars in numba. Everything is in the LOCAL frame of the surface: z is the
triangle's front geometric normal (never flipped by the caller); ``wo`` points toward the previous vertex (Mitsuba's ``si.wi``), ``wi`` is the other direction
(Mitsuba's ``bs.wo``). Values follow Mitsuba's ``eval`` convention: ``f(wo, wi) |cos theta_i|``, cosine included, in
radiance mode (transmission carries the ``1 / eta^2`` solid-angle compression of radiance).
The parameters are the material step's (:func:`.material.material_at`): each entry point takes the kind and the
parameter row (``row``, columns ``P_*``) of the surface's material at the hit, and reads nothing else of the
material table.

Models (R = specular_reflectance or the diffuse albedo, T = specular_transmittance)

    diffuse          f |cos| = R / pi cos(theta_i) with wo, wi both above the surface; cosine-weighted sampling (or,
                     with ``hemisphere = "uniform"``, uniform: p = 1 / (2 pi), the slides' Fig. 5.14)
    conductor        delta reflection (-wo_x, -wo_y, wo_z), weight R F_c(cos theta_o)
    roughconductor   f |cos| = R F_c(wo.h) D(h) G1(wo, h) G1(wi, h) / (4 cos theta_o), h = (wo + wi) / |wo + wi|
                     (Walter et al. 2007, eq. 20)
    dielectric       delta reflection with probability F (weight R) or refraction with 1 - F (weight T / eta_it^2)
    roughdielectric  reflection as roughconductor with F the dielectric Fresnel term, and transmission
                     f |cos| = T (1 - F) D G |wo.h| |wi.h| / (|cos theta_o| (wo.h + eta wi.h)^2), the
                     generalised half vector h = -(wo + eta wi) (Walter et al. 2007, eqs. 16 and 21, with the
                     radiance scaling 1 / eta^2 of Mitsuba), lobe chosen with probability F(wo.h)
    thindielectric   a sheet of two parallel interfaces, both sides alike: with R' = 2 F / (1 + F), F = F(|cos theta_o|)
                     (the sum R + T^2 R + T^2 R^3 + ... of the reflections inside the sheet, T = 1 - F),
                     delta reflection (-wo_x, -wo_y, wo_z) with probability R' (weight R), or delta transmission
                     straight through, wi = -wo, with 1 - R' (weight T; no eta^2: the ray leaves into the medium it
                     came from, Mitsuba's bs.eta = 1)
    plastic          a smooth dielectric coating (Fresnel F) over a Lambertian base, one-sided (or inside Mitsuba's
                     twosided): delta reflection (-wo_x, -wo_y, wo_z) with weight R F(cos theta_o) / P_s, and the
                     diffuse part f |cos| = (1 - F(cos theta_o)) (1 - F(cos theta_i)) / eta^2 diff / pi cos theta_i,
                     diff = rho / (1 - F_dr) (nonlinear = false) or rho / (1 - rho F_dr) (nonlinear = true),
                     F_dr = F_dr(1 / eta) the base's internal diffuse reflectance (rho = diffuse_reflectance);
                     lobe chosen with P_s = F w / (F w + (1 - F)(1 - w)), F = F(cos theta_o), w the specular
                     sampling weight s_mean / (s_mean + d_mean) (the channel means of R and rho); the diffuse lobe
                     cosine-weighted, pdf (1 - P_s) cos theta_i / pi
    roughplastic     the plastic's layers with a rough coating, one-sided (or inside twosided): the glossy lobe
                     f |cos| = R F(wo.h) D(h) G1(wo, h) G1(wi, h) / (4 cos theta_o) (the rough conductor's with the
                     dielectric Fresnel term) plus the diffuse part diff / (pi eta^2) T(cos theta_o) T(cos theta_i)
                     cos theta_i, diff = rho / (1 - R_i) or, nonlinear, rho / (1 - rho R_i); T the rough coating's
                     external transmittance, tabulated at cos theta = max(1e-6, k / 63), k = 0 .. 63, and read by
                     linear interpolation (Mitsuba's ``lerp_gather``), R_i its internal reflectance
                     (:func:`roughplastic_lut`: Mitsuba's ``eval_transmittance`` and ``eval_reflectance`` of
                     microfacet.h, tensor Gauss-Legendre quadratures of 32^2 nodes, 128^2 where the relative index
                     is below 1, over the visible normals' sample space; R_i = 2 mean_k(R(mu_k; 1 / eta) mu_k)).
                     Lobe chosen with P_s = (1 - T) w / ((1 - T) w + T (1 - w)), T = T(cos theta_o), w the specular
                     sampling weight; the glossy lobe sampled as the rough conductor's, the diffuse one
                     cosine-weighted; pdf P_s p_h(h) / (4 wi.h) + (1 - P_s) cos theta_i / pi, weight eval / pdf.
                     The table (LUT_SIZE numbers) is not in the material's row but follows it in the hit's row
                     buffer (columns P_LUT .., reference_impl/materials.py), where the material step copies it
    principled       Burley's BSDF as Mitsuba's principled writes it (below)

    F_c            unpolarised Fresnel reflectance of a conductor with complex index eta + i k (fresnel.h's
                   ``fresnel_conductor``, after K. D. Moeller, "Optics", 1988); 1 for ``material = "none"``
    F              exact unpolarised dielectric Fresnel reflectance (fresnel.h's ``fresnel``)
    F_dr(eta)      diffuse Fresnel reflectance, fresnel.h's ``fresnel_diffuse_reflectance``: for eta < 1 Egan &
                   Hilgeman's fit -1.4399 eta^2 + 0.7099 eta + 0.6681 + 0.0636 / eta (1973), else d'Eon & Irving's
                   quintic in 1 / eta (2011)
    D              Beckmann exp(-tan^2 theta_h / alpha^2) / (pi alpha^2 cos^4 theta_h) or GGX
                   1 / (pi alpha^2 cos^4 theta_h (1 + tan^2 theta_h / alpha^2)^2)
    G1             Smith's masking: GGX 2 / (1 + sqrt(1 + alpha^2 tan^2 theta)); Beckmann Mitsuba's rational fit
                   (3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2) for a = 1 / (alpha tan theta) < 1.6, else 1
                   (Walter et al. 2007, eq. 27); 0 where v.h and v_z differ in sign; G = G1(wo) G1(wi)

The principled BSDF (B = base_color, m = metallic, s = spec_trans, lum(B) = 0.212671 B_r + 0.715160 B_g +
0.072169 B_b, C = B / lum(B) (1 where lum = 0), SW(c) = (1 - c)^5 on [0, 1], wo on the front where cos theta_o > 0)

    weights          brdf = (1 - m)(1 - s), bsdf = (1 - m) s
    main lobes       anisotropic GGX, alpha_u = max(0.001, r^2 / a), alpha_v = max(0.001, r^2 a), r = roughness,
                     a = sqrt(1 - 0.9 anisotropic); h the half vector of the pair (reflection: wo + wi; transmission:
                     wo + eta_path wi, eta_path = eta from the front, 1 / eta from behind), flipped to h_z > 0; each
                     lobe only where wo.h and wi.h lie on the sides the lobe says (principledhelpers.h's
                     ``mac_mic_compatibility``); F = the exact dielectric Fresnel F(wo.h, eta)
    reflection       F_p D G / (4 |cos theta_o|); from the front F_p = (1 - m)(1 - spec_tint) F
                     + m Schlick(B) + (1 - m) spec_tint Schlick(C R0(eta)), R0 = ((eta - 1) / (eta + 1))^2, Schlick(R)
                     = R + (1 - R) SW(|wo.h|) where the light enters the denser side, else SW(cos theta_t) of the
                     refracted direction (1 under total internal reflection); from behind F_p = bsdf F
    transmission     sqrt(B) bsdf (1 - F) D G |wo.h| |wi.h| / (|cos theta_o| (wo.h + eta_path wi.h)^2) (radiance:
                     Walter's eta^2 cancels the 1 / eta^2 of radiance)
    clearcoat        (front) 0.25 cc Schlick_0.04(wo.h) D_GTR1(h) G_cc |cos theta_i|, D_GTR1 = (a^2 - 1) /
                     (pi ln(a^2) (1 + (a^2 - 1) cos^2 theta_h)), a = 0.1 (1 - gloss) + 0.001 gloss, G_cc the Smith GGX
                     masking of alpha 0.25 of wo and wi (exactly as principled.cpp writes it: no 1 / (4 cos theta_o))
    diffuse          (front) brdf B / pi |cos theta_i| ((1 - F_o / 2)(1 - F_i / 2) + R_R (F_o + F_i + F_o F_i (R_R - 1)))
                     with F_o = SW(|cos theta_i|), F_i = SW(|cos theta_o|), R_R = 2 r cos^2 theta_d, cos theta_d =
                     h.wi; with flatness f the bracket lerps toward 1.25 (F_ss (1 / (|cos theta_o| + |cos theta_i|)
                     - 1 / 2) + 1 / 2), F_ss = (1 + (R_R / 2 - 1) F_o)(1 + (R_R / 2 - 1) F_i)
    sheen            (front) sheen (1 - m) SW(|cos theta_d|) ((1 - sheen_tint) + sheen_tint C) |cos theta_i|
    lobe choice      from the front p_d = brdf r_d, p_cc = cc / 4 r_cc, p_t = r_s bsdf (1 - F), p_r = r_s (1 - bsdf
                     (1 - F)) over their sum (r_* the sampling rates; p_t + p_r = r_s, so only the split between the
                     two main lobes depends on F, at the sampled normal); from behind p_t = 1 - F, p_r = F. Diffuse
                     cosine-weighted, clearcoat a GTR1 half vector (cos^2 theta_h = (1 - a^2^(1 - u)) / (1 - a^2))
                     reflected, main lobes a visible GGX normal (anisotropic) reflected or refracted
    pdf              the sum of each lobe's probability times its density: p_r D_vis / (4 |wi.h|), p_t D_vis eta_path^2
                     |wi.h| / (wo.h + eta_path wi.h)^2, p_cc D_GTR1 cos theta_h / (4 |wi.h|), p_d cos theta_i / pi

Sampling of the microfacet normal h

    visible normals (sample_visible = 1)   h ~ D(h) G1(wo, h) max(0, wo.h) / cos theta_o (Heitz & d'Eon 2014):
        stretch wo by alpha, sample the slopes of the visible normals of the unit-roughness surface -- Beckmann by
        Jakob's numerical inversion of the slope CDF in the erf domain (Mitsuba's ``sample_visible_11``), GGX by
        Heitz's closed form ("Sampling the GGX Distribution of Visible Normals", JCGT 7(4), 2018) -- rotate,
        unstretch
    all normals (sample_visible = 0)       h ~ D(h) cos theta_h (Walter et al. 2007, eqs. 28, 35); the rough
        dielectric samples with alpha scaled by 1.2 - 0.2 sqrt(|cos theta_o|) (Walter's trick, as Mitsuba)

    direction pdfs: reflection p(h) / (4 |wi.h|), transmission p(h) eta^2 |wi.h| / (wo.h + eta wi.h)^2
    (Walter et al. 2007, eqs. 14 and 17), times the lobe's probability F or 1 - F on the rough dielectric.

Where this differs from Mitsuba on purpose

* The Beckmann visible-normal pdf uses the exact Smith term G1 = 2 / (1 + erf(a) + exp(-a^2) / (a sqrt(pi))), the
  density the sampler draws from, not the rational fit (Mitsuba's pdf uses the fit, off by up to 0.35 %); ``eval``
  keeps the fit, so values agree with Mitsuba, and every weight is eval / pdf, so the estimator is unbiased for
  Mitsuba's ``eval``.
* The rough dielectric with sample_visible = 0 weighs its samples by eval / pdf (the ratio D / D_scaled of Walter's
  trick included); Mitsuba's weight omits that ratio.
* The lobe of a dielectric and of a thin dielectric is reflection when u_lobe < F (Mitsuba: <=), so a lobe of
  probability 0 is never chosen.
* Plastic's lobe choice where F w + (1 - F)(1 - w) = 0 (eta = 1 and a black base) is the diffuse lobe (Mitsuba:
  0 / 0); the diffuse lobe is cosine-weighted whatever ``hemisphere`` says (that setting is the diffuse kind's).
* The Beckmann slope inversion runs Newton's method to convergence in double precision (Mitsuba: 3 steps in
  single precision).
* The rough plastic's table is integrated in double precision with the converged Beckmann inversion (Mitsuba: float32
  throughout): equal to 2e-5 for int_ior > ext_ior; an inverted coating (int_ior < ext_ior, 128^2 nodes over an
  integrand with a total-internal-reflection edge) to about 1e-3. Its Beckmann visible-normal pdf takes the exact G1
  as the rough conductor's. No planted fault acts on it ("vndf-alpha-squared" acts through the shared sampler).
* The principled BSDF from behind where nothing transmits (spec_trans or 1 - metallic 0): its pdf is 0, as its
  sampler draws nothing there (Mitsuba's ``pdf`` gives F / F = the main lobe's density there; both evals are 0).
* Principled's sheen where spec_trans = 1: kept, as Mitsuba's vectorised variants (llvm_ad_rgb, cuda_ad_rgb, the
  ground truth's) keep it; its scalar variant skips it (the sheen sits inside the diffuse lobe's branch, which a
  scalar skips when brdf = 0).
* Principled's lobe choice draws the main lobe's normal only when a main lobe is chosen (Mitsuba draws it first, for
  every sample): the same probabilities, since only the split between reflection and transmission depends on it.

The door's ``later`` argument: None compiles the rough plastic's and principled's branches out (the path loop of a
scene without them passes None: their code made every glossy scene's loop slower to compile, not to run); True, the
default, keeps them.

Planted faults (bits of :data:`reference_impl.kernels.config.MUTANT_BITS`), each place marked by a comment:
"microfacet-pdf-no-jacobian", "conductor-fresnel-one", "refraction-no-eta2", "vndf-alpha-squared",
"thin-glass-refracts", "plastic-no-internal-reflection", "principled-clearcoat-pdf-jacobian".
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import (JIT, JIT_BORROW, JIT_NONRT, M_CLEARCOAT_PDF_NO_JACOBIAN,
                                           M_CONDUCTOR_FRESNEL_ONE, M_MICROFACET_PDF_NO_JACOBIAN,
                                           M_PLASTIC_NO_INTERNAL_REFLECTION, M_REFRACTION_NO_ETA2,
                                           M_THIN_GLASS_REFRACTS, M_VNDF_ALPHA_SQUARED)
from reference_impl.kernels.material import material_params
from reference_impl.kernels.records import material_tables
from reference_impl.kernels.warps import cosine_hemisphere, uniform_hemisphere
from reference_impl.materials import (CONDUCTOR, DIELECTRIC, DIFFUSE, GGX, LUT_RES, LUT_SIZE, NUM_PARAMS, P_ALPHA,
                                      P_ANISOTROPIC, P_CLEARCOAT, P_CLEARCOAT_GLOSS, P_CLEARCOAT_RATE, P_DIFFUSE,
                                      P_DIFFUSE_RATE, P_DISTRIBUTION, P_ETA, P_FLATNESS, P_INTERNAL_REFLECTANCE, P_IOR,
                                      P_K, P_LUT, P_METALLIC, P_MIRROR, P_NONLINEAR, P_REFLECTANCE, P_ROUGHNESS,
                                      P_SAMPLE_VISIBLE, P_SHEEN, P_SHEEN_TINT, P_SPEC_TINT, P_SPEC_TRANS,
                                      P_SPECULAR_RATE, P_SPECULAR_WEIGHT, P_TRANSMITTANCE, P_TWO_SIDED, PLASTIC,
                                      PRINCIPLED, ROUGHCONDUCTOR, ROUGHDIELECTRIC, ROUGHPLASTIC, ROW_SIZE,
                                      THINDIELECTRIC)
from reference_impl.materials import fresnel_diffuse_reflectance as _fresnel_diffuse_reflectance

INV_PI = 1.0 / np.pi
INV_2PI = 0.5 / np.pi
INV_SQRT_PI = 1.0 / math.sqrt(np.pi)
MIN_ALPHA = 1e-4  # Mitsuba's MicrofacetDistribution::configure clamps alpha to at least this
LUM_R, LUM_G, LUM_B = 0.212671, 0.715160, 0.072169  # Mitsuba's luminance of a linear sRGB colour


# ----------------------------------------------------------------------------------------------------- Fresnel


@njit(**JIT)
def fresnel_dielectric(cos_theta_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric interface (Mitsuba's ``fresnel``).

    ``eta`` = int_ior / ext_ior; ``cos_theta_i`` >= 0 on the outside. Returns (F, cos_theta_t, eta_it, eta_ti):
    the reflectance, the signed cosine of the refracted direction (opposite sign to cos_theta_i; 0 under total
    internal reflection), the relative index in the direction of travel and its reciprocal.
    F = (r_s^2 + r_p^2) / 2, r_s = (c_i - eta_it c_t) / (c_i + eta_it c_t), r_p = (eta_it c_i - c_t) /
    (eta_it c_i + c_t); 1 at c_i = 0 and under total internal reflection, 0 for eta = 1.
    """
    outside = cos_theta_i >= 0.0
    eta_it = eta if outside else 1.0 / eta
    eta_ti = 1.0 / eta if outside else eta
    cos_t_sqr = 1.0 - (1.0 - cos_theta_i * cos_theta_i) * (eta_ti * eta_ti)
    ci = abs(cos_theta_i)
    ct = math.sqrt(cos_t_sqr) if cos_t_sqr > 0.0 else 0.0
    if eta == 1.0:
        r = 0.0
    elif ci == 0.0 or cos_t_sqr <= 0.0:
        r = 1.0
    else:
        a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
        a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
        r = 0.5 * (a_s * a_s + a_p * a_p)
    cos_t = -ct if cos_theta_i >= 0.0 else ct
    return r, cos_t, eta_it, eta_ti


@njit(**JIT)
def fresnel_conductor(cos_theta_i, eta, k):
    """Unpolarised Fresnel reflectance of a conductor of complex index eta + i k, 0 <= cos_theta_i <= 1
    (Mitsuba's ``fresnel_conductor``, from K. D. Moeller, "Optics", 1988):
    a^2 + b^2 = sqrt((eta^2 - k^2 - sin^2)^2 + 4 eta^2 k^2), a = sqrt((a^2 + b^2 + eta^2 - k^2 - sin^2) / 2),
    R_s = (a^2 + b^2 + cos^2 - 2 a cos) / (a^2 + b^2 + cos^2 + 2 a cos),
    R_p = R_s ((a^2 + b^2) cos^2 + sin^4 - 2 a cos sin^2) / ((a^2 + b^2) cos^2 + sin^4 + 2 a cos sin^2),
    F = (R_s + R_p) / 2."""
    c2 = cos_theta_i * cos_theta_i
    s2 = 1.0 - c2
    s4 = s2 * s2
    t1 = eta * eta - k * k - s2
    ab = math.sqrt(max(0.0, t1 * t1 + 4.0 * k * k * eta * eta))
    a = math.sqrt(max(0.0, 0.5 * (ab + t1)))
    term1 = ab + c2
    term2 = 2.0 * cos_theta_i * a
    r_s = (term1 - term2) / (term1 + term2)
    term3 = ab * c2 + s4
    term4 = term2 * s2
    # eta = k = 0 at normal incidence leaves 0 / 0 (no physical conductor): take r_p = r_s there
    r_p = r_s * (term3 - term4) / (term3 + term4) if term3 + term4 > 0.0 else r_s
    return 0.5 * (r_s + r_p)


#: F_dr(eta), compiled (reference_impl.materials.fresnel_diffuse_reflectance: the one formula, which the table's
#: validation also reads).
fresnel_diffuse_reflectance = njit(**JIT)(_fresnel_diffuse_reflectance)


@njit(**JIT_NONRT)
def _conductor_fresnel3(row, mutant, cos_theta_i):
    """F_c per channel for the parameters ``row`` (1 for a mirror, and under "conductor-fresnel-one")."""
    if row[P_MIRROR] != 0.0 or (mutant & M_CONDUCTOR_FRESNEL_ONE):  # mutant "conductor-fresnel-one"
        return 1.0, 1.0, 1.0
    return (fresnel_conductor(cos_theta_i, row[P_ETA], row[P_K]),
            fresnel_conductor(cos_theta_i, row[P_ETA + 1], row[P_K + 1]),
            fresnel_conductor(cos_theta_i, row[P_ETA + 2], row[P_K + 2]))


# ------------------------------------------------------------------------------------------------- microfacets


@njit(**JIT)
def erfinv(y):
    """Inverse error function on (-1, 1): M. Giles' single-precision approximation ("Approximating the erfinv
    function", GPU Computing Gems, 2010) refined by two Newton steps on erf to double precision."""
    if y <= -1.0:
        return -np.inf
    if y >= 1.0:
        return np.inf
    w = -math.log((1.0 - y) * (1.0 + y))
    if w < 5.0:
        w -= 2.5
        p = 2.81022636e-08
        p = 3.43273939e-07 + p * w
        p = -3.5233877e-06 + p * w
        p = -4.39150654e-06 + p * w
        p = 0.00021858087 + p * w
        p = -0.00125372503 + p * w
        p = -0.00417768164 + p * w
        p = 0.246640727 + p * w
        p = 1.50140941 + p * w
    else:
        w = math.sqrt(w) - 3.0
        p = -0.000200214257
        p = 0.000100950558 + p * w
        p = 0.00134934322 + p * w
        p = -0.00367342844 + p * w
        p = 0.00573950773 + p * w
        p = -0.0076224613 + p * w
        p = 0.00943887047 + p * w
        p = 1.00167406 + p * w
        p = 2.83297682 + p * w
    x = p * y
    for _ in range(2):
        x -= (math.erf(x) - y) / (2.0 * INV_SQRT_PI * math.exp(-x * x))
    return x


@njit(**JIT)
def mf_d(ggx, alpha, hx, hy, hz):
    """The normal distribution D(h) (microfacet.h ``eval``; isotropic), 0 where D cos theta_h <= 1e-20."""
    a2 = alpha * alpha
    c2 = hz * hz
    if ggx:
        t = (hx * hx + hy * hy) / a2 + c2
        r = 1.0 / (np.pi * a2 * t * t)
    else:
        r = math.exp(-((hx * hx + hy * hy) / a2) / c2) / (np.pi * a2 * c2 * c2)
    return r if r * hz > 1e-20 else 0.0


@njit(**JIT)
def mf_g1(ggx, alpha, vx, vy, vz, hx, hy, hz):
    """Smith's masking G1(v, h) as Mitsuba's ``smith_g1`` (Beckmann: its rational fit)."""
    if (vx * hx + vy * hy + vz * hz) * vz <= 0.0:
        return 0.0
    xy = alpha * alpha * (vx * vx + vy * vy)
    if xy == 0.0:
        return 1.0
    t2 = xy / (vz * vz)
    if ggx:
        return 2.0 / (1.0 + math.sqrt(1.0 + t2))
    a = 1.0 / math.sqrt(t2)
    if a >= 1.6:
        return 1.0
    return (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)


@njit(**JIT)
def mf_g1_exact(ggx, alpha, vx, vy, vz, hx, hy, hz):
    """Smith's masking with Beckmann's exact Lambda: G1 = 2 / (1 + erf(a) + exp(-a^2) / (a sqrt(pi))),
    a = 1 / (alpha tan theta) (Walter et al. 2007, eq. 25); GGX as :func:`mf_g1` (already exact)."""
    if ggx:
        return mf_g1(ggx, alpha, vx, vy, vz, hx, hy, hz)
    if (vx * hx + vy * hy + vz * hz) * vz <= 0.0:
        return 0.0
    xy = alpha * alpha * (vx * vx + vy * vy)
    if xy == 0.0:
        return 1.0
    a = abs(vz) / math.sqrt(xy)
    return 2.0 / (1.0 + math.erf(a) + math.exp(-a * a) * INV_SQRT_PI / a)


@njit(**JIT)
def mf_pdf(ggx, alpha, visible, wx, wy, wz, hx, hy, hz):
    """Density of :func:`mf_sample`'s normal h per unit solid angle of h, for wz > 0: D(h) G1(w, h) |w.h| / w_z
    (visible normals, exact G1) or D(h) cos theta_h (microfacet.h ``pdf``)."""
    d = mf_d(ggx, alpha, hx, hy, hz)
    if visible:
        return d * mf_g1_exact(ggx, alpha, wx, wy, wz, hx, hy, hz) * abs(wx * hx + wy * hy + wz * hz) / wz
    return d * hz


@njit(**JIT)
def _sample_visible_11(ggx, cos_theta_i, u1, u2):
    """Slopes (x, y) of a visible normal of the unit-roughness surface seen from elevation cos_theta_i > 0
    (microfacet.h ``sample_visible_11``)."""
    if ggx:
        # Heitz 2018: a uniform point on the disk, its y squeezed onto the visible half, lifted onto the hemisphere.
        r1 = 2.0 * u1 - 1.0
        r2 = 2.0 * u2 - 1.0
        if r1 == 0.0 and r2 == 0.0:
            px, py = 0.0, 0.0
        elif abs(r1) > abs(r2):
            phi = 0.25 * np.pi * (r2 / r1)
            px, py = r1 * math.cos(phi), r1 * math.sin(phi)
        else:
            phi = 0.5 * np.pi - 0.25 * np.pi * (r1 / r2)
            px, py = r2 * math.cos(phi), r2 * math.sin(phi)
        s = 0.5 * (1.0 + cos_theta_i)
        lo = math.sqrt(max(0.0, 1.0 - px * px))
        py = lo + (py - lo) * s
        pz = math.sqrt(max(0.0, 1.0 - px * px - py * py))
        sin_theta_i = math.sqrt(max(0.0, 1.0 - cos_theta_i * cos_theta_i))
        norm = 1.0 / (sin_theta_i * py + cos_theta_i * pz)
        return (cos_theta_i * py - sin_theta_i * pz) * norm, px * norm
    # Beckmann (Jakob, "An Improved Visible Normal Sampling Routine for the Beckmann Distribution", 2014): invert
    # the CDF of the visible slopes along x, 1 + x + tan(theta_i) exp(-erfinv(x)^2) / sqrt(pi), in x = erf(slope).
    tan_theta_i = math.sqrt(max(0.0, 1.0 - cos_theta_i * cos_theta_i)) / cos_theta_i
    cot_theta_i = 1.0 / tan_theta_i
    maxval = math.erf(cot_theta_i)
    u1 = min(max(u1, 1e-6), 1.0 - 1e-6)
    u2 = min(max(u2, 1e-6), 1.0 - 1e-6)
    x = maxval - (maxval + 1.0) * math.erf(math.sqrt(-math.log(u1)))
    target = u1 * (1.0 + maxval + INV_SQRT_PI * tan_theta_i * math.exp(-cot_theta_i * cot_theta_i))
    for _ in range(20):
        slope = erfinv(x)
        value = 1.0 + x + INV_SQRT_PI * tan_theta_i * math.exp(-slope * slope) - target
        step = value / (1.0 - slope * tan_theta_i)
        x_new = min(max(x - step, -1.0 + 1e-15), maxval)
        if abs(x_new - x) <= 1e-13:
            x = x_new
            break
        x = x_new
    return erfinv(x), erfinv(2.0 * u2 - 1.0)


@njit(**JIT)
def mf_sample(ggx, alpha, visible, mutant, wx, wy, wz, u1, u2):
    """A microfacet normal h for the direction w (wz > 0) and its density :func:`mf_pdf`: (hx, hy, hz, pdf)."""
    if not visible:
        phi = 2.0 * np.pi * u2
        a2 = alpha * alpha
        if ggx:
            tan2 = a2 * u1 / (1.0 - u1)
            cos_t = 1.0 / math.sqrt(1.0 + tan2)
        else:
            cos_t = 1.0 / math.sqrt(1.0 - a2 * math.log(1.0 - u1))
        sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
        hx, hy, hz = math.cos(phi) * sin_t, math.sin(phi) * sin_t, cos_t
        return hx, hy, hz, mf_pdf(ggx, alpha, visible, wx, wy, wz, hx, hy, hz)
    a = alpha
    if mutant & M_VNDF_ALPHA_SQUARED:  # mutant "vndf-alpha-squared": stretched by alpha^2, the pdf unchanged
        a = alpha * alpha
    hx, hy, hz = visible_normal(ggx, a, a, wx, wy, wz, u1, u2)
    return hx, hy, hz, mf_pdf(ggx, alpha, visible, wx, wy, wz, hx, hy, hz)


@njit(**JIT)
def visible_normal(ggx, ax, ay, wx, wy, wz, u1, u2):
    """A visible normal h of the surface of roughnesses (ax, ay) seen from w (wz > 0): stretch w by (ax, ay), sample
    the unit-roughness slopes (:func:`_sample_visible_11`), rotate, unstretch (Heitz and d'Eon 2014; microfacet.h
    ``sample``)."""
    sx, sy, sz = ax * wx, ay * wy, wz
    inv = 1.0 / math.sqrt(sx * sx + sy * sy + sz * sz)
    sx, sy, sz = sx * inv, sy * inv, sz * inv
    sin2 = sx * sx + sy * sy
    if sin2 > 0.0:
        inv_s = 1.0 / math.sqrt(sin2)
        cos_phi = min(max(sx * inv_s, -1.0), 1.0)
        sin_phi = min(max(sy * inv_s, -1.0), 1.0)
    else:
        cos_phi, sin_phi = 1.0, 0.0
    slope_x, slope_y = _sample_visible_11(ggx, sz, u1, u2)
    tx = (cos_phi * slope_x - sin_phi * slope_y) * ax
    ty = (sin_phi * slope_x + cos_phi * slope_y) * ay
    inv = 1.0 / math.sqrt(tx * tx + ty * ty + 1.0)
    return -tx * inv, -ty * inv, inv


@njit(**JIT_NONRT)
def _alpha(row):
    return max(row[P_ALPHA], MIN_ALPHA)


# ----------------------------------------------------------------------------------------- the models, one each


@njit(**JIT_NONRT)
def _side(row, woz, wiz):
    """For the reflection-only kinds (diffuse, conductors): (ok, sign) with sign flipping both directions to the
    front when the material is two-sided and wo is behind (Mitsuba's ``twosided``); ok False when wo is behind a
    one-sided surface or on the surface."""
    if woz > 0.0:
        return True, 1.0
    if woz < 0.0 and row[P_TWO_SIDED] != 0.0:
        return True, -1.0
    return False, 1.0


@njit(**JIT_NONRT)
def _roughconductor_eval(row, mutant, wox, woy, woz, wix, wiy, wiz):
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0, 0.0, 0.0
    ggx = row[P_DISTRIBUTION] == GGX
    alpha = _alpha(row)
    hx, hy, hz = wox + wix, woy + wiy, woz + wiz
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    d = mf_d(ggx, alpha, hx, hy, hz)
    if d == 0.0:
        return 0.0, 0.0, 0.0
    g = mf_g1(ggx, alpha, wox, woy, woz, hx, hy, hz) * mf_g1(ggx, alpha, wix, wiy, wiz, hx, hy, hz)
    v = d * g / (4.0 * woz)
    f0, f1, f2 = _conductor_fresnel3(row, mutant, wox * hx + woy * hy + woz * hz)
    return (v * f0 * row[P_REFLECTANCE], v * f1 * row[P_REFLECTANCE + 1],
            v * f2 * row[P_REFLECTANCE + 2])


@njit(**JIT_NONRT)
def _roughconductor_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz):
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0
    hx, hy, hz = wox + wix, woy + wiy, woz + wiz
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    wo_h = wox * hx + woy * hy + woz * hz
    wi_h = wix * hx + wiy * hy + wiz * hz
    if wo_h <= 0.0 or wi_h <= 0.0:
        return 0.0
    p = mf_pdf(row[P_DISTRIBUTION] == GGX, _alpha(row), row[P_SAMPLE_VISIBLE] != 0.0,
               wox, woy, woz, hx, hy, hz)
    if mutant & M_MICROFACET_PDF_NO_JACOBIAN:  # mutant "microfacet-pdf-no-jacobian": no 1 / (4 |wi.h|)
        return p
    return p / (4.0 * wi_h)


@njit(**JIT_NONRT)
def _roughdielectric_half(row, wox, woy, woz, wix, wiy, wiz):
    """(ok, reflect, eta_side, hx, hy, hz): the (generalised) half vector of wo, wi, flipped to h_z > 0, and the
    relative index eta of the side wo is on (int/ext outside, ext/int inside)."""
    reflect = woz * wiz > 0.0
    eta = row[P_IOR]
    eta_side = eta if woz > 0.0 else 1.0 / eta
    s = 1.0 if reflect else eta_side
    hx, hy, hz = wox + wix * s, woy + wiy * s, woz + wiz * s
    n2 = hx * hx + hy * hy + hz * hz
    if not n2 > 0.0:
        return False, reflect, eta_side, 0.0, 0.0, 1.0
    inv = 1.0 / math.sqrt(n2)
    if hz < 0.0:
        inv = -inv
    return True, reflect, eta_side, hx * inv, hy * inv, hz * inv


@njit(**JIT_NONRT)
def _roughdielectric_eval(row, mutant, wox, woy, woz, wix, wiy, wiz):
    if woz == 0.0 or wiz == 0.0:
        return 0.0, 0.0, 0.0
    ok, reflect, eta, hx, hy, hz = _roughdielectric_half(row, wox, woy, woz, wix, wiy, wiz)
    if not ok:
        return 0.0, 0.0, 0.0
    ggx = row[P_DISTRIBUTION] == GGX
    alpha = _alpha(row)
    d = mf_d(ggx, alpha, hx, hy, hz)
    if d == 0.0:
        return 0.0, 0.0, 0.0
    g = mf_g1(ggx, alpha, wox, woy, woz, hx, hy, hz) * mf_g1(ggx, alpha, wix, wiy, wiz, hx, hy, hz)
    if g == 0.0:
        return 0.0, 0.0, 0.0
    wo_h = wox * hx + woy * hy + woz * hz
    wi_h = wix * hx + wiy * hy + wiz * hz
    f = fresnel_dielectric(wo_h, row[P_IOR])[0]
    if reflect:
        v = f * d * g / (4.0 * abs(woz))
        return v * row[P_REFLECTANCE], v * row[P_REFLECTANCE + 1], v * row[P_REFLECTANCE + 2]
    denom = wo_h + eta * wi_h
    # Radiance scaling 1 / eta^2 (eta of wo's side): it cancels Walter's eta^2, as in Mitsuba's radiance mode.
    scale = 1.0 / (eta * eta)
    if mutant & M_REFRACTION_NO_ETA2:  # mutant "refraction-no-eta2"
        scale = 1.0
    v = abs(scale * (1.0 - f) * d * g * eta * eta * wo_h * wi_h / (woz * denom * denom))
    return (v * row[P_TRANSMITTANCE], v * row[P_TRANSMITTANCE + 1],
            v * row[P_TRANSMITTANCE + 2])


@njit(**JIT_NONRT)
def _roughdielectric_sample_alpha(row, woz):
    """The alpha the rough dielectric samples h with: Walter's 1.2 - 0.2 sqrt(|cos theta_o|) scaling without
    visible-normal sampling."""
    alpha = _alpha(row)
    if row[P_SAMPLE_VISIBLE] == 0.0:
        alpha *= 1.2 - 0.2 * math.sqrt(abs(woz))
    return alpha


@njit(**JIT_NONRT)
def _roughdielectric_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz):
    if woz == 0.0 or wiz == 0.0:
        return 0.0
    ok, reflect, eta, hx, hy, hz = _roughdielectric_half(row, wox, woy, woz, wix, wiy, wiz)
    if not ok:
        return 0.0
    wo_h = wox * hx + woy * hy + woz * hz
    wi_h = wix * hx + wiy * hy + wiz * hz
    if wo_h * woz <= 0.0 or wi_h * wiz <= 0.0:
        return 0.0
    sgn = 1.0 if woz > 0.0 else -1.0
    p = mf_pdf(row[P_DISTRIBUTION] == GGX, _roughdielectric_sample_alpha(row, woz),
               row[P_SAMPLE_VISIBLE] != 0.0, sgn * wox, sgn * woy, sgn * woz, hx, hy, hz)
    f = fresnel_dielectric(wo_h, row[P_IOR])[0]
    if reflect:
        if mutant & M_MICROFACET_PDF_NO_JACOBIAN:  # mutant "microfacet-pdf-no-jacobian": no 1 / (4 |wi.h|)
            return p * f
        return p * f / (4.0 * abs(wi_h))
    denom = wo_h + eta * wi_h
    return p * (1.0 - f) * abs(eta * eta * wi_h / (denom * denom))


@njit(**JIT_BORROW)
def _thin_reflectance(row, cos_theta_o):
    """The thin dielectric's reflectance R' = 2 F / (1 + F), F = F(|cos theta_o|, eta): the light that the two
    interfaces of the sheet reflect in all, F + (1 - F)^2 F + (1 - F)^2 F^3 + ... (thindielectric.cpp)."""
    r = fresnel_dielectric(abs(cos_theta_o), row[P_IOR])[0]
    return 2.0 * r / (1.0 + r)


@njit(**JIT_BORROW)
def _thin_sample(row, mutant, wox, woy, woz, u_lobe):
    """The thin dielectric's sample (both lobes delta): reflection with probability R' (weight R), else straight
    through, wi = -wo (weight T)."""
    if woz == 0.0:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    r = _thin_reflectance(row, woz)
    if u_lobe < r:
        return (True, -wox, -woy, woz, row[P_REFLECTANCE], row[P_REFLECTANCE + 1], row[P_REFLECTANCE + 2], r,
                True)
    wix, wiy, wiz = -wox, -woy, -woz
    if mutant & M_THIN_GLASS_REFRACTS:  # mutant "thin-glass-refracts": bent by Snell's law at one interface
        _f, cos_t, _eta_it, eta_ti = fresnel_dielectric(abs(woz), row[P_IOR])
        wix, wiy, wiz = -eta_ti * wox, -eta_ti * woy, cos_t if woz > 0.0 else -cos_t
    return (True, wix, wiy, wiz, row[P_TRANSMITTANCE], row[P_TRANSMITTANCE + 1], row[P_TRANSMITTANCE + 2],
            1.0 - r, True)


@njit(**JIT_BORROW)
def _plastic_prob_specular(row, f_o):
    """Plastic's probability of its specular lobe, P_s = F w / (F w + (1 - F)(1 - w)), F = F(cos theta_o), w the
    specular sampling weight (plastic.cpp); 0 where the denominator is 0."""
    w = row[P_SPECULAR_WEIGHT]
    ps = f_o * w
    total = ps + (1.0 - f_o) * (1.0 - w)
    return ps / total if total > 0.0 else 0.0


@njit(**JIT_BORROW)
def _plastic_diffuse(row, mutant, c, fdr):
    """diff of channel ``c``: rho / (1 - F_dr) or, nonlinear, rho / (1 - rho F_dr), ``fdr`` = F_dr(1 / eta) (the
    light that the coating reflects back onto the base, over and over); rho under "plastic-no-internal-reflection"."""
    rho = row[P_DIFFUSE + c]
    if mutant & M_PLASTIC_NO_INTERNAL_REFLECTION:  # mutant "plastic-no-internal-reflection": no 1 / (1 - F_dr)
        return rho
    return rho / (1.0 - (rho * fdr if row[P_NONLINEAR] != 0.0 else fdr))


@njit(**JIT_BORROW)
def _plastic_eval(row, mutant, woz, wiz):
    """Plastic's diffuse part for wo, wi above (woz, wiz > 0): (1 - F(cos theta_o)) (1 - F(cos theta_i)) / eta^2
    diff / pi cos theta_i, per channel."""
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0, 0.0, 0.0
    eta = row[P_IOR]
    v = ((1.0 - fresnel_dielectric(woz, eta)[0]) * (1.0 - fresnel_dielectric(wiz, eta)[0]) / (eta * eta)
         * wiz * INV_PI)
    fdr = fresnel_diffuse_reflectance(1.0 / eta)  # once for the three channels
    return (v * _plastic_diffuse(row, mutant, 0, fdr), v * _plastic_diffuse(row, mutant, 1, fdr),
            v * _plastic_diffuse(row, mutant, 2, fdr))


@njit(**JIT_BORROW)
def _plastic_pdf(row, woz, wiz):
    """The diffuse lobe's density for wo, wi above: (1 - P_s) cos theta_i / pi."""
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0
    return (1.0 - _plastic_prob_specular(row, fresnel_dielectric(woz, row[P_IOR])[0])) * wiz * INV_PI


@njit(**JIT_BORROW)
def _plastic_sample(row, mutant, wox, woy, woz, u_lobe, u1, u2):
    """Plastic's sample: the specular lobe with probability P_s (delta, weight R F / P_s), else the diffuse lobe
    cosine-weighted (weight f |cos| / pdf); wo behind a one-sided plastic samples nothing."""
    ok, sgn = _side(row, woz, 0.0)
    if not ok:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    woz = sgn * woz
    f_o = fresnel_dielectric(woz, row[P_IOR])[0]
    ps = _plastic_prob_specular(row, f_o)
    if u_lobe < ps:
        c = f_o / ps
        return (True, -wox, -woy, sgn * woz, c * row[P_REFLECTANCE], c * row[P_REFLECTANCE + 1],
                c * row[P_REFLECTANCE + 2], ps, True)
    lx, ly, lz = cosine_hemisphere(u1, u2)
    p = (1.0 - ps) * lz * INV_PI
    if not (lz > 0.0 and p > 0.0):
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    v0, v1, v2 = _plastic_eval(row, mutant, woz, lz)
    return True, lx, ly, sgn * lz, v0 / p, v1 / p, v2 / p, p, False


# ---------------------------------------------------------------------------------------------- rough plastic


@njit(**JIT)
def _roughplastic_table(ggx, alpha, eta, mu, nodes, weights, transmit):
    """Mitsuba's ``eval_transmittance`` (``transmit``) or ``eval_reflectance`` (include/mitsuba/render/microfacet.h)
    of a rough dielectric interface of relative index ``eta`` seen from cos theta = mu[k], wi = (sqrt(1 - mu^2), 0,
    mu): the tensor Gauss-Legendre quadrature (``nodes``, ``weights`` on [-1, 1], mapped to [0, 1]^2) of the visible
    normals' sample space, sum of w_x w_y / 4 G1(wo, m) (1 - F(wi.m)) over the samples m whose refraction wo crosses
    the interface, or G1(wo, m) F(wi.m) over those whose reflection stays above."""
    out = np.zeros(len(mu))
    for k in range(len(mu)):
        wz = mu[k]
        wx = math.sqrt(1.0 - wz * wz)
        acc = 0.0
        for a in range(len(nodes)):
            for b in range(len(nodes)):
                hx, hy, hz, _p = mf_sample(ggx, alpha, True, 0, wx, 0.0, wz, 0.5 * nodes[b] + 0.5,
                                           0.5 * nodes[a] + 0.5)
                c = wx * hx + wz * hz
                f, cos_t, _eta_it, eta_ti = fresnel_dielectric(c, eta)
                if transmit:
                    s = c * eta_ti + cos_t
                    ox, oy, oz = hx * s - wx * eta_ti, hy * s, hz * s - wz * eta_ti
                    v = (1.0 - f) if oz * wz < 0.0 else 0.0
                else:
                    ox, oy, oz = 2.0 * c * hx - wx, 2.0 * c * hy, 2.0 * c * hz - wz
                    v = f if oz > 0.0 else 0.0
                if v != 0.0:
                    acc += v * mf_g1(ggx, alpha, ox, oy, oz, hx, hy, hz) * weights[a] * weights[b] * 0.25
        out[k] = acc
    return out


@functools.lru_cache(maxsize=256)
def _roughplastic_lut_cached(ggx: bool, alpha: float, eta: float) -> np.ndarray:
    mu = np.maximum(1e-6, np.linspace(0.0, 1.0, LUT_RES))
    lut = np.empty(LUT_SIZE)
    nodes, weights = np.polynomial.legendre.leggauss(32 if eta > 1.0 else 128)
    lut[:LUT_RES] = _roughplastic_table(ggx, alpha, eta, mu, nodes, weights, True)
    nodes, weights = np.polynomial.legendre.leggauss(32 if 1.0 / eta > 1.0 else 128)
    lut[LUT_RES] = 2.0 * np.mean(_roughplastic_table(ggx, alpha, 1.0 / eta, mu, nodes, weights, False) * mu)
    lut.setflags(write=False)
    return lut


def roughplastic_luts(materials) -> np.ndarray:
    """(M, LUT_SIZE): each rough plastic's table (:func:`roughplastic_lut` of its row), zeros on the other kinds: the
    ``lut`` of :func:`.records.material_tables`."""
    lut = np.zeros((len(materials.kind), LUT_SIZE))
    for m in np.nonzero(materials.kind == ROUGHPLASTIC)[0]:
        row = materials.params[m]
        lut[m] = roughplastic_lut(int(row[P_DISTRIBUTION]), float(row[P_ALPHA]), float(row[P_IOR]))
    return lut


def roughplastic_lut(distribution: int, alpha: float, eta: float) -> np.ndarray:
    """A rough plastic's table (LUT_SIZE numbers, ``MaterialTables.lut``), as Mitsuba 3.9.1's
    ``RoughPlastic::parameters_changed`` (src/bsdfs/roughplastic.cpp) computes it: the external transmittance
    T(mu) = 1 - (the rough coating's reflectance, including the light its microfacets reflect back out) at the
    LUT_RES cosines mu_i = max(1e-6, i / (LUT_RES - 1)), by :func:`_roughplastic_table` with 32 x 32 nodes (128 x 128
    when eta <= 1), visible-normal sampling whatever ``sample_visible`` says; then the internal reflectance
    R_i = 2 mean_i(R(mu_i; 1 / eta) mu_i), the coating's reflectance from inside averaged over a cosine-weighted
    hemisphere (a left Riemann sum of 2 int R mu dmu, as Mitsuba). alpha clamped as the kernels' (MIN_ALPHA)."""
    return _roughplastic_lut_cached(int(distribution) == GGX, max(float(alpha), MIN_ALPHA), float(eta))


@njit(**JIT_BORROW)
def _roughplastic_transmittance(row, cos_theta):
    """T(cos_theta) from the row's table, linearly interpolated as Mitsuba's ``lerp_gather``: x = 63 cos_theta,
    i = min(floor(x), 62), T_i + (x - i)(T_{i+1} - T_i)."""
    x = cos_theta * (LUT_RES - 1)
    i = min(int(x), LUT_RES - 2)
    t0 = row[P_LUT + i]
    return t0 + (row[P_LUT + i + 1] - t0) * (x - i)


@njit(**JIT_BORROW)
def _roughplastic_prob_specular(row, woz):
    """The probability of the glossy lobe, (1 - T(cos theta_o)) w / ((1 - T) w + T (1 - w)), w the specular
    sampling weight (roughplastic.cpp); 0 where the denominator is 0."""
    t_o = _roughplastic_transmittance(row, woz)
    w = row[P_SPECULAR_WEIGHT]
    ps = (1.0 - t_o) * w
    total = ps + t_o * (1.0 - w)
    return ps / total if total > 0.0 else 0.0


@njit(**JIT_BORROW)
def _roughplastic_diffuse(row, c):
    """diff of channel ``c``: rho / (1 - R_i) or, nonlinear, rho / (1 - rho R_i), R_i the table's internal
    reflectance."""
    rho = row[P_DIFFUSE + c]
    ri = row[P_INTERNAL_REFLECTANCE]
    return rho / (1.0 - (rho * ri if row[P_NONLINEAR] != 0.0 else ri))


@njit(**JIT_NONRT)
def _roughplastic_eval(row, wox, woy, woz, wix, wiy, wiz):
    """Rough plastic for wo, wi above (woz, wiz > 0): R F(wo.h) D(h) G1(wo, h) G1(wi, h) / (4 cos theta_o) +
    diff / (pi eta^2) T(cos theta_o) T(cos theta_i) cos theta_i, diff = rho / (1 - R_i) or, nonlinear,
    rho / (1 - rho R_i); per channel."""
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0, 0.0, 0.0
    ggx = row[P_DISTRIBUTION] == GGX
    alpha = _alpha(row)
    eta = row[P_IOR]
    hx, hy, hz = wox + wix, woy + wiy, woz + wiz
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    spec = mf_d(ggx, alpha, hx, hy, hz)
    if spec != 0.0:
        spec *= (mf_g1(ggx, alpha, wox, woy, woz, hx, hy, hz) * mf_g1(ggx, alpha, wix, wiy, wiz, hx, hy, hz)
                 * fresnel_dielectric(wox * hx + woy * hy + woz * hz, eta)[0] / (4.0 * woz))
    v = (_roughplastic_transmittance(row, woz) * _roughplastic_transmittance(row, wiz) * wiz * INV_PI
         / (eta * eta))
    return (spec * row[P_REFLECTANCE] + v * _roughplastic_diffuse(row, 0),
            spec * row[P_REFLECTANCE + 1] + v * _roughplastic_diffuse(row, 1),
            spec * row[P_REFLECTANCE + 2] + v * _roughplastic_diffuse(row, 2))


@njit(**JIT_NONRT)
def _roughplastic_pdf(row, wox, woy, woz, wix, wiy, wiz):
    """P_s p_h(h) / (4 wi.h) + (1 - P_s) cos theta_i / pi for wo, wi above, p_h :func:`mf_pdf` (visible normals:
    D G1(wo, h) / (4 cos theta_o) with the exact G1; all normals: D cos theta_h / (4 wi.h))."""
    if woz <= 0.0 or wiz <= 0.0:
        return 0.0
    ps = _roughplastic_prob_specular(row, woz)
    hx, hy, hz = wox + wix, woy + wiy, woz + wiz
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    wi_h = wix * hx + wiy * hy + wiz * hz
    p = (1.0 - ps) * wiz * INV_PI
    if ps > 0.0 and wi_h > 0.0:
        p += ps * mf_pdf(row[P_DISTRIBUTION] == GGX, _alpha(row), row[P_SAMPLE_VISIBLE] != 0.0,
                         wox, woy, woz, hx, hy, hz) / (4.0 * wi_h)
    return p


@njit(**JIT_NONRT)
def _roughplastic_sample(row, mutant, wox, woy, woz, u_lobe, u1, u2):
    """The glossy lobe with probability P_s (a microfacet normal as the rough conductor's, wi its reflection), else
    the diffuse lobe cosine-weighted; weight f |cos| / pdf with the mixture's pdf (:func:`_roughplastic_pdf`); wo
    behind a one-sided plastic samples nothing."""
    ok, sgn = _side(row, woz, 0.0)
    if not ok:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    woz = sgn * woz
    if u_lobe < _roughplastic_prob_specular(row, woz):
        hx, hy, hz, ph = mf_sample(row[P_DISTRIBUTION] == GGX, _alpha(row), row[P_SAMPLE_VISIBLE] != 0.0, mutant,
                                   wox, woy, woz, u1, u2)
        wo_h = wox * hx + woy * hy + woz * hz
        wix, wiy, wiz = 2.0 * wo_h * hx - wox, 2.0 * wo_h * hy - woy, 2.0 * wo_h * hz - woz
        if not (ph > 0.0 and wo_h > 0.0):
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    else:
        wix, wiy, wiz = cosine_hemisphere(u1, u2)
    if not wiz > 0.0:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    p = _roughplastic_pdf(row, wox, woy, woz, wix, wiy, wiz)
    v0, v1, v2 = _roughplastic_eval(row, wox, woy, woz, wix, wiy, wiz)
    if not (p > 0.0) or (v0 == 0.0 and v1 == 0.0 and v2 == 0.0):
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    return True, wix, wiy, sgn * wiz, v0 / p, v1 / p, v2 / p, p, False
# ------------------------------------------------------------------------------------------------- principled


@njit(**JIT)
def ggx_aniso_d(au, av, hx, hy, hz):
    """The anisotropic GGX distribution D(h) = 1 / (pi a_u a_v (h_x^2 / a_u^2 + h_y^2 / a_v^2 + h_z^2)^2)
    (microfacet.h ``eval``), 0 where D cos theta_h <= 1e-20 (:func:`mf_d` is its isotropic case, kept apart so that
    the isotropic kinds' bits stay as they are)."""
    x, y = hx / au, hy / av
    t = x * x + y * y + hz * hz
    r = 1.0 / (np.pi * au * av * t * t)
    return r if r * hz > 1e-20 else 0.0


@njit(**JIT)
def ggx_aniso_g1(au, av, vx, vy, vz, hx, hy, hz):
    """Smith's anisotropic GGX masking G1(v, h) = 2 / (1 + sqrt(1 + (a_u^2 v_x^2 + a_v^2 v_y^2) / v_z^2)), 1 at
    normal incidence, 0 where v.h and v_z differ in sign (microfacet.h ``smith_g1``)."""
    if (vx * hx + vy * hy + vz * hz) * vz <= 0.0:
        return 0.0
    ax, ay = au * vx, av * vy
    xy = ax * ax + ay * ay
    if xy == 0.0:
        return 1.0
    return 2.0 / (1.0 + math.sqrt(1.0 + xy / (vz * vz)))


@njit(**JIT)
def ggx_aniso_pdf(au, av, wx, wy, wz, hx, hy, hz):
    """Density of :func:`ggx_aniso_sample`'s h per unit solid angle of h, for wz > 0: the visible normals'
    D(h) G1(w, h) |w.h| / w_z."""
    return (ggx_aniso_d(au, av, hx, hy, hz) * ggx_aniso_g1(au, av, wx, wy, wz, hx, hy, hz)
            * abs(wx * hx + wy * hy + wz * hz) / wz)


@njit(**JIT)
def ggx_aniso_sample(au, av, wx, wy, wz, u1, u2):
    """A visible normal h of the anisotropic GGX surface seen from w (wz > 0): stretch w by (a_u, a_v), Heitz's
    unit-roughness sample (:func:`_sample_visible_11`), rotate, unstretch (microfacet.h ``sample``)."""
    return visible_normal(True, au, av, wx, wy, wz, u1, u2)


@njit(**JIT)
def schlick_weight(c):
    """(1 - c)^5, 1 - c clipped to [0, 1] (principledhelpers.h ``schlick_weight``)."""
    m = min(max(1.0 - c, 0.0), 1.0)
    m2 = m * m
    return m2 * m2 * m


@njit(**JIT)
def calc_schlick(r0, cos_theta_i, eta):
    """Schlick's Fresnel R0 + (1 - R0)(1 - cos)^5 of an interface of relative index ``eta`` seen at
    ``cos_theta_i`` (its sign says the side): the cosine is |cos theta_i| where the light goes into the denser
    medium (eta_it > 1), else that of the refracted direction (0 under total internal reflection: F = 1)
    (principledhelpers.h ``calc_schlick``)."""
    outside = cos_theta_i >= 0.0
    eta_it = eta if outside else 1.0 / eta
    eta_ti = 1.0 / eta if outside else eta
    if eta_it > 1.0:
        w = schlick_weight(abs(cos_theta_i))
    else:
        ct2 = 1.0 - (1.0 - cos_theta_i * cos_theta_i) * (eta_ti * eta_ti)
        w = schlick_weight(math.sqrt(ct2) if ct2 > 0.0 else 0.0)
    return r0 + (1.0 - r0) * w


@njit(**JIT)
def gtr1_d(alpha, hz):
    """Burley's GTR1 (Berry) distribution of the clearcoat, D(h) = (a^2 - 1) / (pi ln(a^2) (1 + (a^2 - 1)
    cos^2 theta_h)), 0 where D cos theta_h <= 1e-20 (principledhelpers.h ``GTR1Isotropic::eval``)."""
    a2 = alpha * alpha
    r = (a2 - 1.0) / (np.pi * math.log(a2) * (1.0 + (a2 - 1.0) * hz * hz))
    return r if r * hz > 1e-20 else 0.0


@njit(**JIT)
def smith_ggx1(alpha, vx, vy, vz, hx, hy, hz):
    """The clearcoat's Smith GGX masking 2 / (1 + sqrt(1 + alpha^2 tan^2 theta)) (alpha 0.25), 1 at v_z = 1, 0 where
    v.h and v_z differ in sign (principledhelpers.h ``smith_ggx1``)."""
    if (vx * hx + vy * hy + vz * hz) * vz <= 0.0:
        return 0.0
    if vz == 1.0:
        return 1.0
    c2 = vz * vz
    return 2.0 / (1.0 + math.sqrt(1.0 + alpha * alpha * ((1.0 - c2) / c2)))


@njit(**JIT_NONRT)
def _principled_alphas(row):
    """(a_u, a_v) of the main lobe: roughness^2 stretched by 1 / aspect and aspect, aspect = sqrt(1 - 0.9
    anisotropic), each at least 0.001 (principledhelpers.h ``calc_dist_params``)."""
    r2 = row[P_ROUGHNESS] * row[P_ROUGHNESS]
    aspect = math.sqrt(1.0 - 0.9 * row[P_ANISOTROPIC])
    return max(0.001, r2 / aspect), max(0.001, r2 * aspect)


@njit(**JIT_NONRT)
def _principled_half(row, wox, woy, woz, wix, wiy, wiz):
    """(ok, reflect, eta_path, hx, hy, hz): the rough dielectric's half vector (:func:`_roughdielectric_half`,
    eta_path the relative index of wo's side), not ok where wo or wi is in the surface's plane."""
    if woz * wiz == 0.0:
        return False, woz * wiz > 0.0, row[P_IOR] if woz > 0.0 else 1.0 / row[P_IOR], 0.0, 0.0, 1.0
    return _roughdielectric_half(row, wox, woy, woz, wix, wiy, wiz)


@njit(**JIT_NONRT)
def _principled_probs(row, front, f):
    """The lobe probabilities (diffuse, clearcoat, transmission, reflection) for wo on side ``front`` and the
    dielectric Fresnel ``f`` of the main lobe's normal: from the front brdf r_d, cc / 4 r_c, r_s bsdf (1 - F),
    r_s (1 - bsdf (1 - F)) over their sum (r_* the sampling rates), from behind 0, 0, 1 - F, F (principled.cpp)."""
    metallic, trans = row[P_METALLIC], row[P_SPEC_TRANS]
    bsdf_w = (1.0 - metallic) * trans
    if not front:
        return 0.0, 0.0, 1.0 - f, f
    rs = row[P_SPECULAR_RATE]
    p_d = (1.0 - metallic) * (1.0 - trans) * row[P_DIFFUSE_RATE]
    p_cc = 0.25 * row[P_CLEARCOAT] * row[P_CLEARCOAT_RATE]
    p_st = rs * bsdf_w * (1.0 - f)
    p_sr = rs * (1.0 - bsdf_w * (1.0 - f))
    inv = 1.0 / (p_sr + p_st + p_cc + p_d)
    return p_d * inv, p_cc * inv, p_st * inv, p_sr * inv


@njit(**JIT_NONRT)
def _principled_eval(row, mutant, wox, woy, woz, wix, wiy, wiz):
    """The principled BSDF's f |cos theta_i| (module docstring), per channel."""
    metallic, trans = row[P_METALLIC], row[P_SPEC_TRANS]
    bsdf_w = (1.0 - metallic) * trans
    brdf_w = (1.0 - metallic) * (1.0 - trans)
    front = woz > 0.0
    if woz == 0.0 or not (front or bsdf_w > 0.0):
        return 0.0, 0.0, 0.0
    ok, reflect, eta_path, hx, hy, hz = _principled_half(row, wox, woy, woz, wix, wiy, wiz)
    if not ok:
        return 0.0, 0.0, 0.0
    eta = row[P_IOR]
    wo_h = wox * hx + woy * hy + woz * hz
    wi_h = wix * hx + wiy * hy + wiz * hz
    sgn = 1.0 if front else -1.0
    if reflect:
        compatible = wo_h * sgn > 0.0 and wi_h * sgn > 0.0
    else:
        compatible = wo_h * sgn > 0.0 and wi_h * sgn < 0.0
    f = fresnel_dielectric(wo_h, eta)[0]
    b0, b1, b2 = row[P_REFLECTANCE], row[P_REFLECTANCE + 1], row[P_REFLECTANCE + 2]
    v0, v1, v2 = 0.0, 0.0, 0.0
    if compatible:
        au, av = _principled_alphas(row)
        dg = (ggx_aniso_d(au, av, hx, hy, hz) * ggx_aniso_g1(au, av, wox, woy, woz, hx, hy, hz)
              * ggx_aniso_g1(au, av, wix, wiy, wiz, hx, hy, hz))
        if reflect and f > 0.0:  # the main specular reflection
            c = dg / (4.0 * abs(woz))
            if front:  # metallic and tinted Schlick over the dielectric Fresnel
                tint = row[P_SPEC_TINT]
                lum = LUM_R * b0 + LUM_G * b1 + LUM_B * b2
                eta_it = eta if wo_h >= 0.0 else 1.0 / eta
                r0 = (eta_it - 1.0) / (eta_it + 1.0)
                r0 = r0 * r0
                fd = (1.0 - metallic) * (1.0 - tint) * f
                s0 = s1 = s2 = 0.0
                if metallic != 0.0:
                    s0 = metallic * calc_schlick(b0, wo_h, eta)
                    s1 = metallic * calc_schlick(b1, wo_h, eta)
                    s2 = metallic * calc_schlick(b2, wo_h, eta)
                if tint != 0.0:
                    k = (1.0 - metallic) * tint
                    t0, t1, t2 = (b0 / lum, b1 / lum, b2 / lum) if lum > 0.0 else (1.0, 1.0, 1.0)
                    s0 += k * calc_schlick(t0 * r0, wo_h, eta)
                    s1 += k * calc_schlick(t1 * r0, wo_h, eta)
                    s2 += k * calc_schlick(t2 * r0, wo_h, eta)
                v0, v1, v2 = (fd + s0) * c, (fd + s1) * c, (fd + s2) * c
            else:  # from inside: the dielectric alone
                v0 = v1 = v2 = bsdf_w * f * c
        elif not reflect and bsdf_w > 0.0 and f < 1.0:  # the main specular transmission (radiance: 1 / eta_path^2)
            denom = wo_h + eta_path * wi_h
            c = bsdf_w * abs((1.0 - f) * dg * wo_h * wi_h / (woz * denom * denom))
            v0, v1, v2 = math.sqrt(b0) * c, math.sqrt(b1) * c, math.sqrt(b2) * c
        clearcoat = row[P_CLEARCOAT]
        if reflect and front and clearcoat > 0.0:  # Burley's clearcoat, as principled.cpp writes it
            g = row[P_CLEARCOAT_GLOSS]
            alpha_cc = 0.1 * (1.0 - g) + 0.001 * g
            c = (0.25 * clearcoat * calc_schlick(0.04, wo_h, eta) * gtr1_d(alpha_cc, hz)
                 * smith_ggx1(0.25, wox, woy, woz, hx, hy, hz) * smith_ggx1(0.25, wix, wiy, wiz, hx, hy, hz)
                 * abs(wiz))
            v0, v1, v2 = v0 + c, v1 + c, v2 + c
    if reflect and front:
        f_o, f_i = schlick_weight(abs(wiz)), schlick_weight(abs(woz))  # principled.cpp's Fo (its wo: our wi), Fi
        cos_d = hx * wix + hy * wiy + hz * wiz
        if brdf_w > 0.0:  # diffuse with retro-reflection, and the fake subsurface where flatness > 0
            rr = 2.0 * row[P_ROUGHNESS] * cos_d * cos_d
            lobe = (1.0 - 0.5 * f_i) * (1.0 - 0.5 * f_o) + rr * (f_o + f_i + f_o * f_i * (rr - 1.0))
            flatness = row[P_FLATNESS]
            if flatness != 0.0:
                fss90 = 0.5 * rr
                fss = (1.0 + (fss90 - 1.0) * f_o) * (1.0 + (fss90 - 1.0) * f_i)
                f_ss = 1.25 * (fss * (1.0 / (abs(woz) + abs(wiz)) - 0.5) + 0.5)
                lobe = lobe * (1.0 - flatness) + f_ss * flatness
            c = brdf_w * abs(wiz) * INV_PI * lobe
            v0, v1, v2 = v0 + c * b0, v1 + c * b1, v2 + c * b2
        sheen = row[P_SHEEN]
        if sheen > 0.0 and 1.0 - metallic > 0.0:
            c = sheen * (1.0 - metallic) * schlick_weight(abs(cos_d)) * abs(wiz)
            tint = row[P_SHEEN_TINT]
            if tint != 0.0:
                lum = LUM_R * b0 + LUM_G * b1 + LUM_B * b2
                t0, t1, t2 = (b0 / lum, b1 / lum, b2 / lum) if lum > 0.0 else (1.0, 1.0, 1.0)
                v0 += c * (1.0 - tint + t0 * tint)
                v1 += c * (1.0 - tint + t1 * tint)
                v2 += c * (1.0 - tint + t2 * tint)
            else:
                v0, v1, v2 = v0 + c, v1 + c, v2 + c
    return v0, v1, v2


@njit(**JIT_NONRT)
def _principled_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz):
    """Density of :func:`_principled_sample`'s wi: the lobes' densities times their probabilities
    (:func:`_principled_probs` with F at the pair's half vector); 0 from behind where nothing transmits."""
    bsdf_w = (1.0 - row[P_METALLIC]) * row[P_SPEC_TRANS]
    front = woz > 0.0
    if woz == 0.0 or not (front or bsdf_w > 0.0):
        return 0.0
    ok, reflect, eta_path, hx, hy, hz = _principled_half(row, wox, woy, woz, wix, wiy, wiz)
    if not ok:
        return 0.0
    wo_h = wox * hx + woy * hy + woz * hz
    wi_h = wix * hx + wiy * hy + wiz * hz
    sgn = 1.0 if front else -1.0
    if reflect:
        compatible = wo_h * sgn > 0.0 and wi_h * sgn > 0.0
    else:
        compatible = wo_h * sgn > 0.0 and wi_h * sgn < 0.0
    p_d, p_cc, p_st, p_sr = _principled_probs(row, front, fresnel_dielectric(wo_h, row[P_IOR])[0])
    p = 0.0
    if reflect:
        if compatible:
            jacobian = 1.0 / (4.0 * abs(wi_h))
            au, av = _principled_alphas(row)
            p += p_sr * ggx_aniso_pdf(au, av, sgn * wox, sgn * woy, sgn * woz, hx, hy, hz) * jacobian
            if p_cc > 0.0:
                g = row[P_CLEARCOAT_GLOSS]
                p_h = hz * gtr1_d(0.1 * (1.0 - g) + 0.001 * g, hz)
                if mutant & M_CLEARCOAT_PDF_NO_JACOBIAN:  # mutant "principled-clearcoat-pdf-jacobian"
                    jacobian = 1.0  # the half vector's density taken for the direction's: no 1 / (4 |wi.h|)
                p += p_cc * p_h * jacobian
        p += p_d * abs(wiz) * INV_PI
    elif compatible and p_st > 0.0:
        au, av = _principled_alphas(row)
        denom = wo_h + eta_path * wi_h
        p += (p_st * ggx_aniso_pdf(au, av, sgn * wox, sgn * woy, sgn * woz, hx, hy, hz)
              * abs(eta_path * eta_path * wi_h / (denom * denom)))
    return p


@njit(**JIT_NONRT)
def _principled_sample(row, mutant, wox, woy, woz, u_lobe, u1, u2):
    """The principled sample: a lobe by u_lobe (diffuse, clearcoat, transmission, reflection, principled.cpp's
    order, the last two by F at the main lobe's sampled normal), its direction by (u1, u2) -- cosine-weighted, a
    GTR1 half vector reflected, or a visible GGX normal refracted or reflected -- weight eval / pdf."""
    bsdf_w = (1.0 - row[P_METALLIC]) * row[P_SPEC_TRANS]
    front = woz > 0.0
    if woz == 0.0 or not (front or bsdf_w > 0.0):
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    p_d, p_cc, _p_st, _p_sr = _principled_probs(row, front, 0.0)  # the first two do not depend on F
    if u_lobe < p_d:
        wix, wiy, wiz = cosine_hemisphere(u1, u2)
    elif u_lobe < p_d + p_cc:
        g = row[P_CLEARCOAT_GLOSS]
        alpha = 0.1 * (1.0 - g) + 0.001 * g
        a2 = alpha * alpha
        cos2 = (1.0 - a2 ** (1.0 - u2)) / (1.0 - a2)
        sin_t = math.sqrt(max(0.0, 1.0 - cos2))
        cos_t = math.sqrt(max(0.0, cos2))
        phi = 2.0 * np.pi * u1
        hx, hy, hz = math.cos(phi) * sin_t, math.sin(phi) * sin_t, cos_t
        wo_h = wox * hx + woy * hy + woz * hz
        wix, wiy, wiz = 2.0 * wo_h * hx - wox, 2.0 * wo_h * hy - woy, 2.0 * wo_h * hz - woz
        if wiz * woz <= 0.0:  # reflected below the surface: no sample (not a transmission)
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    else:
        sgn = 1.0 if front else -1.0
        au, av = _principled_alphas(row)
        hx, hy, hz = ggx_aniso_sample(au, av, sgn * wox, sgn * woy, sgn * woz, u1, u2)
        wo_h = wox * hx + woy * hy + woz * hz
        f, cos_t, _eta_it, eta_ti = fresnel_dielectric(wo_h, row[P_IOR])
        p_st = _principled_probs(row, front, f)[2]
        if u_lobe < p_d + p_cc + p_st:
            c = wo_h * eta_ti + cos_t
            wix, wiy, wiz = hx * c - wox * eta_ti, hy * c - woy * eta_ti, hz * c - woz * eta_ti
            if wiz * woz >= 0.0:
                return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        else:
            wix, wiy, wiz = 2.0 * wo_h * hx - wox, 2.0 * wo_h * hy - woy, 2.0 * wo_h * hz - woz
            if wiz * woz <= 0.0:  # reflected below the surface: no sample (not a transmission)
                return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    if wiz * woz == 0.0:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    p = _principled_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz)
    if not p > 0.0:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    v0, v1, v2 = _principled_eval(row, mutant, wox, woy, woz, wix, wiy, wiz)
    if v0 == 0.0 and v1 == 0.0 and v2 == 0.0:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    return True, wix, wiy, wiz, v0 / p, v1 / p, v2 / p, p, False


@njit(**JIT_BORROW)
def bsdf_eval(kind, row, mutant, wox, woy, woz, wix, wiy, wiz, later=True):
    """f(wo, wi) |cos theta_i| of a material of ``kind`` with the parameters ``row`` at the hit (the material
    step's, :func:`.material.material_at`), per channel (v0, v1, v2); 0 for delta BSDFs (and delta lobes) and
    impossible pairs.
    Directions local (z = the front normal)."""
    if kind == DIFFUSE or kind == ROUGHCONDUCTOR:
        ok, sgn = _side(row, woz, wiz)
        if not ok:
            return 0.0, 0.0, 0.0
        woz, wiz = sgn * woz, sgn * wiz
        if kind == DIFFUSE:
            if wiz <= 0.0:
                return 0.0, 0.0, 0.0
            c = wiz * INV_PI
            return c * row[P_REFLECTANCE], c * row[P_REFLECTANCE + 1], c * row[P_REFLECTANCE + 2]
        return _roughconductor_eval(row, mutant, wox, woy, woz, wix, wiy, wiz)
    if kind == ROUGHDIELECTRIC:
        return _roughdielectric_eval(row, mutant, wox, woy, woz, wix, wiy, wiz)
    if kind == PLASTIC:
        ok, sgn = _side(row, woz, wiz)
        if not ok:
            return 0.0, 0.0, 0.0
        return _plastic_eval(row, mutant, sgn * woz, sgn * wiz)
    if later is None:  # a scene without them: their code compiled out (module docstring)
        return 0.0, 0.0, 0.0
    if kind == ROUGHPLASTIC:
        ok, sgn = _side(row, woz, wiz)
        if not ok:
            return 0.0, 0.0, 0.0
        return _roughplastic_eval(row, wox, woy, sgn * woz, wix, wiy, sgn * wiz)
    if kind == PRINCIPLED:
        return _principled_eval(row, mutant, wox, woy, woz, wix, wiy, wiz)
    return 0.0, 0.0, 0.0


@njit(**JIT_BORROW)
def bsdf_pdf(kind, row, mutant, uniform_diffuse, wox, woy, woz, wix, wiy, wiz, later=True):
    """Density of :func:`bsdf_sample`'s wi per unit solid angle (``uniform_diffuse`` as there); 0 for delta BSDFs
    and impossible pairs."""
    if kind == DIFFUSE or kind == ROUGHCONDUCTOR:
        ok, sgn = _side(row, woz, wiz)
        if not ok:
            return 0.0
        woz, wiz = sgn * woz, sgn * wiz
        if kind == DIFFUSE:
            if not wiz > 0.0:
                return 0.0
            return INV_2PI if uniform_diffuse else wiz * INV_PI
        return _roughconductor_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz)
    if kind == ROUGHDIELECTRIC:
        return _roughdielectric_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz)
    if kind == PLASTIC:
        ok, sgn = _side(row, woz, wiz)
        if not ok:
            return 0.0
        return _plastic_pdf(row, sgn * woz, sgn * wiz)
    if later is None:
        return 0.0
    if kind == ROUGHPLASTIC:
        ok, sgn = _side(row, woz, wiz)
        if not ok:
            return 0.0
        return _roughplastic_pdf(row, wox, woy, sgn * woz, wix, wiy, sgn * wiz)
    if kind == PRINCIPLED:
        return _principled_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz)
    return 0.0


@njit(**JIT)
def is_delta(kind):
    """True for the kinds whose every lobe is a Dirac delta (conductor, dielectric, thin dielectric; plastic has a
    diffuse lobe too: light is sampled at it, and its samples say which lobe they are off)."""
    return kind == CONDUCTOR or kind == DIELECTRIC or kind == THINDIELECTRIC


@njit(**JIT_BORROW)
def chooses_lobe(kind, transmits):
    """True for a BSDF whose sample picks a lobe with its first uniform (u_lobe): one that transmits at the hit
    (``transmits``), a plastic, a rough plastic or a principled. The others never read u_lobe, so the engines draw it
    only for these."""
    return transmits or kind == PLASTIC or kind == ROUGHPLASTIC or kind == PRINCIPLED


@njit(**JIT_BORROW)
def sample_eta(kind, row, woz, wiz):
    """The relative index of refraction of a sampled (wo, wi) in the direction of travel (Mitsuba's ``bs.eta``, for
    the throughput roulette's eta^2): eta_it of a transmission through a dielectric, else 1 (the thin dielectric's
    straight-through light leaves into the medium it came from)."""
    if (kind == DIELECTRIC or kind == ROUGHDIELECTRIC or kind == PRINCIPLED) and woz * wiz < 0.0:
        eta = row[P_IOR]
        return eta if woz > 0.0 else 1.0 / eta
    return 1.0


@njit(**JIT_BORROW)
def diffuse_direction(uniform_diffuse, u1, u2):
    """The diffuse kind's local direction for (u1, u2), before the side: cosine-weighted (p = cos / pi), or uniform
    (p = 1 / (2 pi)) with ``uniform_diffuse``. It depends on nothing at x, so a block of paths can draw it before it
    knows its hits (:mod:`.blocks`); :func:`diffuse_sample` makes it :func:`bsdf_sample`'s answer."""
    if uniform_diffuse:
        return uniform_hemisphere(u1, u2)
    return cosine_hemisphere(u1, u2)


@njit(**JIT_BORROW)
def diffuse_sample(row, uniform_diffuse, woz, lx, ly, lz):
    """:func:`bsdf_sample`'s answer for the diffuse kind and wo's local z ``woz`` from its local direction (lx, ly,
    lz) (:func:`diffuse_direction`), turned to wo's side: w = rho (cosine), or 2 rho cos (uniform)."""
    ok, sgn = _side(row, woz, 0.0)
    if not ok or not lz > 0.0:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    if uniform_diffuse:
        c = 2.0 * lz
        return (True, lx, ly, sgn * lz, c * row[P_REFLECTANCE], c * row[P_REFLECTANCE + 1],
                c * row[P_REFLECTANCE + 2], INV_2PI, False)
    return (True, lx, ly, sgn * lz, row[P_REFLECTANCE], row[P_REFLECTANCE + 1], row[P_REFLECTANCE + 2],
            lz * INV_PI, False)


@njit(**JIT_BORROW)
def bsdf_sample(kind, row, mutant, uniform_diffuse, wox, woy, woz, u_lobe, u1, u2, later=True):
    """Sample wi for wo: (ok, wix, wiy, wiz, w0, w1, w2, pdf, delta). The diffuse kind samples the cosine-weighted
    hemisphere (p = cos / pi, w = rho), or with ``uniform_diffuse`` (``hemisphere = "uniform"``, the slides'
    other choice, Fig. 5.14) the uniform one (p = 1 / (2 pi), w = 2 rho cos).

    w = f |cos theta_i| / pdf per channel (a delta lobe: its weight, e.g. R F / P(lobe)); pdf per unit solid angle
    of wi, or for a delta lobe the discrete probability of the lobe; ok False when nothing is sampled (wo behind a
    one-sided surface, a sample below the horizon or on the wrong side for its lobe, a zero weight)."""
    if kind == DIFFUSE:
        lx, ly, lz = diffuse_direction(uniform_diffuse, u1, u2)
        return diffuse_sample(row, uniform_diffuse, woz, lx, ly, lz)
    if kind == CONDUCTOR or kind == ROUGHCONDUCTOR:
        ok, sgn = _side(row, woz, 0.0)
        if not ok:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        woz = sgn * woz
        if kind == CONDUCTOR:
            f0, f1, f2 = _conductor_fresnel3(row, mutant, woz)
            return (True, -wox, -woy, sgn * woz, f0 * row[P_REFLECTANCE], f1 * row[P_REFLECTANCE + 1],
                    f2 * row[P_REFLECTANCE + 2], 1.0, True)
        ggx = row[P_DISTRIBUTION] == GGX
        hx, hy, hz, ph = mf_sample(ggx, _alpha(row), row[P_SAMPLE_VISIBLE] != 0.0, mutant,
                                   wox, woy, woz, u1, u2)
        wo_h = wox * hx + woy * hy + woz * hz
        wix, wiy, wiz = 2.0 * wo_h * hx - wox, 2.0 * wo_h * hy - woy, 2.0 * wo_h * hz - woz
        if not (ph > 0.0 and wiz > 0.0 and wo_h > 0.0):
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        v0, v1, v2 = _roughconductor_eval(row, mutant, wox, woy, woz, wix, wiy, wiz)
        p = _roughconductor_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz)
        if not (p > 0.0) or (v0 == 0.0 and v1 == 0.0 and v2 == 0.0):
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        return True, wix, wiy, sgn * wiz, v0 / p, v1 / p, v2 / p, p, False
    if kind == DIELECTRIC:
        if woz == 0.0:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        r, cos_t, eta_it, eta_ti = fresnel_dielectric(woz, row[P_IOR])
        if u_lobe < r:
            return (True, -wox, -woy, woz, row[P_REFLECTANCE], row[P_REFLECTANCE + 1],
                    row[P_REFLECTANCE + 2], r, True)
        scale = eta_ti * eta_ti
        if mutant & M_REFRACTION_NO_ETA2:  # mutant "refraction-no-eta2"
            scale = 1.0
        return (True, -eta_ti * wox, -eta_ti * woy, cos_t, scale * row[P_TRANSMITTANCE],
                scale * row[P_TRANSMITTANCE + 1], scale * row[P_TRANSMITTANCE + 2], 1.0 - r, True)
    if kind == ROUGHDIELECTRIC:
        if woz == 0.0:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        sgn = 1.0 if woz > 0.0 else -1.0
        hx, hy, hz, ph = mf_sample(row[P_DISTRIBUTION] == GGX, _roughdielectric_sample_alpha(row, woz),
                                   row[P_SAMPLE_VISIBLE] != 0.0, mutant, sgn * wox, sgn * woy, sgn * woz,
                                   u1, u2)
        if not ph > 0.0:
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        wo_h = wox * hx + woy * hy + woz * hz
        if wo_h * woz <= 0.0:  # a normal facing away from wo (all-normals sampling): masked, G1(wo, h) = 0
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        f, cos_t, eta_it, eta_ti = fresnel_dielectric(wo_h, row[P_IOR])
        if u_lobe < f:
            wix, wiy, wiz = 2.0 * wo_h * hx - wox, 2.0 * wo_h * hy - woy, 2.0 * wo_h * hz - woz
            if wiz * woz <= 0.0:
                return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        else:
            c = wo_h * eta_ti + cos_t
            wix, wiy, wiz = hx * c - wox * eta_ti, hy * c - woy * eta_ti, hz * c - woz * eta_ti
            if wiz * woz >= 0.0:
                return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        v0, v1, v2 = _roughdielectric_eval(row, mutant, wox, woy, woz, wix, wiy, wiz)
        p = _roughdielectric_pdf(row, mutant, wox, woy, woz, wix, wiy, wiz)
        if not (p > 0.0) or (v0 == 0.0 and v1 == 0.0 and v2 == 0.0):
            return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
        return True, wix, wiy, wiz, v0 / p, v1 / p, v2 / p, p, False
    if kind == THINDIELECTRIC:
        return _thin_sample(row, mutant, wox, woy, woz, u_lobe)
    if kind == PLASTIC:
        return _plastic_sample(row, mutant, wox, woy, woz, u_lobe, u1, u2)
    if later is None:
        return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False
    if kind == ROUGHPLASTIC:
        return _roughplastic_sample(row, mutant, wox, woy, woz, u_lobe, u1, u2)
    if kind == PRINCIPLED:
        return _principled_sample(row, mutant, wox, woy, woz, u_lobe, u1, u2)
    return False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False


# ------------------------------------------------------------------------------------ vectorised, for the tests


@njit(**JIT)
def _eval_many(materials, m, mutant, uniform_diffuse, wo, wi, out_f, out_p):
    row = np.empty(ROW_SIZE)
    kind = material_params(materials, m, row)
    with_f = len(out_f) > 0  # an empty out_f: the pdf only
    for i in range(len(wi)):
        j = i if len(wo) > 1 else 0
        if with_f:
            v0, v1, v2 = bsdf_eval(kind, row, mutant, wo[j, 0], wo[j, 1], wo[j, 2], wi[i, 0], wi[i, 1], wi[i, 2])
            out_f[i, 0], out_f[i, 1], out_f[i, 2] = v0, v1, v2
        out_p[i] = bsdf_pdf(kind, row, mutant, uniform_diffuse, wo[j, 0], wo[j, 1], wo[j, 2], wi[i, 0], wi[i, 1], wi[i, 2])


@njit(**JIT)
def _sample_many(materials, m, mutant, uniform_diffuse, wo, u, ok, wi, w, pdf, delta):
    row = np.empty(ROW_SIZE)
    kind = material_params(materials, m, row)
    for i in range(len(u)):
        j = i if len(wo) > 1 else 0
        ok_i, wi0, wi1, wi2, w0, w1, w2, pdf_i, delta_i = bsdf_sample(kind, row, mutant, uniform_diffuse, wo[j, 0],
                                                                      wo[j, 1], wo[j, 2], u[i, 0], u[i, 1], u[i, 2])
        ok[i] = ok_i
        wi[i, 0], wi[i, 1], wi[i, 2] = wi0, wi1, wi2
        w[i, 0], w[i, 1], w[i, 2] = w0, w1, w2
        pdf[i] = pdf_i
        delta[i] = delta_i


def _tables(materials):
    return material_tables(materials, lut=roughplastic_luts(materials))


def _uniform(hemisphere: str) -> bool:
    if hemisphere not in ("cosine", "uniform"):
        raise ValueError(f"hemisphere: expected 'cosine' or 'uniform', got {hemisphere!r}")
    return hemisphere == "uniform"


def _directions(a, n=None) -> np.ndarray:
    a = np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1, 3))
    if n is not None and len(a) not in (1, n):
        raise ValueError(f"expected 1 or {n} directions, got {len(a)}")
    return a


def eval_pdf(materials, m: int, wo, wi, mutant: int = 0, hemisphere: str = "cosine") -> tuple[np.ndarray, np.ndarray]:
    """:func:`bsdf_eval` and :func:`bsdf_pdf` of material ``m`` over arrays: ``wo`` (3,) or (n, 3), ``wi`` (n, 3)
    local directions; returns f |cos| (n, 3) and pdf (n,). ``hemisphere``: the diffuse kind's sampling, "cosine"
    or "uniform" (``Settings.hemisphere``)."""
    wi = _directions(wi)
    wo = _directions(wo, len(wi))
    f = np.empty((len(wi), 3))
    p = np.empty(len(wi))
    _eval_many(_tables(materials), int(m), int(mutant), _uniform(hemisphere), wo, wi, f, p)
    return f, p


def pdf(materials, m: int, wo, wi, mutant: int = 0, hemisphere: str = "cosine") -> np.ndarray:
    """:func:`bsdf_pdf` of material ``m`` over arrays, as :func:`eval_pdf` returns it without evaluating the BSDF
    (half the work, for the chi^2 tests' quadrature)."""
    wi = _directions(wi)
    wo = _directions(wo, len(wi))
    p = np.empty(len(wi))
    _eval_many(_tables(materials), int(m), int(mutant), _uniform(hemisphere), wo, wi, np.empty((0, 3)), p)
    return p


def sample(materials, m: int, wo, u, mutant: int = 0, hemisphere: str = "cosine") -> dict[str, np.ndarray]:
    """:func:`bsdf_sample` of material ``m`` over arrays: ``wo`` (3,) or (n, 3), ``u`` (n, 3) uniforms (u_lobe, u1,
    u2), ``hemisphere`` as for :func:`eval_pdf`; returns a dict of ``ok`` (n,) bool, ``wi`` (n, 3), ``weight`` (n, 3), ``pdf`` (n,), ``delta`` (n,) bool."""
    u = np.ascontiguousarray(np.asarray(u, dtype=np.float64).reshape(-1, 3))
    wo = _directions(wo, len(u))
    n = len(u)
    out = dict(ok=np.empty(n, dtype=np.bool_), wi=np.empty((n, 3)), weight=np.empty((n, 3)), pdf=np.empty(n),
               delta=np.empty(n, dtype=np.bool_))
    _sample_many(_tables(materials), int(m), int(mutant), _uniform(hemisphere), wo, u, out["ok"], out["wi"],
                 out["weight"], out["pdf"], out["delta"])
    return out
