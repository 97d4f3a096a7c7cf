"""The numpy integrator that the compiled kernels replaced, loaded from git for side-by-side timings.

``load_baseline(rev)`` copies ``reference_impl/*.py`` as of git revision ``rev`` (default: the last commit whose
integrator was pure numpy, or the environment variable ``REFERENCE_BASELINE_REV``) into a temporary directory as
the package ``reference_baseline`` and imports it, so old and new run in one process on the same machine state.
Returns None when git or the revision is not available.
"""

from __future__ import annotations

import atexit
import importlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
DEFAULT_REV = "5dd5d08"  # the last commit before the compiled kernels (reference_impl/kernels.py, now kernels/)
PACKAGE = "reference_baseline"
_loaded: dict[str, object] = {}


def baseline_rev() -> str:
    return os.environ.get("REFERENCE_BASELINE_REV", DEFAULT_REV)


def load_baseline(rev: str | None = None):
    rev = rev or baseline_rev()
    if rev in _loaded:
        return _loaded[rev]
    try:
        names = subprocess.run(["git", "-C", str(ROOT), "ls-tree", "--name-only", rev, "reference_impl/"],
                               capture_output=True, text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        return None
    if not names or any(Path(n).stem == "kernels" for n in names):  # kernels.py, or the kernels/ package
        return None
    tmp = tempfile.mkdtemp(prefix="reference-baseline-")
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    target = Path(tmp) / PACKAGE
    target.mkdir()
    for name in names:
        if not name.endswith(".py"):
            continue
        text = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{name}"], capture_output=True, text=True,
                              check=True).stdout
        (target / Path(name).name).write_text(text.replace("reference_impl", PACKAGE))
    sys.path.insert(0, str(target.parent))
    try:
        module = importlib.import_module(PACKAGE)
        for sub in ("integrator", "geometry", "camera", "settings"):
            importlib.import_module(f"{PACKAGE}.{sub}")
    finally:
        sys.path.remove(str(target.parent))
    _loaded[rev] = module
    return module


def convert_inputs(baseline, geometry, camera, film, settings):
    """The same scene and settings as the baseline package's own types."""
    import dataclasses

    g = baseline.geometry.Geometry(geometry.vertices, geometry.triangles, geometry.material, geometry.reflectance,
                                   geometry.two_sided, geometry.emission, geometry.light_id)
    cam = baseline.camera.Camera(camera.origin, camera.target, camera.up, camera.fov, camera.fov_axis)
    f = baseline.camera.Film(film.width, film.height, film.filter)
    known = {f.name for f in dataclasses.fields(baseline.settings.Settings)}
    values = {k: v for k, v in dataclasses.asdict(settings).items() if k in known}
    if values.get("direct") == "auto":  # the baseline predates "auto"; on these Lambertian scenes it is "area"
        values["direct"] = settings.resolved(False).direct
    if values.get("rr") == "auto":  # likewise rr = auto: "albedo" on these Lambertian scenes
        values["rr"] = settings.resolved(False).rr
    s = baseline.settings.Settings(**values)
    return g, cam, f, s
