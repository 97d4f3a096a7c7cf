"""The suite format: cases of (scene, renderer with settings, budget, what to compare against, thresholds), read
and checked by :func:`load_suite` before anything runs.

The file format is documented in ``docs/suites.md``. Judging one case is :mod:`harness.running.judge`, running a
whole suite :mod:`harness.running.schedule` (``harness run SUITE`` writes ``results.json``, schema in
``docs/results-schema.md``).
"""

from __future__ import annotations

import dataclasses
import math
import re
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from harness.core.errors import HarnessError, read_user_toml
from harness.files.cases import slug  # the folder name of a case: files/cases.py reads them back
from harness.core.limits import MAX_FILM_SIDE, MAX_TIMEOUT_SECONDS, check_render_cost, film_problem, float_or_inf
from harness.core.text import hint, short, toml_key
from harness.renderers import RenderRequest, external, get_renderer, renderer_names
from harness.running.tolerances import check_table
from harness.scene import load_scene
from harness.scene.load import find_scene
from harness.scene.variants import check_variant_scene, parse_variant
from reference_impl import Film

SUITE_KEYS = ("name", "description", "defaults", "cases", "baseline")  # [baseline]: harness/running/tolerances.py
CASE_KEYS = (
    "name", "scene", "renderer", "settings", "spp", "seconds", "chunk_spp", "seed", "against", "film",
    "metrics", "thresholds", "expect", "alpha", "tile", "ground_truth_spp", "max_depth", "timeout",
    "variant", "requires",
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


@dataclass(frozen=True)
class Suite:
    name: str
    description: str
    path: Path
    cases: tuple[Case, ...]
    baseline: Any = field(default_factory=dict, compare=False)  # the [baseline] table (harness/running/tolerances.py)


# ---- loading ---------------------------------------------------------------------------------------------------


def load_suite(path: str | Path) -> Suite:
    """Read and validate a suite file; every problem is a one-line HarnessError naming the file and key."""
    path = Path(path)
    label = str(path)
    doc = read_user_toml(path, missing="no such suite file")
    _check_keys(label, doc, SUITE_KEYS, "")
    name = _typed(label, "name", doc.get("name", path.stem), str)
    description = _typed(label, "description", doc.get("description", ""), str)
    defaults = _typed(label, "defaults", doc.get("defaults", {}), dict)
    _check_keys(label, defaults, DEFAULT_KEYS, "defaults")
    entries = _typed(label, "cases", doc.get("cases", []), list)
    if not entries:
        raise HarnessError(f"{label}: cases", "expected at least one [[cases]] entry")
    baseline = doc.get("baseline", {})
    if "baseline" in doc:  # checked with or without --baseline: a broken table is an error now, not at a later gate
        check_table(label, baseline)
    cases, names, folders, scenes = [], set(), {}, {}
    known = renderer_names()  # once per suite: it reads every installed package's entry points (2 ms)
    for i, entry in enumerate(entries):
        where = f"cases[{i}]"
        entry = _typed(label, where, entry, dict)
        _check_keys(label, entry, CASE_KEYS, where)
        merged = {**defaults, **entry}
        case = _case(label, path.parent, where, merged, known)
        if case.name in names:
            raise HarnessError(f"{label}: {where}.name", f"duplicate case name {short(case.name)}")
        _check_folder_unique(label, where, case.name, folders)
        _check_case_cost(label, where, case, scenes)
        _check_case_variant(label, where, case, scenes[case.scene])
        _check_case_settings(label, where, case, with_case_overrides(scenes[case.scene], case))
        names.add(case.name)
        cases.append(case)
    if "settings" in defaults and all("settings" in entry for entry in entries):
        _check_unused_default_settings(label, path.parent, defaults, entries[0], known)
    return Suite(name, description, path, tuple(cases), baseline)


def _check_unused_default_settings(label: str, folder: Path, defaults: dict, entry: dict, known) -> None:
    """``defaults.settings`` that every case replaces with its own, checked all the same (as the first case would
    use them), so that a typo there is one line naming ``defaults.settings.KEY`` rather than silently unused."""
    merged = {**defaults, **{k: v for k, v in entry.items() if k != "settings"}}
    case = _case(label, folder, "defaults", merged, known)
    scenes: dict = {}
    _check_case_cost(label, "defaults", case, scenes)
    _check_case_settings(label, "defaults", case, with_case_overrides(scenes[case.scene], case))


def _case(label: str, folder: Path, where: str, d: dict[str, Any], known: list[str]) -> Case:
    """One case of a suite; ``known``: the renderer names (:func:`harness.renderers.renderer_names`)."""

    def key(k: str) -> str:
        return f"{where}.{k}"

    if "scene" not in d:
        raise HarnessError(f"{label}: {key('scene')}", "missing: expected a scene name or a path to a scene file")
    scene = find_scene(_typed(label, key("scene"), d["scene"], str), f"{label}: {key('scene')}", folder)
    name = _case_name(label, key("name"), d.get("name", scene.stem), "name" not in d)
    renderer = _typed(label, key("renderer"), d.get("renderer", "reference"), str)
    renderer = _renderer_known(label, key("renderer"), renderer, known, folder)
    settings = judged_settings(renderer, _settings(label, key("settings"), d.get("settings", {})))
    spp = d.get("spp", None if "seconds" in d else 64)
    seconds = d.get("seconds")
    if spp is not None and seconds is not None:
        raise HarnessError(f"{label}: {where}", "give a budget as spp or as seconds, not both")
    if spp is not None:
        spp = _at_least_two(label, key("spp"), spp)
    if seconds is not None:
        seconds = float(_positive(label, key("seconds"), seconds, (int, float)))
    against = _against(label, key("against"), d.get("against", "ground-truth"), known, folder)
    film = d.get("film")
    if film is not None:
        film = _typed(label, key("film"), film, dict)
        _check_keys(label, film, ("width", "height"), key("film"))
        film = {k: _positive(label, f"{key('film')}.{k}", v, int) for k, v in film.items()}
    max_depth = d.get("max_depth")
    if max_depth is not None:
        max_depth = _typed(label, key("max_depth"), max_depth, int)
        if max_depth < 1 and max_depth != -1:
            raise HarnessError(f"{label}: {key('max_depth')}", f"expected a positive integer or -1, got {max_depth}")
    metrics = tuple(_typed(label, key("metrics"), d.get("metrics", list(METRICS)), list))
    for m in metrics:
        if m not in METRICS:
            raise HarnessError(f"{label}: {key('metrics')}", f"unknown metric {m!r}{hint(m, METRICS)}")
    thresholds = _typed(label, key("thresholds"), d.get("thresholds", {}), dict)
    for m, v in thresholds.items():
        _threshold(label, f"{key('thresholds')}.{toml_key(m)}", m, v)
    expect = _typed(label, key("expect"), d.get("expect", "pass"), str)
    if expect not in EXPECT:
        raise HarnessError(f"{label}: {key('expect')}", f"expected 'pass' or 'fail', got {expect!r}")
    alpha = float(_typed(label, key("alpha"), d.get("alpha", 0.001), (int, float)))
    if not 0 < alpha < 1:
        raise HarnessError(f"{label}: {key('alpha')}", f"expected a probability in (0, 1), got {alpha}")
    return Case(
        name=name, scene=scene, renderer=renderer, settings=settings, spp=spp, seconds=seconds,
        chunk_spp=_positive(label, key("chunk_spp"), d.get("chunk_spp", 4), int),
        seed=_non_negative(label, key("seed"), d.get("seed", 0)), against=against, film=film, max_depth=max_depth,
        metrics=metrics,
        thresholds={k: float(v) for k, v in thresholds.items()}, expect=expect, alpha=alpha,
        tile=_tile(label, key("tile"), d.get("tile", 8)),
        ground_truth_spp=_at_least_two(label, key("ground_truth_spp"), d.get("ground_truth_spp", 1024)),
        timeout=(None if d.get("timeout") is None else _timeout(label, key("timeout"), d["timeout"])),
        variant=_stress_variant(label, key("variant"), d.get("variant")),
        requires=_requires(label, key("requires"), d.get("requires", [])),
    )


#: what a case may require (``requires``): a Mitsuba variant, usable where the harness runs (cuda_ad_rgb needs a
#: working CUDA GPU, llvm_ad_rgb a libLLVM >= 16); where one is not, the case is skipped with the reason
REQUIREMENTS = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")


def _requires(label: str, key: str, value: Any) -> tuple[str, ...]:
    """A case's ``requires``: a list of :data:`REQUIREMENTS` (a single string is taken as a list of one)."""
    items = [value] if isinstance(value, str) else _typed(label, key, value, list)
    out = []
    for i, item in enumerate(items):
        item = _typed(label, f"{key}[{i}]", item, str)
        if item not in REQUIREMENTS:
            raise HarnessError(f"{label}: {key}[{i}]", f"unknown requirement {short(item)}{hint(item, REQUIREMENTS)}; "
                               f"expected one of {', '.join(REQUIREMENTS)} (a Mitsuba variant that must work here)")
        out.append(item)
    return tuple(dict.fromkeys(out))


def _timeout(label: str, key: str, value: Any) -> float:
    """A case's ``timeout`` in seconds: positive, at most a week (1e308 s overflowed the OS's timeout)."""
    value = _positive(label, key, value, (int, float))
    if not value <= MAX_TIMEOUT_SECONDS:
        raise HarnessError(f"{label}: {key}",
                           f"expected at most {MAX_TIMEOUT_SECONDS:g} seconds (a week), got {short(value)}")
    return float(value)


def _case_name(label: str, key: str, value: Any, default: bool) -> str:
    """A case's name, checked: it is printed on one line and becomes a folder name (:func:`slug`), so it has 1 to
    ``MAX_NAME_LENGTH`` characters, not only spaces, none of ``UNSAFE_NAME_CATEGORIES``, and is not "." or ".."."""
    name = _typed(label, key, value, str)
    whose = " (the default: the scene file's name)" if default else ""
    if not name.strip():
        raise HarnessError(f"{label}: {key}", f"expected a non-empty name, got {name!r}")
    if len(name) > MAX_NAME_LENGTH:
        raise HarnessError(f"{label}: {key}", f"expected at most {MAX_NAME_LENGTH} characters, got {len(name)}{whose}: "
                           f"{short(name)}")
    bad = next((ch for ch in name if unicodedata.category(ch) in UNSAFE_NAME_CATEGORIES), None)
    if bad is not None:
        raise HarnessError(f"{label}: {key}", f"expected no control or format characters, got {bad!r} "
                           f"(U+{ord(bad):04X}) in {short(name)}{whose}")
    if name in (".", ".."):
        raise HarnessError(f"{label}: {key}", f"expected a name that is not {name!r} (a case's folder is named after "
                           "it)")
    return name


def _check_folder_unique(label: str, where: str, name: str, folders: dict[str, tuple[str, str]]) -> None:
    """Refuse a case whose folder (``cases/`` + :func:`slug`) is another case's: the second would overwrite the
    first's render. Compared without case, so that the suite runs the same on case-insensitive file systems."""
    folder = slug(name)
    other = folders.get(folder.casefold())
    if other is not None:
        raise HarnessError(f"{label}: {where}.name", (
            f"{short(name)} and {other[0]}.name {short(other[1])} both map to the folder cases/{folder} (each run "
            "of characters other than A-Z a-z 0-9 . _ - becomes _, and case is ignored); rename one"))
    folders[folder.casefold()] = (where, name)


def _threshold(label: str, key: str, metric: Any, value: Any) -> float:
    """A ``thresholds`` entry, checked: a known metric and a finite bound that can be met (error metrics are >= 0,
    so a negative upper bound fails every render; ssim is at most 1)."""
    if metric not in METRICS:
        raise HarnessError(f"{label}: {key}", f"unknown metric{hint(metric, METRICS)}")
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(float_or_inf(value)):
        raise HarnessError(f"{label}: {key}", f"expected a finite number, got {short(value)}")
    if metric not in HIGHER_IS_BETTER and value < 0:
        raise HarnessError(f"{label}: {key}", f"expected an upper bound >= 0 ({metric} is never negative), got {value}")
    if metric == "ssim" and value > 1:
        raise HarnessError(f"{label}: {key}", f"expected a lower bound <= 1 (ssim is at most 1), got {value}")
    return float(value)


def _stress_variant(label: str, key: str, value: Any) -> str | None:
    """A case's ``variant`` (harness/scene/variants.py), normalised (``scale=1000`` -> ``scale=1e3``), or None."""
    if value is None:
        return None
    return parse_variant(_typed(label, key, value, str), f"{label}: {key}").name


MAX_TILE = 1024  # the verdict pads the image to whole tiles: a larger tile only costs memory


def _tile(label: str, key: str, value: Any) -> int:
    value = _positive(label, key, value, int)
    if value > MAX_TILE:
        raise HarnessError(f"{label}: {key}", f"expected a tile side from 1 to {MAX_TILE} pixels, got {value}")
    return value


def _check_case_cost(label: str, where: str, case: Case, scenes: dict) -> None:
    """Load the case's scene (once per suite: its problems are one line naming the scene file, before anything
    runs) and refuse a film or budget whose memory or time estimate is absurd (harness/core/limits.py)."""
    if case.scene not in scenes:
        scenes[case.scene] = load_scene(case.scene)
    scene = scenes[case.scene]
    film = case.film or {}
    width, height = film.get("width", scene.film.width), film.get("height", scene.film.height)
    film_where = f"{label}: {where}.film" if film else f"{scene.path}: film"
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
                          spp_where=f"{label}: {where}.{key}", film_keys=film_keys, spp_name=f"{where}.{key}",
                          envmap=scene.envmap_size, envmap_where=scene.envmap_key)


