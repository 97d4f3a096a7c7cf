"""Image files: OpenEXR read/write, PNG previews, and atomic file writes.

Conventions used throughout the harness:

* An image is a numpy array of shape (H, W, 3): linear radiance in the
  renderer's RGB space, channel order R, G, B.  Row 0 is the *top* of the
  image (the OpenEXR default ``INCREASING_Y`` line order, no flipping).
* A variance image has the same shape and holds, per pixel and channel, the
  variance of that pixel's Monte Carlo estimate.
* EXR files written here are single-part scanline files, ZIP compression,
  float32 channels ``R``, ``G``, ``B`` and, when a variance is given,
  ``variance.R``, ``variance.G``, ``variance.B``.  Extra string metadata
  (renderer, spp, a settings JSON...) is stored as string header attributes.
* Every writer is atomic: the data goes to a temporary file in the destination
  folder, which is flushed, fsync'ed and then ``os.replace``'d over the
  destination.  On any failure the temporary file is removed and the
  destination is left as it was (absent, or with its old content).

Errors a user can cause (a missing, corrupted or truncated EXR file, a file
without R/G/B channels, an unwritable output folder) raise
:class:`harness.core.errors.HarnessError` with a one-line message naming the file.
Programmer errors (bad array shapes, non-string metadata) raise
``ValueError`` / ``TypeError``.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import re
import sys
import shutil
import stat
import tempfile
import threading
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import numpy as np
import OpenEXR

from harness.core import srgb
from harness.core.errors import HarnessError, not_regular
from harness.core.limits import MAX_FILM_PIXELS, MAX_FILM_SIDE, estimate_text
from harness.core.options import switched_off
from harness.core.text import short

__all__ = [
    "ExrImage",
    "StagedFolder",
    "WriteError",
    "atomic_write_bytes",
    "atomic_write_text",
    "exr_bytes",
    "exr_size",
    "link_target",
    "make_folders",
    "make_real_folders",
    "preview_path",
    "read_exr",
    "remove_folders",
    "removed_on_failure",
    "staged_inside",
    "write_exr",
    "write_exr_with_preview",
    "write_png_preview",
]

RGB_CHANNELS: tuple[str, str, str] = ("R", "G", "B")
VARIANCE_CHANNELS: tuple[str, str, str] = ("variance.R", "variance.G", "variance.B")

# Header attributes that OpenEXR itself defines/needs; metadata may not use them.
_RESERVED_ATTRIBUTES = frozenset(
    {
        "channels",
        "chunkCount",
        "compression",
        "dataWindow",
        "displayWindow",
        "lineOrder",
        "maxSamplesPerPixel",
        "name",
        "pixelAspectRatio",
        "screenWindowCenter",
        "screenWindowWidth",
        "tiles",
        "type",
        "version",
    }
)

_EXR_MAGIC = b"\x76\x2f\x31\x01"

# Magenta for NaN pixels in previews, white for +Inf.
_NAN_COLOUR = np.array([255, 0, 255], dtype=np.uint8)
_POS_INF_COLOUR = np.array([255, 255, 255], dtype=np.uint8)


def _current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# Read once at import: reading the umask means setting it, which is not
# thread-safe, so it is not done per write.
_FILE_MODE = 0o666 & ~_current_umask()


# ---------------------------------------------------------------------------
# Atomic writes
# ---------------------------------------------------------------------------


class WriteError(HarnessError):
    """A file or folder could not be written (disk full, a missing or unwritable folder): one line, exit code 2.

    Code that catches broad exceptions to carry on (a report's sections, a case's renderer) lets it through: a
    write that failed means the output is incomplete, which no section note may hide.
    """


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _os_reason(err: OSError) -> str:
    """A short, one-line reason for an OSError (no temp-file names)."""
    return _one_line(err.strerror or str(err) or type(err).__name__)


def _atomic_write(path: str | os.PathLike[str], fill: Callable[[BinaryIO], None]) -> Path:
    """Write a file atomically: ``fill`` writes the content into an open binary file.

    The content goes to a temporary file in the destination folder (:func:`_staged_write`), which is moved over
    ``path`` with ``os.replace``.  On any failure the temporary file is removed and the destination is untouched.

    An ``OSError`` (missing or read-only folder, disk full, destination is a
    folder...) becomes ``WriteError(str(path), "cannot write: <reason>")``;
    any other exception (from ``fill``) propagates unchanged.
    """
    dest = Path(path)
    tmp_name: str | None = _staged_write(dest, fill)
    try:
        os.replace(tmp_name, dest)
        tmp_name = None
    except OSError as err:
        raise WriteError(str(path), f"cannot write: {_write_reason(dest.parent, err)}") from None
    finally:
        if tmp_name is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)
    _fsync_folder(dest.parent)
    return dest


def _staged_write(dest: Path, fill: Callable[[BinaryIO], None]) -> str:
    """The name of a complete temporary file beside ``dest`` holding what ``fill`` wrote: flushed, fsync'ed and
    given the usual permissions (``0o666`` less the umask, or the destination's mode if it already exists), ready
    to be renamed over ``dest``. On any failure it is removed: an ``OSError`` becomes ``WriteError(str(dest),
    "cannot write: <reason>")``, any other exception (from ``fill``) propagates unchanged."""
    folder = dest.parent
    suffix = dest.suffix or ".tmp"
    tmp_name: str | None = None
    try:
        try:
            with tempfile.NamedTemporaryFile(
                dir=folder, prefix=f".{dest.name}.", suffix=suffix, delete=False
            ) as tmp:
                tmp_name = tmp.name
                fill(tmp)
                tmp.flush()
                if _durable():
                    os.fsync(tmp.fileno())
            try:  # a link at dest lends no mode (its target's could be anything): the rename replaces the link
                found = os.stat(dest, follow_symlinks=False)
                mode = found.st_mode & 0o7777 if stat.S_ISREG(found.st_mode) else _FILE_MODE
            except OSError:
                mode = _FILE_MODE
            os.chmod(tmp_name, mode)
            done, tmp_name = tmp_name, None
            return done
        finally:
            if tmp_name is not None:
                with contextlib.suppress(OSError):
                    os.unlink(tmp_name)
    except OSError as err:
        raise WriteError(str(dest), f"cannot write: {_write_reason(folder, err)}") from None


def _write_reason(folder: Path, err: OSError) -> str:
    try:
        if not folder.exists():
            return f"folder {str(folder)!r} does not exist"
        if not folder.is_dir():
            return f"{str(folder)!r} is not a folder"
    except OSError:
        pass
    return _os_reason(err)


def _fsync_folder(folder: Path) -> None:
    """Best effort: make the rename itself durable."""
    if not _durable():
        return
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _durable() -> bool:
    """Whether writes are forced to the disk (``os.fsync`` of each file and of its folder after the rename): always,
    unless ``HARNESS_FSYNC=off`` (or 0, no, false: :func:`harness.core.options.switched_off`), the test suite's
    setting (tests/conftest.py). A write then stays atomic (a complete temporary file renamed over the destination:
    no reader sees half a file) but may be lost if the machine stops, as under ``eatmydata`` or SQLite's
    ``synchronous = OFF``: about 3.5 ms less a file here, and a test run writes thousands (docs/ci.md)."""
    return not switched_off("HARNESS_FSYNC")


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Atomically replace the file at ``path`` with ``data``; returns the path.

    Raises ``WriteError(str(path), "cannot write: <reason>")`` (a HarnessError)
    if the folder is missing or not writable or the disk is full; the
    destination is then left as it was.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise TypeError(f"data must be bytes, got {type(data).__name__}")
    return _atomic_write(path, lambda f: f.write(data))


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Atomically replace the file at ``path`` with ``text`` (UTF-8 by default).

    No newline translation is done.  Same errors as :func:`atomic_write_bytes`.
    """
    if not isinstance(text, str):
        raise TypeError(f"text must be str, got {type(text).__name__}")
    return atomic_write_bytes(path, text.encode(encoding))


def link_or_copy(source: str | os.PathLike[str], dest: str | os.PathLike[str], data: bytes | None = None) -> Path:
    """Atomically make ``dest`` hold the file ``source`` (a finished, durable file that is never rewritten in place:
    the harness replaces files, it does not edit them); returns ``dest``.

    A hard link where the file system allows it (no bytes copied, nothing to fsync): made at ``dest`` itself where
    no file is there yet, else linked under a temporary name beside ``dest``, then ``os.replace``'d over it. Where
    it does not (another file system, a file of another user, a full disk), a copy with :func:`atomic_write_bytes`
    (of ``data`` when the caller has read the file already). Errors as :func:`atomic_write_bytes`; an unreadable
    ``source`` is an ``OSError``."""
    dest = Path(dest)
    try:
        os.link(source, dest)  # a new name (a report's staging folder) is whole as soon as it exists
        return dest
    except FileExistsError:
        pass  # replaced atomically below
    except OSError:
        return atomic_write_bytes(dest, Path(source).read_bytes() if data is None else data)
    tmp = dest.parent / f".{dest.name}.{uuid.uuid4().hex[:12]}{dest.suffix}"
    try:
        os.link(source, tmp)
    except OSError:
        return atomic_write_bytes(dest, Path(source).read_bytes() if data is None else data)
    try:
        os.replace(tmp, dest)
    except OSError as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise WriteError(str(dest), f"cannot write: {_write_reason(dest.parent, err)}") from None
    return dest


def make_folders(path: str | os.PathLike[str], where: str | None = None) -> list[Path]:
    """Create the folder ``path`` and its missing parents; returns the folders created, outermost first, so that
    :func:`remove_folders` can take them back when what follows fails (no empty folders left by a failed command).

    Raises ``WriteError(where, "cannot create 'PATH': <reason>")`` (``where`` defaults to the path) when a folder
    cannot be made (disk full, a file in the way, an unwritable parent); the folders made so far are removed.
    """
    path = Path(path)
    where = str(path) if where is None else where
    missing = []
    probe = path
    while not probe.is_dir():
        if probe.exists() or probe.is_symlink():
            if probe.is_dir():  # made by another process between the two looks (two workers filling one cache)
                break
            raise WriteError(where, f"cannot create {str(path)!r}: {str(probe)!r} is not a folder")
        missing.append(probe)
        if probe.parent == probe:
            break
        probe = probe.parent
    created: list[Path] = []
    for folder in reversed(missing):
        try:
            folder.mkdir()
        except FileExistsError:
            if folder.is_dir():  # made by someone else meanwhile
                continue
            remove_folders(created)
            raise WriteError(where, f"cannot create {str(path)!r}: {str(folder)!r} is not a folder") from None
        except OSError as err:
            remove_folders(created)
            raise WriteError(where, f"cannot create {str(path)!r}: {_os_reason(err)}") from None
        created.append(folder)
    return created


def remove_folders(created: list[Path]) -> None:
    """Remove the folders :func:`make_folders` created, innermost first, where they are still empty."""
    for folder in reversed(created):
        with contextlib.suppress(OSError):
            folder.rmdir()


@contextlib.contextmanager
def removed_on_failure(created: list[Path]):
    """Within the block, the folders :func:`make_folders` made (``created``, which may grow in the block) are
    removed where empty when the block raises, and the exception goes on: a failed command leaves no empty folder
    it made, and keeps what it finished in them."""
    try:
        yield created
    except BaseException:
        remove_folders(created)
        raise


def make_real_folders(root: str | os.PathLike[str], relative: str | os.PathLike[str],
                      where: str | None = None) -> list[Path]:
    """Create ``root / relative`` folder by folder below ``root``, following no symbolic link there: a link (or a
    file) in the way is a ``WriteError`` naming it, so that what is written into the folder cannot land outside
    ``root`` through a link planted in it (``root`` itself is made as :func:`make_folders` makes it, and may be a
    link: it is the caller's choice). Each folder is looked at with ``lstat`` after it is made or found. Returns the
    folders created, outermost first (for :func:`remove_folders`); on an error the ones made so far are removed.
    ``where`` names the error (default: the path in the way)."""
    created = make_folders(root, where)
    path = Path(root)
    try:
        for name in Path(relative).parts:
            path = path / name
            try:
                os.mkdir(path)
                created.append(path)
            except FileExistsError:
                pass
            except OSError as err:
                raise WriteError(where or str(path), f"cannot create {str(path)!r}: {_os_reason(err)}") from None
            _refuse_link(path, where)
    except WriteError:
        remove_folders(created)
        raise
    return created


def _refuse_link(path: Path, where: str | None) -> None:
    """A ``WriteError`` unless ``path`` itself (not what a link there names) is a folder."""
    try:
        mode = os.stat(path, follow_symlinks=False).st_mode
    except OSError as err:
        raise WriteError(where or str(path), f"cannot create {str(path)!r}: {_os_reason(err)}") from None
    if stat.S_ISLNK(mode):
        named = "" if where is None else f"{str(path)!r} "  # the error starts with the path itself by default
        raise WriteError(where or str(path), f"{named}is a symbolic link (to {link_target(path)!r}); expected a "
                         "folder: nothing is written through a link inside the output folder, remove it")
    if not stat.S_ISDIR(mode):
        raise WriteError(where or str(path), f"cannot create {str(path)!r}: it is not a folder")


def link_target(path: str | os.PathLike[str]) -> str:
    """Where the symbolic link ``path`` points, as the link reads ("?" when it cannot be read): for messages."""
    try:
        return os.readlink(path)
    except OSError:
        return "?"


@contextlib.contextmanager
def staged_inside(root: str | os.PathLike[str], relative: str | os.PathLike[str], where: str | None = None):
    """A :class:`StagedFolder` for the folder ``root / relative``, made first with :func:`make_real_folders` (no
    link below ``root`` followed): the caller writes into its ``root`` and calls ``commit()``, which moves the files
    into place together. Leaving the block with an exception (a full disk, an interrupt) removes the staging
    folder and the folders made for it: nothing half-written is left."""
    target = Path(root, relative)
    made = make_real_folders(root, relative, where)
    with removed_on_failure(made), StagedFolder(target, where or str(target), tag="writing") as stage:
        yield stage


class StagedFolder:
    """The files of an output folder ``target``, written into a private staging folder first and moved into place
    together by :meth:`commit`, so that a failure halfway (a full disk, an interrupt) leaves nothing half-written.

    When ``target`` does not exist, the staging folder is made beside it (its missing parents are made too) and
    renamed to ``target``: one atomic step. When it exists (a run's folder holding results.json), the staging
    folder is made inside it and each of its entries is moved over the old one: a file with ``os.replace``, a
    folder by renaming the old one aside, the new one in, and removing the old one, so every entry is either
    old or new, never partial; :meth:`commit` moves the names in ``last`` last (a report's index.html).

    A symbolic link at an entry's name in ``target`` is replaced by the entry, never written through. With
    ``replace_link`` (a folder the harness names inside its output, such as ``studies/``), so is a link at ``target``
    itself: :meth:`commit` puts the new folder in the link's place.

    Used as a context manager: leaving it without :meth:`commit` (an exception) removes the staging folder and
    every folder it made, and a :class:`WriteError` naming a staged path is raised again naming the path it was
    meant for. Errors are one-line WriteErrors at ``where`` (e.g. ``--out``). ``tag`` names the staging folder, a
    hidden one: ``.<tag>-<random>`` inside ``target``, ``.<target's name>.<tag>-<random>`` beside it.
    """

    def __init__(self, target: str | os.PathLike[str], where: str, replace_link: bool = False, tag: str = "staging"):
        self.target = Path(target)
        self.where = where
        self.committed = False
        self.replace_link = replace_link
        linked = replace_link and self.target.is_symlink()  # replaced by commit(), never followed
        if self.target.is_dir() and not linked:
            self._created: list[Path] = []
            self.fresh = False
            self.root = self.target / f".{tag}-{uuid.uuid4().hex[:12]}"
        else:
            if (self.target.exists() or self.target.is_symlink()) and not linked:
                raise WriteError(where, f"cannot create {str(self.target)!r}: it is not a folder")
            self._created = make_folders(self.target.parent, where)
            self.fresh = True
            self.root = self.target.parent / f".{self.target.name}.{tag}-{uuid.uuid4().hex[:12]}"
        try:
            self.root.mkdir()
        except OSError as err:
            remove_folders(self._created)
            raise WriteError(where, f"cannot create {str(self.target)!r}: {_os_reason(err)}") from None

    def __enter__(self) -> StagedFolder:
        return self

    def __exit__(self, kind, error, trace) -> None:
        if not self.committed:
            self.discard()
        if isinstance(error, WriteError) and str(self.root) in str(error):
            raise WriteError(self.relocate(error.where), self.relocate(error.message)) from None

    def relocate(self, text: str) -> str:
        """``text`` with every staged path replaced by the path it is meant for (a path alone is joined as a path:
        ``./.staging-x/a`` becomes ``a`` for the target ``.``, as ``Path(".") / "a"`` spells it)."""
        root = str(self.root)
        if text == root:
            return str(self.target)
        if text.startswith(root + os.sep):
            return str(self.target / text[len(root) + 1:])
        return text.replace(root, str(self.target))

    def commit(self, last: tuple[str, ...] = ()) -> Path:
        """Move the staged files into ``target``; returns ``target``."""
        if self.fresh:
            if self.replace_link and self.target.is_symlink():
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(self.target)  # the link itself: what it names is left alone
            try:
                os.rename(self.root, self.target)
                self.committed = True
            except OSError:
                linked = self.replace_link and self.target.is_symlink()
                if linked or not self.target.is_dir():  # else someone made it meanwhile: move the entries into it
                    self.discard()
                    raise WriteError(self.where, f"cannot create {str(self.target)!r}") from None
        if not self.committed:
            names = sorted(os.listdir(self.root), key=lambda name: (name in last, last.index(name) if name in last
                                                                    else 0, name))
            for name in names:
                self._move(self.root / name, self.target / name)
            with contextlib.suppress(OSError):
                self.root.rmdir()
            self.committed = True
        _fsync_folder(self.target)
        _fsync_folder(self.target.parent)
        return self.target

    def _move(self, source: Path, dest: Path) -> None:
        try:
            if source.is_dir() and dest.is_dir() and not dest.is_symlink():
                old = dest.parent / f".{dest.name}.old-{uuid.uuid4().hex[:12]}"
                os.rename(dest, old)
                try:
                    os.rename(source, dest)
                except OSError:
                    os.rename(old, dest)
                    raise
                shutil.rmtree(old, ignore_errors=True)
            else:
                if source.is_dir() and dest.is_symlink():  # a rename over a link fails: the link itself goes
                    os.unlink(dest)
                os.replace(source, dest)
        except OSError as err:
            self.discard()
            raise WriteError(str(dest), f"cannot write: {_os_reason(err)}") from None

    def discard(self) -> None:
        """Remove the staging folder and every folder made for it (nothing is left of a failed write)."""
        shutil.rmtree(self.root, ignore_errors=True)
        remove_folders(self._created)
        self._created = []


# ---------------------------------------------------------------------------
# EXR
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class ExrImage:
    """An EXR file's content as the harness uses it.

    ``image``: (H, W, 3) float32 linear RGB, row 0 at the top.
    ``variance``: (H, W, 3) float32 per-pixel variance, or None if the file
    has no ``variance.R/G/B`` channels.
    ``metadata``: the file's string header attributes (str -> str).
    """

    image: np.ndarray
    variance: np.ndarray | None = None
    metadata: dict[str, str] = field(default_factory=dict)


def _check_rgb_array(name: str, array: object, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = np.asarray(array)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"{name} must have shape (H, W, 3), got {arr.shape}")
    if arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{name} must not be empty, got shape {arr.shape}")
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} has shape {arr.shape}, expected {shape} like the image")
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
            or arr.dtype == np.bool_):
        raise ValueError(f"{name} must be a real numeric array, got dtype {arr.dtype}")
    return arr


