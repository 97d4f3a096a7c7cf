"""External renderers: any program, run as a command described by a small TOML file (``docs/external-renderers.md``).

A renderer file::

    name = "mitsuba-scalar-cli"                 # default: the file's stem
    description = "..."                         # optional
    command = ["{python}", "{here}/render.py", "{scene_xml}", "--spp", "{spp}", "--seed", "{seed}", "--out", "{out}"]
    timeout = 600                               # seconds per run (default 600)
    repeats = 4                                 # runs with distinct seeds when the EXR has no variance (default 4)

Placeholders in ``command``: ``{scene_xml}`` (the scene exported as Mitsuba XML, :mod:`harness.renderers.export`),
``{scene_json}`` (the scene as scene.json, docs/scene-json.md), ``{scene_gltf}`` (as glTF), ``{mesh_dir}`` (the
folder of scene.json's PLY meshes): each the case's resolved scene, written only when the command names it;
``{scene_toml}`` (the scene file as written), ``{spp}``, ``{seed}``, ``{width}``, ``{height}``, ``{max_depth}``,
``{out}`` (the EXR to write), ``{here}`` (the renderer file's folder) and ``{python}`` (this Python). The command
runs without a shell, in a fresh temporary folder, in a process group of its own that is killed after the run and
when the harness dies (:mod:`harness.renderers.processes`); stdout is discarded and the last 64 KiB of stderr kept.

The EXR is read with :func:`harness.files.imageio.read_exr`: channels R, G, B and, optionally, variance.R/G/B (the
variance of each pixel's estimate, i.e. of the mean; spp - 1 degrees of freedom). Without variance channels the
renderer is run K = ``repeats`` times with independent seeds s_1..s_K and the harness uses

    image    = (1/K) sum_k I_k
    variance = 1/(K (K-1)) sum_k (I_k - image)^2     (the sample variance of the K images over K)

per pixel and channel: an unbiased estimate of the variance of ``image`` with K - 1 degrees of freedom, which the
verdict's t-correction takes from ``RenderResult.info["variance_dof"]``. A request that uses no variance
(``RenderRequest.variance`` False: the convergence study) runs the command once, so that the image holds exactly the
spp asked for; its variance is None.

Render time excludes process start-up (docs/external-renderers.md, "Timing"): a run may report its own
``render_seconds`` (and ``variance_dof``, the degrees of freedom of its variance channels) as EXR string header
attributes or in ``<out>.json`` (:func:`reported_values`); otherwise each run's wall time less the start-up,
measured once per renderer and scene with 1-spp runs on a 1 x 1 film (:meth:`ExternalRenderer.startup_seconds`).
``RenderResult.info["time_from"]`` says which.

A non-zero exit, a timeout, a missing or unreadable EXR, or one of the wrong size raises
:class:`ExternalRendererError` (its message with every control and bidirectional character escaped), which a suite
records as the case's ``error`` with the reason. A missing or invalid renderer file is a user error
(:class:`~harness.core.errors.HarnessError`).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.metadata
import json
import math
import os
import re
import shlex
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError, read_user_toml
from harness.core.limits import MAX_TIMEOUT_SECONDS
from harness.core.text import printable, short, toml_key
from harness.files.imageio import read_exr
from harness.renderers.base import RenderRequest, RenderResult
from harness.renderers.export import scene_files
from harness.renderers.processes import CommandStartError, CommandTimeout, run_group
from harness.renderers.mitsuba import pass_seed
from harness.scene import Scene

PLACEHOLDERS = ("scene_xml", "scene_json", "scene_gltf", "mesh_dir", "scene_toml", "spp", "seed", "width", "height",
                "max_depth", "out", "here", "python")
#: the placeholders that name an export of the case's resolved scene: (format, folder in the run's temporary folder,
#: the path handed over, relative to that folder); every format a command names is written once per render
SCENE_EXPORTS = {"scene_xml": ("mitsuba-xml", "scene", "scene.xml"), "scene_json": ("json", "json", "scene.json"),
                 "mesh_dir": ("json", "json", "meshes"), "scene_gltf": ("gltf", "gltf", "scene.gltf")}
FILE_KEYS = ("name", "description", "command", "timeout", "repeats")
DEFAULT_TIMEOUT_S = 600.0
#: the shortest ``timeout``: starting a process (an interpreter, its imports) alone takes up to a second on a loaded
#: machine, so a shorter timeout fails runs for the machine's load rather than the renderer's
MIN_TIMEOUT_S = 1.0
DEFAULT_REPEATS = 4
STDERR_TAIL_LINES = 3
_PLACEHOLDER = re.compile(r"\{([^{}]*)\}")
MAX_REPEATS = 1000  # each repeat is a whole run of the program, and every image is held until they are combined
#: a renderer's name: it is shown in tables and goes into a temporary folder's name, so no "/", "..", control
#: characters or leading "-"
SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9 ._+-]{0,63}")


class ExternalRendererError(RuntimeError):
    """A run of an external renderer failed (exit code, timeout, missing/unreadable/wrong-size EXR).

    Not a :class:`HarnessError`: a suite records it as the case's error and goes on. The message quotes the
    renderer's own text, so every character that is not printable is escaped (:func:`~harness.core.text.printable`):
    it reaches the terminal, results.json and the report as one line with no terminal controls."""

    def __init__(self, message: str):
        super().__init__(printable(str(message)))


@dataclass(frozen=True)
class ExternalSpec:
    """A validated renderer file."""

    name: str
    path: Path
    command: tuple[str, ...]
    timeout: float = DEFAULT_TIMEOUT_S
    repeats: int = DEFAULT_REPEATS
    description: str = ""


def load_spec(path: str | Path) -> ExternalSpec:
    """Read and validate a renderer TOML file; every problem is a one-line HarnessError naming the file and key."""
    path = Path(path)
    label = str(path)
    doc = read_user_toml(path, missing="no such renderer file; expected a TOML file with command = [...]")
    for key in doc:
        if key not in FILE_KEYS:
            shown = toml_key(key) if len(key) <= 60 else short(key, 60)
            raise HarnessError(f"{label}: {shown}", f"unknown key; expected one of {', '.join(FILE_KEYS)}")
    command = doc.get("command")
    if not isinstance(command, list) or not command or not all(isinstance(a, str) for a in command):
        raise HarnessError(f"{label}: command", f"expected a non-empty list of strings, got {short(command, 80)}")
    for index, arg in enumerate(command):
        if "\0" in arg:
            raise HarnessError(f"{label}: command", f"argument {index} holds a NUL character, which no program's "
                               f"argument can: {short(arg, 60)}")
        for name in _PLACEHOLDER.findall(arg):
            if name not in PLACEHOLDERS:
                raise HarnessError(f"{label}: command", f"unknown placeholder {short('{' + name + '}', 40)} "
                                   f"in {short(arg, 60)}; expected " + ", ".join(f"{{{p}}}" for p in PLACEHOLDERS))
    if not any("{out}" in arg for arg in command):
        raise HarnessError(f"{label}: command", "expected an argument with {out} (the EXR the renderer writes)")
    timeout = doc.get("timeout", DEFAULT_TIMEOUT_S)
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not (
            MIN_TIMEOUT_S <= timeout <= MAX_TIMEOUT_SECONDS):
        raise HarnessError(f"{label}: timeout", f"expected a number of seconds of at least {MIN_TIMEOUT_S:g} "
                           f"(starting a process alone can take that long on a loaded machine) and at most "
                           f"{MAX_TIMEOUT_SECONDS:g} (a week), got {short(timeout, 60)}")
    repeats = doc.get("repeats", DEFAULT_REPEATS)
    if isinstance(repeats, bool) or not isinstance(repeats, int) or not 2 <= repeats <= MAX_REPEATS:
        raise HarnessError(f"{label}: repeats",
                           f"expected an integer from 2 to {MAX_REPEATS}, got {short(repeats, 60)}")
    name = doc.get("name", path.stem)
    description = doc.get("description", "")
    for key, value in (("name", name), ("description", description)):
        if not isinstance(value, str):
            raise HarnessError(f"{label}: {key}", f"expected a string, got {short(value, 60)}")
    if not SAFE_NAME.fullmatch(name):
        default = "" if "name" in doc else " (no name key: the file's stem)"
        raise HarnessError(f"{label}: name", (
            f"expected 1 to 64 letters, digits, spaces and . _ + - starting with a letter or digit (the name goes "
            f"into file names), got {short(name, 60)}{default}"))
    return ExternalSpec(name, path.resolve(), tuple(command), float(timeout), repeats, description)


#: the largest seed handed to ``{seed}``: renderers with a signed 32-bit seed (Cycles, most C programs) take 0 to
#: 2^31 - 1, so every seed is folded into that range (docs/external-renderers.md, "Seeds")
MAX_SEED = 2**31 - 1


def fold_seed(seed: int) -> int:
    """``seed`` folded into 0 .. :data:`MAX_SEED`: seeds already in range are kept, the others are reduced modulo
    2^31 (so a harness seed of 2^31 and one of 0 give the same runs; harness seeds of 32 bits or more are rare)."""
    return int(seed) % (MAX_SEED + 1)


def repeat_seed(seed: int, index: int) -> int:
    """The seed of run ``index`` of a render with ``seed``: a SplitMix64 hash of both (unrelated seeds for nearby
    inputs), folded into 0 .. 2^31 - 1, the range every renderer accepts (:func:`fold_seed`)."""
    return fold_seed(pass_seed(seed, index))


def combine_repeats(images: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, int]:
    """K independent renders I_1..I_K (each (H, W, 3)) as one estimate: their mean, the variance of that mean
    estimated as s^2 / K with s^2 = sum_k (I_k - mean)^2 / (K - 1) (unbiased), and its degrees of freedom K - 1."""
    stack = np.stack([np.asarray(i, dtype=np.float64) for i in images])
    k = stack.shape[0]
    if k < 2:
        raise ValueError("combine_repeats needs at least two renders")
    return stack.mean(axis=0), stack.var(axis=0, ddof=1) / k, k - 1


def _tail(text: str, lines: int = STDERR_TAIL_LINES) -> str:
    """The last ``lines`` non-blank lines of ``text``, each escaped (:func:`printable`), joined by " | " and cut to
    their last 400 characters: the part of a renderer's stderr an error message quotes."""
    kept = [printable(line.strip()) for line in text.strip().splitlines() if line.strip()][-lines:]
    return " | ".join(kept)[-400:]


