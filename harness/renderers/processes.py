"""Running another program so that it cannot outlast its run or fill the harness's memory (external renderers,
docs/external-renderers.md, "Running").

:func:`run_group` starts a command without a shell in a session (and so a process group) of its own, stdin and
stdout on /dev/null, and keeps only the last :data:`STDERR_TAIL_BYTES` of its stderr, read as it comes. When the
command exits, times out or the harness is interrupted, its whole process group is killed (SIGKILL) before the
command is reaped, so that its pid, which is the group's id, cannot be reused by another process in between.

A harness killed outright (SIGKILL, the machine's OOM killer) runs no code: for that, each harness process starts
one :class:`Watchdog`, a small Python process in a session of its own that reads the ids of the groups running from
a pipe whose writing end only the harness holds. The kernel closes that end when the harness dies, however it dies;
the watchdog then reads the end of the pipe, kills every group still registered, and exits. (Linux's
``PR_SET_PDEATHSIG`` would reach only the command itself, not its children, and needs ``preexec_fn``, which is not
safe in a process with threads.) A descendant that starts a session of its own leaves the group and is not followed.
"""

from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

#: the end of a command's stderr that is kept: the last lines of an error, never the whole output of a program that
#: writes without end (read 64 KiB at a time, so the harness holds at most twice this)
STDERR_TAIL_BYTES = 64 * 1024
#: how long the harness reads what is left of stderr after the group is killed (a descendant that left the group may
#: hold it open)
DRAIN_SECONDS = 2.0
#: where no pidfd tells of the exit at once: how often the exit is looked for
POLL_SECONDS = 0.01

#: the watchdog's program (run as ``python -I -S -c``): "+PGID" / "-PGID" lines register and release process groups;
#: at the end of the pipe (the harness has exited) every group still registered is killed
WATCHDOG = r"""
import os, signal
os.chdir("/")
groups, pending = set(), b""
while chunk := os.read(0, 4096):
    *lines, pending = (pending + chunk).split(b"\n")
    for line in lines:
        (groups.add if line[:1] == b"+" else groups.discard)(int(line[1:]))
for group in groups:
    try:
        os.killpg(group, signal.SIGKILL)
    except OSError:
        pass
"""


