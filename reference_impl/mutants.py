"""Planted faults: deliberately wrong variants of the integrator, selectable by name (``--set mutant=NAME``).

``MUTANTS`` are the faults of the integrator and its area lights, ``EMITTER_MUTANTS`` those of the emitters that
are not surfaces (point, spot, directional, environments), ``BSDF_MUTANTS`` those of the glossy and glass BSDFs
(``reference_impl/kernels/bsdf.py``, caught by ``tests/reference_impl/test_bsdf_*.py``); each is run by the canonical suite
(``suites/canonical.toml``) on a scene where it matters, and the emitters' also by
``tests/reference_impl/test_emitters.py`` on scenes built in the test. ``ALL_MUTANTS`` is what ``Settings.mutant``
accepts.

They exist so that tests and the harness's verdict can prove that they catch real mistakes: a verdict that passes
one of these at its default budget is not sharp enough. None runs by default. "energy-loss-2pct" and
"replicates-ddof0" live in ``reference_impl/integrator.py`` (guarded by ``_Context.mutant``), the others in the compiled kernels of
``reference_impl/kernels/``, as bits of ``kernels.config.MUTANT_BITS`` in the kernels' configuration; every place a
fault changes is marked with a comment naming it.
"""

MUTANTS: dict[str, str] = {
    "double-emission": (
        "the slides' pseudo-code taken literally (Fig. 5.14/5.16 computeRadiance adds Le(y) when an indirect ray "
        "lands on a light), on top of the shadow-ray estimate: direct light is counted twice"
    ),
    "no-cosine": "the cosine factor cos(Psi, N_x) at x dropped from the direct (G) and indirect estimators",
    "cosine-pdf-pi": "the cosine-hemisphere pdf taken as cos(theta) instead of cos(theta) / pi (off by a factor pi)",
    "rr-no-reweight": "Russian-roulette survivors not divided by their survival probability",
    "light-pdf-ignored": "direct light divided by pdf(y|k) only: the light-selection pdf(k) ignored",
    "camera-half-pixel": "viewing rays shifted by half a pixel (right and down)",
    "no-ray-offset": "shadow rays start exactly on the surface (no self-intersection offset)",
    "energy-loss-2pct": "every camera sample's radiance scaled by 0.98 (a 2 % energy loss)",
    "replicates-ddof0": (
        "with replicates > 1, the variance of the pixel mean taken as the replicate means' squared deviations / R^2 "
        "(the biased variance, numpy's ddof = 0) instead of / (R (R - 1)): half the true variance at R = 2"
    ),
}

EMITTER_MUTANTS: dict[str, str] = {
    "point-no-inverse-square": "a point light's irradiance taken as I cos instead of I cos / r^2",
    "spot-ignores-beam-width": "a spot light's falloff taken as 1 out to cutoff_angle (beam_width ignored)",
    "envmap-pdf-no-sin": "the envmap's solid-angle pdf taken as p(u, v) / (2 pi^2), the sin(theta) Jacobian dropped",
    "envmap-mirrored-u": "the envmap looked up at 1 - u (the map mirrored left to right)",
    "directional-reversed": "a directional light taken to travel against its direction (lights the other side)",
}

BSDF_MUTANTS: dict[str, str] = {
    "microfacet-pdf-no-jacobian": (
        "the microfacet reflection pdf without the 1/(4|wi.h|) Jacobian from half vectors to directions (Walter et "
        "al. 2007, eq. 14), and the sampled weight f cos / pdf computed from that wrong pdf"
    ),
    "conductor-fresnel-one": "the conductors' Fresnel term (complex index) replaced by 1",
    "refraction-no-eta2": "transmission through dielectrics without the eta^2 radiance scaling (solid-angle compression)",
    "vndf-alpha-squared": (
        "visible-normal sampling stretched by alpha^2 instead of alpha (Heitz 2018), the pdf unchanged: the samples "
        "do not follow the pdf"
    ),
}

# The MIS weights' (reference_impl/kernels/direct.py power_weight): the path loop with direct = mis.
GLOSSY_MUTANTS: dict[str, str] = {
    "mis-weights-not-one": (
        "direct = mis: the light sample weighted by the balance heuristic p_l / (p_l + p_b) while the BSDF sample "
        "keeps the power heuristic p_b^2 / (p_b^2 + p_l^2), so the two weights do not sum to 1"
    ),
}

# The textures' (reference_impl/kernels/texture.py; the texels of kernels/records.py texture_tables).
TEXTURE_MUTANTS: dict[str, str] = {
    "texture-v-flipped": "textures looked up at (u, 1 - v): the image upside down",
    "texture-srgb-as-linear": "an 8-bit sRGB texture's codes taken as linear values code / 255 (no sRGB decoding)",
    "texture-nearest-not-bilinear": "the nearest texel taken where bilinear filtering was asked",
    "texture-half-texel-shift": (
        "bilinear filtering with the texel centres at integer texel coordinates (u W instead of u W - 1/2): the "
        "image shifted by half a texel"
    ),
    "texture-repeat-as-clamp": "wrap_mode = repeat treated as clamp (the edge texels stretched outside [0, 1])",
}

