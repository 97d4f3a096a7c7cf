"""The bilinear lookups' wrapped texel pairs (kernels/texture.py ``wrap_pair``: one division for i and i + 1) are
``wrap_index`` of each, for every wrap mode, on both sides of zero and across many periods."""

from __future__ import annotations

import pytest

from reference_impl.kernels import texture
from reference_impl.textures import CLAMP, MIRROR, REPEAT


@pytest.mark.parametrize("mode", [REPEAT, MIRROR, CLAMP])
@pytest.mark.parametrize("n", [1, 2, 3, 32])
def test_wrap_pair_is_wrap_index_of_i_and_of_i_plus_one(mode, n):
    for i in range(-5 * n - 3, 5 * n + 4):
        assert texture.wrap_pair(i, n, mode) == (texture.wrap_index(i, n, mode), texture.wrap_index(i + 1, n, mode))
    big = 2**52
    assert texture.wrap_pair(big, n, mode) == (texture.wrap_index(big, n, mode), texture.wrap_index(big + 1, n, mode))
    assert texture.wrap_pair(-big, n, mode) == (texture.wrap_index(-big, n, mode),
                                                texture.wrap_index(-big + 1, n, mode))
