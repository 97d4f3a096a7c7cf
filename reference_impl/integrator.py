"""The stochastic global-illumination algorithm of the slides (Fig. 5.16), traced path by path or as a wavefront.

For each pixel, Np viewing rays through the pixel filter h (``computeImage``). At each hit x, the radiance toward
the previous vertex is estimated from the equations, not from the pseudo-code taken literally:

    L(x -> Theta)   = Le(x -> Theta) + L_r(x -> Theta)                          (only at the viewing ray's hit)
    L_r(x -> Theta) = L_direct(x -> Theta) + L_indirect(x -> Theta)              (eq. 5.2)
    <L_direct>      = 1/Nd sum Le(y_i) f_r G(x, y_i) V(x, y_i) / (pdf(k) pdf(y_i | k))   (eq. 5.3, Fig. 5.10)
    <L_indirect>    = 1/Ni sum L_r(r(x, Psi_i) -> -Psi_i) f_r cos(Psi_i, N_x) / p(Psi_i)  (Fig. 5.14)

The indirect estimate recurses on L_r, the *reflected* radiance at the next hit: emission met by an indirect ray is
already in L_direct and is not added again (the literal pseudo-code's ``computeRadiance`` adds Le(y) there, which
counts direct light twice; it survives only as the mutant "double-emission"). Russian roulette divides survivors
by their survival probability (Fig. 5.16, ``estimatedRadiance / (1 - absorption)``).

Two engines trace the same estimator with random numbers of their own (``Settings.engine``; which strategies each
runs: ``settings.CAPABILITIES``). The default, "path", hands a batch of camera samples to one compiled loop
(:func:`kernels.path.trace_paths`: the material step, the BSDF door, the light door and MIS at every vertex) that
follows each path to its end and queries Embree itself (its C API: ``reference_impl/embree_c.py``), after tracing
the batch's camera rays in packets of 16; it runs every scene with Ni = 1. The "wavefront" engine, needed on
Lambertian scenes when paths branch
(Ni > 1): all paths of a batch advance one bounce at a time, every ray query is one batched call, and everything
between two queries is one compiled kernel over all paths (``reference_impl/kernels/``, numba, ``nogil`` so that the
worker threads run kernels and Embree queries concurrently); there is no Python loop over rays. One bounce
(:func:`_bounce`) is: closest hits of the wavefront (Embree) -> :func:`kernels.wavefront.bounce` (emission at the
hits, the Nd direct-light samples and the rays they need, Russian roulette and the next wavefront) -> shadow rays
(Embree, any-hit; closest-hit for hemisphere sampling) -> :func:`kernels.wavefront.resolve_shadow` /
:func:`kernels.wavefront.resolve_hemisphere` (the direct light). The functions ``_direct_*``,
``_shadow_ray_estimate`` and ``_mis_weight_*`` named in comments are the sections of the kernels that compute each
estimator; their formulas are the ones written above.
"""

from __future__ import annotations

import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from reference_impl import rng
from reference_impl.camera import Camera, Film
from reference_impl.emitters import Emitters, scene_radius
from reference_impl.errors import SettingsError
from reference_impl.geometry import Geometry
from reference_impl.intersect import Intersector
from reference_impl.lights import LightSampler, TriangleAreaSampler
from reference_impl.materials import NULL, PRINCIPLED, ROUGHPLASTIC, THINDIELECTRIC, Materials, is_glossy
from reference_impl.media import Media
from reference_impl.sampling import INV_PI
from reference_impl.settings import CAPABILITIES, GLOSSY_DIRECT, Settings

COUNTERS = (
    "camera_rays",  # viewing rays traced
    "shadow_rays",  # occlusion (any-hit) queries toward sampled light points
    "shadow_rays_skipped",  # light samples needing no ray: light faces away, point behind x, or not on a light
    "hemisphere_direct_rays",  # closest-hit rays cast for direct light by hemisphere sampling (Fig. 5.12)
    "indirect_rays",  # closest-hit rays cast for the indirect estimate
    "escaped_rays",  # rays that left the scene
    "back_face_absorbed",  # hits on the back of one-sided surfaces (black, end of path)
    "roulette_terminated",  # paths ended by Russian roulette (including zero-albedo surfaces)
    "nonfinite_samples",  # camera samples whose radiance is NaN or infinite
    "light_selections",  # draws of a light k from pdf(k) (none in a scene with one light)
)
# Time, in microseconds, the worker threads spent inside Embree queries (summed over threads, so it can exceed the
# wall time): the only entry of ``stats`` that is not a deterministic count. The wavefront times each batched query;
# the path loop times one query in kernels.queries.TIMING_STRIDE and scales by the stride.
EMBREE_MICROSECONDS = "embree_microseconds"


def _kernels():
    """reference_impl.kernels with the modules a render runs (``kernels.config``, ``kernels.path``, ...), imported on
    first use (importing numba takes a few tenths of a second, which only a render needs to pay)."""
    from reference_impl import kernels  # optional: numba-compiled, needed only to trace
    from reference_impl.kernels import (bsdf, camera, compile_once, config, film,  # optional: numba; noqa: F401
                                        blocks, path_blocks, path, records, volpath, wavefront)

    return kernels


