"""The standard chi^2 tests of ``reference_impl``'s warps, light sampling and pixel filters (test fixtures).

The machinery is the library module :mod:`harness.judges.chi2`; this module holds what is specific to
``reference_impl``: the samplers under test, the light and triangle fixtures they run on, and the *standard set*
(:func:`standard_cases`). ``tests/reference_impl/test_sampling_chi2.py`` runs and asserts the set, and :func:`standard_p_values`
returns its p-values for any script that wants to quote them (``python tests/reference_impl/chi2_cases.py`` prints them; from a
script: ``sys.path.insert(0, "tests/reference_impl"); import chi2_cases``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from harness.judges.chi2 import (
    FAMILY_ALPHA,
    SPHERE_COS_PHI,
    Chi2Result,
    chi2_test_1d,
    chi2_test_2d,
    chi2_test_discrete,
    directions_to_cos_phi,
    sidak_alpha,
    to_local,
)
from reference_impl import rng, sampling
from reference_impl.filters import make_filter
from reference_impl.geometry import Geometry
from reference_impl.lights import LightSampler, TriangleAreaSampler, cone_points, sphere_cone
from reference_impl.sampling import hemisphere_pdf, sample_hemisphere, square_to_uniform_triangle

# ------------------------------------------------------------------------------ standard set (reference_impl)
#
# Each case draws its uniforms from a fixed seed, so the p-values are reproducible numbers, not a lottery.

N_SAMPLES = 1_000_000
HEMI_RES = (64, 64)  # over SPHERE_COS_PHI: 32 bins of cos theta per hemisphere


def _uniforms(seed: int, n: int, k: int) -> list[np.ndarray]:
    g = np.random.default_rng(seed)
    return [g.random(n) for _ in range(k)]


def _warp_case(name: str, kind: str, seed: int) -> Chi2Result:
    warp = sampling.square_to_cosine_hemisphere if kind == "cosine" else sampling.square_to_uniform_hemisphere
    return chi2_test_2d(
        lambda n: directions_to_cos_phi(warp(*_uniforms(seed, n, 2))),
        lambda c, phi: sampling.hemisphere_pdf(kind, c), SPHERE_COS_PHI, HEMI_RES, N_SAMPLES, name=name,
    )


def hemisphere_world_sampler(kind: str, normal: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """``sample_hemisphere`` about one ``normal`` (repeated), returned in the local frame of that normal."""
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    world, _, _ = sample_hemisphere(kind, u1, u2, np.repeat(normal[None, :], len(u1), axis=0))
    return to_local(world, normal)


HEMISPHERE_NORMALS = {
    "a": (0.3, -0.5, 0.81),
    "b": (-0.6, 0.7, -0.2),
    "c": (0.02, -0.03, -0.95),  # near -z, the branch Duff et al.'s frame switches on
}


def _world_case(name: str, kind: str, normal, seed: int) -> Chi2Result:
    return chi2_test_2d(
        lambda n: directions_to_cos_phi(hemisphere_world_sampler(kind, normal, *_uniforms(seed, n, 2))),
        lambda c, phi: hemisphere_pdf(kind, c), SPHERE_COS_PHI, HEMI_RES, N_SAMPLES, name=name,
    )


# The integrator's random dimensions for the indirect direction and the film offset (reference_impl.integrator).
INDIRECT_U1, INDIRECT_U2, FILM_X, FILM_Y = 9, 10, 0, 1


def keyed_uniforms(seed: int, n: int, dims: Sequence[int], branch: int | None = None, depth: int = 0):
    """Uniforms from ``reference_impl.rng``: path keys for path ids 0 .. n-1, optionally a branch's keys."""
    keys = rng.path_keys(seed, np.arange(n, dtype=np.uint64))
    if branch is not None:
        keys = rng.branch_keys(keys, branch, depth)
    return [rng.uniform(keys, d) for d in dims]


def _keyed_hemisphere_case(name: str, seed: int) -> Chi2Result:
    depth = 2
    dims = (rng.dimension(depth, INDIRECT_U1), rng.dimension(depth, INDIRECT_U2))
    normal = HEMISPHERE_NORMALS["a"]
    return chi2_test_2d(
        lambda n: directions_to_cos_phi(
            hemisphere_world_sampler("cosine", normal, *keyed_uniforms(seed, n, dims, branch=1, depth=depth))
        ),
        lambda c, phi: hemisphere_pdf("cosine", c), SPHERE_COS_PHI, HEMI_RES, N_SAMPLES, name=name,
    )


