"""Writing a ``results.json`` as strict JSON (:func:`dumps`) and reading it back (``harness report``, ``harness baseline save --from``, resuming ``harness run``):
parsed strictly and checked against its schema (docs/results-schema.md), so that every malformation is one line
naming the file and the JSON path of the bad key, e.g. ``DIR/results.json: cases[0].metrics: expected an object,
got -1``, before anything reads a field.

The checker is a small hand-written one (a few combinators below) rather than ``jsonschema``, which the harness
does not depend on: the schema is small, its messages are ours (the path as ``cases[0].render.spp``, the value
cut short), and it also rejects what JSON parsers let through: NaN / Infinity literals, numbers that overflow a
float, integers beyond Python's digit limit, absurd nesting.

Keys the schema does not name are allowed (a later harness may add some) but still scanned for those, and for
nesting deeper than :data:`MAX_DEPTH`.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any


from harness.core.errors import HarnessError, read_user_text

__all__ = ["MAX_DEPTH", "SCHEMA", "check_results", "check_spec", "read_results"]

SCHEMA = 1
#: deepest nesting accepted anywhere (harness run writes at most 6 levels)
MAX_DEPTH = 32
#: integers with more digits than this are refused (Python refuses to convert beyond 4300)
MAX_INT_DIGITS = 100

JsonPath = tuple  # keys (str) and list indices (int) from the top of the document


class _Bad(Exception):
    """A malformation at a JSON path (turned into a HarnessError by :func:`check_results`)."""

    def __init__(self, path: JsonPath, message: str):
        super().__init__(message)
        self.path = path
        self.message = message


# ---- what the parser lets through, kept as markers for the checker to name --------------------------------------


class _NotFinite:
    """A NaN / Infinity literal, or a number that overflows a float (1e999)."""

    def __init__(self, text: str):
        self.text = text


class _HugeInt:
    def __init__(self, digits: int):
        self.digits = digits


def _parse_float(text: str) -> float | _NotFinite:
    value = float(text)
    return value if math.isfinite(value) else _NotFinite(text)


def _parse_int(text: str) -> int | _HugeInt:
    digits = len(text.lstrip("-"))
    return int(text) if digits <= MAX_INT_DIGITS else _HugeInt(digits)


def _short(value: Any, limit: int = 60) -> str:
    """The value as a message shows it after "got": JSON spelling for scalars, the kind for containers."""
    if isinstance(value, _NotFinite):
        return f"{value.text} (not JSON; harness run writes null for a non-finite number)"
    if isinstance(value, _HugeInt):
        return f"an integer of {value.digits} digits"
    if isinstance(value, dict):
        return "an object" if value else "an empty object"
    if isinstance(value, list):
        return f"a list of {len(value)}" if value else "an empty list"
    text = json.dumps(value)  # str, int, float, bool, None; escapes newlines: one line
    return text if len(text) <= limit else text[: limit - 3] + "..."


def format_path(path: JsonPath) -> str:
    """``cases[0].render.spp``; keys that are not plain names JSON-quoted (``settings["a b"]``); a path deeper than
    12 levels cut short."""
    text = ""
    for part in path[:12]:
        if isinstance(part, int):
            text += f"[{part}]"
        elif re.fullmatch(r"[A-Za-z_][A-Za-z0-9_-]*", part):
            text += f".{part}" if text else part
        else:
            text += f"[{json.dumps(part)}]"
    return text + (f"... ({len(path)} levels)" if len(path) > 12 else "")


# ---- the checker's parts: each checks a value at a path, raising _Bad --------------------------------------------


class Spec:
    """A check of one JSON value. ``what`` is how a message names what was expected ("an integer")."""

    what = "a JSON value"

    def check(self, value: Any, path: JsonPath) -> None:
        _scan(value, path)

    def fail(self, value: Any, path: JsonPath) -> None:
        raise _Bad(path, f"expected {self.what}, got {_short(value)}")


def _scan(value: Any, path: JsonPath) -> None:
    """Anything goes, but no NaN / Infinity / huge integer and no nesting beyond MAX_DEPTH."""
    if isinstance(value, (_NotFinite, _HugeInt)):
        raise _Bad(path, f"expected a JSON value, got {_short(value)}")
    if isinstance(value, dict):
        _depth(path)
        for key, item in value.items():
            _scan(item, path + (key,))
    elif isinstance(value, list):
        _depth(path)
        for index, item in enumerate(value):
            _scan(item, path + (index,))


class Scalar(Spec):
    def __init__(self, what: str, test: Callable[[Any], bool]):
        self.what = what
        self.test = test

    def check(self, value: Any, path: JsonPath) -> None:
        if not self.test(value):
            self.fail(value, path)


def _is_int(v: Any) -> bool:
    return type(v) is int  # not bool


def _is_number(v: Any) -> bool:
    return (type(v) is int or type(v) is float) and math.isfinite(v)


STR = Scalar("a string", lambda v: isinstance(v, str))
NAME = Scalar("a non-empty string", lambda v: isinstance(v, str) and v != "")
BOOL = Scalar("true or false", lambda v: isinstance(v, bool))
INT = Scalar("an integer", _is_int)
COUNT = Scalar("an integer >= 0", lambda v: _is_int(v) and v >= 0)
POSITIVE_INT = Scalar("an integer >= 1", lambda v: _is_int(v) and v >= 1)
NUMBER = Scalar("a number", _is_number)
SECONDS = Scalar("a number >= 0", lambda v: _is_number(v) and v >= 0)
POSITIVE = Scalar("a number > 0", lambda v: _is_number(v) and v > 0)
ANY = Spec()


class Enum(Spec):
    def __init__(self, *values: str):
        self.values = values
        self.what = "one of " + ", ".join(json.dumps(v) for v in values)

    def check(self, value: Any, path: JsonPath) -> None:
        if not isinstance(value, str) or value not in self.values:
            self.fail(value, path)


class Nullable(Spec):
    def __init__(self, spec: Spec):
        self.spec = spec
        self.what = f"{spec.what} or null"

    def check(self, value: Any, path: JsonPath) -> None:
        if value is None:
            return
        try:
            self.spec.check(value, path)
        except _Bad as bad:
            if bad.path == path:  # the value itself is wrong: say that null would do too
                self.fail(value, path)
            raise


class ListOf(Spec):
    def __init__(self, item: Spec, length: int | None = None):
        self.item = item
        self.length = length
        self.what = f"a list of {length}" if length is not None else "a list"

    def check(self, value: Any, path: JsonPath) -> None:
        if not isinstance(value, list) or (self.length is not None and len(value) != self.length):
            self.fail(value, path)
        _depth(path)
        for index, item in enumerate(value):
            self.item.check(item, path + (index,))


class DictOf(Spec):
    """An object whose keys are free and whose values all match ``value``."""

    def __init__(self, value: Spec):
        self.value = value
        self.what = "an object"

    def check(self, value: Any, path: JsonPath) -> None:
        if not isinstance(value, dict):
            self.fail(value, path)
        _depth(path)
        for key, item in value.items():
            self.value.check(item, path + (key,))


class Obj(Spec):
    """An object with ``required`` and ``optional`` keys; other keys are allowed and only scanned."""

    what = "an object"

    def __init__(self, required: dict[str, Spec] | None = None, optional: dict[str, Spec] | None = None):
        self.required = required or {}
        self.optional = optional or {}

    def check(self, value: Any, path: JsonPath) -> None:
        if not isinstance(value, dict):
            self.fail(value, path)
        _depth(path)
        for key, spec in self.required.items():
            if key not in value:
                raise _Bad(path + (key,), f"missing; expected {spec.what}")
        for key, item in value.items():
            spec = self.required.get(key) or self.optional.get(key) or ANY
            spec.check(item, path + (key,))


class OneOf(Spec):
    """The first of ``specs`` whose ``accepts`` says the value is of its kind checks it."""

    def __init__(self, what: str, *choices: tuple[Callable[[Any], bool], Spec]):
        self.what = what
        self.choices = choices

    def check(self, value: Any, path: JsonPath) -> None:
        for accepts, spec in self.choices:
            if accepts(value):
                spec.check(value, path)
                return
        self.fail(value, path)


def _depth(path: JsonPath) -> None:
    """A container at ``path``: refused when it is MAX_DEPTH levels down already."""
    if len(path) >= MAX_DEPTH:
        raise _Bad(path, f"nested deeper than {MAX_DEPTH} levels")


# ---- the schema (docs/results-schema.md) -------------------------------------------------------------------------

def _range(what: str, low: float, high: float) -> Spec:
    return Nullable(Scalar(what, lambda v: _is_number(v) and low <= v <= high))


NUM_OR_NULL = Nullable(NUMBER)  # a non-finite number is written as null
NON_NEGATIVE = _range("a number >= 0", 0.0, math.inf)
PROBABILITY = _range("a probability in [0, 1]", 0.0, 1.0)
TRIPLE = ListOf(NUM_OR_NULL, 3)

BUDGET = OneOf('{"spp": int} or {"seconds": float}',
               (lambda v: isinstance(v, dict) and "spp" in v, Obj({"spp": POSITIVE_INT})),
               (lambda v: isinstance(v, dict) and "seconds" in v, Obj({"seconds": POSITIVE})))

AGAINST = Obj({"kind": Enum("ground-truth", "closed-form", "mitsuba", "renderer"), "renderer": Nullable(STR),
               "spp": Nullable(POSITIVE_INT), "seed": Nullable(COUNT), "settings": DictOf(STR)})

GROUND_TRUTH = Obj({"source": STR, "spp": COUNT, "cached": BOOL, "renders": COUNT, "seconds": SECONDS,
                    "path": Nullable(STR), "variant": Nullable(STR), "mitsuba_version": Nullable(STR)})

BIAS = Obj({"per_channel": ListOf(NUM_OR_NULL), "overall": NUM_OR_NULL,
            "stderr_per_channel": Nullable(ListOf(NON_NEGATIVE)), "stderr": NON_NEGATIVE})

METRICS = Obj(optional={"rmse": NON_NEGATIVE, "relmse": NON_NEGATIVE, "mape": NON_NEGATIVE, "psnr": NUM_OR_NULL,
                        "ssim": NUM_OR_NULL, "flip": NON_NEGATIVE, "bias": BIAS})

DOF = OneOf("a number, null or {min, max}", (lambda v: isinstance(v, dict), Obj({"min": NUMBER, "max": NUMBER})),
            (lambda v: True, NON_NEGATIVE))

VERDICT = Obj({
    "verdict": Enum("pass", "fail"), "reason": STR,
    "alpha": Scalar("a probability in (0, 1)", lambda v: _is_number(v) and 0 < v < 1),
    "threshold": Scalar("a probability in (0, 1)", lambda v: _is_number(v) and 0 < v < 1),
    "tile": POSITIVE_INT, "nonfinite_pixels": COUNT,
    "global_bias": Obj({"difference": TRIPLE, "stderr": ListOf(NON_NEGATIVE, 3), "z": TRIPLE,
                        "dof": ListOf(NON_NEGATIVE, 3), "p_values": ListOf(PROBABILITY, 3), "channels": COUNT,
                        "p_value": PROBABILITY}),
    "omnibus": Obj({"statistic": ListOf(NON_NEGATIVE, 3), "dof": ListOf(COUNT, 3), "p_values": ListOf(PROBABILITY, 3),
                    "p_value": PROBABILITY}),
    "max_z": Obj({"statistic": NON_NEGATIVE, "count": COUNT, "p_value": PROBABILITY}),
    "zero_variance": Obj({"tiles": COUNT, "differing": COUNT}),
    "worst_tile": Nullable(Obj({"row": COUNT, "col": COUNT, "y": COUNT, "x": COUNT, "height": COUNT, "width": COUNT,
                                "channel": Enum("R", "G", "B"), "pixels": COUNT, "difference": NUM_OR_NULL,
                                "stderr": NON_NEGATIVE, "z": NUM_OR_NULL, "z_normal": NUM_OR_NULL,
                                "dof": NON_NEGATIVE})),
    "variance_dof": Obj({"test": DOF}, {"ground_truth": DOF, "reference": DOF})},  # "reference": its older name
    {"variance_floor": Obj({"neighbourhood": COUNT, "tiles": COUNT}, {"dispersed": COUNT}),  # absent in older runs
     "sparse": Obj({"min_samples": NON_NEGATIVE, "tiles": COUNT, "share": PROBABILITY})})

RENDER = Obj({"seconds": SECONDS, "spp": COUNT, "paths_per_second": NON_NEGATIVE, "rays": DictOf(COUNT),
              "nonfinite_pixels": COUNT, "settings": DictOf(ANY), "info": DictOf(ANY), "exr": STR})

FILE_NAME = Scalar("a file name (no folder)", lambda v: isinstance(v, str) and v not in ("", ".", "..")
                   and not any(c in v for c in "/\\\0"))

REPORT_IMAGE = Obj({"key": NAME, "title": STR, "exr": FILE_NAME, "png": FILE_NAME, "description": STR,
                    "legend": Nullable(Obj({"cmap": STR, "vmin": NUM_OR_NULL, "vmax": NUM_OR_NULL,
                                            "stops": ListOf(STR), "unit": STR})),
                    "stats": DictOf(NUM_OR_NULL)})

REPORT_IMAGES = Obj({"folder": STR, "error_maps": DictOf(NUM_OR_NULL), "images": ListOf(REPORT_IMAGE)})

CASE_ALWAYS = {"name": NAME, "scene": STR, "renderer": STR, "settings": DictOf(STR), "budget": BUDGET, "seed": COUNT,
               "expect": Enum("pass", "fail"), "against": AGAINST, "status": Enum("pass", "fail", "error", "skipped"),
               "ok": BOOL, "reason": STR, "definition": STR, "wall_seconds": Nullable(SECONDS)}
CASE_COMPARED = {"metrics": METRICS, "verdict": VERDICT, "thresholds": DictOf(NUMBER),
                 "thresholds_broken": ListOf(STR), "render": RENDER}  # required unless status is error or skipped
MACHINE = {"node": STR, "cpu": Nullable(STR), "logical_cores": Nullable(POSITIVE_INT), "gpus": ListOf(STR)}
SYSTEM = Obj({**MACHINE, "os": STR, "python": STR, "numpy": Nullable(STR), "numba": Nullable(STR),
              "embreex": Nullable(STR), "embree": Nullable(STR),
              "mitsuba": Obj({"version": Nullable(STR), "variant": Nullable(STR)}, {"variants_used": ListOf(STR)}),
              "git": Nullable(Obj({"commit": NAME, "dirty": Nullable(BOOL)})), "seconds": SECONDS})
CACHED = Obj({"from": Nullable(STR), "key": STR}, {"machine": Obj(optional=MACHINE)})

VERDICT_MAPS = Obj({"pvalue": NAME, "failing": NAME})

GROUND_TRUTH_NOISE = Obj({"ratio": NON_NEGATIVE, "limit": POSITIVE, "ground_truth_spp": COUNT,
                          "suggested_spp": Nullable(POSITIVE_INT), "warning": Nullable(STR)})

VIEWER = Obj({"folder": STR, "data": FILE_NAME, "thumbnail": FILE_NAME, "pvalue": Nullable(FILE_NAME),
              "p_histogram": Nullable(Obj({"bins": POSITIVE_INT, "counts": ListOf(COUNT), "tested": COUNT,
                                           "failing": COUNT}))})

CASE_OPTIONAL = {"ground_truth": GROUND_TRUTH, "resumed": BOOL, "traceback": STR, "report_images": REPORT_IMAGES,
                 "verdict_maps": VERDICT_MAPS, "viewer": VIEWER, "cached": CACHED,
                 "ground_truth_noise": GROUND_TRUTH_NOISE, "ground_truth_caveat": STR, "requires": ListOf(STR)}


class _Case(Spec):
    """A case record: what a pass or fail needs, beyond what every record has, depends on its status."""

    what = "an object"
    compared = Obj({**CASE_ALWAYS, **CASE_COMPARED}, CASE_OPTIONAL)
    errored = Obj(CASE_ALWAYS, {**CASE_COMPARED, **CASE_OPTIONAL})

    def check(self, value: Any, path: JsonPath) -> None:
        judged = not isinstance(value, dict) or value.get("status") not in ("error", "skipped")
        spec = self.compared if judged else self.errored
        spec.check(value, path)


SUMMARY = Obj({"cases": COUNT, "ok": COUNT, "passed": COUNT, "failed": COUNT, "errors": COUNT,
               "unexpected": ListOf(STR), "mitsuba_renders": COUNT, "resumed": COUNT, "ground_truth_cached": COUNT,
               "wall_seconds": SECONDS}, {"skipped": COUNT, "from_cache": COUNT})

RESULTS = Obj({"schema": Scalar(f"{SCHEMA} (the schema this harness reads)", lambda v: _is_int(v) and v == SCHEMA),
               "suite": STR, "suite_file": STR, "description": STR, "started": STR,
               "host": Obj({"python": STR, "machine": STR, "node": STR}),
               "executor": STR, "complete": BOOL, "cases": ListOf(_Case()), "summary": SUMMARY},
              {"baseline": DictOf(ANY), "system": SYSTEM})


# ---- reading ----------------------------------------------------------------------------------------------------


def check_spec(spec: Spec, doc: Any, where: str) -> None:
    """``doc`` checked against ``spec`` (another file of the harness's own, checked the same way: calibration.json);
    the first malformation is a one-line HarnessError at ``where`` and its JSON path."""
    try:
        spec.check(doc, ())
    except _Bad as bad:
        raise HarnessError(f"{where}: {format_path(bad.path)}", bad.message) from None


def check_results(doc: Any, where: str, hint: str = "") -> dict:
    """``doc`` (parsed by :func:`parse`) if it is a results.json of schema 1; else a one-line HarnessError at
    ``where`` and the JSON path of the first bad key, with ``hint`` appended."""
    suffix = f"; {hint}" if hint else ""
    if not isinstance(doc, dict):
        raise HarnessError(where, f"expected a results.json of harness run (a JSON object), got {_short(doc)}"
                           + suffix)
    try:
        RESULTS.check(doc, ())
    except _Bad as bad:
        raise HarnessError(f"{where}: {format_path(bad.path)}", bad.message + suffix) from None
    return doc


def parse(text: str, where: str, hint: str = "") -> Any:
    """JSON ``text`` parsed with NaN, Infinity, overflowing numbers and huge integers kept as markers (for
    :func:`check_results` to name); a syntax error or absurd nesting is a one-line HarnessError at ``where``."""
    suffix = f"; {hint}" if hint else ""
    try:
        return json.loads(text, parse_constant=_NotFinite, parse_float=_parse_float, parse_int=_parse_int)
    except json.JSONDecodeError as err:
        raise HarnessError(f"{where}: line {err.lineno}, column {err.colno}", f"not JSON: {err.msg}"
                           + suffix) from None
    except RecursionError:
        raise HarnessError(where, f"not a results.json: JSON nested too deeply to read (harness run writes at most "
                           f"a few levels){suffix}") from None


def read_results(path: str | Path, *, where: str | None = None, hint: str = "") -> dict:
    """The checked content of the results.json at ``path``; one-line HarnessError at ``where`` (default: the
    path) when it is missing, unreadable, not UTF-8, not JSON or not a results.json of schema 1."""
    where = str(path) if where is None else where
    text = read_user_text(path, missing="no such results file (harness run writes DIR/results.json)", where=where)
    return check_results(parse(text, where, hint), where, hint)
