"""What a render may cost: film-size limits, and memory and time estimates checked before anything renders.

A scene's film is limited to ``MAX_FILM_SIDE`` pixels per side and ``MAX_FILM_PIXELS`` pixels in all whatever the
machine (``harness.scene.load``). Where the samples per pixel are known too (``harness render``, ``ground-truth``,
``run``), :func:`check_render_cost` refuses a render whose estimates break either of

* memory: ``pixels * BYTES_PER_PIXEL`` above ``MEMORY_FRACTION`` of this machine's physical memory, where
  ``BYTES_PER_PIXEL = 2*24 + 3*24 + 2*12 + 2*12 = 168``: the reference keeps two float64 RGB sums per pixel
  (sum and sum of squares, 24 B each) for the whole render, forms the mean, the sample variance and one temporary
  in float64 at the end (3 x 24 B), returns float32 image and variance (2 x 12 B) and the EXR writer copies both
  into channel planes (2 x 12 B). The batch buffers (``batch_size`` paths) do not grow with the film.
  A scene's environment map adds ``texels * ENVMAP_BYTES_PER_TEXEL`` (128 B), whatever the film: the reference
  builds its tables (``reference_impl.emitters.Emitters``) from the float32 map the scene holds (12 B per texel):
  the texels in float64 (24 B), the luminance, the cells' corners, weights, pdf and conditional cdf (8 B each) and,
  at the peak, the float64 temporaries of the cells' mean colour (3 x 24 B); tracemalloc measures 124 B per texel
  (tests/scene/test_envmap_cost.py). An 8192 x 4096 map costs about 4 GiB however small the film.
* time: ``pixels * spp / PATHS_PER_SECOND`` above ``MAX_SECONDS`` (24 h). ``PATHS_PER_SECOND`` = 1e6 is the order
  of the reference path tracer on a 2-core machine (0.4 to 0.7 M paths/s measured on the Cornell box and
  multi-light scenes with other work running; up to about 2 M/s unloaded); it is an order-of-magnitude estimate,
  so the limit only catches budgets far beyond reason, never a merely slow render.

The reference renderer's settings change both (:func:`reference_cost`, checked by
``harness.renderers.reference.ReferenceRenderer`` before anything is allocated, so for ``harness render``,
``convergence`` and every suite case as it loads):

* memory: each worker thread traces a batch of n camera samples (n from ``batch_size``, spp, the film and the
  thread count, as ``reference_impl.integrator.render`` splits the work) and holds, per path of a wavefront,
  ``WAVEFRONT_ROW_BYTES`` = 120 B (root and key 8 B each; origin, direction and throughput 3 x 8 B each; float32
  copies of origin and direction 3 x 4 B each; the pdf 8 B), twice (the current and the next wavefront), plus
  24 B of radiance and 32 B of hit record per camera sample and ``DIRECT_ROW_BYTES`` (60 B; 88 B for hemisphere
  direct sampling) per direct-light ray (shadow_rays per hit). With ``indirect_rays`` = Ni > 1 the wavefront
  branches: each bounce allocates room for Ni rows per current row (even at a bounce that spawns none), and a
  wavefront longer than 4 x batch_size is split only at camera-sample boundaries, so one sample's m_j rows at
  depth j are bounced together. m_1 = 1, m_{j+1} = m_j Ni s_j, with s_j the survival probability of Russian
  roulette at depths >= rr_depth (rr = albedo: the largest reflectance in the scene; fixed: 1 - absorption; off:
  1), counting every ray as a hit (a closed scene), for the depths 1 .. max_depth - 1 that bounce (max_depth with
  direct = mis).
* time: the paths' estimate above times the rays per camera sample, sum_j m_j (1 + shadow_rays), over that of the
  default settings (Ni = 1, one shadow ray): (1 + shadow_rays) / 2 for Ni = 1. With max_depth = -1 (unbounded)
  and Ni x survival >= 1 the branching never dies out in a closed scene: refused (set a max_depth).

Every refusal is one :class:`HarnessError` line naming the key or option to change and giving both estimates.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from harness.core.errors import HarnessError

MAX_FILM_SIDE = 16384
MAX_FILM_PIXELS = 2**26
BYTES_PER_PIXEL = 2 * 24 + 3 * 24 + 2 * 12 + 2 * 12
ENVMAP_BYTES_PER_TEXEL = 128  # the map and the reference's tables of it at their peak: 124 B measured (above)
PATHS_PER_SECOND = 1e6
MAX_SECONDS = 24 * 3600.0
MEMORY_FRACTION = 0.5
MAX_TIMEOUT_SECONDS = 7 * 24 * 3600.0  # a per-run timeout beyond a week is a typo (and 1e308 s overflows the OS)

WAVEFRONT_ROW_BYTES = 2 * 8 + 3 * 24 + 2 * 12 + 8
CAMERA_SAMPLE_BYTES = 24 + 8 + 24  # radiance, hit index and direct-light total of each camera sample
DIRECT_ROW_BYTES = 8 + 12 + 12 + 4 + 24
HEMISPHERE_DIRECT_ROW_BYTES = 8 + 12 + 12 + 24 + 8 + 24
SPLIT_FACTOR = 4  # reference_impl.integrator._Context.split_cap = 4 * batch_size
DEPTH_SUM_TERMS = 100_000  # an unbounded depth's sums stop here (or when their terms become negligible)


def memory_bytes(width: int, height: int) -> float:
    """Estimated peak memory of a render's per-pixel buffers in bytes: ``width * height * BYTES_PER_PIXEL``."""
    return float_or_inf(width) * float_or_inf(height) * BYTES_PER_PIXEL


