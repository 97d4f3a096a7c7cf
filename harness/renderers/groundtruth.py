"""Ground truth: a closed form where the scene has one, else Mitsuba 3, through a content-addressed cache.

Cache layout (``<cache>/groundtruth/<key>/``): ``estimate.npz`` (mean, variance of the mean, spp), ``image.exr``
(the same as an OpenEXR file for viewers) and ``meta.json`` (what was rendered, how, and the SHA-256 of both data
files and of meta.json's own content with the entry's key, so that an edited ``spp`` or ``chunks``, or an entry
copied under another key, is damage like any other). The key is a SHA-256 over everything that determines the
image: the scene's content key (:func:`scene_digest`: every field of the loaded scene and the bytes of every file
the loader read), the film (size, filter), max_depth, Mitsuba's version, the variant, spp, seed and chunking.

Long renders are split into chunks of ``chunk_spp`` samples, each its own cache entry, merged exactly
(``harness.judges.moments``): an interrupted ground truth resumes where it stopped.

Entries are written into a private temporary folder and renamed into place (atomic); when two processes fill the
same entry, the first rename wins and the second process uses the winner's files. Every read verifies the
checksums; a partial or corrupted entry is removed and rendered again, never used.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

import numpy as np

from reference_impl.camera import OrthographicCamera, ThinLensCamera
from reference_impl.textures import Textures

from harness.core.errors import HarnessError
from harness.files.entries import default_cache_dir, private_name
from harness.files.imageio import WriteError, make_folders, remove_folders, write_exr
from harness.judges.floor import spp_for_share
from harness.judges.moments import Estimate, merge
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.mitsuba import choose_variant
from harness.scene import Scene
from harness.scene.model import DirectionalLight, PointLight, SpotLight
from harness.scene.content_key import content_key
from harness.scene.primitives import sphere_uv
from harness.scene.triangulate import object_to_world, shape_triangles, vertex_normals

FORMAT_VERSION = 6  # of the key: a new format makes every entry a miss once (the cache is content-addressed)
DEFAULT_SPP = 1024
DEFAULT_CHUNK_SPP = 256
DATA_FILES = ("estimate.npz", "image.exr")  # the files of an entry that meta.json's checksums cover
META_CHECKSUM = "meta.json"  # the checksum of meta.json's content (but the checksums) and the entry's key


@dataclass
class GroundTruth:
    """A ground truth: the image a render is judged against, with the variance of each pixel's estimate (zeros for
    a closed form)."""

    image: np.ndarray
    variance: np.ndarray
    source: str  # "closed-form" | "mitsuba"
    spp: int
    info: dict = field(default_factory=dict)
    cached: bool = False  # every chunk came from the cache
    renders: int = 0  # Mitsuba renders performed to produce it (0 when cached or closed form)
    seconds: float = 0.0  # render time spent now
    path: Path | None = None  # the cache entry's EXR


def mitsuba_caveat(scene: Scene) -> str | None:
    """Why Mitsuba's image of ``scene`` is not its expected image, where a known difference says so (docs/mitsuba.md,
    "Known differences"), else None: a cut-out (``mask``) with a point, spot or directional light, whose light
    Mitsuba's path loses through the holes (its shadow rays stop at a mask; only they reach a delta light)."""
    delta = sorted({DELTA_LIGHTS[type(e)] for e in scene.emitters if type(e) in DELTA_LIGHTS})
    masks = sorted(name for name, m in scene.materials.items() if m.type == "mask")
    if not (delta and masks):
        return None
    return (f"Mitsuba's path loses the light of {', '.join(delta)} through the holes of "
            f"{', '.join(masks)} (mask): its image is darker than the expected one there, and a fail may be "
            "Mitsuba's (docs/mitsuba.md, \"Known differences\")")


#: the emitters only a light sample reaches, by their model class: what a caveat calls them
DELTA_LIGHTS = {DirectionalLight: "a directional light", PointLight: "a point light", SpotLight: "a spot light"}


# ---- closed forms ----------------------------------------------------------------------------------------------


def closed_form(scene: Scene) -> GroundTruth:
    """The analytic image of a scene that declares ``closed_form`` (one of :data:`CLOSED_FORMS`).

    furnace: every shape emits the same Le and reflects with the same albedo rho, and they enclose the camera, so
    L = Le + rho L_in with L_in = L after each bounce: L = Le sum_{i < max_depth} rho^i, or Le / (1 - rho) unbounded.

    white-furnace: one diffuse sphere of albedo rho under a ``constant`` environment L, covering every pixel's
    footprint: a convex surface sees only the environment, so every pixel is rho L for max_depth >= 2 or -1
    (one bounce, then the ray escapes), and 0 for max_depth = 1 (the sphere does not emit). A textured rho makes
    each pixel L times the texture's mean over the pixel's footprint on the sphere (:func:`textured_sphere_means`).
    A perfect mirror (conductor, material "none") gives specular_reflectance L the same way; a smooth dielectric with
    specular_reflectance = specular_transmittance = 1 conserves energy, so every pixel is L at max_depth = -1.
    """
    if scene.closed_form not in CLOSED_FORMS:
        raise HarnessError(f"{scene.path}: closed_form", f"no closed form named {scene.closed_form!r}")
    radiance = CLOSED_FORMS[scene.closed_form](scene)
    shape = (scene.film.height, scene.film.width, 3)
    image = np.broadcast_to(radiance.astype(np.float32), shape).copy()
    info = {"closed_form": scene.closed_form}
    if radiance.shape == (3,):  # one radiance for every pixel (a textured sphere's differs from pixel to pixel)
        info["radiance"] = radiance.tolist()
    return GroundTruth(image, np.zeros(shape, np.float32), "closed-form", 0, info=info, cached=False)


