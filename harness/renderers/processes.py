"""Running another program so that neither it nor anything it starts can outlast its run, and so that it cannot
fill the harness's memory (external renderers, docs/external-renderers.md, "No process outlives its run"; the Mitsuba
variant probes, docs/mitsuba.md).

:func:`run_group` runs a command without a shell, stdin and stdout on /dev/null, and keeps only the last
:data:`STDERR_TAIL_BYTES` of its stderr, read as it comes. When the command exits, times out or the harness is
interrupted, every process it started is killed (SIGKILL), however far it went:

- **The supervisor.** On Linux the command runs under a small Python process (:data:`SUPERVISOR`, started as
  ``python -I -S -c``, in a session of its own) that makes itself a *child subreaper* (``prctl(
  PR_SET_CHILD_SUBREAPER)``): every descendant of the command that is orphaned, including one that started a session
  of its own (``setsid``, a daemon's double fork), is re-parented to the supervisor rather than to init. The
  supervisor starts the command in a session of its own (``posix_spawnp``, which reports an exec failure as the
  OS's error; with the environment the supervisor was given, not the one Python changed for itself, PEP 538), waits
  for it, then kills its session's group, and then, round after round until it has no child left, kills and reaps
  each of its children (``/proc``) and that child's group: a killed process's orphans become its children for the
  next round. Only then does it exit, so the run is over only when nothing of it is left. No order in which
  processes fork or die lets one slip between rounds: every living descendant is a child of the supervisor or has
  an ancestor that is, so the supervisor has a child while anything of the run lives, and killing that child hands
  its children over. What escapes is only what the command has another program start for it (a service manager,
  ``at``, a daemon it talks to): that takes a cgroup or a container to catch.
- **The protocol.** The supervisor reads a *control pipe* whose writing end only the harness holds (close-on-exec,
  and closed in a child the harness forks): its end, because the harness closed it (the run timed out or was
  interrupted) or because the harness died however it died, makes the supervisor kill everything and exit; so does
  a SIGTERM, SIGINT or SIGHUP. It tells the harness, one line each on its stdout, the command's pid
  (``pid N``), the command's exit status as soon as the command exits (``exit N``, a signal as -N, as
  :attr:`subprocess.Popen.returncode`; the run's seconds end there) or why it could not start (``start ERRNO``),
  and exits 0 when the killing is done. A supervisor that dies otherwise, or takes more than :data:`STOP_SECONDS`
  to finish, is killed with its group and the command's group, as where there is no supervisor (below).
- **The watchdog.** A harness killed outright (SIGKILL, the machine's OOM killer) runs no code: each harness process
  also starts one :class:`Watchdog`, a small Python process in a session of its own that reads the ids of the
  command groups running from a pipe whose writing end only the harness holds, and kills them when that pipe ends.
  It kills the command's group, never the supervisor, which sees its own control pipe end at the same moment and
  then kills the rest; were the supervisor killed first, the orphans it holds would go to init.

Elsewhere (no Linux, no ``sys.executable``) the command runs directly in a session of its own, and its process
group is killed after its run, before it is reaped (its pid, the group's id, cannot be reused in between); a
descendant that starts a session of its own leaves that group and is not followed. Where the supervisor cannot
become a subreaper (``prctl`` refused, no ``ctypes``), it still kills the command's group and its own children.
(Linux's ``PR_SET_PDEATHSIG`` would reach only the command itself, not its children, and needs ``preexec_fn``,
which is not safe in a process with threads.)
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
#: how long the harness waits for the supervisor to kill what is left of a run before it kills the supervisor
STOP_SECONDS = 5.0
#: the most of the supervisor's stdout (its report lines) held: it writes three short lines
REPORT_BYTES = 256

#: the supervisor's program (run as ``python -I -S -c SUPERVISOR CONTROL_FD COMMAND...``; see the module docstring)
SUPERVISOR = r"""
import os, select, sys
try:
    import _signal as signal  # the signal module without its enums: a third of this program's start-up
