"""``harness bench``: the reference path tracer against Mitsuba 3 in error per second.

For each scene, every contender renders the same film at the same spp, once to warm up (numba's compiled kernels,
Dr.Jit's kernel cache) and then ``repeats`` times with different seeds, the contenders taking turns so that a change
in the shared machine's load falls on all of them alike. Per contender:

- ``seconds``: median render time (the renderer's own clock: no scene loading, no file writing);
- ``paths_per_second`` = pixels x spp / seconds; ``rays_per_second`` where the renderer counts its rays;
- ``cores_busy``: process CPU time / wall time during the timed renders (2.0 = both cores of this machine);
- ``mse``: mean over pixels and channels of (render - ground truth)^2, less the ground truth's own mean variance
  (for an unbiased render E[(R - G)^2] = Var R + Var G), averaged over the repeats;
- ``efficiency`` = 1 / (mse x seconds) (Veach's efficiency of an estimator: the inverse of the product of its
  variance and its cost), and its ratio to each Mitsuba variant's.

Mitsuba runs its plain ``path`` integrator, in one pass per render, as a user would run it (``--set moments=off``):
the per-pixel variances of the harness's ``moment(aov(path))`` wrapper cost Mitsuba time that a user does not pay.

Any other renderer (``harness bench --renderer NAME``: a renderer file, a ``renderers/NAME.toml``, an entry point)
races at the same spp: an external renderer run K times per render (no variance channels) is asked for spp / K per
run, so that its image holds the same samples, and its time is its render time without process start-up
(:mod:`harness.renderers.external`: its own ``render_seconds``, or the wall time less the start-up measured once).

The reference's strategy rows (one setting changed from the defaults) are compared with the defaults at the same
spp and at equal time: each, the defaults too, renders ``repeats`` times more at the spp that takes the defaults'
time, the rows taking turns (:func:`equal_time_renders`); "best" is decided at equal time, named only when told apart (:func:`strategy_verdict`);
an exact estimator reads "zero variance", without an efficiency (:func:`is_exact`).

Each scene also gets the row "embree (own rays)": Embree's own rate on the rays the reference traces there, recorded
once and replayed once per attempt (:mod:`harness.studies.embree_rate`), and the reference's rays per second as a
fraction of it, with its interval over the rounds (:func:`embree_fraction_interval`). A scene can also race
``harness render`` in fresh processes, the reference against Mitsuba ``llvm_ad_rgb`` (:mod:`harness.studies.fresh_race`:
render, start-up and wall seconds; ``--fresh``, and with ``--check`` the scenes of the fresh target). The targets of
the performance issues (:func:`targets`) are checked on the scenes benched (:func:`check_targets`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError
from harness.judges.efficiency import (LEVEL, best_separated, efficiency_ratio, equal_time_spp, float_resolution,
                                       ratio_interval, shown_mse, zero_variance)
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.groundtruth import ground_truth
from harness.renderers.external import ExternalRendererError
from harness.renderers.mitsuba import sampler_takes
from harness.scene import load_scene
from harness.studies import embree_rate, fresh_race

ROOT = Path(__file__).resolve().parents[2]
BENCH_SCENES = ("cornell-box", "soft-shadows", "multi-light")
#: issue 39's canonical scene families: the Lambertian three, veach-mis, cornell-box-specular, one textured, one with
#: many lights, one with a participating medium
CANONICAL_SCENES = BENCH_SCENES + ("veach-mis", "cornell-box-specular", "textured-cornell-box", "lamp-grid",
                                   "fog-box")
#: the film ``--check`` renders a scene at when no ``--film`` is given, where the scene's own would make the check
#: long: the fog box's 256 x 256 takes 2.9 s a reference render at 64 spp (14 contenders x 6 attempts and the
#: equal-time phase: minutes); at 64 x 64 it is the film of docs/performance.md's media race
CHECK_FILMS: dict[str, tuple[int, int]] = {"fog-box": (64, 64)}
#: the fewest rounds ``--check`` races a scene in, where the default would leave its efficiency undecided: a round's MSE
#: on veach-mis and lamp-grid is heavy-tailed (small bright lights), and in 5 rounds the efficiency's interval spanned
#: 0.29-1.04 and 0.67-1.51 (docs/performance.md, "Issue 39's targets"); their renders take about 0.05 s
CHECK_ROUNDS: dict[str, int] = {"veach-mis": 20, "lamp-grid": 20}
DEFAULT_SPP = 64
DEFAULT_REPEATS = 3
DEFAULT_GT_SPP = 4096
#: --check's fewest rounds: each ratio's interval comes from the contenders' per-round MSEs and seconds
MIN_CHECK_REPEATS = 5
#: a machine whose 1-minute load average before the race is above this many per core is busy: its figures are
#: measured and shown, its targets never certified (docs/performance.md, "The method")
BUSY_LOAD_PER_CORE = 0.5
#: where Linux's cpufreq says each core's frequency governor
GOVERNORS = "/sys/devices/system/cpu/cpu[0-9]*/cpufreq/scaling_governor"

# Reference settings tried for "the best strategy" (the first is the defaults). Each is a one-change variation, so
# the table says which choice pays on which scene.
STRATEGIES: tuple[dict[str, str], ...] = (
    {},
    {"sampler": "independent"},
    {"direct": "mis"},
    {"shadow_rays": "2"},
    {"rr_depth": "1"},
    {"rr_depth": "2"},
    {"rr_depth": "5"},
    {"rr": "off"},
    {"light_selection": "uniform"},
)

#: the two comparisons of the strategy rows, as the table, the lines and the JSON name them
SAME_SPP, EQUAL_TIME = "same spp", "equal time"

# Mitsuba samplers raced besides independent and ldsampler on the scenes where a target compares with Mitsuba's best
# sampler (each where it draws exactly the bench's spp: harness.renderers.mitsuba.sampler_takes).
EXTRA_SAMPLERS = ("stratified", "multijitter", "orthogonal")


@dataclass(frozen=True)
class Target:
    """A target of the performance issue: ``measure`` (a key of a scene's ``ratios``, or ``cores_busy``: the
    reference row's) at least ``minimum`` on each of ``scenes``; ``words`` says it for ``--help``."""

    measure: str
    scenes: tuple[str, ...]
    minimum: float
    words: str


#: a target's measure: the reference's rays per second over Embree's own rate on the same rays (the row "embree (own
#: rays)", ``embree_rate.reference_fraction``), with its interval over the rounds (:func:`embree_fraction_interval`)
EMBREE_FRACTION = "embree_fraction"


def targets() -> tuple[Target, ...]:
    """The targets of the performance issues, each checked from figures measured in the same run. The cores target
    asks 0.9 of this machine's cores (1.8 on 2 cores) of the reference's Cornell box renders. Issue 39's: efficiency
    >= 1 x Mitsuba's best sampler on every canonical scene (:data:`CANONICAL_SCENES`), rays/s >= 0.6 of Embree's own
    rate where the rays are recorded (not the fog box: the volumetric loop records none), and a fresh ``harness
    render`` of soft-shadows within 2x of Mitsuba's fresh render time (:mod:`harness.studies.fresh_race`)."""
    cores = 0.9 * (os.cpu_count() or 1)
    recorded = tuple(name for name in CANONICAL_SCENES if name != "fog-box")
    return (
        Target("efficiency_vs_llvm_ad_rgb_ldsampler", BENCH_SCENES, 1.0,
               "efficiency >= 1 x Mitsuba llvm_ad_rgb ldsampler's on cornell-box, soft-shadows and multi-light"),
        Target("efficiency_vs_mitsuba_best", CANONICAL_SCENES, 1.0,
               f"efficiency >= 1 x Mitsuba's best sampler's on {', '.join(CANONICAL_SCENES)}"),
        Target("paths_per_second_vs_llvm_ad_rgb", ("cornell-box",), 0.8,
               "paths/s >= 0.8 x Mitsuba llvm_ad_rgb's on cornell-box"),
        Target("cores_busy", ("cornell-box",), cores, f"with >= {cores:.3g} cores busy there"),
        Target(EMBREE_FRACTION, recorded, 0.6,
               "rays/s >= 0.6 x Embree's own rate on the same rays on each of those but fog-box (whose rays are "
               "not recorded)"),
        Target(fresh_race.RATIO, ("soft-shadows",), 0.5,
               "a fresh harness render's render time within 2x of Mitsuba llvm_ad_rgb's fresh one (Mitsuba's / "
               "the reference's >= 0.5) on soft-shadows"),
    )


def target_scenes() -> list[str]:
    """Every scene a target is checked on, in order."""
    return list(dict.fromkeys(name for t in targets() for name in t.scenes))


def best_sampler_scenes() -> set[str]:
    """The scenes where a target compares with Mitsuba's best sampler (they race :data:`EXTRA_SAMPLERS` too)."""
    return {name for t in targets() if t.measure == "efficiency_vs_mitsuba_best" for name in t.scenes}


def fresh_scenes() -> set[str]:
    """The scenes where a target compares fresh processes (``--check`` races them in fresh processes too)."""
    return {name for t in targets() if t.measure == fresh_race.RATIO for name in t.scenes}


def embree_fraction_interval(reference: Row, embree: dict, level: float = LEVEL) -> dict | None:
    """The reference's rays per second over Embree's own rate on the scene's recorded rays, with its ``level``
    interval over the rounds: fraction = (R / t_ref) / (E / t_embree) = (R / E) x t_embree / t_ref, with R the
    reference's rays per render (its rays per path x pixels x spp), E the recorded rays, t_ref the reference's
    render seconds and t_embree the replay's seconds (all phases) of each round (the replay runs once per round,
    between the renders: ``embree["seconds_all"]``); :func:`harness.judges.efficiency.ratio_interval` on the two
    columns of seconds (the ratio of their means, as the paths/s ratio), scaled by R / E. None where a figure is
    missing (a skipped row, a scene whose rays are not recorded, fewer replays than rounds)."""
    if (reference.error or reference.rays_per_path is None or embree.get("error") or not embree.get("recorded_rays")
            or not reference.seconds_all or len(embree.get("seconds_all") or []) != len(reference.seconds_all)):
        return None
    scale = reference.rays_per_path * reference.width * reference.height * reference.spp / embree["recorded_rays"]
    interval = ratio_interval((embree["seconds_all"],), (reference.seconds_all,), level)
    for key in ("value", "low", "high"):
        if interval.get(key) is not None:
            interval[key] *= scale
    return interval


@dataclass(frozen=True)
class Contender:
    """One renderer configuration in the race: a label, the renderer's name and its ``--set`` values."""

    label: str
    renderer: str
    settings: dict[str, str] = field(default_factory=dict)


def default_contenders(spp: int, extra_samplers: bool = False) -> list[Contender]:
    """The reference at its defaults, Mitsuba's ``llvm_ad_rgb`` and ``scalar_rgb`` at theirs (one pass), and
    ``llvm_ad_rgb`` with its low-discrepancy sampler (``ldsampler``, a (0,2)-sequence: the like of the reference's
    default sampler), so that the gain of stratification is seen on both sides; with ``extra_samplers``, also
    ``llvm_ad_rgb`` with each of :data:`EXTRA_SAMPLERS` that draws exactly ``spp``."""
    plain = {"moments": "off", "chunk_spp": str(spp)}
    contenders = [
        Contender("reference", "reference"),
        Contender("mitsuba llvm_ad_rgb", "mitsuba", {**plain, "variant": "llvm_ad_rgb"}),
        Contender("mitsuba scalar_rgb", "mitsuba", {**plain, "variant": "scalar_rgb"}),
    ]
    if sampler_takes("ldsampler", spp):  # it draws powers of 4 only
        contenders.append(Contender("mitsuba llvm_ad_rgb ldsampler", "mitsuba",
                                    {**plain, "variant": "llvm_ad_rgb", "sampler": "ldsampler"}))
    if extra_samplers:
        contenders += [Contender(f"mitsuba llvm_ad_rgb {sampler}", "mitsuba",
                                 {**plain, "variant": "llvm_ad_rgb", "sampler": sampler})
                       for sampler in EXTRA_SAMPLERS if sampler_takes(sampler, spp)]
    return contenders


@dataclass
class Row:
    """What one contender measured on one scene (see the module docstring for each figure)."""

    scene: str
    label: str
    renderer: str
    settings: dict
    spp: int
    width: int
    height: int
    seconds: float = math.nan
    seconds_all: list[float] = field(default_factory=list)
    paths_per_second: float = math.nan
    rays_per_second: float | None = None
    rays_per_path: float | None = None
    cores_busy: float = math.nan
    mse: float = math.nan
    mse_all: list[float] = field(default_factory=list)
    mse_raw: float = math.nan
    efficiency: float = math.nan
    embree_share: float | None = None
    variant: str | None = None
    stats: dict = field(default_factory=dict)
    error: str | None = None
    #: where the render time comes from, for a renderer that does not time itself in-process (an external one)
    time_from: str | None = None
    #: per repeat, the render's own mean per-pixel variance (of the mean), where the renderer gives one
    variance_all: list[float] = field(default_factory=list)
    #: an exact estimator here: every repeat's own variance (or MSE) at most float32 rounding; no efficiency
    zero_variance: bool = False
    #: a reference strategy row at equal time: the spp that takes the defaults' time, its repeats' MSE and
    #: seconds, and its efficiency 1 / (mean MSE x median seconds) (:func:`equal_time_renders`)
    equal_time_spp: int | None = None
    equal_time_mse_all: list[float] = field(default_factory=list)
    equal_time_seconds_all: list[float] = field(default_factory=list)
    equal_time_efficiency: float = math.nan
    equal_time_error: str | None = None


def mse_against(image: np.ndarray, gt_image: np.ndarray, gt_variance: np.ndarray | None) -> tuple[float, float]:
    """(MSE corrected for the ground truth's own noise, raw MSE): mean (R - G)^2 - mean Var G, and mean (R - G)^2."""
    raw = float(np.mean((image.astype(np.float64) - gt_image.astype(np.float64)) ** 2))
    gt_var = float(np.mean(gt_variance)) if gt_variance is not None else 0.0
    return raw - gt_var, raw


def is_exact(variances: Sequence[float], mse: Sequence[float], gt) -> bool:
    """Whether a row's estimator is exact here (:func:`harness.judges.efficiency.zero_variance`): every repeat's
    own variance (the render's mean per-pixel variance; without one, its raw MSE against the ground truth ``gt``) at
    most float32 rounding of the ground truth's mean absolute level."""
    gt_var = float(np.mean(gt.variance)) if gt.variance is not None else 0.0
    own = list(variances) if len(variances) == len(mse) else [m + gt_var for m in mse]
    level = np.abs(np.asarray(gt.image, dtype=np.float64))
    return zero_variance(own, float_resolution(float(level[np.isfinite(level)].mean()) if level.size else None))


def efficiency(mse: float, seconds: float) -> float:
    """1 / (MSE x seconds); NaN when either is not positive (an MSE at or below the ground truth's noise)."""
    return 1.0 / (mse * seconds) if mse > 0 and seconds > 0 else math.nan


def _cpu_seconds(children: bool = False) -> float:
    """CPU seconds of this process (and, with ``children``, of its finished child processes: an external
    renderer's runs)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    total = usage.ru_utime + usage.ru_stime
    if children:
        kids = resource.getrusage(resource.RUSAGE_CHILDREN)
        total += kids.ru_utime + kids.ru_stime
    return total


def _error_text(err: HarnessError | ExternalRendererError) -> str:
    """A failed render's one line: where and what for the harness's errors, the message for an external renderer's."""
    return f"{err.where}: {err.message}" if isinstance(err, HarnessError) else str(err)


def bench_scene(
    scene,
    contenders: Sequence[Contender],
    *,
    spp: int,
    repeats: int,
    gt,
    seed: int = 1,
    on_render: Callable[[str], None] | None = None,
    between: Callable[[int], None] | None = None,
) -> list[Row]:
    """Race ``contenders`` on ``scene`` (a loaded Scene) at ``spp`` against ground truth ``gt``
    (a :class:`harness.renderers.groundtruth.GroundTruth`). Renders alternate between contenders, repeat by repeat;
    ``between(attempt)``, if given, runs after each attempt's renders (attempt 0: the warm-up), so that another
    measurement takes its turn with them (the Embree replay: :mod:`harness.studies.embree_rate`)."""
    rows = [Row(scene.name, c.label, c.renderer, dict(c.settings), spp, scene.film.width, scene.film.height)
            for c in contenders]
    renderers = [get_renderer(c.renderer) for c in contenders]
    cpu = [0.0] * len(contenders)
    wall = [0.0] * len(contenders)
    for attempt in range(repeats + 1):  # attempt 0 is the warm-up
        for i, (contender, renderer, row) in enumerate(zip(contenders, renderers, rows)):
            if row.error:
                continue
            external = not getattr(renderer, "cheap_to_repeat", True)
            # the race measures MSE against the ground truth, not the render's variance: an external renderer
            # without variance channels runs once at spp (not K times at spp / K, which for a stratified sampler
            # is another estimator)
            request = RenderRequest(spp=spp, seed=seed + attempt, settings=dict(contender.settings),
                                    variance=not external)
            cpu0, wall0 = _cpu_seconds(external), time.perf_counter()
            try:
                result = renderer.render(scene, request)
            except (HarnessError, ExternalRendererError) as err:
                row.error = _error_text(err)
                continue
            cpu1, wall1 = _cpu_seconds(external), time.perf_counter()
            if on_render is not None:
                on_render(f"{scene.name}: {contender.label}" + (" (warm-up)" if attempt == 0 else ""))
            if attempt == 0:
                continue
            row.spp = int(result.spp)
            row.time_from = result.info.get("time_from", row.time_from)
            cpu[i] += cpu1 - cpu0
            wall[i] += wall1 - wall0
            row.seconds_all.append(result.seconds)
            mse, raw = mse_against(result.image, gt.image, gt.variance)
            row.mse_all.append(mse)
            if result.variance is not None:
                row.variance_all.append(float(np.mean(result.variance)))
            row.mse_raw = raw if math.isnan(row.mse_raw) else row.mse_raw + raw
            row.variant = result.info.get("variant")
            if result.rays and set(result.rays) >= {"camera", "shadow", "indirect"}:
                rays = sum(result.rays.values())
                row.rays_per_second = rays / result.seconds if row.rays_per_second is None else row.rays_per_second
                row.rays_per_path = rays / result.paths
            if "embree_microseconds" in result.stats:
                threads = result.info.get("threads", 1)
                share = result.stats["embree_microseconds"] / 1e6 / (result.seconds * threads)
                row.embree_share = share if row.embree_share is None else row.embree_share + share
                row.stats = {k: v for k, v in result.stats.items() if k != "embree_microseconds"}
        if between is not None:
            between(attempt)
    for i, row in enumerate(rows):
        if row.error or not row.seconds_all:
            continue
        n = len(row.seconds_all)
        row.seconds = statistics.median(row.seconds_all)
        row.paths_per_second = row.width * row.height * row.spp / row.seconds if row.seconds > 0 else math.nan
        if row.rays_per_path is not None:
            row.rays_per_second = row.rays_per_path * row.paths_per_second
        row.mse = float(np.mean(row.mse_all))
        row.mse_raw /= n
        row.zero_variance = is_exact(row.variance_all, row.mse_all, gt)
        row.efficiency = math.nan if row.zero_variance else efficiency(row.mse, row.seconds)
        row.cores_busy = cpu[i] / wall[i] if wall[i] > 0 else math.nan
        if row.embree_share is not None:
            row.embree_share /= n
    return rows


def equal_time_renders(scene, rows: Sequence[Row], *, repeats: int, gt, seed: int = 1,
                       on_render: Callable[[str], None] | None = None) -> None:
    """The reference's strategy rows again at equal time: each at the spp that takes the defaults' ("reference"
    row's) mean render time, from its own same-spp renders (:func:`harness.judges.efficiency.equal_time_spp`:
    s* = spp x t_defaults / t, rounded, at most 16 x spp; the same spp where s* is within 1.25 x of it), ``repeats``
    renders each with seeds of their own. Every reference row renders again, the defaults included, the rows taking
    turns within each repeat: the equal-time ratios are measured in one interleaved phase, so that the machine's
    drift between the race and this phase cannot move them. Fills the rows' ``equal_time_*`` fields; a render that
    fails leaves the row's same-spp figures and says why in ``equal_time_error``."""
    base = next((r for r in rows if r.label == "reference" and r.renderer == "reference" and not r.error
                 and r.seconds_all), None)
    if base is None:
        return
    base_seconds = float(np.mean(base.seconds_all))
    todo = [r for r in rows if r.renderer == "reference" and not r.error and r.seconds_all]
    for row in todo:
        row.equal_time_spp = (row.spp if row is base
                              else equal_time_spp(row.spp, float(np.mean(row.seconds_all)), base_seconds))
        row.equal_time_mse_all, row.equal_time_seconds_all = [], []
    renderer = get_renderer("reference")
    for attempt in range(1, repeats + 1):
        for row in todo:
            if row.equal_time_error:
                continue
            request = RenderRequest(spp=row.equal_time_spp, seed=seed + repeats + attempt, settings=dict(row.settings))
            try:
                result = renderer.render(scene, request)
            except HarnessError as err:
                row.equal_time_error = f"{err.where}: {err.message}"
                continue
            row.equal_time_seconds_all.append(result.seconds)
            row.equal_time_mse_all.append(mse_against(result.image, gt.image, gt.variance)[0])
            if on_render is not None:
                on_render(f"{scene.name}: {row.label} at equal time ({row.equal_time_spp} spp)")
    for row in rows:
        if row.equal_time_error:
            row.equal_time_mse_all, row.equal_time_seconds_all = [], []
        elif row.equal_time_seconds_all and not row.zero_variance:
            row.equal_time_efficiency = efficiency(float(np.mean(row.equal_time_mse_all)),
                                                   statistics.median(row.equal_time_seconds_all))


def equal_time_against_best(scene, rows: Sequence[Row], *, repeats: int, gt, seed: int = 1,
                            on_render: Callable[[str], None] | None = None) -> dict | None:
    """The reference's efficiency over Mitsuba's best sampler (:func:`best_mitsuba`) at equal time.

    The reference at its defaults renders at the spp that takes the best row's mean render time
    (:func:`harness.judges.efficiency.equal_time_spp`: s* = spp x t_best / t_reference, the race's spp where that is
    within 1.25 x), taken to the nearest power of two: the reference's stratified sampler is a (0, 2)-sequence per
    pixel, whose sets are whole there (at 30 spp its MSE on soft-shadows was well above what 32 give), and the
    efficiency's 1 / (MSE x s) corrects the rest of the time's difference. The best row renders at its own spp.
    ``repeats`` renders each, with seeds of their own, the two taking turns (so that drift falls on both alike); the
    ratio and its interval from those pairs (:func:`harness.judges.efficiency.efficiency_ratio`). Where s* comes to
    the race's spp, the race's own rounds serve and nothing renders again.

    Beside the race's figure at equal spp, because 1 / (MSE x s) depends on the spp where the error falls faster
    than 1 / N: with the stratified samplers both sides use, MSE ~ N^-1.2 to N^-1.6 between 16 and 256 spp on the
    Lambertian scenes (docs/performance.md), so at equal spp the slower contender's efficiency is counted at more
    samples than it could draw in the other's time, which flatters it.

    Returns None where there is no reference row or no Mitsuba row to compare; else {"mitsuba": the best row's label,
    "spp": s*, "mitsuba_spp", "mse_all", "seconds_all", "mitsuba_mse_all", "mitsuba_seconds_all", "ratio": the
    interval, "rendered": whether the pairs were rendered here, "error": None or what failed}."""
    ref = next((r for r in rows if r.label == "reference" and r.renderer == "reference" and not r.error
                and r.seconds_all and r.mse_all), None)
    best = best_mitsuba(rows)
    if ref is None or best is None or not best.seconds_all or not best.mse_all:
        return None
    spp = equal_time_spp(ref.spp, float(np.mean(ref.seconds_all)), float(np.mean(best.seconds_all)))
    if spp != ref.spp:  # the nearest power of two: where the Sobol sets are whole
        spp = 1 << max(0, round(math.log2(spp)))
    out = {"mitsuba": best.label, "spp": spp, "mitsuba_spp": best.spp, "rendered": spp != ref.spp, "error": None,
           "mse_all": list(ref.mse_all), "seconds_all": list(ref.seconds_all),
           "mitsuba_mse_all": list(best.mse_all), "mitsuba_seconds_all": list(best.seconds_all)}
    if spp != ref.spp:
        sides = {"reference": (get_renderer("reference"), spp, {}, [], []),
                 "mitsuba": (get_renderer(best.renderer), best.spp, dict(best.settings), [], [])}
        for attempt in range(1, repeats + 1):
            order = ("reference", "mitsuba") if attempt % 2 else ("mitsuba", "reference")
            for side in order:
                renderer, side_spp, settings, mse, seconds = sides[side]
                request = RenderRequest(spp=side_spp, seed=seed + 2 * repeats + attempt, settings=settings)
                try:
                    result = renderer.render(scene, request)
                except (HarnessError, ExternalRendererError) as err:
                    out["error"] = _error_text(err)
                    return dict(out, ratio=None)
                seconds.append(result.seconds)
                mse.append(mse_against(result.image, gt.image, gt.variance)[0])
                if on_render is not None:
                    label = f"reference at {spp} spp" if side == "reference" else best.label
                    on_render(f"{scene.name}: {label} (equal time)")
        out["mse_all"], out["seconds_all"] = sides["reference"][3], sides["reference"][4]
        out["mitsuba_mse_all"], out["mitsuba_seconds_all"] = sides["mitsuba"][3], sides["mitsuba"][4]
    usable = all(m > 0 for m in out["mse_all"] + out["mitsuba_mse_all"])
    out["ratio"] = (efficiency_ratio(out["mse_all"], out["seconds_all"], out["mitsuba_mse_all"],
                                     out["mitsuba_seconds_all"]) if usable else None)
    return out


def strategy_verdict(rows: Sequence[Row]) -> dict:
    """The reference's strategy rows (one setting changed from the defaults), each one's efficiency over the
    defaults' ("reference") with its 95 % interval over the repeats (per-seed MSE and seconds:
    :func:`harness.judges.efficiency.efficiency_ratio`), at the same spp and at equal time (each row at the spp that
    takes the defaults' time: :func:`equal_time_renders`); the best, decided at equal time (at the same spp where
    no row was rendered at equal time), named only when told apart from every other row
    (:func:`harness.judges.efficiency.best_separated`). At the same spp the contenders share each attempt's seed,
    which makes those intervals conservative. A row whose MSE is not above the ground truth's noise in some repeat
    has no efficiency; a row of zero variance (:func:`is_exact`) has none either and is left out of the ranking.

    Returns {"comparison": "equal time" | "same spp" (the one "label", "leader" and "tied" are decided on),
    "label": the best | None, "leader", "settings", "tied": [labels not told apart from it], "efficiency_same_spp"
    and "efficiency_equal_time" (the leader's), "relative_efficiency": {"equal time": {label: interval}, "same spp":
    {label: interval}}, "equal_time_spp": {label: spp}, "zero_variance": [labels]}."""
    ref_rows = [r for r in rows if r.renderer == "reference" and not r.error and r.mse_all]
    live = [r for r in ref_rows if not r.zero_variance]

    def usable(mse: Sequence[float], seconds: Sequence[float]) -> bool:
        return bool(mse) and all(m > 0 for m in mse) and all(t > 0 for t in seconds)

    same = {r.label: (r.mse_all, r.seconds_all) for r in live if usable(r.mse_all, r.seconds_all)}
    timed = {r.label: (r.equal_time_mse_all, r.equal_time_seconds_all) for r in live
             if r.equal_time_spp is not None and usable(r.equal_time_mse_all, r.equal_time_seconds_all)}
    comparison = EQUAL_TIME if "reference" in timed else SAME_SPP
    decision = best_separated(timed if comparison == EQUAL_TIME else same)

    def relative(samples: dict) -> dict:
        base = samples.get("reference")
        return {label: efficiency_ratio(*sample, *base) for label, sample in samples.items()
                if base is not None and label != "reference"}

    leader = next((r for r in ref_rows if r.label == decision["leader"]), None)
    return {"comparison": comparison, "label": decision["best"], "leader": decision["leader"],
            "settings": leader.settings if leader is not None else None,
            "efficiency_same_spp": leader.efficiency if leader is not None else None,
            "efficiency_equal_time": leader.equal_time_efficiency if leader is not None else None,
            "tied": decision["tied"], "relative_efficiency": {EQUAL_TIME: relative(timed), SAME_SPP: relative(same)},
            "equal_time_spp": {r.label: r.equal_time_spp for r in ref_rows if r.equal_time_spp is not None},
            "zero_variance": [r.label for r in ref_rows if r.zero_variance]}


def best_mitsuba(rows: Sequence[Row]) -> Row | None:
    """The Mitsuba row of highest efficiency (any variant and sampler raced), or None."""
    raced = [r for r in rows if r.renderer == "mitsuba" and not r.error and math.isfinite(r.efficiency)]
    return max(raced, key=lambda r: r.efficiency, default=None)


def mitsuba_key(row: Row) -> str:
    """A Mitsuba row's name in the ratios' keys: its variant, with ``_<sampler>`` for a sampler other than Mitsuba's
    default (``efficiency_vs_llvm_ad_rgb_ldsampler``)."""
    variant = row.settings.get("variant") or row.variant or "mitsuba"
    if row.settings.get("sampler", "independent") != "independent":
        variant += "_" + row.settings["sampler"]
    return variant


def ratios(rows: Sequence[Row], label: str = "reference") -> dict[str, float]:
    """Efficiency and paths/s of row ``label`` over every Mitsuba row, keyed ``efficiency_vs_<variant>`` (with
    ``_<sampler>`` added for a sampler other than Mitsuba's default), and its efficiency over the best Mitsuba
    row's (:func:`best_mitsuba`), ``efficiency_vs_mitsuba_best``."""
    mine = next((r for r in rows if r.label == label), None)
    out: dict[str, float] = {}
    if mine is None:
        return out
    for row in rows:
        if row.renderer != "mitsuba" or row.error:
            continue
        variant = mitsuba_key(row)
        out[f"efficiency_vs_{variant}"] = mine.efficiency / row.efficiency
        out[f"paths_per_second_vs_{variant}"] = mine.paths_per_second / row.paths_per_second
    best = best_mitsuba(rows)
    if best is not None:  # one of the rows above
        out["efficiency_vs_mitsuba_best"] = out[f"efficiency_vs_{mitsuba_key(best)}"]
    return out


def ratio_intervals(rows: Sequence[Row], label: str = "reference", level: float = LEVEL) -> dict[str, dict]:
    """The ratios of :func:`ratios` (the same keys) with their ``level`` confidence intervals over the timed rounds:
    efficiency (mean MSE x mean seconds of the other row over row ``label``'s) and paths/s (mean seconds of the other
    over ``label``'s: the same paths), each by :func:`harness.judges.efficiency.ratio_interval` (the delta method
    on the log, Welch's degrees of freedom). Each dict: {value, low, high, level, dof, seeds}; low and high None
    with fewer than two rounds or an MSE at the ground truth's noise; no entry for a row without its rounds."""
    mine = next((r for r in rows if r.label == label), None)
    out: dict[str, dict] = {}
    if mine is None or mine.error or not _rounds(mine):
        return out
    for row in rows:
        if row.renderer != "mitsuba" or row.error or not _rounds(row):
            continue
        variant = mitsuba_key(row)
        out[f"efficiency_vs_{variant}"] = efficiency_ratio(mine.mse_all, mine.seconds_all, row.mse_all,
                                                           row.seconds_all, level)
        out[f"paths_per_second_vs_{variant}"] = ratio_interval((row.seconds_all,), (mine.seconds_all,), level)
    best = best_mitsuba(rows)
    if best is not None and _rounds(best):  # one of the rows above: its interval, not computed again
        out["efficiency_vs_mitsuba_best"] = dict(out[f"efficiency_vs_{mitsuba_key(best)}"])
    return out


def _rounds(row: Row) -> bool:
    """Whether ``row`` holds its rounds' MSEs and seconds, paired (a row without them has no interval: its ratios
    are the point values alone)."""
    return len(row.mse_all) > 0 and len(row.mse_all) == len(row.seconds_all)


def machine_state() -> dict:
    """The machine as a race found it: the 1-, 5- and 15-minute load averages, the cores, and the CPU frequency
    governors of its cores (Linux's cpufreq; None where the kernel shows none)."""
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    governors = set()
    for path in sorted(Path("/").glob(GOVERNORS.lstrip("/"))):
        try:
            governors.add(path.read_text().strip())
        except OSError:
            continue
    return {"load_average": load, "cpu_count": os.cpu_count(), "governors": sorted(governors) or None}


def busy_reason(before: dict) -> str | None:
    """Why a race that started on a machine in state ``before`` (:func:`machine_state`) cannot certify a target:
    a 1-minute load average above :data:`BUSY_LOAD_PER_CORE` per core (other work shares the cores, and Mitsuba's
    and the reference's times do not slow alike); None on an idle machine."""
    load, cores = before.get("load_average"), before.get("cpu_count") or 1
    if load is None:
        return None
    limit = BUSY_LOAD_PER_CORE * cores
    if load[0] > limit:
        return (f"the machine was busy: load average {load[0]:.2f} before the race on {cores} cores (at most "
                f"{limit:.2f} to certify)")
    return None


def contender_ratios(rows: Sequence[Row], label: str) -> dict[str, float]:
    """Efficiency and paths/s of row ``label`` (a renderer given with ``--renderer``) over the reference's (at its
    defaults) and over every Mitsuba row's (:func:`ratios`)."""
    mine = next((r for r in rows if r.label == label), None)
    ref = next((r for r in rows if r.label == "reference" and not r.error), None)
    out: dict[str, float] = {}
    if mine is None or mine.error:
        return out
    if ref is not None:
        out["efficiency_vs_reference"] = mine.efficiency / ref.efficiency
        out["paths_per_second_vs_reference"] = mine.paths_per_second / ref.paths_per_second
    out.update(ratios(rows, label))
    return out


def renderer_label(name: str) -> str:
    """A contender's label for a renderer given by name or by file (the file's stem)."""
    return Path(name).stem if name.endswith(".toml") or "/" in name else name


def target_figures(block: dict) -> tuple[dict[str, float], dict[str, dict]]:
    """A scene's figures that targets name, and their intervals: the race's ``ratios`` and ``ratio_intervals``,
    :data:`EMBREE_FRACTION` (``embree_rate.reference_fraction`` and ``embree_rate.fraction_interval``) and the
    fresh-process race's ratio (``fresh.ratios``, ``fresh.ratio_intervals``)."""
    figures, intervals = dict(block.get("ratios") or {}), dict(block.get("ratio_intervals") or {})
    embree = block.get("embree_rate") or {}
    if embree and not embree.get("error"):
        figures[EMBREE_FRACTION] = embree.get("reference_fraction")
        if embree.get("fraction_interval") is not None:
            intervals[EMBREE_FRACTION] = embree["fraction_interval"]
    fresh = block.get("fresh") or {}
    figures.update(fresh.get("ratios") or {})
    intervals.update(fresh.get("ratio_intervals") or {})
    return figures, intervals


def check_targets(scenes: dict[str, dict]) -> list[dict]:
    """Each target of :func:`targets` on each of its scenes that was benched (``scenes``: the result's
    ``scenes``, by name): {name, scene, ratio (the measure), minimum, measured, low, high, met}; ``measured`` None
    and ``met`` None where the figure is missing or not finite (a contender skipped, an MSE at the ground truth's
    noise; the Embree row or the fresh race not run). The figures are :func:`target_figures`'. Where the scene's
    block has the figure's interval (``ratio_intervals``: every race's) ``measured`` is
    its value and a target is met only when its lower bound ``low`` clears the minimum (None without a bound:
    fewer than two rounds); the cores target compares its one figure."""
    out = []
    for target in targets():
        for name in target.scenes:
            block = scenes.get(name)
            if block is None:
                continue
            figures, intervals = target_figures(block)
            if target.measure == "cores_busy":
                ref = next((r for r in block["rows"] if r["label"] == "reference" and not r.get("error")), None)
                measured = ref["cores_busy"] if ref is not None else None
            else:
                measured = figures.get(target.measure)
            if measured is not None and not math.isfinite(measured):
                measured = None
            met = None if measured is None else bool(measured >= target.minimum)
            low = high = None
            interval = intervals.get(target.measure)
            if interval is not None:
                measured, low, high = interval.get("value"), interval.get("low"), interval.get("high")
                met = None if low is None else bool(low >= target.minimum)
            out.append({"name": target.measure, "scene": name, "ratio": target.measure, "minimum": target.minimum,
                        "measured": measured, "low": low, "high": high, "met": met})
    return out


def targets_met(checked: Sequence[dict]) -> bool:
    """Whether every checked target is met (one not measured is not)."""
    return all(t["met"] is True for t in checked)


_MEMORY_CHILD = """
import dataclasses, json, sys
from harness.core.memory import peak_rss_bytes
from harness.renderers import RenderRequest, get_renderer
from harness.scene import load_scene
scene = load_scene(sys.argv[1])
size, spp = int(sys.argv[2]), int(sys.argv[3])
scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=size, height=size))
result = get_renderer("reference").render(scene, RenderRequest(spp=spp, seed=1))
print(json.dumps({"seconds": result.seconds, "paths_per_second": result.paths / result.seconds,
                  "peak_rss_kib": peak_rss_bytes() / 1024}))
"""


def peak_memory(scene_path: Path, size: int, spp: int) -> dict:
    """Peak resident memory of a reference render of ``scene_path`` at ``size`` x ``size`` and ``spp``, in a child
    process (its VmHWM, :func:`harness.core.memory.peak_rss_bytes`: the interpreter, numba, Embree, the film's sums
    and the batches' buffers; not ru_maxrss, which the child inherits from this process)."""
    load_scene(scene_path)  # bad input fails here, with its one line
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _MEMORY_CHILD, str(scene_path), str(size), str(spp)],
                          capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"memory render failed: {proc.stderr.strip().splitlines()[-1:]}")
    summary = json.loads(proc.stdout.strip().splitlines()[-1])
    return {"scene": str(scene_path), "width": size, "height": size, "spp": spp,
            "peak_rss_mib": summary["peak_rss_kib"] / 1024.0,
            "seconds": summary["seconds"], "wall_seconds": wall, "paths_per_second": summary["paths_per_second"]}


