"""The path loop (pbrt-v4's ``PathIntegrator::Li``, Mitsuba's ``path.cpp``): each camera path from its viewing ray to
its end in one compiled loop that queries Embree itself, for every scene and every strategy with Ni = 1 (Ni > 1, the
slides' branching paths, is the wavefront's: :mod:`.wavefront`).

At each vertex x (its surface record, :class:`.surface.SurfaceHit`: front geometric normal N; the BSDF's local frame
is the shading frame, z = N, never flipped; wo toward the previous vertex; the BSDF's kind and parameters from the
material step, :func:`.material.material_at`) the path adds

* emission Le(x -> wo) of an area light's front side, met by the ray that found x, weighted by w_b:
  1 at the camera hit or after a delta bounce (no light sample could have found it) or with ``direct = bsdf``;
  0 with ``direct = area``, ``global-area`` and the hemisphere strategies (their direct light found it: the
  slides' L_r recursion, eq. 5.2); with ``direct = mis`` the power heuristic (Veach 1997, ch. 9)
  w_b = p_b^2 / (p_b^2 + p_l^2), p_b the BSDF's solid-angle pdf of that ray at the previous vertex and
  p_l = Nd pdf(k) / A_k |x - y|^2 / cos_y the light samples' density of the same direction (Nd pdf(k) /
  (2 pi (1 - cos theta_max)) on a sphere light they draw by its cone from x: ``light_sampling.light_density``, at
  the previous vertex); the environment met
  by an escaping ray likewise, with p_l = Nd pdf(k_env) p_env(w). With the planted fault "double-emission", 1 at
  every hit (the pseudo-code's computeRadiance taken literally).
* direct light (none at a delta BSDF; :mod:`.direct`), 1/Nd sum of Le G V f|cos_x| / p over Nd samples, by
  ``direct``: ``area`` and ``mis``, light k with pdf(k) and a point on it or an emitter's own sample (the light
  door, :func:`.direct.light_connection`), on either side of a surface that transmits, weighted with ``mis`` by
  w_l = p_l^2 / (p_l^2 + p_b^2) (delta lights: 1); ``global-area``, a point uniform over every surface
  (Fig. 5.13); ``hemisphere-cosine`` / ``-uniform``, a direction Psi about N and the emission the ray finds,
  Le f|cos| / p(Psi) (Fig. 5.12). f|cos_x| is the BSDF door's (:func:`.bsdf.bsdf_eval`). The emitters a strategy
  cannot find (hemisphere: delta lights; global area: delta lights and the environment; ``bsdf``: delta lights) add
  their own sample once per hit, as if each were the only light (pdf(k) = 1).
* the next ray: :func:`.bsdf.bsdf_sample` (the diffuse kind cosine-weighted, or uniform with ``hemisphere =
  uniform``), beta *= its weight f|cos|/p (eta^2 radiance scaling included), then Russian roulette from
  ``rr_depth`` on, survivors divided by q: "albedo" q = the diffuse albedo max_c rho_c (the slides' 1 - absorption,
  Fig. 5.16) or, for the other kinds, min(1, max channel of the weight); "fixed" q = 1 - alpha; "throughput"
  q = min(max(beta) eta^2, 0.95) (Mitsuba's; eta the product of the relative indices of the refractions so far);
  "pbrt" q = min(max(beta) eta^2, 1) (pbrt-v4's: a path of throughput 1 is never cut, so furnaces of glass or
  mirrors stay exact).

Path lengths follow Mitsuba's max_depth: emission of vertex i counts for i <= max_depth, direct light at x_i when
i + 1 <= max_depth, the next ray when its vertex can still add something (a vertex whose next would add direct
light only, which max_depth forbids, draws none unless its BSDF is a delta). A path is cut after MAX_VERTICES
vertices whatever max_depth says (a closed perfect mirror, whose weight is 1, would never end). A one-sided surface
seen from behind (and not transmitting) ends its path, black.

Random numbers past the camera are independent hashes ``uniform(key, dim_salt(depth, PURPOSE, j))``, except at
the first hit with ``sampler = sobol``: there each pixel's light samples, hemisphere directions, BSDF directions and
(BSDF lobe, roulette) pairs are stratified point sets (:func:`.sobol.path_first_hit_seeds`), computed ahead for the
pixel's run of samples, the light sample's choices of light and piece reusing its point's first coordinate
(:func:`.emitters.split_light_piece_all`; global area sampling's triangle likewise). The camera rays are traced
first, 16 consecutive ones (one pixel's samples) per packet query. Rays leave x from its origin offset along the
normal on the side the new direction leaves (:mod:`.surface`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.emitters import DIRECTIONAL, ENV_CONSTANT, ENV_MAP, POINT, SPOT
from reference_impl.kernels.bsdf import bsdf_eval, bsdf_pdf, bsdf_sample, chooses_lobe, is_delta, sample_eta
from reference_impl.kernels.config import (C_BACK_FACE, C_ESCAPED, C_HEMI_DIRECT, C_INDIRECT, C_LIGHT_SELECT,
                                           C_ROULETTE, C_SHADOW, C_SHADOW_SKIPPED, DIRECT_AREA, DIRECT_BSDF,
                                           DIRECT_GLOBAL_AREA, DIRECT_HEMI_COSINE, DIRECT_HEMI_UNIFORM, DIRECT_MIS,
                                           HEMI_UNIFORM, JIT, JIT_BORROW, M_COSINE_PDF_PI, M_DOUBLE_EMISSION,
                                           M_LIGHT_PDF_IGNORED, M_NO_COSINE, M_RR_NO_REWEIGHT, M_SHADING_NORMAL_SIDE,
                                           RR_ALBEDO, RR_OFF, RR_PBRT, RR_THROUGHPUT, SAMPLER_SOBOL)
from reference_impl.kernels.direct import (connection_ray, emission_weight, emitter_connection, light_choice,
                                           light_connection, light_sample, point_connection, power_weight,
                                           tree_choice)
from reference_impl.kernels.emitters import env_light_pdf, env_radiance
from reference_impl.kernels.cutout import shadow_transmittance, through_holes
from reference_impl.kernels.material import material_at, material_at_nested
from reference_impl.kernels.queries import (TIMING_STRIDE, closest_prim_timed, closest_prims_packets, now_ns,
                                            occluded_timed, ray_buffer)
from reference_impl.kernels.record import record_camera, record_closest, record_occluded
from reference_impl.kernels.rng import dim_salt, uniform
from reference_impl.kernels.sobol import (NOTHING_HELD, PathFirstHitPairs, ahead, held_point, longest_run,
                                          pair_point, path_first_hit_seeds, pixel_run, uniform_2d)
from reference_impl.kernels.shading import geometric_frame, shading_frame, through_map, uv_aligned
from reference_impl.kernels.surface import emission_at, hit_at, offset_origin, surface_hit
from reference_impl.kernels.warps import PI, dot3, sample_hemisphere
from reference_impl.materials import (DIELECTRIC, DIFFUSE, P_ANISOTROPIC, P_METALLIC, P_REFLECTANCE, P_SPEC_TRANS, P_TWO_SIDED,
                                      PRINCIPLED, ROUGHDIELECTRIC, ROW_SIZE, THINDIELECTRIC)
from reference_impl.rng import (BLEND, BSDF_LOBE, BSDF_U1, BSDF_U2, COMPLEMENT_U1, COMPLEMENT_U2, DIRECT_DIR_U1,
                                DIRECT_DIR_U2, ROULETTE)

MAX_VERTICES = 1 << 16
RR_THROUGHPUT_CAP = 0.95  # Mitsuba's path integrator


@njit(**JIT_BORROW)
def connect(mutant, kind, row, uniform_diffuse, mis, conn, transmits, side, n0, n1, n2, sf, lo0, lo1, lo2, later):
    """What connection ``conn`` (:class:`.direct.Connection`) brings through x's BSDF where nothing blocks it: (whether it needs
    a shadow ray at all, N . wi, and Le G f |cos_x| / p with its MIS weight, per channel). The geometric normal N
    decides the side: None where wi is on the side a surface that does not transmit does not reflect from (``side``
    = the side of wo), where the shading frame ``sf`` (:class:`.shading.ShadingFrame`) would call wi a reflection
    and N a transmission or the other way round, or where f = 0; f |cos| in the shading frame (times a map's
    terminator, :func:`.shading.through_map`). With the planted fault "no-cosine", f without |cos_x|; with
    "shading-normal-side", no side test but the shading frame's (light leaks through a leaning shading normal)."""
    wi0, wi1, wi2 = conn.wi0, conn.wi1, conn.wi2
    cos_x = dot3(n0, n1, n2, wi0, wi1, wi2)
    leaks = sf.differs and (mutant & M_SHADING_NORMAL_SIDE) != 0  # planted fault "shading-normal-side"
    if not (conn.needed and cos_x != 0 and (transmits or side * cos_x > 0 or leaks)):
        return False, cos_x, 0.0, 0.0, 0.0
    li0, li1, li2 = dot3(sf.s0, sf.s1, sf.s2, wi0, wi1, wi2), dot3(sf.t0, sf.t1, sf.t2, wi0, wi1, wi2), cos_x
    keep = 1.0
    if sf.differs:
        li2 = dot3(sf.n0, sf.n1, sf.n2, wi0, wi1, wi2)
        if transmits and not leaks and (li2 * lo2 > 0) != (side * cos_x > 0):
            return False, cos_x, 0.0, 0.0, 0.0
        keep = through_map(sf, wi0, wi1, wi2, li2)
        if keep == 0.0:
            return False, cos_x, 0.0, 0.0, 0.0
    f0, f1, f2 = bsdf_eval(kind, row, mutant, lo0, lo1, lo2, li0, li1, li2, later)
    if not (f0 > 0 or f1 > 0 or f2 > 0):
        return False, cos_x, 0.0, 0.0, 0.0
    if sf.perturbed:
        f0, f1, f2 = f0 * keep, f1 * keep, f2 * keep
    if mutant & M_NO_COSINE:  # mutant "no-cosine" (direct light)
        inv_cos = 1.0 / abs(li2)
        f0, f1, f2 = f0 * inv_cos, f1 * inv_cos, f2 * inv_cos
    w = 1.0
    p_l = conn.p_l
    if mis and p_l > 0:
        p_b = bsdf_pdf(kind, row, mutant, uniform_diffuse, lo0, lo1, lo2, li0, li1, li2, later)
        w = power_weight(mutant, p_l, p_b, True)
    return True, cos_x, conn.v0 * f0 * w, conn.v1 * f1 * w, conn.v2 * f2 * w