def _keyed_square_case(name: str, seed: int) -> Chi2Result:
    """The pair of film dimensions straight: (u_x, u_y) must be uniform on the unit square."""
    dims = (rng.dimension(0, FILM_X), rng.dimension(0, FILM_Y))
    return chi2_test_2d(
        lambda n: keyed_uniforms(seed, n, dims), lambda x, y: np.ones_like(x), ((0, 1), (0, 1)), (64, 64),
        N_SAMPLES, name=name, order=1,
    )


# A skewed triangle in the plane (no axis-aligned or 45-degree edges, so no edge runs along bin nodes).
TRIANGLE_2D = np.array([[0.13, 0.21], [1.37, 0.52], [0.46, 1.19]])


def triangle_pdf(tri: np.ndarray, tol: float = 1e-12) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """1 / area inside the 2D triangle ``tri`` (3, 2), 0 outside."""
    a, b, c = tri
    e1, e2 = b - a, c - a
    det = e1[0] * e2[1] - e1[1] * e2[0]
    area = 0.5 * abs(det)

    def pdf(x, y):
        px, py = x - a[0], y - a[1]
        b1 = (px * e2[1] - py * e2[0]) / det
        b2 = (e1[0] * py - e1[1] * px) / det
        inside = (b1 >= -tol) & (b2 >= -tol) & (b1 + b2 <= 1 + tol)
        return np.where(inside, 1.0 / area, 0.0)

    return pdf


def bbox(points: np.ndarray) -> tuple[tuple[float, float], ...]:
    return tuple((float(lo), float(hi)) for lo, hi in zip(points.min(axis=0), points.max(axis=0)))


def triangle_sampler(tri: np.ndarray, warp: Callable | None = None, seed: int = 0):
    """Points A + b1 (B - A) + b2 (C - A) of a 2D triangle from ``warp`` (default square_to_uniform_triangle)."""
    warp = warp or square_to_uniform_triangle

    def sample(n):
        b1, b2 = warp(*_uniforms(seed, n, 2))
        p = tri[0] + b1[:, None] * (tri[1] - tri[0]) + b2[:, None] * (tri[2] - tri[0])
        return p[:, 0], p[:, 1]

    return sample


def _triangle_case(name: str, seed: int) -> Chi2Result:
    return chi2_test_2d(
        triangle_sampler(TRIANGLE_2D, seed=seed), triangle_pdf(TRIANGLE_2D), bbox(TRIANGLE_2D), (48, 48),
        N_SAMPLES, name=name, quadrature="midpoint", order=24,
    )


def rotation(axis, angle: float) -> np.ndarray:
    """Rodrigues rotation matrix about ``axis`` by ``angle`` radians."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


@dataclass(frozen=True)
class PlanarLight:
    """A light polygon given in 2D plane coordinates, placed in 3D by ``origin + R @ (x, y, 0)``."""

    polygon: np.ndarray  # (m, 2) convex, counter-clockwise
    triangles: np.ndarray  # (t, 3) indices into polygon
    R: np.ndarray
    origin: np.ndarray

    def vertices3d(self) -> np.ndarray:
        p = np.column_stack([self.polygon, np.zeros(len(self.polygon))])
        return self.origin + p @ self.R.T

    def to_plane(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, out-of-plane offset) of 3D points."""
        q = (pts - self.origin) @ self.R
        return q[:, 0], q[:, 1], q[:, 2]

    def triangle_areas(self) -> np.ndarray:
        """Areas of the triangles, from the 2D polygon (independently of Geometry.area)."""
        a, b, c = (self.polygon[self.triangles[:, i]] for i in range(3))
        return 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))

    def area(self) -> float:
        x, y = self.polygon[:, 0], self.polygon[:, 1]
        return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))

    def inside(self, x: np.ndarray, y: np.ndarray, tol: float = 1e-12) -> np.ndarray:
        ok = np.ones(np.shape(x), bool)
        m = len(self.polygon)
        for i in range(m):
            a, b = self.polygon[i], self.polygon[(i + 1) % m]
            ok &= (b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]) >= -tol
        return ok


