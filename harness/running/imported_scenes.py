"""A suite's ``scene = "FILE.xml"`` (Mitsuba 3 XML) or ``"FILE.gltf"`` / ``"FILE.glb"`` (glTF 2.0): the file imported
when the suite is loaded (:func:`harness.renderers.importers.import_scene`, strict: whatever the scene format cannot
express is one line naming the element) and kept in the cache by its content, so that a case names a scene file of
the scene format like any other.

The import runs on every load (a scene's parse takes well under a second); what it gives, the scene file's text and
the files it names, is written once to ``IMPORTS/<digest>/`` (``IMPORTS``: the ``imports`` folder of the ground-truth
cache), the digest a SHA-256 of that text and those files. An unchanged source gives the same folder, so every key
derived from the scene (its ground truth, the results cache) is unchanged too; a changed one (the XML, or a mesh or
texture it names) gives another folder.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from harness.renderers import groundtruth
from harness.renderers.importers import IMPORTERS, import_scene
from harness.renderers.imports import SCENE_FILE, write_imported

#: the ground-truth cache's folder of imported scenes
IMPORTS_FOLDER = "imports"


def is_foreign(path: str | Path) -> bool:
    """Whether ``path`` names a file of another format that :func:`scene_file` imports (by its suffix)."""
    return Path(path).suffix.lower() in IMPORTERS


def imports_folder(cache_dir: str | Path | None = None) -> Path:
    """Where imported scenes are kept: ``cache_dir/imports`` (default: the ground-truth cache's folder,
    ``$HARNESS_CACHE_DIR`` or the user cache dir)."""
    return Path(cache_dir if cache_dir is not None else groundtruth.default_cache_dir()) / IMPORTS_FOLDER


def scene_file(path: str | Path, cache_dir: str | Path | None = None) -> Path:
    """The scene file (TOML) of the foreign scene at ``path``, imported and kept by its content under
    :func:`imports_folder`; a HarnessError (one line) where the file cannot be imported."""
    imported = import_scene(Path(path))
    digest = hashlib.sha256(imported.toml.encode())
    for name in sorted(imported.files):
        digest.update(b"\0" + name.encode() + b"\0" + hashlib.sha256(imported.files[name]).digest())
    folder = imports_folder(cache_dir) / digest.hexdigest()[:32]
    if not (folder / SCENE_FILE).is_file():  # the scene file is written last: its presence means the whole entry
        write_imported(imported, folder)
    return folder / SCENE_FILE
