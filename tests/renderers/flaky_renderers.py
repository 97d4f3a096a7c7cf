"""Test-only renderers that misbehave the ways a real one can: hang, crash the process, exit it.

``register()`` adds them to the harness's renderer table; tests pass it as a worker initializer so that worker
processes know them too (``harness.running.executors.LocalExecutor(initializer=...)``).
"""

from __future__ import annotations

import os
import signal
import time


class _Misbehaving:
    def render(self, scene, request):
        self.misbehave()
        raise AssertionError("unreachable")


class HangRenderer(_Misbehaving):
    name = "test-hang"

    def misbehave(self):
        time.sleep(3600)


class SegfaultRenderer(_Misbehaving):
    name = "test-segfault"

    def misbehave(self):
        os.kill(os.getpid(), signal.SIGSEGV)
        time.sleep(60)


class ExitRenderer(_Misbehaving):
    name = "test-exit"

    def misbehave(self):
        os._exit(3)


def register() -> None:
    from harness import renderers

    for cls in (HangRenderer, SegfaultRenderer, ExitRenderer):
        renderers._RENDERERS[cls.name] = cls