def _run(argv: list[str], cwd: Path, timeout: float, name: str) -> tuple[float, str]:
    """Run ``argv`` without a shell in its own process group, stdout discarded, killed with its whole group when it
    exits (:func:`~harness.renderers.processes.run_group`); returns (seconds, the end of its stderr). Raises
    ExternalRendererError when it cannot start, exits non-zero or times out."""
    try:
        code, seconds, stderr = run_group(argv, cwd, timeout)
    except CommandStartError as err:
        raise ExternalRendererError(f"renderer {name!r} could not start {short(argv[0], 200)}: {err}") from None
    except CommandTimeout:
        command = shlex.join(argv)
        raise ExternalRendererError(f"renderer {name!r} timed out after {timeout:g} s (killed): "
                                    + (command if len(command) <= 400 else command[:397] + "...")) from None
    text = stderr.decode("utf-8", "replace")
    if code != 0:
        tail = _tail(text)
        raise ExternalRendererError(f"renderer {name!r} exited with code {code}"
                                    + (f": {tail}" if tail else " (no stderr)"))
    return seconds, text


#: runs of the start-up probe (:meth:`ExternalRenderer.startup_seconds`); their median counts (the probe follows
#: the render's own runs, so the disk cache is warm; the median is robust to one run slowed by the machine's load,
#: where the shortest would be biased low and leave start-up time in every render time)
STARTUP_PROBES = 3
#: the keys a renderer may report of itself: as string attributes of the EXR header or in ``<out>.json``
REPORTED_KEYS = ("render_seconds", "variance_dof")
#: start-up seconds measured per (renderer file, scene): once per process
_STARTUP: dict[tuple, tuple[float, str]] = {}
_REMEASURED: set[tuple] = set()


