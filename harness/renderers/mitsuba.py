"""Adapter: a :class:`~harness.scene.Scene` rendered by Mitsuba 3, with per-pixel variances (``docs/mitsuba.md``).

Three parts:

* **Variant choice** (:func:`choose_variant`): ``cuda_ad_rgb`` where a GPU works, else ``llvm_ad_rgb`` where a
  libLLVM >= 16 can be found, else ``scalar_rgb``. Each candidate is tried in a *subprocess* (a 4 x 4 render),
  because Dr.Jit's LLVM backend aborts the whole process on some LLVM versions (15), which no ``try`` can catch.
  ``DRJIT_LIBLLVM_PATH`` is set to the library that passed before Mitsuba runs anything in this process.
* **Scene conversion** (:func:`scene_to_mitsuba_dict`): the scene's Mitsuba plugins
  (:mod:`harness.renderers.mitsuba_spec`) in the form ``mi.load_dict`` takes (:func:`load_dict_form`).
* **Rendering in passes** (:class:`MitsubaRenderer`): independent passes with distinct seeds, each through Mitsuba's
  ``moment`` integrator, so every pixel's variance comes from all of its samples; passes are merged by adding
  float64 sums (:func:`merge_moments`).

Mitsuba is imported lazily (:func:`import_mitsuba`): importing this module costs nothing and never touches LLVM.
"""

from __future__ import annotations

import glob
import importlib.metadata
import json
import dataclasses
import math
import os
import re
import shutil
import sys
import tempfile
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError
from harness.judges.moments import Estimate
from harness.renderers.base import RenderRequest, RenderResult
from harness.renderers.mitsuba_spec import (
    RR_DEPTH,
    ImageFile,
    LookAt,
    MeshFile,
    MitsubaSpec,
    Parameter,
    Point,
    UVTransform,
    Vector,
    scene_spec,
)
from harness.renderers.processes import CommandStartError, CommandTimeout, run_group
from harness.scene import Scene
from reference_impl.filters import make_filter

# Variants in order of preference. Only RGB variants: the scene format is RGB (spectral variants would upsample the
# colours, mono ones would collapse them), so any other variant would render a different image.
VARIANT_ORDER = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")
MIN_LLVM_VERSION = 16  # Dr.Jit 1.5's LLVM backend aborts the process on LLVM 15 ("Cannot select: fminimum")
DEFAULT_CHUNK_SPP = 64
MAX_PASS_SAMPLES = 2**31  # camera samples per pass at most (Mitsuba's wavefront index is 32-bit)
SETTING_KEYS = ("chunk_spp", "integrator", "max_depth", "moments", "sampler", "variant")
#: ``--set integrator``: Mitsuba's integrator, in place of the scene's (``path``, or ``volpath`` for a scene with
#: media or a ``null`` material: mitsuba_spec.scene_spec): ``volpathmis``, the volumetric path tracer with spectral
#: MIS, is the media's second estimator (suites/media.toml)
INTEGRATORS = ("path", "volpath", "volpathmis")
# Mitsuba's samplers (``--set sampler=...``); "independent" is its default and the ground truth's.
SAMPLERS = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")


def sampler_takes(sampler: str, count: int) -> bool:
    """Whether Mitsuba's ``sampler`` draws exactly ``count`` samples per pixel (others round it, with a warning on
    stdout): stratified and multijitter want a square, ldsampler a power of 4 from 4 up, orthogonal the square of a
    prime (checked against Mitsuba 3.9.1's ``sample_count()``)."""
    root = math.isqrt(count)
    if sampler == "independent":
        return count >= 1
    if root * root != count:
        return False
    if sampler == "ldsampler":  # and at least 4: Mitsuba rounds 1 up to 4
        return root >= 2 and root & (root - 1) == 0
    if sampler == "orthogonal":
        return root >= 2 and all(root % d for d in range(2, math.isqrt(root) + 1))
    return True


#: how long a probe (:func:`probe_variant`) may run before it counts as failed: llvm_ad_rgb answers in about 0.4 s,
#: Dr.Jit's kernel cache cold or warm (docs/mitsuba.md)
PROBE_TIMEOUT_S = 120.0

_LIBLLVM_GLOBS = (
    "/usr/lib/*-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib/llvm*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/lib64/llvm*/lib/libLLVM*.so*",
    "/usr/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/usr/local/opt/llvm*/lib/libLLVM*.dylib",
    "/opt/homebrew/opt/llvm*/lib/libLLVM*.dylib",
    "/opt/local/libexec/llvm-*/lib/libLLVM*.dylib",
)


