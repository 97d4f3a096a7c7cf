"""The core helpers, one of each (harness/core/text.py, harness/core/jsonsafe.py): the did-you-mean hint, a value
cut short for a message, the JSON sanitiser and its writer; and the names the judges' signatures use."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import json
import math
from pathlib import Path

import numpy as np
import pytest

from harness.core import jsonsafe
from harness.core.text import hint, short, toml_key
from harness.judges import metrics
from harness.judges.verdict import verdict
from harness.running import judge
from harness.running.cases import load_suite
from harness.running.schedule import run_suite

ROOT = Path(__file__).resolve().parents[2]


def test_hint_short_and_toml_key():
    assert hint("sppp", ["spp", "seed"]) == "; did you mean 'spp'?"
    assert hint("zzz", ["spp"]) == "" and hint(3, ["3x"]) == "; did you mean '3x'?"
    assert short("x" * 100) == repr("x" * 100)[:77] + "..." and len(short("x" * 100, 60)) == 60
    assert short(10 ** 5000) == "a huge integer"  # more digits than Python prints
    assert toml_key("relmse") == "relmse" and toml_key("a b") == '"a b"' and toml_key("a\nb") == '"a\\nb"'


@pytest.mark.slow  # over 0.5 s: outside the inner loop (pytest -m "not slow")
def test_one_did_you_mean_in_the_harness():
    """difflib (the did-you-mean) is imported by core/text.py alone (reference_impl, below core, has its own)."""
    users = []
    for path in sorted((ROOT / "harness").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module] if isinstance(node, ast.ImportFrom) else [])
            if "difflib" in names:
                users.append(path.relative_to(ROOT).as_posix())
    assert users == ["harness/core/text.py"]


@dataclasses.dataclass
class _Point:
    x: float
    where: Path


def test_plain_gives_only_json_types():
    value = {1: (np.float32(0.5), np.int64(3), np.bool_(True)), "nan": math.nan, "inf": -math.inf,
             "array": np.array([[1.0, np.inf]]), "path": Path("/tmp/a"), "point": _Point(math.nan, Path("b"))}
    assert jsonsafe.plain(value) == {"1": [0.5, 3, True], "nan": None, "inf": None, "array": [[1.0, None]],
                                     "path": "/tmp/a", "point": {"x": None, "where": "b"}}
    assert type(jsonsafe.plain(np.int64(3))) is int and type(jsonsafe.plain(np.bool_(False))) is bool
    text = jsonsafe.dumps({"v": [np.float64(math.nan), 1]}, indent=2)
    assert json.loads(text) == {"v": [None, 1]} and "NaN" not in text
    with pytest.raises(TypeError):  # not JSON and not sanitisable: refused, not written as something else
        jsonsafe.dumps({"v": object()})


class _NonFiniteExecutor:
    """Runs nothing: every case 'passes' with non-finite numbers in its record, as a renderer's info might have."""

    name = "fake"
    chunks = False

    def run(self, tasks):
        for task in tasks:
            record = dict(judge.case_header(task.payload[0]), status="pass", ok=True,
                          metrics={"psnr": math.inf, "rmse": np.float32(0.25)}, render={"seconds": math.nan})
            yield task, ("ok", record)


def test_results_json_holds_null_for_non_finite_numbers(tmp_path):
    """results.json is strict JSON (docs/results-schema.md: null for a non-finite number), whatever a record holds."""
    suite_file = tmp_path / "s.toml"
    suite_file.write_text(f'[[cases]]\nscene = "{ROOT / "scenes" / "furnace.toml"}"\nspp = 2\n')
    run_suite(load_suite(suite_file), tmp_path / "out", executor=_NonFiniteExecutor())

    def refuse(constant):
        raise AssertionError(f"results.json holds {constant}")

    doc = json.loads((tmp_path / "out" / "results.json").read_text(), parse_constant=refuse)
    case = doc["cases"][0]
    assert case["metrics"] == {"psnr": None, "rmse": 0.25} and case["render"] == {"seconds": None}


def test_the_judges_compare_a_test_image_with_the_expected_one():
    """The image judged against is "expected" in the judges' signatures ("reference" names the tracer under test)."""
    params = inspect.signature(verdict).parameters
    assert list(params)[:4] == ["test", "test_variance", "expected", "expected_variance"] and "expected_dof" in params
    for fn in (metrics.rmse, metrics.relmse, metrics.mape, metrics.psnr, metrics.ssim, metrics.flip, metrics.bias,
               metrics.finite_mask):
        assert list(inspect.signature(fn).parameters)[:2] == ["test", "expected"], fn.__name__
    image = np.full((4, 4, 3), 0.5)
    zeros = np.zeros_like(image)
    assert verdict(test=image, test_variance=zeros, expected=image, expected_variance=zeros, tile=2).passed
