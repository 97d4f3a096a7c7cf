"""[[emitters]] through Mitsuba 3 (docs/mitsuba.md, "Emitters"; docs/scene-format.md, "Emitters"): the adapter's
plugins against closed forms, the envmap mapping and the spot falloff the docs state, the ground-truth key, and the
exports (Mitsuba XML that renders like the adapter, glTF with KHR_lights_punctual).

Every render is scalar_rgb, at most 16 x 16 pixels. A statistical comparison states its false-alarm probability:
each z-test and each tile chi-square test below rejects a correct renderer with probability FALSE_ALARM (1e-4)."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from harness.cli import main
from harness.core.errors import HarnessError
from harness.files.imageio import read_exr, write_exr
from harness.judges.mc import FALSE_ALARM, image_mean, tile_chi2, z_critical, z_scores
from harness.judges.verdict import verdict
from harness.renderers import RenderRequest, get_renderer
from harness.renderers.export import export_losses, export_scene
from harness.renderers.external import combine_repeats
from harness.renderers.groundtruth import ground_truth, scene_digest
from harness.renderers.mitsuba import import_mitsuba, scene_to_mitsuba_dict
from harness.scene import load_scene
from harness.scene.kinds.emitters import LUMENS_PER_WATT
from harness.scene.triangulate import rotate_matrix

VARIANT = "scalar_rgb"
RHO = [0.2, 0.5, 0.8]
FLOOR = """
[[shapes]]
name = "floor"
type = "rectangle"
material = "grey"
rotate = { axis = [1, 0, 0], angle = -90 }
scale = 3
"""
Z3 = z_critical(FALSE_ALARM, 3)  # one z per channel


def toml_vector(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def scene_file(folder: Path, emitters: list[str], *, shapes: str = FLOOR, origin=(0, 3, 0), target=(0, 0, 0),
               up=(0, 0, -1), fov: float = 40, size=(16, 16), depth: int = 2, rho=RHO, name="scene") -> Path:
    """A scene file: a camera (by default 3 above the floor, looking straight down, image top toward -z), one grey
    material, ``shapes`` (TOML) and one [[emitters]] entry per body."""
    text = f"""name = "{name}"
