"""The perf map of tests/studies/benchmarks/kernel_profile.py: numba's compiled functions named at their addresses
(perf itself is not run here)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
from numba import njit

sys.path.insert(0, str(Path(__file__).resolve().parent / "benchmarks"))
import kernel_profile  # noqa: E402


def _twice_plus_one(x):
    return 2.0 * x + 1.0


def test_demangle_gives_the_qualified_name():
    assert kernel_profile.demangle("_ZN14reference_impl7kernels4bsdf6mf_pdfB3v12E5Arrayd") == \
        "reference_impl.kernels.bsdf.mf_pdf"
    assert kernel_profile.demangle("NRT_incref") == "NRT_incref"


def test_the_map_names_a_function_compiled_here_at_its_address(tmp_path):
    compiled = njit(cache=False)(_twice_plus_one)
    assert compiled(1.0) == 3.0
    functions = kernel_profile.dispatcher_functions([compiled])
    (overload,) = compiled.overloads.values()
    address = overload.library.get_pointer_to_function(overload.fndesc.llvm_func_name)
    assert functions[address].endswith("_twice_plus_one")
    path = tmp_path / "perf-1.map"
    assert kernel_profile.write_perf_map(functions, path) == len(functions)
    rows = [line.split(" ", 2) for line in path.read_text().splitlines()]
    starts = [int(start, 16) for start, _size, _name in rows]
    assert starts == sorted(starts)
    named = [(int(start, 16), int(size, 16)) for start, size, name in rows if name.endswith("_twice_plus_one")]
    assert any(start <= address < start + size for start, size in named)


@pytest.mark.parametrize("argv, named", [(["no-such-scene"], "no-such-scene.toml"),
                                         (["furnace", "--set", "bogus"], "--set"),
                                         (["furnace", "--out", "/no/such/folder/perf.data"], "--out")])
def test_bad_input_is_one_line_naming_it_and_exit_2(monkeypatch, capsys, argv, named):
    monkeypatch.setattr(kernel_profile.shutil, "which", lambda _name: "/usr/bin/perf")  # checked before perf runs
    monkeypatch.setenv("NUMBA_CACHE_DIR", os.environ.get("NUMBA_CACHE_DIR", ""))  # the script points it elsewhere
    assert kernel_profile.main(argv) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("kernel_profile:")]
    assert len(err) == 1 and named in err[0]
