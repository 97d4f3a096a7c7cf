"""A suite's ``scene = "generated:NAME"`` (or ``"generated:NAME?key=value&..."``): a scene the project generates
(:mod:`harness.generators`), written once into the ground-truth cache and then used like any scene file.

The folder is ``GENERATED/<name>-<key>/`` (``GENERATED``: the ``generated`` folder of the ground-truth cache; the key
:func:`harness.generators.generation_key`, a SHA-256 of the generators' source files and the full parameters), written
into a temporary folder beside it and renamed into place, so a folder that exists is whole: a second load, in this
process or another, finds it and generates nothing. A generator that changes (any of its source files) gives a new
folder; the scene's content key (its ground truth, the results cache) follows the bytes it writes.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from harness.core.errors import HarnessError
from harness.generators import PREFIX, generation_key, parse_spec, scene_file_name
from harness.renderers import groundtruth

#: the ground-truth cache's folder of generated scenes
GENERATED_FOLDER = "generated"


def is_generated(value: str) -> bool:
    """Whether a suite's ``scene`` value names a generated scene (``generated:...``)."""
    return value.startswith(PREFIX)


def generated_folder(cache_dir: str | Path | None = None) -> Path:
    """Where generated scenes are kept: ``cache_dir/generated`` (default: the ground-truth cache's folder)."""
    return Path(cache_dir if cache_dir is not None else groundtruth.default_cache_dir()) / GENERATED_FOLDER


def scene_file(value: str, where: str, cache_dir: str | Path | None = None) -> Path:
    """The scene file of ``value`` (``generated:NAME[?key=value&...]``), generated under :func:`generated_folder`
    unless already there; an unknown name or a bad parameter is one HarnessError at ``where``."""
    generator, params = parse_spec(value[len(PREFIX):], where)
    folder = generated_folder(cache_dir) / f"{generator.name}-{generation_key(generator.name, params)}"
    name = scene_file_name(generator.name)
    if (folder / name).is_file():
        return folder / name
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        scratch = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    except OSError as err:
        raise HarnessError(where, f"cannot write the generated scene under {folder.parent}: "
                                  f"{err.strerror or err}") from None
    try:
        try:
            generator(scratch, **params)
        except HarnessError as err:  # parameters the generator cannot meet together: at the suite's key
            raise HarnessError(where, err.message) from None
        try:
            os.rename(scratch, folder)
        except OSError:
            if not (folder / name).is_file():  # another process's rename won: its folder is the same bytes
                raise
    except OSError as err:
        raise HarnessError(where, f"cannot write the generated scene into {folder}: {err.strerror or err}") from None
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return folder / name