[camera]
origin = {toml_vector(origin)}
target = {toml_vector(target)}
up = {toml_vector(up)}
fov = {fov}
[film]
width = {size[0]}
height = {size[1]}
[integrator]
max_depth = {depth}
[materials.grey]
reflectance = {toml_vector(rho)}
{shapes}
""" + "".join(f"\n[[emitters]]\n{body}\n" for body in emitters)
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path


def render(scene, spp: int, seed: int = 0, **settings):
    request = RenderRequest(spp=spp, seed=seed, settings={"variant": VARIANT, **{k: str(v) for k, v in settings.items()}})
    return get_renderer("mitsuba").render(scene, request)


def floor_points(scene, sub: int = 16) -> np.ndarray:
    """Where the camera rays through a sub x sub grid of each pixel hit the floor y = 0: (H, sub, W, sub, 3)."""
    width, height = scene.film.width, scene.film.height
    offsets = (np.arange(sub) + 0.5) / sub
    film_x, film_y = np.meshgrid((np.arange(width)[:, None] + offsets).ravel(),
                                 (np.arange(height)[:, None] + offsets).ravel())
    origins, directions = scene.camera.generate_rays(film_x.ravel(), film_y.ravel(), width, height)
    points = origins - (origins[:, 1] / directions[:, 1])[:, None] * directions
    assert np.all(np.abs(points[:, [0, 2]]) < 3), "the floor fills the image"
    return points.reshape(height, sub, width, sub, 3)


def floor_pixels(scene, radiance, sub: int = 16) -> np.ndarray:
    """Each pixel's exact expectation (box filter) when every camera ray hits the floor: the mean of
    ``radiance(points)`` over a sub x sub grid of the pixel (midpoint rule; its error is orders of magnitude below
    the noise here)."""
    points = floor_points(scene, sub)
    return radiance(points.reshape(-1, 3)).reshape(points.shape).mean(axis=(1, 3))


def against_closed_form(result, expected: np.ndarray, label: str, tile: int = 4):
    """z-scores of the image mean and the tile chi-square of the per-pixel differences, each at FALSE_ALARM."""
    z = z_scores(image_mean(result.image, result.variance), expected.reshape(-1, 3).mean(axis=0))
    statistic, dof, p = tile_chi2(result.image - expected, result.variance, tile)
    print(f"{label}: z {np.round(z, 2)} (|z| < {Z3:.2f}), tile chi2 {statistic:.1f} / {dof} p {p:.3g}")
    return z, p


# --------------------------------------------------------------------------------------------------------------------
# Closed forms


@pytest.mark.slow
def test_point_light_over_a_diffuse_floor(tmp_path):
    """L = rho / pi * I cos(theta) / r^2, cos(theta) = h / r at height h; and the same test rejects I / r^2."""
    position, intensity = np.array([0.3, 1.0, -0.2]), np.array([2.0, 3.0, 4.0])
    scene = load_scene(scene_file(tmp_path, [
        f'type = "point"\nposition = {toml_vector(position)}\nintensity = {toml_vector(intensity)}']))
    result = render(scene, spp=16, seed=1)

    def radiance(points, cosine=True):
        offset = position - points
        r = np.linalg.norm(offset, axis=1, keepdims=True)
        cos = offset[:, 1:2] / r if cosine else 1.0
        return np.asarray(RHO) / math.pi * intensity * cos / r**2

    z, p = against_closed_form(result, floor_pixels(scene, radiance), "point light")
    assert np.all(np.abs(z) < Z3) and p > FALSE_ALARM
    z_wrong, p_wrong = against_closed_form(result, floor_pixels(scene, lambda x: radiance(x, cosine=False)),
                                           "point light against I / r^2 (must fail)")
    assert np.all(np.abs(z_wrong) > Z3) and p_wrong < FALSE_ALARM


@pytest.mark.slow
def test_directional_light_on_a_diffuse_floor(tmp_path):
    """L = rho / pi * E cos(theta) everywhere. The estimator is deterministic here (every sample is that value), so
    the render's variance is float32 rounding and the comparison is to float32 precision (z_scores' floor)."""
    direction, irradiance = np.array([0.3, -1.0, 0.2]), np.array([1.0, 2.0, 3.0])
    scene = load_scene(scene_file(tmp_path, [
        f'type = "directional"\ndirection = {toml_vector(direction)}\nirradiance = {toml_vector(irradiance)}']))
    result = render(scene, spp=4, seed=2)
    cos = -direction[1] / np.linalg.norm(direction)
    expected = np.broadcast_to(np.asarray(RHO) / math.pi * irradiance * cos, result.image.shape)
    z, _ = against_closed_form(result, expected, "directional light")
    relative = np.abs(result.image / expected - 1).max()
    print(f"directional light: largest relative pixel error {relative:.2g}")
    assert np.all(np.abs(z) < Z3) and relative < 1e-5


@pytest.mark.slow
def test_constant_environment_furnace(tmp_path):
    """A white diffuse sphere (albedo 1) under a constant environment L: every pixel is L, the sphere's too
    (convex: every bounce escapes to L). Also rendered with moments off (Mitsuba's plain path integrator)."""
    radiance = np.array([0.5, 1.0, 2.0])
    sphere = '[[shapes]]\ntype = "sphere"\nmaterial = "grey"\nradius = 1\n'
    scene = load_scene(scene_file(tmp_path, [f'type = "constant"\nradiance = {toml_vector(radiance)}'],
                                  shapes=sphere, origin=(0, 0, 4), up=(0, 1, 0), depth=-1, rho=[1, 1, 1]))
    result = render(scene, spp=32, seed=3)
    expected = np.broadcast_to(radiance, result.image.shape).astype(np.float64)
    z, p = against_closed_form(result, expected, "constant furnace")
    assert np.all(np.abs(z) < Z3) and p > FALSE_ALARM
    background = np.all(result.variance == 0, axis=2)
    assert 0 < background.sum() < background.size  # the sphere fills part of the image
    np.testing.assert_array_equal(result.image[background], np.broadcast_to(radiance, (background.sum(), 3)))
    plain = render(scene, spp=32, seed=4, moments="off")
    assert plain.variance is None
    z_plain = z_scores(image_mean(plain.image, result.variance), radiance)  # its variance ~ the moment render's
    print(f"constant furnace, moments off: z {np.round(z_plain, 2)}")
    assert np.all(np.abs(z_plain) < Z3)


def spot_falloff(theta_deg, cutoff, beam):
    """Mitsuba's spot.cpp: 1 within beam_width, linear in the angle down to 0 at cutoff_angle, 0 beyond."""
    theta = np.asarray(theta_deg, dtype=np.float64)
    return np.where(theta <= beam, 1.0, np.clip((cutoff - theta) / (cutoff - beam), 0.0, 1.0))


def spot_falloff_in_cos(theta_deg, cutoff, beam):
    """A plausible wrong model: linear in cos(theta) between the two angles."""
    cos, cos_c, cos_b = (np.cos(np.radians(a)) for a in (theta_deg, cutoff, beam))
    return np.clip((cos - cos_c) / (cos_b - cos_c), 0.0, 1.0)


@pytest.mark.slow
def test_spot_falloff_is_linear_in_the_angle(tmp_path):
    """A spot 1 above the floor, pointing down (cutoff 30, beam 15): the pixels wholly inside the beam and those
    wholly between beam and cutoff each match L = rho / pi * I f(theta) cos(theta) / r^2 with Mitsuba's falloff f;
    the same tests reject a falloff linear in cos(theta)."""
    cutoff, beam, intensity = 30.0, 15.0, np.array([3.0, 3.0, 3.0])
    scene = load_scene(scene_file(tmp_path, [
        f'type = "spot"\nposition = [0, 1, 0]\ntarget = [0, 0, 0]\nintensity = {toml_vector(intensity)}\n'
        f'cutoff_angle = {cutoff}\nbeam_width = {beam}'], fov=2 * math.degrees(math.atan(0.7 / 3))))
    result = render(scene, spp=32, seed=5)

    def radiance(points, falloff=spot_falloff):
        offset = np.array([0.0, 1.0, 0.0]) - points
        r = np.linalg.norm(offset, axis=1, keepdims=True)
        theta = np.degrees(np.arccos(offset[:, 1:2] / r))
        return np.asarray(RHO) / math.pi * intensity * falloff(theta, cutoff, beam) * offset[:, 1:2] / r**3

    points = floor_points(scene)
    theta = np.degrees(np.arctan(np.hypot(points[..., 0], points[..., 2])))  # the angle from the axis (height 1)
    low, high = theta.min(axis=(1, 3)), theta.max(axis=(1, 3))
    groups = {"inside beam_width": high < beam, "between beam_width and cutoff_angle": (low > beam) & (high < cutoff)}
    right, wrong = floor_pixels(scene, radiance), floor_pixels(scene, lambda p: radiance(p, spot_falloff_in_cos))
    for label, mask in groups.items():
        assert mask.sum() >= 12, (label, mask.sum())
        measured = image_mean(result.image[mask][None], result.variance[mask][None])
        z = z_scores(measured, right[mask].mean(axis=0))
        z_cos = z_scores(measured, wrong[mask].mean(axis=0))
        print(f"spot, {mask.sum()} pixels {label}: z {np.round(z, 2)}; against a falloff linear in cos z "
              f"{np.round(z_cos, 1)}")
        assert np.all(np.abs(z) < Z3), (label, z)
        if label.startswith("between"):
            assert np.all(np.abs(z_cos) > Z3), (label, z_cos)
    z, p = against_closed_form(result, right, "spot, whole image")
    assert p > FALSE_ALARM


# --------------------------------------------------------------------------------------------------------------------
# The envmap mapping (docs/scene-format.md, "Emitters")


def documented_lookup(image: np.ndarray, to_world: np.ndarray, scale: float, direction: np.ndarray,
                      rows_like_columns: bool = False) -> np.ndarray:
    """The envmap's radiance toward world ``direction`` as docs/scene-format.md states Mitsuba's mapping: local
    d = to_world^T direction; u = atan2(d.x, -d.z) / 2 pi wrapped into [0, 1), v = acos(d.y) / pi; bilinear
    between columns whose centres are at u = (j + 0.5) / W (wrapping around) and rows at v = i / (H - 1).
    ``rows_like_columns``: a plausible wrong mapping, rows centred at v = (i + 0.5) / H (clamped at the poles)."""
    height, width = image.shape[:2]
    d = to_world[:3, :3].T @ direction
    u = math.atan2(d[0], -d[2]) / (2 * math.pi)
    u -= math.floor(u)
    v = math.acos(max(-1.0, min(1.0, d[1]))) / math.pi
    x = u * width - 0.5
    y = min(max(v * height - 0.5, 0.0), height - 1.0) if rows_like_columns else v * (height - 1)
    x0, y0 = math.floor(x), min(math.floor(y), height - 2)
    fx, fy = x - x0, y - y0
    texel = lambda row, column: image[row, column % width].astype(np.float64)  # noqa: E731
    top = (1 - fx) * texel(y0, x0) + fx * texel(y0, x0 + 1)
    bottom = (1 - fx) * texel(y0 + 1, x0) + fx * texel(y0 + 1, x0 + 1)
    return scale * ((1 - fy) * top + fy * bottom)


@pytest.mark.slow
def test_envmap_mapping_is_the_documented_one(tmp_path):
    """Mitsuba's envmap plugin, built by the adapter, against documented_lookup: 600 random directions and the seam
    (-z), a rotated map with a scale; float32 precision (relative 1e-5). (Not the poles themselves: there the
    azimuth, hence the value in row 0 or H - 1, depends on the rounding of d.x and d.z.)"""
    rng = np.random.default_rng(7)
    image = rng.uniform(0.1, 2.0, (5, 8, 3)).astype(np.float32)
    write_exr(tmp_path / "map.exr", image)
    scene = load_scene(scene_file(tmp_path, [
        'type = "envmap"\nfile = "map.exr"\nscale = 1.5\nrotate = [{ axis = [0.3, 1, 0.2], angle = 37 }, '
        '{ axis = [1, 0, 0], angle = 11 }]']))
    mi = import_mitsuba(VARIANT)
    emitter = [e for e in mi.load_dict(scene_to_mitsuba_dict(scene, VARIANT)).emitters()
               if "EnvironmentMap" in str(e)][0]
    light = scene.emitters[0]
    seam = light.to_world[:3, :3] @ np.array([[0, 0, -1], [1e-4, 0.3, -1], [-1e-4, 0.3, -1], [0, -0.9, -1]]).T
    directions = np.concatenate([rng.normal(size=(600, 3)), seam.T])
    worst = worst_other = 0.0
    for direction in directions / np.linalg.norm(directions, axis=1, keepdims=True):
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-direction))  # an escaping ray travels along `direction`
        got = np.array(emitter.eval(si), dtype=np.float64).ravel()
        expected = documented_lookup(light.image, light.to_world, light.scale, direction)
        other = documented_lookup(light.image, light.to_world, light.scale, direction, rows_like_columns=True)
        worst = max(worst, float(np.max(np.abs(got / expected - 1))))
        worst_other = max(worst_other, float(np.max(np.abs(got / other - 1))))
    print(f"envmap mapping: largest relative difference from the documented lookup {worst:.2g} over "
          f"{len(directions)} directions (from rows centred like the columns: {worst_other:.2g})")
    assert worst < 1e-5
    assert worst_other > 0.1  # the test can fail


