"""The files a scene names and the files they name in turn: a PLY's element counts checked against its header, and
the files a mesh file names (an OBJ's ``mtllib``, an MTL's ``map_Kd``, a PLY's ``comment TextureFile``) confined to
the scene's folder.

The harness ignores materials and textures, so :mod:`harness.scene.load` tells trimesh to skip them
(``skip_materials``) and hands it bytes the harness read itself: trimesh opens no file of its own. The resolver it
is handed, :class:`ConfinedResolver`, is the one road to any file a mesh names, for trimesh and for a later reader
of textures: :func:`confined_path` resolves a name, refuses one that leaves the scene's folder (after symlinks)
unless outside paths are allowed, and refuses what is not a regular file before it is opened (a named pipe blocks
the open, a device never ends the read); the scene's own ``file`` keys go through the same function.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from harness.core.errors import HarnessError, not_regular, read_user_bytes

#: the most a mesh file, or a file it names, may hold: it is read whole before it is parsed
MAX_MESH_BYTES = 2**30

#: numpy's code of each PLY property type (the names trimesh's PLY reader takes)
PLY_TYPES = {"char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1", "short": "i2", "ushort": "u2", "int16": "i2",
             "uint16": "u2", "int": "i4", "uint": "u4", "int32": "i4", "uint32": "u4", "int64": "i8", "uint64": "u8",
             "float16": "f2", "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def confined_path(folder: Path, name: str, what: str, where: str, *, allow_outside: bool = False,
                  base: Path | None = None, outside_hint: str = "--allow-outside-paths allows others") -> Path:
    """The absolute, symlink-resolved path of a file named ``name`` relative to ``base`` (default: ``folder``, the
    scene file's folder), which must exist, be a regular file and, unless ``allow_outside``, lie inside ``folder``.

    Parameters
    ----------
    folder : Path
        The scene file's folder: what every file the scene pulls in must stay in.
    name : str
        The name as the file wrote it (relative, or absolute).
    what : str
        What the file is, for the messages ("mesh", "envmap", "material library").
    where : str
        The HarnessError's location (the scene file and the key that named the file).
    allow_outside : bool
        ``--allow-outside-paths``: the folder rule is lifted (the file rules are not).
    base : Path, optional
        The folder ``name`` is relative to, where that is not the scene's (an OBJ's ``mtllib``: the OBJ's folder).
    outside_hint : str
        What the message of a file outside the folder adds in parentheses (a command without
        ``--allow-outside-paths``, such as ``harness import``, passes "").

    Raises
    ------
    HarnessError
        At ``where``: a name that cannot be resolved, leaves ``folder``, is no regular file (checked before anything
        opens it) or does not exist.
    """
    base = folder if base is None else base
    try:
        path = (base / name).resolve()
        root = folder.resolve()
    except (OSError, ValueError, RuntimeError) as err:
        raise HarnessError(where, f"cannot resolve the {what} file name {name!r}: {err}") from None
    if not allow_outside and not path.is_relative_to(root):
        raise HarnessError(where, (
            f"{what} file {name!r} resolves to {str(path)!r}, outside the scene's folder {str(root)!r}; "
            f"expected a file inside it{f' ({outside_hint})' if outside_hint else ''}"))
    irregular = not_regular(path, where)
    if irregular is not None:
        raise HarnessError(where, f"{what} file {name!r} is {irregular.message}") from None
    try:
        exists = path.is_file()
    except (OSError, ValueError):
        exists = False
    if not exists:
        raise HarnessError(where, f"no such {what} file: {name!r} (relative to {str(base)!r})")
    return path


class ConfinedResolver:
    """A trimesh resolver (``get``, ``resolver[name]``) for the files a mesh file names, each read through
    :func:`confined_path`: relative to the mesh file's folder, inside the scene's folder unless outside paths are
    allowed, a regular file, at most :data:`MAX_MESH_BYTES`. Anything else is a :class:`HarnessError` at ``where``
    (the scene file and the mesh's ``file`` key). It writes nothing and lists nothing; ``opened``, when given, is
    called with each path before it is read (the loader's record of the files a scene is read from)."""

    def __init__(self, folder: Path, base: Path, where: str, *, allow_outside: bool = False,
                 opened: Callable[[Path], Path] | None = None):
        self.folder = Path(folder)
        self.base = Path(base)
        self.where = where
        self.allow_outside = allow_outside
        self.opened = opened

    def get(self, name: str) -> bytes:
        """The bytes of the file ``name`` names (relative to the mesh file's folder)."""
        if not isinstance(name, str) or not name.strip():
            raise HarnessError(self.where, f"expected a file name, got {name!r}")
        path = confined_path(self.folder, name.strip(), "referenced", self.where, allow_outside=self.allow_outside,
                             base=self.base)
        if self.opened is not None:
            self.opened(path)
        return read_user_bytes(path, missing=f"no such file: {name!r}", where=self.where, limit=MAX_MESH_BYTES)

    def __getitem__(self, name: str) -> bytes:
        return self.get(name)

    def keys(self):
        """No names: the resolver answers only for files a mesh names."""
        return iter(())

    def write(self, name: str, data) -> None:
        """Refused: loading a scene writes nothing."""
        raise HarnessError(self.where, f"cannot write {name!r}: loading a scene writes no file")

    def namespaced(self, namespace: str) -> ConfinedResolver:
        """The same confinement for names relative to the subfolder ``namespace`` of the mesh file's folder."""
        return ConfinedResolver(self.folder, self.base / namespace, self.where, allow_outside=self.allow_outside,
                                opened=self.opened)


def ply_count_problem(data: bytes) -> str | None:
    """Why a PLY file's data does not hold what its header declares, or None.

    The header (read as trimesh reads it) declares each element's count; the data must hold exactly that many
    rows. ASCII: one line a row (trimesh takes rows by line and silently drops what a truncated file lacks);
    binary: the rows' bytes, every list as long as in the element's first row (as trimesh reads them), and nothing
    after the last element. A header that claims 10^9 faces is checked by arithmetic, not by allocating them.
    """
    header = _ply_header(data)
    if isinstance(header, str):
        return header
    is_ascii, big_endian, elements, start = header
    if is_ascii:
        return _ply_ascii_problem(data[start:], elements)
    return _ply_binary_problem(data, start, elements, ">" if big_endian else "<")


def _ply_header(data: bytes):
    """(is ascii, big endian, [(name, count, [(list count type or None, type)])], data offset), or a problem."""
    lines = _lines(data)
    first = next(lines, (b"", 0))[0]
    if b"ply" not in first.lower():
        return "expected a PLY file starting with 'ply'"
    encoding = next(lines, (b"", 0))[0].decode("utf-8", "replace").strip().lower()
    elements: list[tuple[str, int, list]] = []
    for number, (raw, offset) in enumerate(lines, 3):
        fields = raw.decode("utf-8", "replace").split()
        if "end_header" in fields:
            return "ascii" in encoding, "big" in encoding, elements, offset
        if fields and "element" in fields[0]:
            try:
                name, count = fields[1:]
                count = int(count)
            except ValueError:
                count = -1
            if count < 0:
                return f"header line {number}: expected 'element NAME COUNT', got {_quoted(raw)}"
            elements.append((name, count, []))
        elif fields and "property" in fields[0]:
            problem = _ply_property(fields, elements)
            if problem:
                return f"header line {number}: {problem}, got {_quoted(raw)}"
    return "expected a header ending in 'end_header'"


def _lines(data: bytes):
    """(line, offset of the next line) of ``data`` split at b"\\n", as trimesh's ``readline`` reads a header."""
    start = 0
    while start < len(data):
        end = data.find(b"\n", start)
        end = len(data) if end < 0 else end
        yield data[start:end], min(end + 1, len(data))
        start = end + 1


def _quoted(raw: bytes) -> str:
    return repr(raw[:60].decode("utf-8", "replace").strip())


def _ply_property(fields: list[str], elements: list) -> str | None:
    """Add one ``property TYPE NAME`` or ``property list COUNT_TYPE TYPE NAME`` to the last element, or why not."""
    if not elements:
        return "a property before any element"
    if len(fields) == 3 and fields[1] in PLY_TYPES:
        elements[-1][2].append((None, PLY_TYPES[fields[1]]))
        return None
    if (len(fields) == 5 and "list" in fields[1] and PLY_TYPES.get(fields[2], "f")[0] in "iu"
            and fields[3] in PLY_TYPES):
        elements[-1][2].append((PLY_TYPES[fields[2]], PLY_TYPES[fields[3]]))
        return None
    return "expected 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME' (an integer count) with PLY types"


def _short(count: int, name: str, have: int) -> str:
    return (f"its header declares {count} {name} elements but the file holds {have} (truncated, or a header that "
            "lies)")


def _ply_ascii_problem(body: bytes, elements: list) -> str | None:
    """Rows of an ASCII PLY: one line each, in the header's order (trimesh's ``str.splitlines`` of the UTF-8 text)."""
    try:
        lines = body.decode("utf-8").splitlines()
    except UnicodeDecodeError as err:
        return f"expected UTF-8 text after an ASCII header, got an undecodable byte at offset {err.start}"
    used = 0
    for name, count, _ in elements:
        have = max(0, min(count, len(lines) - used))
        if have < count:
            return _short(count, name, have)
        used += count
    extra = sum(1 for line in lines[used:] if line.strip())
    if extra:
        return f"{extra} line{'s' if extra > 1 else ''} of data after the {used} rows its header declares"
    return None


def _ply_binary_problem(data: bytes, offset: int, elements: list, endian: str) -> str | None:
    """Rows of a binary PLY: each element's rows as long as its first row (lists as long as there), back to back."""
    for name, count, properties in elements:
        if count == 0 or not properties:
            continue
        row, lists = 0, []
        for count_type, item_type in properties:
            if count_type is None:
                row += np.dtype(item_type).itemsize
                continue
            count_dtype = np.dtype(endian + count_type)
            if offset + row + count_dtype.itemsize > len(data):
                return _short(count, name, 0)
            length = int(np.frombuffer(data, count_dtype, 1, offset + row)[0])
            if length < 0:
                return f"the first {name} element has a list of {length} entries"
            lists.append((row, count_dtype, length))
            row += count_dtype.itemsize + length * np.dtype(item_type).itemsize
        have = min(count, (len(data) - offset) // row)
        if have < count:
            return _short(count, name, have)
        for position, count_dtype, length in lists:
            lengths = np.ndarray((count,), count_dtype, data, offset + position, (row,))
            differing = np.flatnonzero(lengths != length)
            if differing.size:
                return (f"{name} element {int(differing[0])} has a list of {int(lengths[differing[0]])} entries, "
                        f"the first {length}; a binary PLY's lists must all be as long as in its first row")
        offset += count * row
    if offset != len(data):
        return f"{len(data) - offset} bytes of data after the elements its header declares"
    return None


def read_mesh(data: bytes, file_type: str, resolver: ConfinedResolver | None = None):
    """A PLY or OBJ file's mesh as the harness reads every mesh file: trimesh, from bytes read by the caller.

    The scene loader (:meth:`harness.scene.load`'s mesh) and the pbrt importer's ``plymesh`` read their files here,
    so a file the one takes the other takes, with the same one-line refusals. A PLY's rows are first checked
    against its header (:func:`ply_count_problem`); trimesh is told to skip materials and textures and to leave the
    mesh as the file holds it (``process=False``: no vertex merged, no face dropped); a PLY's quads are split as
    trimesh splits them, (0 1 2) and (2 3 0).

    Parameters
    ----------
    data : bytes
        The file's bytes.
    file_type : str
        ``"ply"`` or ``"obj"``.
    resolver : ConfinedResolver, optional
        The road to the files the mesh file names (an OBJ's ``mtllib``); None: a PLY alone.

    Returns
    -------
    tuple
        ``(vertices (V, 3) float64, triangles (F, 3) int64, normals (V, 3) float64 or None, uv (V, 2) float64 or
        None, polygons)``: the file's vertex normals (PLY ``nx ny nz``, OBJ ``vn``) and texture coordinates (PLY
        ``u v`` / ``s t`` / ``texture_u texture_v``, OBJ ``vt``) as the file holds them (no flip), None where absent
        or not one per vertex; ``polygons`` a PLY's faces as its header's first list property holds them (a list
        of index arrays; None for an OBJ), for a reader that must know which were quads.

    Raises
    ------
    ValueError
        One line: what is wrong with the file (its rows against its header, or trimesh's own reason).
    HarnessError
        A file the mesh names that ``resolver`` refuses.
    """
    if file_type == "ply":
        problem = ply_count_problem(data)
        if problem:
            raise ValueError(problem)
    try:
        import trimesh  # optional: 0.6 s (scipy, networkx) at every command's start; only mesh files need it
        mesh = trimesh.load(io.BytesIO(data), file_type=file_type, resolver=resolver, process=False,
                            skip_materials=True)
        if isinstance(mesh, trimesh.Scene):  # several parts: one mesh, as Mitsuba reads the file
            mesh = trimesh.util.concatenate(mesh.dump())
        # the file's vertex normals (PLY nx, ny, nz; OBJ vn), which trimesh keeps in its cache as read
        normals = mesh._cache.cache.get("vertex_normals")
        vertices = np.array(mesh.vertices, dtype=np.float64).reshape(-1, 3)
        triangles = np.array(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
        uv = getattr(mesh.visual, "uv", None)  # PLY u, v / s, t / texture_u, texture_v; OBJ vt (Mitsuba's)
        uv = None if uv is None or len(uv) != len(vertices) else np.array(uv, dtype=np.float64).reshape(-1, 2)
        if normals is not None:
            normals = np.array(normals, dtype=np.float64).reshape(-1, 3)
            normals = normals if len(normals) == len(vertices) else None
        polygons = None
        if file_type == "ply":
            raw = mesh.metadata.get("_ply_raw", {}).get("face", {}).get("data")
            rows: Any = []
            if isinstance(raw, np.ndarray) and raw.dtype.names:  # binary: records, the list their first field
                rows = raw[raw.dtype.names[0]]
                if rows.dtype.names:  # (count, indices) records of equal lists
                    rows = rows[rows.dtype.names[-1]]
            elif isinstance(raw, dict) and raw:  # ASCII: the lists by property name
                rows = next(iter(raw.values()))
            polygons = [np.asarray(row, np.int64).ravel() for row in rows]
    except HarnessError:
        raise
    except Exception as err:  # trimesh's parsers raise many kinds of exceptions for broken files
        reason = " ".join(str(err).split()) or type(err).__name__
        raise ValueError(reason[:300]) from None
    return vertices, triangles, normals, uv, polygons
