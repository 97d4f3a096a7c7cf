"""Ground truth (harness/renderers/groundtruth.py): the furnace's closed form, Mitsuba ground truths through the
content-addressed cache (keys, chunks, resumption, corruption, concurrent writers) and the ``ground-truth`` CLI.

Every Mitsuba render here is tiny (8 x 8 or 16 x 16 pixels, a few samples per pixel, ``scalar_rgb``) and every cache
lives under ``tmp_path``; ``$HARNESS_CACHE_DIR`` points into ``tmp_path`` too, so the user's cache is never touched.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, SCENES, load_small

from harness.core.errors import HarnessError
from harness.renderers.groundtruth import Cache, ground_truth
from harness.files.imageio import read_exr
from harness.judges.moments import Estimate, merge
from harness.renderers.mitsuba import MitsubaRenderer
from harness.scene import load_scene

pytestmark = pytest.mark.slow  # renders or starts processes: outside the inner loop (pytest -m "not slow")

VARIANT = "scalar_rgb"  # the fastest variant for 8 x 8 films (no JIT compilation)
LE = np.array([1.0, 1.0, 1.0])
RHO = np.array([0.3, 0.5, 0.7])
TESTS = Path(__file__).resolve().parents[1]  # tests/: conftest.py


@pytest.fixture(autouse=True)
def isolated_default_cache(tmp_path, monkeypatch):
    """Point the default ground-truth cache into tmp_path, so nothing here can write to the user's cache."""
    monkeypatch.setenv("HARNESS_CACHE_DIR", str(tmp_path / "default-cache"))


@pytest.fixture
def renders(monkeypatch):
    """Wrap MitsubaRenderer.render: ``renders.calls`` counts calls, ``renders.results`` keeps each result and
    ``renders.fail_on`` (a call number, 1-based) makes that call raise (an interrupted ground truth)."""
    original = MitsubaRenderer.render

    class Recorder:
        calls = 0
        results: list = []
        fail_on: int | None = None

    Recorder.results = []

    def wrapped(self, scene, request):
        Recorder.calls += 1
        if Recorder.fail_on is not None and Recorder.calls == Recorder.fail_on:
            raise RuntimeError("interrupted")
        result = original(self, scene, request)
        Recorder.results.append(result)
        return result

    monkeypatch.setattr(MitsubaRenderer, "render", wrapped)
    return Recorder


def small(name: str = "soft-shadows", width: int = 8, height: int | None = None, **overrides):
    return load_small(name, width, height, **overrides)


def gt(scene, cache_dir, *, spp: int = 4, chunk_spp: int = 4, seed: int = 0, **kwargs):
    return ground_truth(scene, spp=spp, chunk_spp=chunk_spp, seed=seed, cache_dir=cache_dir, variant=VARIANT,
                        **kwargs)


def entries(cache_dir: Path) -> list[Path]:
    """The cache's entry folders (not the hidden .tmp-* / .bad-* folders)."""
    folder = Path(cache_dir) / "groundtruth"
    if not folder.exists():
        return []
    return sorted(p for p in folder.iterdir() if not p.name.startswith("."))


def hidden(cache_dir: Path) -> list[Path]:
    folder = Path(cache_dir) / "groundtruth"
    return sorted(p for p in folder.iterdir() if p.name.startswith(".")) if folder.exists() else []


def copy_scene(name: str, folder: Path, size: int = 8) -> Path:
    """A canonical scene file copied into ``folder`` with its film shrunk to size x size (for the CLI)."""
    text = (SCENES / f"{name}.toml").read_text()
    lines = []
    for line in text.splitlines():
        if line.startswith("width =") or line.startswith("height ="):
            line = f"{line.split('=')[0]}= {size}"
        lines.append(line)
    path = folder / f"{name}.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def assert_same(a, b):
    """Bitwise-identical image and variance."""
    assert a.image.dtype == b.image.dtype and a.variance.dtype == b.variance.dtype
    assert a.image.tobytes() == b.image.tobytes()
    assert a.variance.tobytes() == b.variance.tobytes()


# --------------------------------------------------------------------------------------------------------------------
# 1. Closed form


