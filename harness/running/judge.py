"""Judging one case: its ground truth (:func:`ground_truth_for`), its render within the budget
(:mod:`harness.running.budget`), the comparison (:func:`harness.running.compare.compare_images`), its thresholds,
the verdict's tile maps (``pvalue.exr``, ``failing.exr``: :mod:`harness.files.verdict_maps`), its report images
(:mod:`harness.files.report_images`) and the data of the report's comparison viewer
(:mod:`harness.files.viewer_data`), as the case's record in ``results.json``
(``docs/results-schema.md``)."""

from __future__ import annotations

import dataclasses
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from harness.core.errors import HarnessError
from harness.files.cases import GROUND_TRUTH_FILE
from harness.files import imageio
from harness.files.previews import display_exposure
from harness.files.report_images import IMAGES_FOLDER, ReportImages, make_report_images
from harness.files.viewer_data import ViewerData, make_viewer_data
from harness.files.verdict_maps import write_verdict_maps
from harness.judges.floor import GROUND_TRUTH_SHARE_LIMIT, ground_truth_share, spp_for_share
from harness.renderers import RenderRequest, get_renderer, groundtruth
from harness.renderers.external import variance_metadata
from harness.renderers.mitsuba import resolve_variant
from harness.renderers.validate import validate_result
from harness.running.budget import render_with_budget
from harness.running.cases import HIGHER_IS_BETTER, Case, slug, with_case_overrides
from harness.running.compare import compare_images
from harness.scene import load_scene
from harness.scene.variants import parse_variant


def case_scene(case: Case, for_ground_truth: bool = False):
    """The case's scene: film and depth overrides, then its stress ``variant``, unless ``for_ground_truth`` and the
    variant must not change the image (then the untransformed scene is the ground truth's)."""
    render_scene, gt_scene = case_scenes(case)
    return gt_scene if for_ground_truth else render_scene


def case_scenes(case: Case):
    """(the scene the case renders, the scene its ground truth is made from), from one read of the scene file: the
    same scene unless a stress ``variant`` must not change the image (:func:`case_scene`)."""
    scene = with_case_overrides(load_scene(case.scene), case)
    if case.variant is None:
        return scene, scene
    stress_variant = parse_variant(case.variant, f"{case.scene}: variant")
    varied = stress_variant.apply(scene)
    return varied, (scene if stress_variant.judged_against_original else varied)


def ground_truth_for(case: Case, scene, cache_dir, variant: str | None, progress=None):
    """The image a case is judged against (``case.against``), as a GroundTruth: the scene's closed form, Mitsuba's
    ground truth through the cache, or another renderer's seeded render."""
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


def ground_truth_noise(case: Case, result, gt, outcome: str | None = None) -> dict | None:
    """How much the ground truth's own noise blunts the case's verdict (the record's ``ground_truth_noise``): the
    ratio of its mean variance to the test render's (:func:`harness.judges.floor.ground_truth_share`), and where it
    exceeds 1/4 a ``warning`` and the ``suggested_spp`` that would bring it under (docs/suites.md, "A ground truth
    that does not blunt the test"). A case that expects "fail" and failed (``outcome``: its planted fault was
    caught through that noise) gets the ratio and the suggestion but no warning: the noise hid nothing the case is
    for. None where either image has no variance or the test's is 0."""
    if result.variance is None or gt.variance is None:
        return None
    share = ground_truth_share(result.variance, gt.variance)
    if share is None:
        return None
    out = {"ratio": share, "limit": GROUND_TRUTH_SHARE_LIMIT, "ground_truth_spp": int(gt.spp or 0),
           "suggested_spp": None, "warning": None}
    if share > GROUND_TRUTH_SHARE_LIMIT and gt.spp:
        key = "against.spp" if case.against.kind == "renderer" else "ground_truth_spp"
        out["suggested_spp"] = spp_for_share(int(gt.spp), share)
        if case.expect == "fail" and outcome == "fail":
            return out
        out["warning"] = (f"the ground truth's mean variance is {share:.2f} x the test render's (over 1/4): its noise, "
                          f"not the test's budget, limits what the verdict can see; {key} = "
                          f"{out['suggested_spp']} would bring it under 1/4")
    return out


def unmet_requirement(case: Case) -> str | None:
    """Why the case cannot run here (a Mitsuba variant it ``requires`` is not usable: no CUDA GPU, no libLLVM),
    as the reason of its "skipped" record; None where every requirement is met."""
    for variant in case.requires:
        try:
            resolve_variant(variant)
        except HarnessError as err:
            return f"needs Mitsuba {variant}: {err.message}"
    return None


