"""The thin-lens and orthographic cameras of the core (reference_impl/camera.py, kernels/camera.py): the aperture's
points against their own pdf (chi^2), the rays of a film point meeting on the plane of focus, the orthographic
rays' origins and directions, and the cameras' planted faults each caught by the check it breaks."""

from __future__ import annotations

import numpy as np
import pytest

from harness.judges.chi2 import chi2_test_2d, sidak_alpha
from reference_impl import Film, Geometry, Settings, integrator
from reference_impl.camera import Camera, OrthographicCamera, ThinLensCamera
from reference_impl.errors import SettingsError
from reference_impl.kernels import camera as camera_kernel
from reference_impl.kernels import records
from reference_impl.sampling import square_to_uniform_disk_concentric
from reference_impl.kernels.warps import concentric_disk

N = 400_000
ALPHA = sidak_alpha(4)  # the four chi^2 tests of this module, family 1e-3
LOOK = dict(origin=(0.3, -0.2, 4.0), target=(0.0, 0.1, 0.0), up=(0.1, 1.0, 0.0))


def _geometry() -> Geometry:
    """One grey square far behind the camera's view (the camera kernel needs a context, not a scene)."""
    vertices = np.array([[-1.0, -1.0, -50.0], [1.0, -1.0, -50.0], [1.0, 1.0, -50.0], [-1.0, 1.0, -50.0]])
    return Geometry(vertices=vertices, triangles=np.array([[0, 1, 2], [0, 2, 3]]), material=np.zeros(2, np.int64),
                    reflectance=np.array([[0.5, 0.5, 0.5]]), two_sided=np.array([False]), emission=np.zeros((2, 3)),
                    light_id=np.full(2, -1))


def camera_rays(camera, width: int = 64, height: int = 32, spp: int = 200, mutant: str = "",
                sampler: str = "independent"):
    """The kernel's viewing rays (origins, directions) of every pixel's ``spp`` samples, and the film points'
    pixels."""
    settings = Settings(spp=spp, seed=3, max_depth=2, threads=1, mutant=mutant, sampler=sampler)
    ctx = integrator._Context(_geometry(), camera, Film(width, height, "box"), settings)
    n = width * height * spp
    pixel = np.repeat(np.arange(width * height, dtype=np.int64), spp)
    sample = np.tile(np.arange(spp, dtype=np.int64), width * height)
    state = integrator._view(ctx.workspace().state(0, n), n)
    camera_kernel.camera_paths(records.film_samples(pixel, sample, ctx.seed_key), ctx.config, ctx.camera_record,
                               records.filter_samples(ctx.filter_kind), state)
    return np.array(state[2]), np.array(state[3]), pixel


def _lens() -> ThinLensCamera:
    return ThinLensCamera(**LOOK, fov=50.0, aperture_radius=0.3, focus_distance=3.5)


