"""The residual estimator of method (4): zero for an exact P1 solution, reliable and efficient."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from conftest import shipped_case
from contactfem.estimator import TERM_NAMES, estimate
from contactfem.solve import prepare, solve_case
from test_norms import DELTA, LinearCompression, compression_case


def test_estimator_vanishes_for_an_exact_p1_solution():
    """The compressed block: linear exact solution, consistent data (rollers, free side,
    uniform pressure, all nodes in contact), so every residual is round-off."""
    case = compression_case(4)
    problem = prepare(case)
    outcome = solve_case(case, method="positive", problem=problem)
    result = estimate(case, problem, outcome.solution)
    exact = LinearCompression(problem.law.lam, problem.law.mu)
    energy_scale = np.sqrt(exact.p * DELTA * 2.0)  # a(u, u)^½ of the block, order of magnitude
    assert set(result.terms) == set(TERM_NAMES)
    assert result.indicators.shape == (problem.mesh.n_triangles,)
    assert result.total <= 1e-10 * energy_scale
    assert np.all(result.indicators >= 0)


def test_estimator_refuses_the_standard_method():
    case = compression_case(2)
    problem = prepare(case)
    outcome = solve_case(case, method="standard", problem=problem)
    with pytest.raises(ValueError, match="method"):
        estimate(case, problem, outcome.solution)


def test_effectivity_is_bounded_on_the_manufactured_case():
    """η / true energy error over three uniform levels stays in a narrow band (about 7.2),
    and η decreases like the error (rate 1 in h)."""
    case = shipped_case("manufactured")
    case = replace(case, mesh=replace(case.mesh, divisions=(8, 4)))
    etas, errors = [], []
    for level in range(3):
        problem = prepare(case, refine=level)
        outcome = solve_case(case, method="positive", problem=problem)
        result = estimate(case, problem, outcome.solution)
        etas.append(result.total)
        errors.append(outcome.report["errors"]["displacement_energy"])
        assert result.summary()["terms"]["complementarity"] >= 0
    effectivity = np.array(etas) / np.array(errors)
    assert np.all((effectivity > 1.0) & (effectivity < 20.0)), effectivity
    assert effectivity.max() / effectivity.min() < 1.2, effectivity
    rates = np.log2(np.array(etas[:-1]) / np.array(etas[1:]))
    assert np.all(np.abs(rates - 1.0) < 0.1), rates


def test_complementarity_term_lives_on_transition_edges():
    """∫ λ_h (g0 − u_hn) ≥ 0 is nonzero only on ΓC edges joining an active and an inactive node."""
    case = shipped_case("square")
    case = replace(case, mesh=replace(case.mesh, divisions=(16, 16)))
    problem = prepare(case)
    outcome = solve_case(case, method="positive", problem=problem)
    result = estimate(case, problem, outcome.solution)
    term = result.terms["complementarity"]
    assert np.all(term >= 0)
    carriers = np.flatnonzero(term > 0)
    assert 1 <= len(carriers) <= 4