# --------------------------------------------------------------------------------------------------------------------
# libLLVM search


def libllvm_version(path: str) -> int | None:
    """The LLVM major version a library path names (``libLLVM-19.so``, ``libLLVM.so.19.1``, ``llvm-17/lib/...``)."""
    name = os.path.basename(path)
    for pattern in (r"libLLVM-(\d+)", r"libLLVM\.so\.(\d+)", r"libLLVM\.(\d+)\.dylib"):
        match = re.search(pattern, name)
        if match:
            return int(match.group(1))
    match = re.search(r"llvm[-@]?(\d+)", os.path.dirname(path))
    return int(match.group(1)) if match else None


def find_libllvm_candidates() -> list[str]:
    """Shared libLLVM files worth trying, best first.

    ``$DRJIT_LIBLLVM_PATH`` (if set and present) comes first whatever its version; then libraries of version
    >= :data:`MIN_LLVM_VERSION` from the usual system folders, newest first. One entry per real file.
    """
    found: dict[str, tuple[int, str]] = {}
    env = os.environ.get("DRJIT_LIBLLVM_PATH")
    ordered: list[str] = []
    seen: set[str] = set()
    if env and os.path.isfile(env):
        ordered.append(env)
        seen.add(os.path.realpath(env))
    for pattern in _LIBLLVM_GLOBS:
        for path in glob.glob(pattern):
            if path.endswith((".a", ".la")) or not os.path.isfile(path):
                continue
            version = libllvm_version(path)
            if version is None:
                version = libllvm_version(os.path.realpath(path))
            if version is None or version < MIN_LLVM_VERSION:
                continue
            real = os.path.realpath(path)
            if real in seen:
                continue
            # Prefer the shortest name of one real file (libLLVM-19.so over libLLVM.so.19.1): either works.
            if real not in found or len(path) < len(found[real][1]):
                found[real] = (version, path)
    ordered += [path for _, path in sorted(found.values(), key=lambda item: (-item[0], item[1]))]
    return ordered


# --------------------------------------------------------------------------------------------------------------------
# Probing a variant in a subprocess

_PROBE_SCRIPT = r"""
import os
import sys
if len(sys.argv) > 2:  # the libLLVM to try, before Dr.Jit reads the variable
    os.environ["DRJIT_LIBLLVM_PATH"] = sys.argv[2]
import numpy as np
import mitsuba as mi
mi.set_variant(sys.argv[1])
scene = mi.load_dict({
    "type": "scene",
    "integrator": {"type": "path", "max_depth": 3},
    "sensor": {
        "type": "perspective", "fov": 40.0,
        "to_world": mi.ScalarTransform4f.look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
        "film": {"type": "hdrfilm", "width": 4, "height": 4, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": "independent", "sample_count": 4},
    },
    "light": {"type": "rectangle", "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}},
})
image = np.array(mi.render(scene, spp=4))
assert image.shape == (4, 4, 3) and np.all(np.isfinite(image)) and image.max() > 0.5, image
print("MITSUBA_PROBE_OK", sys.argv[1], file=sys.stderr)
"""


def gpu_present() -> bool:
    """True if an NVIDIA GPU might be usable: ``nvidia-smi`` on PATH or ``/dev/nvidia0``."""
    return shutil.which("nvidia-smi") is not None or os.path.exists("/dev/nvidia0")


def probe_variant(variant: str, libllvm: str | None = None, timeout: float = PROBE_TIMEOUT_S) -> bool:
    """Whether ``variant`` renders a tiny scene (with ``$DRJIT_LIBLLVM_PATH`` = ``libllvm`` where given), tried in a
    fresh Python process: a crash or a hang there is just False. The process runs under
    :func:`.processes.run_group`, so that it and all it started are killed at the timeout, and when this process ends
    however it ends."""
    argv = [sys.executable, "-c", _PROBE_SCRIPT, variant] + ([libllvm] if libllvm else [])
    try:
        code, _seconds, stderr = run_group(argv, Path(tempfile.gettempdir()), timeout)
    except (CommandTimeout, CommandStartError):
        return False
    return code == 0 and f"MITSUBA_PROBE_OK {variant}".encode() in stderr


def _package_version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "?"


def probe_cache_path() -> Path | None:
    """The JSON file remembering probe results across processes (None: no file cache)."""
    root = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(root) / "rendering-harness" / "mitsuba-variant-probes.json"