def _furnace(scene: Scene) -> np.ndarray:
    """Every pixel's radiance in the furnace (every shape emits Le and has albedo rho, and they enclose the camera)."""
    if scene.emitters:
        raise HarnessError(f"{scene.path}: closed_form", (
            "the furnace closed form holds for emitting shapes alone; this scene also has [[emitters]] "
            f"({', '.join(e.type for e in scene.emitters)})"))
    used = [scene.materials[s.material] for s in scene.shapes]
    glossy = sorted({m.type for m in used if not m.is_diffuse})
    if glossy:
        raise HarnessError(f"{scene.path}: closed_form", (
            f"the furnace closed form holds for diffuse materials alone; this scene also has {', '.join(glossy)}"))
    emissions = {tuple(s.emission) if s.emission else None for s in scene.shapes}
    albedos = {tuple(scene.materials[s.material].reflectance) for s in scene.shapes}
    if len(emissions) != 1 or None in emissions or len(albedos) != 1:
        raise HarnessError(
            f"{scene.path}: closed_form",
            "the furnace closed form needs every shape to emit the same Le and have the same reflectance",
        )
    le = np.array(next(iter(emissions)))
    rho = np.array(next(iter(albedos)))
    if scene.max_depth == -1:
        if np.any(rho >= 1):
            raise HarnessError(f"{scene.path}: closed_form", "an unbounded furnace needs every albedo < 1")
        return le / (1.0 - rho)
    return le * sum(rho**i for i in range(scene.max_depth))


def _white_furnace(scene: Scene) -> np.ndarray:
    """Every pixel's radiance in the white furnace: rho L (max_depth >= 2 or -1), 0 (max_depth = 1)."""
    where = f"{scene.path}: closed_form"
    kinds = [e.type for e in scene.emitters]
    if kinds != ["constant"]:
        raise HarnessError(where, "the white-furnace closed form needs exactly one [[emitters]] entry, a constant "
                                  f"environment; this scene has {', '.join(kinds) or 'none'}")
    if len(scene.shapes) != 1 or scene.shapes[0].type != "sphere" or scene.shapes[0].emission is not None:
        found = ", ".join(f"{s.type}{' (emitting)' if s.emission else ''}" for s in scene.shapes) or "none"
        raise HarnessError(where, "the white-furnace closed form needs exactly one shape, a sphere that does not "
                                  f"emit; this scene has {found}")
    problem = sphere_coverage_problem(scene)
    if problem:
        raise HarnessError(where, f"the white-furnace closed form needs the sphere to cover every pixel's filter "
                                  f"footprint: {problem}")
    material = scene.materials[scene.shapes[0].material]
    radiance = np.array(scene.emitters[0].radiance, dtype=np.float64)
    if material.type in ("plastic", "roughplastic"):
        raise HarnessError(where, f"the white-furnace closed form has no {material.type} sphere (its albedo varies "
                                  "with the angle: tests/reference_impl/test_bsdf_thin_plastic.py and "
                                  "test_bsdf_roughplastic.py tabulate it)")
    if material.type == "principled":
        raise HarnessError(where, "the white-furnace closed form has no principled sphere (its albedo varies with "
                                  "the angle and exceeds 1: tests/reference_impl/test_bsdf_principled.py tabulates "
                                  "it)")
    if material.is_dielectric:
        # a smooth dielectric (or thin sheet) loses nothing (each bounce keeps F / F or (1 - F) / (1 - F), and the
        # eta^2 of entering and leaving cancel), but only an unbounded path gets all of it out again
        if material.type not in ("dielectric", "thindielectric") or scene.max_depth != -1 or \
                material.specular_reflectance != (1.0, 1.0, 1.0) or material.specular_transmittance != (1.0, 1.0, 1.0):
            raise HarnessError(where, (
                "the white-furnace closed form of a dielectric sphere needs a smooth one (type dielectric) with "
                "specular_reflectance = specular_transmittance = 1 at max_depth = -1 (then every pixel is L; a "
                f"thindielectric likewise); this scene has a {material.type} at max_depth = {scene.max_depth}"))
        return radiance
    if material.is_conductor and not (material.type == "conductor" and material.mirror):
        raise HarnessError(where, (
            "the white-furnace closed form of a conductor sphere needs a perfect mirror (type conductor, material "
            f"\"none\": every pixel specular_reflectance * L); this scene has a {material.type}"
            f"{'' if material.mirror else ' with eta / k (Fresnel < 1)'}"))
    if scene.max_depth == 1:
        return np.zeros(3)
    if material.textures:
        if not material.is_diffuse or scene.film.filter != "box":
            raise HarnessError(where, "the white-furnace closed form of a textured sphere needs a diffuse one and "
                                      f"the box filter; this scene has a {material.type} and the "
                                      f"{scene.film.filter} filter")
        return textured_sphere_means(scene) * radiance
    albedo = material.reflectance if material.is_diffuse else material.specular_reflectance
    return np.array(albedo, dtype=np.float64) * radiance


def sphere_coverage_problem(scene: Scene) -> str | None:
    """None if the scene's first shape (a sphere) covers the whole film as the camera sees it, else why not.

    The film's footprint is every point a pixel's filter reaches: [1/2 - r, W - 1/2 + r] x [1/2 - r, H - 1/2 + r]
    in film coordinates (r the filter radius in pixels; box: [0, W] x [0, H]). The sphere covers a cone of
    directions from the eye, of half-angle asin(a / d) (d the distance to the centre, a the radius of the largest
    ball centred there inside both the analytic sphere and the reference's icosphere: the distance to its nearest
    face plane); a convex cone holds the footprint's image iff it holds its four corner rays.
    """
    sphere = scene.shapes[0]
    matrix = object_to_world(sphere)
    centre = matrix[:3, 3]
    vertices, triangles = shape_triangles(sphere)
    corners = vertices[triangles]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    inner = float(np.min(np.abs(np.einsum("ij,ij->i", normals, corners[:, 0] - centre))))
    inner = min(inner, float(np.linalg.norm(matrix[:3, 0])))
    eye = np.asarray(scene.camera.origin, dtype=np.float64)
    to_centre = centre - eye
    distance = float(np.linalg.norm(to_centre))
    if distance <= inner:
        return f"the camera is inside the sphere ({distance:.6g} from its centre, inscribed radius {inner:.6g})"
    width, height = scene.film.width, scene.film.height
    reach = scene.film.pixel_filter.radius - 0.5  # how far past the film's edge the border pixels' filters reach
    film_x = np.array([-reach, width + reach, -reach, width + reach])
    film_y = np.array([-reach, -reach, height + reach, height + reach])
    _origins, directions = scene.camera.generate_rays(film_x, film_y, width, height)
    cosines = directions @ (to_centre / distance)
    angle = math.degrees(math.acos(min(1.0, float(np.min(cosines)))))
    half_angle = math.degrees(math.asin(inner / distance))
    if angle >= half_angle:
        return (f"the film's farthest corner ray (with the {scene.film.filter} filter's reach) is {angle:.4g} degrees "
                f"from the sphere's centre, the sphere's angular radius {half_angle:.4g} degrees")
    return None


