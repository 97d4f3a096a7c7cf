"""The medium types of a ``[media.NAME]`` table (Mitsuba 3's medium plugins of the same names and parameters,
docs/scene-format.md, "Participating media"), one :class:`MediumKind` each in :data:`MEDIA`: its keys and their
reading, its row of the core's media table (:mod:`reference_impl.media`, whose defaults are the model's), its Mitsuba
plugin and its scene.json entry.

A homogeneous medium attenuates a ray by the transmittance T(t) = exp(-sigma_t scale t) per channel (Beer-Lambert;
Pharr, Jakob and Humphreys, *Physically Based Rendering*, 4th ed., section 11.2) and scatters a fraction ``albedo``
of what it attenuates by its phase function: ``isotropic``, p = 1 / (4 pi), or Henyey-Greenstein,
p(cos) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^(3/2)) (PBRT 4th ed., section 11.3.1), Mitsuba's ``hg``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

from reference_impl import media as core

from harness.scene.kinds.mitsuba_values import rgb
from harness.scene.model import MEDIUM_TYPES, PHASE_TYPES, Medium

DEFAULT_TYPE = "homogeneous"
DEFAULT_PHASE = "isotropic"
#: Mitsuba's medium plugins the scene format refuses, with the reason (one line at the table's ``type``).
REFUSED_TYPES = {"heterogeneous": "not supported yet (a grid volume's density: issue 38 takes homogeneous media only)"}
#: The keys of a ``phase`` table by its type (``type`` aside).
PHASE_KEYS = {"isotropic": (), "hg": ("g",)}
#: The core's phase function of each Mitsuba phase plugin.
CORE_PHASES = {"isotropic": core.ISOTROPIC, "hg": core.HG}
assert tuple(PHASE_KEYS) == PHASE_TYPES


@dataclass(frozen=True)
class MediumKind:
    """One medium type.

    Attributes
    ----------
    name : str
        The ``type`` value (Mitsuba's plugin name).
    keys : tuple of str
        The keys its table may hold.
    read : callable
        ``read(reader, entry, key) -> dict``: the :class:`~harness.scene.model.Medium` fields of the table ``entry``
        at key path ``key`` but ``name`` and ``type``, read with the scene reader's typed readers (``reader``:
        :class:`harness.scene.load._SceneReader`); a bad value is its one-line HarnessError.
    """

    name: str
    keys: tuple[str, ...]
    read: Callable[[Any, dict, str], dict]

    def to_core(self, medium: Medium) -> dict:
        """The core's row of ``medium`` (:class:`reference_impl.media.Media`'s columns): ``sigma_t`` (the
        extinction, Mitsuba's sigma_t x scale), ``albedo``, ``phase`` (:data:`CORE_PHASES`) and ``g``."""
        return {"sigma_t": medium.extinction, "albedo": tuple(medium.albedo), "phase": CORE_PHASES[medium.phase],
                "g": float(medium.g) if medium.phase == "hg" else 0.0}

    def to_mitsuba(self, medium: Medium) -> dict:
        """Mitsuba's plugin of ``medium``, every parameter written out: ``sigma_t`` and ``albedo`` as ``rgb``,
        ``scale`` and the ``phase`` plugin (``{"type": "hg", "g": g}`` or ``{"type": "isotropic"}``)."""
        return {"type": self.name, "albedo": rgb(medium.albedo), "sigma_t": rgb(medium.sigma_t),
                "scale": float(medium.scale), "phase": phase_plugin(medium)}

    def to_scene_json(self, medium: Medium) -> dict:
        """The scene.json entry of ``medium`` (docs/scene-json.md): ``sigma_t`` with ``scale`` applied."""
        return {"type": self.name, "sigma_t": [float(v) for v in medium.extinction],
                "albedo": [float(v) for v in medium.albedo], "phase": phase_plugin(medium)}


def phase_plugin(medium: Medium) -> dict:
    """Mitsuba's phase plugin (and the scene.json ``phase``): ``{"type": "isotropic"}`` or ``{"type": "hg", "g":
    g}``."""
    if medium.phase == "hg":
        return {"type": "hg", "g": float(medium.g)}
    return {"type": "isotropic"}


def read_media(reader, document: dict) -> dict[str, Medium]:
    """The ``[media]`` table: each ``[media.NAME]`` read by its type's entry, in the file's order."""
    table = reader.table(document.get("media", {}), "media")
    return {name: read_medium(reader, name, entry) for name, entry in table.items()}


def read_medium(reader, name: str, entry: Any) -> Medium:
    """One ``[media.NAME]`` table: its type (default homogeneous; ``heterogeneous`` refused in one line) and that
    type's keys.

    Parameters
    ----------
    reader : harness.scene.load._SceneReader
        The scene reader (its typed readers and errors).
    name : str
        The table's name.
    entry : object
        The parsed table.

    Returns
    -------
    Medium
    """
    key = reader.join("media", name)
    entry = reader.table(entry, key)
    kind_name = entry.get("type", DEFAULT_TYPE)
    if isinstance(kind_name, str) and kind_name in REFUSED_TYPES:
        raise reader.error(f"{key}.type", f"medium type {kind_name!r} is {REFUSED_TYPES[kind_name]}; expected "
                                          f"one of {', '.join(MEDIA)}")
    kind = MEDIA[reader.choice(kind_name, f"{key}.type", tuple(MEDIA))]
    reader.check_keys(entry, kind.keys, key)
    return Medium(name, type=kind.name, **kind.read(reader, entry, key))


def _unit_rgb(reader, entry: dict, item: str, key: str, default) -> tuple[float, float, float]:
    """A float or [r, g, b], each in [0, 1] (an albedo)."""
    what = "a number or a list of 3 numbers, each in [0, 1]"
    raw = entry.get(item, list(default))
    value = reader.colour_or_number(raw, f"{key}.{item}", what)
    if not all(0.0 <= v <= 1.0 for v in value):
        raise reader.expected(f"{key}.{item}", what, raw)
    return value


def _read_homogeneous(reader, entry: dict, key: str) -> dict:
    """``albedo`` in [0, 1], ``sigma_t`` >= 0 and finite, ``scale`` > 0, with sigma_t x scale at most the core's
    :data:`reference_impl.media.MAX_SIGMA_T`; ``phase``."""
    albedo = _unit_rgb(reader, entry, "albedo", key, core.DEFAULT_ALBEDO)
    what = "a number or a list of 3 numbers, each >= 0 and finite (per unit length)"
    raw = entry.get("sigma_t", core.DEFAULT_SIGMA_T)
    sigma_t = reader.colour_or_number(raw, f"{key}.sigma_t", what)
    if not all(v >= 0.0 for v in sigma_t):
        raise reader.expected(f"{key}.sigma_t", what, raw)
    scale = float(reader.positive(entry.get("scale", core.DEFAULT_SCALE), f"{key}.scale"))
    extinction = max(sigma_t) * scale
    if not (math.isfinite(extinction) and extinction <= core.MAX_SIGMA_T):
        raise reader.error(f"{key}.sigma_t", f"sigma_t x scale reaches {extinction:.6g} per unit length; expected "
                                             f"at most {core.MAX_SIGMA_T:g}")
    return {"albedo": albedo, "sigma_t": sigma_t, "scale": scale, **_read_phase(reader, entry, key)}


def _read_phase(reader, entry: dict, key: str) -> dict:
    """``phase = { type = "isotropic" }`` (the default) or ``{ type = "hg", g = G }``, g in (-1, 1)."""
    if "phase" not in entry:
        return {"phase": DEFAULT_PHASE, "g": core.DEFAULT_G}
    phase_key = f"{key}.phase"
    table = reader.table(entry["phase"], phase_key)
    phase = reader.choice(reader.require(table, "type", phase_key, "isotropic or hg"), f"{phase_key}.type",
                          PHASE_TYPES)
    reader.check_keys(table, ("type", *PHASE_KEYS[phase]), phase_key)
    g = core.DEFAULT_G
    if phase == "hg":
        what = "a number in (-1, 1) (g > 0 scatters forward)"
        g = reader.number(table.get("g", core.DEFAULT_G), f"{phase_key}.g", what)
        if not -1.0 < g < 1.0:
            raise reader.expected(f"{phase_key}.g", what, table["g"])
    return {"phase": phase, "g": g}


#: Every medium type by its name, in :data:`harness.scene.model.MEDIUM_TYPES`'s order.
MEDIA: dict[str, MediumKind] = {kind.name: kind for kind in (
    MediumKind("homogeneous", ("type", "albedo", "sigma_t", "scale", "phase"), _read_homogeneous),
)}
assert tuple(MEDIA) == MEDIUM_TYPES