def _check_metadata(metadata: Mapping[str, str] | None) -> dict[str, str]:
    if metadata is None:
        return {}
    out: dict[str, str] = {}
    for key, value in metadata.items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise TypeError(
                f"metadata must map str to str, got {type(key).__name__} -> {type(value).__name__}"
                f" for key {key!r}"
            )
        if not key:
            raise ValueError("metadata keys must not be empty")
        if key in _RESERVED_ATTRIBUTES:
            raise ValueError(f"metadata key {key!r} is a reserved OpenEXR header attribute")
        out[key] = value
    return out


def write_exr(
    path: str | os.PathLike[str],
    image: np.ndarray,
    variance: np.ndarray | None = None,
    metadata: Mapping[str, str] | None = None,
) -> Path:
    """Write ``image`` (and optionally ``variance``) as an OpenEXR file, atomically.

    ``image`` and ``variance`` are (H, W, 3) arrays (converted to float32; NaN
    and Inf are written as they are).  The file is a single-part scanline
    image with ZIP compression and float32 channels ``R``, ``G``, ``B`` plus,
    if ``variance`` is given, ``variance.R``, ``variance.G``, ``variance.B``.
    ``metadata`` (str -> str) becomes extra string header attributes; keys
    may not be reserved OpenEXR attribute names (``channels``, ``type``...).
    Row 0 is the top of the image.

    Returns the path.  Raises ``ValueError``/``TypeError`` for bad shapes or
    metadata, and ``HarnessError(str(path), "cannot write: <reason>")`` when
    the output folder is missing or not writable (nothing is left behind).
    """
    return _atomic_write(path, _exr_fill(image, variance, metadata))