def footprint_rays(scene: Scene, side: int):
    """Each film row y's camera rays through ``side`` x ``side`` midpoints of each of its pixels' box footprints:
    (y, origins, directions), the W side^2 rays pixel by pixel (the midpoint rule of the closed forms)."""
    width, height = scene.film.width, scene.film.height
    offsets = (np.arange(side) + 0.5) / side
    for y in range(height):
        fx, fy = np.meshgrid(np.arange(width)[:, None] + offsets[None, :], y + offsets, indexing="ij")
        yield (y, *scene.camera.generate_rays(fx.ravel(), np.broadcast_to(fy, fx.shape).ravel(), width, height))


#: Points per pixel side of :func:`textured_sphere_means`' quadrature.
QUADRATURE_SIDE = 32


def textured_sphere_means(scene: Scene, side: int = QUADRATURE_SIDE) -> np.ndarray:
    """(H, W, 3): each pixel's mean of the sphere's textured reflectance over its box footprint, by the midpoint rule
    on ``side`` x ``side`` points per pixel: each point's camera ray meets the analytic sphere at x, whose texture
    coordinates are Mitsuba's (p = to_object x: u = atan2(p_y, p_x) / (2 pi) mod 1, v = acos(p_z) / pi), and the
    texture is looked up there by the reference's lookup (kernels/texture.py, checked against Mitsuba's bitmaps in
    tests/reference_impl/test_textures.py). The scene's checks (one sphere covering the footprint) are the
    caller's."""
    from reference_impl.kernels import records, texture as lookup  # optional: numba's kernels, closed forms only

    sphere = scene.shapes[0]
    (item, tex), = scene.materials[sphere.material].textures
    tables = records.texture_tables(Textures((tex.core,)))
    to_world = object_to_world(sphere)
    to_object = np.linalg.inv(to_world)
    centre, radius = to_world[:3, 3], float(np.linalg.norm(to_world[:3, 0]))
    width, height = scene.film.width, scene.film.height
    out = np.empty((height, width, 3))
    for y, origins, directions in footprint_rays(scene, side):
        oc = origins - centre
        b = np.einsum("ij,ij->i", oc, directions)
        c = np.einsum("ij,ij->i", oc, oc) - radius * radius
        t = -b - np.sqrt(b * b - c)  # the nearer root: the camera is outside (the coverage check)
        p = (origins + t[:, None] * directions) @ to_object[:3, :3].T + to_object[:3, 3]
        values = lookup.evaluate(tables, 0, sphere_uv(p)).reshape(width, side * side, 3)
        out[y] = values.mean(axis=1)
    return out


def _leaning_plate(scene: Scene) -> np.ndarray:
    """(H, W, 3): a smooth-shaded diffuse mesh under suns, alone, covering the film: each pixel the mean over its box
    footprint of rho / pi sum_k E_k max(0, n_s . l_k) [N . l_k > 0] [n_s . wo > 0] (:func:`shaded_plate_means`)."""
    where = f"{scene.path}: closed_form"
    if len(scene.shapes) != 1 or scene.shapes[0].type != "mesh" or scene.shapes[0].emission is not None:
        raise HarnessError(where, "the leaning-plate closed form needs exactly one shape, a mesh that does not emit")
    _check_sunlit_diffuse(scene, "leaning-plate")
    key = scene_digest(scene)
    if key not in _PLATE_MEANS:  # a suite's cases of one scene share it (seconds each)
        _PLATE_MEANS.clear()
        _PLATE_MEANS[key] = shaded_plate_means(scene)
    return _PLATE_MEANS[key]


def _check_sunlit_diffuse(scene: Scene, name: str) -> None:
    """What :func:`shaded_plate_means` needs of the closed form ``name``'s one shape and lights: a one-sided diffuse
    material without textures, [[emitters]] that are all directional, the box filter and max_depth >= 2 or -1."""
    where = f"{scene.path}: closed_form"
    material = scene.materials[scene.shapes[0].material]
    if not material.is_diffuse or material.textures or material.perturbation or material.two_sided:
        raise HarnessError(where, f"the {name} closed form needs a one-sided diffuse material without textures")
    if not scene.emitters or any(e.type != "directional" for e in scene.emitters):
        raise HarnessError(where, f"the {name} closed form needs [[emitters]] that are all directional")
    if scene.film.filter != "box" or scene.max_depth == 1:
        raise HarnessError(where, f"the {name} closed form needs the box filter and max_depth >= 2 or -1")


_PLATE_MEANS: dict[str, np.ndarray] = {}
#: Points per pixel side of :func:`shaded_plate_means`' quadrature: its integrand is smooth within a triangle (the
#: blend of the normals) with a kink at the edges, so the midpoint rule's error, O(1/side^2) of the variation across
#: a pixel, is 2e-7 of the value at most here (side 16 against 64 on scenes/leaning-plate.toml, largest pixel).
PLATE_QUADRATURE_SIDE = 16