def _check_case_variant(label: str, where: str, case: Case, scene) -> None:
    """Apply a case's stress ``variant`` to its (loaded) scene now: a variant the scene cannot have (no light, no
    rectangle) or one that gives an invalid scene is one line naming ``cases[i].variant`` before anything runs."""
    if case.variant is None:
        return
    try:
        check_variant_scene(parse_variant(case.variant).apply(with_case_overrides(scene, case)))
    except HarnessError as err:
        message = err.message if err.message.startswith("variant ") else f"variant {case.variant}: {err.message}"
        raise HarnessError(f"{label}: {where}.variant", f"on {scene.path}: {message}") from None


def _check_case_settings(label: str, where: str, case: Case, scene) -> None:
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
            raise HarnessError(f"{label}: {key}.{err.where[len('--set '):]}", err.message) from None


def _against(label: str, key: str, value: Any, renderers: list[str], folder: Path | None = None) -> Against:
    if isinstance(value, str):
        if value not in AGAINST_KINDS:
            raise HarnessError(f"{label}: {key}", f"expected one of {', '.join(AGAINST_KINDS)} or a table "
                               f"{{renderer = ..., spp = ...}}, got {value!r}{hint(value, AGAINST_KINDS)}")
        return Against(value)
    table = _typed(label, key, value, dict)
    _check_keys(label, table, AGAINST_KEYS, key)
    if "renderer" not in table:
        raise HarnessError(f"{label}: {key}.renderer", "missing: expected the name of the renderer to compare with")
    renderer = _typed(label, f"{key}.renderer", table["renderer"], str)
    renderer = _renderer_known(label, f"{key}.renderer", renderer, renderers, folder)
    spp = _positive(label, f"{key}.spp", table.get("spp", 256), int)
    if spp < 2:
        raise HarnessError(f"{label}: {key}.spp", f"expected at least 2 (the reference render's variance comes from "
                           f"its samples; one sample per pixel gives none), got {spp}")
    settings = _settings(label, f"{key}.settings", table.get("settings", {}))
    extra = sorted(set(settings) - {"variant"}) if renderer == "mitsuba" else []
    if extra:  # a Mitsuba render to judge against goes through the ground-truth cache, which keys the variant only
        raise HarnessError(f"{label}: {key}.settings.{toml_key(extra[0])}", "a Mitsuba render compared against "
                           "takes only variant (it is rendered through the ground-truth cache, with the moment "
                           "integrator and the independent sampler)")
    return Against(
        "renderer", renderer, spp,
        _non_negative(label, f"{key}.seed", table.get("seed", 1_000_003)),
        judged_settings(renderer, settings),
    )


