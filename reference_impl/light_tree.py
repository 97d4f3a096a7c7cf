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

Building (compiled with numba; it runs when a render starts): top-down, splitting the lights of a node at one of
11 planes (12 buckets of their box centres along each axis) that minimises pbrt-v4's cost, the sum over the two sides
of phi M_Omega K_r S (M_Omega the cone's solid-angle measure, K_r the node's longest extent over the axis's, S the
box's surface area); lights whose centres coincide are split in half by count. A node's cone here is not pbrt-v4's
pairwise union but one cone around the power-weighted mean axis a holding each light's cone, theta = max_k
(angle(a, w_k) + theta_o_k) (capped at pi; the whole sphere where the weighted axes cancel): it holds every normal
too (so importance stays a bound), in one pass over the node's lights. Depth is held under 64 so that each light's
path from the root fits the 64 bits of ``trail`` (bit j: the child taken at depth j, 1 the second); near that depth
the split is by count.

Emitters that are not surfaces (point, spot, directional, environments) are not in the tree: as in pbrt-v4 each is
chosen with probability 1 / (n_other + 1) and the tree with 1 / (n_other + 1) (pbrt-v4's ``pInfinite``; 0 without
area lights).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.geometry import Geometry
from reference_impl.kernels.config import JIT

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


@njit(**JIT)
def _cone_of(members, w, theta, phi):
    """(axis, half-angle) of one cone holding the cones of ``members``: the axis the normalised sum of phi_i w_i
    (pbrt-v4 would union pairwise), the half-angle max_i (angle(axis, w_i) + theta_i), capped at pi; (0, 0, 1) and
    pi where the axes cancel."""
    a0 = a1 = a2 = 0.0
    for i in members:
        a0 += phi[i] * w[i, 0]
        a1 += phi[i] * w[i, 1]
        a2 += phi[i] * w[i, 2]
    length = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if not length > 1e-12:
        return 0.0, 0.0, 1.0, math.pi
    a0, a1, a2 = a0 / length, a1 / length, a2 / length
    half = 0.0
    for i in members:
        c = min(1.0, max(-1.0, a0 * w[i, 0] + a1 * w[i, 1] + a2 * w[i, 2]))
        half = max(half, math.acos(c) + theta[i])
    return a0, a1, a2, min(half, math.pi)


@njit(**JIT)
def _cost(lo, hi, phi, theta_o, k_r):
    """pbrt-v4's cost of light bounds (``EvaluateCost``, theta_e = pi / 2): phi M_Omega K_r S, with
    M_Omega = 2 pi (1 - cos theta_o) + pi / 2 (2 theta_w sin theta_o - cos(theta_o - 2 theta_w)
    - 2 theta_o sin theta_o + cos theta_o), theta_w = min(theta_o + theta_e, pi), S the box's surface area."""
    theta_w = min(theta_o + math.pi / 2, math.pi)
    cos_o, sin_o = math.cos(theta_o), math.sin(theta_o)
    m_omega = 2 * math.pi * (1 - cos_o) + math.pi / 2 * (2 * theta_w * sin_o - math.cos(theta_o - 2 * theta_w)
                                                          - 2 * theta_o * sin_o + cos_o)
    d0, d1, d2 = max(hi[0] - lo[0], 0.0), max(hi[1] - lo[1], 0.0), max(hi[2] - lo[2], 0.0)
    return phi * m_omega * k_r * 2 * (d0 * d1 + d1 * d2 + d2 * d0)


@njit(**JIT)
def _split(members, depth, lo, hi, phi, w, theta, centre):
    """The number of ``members`` (reordered in place) on the left side of the cheapest of the candidate planes
    (module docstring); by count, along the centres' longest extent, where the centres coincide or depth must stay
    under MAX_DEPTH."""
    n = len(members)
    c_lo = np.full(3, np.inf)
    c_hi = np.full(3, -np.inf)
    n_lo = np.full(3, np.inf)
    n_hi = np.full(3, -np.inf)
    for i in members:
        for a in range(3):
            c_lo[a] = min(c_lo[a], centre[i, a])
            c_hi[a] = max(c_hi[a], centre[i, a])
            n_lo[a] = min(n_lo[a], lo[i, a])
            n_hi[a] = max(n_hi[a], hi[i, a])
    extent = c_hi - c_lo
    node_extent = n_hi - n_lo
    longest = 0
    for a in range(3):
        if extent[a] > extent[longest]:
            longest = a
    by_count = not extent[longest] > 0 or MAX_DEPTH - depth <= math.ceil(math.log2(n)) + 1
    best_cost, best_axis, best_cut = np.inf, -1, 0
    if not by_count:
        box_lo, box_hi = np.empty(3), np.empty(3)
        for axis in range(3):
            if not extent[axis] > 0:
                continue
            order = members[np.argsort(centre[members, axis], kind="mergesort")]
            k_r = node_extent.max() / node_extent[axis] if node_extent[axis] > 0 else 1.0
            previous = 0
            for b in range(1, BUCKETS):  # the cut before the first member of bucket b
                cut = previous
                while cut < n and min(int(BUCKETS * (centre[order[cut], axis] - c_lo[axis]) / extent[axis]),
                                      BUCKETS - 1) < b:
                    cut += 1
                previous = cut
                if cut == 0 or cut == n:
                    continue
                cost = 0.0
                for side in range(2):
                    part = order[:cut] if side == 0 else order[cut:]
                    box_lo[:] = np.inf
                    box_hi[:] = -np.inf
                    total = 0.0
                    for i in part:
                        total += phi[i]
                        for a in range(3):
                            box_lo[a] = min(box_lo[a], lo[i, a])
                            box_hi[a] = max(box_hi[a], hi[i, a])
                    half = _cone_of(part, w, theta, phi)[3]
                    cost += _cost(box_lo, box_hi, total, half, k_r)
                if cost < best_cost:
                    best_cost, best_axis, best_cut = cost, axis, cut
    if best_axis < 0:  # by count (also where every cost is infinite or nan)
        best_axis, best_cut = longest, n // 2
    members[:] = members[np.argsort(centre[members, best_axis], kind="mergesort")]
    return best_cut


@njit(**JIT)
def _build(lo, hi, phi, w, theta, centre):
    """The nodes in depth-first order (a node's first child the next node) and each light's trail (module
    docstring): node arrays (lo, hi, phi, w, cos_o, child, leaf) and trail."""
    n = len(phi)
    m = 2 * n - 1
    n_lo, n_hi, n_w = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 3))
    n_phi, n_cos = np.empty(m), np.empty(m)
    child = np.full(m, -1, np.int64)
    leaf = np.zeros(m, np.bool_)
    trail = np.zeros(n, np.uint64)
    members = np.arange(n)
    # stack of (start, end, depth, trail bits, parent whose second child this is, or -1)
    stack = np.empty((2 * MAX_DEPTH + 4, 5), np.int64)
    top = 0
    stack[0] = (0, n, 0, 0, -1)
    top = 1
    count = 0
    while top > 0:
        top -= 1
        start, end, depth, bits, parent = stack[top]
        index = count
        count += 1
        if parent >= 0:
            child[parent] = index
        part = members[start:end]
        for a in range(3):
            n_lo[index, a] = np.inf
            n_hi[index, a] = -np.inf
        total = 0.0
        for i in part:
            total += phi[i]
            for a in range(3):
                n_lo[index, a] = min(n_lo[index, a], lo[i, a])
                n_hi[index, a] = max(n_hi[index, a], hi[i, a])
        if end - start == 1:
            i = part[0]
            n_phi[index] = phi[i]
            n_w[index] = w[i]
            n_cos[index] = math.cos(theta[i])
            child[index] = i
            leaf[index] = True
            trail[i] = np.uint64(bits)
            continue
        a0, a1, a2, half = _cone_of(part, w, theta, phi)
        n_phi[index] = total
        n_w[index, 0], n_w[index, 1], n_w[index, 2] = a0, a1, a2
        n_cos[index] = math.cos(half)
        cut = _split(part, depth, lo, hi, phi, w, theta, centre)
        # the second child first onto the stack, so that the first is numbered next (index + 1)
        stack[top] = (start + cut, end, depth + 1, bits | (1 << depth), index)
        stack[top + 1] = (start, start + cut, depth + 1, bits, -1)
        top += 2
    return n_lo, n_hi, n_phi, n_w, n_cos, child, leaf, trail


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
        b = light_bounds(geometry, area, spheres)
        self.p_tree = 1.0 / (num_other + 1)
        theta = np.arccos(np.clip(b["cos_o"], -1.0, 1.0))
        centre = 0.5 * (b["lo"] + b["hi"])
        if len(b["phi"]):
            (self.lo, self.hi, self.phi, self.w, self.cos_o, self.child, self.leaf,
             self.trail) = _build(b["lo"], b["hi"], b["phi"], b["w"], theta, centre)
        else:
            self.lo, self.hi, self.w = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3))
            self.phi, self.cos_o = np.zeros(0), np.zeros(0)
            self.child, self.leaf, self.trail = np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, np.uint64)

    def __len__(self) -> int:
        return len(self.phi)
