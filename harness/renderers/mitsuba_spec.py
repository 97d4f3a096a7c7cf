"""The scene as Mitsuba 3 plugins: one nested dict in ``mi.load_dict``'s form, built from the loaded scene.

The Mitsuba adapter hands it to ``mi.load_dict`` (:func:`harness.renderers.mitsuba.load_dict_form`) and the export
writes it as XML (:func:`harness.renderers.mitsuba_xml.spec_xml`), so both describe the same scene. A plugin is a
dict with a ``type``; its properties are bools, ints, floats, strings, ``{"type": "rgb", "value": [r, g, b]}``
colours, ``{"type": "ref", "id": key}`` references to a top-level plugin, nested plugins, and these neutral values,
which each form writes its own way:

* a 4x4 float64 ``numpy`` array: a transform (``to_world``);
* :class:`LookAt`: the camera's look-at transform;
* :class:`Point`, :class:`Vector`: a position and a direction;
* :class:`Parameter`: a value the XML leaves to its reader (``$spp``), with its default;
* :class:`MeshFile`, :class:`ImageFile`: a mesh's triangles and an environment map's pixels, with the file each
  becomes in an export.

These values live in :mod:`harness.scene.kinds.mitsuba_values` (the scene's registries write their plugins with
them) and are importable from here. A material's and an emitter's plugin are their type's entry's
(:data:`harness.scene.kinds.materials.MATERIALS`, :data:`harness.scene.kinds.emitters.EMITTERS`).

Keys: ``bsdf_<j>`` for material j (file order), ``shape_<i>`` for shape i, ``emitter_<k>`` for ``[[emitters]]``
entry k, ``medium_<m>`` for ``[media]`` entry m (file order; before the sensor and the shapes, which name it by
reference: a shape's ``interior`` / ``exterior``, the sensor's ``medium``) (docs/mitsuba.md, "Scene conversion").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from harness.renderers.meshfiles import MESH_DIR, TEXTURE_DIR, safe_name
from harness.scene import Scene
from harness.scene.kinds.cameras import camera_kind
from harness.scene.kinds.emitters import EMITTERS
from harness.scene.kinds.media import MEDIA
from harness.scene.kinds.composites import ALL_MATERIALS
from harness.scene.kinds.shapes import SHAPES
from harness.scene.kinds.textures import TEXTURES
from harness.scene.kinds.mitsuba_values import (  # noqa: F401 (the spec's values, importable from here)
    ImageFile,
    LookAt,
    MeshFile,
    Parameter,
    Point,
    UVTransform,
    Vector,
    rgb,
    xyz,
)
from harness.scene.triangulate import object_to_world, shape_triangles, vertex_normals, vertex_uv

RR_DEPTH = 5  # Mitsuba's default (the reference's is 1: roulette changes the noise, not the expectation)
NEAR_FRACTION = 1e-3  # near_clip = this fraction of the distance from the camera to the nearest surface
FAR_MARGIN = 1.1  # far_clip = this factor times the distance to the farthest corner of the scene's bounding box


@dataclass(frozen=True)
class MitsubaSpec:
    """The scene as Mitsuba plugins.

    Attributes
    ----------
    plugins : dict
        ``{"type": "scene", key: plugin, ...}``, in ``mi.load_dict``'s form with the neutral values above.
    comments : dict
        What each top-level key stands for in the scene file (``"shape 3: floor"``), for a reader of the XML.
    """

    plugins: dict
    comments: dict = field(default_factory=dict)


def scene_spec(scene: Scene, *, max_depth: int | None = None, spp: int | Parameter = 4,
               seed: Parameter | None = None, sampler: str = "independent") -> MitsubaSpec:
    """The scene as Mitsuba plugins: ``path`` integrator (``volpath`` for a scene with media or a ``null``
    material: :attr:`Scene.has_media`), one medium per ``[media]`` entry, the camera's sensor, one BSDF per material,
    one shape per shape, one emitter per ``[[emitters]]`` entry.

    Rectangles, cubes and spheres keep their plugin and placement matrix (the reference traces the same analytic
    sphere); meshes are the loaded triangles.

    Parameters
    ----------
    scene : Scene
        The loaded scene.
    max_depth : int, optional
        The integrator's ``max_depth``; the scene's where None.
    spp : int or Parameter
        The sampler's ``sample_count``.
    seed : Parameter, optional
        The sampler's ``seed``; left to Mitsuba where None (a render passes its own).
    sampler : str
        Mitsuba's sampler plugin.

    Returns
    -------
    MitsubaSpec
        The plugins and a comment per material, shape and emitter.
    """
    depth = scene.max_depth if max_depth is None else max_depth
    plugins: dict = {"type": "scene",
                     "integrator": volpath_integrator(depth) if scene.has_media else path_integrator(depth)}
    comments: dict = {}
    medium_key = {name: f"medium_{m}" for m, name in enumerate(scene.media)}
    for name, medium in scene.media.items():
        plugins[medium_key[name]] = MEDIA[medium.type].to_mitsuba(medium)
        comments[medium_key[name]] = f"medium {name}"
    plugins["sensor"] = sensor_plugin(scene, spp, seed, sampler)
    if scene.camera_medium is not None:
        plugins["sensor"]["medium"] = {"type": "ref", "id": medium_key[scene.camera_medium]}
    material_key = {}
    for j, (name, material) in enumerate(scene.materials.items()):
        material_key[name] = f"bsdf_{j}"
        plugins[f"bsdf_{j}"], comments[f"bsdf_{j}"] = bsdf_dict(material), f"material {name}"
    for shape in scene.shapes:
        key = f"shape_{shape.index}"
        kind = SHAPES[shape.type]
        as_mesh = not kind.analytic
        material = scene.materials[shape.material]
        uv = vertex_uv(shape) if as_mesh and material.needs_coordinates else None
        plugins[key] = shape_plugin(shape, material_key[shape.material], as_mesh, uv)
        for side in ("interior", "exterior"):  # Mitsuba's medium transition, by reference
            if getattr(shape, side) is not None:
                plugins[key][side] = {"type": "ref", "id": medium_key[getattr(shape, side)]}
        comments[key] = f"shape {shape.index}: {shape.name}"
    for emitter in scene.emitters:
        plugins[f"emitter_{emitter.index}"] = light_spec(emitter)
        comments[f"emitter_{emitter.index}"] = f"emitter {emitter.index}: {emitter.name}"
    return MitsubaSpec(plugins, comments)


def sensor_plugin(scene: Scene, spp: int | Parameter, seed: Parameter | None, sampler: str) -> dict:
    """The camera's sensor (its entry of :data:`harness.scene.kinds.cameras.CAMERAS`: its plugin, parameters and
    look-at) with the scene's clip planes (:func:`clip_planes`), its sampler and film (:func:`film_dict`)."""
    near, far = clip_planes(scene)
    samples = {"type": sampler, "sample_count": spp if isinstance(spp, Parameter) else int(spp)}
    if seed is not None:
        samples["seed"] = seed
    return {**camera_kind(scene.camera).to_mitsuba(scene.camera, near, far), "sampler": samples,
            "film": film_dict(scene)}


