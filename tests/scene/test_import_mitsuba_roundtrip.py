"""The acceptance test of ``harness import`` for Mitsuba 3 XML (issue 37): every canonical scene, exported as Mitsuba
XML (as ``harness export SCENE --format mitsuba-xml`` writes it) and imported back, is the same scene to the core:
the same triangles, texture coordinates and normals (bit for bit, where the XML carries them in float32: against
the float32 of the original), the same material and emitter tables, camera, film and depth; every one but
smooth-twins renders a bit-identical image with the reference (three at their own film, all on a small one).

What the XML does not carry, and so is compared apart:

* a sphere's ``subdivisions`` (the icosphere the exports and Cycles get; Mitsuba and the reference trace the
  analytic sphere): the original is compared at the default, 3;
* the names of shapes, materials and textures (``shape_3``, ``bsdf_0``, the texture file's stem) and so the order
  of the textures in the core's list: the material table is compared with each texture slot resolved to the
  texture it names;
* ``regions`` and ``description`` (the harness's own keys);
* the names of media (``medium_0``): the core's media tables are compared without them.

A scene with media renders with the reference once the volumetric path loop is on the branch (until then the core
refuses it, and its render tests are skipped).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENES
from reference_impl import Film

from harness.renderers import RenderRequest, get_renderer
from harness.renderers.export import export_scene
from harness.renderers.importers import import_scene
from harness.renderers.imports import write_imported
from harness.core.errors import HarnessError
from harness.scene import emitter_arrays, load_scene, material_arrays, media_arrays, triangulate
from harness.scene.triangulate import shape_triangles, shape_uv, vertex_normals

mi = pytest.importorskip("mitsuba")

CANONICAL = sorted(p.stem for p in SCENES.glob("*.toml"))
#: scenes whose reference renders at their own film are compared bit for bit (every scene is, on a 16 x 16 film)
RENDERED = ["cutout-leaf", "textured-cornell-box", "point-spot"]
#: scenes whose images are not the same bit for bit, and why
NOT_BIT_IDENTICAL = {
    "smooth-twins": "its eggs' vertex normals come back as the float32 the PLY holds, renormalised in float64 on "
                    "load (within 3e-8 of the original's): 26 of 256 pixels differ by at most 9e-8",
}


def round_trip(name: str, folder: Path):
    """The canonical scene ``name`` and its export imported back, both loaded."""
    original = load_scene(SCENES / f"{name}.toml")
    export_scene(original, "mitsuba-xml", folder / "xml", spp=4, seed=0)
    imported = import_scene(folder / "xml" / "scene.xml")
    assert imported.dropped == []
    back = load_scene(write_imported(imported, folder / "imported"))
    shapes = tuple(dataclasses.replace(s, subdivisions=3) if s.type == "sphere" else s for s in original.shapes)
    return dataclasses.replace(original, shapes=shapes), back


def as_fields(value):
    """A record's fields as a dict (dataclasses, named tuples, plain objects), None for anything else."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if hasattr(value, "_asdict"):
        return value._asdict()
    if hasattr(value, "__dict__") and not isinstance(value, (type, Path)):  # the core's plain classes
        return dict(vars(value))
    return None


