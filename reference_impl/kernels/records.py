"""The named records the kernels take: the scene, its lights, its surfaces, its other emitters and its materials as
tables of arrays, the camera, the pixel filter's draws and the camera samples of a batch, each a ``NamedTuple``
built here and only here (one function each, from the core's objects), read in the kernels by field name.

numba compiles a field read ``record.name`` as it compiles ``record[i]``: a record costs a kernel nothing. The
arrays are contiguous and of the dtypes the kernels are compiled for, so every scene runs the same compiled
signatures. Tables per triangle have T rows, per material M, per light N_L (the area lights first, then the
emitters that are not surfaces), per light piece P (:class:`reference_impl.lights.LightSampler`), per emitter E.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from reference_impl import textures as tx
from reference_impl.camera import OrthographicCamera, ThinLensCamera
from reference_impl.errors import SettingsError
from reference_impl.materials import LUT_SIZE, NUM_SLOTS, ROUGHPLASTIC

_c = np.ascontiguousarray


class SceneTables(NamedTuple):
    """The triangles and their materials as the engines read them.

    Attributes
    ----------
    prim_to_tri : (primitives,) int64
        The triangle of each Embree primitive (``Intersector.prim_to_tri``).
    normal : (T, 3) float64
        The unit geometric normal N of the front side, N = (c1 - c0) x (c2 - c0) / |(c1 - c0) x (c2 - c0)|.
    corner0 : (T, 3) float64
        The first corner c0: the point of the triangle's plane a hit distance is computed from.
    corners : (T, 3, 3) float64
        The corners c0, c1, c2.
    emission : (T, 3) float64
        Le of the front side (0 off the lights).
    light_id : (T,) int64
        The light k the triangle belongs to, -1 off the lights.
    material : (T,) int64
        The triangle's material, a row of :class:`MaterialTables` (what it is at a hit: the material step,
        :mod:`.material`).
    uv : (T, 3, 2) or (0, 3, 2) float64
        The texture coordinates at the corners (``Geometry.uv``); empty where no material is textured (no hit
        computes them).
    sphere_of : (T,) or (0,) int64
        ``Geometry.sphere_of``: the analytic sphere a triangle stands in for, -1 for none; empty in a scene without
        spheres (no hit asks).
    sphere : (S, 5) float64
        Per sphere: its centre c, radius r and side, +1 where the front side is outside, -1 where inside
        (``Geometry.sphere_inward``): the front normal at x is side (x - c) / r.
    sphere_to_object : (S, 4, 4) float64
        ``Geometry.sphere_to_object`` (its texture coordinates).
    emission_texture : (T,) or (0,) int64
        ``Geometry.emission_texture``, empty where no light is textured (a hit reads ``emission`` alone).
    normals : (T, 3, 3) or (0, 3, 3) float64
        ``Geometry.normals``, the unit vertex normals at the corners; empty where no triangle has them (every hit's
        shading normal is its geometric one).
    smooth : (T,) or (0,) bool
        ``Geometry.smooth``: whether the triangle has vertex normals; empty with ``normals``.
    """

    prim_to_tri: np.ndarray
    normal: np.ndarray
    corner0: np.ndarray
    corners: np.ndarray
    emission: np.ndarray
    light_id: np.ndarray
    material: np.ndarray
    uv: np.ndarray
    sphere_of: np.ndarray
    sphere: np.ndarray
    sphere_to_object: np.ndarray
    emission_texture: np.ndarray
    normals: np.ndarray
    smooth: np.ndarray


def scene_tables(geometry, prim_to_tri: np.ndarray, textured: bool = False) -> SceneTables:
    """The :class:`SceneTables` of ``geometry`` (:class:`reference_impl.Geometry`) for Embree's primitives
    ``prim_to_tri``; the texture coordinates only where ``textured`` (a material has a texture) or a light is."""
    g = geometry
    uv = np.zeros((0, 3, 2))
    emission_texture = g.emission_texture if g.textured_lights else np.zeros(0, np.int64)
    if textured or g.textured_lights:
        uv = g.uv if len(g.uv) else np.zeros((len(g.triangles), 3, 2))
    sphere = np.column_stack([g.sphere_center, g.sphere_radius, np.where(g.sphere_inward, -1.0, 1.0)])
    smooth = g.has_shading_normals
    return SceneTables(
        prim_to_tri=_c(prim_to_tri, dtype=np.int64), normal=_c(g.normal), corner0=_c(g.corners[:, 0]),
        corners=_c(g.corners), emission=_c(g.emission), light_id=_c(g.light_id), material=_c(g.material),
        uv=_c(uv, dtype=np.float64), sphere_of=_c(g.sphere_of, dtype=np.int64),
        sphere=_c(sphere.reshape(-1, 5), dtype=np.float64), sphere_to_object=_c(g.sphere_to_object, dtype=np.float64),
        emission_texture=_c(emission_texture, dtype=np.int64),
        normals=_c(g.normals if smooth else np.zeros((0, 3, 3)), dtype=np.float64),
        smooth=_c(g.smooth if smooth else np.zeros(0, bool), dtype=np.bool_))


class LightTables(NamedTuple):
    """The lights of pdf(k) and their pieces (:class:`reference_impl.lights.LightSampler`, whose attributes these
    are).

    Attributes
    ----------
    cdf : (N_L,) float64
        The cdf of pdf(k) over the lights.
    triangles : (P,) int64
        Per piece: its triangle (of a parallelogram, the half a + b <= 1).
    first : (N_A,) int64
        Per area light: its first piece.
    count : (N_A,) int64
        Per area light: how many pieces it has.
    within_cdf : (P,) float64
        Per piece: the cdf of A_piece / A_k within its light.
    pmf : (N_L,) float64
        pdf(k).
    area : (N_A,) float64
        A_k.
    frames : (P, 3, 3) float64
        Per piece: its frame (o, e1, e2), y = o + a e1 + b e2.
    parallelogram : (P,) bool
        Per piece: (a, b) = (u1, u2) on a parallelogram, a triangle's barycentrics otherwise.
    other : (P,) int64
        Per piece: the triangle where a + b > 1 (a triangle's own otherwise).
    sphere : (P,) bool
        Per piece: a whole sphere, frame (c, (r, 0, 0), 0), its first triangle in ``triangles`` and ``other``.
    cone : (N_A, 4) float64
        Per area light: the centre and radius of a sphere drawn by its cone from outside (emission outward), else 0.
    """

    cdf: np.ndarray
    triangles: np.ndarray
    first: np.ndarray
    count: np.ndarray
    within_cdf: np.ndarray
    pmf: np.ndarray
    area: np.ndarray
    frames: np.ndarray
    parallelogram: np.ndarray
    other: np.ndarray
    sphere: np.ndarray
    cone: np.ndarray


def light_tables(sampler) -> LightTables:
    """The :class:`LightTables` of a :class:`reference_impl.lights.LightSampler`, or empty ones for None (a scene
    without lights)."""
    if sampler is None:
        f, i = np.zeros(0), np.zeros(0, np.int64)
        return LightTables(f, i, i, i, f, f, f, np.zeros((0, 3, 3)), np.zeros(0, np.bool_), i, np.zeros(0, np.bool_),
                           np.zeros((0, 4)))
    s = sampler
    return LightTables(
        cdf=_c(s.cdf, dtype=np.float64), triangles=_c(s.triangles, dtype=np.int64), first=_c(s.first, dtype=np.int64),
        count=_c(s.count, dtype=np.int64), within_cdf=_c(s.within_cdf, dtype=np.float64),
        pmf=_c(s.pmf, dtype=np.float64), area=_c(s.area, dtype=np.float64), frames=_c(s.frames, dtype=np.float64),
        parallelogram=_c(s.parallelogram, dtype=np.bool_), other=_c(s.other, dtype=np.int64),
        sphere=_c(s.sphere, dtype=np.bool_), cone=_c(s.cone, dtype=np.float64))


class TreeTables(NamedTuple):
    """The light tree of ``light_selection = "tree"``: the attributes of
    :class:`reference_impl.light_tree.LightTree` (``lo``, ``hi``, ``phi``, ``w``, ``cos_o``, ``child``, ``leaf``,
    ``trail``; M nodes over the N_A area lights), and what the importance reads of each node ready made.

    Attributes
    ----------
    sin_o : (M,) float64
        Its cone's sin theta_o.
    centre : (M, 3) float64
        Its box's centre (lo + hi) / 2.
    r2 : (M,) float64
        The squared radius of the box's bounding sphere, |hi - lo|^2 / 4.
    p_tree : (1,) float64
        The probability of choosing the tree rather than an emitter that is not a surface.
    """

    lo: np.ndarray
    hi: np.ndarray
    phi: np.ndarray
    w: np.ndarray
    cos_o: np.ndarray
    sin_o: np.ndarray
    centre: np.ndarray
    r2: np.ndarray
    child: np.ndarray
    leaf: np.ndarray
    trail: np.ndarray
    p_tree: np.ndarray


def tree_tables(sampler) -> "TreeTables | None":
    """The :class:`TreeTables` of a :class:`reference_impl.lights.LightSampler` whose selection is "tree", else None
    (which compiles the tree out of the path loop)."""
    tree = getattr(sampler, "tree", None)
    if tree is None:
        return None
    half = 0.5 * (tree.hi - tree.lo)
    return TreeTables(lo=_c(tree.lo, dtype=np.float64), hi=_c(tree.hi, dtype=np.float64),
                      phi=_c(tree.phi, dtype=np.float64), w=_c(tree.w, dtype=np.float64),
                      cos_o=_c(tree.cos_o, dtype=np.float64),
                      sin_o=_c(np.sqrt(np.maximum(0.0, 1.0 - tree.cos_o * tree.cos_o)), dtype=np.float64),
                      centre=_c(0.5 * (tree.lo + tree.hi), dtype=np.float64),
                      r2=_c((half * half).sum(axis=1), dtype=np.float64), child=_c(tree.child, dtype=np.int64),
                      leaf=_c(tree.leaf, dtype=np.bool_), trail=_c(tree.trail, dtype=np.uint64),
                      p_tree=np.array([tree.p_tree], np.float64))


class SurfaceTables(NamedTuple):
    """Every surface, for global area sampling (:class:`reference_impl.lights.TriangleAreaSampler`).

    Attributes
    ----------
    triangles : (N,) int64
        The triangles of positive area, and each sphere's first triangle in place of its own.
    cdf : (N,) float64
        The cdf of A_t / A_scene over them (a sphere's A_t = 4 pi r^2).
    sphere : (N, 4) or (0, 4) float64
        Per entry: a sphere's centre and radius, or 0 for a triangle; empty in a scene without spheres.
    """

    triangles: np.ndarray
    cdf: np.ndarray
    sphere: np.ndarray


def surface_tables(sampler) -> SurfaceTables:
    """The :class:`SurfaceTables` of a :class:`reference_impl.lights.TriangleAreaSampler`, or empty ones for None
    (a scene without area)."""
    if sampler is None:
        return SurfaceTables(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 4)))
    spheres = sampler.sphere if np.any(sampler.sphere[:, 3] > 0) else np.zeros((0, 4))
    return SurfaceTables(_c(sampler.triangles, dtype=np.int64), _c(sampler.cdf, dtype=np.float64),
                         _c(spheres, dtype=np.float64))


class EmitterTables(NamedTuple):
    """The emitters that are not surfaces (:class:`reference_impl.emitters.Emitters`, whose attributes these are).

    Attributes
    ----------
    kind : (E,) int64
        POINT, SPOT, DIRECTIONAL, ENV_CONSTANT, ENV_MAP.
    position : (E, 3) float64
        Point, spot: where it is.
    direction : (E, 3) float64
        Directional: the unit direction the light travels.
    intensity : (E, 3) float64
        I (point, spot), E (directional), L (constant), the scale (envmap).
    to_local, to_world : (E, 3, 3) float64
        Spot, envmap: the linear part of to_world^-1 and of to_world.
    spot : (E, 4) float64
        Spot: cos(cutoff), cutoff, cos(beam_width), 1 / (cutoff - beam_width).
    env_image : (H, W, 3) float64
        The envmap's texels.
    env_cell_pdf : (H - 1, W) float64
        p(u, v) of each cell of the bilinear interpolation.
    env_row_cdf : (H - 1,) float64
        The marginal cdf of the cell rows.
    env_col_cdf : (H - 1, W) float64
        Each row's conditional cdf of its cells.
    """

    kind: np.ndarray
    position: np.ndarray
    direction: np.ndarray
    intensity: np.ndarray
    to_local: np.ndarray
    to_world: np.ndarray
    spot: np.ndarray
    env_image: np.ndarray
    env_cell_pdf: np.ndarray
    env_row_cdf: np.ndarray
    env_col_cdf: np.ndarray


def emitter_tables(emitters) -> EmitterTables:
    """The :class:`EmitterTables` of a :class:`reference_impl.emitters.Emitters`."""
    e = emitters
    return EmitterTables(
        kind=_c(e.kind, dtype=np.int64), position=_c(e.position), direction=_c(e.direction),
        intensity=_c(e.intensity), to_local=_c(e.to_local), to_world=_c(e.to_world), spot=_c(e.spot),
        env_image=_c(e.env_image, dtype=np.float64), env_cell_pdf=_c(e.env_cell_pdf), env_row_cdf=_c(e.env_row_cdf),
        env_col_cdf=_c(e.env_col_cdf))


class MaterialTables(NamedTuple):
    """The materials, as every engine's material step reads them (:class:`reference_impl.Materials`, whose attributes
    these are).

    Attributes
    ----------
    kind : (M,) int64
        DIFFUSE .. ROUGHPLASTIC (:mod:`reference_impl.materials`).
    params : (M, NUM_PARAMS) float64
        One row per material, its columns the ``P_*`` of :mod:`reference_impl.materials`.
    texture : (M, NUM_SLOTS) or (0, NUM_SLOTS) int64
        ``Materials.texture``: per material and texture slot, the texture driving it or -1; empty where no material
        is textured (the material step then copies rows only).
    textures : TextureTables
        The textures.
    lut : (M, LUT_SIZE) float64
        A rough plastic's table (:func:`.bsdf.roughplastic_luts`), which the material step appends to its row; zeros
        on the other kinds.
    """

    kind: np.ndarray
    params: np.ndarray
    texture: np.ndarray
    textures: "TextureTables"
    lut: np.ndarray


class TextureTables(NamedTuple):
    """The textures (:class:`reference_impl.textures.Textures`), as :mod:`.texture` reads them; K textures.

    Attributes
    ----------
    kind : (K,) int64
        BITMAP or CHECKERBOARD (:mod:`reference_impl.textures`).
    filter : (K,) int64
        NEAREST or BILINEAR.
    wrap : (K,) int64
        REPEAT, MIRROR or CLAMP.
    width, height : (K,) int64
        A bitmap's size in texels.
    offset : (K,) int64
        A bitmap's first texel in ``texels``; texel (i, j) (column i, row j from the top) is
        ``texels[offset + j * width + i]``.
    texels : (N, 3) float64
        Every bitmap's linear values, one after the other.
    to_uv : (K, 3, 3) float64
        Each texture's affine map of (u, v).
    colors : (K, 2, 3) float64
        A checkerboard's color0 and color1.
    """

    kind: np.ndarray
    filter: np.ndarray
    wrap: np.ndarray
    width: np.ndarray
    height: np.ndarray
    offset: np.ndarray
    texels: np.ndarray
    to_uv: np.ndarray
    colors: np.ndarray


def texture_tables(textures, srgb_as_linear: bool = False) -> TextureTables:
    """The :class:`TextureTables` of a :class:`reference_impl.textures.Textures` (``srgb_as_linear``: the planted
    fault "texture-srgb-as-linear", sRGB codes taken as code / 255)."""
    items = textures.items if textures is not None else ()
    count = len(items)
    kind, filt, wrap, width, height, offset = (np.zeros(count, np.int64) for _ in range(6))
    to_uv, colors, texels = np.zeros((count, 3, 3)), np.zeros((count, 2, 3)), []
    start = 0
    for k, item in enumerate(items):
        to_uv[k] = item.to_uv
        if isinstance(item, tx.Checkerboard):
            kind[k] = tx.CHECKERBOARD
            colors[k] = (item.color0, item.color1)
            continue
        image = item.linear(srgb_as_linear)
        kind[k], filt[k], wrap[k] = tx.BITMAP, tx.FILTERS[item.filter_type], tx.WRAPS[item.wrap_mode]
        height[k], width[k] = image.shape[:2]
        offset[k] = start
        texels.append(image.reshape(-1, 3))
        start += image.shape[0] * image.shape[1]
    return TextureTables(kind, filt, wrap, width, height, offset,
                         _c(np.concatenate(texels) if texels else np.zeros((0, 3)), dtype=np.float64), to_uv, colors)


def material_tables(materials, mutant: str = "", lut: np.ndarray | None = None) -> MaterialTables:
    """The :class:`MaterialTables` of a :class:`reference_impl.Materials` (``mutant``: the render's planted fault,
    "texture-srgb-as-linear" changes the texels; ``lut``: the rough plastics' tables, :func:`.bsdf.roughplastic_luts`
    of ``materials``, required where there is one: SettingsError without)."""
    if lut is None:
        if np.any(materials.kind == ROUGHPLASTIC):
            raise SettingsError("materials.lut", "a rough plastic needs its table: pass "
                                "reference_impl.kernels.bsdf.roughplastic_luts(materials)")
        lut = np.zeros((len(materials.kind), LUT_SIZE))
    if np.shape(lut) != (len(materials.kind), LUT_SIZE):
        raise SettingsError("materials.lut", f"expected an array of shape ({len(materials.kind)}, {LUT_SIZE}), "
                            f"got {np.shape(lut)}")
    texture = materials.texture if materials.textured else np.zeros((0, NUM_SLOTS), np.int64)
    texture.setflags(write=False)  # read-only as Materials.texture is: one type for the kernels either way
    return MaterialTables(_c(materials.kind, dtype=np.int64), _c(materials.params, dtype=np.float64),
                          _c(texture, dtype=np.int64),
                          texture_tables(materials.textures, mutant == "texture-srgb-as-linear"),
                          _c(lut, dtype=np.float64))


class FilmSamples(NamedTuple):
    """The camera samples of a batch: sample i is number ``sample[i]`` of pixel ``pixel[i]`` (row-major, y * W + x).

    Attributes
    ----------
    pixel : (n,) int64
    sample : (n,) int64
    seed_key : numpy.uint64
        The key every path and pixel key is derived from (:func:`reference_impl.rng.seed_key`).
    """

    pixel: np.ndarray
    sample: np.ndarray
    seed_key: np.uint64


def film_samples(pixel: np.ndarray, sample: np.ndarray, seed_key: np.uint64) -> FilmSamples:
    """The :class:`FilmSamples` of camera samples (``pixel``, ``sample``) of a pass whose seed has key
    ``seed_key``."""
    return FilmSamples(_c(pixel, dtype=np.int64), _c(sample, dtype=np.int64), np.uint64(seed_key))


class CameraRecord(NamedTuple):
    """The camera as the viewing rays need it (a camera of :mod:`reference_impl.camera` on a film of ``width`` x
    ``height``). ``model`` :data:`PERSPECTIVE`: the ray through film point (p_x, p_y) leaves ``eye`` along
    normalize(frame l), l = ((1 - 2 p_x / W) tan_x, (1 - 2 p_y / H) tan_y, 1); :data:`THINLENS`: it leaves
    eye + frame a, a = aperture_radius (disk point, 0), along normalize(frame (focus_distance l - a));
    :data:`ORTHOGRAPHIC`: it leaves eye + frame ((1 - 2 p_x / W) half_x, (1 - 2 p_y / H) half_y, 0) along frame's
    +z.

    Attributes
    ----------
    model : int
        :data:`PERSPECTIVE`, :data:`THINLENS` or :data:`ORTHOGRAPHIC`.
    eye : (3,) float64
    frame : (3, 3) float64
        Columns: camera +x (left), +y (up), +z (forward) in world space.
    tan_x, tan_y : float
        tan of half the field of view along x and y (perspective, thin lens).
    width, height : int
        The film's size in pixels.
    aperture_radius, focus_distance : float
        The thin lens's (0 otherwise).
    half_x, half_y : float
        Half the orthographic film's width and height in scene units (0 otherwise).
    """

    model: int
    eye: np.ndarray
    frame: np.ndarray
    tan_x: float
    tan_y: float
    width: int
    height: int
    aperture_radius: float
    focus_distance: float
    half_x: float
    half_y: float


PERSPECTIVE, THINLENS, ORTHOGRAPHIC = range(3)


def camera_record(camera, width: int, height: int) -> CameraRecord:
    """The :class:`CameraRecord` of ``camera`` (:class:`reference_impl.Camera`, :class:`.ThinLensCamera` or
    :class:`.OrthographicCamera`) on a film of ``width`` x ``height``."""
    eye = np.asarray(camera.origin, dtype=np.float64)
    frame = _c(camera.frame(), dtype=np.float64)
    if isinstance(camera, OrthographicCamera):
        half_x, half_y = camera.extent(width, height)
        return CameraRecord(ORTHOGRAPHIC, eye, frame, 0.0, 0.0, int(width), int(height), 0.0, 0.0, half_x, half_y)
    tan_x, tan_y = camera.tan_half_fov(width, height)
    if isinstance(camera, ThinLensCamera):
        return CameraRecord(THINLENS, eye, frame, float(tan_x), float(tan_y), int(width), int(height),
                            float(camera.aperture_radius), float(camera.focus_distance), 0.0, 0.0)
    return CameraRecord(PERSPECTIVE, eye, frame, float(tan_x), float(tan_y), int(width), int(height), 0.0, 0.0, 0.0,
                        0.0)


class FilterSamples(NamedTuple):
    """The pixel filter of a batch: its kind, and for the Gaussian the offsets and weights numpy drew
    (``PixelFilter.sample``; empty for box and tent, which the kernel draws itself).

    Attributes
    ----------
    kind : int
        FILTER_BOX, FILTER_TENT or FILTER_GAUSSIAN (:mod:`.config`).
    dx, dy : (n,) or (0,) float64
        The film offsets of the samples from their pixel centres.
    weight : (n,) or (0,) float64
        h(p) / (pdf(p) int h) of each sample.
    """

    kind: int
    dx: np.ndarray
    dy: np.ndarray
    weight: np.ndarray


def filter_samples(kind: int, drawn=None) -> FilterSamples:
    """The :class:`FilterSamples` of a filter of ``kind``, with ``drawn`` = (dx, dy, weight) for the Gaussian (None:
    the kernel draws them)."""
    if drawn is None:
        return FilterSamples(int(kind), np.zeros(0), np.zeros(0), np.zeros(0))
    dx, dy, weight = drawn
    return FilterSamples(int(kind), _c(dx, dtype=np.float64), _c(dy, dtype=np.float64), _c(weight, dtype=np.float64))


#: the entries of RayRecord.counts: queries made, and packet calls made (the blocks' groups)
COUNT_CLOSEST, COUNT_OCCLUSION, COUNT_CLOSEST_GROUPS, COUNT_OCCLUSION_GROUPS = 0, 1, 2, 3


class RayRecord(NamedTuple):
    """Room for the queries of one batch of the path loop and Embree's answers (:mod:`.record`, for
    :mod:`reference_impl.replay`): the camera rays in float32 as their packets take them; the other rays in float64,
    as the sphere tests take them (Embree's query rounds them to float32 itself), so that a replay asks the same.

    Attributes
    ----------
    camera_origin, camera_direction : (n, 3) float32
        The batch's camera rays, one row each.
    camera_prim : (n,) int32
        Their closest hits (-1: a miss).
    closest_origin, closest_direction : (q, 3) float64
        The closest-hit rays past the camera.
    closest_prim : (q,) int32
        Their hits.
    occlusion_origin, occlusion_direction : (s, 3) float64
        The occlusion rays.
    occlusion_tfar : (s,) float32
        Where each stops.
    occlusion_blocked : (s,) int8
        1 where something blocked it, 0 where not.
    closest_groups, occlusion_groups : (q,) and (s,) int64
        Where an engine sends its rays in packets (:mod:`.blocks`): the number of rays of each call that sent
        consecutive recorded rays as packets of ``packet_width`` (the first packet of a call starts at its first
        ray); nothing where it sends one ray per query (the path loop).
    counts : (4,) int64
        The closest-hit (``counts[COUNT_CLOSEST]``) and the occlusion (``counts[COUNT_OCCLUSION]``) queries made,
        also those past q and s: a count above its room says the batch must be traced again with more; the groups
        recorded (``COUNT_CLOSEST_GROUPS``, ``COUNT_OCCLUSION_GROUPS``).
    """

    camera_origin: np.ndarray
    camera_direction: np.ndarray
    camera_prim: np.ndarray
    closest_origin: np.ndarray
    closest_direction: np.ndarray
    closest_prim: np.ndarray
    occlusion_origin: np.ndarray
    occlusion_direction: np.ndarray
    occlusion_tfar: np.ndarray
    occlusion_blocked: np.ndarray
    closest_groups: np.ndarray
    occlusion_groups: np.ndarray
    counts: np.ndarray


def ray_record(cameras: int, closest: int, occlusion: int) -> RayRecord:
    """An empty :class:`RayRecord` with room for ``cameras`` camera rays, ``closest`` closest-hit and ``occlusion``
    occlusion queries."""
    f32, f64 = np.float32, np.float64
    return RayRecord(np.empty((cameras, 3), f32), np.empty((cameras, 3), f32), np.empty(cameras, np.int32),
                     np.empty((closest, 3), f64), np.empty((closest, 3), f64), np.empty(closest, np.int32),
                     np.empty((occlusion, 3), f64), np.empty((occlusion, 3), f64), np.empty(occlusion, f32),
                     np.empty(occlusion, np.int8), np.empty(closest, np.int64), np.empty(occlusion, np.int64),
                     np.zeros(4, np.int64))


class MediumTables(NamedTuple):
    """The participating media and the triangles' medium transitions as the volumetric path loop reads them
    (:mod:`.volpath`): the attributes of :class:`reference_impl.media.Media` of the same names, contiguous."""

    sigma_t: np.ndarray
    albedo: np.ndarray
    phase: np.ndarray
    g: np.ndarray
    interior: np.ndarray
    exterior: np.ndarray
    transition: np.ndarray
    camera: int


def medium_tables(media, num_triangles: int) -> MediumTables:
    """The :class:`MediumTables` of a :class:`reference_impl.media.Media`, or of none (``media`` None: a scene whose
    only medium word is a ``null`` material) over ``num_triangles`` triangles."""
    if media is None:
        none = np.full(num_triangles, -1, np.int64)
        return MediumTables(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0), none, none.copy(),
                            np.zeros(num_triangles, np.bool_), -1)
    return MediumTables(_c(media.sigma_t), _c(media.albedo), _c(media.phase, dtype=np.int64), _c(media.g),
                        _c(media.interior, dtype=np.int64), _c(media.exterior, dtype=np.int64),
                        _c(media.transition, dtype=np.bool_), int(media.camera))
