"""What a render may cost: film-size limits, and memory and time estimates checked before anything renders.

A scene's film is limited to ``MAX_FILM_SIDE`` pixels per side and ``MAX_FILM_PIXELS`` pixels in all whatever the
machine (``harness.scene.load``). Where the samples per pixel are known too (``harness render``, ``ground-truth``,
``run``), :func:`check_render_cost` refuses a render whose estimates break either of

* memory: ``pixels * BYTES_PER_PIXEL`` above ``MEMORY_FRACTION`` of this machine's physical memory, where
  ``BYTES_PER_PIXEL = 2*24 + 3*24 + 2*12 + 2*12 = 168``: the reference keeps two float64 RGB sums per pixel
  (sum and sum of squares, 24 B each) for the whole render, forms the mean, the sample variance and one temporary
  in float64 at the end (3 x 24 B), returns float32 image and variance (2 x 12 B) and the EXR writer copies both
  into channel planes (2 x 12 B). The batch buffers (``batch_size`` paths) do not grow with the film.
* time: ``pixels * spp / PATHS_PER_SECOND`` above ``MAX_SECONDS`` (24 h). ``PATHS_PER_SECOND`` = 1e6 is the order
  of the reference path tracer on a 2-core machine (0.4 to 0.7 M paths/s measured on the Cornell box and
  multi-light scenes with other work running; up to about 2 M/s unloaded); it is an order-of-magnitude estimate,
  so the limit only catches budgets far beyond reason, never a merely slow render.

Every refusal is one :class:`HarnessError` line naming the key or option to change and giving both estimates.
"""

from __future__ import annotations

import os

from harness.errors import HarnessError

MAX_FILM_SIDE = 16384
MAX_FILM_PIXELS = 2**26
BYTES_PER_PIXEL = 2 * 24 + 3 * 24 + 2 * 12 + 2 * 12
PATHS_PER_SECOND = 1e6
MAX_SECONDS = 24 * 3600.0
MEMORY_FRACTION = 0.5


def memory_bytes(width: int, height: int) -> float:
    """Estimated peak memory of a render's per-pixel buffers in bytes: ``width * height * BYTES_PER_PIXEL``."""
    return _float(width) * _float(height) * BYTES_PER_PIXEL


def render_seconds(width: int, height: int, spp: int) -> float:
    """Estimated render time: ``width * height * spp / PATHS_PER_SECOND``."""
    return _float(width) * _float(height) * _float(spp) / PATHS_PER_SECOND


def _float(value) -> float:
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
        paths = _float(width) * _float(height) * _float(spp)
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
                      seconds: float | None = None) -> None:
    """Refuse a render of ``width x height`` pixels at ``spp`` samples per pixel (or for ``seconds`` of rendering,
    a time budget) whose estimated memory or time breaks the limits above.

    ``film_where`` / ``spp_where`` are the HarnessError locations blamed for memory / time (e.g.
    ``"scenes/x.toml: film"``, ``"--spp"``); ``film_keys`` and ``spp_name`` name what to lower in the message.
    """
    memory, available = memory_bytes(width, height), machine_memory()
    budget_spp = spp if seconds is None else None
    if available is not None and memory > MEMORY_FRACTION * available:
        raise HarnessError(film_where, (
            f"{width} x {height} pixels need {estimate_text(width, height, budget_spp)}, more than "
            f"{MEMORY_FRACTION:.0%} of this machine's {format_bytes(available)}; lower {film_keys}"))
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
