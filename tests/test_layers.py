"""The package's imports keep one direction of flow: case → mesh → discrete problem → kernel → result
→ report and writers. The case package reads and validates and imports nothing numerical.

Read from the source (every import, module level or inside a function, except under
``if TYPE_CHECKING:``), not from what happens to be imported at run time.
"""

from __future__ import annotations

import ast
import io
import re
import sys
import tokenize
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "contactfem"

#: The numerical core: arrays and sparse matrices in, arrays out.
CORE = ("contactfem.kernel", "contactfem.linalg", "contactfem.methods", "contactfem.assembly",
        "contactfem.quadrature")
#: What the core may import of the package.
CORE_MAY_IMPORT = CORE + ("contactfem.errors", "contactfem.mesh.topology", "contactfem.timings")
#: The pipeline and the studies built on it: they return data and never write.
PIPELINE = ("contactfem.case", "contactfem.discretize", "contactfem.solve", "contactfem.sequencing",
            "contactfem.result", "contactfem.report", "contactfem.estimator", "contactfem.norms",
            "contactfem.studies", "contactfem.adaptive", "contactfem.exact", "contactfem.expressions",
            "contactfem.mesh", "contactfem.sweep", "contactfem.engines")
#: Writers, pictures and the terminal: only the command line calls them.
WRITERS = ("contactfem.io", "contactfem.render", "contactfem.plots", "contactfem.cli", "contactfem.progress")
#: All the case package may import besides the standard library: NumPy, PyYAML, and of the
#: package its errors, the safe expression compiler and its own modules.
CASE_MAY_IMPORT = ("numpy", "yaml", "contactfem.errors", "contactfem.expressions", "contactfem.case")


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


def imports_of(path: Path, package: Path = PACKAGE) -> set[str]:
    """Every module ``path`` imports, package or not, by its absolute name (relative imports
    resolved; ``from a import b`` names a.b when b is a module of the package, else a),
    except under ``if TYPE_CHECKING:``."""
    modules = {_module_name(p, package) for p in package.rglob("*.py")}
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = _type_checking_lines(tree)
    here = _module_name(path, package).split(".")
    if path.name != "__init__.py":
        here = here[:-1]
    names: set[str] = set()
    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = here[:len(here) - node.level + 1] if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            for alias in node.names:
                submodule = f"{module}.{alias.name}"
                names.add(submodule if submodule in modules else module)
    return names


def foreign_imports(subpackage: str, allowed: tuple[str, ...], package: Path = PACKAGE) -> list[tuple[str, str]]:
    """(module, import) of every module of ``subpackage`` importing beyond the standard library and ``allowed``."""
    found = []
    for path in sorted((package / subpackage.split(".", 1)[1].replace(".", "/")).rglob("*.py")):
        for name in sorted(imports_of(path, package)):
            if name.split(".")[0] not in sys.stdlib_module_names and not _within(name, allowed):
                found.append((_module_name(path, package), name))
    return found


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


def test_the_case_package_imports_nothing_numerical():
    """Only the standard library, NumPy, PyYAML, contactfem.errors, contactfem.expressions and
    its own modules; and the expression compiler takes nothing of the package but its errors."""
    assert foreign_imports("contactfem.case", CASE_MAY_IMPORT) == []
    assert import_graph()["contactfem.expressions"] <= {"contactfem.errors"}


def test_the_import_reader_sees_imports_in_functions_and_relative_ones(tmp_path):
    package = tmp_path / "contactfem"
    (package / "case").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "exact.py").write_text("")
    (package / "case" / "__init__.py").write_text("from . import a\nfrom .a import f\n")
    (package / "case" / "a.py").write_text(
        "import numpy as np\nfrom typing import TYPE_CHECKING\nfrom .. import exact\n"
        "if TYPE_CHECKING:\n    import contactfem.kernel\n"
        "def f():\n    import scipy.sparse\n    from contactfem.case import b\n")
    assert foreign_imports("contactfem.case", CASE_MAY_IMPORT, package) == [
        ("contactfem.case.a", "contactfem.exact"), ("contactfem.case.a", "scipy.sparse")]
    assert imports_of(package / "case" / "__init__.py", package) == {"contactfem.case.a"}


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


#: What the kernel's modules may import of the package: each other, the linear solvers, the
#: errors and the reporting clock.
KERNEL_MAY_IMPORT = ("contactfem.kernel", "contactfem.linalg", "contactfem.errors", "contactfem.timings")
#: The modules that may reach CHOLMOD's library through ctypes, with its hard-coded layout.
CTYPES_ROUTE = ("contactfem.linalg.cholmod_direct", "contactfem.linalg.cholmod_ctypes", "contactfem.linalg.supernodal")


def test_the_kernel_imports_only_itself_the_solvers_errors_and_the_reporting_clock():
    graph = import_graph()
    beyond = [(m, t) for m in graph if _within(m, ("contactfem.kernel",)) for t in graph[m]
              if not _within(t, KERNEL_MAY_IMPORT)]
    assert beyond == []


def test_the_newton_loop_reaches_the_linear_algebra_only_through_its_solver():
    """The loop reads as an algorithm: the factorisations are the Schur solver's business."""
    graph = import_graph()
    assert not any(_within(t, ("contactfem.linalg",)) for t in graph["contactfem.kernel.newton"])
    assert "contactfem.kernel.schur" in graph["contactfem.kernel.newton"]


