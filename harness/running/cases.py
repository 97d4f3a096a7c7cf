"""The suite format: cases of (scene, renderer with settings, budget, what to compare against, thresholds), read
and checked by :func:`load_suite` before anything runs.

The file format is documented in ``docs/suites.md``. Judging one case is :mod:`harness.running.judge`, running a
whole suite :mod:`harness.running.schedule` (``harness run SUITE`` writes ``results.json``, schema in
``docs/results-schema.md``).
"""

from __future__ import annotations

import dataclasses
import math
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from harness.core.errors import HarnessError, read_user_toml
from harness.files.cases import slug  # the folder name of a case: files/cases.py reads them back
from harness.core.limits import MAX_FILM_SIDE, MAX_TIMEOUT_SECONDS, check_render_cost, film_problem, float_or_inf
from harness.core.text import hint, short
from harness.renderers import RenderRequest, external, get_renderer, renderer_names
from harness.running import generated_scenes, imported_scenes
from harness.running.tolerances import check_table
from harness.scene import load_scene
from harness.scene.load import find_scene
from harness.scene.typed_reader import PYTHON_PHRASING, TypedReader
from harness.scene.variants import check_variant_scene, parse_variant
from reference_impl import Film

SUITE_KEYS = ("name", "description", "defaults", "cases", "baseline")  # [baseline]: harness/running/tolerances.py
CASE_KEYS = (
    "name", "scene", "renderer", "settings", "spp", "seconds", "chunk_spp", "seed", "against", "film",
    "metrics", "thresholds", "expect", "alpha", "tile", "ground_truth_spp", "max_depth", "timeout",
    "variant", "requires", "studies",
)
DEFAULT_KEYS = tuple(k for k in CASE_KEYS if k not in ("name", "scene"))
AGAINST_KEYS = ("renderer", "spp", "seed", "settings")
AGAINST_KINDS = ("ground-truth", "closed-form", "mitsuba")
METRICS = ("rmse", "relmse", "mape", "psnr", "ssim", "flip", "bias")
HIGHER_IS_BETTER = ("psnr", "ssim")
EXPECT = ("pass", "fail")
MAX_NAME_LENGTH = 200  # a case name becomes a folder name (slug), and file systems allow 255 bytes
#: Unicode categories refused in case names: control and format characters (newlines, NUL, bidirectional
#: overrides), line and paragraph separators, surrogates. Names are printed one per line and become folder names.
UNSAFE_NAME_CATEGORIES = ("Cc", "Cf", "Zl", "Zp", "Cs")
MIN_SPP = 2  # the verdict needs each pixel's sample variance: one sample per pixel gives none
#: A suite judges the reference renderer's stratified sampler with its samples as this many independent replicates
#: (``--set replicates``), so that the variance it reports is unbiased rather than an upper bound
#: (docs/suites.md, "Honest variances"); a case that sets ``replicates`` or another sampler keeps its own.
SUITE_REPLICATES = 2


@dataclass(frozen=True)
class Against:
    """What a case's render is compared with: "ground-truth" (the scene's closed form, else Mitsuba),
    "closed-form", "mitsuba" (Mitsuba ground truth even where a closed form exists), or another renderer's render."""

    kind: str
    renderer: str | None = None
    spp: int | None = None
    seed: int = 1_000_003
    settings: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Case:
    name: str
    scene: Path
    renderer: str = "reference"
    settings: dict[str, str] = field(default_factory=dict)
    spp: int | None = 64
    seconds: float | None = None
    chunk_spp: int = 4
    seed: int = 0
    against: Against = Against("ground-truth")
    film: dict[str, int] | None = None
    max_depth: int | None = None
    metrics: tuple[str, ...] = METRICS
    thresholds: dict[str, float] = field(default_factory=dict)
    expect: str = "pass"
    alpha: float = 0.001
    tile: int = 8
    ground_truth_spp: int = 1024
    timeout: float | None = None  # seconds before a worker running the case is killed (None: derived, executors.py)
    variant: str | None = None  # a transformed scene (harness/scene/variants.py), e.g. "scale=1e3"
    requires: tuple[str, ...] = ()  # Mitsuba variants that must work here, else the case is skipped (REQUIREMENTS)
    studies: bool = True  # False: left out of the suite's studies (harness/studies/suite_studies.py)


