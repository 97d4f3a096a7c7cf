"""A bounding volume hierarchy over the area lights, for light selection that depends on the shading point
(``light_selection = "tree"``; pbrt-v4's ``BVHLightSampler``, after Conty Estevez and Kulla 2018, "Importance
Sampling of Many Lights with Adaptive Tree Splitting").

Each light k gets *light bounds*: the box of its points, its power phi_k = pi A_k lum(Le_k) (what "power" selection
weighs by), and the cone of directions it emits into, an axis w with half-angle theta_o holding every surface normal
of the light (theta_o = pi for a sphere) widened by theta_e = pi / 2 (a one-sided diffuse emitter's hemisphere). A
node's bounds hold its two children's: the union of the boxes, the sum of the powers, and a cone holding both cones.

At a shading point x with normal n (:mod:`reference_impl.kernels.light_tree`) a node's importance is a conservative
estimate of what its lights can send to x (pbrt-v4, ``LightBounds::Importance``):

    I(x, n) = phi cos(theta') / d^2 * cos(theta'_i)      (0 where theta' >= theta_e)
    theta'   = max(0, theta_w - theta_o - theta_b)       the angle between the cone and the direction to x, less the
                                                          box's angular radius theta_b as seen from x
    theta'_i = max(0, theta_i - theta_b)                 the angle between n and the direction to the box, likewise
    d^2      = max(|x - c|^2, (|diag| / 2)^2)             c the box's centre (clamped so a point near a big box does
                                                          not give it an unbounded importance)

with theta_w the angle between w and x - c, theta_i the one between +-n and c - x (|cos|: both sides of x) and
theta_b the half-angle of the cone from x holding the box's bounding sphere (pi where x is inside it). The selection
walks down from the root choosing a child with probability I_child / (I_left + I_right), so a light's pmf is the
product of its choices' probabilities along the path: pdf(k | x, n) > 0 wherever light k can light x (I is a bound,
never 0 where the light can send anything to x), and the estimator stays unbiased.

Building (here, with numpy): top-down, splitting the lights of a node at one of 11 planes (12 buckets of their box
centres along each axis) that minimises pbrt-v4's cost, the sum over the two sides of phi M_Omega K_r S (M_Omega the
cone's solid-angle measure, K_r the node's longest extent over the axis's, S the box's surface area); lights whose
centres coincide are split in half by count. A node's cone here is not pbrt-v4's pairwise union but one cone around
the power-weighted mean axis a holding each light's cone, theta = max_k (angle(a, w_k) + theta_o_k) (capped at pi;
the whole sphere where the weighted axes cancel): it holds every normal too (so importance stays a bound), and it
is computed for many candidate splits at once. Depth is held under 64 so that each light's path from the root fits
the 64 bits of ``trail`` (bit j: the child taken at depth j, 1 the second); near that depth the split is by count.

Emitters that are not surfaces (point, spot, directional, environments) are not in the tree: as in pbrt-v4 each is
chosen with probability 1 / (n_other + 1) and the tree with 1 / (n_other + 1) (pbrt-v4's ``pInfinite``).
"""

from __future__ import annotations

import math

import numpy as np

from reference_impl.geometry import Geometry

BUCKETS = 12  # candidate planes per axis: BUCKETS - 1 (pbrt-v4's 12 buckets)
MAX_DEPTH = 63  # a light's path from the root: at most 63 choices (its trail's 64 bits)
_LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def light_bounds(geometry: Geometry, area: np.ndarray, spheres: np.ndarray) -> dict[str, np.ndarray]:
    """The bounds of each area light k (its triangles ``geometry.light_id == k``): box ``lo``, ``hi`` (N_A, 3),
    power ``phi`` (N_A,) = pi A_k lum(Le_k), cone axis ``w`` (N_A, 3) and ``cos_o`` (N_A,).

    Parameters
    ----------
    geometry : Geometry
    area : (N_A,) float64
        A_k (a sphere light's 4 pi r^2).
    spheres : (N_A,) int64
        Per light: the analytic sphere it is, or -1.
    """
    n = geometry.num_lights
    emissive = np.flatnonzero(geometry.light_id >= 0)
    ids = geometry.light_id[emissive]
    corners = geometry.corners[emissive]
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    np.minimum.at(lo, ids, corners.min(axis=1))
    np.maximum.at(hi, ids, corners.max(axis=1))
    # The cone: the area-weighted mean normal, opened to hold every triangle's normal.
    summed = np.zeros((n, 3))
    np.add.at(summed, ids, geometry.normal[emissive] * geometry.area[emissive, None])
    length = np.linalg.norm(summed, axis=1)
    w = np.where(length[:, None] > 0, summed / np.where(length > 0, length, 1.0)[:, None], [0.0, 0.0, 1.0])
    cos = np.einsum("ij,ij->i", geometry.normal[emissive], w[ids])
    cos_o = np.ones(n)
    np.minimum.at(cos_o, ids, np.clip(cos, -1.0, 1.0))
    cos_o[length <= 0] = -1.0
    # luminance of a light: its triangles' area-weighted mean emission (one value for a light of one emission)
    radiance = np.zeros(n)
    np.add.at(radiance, ids, geometry.area[emissive] * (geometry.emission[emissive] @ _LUMINANCE))
    phi = np.pi * radiance
    on = spheres >= 0
    if np.any(on):
        s = spheres[on]
        centre, radius = geometry.sphere_center[s], geometry.sphere_radius[s]
        lo[on], hi[on] = centre - radius[:, None], centre + radius[:, None]
        w[on], cos_o[on] = [0.0, 0.0, 1.0], -1.0
        first = geometry.sphere_first[s]
        phi[on] = np.pi * area[on] * (geometry.emission[first] @ _LUMINANCE)
    return {"lo": lo, "hi": hi, "phi": phi, "w": w, "cos_o": cos_o}


