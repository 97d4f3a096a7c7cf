"""``harness convergence SCENE``: error against spp and time for one or more renderers and settings, with the
fitted slope, bias detection and equal-time / equal-error comparisons (docs/report.md)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from harness.cli.common import EXIT_OK, SCENE_HELP, check_cost, progress_bar
from harness.core.limits import render_seconds
from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import parse_set, require_non_negative, require_positive
from harness.renderers import RenderRequest, get_renderer, groundtruth, renderer_names
from harness.report import write_convergence_report
from harness.scene import load_scene, scene_argument
from harness.studies.convergence import Series, parse_ladder, replace_film, run_convergence, spectrum_balance


MAX_REPEATS = 1000  # the spread of 1000 runs is known to 2 %: more would measure nothing new


class _SeriesAction(argparse.Action):
    """--renderer starts a curve; --set adds a setting to the latest curve (before any --renderer: to every curve)."""

    def __call__(self, parser, namespace, values, option_string=None):
        series = getattr(namespace, "series", None)
        if series is None:
            series = []
            namespace.series = series
        if self.dest == "renderer":
            series.append({"renderer": values, "settings": {}})
        else:
            target = series[-1]["settings"] if series else namespace.common_settings
            target.update(parse_set([values]))


def register(sub, common) -> None:
    """Add ``convergence`` to the subparsers ``sub``."""
    parser = common.own()
    parser.add_argument("scene", help=SCENE_HELP)
    parser.add_argument("--renderer", action=_SeriesAction,
                        help="starts a curve (repeatable; default: one reference curve)")
    parser.add_argument("--set", action=_SeriesAction, metavar="KEY=VALUE", dest="set",
                        help="a setting of the latest --renderer's curve (before any --renderer: of every curve)")
    parser.add_argument("--spp", default="1,2,4,8,16,32,64", type=options.spp_ladder,
                        help="spp ladder, comma-separated (default 1,2,4,8,16,32,64)")
    parser.add_argument("--seconds", type=options.seconds_ladder,
                        help="time ladder, comma-separated seconds (chunks of --chunk-spp until spent)")
    parser.add_argument("--chunk-spp", type=options.positive_int, default=1,
                        help="spp per chunk of a --seconds rung (default 1)")
    parser.add_argument("--film", type=options.film_size, help="resolution WIDTHxHEIGHT (default: the scene's)")
    parser.add_argument("--ground-truth-spp", type=options.positive_int, default=1024,
                        help="Mitsuba ground-truth spp (default 1024)")
    parser.add_argument("--seed", type=options.non_negative_int, default=1,
                        help="first seed; every render gets its own (default 1)")
    parser.add_argument("--repeats", type=options.int_type(1, MAX_REPEATS, what=f"an integer from 1 to {MAX_REPEATS}"),
                        default=1, help="independent renders (distinct seeds) per rung: E[MSE], its spread and the error "
                        "spectrum ensemble over them (default 1)")
    parser.add_argument("--k", type=options.positive_number, default=3.0,
                        help="multiple of the expected scatter that flags bias (default 3)")
    parser.set_defaults(func=run, series=None, common_settings={})
    sub.add_parser(
        "convergence", parents=[parser, common.out("output folder (default reports/convergence/<scene>)"),
                 common.json("also print convergence.json (on stdout, the other lines then on stderr)"),
                 common.quiet(), common.cache_dir(), common.mitsuba_variant(), common.allow_outside_paths()])


def run(args: argparse.Namespace) -> int:
    """Render the curves against the ground truth, write the convergence report, print each curve's slope and
    the equal-time / equal-error comparisons."""
    spp = parse_ladder(args.spp, "--spp") if args.spp else []
    seconds = parse_ladder(args.seconds, "--seconds", float) if args.seconds else []
    if not spp and not seconds:
        raise HarnessError("--spp", "give an spp ladder (e.g. --spp 1,2,4,8,16) and/or a --seconds ladder")
    for name, value in (("--ground-truth-spp", args.ground_truth_spp), ("--chunk-spp", args.chunk_spp)):
        require_positive(name, value)
    require_non_negative("--seed", args.seed)
    if not (math.isfinite(args.k) and args.k > 0):  # NaN would flag nothing, 0 everything
        raise HarnessError("--k", f"expected a positive multiple of the expected scatter, got {args.k}")
    width = height = None
    if args.film:
        w, sep, h = args.film.lower().partition("x")
        if not sep or not w.isdigit() or not h.isdigit() or int(w) < 1 or int(h) < 1:
            raise HarnessError("--film", f"expected WIDTHxHEIGHT, e.g. 32x32, got {args.film!r}")
        width, height = int(w), int(h)
    specs = getattr(args, "series", None) or [{"renderer": "reference", "settings": {}}]
    series = []
    for spec in specs:
        if spec["renderer"] not in renderer_names() and not spec["renderer"].endswith(".toml"):
            raise HarnessError("--renderer", f"expected one of {', '.join(renderer_names())}, got {spec['renderer']!r}")
        series.append(Series(spec["renderer"], {**args.common_settings, **spec["settings"]}))
    scene = replace_film(load_scene(scene_argument(args.scene)), width, height)
    if spp:
        check_cost(scene, max(spp), "--spp")
    for option, value in (("--ground-truth-spp", args.ground_truth_spp), ("--chunk-spp", args.chunk_spp)):
        check_cost(scene, value, option)  # where it is unused too (a closed-form scene, no --seconds): a typo all the same
    if seconds:  # each rung renders chunks until its seconds are spent, per curve: at most a budget's 24 h
        check_cost(scene, None, "--seconds", seconds=max(seconds))
    _check_series(scene, series, ([max(spp)] if spp else []) + ([args.chunk_spp] if seconds else []), args.seed)
    check_cost(scene, None, "--repeats", seconds=_ladder_seconds(scene, spp, seconds, args.repeats * len(series)))
    bar = progress_bar(args, f"convergence {scene.name}", "render", total=len(series) * (len(spp) + len(seconds)))
    try:
        gt = groundtruth.ground_truth(scene, spp=args.ground_truth_spp, cache_dir=args.cache_dir,
                                      variant=args.mitsuba_variant)
        result = run_convergence(scene, gt, series, spp=spp, seconds=seconds, seed=args.seed, chunk_spp=args.chunk_spp,
                                 k=args.k, variant=args.mitsuba_variant, repeats=args.repeats, spectrum=True,
                                 progress=(lambda _: bar.update(1)) if bar is not None else None)
    finally:
        if bar is not None:
            bar.close()
    out = Path(args.out) if args.out else Path("reports") / "convergence" / scene.path.stem
    paths = write_convergence_report(result, out)
    human = sys.stderr if args.json else sys.stdout  # with --json, stdout holds the JSON alone
    for s in result["series"]:
        fit = s["fit_rmse"]
        slope = "n/a" if fit.get("slope") is None else f"{fit['slope']:.3f}"
        flag = f"; flattens from {fit['departure_spp']:g} spp (bias?)" if fit.get("biased") else ""
        timing = f"; render time: {s['time_from']}" if s.get("time_from") else ""
        print(f"{s['label']}: slope of log RMSE vs log spp {slope}{flag}{timing}", file=human)
        for line in _rung_lines(s["points"]):
            print(f"  {line}", file=human)
        for warning in s.get("warnings", []):
            print(f"harness: warning: {warning}", file=sys.stderr)
    comparison = (result.get("comparisons") or {}).get("rmse_corrected")
    if comparison and comparison["equal_time"].get("time"):
        et = comparison["equal_time"]
        print(f"equal time ({et['time']:.3g} s): " + ", ".join(
            f"{k} RMSE {v:.4g}" if v is not None else f"{k} {_missing(et, k)}" for k, v in et["errors"].items()),
            file=human)
    if comparison and comparison["equal_error"].get("error"):
        ee = comparison["equal_error"]
        print(f"equal error (RMSE {ee['error']:.4g}): " + ", ".join(
            f"{k} {v:.3g} s" if v is not None else f"{k} {_missing(ee, k)}" for k, v in ee["times"].items()),
            file=human)
    if args.json:
        print(Path(paths["report_json"]).read_text())
    print(f"wrote {paths['index']} and {paths['report_json']}", file=human)
    return EXIT_OK


def _ladder_seconds(scene, spp: list[int], seconds: list[float], runs: int) -> float:
    """The estimated render time of every rung, ``runs`` times (K repeats of every curve): a --repeats whose
    whole study breaks the 24 h limit is refused before anything renders."""
    return runs * (sum(render_seconds(scene.film.width, scene.film.height, n) for n in spp) + sum(seconds))


def _rung_lines(points: list[dict]) -> list[str]:
    """Per rung: E[MSE] (corrected) with its spread over the repeats, and where the error's power lies."""
    lines = []
    for p in points:
        budget = p["budget"]
        where = f"{budget['spp']} spp" if "spp" in budget else f"{budget['seconds']:g} s"
        text = f"{where}: MSE {_num(p.get('mse_corrected'))}"
        spread = p.get("repeats")
        if spread:
            band = spread.get("mse_corrected_band") or [None, None]
            text = (f"{where}: E[MSE] {_num(p.get('mse_corrected'))} over {spread['k']} runs (sd "
                    f"{_num(spread.get('mse_corrected_std'))}, 10-90 % {_num(band[0])} .. {_num(band[1])})")
        spectrum = p.get("spectrum")
        if spectrum:
            low, high = spectrum_balance(spectrum)
            text += (f"; error spectrum: lowest tenth of frequencies {_num(low)}, upper half {_num(high)} "
                     f"(floor {_num(spectrum['floor'])} removed; the render's own variance {_num(spectrum.get('render_variance'))})")
        lines.append(text)
    return lines


def _num(value) -> str:
    return "n/a" if value is None else f"{value:.3g}"


def _missing(comparison: dict, label: str) -> str:
    """How a comparison without a value for ``label`` says so: "out of range" (beyond 2x its measured times)."""
    return "out of range" if (comparison.get("out_of_range") or {}).get(label) else "n/a"


def _check_series(scene, series, budgets: list[int], seed: int) -> None:
    """Let each built-in renderer of a convergence check its settings at the largest render it will do (the
    reference's memory and time estimates too), before the ground truth or any curve is rendered."""
    for s in series:
        check = getattr(get_renderer(s.renderer), "check", None) if s.renderer in ("reference", "mitsuba") else None
        for spp in budgets if check is not None else []:
            check(scene, RenderRequest(spp=spp, seed=seed, settings=dict(s.settings)))