@dataclass(frozen=True)
class Suite:
    name: str
    description: str
    path: Path
    cases: tuple[Case, ...]
    baseline: Any = field(default_factory=dict, compare=False)  # the [baseline] table (harness/running/tolerances.py)


# ---- loading ---------------------------------------------------------------------------------------------------


def load_suite(path: str | Path, cache_dir: str | Path | None = None) -> Suite:
    """Read and validate a suite file; every problem is a one-line HarnessError naming the file and key. A case's
    scene of another format (Mitsuba 3 XML, glTF 2.0) is imported and kept under ``cache_dir`` (default: the
    ground-truth cache's folder; :mod:`harness.running.imported_scenes`), and a generated one (``generated:NAME``)
    generated there once (:mod:`harness.running.generated_scenes`)."""
    path = Path(path)
    reader = TypedReader(str(path), PYTHON_PHRASING)
    doc = read_user_toml(path, missing="no such suite file")
    reader.check_keys(doc, SUITE_KEYS, "")
    name = reader.string(doc.get("name", path.stem), "name")
    description = reader.string(doc.get("description", ""), "description")
    defaults = reader.table(doc.get("defaults", {}), "defaults")
    reader.check_keys(defaults, DEFAULT_KEYS, "defaults")
    entries = reader.array(doc.get("cases", []), "cases")
    if not entries:
        raise reader.error("cases", "expected at least one [[cases]] entry")
    baseline = doc.get("baseline", {})
    if "baseline" in doc:  # checked with or without --baseline: a broken table is an error now, not at a later gate
        check_table(reader.label, baseline)
    cases, names, folders, scenes = [], set(), {}, {}
    known = renderer_names()  # once per suite: it reads every installed package's entry points (2 ms)
    for i, entry in enumerate(entries):
        where = f"cases[{i}]"
        entry = reader.table(entry, where)
        reader.check_keys(entry, CASE_KEYS, where)
        merged = {**defaults, **entry}
        case = _case(reader, path.parent, where, merged, known, cache_dir)
        if case.name in names:
            raise reader.error(f"{where}.name", f"duplicate case name {short(case.name)}")
        _check_folder_unique(reader, where, case.name, folders)
        _check_case_cost(reader, where, case, scenes)
        _check_case_variant(reader, where, case, scenes[case.scene])
        _check_case_settings(reader, where, case, with_case_overrides(scenes[case.scene], case))
        names.add(case.name)
        cases.append(case)
    if "settings" in defaults and all("settings" in entry for entry in entries):
        _check_unused_default_settings(reader, path.parent, defaults, entries[0], known, cache_dir)
    return Suite(name, description, path, tuple(cases), baseline)


def _check_unused_default_settings(reader: TypedReader, folder: Path, defaults: dict, entry: dict, known,
                                   cache_dir: str | Path | None = None) -> None:
    """``defaults.settings`` that every case replaces with its own, checked all the same (as the first case would
    use them), so that a typo there is one line naming ``defaults.settings.KEY`` rather than silently unused."""
    merged = {**defaults, **{k: v for k, v in entry.items() if k != "settings"}}
    case = _case(reader, folder, "defaults", merged, known, cache_dir)
    scenes: dict = {}
    _check_case_cost(reader, "defaults", case, scenes)
    _check_case_settings(reader, "defaults", case, with_case_overrides(scenes[case.scene], case))


