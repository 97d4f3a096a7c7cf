"""The house's rule (docs/architecture.md), from the code's own imports: every module of ``harness`` and
``reference_impl`` imports only modules of its own layer or of the layers below; no circle of imports; no import
inside a function except of an optional heavy dependency, marked at that line with a comment saying why
(``# optional: ...``). The graph is read with :mod:`ast`, nothing is imported."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("reference_impl", "harness")

# Bottom to top; a module belongs to the first prefix that matches (longest prefixes first within a layer).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("reference_impl",),
    ("harness.core",),
    ("harness.judges",),
    ("harness.scene", "harness.files", "harness.generators"),
    ("harness.renderers",),
    ("harness.running",),
    ("harness.studies",),
    ("harness.report",),
    ("harness.cli", "harness.pytest_plugin", "harness.__main__"),
)
UNLAYERED = ("harness",)  # the package itself: a docstring, imports nothing
# The modules that import others by name (importlib.import_module: a command's module only when it runs), and the
# top-level table in each that names them (docs/architecture.md, "Modules loaded by name"): the table's strings that
# name a project module count as that module's imports, for the layers and the circles alike.
LOADED_BY_NAME = {"harness.cli": "COMMANDS", "harness.cli.report": "STUDY_COMPUTE"}
# Heavy libraries (0.5-0.9 s to import, each) and the only modules that may import them, inside the function that
# needs them, so that a command that does not call it does not pay (docs/performance.md, "Imports at every start";
# tests/cli/test_start_up_imports.py checks the commands themselves). colour-science: the sRGB curve is
# harness.core.srgb; trimesh: mesh files only (the icosphere is harness.scene.triangulate's); scipy.stats: the
# binomials of calibrate (p-values come from scipy.special, harness.judges.distributions); matplotlib: colormaps and
# the studies' plots.
HEAVY_ONLY_IN = {
    "colour": (),
    "trimesh": ("harness.scene.mesh_files", "harness.renderers.meshfiles"),
    "scipy.stats": ("harness.judges.power", "harness.running.calibrate"),
    "matplotlib": ("harness.files.previews", "harness.studies.figures"),
    "skimage": ("harness.judges.metrics",),
}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def layer_of(name: str) -> int | None:
    for index, prefixes in enumerate(LAYERS):
        if any(name == p or name.startswith(p + ".") for p in prefixes):
            return index
    return None


@functools.cache
def parsed(path: Path) -> tuple[list[str], ast.Module, list[tuple[ast.stmt, bool]]]:
    """A module's lines, syntax tree and import statements (each with: inside a function?), read once per process:
    every test here looks at all modules (the trees are only read)."""
    source = path.read_text(encoding="utf-8")
    tree = ast.parse(source)
    return source.splitlines(), tree, import_statements(tree)


def import_statements(tree: ast.Module) -> list[tuple[ast.stmt, bool]]:
    """Every import statement of a syntax tree, with: inside a function?"""
    found = []
    stack = [(tree, False)]
    while stack:  # one pass over the tree, each node once (not once per enclosing function)
        node, inside = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append((node, inside))
        inside = inside or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
        stack.extend((child, inside) for child in ast.iter_child_nodes(node))
    return found


def imports(path: Path, name: str, known: dict[str, Path]) -> list[tuple[str, int, bool, str]]:
    """(imported module, line, inside a function?, the line's text) for every import of a project module."""
    lines, tree, statements = parsed(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []

    def resolve(target: str) -> str | None:
        while target and target not in known:
            target = target.rpartition(".")[0]
        return target or None

    for node, inside in statements:
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        else:
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        for target in targets:
            if target.split(".")[0] in PACKAGES:
                resolved = resolve(target)
                if resolved and resolved != name:
                    found.append((resolved, node.lineno, inside, lines[node.lineno - 1]))
    if name in LOADED_BY_NAME:
        for target, line in loaded_by_name(tree, LOADED_BY_NAME[name]):
            found.append((resolve(target) or target, line, False, lines[line - 1]))
    return sorted(found, key=lambda item: item[1])


def loaded_by_name(tree: ast.Module, table: str) -> list[tuple[str, int]]:
    """(module, line) for every string naming a module of the project in the top-level assignment ``table``."""
    out = []
    for node in tree.body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == table for t in targets):
                out += [(c.value, c.lineno) for c in ast.walk(node.value) if isinstance(c, ast.Constant)
                        and isinstance(c.value, str) and c.value.split(".")[0] in PACKAGES and "." in c.value]
    return out


def calls_import_by_name(tree: ast.Module) -> bool:
    """Whether the module calls ``importlib.import_module`` or ``__import__``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call):
            func = node.func
            if (isinstance(func, ast.Attribute) and func.attr == "import_module") or \
                    (isinstance(func, ast.Name) and func.id in ("import_module", "__import__")):
                return True
    return False


def nested_imports(path: Path) -> list[tuple[int, str]]:
    """Every import statement inside a function (of any module, project or not), with its line's text."""
    lines, _, statements = parsed(path)
    return sorted({(node.lineno, lines[node.lineno - 1]) for node, inside in statements if inside})


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: {t for t, *_ in imports(path, name, known)} for name, path in known.items()}


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, on, stack, out, counter = {}, {}, set(), [], [], [0]

    def strong(v):
        work = [(v, iter(sorted(edges.get(v, ()))))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        while work:
            node, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                    break
                if w in on:
                    low[node] = min(low[node], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == node:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            strong(v)
    return out


def test_every_module_has_a_layer():
    missing = [m for m in modules() if layer_of(m) is None and m not in UNLAYERED]
    assert not missing, f"modules outside every layer of docs/architecture.md: {missing}"


def test_no_circle_of_imports():
    assert cycles(graph()) == []


def test_no_module_imports_a_layer_above_it():
    known = modules()
    upward = []
    for name, path in known.items():
        mine = layer_of(name)
        for target, line, _, text in imports(path, name, known):
            theirs = layer_of(target)
            if mine is not None and theirs is not None and theirs > mine:
                upward.append(f"{path.relative_to(ROOT)}:{line}: {text.strip()}")
    assert not upward, "imports running up the layers:\n" + "\n".join(upward)


def test_reference_impl_imports_neither_harness_nor_mitsuba():
    for name, path in modules().items():
        if name.startswith("reference_impl"):
            for node in ast.walk(parsed(path)[1]):
                if isinstance(node, ast.Import):
                    roots = [a.name.split(".")[0] for a in node.names]
                elif isinstance(node, ast.ImportFrom) and not node.level:
                    roots = [(node.module or "").split(".")[0]]
                else:
                    continue
                assert not {"harness", "mitsuba"} & set(roots), (path, node.lineno)


def test_imports_inside_functions_are_optional_heavy_dependencies_and_say_so():
    bad = []
    for name, path in modules().items():
        for line, text in nested_imports(path):
            if "# optional:" not in text:
                bad.append(f"{path.relative_to(ROOT)}:{line}: {text.strip()}")
    assert not bad, "imports inside functions without '# optional: why':\n" + "\n".join(bad)


def heavy_imports(statements: list[tuple[ast.stmt, bool]]) -> list[tuple[str, int, bool]]:
    """(library of :data:`HEAVY_ONLY_IN`, line, inside a function?) for every import of one."""
    found = []
    for node, inside in statements:
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif not node.level:
            names = [node.module or ""] + [f"{node.module}.{a.name}" for a in node.names]  # from scipy import stats
        else:
            continue
        for heavy in HEAVY_ONLY_IN:
            if any(n == heavy or n.startswith(heavy + ".") for n in names):
                found.append((heavy, node.lineno, inside))
    return found


def test_heavy_libraries_are_imported_only_where_needed_and_inside_a_function():
    bad = []
    for name, path in modules().items():
        for heavy, line, inside in heavy_imports(parsed(path)[2]):
            if name not in HEAVY_ONLY_IN[heavy] or not inside:
                bad.append(f"{path.relative_to(ROOT)}:{line}: {heavy} ({'' if inside else 'at the top, '}allowed "
                           f"only inside functions of {', '.join(HEAVY_ONLY_IN[heavy]) or 'no module'})")
    assert not bad, "heavy imports outside their places:\n" + "\n".join(bad)


def test_modules_loaded_by_name_are_declared_and_exist():
    """A module that imports by name declares what in its table (else the layer and circle checks would not see
    it), and every module a table names exists (a misspelt command module fails here, not when a user runs it)."""
    known = modules()
    undeclared = [n for n, p in known.items()
                  if calls_import_by_name(parsed(p)[1]) and n not in LOADED_BY_NAME]
    assert not undeclared, f"modules importing by name without a table in LOADED_BY_NAME: {undeclared}"
    for name, table in LOADED_BY_NAME.items():
        named = loaded_by_name(parsed(known[name])[1], table)
        assert named, f"{name}.{table} names no module"
        missing = [target for target, _ in named if target not in known]
        assert not missing, f"{name}.{table} names modules that do not exist: {missing}"
    assert "harness.cli.report" in graph()["harness.cli"]


def test_the_checks_can_fail():
    """The cycle finder and the layer table on a planted graph: a circle and an upward arrow are seen."""
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert layer_of("harness.cli.run") > layer_of("harness.running.cases") > layer_of("harness.core.errors")
    assert layer_of("harness.report.build") > layer_of("harness.studies.convergence")
    planted = ast.parse('import importlib\nT = (("a", "harness.cli.nope", "help"),)\nimportlib.import_module("x")\n')
    assert loaded_by_name(planted, "T") == [("harness.cli.nope", 2)] and calls_import_by_name(planted)
    planted = ast.parse("from scipy import stats\nimport numpy\ndef f():\n    import colour.models\n")
    assert sorted(heavy_imports(import_statements(planted))) == [("colour", 4, True), ("scipy.stats", 1, False)]