def shape_plugin(shape, bsdf_key: str, as_mesh: bool, uv=None) -> dict:
    """One shape: its plugin and placement matrix, or (``as_mesh``) its triangles as a ``ply`` with its vertex
    normals where it is smooth-shaded (else ``face_normals``) and ``uv``, its vertices' texture coordinates, where
    its material is textured; its BSDF by reference, an emitting shape's ``area`` emitter."""
    if as_mesh:
        vertices, triangles = shape_triangles(shape)  # world space; flip_normals is in the winding
        # the reference's vertex normals, written out (Mitsuba's own; a light's are its pieces' normals: flat)
        normals = None if shape.is_emitter else vertex_normals(shape, vertices, triangles)
        mesh = MeshFile(shape.name, f"{MESH_DIR}/{shape.index}-{safe_name(shape.name)}.ply", vertices, triangles,
                        uv, normals)
        plugin = {"type": "ply", "filename": mesh, "face_normals": normals is None}
    else:
        plugin = {"type": shape.type, "to_world": np.asarray(object_to_world(shape), dtype=np.float64)}
        if shape.flip_normals:
            plugin["flip_normals"] = True
    plugin["bsdf"] = {"type": "ref", "id": bsdf_key}
    if shape.is_emitter:
        plugin["emitter"] = emitter_dict(shape)
    return plugin