QUADRANTS = np.array([[[1.0 + k + 4 * half, 0.5, 0.25 * (k + 1)] for k in range(4) for _ in range(4)]
                      for half in (0, 1) for _ in range(4)], dtype=np.float32)  # 16 x 8: 4 azimuth blocks x 2 halves


@pytest.mark.slow
@pytest.mark.parametrize("rotate", [None, 90])
def test_envmap_orientation_seen_by_cameras(tmp_path, rotate):
    """A map of 8 uniform blocks (4 azimuth quarters x upper / lower half), seen by a narrow camera looking at each
    block's centre, u = (k + 0.5) / 4, v = 1/4 or 3/4, in the documented direction (sin 2pi u sin pi v, cos pi v,
    -cos 2pi u sin pi v), turned by the map's to_world: each pixel is the block's colour times scale."""
    write_exr(tmp_path / "quadrants.exr", QUADRANTS)
    body = 'type = "envmap"\nfile = "quadrants.exr"\nscale = 2'
    body += f"\nrotate = {{ axis = [0, 1, 0], angle = {rotate} }}" if rotate is not None else ""
    to_world = rotate_matrix([0, 1, 0], rotate or 0)[:3, :3]
    for half in (0, 1):
        for k in range(4):
            u, v = (k + 0.5) / 4, 0.25 + 0.5 * half
            local = np.array([math.sin(2 * math.pi * u) * math.sin(math.pi * v), math.cos(math.pi * v),
                              -math.cos(2 * math.pi * u) * math.sin(math.pi * v)])
            scene = load_scene(scene_file(tmp_path, [body], shapes="", origin=(0, 0, 0), target=to_world @ local,
                                          up=(0, 1, 0), fov=0.5, size=(2, 2), depth=1, name=f"look-{half}-{k}"))
            result = render(scene, spp=2)
            np.testing.assert_allclose(result.image, np.broadcast_to(2 * QUADRANTS[4 * half, 4 * k], (2, 2, 3)),
                                       rtol=1e-6, err_msg=f"block {k} of half {half}")