def exr_bytes(image: np.ndarray, variance: np.ndarray | None = None,
              metadata: Mapping[str, str] | None = None) -> bytes:
    """The bytes of the OpenEXR file :func:`write_exr` would write, in memory (for writers that stage several files,
    such as ``harness export``)."""
    buffer = io.BytesIO()
    _exr_fill(image, variance, metadata)(buffer)
    return buffer.getvalue()


def _exr_fill(image: np.ndarray, variance: np.ndarray | None, metadata: Mapping[str, str] | None
              ) -> Callable[[BinaryIO], None]:
    """What writes the EXR file of :func:`write_exr` into an open binary file (its arguments checked first)."""
    img = _check_rgb_array("image", image)
    var = None if variance is None else _check_rgb_array("variance", variance, img.shape)
    header: dict[str, object] = dict(_check_metadata(metadata))
    header["compression"] = OpenEXR.ZIP_COMPRESSION
    header["type"] = OpenEXR.scanlineimage

    channels: dict[str, np.ndarray] = {}
    for i, name in enumerate(RGB_CHANNELS):
        channels[name] = np.ascontiguousarray(img[:, :, i], dtype=np.float32)
    if var is not None:
        for i, name in enumerate(VARIANCE_CHANNELS):
            channels[name] = np.ascontiguousarray(var[:, :, i], dtype=np.float32)

    exr = OpenEXR.File(header, channels)

    def fill(f: BinaryIO) -> None:
        try:
            exr.write(f)
        except (RuntimeError, ValueError) as err:
            # Failures writing to the stream (e.g. disk full) surface as RuntimeError.
            raise OSError(_one_line(str(err))) from err

    return fill