def _case(reader: TypedReader, folder: Path, where: str, d: dict[str, Any], known: list[str],
          cache_dir: str | Path | None = None) -> Case:
    """One case of a suite; ``known``: the renderer names (:func:`harness.renderers.renderer_names`); a scene of
    another format imported under ``cache_dir`` (:func:`harness.running.imported_scenes.scene_file`)."""

    def key(k: str) -> str:
        return f"{where}.{k}"

    if "scene" not in d:
        raise reader.error(key("scene"), "missing: expected a scene name or a path to a scene file")
    value = reader.string(d["scene"], key("scene"))
    if generated_scenes.is_generated(value):
        scene = source = generated_scenes.scene_file(value, reader.where(key("scene")), cache_dir)
        stem = value[len("generated:"):].partition("?")[0]
    else:
        source = find_scene(value, reader.where(key("scene")), folder)
        scene = imported_scenes.scene_file(source, cache_dir) if imported_scenes.is_foreign(source) else source
        stem = source.stem
    name = _case_name(reader, key("name"), d.get("name", stem), "name" not in d)
    renderer = reader.string(d.get("renderer", "reference"), key("renderer"))
    renderer = _renderer_known(reader, key("renderer"), renderer, known, folder)
    settings = judged_settings(renderer, _settings(reader, key("settings"), d.get("settings", {})))
    spp = d.get("spp", None if "seconds" in d else 64)
    seconds = d.get("seconds")
    if spp is not None and seconds is not None:
        raise reader.error(where, "give a budget as spp or as seconds, not both")
    if spp is not None:
        spp = _at_least_two(reader, key("spp"), spp)
    if seconds is not None:
        seconds = float(reader.positive(seconds, key("seconds")))
    against = _against(reader, key("against"), d.get("against", "ground-truth"), known, folder)
    film = d.get("film")
    if film is not None:
        film = reader.table(film, key("film"))
        reader.check_keys(film, ("width", "height"), key("film"))
        film = {k: reader.positive(v, f"{key('film')}.{k}", integer=True) for k, v in film.items()}
    max_depth = d.get("max_depth")
    if max_depth is not None:
        max_depth = reader.integer(max_depth, key("max_depth"))
        if max_depth < 1 and max_depth != -1:
            raise reader.error(key("max_depth"), f"expected a positive integer or -1, got {max_depth}")
    metrics = tuple(reader.array(d.get("metrics", list(METRICS)), key("metrics")))
    for m in metrics:
        if m not in METRICS:
            raise reader.error(key("metrics"), f"unknown metric {m!r}{hint(m, METRICS)}")
    thresholds = reader.table(d.get("thresholds", {}), key("thresholds"))
    for m, v in thresholds.items():
        _threshold(reader, reader.join(key("thresholds"), m), m, v)
    expect = reader.string(d.get("expect", "pass"), key("expect"))
    if expect not in EXPECT:
        raise reader.error(key("expect"), f"expected 'pass' or 'fail', got {expect!r}")
    alpha = float(reader.numeric(d.get("alpha", 0.001), key("alpha")))
    if not 0 < alpha < 1:
        raise reader.error(key("alpha"), f"expected a probability in (0, 1), got {alpha}")
    return Case(
        name=name, scene=scene, renderer=renderer, settings=settings, spp=spp, seconds=seconds,
        chunk_spp=reader.positive(d.get("chunk_spp", 4), key("chunk_spp"), integer=True),
        seed=reader.non_negative(d.get("seed", 0), key("seed")), against=against, film=film, max_depth=max_depth,
        metrics=metrics,
        thresholds={k: float(v) for k, v in thresholds.items()}, expect=expect, alpha=alpha,
        tile=_tile(reader, key("tile"), d.get("tile", 8)),
        ground_truth_spp=_at_least_two(reader, key("ground_truth_spp"), d.get("ground_truth_spp", 1024)),
        timeout=(None if d.get("timeout") is None else _timeout(reader, key("timeout"), d["timeout"])),
        variant=_stress_variant(reader, key("variant"), d.get("variant")),
        requires=_requires(reader, key("requires"), d.get("requires", [])),
        studies=reader.boolean(d.get("studies", True), key("studies")),
    )


#: what a case may require (``requires``): a Mitsuba variant, usable where the harness runs (cuda_ad_rgb needs a
#: working CUDA GPU, llvm_ad_rgb a libLLVM >= 16); where one is not, the case is skipped with the reason
REQUIREMENTS = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")