# --------------------------------------------------------------------------------------------------------------------
# The ground-truth key


ALL_BUT_CONSTANT = [
    'type = "point"\nposition = [0.3, 1, -0.2]\nintensity = [2, 3, 4]',
    'type = "spot"\nposition = [0, 1, 0]\ntarget = [0.2, 0, 0]\nintensity = [3, 3, 3]\ncutoff_angle = 30',
    'type = "directional"\ndirection = [0.3, -1, 0.2]\nirradiance = [0.5, 0.6, 0.7]',
    'type = "envmap"\nfile = "textures/sky.exr"\nscale = 0.5\nrotate = { axis = [0, 1, 0], angle = 30 }',
]
CONSTANT = 'type = "constant"\nradiance = [0.2, 0.3, 0.4]'
SPHERE = '[[shapes]]\nname = "ball"\ntype = "sphere"\nmaterial = "grey"\ncenter = [0.3, 0.4, 0]\nradius = 0.4\n'


@pytest.fixture
def sky_folder(tmp_path) -> Path:
    (tmp_path / "textures").mkdir()
    (tmp_path / "textures" / "sky.exr").write_bytes((Path(__file__).parents[2] / "scenes" / "textures" /
                                                     "sky.exr").read_bytes())
    return tmp_path


def test_digest_changes_with_every_emitter_field(sky_folder):
    scene = load_scene(scene_file(sky_folder, ALL_BUT_CONSTANT))
    constant = load_scene(scene_file(sky_folder, [CONSTANT], name="constant"))
    base, base_constant = scene_digest(scene), scene_digest(constant)
    point, spot, directional, envmap = scene.emitters
    changed = {
        "point.position": dataclasses.replace(point, position=(0.3, 1.0, -0.25)),
        "point.intensity": dataclasses.replace(point, intensity=(2.0, 3.0, 4.5)),
        "spot.to_world": dataclasses.replace(spot, to_world=spot.to_world @ rotate_matrix([0, 0, 1], 1e-3)),
        "spot.intensity": dataclasses.replace(spot, intensity=(3.0, 3.0, 3.1)),
        "spot.cutoff_angle": dataclasses.replace(spot, cutoff_angle=31.0),
        "spot.beam_width": dataclasses.replace(spot, beam_width=22.0),
        "directional.direction": dataclasses.replace(directional, direction=(0.0, -1.0, 0.0)),
        "directional.irradiance": dataclasses.replace(directional, irradiance=(0.5, 0.6, 0.8)),
        "envmap.scale": dataclasses.replace(envmap, scale=0.51),
        "envmap.to_world": dataclasses.replace(envmap, to_world=np.eye(4)),
        "envmap.image": dataclasses.replace(envmap, image=np.where(envmap.image == envmap.image.max(), 1.0,
                                                                   envmap.image).astype(np.float32)),
    }
    digests = {base}
    for label, emitter in changed.items():
        emitters = tuple(emitter if e.index == emitter.index else e for e in scene.emitters)
        digest = scene_digest(dataclasses.replace(scene, emitters=emitters))
        assert digest not in digests, label
        digests.add(digest)
    assert scene_digest(dataclasses.replace(scene, emitters=scene.emitters[:3])) not in digests  # one emitter fewer
    (light,) = constant.emitters
    assert scene_digest(dataclasses.replace(constant, emitters=(dataclasses.replace(light, radiance=(0.2, 0.3, 0.5)),
                                                                ))) != base_constant
    assert scene_digest(load_scene(scene.path)) == base  # and it is a function of the content