def judged_settings(renderer: str, settings: dict[str, str]) -> dict[str, str]:
    """A case's renderer settings as the suite runs them: the reference's stratified sampler with
    :data:`SUITE_REPLICATES` replicates unless the case says otherwise (another sampler, or ``replicates``)."""
    if renderer != "reference" or "replicates" in settings or settings.get("sampler", "sobol") != "sobol":
        return settings
    return {**settings, "replicates": str(SUITE_REPLICATES)}


def _renderer_known(label: str, key: str, name: str, known: list[str], folder: Path | None = None) -> str:
    """The renderer a case names: a known name, or the absolute path of a renderer file given relative to the
    suite's folder (or the current one); a file is validated now (harness.renderers.external)."""
    if external.looks_like_path(name):
        try:
            path = external.resolve_path(name, (folder,) if folder is not None else ())
        except OSError as err:  # a name too long for the file system, a loop of symbolic links, ...
            raise HarnessError(f"{label}: {key}", f"cannot look for the renderer file {short(name)}: "
                               f"{err.strerror or err}") from None
        if path is None:
            raise HarnessError(f"{label}: {key}", f"no renderer file {short(name)} (relative to {folder or '.'})")
        external.load_spec(path)
        return str(path)
    if name not in known:
        raise HarnessError(f"{label}: {key}", f"unknown renderer {name!r}{hint(name, known)} (known: {', '.join(known)})")
    files = external.renderer_files()
    if name in files:
        external.load_spec(files[name])
    return name


