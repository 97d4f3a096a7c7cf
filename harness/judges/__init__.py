"""Judges: statistical tests you can run on your own samplers and images (numpy and scipy only).

* :mod:`harness.judges.chi2` -- chi-square goodness-of-fit of a sampling routine against its own pdf, the idea of
  Mitsuba 3's ``mitsuba.chi2``: :func:`~harness.judges.chi2.chi2_test` (any dimension), ``chi2_test_1d``,
  ``chi2_test_2d``, ``chi2_test_discrete``, the result type ``Chi2Result``, ``sidak_alpha`` for a family of tests,
  and the direction helpers (``directions_to_cos_phi``, ``SPHERE_COS_PHI``, ``to_local``, ...).
* :mod:`harness.judges.mc` -- Monte Carlo image statistics with tolerances from the estimator's own variance:
  ``image_mean``, ``z_scores``, ``z_critical`` (Bonferroni) and the omnibus ``tile_chi2``.

These modules import nothing from the rest of the harness, so they can be used (or copied) on their own.
"""

from harness.judges.chi2 import (
    FAMILY_ALPHA,
    SPHERE_COS_PHI,
    Chi2Result,
    chi2_test,
    chi2_test_1d,
    chi2_test_2d,
    chi2_test_discrete,
    directions_to_cos_phi,
    sidak_alpha,
)
from harness.judges.mc import FALSE_ALARM, ImageMean, image_mean, tile_chi2, z_critical, z_scores

__all__ = [
    "FAMILY_ALPHA",
    "SPHERE_COS_PHI",
    "Chi2Result",
    "chi2_test",
    "chi2_test_1d",
    "chi2_test_2d",
    "chi2_test_discrete",
    "directions_to_cos_phi",
    "sidak_alpha",
    "FALSE_ALARM",
    "ImageMean",
    "image_mean",
    "tile_chi2",
    "z_critical",
    "z_scores",
]