def _point_triangle_distances(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance from point ``p`` to each triangle (a[i], b[i], c[i])."""

    def segment(u, v):
        d = v - u
        dd = np.einsum("ij,ij->i", d, d)
        t = np.clip(np.einsum("ij,ij->i", p - u, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        return np.linalg.norm(p - (u + t[:, None] * d), axis=1)

    ab, ac, ap = b - a, c - a, p - a
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((ab, ab), (ab, ac), (ac, ac)))
    d20, d21 = np.einsum("ij,ij->i", ap, ab), np.einsum("ij,ij->i", ap, ac)
    denom = d00 * d11 - d01 * d01
    ok = denom > 0
    safe = np.where(ok, denom, 1.0)
    s = (d11 * d20 - d01 * d21) / safe
    t = (d00 * d21 - d01 * d20) / safe
    inside = ok & (s >= 0) & (t >= 0) & (s + t <= 1)
    normal = np.cross(ab, ac)
    plane = np.abs(np.einsum("ij,ij->i", ap, normal)) / np.sqrt(np.where(ok, denom, 1.0))
    edges = np.minimum(np.minimum(segment(a, b), segment(b, c)), segment(c, a))
    return np.where(inside, plane, edges)


def clip_planes(scene: Scene) -> tuple[float, float]:
    """``near_clip``, ``far_clip`` for the scene's camera.

    near = :data:`NEAR_FRACTION` of the distance from the eye to the nearest surface (spheres exactly, other shapes
    by their triangles), far = :data:`FAR_MARGIN` times the distance to the farthest corner of the scene's bounding
    box. Mitsuba's defaults (0.01, 10000) would clip away a scene scaled down or up far enough.
    """
    eye = np.asarray(scene.camera.origin, dtype=np.float64)
    nearest, corners = math.inf, []
    with np.errstate(all="ignore"):
        for shape in scene.shapes:
            sphere = SHAPES[shape.type].sphere
            if sphere is not None:
                centre, radius = sphere(shape)
                nearest = min(nearest, abs(float(np.linalg.norm(eye - centre)) - radius))
                corners += [centre - radius, centre + radius]
                continue
            vertices, triangles = shape_triangles(shape)
            corners += [vertices.min(axis=0), vertices.max(axis=0)]
            t = vertices[triangles]
            distances = _point_triangle_distances(eye[None, :], t[:, 0], t[:, 1], t[:, 2])
            if distances.size:
                nearest = min(nearest, float(np.nanmin(distances)))
    if not corners:
        return 1e-3, 1e4  # nothing to see: anything valid will do
    lo, hi = np.min(corners, axis=0), np.max(corners, axis=0)
    box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    farthest = float(np.max(np.linalg.norm(box - eye, axis=1)))
    far = FAR_MARGIN * farthest + 1e-6 * max(farthest, 1e-30)
    if not (math.isfinite(nearest) and nearest > 0):
        nearest = 1e-3 * farthest  # the eye lies on a surface: a tiny near plane anyway
    near = max(NEAR_FRACTION * nearest, 1e-7 * farthest)
    if not (math.isfinite(near) and near > 0):
        near = 1e-6
    far = max(far, 2.0 * near)
    return float(near), float(far)


def bsdf_dict(material) -> dict:
    """Mitsuba's dict of ``material``: its plugin (``diffuse``, ``conductor``, ``roughconductor``, ``dielectric``,
    ``roughdielectric``, ``thindielectric``, ``plastic``, ``roughplastic``,
    ``principled``, ``blendbsdf``, ``mask``) with every parameter written out (so Mitsuba's defaults
    never decide), inside ``twosided`` when two-sided. A conductor with eta = 0, k = 1 is written as Mitsuba's ``material = "none"``."""
    return ALL_MATERIALS[material.type].to_mitsuba(material)


def emitter_dict(shape) -> dict:
    """Mitsuba's ``area`` emitter dict of an emitting shape (its RGB radiance, or its texture's plugin)."""
    if shape.emission_texture is not None:
        texture = shape.emission_texture
        return {"type": "area", "radiance": TEXTURES[texture.type].to_mitsuba(texture)}
    return {"type": "area", "radiance": rgb(shape.emission)}


def texture_path(emitter) -> str | None:
    """The file an ``[[emitters]]`` entry's image becomes in an export (``textures/<index>-<name>.exr``), or None
    for a type without one."""
    if not EMITTERS[emitter.type].textured:
        return None
    return f"{TEXTURE_DIR}/{emitter.index}-{safe_name(emitter.name)}.exr"


def light_spec(emitter) -> dict:
    """Mitsuba's plugin of an ``[[emitters]]`` entry (docs/mitsuba.md, "Emitters"): its parameters written out,
    colours as ``rgb``, an envmap's pixels as an :class:`ImageFile`."""
    return EMITTERS[emitter.type].to_mitsuba(emitter, texture_path(emitter))


def film_dict(scene: Scene) -> dict:
    """Mitsuba's ``hdrfilm``: the scene's size and filter (always explicit: Mitsuba's default is the Gaussian).

    ``sample_border`` is on for tent and Gaussian filters, so that border pixels also receive samples from outside
    the image, as the reference's (filter-importance-sampled) border pixels do.
    """
    rfilter = {"box": {"type": "box"}, "tent": {"type": "tent", "radius": 1.0},
               "gaussian": {"type": "gaussian", "stddev": 0.5}}[scene.film.filter]
    return {
        "type": "hdrfilm",
        "width": int(scene.film.width),
        "height": int(scene.film.height),
        "rfilter": rfilter,
        "pixel_format": "rgb",
        "component_format": "float32",
        "sample_border": scene.film.filter != "box",
    }


def volpath_integrator(max_depth: int) -> dict:
    """Mitsuba's ``volpath`` integrator (a scene with media or a ``null`` material) with the ``max_depth`` and
    ``rr_depth`` the ``path`` integrator gets (:func:`path_integrator`)."""
    return {**path_integrator(max_depth), "type": "volpath"}


def path_integrator(max_depth: int) -> dict:
    """Mitsuba's ``path`` integrator with ``max_depth`` and ``rr_depth`` :data:`RR_DEPTH`."""
    return {"type": "path", "max_depth": int(max_depth), "rr_depth": RR_DEPTH}
