"""Viewing rays (``computeImage`` of Fig. 5.16): Np per pixel, through the pixel filter h, from the camera's model
(:class:`.records.CameraRecord`: :class:`reference_impl.Camera`'s pinhole, :class:`~reference_impl.camera.
ThinLensCamera`, :class:`~reference_impl.camera.OrthographicCamera`, each ``generate_rays`` of its own) and
:class:`PixelFilter`'s samples.

    film point   p = pixel centre + (dx, dy),  (dx, dy) ~ h / int h, one coordinate per uniform u:
                 box u - 1/2; tent sqrt(2 u) - 1 below u = 1/2, else 1 - sqrt(2 (1 - u)); Gaussian from its table
    weight       w = h(p) / (pdf(p) int h) = 1 for box and tent (the Gaussian's comes with its table's samples)
    perspective  from the eye along normalize(frame l),  l = ((1 - 2 p_x / W) tan_x, (1 - 2 p_y / H) tan_y, 1)
    thin lens    from eye + frame a along normalize(frame (f l - a)): a = r (disk point, 0), the disk point
                 Shirley and Chiu's concentric map of two uniforms (pdf 1 / (pi r^2) per unit area of the
                 aperture), f = focus_distance, so that every ray of p meets the plane z_cam = f at f l (Mitsuba's
                 ``thinlens``); weight 1
    orthographic from eye + frame ((1 - 2 p_x / W) half_x, (1 - 2 p_y / H) half_y, 0) along frame's +z
                 (Mitsuba's ``orthographic``); weight 1

Planted faults (bits of :data:`reference_impl.kernels.config.MUTANT_BITS`), each place marked by a comment:
"camera-half-pixel", "lens-sampled-on-square", "focus-along-ray", "orthographic-origin-not-offset".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from reference_impl.kernels.config import (FILTER_BOX, FILTER_GAUSSIAN, JIT, M_CAMERA_HALF_PIXEL, M_FOCUS_ALONG_RAY,
                                           M_LENS_SQUARE, M_ORTHO_ORIGIN_NOT_OFFSET, SAMPLER_SOBOL)
from reference_impl.kernels.records import ORTHOGRAPHIC, THINLENS
from reference_impl.kernels.rng import dim_salt, path_key, pixel_key, uniform
from reference_impl.kernels.sobol import pixel_run, sobol_points, sobol_seeds
from reference_impl.kernels.warps import concentric_disk
from reference_impl.rng import FILM_X, FILM_Y, LENS_U1, LENS_U2


@njit(**JIT)
def filter_sample(kind, u):
    """PixelFilter.sample_1d of the box and tent filters for one uniform: (offset, weight)."""
    if kind == FILTER_BOX:
        return u - 0.5, 1.0
    x = math.sqrt(2.0 * u) - 1.0 if u < 0.5 else 1.0 - math.sqrt(2.0 * (1.0 - u))
    return x, 1.0


@njit(**JIT)
def camera_paths(samples, cfg, camera, pixel_filter, out):
    """The viewing rays of the camera samples ``samples`` (:class:`.records.FilmSamples`; integrator's
    _trace_camera_paths, the cameras' generate_rays) through ``camera`` (:class:`.records.CameraRecord`).

    Box and tent filter offsets are drawn here (``cfg.sampler`` sobol: from the pixel's stratified set, index
    ``sample``); the Gaussian's (a table lookup and exp) come in ``pixel_filter`` (:class:`.records.FilterSamples`,
    from PixelFilter.sample), so that numpy's exp, not libm's, gives their bits. ``cfg``: the pass's
    :class:`.config.KernelConfig` (its spp, sampler and the cameras' planted faults). A thin lens's aperture
    point takes two uniforms of the path's key (dimensions ``LENS_U1``, ``LENS_U2`` at depth 0), also with the
    stratified sampler.
    Writes the wavefront ``out`` (root, key, origin, direction, origin32, direction32, beta, pdf_dir, env_pdf; the
    last is not written: the viewing ray's hit counts emission unweighted): root i for
    sample i, float64 origins and unit directions with their float32 copies for Embree, and the throughput (the
    filter weight in all three channels).
    """
    pixel, sample, seed_key = samples.pixel, samples.sample, samples.seed_key
    spp = cfg.spp
    sobol = cfg.sampler == SAMPLER_SOBOL
    mutant = cfg.mutant
    half_pixel = (mutant & M_CAMERA_HALF_PIXEL) != 0
    filter_kind = pixel_filter.kind
    pre_dx, pre_dy, pre_w = pixel_filter.dx, pixel_filter.dy, pixel_filter.weight
    width, height, tan_x, tan_y = camera.width, camera.height, camera.tan_x, camera.tan_y
    frame, eye = camera.frame, camera.eye
    model = camera.model
    salt_lens_1, salt_lens_2 = dim_salt(0, LENS_U1, 0), dim_salt(0, LENS_U2, 0)
    root, key, origin, direction, o32, d32, beta, pdf_dir, _env_pdf = out
    n = len(pixel)
    salt_x = dim_salt(0, FILM_X, 0)
    salt_y = dim_salt(0, FILM_Y, 0)
    stratified = sobol and filter_kind != FILTER_GAUSSIAN
    film_u = np.empty(n if stratified else 0)
    film_v = np.empty(n if stratified else 0)
    i = 0
    while stratified and i < n:  # each pixel's run of consecutive samples at once (sobol_points)
        m = pixel_run(pixel, sample, i)
        sobol_points(sobol_seeds(pixel_key(seed_key, pixel[i]), salt_x, spp), sample[i], m, film_u, film_v, i)
        i += m
    for i in range(n):
        k = path_key(seed_key, np.uint64(pixel[i]) * np.uint64(spp) + np.uint64(sample[i]))
        key[i] = k
        if filter_kind == FILTER_GAUSSIAN:
            dx, dy, w = pre_dx[i], pre_dy[i], pre_w[i]
        else:
            if sobol:
                ux, uy = film_u[i], film_v[i]
            else:
                ux, uy = uniform(k, salt_x), uniform(k, salt_y)
            dx, wx = filter_sample(filter_kind, ux)
            dy, wy = filter_sample(filter_kind, uy)
            w = wx * wy
        film_x = np.float64(pixel[i] % width) + 0.5 + dx
        film_y = np.float64(pixel[i] // width) + 0.5 + dy
        if half_pixel:  # mutant "camera-half-pixel"
            film_x, film_y = film_x + 0.5, film_y + 0.5
        o0, o1, o2 = eye[0], eye[1], eye[2]
        if model == ORTHOGRAPHIC:
            c0 = (1.0 - 2.0 * film_x / width) * camera.half_x
            c1 = (1.0 - 2.0 * film_y / height) * camera.half_y
            if mutant & M_ORTHO_ORIGIN_NOT_OFFSET:  # mutant "orthographic-origin-not-offset"
                c0, c1 = 0.0, 0.0
            o0 += c0 * frame[0, 0] + c1 * frame[0, 1]
            o1 += c0 * frame[1, 0] + c1 * frame[1, 1]
            o2 += c0 * frame[2, 0] + c1 * frame[2, 1]
            d0, d1, d2 = frame[0, 2], frame[1, 2], frame[2, 2]
        else:
            l0 = (1.0 - 2.0 * film_x / width) * tan_x
            l1 = (1.0 - 2.0 * film_y / height) * tan_y
            l2 = 1.0
            if model == THINLENS:
                ua, ub = uniform(k, salt_lens_1), uniform(k, salt_lens_2)
                if mutant & M_LENS_SQUARE:  # mutant "lens-sampled-on-square"
                    a0, a1 = 2.0 * ua - 1.0, 2.0 * ub - 1.0
                else:
                    a0, a1 = concentric_disk(ua, ub)
                a0, a1 = a0 * camera.aperture_radius, a1 * camera.aperture_radius
                f = camera.focus_distance
                if mutant & M_FOCUS_ALONG_RAY:  # mutant "focus-along-ray": f along the ray, not along the axis
                    f = f / math.sqrt(l0 * l0 + l1 * l1 + 1.0)
                l0, l1, l2 = f * l0 - a0, f * l1 - a1, f
                o0 += a0 * frame[0, 0] + a1 * frame[0, 1]
                o1 += a0 * frame[1, 0] + a1 * frame[1, 1]
                o2 += a0 * frame[2, 0] + a1 * frame[2, 1]
            d0 = l0 * frame[0, 0] + l1 * frame[0, 1] + l2 * frame[0, 2]
            d1 = l0 * frame[1, 0] + l1 * frame[1, 1] + l2 * frame[1, 2]
            d2 = l0 * frame[2, 0] + l1 * frame[2, 1] + l2 * frame[2, 2]
            norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            inv_norm = 1.0 / norm
            d0, d1, d2 = d0 * inv_norm, d1 * inv_norm, d2 * inv_norm
        direction[i, 0], direction[i, 1], direction[i, 2] = d0, d1, d2
        d32[i, 0], d32[i, 1], d32[i, 2] = d0, d1, d2
        origin[i, 0], origin[i, 1], origin[i, 2] = o0, o1, o2
        o32[i, 0], o32[i, 1], o32[i, 2] = o0, o1, o2
        beta[i, 0], beta[i, 1], beta[i, 2] = w, w, w
        root[i] = i
        pdf_dir[i] = 0.0
