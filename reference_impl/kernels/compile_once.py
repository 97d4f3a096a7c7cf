"""One compilation of a kernel's specialization across the processes that share numba's cache.

numba compiles a ``cache=True`` function for new argument types in the process that first calls it, then saves the
result in its cache; a second process that needs the same specialization at the same time compiles it again (its
cache has no entry yet), the same work twice. A suite run's workers render scenes of the same kinds side by side, and
the path loop's specializations take seconds each to compile, so :func:`compile_once` makes the second process wait
for the first: an exclusive ``flock`` per (function, signature) beside numba's cache, held while
``Dispatcher.compile`` loads the specialization from the cache or compiles and saves it. The waiting process then
finds it in the cache. Within a process numba's own compiler lock already serialises compilation.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import tempfile
from pathlib import Path


def _lock_folder(dispatcher) -> Path:
    """numba's cache folder of ``dispatcher`` (where its index and data files are), else a folder in the system's
    temporary directory."""
    cache = getattr(dispatcher, "_cache", None)
    folder = getattr(cache, "_cache_path", None)
    if folder and os.path.isdir(folder) and os.access(folder, os.W_OK):
        return Path(folder)
    fallback = Path(tempfile.gettempdir()) / f"reference_impl-compile-{os.getuid()}"
    fallback.mkdir(mode=0o700, exist_ok=True)
    return fallback


def signature(dispatcher, args: tuple) -> tuple:
    """The numba types of ``args`` as ``dispatcher`` would compile them: one specialization per distinct tuple."""
    return tuple(dispatcher.typeof_pyval(a) for a in args)


def compile_once(dispatcher, args: tuple) -> None:
    """Make ``dispatcher``'s specialization for the types of ``args`` ready in this process (numba's
    ``Dispatcher.compile``: loaded from the cache, else compiled and saved), one process at a time per signature.
    Nothing happens when this process has it already, or when ``dispatcher`` is not compiled (``NUMBA_DISABLE_JIT``)."""
    if not hasattr(dispatcher, "typeof_pyval"):
        return
    types = signature(dispatcher, args)
    if types in dispatcher.overloads:
        return
    name = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
    digest = hashlib.sha256(f"{name}{types}".encode()).hexdigest()[:24]
    path = _lock_folder(dispatcher) / f"{dispatcher.py_func.__name__}-{digest}.lock"
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            dispatcher.compile(types)
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