def _angle(cos: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(cos, -1.0, 1.0))


def _cones(w: np.ndarray, theta: np.ndarray, phi: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A cone holding the cones of each group of lights: ``groups`` (G, n) bool, whether light i is in group g.
    Axis a_g = normalised sum of phi_i w_i over the group (pbrt-v4 would union pairwise), half-angle
    max_i (angle(a_g, w_i) + theta_i), capped at pi; (0, 0, 1) and pi where the axes cancel."""
    weighted = groups.astype(np.float64) @ (phi[:, None] * w)  # (G, 3)
    length = np.linalg.norm(weighted, axis=1)
    axis = np.where(length[:, None] > 1e-12, weighted / np.maximum(length, 1e-300)[:, None], [0.0, 0.0, 1.0])
    spread = _angle(axis @ w.T) + theta[None, :]  # (G, n)
    half = np.where(groups, spread, -np.inf).max(axis=1)
    half = np.where(length > 1e-12, np.minimum(half, np.pi), np.pi)
    return axis, half


def _cost(lo: np.ndarray, hi: np.ndarray, phi: np.ndarray, theta_o: np.ndarray, k_r: float) -> np.ndarray:
    """pbrt-v4's cost of light bounds (``EvaluateCost``, theta_e = pi / 2): phi M_Omega K_r S, with
    M_Omega = 2 pi (1 - cos theta_o) + pi / 2 (2 theta_w sin theta_o - cos(theta_o - 2 theta_w)
    - 2 theta_o sin theta_o + cos theta_o), theta_w = min(theta_o + theta_e, pi), S the box's surface area."""
    theta_w = np.minimum(theta_o + np.pi / 2, np.pi)
    cos_o, sin_o = np.cos(theta_o), np.sin(theta_o)
    m_omega = 2 * np.pi * (1 - cos_o) + np.pi / 2 * (2 * theta_w * sin_o - np.cos(theta_o - 2 * theta_w)
                                                      - 2 * theta_o * sin_o + cos_o)
    d = np.maximum(hi - lo, 0.0)
    surface = 2 * (d[:, 0] * d[:, 1] + d[:, 1] * d[:, 2] + d[:, 2] * d[:, 0])
    return phi * m_omega * k_r * surface


class LightTree:
    """The tree over area lights 0 .. N_A - 1 (module docstring), as flat arrays the kernels read.

    Attributes
    ----------
    lo, hi : (M, 3) float64
        Each node's box.
    phi : (M,) float64
        Its power.
    w : (M, 3) float64
        Its cone's axis.
    cos_o : (M,) float64
        Its cone's cos theta_o (cos theta_e = 0 for every node: one-sided diffuse emitters).
    child : (M,) int64
        An inner node's second child (its first is the next node, index + 1); a leaf's light.
    leaf : (M,) bool
    trail : (N_A,) uint64
        Per light, the choices from the root to its leaf: bit j = 1 where the second child is taken at depth j.
    p_tree : float
        The probability that the tree is chosen rather than one of the other emitters: 1 / (n_other + 1).
    """

    def __init__(self, geometry: Geometry, area: np.ndarray, spheres: np.ndarray, num_other: int = 0):
        bounds = light_bounds(geometry, area, spheres)
        self.p_tree = 1.0 / (num_other + 1)
        n = len(bounds["phi"])
        self._b = bounds
        self._theta = _angle(bounds["cos_o"])
        self._centre = 0.5 * (bounds["lo"] + bounds["hi"])
        nodes: list[list] = []  # per node: [lo, hi, phi, w, cos_o, child, leaf]
        self.trail = np.zeros(n, np.uint64)
        if n:
            self._build(np.arange(n), 0, 0, nodes)
        self.lo = np.array([v[0] for v in nodes], np.float64).reshape(-1, 3)
        self.hi = np.array([v[1] for v in nodes], np.float64).reshape(-1, 3)
        self.phi = np.array([v[2] for v in nodes], np.float64)
        self.w = np.array([v[3] for v in nodes], np.float64).reshape(-1, 3)
        self.cos_o = np.array([v[4] for v in nodes], np.float64)
        self.child = np.array([v[5] for v in nodes], np.int64)
        self.leaf = np.array([v[6] for v in nodes], np.bool_)
        del self._b, self._theta, self._centre

    def __len__(self) -> int:
        return len(self.phi)

    def _node(self, members: np.ndarray) -> list:
        b = self._b
        lo, hi = b["lo"][members].min(axis=0), b["hi"][members].max(axis=0)
        if len(members) == 1:
            i = members[0]
            return [lo, hi, b["phi"][i], b["w"][i], b["cos_o"][i], int(i), True]
        axis, half = _cones(b["w"][members], self._theta[members], b["phi"][members], np.ones((1, len(members)), bool))
        return [lo, hi, b["phi"][members].sum(), axis[0], math.cos(half[0]), -1, False]

    def _build(self, members: np.ndarray, depth: int, trail_bits: int, nodes: list) -> None:
        index = len(nodes)
        nodes.append(self._node(members))
        if len(members) == 1:
            self.trail[members[0]] = np.uint64(trail_bits)
            return
        left, right = self._split(members, depth)
        self._build(left, depth + 1, trail_bits, nodes)
        nodes[index][5] = len(nodes)
        self._build(right, depth + 1, trail_bits | (1 << depth), nodes)

    def _split(self, members: np.ndarray, depth: int) -> tuple[np.ndarray, np.ndarray]:
        """The two sides of the cheapest of the candidate planes (module docstring); by count, along the centres'
        longest extent, where the centres coincide or depth must stay under :data:`MAX_DEPTH`."""
        b, centre = self._b, self._centre[members]
        c_lo, c_hi = centre.min(axis=0), centre.max(axis=0)
        extent = c_hi - c_lo
        n = len(members)
        node_extent = b["hi"][members].max(axis=0) - b["lo"][members].min(axis=0)
        by_count = extent.max() <= 0 or MAX_DEPTH - depth <= math.ceil(math.log2(n)) + 1
        best = (np.inf, None)
        for axis in range(3) if not by_count else ():
            if extent[axis] <= 0:
                continue
            order = np.argsort(centre[:, axis], kind="stable")
            sorted_members = members[order]
            bucket = np.minimum((BUCKETS * (centre[order, axis] - c_lo[axis]) / extent[axis]).astype(np.int64),
                                BUCKETS - 1)
            cuts = np.unique(np.searchsorted(bucket, np.arange(1, BUCKETS), side="left"))
            cuts = cuts[(cuts > 0) & (cuts < n)]
            if not len(cuts):
                continue
            positions = np.arange(n)
            left = positions[None, :] < cuts[:, None]  # (C, n): light i on the left of cut c
            phi, theta = b["phi"][sorted_members], self._theta[sorted_members]
            w = b["w"][sorted_members]
            k_r = node_extent.max() / node_extent[axis] if node_extent[axis] > 0 else 1.0
            cost = np.zeros(len(cuts))
            for side in (left, ~left):
                _axes, half = _cones(w, theta, phi, side)
                lo = np.where(side[:, :, None], b["lo"][sorted_members][None], np.inf).min(axis=1)
                hi = np.where(side[:, :, None], b["hi"][sorted_members][None], -np.inf).max(axis=1)
                cost += _cost(lo, hi, side.astype(np.float64) @ phi, half, k_r)
            c = int(np.argmin(cost))
            if cost[c] < best[0]:
                best = (cost[c], (sorted_members[:cuts[c]], sorted_members[cuts[c]:]))
        if best[1] is None:  # by count (also where every cost is infinite or nan)
            axis = int(np.argmax(extent))
            order = np.argsort(centre[:, axis], kind="stable")
            return members[order[:n // 2]], members[order[n // 2:]]
        return best[1]