def _requires(reader: TypedReader, key: str, value: Any) -> tuple[str, ...]:
    """A case's ``requires``: a list of :data:`REQUIREMENTS` (a single string is taken as a list of one)."""
    items = [value] if isinstance(value, str) else reader.array(value, key)
    out = []
    for i, item in enumerate(items):
        item = reader.string(item, f"{key}[{i}]")
        if item not in REQUIREMENTS:
            raise reader.error(f"{key}[{i}]", f"unknown requirement {short(item)}{hint(item, REQUIREMENTS)}; "
                               f"expected one of {', '.join(REQUIREMENTS)} (a Mitsuba variant that must work here)")
        out.append(item)
    return tuple(dict.fromkeys(out))


def _timeout(reader: TypedReader, key: str, value: Any) -> float:
    """A case's ``timeout`` in seconds: positive, at most a week (1e308 s overflowed the OS's timeout)."""
    value = reader.positive(value, key)
    if not value <= MAX_TIMEOUT_SECONDS:
        raise reader.expected(key, f"at most {MAX_TIMEOUT_SECONDS:g} seconds (a week)", value)
    return float(value)


def _case_name(reader: TypedReader, key: str, value: Any, default: bool) -> str:
    """A case's name, checked: it is printed on one line and becomes a folder name (:func:`slug`), so it has 1 to
    ``MAX_NAME_LENGTH`` characters, not only spaces, none of ``UNSAFE_NAME_CATEGORIES``, and is not "." or ".."."""
    name = reader.string(value, key)
    whose = " (the default: the scene file's name)" if default else ""
    if not name.strip():
        raise reader.error(key, f"expected a non-empty name, got {name!r}")
    if len(name) > MAX_NAME_LENGTH:
        raise reader.error(key, f"expected at most {MAX_NAME_LENGTH} characters, got {len(name)}{whose}: "
                           f"{short(name)}")
    bad = next((ch for ch in name if unicodedata.category(ch) in UNSAFE_NAME_CATEGORIES), None)
    if bad is not None:
        raise reader.error(key, f"expected no control or format characters, got {bad!r} "
                           f"(U+{ord(bad):04X}) in {short(name)}{whose}")
    if name in (".", ".."):
        raise reader.error(key, f"expected a name that is not {name!r} (a case's folder is named after "
                           "it)")
    return name


def _check_folder_unique(reader: TypedReader, where: str, name: str, folders: dict[str, tuple[str, str]]) -> None:
    """Refuse a case whose folder (``cases/`` + :func:`slug`) is another case's: the second would overwrite the
    first's render. Compared without case, so that the suite runs the same on case-insensitive file systems."""
    folder = slug(name)
    other = folders.get(folder.casefold())
    if other is not None:
        raise reader.error(f"{where}.name", (
            f"{short(name)} and {other[0]}.name {short(other[1])} both map to the folder cases/{folder} (each run "
            "of characters other than A-Z a-z 0-9 . _ - becomes _, and case is ignored); rename one"))
    folders[folder.casefold()] = (where, name)


def _threshold(reader: TypedReader, key: str, metric: Any, value: Any) -> float:
    """A ``thresholds`` entry, checked: a known metric and a finite bound that can be met (error metrics are >= 0,
    so a negative upper bound fails every render; ssim is at most 1)."""
    if metric not in METRICS:
        raise reader.error(key, f"unknown metric{hint(metric, METRICS)}")
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(float_or_inf(value)):
        raise reader.expected(key, "a finite number", value)
    if metric not in HIGHER_IS_BETTER and value < 0:
        raise reader.error(key, f"expected an upper bound >= 0 ({metric} is never negative), got {value}")
    if metric == "ssim" and value > 1:
        raise reader.error(key, f"expected a lower bound <= 1 (ssim is at most 1), got {value}")
    return float(value)


def _stress_variant(reader: TypedReader, key: str, value: Any) -> str | None:
    """A case's ``variant`` (harness/scene/variants.py), normalised (``scale=1000`` -> ``scale=1e3``), or None."""
    if value is None:
        return None
    return parse_variant(reader.string(value, key), reader.where(key)).name


MAX_TILE = 1024  # the verdict pads the image to whole tiles: a larger tile only costs memory


