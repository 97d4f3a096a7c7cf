"""The scale study (``harness bench --scaling``): the reference and Mitsuba on a terrain of N triangles, for several N.

For each N a seeded terrain (:mod:`harness.studies.terrain`) is written, its ground truth rendered by Mitsuba at
``gt_spp`` through the ground-truth cache (:func:`harness.renderers.groundtruth.ground_truth`), and then, round after
round, the reference and Mitsuba each render it once **in a fresh process** (``python -m harness.studies.scaling``),
the two taking turns (reference, Mitsuba, reference, Mitsuba, ...) so that a change of the machine's load falls on
both. A child process measures, in its own clock:

- ``load``: the scene file to the arrays the kernels take. The reference: :func:`harness.scene.load_scene` (the
  TOML, the PLY through trimesh, the placement checks), the arrays (:func:`harness.scene.triangulate` and the
  emitter and material tables) and the render's set-up less the Embree commit (the light and surface samplers, the
  kernels' records, the compiled kernels loaded before the render's clock starts). Mitsuba: the same :func:`~harness.scene.load_scene`, then the scene as Mitsuba's dict and
  ``mi.load_dict`` (its meshes, its own acceleration structure: Mitsuba's BVH is inside its load);
- ``bvh``: the reference's Embree scene commit (``rtcCommitScene``: :class:`reference_impl.embree_c.TriangleScene`);
- ``render``: the render's own clock (no loading), and paths per second = pixels x spp / render;
- ``peak_rss``: the child's peak resident set (``VmHWM``: :func:`harness.core.memory.peak_rss_bytes`, not
  ``ru_maxrss``, which a child inherits from its parent), and ``rss_per_triangle`` = (peak - the peak after its
  imports, before the scene) / N, the bytes the scene and the render cost per triangle (the film's and the batches'
  buffers included: a constant that dominates small meshes; the table's footer gives the marginal bytes per
  triangle between consecutive sizes, (peak_b - peak_a) / (N_b - N_a)); the reference's ``load_rss``, its peak
  before the render (the arrays, before Embree and the render's buffers);
- ``mse``: mean over pixels and channels of (render - ground truth)^2 less the ground truth's own mean variance
  (:func:`harness.studies.bench.mse_against`), and ``efficiency`` = 1 / (MSE x render seconds) (Veach's efficiency of
  an estimator: 1 / (variance x cost); :func:`harness.studies.bench.efficiency`), from the mean MSE over the rounds
  and the median render time.

Each figure is the median over the rounds, with its spread (the smallest and the largest). Before the rounds, both
renderers render the smallest terrain once, untimed, so that numba's and Dr.Jit's kernel caches are filled and no
round pays a compile. Mitsuba runs ``llvm_ad_rgb`` where it works, else ``scalar_rgb``, its plain ``path``
integrator in one pass (``moments = off``), with its low-discrepancy ``ldsampler`` where that draws exactly the spp
(powers of 4; the like of the reference's stratified default, as ``harness bench``'s sampler-matched row), else its
independent sampler.
"""

from __future__ import annotations

import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from harness.core.errors import HarnessError
from harness.core.memory import peak_rss_bytes
from harness.files.entries import default_cache_dir
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.groundtruth import ground_truth
from harness.renderers.mitsuba import import_mitsuba, resolve_variant, sampler_takes
from harness.scene import load_scene
from harness.studies import terrain
from harness.studies.bench import efficiency, mse_against

DEFAULT_TRIANGLES = (10_000, 100_000, 1_000_000, 10_000_000)
DEFAULT_SIZE, DEFAULT_SPP, DEFAULT_ROUNDS, DEFAULT_GT_SPP = 256, 64, 3, 1024
#: the most triangles one size may ask (10 M take about 6 GiB in the reference, docs/performance.md, "Scale")
MAX_TRIANGLES = 100_000_000
CONTENDERS = ("reference", "mitsuba")
PACKAGE_ROOT = Path(__file__).resolve().parents[2]
SEED = 1
_SUFFIX = {"": 1, "k": 1_000, "K": 1_000, "M": 1_000_000}


