"""The one exception type for errors a user can cause (bad scene files, options, EXR files), and the readers of
the files a user names (scene, suite, renderer, results and baseline files), which turn every problem into one."""

from __future__ import annotations

import os
import stat
import tomllib

#: the most a TOML or JSON file the user names may hold: far beyond any real scene, suite or results file, and a
#: bound on what a wrong path (a device, a log, an image) can make the harness read and parse
MAX_TEXT_BYTES = 64 * 2**20
#: ``1``: a scene file may name mesh and map files outside its own folder (``harness.scene.load``); the CLI's
#: ``--allow-outside-paths`` sets it for the command's duration, so that worker processes follow the choice
ALLOW_OUTSIDE_ENV = "HARNESS_ALLOW_OUTSIDE_PATHS"

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISFIFO, "a named pipe"), (stat.S_ISSOCK, "a socket"))


class HarnessError(Exception):
    """A user-caused error. ``str(err)`` is one line: the file, the key or option, and what was expected.

    Only the CLI turns it into a printed line and exit code 2.
    """

    def __init__(self, where: str, message: str):
        super().__init__(f"{where}: {message}" if where else message)
        self.where = where
        self.message = message


def file_kind(mode: int) -> str:
    """"a regular file", "a directory", "a character device", ... for an ``st_mode``."""
    if stat.S_ISREG(mode):
        return "a regular file"
    return next((name for test, name in _KINDS if test(mode)), "not a file")


def not_regular(path, where: str | None = None) -> HarnessError | None:
    """A HarnessError "not a regular file (a character device)" if ``path`` exists and is not a regular file (after
    symlinks), else None (a missing or unreadable path is the caller's open() to report). Reading a device such as
    /dev/zero never ends, and opening a named pipe blocks until someone writes to it."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(mode):
        return None
    return HarnessError(str(path) if where is None else where, f"not a regular file ({file_kind(mode)})")


def read_user_bytes(path, *, missing: str, where: str | None = None, limit: int = MAX_TEXT_BYTES,
                    directory: str | None = None) -> bytes:
    """The bytes of a file the user named, at most ``limit`` of them. A one-line HarnessError at ``where`` (default:
    the path) otherwise: ``missing`` when there is no such file, ``directory`` (default "not a regular file (a
    directory)") for a folder, "not a regular file (...)" for a device, pipe or socket, "larger than ..." past the
    limit, ``cannot read: ...`` for anything else that stops the read."""
    where = str(path) if where is None else where
    try:
        mode = os.stat(path).st_mode
        if stat.S_ISDIR(mode) and directory:
            raise HarnessError(where, directory)
        if not stat.S_ISREG(mode):
            raise HarnessError(where, f"not a regular file ({file_kind(mode)})")
        # O_NONBLOCK: should a named pipe replace the file after the stat, opening it must not wait for a writer
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
        with open(fd, "rb") as handle:
            mode = os.fstat(handle.fileno()).st_mode
            if not stat.S_ISREG(mode):
                raise HarnessError(where, f"not a regular file ({file_kind(mode)})")
            data = handle.read(limit + 1)
    except FileNotFoundError:
        raise HarnessError(where, missing) from None
    except (OSError, ValueError) as err:  # ValueError: a NUL byte in the path
        raise HarnessError(where, f"cannot read: {getattr(err, 'strerror', None) or err}") from None
    if len(data) > limit:
        raise HarnessError(where, f"larger than {limit / 2**20:g} MiB; expected a text file no larger than that "
                                  "(is this the right file?)")
    return data


def read_user_text(path, *, missing: str, where: str | None = None, limit: int = MAX_TEXT_BYTES) -> str:
    """:func:`read_user_bytes` decoded as UTF-8; an undecodable byte is one line too."""
    where = str(path) if where is None else where
    data = read_user_bytes(path, missing=missing, where=where, limit=limit)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise HarnessError(where, f"cannot read: expected UTF-8 text, got an undecodable byte at offset "
                                  f"{err.start}") from None


def read_user_toml(path, *, missing: str) -> dict:
    """:func:`read_user_text`, parsed as TOML; a syntax error, an integer beyond Python's digit limit or absurd
    nesting is one line too (``invalid TOML: ...``). (Scene files have their own reader, with line and column.)"""
    text = read_user_text(path, missing=missing)
    try:
        return tomllib.loads(text)
    except (ValueError, RecursionError) as err:  # tomllib.TOMLDecodeError is a ValueError
        raise HarnessError(str(path), f"invalid TOML: {err}") from None


__all__ = ["HarnessError", "MAX_TEXT_BYTES", "file_kind", "not_regular", "read_user_bytes",
           "read_user_text", "read_user_toml"]
