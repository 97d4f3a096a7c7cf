"""The direct-light estimator, one sample at a time (``integrator._direct_*``,
``_shadow_ray_estimate``, ``_mis_weight_*``): eq. 5.3 of the slides,

    <L_direct(x -> Theta)> = 1/Nd sum_i Le(y_i -> x) f_r G(x, y_i) V(x, y_i) / p(y_i),
    G(x, y) = cos(theta_x) cos(theta_y) / |x - y|^2                                     (Fig. 5.7, radianceTransfer)

with y drawn by one of three strategies (``Settings.direct``):

* area ("area", "mis"): light k with pdf(k), then y uniform on k, p(y) = pdf(k) / A_k (Fig. 5.8, 5.10);
* global area ("global-area"): y uniform over every surface, p(y) = 1 / A_scene; a y off the lights has Le = 0 and
  costs no ray (Fig. 5.13);
* hemisphere ("hemisphere-cosine", "-uniform"): a direction Psi from p(Psi), and Le of what the ray from x finds
  there, counted on an emitter's front side only: Le f_r cos(Psi, N_x) / p(Psi) (Fig. 5.12).

A point sample is computed as Le f_r s, s = (cos_x cos_y) / (|x - y|^2 p(y)) (one division). It needs no shadow ray
where y faces away from x, lies behind x's surface or is not on a light (all counted as skipped); the ray starts at
x's offset origin and stops short of y (:mod:`.surface`), and V = 1 where nothing blocks it. With "mis" (beyond the
slides) the sample is weighted by the power heuristic (Veach 1997) against the Ni indirect rays, which could have found
the same light: w = p_l^2 / (p_l^2 + p_h^2), p_l = Nd p(y) |x - y|^2 / cos_y (as a density of directions),
p_h = Ni p(Psi); the emission an indirect ray finds is weighted the other way round (:func:`.vertex.emitted`).

In a scene with emitters that are not surfaces (point, spot, directional lights, an environment), light k runs over
the area lights and then those emitters (:func:`light_sample_all`, whose emitter samples are
:func:`.emitters.emitter_sample`'s); a strategy that cannot find some of them (hemisphere sampling: delta lights;
global area sampling: delta lights and the environment) adds each one's own sample once per hit
(:func:`complement_sample`). Without such emitters the wavefront calls :func:`light_sample` and :func:`shadow_ray`:
numba compiles the other branch out.

The wavefront (Ni > 1) forms its samples with Lambert's f_r here (:func:`shadow_ray`, :func:`emitter_sample`); the
path loop (:mod:`.path`) takes the same samples as *connections* (the light door: :func:`light_connection`,
:func:`point_connection`, :func:`emitter_connection`, the section at the end) and reflects them through the BSDF
door (:func:`.path.connect`), with the power heuristic against the BSDF's own pdf (:func:`power_weight`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from reference_impl.emitters import DIRECTIONAL, ENV_CONSTANT, ENV_MAP, POINT, SPOT
from reference_impl.kernels.config import (DIRECT_GLOBAL_AREA, DIRECT_HEMI_COSINE, DIRECT_MIS, HEMI_COSINE, JIT,
                                           JIT_BORROW, JIT_NONRT, M_LIGHT_PDF_IGNORED, M_MIS_WEIGHTS_NOT_ONE,
                                           M_NO_COSINE, M_NO_RAY_OFFSET, M_SPHERE_CONE_PDF_AREA,
                                           M_SPHERE_POINTS_THETA, M_TREE_PMF_AT_HIT)
from reference_impl.kernels.emitters import (emitter_direction, emitter_sample, piece_within, split_light_piece_all,
                                             split_light_uniform_all)
from reference_impl.kernels.light_sampling import (drawn_by_cone, light_density, light_point, point_in_cone,
                                                   point_on_light, sample_light_point, sample_surface_point,
                                                   search_within, sphere_cone, split_light_uniform,
                                                   split_surface_uniform, toward_light_point)
from reference_impl.kernels.light_tree import pmf_of, select
from reference_impl.kernels.warps import sample_discrete
from reference_impl.kernels.rng import dim_salt, uniform
from reference_impl.kernels.sobol import pair_point, uniform_2d
from reference_impl.kernels.surface import emission_at, offset_origin, origin_offset, shadow_t_max
from reference_impl.kernels.warps import HALF_INV_PI, dot3, hemisphere_pdf, sample_hemisphere
from reference_impl.rng import (COMPLEMENT_U1, COMPLEMENT_U2, DIRECT_DIR_U1, DIRECT_DIR_U2, LIGHT_SELECT,
                                LIGHT_TRIANGLE, LIGHT_U1, LIGHT_U2)


@njit(**JIT_NONRT)
def planted_sphere_point(cfg, scene, tri, y0, y1, y2, u1, u2):
    """The light point y on triangle ``tri`` as drawn, or with the planted fault "sphere-points-uniform-theta" on a
    sphere's the point at z = cos(pi u1) (uniform in the polar angle, not in area), its pdf left as it was."""
    if not (cfg.mutant & M_SPHERE_POINTS_THETA and scene.sphere_of.shape[0] > 0 and scene.sphere_of[tri] >= 0):
        return y0, y1, y2
    sp = scene.sphere
    s = scene.sphere_of[tri]
    z = math.cos(math.pi * u1)
    rho = math.sqrt(max(0.0, 1.0 - z * z))
    return (sp[s, 0] + sp[s, 3] * rho * math.cos(2.0 * math.pi * u2),
            sp[s, 1] + sp[s, 3] * rho * math.sin(2.0 * math.pi * u2), sp[s, 2] + sp[s, 3] * z)


