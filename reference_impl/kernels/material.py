"""The material step: between a hit and its BSDF, what the surface's material is at that hit (pbrt-v4's
``Material::GetBxDF``, which evaluates a material's textures at the hit and returns the BSDF they make).

    (kind, params)(hit) = (kind_m, row_m),   m = hit.material

Every parameter is constant over a surface today, so the step hands on material m's kind and its row of
:class:`reference_impl.Materials` unchanged (the columns are the ``P_*`` of :mod:`reference_impl.materials`). A
texture will be looked up here, at the hit's texture coordinates (:class:`.surface.SurfaceHit`'s ``tex_u``,
``tex_v``), and replace the columns it drives; the BSDF (:mod:`.bsdf`) reads its parameters only from the row this
step writes.

The row is written into the caller's room for it (``params``, NUM_PARAMS float64, one per engine call, reused at
every hit): a step that alters it needs no other buffer, and a hit costs no allocation, no reference count and no
registers held across the vertex.
"""

from __future__ import annotations

from numba import njit

from reference_impl.kernels.config import JIT_BORROW
from reference_impl.materials import NUM_PARAMS


@njit(**JIT_BORROW)
def material_params(materials, m, params):
    """Material ``m`` of ``materials`` (:class:`.records.MaterialTables`): its row of parameters, unchanged, written
    into ``params``; returns its kind."""
    table = materials.params
    for c in range(NUM_PARAMS):
        params[c] = table[m, c]
    return materials.kind[m]


@njit(**JIT_BORROW)
def material_at(materials, hit, params):
    """The material step at ``hit`` (:class:`.surface.SurfaceHit`): the parameters of its material at the hit,
    written into ``params`` (NUM_PARAMS float64, the ``P_*`` columns), and its kind (returned), which the BSDF
    (:mod:`.bsdf`) evaluates and samples. Nothing varies over a surface yet (no textures): material
    ``hit.material``'s row, unchanged."""
    return material_params(materials, hit.material, params)
