"""This process's peak resident memory, measured so that a child process does not inherit its parent's.

``getrusage(RUSAGE_SELF).ru_maxrss`` is the wrong figure for a fresh child on Linux: the kernel keeps the largest
resident set of the process's earlier images across ``execve`` (``setmax_mm_hiwater_rss`` in fs/exec.c), so a
child started by a parent that had grown to 1.3 GiB reports 1.3 GiB whatever it does itself. ``VmHWM`` of
``/proc/self/status`` ("peak resident set size", proc(5)) is the high-water mark of the current address space
alone, which ``execve`` starts anew.
"""

from __future__ import annotations

import resource
import sys


def peak_rss_bytes() -> int:
    """The peak resident set of this process's current image in bytes: ``VmHWM`` (kB) of ``/proc/self/status``
    where there is one (Linux), else ``ru_maxrss`` (bytes on macOS, KiB elsewhere)."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as status:
            for line in status:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak if sys.platform == "darwin" else peak * 1024
