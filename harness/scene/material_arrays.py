"""Turn a :class:`Scene`'s ``[materials.NAME]`` tables into the core's :class:`reference_impl.Materials` (the table
the reference renderer's BSDF kernels read beside the triangles of :func:`harness.scene.triangulate`), in the order
``Geometry.material`` indexes them (the file's)."""

from __future__ import annotations

import numpy as np

import reference_impl
from reference_impl import materials as core
from reference_impl.errors import SettingsError
from reference_impl.textures import Textures

from harness.core.errors import HarnessError
from harness.scene.kinds.composites import ALL_MATERIALS
from harness.scene.model import Material, Scene


def material_row(material: Material) -> np.ndarray:
    """The core's parameter row of one material of the scene model (its type's
    :meth:`~harness.scene.kinds.materials.MaterialKind.to_core`)."""
    return ALL_MATERIALS[material.type].to_core(material)


def material_table(scene: Scene) -> reference_impl.Materials:
    """Every material of ``scene`` as the core's table, in file order."""
    materials = list(scene.materials.values())
    kind = np.array([ALL_MATERIALS[m.type].core_kind for m in materials], dtype=np.int64)
    rows = {m.name: j for j, m in enumerate(materials)}
    params = np.array([ALL_MATERIALS[m.type].to_core(m, rows) if m.nested else material_row(m) for m in materials],
                      dtype=np.float64).reshape(-1, core.NUM_PARAMS)
    used = scene.used_textures
    number = {texture.name: k for k, texture in enumerate(used)}
    texture = np.full((len(materials), core.NUM_SLOTS), -1, dtype=np.int64)
    for m, material in enumerate(materials):
        for slot, name in ALL_MATERIALS[material.type].core_slots(material).items():
            texture[m, list(core.TEXTURE_SLOTS).index(slot)] = number[name]
    try:
        textures = Textures(tuple(t.core for t in used))
        return reference_impl.Materials(kind, params, texture, textures)
    except SettingsError as err:
        # The core names a material by its row; the file names it by its table.
        raise HarnessError(str(scene.path), f"cannot use the materials: {err.key}: {err.message}") from err


def material_arrays(scene: Scene) -> reference_impl.Materials | None:
    """The core's material table, or None for a scene whose materials are all Lambertian and untextured (which then
    renders exactly as it did before other materials existed: ``Geometry.reflectance`` and ``two_sided`` say it
    all)."""
    if not scene.has_glossy_materials and not scene.used_textures:
        return None
    return material_table(scene)