# Limits on what a file may claim before its pixels are read (a corrupted header can claim terabytes): the film
# limits of harness/core/limits.py, and a generous number of channels; for a multi-part file, over all its parts
# (the OpenEXR binding reads every part, though only part 0 is used).
MAX_READ_CHANNELS = 64
#: String header attributes the harness reads as counts (the degrees of freedom of a file's variance:
#: ``variance_dof``, else ``spp`` - 1, in :mod:`harness.running.compare`). A number there must be finite and within
#: 0 .. ``MAX_COUNT_ATTRIBUTE`` (integers up to 2^53 are exact as floats), checked with the header.
COUNT_ATTRIBUTES = ("spp", "variance_dof")
MAX_COUNT_ATTRIBUTE = 2**53

_CAPTURE_LOCK = threading.Lock()
_LIBRARY_MESSAGE = re.compile(r"\((EXR_ERR_[A-Z_]+)\)\s*(.*)")
_BINDING_WARNING = re.compile(r"Warning: Exception raised reading pixel data for part \d+ - (.*)")


@contextlib.contextmanager
def _captured_output():
    """Capture what OpenEXR prints while a file is read: the Python binding's warnings (on ``sys.stdout``) and the C
    library's messages (on file descriptor 2), so that a broken file gives one line of ours, not library chatter.

    Yields a list that holds the captured (stdout, stderr) text once the block has ended. The redirection is
    process-wide, so it is serialised by a lock; text others wrote meanwhile is passed on when the read succeeds.
    """
    captured: list[tuple[str, str]] = []
    with _CAPTURE_LOCK:
        buffer = io.StringIO()
        with contextlib.ExitStack() as stack:
            sink = saved = None
            try:
                sys.stderr.flush()
                sink = stack.enter_context(tempfile.TemporaryFile())
                saved = os.dup(2)
                os.dup2(sink.fileno(), 2)
            except (OSError, ValueError, AttributeError):  # no usable fd 2: capture the binding's text only
                if saved is not None:
                    os.close(saved)
                sink = saved = None
            try:
                with contextlib.redirect_stdout(buffer):
                    yield captured
            finally:
                errors = ""
                if saved is not None:
                    os.dup2(saved, 2)
                    os.close(saved)
                    sink.seek(0)
                    errors = sink.read().decode("utf-8", errors="replace")
                captured.append((buffer.getvalue(), errors))