def parse_triangles(text: str) -> list[int]:
    """``"10k,100k,1M,10M"`` as [10000, 100000, 1000000, 10000000]: comma-separated counts, each an integer or a
    number with ``k`` (thousand) or ``M`` (million), from 1 to :data:`MAX_TRIANGLES`, no count twice. A
    HarnessError at ``--triangles`` names the first bad one."""
    counts = []
    for item in text.split(","):
        word = item.strip()
        match = re.fullmatch(r"([0-9]+(?:\.[0-9]+)?)([kKM]?)", word)
        value = float(match[1]) * _SUFFIX[match[2]] if match else math.nan
        if not match or value != int(value) or not 1 <= value <= MAX_TRIANGLES:
            raise HarnessError("--triangles", f"expected comma-separated triangle counts from 1 to "
                                              f"{MAX_TRIANGLES // 1_000_000}M (e.g. 10k,100k,1M), got {word!r}")
        if int(value) in counts:
            raise HarnessError("--triangles", f"{word!r} ({int(value)} triangles) is given twice")
        counts.append(int(value))
    return counts


def count_text(n: int) -> str:
    """A triangle count as the option writes it: 10k, 1M, 2.5M, 1234."""
    for factor, suffix in ((1_000_000, "M"), (1_000, "k")):
        if n >= factor and n % (factor // 10) == 0:
            return f"{n / factor:g}{suffix}"
    return str(n)


def mitsuba_variant() -> str:
    """``llvm_ad_rgb`` where it works here, else ``scalar_rgb``."""
    try:
        return resolve_variant("llvm_ad_rgb").variant
    except HarnessError:
        return "scalar_rgb"


# ---- the child: one render of one contender in a fresh process -------------------------------------------------


def _child_reference(scene_path: str, spp: int, seed: int) -> tuple[dict, np.ndarray]:
    import reference_impl.embree_c as embree_c  # optional: loads numba; the reference's child alone needs it

    commit = [0.0]
    plain_init = embree_c.TriangleScene.__init__

    def timed_init(self, *args, **kwargs):  # the commit is inside TriangleScene's constructor
        start = time.perf_counter()
        plain_init(self, *args, **kwargs)
        commit[0] += time.perf_counter() - start

    embree_c.TriangleScene.__init__ = timed_init
    base = peak_rss_bytes()
    start = time.perf_counter()
    scene = load_scene(scene_path)
    scene_seconds = time.perf_counter() - start
    renderer = get_renderer("reference")
    start = time.perf_counter()
    geometry = renderer._arrays(scene)[0]  # the arrays the render below takes (it keeps them)
    array_seconds = time.perf_counter() - start
    load_rss = peak_rss_bytes()
    start = time.perf_counter()
    result = renderer.render(scene, RenderRequest(spp=spp, seed=seed))
    wall = time.perf_counter() - start
    setup = wall - result.seconds - commit[0]
    return ({"scene_seconds": scene_seconds, "array_seconds": array_seconds, "setup_seconds": setup,
             "load_seconds": scene_seconds + array_seconds + setup, "bvh_seconds": commit[0],
             "render_seconds": result.seconds, "paths": result.paths, "triangles": int(len(geometry.triangles)),
             "base_rss": base, "load_rss": load_rss, "peak_rss": peak_rss_bytes(), "variant": None}, result.image)


def _child_mitsuba(scene_path: str, spp: int, seed: int, variant: str) -> tuple[dict, np.ndarray]:
    import_mitsuba(resolve_variant(variant).variant)  # Mitsuba's import and its JIT backend: not the scene's
    base = peak_rss_bytes()
    start = time.perf_counter()
    scene = load_scene(scene_path)
    scene_seconds = time.perf_counter() - start
    settings = {"variant": variant, "moments": "off", "chunk_spp": str(spp)}
    if sampler_takes("ldsampler", spp):  # sampler-matched: a (0,2)-sequence, as the reference's default
        settings["sampler"] = "ldsampler"
    request = RenderRequest(spp=spp, seed=seed, settings=settings)
    start = time.perf_counter()
    result = get_renderer("mitsuba").render(scene, request)
    wall = time.perf_counter() - start
    setup = wall - result.seconds  # the dict, mi.load_dict (meshes, Mitsuba's BVH), the film read back
    return ({"scene_seconds": scene_seconds, "array_seconds": 0.0, "setup_seconds": setup,
             "load_seconds": scene_seconds + setup, "bvh_seconds": None, "render_seconds": result.seconds,
             "paths": result.paths, "triangles": None, "base_rss": base, "peak_rss": peak_rss_bytes(),
             "variant": result.info.get("variant")}, result.image)


def child_main(argv: Sequence[str]) -> int:
    """``python -m harness.studies.scaling CONTENDER SCENE SPP SEED IMAGE.npy [VARIANT]``: one render; its figures
    as one JSON line on stdout, its image into IMAGE.npy."""
    contender, scene_path, spp, seed, image_path = argv[:5]
    if contender == "reference":
        figures, image = _child_reference(scene_path, int(spp), int(seed))
    else:
        figures, image = _child_mitsuba(scene_path, int(spp), int(seed), argv[5])
    np.save(image_path, np.asarray(image, dtype=np.float32))
    print(json.dumps(figures))
    return 0


# ---- the parent: rounds, medians, the table --------------------------------------------------------------------


def run_child(contender: str, scene: Path, spp: int, seed: int, variant: str, folder: Path) -> tuple[dict, np.ndarray]:
    """One render in a fresh process; its figures and image, or ({"error": ...}, None) when it failed (the last line
    of its stderr; a kill by a signal named, e.g. SIGKILL from the kernel's out-of-memory killer)."""
    image_path = folder / f"{contender}.npy"
    argv = [sys.executable, "-m", "harness.studies.scaling", contender, str(scene), str(spp), str(seed),
            str(image_path), variant]
    env = dict(os.environ)  # the child imports this harness, wherever it was started from
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(PACKAGE_ROOT), env.get("PYTHONPATH")]))
    proc = subprocess.run(argv, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        if proc.returncode < 0:
            return {"error": f"killed by signal {-proc.returncode} (out of memory?)"}, None
        last = (proc.stderr.strip().splitlines() or ["exit code %d" % proc.returncode])[-1]
        return {"error": last[:300]}, None
    figures = json.loads(proc.stdout.strip().splitlines()[-1])
    image = np.load(image_path)
    image_path.unlink()
    return figures, image


def _spread(values: list[float]) -> dict:
    """Median, smallest and largest of ``values`` (None for an empty list)."""
    if not values:
        return {"median": None, "low": None, "high": None}
    return {"median": statistics.median(values), "low": min(values), "high": max(values)}


def summarise(triangles: int, contender: str, rounds: list[dict], width: int, height: int, spp: int) -> dict:
    """A row of the table: the medians and spreads of the rounds' figures, the peak RSS per triangle, the
    efficiency from the mean MSE and the median render time."""
    good = [r for r in rounds if "error" not in r]
    row = {"triangles": triangles, "contender": contender, "rounds": rounds,
           "error": next((r["error"] for r in rounds if "error" in r), None)}
    for key in ("load_seconds", "bvh_seconds", "render_seconds", "scene_seconds", "array_seconds", "setup_seconds",
                "peak_rss"):
        row[key] = _spread([r[key] for r in good if r.get(key) is not None])
    per_triangle = [(r["peak_rss"] - r["base_rss"]) / triangles for r in good]
    row["rss_per_triangle"] = _spread(per_triangle)
    seconds = row["render_seconds"]["median"]
    row["paths_per_second"] = width * height * spp / seconds if seconds else None
    mse = [r["mse"] for r in good]
    row["mse"] = float(np.mean(mse)) if mse else None
    row["efficiency"] = efficiency(row["mse"], seconds) if mse and seconds else None
    row["variant"] = next((r.get("variant") for r in good if r.get("variant")), None)
    return row


def run_scaling(
    *,
    triangles: Sequence[int] = DEFAULT_TRIANGLES,
    size: int = DEFAULT_SIZE,
    spp: int = DEFAULT_SPP,
    rounds: int = DEFAULT_ROUNDS,
    gt_spp: int = DEFAULT_GT_SPP,
    cache_dir: Path | str | None = None,
    folder: Path | str | None = None,
    say: Callable[[str], None] | None = None,
) -> dict:
    """The scale study (module docstring): per triangle count, the reference and Mitsuba in ``rounds`` interleaved
    rounds of fresh processes at ``size`` x ``size`` and ``spp``, against a Mitsuba ground truth of ``gt_spp``.
    The terrains are written into ``folder`` (default: ``terrains`` in the cache folder)."""
    say = say or (lambda text: None)
    root = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    folder = Path(folder) if folder is not None else root / "terrains"
    variant = mitsuba_variant()
    result = {"size": size, "spp": spp, "rounds": rounds, "ground_truth_spp": gt_spp, "mitsuba_variant": variant,
              "seed": SEED, "cpu_count": os.cpu_count(), "load_average_before": list(os.getloadavg()),
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "rows": [], "ratios": {}}
    scenes = {}
    for n in triangles:
        say(f"terrain {count_text(n)}: writing")
        written = terrain.write_terrain(folder, n, seed=SEED, size=size)
        scenes[n] = written.scene
    with tempfile.TemporaryDirectory(prefix="harness-scaling-") as tmp:
        work = Path(tmp)
        smallest = min(triangles)
        for contender in CONTENDERS:  # fills numba's and Dr.Jit's kernel caches: no round pays a compile
            say(f"warm-up: {contender} on terrain {count_text(smallest)}")
            figures, _ = run_child(contender, scenes[smallest], spp, SEED, variant, work)
            if "error" in figures:
                say(f"warm-up: {contender}: {figures['error']}")
        for n in triangles:
            say(f"terrain {count_text(n)}: ground truth (Mitsuba, {gt_spp} spp, cached)")
            scene = load_scene(scenes[n])
            gt = ground_truth(scene, spp=gt_spp, cache_dir=cache_dir, use_closed_form=False)
            del scene
            per = {c: [] for c in CONTENDERS}
            for r in range(rounds):
                for contender in CONTENDERS:
                    figures, image = run_child(contender, scenes[n], spp, SEED + 1 + r, variant, work)
                    if image is not None:
                        figures["mse"], figures["mse_raw"] = mse_against(image, gt.image, gt.variance)
                        say(f"terrain {count_text(n)}: {contender} round {r + 1}/{rounds}: load "
                            f"{figures['load_seconds']:.2f} s, render {figures['render_seconds']:.2f} s, peak "
                            f"{figures['peak_rss'] / 2**20:.0f} MiB")
                    else:
                        say(f"terrain {count_text(n)}: {contender} round {r + 1}/{rounds}: {figures['error']}")
                    per[contender].append(figures)
            rows = [summarise(n, c, per[c], size, size, spp) for c in CONTENDERS]
            result["rows"] += rows
            ref, mit = rows
            result["ratios"][str(n)] = {
                "efficiency": ref["efficiency"] / mit["efficiency"] if ref["efficiency"] and mit["efficiency"]
                else None,
                "paths_per_second": ref["paths_per_second"] / mit["paths_per_second"]
                if ref["paths_per_second"] and mit["paths_per_second"] else None,
                "load_seconds": ref["load_seconds"]["median"] / mit["load_seconds"]["median"]
                if ref["load_seconds"]["median"] and mit["load_seconds"]["median"] else None,
                "peak_rss": ref["peak_rss"]["median"] / mit["peak_rss"]["median"]
                if ref["peak_rss"]["median"] and mit["peak_rss"]["median"] else None}
    result["load_average_after"] = list(os.getloadavg())
    return result


def _cell(spread: dict, scale: float = 1.0, digits: int = 2) -> str:
    """"median (low-high)", or "-" when nothing was measured."""
    if spread["median"] is None:
        return "-"
    m, lo, hi = (spread[k] * scale for k in ("median", "low", "high"))
    return f"{m:.{digits}f}" if lo == hi else f"{m:.{digits}f} ({lo:.{digits}f}-{hi:.{digits}f})"


COLUMNS = ("triangles", "contender", "load s", "BVH s", "render s", "Mpaths/s", "peak RSS MiB", "B/triangle", "MSE",
           "efficiency", "eff. ref/Mitsuba")


def format_table(result: dict) -> str:
    """The scale table: one line per (triangle count, contender), medians with the rounds' range in brackets."""
    lines = [f"scale: terrain at {result['size']}x{result['size']}, {result['spp']} spp, median (range) of "
             f"{result['rounds']} rounds in fresh processes, reference and Mitsuba {result['mitsuba_variant']} "
             f"taking turns; ground truth Mitsuba at {result['ground_truth_spp']} spp; {result['date']}, load "
             f"average {result['load_average_before'][0]:.2f} before, {result['load_average_after'][0]:.2f} after"]
    widths = (9, 9, 18, 17, 18, 8, 18, 14, 10, 10, 16)
    lines.append("  ".join(f"{c:<{w}}" for c, w in zip(COLUMNS, widths)).rstrip())
    lines.append("-" * len(lines[-1]))
    for row in result["rows"]:
        n = row["triangles"]
        if row["error"] and row["render_seconds"]["median"] is None:
            lines.append(f"{count_text(n):<9}  {row['contender']:<9}  failed: {row['error']}")
            continue
        ratio = result["ratios"].get(str(n), {}).get("efficiency") if row["contender"] == "reference" else None
        cells = (count_text(n), row["contender"], _cell(row["load_seconds"]), _cell(row["bvh_seconds"]),
                 _cell(row["render_seconds"]),
                 f"{row['paths_per_second'] / 1e6:.3g}" if row["paths_per_second"] else "-",
                 _cell(row["peak_rss"], 1 / 2**20, 0), _cell(row["rss_per_triangle"], 1.0, 0),
                 f"{row['mse']:.3g}" if row["mse"] is not None else "-",
                 f"{row['efficiency']:.3g}" if row["efficiency"] else "-",
                 f"{ratio:.2f}" if ratio else "")
        lines.append("  ".join(f"{c:<{w}}" for c, w in zip(cells, widths)).rstrip())
    marginal = marginal_bytes(result)
    for contender, steps in marginal.items():
        if steps:
            lines.append(f"{contender}: peak RSS per added triangle " + ", ".join(
                f"{count_text(a)}->{count_text(b)} {v:.0f} B" for a, b, v in steps))
    return "\n".join(lines)


def marginal_bytes(result: dict) -> dict[str, list[tuple[int, int, float]]]:
    """Per contender, (N_a, N_b, (peak_b - peak_a) / (N_b - N_a)) between consecutive triangle counts measured:
    the bytes one more triangle costs, free of the constant (interpreter, kernels, film and batch buffers)."""
    out: dict[str, list] = {}
    for contender in CONTENDERS:
        points = sorted((row["triangles"], row["peak_rss"]["median"]) for row in result["rows"]
                        if row["contender"] == contender and row["peak_rss"]["median"] is not None)
        out[contender] = [(a, b, (pb - pa) / (b - a)) for (a, pa), (b, pb) in zip(points, points[1:])]
    return out


if __name__ == "__main__":
    sys.exit(child_main(sys.argv[1:]))
