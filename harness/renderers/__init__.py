"""Renderers the harness can run, behind one protocol: ``render(scene, request) -> RenderResult``."""

from __future__ import annotations

from harness.errors import HarnessError
from harness.renderers.base import RenderRequest, RenderResult, Renderer
from harness.renderers.mitsuba import MitsubaRenderer
from harness.renderers.reference import ReferenceRenderer

_RENDERERS: dict[str, type] = {"mitsuba": MitsubaRenderer, "reference": ReferenceRenderer}


def renderer_names() -> list[str]:
    return sorted(_RENDERERS)


def get_renderer(name: str) -> Renderer:
    """The renderer registered under ``name``; unknown names are a user error (option --renderer)."""
    try:
        return _RENDERERS[name]()
    except KeyError:
        raise HarnessError("--renderer", f"expected one of {', '.join(renderer_names())}, got {name!r}") from None


__all__ = ["RenderRequest", "RenderResult", "Renderer", "get_renderer", "renderer_names"]
