"""The importers' one TOML writer (harness.renderers.imports.toml_value, toml_key): what it writes reads back as
the same values."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from harness.renderers.imports import toml_key, toml_table, toml_value


def test_values_read_back_as_written():
    values = {"t": True, "i": -3, "f": 0.1 + 0.2, "neg_zero": -0.0, "tiny": 5e-324, "s": 'a "b"\\ \x7f \u00e9 \n',
              "list": [1, 2.5, "x"], "array": np.array([0.25, -1.0]), "np_f": np.float32(0.1), "np_i": np.int64(7),
              "inline": {"key with space": 1.0, "bare-key_1": [0.5]}}
    text = "\n".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in values.items())
    back = tomllib.loads(text)
    assert back["f"] == 0.1 + 0.2 and math.copysign(1.0, back["neg_zero"]) == -1.0 and back["tiny"] == 5e-324
    assert back["s"] == values["s"] and back["list"] == [1, 2.5, "x"] and back["array"] == [0.25, -1.0]
    assert back["np_f"] == float(np.float32(0.1)) and back["np_i"] == 7 and back["t"] is True
    assert back["inline"] == {"key with space": 1.0, "bare-key_1": [0.5]}
    infinite = tomllib.loads(f"a = {toml_value(math.inf)}\nb = {toml_value(-math.inf)}\nc = {toml_value(math.nan)}")
    assert infinite["a"] == math.inf and infinite["b"] == -math.inf and math.isnan(infinite["c"])
    assert toml_key("plain_key-1") == "plain_key-1" and toml_key("a.b") == '"a.b"'
    assert tomllib.loads("\n".join(toml_table("materials.red", {"reflectance": [0.9, 0.1, 0.1]}))) == {
        "materials": {"red": {"reflectance": [0.9, 0.1, 0.1]}}}
    with pytest.raises(TypeError):
        toml_value(object())
