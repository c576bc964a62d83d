"""No decision of contactfem.linalg comes from the wall clock: the same matrices give the
same routes, the same counted statistics, the same modelled seconds and the same
solutions bit for bit, however erratic the clock; and no module of the package reads one."""

from __future__ import annotations

import ast
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import contactfem.linalg as linalg
from contactfem.linalg import cholmod_ctypes, registry

PACKAGE = Path(linalg.__file__).resolve().parent
#: The clocks of the time module (and their _ns twins), which linalg must not read.
CLOCKS = {"perf_counter", "time", "monotonic", "process_time", "thread_time", "clock_gettime"}


def _grid(side: int, seed: int) -> sp.csr_matrix:
    """A 2D grid Laplacian on two weakly coupled components, plus a random diagonal."""
    grid = sp.diags([-1.0, -1.0, 4.0, -1.0, -1.0], [-side, -1, 0, 1, side], shape=(side * side, side * side))
    blocks = sp.kron(sp.eye(2), grid) + 0.1 * sp.kron(sp.csr_matrix([[0, 1], [1, 0]]), sp.eye(side * side))
    return sp.csr_matrix(blocks + sp.diags(np.random.default_rng(seed).uniform(0.2, 0.3, blocks.shape[0])))


def _run_sequence() -> list:
    """What every backend here decides and returns on one sequence: a pattern analysed
    ahead, three matrices of it factorised, solved, and forward columns taken in batches
    (2, 300 and 3 columns) through whichever route the backend chooses."""
    record: list = []
    rng = np.random.default_rng(7)
    for backend in linalg.available_backends():
        for side in (20, 80):
            base = _grid(side, seed=side)
            n = base.shape[0]
            rhs = rng.standard_normal((n, 2))
            factorizer = linalg.Factorizer(backend, name="the test matrix")
            factorizer.analyse(base)
            record.append((backend, side, factorizer.ahead_seconds))
            for shift in (0.0, 0.5, 0.25):
                factor = factorizer.factorize(sp.csr_matrix(base + shift * sp.identity(n)))
                solved = np.asarray(factor.solve(rhs))
                record.append((factorizer.costs[-1], factorizer.analysis_seconds[-1], solved.tobytes()))
                if not callable(getattr(factor, "forward_sparse", None)):
                    continue
                for k in (2, 300, 3):
                    rows = rng.choice(n, size=k, replace=False)
                    columns = sp.csc_matrix((np.ones(k), (rows, np.arange(k))), shape=(n, k))
                    seconds = getattr(factor, "forward_seconds", None)
                    before = (seconds(k), factor._route_seconds(k)) if callable(seconds) else None
                    forward, scaled = factor.forward_sparse(columns)
                    record.append((before, getattr(factor, "route", None), getattr(factor, "setup_seconds", None),
                                   forward.indptr.tobytes(), forward.indices.tobytes(), forward.data.tobytes(),
                                   scaled.data.tobytes()))
            record.append((factorizer.seconds, factorizer.costs))
    return record


def _erratic_clock(seed: int):
    """A clock that jumps about: a random walk with steps of either sign, up to a second."""
    state = {"now": 1000.0, "rng": np.random.default_rng(seed)}

    def clock() -> float:
        state["now"] += float(state["rng"].uniform(-1.0, 1.0))
        return state["now"]

    return clock


@pytest.mark.parametrize("switch", [0, 2], ids=["simplicial-first", "supernodal"])
def test_decisions_and_solutions_do_not_depend_on_the_clock(monkeypatch, switch):
    """Run the sequence with the real clock, then with every clock of the time module
    replaced by an erratic random walk: the forward routes chosen, the modelled seconds,
    the counted costs and every solution are bit-identical."""
    if registry.installed("cvxopt") and cholmod_ctypes.cholmod_library() is not None:
        monkeypatch.setattr(cholmod_ctypes, "_FACTOR_SWITCH", switch)
    elif switch:
        pytest.skip("the kind of factor is chosen only in the library called directly")
    steady = _run_sequence()
    for name in ("perf_counter", "monotonic", "process_time", "time"):
        monkeypatch.setattr(time, name, _erratic_clock(len(name)))
        monkeypatch.setattr(time, f"{name}_ns", lambda: 0)
    erratic = _run_sequence()
    monkeypatch.undo()
    assert erratic == steady
    routes = [entry[1] for entry in steady if len(entry) == 7 and entry[1] is not None]
    if routes:  # CHOLMOD called directly: several routes were taken, as the counts chose
        assert len(set(routes)) >= 2 and set(routes) <= {"blocked", "pattern", "supernodal"}
        # A supernodal factor's own blocks serve while it is supernodal (the supernodal run's
        # first factorisations).
        assert ("supernodal" in routes) is (switch == 2)


def clock_reads(source: str) -> list[str]:
    """Where ``source`` imports the time module's clocks or reads one (``time.perf_counter``,
    ``from time import monotonic``, ``import time``), as "line: what"."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [f"{node.lineno}: import {a.name}" for a in node.names if a.name == "time"]
        elif isinstance(node, ast.ImportFrom) and node.module == "time":
            found += [f"{node.lineno}: from time import {a.name}" for a in node.names]
        elif isinstance(node, ast.Attribute) and node.attr.removesuffix("_ns") in CLOCKS - {"time"}:
            found.append(f"{node.lineno}: .{node.attr}")
        elif (isinstance(node, ast.Attribute) and node.attr.removesuffix("_ns") == "time"
              and isinstance(node.value, ast.Name) and node.value.id == "time"):
            found.append(f"{node.lineno}: time.{node.attr}")
    return found


def test_no_module_of_linalg_reads_a_clock():
    """No module under contactfem/linalg imports the time module or reads a clock: costs
    are counted and turned into seconds by the rates of costs.py alone."""
    modules = sorted(PACKAGE.rglob("*.py"))
    assert len(modules) >= 10
    reads = {str(path.relative_to(PACKAGE)): clock_reads(path.read_text(encoding="utf-8")) for path in modules}
    assert {name: found for name, found in reads.items() if found} == {}


@pytest.mark.parametrize("source", [
    "import time\n",
    "from time import perf_counter\n",
    "import time as t\nt.perf_counter()\n",
    "x = clock.monotonic_ns()\n",
    "import time\ntime.time()\n",
    "import os\nos.times().process_time\n",
])
def test_the_clock_check_finds_each_way_of_reading_one(source):
    assert clock_reads(source)


def test_the_clock_check_leaves_other_code_alone():
    assert clock_reads("import numpy as np\nseconds = cost.entries / rate\nx = np.linalg.solve(a, b)\n") == []
