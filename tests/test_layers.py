"""The package's imports keep one direction of flow: case → mesh → discrete problem → kernel → result
→ report and writers.

Read from the source (every import, module level or inside a function, except under
``if TYPE_CHECKING:``), not from what happens to be imported at run time.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "contactfem"

#: The numerical core: arrays and sparse matrices in, arrays out.
CORE = ("contactfem.kernel", "contactfem.linalg", "contactfem.methods", "contactfem.assembly",
        "contactfem.quadrature")
#: What the core may import of the package.
CORE_MAY_IMPORT = CORE + ("contactfem.errors", "contactfem.mesh.topology")
#: The pipeline and the studies built on it: they return data and never write.
PIPELINE = ("contactfem.case", "contactfem.discretize", "contactfem.solve", "contactfem.sequencing",
            "contactfem.result", "contactfem.report", "contactfem.estimator", "contactfem.norms",
            "contactfem.studies", "contactfem.adaptive", "contactfem.exact", "contactfem.expressions",
            "contactfem.mesh", "contactfem.sweep")
#: Writers, pictures and the terminal: only the command line calls them.
WRITERS = ("contactfem.io", "contactfem.render", "contactfem.plots", "contactfem.cli", "contactfem.progress")


def _module_name(path: Path, package: Path) -> str:
    parts = path.relative_to(package.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _type_checking_lines(tree: ast.AST) -> set[int]:
    lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            for child in node.body:
                lines.update(range(child.lineno, (child.end_lineno or child.lineno) + 1))
    return lines


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Module → the package modules it imports (a ``from a import b`` names a.b when b is a module)."""
    modules = {_module_name(p, package): p for p in package.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _type_checking_lines(tree)
        targets: set[str] = set()
        for node in ast.walk(tree):
            if getattr(node, "lineno", None) in skip:
                continue
            if isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                for alias in node.names:
                    submodule = f"{node.module}.{alias.name}"
                    targets.add(submodule if submodule in modules else node.module)
        graph[name] = {t for t in targets if t in modules and t != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in sorted(graph[node]):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def _within(module: str, prefixes: tuple[str, ...]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def test_no_import_cycle():
    assert cycles(import_graph()) == []


def test_the_numerical_core_imports_nothing_above_it():
    graph = import_graph()
    upward = [(m, t) for m in graph if _within(m, CORE) for t in graph[m] if not _within(t, CORE_MAY_IMPORT)]
    assert upward == []


def test_the_pipeline_never_imports_the_writers():
    graph = import_graph()
    writing = [(m, t) for m in graph if _within(m, PIPELINE) for t in graph[m] if _within(t, WRITERS)]
    assert writing == []


def test_the_names_a_case_is_checked_against_are_the_registries():
    """The case layer keeps its own copies of the registries' names; they must not drift."""
    from contactfem.case import names
    from contactfem.io.registry import DEFAULT_FORMATS, FORMAT_NAMES, FORMATS
    from contactfem.linalg import BACKEND_CHOICES
    from contactfem.methods import METHOD_NAMES

    assert names.METHOD_NAMES == METHOD_NAMES
    assert names.BACKEND_CHOICES == BACKEND_CHOICES
    assert names.FORMAT_NAMES == FORMAT_NAMES
    assert names.DEFAULT_FORMATS == DEFAULT_FORMATS
    assert names.FORMAT_NEEDS == {name: format.needs for name, format in FORMATS.items() if format.needs}


@pytest.mark.parametrize("source, expected", [
    ("import contactfem.b\n", [["contactfem.a", "contactfem.b"]]),
    ("import contactfem.c\n", []),
])
def test_the_cycle_finder_finds_a_cycle_and_only_a_cycle(tmp_path, source, expected):
    package = tmp_path / "contactfem"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text(source)
    (package / "b.py").write_text("def f():\n    from contactfem.a import g\n")
    (package / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import contactfem.a\n")
    assert cycles(import_graph(package)) == expected
