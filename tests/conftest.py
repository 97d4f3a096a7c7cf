from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path

# One OpenBLAS thread per test process (and the processes it starts), set before numpy loads OpenBLAS: the tests'
# matrix products are (n, 3) @ (3, 3), too small to share, and on two cores already busy with two xdist workers
# OpenBLAS's second thread only spins (tests/reference_impl and tests/judges' statistical files: 47 -> 42
# CPU-seconds; docs/performance.md). An explicit setting in the environment wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# Files are written atomically but not forced to the disk (harness.files.imageio._durable): a run writes thousands,
# at about 3.5 ms of fsync each here. tests/files/test_imageio.py turns fsync back on where it tests it.
os.environ.setdefault("HARNESS_FSYNC", "off")

import pytest  # noqa: E402
from hypothesis import settings  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
# tests/ mirrors the packages (tests/running/ tests harness/running/, ...). Test helpers that several folders use
# (chi2_cases, flaky_renderers, fuzz, test_hostile_input's cli() ...) import by module name: every folder on the path.
TESTS = Path(__file__).resolve().parent
for _folder in sorted(p for p in TESTS.iterdir() if p.is_dir() and not p.name.startswith((".", "_"))):
    sys.path.insert(0, str(_folder))
sys.path.insert(0, str(TESTS))

# Hypothesis: the same examples at every run. derandomize draws them from a seed fixed per test; without a database
# no failing example saved by an earlier run can change what a later run tries. HARNESS_FUZZ=long (docs/ci.md)
# selects the long profile and multiplies every test's max_examples by LONG_FUZZ_FACTOR (fuzz_examples).
FUZZ_LONG = os.environ.get("HARNESS_FUZZ", "") == "long"
LONG_FUZZ_FACTOR = 20
settings.register_profile("deterministic", derandomize=True, database=None, print_blob=True)
settings.register_profile("long", derandomize=True, database=None, print_blob=True, max_examples=2000)
settings.load_profile("long" if FUZZ_LONG else "deterministic")


def fuzz_examples(count: int) -> int:
    """``max_examples`` for a test's ``@settings``: ``count`` in the default run, LONG_FUZZ_FACTOR times as many
    under HARNESS_FUZZ=long (an explicit max_examples overrides the profile's)."""
    return count * LONG_FUZZ_FACTOR if FUZZ_LONG else count


_WARMUP_SECONDS = pytest.StashKey[float]()


def pytest_configure(config):
    """Keep bytecode in this process even where ``PYTHONDONTWRITEBYTECODE`` is set (as on the shared machines here):
    pytest then keeps each test module's rewritten bytecode in ``__pycache__`` (git-ignored) and every xdist worker
    of a later run reads it instead of rewriting the asserts of ~290 modules again (a worker's collection: 10.2 s
    without, 4.9 s with, docs/ci.md). ``HARNESS_TEST_WARMUP=off`` leaves the interpreter's setting alone."""
    if os.environ.get("HARNESS_TEST_WARMUP", "") != "off":
        sys.dont_write_bytecode = False


def pytest_sessionstart(session):
    """Fill numba's cache with the reference renderer's kernels before any test (or xdist worker) starts, when it
    is cold (a clean clone: CI). In the controlling process only: xdist starts its workers after this hook, so they
    and the ``harness`` subprocesses of the tests load the kernels instead of each compiling them again
    (tests/warm_kernels.py; ``HARNESS_TEST_WARMUP=off`` skips it, docs/ci.md)."""
    if os.environ.get("PYTEST_XDIST_WORKER") or os.environ.get("HARNESS_TEST_WARMUP", "") == "off":
        return
    import warm_kernels

    if not warm_kernels.cache_is_warm():
        seconds = warm_kernels.warm_in_parallel()
        session.config.stash[_WARMUP_SECONDS] = seconds


def pytest_terminal_summary(terminalreporter, config):
    seconds = config.stash.get(_WARMUP_SECONDS, None)
    if seconds is not None:
        terminalreporter.write_line(f"numba's cache was cold: the kernels were compiled before the tests in "
                                    f"{seconds:.1f} s (tests/warm_kernels.py)")



# A small valid scene file: a camera, a 16 x 16 film and one white material, no shapes. Tests add shapes to it.
MINIMAL_SCENE = """\
name = "minimal"

[camera]
origin = [0, 0, 5]
target = [0, 0, 0]
up = [0, 1, 0]
fov = 40

[film]
width = 16
height = 16

[materials.white]
reflectance = [0.8, 0.8, 0.8]
"""


