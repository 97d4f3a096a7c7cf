"""The Mitsuba 3 adapter: scene conversion, variant choice, moments and variances, and agreement with closed forms,
with Mitsuba's own Cornell box and with the reference renderer (statistical tests, see harness/judges/mc.py)."""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest
from conftest import SCENES, load_small, render_reference
from harness.judges.mc import FALSE_ALARM, image_mean, tile_chi2, z_critical, z_scores

import harness.renderers.mitsuba as mts
from harness.core.errors import HarnessError
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.mitsuba_spec import clip_planes
from harness.scene import load_scene
from harness.scene.triangulate import (
    object_to_world,
    rotate_matrix,
    scale_matrix,
    shape_triangles,
    translate_matrix,
    triangle_areas,
    unit_cube,
    unit_sphere,
)

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

CANONICAL = sorted(p.stem for p in SCENES.glob("*.toml"))
RHO = np.array([0.3, 0.5, 0.7])


@pytest.fixture(scope="module")
def variant() -> str:
    """The variant the adapter picks on this machine (probes in subprocesses, so this never crashes pytest)."""
    return mts.choose_variant()


def render_mitsuba(scene, spp: int, seed: int = 0, **settings):
    request = RenderRequest(spp=spp, seed=seed, settings={k: str(v) for k, v in settings.items()})
    return get_renderer("mitsuba").render(scene, request)


# --------------------------------------------------------------------------------------------------------------------
# Scene conversion


@pytest.mark.parametrize("name", CANONICAL)
def test_canonical_scene_dicts_load(name):
    scene = load_scene(SCENES / f"{name}.toml")
    mi = mts.import_mitsuba("scalar_rgb")
    scene_dict = mts.scene_to_mitsuba_dict(scene, "scalar_rgb")
    loaded = mi.load_dict(scene_dict)
    # Mitsuba merges non-emitting meshes that share a BSDF, so count triangles and area rather than shape objects.
    shapes = loaded.shapes()
    # spheres are analytic in every scene (as in the reference)
    analytic = ("sphere",)
    spheres = [s for s in scene.shapes if s.type in analytic]
    assert sum(not s.is_mesh() for s in shapes) == len(spheres)
    expected_triangles = sum(len(shape_triangles(s)[1]) for s in scene.shapes if s.type not in analytic)
    assert sum(s.face_count() for s in shapes if s.is_mesh()) == expected_triangles
    expected_area = sum(triangle_areas(*shape_triangles(s)).sum() for s in scene.shapes if s.type not in analytic)
    expected_area += sum(4 * math.pi * np.linalg.norm(object_to_world(s)[:3, 0]) ** 2 for s in spheres)
    area = sum(float(np.ravel(s.surface_area())[0]) for s in shapes)
    assert area == pytest.approx(expected_area, rel=1e-5)
    # one Mitsuba emitter per emitting shape and per [[emitters]] entry
    assert len(loaded.emitters()) == len(scene.lights) + len(scene.emitters)
    assert sum(s.is_emitter() for s in shapes) == len(scene.lights)
    sensor = loaded.sensors()[0]
    film = sensor.film()
    assert list(film.size()) == [scene.film.width, scene.film.height]
    expected_filter = {"box": ("BoxFilter", 0.5), "tent": ("TentFilter", 1.0), "gaussian": ("GaussianFilter", 2.0)}
    kind, radius = expected_filter[scene.film.filter]
    assert str(film.rfilter()).startswith(kind) and film.rfilter().radius() == pytest.approx(radius)
    integrator = "volpath" if scene.has_media else "path"  # a scene with media or a null material: volpath
    assert scene_dict["integrator"] == {"type": integrator, "max_depth": scene.max_depth, "rr_depth": 5}
    depth = 2**32 - 1 if scene.max_depth == -1 else scene.max_depth
    assert f"max_depth = {depth}" in str(loaded.integrator())
    params = mi.traverse(sensor)
    if "x_fov" in params:  # perspective and thin lens (an orthographic sensor has no field of view)
        fov_x = scene.camera.tan_half_fov(scene.film.width, scene.film.height)[0]
        assert math.tan(math.radians(params["x_fov"]) / 2) == pytest.approx(fov_x, rel=1e-5)
    near, far = params["near_clip"], params["far_clip"]
    assert 0 < near < far


