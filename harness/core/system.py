"""Provenance: the machine and software a run was made with (the ``system`` block of results.json, report.json,
the report's "System" table and a baseline file), gathered once per run and cheaply (a few milliseconds: no library
is imported for its version, which comes from the installed distribution's metadata; Embree's own version is asked
of its library only where the reference renderer has loaded it already).

:func:`machine_differences` says whether two blocks come from different machines (a baseline saved elsewhere, a
case answered from a results cache filled elsewhere): by :data:`MACHINE_KEYS`.
"""

from __future__ import annotations

import os
import platform
import shutil
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path
from typing import Any

__all__ = ["MACHINE_KEYS", "gather", "machine_differences", "machine_line"]

#: what tells machines apart: the host name (a container's is its own), the CPU, its logical cores, the GPUs
MACHINE_KEYS = ("node", "cpu", "logical_cores", "gpus")
#: the harness's checkout (where ``git`` is asked for the commit); None-safe outside one
ROOT = Path(__file__).resolve().parents[2]
#: seconds allowed to each outside program (git, nvidia-smi)
PROGRAM_TIMEOUT = 2.0


def _version(distribution: str) -> str | None:
    try:
        return metadata.version(distribution)
    except metadata.PackageNotFoundError:
        return None


def cpu_model() -> str | None:
    """The CPU's model name from /proc/cpuinfo (Linux), else :func:`platform.processor`."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                name, _, value = line.partition(":")
                if name.strip().lower() in ("model name", "cpu model", "hardware") and value.strip():
                    return value.strip()
    except OSError:
        pass
    return platform.processor() or None


def _run(*command: str) -> str | None:
    """The stdout of ``command`` (stripped), None where it cannot run, fails or takes too long."""
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=PROGRAM_TIMEOUT, check=False,
                              stdin=subprocess.DEVNULL)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def gpus() -> list[str]:
    """``nvidia-smi -L``'s lines (one per GPU: "GPU 0: NVIDIA H200 (UUID: ...)"); [] without nvidia-smi or GPU."""
    if shutil.which("nvidia-smi") is None:
        return []
    out = _run("nvidia-smi", "-L")
    return [line.strip() for line in (out or "").splitlines() if line.strip().startswith("GPU")]


def git_state(root: Path = ROOT) -> dict | None:
    """``{"commit": SHA, "dirty": bool}`` of the checkout the harness runs from (dirty: a tracked file differs
    from the commit, or an untracked file that git does not ignore is there); None outside a git checkout or
    without git."""
    if not (root / ".git").exists() or shutil.which("git") is None:
        return None
    commit = _run("git", "-C", str(root), "rev-parse", "HEAD")
    if not commit:
        return None
    status = _run("git", "-C", str(root), "status", "--porcelain")
    return {"commit": commit, "dirty": None if status is None else bool(status)}


def _embree() -> str | None:
    """Embree's version from its library, where the reference renderer has loaded it (never imported here)."""
    embree_c = sys.modules.get("reference_impl.embree_c")
    if embree_c is None:
        return None
    try:
        return embree_c.device_version()
    except Exception:  # noqa: BLE001 - provenance is best effort: a library that cannot answer is unknown
        return None


def gather(mitsuba_variant: str | None = None) -> dict[str, Any]:
    """The system block: ``node``, ``cpu`` (model), ``logical_cores``, ``os`` (:func:`platform.platform`),
    ``python``, the versions of ``numpy``, ``numba``, ``embreex`` (distributions) and ``embree`` (the library's
    own, where loaded), ``mitsuba`` (``{"version", "variant"}``: the distribution's version, never imported, and
    the variant asked for, None for the default choice), ``gpus`` (``nvidia-smi -L``), ``git`` (:func:`git_state`)
    and ``seconds`` (what gathering took)."""
    start = time.perf_counter()
    block = {
        "node": platform.node(), "cpu": cpu_model(), "logical_cores": os.cpu_count(), "os": platform.platform(),
        "python": platform.python_version(), "numpy": _version("numpy"), "numba": _version("numba"),
        "embreex": _version("embreex"), "embree": _embree(),
        "mitsuba": {"version": _version("mitsuba"), "variant": mitsuba_variant},
        "gpus": gpus(), "git": git_state(),
    }
    block["seconds"] = time.perf_counter() - start
    return block


def machine_differences(before: Any, now: Any) -> list[str]:
    """What differs between two system blocks' machines (:data:`MACHINE_KEYS`), as "key A -> B"; [] where they
    are the same machine or either block is missing (nothing can be said)."""
    if not isinstance(before, dict) or not isinstance(now, dict):
        return []
    out = []
    for key in MACHINE_KEYS:
        if key in before and key in now and before[key] != now[key]:
            a, b = before[key], now[key]
            if key == "gpus":
                a, b = ("; ".join(map(str, v)) or "none" if isinstance(v, list) else v for v in (a, b))
                key = "GPUs"
            out.append(f"{key} {a} -> {b}")
    return out


def machine_line(block: Any) -> str:
    """One line naming a system block's machine: "node (CPU, N logical cores, OS)"."""
    if not isinstance(block, dict):
        return "unknown machine"
    gpu = f", {len(block['gpus'])} GPU" if block.get("gpus") else ""
    return (f"{block.get('node')} ({block.get('cpu')}, {block.get('logical_cores')} logical cores{gpu}, "
            f"{block.get('os')})")