def shaded_plate_means(scene: Scene, side: int = PLATE_QUADRATURE_SIDE, misses: bool = False) -> np.ndarray:
    """(H, W, 3): each pixel's mean over its box footprint, by the midpoint rule on ``side`` x ``side`` points, of
    the light a one-sided diffuse mesh (the scene's one shape) reflects toward the camera from directional lights:

        L = rho / pi sum_k E_k max(0, n_s . l_k) [N . l_k > 0] [n_s . wo > 0] [N . wo > 0],

    n_s the normalised barycentric blend of the vertex normals (:func:`harness.scene.triangulate.vertex_normals`),
    N the triangle's geometric normal, which decides the side (no light through the plate), l_k the direction toward
    sun k, wo toward the camera. Every point's ray must meet the mesh (HarnessError otherwise): the mesh covers the
    film, nothing else is in the scene; with ``misses``, a ray that misses it adds 0 (nothing else is there)."""
    shape = scene.shapes[0]
    vertices, triangles = shape_triangles(shape)
    corners = vertices[triangles]
    e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    geometric = np.cross(e1, e2)
    geometric /= np.linalg.norm(geometric, axis=1, keepdims=True)
    normals = vertex_normals(shape, vertices, triangles)
    if normals is None:  # flat: each corner's normal its triangle's
        vertices, triangles = corners.reshape(-1, 3), np.arange(3 * len(triangles)).reshape(-1, 3)
        normals = np.repeat(geometric, 3, axis=0)
    rho = np.asarray(scene.materials[shape.material].reflectance, dtype=np.float64)
    suns = [(-np.asarray(e.direction, dtype=np.float64) / np.linalg.norm(e.direction),
             np.asarray(e.irradiance, dtype=np.float64)) for e in scene.emitters]
    width, height = scene.film.width, scene.film.height
    out = np.empty((height, width, 3))
    for y, origins, directions in footprint_rays(scene, side):
        best_t = np.full(len(origins), np.inf)
        shading = np.zeros_like(origins)
        face = np.zeros_like(origins)
        for tri in range(len(triangles)):  # Moeller-Trumbore against each triangle: the nearest hit
            p = np.cross(directions, e2[tri])
            det = p @ e1[tri]
            with np.errstate(all="ignore"):
                inv = 1.0 / det
                s = origins - corners[tri, 0]
                u = np.einsum("ij,ij->i", s, p) * inv
                q = np.cross(s, e1[tri])
                v = np.einsum("ij,ij->i", directions, q) * inv
                t = (q @ e2[tri]) * inv
            hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < best_t)
            best_t[hit] = t[hit]
            blend = ((1 - u - v)[:, None] * normals[triangles[tri, 0]] + u[:, None] * normals[triangles[tri, 1]]
                     + v[:, None] * normals[triangles[tri, 2]])
            shading[hit] = blend[hit] / np.linalg.norm(blend[hit], axis=1, keepdims=True)
            face[hit] = geometric[tri]
        if not misses and not np.all(np.isfinite(best_t)):
            raise HarnessError(f"{scene.path}: closed_form", "the leaning-plate closed form needs the mesh to cover "
                                                             "every pixel's footprint")
        wo = -directions
        seen = (np.einsum("ij,ij->i", shading, wo) > 0) & (np.einsum("ij,ij->i", face, wo) > 0)
        radiance = np.zeros((len(origins), 3))
        for toward, irradiance in suns:
            cos = np.maximum(shading @ toward, 0.0) * (face @ toward > 0)
            radiance += (cos * seen)[:, None] * irradiance
        out[y] = (radiance * rho / np.pi).reshape(width, side * side, 3).mean(axis=1)
    return out


def _sunlit_floor(scene: Scene) -> np.ndarray:
    """(H, W, 3): a flat one-sided diffuse mesh under suns, alone, seen by an orthographic camera: each pixel the
    mean over its box footprint of rho / pi sum_k E_k max(0, N . l_k) where the pixel's parallel ray meets the
    mesh, 0 where it misses (nothing else is in the scene) (:func:`shaded_plate_means`)."""
    where = f"{scene.path}: closed_form"
    if not isinstance(scene.camera, OrthographicCamera):
        raise HarnessError(where, "the sunlit-floor closed form needs an orthographic [camera]")
    if len(scene.shapes) != 1 or scene.shapes[0].emission is not None:
        raise HarnessError(where, "the sunlit-floor closed form needs exactly one shape that does not emit")
    _check_sunlit_diffuse(scene, "sunlit-floor")
    return shaded_plate_means(scene, misses=True)


#: Points per pixel side of :func:`focused_plane_means`' quadrature.
FOCUS_QUADRATURE_SIDE = 8


def _focused_plane(scene: Scene) -> np.ndarray:
    """(H, W, 3): an emitting rectangle on a thin lens's plane of focus, alone: every ray through a film point p,
    whatever its aperture point, meets the plane z_cam = focus_distance where the pinhole ray of p meets it, so each
    pixel is the mean of the rectangle's Le over its box footprint through the pinhole, whatever the aperture
    (:func:`focused_plane_means`)."""
    where = f"{scene.path}: closed_form"
    camera = scene.camera
    if not isinstance(camera, ThinLensCamera):
        raise HarnessError(where, "the focused-plane closed form needs a thinlens [camera]")
    if len(scene.shapes) != 1 or scene.shapes[0].type != "rectangle" or scene.shapes[0].emission is None:
        raise HarnessError(where, "the focused-plane closed form needs exactly one shape, an emitting rectangle")
    if scene.emitters or scene.film.filter != "box":
        raise HarnessError(where, "the focused-plane closed form needs no [[emitters]] and the box filter")
    to_world = object_to_world(scene.shapes[0])
    normal = np.linalg.inv(to_world[:3, :3]).T @ np.array([0.0, 0.0, 1.0])
    normal /= np.linalg.norm(normal)
    frame = camera.frame()
    depth = float((to_world[:3, 3] - np.asarray(camera.origin, dtype=np.float64)) @ frame[:, 2])
    if abs(abs(normal @ frame[:, 2]) - 1.0) > 1e-12 or abs(depth - camera.focus_distance) > 1e-9 * depth:
        raise HarnessError(where, "the focused-plane closed form needs the rectangle square to the camera's axis at "
                                  f"focus_distance ({camera.focus_distance:g}) along it, got {depth:g}")
    return focused_plane_means(scene)


