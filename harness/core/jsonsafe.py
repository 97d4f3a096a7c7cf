"""The one JSON sanitiser: what the harness writes as JSON goes through :func:`plain` (or :func:`dumps`).

Non-finite floats become None (``null``: JSON has no NaN or infinity), numpy scalars and arrays plain Python
numbers and lists, paths strings, dataclass instances dicts, dict keys strings, tuples lists. Anything else is
left as it is (``json.dumps`` then refuses it). ``strings``, where given, maps every string value (not the dict
keys, not the paths) on the same walk: the report rewrites its staged paths so (harness.report.build).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import PurePath
from collections.abc import Callable
from typing import Any

import numpy as np


def plain(value: Any, strings: Callable[[str], str] | None = None) -> Any:
    """``value`` with only JSON's types in it (see the module docstring); ``strings(text)`` for every string value."""
    if isinstance(value, str):
        return value if strings is None else strings(value)
    if isinstance(value, dict):
        return {str(k): plain(v, strings) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v, strings) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist(), strings)
    if isinstance(value, np.generic):
        return plain(value.item(), strings)
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, PurePath):
        return str(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return plain(dataclasses.asdict(value), strings)
    return value


def dumps(value: Any, strings: Callable[[str], str] | None = None, **kwargs: Any) -> str:
    """``json.dumps`` of :func:`plain` ``(value, strings)`` with ``allow_nan=False`` (``kwargs``: indent, sort_keys,
    ...)."""
    return json.dumps(plain(value, strings), allow_nan=False, **kwargs)