def _probe_key(variant: str, libllvm: str | None) -> str:
    """What a probe result depends on: versions, interpreter, and the library file's identity."""
    parts = [variant, _package_version("mitsuba"), _package_version("drjit"), sys.executable]
    if libllvm:
        try:
            st = os.stat(libllvm)
            parts += [os.path.realpath(libllvm), str(st.st_size), str(st.st_mtime_ns)]
        except OSError:
            parts.append(libllvm)
    if variant.startswith("cuda"):
        try:
            parts.append(Path("/proc/driver/nvidia/version").read_text().splitlines()[0])
        except (OSError, IndexError):
            parts.append("no-driver-version")
    return "|".join(parts)


def _probe_cached(variant: str, libllvm: str | None) -> bool:
    """:func:`probe_variant`, remembered in :func:`probe_cache_path` (unreadable or unwritable caches are ignored)."""
    path = probe_cache_path()
    key = _probe_key(variant, libllvm)
    cache: dict = {}
    if path is not None:
        try:
            cache = json.loads(path.read_text())
            if isinstance(cache.get(key), bool):
                return cache[key]
        except (OSError, ValueError, AttributeError):
            cache = {}
    ok = probe_variant(variant, libllvm)
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            cache = cache if isinstance(cache, dict) else {}
            cache[key] = ok
            with tempfile.NamedTemporaryFile("w", dir=path.parent, delete=False, suffix=".tmp") as tmp:
                json.dump(cache, tmp, indent=1, sort_keys=True)
            os.replace(tmp.name, path)
        except OSError:
            pass
    return ok


# --------------------------------------------------------------------------------------------------------------------
# Variant choice


@dataclass(frozen=True)
class VariantChoice:
    """A variant that passed its probe, and the libLLVM it needs (llvm variants only)."""

    variant: str
    libllvm: str | None = None


_CHOICES: dict[str | None, VariantChoice] = {}


def reset_variant_cache() -> None:
    """Forget this process's variant decisions (tests)."""
    _CHOICES.clear()


_EXPECTED_LIBLLVM = (f"expected the path of a libLLVM >= {MIN_LLVM_VERSION} (e.g. "
                     "/usr/lib/x86_64-linux-gnu/libLLVM-19.so), or the variable unset")


def check_user_libllvm() -> None:
    """Refuse a ``$DRJIT_LIBLLVM_PATH`` that is no working libLLVM, before this process imports Mitsuba.

    Dr.Jit reads the variable when Mitsuba is first imported, so the harness cannot replace a bad one later; on
    some libraries (LLVM 15) its LLVM backend aborts the whole process, on others it prints its own errors. The
    library is therefore tried in a child process (:func:`probe_variant`: ``llvm_ad_rgb``, a 4 x 4 render, its
    output captured, with a timeout), its answer remembered per file (path, size, mtime; :func:`_probe_cached`).
    A missing file, or a child that fails, crashes or prints no success: HarnessError at ``DRJIT_LIBLLVM_PATH``
    (one line, nothing of Dr.Jit's output shown). Unset or empty: nothing to check.
    """
    libllvm = os.environ.get("DRJIT_LIBLLVM_PATH")
    if not libllvm:
        return
    if not os.path.isfile(libllvm):
        raise HarnessError("DRJIT_LIBLLVM_PATH", f"no file {libllvm!r}: {_EXPECTED_LIBLLVM}")
    if libllvm in _USER_LIBLLVM_OK:
        return
    if not _probe_cached("llvm_ad_rgb", libllvm):
        version = libllvm_version(libllvm) or libllvm_version(os.path.realpath(libllvm))
        named = f" (its name says LLVM {version})" if version is not None else ""
        raise HarnessError("DRJIT_LIBLLVM_PATH", f"{libllvm!r}{named} failed a test render of llvm_ad_rgb in a "
                                                 f"separate process: {_EXPECTED_LIBLLVM}")
    _USER_LIBLLVM_OK.add(libllvm)


_USER_LIBLLVM_OK: set[str] = set()  # values of $DRJIT_LIBLLVM_PATH this process found working


def available_variants() -> list[str]:
    """The variants this Mitsuba build has (importing Mitsuba runs no JIT backend, so this is safe).

    Raises HarnessError (``DRJIT_LIBLLVM_PATH``) where that variable names no working libLLVM
    (:func:`check_user_libllvm`), before Mitsuba is imported here."""
    check_user_libllvm()
    try:
        import mitsuba  # optional: Mitsuba takes seconds to import and only Mitsuba renders need it
    except ImportError as err:
        raise HarnessError("--renderer mitsuba", f"cannot import Mitsuba 3 ({err}); pip install mitsuba") from None
    return list(mitsuba.variants())


