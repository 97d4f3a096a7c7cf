"""Reading the values of a parsed TOML file by type: tables, strings, booleans, integers, numbers, vectors, matrices,
one of a set of names, known keys. Each problem is a one-line :class:`~harness.core.errors.HarnessError` whose
``where`` is ``"<file>: <key path>"`` and whose message says what was expected and what was found.

:class:`TypedReader` holds the readers; :class:`Phrasing` how its messages show a value, spell a key and refuse an
unknown key. The scene format (:mod:`harness.scene.load`) reads with :data:`TOML_PHRASING`, the suite format
(:mod:`harness.running.cases`) with :data:`PYTHON_PHRASING`.
"""

from __future__ import annotations

import datetime
import json
import math
import re
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from harness.core.errors import HarnessError
from harness.core.limits import float_or_inf
from harness.core.text import hint, short, toml_key

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


# ---- values and keys in messages -----------------------------------------------------------------------------------


def show_value(value: Any, limit: int = 60) -> str:
    """A short TOML-like rendering of a parsed value for "got ..." in messages."""
    text = _toml_text(value, depth=0)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _toml_text(value: Any, depth: int) -> str:
    if depth > 4:
        return "..."
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        try:
            return str(value)
        except ValueError:  # more digits than Python will print
            return "a huge integer"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return quoted(value)
    if isinstance(value, list):
        items = [_toml_text(item, depth + 1) for item in value[:8]]
        return "[" + ", ".join(items) + (", ...]" if len(value) > 8 else "]")
    if isinstance(value, dict):
        items = [f"{key_text(k)} = {_toml_text(v, depth + 1)}" for k, v in list(value.items())[:8]]
        return "{" + ", ".join(items) + (", ...}" if len(value) > 8 else "}")
    if isinstance(value, (datetime.date, datetime.time)):
        return value.isoformat()
    return repr(value)


def key_text(key: str) -> str:
    """A key as TOML writes it: bare if it can be, quoted otherwise (:func:`quoted`)."""
    return key if _BARE_KEY.fullmatch(key) else quoted(key)


def quoted(text: str) -> str:
    """A JSON string literal that stays on one line: non-printable characters (line and paragraph separators
    too, which JSON leaves alone) are escaped as \\uXXXX."""
    return "".join(ch if ch.isprintable() else ch.encode("unicode_escape").decode("ascii")
                   for ch in json.dumps(text, ensure_ascii=False))


