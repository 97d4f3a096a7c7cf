"""The canonical scenes' texture images are what harness/scene/texture_images.py makes, pixel for pixel."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from harness.files.imageio import read_exr
from harness.scene import texture_images


def _read(path):
    return iio.imread(path) if path.suffix == ".png" else read_exr(path).image


@pytest.mark.parametrize("folder,name", [(texture_images.DEFAULT_FOLDER, n) for n in sorted(texture_images.IMAGES)]
                         + [(texture_images.STRESS_FOLDER, n) for n in sorted(texture_images.STRESS_IMAGES)])
def test_the_committed_texture_is_the_generators(folder, name):
    make = {**texture_images.IMAGES, **texture_images.STRESS_IMAGES}[name]
    np.testing.assert_array_equal(_read(folder / name), make())


def test_the_generator_writes_them(tmp_path):
    assert texture_images.main([str(tmp_path)]) == 0
    for name, make in {**texture_images.IMAGES, **texture_images.STRESS_IMAGES}.items():
        np.testing.assert_array_equal(_read(tmp_path / name), make())