@pytest.mark.parametrize("max_depth", [1, 3, -1])
def test_furnace_closed_form(max_depth, tmp_path, monkeypatch):
    def no_render(self, scene, request):
        raise AssertionError("the closed form must not render")

    monkeypatch.setattr(MitsubaRenderer, "render", no_render)
    scene = dataclasses.replace(load_scene(SCENES / "furnace.toml"), max_depth=max_depth)
    result = ground_truth(scene, cache_dir=tmp_path / "cache")

    expected = LE / (1.0 - RHO) if max_depth == -1 else LE * sum(RHO**i for i in range(max_depth))
    if max_depth == 1:
        np.testing.assert_allclose(expected, LE)
    if max_depth == -1:
        np.testing.assert_allclose(expected, [1 / 0.7, 2.0, 1 / 0.3])
    assert result.source == "closed-form"
    assert result.image.shape == (scene.film.height, scene.film.width, 3)
    assert np.all(result.image == result.image[0, 0])  # every pixel the same
    np.testing.assert_allclose(result.image[0, 0], expected, rtol=1e-6)
    assert result.variance.shape == result.image.shape and not np.any(result.variance)
    assert result.renders == 0 and result.spp == 0 and result.path is None
    np.testing.assert_allclose(result.info["radiance"], expected, rtol=1e-12)
    assert not (tmp_path / "cache").exists()  # the cache is not even opened


def test_furnace_closed_form_can_be_skipped(tmp_path, renders):
    """use_closed_form=False renders the furnace with Mitsuba instead, which agrees with the closed form."""
    scene = dataclasses.replace(small("furnace"), max_depth=2)
    result = gt(scene, tmp_path, spp=16, chunk_spp=16)
    assert result.source == "closed-form" and renders.calls == 0
    mitsuba = gt(scene, tmp_path, spp=16, chunk_spp=16, use_closed_form=False)
    assert mitsuba.source == "mitsuba" and renders.calls == 1
    # L = Le (1 + rho) exactly for every path of depth 2 (light sampling inside a sphere: tiny variance).
    np.testing.assert_allclose(mitsuba.image.mean(axis=(0, 1)), LE * (1 + RHO), rtol=0.05)


def _with_shapes(scene, *changes):
    base = scene.shapes[0]
    shapes = [base] + [dataclasses.replace(base, index=i + 1, name=f"extra{i}", **c) for i, c in enumerate(changes)]
    return dataclasses.replace(scene, shapes=shapes)


@pytest.mark.parametrize(
    "changes",
    [
        [{"emission": (2.0, 2.0, 2.0)}],  # two different emissions
        [{"emission": None}],  # a shape that does not emit
    ],
    ids=["two-emissions", "non-emitting-shape"],
)
def test_furnace_closed_form_rejects_other_scenes(changes, tmp_path, monkeypatch):
    monkeypatch.setattr(MitsubaRenderer, "render", lambda *a: pytest.fail("must not render"))
    scene = _with_shapes(load_scene(SCENES / "furnace.toml"), *changes)
    with pytest.raises(HarnessError, match="furnace closed form"):
        ground_truth(scene, cache_dir=tmp_path)


def test_furnace_closed_form_rejects_two_albedos(tmp_path):
    furnace = load_scene(SCENES / "furnace.toml")
    materials = dict(furnace.materials)
    materials["other"] = dataclasses.replace(materials["grey"], name="other", reflectance=(0.1, 0.1, 0.1))
    scene = _with_shapes(dataclasses.replace(furnace, materials=materials), {"material": "other"})
    with pytest.raises(HarnessError, match="furnace closed form"):
        ground_truth(scene, cache_dir=tmp_path)


def test_furnace_file_with_two_emissions(tmp_path):
    """The same from a scene file: a second, brighter sphere inside the furnace."""
    text = (SCENES / "furnace.toml").read_text() + textwrap.dedent("""
        [[shapes]]
        name = "inner"
        type = "sphere"
        radius = 0.5
        material = "grey"
        flip_normals = true
        emission = [2.0, 2.0, 2.0]
        """)
    path = tmp_path / "furnace2.toml"
    path.write_text(text)
    with pytest.raises(HarnessError, match="furnace closed form") as err:
        ground_truth(load_scene(path), cache_dir=tmp_path)
    assert "\n" not in str(err.value)


def test_unbounded_furnace_needs_albedo_below_one(tmp_path):
    furnace = load_scene(SCENES / "furnace.toml")
    materials = {"grey": dataclasses.replace(furnace.materials["grey"], reflectance=(1.0, 0.5, 0.5))}
    with pytest.raises(HarnessError, match="albedo < 1"):
        ground_truth(dataclasses.replace(furnace, materials=materials), cache_dir=tmp_path)


# --------------------------------------------------------------------------------------------------------------------
# 2. Mitsuba ground truth and the cache key


