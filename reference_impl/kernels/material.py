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
"""

from __future__ import annotations

from numba import njit

from reference_impl.kernels.config import JIT_BORROW, JIT_NONRT
from reference_impl.kernels.texture import texture_eval, texture_eval_1
from reference_impl.materials import LUT_SIZE, NUM_PARAMS, NUM_SLOTS, P_LUT, ROUGHPLASTIC, ROW_SIZE, TEXTURE_SLOTS

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