except ImportError:
    import signal
try:
    import ctypes
except ImportError:
    ctypes = None
STOPS = {signal.SIGTERM, signal.SIGINT, signal.SIGHUP}

def report(line):
    try:
        os.write(1, line.encode() + b"\n")
    except OSError:  # the harness is gone: the control pipe says so too
        pass

def environment():  # as received: Python may have set LC_CTYPE since (PEP 538), which the command must not see
    try:
        with open("/proc/self/environ", "rb") as file:
            entries = file.read().split(b"\0")
    except OSError:
        return os.environ
    return dict(entry.split(b"=", 1) for entry in entries if entry.find(b"=") > 0)

def subreaper():
    try:
        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
    except Exception:  # no ctypes, no prctl: the command's group and this process's children are still killed
        pass

def spawn(argv):
    actions = [(os.POSIX_SPAWN_OPEN, 1, os.devnull, os.O_WRONLY, 0)]
    defaults = (signal.SIGPIPE, signal.SIGXFSZ)  # as subprocess restores them
    try:
        return os.posix_spawnp(argv[0], argv, environment(), file_actions=actions, setsigdef=defaults, setsid=True)
    except NotImplementedError:  # no POSIX_SPAWN_SETSID: a process group of its own
        return os.posix_spawnp(argv[0], argv, environment(), file_actions=actions, setsigdef=defaults, setpgroup=0)

def exited(command):  # the command's status once it has exited (not reaped); orphans that ended are reaped
    while (info := os.waitid(os.P_ALL, 0, os.WEXITED | os.WNOHANG | os.WNOWAIT)) is not None:
        if info.si_pid == command:
            return info.si_status if info.si_code == os.CLD_EXITED else -info.si_status
        os.waitpid(info.si_pid, 0)
    return None

def wait(command, control, wake):  # the command's status, or None where the run is stopped first
    while (status := exited(command)) is None:
        ready = select.select([control, wake], [], [])[0]
        if control in ready and not os.read(control, 64):
            return None
        if wake in ready and STOPS & set(os.read(wake, 64)):
            return None
    return status

def kill(pid, group=False):
    try:
        (os.killpg if group else os.kill)(pid, signal.SIGKILL)
    except OSError:
        pass

def children(me):
    try:
        with open(f"/proc/self/task/{me}/children", "rb") as file:
            return [int(pid) for pid in file.read().split()]
    except OSError:  # a kernel without it: every process's parent is looked at
        pass
    found = []
    for name in (entry.name for entry in os.scandir("/proc") if entry.name.isdigit()):
        try:
            with open(f"/proc/{name}/stat", "rb") as file:
                if int(file.read().rsplit(b")", 1)[1].split()[1]) == me:
                    found.append(int(name))
        except (OSError, IndexError, ValueError):
            pass
    return found

def clean(command, wake):  # kill the command's group, then every child (orphans come here) until none is left
    me, mine = os.getpid(), os.getpgid(0)
    kill(command, group=True)
    while True:
        try:  # a descendant alive or dying has an ancestor that is a child of this process: none left, none alive
            while os.waitpid(-1, os.WNOHANG)[0]:
                pass
        except ChildProcessError:
            return
        for pid in children(me):
            kill(pid)
            try:
                group = os.getpgid(pid)
            except OSError:
                continue
            if group != mine:
                kill(group, group=True)
        if select.select([wake], [], [], 0.01)[0]:
            os.read(wake, 4096)