def _settings(label: str, key: str, value: Any) -> dict[str, str]:
    table = _typed(label, key, value, dict)
    out = {}
    for k, v in table.items():
        if isinstance(v, (dict, list)):
            raise HarnessError(f"{label}: {key}.{toml_key(k)}", f"expected a string or number, got {short(v)}")
        out[str(k)] = str(v).lower() if isinstance(v, bool) else str(v)
    return out


def _check_keys(label: str, table: dict, known: tuple[str, ...], parent: str) -> None:
    for k in table:
        if k not in known:
            where = f"{parent}.{toml_key(k)}" if parent else toml_key(k)
            raise HarnessError(f"{label}: {where}", f"unknown key{hint(k, known)}; expected one of {', '.join(known)}")


def _typed(label: str, key: str, value: Any, kind):
    if isinstance(value, bool) and kind is not bool:
        ok = False
    else:
        ok = isinstance(value, kind)
    if not ok:
        names = {str: "a string", dict: "a table", list: "a list", int: "an integer"}
        what = names.get(kind, "a number") if not isinstance(kind, tuple) else "a number"
        raise HarnessError(f"{label}: {key}", f"expected {what}, got {short(value)}")
    if isinstance(kind, tuple) and float in kind and not isinstance(value, float) and float_or_inf(value) == math.inf:
        raise HarnessError(f"{label}: {key}", f"expected a finite number, got an integer of {len(str(value))} digits")
    return value


def _positive(label: str, key: str, value: Any, kind) -> Any:
    value = _typed(label, key, value, kind)
    if not value > 0 or (isinstance(value, float) and not np.isfinite(value)):
        raise HarnessError(f"{label}: {key}", f"expected a positive number, got {value!r}")
    return value


def _at_least_two(label: str, key: str, value: Any) -> int:
    """A sample count the verdict can use: an integer >= ``MIN_SPP``."""
    value = _positive(label, key, value, int)
    if value < MIN_SPP:
        raise HarnessError(f"{label}: {key}", f"expected >= {MIN_SPP} (the verdict needs each pixel's sample variance; "
                           f"one sample per pixel gives none), got {value}")
    return value


def _non_negative(label: str, key: str, value: Any) -> int:
    value = _typed(label, key, value, int)
    if value < 0:
        raise HarnessError(f"{label}: {key}", f"expected a non-negative integer, got {value}")
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
