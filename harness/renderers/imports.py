"""Scenes written for other renderers read into this project's scene format (``harness import FILE --out DIR``).

Each format has a module of its own (``import_mitsuba``: Mitsuba 3 XML; ``import_gltf``: glTF 2.0; ``import_pbrt``:
pbrt-v4), chosen by the file's suffix in :mod:`harness.renderers.importers`, and each gives an
:class:`ImportedScene`: the text of a scene file in the TOML format (docs/scene-format.md) and the files it names
(PLY meshes, texture images), which :func:`write_imported` writes into a folder. Whatever a format holds that the
scene format cannot express is refused in one line naming the element and its place in the file (line and column, or
the glTF JSON path); with ``lenient`` it is dropped instead, listed in ``dropped`` and in the scene's description,
never silently changed.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.files.imageio import StagedFolder, atomic_write_bytes, atomic_write_text, make_folders

#: the scene file an import writes
SCENE_FILE = "scene.toml"


@dataclass
class ImportedScene:
    """A scene read from another format.

    toml     the scene file's text (TOML, docs/scene-format.md), naming its files by paths relative to itself
    files    {relative path: bytes} of every file ``toml`` names (PLY meshes, PNG / EXR textures)
    dropped  what ``lenient`` left out: one line each, naming the element, its place in the file and why
    source   the file read
    """

    toml: str
    files: dict[str, bytes] = field(default_factory=dict)
    dropped: list[str] = field(default_factory=list)
    source: Path | None = None


def write_imported(imported: ImportedScene, out_dir: str | Path) -> Path:
    """Write ``scene.toml`` and the files it names into the folder ``out_dir`` (created if needed), as ``harness
    export`` writes its files: staged and moved into place together (:class:`harness.files.imageio.StagedFolder`),
    replacing files of the same names, so a failed write leaves ``out_dir`` as it was. Returns the scene file's path.
    """
    out_dir = Path(out_dir)
    with StagedFolder(out_dir, "--out") as stage:
        for rel, data in imported.files.items():
            path = stage.root / rel
            make_folders(path.parent)
            atomic_write_bytes(path, data)
        atomic_write_text(stage.root / SCENE_FILE, imported.toml)
        stage.commit(last=(SCENE_FILE,))  # the scene file last: it names the others
    return out_dir / SCENE_FILE


def toml_key(name: str) -> str:
    """A key as TOML reads it back: bare where it can be (letters, digits, ``_``, ``-``), else a basic string."""
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else toml_value(name)


def toml_value(value) -> str:
    """A TOML value that reads back as ``value``: booleans; integers; floats by their shortest ``repr`` (the same
    float64 read back, -0.0 and TOML's ``inf`` / ``nan`` included, which the scene loader then judges); strings as
    JSON writes them (its escapes are TOML's basic string's; DEL, which TOML refuses raw, escaped too); lists,
    tuples and numpy arrays as arrays; dicts as inline tables. Another type is a TypeError (a bug, not a user's)."""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        text = repr(float(value))
        return {"nan": "nan", "inf": "inf", "-inf": "-inf"}.get(text, text)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {value!r} as TOML")


def toml_table(header: str, entries: dict) -> list[str]:
    """``[header]`` (or ``[[header]]`` given with its brackets) after an empty line, and its ``key = value`` lines
    (the keys as given: the caller's are bare)."""
    head = header if header.startswith("[[") else f"[{header}]"
    return ["", head] + [f"{key} = {toml_value(value)}" for key, value in entries.items()]
