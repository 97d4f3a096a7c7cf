"""What the kernels share besides code: numba's compile options, the settings as the kernels read them
(:class:`KernelConfig` and the table that fills it from :class:`reference_impl.settings.Settings`), the modes and
planted faults, and the order of the counters.

Every setting is a runtime int or float of one :class:`KernelConfig`, never a compile-time constant, so every
setting runs the same compiled signatures and no setting triggers a compilation.
"""

from typing import NamedTuple

from reference_impl.errors import SettingsError

# Every kernel is nogil (the integrator's thread pool runs them concurrently, as it runs Embree queries) and cached
# (reference_impl/kernels/__pycache__). IEEE semantics are kept: no fastmath (no reassociation, no FMA contraction),
# and error_model="numpy" so a division by zero gives inf/NaN as in numpy instead of raising. Reference counting and
# LLVM inlining are set explicitly: numba would otherwise let a function inherit them from whichever caller happened
# to compile it first.
JIT = dict(cache=True, nogil=True, error_model="numpy", _nrt=True, forceinline=False)
# Helpers that take arrays are inlined into their callers at numba's level: a call that passes an array increments
# and decrements its reference count atomically, and with two threads sharing the scene's arrays those atomics took
# a quarter of a render's time (perf: NRT_incref / NRT_decref).
JIT_INLINE = dict(JIT, inline="always")
# The helpers that share a vertex's work (between the engines, and within the path loop) take the caller's arrays and
# branch on what they find. Inlined at numba's level, their arguments' reference counts die on different branches,
# where numba's pruning of them fails: the path loop kept 15 increments and 29 decrements of the light tables around
# each light sample, and the engines were 11-17 % slower than with the code written out twice. These helpers only
# borrow the arrays and allocate nothing, so they are compiled without reference counting (``_nrt=False``, numba's
# option for such code) and always inlined by LLVM (``forceinline``): no count and no call is left in the loops.
JIT_BORROW = dict(JIT, _nrt=False, forceinline=True)
# Helpers that only borrow arrays but are too large or too many to inline everywhere (the BSDFs' lobes): no reference
# counting, calls left to LLVM. (The BSDFs with reference counting spent 3.5 % of a cornell-box-specular render in
# NRT_incref / NRT_decref; without it, and bsdf_eval / bsdf_pdf / bsdf_sample inlined, the render took 0.88-0.95x
# the time.)
JIT_NONRT = dict(JIT, _nrt=False)

# Counters, in the order of integrator.COUNTERS.
(C_CAMERA, C_SHADOW, C_SHADOW_SKIPPED, C_HEMI_DIRECT, C_INDIRECT, C_ESCAPED, C_BACK_FACE, C_ROULETTE, C_NONFINITE,
 C_LIGHT_SELECT) = range(10)

DIRECT_AREA, DIRECT_MIS, DIRECT_GLOBAL_AREA, DIRECT_HEMI_COSINE, DIRECT_HEMI_UNIFORM, DIRECT_BSDF = range(6)
# "auto" never reaches a kernel: a render resolves it (Settings.resolved) to "area" or "mis" (and rr's "auto" to
# "albedo" or "pbrt") before kernel_config reads the settings.
DIRECT_MODES = {"area": DIRECT_AREA, "mis": DIRECT_MIS, "global-area": DIRECT_GLOBAL_AREA,
                "hemisphere-cosine": DIRECT_HEMI_COSINE, "hemisphere-uniform": DIRECT_HEMI_UNIFORM,
                "bsdf": DIRECT_BSDF}
HEMI_UNIFORM, HEMI_COSINE = 0, 1
HEMISPHERE_MODES = {"uniform": HEMI_UNIFORM, "cosine": HEMI_COSINE}
RR_OFF, RR_ALBEDO, RR_FIXED, RR_THROUGHPUT, RR_PBRT = 0, 1, 2, 3, 4
RR_MODES = {"off": RR_OFF, "albedo": RR_ALBEDO, "fixed": RR_FIXED, "throughput": RR_THROUGHPUT, "pbrt": RR_PBRT}
SAMPLER_INDEPENDENT, SAMPLER_SOBOL = 0, 1
SAMPLER_MODES = {"independent": SAMPLER_INDEPENDENT, "sobol": SAMPLER_SOBOL}
FILTER_BOX, FILTER_TENT, FILTER_GAUSSIAN = 0, 1, 2
FILTER_KINDS = {"box": FILTER_BOX, "tent": FILTER_TENT, "gaussian": FILTER_GAUSSIAN}
EMIT_NONE, EMIT_ALL, EMIT_MIS = 0, 1, 2  # emission at a hit: not counted, counted, counted with the MIS weight
ENV_IMPORTANCE, ENV_UNIFORM, ENV_COSINE = range(3)
ENV_SAMPLING_MODES = {"importance": ENV_IMPORTANCE, "uniform": ENV_UNIFORM, "cosine": ENV_COSINE}