def aperture_points(mutant: str = "", sampler: str = "independent") -> np.ndarray:
    """The kernel's aperture points of a thin lens, in units of its radius, camera-space (x, y)."""
    cam = _lens()
    origins, _d, _p = camera_rays(cam, 32, 25, N // 800, mutant, sampler)
    local = (origins - np.asarray(cam.origin)) @ cam.frame()
    assert np.allclose(local[:, 2], 0.0, atol=1e-12), "the aperture is the plane through the eye"
    return local[:, :2] / cam.aperture_radius


def _disk_chi2(points: np.ndarray, name: str):
    """(rho^2, phi) of unit-disk points: a uniform point of the disk has the density 1 / (2 pi) there."""
    r2 = np.sum(points**2, axis=1)
    phi = np.mod(np.arctan2(points[:, 1], points[:, 0]), 2 * np.pi)
    it = iter([(r2, phi)])
    return chi2_test_2d(lambda n: next(it), lambda a, b: np.full(np.shape(a), 0.5 / np.pi),
                        [(0.0, 1.0), (0.0, 2 * np.pi)], (20, 40), len(r2), name=name)


@pytest.mark.parametrize("sampler", ["independent", "sobol"])
def test_the_aperture_points_are_uniform_on_the_disk(sampler):
    result = _disk_chi2(aperture_points(sampler=sampler), f"aperture-{sampler}")
    assert result.passed(ALPHA), result.failures(ALPHA)


def test_the_lens_on_a_square_is_caught_by_the_chi2_test():
    result = _disk_chi2(aperture_points("lens-sampled-on-square"), "aperture-square")
    assert not result.passed(ALPHA)
    assert any("outside the domain" in line for line in result.failures(ALPHA))


def test_the_concentric_map_is_uniform_on_the_disk_and_the_kernel_is_the_numpy_map():
    g = np.random.default_rng(11)
    u1, u2 = g.random(N), g.random(N)
    points = square_to_uniform_disk_concentric(u1, u2)
    result = _disk_chi2(points, "concentric")
    assert result.passed(ALPHA), result.failures(ALPHA)
    kernel = np.array([concentric_disk(a, b) for a, b in zip(u1[:2000], u2[:2000])])
    assert np.allclose(kernel, points[:2000], rtol=0, atol=1e-15)
    # Mitsuba 3.9.1's own map at (0.1, 0.1): (-0.8 cos 45, -0.8 sin 45) (docs/mitsuba.md)
    assert np.allclose(square_to_uniform_disk_concentric(np.array([0.1]), np.array([0.1]))[0],
                       [-0.8 / np.sqrt(2), -0.8 / np.sqrt(2)], atol=1e-15)


def _focus_points(cam, origins, directions):
    """Where each ray meets the camera-space plane z = focus_distance, in camera space."""
    frame = cam.frame()
    o = (origins - np.asarray(cam.origin)) @ frame
    d = directions @ frame
    t = (cam.focus_distance - o[:, 2]) / d[:, 2]
    return o + t[:, None] * d


def test_every_ray_of_a_film_point_meets_the_pinhole_ray_on_the_plane_of_focus():
    """With the box filter's offset the same for one film point, the rays of one pixel's samples spread; so take a
    one-sample film where every pixel's film point is its own: each ray meets the plane of focus where the pinhole
    ray of its film point does (Mitsuba's thinlens: a plane along the axis, docs/mitsuba.md)."""
    cam = _lens()
    origins, directions, pixel = camera_rays(cam, 64, 32, 4)
    film_x, film_y = _film_points(cam, origins, directions, 64, 32)
    pin_o, pin_d = Camera(**LOOK, fov=50.0).generate_rays(film_x, film_y, 64, 32)
    assert np.allclose(_focus_points(cam, origins, directions), _focus_points(cam, pin_o, pin_d), atol=1e-9)
    assert np.all(np.floor(film_x) + 64 * np.floor(film_y) == pixel)
    wrong_o, wrong_d, _p = camera_rays(cam, 64, 32, 4, mutant="focus-along-ray")
    fx, fy = _film_points(cam, wrong_o, wrong_d, 64, 32)
    assert not np.allclose(fx, film_x, atol=1e-6), "the focus along the ray moved where the rays meet"


def _film_points(cam, origins, directions, width, height):
    """The film point whose pinhole ray meets each ray on the plane of focus (l = focus point / f)."""
    f = _focus_points(cam, origins, directions) / cam.focus_distance
    tan_x, tan_y = cam.tan_half_fov(width, height)
    return (1.0 - f[:, 0] / tan_x) * width / 2.0, (1.0 - f[:, 1] / tan_y) * height / 2.0


def test_the_thin_lens_numpy_rays_meet_the_kernel_rules():
    cam = _lens()
    g = np.random.default_rng(5)
    fx, fy = g.random(1000) * 64, g.random(1000) * 32
    origins, directions = cam.generate_rays(fx, fy, 64, 32, lens=(g.random(1000), g.random(1000)))
    pin_o, pin_d = Camera(**LOOK, fov=50.0).generate_rays(fx, fy, 64, 32)
    assert np.allclose(_focus_points(cam, origins, directions), _focus_points(cam, pin_o, pin_d), atol=1e-9)
    assert np.allclose(np.linalg.norm(directions, axis=1), 1.0)
    same_o, same_d = cam.generate_rays(fx, fy, 64, 32)  # no lens sample: the pinhole's ray
    assert np.array_equal(same_d, pin_d) and np.array_equal(same_o, pin_o)


def test_the_orthographic_rays_start_on_their_pixels_point_and_go_forward():
    cam = OrthographicCamera(**LOOK, scale=(2.0, 3.0, 1.0))
    origins, directions, pixel = camera_rays(cam, 64, 32, 2)
    frame = cam.frame()
    assert np.allclose(directions, frame[:, 2], atol=1e-15)
    local = (origins - np.asarray(cam.origin)) @ frame
    assert np.allclose(local[:, 2], 0.0, atol=1e-12)
    # film (p_x, p_y) at camera ((1 - 2 p_x / W) s_x, (1 - 2 p_y / H) s_y H / W): Mitsuba's extent (docs/mitsuba.md)
    px = (1.0 - local[:, 0] / 2.0) * 32.0
    py = (1.0 - local[:, 1] / 1.5) * 16.0
    assert np.all(np.floor(px) + 64 * np.floor(py) == pixel)
    numpy_o, numpy_d = cam.generate_rays(np.array([0.0, 64.0, 32.0]), np.array([0.0, 32.0, 16.0]), 64, 32)
    assert np.allclose((numpy_o - np.asarray(cam.origin)) @ frame, [[2.0, 1.5, 0.0], [-2.0, -1.5, 0.0], [0, 0, 0]])
    assert np.allclose(numpy_d, frame[:, 2])
    wrong, _d, _p = camera_rays(cam, 64, 32, 2, mutant="orthographic-origin-not-offset")
    assert np.allclose(wrong, np.asarray(cam.origin)), "the fault: every ray from the eye"


def test_the_perspective_rays_are_unchanged_by_the_camera_models():
    """The pinhole's rays as the kernel wrote them before the lens and the orthographic camera came (normalize(frame
    (l0, l1, 1)) from the eye): the same bits."""
    cam = Camera(**LOOK, fov=50.0)
    origins, directions, pixel = camera_rays(cam, 16, 8, 4)
    assert np.array_equal(origins, np.broadcast_to(np.asarray(cam.origin), origins.shape))
    frame = cam.frame()
    local = directions @ frame
    l0, l1 = local[:, 0] / local[:, 2], local[:, 1] / local[:, 2]
    tan_x, tan_y = cam.tan_half_fov(16, 8)
    px, py = (1.0 - l0 / tan_x) * 8.0, (1.0 - l1 / tan_y) * 4.0
    assert np.all(np.floor(px) + 16 * np.floor(py) == pixel)


@pytest.mark.parametrize("kwargs, key", [
    (dict(aperture_radius=-0.1), "camera.aperture_radius"),
    (dict(aperture_radius=float("nan")), "camera.aperture_radius"),
    (dict(aperture_radius=0.1, focus_distance=0.0), "camera.focus_distance"),
    (dict(aperture_radius=0.1, focus_distance=float("inf")), "camera.focus_distance"),
])
def test_a_thin_lens_out_of_range_is_refused(kwargs, key):
    with pytest.raises(SettingsError) as error:
        ThinLensCamera(**LOOK, fov=40.0, **kwargs)
    assert error.value.key == key


@pytest.mark.parametrize("scale", [(0.0, 1.0, 1.0), (1.0, -1.0, 1.0), (1.0, 1.0), (1.0, float("inf"), 1.0)])
def test_an_orthographic_scale_out_of_range_is_refused(scale):
    with pytest.raises(SettingsError) as error:
        OrthographicCamera(**LOOK, scale=scale)
    assert error.value.key == "camera.scale"
