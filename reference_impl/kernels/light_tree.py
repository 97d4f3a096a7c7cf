"""Light selection by the light tree (``light_selection = "tree"``, :mod:`reference_impl.light_tree`): the importance
of a node at a shading point, a light drawn by walking down the tree, and the pmf of a given light.

    I(x, n)   = phi cos(theta') / d^2 cos(theta'_i), 0 where theta' >= theta_e = pi / 2
                (pbrt-v4's LightBounds::Importance)
    walk      at each inner node the first child with p0 = I_0 / (I_0 + I_1), the second with I_1 / (I_0 + I_1);
              the uniform rescaled into the chosen interval each time (sample reuse)
    pdf(k|x)  = p_tree prod over k's path of I_taken / (I_0 + I_1)

``tree_pmf`` multiplies the same quotients in the same order as ``tree_select`` (the same bits): the pmf a light
sample was drawn with and the one the MIS weight of a BSDF sample that hit the same light reads are equal. x and n
are the shading point and its geometric normal (either side: |cos|).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import JIT, JIT_BORROW, M_TREE_NO_BOUND_ANGLE
from reference_impl.kernels.warps import rescale_within

_BELOW_ONE = np.nextafter(1.0, 0.0)


@njit(**JIT_BORROW)
def _cos_minus(sin_a, cos_a, sin_b, cos_b):
    """cos(max(0, a - b)) from the sines and cosines of a, b in [0, pi]."""
    if cos_a > cos_b:  # a < b
        return 1.0
    return cos_a * cos_b + sin_a * sin_b


@njit(**JIT_BORROW)
def _sin_minus(sin_a, cos_a, sin_b, cos_b):
    """sin(max(0, a - b))."""
    if cos_a > cos_b:
        return 0.0
    return sin_a * cos_b - cos_a * sin_b


@njit(**JIT_BORROW)
def importance(tree, node, x0, x1, x2, n0, n1, n2, mutant=0):
    """I(x, n) of ``node`` (module docstring; reference_impl.light_tree for the terms)."""
    centre = tree.centre
    r2 = tree.r2[node]  # the bounding sphere's radius^2 = (|diag| / 2)^2
    v0, v1, v2 = x0 - centre[node, 0], x1 - centre[node, 1], x2 - centre[node, 2]
    dist2 = v0 * v0 + v1 * v1 + v2 * v2
    d2 = max(dist2, r2)
    if not d2 > 0.0:
        d2 = 1e-300
    # theta_b: the cone from x holding the bounding sphere; the whole sphere where x is inside it
    if mutant & M_TREE_NO_BOUND_ANGLE:  # mutant "light-tree-no-bound-angle": the box as a point at its centre
        cos_b, sin_b = 1.0, 0.0
    elif dist2 <= r2:
        cos_b, sin_b = -1.0, 0.0
    else:
        sin2 = r2 / dist2
        cos_b = math.sqrt(max(0.0, 1.0 - sin2))
        sin_b = math.sqrt(sin2)
    inv = 1.0 / math.sqrt(dist2) if dist2 > 0.0 else 0.0
    wi0, wi1, wi2 = v0 * inv, v1 * inv, v2 * inv  # from the box toward x
    cos_w = tree.w[node, 0] * wi0 + tree.w[node, 1] * wi1 + tree.w[node, 2] * wi2
    sin_w = math.sqrt(max(0.0, 1.0 - cos_w * cos_w))
    cos_o, sin_o = tree.cos_o[node], tree.sin_o[node]
    cos_x = _cos_minus(sin_w, cos_w, sin_o, cos_o)  # theta_w - theta_o
    sin_x = _sin_minus(sin_w, cos_w, sin_o, cos_o)
    cos_p = _cos_minus(sin_x, cos_x, sin_b, cos_b)  # ... - theta_b
    if cos_p <= 0.0:  # theta' >= theta_e = pi / 2
        return 0.0
    value = tree.phi[node] * cos_p / d2
    if n0 != 0.0 or n1 != 0.0 or n2 != 0.0:
        cos_i = abs(wi0 * n0 + wi1 * n1 + wi2 * n2)
        sin_i = math.sqrt(max(0.0, 1.0 - cos_i * cos_i))
        value *= _cos_minus(sin_i, cos_i, sin_b, cos_b)
    return max(value, 0.0)


@njit(**JIT_BORROW)
def _children(tree, node, x0, x1, x2, n0, n1, n2, mutant):
    """The importances (I_first, I_second) of an inner node's two children and their sum: what both walks read, in
    one order."""
    i0 = importance(tree, node + 1, x0, x1, x2, n0, n1, n2, mutant)
    i1 = importance(tree, tree.child[node], x0, x1, x2, n0, n1, n2, mutant)
    return i0, i1, i0 + i1


@njit(**JIT_BORROW)
def tree_select(tree, u, x0, x1, x2, n0, n1, n2, mutant=0):
    """An area light drawn by the tree at x, for a uniform u already rescaled to the tree's share (:func:`select`):
    (light, its pmf within the tree, what is left of u inside the light's interval); light -1 where no node of the
    tree can light x."""
    node = 0
    pmf = 1.0
    child, leaf = tree.child, tree.leaf
    while not leaf[node]:
        i0, i1, total = _children(tree, node, x0, x1, x2, n0, n1, n2, mutant)
        if not total > 0.0:
            return -1, 0.0, u
        p0 = i0 / total
        if u < p0:
            pmf *= p0
            u = rescale_within(u, 0.0, p0)
            node = node + 1
        else:
            pmf *= i1 / total
            u = rescale_within(u, p0, 1.0)
            node = child[node]
    if node == 0 and not importance(tree, 0, x0, x1, x2, n0, n1, n2, mutant) > 0.0:  # one light, which cannot light x
        return -1, 0.0, u
    return child[node], pmf, u


@njit(**JIT_BORROW)
def tree_pmf(tree, light, x0, x1, x2, n0, n1, n2, mutant=0):
    """The pmf of area light ``light`` within the tree at x: the product :func:`tree_select` forms, in its order."""
    node = 0
    pmf = 1.0
    bits = tree.trail[light]
    child, leaf = tree.child, tree.leaf
    while not leaf[node]:
        i0, i1, total = _children(tree, node, x0, x1, x2, n0, n1, n2, mutant)
        if not total > 0.0:
            return 0.0
        if bits & np.uint64(1):
            pmf *= i1 / total
            node = child[node]
        else:
            pmf *= i0 / total
            node = node + 1
        bits >>= np.uint64(1)
    return pmf


@njit(**JIT_BORROW)
def select(tree, num_area, num_lights, u, x0, x1, x2, n0, n1, n2, mutant=0):
    """Light k from pdf(k | x): with probability 1 - p_tree one of the emitters that are not surfaces (k >= num_area,
    uniformly), else an area light by the tree. (k, pdf(k | x), what is left of u inside k's interval); k = -1 where
    the tree was chosen and nothing in it can light x."""
    p_tree = tree.p_tree[0]
    num_other = num_lights - num_area
    if num_other > 0:
        p_other = 1.0 - p_tree
        if u < p_other or num_area == 0:
            each = p_other / num_other if num_area > 0 else 1.0 / num_other
            span = p_other if num_area > 0 else 1.0
            e = min(int(u / span * num_other), num_other - 1)
            return num_area + e, each, max(0.0, rescale_within(u, e * span / num_other, (e + 1) * span / num_other))
        u = rescale_within(u, p_other, 1.0)
    light, pmf, rest = tree_select(tree, u, x0, x1, x2, n0, n1, n2, mutant)
    return light, pmf * p_tree, rest


@njit(**JIT_BORROW)
def pmf_of(tree, light, x0, x1, x2, n0, n1, n2, mutant=0):
    """pdf(k | x) of area light k = ``light``: p_tree times its pmf within the tree."""
    return tree.p_tree[0] * tree_pmf(tree, light, x0, x1, x2, n0, n1, n2, mutant)


@njit(**JIT)
def select_many(tree, num_area, num_lights, u, x, n, mutant=0):
    """:func:`select` for each uniform u[i] at x[i] with normal n[i]: (k, pdf(k | x)) arrays (tests, studies)."""
    m = len(u)
    light = np.empty(m, np.int64)
    pmf = np.empty(m)
    for i in range(m):
        k, p, _rest = select(tree, num_area, num_lights, u[i], x[i, 0], x[i, 1], x[i, 2], n[i, 0], n[i, 1], n[i, 2],
                             mutant)
        light[i] = k
        pmf[i] = p
    return light, pmf


@njit(**JIT)
def pmf_many(tree, light, x, n, mutant=0):
    """:func:`pmf_of` for each light[i] at x[i] with normal n[i] (tests, studies)."""
    out = np.empty(len(light))
    for i in range(len(light)):
        out[i] = pmf_of(tree, light[i], x[i, 0], x[i, 1], x[i, 2], n[i, 0], n[i, 1], n[i, 2], mutant)
    return out


__all__ = ["importance", "pmf_many", "pmf_of", "select", "select_many", "tree_pmf", "tree_select"]