def assert_same(a, b, path: str, skip=()) -> None:
    """``a`` and ``b`` equal field by field, arrays bit for bit (NaN equal to NaN)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), path
        return
    fields = as_fields(a)
    if fields is not None:
        other = as_fields(b)
        assert other is not None and set(fields) == set(other), path
        for key in fields:
            if key not in skip:
                assert_same(fields[key], other[key], f"{path}.{key}", skip)
        return
    if isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f"{path}[{i}]", skip)
        return
    assert a == b, (path, a, b)


def float32(values: np.ndarray) -> np.ndarray:
    return np.asarray(values, np.float64).astype(np.float32).astype(np.float64)


@pytest.mark.parametrize("name", CANONICAL)
def test_a_canonical_scene_round_trips_through_mitsuba_xml(name, tmp_path):
    original, back = round_trip(name, tmp_path)
    assert len(original.shapes) == len(back.shapes)
    for a, b in zip(original.shapes, back.shapes):
        va, ta = shape_triangles(a)
        vb, tb = shape_triangles(b)
        assert np.array_equal(ta, tb), a.name
        as_mesh = a.type == "mesh"  # written as a float32 PLY in world space
        assert np.array_equal(float32(va) if as_mesh else va, vb), a.name
        assert_same(shape_uv(a, ta), shape_uv(b, tb), f"{a.name} uv")
        assert (a.emission is None) == (b.emission is None) and a.flip_normals == b.flip_normals, a.name
        na, nb = vertex_normals(a, va, ta), vertex_normals(b, vb, tb)
        assert (na is None) == (nb is None), a.name
        if na is not None:  # float32 in the PLY, renormalised on load
            assert np.allclose(na, nb, rtol=0, atol=1e-7) if as_mesh else np.array_equal(na, nb), a.name
    meshes = any(s.type == "mesh" for s in original.shapes)
    geometry_a, geometry_b = triangulate(original), triangulate(back)
    skip = ("vertices", "normal", "normals", "area", "corners") if meshes else ()
    assert_same(geometry_a, geometry_b, "geometry", skip=skip + ("emission_texture",))
    assert_same(emission_textures(original, geometry_a), emission_textures(back, geometry_b), "emission textures")
    assert_same(resolved_materials(original), resolved_materials(back), "materials")
    assert_same(emitter_arrays(original), emitter_arrays(back), "emitters")
    assert_same(media_arrays(original, geometry_a), media_arrays(back, geometry_b), "media", skip=("names",))
    assert_same(original.camera, back.camera, "camera")
    assert_same(original.film, back.film, "film")
    assert original.max_depth == back.max_depth


def texture_keys(scene) -> list:
    """The scene's textures in the core's order, each as what it holds (its image, not its name)."""
    return [(t.type, t.core) for t in scene.used_textures]


def emission_textures(scene, geometry):
    """Each triangle's emission texture as the texture itself (None: none)."""
    keys = texture_keys(scene)
    return [None if k < 0 else keys[k] for k in np.asarray(geometry.emission_texture).tolist()] \
        if geometry.emission_texture is not None else None


def resolved_materials(scene):
    """The core's material table with each texture slot replaced by the texture it names."""
    table = material_arrays(scene)
    if table is None:
        return None
    keys = texture_keys(scene)
    slots = [[None if k < 0 else keys[k] for k in row] for row in np.asarray(table.texture).tolist()]
    return table.kind, table.params, slots


def render(scene, request: RenderRequest):
    """The reference's render of ``scene``; skipped for a scene with media while the core refuses them."""
    try:
        return get_renderer("reference").render(scene, request)
    except HarnessError as err:
        if scene.media and "not traced yet" in err.message:
            pytest.skip("the volumetric path loop is not on this branch yet")
        raise


@pytest.mark.slow
@pytest.mark.parametrize("name", RENDERED)
def test_an_imported_canonical_scene_renders_the_same_image(name, tmp_path):
    original, back = round_trip(name, tmp_path)
    renderer = get_renderer("reference")
    a = renderer.render(original, RenderRequest(spp=2, seed=0))
    b = renderer.render(back, RenderRequest(spp=2, seed=0))
    assert np.array_equal(a.image, b.image, equal_nan=True)


@pytest.mark.slow
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(reason=NOT_BIT_IDENTICAL[n], strict=True))
                                  if n in NOT_BIT_IDENTICAL else n for n in CANONICAL])
def test_every_imported_canonical_scene_renders_the_same_small_image(name, tmp_path):
    """On a 16 x 16 film at 1 spp, against the scene file itself (its spheres' own subdivisions: the reference
    traces the analytic sphere, so they change no pixel)."""
    _, back = round_trip(name, tmp_path)
    original = load_scene(SCENES / f"{name}.toml")
    film = Film(16, 16, original.film.filter)
    a = render(dataclasses.replace(original, film=film), RenderRequest(spp=1, seed=0))
    b = render(dataclasses.replace(back, film=film), RenderRequest(spp=1, seed=0))
    assert np.array_equal(a.image, b.image, equal_nan=True)
