"""The residual estimator of method (4): zero for an exact P1 solution, reliable and efficient."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import shipped_case
from test_norms import DELTA, LinearCompression, compression_case

from contactfem.estimator import TERM_NAMES, estimate
from contactfem.report import exact_errors
from contactfem.solve import prepare, solve_case


def test_estimator_vanishes_for_an_exact_p1_solution():
    """The compressed block: linear exact solution, consistent data (rollers, free side,
    uniform pressure, all nodes in contact), so every residual is round-off."""
    case = compression_case(4)
    problem = prepare(case)
    outcome = solve_case(case, method="positive", problem=problem)
    result = estimate(problem, outcome.solution)
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
        estimate(problem, outcome.solution)


def test_effectivity_is_bounded_on_the_manufactured_case():
    """η / true energy error over three uniform levels stays in a narrow band (about 7.2),
    and η decreases like the error (rate 1 in h)."""
    case = shipped_case("manufactured")
    case = replace(case, mesh=replace(case.mesh, divisions=(8, 4)))
    etas, errors = [], []
    for level in range(3):
        problem = prepare(case, refine=level)
        outcome = solve_case(case, method="positive", problem=problem)
        result = estimate(problem, outcome.solution)
        etas.append(result.total)
        errors.append(exact_errors(problem, outcome.solution)["displacement_energy"])
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
    result = estimate(problem, outcome.solution)
    term = result.terms["complementarity"]
    assert np.all(term >= 0)
    carriers = np.flatnonzero(term > 0)
    assert 1 <= len(carriers) <= 4


def test_a_symmetry_line_contributes_its_tangential_residual_only():
    """On a symmetry line u·n_s = 0 is imposed, so −n_s·σν is the support's reaction, not an
    error: the Neumann residual there is h_E² |t·σ_T ν|² / (2μ), with t the line's tangent.
    The reaction itself is far from zero here, so counting it would show."""
    from conftest import case_from, square_case_dict

    data = square_case_dict(8)
    data["boundary"] = {"left": "symmetry", "top": {"traction": [2.0e3, "-1e4*(1+x)"]},
                        "right": {"displacement": [None, 0.0]}, "bottom": "contact"}
    case = case_from(data)
    problem = prepare(case)
    outcome = solve_case(case, method="positive", problem=problem)
    result = estimate(problem, outcome.solution)

    mesh = problem.mesh
    left = mesh.edges_of("left")
    triangle = mesh.topology.edge_triangles[mesh.topology.edge_index(left[:, 0], left[:, 1])].max(axis=1)
    # Triangles whose only natural-boundary edge is on the symmetry line.
    natural_triangles = mesh.topology.edge_triangles[
        mesh.topology.edge_index(*problem.loads.natural.edges.T)].max(axis=1)
    alone = np.bincount(natural_triangles, minlength=mesh.n_triangles)[triangle] == 1
    length = np.linalg.norm(mesh.points[left[:, 1]] - mesh.points[left[:, 0]], axis=1)
    sxx, syy, sxy = outcome.solution.stress[triangle, :3].T
    tangential = sxy  # t = (0, ±1), ν = (−1, 0): t·σν = ∓σ_xy
    normal = sxx
    scale = 1 / (2 * problem.law.mu)
    expected = scale * length**2 * tangential**2
    np.testing.assert_allclose(result.terms["neumann"][triangle[alone]], expected[alone], rtol=1e-12)
    reaction = scale * length**2 * normal**2
    assert reaction[alone].sum() > 10 * expected[alone].sum()
