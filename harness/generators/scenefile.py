"""A generated scene as text and bytes: its TOML written value by value, and the files it names.

A generator builds a :class:`SceneFiles` (the scene file's text, ``{relative path: bytes}`` of its meshes and
textures, and its counts), and :func:`write_scene` writes it into a folder. Numbers are written with 7 significant
digits (``%.7g``), so the text is the same on every run and every machine that computes the same float64 values.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.files.imageio import atomic_write_bytes

def scene_file_name(generator: str) -> str:
    """The scene file's name inside a generated folder: the generator's name (``city.toml``), which the studies and
    the report name the scene by."""
    return f"{generator}.toml"
#: the record of what made the folder (generator, parameters, key, counts), beside the scene file
MANIFEST = "generated.json"


def number(x: float) -> str:
    """A float as TOML: 7 significant digits, always with a decimal point or an exponent."""
    text = f"{float(x):.7g}"
    return text if any(c in text for c in ".en") else text + ".0"


def value(x) -> str:
    """A TOML value: a string, bool, int, float, list (of these) or dict (an inline table)."""
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        return number(x)
    if isinstance(x, str):
        return json.dumps(x)  # a JSON string of printable text is a TOML basic string
    if isinstance(x, dict):
        return "{ " + ", ".join(f"{k} = {value(v)}" for k, v in x.items()) + " }"
    return "[" + ", ".join(value(v) for v in x) + "]"


def table(header: str, entries: dict) -> str:
    """``[header]`` (or ``[[header]]`` given with its brackets) and its ``key = value`` lines."""
    head = header if header.startswith("[") else f"[{header}]"
    return "\n".join([head] + [f"{k} = {value(v)}" for k, v in entries.items()]) + "\n"


@dataclass
class SceneFiles:
    """A generated scene: ``toml`` (the scene file's text), ``files`` (``{path relative to the scene file: bytes}``)
    and ``counts`` (``triangles``, ``lights``, ``shapes``, ... as the scene's docs give them)."""

    toml: str
    files: dict[str, bytes] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)


def write_scene(scene: SceneFiles, folder: Path, manifest: dict) -> Path:
    """Write the scene's files, then ``generated.json`` (``manifest`` plus the counts), then the scene file last
    (its presence means the whole folder), each atomically; returns the scene file's path."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in sorted(scene.files):
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(folder / name, scene.files[name])
    record = {**manifest, "counts": scene.counts, "files": sorted(scene.files)}
    atomic_write_bytes(folder / MANIFEST, (json.dumps(record, indent=1, sort_keys=True) + "\n").encode())
    return atomic_write_bytes(folder / scene_file_name(manifest["generator"]), scene.toml.encode())
