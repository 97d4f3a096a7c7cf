"""Replicates (``Settings.replicates``): each pixel's Np samples as R independently seeded renders, the variance of
the pixel mean from the spread of the replicate means (docs/reference-renderer.md, "Replicates")."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from harness.renderers import RenderRequest, get_renderer
from harness.running.budget import _merged_dof
from harness.scene import load_scene
from reference_impl import Film, Settings

CORNELL = Path(__file__).resolve().parents[2] / "scenes" / "cornell-box.toml"


def _scene(film: int = 16):
    scene = load_scene(CORNELL)
    return dataclasses.replace(scene, film=Film(film, film, scene.film.filter))


def _render(scene, spp, seed=0, **settings):
    request = RenderRequest(spp=spp, seed=seed, settings={k: str(v) for k, v in settings.items()})
    return get_renderer("reference").render(scene, request)


def test_replicate_sizes_and_seeds():
    assert Settings(spp=7, replicates=3).replicate_sizes() == (3, 2, 2)
    assert Settings(spp=8, replicates=2).replicate_sizes() == (4, 4)
    assert Settings(spp=3, replicates=8).replicate_sizes() == (1, 1, 1)  # R > Np is Np
    assert Settings(spp=5).replicate_sizes() == (5,)
    s = Settings(seed=11, replicates=4)
    seeds = [s.replicate_seed(r) for r in range(4)]
    assert seeds[0] == 11 and len(set(seeds)) == 4 and all(0 <= x < 1 << 63 for x in seeds)
    assert Settings(seed=12).replicate_seed(1) != s.replicate_seed(1)


def test_one_replicate_is_the_render_it_always_was():
    scene = _scene()
    a, b = _render(scene, 8, seed=3), _render(scene, 8, seed=3, replicates=1)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.variance, b.variance)
    assert "variance_dof" not in b.info


def test_replicates_are_independently_seeded_renders():
    """R = 2: the image is the mean of two renders of Np / 2 samples (seeds ``replicate_seed(0)`` and ``(1)``) and
    the variance (a - b)^2 / 4, the sample variance of two means over 2, to float32 rounding."""
    scene = _scene()
    both = _render(scene, 8, seed=3, replicates=2)
    a = _render(scene, 4, seed=3).image.astype(np.float64)
    b = _render(scene, 4, seed=Settings(seed=3, replicates=2).replicate_seed(1)).image.astype(np.float64)
    assert not np.array_equal(a, b)
    np.testing.assert_allclose(both.image, (a + b) / 2, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(both.variance, (a - b) ** 2 / 4, rtol=1e-5, atol=1e-9)
    assert both.info["replicates"] == 2 and both.info["variance_dof"] == 1


@pytest.mark.parametrize("engine", ["path", "wavefront"])
def test_replicates_do_not_depend_on_batch_or_threads(engine):
    scene = _scene()
    a = _render(scene, 12, seed=5, replicates=3, engine=engine)
    b = _render(scene, 12, seed=5, replicates=3, engine=engine, threads=1, batch_size=100)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.variance, b.variance)


def _variance_ratio(scene, spp, seeds, **settings):
    """Sum over pixels of the empirical variance of the pixel estimates across ``seeds`` renders, over the sum of
    their mean reported variance; and the standard error of that ratio's logarithm under the null (an honest
    reported variance), from the chi-square spread of both sums and their effective number of pixels."""
    renders = [_render(scene, spp, seed=s, **settings) for s in range(seeds)]
    images = np.stack([r.image.astype(np.float64) for r in renders])
    reported = np.stack([r.variance.astype(np.float64) for r in renders])
    empirical = images.var(axis=0, ddof=1)[..., 1]  # one channel: the three are nearly perfectly correlated
    mean_reported = reported.mean(axis=0)[..., 1]
    n_eff = empirical.sum() ** 2 / (empirical ** 2).sum()  # Kish's effective number of equally noisy pixels
    dof = renders[0].info.get("variance_dof", spp - 1)
    se = math.sqrt((2 / (seeds - 1) + 2 / (dof * seeds)) / n_eff)
    return empirical.sum() / mean_reported.sum(), se


def test_replicate_variance_is_unbiased_where_the_sample_variance_overstates_it():
    """48 seeds of a 32 x 32 Cornell box at 8 spp: with R = 2 the reported variance matches the variance of the
    pixel estimates across seeds (log-ratio within 4.5 standard errors, about 0.09 each: a false alarm about 1 in
    150 000; measured 1.03); the planted fault "replicates-ddof0" (half the variance) is 7 standard errors out;
    and with one replicate the stratified sampler's sample variance over-states it (measured ratio 0.18), the bias
    that replicates remove."""
    scene = _scene(32)
    ratio, se = _variance_ratio(scene, 8, 48, replicates=2)
    assert abs(math.log(ratio)) < 4.5 * se, (ratio, se)
    ratio_fault, se = _variance_ratio(scene, 8, 48, replicates=2, mutant="replicates-ddof0")
    assert math.log(ratio_fault) > 4.5 * se, (ratio_fault, se)
    ratio_one, se_one = _variance_ratio(scene, 8, 48)
    assert math.log(ratio_one) < -4.5 * se_one, (ratio_one, se_one)


def test_the_budget_merges_the_degrees_of_freedom_of_replicated_chunks():
    class R:
        def __init__(self, spp, dof):
            self.spp, self.info = spp, ({} if dof is None else {"variance_dof": dof})

    assert _merged_dof([R(4, None), R(4, None)]) == {}
    assert _merged_dof([R(8, 1)]) == {"variance_dof": 1}
    assert _merged_dof([R(4, 3)] * 5) == {"variance_dof": 19}  # nu = n - 1: all N - 1 samples' worth
    # K chunks of 4 samples as 2 replicates: (N - 1)^2 / (K (n - 1)^2 + K - 1)
    assert _merged_dof([R(4, 1)] * 10) == {"variance_dof": int(39 ** 2 / (10 * 9 + 9))}