@dataclass
class _Runs:
    """What the runs of one render gave (:meth:`ExternalRenderer._runs`)."""

    images: list = field(default_factory=list)
    variance: np.ndarray | None = None
    wall: list = field(default_factory=list)
    reported: list = field(default_factory=list)
    seeds: list = field(default_factory=list)
    argvs: list = field(default_factory=list)


def reported_values(metadata: dict[str, str] | None, out: Path, name: str) -> dict[str, float | int]:
    """What a run reported of itself: ``render_seconds`` (seconds spent rendering, start-up excluded) and
    ``variance_dof`` (degrees of freedom of its variance channels), from the EXR's string header attributes or,
    for a key the header lacks, from the JSON file ``<out>.json`` beside it (``{out}`` with ".json" appended:
    ``render.exr.json``). A bad value raises :class:`ExternalRendererError` (the run's output is wrong, not the
    user's input)."""
    found: dict[str, object] = {k: v for k, v in (metadata or {}).items() if k in REPORTED_KEYS}
    side = Path(str(out) + ".json")
    if side.is_file() and any(k not in found for k in REPORTED_KEYS):
        try:
            doc = json.loads(side.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as err:
            raise ExternalRendererError(f"renderer {name!r} wrote an unreadable {side.name}: "
                                        f"{str(err).splitlines()[0] if str(err) else type(err).__name__}") from None
        if not isinstance(doc, dict):
            raise ExternalRendererError(f"renderer {name!r} wrote {side.name} holding {type(doc).__name__}; expected "
                                        'an object such as {"render_seconds": 1.5, "variance_dof": 63}')
        found.update({k: doc[k] for k in REPORTED_KEYS if k in doc and k not in found})
    out_values: dict[str, float | int] = {}
    for key, raw in found.items():
        try:
            number = float(raw) if not isinstance(raw, bool) else math.nan
        except (TypeError, ValueError):
            number = math.nan
        if key == "render_seconds":
            ok = math.isfinite(number) and number >= 0
            want = "a non-negative number of seconds"
        else:
            ok = math.isfinite(number) and number >= 1 and number == int(number)
            want = "a positive integer"
        if not ok:
            raise ExternalRendererError(f"renderer {name!r} reported {key} = {short(raw, 40)}; expected {want}")
        out_values[key] = number if key == "render_seconds" else int(number)
    return out_values


class ExternalRenderer:
    """A renderer run as an external command (see the module docstring)."""

    #: each run restarts a process: the studies do not repeat a render just to time it better
    cheap_to_repeat = False

    def __init__(self, spec: ExternalSpec):
        self.spec = spec
        self.name = spec.name

    def argv(self, values: dict[str, str]) -> list[str]:
        """The command with every placeholder replaced."""
        return [_PLACEHOLDER.sub(lambda m: values[m.group(1)], arg) for arg in self.spec.command]

    def _read(self, path: Path, scene: Scene):
        if not path.is_file():
            raise ExternalRendererError(f"renderer {self.name!r} exited with code 0 but wrote no EXR ({path.name})")
        try:
            exr = read_exr(path)
        except HarnessError as err:
            raise ExternalRendererError(f"renderer {self.name!r} wrote an unreadable EXR: {err.message}") from None
        want = (scene.film.height, scene.film.width)
        if exr.image.shape[:2] != want:
            raise ExternalRendererError(
                f"renderer {self.name!r} wrote a {exr.image.shape[1]}x{exr.image.shape[0]} EXR; expected "
                f"{want[1]}x{want[0]}")
        return exr

    def values(self, scene: Scene, request: RenderRequest, work: Path) -> dict[str, str]:
        """The placeholders of one render but ``{seed}`` and ``{out}``: the case's resolved ``scene`` (its film,
        depth and stress variant applied) exported into ``work`` in each format the command names, and only
        those (:data:`SCENE_EXPORTS`)."""
        named = {name for arg in self.spec.command for name in _PLACEHOLDER.findall(arg)}
        written: set[str] = set()
        values = {
            "scene_toml": str(Path(scene.path).resolve()),
            "spp": str(request.spp), "width": str(scene.film.width), "height": str(scene.film.height),
            "max_depth": str(scene.max_depth), "here": str(self.spec.path.parent), "python": sys.executable,
        }
        for placeholder, (fmt, folder, rel) in SCENE_EXPORTS.items():
            if placeholder not in named:
                continue
            if fmt not in written:
                (work / folder).mkdir()
                for name, data in scene_files(scene, fmt, spp=request.spp, seed=request.seed).items():
                    (work / folder / name).parent.mkdir(parents=True, exist_ok=True)
                    (work / folder / name).write_bytes(data)
                written.add(fmt)
            if placeholder == "mesh_dir":
                (work / folder / rel).mkdir(exist_ok=True)  # a scene without shapes still gets its (empty) folder
            values[placeholder] = str(work / folder / rel)
        return values

    def render(self, scene: Scene, request: RenderRequest) -> RenderResult:
        if request.settings:
            key = next(iter(request.settings))
            raise HarnessError(f"--set {key}", f"external renderer {self.name!r} takes no settings (put options in "
                               f"its command, {self.spec.path})")
        if request.spp < 1:
            raise HarnessError("--spp", f"expected a positive integer, got {request.spp}")
        runs = self._runs(scene, request, max_runs=None if request.variance else 1)
        seconds, time_from, startup = self._render_seconds(scene, runs)
        images, variance, seeds, argvs = runs.images, runs.variance, runs.seeds, runs.argvs
        width, height = scene.film.width, scene.film.height
        if variance is not None:
            image, var, spp = images[0], variance.astype(np.float64), request.spp
            dof = runs.reported[0].get("variance_dof", request.spp - 1)
            source = "the renderer's variance channels"
        elif len(images) == 1:  # the caller asked for no variance (RenderRequest.variance): one run, none estimated
            image, var, dof, spp = images[0], None, None, request.spp
            source = "none (one run: the caller uses no variance)"
        else:
            image, var, dof = combine_repeats(images)
            spp = request.spp * len(images)
            source = f"{len(images)} runs with independent seeds (sample variance / K, K - 1 dof)"
        info = {"command": argvs[0], "renderer_file": str(self.spec.path), "runs": len(images), "seeds": seeds,
                "variance_from": source, "variance_dof": dof, "spp_per_run": request.spp,
                "time_from": time_from, "wall_seconds": float(sum(runs.wall)), "startup_seconds": startup}
        return RenderResult(
            renderer=self.name, image=image.astype(np.float32),
            variance=None if var is None else var.astype(np.float32), seconds=seconds,
            spp=spp, rays={"camera": width * height * spp}, stats={"runs": len(images)},
            settings={"spp": request.spp, "seed": request.seed, "repeats": self.spec.repeats,
                      "timeout": self.spec.timeout, "command": list(self.spec.command)},
            info=info,
        )

    def _render_seconds(self, scene: Scene, runs: "_Runs") -> tuple[float, str, float | None]:
        """(render seconds of all runs, where they come from, the start-up subtracted or None): the renderer's own
        ``render_seconds`` where every run reported one, else each run's wall time less the start-up
        (:meth:`startup_seconds`), never below 0."""
        own = [r.get("render_seconds") for r in runs.reported]
        if all(v is not None for v in own):
            return float(sum(own)), "renderer", None
        startup, how = self.startup_seconds(scene)
        if min(runs.wall) < startup:  # a whole run took less than the start-up: the probes were slowed; once more
            startup, how = self.startup_seconds(scene, again=True)
        seconds = float(sum(max(wall - startup, 0.0) for wall in runs.wall))
        return seconds, f"start-up subtracted ({startup:.3g} s measured with {how})", startup

    def startup_seconds(self, scene: Scene, again: bool = False) -> tuple[float, str]:
        """The start-up of one run (process start, imports, scene loading, writing the EXR) on ``scene``, measured
        once per renderer and scene in this process: the median of :data:`STARTUP_PROBES` runs at 1 spp on a
        1 x 1 film of the same scene (one path of rendering, so the whole run is start-up), and how it was
        measured. Where the renderer cannot render a 1 x 1 film, 1-spp runs at the scene's film: their time
        includes one sample per pixel of rendering, so the render time left after subtracting it is a lower bound
        (and says so). ``again``: a run was faster than the start-up measured (the machine's load slowed the
        probes), so it is measured once more, once per renderer and scene, and the smaller median is kept."""
        key = (self.spec, str(getattr(scene, "path", "")), scene.name, scene.max_depth,
               (scene.film.width, scene.film.height))
        if again and key in _STARTUP and key not in _REMEASURED:
            _REMEASURED.add(key)
            first, how = _STARTUP.pop(key)
            second, how = self.startup_seconds(scene)
            _STARTUP[key] = (min(first, second), how + f"; measured twice ({first:.3g} s, {second:.3g} s): a run "
                             "was faster than the first, the smaller is kept")
        if key not in _STARTUP:
            tiny = dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=1, height=1))
            try:
                walls = [self._runs(tiny, RenderRequest(spp=1, seed=i), max_runs=1).wall[0]
                         for i in range(STARTUP_PROBES)]
                how = f"1-spp runs on a 1x1 film, the median of {STARTUP_PROBES}"
            except ExternalRendererError:
                walls = [self._runs(scene, RenderRequest(spp=1, seed=i), max_runs=1).wall[0]
                         for i in range(STARTUP_PROBES)]
                how = (f"1-spp runs at the scene's film, the median of {STARTUP_PROBES}: they include 1 spp of "
                       "rendering, so the time left is a lower bound")
            _STARTUP[key] = (float(np.median(walls)), how)
        return _STARTUP[key]

    def _runs(self, scene: Scene, request: RenderRequest, max_runs: int | None = None) -> "_Runs":
        """Run the command once, or ``repeats`` times (at most ``max_runs``) when its EXR has no variance channels:
        the images, the first EXR's variance, each run's wall time and what it reported of itself
        (:func:`reported_values`), the seeds and command lines."""
        with tempfile.TemporaryDirectory(prefix=f"harness-{self.name}-") as tmp:
            work = Path(tmp)
            values = self.values(scene, request, work)
            done = _Runs()
            runs = 1
            index = 0
            while index < runs:
                seed = fold_seed(request.seed) if index == 0 else repeat_seed(request.seed, index)
                out = work / f"render-{index}.exr"
                argv = self.argv(dict(values, seed=str(seed), out=str(out)))
                elapsed, _ = _run(argv, work, self.spec.timeout, self.name)
                exr = self._read(out, scene)
                done.wall.append(elapsed)
                done.reported.append(reported_values(exr.metadata, out, self.name))
                done.images.append(exr.image.astype(np.float64))
                done.seeds.append(seed)
                done.argvs.append(shlex.join(argv))
                if index == 0:
                    done.variance = exr.variance
                    runs = 1 if exr.variance is not None else min(self.spec.repeats, max_runs or self.spec.repeats)
                index += 1
                if request.progress is not None:
                    request.progress(index, runs)
        return done


