"""Text for one-line messages: the did-you-mean hint, a value cut short after "got", a key as TOML spells it,
another program's text made safe to print."""

from __future__ import annotations

import difflib
import json
import re
from typing import Any


def hint(word: Any, candidates) -> str:
    """``"; did you mean 'x'?"`` for the candidate closest to ``word``, or an empty string."""
    close = difflib.get_close_matches(str(word), list(candidates), n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def short(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters, for "got ..." in one-line messages (an integer with more digits
    than Python prints is "a huge integer")."""
    try:
        text = repr(value)
    except ValueError:  # an integer with more digits than Python prints
        text = "a huge integer"
    return text if len(text) <= limit else text[: limit - 3] + "..."


def printable(text: str) -> str:
    """``text`` with every character that is not printable written as its Python escape (``\\x1b``, ``\\n``,
    ``\\u202e``): controls (C0, DEL, C1), format characters (the bidirectional overrides and isolates
    U+202A-202E and U+2066-2069, the marks U+200E/F, zero-width characters), line and paragraph separators and
    surrogates. For text written by another program (a renderer's stderr): printed, it stays on one line, moves no
    terminal's cursor, sets no title and reverses nothing after it."""
    return "".join(ch if ch.isprintable() else ch.encode("unicode_escape", "backslashreplace").decode("ascii")
                   for ch in text)


def toml_key(name: str) -> str:
    """A key as TOML writes it in a key path: bare if it can be, else quoted with every odd character escaped."""
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else json.dumps(name)
