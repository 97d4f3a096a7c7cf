"""Where a render's time goes, compiled function by compiled function: ``perf record`` on a one-thread render loop,
with the numba kernels named.

    .venv/bin/python tests/studies/benchmarks/kernel_profile.py SCENE [--spp 64] [--seconds 30] [--top 25]
        [--set key=value ...] [--out perf.data]

perf names the code of shared objects by their symbols, but numba's kernels live in memory LLVM wrote at run time,
which perf shows as ``[JIT] tid N`` with bare addresses. perf reads names for such code from ``/tmp/perf-PID.map``
(lines ``START SIZE NAME``, hex; perf's "perf map" convention for JIT compilers). This script compiles the kernels
into a fresh numba cache (code loaded from numba's cache has no LLVM module left to read the names from), renders
once, writes that file for every function of every compiled kernel (:func:`write_perf_map`), then renders in a loop
while ``perf record`` samples this process, and prints the shares by function and by shared object.

Needs ``perf`` (Debian: ``linux-perf``) and the right to sample one's own process (``perf_event_paranoid`` <= 2, or
root). A function LLVM inlined into another is counted in the one it was inlined into. Results:
docs/performance.md, "Issue 39: where the time goes, function by function".
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def demangle(name: str) -> str:
    """The dotted qualified name in a numba symbol (``_ZN<len><part>...E<types>``: the Itanium form numba uses),
    e.g. ``reference_impl.kernels.bsdf.mf_pdf``; other names as they are."""
    if not name.startswith("_ZN"):
        return name
    i, parts = 3, []
    while i < len(name) and name[i].isdigit():
        j = i
        while name[j].isdigit():
            j += 1
        length = int(name[i:j])
        parts.append(name[j:j + length])
        i = j + length
    return ".".join(p for p in parts if not p.startswith("_3clocals")) or name


def dispatcher_functions(dispatchers) -> dict[int, str]:
    """{address: qualified name} of every function defined in the compiled specializations of ``dispatchers``
    (numba ``CPUDispatcher`` objects). Only specializations compiled in this process have their LLVM module, and so
    their names; those loaded from numba's cache are left out."""
    found: dict[int, str] = {}
    for dispatcher in dispatchers:
        for compiled in dispatcher.overloads.values():
            library = compiled.library
            for function in library.get_defined_functions():
                address = library.get_pointer_to_function(function.name)
                if address:
                    found[address] = demangle(function.name)
    return found


def kernel_functions(package_name: str = "reference_impl.kernels") -> dict[int, str]:
    """:func:`dispatcher_functions` of every numba dispatcher of the modules of ``package_name``."""
    import importlib
    import pkgutil

    from numba.core.registry import CPUDispatcher

    package = importlib.import_module(package_name)
    dispatchers = []
    for info in pkgutil.iter_modules(package.__path__):
        module = importlib.import_module(f"{package_name}.{info.name}")
        dispatchers += [value for value in vars(module).values() if isinstance(value, CPUDispatcher)]
    return dispatcher_functions(dispatchers)


def write_perf_map(functions: dict[int, str], path: Path) -> int:
    """Write ``functions`` ({address: name}) as a perf map: each function from its address to the next one's (the
    last 64 KiB), at most 1 MiB. Returns the number of lines."""
    addresses = sorted(functions)
    with open(path, "w") as handle:
        for k, address in enumerate(addresses):
            end = addresses[k + 1] if k + 1 < len(addresses) else address + (1 << 16)
            handle.write(f"{address:x} {min(end - address, 1 << 20):x} {functions[address]}\n")
    return len(addresses)


def shares(perf_data: Path, key: str) -> list[tuple[float, str]]:
    """(percent, name) rows of ``perf report --sort KEY`` (``sym`` or ``dso``), self time, largest first."""
    out = subprocess.run(["perf", "report", "-i", str(perf_data), "--no-children", "--sort", key, "--stdio"],
                         capture_output=True, text=True, check=True).stdout
    rows = []
    for line in out.splitlines():
        line = line.strip()
        if not line or line.startswith("#") or not line[0].isdigit() or "%" not in line:
            continue
        percent, _, rest = line.partition("%")
        rows.append((float(percent), rest.strip().removeprefix("[.]").removeprefix("[k]").strip()))
    return rows


