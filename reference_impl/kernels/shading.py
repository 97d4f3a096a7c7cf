"""The shading frame at a hit: the normal the BSDF's cosines are taken about (Mitsuba 3.9.1's ``si.sh_frame``, then
its ``normalmap`` and ``bumpmap`` BSDFs; pbrt-v4's ``NormalMap`` / ``BumpMap``, applied in the material step).

    vertex normals   n_u = normalize((1 - u - v) n_0 + u n_1 + v n_2)        (a triangle with vertex normals;
                                                                            else n_u = N, the geometric normal)
    tangents         dp/du, dp/dv from the corners and their texture coordinates (det = du_1 dv_2 - dv_1 du_2):
                     dp/du = (dv_2 e_1 - dv_1 e_2) / det,  dp/dv = (-du_2 e_1 + du_1 e_2) / det,  e_i = p_i - p_0;
                     on a sphere Mitsuba's analytic ones (sphere.cpp), at p = to_object x, rho = sqrt(p_x^2 + p_y^2):
                     dp/du = 2 pi L (-p_y, p_x, 0),  dp/dv = pi L (p_z p_x / rho, p_z p_y / rho, -rho)
                     (L the linear part of to_world; dp/dv = pi L (1, 0, 0) at a pole, rho = 0)
                     s_u = normalize(dp/du - n_u (n_u . dp/du)),  t_u = n_u x s_u
    normal map       n = 2 rgb - 1 in (s_u, t_u, n_u)           (the texture's raw value at the hit)
    bump map         dp/du' = dp/du + n_u (scale df/du - n_u . dp/du), dp/dv' likewise,
                     n = normalize(dp/du' x dp/dv'), turned to N's side, then taken into (s_u, t_u, n_u)
                     (df/du, df/dv: the height's gradient, :func:`.texture.texture_grad_1`)
    invalid normals  where wo_z (n . wo) <= 0 (flip_invalid_normals): n = (-n_x, -n_y, n_z)
    the frame        n' = normalize(n),  s' = normalize((1, 0, 0) - n' n'_x),  t' = n' x s'
    terminator       G(w) = 2 / (1 + sqrt(1 + alpha^2 tan^2 theta_u(w))),  alpha^2 = min(tan^2 theta(n') / 8, 1)
                     (Estevez et al. 2019; use_shadowing_function), theta_u about n_u

A direction w counts through a perturbed frame only where (n_u . w)(n' . w) > 0 (Mitsuba's ``active``), and its
f cos is multiplied by G(w) (the pdf is the nested BSDF's). Which side of the surface a direction is on is the
geometric normal's to decide (the path loop, :mod:`.path`); the cosines are the shading frame's. Mitsuba's bump map
takes s' from the world dp/du against the local n' (normalmap.h); here s' is the normal map's rule for both, which
only an anisotropic BSDF could tell apart. An anisotropic principled's frame is turned about n so that s follows
dp/du (:func:`uv_aligned`, Mitsuba's ``initialize_sh_frame``): its lobe's long axis lies along the texture's u.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from numba import njit

from reference_impl.kernels.config import (JIT_BORROW, JIT_NONRT, M_BUMP_SCALE_IGNORED, M_NORMALMAP_GREEN_INVERTED,
                                           M_NORMALS_UNNORMALISED)
from reference_impl.kernels.texture import texture_grad_1
from reference_impl.kernels.warps import dot3, tangent_frame
from reference_impl.materials import (P_BUMP_SCALE, P_FLIP_INVALID, P_NORMAL, P_PERTURB, P_SHADOWING,
                                      PERTURB_BUMPMAP, PERTURB_NONE, TEXTURE_SLOTS)

_BUMP_SLOT = list(TEXTURE_SLOTS).index("bumpmap")


class ShadingFrame(NamedTuple):
    """The frame the BSDF works in at a hit, built by :func:`shading_frame`.

    Attributes
    ----------
    s0, s1, s2, t0, t1, t2, n0, n1, n2 : float
        The BSDF's local x, y and z axes (world): z is the shading normal (perturbed, where a normal or bump map is).
    u0, u1, u2 : float
        The shading normal before a normal or bump map (the vertex normals' blend, or N).
    alpha2 : float
        The shadow terminator's alpha^2, or -1 where there is none (no map, or use_shadowing_function off).
    differs : bool
        Whether n may differ from the geometric normal N (vertex normals or a map): the side test is needed.
    perturbed : bool
        Whether a normal or bump map perturbed the frame (the ``active`` test and G apply).
    """

    s0: float
    s1: float
    s2: float
    t0: float
    t1: float
    t2: float
    n0: float
    n1: float
    n2: float
    u0: float
    u1: float
    u2: float
    alpha2: float
    differs: bool
    perturbed: bool


@njit(**JIT_BORROW)
def geometric_frame(hit):
    """The :class:`ShadingFrame` of a scene without shading normals: the hit's geometric frame, its flags constants
    (so that the side tests that read them fold away where the path loop inlines it)."""
    return ShadingFrame(hit.ss0, hit.ss1, hit.ss2, hit.st0, hit.st1, hit.st2, hit.sn0, hit.sn1, hit.sn2, hit.sn0,
                        hit.sn1, hit.sn2, -1.0, False, False)


@njit(**JIT_BORROW)
def shading_frame(scene, materials, hit, row, wo0, wo1, wo2, mutant):
    """The :class:`ShadingFrame` at ``hit`` (:class:`.surface.SurfaceHit`) of a material with parameters ``row`` (the
    material step's), seen from unit direction wo; ``mutant``: the planted-fault bits."""
    s0, s1, s2, t0, t1, t2 = hit.ss0, hit.ss1, hit.ss2, hit.st0, hit.st1, hit.st2
    n0, n1, n2 = hit.sn0, hit.sn1, hit.sn2
    smooth = False
    if scene.smooth.shape[0] > 0:  # a scene with vertex normals
        if scene.smooth[hit.tri]:
            smooth = True
            n0, n1, n2, s0, s1, s2, t0, t1, t2 = vertex_normal(scene, hit.tri, hit.u, hit.v, n0, n1, n2, mutant)
    if row[P_PERTURB] == PERTURB_NONE:
        return ShadingFrame(s0, s1, s2, t0, t1, t2, n0, n1, n2, n0, n1, n2, -1.0, smooth, False)
    return perturbed_frame(scene, materials, hit, row, n0, n1, n2, wo0, wo1, wo2, mutant)


@njit(**JIT_NONRT)
def vertex_normal(scene, tri, u, v, g0, g1, g2, mutant):
    """The shading normal at barycentrics (u, v) of triangle ``tri``, its corners' normals blended and normalised
    (where the blend is zero, between normals that turn to opposite sides, the geometric normal g), and tangents
    about it: (n, s, t). With the planted fault "normals-not-renormalised" n is the blend as it is (the tangents of
    its direction)."""
    c = scene.normals
    w = 1.0 - u - v
    b0 = w * c[tri, 0, 0] + u * c[tri, 1, 0] + v * c[tri, 2, 0]
    b1 = w * c[tri, 0, 1] + u * c[tri, 1, 1] + v * c[tri, 2, 1]
    b2 = w * c[tri, 0, 2] + u * c[tri, 1, 2] + v * c[tri, 2, 2]
    n0, n1, n2, ok = _normalize(b0, b1, b2)
    if not ok:
        n0, n1, n2, b0, b1, b2 = g0, g1, g2, g0, g1, g2
    s0, s1, s2, t0, t1, t2 = tangent_frame(n0, n1, n2)
    if mutant & M_NORMALS_UNNORMALISED:  # planted fault "normals-not-renormalised"
        return b0, b1, b2, s0, s1, s2, t0, t1, t2
    return n0, n1, n2, s0, s1, s2, t0, t1, t2


@njit(**JIT_BORROW)
def _normalize(x0, x1, x2):
    length = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if not length > 0:
        return 0.0, 0.0, 0.0, False
    inv = 1.0 / length
    return x0 * inv, x1 * inv, x2 * inv, True


@njit(**JIT_BORROW)
def position_derivatives(scene, tri):
    """(dp/du, dp/dv) of triangle ``tri`` from its corners and texture coordinates (Mitsuba's mesh.cpp; module
    docstring), and whether they exist (det != 0)."""
    p = scene.corners
    uv = scene.uv
    e10, e11, e12 = p[tri, 1, 0] - p[tri, 0, 0], p[tri, 1, 1] - p[tri, 0, 1], p[tri, 1, 2] - p[tri, 0, 2]
    e20, e21, e22 = p[tri, 2, 0] - p[tri, 0, 0], p[tri, 2, 1] - p[tri, 0, 1], p[tri, 2, 2] - p[tri, 0, 2]
    du1, dv1 = uv[tri, 1, 0] - uv[tri, 0, 0], uv[tri, 1, 1] - uv[tri, 0, 1]
    du2, dv2 = uv[tri, 2, 0] - uv[tri, 0, 0], uv[tri, 2, 1] - uv[tri, 0, 1]
    det = du1 * dv2 - dv1 * du2
    if det == 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False
    inv = 1.0 / det
    return ((dv2 * e10 - dv1 * e20) * inv, (dv2 * e11 - dv1 * e21) * inv, (dv2 * e12 - dv1 * e22) * inv,
            (-du2 * e10 + du1 * e20) * inv, (-du2 * e11 + du1 * e21) * inv, (-du2 * e12 + du1 * e22) * inv, True)


@njit(**JIT_BORROW)
def sphere_derivatives(scene, s, x0, x1, x2):
    """(dp/du, dp/dv) of sphere ``s`` at its point x, Mitsuba's (module docstring), and True. L = r^2 M^T for the
    linear part M of to_object (a rotation over r: its inverse is r^2 times its transpose)."""
    m = scene.sphere_to_object[s]
    p0 = m[0, 0] * x0 + m[0, 1] * x1 + m[0, 2] * x2 + m[0, 3]
    p1 = m[1, 0] * x0 + m[1, 1] * x1 + m[1, 2] * x2 + m[1, 3]
    p2 = m[2, 0] * x0 + m[2, 1] * x1 + m[2, 2] * x2 + m[2, 3]
    rho = math.sqrt(p0 * p0 + p1 * p1)
    a0, a1, a2 = -2.0 * math.pi * p1, 2.0 * math.pi * p0, 0.0
    if rho > 0.0:
        b0, b1, b2 = math.pi * p2 * p0 / rho, math.pi * p2 * p1 / rho, -math.pi * rho
    else:
        b0, b1, b2 = math.pi, 0.0, 0.0
    r2 = scene.sphere[s, 3] * scene.sphere[s, 3]
    return (r2 * (m[0, 0] * a0 + m[1, 0] * a1 + m[2, 0] * a2), r2 * (m[0, 1] * a0 + m[1, 1] * a1 + m[2, 1] * a2),
            r2 * (m[0, 2] * a0 + m[1, 2] * a1 + m[2, 2] * a2), r2 * (m[0, 0] * b0 + m[1, 0] * b1 + m[2, 0] * b2),
            r2 * (m[0, 1] * b0 + m[1, 1] * b1 + m[2, 1] * b2), r2 * (m[0, 2] * b0 + m[1, 2] * b1 + m[2, 2] * b2),
            True)


@njit(**JIT_NONRT)
def uv_aligned(scene, hit, frame):
    """``frame`` turned about its normal n so that its s follows the surface's dp/du, as Mitsuba's shading frame
    does (``SurfaceInteraction::initialize_sh_frame``: s = normalize(dp/du - n (n . dp/du)), t = n x s), for a BSDF
    that is not symmetric about n (an anisotropic principled); dp/du a sphere's analytic one or a triangle's from its
    texture coordinates (:func:`position_derivatives`); ``frame`` unchanged where there is none (a triangle without
    coordinates: Mitsuba's frame there is Duff et al.'s of the normal, this one's)."""
    if scene.sphere_of.shape[0] > 0 and scene.sphere_of[hit.tri] >= 0:
        du0, du1, du2, _dv0, _dv1, _dv2, ok = sphere_derivatives(scene, scene.sphere_of[hit.tri], hit.x0, hit.x1,
                                                                 hit.x2)
    elif scene.uv.shape[0] > 0:
        du0, du1, du2, _dv0, _dv1, _dv2, ok = position_derivatives(scene, hit.tri)
    else:
        return frame
    n0, n1, n2 = frame.n0, frame.n1, frame.n2
    proj = dot3(n0, n1, n2, du0, du1, du2)
    s0, s1, s2, ok_s = _normalize(du0 - n0 * proj, du1 - n1 * proj, du2 - n2 * proj)
    if not (ok and ok_s):
        return frame
    return ShadingFrame(s0, s1, s2, n1 * s2 - n2 * s1, n2 * s0 - n0 * s2, n0 * s1 - n1 * s0, n0, n1, n2, frame.u0,
                        frame.u1, frame.u2, frame.alpha2, frame.differs, frame.perturbed)


@njit(**JIT_NONRT)
def perturbed_frame(scene, materials, hit, row, n0, n1, n2, wo0, wo1, wo2, mutant):
    """:func:`shading_frame` where a normal or bump map perturbs the shading normal n (module docstring)."""
    if scene.sphere_of.shape[0] > 0 and scene.sphere_of[hit.tri] >= 0:
        du0, du1, du2, dv0, dv1, dv2, ok = sphere_derivatives(scene, scene.sphere_of[hit.tri], hit.x0, hit.x1, hit.x2)
    else:
        du0, du1, du2, dv0, dv1, dv2, ok = position_derivatives(scene, hit.tri)
    proj = dot3(n0, n1, n2, du0, du1, du2)
    s0, s1, s2, ok_s = _normalize(du0 - n0 * proj, du1 - n1 * proj, du2 - n2 * proj)
    if not (ok and ok_s):
        s0, s1, s2, _t0, _t1, _t2 = tangent_frame(n0, n1, n2)
    t0, t1, t2 = n1 * s2 - n2 * s1, n2 * s0 - n0 * s2, n0 * s1 - n1 * s0
    if row[P_PERTURB] == PERTURB_BUMPMAP:
        k = materials.texture[hit.material, _BUMP_SLOT]
        gu, gv = texture_grad_1(materials.textures, k, hit.tex_u, hit.tex_v, mutant)
        scale = 1.0 if mutant & M_BUMP_SCALE_IGNORED else row[P_BUMP_SCALE]  # planted fault "bumpmap-scale-ignored"
        gu, gv = gu * scale, gv * scale
        a = gu - dot3(n0, n1, n2, du0, du1, du2)
        b = gv - dot3(n0, n1, n2, dv0, dv1, dv2)
        pu0, pu1, pu2 = du0 + n0 * a, du1 + n1 * a, du2 + n2 * a
        pv0, pv1, pv2 = dv0 + n0 * b, dv1 + n1 * b, dv2 + n2 * b
        w0, w1, w2, ok_n = _normalize(pu1 * pv2 - pu2 * pv1, pu2 * pv0 - pu0 * pv2, pu0 * pv1 - pu1 * pv0)
        if not ok_n:
            w0, w1, w2 = n0, n1, n2
        if dot3(hit.n0, hit.n1, hit.n2, w0, w1, w2) < 0.0:  # the geometric normal's side
            w0, w1, w2 = -w0, -w1, -w2
        x, y, z = dot3(s0, s1, s2, w0, w1, w2), dot3(t0, t1, t2, w0, w1, w2), dot3(n0, n1, n2, w0, w1, w2)
    else:
        x, y, z = 2.0 * row[P_NORMAL] - 1.0, 2.0 * row[P_NORMAL + 1] - 1.0, 2.0 * row[P_NORMAL + 2] - 1.0
        if mutant & M_NORMALMAP_GREEN_INVERTED:  # planted fault "normalmap-green-inverted"
            y = -y
    if row[P_FLIP_INVALID] != 0.0:
        lz = dot3(n0, n1, n2, wo0, wo1, wo2)
        if lz * (dot3(s0, s1, s2, wo0, wo1, wo2) * x + dot3(t0, t1, t2, wo0, wo1, wo2) * y + lz * z) <= 0.0:
            x, y = -x, -y
    x, y, z, ok_p = _normalize(x, y, z)
    if not ok_p:
        x, y, z = 0.0, 0.0, 1.0
    # s' = normalize((1, 0, 0) - n' x'), t' = n' x s' (local)
    a0, a1, a2, ok_a = _normalize(1.0 - x * x, -y * x, -z * x)
    if not ok_a:  # n' along s_u
        a0, a1, a2 = 0.0, 1.0, 0.0
    b0, b1, b2 = y * a2 - z * a1, z * a0 - x * a2, x * a1 - y * a0
    alpha2 = -1.0
    if row[P_SHADOWING] != 0.0:
        tan2 = max(0.0, 1.0 - z * z) / (z * z) if z != 0.0 else math.inf
        alpha2 = min(0.125 * tan2, 1.0)
    return ShadingFrame(a0 * s0 + a1 * t0 + a2 * n0, a0 * s1 + a1 * t1 + a2 * n1, a0 * s2 + a1 * t2 + a2 * n2,
                        b0 * s0 + b1 * t0 + b2 * n0, b0 * s1 + b1 * t1 + b2 * n1, b0 * s2 + b1 * t2 + b2 * n2,
                        x * s0 + y * t0 + z * n0, x * s1 + y * t1 + z * n1, x * s2 + y * t2 + z * n2,
                        n0, n1, n2, alpha2, True, True)


@njit(**JIT_BORROW)
def through_map(frame, w0, w1, w2, cos_w):
    """What a direction w (unit, world; cos_w = n' . w) keeps through ``frame``'s map: 1 where nothing perturbs it,
    0 where (n_u . w)(n' . w) <= 0, else the shadow terminator G(w) (1 without it)."""
    if not frame.perturbed:
        return 1.0
    cu = dot3(frame.u0, frame.u1, frame.u2, w0, w1, w2)
    if not cu * cos_w > 0.0:
        return 0.0
    if frame.alpha2 < 0.0:
        return 1.0
    tan2 = max(0.0, 1.0 - cu * cu) / (cu * cu)
    return 2.0 / (1.0 + math.sqrt(1.0 + frame.alpha2 * tan2))


__all__ = ["ShadingFrame", "geometric_frame", "position_derivatives", "shading_frame", "sphere_derivatives",
           "through_map", "vertex_normal"]