def judged_images(result, gt) -> tuple[imageio.ExrImage, imageio.ExrImage]:
    """A case's render and its ground truth as the verdict takes them: images, variances and the metadata that
    gives their degrees of freedom (the render's ``spp`` or ``variance_dof``; the ground truth's ``spp`` or ``variance_dof``)."""
    gt_meta = {"spp": str(gt.spp)} if gt.spp else {}
    if gt.info.get("variance_dof") is not None:  # another renderer's render with replicates
        gt_meta["variance_dof"] = str(int(gt.info["variance_dof"]))
    return (imageio.ExrImage(result.image, result.variance, variance_metadata(result)),
            imageio.ExrImage(gt.image, gt.variance, gt_meta))


def run_case(case: Case, out_dir: Path, *, cache_dir=None, variant=None, progress=None,
             keep: dict | None = None) -> dict:
    """Run one case; a renderer that fails makes the case an "error" with the reason, never stops the suite.
    ``keep``: where given, a dict that receives the judged images (``test``, ``ground_truth``: ExrImage), the
    render's RenderResult (``result``) and the GroundTruth (``gt``), for a caller that judges the render again
    (harness calibrate)."""
    record = case_header(case)
    start = time.perf_counter()
    missing = unmet_requirement(case)
    if missing is not None:  # nothing judged: not a failure of the renderer, not a pass
        record.update(status="skipped", ok=True, reason=missing, wall_seconds=time.perf_counter() - start)
        return record
    try:
        scene, gt_scene = case_scenes(case)
        record["film"] = {"width": scene.film.width, "height": scene.film.height}  # as rendered (with its overrides)
        gt = ground_truth_for(case, gt_scene, cache_dir, variant, progress)
        record["ground_truth"] = {
            "source": gt.source, "spp": gt.spp, "cached": gt.cached, "renders": gt.renders,
            "seconds": gt.seconds, "path": str(gt.path) if gt.path else None,
            "variant": gt.info.get("variant") or gt.info.get("info", {}).get("variant"),
            "mitsuba_version": gt.info.get("mitsuba"),
        }
        result = render_with_budget(case, scene, variant, cache_dir=cache_dir)
        validate_result(result, scene.film.width, scene.film.height)  # a bad image: this case's error, before writing
        folder = out_dir / "cases" / slug(case.name)
        # every file of the case is written into a staging folder inside its folder and moved into place at the end
        # (a full disk leaves nothing half-written, and no empty case folder); no link inside out_dir is followed
        with imageio.staged_inside(out_dir, Path("cases", slug(case.name))) as stage:
            _judge_into(stage, case, scene, result, gt, record, keep)
            stage.commit()
    except HarnessError:
        raise
    except Exception as err:  # a renderer or adapter failure fails this case only
        record.update(status="error", ok=False, reason=f"{type(err).__name__}: {err}".splitlines()[0],
                      traceback=traceback.format_exc(limit=8))
    record["wall_seconds"] = time.perf_counter() - start
    return record


def _judge_into(stage: imageio.StagedFolder, case: Case, scene, result, gt, record: dict, keep: dict | None) -> None:
    """Judge the case's render ``result`` against its ground truth ``gt``: its files (the render, the ground truth
    judged against where no cache holds it, the verdict maps, the report images, the viewer's data) written into
    ``stage.root``, and ``record`` filled in, with their paths as they will be once ``stage`` is committed."""
    staged, folder = stage.root, stage.target
    imageio.write_exr_with_preview(staged / "render.exr", result.image, result.variance, metadata={
        "renderer": result.renderer, "case": case.name, **variance_metadata(result)})
    if gt.path is None:  # a closed form or another renderer's image: kept, so the report reads what was judged
        imageio.write_exr(staged / GROUND_TRUTH_FILE, gt.image, gt.variance,
                          metadata={"case": case.name, "source": gt.source})
        record["ground_truth"]["path"] = str(folder / GROUND_TRUTH_FILE)
    maps: dict = {}
    test_image, truth_image = judged_images(result, gt)
    comparison = compare_images(test_image, truth_image, tile=case.tile, alpha=case.alpha, maps=maps)
    if keep is not None:  # harness calibrate plants errors into this very render
        keep.update(test=test_image, ground_truth=truth_image, result=result, gt=gt)
    all_metrics = dict(comparison["metrics"], bias=comparison["bias"])
    metrics = {k: all_metrics[k] for k in case.metrics if k in all_metrics}
    broken = check_thresholds(all_metrics, case.thresholds)
    verdict = comparison["verdict"]
    outcome = "pass" if verdict["verdict"] == "pass" and not broken else "fail"
    noise = ground_truth_noise(case, result, gt, outcome)
    if noise is not None:
        record["ground_truth_noise"] = noise
    caveat = groundtruth.mitsuba_caveat(scene) if gt.source == "mitsuba" else None
    if caveat is not None:
        record["ground_truth_caveat"] = caveat
    reason = verdict.get("reason", "") if verdict["verdict"] != "pass" else ""
    if broken:
        reason = "; ".join(filter(None, [reason, "threshold: " + ", ".join(broken)]))
    record.update(
        status=outcome, reason=reason, ok=outcome == case.expect, metrics=metrics, verdict=verdict,
        thresholds=case.thresholds, thresholds_broken=broken,
        render={"seconds": result.seconds, "spp": result.spp,
                "paths_per_second": result.paths / max(result.seconds, 1e-12), "rays": result.rays,
                "nonfinite_pixels": result.nonfinite_pixels, "settings": result.settings, "info": result.info,
                "exr": str(folder / "render.exr")},
    )
    tiles = maps.get("tiles")
    if tiles is not None:  # every judged case, pass or fail: the report's viewer shows them for all
        written = write_verdict_maps(staged, tiles, tile=verdict["tile"], alpha=verdict["alpha"],
                                     threshold=verdict["threshold"], height=scene.film.height,
                                     width=scene.film.width, metadata={"case": case.name})
        record["verdict_maps"] = {key: str(folder / path.name) for key, path in written.items()}
    images = report_images(case, staged, result, gt, maps.get("flip"))
    if images is not None:
        record["report_images"] = dict(images.record(), folder=str(folder / IMAGES_FOLDER))
    viewer = viewer_files(case, staged, result, gt, maps, verdict)
    if viewer is not None:
        record["viewer"] = dict(viewer.record(), folder=str(folder))