def test_clip_planes_follow_the_scene_scale(variant):
    """A scene shrunk 1000-fold around the origin (camera included) renders the same image: Mitsuba's default
    near_clip = 0.01 would cut it all away."""
    scene = load_small("cornell-box", 16)
    shrink = np.diag([1e-3, 1e-3, 1e-3, 1.0])
    camera = dataclasses.replace(scene.camera, origin=tuple(1e-3 * np.array(scene.camera.origin)),
                                 target=tuple(1e-3 * np.array(scene.camera.target)))
    shapes = [dataclasses.replace(s, to_world=shrink @ s.to_world) for s in scene.shapes]
    small = dataclasses.replace(scene, camera=camera, shapes=shapes)
    near, far = clip_planes(small)
    assert near < 2.9e-3 * 1e-2 and 3e-3 < far < 1e-2
    a = render_mitsuba(scene, spp=16, seed=4, variant=variant)
    b = render_mitsuba(small, spp=16, seed=4, variant=variant)
    assert b.image.mean() > 0.1
    z = z_scores(image_mean(b.image, b.variance), image_mean(a.image, a.variance))
    assert np.all(np.abs(z) < z_critical(FALSE_ALARM, 3)), z


def test_cornell_box_matches_mitsubas_own(variant):
    """Our converted Cornell box and mitsuba.cornell_box() (with a box filter) render the same image from the same
    random numbers: equal up to float32 rounding of the placements."""
    scene = load_small("cornell-box", 32)
    mi = mts.import_mitsuba(variant)
    ours = mts.scene_to_mitsuba_dict(scene, variant)
    theirs = mi.cornell_box()
    theirs["sensor"]["film"].update(width=32, height=32, rfilter={"type": "box"})
    a = np.array(mi.render(mi.load_dict(ours), seed=5, spp=64), dtype=np.float64)
    b = np.array(mi.render(mi.load_dict(theirs), seed=5, spp=64), dtype=np.float64)
    differing = np.abs(a - b) > 1e-4 * np.maximum(np.abs(b), 1e-2)
    assert differing.mean() < 0.01, differing.mean()
    assert np.allclose(a.mean(axis=(0, 1)), b.mean(axis=(0, 1)), rtol=1e-4, atol=0)
    assert b.mean() > 0.1


def _mesh_version(shape, vertices, triangles):
    return dataclasses.replace(shape, type="mesh", to_world=object_to_world(shape), mesh_vertices=np.array(vertices),
                               mesh_triangles=np.array(triangles))


def test_mesh_shapes_render_like_native_ones():
    """The soft-shadow occluder as a mi.Mesh built from our arrays renders like Mitsuba's own cube from the same
    random numbers (a few pixels differ by float rounding of hit points, which changes some paths)."""
    scene = load_small("soft-shadows", 24)
    occluder = scene.shapes[1]
    assert occluder.type == "cube"
    shapes = [scene.shapes[0], _mesh_version(occluder, *unit_cube()), scene.shapes[2]]
    meshed = dataclasses.replace(scene, shapes=shapes)
    a = render_mitsuba(scene, spp=32, seed=2, variant="scalar_rgb")
    b = render_mitsuba(meshed, spp=32, seed=2, variant="scalar_rgb")
    differing = np.abs(a.image - b.image) > 1e-4 * np.maximum(np.abs(a.image), 1e-2)
    assert differing.mean() < 0.1, differing.mean()
    z = z_scores(image_mean(b.image, b.variance), image_mean(a.image, a.variance))
    assert np.all(np.abs(z) < z_critical(FALSE_ALARM, 3)), z


