"""The in-memory form of a scene file (see ``docs/scene-format.md``): plain, validated, immutable records.

:func:`harness.scene.load_scene` builds these from a TOML file; :func:`harness.scene.triangulate` turns them into the
flat triangle arrays of :class:`reference_impl.geometry.Geometry`; renderer adapters read them directly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from reference_impl.camera import Camera, Film, OrthographicCamera, ThinLensCamera
from reference_impl.emitters import DEFAULT_BEAM_WIDTH, DEFAULT_CUTOFF_ANGLE, DEFAULT_SCALE
from reference_impl.materials import (DEFAULT_ALPHA, DEFAULT_DIFFUSE, DEFAULT_DISTRIBUTION, DEFAULT_EXT_IOR,
                                      DEFAULT_INT_IOR, DEFAULT_NONLINEAR, DEFAULT_SAMPLE_VISIBLE, DEFAULT_SPECULAR,
                                      DEFAULT_WEIGHT, MIRROR_ETA, MIRROR_K, PLASTIC_INT_IOR, PRINCIPLED_DEFAULTS)
from reference_impl.materials import DISTRIBUTIONS as CORE_DISTRIBUTIONS
from reference_impl import media as core_media
from reference_impl import textures as core_textures
from reference_impl.textures import Texture as CoreTexture

SHAPE_TYPES = ("rectangle", "cube", "sphere", "mesh")
EMITTER_TYPES = ("point", "spot", "directional", "constant", "envmap")

Vector3 = tuple[float, float, float]


TEXTURE_TYPES = ("bitmap", "checkerboard")  # Mitsuba's texture plugins
FILTER_TYPES = ("bilinear", "nearest")  # a bitmap's filter_type
WRAP_MODES = ("repeat", "mirror", "clamp")  # a bitmap's wrap_mode


@dataclass(frozen=True, eq=False)
class Texture:
    """One ``[textures.NAME]`` table: Mitsuba's texture plugin ``type`` with its parameters (docs/scene-format.md,
    "Textures"; the lookups are :mod:`reference_impl.textures`').

    ``bitmap``: ``file`` (PNG, JPEG or OpenEXR, the ``filename`` key), read into ``image``, (H, W, 3), row 0 the
    image's top: uint8 codes for an 8-bit file, float32 linear values for an EXR; ``raw = False`` decodes an 8-bit
    image's sRGB codes, ``raw = True`` takes code / 255; ``filter_type`` and ``wrap_mode`` as Mitsuba's.
    ``checkerboard``: ``color0`` and ``color1``. Both: ``to_uv``, the 3x3 affine map of the texture coordinates.
    """

    name: str
    type: str
    to_uv: np.ndarray
    file: Path | None = None
    image: np.ndarray | None = None
    filter_type: str = "bilinear"
    wrap_mode: str = "repeat"
    raw: bool = False
    color0: Vector3 = (0.4, 0.4, 0.4)  # Mitsuba's checkerboard defaults
    color1: Vector3 = (0.2, 0.2, 0.2)

    @cached_property
    def core(self) -> CoreTexture:
        """The core's texture (:mod:`reference_impl.textures`): an 8-bit image not ``raw`` is sRGB-decoded there."""
        if self.type == "checkerboard":
            return core_textures.Checkerboard(self.color0, self.color1, self.to_uv)
        srgb = self.image.dtype == np.uint8 and not self.raw
        return core_textures.Bitmap(self.image, self.filter_type, self.wrap_mode, srgb, self.to_uv)

    @property
    def scalar_range(self) -> tuple[float, float]:
        """The least and the largest value the texture takes as one number (a one-channel parameter, ``alpha``:
        Mitsuba's ``eval_1``, a bitmap's luminance, a checkerboard colour's mean)."""
        values = core_textures.scalar_values(self.core)
        return float(np.min(values)), float(np.max(values))

    @property
    def scalar_mean(self) -> float:
        """The mean of the texture as one number (of :attr:`scalar_range`'s values)."""
        return float(np.mean(core_textures.scalar_values(self.core)))

    @property
    def mean_value(self) -> tuple[float, float, float]:
        """The mean of the texture's texels (a checkerboard's two colours), per channel: a textured light's stand-in
        radiance where a light is chosen by its power."""
        return tuple(float(c) for c in self.core.values().mean(axis=0))

    @property
    def max_value(self) -> tuple[float, float, float]:
        """The largest value the texture takes, per channel (the bound of a lookup: filtering interpolates)."""
        return tuple(float(c) for c in self.core.values().max(axis=0))