def _library_reason(text: str) -> str:
    """The most telling line of what OpenEXR printed, without the file name it starts with."""
    for line in text.splitlines():
        found = _LIBRARY_MESSAGE.search(line)
        if found:
            return f"{found[1]}: {found[2].strip()}"
    for line in text.splitlines():
        found = _BINDING_WARNING.search(line)
        if found:
            return found[1].strip()
    return ""


def _passed_on(out: str, err: str) -> None:
    """Text captured during a successful read (another thread's, say) goes where it was going after all."""
    if out:
        sys.stdout.write(out)
    if err:
        sys.stderr.write(err)


def _open_exr(path: str, **options):
    """``OpenEXR.File(path, **options)`` with its chatter captured; HarnessError (one line) if it fails."""
    broken = "cannot read OpenEXR file (corrupted or truncated?)"
    failure = None
    with _captured_output() as captured:
        try:
            exr = OpenEXR.File(path, **options)
        except (RuntimeError, ValueError, OSError, TypeError, MemoryError, UnicodeDecodeError) as err:
            exr, failure = None, _one_line(str(err)) or type(err).__name__
    out, err = captured[0]
    text = out + err
    reason = _library_reason(text)
    if exr is None or not exr.parts or _BINDING_WARNING.search(text):
        detail = "; ".join(filter(None, [reason, failure])) or "no readable part"
        raise HarnessError(path, f"{broken}: {_one_line(detail)}"[:400])
    _passed_on(out, err)
    return exr


