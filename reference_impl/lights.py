"""Sampling points on lights: light selection pdf(k) and point sampling pdf(y|k) (slides, Fig. 5.8 and 5.10),
and sampling points on all surfaces of the scene (global area sampling, Fig. 5.13).

A light k is one emissive shape: a set of triangles sharing ``Geometry.light_id == k``. A point on it is drawn by
picking one of its pieces with probability area / A_k and a uniform point on that piece, so pdf(y | k) = 1 / A_k for
every point of the light. A piece is a triangle, or, for a light of exactly two triangles that form a planar
parallelogram (a rectangle light), the whole parallelogram (:func:`parallelogram_frame`):

    triangle       y = c0 + b1 (c1 - c0) + b2 (c2 - c0),  b1 = 1 - sqrt(u1), b2 = u2 sqrt(u1)
                   (sampling.square_to_uniform_triangle)
    parallelogram  y = p0 + u1 e1 + u2 e2  (p0 one corner, e1 and e2 its two edges; Jacobian |e1 x e2| = A_k)

One piece for a rectangle keeps a stratified (u1, u2) stratified over the whole rectangle: split into two triangles
(one uniform picking the triangle, the sqrt warp in each) the strata of the net are folded and stretched. A sphere
(``Geometry.sphere_of``) is one piece, the sphere itself, of area A = 4 pi r^2:

    sphere         y = c + r (sqrt(1 - z^2) cos phi, sqrt(1 - z^2) sin phi, z),  z = 1 - 2 u1, phi = 2 pi u2

(uniform in area: Archimedes' hat-box theorem; Mitsuba's ``square_to_uniform_sphere``). The path loops sample a
sphere light seen from a point x outside it by the cone it subtends instead (:func:`cone_points`, as Mitsuba's
``sphere`` and pbrt-v4's ``Sphere::Sample`` do): every point of the cone's cap is one x can see, where half the
sphere's area faces away from x. With D = |c - x| and sin^2 theta_max = r^2 / D^2,

    1 - cos theta_max = sin^2 theta_max / (1 + cos theta_max)     (no cancellation for a far sphere)
    1 - cos theta     = u1 (1 - cos theta_max),  phi = 2 pi u2     (uniform in the cone's solid angle)
    y                 = the nearer point of the sphere along x + t w, t = D (cos theta - sqrt(sin^2 theta_max -
                        sin^2 theta)), w the direction (theta, phi) about (c - x) / D; taken back onto the sphere,
                        c + r (y - c) / |y - c|
    p(w)              = 1 / (2 pi (1 - cos theta_max))  per unit solid angle at x

A sphere light whose emission faces inward (``Geometry.sphere_inward``), or an x on or inside the sphere, keeps the
area sampling above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reference_impl.geometry import Geometry
from reference_impl.sampling import sample_discrete, square_to_uniform_triangle, to_world, unit_circle

LIGHT_SELECTIONS = ("power", "uniform", "tree")

# Luminance weights of linear sRGB / Rec. 709 primaries (the scalar "power" of an RGB radiance).
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class SurfacePoints:
    """Points sampled on triangles, with what the estimators need of them."""

    triangle: np.ndarray  # (n,) triangle index
    position: np.ndarray  # (n, 3)
    normal: np.ndarray  # (n, 3) unit geometric normal (front side)
    pdf_area: np.ndarray  # (n,) density per unit area of the whole sampling procedure


def sphere_points(center: np.ndarray, radius: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Uniform points of spheres (centres (n, 3), radii (n,)): c + r (sqrt(1 - z^2) cos phi, sqrt(1 - z^2) sin phi,
    z), z = 1 - 2 u1, phi = 2 pi u2."""
    z = 1.0 - 2.0 * u1
    rho = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    cos_phi, sin_phi = unit_circle(u2)  # phi = 2 pi u2
    return center + radius[:, None] * np.stack([rho * cos_phi, rho * sin_phi, z], axis=1)


