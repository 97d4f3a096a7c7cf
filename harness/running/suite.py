"""Suites: cases of (scene, renderer with settings, budget, what to compare against, thresholds), run as a gate.

The file format is documented in ``docs/suites.md``; ``harness run SUITE`` runs one and writes ``results.json``
(schema in ``docs/results-schema.md``).
"""

from __future__ import annotations

import dataclasses
import difflib
import itertools
import json
import math
import platform
import re
import time
import traceback
import unicodedata
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from harness.core.errors import HarnessError, read_user_toml
from harness.core.limits import MAX_TIMEOUT_SECONDS
from harness.files.cases import GROUND_TRUTH_FILE

SUITE_KEYS = ("name", "description", "defaults", "cases", "baseline")  # [baseline]: harness/running/baseline.py
CASE_KEYS = (
    "name", "scene", "renderer", "settings", "spp", "seconds", "chunk_spp", "seed", "against", "film",
    "metrics", "thresholds", "expect", "alpha", "tile", "ground_truth_spp", "max_depth", "timeout",
    "variant",
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
    variant: str | None = None  # a transformed scene (harness/studies/stress.py), e.g. "scale=1e3"


@dataclass(frozen=True)
class Suite:
    name: str
    description: str
    path: Path
    cases: tuple[Case, ...]
    baseline: Any = field(default_factory=dict, compare=False)  # the file's [baseline] table, checked by harness/running/baseline.py


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
        # harness.running.baseline imports this module (and scipy): imported here, only for a suite that has the table
        from harness.running.baseline import check_table

        check_table(label, baseline)
    cases, names, folders, scenes = [], set(), {}, {}
    for i, entry in enumerate(entries):
        where = f"cases[{i}]"
        entry = _typed(label, where, entry, dict)
        _check_keys(label, entry, CASE_KEYS, where)
        merged = {**defaults, **entry}
        case = _case(label, path.parent, where, merged)
        if case.name in names:
            raise HarnessError(f"{label}: {where}.name", f"duplicate case name {_short(case.name)}")
        _check_folder_unique(label, where, case.name, folders)
        _check_case_cost(label, where, case, scenes)
        _check_case_variant(label, where, case, scenes[case.scene])
        _check_case_settings(label, where, case, _with_case_overrides(scenes[case.scene], case))
        names.add(case.name)
        cases.append(case)
    return Suite(name, description, path, tuple(cases), baseline)


def _case(label: str, folder: Path, where: str, d: dict[str, Any]) -> Case:
    from harness.renderers import renderer_names

    def key(k: str) -> str:
        return f"{where}.{k}"

    if "scene" not in d:
        raise HarnessError(f"{label}: {key('scene')}", "missing: expected a scene name or a path to a scene file")
    scene = _scene_path(label, key("scene"), folder, _typed(label, key("scene"), d["scene"], str))
    name = _case_name(label, key("name"), d.get("name", scene.stem), "name" not in d)
    renderer = _typed(label, key("renderer"), d.get("renderer", "reference"), str)
    renderer = _renderer_known(label, key("renderer"), renderer, renderer_names(), folder)
    settings = _settings(label, key("settings"), d.get("settings", {}))
    spp = d.get("spp", None if "seconds" in d else 64)
    seconds = d.get("seconds")
    if spp is not None and seconds is not None:
        raise HarnessError(f"{label}: {where}", "give a budget as spp or as seconds, not both")
    if spp is not None:
        spp = _at_least_two(label, key("spp"), spp)
    if seconds is not None:
        seconds = float(_positive(label, key("seconds"), seconds, (int, float)))
    against = _against(label, key("against"), d.get("against", "ground-truth"), renderer_names(), folder)
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
            raise HarnessError(f"{label}: {key('metrics')}", f"unknown metric {m!r}{_hint(m, METRICS)}")
    thresholds = _typed(label, key("thresholds"), d.get("thresholds", {}), dict)
    for m, v in thresholds.items():
        _threshold(label, f"{key('thresholds')}.{_key(m)}", m, v)
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
    )