# ---- finding renderers: renderer files by path or by name, and the ``harness.renderers`` entry points -------------

ENTRY_POINT_GROUP = "harness.renderers"
REPO_ROOT = Path(__file__).resolve().parents[2]


def looks_like_path(value: str) -> bool:
    """True if a --renderer value names a file rather than a renderer: it ends in .toml or holds a slash."""
    return value.endswith(".toml") or "/" in value or os.sep in value


def renderer_dirs(extra: tuple[Path, ...] = ()) -> list[Path]:
    """Folders whose ``NAME.toml`` files make NAME a renderer name: ``extra`` (e.g. beside a suite), then
    ``./renderers`` and the ``renderers/`` folder of this checkout."""
    out: list[Path] = []
    for folder in (*extra, Path.cwd() / "renderers", REPO_ROOT / "renderers"):
        folder = Path(folder).resolve()
        if folder not in out and folder.is_dir():
            out.append(folder)
    return out


def renderer_files(extra: tuple[Path, ...] = ()) -> dict[str, Path]:
    """``{name: path}`` of every ``renderers/NAME.toml`` (the first folder of :func:`renderer_dirs` wins)."""
    found: dict[str, Path] = {}
    for folder in renderer_dirs(extra):
        for path in sorted(folder.glob("*.toml")):
            found.setdefault(path.stem, path)
    return found


