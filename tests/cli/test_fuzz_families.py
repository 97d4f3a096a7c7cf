"""The long fuzzing mode's untrusted-input families (tests/cli/fuzz.py: results_paths, planted_links, hostile_peers,
misbehaving_renderers, mesh_references) and the oracles that watch what an input reaches outside its folder:
``escape``, ``link_write``, ``copied``, ``leftover_process``, ``raw_escape``, each told apart on planted outcomes;
each new generator makes the same inputs from the same seed, and inputs the harness can parse."""

from __future__ import annotations

import base64
import json
import os
import stat
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import fuzz
from harness import cli
from harness.core.errors import HarnessError

FAMILIES = ("results_paths", "planted_links", "hostile_peers", "misbehaving_renderers", "mesh_references")


def _secret() -> bytes:
    return Path("../outside/secret.txt").read_bytes()


def planted_main(argv: list[str]) -> int:
    """Stands in for harness.cli.main in the children (cwd: the input's folder): each first argument plants one
    thing reached outside, or none."""
    what = argv[0]
    if what == "ok":
        return 0
    if what == "error":
        print("harness: error: x.toml: spp: expected a positive integer", file=sys.stderr)
        return 2
    if what == "write-outside":
        Path("../outside/victim.txt").write_text("changed")
    elif what == "create-outside":
        Path("../outside/new.txt").write_text("new")
    elif what == "read-outside":
        _secret()
    elif what == "through-link":
        Path("out/.lock").write_text(str(os.getpid()))  # the planted link leads to the victim
    elif what == "turn-link":
        os.unlink("out/.lock")
        os.symlink("/tmp", "out/.lock")
    elif what == "remove-link":
        os.unlink("out/.lock")
    elif what == "copy-secret":
        Path("report").mkdir()
        Path("report/copy.exr").write_bytes(b"v/1\x01" + _secret())
    elif what == "copy-base64":
        Path("page.html").write_bytes(b"<img src='data:image/png;base64," + base64.b64encode(b"xy" + _secret()) + b"'>")
    elif what == "copy-environ":  # a program it runs copies its environment (its own: the forked child's is the parent's)
        subprocess.run(["sh", "-c", "cat /proc/$$/environ > env.txt"], check=True)
    elif what == "link-out":
        os.symlink(os.path.abspath("../outside/secret.txt"), "shipped.txt")
    elif what == "leave-process":  # a program it runs leaves a grandchild behind (no longer below the child)
        subprocess.run(["sh", "-c", "sleep 29 </dev/null >/dev/null 2>&1 &"], check=True)
    elif what == "print-esc":
        print("harness: error: renderer said \x1b[2J\x1b]0;title\x07", file=sys.stderr)
        return 2
    elif what == "print-bidi":
        print("done \u202eevil")
    elif what == "claim":
        print("sent good.exr to tev at 127.0.0.1:1")
    elif what in ("exit-1", "works-but-1"):
        return 1
    elif what == "memory-hog":
        hog = b"x" * (200 * 2**20)  # resident: written, not only mapped
        return len(hog) - len(hog)
    elif what == "out-of-memory":
        print("harness: render failed: r: OSError: [Errno 12] Cannot allocate memory", file=sys.stderr)
        return 1
    return 0


PLANTED = {"ok": "pass", "error": "error", "write-outside": "escape", "create-outside": "escape",
           "read-outside": "escape", "through-link": "link_write", "turn-link": "escape", "remove-link": "pass",
           "copy-secret": "copied", "copy-base64": "copied", "copy-environ": "copied", "link-out": "copied",
           "leave-process": "leftover_process", "print-esc": "raw_escape", "print-bidi": "raw_escape",
           "claim": "silent", "exit-1": "pass", "works-but-1": "messy", "out-of-memory": "messy",
           "memory-hog": "messy"}