MATERIAL_TYPES = ("diffuse", "conductor", "roughconductor", "dielectric", "roughdielectric", "thindielectric",
                  "plastic", "roughplastic", "principled", "null")  # Mitsuba's plugins
CONDUCTOR_TYPES = ("conductor", "roughconductor")
DIELECTRIC_TYPES = ("dielectric", "roughdielectric", "thindielectric")  # int_ior, ext_ior, specular_transmittance
ROUGH_TYPES = ("roughconductor", "roughdielectric", "roughplastic")
DISTRIBUTIONS = tuple(CORE_DISTRIBUTIONS)  # Mitsuba's microfacet distributions
# The defaults of the fields below are the core's (reference_impl.materials, reference_impl.emitters): Mitsuba's.


MEDIUM_TYPES = ("homogeneous",)  # Mitsuba's medium plugins the scene format takes
PHASE_TYPES = ("isotropic", "hg")  # Mitsuba's phase function plugins


@dataclass(frozen=True)
class Medium:
    """One ``[media.NAME]`` table: Mitsuba 3's ``homogeneous`` medium (docs/scene-format.md, "Participating media").

    The extinction per unit length is ``sigma_t * scale`` per channel (Mitsuba's ``sigma_t`` and ``scale``), the
    single-scattering albedo ``albedo`` (sigma_s = albedo sigma_t, sigma_a = (1 - albedo) sigma_t); ``phase`` is
    Mitsuba's phase plugin, ``isotropic`` (p = 1 / (4 pi)) or ``hg`` (Henyey-Greenstein with asymmetry ``g``, g > 0
    forward). Defaults are Mitsuba's (:mod:`reference_impl.media`).
    """

    name: str
    type: str = "homogeneous"
    albedo: Vector3 = core_media.DEFAULT_ALBEDO
    sigma_t: Vector3 = (core_media.DEFAULT_SIGMA_T,) * 3
    scale: float = core_media.DEFAULT_SCALE
    phase: str = "isotropic"
    g: float = core_media.DEFAULT_G

    @property
    def extinction(self) -> Vector3:
        """sigma_t x scale per channel: the extinction per unit length the core and scene.json take."""
        return tuple(float(s) * float(self.scale) for s in self.sigma_t)


@dataclass(frozen=True)
class Perturbation:
    """A ``normalmap`` or ``bumpmap`` material's map (Mitsuba's plugins of those names, around the BSDF its ``bsdf``
    key names; docs/scene-format.md, "Shading normals").

    ``type = "normalmap"``: ``texture`` is the tangent-space normal map (``normalmap = { texture = "N" }``, raw RGB,
    n = 2 rgb - 1); ``type = "bumpmap"``: ``texture`` is the height (a bitmap, its luminance), ``scale`` its factor.
    ``flip_invalid_normals`` and ``use_shadowing_function`` are Mitsuba's keys of both (default true).
    """

    type: str
    texture: Texture
    bsdf: str  # the name of the material it wraps
    scale: float = 1.0
    flip_invalid_normals: bool = True
    use_shadowing_function: bool = True


