r"""The BSDF door of the materials made of others (Mitsuba 3.9.1's src/bsdfs/blendbsdf.cpp, mask.cpp, twosided.cpp),
over arrays, for the tests: eval, pdf and sample of a composite row of :class:`reference_impl.Materials` as Mitsuba's
plugin defines them, from its nested materials' door (:mod:`.bsdf`; a nested composite through this one).

    blendbsdf   f = (1 - w) f_0 + w f_1,  p = (1 - w) p_0 + w p_1; sample: material 1 where u_lobe <= w (u_lobe / w
                reused), else 0 ((u_lobe - w) / (1 - w)); a non-delta sample's weight is f / p and its pdf p, of the
                blend (Mitsuba's ``sample`` does the same); a delta lobe's pdf is its probability times the choice's
                (w or 1 - w), its weight the lobe's own
    mask        f = a f_n,  p = a p_n (a = opacity); sample: the nested material where u_lobe < a (u_lobe / a
                reused; pdf times a, the weight unchanged), else the hole: wi = -wo, weight 1, the discrete
                probability 1 - a, a delta (Mitsuba's ``Null`` lobe)
    twosided    wo on the front (z > 0): the front material at (wo, wi); behind: the back material at the mirrored
                directions (z negated), its sample's wi mirrored back; wo_z = 0: nothing

The renderer's path loop does not call this door: its material step resolves a composite to one of its materials at
each hit (:func:`.material.resolve_nested`, the blend's and twosided's choice; a mask's hole where the ray meets the
shape, :mod:`.cutout`), whose expected f is the f above.

Where this differs from Mitsuba on purpose: Mitsuba's blend mixes a delta lobe's discrete probability with the other
material's density at the same direction (a blend of a delta and a non-delta material has the wrong weight there);
here a delta lobe keeps its own weight.
"""

from __future__ import annotations

import numpy as np

from reference_impl.kernels import bsdf
from reference_impl.materials import BLENDBSDF, COMPOSITES, MASK, P_NESTED, P_WEIGHT, TWOSIDED


def _dirs(a, n=None) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    return np.ascontiguousarray(np.broadcast_to(a, (n, 3)) if n is not None and len(a) == 1 else a)


def _nested(materials, m: int) -> tuple[int, int, float]:
    row = materials.params[m]
    return int(row[P_NESTED]), int(row[P_NESTED + 1]), float(np.clip(row[P_WEIGHT], 0.0, 1.0))


def _mirror(d: np.ndarray) -> np.ndarray:
    return d * np.array([1.0, 1.0, -1.0])


def eval_pdf(materials, m: int, wo, wi, mutant: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """f |cos theta_i| (n, 3) and pdf (n,) of material ``m`` (any kind) at local directions ``wo`` (3,) or (n, 3),
    ``wi`` (n, 3)."""
    kind = int(materials.kind[m])
    if kind not in COMPOSITES:
        return bsdf.eval_pdf(materials, m, wo, wi, mutant)
    wi = _dirs(wi)
    wo = _dirs(wo, len(wi))
    a, b, w = _nested(materials, m)
    if kind == BLENDBSDF:
        fa, pa = eval_pdf(materials, a, wo, wi, mutant)
        fb, pb = eval_pdf(materials, b, wo, wi, mutant)
        return (1.0 - w) * fa + w * fb, (1.0 - w) * pa + w * pb
    if kind == MASK:
        f, p = eval_pdf(materials, a, wo, wi, mutant)
        return w * f, w * p
    f, p = np.zeros((len(wi), 3)), np.zeros(len(wi))
    front, back = wo[:, 2] > 0, wo[:, 2] < 0
    if front.any():
        f[front], p[front] = eval_pdf(materials, a, wo[front], wi[front], mutant)
    if back.any():
        f[back], p[back] = eval_pdf(materials, b, _mirror(wo[back]), _mirror(wi[back]), mutant)
    return f, p


def pdf(materials, m: int, wo, wi, mutant: int = 0) -> np.ndarray:
    """The pdf of :func:`eval_pdf` alone."""
    if int(materials.kind[m]) not in COMPOSITES:
        return bsdf.pdf(materials, m, wo, wi, mutant)
    return eval_pdf(materials, m, wo, wi, mutant)[1]


def sample(materials, m: int, wo, u, mutant: int = 0) -> dict[str, np.ndarray]:
    """Sample wi of material ``m`` (any kind) for ``wo`` (3,) or (n, 3) with uniforms ``u`` (n, 3) (u_lobe, u1, u2):
    a dict of ``ok``, ``wi``, ``weight``, ``pdf``, ``delta`` as :func:`.bsdf.sample` returns."""
    kind = int(materials.kind[m])
    if kind not in COMPOSITES:
        return bsdf.sample(materials, m, wo, u, mutant)
    u = np.array(u, dtype=np.float64).reshape(-1, 3)
    n = len(u)
    wo = _dirs(wo, n)
    out = dict(ok=np.zeros(n, bool), wi=np.zeros((n, 3)), weight=np.zeros((n, 3)), pdf=np.zeros(n),
               delta=np.zeros(n, bool))
    a, b, w = _nested(materials, m)

    def put(where, s, pdf_scale=1.0):
        for k in out:
            out[k][where] = s[k]
        out["pdf"][where] *= pdf_scale

    if kind == TWOSIDED:
        for side, nested, flip in ((wo[:, 2] > 0, a, False), (wo[:, 2] < 0, b, True)):
            if side.any():
                s = sample(materials, nested, _mirror(wo[side]) if flip else wo[side], u[side], mutant)
                if flip:
                    s["wi"] = _mirror(s["wi"])
                put(side, s)
        return out
    if kind == MASK:
        solid = u[:, 0] < w
        hole = ~solid
        out["ok"][hole], out["wi"][hole], out["weight"][hole] = True, -wo[hole], 1.0
        out["pdf"][hole], out["delta"][hole] = 1.0 - w, True
        if solid.any():
            us = u[solid].copy()
            us[:, 0] /= w
            put(solid, sample(materials, a, wo[solid], us, mutant), w)
        return out
    second = (u[:, 0] <= w) & (w > 0)
    for chosen, nested, p_choice in ((~second, a, 1.0 - w), (second, b, w)):
        if not chosen.any():
            continue
        us = u[chosen].copy()
        us[:, 0] = us[:, 0] / w if nested == b and chosen is second else (us[:, 0] - w) / (1.0 - w)
        put(chosen, sample(materials, nested, wo[chosen], us, mutant), p_choice)
    smooth = out["ok"] & ~out["delta"]
    if smooth.any():
        f, p = eval_pdf(materials, m, wo[smooth], out["wi"][smooth], mutant)
        good = p > 0
        weight = np.zeros_like(f)
        weight[good] = f[good] / p[good, None]
        out["weight"][smooth], out["pdf"][smooth] = weight, p
        out["ok"][np.flatnonzero(smooth)[~good]] = False
    return out
