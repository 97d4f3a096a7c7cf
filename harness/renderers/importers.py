"""``import_scene``: a scene of another renderer's format read into the scene format, by the file's suffix.

It sits above the importers (each imports :class:`harness.renderers.imports.ImportedScene` from the module below
it), so the dispatch is its own module: ``harness.renderers.imports`` importing the importers would close a circle.
"""

from __future__ import annotations

from pathlib import Path

from harness.core.errors import HarnessError
from harness.renderers.import_mitsuba import import_mitsuba
from harness.renderers.imports import ImportedScene

#: the suffixes read, and the importer of each
IMPORTERS = {".xml": import_mitsuba}
# glTF (.gltf, .glb): harness.renderers.import_gltf.import_gltf, imported above and listed here once it exists on
# this branch (another helper writes it); until then its suffixes are refused below.


def import_scene(path: str | Path, *, lenient: bool = False) -> ImportedScene:
    """The scene at ``path`` (Mitsuba 3 XML by its suffix ``.xml``) as an :class:`ImportedScene`; ``lenient`` drops
    what cannot be expressed instead of refusing the file (each importer's rules)."""
    path = Path(path)
    importer = IMPORTERS.get(path.suffix.lower())
    if importer is None:
        raise HarnessError(str(path), "expected a Mitsuba 3 .xml file (glTF: not yet)")
    return importer(path, lenient=lenient)