# The shading normals' (reference_impl/kernels/shading.py; the side test in kernels/path.py).
NORMAL_MUTANTS: dict[str, str] = {
    "normals-not-renormalised": (
        "a hit's shading normal taken as the barycentric blend of the vertex normals without normalising it (shorter "
        "than 1 inside a triangle whose normals differ: every cosine too small)"
    ),
    "shading-normal-side": (
        "the shading normal deciding which side of the surface a direction is on, where the geometric one should: "
        "light below a surface whose shading normal leans toward it leaks through"
    ),
    "normalmap-green-inverted": "a normal map's green channel inverted (n_y = 1 - 2 g: the other handedness)",
    "bumpmap-scale-ignored": "a bump map's scale ignored (taken as 1)",
}

# The analytic spheres' (the light samples of kernels/direct.py).
SPHERE_MUTANTS: dict[str, str] = {
    "sphere-points-uniform-theta": (
        "a sphere light's points drawn uniform in the polar angle (z = cos(pi u1)) where their pdf says uniform in "
        "area, 1 / (4 pi r^2): the poles oversampled, the equator under (a fault of the area sampler, which an x "
        "inside the sphere and the wavefront use; with it, sphere lights are drawn by area from outside too)"
    ),
    "sphere-cone-pdf-area": (
        "a sphere light's points drawn by the cone it subtends from x but weighed with the area density pdf(k) / "
        "(4 pi r^2), the measure of the area sampler they replaced, where the cone's is 1 / (2 pi (1 - cos "
        "theta_max)) per unit solid angle"
    ),
}

# The cameras' (the lens and the orthographic rays of kernels/camera.py).
CAMERA_MUTANTS: dict[str, str] = {
    "lens-sampled-on-square": (
        "the thin lens's aperture point drawn uniform on the square [-r, r]^2 instead of the disk of radius r (the "
        "concentric map skipped): a square bokeh, out-of-focus light spread wider"
    ),
    "focus-along-ray": (
        "the thin lens focused at the distance focus_distance along each pixel's ray (a sphere of focus) instead of "
        "on the plane z = focus_distance along the camera's axis (Mitsuba's meaning)"
    ),
    "orthographic-origin-not-offset": (
        "an orthographic ray starting at the camera's origin for every pixel instead of at the pixel's own point on "
        "the near plane (the extent not applied to the origins)"
    ),
}

# The thin dielectric's and the plastic's (kernels/bsdf.py).
MATERIAL_MUTANTS: dict[str, str] = {
    "thin-glass-refracts": (
        "thindielectric's transmission bent as a refraction through one interface (the direction Snell's law gives) "
        "instead of passing straight through the thin sheet"
    ),
    "plastic-no-internal-reflection": (
        "plastic's diffuse base without its internal reflection: the 1 / (1 - F_dr) multiple-scattering term under "
        "the coating dropped (Mitsuba's plastic, nonlinear = false)"
    ),
    "principled-clearcoat-pdf-jacobian": (
        "the principled BSDF's clearcoat lobe's direction pdf without the reflection Jacobian 1 / (4 |wo.h|): its "
        "half-vector density taken for the direction's (the weights of clearcoat samples and the MIS weights wrong)"
    ),
    "mask-opacity-1-in-shadow-rays": (
        "a mask's cut-out treated as opaque by shadow rays (opacity 1) while paths still pass through its holes: the "
        "light seen through the holes by next-event estimation lost"
    ),
}

# The light tree's (light_selection = "tree": kernels/light_tree.py, the MIS weight in kernels/path.py); run by
# suites/many-lights.toml, not the canonical suite (docs/suites.md).
TREE_MUTANTS: dict[str, str] = {
    "light-tree-no-bound-angle": (
        "the light tree's importance without the angle theta_b its box subtends from x (each node taken as a point "
        "at its centre): nodes and lights that can light x get importance 0 and are never chosen"
    ),
    "light-tree-pmf-at-hit": (
        "direct = mis with the tree: the MIS weight of a BSDF sample that hits a light reads pdf(k | y) at the light's "
        "own point y instead of pdf(k | x) at the vertex the ray left"
    ),
}

# The participating media's (kernels/volpath.py); run by the canonical suite's media scenes.
MEDIA_MUTANTS: dict[str, str] = {
    "nee-no-transmittance": (
        "next-event estimation from a medium or a surface without the shadow ray's transmittance through the media "
        "it crosses (surfaces still block it)"
    ),
    "hg-g-flipped": "Henyey-Greenstein sampled and evaluated with -g: forward scattering taken as backward",
    "free-flight-pdf-no-sigma-t": (
        "a free flight's density taken as exp(-sigma_t t) instead of sigma_t exp(-sigma_t t): every scattering "
        "weighted by sigma_t too much"
    ),
    "albedo-applied-twice": "a scattering event weighted by albedo^2 instead of albedo",
    "null-boundary-as-bounce": (
        "crossing a null (index-matched) boundary counted as a vertex of the path: max_depth reached too soon"
    ),
}

ALL_MUTANTS: dict[str, str] = {**MUTANTS, **EMITTER_MUTANTS, **BSDF_MUTANTS, **GLOSSY_MUTANTS, **TEXTURE_MUTANTS,
                               **NORMAL_MUTANTS, **SPHERE_MUTANTS, **CAMERA_MUTANTS, **MATERIAL_MUTANTS,
                               **TREE_MUTANTS, **MEDIA_MUTANTS}