def light_geometry(lights: Sequence[tuple[PlanarLight, Sequence[float]]], floor: bool = True):
    """A :class:`reference_impl.geometry.Geometry` of the given (light, radiance) pairs plus a grey floor.

    Triangles of different lights are interleaved in the arrays (and the floor put first), so that the light
    sampler's grouping by ``light_id`` is exercised. Returns the geometry and, per triangle, its row in its light's
    ``triangles`` (-1 for the floor).
    """
    verts, tris, emission, light_id, local = [], [], [], [], []
    if floor:
        verts += [[-5, -5, -1], [5, -5, -1], [5, 5, -1]]
        tris.append([0, 1, 2])
        emission.append([0, 0, 0])
        light_id.append(-1)
        local.append(-1)
    per_light = []
    for k, (light, le) in enumerate(lights):
        base = len(verts)
        verts += light.vertices3d().tolist()
        per_light.append([(list(base + t), list(le), k) for t in light.triangles])
    for j in range(max(len(p) for p in per_light)):  # round robin over the lights
        for p in per_light:
            if j < len(p):
                tris.append(p[j][0])
                emission.append(p[j][1])
                light_id.append(p[j][2])
                local.append(j)
    t = len(tris)
    geometry = Geometry(
        vertices=np.array(verts, float), triangles=np.array(tris), material=np.zeros(t, int),
        reflectance=np.array([[0.5, 0.5, 0.5]]), two_sided=np.array([False]), emission=np.array(emission, float),
        light_id=np.array(light_id),
    )
    return geometry, np.array(local)


def rectangle_light() -> PlanarLight:
    """A 0.7 x 0.3 rectangle (the unit square scaled), two triangles, tilted and rotated in 3D (a parallelogram:
    the light sampler takes it as one piece)."""
    poly = np.array([[0.0, 0.0], [0.7, 0.0], [0.7, 0.3], [0.0, 0.3]])
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    return PlanarLight(poly, tris, rotation([0.4, -1.0, 0.7], 1.1), np.array([0.2, 1.5, 0.9]))


def parallelogram_light() -> PlanarLight:
    """A skewed parallelogram (edges 0.8 and 0.5 at 53 degrees, no edge along a bin line), split along its other
    diagonal (1-3) than :func:`rectangle_light`'s, tilted and rotated in 3D: one piece for the light sampler."""
    e1, e2 = np.array([0.8, 0.0]), 0.5 * np.array([np.cos(np.radians(53.0)), np.sin(np.radians(53.0))])
    poly = np.array([[0.05, 0.02], [0.05, 0.02] + e1, [0.05, 0.02] + e1 + e2, [0.05, 0.02] + e2])
    tris = np.array([[1, 2, 3], [1, 3, 0]])
    return PlanarLight(poly, tris, rotation([-0.7, 0.3, 0.5], 0.8), np.array([-0.3, 0.4, 1.7]))


def fan_light() -> PlanarLight:
    """A convex hexagon on an ellipse, fanned from one vertex into 4 triangles of very unequal areas."""
    ang = np.radians([0.0, 17.0, 103.0, 148.0, 236.0, 322.0])
    poly = np.column_stack([0.8 * np.cos(ang), 0.45 * np.sin(ang)])
    tris = np.array([[0, i, i + 1] for i in range(1, len(poly) - 1)])
    return PlanarLight(poly, tris, rotation([-0.3, 0.2, 1.0], 2.3), np.array([-0.4, 0.1, 2.0]))


def light_point_sampler(geometry, light: PlanarLight, seed: int, selection: str = "power", reuse: bool = False):
    """Points from ``LightSampler(geometry, selection).sample`` in the plane coordinates of ``light``; with ``reuse``,
    from ``sample(*split_uniform(u1), u2)`` (the stratified sampler's one 2D sample per light sample)."""
    sampler = LightSampler(geometry, selection)

    def sample(n):
        if reuse:
            u1, u2 = _uniforms(seed, n, 2)
            k, pts = sampler.sample(*sampler.split_uniform(u1), u2)
        else:
            k, pts = sampler.sample(*_uniforms(seed, n, 4))
        x, y, z = light.to_plane(pts.position)
        if np.any(k != 0) or np.max(np.abs(z)) > 1e-9:
            return np.full(n, np.nan), np.full(n, np.nan)  # off the light: every sample out of domain
        return x, y

    def pdf(x, y):
        return np.where(light.inside(x, y), sampler.pdf_area(np.zeros(len(x), np.int64)), 0.0)

    return sampler, sample, pdf


