"""How much energy a single-scattering rough conductor loses, by roughness: the white furnace with a rough
conductor of Fresnel 1 (``scenes/white-furnace-rough.toml``), rendered by the reference and by Mitsuba 3 at each
alpha, side by side.

A microfacet BRDF with Smith's shadowing-masking counts light that leaves after one scattering event on the
microsurface and drops the light that would scatter again between microfacets (Heitz et al., "Multiple-Scattering
Microfacet BSDFs with the Smith Model", SIGGRAPH 2016, Fig. 1: a GGX conductor of Fresnel 1 keeps ~60 % at
alpha = 1 under uniform lighting). Under a constant environment L every pixel of a lossless surface would be L;
the ratio of the image's mean to L is the energy kept, averaged over the sphere's view directions as the camera
sees them. Both renderers must lose the same amount: the difference is judged by its z-score (the two means'
standard errors from the renders' own per-pixel variances; pixels are independent).

``python -m harness.studies.furnace_loss`` prints the table (``--help`` for the alphas, spp and film)."""

from __future__ import annotations

import dataclasses
import math
import sys

import numpy as np

from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import Parser
from harness.renderers import RenderRequest, get_renderer
from harness.scene import load_scene
from harness.scene.model import Scene
from reference_impl import Film

ALPHAS = (0.05, 0.1, 0.25, 0.5, 0.75, 1.0)
DISTRIBUTIONS = ("ggx", "beckmann")


def with_roughness(scene: Scene, alpha: float, distribution: str) -> Scene:
    """The furnace with its one material's ``alpha`` and ``distribution`` replaced."""
    (name, material), = scene.materials.items()
    changed = dataclasses.replace(material, alpha=float(alpha), distribution=distribution)
    return dataclasses.replace(scene, materials={name: changed})


def kept_fraction(result, radiance: np.ndarray) -> tuple[float, float]:
    """(mean over pixels and channels of image / L, its standard error from the per-pixel variances)."""
    ratio = np.asarray(result.image, np.float64) / radiance
    n = ratio.size
    if result.variance is None:
        return float(ratio.mean()), float("nan")
    var = np.asarray(result.variance, np.float64) / radiance**2
    return float(ratio.mean()), float(math.sqrt(var.sum()) / n)


def energy_loss_table(scene: Scene, alphas=ALPHAS, distributions=DISTRIBUTIONS, spp: int = 64, seed: int = 0,
                      mitsuba_variant: str | None = None, progress=None) -> list[dict]:
    """One row per (distribution, alpha): the fraction of L each renderer keeps, its standard error, and the
    z-score of their difference."""
    radiance = np.array(scene.emitters[0].radiance, dtype=np.float64)
    reference, mitsuba = get_renderer("reference"), get_renderer("mitsuba")
    settings = {"variant": mitsuba_variant} if mitsuba_variant else {}
    rows = []
    for distribution in distributions:
        for alpha in alphas:
            s = with_roughness(scene, alpha, distribution)
            ref = reference.render(s, RenderRequest(spp=spp, seed=seed))
            mit = mitsuba.render(s, RenderRequest(spp=spp, seed=seed, settings=dict(settings)))
            (rk, rse), (mk, mse) = kept_fraction(ref, radiance), kept_fraction(mit, radiance)
            z = (rk - mk) / math.hypot(rse, mse) if rse > 0 or mse > 0 else float("nan")
            rows.append({"distribution": distribution, "alpha": float(alpha), "reference": rk,
                         "reference_se": rse, "mitsuba": mk, "mitsuba_se": mse, "z": z,
                         "mitsuba_variant": mit.settings.get("variant")})
            if progress is not None:
                progress(rows[-1])
    return rows


def format_table(rows: list[dict]) -> str:
    lines = ["| distribution | alpha | reference keeps | Mitsuba keeps | difference z |", "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['distribution']} | {r['alpha']:g} | {r['reference']:.4f} +- {r['reference_se']:.4f} | "
                     f"{r['mitsuba']:.4f} +- {r['mitsuba_se']:.4f} | {r['z']:+.2f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = Parser(prog="python -m harness.studies.furnace_loss", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="scenes/white-furnace-rough.toml",
                        help="a white furnace with one rough material (default scenes/white-furnace-rough.toml)")
    parser.add_argument("--alphas", default=",".join(f"{a:g}" for a in ALPHAS),
                        help="comma-separated roughnesses in (0, 1] (default %(default)s)")
    parser.add_argument("--distributions", default=",".join(DISTRIBUTIONS), help="ggx and/or beckmann (default %(default)s)")
    parser.add_argument("--spp", type=options.positive_int, default=64, help="samples per pixel of each render (default 64)")
    parser.add_argument("--size", type=options.positive_int, default=32, help="film width and height (default 32)")
    parser.add_argument("--mitsuba-variant", default=None, help="Mitsuba variant, e.g. scalar_rgb (default: the best that works)")
    try:
        args = parser.parse_args(argv)
        try:
            alphas = [float(a) for a in args.alphas.split(",")]
        except ValueError:
            raise HarnessError("--alphas", f"expected comma-separated numbers, got {args.alphas!r}") from None
        if not all(0 < a <= 1 for a in alphas):
            raise HarnessError("--alphas", f"expected roughnesses in (0, 1], got {args.alphas!r}")
        bad = [d for d in args.distributions.split(",") if d not in DISTRIBUTIONS]
        if bad:
            raise HarnessError("--distributions", f"expected {' or '.join(DISTRIBUTIONS)}, got {bad[0]!r}")
        scene = load_scene(args.scene)
        if (len(scene.materials) != 1 or not next(iter(scene.materials.values())).is_rough or not scene.emitters
                or scene.emitters[0].type != "constant"):
            raise HarnessError(args.scene, "expected a white furnace: one rough material, a constant environment")
    except HarnessError as err:
        print(f"harness: error: {err}", file=sys.stderr)
        return 2
    scene = dataclasses.replace(scene, film=Film(args.size, args.size, scene.film.filter))
    rows = energy_loss_table(scene, alphas, args.distributions.split(","), args.spp,
                             mitsuba_variant=args.mitsuba_variant,
                             progress=lambda r: print(f"{r['distribution']} alpha {r['alpha']:g}: reference "
                                                      f"{r['reference']:.4f}, Mitsuba {r['mitsuba']:.4f}",
                                                      file=sys.stderr, flush=True))
    print(format_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