def row_dict(row: Row) -> dict:
    return dataclasses.asdict(row)


def format_table(rows: Sequence[Row], replayed: dict | None = None) -> str:
    """A fixed-width table of the rows (one scene or several), and ``replayed`` (a scene's ``embree_rate``) as its
    last row: the replay's seconds (all phases), its combined rays per second and cores. Every figure is at the same
    spp but the last two columns: a reference strategy row's spp that takes the defaults' time and its efficiency
    there (:func:`equal_time_renders`). A row of zero variance shows "zero variance" for its efficiencies."""
    head = (f"{'scene':<13} {'contender':<34} {'seconds':>8} {'Mpaths/s':>9} {'Mrays/s':>8} {'cores':>5} "
            f"{'MSE':>10} {'eff. same spp':>13} {'embree':>6} {'equal-time spp':>14} {'eff. equal time':>15}")
    lines = [head, "-" * len(head)]
    for r in rows:
        if r.error:
            lines.append(f"{r.scene:<13} {r.label:<34} skipped: {r.error}")
            continue
        rays = f"{r.rays_per_second / 1e6:8.2f}" if r.rays_per_second else f"{'n/a':>8}"
        embree = f"{r.embree_share:6.0%}" if r.embree_share is not None else f"{'':>6}"
        floor = r.mse_raw - r.mse if math.isfinite(r.mse_raw) and math.isfinite(r.mse) else 0.0
        shown = shown_mse(r.mse, floor)
        bound = "< " + format(shown["bound"] or 0.0, ".2g")
        mse = f"{shown['value']:10.4g}" if shown["value"] is not None else f"{bound:>10}"
        eff = f"{'zero variance':>13}" if r.zero_variance else f"{r.efficiency:13.4g}"
        timed = ""
        if r.equal_time_error:
            timed = f" {'failed':>14} {'':>15}"
        elif r.equal_time_spp is not None:
            timed = f" {r.equal_time_spp:14d} " + (f"{'zero variance':>15}" if r.zero_variance
                                                   else f"{r.equal_time_efficiency:15.4g}")
        lines.append(f"{r.scene:<13} {r.label:<34} {r.seconds:8.3f} {r.paths_per_second / 1e6:9.3f} {rays} "
                     f"{r.cores_busy:5.2f} {mse} {eff} {embree}{timed}".rstrip())
    if replayed is not None:
        scene = rows[0].scene if rows else ""
        if replayed.get("error"):
            lines.append(f"{scene:<13} {embree_rate.LABEL:<34} skipped: {replayed['error']}")
        else:
            seconds = sum(v for v in replayed["seconds"].values() if math.isfinite(v))
            lines.append(f"{scene:<13} {embree_rate.LABEL:<34} {seconds:8.3f} {'n/a':>9} "
                         f"{replayed['rays_per_second'] / 1e6:8.2f} {replayed['cores_busy']:5.2f}")
    return "\n".join(lines)