def _light_points_case(name: str, light: PlanarLight, res, quadrature: str, order: int, seed: int,
                       reuse: bool = False, pieces: int | None = None) -> Chi2Result:
    geom, _ = light_geometry([(light, (4.0, 3.0, 2.0))])
    sampler, sample, pdf = light_point_sampler(geom, light, seed, reuse=reuse)
    if pieces is not None:  # the case is about a light sampled as one parallelogram (or as its triangles)
        assert sampler.count.tolist() == [pieces] and sampler.parallelogram.tolist() == [pieces == 1] * pieces
    return chi2_test_2d(sample, pdf, bbox(light.polygon), res, N_SAMPLES, name=name, quadrature=quadrature, order=order)


def _parallelogram_reuse_case(name: str, seed: int) -> Chi2Result:
    """The stratified sampler's one 2D sample per light sample, ``sample(*split_uniform(u1), u2)``, over
    :func:`parallelogram_light` and a brighter single triangle: the points that land on the parallelogram (light 0,
    chosen with pdf(0)) must be uniform over it, pdf(y | 0) = 1 / A_0, through both rescalings of u1."""
    light = parallelogram_light()
    other = PlanarLight(TRIANGLE_2D, np.array([[0, 1, 2]]), rotation([1, 0, 0], 0.4), np.array([0.5, -2.0, 1.0]))
    geom, _ = light_geometry([(light, (4.0, 3.0, 2.0)), (other, (9.0, 9.0, 9.0))])
    sampler = LightSampler(geom, "power")
    assert sampler.count.tolist() == [1, 1] and sampler.parallelogram.tolist() == [True, False]
    g = np.random.default_rng(seed)

    def sample(n):
        xs, ys, got = [], [], 0
        while got < n:  # the points on light 0, in the order drawn, until there are n
            u1, u2 = g.random(2 * n), g.random(2 * n)
            k, pts = sampler.sample(*sampler.split_uniform(u1), u2)
            x, y, z = light.to_plane(pts.position[k == 0])
            if np.max(np.abs(z)) > 1e-9:
                return np.full(n, np.nan), np.full(n, np.nan)
            xs.append(x)
            ys.append(y)
            got += len(x)
        return np.concatenate(xs)[:n], np.concatenate(ys)[:n]

    def pdf(x, y):
        return np.where(light.inside(x, y), 1.0 / sampler.area[0], 0.0)

    return chi2_test_2d(sample, pdf, bbox(light.polygon), (48, 32), N_SAMPLES, name=name, quadrature="midpoint",
                        order=24)


def fan_triangle_choices(seed: int, n: int = N_SAMPLES, mutate: Callable | None = None) -> np.ndarray:
    """Which triangle of :func:`fan_light` (its row in ``triangles``) ``LightSampler.sample`` picked, n times.
    ``mutate(sampler)`` may corrupt the sampler first (to prove the test can fail)."""
    geom, local = light_geometry([(fan_light(), (4.0, 3.0, 2.0))])
    sampler = LightSampler(geom, "power")
    if mutate is not None:
        mutate(sampler)
    _, pts = sampler.sample(*_uniforms(seed, n, 4))
    return local[pts.triangle]


def _fan_choice_case(name: str, seed: int) -> Chi2Result:
    areas = fan_light().triangle_areas()
    return chi2_test_discrete(fan_triangle_choices(seed), areas / areas.sum(), name=name)


def four_lights() -> list[tuple[PlanarLight, tuple[float, float, float]]]:
    """Four lights of different shapes, sizes and radiances (areas span ~40x, powers ~20x)."""
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    two = np.array([[0, 1, 2], [0, 2, 3]])
    return [
        (PlanarLight(np.array([[0.0, 0.0], [0.6, 0.1], [0.2, 0.5]]), np.array([[0, 1, 2]]), rotation([1, 0, 0], 0.3),
                     np.array([0.0, 0.0, 3.0])), (10.0, 10.0, 10.0)),
        (PlanarLight(sq * [1.2, 0.5], two, rotation([0, 1, 0], 2.0), np.array([1.0, 0.0, 2.0])), (1.0, 5.0, 0.2)),
        (fan_light(), (20.0, 0.5, 0.5)),
        (PlanarLight(sq * 0.15, two, rotation([1, 1, 0], 0.7), np.array([-1.0, 1.0, 2.5])), (0.3, 0.3, 30.0)),
    ]


LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709


def light_selection_samples(selection: str, seed: int, n: int = N_SAMPLES):
    """(LightSampler over :func:`four_lights`, chosen light indices, sampled triangles)."""
    sampler = LightSampler(light_geometry(four_lights())[0], selection)
    k, pts = sampler.sample(*_uniforms(seed, n, 4))
    return sampler, k, pts.triangle


def _selection_case(name: str, selection: str, seed: int) -> Chi2Result:
    sampler, k, _ = light_selection_samples(selection, seed)
    return chi2_test_discrete(k, sampler.pdf_select(np.arange(sampler.num_lights)), name=name)


def _global_area_case(name: str, seed: int) -> Chi2Result:
    """``TriangleAreaSampler`` over every triangle of the 4-light scene (floor included): choice vs area / total."""
    geom, _ = light_geometry(four_lights())
    corners = geom.vertices[geom.triangles]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    pts = TriangleAreaSampler(geom, np.arange(len(areas))).sample(*_uniforms(seed, N_SAMPLES, 3))
    return chi2_test_discrete(pts.triangle, areas / areas.sum(), name=name)


SPHERE_CENTER, SPHERE_RADIUS = np.array([0.7, -1.2, 2.5]), 0.6


def sphere_geometry(emits: bool = True, inward: bool = False, floor: bool = False) -> Geometry:
    """One analytic sphere (centre :data:`SPHERE_CENTER`, radius :data:`SPHERE_RADIUS`; its stand-in the 2-times
    subdivided icosphere, wound toward the front side, outside unless ``inward``), emitting 1 where ``emits``, and
    with ``floor`` a 4 x 4 square below it that does not emit."""
    from harness.scene.triangulate import unit_sphere

    vertices, triangles = unit_sphere(2)
    vertices = SPHERE_CENTER + SPHERE_RADIUS * np.asarray(vertices, float)
    triangles = np.asarray(triangles, np.int64)[:, ::-1] if inward else np.asarray(triangles, np.int64)
    t = len(triangles)
    to_world = np.diag([SPHERE_RADIUS, SPHERE_RADIUS, SPHERE_RADIUS, 1.0])
    to_world[:3, 3] = SPHERE_CENTER
    emission = np.ones((t, 3)) if emits else np.zeros((t, 3))
    light_id = np.zeros(t, np.int64) if emits else np.full(t, -1)
    sphere_of = np.zeros(t, np.int64)
    if floor:
        square = np.array([[-2.0, -2.0, 0.0], [2.0, -2.0, 0.0], [2.0, 2.0, 0.0], [-2.0, 2.0, 0.0]])
        triangles = np.vstack([triangles, len(vertices) + np.array([[0, 1, 2], [0, 2, 3]])])
        vertices = np.vstack([vertices, square])
        emission = np.vstack([emission, np.zeros((2, 3))])
        light_id = np.concatenate([light_id, [-1, -1]])
        sphere_of = np.concatenate([sphere_of, [-1, -1]])
    n = len(triangles)
    return Geometry(vertices=vertices, triangles=triangles, material=np.zeros(n, np.int64),
                    reflectance=np.array([[0.5, 0.5, 0.5]]), two_sided=np.array([False]), emission=emission,
                    light_id=light_id, sphere_of=sphere_of, sphere_to_object=np.linalg.inv(to_world)[None])