def main(argv=None) -> int:
    from harness.core import options

    parser = argparse.ArgumentParser(description="Where a render's time goes, compiled function by compiled function: "
                                     "perf record on a one-thread render loop, numba's kernels named. Needs perf.")
    parser.add_argument("scene", help="a scene NAME of scenes/ or a scene file")
    parser.add_argument("--spp", type=options.int_type(minimum=1), default=64, help="samples per pixel (64)")
    parser.add_argument("--seconds", type=options.number_type(positive=True), default=30.0,
                        help="how long perf samples the render loop")
    parser.add_argument("--top", type=options.int_type(minimum=1), default=25, help="functions listed")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a renderer setting")
    parser.add_argument("--out", type=options.out_file, help="keep perf's data here (default: a temporary file)")
    args = parser.parse_args(argv)
    if shutil.which("perf") is None:
        print("kernel_profile: perf not found (Debian: apt-get install linux-perf)", file=sys.stderr)
        return 2
    if args.out is not None and not Path(args.out).resolve().parent.is_dir():
        print(f"kernel_profile: --out: expected a file in an existing folder, got {args.out}", file=sys.stderr)
        return 2
    scratch = Path(tempfile.mkdtemp(prefix="kernel-profile-"))
    try:
        return _profile(args, scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _profile(args, scratch: Path) -> int:
    """Compile, render once, then render while perf samples: :func:`main`'s work, in its scratch folder."""
    os.environ["NUMBA_CACHE_DIR"] = str(scratch / "numba")  # compiled here, so that their names can be read
    from harness.core import options
    from harness.core.errors import HarnessError
    from harness.renderers import RenderRequest, get_renderer
    from harness.scene import load_scene

    root = Path(__file__).resolve().parents[3]
    path = Path(args.scene) if args.scene.endswith(".toml") else root / "scenes" / f"{args.scene}.toml"
    renderer = get_renderer("reference")
    try:
        scene = load_scene(path)
        request = RenderRequest(spp=args.spp, seed=1, settings={"threads": 1, **options.parse_set(args.set)})
        print(f"compiling and rendering {path.name} once ...", file=sys.stderr, flush=True)
        renderer.render(scene, request)
    except HarnessError as err:
        print(f"kernel_profile: {err}", file=sys.stderr)
        return 2
    perf_map = Path(f"/tmp/perf-{os.getpid()}.map")
    count = write_perf_map(kernel_functions(), perf_map)
    perf_data = Path(args.out) if args.out else scratch / "perf.data"
    recorder = subprocess.Popen(["perf", "record", "-F", "2000", "-p", str(os.getpid()), "-o", str(perf_data), "--",
                                 "sleep", str(args.seconds)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    start, renders, seconds = time.perf_counter(), 0, 0.0
    while recorder.poll() is None:
        seconds += renderer.render(scene, request).seconds
        renders += 1
    wall = time.perf_counter() - start
    try:
        if recorder.returncode != 0:
            print(f"kernel_profile: perf record failed (exit {recorder.returncode}): may this user sample its own "
                  "process? (perf_event_paranoid)", file=sys.stderr)
            return 2
        functions, objects = shares(perf_data, "sym"), shares(perf_data, "dso")
    finally:
        perf_map.unlink(missing_ok=True)
    print(f"{path.name}, {args.spp} spp, one thread: {renders} renders in {wall:.1f} s "
          f"({seconds / max(renders, 1):.4f} s each); {count} compiled functions named")
    print("by shared object:")
    for percent, name in objects[:8]:
        print(f"  {percent:5.1f} %  {name}")
    print("by function:")
    for percent, name in functions[:args.top]:
        print(f"  {percent:5.1f} %  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