def _interval_text(interval: dict) -> str:
    """"1.33 [0.99, 1.80]", or the value alone without an interval (one repeat), or "not measured"."""
    if interval.get("value") is None:
        return "not measured"
    if interval.get("low") is None:
        return f"{interval['value']:.3g}"
    return f"{interval['value']:.3g} [{interval['low']:.3g}, {interval['high']:.3g}]"


def format_best_strategy(best: dict) -> str:
    """The line that names the best reference strategy (at equal time) with its efficiency over the defaults' and
    its interval, or says that none is told apart at this budget; then every strategy's efficiency / the defaults'
    at equal time (with the spp that took the defaults' time) and at the same spp, and the rows of zero
    variance."""
    comparison = best.get("comparison", SAME_SPP)
    relative = best.get("relative_efficiency") or {}
    spp = best.get("equal_time_spp") or {}
    tail = ""
    for kind, words in ((EQUAL_TIME, "at equal time (each at the spp that takes the defaults' time)"),
                        (SAME_SPP, "at the same spp")):
        listing = "; ".join(f"{label.removeprefix('reference ')} {_interval_text(v)}"
                            + (f" at {spp[label]} spp" if kind == EQUAL_TIME and label in spp else "")
                            for label, v in (relative.get(kind) or {}).items() if v.get("value") is not None)
        if listing:
            tail += f"\nefficiency / the defaults' {words}, 95 % intervals over the repeats: {listing}"
    if best.get("zero_variance"):
        tail += ("\nzero variance (exact here: no efficiency, not ranked): "
                 + ", ".join(best["zero_variance"]))
    head = f"best reference strategy at {comparison}"
    if best.get("label"):
        ratio = (relative.get(comparison) or {}).get(best["label"])
        text = f" (efficiency / the defaults' {_interval_text(ratio)})" if ratio else ""
        return f"{head}: {best['label']}{text}, told apart from every other{tail}"
    if best.get("leader"):
        return (f"{head}: not told apart at this budget (highest efficiency: {best['leader']}; "
                f"not told apart from {', '.join(best.get('tied') or [])}){tail}")
    return f"{head}: none measured{tail}"