def sphere_cos_phi(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(z, phi) of points on the sphere of :func:`sphere_geometry`: z the cosine of the polar angle, phi in
    [0, 2 pi); NaN for a point off the sphere (by more than 1e-12 of the radius). A uniform point of the sphere has
    the density 1 / (4 pi) in (z, phi), which is 1 / (4 pi r^2) per unit area times the Jacobian r^2."""
    d = (points - SPHERE_CENTER) / SPHERE_RADIUS
    off = np.abs(np.linalg.norm(d, axis=1) - 1.0) > 1e-12
    z, phi = np.clip(d[:, 2], -1.0, 1.0), np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
    return np.where(off, np.nan, z), np.where(off, np.nan, phi)


def _sphere_light_case(name: str, seed: int, reuse: bool = False) -> Chi2Result:
    """``LightSampler`` on a sphere light: one piece, the sphere itself, its points uniform in area (pdf(y) =
    pdf_area = 1 / (4 pi r^2), i.e. 1 / (4 pi) in (z, phi)); with ``reuse``, from
    ``sample(*split_uniform(u1), u2)``."""
    sampler = LightSampler(sphere_geometry(), "power")
    assert sampler.sphere.tolist() == [True] and sampler.count.tolist() == [1]
    g = np.random.default_rng(seed)

    def sample(n):
        if reuse:
            u1, u2 = g.random(n), g.random(n)
            _k, pts = sampler.sample(*sampler.split_uniform(u1), u2)
        else:
            _k, pts = sampler.sample(g.random(n), g.random(n), g.random(n), g.random(n))
        return sphere_cos_phi(pts.position)

    def pdf(z, phi):
        return sampler.pdf_area(np.zeros(len(z), np.int64)) * SPHERE_RADIUS**2

    return chi2_test_2d(sample, pdf, [(-1.0, 1.0), (0.0, 2 * np.pi)], (24, 48), N_SAMPLES, name=name,
                        quadrature="midpoint", order=4)


def cone_coordinates(points: np.ndarray, x: np.ndarray, center: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points y seen from x as (h, phi) about the axis (c - x) / |c - x|: h = 1 - cos theta = 2 sin^2(theta / 2)
    (from atan2, exact for a far sphere's thin cone), phi in [0, 2 pi) in the frame of ``sampling.coordinate_frame``.
    A solid angle is dh dphi."""
    axis = (center - x) / np.linalg.norm(center - x)
    s, t = sampling.coordinate_frame(axis[None, :])
    w = points - x
    w /= np.linalg.norm(w, axis=1)[:, None]
    along = w @ axis
    across = np.linalg.norm(np.cross(w, axis), axis=1)
    theta = np.arctan2(across, along)
    phi = np.mod(np.arctan2(w @ t[0], w @ s[0]), 2 * np.pi)
    return 2.0 * np.sin(0.5 * theta) ** 2, phi


def _sphere_cone_case(name: str, seed: int, distance: float) -> Chi2Result:
    """``lights.cone_points``: a sphere light seen from x at ``distance`` radii, its points uniform in the solid angle
    of the cone it subtends: p(w) = 1 / (2 pi (1 - cos theta_max)), the routine's own density, in (h, phi)."""
    x = SPHERE_CENTER + distance * SPHERE_RADIUS * np.array([0.6, -0.8, 0.0])
    g = np.random.default_rng(seed)
    one = (SPHERE_CENTER[None, :], np.array([SPHERE_RADIUS]), x[None, :])
    _d2, _s2, one_minus = sphere_cone(*one)
    density = cone_points(*one, np.array([0.5]), np.array([0.5]))[1][0]

    def sample(n):
        pts, pdf = cone_points(np.repeat(SPHERE_CENTER[None, :], n, axis=0), np.full(n, SPHERE_RADIUS),
                               np.repeat(x[None, :], n, axis=0), g.random(n), g.random(n))
        assert np.all(pdf == density)
        return cone_coordinates(pts, x, SPHERE_CENTER)

    return chi2_test_2d(sample, lambda h, phi: np.full(len(h), density), [(0.0, float(one_minus[0])), (0.0, 2 * np.pi)],
                        (24, 48), N_SAMPLES, name=name, quadrature="midpoint", order=4)


def _global_area_sphere_case(name: str, seed: int) -> Chi2Result:
    """``TriangleAreaSampler`` over a sphere and a square floor: the sphere is one entry of area 4 pi r^2, chosen
    against the floor's two triangles by area / total."""
    geom = sphere_geometry(emits=False, floor=True)
    sampler = TriangleAreaSampler(geom, np.arange(len(geom.triangles)))
    assert sampler.triangles.tolist() == [0, len(geom.triangles) - 2, len(geom.triangles) - 1]
    pts = sampler.sample(*_uniforms(seed, N_SAMPLES, 3))
    choice = np.searchsorted(sampler.triangles, pts.triangle)
    areas = np.array([4 * np.pi * SPHERE_RADIUS**2, 8.0, 8.0])
    return chi2_test_discrete(choice, areas / areas.sum(), name=name)


def _filter_case(name: str, filt: str, res: int, quadrature: str, order: int, seed: int) -> Chi2Result:
    f = make_filter(filt)
    return chi2_test_1d(
        lambda n: f.sample_1d(_uniforms(seed, n, 1)[0])[0], f.pdf_1d, (-f.radius, f.radius), res, N_SAMPLES,
        name=name, quadrature=quadrature, order=order,
    )


def standard_cases() -> dict[str, Callable[[], Chi2Result]]:
    """The standard chi^2 tests of reference_impl, by name; each call runs one test (about 10^6 samples)."""
    cases: dict[str, Callable[[], Chi2Result]] = {
        "cosine_warp": lambda: _warp_case("cosine_warp", "cosine", 101),
        "uniform_warp": lambda: _warp_case("uniform_warp", "uniform", 102),
    }
    for i, (label, normal) in enumerate(HEMISPHERE_NORMALS.items()):
        for j, kind in enumerate(("cosine", "uniform")):
            nm = f"sample_hemisphere_{kind}_n{label}"
            cases[nm] = lambda nm=nm, kind=kind, normal=normal, s=200 + 10 * i + j: _world_case(nm, kind, normal, s)
    cases["keyed_rng_hemisphere_cosine"] = lambda: _keyed_hemisphere_case("keyed_rng_hemisphere_cosine", 301)
    cases["keyed_rng_film_square"] = lambda: _keyed_square_case("keyed_rng_film_square", 302)
    cases["uniform_triangle"] = lambda: _triangle_case("uniform_triangle", 401)
    cases["light_rectangle_points"] = lambda: _light_points_case(
        "light_rectangle_points", rectangle_light(), (56, 24), "gauss", 2, 501, pieces=1
    )
    cases["light_parallelogram_points"] = lambda: _light_points_case(
        "light_parallelogram_points", parallelogram_light(), (48, 32), "midpoint", 24, 505, pieces=1
    )
    cases["light_parallelogram_points_reused_uniform"] = lambda: _parallelogram_reuse_case(
        "light_parallelogram_points_reused_uniform", 506
    )
    cases["light_fan_points"] = lambda: _light_points_case(
        "light_fan_points", fan_light(), (48, 32), "midpoint", 24, 502
    )
    cases["light_fan_points_reused_uniform"] = lambda: _light_points_case(
        "light_fan_points_reused_uniform", fan_light(), (48, 32), "midpoint", 24, 504, reuse=True
    )
    cases["light_fan_triangle_choice"] = lambda: _fan_choice_case("light_fan_triangle_choice", 503)
    cases["light_select_power"] = lambda: _selection_case("light_select_power", "power", 601)
    cases["light_select_uniform"] = lambda: _selection_case("light_select_uniform", "uniform", 602)
    cases["global_area_triangle_choice"] = lambda: _global_area_case("global_area_triangle_choice", 603)
    cases["light_sphere_points"] = lambda: _sphere_light_case("light_sphere_points", 507)
    cases["light_sphere_points_reused_uniform"] = lambda: _sphere_light_case("light_sphere_points_reused_uniform",
                                                                             508, reuse=True)
    cases["global_area_sphere_choice"] = lambda: _global_area_sphere_case("global_area_sphere_choice", 604)
    cases["light_sphere_cone"] = lambda: _sphere_cone_case("light_sphere_cone", 509, 1.7)
    cases["light_sphere_cone_far"] = lambda: _sphere_cone_case("light_sphere_cone_far", 510, 3000.0)
    cases["filter_tent"] = lambda: _filter_case("filter_tent", "tent", 100, "gauss", 4, 701)
    cases["filter_gaussian"] = lambda: _filter_case("filter_gaussian", "gaussian", 128, "midpoint", 16, 702)
    return cases


STANDARD_NAMES = tuple(standard_cases())
STANDARD_ALPHA = sidak_alpha(len(STANDARD_NAMES))


def standard_results() -> list[Chi2Result]:
    return [run() for run in standard_cases().values()]


def standard_p_values() -> dict[str, float]:
    """p-value of every test of the standard set, by name (compare each with :data:`STANDARD_ALPHA`)."""
    return {r.name: r.p_value for r in standard_results()}


if __name__ == "__main__":
    print(f"alpha per test = {STANDARD_ALPHA:.3g} (family {FAMILY_ALPHA:g} over {len(STANDARD_NAMES)} tests)")
    for r in standard_results():
        print(r.line(), "ok" if r.passed(STANDARD_ALPHA) else "FAIL: " + "; ".join(r.failures(STANDARD_ALPHA)))
