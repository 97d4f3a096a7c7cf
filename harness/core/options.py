"""Checks of command-line option values shared by the subcommands: one line naming the option (exit code 2).

Two layers. The argparse ``type=`` functions below (:func:`positive_int`, :func:`seconds`, :func:`spp_ladder`, ...)
parse an option's text strictly as it is read: integers in plain decimal digits only (``int()`` would also take
``1_000``, `` 7 `` and other scripts' digits), finite numbers only (no ``nan``, ``inf`` or ``1e999``), ladders
strictly increasing, output paths (:data:`out_folder`, :data:`out_file`) not empty and
not too long for the file system. Their :class:`argparse.ArgumentTypeError` message becomes ``OPTION: message``
(:class:`Parser`). The ``require_*`` functions check values that did not come through argparse;
:func:`parse_set` reads repeated ``--set KEY=VALUE`` options.
"""

from __future__ import annotations

import argparse
import math
import os
import re

from harness.core.errors import HarnessError
from harness.core.limits import MAX_FILM_SIDE, MAX_TIMEOUT_SECONDS, film_problem
from harness.core.text import hint, short

_OPTION_MESSAGE = re.compile(r"argument (-[^\s:]*): (.*)", re.S)
_INTEGER = re.compile(r"-?[0-9]+")
_NUMBER = re.compile(r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
_SIZE = re.compile(r"([0-9]+)[xX]([0-9]+)")



class Parser(argparse.ArgumentParser):
    """argparse, but an option is taken only by its whole name (``--sp`` is not ``--spp``: a prefix that names one
    option today names two after the next option is added), and a usage error is one line naming the option (and
    exit code 2): an unknown option names itself, with the closest option of its command."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def parse_args(self, args=None, namespace=None):  # noqa: D102 - argparse's signature
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            command = self._command_run(parsed)
            command._refuse_unknown(extras)
            raise HarnessError(command.prog, f"unrecognized arguments: {' '.join(extras)}")
        return parsed

    def parse_known_args(self, args=None, namespace=None):  # noqa: D102 - argparse's signature
        self._words = list(args) if args is not None else None  # for error(): an unknown option among them
        return super().parse_known_args(args, namespace)

    def _command_run(self, parsed: argparse.Namespace) -> argparse.ArgumentParser:
        """The (sub)command whose options count: the one ``parsed`` ran (nested: ``baseline save``)."""
        command = self
        action = next((a for a in self._actions if isinstance(a, argparse._SubParsersAction)), None)
        while action is not None:
            chosen = action.choices.get(getattr(parsed, action.dest, None) or "")
            if chosen is None:
                break
            command = chosen
            action = next((a for a in chosen._actions if isinstance(a, argparse._SubParsersAction)), None)
        return command

    def _refuse_unknown(self, words: list[str]) -> None:
        """The one line for the first of ``words`` that looks like an option this parser does not have, with the
        closest one it has; nothing when there is none."""
        known = [flag for action in self._actions for flag in action.option_strings]
        for word in words:
            if word == "--":
                return
            name = word.partition("=")[0]
            if word.startswith("-") and len(word) > 1 and not _NUMBER.fullmatch(word) and name not in known:
                raise HarnessError(name, f"unknown option of {self.prog}{hint(name, known)}")

    def error(self, message: str) -> None:  # noqa: D401 - argparse's signature
        if message.startswith("the following arguments are required") and getattr(self, "_words", None):
            # "--spp is required" after ``--sp 4``: the typo is the news
            self._refuse_unknown(self._words)
        match = _OPTION_MESSAGE.fullmatch(message)
        if match:  # "argument -s/--spp: expected ..." -> "--spp: expected ..."
            names = match[1].split("/")
            raise HarnessError(max(names, key=len), match[2])
        raise HarnessError(self.prog, message)

#: the values of an on/off environment variable that turn its feature off (any case, spaces around ignored)
OFF_WORDS = ("off", "0", "no", "false")


def switched_off(variable: str) -> bool:
    """Whether the environment variable ``variable`` turns its feature off (:data:`OFF_WORDS`); unset, empty or any
    other value leaves it on (``HARNESS_RESULTS_CACHE``, ``HARNESS_FSYNC``)."""
    return os.environ.get(variable, "").strip().lower() in OFF_WORDS


#: the values of an on/off environment variable that turn its feature on (:func:`env_switch`)
ON_WORDS = ("1", "on", "yes", "true")


def env_switch(variable: str, default: bool = False) -> bool:
    """The environment variable ``variable`` read as a strict switch: :data:`ON_WORDS` on, :data:`OFF_WORDS` off
    (any case, spaces around ignored), unset or empty ``default``; any other value is a HarnessError naming the
    variable (``HARNESS_ALLOW_OUTSIDE_PATHS``: a typo must not decide what a scene may read)."""
    text = os.environ.get(variable, "").strip().lower()
    if not text:
        return default
    if text in ON_WORDS or text in OFF_WORDS:
        return text in ON_WORDS
    raise HarnessError(variable, f"expected one of {', '.join(ON_WORDS)} (on) or {', '.join(OFF_WORDS)} (off), or "
                                 f"the variable unset, got {short(os.environ[variable])}")


def require_positive(option: str, value: int) -> int:
    """``value`` if it is >= 1, else the user error "OPTION: expected a positive integer, got VALUE"."""
    if value < 1:
        raise HarnessError(option, f"expected a positive integer, got {value}")
    return value


def require_non_negative(option: str, value: int) -> int:
    """``value`` if it is >= 0 (seeds), else the user error "OPTION: expected a non-negative integer, got VALUE"."""
    if value < 0:
        raise HarnessError(option, f"expected a non-negative integer, got {value}")
    return value


def parse_set(values: list[str]) -> dict[str, str]:
    """``--set KEY=VALUE`` options (repeatable) as a dict, keys and values stripped; a later key wins. An item
    without ``=`` or with an empty key is the user error "--set: expected key=value, got ITEM"."""
    settings: dict[str, str] = {}
    for item in values:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise HarnessError("--set", f"expected key=value, got {item!r}")
        settings[key.strip()] = value.strip()
    return settings


# ---- argparse type= functions ---------------------------------------------------------------------------------


def parse_int(text: str, what: str = "an integer") -> int:
    """``text`` as an integer if it is plain decimal digits (an optional leading ``-``), else ArgumentTypeError."""
    if not isinstance(text, str) or not _INTEGER.fullmatch(text):
        raise argparse.ArgumentTypeError(f"expected {what} in plain decimal digits, got {text!r}")
    try:
        return int(text)
    except ValueError:  # more digits than Python converts (sys.get_int_max_str_digits)
        raise argparse.ArgumentTypeError(f"expected {what} of a sensible size, got {len(text)} digits") from None


def parse_number(text: str, what: str = "a finite number") -> float:
    """``text`` as a finite float if it is a decimal number (``0.5``, ``2``, ``1e-3``), else ArgumentTypeError."""
    if not isinstance(text, str) or not _NUMBER.fullmatch(text):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    value = float(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return value


def int_type(minimum: int | None = None, maximum: int | None = None, what: str = "an integer"):
    """An argparse ``type=`` for an integer in [minimum, maximum] (either bound optional); ``what`` names it."""

    def convert(text: str) -> int:
        value = parse_int(text, what)
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
        return value

    convert.__name__ = "integer"
    return convert


def number_type(*, positive: bool = False, maximum: float | None = None, what: str = "a finite number"):
    """An argparse ``type=`` for a finite number, > 0 if ``positive``, <= ``maximum`` if given."""

    def convert(text: str) -> float:
        value = parse_number(text, what)
        if (positive and not value > 0) or (maximum is not None and value > maximum):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    convert.__name__ = "number"
    return convert


positive_int = int_type(1, what="a positive integer")
non_negative_int = int_type(0, what="a non-negative integer")
positive_number = number_type(positive=True, what="a positive finite number")
seconds = number_type(positive=True, maximum=MAX_TIMEOUT_SECONDS,
                      what=f"a positive number of seconds of at most {MAX_TIMEOUT_SECONDS:g} (a week)")


def probability(text: str) -> float:
    """A false-alarm probability in (0, 1)."""
    value = parse_number(text, "a false-alarm probability in (0, 1)")
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"expected a false-alarm probability in (0, 1), got {text!r}")
    return value


def film_size(text: str) -> str:
    """``WIDTHxHEIGHT`` with positive plain-decimal sides (e.g. ``64x64``); returned as given."""
    match = _SIZE.fullmatch(text) if isinstance(text, str) else None
    if not match or int(match[1]) < 1 or int(match[2]) < 1:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT with positive integer sides, e.g. 64x64, got {text!r}")
    return text


MAX_NAME_BYTES = 200  # a file system takes 255 bytes a name; the harness adds to a name (".tmp-...", ".png")
MAX_PATH_BYTES = 3000  # of PATH_MAX's 4096, with room for the files written inside a folder


def path_problem(text: str) -> str | None:
    """Why the file system would refuse ``text`` as a path (a NUL character, a name over :data:`MAX_NAME_BYTES`
    bytes, a path over :data:`MAX_PATH_BYTES`), or None: found before anything is read, rendered or written."""
    if "\0" in text:
        return "a path cannot hold a NUL character"
    try:
        raw = os.fsencode(text)
    except UnicodeEncodeError:
        return "a name this file system cannot encode"
    longest = max((len(part) for part in raw.split(b"/")), default=0)
    if longest > MAX_NAME_BYTES:
        return f"a name of {longest} bytes, more than the {MAX_NAME_BYTES} a name may have here"
    if len(raw) > MAX_PATH_BYTES:
        return f"{len(raw)} bytes, more than the {MAX_PATH_BYTES} a path may have here"
    return None


def path_type(what: str):
    """An argparse ``type=`` for an output path (``what``: "a folder path"): any text but an empty or blank one,
    which would otherwise read as "not given" (the default folder) or as the current folder."""

    def convert(text: str) -> str:
        if not isinstance(text, str) or not text.strip():
            raise argparse.ArgumentTypeError(f"expected {what}, got an empty string")
        problem = path_problem(text)
        if problem:
            raise argparse.ArgumentTypeError(f"expected {what}, got {short(text)}: {problem}")
        return text

    convert.__name__ = "path"
    return convert


out_folder = path_type("a folder path")
out_file = path_type("a file path")


def parse_ladder(text: str, kind: type = int) -> list:
    """``'1,2,4'`` as a strictly increasing list of positive integers (``kind=int``) or finite numbers
    (``kind=float``); ArgumentTypeError otherwise (a ladder out of order is refused, not sorted: it is likelier a
    typo than a wish)."""
    what = "positive integers" if kind is int else "positive numbers"
    items = [item.strip() for item in str(text).split(",")]
    if not any(items):
        raise argparse.ArgumentTypeError(f"expected comma-separated {what}, e.g. 1,2,4, got {text!r}")
    values = []
    for item in items:
        if not item:
            continue
        value = parse_int(item, "integers") if kind is int else parse_number(item, "finite numbers")
        if not value > 0:
            raise argparse.ArgumentTypeError(f"expected comma-separated {what}, got {item!r}")
        if values and not value > values[-1]:
            raise argparse.ArgumentTypeError(
                f"expected a strictly increasing ladder, got {item} after {values[-1]} in {text!r}")
        values.append(value)
    return values


def spp_ladder(text: str) -> str:
    """An argparse ``type=`` for a comma-separated spp ladder (strictly increasing positive integers); the text
    is returned as given, for the command's own parser ("" too: no ladder)."""
    if str(text).strip():
        parse_ladder(text, int)
    return text


MAX_BUDGET_FACTOR = 64.0  # harness calibrate --budgets: 64 x a case's budget is already a day on some cases


def budget_factors(text: str) -> str:
    """An argparse ``type=`` for ``harness calibrate --budgets``: comma-separated factors of a case's budget,
    strictly increasing, each > 0 and at most :data:`MAX_BUDGET_FACTOR`; the text is returned as given."""
    values = parse_ladder(text, float)
    if values[-1] > MAX_BUDGET_FACTOR:
        raise argparse.ArgumentTypeError(f"expected factors of at most {MAX_BUDGET_FACTOR:g}, got {values[-1]:g}")
    return text


def int_list(minimum: int, what: str):
    """An argparse ``type=`` for a strictly increasing comma-separated list of integers, each >= ``minimum``
    (``harness calibrate --spp 16,64,256``, ``--replicates 1,2,4``), as a tuple; ``what`` says why the least."""

    def convert(text: str) -> tuple[int, ...]:
        values = parse_ladder(text, int)
        if values[0] < minimum:
            raise argparse.ArgumentTypeError(f"expected comma-separated integers >= {minimum} ({what}), "
                                             f"got {values[0]} in {short(text)}")
        return tuple(values)

    convert.__name__ = "integers"
    return convert


#: the words of ``harness calibrate --films``: the case's own film, and it halved and doubled
FILM_WORDS = ("scene", "half", "double")
MIN_SWEEP_SIDE = 8  # a film side of a sweep: one verdict tile of the default 8 pixels


def film_list(text: str) -> tuple:
    """An argparse ``type=`` for ``harness calibrate --films``: comma-separated :data:`FILM_WORDS` or ``WxH``
    (each side from :data:`MIN_SWEEP_SIDE` to the film limit), as a tuple of words and (width, height) pairs; the
    words are resolved against each case's film by the calibration."""
    items = [item.strip() for item in str(text).split(",")]
    if not any(items):
        raise argparse.ArgumentTypeError(f"expected comma-separated films (scene, half, double or WxH), got {text!r}")
    films = []
    for item in filter(None, items):
        match = _SIZE.fullmatch(item)
        if item in FILM_WORDS:
            films.append(item)
        elif not match:
            raise argparse.ArgumentTypeError(f"expected comma-separated films (scene, half, double or WxH, e.g. "
                                             f"64x64), got {short(item)}{hint(item, list(FILM_WORDS))}")
        else:
            width, height = parse_int(match[1], "film sides"), parse_int(match[2], "film sides")
            if not MIN_SWEEP_SIDE <= min(width, height) <= max(width, height) <= MAX_FILM_SIDE:
                raise argparse.ArgumentTypeError(f"expected film sides from {MIN_SWEEP_SIDE} to {MAX_FILM_SIDE} "
                                                 f"pixels, got {item}")
            problem = film_problem(width, height)
            if problem:
                raise argparse.ArgumentTypeError(problem)
            films.append((width, height))
    return tuple(films)


def seconds_ladder(text: str) -> str:
    """An argparse ``type=`` for a comma-separated ladder of seconds (strictly increasing, finite, > 0); an empty
    one is refused (it has no default to stand for)."""
    parse_ladder(text, float)
    return text


_HOST_PORT = re.compile(r"(?:\[([0-9A-Fa-f:.]+)\]|([A-Za-z0-9.-]+)):([0-9]{1,5})")


def host_port(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (a name or IPv4 address, or an IPv6 address in brackets, ``[::1]:14158``; the port 1 to 65535)
    as (host, port)."""
    match = _HOST_PORT.fullmatch(text) if isinstance(text, str) else None
    if not match or not 1 <= int(match[3]) <= 65535:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT with a port from 1 to 65535, e.g. 127.0.0.1:14158, "
                                         f"got {short(text)}")
    return (match[1] or match[2], int(match[3]))
