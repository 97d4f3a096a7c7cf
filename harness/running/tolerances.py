"""A baseline's tolerances: a suite file's ``[baseline]`` table and ``--baseline-tolerance KEY=VALUE``, parsed and
checked (what each one means: :mod:`harness.running.baseline`, ``docs/ci.md``). Read when a suite loads
(:func:`harness.running.cases.load_suite`), so a broken table is an error with or without ``--baseline``. Values are
read by :class:`~harness.scene.typed_reader.TypedReader` in the suite format's phrasing."""

from __future__ import annotations

from typing import Any

from harness.core.text import hint
from harness.scene.typed_reader import PYTHON_PHRASING, TypedReader

DEFAULT_ALPHA = 1e-3
NOISE_METRICS = ("rmse", "relmse", "mape")  # image means of a per-pixel error: statistical by default
FACTOR_METRICS = ("rmse", "relmse", "mape", "flip")  # lower is better: new <= factor x baseline
TOLERANCE_KEYS = (*FACTOR_METRICS, "psnr", "ssim", "bias", "seconds", "paths_per_second", "alpha")
DEFAULTS: dict[str, float | str] = {
    "rmse": "auto", "relmse": "auto", "mape": "auto", "bias": "auto", "flip": "off", "psnr": "off", "ssim": "off",
    "seconds": "off", "paths_per_second": "off", "alpha": DEFAULT_ALPHA,
}
OPTION = "--baseline-tolerance"
_NUMBER = "a finite number, 'auto' or 'off'"
#: The numbers each tolerance takes: (in range, what is expected), by key; the others take any finite number.
_RANGES = {
    "alpha": (lambda v: 0 < v < 1, "a probability in (0, 1)"),
    **{key: (lambda v: v >= 1, "a factor >= 1 (1.10 = 10 % worse allowed)")
       for key in (*FACTOR_METRICS, "seconds", "paths_per_second")},
    **{key: (lambda v: v >= 0, "the drop allowed, >= 0") for key in ("psnr", "ssim")},
    "bias": (lambda v: v > 0, "a positive |z| bound"),
}


class _OptionReader(TypedReader):
    """The typed readers of ``--baseline-tolerance``: a problem is placed at ``--baseline-tolerance KEY``."""

    def __init__(self):
        super().__init__(OPTION, PYTHON_PHRASING)

    def where(self, key: str) -> str:
        """``"--baseline-tolerance <key>"``, or the option alone (an empty ``key``)."""
        return f"{self.label} {key}" if key else self.label


def read_tolerance(reader: TypedReader, path: str, key: str, value: Any) -> float | str:
    """One tolerance value, checked: a number (its meaning: :mod:`harness.running.baseline`), "auto" or "off".

    Parameters
    ----------
    reader : TypedReader
        The reader of the suite file or of the option (its messages' place and phrasing).
    path : str
        The key path of the value, as messages name it.
    key : str
        The tolerance's name.
    value : object
        The parsed TOML value, or the option's text.

    Returns
    -------
    float or str
        The number, ``"auto"`` or ``"off"``.
    """
    if key not in TOLERANCE_KEYS:
        raise reader.error(path, f"unknown baseline tolerance{hint(key, TOLERANCE_KEYS)}; expected one of "
                                 f"{', '.join(TOLERANCE_KEYS)}")
    word = value.strip().lower() if isinstance(value, str) else None
    if value is False or word == "off":
        return "off"
    if word == "auto":
        return _auto(reader, path, key)
    number = reader.number(_from_text(reader, path, value), path, _NUMBER)
    _check_range(reader, path, key, number)
    return number


def _auto(reader: TypedReader, path: str, key: str) -> str:
    """``"auto"``, for the tolerances that have a statistical rule."""
    if key not in (*NOISE_METRICS, "bias"):
        raise reader.error(path, f"'auto' (a statistical rule) exists only for {', '.join(NOISE_METRICS)} and "
                                 "bias; give a number or 'off'")
    return "auto"


def _from_text(reader: TypedReader, path: str, value: Any) -> Any:
    """A string's number (``"1.10"``: an option's text, or a quoted number in the table); other values as given."""
    if not isinstance(value, str):
        return value
    try:
        return float(value)
    except ValueError:
        raise reader.expected(path, "a number, 'auto' or 'off'", value) from None


def _check_range(reader: TypedReader, path: str, key: str, number: float) -> None:
    """Refuse a number outside the range of tolerance ``key`` (:data:`_RANGES`)."""
    if key in _RANGES:
        in_range, what = _RANGES[key]
        if not in_range(number):
            raise reader.error(path, f"expected {what}, got {number}")


def check_table(label: str, table: Any) -> dict[str, float | str]:
    """A suite file's ``[baseline]`` table, checked (``label`` names the file): its tolerances, parsed. Called when
    the suite loads, so a broken table is an error whether or not the run has ``--baseline``."""
    reader = TypedReader(label, PYTHON_PHRASING)
    if not isinstance(table, dict):
        raise reader.expected("baseline", "a table [baseline]", table)
    return {key: read_tolerance(reader, reader.join("baseline", key), key, value) for key, value in table.items()}


def suite_tolerances(suite) -> dict[str, float | str]:
    """The suite file's ``[baseline]`` table (checked), on top of the defaults."""
    return {**DEFAULTS, **check_table(str(suite.path), suite.baseline)}


def option_tolerances(items: list[str], base: dict[str, float | str]) -> dict[str, float | str]:
    """``--baseline-tolerance KEY=VALUE`` items on top of ``base``."""
    reader = _OptionReader()
    out = dict(base)
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise reader.error("", f"expected KEY=VALUE (e.g. relmse=1.10), got {item!r}")
        key = key.strip()
        out[key] = read_tolerance(reader, key, key, value.strip())
    return out