def _session_cache_dir(tmp_path_factory) -> Path:
    """This run's ground-truth cache: one folder for all pytest-xdist workers of the run (the parent of their base
    temporary folders is the run's own), so that a Mitsuba ground truth is rendered once per run, not once per
    worker; the cache is content-addressed and safe for concurrent processes (tests/renderers/test_groundtruth.py,
    ``test_two_processes_fill_the_same_entries``). Without xdist, a folder of the run's base temporary folder."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        folder = tmp_path_factory.getbasetemp().parent / "harness-cache"
        folder.mkdir(exist_ok=True)
        return folder
    return tmp_path_factory.mktemp("harness-cache")


@pytest.fixture(scope="session", autouse=True)
def _private_cache(tmp_path_factory):
    """Every test (and every subprocess it starts) uses a ground-truth cache fresh for this run (shared by its
    xdist workers, :func:`_session_cache_dir`), never the user's, and no
    results cache (``HARNESS_RESULTS_CACHE=off``): a test that runs a suite, patches a renderer and runs it again
    must see it render. tests/running/test_result_cache.py turns the results cache on, in a folder of its own."""
    previous = {name: os.environ.get(name) for name in ("HARNESS_CACHE_DIR", "HARNESS_RESULTS_CACHE")}
    os.environ["HARNESS_CACHE_DIR"] = str(_session_cache_dir(tmp_path_factory))
    os.environ["HARNESS_RESULTS_CACHE"] = "off"
    yield
    for name, value in previous.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


@pytest.fixture(scope="session")
def scenes_dir() -> Path:
    return SCENES


def load_small(name: str, width: int, height: int | None = None, **overrides):
    """A canonical scene at a smaller resolution (same camera), for fast statistical tests."""
    from harness.scene import load_scene
    from reference_impl import Film

    scene = load_scene(SCENES / f"{name}.toml")
    film = Film(width, height or width, scene.film.filter)
    return dataclasses.replace(scene, film=film, **overrides)


def render_spied(scene, spp: int, blocks: bool, monkeypatch, kernel: tuple[str, str], seed: int = 3, **settings):
    """A reference render with the paths in blocks where a scene allows (``blocks``, ``integrator.BLOCKS``) or with
    the path loop alone, and whether the kernel ``kernel`` (module of ``reference_impl.kernels``, function) ran."""
    from harness.renderers import RenderRequest, get_renderer
    from reference_impl import integrator

    kernels = integrator._kernels()
    module, name = getattr(kernels, kernel[0]), kernel[1]
    calls = []
    traced = getattr(module, name)

    def spy(*args):
        calls.append(len(args[0][0]))
        return traced(*args)

    monkeypatch.setattr(integrator, "BLOCKS", blocks)
    monkeypatch.setattr(module, name, spy)
    request = RenderRequest(spp=spp, seed=seed, settings={k: str(v) for k, v in settings.items()})
    return get_renderer("reference").render(scene, request), bool(calls)


def same_as_path_loop(scene, spp: int, monkeypatch, kernel: tuple[str, str], **settings):
    """Render ``scene`` with the blocks, where ``kernel`` must run, and with the path loop alone: the same image,
    variance and counters (the Embree time aside). Returns the blocks' render."""
    import numpy as np

    blocks, ran = render_spied(scene, spp, True, monkeypatch, kernel, **settings)
    loop, loop_ran = render_spied(scene, spp, False, monkeypatch, kernel, **settings)
    assert ran and not loop_ran
    assert np.array_equal(blocks.image, loop.image)
    assert np.array_equal(blocks.variance, loop.variance, equal_nan=True)
    counters = {k: v for k, v in blocks.stats.items() if k != "embree_microseconds"}
    assert counters == {k: v for k, v in loop.stats.items() if k != "embree_microseconds"}
    return blocks


def render_reference(scene, spp: int, seed: int = 0, **settings):
    """Render with the reference renderer through the harness adapter; settings as key=value strings."""
    from harness.renderers import RenderRequest, get_renderer

    request = RenderRequest(spp=spp, seed=seed, settings={k: str(v) for k, v in settings.items()})
    return get_renderer("reference").render(scene, request)


def ply_ascii(vertices, faces, normals=None, uv=None) -> str:
    """An ASCII PLY (:func:`harness.scene.mesh_assets.ply_text`) of ``vertices`` and ``faces``, with ``nx, ny, nz``
    (written as given: "nan" stays nan) and ``u, v`` where given."""
    import numpy as np

    from harness.scene.mesh_assets import ply_text

    return ply_text(np.asarray(vertices, float), np.asarray(faces),
                    None if normals is None else np.asarray(normals, float),
                    None if uv is None else np.asarray(uv, float)).decode()