def _timeout(label: str, key: str, value: Any) -> float:
    """A case's ``timeout`` in seconds: positive, at most a week (1e308 s overflowed the OS's timeout)."""
    value = _positive(label, key, value, (int, float))
    if not value <= MAX_TIMEOUT_SECONDS:
        raise HarnessError(f"{label}: {key}",
                           f"expected at most {MAX_TIMEOUT_SECONDS:g} seconds (a week), got {_short(value)}")
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
                           f"{_short(name)}")
    bad = next((ch for ch in name if unicodedata.category(ch) in UNSAFE_NAME_CATEGORIES), None)
    if bad is not None:
        raise HarnessError(f"{label}: {key}", f"expected no control or format characters, got {bad!r} "
                           f"(U+{ord(bad):04X}) in {_short(name)}{whose}")
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
            f"{_short(name)} and {other[0]}.name {_short(other[1])} both map to the folder cases/{folder} (each run "
            "of characters other than A-Z a-z 0-9 . _ - becomes _, and case is ignored); rename one"))
    folders[folder.casefold()] = (where, name)


def _threshold(label: str, key: str, metric: Any, value: Any) -> float:
    """A ``thresholds`` entry, checked: a known metric and a finite bound that can be met (error metrics are >= 0,
    so a negative upper bound fails every render; ssim is at most 1)."""
    if metric not in METRICS:
        raise HarnessError(f"{label}: {key}", f"unknown metric{_hint(metric, METRICS)}")
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(_float_or_inf(value)):
        raise HarnessError(f"{label}: {key}", f"expected a finite number, got {_short(value)}")
    if metric not in HIGHER_IS_BETTER and value < 0:
        raise HarnessError(f"{label}: {key}", f"expected an upper bound >= 0 ({metric} is never negative), got {value}")
    if metric == "ssim" and value > 1:
        raise HarnessError(f"{label}: {key}", f"expected a lower bound <= 1 (ssim is at most 1), got {value}")
    return float(value)


def _stress_variant(label: str, key: str, value: Any) -> str | None:
    """A case's ``variant`` (harness/studies/stress.py), normalised (``scale=1000`` -> ``scale=1e3``), or None."""
    if value is None:
        return None
    from harness.studies.stress import parse_variant

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
    from harness.core.limits import MAX_FILM_SIDE, check_render_cost, film_problem
    from harness.scene import load_scene

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
    elif case.against.kind == "mitsuba" or (case.against.kind == "ground-truth" and not scene.closed_form):
        budgets.append((case.ground_truth_spp, None, "ground_truth_spp"))
    for spp, seconds, key in budgets:
        check_render_cost(width, height, spp, seconds=seconds, film_where=film_where,
                          spp_where=f"{label}: {where}.{key}", film_keys=film_keys, spp_name=f"{where}.{key}")


def _check_case_variant(label: str, where: str, case: Case, scene) -> None:
    """Apply a case's stress ``variant`` to its (loaded) scene now: a variant the scene cannot have (no light, no
    rectangle) or one that gives an invalid scene is one line naming ``cases[i].variant`` before anything runs."""
    if case.variant is None:
        return
    from harness.studies.stress import check_variant_scene, parse_variant

    try:
        check_variant_scene(parse_variant(case.variant).apply(_with_case_overrides(scene, case)))
    except HarnessError as err:
        message = err.message if err.message.startswith("variant ") else f"variant {case.variant}: {err.message}"
        raise HarnessError(f"{label}: {where}.variant", f"on {scene.path}: {message}") from None


def _check_case_settings(label: str, where: str, case: Case, scene) -> None:
    """Let the built-in renderers check a case's settings (and its comparison render's) before anything runs: a bad
    one is a one-line error naming the suite file and the key, not a failure halfway through the run."""
    from harness.renderers import RenderRequest, get_renderer

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


def _scene_path(label: str, key: str, folder: Path, value: str) -> Path:
    candidates = [folder / value]
    if "/" not in value and not value.endswith(".toml"):
        # A bare name: a scene beside the suite's folder, in ./scenes, or one of this checkout's canonical scenes.
        canonical = Path(__file__).resolve().parent.parent / "scenes" / f"{value}.toml"
        candidates += [folder.parent / "scenes" / f"{value}.toml", Path("scenes") / f"{value}.toml", canonical]
        candidates = list(dict.fromkeys(candidates))
    for c in candidates:
        try:
            if c.is_file():
                return c
        except OSError as err:  # a name too long for the file system, a loop of symbolic links, ...
            raise HarnessError(f"{label}: {key}", f"cannot look for the scene file {_short(str(c))}: "
                               f"{err.strerror or err}") from None
    raise HarnessError(f"{label}: {key}", f"no scene {_short(value)} (looked for "
                       f"{', '.join(_short(str(c)) for c in candidates)})")


