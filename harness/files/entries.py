"""A content-addressed store of folder entries (``root/<key>/``): a few files and their metadata, written into a
private temporary folder and renamed into place, so that no reader ever sees half an entry. The results cache of
``harness run`` keeps its cases' outcomes and its studies here (:mod:`harness.running.result_cache`).

An entry is ``entry.json`` (the key, the metadata, the SHA-256 and size of every file, and the SHA-256 of its own
content with the key: an edited ``entry.json``, or an entry copied under another key, is damage like any other)
and ``files/<relative path>``. Every read checks the checksums of what it reads: a missing, partial, edited or
corrupt entry is a miss (``None``), never an exception, and is removed. When two processes store the same key, the
first rename wins; :meth:`EntryStore.store` with ``replace`` puts a fresh entry over an old one.

Private folders (an entry being written, ``.tmp-*``; one being removed, ``.bad-*``) are named for their writer
(:func:`private_name`: host, pid, a random part), so that :func:`sweep_stale` can remove those a killed process
left behind: its pid is gone on this host, or the folder is older than :data:`STALE_SECONDS`.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import socket
import stat
import time
import uuid
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from harness.files.imageio import WriteError, atomic_write_bytes, make_folders

_GIVEN_CACHE_FOLDERS: list[Path] = []  # the cache folders this process was given (--cache-dir), besides the default


def default_cache_dir() -> Path:
    """``$HARNESS_CACHE_DIR``, else ``$XDG_CACHE_HOME/rendering-harness``, else ``~/.cache/rendering-harness``."""
    if os.environ.get("HARNESS_CACHE_DIR"):
        return Path(os.environ["HARNESS_CACHE_DIR"])
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "rendering-harness"


def use_cache_folder(folder: str | os.PathLike[str]) -> None:
    """Record ``folder`` (a ``--cache-dir`` the user gave and the harness checked) as one of this process's cache
    folders (:func:`cache_folders`)."""
    real = Path(os.path.realpath(folder))
    if real not in _GIVEN_CACHE_FOLDERS:
        _GIVEN_CACHE_FOLDERS.append(real)


def cache_folders() -> list[Path]:
    """The cache folders of this process: :func:`default_cache_dir` and those given with :func:`use_cache_folder`
    (real paths). A record of a results.json may name a ground truth in one of them, and nowhere else outside its
    run folder (:func:`harness.files.cases.cache_entry_image`)."""
    return [Path(os.path.realpath(default_cache_dir())), *_GIVEN_CACHE_FOLDERS]

FORMAT = 1
ENTRY_FILE = "entry.json"
FILES = "files"
#: what reading a damaged entry can raise (all of them make the entry a miss)
_DAMAGE = (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError)
#: the prefixes of private folders: an entry being written, one being removed
PRIVATE_PREFIXES = (".tmp-", ".bad-")
#: a private folder older than this is left over whoever wrote it (writing one takes seconds)
STALE_SECONDS = 6 * 3600


def _host() -> str:
    """This machine's name as a private folder's name holds it (letters, digits and dots, at most 64)."""
    return re.sub(r"[^A-Za-z0-9.]", "_", socket.gethostname())[:64] or "host"


def private_name(prefix: str) -> str:
    """A name for a private folder (``prefix`` one of :data:`PRIVATE_PREFIXES`) that no other writer takes and
    that says whose it is: ``PREFIX<host>-<pid>-<random hex>``."""
    return f"{prefix}{_host()}-{os.getpid()}-{uuid.uuid4().hex}"


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this machine (one we may not signal exists too)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _writer_gone(name: str, age: float) -> bool:
    """Whether the private folder ``name``, ``age`` seconds old, has no writer any more: older than
    :data:`STALE_SECONDS`, or named by :func:`private_name` on this host for a process that is gone. A name of
    another host, or of no known form (an older harness's), is kept until it is old."""
    if age > STALE_SECONDS:
        return True
    host, _, rest = name.partition("-")[2].partition("-")  # after the prefix: host-pid-hex
    pid, _, tail = rest.partition("-")
    return host == _host() and pid.isdigit() and bool(tail) and not _alive(int(pid))


def sweep_stale(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the private folders (``.tmp-*``, ``.bad-*``) in ``folder`` whose writer is gone (:func:`_writer_gone`):
    what a process killed while it wrote or removed an entry leaves behind. Returns those removed; a folder that
    cannot be listed or removed is left alone (a cache is never a reason for a command to fail)."""
    removed: list[Path] = []
    now = time.time()
    try:
        listing = list(os.scandir(folder))
    except OSError:
        return removed
    for item in listing:
        if not item.name.startswith(PRIVATE_PREFIXES):
            continue
        try:
            info = item.stat(follow_symlinks=False)
        except OSError:
            continue
        if stat.S_ISDIR(info.st_mode) and _writer_gone(item.name, now - info.st_mtime):
            shutil.rmtree(item.path, ignore_errors=True)
            removed.append(Path(item.path))
    return removed


@dataclass(frozen=True)
class Entry:
    """An entry as :meth:`EntryStore.load` found it: its key, metadata and files (relative path: SHA-256)."""

    key: str
    meta: dict
    files: dict[str, str]
    folder: Path


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _self_sha256(key: str, doc: dict) -> str:
    """SHA-256 of an entry's key and its entry.json content but the checksum itself (JSON, sorted keys)."""
    content = {k: v for k, v in doc.items() if k != "sha256"}
    return _sha256(f"{key}\n{json.dumps(content, sort_keys=True)}".encode())


def _safe_relative(relative: str) -> bool:
    """A relative POSIX path that stays inside its folder (no ``..``, not absolute, no backslash or NUL)."""
    if not isinstance(relative, str) or not relative or "\\" in relative or "\x00" in relative:
        return False
    path = PurePosixPath(relative)
    return not path.is_absolute() and all(part not in ("", ".", "..") for part in path.parts)


class EntryStore:
    """Entries under ``root`` (created on the first store)."""

    def __init__(self, root: str | os.PathLike[str]):
        self.root = Path(root)

    def entry(self, key: str) -> Path:
        return self.root / key

    def load(self, key: str) -> Entry | None:
        """The entry of ``key`` with its entry.json checked (not yet its files: :meth:`read_files`), or None when
        absent or damaged (a damaged one is removed)."""
        folder = self.entry(key)
        try:
            doc = json.loads((folder / ENTRY_FILE).read_text(encoding="utf-8"))
            if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("key") != key:
                raise ValueError("not an entry of this key and format")
            if doc.get("sha256") != _self_sha256(key, doc):
                raise ValueError("entry.json was edited")
            files = {name: item["sha256"] for name, item in doc["files"].items()}
            if not all(_safe_relative(name) and isinstance(sha, str) for name, sha in files.items()):
                raise ValueError("a file name leaves the entry")
            if not isinstance(doc["meta"], dict):
                raise ValueError("meta is not an object")
        except FileNotFoundError:
            if folder.exists():  # a folder without entry.json: not ours to use
                self.discard(key)
            return None
        except _DAMAGE:
            self.discard(key)
            return None
        return Entry(key, doc["meta"], files, folder)

    def read_files(self, entry: Entry) -> dict[str, bytes] | None:
        """Every file of ``entry``, its checksum verified; None (and the entry removed) when one is missing or
        differs."""
        contents = {}
        try:
            for name, sha in entry.files.items():
                data = (entry.folder / FILES / name).read_bytes()
                if _sha256(data) != sha:
                    raise ValueError(f"checksum mismatch in {name}")
                contents[name] = data
        except _DAMAGE:
            self.discard(entry.key)
            return None
        return contents

    def copy_out(self, entry: Entry, dest: str | os.PathLike[str]) -> list[Path] | None:
        """Write every file of ``entry`` into ``dest`` (each atomically, its folders made), all checksums verified
        before the first write; the paths written, or None when the entry is damaged (nothing written)."""
        contents = self.read_files(entry)
        if contents is None:
            return None
        written = []
        for name, data in sorted(contents.items()):
            path = Path(dest, *PurePosixPath(name).parts)
            make_folders(path.parent)
            written.append(atomic_write_bytes(path, data))
        return written

    def store(self, key: str, meta: dict, files: dict[str, str | os.PathLike[str]], *, replace: bool = False) -> bool:
        """Store ``files`` (relative path in the entry: the file to copy) and ``meta`` (JSON) under ``key``. Without
        ``replace`` a valid entry another process stored first is kept; with it, the new entry takes its place.
        Returns whether these files were renamed into place (False also when another process's valid entry was
        kept); a write that fails (a full disk, a file gone) leaves no trace and returns False: a cache is never a
        reason for a run to fail."""
        if not all(_safe_relative(name) for name in files):
            raise ValueError(f"entry file names must be relative paths inside the entry: {sorted(files)}")
        tmp = self.root / private_name(".tmp-")
        try:
            make_folders(self.root)
            tmp.mkdir()
            listed = {}
            for name, source in sorted(files.items()):
                data = Path(source).read_bytes()
                target = tmp / FILES / Path(*PurePosixPath(name).parts)
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(data)
                listed[name] = {"sha256": _sha256(data), "size": len(data)}
            doc = {"format": FORMAT, "key": key, "meta": json.loads(json.dumps(meta)), "files": listed}
            doc["sha256"] = _self_sha256(key, doc)
            (tmp / ENTRY_FILE).write_text(json.dumps(doc, indent=1, sort_keys=True), encoding="utf-8")
            return self._rename_in(tmp, key, replace)
        except (OSError, WriteError, TypeError, ValueError):
            return False
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)

    def _rename_in(self, tmp: Path, key: str, replace: bool) -> bool:
        target = self.entry(key)
        for _attempt in range(3):
            if replace and target.exists():
                self.discard(key)
            try:
                os.rename(tmp, target)
                return True
            except OSError:
                # taken: keep a valid entry (unless replacing); load() removes a damaged one, then try again
                if not replace and self.load(key) is not None:
                    return False
        return False

    def discard(self, key: str) -> None:
        """Remove the entry of ``key`` (renamed aside first, so no reader sees it half removed)."""
        trash = self.root / private_name(".bad-")
        try:
            os.rename(self.entry(key), trash)
        except OSError:
            return
        shutil.rmtree(trash, ignore_errors=True)
