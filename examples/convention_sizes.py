"""How large are the convention mistakes of docs/external-renderers.md ("For renderer authors")?

Renders cornell-box at 64 x 64, 512 spp, with the reference renderer, as it is and with each mistake (one path
vertex too many or too few, a Gaussian pixel filter, emission from both sides of the light), and prints how much
each changes the image's mean and the mean of the 8 x 8-pixel tile it changes most, beside the same figures for the
right scene rendered with another seed (the noise). About two minutes on two cores.

    python examples/convention_sizes.py
"""

import dataclasses
from pathlib import Path

import numpy as np

from harness.renderers import RenderRequest, get_renderer
from harness.scene import load_scene
from reference_impl.camera import Film

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "cornell-box.toml"
SIZE, SPP, TILE = 64, 512, 8


def tiles(image: np.ndarray) -> np.ndarray:
    n = SIZE // TILE
    return image.reshape(n, TILE, n, TILE, 3).mean(axis=(1, 3))


def main() -> None:
    base = load_scene(SCENE)
    base = dataclasses.replace(base, film=Film(SIZE, SIZE, "box"))
    reference = get_renderer("reference")

    def render(scene, seed=7):
        return reference.render(scene, RenderRequest(spp=SPP, seed=seed)).image.astype(np.float64)

    right = render(base)
    light = base.lights[0]
    back = dataclasses.replace(light, index=len(base.shapes), name="light-back", flip_normals=not light.flip_normals)
    variants = {
        "max_depth + 1 (Cycles max_bounces = max_depth)": dataclasses.replace(base, max_depth=base.max_depth + 1),
        "max_depth + 2": dataclasses.replace(base, max_depth=base.max_depth + 2),
        "max_depth - 1": dataclasses.replace(base, max_depth=base.max_depth - 1),
        "gaussian filter (stddev 0.5)": dataclasses.replace(base, film=Film(SIZE, SIZE, "gaussian")),
        "two-sided emission": dataclasses.replace(base, shapes=[*base.shapes, back]),
    }
    images = {name: render(scene) for name, scene in variants.items()}
    images["null (the right scene, another seed)"] = render(base, seed=8)
    for name, image in images.items():
        change = tiles(image) / tiles(right) - 1
        worst = change.flat[np.abs(change).argmax()]
        print(f"{name:48s} image mean {100 * (image.mean() / right.mean() - 1):+6.2f} %  "
              f"worst {TILE}x{TILE}-pixel tile {100 * worst:+7.2f} %")


if __name__ == "__main__":
    main()