def _against(label: str, key: str, value: Any, renderers: list[str], folder: Path | None = None) -> Against:
    if isinstance(value, str):
        if value not in AGAINST_KINDS:
            raise HarnessError(f"{label}: {key}", f"expected one of {', '.join(AGAINST_KINDS)} or a table "
                               f"{{renderer = ..., spp = ...}}, got {value!r}{_hint(value, AGAINST_KINDS)}")
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
    return Against(
        "renderer", renderer, spp,
        _non_negative(label, f"{key}.seed", table.get("seed", 1_000_003)),
        _settings(label, f"{key}.settings", table.get("settings", {})),
    )


def _renderer_known(label: str, key: str, name: str, known: list[str], folder: Path | None = None) -> str:
    """The renderer a case names: a known name, or the absolute path of a renderer file given relative to the
    suite's folder (or the current one); a file is validated now (harness.renderers.external)."""
    from harness.renderers import external

    if external.looks_like_path(name):
        try:
            path = external.resolve_path(name, (folder,) if folder is not None else ())
        except OSError as err:  # a name too long for the file system, a loop of symbolic links, ...
            raise HarnessError(f"{label}: {key}", f"cannot look for the renderer file {_short(name)}: "
                               f"{err.strerror or err}") from None
        if path is None:
            raise HarnessError(f"{label}: {key}", f"no renderer file {_short(name)} (relative to {folder or '.'})")
        external.load_spec(path)
        return str(path)
    if name not in known:
        raise HarnessError(f"{label}: {key}", f"unknown renderer {name!r}{_hint(name, known)} (known: {', '.join(known)})")
    files = external.renderer_files()
    if name in files:
        external.load_spec(files[name])
    return name


def _settings(label: str, key: str, value: Any) -> dict[str, str]:
    table = _typed(label, key, value, dict)
    out = {}
    for k, v in table.items():
        if isinstance(v, (dict, list)):
            raise HarnessError(f"{label}: {key}.{_key(k)}", f"expected a string or number, got {_short(v)}")
        out[str(k)] = str(v).lower() if isinstance(v, bool) else str(v)
    return out


def _check_keys(label: str, table: dict, known: tuple[str, ...], parent: str) -> None:
    for k in table:
        if k not in known:
            where = f"{parent}.{_key(k)}" if parent else _key(k)
            raise HarnessError(f"{label}: {where}", f"unknown key{_hint(k, known)}; expected one of {', '.join(known)}")


