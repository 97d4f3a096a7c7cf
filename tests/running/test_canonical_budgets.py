"""The canonical suite's budgets keep every ground truth's noise under 1/4 of its test render's, checked from the
budgets alone (docs/suites.md, "A ground truth that does not blunt the test"): a case whose budgets break the rule,
or a new case nobody measured, fails here before any run prints its warning."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from harness.judges.floor import GROUND_TRUTH_SHARE_LIMIT
from harness.running.cases import load_suite
from harness.running.judge import ground_truth_noise

CANONICAL = Path(__file__).resolve().parents[2] / "suites" / "canonical.toml"

#: Each case's per-sample variance ratio k: the ground truth's (Mitsuba's) variance per sample over the test
#: render's, so that its share of the verdict's variance is k x spp / ground_truth_spp. Measured by a run of the
#: canonical suite (2026-12-05, llvm_ad_rgb): k = ground_truth_noise.ratio x ground_truth_spp / spp of each record.
#: 0: a closed-form ground truth. A new case needs its k: run it and read ``ground_truth_noise`` in results.json.
PER_SAMPLE_RATIO = {
    "cornell-box/reference": 4.63,
    "furnace/reference": 0.0,
    "soft-shadows/reference": 24.5,
    "multi-light/reference": 4.98,
    "furnace/mitsuba-vs-closed-form": 0.0,
    "white-furnace/mitsuba-vs-closed-form": 0.0,
    "white-furnace-albedo-1/mitsuba-vs-closed-form": 0.0,
    "cornell-box/sampler-independent": 0.992,
    "cornell-box/direct-hemisphere-cosine": 0.363,
    "cornell-box/direct-hemisphere-uniform": 0.21,
    "cornell-box/direct-global-area": 0.125,
    "cornell-box/direct-mis": 19.8,
    "cornell-box/light-selection-uniform": 19.8,
    "cornell-box/hemisphere-uniform": 9.2,
    "cornell-box/rr-fixed": 13.8,
    "cornell-box/rr-off": 21.8,
    "soft-shadows/direct-hemisphere-cosine": 0.17,
    "soft-shadows/direct-hemisphere-uniform": 0.0767,
    "soft-shadows/direct-global-area": 0.121,
    "soft-shadows/direct-mis": 27.0,
    "soft-shadows/light-selection-uniform": 27.2,
    "soft-shadows/hemisphere-uniform": 27.2,
    "soft-shadows/rr-fixed": 27.2,
    "soft-shadows/rr-off": 27.2,
    "multi-light/direct-hemisphere-cosine": 0.0083,
    "multi-light/direct-hemisphere-uniform": 0.00481,
    "multi-light/direct-global-area": 0.00327,
    "multi-light/direct-mis": 5.87,
    "multi-light/light-selection-uniform": 5.44,
    "multi-light/hemisphere-uniform": 4.13,
    "multi-light/rr-fixed": 3.95,
    "multi-light/rr-off": 5.66,
    "furnace/direct-hemisphere-cosine": 0.0,
    "furnace/direct-hemisphere-uniform": 0.0,
    "furnace/direct-global-area": 0.0,
    "furnace/direct-mis": 0.0,
    "furnace/light-selection-uniform": 0.0,
    "furnace/hemisphere-uniform": 0.0,
    "furnace/rr-fixed": 0.0,
    "furnace/rr-off-max-depth-16": 0.0,
    "cornell-box/mutant-double-emission": 0.223,
    "cornell-box/mutant-no-cosine": 0.00226,
    "cornell-box/mutant-cosine-pdf-pi": 12.8,
    "furnace/mutant-rr-no-reweight": 0.0,
    "multi-light/mutant-light-pdf-ignored": 40.7,
    "soft-shadows/mutant-camera-half-pixel": 20.5,
    "soft-shadows/mutant-no-ray-offset": 9.36,
    "furnace/mutant-energy-loss-2pct": 0.0,
    "white-furnace/mutant-replicates-ddof0": 0.0,
    "white-furnace/reference": 0.0,
    "white-furnace-albedo-1/reference": 0.0,
    "white-furnace/env-sampling-cosine": 0.0,
    "white-furnace/env-sampling-uniform": 0.0,
    "white-furnace/direct-mis": 0.0,
    "white-furnace/direct-hemisphere-uniform": 0.0,
    "white-furnace/direct-global-area": 0.0,
    "white-furnace-albedo-1/rr-off-max-depth-16": 0.0,
    "white-furnace-albedo-1/mutant-energy-loss-2pct": 0.0,
    "white-furnace/mutant-no-cosine": 0.0,
    "point-spot/reference": 11.3,
    "point-spot/direct-mis": 3.24,
    "point-spot/direct-hemisphere-cosine": 256.0,
    "point-spot/direct-hemisphere-uniform": 256.0,
    "point-spot/direct-global-area": 256.0,
    "point-spot/light-selection-uniform": 40.1,
    "point-spot/hemisphere-uniform": 3.25,
    "point-spot/rr-off": 3.24,
    "point-spot/mutant-point-no-inverse-square": 3.11,
    "point-spot/mutant-spot-ignores-beam-width": 1.34,
    "sun-sky/reference": 15.1,
    "sun-sky/direct-mis": 27.0,
    "sun-sky/direct-hemisphere-cosine": 185.0,
    "sun-sky/direct-hemisphere-uniform": 165.0,
    "sun-sky/direct-global-area": 14.3,
    "sun-sky/env-sampling-uniform": 15.1,
    "sun-sky/env-sampling-cosine": 35.7,
    "sun-sky/light-selection-uniform": 18.9,
    "sun-sky/hemisphere-uniform": 13.8,
    "sun-sky/rr-fixed": 13.6,
    "sun-sky/mutant-directional-reversed": 23.6,
    "envmap/reference": 1.09,
    "envmap/direct-mis": 1.32,
    "envmap/env-sampling-uniform": 0.00128,
    "envmap/env-sampling-cosine": 0.00285,
    "envmap/env-sampling-uniform-mis": 0.00363,
    "envmap/direct-hemisphere-cosine": 0.00352,
    "envmap/direct-hemisphere-uniform": 0.00196,
    "envmap/direct-global-area": 0.393,
    "envmap/hemisphere-uniform": 1.04,
    "envmap/rr-off": 1.09,
    "envmap/mutant-envmap-pdf-no-sin": 0.0709,
    "envmap/mutant-envmap-mirrored-u": 0.000124,
    "white-furnace/hemisphere-uniform": 0.0,
    "white-furnace/rr-fixed": 0.0,
    "white-furnace/rr-off-max-depth-16": 0.0,
    "point-spot/rr-fixed": 3.13,
    "sun-sky/rr-off": 15.1,
    "envmap/rr-fixed": 1.03,
    # veach-mis and medium-emitter re-measured 2026-12-07: their sphere lights drawn by the cone they subtend
    "veach-mis/reference": 8.15,
    "veach-mis/direct-area": 2.34,
    "veach-mis/light-selection-uniform": 4.69,
    "veach-mis/rr-throughput": 4.69,
    "veach-mis/rr-fixed": 4.67,
    "veach-mis/rr-off": 4.69,
    "veach-mis/direct-bsdf": 0.681,
    "cornell-box-specular/reference": 3.26,
    "cornell-box-specular/direct-area": 3.26,
    "cornell-box-specular/direct-bsdf": 0.538,
    "underwater/reference": 1.24,
    "underwater/direct-bsdf": 0.0161,
    "underwater/direct-area": 1.19,
    "white-furnace-glass/mitsuba-vs-closed-form": 0.0,
    "white-furnace-rough/reference": 16.9,
    "white-furnace-rough/direct-area": 20.4,
    "white-furnace-rough/direct-bsdf": 5.72,
    "veach-mis/mutant-microfacet-pdf-no-jacobian": 4.79,
    "white-furnace-rough/mutant-mis-weights-not-one": 16.6,
    "veach-mis/mutant-conductor-fresnel-one": 3.42,
    "veach-mis/mutant-vndf-alpha-squared": 5.07,
    "veach-mis/mutant-sphere-points-uniform-theta": 18.8,  # 2026-12-06: ratio 0.589 at 512 spp, 16384
    "veach-mis/mutant-sphere-cone-pdf-area": 2.56,  # 2026-12-07: ratio 0.0100 at 64 spp, 16384
    "underwater/mutant-refraction-no-eta2": 0.405,
    # measured 2026-12-05 (issue 35), llvm_ad_rgb; the textured furnace's ground truth is its closed form
    "textured-furnace/reference": 0.0,
    "textured-furnace/mitsuba-vs-closed-form": 0.0,
    "textured-cornell-box/reference": 9.81,
    "textured-furnace/direct-hemisphere-uniform": 0.0,
    "textured-furnace/direct-global-area": 0.0,
    "textured-furnace/direct-mis": 0.0,
    "textured-furnace/hemisphere-uniform": 0.0,
    "textured-furnace/rr-fixed": 0.0,
    "textured-furnace/rr-off": 0.0,
    "textured-cornell-box/direct-area": 9.61,
    "textured-cornell-box/direct-bsdf": 0.36,
    "textured-furnace/mutant-texture-v-flipped": 0.0,
    "textured-furnace/mutant-texture-srgb-as-linear": 0.0,
    "textured-furnace/mutant-texture-nearest-not-bilinear": 0.0,
    "textured-furnace/mutant-texture-half-texel-shift": 0.0,
    "textured-furnace/mutant-texture-repeat-as-clamp": 0.0,
    # measured 2026-12-06 (issue 35, shading normals), llvm_ad_rgb; the leaning plate's ground truth is its closed form
    "leaning-plate/reference": 0.0,
    "leaning-plate/mitsuba-vs-closed-form": 0.0,
    "smooth-twins/reference": 2.49,
    "mapped-plates/reference": 32.5,
    "leaning-plate/mutant-normals-not-renormalised": 0.0,
    "leaning-plate/mutant-shading-normal-side": 0.0,
    "mapped-plates/mutant-normalmap-green-inverted": 33.0,
    "mapped-plates/mutant-bumpmap-scale-ignored": 18.5,
    "leaning-plate/direct-hemisphere-cosine": 0.0,
    "leaning-plate/direct-hemisphere-uniform": 0.0,
    "leaning-plate/direct-global-area": 0.0,
    "leaning-plate/direct-mis": 0.0,
    "leaning-plate/light-selection-uniform": 0.0,
    "leaning-plate/hemisphere-uniform": 0.0,
    "leaning-plate/rr-fixed": 0.0,
    "leaning-plate/rr-off": 0.0,
    "mapped-plates/direct-hemisphere-cosine": 0.001,
    "mapped-plates/direct-hemisphere-uniform": 0.001,
    "mapped-plates/direct-global-area": 0.029,
    "mapped-plates/direct-mis": 32.2,
    "mapped-plates/hemisphere-uniform": 32.5,
    "mapped-plates/rr-fixed": 32.5,
    "mapped-plates/rr-off": 32.5,
    "smooth-twins/direct-area": 2.44,
    "smooth-twins/direct-bsdf": 0.004,
    "focused-plane/mitsuba-vs-closed-form": 0.0,
    "focused-plane/mutant-focus-along-ray": 0.0,
    "orthographic-floor/mitsuba-vs-closed-form": 0.0,
    "depth-of-field/reference": 1.10,  # 2026-12-06: ratio 0.0342 at 256 spp, 8192 spp of ground truth
    "depth-of-field/mutant-lens-sampled-on-square": 0.99,  # 2026-12-06: ratio 0.124 at 1024 spp
    "thin-glass-window/reference": 14.4,  # 2026-12-06
    "thin-glass-window/mutant-thin-glass-refracts": 15.5,
    "plastic-cornell-box/reference": 4.14,
    "plastic-cornell-box/mutant-plastic-no-internal-reflection": 4.52,
    "cutout-leaf/reference": 65.4,  # 2026-12-06: Mitsuba finds the light through the holes by BSDF sampling only
    "cutout-leaf/mutant-mask-opacity-1-in-shadow-rays": 81.2,
    "principled-grid/reference": 1.54,
    "principled-grid/mutant-principled-clearcoat-pdf-jacobian": 1.52,
    "material-balls-furnace/reference": 1.90,
    "material-balls/reference": 1.16,
    # the media: 2026-12-06, after the volpath loop's first vertex was stratified (issue 39; before: fog-box 1.2,
    # hg-cloud 1.59, its hg-g-flipped 15.1, medium-emitter 0.8, glass-medium 0.86)
    "fog-box/reference": 4.39,
    "fog-box/mutant-nee-no-transmittance": 4.26,
    "fog-box/mutant-free-flight-pdf-no-sigma-t": 5.32,
    "fog-box/mutant-albedo-applied-twice": 4.85,
    "media-slab/reference": 0.0,
    "medium-furnace/reference": 0.0,
    "hg-cloud/reference": 1.5,
    "hg-cloud/mutant-hg-g-flipped": 20.3,
    "medium-emitter/reference": 7.26,
    "medium-emitter/mutant-null-boundary-as-bounce": 0.959,
    "glass-medium/reference": 1.09,
}

#: Cases whose ground truth has no variance to compare, or whose test render reports none (``ground_truth_noise``
#: absent: closed forms with a noiseless test).
NO_RATIO = {
    "white-furnace/mitsuba-max-depth-1",
    "white-furnace/direct-hemisphere-cosine",
    "white-furnace-mirror/reference",
    "white-furnace-mirror/direct-area",
    "white-furnace-mirror/direct-bsdf",
    "white-furnace-mirror/mitsuba-vs-closed-form",
    "white-furnace-glass/reference",
    "white-furnace-glass/direct-bsdf",
    "white-furnace-glass/direct-area",
    "focused-plane/reference",
    "orthographic-floor/reference",
    "orthographic-floor/mutant-orthographic-origin-not-offset",
}

#: Cases expected to pass that break the rule, each of which must stay over the limit while listed. Where the ground
#: truth the rule asks for costs more Mitsuba time than the README's first command can pay on a fresh 2-core
#: machine (10 minutes), a case is sized to its ground truth instead (cornell-box's 64 x 64 strategy cases at 64 spp
#: against 8192, sun-sky's hemisphere cases at 16 spp against 16384). Point-spot's hemisphere and global-area cases
#: (k = 256) cannot be: against a sharper ground truth a correct render of its hard shadows fails the tile
#: statistic now and then (8 spp against 16384: direct-global-area failed, max |z| 6.8), the wrong tail of issue 33's
#: section 5; they stay at 64 spp against 1024, and warn, until that is fixed.
OVER_BUDGET: set[str] = set()


def share(case) -> float:
    """The ground truth's predicted share of the verdict's variance: k x spp / ground_truth_spp."""
    return PER_SAMPLE_RATIO[case.name] * case.spp / case.ground_truth_spp


@pytest.fixture(scope="module")
def cases():
    return load_suite(CANONICAL).cases


def test_every_case_has_a_measured_ratio(cases):
    missing = [c.name for c in cases if c.name not in PER_SAMPLE_RATIO and c.name not in NO_RATIO]
    assert not missing, f"no per-sample variance ratio measured for {missing}: run the case and add its k"


def test_every_case_expected_to_pass_has_a_ground_truth_under_a_quarter_of_its_noise(cases):
    over = {c.name: round(share(c), 3) for c in cases
            if c.expect == "pass" and c.name in PER_SAMPLE_RATIO and share(c) > GROUND_TRUTH_SHARE_LIMIT}
    unexpected = {name: r for name, r in over.items() if name not in OVER_BUDGET}
    assert not unexpected, (f"ground truth's share of the verdict's variance over 1/4 (raise ground_truth_spp to "
                            f"4 x k x spp): {unexpected}")
    assert set(over) == OVER_BUDGET, f"fixed, remove from OVER_BUDGET: {sorted(OVER_BUDGET - set(over))}"


def test_planted_faults_are_exempt_only_while_caught():
    """A case that expects "fail" and fails: the ratio and the suggestion, no warning (its fault was caught through
    the noise). One that passes (its fault hidden, perhaps by that noise): the warning."""
    case = SimpleNamespace(expect="fail", against=SimpleNamespace(kind="ground-truth"))
    result = SimpleNamespace(variance=np.full((4, 4, 3), 1.0))
    gt = SimpleNamespace(variance=np.full((4, 4, 3), 2.0), spp=1024)
    caught = ground_truth_noise(case, result, gt, "fail")
    assert caught["ratio"] == 2.0 and caught["suggested_spp"] == 8192 and caught["warning"] is None
    hidden = ground_truth_noise(case, result, gt, "pass")
    assert "8192 would bring it under 1/4" in hidden["warning"]
    expected_pass = ground_truth_noise(SimpleNamespace(expect="pass", against=case.against), result, gt, "pass")
    assert expected_pass["warning"] is not None