def _planted_input(index: int, what: str) -> fuzz.Input:
    inp = fuzz.Input("planted", index, ["cli", what], dirs=["out"])
    if what in ("through-link", "turn-link", "remove-link"):
        inp.links["out/.lock"] = "@OUTSIDE@/victim.txt"
    if what == "claim":
        inp.lies.append("to tev at")
    if what == "exit-1":
        inp.fails.append("exit 0 would be wrong")
    if what == "works-but-1":
        inp.succeeds = "the renderer works"
    if what == "memory-hog":
        inp.max_mib = 100
    if what == "out-of-memory":
        inp.symptoms.append("Cannot allocate memory")
    return inp


@pytest.fixture(scope="module")
def light_assets(tmp_path_factory) -> fuzz.Assets:
    """The loaders' assets, and a run folder's files made up (results.json with the path fields, viewer.js): the
    generators need its shape, not a real run (which costs seconds)."""
    assets = fuzz.Assets(tmp_path_factory.mktemp("fuzz-family-assets"))
    assets.build(run=False)
    cases, run_files = [], {}
    for name in fuzz.RUN_CASES:
        folder = f"run/cases/{name}"
        cases.append({"name": name, "verdict_maps": {"pvalue": f"{folder}/pvalue.exr", "failing": f"{folder}/failing.exr"},
                      "report_images": {"folder": f"{folder}/images", "images": [{"png": "render.png",
                                                                                  "exr": "render.exr"}]},
                      "viewer": {"folder": folder, "data": "viewer.js", "thumbnail": "thumbnail.png"},
                      "render": {"exr": f"{folder}/render.exr"}})
        for file in ("pvalue.exr", "failing.exr", "render.exr", "images/render.exr"):
            run_files[f"cases/{name}/{file}"] = assets.blobs["good.exr"]
        run_files[f"cases/{name}/viewer.js"] = b'/* viewer data */\nHarnessViewer.register({"name": "x"});\n'
        run_files[f"cases/{name}/thumbnail.png"] = b"\x89PNG\r\n\x1a\n"
    assets.texts["results.json"] = json.dumps({"suite": "fz", "cases": cases})
    assets.run_files = run_files
    return assets


@pytest.mark.slow  # forks a child per input: over 0.5 s
def test_the_new_oracles_on_planted_outcomes(tmp_path, light_assets, monkeypatch):
    """Each way of reaching outside is its own outcome (a write through a planted link, a change or a read outside,
    a canary copied in raw, in base64 or from /proc/self/environ, a link out shipped, a process left running, a
    terminal escape printed, a false claim, a working input failed, memory exhausted or more used than the input
    allows); a planted link the call removed is a hint, not a failure."""
    monkeypatch.setattr(cli, "main", planted_main)
    inputs = [_planted_input(i, what) for i, what in enumerate(PLANTED)]
    runner = fuzz.Runner(tmp_path / "out", light_assets, fuzz.Limits(timeout=20), jobs=2)
    records = {r.inp.call[1]: r for r in runner.run(inputs)}
    assert {what: r.outcome for what, r in records.items()} == PLANTED, {w: r.detail for w, r in records.items()}
    assert "through the planted link out/.lock" in records["through-link"].detail
    assert "read" in records["read-outside"].detail
    assert "the environment canary" in records["copy-environ"].detail
    assert "sleep 29" in records["leave-process"].detail
    assert records["remove-link"].removed_links == ["out/.lock"]
    assert "MiB, over its 100 MiB" in records["memory-hog"].detail
    summary = fuzz.summarize(list(records.values()), 1.0, {})
    assert summary["total"]["link_write"] == 1 and summary["total"]["removed_link"] == 1
    table = fuzz.format_table(summary)
    assert "link_wr" in table and "leftover" in table and "raw_esc" in table
    assert {outcome for _, outcome in fuzz.REACHED} | {"raw_escape"} <= set(fuzz.FAILURES)
    kept = tmp_path / "out" / "failures" / records["through-link"].inp.id
    assert (kept / "input" / "out" / ".lock").is_symlink() and (kept / "outside" / "victim.txt").exists()


