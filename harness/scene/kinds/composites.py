"""The material types made of other materials (Mitsuba's ``blendbsdf``, ``mask`` and ``twosided`` with nested
BSDFs; docs/scene-format.md, "Materials made of materials"): each names the ``[materials.NAME]`` tables it is made of
with ``bsdf``, read after the tables it names (:func:`read_composites`), and holds them
(:attr:`~harness.scene.model.Material.nested`).

* ``blendbsdf``: ``weight`` (a number or a texture's one number, in [0, 1]; Mitsuba's default 0.5 where none is
  given) and ``bsdf = ["A", "B"]``: f = (1 - weight) f_A + weight f_B.
* ``mask``: ``opacity`` (likewise, default 0.5) and ``bsdf = "A"``: f = opacity f_A plus a hole of probability
  1 - opacity; a shape's own material only (not nested in another, not on an emitter).
* ``twosided``: ``bsdf = "A"`` (A on both sides) or ``bsdf = ["FRONT", "BACK"]``; materials without transmission.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from reference_impl import materials as core

from harness.scene.kinds.materials import MATERIALS, MaterialKind
from harness.scene.kinds.textures import TEXTURES, texture_reference
from harness.scene.model import Material

COMPOSITE_TYPES = ("blendbsdf", "mask", "twosided")
_KEYS = {"blendbsdf": ("type", "weight", "bsdf"), "mask": ("type", "opacity", "bsdf"), "twosided": ("type", "bsdf")}
_WEIGHT_KEY = {"blendbsdf": "weight", "mask": "opacity"}


def is_composite(entry: Any) -> bool:
    """Whether a ``[materials.NAME]`` table is of a composite type."""
    return isinstance(entry, dict) and entry.get("type") in COMPOSITE_TYPES


def read_composites(reader, entries: dict[str, dict], materials: dict[str, Material]) -> dict[str, Material]:
    """The composite tables ``entries`` (name: table), each with the materials its ``bsdf`` names (of
    ``materials``, read before, or another composite of ``entries``): {name: Material}."""
    done: dict[str, Material] = {}

    def read(name: str, chain: tuple[str, ...]) -> Material:
        if name in done:
            return done[name]
        key = reader.join("materials", name)
        entry = entries[name]
        kind = entry["type"]
        for item in entry:
            if item not in _KEYS[kind]:
                raise reader.error(f"{key}.{item}", f"a {kind} takes the keys {', '.join(_KEYS[kind])}; got {item!r}")
        raw = reader.require(entry, "bsdf", key, "the name of the material it is made of" if kind == "mask" else
                             "the names of the materials it is made of")
        count = {"blendbsdf": (2,), "mask": (1,), "twosided": (1, 2)}[kind]
        names = [raw] if isinstance(raw, str) else raw
        what = {"blendbsdf": 'a list of two material names, ["A", "B"]', "mask": 'a material name, "A"',
                "twosided": 'a material name, "A", or two, ["FRONT", "BACK"]'}[kind]
        if not isinstance(names, list) or len(names) not in count or not all(isinstance(n, str) for n in names) \
                or (kind == "blendbsdf" and isinstance(raw, str)):
            raise reader.expected(f"{key}.bsdf", what, raw)
        nested = []
        for n in names:
            if n == name or n in chain:
                raise reader.error(f"{key}.bsdf", f"material {n!r} contains {name!r}: expected materials that do "
                                                  "not contain the material itself")
            if n in entries:
                if entries[n]["type"] == "mask":
                    raise reader.error(f"{key}.bsdf", f"material {n!r} is a mask: a mask is a shape's own material, "
                                                      "not nested in another")
                nested.append(read(n, chain + (name,)))
            elif n in materials:
                nested.append(materials[n])
            else:
                defined = ", ".join(repr(m) for m in (*materials, *entries)) or "none"
                raise reader.error(f"{key}.bsdf", f"unknown material {n!r} (defined in [materials]: {defined})")
        if kind == "twosided":
            for m in nested:
                crossing = [leaf for leaf in _leaves(m) if not MATERIALS[leaf.type].two_sided]
                if crossing:
                    raise reader.error(f"{key}.bsdf", f"material {crossing[0].name!r} ({crossing[0].type}) transmits "
                                                      "light: a twosided takes materials without transmission (as "
                                                      "Mitsuba's), those that take two_sided")
            if len(nested) == 1:
                nested = nested * 2
        weight, textures = core.DEFAULT_WEIGHT, ()
        item = _WEIGHT_KEY.get(kind)
        if item is not None and item in entry:
            value = entry[item]
            if isinstance(value, dict) and "texture" in value:
                texture = texture_reference(reader, value, f"{key}.{item}", reader.scene_textures)
                if texture.type != "bitmap":
                    raise reader.error(f"{key}.{item}", f"texture {texture.name!r} is a {texture.type}: {item} takes "
                                                        "a bitmap (its luminance; Mitsuba 3.9.1's checkerboard as one "
                                                        "number swaps its two colours)")
                textures = ((item, texture),)
                weight = float(min(max(texture.scalar_range[1], 0.0), 1.0))
            else:
                what = f"a number in [0, 1] or {{ texture = \"NAME\" }}"
                weight = reader.number(value, f"{key}.{item}", what)
                if not 0.0 <= weight <= 1.0:
                    raise reader.expected(f"{key}.{item}", what, value)
        bound = tuple(float(x) for x in np.max([m.reflectance for m in nested], axis=0))
        done[name] = Material(name, reflectance=bound, type=kind, weight=weight, nested=tuple(nested),
                              textures=textures)
        return done[name]

    for name in entries:
        read(name, ())
    return done


def _leaves(material: Material) -> list[Material]:
    """The materials that are no composite inside ``material`` (itself where it is none)."""
    if material.type not in COMPOSITE_TYPES:
        return [material]
    return [leaf for m in material.nested for leaf in _leaves(m)]


def leaves(material: Material) -> list[Material]:
    """The materials that are no composite inside ``material``, each once."""
    return list({id(m): m for m in _leaves(material)}.values())


def _json(material: Material) -> dict:
    out: dict = {}
    item = _WEIGHT_KEY.get(material.type)
    if item is not None:
        out[item] = float(material.weight)
    names = [m.name for m in material.nested]
    out["bsdf"] = names[0] if material.type == "mask" or (material.type == "twosided" and names[0] == names[1]) \
        else names
    return out


def _gltf(material: Material) -> tuple[dict, dict]:
    """The glTF form of the material that stands for it (:func:`stand_in`); a mask's opacity as the base colour's
    alpha (glTF's alphaMode BLEND, set by the export)."""
    factors, extensions = ALL_MATERIALS[stand_in(material).type].to_gltf(stand_in(material))
    if material.type == "mask":
        colour = list(factors.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0]))
        factors = {**factors, "baseColorFactor": colour[:3] + [float(material.weight)]}
    return factors, extensions


