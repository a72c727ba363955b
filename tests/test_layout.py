"""The package's dependencies run one way: no two subpackages (or top-level modules) import
each other, at module level or inside functions; type-only imports do not count."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "pidyn"


def _unit(module: str) -> str:
    """``pidyn.discrepancy.storeys`` -> ``discrepancy``; ``pidyn.signals`` -> ``signals``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def _type_only(tree: ast.AST) -> set[int]:
    """Line numbers of imports under ``if TYPE_CHECKING:``."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.If)
            and getattr(node.test, "id", getattr(node.test, "attr", "")) == "TYPE_CHECKING"
        ):
            for sub in ast.walk(node):
                if isinstance(sub, (ast.Import, ast.ImportFrom)):
                    lines.add(sub.lineno)
    return lines


def package_graph() -> dict[str, dict[str, set[str]]]:
    """unit -> imported unit -> the files that import it."""
    graph: dict[str, dict[str, set[str]]] = defaultdict(lambda: defaultdict(set))
    for f in SRC.rglob("*.py"):
        rel = f.relative_to(SRC.parent).with_suffix("")
        unit = rel.parts[1] if len(rel.parts) > 1 else rel.parts[0]
        tree = ast.parse(f.read_text())
        skip = _type_only(tree)
        for node in ast.walk(tree):
            if getattr(node, "lineno", None) in skip:
                continue
            names = []
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pidyn."):
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names if a.name.startswith("pidyn.")]
            for name in names:
                target = _unit(name)
                if target != unit:
                    graph[unit.removesuffix(".py")][target].add(str(rel))
    return graph


def test_no_two_parts_of_the_package_import_each_other():
    graph = package_graph()
    cycles = [
        (a, b, sorted(graph[a][b]), sorted(graph[b][a]))
        for a in graph
        for b in graph[a]
        if a < b and a in graph.get(b, {})
    ]
    assert not cycles, cycles


def test_the_weak_form_and_signals_need_neither_torch_nor_the_diagnosis():
    """The low modules every part shares import NumPy and SciPy only."""
    for name in ("signals.py", "weak_form.py"):
        tree = ast.parse((SRC / name).read_text())
        imported = {
            (n.module if isinstance(n, ast.ImportFrom) else a.name).split(".")[0]
            for n in ast.walk(tree)
            if isinstance(n, (ast.Import, ast.ImportFrom))
            for a in (n.names if isinstance(n, ast.Import) else [n])
            if not isinstance(n, ast.ImportFrom) or n.module
        }
        assert imported <= {"__future__", "dataclasses", "numpy", "scipy", "typing", "math"}, (name, imported)


def file_graph() -> dict[str, set[str]]:
    """module -> the package's modules it imports, at module level or inside functions (a package's
    ``__init__`` counts as the package; ``from pkg import mod`` imports ``pkg.mod``)."""
    files = {}
    for f in SRC.rglob("*.py"):
        rel = f.relative_to(SRC.parent).with_suffix("")
        parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
        files[".".join(parts)] = f
    graph: dict[str, set[str]] = {m: set() for m in files}
    for mod, f in files.items():
        tree = ast.parse(f.read_text())
        skip = _type_only(tree)
        for node in ast.walk(tree):
            if getattr(node, "lineno", None) in skip:
                continue
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("pidyn"):
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            graph[mod] |= {n for n in names if n in files and n != mod}
    return graph


def _no_cycle(graph: dict[str, set[str]]) -> None:
    done: set[str] = set()
    path: list[str] = []

    def visit(node: str) -> None:
        if node in done:
            return
        assert node not in path, " -> ".join(path[path.index(node) :] + [node])
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            visit(nxt)
        path.pop()
        done.add(node)

    for node in sorted(graph):
        visit(node)


def test_the_parts_of_the_package_form_no_cycle_of_any_length():
    """A topological order exists: signals and systems below, tasks at the top."""
    _no_cycle({a: set(b) for a, b in package_graph().items()})


def test_no_file_imports_itself_through_others():
    """Within the parts too: no circle of files, counting the imports made inside functions."""
    _no_cycle(file_graph())


def test_the_tasks_only_wire():
    """Every module in ``pidyn.tasks`` composes, runs and writes in at most 150 lines; the domain
    logic lives in the package."""
    long = {f.name: n for f in (SRC / "tasks").glob("*.py") if (n := len(f.read_text().splitlines())) > 150}
    assert not long, long


def test_no_function_is_longer_than_60_lines():
    """A function says one thing: the package, the experiments and the scripts, each at most 60
    lines from its ``def`` to its last line."""
    root = SRC.parents[1]
    files = [*SRC.rglob("*.py"), *(root / "experiments").glob("*.py"), *root.glob("*.py")]
    long = []
    for f in files:
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > 60:
                    long.append(f"{f.relative_to(root)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, long


def test_no_file_is_longer_than_500_lines():
    """A file a newcomer reads in one sitting: what grows past it is split where it has a seam."""
    long = [
        f"{f.relative_to(SRC.parent)} ({n} lines)"
        for f in sorted(SRC.rglob("*.py"))
        if (n := len(f.read_text().splitlines())) > 500
    ]
    assert not long, long


def test_an_import_inside_a_function_says_why():
    """Imports live at the top of a module; the few inside a function (a heavy or optional library
    loaded on first use, a task imported once the settings hold) carry their reason in a comment."""
    bare = []
    for f in SRC.rglob("*.py"):
        lines = f.read_text().splitlines()
        for node in ast.walk(ast.parse("\n".join(lines))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for sub in ast.walk(node):
                if isinstance(sub, (ast.Import, ast.ImportFrom)):
                    near = lines[sub.lineno - 2 : sub.end_lineno]
                    if not any("#" in ln for ln in near):
                        bare.append(f"{f.relative_to(SRC)}:{sub.lineno}")
    assert not bare, bare


def test_the_studies_share_through_the_package_not_by_path():
    """``experiments/`` imports what its studies share from ``pidyn.bench``: none edits sys.path."""
    root = SRC.parents[1]
    edits = [f.name for f in (root / "experiments").glob("*.py") if "sys.path" in f.read_text()]
    assert not edits, edits
