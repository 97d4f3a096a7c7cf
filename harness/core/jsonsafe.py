"""The one JSON sanitiser: what the harness writes as JSON goes through :func:`plain` (or :func:`dumps`).

Non-finite floats become None (``null``: JSON has no NaN or infinity), numpy scalars and arrays plain Python
numbers and lists, paths strings, dataclass instances dicts, dict keys strings, tuples lists. Anything else is
left as it is (``json.dumps`` then refuses it).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import PurePath
from typing import Any

import numpy as np


def plain(value: Any) -> Any:
    """``value`` with only JSON's types in it (see the module docstring)."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return plain(value.item())
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, PurePath):
        return str(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return plain(dataclasses.asdict(value))
    return value


def dumps(value: Any, **kwargs: Any) -> str:
    """``json.dumps`` of :func:`plain` ``(value)`` with ``allow_nan=False`` (``kwargs``: indent, sort_keys, ...)."""
    return json.dumps(plain(value), allow_nan=False, **kwargs)