def test_second_call_comes_from_the_cache(tmp_path, renders):
    scene = small()
    first = gt(scene, tmp_path)
    assert renders.calls == 1
    assert first.source == "mitsuba" and first.spp == 4 and not first.cached and first.renders == 1
    assert first.image.shape == (8, 8, 3) and first.image.dtype == np.float32
    assert np.all(np.isfinite(first.image)) and first.image.mean() > 0
    assert first.path is not None and first.path.name == "image.exr" and first.path.exists()
    assert first.path.parent.parent == tmp_path / "groundtruth"
    assert Cache(tmp_path).load(first.path.parent.name) is not None
    # the same as the render itself
    np.testing.assert_array_equal(first.image, renders.results[0].image)
    np.testing.assert_array_equal(first.variance, renders.results[0].variance)

    second = gt(scene, tmp_path)
    assert renders.calls == 1  # no render at all
    assert second.cached and second.renders == 0 and second.source == "mitsuba" and second.spp == 4
    assert_same(first, second)
    assert second.path == first.path
    exr = read_exr(second.path)
    np.testing.assert_array_equal(exr.image, second.image)
    np.testing.assert_array_equal(exr.variance, second.variance)
    assert second.info["variant"] == VARIANT and second.info["spp"] == 4


def test_scene_folder_does_not_matter_only_its_bytes(tmp_path, renders):
    """The key is over the file's content (its bytes and its name): a byte-identical copy in another folder hits the
    same entry."""
    copy = tmp_path / "elsewhere" / "soft-shadows.toml"
    copy.parent.mkdir()
    copy.write_bytes((SCENES / "soft-shadows.toml").read_bytes())
    original = small()
    first = gt(original, tmp_path / "cache")
    moved = dataclasses.replace(load_scene(copy), film=original.film)
    second = gt(moved, tmp_path / "cache")
    assert renders.calls == 1 and second.cached and second.path == first.path


def test_key_changes_with_what_determines_the_image(tmp_path, renders):
    cache = tmp_path / "cache"
    copied = tmp_path / "scene" / "soft-shadows.toml"
    copied.parent.mkdir()
    copied.write_bytes((SCENES / "soft-shadows.toml").read_bytes())
    film = small().film
    scene = dataclasses.replace(load_scene(copied), film=film)

    base = gt(scene, cache)
    assert renders.calls == 1
    seen = {base.path.parent.name}

    def differs(result, new_renders: int = 1):
        before = renders.calls - new_renders
        assert result.renders == new_renders and not result.cached, result.info
        assert renders.calls == before + new_renders
        assert result.path.parent.name not in seen
        seen.add(result.path.parent.name)

    differs(gt(scene, cache, spp=2, chunk_spp=2))
    differs(gt(scene, cache, seed=1))
    differs(gt(dataclasses.replace(scene, film=dataclasses.replace(film, width=16)), cache))
    differs(gt(dataclasses.replace(scene, film=dataclasses.replace(film, height=6)), cache))
    differs(gt(dataclasses.replace(scene, film=dataclasses.replace(film, filter="tent")), cache))
    differs(gt(dataclasses.replace(scene, max_depth=3), cache))
    # 8 spp in chunks of 4: a new ground truth whose first chunk is the base's (same seed, index and size)
    differs(gt(scene, cache, spp=8, chunk_spp=4), new_renders=1)

    # the scene file's bytes: a comment changes nothing in the scene, but the key is over the bytes
    with copied.open("a") as f:
        f.write("# a comment\n")
    edited = dataclasses.replace(load_scene(copied), film=film)
    differs(gt(edited, cache))

    # and every one of these is now cached (the key reads the file when the ground truth is asked for)
    calls = renders.calls
    assert gt(edited, cache).cached
    copied.write_bytes((SCENES / "soft-shadows.toml").read_bytes())
    assert gt(scene, cache).path == base.path
    assert gt(scene, cache, seed=1).cached and gt(dataclasses.replace(scene, max_depth=3), cache).cached
    assert gt(scene, cache).cached and gt(scene, cache, spp=8, chunk_spp=4).cached
    assert renders.calls == calls


MESH_SCENE = """\
name = "mesh-floor"

[camera]
origin = [0.0, 1.5, 2.5]
target = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov = 50.0

[film]
width = 8
height = 8

[integrator]
max_depth = 2

[materials.grey]
reflectance = [0.6, 0.6, 0.6]

[[shapes]]
name = "floor"
type = "mesh"
material = "grey"
file = "floor.ply"

[[shapes]]
name = "light"
type = "rectangle"
material = "grey"
translate = [0.0, 2.0, 0.0]
rotate = { axis = [1.0, 0.0, 0.0], angle = 90.0 }
emission = [4.0, 4.0, 4.0]
"""


