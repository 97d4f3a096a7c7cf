"""Text for one-line messages: the did-you-mean hint, a value cut short after "got", a key as TOML spells it."""

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


def toml_key(name: str) -> str:
    """A key as TOML writes it in a key path: bare if it can be, else quoted with every odd character escaped."""
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else json.dumps(name)
