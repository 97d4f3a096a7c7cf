"""The material types of a ``[materials.NAME]`` table (Mitsuba's BSDF plugins of the same names and parameters,
docs/scene-format.md, "Materials"), one :class:`MaterialKind` each in :data:`MATERIALS`: its keys and their reading,
its row of the core's table (:mod:`reference_impl.materials`, whose defaults are the model's), its Mitsuba plugin,
its scene.json entry and its glTF 2.0 material with what that form loses."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from reference_impl import materials as core

from harness.scene.kinds.mitsuba_values import rgb
from harness.scene.kinds.perturbations import PERTURBATIONS
from harness.scene.kinds.textures import TEXTURES, texture_reference
from harness.scene.model import (DEFAULT_ALPHA, DEFAULT_DIFFUSE, DEFAULT_DISTRIBUTION, DEFAULT_EXT_IOR,
                                 DEFAULT_INT_IOR, DEFAULT_NONLINEAR, DEFAULT_SAMPLE_VISIBLE, DISTRIBUTIONS,
                                 MATERIAL_TYPES, MIRROR_ETA, MIRROR_K, PLASTIC_INT_IOR, Material, Principled,
                                 Texture)

DEFAULT_TYPE = "diffuse"
CONDUCTOR_MATERIALS = ("none",)  # Mitsuba's named conductors but "none" (a perfect mirror) are refused
# Mitsuba 3.9.1's "Cu" in its RGB variants (mi.load_dict({"type": "conductor", "material": "Cu"}) in scalar_rgb),
# quoted by the refusal of named materials so that a user can type them.
CU_ETA = (0.201005, 0.92375, 1.10222)
CU_K = (3.91326, 2.45305, 2.14209)
# Ranges the reference's BSDFs are tested over (docs/scene-format.md): alpha from near-specular to very rough;
# indices and extinction coefficients of every real material, with room to spare.
MIN_ALPHA, MAX_ALPHA = 1e-4, 1.0
MIN_IOR, MAX_IOR = 0.01, 100.0
MAX_PLASTIC_ETA = 3.8  # about where Mitsuba's F_dr(1 / eta) (the Egan-Hilgeman fit) reaches 1
MAX_CONDUCTOR_INDEX = 100.0
#: Mitsuba's keys of anisotropic roughness, refused in one line (the reference's microfacet models are isotropic).
ANISOTROPIC_KEYS = ("alpha_u", "alpha_v")
#: The core's texture slot (:data:`reference_impl.materials.TEXTURE_SLOTS`) of each parameter a texture may drive.
TEXTURE_SLOTS = {"reflectance": "reflectance", "specular_reflectance": "reflectance",
                 "specular_transmittance": "transmittance", "alpha": "alpha", "diffuse_reflectance": "diffuse",
                 "base_color": "reflectance", **{item: item for item in core.PRINCIPLED_UNIT},
                 "weight": "weight", "opacity": "weight"}
#: The one-number parameters a texture may drive (Mitsuba's ``eval_1``: a bitmap's luminance) and their ranges.
ONE_NUMBER_RANGES = {"alpha": (MIN_ALPHA, MAX_ALPHA), **{item: (0.0, 1.0) for item in core.PRINCIPLED_UNIT}}


@dataclass(frozen=True)
class MaterialKind:
    """One material type.

    Attributes
    ----------
    name : str
        The ``type`` value (Mitsuba's plugin name).
    core_kind : int
        Its kind in the core's table (:data:`reference_impl.materials.DIFFUSE` ...).
    keys : tuple of str
        The keys its table may hold.
    read : callable
        ``read(reader, entry, key) -> dict``: the :class:`~harness.scene.model.Material` fields of the table
        ``entry`` at key path ``key`` but ``name``, ``type`` and ``two_sided``, read with the scene reader's typed
        readers (``reader``: :class:`harness.scene.load._SceneReader`); a bad value is its HarnessError.
    parameters : callable
        ``parameters(material) -> dict``: the parameters of its Mitsuba plugin, every one written out.
    json : callable
        ``json(material) -> dict``: its parameters in the scene.json entry (``type`` and ``two_sided`` aside).
    gltf : callable
        ``gltf(material) -> (dict, dict)``: its glTF 2.0 metallic-roughness factors (the keys of
        ``pbrMetallicRoughness``) and its glTF extensions (docs/external-renderers.md, "glTF materials").
    refused : tuple of (str, str)
        Keys of other types that this one refuses with a reason of their own.
    gltf_losses : callable
        ``gltf_losses(material) -> tuple of str``: the keys of :data:`GLTF_LOSSES` that its glTF form loses.
    textured : tuple of str
        The keys that take ``{ texture = "NAME" }`` in place of a value (Mitsuba's texture-valued parameters, of
        those the reference looks up: :data:`TEXTURE_SLOTS`).
    gltf_base : str
        The parameter its glTF base colour (and OBJ's ``Kd``) is made from, whose texture those formats can carry.
    """

    name: str
    core_kind: int
    keys: tuple[str, ...]
    read: Callable[[Any, dict, str], dict]
    parameters: Callable[[Material], dict]
    json: Callable[[Material], dict]
    gltf: Callable[[Material], tuple[dict, dict]]
    refused: tuple[tuple[str, str], ...] = ()
    gltf_losses: Callable[[Material], tuple[str, ...]] = lambda _material: ()
    textured: tuple[str, ...] = ()
    gltf_base: str = "reflectance"

    @property
    def two_sided(self) -> bool:
        """Whether the type takes ``two_sided`` (Mitsuba's ``twosided`` wrapper)."""
        return "two_sided" in self.keys

    def core_slots(self, material: Material) -> dict[str, str]:
        """``{core slot: texture name}`` of the parameters a texture drives (:data:`TEXTURE_SLOTS`), and of a normal
        or bump map's texture."""
        slots = {TEXTURE_SLOTS[item]: texture.name for item, texture in material.textures}
        if material.perturbation is not None:
            slots[material.perturbation.type] = material.perturbation.texture.name
        return slots

    def to_core(self, material: Material) -> np.ndarray:
        """The core's parameter row of ``material`` (same parameters, Mitsuba's meaning; a textured parameter holds
        its texture's largest value, which the material step replaces at every hit)."""
        row = self._core_row(material)
        if material.perturbation is not None:
            for column, value in PERTURBATIONS[material.perturbation.type].core_columns(material).items():
                row[column] = value
        return row

    def _core_row(self, material: Material) -> np.ndarray:
        if self.core_kind == core.NULL:  # Mitsuba's null BSDF: a row the kernels never read
            return np.zeros(core.NUM_PARAMS, dtype=np.float64)
        if self.core_kind == core.DIFFUSE:
            return core.material_row(core.DIFFUSE, reflectance=material.reflectance, two_sided=material.two_sided)
        if self.core_kind == core.PRINCIPLED:
            values = dataclasses.asdict(material.principled)
            return core.material_row(core.PRINCIPLED, **values)
        if self.core_kind == core.PLASTIC:
            return core.material_row(
                core.PLASTIC, reflectance=material.specular_reflectance, diffuse=material.diffuse_reflectance,
                int_ior=material.int_ior, ext_ior=material.ext_ior, two_sided=material.two_sided,
                nonlinear=material.nonlinear, specular_sampling_weight=_plastic_sampling_weight(material))
        if self.core_kind == core.ROUGHPLASTIC:
            return core.material_row(
                core.ROUGHPLASTIC, reflectance=material.specular_reflectance, diffuse=material.diffuse_reflectance,
                int_ior=material.int_ior, ext_ior=material.ext_ior, two_sided=material.two_sided,
                nonlinear=material.nonlinear, specular_sampling_weight=_plastic_sampling_weight(material),
                alpha=material.alpha, distribution=core.DISTRIBUTIONS[material.distribution],
                sample_visible=material.sample_visible)
        return core.material_row(
            self.core_kind, reflectance=material.specular_reflectance, eta=material.eta, k=material.k,
            transmittance=material.specular_transmittance, alpha=material.alpha,
            distribution=core.DISTRIBUTIONS[material.distribution], sample_visible=material.sample_visible,
            int_ior=material.int_ior, ext_ior=material.ext_ior, two_sided=material.two_sided,
            mirror=material.mirror)

    def to_mitsuba(self, material: Material) -> dict:
        """Mitsuba's dict of ``material``: its plugin with every parameter written out (so Mitsuba's defaults never
        decide), inside ``twosided`` when two-sided."""
        spec = {"type": self.name, **self.parameters(material)}
        for item, texture in material.textures:
            spec[item] = TEXTURES[texture.type].to_mitsuba(texture)
        spec = {"type": "twosided", "bsdf": spec} if material.two_sided else spec
        if material.perturbation is not None:  # Mitsuba's normalmap / bumpmap around it
            return PERTURBATIONS[material.perturbation.type].to_mitsuba(material, spec)
        return spec

    def to_scene_json(self, material: Material) -> dict:
        """The scene.json entry of ``material``: every parameter of its plugin, ``two_sided`` where it applies."""
        out = {"type": self.name, **self.json(material)}
        for item, texture in material.textures:
            out[item] = {"texture": texture.name}
        if self.two_sided:
            out["two_sided"] = bool(material.two_sided)
        if material.perturbation is not None:
            return PERTURBATIONS[material.perturbation.type].to_scene_json(material, out)
        return out

    def to_gltf(self, material: Material) -> tuple[dict, dict]:
        """The glTF 2.0 metallic-roughness factors of ``material`` and its glTF extensions."""
        return self.gltf(material)

    def gltf_double_sided(self, material: Material) -> bool:
        """glTF's ``doubleSided`` of ``material``: two-sided, or of a type that light crosses from either side (one
        without ``two_sided``, a dielectric; a principled one whose spec_trans is not 0)."""
        if material.principled is not None:
            return _principled_transmits(material)
        return bool(material.two_sided or not self.two_sided)


def read_material(reader, name: str, entry: Any) -> Material:
    """One ``[materials.NAME]`` table: its type (default diffuse) and that type's parameters, of which those the
    type lists as ``textured`` may name a texture (``{ texture = "NAME" }``).

    Parameters
    ----------
    reader : harness.scene.load._SceneReader
        The scene reader (its typed readers and errors).
    name : str
        The table's name.
    entry : object
        The parsed table; a parameter's ``{ texture = "NAME" }`` names one of ``reader.scene_textures`` (the scene's
        ``[textures]``, read first).

    Returns
    -------
    Material
    """
    key = reader.join("materials", name)
    entry = reader.table(entry, key)
    for item in ANISOTROPIC_KEYS:
        if item in entry:
            raise reader.error(f"{key}.{item}", "anisotropic roughness (Mitsuba's alpha_u and alpha_v) is not in the "
                                                "reference's microfacet models: expected alpha (isotropic)")
    reader.check_keys(entry, MATERIAL_KEYS, key)
    kind = MATERIALS[reader.choice(entry.get("type", DEFAULT_TYPE), f"{key}.type", tuple(MATERIALS))]
    for item, reason in kind.refused:
        if item in entry:
            raise reader.error(f"{key}.{item}", f"a {kind.name} has no {item}: {reason}")
    for item in entry:
        if item not in kind.keys:
            owners = " or ".join(repr(t) for t, other in MATERIALS.items() if item in other.keys)
            raise reader.error(f"{key}.{item}", f"key {item!r} applies only to materials of type {owners}, "
                                                f"not {kind.name!r}")
    two_sided = reader.boolean(entry.get("two_sided", False), f"{key}.two_sided")
    entry, textured = _textured_parameters(reader, kind, entry, key, reader.scene_textures)
    return Material(name, type=kind.name, two_sided=two_sided, textures=textured, **kind.read(reader, entry, key))


def _textured_parameters(reader, kind: MaterialKind, entry: dict, key: str,
                         textures: dict[str, Texture]) -> tuple[dict, tuple]:
    """The table with each parameter that names a texture replaced by the texture's largest value (what the type's
    reader checks, and the row's bound), and the (parameter, texture) pairs."""
    entry, textured = dict(entry), []
    for item, value in list(entry.items()):
        if not (isinstance(value, dict) and "texture" in value):
            continue
        if item == "alpha" and kind.name == "roughplastic":
            raise reader.error(f"{key}.{item}", "alpha of a roughplastic takes no texture: Mitsuba's roughplastic "
                                                "takes a number (it tabulates its coating for one roughness)")
        if item not in kind.textured:
            takes = ", ".join(kind.textured) or "none of its parameters"
            raise reader.error(f"{key}.{item}", f"{item} of a {kind.name} takes no texture (textures drive: {takes})")
        texture = texture_reference(reader, value, f"{key}.{item}", textures)
        if item in ONE_NUMBER_RANGES:  # one number: Mitsuba's eval_1 (a bitmap's luminance)
            if texture.type != "bitmap":
                raise reader.error(f"{key}.{item}", f"texture {texture.name!r} is a {texture.type}: {item} takes a "
                                                    "bitmap (Mitsuba 3.9.1's checkerboard as one number swaps its "
                                                    "two colours, tests/reference_impl/test_textures.py)")
            low, high = texture.scalar_range
            least, most = ONE_NUMBER_RANGES[item]
            if not (least <= low and high <= most):
                raise reader.error(f"{key}.{item}", f"texture {texture.name!r} has luminances from {low:.6g} to "
                                                    f"{high:.6g}; {item} takes values in [{least:g}, {most:g}]")
            entry[item] = high
        else:
            top = texture.max_value
            if max(top) > 1.0:
                raise reader.error(f"{key}.{item}", f"texture {texture.name!r} has values up to {max(top):.6g}; "
                                                    f"{item} takes values in [0, 1]")
            entry[item] = list(top)
        textured.append((item, texture))
    return entry, tuple(textured)


# ---- reading -------------------------------------------------------------------------------------------------------


def _read_diffuse(reader, entry: dict, key: str) -> dict:
    what = "a list of 3 numbers in [0, 1]"
    raw = reader.require(entry, "reflectance", key, what)
    reflectance = reader.vector3(raw, f"{key}.reflectance", what)
    if not all(0.0 <= channel <= 1.0 for channel in reflectance):
        raise reader.expected(f"{key}.reflectance", what, raw)
    return {"reflectance": reflectance}


def _read_conductor(reader, entry: dict, key: str) -> dict:
    """A conductor's fields; ``reflectance`` (the bound of one bounce) is its specular_reflectance."""
    fields = {"specular_reflectance": _unit_colour(reader, entry, "specular_reflectance", key)}
    fields.update(_complex_index(reader, entry, key))
    fields["reflectance"] = fields["specular_reflectance"]
    return fields


def _read_dielectric(reader, entry: dict, key: str) -> dict:
    """A dielectric's fields; ``reflectance`` is the larger of its specular reflectance and transmittance."""
    fields: dict[str, Any] = {"specular_reflectance": _unit_colour(reader, entry, "specular_reflectance", key),
                              "specular_transmittance": _unit_colour(reader, entry, "specular_transmittance", key)}
    for item, default in (("int_ior", DEFAULT_INT_IOR), ("ext_ior", DEFAULT_EXT_IOR)):
        fields[item] = _index_of_refraction(reader, entry.get(item, default), f"{key}.{item}")
    fields["reflectance"] = tuple(max(r, t) for r, t in zip(fields["specular_reflectance"],
                                                            fields["specular_transmittance"]))
    return fields


def _read_plastic(reader, entry: dict, key: str, rough: bool = False) -> dict:
    """A plastic's fields (Mitsuba's defaults: diffuse_reflectance 0.5, specular_reflectance 1, int_ior 1.49
    (polypropylene), ext_ior 1.000277 (air), nonlinear false); ``reflectance`` is the larger of its specular and
    diffuse reflectances."""
    fields: dict[str, Any] = {
        "diffuse_reflectance": _unit_colour(reader, entry, "diffuse_reflectance", key, DEFAULT_DIFFUSE[0]),
        "specular_reflectance": _unit_colour(reader, entry, "specular_reflectance", key),
        "nonlinear": reader.boolean(entry.get("nonlinear", DEFAULT_NONLINEAR), f"{key}.nonlinear")}
    for item, default in (("int_ior", PLASTIC_INT_IOR), ("ext_ior", DEFAULT_EXT_IOR)):
        fields[item] = _index_of_refraction(reader, entry.get(item, default), f"{key}.{item}")
    eta = fields["int_ior"] / fields["ext_ior"]
    fdr = core.fresnel_diffuse_reflectance(1.0 / eta)
    if not rough and not 0.0 <= fdr < 1.0:
        item = "int_ior" if "int_ior" in entry else "ext_ior"
        raise reader.error(f"{key}.{item}", (
            f"expected int_ior / ext_ior below {MAX_PLASTIC_ETA:g} for a plastic (Mitsuba's fit of the coating's "
            f"internal diffuse reflectance exceeds 1 beyond), got {eta:.6g}"))
    fields["reflectance"] = tuple(max(s, d) for s, d in zip(fields["specular_reflectance"],
                                                            fields["diffuse_reflectance"]))
    return fields


def _read_roughplastic(reader, entry: dict, key: str) -> dict:
    """A rough plastic's fields: a plastic's (Mitsuba's same defaults; no bound on int_ior / ext_ior from F_dr, which
    it does not use: its internal reflectance is integrated) but int_ior != ext_ior (Mitsuba refuses an index-matched
    coating), and alpha, distribution, sample_visible (Mitsuba's defaults 0.1, beckmann, true)."""
    fields = _read_plastic(reader, entry, key, rough=True)
    if np.float32(fields["int_ior"]) == np.float32(fields["ext_ior"]):
        item = "int_ior" if "int_ior" in entry else "ext_ior"
        raise reader.error(f"{key}.{item}", (
            f"expected int_ior != ext_ior for a roughplastic (Mitsuba refuses an index-matched coating), got both "
            f"{fields['int_ior']:g}"))
    return {**fields, **_roughness(reader, entry, key)}


def _plastic_sampling_weight(material: Material) -> float:
    """Plastic's specular sampling weight from the channel means of its specular and diffuse reflectances, a
    texture's mean over its texels where one drives them (Mitsuba's ``Texture::mean``)."""
    def mean(item: str) -> float:
        texture = material.texture(item)
        return float(np.mean(texture.mean_value if texture is not None else getattr(material, item)))
    return core.plastic_sampling_weight(mean("specular_reflectance"), mean("diffuse_reflectance"))


def _principled_transmits(material: Material) -> bool:
    """Mitsuba's ``m_has_spec_trans``: spec_trans given as a texture or a number other than 0."""
    return material.principled.spec_trans != 0.0 or material.texture("spec_trans") is not None


def _read_principled(reader, entry: dict, key: str) -> dict:
    """A principled material's fields (Mitsuba 3.9.1's names and defaults: base_color 0.5, roughness 0.5,
    specular 0.5, the other weights 0, the sampling rates 1); ``eta`` and ``specular`` are one parameter (eta =
    2 / (1 - sqrt(0.08 specular)) - 1), given once at most, nudged as Mitsuba does where spec_trans is given
    (eta 1 -> 1.001, specular 0 -> 1e-3)."""
    if "eta" in entry and "specular" in entry:
        raise reader.error(f"{key}.specular", "expected either eta or specular, not both (Mitsuba's principled "
                                              "takes one: specular = ((eta - 1) / (eta + 1))^2 / 0.08)")
    values: dict[str, Any] = {"base_color": _unit_colour(reader, entry, "base_color", key,
                                                         core.PRINCIPLED_DEFAULTS["base_color"][0])}
    what = "a finite number in [0, 1]"
    for item in core.PRINCIPLED_UNIT:
        values[item] = reader.number(entry.get(item, core.PRINCIPLED_DEFAULTS[item]), f"{key}.{item}", what)
        if not 0.0 <= values[item] <= 1.0:
            raise reader.expected(f"{key}.{item}", what, entry[item])
    rate = "a finite number > 0 (a lobe's weight in the choice of lobe)"
    for item in ("main_specular_sampling_rate", "clearcoat_sampling_rate", "diffuse_reflectance_sampling_rate"):
        values[item] = reader.number(entry.get(item, 1.0), f"{key}.{item}", rate)
        if not values[item] > 0.0:
            raise reader.expected(f"{key}.{item}", rate, entry[item])
    transmits = "spec_trans" in entry and (isinstance(entry["spec_trans"], list) or values["spec_trans"] != 0.0)
    if "eta" in entry:
        eta = _index_of_refraction(reader, entry["eta"], f"{key}.eta")
        values["eta"] = 1.001 if transmits and eta == 1.0 else eta
    else:
        specular = reader.number(entry.get("specular", core.PRINCIPLED_DEFAULTS["specular"]), f"{key}.specular",
                                 what)
        if not 0.0 <= specular <= 1.0:
            raise reader.expected(f"{key}.specular", what, entry["specular"])
        values["eta"] = core.principled_eta(specular, transmits)
    return {"principled": Principled(**values), "reflectance": (1.0, 1.0, 1.0)}


def _principled_parameters(material: Material) -> dict:
    """Mitsuba's parameters: every one written out, the index as ``eta`` (whichever spelling the file used)."""
    values = dataclasses.asdict(material.principled)
    values["base_color"] = rgb(values["base_color"])
    return {item: (value if item == "base_color" else float(value)) for item, value in values.items()}


def _principled_json(material: Material) -> dict:
    values = dataclasses.asdict(material.principled)
    values["base_color"] = _numbers(values["base_color"])
    return {item: (value if item == "base_color" else float(value)) for item, value in values.items()}


def _read_roughdielectric(reader, entry: dict, key: str) -> dict:
    fields = _read_dielectric(reader, entry, key)
    if np.float32(fields["int_ior"]) == np.float32(fields["ext_ior"]):
        item = "int_ior" if "int_ior" in entry else "ext_ior"
        raise reader.error(f"{key}.{item}", (
            f"expected int_ior != ext_ior for a roughdielectric (Mitsuba refuses an index-matched rough "
            f"interface), got both {fields['int_ior']:g}; an invisible surface is a dielectric"))
    return {**fields, **_roughness(reader, entry, key)}


def _roughness(reader, entry: dict, key: str) -> dict:
    """A rough type's ``alpha``, ``distribution`` and ``sample_visible``."""
    what = f"a finite number in [{MIN_ALPHA:g}, {MAX_ALPHA:g}] (the microfacets' roughness)"
    alpha = reader.number(entry.get("alpha", DEFAULT_ALPHA), f"{key}.alpha", what)
    if not MIN_ALPHA <= alpha <= MAX_ALPHA:
        raise reader.expected(f"{key}.alpha", what, entry["alpha"])
    return {"alpha": alpha,
            "distribution": reader.choice(entry.get("distribution", DEFAULT_DISTRIBUTION), f"{key}.distribution",
                                          DISTRIBUTIONS),
            "sample_visible": reader.boolean(entry.get("sample_visible", DEFAULT_SAMPLE_VISIBLE),
                                             f"{key}.sample_visible")}


def _unit_colour(reader, entry: dict, item: str, key: str, default: float = 1.0) -> tuple[float, float, float]:
    """``specular_reflectance`` / ``specular_transmittance`` / ``diffuse_reflectance``: a number or [r, g, b], each
    in [0, 1]; default ``default`` (1)."""
    what = "a number or a list of 3 numbers, each in [0, 1]"
    colour = reader.colour_or_number(entry.get(item, default), f"{key}.{item}", what)
    if not all(0.0 <= channel <= 1.0 for channel in colour):
        raise reader.expected(f"{key}.{item}", what, entry[item])
    return colour


def _complex_index(reader, entry: dict, key: str) -> dict[str, tuple[float, float, float]]:
    """A conductor's ``eta`` and ``k`` (Mitsuba's defaults 0 and 1), or ``material = "none"`` (the same: a perfect
    mirror); other named materials are refused."""
    if "material" in entry:
        material = entry["material"]
        if material not in CONDUCTOR_MATERIALS:
            raise reader.error(f"{key}.material", (
                f'expected "none" (a perfect mirror), got {reader.show(material)}: named conductors are not '
                f"supported; give eta and k (Mitsuba 3.9.1's RGB Cu: eta = [{', '.join(map(str, CU_ETA))}], "
                f"k = [{', '.join(map(str, CU_K))}])"))
        given = [item for item in ("eta", "k") if item in entry]
        if given:
            raise reader.error(f"{key}.material",
                               f'expected either material = "none" or eta / k, not both (found {", ".join(given)})')
    what = f"a number or a list of 3 numbers, each in [0, {MAX_CONDUCTOR_INDEX:g}]"
    values = {}
    for item, default in (("eta", MIRROR_ETA), ("k", MIRROR_K)):
        values[item] = reader.colour_or_number(entry.get(item, list(default)), f"{key}.{item}", what)
        if not all(0.0 <= channel <= MAX_CONDUCTOR_INDEX for channel in values[item]):
            raise reader.expected(f"{key}.{item}", what, entry[item])
    for channel, (eta, k) in enumerate(zip(values["eta"], values["k"])):
        if eta == 0 and k == 0:
            where = f"{key}.eta" if "eta" in entry else f"{key}.k"
            raise reader.error(where, (
                f"eta and k are both 0 in channel {'RGB'[channel]}: a complex index of 0 has no Fresnel "
                "reflectance; expected eta > 0 or k > 0 in every channel"))
    return values


def _index_of_refraction(reader, value: Any, key: str) -> float:
    what = f"a finite number in [{MIN_IOR:g}, {MAX_IOR:g}] (an index of refraction)"
    if isinstance(value, str):
        raise reader.error(key, f"expected {what}, got {reader.show(value)}: named indices are not supported; give "
                                "the number")
    ior = reader.number(value, key, what)
    if not MIN_IOR <= ior <= MAX_IOR:
        raise reader.expected(key, what, value)
    return ior


# ---- Mitsuba's parameters and scene.json's ------------------------------------------------------------------------


def _numbers(values) -> list:
    return np.asarray(values, dtype=np.float64).tolist()


def _complex_index_parameters(material: Material) -> dict:
    if material.mirror:
        return {"material": "none"}
    return {"eta": rgb(material.eta), "k": rgb(material.k)}


def _rough_parameters(material: Material) -> dict:
    return {"alpha": float(material.alpha), "distribution": material.distribution,
            "sample_visible": bool(material.sample_visible)}


def _conductor_parameters(material: Material) -> dict:
    return {**_complex_index_parameters(material), "specular_reflectance": rgb(material.specular_reflectance)}


def _dielectric_parameters(material: Material) -> dict:
    return {"int_ior": float(material.int_ior), "ext_ior": float(material.ext_ior),
            "specular_reflectance": rgb(material.specular_reflectance),
            "specular_transmittance": rgb(material.specular_transmittance)}


def _plastic_parameters(material: Material) -> dict:
    return {"diffuse_reflectance": rgb(material.diffuse_reflectance),
            "specular_reflectance": rgb(material.specular_reflectance), "int_ior": float(material.int_ior),
            "ext_ior": float(material.ext_ior), "nonlinear": bool(material.nonlinear)}


def _plastic_json(material: Material) -> dict:
    return {"diffuse_reflectance": _numbers(material.diffuse_reflectance),
            "specular_reflectance": _numbers(material.specular_reflectance), "int_ior": float(material.int_ior),
            "ext_ior": float(material.ext_ior), "nonlinear": bool(material.nonlinear)}


def _roughplastic_parameters(material: Material) -> dict:
    return {**_plastic_parameters(material), **_rough_parameters(material)}


def _roughplastic_json(material: Material) -> dict:
    return {**_plastic_json(material), **_rough_parameters(material)}


def _conductor_json(material: Material) -> dict:
    return {"eta": _numbers(material.eta), "k": _numbers(material.k),
            "specular_reflectance": _numbers(material.specular_reflectance)}


def _dielectric_json(material: Material) -> dict:
    return {"int_ior": float(material.int_ior), "ext_ior": float(material.ext_ior),
            "specular_reflectance": _numbers(material.specular_reflectance),
            "specular_transmittance": _numbers(material.specular_transmittance)}


# ---- glTF's material and what it loses ---------------------------------------------------------------------------


#: What glTF's metallic-roughness model and its extensions cannot say exactly of a material, by key, in the order the
#: export lists them; ``{materials}`` is the list of the materials that lose it.
GLTF_LOSSES: dict[str, str] = {
    "fresnel": ("glTF metals have Schlick's Fresnel from a base colour: {materials} written with base colour = "
                "normal-incidence reflectance x specular_reflectance (eta, k in the node's extras)"),
    "beckmann": "glTF's microfacets are GGX: {materials} (beckmann) written with roughness sqrt(alpha)",
    "tint": "glTF's transmission has no reflection tint: specular_reflectance of {materials} left out",
    "culled": "glTF's single-sided materials are culled from behind, not black: {materials}",
    "thin": ("glTF's thin-walled transmission (KHR_materials_volume absent) reflects as one interface, not as the "
             "sheet's two, R' = 2 F / (1 + F): {materials}"),
    "blend": ("glTF has no blend of materials: {materials} written as the material of the larger weight"),
    "mask": ("glTF's alpha blending is not a cut-out's hole: {materials} written as the nested material with alphaMode "
             "BLEND and the opacity as base colour alpha"),
    "back": "glTF has one material per side pair: {materials} written as the front material, double-sided",
    "burley": ("glTF's metallic-roughness model is not Burley's principled one: {materials} written with its base "
               "colour, metallic, roughness and the clearcoat, sheen, transmission, ior and specular extensions "
               "(approximately); its retro-reflection, flatness, anisotropy and sampling rates lost"),
    "null": ("glTF has no index-matched boundary (Mitsuba's null BSDF, a medium's surface): {materials} written as a "
             "transparent material (base colour alpha 0, alphaMode BLEND), its medium left out"),
    "coating": ("glTF's dielectric base (metallic 0) has no light reflected back and forth under its coating: "
                "{materials} written with base colour = diffuse_reflectance (the 1 / (1 - F_dr) term and nonlinear "
                "lost)"),
}
_WHITE = (1.0, 1.0, 1.0)


def normal_incidence_reflectance(eta, k) -> list[float]:
    """A conductor's Fresnel reflectance at normal incidence, per channel: ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)
    (1 for Mitsuba's perfect mirror eta = 0, k = 1)."""
    eta, k = np.asarray(eta, dtype=np.float64), np.asarray(k, dtype=np.float64)
    return [float(x) for x in ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)]


def _diffuse_gltf(material: Material) -> tuple[dict, dict]:
    """Base colour = reflectance, metallic 0, roughness 1."""
    return {"baseColorFactor": [*material.reflectance, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}, {}


def _conductor_gltf(material: Material, roughness: float) -> tuple[dict, dict]:
    """Metallic 1, base colour = the normal-incidence Fresnel reflectance times specular_reflectance (exact for a
    perfect mirror; glTF's Schlick Fresnel approximates the others)."""
    f0 = normal_incidence_reflectance(material.eta, material.k)
    colour = [min(1.0, f * r) for f, r in zip(f0, material.specular_reflectance)]
    return {"baseColorFactor": [*colour, 1.0], "metallicFactor": 1.0, "roughnessFactor": roughness}, {}


def _dielectric_gltf(material: Material, roughness: float) -> tuple[dict, dict]:
    """Metallic 0, base colour = specular_transmittance, ``KHR_materials_transmission`` 1, ``KHR_materials_ior`` =
    int_ior / ext_ior (glTF's outside is index 1, so the relative index keeps the interface),
    ``KHR_materials_volume`` (a solid that refracts, not a thin wall)."""
    extensions = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                  "KHR_materials_ior": {"ior": float(material.int_ior / material.ext_ior)},
                  "KHR_materials_volume": {"thicknessFactor": 1.0}}
    return {"baseColorFactor": [*material.specular_transmittance, 1.0], "metallicFactor": 0.0,
            "roughnessFactor": roughness}, extensions


def _thindielectric_gltf(material: Material) -> tuple[dict, dict]:
    """Metallic 0, roughness 0, base colour = specular_transmittance, ``KHR_materials_transmission`` 1,
    ``KHR_materials_ior`` = int_ior / ext_ior, no ``KHR_materials_volume`` (glTF's thin-walled material: light
    passes straight through)."""
    extensions = {"KHR_materials_transmission": {"transmissionFactor": 1.0},
                  "KHR_materials_ior": {"ior": float(material.int_ior / material.ext_ior)}}
    return {"baseColorFactor": [*material.specular_transmittance, 1.0], "metallicFactor": 0.0,
            "roughnessFactor": 0.0}, extensions


def _plastic_gltf(material: Material) -> tuple[dict, dict]:
    """Metallic 0, roughness 0 (a smooth dielectric over a diffuse base), base colour = diffuse_reflectance,
    ``KHR_materials_ior`` = int_ior / ext_ior and, where specular_reflectance is not white,
    ``KHR_materials_specular``'s specularColorFactor = specular_reflectance (the tint of the coating's Fresnel)."""
    extensions: dict = {"KHR_materials_ior": {"ior": float(material.int_ior / material.ext_ior)}}
    if material.specular_reflectance != _WHITE:
        extensions["KHR_materials_specular"] = {"specularColorFactor": _numbers(material.specular_reflectance)}
    return {"baseColorFactor": [*material.diffuse_reflectance, 1.0], "metallicFactor": 0.0,
            "roughnessFactor": 0.0}, extensions


def _roughplastic_gltf(material: Material) -> tuple[dict, dict]:
    """As :func:`_plastic_gltf`, with roughness sqrt(alpha) (glTF's dielectric specular is GGX of alpha =
    roughness^2)."""
    factors, extensions = _plastic_gltf(material)
    return {**factors, "roughnessFactor": _rough_gltf_roughness(material)}, extensions
def _principled_gltf(material: Material) -> tuple[dict, dict]:
    """glTF's metallic-roughness of a principled material: base colour, metallic and roughness directly (glTF's GGX
    alpha is roughness^2, as principled's); the rest where an extension carries it: ``KHR_materials_ior`` = eta,
    ``KHR_materials_transmission`` = spec_trans (with ``KHR_materials_volume``: a solid that refracts),
    ``KHR_materials_clearcoat`` = clearcoat with roughness sqrt(alpha_cc), alpha_cc = 0.1 (1 - gloss) + 0.001 gloss
    (GTR1's alpha read as GGX's), ``KHR_materials_sheen`` = sheen x the tinted sheen colour (roughness 0.5: glTF's
    Charlie sheen is not Burley's Schlick-weighted one), ``KHR_materials_specular``'s specularColorFactor = the
    tinted F0 scale (1 - spec_tint) + spec_tint base_color / luminance(base_color)."""
    p = material.principled
    base = np.asarray(p.base_color, dtype=np.float64)
    lum = float(base @ np.array([0.212671, 0.715160, 0.072169]))
    tint = base / lum if lum > 0 else np.ones(3)
    extensions: dict = {"KHR_materials_ior": {"ior": float(p.eta)}}
    if p.spec_trans > 0 or material.texture("spec_trans") is not None:
        extensions["KHR_materials_transmission"] = {"transmissionFactor": float(p.spec_trans)}
        extensions["KHR_materials_volume"] = {"thicknessFactor": 1.0}
    if p.clearcoat > 0:
        alpha_cc = 0.1 * (1.0 - p.clearcoat_gloss) + 0.001 * p.clearcoat_gloss
        extensions["KHR_materials_clearcoat"] = {"clearcoatFactor": float(p.clearcoat),
                                                 "clearcoatRoughnessFactor": float(math.sqrt(alpha_cc))}
    if p.sheen > 0:
        colour = p.sheen * ((1.0 - p.sheen_tint) + p.sheen_tint * tint)
        extensions["KHR_materials_sheen"] = {"sheenColorFactor": _numbers(np.minimum(colour, 1.0)),
                                             "sheenRoughnessFactor": 0.5}
    if p.spec_tint > 0:
        extensions["KHR_materials_specular"] = {
            "specularColorFactor": _numbers((1.0 - p.spec_tint) + p.spec_tint * tint)}
    return {"baseColorFactor": [*map(float, base), 1.0], "metallicFactor": float(p.metallic),
            "roughnessFactor": float(p.roughness)}, extensions


def _principled_gltf_losses(material: Material) -> tuple[str, ...]:
    return ("burley",) + (() if _principled_transmits(material) else ("culled",))


def _rough_gltf_roughness(material: Material) -> float:
    """glTF's roughness of a rough type: sqrt(alpha) (glTF's GGX alpha is roughness^2: exact for ggx)."""
    return math.sqrt(material.alpha)


def _conductor_gltf_losses(material: Material) -> tuple[str, ...]:
    """A conductor loses its Fresnel unless it is a white perfect mirror, and its back side unless two-sided."""
    fresnel = () if material.mirror and material.specular_reflectance == _WHITE else ("fresnel",)
    return fresnel + (() if material.two_sided else ("culled",))


def _beckmann_gltf_losses(material: Material) -> tuple[str, ...]:
    return ("beckmann",) if material.distribution == "beckmann" else ()


def _dielectric_gltf_losses(material: Material) -> tuple[str, ...]:
    return ("tint",) if material.specular_reflectance != _WHITE else ()


def _thindielectric_gltf_losses(material: Material) -> tuple[str, ...]:
    return ("thin",) + _dielectric_gltf_losses(material)


def _plastic_gltf_losses(material: Material) -> tuple[str, ...]:
    return ("coating",) + (() if material.two_sided else ("culled",))


_CONDUCTOR_KEYS = ("type", "material", "eta", "k", "specular_reflectance", "two_sided")
_PLASTIC_KEYS = ("type", "diffuse_reflectance", "specular_reflectance", "int_ior", "ext_ior", "nonlinear",
                 "two_sided")
_DIELECTRIC_KEYS = ("type", "int_ior", "ext_ior", "specular_reflectance", "specular_transmittance")
_ROUGH_KEYS = ("alpha", "distribution", "sample_visible")
_NOT_TWO_SIDED = (("two_sided", "light crosses it from either side (Mitsuba's twosided wrapper takes no "
                                "transmitting BSDF); int_ior is the index behind the front side, ext_ior the one in "
                                "front"),)
_PRINCIPLED_KEYS = ("type", "base_color", "roughness", "metallic", "specular", "eta", "spec_tint", "anisotropic",
                    "sheen", "sheen_tint", "clearcoat", "clearcoat_gloss", "spec_trans", "flatness",
                    "main_specular_sampling_rate", "clearcoat_sampling_rate", "diffuse_reflectance_sampling_rate")
_PRINCIPLED_NOT_TWO_SIDED = (("two_sided", "Mitsuba's principled reflects on its front side and, where spec_trans "
                                           "> 0, transmits from both (its twosided wrapper is not taken here)"),)
_THIN_NOT_TWO_SIDED = (("two_sided", "a thin sheet is two-sided by nature (both sides reflect and transmit "
                                     "alike)"),)

def _null_gltf(material: Material) -> tuple[dict, dict]:
    """A fully transparent material (base colour alpha 0; the export blends it, alphaMode BLEND)."""
    return {"baseColorFactor": [1.0, 1.0, 1.0, 0.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}, {}


#: Every material type by its name, in :data:`harness.scene.model.MATERIAL_TYPES`'s order.
MATERIALS: dict[str, MaterialKind] = {kind.name: kind for kind in (
    MaterialKind("diffuse", core.DIFFUSE, ("type", "reflectance", "two_sided"), _read_diffuse,
                 parameters=lambda m: {"reflectance": rgb(m.reflectance)},
                 json=lambda m: {"reflectance": _numbers(m.reflectance)}, gltf=_diffuse_gltf,
                 textured=("reflectance",)),
    MaterialKind("conductor", core.CONDUCTOR, _CONDUCTOR_KEYS, _read_conductor,
                 parameters=_conductor_parameters, json=_conductor_json,
                 gltf=lambda m: _conductor_gltf(m, 0.0), gltf_losses=_conductor_gltf_losses,
                 textured=("specular_reflectance",), gltf_base="specular_reflectance"),
    MaterialKind("roughconductor", core.ROUGHCONDUCTOR, _CONDUCTOR_KEYS + _ROUGH_KEYS,
                 lambda reader, entry, key: {**_read_conductor(reader, entry, key),
                                             **_roughness(reader, entry, key)},
                 parameters=lambda m: {**_conductor_parameters(m), **_rough_parameters(m)},
                 json=lambda m: {**_conductor_json(m), **_rough_parameters(m)},
                 gltf=lambda m: _conductor_gltf(m, _rough_gltf_roughness(m)),
                 gltf_losses=lambda m: _conductor_gltf_losses(m) + _beckmann_gltf_losses(m),
                 textured=("specular_reflectance", "alpha"), gltf_base="specular_reflectance"),
    MaterialKind("dielectric", core.DIELECTRIC, _DIELECTRIC_KEYS, _read_dielectric,
                 parameters=_dielectric_parameters, json=_dielectric_json,
                 gltf=lambda m: _dielectric_gltf(m, 0.0), refused=_NOT_TWO_SIDED,
                 gltf_losses=_dielectric_gltf_losses, textured=("specular_reflectance", "specular_transmittance"),
                 gltf_base="specular_transmittance"),
    MaterialKind("roughdielectric", core.ROUGHDIELECTRIC, _DIELECTRIC_KEYS + _ROUGH_KEYS, _read_roughdielectric,
                 parameters=lambda m: {**_dielectric_parameters(m), **_rough_parameters(m)},
                 json=lambda m: {**_dielectric_json(m), **_rough_parameters(m)},
                 gltf=lambda m: _dielectric_gltf(m, _rough_gltf_roughness(m)), refused=_NOT_TWO_SIDED,
                 gltf_losses=lambda m: _beckmann_gltf_losses(m) + _dielectric_gltf_losses(m),
                 textured=("specular_reflectance", "specular_transmittance", "alpha"),
                 gltf_base="specular_transmittance"),
    MaterialKind("thindielectric", core.THINDIELECTRIC, _DIELECTRIC_KEYS, _read_dielectric,
                 parameters=_dielectric_parameters, json=_dielectric_json, gltf=_thindielectric_gltf,
                 refused=_THIN_NOT_TWO_SIDED, gltf_losses=_thindielectric_gltf_losses,
                 textured=("specular_reflectance", "specular_transmittance"), gltf_base="specular_transmittance"),
    MaterialKind("plastic", core.PLASTIC, _PLASTIC_KEYS, _read_plastic, parameters=_plastic_parameters,
                 json=_plastic_json, gltf=_plastic_gltf, gltf_losses=_plastic_gltf_losses,
                 textured=("diffuse_reflectance", "specular_reflectance"), gltf_base="diffuse_reflectance"),
    MaterialKind("roughplastic", core.ROUGHPLASTIC, _PLASTIC_KEYS + _ROUGH_KEYS, _read_roughplastic,
                 parameters=_roughplastic_parameters, json=_roughplastic_json, gltf=_roughplastic_gltf,
                 gltf_losses=lambda m: _plastic_gltf_losses(m) + _beckmann_gltf_losses(m),
                 textured=("diffuse_reflectance", "specular_reflectance"), gltf_base="diffuse_reflectance"),
    MaterialKind("principled", core.PRINCIPLED, _PRINCIPLED_KEYS, _read_principled,
                 parameters=_principled_parameters, json=_principled_json, gltf=_principled_gltf,
                 refused=_PRINCIPLED_NOT_TWO_SIDED, gltf_losses=_principled_gltf_losses,
                 textured=("base_color",) + core.PRINCIPLED_UNIT, gltf_base="base_color"),
    # Mitsuba's null BSDF: no keys; light crosses it unchanged (it passes everything: reflectance, the bound of one
    # bounce, is 1)
    MaterialKind("null", core.NULL, ("type",), lambda reader, entry, key: {"reflectance": _WHITE},
                 parameters=lambda m: {}, json=lambda m: {}, gltf=_null_gltf, gltf_losses=lambda m: ("null",)),
)}
assert tuple(MATERIALS) == MATERIAL_TYPES
#: Every key of any type, for did-you-mean hints.
MATERIAL_KEYS = tuple(dict.fromkeys(key for kind in MATERIALS.values() for key in kind.keys))
