"""The canonical scenes with [[emitters]] (scenes/point-spot.toml, sun-sky.toml, envmap.toml): what their
descriptions promise is in the frame (the spot's falloff ring, the shadows), checked from the geometry, and each
renders in Mitsuba to finite values."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import SCENES

from harness.renderers import RenderRequest, get_renderer
from harness.scene import load_scene
from harness.scene.sky import sun_direction
from reference_impl import Film

EMITTER_SCENES = ("point-spot", "sun-sky", "envmap")


def film_position(scene, points: np.ndarray) -> np.ndarray:
    """Film coordinates (x right, y down, in pixels; [0, W] x [0, H] is the image) of world points in front of the
    camera: the inverse of Camera.generate_rays."""
    camera, width, height = scene.camera, scene.film.width, scene.film.height
    local = (np.asarray(points, float) - np.asarray(camera.origin, float)) @ camera.frame()
    assert np.all(local[:, 2] > 0), "behind the camera"
    tan_x, tan_y = camera.tan_half_fov(width, height)
    x = (1.0 - local[:, 0] / local[:, 2] / tan_x) * width / 2
    y = (1.0 - local[:, 1] / local[:, 2] / tan_y) * height / 2
    return np.stack([x, y], axis=1)


def in_frame(scene, points: np.ndarray, margin: float = 1.0) -> np.ndarray:
    xy = film_position(scene, points)
    return ((xy[:, 0] > margin) & (xy[:, 0] < scene.film.width - margin) & (xy[:, 1] > margin)
            & (xy[:, 1] < scene.film.height - margin))


def shadow_on_floor(point: np.ndarray, toward_light: np.ndarray) -> np.ndarray:
    """Where the shadow of ``point`` falls on the floor y = 0, for light arriving from direction ``toward_light``."""
    return point - point[1] / toward_light[1] * toward_light


def corners(shape) -> np.ndarray:
    cube = np.array([[x, y, z, 1.0] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    return (cube @ shape.to_world.T)[:, :3]


def floor_rays_hit(scene, floor) -> bool:
    """Every corner ray of the film meets the floor (y = 0) inside its square."""
    _o, directions = scene.camera.generate_rays(np.array([0.0, 64, 0, 64]), np.array([0.0, 0, 64, 64]), 64, 64)
    eye = np.asarray(scene.camera.origin, float)
    hits = eye - (eye[1] / directions[:, 1])[:, None] * directions
    half = np.linalg.norm(floor.to_world[:3, 0])
    return bool(np.all(directions[:, 1] < 0) and np.all(np.abs(hits[:, [0, 2]]) < half))


def test_point_spot_shows_the_cone_edge_and_both_shadows():
    scene = load_scene(SCENES / "point-spot.toml")
    shapes = {s.name: s for s in scene.shapes}
    point, spot = scene.emitters
    assert (point.type, spot.type) == ("point", "spot") and floor_rays_hit(scene, shapes["floor"])
    # The falloff ring: where the cones at beam_width and cutoff_angle meet the floor, wholly in view.
    apex, axis = spot.position, spot.axis
    side = np.cross(axis, [1.0, 0, 0])
    side /= np.linalg.norm(side)
    other = np.cross(axis, side)
    angles = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    for degrees in (spot.beam_width, spot.cutoff_angle):
        theta = np.radians(degrees)
        rays = np.cos(theta) * axis + np.sin(theta) * (np.cos(angles)[:, None] * side + np.sin(angles)[:, None] * other)
        assert np.all(rays[:, 1] < 0), degrees  # the whole cone meets the floor
        ring = apex - (apex[1] / rays[:, 1])[:, None] * rays
        assert np.all(in_frame(scene, ring)), degrees

    def in_cone(points):
        offsets = points - apex
        cosines = offsets @ axis / np.linalg.norm(offsets, axis=1)
        return cosines > np.cos(np.radians(spot.cutoff_angle))

    # The hard shadows of the box's top corners: from the point light in view and partly inside the spot's cone
    # (lit by the spot there), and the spot's own shadow of the box, in its cone and in view.
    top = corners(shapes["occluder"])[[1, 3, 5, 7]]
    from_point = np.array([shadow_on_floor(c, np.asarray(point.position) - c) for c in top])
    assert np.all(in_frame(scene, from_point)) and np.any(in_cone(from_point))
    from_spot = np.array([shadow_on_floor(c, apex - c) for c in top])
    assert np.any(in_cone(from_spot) & in_frame(scene, from_spot))


def test_sun_sky_shadows_and_sky_in_view():
    scene = load_scene(SCENES / "sun-sky.toml")
    sun, sky = scene.emitters
    assert (sun.type, sky.type) == ("directional", "constant")
    toward_sun = -np.asarray(sun.direction)
    assert toward_sun[1] > 0.5  # high enough for short shadows
    for box in scene.shapes[1:]:
        top = corners(box)[[1, 3, 5, 7]]
        shadow = np.array([shadow_on_floor(c, toward_sun) for c in top])
        assert np.all(in_frame(scene, shadow)), box.name
    # the top row looks above the horizon (sky), the bottom row at the ground
    _o, directions = scene.camera.generate_rays(np.array([32.0, 32.0]), np.array([0.0, 64.0]), 64, 64)
    assert directions[0, 1] > 0 > directions[1, 1]


def test_envmap_sun_shadows_in_view():
    scene = load_scene(SCENES / "envmap.toml")
    (env,) = scene.emitters
    assert env.type == "envmap" and env.file.name == "sky.exr"
    toward_sun = np.asarray(env.to_world)[:3, :3] @ sun_direction()
    shapes = {s.name: s for s in scene.shapes}
    ball = shapes["ball"]
    centre, radius = np.asarray(ball.center), ball.radius
    # the shadow of the ball's centre and of the box's top corners on the floor, in view, left of their objects
    ball_shadow = shadow_on_floor(centre, toward_sun)
    box_top = corners(shapes["dark-box"])[[1, 3, 5, 7]]
    box_shadow = np.array([shadow_on_floor(c, toward_sun) for c in box_top])
    assert np.all(in_frame(scene, np.vstack([ball_shadow, box_shadow])))
    assert film_position(scene, ball_shadow[None])[0, 0] < film_position(scene, centre[None])[0, 0] - 5
    # the ball's shadow centre is not under the box (half-diagonal 0.3 sqrt 2), and the sky is in the top row
    box_foot = np.asarray(shapes["dark-box"].to_world[:3, 3])
    assert np.linalg.norm((ball_shadow - box_foot)[[0, 2]]) > 0.3 * np.sqrt(2) and radius > 0
    _o, directions = scene.camera.generate_rays(np.array([32.0]), np.array([0.0]), 64, 64)
    assert directions[0, 1] > 0


@pytest.mark.slow
@pytest.mark.parametrize("name", EMITTER_SCENES)
def test_renders_finite_in_mitsuba(name):
    scene = load_scene(SCENES / f"{name}.toml")
    scene = dataclasses.replace(scene, film=Film(16, 16, scene.film.filter))
    result = get_renderer("mitsuba").render(scene, RenderRequest(spp=4, seed=1, settings={"variant": "scalar_rgb"}))
    assert np.all(np.isfinite(result.image)) and np.all(np.isfinite(result.variance))
    assert np.all(result.image >= 0) and result.image.mean() > 0.05
