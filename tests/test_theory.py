"""What the paper proves, checked on discrete solutions of both methods.

- Proposition 2.1: method (4) gives λh ≥ 0 and u_hn ≤ g at the nodes, with λh (u_hn − g) = 0.
- Method (5): only (M θ)_x ≥ 0; θ may be negative near lift-off.
- Proposition 2.2: the two displacements agree and λh = D⁻¹ M θh (= πh θh).
- Equilibrium: applied loads + contact force + reactions = 0, since K annihilates rigid motions.
- Scale invariance: E and all loads times 1e6 leave u and the Newton iterations unchanged.
- An independent solver (NNLS on the condensed problem of method 4, SLSQP on method 5's
  own QP in θ) reproduces the kernel's multipliers.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize as so
from conftest import case_from, shipped_case, square_case_dict

from contactfem.methods import get_method
from contactfem.report import equilibrium
from contactfem.solve import prepare, solve_case


def square(divisions: int, **changes):
    data = square_case_dict(divisions)
    data["mesh"].update(changes)
    return case_from(data)


CASES = {
    "square-8": lambda: square(8),
    "square-16-left": lambda: square(16, diagonal="left"),
    "square-24-crossed": lambda: square(24, diagonal="crossed"),
    "hole": lambda: shipped_case("hole"),
    "hertz": lambda: shipped_case("hertz"),
    "punch": lambda: shipped_case("punch"),
    "punch-coarse": lambda: coarse_punch(),
}


def coarse_punch():
    """The shipped punch (slanted obstacle, gap, one free displacement component) on a 10 x 5 mesh."""
    import yaml

    data = yaml.safe_load(shipped_case("punch").text)
    data["mesh"]["divisions"] = [10, 5]
    return case_from(data)


@pytest.fixture(scope="module", params=list(CASES))
def both_methods(request):
    case = CASES[request.param]()
    problem = prepare(case)
    return {name: solve_case(case, method=name, problem=problem) for name in ("positive", "standard")}


def test_positive_method_sign_conditions_hold_at_the_nodes(both_methods):
    """λ ≥ 0, u_n ≤ g and λ (u_n − g) = 0 at every contact node, to 1e-12 relative."""
    contact = both_methods["positive"].solution.contact
    slack = contact.normal_displacement - contact.gap
    force_scale = np.abs(contact.multiplier).max()
    gap_scale = max(np.abs(slack).max(), np.abs(contact.normal_displacement).max())
    assert contact.multiplier.min() >= -1e-12 * force_scale
    assert slack.max() <= 1e-12 * gap_scale
    assert np.abs(contact.multiplier * slack).max() <= 1e-12 * force_scale * gap_scale


def test_standard_method_is_only_weakly_positive(both_methods):
    """(M θ)_x ≥ 0 and complementary with u_n − g; u_n ≤ g, all to 1e-12 relative."""
    contact = both_methods["standard"].solution.contact
    slack = contact.normal_displacement - contact.gap
    force_scale = np.abs(contact.nodal_force).max()
    gap_scale = max(np.abs(slack).max(), np.abs(contact.normal_displacement).max())
    assert contact.nodal_force.min() >= -1e-12 * force_scale
    assert slack.max() <= 1e-12 * gap_scale
    assert np.abs(contact.nodal_force * slack).max() <= 1e-12 * force_scale * gap_scale


def test_square_standard_multiplier_dips_below_zero():
    """On the square the body lifts off inside ΓC; θh oscillates there and goes negative,
    while λh stays ≥ 0 (the point of method (4))."""
    case = square(16)
    problem = prepare(case)
    theta = solve_case(case, method="standard", problem=problem).solution.contact.multiplier
    lam = solve_case(case, method="positive", problem=problem).solution.contact.multiplier
    assert theta.min() < -1e-3 * theta.max()
    assert lam.min() >= -1e-12 * lam.max()


def test_proposition_2_2_same_displacement_and_lambda_is_pi_h_theta(both_methods):
    """u_h = w_h to 1e-10 relative, and λ = D⁻¹ M θ to 1e-10 relative."""
    positive, standard = both_methods["positive"], both_methods["standard"]
    u, w = positive.solution.displacement, standard.solution.displacement
    assert np.abs(u - w).max() <= 1e-10 * np.abs(u).max()
    masses = positive.problem.contact.masses
    pi_theta = (masses.consistent @ standard.solution.contact.multiplier) / masses.lumped
    lam = positive.solution.contact.multiplier
    assert np.abs(lam - pi_theta).max() <= 1e-10 * np.abs(lam).max()


def test_equilibrium_of_forces_and_moments(both_methods):
    """Applied loads + obstacle force + support reactions balance to 1e-10 relative."""
    for outcome in both_methods.values():
        balance = equilibrium(outcome.problem, outcome.solution.displacement, outcome.solution.contact.nodal_force)
        assert balance["relative_force_residual"] <= 1e-10
        assert balance["relative_moment_residual"] <= 1e-10


def condensed(outcome):
    """The contact problem reduced to the normal unknowns: d = d0 − S (B μ), S = P K⁻¹ Pᵀ."""
    system = outcome.problem.contact_system(get_method(outcome.solution.method)).system
    full = system.stiffness.toarray()
    free = np.setdiff1d(np.arange(full.shape[0]), system.fixed_dofs)
    k = full[np.ix_(free, free)]
    load = system.load[free] - full[np.ix_(free, system.fixed_dofs)] @ system.fixed_values
    position = np.full(full.shape[0], -1)
    position[free] = np.arange(len(free))
    pick = np.zeros((len(system.normal_dofs), len(free)))
    pick[np.arange(len(system.normal_dofs)), position[system.normal_dofs]] = 1.0
    schur = pick @ np.linalg.solve(k, pick.T)
    d0 = pick @ np.linalg.solve(k, load)
    return schur, d0, system.gap, system.multiplier_mass.toarray()


SMALL = ["square-8", "punch-coarse"]


@pytest.mark.parametrize("name", SMALL)
def test_positive_method_matches_nonnegative_least_squares(name):
    """Method (4) condensed is min ½ λᵀ(DSD)λ − λᵀD(d0 − G) over λ ≥ 0; with DSD = RᵀR this is
    the NNLS problem min ‖Rλ − R⁻ᵀ D(d0 − G)‖, which scipy's Lawson–Hanson active set
    solves independently of our kernel. Agreement to 1e-8 relative."""
    outcome = solve_case(CASES[name](), method="positive")
    schur, d0, gap, lumped = condensed(outcome)
    a = lumped @ schur @ lumped
    b = lumped @ (d0 - gap)
    r = np.linalg.cholesky(a).T
    lam, _ = so.nnls(r, np.linalg.solve(r.T, b))
    kernel = outcome.solution.contact.multiplier
    assert np.abs(lam - kernel).max() <= 1e-8 * np.abs(lam).max()


@pytest.mark.parametrize("name", SMALL)
def test_standard_method_matches_sequential_quadratic_programming(name):
    """Method (5) in its own unknown θ: min ½ θᵀ(MSM)θ − θᵀM(d0 − G) subject to M θ ≥ 0
    (general linear constraints, not bounds), solved by SLSQP. SLSQP alone is not accurate
    on this ill-conditioned QP, so its answer only names the rows where M θ = 0 binds; the
    QP with those rows as equalities is solved exactly, and the result is certified
    optimal by the KKT conditions (Mθ ≥ 0, constraint multipliers ν ≥ 0, Aθ − b = Mᵀν)
    without reference to our kernel. θ then agrees with the kernel's to 1e-8 relative."""
    outcome = solve_case(CASES[name](), method="standard")
    schur, d0, gap, mass = condensed(outcome)
    a = mass @ schur @ mass
    b = mass @ (d0 - gap)
    result = so.minimize(
        lambda t: 0.5 * t @ a @ t - b @ t, np.zeros(len(b)), jac=lambda t: a @ t - b, method="SLSQP",
        constraints=[{"type": "ineq", "fun": lambda t: mass @ t, "jac": lambda t: mass}],
        options={"ftol": 1e-12, "maxiter": 1000},
    )
    assert result.success
    forces = mass @ result.x
    inactive = forces <= 1e-6 * forces.max()  # rows where M θ = 0 holds as an equality
    rows = mass[inactive]
    kkt = np.block([[a, rows.T], [rows, np.zeros((len(rows), len(rows)))]])
    solution = np.linalg.solve(kkt, np.concatenate([b, np.zeros(len(rows))]))
    theta, nu = solution[: len(b)], -solution[len(b):]
    force_scale = np.abs(mass @ theta).max()
    assert (mass @ theta).min() >= -1e-12 * force_scale
    assert nu.min(initial=0.0) >= -1e-10 * np.abs(nu).max(initial=1.0)
    kernel = outcome.solution.contact.multiplier
    assert np.abs(theta - kernel).max() <= 1e-8 * np.abs(theta).max()


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_scale_invariance(method):
    """E and every load multiplied by 1e6: same Newton iterations and active sets, the same
    displacement to 1e-10 relative, multipliers scaled by 1e6."""
    base_data = square_case_dict(16)
    scaled_data = square_case_dict(16)
    scaled_data["material"]["E"] = 1.0e12
    scaled_data["boundary"]["top"] = {"traction": [1.0e10, "-1e10*(1-1.5*x)"]}
    base = solve_case(case_from(base_data), method=method)
    scaled = solve_case(case_from(scaled_data), method=method)
    assert scaled.kernel.iterations == base.kernel.iterations
    assert [r.active for r in scaled.kernel.history] == [r.active for r in base.kernel.history]
    u, v = base.solution.displacement, scaled.solution.displacement
    assert np.abs(u - v).max() <= 1e-10 * np.abs(u).max()
    lam, mu = base.solution.contact.multiplier, scaled.solution.contact.multiplier
    assert np.abs(mu - 1e6 * lam).max() <= 1e-10 * np.abs(1e6 * lam).max()


def test_every_installed_backend_gives_the_same_solution():
    """SuperLU, CHOLMOD and Pardiso factorise the same SPD matrices: solutions agree to 1e-10."""
    from contactfem.linalg import available_backends

    case = square(16)
    problem = prepare(case)
    results = {
        name: solve_case(case.with_solver(backend=name), method="positive", problem=problem)
        for name in available_backends()
    }
    reference = results["superlu"].solution.displacement
    for name, outcome in results.items():
        assert outcome.backend == name
        assert np.abs(outcome.solution.displacement - reference).max() <= 1e-10 * np.abs(reference).max()
