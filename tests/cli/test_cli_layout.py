"""The command line's layout (harness/cli): one module per command with ``register(sub, common)`` and
``run(args)``, the shared options declared once (the same flag, kind and help text in every command that takes
them), each command's own options listed before the shared ones, and help that names what it checks."""

from __future__ import annotations

import argparse
import importlib
import pkgutil

import pytest
from conftest import ROOT

import harness.cli
from harness.cli import build_parser, main
from harness.core.errors import HarnessError
from harness.core.options import parse_set

# The commands in the order `harness --help` lists them (it did so before the split, too).
ORDER = ["render", "ground-truth", "compare", "run", "baseline", "report", "view", "convergence", "calibrate",
         "export", "import", "generate", "bench", "stress"]
# The commands that load scene files (and so follow their mesh paths).
LOADS_SCENES = ["render", "ground-truth", "run", "report", "convergence", "calibrate", "export", "bench", "stress",
                "baseline save"]
SHARED = ["--quiet", "--cache-dir", "--mitsuba-variant", "--allow-outside-paths"]


def commands() -> dict[str, argparse.ArgumentParser]:
    """Every command's parser by name, ``baseline save`` included."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    found = dict(sub.choices)
    nested = next(a for a in found["baseline"]._actions if isinstance(a, argparse._SubParsersAction))
    found["baseline save"] = nested.choices["save"]
    return found


def option(parser: argparse.ArgumentParser, flag: str) -> argparse.Action | None:
    return next((a for a in parser._actions if flag in a.option_strings), None)


def test_one_module_per_command_with_register_and_run():
    # shared by the commands, not commands
    names = {m.name for m in pkgutil.iter_modules(harness.cli.__path__)} - {"common", "studies", "study_compute"}
    assert {module.rpartition(".")[2] for _, module, _ in harness.cli.COMMANDS} == names
    assert [name for name, _, _ in harness.cli.COMMANDS] == ORDER
    for name in names:
        module = importlib.import_module(f"harness.cli.{name}")
        assert callable(module.register) and callable(module.run), name
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert list(sub.choices) == ORDER


@pytest.mark.parametrize("flag", SHARED)
def test_a_shared_option_is_the_same_everywhere(flag):
    """Declared once: the same kind of option with the same help text in every command that takes it (the
    texts used to differ, or be missing, from command to command)."""
    found = {name: option(p, flag) for name, p in commands().items()}
    taken = {name: a for name, a in found.items() if a is not None}
    assert len(taken) >= 5, taken
    kinds = {(type(a).__name__, a.help, a.metavar) for a in taken.values()}
    assert len(kinds) == 1, kinds
    assert next(iter(kinds))[1], f"{flag} has no help text"


def test_every_command_that_loads_scenes_takes_allow_outside_paths_and_the_others_do_not():
    found = commands()
    assert sorted(n for n, p in found.items() if option(p, "--allow-outside-paths")) == sorted(LOADS_SCENES)


def test_every_argument_has_help_and_own_options_come_first():
    for name, parser in commands().items():
        if name == "baseline":
            continue
        actions = [a for a in parser._actions if not isinstance(a, argparse._HelpAction)]
        missing = [a.dest for a in actions if not a.help]
        assert not missing, f"{name}: arguments without help: {missing}"
        shared = [i for i, a in enumerate(actions) if set(a.option_strings) & {"--out", "--json", *SHARED}]
        if shared:  # the command's own arguments, then the shared ones
            assert shared == list(range(shared[0], len(actions))), name


def test_required_arguments_are_named_in_the_order_the_command_declares_them(capsys):
    assert main(["render"]) == 2
    assert capsys.readouterr().err.strip().endswith("the following arguments are required: scene, --spp, --out")
    assert main(["export", "scene.toml"]) == 2
    assert capsys.readouterr().err.strip().endswith("the following arguments are required: --format, --out")


def test_help_speaks_of_the_product():
    found = commands()
    check = option(found["bench"], "--check").help
    assert "issue" not in check and "ldsampler" in check and "best sampler" in check and "cores busy" in check
    compare = found["compare"].format_usage()
    assert compare.rstrip().endswith("test ground-truth")
    for name, parser in found.items():
        assert "issue" not in parser.format_help(), name


def test_parse_set_reads_key_value_pairs():
    assert parse_set([" direct = mis", "rr=off", "rr=on", "empty="]) == {"direct": "mis", "rr": "on", "empty": ""}
    for bad in ("novalue", "=x", " =x"):
        with pytest.raises(HarnessError) as err:
            parse_set([bad])
        assert str(err.value) == f"--set: expected key=value, got {bad!r}"


def test_python_dash_m_harness_and_the_console_script_entry_point():
    text = (ROOT / "pyproject.toml").read_text()
    assert 'harness = "harness.cli:main"' in text
    with pytest.raises(SystemExit) as stop:
        main(["--help"])
    assert stop.value.code == 0