class Watchdog:
    """The watchdog process of this harness process (see the module docstring), started on first use and again in a
    forked child (which must not share its parent's)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._fd: int | None = None
        self._owner = 0
        self._groups: set[int] = set()
        self._pid: int | None = None

    def watch(self, group: int) -> None:
        """Register ``group``: it is killed if this process dies before :meth:`release`."""
        with self._lock:
            self._groups.add(group)
            self._send(f"+{group}\n")

    def release(self, group: int) -> None:
        """Forget ``group`` (killed and reaped by the caller)."""
        with self._lock:
            self._groups.discard(group)
            self._send(f"-{group}\n")

    def pid(self) -> int | None:
        """The watchdog's process id (for tests), None before this process's first command or where it could not
        be started."""
        with self._lock:
            return self._pid if self._fd is not None and self._owner == os.getpid() else None

    def forget(self) -> None:
        """In a forked child: drop the parent's watchdog (its pipe closed here, so that it still sees the parent's
        end) and its groups; the child starts its own when it runs a command."""
        self._lock = threading.Lock()
        if self._fd is not None and self._owner != os.getpid():
            try:
                os.close(self._fd)
            except OSError:
                pass
            self._fd = None
        self._groups, self._pid = set(), None

    def _send(self, line: str) -> None:
        for _ in range(2):  # a watchdog that was killed is started again, with every group still running
            if self._fd is None or self._owner != os.getpid():
                if not self._start():
                    return  # the command still runs and is killed after its run; a harness death is not guarded
                line = "".join(f"+{g}\n" for g in self._groups) if line.startswith("+") else line
            try:
                os.write(self._fd, line.encode())
                return
            except OSError:  # gone (EPIPE), or stopped with a full pipe (EAGAIN): another takes over
                os.close(self._fd)
                self._fd = None
                try:  # reap the watchdog that died, where it was this process's
                    os.waitpid(self._pid, os.WNOHANG)
                except ChildProcessError:
                    pass

    def _start(self) -> bool:
        if not sys.executable:
            return False
        read, write = os.pipe()  # not inheritable: only the watchdog's stdin holds the reading end
        try:
            self._pid = os.posix_spawn(
                sys.executable, [sys.executable, "-I", "-S", "-c", WATCHDOG], os.environ, setsid=True,
                file_actions=[(os.POSIX_SPAWN_DUP2, read, 0),
                              (os.POSIX_SPAWN_OPEN, 1, os.devnull, os.O_WRONLY, 0),
                              (os.POSIX_SPAWN_OPEN, 2, os.devnull, os.O_WRONLY, 0)])
        except (OSError, NotImplementedError):  # NotImplementedError: no POSIX_SPAWN_SETSID on this system
            os.close(write)
            return False
        finally:
            os.close(read)
        os.set_blocking(write, False)  # a stopped watchdog must not block the harness (lines are atomic writes)
        self._fd, self._owner = write, os.getpid()
        return True


WATCHDOG_OF_THIS_PROCESS = Watchdog()
os.register_at_fork(after_in_child=WATCHDOG_OF_THIS_PROCESS.forget)


class CommandTimeout(Exception):
    """The command ran past its timeout; its process group has been killed."""


class CommandStartError(Exception):
    """The command could not be started (``str(err)``: why)."""


def run_group(argv: list[str], cwd: Path, timeout: float) -> tuple[int, float, bytes]:
    """Run ``argv`` (no shell, in ``cwd``) in its own process group; returns (exit code, seconds until it exited, the
    last :data:`STDERR_TAIL_BYTES` of its stderr). Its group is killed when it exits, whatever the outcome; raises
    :class:`CommandTimeout` after ``timeout`` seconds, :class:`CommandStartError` when it cannot start."""
    start = time.perf_counter()
    try:
        proc = subprocess.Popen(argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, start_new_session=True)
    except (OSError, ValueError) as err:
        raise CommandStartError(getattr(err, "strerror", None) or str(err)) from None
    WATCHDOG_OF_THIS_PROCESS.watch(proc.pid)
    tail = bytearray()
    try:
        exited = _wait(proc, start + timeout, tail)
        seconds = time.perf_counter() - start
        _kill_group(proc.pid)  # before reading the rest: a descendant still writing would hold stderr open
        _drain(proc.stderr.fileno(), tail, DRAIN_SECONDS)
    finally:
        _kill_group(proc.pid)  # (again, for an interrupt) before the reaping, which frees the pid, the group's id
        proc.wait()
        proc.stderr.close()
        WATCHDOG_OF_THIS_PROCESS.release(proc.pid)
    if not exited:
        raise CommandTimeout()
    return proc.returncode, seconds, bytes(tail)


def _exited(proc: subprocess.Popen) -> bool:
    """Has ``proc`` exited? Without reaping it where the system can (``waitid`` with ``WNOWAIT``)."""
    if hasattr(os, "waitid"):
        try:
            return os.waitid(os.P_PID, proc.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None
        except ChildProcessError:  # reaped by someone else (SIGCHLD ignored)
            return True
    return proc.poll() is not None


def _pidfd(pid: int) -> int | None:
    """A file descriptor that becomes readable when ``pid`` exits (Linux 5.3+), or None."""
    try:
        return os.pidfd_open(pid)
    except (AttributeError, OSError):
        return None


def _wait(proc: subprocess.Popen, deadline: float, tail: bytearray) -> bool:
    """Keep the tail of ``proc``'s stderr in ``tail`` until it exits (True) or ``deadline`` passes (False)."""
    err = proc.stderr.fileno()
    os.set_blocking(err, False)
    pidfd = _pidfd(proc.pid)
    with selectors.DefaultSelector() as selector:
        selector.register(err, selectors.EVENT_READ)
        if pidfd is not None:
            selector.register(pidfd, selectors.EVENT_READ)
        try:
            while not _exited(proc):
                left = deadline - time.perf_counter()
                if left <= 0:
                    return False
                for key, _ in selector.select(left if pidfd is not None else min(left, POLL_SECONDS)):
                    if key.fd == err and not _read_tail(err, tail):
                        selector.unregister(err)  # stderr closed; the command may still run
        finally:
            if pidfd is not None:
                os.close(pidfd)
    return True


def _read_tail(fd: int, tail: bytearray) -> bool:
    """One read of ``fd`` onto ``tail``, of which the last :data:`STDERR_TAIL_BYTES` are kept; False at its end."""
    try:
        chunk = os.read(fd, STDERR_TAIL_BYTES)
    except BlockingIOError:
        return True
    tail += chunk
    del tail[:-STDERR_TAIL_BYTES]
    return bool(chunk)


def _drain(fd: int, tail: bytearray, seconds: float) -> None:
    """Read what is left of ``fd`` into ``tail`` until its end, for at most ``seconds``."""
    deadline = time.perf_counter() + seconds
    with selectors.DefaultSelector() as selector:
        selector.register(fd, selectors.EVENT_READ)
        while (left := deadline - time.perf_counter()) > 0 and selector.select(left):
            if not _read_tail(fd, tail):
                return


def _kill_group(group: int) -> None:
    """SIGKILL every process of ``group``; a group already gone is fine."""
    try:
        os.killpg(group, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