def mirrored_soft_shadows(width: int):
    """soft-shadows with the orientation rules exercised: the light is a rectangle facing up with flip_normals (so
    it shines down), the floor and the occluder are mirrored (negative x scale: rectangles and cubes keep their front
    side in Mitsuba), and an extra mesh cube on the floor has flip_normals (front side inward: black from outside,
    which changes the image mean by ~7 %)."""
    scene = load_small("soft-shadows", width)
    light, occluder, floor = scene.shapes
    rot_up = rotate_matrix([1, 0, 0], -90)
    light = dataclasses.replace(light, to_world=translate_matrix([0, 2, 0]) @ rot_up @ scale_matrix(0.5),
                                flip_normals=True)
    floor = dataclasses.replace(floor, to_world=rot_up @ scale_matrix([-2.5, 2.5, 2.5]))
    mirrored_occluder = dataclasses.replace(occluder, to_world=occluder.to_world @ scale_matrix([-1, 1, 1]))
    mesh = dataclasses.replace(_mesh_version(occluder, *unit_cube()), name="inside-out", flip_normals=True,
                               to_world=translate_matrix([0.6, 0.3, 0.2]) @ scale_matrix(0.2), index=3)
    return dataclasses.replace(scene, shapes=[light, mirrored_occluder, floor, mesh])


# --------------------------------------------------------------------------------------------------------------------
# Moments and variances


