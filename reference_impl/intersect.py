"""The one place that talks to Embree: closest-hit and occlusion queries, in batches or (from the kernels) one ray at
a time.

The scene is built through Embree 4's C API (:mod:`reference_impl.embree_c`, the library the embreex wheel ships) and
queried by compiled loops that call ``rtcIntersect1`` / ``rtcOccluded1``, the same functions embreex's ``run`` calls
once per ray. Embree works in float32 and starts every ray at t = 0, so callers offset ray origins off the surface
(:func:`offset_origin`). Hit distances are recomputed here in float64 from the triangle's plane (a sphere's from
the sphere, :func:`sphere_distance`), so hit points are as exact as the float64 ray allows, not rounded through
Embree's float32 t. Embree holds the triangles; the queries test each sphere themselves, in float64
(:mod:`reference_impl.kernels.queries`), never the triangles that stand in for it.
"""

from __future__ import annotations

import numpy as np

from reference_impl.geometry import Geometry

# Relative size of the offset that moves a ray origin off its surface: 8 to 16 float32 ulps of the coordinates
# (Embree's precision), plus a tiny fraction of the scene's size. 2^-17 (64 to 128 ulps) was 2.3 % of the Cornell box
# once the box was moved 1e4 from the origin, and biased its contact shadows (harness stress, docs/stress.md).
_OFFSET_REL = 2.0**-20
_OFFSET_SCENE = 2.0**-22


