"""Which materials keep the energy of the light, which lose it and how much, beside Mitsuba: the white furnace
(``scenes/white-furnace-rough.toml``: a sphere under a constant environment L and nothing else) with its sphere made
of each material of :data:`ROWS` in turn, white where the material has a colour, rendered by the reference and by
Mitsuba 3 (the table :mod:`harness.studies.furnace_loss` gives for the rough conductor's roughness).

A lossless material keeps L in every pixel; the ratio of the image's mean to L is the fraction kept, averaged over
the view directions the camera sees the sphere from. Single-scattering microfacet lobes lose the light that would
scatter again between microfacets; Mitsuba's plastics and its principled model can return more than 1 (their
diffuse bases' internal-reflection term, principled's retro-reflection and sheen). The two renderers must agree:
their difference is judged by its z-score (each mean's standard error from its own per-pixel variances).

``python -m harness.studies.material_furnace`` prints the table (``--help`` for the spp, the film and the rows)."""

from __future__ import annotations

import fnmatch
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

from harness.core import options
from harness.core.errors import HarnessError
from harness.core.options import Parser
from harness.renderers import RenderRequest, get_renderer
from harness.scene import load_scene
from harness.studies.furnace_loss import kept_fraction

EXACT = 1e-6  # a standard error below this: the renders are exact, their difference float rounding
FURNACE = Path(__file__).resolve().parents[2] / "scenes" / "white-furnace-rough.toml"
_WHITE_DIFFUSE = '[materials.white]\nreflectance = [1.0, 1.0, 1.0]\n'

#: (row name, the ``[materials]`` tables of the sphere's material, named ``ball``, and of what it holds)
ROWS: tuple[tuple[str, str], ...] = (
    *((f"roughplastic ggx alpha {a:g}", f'[materials.ball]\ntype = "roughplastic"\ndistribution = "ggx"\nalpha = {a}\n'
       'diffuse_reflectance = 1.0\n') for a in (0.05, 0.3, 0.7)),
    ("roughplastic beckmann alpha 0.3", '[materials.ball]\ntype = "roughplastic"\nalpha = 0.3\n'
                                        'diffuse_reflectance = 1.0\n'),
    ("plastic", '[materials.ball]\ntype = "plastic"\ndiffuse_reflectance = 1.0\n'),
    ("thindielectric", '[materials.ball]\ntype = "thindielectric"\n'),
    *((f"principled metallic {m:g} roughness {r:g}", f'[materials.ball]\ntype = "principled"\nbase_color = 1.0\n'
       f'metallic = {m}\nroughness = {r}\n') for m in (0.0, 1.0) for r in (0.2, 0.5, 0.9)),
    ("principled sheen 1", '[materials.ball]\ntype = "principled"\nbase_color = 1.0\nroughness = 0.5\nsheen = 1.0\n'),
    ("principled clearcoat 1", '[materials.ball]\ntype = "principled"\nbase_color = 1.0\nroughness = 0.5\n'
                               'clearcoat = 1.0\nclearcoat_gloss = 0.9\n'),
    ("principled spec_trans 1", '[materials.ball]\ntype = "principled"\nbase_color = 1.0\nroughness = 0.3\n'
                                'spec_trans = 1.0\n'),
    ("blendbsdf 0.5 of diffuse and rough mirror", _WHITE_DIFFUSE + '[materials.mirror]\ntype = "roughconductor"\n'
     'distribution = "ggx"\nalpha = 0.7\n[materials.ball]\ntype = "blendbsdf"\nweight = 0.5\nbsdf = ["white", '
     '"mirror"]\n'),
    ("mask 0.5 of a twosided diffuse", _WHITE_DIFFUSE + '[materials.sides]\ntype = "twosided"\nbsdf = "white"\n'
     '[materials.ball]\ntype = "mask"\nopacity = 0.5\nbsdf = "sides"\n'),
    ("twosided of diffuse and roughplastic", _WHITE_DIFFUSE + '[materials.coat]\ntype = "roughplastic"\nalpha = 0.3\n'
     'diffuse_reflectance = 1.0\n[materials.ball]\ntype = "twosided"\nbsdf = ["white", "coat"]\n'),
    # issue 38's null material, and the media inside a null and a glass boundary (a table [media.inside] is the
    # ball's interior, furnace_with): an albedo-1 medium loses nothing
    ("null", '[materials.ball]\ntype = "null"\n'),
    ("null around an albedo-1 medium (sigma_t 2, HG g 0.5)", '[media.inside]\nsigma_t = 2.0\nalbedo = 1.0\n'
     'phase = { type = "hg", g = 0.5 }\n[materials.ball]\ntype = "null"\n'),
    ("dielectric around an albedo-1 medium (sigma_t 2)", '[media.inside]\nsigma_t = 2.0\nalbedo = 1.0\n'
     '[materials.ball]\ntype = "dielectric"\n'),
)
#: a row's medium table of this name fills the ball (its interior)
INSIDE = "inside"