@dataclass(frozen=True)
class Principled:
    """A ``principled`` material's parameters (Mitsuba 3.9.1's ``principled``, its names and defaults,
    :data:`reference_impl.materials.PRINCIPLED_DEFAULTS`): ``eta`` is the interior / exterior index the material
    uses, whether the file gave ``eta`` or ``specular`` (:func:`reference_impl.materials.principled_eta`), with
    Mitsuba's nudges where spec_trans is given (eta 1 -> 1.001, specular 0 -> 1e-3)."""

    base_color: Vector3 = PRINCIPLED_DEFAULTS["base_color"]
    roughness: float = PRINCIPLED_DEFAULTS["roughness"]
    metallic: float = 0.0
    spec_tint: float = 0.0
    anisotropic: float = 0.0
    sheen: float = 0.0
    sheen_tint: float = 0.0
    clearcoat: float = 0.0
    clearcoat_gloss: float = 0.0
    spec_trans: float = 0.0
    flatness: float = 0.0
    eta: float = 1.5
    main_specular_sampling_rate: float = 1.0
    clearcoat_sampling_rate: float = 1.0
    diffuse_reflectance_sampling_rate: float = 1.0


@dataclass(frozen=True)
class Material:
    """One ``[materials.NAME]`` table: Mitsuba's BSDF plugin ``type`` with its parameters (docs/scene-format.md).

    ``type = "diffuse"`` (the default): a Lambertian BRDF f_r = reflectance / pi (Mitsuba's ``diffuse``);
    ``two_sided = False`` reflects on the front side of a surface only (the back side is black), like Mitsuba's
    BSDFs; ``True`` reflects on both sides (Mitsuba's ``twosided`` wrapper). Conductors and the plastics take the same
    meaning of ``two_sided``; dielectrics (the thin one too) have no ``two_sided`` (light crosses them from either
    side).

    The fields of the other types keep Mitsuba's defaults where a type does not use them. ``reflectance`` of a
    non-diffuse material is a per-channel bound of what one bounce keeps: ``specular_reflectance`` for conductors
    (Fresnel <= 1), the larger of ``specular_reflectance`` and ``specular_transmittance`` for dielectrics, the
    larger of ``specular_reflectance`` and ``diffuse_reflectance`` for the plastics (each part keeps at most its own),
    1 for principled (whose model does not conserve energy: its retro-reflection and sheen can return more than
    comes in, tests/reference_impl/test_bsdf_principled.py's furnace table).
    """

    name: str
    reflectance: Vector3
    two_sided: bool = False
    type: str = "diffuse"
    eta: Vector3 = MIRROR_ETA  # conductors: the real part of the complex index of refraction, per channel
    k: Vector3 = MIRROR_K  # conductors: its imaginary part (the extinction coefficient)
    specular_reflectance: Vector3 = DEFAULT_SPECULAR
    specular_transmittance: Vector3 = DEFAULT_SPECULAR  # dielectrics
    alpha: float = DEFAULT_ALPHA  # rough types: the isotropic microfacet roughness
    distribution: str = DEFAULT_DISTRIBUTION  # rough types: one of DISTRIBUTIONS
    sample_visible: bool = DEFAULT_SAMPLE_VISIBLE  # rough types: sample the visible normals
    int_ior: float = DEFAULT_INT_IOR  # dielectrics: the index inside (behind the front side)
    ext_ior: float = DEFAULT_EXT_IOR  # dielectrics: the index outside (on the front side)
    diffuse_reflectance: Vector3 = DEFAULT_DIFFUSE  # plastic: the albedo of the base under the coating
    nonlinear: bool = DEFAULT_NONLINEAR  # plastic: the base's internal reflections tinted by its own colour
    principled: Principled | None = None  # principled: its parameters
    # (parameter, texture) of every parameter a texture drives, in the order of the type's keys; the parameter's own
    # field then holds the texture's largest value (a bound of what one bounce keeps)
    textures: tuple[tuple[str, Texture], ...] = ()
    # a normalmap or bumpmap material: its map; the fields above are those of the material its ``bsdf`` names
    perturbation: Perturbation | None = None
    # blendbsdf: the weight of its second material; mask: its opacity (harness/scene/kinds/composites.py)
    weight: float = DEFAULT_WEIGHT
    # blendbsdf, mask, twosided: the materials it is made of (a mask's and a one-material twosided's, twice)
    nested: tuple["Material", ...] = ()

    def texture(self, parameter: str) -> Texture | None:
        """The texture that drives ``parameter``, or None."""
        return dict(self.textures).get(parameter)

    @property
    def looks_up_textures(self) -> bool:
        """Whether a hit on it looks a texture up: a texture, a map, or a nested material that does."""
        return bool(self.textures or self.perturbation is not None or any(m.looks_up_textures for m in self.nested))

    @property
    def needs_coordinates(self) -> bool:
        """Whether a hit on it reads texture coordinates: it looks a texture up, or it is (or holds) an anisotropic
        principled, whose frame follows dp/du (where a mesh has none, Mitsuba's frame of the normal alone)."""
        anisotropic = self.principled is not None and (self.principled.anisotropic != 0
                                                       or self.texture("anisotropic") is not None)
        return self.looks_up_textures or anisotropic or any(m.needs_coordinates for m in self.nested)

    @property
    def is_diffuse(self) -> bool:
        return self.type == "diffuse"

    @property
    def is_conductor(self) -> bool:
        return self.type in CONDUCTOR_TYPES

    @property
    def is_dielectric(self) -> bool:
        return self.type in DIELECTRIC_TYPES

    @property
    def is_rough(self) -> bool:
        return self.type in ROUGH_TYPES

    @property
    def mirror(self) -> bool:
        """A conductor with Mitsuba's ``material = "none"`` (eta = 0, k = 1): Fresnel = 1 exactly."""
        return self.is_conductor and tuple(self.eta) == MIRROR_ETA and tuple(self.k) == MIRROR_K