def finite_float(value: Any) -> float | None:
    """``value`` as a float if it is a finite TOML number (not a boolean), else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def _unknown_key_named(key: str, known: tuple[str, ...]) -> str:
    listed = "; expected one of: " + ", ".join(known)
    return f"unknown key {key!r}{hint(key, known) or listed}"


def _unknown_key_listed(key: str, known: tuple[str, ...]) -> str:
    return f"unknown key{hint(key, known)}; expected one of {', '.join(known)}"


@dataclass(frozen=True)
class Phrasing:
    """How a reader's messages show a value, spell a key in a key path and refuse an unknown key.

    Attributes
    ----------
    show : callable
        ``show(value) -> str``: a parsed value after "got".
    key_text : callable
        ``key_text(key) -> str``: one key of a key path.
    unknown_key : callable
        ``unknown_key(key, known) -> str``: the message refusing ``key``, which is not among ``known``.
    """

    show: Callable[[Any], str]
    key_text: Callable[[str], str]
    unknown_key: Callable[[str, tuple[str, ...]], str]


#: Values as TOML writes them (:func:`show_value`), keys bare or quoted (:func:`key_text`); an unknown key named, with
#: the closest known key or else the list of them. The scene format's.
TOML_PHRASING = Phrasing(show_value, key_text, _unknown_key_named)
#: Values as Python writes them, cut at 80 characters (:func:`harness.core.text.short`), keys bare or quoted
#: (:func:`harness.core.text.toml_key`); an unknown key with the closest known key and the list of them. The suite
#: format's.
PYTHON_PHRASING = Phrasing(short, toml_key, _unknown_key_listed)


# ---- the reader ----------------------------------------------------------------------------------------------------


class TypedReader:
    """The typed readers of one parsed TOML file: each returns the value read or raises a one-line
    :class:`HarnessError` at ``"<label>: <key>"``.

    Parameters
    ----------
    label : str
        The file as messages name it.
    phrasing : Phrasing
        How the messages show values and keys (:data:`TOML_PHRASING`, :data:`PYTHON_PHRASING`).
    """

    def __init__(self, label: str, phrasing: Phrasing = TOML_PHRASING):
        self.label = label
        self.phrasing = phrasing

    # ---- errors and key paths ------------------------------------------------------------------------------------

    def where(self, key: str) -> str:
        """``"<label>: <key>"``, or the label alone for the whole file (an empty ``key``)."""
        return f"{self.label}: {key}" if key else self.label

    def error(self, key: str, message: str) -> HarnessError:
        return HarnessError(self.where(key), message)

    def expected(self, key: str, what: str, value: Any) -> HarnessError:
        return self.error(key, f"expected {what}, got {self.show(value)}")

    def show(self, value: Any) -> str:
        """A parsed value in a message."""
        return self.phrasing.show(value)

    def join(self, parent: str, key: str) -> str:
        """The dotted key path of ``key`` inside the table at ``parent``."""
        text = self.phrasing.key_text(key)
        return f"{parent}.{text}" if parent else text

    # ---- tables and keys -----------------------------------------------------------------------------------------

    def check_keys(self, table: dict, known: tuple[str, ...], parent: str) -> None:
        """Refuse keys of ``table`` that are not in ``known``, suggesting the closest known one."""
        for key in table:
            if key not in known:
                raise self.error(self.join(parent, key), self.phrasing.unknown_key(key, known))

    def require(self, table: dict, key: str, parent: str, what: str) -> Any:
        if key not in table:
            raise self.error(self.join(parent, key), f"missing required key {key!r} ({what})")
        return table[key]

    def required_table(self, document: dict, name: str) -> dict:
        if name not in document:
            raise self.error(name, f"missing required table [{name}]")
        return self.table(document[name], name)

    def table(self, value: Any, key: str) -> dict:
        if not isinstance(value, dict):
            raise self.expected(key, "a table", value)
        return value

    def array(self, value: Any, key: str, what: str = "a list") -> list:
        if not isinstance(value, list):
            raise self.expected(key, what, value)
        return value

    # ---- values --------------------------------------------------------------------------------------------------

    def string(self, value: Any, key: str) -> str:
        if not isinstance(value, str):
            raise self.expected(key, "a string", value)
        return value

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.expected(key, "true or false", value)
        return value

    def integer(self, value: Any, key: str, what: str = "an integer") -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.expected(key, what, value)
        return value

    def number(self, value: Any, key: str, what: str = "a finite number") -> float:
        """A finite number (an integer or a float, not a boolean), as a float."""
        number = finite_float(value)
        if number is None:
            raise self.expected(key, what, value)
        return number

    def numeric(self, value: Any, key: str) -> int | float:
        """An integer or a float as parsed (not a boolean): a float may be infinite or nan, an integer may not be
        beyond a float's range."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.expected(key, "a number", value)
        if not isinstance(value, float) and float_or_inf(value) == math.inf:
            raise self.error(key, f"expected a finite number, got an integer of {len(str(value))} digits")
        return value

    def positive(self, value: Any, key: str, *, integer: bool = False) -> int | float:
        """A positive integer (``integer``) or a positive finite number (:meth:`numeric`), as parsed."""
        value = self.integer(value, key) if integer else self.numeric(value, key)
        if not value > 0 or (isinstance(value, float) and not np.isfinite(value)):
            raise self.error(key, f"expected a positive number, got {value!r}")
        return value

    def non_negative(self, value: Any, key: str) -> int:
        """An integer >= 0."""
        value = self.integer(value, key)
        if value < 0:
            raise self.error(key, f"expected a non-negative integer, got {value}")
        return value

    def vector3(self, value: Any, key: str, what: str = "a list of 3 finite numbers") -> tuple[float, float, float]:
        if not isinstance(value, list) or len(value) != 3:
            raise self.expected(key, what, value)
        numbers = [finite_float(item) for item in value]
        if any(number is None for number in numbers):
            raise self.expected(key, what, value)
        return tuple(numbers)

    def colour_or_number(self, value: Any, key: str, what: str) -> tuple[float, float, float]:
        """One finite number (the same in every channel, as Mitsuba takes it) or a list of 3."""
        if isinstance(value, list):
            return self.vector3(value, key, what)
        number = self.number(value, key, what)
        return (number, number, number)

    def matrix4(self, value: Any, key: str) -> np.ndarray:
        what = "a 4x4 nested list of finite numbers (row-major)"
        if not isinstance(value, list) or len(value) != 4:
            raise self.expected(key, what, value)
        rows = []
        for row in value:
            if not isinstance(row, list) or len(row) != 4:
                raise self.expected(key, what, value)
            numbers = [finite_float(item) for item in row]
            if any(number is None for number in numbers):
                raise self.expected(key, what, value)
            rows.append(numbers)
        matrix = np.array(rows, dtype=np.float64)
        if not np.array_equal(matrix[3], [0.0, 0.0, 0.0, 1.0]):
            raise self.expected(key, "an affine transform whose last row is [0, 0, 0, 1]", value[3])
        return matrix

    def choice(self, value: Any, key: str, choices: tuple[str, ...]) -> str:
        """One of ``choices``, with the closest one suggested."""
        if not isinstance(value, str) or value not in choices:
            suggestion = hint(value, choices) if isinstance(value, str) else ""
            raise self.error(key, f"expected one of {', '.join(choices)}, got {self.show(value)}{suggestion}")
        return value
