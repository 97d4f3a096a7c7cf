"""The command line: parse, call, print. User errors become one line on stderr and exit code 2."""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import select
import sys
from pathlib import Path

from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import require_non_negative, require_positive

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2
# A closed stdout (``harness ... | head``): what a shell reports for a command killed by SIGPIPE, 128 + 13. Python
# ignores SIGPIPE, so the harness sees BrokenPipeError instead, and exits quietly with this code.
EXIT_BROKEN_PIPE = 141

_OPTION_MESSAGE = re.compile(r"argument (-[^\s:]*): (.*)", re.S)


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line naming the option (and exit code 2)."""

    def error(self, message: str) -> None:  # noqa: D401 - argparse's signature
        match = _OPTION_MESSAGE.fullmatch(message)
        if match:  # "argument -s/--spp: expected ..." -> "--spp: expected ..."
            names = match[1].split("/")
            raise HarnessError(max(names, key=len), match[2])
        raise HarnessError(self.prog, message)


def _parse_set(values: list[str]) -> dict[str, str]:
    settings: dict[str, str] = {}
    for item in values:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise HarnessError("--set", f"expected key=value, got {item!r}")
        settings[key.strip()] = value.strip()
    return settings


def _progress_bar(enabled: bool, description: str):
    """A tqdm bar on stderr fed by ``progress(done, total)`` callbacks, or None when quiet / not a terminal."""
    if not enabled:
        return None, None
    from tqdm import tqdm

    bar = tqdm(total=0, desc=description, unit="path", unit_scale=True, file=sys.stderr, leave=False)

    def progress(done: int, total: int) -> None:
        if bar.total != total:
            bar.total = total
        bar.update(done - bar.n)

    return bar, progress


def cmd_render(args: argparse.Namespace) -> int:
    from harness.files import imageio
    from harness.renderers import RenderRequest, get_renderer
    from harness.scene import load_scene

    out = Path(args.out)
    if out.suffix.lower() != ".exr":
        raise HarnessError("--out", f"expected a file name ending in .exr, got {args.out!r}")
    if not out.parent.is_dir():
        raise HarnessError("--out", f"folder {str(out.parent)!r} does not exist")
    if not os.access(out.parent, os.W_OK):
        raise HarnessError("--out", f"folder {str(out.parent)!r} is not writable")
    require_positive("--spp", args.spp)
    require_non_negative("--seed", args.seed)
    scene = load_scene(args.scene)
    _check_cost(scene, args.spp, "--spp")
    renderer = get_renderer(args.renderer)
    settings = _parse_set(args.set)
    if args.mitsuba_variant:
        if renderer.name != "mitsuba":
            raise HarnessError("--mitsuba-variant", "applies to --renderer mitsuba only")
        settings["variant"] = args.mitsuba_variant
    show = not args.quiet and sys.stderr.isatty()
    bar, progress = _progress_bar(show, f"{renderer.name} {scene.name}")
    from harness.renderers.external import ExternalRendererError, variance_metadata
    from harness.renderers.validate import BadRenderError, validate_result

    try:
        result = renderer.render(scene, RenderRequest(spp=args.spp, seed=args.seed, settings=settings, progress=progress))
        validate_result(result, scene.film.width, scene.film.height, for_verdict=False)
    except (ExternalRendererError, BadRenderError) as err:  # the renderer failed, not the user's input: exit 1
        print(f"harness: render failed: {renderer.name}: {err}", file=sys.stderr)
        return EXIT_FAIL
    except HarnessError:
        raise
    except Exception as err:  # a crash inside the renderer: one line (HARNESS_DEBUG=1 shows the traceback)
        if os.environ.get("HARNESS_DEBUG"):
            raise
        print(f"harness: render failed: {renderer.name}: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
              " (HARNESS_DEBUG=1 shows the traceback)", file=sys.stderr)
        return EXIT_FAIL
    finally:
        if bar is not None:
            bar.close()
    metadata = {
        "renderer": result.renderer,
        "scene": str(scene.path),
        **variance_metadata(result),
        "seed": str(args.seed),
        "settings": json.dumps(result.settings, sort_keys=True),
    }
    imageio.write_exr(out, result.image, result.variance, metadata=metadata)
    preview = imageio.write_png_preview(imageio.preview_path(out), result.image)
    summary = _render_summary(result, scene, out, preview, args.seed)
    if args.json:
        print(json.dumps(summary, indent=2, sort_keys=False))
    else:
        print(
            f"{result.renderer}: {scene.name} {scene.film.width}x{scene.film.height}, {result.spp} spp in "
            f"{result.seconds:.2f} s ({summary['paths_per_second'] / 1e6:.3f} M paths/s, "
            f"{summary['rays_per_second'] / 1e6:.2f} M rays/s); {summary['nonfinite_pixels']} non-finite pixels\n"
            f"wrote {out} and {preview}"
        )
    return EXIT_OK


MAX_TILE = 1024  # the verdict pads the image to whole tiles: a larger tile only costs memory


def _check_cost(scene, spp: int, option: str) -> None:
    """Refuse a render of ``scene`` at ``spp`` whose memory or time estimate is absurd (harness/core/limits.py)."""
    from harness.core.limits import check_render_cost

    check_render_cost(scene.film.width, scene.film.height, spp, film_where=f"{scene.path}: film",
                      spp_where=option, film_keys=f"film.width / film.height in {scene.path}", spp_name=option)


def cmd_ground_truth(args: argparse.Namespace) -> int:
    from harness.renderers import groundtruth
    from harness.scene import load_scene

    require_positive("--spp", args.spp)
    require_positive("--chunk-spp", args.chunk_spp)
    require_non_negative("--seed", args.seed)
    scene = load_scene(args.scene)
    _check_cost(scene, args.spp, "--spp")  # with a closed form too: a budget no render could meet is a typo
    show = not args.quiet and sys.stderr.isatty()
    bar, progress = _progress_bar(show, f"ground truth {scene.name}")
    try:
        gt = groundtruth.ground_truth(
            scene, spp=args.spp, seed=args.seed, cache_dir=args.cache_dir, variant=args.mitsuba_variant,
            chunk_spp=args.chunk_spp, use_closed_form=not args.no_closed_form, progress=progress,
        )
    finally:
        if bar is not None:
            bar.close()
    summary = {
        "scene": str(scene.path), "source": gt.source, "spp": gt.spp, "cached": gt.cached, "renders": gt.renders,
        "seconds": gt.seconds, "path": str(gt.path) if gt.path else None,
        "mean_radiance": [float(v) for v in gt.image.astype(float).mean(axis=(0, 1))], "info": gt.info,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    elif gt.source == "closed-form":
        print(f"{scene.name}: closed form ({gt.info.get('closed_form')}), radiance {gt.info.get('radiance')}; no render needed")
    else:
        state = "from the cache" if gt.cached else f"rendered in {gt.seconds:.1f} s ({gt.renders} chunk renders)"
        print(f"{scene.name}: Mitsuba {gt.info.get('variant')} {gt.spp} spp, {state}\n{gt.path}")
    return EXIT_OK


def cmd_compare(args: argparse.Namespace) -> int:
    from harness.running.compare import compare_files

    if not 1 <= args.tile <= MAX_TILE:
        raise HarnessError("--tile", f"expected an integer from 1 to {MAX_TILE} (pixels per tile side), got {args.tile}")
    if not 0 < args.alpha < 1:
        raise HarnessError("--alpha", f"expected a false-alarm probability in (0, 1), got {args.alpha}")
    report = compare_files(args.test, args.reference, tile=args.tile, alpha=args.alpha)
    if args.json:
        print(json.dumps(report, indent=2, default=float))
    else:
        m = report["metrics"]
        v = report["verdict"]
        print(f"verdict: {v['verdict']}" + (f" ({v.get('reason')})" if v.get("reason") else ""))
        # a metric that is not a finite number is None (null in --json): PSNR of identical images or of an all-zero
        # reference, every metric when no pixel is finite in both images
        why = " (no pixel is finite in both images)" if not report.get("metric_pixels") else ""
        for key in ("rmse", "relmse", "mape", "psnr", "ssim", "flip"):
            if key in m:
                print(f"  {key:7s} {m[key]:.6g}" if m[key] is not None else f"  {key:7s} undefined{why}")
    return EXIT_OK if report["verdict"]["verdict"] == "pass" else EXIT_FAIL


def cmd_run(args: argparse.Namespace) -> int:
    from harness.running.suite import load_suite, run_suite

    from harness.running import executors
    from harness.running import runstate

    suite = load_suite(args.suite)
    executor = executors.make_executor(args.executor, args.workers)  # checked before anything is written
    if args.timeout is not None and not args.timeout > 0:
        raise HarnessError("--timeout", f"expected a positive number of seconds, got {args.timeout}")
    gate = _baseline_gate(args, suite)  # --baseline / --junit checked before anything runs (harness/running/baseline.py)
    out = runstate.output_folder(args.out, Path("reports") / suite.name)  # created and written to before any render
    with runstate.locked(out):  # a second run into the same folder stops here (one line naming the holder's pid)
        show = not args.quiet and sys.stderr.isatty()
        bar = None
        if show:
            from tqdm import tqdm

            bar = tqdm(total=len(suite.cases), desc=suite.name, unit="case", file=sys.stderr)

        def on_case(index: int, record: dict) -> None:
            if gate is not None:
                gate.check(suite.cases[index], record)
            if bar is not None:
                bar.set_postfix_str(f"{record['name']}: {record['status']}")
                bar.update(1)
            elif not args.quiet:
                mark = "ok " if record["ok"] else "BAD"
                print(f"[{index + 1}/{len(suite.cases)}] {mark} {record['name']}: {record['status']}"
                      + (f" ({record['reason']})" if record.get("reason") else ""), file=sys.stderr)

        done = [0]

        def on_resume(kept: int, total: int) -> None:
            done[0] = kept
            print(f"resuming: {kept} of {total} cases done", file=sys.stderr)

        def on_each(index: int, record: dict) -> None:
            done[0] += 1
            on_case(index, record)

        try:
            with runstate.interruptible():
                results = run_suite(suite, out, cache_dir=args.cache_dir, variant=args.mitsuba_variant,
                                    on_case=on_each, executor=executor, resume=not args.fresh, on_resume=on_resume,
                                    timeout=args.timeout)
        except runstate.Interrupted as stop:
            if bar is not None:
                bar.close()
                bar = None
            print(f"harness: interrupted after {done[0]} of {len(suite.cases)} cases; run again to resume",
                  file=sys.stderr)
            return stop.exit_code
        finally:
            if bar is not None:
                bar.close()
        baseline_lines = gate.finish(results, out) if gate is not None else []
        summary = results["summary"]
        print(f"{suite.name}: {summary['ok']}/{summary['cases']} cases as expected "
              f"({summary['passed']} passed, {summary['failed']} failed, {summary['errors']} errors) in "
              f"{summary['wall_seconds']:.1f} s; {summary['mitsuba_renders']} Mitsuba renders; {out / 'results.json'}")
        for name in summary["unexpected"]:
            record = next(r for r in results["cases"] if r["name"] == name)
            print(f"  unexpected: {name}: {record['status']} (expected {record['expect']}) {record.get('reason', '')}")
        for line in baseline_lines:
            print(line)
        if args.junit:
            from harness.running import junit

            print(f"junit: {junit.write(results, args.junit)}")
        _write_run_report(args, out)
    return EXIT_OK if not summary["unexpected"] else EXIT_FAIL


def _baseline_gate(args: argparse.Namespace, suite):
    """The run's baseline gate (None without --baseline); bad --baseline, --baseline-tolerance or --junit input
    is a one-line error before anything runs."""
    from harness.running import baseline
    from harness.running import junit

    gate = None
    if args.baseline:
        gate = baseline.Gate(args.baseline, suite, tolerance_options=args.baseline_tolerance,
                             cache_dir=args.cache_dir, variant=args.mitsuba_variant)
    elif args.baseline_tolerance:
        raise HarnessError("--baseline-tolerance", "applies only with --baseline FILE")
    if args.junit:
        junit.check_writable(args.junit)
    return gate


def cmd_baseline_save(args: argparse.Namespace) -> int:
    from harness.running.baseline import save_command

    return save_command(args)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from harness.running import calibrate
    from harness.running import runstate
    from harness.running.suite import load_suite

    require_positive("--seeds", args.seeds)
    suite = load_suite(args.suite)
    calibrate.select_cases(suite, args.cases)  # a --cases pattern that matches no case: one line, before any render
    out = runstate.output_folder(args.out, Path("reports") / f"{suite.name}-calibration")

    def on_progress(name: str, seed: int) -> None:
        if not args.quiet:
            print(f"  {name} seed {seed}", file=sys.stderr, flush=True)

    with runstate.locked(out):
        result = calibrate.calibrate(suite, out, seeds=args.seeds, patterns=args.cases, cache_dir=args.cache_dir,
                                     variant=args.mitsuba_variant, on_progress=on_progress)
        calibrate.write(result, out / "calibration.json")
    for line in calibrate.summary_lines(result):
        print(line)
    print(f"wrote {out / 'calibration.json'}")
    return EXIT_OK


def _write_run_report(args: argparse.Namespace, out: Path) -> None:
    """The studies and the report of a finished run (DIR/studies/, DIR/index.html, report.json, summary.md). A
    study or report that fails in its own code is one line on stderr and leaves the run's exit code alone; one
    that cannot be written (a full disk) is a WriteError: one line and exit code 2, the old files (if any) left as
    they were."""
    from harness.files.imageio import WriteError

    if getattr(args, "no_report", False):
        return
    from harness.cli import studies

    if not args.no_studies:
        studies.write_studies(args, out / "results.json", out / "studies")
    try:
        from harness.report import write_suite_report

        paths = write_suite_report(out / "results.json", out, studies.report_options(args))
        print(f"report: {paths['index']} ({paths['seconds']:.1f} s)")
    except (KeyboardInterrupt, WriteError):
        raise
    except Exception as err:  # noqa: BLE001 - the gate's result stands whatever happens to its report
        reason = " ".join(str(err).split()) or type(err).__name__
        print(f"harness: report not written: {type(err).__name__}: {reason}"[:400], file=sys.stderr)


def cmd_report(args: argparse.Namespace) -> int:
    from harness.cli import studies
    from harness.files.studies import studies_folder
    from harness.report import write_suite_report

    studies.check_report_flags(args)
    results = Path(args.results)
    out = Path(args.out) if args.out else results.parent
    studies_dir = studies_folder(out) if args.studies else None  # None: the studies beside results.json
    if args.studies:
        studies.write_studies(args, results, studies_dir)
    paths = write_suite_report(results, out, studies.report_options(args), studies_dir=studies_dir)
    print(f"wrote {paths['index']}, {paths['report_json']} and {paths['summary']} in {paths['seconds']:.1f} s")
    return EXIT_OK


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
            target.update(_parse_set([values]))


def cmd_convergence(args: argparse.Namespace) -> int:
    from harness.renderers import groundtruth
    from harness.report import write_convergence_report
    from harness.studies.convergence import Series, parse_ladder, replace_film, run_convergence
    from harness.renderers import renderer_names
    from harness.scene import load_scene

    spp = parse_ladder(args.spp, "--spp") if args.spp else []
    seconds = parse_ladder(args.seconds, "--seconds", float) if args.seconds else []
    if not spp and not seconds:
        raise HarnessError("--spp", "give an spp ladder (e.g. --spp 1,2,4,8,16) and/or a --seconds ladder")
    for name, value in (("--ground-truth-spp", args.ground_truth_spp), ("--chunk-spp", args.chunk_spp)):
        require_positive(name, value)
    require_non_negative("--seed", args.seed)
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
    scene = replace_film(load_scene(args.scene), width, height)
    if spp:
        _check_cost(scene, max(spp), "--spp")
    _check_series(scene, series, ([max(spp)] if spp else []) + ([args.chunk_spp] if seconds else []), args.seed)
    show = not args.quiet and sys.stderr.isatty()
    bar = None
    if show:
        from tqdm import tqdm

        bar = tqdm(total=len(series) * (len(spp) + len(seconds)), desc=f"convergence {scene.name}", unit="render",
                   file=sys.stderr, leave=False)
    try:
        gt = groundtruth.ground_truth(scene, spp=args.ground_truth_spp, cache_dir=args.cache_dir,
                                      variant=args.mitsuba_variant)
        result = run_convergence(scene, gt, series, spp=spp, seconds=seconds, seed=args.seed, chunk_spp=args.chunk_spp,
                                 k=args.k, variant=args.mitsuba_variant,
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
        print(f"{s['label']}: slope of log RMSE vs log spp {slope}{flag}", file=human)
    comparison = (result.get("comparisons") or {}).get("rmse_corrected")
    if comparison and comparison["equal_time"].get("time"):
        et = comparison["equal_time"]
        print(f"equal time ({et['time']:.3g} s): " + ", ".join(
            f"{k} RMSE {v:.4g}" if v is not None else f"{k} n/a" for k, v in et["errors"].items()), file=human)
    if comparison and comparison["equal_error"].get("error"):
        ee = comparison["equal_error"]
        print(f"equal error (RMSE {ee['error']:.4g}): " + ", ".join(
            f"{k} {v:.3g} s" if v is not None else f"{k} n/a" for k, v in ee["times"].items()), file=human)
    if args.json:
        print(Path(paths["report_json"]).read_text())
    print(f"wrote {paths['index']} and {paths['report_json']}", file=human)
    return EXIT_OK


def _check_series(scene, series, budgets: list[int], seed: int) -> None:
    """Let each built-in renderer of a convergence check its settings at the largest render it will do (the
    reference's memory and time estimates too), before the ground truth or any curve is rendered."""
    from harness.renderers import RenderRequest, get_renderer

    for s in series:
        check = getattr(get_renderer(s.renderer), "check", None) if s.renderer in ("reference", "mitsuba") else None
        for spp in budgets if check is not None else []:
            check(scene, RenderRequest(spp=spp, seed=seed, settings=dict(s.settings)))


def _render_summary(result, scene, out: Path, preview: Path, seed: int) -> dict:
    import numpy as np

    total_rays = sum(result.rays.values())
    seconds = max(result.seconds, 1e-12)
    return {
        "renderer": result.renderer,
        "scene": str(scene.path),
        "width": scene.film.width,
        "height": scene.film.height,
        "spp": result.spp,
        "seed": seed,
        "seconds": result.seconds,
        "paths": result.paths,
        "paths_per_second": result.paths / seconds,
        "rays": dict(result.rays, total=total_rays),
        "rays_per_second": total_rays / seconds,
        "nonfinite_pixels": result.nonfinite_pixels,
        "mean_radiance": [float(v) for v in np.mean(result.image.astype(np.float64), axis=(0, 1))],
        "settings": result.settings,
        "stats": result.stats,
        "info": result.info,
        "out": str(out),
        "preview": str(preview),
        "host": {"python": platform.python_version(), "cpus": os.cpu_count()},
    }


def _add_study_flags(parser: argparse.ArgumentParser, command: str) -> None:
    """The flags of the studies (harness/cli/studies.py), the same on ``run`` and ``report``. On ``report`` the
    --no-... flags leave a section out of the page (and, with --studies, its study out of the computing); the others
    apply only with --studies."""
    with_studies = " (with --studies)" if command == "report" else ""
    parser.add_argument("--convergence-spp", default=None if command == "report" else "1,2,4,8,16",
                        type=options.spp_ladder,
                        help=f"spp ladder of each scene's convergence study{with_studies} (default 1,2,4,8,16)")
    parser.add_argument("--strategy-spp", type=options.positive_int, default=None if command == "report" else 16,
                        help=f"spp of strategy renders no case covers{with_studies} (default 16)")
    leave, also = ("leave out", " (with --studies: and do not compute it)") if command == "report" else ("skip", "")
    parser.add_argument("--no-convergence", action="store_true",
                        help=f"{leave} the convergence {'section' if command == 'report' else 'study'}{also}")
    parser.add_argument("--no-shadow-rays", action="store_true", help=f"{leave} the shadow-ray study{also}")
    parser.add_argument("--no-strategies", action="store_true", help=f"{leave} the strategy comparison{also}")
    parser.add_argument("--no-strategy-renders", action="store_true",
                        help=f"compare only strategies the suite's cases cover{with_studies}")


def build_parser() -> argparse.ArgumentParser:
    from harness.renderers import renderer_names

    parser = _Parser(prog="harness", description="Validation and benchmark harness for Monte Carlo renderers.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    render = sub.add_parser("render", help="render a scene to an OpenEXR file (plus a PNG preview)")
    render.add_argument("scene", help="scene file (TOML, see docs/scene-format.md)")
    render.add_argument("--renderer", default="reference", help=f"one of: {', '.join(renderer_names())}, or the "
                        "path of a renderer file (.toml, docs/external-renderers.md)")
    render.add_argument("--spp", type=options.positive_int, required=True, help="viewing rays (samples) per pixel, Np")
    render.add_argument("--seed", type=options.non_negative_int, default=0,
                        help="seed of every random stream (default 0)")
    render.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="a renderer setting, e.g. direct=global-area, shadow_rays=4, rr=off, max_depth=3, sampler=independent "
             "(repeatable; see docs/reference-renderer.md)",
    )
    render.add_argument("--out", required=True, help="output .exr (R, G, B and variance.R/G/B); a .png preview is written beside it")
    render.add_argument("--json", action="store_true", help="print one JSON object with timings and counters")
    render.add_argument("--quiet", action="store_true", help="no progress bar")
    render.add_argument("--mitsuba-variant", help="Mitsuba variant for --renderer mitsuba (default: the best that works)")
    render.set_defaults(func=cmd_render)

    gt = sub.add_parser("ground-truth", help="render (or fetch from the cache) a scene's ground truth and print where it is")
    gt.add_argument("scene")
    gt.add_argument("--spp", type=options.positive_int, default=1024, help="samples per pixel (default 1024)")
    gt.add_argument("--seed", type=options.non_negative_int, default=0)
    gt.add_argument("--chunk-spp", type=options.positive_int, default=256,
                    help="samples per cached chunk (default 256)")
    gt.add_argument("--cache-dir", help="cache folder (default: $HARNESS_CACHE_DIR or the user cache dir)")
    gt.add_argument("--mitsuba-variant", help="override the Mitsuba variant (default: the best that works)")
    gt.add_argument("--no-closed-form", action="store_true", help="render with Mitsuba even if the scene has a closed form")
    gt.add_argument("--json", action="store_true")
    gt.add_argument("--quiet", action="store_true")
    gt.set_defaults(func=cmd_ground_truth)

    cmp = sub.add_parser("compare", help="metrics and a statistical verdict for a render against a reference (exit 1 on fail)")
    cmp.add_argument("test", help="the render to judge (.exr with variance.R/G/B channels)")
    cmp.add_argument("reference", help="the reference (.exr; variance channels optional for a closed form)")
    cmp.add_argument("--tile", type=options.parse_int, default=8,
                     help="tile size in pixels for the verdict (default 8)")
    cmp.add_argument("--alpha", type=options.probability, default=0.001,
                     help="false-alarm probability of the verdict (default 0.001)")
    cmp.add_argument("--json", action="store_true")
    cmp.set_defaults(func=cmd_compare)

    run = sub.add_parser("run", help="run a suite: exit 0 when every case is as expected, 1 when not, 2 on bad input")
    run.add_argument("suite", help="suite file (TOML, see docs/suites.md)")
    run.add_argument("--out", help="output folder (default reports/<suite name>)")
    run.add_argument("--cache-dir", help="ground-truth cache folder")
    run.add_argument("--mitsuba-variant", help="override the Mitsuba variant")
    run.add_argument("--quiet", action="store_true")
    run.add_argument("--no-report", action="store_true",
                     help="do not write the studies or the report (studies/, index.html, report.json)")
    run.add_argument("--executor", default="local", help="where cases run: local (a process pool, the default), "
                     "serial (in this process), dask (a Dask LocalCluster) or tcp://HOST:PORT (a Dask scheduler)")
    run.add_argument("--workers", type=options.positive_int,
                     help="worker processes of local (default 1) or dask (default 2)")
    run.add_argument("--timeout", type=options.seconds,
                     help="seconds before a case's worker is killed (default: the case's "
                     "timeout key, else 600 s for an spp budget, max(120 s, 20 x the budget) for a seconds budget)")
    run.add_argument("--fresh", action="store_true", help="ignore an earlier results.json in --out: run every case "
                     "(default: resume, keeping the cases it finished)")
    run.add_argument("--baseline", metavar="FILE", help="also fail a case whose metrics regressed against this "
                     "baseline (harness baseline save; docs/ci.md)")
    run.add_argument("--baseline-tolerance", action="append", default=[], metavar="KEY=VALUE",
                     help="override a baseline rule, e.g. relmse=1.10 (10 %% worse allowed), seconds=1.5, bias=off "
                     "(repeatable; docs/ci.md)")
    run.add_argument("--junit", metavar="FILE", help="also write JUnit XML of the run for CI (docs/ci.md)")
    run.add_argument("--no-studies", action="store_true", help="compute no study (convergence, shadow rays, "
                     "strategies) after the suite; the report then says how to get them")
    _add_study_flags(run, "run")
    run.set_defaults(func=cmd_run)

    bl = sub.add_parser("baseline", help="save a suite's metrics as a baseline that harness run --baseline gates on")
    bl_sub = bl.add_subparsers(dest="baseline_command", required=True, parser_class=_Parser)
    bls = bl_sub.add_parser("save", help="run the suite (or take --from RESULTS.json) and write its baseline")
    bls.add_argument("suite", help="suite file (TOML, see docs/suites.md)")
    bls.add_argument("--out", required=True, metavar="FILE", help="the baseline file to write (JSON)")
    bls.add_argument("--from", dest="from_results", metavar="RESULTS.json",
                     help="take this earlier run of the suite instead of running it")
    bls.add_argument("--run-out", help="output folder of the run (default reports/<suite name>-baseline)")
    bls.add_argument("--allow-unexpected", action="store_true",
                     help="write the baseline even if some cases did not end as expected")
    bls.add_argument("--cache-dir", help="ground-truth cache folder")
    bls.add_argument("--mitsuba-variant", help="override the Mitsuba variant")
    bls.add_argument("--quiet", action="store_true")
    bls.set_defaults(func=cmd_baseline_save)

    rep = sub.add_parser("report", help="write the HTML report of a suite run (index.html, report.json, summary.md)")
    rep.add_argument("results", help="a results.json written by harness run")
    rep.add_argument("--out", help="output folder (default: the results file's folder)")
    rep.add_argument("--studies", action="store_true",
                     help="compute the run's studies first (they render and time, as harness run does after its "
                     "suite), into --out's studies/; without it the report formats the studies the run wrote")
    _add_study_flags(rep, "report")
    rep.add_argument("--cache-dir", help="ground-truth cache folder (of the studies' Mitsuba renders, with --studies)")
    rep.add_argument("--mitsuba-variant", help="override the Mitsuba variant (of the studies, with --studies)")
    rep.add_argument("--quiet", action="store_true")
    rep.set_defaults(func=cmd_report)

    cv = sub.add_parser("convergence", help="error against spp and time for one or more renderers/settings, with "
                        "the fitted slope, bias detection and equal-time / equal-error comparisons")
    cv.add_argument("scene")
    cv.add_argument("--renderer", action=_SeriesAction, help="starts a curve (repeatable; default: one reference curve)")
    cv.add_argument("--set", action=_SeriesAction, metavar="KEY=VALUE", dest="set",
                    help="a setting of the latest --renderer's curve (before any --renderer: of every curve)")
    cv.add_argument("--spp", default="1,2,4,8,16,32,64", type=options.spp_ladder,
                    help="spp ladder, comma-separated (default 1,2,4,8,16,32,64)")
    cv.add_argument("--seconds", type=options.seconds_ladder,
                    help="time ladder, comma-separated seconds (chunks of --chunk-spp until spent)")
    cv.add_argument("--chunk-spp", type=options.positive_int, default=1,
                    help="spp per chunk of a --seconds rung (default 1)")
    cv.add_argument("--film", type=options.film_size, help="resolution WIDTHxHEIGHT (default: the scene's)")
    cv.add_argument("--ground-truth-spp", type=options.positive_int, default=1024,
                    help="Mitsuba ground-truth spp (default 1024)")
    cv.add_argument("--seed", type=options.non_negative_int, default=1,
                    help="first seed; every render gets its own (default 1)")
    cv.add_argument("--k", type=options.positive_number, default=3.0,
                    help="multiple of the expected scatter that flags bias (default 3)")
    cv.add_argument("--out", help="output folder (default reports/convergence/<scene>)")
    cv.add_argument("--cache-dir", help="ground-truth cache folder")
    cv.add_argument("--mitsuba-variant", help="override the Mitsuba variant")
    cv.add_argument("--json", action="store_true", help="also print convergence.json")
    cv.add_argument("--quiet", action="store_true")
    cv.set_defaults(func=cmd_convergence, series=None, common_settings={})

    cal = sub.add_parser("calibrate", help="false alarms of the verdict over many seeds, and how planted faults fail")
    cal.add_argument("suite")
    cal.add_argument("--seeds", type=options.positive_int, default=50, help="seeds per expect=pass case (default 50)")
    cal.add_argument("--cases", action="append", help="only cases whose name matches this glob (repeatable)")
    cal.add_argument("--out", help="output folder (default reports/<suite>-calibration)")
    cal.add_argument("--cache-dir")
    cal.add_argument("--mitsuba-variant")
    cal.add_argument("--quiet", action="store_true")
    cal.set_defaults(func=cmd_calibrate)
    from harness.cli.export import register as register_export

    register_export(sub)
    from harness.cli.bench import register as register_bench

    register_bench(sub)
    from harness.studies.stress import add_parser as register_stress

    register_stress(sub)
    for name in SCENE_COMMANDS:  # commands that load scene files, and so follow their mesh paths
        if name in sub.choices:
            try:
                sub.choices[name].add_argument(
                    "--allow-outside-paths", action="store_true",
                    help="let scenes name mesh files outside their own folder (default: refused)")
            except argparse.ArgumentError:  # the command defines it itself
                pass
    return parser


SCENE_COMMANDS = ("render", "ground-truth", "run", "report", "convergence", "calibrate", "stress", "bench", "export")


class _OutsidePaths:
    """With ``--allow-outside-paths``: set ``$HARNESS_ALLOW_OUTSIDE_PATHS`` (read by load_scene, inherited by worker
    processes) for the command's duration, then restore it."""

    def __init__(self, args: argparse.Namespace):
        self.allow = bool(getattr(args, "allow_outside_paths", False))

    def __enter__(self):
        from harness.scene.load import ALLOW_OUTSIDE_ENV

        self.saved = os.environ.get(ALLOW_OUTSIDE_ENV)
        if self.allow:
            os.environ[ALLOW_OUTSIDE_ENV] = "1"

    def __exit__(self, *exc):
        from harness.scene.load import ALLOW_OUTSIDE_ENV

        if self.allow:
            if self.saved is None:
                os.environ.pop(ALLOW_OUTSIDE_ENV, None)
            else:
                os.environ[ALLOW_OUTSIDE_ENV] = self.saved


def _run(argv: list[str] | None) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        with _OutsidePaths(args):
            return args.func(args)
    except HarnessError as err:
        print(f"harness: error: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("harness: interrupted", file=sys.stderr)
        return 130


def _closed(stream) -> bool:
    """Whether ``stream`` is a pipe (or socket) whose reader has gone: poll() reports an error on it."""
    try:
        poller = select.poll()
        poller.register(stream.fileno(), select.POLLOUT)
        return any(events & (select.POLLERR | select.POLLHUP) for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll() (Windows) or no file descriptor: assume closed
        return True


def _discard(stream) -> None:
    """Point ``stream``'s file descriptor at /dev/null, so that what is still buffered (flushed again at
    interpreter shutdown) goes nowhere instead of raising BrokenPipeError there."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)
    except (AttributeError, OSError, ValueError):
        pass


def main(argv: list[str] | None = None) -> int:
    """The ``harness`` command: its exit code. A closed stdout or stderr (``harness ... | head -c 10``) ends the
    command quietly with :data:`EXIT_BROKEN_PIPE` (the Python documentation's recipe for SIGPIPE)."""
    try:
        try:
            return _run(argv)
        finally:  # also after --help's SystemExit: a closed pipe shows here, not at interpreter shutdown
            sys.stdout.flush()
    except BrokenPipeError:
        broken = [stream for stream in (sys.stdout, sys.stderr) if _closed(stream)]
        if not broken:  # not ours: some other pipe (a worker's) broke
            raise
        for stream in broken:
            _discard(stream)
        return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())
