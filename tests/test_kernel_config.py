"""The settings reach the kernels through one table (reference_impl/kernels/config.py), and the kernels' compiled
code is never stale.

``kernels.config.FROM_SETTINGS`` names, for each slot of ``KernelConfig``, the ``Settings`` field that fills it;
``NOT_SLOTS`` says where the other fields go. Every field must be in exactly one of them, every slot filled, and
every configuration the same numba type (so that no setting compiles the kernels again).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numba

from reference_impl import Settings
from reference_impl.kernels import _cache_folder, _drop_stale_cache, config
from reference_impl.mutants import ALL_MUTANTS, EMITTER_MUTANTS, MUTANTS
from reference_impl.settings import DIRECT_STRATEGIES, HEMISPHERES, ROULETTES, SAMPLERS


def test_every_setting_fills_a_slot_or_is_said_to_go_elsewhere():
    filled_by = [field for field, _fill in config.FROM_SETTINGS.values()]
    assert len(filled_by) == len(set(filled_by))
    assert sorted(filled_by + list(config.NOT_SLOTS)) == sorted(Settings.field_names())
    assert sorted(list(config.FROM_SETTINGS) + list(config.FROM_SCENE)) == sorted(config.KernelConfig._fields)


def test_the_slots_hold_what_the_settings_say():
    settings = Settings(spp=8, shadow_rays=3, indirect_rays=2, direct="mis", hemisphere="uniform", rr="fixed",
                        rr_depth=2, absorption=0.25, max_depth=5, sampler="independent", mutant="no-cosine")
    cfg = config.kernel_config(settings, 4, 1e-6, 0.5)
    assert (cfg.spp, cfg.shadow_rays, cfg.indirect_rays, cfg.rr_depth, cfg.max_depth) == (8, 3, 2, 2, 5)
    assert (cfg.direct, cfg.hemisphere, cfg.rr, cfg.sampler) == (config.DIRECT_MIS, config.HEMI_UNIFORM,
                                                                 config.RR_FIXED, config.SAMPLER_INDEPENDENT)
    assert cfg.survival == 0.75 and cfg.mutant == config.M_NO_COSINE
    assert (cfg.depth, cfg.num_lights, cfg.offset_scene, cfg.surface_pdf) == (0, 4, 1e-6, 0.5)
    assert (cfg.num_area_lights, cfg.env_light, cfg.env_sampling) == (4, -1, config.ENV_IMPORTANCE)
    cfg = config.kernel_config(Settings(env_sampling="cosine", max_depth=2).resolved(False), 5, 0.0, 0.0, num_area_lights=2,
                               env_light=4)
    assert (cfg.num_lights, cfg.num_area_lights, cfg.env_light, cfg.env_sampling) == (5, 2, 4, config.ENV_COSINE)


def test_every_planted_fault_but_the_integrators_and_the_texels_is_a_kernel_bit():
    # "texture-srgb-as-linear" is in the texels the tables are built with (kernels/records.py texture_tables)
    assert set(config.MUTANT_BITS) == set(ALL_MUTANTS) - {"energy-loss-2pct", "replicates-ddof0",
                                                          "texture-srgb-as-linear"}
    assert not set(MUTANTS) & set(EMITTER_MUTANTS)
    bits = list(config.MUTANT_BITS.values())
    assert all(b & (b - 1) == 0 for b in bits) and len(set(bits)) == len(bits)


def test_every_configuration_is_one_numba_type():
    """Settings are runtime values: ints and floats of one namedtuple type, whatever the values."""
    types = set()
    for direct, hemisphere, rr, sampler, mutant in itertools.product(DIRECT_STRATEGIES, HEMISPHERES, ROULETTES,
                                                                      SAMPLERS, ["", *sorted(ALL_MUTANTS)]):
        settings = Settings(direct=direct, hemisphere=hemisphere, rr=rr, sampler=sampler, mutant=mutant, max_depth=3,
                            absorption=0)
        cfg = config.kernel_config(settings.resolved(False), 1, 0, 1)
        types.add(numba.typeof(cfg))
        types.add(numba.typeof(cfg._replace(depth=3)))
    assert len(types) == 1


def _package(tmp_path):
    """A stand-in for reference_impl/kernels: a package folder with two modules, beside the modules the kernels
    compile in."""
    (tmp_path / "embree_c.py").write_text("A = 1\n")
    (tmp_path / "rng.py").write_text("B = 2\n")
    (tmp_path / "emitters.py").write_text("C = 3\n")
    (tmp_path / "sampling.py").write_text("D = 4\n")
    package = tmp_path / "kernels"
    package.mkdir()
    (package / "path.py").write_text("def f():\n    return 1\n")
    (package / "direct.py").write_text("def g():\n    return 2\n")
    return package


def test_cached_kernels_are_dropped_when_any_source_changes(tmp_path, monkeypatch):
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    package = _package(tmp_path)
    cache = _cache_folder(package)
    assert cache == package / "__pycache__"
    cache.mkdir()
    cached = cache / "path.f-1.py311.1.nbc"
    bytecode = cache / "path.cpython-311.pyc"
    bytecode.write_bytes(b"python's own")
    cached.write_bytes(b"compiled")
    _drop_stale_cache(package)  # no stamp yet: whatever is there may be stale
    assert not cached.exists()
    cached.write_bytes(b"compiled")
    _drop_stale_cache(package)  # the same sources: kept
    assert cached.exists()
    (package / "direct.py").write_text("def g():\n    return 3\n")  # a helper path.f may inline changed
    _drop_stale_cache(package)
    assert not cached.exists()
    cached.write_bytes(b"compiled")
    (tmp_path / "rng.py").write_text("B = 3\n")  # a constant the kernels compile in changed
    _drop_stale_cache(package)
    assert not cached.exists()
    assert bytecode.exists()  # only numba's files go


def test_an_unwritable_cache_folder_is_left_alone(tmp_path, monkeypatch):
    package = _package(tmp_path)
    monkeypatch.setattr("reference_impl.kernels._cache_folder", lambda _package: Path("/proc/harness-kernels"))
    _drop_stale_cache(package)  # neither raises nor writes
    assert not Path("/proc/harness-kernels").exists()