def _check_claimed_size(path: str, header: dict, max_pixels: int | None = None, part: str = "") -> tuple[int, int]:
    """Refuse a header whose data window or channel count is beyond the harness's limits (and, when given, whose
    data window has more than ``max_pixels`` pixels), before pixels are read. ``part``: "part 1: " and so on in the
    messages of a multi-part file. Returns (width, height, channels) claimed."""
    try:
        low, high = (np.asarray(corner, dtype=np.int64) for corner in header["dataWindow"])
        width, height = int(high[0] - low[0] + 1), int(high[1] - low[1] + 1)
    except (KeyError, TypeError, ValueError, IndexError) as err:
        raise HarnessError(path, f"cannot read OpenEXR file (corrupted?): {part}bad dataWindow "
                                 f"({_one_line(str(err))})") from None
    if width < 1 or height < 1:
        raise HarnessError(path, f"{part}data window is {width} x {height} pixels; expected a non-empty image "
                                 "(corrupted?)")
    if max(width, height) > MAX_FILM_SIDE or width * height > MAX_FILM_PIXELS:
        raise HarnessError(path, (
            f"{part}data window is {width} x {height} pixels ({estimate_text(width, height)}); expected at most "
            f"{MAX_FILM_SIDE} per side and 2^26 pixels (a film the harness renders; corrupted header?)"))
    if max_pixels is not None and width * height > max_pixels:
        raise HarnessError(path, f"{part}is {width} x {height} = {width * height} pixels; expected at most "
                                 f"{max_pixels}")
    channels = header.get("channels") or []
    if len(channels) > MAX_READ_CHANNELS:
        raise HarnessError(path, f"{part}has {len(channels)} channels; expected at most {MAX_READ_CHANNELS} "
                                 "(corrupted?)")
    return width, height, len(channels)


def _check_parts(path: str, headers: list[dict], max_pixels: int | None = None) -> tuple[int, int]:
    """Refuse a file any of whose parts claims more than :func:`_check_claimed_size` allows, or whose parts
    together claim more pixels or channels than one part may (the binding reads every part's pixels), and a
    count attribute of part 0 (:data:`COUNT_ATTRIBUTES`) that is not a sane number; all on the headers alone.
    Returns part 0's (width, height)."""
    pixels = channels = 0
    sizes = []
    for index, header in enumerate(headers):
        part = f"part {index}: " if len(headers) > 1 else ""
        width, height, count = _check_claimed_size(path, header, max_pixels, part)
        pixels, channels = pixels + width * height, channels + count
        sizes.append((width, height))
    if pixels > MAX_FILM_PIXELS or channels > MAX_READ_CHANNELS:
        raise HarnessError(path, (
            f"has {len(headers)} parts claiming {pixels} pixels and {channels} channels in all; expected at most "
            f"2^26 pixels and {MAX_READ_CHANNELS} channels over all parts (corrupted header?)"))
    if not headers:
        raise HarnessError(path, "cannot read OpenEXR file (corrupted?): no part")
    _check_count_attributes(path, headers[0])
    return sizes[0]


