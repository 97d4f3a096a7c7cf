"""What an environment map costs a render (harness/core/limits.py, docs/robustness.md "Absurd resolutions"): its
tables count in the memory estimate whatever the film (an 8192 x 4096 map that compresses to 418 KB cost 4.1 GB
for a 4 x 4 render, while the check counted the film only), a map whose tables alone cannot fit is refused on the
file's header before any pixel is read, and the estimate's constant holds for a map measured here."""

from __future__ import annotations

import struct
import tracemalloc
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from conftest import MINIMAL_SCENE

from harness.cli import main
from harness.core import limits
from harness.core.errors import HarnessError
from harness.files.imageio import read_exr, write_exr
from harness.scene import load as scene_load
from harness.scene import load_scene
from harness.scene.emitter_arrays import emitter_arrays

GIB = 2**30
SCENE = MINIMAL_SCENE + """
[[shapes]]
type = "rectangle"
material = "white"

[[emitters]]
type = "envmap"
file = "sky.exr"
"""
WINDOW = b"dataWindow\x00box2i\x00"


def _scene(folder: Path, image: np.ndarray) -> Path:
    write_exr(folder / "sky.exr", image)
    (folder / "scene.toml").write_text(SCENE)
    return folder / "scene.toml"


def _claim(path: Path, width: int, height: int) -> None:
    """Patch the file's dataWindow to claim ``width x height`` pixels (tests/cli/fuzz.py's ``_patch_window``): a
    header that lies, with a few pixels' data behind it."""
    data = path.read_bytes()
    start = data.index(WINDOW) + len(WINDOW) + 4
    path.write_bytes(data[:start] + struct.pack("<4i", 0, 0, width - 1, height - 1) + data[start + 16:])


def _machine(monkeypatch, memory: float) -> None:
    monkeypatch.setattr(limits, "machine_memory", lambda: int(memory))


def _sky(width: int, height: int) -> np.ndarray:
    return (np.random.default_rng(1).random((height, width, 3)) + 0.05).astype(np.float32)


def test_an_8k_map_costs_about_4_gib_whatever_the_film():
    assert limits.envmap_bytes(8192, 4096) == 8192 * 4096 * limits.ENVMAP_BYTES_PER_TEXEL
    assert 3.9 * GIB < limits.envmap_bytes(8192, 4096) < 4.3 * GIB  # the 4.1 GB measured for a 4 x 4 render
    cost = limits.reference_cost(4, 4, 16, envmap=(8192, 4096))
    assert cost.memory >= limits.envmap_bytes(8192, 4096) + limits.memory_bytes(4, 4)


def test_a_4x4_render_with_an_8k_map_is_refused_where_memory_is_short(monkeypatch):
    """6 GiB of memory: half of it is less than the map's tables; the film alone is 2.6 KiB."""
    _machine(monkeypatch, 6 * GIB)
    where = "scene.toml: emitters[0].file"
    kwargs = dict(film_where="scene.toml: film", spp_where="--spp", envmap_where=where)
    limits.check_render_cost(4, 4, 16, **kwargs)  # no map: passes
    with pytest.raises(HarnessError) as caught:
        limits.check_render_cost(4, 4, 16, envmap=(8192, 4096), **kwargs)
    assert caught.value.where == where
    assert caught.value.message.startswith("4 x 4 pixels with a 8192 x 4096 environment map need about 4.0 GiB")
    with pytest.raises(HarnessError, match="4.0 GiB of it the environment map's tables"):
        limits.check_reference_cost(4, 4, 16, where="--spp", settings_text="defaults", lower="--spp",
                                    envmap=(8192, 4096))
    _machine(monkeypatch, 64 * GIB)
    limits.check_render_cost(4, 4, 16, envmap=(8192, 4096), **kwargs)  # a machine with room renders it


def test_an_8k_header_is_refused_before_any_pixel_is_read(tmp_path, monkeypatch):
    """A 4 x 3 map whose header claims 8192 x 4096: refused on the header (its pixels would not even be there)."""
    scene = _scene(tmp_path, _sky(4, 3))
    _claim(tmp_path / "sky.exr", 8192, 4096)
    _machine(monkeypatch, 6 * GIB)
    monkeypatch.setattr(scene_load, "read_exr", lambda *a, **k: pytest.fail("the map's pixels were read"))
    with pytest.raises(HarnessError) as caught:
        load_scene(scene)
    assert caught.value.where == f"{scene}: emitters[0].file"
    assert caught.value.message == (
        "envmap file 'sky.exr': a 8192 x 4096 map needs about 4.0 GiB of memory to render (128 B per texel: the map "
        "and the reference's sampling tables), more than 50% of this machine's 6.0 GiB; expected a smaller map")


def test_a_normal_map_still_loads_and_renders_where_memory_is_short(tmp_path, monkeypatch):
    scene = _scene(tmp_path, _sky(128, 64))
    _machine(monkeypatch, 6 * GIB)
    loaded = load_scene(scene)
    assert loaded.envmap_size == (128, 64) and loaded.envmap_key == f"{scene}: emitters[0].file"
    limits.check_render_cost(16, 16, 16, film_where="film", spp_where="--spp", envmap=loaded.envmap_size,
                             envmap_where=loaded.envmap_key)


def test_render_counts_the_map_before_rendering(tmp_path, monkeypatch, capfd):
    """A 64 x 32 map (256 KiB of tables) loads on a machine of 600 KB, but with the 16 x 16 film (42 KiB) a render
    needs more than half of it: one line naming the map's key, exit 2, nothing written."""
    scene = _scene(tmp_path, _sky(64, 32))
    _machine(monkeypatch, 600_000)
    out = tmp_path / "out.exr"
    code = main(["render", str(scene), "--spp", "1", "--out", str(out)])
    err = capfd.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"{scene}: emitters[0].file: 16 x 16 pixels with a 64 x 32 environment map need about 298.0 KiB" in err
    assert not out.exists()


def test_the_constant_holds_for_a_measured_map(tmp_path):
    """tracemalloc's peak while a 512 x 256 map is read as load_scene reads it and the reference builds its tables
    (emitter_arrays, as the reference renderer does): within the estimate, and not far below it (an estimate that
    holds, not a guess). The scene file's own read is left out: it reserves a buffer of the 64 MiB a scene file may
    hold, whatever the map."""
    scene = _scene(tmp_path, _sky(512, 256))
    loaded = load_scene(scene)
    emitter_arrays(loaded)  # imports and first-call allocations out of the measurement
    tracemalloc.start()
    try:
        image = read_exr(tmp_path / "sky.exr", max_pixels=scene_load.MAX_ENVMAP_PIXELS).image
        arrays = emitter_arrays(replace(loaded, emitters=(replace(loaded.emitters[0], image=image),)))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert arrays.env_image.shape == (256, 512, 3)
    per_texel = peak / (512 * 256)
    assert 0.85 * limits.ENVMAP_BYTES_PER_TEXEL <= per_texel <= limits.ENVMAP_BYTES_PER_TEXEL, per_texel
