"""Tiny scenes with emitters that are not shapes, built in memory (the scene model of harness/scene/model.py), and
their closed forms (test fixtures for tests/reference_impl/test_emitters.py and test_emitters_chi2.py).

Until the loader reads ``[[emitters]]``, scenes are built as ``Scene`` records directly; the shapes are Mitsuba's
(rectangle, sphere) with ``to_world`` matrices from harness.scene.triangulate.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from harness.scene.model import (ConstantEnvironment, DirectionalLight, EnvironmentMap, Material, PointLight, Scene,
                                 Shape, SpotLight)
from harness.scene.emitter_arrays import core_record
from harness.scene.triangulate import rotate_matrix, scale_matrix, translate_matrix
from reference_impl import Camera, Emitters, Film
from reference_impl.emitters import environment_radiance, uv_to_direction

RHO = 0.6  # albedo of the test planes and spheres (grey: the three channels agree)


def plane_scene(size: int = 8, rho: float = RHO, half: float = 20.0, max_depth: int = 2, emitters=(),
                camera: Camera | None = None, normal_up: str = "z", tilt: float = 0.0) -> Scene:
    """A one-sided diffuse square of side 2 ``half`` at the origin, facing +z (or +y with ``normal_up="y"``, then
    tilted by ``tilt`` degrees toward +x), seen from above by a ``size`` x ``size`` box-filtered film."""
    to_world = scale_matrix(half)
    if normal_up == "y":
        to_world = rotate_matrix((0, 0, 1), -tilt) @ rotate_matrix((1, 0, 0), -90.0) @ to_world  # +z -> +y
    if camera is None:
        normal = plane_normal(normal_up, tilt)
        camera = (Camera(origin=(0.0, 0.0, 3.0), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=40.0)
                  if normal_up == "z" else
                  Camera(origin=tuple(3.0 * normal), target=(0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0), fov=40.0))
    shape = Shape(index=0, name="plane", type="rectangle", material="grey", to_world=to_world)
    return Scene(name="plane", description="", camera=camera, film=Film(size, size, "box"), max_depth=max_depth,
                 materials={"grey": Material("grey", (rho, rho, rho))}, shapes=[shape], path=Path("plane.toml"),
                 emitters=tuple(emitters))


def plane_normal(normal_up: str = "z", tilt: float = 0.0) -> np.ndarray:
    """The front normal of :func:`plane_scene`'s plane."""
    if normal_up == "z":
        return np.array([0.0, 0.0, 1.0])
    return np.array([np.sin(np.radians(tilt)), np.cos(np.radians(tilt)), 0.0])


def sphere_scene(size: int = 8, rho: float = RHO, distance: float = 1.6, fov: float = 40.0, max_depth: int = -1,
                 emitters=(), subdivisions: int = 2) -> Scene:
    """A one-sided diffuse unit sphere at the origin (an icosphere: a convex polyhedron) seen from ``distance``."""
    shape = Shape(index=0, name="ball", type="sphere", material="grey", to_world=np.eye(4),
                  subdivisions=subdivisions)
    camera = Camera(origin=(0.0, 0.0, distance), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=fov)
    return Scene(name="ball", description="", camera=camera, film=Film(size, size, "box"), max_depth=max_depth,
                 materials={"grey": Material("grey", (rho, rho, rho))}, shapes=[shape], path=Path("ball.toml"),
                 emitters=tuple(emitters))


def open_box_scene(size: int = 8, rho: float = 1.0, max_depth: int = -1, emitters=()) -> Scene:
    """Five two-sided faces of the cube [-1, 1]^3 (no top: open toward +z), seen from above through the opening."""
    faces = []
    for name, rotation, offset in (("floor", np.eye(4), (0, 0, -1)),
                                   ("left", rotate_matrix((0, 1, 0), 90), (-1, 0, 0)),
                                   ("right", rotate_matrix((0, 1, 0), -90), (1, 0, 0)),
                                   ("back", rotate_matrix((1, 0, 0), -90), (0, 1, 0)),
                                   ("front", rotate_matrix((1, 0, 0), 90), (0, -1, 0))):
        faces.append(Shape(index=len(faces), name=name, type="rectangle", material="white",
                           to_world=translate_matrix(offset) @ rotation))
    camera = Camera(origin=(0.0, 0.0, 4.5), target=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov=22.0)
    return Scene(name="open-box", description="", camera=camera, film=Film(size, size, "box"), max_depth=max_depth,
                 materials={"white": Material("white", (rho, rho, rho), two_sided=True)}, shapes=faces,
                 path=Path("open-box.toml"), emitters=tuple(emitters))


def point(position, intensity) -> PointLight:
    return PointLight(index=0, name="point", position=tuple(map(float, position)), intensity=tuple(intensity))


def spot(position, target, intensity, cutoff_angle: float, beam_width: float) -> SpotLight:
    """A spot at ``position`` whose axis (local +z) points at ``target``."""
    p, t = np.asarray(position, float), np.asarray(target, float)
    z = (t - p) / np.linalg.norm(t - p)
    helper = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    to_world = np.eye(4)
    to_world[:3, 0], to_world[:3, 1], to_world[:3, 2], to_world[:3, 3] = x, y, z, p
    return SpotLight(index=0, name="spot", to_world=to_world, intensity=tuple(intensity), cutoff_angle=cutoff_angle,
                     beam_width=beam_width)


def directional(direction, irradiance) -> DirectionalLight:
    return DirectionalLight(index=0, name="sun", direction=tuple(map(float, direction)), irradiance=tuple(irradiance))