def _check_count_attributes(path: str, header: dict) -> None:
    """Refuse a count attribute (:data:`COUNT_ATTRIBUTES`) holding a number that is not finite or lies outside
    0 .. 2^53: a 400-digit ``variance_dof`` would overflow the verdict's floats. Text that is no number at all is left
    to the reader, which ignores it."""
    for key in COUNT_ATTRIBUTES:
        raw = header.get(key)
        if not isinstance(raw, str):
            continue
        try:
            number = float(raw)
        except ValueError:
            continue
        if not (math.isfinite(number) and 0 <= number <= MAX_COUNT_ATTRIBUTE):
            raise HarnessError(path, f"header attribute {key} = {short(raw, 40)}; expected a count from 0 to "
                                     "2^53 (corrupted header?)")


def exr_size(path: str | os.PathLike[str], *, max_pixels: int | None = None) -> tuple[int, int]:
    """(width, height) of an OpenEXR file's part 0, from its headers alone, after every check :func:`read_exr`
    makes on them (so a caller can refuse what the pixels would cost before reading them). HarnessError (one line)
    as :func:`read_exr`."""
    where = str(path)
    _check_magic(where)
    with _open_exr(where, header_only=True) as exr:
        headers = [dict(part.header) for part in exr.parts]
    return _check_parts(where, headers, max_pixels)


def _check_magic(path: str) -> None:
    """Refuse a path that is no regular file or does not start with OpenEXR's magic number (one line)."""
    irregular = None if os.path.isdir(path) else not_regular(path)  # a device or pipe: reading it never ends
    if irregular is not None:
        raise HarnessError(path, f"{irregular.message}; expected an OpenEXR image file")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
    except FileNotFoundError:
        raise HarnessError(path, "no such file; expected an OpenEXR image") from None
    except IsADirectoryError:
        raise HarnessError(path, "is a folder; expected an OpenEXR image file") from None
    except OSError as err:
        raise HarnessError(path, f"cannot read: {_os_reason(err)}") from None
    if magic != _EXR_MAGIC:
        raise HarnessError(path, "not an OpenEXR file (bad magic number)")


def _read_channels(path: str, max_pixels: int | None = None) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    """All channel arrays and the header of part 0, or HarnessError (one line, nothing printed) if unreadable.

    The headers of every part are read first and their claimed sizes and part 0's count attributes checked
    (:func:`exr_size`), so a corrupted header cannot make the reader allocate more than a film the harness
    renders would need, nor hand the verdict a count that overflows.
    """
    exr_size(path, max_pixels=max_pixels)
    broken = "cannot read OpenEXR file (corrupted or truncated?)"
    exr = _open_exr(path, separate_channels=True)
    try:
        with exr:
            header = dict(exr.header())
            _check_claimed_size(path, header, max_pixels)
            channels = {name: np.asarray(ch.pixels) for name, ch in exr.channels().items()}
    except HarnessError:
        raise
    except (RuntimeError, ValueError, OSError, TypeError, MemoryError) as err:
        raise HarnessError(path, f"{broken}: {_one_line(str(err))}") from None
    return channels, header


def _stack(path: str, channels: dict[str, np.ndarray], names: tuple[str, ...]) -> np.ndarray:
    planes = []
    for name in names:
        arr = channels[name]
        if arr.dtype not in (np.float16, np.float32):
            raise HarnessError(
                path, f"channel {name} has pixel type {arr.dtype}; expected HALF or FLOAT"
            )
        planes.append(arr)
    shapes = {p.shape for p in planes}
    if len(shapes) != 1 or planes[0].ndim != 2:
        found = ", ".join(f"{n} {p.shape}" for n, p in zip(names, planes))
        raise HarnessError(path, f"channels must all be full-resolution 2-D planes of one size; got {found}")
    return np.stack(planes, axis=-1).astype(np.float32, copy=False)


def read_exr(path: str | os.PathLike[str], *, max_pixels: int | None = None) -> ExrImage:
    """Read an EXR file with channels ``R``, ``G``, ``B`` (HALF or FLOAT).

    Optional ``variance.R``, ``variance.G``, ``variance.B`` become
    ``ExrImage.variance``; other channels (``A``, depth, AOVs) are ignored,
    so files from Mitsuba and other renderers are accepted.  Pixels are
    returned as float32, row 0 at the top.  ``metadata`` holds the header's
    string attributes.  Only the first part of a multi-part file is used.

    Raises ``HarnessError(str(path), ...)`` (one line) if the file is missing,
    not an OpenEXR file, corrupted or truncated, lacks R/G/B, has only some
    of the variance channels, or has channels of inconsistent sizes; and, checked on the headers before any pixel is
    read, if any part claims more than a film the harness renders (or, when ``max_pixels`` is given, more pixels than
    that), the parts together claim more than one part may, or a count attribute (``spp``, ``variance_dof``) holds a
    number that is not finite or lies outside 0 .. 2^53.
    """
    where = str(path)
    channels, header = _read_channels(where, max_pixels)

    missing = [name for name in RGB_CHANNELS if name not in channels]
    if missing:
        found = ", ".join(sorted(channels)) or "none"
        raise HarnessError(
            where, f"expected channels R, G, B; missing {', '.join(missing)} (found: {found})"
        )
    image = _stack(where, channels, RGB_CHANNELS)

    variance = None
    present = [name for name in VARIANCE_CHANNELS if name in channels]
    if present:
        if len(present) != len(VARIANCE_CHANNELS):
            absent = [name for name in VARIANCE_CHANNELS if name not in channels]
            raise HarnessError(
                where,
                f"has {', '.join(present)} but not {', '.join(absent)}; "
                "expected all of variance.R, variance.G, variance.B or none",
            )
        variance = _stack(where, channels, VARIANCE_CHANNELS)
        if variance.shape != image.shape:
            raise HarnessError(
                where,
                f"variance channels have shape {variance.shape[:2]}, expected {image.shape[:2]} like R, G, B",
            )

    metadata = {
        key: value
        for key, value in header.items()
        if isinstance(key, str) and isinstance(value, str) and key not in _RESERVED_ATTRIBUTES
    }
    return ExrImage(image=image, variance=variance, metadata=metadata)


