"""The materials that perturb another's shading normal: ``type = "normalmap"`` and ``type = "bumpmap"``
(Mitsuba 3.9.1's BSDF plugins of those names, around the material their ``bsdf`` key names; docs/scene-format.md,
"Shading normals"), one :class:`PerturbationKind` each in :data:`PERTURBATIONS`: its keys and their reading, its
columns of the core's row (:mod:`reference_impl.materials`), its Mitsuba plugin around the nested one's and its
scene.json entry. The reference perturbs the frame in :mod:`reference_impl.kernels.shading`."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

from reference_impl import materials as core

from harness.scene.kinds.textures import TEXTURES, texture_reference
from harness.scene.model import Material, Perturbation

COMMON_KEYS = ("type", "bsdf", "flip_invalid_normals", "use_shadowing_function")


@dataclass(frozen=True)
class PerturbationKind:
    """One perturbing material type.

    Attributes
    ----------
    name : str
        The ``type`` value (Mitsuba's plugin name).
    core_perturb : int
        Its :data:`reference_impl.materials.P_PERTURB` value.
    texture_key : str
        The key that names its texture (``{ texture = "NAME" }``).
    keys : tuple of str
        The keys its table may hold.
    check : callable
        ``check(reader, texture, key) -> None``: a HarnessError where the texture cannot serve.
    mitsuba_texture_key : str
        The name its texture has in Mitsuba's plugin.
    """

    name: str
    core_perturb: int
    texture_key: str
    keys: tuple[str, ...]
    check: Callable[[Any, Any, str], None]
    mitsuba_texture_key: str

    def to_mitsuba(self, material: Material, nested: dict) -> dict:
        """Mitsuba's plugin around ``nested`` (the wrapped material's dict)."""
        p = material.perturbation
        spec = {"type": self.name, self.mitsuba_texture_key: TEXTURES[p.texture.type].to_mitsuba(p.texture),
                "bsdf": nested, "flip_invalid_normals": bool(p.flip_invalid_normals),
                "use_shadowing_function": bool(p.use_shadowing_function)}
        if self.name == "bumpmap":
            spec["scale"] = float(p.scale)
        return spec

    def to_scene_json(self, material: Material, nested: dict) -> dict:
        """The scene.json entry around ``nested`` (the wrapped material's entry)."""
        p = material.perturbation
        out = {"type": self.name, self.texture_key: {"texture": p.texture.name}, "bsdf": nested,
               "flip_invalid_normals": bool(p.flip_invalid_normals),
               "use_shadowing_function": bool(p.use_shadowing_function)}
        if self.name == "bumpmap":
            out["scale"] = float(p.scale)
        return out

    def core_columns(self, material: Material) -> dict[int, float]:
        """The core row's columns it sets (:data:`reference_impl.materials.P_PERTURB` ...)."""
        p = material.perturbation
        return {core.P_PERTURB: self.core_perturb, core.P_BUMP_SCALE: float(p.scale),
                core.P_FLIP_INVALID: float(bool(p.flip_invalid_normals)),
                core.P_SHADOWING: float(bool(p.use_shadowing_function))}


def _check_normal_map(reader, texture, key: str) -> None:
    if texture.type != "bitmap" or not texture.raw:
        what = "a bitmap without raw = true" if texture.type == "bitmap" else f"a {texture.type}"
        raise reader.error(key, f"texture {texture.name!r} is {what}: a normal map takes a bitmap with raw = true "
                                "(its RGB are the normal's coordinates, 2 rgb - 1, never sRGB-decoded)")


def _check_height(reader, texture, key: str) -> None:
    if texture.type != "bitmap":
        raise reader.error(key, f"texture {texture.name!r} is a {texture.type}: a bump map takes a bitmap (Mitsuba "
                                "3.9.1's only texture with a gradient, eval_1_grad)")


#: Every perturbing type by its name.
PERTURBATIONS: dict[str, PerturbationKind] = {kind.name: kind for kind in (
    PerturbationKind("normalmap", core.PERTURB_NORMALMAP, "normalmap", COMMON_KEYS + ("normalmap",),
                     _check_normal_map, "normalmap"),
    PerturbationKind("bumpmap", core.PERTURB_BUMPMAP, "texture", COMMON_KEYS + ("texture", "scale"),
                     _check_height, "height"),
)}


def read_perturbed(reader, name: str, entry: dict, key: str, materials: dict[str, Material]) -> Material:
    """A ``normalmap`` or ``bumpmap`` table (``entry`` at ``key``): the material its ``bsdf`` names (one of
    ``materials``, read before: a material that perturbs none) with its map."""
    kind = PERTURBATIONS[entry["type"]]
    for item in entry:
        if item not in kind.keys:
            raise reader.error(f"{key}.{item}", f"a {kind.name} takes the keys {', '.join(kind.keys)}; "
                                                f"got {item!r}")
    nested = reader.string(reader.require(entry, "bsdf", key, "the name of the material it perturbs"),
                           f"{key}.bsdf")
    if nested not in materials:
        if nested in reader.perturbing_names:
            raise reader.error(f"{key}.bsdf", f"material {nested!r} is a normalmap or bumpmap: a {kind.name} "
                                              "perturbs a material that perturbs none")
        defined = ", ".join(repr(m) for m in materials) or "none"
        raise reader.error(f"{key}.bsdf", f"unknown material {nested!r} (defined in [materials]: {defined})")
    texture_key = f"{key}.{kind.texture_key}"
    value = reader.require(entry, kind.texture_key, key, '{ texture = "NAME" }')
    texture = texture_reference(reader, value, texture_key, reader.scene_textures)
    if texture is None:
        raise reader.expected(texture_key, '{ texture = "NAME" } (a [textures] table)', value)
    kind.check(reader, texture, texture_key)
    scale = 1.0
    if "scale" in entry:
        scale = reader.number(entry["scale"], f"{key}.scale", "a finite number")
        if not math.isfinite(scale):
            raise reader.expected(f"{key}.scale", "a finite number", entry["scale"])
    flip = reader.boolean(entry.get("flip_invalid_normals", True), f"{key}.flip_invalid_normals")
    shadowing = reader.boolean(entry.get("use_shadowing_function", True), f"{key}.use_shadowing_function")
    return dataclasses.replace(materials[nested], name=name, perturbation=Perturbation(
        kind.name, texture, nested, scale, flip, shadowing))