def test_merge_moments_equals_all_samples_at_once():
    rng = np.random.default_rng(3)
    samples = rng.gamma(0.5, 2.0, size=(200, 5, 4, 3)) + 100.0  # skewed, large mean: a cancellation-prone case
    chunks = np.split(samples, [7, 64, 65, 150])
    parts = [mts.Moments(len(c), c.sum(axis=0), (c * c).sum(axis=0)) for c in chunks]
    merged = mts.merge_moments(parts)
    reversed_merge = mts.merge_moments(parts[::-1])
    assert merged.n == 200
    np.testing.assert_allclose(merged.s1, samples.sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(merged.s2, (samples * samples).sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(reversed_merge.s1, merged.s1, rtol=1e-12)
    mean, variance = mts.mean_and_variance(merged)
    np.testing.assert_allclose(mean, samples.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(variance, samples.var(axis=0, ddof=1) / 200, rtol=1e-9)
    means = [mts.Moments.from_means(len(c), c.mean(axis=0), (c * c).mean(axis=0)) for c in chunks]
    np.testing.assert_allclose(mts.merge_moments(means).s2, merged.s2, rtol=1e-12)
    with pytest.raises(ValueError):
        mts.merge_moments([])
    one = mts.mean_and_variance(mts.Moments(1, samples[0], samples[0] ** 2))[1]
    assert np.all(np.isnan(one))


def test_moment_channels_hold_rgb_moments(variant):
    """moment(aov(path)): the m1 channels equal the RGB image, and m2 >= m1^2, pass by pass."""
    scene = load_small("cornell-box", 16)
    mi = mts.import_mitsuba(variant)
    scene_dict = mts.scene_to_mitsuba_dict(scene, variant)
    scene_dict["integrator"] = mts.moment_integrator(scene_dict["integrator"])
    loaded = mi.load_dict(scene_dict)
    out = np.array(mi.render(loaded, seed=1, spp=16), dtype=np.float64)
    m1, m2 = mts.moment_channels(loaded.integrator(), out.shape[2])
    assert out.shape[2] == 17 and m1 == [3, 4, 5] and m2 == [10, 11, 12]
    np.testing.assert_array_equal(out[..., m1], out[..., :3])
    assert np.all(out[..., m2] >= out[..., m1] ** 2 * (1 - 1e-5) - 1e-7)
    assert np.any(out[..., m2] > out[..., m1] ** 2 * 1.01)  # some pixels are noisy


def test_variance_falls_like_one_over_spp(variant):
    scene = load_small("soft-shadows", 16)
    low = render_mitsuba(scene, spp=16, seed=1, variant=variant, chunk_spp=16)
    high = render_mitsuba(scene, spp=256, seed=2, variant=variant, chunk_spp=64)
    assert low.stats["passes"] == 1 and high.stats["passes"] == 4
    ratio = low.variance.astype(np.float64).sum() / high.variance.astype(np.float64).sum()
    print(f"variance ratio 16 spp / 256 spp: {ratio:.3f} (expected 16)")
    assert 16 / 1.25 < ratio < 16 * 1.25


def test_variance_matches_the_spread_of_independent_renders(variant):
    """The per-pixel variance of the mean agrees with the variance seen across independent renders."""
    scene = load_small("soft-shadows", 12)
    renders = [render_mitsuba(scene, spp=16, seed=100 + k, variant=variant, chunk_spp=8) for k in range(40)]
    images = np.array([r.image for r in renders], dtype=np.float64)
    estimated = np.mean([r.variance for r in renders], axis=0, dtype=np.float64).sum()
    empirical = images.var(axis=0, ddof=1).sum()
    print(f"estimated / empirical variance: {estimated / empirical:.3f}")
    assert 0.8 < estimated / empirical < 1.25


# --------------------------------------------------------------------------------------------------------------------
# Closed forms and agreement with the reference


def furnace_radiance(max_depth: int) -> np.ndarray:
    if max_depth == -1:
        return 1.0 / (1.0 - RHO)
    return sum(RHO**i for i in range(max_depth))


@pytest.mark.parametrize("max_depth", [2, -1])
def test_furnace_closed_form_with_a_mesh_enclosure(variant, max_depth):
    """The furnace closed form holds for any closed enclosure: here the reference's own icosphere (subdivisions 4)
    as a Mitsuba mesh. (Mitsuba loses ~0.01 % of the energy in it, float32 cracks: a z of -7 at 2.6e5 samples;
    this budget keeps that far below the tolerance.)"""
    scene = load_small("furnace", 8)
    sphere = scene.shapes[0]
    meshed = dataclasses.replace(scene, shapes=[_mesh_version(sphere, *unit_sphere(sphere.subdivisions))])
    result = render_mitsuba(meshed, spp=32, seed=3, variant=variant, max_depth=max_depth)
    measured = image_mean(result.image, result.variance)
    z = z_scores(measured, furnace_radiance(max_depth))
    print(f"furnace (mesh) max_depth={max_depth}: mean {np.round(measured.mean, 5)} z {np.round(z, 2)}")
    assert np.all(np.abs(z) < 4.0), z


@pytest.mark.parametrize("max_depth", [2, -1])
def test_furnace_with_mitsubas_analytic_sphere(variant, max_depth):
    """furnace.toml as is: Mitsuba's analytic sphere, within 3 % of the closed form.

    Not a z-test: Mitsuba 3.9.1 is biased here (docs/mitsuba.md). For hit points that round to just outside the
    sphere, the sphere's ``sample_direction`` still uses area sampling (its inside case) while ``pdf_direction``
    returns the cone pdf (its outside case), so the MIS weights of the two strategies do not sum to one and the
    image comes out too bright, by an amount that depends on how precisely the variant places hit points on the
    sphere: here +0.06 to +0.24 % with llvm_ad_rgb, +0.34 to +0.92 % with scalar_rgb, +1.0 to +2.4 % with
    cuda_ad_rgb (on an H100). Both strategies alone are exact and noiseless here (each samples cos / pi), so the
    per-pixel variance is almost entirely that inconsistency: the bias is many standard errors whatever the budget.
    A depth off by one, a missing bounce or a lost emitter is off by 7 % or more.
    """
    result = render_mitsuba(load_small("furnace", 32), spp=64, seed=4, variant=variant, max_depth=max_depth)
    measured = image_mean(result.image, result.variance)
    expected = furnace_radiance(max_depth)
    relative = measured.mean / expected - 1
    print(f"furnace (analytic) max_depth={max_depth}: mean {np.round(measured.mean, 5)} "
          f"rel. error {np.round(relative, 5)} z {np.round(z_scores(measured, expected), 2)}")
    assert np.all(np.abs(relative) < 0.03), relative


@pytest.mark.parametrize("name, pixel_filter", [("soft-shadows", "box"), ("cornell-box", "box"), ("mirrored", "box"),
                                                ("soft-shadows", "tent"), ("cornell-box", "gaussian")])
def test_reference_and_mitsuba_agree(variant, name, pixel_filter):
    """Image means within 4.5 combined standard errors, and tile by tile (8 x 8 pixels) a chi^2-consistent sum of
    squared z-scores. Tent and Gaussian: Mitsuba splats samples into neighbouring pixels (sample_border on) where
    the reference importance-samples the filter: same expectation; Mitsuba's variances there are approximate
    (conservative) and its pixels correlated, so only the means are compared."""
    scene = mirrored_soft_shadows(32) if name == "mirrored" else load_small(name, 32)
    scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, filter=pixel_filter))
    ours = render_reference(scene, spp=128, seed=21)
    theirs = render_mitsuba(scene, spp=128, seed=22, variant=variant)
    a, b = image_mean(theirs.image, theirs.variance), image_mean(ours.image, ours.variance)
    z = z_scores(a, b)
    statistic, dof, p = tile_chi2(theirs.image - ours.image, theirs.variance + ours.variance, tile=8)
    print(f"{name}: mitsuba {np.round(a.mean, 5)} reference {np.round(b.mean, 5)} z {np.round(z, 2)} "
          f"tile chi2 {statistic:.1f} / {dof} p {p:.3g}")
    assert np.all(np.abs(z) < 4.5), z
    if pixel_filter == "box":
        assert p > FALSE_ALARM, (statistic, dof, p)


def test_comparison_with_the_reference_can_fail(variant):
    """The same comparison rejects a Mitsuba image dimmed by 2 % (soft shadows)."""
    scene = load_small("soft-shadows", 32)
    ours = render_reference(scene, spp=128, seed=21)
    theirs = render_mitsuba(scene, spp=128, seed=22, variant=variant)
    z = z_scores(image_mean(theirs.image * 0.98, theirs.variance * 0.98**2), image_mean(ours.image, ours.variance))
    assert np.all(z < -4.5), z


# --------------------------------------------------------------------------------------------------------------------
# Variant choice


@pytest.fixture
def fake_machine(monkeypatch):
    """A machine with a GPU flag, libLLVM candidates and probe outcomes chosen by the test; no file cache."""
    state = {"gpu": False, "libs": [], "works": set(), "probed": []}

    def probe(variant, libllvm=None, timeout=0):
        state["probed"].append((variant, libllvm))
        return (variant, libllvm) in state["works"]

    monkeypatch.setattr(mts, "probe_variant", probe)
    monkeypatch.setattr(mts, "probe_cache_path", lambda: None)
    monkeypatch.setattr(mts, "gpu_present", lambda: state["gpu"])
    monkeypatch.setattr(mts, "find_libllvm_candidates", lambda: list(state["libs"]))
    # the machine's own libLLVM, which an earlier test's Mitsuba import in this worker may have put in the
    # environment, is no part of the fake machine
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH", raising=False)
    mts.reset_variant_cache()
    yield state
    mts.reset_variant_cache()


def test_variant_order_cuda_then_llvm_then_scalar(fake_machine):
    m = fake_machine
    m["gpu"], m["libs"] = True, ["/x/libLLVM-15.so", "/x/libLLVM-19.so"]
    m["works"] = {("cuda_ad_rgb", None), ("llvm_ad_rgb", "/x/libLLVM-19.so"), ("scalar_rgb", None)}
    assert mts.choose_variant() == "cuda_ad_rgb"

    mts.reset_variant_cache()
    m["works"].discard(("cuda_ad_rgb", None))
    assert mts.resolve_variant() == mts.VariantChoice("llvm_ad_rgb", "/x/libLLVM-19.so")
    assert ("llvm_ad_rgb", "/x/libLLVM-15.so") in m["probed"]  # tried first, failed, next library

    mts.reset_variant_cache()
    m["probed"].clear()
    m["gpu"], m["libs"] = False, []
    assert mts.choose_variant() == "scalar_rgb"
    assert all(v != "cuda_ad_rgb" for v, _ in m["probed"])  # no GPU: CUDA is not even probed

    mts.reset_variant_cache()
    m["probed"].clear()
    assert mts.choose_variant() == "scalar_rgb"
    assert mts.choose_variant() == "scalar_rgb"
    assert m["probed"] == [("scalar_rgb", None)]  # decided once per process


def test_requested_variant_is_validated(fake_machine):
    m = fake_machine
    m["works"] = {("scalar_rgb", None)}
    assert mts.choose_variant("scalar_rgb") == "scalar_rgb"
    for bad in ("no_such_variant", "scalar_spectral", "cuda_ad_rgb", "llvm_ad_rgb"):
        with pytest.raises(HarnessError) as err:
            mts.choose_variant(bad)
        assert err.value.where == "--set variant" and bad in str(err.value)


def test_libllvm_search_order(monkeypatch, tmp_path):
    for name in ("libLLVM-15.so", "libLLVM-19.so", "libLLVM.so.17.1", "libLLVM-14.so.1", "libLLVMCore.a"):
        (tmp_path / name).write_bytes(b"")
    os.symlink(tmp_path / "libLLVM-19.so", tmp_path / "libLLVM.so.19.1")
    monkeypatch.setattr(mts, "_LIBLLVM_GLOBS", (str(tmp_path / "libLLVM*"),))
    monkeypatch.delenv("DRJIT_LIBLLVM_PATH", raising=False)
    assert mts.find_libllvm_candidates() == [str(tmp_path / "libLLVM-19.so"), str(tmp_path / "libLLVM.so.17.1")]
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", str(tmp_path / "libLLVM-15.so"))  # the user's choice comes first
    assert mts.find_libllvm_candidates()[0] == str(tmp_path / "libLLVM-15.so")
    assert mts.libllvm_version("/usr/lib/llvm-18/lib/libLLVM.so") == 18


@pytest.mark.parametrize("value", ["missing", "not-a-library"])
def test_a_bad_drjit_libllvm_path_is_one_line_naming_it(tmp_path, value):
    """``DRJIT_LIBLLVM_PATH`` naming no file, or a file that is no libLLVM, ends a Mitsuba ground truth with exit code
    2 and a last line naming the variable and what was expected (it was a traceback): Dr.Jit reads the variable when
    Mitsuba is first imported, before the harness could pass it the library its probe found."""
    import subprocess
    import sys

    path = tmp_path / "libLLVM.so"
    if value == "not-a-library":
        if not mts.find_libllvm_candidates():  # without a working libLLVM the harness renders with scalar_rgb
            pytest.skip("no libLLVM >= 16 on this machine")
        path.write_text("not a library\n")
    done = subprocess.run([sys.executable, "-m", "harness", "ground-truth", str(SCENES / "furnace.toml"), "--spp",
                           "2", "--no-closed-form", "--out", str(tmp_path / "gt.exr"), "--quiet"],
                          env={**os.environ, "DRJIT_LIBLLVM_PATH": str(path)}, capture_output=True, text=True,
                          timeout=300, check=False)
    last = done.stderr.strip().splitlines()[-1]
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert last.startswith("harness: error: DRJIT_LIBLLVM_PATH: ") and "expected the path of a libLLVM >= 16" in last
    assert not (tmp_path / "gt.exr").exists()


def test_probe_survives_a_crashing_variant():
    """A variant whose process dies or fails is just 'not usable': Dr.Jit 1.5 aborts the process on LLVM 15."""
    assert mts.probe_variant("no_such_variant") is False
    llvm15 = "/usr/lib/x86_64-linux-gnu/libLLVM-15.so"
    if os.path.exists(llvm15):
        assert mts.probe_variant("llvm_ad_rgb", llvm15) is False


# --------------------------------------------------------------------------------------------------------------------
# The renderer


def test_scalar_rgb_renders_and_records_what_it_used():
    scene = load_small("cornell-box", 16)
    progress = []
    request = RenderRequest(spp=20, seed=9, settings={"variant": "scalar_rgb", "chunk_spp": "8"},
                            progress=lambda done, total: progress.append((done, total)))
    result = get_renderer("mitsuba").render(scene, request)
    assert result.renderer == "mitsuba" and result.image.shape == (16, 16, 3) and result.image.dtype == np.float32
    assert result.variance.shape == (16, 16, 3) and result.variance.dtype == np.float32
    assert np.all(np.isfinite(result.image)) and np.all(result.variance >= 0) and result.image.mean() > 0.05
    mi = mts.import_mitsuba("scalar_rgb")
    assert result.info["variant"] == "scalar_rgb" and result.info["mitsuba_version"] == mi.__version__
    assert result.info["libllvm"] is None
    assert result.settings == {"variant": "scalar_rgb", "chunk_spp": 8, "max_depth": 8, "moments": "on",
                               "sampler": "independent", "rr_depth": 5, "spp": 20, "seed": 9}
    assert result.stats["passes"] == 3 and result.rays == {"camera": 16 * 16 * 20}
    assert progress == [(2048, 5120), (4096, 5120), (5120, 5120)]
    assert result.seconds > 0
    again = get_renderer("mitsuba").render(scene, request)
    assert again.image.tobytes() == result.image.tobytes() and again.variance.tobytes() == result.variance.tobytes()


def test_llvm_renders_deterministically_when_available():
    try:
        mts.choose_variant("llvm_ad_rgb")
    except HarnessError as err:
        pytest.skip(str(err))
    scene = load_small("cornell-box", 16)
    a = render_mitsuba(scene, spp=32, seed=5, variant="llvm_ad_rgb")
    b = render_mitsuba(scene, spp=32, seed=5, variant="llvm_ad_rgb")
    assert a.info["variant"] == "llvm_ad_rgb" and a.info["libllvm"]
    assert a.image.tobytes() == b.image.tobytes()  # box filter: bitwise deterministic
    c = render_mitsuba(scene, spp=32, seed=6, variant="llvm_ad_rgb")
    assert c.image.tobytes() != a.image.tobytes()


@pytest.mark.parametrize("settings, where", [
    ({"shadow_rays": "2"}, "--set shadow_rays"),
    ({"spp": "4"}, "--set spp"),
    ({"chunk_spp": "0"}, "--set chunk_spp"),
    ({"chunk_spp": "many"}, "--set chunk_spp"),
    ({"max_depth": "0"}, "--set max_depth"),
    ({"variant": "nope"}, "--set variant"),
    ({"moments": "maybe"}, "--set moments"),
    ({"sampler": "sobol"}, "--set sampler"),
    ({"sampler": "ldsampler"}, "--set sampler"),  # 8 spp: Mitsuba's ldsampler would round it to 16
    ({"sampler": "multijitter"}, "--set sampler"),  # not a square
])
def test_bad_settings_are_user_errors(settings, where):
    scene = load_small("soft-shadows", 4)
    with pytest.raises(HarnessError) as err:
        get_renderer("mitsuba").render(scene, RenderRequest(spp=8, settings=settings))
    assert err.value.where == where
    if where == "--set shadow_rays":
        assert "chunk_spp, integrator, max_depth, moments, sampler, variant" in str(err.value)


def test_sampler_counts_mitsuba_draws_exactly():
    assert [n for n in range(1, 70) if mts.sampler_takes("ldsampler", n)] == [4, 16, 64]
    assert [n for n in range(1, 70) if mts.sampler_takes("multijitter", n)] == [1, 4, 9, 16, 25, 36, 49, 64]
    assert [n for n in range(1, 130) if mts.sampler_takes("orthogonal", n)] == [4, 9, 25, 49, 121]
    assert all(mts.sampler_takes("independent", n) for n in range(1, 70))


def test_a_stratified_mitsuba_sampler_is_used_and_less_noisy():
    """``--set sampler=ldsampler`` reaches Mitsuba's sensor, and its image is closer to the ground truth than the
    independent sampler's at 64 spp (soft shadows, 32 x 32: measured MSE ratio about 0.3; demanded < 0.8 over 4 seeds,
    where the two MSEs' own spread is ~10 %)."""
    scene = load_small("soft-shadows", 32)
    sd = mts.scene_to_mitsuba_dict(scene, "scalar_rgb", sampler="ldsampler")
    assert sd["sensor"]["sampler"]["type"] == "ldsampler"
    truth = render_mitsuba(scene, spp=1024, seed=100, variant="scalar_rgb").image.astype(np.float64)
    mse = {}
    for sampler in ("independent", "ldsampler"):
        mse[sampler] = np.mean([np.mean((render_mitsuba(scene, spp=64, seed=s, variant="scalar_rgb", sampler=sampler)
                                         .image - truth) ** 2) for s in range(4)])
    assert mse["ldsampler"] < 0.8 * mse["independent"], mse


def test_plain_path_integrator_renders_the_moment_renders_samples():
    """``moments=off`` (Mitsuba's own ``path``, as ``harness bench`` times it) draws the same samples as the
    ``moment(aov(path))`` wrapper: the same image, without the variance."""
    scene = load_small("cornell-box", 16)
    with_moments = render_mitsuba(scene, spp=8, seed=3, variant="scalar_rgb", chunk_spp="4")
    plain = render_mitsuba(scene, spp=8, seed=3, variant="scalar_rgb", chunk_spp="4", moments="off")
    assert plain.variance is None and plain.settings["moments"] == "off" and plain.info["integrator"] == "path"
    np.testing.assert_allclose(plain.image, with_moments.image, rtol=1e-5, atol=1e-6)
