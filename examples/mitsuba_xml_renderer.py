#!/usr/bin/env python3
"""A minimal "foreign" renderer: renders a Mitsuba 3 XML scene file and writes an OpenEXR with R, G, B.

It knows nothing of the harness: it is what a user's own renderer looks like from the outside. Used by
``renderers/mitsuba-scalar-cli.toml`` and tests/test_external_renderer.py.

    python mitsuba_xml_renderer.py SCENE.xml --spp 16 --seed 3 --out image.exr [--variant scalar_rgb]
                                   [--energy-loss 0.03] [--fail-with-exit N]

``--energy-loss f`` is a planted fault: every pixel is multiplied by (1 - f), i.e. the renderer loses the fraction f
of the light. ``--fail-with-exit N`` exits with code N after writing to stderr (to test failure handling).
"""

import argparse
import sys


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", help="Mitsuba 3 XML scene")
    parser.add_argument("--spp", type=int, required=True)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True, help="OpenEXR file to write")
    parser.add_argument("--variant", default="scalar_rgb")
    parser.add_argument("--energy-loss", type=float, default=0.0, help="planted fault: lose this fraction of light")
    parser.add_argument("--fail-with-exit", type=int, default=0)
    args = parser.parse_args()
    if args.fail_with_exit:
        print(f"mitsuba_xml_renderer: failing on purpose with exit code {args.fail_with_exit}", file=sys.stderr)
        return args.fail_with_exit

    import mitsuba as mi
    import numpy as np

    mi.set_variant(args.variant)
    scene = mi.load_file(args.scene, spp=args.spp, seed=args.seed)
    image = np.array(mi.render(scene, spp=args.spp, seed=args.seed), dtype=np.float32)[..., :3]
    image *= np.float32(1.0 - args.energy_loss)
    mi.Bitmap(image, mi.Bitmap.PixelFormat.RGB).write(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
