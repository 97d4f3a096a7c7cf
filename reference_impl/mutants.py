"""Planted faults: deliberately wrong variants of the integrator, selectable by name (``--set mutant=NAME``).

They exist so that tests and the harness's verdict can prove they catch real mistakes. None runs by default.
Each entry maps a name to what it gets wrong; the integrator consults ``Settings.mutant`` at the one place each
fault lives.
"""

MUTANTS: dict[str, str] = {
    "double-emission": (
        "the slides' pseudo-code taken literally (Fig. 5.14/5.16 computeRadiance adds Le(y) when an indirect ray "
        "lands on a light), on top of the shadow-ray estimate: direct light is counted twice"
    ),
}
