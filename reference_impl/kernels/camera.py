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

from reference_impl.kernels.config import (FILTER_BOX, FILTER_GAUSSIAN, JIT, JIT_BORROW, M_CAMERA_HALF_PIXEL,
                                           M_FOCUS_ALONG_RAY, M_LENS_SQUARE, M_ORTHO_ORIGIN_NOT_OFFSET, SAMPLER_SOBOL)
from reference_impl.kernels.records import ORTHOGRAPHIC, PERSPECTIVE, THINLENS
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


@njit(**JIT_BORROW)
def film_direction(film_x, film_y, width, height, tan_x, tan_y):
    """(l_x, l_y) of the direction l = ((1 - 2 p_x / W) tan_x, (1 - 2 p_y / H) tan_y, 1) through film point p, in the
    camera's frame; with the half-widths of an orthographic film in place of the tangents, the origin's offset."""
    return (1.0 - 2.0 * film_x / width) * tan_x, (1.0 - 2.0 * film_y / height) * tan_y


@njit(**JIT_BORROW)
def unit_frame_direction(f00, f01, f02, f10, f11, f12, f20, f21, f22, l0, l1, l2):
    """normalize(frame l), the frame's rows (f00, f01, f02) .. (f20, f21, f22): one square root, one division."""
    d0 = l0 * f00 + l1 * f01 + l2 * f02
    d1 = l0 * f10 + l1 * f11 + l2 * f12
    d2 = l0 * f20 + l1 * f21 + l2 * f22
    inv_norm = 1.0 / math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return d0 * inv_norm, d1 * inv_norm, d2 * inv_norm


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
    # 1. the film points, their filter weights and the paths' keys
    film_x, film_y, weight = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):  # in a loop of its own, which LLVM vectorises
        key[i] = path_key(seed_key, np.uint64(pixel[i]) * np.uint64(spp) + np.uint64(sample[i]))
    last_pixel, column, row = -1, 0.0, 0.0
    for i in range(n):
        if pixel[i] != last_pixel:  # a pixel's samples come together: its column and row once
            last_pixel = pixel[i]
            column, row = np.float64(last_pixel % width), np.float64(last_pixel // width)
        k = key[i]
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
        fx = column + 0.5 + dx
        fy = row + 0.5 + dy
        if half_pixel:  # mutant "camera-half-pixel"
            fx, fy = fx + 0.5, fy + 0.5
        film_x[i], film_y[i], weight[i] = fx, fy, w
    f00, f01, f02 = frame[0, 0], frame[0, 1], frame[0, 2]
    f10, f11, f12 = frame[1, 0], frame[1, 1], frame[1, 2]
    f20, f21, f22 = frame[2, 0], frame[2, 1], frame[2, 2]
    e0, e1, e2 = eye[0], eye[1], eye[2]
    # 2. the rays: the pinhole's in a loop over one array per coordinate, which LLVM vectorises (an array of rows
    # (n, 3) it does not: docs/performance.md, "Camera rays in arrays of coordinates"); the others one by one
    ray_x, ray_y, ray_z = np.empty(n), np.empty(n), np.empty(n)
    if model == PERSPECTIVE:
        for i in range(n):
            l0, l1 = film_direction(film_x[i], film_y[i], width, height, tan_x, tan_y)
            ray_x[i], ray_y[i], ray_z[i] = unit_frame_direction(f00, f01, f02, f10, f11, f12, f20, f21, f22, l0, l1,
                                                                1.0)
    for i in range(n):
        o0, o1, o2 = e0, e1, e2
        if model == ORTHOGRAPHIC:
            c0, c1 = film_direction(film_x[i], film_y[i], width, height, camera.half_x, camera.half_y)
            if mutant & M_ORTHO_ORIGIN_NOT_OFFSET:  # mutant "orthographic-origin-not-offset"
                c0, c1 = 0.0, 0.0
            o0 += c0 * f00 + c1 * f01
            o1 += c0 * f10 + c1 * f11
            o2 += c0 * f20 + c1 * f21
            ray_x[i], ray_y[i], ray_z[i] = f02, f12, f22
        elif model == THINLENS:
            k = key[i]
            l0, l1 = film_direction(film_x[i], film_y[i], width, height, tan_x, tan_y)
            ua, ub = uniform(k, salt_lens_1), uniform(k, salt_lens_2)
            if mutant & M_LENS_SQUARE:  # mutant "lens-sampled-on-square"
                a0, a1 = 2.0 * ua - 1.0, 2.0 * ub - 1.0
            else:
                a0, a1 = concentric_disk(ua, ub)
            a0, a1 = a0 * camera.aperture_radius, a1 * camera.aperture_radius
            f = camera.focus_distance
            if mutant & M_FOCUS_ALONG_RAY:  # mutant "focus-along-ray": f along the ray, not along the axis
                f = f / math.sqrt(l0 * l0 + l1 * l1 + 1.0)
            o0 += a0 * f00 + a1 * f01
            o1 += a0 * f10 + a1 * f11
            o2 += a0 * f20 + a1 * f21
            ray_x[i], ray_y[i], ray_z[i] = unit_frame_direction(f00, f01, f02, f10, f11, f12, f20, f21, f22,
                                                                f * l0 - a0, f * l1 - a1, f)
        d0, d1, d2 = ray_x[i], ray_y[i], ray_z[i]
        direction[i, 0], direction[i, 1], direction[i, 2] = d0, d1, d2
        d32[i, 0], d32[i, 1], d32[i, 2] = d0, d1, d2
        origin[i, 0], origin[i, 1], origin[i, 2] = o0, o1, o2
        o32[i, 0], o32[i, 1], o32[i, 2] = o0, o1, o2
        w = weight[i]
        beta[i, 0], beta[i, 1], beta[i, 2] = w, w, w
        root[i] = i
        pdf_dir[i] = 0.0