def format_equal_time(block: dict) -> str:
    """The line of :func:`equal_time_against_best`'s figure."""
    where = (f"the reference at {block['spp']} spp against {block['mitsuba']} at {block['mitsuba_spp']}"
             if block["rendered"] else f"both at {block['spp']} spp, the race's rounds")
    head = f"reference / Mitsuba's best at equal time ({where})"
    if block.get("error"):
        return f"{head}: not measured ({block['error']})"
    ratio = block.get("ratio")
    if ratio is None:
        return f"{head}: not measured (an MSE at or below the ground truth's noise)"
    return f"{head}: efficiency {_interval_text(ratio)} (not a target: the targets are at equal spp)"


def format_embree(embree: dict) -> str:
    """The line under a scene's table that says what the Embree row replayed and the reference's fraction of it."""
    if embree.get("error"):
        return f"{embree_rate.LABEL}: skipped: {embree['error']}"
    n = embree["rays"]
    return (f"{embree_rate.LABEL}: {embree['recorded_rays'] / 1e6:.2f} M rays of {embree['recorded_paths']} paths "
            f"recorded (camera {n['camera'] / 1e6:.2f} M, closest-hit {n['closest'] / 1e6:.2f} M, occlusion "
            f"{n['occlusion'] / 1e6:.2f} M; {embree['rays_per_path']:.2f} rays per path), {embree['replays']} timed "
            f"replays on {embree['threads']} threads, the same answers: closest-hit "
            f"{embree['closest_hit_rays_per_second'] / 1e6:.2f} Mrays/s, occlusion "
            f"{embree['occlusion_rays_per_second'] / 1e6:.2f} Mrays/s, combined {embree['rays_per_second'] / 1e6:.2f} "
            f"Mrays/s; reference rays/s / Embree's = {embree['reference_fraction']:.2f}"
            + (f" ({_interval_text(embree['fraction_interval'])}, {embree['fraction_interval'].get('level', LEVEL):.0%}"
               " interval over the rounds)" if embree.get("fraction_interval") else ""))


