"""kernels.compile_once: a second process waits for the first one's compilation of a specialization and then loads
it from numba's cache instead of compiling it again."""

from __future__ import annotations

import fcntl
import subprocess
import sys
import textwrap
import time

import pytest

pytest.importorskip("numba")

MODULE = '''
import numba

@numba.njit(cache=True)
def twice(x):
    return 2 * x
'''

CHILD = textwrap.dedent('''
    import sys
    sys.path.insert(0, sys.argv[1])
    import numpy as np
    import toy
    from reference_impl.kernels.compile_once import compile_once
    compile_once(toy.twice, (np.float64(1.0),))
    print(sum(toy.twice.stats.cache_hits.values()), sum(toy.twice.stats.cache_misses.values()), flush=True)
''')


def _child(folder, env):
    return subprocess.Popen([sys.executable, "-c", CHILD, str(folder)], env=env, stdout=subprocess.PIPE, text=True)


def _hits_and_misses(out: str) -> tuple[int, int]:
    hits, misses = out.split()
    return int(hits), int(misses)


def test_a_second_process_waits_for_the_lock_then_loads_from_the_cache(tmp_path, monkeypatch):
    import os

    import numpy as np

    from reference_impl.kernels import compile_once

    (tmp_path / "toy.py").write_text(MODULE)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    child = _child(tmp_path, env)
    assert child.wait(timeout=120) == 0
    assert _hits_and_misses(child.stdout.read()) == (0, 1)  # the first process compiled it
    child = _child(tmp_path, env)
    assert child.wait(timeout=120) == 0
    assert _hits_and_misses(child.stdout.read()) == (1, 0)  # the second loaded it from the cache
    locks = list((tmp_path / "cache").rglob("twice-*.lock"))
    assert len(locks) == 1  # beside numba's cache of the function
    with open(locks[0], "a") as handle:  # another process holds the lock: the child waits for it
        fcntl.flock(handle, fcntl.LOCK_EX)
        child = _child(tmp_path, env)
        time.sleep(3.0)
        assert child.poll() is None
        fcntl.flock(handle, fcntl.LOCK_UN)
    assert child.wait(timeout=120) == 0
    assert _hits_and_misses(child.stdout.read()) == (1, 0)
    assert compile_once.compile_once(lambda x: x, (np.float64(1.0),)) is None  # not a dispatcher: nothing to do