def _usable(variant: str) -> VariantChoice | None:
    """Probe one variant; for llvm variants, try each libLLVM candidate until one works."""
    if variant.startswith("cuda"):
        return VariantChoice(variant) if gpu_present() and _probe_cached(variant, None) else None
    if variant.startswith("llvm"):
        for lib in find_libllvm_candidates():
            if _probe_cached(variant, lib):
                return VariantChoice(variant, lib)
        return None
    return VariantChoice(variant) if _probe_cached(variant, None) else None


def resolve_variant(requested: str | None = None) -> VariantChoice:
    """The variant to render with and its libLLVM: ``requested`` if it works, else the first of
    :data:`VARIANT_ORDER` that works. Decided once per process (and per ``requested``).

    Raises HarnessError (``--set variant``) for a requested variant this Mitsuba lacks, one that is not an RGB
    variant, or one that fails its probe.
    """
    if requested in _CHOICES:
        return _CHOICES[requested]
    if requested is not None:
        known = available_variants()
        rgb = [v for v in known if v.endswith("_rgb")]
        if requested not in known:
            raise HarnessError("--set variant", f"expected one of {', '.join(rgb)}, got {requested!r}")
        if requested not in rgb:
            raise HarnessError("--set variant", f"expected an RGB variant ({', '.join(rgb)}), got {requested!r}: "
                                                "the scene format is RGB")
        choice = _usable(requested)
        if choice is None:
            why = {"cuda": "no working CUDA GPU", "llvm": f"no working libLLVM >= {MIN_LLVM_VERSION} found (set "
                   "DRJIT_LIBLLVM_PATH)"}.get(requested.split("_")[0], "its test render failed")
            raise HarnessError("--set variant", f"{requested} is not usable here: {why}")
    else:
        known = set(available_variants())
        choice = None
        for variant in VARIANT_ORDER:
            if variant in known:
                choice = _usable(variant)
                if choice is not None:
                    break
        if choice is None:
            raise HarnessError("--renderer mitsuba", f"none of {', '.join(VARIANT_ORDER)} works in this Mitsuba")
    _CHOICES[requested] = choice
    return choice


def choose_variant(requested: str | None = None) -> str:
    """``cuda_ad_rgb`` where a GPU works, ``llvm_ad_rgb`` where a libLLVM >= 16 works, else ``scalar_rgb``;
    ``requested`` overrides (HarnessError if unknown or unusable). See :func:`resolve_variant`."""
    return resolve_variant(requested).variant


def import_mitsuba(variant: str):
    """Import Mitsuba with ``variant`` active, ``DRJIT_LIBLLVM_PATH`` set first for llvm variants; returns ``mi``.

    For llvm variants the library comes from :func:`resolve_variant` (probing if not done yet).
    """
    given = os.environ.get("DRJIT_LIBLLVM_PATH")
    if "mitsuba" not in sys.modules:
        check_user_libllvm()
    if variant.startswith("llvm"):
        known = [c for c in _CHOICES.values() if c.variant == variant]
        choice = known[0] if known else resolve_variant(variant)
        if choice.libllvm:
            os.environ["DRJIT_LIBLLVM_PATH"] = choice.libllvm
    import mitsuba as mi  # optional: Mitsuba takes seconds to import and only Mitsuba renders need it

    if mi.variant() != variant:
        try:
            mi.set_variant(variant)
        except ImportError as err:
            if not variant.startswith("llvm") or not given:
                raise
            # Dr.Jit read the user's library when Mitsuba was first imported here (to list its variants), before
            # the probed one could replace it: the variable is what is wrong
            raise HarnessError("DRJIT_LIBLLVM_PATH", f"{variant} cannot load {given!r} "
                                                     f"({str(err).splitlines()[0][:120]}): expected the path of a "
                                                     f"libLLVM >= {MIN_LLVM_VERSION}, or the variable unset") from None
    return mi


# --------------------------------------------------------------------------------------------------------------------
# Scene conversion


def scene_to_mitsuba_dict(scene: Scene, variant: str, *, max_depth: int | None = None, spp: int = 4,
                          sampler: str = "independent") -> dict:
    """The scene as a Mitsuba 3 scene dict for ``variant`` (which this makes the active variant).

    Parameters
    ----------
    scene : Scene
        The loaded scene.
    variant : str
        Mitsuba's variant.
    max_depth : int, optional
        The integrator's ``max_depth``; the scene's where None.
    spp : int
        The sampler's ``sample_count``.
    sampler : str
        Mitsuba's sampler plugin.

    Returns
    -------
    dict
        :func:`harness.renderers.mitsuba_spec.scene_spec` in the form ``mi.load_dict`` takes
        (:func:`load_dict_form`).
    """
    mi = import_mitsuba(variant)
    return load_dict_form(mi, scene_spec(scene, max_depth=max_depth, spp=spp, sampler=sampler))