def entry_points() -> dict[str, object]:
    """``{name: EntryPoint}`` of the installed packages' ``harness.renderers`` entry points."""
    return {ep.name: ep for ep in _installed_entry_points()}


@functools.cache
def _installed_entry_points() -> tuple:
    # read once per process: each read walks every installed package's metadata (4-5 ms), and a suite asks per case
    return tuple(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP))


def resolve_path(value: str, bases: tuple[Path, ...] = ()) -> Path | None:
    """The renderer file a path-like ``value`` names: relative to each of ``bases`` first, then to the current
    folder; None if no such file exists."""
    candidates = [Path(base) / value for base in bases] + [Path(value)]
    return next((c.resolve() for c in candidates if c.is_file()), None)


def load_entry_point(name: str, ep) -> object:
    """Call the object an entry point names (a renderer class or a factory taking no arguments)."""
    try:
        renderer = ep.load()()
    except Exception as err:  # noqa: BLE001 - a broken plugin is the user's configuration
        raise HarnessError("--renderer", f"entry point {name!r} ({ep.value}) of group {ENTRY_POINT_GROUP} failed: "
                           f"{type(err).__name__}: {err}".splitlines()[0]) from None
    if not callable(getattr(renderer, "render", None)):
        raise HarnessError("--renderer", f"entry point {name!r} ({ep.value}) gave {renderer!r}, which has no "
                           "render(scene, request) method")
    if not getattr(renderer, "name", None):
        renderer.name = name
    return renderer