@dataclass
class RenderOutput:
    """What a render returns: the pixel estimates, their variances, and counters.

    image    (H, W, 3) float32: mean of the Np weighted samples of each pixel.
    variance (H, W, 3) float32: variance of that mean, estimated as the sample variance / Np; NaN when Np = 1.
             Exact in expectation for ``sampler = "independent"``; an upper bound for "sobol", whose samples of a
             pixel are stratified (docs/reference-renderer.md).
    stats    counters (see ``COUNTERS``) plus ``paths`` (camera paths traced) and ``embree_microseconds`` (time in
             Embree queries, summed over threads).
    seconds  wall time of the render alone (no scene loading, no file writing, no kernel loading).
    load_seconds  wall time of loading, before the clock starts, every compiled kernel specialisation the render
             calls (:func:`_load_kernels`: from numba's cache in a fresh process, nothing to do in one that
             rendered the same kinds of scene before).
    variance_dof  degrees of freedom of ``variance``: R - 1 with R > 1 replicates (``Settings.replicates``), else
             Np - 1; None when Np = 1.
    """

    image: np.ndarray
    variance: np.ndarray
    stats: dict[str, int]
    seconds: float
    settings: Settings = field(repr=False, default=None)
    variance_dof: int | None = None
    load_seconds: float = 0.0


class _Sampling(NamedTuple):
    """Where a pass over the pixels draws its numbers: its samples per pixel, its seed, its key
    (:func:`reference_impl.rng.seed_key`) and the kernels' configuration with that spp. The render itself, or one of
    its replicates."""

    spp: int
    seed: int
    seed_key: np.uint64
    config: tuple


@dataclass
class _PathState:
    """The active paths of a wavefront, one row each, sorted by root."""

    root: np.ndarray  # (n,) index of the camera sample this path belongs to
    key: np.ndarray  # (n,) uint64 random-stream key
    origin: np.ndarray  # (n, 3)
    direction: np.ndarray  # (n, 3) unit
    origin32: np.ndarray  # (n, 3) float32 copy of origin, for Embree
    direction32: np.ndarray  # (n, 3) float32 copy of direction, for Embree
    beta: np.ndarray  # (n, 3) throughput: product of weights f cos / p / Ni / q so far
    pdf_dir: np.ndarray  # (n,) Ni * p(Psi) of the ray that reached the next vertex (used by MIS only)
    env_pdf: np.ndarray  # (n,) Nd pdf(k_env) p(Psi) of the light samples at its origin (MIS with an environment only)

    def __len__(self) -> int:
        return len(self.root)

    def arrays(self) -> tuple:
        return (self.root, self.key, self.origin, self.direction, self.origin32, self.direction32, self.beta,
                self.pdf_dir, self.env_pdf)

    def take(self, idx) -> "_PathState":
        return _PathState(*(a[idx] for a in self.arrays()))


def _alloc_state(capacity: int) -> tuple:
    """Room for a wavefront of ``capacity`` paths (the fields of :class:`_PathState`)."""
    return (np.empty(capacity, np.int64), np.empty(capacity, np.uint64), np.empty((capacity, 3)),
            np.empty((capacity, 3)), np.empty((capacity, 3), np.float32), np.empty((capacity, 3), np.float32),
            np.empty((capacity, 3)), np.empty(capacity), np.empty(capacity))


def _view(buffers: tuple, n: int) -> tuple:
    return tuple(a[:n] for a in buffers)


