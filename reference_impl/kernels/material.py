"""The material step: between a hit and its BSDF, what the surface's material is at that hit (pbrt-v4's
``Material::GetBxDF``, which evaluates a material's textures at the hit and returns the BSDF they make).

    (kind, params)(hit) = (kind_m, row_m),   m = hit.material

The step hands on material m's kind and its row of :class:`reference_impl.Materials` (the columns are the ``P_*`` of
:mod:`reference_impl.materials`), with the columns a texture drives (``Materials.texture``, the slots of
:data:`reference_impl.materials.TEXTURE_SLOTS`) replaced by the texture's value at the hit's texture coordinates
(:class:`.surface.SurfaceHit`'s ``tex_u``, ``tex_v``; :func:`.texture.texture_eval`); the BSDF (:mod:`.bsdf`) reads
its parameters only from the row this step writes.

The row is written into the caller's room for it (``params``, NUM_PARAMS float64 -- ROW_SIZE where a rough plastic
may be hit: its table follows the row --, one per engine call, reused at every hit): a step that alters it needs no
other buffer, and a hit costs no allocation, no reference count and no registers held across the vertex.

A material made of others (:data:`reference_impl.materials.COMPOSITES`) is resolved here to one of them, as
pbrt-v4's ``MixMaterial`` is (``ChooseMaterial``, src/pbrt/materials.h): a ``blendbsdf`` of weight w is its second
material with probability w and its first with 1 - w (one uniform u per hit: u <= w picks the second, then u / w is
used again below it, else (u - w) / (1 - w): Mitsuba's ``blendbsdf::sample`` order), which makes the vertex's
expected f (1 - w) f_0 + w f_1, Mitsuba's ``eval``; the BSDF sample, the light samples and their MIS weights are then
all the chosen material's, so each stays consistent with its own pdf. A ``twosided`` of two materials is its front
one where wo is on the front of the geometric normal, else its back one seen mirrored (the row's ``two_sided``
flag, Mitsuba's flip of both directions). A ``mask`` is its nested material here; its holes are met where the ray
meets the shape (kernels/path.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from reference_impl.kernels.config import JIT_BORROW, JIT_NONRT
from reference_impl.kernels.texture import texture_eval, texture_eval_1
from reference_impl.materials import (BLENDBSDF, LUT_SIZE, MASK, NUM_PARAMS, NUM_SLOTS, P_LUT, P_NESTED, P_TWO_SIDED,
                                      P_WEIGHT, ROUGHPLASTIC, ROW_SIZE, TEXTURE_SLOTS, TWOSIDED)

_SLOT_COLUMN = tuple(column for column, _ in TEXTURE_SLOTS.values())
_SLOT_CHANNELS = tuple(channels for _, channels in TEXTURE_SLOTS.values())


@njit(**JIT_BORROW)
def material_params(materials, m, params):
    """Material ``m`` of ``materials`` (:class:`.records.MaterialTables`): its row of parameters, unchanged, written
    into ``params``; returns its kind. A rough plastic's table (``materials.lut``) follows, in columns
    ``P_LUT ..`` of a buffer of ``ROW_SIZE`` (a shorter buffer, an engine's that runs Lambertian scenes, gets none)."""
    table = materials.params
    for c in range(NUM_PARAMS):
        params[c] = table[m, c]
    kind = materials.kind[m]
    if kind == ROUGHPLASTIC and params.shape[0] >= ROW_SIZE:
        lut = materials.lut
        for c in range(LUT_SIZE):
            params[P_LUT + c] = lut[m, c]
    return kind


@njit(**JIT_BORROW)
def material_at(materials, hit, params, mutant):
    """The material step at ``hit`` (:class:`.surface.SurfaceHit`): the parameters of its material at the hit,
    written into ``params`` (NUM_PARAMS float64, the ``P_*`` columns), and its kind (returned), which the BSDF
    (:mod:`.bsdf`) evaluates and samples: material ``hit.material``'s row, each textured slot replaced by its
    texture's value at (``hit.tex_u``, ``hit.tex_v``) (a one-channel slot, ``alpha``, its one number,
    :func:`.texture.texture_eval_1`; a normal map's its raw RGB; a bump map's height none: the shading frame,
    :mod:`.shading`, takes its gradient). ``mutant``: the render's planted-fault bits (the textures' are in
    :func:`.texture.texture_eval`)."""
    m = hit.material
    kind = material_params(materials, m, params)
    if materials.texture.shape[0] > 0:  # a scene with textures
        textured_params(materials, m, hit.tex_u, hit.tex_v, params, mutant)
    return kind


@njit(**JIT_NONRT)
def textured_params(materials, m, tex_u, tex_v, params, mutant):
    """Each textured slot of material ``m``'s row ``params`` replaced by its texture's value at (tex_u, tex_v)
    (called, not inlined: a scene without textures never comes here)."""
    slots = materials.texture
    for s in range(NUM_SLOTS):
        k = slots[m, s]
        if k >= 0:
            c = _SLOT_COLUMN[s]
            if _SLOT_CHANNELS[s] == 3:
                params[c], params[c + 1], params[c + 2] = texture_eval(materials.textures, k, tex_u, tex_v, mutant)
            elif _SLOT_CHANNELS[s] == 1:
                params[c] = texture_eval_1(materials.textures, k, tex_u, tex_v, mutant)
            # (0 channels: a bump map's height, whose gradient the shading frame looks up, kernels/shading.py)


_WEIGHT_SLOT = list(TEXTURE_SLOTS).index("weight")
MAX_NESTING = 16  # composites within composites: a deeper chain stops at its 16th (the table refuses cycles)


@njit(**JIT_BORROW)
def composite_weight(materials, m, tex_u, tex_v, mutant):
    """A blendbsdf's weight or a mask's opacity at (tex_u, tex_v): its texture's one number where one drives it, else
    the row's, clipped to [0, 1] (Mitsuba's ``eval_weight`` / ``eval_opacity``)."""
    w = materials.params[m, P_WEIGHT]
    if materials.texture.shape[0] > 0:
        k = materials.texture[m, _WEIGHT_SLOT]
        if k >= 0:
            w = texture_eval_1(materials.textures, k, tex_u, tex_v, mutant)
    return min(max(w, 0.0), 1.0)



@njit(**JIT_BORROW)
def resolve_nested(materials, m, front, tex_u, tex_v, u, mutant):
    """The material that is not a composite which material ``m`` is at a hit (``front``: wo on the front of the
    geometric normal; ``u``: the hit's uniform for the blends): (row, mirrored), mirrored where a twosided's back
    material was taken (module docstring)."""
    mirrored = False
    for _ in range(MAX_NESTING):
        kind = materials.kind[m]
        if kind == BLENDBSDF:
            w = composite_weight(materials, m, tex_u, tex_v, mutant)
            if u <= w and w > 0.0:
                u = u / w
                m = np.int64(materials.params[m, P_NESTED + 1])
            else:
                u = (u - w) / (1.0 - w)
                m = np.int64(materials.params[m, P_NESTED])
        elif kind == TWOSIDED:
            mirrored = True
            m = np.int64(materials.params[m, P_NESTED] if front else materials.params[m, P_NESTED + 1])
        elif kind == MASK:
            m = np.int64(materials.params[m, P_NESTED])
        else:
            break
    return m, mirrored


@njit(**JIT_BORROW)
def material_at_nested(materials, hit, params, mutant, u):
    """:func:`material_at` for a table with composites: material ``hit.material`` resolved (:func:`resolve_nested`,
    ``u`` the hit's uniform), then the step at the material it resolved to; a twosided's row marked two-sided."""
    m, mirrored = resolve_nested(materials, hit.material, hit.cos_out > 0, hit.tex_u, hit.tex_v, u, mutant)
    kind = material_params(materials, m, params)
    if materials.texture.shape[0] > 0:
        textured_params(materials, m, hit.tex_u, hit.tex_v, params, mutant)
    if mirrored:
        params[P_TWO_SIDED] = 1.0
    return kind