@njit(**JIT_BORROW)
def light_sample(cfg, sob, seeds, index, j, key, depth, scene, lights, surfaces):
    """Sample j of a hit's Nd point samples (``_direct_area_sample``, ``_direct_global_area_sample``), for the
    camera sample ``index`` of its pixel: (whether a light was chosen, the triangle of y, y, p(y) per unit area).
    The stratified sampler (``sob``) draws one 2D point of the pixel's set ``seeds`` and reuses its first coordinate
    for the discrete choices (lights.LightSampler.split_uniform); independent numbers need no reuse."""
    corners = scene.corners
    if sob:
        u_a, u_b = pair_point(seeds, index * cfg.shadow_rays + j)
    else:
        u_a, u_b = uniform(key, dim_salt(depth, LIGHT_U1, j)), uniform(key, dim_salt(depth, LIGHT_U2, j))
    if cfg.direct == DIRECT_GLOBAL_AREA:
        if sob:
            u_tri, u_a = split_surface_uniform(surfaces, u_a)
        else:
            u_tri = uniform(key, dim_salt(depth, LIGHT_TRIANGLE, j))
        tri, y0, y1, y2 = sample_surface_point(surfaces, corners, u_tri, u_a, u_b)
        return False, tri, y0, y1, y2, cfg.surface_pdf
    num_lights = cfg.num_lights
    if sob:
        u_select, u_tri, u_a = split_light_uniform(lights, num_lights, u_a)
    else:  # with one light there is nothing to choose (pdf(k) = 1) and nothing to draw
        u_select = uniform(key, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
        u_tri = uniform(key, dim_salt(depth, LIGHT_TRIANGLE, j))
    light, tri, y0, y1, y2 = sample_light_point(lights, num_lights, u_select, u_tri, u_a, u_b)
    if cfg.mutant:  # mutant "sphere-points-uniform-theta"
        y0, y1, y2 = planted_sphere_point(cfg, scene, tri, y0, y1, y2, u_a, u_b)
    light_pmf, light_area = lights.pmf, lights.area
    if cfg.mutant & M_LIGHT_PDF_IGNORED:  # mutant "light-pdf-ignored": pdf(y|k) alone
        return num_lights > 1, tri, y0, y1, y2, 1.0 / light_area[light]
    return num_lights > 1, tri, y0, y1, y2, light_pmf[light] / light_area[light]


@njit(**JIT_BORROW)
def light_sample_all(cfg, sob, seeds, index, j, key, depth, scene, lights, surfaces, emitters, x0, x1, x2, n0, n1,
                     n2, ox0, ox1, ox2, f0, f1, f2):
    """Sample j of a hit's Nd light samples in a scene with emitters that are not surfaces (:func:`light_sample`
    and :func:`shadow_ray` in one, over lights k < N_A, the area lights, and k >= N_A, the emitters, with
    :func:`.emitters.emitter_sample`): (whether a light was chosen, and :func:`shadow_ray`'s answer). The random
    numbers are those of :func:`light_sample`; an emitter's direction takes the uniforms a point on a triangle
    would have taken (with the stratified sampler, what is left of the first coordinate after the choice of k)."""
    if cfg.direct == DIRECT_GLOBAL_AREA:
        _sel, tri, y0, y1, y2, pdf_area = light_sample(cfg, sob, seeds, index, j, key, depth, scene, lights,
                                                       surfaces)
        needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = shadow_ray(cfg, scene, x0, x1, x2, n0, n1, n2, ox0,
                                                                         ox1, ox2, f0, f1, f2, tri, y0, y1, y2,
                                                                         pdf_area)
        return False, needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2
    cdf, light_pmf, light_area = lights.cdf, lights.pmf, lights.area
    num_lights = cfg.num_lights
    if sob:
        u_a, u_b = pair_point(seeds, index * cfg.shadow_rays + j)
        light, u_select, u_tri, u_a = split_light_uniform_all(lights, num_lights, cfg.num_area_lights, u_a)
        u_dir = u_tri
    else:
        u_a, u_b = uniform(key, dim_salt(depth, LIGHT_U1, j)), uniform(key, dim_salt(depth, LIGHT_U2, j))
        u_select = uniform(key, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
        u_tri = uniform(key, dim_salt(depth, LIGHT_TRIANGLE, j))
        light = sample_discrete(cdf, u_select) if num_lights > 1 else 0
        u_dir = u_a
    pdf_select = 1.0 if cfg.mutant & M_LIGHT_PDF_IGNORED else light_pmf[light]  # mutant "light-pdf-ignored"
    if light < cfg.num_area_lights:
        tri, y0, y1, y2 = light_point(lights, light, u_tri, u_a, u_b)
        if cfg.mutant:  # mutant "sphere-points-uniform-theta"
            y0, y1, y2 = planted_sphere_point(cfg, scene, tri, y0, y1, y2, u_a, u_b)
        needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = shadow_ray(cfg, scene, x0, x1, x2, n0, n1, n2, ox0,
                                                                         ox1, ox2, f0, f1, f2, tri, y0, y1, y2,
                                                                         pdf_select / light_area[light])
    else:
        needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = emitter_sample(
            cfg, emitters, light - cfg.num_area_lights, pdf_select, u_dir, u_b, x0, x1, x2, n0, n1, n2, ox0, ox1,
            ox2, f0, f1, f2)
    return num_lights > 1, needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2


@njit(**JIT_BORROW)
def complement_sample(cfg, emitters, e, key, depth, x0, x1, x2, n0, n1, n2, ox0, ox1, ox2, f0, f1, f2):
    """With a direct strategy that cannot find emitter e (hemisphere sampling cannot find a delta light, global area
    sampling neither a delta light nor an environment): e's own light sample, as if it were the only light
    (pdf(k) = 1), once per hit, added to the strategy's estimate. (whether e is such an emitter, and
    :func:`.emitters.emitter_sample`'s answer.) An environment's direction comes from its own uniforms."""
    kind = emitters.kind[e]
    if (kind == ENV_CONSTANT or kind == ENV_MAP) and cfg.direct != DIRECT_GLOBAL_AREA:  # hemisphere rays find it
        return False, False, x0, x1, x2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    u1 = uniform(key, dim_salt(depth, COMPLEMENT_U1, e))
    u2 = uniform(key, dim_salt(depth, COMPLEMENT_U2, e))
    needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2 = emitter_sample(cfg, emitters, e, 1.0, u1, u2, x0, x1, x2,
                                                                         n0, n1, n2, ox0, ox1, ox2, f0, f1, f2)
    return True, needed, so0, so1, so2, r0, r1, r2, tfar, v0, v1, v2


@njit(**JIT_BORROW)
def shadow_ray(cfg, scene, x0, x1, x2, n0, n1, n2, ox0, ox1, ox2, f0, f1, f2, ltri, y0, y1, y2, pdf_area):
    """The shadow ray of a point sample y on triangle ``ltri`` (p(y) per unit area ``pdf_area``) seen from x (normal
    N_x, offset origin ox, f_r = f), and what it carries where nothing blocks it (``_shadow_ray_estimate``,
    ``_mis_weight_light``): (whether the sample needs a ray at all, the ray's origin, unit direction and t_max,
    Le f_r G / p(y) with its MIS weight)."""
    emission, light_id = scene.emission, scene.light_id
    wi0, wi1, wi2, dist2, cos_y = toward_light_point(scene, ltri, y0, y1, y2, x0, x1, x2)
    cos_x = dot3(n0, n1, n2, wi0, wi1, wi2)
    if not (cos_x > 0 and cos_y > 0 and light_id[ltri] >= 0 and dist2 > 0):
        return False, x0, x1, x2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    if cfg.mutant & M_NO_RAY_OFFSET:  # mutant "no-ray-offset"
        so0, so1, so2 = x0, x1, x2
    else:
        so0, so1, so2 = ox0, ox1, ox2
    g0, g1, g2 = y0 - so0, y1 - so1, y2 - so2
    seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
    t_max = shadow_t_max(seg_len, origin_offset(cfg.offset_scene, y0, y1, y2), cos_y)
    inv_seg = 1.0 / seg_len
    cos_at_x = 1.0 if cfg.mutant & M_NO_COSINE else cos_x  # mutant "no-cosine" (direct light)
    scale = (cos_at_x * cos_y) / (dist2 * pdf_area)  # G(x, y) V / p(y), for V = 1 (one division)
    v0 = emission[ltri, 0] * f0 * scale
    v1 = emission[ltri, 1] * f1 * scale
    v2 = emission[ltri, 2] * f2 * scale
    if cfg.direct == DIRECT_MIS:  # _mis_weight_light
        p_light = cfg.shadow_rays * pdf_area * dist2 / cos_y
        p_hemi = cfg.indirect_rays * hemisphere_pdf(cfg.hemisphere == HEMI_COSINE, cos_x)
        w = p_light * p_light / (p_light * p_light + p_hemi * p_hemi)
        v0, v1, v2 = v0 * w, v1 * w, v2 * w
    return True, so0, so1, so2, g0 * inv_seg, g1 * inv_seg, g2 * inv_seg, max(t_max, 0.0), v0, v1, v2


@njit(**JIT_BORROW)
def hemisphere_sample(cfg, sob, seeds, index, j, key, depth, n0, n1, n2):
    """Sample j of a hit's Nd direction samples (``_direct_hemisphere_sample``), for the camera sample ``index`` of
    its pixel: the direction Psi, and cos(Psi, N_x) / p(Psi), or -1 where p(Psi) = 0 (nothing to count)."""
    u_a, u_b = uniform_2d(sob, seeds, index * cfg.shadow_rays + j, key, j, depth, DIRECT_DIR_U1, DIRECT_DIR_U2)
    w0, w1, w2, cos_theta, pdf = sample_hemisphere(cfg.direct == DIRECT_HEMI_COSINE, u_a, u_b, n0, n1, n2)
    return w0, w1, w2, cos_theta / pdf if pdf > 0 else -1.0


@njit(**JIT)
def hemisphere_weight(ratio, w0, w1, w2, m0, m1, m2):
    """What the emission found by a direction sample Psi (``ratio`` cos / p from :func:`hemisphere_sample`) is
    multiplied by, besides f_r, where the ray hit a triangle of normal m: the ratio on the emitter's front side
    (Psi . m < 0), else 0."""
    faces_x = dot3(w0, w1, w2, m0, m1, m2) < 0
    return ratio * (1.0 if faces_x else 0.0)


# ----------------------------------------------------------------- the path loop's connections (kernels/path.py)
class Connection(NamedTuple):
    """A light sample seen from x, before x's BSDF and the shadow ray. The loop multiplies ``v`` by the BSDF door's
    f |cos_x| (:func:`.path.connect`) and traces :func:`connection_ray`."""

    needed: bool  # whether it can bring light at all
    wi0: float  # the unit direction wi from x
    wi1: float
    wi2: float
    v0: float  # Le G / (p cos_x) per channel: what it carries without f |cos_x|
    v1: float
    v2: float
    p_l: float  # the light samples' solid-angle density of wi, Nd included; 0 for delta lights
    inf_ray: bool  # whether the shadow ray is infinite (a directional light, an environment)
    y0: float  # the point y it ends at
    y1: float
    y2: float
    cos_y: float  # at y (1 for an emitter that is not a surface)
    on_surface: bool  # whether y is on a triangle, whose own offset the shadow ray stops short of


@njit(**JIT_BORROW)
def no_connection():
    """The :class:`Connection` that brings nothing."""
    return Connection(False, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, False, 0.0, 0.0, 0.0, 1.0, False)


@njit(**JIT_BORROW)
def power_weight(mutant, p_self, p_other, light_side):
    """The power heuristic's weight p_self^2 / (p_self^2 + p_other^2) (Veach 1997, ch. 9); with the planted fault
    "mis-weights-not-one", the light samples' (``light_side``) is the balance heuristic's p_self / (p_self + p_other)."""
    if light_side and mutant & M_MIS_WEIGHTS_NOT_ONE:  # mutant "mis-weights-not-one"
        return p_self / (p_self + p_other)
    return p_self * p_self / (p_self * p_self + p_other * p_other)


@njit(**JIT_BORROW)
def light_piece(cfg, lights, light, u_tri):
    """The piece (a row of the light tables) of area light k = ``light`` that u_tri picks within k's cdf; -1 for
    an emitter that is not a surface."""
    if light >= cfg.num_area_lights:
        return -1
    f = lights.first[light]
    return f + search_within(lights.within_cdf, f, lights.count[light], u_tri)


@njit(**JIT_BORROW)
def light_choice(cfg, lights, sob, u_a, u_b, key, depth, j):
    """Light sample j's choices at vertex ``depth`` of the path with ``key`` (area sampling, without a light tree):
    (light k, its piece, u1, u2). With the stratified sampler (``sob``) one 2D point (u_a, u_b) of the pixel's set:
    its first coordinate picks k and the piece and what is left of it is u1 (:func:`.emitters.split_light_piece_all`);
    else four independent numbers (with one light, none for k: pdf(k) = 1)."""
    num_lights = cfg.num_lights
    if sob:
        sel, piece, u1 = split_light_piece_all(lights, num_lights, cfg.num_area_lights, u_a)
        return sel, piece, u1, u_b
    u_sel = uniform(key, dim_salt(depth, LIGHT_SELECT, j)) if num_lights > 1 else 0.0
    u_tri = uniform(key, dim_salt(depth, LIGHT_TRIANGLE, j))
    u1 = uniform(key, dim_salt(depth, LIGHT_U1, j))
    u2 = uniform(key, dim_salt(depth, LIGHT_U2, j))
    sel = sample_discrete(lights.cdf, u_sel) if num_lights > 1 else 0
    return sel, light_piece(cfg, lights, sel, u_tri), u1, u2


@njit(**JIT_BORROW)
def tree_choice(cfg, lights, tree, sob, u_a, u_b, key, depth, j, x0, x1, x2, n0, n1, n2, mutant):
    """Light sample j's choices at vertex x (normal N) of the path with ``key``, drawn from the light tree
    (:func:`.light_tree.select`, pdf(k | x)): (light k, pdf(k | x), its piece, u1, u2); k < 0 where nothing in the
    tree can light x. With the stratified sampler (``sob``) one 2D point (u_a, u_b) of the pixel's set: its first
    coordinate walks the tree and what is left of it picks the piece and is u1 (:func:`.emitters.piece_within`);
    else four independent numbers."""
    if sob:
        sel, pmf_k, u_rest = select(tree, cfg.num_area_lights, cfg.num_lights, u_a, x0, x1, x2, n0, n1, n2, mutant)
        piece, u1 = piece_within(lights, cfg.num_area_lights, sel, u_rest)
        return sel, pmf_k, piece, u1, u_b
    u_sel = uniform(key, dim_salt(depth, LIGHT_SELECT, j))
    u_tri = uniform(key, dim_salt(depth, LIGHT_TRIANGLE, j))
    u1 = uniform(key, dim_salt(depth, LIGHT_U1, j))
    u2 = uniform(key, dim_salt(depth, LIGHT_U2, j))
    sel, pmf_k, _rest = select(tree, cfg.num_area_lights, cfg.num_lights, u_sel, x0, x1, x2, n0, n1, n2, mutant)
    return sel, pmf_k, light_piece(cfg, lights, sel, u_tri), u1, u2


@njit(**JIT_BORROW)
def emission_weight(lights, tree, light, nd, prev_pdf, px, qn, hit, t, cos_out, mutant):
    """MIS weight (power heuristic) of area light ``light``'s emission met at ``hit`` (distance t, cos_out = cos at
    the light) by a BSDF ray of solid-angle pdf ``prev_pdf`` from the vertex ``px`` (normal ``qn``): against the Nd
    light samples' density of the same direction there (:func:`.light_sampling.light_density`, pdf(k) the light's
    pmf or the light tree's pdf(k | px), with the planted fault "light-tree-pmf-at-hit" the tree's at the hit)."""
    if tree is None:
        pmf_k = lights.pmf[light]
    else:
        tx0, tx1, tx2 = px
        tn0, tn1, tn2 = qn
        if mutant & M_TREE_PMF_AT_HIT:  # mutant "light-tree-pmf-at-hit": at the light's point
            tx0, tx1, tx2, tn0, tn1, tn2 = hit.x0, hit.x1, hit.x2, hit.n0, hit.n1, hit.n2
        pmf_k = pmf_of(tree, light, tx0, tx1, tx2, tn0, tn1, tn2, mutant)
    p_light = light_density(lights, light, nd, pmf_k, px[0], px[1], px[2], t, cos_out, mutant)
    return power_weight(mutant, prev_pdf, p_light, False)


@njit(**JIT_BORROW)
def point_connection(cfg, scene, textures, tri, y0, y1, y2, pdf_area, x0, x1, x2):
    """The connection (above) of a point y on triangle ``tri`` drawn with density ``pdf_area`` per unit area
    (area sampling: pdf(k) / A_k; global area sampling: 1 / A_scene): Le(y) G / (p(y) cos_x) = Le(y) cos_y /
    (r^2 p(y)), p_l = Nd p(y) r^2 / cos_y (Le(y) a texture's value at y on a textured light: ``textures``, the
    materials' :class:`.records.TextureTables`). None where y is not on an emitter, faces away from x or sits at
    x."""
    wi0, wi1, wi2, dist2, cos_y = toward_light_point(scene, tri, y0, y1, y2, x0, x1, x2)
    if not (dist2 > 0 and cos_y > 0 and scene.light_id[tri] >= 0):
        return no_connection()
    e0, e1, e2 = emission_at(scene, textures, tri, y0, y1, y2, cfg.mutant)
    scale = cos_y / (dist2 * pdf_area)
    p_l = cfg.shadow_rays * pdf_area * dist2 / cos_y
    return Connection(True, wi0, wi1, wi2, e0 * scale, e1 * scale, e2 * scale, p_l, False, y0, y1, y2, cos_y, True)


@njit(**JIT_BORROW)
def cone_connection(cfg, scene, textures, tri, y0, y1, y2, pdf_select, p_cone, x0, x1, x2):
    """The connection (above) of a point y of a sphere light (its first triangle ``tri``) drawn from x by the cone
    the sphere subtends (:func:`.light_sampling.point_in_cone`, density ``p_cone`` per unit solid angle), the light
    chosen with ``pdf_select``: Le(y) / (pdf(k) p(w)), p_l = Nd pdf(k) p(w). None where y does not face x (a point
    on the cap's rim, by rounding)."""
    wi0, wi1, wi2, dist2, cos_y = toward_light_point(scene, tri, y0, y1, y2, x0, x1, x2)
    if not (dist2 > 0 and cos_y > 0):
        return no_connection()
    e0, e1, e2 = emission_at(scene, textures, tri, y0, y1, y2, cfg.mutant)
    p = pdf_select * p_cone
    scale = 1.0 / p
    return Connection(True, wi0, wi1, wi2, e0 * scale, e1 * scale, e2 * scale, cfg.shadow_rays * p, False, y0, y1,
                      y2, cos_y, True)


@njit(**JIT_BORROW)
def emitter_connection(cfg, emitters, e, pdf_select, u1, u2, x0, x1, x2, n0, n1, n2, front_only):
    """The connection (above) of emitter e, which is not a surface, chosen with ``pdf_select``, from the light door
    (:func:`.emitters.emitter_direction`; ``front_only``: only directions above N): Le s / (r^2 pdf(k)) for a point
    or spot light, E / pdf(k) for a directional one, L(w) / (pdf(k) p(w)) with p_l = Nd pdf(k) p(w) for an
    environment."""
    ok, k, wi0, wi1, wi2, dist2, falloff, pdf, le0, le1, le2, p0, p1, p2 = emitter_direction(
        cfg, emitters, e, u1, u2, x0, x1, x2, n0, n1, n2, front_only)
    if not ok:
        return no_connection()
    if k == POINT or k == SPOT:
        scale = falloff / (dist2 * pdf_select)
        return Connection(True, wi0, wi1, wi2, le0 * scale, le1 * scale, le2 * scale, 0.0, False, p0, p1, p2, 1.0,
                          False)
    if k == DIRECTIONAL:
        scale = 1.0 / pdf_select
        return Connection(True, wi0, wi1, wi2, le0 * scale, le1 * scale, le2 * scale, 0.0, True, 0.0, 0.0, 0.0, 1.0,
                          False)
    scale = 1.0 / (pdf_select * pdf)
    return Connection(True, wi0, wi1, wi2, le0 * scale, le1 * scale, le2 * scale, cfg.shadow_rays * pdf_select * pdf,
                      True, 0.0, 0.0, 0.0, 1.0, False)


@njit(**JIT_BORROW)
def area_light_point(cfg, scene, lights, light, piece, pdf_select, u1, u2):
    """A point y of area light k = ``light`` (chosen with ``pdf_select``) drawn by area: on k's ``piece``
    (:func:`light_piece`) from (u1, u2), with the planted fault "sphere-points-uniform-theta" on a sphere as that
    fault draws it: (the triangle y lies in, y, p(y) = pdf(k) / A_k). It depends on nothing at x, so a block of paths
    can draw its points before it knows its hits (:mod:`.blocks`)."""
    tri, y0, y1, y2 = point_on_light(lights, piece, u1, u2)
    if cfg.mutant:  # mutant "sphere-points-uniform-theta"
        y0, y1, y2 = planted_sphere_point(cfg, scene, tri, y0, y1, y2, u1, u2)
    return tri, y0, y1, y2, pdf_select / lights.area[light]


@njit(**JIT_BORROW)
def light_connection(cfg, scene, textures, lights, emitters, light, piece, pdf_select, u1, u2, x0, x1, x2, n0, n1,
                     n2, front_only):
    """The connection (above) of light k = ``light`` (chosen with ``pdf_select``): a point on area light k's
    ``piece`` (:func:`light_piece`) from (u1, u2), or emitter k - N_A's own sample (:func:`emitter_connection`). A
    sphere light seen from outside (``lights.cone``) gives a point of the cone it subtends from x
    (:func:`cone_connection`); with the planted fault "sphere-cone-pdf-area" weighed with the area density pdf(k) / A_k
    instead, and with "sphere-points-uniform-theta" (a fault of the area sampler) drawn by area."""
    if light < cfg.num_area_lights:
        if drawn_by_cone(lights, light, cfg.mutant):
            c0, c1, c2, r = lights.cone[light, 0], lights.cone[light, 1], lights.cone[light, 2], lights.cone[light, 3]
            d2, s2, one_minus = sphere_cone(c0, c1, c2, r, x0, x1, x2)
            if one_minus > 0.0:
                tri = lights.triangles[piece]
                y0, y1, y2 = point_in_cone(c0, c1, c2, r, x0, x1, x2, d2, s2, one_minus, u1, u2)
                if cfg.mutant & M_SPHERE_CONE_PDF_AREA:  # mutant "sphere-cone-pdf-area"
                    return point_connection(cfg, scene, textures, tri, y0, y1, y2, pdf_select / lights.area[light],
                                            x0, x1, x2)
                return cone_connection(cfg, scene, textures, tri, y0, y1, y2, pdf_select, HALF_INV_PI / one_minus,
                                       x0, x1, x2)
        tri, y0, y1, y2, pdf_area = area_light_point(cfg, scene, lights, light, piece, pdf_select, u1, u2)
        return point_connection(cfg, scene, textures, tri, y0, y1, y2, pdf_area, x0, x1, x2)
    if emitters is not None:
        return emitter_connection(cfg, emitters, light - cfg.num_area_lights, pdf_select, u1, u2, x0, x1, x2, n0,
                                  n1, n2, front_only)
    return no_connection()


@njit(**JIT_BORROW)
def connection_ray(cfg, conn, cos_x, transmits, x0, x1, x2, n0, n1, n2, ox0, ox1, ox2):
    """The shadow ray of connection ``conn`` (:class:`Connection`) from x (front normal N, ``cos_x`` = N . wi):
    (origin, unit direction, t_max). It leaves from x's offset origin ``ox`` on the side x reflects from, or for a
    surface that transmits (``transmits``) on the side of wi; with the planted fault "no-ray-offset" from x itself.
    It stops short of y (:func:`.surface.shadow_t_max`, y's own offset where y is on a triangle), or is infinite
    toward a directional light or an environment."""
    if cfg.mutant & M_NO_RAY_OFFSET:  # mutant "no-ray-offset"
        so0, so1, so2 = x0, x1, x2
    elif transmits:
        side = 1.0 if cos_x > 0 else -1.0
        so0, so1, so2 = offset_origin(cfg.offset_scene, x0, x1, x2, side * n0, side * n1, side * n2)
    else:
        so0, so1, so2 = ox0, ox1, ox2
    if conn.inf_ray:
        return so0, so1, so2, conn.wi0, conn.wi1, conn.wi2, np.inf
    g0, g1, g2 = conn.y0 - so0, conn.y1 - so1, conn.y2 - so2
    seg_len = math.sqrt(dot3(g0, g1, g2, g0, g1, g2))
    inv_seg = 1.0 / seg_len
    y_offset = origin_offset(cfg.offset_scene, conn.y0, conn.y1, conn.y2) if conn.on_surface else 0.0
    return (so0, so1, so2, g0 * inv_seg, g1 * inv_seg, g2 * inv_seg,
            max(shadow_t_max(seg_len, y_offset, conn.cos_y), 0.0))