class Intersector:
    """Batched ray queries against one scene. Thread-safe: the query loops release the GIL, and Embree allows
    concurrent queries on a committed scene."""

    def __init__(self, geometry: Geometry):
        from reference_impl.embree_c import TriangleScene  # optional: loads numba, needed only for a scene

        self.geometry = geometry
        self.scene_size = max(geometry.extent, 1e-30)
        self._embree = None
        usable = geometry.area > 0
        if geometry.num_spheres:  # a sphere's triangles stand in for it: Embree gets the sphere itself
            usable &= geometry.sphere_of < 0
        self._usable = usable
        # Each sphere's centre and radius, tested beside Embree's triangles by the queries (kernels.queries).
        self.spheres = np.ascontiguousarray(np.column_stack([geometry.sphere_center, geometry.sphere_radius]),
                                            dtype=np.float64).reshape(-1, 4)
        if np.any(usable) or geometry.num_spheres:
            # Degenerate triangles are left out; primID indexes the kept ones, then one primitive per sphere (from
            # `sphere_base` on), all mapped back with `_prim_to_tri` (a sphere's to its first triangle).
            self._prim_to_tri = np.concatenate([np.flatnonzero(usable), geometry.sphere_first])
            self._embree = TriangleScene(geometry.vertices, geometry.triangles[usable])
        self.sphere_base = int(np.count_nonzero(usable))

    @property
    def scene_pointer(self) -> int:
        """The RTCScene handle for kernels that query Embree themselves (0 when there is nothing to hit)."""
        return self._embree.pointer if self._embree is not None else 0

    @property
    def packet_width(self) -> int:
        """Rays per packet query: the widest packet Embree traces natively on this processor (16, 8 or 4; 1: none,
        or nothing to hit). :mod:`reference_impl.embree_c`."""
        return self._embree.packet_width if self._embree is not None else 1

    @property
    def prim_to_tri(self) -> np.ndarray:
        """Triangle index of each Embree primitive (the usable triangles, in order)."""
        return self._prim_to_tri if self._embree is not None else np.zeros(0, np.int64)

    @property
    def offset_scene(self) -> float:
        """The scene-size part of :meth:`offset`."""
        return _OFFSET_SCENE * self.scene_size

    def closest_prims(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Embree's closest-hit query on float32 (n, 3) C-contiguous rays: the primitive hit (an index into
        :attr:`prim_to_tri`), -1 for a miss, as int32. The wavefront integrator calls this directly."""
        return self._query("closest_prims", origins, directions)

    def closest_prims_coherent(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """:meth:`closest_prims` for rays that come in runs travelling together (one pixel's camera rays): one
        packet query per :attr:`packet_width` rays. The same hits."""
        n = len(origins)
        out = np.full(n, -1, np.int32)
        if self._embree is not None and n:
            from reference_impl.kernels import queries  # optional: numba-compiled; loaded only when a scene is queried

            queries.closest_prims_packets(self._embree.pointer, self.packet_width, origins, directions, out,
                                          self.spheres, self.sphere_base)
        return out

    def occluders(self, origins: np.ndarray, directions: np.ndarray, tfar: np.ndarray) -> np.ndarray:
        """Embree's any-hit query on float32 rays with float32 ``tfar``: >= 0 where something blocks the segment,
        -1 where nothing does (int32)."""
        return self._query("occluders", origins, directions, tfar)

    def _query(self, kernel: str, *rays: np.ndarray) -> np.ndarray:
        """Run the batch query ``kernels.queries.<kernel>(scene, *rays, out, spheres[, base])``: int32 per ray, -1
        where nothing is hit."""
        n = len(rays[0])
        out = np.full(n, -1, np.int32)
        if self._embree is not None and n:
            from reference_impl.kernels import queries  # optional: numba-compiled; loaded only when a scene is queried

            extra = (self.spheres,) if kernel == "occluders" else (self.spheres, self.sphere_base)
            getattr(queries, kernel)(self._embree.pointer, *rays, out, *extra)
        return out

    def closest_hit(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Triangle index (-1 for a miss) and float64 distance t along unit ``directions`` of the closest hit."""
        n = len(origins)
        if self._embree is None or n == 0:
            return np.full(n, -1, np.int64), np.full(n, np.inf)
        prim = self.closest_prims(_f32(origins), _f32(directions))
        hit = prim >= 0
        tri = np.full(n, -1, np.int64)
        tri[hit] = self._prim_to_tri[prim[hit]]
        t = np.full(n, np.inf)
        if np.any(hit):
            th = tri[hit]
            normal = self.geometry.normal[th]
            v0 = self.geometry.corners[th, 0]
            denom = np.einsum("ij,ij->i", directions[hit], normal)
            with np.errstate(divide="ignore", invalid="ignore"):
                t_hit = np.einsum("ij,ij->i", v0 - origins[hit], normal) / denom
            if self.geometry.num_spheres:
                which = self.geometry.sphere_of[th]
                on = which >= 0
                t_hit[on] = sphere_distance(self.geometry.sphere_center[which[on]],
                                            self.geometry.sphere_radius[which[on]], origins[hit][on],
                                            directions[hit][on])
            # Grazing hits where the plane equation is ill-conditioned fall back to a tiny positive distance.
            t[hit] = np.where(np.isfinite(t_hit) & (t_hit > 0), t_hit, 0.0)
        return tri, t

    def occluded(self, origins: np.ndarray, directions: np.ndarray, t_max: np.ndarray) -> np.ndarray:
        """True where something blocks the segment origin + t direction, 0 < t < t_max (any-hit query)."""
        n = len(origins)
        if self._embree is None or n == 0:
            return np.zeros(n, bool)
        tfar = np.ascontiguousarray(np.maximum(t_max, 0.0), dtype=np.float32)
        return self.occluders(_f32(origins), _f32(directions), tfar) >= 0

    def offset(self, points: np.ndarray) -> np.ndarray:
        """Per-point distance by which to move a ray origin off the surface along its normal."""
        return _OFFSET_REL * np.max(np.abs(points), axis=1) + _OFFSET_SCENE * self.scene_size


def sphere_distance(center: np.ndarray, radius: np.ndarray, origins: np.ndarray,
                    directions: np.ndarray) -> np.ndarray:
    """The nearer root t > 0 of |o + t d - c| = r for rays (unit d) that Embree found on spheres, 0 where neither
    root is: kernels.surface.sphere_hit_point, q = -(b + sign(b) sqrt(b^2 - k)), roots q and k / q."""
    m = origins - center
    b = np.einsum("ij,ij->i", m, directions)
    k = np.einsum("ij,ij->i", m, m) - radius * radius
    q = -(b + np.copysign(np.sqrt(np.maximum(b * b - k, 0.0)), b))
    with np.errstate(divide="ignore", invalid="ignore"):
        other = np.where(q != 0.0, k / q, 0.0)
    near, far = np.minimum(q, other), np.maximum(q, other)
    return np.where(near > 0, near, np.where(far > 0, far, 0.0))


def offset_origin(points: np.ndarray, normals: np.ndarray, distance: np.ndarray) -> np.ndarray:
    """Move ``points`` by ``distance`` along ``normals`` (already oriented toward the side the ray leaves)."""
    return points + distance[:, None] * normals


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)
