"""How many specializations of the path loop the scenes compile: numba compiles one per distinct tuple of argument
types, seconds each with a cold cache, so scenes that differ only in textured lights or spheres must hand
``kernels.path.trace_paths`` the same types (``integrator._Context.features``), and a read-only array must not
turn writable on scenes without textures (docs/performance.md, "The README's first command")."""

from __future__ import annotations

import pytest

from tests.conftest import load_small

pytest.importorskip("numba")


class _Stop(Exception):
    """Raised where the render would compile the path loop: the signature is all the test needs."""


def _signature(name: str, monkeypatch, **settings) -> tuple:
    """The argument types a render of scene ``name`` (4 x 4, 1 spp) hands the path loop, found without compiling."""
    from harness.renderers import RenderRequest, get_renderer
    from reference_impl import integrator

    kernels = integrator._kernels()
    real = kernels.compile_once.compile_once
    found = []

    def spy(dispatcher, args):
        if dispatcher is kernels.path.trace_paths:
            found.append(kernels.compile_once.signature(dispatcher, args))
            raise _Stop
        real(dispatcher, args)

    monkeypatch.setattr(kernels.compile_once, "compile_once", spy)
    request = RenderRequest(spp=1, seed=1, settings={k: str(v) for k, v in settings.items()})
    with pytest.raises(_Stop):
        get_renderer("reference").render(load_small(name, 4), request)
    return found[0]


@pytest.mark.parametrize("with_emitters, scenes", [
    # spheres, a textured light, neither (the plain Lambertian loop of a strategy the blocks do not take)
    (False, [("furnace", {}), ("depth-of-field", {}), ("focused-plane", {}),
             ("cornell-box", {"direct": "hemisphere-cosine"})]),
    # the same with emitters that are not surfaces: points and spots, a sky, an environment with a sphere
    (True, [("point-spot", {}), ("sun-sky", {}), ("white-furnace", {}), ("orthographic-floor", {})]),
])
def test_lambertian_scenes_share_one_path_loop(with_emitters, scenes, monkeypatch):
    signatures = {name: _signature(name, monkeypatch, **settings) for name, settings in scenes}
    distinct = set(signatures.values())
    assert len(distinct) == 1, {name: str(sig) for name, sig in signatures.items()}
    emitters = next(iter(distinct))[11]  # trace_paths' emitters argument: None compiles their branches out
    assert (str(emitters) != "none") is with_emitters


def test_textured_materials_keep_the_read_only_type(monkeypatch):
    plain = _signature("furnace", monkeypatch)
    textured = _signature("textured-furnace", monkeypatch)
    assert plain[5] == textured[5]  # the material tables: read-only arrays either way
