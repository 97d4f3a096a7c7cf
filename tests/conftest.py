from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
sys.path.insert(0, str(Path(__file__).resolve().parent))  # test helpers: tests/chi2_cases.py, flaky_renderers.py

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


@pytest.fixture(scope="session", autouse=True)
def _private_cache(tmp_path_factory):
    """Every test (and every subprocess it starts) uses a fresh ground-truth cache, never the user's."""
    import os

    previous = os.environ.get("HARNESS_CACHE_DIR")
    os.environ["HARNESS_CACHE_DIR"] = str(tmp_path_factory.mktemp("harness-cache"))
    yield
    if previous is None:
        os.environ.pop("HARNESS_CACHE_DIR", None)
    else:
        os.environ["HARNESS_CACHE_DIR"] = previous


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


def render_reference(scene, spp: int, seed: int = 0, **settings):
    """Render with the reference renderer through the harness adapter; settings as key=value strings."""
    from harness.renderers import RenderRequest, get_renderer

    request = RenderRequest(spp=spp, seed=seed, settings={k: str(v) for k, v in settings.items()})
    return get_renderer("reference").render(scene, request)