def focused_plane_means(scene: Scene, side: int = FOCUS_QUADRATURE_SIDE) -> np.ndarray:
    """(H, W, 3): each pixel's mean, by the midpoint rule on ``side`` x ``side`` points, of the emission Le(x) of
    the scene's one shape, a rectangle, at the point x where each point's pinhole ray meets it (0 where it misses,
    or meets its back); a textured Le looked up at Mitsuba's rectangle coordinates ((x_l + 1) / 2, (y_l + 1) / 2) of
    the local point x_l by the reference's lookup (kernels/texture.py, checked against Mitsuba's textures in
    tests/reference_impl/test_textures.py)."""
    from reference_impl.kernels import records, texture as lookup  # optional: numba's kernels, closed forms only

    shape = scene.shapes[0]
    to_world = object_to_world(shape)
    to_object = np.linalg.inv(to_world)
    width, height = scene.film.width, scene.film.height
    tables = None
    if shape.emission_texture is not None:
        tables = records.texture_tables(Textures((shape.emission_texture.core,)))
    out = np.empty((height, width, 3))
    for y, origins, directions in footprint_rays(scene, side):
        o = origins @ to_object[:3, :3].T + to_object[:3, 3]
        d = directions @ to_object[:3, :3].T
        with np.errstate(all="ignore"):
            t = -o[:, 2] / d[:, 2]
        local = o + t[:, None] * d
        inside = (t > 0) & (np.abs(local[:, 0]) <= 1) & (np.abs(local[:, 1]) <= 1) & (d[:, 2] < 0)
        if tables is None:
            values = np.broadcast_to(np.asarray(shape.emission, dtype=np.float64), (len(o), 3))
        else:
            values = lookup.evaluate(tables, 0, (local[:, :2] + 1.0) / 2.0)
        out[y] = (values * inside[:, None]).reshape(width, side * side, 3).mean(axis=1)
    return out


#: Points per pixel side of :func:`absorbing_cube_means`' quadrature.
CHORD_QUADRATURE_SIDE = 8


def _one_constant_environment(scene: Scene, name: str) -> np.ndarray:
    """The radiance L of the scene's one emitter, a constant environment, and no emitting shape; else HarnessError."""
    where = f"{scene.path}: closed_form"
    kinds = [e.type for e in scene.emitters]
    if kinds != ["constant"] or any(s.emission is not None for s in scene.shapes):
        raise HarnessError(where, f"the {name} closed form needs exactly one [[emitters]] entry, a constant "
                                  f"environment, and no emitting shape; this scene has {', '.join(kinds) or 'none'}")
    return np.array(scene.emitters[0].radiance, dtype=np.float64)


def _beer_lambert(scene: Scene) -> np.ndarray:
    """(H, W, 3): null-bounded cubes of absorbing media (albedo 0) before a constant environment L, seen from
    vacuum: each ray through them carries L exp(-sum_k sigma_t,k s_k), s_k its chord through cube k (Beer-Lambert;
    nothing scatters light into it), each pixel the mean over its box footprint (:func:`absorbing_cube_means`)."""
    where = f"{scene.path}: closed_form"
    radiance = _one_constant_environment(scene, "beer-lambert")
    if scene.camera_medium is not None or scene.film.filter != "box":
        raise HarnessError(where, "the beer-lambert closed form needs the camera in vacuum and the box filter")
    for shape in scene.shapes:
        medium = scene.media.get(shape.interior) if shape.interior else None
        if (shape.type != "cube" or scene.materials[shape.material].type != "null" or shape.exterior is not None
                or medium is None or any(a != 0 for a in medium.albedo)):
            raise HarnessError(where, "the beer-lambert closed form needs every shape a cube of the null material "
                                      "around an absorbing medium (albedo 0) in vacuum; shape "
                                      f"{shape.name!r} is not")
    return absorbing_cube_means(scene, radiance)


def absorbing_cube_means(scene: Scene, radiance: np.ndarray, side: int = CHORD_QUADRATURE_SIDE) -> np.ndarray:
    """(H, W, 3): each pixel's mean, by the midpoint rule on ``side`` x ``side`` points, of L exp(-sum_k sigma_k s_k)
    with s_k the chord of the point's camera ray through cube k (Mitsuba's [-1, 1]^3 under ``to_world``: the slab
    method in the cube's own space, where the ray's parameter t is the world one's). The scene's checks are the
    caller's."""
    width, height = scene.film.width, scene.film.height
    out = np.empty((height, width, 3))
    cubes = [(np.linalg.inv(object_to_world(s)), np.array(scene.media[s.interior].extinction)) for s in scene.shapes]
    for y, origins, directions in footprint_rays(scene, side):
        depth = np.zeros((len(origins), 3))
        for to_object, sigma in cubes:
            o = origins @ to_object[:3, :3].T + to_object[:3, 3]
            d = directions @ to_object[:3, :3].T
            with np.errstate(divide="ignore", invalid="ignore"):
                t1, t2 = (-1.0 - o) / d, (1.0 - o) / d
            near = np.nanmax(np.where(np.isnan(t1), -np.inf, np.minimum(t1, t2)), axis=1)
            far = np.nanmin(np.where(np.isnan(t2), np.inf, np.maximum(t1, t2)), axis=1)
            inside_slabs = np.all((d != 0) | (np.abs(o) <= 1), axis=1)
            chord = np.where(inside_slabs, np.clip(far - np.maximum(near, 0.0), 0.0, None), 0.0)
            depth += chord[:, None] * sigma[None, :]
        out[y] = (radiance[None, :] * np.exp(-depth)).reshape(width, side * side, 3).mean(axis=1)
    return out