@dataclass(frozen=True, eq=False)
class Shape:
    """One ``[[shapes]]`` entry.

    Attributes
    ----------
    index : int
        Position in the file's ``shapes`` array (0-based); error messages call it ``shapes[index]``.
    name : str
        The ``name`` key, or ``"shape<index>"`` when absent.
    type : str
        One of :data:`SHAPE_TYPES`.
    material : str
        Name of a key of :attr:`Scene.materials`.
    to_world : (4, 4) float64
        The placement, row-major, applied to column vectors (p' = M p): either the file's ``to_world`` or
        Translate @ Rotate @ Scale built from ``translate`` / ``rotate`` / ``scale`` (identity if none is given).
        For spheres it does *not* include ``center`` / ``radius``: the sphere's object-to-world matrix is
        ``to_world @ translate(center) @ scale(radius)``, as in Mitsuba.
    emission : (r, g, b) or None
        Radiance emitted from the front side; None for shapes that do not emit. A textured light's is its
        texture's mean (:attr:`Texture.mean_value`), the stand-in a light's power is estimated with.
    emission_texture : Texture or None
        The texture whose value at a point is the radiance emitted there (``emission = { texture = "NAME" }``,
        Mitsuba's ``area`` emitter with a textured ``radiance``).
    flip_normals : bool
        Mitsuba's ``flip_normals``: swap the front and back sides.
    file : Path or None
        Meshes only: the absolute path of the PLY / OBJ file.
    center, radius, subdivisions :
        Spheres only (other shapes keep the defaults): the sphere in its own space, and the number of icosphere
        subdivisions used when triangulating it.
    mesh_vertices, mesh_triangles : ndarray or None
        Meshes only: the file's vertices (V, 3) and triangles (T, 3) in object space, as read at load time.
    mesh_uv : ndarray or None
        Meshes only: the file's texture coordinates (V, 2) as Mitsuba holds them (an OBJ's ``vt`` with v flipped,
        1 - v, where ``flip_tex_coords``), or None for a file without them.
    flip_tex_coords : bool
        Meshes only: Mitsuba's ``flip_tex_coords`` (its default: true for OBJ, false for PLY).
    face_normals : bool
        Meshes only: Mitsuba's ``face_normals`` (default false): shade flat, ignoring the file's vertex normals and
        computing none.
    mesh_normals : ndarray or None
        Meshes only: the file's vertex normals (V, 3) in object space (PLY ``nx, ny, nz``; OBJ ``vn``), or None for
        a file without them (whose normals are then computed as Mitsuba does, :mod:`harness.scene.triangulate`).
    """

    index: int
    name: str
    type: str
    material: str
    to_world: np.ndarray
    emission: Vector3 | None = None
    flip_normals: bool = False
    file: Path | None = None
    center: Vector3 = (0.0, 0.0, 0.0)
    radius: float = 1.0
    subdivisions: int = 3
    mesh_vertices: np.ndarray | None = None
    mesh_triangles: np.ndarray | None = None
    mesh_uv: np.ndarray | None = None
    flip_tex_coords: bool = False
    emission_texture: Texture | None = None
    face_normals: bool = False
    mesh_normals: np.ndarray | None = None
    interior: str | None = None  # the medium behind its front side (a name of Scene.media), Mitsuba's meaning
    exterior: str | None = None  # the medium in front of its front side

    @property
    def is_medium_transition(self) -> bool:
        """Whether the shape names a medium on either side (Mitsuba's ``is_medium_transition``)."""
        return self.interior is not None or self.exterior is not None

    @property
    def is_emitter(self) -> bool:
        """True if the shape is an area light."""
        return self.emission is not None