def load_dict_form(mi, spec: MitsubaSpec) -> dict:
    """The spec as ``mi.load_dict`` takes it: transforms as ``mi.ScalarTransform4f``, points and vectors as lists,
    parameters as their defaults, and the files held in memory: a mesh as an ``mi.Mesh`` (:func:`_mesh_object`),
    an envmap's pixels as its ``bitmap``, so Mitsuba renders exactly the arrays the scene holds (and the
    ground-truth key hashes), never a file read again."""
    return _load_dict_value(mi, spec.plugins, spec.plugins)


def _load_dict_value(mi, value, plugins: dict):
    """One value of the spec in ``mi.load_dict``'s form (``plugins``: the top level, which references name)."""
    if isinstance(value, dict):
        if isinstance(value.get("filename"), MeshFile):
            return _mesh_object(mi, value, plugins)
        return {("bitmap" if isinstance(item, ImageFile) else key): _load_dict_value(mi, item, plugins)
                for key, item in value.items()}
    if isinstance(value, np.ndarray):
        return mi.ScalarTransform4f(np.asarray(value, dtype=np.float64).tolist())
    if isinstance(value, LookAt):
        look_at = mi.ScalarTransform4f.look_at(origin=list(value.origin), target=list(value.target), up=list(value.up))
        return look_at if value.scale is None else look_at @ mi.ScalarTransform4f.scale(list(value.scale))
    if isinstance(value, (Point, Vector)):
        return list(value.xyz)
    if isinstance(value, Parameter):
        return value.default
    if isinstance(value, ImageFile):
        # a writable copy: Mitsuba's binding refuses read-only arrays (the scene's image is read-only); an 8-bit
        # image stays uint8, which Mitsuba takes as sRGB codes (as from a PNG, bit for bit)
        dtype = np.uint8 if value.image.dtype == np.uint8 else np.float32
        return mi.Bitmap(np.array(value.image, dtype=dtype, order="C"), mi.Bitmap.PixelFormat.RGB)
    if isinstance(value, UVTransform):
        return mi.ScalarTransform3f(np.asarray(value.matrix, dtype=np.float64).tolist())
    return value


def _mesh_object(mi, plugin: dict, plugins: dict) -> object:
    """An ``mi.Mesh`` of a ``ply`` plugin whose file is a :class:`MeshFile`, built from its triangles (float32
    positions, flat normals, its texture coordinates if it has them), with the plugin's other properties (its BSDF,
    a reference resolved, loaded anew)."""
    mesh = plugin["filename"]
    props = mi.Properties()
    for key, value in plugin.items():
        if key in ("type", "filename"):
            continue
        if isinstance(value, dict) and value["type"] == "ref":
            value = plugins[value["id"]]
        value = _load_dict_value(mi, value, plugins)
        props[key] = mi.load_dict(value) if isinstance(value, dict) else value
    shape = mi.Mesh(mesh.name, len(mesh.vertices), len(mesh.triangles), props=props,
                    has_vertex_normals=mesh.normals is not None, has_vertex_texcoords=mesh.uv is not None)
    params = mi.traverse(shape)
    params["vertex_positions"] = np.ascontiguousarray(mesh.vertices, dtype=np.float32).ravel()
    if mesh.normals is not None:  # updated with the positions: else Mitsuba would compute its own
        params["vertex_normals"] = np.ascontiguousarray(mesh.normals, dtype=np.float32).ravel()
    params["faces"] = np.ascontiguousarray(mesh.triangles, dtype=np.uint32).ravel()
    if mesh.uv is not None:
        params["vertex_texcoords"] = np.ascontiguousarray(mesh.uv, dtype=np.float32).ravel()
    params.update()
    return shape


def moment_integrator(nested: dict) -> dict:
    """``moment`` around ``aov`` around ``nested``: per-pixel first and second moments of the RGB samples.

    ``moment`` alone gives the moments of its nested integrator's colour converted to XYZ (whose second moments
    cannot be turned into RGB ones); the ``aov`` integrator in between passes the nested colour on as R, G, B
    (and A) AOV channels, whose moments ``moment`` then adds (see :func:`moment_channels`).
    """
    return {"type": "moment", "rgb": {"type": "aov", "aovs": "", "path": nested}}


# --------------------------------------------------------------------------------------------------------------------
# Moments of the samples