def _medium_furnace(scene: Scene) -> np.ndarray:
    """Every pixel's radiance in a medium furnace: media of albedo 1 behind null boundaries (or around the camera)
    under a constant environment L and nothing else: radiance is conserved along and between scatterings, so the
    uniform field L solves the volume rendering equation: every pixel is L (max_depth = -1)."""
    where = f"{scene.path}: closed_form"
    radiance = _one_constant_environment(scene, "medium-furnace")
    if scene.max_depth != -1:
        raise HarnessError(where, "the medium-furnace closed form needs max_depth = -1 (unbounded)")
    if any(scene.materials[s.material].type != "null" for s in scene.shapes):
        raise HarnessError(where, "the medium-furnace closed form needs every shape of the null material")
    if not scene.media or any(any(a != 1 for a in m.albedo) for m in scene.media.values()):
        raise HarnessError(where, "the medium-furnace closed form needs media, every one of albedo 1")
    return radiance


CLOSED_FORMS: dict[str, Callable[[Scene], np.ndarray]] = {"furnace": _furnace, "white-furnace": _white_furnace,
                                                          "leaning-plate": _leaning_plate,
                                                          "sunlit-floor": _sunlit_floor,
                                                          "focused-plane": _focused_plane,
                                                          "beer-lambert": _beer_lambert,
                                                          "medium-furnace": _medium_furnace}


# ---- the cache -------------------------------------------------------------------------------------------------


def scene_digest(scene: Scene) -> str:
    """The scene's content key (:func:`harness.scene.content_key.content_key`): every field of the loaded scene,
    camera, film, materials, shapes and emitters (arrays by their bytes), and the bytes of every file the loader
    read (:attr:`Scene.files`: the scene file, its meshes, its environment maps). A scene changed in memory after
    loading (a suite's resolution or depth override, a test's edit) or a file edited since is never served another
    scene's entry."""
    return content_key(scene)


def mitsuba_version() -> str:
    try:
        return metadata.version("mitsuba")
    except metadata.PackageNotFoundError:
        return "not installed"


def _key(fields: dict) -> str:
    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _meta_sha256(key: str, meta: dict) -> str:
    """SHA-256 of an entry's key and its metadata but the checksums, as meta.json holds them (JSON, sorted keys)."""
    content = {k: v for k, v in meta.items() if k != "sha256"}
    return hashlib.sha256(f"{key}\n{json.dumps(content, sort_keys=True)}".encode()).hexdigest()


class Cache:
    """Content-addressed entries of per-pixel estimates under ``root/groundtruth``."""

    def __init__(self, root: Path | str | None = None):
        self.root = Path(root) if root is not None else default_cache_dir()
        self.folder = self.root / "groundtruth"

    def entry(self, key: str) -> Path:
        return self.folder / key

    def load(self, key: str) -> tuple[Estimate, dict] | None:
        """The verified entry, or None when absent; a damaged entry is removed (and reported as absent)."""
        folder = self.entry(key)
        meta_path = folder / "meta.json"
        if not meta_path.exists():
            if folder.exists():
                self._discard(folder)
            return None
        try:
            meta = json.loads(meta_path.read_text())
            # meta.json may parse and still be garbage (null, a list, no checksums): every data file must be listed
            checksums = meta.get("sha256") if isinstance(meta, dict) else None
            if not isinstance(checksums, dict) or any(name not in checksums for name in (*DATA_FILES, META_CHECKSUM)):
                raise ValueError("meta.json lacks the checksums of the data files or its own")  # older entries too
            if checksums[META_CHECKSUM] != _meta_sha256(key, meta):
                raise ValueError("meta.json was edited, or the entry is not this key's")
            for name in DATA_FILES:
                if _sha256(folder / name) != checksums[name]:
                    raise ValueError(f"checksum mismatch in {name}")
            with np.load(folder / "estimate.npz") as data:
                estimate = Estimate(data["mean"], data["variance"], int(data["n"]))
        except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile):
            self._discard(folder)
            return None
        return estimate, meta

    def store(self, key: str, estimate: Estimate, meta: dict) -> Path:
        """Write an entry atomically; if another process stored it first, keep theirs. A failed write (a full disk)
        is a one-line WriteError naming the cache, and leaves neither the entry nor folders made for it."""
        created: list[Path] = []
        tmp = self.folder / private_name(".tmp-")
        failure: OSError | None = None
        try:
            created = make_folders(self.folder)
            tmp.mkdir()
            np.savez(tmp / "estimate.npz", mean=estimate.mean, variance=estimate.variance, n=estimate.n)
            write_exr(tmp / "image.exr", estimate.mean, estimate.variance,
                      metadata={"harness.renderers.groundtruth": json.dumps({k: v for k, v in meta.items() if k != "sha256"})})
            meta = json.loads(json.dumps({k: v for k, v in meta.items() if k != "sha256"}))  # as load() reads it
            meta["sha256"] = {**{name: _sha256(tmp / name) for name in DATA_FILES},
                              META_CHECKSUM: _meta_sha256(key, meta)}
            (tmp / "meta.json").write_text(json.dumps(meta, indent=2, sort_keys=True))
            for _attempt in range(3):
                try:
                    os.rename(tmp, self.entry(key))
                    break
                except OSError as err:
                    # Taken: keep a valid entry; a damaged one is removed by load(), then try to take its place
                    # (another process may take it first, hence the retries).
                    if self.load(key) is not None:
                        break
                    failure = err
            else:
                raise failure
        except (OSError, WriteError) as err:
            shutil.rmtree(tmp, ignore_errors=True)
            remove_folders(created)
            # name the cache, not the temporary file
            reason = err.message.removeprefix("cannot write: ") if isinstance(err, WriteError) else \
                (err.strerror or str(err))
            raise WriteError(str(self.root), f"cannot write the ground-truth cache: {reason}") from None
        finally:
            if tmp.exists():  # another process's entry was kept, or an exception of another kind
                shutil.rmtree(tmp, ignore_errors=True)
        return self.entry(key) / "image.exr"

    def _discard(self, folder: Path) -> None:
        trash = self.folder / private_name(".bad-")
        try:
            os.rename(folder, trash)
            shutil.rmtree(trash, ignore_errors=True)
        except OSError:
            pass


