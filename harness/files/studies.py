"""The studies' files in a run's folder (written by :mod:`harness.studies.suite_studies`, formatted by the report):
``OUT/studies/studies.json`` and the images and plots it names, by paths relative to that folder.

Reading them back never raises: a missing, unreadable or malformed studies.json is ``(None, why)``
(:func:`read_studies`), and a named file is used only where it lies inside the studies' folder, and that folder
inside the run folder that holds it, after symlinks (:func:`study_file`); it is read only as the PNG or OpenEXR file
its name says (:func:`read_study_file`), so a hand-edited studies.json cannot make the report copy files from
elsewhere.
"""

from __future__ import annotations

import json
from pathlib import Path, PurePosixPath
from typing import Any

from harness.core.errors import MAX_TEXT_BYTES
from harness.files.confined import Refused, inside, read_inside

STUDIES_FOLDER = "studies"
STUDIES_FILE = "studies.json"
STUDIES_SCHEMA = 1
STUDIES_KIND = "suite-studies"


def studies_folder(results_dir: str | Path) -> Path:
    """Where a run's studies are: ``results_dir/studies``."""
    return Path(results_dir) / STUDIES_FOLDER


def _refuse_constant(text: str) -> Any:
    raise ValueError(f"{text} is not JSON")


def read_studies(folder: str | Path) -> tuple[dict | None, str | None]:
    """``folder/studies.json`` parsed, or (None, why not) where it is missing, unreadable or not a studies file of
    this schema."""
    path = Path(folder) / STUDIES_FILE
    if not path.exists():
        return None, f"{path} not found"
    try:
        text = read_inside(Path(folder).parent, path, limit=MAX_TEXT_BYTES).decode("utf-8")
        doc = json.loads(text, parse_constant=_refuse_constant)
    except Refused as why:
        return None, f"{path}: {why}"
    except (ValueError, RecursionError) as err:
        return None, f"{path}: not valid JSON ({' '.join(str(err).split())[:120]})"
    if not isinstance(doc, dict) or doc.get("kind") != STUDIES_KIND or doc.get("schema") != STUDIES_SCHEMA:
        return None, f"{path}: not a studies file of schema {STUDIES_SCHEMA} (kind {STUDIES_KIND!r})"
    return doc, None


def study_file(folder: str | Path, relative: Any) -> Path | None:
    """The file ``relative`` (a path studies.json names, e.g. ``convergence/furnace.png``) inside ``folder``; None
    when it is not a relative path that stays inside the folder and the run folder that holds it (``folder``'s
    parent) after symlinks, or no such file exists."""
    if not isinstance(relative, str) or not relative or "\\" in relative or "\x00" in relative:
        return None
    parts = PurePosixPath(relative).parts
    if PurePosixPath(relative).is_absolute() or any(p in ("..", ".") for p in parts):
        return None
    root = Path(folder).resolve()
    path = (root / Path(*parts)).resolve()
    if not path.is_relative_to(root) or inside(Path(folder).parent, path) is None or not path.is_file():
        return None
    return path


def read_study_file(folder: str | Path, relative: Any) -> bytes | None:
    """The bytes of :func:`study_file`, read inside the run folder and checked as the kind its name says (a PNG, an
    OpenEXR file: :func:`harness.files.confined.read_inside`); None where it is not such a file."""
    path = study_file(folder, relative)
    kind = {".png": "png", ".exr": "exr"}.get(path.suffix.lower()) if path is not None else None
    if kind is None:
        return None
    try:
        return read_inside(Path(folder).parent, path, kind=kind)
    except Refused:
        return None