def main():
    control, argv = int(sys.argv[1]), sys.argv[2:]
    os.set_inheritable(control, False)
    wake, woken = os.pipe()
    for fd in (wake, woken):
        os.set_blocking(fd, False)
    signal.set_wakeup_fd(woken, warn_on_full_buffer=False)
    for number in (signal.SIGCHLD, *STOPS):
        if signal.getsignal(number) != signal.SIG_IGN:
            signal.signal(number, lambda *_: None)
    subreaper()
    try:
        command = spawn(argv)
    except OSError as err:
        report(f"start {err.errno}")
        return
    report(f"pid {command}")
    status = wait(command, control, wake)
    if status is not None:
        report(f"exit {status}")
    clean(command, wake)

main()
"""

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


#: the harness's ends of the running supervisors' control pipes (closed in a forked child, which must not keep a
#: supervisor waiting after the harness is gone)
_CONTROLS: set[int] = set()


def _forget_controls() -> None:
    """In a forked child: close the parent's ends of its supervisors' control pipes."""
    for fd in list(_CONTROLS):
        try:
            os.close(fd)
        except OSError:
            pass
    _CONTROLS.clear()


os.register_at_fork(after_in_child=_forget_controls)


class CommandTimeout(Exception):
    """The command ran past its timeout; every process of it has been killed."""


class CommandStartError(Exception):
    """The command could not be started (``str(err)``: why)."""


def supervised() -> bool:
    """Does :func:`run_group` run commands under the supervisor here (Linux, with a Python to run it)?"""
    return sys.platform.startswith("linux") and bool(sys.executable) and hasattr(os, "posix_spawnp")


def run_group(argv: list[str], cwd: Path, timeout: float) -> tuple[int, float, bytes]:
    """Run ``argv`` (no shell, in ``cwd``) so that nothing it starts outlives it (see the module docstring); returns
    (exit code, or -N for a signal N; seconds until it exited; the last :data:`STDERR_TAIL_BYTES` of its stderr).
    Raises :class:`CommandTimeout` after ``timeout`` seconds, :class:`CommandStartError` when it cannot start."""
    start = time.perf_counter()
    run = _Run(argv, cwd, supervised())
    tail = bytearray()
    try:
        finished = run.wait(start + timeout, tail)
        seconds = (time.perf_counter() if run.exited_at is None else run.exited_at) - start
        run.stop()  # before reading the rest: a descendant still writing would hold stderr open
        _drain(run.proc.stderr.fileno(), tail, DRAIN_SECONDS)
    finally:
        run.close()
    if run.start_error is not None:
        raise CommandStartError(run.start_error)
    if not finished:
        raise CommandTimeout()
    return run.returncode(), seconds, bytes(tail)


class _Run:
    """One command of :func:`run_group`: under the supervisor (``supervise``), whose reports it reads, or directly
    in a session of its own."""

    def __init__(self, argv: list[str], cwd: Path, supervise: bool):
        self.supervised = supervise
        self.control: int | None = None  # the harness's end of the supervisor's control pipe, open while it runs
        self.group: int | None = None  # the command's process group, registered with the watchdog
        self.code: int | None = None  # the command's exit status, as the supervisor reported it
        self.exited_at: float | None = None  # when the report of the exit came
        self.start_error: str | None = None
        self._report = bytearray()
        self._stopped = False
        command, keep = argv, ()
        if supervise:
            read_end, self.control = os.pipe()  # both close-on-exec: the supervisor gets the reading end alone
            _CONTROLS.add(self.control)
            command, keep = [sys.executable, "-I", "-S", "-c", SUPERVISOR, str(read_end), *argv], (read_end,)
        try:
            self.proc = subprocess.Popen(command, cwd=cwd, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                         stdout=subprocess.PIPE if supervise else subprocess.DEVNULL,
                                         start_new_session=True, pass_fds=keep)
        except (OSError, ValueError) as err:
            self._close_control()
            raise CommandStartError(getattr(err, "strerror", None) or str(err)) from None
        finally:
            for fd in keep:
                os.close(fd)
        if not supervise:
            self._watch(self.proc.pid)

    def wait(self, deadline: float, tail: bytearray) -> bool:
        """Keep the tail of the command's stderr in ``tail`` (and take the supervisor's reports) until the command
        exits or cannot start (True) or ``deadline`` passes (False)."""
        err = self.proc.stderr.fileno()
        readers = {err: lambda: _read_tail(err, tail)}
        if self.supervised:
            readers[self.proc.stdout.fileno()] = self._read_report
        pidfd = _pidfd(self.proc.pid)
        with selectors.DefaultSelector() as selector:
            for fd in readers:
                os.set_blocking(fd, False)
                selector.register(fd, selectors.EVENT_READ)
            if pidfd is not None:
                selector.register(pidfd, selectors.EVENT_READ)
            try:
                while not self._finished():
                    left = deadline - time.perf_counter()
                    if left <= 0:
                        return False
                    for key, _ in selector.select(left if pidfd is not None else min(left, POLL_SECONDS)):
                        if key.fd in readers and not readers[key.fd]():
                            selector.unregister(key.fd)  # closed; the command may still run
            finally:
                if pidfd is not None:
                    os.close(pidfd)
        return True

    def stop(self) -> None:
        """Kill what is left of the run: the command's group, or the supervisor's whole tree (its control pipe
        closed, it kills everything and exits; one that does not within :data:`STOP_SECONDS`, or that died some
        other way, is killed with its group and the command's group)."""
        if not self.supervised:
            _kill_group(self.proc.pid)
            return
        if self._stopped:
            return
        self._close_control()
        try:
            self.proc.wait(STOP_SECONDS)
        except subprocess.TimeoutExpired:
            _kill_group(self.proc.pid)  # (before the reaping, which frees the pid, the group's id)
        if self.proc.returncode != 0 and self.group is not None:
            _kill_group(self.group)
        self._stopped = True

    def close(self) -> None:
        """Make sure the run is over (an interrupt may come anywhere): stopped (again, for an interrupt), the
        process reaped, its pipes closed, the command's group released from the watchdog."""
        self.stop()
        self.proc.wait()
        self.proc.stderr.close()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        if self.group is not None:
            WATCHDOG_OF_THIS_PROCESS.release(self.group)

    def returncode(self) -> int:
        """The command's exit status: as the supervisor reported it, else the process's own."""
        return self.code if self.code is not None else self.proc.returncode

    def _finished(self) -> bool:
        if not self.supervised:
            return _exited(self.proc)
        if self.code is None and self.start_error is None and _exited(self.proc):
            for _ in range(4):  # what it wrote before it exited (three short lines at most)
                if not self._read_report():
                    break
            return True
        return self.code is not None or self.start_error is not None

    def _read_report(self) -> bool:
        """One read of the supervisor's stdout: its complete lines taken; False at its end."""
        try:
            chunk = os.read(self.proc.stdout.fileno(), REPORT_BYTES)
        except BlockingIOError:
            return True
        *lines, rest = (bytes(self._report) + chunk).split(b"\n")
        self._report[:] = rest[-REPORT_BYTES:]
        for line in lines:
            self._take(line)
        return bool(chunk)

    def _take(self, line: bytes) -> None:
        """Take one report line of the supervisor (a line it did not write is ignored: a descendant may reach its
        stdout through /proc)."""
        word, _, number = line.partition(b" ")
        try:
            value = int(number)
        except ValueError:
            return
        if word == b"pid" and self.group is None and value > 1:
            self._watch(value)
        elif word == b"exit" and self.code is None:
            self.code, self.exited_at = value, time.perf_counter()
        elif word == b"start" and self.start_error is None and 0 < value < 4096:
            self.start_error = os.strerror(value)

    def _watch(self, group: int) -> None:
        self.group = group
        WATCHDOG_OF_THIS_PROCESS.watch(group)

    def _close_control(self) -> None:
        if self.control is not None:
            _CONTROLS.discard(self.control)  # before closing: a child forked meanwhile must not close another fd
            os.close(self.control)
            self.control = None


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