def write_floor(path: Path, y: float = 0.0) -> None:
    """A 2 x 2 quad facing +y, written as PLY by trimesh."""
    import trimesh

    vertices = np.array([[-1, y, -1], [1, y, -1], [1, y, 1], [-1, y, 1]], dtype=np.float64)
    faces = np.array([[0, 3, 2], [0, 2, 1]])
    trimesh.Trimesh(vertices, faces, process=False).export(path)


def test_mesh_file_is_part_of_the_key(tmp_path, renders):
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "mesh.toml").write_text(MESH_SCENE)
    write_floor(folder / "floor.ply")
    cache = tmp_path / "cache"

    first = gt(load_scene(folder / "mesh.toml"), cache)
    assert renders.calls == 1 and first.image.mean() > 0
    assert gt(load_scene(folder / "mesh.toml"), cache).cached and renders.calls == 1

    write_floor(folder / "floor.ply", y=-0.5)  # same scene file, different mesh
    second = gt(load_scene(folder / "mesh.toml"), cache)
    assert renders.calls == 2 and not second.cached
    assert second.path.parent != first.path.parent
    assert not np.array_equal(first.image, second.image)

    write_floor(folder / "floor.ply")  # the original bytes again: the original entry
    third = gt(load_scene(folder / "mesh.toml"), cache)
    assert renders.calls == 2 and third.cached and third.path == first.path
    assert_same(first, third)


def test_missing_mesh_file_is_a_harness_error(tmp_path):
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "mesh.toml").write_text(MESH_SCENE)
    write_floor(folder / "floor.ply")
    scene = load_scene(folder / "mesh.toml")
    (folder / "floor.ply").unlink()
    with pytest.raises(HarnessError, match="content key") as error:
        gt(scene, tmp_path / "cache")
    assert error.value.where == str((folder / "floor.ply").resolve())


# --------------------------------------------------------------------------------------------------------------------
# 3. Chunks


def test_chunks_merge_exactly(tmp_path, renders):
    scene = small()
    progress = []
    result = gt(scene, tmp_path, spp=6, chunk_spp=2, progress=lambda done, total: progress.append((done, total)))
    assert renders.calls == 3 and result.renders == 3 and result.info["chunks"] == 3
    assert progress == [(2, 6), (4, 6), (6, 6)]
    chunks = [Estimate(r.image, r.variance, 2) for r in renders.results]
    assert all(r.spp == 2 for r in renders.results)
    # three independent chunks (different seeds)
    assert not np.array_equal(chunks[0].mean, chunks[1].mean) and not np.array_equal(chunks[1].mean, chunks[2].mean)
    merged = merge(chunks)
    assert merged.n == 6
    np.testing.assert_array_equal(result.image, merged.mean.astype(np.float32))
    np.testing.assert_array_equal(result.variance, merged.variance.astype(np.float32))
    # and the cached full entry holds the float64 merge itself
    estimate, meta = Cache(tmp_path).load(result.path.parent.name)
    assert estimate.n == 6 and meta["chunks"] == 3
    np.testing.assert_array_equal(estimate.mean, merged.mean)
    np.testing.assert_array_equal(estimate.variance, merged.variance)
    # four entries: three chunks and the merged one
    assert len(entries(tmp_path)) == 4


def test_last_chunk_holds_the_remainder(tmp_path, renders):
    result = gt(small(), tmp_path, spp=5, chunk_spp=2)
    assert [r.spp for r in renders.results] == [2, 2, 1]
    assert result.spp == 5 and result.info["chunks"] == 3
    merged = merge(Estimate(r.image, r.variance, r.spp) for r in renders.results)
    np.testing.assert_array_equal(result.image, merged.mean.astype(np.float32))


def test_interrupted_ground_truth_resumes(tmp_path, renders):
    scene = small()
    renders.fail_on = 2
    with pytest.raises(RuntimeError, match="interrupted"):
        gt(scene, tmp_path, spp=6, chunk_spp=2)
    assert renders.calls == 2
    (kept,) = entries(tmp_path)  # chunk 1 and nothing else
    estimate, meta = Cache(tmp_path).load(kept.name)
    assert meta["chunk"] == 0 and meta["spp"] == 2 and estimate.n == 2
    np.testing.assert_array_equal(estimate.mean, renders.results[0].image)
    assert not hidden(tmp_path)

    renders.fail_on = None
    result = gt(scene, tmp_path, spp=6, chunk_spp=2)
    assert renders.calls == 4 and result.renders == 2 and not result.cached
    merged = merge(Estimate(r.image, r.variance, 2) for r in renders.results)  # chunk 1, then 2 and 3
    np.testing.assert_array_equal(result.image, merged.mean.astype(np.float32))
    np.testing.assert_array_equal(result.variance, merged.variance.astype(np.float32))

    # the resumed ground truth is the one an uninterrupted run gives
    fresh = gt(scene, tmp_path / "fresh", spp=6, chunk_spp=2)
    assert_same(fresh, result)