# ---- emitters that are not shapes ([[emitters]]; Mitsuba's plugins of the same names and parameters) ----------


@dataclass(frozen=True)
class PointLight:
    """Mitsuba's ``point``: radiant ``intensity`` I (W/sr, RGB) at ``position``; irradiance I cos / r^2."""

    index: int
    name: str
    position: Vector3
    intensity: Vector3
    type = "point"


@dataclass(frozen=True, eq=False)
class SpotLight:
    """Mitsuba's ``spot``: ``intensity`` I (W/sr) along the axis, from ``to_world``'s origin along its local +z.

    Falloff (Mitsuba's ``spot.cpp``), theta the angle from the axis: 1 for theta <= ``beam_width``, linear in
    theta down to 0 at ``cutoff_angle`` ((cutoff - theta) / (cutoff - beam_width)), 0 beyond (degrees here).
    """

    index: int
    name: str
    to_world: np.ndarray  # 4x4, world from the light's frame: origin = position, +z = the cone's axis
    intensity: Vector3
    cutoff_angle: float = DEFAULT_CUTOFF_ANGLE
    beam_width: float = DEFAULT_BEAM_WIDTH  # the loader's default: 3/4 of cutoff_angle
    type = "spot"

    @property
    def position(self) -> np.ndarray:
        return np.asarray(self.to_world, dtype=np.float64)[:3, 3].copy()

    @property
    def axis(self) -> np.ndarray:
        z = np.asarray(self.to_world, dtype=np.float64)[:3, 2]
        return z / np.linalg.norm(z)


@dataclass(frozen=True)
class DirectionalLight:
    """Mitsuba's ``directional``: ``irradiance`` E (W/m^2, RGB) on a surface facing it, light travelling along the
    unit vector ``direction`` (toward the scene, as in Mitsuba)."""

    index: int
    name: str
    direction: Vector3
    irradiance: Vector3
    type = "directional"


@dataclass(frozen=True)
class ConstantEnvironment:
    """Mitsuba's ``constant``: ``radiance`` L (RGB) arriving from every direction, seen by every escaping ray."""

    index: int
    name: str
    radiance: Vector3
    type = "constant"


@dataclass(frozen=True, eq=False)
class EnvironmentMap:
    """Mitsuba's ``envmap``: a lat-long OpenEXR image (``file``, read into ``image``, (H, W, 3) float32 linear RGB)
    times ``scale``, placed by ``to_world`` (world from the map's frame; a rotation). Orientation and bilinear
    interpolation as Mitsuba's ``envmap.cpp`` (docs/scene-format.md, "Emitters", gives the mapping)."""

    index: int
    name: str
    file: Path
    image: np.ndarray
    to_world: np.ndarray
    scale: float = DEFAULT_SCALE
    type = "envmap"


