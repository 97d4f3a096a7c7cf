"""Renders of tiny canonical scenes keep the exact bits stored in ``tests/reference_impl/data/image_checksums.json``.

Every strategy and setting value of ``reference_impl.Settings``, every planted fault of ``reference_impl/mutants.py``
and every pixel filter is rendered on a 16 x 16 crop of a canonical scene at 4 spp, by both engines and with both
samplers (scenes with emitters that are not surfaces or with materials that are not diffuse: ``LOOP_CASES``, where
the wavefront runs only the Lambertian ones), and the SHA-256 of the float32 image and of the variance bytes, and
the counters, must be those stored. A
change meant to keep the images (a refactor of the kernels) must pass this unchanged; a change meant to alter them
regenerates the file, in a commit of its own, and says why:

    REGENERATE_IMAGE_CHECKSUMS=1 python -m pytest tests/reference_impl/test_image_checksums.py -q

which renders every case and rewrites the JSON file (the tests then pass against what they just wrote). The bits
depend on the numpy build, the CPU and libm (sin, cos, sqrt), as docs/performance.md says: on another machine the
checksums may have to be regenerated from a commit known to be good. All renders run in this one process, so numba's
compiled kernels are loaded once; the file takes a few seconds once they are in numba's cache.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
from pathlib import Path

import pytest
from conftest import load_small

from harness.scene import emitter_arrays, material_arrays, media_arrays, triangulate

DATA = Path(__file__).resolve().parent / "data" / "image_checksums.json"
REGENERATE = "REGENERATE_IMAGE_CHECKSUMS"
SIZE, SPP, SEED = 16, 4, 7

# (scene, settings): each value of each setting at least once, on a scene where it makes a difference.
BASE_CASES = [
    ("cornell-box", {}),
    ("multi-light", {}),
    ("soft-shadows", {}),
    ("furnace", {}),
    ("multi-light", {"direct": "hemisphere-cosine"}),
    ("multi-light", {"direct": "hemisphere-uniform", "shadow_rays": 2}),
    ("multi-light", {"direct": "global-area"}),
    ("cornell-box", {"direct": "global-area", "shadow_rays": 3}),
    ("multi-light", {"direct": "mis"}),
    ("cornell-box", {"direct": "mis", "shadow_rays": 2, "hemisphere": "uniform"}),
    ("cornell-box", {"direct": "mis", "indirect_rays": 2}),
    ("multi-light", {"shadow_rays": 3}),
    ("multi-light", {"light_selection": "uniform"}),
    ("cornell-box", {"indirect_rays": 2}),
    ("cornell-box", {"indirect_rays": 3, "shadow_rays": 2, "max_depth": 4}),
    ("cornell-box", {"hemisphere": "uniform"}),
    ("cornell-box", {"rr": "fixed"}),
    ("cornell-box", {"rr": "fixed", "absorption": 0.5, "rr_depth": 1}),
    ("cornell-box", {"rr": "off"}),
    ("furnace", {"rr_depth": 1}),
    ("cornell-box", {"max_depth": 1}),
    ("cornell-box", {"max_depth": 2}),
    ("cornell-box", {"max_depth": -1}),
    ("multi-light", {"direct": "mis", "max_depth": 2}),
    ("cornell-box", {"filter": "tent"}),
    ("cornell-box", {"filter": "gaussian"}),
    ("cornell-box", {"mutant": "double-emission"}),
    ("cornell-box", {"mutant": "no-cosine"}),
    ("cornell-box", {"mutant": "cosine-pdf-pi"}),
    ("furnace", {"mutant": "rr-no-reweight"}),
    ("multi-light", {"mutant": "light-pdf-ignored"}),
    ("multi-light", {"mutant": "light-pdf-ignored", "direct": "mis"}),
    ("soft-shadows", {"mutant": "camera-half-pixel"}),
    ("soft-shadows", {"mutant": "no-ray-offset"}),
    ("furnace", {"mutant": "energy-loss-2pct"}),
]
# Scenes with emitters that are not surfaces, and glossy scenes (whose every render is the path loop's).
LOOP_CASES = [
    ("point-spot", {}),
    ("point-spot", {"direct": "hemisphere-cosine"}),
    ("point-spot", {"mutant": "spot-ignores-beam-width"}),
    ("sun-sky", {"direct": "global-area"}),
    ("sun-sky", {"env_sampling": "cosine", "direct": "mis"}),
    ("envmap", {}),
    ("envmap", {"mutant": "envmap-mirrored-u"}),
    ("veach-mis", {}),
    ("veach-mis", {"direct": "bsdf"}),
    ("veach-mis", {"mutant": "mis-weights-not-one"}),
    ("cornell-box-specular", {}),
    ("cornell-box-specular", {"rr": "throughput", "direct": "area"}),
    ("underwater", {}),
    ("underwater", {"mutant": "refraction-no-eta2"}),
    ("white-furnace-rough", {"mutant": "microfacet-pdf-no-jacobian"}),
    # shading normals (vertex normals, a normal and a bump map): the path loop's alone
    ("smooth-twins", {}),
    ("mapped-plates", {}),
    ("mapped-plates", {"direct": "hemisphere-cosine"}),
    ("leaning-plate", {"direct": "mis"}),
]
# Scenes with media or null boundaries: the volumetric path loop's alone (whatever ``engine`` says), both samplers
# (``independent`` keeps the hashes of every number; ``sobol`` draws the first vertex from the pixel's sets).
MEDIA_CASES = [
    ("fog-box", {}),
    ("fog-box", {"transmittance": "track", "rr": "albedo", "rr_depth": 1}),
    ("media-slab", {}),
    ("medium-furnace", {}),
    ("hg-cloud", {}),
    ("hg-cloud", {"medium_direct": "phase"}),
    ("medium-emitter", {}),
    ("medium-emitter", {"medium_direct": "light"}),
    ("glass-medium", {}),
    ("glass-medium", {"rr_depth": 1}),
    ("glass-sphere-medium", {}),
]
GLOSSY = {"veach-mis", "cornell-box-specular", "underwater", "white-furnace-rough", "smooth-twins", "mapped-plates",
          "leaning-plate"}  # (and the scenes with shading normals: no wavefront)
CASES = [(scene, {**settings, "engine": engine, "sampler": sampler})
         for scene, settings in BASE_CASES + LOOP_CASES for engine in ("path", "wavefront")
         for sampler in ("sobol", "independent") if not (engine == "wavefront" and scene in GLOSSY)]
CASES += [(scene, {**settings, "engine": "path", "sampler": sampler}) for scene, settings in MEDIA_CASES
          for sampler in ("sobol", "independent")]


def _case_id(scene: str, settings: dict) -> str:
    return "/".join([scene] + [f"{k}={v}" for k, v in settings.items()])


IDS = [_case_id(*case) for case in CASES]


@functools.cache
def _inputs(name: str, pixel_filter: str | None):
    scene = load_small(name, SIZE)
    if pixel_filter is not None:
        scene = dataclasses.replace(scene, film=dataclasses.replace(scene.film, filter=pixel_filter))
    materials = material_arrays(scene)
    geometry = triangulate(scene)
    media = media_arrays(scene, geometry)
    extra = {} if materials is None else {"materials": materials}
    if media is not None:
        extra["media"] = media
    return geometry, scene.camera, scene.film, scene.max_depth, emitter_arrays(scene), extra


@functools.cache
def _checksum(case_id: str) -> dict:
    """The render of one case: SHA-256 of its image and variance bytes, and its counters (not Embree's time)."""
    import reference_impl  # numba is imported with the first render

    scene, settings = CASES[IDS.index(case_id)]
    settings = dict(settings)
    geometry, camera, film, max_depth, emitters, materials = _inputs(scene, settings.pop("filter", None))
    values = {"spp": SPP, "seed": SEED, "max_depth": max_depth, "threads": 1, **settings}
    out = reference_impl.render(geometry, camera, film, reference_impl.Settings(**values), emitters=emitters,
                                **materials)
    stats = {k: v for k, v in sorted(out.stats.items()) if k != "embree_microseconds"}
    return {"image": hashlib.sha256(out.image.tobytes()).hexdigest(),
            "variance": hashlib.sha256(out.variance.tobytes()).hexdigest(), "stats": stats}


@pytest.fixture(scope="module")
def stored() -> dict:
    if os.environ.get(REGENERATE):
        data = {"size": SIZE, "spp": SPP, "seed": SEED, "cases": {i: _checksum(i) for i in IDS}}
        DATA.parent.mkdir(parents=True, exist_ok=True)
        tmp = DATA.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
        tmp.replace(DATA)
    return json.loads(DATA.read_text())


def test_the_stored_checksums_are_of_these_cases(stored):
    assert (stored["size"], stored["spp"], stored["seed"]) == (SIZE, SPP, SEED)
    assert sorted(stored["cases"]) == sorted(IDS), f"cases changed: regenerate with {REGENERATE}=1"


@pytest.mark.parametrize("case_id", IDS)
def test_render_keeps_its_bits(case_id, stored):
    expected = stored["cases"].get(case_id)
    assert expected is not None, f"no stored checksum for {case_id}: regenerate with {REGENERATE}=1"
    assert _checksum(case_id) == expected
