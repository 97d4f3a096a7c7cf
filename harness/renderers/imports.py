"""Scenes written for other renderers read into this project's scene format (``harness import FILE --out DIR``).

Each format has a module of its own (``import_mitsuba``: Mitsuba 3 XML; ``import_gltf``: glTF 2.0; ``import_pbrt``:
pbrt-v4), chosen by the file's suffix in :mod:`harness.renderers.importers`, and each gives an :class:`ImportedScene`: the text of a scene file in the TOML format (docs/scene-format.md) and the files it names
(PLY meshes, texture images), which :func:`write_imported` writes into a folder. Whatever a format holds that the
scene format cannot express is refused in one line naming the element and its place in the file (line and column,
or the glTF JSON path); with ``lenient`` it is dropped instead, listed in ``dropped`` and in the scene's
description, never silently changed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

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