class _Workspace:
    """One worker thread's buffers, reused by every bounce of every batch it traces: two wavefronts (with Ni = 1 the
    next wavefront is written into the one the current wavefront does not use), and the hits of a bounce with their
    direct-light rays. Writing into fresh memory at every bounce costs page faults: about a fifth of the render time
    at the default batch size. Buffers only grow; one that is replaced stays alive as long as a view of it does."""

    def __init__(self, nd: int, hemisphere: bool, complements: int = 0):
        self._nd = nd
        self._hemisphere = hemisphere
        self._complements = complements  # complement rays per hit (kernels.direct.complement_sample)
        self._states: list[tuple | None] = [None, None]
        self._hit_capacity = -1
        self.hits = self.total = self.rays = self.crays = None
        self._radiance = None
        self._samples = None

    def samples(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Room for the (pixel, sample) of ``n`` camera samples (valid until this thread's next batch)."""
        if self._samples is None or len(self._samples[0]) < n:
            self._samples = (np.empty(n, np.int64), np.empty(n, np.int64))
        return self._samples[0][:n], self._samples[1][:n]

    def radiance(self, n: int, zeroed: bool = True) -> np.ndarray:
        """Room for ``n`` camera samples' radiance, zeroed unless the kernel writes every row (valid until this
        thread's next batch)."""
        if self._radiance is None or len(self._radiance) < n:
            self._radiance = np.empty((n, 3))
        view = self._radiance[:n]
        if zeroed:
            view.fill(0.0)
        return view

    def state(self, which: int, n: int) -> tuple:
        """Wavefront buffer ``which`` (0 or 1), with room for ``n`` paths."""
        buf = self._states[which]
        if buf is None or len(buf[0]) < n:
            buf = self._states[which] = _alloc_state(n)
        return buf

    def direct(self, n: int) -> tuple:
        """(hits, total, rays) with room for ``n`` hits and their Nd direct-light rays each (see kernels.wavefront.bounce)."""
        if self._hit_capacity < n:
            cap, hemi = n * self._nd, self._hemisphere
            self.hits = np.empty(n, np.int64)
            self.total = np.empty((n, 3))
            self.rays = (np.empty(cap, np.int64), np.empty((cap, 3), np.float32), np.empty((cap, 3), np.float32),
                         np.empty(0 if hemi else cap, np.float32), np.empty((cap, 3)), np.empty(cap if hemi else 0),
                         np.empty((cap if hemi else 0, 3)))
            ccap = n * self._complements
            self.crays = (np.empty(ccap, np.int64), np.empty((ccap, 3), np.float32), np.empty((ccap, 3), np.float32),
                          np.empty(ccap, np.float32), np.empty((ccap, 3)))
            self._hit_capacity = n
        return self.hits, self.total, self.rays

    def complement_rays(self) -> tuple:
        """(owner, origin32, direction32, tfar32, value) of the complement shadow rays (after :meth:`direct`)."""
        return self.crays


class _Context:
    """Everything shared by all batches of one render (read-only once built)."""

    def __init__(self, geometry: Geometry, camera: Camera, film: Film, settings: Settings,
                 emitters: Emitters | None = None, materials: Materials | None = None, media: Media | None = None):
        if settings.max_depth is None:
            raise SettingsError("max_depth", "expected the scene's max_depth to be resolved before rendering")
        settings = settings.resolved(is_glossy(materials))  # direct = auto and rr = auto: the one place
        self.engine, self.materials = _engine(geometry, settings, emitters, materials)
        self.media = media if media is not None and len(media) else None
        if media is not None:
            media.check_triangles(len(geometry.triangles))
        if self.media is not None or np.any(self.materials.kind == NULL):
            self.engine = _volpath_engine(geometry, settings, emitters, self.materials)
        self.max_depth = settings.resolved_max_depth(settings.max_depth)
        self.geometry = geometry
        self.camera = camera
        self.film = film
        self.filter = film.pixel_filter
        self.settings = settings
        self.intersector = Intersector(geometry)
        # Emitters that are not surfaces; none at all is the scene without them, to the bit (kernels.config).
        self.emitters = emitters if emitters is not None and len(emitters) else None
        self.has_lights = geometry.num_lights > 0 or self.emitters is not None
        extra_power = None
        if self.emitters is not None:
            used = np.zeros(len(geometry.vertices), bool)  # the vertices of triangles (np.unique sorts: slower)
            used[geometry.triangles.ravel()] = True
            extra_power = self.emitters.powers(scene_radius(geometry.vertices[used] if len(geometry.triangles)
                                                            else geometry.vertices))
        self.lights = LightSampler(geometry, settings.light_selection, extra_power) if self.has_lights else None
        usable = np.flatnonzero(geometry.area > 0)
        self.all_surfaces = TriangleAreaSampler(geometry, usable) if len(usable) else None
        self.mutant = settings.mutant  # a planted fault (reference_impl/mutants.py), "" in every real render
        self.split_cap = 4 * settings.batch_size
        self.hemisphere_direct = settings.direct in ("hemisphere-cosine", "hemisphere-uniform")
        self._local = threading.local()
        self._kernel_tables()

    def workspace(self) -> _Workspace:
        """The calling thread's buffers."""
        ws = getattr(self._local, "workspace", None)
        if ws is None:
            ws = self._local.workspace = _Workspace(self.settings.shadow_rays, self.hemisphere_direct,
                                                    self.complements)
        return ws

    def _kernel_tables(self) -> None:
        """The scene, the samplers and the settings as the records and the configuration the kernels take
        (:mod:`reference_impl.kernels.records`, :mod:`reference_impl.kernels.config`)."""
        kernels = _kernels()
        records = kernels.records
        s = self.settings
        self.scene_tables = records.scene_tables(self.geometry, self.intersector.prim_to_tri,
                                                 self.materials.textured or self.materials.anisotropic)
        self.light_tables = records.light_tables(self.lights)
        # None unless light_selection = "tree": the path loop compiles the tree out
        self.tree_tables = records.tree_tables(self.lights)
        self.surface_tables = records.surface_tables(self.all_surfaces)
        surface_pdf = 1.0 / self.all_surfaces.total_area if self.all_surfaces is not None else 0.0
        num_lights = self.lights.num_lights if self.lights is not None else 0
        em = self.emitters
        env_light = self.geometry.num_lights + em.env if em is not None and em.env >= 0 else -1
        self.config = kernels.config.kernel_config(s, num_lights, self.intersector.offset_scene, surface_pdf,
                                                   num_area_lights=self.geometry.num_lights, env_light=env_light,
                                                   packet_width=self.intersector.packet_width)
        self.material_tables = records.material_tables(self.materials, self.mutant,
                                                       kernels.bsdf.roughplastic_luts(self.materials))
        # None where no area light is textured (with shading, spheres and emitters: which scenes the blocks take)
        self.light_textures = self.material_tables.textures if self.geometry.textured_lights else None
        # None where every material is diffuse: the path loop compiles the BSDF door's other kinds out
        self.other_kinds = True if is_glossy(self.materials) else None
        # None where no triangle has vertex normals and no material a normal or bump map
        self.shading = True if (self.geometry.has_shading_normals or self.materials.perturbed
                                or self.materials.anisotropic) else None
        # None where no material is made of others (blendbsdf, twosided of two, mask) / is a mask: the path loop
        # compiles the material step's resolution / the cut-outs' holes out
        self.masks = True if self.materials is not None and self.materials.masked else None
        self.nested = True if self.materials is not None and (self.materials.nested or self.masks) else None
        # None where no material is a rough plastic or a principled: the BSDF door's branches for them compiled out
        self.later = True if np.any(np.isin(self.materials.kind, (ROUGHPLASTIC, PRINCIPLED))) else None
        self.medium_tables = records.medium_tables(self.media, len(self.geometry.triangles))
        self.volpath_emitters = records.emitter_tables(self.emitters if self.emitters is not None else Emitters([]))
        # What the path loop takes for textured lights and spheres: given on every scene (a lookup the scene's
        # tables answer: no textured light, no sphere), so that scenes differing in them share one compiled
        # specialization at the same speed. Emitters and shading frames stay None where a scene has none, and the
        # glossy blocks keep the flags above: given them, renders were slower (docs/performance.md, "The README's
        # first command").
        self.features = (self.material_tables.textures, self.scene_tables.sphere)
        self.compiled = False  # whether the path loop's specialization is ready here (kernels.compile_once)
        self.emitter_tables = None
        self.complements = 0  # shadow rays per hit for the emitters the direct strategy cannot find
        if em is not None:
            self.emitter_tables = records.emitter_tables(em)
            if s.direct in ("hemisphere-cosine", "hemisphere-uniform", "global-area"):
                self.complements = len(em)
        # Paths traced in blocks that go from vertex to vertex together, their rays in packets (kernels/blocks.py;
        # the path loop's bits), on a Lambertian scene lit by area lights alone, which the path loop runs with its
        # options compiled out
        self.blocks = (BLOCKS and self.engine == "path" and s.direct == "area" and self.other_kinds is None
                       and em is None and self.light_textures is None and self.shading is None
                       and self.masks is None and self.nested is None and self.tree_tables is None
                       and not self.geometry.num_spheres)
        # ... and likewise a scene with a material that is not diffuse, but for masks and nested materials
        # (kernels/path_blocks.py). Lambertian scenes with emitters, spheres, shading normals, textured lights or a
        # light tree keep the path loop, which their hemisphere and global-area strategies need anyway: one kernel
        # compiled for them, not two (docs/performance.md, "Issue 39: the path loop's scenes in blocks")
        self.path_blocks = (BLOCKS and self.engine == "path" and self.other_kinds is not None
                            and s.direct in ("area", "mis", "bsdf") and self.masks is None and self.nested is None)
        self.filter_kind = kernels.config.FILTER_KINDS[self.filter.name]
        self.camera_record = records.camera_record(self.camera, self.film.width, self.film.height)
        self.seed_key = rng.seed_key(s.seed)
        self.sampling = _Sampling(s.spp, s.seed, self.seed_key, self.config)

    def replicate(self, r: int, spp: int) -> _Sampling:
        """Replicate ``r`` of ``spp`` samples per pixel: a render of its own seed (``Settings.replicate_seed``)."""
        seed = self.settings.replicate_seed(r)
        return _Sampling(spp, seed, rng.seed_key(seed), self.config._replace(spp=spp))


class _Clock:
    """Seconds one worker spent inside Embree queries."""

    __slots__ = ("seconds",)

    def __init__(self):
        self.seconds = 0.0


# What a scene with a material that is not diffuse says of a strategy it does not take (a row of CAPABILITIES
# without "glossy"), before the value.
_GLOSSY_REFUSALS = {
    "direct": f"take direct = {', '.join(GLOSSY_DIRECT)} or auto",
    "indirect_rays": "trace one BSDF sample per vertex: expected indirect_rays = 1",
    "env_sampling": "sample the environment on both sides of a surface: expected "
                    + " or ".join(v for (k, v), e in CAPABILITIES.items() if k == "env_sampling" and "glossy" in e),
}


def _volpath_engine(geometry: Geometry, settings: Settings, emitters: Emitters | None, materials: Materials) -> str:
    """"volpath" (kernels/volpath.py), the engine of a scene with media or a ``null`` material, or SettingsError
    naming what it does not trace: a strategy whose row of CAPABILITIES lacks "volpath", and the scene words it does
    not carry yet (textured lights, shading normals, composite materials, the thin dielectric, whose Mitsuba volpath
    lets shadow rays through as a null boundary)."""
    rows = settings.strategies(emitters is not None and emitters.env >= 0, media=True)
    for (key, value), engines in ((row, CAPABILITIES.get(row, ())) for row in rows):
        if "volpath" not in engines:
            allowed = [v for (k, v), e in CAPABILITIES.items() if k == key and "volpath" in e]
            raise SettingsError(key, f"scenes with media take {key} = {' or '.join(allowed)}, got "
                                     f"{getattr(settings, key)!r}")
    words = (("textured area lights", geometry.textured_lights),
             ("shading normals (vertex normals, normal or bump maps)",
              geometry.has_shading_normals or materials.perturbed or materials.anisotropic),
             ("composite materials (blendbsdf, mask, twosided of two)", materials.nested or materials.masked),
             ("a thindielectric", bool(np.any(materials.kind == THINDIELECTRIC))))
    for word, present in words:
        if present:
            raise SettingsError("media", f"the volumetric path loop does not trace {word} yet")
    return "volpath"


def _engine(geometry: Geometry, settings: Settings, emitters: Emitters | None,
            materials: Materials | None) -> tuple[str, Materials]:
    """Which engine traces the render, "path" (kernels/path.py) or "wavefront" (kernels/wavefront.py), by
    :data:`~reference_impl.settings.CAPABILITIES`: a scene with a material that is not diffuse runs the path loop; a
    Lambertian one ``settings.engine``, or the other engine where a strategy needs it. And the material table every
    engine's material step reads (the geometry's diffuse albedos where none is given). SettingsError for a strategy
    the scene or no engine runs. ``settings`` are resolved already."""
    if materials is not None and len(materials) != len(geometry.reflectance):
        raise SettingsError("materials", f"expected one material per entry of the geometry's reflectance "
                                         f"({len(geometry.reflectance)}), got {len(materials)}")
    glossy = is_glossy(materials)
    # an unresolved "auto" is in no row: no engine runs it
    rows = {row: CAPABILITIES.get(row, ()) for row in settings.strategies(emitters is not None and emitters.env >= 0)}
    if materials is None:
        materials = Materials.diffuse(geometry.reflectance, geometry.two_sided)
    if np.any(geometry.emission_texture >= len(materials.textures)):
        raise SettingsError("emission_texture", f"expected -1 or a texture index below {len(materials.textures)} "
                                                "(the materials' textures)")
    if geometry.textured_lights and (settings.engine == "wavefront" or settings.indirect_rays > 1):
        raise SettingsError("indirect_rays" if settings.indirect_rays > 1 else "engine",
                            "a textured area light is traced by the path loop alone: expected indirect_rays = 1 and "
                            f"engine = path, got {settings.indirect_rays} and {settings.engine!r}")
    shading = geometry.has_shading_normals or materials.perturbed
    if shading and (settings.engine == "wavefront" or settings.indirect_rays > 1):
        raise SettingsError("indirect_rays" if settings.indirect_rays > 1 else "engine",
                            "shading normals (vertex normals, a normal or bump map) are traced by the path loop "
                            f"alone: expected indirect_rays = 1 and engine = path, got {settings.indirect_rays} and "
                            f"{settings.engine!r}")
    if glossy:
        for (key, value), engines in rows.items():
            if "glossy" not in engines and key in _GLOSSY_REFUSALS:
                raise SettingsError(key, f"scenes with a material that is not diffuse {_GLOSSY_REFUSALS[key]}, "
                                         f"got {getattr(settings, key)!r}")
        return "path", materials
    other = "wavefront" if settings.engine == "path" else "path"
    for engine in (settings.engine, other):
        if all(engine in engines for engines in rows.values()) and not (shading and engine == "wavefront"):
            return engine, materials
    path_only = next(row for row, engines in rows.items() if "wavefront" not in engines)
    raise SettingsError("indirect_rays", "the path loop traces one ray per vertex (indirect_rays > 1 is the "
                                         "wavefront's, which does not run {} = {}): expected indirect_rays = 1, got "
                                         "{}".format(*path_only, settings.indirect_rays))


def render(geometry: Geometry, camera: Camera, film: Film, settings: Settings, progress=None,
           emitters: Emitters | None = None, materials: Materials | None = None,
           media: Media | None = None) -> RenderOutput:
    """Render an image with the slides' algorithm (Fig. 5.16).

    ``settings.max_depth`` must be set (the harness fills in the scene's). ``progress``, if given, is called from
    the calling thread as ``progress(done_paths, total_paths)``. ``emitters``: the scene's emitters that are not
    surfaces (point, spot, directional lights, an environment), or None. The result depends only on the inputs and
    ``settings.seed``: not on ``batch_size`` or ``threads``. ``materials``: the scene's material table
    (:class:`Materials`, in the order ``geometry.material`` indexes), or None (all Lambertian, as
    ``geometry.reflectance`` says). None or all diffuse runs ``settings.engine`` (or the other engine where a
    strategy needs it: :func:`_engine`); a material that is not diffuse the path loop (kernels/path.py).
    ``direct = auto`` and ``rr = auto`` are resolved by the render's context (:meth:`Settings.resolved`, for
    :func:`~reference_impl.materials.is_glossy`); the output's settings hold the resolved ones. ``media``: the
    scene's participating media and its triangles' medium transitions (:class:`~reference_impl.media.Media`), or
    None; a scene with media or a ``null`` material runs the volumetric path loop (kernels/volpath.py).
    """
    ctx = _Context(geometry, camera, film, settings, emitters, materials, media)
    settings = ctx.settings
    kernels = _kernels()
    width, height, spp = film.width, film.height, settings.spp
    num_pixels = width * height
    threads = settings.worker_threads()
    # Units of work: ranges of whole pixels, all their samples in order, so every pixel's sum is formed in sample
    # order whatever the decomposition. Small enough to keep every thread busy: at most batch_size paths, and at least
    # UNITS_PER_THREAD units a thread.
    pixels_per_unit = max(1, settings.batch_size // spp)
    pixels_per_unit = min(pixels_per_unit, max(1, math.ceil(num_pixels / (UNITS_PER_THREAD * threads))))
    samples_per_chunk = max(1, min(spp, settings.batch_size // pixels_per_unit))
    units = [(p0, min(num_pixels, p0 + pixels_per_unit)) for p0 in range(0, num_pixels, pixels_per_unit)]

    sizes = settings.replicate_sizes()
    passes = [ctx.sampling] if len(sizes) == 1 else [ctx.replicate(r, n) for r, n in enumerate(sizes)]
    total = np.zeros((num_pixels, 3))
    total_sq = np.zeros((num_pixels, 3))
    stats = dict.fromkeys(COUNTERS, 0)
    stats[EMBREE_MICROSECONDS] = 0
    scale = 0.98 if ctx.mutant == "energy-loss-2pct" else 1.0
    loaded = time.perf_counter()
    if units and ctx.has_lights:
        _load_kernels(ctx, passes[0], scale)
    start = time.perf_counter()

    def run_pass(unit, sampling, sums, sums_sq, offset, unit_stats):
        """Every sample of ``sampling`` (one replicate, or the render) of the unit's pixels, summed into
        ``sums[offset + p]`` in sample order."""
        p0, p1 = unit
        for s0 in range(0, sampling.spp, samples_per_chunk):
            s1 = min(sampling.spp, s0 + samples_per_chunk)
            pixel, sample = ctx.workspace().samples((p1 - p0) * (s1 - s0))
            kernels.film.unit_samples(p0, p1, s0, s1, pixel, sample)
            values = _trace_camera_paths(ctx, pixel, sample, unit_stats, sampling=sampling, finish=False)
            # Sequential sums in sample order, so chunking cannot change a single bit.
            unit_stats["nonfinite_samples"] += kernels.film.finish_and_accumulate(sums, sums_sq, offset, values,
                                                                                s1 - s0, scale)

    def run_unit(unit):
        p0, p1 = unit
        unit_stats = dict.fromkeys(COUNTERS, 0)
        unit_stats[EMBREE_MICROSECONDS] = 0
        if len(passes) == 1:
            run_pass(unit, passes[0], total, total_sq, p0, unit_stats)
        else:
            # The replicates' means, combined one by one (Welford): total <- their mean, total_sq <- the sum of
            # their squared deviations from it.
            sums, sums_sq = np.empty((p1 - p0, 3)), np.empty((p1 - p0, 3))
            mean, m2 = total[p0:p1], total_sq[p0:p1]
            for r, sampling in enumerate(passes):
                sums.fill(0.0)
                run_pass(unit, sampling, sums, sums_sq, 0, unit_stats)
                value = sums / sampling.spp
                delta = value - mean
                mean += delta / (r + 1)
                m2 += delta * (value - mean)
        return (p1 - p0) * spp, unit_stats

    done = 0
    if not ctx.has_lights:  # nothing emits: the image is black, exactly, and needs no ray at all
        units = []
        if progress is not None:
            progress(num_pixels * spp, num_pixels * spp)
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for paths, unit_stats in pool.map(run_unit, units):
            done += paths
            for k, v in unit_stats.items():
                stats[k] += v
            if progress is not None:
                progress(done, num_pixels * spp)
    seconds = time.perf_counter() - start

    replicates = len(passes)
    if replicates > 1:  # the mean of the replicate means; the variance of that mean from their spread
        mean = total
        var_of_mean = total_sq / (replicates - 1) / replicates
        if ctx.mutant == "replicates-ddof0":  # planted fault: the biased variance of the replicate means
            var_of_mean = total_sq / replicates / replicates
        dof = replicates - 1
    else:
        mean = total / spp
        dof = spp - 1 if spp > 1 else None
    if not ctx.has_lights:
        var_of_mean = np.zeros_like(mean)
    elif replicates > 1:
        pass
    elif spp > 1:
        sample_var = np.maximum(total_sq - total * total / spp, 0.0) / (spp - 1)
        var_of_mean = sample_var / spp
    else:
        var_of_mean = np.full_like(mean, np.nan)
    stats["paths"] = num_pixels * spp
    return RenderOutput(
        image=mean.reshape(height, width, 3).astype(np.float32),
        variance=var_of_mean.reshape(height, width, 3).astype(np.float32),
        stats=stats,
        seconds=seconds,
        settings=settings,
        variance_dof=dof,
        load_seconds=start - loaded,
    )


#: whether paths may be traced in blocks with their rays in packets (kernels/blocks.py) where a scene allows it; the
#: images are the same either way (tests/reference_impl/test_blocks.py switches it)
BLOCKS = True

#: the least number of units of work a render's pixels are cut into, per worker thread: enough that the units' unequal
#: costs (a film's bright and dark rows) even out between the threads (docs/performance.md, "Units of work")
UNITS_PER_THREAD = 8

#: how many pixels, spread over the film, the warm step traces (:func:`_load_kernels`)
WARM_PIXELS = 64
#: camera samples of each of them
WARM_SAMPLES = 4


def _load_kernels(ctx: _Context, sampling: _Sampling, scale: float) -> None:
    """Make every compiled kernel specialisation the render's workers will call ready in this process before the
    render's clock starts, so that ``RenderOutput.seconds`` is the render alone: a fresh process would otherwise load
    them from numba's cache (about half a second for the path loop) inside the timed region, in the first batch of
    each worker.

    Loaded by calling them, with the render's own argument types, on a warm batch that the render never reads:
    :data:`WARM_SAMPLES` camera samples of each of :data:`WARM_PIXELS` pixels spread evenly over the film (the same
    buffers' kinds as :func:`render`'s batches: the calling thread's workspace, pixel sums and counters of its own).
    The path and volumetric loops are one kernel each, loaded whatever the batch meets; the wavefront calls a kernel
    per step (shadow rays, hemisphere rays, the next bounce's queries), which a batch spread over the film meets on
    any scene with light. The random streams are keyed by (seed, pixel, sample), counters rather than states
    (:mod:`reference_impl.rng`), so the warm batch changes no bit of the image, and its counters are dropped."""
    kernels = _kernels()
    num_pixels = ctx.film.width * ctx.film.height
    chosen = np.unique(np.linspace(0, num_pixels - 1, min(WARM_PIXELS, num_pixels)).astype(np.int64))
    count = min(WARM_SAMPLES, sampling.spp)
    pixel, sample = ctx.workspace().samples(len(chosen) * count)
    for k, p in enumerate(chosen.tolist()):
        kernels.film.unit_samples(p, p + 1, 0, count, pixel[k * count:(k + 1) * count], sample[k * count:(k + 1) * count])
    dropped = dict.fromkeys(COUNTERS, 0)
    dropped[EMBREE_MICROSECONDS] = 0
    values = _trace_camera_paths(ctx, pixel, sample, dropped, sampling=sampling, finish=False)
    sums = np.zeros((len(chosen), 3))
    kernels.film.finish_and_accumulate(sums, np.zeros_like(sums), 0, values, count, scale)


def _trace_camera_paths(ctx: _Context, pixel: np.ndarray, sample: np.ndarray, stats: dict, record=None,
                        sampling: _Sampling | None = None, finish: bool = True) -> np.ndarray:
    """Radiance estimates (n, 3) of camera samples (pixel, sample): ``rad(ray) * h(p)`` of Fig. 5.16. ``record``:
    buffers for the rays of the path loop or of the blocks (:mod:`reference_impl.kernels.record`, used by
    :mod:`reference_impl.replay`;
    the wavefront's rays are recorded from its batched queries). ``sampling``: the pass the samples
    belong to (a replicate), by default the render's own. ``finish`` = False leaves the planted fault
    "energy-loss-2pct" and the count of non-finite samples to the caller (:func:`kernels.film.finish_and_accumulate`,
    in the same pass as the pixel sums)."""
    kernels = _kernels()
    sampling = sampling or ctx.sampling
    config, seed, spp = sampling.config, sampling.seed, sampling.spp
    n = len(pixel)
    sobol = config.sampler == kernels.config.SAMPLER_SOBOL
    drawn = None
    if ctx.filter_kind == kernels.config.FILTER_GAUSSIAN:  # sampled through its table by the numpy filter code
        if sobol:
            ux, uy = rng.sobol_2d(rng.pixel_keys(seed, pixel), sample, spp, rng.dimension(0, rng.FILM_X))
        else:
            keys = rng.path_keys(seed, pixel.astype(np.uint64) * np.uint64(spp) + sample.astype(np.uint64))
            ux, uy = rng.uniform(keys, rng.dimension(0, rng.FILM_X)), rng.uniform(keys, rng.dimension(0, rng.FILM_Y))
        drawn = ctx.filter.sample(ux, uy)
    first = _view(ctx.workspace().state(0, n), n)
    film_samples = kernels.records.film_samples(pixel, sample, sampling.seed_key)
    pixel_filter = kernels.records.filter_samples(ctx.filter_kind, drawn)
    kernels.camera.camera_paths(film_samples, config, ctx.camera_record, pixel_filter, first)
    # paths traced in blocks (a path-loop scene: _Context.blocks, path_blocks), recorded there too
    in_blocks = ctx.blocks or ctx.path_blocks
    # the blocks write every path's row (the path loop and the wavefront add to theirs)
    radiance = ctx.workspace().radiance(n, zeroed=not in_blocks)
    counters = np.zeros(len(COUNTERS), np.int64)
    counters[kernels.config.C_CAMERA] = n
    clock = _Clock()
    if ctx.engine == "volpath":
        if record is not None:
            raise SettingsError("media", "the volumetric path loop's rays are not recorded (replay)")
        timing = np.zeros(2, np.int64)
        # one specialization for every scene with media (emitters and spheres always given, possibly empty; every
        # BSDF kind compiled in): one compilation, whatever the scene
        args = (first, ctx.intersector.scene_pointer, ctx.scene_tables, ctx.light_tables, ctx.material_tables, config,
                radiance, counters, timing, film_samples, ctx.volpath_emitters, ctx.medium_tables, ctx.scene_tables.sphere, True)
        if not ctx.compiled:
            kernels.compile_once.compile_once(kernels.volpath.trace_volpaths, args)
            ctx.compiled = True
        kernels.volpath.trace_volpaths(*args)
        clock.seconds += timing[0] * 1e-9
    elif ctx.path_blocks:
        timing = np.zeros(2, np.int64)
        args = (first, ctx.intersector.scene_pointer, ctx.scene_tables, ctx.light_tables, ctx.material_tables, config,
                radiance, counters, timing, film_samples, ctx.emitter_tables, ctx.other_kinds, ctx.light_textures,
                ctx.shading,
                ctx.scene_tables.sphere if ctx.geometry.num_spheres else None, ctx.later, ctx.tree_tables, record)
        if not ctx.compiled:
            kernels.compile_once.compile_once(kernels.path_blocks.trace_path_blocks, args)
            ctx.compiled = True
        kernels.path_blocks.trace_path_blocks(*args)
        clock.seconds += timing[0] * 1e-9
    elif in_blocks:
        timing = np.zeros(2, np.int64)
        args = (first, ctx.intersector.scene_pointer, ctx.scene_tables, ctx.light_tables, ctx.material_tables, config,
                radiance, counters, timing, film_samples, record)
        if not ctx.compiled:
            kernels.compile_once.compile_once(kernels.blocks.trace_blocks, args)
            ctx.compiled = True
        kernels.blocks.trace_blocks(*args)
        clock.seconds += timing[0] * 1e-9
    elif ctx.engine == "path":
        timing = np.zeros(2, np.int64)
        textures, spheres = ctx.features
        args = (first, ctx.intersector.scene_pointer, ctx.scene_tables, ctx.light_tables, ctx.surface_tables,
                ctx.material_tables, config, radiance, counters, timing, film_samples, ctx.emitter_tables,
                ctx.other_kinds, textures, record, ctx.shading, spheres, ctx.nested, ctx.masks, ctx.later,
                ctx.tree_tables)
        if not ctx.compiled:  # the first call of this render: another process may be compiling the same loop
            kernels.compile_once.compile_once(kernels.path.trace_paths, args)
            ctx.compiled = True
        kernels.path.trace_paths(*args)
        clock.seconds += timing[0] * 1e-9
    else:
        _trace(ctx, _PathState(*first), 1, radiance, counters, clock, film_samples, config)
    if finish:
        counters[kernels.config.C_NONFINITE] += kernels.film.finish_samples(radiance, 0.98 if ctx.mutant == "energy-loss-2pct" else 1.0)
    for name, count in zip(COUNTERS, counters.tolist()):
        stats[name] += count
    stats[EMBREE_MICROSECONDS] += int(round(clock.seconds * 1e6))
    return radiance


def _trace(ctx: _Context, state: _PathState, depth: int, radiance: np.ndarray, counters: np.ndarray, clock: _Clock,
           film_samples: tuple, config) -> None:
    """Advance the wavefront until every path has ended. With Ni = 1 it never grows: it lives in the thread's
    workspace, the next wavefront written into the other half of it. With Ni > 1 it grows; each next wavefront is
    new memory, and a wavefront is split at camera-sample boundaries, so each sample's contributions are still
    summed in the same order."""
    if ctx.settings.indirect_rays == 1:
        ws = ctx.workspace()
        current = 0  # state is in wavefront buffer 0 (the camera rays)
        while len(state):
            state = _bounce(ctx, state, depth, radiance, counters, clock, ws.state(1 - current, len(state)), film_samples,
                            config)
            current = 1 - current
            depth += 1
        return
    while len(state):
        if len(state) > ctx.split_cap:
            mid = np.searchsorted(state.root, state.root[len(state) // 2])
            if mid == 0:
                mid = np.searchsorted(state.root, state.root[0], side="right")
            if mid < len(state):
                _trace(ctx, state.take(slice(0, mid)), depth, radiance, counters, clock, film_samples, config)
                _trace(ctx, state.take(slice(mid, None)), depth, radiance, counters, clock, film_samples, config)
                return
        state = _bounce(ctx, state, depth, radiance, counters, clock, _alloc_state(len(state) * ctx.settings.indirect_rays),
                        film_samples, config)
        depth += 1


def _bounce(ctx: _Context, state: _PathState, depth: int, radiance: np.ndarray, counters: np.ndarray, clock: _Clock,
            out: tuple, film_samples: tuple, config) -> _PathState:
    """Find the hits x of the current rays (vertex number ``depth``), add their contributions and return the rays
    of the next wavefront (written into ``out``, room for Ni rows per current row)."""
    kernels = _kernels()
    intersector = ctx.intersector
    t0 = time.perf_counter()
    if depth == 1:  # camera rays, one pixel's samples together: packet queries
        prim = intersector.closest_prims_coherent(state.origin32, state.direction32)
    else:
        prim = intersector.closest_prims(state.origin32, state.direction32)
    clock.seconds += time.perf_counter() - t0
    ws = ctx.workspace()
    hits, total, rays = ws.direct(len(state))
    crays = ws.complement_rays()
    m, s, n_next, c = kernels.wavefront.bounce(
        state.arrays(), prim, ctx.scene_tables, ctx.light_tables, ctx.surface_tables, ctx.material_tables,
        config._replace(depth=depth),
        radiance, counters, hits, rays, out, film_samples, ctx.emitter_tables, crays,
    )
    if m:
        nd = ctx.settings.shadow_rays
        hits = hits[:m]
        owner, o32, d32, tfar, value, aux, direction = rays
        if ctx.hemisphere_direct:
            t0 = time.perf_counter()
            s_prim = intersector.closest_prims(o32[:s], d32[:s])
            clock.seconds += time.perf_counter() - t0
            kernels.wavefront.resolve_hemisphere(state.root, state.beta, hits, nd, owner[:s], value[:s], aux[:s],
                                                 o32[:s], direction[:s], s_prim, ctx.scene_tables, total, radiance,
                                                 config, ctx.emitter_tables)
        else:
            t0 = time.perf_counter()
            s_hit = intersector.occluders(o32[:s], d32[:s], tfar[:s])
            clock.seconds += time.perf_counter() - t0
            kernels.wavefront.resolve_shadow(state.root, state.beta, hits, nd, owner[:s], value[:s], s_hit, total, radiance)
        if c:  # after the strategy's own estimate, as the path loop adds them
            c_owner, c_o32, c_d32, c_tfar, c_value = crays
            t0 = time.perf_counter()
            c_hit = intersector.occluders(c_o32[:c], c_d32[:c], c_tfar[:c])
            clock.seconds += time.perf_counter() - t0
            kernels.wavefront.resolve_complement(state.root, state.beta, hits, c_owner[:c], c_value[:c], c_hit, total,
                                                 radiance)
    return _PathState(*_view(out, n_next))


__all__ = ["COUNTERS", "EMBREE_MICROSECONDS", "INV_PI", "RenderOutput", "render"]