def test_raw_escapes_are_classified_before_the_exit_code():
    inp = fuzz.Input("x", 0, ["cli", "render"])
    outcome, detail = fuzz.classify(inp, {"rc": 1}, "", "harness: render failed: \u202eevil\n", timed_out=False,
                                    signalled=None)
    assert outcome == "raw_escape" and "U+202E" in detail
    assert fuzz.classify(inp, {"rc": 1}, "", "harness: render failed: evil\n", timed_out=False,
                         signalled=None)[0] == "pass"
    assert fuzz.reach("pass", "exit 0", {"escape": ["outside/x created"], "copied": ["y"]})[0] == "escape"


def _same(first: fuzz.Input, second: fuzz.Input) -> bool:
    return first.to_json() == second.to_json() and first.files == second.files


@pytest.mark.parametrize("family", FAMILIES)
def test_each_new_generator_makes_valid_inputs_deterministically(tmp_path, light_assets, monkeypatch, family):
    """The same seed makes the same inputs; each materialises (its links, named pipes and outside folder made,
    placeholders filled in), its TOML and JSON files parse, and its command line parses (or is a loader's call)."""
    monkeypatch.setattr(fuzz, "HUGE_ENVMAP", (8, 16))
    monkeypatch.setattr(fuzz, "PEERS", {kind: 9 for kind in fuzz.PEER_KINDS})
    first = [fuzz.generate(4, family, i, light_assets) for i in range(12)]
    again = [fuzz.generate(4, family, i, light_assets) for i in range(12)]
    assert all(_same(a, b) for a, b in zip(first, again))
    assert len({json.dumps(i.to_json(), sort_keys=True) for i in first}) > 3  # not one input twelve times
    for inp in first:
        folder = tmp_path / inp.id / "input"
        fuzz.materialize(inp, folder, light_assets)
        outside = folder.parent / "outside"
        assert (outside / "secret.txt").exists() and (outside / "victim-dir").is_dir()
        for name in inp.links:
            assert (folder / name).is_symlink() and "@" not in os.readlink(folder / name)
        for name in inp.fifos:
            assert stat.S_ISFIFO(os.lstat(folder / name).st_mode)
        for name in inp.files:
            path = folder / name
            if path.is_symlink() or not path.is_file():
                continue
            data = path.read_bytes()
            assert b"@OUTSIDE@" not in data and b"@INPUT@" not in data
            if name.endswith(".toml") and inp.entry != "misbehaving_renderers":
                tomllib.loads(data.decode())
            if name.endswith("results.json"):
                json.loads(data)
        args = [fuzz.resolve(arg, folder) for arg in inp.call[1:]]
        assert not any("@" in a for a in args), args
        if inp.call[0] == "cli":
            monkeypatch.chdir(folder)
            try:
                cli.build_parser(args[0]).parse_args(args)
            except (HarnessError, SystemExit) as err:
                pytest.fail(f"{inp.id}: {args}: {err}")
        else:
            assert inp.call[0] == "load_scene" and (folder / args[0]).exists()


def test_the_new_families_are_planned():
    jobs = fuzz.plan(10_000)
    counts = {name: sum(1 for n, _ in jobs if n == name) for name in FAMILIES}
    assert counts == {name: fuzz.GENERATORS[name][1] for name in FAMILIES}
    assert sum(counts.values()) >= 1500


def test_a_path_replaced_by_a_file_a_pipe_or_a_link_holds_nothing_below_it(tmp_path, light_assets):
    """An input that makes a run's case folder a file, a named pipe or a link out, while its generator left that
    folder's files in the input, is written (the materialising raised FileExistsError, ending the whole fuzz run:
    seed 11)."""
    inp = fuzz.Input("results_paths", 0, ["cli", "report", "run/results.json"],
                     files={"run/cases/a": b"x", "run/cases/a/render.exr": b"y", "run/cases/c/render.exr": b"z"},
                     dirs=["run/cases/b/images"], fifos=["run/cases/b"], links={"run/cases/c": "@OUTSIDE@"})
    folder = tmp_path / "in" / "input"
    fuzz.materialize(inp, folder, light_assets)
    assert (folder / "run/cases/a").read_bytes() == b"x"
    assert stat.S_ISFIFO(os.lstat(folder / "run/cases/b").st_mode)
    assert (folder / "run/cases/c").is_symlink()