@njit(**JIT_BORROW)
def shadow_query(scene_ptr, words, floats, ts, queries, sampled_ns, record, ray, spheres):
    """Whether anything blocks the shadow ray ``ray`` (origin, unit direction, t_max: :func:`.direct.connection_ray`),
    the occlusion query (the scene's ``spheres``, then Embree's) timed as :func:`.queries.occluded_timed` times it,
    and recorded where ``record`` is given: (blocked, queries, sampled_ns). Nothing blocks it in a scene without
    geometry (``scene_ptr`` 0)."""
    so0, so1, so2, r0, r1, r2, tfar = ray
    if scene_ptr == 0:
        return False, queries, sampled_ns
    blocked, queries, sampled_ns = occluded_timed(scene_ptr, words, floats, ts, queries, sampled_ns, so0, so1, so2, r0,
                                                  r1, r2, np.float32(tfar), spheres)
    if record is not None:
        record_occluded(record, so0, so1, so2, r0, r1, r2, np.float32(tfar), blocked)
    return blocked, queries, sampled_ns


@njit(**JIT_BORROW)
def next_ray(cfg, kind, row, uniform_diffuse, wanted, u_lobe, u1, u2, u_rr, key, depth, lo, beta, eta2, sf, geo, side,
             x, ox, later):
    """The next ray from x, sampled from the BSDF (:func:`.bsdf.bsdf_sample`, uniforms u_lobe, u1, u2), then Russian
    roulette (module docstring; u_rr, or where it is negative a hash of ``key`` drawn here) and the planted faults of
    the indirect estimate. ``wanted``: whether the next vertex can add anything but direct light (max_depth); a
    sample off a delta lobe goes on either way. ``lo``: wo in the shading frame ``sf`` (:class:`.shading.ShadingFrame`);
    ``geo`` the geometric normal N, which decides the side (a sample the shading frame calls a reflection and N a
    transmission, or the other way round, ends the path: no light leaks through a leaning shading normal); ``beta``
    the throughput so far, ``eta2`` the product of the relative ior^2 of the refractions so far; ``side`` the side
    of wo (+1: N's), ``ox`` x's offset origin on that side. Returns (whether the path goes on, whether roulette (or a weight
    that is zero or not finite) cut it, its direction, origin, the normal on the side it leaves, its throughput,
    eta2, its pdf, whether it is off a delta lobe)."""
    lo0, lo1, lo2 = lo
    sample = bsdf_sample(kind, row, cfg.mutant, uniform_diffuse, lo0, lo1, lo2, u_lobe, u1, u2, later)
    return ray_after_sample(cfg, kind, row, uniform_diffuse, wanted, sample, u_rr, key, depth, lo, beta, eta2, sf, geo,
                            side, x, ox)