@pytest.mark.slow
def test_a_changed_envmap_file_is_not_served_the_old_ground_truth(sky_folder):
    path = scene_file(sky_folder, [ALL_BUT_CONSTANT[3]], size=(8, 8))
    cache = sky_folder / "cache"

    def gt():
        return ground_truth(load_scene(path), spp=4, chunk_spp=4, cache_dir=cache, variant=VARIANT)

    first = gt()
    assert first.renders == 1 and gt().cached
    exr = sky_folder / "textures" / "sky.exr"
    original = exr.read_bytes()
    image = read_exr(exr).image.copy()
    image[40:, :, :] *= 0.5  # a darker ground, same file name and size
    write_exr(exr, image)
    second = gt()
    assert second.renders == 1 and not second.cached and second.path != first.path
    assert not np.array_equal(first.image, second.image)
    exr.write_bytes(original)
    third = gt()
    assert third.cached and third.path == first.path and np.array_equal(third.image, first.image)


def test_the_furnace_closed_form_refuses_emitters(tmp_path):
    text = (Path(__file__).parents[2] / "scenes" / "furnace.toml").read_text()
    path = tmp_path / "furnace.toml"
    path.write_text(text + '\n[[emitters]]\ntype = "point"\nposition = [0, 0, 0]\nintensity = [1, 1, 1]\n')
    with pytest.raises(HarnessError) as info:
        ground_truth(load_scene(path))
    assert info.value.where == f"{path}: closed_form" and "[[emitters]] (point)" in info.value.message