Emitter = PointLight | SpotLight | DirectionalLight | ConstantEnvironment | EnvironmentMap


@dataclass(frozen=True, eq=False)
class Scene:
    """A whole scene file.

    ``materials`` keeps the file's order (``Geometry.material`` indexes materials in that order); ``shapes`` keeps
    the file's order (light ids number the emissive shapes in that order). ``path`` is the scene file's path as it
    was given to :func:`load_scene`. ``closed_form`` names a known analytic solution of the scene ("furnace"), or
    None. ``files`` is every file the loader read to build the scene, once each in the order read: the scene file
    first, then each file it names (meshes, environment maps, any file a later key names); the content key
    (:mod:`harness.scene.content_key`) hashes their bytes.
    """

    name: str
    description: str
    camera: Camera | ThinLensCamera | OrthographicCamera
    film: Film
    max_depth: int
    materials: dict[str, Material]
    shapes: list[Shape]
    path: Path
    closed_form: str | None = None
    emitters: tuple[Emitter, ...] = ()  # [[emitters]] in the file's order; emitting shapes are in ``shapes``
    regions: tuple[str, ...] = ()  # shape names: the strategy table's per-region efficiencies (their pixels)
    files: tuple[Path, ...] = ()  # every file read to load the scene (the scene file first)
    textures: dict[str, Texture] = field(default_factory=dict)  # [textures.NAME] in the file's order
    media: dict[str, Medium] = field(default_factory=dict)  # [media.NAME] in the file's order
    camera_medium: str | None = None  # [camera] medium: the medium the camera sits in, a name of ``media``

    @property
    def has_media(self) -> bool:
        """Whether the scene is volumetric: it defines a medium or uses a ``null`` material (Mitsuba's ``volpath``
        integrator then, and the reference's volumetric path loop)."""
        return bool(self.media) or any(m.type == "null" for m in self.materials.values())

    @property
    def used_textures(self) -> list[Texture]:
        """The textures some material's parameter or some light's emission takes, in the order of :attr:`textures`
        (the core's order)."""
        used = {id(texture) for material in self.materials.values() for _, texture in material.textures}
        used |= {id(m.perturbation.texture) for m in self.materials.values() if m.perturbation is not None}
        used |= {id(shape.emission_texture) for shape in self.shapes if shape.emission_texture is not None}
        return [texture for texture in self.textures.values() if id(texture) in used]

    @property
    def has_glossy_materials(self) -> bool:
        """Whether the scene is glossy: a material is not Lambertian (conductors, dielectrics).

        The harness's one rule, and the one the core's is built from: :func:`harness.scene.material_arrays` hands
        the core a material table exactly when it holds, so :func:`reference_impl.materials.is_glossy` of that
        table agrees. A glossy scene runs the reference's path loop with every BSDF kind (``direct`` and ``rr`` =
        "auto" resolved by :meth:`reference_impl.Settings.resolved`), and Mitsuba gets its spheres as meshes."""
        return any(not m.is_diffuse for m in self.materials.values())

    @property
    def envmap_size(self) -> tuple[int, int] | None:
        """(width, height) of the scene's environment map, or None: its tables count in a render's memory
        (harness.core.limits.envmap_bytes)."""
        for emitter in self.emitters:
            if isinstance(emitter, EnvironmentMap):
                return int(emitter.image.shape[1]), int(emitter.image.shape[0])
        return None

    @property
    def envmap_key(self) -> str | None:
        """``"FILE: emitters[i].file"``, the key that names the scene's environment map, or None."""
        for emitter in self.emitters:
            if isinstance(emitter, EnvironmentMap):
                return f"{self.path}: emitters[{emitter.index}].file"
        return None

    @property
    def lights(self) -> list[Shape]:
        """The emissive shapes, in light-id order (light k is ``lights[k]``)."""
        return [shape for shape in self.shapes if shape.is_emitter]
