"""The content key of a loaded scene: a SHA-256 over everything the :class:`~harness.scene.model.Scene` holds.

The key walks the scene's values recursively and hashes each by its kind, so a field added to any scene dataclass
(the scene, its camera and film, a material, a shape, an emitter) enters the key without a line written for it:

* a dataclass: its class name, then every field by name (but :data:`EXCLUDED_FIELDS`, and :data:`WHERE_SET_FIELDS`
  where they hold their defaults);
* a dict: its items in order; a list or tuple: its items in order;
* a numpy array: its shape, dtype and the SHA-256 of its bytes; a numpy scalar as the Python number it holds;
* a float, int, bool, str, enum member or None: its ``repr``;
* a :class:`~pathlib.Path`: the file's name and the SHA-256 of its bytes, read when the key is computed.

Every file the loader read is a Path of :attr:`Scene.files <harness.scene.model.Scene.files>`, so the key holds
the bytes of the scene file and of every file it names (meshes, environment maps, any later kind) as well as what
was loaded from them. A value of any other type is a ``TypeError`` naming where it sits: a new kind of value needs
a rule here, never silence.
"""

from __future__ import annotations

import dataclasses
import enum
import hashlib
import os
import stat
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError, file_kind
from harness.scene.model import (ConstantEnvironment, DirectionalLight, EnvironmentMap, PointLight, Scene, Shape,
                                 SpotLight)

#: The fields left out of the key, by class: the only ones, each because it changes no image and no measurement.
#: An ``[[emitters]]`` entry's ``index`` is its position in ``Scene.emitters``, which the key holds already (the
#: emitters in order); its ``name`` labels it in messages and exports, and nothing renders or measures by it (a
#: region names a shape, not an emitter).
EXCLUDED_FIELDS: dict[type, frozenset[str]] = {
    kind: frozenset({"index", "name"})
    for kind in (PointLight, SpotLight, DirectionalLight, ConstantEnvironment, EnvironmentMap)
}


#: The fields a scene's key holds only where they are not their default, by class: fields added after the key's
#: format 6 (issue 38's media) that a scene without them leaves at their defaults, so that such a scene keeps the key
#: (and the cached ground truths) it had before the fields existed. A value other than the default enters the key
#: as every field does.
WHERE_SET_FIELDS: dict[type, frozenset[str]] = {
    Scene: frozenset({"media", "camera_medium"}),
    Shape: frozenset({"interior", "exterior"}),
}


def content_key(value) -> str:
    """The SHA-256 (hex) of everything ``value`` (a loaded scene, or any part of one) holds.

    Parameters
    ----------
    value : Scene, or any value built of the kinds the module docstring lists
        What to key.

    Returns
    -------
    str
        64 hexadecimal digits: equal for equal content, whatever object holds it.

    Raises
    ------
    HarnessError
        A file the value names cannot be read (one line naming the file).
    TypeError
        A value of a kind the key has no rule for.
    """
    digest = hashlib.sha256()
    for token in content_tokens(value, type(value).__name__, {}):
        digest.update(token.encode("utf-8", "surrogatepass"))
        digest.update(b"\n")
    return digest.hexdigest()


def content_tokens(value, where: str, files: dict[Path, str]) -> Iterator[str]:
    """The tokens that stand for ``value`` in the key, one line each (strings as ``repr``, so none holds a line
    break), containers bracketed so that the sequence reads back one way only.

    Parameters
    ----------
    value
        What to describe.
    where : str
        Where ``value`` sits (``Scene.shapes[2].file``), for the TypeError of a value without a rule.
    files : dict
        The SHA-256 of each file already read for this key, so that a file named twice is read once.
    """
    if isinstance(value, np.generic):  # before float: numpy's float64 is one
        yield from content_tokens(value.item(), where, files)
    elif value is None or isinstance(value, (bool, int, float, str, enum.Enum)):
        yield f"{type(value).__name__} {value!r}"
    elif isinstance(value, np.ndarray):
        yield array_token(value, where)
    elif isinstance(value, Path):
        if value not in files:
            files[value] = file_sha256(value)
        yield f"file {value.name!r} {files[value]}"
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        yield f"{type(value).__qualname__} {{"
        for field in keyed_fields(value):
            yield f"field {field.name}"
            yield from content_tokens(getattr(value, field.name), f"{where}.{field.name}", files)
        yield "}"
    elif isinstance(value, dict):
        yield "dict {"
        for index, (key, item) in enumerate(value.items()):
            yield from content_tokens(key, f"{where} key {index}", files)
            yield from content_tokens(item, f"{where}[{key!r}]", files)
        yield "}"
    elif isinstance(value, (list, tuple)):
        yield "["
        for index, item in enumerate(value):
            yield from content_tokens(item, f"{where}[{index}]", files)
        yield "]"
    else:
        raise TypeError(f"{where}: the content key has no rule for a {type(value).__qualname__}")


def keyed_fields(value) -> list[dataclasses.Field]:
    """The fields of the dataclass instance ``value`` that the key holds: all of them but those
    :data:`EXCLUDED_FIELDS` names for its very class, and those :data:`WHERE_SET_FIELDS` names where they hold
    their default (None, an empty dict)."""
    excluded = EXCLUDED_FIELDS.get(type(value), frozenset())
    where_set = WHERE_SET_FIELDS.get(type(value), frozenset())
    return [field for field in dataclasses.fields(value) if field.name not in excluded
            and not (field.name in where_set and getattr(value, field.name) in (None, {}))]


def array_token(array: np.ndarray, where: str) -> str:
    """An array's token: its shape, its dtype and the SHA-256 of its bytes in C order (an array of Python objects,
    whose bytes are addresses, has no rule)."""
    if array.dtype.hasobject:
        raise TypeError(f"{where}: the content key has no rule for an array of Python objects")
    data = np.ascontiguousarray(array)
    return f"array {data.shape} {data.dtype.str} {hashlib.sha256(data.tobytes()).hexdigest()}"


def file_sha256(path: Path) -> str:
    """The SHA-256 (hex) of the bytes of the regular file at ``path``; a HarnessError naming the file if it cannot
    be read or is not a regular file (a named pipe put in its place is refused, not waited on)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
        with open(fd, "rb") as handle:
            mode = os.fstat(handle.fileno()).st_mode
            if not stat.S_ISREG(mode):
                raise HarnessError(str(path), f"cannot read for the scene's content key: not a regular file "
                                              f"({file_kind(mode)})")
            return hashlib.file_digest(handle, "sha256").hexdigest()
    except (OSError, ValueError) as err:  # ValueError: a NUL byte in the path
        raise HarnessError(str(path), f"cannot read for the scene's content key: "
                                      f"{getattr(err, 'strerror', None) or err}") from None