@dataclass(frozen=True)
class Moments:
    """Sums over a pixel's samples: ``n`` samples (per pixel), ``s1`` = sum of x, ``s2`` = sum of x^2 (float64)."""

    n: float
    s1: np.ndarray
    s2: np.ndarray

    @classmethod
    def from_means(cls, n: float, m1: np.ndarray, m2: np.ndarray) -> Moments:
        """From per-pixel means of x and x^2 over ``n`` samples (what Mitsuba's ``moment`` integrator outputs)."""
        return cls(float(n), float(n) * np.asarray(m1, np.float64), float(n) * np.asarray(m2, np.float64))


def merge_moments(parts: Iterable[Moments]) -> Moments:
    """The moments of the union of independent sample sets: sums add (exact up to float64 rounding)."""
    parts = list(parts)
    if not parts:
        raise ValueError("merge_moments needs at least one part")
    n = math.fsum(p.n for p in parts)
    s1 = np.sum([p.s1 for p in parts], axis=0, dtype=np.float64)
    s2 = np.sum([p.s2 for p in parts], axis=0, dtype=np.float64)
    return Moments(n, s1, s2)


def filter_efficiency(name: str) -> float:
    """(integral h)^2 / integral h^2 of the 2D pixel filter: Mitsuba's splatted estimate of a pixel from samples at
    density N per unit area has the variance of a plain mean of about this factor times N samples (box 1, tent
    2.25, Gaussian ~pi)."""
    pixel_filter = make_filter(name)
    if name == "box":
        return 1.0
    cells = 200000  # midpoint rule; the kernels are smooth enough for 1e-9 accuracy
    x = (np.arange(cells) + 0.5) / cells * 2.0 * pixel_filter.radius - pixel_filter.radius
    h = pixel_filter.eval_1d(x)
    one_d = h.sum() ** 2 / (h * h).sum() * (2.0 * pixel_filter.radius / cells)
    return float(one_d**2)