def test_the_linear_solvers_import_only_themselves_and_the_errors():
    graph = import_graph()
    beyond = [(m, t) for m in graph if _within(m, ("contactfem.linalg",)) for t in graph[m]
              if not _within(t, ("contactfem.linalg", "contactfem.errors"))]
    assert beyond == []


def test_the_ctypes_route_is_reached_only_through_cvxopts_backend():
    """The direct CHOLMOD route, with its struct offsets, stays behind one switch: only the
    cvxopt backend (which checks contactfem.linalg.direct_cholmod_enabled) imports it."""
    graph = import_graph()
    reaching = sorted(m for m in graph for t in graph[m] if _within(t, CTYPES_ROUTE) and not _within(m, CTYPES_ROUTE))
    assert reaching == ["contactfem.linalg.cholmod_cvxopt"]


def test_the_discretisation_asks_the_obstacle_through_its_protocol():
    """No module beyond the obstacles' own builds a concrete obstacle: they call obstacle_of."""
    concrete = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "obstacles.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("HalfPlane", "Segment"):
                concrete.append(f"{path.name}:{node.lineno}")
    assert concrete == []


#: Modules whose comments and docstrings state the design and leave measurements to
#: benchmarks/results and docs/performance.md ("Measured design choices"): the top-level
#: modules and those of these subpackages, except the ones listed as not yet cleaned.
MEASUREMENT_FREE_PACKAGES = ("", "case", "cli", "discretize", "mesh", "kernel", "linalg", "io")
NOT_YET_CLEANED: tuple[str, ...] = ()


def measurement_free_modules(package: Path = PACKAGE) -> list[str]:
    """Paths, relative to the package, of the modules the measurement rule covers."""
    names = [str(path.relative_to(package)) for sub in MEASUREMENT_FREE_PACKAGES
             for path in sorted((package / sub).glob("*.py"))]
    return [name for name in names if name not in NOT_YET_CLEANED]


_FIGURE = r"\d[\d.,]*\s?(?:ms|µs|s|GB|GiB|MB|kB|%)"
#: What a measured figure looks like in prose: a duration in (micro)seconds, a range of times,
#: sizes or shares, one figure taken against another, a run that "took" some amount, a count of
#: page faults, or a measured peak of memory. A size stated as a default or a bound ("16 GiB
#: when the system does not say") is design; units in a message ("… GiB" in an f-string) are
#: string literals, not prose; a bare number (an equation, a theorem, a constant) has no unit.
MEASURED_FIGURE = re.compile("|".join([
    r"\d\s?(?:ms|µs)(?!\w)",
    rf"\d[\d.,]*\s?[–-]\s?{_FIGURE}(?!\w)",
    rf"{_FIGURE}?\s+(?:against|instead of)\s+\d",
    r"\btook\s+(?:about\s+)?\d",
    r"\d\s?page faults",
    r"\bpeak(?:s|ed)?\b[^.;:]{0,24}?\d[\d.]*\s?(?:GB|GiB|MB)(?!\w)",
    r"\d[\d.]*\s?(?:GB|GiB|MB)\s+(?:peak|measured)\b",
]))


def prose_lines(source: str) -> list[tuple[int, str]]:
    """(line, text) of every comment and docstring line of ``source``: module, class and
    function docstrings, and the string that follows an assignment (an attribute's
    docstring). Other string literals (messages, f-strings) are not prose."""
    lines = [(token.start[0], token.string) for token in tokenize.generate_tokens(io.StringIO(source).readline)
             if token.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(source)):
        body = getattr(node, "body", None)
        if not isinstance(body, list):
            continue
        documented = isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
        docstrings = [body[0]] if documented else []
        docstrings += [after for before, after in zip(body, body[1:])
                       if isinstance(before, (ast.Assign, ast.AnnAssign))]
        for statement in docstrings:
            if (isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Constant)
                    and isinstance(statement.value.value, str)):
                lines += [(statement.lineno + k, text) for k, text in enumerate(statement.value.value.splitlines())]
    return sorted(lines)


def measured_figures(source: str) -> list[tuple[int, str]]:
    return [(line, text.strip()) for line, text in prose_lines(source) if MEASURED_FIGURE.search(text)]


def test_comments_and_docstrings_state_the_design_not_measurements():
    """Measurements go to benchmarks/results and the docs; the code says what and why."""
    modules = measurement_free_modules()
    assert "sequencing.py" in modules and "kernel/costs.py" in modules
    found = [(name, *hit) for name in modules
             for hit in measured_figures((PACKAGE / name).read_text(encoding="utf-8"))]
    assert found == []


def test_the_measurement_rule_reads_prose_and_only_prose():
    source = '''"""Module: contact solve 19.5-21.3 ms at 1 000 segments."""
LIMIT = 8  #: a hint in GiB units, equation (4), Theorem 3.7, 2 x this + 1 entries
# the queries took 0.13 s of 0.2 s
message = f"needs about {LIMIT:.3g} GiB, more than 75% of 8 GiB"
SHARE = 0.75
"""18.25 GB measured; a whole solve peaks near 5 GB."""


def f():
    """Keeps 0.45 against 3.0 for both coordinates; a sixteenth of the unknowns."""
    return "took 2 s"
'''
    assert [line for line, _ in measured_figures(source)] == [1, 3, 6, 10]
    for clean in ("the order in h, 2.8 times per halving", "h four times larger (a sixteenth)",
                  "see docs/performance.md#measured-design-choices", "(a default of 16 GiB when unknown)",
                  "Numer. Math. 101 (2005) 523–549", "edge-midpoint rule, degree 5"):
        assert not MEASURED_FIGURE.search(clean), clean