def envmap_bytes(width: int, height: int) -> float:
    """Estimated peak memory of a render's environment map of ``width x height`` texels in bytes (the map and the
    reference's tables of it): ``width * height * ENVMAP_BYTES_PER_TEXEL``."""
    return float_or_inf(width) * float_or_inf(height) * ENVMAP_BYTES_PER_TEXEL


def envmap_problem(width: int, height: int) -> str | None:
    """Why an environment map of ``width x height`` texels cannot be rendered on this machine (its tables alone
    need more than ``MEMORY_FRACTION`` of the physical memory), or None; checked on the file's header, before any
    pixel is read."""
    memory, available = envmap_bytes(width, height), machine_memory()
    if available is None or memory <= MEMORY_FRACTION * available:
        return None
    return (f"a {width} x {height} map needs about {format_bytes(memory)} of memory to render "
            f"({ENVMAP_BYTES_PER_TEXEL} B per texel: the map and the reference's sampling tables), more than "
            f"{MEMORY_FRACTION:.0%} of this machine's {format_bytes(available)}; expected a smaller map")


def render_seconds(width: int, height: int, spp: int) -> float:
    """Estimated render time: ``width * height * spp / PATHS_PER_SECOND``."""
    return float_or_inf(width) * float_or_inf(height) * float_or_inf(spp) / PATHS_PER_SECOND


def float_or_inf(value) -> float:
    """``float(value)``, or infinity for an integer beyond float's range (TOML integers are unbounded)."""
    try:
        return float(value)
    except OverflowError:
        return float("inf")


