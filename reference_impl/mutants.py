"""Planted faults: deliberately wrong variants of the integrator, selectable by name (``--set mutant=NAME``).

They exist so that tests and the harness's verdict can prove that they catch real mistakes: a verdict that passes
one of these at its default budget is not sharp enough. None runs by default. "energy-loss-2pct" lives in
``reference_impl/integrator.py`` (guarded by ``_Context.mutant``), the others in the compiled kernels of
``reference_impl/kernels/``, as bits of ``kernels.config.MUTANT_BITS`` in the kernels' configuration; every place a
fault changes is marked with a comment naming it.
"""

MUTANTS: dict[str, str] = {
    "double-emission": (
        "the slides' pseudo-code taken literally (Fig. 5.14/5.16 computeRadiance adds Le(y) when an indirect ray "
        "lands on a light), on top of the shadow-ray estimate: direct light is counted twice"
    ),
    "no-cosine": "the cosine factor cos(Psi, N_x) at x dropped from the direct (G) and indirect estimators",
    "cosine-pdf-pi": "the cosine-hemisphere pdf taken as cos(theta) instead of cos(theta) / pi (off by a factor pi)",
    "rr-no-reweight": "Russian-roulette survivors not divided by their survival probability",
    "light-pdf-ignored": "direct light divided by pdf(y|k) only: the light-selection pdf(k) ignored",
    "camera-half-pixel": "viewing rays shifted by half a pixel (right and down)",
    "no-ray-offset": "shadow rays start exactly on the surface (no self-intersection offset)",
    "energy-loss-2pct": "every camera sample's radiance scaled by 0.98 (a 2 % energy loss)",
}