def sphere_cone(center: np.ndarray, radius: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cones that spheres (centres (n, 3), radii (n,)) subtend from points x (n, 3): (D^2 = |c - x|^2,
    sin^2 theta_max = r^2 / D^2, 1 - cos theta_max = sin^2 theta_max / (1 + cos theta_max)), the last 0 where x is
    not outside its sphere (no cone)."""
    w = center - x
    d2 = w[:, 0] * w[:, 0] + w[:, 1] * w[:, 1] + w[:, 2] * w[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s2 = (radius * radius) / d2
    outside = s2 < 1.0
    cos_max = np.sqrt(np.where(outside, 1.0 - s2, 0.0))
    return d2, s2, np.where(outside, s2 / (1.0 + cos_max), 0.0)


def cone_points(center: np.ndarray, radius: np.ndarray, x: np.ndarray, u1: np.ndarray,
                u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points of spheres (centres (n, 3), radii (n,)) uniform in the solid angle of the cone each subtends from x
    (n, 3), all outside their spheres (module docstring): (the points y (n, 3), p(w) = 1 / (2 pi (1 - cos
    theta_max)) per unit solid angle at x)."""
    d2, s2, one_minus = sphere_cone(center, radius, x)
    h = u1 * one_minus  # 1 - cos theta
    cos_t = 1.0 - h
    sin2 = h * (2.0 - h)
    sin_t = np.sqrt(np.maximum(0.0, sin2))
    cos_phi, sin_phi = unit_circle(u2)  # phi = 2 pi u2
    d = np.sqrt(d2)
    axis = (center - x) / d[:, None]
    w = to_world(np.stack([sin_t * cos_phi, sin_t * sin_phi, cos_t], axis=1), axis)
    t = d * (cos_t - np.sqrt(np.maximum(0.0, s2 - sin2)))
    m = x + t[:, None] * w - center
    scale = radius / np.sqrt(m[:, 0] * m[:, 0] + m[:, 1] * m[:, 1] + m[:, 2] * m[:, 2])
    return center + m * scale[:, None], (0.5 * (1.0 / np.pi)) / one_minus


def front_normals(geometry: Geometry, tri: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """The unit front normal at points ``pos`` of triangles ``tri``: the triangle's, or on a sphere's triangle the
    sphere's at the point, side (y - c) / |y - c| (kernels.surface.normal_at)."""
    normal = geometry.normal[tri].copy()
    if geometry.num_spheres:
        s = geometry.sphere_of[tri]
        on = s >= 0
        m = pos[on] - geometry.sphere_center[s[on]]
        side = np.where(geometry.sphere_inward[s[on]], -1.0, 1.0)
        normal[on] = m * (side / np.linalg.norm(m, axis=1))[:, None]
    return normal


def _uniform_point_on(geometry: Geometry, tri: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    b1, b2 = square_to_uniform_triangle(u1, u2)
    c = geometry.corners[tri]
    return c[:, 0] + b1[:, None] * (c[:, 1] - c[:, 0]) + b2[:, None] * (c[:, 2] - c[:, 0])


PARALLELOGRAM_TOLERANCE = 1e-9  # relative: of the longest edge for the corners, absolute for the unit normals


def parallelogram_frame(geometry: Geometry, t0: int, t1: int) -> np.ndarray | None:
    """The frame (p0, e1, e2) of the parallelogram that triangles t0 and t1 form, or None where they do not form one.

    They form one where they share a diagonal (two corners at exactly the same positions, the opposite corners o0 of
    t0 and o1 of t1 distinct), |o0 + o1 - (s1 + s2)| <= 1e-9 x the longest edge (s1, s2 the shared corners: the
    diagonals bisect each other), both have area > 0, the same emission and unit normals within 1e-9 (a planar
    quad, not folded, both facing one way). Then p0 = o0, e1 = s1 - o0, e2 = s2 - o0, with (o0, s1, s2) in t0's
    winding (e1 x e2 along t0's normal); the point p0 + a e1 + b e2 lies in t0 where a + b <= 1, else in t1."""
    if not (geometry.area[t0] > 0 and geometry.area[t1] > 0):
        return None
    if not np.array_equal(geometry.emission[t0], geometry.emission[t1]):
        return None
    if not np.linalg.norm(geometry.normal[t0] - geometry.normal[t1]) <= PARALLELOGRAM_TOLERANCE:
        return None
    c0, c1 = geometry.corners[t0], geometry.corners[t1]
    shared = [(i, j) for i in range(3) for j in range(3) if np.array_equal(c0[i], c1[j])]
    if len(shared) != 2 or len({i for i, _ in shared}) != 2 or len({j for _, j in shared}) != 2:
        return None
    i0 = 3 - shared[0][0] - shared[1][0]  # the corner of t0 off the diagonal
    j0 = 3 - shared[0][1] - shared[1][1]
    o0, o1 = c0[i0], c1[j0]
    s1, s2 = c0[(i0 + 1) % 3], c0[(i0 + 2) % 3]
    longest = max(np.linalg.norm(a - b) for a, b in ((s1, o0), (s2, o0), (s1, s2), (s1, o1), (s2, o1)))
    if not np.linalg.norm(o0 + o1 - (s1 + s2)) <= PARALLELOGRAM_TOLERANCE * longest:
        return None
    return np.array([o0, s1 - o0, s2 - o0])


class TriangleAreaSampler:
    """Picks a triangle from a set with probability proportional to its area, then a uniform point on it. A sphere's
    triangles in the set are replaced by one entry, its first triangle, of area 4 pi r^2, whose point is uniform on
    the sphere (``sphere``: per entry its centre and radius, 0 for a triangle)."""

    def __init__(self, geometry: Geometry, triangles: np.ndarray):
        self.geometry = geometry
        triangles = np.asarray(triangles, dtype=np.int64)
        areas = geometry.area[triangles]
        self.sphere = np.zeros((len(triangles), 4))
        if geometry.num_spheres:
            which = geometry.sphere_of[triangles]
            keep = which < 0
            values, index = np.unique(which, return_index=True)
            keep[index[values >= 0]] = True  # each sphere's first entry
            triangles, which, areas = triangles[keep], which[keep], areas[keep]
            on = which >= 0
            triangles[on] = geometry.sphere_first[which[on]]
            areas = np.where(on, geometry.sphere_area[np.maximum(which, 0)], areas)
            self.sphere = np.zeros((len(triangles), 4))
            self.sphere[on, :3] = geometry.sphere_center[which[on]]
            self.sphere[on, 3] = geometry.sphere_radius[which[on]]
        self.triangles = triangles
        self.total_area = float(areas.sum())
        self.cdf = np.cumsum(areas) / self.total_area if self.total_area > 0 else np.ones(len(areas))

    def split_uniform(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One uniform for both the triangle and the point: (u_tri, u1) = (u, what is left of u inside the chosen
        triangle's cdf interval, :func:`rescale_within`). ``sample(*split_uniform(u), u2)`` is then one 2D sample, so
        a stratified (u, u2) stays stratified over the whole set, not only within each triangle."""
        index = sample_discrete(self.cdf, u)
        return u, rescale_within(u, np.where(index > 0, self.cdf[index - 1], 0.0), self.cdf[index])

    def sample(self, u_tri: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> SurfacePoints:
        """Points with pdf 1 / (total area of the set)."""
        entry = sample_discrete(self.cdf, u_tri)
        tri = self.triangles[entry]
        pos = _uniform_point_on(self.geometry, tri, u1, u2)
        on = self.sphere[entry, 3] > 0
        pos[on] = sphere_points(self.sphere[entry[on], :3], self.sphere[entry[on], 3], u1[on], u2[on])
        pdf = np.full(len(tri), 1.0 / self.total_area)
        return SurfacePoints(tri, pos, front_normals(self.geometry, tri, pos), pdf)


class LightSampler:
    """Light selection with pdf(k) ("power": proportional to Phi_k = pi A_k lum(Le_k); "uniform": 1 / N_L; "tree":
    pdf(k | x) from the light tree at the shading point, :mod:`reference_impl.light_tree`, ``tree``, whose area
    lights' ``pmf`` is NaN: only the kernels choose by it) and a point y on light k with pdf(y | k) = 1 / A_k. The
    combined density per unit area is pdf(k) / A_k. A sphere light whose emission faces outward is also listed in
    ``cone`` (its centre and radius; zeros for every other light): the path loops draw its point from a shading point
    outside it by the cone it subtends (:func:`cone_points`).

    Within light k the table has one entry per piece (``first[k]``, ``count[k]``, ``within_cdf``: a triangle, or a
    whole parallelogram, :func:`parallelogram_frame`), each with a float64 frame (origin, edge 1, edge 2: c0, c1 - c0,
    c2 - c0 for a triangle, p0, e1, e2 for a parallelogram), its flag ``parallelogram`` and the triangles it covers:
    ``triangles`` (a triangle's own; the parallelogram's half a + b <= 1) and ``other`` (the same, or the other half).

    Lights k < ``num_area`` are the area lights (emissive shapes); with ``extra_power`` (the powers Phi of the
    emitters that are not surfaces, :meth:`reference_impl.emitters.Emitters.powers`) lights num_area + e follow, one
    per emitter e, chosen with the same pdf(k) (their points or directions are drawn by the integrator). Without
    them every table is what it was for area lights alone."""

    def __init__(self, geometry: Geometry, selection: str, extra_power: np.ndarray | None = None):
        self.geometry = geometry
        self.num_area = num_area = geometry.num_lights
        extra = np.zeros(0) if extra_power is None else np.asarray(extra_power, dtype=np.float64)
        self.num_lights = num_area + len(extra)
        emissive = np.flatnonzero(geometry.light_id >= 0)
        # Triangles sorted by light, then each light's cumulative-area table as one global array.
        order = emissive[np.argsort(geometry.light_id[emissive], kind="stable")]
        ids = geometry.light_id[order]
        self.area = np.bincount(ids, weights=geometry.area[order], minlength=num_area)  # A_k
        entries, other, frames, flags, cdfs, first, count, spheres = [], [], [], [], [], [], [], []
        for k in range(num_area):  # one pass per light, not per ray
            tris = order[np.searchsorted(ids, k):np.searchsorted(ids, k, side="right")]
            frame = parallelogram_frame(geometry, tris[0], tris[1]) if len(tris) == 2 else None
            sphere = geometry.sphere_of[tris[0]] if geometry.num_spheres else -1
            first.append(len(entries))
            spheres.extend([sphere >= 0] * (1 if sphere >= 0 or frame is not None else len(tris)))
            if sphere >= 0:  # the sphere itself (load: a light is one shape)
                self.area[k] = geometry.sphere_area[sphere]
                entries.append(geometry.sphere_first[sphere])
                other.append(geometry.sphere_first[sphere])
                frames.append([geometry.sphere_center[sphere], [geometry.sphere_radius[sphere], 0.0, 0.0],
                               [0.0, 0.0, 0.0]])
                flags.append(False)
                cdfs.append([1.0])
            elif frame is not None:
                entries.append(tris[0])
                other.append(tris[1])
                frames.append(frame)
                flags.append(True)
                cdfs.append([(geometry.area[tris[0]] + geometry.area[tris[1]]) / self.area[k]])
            else:
                c = geometry.corners[tris]
                entries.extend(tris)
                other.extend(tris)
                frames.extend(np.stack([c[:, 0], c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]], axis=1))
                flags.extend([False] * len(tris))
                cdfs.append(np.cumsum(geometry.area[tris]) / self.area[k])
            count.append(len(entries) - first[-1])
        self.triangles = np.array(entries, np.int64)  # per entry: the triangle (of a parallelogram: a + b <= 1)
        self.other = np.array(other, np.int64)  # per entry: the triangle where a + b > 1
        self.frames = np.array(frames, np.float64).reshape(-1, 3, 3)  # per entry: origin, edge 1, edge 2
        self.parallelogram = np.array(flags, bool)
        self.sphere = np.array(spheres, bool)  # per entry: a whole sphere, frame (c, (r, 0, 0), 0)
        self.first = np.array(first, np.int64)  # first entry of each light
        self.count = np.array(count, np.int64)  # entries of each light
        self.within_cdf = np.concatenate(cdfs) if cdfs else np.zeros(0)
        # per area light: the centre and radius of a sphere sampled by its cone from outside (emission outward), 0
        self.cone = np.zeros((num_area, 4))
        for k in np.flatnonzero(self.sphere[self.first]) if num_area else ():
            sphere = geometry.sphere_of[self.triangles[self.first[k]]]
            if not geometry.sphere_inward[sphere]:
                self.cone[k, :3] = geometry.sphere_center[sphere]
                self.cone[k, 3] = geometry.sphere_radius[sphere]
        if selection == "power":
            radiance = np.zeros(num_area)
            # A light's power: sum over its triangles of pi * area * lum(Le); a sphere's pi 4 pi r^2 lum(Le).
            np.add.at(radiance, ids, np.pi * geometry.area[order] * (geometry.emission[order] @ _LUMINANCE))
            for k in np.flatnonzero(self.sphere[self.first]) if num_area else ():
                emission = geometry.emission[self.triangles[self.first[k]]]
                radiance[k] = np.pi * self.area[k] * float(emission @ _LUMINANCE)
            weights = radiance  # > 0: every emitter has some positive channel and all luminance weights are > 0
            if len(extra):
                weights = np.concatenate([weights, extra])
                if not weights.sum() > 0:  # only infinite lights in a scene of no extent: nothing to weigh by
                    weights = np.ones(self.num_lights)
        else:
            weights = np.ones(self.num_lights)
        self.pmf = weights / weights.sum() if self.num_lights else weights
        self.tree = None
        if selection == "tree":  # an area light's pdf(k | x) is the tree's (kernels.light_tree); an emitter's 1/(n+1)
            from reference_impl.light_tree import LightTree  # optional: numba, imported where a tree is built only

            spheres = geometry.sphere_of[self.triangles[self.first]] if geometry.num_spheres else np.full(num_area, -1)
            self.tree = LightTree(geometry, self.area, spheres, len(extra))
            if not num_area:
                self.tree.p_tree = 0.0
            self.pmf = np.concatenate([np.full(num_area, np.nan),  # per shading point: no table holds it
                                       np.full(len(extra), (1.0 - self.tree.p_tree) / max(len(extra), 1))])
        self.cdf = np.cumsum(self.pmf)
        if self.num_lights:
            self.cdf[-1] = 1.0

    def pdf_select(self, light: np.ndarray) -> np.ndarray:
        """pdf(k)."""
        return self.pmf[light]

    def pdf_area(self, light: np.ndarray) -> np.ndarray:
        """pdf(k) * pdf(y | k) = pdf(k) / A_k, per unit area on light k."""
        return self.pmf[light] / self.area[light]

    def select(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Light k from pdf(k) for each uniform, over area lights and emitters, and what is left of u inside k's
        interval of the cdf (:func:`rescale_within`: a fresh uniform, the first coordinate of an emitter's direction
        with the stratified sampler; kernels.emitters.split_light_uniform_all)."""
        u = np.asarray(u, dtype=np.float64)
        if self.num_lights <= 1:
            return np.zeros(len(u), np.int64), u
        light = sample_discrete(self.cdf, u)
        return light, rescale_within(u, np.where(light > 0, self.cdf[light - 1], 0.0), self.cdf[light])

    def split_uniform(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One uniform for the light, its piece and the point (sample reuse, as pbrt-v4's light samplers do):
        u_select = u picks light k; what is left of it inside k's cdf interval picks the piece (a triangle, or a
        whole parallelogram: then the piece's interval is [0, 1) and u1 = u_tri); what is left of that inside the
        piece's interval is u1 (:func:`rescale_within` each time). ``sample(*split_uniform(u), u2)`` is one 2D
        sample over all lights: a stratified (u, u2) stays stratified over the lights, not only within each piece.
        (Area lights only: a light k >= ``num_area`` has no pieces, see :meth:`select`.)"""
        u = np.asarray(u, dtype=np.float64)
        if self.num_lights > 1:
            light = sample_discrete(self.cdf, u)
            u_tri = rescale_within(u, np.where(light > 0, self.cdf[light - 1], 0.0), self.cdf[light])
        else:
            light, u_tri = np.zeros(len(u), np.int64), u
        first = self.first[light]
        local = _search_within(self.within_cdf, first, self.count[light], u_tri)
        lo = np.where(local > 0, self.within_cdf[first + local - 1], 0.0)
        return u, u_tri, rescale_within(u_tri, lo, self.within_cdf[first + local])

    def point_on_entry(self, entry: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A uniform point on each table entry, and the triangle it lies in: y = o + a e1 + b e2 of the entry's frame
        (o, e1, e2), (a, b) = (u1, u2) on a parallelogram and the triangle's barycentrics (1 - sqrt(u1), u2 sqrt(u1))
        otherwise (both computed, one selected by the flag, as in the kernels: kernels.light_sampling.point_on_light).
        A parallelogram's point is in ``other[entry]`` where a + b > 1, else in ``triangles[entry]``."""
        b1, b2 = square_to_uniform_triangle(u1, u2)
        par = self.parallelogram[entry]
        a = np.where(par, u1, b1)
        b = np.where(par, u2, b2)
        pos = np.empty((len(entry), 3))
        for c in range(3):  # o + a e1 + b e2 per coordinate, from (entries,) columns (no (n, 3, 3) gather)
            f = self.frames[:, :, c]
            pos[:, c] = f[entry, 0] + a * f[entry, 1] + b * f[entry, 2]
        on = self.sphere[entry]
        pos[on] = sphere_points(self.frames[entry[on], 0], self.frames[entry[on], 1, 0], u1[on], u2[on])
        return np.where(a + b > 1.0, self.other[entry], self.triangles[entry]), pos

    def sample(self, u_select: np.ndarray, u_tri: np.ndarray, u1: np.ndarray, u2: np.ndarray):
        """Light indices k and points y on them; pdf_area = pdf(k) pdf(y | k)."""
        light = sample_discrete(self.cdf, u_select) if self.num_lights > 1 else np.zeros(len(u_select), np.int64)
        first = self.first[light]
        local = _search_within(self.within_cdf, first, self.count[light], u_tri)  # only within light k's pieces
        tri, pos = self.point_on_entry(first + local, u1, u2)
        return light, SurfacePoints(tri, pos, front_normals(self.geometry, tri, pos), self.pdf_area(light))


_BELOW_ONE = np.nextafter(1.0, 0.0)


def rescale_within(u: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(u - lo) / (hi - lo): a uniform u that a discrete choice took because lo <= u < hi, made a fresh uniform on
    [0, 1) again (clamped below 1, against rounding and a last cdf entry a hair under 1)."""
    return np.minimum((u - lo) / (hi - lo), _BELOW_ONE)


def _search_within(cdf: np.ndarray, first: np.ndarray, count: np.ndarray, u: np.ndarray) -> np.ndarray:
    """For each ray, the index i < count with cdf[first + i - 1] <= u < cdf[first + i] (vectorised bisection)."""
    lo = np.zeros(len(u), np.int64)
    hi = count - 1
    while True:
        active = lo < hi
        if not np.any(active):
            return lo
        mid = (lo + hi) // 2
        go_right = cdf[first + mid] <= u
        lo = np.where(active & go_right, mid + 1, lo)
        hi = np.where(active & ~go_right, mid, hi)