def run_bench(
    *,
    scenes: Sequence[str] = BENCH_SCENES,
    spp: int = DEFAULT_SPP,
    repeats: int = DEFAULT_REPEATS,
    gt_spp: int = DEFAULT_GT_SPP,
    strategies: bool = True,
    cache_dir=None,
    on_render: Callable[[str], None] | None = None,
    renderers: Sequence[str] = (),
    embree: bool = True,
    embree_rays: int = embree_rate.DEFAULT_MAX_RAYS,
    film: tuple[int, int] | None = None,
    films: dict[str, tuple[int, int]] | None = None,
    fresh: bool | Sequence[str] = False,
    rounds: dict[str, int] | None = None,
) -> dict:
    """The whole benchmark: per scene, the default contenders (:func:`default_contenders`, with the extra Mitsuba
    samplers on :func:`best_sampler_scenes`), each of ``renderers`` (any renderer name or file, at the same spp, its
    render time without start-up) and (``strategies``) the reference's strategy variations; the reference/Mitsuba
    ratios (and each other renderer's over the reference and Mitsuba); with ``embree``, Embree's own rate on the
    scene's rays (at most about ``embree_rays`` recorded: :mod:`harness.studies.embree_rate`), replayed once per
    attempt; the targets (:func:`check_targets`) on the scenes benched. ``film``: (width, height) replacing every
    scene's film (``--film``; its filter kept), recorded in the result; ``films``: the same by scene name, for the
    scenes ``film`` does not cover (``--check``'s :data:`CHECK_FILMS`), recorded in the scene's block. ``fresh``:
    True, or the names of the scenes, to race ``harness render`` in fresh processes after the warm race
    (:func:`harness.studies.fresh_race.fresh_race`, ``repeats`` rounds, the scene's block's ``fresh``).
    ``rounds``: at least this many rounds for the scenes it names (``--check``'s :data:`CHECK_ROUNDS`), recorded in
    the scene's block as ``repeats`` where it differs from ``repeats``."""
    result: dict = {"spp": spp, "repeats": repeats, "ground_truth_spp": gt_spp, "cpu_count": os.cpu_count(),
                    **({"film": list(film)} if film else {}), "machine": {"before": machine_state()}, "scenes": {}}
    for name in scenes:
        path = Path(name)
        if not path.suffix:
            path = ROOT / "scenes" / f"{name}.toml"
        scene = load_scene(path)
        size = film or (films or {}).get(scene.name)
        if size:
            scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, width=size[0], height=size[1]))
        gt = ground_truth(scene, spp=gt_spp, cache_dir=cache_dir, use_closed_form=True)
        contenders = default_contenders(spp, extra_samplers=scene.name in best_sampler_scenes())
        contenders += [Contender(renderer_label(name), name) for name in renderers]
        if strategies:
            contenders += [Contender("reference " + " ".join(f"{k}={v}" for k, v in s.items()), "reference", s)
                           for s in STRATEGIES[1:]]
        rate, rate_error = None, None
        if embree:
            try:
                rate = embree_rate.EmbreeRate(scene, spp=spp, max_rays=embree_rays)
            except HarnessError as err:
                rate_error = f"{err.where}: {err.message}"

        def between(attempt: int, rate=rate, scene=scene) -> None:
            if attempt == 0:
                rate.warm_up()
            else:
                rate.measure()
            if on_render is not None:
                on_render(f"{scene.name}: {embree_rate.LABEL}" + (" (warm-up)" if attempt == 0 else ""))

        scene_repeats = max(repeats, (rounds or {}).get(scene.name, 0))
        rows = bench_scene(scene, contenders, spp=spp, repeats=scene_repeats, gt=gt, on_render=on_render,
                           between=between if rate is not None else None)
        if strategies:
            equal_time_renders(scene, rows, repeats=scene_repeats, gt=gt, on_render=on_render)
        best = strategy_verdict(rows)
        equal_time = (equal_time_against_best(scene, rows, repeats=scene_repeats, gt=gt, on_render=on_render)
                      if scene.name in best_sampler_scenes() else None)
        result["scenes"][scene.name] = {
            "scene_file": str(path),
            "ground_truth": {"source": gt.source, "spp": gt.spp, "variant": gt.info.get("variant")
                             or gt.info.get("info", {}).get("variant")},
            "rows": [row_dict(r) for r in rows],
            "ratios": ratios(rows),
            "ratio_intervals": ratio_intervals(rows),
            "contenders": {renderer_label(name): contender_ratios(rows, renderer_label(name)) for name in renderers},
            "best_strategy": dict(best, ratios=ratios(rows, best["leader"]) if best["leader"] else {}),
            "mitsuba_best": mitsuba.label if (mitsuba := best_mitsuba(rows)) is not None else None,
        }
        if equal_time is not None:
            result["scenes"][scene.name]["equal_time_vs_mitsuba_best"] = equal_time
        if size and not film:
            result["scenes"][scene.name]["film"] = list(size)
        if scene_repeats != repeats:
            result["scenes"][scene.name]["repeats"] = scene_repeats
        if rate is not None or rate_error is not None:
            ref = next((r for r in rows if r.label == "reference" and not r.error), None)
            block = (rate.result(ref.rays_per_second if ref is not None else None) if rate is not None
                     else {"label": embree_rate.LABEL, "error": rate_error})
            if ref is not None and not block.get("error"):
                block["fraction_interval"] = embree_fraction_interval(ref, block)
            result["scenes"][scene.name]["embree_rate"] = block
        if fresh is True or (fresh and scene.name in fresh):
            result["scenes"][scene.name]["fresh"] = fresh_race.fresh_race(
                path, spp=spp, rounds=scene_repeats, film=size or None, on_render=on_render)
    result["machine"]["after"] = machine_state()
    result["machine"]["busy"] = busy_reason(result["machine"]["before"])
    result["targets"] = check_targets(result["scenes"])
    return result


