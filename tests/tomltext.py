"""TOML text of a Python document, for tests that write generated scene and suite files: ``tomli_w`` (the
writer that pairs with the standard library's ``tomllib``) after leaving out None values, which TOML lacks."""

from __future__ import annotations

import json

import tomli_w


def without_none(value):
    """``value`` with every None (in tables and arrays, at any depth) left out."""
    if isinstance(value, dict):
        return {str(k): without_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [without_none(v) for v in value if v is not None]
    return value


def to_toml(document: dict) -> str:
    """The TOML text of ``document`` (keys quoted where TOML needs it, NaN and infinities as TOML writes them)."""
    return tomli_w.dumps(without_none(document))


def toml_string(text: str) -> str:
    """``text`` as a TOML basic string, to put into a document's text by hand (JSON's escapes, non-ASCII kept)."""
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")