# --------------------------------------------------------------------------------------------------------------------
# 4. Corruption


def _flip_npz(entry: Path) -> None:
    path = entry / "estimate.npz"
    data = bytearray(path.read_bytes())
    for i in range(len(data) // 2, len(data) // 2 + 8):
        data[i] ^= 0xFF
    path.write_bytes(bytes(data))


def _replace_npz(entry: Path) -> None:
    """A perfectly readable estimate.npz, but not the one that was rendered: only the checksum can tell."""
    with np.load(entry / "estimate.npz") as data:
        mean, variance, n = data["mean"], data["variance"], data["n"]
    with open(entry / "estimate.npz", "wb") as f:
        np.savez(f, mean=mean * 2 + 1, variance=variance, n=n)


def _truncate_exr(entry: Path) -> None:
    path = entry / "image.exr"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _delete_meta(entry: Path) -> None:
    (entry / "meta.json").unlink()


def _meta_writer(content: bytes):
    def write(entry: Path) -> None:
        (entry / "meta.json").write_bytes(content)

    return write


def _truncate_meta(entry: Path) -> None:
    path = entry / "meta.json"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _drop_checksums(entry: Path) -> None:
    """meta.json still parses but no longer lists the checksums: the entry cannot be verified."""
    path = entry / "meta.json"
    meta = json.loads(path.read_text())
    meta["sha256"] = {}
    path.write_text(json.dumps(meta))
    _replace_npz(entry)


DAMAGE = {
    "flip-npz-bytes": _flip_npz,
    "replace-npz": _replace_npz,
    "truncate-exr": _truncate_exr,
    "empty-exr": lambda e: (e / "image.exr").write_bytes(b""),
    "delete-exr": lambda e: (e / "image.exr").unlink(),
    "delete-npz": lambda e: (e / "estimate.npz").unlink(),
    "delete-meta": _delete_meta,
    "garbage-meta": _meta_writer(b"\x00\xff garbage \xfe{{{"),
    "text-garbage-meta": _meta_writer(b"this is not json"),
    "empty-meta": _meta_writer(b""),
    "truncated-meta": _truncate_meta,
    "json-null-meta": _meta_writer(b"null"),
    "json-list-meta": _meta_writer(b"[1, 2, 3]"),
    "json-string-meta": _meta_writer(b'"garbage"'),
    "meta-without-checksums": _meta_writer(b"{}"),
    "meta-checksums-not-a-dict": _meta_writer(b'{"sha256": ["x"]}'),
    "meta-checksums-dropped": _drop_checksums,
}


@pytest.mark.parametrize("damage", list(DAMAGE), ids=list(DAMAGE))
def test_damaged_entries_are_rendered_again(damage, tmp_path, renders):
    scene = small()
    good = gt(scene, tmp_path, spp=4, chunk_spp=2)
    assert renders.calls == 2 and len(entries(tmp_path)) == 3
    for entry in entries(tmp_path):  # every chunk and the merged entry
        DAMAGE[damage](entry)

    again = gt(scene, tmp_path, spp=4, chunk_spp=2)
    assert renders.calls == 4 and again.renders == 2 and not again.cached  # detected, rendered again
    assert_same(again, good)  # scalar_rgb renders are deterministic: the damaged data was not used
    assert np.all(np.isfinite(again.image))
    # the cache is whole again, with no leftovers
    assert len(entries(tmp_path)) == 3 and not hidden(tmp_path)
    for entry in entries(tmp_path):
        assert Cache(tmp_path).load(entry.name) is not None
    third = gt(scene, tmp_path, spp=4, chunk_spp=2)
    assert renders.calls == 4 and third.cached
    assert_same(third, good)


@pytest.mark.parametrize("damage", ["flip-npz-bytes", "truncate-exr", "garbage-meta", "json-null-meta"])
def test_damaged_merged_entry_is_rebuilt_from_its_chunks(damage, tmp_path, renders):
    scene = small()
    good = gt(scene, tmp_path, spp=4, chunk_spp=2)
    DAMAGE[damage](good.path.parent)
    again = gt(scene, tmp_path, spp=4, chunk_spp=2)
    assert renders.calls == 2 and again.renders == 0 and again.cached
    assert_same(again, good)
    assert Cache(tmp_path).load(good.path.parent.name) is not None and not hidden(tmp_path)


@pytest.mark.parametrize("damage", list(DAMAGE), ids=list(DAMAGE))
def test_cache_load_never_returns_damaged_data(damage, tmp_path):
    cache = Cache(tmp_path)
    estimate = Estimate(np.full((4, 4, 3), 0.5, np.float32), np.full((4, 4, 3), 0.01, np.float32), 8)
    cache.store("k", estimate, {"what": "test"})
    assert cache.load("k") is not None
    DAMAGE[damage](cache.entry("k"))
    assert cache.load("k") is None
    assert not cache.entry("k").exists() and not hidden(tmp_path)
    cache.store("k", estimate, {"what": "test"})  # the place is free again
    loaded, meta = cache.load("k")
    np.testing.assert_array_equal(loaded.mean, estimate.mean)
    assert meta["what"] == "test"


def test_leftover_entry_folder_without_meta_is_replaced(tmp_path):
    """An entry folder without meta.json (a crashed writer of an older version, a user's cp) is never used."""
    cache = Cache(tmp_path)
    cache.entry("k").mkdir(parents=True)
    (cache.entry("k") / "estimate.npz").write_bytes(b"junk")
    estimate = Estimate(np.ones((2, 2, 3)), np.zeros((2, 2, 3)), 4)
    cache.store("k", estimate, {})
    loaded, _ = cache.load("k")
    np.testing.assert_array_equal(loaded.mean, estimate.mean)


# --------------------------------------------------------------------------------------------------------------------
# 5. Concurrency


def test_store_keeps_an_existing_valid_entry(tmp_path):
    cache = Cache(tmp_path)
    first = Estimate(np.full((4, 4, 3), 1.0), np.full((4, 4, 3), 0.1), 4)
    second = Estimate(np.full((4, 4, 3), 2.0), np.full((4, 4, 3), 0.2), 4)
    path = cache.store("k", first, {"writer": "first"})
    before = {p.name: p.read_bytes() for p in cache.entry("k").iterdir()}
    assert cache.store("k", second, {"writer": "second"}) == path
    after = {p.name: p.read_bytes() for p in cache.entry("k").iterdir()}
    assert after == before
    loaded, meta = cache.load("k")
    assert meta["writer"] == "first"
    np.testing.assert_array_equal(loaded.mean, first.mean)
    np.testing.assert_array_equal(read_exr(path).image, first.mean.astype(np.float32))
    assert [p.name for p in tmp_path.joinpath("groundtruth").iterdir()] == ["k"]


def test_store_replaces_a_damaged_entry(tmp_path):
    cache = Cache(tmp_path)
    first = Estimate(np.full((4, 4, 3), 1.0), np.full((4, 4, 3), 0.1), 4)
    second = Estimate(np.full((4, 4, 3), 2.0), np.full((4, 4, 3), 0.2), 4)
    cache.store("k", first, {"writer": "first"})
    _truncate_exr(cache.entry("k"))
    cache.store("k", second, {"writer": "second"})
    loaded, meta = cache.load("k")
    assert meta["writer"] == "second"
    np.testing.assert_array_equal(loaded.mean, second.mean)
    assert not hidden(tmp_path)


def test_store_races_another_writer_for_a_damaged_entry(tmp_path, monkeypatch):
    """A damaged entry is removed by store(); another process takes the free place before this one: its (valid)
    entry is kept, and store() neither fails nor overwrites it."""
    cache = Cache(tmp_path)
    mine = Estimate(np.full((4, 4, 3), 1.0), np.full((4, 4, 3), 0.1), 4)
    theirs = Estimate(np.full((4, 4, 3), 2.0), np.full((4, 4, 3), 0.2), 4)
    cache.store("k", mine, {"writer": "old"})
    _truncate_exr(cache.entry("k"))
    real_load, real_store = Cache.load, Cache.store
    raced = []

    def racing_load(self, key):
        found = real_load(self, key)  # removes the damaged entry
        if found is None and not raced:
            raced.append(True)
            real_store(self, key, theirs, {"writer": "other"})  # the other process is faster
        return found

    monkeypatch.setattr(Cache, "load", racing_load)
    path = cache.store("k", mine, {"writer": "me"})
    monkeypatch.setattr(Cache, "load", real_load)
    assert raced and path == cache.entry("k") / "image.exr"
    loaded, meta = cache.load("k")
    assert meta["writer"] == "other"
    np.testing.assert_array_equal(loaded.mean, theirs.mean)
    assert not hidden(tmp_path)


def test_losing_writer_uses_the_winners_entry(tmp_path, renders, monkeypatch):
    """When another process stores the same entry first, the ground truth returned is the winner's (the cache's),
    not this process's own render: every user of one key sees the same image, and the image is the one at path."""
    real_store = Cache.store

    def racing_store(self, key, estimate, meta):
        if not self.entry(key).exists():  # another process wins the race with a different estimate
            other = Estimate(estimate.mean * 0 + 7.0, estimate.variance * 0 + 0.5, estimate.n)
            real_store(self, key, other, dict(meta, writer="other"))
        return real_store(self, key, estimate, meta)

    monkeypatch.setattr(Cache, "store", racing_store)
    result = gt(small(), tmp_path, spp=4, chunk_spp=2)
    assert renders.calls == 2
    estimate, meta = Cache(tmp_path).load(result.path.parent.name)
    assert meta.get("writer") == "other"
    np.testing.assert_array_equal(result.image, estimate.mean.astype(np.float32))
    np.testing.assert_array_equal(result.variance, estimate.variance.astype(np.float32))
    np.testing.assert_array_equal(read_exr(result.path).image, result.image)
    # and the next call (from the cache) returns the very same image
    again = gt(small(), tmp_path, spp=4, chunk_spp=2)
    assert again.cached and renders.calls == 2
    assert_same(again, result)


WORKER = r"""
import hashlib, json, sys, time
from pathlib import Path
sys.path.insert(0, sys.argv[1])
import numpy as np
from conftest import load_small
from harness.renderers.groundtruth import Cache, ground_truth
from harness.judges.moments import Estimate
from harness.renderers.mitsuba import choose_variant, import_mitsuba

cache_dir, go, ready, role = sys.argv[2:6]
choose_variant("scalar_rgb")
import_mitsuba("scalar_rgb")
scene = load_small("soft-shadows", 8)
Path(ready).touch()
deadline = time.time() + 60
while not Path(go).exists() and time.time() < deadline:
    time.sleep(0.001)
out = {"gt": [], "role": role}
for seed in range(6):
    gt = ground_truth(scene, spp=4, chunk_spp=2, seed=seed, cache_dir=cache_dir, variant="scalar_rgb")
    digest = hashlib.sha256(gt.image.tobytes() + gt.variance.tobytes()).hexdigest()
    out["gt"].append({"seed": seed, "renders": gt.renders, "digest": digest, "path": str(gt.path)})
cache = Cache(cache_dir)
value = {"a": 1.0, "b": 2.0}[role]
for i in range(40):
    est = Estimate(np.full((4, 4, 3), value), np.full((4, 4, 3), value / 10), 3)
    cache.store(f"stress-{i:02d}", est, {"writer": role})
print(json.dumps(out))
"""


def test_two_processes_fill_the_same_entries(tmp_path):
    cache_dir = tmp_path / "cache"
    go = tmp_path / "go"
    env = dict(os.environ, HARNESS_CACHE_DIR=str(tmp_path / "default-cache"))
    procs = []
    for role in ("a", "b"):
        ready = tmp_path / f"ready-{role}"
        procs.append(subprocess.Popen(
            [sys.executable, "-c", WORKER, str(TESTS), str(cache_dir), str(go), str(ready), role],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env,
        ))
    deadline = time.time() + 60
    while not all((tmp_path / f"ready-{r}").exists() for r in "ab"):
        assert time.time() < deadline and all(p.poll() is None for p in procs), "workers did not start"
        time.sleep(0.01)
    go.touch()  # both start at once
    outputs = []
    for proc in procs:
        stdout, stderr = proc.communicate(timeout=120)
        assert proc.returncode == 0, stderr
        outputs.append(json.loads(stdout.strip().splitlines()[-1]))

    cache = Cache(cache_dir)
    a, b = outputs
    for ra, rb in zip(a["gt"], b["gt"]):
        assert ra["path"] == rb["path"]
        assert ra["digest"] == rb["digest"]  # both got the same ground truth ...
        estimate, _ = cache.load(Path(ra["path"]).parent.name)  # ... the one in the cache, valid
        mean, variance = estimate.mean.astype(np.float32), estimate.variance.astype(np.float32)
        assert hashlib.sha256(mean.tobytes() + variance.tobytes()).hexdigest() == ra["digest"]
    # each seed: 2 chunks + the merged entry; plus the 40 stress entries
    names = [p.name for p in entries(cache_dir)]
    assert len(names) == 6 * 3 + 40
    for name in names:
        found = cache.load(name)
        assert found is not None, name
        if name.startswith("stress-"):
            estimate, meta = found
            value = {"a": 1.0, "b": 2.0}[meta["writer"]]
            np.testing.assert_array_equal(estimate.mean, np.full((4, 4, 3), value))  # one writer's files, whole
            np.testing.assert_array_equal(read_exr(cache.entry(name) / "image.exr").image, estimate.mean)
    assert not hidden(cache_dir)  # no .tmp-* (nor .bad-*) folders left behind


# --------------------------------------------------------------------------------------------------------------------
# 6. The CLI


def run_cli(*args: str, env_cache: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, HARNESS_CACHE_DIR=str(env_cache))
    return subprocess.run([sys.executable, "-m", "harness", "ground-truth", *args], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=120)


def in_process(capfd, *args: str) -> subprocess.CompletedProcess:
    """``harness ground-truth ARGS`` through main() in this process (the default cache is isolated_default_cache's),
    as run_cli's result: no interpreter to start, Mitsuba imported once. test_cli_closed_form keeps a process."""
    from harness.cli import main

    capfd.readouterr()
    code = main(["ground-truth", *args])
    out, err = capfd.readouterr()
    return subprocess.CompletedProcess(["harness", "ground-truth", *args], code, out, err)


def test_cli_closed_form(tmp_path):
    proc = run_cli("scenes/furnace.toml", "--json", env_cache=tmp_path / "default-cache")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["source"] == "closed-form" and summary["renders"] == 0 and summary["path"] is None
    np.testing.assert_allclose(summary["mean_radiance"], LE / (1 - RHO), rtol=1e-6)
    assert not (tmp_path / "default-cache").exists()


def test_cli_mitsuba_ground_truth_and_cache(tmp_path, capfd):
    scene = copy_scene("soft-shadows", tmp_path)
    cache = tmp_path / "cache"
    args = (str(scene), "--cache-dir", str(cache), "--spp", "8", "--chunk-spp", "4", "--json", "--quiet",
            "--mitsuba-variant", VARIANT)
    first = in_process(capfd, *args)
    assert first.returncode == 0, first.stderr
    one = json.loads(first.stdout)
    assert one["source"] == "mitsuba" and one["renders"] == 2 and one["cached"] is False and one["spp"] == 8

    second = in_process(capfd, *args)
    assert second.returncode == 0, second.stderr
    two = json.loads(second.stdout)
    assert two["renders"] == 0 and two["cached"] is True
    assert two["path"] == one["path"] and two["mean_radiance"] == one["mean_radiance"]

    path = Path(two["path"])
    assert path.name == "image.exr" and path.is_file() and cache in path.parents
    exr = read_exr(path)  # R, G, B and variance.R/G/B
    assert exr.image.shape == (8, 8, 3) and exr.variance is not None and exr.variance.shape == (8, 8, 3)
    assert np.all(exr.variance >= 0) and np.any(exr.variance > 0)
    np.testing.assert_allclose(exr.image.astype(float).mean(axis=(0, 1)), two["mean_radiance"], rtol=1e-6)
    assert not (tmp_path / "default-cache").exists()

    # the CLI and the API share entries
    api = ground_truth(load_scene(scene), spp=8, chunk_spp=4, cache_dir=cache, variant=VARIANT)
    assert api.cached and str(api.path) == two["path"]


def test_cli_missing_scene(tmp_path, capfd):
    proc = in_process(capfd, str(tmp_path / "nope.toml"), "--json")
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip("\n").split("\n")
    assert len(lines) == 1 and lines[0].startswith("harness: error:") and "nope.toml" in lines[0]


def test_cli_bad_spp(tmp_path, capfd):
    scene = copy_scene("soft-shadows", tmp_path)
    proc = in_process(capfd, str(scene), "--cache-dir", str(tmp_path / "c"), "--spp", "0")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "--spp" in proc.stderr


def test_a_scene_changed_after_loading_gets_its_own_entry(tmp_path):
    """The key covers the loaded scene, not only the file: an edit in memory is never served the old entry."""
    import dataclasses as _dc

    from conftest import load_small
    from harness.renderers.groundtruth import scene_digest

    scene = load_small("cornell-box", 8)
    light = next(i for i, s in enumerate(scene.shapes) if s.emission is not None)
    brighter = list(scene.shapes)
    brighter[light] = _dc.replace(brighter[light], emission=(100.0, 100.0, 100.0))
    assert scene_digest(scene) != scene_digest(_dc.replace(scene, shapes=brighter))
    moved = _dc.replace(scene, camera=_dc.replace(scene.camera, fov=30.0))
    assert scene_digest(scene) != scene_digest(moved)
    assert scene_digest(scene) == scene_digest(load_small("cornell-box", 8))
