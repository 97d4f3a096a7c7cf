"""Files of a run folder read as someone else may have written them: a path that results.json or studies.json
names is followed only where it stays inside the run folder after every symlink, and a file is read only where it is
a regular file, within a size limit, of the kind its name says (an OpenEXR file, a PNG).

The run folder (``harness report``'s results folder, ``harness run``'s ``--out``) is the root. :func:`inside` says
where a path lands (None: outside the root); :func:`read_inside` opens it component by component from the root with
``O_NOFOLLOW``, so that a symlink swapped in after the check cannot lead the read elsewhere, and checks what it
read. A refusal is :class:`Refused`, whose message says why in a few words (the report writes it as a note on the
case). Files placed into a report are copies of what was read and checked (:func:`copy_inside`), never hard links:
a link would share the file with whoever wrote the run folder.
"""

from __future__ import annotations

import os
import stat
import struct
from pathlib import Path

from harness.core.errors import file_kind
from harness.core.limits import MAX_FILM_PIXELS
from harness.files.imageio import atomic_write_bytes

__all__ = ["EXR_MAGIC", "MAX_EXR_BYTES", "MAX_PNG_BYTES", "PNG_SIGNATURE", "Refused", "copy_inside",
           "first_inside", "inside", "outside_note", "read_inside"]

EXR_MAGIC = b"\x76\x2f\x31\x01"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: an EXR of the largest film the harness renders: image and variance, 6 float32 channels a pixel, and its header
MAX_EXR_BYTES = MAX_FILM_PIXELS * 6 * 4 + 2**20
#: the largest PNG read back (a preview of the largest film, 8-bit RGB, with room for a poor compression)
MAX_PNG_BYTES = MAX_FILM_PIXELS * 4 + 2**20

_O_DIR = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0)
_O_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_O_FILE = os.O_RDONLY | _O_NOFOLLOW | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)


class Refused(Exception):
    """A path or file not used: outside the root, not a regular file, too large, or not of its kind."""


def inside(root: str | os.PathLike[str], path: str | os.PathLike[str]) -> Path | None:
    """The real path of ``path`` (relative to the working folder, as harness run recorded it) where it lies inside
    the real path of ``root`` after every symlink; None where it lies elsewhere (or cannot be resolved)."""
    try:
        real_root = Path(os.path.realpath(root))
        real = Path(os.path.realpath(path))
    except (OSError, ValueError):
        return None
    return real if real != real_root and real.is_relative_to(real_root) else None


def outside_note(what: str, path: object, root: str | os.PathLike[str]) -> str | None:
    """The note for the report where ``what`` (a key of results.json) names ``path`` that exists outside the run
    folder ``root``; None where ``path`` is not a path, lies inside the root, or names nothing (a run folder that
    moved: its old paths are gone, and the files are looked for in the folder)."""
    if not isinstance(path, (str, os.PathLike)) or not str(path) or "\0" in str(path):
        return None
    try:
        exists = os.path.lexists(path)
    except (OSError, ValueError):
        return None
    if not exists or inside(root, path) is not None:
        return None
    return f"{what} names {str(path)!r}, outside the run folder: not read"


def _open_inside(real_root: Path, real: Path) -> int:
    """A descriptor of ``real`` (a real path inside ``real_root``) opened one component at a time from the root,
    none of them a symlink."""
    parts = real.relative_to(real_root).parts
    fd = os.open(real_root, _O_DIR)
    try:
        for part in parts[:-1]:
            child = os.open(part, _O_DIR | _O_NOFOLLOW, dir_fd=fd)
            os.close(fd)
            fd = child
        return os.open(parts[-1], _O_FILE, dir_fd=fd)
    finally:
        os.close(fd)


def _is_png(data: bytes) -> bool:
    """PNG's signature and its first chunk, a well-formed IHDR of a film's size."""
    if len(data) < 33 or not data.startswith(PNG_SIGNATURE) or data[12:16] != b"IHDR":
        return False
    length, width, height = struct.unpack(">III", data[8:12] + data[16:24])
    return length == 13 and 0 < width and 0 < height and width * height <= MAX_FILM_PIXELS


def _check_kind(data: bytes, kind: str) -> None:
    if kind == "exr" and not data.startswith(EXR_MAGIC):
        raise Refused("not an OpenEXR file")
    if kind == "png" and not _is_png(data):
        raise Refused("not a PNG image")


def read_inside(root: str | os.PathLike[str], path: str | os.PathLike[str], *, kind: str | None = None,
                limit: int | None = None, head: int | None = None) -> bytes:
    """The bytes of the file ``path`` inside the run folder ``root``: a regular file (not a device, fifo or folder;
    a symlink only where it leads to a file inside the root), at most ``limit`` bytes (default by ``kind``), of
    the ``kind`` its name says (``"exr"``: OpenEXR's magic number; ``"png"``: PNG's signature and header; None: any).
    ``head``: only its first ``head`` bytes are read (and checked), its size taken from the file system.
    :class:`Refused` otherwise."""
    real_root = Path(os.path.realpath(root))
    real = inside(real_root, path)
    if real is None:
        raise Refused("outside the run folder")
    if limit is None:
        limit = {"exr": MAX_EXR_BYTES, "png": MAX_PNG_BYTES}.get(kind or "", 64 * 2**20)
    try:
        fd = _open_inside(real_root, real)
    except FileNotFoundError:
        raise Refused("not found") from None
    except (OSError, ValueError) as err:
        raise Refused(f"cannot read: {getattr(err, 'strerror', None) or err}") from None
    with open(fd, "rb") as handle:
        status = os.fstat(handle.fileno())
        if not stat.S_ISREG(status.st_mode):
            raise Refused(f"not a regular file ({file_kind(status.st_mode)})")
        if status.st_size > limit:
            raise Refused(f"larger than {limit} bytes")
        try:
            data = handle.read(limit + 1 if head is None else head)
        except OSError as err:
            raise Refused(f"cannot read: {err.strerror or err}") from None
    if len(data) > limit:
        raise Refused(f"larger than {limit} bytes")
    _check_kind(data, kind or "")
    return data


def copy_inside(root: str | os.PathLike[str], source: str | os.PathLike[str], dest: str | os.PathLike[str], *,
                kind: str, data: bytes | None = None) -> Path:
    """``dest`` written (atomically) with a copy of ``source``, read and checked by :func:`read_inside` (``data``:
    the bytes a caller read that way already); returns ``dest``. Never a link: the report's file is its own."""
    return atomic_write_bytes(dest, read_inside(root, source, kind=kind) if data is None else data)


def first_inside(root: str | os.PathLike[str], candidates: list, *, kind: str | None, what: str,
                 notes: list[str] | None = None) -> tuple[Path, bytes] | None:
    """The first of ``candidates`` (paths results.json names, then where harness run writes them in the run folder)
    that :func:`read_inside` reads: (its path, its bytes); None where none does. A candidate outside the run folder
    that exists, or a file inside it that is refused for anything but being missing, adds a note to ``notes``
    (``what``: the key of results.json, for the note)."""
    for candidate in candidates:
        if not isinstance(candidate, (str, os.PathLike)) or not str(candidate):
            continue
        note = outside_note(what, candidate, root)
        if note is not None:
            _add(notes, note)
            continue
        try:
            return Path(candidate), read_inside(root, candidate, kind=kind)
        except Refused as why:
            if str(why) not in ("not found", "outside the run folder"):
                _add(notes, f"{what}: {str(candidate)!r}: {why}: not used")
    return None


def _add(notes: list[str] | None, note: str) -> None:
    if notes is not None and note not in notes:
        notes.append(note)
