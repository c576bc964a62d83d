"""The same case gives the same Newton path and bit-identical results whatever the clock says.

No decision of the solver may come from the wall clock: the cost model that chooses
between Schur updates and refactorisation counts work (:mod:`contactfem.kernel.costs`),
and the clock is read only for reported seconds (:mod:`contactfem.timings`). A busy
machine is imitated by a clock that jumps erratically; the results must not move by a bit.
"""

from __future__ import annotations

import ast
import itertools
import time
from pathlib import Path

import numpy as np
import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "contactfem"
CLOCKS = {"perf_counter", "time", "monotonic", "process_time", "perf_counter_ns", "monotonic_ns", "time_ns"}


def _erratic_clock():
    """A clock whose steps are random: from microseconds to seconds, as on a loaded machine."""
    rng = np.random.default_rng(11)
    now = itertools.accumulate(rng.lognormal(mean=-6.0, sigma=4.0, size=1_000_000))
    return lambda: next(now)


def _solve(case, method):
    from contactfem.solve import solve_case

    result = solve_case(case, method=method)
    kernel = result.kernel
    path = [(r.active, r.added, r.removed, r.proposed, r.proposer) for r in kernel.history]
    return kernel, path, result.sequencing


@pytest.mark.parametrize("method", ["positive", "standard"])
@pytest.mark.parametrize("name", ["rough", "hertz_platen"])
def test_a_solve_is_bit_identical_under_an_erratic_clock(monkeypatch, name, method):
    """cases/rough.yaml (sequencing, Schur updates, zone fronts) and the Hertz platen (a body
    pushed by a prescribed advance): solved with the real clock and with one that jumps by
    up to seconds between reads, the displacement, the multiplier, the active set, the
    Newton path and the factorisations are identical to the last bit."""
    from conftest import shipped_case

    import contactfem.timings as timings

    case = shipped_case(name)
    quiet, quiet_path, _ = _solve(case, method)
    clock = _erratic_clock()
    monkeypatch.setattr(time, "perf_counter", clock)
    monkeypatch.setattr(timings, "clock", clock)
    busy, busy_path, _ = _solve(case, method)
    assert busy_path == quiet_path
    assert (busy.factorizations, busy.column_solves) == (quiet.factorizations, quiet.column_solves)
    assert np.array_equal(busy.active, quiet.active)
    assert busy.displacement.tobytes() == quiet.displacement.tobytes()
    assert busy.multiplier.tobytes() == quiet.multiplier.tobytes()


def _clock_reads(path: Path) -> list[str]:
    """Where a module reads the clock: ``time.<clock>`` attributes and ``from time import``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr in CLOCKS and isinstance(node.value, ast.Name) \
                and node.value.id == "time":
            found.append(f"{path.name}:{node.lineno}")
        elif isinstance(node, ast.ImportFrom) and node.module == "time":
            found.append(f"{path.name}:{node.lineno}")
    return found


@pytest.mark.parametrize("package", ["kernel", "linalg"])
def test_the_solver_never_reads_the_clock(package):
    """The kernel and the linear solvers read no clock: their decisions come from counts.
    Seconds a step reports come from contactfem.timings, which nothing decides from."""
    root = PACKAGE / package
    files = sorted(root.rglob("*.py")) if root.is_dir() else [PACKAGE / f"{package}.py"]
    reads = [read for path in files for read in _clock_reads(path)]
    assert reads == []


#: The two modules that read the clock: the reported seconds and the progress lines' times.
CLOCK_READERS = ("timings.py", "progress.py")


def test_the_clock_is_read_only_for_reported_seconds_and_progress():
    """Every other module of the package takes its seconds from contactfem.timings.clock, so
    that a read of the clock is visible where it is made and nothing else depends on it."""
    files = [path for path in sorted(PACKAGE.rglob("*.py")) if str(path.relative_to(PACKAGE)) not in CLOCK_READERS]
    reads = [read for path in files for read in _clock_reads(path)]
    assert reads == []