def format_report(result: dict) -> str:
    """The human-readable form of :func:`run_bench`'s result."""
    out = []
    for name, block in result["scenes"].items():
        rows = [Row(**r) for r in block["rows"]]
        gt = block["ground_truth"]
        out.append(f"{name}: {rows[0].width}x{rows[0].height}"
                   + (" (--check's film for it)" if block.get("film") else "") + f", {result['spp']} spp, median of "
                   f"{block.get('repeats', result['repeats'])} "
                   f"timed renders after a warm-up; ground truth: {gt['source']} {gt['spp'] or ''} spp "
                   f"{gt['variant'] or ''}".rstrip())
        out.append(format_table(rows, block.get("embree_rate")))
        if block.get("embree_rate") is not None:
            out.append(format_embree(block["embree_rate"]))
        if block.get("fresh") is not None:
            out.append(fresh_race.format_fresh(block["fresh"]))
        ratio_text = ", ".join(f"{k} {v:.2f}" for k, v in block["ratios"].items())
        out.append(f"reference / Mitsuba: {ratio_text}"
                   + (f" (Mitsuba's best: {block['mitsuba_best']})" if block.get("mitsuba_best") else ""))
        intervals = block.get("ratio_intervals") or {}
        if intervals:
            level = next(iter(intervals.values())).get("level", LEVEL)
            out.append(f"reference / Mitsuba over the {block.get('repeats', result['repeats'])} rounds, "
                       f"{level:.0%} intervals: "
                       + ", ".join(f"{k} {_interval_text(v)}" for k, v in intervals.items()))
        if block.get("equal_time_vs_mitsuba_best") is not None:
            out.append(format_equal_time(block["equal_time_vs_mitsuba_best"]))
        for label, values in (block.get("contenders") or {}).items():
            row = next((r for r in rows if r.label == label), None)
            text = ", ".join(f"{k} {v:.3g}" for k, v in values.items() if isinstance(v, float) and math.isfinite(v))
            timing = f" (render time: {row.time_from})" if row is not None and row.time_from else ""
            out.append(f"{label} / reference and Mitsuba: {text or 'not measured'}{timing}")
        out.append(format_best_strategy(block["best_strategy"]))
        out.append("")
    for target in result.get("targets", []):
        measured = "not measured" if target["measured"] is None else f"{target['measured']:.2f}"
        if target.get("low") is not None:
            measured += f" [{target['low']:.2f}, {target['high']:.2f}]"
        state = "met" if target["met"] else "NOT met"
        out.append(f"target {target['name']} on {target['scene']} >= {target['minimum']:.2f}: {measured} ({state})")
    machine = result.get("machine") or {}
    if machine.get("before") is not None:
        out.append("machine: load average " + " -> ".join(
            str(machine[k].get("load_average")) for k in ("before", "after") if k in machine)
            + f", governors {machine['before'].get('governors')}")
    if machine.get("busy"):
        out.append(f"not certified: {machine['busy']}")
    if "memory" in result:
        m = result["memory"]
        out.append(f"peak memory: {m['peak_rss_mib']:.0f} MiB for {m['width']}x{m['height']} at {m['spp']} spp "
                   f"({m['seconds']:.1f} s render)")
    return "\n".join(out)