def stand_in(material: Material) -> Material:
    """The one material a format without composites is given for ``material``: a mask's nested one, a blend's of
    the larger weight (the second at 0.5 and above), a twosided's front one."""
    while material.type in COMPOSITE_TYPES:
        material = material.nested[1 if material.type == "blendbsdf" and material.weight >= 0.5 else 0]
    return material


def _gltf_losses(material: Material) -> tuple[str, ...]:
    return {"blendbsdf": ("blend",), "mask": ("mask",), "twosided": ("back",)}[material.type]


@dataclasses.dataclass(frozen=True)
class CompositeKind(MaterialKind):
    """A :class:`~harness.scene.kinds.materials.MaterialKind` of materials made of others: its Mitsuba plugin holds
    its nested materials' plugins, its row of the core's table their rows (given by the table's builder,
    :func:`harness.scene.material_arrays.material_table`)."""

    def core_slots(self, material: Material) -> dict[str, str]:
        return {"weight": texture.name for _, texture in material.textures}

    def to_core(self, material: Material, rows: dict[str, int] | None = None) -> np.ndarray:
        """The core's row: the weight or opacity and the rows of the nested materials (``rows``: name to row)."""
        rows = rows or {}
        first, second = (rows.get(m.name, 0) for m in (material.nested[0], material.nested[-1]))
        return core.material_row(self.core_kind, weight=material.weight, nested=(first, second))

    def to_mitsuba(self, material: Material) -> dict:
        """Mitsuba's dict: the plugin with its nested materials' dicts inside (``bsdf_0``, ``bsdf_1``; a mask's
        ``bsdf``), the weight or opacity a number or its texture's plugin."""
        spec: dict = {"type": material.type}
        item = _WEIGHT_KEY.get(material.type)
        if item is not None:
            texture = material.texture(item)
            spec[item] = TEXTURES[texture.type].to_mitsuba(texture) if texture is not None else float(material.weight)
        if material.type == "mask":
            spec["bsdf"] = ALL_MATERIALS[material.nested[0].type].to_mitsuba(material.nested[0])
        else:
            for j, m in enumerate(material.nested):
                spec[f"bsdf_{j}"] = ALL_MATERIALS[m.type].to_mitsuba(m)
        return spec

    def to_scene_json(self, material: Material) -> dict:
        out = {"type": self.name, **self.json(material)}
        for item, texture in material.textures:
            out[item] = {"texture": texture.name}
        return out

    def gltf_double_sided(self, material: Material) -> bool:
        return material.type == "twosided" or ALL_MATERIALS[stand_in(material).type].gltf_double_sided(
            stand_in(material))


COMPOSITES: dict[str, MaterialKind] = {
    "blendbsdf": CompositeKind("blendbsdf", core.BLENDBSDF, _KEYS["blendbsdf"], lambda r, e, k: {}, parameters=None,
                               json=_json, gltf=_gltf, gltf_losses=_gltf_losses, textured=("weight",)),
    "mask": CompositeKind("mask", core.MASK, _KEYS["mask"], lambda r, e, k: {}, parameters=None, json=_json,
                          gltf=_gltf, gltf_losses=_gltf_losses, textured=("opacity",)),
    "twosided": CompositeKind("twosided", core.TWOSIDED, _KEYS["twosided"], lambda r, e, k: {}, parameters=None,
                              json=_json, gltf=_gltf, gltf_losses=_gltf_losses),
}
#: Every material type by its name: :data:`~harness.scene.kinds.materials.MATERIALS` and the composites.
ALL_MATERIALS: dict[str, MaterialKind] = {**MATERIALS, **COMPOSITES}