@njit(**JIT_BORROW)
def ray_after_sample(cfg, kind, row, uniform_diffuse, wanted, sample, u_rr, key, depth, lo, beta, eta2, sf, geo, side,
                     x, ox):
    """:func:`next_ray` past the BSDF's sample ``sample`` (:func:`.bsdf.bsdf_sample`'s answer): the planted faults
    of the indirect estimate, the direction in world space, its side, Russian roulette; the same answer."""
    mutant = cfg.mutant
    lo0, lo1, lo2 = lo
    b0, b1, b2 = beta
    nx0, nx1, nx2 = geo
    x0, x1, x2 = x
    ok, li0, li1, li2, w0, w1, w2, pdf, delta = sample
    # nothing sampled (below the horizon, a zero weight): the path carries no more light
    if not (ok and (wanted or delta)):
        return False, False, 0.0, 0.0, 1.0, x0, x1, x2, nx0, nx1, nx2, 0.0, 0.0, 0.0, eta2, 0.0, False
    if not delta:
        if mutant & M_NO_COSINE:  # mutant "no-cosine" (indirect light): f / p, without |cos|
            inv_cos = 1.0 / abs(li2)
            w0, w1, w2 = w0 * inv_cos, w1 * inv_cos, w2 * inv_cos
        if (mutant & M_COSINE_PDF_PI) and kind == DIFFUSE and not uniform_diffuse:
            # mutant "cosine-pdf-pi": the cosine-hemisphere pdf taken as cos, not cos / pi
            pdf = pdf * PI
            w0, w1, w2 = w0 / PI, w1 / PI, w2 / PI
    wn0 = li0 * sf.s0 + li1 * sf.t0 + li2 * sf.n0
    wn1 = li0 * sf.s1 + li1 * sf.t1 + li2 * sf.n1
    wn2 = li0 * sf.s2 + li1 * sf.t2 + li2 * sf.n2
    inv_len = 1.0 / math.sqrt(wn0 * wn0 + wn1 * wn1 + wn2 * wn2)
    wn0, wn1, wn2 = wn0 * inv_len, wn1 * inv_len, wn2 * inv_len
    g = li2  # N . w, which decides the side it leaves from
    if sf.differs:
        g = dot3(nx0, nx1, nx2, wn0, wn1, wn2)
        # planted fault "shading-normal-side": the shading frame's side alone
        if not (cfg.mutant & M_SHADING_NORMAL_SIDE) and ((li2 * lo2 > 0) != (g * side > 0) or g == 0):
            return False, False, 0.0, 0.0, 1.0, x0, x1, x2, nx0, nx1, nx2, 0.0, 0.0, 0.0, eta2, 0.0, False
        keep = through_map(sf, wn0, wn1, wn2, li2)
        w0, w1, w2 = w0 * keep, w1 * keep, w2 * keep
    nb0, nb1, nb2 = b0 * w0, b1 * w1, b2 * w2
    eta_rel = sample_eta(kind, row, lo2, li2)
    eta2 *= eta_rel * eta_rel
    if cfg.rr != RR_OFF and depth >= cfg.rr_depth:
        if cfg.rr == RR_THROUGHPUT:
            q = min(max(nb0, nb1, nb2) * eta2, RR_THROUGHPUT_CAP)
        elif cfg.rr == RR_PBRT:
            q = min(max(nb0, nb1, nb2) * eta2, 1.0)
        elif cfg.rr == RR_ALBEDO:
            if kind == DIFFUSE:  # the slides' 1 - absorption: the albedo rho
                q = min(max(row[P_REFLECTANCE], row[P_REFLECTANCE + 1], row[P_REFLECTANCE + 2]), 1.0)
            else:
                q = min(max(w0, w1, w2), 1.0)
        else:
            q = cfg.survival
        if u_rr < 0:
            u_rr = uniform(key, dim_salt(depth, ROULETTE, 0))
        if not (u_rr < q):
            return False, True, 0.0, 0.0, 1.0, x0, x1, x2, nx0, nx1, nx2, 0.0, 0.0, 0.0, eta2, 0.0, False
        if not (mutant & M_RR_NO_REWEIGHT):  # mutant "rr-no-reweight": survivors not divided by q
            inv_q = 1.0 / q
            nb0, nb1, nb2 = nb0 * inv_q, nb1 * inv_q, nb2 * inv_q
    if not ((math.isfinite(nb0) and math.isfinite(nb1) and math.isfinite(nb2)) and (nb0 > 0 or nb1 > 0 or nb2 > 0)):
        return False, True, 0.0, 0.0, 1.0, x0, x1, x2, nx0, nx1, nx2, 0.0, 0.0, 0.0, eta2, 0.0, False
    if g * side > 0:  # leaves on the side of wo
        pn0, pn1, pn2 = side * nx0, side * nx1, side * nx2
        o0, o1, o2 = ox
    else:
        pn0, pn1, pn2 = -side * nx0, -side * nx1, -side * nx2
        o0, o1, o2 = offset_origin(cfg.offset_scene, x0, x1, x2, pn0, pn1, pn2)
    return True, False, wn0, wn1, wn2, o0, o1, o2, pn0, pn1, pn2, nb0, nb1, nb2, eta2, pdf, delta