def mean_and_variance(moments: Moments, efficiency: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel mean S1/N and the variance of that mean.

    With ``efficiency`` 1 (box filter): (S2 - S1^2/N) / (N - 1) / N, the unbiased sample variance over N. Otherwise
    the weighted population variance S2/N - mean^2 divided by (N_eff - 1), N_eff = efficiency * N. NaN when
    N_eff <= 1.
    """
    n = float(moments.n)
    if efficiency == 1.0:  # plain samples: the harness's one formula for a mean and its variance
        estimate = Estimate.from_sums(moments.s1, moments.s2, n)
        return estimate.mean, estimate.variance
    mean = moments.s1 / n
    n_eff = efficiency * n
    if n_eff <= 1.0:
        return mean, np.full_like(mean, np.nan)
    variance = (moments.s2 / n - mean * mean) / (n_eff - 1.0)
    return mean, np.maximum(variance, 0.0)


def moment_channels(integrator, channel_count: int) -> tuple[list[int], list[int]]:
    """Indices of the m1 and m2 R, G, B channels in what ``mi.render`` returns for :func:`moment_integrator`.

    ``mi.render`` returns the film's R, G, B followed by the integrator's AOV channels, ``integrator.aov_names()``:
    for moment(aov(path)) those are ``<aov>.<path>.R, .G, .B, .A``, then the XYZ first moments ``<aov>.X, .Y, .Z``,
    then the same seven names prefixed ``m2_`` (second moments).
    """
    names = list(integrator.aov_names())
    base = channel_count - len(names)
    first = [n for n in names if n.endswith(".R") and not n.startswith("m2_")]
    if base != 3 or len(first) != 1:
        raise RuntimeError(f"unexpected channels from Mitsuba's moment integrator: {names}")
    stem = first[0][:-2]
    m1 = [base + names.index(f"{stem}.{c}") for c in "RGB"]
    m2 = [base + names.index(f"m2_{stem}.{c}") for c in "RGB"]
    return m1, m2


# --------------------------------------------------------------------------------------------------------------------
# The renderer


def pass_seed(seed: int, index: int) -> int:
    """A 32-bit Mitsuba seed for pass ``index`` of a render with ``seed``: a SplitMix64 hash of both, so that passes
    (and renders with nearby seeds) get unrelated seeds rather than consecutive ones, which Mitsuba's per-block
    seeding in scalar variants could make overlap."""
    mask = (1 << 64) - 1
    z = (int(seed) * 0x9E3779B97F4A7C15 + int(index) * 0xD1B54A32D192ED03 + 0x632BE59BD9B4E019) & mask
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
    z ^= z >> 31
    return int(z & 0xFFFFFFFF)


def _parse_int(key: str, value: str) -> int:
    """A setting's integer: plain decimal digits (``int()`` takes ``1_000`` too), within Mitsuba's 32 bits."""
    text = str(value).strip() if not isinstance(value, bool) else ""
    if not re.fullmatch(r"-?[0-9]{1,10}", text) or not -(2**31) <= int(text) < 2**31:
        raise HarnessError(f"--set {key}", f"expected an integer in plain decimal digits, of at most 2**31 - 1, "
                           f"got {value!r}")
    return int(text)


@dataclass(frozen=True)
class MitsubaSettings:
    variant: str | None
    chunk_spp: int
    max_depth: int
    moments: bool = True
    sampler: str = "independent"
    integrator: str | None = None  # None: the scene's (path or volpath)


def parse_settings(scene: Scene, settings: dict[str, str]) -> MitsubaSettings:
    """``--set`` values: ``variant``, ``chunk_spp`` (spp per pass, default 64), ``max_depth`` (default: the scene's),
    ``moments`` (``on``, the default: per-pixel variances through ``moment(aov(path))``; ``off``: Mitsuba's plain
    ``path`` integrator as a user runs it, no variance, used to time Mitsuba at its defaults), ``sampler`` (one of
    :data:`SAMPLERS`; default ``independent``: a stratified one makes the moment variances an upper bound),
    ``integrator`` (one of :data:`INTEGRATORS`; default: the scene's, ``path`` or ``volpath``)."""
    for key in settings:
        if key in ("spp", "seed"):
            raise HarnessError(f"--set {key}", f"give {key} with --{key}, not --set")
        if key not in SETTING_KEYS:
            raise HarnessError(f"--set {key}", f"unknown Mitsuba setting; expected one of {', '.join(SETTING_KEYS)}")
    chunk = _parse_int("chunk_spp", settings["chunk_spp"]) if "chunk_spp" in settings else DEFAULT_CHUNK_SPP
    if chunk < 1:
        raise HarnessError("--set chunk_spp", f"expected a positive integer, got {chunk}")
    depth = _parse_int("max_depth", settings["max_depth"]) if "max_depth" in settings else scene.max_depth
    if depth == 0 or depth < -1:
        raise HarnessError("--set max_depth", f"expected -1 (unbounded) or an integer >= 1, got {depth}")
    variant = settings.get("variant") or None
    moments = str(settings.get("moments", "on")).strip().lower()
    if moments not in ("on", "off"):
        raise HarnessError("--set moments", f"expected on or off, got {settings['moments']!r}")
    sampler = str(settings.get("sampler", "independent")).strip()
    if sampler not in SAMPLERS:
        raise HarnessError("--set sampler", f"expected one of {', '.join(SAMPLERS)}, got {settings['sampler']!r}")
    integrator = settings.get("integrator")
    if integrator is not None and str(integrator).strip() not in INTEGRATORS:
        raise HarnessError("--set integrator", f"expected one of {', '.join(INTEGRATORS)}, got {integrator!r}")
    return MitsubaSettings(variant.strip() if variant else None, chunk, depth, moments == "on", sampler,
                           str(integrator).strip() if integrator is not None else None)


def check_sampler_count(options: MitsubaSettings, spp: int) -> None:
    """A stratified sampler renders in one pass of exactly ``spp`` samples, or not at all (HarnessError)."""
    if options.sampler != "independent" and not sampler_takes(options.sampler, spp):
        want = {"ldsampler": "a power of 4 (>= 4)", "orthogonal": "the square of a prime"}.get(options.sampler, "a square")
        raise HarnessError("--set sampler", f"{options.sampler} draws {want} samples per pixel; --spp {spp} is not "
                                            "(Mitsuba would round it and the timing would count the wrong samples)")


class MitsubaRenderer:
    """Mitsuba 3's ``path`` integrator on the same scene, in passes, with per-pixel variances from all samples."""

    name = "mitsuba"

    def check(self, scene: Scene, request: RenderRequest) -> None:
        """Refuse bad ``--set`` values before any work (HarnessError at ``--set KEY``); imports no Mitsuba."""
        check_sampler_count(parse_settings(scene, request.settings), request.spp)

    def render(self, scene: Scene, request: RenderRequest) -> RenderResult:
        if request.spp < 1:
            raise HarnessError("--spp", f"expected a positive integer, got {request.spp}")
        options = parse_settings(scene, request.settings)
        check_sampler_count(options, request.spp)
        if options.sampler != "independent":  # one pass: its point set is the pixel's whole sample set
            options = dataclasses.replace(options, chunk_spp=request.spp)
        choice = resolve_variant(options.variant)
        mi = import_mitsuba(choice.variant)
        import drjit as dr  # optional: Dr.Jit comes with Mitsuba, imported only to render with it

        scene_dict = scene_to_mitsuba_dict(scene, choice.variant, max_depth=options.max_depth,
                                           spp=min(options.chunk_spp, request.spp), sampler=options.sampler)
        if options.integrator is not None:
            scene_dict["integrator"] = {**scene_dict["integrator"], "type": options.integrator}
        if options.moments:
            scene_dict["integrator"] = moment_integrator(scene_dict["integrator"])
        logger, level = mi.logger(), mi.logger().log_level()
        if scene.used_textures:
            # Mitsuba warns of a bitmap with values above 1 on every load, a light's radiance included; the loader
            # has checked every texture's range against its parameter (docs/scene-format.md, "Textures"). Loaded
            # on this thread, whose logger this is (a parallel load builds plugins on threads of their own), and
            # quiet until the passes are rendered: Mitsuba checks a bitmap's range when it first evaluates it.
            logger.set_log_level(mi.LogLevel.Error)
        try:
            mitsuba_scene = mi.load_dict(scene_dict, parallel=not scene.used_textures)
        except Exception as err:  # Mitsuba raises plain RuntimeErrors for anything it rejects
            logger.set_log_level(level)
            raise HarnessError(str(scene.path), f"Mitsuba cannot load the scene: {err}") from None

        try:
            width, height = scene.film.width, scene.film.height
            film = mitsuba_scene.sensors()[0].film()
            border = int(film.rfilter().border_size()) if scene.film.filter != "box" else 0
            # Mitsuba's wavefront (sampled pixels x spp of one pass) must stay below 2^32 lanes.
            chunk = max(1, min(options.chunk_spp, MAX_PASS_SAMPLES // ((width + 2 * border) * (height + 2 * border))))
            total_paths = width * height * request.spp
            m1_idx = m2_idx = None
            parts: list[Moments] = []
            plain_sum: np.ndarray | float = 0.0  # sum of pass means x pass spp, when moments are off
            seconds, first_pass_seconds, done = 0.0, 0.0, 0
            passes = math.ceil(request.spp / chunk)
            for index in range(passes):
                n = min(chunk, request.spp - index * chunk)
                start = time.perf_counter()
                out = np.array(mi.render(mitsuba_scene, seed=pass_seed(request.seed, index), spp=n), dtype=np.float32)
                elapsed = time.perf_counter() - start
                seconds += elapsed
                if index == 0:
                    first_pass_seconds = elapsed
                    if options.moments:
                        m1_idx, m2_idx = moment_channels(mitsuba_scene.integrator(), out.shape[2])
                if options.moments:
                    parts.append(Moments.from_means(n, out[..., m1_idx], out[..., m2_idx]))
                else:
                    plain_sum = plain_sum + out[..., :3].astype(np.float64) * n
                done += width * height * n
                if request.progress is not None:
                    request.progress(done, total_paths)

        finally:
            logger.set_log_level(level)

        if options.moments:
            merged = merge_moments(parts)
            image, variance = mean_and_variance(merged, filter_efficiency(scene.film.filter))
            variance = variance.astype(np.float32)
        else:
            image, variance = plain_sum / request.spp, None
        camera_rays = (width + 2 * border) * (height + 2 * border) * request.spp
        near, far = scene_dict["sensor"]["near_clip"], scene_dict["sensor"]["far_clip"]
        return RenderResult(
            renderer=self.name,
            image=image.astype(np.float32),
            variance=variance,
            seconds=seconds,
            spp=request.spp,
            rays={"camera": int(camera_rays)},
            stats={"passes": passes, "chunk_spp": chunk, "camera_rays": int(camera_rays),
                   "border_pixels": border},
            settings={"variant": choice.variant, "chunk_spp": chunk, "max_depth": options.max_depth,
                      "moments": "on" if options.moments else "off", "sampler": options.sampler,
                      "rr_depth": RR_DEPTH, "spp": request.spp, "seed": request.seed},
            info={
                "variant": choice.variant,
                "mitsuba_version": mi.__version__,
                "drjit_version": dr.__version__,
                "libllvm": choice.libllvm,
                "integrator": "moment(aov(path))" if options.moments else "path",
                "near_clip": near,
                "far_clip": far,
                "sample_border": bool(scene_dict["sensor"]["film"]["sample_border"]),
                "first_pass_seconds": first_pass_seconds,
                "rays_note": "Mitsuba reports no ray counts; camera rays are counted (incl. sampled border pixels), "
                             "shadow and indirect rays are unknown",
            },
        )