def find_renderer(name: str, bases: tuple[Path, ...] = ()):
    """A renderer file given by path, a ``renderers/NAME.toml``, or an entry point; None if ``name`` is none of
    these. A path that does not exist is a HarnessError."""
    if looks_like_path(name):
        path = resolve_path(name, bases)
        if path is None:
            raise HarnessError("--renderer", f"no renderer file {name!r}; expected a renderer name or the path of a "
                               "TOML file with command = [...] (docs/external-renderers.md)")
        return ExternalRenderer(load_spec(path))
    files = renderer_files(tuple(Path(b) / "renderers" for b in bases))
    if name in files:
        return ExternalRenderer(load_spec(files[name]))
    points = entry_points()
    if name in points:
        return load_entry_point(name, points[name])
    return None


def external_names(bases: tuple[Path, ...] = ()) -> list[str]:
    """Names of renderer files and entry points."""
    return sorted(set(renderer_files(tuple(Path(b) / "renderers" for b in bases))) | set(entry_points()))


def variance_metadata(result: RenderResult) -> dict[str, str]:
    """EXR metadata that tells the verdict the degrees of freedom of ``result.variance``: ``spp`` always, and
    ``variance_dof`` where it is not spp - 1 (K - 1 for K repeated runs; read by harness.running.compare)."""
    meta = {"spp": str(result.spp)}
    if result.info.get("variance_dof") is not None:
        meta["variance_dof"] = str(int(result.info["variance_dof"]))
    return meta
