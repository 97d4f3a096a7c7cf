"""``import_scene``: a scene of another renderer's format read into the scene format, by the file's suffix.

It sits above the importers (each imports :class:`harness.renderers.imports.ImportedScene` from the module below
it), so the dispatch is its own module: ``harness.renderers.imports`` importing the importers would close a circle.
"""

from __future__ import annotations

from pathlib import Path

from harness.core.errors import HarnessError
from harness.renderers.import_gltf import import_gltf
from harness.renderers.import_mitsuba import import_mitsuba
from harness.renderers.import_pbrt import import_pbrt
from harness.renderers.imports import ImportedScene

#: the suffixes read, and the importer of each
IMPORTERS = {".xml": import_mitsuba, ".gltf": import_gltf, ".glb": import_gltf, ".pbrt": import_pbrt}


def import_scene(path: str | Path, *, lenient: bool = False) -> ImportedScene:
    """The scene at ``path`` (Mitsuba 3 XML by its suffix ``.xml``, glTF 2.0 by ``.gltf`` or ``.glb``, pbrt-v4 by
    ``.pbrt``) as an :class:`ImportedScene`; ``lenient`` drops what cannot be expressed instead of refusing the file
    (each importer's rules)."""
    path = Path(path)
    importer = IMPORTERS.get(path.suffix.lower())
    if importer is None:
        raise HarnessError(str(path), "expected a Mitsuba 3 .xml, a glTF 2.0 .gltf or .glb, or a pbrt-v4 .pbrt file")
    return importer(path, lenient=lenient)
