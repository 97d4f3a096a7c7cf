"""What the kernels share besides code: numba's compile options, the configuration slots, modes and planted faults,
and the order of the counters.

Every setting is a runtime integer or float of two small arrays, ``cfg`` (int64) and ``cfg_f`` (float64), never a
compile-time constant, so every setting runs the same compiled signatures and no setting triggers a compilation.
"""

from __future__ import annotations

# Every kernel is nogil (the integrator's thread pool runs them concurrently, as it runs Embree queries) and cached
# (reference_impl/kernels/__pycache__). IEEE semantics are kept: no fastmath (no reassociation, no FMA contraction),
# and error_model="numpy" so a division by zero gives inf/NaN as in numpy instead of raising. Reference counting and
# LLVM inlining are set explicitly: numba would otherwise let a function inherit them from whichever caller happened
# to compile it first.
JIT = dict(cache=True, nogil=True, error_model="numpy", _nrt=True, forceinline=False)
# Helpers that take arrays are inlined into their callers at numba's level: a call that passes an array increments
# and decrements its reference count atomically, and with two threads sharing the scene's arrays those atomics took
# a quarter of a render's time (perf: NRT_incref / NRT_decref).
JIT_INLINE = dict(JIT, inline="always")
# The helpers that share a vertex's work between the two engines take the caller's arrays and branch on what they
# find, so an inlined copy's reference counts die on different branches, where numba's pruning of them fails: one
# light sample kept 13 increments and 23 decrements in the path loop, and the engines were 11-17 % slower. They only
# borrow the arrays and allocate nothing, so they are compiled without reference counting (``_nrt=False``, numba's
# option for such code) and always inlined by LLVM (``forceinline``): no count and no call is left.
JIT_BORROW = dict(JIT, _nrt=False, forceinline=True)

# Counters, in the order of integrator.COUNTERS.
(C_CAMERA, C_SHADOW, C_SHADOW_SKIPPED, C_HEMI_DIRECT, C_INDIRECT, C_ESCAPED, C_BACK_FACE, C_ROULETTE, C_NONFINITE,
 C_LIGHT_SELECT) = range(10)

# Integer configuration of one bounce (the ``cfg`` array of :func:`bounce`).
(CFG_DEPTH, CFG_EMIT, CFG_ALLOW_NEXT, CFG_ALLOW_INDIRECT, CFG_DIRECT, CFG_ND, CFG_NI, CFG_HEMI_COSINE, CFG_RR,
 CFG_RR_DEPTH, CFG_MUTANTS, CFG_NUM_LIGHTS, CFG_SOBOL, CFG_SPP, CFG_SIZE) = range(15)
# The stratified sampler ("sobol") draws the camera sample (depth 0) and the decisions of the first hit (depth 1:
# light sample, roulette, indirect direction); deeper ones are independent. Measured on the Cornell box, 64 spp: the
# first hit gives nearly all of the gain (MSE 5.6e-4 -> 1.5e-4); going on to depth 2 took 3 % more time for 3 % less
# MSE.
# Float configuration (the ``cfg_f`` array).
CFGF_FIXED_SURVIVAL, CFGF_OFFSET_SCENE, CFGF_SURFACE_PDF, CFGF_SIZE = range(4)

EMIT_NONE, EMIT_ALL, EMIT_MIS = 0, 1, 2  # emission at the hit: not counted, counted, counted with the MIS weight
DIRECT_AREA, DIRECT_MIS, DIRECT_GLOBAL_AREA, DIRECT_HEMI_COSINE, DIRECT_HEMI_UNIFORM = range(5)
DIRECT_MODES = {"area": DIRECT_AREA, "mis": DIRECT_MIS, "global-area": DIRECT_GLOBAL_AREA,
                "hemisphere-cosine": DIRECT_HEMI_COSINE, "hemisphere-uniform": DIRECT_HEMI_UNIFORM}
RR_OFF, RR_ALBEDO, RR_FIXED = 0, 1, 2
RR_MODES = {"off": RR_OFF, "albedo": RR_ALBEDO, "fixed": RR_FIXED}
FILTER_BOX, FILTER_TENT, FILTER_GAUSSIAN = 0, 1, 2
FILTER_KINDS = {"box": FILTER_BOX, "tent": FILTER_TENT, "gaussian": FILTER_GAUSSIAN}

# Planted faults (reference_impl/mutants.py) that live in the kernels, as bits of cfg[CFG_MUTANTS]; each place one
# changes is marked with a comment naming it. ("camera-half-pixel" is an argument of camera_paths; "double-emission" is the
# EMIT_ALL mode chosen by the integrator; "energy-loss-2pct" is the scale of finish_samples.)
M_NO_COSINE, M_COSINE_PDF_PI, M_RR_NO_REWEIGHT, M_LIGHT_PDF_IGNORED, M_NO_RAY_OFFSET = 1, 2, 4, 8, 16
MUTANT_BITS = {"no-cosine": M_NO_COSINE, "cosine-pdf-pi": M_COSINE_PDF_PI, "rr-no-reweight": M_RR_NO_REWEIGHT,
               "light-pdf-ignored": M_LIGHT_PDF_IGNORED, "no-ray-offset": M_NO_RAY_OFFSET}
