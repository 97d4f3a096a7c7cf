"""The studies' files in a run's folder (written by :mod:`harness.studies.suite_studies`, formatted by the report):
``OUT/studies/studies.json`` and the images and plots it names, by paths relative to that folder.

Reading them back never raises: a missing, unreadable or malformed studies.json is ``(None, why)``
(:func:`read_studies`), and a named file is used only where it lies inside the studies' folder
(:func:`study_file`), so a hand-edited studies.json cannot make the report copy files from elsewhere.
"""

from __future__ import annotations

import json
from pathlib import Path, PurePosixPath
from typing import Any

from harness.core.errors import HarnessError, read_user_text

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
        doc = json.loads(read_user_text(path, missing="studies file not found"), parse_constant=_refuse_constant)
    except HarnessError as err:
        return None, str(err)
    except (ValueError, RecursionError) as err:
        return None, f"{path}: not valid JSON ({' '.join(str(err).split())[:120]})"
    if not isinstance(doc, dict) or doc.get("kind") != STUDIES_KIND or doc.get("schema") != STUDIES_SCHEMA:
        return None, f"{path}: not a studies file of schema {STUDIES_SCHEMA} (kind {STUDIES_KIND!r})"
    return doc, None


def study_file(folder: str | Path, relative: Any) -> Path | None:
    """The file ``relative`` (a path studies.json names, e.g. ``convergence/furnace.png``) inside ``folder``; None
    when it is not a relative path that stays inside the folder, or no such file exists."""
    if not isinstance(relative, str) or not relative or "\\" in relative or "\x00" in relative:
        return None
    parts = PurePosixPath(relative).parts
    if PurePosixPath(relative).is_absolute() or any(p in ("..", ".") for p in parts):
        return None
    root = Path(folder).resolve()
    path = (root / Path(*parts)).resolve()
    if not path.is_relative_to(root) or not path.is_file():
        return None
    return path
