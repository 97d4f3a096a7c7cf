"""The material step: between a hit and its BSDF, what the surface's material is at that hit (pbrt-v4's
``Material::GetBxDF``, which evaluates a material's textures at the hit and returns the BSDF they make).

    Bsdf(hit) = (kind_m, row_m),   m = hit.material

Every parameter is constant over a surface today, so the step hands on material m's kind and its row of
:class:`reference_impl.Materials` unchanged (its columns are the ``P_*`` of :mod:`reference_impl.materials`). A
texture will be looked up here, at the hit's texture coordinates (:class:`.surface.SurfaceHit`'s ``tex_u``,
``tex_v``), and replace the columns it drives; the BSDF (:mod:`.bsdf`) reads its parameters only from the
:class:`Bsdf` this step returns.

The row is copied into a tuple of NUM_PARAMS floats: a value, so a step that alters it needs no buffer, and a
kernel that holds it holds no reference to the table (no reference count per hit).
"""

from __future__ import annotations

from typing import NamedTuple

from numba import njit
from numba.np.unsafe.ndarray import to_fixed_tuple

from reference_impl.kernels.config import JIT_BORROW
from reference_impl.materials import NUM_PARAMS


class Bsdf(NamedTuple):
    """The BSDF at one hit: what :mod:`.bsdf` evaluates and samples.

    Attributes
    ----------
    kind : int
        DIFFUSE .. ROUGHDIELECTRIC (:mod:`reference_impl.materials`).
    params : tuple of NUM_PARAMS floats
        The parameters at the hit, indexed by the ``P_*`` columns of :mod:`reference_impl.materials`.
    """

    kind: int
    params: tuple


@njit(**JIT_BORROW)
def material_bsdf(materials, m):
    """The :class:`Bsdf` of material ``m`` of ``materials`` (:class:`.records.MaterialTables`): its kind and its
    row of parameters, unchanged."""
    return Bsdf(materials.kind[m], to_fixed_tuple(materials.params[m], NUM_PARAMS))


@njit(**JIT_BORROW)
def material_at(materials, hit):
    """The material step at ``hit`` (:class:`.surface.SurfaceHit`): the :class:`Bsdf` of its material, whose
    parameters do not vary over a surface (no textures yet), hence material ``hit.material``'s row unchanged."""
    return material_bsdf(materials, hit.material)