# Planted faults (reference_impl/mutants.py) that live in the kernels, as bits of KernelConfig.mutant; each place
# one changes is marked with a comment naming it. ("energy-loss-2pct" is the integrator's scale of finish_samples.)
(M_NO_COSINE, M_COSINE_PDF_PI, M_RR_NO_REWEIGHT, M_LIGHT_PDF_IGNORED, M_NO_RAY_OFFSET, M_DOUBLE_EMISSION,
 M_CAMERA_HALF_PIXEL, M_POINT_NO_INVERSE_SQUARE, M_SPOT_IGNORES_BEAM_WIDTH, M_ENVMAP_PDF_NO_SIN, M_ENVMAP_MIRRORED_U,
 M_DIRECTIONAL_REVERSED) = (1 << b for b in range(12))
MUTANT_BITS = {"no-cosine": M_NO_COSINE, "cosine-pdf-pi": M_COSINE_PDF_PI, "rr-no-reweight": M_RR_NO_REWEIGHT,
               "light-pdf-ignored": M_LIGHT_PDF_IGNORED, "no-ray-offset": M_NO_RAY_OFFSET,
               "double-emission": M_DOUBLE_EMISSION, "camera-half-pixel": M_CAMERA_HALF_PIXEL,
               "point-no-inverse-square": M_POINT_NO_INVERSE_SQUARE,
               "spot-ignores-beam-width": M_SPOT_IGNORES_BEAM_WIDTH, "envmap-pdf-no-sin": M_ENVMAP_PDF_NO_SIN,
               "envmap-mirrored-u": M_ENVMAP_MIRRORED_U, "directional-reversed": M_DIRECTIONAL_REVERSED}
# Planted faults of the BSDFs (reference_impl/kernels/bsdf.py; reference_impl.mutants.BSDF_MUTANTS).
M_MICROFACET_PDF_NO_JACOBIAN, M_CONDUCTOR_FRESNEL_ONE, M_REFRACTION_NO_ETA2, M_VNDF_ALPHA_SQUARED = (
    1 << b for b in range(12, 16))
MUTANT_BITS.update({"microfacet-pdf-no-jacobian": M_MICROFACET_PDF_NO_JACOBIAN,
                    "conductor-fresnel-one": M_CONDUCTOR_FRESNEL_ONE, "refraction-no-eta2": M_REFRACTION_NO_ETA2,
                    "vndf-alpha-squared": M_VNDF_ALPHA_SQUARED})
# The MIS weights' planted fault (reference_impl/kernels/direct.py power_weight; reference_impl.mutants.GLOSSY_MUTANTS).
M_MIS_WEIGHTS_NOT_ONE = 1 << 16
MUTANT_BITS["mis-weights-not-one"] = M_MIS_WEIGHTS_NOT_ONE
# The textures' planted faults (reference_impl/kernels/texture.py; reference_impl.mutants.TEXTURE_MUTANTS;
# "texture-srgb-as-linear" is in the texels, records.texture_tables).
M_TEXTURE_V_FLIPPED, M_TEXTURE_NEAREST, M_TEXTURE_HALF_TEXEL, M_TEXTURE_REPEAT_AS_CLAMP = (1 << b for b in range(17, 21))
MUTANT_BITS.update({"texture-v-flipped": M_TEXTURE_V_FLIPPED, "texture-nearest-not-bilinear": M_TEXTURE_NEAREST,
                    "texture-half-texel-shift": M_TEXTURE_HALF_TEXEL,
                    "texture-repeat-as-clamp": M_TEXTURE_REPEAT_AS_CLAMP})
# The shading normals' planted faults (reference_impl/kernels/shading.py and the path loop's side test;
# reference_impl.mutants.NORMAL_MUTANTS).
M_NORMALS_UNNORMALISED, M_SHADING_NORMAL_SIDE, M_NORMALMAP_GREEN_INVERTED, M_BUMP_SCALE_IGNORED = (
    1 << b for b in range(21, 25))
MUTANT_BITS.update({"normals-not-renormalised": M_NORMALS_UNNORMALISED,
                    "shading-normal-side": M_SHADING_NORMAL_SIDE,
                    "normalmap-green-inverted": M_NORMALMAP_GREEN_INVERTED,
                    "bumpmap-scale-ignored": M_BUMP_SCALE_IGNORED})