def _tile(reader: TypedReader, key: str, value: Any) -> int:
    value = reader.positive(value, key, integer=True)
    if value > MAX_TILE:
        raise reader.error(key, f"expected a tile side from 1 to {MAX_TILE} pixels, got {value}")
    return value


def _check_case_cost(reader: TypedReader, where: str, case: Case, scenes: dict) -> None:
    """Load the case's scene (once per suite: its problems are one line naming the scene file, before anything
    runs) and refuse a film or budget whose memory or time estimate is absurd (harness/core/limits.py)."""
    if case.scene not in scenes:
        scenes[case.scene] = load_scene(case.scene)
    scene = scenes[case.scene]
    film = case.film or {}
    width, height = film.get("width", scene.film.width), film.get("height", scene.film.height)
    film_where = reader.where(f"{where}.film") if film else f"{scene.path}: film"
    film_keys = f"{where}.film" if film else f"film.width / film.height in {scene.path}"
    if max(width, height) > MAX_FILM_SIDE:
        raise HarnessError(film_where, f"expected at most {MAX_FILM_SIDE} pixels per side, got {width} x {height}; "
                           f"lower {film_keys}")
    problem = film_problem(width, height)
    if problem:
        raise HarnessError(film_where, f"{problem}; lower {film_keys}")
    budgets = [(case.spp, case.seconds, "spp" if case.seconds is None else "seconds")]
    if case.against.kind == "renderer":
        budgets.append((case.against.spp, None, "against.spp"))
    # checked where it is not used too (a closed-form scene, against a renderer): an absurd value is a typo all the same
    budgets.append((case.ground_truth_spp, None, "ground_truth_spp"))
    for spp, seconds, key in budgets:
        check_render_cost(width, height, spp, seconds=seconds, film_where=film_where,
                          spp_where=reader.where(f"{where}.{key}"), film_keys=film_keys, spp_name=f"{where}.{key}",
                          envmap=scene.envmap_size, envmap_where=scene.envmap_key)


def _check_case_variant(reader: TypedReader, where: str, case: Case, scene) -> None:
    """Apply a case's stress ``variant`` to its (loaded) scene now: a variant the scene cannot have (no light, no
    rectangle) or one that gives an invalid scene is one line naming ``cases[i].variant`` before anything runs."""
    if case.variant is None:
        return
    try:
        check_variant_scene(parse_variant(case.variant).apply(with_case_overrides(scene, case)))
    except HarnessError as err:
        message = err.message if err.message.startswith("variant ") else f"variant {case.variant}: {err.message}"
        raise reader.error(f"{where}.variant", f"on {scene.path}: {message}") from None


def _check_case_settings(reader: TypedReader, where: str, case: Case, scene) -> None:
    """Let the built-in renderers check a case's settings (and its comparison render's) before anything runs: a bad
    one is a one-line error naming the suite file and the key, not a failure halfway through the run."""
    requests = [(case.renderer, case.settings, case.spp if case.seconds is None else case.chunk_spp, f"{where}.settings")]
    if case.against.kind == "renderer":
        requests.append((case.against.renderer, case.against.settings, case.against.spp, f"{where}.against.settings"))
    for name, settings, spp, key in requests:
        check = getattr(get_renderer(name), "check", None) if name in ("reference", "mitsuba") else None
        if check is None or spp is None:
            continue
        try:
            check(scene, RenderRequest(spp=spp, seed=case.seed, settings=dict(settings)))
        except HarnessError as err:
            if not err.where.startswith("--set "):
                raise
            raise reader.error(f"{key}.{err.where[len('--set '):]}", err.message) from None


