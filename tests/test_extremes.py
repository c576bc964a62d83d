"""Stability at the extremes, the fast subset of benchmarks/extremes.py (the full set runs there).

Each case goes through ``contactfem solve``; a solved case must converge within its cap,
satisfy the sign conditions and equilibrium relative to its data, and write only finite
numbers (every file read back); a refused one exits 2 with one line naming the key.
Across cases: E with proportional loads and the load scale leave the normalised solution
and the iteration count unchanged; the rotated square gives the rotated displacement.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import extremes  # noqa: E402

CASES = extremes.catalogue(fast=True)


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory):
    directory = tmp_path_factory.mktemp("extremes")
    return {case.name: extremes.run_case(case, directory / f"case{i}") for i, case in enumerate(CASES)}


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_case_solves_or_is_refused(case, outcomes):
    outcome = outcomes[case.name]
    assert outcome.status == ("refused" if case.refuse or case.unsolvable else "solved"), outcome.detail


def test_scale_and_rotation_invariance(outcomes):
    assert extremes.compare_groups(list(outcomes.values()), CASES) == []


def test_locking_warning_only_past_the_threshold(outcomes):
    solved = {name: o for name, o in outcomes.items() if o.status == "solved"}
    warned = {name for name, o in solved.items() if any(w.startswith("nearly incompressible")
                                                        for w in o.figures["warnings"])}
    assert warned == {"nu=0.4999"}


def test_the_untouched_warning_exactly_where_no_node_touches(outcomes):
    """The report warns that nothing touched on the scenes whose contact zone is empty
    (the body lifted off, the obstacle far below), and only there."""
    solved = {name: o for name, o in outcomes.items() if o.status == "solved"}
    untouched = {name for name, o in solved.items() if o.figures["active_nodes"] == 0}
    warned = {name for name, o in solved.items() if any(w.startswith("no contact node touches the obstacle")
                                                        for w in o.figures["warnings"])}
    assert warned == untouched and {"full lift-off", "far obstacle"} <= untouched


@pytest.mark.slow
def test_full_extremes_set():
    results = extremes.run(fast=False, largest=256)
    assert results["counts"]["failed"] == 0, [c for c in results["cases"] if c["status"] == "failed"]
    assert results["cross_checks"] == []