# ---------------------------------------------------------------------------
# PNG previews
# ---------------------------------------------------------------------------


def preview_path(exr_path: str | os.PathLike[str]) -> Path:
    """The PNG preview beside an EXR file: ``foo.exr`` -> ``foo.png``."""
    return Path(exr_path).with_suffix(".png")


def tonemap_srgb8(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Linear RGB (H, W, 3) -> sRGB uint8 (H, W, 3), as used by previews.

    The image is scaled by ``2**exposure``, clipped to [0, 1], encoded with
    the sRGB transfer function (:func:`harness.core.srgb.encode`) and rounded to 8 bit.
    Pixels with any NaN channel become magenta; otherwise pixels with any
    +Inf channel become white (-Inf clips to 0).
    """
    img = _check_rgb_array("image", image).astype(np.float64)
    nan = np.isnan(img).any(axis=-1)
    pos_inf = np.isposinf(img).any(axis=-1) & ~nan
    with np.errstate(invalid="ignore", over="ignore"):
        scaled = np.clip(np.nan_to_num(img * 2.0 ** float(exposure), nan=0.0), 0.0, 1.0)
    encoded = srgb.encode(scaled)
    out = np.round(np.clip(encoded, 0.0, 1.0) * 255.0).astype(np.uint8)
    out[pos_inf] = _POS_INF_COLOUR
    out[nan] = _NAN_COLOUR
    return out


def write_png_preview(
    path: str | os.PathLike[str], image: np.ndarray, exposure: float = 0.0
) -> Path:
    """Write an 8-bit sRGB PNG preview of linear ``image`` (H, W, 3), atomically.

    Tone mapping is :func:`tonemap_srgb8`: ``sRGB(clip(image * 2**exposure, 0, 1))``;
    NaN pixels are magenta, +Inf pixels white.  Returns the path.  Raises
    ``ValueError`` for a bad shape and ``HarnessError(str(path), "cannot write: ...")``
    if the folder is missing or not writable.
    """
    return atomic_write_bytes(path, _png_bytes(image, exposure))


def _png_bytes(image: np.ndarray, exposure: float = 0.0) -> bytes:
    return encode_png(tonemap_srgb8(image, exposure))


def encode_png(pixels: np.ndarray) -> bytes:
    """uint8 (H, W, 3|4) -> PNG bytes (through the imageio package).

    Notes
    -----
    imageio is imported here, not with this module: it costs about 70 ms of every process's start (its own import
    and ``importlib.metadata``), and most processes that read or write EXR files (renderers' workers, external
    renderers) write no PNG (docs/performance.md, "Imports at every start").
    """
    import imageio.v3 as iio  # optional: ~70 ms to import, PNGs only (the imageio package, not this module)

    return iio.imwrite("<bytes>", np.ascontiguousarray(pixels), extension=".png")


def write_exr_with_preview(
    path: str | os.PathLike[str],
    image: np.ndarray,
    variance: np.ndarray | None = None,
    metadata: Mapping[str, str] | None = None,
    exposure: float = 0.0,
) -> tuple[Path, Path]:
    """Write an EXR file (:func:`write_exr`) and its PNG preview beside it (:func:`preview_path`,
    :func:`write_png_preview`) as a pair: both are written to temporary files first and renamed into place only
    when both are whole, so a failure (a full disk) leaves neither new file, and an old pair as it was. Returns
    (the EXR's path, the preview's). Errors as :func:`write_exr`.
    """
    dest = Path(path)
    preview = preview_path(dest)
    fill = _exr_fill(image, variance, metadata)
    png = _png_bytes(image, exposure)
    for target in (dest, preview):  # a rename over a folder would fail halfway through the pair
        if target.is_dir():
            raise WriteError(str(target), "cannot write: it is a folder")
    staged: list[str] = []
    try:
        staged.append(_staged_write(dest, fill))
        staged.append(_staged_write(preview, lambda f: f.write(png)))
        for target in (preview, dest):  # both are whole: the renames (in one folder) do not fail on a full disk
            try:
                os.replace(staged[-1], target)
            except OSError as err:
                raise WriteError(str(target), f"cannot write: {_os_reason(err)}") from None
            staged.pop()
    finally:
        for tmp_name in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp_name)
    _fsync_folder(dest.parent)
    return dest, preview
