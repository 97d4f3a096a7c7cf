"""Short labels for the report's tables: a long text cut at a word with an ellipsis, a renderer file named by its
file name; the whole text goes in the cell's ``title`` (shown on hover)."""

from __future__ import annotations

from pathlib import PurePath

ELLIPSIS = "…"


def clip(text: str | None, limit: int = 120) -> str:
    """``text`` (whitespace runs made one space) at most ``limit`` characters: cut after the last whole word that
    fits and ended with an ellipsis, never inside a word (a single word longer than ``limit`` is cut, with the
    ellipsis)."""
    words = " ".join(str(text or "").split())
    if len(words) <= limit:
        return words
    head = words[: limit - len(ELLIPSIS) + 1]
    cut = head.rfind(" ")
    head = head[:cut] if cut > 0 else head[: limit - len(ELLIPSIS)]
    return head.rstrip(" ,;:.-([{") + ELLIPSIS


def renderer_label(renderer: str | None) -> str | None:
    """How a table names a case's renderer: a built-in's name as it is; a renderer file (results.json holds its
    absolute path) by its file name, e.g. ``toy.toml``."""
    if renderer is None:
        return None
    text = str(renderer)
    if "/" in text or "\\" in text:
        return PurePath(text.replace("\\", "/")).name or text
    return text


def title_of(full: str | None, shown: str | None) -> str | None:
    """The ``title`` attribute of a cell: the whole text where the cell shows less of it (or another name for it),
    else None."""
    if full is None or str(full) == shown or " ".join(str(full).split()) == shown:
        return None
    return str(full)