@njit(**JIT)
def trace_paths(state, scene_ptr, scene, lights, surfaces, materials, cfg, radiance, counters, timing, film_samples,
                emitters, other_kinds, textures=None, record=None, shading=None, spheres=None, nested=None,
                masks=None, later=None, tree=None):
    """Trace every camera path of ``state`` (the wavefront's ``camera_paths`` wrote them) to its end, one at a time
    (module docstring), adding each path's radiance to ``radiance[root]``.

    ``scene``, ``lights``, ``surfaces``, ``materials`` (indexed by the scene's material ids): the scene's tables
    (:mod:`.records`); ``emitters``: the tables of the emitters that are not surfaces, or None, which compiles
    every branch for them out (numba decides ``emitters is not None`` from the argument's type); ``other_kinds``
    likewise: None where every material is diffuse, which compiles the BSDF door's other kinds out (a loop of its
    own for Lambertian scenes, from the same source), else True; ``textures`` likewise: None where no area light is
    textured (every Le is its triangle's row: the lookups compiled out), else the materials' texture tables;
    ``shading`` likewise: None where no triangle has vertex normals and no material a normal or bump map (every
    frame the geometric one, :func:`.shading.geometric_frame`, whose constant flags fold the side tests away), else
    True (:func:`.shading.shading_frame`); ``spheres`` likewise: None in a scene without spheres (the queries' sphere
    tests compiled out), else ``scene.sphere``; ``nested`` likewise: None where no material is made of others, else
    True (the material step resolves them, :func:`.material.material_at_nested`); ``masks`` likewise: None where no
    material is a mask, else True (rays pass their holes and shadow rays cross them, :mod:`.cutout`); ``later``
    likewise: None where no material is a rough plastic or a principled (the BSDF door's branches for them compiled
    out, :mod:`.bsdf`), else True. The integrator gives ``textures`` and ``spheres`` on every scene
    (``integrator._Context.features``): one specialization whether a scene has them or not.
    ``cfg``: the render's :class:`.config.KernelConfig` (its ``depth`` is not used: each vertex knows its own).
    ``film_samples`` (:class:`.records.FilmSamples`): the camera samples, for the stratified sampler.
    ``timing[0]`` receives the nanoseconds spent in Embree (one query in ``TIMING_STRIDE`` timed), ``timing[1]``
    the number of queries. ``record``: None in a render (compiled out), or buffers that receive every query's ray
    and answer (:mod:`.record`, for :mod:`reference_impl.replay`)."""
    root, key, origin, direction, o32, d32, beta, _pdf_dir, _env_pdf = state
    emission, light_id, prim_to_tri, tri_normal = scene.emission, scene.light_id, scene.prim_to_tri, scene.normal
    sphere_base = prim_to_tri.shape[0] - scene.sphere.shape[0]  # spheres: tested beside Embree's triangles (.queries)
    light_pmf = lights.pmf
    nd = cfg.shadow_rays
    inv_nd = 1.0 / nd  # exact for Nd = 1, 2, 4, ...
    direct = cfg.direct
    mutant = cfg.mutant
    max_depth = cfg.max_depth
    num_lights = cfg.num_lights
    mis = direct == DIRECT_MIS
    light_points = direct == DIRECT_AREA or mis  # light k with pdf(k), then a point on it or its own sample
    global_area = direct == DIRECT_GLOBAL_AREA
    hemi_direct = direct == DIRECT_HEMI_COSINE or direct == DIRECT_HEMI_UNIFORM
    if other_kinds is not None:  # glossy scenes take neither (integrator._engine): compiled out of their loop
        global_area = False
        hemi_direct = False
    # whether emission met past the camera hit counts (weighted with mis): the strategies that draw no light sample
    # for it; with the planted fault "double-emission" at every hit, unweighted
    double_emission = (mutant & M_DOUBLE_EMISSION) != 0
    finds_emission = mis or direct == DIRECT_BSDF
    # the emitters the strategy cannot find, each with its own sample once per hit
    own_samples = direct == DIRECT_BSDF or hemi_direct or global_area
    uniform_diffuse = cfg.hemisphere == HEMI_UNIFORM
    sobol = cfg.sampler == SAMPLER_SOBOL
    film_pixel, film_sample, seed_key = film_samples.pixel, film_samples.sample, film_samples.seed_key
    # The first hit's points of each pixel's run of samples, computed ahead (kernels.sobol.sobol_points).
    fh = path_first_hit_seeds(seed_key, 0, 1, 1)
    fh_pixel = -1
    si = 0
    size = longest_run(film_samples) * nd if sobol else 0
    lx, ly = np.empty(size), np.empty(size)
    dx, dy = np.empty(size), np.empty(size)
    bx, by = np.empty(size), np.empty(size)
    cx, cy = np.empty(size), np.empty(size)
    held = PathFirstHitPairs(NOTHING_HELD, NOTHING_HELD, NOTHING_HELD, NOTHING_HELD)
    # the first hits' BSDF and roulette points are computed ahead only where a first hit's next ray can be drawn
    # without a delta lobe (else the few a delta material draws come from their seeds: the same points)
    next_ray_drawn = finds_emission or max_depth == -1 or max_depth >= 3
    # the (lobe, roulette) pair only where a first hit reads it: a lobe of a glossy scene's dielectric or plastic, or
    # roulette played at the first hit
    first_roulette = cfg.rr != RR_OFF and cfg.rr_depth <= 1
    lobe_roulette_drawn = first_roulette
    if other_kinds is not None:
        lobe_roulette_drawn = True
    row = np.empty(ROW_SIZE)  # the material step's parameters at the current vertex (and a rough plastic's table)
    words, floats = ray_buffer()
    ts = np.zeros(2, np.int64)
    queries = 0
    sampled_ns = 0
    clock_ns = 1 << 62  # the cheapest of a few back-to-back clock reads: what a timed interval holds besides Embree
    for _ in range(8):
        t_start = now_ns(ts)
        clock_ns = min(clock_ns, now_ns(ts) - t_start)
    # The camera rays first, 16 of one pixel's samples per packet query (the same hits as one query per ray).
    n = len(root)
    first_prim = np.full(n, -1, np.int32)
    packet_ns = 0
    if scene_ptr != 0:
        t_start = now_ns(ts)
        closest_prims_packets(scene_ptr, cfg.packet_width, o32, d32, first_prim, spheres, sphere_base)
        packet_ns = now_ns(ts) - t_start
        if record is not None:
            record_camera(record, o32, d32, first_prim)

    count_back_face = 0
    count_escaped = 0
    count_hemi_direct = 0
    count_indirect = 0
    count_light_select = 0
    count_roulette = 0
    count_shadow = 0
    count_shadow_skipped = 0
    for i in range(n):
        r = root[i]
        k = key[i]
        o0, o1, o2 = origin[i, 0], origin[i, 1], origin[i, 2]
        d0, d1, d2 = direction[i, 0], direction[i, 1], direction[i, 2]
        b0, b1, b2 = beta[i, 0], beta[i, 1], beta[i, 2]
        rad0, rad1, rad2 = radiance[r, 0], radiance[r, 1], radiance[r, 2]  # summed here, stored once
        depth = 1
        prev_delta = True  # the camera ray: what it finds, no light sample could have found
        prev_pdf = 0.0  # the BSDF's solid-angle pdf of the ray that reached this vertex
        pn0, pn1, pn2 = 0.0, 0.0, 1.0  # the previous vertex's normal on the side the ray left (env_light_pdf)
        # the previous vertex (the light tree's pmf, a sphere light's cone: light_density) and its N (the tree's)
        px0, px1, px2, qn0, qn1, qn2 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        eta2 = 1.0  # product of the relative ior^2 of the refractions so far (rr = "throughput", "pbrt")
        if sobol:
            if film_pixel[r] != fh_pixel:  # a pixel's samples come together: its seeds and points once
                fh_pixel = film_pixel[r]
                fh = path_first_hit_seeds(seed_key, fh_pixel, cfg.spp, nd)
                first, m_run = film_sample[r], pixel_run(film_pixel, film_sample, r)
                held = PathFirstHitPairs(ahead(fh.light, first * nd, m_run * nd, lx, ly, not hemi_direct),
                                         ahead(fh.direction, first * nd, m_run * nd, dx, dy, hemi_direct),
                                         ahead(fh.bsdf, first, m_run, bx, by, next_ray_drawn),
                                         ahead(fh.lobe_roulette, first, m_run, cx, cy,
                                               next_ray_drawn and lobe_roulette_drawn))
            si = film_sample[r]
        while True:
            sob = sobol and depth == 1
            counts = prev_delta or finds_emission or double_emission  # emission found here counts
            weighted = mis and not (prev_delta or double_emission)  # ... with the MIS weight
            if depth == 1:
                p = np.int64(first_prim[i])
            elif scene_ptr != 0:
                p, queries, sampled_ns = closest_prim_timed(scene_ptr, words, floats, ts, queries, sampled_ns, o0, o1,
                                                            o2, d0, d1, d2, spheres, sphere_base)
                if record is not None:
                    record_closest(record, o0, o1, o2, d0, d1, d2, p)
            else:
                p = -1
            travelled = 0.0  # the distance to the last query's origin: past a mask's holes (kernels/cutout.py)
            if masks is not None and p >= 0:
                p, o0, o1, o2, travelled, queries, sampled_ns = through_holes(
                    cfg, scene_ptr, words, floats, ts, queries, sampled_ns, scene, materials, spheres, sphere_base, p,
                    k, depth, o0, o1, o2, d0, d1, d2)
            if p < 0:
                count_escaped += 1
                if emitters is not None:
                    if cfg.env_light >= 0 and counts:  # the environment, seen by the escaping ray
                        e0, e1, e2 = env_radiance(cfg, emitters, d0, d1, d2)
                        w = 1.0
                        if weighted:
                            p_env = env_light_pdf(cfg, lights, emitters, d0, d1, d2, pn0, pn1, pn2)
                            w = power_weight(mutant, prev_pdf, p_env, False) if p_env > 0 else 1.0
                        rad0 += b0 * e0 * w
                        rad1 += b1 * e1 * w
                        rad2 += b2 * e2 * w
                break
            hit = surface_hit(scene, p, o0, o1, o2, d0, d1, d2)
            tri, t, cos_out = hit.tri, hit.t + travelled, hit.cos_out
            if counts:
                light = light_id[tri]
                if light >= 0 and cos_out > 0:
                    w = 1.0
                    if weighted:  # pdf(k) (the tree's: pdf(k | x) at the vertex the ray left) and the light's density
                        w = emission_weight(lights, tree, light, nd, prev_pdf, (px0, px1, px2), (qn0, qn1, qn2), hit,
                                            t, cos_out, mutant)
                    le0, le1, le2 = emission_at(scene, textures, tri, hit.x0, hit.x1, hit.x2, mutant)
                    rad0 += b0 * le0 * w
                    rad1 += b1 * le1 * w
                    rad2 += b2 * le2 * w
            if not (max_depth == -1 or depth + 1 <= max_depth) or depth >= MAX_VERTICES:
                break
            if nested is None:
                kind = material_at(materials, hit, row, mutant)  # the material step: the BSDF's kind and parameters
            else:  # ... of the material a blend or a twosided is at x
                kind = material_at_nested(materials, hit, row, mutant, uniform(k, dim_salt(depth, BLEND, 0)))
            if other_kinds is None:
                kind = DIFFUSE  # what the table says, known to the compiler
            transmits = kind == DIELECTRIC or kind == ROUGHDIELECTRIC or kind == THINDIELECTRIC
            if kind == PRINCIPLED:  # light crosses it where its transmission lobe has a weight at x
                transmits = (1.0 - row[P_METALLIC]) * row[P_SPEC_TRANS] > 0
            lobed = chooses_lobe(kind, transmits)  # the kinds that choose a lobe read u_lobe
            if not (cos_out > 0 or row[P_TWO_SIDED] != 0 or transmits):
                count_back_face += 1  # the back of a one-sided surface: black
                break
            x0, x1, x2 = hit.x0, hit.x1, hit.x2
            nx0, nx1, nx2 = hit.n0, hit.n1, hit.n2
            side = 1.0 if cos_out > 0 else -1.0  # the side of wo
            ns0, ns1, ns2 = side * nx0, side * nx1, side * nx2
            ox0, ox1, ox2 = offset_origin(cfg.offset_scene, x0, x1, x2, ns0, ns1, ns2)
            # The BSDF's local frame: the shading frame (vertex normals, a normal or bump map; else N's)
            wo0, wo1, wo2 = -d0, -d1, -d2
            if shading is None:
                sf = geometric_frame(hit)
            else:
                sf = shading_frame(scene, materials, hit, row, wo0, wo1, wo2, mutant)
                if kind == PRINCIPLED and row[P_ANISOTROPIC] != 0.0:  # its lobe's axes along dp/du and n x dp/du
                    sf = uv_aligned(scene, hit, sf)
            s0, s1, s2, t0, t1, t2 = sf.s0, sf.s1, sf.s2, sf.t0, sf.t1, sf.t2
            lo0, lo1 = dot3(s0, s1, s2, wo0, wo1, wo2), dot3(t0, t1, t2, wo0, wo1, wo2)
            lo2 = dot3(sf.n0, sf.n1, sf.n2, wo0, wo1, wo2) if sf.differs else cos_out
            delta_bsdf = is_delta(kind)

            # The next ray, sampled from the BSDF, then Russian roulette (next_ray), where the next vertex can add
            # more than direct light (max_depth) or the BSDF has a delta lobe. On a Lambertian scene it is drawn
            # before the direct light's queries (the random numbers are counter-based, so the order of drawing
            # changes nothing), which gives the processor independent arithmetic to overlap with them; on a glossy
            # one after them, where its state would be kept across the BSDF's calls.
            wanted = finds_emission or max_depth == -1 or depth + 2 <= max_depth
            drawn = wanted or delta_bsdf
            if drawn:
                if sob:
                    bu1, bu2 = pair_point(held_point(fh.bsdf, bx, by, held.bsdf, si), si)
                    u_lobe, u_rr = 0.0, -1.0
                    if lobed or first_roulette:  # only they read the pair
                        u_lobe, u_rr = pair_point(held_point(fh.lobe_roulette, cx, cy, held.lobe_roulette, si), si)
                else:
                    u_lobe = uniform(k, dim_salt(depth, BSDF_LOBE, 0)) if lobed else 0.0  # only they read it
                    bu1 = uniform(k, dim_salt(depth, BSDF_U1, 0))
                    bu2 = uniform(k, dim_salt(depth, BSDF_U2, 0))
                    u_rr = -1.0  # drawn by next_ray only where roulette is played
            # the vertex as next_ray takes it (tuples of numbers only: no array in them, no reference count)
            lo, thru, geo = (lo0, lo1, lo2), (b0, b1, b2), (nx0, nx1, nx2)
            xs, oxs = (x0, x1, x2), (ox0, ox1, ox2)
            go_on, cut = False, False
            if other_kinds is None:
                if drawn:
                    (go_on, cut, n0, n1, n2, m0, m1, m2, pn0, pn1, pn2, nb0, nb1, nb2, eta2, pdf,
                     delta) = next_ray(cfg, kind, row, uniform_diffuse, wanted, u_lobe, bu1, bu2, u_rr, k, depth,
                                       lo, thru, eta2, sf, geo, side, xs, oxs, later)

            # Direct light (none at a delta BSDF).
            if not delta_bsdf:
                tot0, tot1, tot2 = 0.0, 0.0, 0.0
                if hemi_direct:  # Nd directions about N, and the emission each finds (Fig. 5.12)
                    for j in range(nd):
                        u_a, u_b = uniform_2d(sob, held_point(fh.direction, dx, dy, held.direction, si * nd + j),
                                              si * nd + j, k, j, depth, DIRECT_DIR_U1, DIRECT_DIR_U2)
                        h0, h1, h2, cos_h, pdf_h = sample_hemisphere(direct == DIRECT_HEMI_COSINE, u_a, u_b, ns0,
                                                                     ns1, ns2)
                        count_hemi_direct += 1
                        hp = np.int64(-1)
                        if scene_ptr != 0:
                            hp, queries, sampled_ns = closest_prim_timed(scene_ptr, words, floats, ts, queries,
                                                                         sampled_ns, ox0, ox1, ox2, h0, h1, h2,
                                                                         spheres, sphere_base)
                            if record is not None:
                                record_closest(record, ox0, ox1, ox2, h0, h1, h2, hp)
                        if not pdf_h > 0:
                            continue
                        if hp < 0:
                            if emitters is not None:
                                if cfg.env_light >= 0:  # the environment, found by Psi
                                    le0, le1, le2 = env_radiance(cfg, emitters, h0, h1, h2)
                                else:
                                    continue
                            else:
                                continue
                        else:
                            htri = prim_to_tri[hp]
                            if light_id[htri] < 0:
                                continue  # not an emitter
                            if spheres is not None and hp >= sphere_base:  # a sphere light: its normal at the point
                                _t, q0, q1, q2, hn0, hn1, hn2, _c = hit_at(scene, htri, ox0, ox1, ox2, h0, h1, h2)
                            else:
                                hn0, hn1, hn2 = tri_normal[htri, 0], tri_normal[htri, 1], tri_normal[htri, 2]
                            if not dot3(h0, h1, h2, hn0, hn1, hn2) < 0:
                                continue  # not an emitter's front side
                            le0, le1, le2 = emission[htri, 0], emission[htri, 1], emission[htri, 2]
                            if textures is not None:  # Le at the point Psi found on a textured light
                                _t, q0, q1, q2, _n0, _n1, _n2, _c = hit_at(scene, htri, ox0, ox1, ox2, h0, h1, h2)
                                le0, le1, le2 = emission_at(scene, textures, htri, q0, q1, q2, mutant)
                        hl0, hl1, hl2 = dot3(s0, s1, s2, h0, h1, h2), dot3(t0, t1, t2, h0, h1, h2), side * cos_h
                        keep = 1.0
                        if sf.differs:  # Psi is on wo's side of N: the shading frame's cosine, a map's terminator
                            hl2 = dot3(sf.n0, sf.n1, sf.n2, h0, h1, h2)
                            keep = through_map(sf, h0, h1, h2, hl2)
                        f0, f1, f2 = bsdf_eval(kind, row, mutant, lo0, lo1, lo2, hl0, hl1, hl2, later)
                        f0, f1, f2 = f0 * keep, f1 * keep, f2 * keep
                        inv_p = 1.0 / pdf_h
                        tot0 += le0 * f0 * inv_p
                        tot1 += le1 * f1 * inv_p
                        tot2 += le2 * f2 * inv_p
                # Nd points on the lights (or on every surface), then the emitters the strategy cannot find, each
                # its own sample once (pdf(k) = 1): one connection each, through the BSDF, and its shadow ray.
                # light samples from N's side only where x does not transmit (and, with the planted fault
                # "shading-normal-side", the shading frame decides instead: connect)
                front_only = not transmits and not (sf.differs and (mutant & M_SHADING_NORMAL_SIDE) != 0)
                points = nd if light_points or global_area else 0
                own = 0
                if emitters is not None:
                    if own_samples:
                        own = len(emitters.kind)
                ct0, ct1, ct2 = 0.0, 0.0, 0.0
                for j in range(points + own):
                    if j < points:
                        if global_area:
                            _sel, gtri, y0, y1, y2, pdf_area = light_sample(
                                cfg, sob, held_point(fh.light, lx, ly, held.light, si * nd + j), si, j, k, depth,
                                scene, lights, surfaces)
                            conn = point_connection(cfg, scene, textures, gtri, y0, y1, y2, pdf_area, x0, x1, x2)
                        else:
                            u_a, u_b = 0.0, 0.0
                            if sob:  # one 2D point: its first coordinate picks the light and the piece too
                                u_a, u_b = pair_point(held_point(fh.light, lx, ly, held.light, si * nd + j),
                                                      si * nd + j)
                            if tree is not None:  # pdf(k | x) from the light tree (kernels/light_tree.py)
                                sel, tree_pmf_k, piece, u1, u2 = tree_choice(cfg, lights, tree, sob, u_a, u_b, k,
                                                                             depth, j, x0, x1, x2, nx0, nx1, nx2,
                                                                             mutant)
                                if sel < 0:  # nothing in the tree can light x
                                    continue
                            else:
                                sel, piece, u1, u2 = light_choice(cfg, lights, sob, u_a, u_b, k, depth, j)
                            if num_lights > 1:
                                count_light_select += 1
                            # mutant "light-pdf-ignored": pdf(y|k) alone
                            pdf_select = light_pmf[sel] if tree is None else tree_pmf_k
                            if mutant & M_LIGHT_PDF_IGNORED:
                                pdf_select = 1.0
                            conn = light_connection(cfg, scene, textures, lights, emitters, sel, piece, pdf_select, u1,
                                                    u2, x0, x1, x2, ns0, ns1, ns2, front_only)
                    elif emitters is not None:
                        e = j - points
                        ekind = emitters.kind[e]
                        if not (ekind == POINT or ekind == SPOT or ekind == DIRECTIONAL
                                or (global_area and (ekind == ENV_CONSTANT or ekind == ENV_MAP))):
                            continue
                        u1 = uniform(k, dim_salt(depth, COMPLEMENT_U1, e))
                        u2 = uniform(k, dim_salt(depth, COMPLEMENT_U2, e))
                        conn = emitter_connection(cfg, emitters, e, 1.0, u1, u2, x0, x1, x2, ns0, ns1, ns2,
                                                  front_only)
                    else:
                        continue
                    needed, cos_x, v0, v1, v2 = connect(mutant, kind, row, uniform_diffuse, mis and j < points, conn,
                                                        transmits, side, nx0, nx1, nx2, sf, lo0, lo1, lo2, later)
                    if not needed:
                        count_shadow_skipped += 1
                        continue
                    count_shadow += 1
                    ray = connection_ray(cfg, conn, cos_x, not front_only, x0, x1, x2, nx0, nx1, nx2, ox0, ox1, ox2)
                    if masks is None:
                        blocked, queries, sampled_ns = shadow_query(scene_ptr, words, floats, ts, queries, sampled_ns,
                                                                    record, ray, spheres)
                        if blocked:
                            continue
                    else:  # the masks it crosses let 1 - opacity through (kernels/cutout.py)
                        tr, queries, sampled_ns = shadow_transmittance(cfg, scene_ptr, words, floats, ts, queries,
                                                                       sampled_ns, scene, materials, spheres,
                                                                       sphere_base, ray)
                        if tr == 0.0:
                            continue
                        v0, v1, v2 = v0 * tr, v1 * tr, v2 * tr
                    if j < points:
                        tot0 += v0
                        tot1 += v1
                        tot2 += v2
                    else:
                        ct0 += v0
                        ct1 += v1
                        ct2 += v2
                rad0 += b0 * (tot0 * inv_nd)
                rad1 += b1 * (tot1 * inv_nd)
                rad2 += b2 * (tot2 * inv_nd)
                if own > 0:
                    rad0 += b0 * ct0
                    rad1 += b1 * ct1
                    rad2 += b2 * ct2

            if other_kinds is not None:
                if drawn:
                    (go_on, cut, n0, n1, n2, m0, m1, m2, pn0, pn1, pn2, nb0, nb1, nb2, eta2, pdf,
                     delta) = next_ray(cfg, kind, row, uniform_diffuse, wanted, u_lobe, bu1, bu2, u_rr, k, depth,
                                       lo, thru, eta2, sf, geo, side, xs, oxs, later)
            count_roulette += cut
            if not go_on:
                break
            count_indirect += 1
            d0, d1, d2 = n0, n1, n2
            o0, o1, o2 = m0, m1, m2
            b0, b1, b2 = nb0, nb1, nb2
            prev_delta = delta
            prev_pdf = pdf
            px0, px1, px2 = x0, x1, x2
            if tree is not None:
                qn0, qn1, qn2 = nx0, nx1, nx2
            depth += 1
        radiance[r, 0], radiance[r, 1], radiance[r, 2] = rad0, rad1, rad2
    counters[C_BACK_FACE] += count_back_face
    counters[C_ESCAPED] += count_escaped
    counters[C_HEMI_DIRECT] += count_hemi_direct
    counters[C_INDIRECT] += count_indirect
    counters[C_LIGHT_SELECT] += count_light_select
    counters[C_ROULETTE] += count_roulette
    counters[C_SHADOW] += count_shadow
    counters[C_SHADOW_SKIPPED] += count_shadow_skipped
    timed = queries // TIMING_STRIDE  # the queries closest_prim_timed / occluded_timed timed
    timing[0] += max(sampled_ns - timed * clock_ns, 0) * TIMING_STRIDE + packet_ns
    timing[1] += queries + n


__all__ = ["MAX_VERTICES", "connect", "next_ray", "ray_after_sample", "shadow_query", "trace_paths"]