def report_images(case: Case, folder: Path, result, gt, flip) -> ReportImages | None:
    """The case's report images, written into ``folder/images`` (:func:`harness.files.report_images.make_report_images`)
    from the images as its EXRs hold them (float32); ``flip``: the comparison's FLIP ``(mean, map)``, used where it
    was computed on those very arrays. None where they cannot be made for a reason of their own (the report then
    tries again and names it in the case's section): the case's outcome stands. A file that cannot be written is a
    WriteError, which stops the run as the render's would."""
    render = np.asarray(result.image, np.float32)
    truth = np.asarray(gt.image, np.float32)
    try:
        with imageio.removed_on_failure(imageio.make_folders(folder / IMAGES_FOLDER)):  # no empty folder left
            return make_report_images(
                folder / IMAGES_FOLDER, case=case.name, renderer=case.renderer, spp=result.spp, render=render,
                render_variance=None if result.variance is None else np.asarray(result.variance, np.float32),
                truth=truth, truth_variance=(np.zeros_like(truth) if gt.variance is None
                                             else np.asarray(gt.variance, np.float32)),
                truth_source=str(gt.source or "ground truth"), truth_spp=int(gt.spp or 0),
                flip=flip if render is result.image and truth is gt.image else None)
    except HarnessError:
        raise
    except Exception:  # noqa: BLE001 - a map that cannot be drawn is the report's to name, not the case's failure
        return None


def viewer_files(case: Case, folder: Path, result, gt, maps: dict, verdict: dict) -> ViewerData | None:
    """The data of the report's comparison viewer, written into ``folder`` (``viewer.js`` and the thumbnails:
    :func:`harness.files.viewer_data.make_viewer_data`) from the images as their EXRs hold them, the comparison's
    FLIP map and the verdict's tiles (``maps``). None where they cannot be made for a reason of their own (the report
    then makes them, and names what fails): the case's outcome stands. A file that cannot be written is a
    WriteError, which stops the run as the render's would."""
    render = np.asarray(result.image, np.float32)
    truth = np.asarray(gt.image, np.float32)
    flip = maps.get("flip")
    try:
        return make_viewer_data(
            folder, name=case.name, render=render,
            render_variance=None if result.variance is None else np.asarray(result.variance, np.float32),
            truth=truth, truth_variance=None if gt.variance is None else np.asarray(gt.variance, np.float32),
            flip=flip[1] if flip is not None else None, tiles=maps.get("tiles"), tile=verdict.get("tile"),
            alpha=verdict.get("alpha"), threshold=verdict.get("threshold"), exposure=display_exposure(truth),
            labels={"render": f"{case.renderer}, {result.spp} spp",
                    "truth": f"{gt.source or 'ground truth'}" + (f", {gt.spp} spp" if gt.spp else "")})
    except HarnessError:
        raise
    except Exception:  # noqa: BLE001 - data the viewer cannot have is the report's to name, not the case's failure
        return None


def case_header(case: Case) -> dict[str, Any]:
    """The fields every record of a case starts with, whatever its outcome."""
    return {
        "name": case.name, "scene": str(case.scene), "renderer": case.renderer, "settings": case.settings,
        "budget": {"spp": case.spp} if case.spp is not None else {"seconds": case.seconds},
        "seed": case.seed, "expect": case.expect, "against": dataclasses.asdict(case.against),
        # the scene's changes a command that reproduces the case must repeat (absent where the case makes none)
        **({"max_depth": case.max_depth} if case.max_depth is not None else {}),
        **({"variant": case.variant} if case.variant is not None else {}),
        **({"requires": list(case.requires)} if case.requires else {}),
    }