def constant(radiance) -> ConstantEnvironment:
    return ConstantEnvironment(index=0, name="sky", radiance=tuple(radiance))


def envmap(image: np.ndarray, to_world: np.ndarray | None = None, scale: float = 1.0) -> EnvironmentMap:
    return EnvironmentMap(index=0, name="envmap", file=Path("sky.exr"), image=np.asarray(image, np.float32),
                          to_world=np.eye(4) if to_world is None else to_world, scale=scale)


def sun_sky_map(width: int = 32, height: int = 16, sun_uv=(0.3, 0.3), sun: float = 2000.0) -> np.ndarray:
    """A procedural lat-long map: a sky brighter toward v = 0 (up), bluish, asymmetric in u, and a sharp sun of one
    texel ``sun`` times brighter than the sky at ``sun_uv``."""
    v = (np.arange(height) / (height - 1))[:, None]
    u = ((np.arange(width) + 0.5) / width)[None, :]
    sky = 0.2 + 0.8 * (1 - v) + 0.3 * np.sin(2 * np.pi * u) ** 2 * (u < 0.5)
    image = np.stack([0.6 * sky, 0.8 * sky, 1.0 * sky], axis=-1)
    i, j = int(round(sun_uv[1] * (height - 1))), int(sun_uv[0] * width)
    image[i, j] = sun * np.array([1.0, 0.9, 0.7])
    return image.astype(np.float32)


def with_emitters(scene: Scene, *emitters) -> Scene:
    return dataclasses.replace(scene, emitters=tuple(
        dataclasses.replace(e, index=i) for i, e in enumerate(emitters)))


# ---------------------------------------------------------------------------------------------- closed forms


def plane_hits(scene: Scene, nodes: int = 8):
    """For each pixel of ``scene``'s film, Gauss-Legendre nodes over the pixel (box filter) and where their viewing
    rays hit the plane z = 0 (or y = 0): (points (H, W, n, 3), weights (n,) summing to 1)."""
    film, camera = scene.film, scene.camera
    g, w = np.polynomial.legendre.leggauss(nodes)
    g, w = 0.5 * (g + 1.0), 0.5 * w
    gx, gy = np.meshgrid(g, g)
    wx, wy = np.meshgrid(w, w)
    weights = (wx * wy).reshape(-1)
    px, py = np.meshgrid(np.arange(film.width), np.arange(film.height))
    fx = (px[..., None] + gx.reshape(-1)).reshape(-1)
    fy = (py[..., None] + gy.reshape(-1)).reshape(-1)
    origins, dirs = camera.generate_rays(fx, fy, film.width, film.height)
    axis = 2 if abs(dirs[0, 2]) > abs(dirs[0, 1]) else 1
    t = -origins[:, axis] / dirs[:, axis]
    points = origins + t[:, None] * dirs
    return points.reshape(film.height, film.width, -1, 3), weights


def point_on_plane(scene: Scene, position, intensity, rho: float = RHO, inverse_square: bool = True) -> np.ndarray:
    """rho / pi I cos / r^2 over each pixel of the plane z = 0 under a point light (H, W, 3)."""
    points, weights = plane_hits(scene)
    d = np.asarray(position, float) - points
    r2 = np.sum(d * d, axis=-1)
    cos = d[..., 2] / np.sqrt(r2)
    value = rho / np.pi * np.maximum(cos, 0) / (r2 if inverse_square else 1.0)
    return (value @ weights)[..., None] * np.asarray(intensity, float)


def spot_on_plane(scene: Scene, light: SpotLight, rho: float = RHO, ignore_beam: bool = False) -> np.ndarray:
    """rho / pi I s(theta) cos / r^2 over each pixel of the plane z = 0 under a spot light (H, W, 3)."""
    points, weights = plane_hits(scene)
    p = light.position
    d = p - points
    r2 = np.sum(d * d, axis=-1)
    cos = d[..., 2] / np.sqrt(r2)
    theta = np.degrees(np.arccos(np.clip(np.sum(-d * light.axis, axis=-1) / np.sqrt(r2), -1, 1)))
    c, b = light.cutoff_angle, light.beam_width
    falloff = np.where(theta <= b, 1.0, np.clip((c - theta) / (c - b), 0.0, 1.0))
    if ignore_beam:
        falloff = (theta < c).astype(float)
    value = rho / np.pi * np.maximum(cos, 0) * falloff / r2
    return (value @ weights)[..., None] * np.asarray(light.intensity, float)


def envmap_on_plane(emitter: EnvironmentMap, normal, rho: float = RHO, n: int = 1024) -> np.ndarray:
    """rho / pi int L(w) max(0, n . w) dw: the radiance of an unoccluded diffuse plane of normal ``n`` under an
    envmap (the same at every point), by a midpoint rule over (u, v) on the map's bilinear radiance (RGB)."""
    emitters = Emitters([core_record(emitter)])
    u = (np.arange(2 * n) + 0.5) / (2 * n)
    v = (np.arange(n) + 0.5) / n
    uu, vv = np.meshgrid(u, v)
    local = uv_to_direction(uu.ravel(), vv.ravel())
    world = local @ emitters.to_world[0].T
    cos = np.maximum(world @ np.asarray(normal, float), 0.0)
    weight = cos * 2 * np.pi**2 * np.sin(np.pi * vv.ravel()) / (2 * n * n)
    return rho / np.pi * (environment_radiance(emitters, world).T @ weight)
