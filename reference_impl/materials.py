"""The material table of the core: one row per material, as plain arrays the BSDF kernels read.

Each material is a kind (:data:`DIFFUSE`, :data:`CONDUCTOR`, :data:`ROUGHCONDUCTOR`, :data:`DIELECTRIC`,
:data:`ROUGHDIELECTRIC`, :data:`THINDIELECTRIC`, :data:`PLASTIC`, :data:`ROUGHPLASTIC`, :data:`PRINCIPLED`, Mitsuba 3's
plugins
``diffuse``, ``conductor``, ``roughconductor``, ``dielectric``, ``roughdielectric``, ``thindielectric``, ``plastic``,
``roughplastic``, ``principled``; and the composites, :data:`COMPOSITES`) and a row of :data:`NUM_PARAMS` float64 numbers whose columns are the ``P_*`` constants below.
A rough plastic also has a table (:data:`LUT_SIZE` numbers: its coating's transmittance over cos theta and its
internal reflectance, from alpha, the distribution and eta: ``reference_impl.kernels.bsdf.roughplastic_luts``, which
the kernels' ``MaterialTables.lut`` holds) that the material step appends to the hit's row, after its NUM_PARAMS
columns (:data:`ROW_SIZE`, :data:`P_LUT`).
The kernels of :mod:`reference_impl.kernels.bsdf` evaluate and sample them; the harness builds the table from the
scene's ``[materials.NAME]`` in the order ``Geometry.material`` indexes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_impl.errors import SettingsError
from reference_impl.textures import Bitmap, Textures

DIFFUSE, CONDUCTOR, ROUGHCONDUCTOR, DIELECTRIC, ROUGHDIELECTRIC, THINDIELECTRIC, PLASTIC = range(7)
#: Reserved for issue 36's other plugins (each joins KIND_NAMES with its kernels): ``roughplastic``, ``principled``.
ROUGHPLASTIC, PRINCIPLED = 7, 8
#: The kinds made of other materials (Mitsuba's ``blendbsdf``, ``mask`` and ``twosided`` with its own nested
#: materials): their rows name the nested materials' rows (:data:`P_NESTED`), and the material step
#: (kernels/material.py) resolves them to one of the kinds above at each hit.
BLENDBSDF, MASK, TWOSIDED = 9, 10, 11
COMPOSITES = (BLENDBSDF, MASK, TWOSIDED)
#: Mitsuba's ``null`` BSDF: an index-matched boundary that light crosses unchanged (a medium's surface); not a
#: vertex of the path (the volumetric path loop, kernels/volpath.py, passes it; its row reads nothing)
NULL = 12
#: Mitsuba's plugin name of each kind.
KIND_NAMES = {DIFFUSE: "diffuse", CONDUCTOR: "conductor", ROUGHCONDUCTOR: "roughconductor",
              DIELECTRIC: "dielectric", ROUGHDIELECTRIC: "roughdielectric", THINDIELECTRIC: "thindielectric",
              PLASTIC: "plastic", ROUGHPLASTIC: "roughplastic", PRINCIPLED: "principled", BLENDBSDF: "blendbsdf",
              MASK: "mask", TWOSIDED: "twosided", NULL: "null"}
#: The kinds that light crosses (the path loop's ``transmits``; no ``two_sided`` flag: both sides by nature).
TRANSMITTING = (DIELECTRIC, ROUGHDIELECTRIC, THINDIELECTRIC)
BECKMANN, GGX = 0, 1
DISTRIBUTIONS = {"beckmann": BECKMANN, "ggx": GGX}

# Columns of Materials.params.
P_REFLECTANCE = 0  # 0-2: reflectance (diffuse) | specular_reflectance (the others, plastic's coating included)
P_ETA = 3  # 3-5: conductor eta (real part of the complex index), per channel
P_K = 6  # 6-8: conductor k (imaginary part)
P_TRANSMITTANCE = 9  # 9-11: specular_transmittance (dielectrics, thindielectric)
P_ALPHA = 12  # microfacet roughness (rough kinds)
P_DISTRIBUTION = 13  # BECKMANN | GGX
P_SAMPLE_VISIBLE = 14  # 1: visible-normal sampling, 0: sampling of D(m) cos(theta_m)
P_IOR = 15  # dielectrics, thindielectric, plastic: eta = int_ior / ext_ior
P_TWO_SIDED = 16  # 1: Mitsuba's twosided wrapper (diffuse, conductors and plastic only)
P_MIRROR = 17  # 1: conductor with material = "none" (Fresnel = 1)
P_PERTURB = 18  # PERTURB_NONE | PERTURB_NORMALMAP | PERTURB_BUMPMAP: Mitsuba's normalmap / bumpmap around the kind
P_BUMP_SCALE = 19  # bumpmap: scale
P_NORMAL = 20  # 20-22: normalmap: the tangent-space normal's texture value (rgb, n = 2 rgb - 1), at a hit the texture's
P_FLIP_INVALID = 23  # normalmap, bumpmap: 1: flip_invalid_normals
P_SHADOWING = 24  # normalmap, bumpmap: 1: use_shadowing_function (the shadow terminator)
# plastic's own parameters, in columns no plastic reads otherwise (a conductor's eta and k)
P_DIFFUSE = P_ETA  # 3-5: plastic's diffuse_reflectance
P_NONLINEAR = P_K  # 6: plastic: 1: nonlinear (diff / (1 - diff F_dr)), 0: diff / (1 - F_dr)
P_SPECULAR_WEIGHT = P_K + 1  # 7: plastic: Mitsuba's specular_sampling_weight s_mean / (d_mean + s_mean)
# the composites' columns (their rows read nothing else)
P_WEIGHT = P_ALPHA  # 12: blendbsdf's weight (of its second material), mask's opacity
P_NESTED = P_ETA  # 3-4: the rows of the nested materials (blendbsdf: bsdf_0, bsdf_1; mask: its one, twice;
#                   twosided: the front's, the back's)
# principled's own parameters, in columns no principled reads otherwise (its base_color is P_REFLECTANCE, its eta
# P_IOR; the map columns 18-24 keep their meaning)
P_METALLIC = P_ETA  # 3
P_SPEC_TINT = P_ETA + 1  # 4
P_ANISOTROPIC = P_ETA + 2  # 5
P_SHEEN = P_K  # 6
P_SHEEN_TINT = P_K + 1  # 7
P_CLEARCOAT = P_K + 2  # 8
P_CLEARCOAT_GLOSS = P_TRANSMITTANCE  # 9
P_SPEC_TRANS = P_TRANSMITTANCE + 1  # 10
P_FLATNESS = P_TRANSMITTANCE + 2  # 11
P_ROUGHNESS = P_ALPHA  # 12
P_SPECULAR_RATE = P_DISTRIBUTION  # 13: main_specular_sampling_rate
P_CLEARCOAT_RATE = P_SAMPLE_VISIBLE  # 14: clearcoat_sampling_rate
P_DIFFUSE_RATE = P_MIRROR  # 17: diffuse_reflectance_sampling_rate
NUM_PARAMS = 26  # 25 spare
# roughplastic: its table (Mitsuba's roughplastic.cpp precomputes it in parameters_changed), not in the material
# table's row but in MaterialTables.lut, which the material step copies into the hit's row after the NUM_PARAMS columns
LUT_RES = 64  # MI_ROUGH_TRANSMITTANCE_RES: the external transmittance at cos theta = max(1e-6, i / 63), i = 0 .. 63
LUT_SIZE = LUT_RES + 1  # ... and the internal reflectance
P_LUT = NUM_PARAMS  # in the hit's row: LUT_RES transmittances, then the internal reflectance
P_INTERNAL_REFLECTANCE = P_LUT + LUT_RES
ROW_SIZE = NUM_PARAMS + LUT_SIZE  # the length of the row buffer a glossy engine gives the material step

PERTURB_NONE, PERTURB_NORMALMAP, PERTURB_BUMPMAP = 0, 1, 2
#: Mitsuba's plugin name of each perturbation.
PERTURB_NAMES = {PERTURB_NORMALMAP: "normalmap", PERTURB_BUMPMAP: "bumpmap"}

#: The parameters a texture may drive (Mitsuba's texture-valued parameters): their first column and channel count,
#: in the order of the columns of ``Materials.texture``. The bump map's height (channels 0) is not written into the
#: row: its gradient is looked up where the frame is perturbed (kernels/shading.py).
TEXTURE_SLOTS = {"reflectance": (P_REFLECTANCE, 3), "transmittance": (P_TRANSMITTANCE, 3), "alpha": (P_ALPHA, 1),
                 "normalmap": (P_NORMAL, 3), "bumpmap": (P_BUMP_SCALE, 0), "diffuse": (P_DIFFUSE, 3),
                 # principled's one-number parameters (its base_color is the reflectance slot)
                 "roughness": (P_ROUGHNESS, 1), "metallic": (P_METALLIC, 1), "spec_tint": (P_SPEC_TINT, 1),
                 "anisotropic": (P_ANISOTROPIC, 1), "sheen": (P_SHEEN, 1), "sheen_tint": (P_SHEEN_TINT, 1),
                 "clearcoat": (P_CLEARCOAT, 1), "clearcoat_gloss": (P_CLEARCOAT_GLOSS, 1),
                 "spec_trans": (P_SPEC_TRANS, 1), "flatness": (P_FLATNESS, 1),
                 "weight": (P_WEIGHT, 1)}
#: principled's one-number parameters in [0, 1] (the slots of the same names).
PRINCIPLED_UNIT = ("roughness", "metallic", "spec_tint", "anisotropic", "sheen", "sheen_tint", "clearcoat",
                   "clearcoat_gloss", "spec_trans", "flatness")
NUM_SLOTS = len(TEXTURE_SLOTS)

#: Mitsuba 3.9.1's defaults (its plugins' constructors, src/bsdfs/*.cpp): alpha 0.1, the Beckmann distribution with
#: visible-normal sampling, int_ior "bk7" = 1.5046, ext_ior "air" = 1.000277, specular_* = 1; a conductor's material
#: "none" (eta = 0, k = 1: Fresnel = 1, a perfect mirror).
DEFAULT_ALPHA = 0.1
DEFAULT_DISTRIBUTION = "beckmann"
DEFAULT_SAMPLE_VISIBLE = True
DEFAULT_INT_IOR = 1.5046
DEFAULT_EXT_IOR = 1.000277
DEFAULT_SPECULAR = (1.0, 1.0, 1.0)
#: Mitsuba 3.9.1's plastic (src/bsdfs/plastic.cpp): int_ior "polypropylene" = 1.49, diffuse_reflectance 0.5,
#: nonlinear false.
PLASTIC_INT_IOR = 1.49
DEFAULT_DIFFUSE = (0.5, 0.5, 0.5)
DEFAULT_NONLINEAR = False
#: Mitsuba 3.9.1's blendbsdf and mask (src/bsdfs/blendbsdf.cpp, mask.cpp): weight (required there) and opacity
#: default 0.5.
DEFAULT_WEIGHT = 0.5
MIRROR_ETA = (0.0, 0.0, 0.0)
MIRROR_K = (1.0, 1.0, 1.0)
#: Mitsuba 3.9.1's principled (src/bsdfs/principled.cpp): base_color 0.5, roughness 0.5, specular 0.5 (eta from it,
#: :func:`principled_eta`), every other weight 0, the three sampling rates 1.
PRINCIPLED_DEFAULTS = {"base_color": (0.5, 0.5, 0.5), "roughness": 0.5, "metallic": 0.0, "spec_tint": 0.0,
                       "anisotropic": 0.0, "sheen": 0.0, "sheen_tint": 0.0, "clearcoat": 0.0, "clearcoat_gloss": 0.0,
                       "spec_trans": 0.0, "flatness": 0.0, "specular": 0.5, "main_specular_sampling_rate": 1.0,
                       "clearcoat_sampling_rate": 1.0, "diffuse_reflectance_sampling_rate": 1.0}


@dataclass(frozen=True, eq=False)
class Materials:
    """The materials of a scene.

    Attributes
    ----------
    kind : (M,) int64
        :data:`DIFFUSE` .. :data:`ROUGHPLASTIC`.
    params : (M, NUM_PARAMS) float64
        The columns ``P_*`` of this module; columns a kind does not use are ignored (keep them 0).
    texture : (M, NUM_SLOTS) int64, optional
        Per material and :data:`TEXTURE_SLOTS` entry: the texture of ``textures`` that drives that parameter (its
        value at a hit replaces the row's columns; a one-channel parameter takes the texture's first channel), -1
        where none does. None: no texture anywhere.
    textures : reference_impl.textures.Textures, optional
        The textures ``texture`` names.

    Validation (:class:`SettingsError` naming ``materials.kind`` or ``materials.params``): known kinds; finite
    parameters; reflectances and transmittances in [0, 1]; alpha > 0 on rough kinds; eta > 0 on dielectrics, the
    thin dielectric and the plastics (and != 1 on the rough ones, as Mitsuba); k >= 0 on conductors; the distribution,
    sample_visible, two_sided, mirror and nonlinear flags 0 or 1; two_sided 0 on the kinds light crosses; plastic's
    diffuse_reflectance in [0, 1] and its specular sampling weight in (0, 1]; no texture for a rough plastic's alpha
    (Mitsuba's roughplastic takes a float).
    """

    kind: np.ndarray
    params: np.ndarray
    texture: np.ndarray | None = None
    textures: Textures | None = None

    def __post_init__(self) -> None:
        kind = np.ascontiguousarray(self.kind, dtype=np.int64).reshape(-1)
        params = np.ascontiguousarray(self.params, dtype=np.float64)
        if params.ndim != 2 or params.shape != (len(kind), NUM_PARAMS):
            raise SettingsError("materials.params", f"expected an array of shape ({len(kind)}, {NUM_PARAMS}), "
                                f"got {params.shape}")
        if not np.all(np.isin(kind, list(KIND_NAMES))):
            raise SettingsError("materials.kind", f"expected kinds {', '.join(map(str, KIND_NAMES))} "
                                f"({', '.join(KIND_NAMES.values())})")
        _check_params(kind, params)
        texture, textures = _check_textures(kind, self.texture, self.textures)
        _check_perturbations(params, texture, textures)
        object.__setattr__(self, "texture", texture)
        object.__setattr__(self, "textures", textures)
        params.setflags(write=False)
        kind.setflags(write=False)
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "params", params)

    @classmethod
    def diffuse(cls, reflectance, two_sided) -> "Materials":
        """An all-diffuse table: ``reflectance`` (M, 3) albedos, ``two_sided`` (M,) flags (Geometry's arrays)."""
        reflectance = np.asarray(reflectance, dtype=np.float64).reshape(-1, 3)
        two_sided = np.asarray(two_sided, dtype=bool).reshape(-1)
        if len(two_sided) != len(reflectance):
            raise SettingsError("materials.params", "expected one two_sided flag per reflectance")
        params = np.zeros((len(reflectance), NUM_PARAMS))
        params[:, P_REFLECTANCE:P_REFLECTANCE + 3] = reflectance
        params[:, P_TWO_SIDED] = two_sided
        return cls(np.full(len(reflectance), DIFFUSE, dtype=np.int64), params)

    @property
    def all_diffuse(self) -> bool:
        """True when every material is Lambertian (the scene runs the engines that predate this table)."""
        return bool(np.all(self.kind == DIFFUSE))

    @property
    def nested(self) -> bool:
        """True when a material is a blendbsdf or a twosided of its own nested materials (the material step resolves
        them at every hit)."""
        return bool(np.any((self.kind == BLENDBSDF) | (self.kind == TWOSIDED)))

    @property
    def anisotropic(self) -> bool:
        """True when a principled material is anisotropic (its frame follows the surface's dp/du: the path loop's
        shading frame and the texture coordinates are needed)."""
        principled = self.kind == PRINCIPLED
        return bool(np.any(principled & (self.params[:, P_ANISOTROPIC] != 0))
                    or np.any(self.texture[principled, list(TEXTURE_SLOTS).index("anisotropic")] >= 0))

    @property
    def masked(self) -> bool:
        """True when a material is a mask (a cut-out: paths and shadow rays pass its holes)."""
        return bool(np.any(self.kind == MASK))

    @property
    def perturbed(self) -> bool:
        """True when a material is a normal or bump map around its kind (:data:`P_PERTURB`)."""
        return bool(np.any(self.params[:, P_PERTURB] != PERTURB_NONE))

    @property
    def textured(self) -> bool:
        """True when a texture drives a parameter of some material."""
        return bool(np.any(self.texture >= 0))

    def __len__(self) -> int:
        return len(self.kind)


def _check_textures(kind: np.ndarray, texture, textures) -> tuple[np.ndarray, Textures]:
    """``texture`` as (M, NUM_SLOTS) int64 (all -1 where None) and ``textures`` (empty where None); SettingsError
    for an index out of range or a texture whose values the parameter cannot take."""
    textures = textures if textures is not None else Textures()
    if texture is None:
        texture = np.full((len(kind), NUM_SLOTS), -1, dtype=np.int64)
    texture = np.ascontiguousarray(texture, dtype=np.int64)
    if texture.shape != (len(kind), NUM_SLOTS):
        raise SettingsError("materials.texture", f"expected an array of shape ({len(kind)}, {NUM_SLOTS}), "
                            f"got {texture.shape}")
    if np.any(texture < -1) or np.any(texture >= len(textures)):
        raise SettingsError("materials.texture", f"expected -1 or a texture index below {len(textures)}")
    for m, slot in zip(*np.nonzero(texture >= 0)):
        name = list(TEXTURE_SLOTS)[slot]
        top = textures.max_value(int(texture[m, slot]))
        where = f"materials.texture[{m}] ({KIND_NAMES[int(kind[m])]})"
        if name in ("reflectance", "transmittance", "diffuse") and np.any(top > 1):
            raise SettingsError(where, f"expected the texture of {name} in [0, 1], got values up to {top.max():g}")
        if name == "alpha" and kind[m] == ROUGHPLASTIC:
            raise SettingsError(where, "expected a number for alpha (Mitsuba's roughplastic takes no texture for it)")
        if name == "alpha":
            low, high = textures.scalar_range(int(texture[m, slot]))
            if not (low > 0 and high < np.inf):
                raise SettingsError(where, f"expected the texture of alpha > 0, got values from {low:g}")
        if name in PRINCIPLED_UNIT:
            low, high = textures.scalar_range(int(texture[m, slot]))
            if not (low >= 0 and high <= 1):
                raise SettingsError(where, f"expected the texture of {name} in [0, 1], got values from {low:g} to "
                                           f"{high:g}")
    texture.setflags(write=False)
    return texture, textures


def _check_perturbations(params: np.ndarray, texture: np.ndarray, textures: Textures) -> None:
    """SettingsError for a normal map's or bump map's texture on a material that is not one, or a bump map without a
    bitmap height (Mitsuba 3.9.1's ``eval_1_grad`` is a bitmap's alone)."""
    slots = list(TEXTURE_SLOTS)
    for m in range(len(params)):
        perturb = params[m, P_PERTURB]
        for slot, wanted in (("normalmap", PERTURB_NORMALMAP), ("bumpmap", PERTURB_BUMPMAP)):
            k = int(texture[m, slots.index(slot)])
            if k >= 0 and perturb != wanted:
                raise SettingsError(f"materials.texture[{m}]", f"a {slot} texture on a material that is no {slot}")
        k = int(texture[m, slots.index("bumpmap")])
        if perturb == PERTURB_BUMPMAP and (k < 0 or not isinstance(textures.items[k], Bitmap)):
            raise SettingsError(f"materials.texture[{m}]", "expected a bitmap's height for a bumpmap")


def is_glossy(materials: Materials | None) -> bool:
    """Whether a scene is glossy: its material table is given and holds a material that is not Lambertian.

    The one rule the core decides it by: a glossy scene runs the path loop (kernels/path.py), whatever
    ``engine`` says, with the BSDF door's every kind compiled in, and resolves
    ``direct = auto`` and ``rr = auto`` as :meth:`Settings.resolved <reference_impl.settings.Settings.resolved>`
    says.

    Parameters
    ----------
    materials : Materials or None
        The scene's material table, or None (every material Lambertian, as ``Geometry.reflectance`` says).

    Returns
    -------
    bool
        True when a material is not diffuse.
    """
    return materials is not None and not materials.all_diffuse


def material_row(kind: int, *, reflectance=DEFAULT_SPECULAR, eta=MIRROR_ETA, k=MIRROR_K,
                 transmittance=DEFAULT_SPECULAR, alpha: float = DEFAULT_ALPHA,
                 distribution: int = DISTRIBUTIONS[DEFAULT_DISTRIBUTION],
                 sample_visible: bool = DEFAULT_SAMPLE_VISIBLE, int_ior: float | None = None,
                 ext_ior: float = DEFAULT_EXT_IOR,
                 two_sided: bool = False, mirror: bool = False, perturb: int = PERTURB_NONE, bump_scale: float = 1.0,
                 flip_invalid_normals: bool = True, use_shadowing_function: bool = True, diffuse=DEFAULT_DIFFUSE,
                 nonlinear: bool = DEFAULT_NONLINEAR, specular_sampling_weight: float | None = None,
                 weight: float = DEFAULT_WEIGHT, nested: tuple[int, int] = (0, 0), **principled) -> np.ndarray:
    """One row of ``Materials.params`` from named values (for tests and for the harness's builder).

    ``reflectance`` is the diffuse albedo or the specular_reflectance; ``eta``, ``k`` the conductor's complex index
    (Mitsuba's default without a named material is eta = 0, k = 1: Fresnel = 1); ``int_ior / ext_ior`` becomes
    :data:`P_IOR`. ``perturb``, ``bump_scale``, ``flip_invalid_normals``, ``use_shadowing_function``: Mitsuba's
    ``normalmap`` or ``bumpmap`` around the kind (its normal map's value is the texture's, at each hit).
    ``diffuse``, ``nonlinear``: plastic's diffuse_reflectance and nonlinear; ``specular_sampling_weight`` its
    probability weight of the specular lobe, by default :func:`plastic_sampling_weight` of ``reflectance`` and
    ``diffuse`` (a textured parameter's mean is the harness's to give). ``weight``, ``nested``: a composite's
    (:data:`COMPOSITES`) weight or opacity and the rows of its nested materials (a mask's and a twosided's one
    material: the same row twice); a composite's row holds nothing else.
    ``principled``: a principled row's parameters by Mitsuba's names (:data:`PRINCIPLED_DEFAULTS`' keys, and ``eta``
    as a number or ``specular``; ``base_color`` or ``reflectance``), Mitsuba's defaults for the others
    (:func:`_principled_columns`); TypeError for them on another kind.
    """
    if kind == PRINCIPLED:
        principled = dict(principled)
        if eta is not MIRROR_ETA:
            principled["eta"] = eta
        if reflectance is not DEFAULT_SPECULAR:
            principled.setdefault("base_color", reflectance)
        eta = MIRROR_ETA
    elif principled:
        raise TypeError(f"material_row: unexpected keywords {sorted(principled)} for kind {kind}")
    row = np.zeros(NUM_PARAMS)
    if kind in COMPOSITES:
        row[P_WEIGHT] = weight
        row[P_NESTED], row[P_NESTED + 1] = nested
        return row
    row[P_REFLECTANCE:P_REFLECTANCE + 3] = np.broadcast_to(np.asarray(reflectance, dtype=np.float64), 3)
    row[P_ETA:P_ETA + 3] = np.broadcast_to(np.asarray(eta, dtype=np.float64), 3)
    row[P_K:P_K + 3] = np.broadcast_to(np.asarray(k, dtype=np.float64), 3)
    row[P_TRANSMITTANCE:P_TRANSMITTANCE + 3] = np.broadcast_to(np.asarray(transmittance, dtype=np.float64), 3)
    row[P_ALPHA] = alpha
    row[P_DISTRIBUTION] = distribution
    row[P_SAMPLE_VISIBLE] = bool(sample_visible)
    if int_ior is None:  # Mitsuba's default: bk7, polypropylene for the plastics
        int_ior = PLASTIC_INT_IOR if kind in (PLASTIC, ROUGHPLASTIC) else DEFAULT_INT_IOR
    row[P_IOR] = int_ior / ext_ior
    row[P_TWO_SIDED] = bool(two_sided)
    row[P_MIRROR] = bool(mirror)
    row[P_PERTURB] = perturb
    row[P_BUMP_SCALE] = bump_scale
    row[P_NORMAL:P_NORMAL + 3] = (0.5, 0.5, 1.0)  # n = (0, 0, 1): the frame unperturbed
    row[P_FLIP_INVALID] = bool(flip_invalid_normals)
    row[P_SHADOWING] = bool(use_shadowing_function)
    if kind == PRINCIPLED:  # its own columns, in place of the conductors', dielectrics' and rough kinds'
        _principled_columns(row, principled)
    if kind in (PLASTIC, ROUGHPLASTIC):  # their own columns, in place of a conductor's eta and k
        row[P_ETA:P_K + 3] = 0.0
        row[P_DIFFUSE:P_DIFFUSE + 3] = np.broadcast_to(np.asarray(diffuse, dtype=np.float64), 3)
        row[P_NONLINEAR] = bool(nonlinear)
        if specular_sampling_weight is None:
            specular_sampling_weight = plastic_sampling_weight(np.mean(row[P_REFLECTANCE:P_REFLECTANCE + 3]),
                                                               np.mean(row[P_DIFFUSE:P_DIFFUSE + 3]))
        row[P_SPECULAR_WEIGHT] = specular_sampling_weight
    return row


def fresnel_diffuse_reflectance(eta: float) -> float:
    """The diffuse Fresnel reflectance F_dr of a dielectric interface of relative index ``eta`` (the fraction of
    uniformly diffuse light it reflects), Mitsuba 3.9.1's fit (include/mitsuba/render/fresnel.h,
    ``fresnel_diffuse_reflectance``): for eta < 1 Egan and Hilgeman's (1973)
    F_dr = -1.4399 eta^2 + 0.7099 eta + 0.6681 + 0.0636 / eta, else d'Eon and Irving's (2011)
    F_dr = 0.919317 - 3.4793 x + 6.75335 x^2 - 7.80989 x^3 + 4.98554 x^4 - 1.36881 x^5, x = 1 / eta.
    Plastic's base sees F_dr(1 / eta) from inside its coating."""
    if eta < 1.0:
        return 0.0636 / eta + eta * (eta * -1.4399 + 0.7099) + 0.6681
    x = 1.0 / eta
    return 0.919317 + x * (-3.4793 + x * (6.75335 + x * (-7.80989 + x * (4.98554 + x * -1.36881))))


def plastic_sampling_weight(specular_mean: float, diffuse_mean: float) -> float:
    """Plastic's weight of its specular lobe in the choice of lobe: s_mean / (d_mean + s_mean), the means of
    specular_reflectance and diffuse_reflectance over their channels (a texture's over its texels), as Mitsuba
    3.9.1's ``SmoothPlastic::parameters_changed`` (src/bsdfs/plastic.cpp); 1/2 where both are 0 (a black
    material, which Mitsuba leaves undefined)."""
    total = float(specular_mean) + float(diffuse_mean)
    return float(specular_mean) / total if total > 0 else 0.5


def _check_params(kind: np.ndarray, params: np.ndarray) -> None:
    """Raise :class:`SettingsError` on the first row that a kernel could not evaluate meaningfully."""
    where = "materials.params"
    if not np.all(np.isfinite(params)):
        raise SettingsError(where, "expected finite numbers")
    for m, (kd, row) in enumerate(zip(kind, params)):
        name = f"{where}[{m}] ({KIND_NAMES[int(kd)]})"
        if kd in COMPOSITES:
            _check_composite(name, m, kind, params)
            continue
        rgb = row[P_REFLECTANCE:P_REFLECTANCE + 3]
        if np.any(rgb < 0) or np.any(rgb > 1):
            raise SettingsError(name, "expected the reflectance in [0, 1]")
        flags = ((P_TWO_SIDED, "two_sided"), (P_MIRROR, "mirror"), (P_SAMPLE_VISIBLE, "sample_visible"),
                 (P_DISTRIBUTION, "distribution"), (P_FLIP_INVALID, "flip_invalid_normals"),
                 (P_SHADOWING, "use_shadowing_function"))
        if kd == PRINCIPLED:  # its sampling rates sit in the distribution, sample_visible and mirror columns
            flags = tuple(f for f in flags if f[0] not in (P_SPECULAR_RATE, P_CLEARCOAT_RATE, P_DIFFUSE_RATE))
        for col, label in flags:
            if row[col] not in (0.0, 1.0):
                raise SettingsError(name, f"expected {label} 0 or 1, got {row[col]!r}")
        if row[P_PERTURB] not in (PERTURB_NONE, PERTURB_NORMALMAP, PERTURB_BUMPMAP):
            raise SettingsError(name, f"expected perturb {PERTURB_NONE}, {PERTURB_NORMALMAP} or {PERTURB_BUMPMAP}, "
                                f"got {row[P_PERTURB]!r}")
        if kd in (ROUGHCONDUCTOR, ROUGHDIELECTRIC, ROUGHPLASTIC) and not row[P_ALPHA] > 0:
            raise SettingsError(name, f"expected alpha > 0, got {row[P_ALPHA]!r}")
        if kd in (CONDUCTOR, ROUGHCONDUCTOR) and np.any(row[P_K:P_K + 3] < 0):
            raise SettingsError(name, "expected k >= 0")
        if kd in (CONDUCTOR, ROUGHCONDUCTOR) and np.any(row[P_ETA:P_ETA + 3] < 0):
            raise SettingsError(name, "expected eta >= 0")
        if kd in TRANSMITTING:
            trans = row[P_TRANSMITTANCE:P_TRANSMITTANCE + 3]
            if np.any(trans < 0) or np.any(trans > 1):
                raise SettingsError(name, "expected the specular_transmittance in [0, 1]")
            if not row[P_IOR] > 0:
                raise SettingsError(name, f"expected eta = int_ior / ext_ior > 0, got {row[P_IOR]!r}")
            if kd == ROUGHDIELECTRIC and row[P_IOR] == 1.0:
                raise SettingsError(name, "expected int_ior != ext_ior (Mitsuba's roughdielectric refuses an "
                                    "index-matched interface; use a dielectric)")
            if row[P_TWO_SIDED] and kd == THINDIELECTRIC:
                raise SettingsError(name, "two_sided does not apply to a thindielectric (it is two-sided by nature)")
            if row[P_TWO_SIDED]:
                raise SettingsError(name, "two_sided does not apply to dielectrics")
        if kd in (PLASTIC, ROUGHPLASTIC):
            _check_plastic(name, row, rough=kd == ROUGHPLASTIC)
        if kd == ROUGHPLASTIC and row[P_IOR] == 1.0:
            raise SettingsError(name, "expected int_ior != ext_ior (Mitsuba's roughplastic refuses an index-matched "
                                "coating)")
        if kd == PRINCIPLED:
            _check_principled(name, row)


def nested_rows(kind: np.ndarray, params: np.ndarray, m: int) -> tuple[int, int]:
    """The two rows a composite material ``m`` names (:data:`P_NESTED`)."""
    return int(params[m, P_NESTED]), int(params[m, P_NESTED + 1])


def leaves(kind: np.ndarray, params: np.ndarray, m: int) -> set[int]:
    """The materials that are no composite reached from ``m`` through its nested ones (``m`` itself if it is none)."""
    out, todo, seen = set(), [m], set()
    while todo:
        r = todo.pop()
        if r in seen:
            continue
        seen.add(r)
        if kind[r] in COMPOSITES:
            todo.extend(nested_rows(kind, params, r))
        else:
            out.add(r)
    return out


def _check_composite(name: str, m: int, kind: np.ndarray, params: np.ndarray) -> None:
    """A composite's columns: its nested rows exist, are not itself nor (through others) lead back to it, none is a
    mask (a mask is a shape's own material: the path meets its holes where the ray meets the shape); a blendbsdf's
    weight and a mask's opacity in [0, 1]; a twosided's nested materials transmit nothing (Mitsuba's twosided
    refuses them)."""
    row = params[m]
    for c in (P_NESTED, P_NESTED + 1):
        r = row[c]
        if not (r == int(r) and 0 <= r < len(kind)):
            raise SettingsError(name, f"expected nested material rows in 0 .. {len(kind) - 1}, got {r!r}")
    todo, seen = list(nested_rows(kind, params, m)), set()
    while todo:
        r = todo.pop()
        if r == m:
            raise SettingsError(name, "expected nested materials that do not contain the material itself")
        if r in seen:
            continue
        seen.add(r)
        if kind[r] == MASK:
            raise SettingsError(name, f"material {r} is a mask: a mask is a shape's own material, not nested")
        if kind[r] in COMPOSITES:
            todo.extend(nested_rows(kind, params, r))
    if kind[m] in (BLENDBSDF, MASK) and not 0.0 <= row[P_WEIGHT] <= 1.0:
        label = "weight" if kind[m] == BLENDBSDF else "opacity"
        raise SettingsError(name, f"expected the {label} in [0, 1], got {row[P_WEIGHT]!r}")
    if kind[m] == TWOSIDED:
        for r in leaves(kind, params, m):
            if kind[r] in TRANSMITTING:
                raise SettingsError(name, f"material {r} ({KIND_NAMES[int(kind[r])]}) transmits: a twosided takes "
                                    "materials without transmission (as Mitsuba's)")


def _check_plastic(name: str, row: np.ndarray, rough: bool = False) -> None:
    """Plastic's columns: diffuse_reflectance in [0, 1], eta > 0 (and, smooth, F_dr(1 / eta) < 1: the rough one
    integrates its internal reflectance, which is always below 1), the nonlinear flag 0 or 1, the specular sampling
    weight in [0, 1]."""
    diffuse = row[P_DIFFUSE:P_DIFFUSE + 3]
    if np.any(diffuse < 0) or np.any(diffuse > 1):
        raise SettingsError(name, "expected the diffuse_reflectance in [0, 1]")
    if not row[P_IOR] > 0:
        raise SettingsError(name, f"expected eta = int_ior / ext_ior > 0, got {row[P_IOR]!r}")
    fdr = 0.0 if rough else fresnel_diffuse_reflectance(1.0 / row[P_IOR])
    if not 0.0 <= fdr < 1.0:
        raise SettingsError(name, f"expected eta = int_ior / ext_ior whose internal diffuse Fresnel reflectance "
                                  f"F_dr(1 / eta) is in [0, 1) (Mitsuba's fit), got eta {row[P_IOR]!r}, F_dr {fdr:.4g}")
    if row[P_NONLINEAR] not in (0.0, 1.0):
        raise SettingsError(name, f"expected nonlinear 0 or 1, got {row[P_NONLINEAR]!r}")
    if not 0.0 <= row[P_SPECULAR_WEIGHT] <= 1.0:
        raise SettingsError(name, f"expected the specular sampling weight in [0, 1], got {row[P_SPECULAR_WEIGHT]!r}")


def _check_principled(name: str, row: np.ndarray) -> None:
    """Principled's columns: its one-number weights in [0, 1], eta > 0, the sampling rates > 0, one-sided."""
    for slot in PRINCIPLED_UNIT:
        value = row[TEXTURE_SLOTS[slot][0]]
        if not 0.0 <= value <= 1.0:
            raise SettingsError(name, f"expected {slot} in [0, 1], got {value!r}")
    if not row[P_IOR] > 0:
        raise SettingsError(name, f"expected eta > 0, got {row[P_IOR]!r}")
    for col, label in ((P_SPECULAR_RATE, "main_specular_sampling_rate"), (P_CLEARCOAT_RATE, "clearcoat_sampling_rate"),
                       (P_DIFFUSE_RATE, "diffuse_reflectance_sampling_rate")):
        if not row[col] > 0:
            raise SettingsError(name, f"expected {label} > 0, got {row[col]!r}")
    if row[P_TWO_SIDED]:
        raise SettingsError(name, "two_sided does not apply to a principled material (Mitsuba's principled "
                                  "reflects on its front, and transmits from both sides where spec_trans > 0)")


def principled_eta(specular: float, spec_trans: bool = False) -> float:
    """Mitsuba 3.9.1's principled eta from its ``specular``: eta = 2 / (1 - sqrt(0.08 specular)) - 1 (the inverse of
    specular = (eta - 1)^2 / (eta + 1)^2 / 0.08); specular 0 becomes 1e-3 where the material transmits
    (``spec_trans`` given and not 0: eta = 1 is no interface to refract at), as Mitsuba's constructor does."""
    if spec_trans and specular == 0.0:
        specular = 1e-3
    return 2.0 / (1.0 - np.sqrt(0.08 * specular)) - 1.0


def principled_row(**principled) -> np.ndarray:
    """One principled row: :func:`material_row` (``PRINCIPLED``, ``**principled``)."""
    return material_row(PRINCIPLED, **principled)


def _principled_columns(row: np.ndarray, principled: dict) -> None:
    """Principled's columns of ``row`` from Mitsuba's parameter names (``base_color``, ``roughness``, ``metallic``,
    ``spec_tint``, ``anisotropic``, ``sheen``, ``sheen_tint``, ``clearcoat``, ``clearcoat_gloss``, ``spec_trans``,
    ``flatness``, ``eta`` or ``specular``, the three ``*_sampling_rate``), Mitsuba's defaults for the others;
    ``eta`` = 1 becomes 1.001 where spec_trans is not 0, as Mitsuba's constructor does. Both ``eta`` and
    ``specular``: ValueError (Mitsuba: "either use eta or specular")."""
    eta, specular = principled.pop("eta", None), principled.pop("specular", None)
    if eta is not None and specular is not None:
        raise ValueError("principled: either eta or specular, not both (Mitsuba's two spellings of one thing)")
    unknown = set(principled) - set(PRINCIPLED_DEFAULTS)
    if unknown:
        raise TypeError(f"principled: unexpected keywords {sorted(unknown)}")
    values = {**PRINCIPLED_DEFAULTS, **principled}
    transmits = values["spec_trans"] != 0.0
    if eta is None:
        eta = principled_eta(PRINCIPLED_DEFAULTS["specular"] if specular is None else specular, transmits)
    elif transmits and eta == 1.0:
        eta = 1.001
    row[P_ETA:P_ALPHA + 1] = 0.0
    row[P_DISTRIBUTION] = row[P_SAMPLE_VISIBLE] = row[P_MIRROR] = 0.0
    row[P_REFLECTANCE:P_REFLECTANCE + 3] = np.broadcast_to(np.asarray(values["base_color"], dtype=np.float64), 3)
    row[P_IOR] = float(eta)
    for slot in PRINCIPLED_UNIT:
        row[TEXTURE_SLOTS[slot][0]] = values[slot]
    row[P_SPECULAR_RATE] = values["main_specular_sampling_rate"]
    row[P_CLEARCOAT_RATE] = values["clearcoat_sampling_rate"]
    row[P_DIFFUSE_RATE] = values["diffuse_reflectance_sampling_rate"]
