"""Compiled kernels of the integrator, in numba: whole paths one at a time, or one bounce of a wavefront.

Two engines trace the same estimator (``Settings.engine``): :mod:`.path`, the path loop, follows each camera path
from its viewing ray to its end in one loop and asks Embree for each hit and shadow ray on the spot, through Embree's C
API (:mod:`.queries`), on every scene (Ni = 1); :mod:`.wavefront` is one bounce of every path of a batch between
batched queries, on Lambertian scenes (used with Ni > 1, where paths branch). They draw different random numbers, so
their images agree in expectation, not in bits (``tests/reference_impl/test_engines.py``).

=================== ========================================================== ====================================
module              what it holds                                              numpy definition it repeats
=================== ========================================================== ====================================
``config``          compile options, the settings as the kernels read them     ``Settings`` (the table of slots)
                    (``KernelConfig``), modes, planted-fault bits, counters
``records``         the scene, lights, surfaces, emitters, materials, camera,  ``Geometry``, ``LightSampler``,
                    pixel filter and camera samples as the kernels take them   ``Emitters``, ``Materials``, ``Camera``
                    (named tuples of arrays, each built by one function)
``rng``             hashed random numbers: keys, dimensions, uniforms          ``reference_impl.rng``
``sobol``           the stratified sampler: scrambled, shuffled Sobol points   ``rng.sobol_2d``
``warps``           hemisphere warps, the world frame, discrete choices        ``reference_impl.sampling``
``light_sampling``  points on the lights (Fig. 5.8, 5.10) and on all surfaces  ``reference_impl.lights``
                    (Fig. 5.13)
``emitters``        point, spot, directional lights and environments: their   ``reference_impl.emitters``
                    light samples, the environment's radiance and directions
``surface``         the surface record of a hit (``SurfaceHit``: triangle,     ``reference_impl.intersect``
                    material, the hit point in float64, normal,
                    barycentrics, texture coordinates, shading frame), ray
                    origin offsets, where a shadow ray stops
``camera``          viewing rays through the pixel filter (Fig. 5.16)          ``Camera``, ``filters``
``vertex``          the wavefront's vertex: its rules (max_depth), emission,   ``integrator`` (eq. 5.2, Fig. 5.14)
                    roulette, the indirect ray
``direct``          the direct-light estimator: light and surface samples,     ``integrator`` (eq. 5.3, Fig. 5.7,
                    shadow rays, MIS, hemisphere samples; the path loop's      5.10, 5.12, 5.13)
                    connections (the light door)
``queries``         Embree's C API: ray buffers, closest hit, occlusion,       ``Intersector`` (embreex)
                    packets, timing
``wavefront``       one bounce of a batch, and the direct light once Embree    the wavefront engine
                    has answered
``path``            the path loop: whole paths, one at a time, every scene     (none: the wavefront in expectation,
                    and strategy with Ni = 1 (BSDF door, light door, MIS)      closed forms, Mitsuba)
``blocks``          the path loop's work on a Lambertian scene lit by area     (none: the path loop's bits,
                    lights, in blocks of paths that go from vertex to vertex   tests/reference_impl/
                    together, their rays as Embree packets                     test_blocks.py)
``material``        the material step: a material's kind and parameters at a   (none: the parameters are
                    hit, which the BSDF reads                                  ``Materials.params``' rows)
``bsdf``            evaluation, pdf and sampling of the materials' BSDFs       (none: Mitsuba 3's plugins; chi^2
                                                                               and Mitsuba checks)
``record``          the path loop's rays and Embree's answers, recorded        (none: reference_impl.replay checks
                    for replay (compiled out of a render)                      the replayed hits against them)
``film``            the samples' end: non-finite count, per-pixel sums         ``np.cumsum`` in sample order
=================== ========================================================== ====================================

Both engines take the hit from ``surface``, the material from ``material``, the light door's samples from
``emitters`` and ``light_sampling``; the path loop reflects through the BSDF door (``bsdf``), the wavefront through
Lambert's f_r (``vertex``), the slides' branching estimator for Ni > 1.

The numpy functions stay the documented definitions (the chi^2 tests run them); the kernels repeat the same
formulas, operation for operation (same order of floating-point operations wherever the numpy code fixes one), so
the warps and samplers give the numpy functions' bits. (The shading arithmetic has since been reordered for speed,
one division and three products where three divisions were, so images are no longer those of the numpy integrator
of git 5dd5d08.) The order of numpy's einsum sums and
the last bits of sin/cos/sqrt come from the numpy build, the CPU and libm (the hemisphere warps' cos and sin are
``sampling.unit_circle``'s polynomials, not libm's), so elsewhere the two may differ in last
bits (each still deterministic). ``tests/test_kernel_equivalence.py`` checks the warps, light sampling and random
numbers against the numpy functions, bit for bit; ``tests/reference_impl/test_image_checksums.py`` holds whole renders to stored
bits.

Every kernel is ``nogil`` and sequential within a batch, so results never depend on the thread count or the batch
size (:mod:`.config` has the compile options). ``cache=True`` keeps the compiled code in ``__pycache__``: only the
first import on a machine pays the compile time. numba checks a cached kernel only against the file it is written
in, while the kernels inline code from the other modules of this package; :func:`_drop_stale_cache` therefore drops
the package's cached code whenever any of its sources changes.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

try:
    from numba.core import caching as _numba_caching  # where numba caches: its internal module, hence the fallback
except ImportError:
    _numba_caching = None

_HERE = Path(__file__).resolve().parent
# Besides this package, the kernels compile in constants and code of these modules.
_ALSO_COMPILED_IN = ("embree_c.py", "rng.py", "emitters.py", "sampling.py")
_STAMP = "kernel-sources.sha256"


def _sources_digest(package: Path) -> str:
    """SHA-256 of the kernels' sources: every module of ``package`` and the modules they compile in."""
    digest = hashlib.sha256()
    for path in sorted(package.glob("*.py")) + [package.parent / name for name in _ALSO_COMPILED_IN]:
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _cache_folder(package: Path) -> Path:
    """The folder numba caches the kernels of ``package`` in: the first of its locators that can write (a
    ``NUMBA_CACHE_DIR``, the package's ``__pycache__``, numba's user-wide folder)."""
    try:
        for locator in (_numba_caching.UserProvidedCacheLocator, _numba_caching.InTreeCacheLocator,
                        _numba_caching.UserWideCacheLocator):
            found = locator.from_function(_sources_digest, str(package / "config.py"))
            if found is not None:
                return Path(found.get_cache_path())
    except (AttributeError, TypeError):
        pass
    return package / "__pycache__"


def _drop_stale_cache(package: Path = _HERE) -> None:
    """Remove numba's cached kernels of ``package`` (``*.nbi``, ``*.nbc``) when its sources have changed since they
    were cached, then note the sources' digest beside them: numba itself would reload a kernel whose own file is
    unchanged even after a helper it inlines from another module was edited. Nothing happens where the folder cannot
    be written."""
    cache = _cache_folder(package)
    stamp = cache / _STAMP
    digest = _sources_digest(package)
    try:
        if stamp.read_text() == digest:
            return
    except OSError:
        pass
    try:
        cache.mkdir(parents=True, exist_ok=True)
        for stale in [*cache.glob("*.nbi"), *cache.glob("*.nbc")]:
            stale.unlink(missing_ok=True)
        stamp.write_text(digest)  # after the removal, so that no process takes stale files for fresh ones
    except OSError:
        pass


_drop_stale_cache()