# --------------------------------------------------------------------------------------------------------------------
# Exports and the command line


def _emitter_signature(emitter) -> str:
    """What Mitsuba made of one emitter, without addresses and the envmap's file name (the dict has a bitmap)."""
    return re.sub(r"0x[0-9a-f]+|\s*filename = \"[^\"]*\",?", "", str(emitter))


@pytest.mark.slow
@pytest.mark.parametrize("which", ["point-spot-directional-envmap", "constant"])
def test_mitsuba_xml_with_every_emitter_renders_like_the_adapter(sky_folder, which):
    """The XML's emitters are the dict's (Mitsuba's own description of each), and K = 8 renders of each agree by the
    statistical verdict (variance of the mean from the runs, K - 1 dof, alpha = 1e-3), as for shapes in
    tests/renderers/test_export.py."""
    emitters = ALL_BUT_CONSTANT if which != "constant" else [CONSTANT]
    scene = load_scene(scene_file(sky_folder, emitters, shapes=FLOOR + SPHERE, origin=(0, 1.5, 2.5), up=(0, 1, 0),
                                  size=(12, 10), depth=3))
    out = sky_folder / "xml"
    files = export_scene(scene, "mitsuba-xml", out, spp=4)
    assert (out / "textures" / "3-emitter3.exr" in files) == (which != "constant")
    mi = import_mitsuba(VARIANT)
    from_xml = mi.load_file(str(out / "scene.xml"))
    from_dict = mi.load_dict(scene_to_mitsuba_dict(scene, VARIANT, spp=4))
    xml_emitters = [_emitter_signature(e) for e in from_xml.emitters() if "AreaLight" not in str(e)]
    assert sorted(xml_emitters) == sorted(_emitter_signature(e) for e in from_dict.emitters())
    assert len(xml_emitters) == len(emitters)
    k = 8
    xml_runs = [np.array(mi.render(from_xml, seed=100 + i, spp=8), np.float64) for i in range(k)]
    dict_runs = [np.array(mi.render(from_dict, seed=200 + i, spp=8), np.float64) for i in range(k)]
    test, test_var, dof = combine_repeats(xml_runs)
    ref, ref_var, _ = combine_repeats(dict_runs)
    assert test.min() > 0
    outcome = verdict(test, test_var, ref, ref_var, tile=2, alpha=1e-3, test_dof=dof, expected_dof=dof)
    print(f"xml vs dict ({which}): {outcome.reason}")
    assert outcome.passed, outcome.reason