def _hint(word: str, candidates) -> str:
    close = difflib.get_close_matches(str(word), list(candidates), n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def _typed(label: str, key: str, value: Any, kind):
    if isinstance(value, bool) and kind is not bool:
        ok = False
    else:
        ok = isinstance(value, kind)
    if not ok:
        names = {str: "a string", dict: "a table", list: "a list", int: "an integer"}
        what = names.get(kind, "a number") if not isinstance(kind, tuple) else "a number"
        raise HarnessError(f"{label}: {key}", f"expected {what}, got {_short(value)}")
    if isinstance(kind, tuple) and float in kind and not isinstance(value, float) and _float_or_inf(value) == math.inf:
        raise HarnessError(f"{label}: {key}", f"expected a finite number, got an integer of {len(str(value))} digits")
    return value


def _key(name: str) -> str:
    """A key as TOML writes it in a key path: bare if it can be, else quoted with every odd character escaped."""
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else json.dumps(name)


def _float_or_inf(value) -> float:
    try:
        return float(value)
    except OverflowError:
        return math.inf


def _short(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters, for "got ..." in one-line messages."""
    try:
        text = repr(value)
    except ValueError:  # an integer with more digits than Python prints
        text = "a huge integer"
    return text if len(text) <= limit else text[: limit - 3] + "..."


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


# ---- running ---------------------------------------------------------------------------------------------------


def slug(name: str) -> str:
    """The folder name of a case (``OUT/cases/<slug>``): each run of characters other than A-Z a-z 0-9 . _ -
    replaced by _, leading and trailing _ removed; "case" where nothing (or only "." or "..") is left, so a slug
    never leaves its parent folder. Not injective (``a/b`` and ``a_b`` give ``a_b``): :func:`load_suite` refuses a
    suite in which two cases share a slug (ignoring case)."""
    text = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_")
    return text if text not in ("", ".", "..") else "case"


def case_scene(case: Case, for_ground_truth: bool = False):
    """The case's scene: film and depth overrides, then its stress ``variant``, unless ``for_ground_truth`` and the
    variant must not change the image (then the untransformed scene is the reference's)."""
    render_scene, reference_scene = case_scenes(case)
    return reference_scene if for_ground_truth else render_scene


def _with_case_overrides(scene, case: Case):
    """The scene with the case's ``film`` and ``max_depth`` overrides."""
    from reference_impl import Film

    if case.film:
        film = Film(case.film.get("width", scene.film.width), case.film.get("height", scene.film.height),
                    scene.film.filter)
        scene = dataclasses.replace(scene, film=film)
    if case.max_depth is not None:  # the scene's own depth, so the ground truth and the render agree
        scene = dataclasses.replace(scene, max_depth=case.max_depth)
    return scene


def case_scenes(case: Case):
    """(the scene the case renders, the scene its reference is made from), from one read of the scene file: the
    same scene unless a stress ``variant`` must not change the image (:func:`case_scene`)."""
    from harness.scene import load_scene

    scene = _with_case_overrides(load_scene(case.scene), case)
    if case.variant is None:
        return scene, scene
    from harness.studies.stress import parse_variant

    stress_variant = parse_variant(case.variant, f"{case.scene}: variant")
    varied = stress_variant.apply(scene)
    return varied, (scene if stress_variant.judged_against_original else varied)


def render_with_budget(case: Case, scene, variant: str | None, progress=None, cache_dir=None):
    """Render a case's test image within its budget: spp at once, or chunks of chunk_spp until ``seconds``."""
    from harness.renderers import RenderRequest, get_renderer

    renderer = get_renderer(case.renderer)
    settings = dict(case.settings)
    if case.renderer == "mitsuba" and variant and "variant" not in settings:
        settings["variant"] = variant
    if case.renderer == "mitsuba" and case.spp is not None and set(settings) <= {"variant"}:
        return _cached_mitsuba_render(case, scene, settings.get("variant"), cache_dir, progress)
    if case.spp is not None:
        return renderer.render(scene, RenderRequest(spp=case.spp, seed=case.seed, settings=settings, progress=progress))
    seeds = (case.seed + 7919 * index for index in itertools.count())
    return render_for_seconds(renderer, scene, case.seconds, case.chunk_spp, seeds, settings, progress)


def render_for_seconds(renderer, scene, seconds: float, chunk_spp: int, seeds, settings: dict[str, str],
                       progress=None):
    """Render chunks of ``chunk_spp`` (seeds drawn from the iterator ``seeds``) until ``seconds`` of render time
    are spent, and merge them exactly (``harness.judges.moments``) into one RenderResult with the summed time and rays;
    ``info["seeds"]`` lists the seeds used."""
    from harness.judges.moments import Estimate, merge
    from harness.renderers import RenderRequest

    chunks, results, used, spent = [], [], [], 0.0
    while spent < seconds:
        seed = next(seeds)
        result = renderer.render(scene, RenderRequest(spp=chunk_spp, seed=seed, settings=dict(settings)))
        spent += result.seconds
        results.append(result)
        used.append(seed)
        chunks.append(Estimate(result.image, result.variance, result.spp))
        if progress is not None:
            progress(min(spent, seconds), seconds)
    merged = merge(chunks)
    first = results[0]
    return dataclasses.replace(
        first, image=merged.mean.astype(np.float32), variance=merged.variance.astype(np.float32),
        seconds=spent, spp=merged.n,
        rays={k: sum(r.rays.get(k, 0) for r in results) for k in first.rays},
        stats={k: sum(r.stats.get(k, 0) for r in results) for k in first.stats},
        info=dict(first.info, chunks=len(results), seeds=used),
    )


def _cached_mitsuba_render(case: Case, scene, variant: str | None, cache_dir, progress):
    """A Mitsuba test render through the ground-truth cache, so a suite's second run renders nothing."""
    return cached_mitsuba_render(scene, case.spp, case.seed, variant, cache_dir, progress)


def cached_mitsuba_render(scene, spp: int, seed: int, variant: str | None, cache_dir, progress=None, chunk_spp=None):
    """A Mitsuba render of ``spp`` samples through the ground-truth cache, as a RenderResult. Its ``seconds`` is
    the time the render took when it was made (from the cache entry's metadata)."""
    from harness.renderers import groundtruth
    from harness.renderers import RenderResult

    gt = groundtruth.ground_truth(scene, spp=spp, seed=seed, cache_dir=cache_dir, variant=variant,
                                  use_closed_form=False, progress=progress,
                                  chunk_spp=chunk_spp or groundtruth.DEFAULT_CHUNK_SPP)
    info = dict(gt.info.get("info", {}), cached=gt.cached, mitsuba_renders=gt.renders)
    width, height = scene.film.width, scene.film.height
    return RenderResult(
        renderer="mitsuba", image=gt.image, variance=gt.variance,
        seconds=float(gt.info.get("render_seconds", gt.seconds)),
        spp=gt.spp, rays={"camera": width * height * gt.spp}, stats={"mitsuba_renders": gt.renders},
        settings={"spp": gt.spp, "seed": seed, "variant": gt.info.get("variant")}, info=info,
    )


class CachedMitsubaRenderer:
    """Mitsuba behind the ground-truth cache: a render already made (same scene, spp, seed, variant) is not made
    again. Used where reports and studies render Mitsuba, so that re-running them performs no Mitsuba render."""

    name = "mitsuba"

    def __init__(self, cache_dir=None, variant: str | None = None):
        self.cache_dir = cache_dir
        self.variant = variant

    def render(self, scene, request):
        variant = request.settings.get("variant", self.variant)
        if set(request.settings) - {"variant"}:
            raise HarnessError("--set", "cached Mitsuba renders take no settings but the variant")
        return cached_mitsuba_render(scene, request.spp, request.seed, variant, self.cache_dir, request.progress,
                                     chunk_spp=request.spp)


def reference_for(case: Case, scene, cache_dir, variant: str | None, progress=None):
    """The image a case is compared with, as a GroundTruth."""
    from harness.renderers import groundtruth
    from harness.renderers import RenderRequest, get_renderer

    kind = case.against.kind
    if kind == "closed-form":
        if not scene.closed_form:
            raise HarnessError(f"{case.scene}: closed_form", f"case {case.name!r} compares against a closed form, "
                               "but the scene declares none")
        return groundtruth.closed_form(scene)
    if kind in ("ground-truth", "mitsuba"):
        return groundtruth.ground_truth(scene, spp=case.ground_truth_spp, cache_dir=cache_dir, variant=variant,
                                        use_closed_form=kind == "ground-truth", progress=progress)
    against = case.against
    if against.renderer == "mitsuba":  # Mitsuba renders always go through the cache
        return groundtruth.ground_truth(scene, spp=against.spp, seed=against.seed, cache_dir=cache_dir,
                                        variant=against.settings.get("variant", variant), use_closed_form=False,
                                        progress=progress)
    result = get_renderer(against.renderer).render(
        scene, RenderRequest(spp=against.spp, seed=against.seed, settings=dict(against.settings)))
    return groundtruth.GroundTruth(result.image, result.variance, against.renderer, against.spp,
                                   info={"settings": result.settings, **result.info}, seconds=result.seconds)


def check_thresholds(metrics: dict, thresholds: dict[str, float]) -> list[str]:
    """Descriptions of every threshold a metric breaks (upper bounds; lower bounds for psnr and ssim)."""
    broken = []
    for name, limit in thresholds.items():
        value = metrics.get(name)
        if isinstance(value, dict):  # bias: compare its magnitude
            value = abs(value.get("overall", value.get("value", 0.0)))
        if value is None or not np.isfinite(value):
            broken.append(f"{name} is {value}")
        elif name in HIGHER_IS_BETTER and value < limit:
            broken.append(f"{name} {value:.4g} < {limit:.4g}")
        elif name not in HIGHER_IS_BETTER and value > limit:
            broken.append(f"{name} {value:.4g} > {limit:.4g}")
    return broken


def run_case(case: Case, out_dir: Path, *, cache_dir=None, variant=None, progress=None) -> dict:
    """Run one case; a renderer that fails makes the case an "error" with the reason, never stops the suite."""
    from harness.files import imageio
    from harness.running.compare import compare_images
    from harness.renderers.external import variance_metadata
    from harness.renderers.validate import validate_result

    record = case_header(case)
    start = time.perf_counter()
    try:
        scene, reference_scene = case_scenes(case)
        gt = reference_for(case, reference_scene, cache_dir, variant, progress)
        record["ground_truth"] = {
            "source": gt.source, "spp": gt.spp, "cached": gt.cached, "renders": gt.renders,
            "seconds": gt.seconds, "path": str(gt.path) if gt.path else None,
            "variant": gt.info.get("variant") or gt.info.get("info", {}).get("variant"),
            "mitsuba_version": gt.info.get("mitsuba"),
        }
        result = render_with_budget(case, scene, variant, cache_dir=cache_dir)
        validate_result(result, scene.film.width, scene.film.height)  # a bad image: this case's error, before writing
        folder = out_dir / "cases" / slug(case.name)
        folder.mkdir(parents=True, exist_ok=True)
        if gt.path is None:  # a closed form or another renderer's image: kept, so the report reads what was judged
            record["ground_truth"]["path"] = str(imageio.write_exr(folder / GROUND_TRUTH_FILE, gt.image, gt.variance,
                                                                   metadata={"case": case.name, "source": gt.source}))
        imageio.write_exr(folder / "render.exr", result.image, result.variance,
                          metadata={"renderer": result.renderer, "case": case.name})
        imageio.write_png_preview(folder / "render.png", result.image)
        gt_meta = {"spp": str(gt.spp)} if gt.spp else {}
        comparison = compare_images(
            imageio.ExrImage(result.image, result.variance, variance_metadata(result)),
            imageio.ExrImage(gt.image, gt.variance, gt_meta),
            tile=case.tile, alpha=case.alpha,
        )
        all_metrics = dict(comparison["metrics"], bias=comparison["bias"])
        metrics = {k: all_metrics[k] for k in case.metrics if k in all_metrics}
        broken = check_thresholds(all_metrics, case.thresholds)
        verdict = comparison["verdict"]
        outcome = "pass" if verdict["verdict"] == "pass" and not broken else "fail"
        reason = verdict.get("reason", "") if verdict["verdict"] != "pass" else ""
        if broken:
            reason = "; ".join(filter(None, [reason, "threshold: " + ", ".join(broken)]))
        record.update(
            status=outcome, reason=reason, ok=outcome == case.expect, metrics=metrics, verdict=verdict,
            thresholds=case.thresholds, thresholds_broken=broken,
            render={"seconds": result.seconds, "spp": result.spp, "paths_per_second": result.paths / max(result.seconds, 1e-12),
                    "rays": result.rays, "nonfinite_pixels": result.nonfinite_pixels, "settings": result.settings,
                    "info": result.info, "exr": str(folder / "render.exr")},
        )
    except HarnessError:
        raise
    except Exception as err:  # a renderer or adapter failure fails this case only
        record.update(status="error", ok=False, reason=f"{type(err).__name__}: {err}".splitlines()[0],
                      traceback=traceback.format_exc(limit=8))
    record["wall_seconds"] = time.perf_counter() - start
    return record


def case_header(case: Case) -> dict[str, Any]:
    """The fields every record of a case starts with, whatever its outcome."""
    return {
        "name": case.name, "scene": str(case.scene), "renderer": case.renderer, "settings": case.settings,
        "budget": {"spp": case.spp} if case.spp is not None else {"seconds": case.seconds},
        "seed": case.seed, "expect": case.expect, "against": dataclasses.asdict(case.against),
    }


def run_suite(suite: Suite, out_dir: Path, *, cache_dir=None, variant=None,
              on_case: Callable[[int, dict], None] | None = None, executor=None, resume: bool = False,
              on_resume: Callable[[int, int], None] | None = None, timeout: float | None = None) -> dict:
    """Run every case on ``executor`` (default: in this process, in order; ``harness.running.executors``), rewriting
    ``results.json`` atomically after each finished case, records in suite order whatever order cases finish in
    (finished cases are never lost). With ``resume``, the finished records of an earlier run of this suite in
    ``out_dir`` whose case definitions are unchanged are kept (``"resumed": true``) and only the rest run
    (``harness.running.runstate``); ``on_resume(kept, total)`` is told how many. A task whose worker is killed (past
    ``timeout``, else the case's own, see ``executors.case_timeout``) or dies makes its case an error."""
    from harness.running import executors
    from harness.running import runstate
    from harness.files.imageio import atomic_write_text

    out_dir.mkdir(parents=True, exist_ok=True)
    started = time.time()
    results: dict[str, Any] = {
        "schema": 1, "suite": suite.name, "suite_file": str(suite.path), "description": suite.description,
        "started": time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(started)),
        "host": {"python": platform.python_version(), "machine": platform.machine(), "node": platform.node()},
        "cases": [],
    }
    executor = executor or executors.SerialExecutor()
    results["executor"] = executor.name
    digests = [runstate.case_digest(case) for case in suite.cases]
    records = runstate.reusable(out_dir / "results.json", suite.name, suite.cases, digests) if resume else {}
    if records and on_resume is not None:
        on_resume(len(records), len(suite.cases))

    def write() -> None:
        results["cases"] = [records[i] for i in sorted(records)]
        results["complete"] = len(records) == len(suite.cases)
        results["summary"] = summarise(results["cases"], time.time() - started)
        with runstate.no_interrupts():  # a signal waits until the file is renamed into place
            atomic_write_text(out_dir / "results.json", json.dumps(results, indent=2, default=_json_default))

    todo = [(i, case) for i, case in enumerate(suite.cases) if i not in records]
    tasks = executors.plan(todo, out_dir, cache_dir=cache_dir, variant=variant, timeout=timeout,
                           chunks=executor.chunks)
    rendered: set[str] = set()  # chunk tasks that rendered, not yet counted in a case's record
    outcomes = executor.run(tasks)
    try:
        for task, outcome in outcomes:
            if outcome[0] == "failed" and runstate.requested():
                runstate.check()  # a worker that died of the signal that stops the run is not the case's fault
            if outcome[0] == "harness-error":
                raise HarnessError(outcome[1], outcome[2])
            if task.kind != "case":
                if outcome == ("ok", True):
                    rendered.add(task.key)
                continue
            index = int(task.key.split(":")[1])
            case = suite.cases[index]
            if outcome[0] == "ok":
                record = outcome[1]
                mine = rendered.intersection(task.deps)  # its chunks rendered ahead count as its renders
                if mine and "ground_truth" in record:
                    rendered -= mine
                    record["ground_truth"].update(renders=record["ground_truth"]["renders"] + len(mine), cached=False)
            else:  # the worker was killed or died: the suite goes on
                record = dict(case_header(case), status="error", ok=False, reason=outcome[1],
                              wall_seconds=outcome[2] if len(outcome) > 2 else None)
            record["definition"] = digests[index]
            records[index] = record
            write()
            if on_case is not None:
                on_case(index, record)
            runstate.check()
    finally:
        outcomes.close()  # stops the workers, whatever ended the loop
    if not todo:  # everything was resumed: still record this run
        write()
    return results


def summarise(records: list[dict], wall: float) -> dict:
    return {
        "cases": len(records),
        "ok": sum(r["ok"] for r in records),
        "passed": sum(r.get("status") == "pass" for r in records),
        "failed": sum(r.get("status") == "fail" for r in records),
        "errors": sum(r.get("status") == "error" for r in records),
        "unexpected": [r["name"] for r in records if not r["ok"]],
        "mitsuba_renders": sum(_mitsuba_renders(r) for r in records if not r.get("resumed")),  # by this run
        "resumed": sum(bool(r.get("resumed")) for r in records),
        "ground_truth_cached": sum(bool(r.get("ground_truth", {}).get("cached")) for r in records),
        "wall_seconds": wall,
    }


def _mitsuba_renders(record: dict) -> int:
    """Mitsuba renders a case performed: for its ground truth, and for its test render if Mitsuba made it."""
    renders = record.get("ground_truth", {}).get("renders", 0)
    render = record.get("render", {})
    if record.get("renderer") == "mitsuba":
        renders += render.get("info", {}).get("mitsuba_renders", 1 if render else 0)
    return renders


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")
