"""Every choice of the algorithm as a setting, with the defaults first (``--set key=value`` in the CLI)."""

from __future__ import annotations

import difflib
import os
from dataclasses import asdict, dataclass, fields, replace

from reference_impl.emitters import ENV_SAMPLINGS
from reference_impl.errors import SettingsError
from reference_impl.lights import LIGHT_SELECTIONS
from reference_impl.mutants import ALL_MUTANTS
from reference_impl.rng import _mix64_int

DIRECT_STRATEGIES = ("auto", "area", "hemisphere-cosine", "hemisphere-uniform", "global-area", "mis", "bsdf")
HEMISPHERES = ("cosine", "uniform")
ROULETTES = ("auto", "albedo", "fixed", "throughput", "pbrt", "off")
#: the values of ``engine``: how paths are traced (the path loop, or the wavefront, which alone branches, Ni > 1)
ENGINES = ("path", "wavefront")
_LAMBERTIAN = ENGINES
_ALL = ENGINES + ("glossy", "volpath")
_PATH = ("path", "glossy", "volpath")
_SURFACES = ("path", "glossy")
_MEDIA = ("volpath",)
#: The capability matrix: each strategy (a setting's resolved value; ``indirect_rays`` as 1 or more, ``env_sampling``
#: on scenes with an environment, ``medium_direct`` and ``transmittance`` on scenes with media) and where it runs.
#: "path" (kernels/path.py: each path to its end in one loop) and "wavefront" (kernels/wavefront.py: every bounce of
#: a batch at once) are ``engine``'s values on scenes whose materials are all diffuse; "glossy" is a scene with a
#: material that is not diffuse, which the path loop runs whatever ``engine`` says; "volpath" a scene with media or a
#: ``null`` material, which the volumetric path loop (kernels/volpath.py) runs. The engine selection reads it
#: (``integrator._engine``): a strategy that ``engine`` does not run takes the render to the other engine; one that a
#: glossy scene or a scene with media does not take is refused there. docs/reference-renderer.md shows it as a table.
CAPABILITIES: dict[tuple[str, str], tuple[str, ...]] = {
    ("direct", "area"): _ALL,
    ("direct", "hemisphere-cosine"): _LAMBERTIAN,
    ("direct", "hemisphere-uniform"): _LAMBERTIAN,
    ("direct", "global-area"): _LAMBERTIAN,
    ("direct", "mis"): _ALL,
    ("direct", "bsdf"): _PATH,
    ("rr", "albedo"): _ALL,
    ("rr", "fixed"): _ALL,
    ("rr", "throughput"): _PATH,
    ("rr", "pbrt"): _PATH,
    ("rr", "off"): _ALL,
    ("indirect_rays", "1"): _ALL,
    ("indirect_rays", "> 1"): ("wavefront",),
    ("env_sampling", "importance"): _ALL,
    ("env_sampling", "uniform"): _ALL,
    ("env_sampling", "cosine"): _LAMBERTIAN,
    ("light_selection", "power"): _ALL,
    ("light_selection", "uniform"): _ALL,
    ("light_selection", "tree"): _SURFACES,
    ("medium_direct", "mis"): _MEDIA,
    ("medium_direct", "light"): _MEDIA,
    ("medium_direct", "phase"): _MEDIA,
    ("transmittance", "ratio"): _MEDIA,
    ("transmittance", "track"): _MEDIA,
}
#: the direct strategies of scenes with a material that is not diffuse
GLOSSY_DIRECT = tuple(v for (k, v), engines in CAPABILITIES.items() if k == "direct" and "glossy" in engines)
SAMPLERS = ("sobol", "independent")
#: the values of ``medium_direct`` and ``transmittance`` (scenes with media: kernels/volpath.py)
MEDIUM_DIRECT = ("mis", "light", "phase")
TRANSMITTANCES = ("ratio", "track")
#: what ``direct = "auto"`` runs on a Lambertian-only scene (False) and on a glossy one (True): Settings.resolved
AUTO_DIRECT = {False: "area", True: "mis"}
#: what ``rr = "auto"`` plays on a Lambertian-only scene (False) and on a glossy one (True; pbrt-v4's throughput
#: roulette, which never cuts a path of throughput 1, as in a furnace of glass or mirrors): Settings.resolved
AUTO_RR = {False: "albedo", True: "pbrt"}