def furnace_with(materials: str, folder: Path, size: int):
    """The furnace scene with its sphere's material replaced by the tables ``materials`` (its main one ``ball``; a
    ``[media.inside]`` table among them the sphere's interior), at ``size`` x ``size`` pixels, written into
    ``folder`` and loaded."""
    text = FURNACE.read_text()
    start, end = text.index("[materials.ball]"), text.index("[[shapes]]")
    text = text[:start] + materials + "\n" + text[end:]
    if f"[media.{INSIDE}]" in materials:
        text = text.replace('material = "ball"\n', f'material = "ball"\ninterior = "{INSIDE}"\n', 1)
    text = text.replace("width = 64", f"width = {size}").replace("height = 64", f"height = {size}")
    path = folder / "furnace.toml"
    path.write_text(text)
    return load_scene(path)


def material_table(rows=ROWS, spp: int = 64, size: int = 32, seed: int = 0, mitsuba_variant: str | None = None,
                   progress=None) -> list[dict]:
    """One row per material: the fraction of L each renderer keeps, its standard error and their difference's z."""
    reference, mitsuba = get_renderer("reference"), get_renderer("mitsuba")
    settings = {"variant": mitsuba_variant} if mitsuba_variant else {}
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, tables in rows:
            scene = furnace_with(tables, Path(tmp), size)
            radiance = np.asarray(scene.emitters[0].radiance, dtype=np.float64)
            (rk, rse) = kept_fraction(reference.render(scene, RenderRequest(spp=spp, seed=seed)), radiance)
            (mk, mse) = kept_fraction(mitsuba.render(scene, RenderRequest(spp=spp, seed=seed, settings=dict(settings))),
                                      radiance)
            se = math.hypot(rse, mse)
            # both all but noise-free (a lossless sheet: every pixel L to float precision): no z to speak of
            z = (rk - mk) / se if se > EXACT else float("nan")
            out.append({"material": name, "reference": rk, "reference_se": rse, "mitsuba": mk, "mitsuba_se": mse,
                        "z": z})
            if progress is not None:
                progress(out[-1])
    return out


def format_table(rows: list[dict]) -> str:
    lines = ["| material | reference keeps | Mitsuba keeps | difference z |", "|---|---|---|---|"]
    for r in rows:
        z = f"{r['z']:+.2f}" if math.isfinite(r["z"]) else f"exact ({r['reference'] - r['mitsuba']:+.1e})"
        lines.append(f"| {r['material']} | {r['reference']:.4f} +- {r['reference_se']:.4f} | "
                     f"{r['mitsuba']:.4f} +- {r['mitsuba_se']:.4f} | {z} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = Parser(prog="python -m harness.studies.material_furnace", description=__doc__.split("\n\n")[0])
    parser.add_argument("--spp", type=options.positive_int, default=64, help="samples per pixel of each render (default 64)")
    parser.add_argument("--size", type=options.positive_int, default=32, help="film width and height (default 32)")
    parser.add_argument("--rows", default="*", help="only the rows whose name matches this glob (default all)")
    parser.add_argument("--mitsuba-variant", default=None, help="Mitsuba variant, e.g. scalar_rgb (default: the best that works)")
    try:
        args = parser.parse_args(argv)
        rows = [row for row in ROWS if fnmatch.fnmatch(row[0], args.rows)]
        if not rows:
            raise HarnessError("--rows", f"expected a glob matching a row ({', '.join(r[0] for r in ROWS)}), got "
                                         f"{args.rows!r}")
    except HarnessError as err:
        print(f"harness: error: {err}", file=sys.stderr)
        return 2
    table = material_table(rows, args.spp, args.size, mitsuba_variant=args.mitsuba_variant,
                           progress=lambda r: print(f"{r['material']}: reference {r['reference']:.4f}, Mitsuba "
                                                    f"{r['mitsuba']:.4f}", file=sys.stderr, flush=True))
    print(format_table(table))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
