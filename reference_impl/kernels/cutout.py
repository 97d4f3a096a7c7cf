r"""Cut-outs: Mitsuba's ``mask`` (src/bsdfs/mask.cpp) met by a path and by a shadow ray.

A mask of opacity a (a number or a texture's one number at the hit, clipped to [0, 1]) is its nested material with
probability a and a hole with 1 - a: Mitsuba's ``mask`` BSDF, f = a f_nested, with a delta "null" lobe that passes
the ray on unchanged, of probability 1 - a and weight 1.

* **A path** (:func:`through_holes`) decides at each mask it meets, with one uniform per mask
  (``MASK_PASS``, index j = how many masks the ray has met), u < a: the surface (its nested material, weight
  a / a = 1); else on through the hole, along the same ray from the far side, with weight (1 - a) / (1 - a) = 1. A
  hole is no vertex: the path's depth, its last BSDF pdf and its last vertex (whose light pdf the MIS weight of an
  emitter found beyond uses, at the whole distance travelled) are those before the hole. (Mitsuba counts the null
  lobe as a bounce of max_depth; the expected image is the same where max_depth does not cut a path short, so the
  canonical scenes of cut-outs leave it at -1.)
* **A shadow ray** (:func:`shadow_transmittance`) is not stopped by a mask but multiplied by 1 - a at each one it
  crosses (pbrt-v4's alpha-tested shadow rays do the same with a stochastic test; here exactly), so next-event
  estimation sees the light through the holes that BSDF sampling reaches: the MIS weights of both sum to one for
  every path. (Mitsuba's ``path`` stops its shadow rays at any shape and reaches the same light by the null lobe
  alone, weighted 1 as a delta: the same expected image, noisier.) With the planted fault
  "mask-opacity-1-in-shadow-rays" a mask stops the shadow ray, while the paths still weigh their emission by MIS
  as if next-event estimation had seen it: the light through the holes is lost in part.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import JIT_NONRT, M_MASK_OPAQUE_TO_SHADOWS
from reference_impl.kernels.material import composite_weight
from reference_impl.kernels.queries import closest_prim_timed, closest_prim_within_timed
from reference_impl.kernels.rng import dim_salt, uniform
from reference_impl.kernels.surface import offset_origin, surface_hit
from reference_impl.materials import MASK
from reference_impl.rng import MASK_PASS

MAX_HOLES = 1024  # masks one ray passes at most; past them it stops at the next one's surface


@njit(**JIT_NONRT)
def _beyond(cfg, hit, d0, d1, d2):
    """Where a ray through the hole at ``hit`` goes on: hit's point offset to the far side along its normal."""
    side = 1.0 if d0 * hit.n0 + d1 * hit.n1 + d2 * hit.n2 > 0.0 else -1.0
    return offset_origin(cfg.offset_scene, hit.x0, hit.x1, hit.x2, side * hit.n0, side * hit.n1, side * hit.n2)


@njit(**JIT_NONRT)
def through_holes(cfg, scene_ptr, words, floats, ts, queries, sampled_ns, scene, materials, spheres, base, p, key,
                  depth, o0, o1, o2, d0, d1, d2):
    """The hit a path's ray (origin o, direction d, first hit primitive ``p`` >= 0) stops at: at each mask it meets,
    the surface with probability a, else on through the hole (module docstring). Returns (primitive or -1, the
    origin of the last query, the distance travelled to it, queries, sampled_ns)."""
    travelled = 0.0
    for j in range(MAX_HOLES):
        m = scene.material[scene.prim_to_tri[p]]
        if materials.kind[m] != MASK:
            break
        hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
        if uniform(key, dim_salt(depth, MASK_PASS, j)) < composite_weight(materials, m, hit.tex_u, hit.tex_v,
                                                                          cfg.mutant):
            break
        n0, n1, n2 = _beyond(cfg, hit, d0, d1, d2)
        travelled += (n0 - o0) * d0 + (n1 - o1) * d1 + (n2 - o2) * d2
        o0, o1, o2 = n0, n1, n2
        p, queries, sampled_ns = closest_prim_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1, o2,
                                                    d0, d1, d2, spheres, base)
        if p < 0:
            break
    return p, o0, o1, o2, travelled, queries, sampled_ns


@njit(**JIT_NONRT)
def shadow_transmittance(cfg, scene_ptr, words, floats, ts, queries, sampled_ns, scene, materials, spheres, base,
                         ray):
    """The fraction of light a shadow ray (origin, unit direction, t_max: :func:`.direct.connection_ray`) carries
    past the masks it crosses, prod (1 - a_j); 0 where any other surface stops it (module docstring). Returns
    (transmittance, queries, sampled_ns)."""
    o0, o1, o2, d0, d1, d2, tfar = ray
    tr = 1.0
    if scene_ptr == 0:
        return tr, queries, sampled_ns
    for _ in range(MAX_HOLES):
        p, queries, sampled_ns = closest_prim_within_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1,
                                                           o2, d0, d1, d2, np.float32(tfar), spheres, base)
        if p < 0:
            return tr, queries, sampled_ns
        m = scene.material[scene.prim_to_tri[p]]
        if materials.kind[m] != MASK or (cfg.mutant & M_MASK_OPAQUE_TO_SHADOWS):  # mutant "mask-opacity-1-in-..."
            return 0.0, queries, sampled_ns
        hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
        tr *= 1.0 - composite_weight(materials, m, hit.tex_u, hit.tex_v, cfg.mutant)
        if tr == 0.0:
            return 0.0, queries, sampled_ns
        n0, n1, n2 = _beyond(cfg, hit, d0, d1, d2)
        if not math.isinf(tfar):
            tfar -= (n0 - o0) * d0 + (n1 - o1) * d1 + (n2 - o2) * d2
        o0, o1, o2 = n0, n1, n2
    return 0.0, queries, sampled_ns
