"""Renderers the harness can run, behind one protocol: ``render(scene, request) -> RenderResult``."""

from __future__ import annotations

from harness.core.errors import HarnessError
from harness.renderers.base import RenderRequest, RenderResult, Renderer
from harness.renderers.external import external_names, find_renderer
from harness.renderers.mitsuba import MitsubaRenderer
from harness.renderers.reference import ReferenceRenderer

_RENDERERS: dict[str, type] = {"mitsuba": MitsubaRenderer, "reference": ReferenceRenderer}


def renderer_names(bases: tuple = ()) -> list[str]:
    """Built-in renderers, ``renderers/NAME.toml`` files and ``harness.renderers`` entry points
    (``harness.renderers.external``); ``bases``: further folders whose ``renderers/`` subfolder counts."""
    return sorted(set(_RENDERERS) | set(external_names(tuple(bases))))


def get_renderer(name: str, bases: tuple = ()) -> Renderer:
    """The renderer ``name``: a built-in, the path of a renderer TOML file, a ``renderers/NAME.toml`` or a
    ``harness.renderers`` entry point (docs/external-renderers.md); anything else is a user error (--renderer)."""
    if name in _RENDERERS:
        return _RENDERERS[name]()
    renderer = find_renderer(name, tuple(bases))
    if renderer is None:
        raise HarnessError("--renderer", f"expected one of {', '.join(renderer_names(bases))} or the path of a "
                           f"renderer file (.toml), got {name!r}")
    return renderer


__all__ = ["RenderRequest", "RenderResult", "Renderer", "get_renderer", "renderer_names"]