M_SPHERE_POINTS_THETA = 1 << 25  # the analytic spheres' light samples (kernels/direct.py planted_sphere_point)
MUTANT_BITS["sphere-points-uniform-theta"] = M_SPHERE_POINTS_THETA
# The cameras' planted faults (reference_impl/kernels/camera.py; reference_impl.mutants.CAMERA_MUTANTS).
M_LENS_SQUARE, M_FOCUS_ALONG_RAY, M_ORTHO_ORIGIN_NOT_OFFSET = (1 << b for b in range(26, 29))
MUTANT_BITS.update({"lens-sampled-on-square": M_LENS_SQUARE, "focus-along-ray": M_FOCUS_ALONG_RAY,
                    "orthographic-origin-not-offset": M_ORTHO_ORIGIN_NOT_OFFSET})
# The thin dielectric's and the plastic's planted faults (reference_impl/kernels/bsdf.py;
# reference_impl.mutants.MATERIAL_MUTANTS).
M_THIN_GLASS_REFRACTS, M_PLASTIC_NO_INTERNAL_REFLECTION = (1 << b for b in range(29, 31))
MUTANT_BITS.update({"thin-glass-refracts": M_THIN_GLASS_REFRACTS,
                    "plastic-no-internal-reflection": M_PLASTIC_NO_INTERNAL_REFLECTION})
# The principled BSDF's and the mask's (reference_impl/kernels/bsdf.py, kernels/path.py;
# reference_impl.mutants.MATERIAL_MUTANTS).
M_CLEARCOAT_PDF_NO_JACOBIAN, M_MASK_OPAQUE_TO_SHADOWS = (1 << b for b in range(31, 33))
MUTANT_BITS.update({"principled-clearcoat-pdf-jacobian": M_CLEARCOAT_PDF_NO_JACOBIAN,
                    "mask-opacity-1-in-shadow-rays": M_MASK_OPAQUE_TO_SHADOWS})
# The light tree's planted faults (reference_impl/kernels/light_tree.py, kernels/path.py;
# reference_impl.mutants.TREE_MUTANTS).
M_TREE_NO_BOUND_ANGLE, M_TREE_PMF_AT_HIT = (1 << b for b in range(33, 35))
MUTANT_BITS.update({"light-tree-no-bound-angle": M_TREE_NO_BOUND_ANGLE, "light-tree-pmf-at-hit": M_TREE_PMF_AT_HIT})
# The participating media's planted faults (reference_impl/kernels/volpath.py; reference_impl.mutants.MEDIA_MUTANTS).
M_NEE_NO_TRANSMITTANCE, M_HG_G_FLIPPED, M_FLIGHT_PDF_NO_SIGMA_T, M_ALBEDO_TWICE, M_NULL_AS_BOUNCE = (
    1 << b for b in range(35, 40))
MUTANT_BITS.update({"nee-no-transmittance": M_NEE_NO_TRANSMITTANCE, "hg-g-flipped": M_HG_G_FLIPPED,
                    "free-flight-pdf-no-sigma-t": M_FLIGHT_PDF_NO_SIGMA_T, "albedo-applied-twice": M_ALBEDO_TWICE,
                    "null-boundary-as-bounce": M_NULL_AS_BOUNCE})
# The sphere lights' cone (reference_impl/kernels/direct.py light_connection; reference_impl.mutants.SPHERE_MUTANTS).
M_SPHERE_CONE_PDF_AREA = 1 << 40
MUTANT_BITS["sphere-cone-pdf-area"] = M_SPHERE_CONE_PDF_AREA
MEDIUM_LIGHT, MEDIUM_PHASE, MEDIUM_MIS = range(3)
MEDIUM_DIRECT_MODES = {"light": MEDIUM_LIGHT, "phase": MEDIUM_PHASE, "mis": MEDIUM_MIS}
TR_RATIO, TR_TRACK = range(2)
TRANSMITTANCE_MODES = {"ratio": TR_RATIO, "track": TR_TRACK}