@dataclass(frozen=True)
class Settings:
    """The reference integrator's settings. Slide names in brackets.

    spp             [Np] viewing rays per pixel, placed over the support of the pixel filter h.
    seed            seed of every random stream.
    sampler         where the uniforms come from: "sobol" (beyond the slides: each pixel's Np camera samples, and the
                    Np x Nd light samples, Np roulette numbers and Np x Ni indirect directions of the first hits
                    (in the volumetric path loop: the first vertex's free flight, light samples and direction),
                    are stratified point sets: a shuffled, Owen-scrambled Sobol (0,2)-sequence per pixel and pair of
                    dimensions, Burley 2020; deeper vertices as "independent"), or "independent" (every uniform an
                    independent hash of the path, the dimension and the seed: the slides' plain Monte Carlo). Each
                    sample is uniform either way (unbiased). With "sobol" a pixel's samples are not independent: its
                    sample variance / Np over-estimates the variance of its mean (a conservative verdict), unless
                    ``replicates`` > 1.
    replicates      [R] independent randomised replicates of each pixel's Np samples (beyond the slides): the
                    samples are split into R groups of Np / R (sizes differing by at most one), each an
                    independently seeded render of its own (its own scrambles and random streams); the pixel's
                    estimate is the mean of the R group means and its variance the sample variance of the group
                    means / R, an unbiased estimate with R - 1 degrees of freedom whatever the sampler (Owen 1997;
                    L'Ecuyer and Lemieux 2002). 1, the default, is one point set per pixel: the lowest error, and
                    with "sobol" a variance that is only an upper bound. R > Np is taken as Np.
    shadow_rays     [Nd] direct-light samples per hit.
    direct          how they are drawn: "area" (pick light k with pdf(k), a point y with pdf(y|k); Fig. 5.7, 5.8,
                    5.10), "hemisphere-cosine" / "hemisphere-uniform" (Fig. 5.12), "global-area" (Fig. 5.13), "mis"
                    (beyond the slides: area samples and the indirect rays combined by the power heuristic), "bsdf"
                    (no light samples: the emission the BSDF-sampled rays find; the path loop), or "auto", the
                    default: "area" on Lambertian-only scenes, "mis" where a material is not diffuse
                    (:meth:`resolved`).
    light_selection pdf(k): "power" (proportional to emitted power), "uniform", or "tree" (pdf(k | x): a light
                    tree over the area lights, each node's importance at the shading point; pbrt-v4's
                    BVHLightSampler; the path loop only; :mod:`reference_impl.light_tree`).
    env_sampling    directions toward an environment, as light samples: "importance" (an envmap by its luminance
                    times solid angle, cell by cell; a constant environment uniformly), "uniform" (over the sphere) or
                    "cosine" (about the normal at x). Scenes without an environment ignore it.
    indirect_rays   [Ni] indirect rays per hit (the recursion branches Ni ways at every hit).
    hemisphere      their directions off a diffuse surface (the diffuse BSDF's sampling): "cosine" or "uniform".
    rr              Russian roulette: "albedo" (survival = the diffuse albedo max_c rho_c; for the other materials the
                    largest channel of the bounce's weight f cos / p, at most 1), "fixed" (absorption alpha, as the
                    slides), "throughput" (Mitsuba's: min(max channel of the throughput x eta^2, 0.95); the path
                    loop only), "pbrt" (pbrt-v4's: min(max channel of the throughput x eta^2, 1), so a path whose
                    throughput is 1, as in a furnace of glass or mirrors, is never cut; the path loop only),
                    "off", or "auto", the default: "albedo" on Lambertian-only scenes, "pbrt" where a material is
                    not diffuse (:meth:`resolved`).
    rr_depth        first path depth (camera hit = 1) at which roulette is played.
    absorption      alpha for rr = "fixed".
    max_depth       longest path in segments, Mitsuba's meaning (1 = emitters seen directly, 2 = plus direct light,
                    -1 = unbounded); None = the scene's.
    batch_size      camera paths traced together (memory / speed only: the image does not depend on it).
    threads         worker threads (speed only: the image does not depend on it); 0 = all cores.
    medium_direct   direct light at a scattering point in a medium (scenes with media): "mis" (light samples and
                    phase-sampled rays combined by the power heuristic), "light" (light samples only: emission a
                    phase-sampled ray finds is not counted) or "phase" (no light samples but those of delta lights:
                    the emission the phase-sampled rays find).
    transmittance   a shadow ray's transmittance through media: "ratio" (ratio tracking, whose control extinction
                    is the homogeneous medium's own sigma_t: exp(-sigma_t s) exactly, Novak et al. 2014's residual
                    ratio tracking with a zero residual) or "track" (delta tracking: 0 or 1 by a free flight over
                    the segment, weighted per channel; Woodcock et al. 1965).
    engine          how paths are traced on scenes whose materials are all Lambertian (the same estimator either way,
                    not the same bits): "path", each path from its camera ray to its end in one compiled loop that
                    queries Embree itself (Ni = 1 only; with Ni > 1 the wavefront is used); or "wavefront", every
                    bounce of a batch at once, queries in batches (Ni >= 1). Scenes with a material that is not
                    diffuse run the path loop. Which engine runs which strategy: :data:`CAPABILITIES`.
    mutant          name of a planted fault (see ``reference_impl.mutants``); "" = none. Never on by default.
    """

    spp: int = 16
    seed: int = 0
    sampler: str = "sobol"
    replicates: int = 1
    shadow_rays: int = 1
    direct: str = "auto"
    light_selection: str = "power"
    env_sampling: str = "importance"
    indirect_rays: int = 1
    hemisphere: str = "cosine"
    rr: str = "auto"
    rr_depth: int = 3
    absorption: float = 0.2
    max_depth: int | None = None
    batch_size: int = 1 << 15
    threads: int = 0
    medium_direct: str = "mis"
    transmittance: str = "ratio"
    engine: str = "path"
    mutant: str = ""

    def __post_init__(self) -> None:
        _positive_int(self, "spp")
        _positive_int(self, "replicates")
        _positive_int(self, "shadow_rays")
        _positive_int(self, "indirect_rays")
        _positive_int(self, "rr_depth")
        _positive_int(self, "batch_size")
        if not _is_int(self.seed) or self.seed < 0:
            raise SettingsError("seed", f"expected a non-negative integer, got {self.seed!r}")
        if not _is_int(self.threads) or self.threads < 0:
            raise SettingsError("threads", f"expected a non-negative integer (0 = all cores), got {self.threads!r}")
        _choice(self, "direct", DIRECT_STRATEGIES)
        _choice(self, "light_selection", LIGHT_SELECTIONS)
        _choice(self, "env_sampling", ENV_SAMPLINGS)
        _choice(self, "hemisphere", HEMISPHERES)
        _choice(self, "rr", ROULETTES)
        _choice(self, "engine", ENGINES)
        _choice(self, "sampler", SAMPLERS)
        _choice(self, "medium_direct", MEDIUM_DIRECT)
        _choice(self, "transmittance", TRANSMITTANCES)
        if self.sampler == "sobol" and self.spp * max(self.shadow_rays, self.indirect_rays) >= 1 << 32:
            raise SettingsError("spp", "sampler = sobol takes spp x max(shadow_rays, indirect_rays) < 2^32 points per pixel")
        if not isinstance(self.absorption, (int, float)) or not (0.0 <= self.absorption < 1.0):
            raise SettingsError("absorption", f"expected a number in [0, 1), got {self.absorption!r}")
        if self.max_depth is not None and (not _is_int(self.max_depth) or (self.max_depth < 1 and self.max_depth != -1)):
            raise SettingsError("max_depth", f"expected a positive integer or -1 (unbounded), got {self.max_depth!r}")
        if self.mutant and self.mutant not in ALL_MUTANTS:
            raise SettingsError("mutant", f"expected one of {', '.join(sorted(ALL_MUTANTS))} or empty, got {self.mutant!r}")

    @classmethod
    def field_names(cls) -> list[str]:
        return [f.name for f in fields(cls)]

    @classmethod
    def from_strings(cls, values: dict[str, str], base: "Settings | None" = None) -> "Settings":
        """Settings from ``key=value`` strings (as typed after ``--set``), converted to each field's type."""
        current = asdict(base or cls())
        for key, text in values.items():
            if key not in current:
                close = difflib.get_close_matches(key, current, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise SettingsError(key, f"unknown setting (known: {', '.join(current)}){hint}")
            current[key] = _parse(key, text, cls.__dataclass_fields__[key].default)
        return cls(**current)

    def resolved_max_depth(self, scene_max_depth: int) -> int:
        depth = scene_max_depth if self.max_depth is None else self.max_depth
        if depth == -1 and self.rr == "off":
            raise SettingsError("rr", "max_depth = -1 (unbounded) needs Russian roulette (rr = albedo or fixed)")
        if depth == -1 and self.rr == "fixed" and self.absorption == 0:
            raise SettingsError("absorption", "max_depth = -1 with rr = fixed needs absorption > 0")
        return depth

    def resolved(self, glossy: bool) -> "Settings":
        """These settings with ``direct = "auto"`` and ``rr = "auto"`` resolved for a scene.

        The one place "auto" is resolved; a render resolves its settings once, where it starts, and every later
        reader (the kernels' configuration, the engines, the recorded settings) sees the resolved ones.

        Parameters
        ----------
        glossy : bool
            Whether a material of the scene is not diffuse (:func:`reference_impl.materials.is_glossy`).

        Returns
        -------
        Settings
            ``self`` when neither is "auto"; else a copy with ``direct`` from :data:`AUTO_DIRECT` and ``rr`` from
            :data:`AUTO_RR` for ``glossy``.
        """
        direct = AUTO_DIRECT[glossy] if self.direct == "auto" else self.direct
        rr = AUTO_RR[glossy] if self.rr == "auto" else self.rr
        if (direct, rr) == (self.direct, self.rr):
            return self
        return replace(self, direct=direct, rr=rr)

    def strategies(self, environment: bool, media: bool = False) -> list[tuple[str, str]]:
        """The rows of :data:`CAPABILITIES` these resolved settings choose, ``env_sampling``'s only on a scene with
        an ``environment``, ``medium_direct``'s and ``transmittance``'s only on a scene with ``media``."""
        rows = [("direct", self.direct), ("rr", self.rr), ("indirect_rays", "1" if self.indirect_rays == 1 else "> 1"),
                ("light_selection", self.light_selection)]
        if environment:
            rows.append(("env_sampling", self.env_sampling))
        if media:
            rows += [("medium_direct", self.medium_direct), ("transmittance", self.transmittance)]
        return rows

    def replicate_sizes(self) -> tuple[int, ...]:
        """The samples per pixel of each of the ``min(replicates, spp)`` replicates: ``spp`` split as evenly as
        possible, the larger ones first."""
        count = min(self.replicates, self.spp)
        base, extra = divmod(self.spp, count)
        return tuple(base + (1 if r < extra else 0) for r in range(count))

    def replicate_seed(self, r: int) -> int:
        """The seed of replicate ``r``: ``seed`` itself for r = 0 (so one replicate is the render it always was),
        else a 63-bit hash of (seed, r), independent of it."""
        if r == 0:
            return self.seed
        return _mix64_int(_mix64_int(self.seed ^ 0x5851F42D4C957F2D) + r * 0x9E3779B97F4A7C15) >> 1

    def worker_threads(self) -> int:
        return self.threads or (os.cpu_count() or 1)

    def as_dict(self) -> dict:
        return asdict(self)


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _positive_int(s: Settings, key: str) -> None:
    v = getattr(s, key)
    if not _is_int(v) or v < 1:
        raise SettingsError(key, f"expected a positive integer, got {v!r}")


def _choice(s: Settings, key: str, allowed: tuple[str, ...]) -> None:
    v = getattr(s, key)
    if v not in allowed:
        raise SettingsError(key, f"expected one of {', '.join(allowed)}, got {v!r}")


def _parse(key: str, text: str, default):
    if not isinstance(text, str):
        return text
    if key == "max_depth":
        if text.strip().lower() in ("", "none", "scene"):
            return None
        default = 0
    try:
        if isinstance(default, bool):
            raise SettingsError(key, "boolean settings are not supported")
        if isinstance(default, int):
            return int(text)
        if isinstance(default, float):
            return float(text)
    except ValueError:
        kind = "an integer" if isinstance(default, int) else "a number"
        raise SettingsError(key, f"expected {kind}, got {text!r}") from None
    return text