def test_gltf_has_the_punctual_lights(sky_folder):
    scene = load_scene(scene_file(sky_folder, ALL_BUT_CONSTANT, shapes=FLOOR + SPHERE))
    files = export_scene(scene, "gltf", sky_folder / "gltf")
    document = json.loads(files[0].read_text())
    assert "KHR_lights_punctual" in document["extensionsUsed"]
    lights = document["extensions"]["KHR_lights_punctual"]["lights"]
    assert [light["type"] for light in lights] == ["point", "spot", "directional"]  # no envmap in glTF
    nodes = {node["extensions"]["KHR_lights_punctual"]["light"]: node for node in document["nodes"]
             if "extensions" in node}
    roots = document["scenes"][document.get("scene", 0)]["nodes"]
    point, spot, directional, _envmap = scene.emitters
    for index, (emitter, rgb) in enumerate([(point, point.intensity), (spot, spot.intensity),
                                            (directional, directional.irradiance)]):
        light, node = lights[index], nodes[index]
        assert document["nodes"].index(node) in roots and light["name"] == emitter.name
        assert max(light["color"]) == 1.0 and min(light["color"]) >= 0
        np.testing.assert_allclose(np.array(light["color"]) * light["intensity"] / LUMENS_PER_WATT, rgb)
        if emitter.type != "directional":
            np.testing.assert_allclose(node["translation"], emitter.position)
        if emitter.type != "point":  # a glTF light shines along its node's -z
            axis = spot.axis if emitter.type == "spot" else directional.direction
            np.testing.assert_allclose(Rotation.from_quat(node["rotation"]).apply([0, 0, -1]), axis, atol=1e-12)
    assert lights[1]["spot"] == {"innerConeAngle": math.radians(22.5), "outerConeAngle": math.radians(30)}
    loaded = trimesh.load(files[0], force="scene")  # the meshes still load
    assert sum(len(g.faces) for g in loaded.geometry.values()) == 2 + 1280
    assert export_losses(scene, "gltf") == ["glTF 2.0 has no environment light: left out emitter3 (envmap) "
                                            "(KHR_lights_punctual has point, spot and directional lights only)"]
    assert export_losses(scene, "mitsuba-xml") == []
    assert export_losses(scene, "ply") == [
        "ply has no lights: left out emitters emitter0 (point), emitter1 (spot), emitter2 (directional), "
        "emitter3 (envmap)"]


def test_gltf_spot_with_equal_angles_keeps_inner_below_outer(sky_folder):
    scene = load_scene(scene_file(sky_folder, [
        'type = "spot"\nposition = [0, 1, 0]\ntarget = [0, 0, 0]\nintensity = [1, 1, 1]\nbeam_width = 20']))
    document = json.loads(export_scene(scene, "gltf", sky_folder / "gltf")[0].read_text())
    cone = document["extensions"]["KHR_lights_punctual"]["lights"][0]["spot"]
    assert cone["innerConeAngle"] < cone["outerConeAngle"] == math.radians(20)


def test_export_cli_warns_on_one_line_for_what_a_format_cannot_hold(sky_folder, capsys):
    path = scene_file(sky_folder, [CONSTANT, ALL_BUT_CONSTANT[0]])
    assert main(["export", str(path), "--format", "gltf", "--out", str(sky_folder / "g")]) == 0
    captured = capsys.readouterr()
    assert captured.err == ("harness: warning: glTF 2.0 has no environment light: left out emitter0 (constant) "
                            "(KHR_lights_punctual has point, spot and directional lights only)\n")
    assert main(["export", str(path), "--format", "mitsuba-xml", "--out", str(sky_folder / "x")]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_render_cli_with_mitsuba_and_emitters(sky_folder, capsys):
    path = scene_file(sky_folder, ALL_BUT_CONSTANT, size=(8, 6))
    out = sky_folder / "render.exr"
    assert main(["render", str(path), "--renderer", "mitsuba", "--mitsuba-variant", VARIANT, "--spp", "4",
                 "--out", str(out)]) == 0
    written = read_exr(out)
    assert written.image.shape == (6, 8, 3) and np.all(np.isfinite(written.image)) and written.image.min() > 0
    assert written.variance is not None