def machine_memory() -> int | None:
    """This machine's physical memory in bytes, or None where the OS does not say."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def format_bytes(n: float) -> str:
    if not n < float("inf"):
        return "an unbounded amount"
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError("unreachable")


def format_seconds(s: float) -> str:
    if not s < float("inf"):
        return "forever"
    if s < 120:
        return f"{s:.1f} s"
    if s < 7200:
        return f"{s / 60:.0f} min"
    if s < 3 * 86400:
        return f"{s / 3600:.1f} h"
    if s < 3 * 365 * 86400:
        return f"{s / 86400:.0f} days"
    return f"{s / (365 * 86400):.3g} years"


def estimate_text(width: int, height: int, spp: int | None = None) -> str:
    """"about 1.2 GiB of memory (168 B per pixel) and about 3.4 h (1.2e10 paths at 1 M paths/s)"."""
    text = f"about {format_bytes(memory_bytes(width, height))} of memory ({BYTES_PER_PIXEL} B per pixel)"
    if spp is not None:
        paths = float_or_inf(width) * float_or_inf(height) * float_or_inf(spp)
        text += (f" and about {format_seconds(render_seconds(width, height, spp))} "
                 f"({paths:.3g} paths at {PATHS_PER_SECOND / 1e6:g} M paths/s)")
    return text


def film_problem(width: int, height: int) -> str | None:
    """Why a film of this size is refused on any machine (side or pixel-count limit), or None."""
    if width * height > MAX_FILM_PIXELS:
        return (f"expected at most {MAX_FILM_PIXELS} pixels (2^26), got {width} x {height} = {width * height} "
                f"({estimate_text(width, height)})")
    return None


def check_render_cost(width: int, height: int, spp: int | None, *, film_where: str, spp_where: str,
                      film_keys: str = "the film's width / height", spp_name: str = "spp",
                      seconds: float | None = None, envmap: tuple[int, int] | None = None,
                      envmap_where: str | None = None) -> None:
    """Refuse a render of ``width x height`` pixels at ``spp`` samples per pixel (or for ``seconds`` of rendering,
    a time budget) whose estimated memory or time breaks the limits above.

    ``film_where`` / ``spp_where`` are the HarnessError locations blamed for memory / time (e.g.
    ``"scenes/x.toml: film"``, ``"--spp"``); ``film_keys`` and ``spp_name`` name what to lower in the message.
    ``envmap``: the (width, height) of the scene's environment map, whose tables count too; the memory is blamed on
    ``envmap_where`` (its ``file`` key) when they cost more than the film.
    """
    memory, available = memory_bytes(width, height), machine_memory()
    texels = envmap_bytes(*envmap) if envmap is not None else 0.0
    budget_spp = spp if seconds is None else None
    if available is not None and memory + texels > MEMORY_FRACTION * available:
        if envmap is None:
            raise HarnessError(film_where, (
                f"{width} x {height} pixels need {estimate_text(width, height, budget_spp)}, more than "
                f"{MEMORY_FRACTION:.0%} of this machine's {format_bytes(available)}; lower {film_keys}"))
        where = envmap_where if texels > memory and envmap_where else film_where
        raise HarnessError(where, (
            f"{width} x {height} pixels with a {envmap[0]} x {envmap[1]} environment map need about "
            f"{format_bytes(memory + texels)} of memory ({BYTES_PER_PIXEL} B per pixel, {ENVMAP_BYTES_PER_TEXEL} B "
            f"per texel of the map), more than {MEMORY_FRACTION:.0%} of this machine's {format_bytes(available)}; "
            f"lower {film_keys} or use a smaller map"))
    if seconds is not None:
        if seconds > MAX_SECONDS:
            raise HarnessError(spp_where, (
                f"expected a time budget of at most {format_seconds(MAX_SECONDS)}, got {format_seconds(seconds)} "
                f"({estimate_text(width, height)}); lower {spp_name}"))
        return
    if spp is not None and render_seconds(width, height, spp) > MAX_SECONDS:
        raise HarnessError(spp_where, (
            f"{width} x {height} pixels at {spp} spp need {estimate_text(width, height, spp)}, more than the "
            f"{format_seconds(MAX_SECONDS)} limit; lower {spp_name} or {film_keys}"))


@dataclass(frozen=True)
class ReferenceCost:
    """What :func:`reference_cost` estimates for one reference render."""

    memory: float  # bytes: the per-pixel buffers and every worker thread's wavefront buffers
    seconds: float  # the paths' time estimate scaled by ``relative_work``
    relative_work: float  # rays per camera sample over those of the default settings (math.inf: unbounded)
    wavefront_rows: float  # the largest wavefront allocation of one thread, in paths
    direct_rows: float = 0.0  # the direct-light rays of one thread's largest bounce
    unbounded: bool = False  # max_depth = -1 and indirect_rays x survival >= 1: the branching never dies out


def _batch(pixels: int, spp: int, batch_size: int, threads: int) -> tuple[int, int]:
    """(camera samples per batch, threads that get work) as ``reference_impl.integrator.render`` splits a render."""
    per_unit = max(1, batch_size // spp)
    per_unit = min(per_unit, max(1, math.ceil(pixels / (4 * threads))))
    samples = max(1, min(spp, batch_size // per_unit))
    units = math.ceil(pixels / per_unit)
    return per_unit * samples, min(threads, units)


def _depth_terms(indirect_rays: int, survival: float, rr_depth: int, bounces: float):
    """m_1, m_2, ... (expected rows per camera sample at each bouncing depth, every ray a hit), or None when the
    sum of the m_j diverges (unbounded depth and indirect_rays x survival >= 1)."""
    if bounces == math.inf and indirect_rays * survival >= 1:
        return None
    terms, m, total, depth = [], 1.0, 0.0, 1
    while depth <= min(bounces, DEPTH_SUM_TERMS):
        terms.append(m)
        total += m
        if m == math.inf:  # overflowed before roulette could stop it (0 x inf would hide it)
            break
        m *= indirect_rays * (survival if depth >= rr_depth else 1.0)
        depth += 1
        if depth > rr_depth and m < 1e-12 * total:  # the rest cannot change the sums
            break
    return terms


def reference_cost(width: int, height: int, spp: int, *, shadow_rays: int = 1, indirect_rays: int = 1,
                   max_depth: int = -1, survival: float = 1.0, rr_depth: int = 3, mis: bool = False,
                   hemisphere_direct: bool = False, batch_size: int = 1 << 15, threads: int = 1,
                   envmap: tuple[int, int] | None = None) -> ReferenceCost:
    """Memory and time estimates of a reference render with these settings (module docstring).

    ``survival``: Russian roulette's survival probability (1.0 for rr = off); ``threads``: the resolved count;
    ``envmap``: the (width, height) of the scene's environment map, whose tables count too.
    """
    pixels = int(width) * int(height)
    n, busy = _batch(pixels, spp, batch_size, threads)
    direct_row = HEMISPHERE_DIRECT_ROW_BYTES if hemisphere_direct else DIRECT_ROW_BYTES
    bounces = math.inf if max_depth == -1 else max(1, max_depth if mis else max_depth - 1)
    if indirect_rays == 1:
        relative, rows, hits = (1 + shadow_rays) / 2, float(n), float(n)
        per_thread = n * (2 * WAVEFRONT_ROW_BYTES + CAMERA_SAMPLE_BYTES + shadow_rays * direct_row)
    else:
        terms = _depth_terms(indirect_rays, survival, rr_depth, bounces)
        plain = _depth_terms(1, survival, rr_depth, bounces)
        if terms is None:
            return ReferenceCost(math.inf, math.inf, math.inf, math.inf, math.inf, unbounded=True)
        relative = sum(terms) * (1 + shadow_rays) / (2 * sum(plain))
        split = SPLIT_FACTOR * batch_size
        bounced = [min(n * m, max(split, m)) for m in terms]  # the longest wavefront bounced at each depth
        rows, hits = max(bounced) * indirect_rays, max(bounced)
        per_thread = (n * (WAVEFRONT_ROW_BYTES + CAMERA_SAMPLE_BYTES) + sum(bounced) * indirect_rays
                      * WAVEFRONT_ROW_BYTES + max(bounced) * shadow_rays * direct_row)
    memory = memory_bytes(width, height) + busy * per_thread + (envmap_bytes(*envmap) if envmap else 0.0)
    return ReferenceCost(memory, render_seconds(width, height, spp) * relative, relative, rows, hits * shadow_rays)


def check_reference_cost(width: int, height: int, spp: int, *, where: str, settings_text: str, lower: str,
                         **settings) -> None:
    """Refuse a reference render whose :func:`reference_cost` breaks the memory or time limit: a HarnessError at
    ``where`` (the setting to blame) that shows ``settings_text`` and says to lower ``lower``."""
    cost = reference_cost(width, height, spp, **settings)
    head = f"{width} x {height} pixels at {spp} spp with {settings_text}"
    if cost.unbounded:
        ni, survival = settings.get("indirect_rays", 1), settings.get("survival", 1.0)
        raise HarnessError(where, (
            f"indirect_rays = {ni} with max_depth = -1 (unbounded) and a Russian-roulette survival of up to "
            f"{survival:g}: each hit spawns up to {ni * survival:g} paths on average, a branching that never dies out "
            "in a closed scene; set a max_depth (--set max_depth=N or the scene's integrator.max_depth) or lower "
            "indirect_rays"))
    available = machine_memory()
    if available is not None and cost.memory > MEMORY_FRACTION * available:
        envmap = settings.get("envmap")
        tables = f"; {format_bytes(envmap_bytes(*envmap))} of it the environment map's tables" if envmap else ""
        raise HarnessError(where, (
            f"{head} need about {format_bytes(cost.memory)} of memory (per worker thread: wavefronts of up to "
            f"{cost.wavefront_rows:.3g} paths and {cost.direct_rows:.3g} direct-light rays{tables}), more than "
            f"{MEMORY_FRACTION:.0%} of this machine's {format_bytes(available)}; lower {lower}"))
    if cost.seconds > MAX_SECONDS:
        raise HarnessError(where, (
            f"{head} need about {format_seconds(cost.seconds)} ({cost.relative_work:.3g} x the rays per path of the "
            f"default settings, at {PATHS_PER_SECOND / 1e6:g} M default paths/s), more than the "
            f"{format_seconds(MAX_SECONDS)} limit; lower {lower}"))