# ---- Mitsuba ground truth --------------------------------------------------------------------------------------


def _stored(cache: Cache, key: str, estimate: Estimate) -> Estimate:
    """What the cache holds under ``key`` after a store: when another process stored it first, its estimate (the
    files at the entry's path), so that every user of a key gets the same image; else ``estimate`` itself."""
    found = cache.load(key)
    return found[0] if found is not None else estimate


def ground_truth(
    scene: Scene,
    *,
    spp: int = DEFAULT_SPP,
    seed: int = 0,
    cache_dir: Path | str | None = None,
    variant: str | None = None,
    chunk_spp: int = DEFAULT_CHUNK_SPP,
    use_closed_form: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> GroundTruth:
    """Ground truth for ``scene``: its closed form if it has one (and ``use_closed_form``), else a Mitsuba render
    of ``spp`` samples per pixel in chunks of ``chunk_spp``, each chunk cached."""
    if scene.closed_form and use_closed_form:
        return closed_form(scene)
    if spp < 1:
        raise HarnessError("--spp", f"expected a positive number of samples, got {spp}")
    if chunk_spp < 1:
        raise HarnessError("--chunk-spp", f"expected a positive number of samples, got {chunk_spp}")
    variant = choose_variant(variant)
    cache = Cache(cache_dir)
    base = _base(scene, seed, variant)
    full_key = _key(dict(base, spp=spp, chunk_spp=chunk_spp))
    found = cache.load(full_key)
    if found is not None:
        estimate, meta = found
        if progress is not None:
            progress(1, 1)
        return GroundTruth(estimate.mean.astype(np.float32), estimate.variance.astype(np.float32), "mitsuba", spp,
                           info=meta, cached=True, path=cache.entry(full_key) / "image.exr")

    counts = _counts(spp, chunk_spp)
    chunks: list[Estimate] = []
    renders, seconds, info = 0, 0.0, {}
    render_seconds = 0.0  # the chunks' own render times, whenever they were rendered (by this call or before)
    done = 0
    for index, count in enumerate(counts):
        estimate, rendered, chunk_meta = _chunk(scene, cache, base, index, count,
                                                progress=_within(progress, done, count, spp))
        if rendered is not None:
            seconds += rendered
            renders += 1
        info = chunk_meta.get("info") or info
        render_seconds += float(chunk_meta.get("render_seconds") or 0.0)
        chunks.append(estimate)
        done += count
        if progress is not None:
            progress(done, spp)
    merged = merge(chunks)
    meta = dict(base, spp=spp, chunk_spp=chunk_spp, chunks=len(counts), info=info, render_seconds=render_seconds)
    path = cache.store(full_key, merged, meta)
    merged = _stored(cache, full_key, merged)
    return GroundTruth(merged.mean.astype(np.float32), merged.variance.astype(np.float32), "mitsuba", spp,
                       info=meta, cached=renders == 0, renders=renders, seconds=seconds, path=path)


#: samples per pixel of each pilot render of :func:`auto_spp`
PILOT_SPP = 16


@dataclass(frozen=True)
class AutoSpp:
    """The ground truth's spp chosen by :func:`auto_spp`, and why: ``ratio`` is the ground-truth renderer's
    per-sample variance over the test renderer's (means over pixels and channels, from ``pilot_spp`` pilots)."""

    spp: int
    test_spp: int
    ratio: float
    test_per_sample: float
    ground_truth_per_sample: float
    pilot_spp: int
    test_renderer: str
    variant: str

    def reason(self) -> str:
        need = 4.0 * self.test_spp * self.ratio
        return (f"{self.spp} spp: the ground truth's variance at most 1/4 of the test's needs 4 x {self.test_spp} "
                f"(test spp) x {self.ratio:.3g} (per-sample variance of Mitsuba {self.variant}, "
                f"{self.ground_truth_per_sample:.3g}, over {self.test_renderer}'s, {self.test_per_sample:.3g}; "
                f"{self.pilot_spp}-spp pilots) = {need:.4g} spp, rounded up to a power of 2")

    def to_dict(self) -> dict:
        return {"spp": self.spp, "test_spp": self.test_spp, "ratio": self.ratio,
                "test_per_sample_variance": self.test_per_sample,
                "ground_truth_per_sample_variance": self.ground_truth_per_sample, "pilot_spp": self.pilot_spp,
                "test_renderer": self.test_renderer, "variant": self.variant, "reason": self.reason()}


def auto_spp(scene: Scene, *, test_spp: int, test_renderer: str = "reference", test_settings: dict | None = None,
             variant: str | None = None, pilot_spp: int = PILOT_SPP, seed: int = 0) -> AutoSpp:
    r"""The spp of a Mitsuba ground truth whose variance is at most 1/4 of a test render's at ``test_spp``
    (:data:`harness.judges.floor.GROUND_TRUTH_SHARE_LIMIT`): a pilot render of each renderer at ``pilot_spp`` gives
    its per-sample variance :math:`\sigma^2 = \bar V \cdot n` (the variance of the mean times the samples), and
    :math:`spp_{gt} \ge 4\, spp_{test}\, \sigma^2_{gt} / \sigma^2_{test}`, rounded up to a power of two, and
    at least ``test_spp``.

    Notes
    -----
    A variance of the mean falls as 1 / spp for independent samples; a stratified test renderer's falls faster, so
    the ratio taken at the pilot's spp errs on the side of more ground-truth samples. The pilots are not cached.
    """
    variant = choose_variant(variant)
    test = get_renderer(test_renderer).render(scene, RenderRequest(spp=pilot_spp, seed=seed,
                                                                   settings=dict(test_settings or {})))
    truth = get_renderer("mitsuba").render(scene, RenderRequest(spp=pilot_spp, seed=seed + 1,
                                                                settings={"variant": variant}))
    if test.variance is None:
        raise HarnessError("--test-renderer", f"{test_renderer} wrote no variance: --spp auto needs its per-pixel "
                                              "variance (a renderer file with repeats gives one)")
    per_sample = []
    for result in (test, truth):
        v = np.asarray(result.variance, np.float64)
        ok = np.isfinite(v)
        per_sample.append(float(v[ok].mean()) * result.spp if ok.any() else 0.0)
    if per_sample[0] <= 0:
        raise HarnessError("--spp", f"auto: the {test_renderer} pilot has no variance (a noiseless render): any "
                                    "ground truth spp is enough; give --spp N")
    ratio = per_sample[1] / per_sample[0]
    spp = spp_for_share(test_spp, ratio) if ratio > 0 else 1
    return AutoSpp(spp, test_spp, ratio, per_sample[0], per_sample[1], pilot_spp, test_renderer, variant)


def _base(scene: Scene, seed: int, variant: str) -> dict:
    """What every cache key of a Mitsuba ground truth holds (``variant`` already resolved)."""
    return {
        "format": FORMAT_VERSION,
        "scene": scene_digest(scene),
        "film": [scene.film.width, scene.film.height, scene.film.filter],
        "max_depth": scene.max_depth,
        "mitsuba": mitsuba_version(),
        "variant": variant,
        "seed": seed,
    }


def _counts(spp: int, chunk_spp: int) -> list[int]:
    return [chunk_spp] * (spp // chunk_spp) + ([spp % chunk_spp] if spp % chunk_spp else [])


def _within(progress: Callable[[int, int], None] | None, before: int, count: int, spp: int):
    """The ``progress(done, total)`` of one chunk's render (paths of its passes) as the ground truth's (samples
    per pixel of all its chunks, ``before`` of them done): the caller hears of every pass but the chunk's last,
    which :func:`ground_truth` reports once the chunk is stored (a caller that stops there keeps the chunk)."""
    if progress is None:
        return None

    def report(done: int, total: int) -> None:
        if done < total:
            progress(before + (count * done) // max(total, 1), spp)

    return report


def _chunk(scene: Scene, cache: Cache, base: dict, index: int, count: int, progress=None):
    """Chunk ``index`` of ``count`` samples from the cache, else rendered (``progress(done, total)`` after each
    pass) and stored: (estimate, None, meta) when it was cached, (estimate, seconds spent now, meta) when it was
    rendered now."""
    chunk_key = _key(dict(base, chunk=index, chunk_spp=count))
    found = cache.load(chunk_key)
    if found is not None:
        return found[0], None, found[1]
    chunk_seed = int(hashlib.sha256(f"{base['seed']}/{index}".encode()).hexdigest()[:8], 16)
    start = time.perf_counter()
    result = get_renderer("mitsuba").render(
        scene, RenderRequest(spp=count, seed=chunk_seed, settings={"variant": base["variant"]}, progress=progress))
    seconds = time.perf_counter() - start
    info = dict(result.info)
    estimate = Estimate(result.image, result.variance, count)
    meta = dict(base, chunk=index, spp=count, chunk_seed=chunk_seed, render_seconds=result.seconds, info=info)
    cache.store(chunk_key, estimate, meta)
    return _stored(cache, chunk_key, estimate), seconds, meta


def entry_key(scene: Scene, *, spp: int, seed: int = 0, variant: str | None = None,
              chunk_spp: int = DEFAULT_CHUNK_SPP) -> str:
    """The key of the merged entry :func:`ground_truth` reads or writes for these arguments (``variant``
    resolved as it resolves it)."""
    return _key(dict(_base(scene, seed, choose_variant(variant)), spp=spp, chunk_spp=chunk_spp))


def entry_checksum(key: str, cache_dir: Path | str | None = None) -> str | None:
    """The SHA-256 of the estimate the entry ``key`` holds, every checksum of the entry verified; None when there
    is no such entry or it is damaged (:meth:`Cache.load` removes it when it is next read). What an entry holds
    is fixed once it is written (the first rename wins), so this names the image every reader of the key gets."""
    folder = Cache(cache_dir).entry(key)
    try:
        meta = json.loads((folder / "meta.json").read_text())
        checksums = meta["sha256"]
        if checksums[META_CHECKSUM] != _meta_sha256(key, meta):
            return None
        if any(_sha256(folder / name) != checksums[name] for name in DATA_FILES):
            return None
        return str(checksums["estimate.npz"])
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


@dataclass(frozen=True)
class ChunkJob:
    """One chunk of a Mitsuba ground truth, as a unit of work an executor can run anywhere that sees the cache:
    ``ground_truth()`` with the same arguments merges the chunks it finds cached, so rendering the chunks of a
    long ground truth as separate tasks first gives the same image, bit for bit."""

    scene: Scene
    key: str  # the chunk's cache key (jobs with the same key are the same work)
    index: int
    count: int
    base: dict
    cache_dir: str | None

    def run(self) -> bool:
        """Render the chunk unless it is cached; True when it was rendered now."""
        return _chunk(self.scene, Cache(self.cache_dir), self.base, self.index, self.count)[1] is not None


def missing_chunks(scene: Scene, *, spp: int, seed: int = 0, cache_dir=None, variant: str | None = None,
                   chunk_spp: int = DEFAULT_CHUNK_SPP) -> list[ChunkJob]:
    """The chunks ``ground_truth()`` would render for these arguments: none when the merged entry or every chunk
    is cached (a damaged entry counts as missing)."""
    base = _base(scene, seed, choose_variant(variant))
    cache = Cache(cache_dir)
    if cache.load(_key(dict(base, spp=spp, chunk_spp=chunk_spp))) is not None:
        return []
    jobs = []
    for index, count in enumerate(_counts(spp, chunk_spp)):
        key = _key(dict(base, chunk=index, chunk_spp=count))
        if cache.load(key) is None:
            jobs.append(ChunkJob(scene, key, index, count, base, None if cache_dir is None else str(cache_dir)))
    return jobs