class KernelConfig(NamedTuple):
    """Every setting the kernels read, one slot each. A slot filled by a :class:`Settings` field has that field's
    name (:data:`FROM_SETTINGS` says how it is filled); the others come from the scene (:data:`FROM_SCENE`). Only
    ints and floats, so that every configuration is the same numba type."""

    depth: int  # the vertex a wavefront bounce is at (the viewing ray's hit is 1); 0 for the path loop
    max_depth: int  # longest path in segments, -1 unbounded
    direct: int  # DIRECT_*
    shadow_rays: int  # [Nd]
    indirect_rays: int  # [Ni]
    hemisphere: int  # HEMI_*
    rr: int  # RR_*
    rr_depth: int  # first vertex at which roulette is played
    survival: float  # q of rr = "fixed"
    mutant: int  # M_* bits
    sampler: int  # SAMPLER_*
    spp: int  # [Np]
    num_lights: int  # N_L
    offset_scene: float  # the scene-size part of a ray origin's offset (Intersector.offset_scene)
    surface_pdf: float  # 1 / A_scene, the density of global area sampling
    env_sampling: int  # ENV_*: how light samples draw directions toward an environment
    num_area_lights: int  # N_A: lights 0 .. N_A - 1 are area lights, N_A .. N_L - 1 the emitters that are not
    env_light: int  # the light index k of the environment, -1 without one
    packet_width: int  # rays per packet query: the widest Embree traces natively here (16, 8 or 4; 1: no packets)
    medium_direct: int  # MEDIUM_*: direct light at a medium's scattering points (kernels/volpath.py)
    transmittance: int  # TR_*: a shadow ray's transmittance through media (kernels/volpath.py)


# The scene as the kernels take it: the records of reference_impl.kernels.records (SceneTables, LightTables,
# SurfaceTables, MaterialTables; EmitterTables only in scenes that have emitters which are not surfaces, None
# otherwise, which compiles every branch for them out of the engines: such scenes run exactly the code they ran before
# those emitters existed).

# The one table from Settings to the kernels: slot of KernelConfig -> (the Settings field that fills it, its value in
# the slot).
FROM_SETTINGS = {
    "max_depth": ("max_depth", int),  # resolved to the scene's before a render
    "direct": ("direct", DIRECT_MODES.__getitem__),
    "shadow_rays": ("shadow_rays", int),
    "indirect_rays": ("indirect_rays", int),
    "hemisphere": ("hemisphere", HEMISPHERE_MODES.__getitem__),
    "rr": ("rr", RR_MODES.__getitem__),
    "rr_depth": ("rr_depth", int),
    "survival": ("absorption", lambda absorption: float(1.0 - absorption)),
    "mutant": ("mutant", lambda mutant: MUTANT_BITS.get(mutant, 0)),  # "" and "energy-loss-2pct": no bit
    "sampler": ("sampler", SAMPLER_MODES.__getitem__),
    "spp": ("spp", int),
    "env_sampling": ("env_sampling", ENV_SAMPLING_MODES.__getitem__),
    "medium_direct": ("medium_direct", MEDIUM_DIRECT_MODES.__getitem__),
    "transmittance": ("transmittance", TRANSMITTANCE_MODES.__getitem__),
}
# The slots the render fills from the scene (integrator._Context), and depth per wavefront bounce.
FROM_SCENE = ("depth", "num_lights", "offset_scene", "surface_pdf", "num_area_lights", "env_light", "packet_width")
# The Settings fields that fill no slot, and where they go instead.
NOT_SLOTS = {
    "seed": "its key, rng.seed_key(seed): FilmSamples.seed_key, read by camera_paths and the engines",
    "light_selection": "the light tables' pdf(k) (lights.LightSampler)",
    "batch_size": "how many camera samples the integrator hands to a kernel at once",
    "threads": "the integrator's thread pool",
    "engine": "which engine the integrator runs",
    "replicates": "the integrator's passes: each replicate its own seed_key and an spp slot of its own size",
}


def kernel_config(settings, num_lights: int, offset_scene: float, surface_pdf: float,
                  num_area_lights: int | None = None, env_light: int = -1, packet_width: int = 1) -> KernelConfig:
    """The :class:`KernelConfig` of a render with ``settings`` (max_depth resolved) on a scene with ``num_lights``
    lights, the first ``num_area_lights`` of them area lights (all, by default), the environment light
    ``env_light`` (-1: none), Embree's packets of ``packet_width`` rays (1: one query per ray); ``depth`` 0 (a
    wavefront bounce sets its own: ``config._replace(depth=...)``).
    ``settings`` are resolved (:meth:`Settings.resolved <reference_impl.settings.Settings.resolved>`): a ``direct``
    or ``rr`` of "auto" is a SettingsError."""
    for key in ("direct", "rr"):
        if getattr(settings, key) == "auto":
            raise SettingsError(key, "expected the resolved settings (Settings.resolved), got 'auto'")
    slots = {slot: fill(getattr(settings, field)) for slot, (field, fill) in FROM_SETTINGS.items()}
    area = int(num_lights if num_area_lights is None else num_area_lights)
    return KernelConfig(depth=0, num_lights=int(num_lights), offset_scene=float(offset_scene),
                        surface_pdf=float(surface_pdf), num_area_lights=area, env_light=int(env_light),
                        packet_width=int(packet_width), **slots)