def _against(reader: TypedReader, key: str, value: Any, renderers: list[str], folder: Path | None = None) -> Against:
    if isinstance(value, str):
        if value not in AGAINST_KINDS:
            raise reader.error(key, f"expected one of {', '.join(AGAINST_KINDS)} or a table "
                               f"{{renderer = ..., spp = ...}}, got {value!r}{hint(value, AGAINST_KINDS)}")
        return Against(value)
    table = reader.table(value, key)
    reader.check_keys(table, AGAINST_KEYS, key)
    if "renderer" not in table:
        raise reader.error(f"{key}.renderer", "missing: expected the name of the renderer to compare with")
    renderer = reader.string(table["renderer"], f"{key}.renderer")
    renderer = _renderer_known(reader, f"{key}.renderer", renderer, renderers, folder)
    spp = reader.positive(table.get("spp", 256), f"{key}.spp", integer=True)
    if spp < 2:
        raise reader.error(f"{key}.spp", f"expected at least 2 (the reference render's variance comes from "
                           f"its samples; one sample per pixel gives none), got {spp}")
    settings = _settings(reader, f"{key}.settings", table.get("settings", {}))
    extra = sorted(set(settings) - {"variant"}) if renderer == "mitsuba" else []
    if extra:  # a Mitsuba render to judge against goes through the ground-truth cache, which keys the variant only
        raise reader.error(reader.join(f"{key}.settings", extra[0]), "a Mitsuba render compared against "
                           "takes only variant (it is rendered through the ground-truth cache, with the moment "
                           "integrator and the independent sampler)")
    return Against(
        "renderer", renderer, spp,
        reader.non_negative(table.get("seed", 1_000_003), f"{key}.seed"),
        judged_settings(renderer, settings),
    )


def judged_settings(renderer: str, settings: dict[str, str]) -> dict[str, str]:
    """A case's renderer settings as the suite runs them: the reference's stratified sampler with
    :data:`SUITE_REPLICATES` replicates unless the case says otherwise (another sampler, or ``replicates``)."""
    if renderer != "reference" or "replicates" in settings or settings.get("sampler", "sobol") != "sobol":
        return settings
    return {**settings, "replicates": str(SUITE_REPLICATES)}


def _renderer_known(reader: TypedReader, key: str, name: str, known: list[str], folder: Path | None = None) -> str:
    """The renderer a case names: a known name, or the absolute path of a renderer file given relative to the
    suite's folder (or the current one); a file is validated now (harness.renderers.external)."""
    if external.looks_like_path(name):
        try:
            path = external.resolve_path(name, (folder,) if folder is not None else ())
        except OSError as err:  # a name too long for the file system, a loop of symbolic links, ...
            raise reader.error(key, f"cannot look for the renderer file {short(name)}: "
                               f"{err.strerror or err}") from None
        if path is None:
            raise reader.error(key, f"no renderer file {short(name)} (relative to {folder or '.'})")
        external.load_spec(path)
        return str(path)
    if name not in known:
        raise reader.error(key, f"unknown renderer {name!r}{hint(name, known)} (known: {', '.join(known)})")
    files = external.renderer_files()
    if name in files:
        external.load_spec(files[name])
    return name


def _settings(reader: TypedReader, key: str, value: Any) -> dict[str, str]:
    table = reader.table(value, key)
    out = {}
    for k, v in table.items():
        if isinstance(v, (dict, list)):
            raise reader.expected(reader.join(key, k), "a string or number", v)
        out[str(k)] = str(v).lower() if isinstance(v, bool) else str(v)
    return out


def _at_least_two(reader: TypedReader, key: str, value: Any) -> int:
    """A sample count the verdict can use: an integer >= ``MIN_SPP``."""
    value = reader.positive(value, key, integer=True)
    if value < MIN_SPP:
        raise reader.error(key, f"expected >= {MIN_SPP} (the verdict needs each pixel's sample variance; "
                           f"one sample per pixel gives none), got {value}")
    return value


# ---- a case's folder and scene ---------------------------------------------------------------------------------


def with_case_overrides(scene, case: Case):
    """The scene with the case's ``film`` and ``max_depth`` overrides."""
    if case.film:
        film = Film(case.film.get("width", scene.film.width), case.film.get("height", scene.film.height),
                    scene.film.filter)
        scene = dataclasses.replace(scene, film=film)
    if case.max_depth is not None:  # the scene's own depth, so the ground truth and the render agree
        scene = dataclasses.replace(scene, max_depth=case.max_depth)
    return scene
