"""The leaning plate's closed form (harness.renderers.groundtruth.shaded_plate_means): exact where the answer is
known, blind to a sun below the plate, converged in its quadrature, and refused on scenes it does not describe."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from harness.core.errors import HarnessError
from harness.renderers.groundtruth import closed_form, shaded_plate_means
from harness.scene.load import load_scene

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "leaning-plate.toml"


@pytest.fixture(scope="module")
def plate():
    return dataclasses.replace(load_scene(SCENE), film=dataclasses.replace(load_scene(SCENE).film, width=12,
                                                                          height=12))


def test_flat_normals_give_lambert_exactly(plate):
    """With face_normals the plate is flat: every pixel rho / pi E cos(theta) of the upper sun alone."""
    shape = dataclasses.replace(plate.shapes[0], face_normals=True, mesh_normals=None)
    scene = dataclasses.replace(plate, shapes=[shape])
    image = shaded_plate_means(scene, side=4)
    sun = scene.emitters[0]
    toward = -np.asarray(sun.direction) / np.linalg.norm(sun.direction)
    expected = np.asarray(scene.materials["grey"].reflectance) / np.pi * toward[2]
    np.testing.assert_allclose(image, np.broadcast_to(expected, image.shape), rtol=1e-12)


def test_the_sun_below_adds_nothing(plate):
    above_only = dataclasses.replace(plate, emitters=plate.emitters[:1])
    np.testing.assert_array_equal(shaded_plate_means(plate, side=4), shaded_plate_means(above_only, side=4))
    below_only = dataclasses.replace(plate, emitters=plate.emitters[1:])
    assert not np.any(shaded_plate_means(below_only, side=4))


def test_the_quadrature_has_converged(plate):
    coarse, fine = shaded_plate_means(plate, side=16), shaded_plate_means(plate, side=48)
    assert np.max(np.abs(coarse / fine - 1.0)) < 1e-6


def test_it_refuses_a_scene_it_does_not_describe(plate):
    glossy = dataclasses.replace(plate, materials={"grey": dataclasses.replace(plate.materials["grey"],
                                                                               two_sided=True)})
    with pytest.raises(HarnessError, match="one-sided diffuse"):
        closed_form(glossy)
    with pytest.raises(HarnessError, match="all directional"):
        closed_form(dataclasses.replace(plate, emitters=[]))
    wide = dataclasses.replace(plate, camera=dataclasses.replace(plate.camera, fov=120.0))
    with pytest.raises(HarnessError, match="cover"):
        closed_form(wide)
