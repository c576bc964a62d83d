"""The active set kernel on complementarity problems small enough to solve by hand.

Each problem is K u + B μ = F, Bμ ≥ 0, u − G ≤ 0, (Bμ)(u − G) = 0 with every unknown a
contact unknown (normal_dofs = all). The solutions in the docstrings are derived by
guessing the contact set, solving the linear system and checking both sign conditions.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from contactfem.kernel import ContactSystem, Status, solve_contact
from contactfem.linalg import available_backends


def system(k, f, g, b=None) -> ContactSystem:
    k = np.atleast_2d(np.asarray(k, dtype=float))
    n = k.shape[0]
    b = np.eye(n) if b is None else np.asarray(b, dtype=float)
    return ContactSystem(
        stiffness=sp.csr_matrix(k), load=np.asarray(f, dtype=float), normal_dofs=np.arange(n),
        gap=np.asarray(g, dtype=float), multiplier_mass=sp.csr_matrix(b),
    )


@pytest.mark.parametrize("backend", available_backends())
@pytest.mark.parametrize(
    "k, f, g, u, mu",
    [
        # one spring, free: 2u = 1 gives u = 0.5 < g = 1, no force.
        (2.0, [1.0], [1.0], [0.5], [0.0]),
        # one spring pushed past the gap: u = g = 1, μ = f − k g = 4 − 2 = 2.
        (2.0, [4.0], [1.0], [1.0], [2.0]),
        # negative gap (overlap), no load: the obstacle pushes the node out to u = −1, μ = 2.
        (2.0, [0.0], [-1.0], [-1.0], [2.0]),
        # unloaded spring resting on the obstacle: u = 0, μ = 0 (degenerate, both zero).
        (2.0, [0.0], [0.0], [0.0], [0.0]),
    ],
)
def test_one_unknown(backend, k, f, g, u, mu):
    result = solve_contact(system(k, f, g), backend=backend)
    assert result.status is Status.CONVERGED
    np.testing.assert_allclose(result.displacement, u, atol=1e-14)
    np.testing.assert_allclose(result.multiplier, mu, atol=1e-14)


def test_two_coupled_unknowns_one_in_contact():
    """K = [[2,−1],[−1,2]], F = (1, −1), G = 0.

    Free solution K⁻¹F = (1/3, −1/3) violates u1 ≤ 0. With u1 = 0: 2 u2 = −1, u2 = −1/2 ≤ 0,
    and μ1 = F1 − (K u)1 = 1 − 1/2 = 1/2 ≥ 0. From the empty start, the free solution
    penetrates at node 1 only, which becomes active: two solves, the second repeating its set.
    """
    result = solve_contact(system([[2, -1], [-1, 2]], [1, -1], [0, 0]))
    assert result.status is Status.CONVERGED
    np.testing.assert_allclose(result.displacement, [0.0, -0.5], atol=1e-14)
    np.testing.assert_allclose(result.multiplier, [0.5, 0.0], atol=1e-14)
    np.testing.assert_array_equal(result.active, [True, False])
    assert result.iterations == 2


def test_consistent_mass_gives_a_negative_multiplier():
    """K = I, F = (1, −1), G = 0, B = [[2, 1], [1, 2]] (a consistent mass).

    Node 1 is pushed in: u1 = 0, (Bμ)1 = 1; node 2 is pulled out: u2 = −1, (Bμ)2 = 0.
    So μ = B⁻¹(1, 0) = (2/3, −1/3): the nodal forces are ≥ 0 while μ2 < 0, the weak
    positivity of the standard method.
    """
    result = solve_contact(system(np.eye(2), [1, -1], [0, 0], b=[[2, 1], [1, 2]]))
    assert result.status is Status.CONVERGED
    np.testing.assert_allclose(result.displacement, [0.0, -1.0], atol=1e-14)
    np.testing.assert_allclose(result.multiplier, [2 / 3, -1 / 3], atol=1e-14)
    np.testing.assert_allclose(result.nodal_force, [1.0, 0.0], atol=1e-14)


def test_four_unknown_chain_touching_at_its_end():
    """K = tridiag(−1, 2, −1) of size 4, F = (0, 0, 0, 5), G = (10, 10, 10, 1).

    Free solution K⁻¹F = (1, 2, 3, 4) violates u4 ≤ 1. With u4 = 1 the first three solve
    tridiag(−1,2,−1) u = (0, 0, 1): u = (1/4, 1/2, 3/4), all below 10, and
    μ4 = 5 − (−3/4 + 2) = 15/4 ≥ 0.
    """
    k = 2 * np.eye(4) - np.eye(4, k=1) - np.eye(4, k=-1)
    result = solve_contact(system(k, [0, 0, 0, 5], [10, 10, 10, 1]))
    assert result.status is Status.CONVERGED
    np.testing.assert_allclose(result.displacement, [0.25, 0.5, 0.75, 1.0], atol=1e-14)
    np.testing.assert_allclose(result.multiplier, [0, 0, 0, 3.75], atol=1e-14)


def test_three_unknowns_with_a_non_contact_unknown():
    """Unknowns (u0, u1, v): only u0, u1 are contact unknowns; v is an ordinary unknown.

    K = [[2,0,−1],[0,2,−1],[−1,−1,2]], F = (0, 0, 4), G = (0.5, 0.5). Free solution:
    v = 4, u0 = u1 = 2 > 0.5. Both active: u0 = u1 = 0.5, then 2 v = 4 + 1 gives v = 2.5
    and μ_i = 0 − (2·0.5 − 2.5) = 1.5 ≥ 0.
    """
    k = np.array([[2.0, 0, -1], [0, 2, -1], [-1, -1, 2]])
    sys3 = ContactSystem(
        stiffness=sp.csr_matrix(k), load=np.array([0.0, 0.0, 4.0]), normal_dofs=np.array([0, 1]),
        gap=np.array([0.5, 0.5]), multiplier_mass=sp.identity(2, format="csr"),
    )
    result = solve_contact(sys3)
    assert result.status is Status.CONVERGED
    np.testing.assert_allclose(result.displacement, [0.5, 0.5, 2.5], atol=1e-14)
    np.testing.assert_allclose(result.multiplier, [1.5, 1.5], atol=1e-14)


def test_iteration_cap_is_reported_not_raised():
    """Two solves are needed above; a cap of one returns MAX_ITERATIONS with the last iterate."""
    result = solve_contact(system([[2, -1], [-1, 2]], [1, -1], [0, 0]), max_iterations=1)
    assert result.status is Status.MAX_ITERATIONS
    assert result.iterations == 1


def test_scaling_forces_scales_multiplier_and_keeps_iterations():
    """Multiplying K and F by 1e6 leaves u and the active sets unchanged and scales μ by 1e6 (c follows K)."""
    k = 2 * np.eye(4) - np.eye(4, k=1) - np.eye(4, k=-1)
    base = solve_contact(system(k, [0, 0, 0, 5], [10, 10, 10, 1]))
    scaled = solve_contact(system(1e6 * k, [0, 0, 0, 5e6], [10, 10, 10, 1]))
    assert scaled.iterations == base.iterations
    np.testing.assert_allclose(scaled.displacement, base.displacement, rtol=1e-14)
    np.testing.assert_allclose(scaled.multiplier, 1e6 * base.multiplier, rtol=1e-14)


# A 6x6 SPD problem found by random search on which plain primal–dual active set Newton,
# started from the given set, revisits the set of its second iteration.
CYCLING_K = np.array([
    [25.754986512629742, 7.4932091971787109, -40.297945114623886, 27.710624293007012, -1.4584316650516906, -51.714593656474598],
    [7.4932091971787109, 112.63505729996257, 47.148759191137984, 95.766680099624523, -42.171685762874944, -6.8675841457324251],
    [-40.297945114623886, 47.148759191137984, 95.337588611063339, 3.2174016195704485, -20.270118340963023, 86.069878400898091],
    [27.710624293007012, 95.766680099624523, 3.2174016195704485, 100.63085557546876, -35.252021766792915, -50.196152640137697],
    [-1.4584316650516906, -42.171685762874944, -20.270118340963023, -35.252021766792915, 16.295893625765757, 0.071491779557255969],
    [-51.714593656474598, -6.8675841457324251, 86.069878400898091, -50.196152640137697, 0.071491779557255969, 105.89250379729128],
])
CYCLING_F = np.array([4.534143132567809, -3.772803403363463, -3.4495549395958176, -8.786958075467437, -0.3164404899390113, 6.1533433031949425])
CYCLING_G = np.array([0.6304053218256808, 0.2624465907021045, -0.13613884828772888, 0.6014324497226521, 0.8696762949359567, -0.3851143409839568])
CYCLING_START = np.array([True, True, True, False, False, False])


def test_plain_newton_cycles_and_says_so():
    """Without the safeguard the kernel stops at the first repeated set with status CYCLING
    (instead of running to the iteration cap)."""
    result = solve_contact(system(CYCLING_K, CYCLING_F, CYCLING_G), initial_active=CYCLING_START,
                           safeguard=False, max_iterations=100)
    assert result.status is Status.CYCLING
    assert "cycles" in result.message
    assert result.iterations < 10


def test_safeguard_resolves_the_cycle_to_the_complementarity_solution():
    """With the least-index safeguard the same start converges, and the answer satisfies the
    conditions directly: K u + μ = F, μ ≥ 0, u ≤ G, μ (u − G) = 0 (to 1e-12 relative)."""
    result = solve_contact(system(CYCLING_K, CYCLING_F, CYCLING_G), initial_active=CYCLING_START,
                           max_iterations=100)
    assert result.status is Status.CONVERGED
    assert result.cycle_detected_at is not None
    assert "least-index" in result.message
    u, mu = result.displacement, result.multiplier
    scale = np.abs(CYCLING_F).max()
    assert np.abs(CYCLING_K @ u + mu - CYCLING_F).max() <= 1e-12 * scale
    assert mu.min() >= -1e-12 * scale
    assert (u - CYCLING_G).max() <= 1e-12 * np.abs(u).max()
    assert np.abs(mu * (u - CYCLING_G)).max() <= 1e-12 * scale * np.abs(u).max()


@pytest.mark.parametrize("start", [None, "empty"])
def test_safeguard_changes_nothing_on_an_easy_problem(start):
    """On the chain problem plain Newton converges; the safeguard never engages and the
    iterates are identical with it on or off."""
    k = 2 * np.eye(4) - np.eye(4, k=1) - np.eye(4, k=-1)
    initial = None if start is None else np.zeros(4, dtype=bool)
    on = solve_contact(system(k, [0, 0, 0, 5], [10, 10, 10, 1]), initial_active=initial)
    off = solve_contact(system(k, [0, 0, 0, 5], [10, 10, 10, 1]), initial_active=initial, safeguard=False)
    assert on.cycle_detected_at is None
    assert [r.active for r in on.history] == [r.active for r in off.history]
    np.testing.assert_array_equal(on.displacement, off.displacement)


# The 4-unknown chain scaled to a stiffness of 1e6: its free solution (1, 2, 3, 4) penetrates
# the obstacle at the last node by 3, so c (d − G) = 3e-6 for c = 1e-6, far below any
# absolute threshold tied to the forces (‖K‖ ‖u‖ ~ 1e7).
CHAIN_K = 1e6 * (2 * np.eye(4) - np.eye(4, k=1) - np.eye(4, k=-1))
CHAIN_F = np.array([0.0, 0.0, 0.0, 5e6])
CHAIN_G = np.array([10.0, 10.0, 10.0, 1.0])


@pytest.mark.parametrize("c", [1e-6, 1.0, 1e6, 1e-6 * 2e6, 1e6 * 2e6])
def test_c_does_not_change_the_answer(c):
    """c = 1e-6, 1, 1e6 (absolute, and relative to the default 2e6): the same active sets,
    iterations and answer, u = (1/4, 1/2, 3/4, 1), μ4 = 3.75e6 (the chain's solution)."""
    reference = solve_contact(system(CHAIN_K, CHAIN_F, CHAIN_G))
    result = solve_contact(system(CHAIN_K, CHAIN_F, CHAIN_G), c=c)
    assert result.status is Status.CONVERGED, result.message
    assert [r.active for r in result.history] == [r.active for r in reference.history]
    np.testing.assert_array_equal(result.active, [False, False, False, True])
    np.testing.assert_allclose(result.displacement, [0.25, 0.5, 0.75, 1.0], rtol=1e-10)
    np.testing.assert_allclose(result.multiplier, [0, 0, 0, 3.75e6], rtol=1e-10, atol=1e-10 * 3.75e6)
    np.testing.assert_allclose(result.displacement, reference.displacement, rtol=1e-10, atol=0)
    assert result.c == c


@pytest.mark.parametrize("factor", [1e-6, 1e6])
@pytest.mark.parametrize("start", [None, "cycling"])
def test_scaling_stiffness_and_loads_keeps_every_active_set(factor, start):
    """K and F times 1e±6: the same sequence of active sets (also through the least-index
    safeguard of the cycling problem), the same u and μ scaled by the factor, to 1e-10."""
    k, f, g, initial = (CHAIN_K, CHAIN_F, CHAIN_G, None) if start is None else (
        CYCLING_K, CYCLING_F, CYCLING_G, CYCLING_START)
    base = solve_contact(system(k, f, g), initial_active=initial, max_iterations=100)
    scaled = solve_contact(system(factor * k, factor * f, g), initial_active=initial, max_iterations=100)
    assert base.status is scaled.status is Status.CONVERGED
    assert [(r.active, r.added, r.removed) for r in scaled.history] == [
        (r.active, r.added, r.removed) for r in base.history]
    np.testing.assert_array_equal(scaled.active, base.active)
    np.testing.assert_allclose(scaled.displacement, base.displacement, rtol=1e-10,
                               atol=1e-10 * np.abs(base.displacement).max())
    np.testing.assert_allclose(scaled.multiplier / factor, base.multiplier, rtol=1e-10,
                               atol=1e-10 * np.abs(base.multiplier).max())


def test_a_finite_element_system_is_independent_of_c_and_of_units():
    """The square of the core issue (16 x 16): c = 1e-6, 1, 1e6 (absolute, the default being
    about 3e6) and 1e±6 times the default, and E with the loads times 1e±6, give the same
    active set and the same answer to 1e-10."""
    from dataclasses import replace

    from conftest import case_from, square_case_dict

    from contactfem.kernel import default_c
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    problem = prepare(case_from(square_case_dict(16)))
    for method in ("positive", "standard"):
        sys_ = problem.contact_system(get_method(method)).system
        base = solve_contact(sys_)
        assert base.status is Status.CONVERGED and 0 < base.active.sum() < len(base.active)
        scale_u = np.abs(base.displacement).max()
        scale_mu = np.abs(base.multiplier).max()
        for c in (1e-6, 1.0, 1e6, 1e-6 * default_c(sys_), 1e6 * default_c(sys_)):
            other = solve_contact(sys_, c=c)
            assert other.status is Status.CONVERGED, other.message
            np.testing.assert_array_equal(other.active, base.active)
            np.testing.assert_allclose(other.displacement, base.displacement, rtol=0, atol=1e-10 * scale_u)
        for factor in (1e-6, 1e6):
            scaled = solve_contact(replace(sys_, stiffness=factor * sys_.stiffness, load=factor * sys_.load))
            assert scaled.status is Status.CONVERGED, scaled.message
            np.testing.assert_array_equal(scaled.active, base.active)
            assert scaled.iterations == base.iterations
            np.testing.assert_allclose(scaled.displacement, base.displacement, rtol=0, atol=1e-10 * scale_u)
            np.testing.assert_allclose(scaled.multiplier / factor, base.multiplier, rtol=0, atol=1e-10 * scale_mu)


def test_converged_results_carry_a_passed_certificate():
    """Every CONVERGED result above comes with its certificate, all checks passed."""
    result = solve_contact(system(CHAIN_K, CHAIN_F, CHAIN_G))
    assert result.status is Status.CONVERGED
    assert result.certificate is not None and result.certificate.passed
    assert set(result.certificate.checks) == {
        "finite", "force_resolution", "equilibrium", "force_sign", "penetration", "complementarity"}


# --- fragmented active sets and the cost of the linear algebra -------------------------------

def alternating_chain(n: int, k0: float = 1.0, k1: float = 4.0, f: float = 1.0, gap: float = 10.0):
    """n = 2p + 1 nodes, each on a ground spring k0 and tied to its neighbours by springs k1,
    all pushed by f towards obstacles at u = 0 (even nodes) and u = ``gap`` (odd nodes).

    Hand solution: every even node touches (u = 0) and every odd node floats at
    u = f / (k0 + 2 k1) < gap, between two fixed neighbours; an even node's contact force
    is f + k1 (u_left + u_right) > 0. So p + 1 patches of one node each, 2p transitions.
    """
    k = (k0 + 2 * k1) * np.eye(n) - k1 * (np.eye(n, k=1) + np.eye(n, k=-1))
    k[0, 0] -= k1
    k[-1, -1] -= k1
    load = np.full(n, f)
    gaps = np.where(np.arange(n) % 2 == 0, 0.0, gap)
    u = np.where(np.arange(n) % 2 == 0, 0.0, f / (k0 + 2 * k1))
    force = np.where(np.arange(n) % 2 == 0, load - k @ u, 0.0)
    return k, load, gaps, u, force


def tridiagonal_mass(n: int) -> np.ndarray:
    """The consistent boundary mass of n nodes spaced 1 apart (the standard method's B)."""
    m = (np.eye(n, k=1) + np.eye(n, k=-1)) / 6 + 2 * np.eye(n) / 3
    m[0, 0] = m[-1, -1] = 1 / 3
    return m


@pytest.mark.parametrize("backend", available_backends())
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_hundreds_of_patches_are_solved_exactly_in_a_few_factorisations(backend, mass):
    """801 nodes, 401 one-node patches: from the cold start the unconstrained solve pushes
    every even node in (the odd ones stay below their gap), the next set is the answer and
    the third step confirms it; at most two factorisations whatever the method's mass."""
    n = 801
    k, f, g, u, force = alternating_chain(n)
    b = np.eye(n) if mass == "lumped" else tridiagonal_mass(n)
    result = solve_contact(system(k, f, g, b=b), backend=backend)
    assert result.status is Status.CONVERGED, result.message
    assert int(result.active[1:].astype(int) @ (~result.active[:-1]).astype(int)) + 1 == 401
    np.testing.assert_allclose(result.displacement, u, atol=1e-12)
    np.testing.assert_allclose(result.nodal_force, force, atol=1e-12)
    assert result.iterations <= 3
    assert result.factorizations <= 2
    assert result.certificate.passed


def test_a_second_guess_is_asked_only_when_the_first_step_does_not_settle():
    """The alternating chain (101 one-node patches). Started from its answer, the first step
    settles and the guess is never asked. Started cold, the guess (the answer with two
    nodes wrong) replaces Newton's update: the first record counts the guess's changes,
    the second step starts from it and Newton corrects the two nodes, to the hand solution.
    A guess of None leaves Newton's own iteration, step for step."""
    n = 201
    k, f, g, u, force = alternating_chain(n)
    answer = np.arange(n) % 2 == 0
    guess = answer.copy()
    guess[[10, 101]] = ~guess[[10, 101]]
    asked: list[int] = []

    def second_guess():
        asked.append(1)
        return guess

    settled = solve_contact(system(k, f, g), initial_active=answer, second_guess=second_guess)
    assert settled.status is Status.CONVERGED and settled.iterations == 1 and not asked

    cold = np.zeros(n, dtype=bool)
    guessed = solve_contact(system(k, f, g), initial_active=cold, second_guess=second_guess)
    assert asked == [1]
    assert guessed.status is Status.CONVERGED, guessed.message
    assert (guessed.history[0].added, guessed.history[0].removed) == (int(guess.sum()), 0)
    assert guessed.history[1].active == int(guess.sum())
    np.testing.assert_array_equal(guessed.active, answer)
    np.testing.assert_allclose(guessed.displacement, u, atol=1e-12)
    np.testing.assert_allclose(guessed.nodal_force, force, atol=1e-12)

    plain = solve_contact(system(k, f, g), initial_active=cold)
    unguessed = solve_contact(system(k, f, g), initial_active=cold, second_guess=lambda: None)
    assert [step.active for step in unguessed.history] == [step.active for step in plain.history]
    np.testing.assert_array_equal(unguessed.active, plain.active)


def test_a_start_a_few_nodes_off_costs_columns_not_factorisations():
    """Started from the answer with 3 nodes flipped (6 transitions moved), the kernel solves
    the 3 changes through the Schur complement of its first factorisation (one column each)
    when the measured costs say columns are cheaper."""
    from contactfem.kernel import ActiveSetSolver

    n = 401
    k, f, g, u, _ = alternating_chain(n)
    linear = ActiveSetSolver(system(k, f, g), "superlu")
    start = np.arange(n) % 2 == 0
    start[[10, 200, 301]] = ~start[[10, 200, 301]]
    linear.solve(start)
    assert linear.factorizations == 1
    # Pretend a factorisation costs 10 columns: 3 changes go through the Schur complement...
    linear.column_seconds, linear.refactorization_seconds = 1.0, 10.0
    answer = np.arange(n) % 2 == 0
    displacement, _ = linear.solve(answer)
    assert (linear.factorizations, linear.column_solves) == (1, 3)
    np.testing.assert_allclose(displacement, u, atol=1e-12)
    # ...and 20 changes from the reference are refactorised.
    other = answer.copy()
    other[1:40:2] = True
    linear.column_seconds, linear.refactorization_seconds = 1.0, 10.0
    linear.solve(other)
    assert linear.factorizations == 2


def test_a_fixed_change_budget_still_bounds_the_schur_updates():
    """``max_changes`` replaces the cost model: more changed nodes than it refactorise."""
    from contactfem.kernel import ActiveSetSolver

    n = 101
    k, f, g, _, _ = alternating_chain(n)
    linear = ActiveSetSolver(system(k, f, g), "superlu", max_changes=4)
    answer = np.arange(n) % 2 == 0
    linear.solve(answer)
    few = answer.copy()
    few[[1, 3, 5]] = True
    linear.solve(few)
    assert linear.factorizations == 1
    many = answer.copy()
    many[1:12:2] = True
    linear.solve(many)
    assert linear.factorizations == 2


@pytest.mark.parametrize("backend", available_backends())
def test_refactorisations_with_one_pattern_reuse_the_analysis_and_stay_exact(backend):
    """A Factorizer factorises differently masked matrices of one pattern (the kernel's
    case); each factorisation solves its own matrix, whatever the backend reuses."""
    from contactfem.linalg import Factorizer

    n = 60
    k, _, _, _, _ = alternating_chain(n)
    factorizer = Factorizer(backend)
    rhs = np.linspace(1.0, 2.0, n)
    for scale in (1.0, 3.0, 0.5):
        matrix = sp.csr_matrix(scale * k)
        x = factorizer.factorize(matrix).solve(rhs)
        np.testing.assert_allclose(matrix @ x, rhs, rtol=0, atol=1e-12)
    assert len(factorizer.seconds) == 3


def test_the_safeguard_holds_oscillating_nodes_and_says_how_it_resolved_the_cycle():
    """The cycling problem: the set repeats, the kernel holds the nodes that flipped back and
    forth (or falls back to single least-index changes) and names what it did."""
    result = solve_contact(system(CYCLING_K, CYCLING_F, CYCLING_G), initial_active=CYCLING_START,
                           max_iterations=100)
    assert result.status is Status.CONVERGED
    assert result.cycle_detected_at is not None
    assert "resolved by" in result.message and "least-index" in result.message


@pytest.mark.parametrize("backend", available_backends())
def test_a_refactorisation_of_the_same_pattern_solves_its_own_matrix(backend):
    """The kernel refactorises matrices of one pattern with different values (each active
    set masks other rows); a backend that keeps its analysis (CHOLMOD) must take the new
    values: each factorisation solves its own matrix to round-off."""
    from contactfem.linalg import Factorizer

    rng = np.random.default_rng(7)
    n = 60
    base = sp.random(n, n, density=0.08, random_state=rng, format="csr")
    pattern = (base + base.T + sp.identity(n)).tocsr()
    factorizer = Factorizer(backend, name="the test matrix")
    for scale in (1.0, 3.0, 0.25):
        matrix = pattern.copy()
        matrix.data = rng.uniform(-1, 1, matrix.nnz)
        matrix = (matrix + matrix.T).tocsr()
        matrix = (matrix + sp.identity(n) * (np.abs(matrix).sum(axis=1).max() + scale)).tocsr()
        matrix.sort_indices()
        rhs = rng.uniform(size=n)
        solution = np.asarray(factorizer.factorize(matrix, check=False).solve(rhs)).ravel()
        assert np.abs(matrix @ solution - rhs).max() <= 1e-12 * np.abs(rhs).max()


def test_the_masked_matrix_rewritten_in_place_equals_one_masked_afresh(monkeypatch):
    """Successive active sets rewrite only the rows and columns whose state changed (or,
    when those rows reach as many entries as the pattern holds, mask it in one pass); the
    result is the matrix masked from scratch, entry for entry, on a problem with supports
    and contact nodes in rotated frames, by either way."""
    from conftest import case_from, square_case_dict

    from contactfem.kernel import ActiveSetSolver
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    problem = prepare(case_from(square_case_dict(12)))
    contact = problem.contact_system(get_method("standard")).system
    linear = ActiveSetSolver(contact, "superlu")
    searches = []
    masking = linear.masking
    search = masking._entries_of
    monkeypatch.setattr(masking, "_entries_of", lambda dofs: searches.append(len(dofs)) or search(dofs))
    rng = np.random.default_rng(7)
    m, n = len(contact.gap), len(linear.supported)
    fixed = linear.supported.copy()
    for step in range(8):
        # A third of every unknown fixed anew (rows reaching the whole pattern), or one
        # contact node flipped.
        if step % 2 == 0:
            fixed = linear.supported | (rng.random(n) < 1 / 3)
        else:
            fixed = fixed.copy()
            fixed[linear.normal_dofs[rng.integers(m)]] ^= True
        masked = masking.masked(fixed)
        pattern = masking.pattern
        keep = ~fixed[masking.entry_rows] & ~fixed[pattern.indices]
        expected = np.where(keep, pattern.data, 0.0)
        expected[masking.diagonal[fixed]] = 1.0
        np.testing.assert_array_equal(masked.data, expected)
        assert masked.indices is pattern.indices or np.array_equal(masked.indices, pattern.indices)
    # The single flips were searched row by row, the redrawn thirds masked in one pass.
    assert searches == [1, 1, 1, 1]


@pytest.mark.skipif("cholmod" not in available_backends(), reason="CHOLMOD not installed")
@pytest.mark.parametrize("route", ["library", "interface"])
def test_schur_updates_from_forward_columns_match_a_fresh_factorisation(monkeypatch, route):
    """With CHOLMOD through cvxopt the Schur complement over the changed nodes comes from
    sparse forward columns W = L⁻¹ P C (Cᵀ K⁻¹ C = Wᵀ D⁻¹ W) and u from one full solve: on
    a rough base, a set that releases some nodes of the reference and adds others gives
    the displacement and reactions of factorising that set itself, to round-off, while each
    column holds a small fraction of the unknowns. Both of cvxopt's routes: the bundled
    library called directly (W alone), and cvxopt's interface (W and D⁻¹ W kept apart)."""
    from test_sequencing import rough_polygon_case

    from contactfem.kernel import ActiveSetSolver
    from contactfem.linalg import backend_provider, cholmod_ctypes
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    if backend_provider("cholmod") != "cvxopt":
        pytest.skip("the forward columns are cvxopt's")
    if route == "interface":
        monkeypatch.setitem(cholmod_ctypes._LIBRARY_STATE, "library", None)
    elif cholmod_ctypes.cholmod_library() is None:
        pytest.skip("no CHOLMOD library bundled with cvxopt here")
    import contactfem.kernel.costs as costs

    monkeypatch.setattr(costs, "FORWARD_COLUMNS_FROM", 0)  # a small mesh, to keep the test quick
    monkeypatch.setattr(costs, "SIMPLICIAL_FORWARD_COLUMNS_FROM", 0)
    contact = prepare(rough_polygon_case(600)).contact_system(get_method("positive")).system
    converged = solve_contact(contact, backend="cholmod")
    rng = np.random.default_rng(5)
    reference = converged.active.copy()
    target = reference.copy()
    flip = rng.choice(len(target), 24, replace=False)
    target[flip] = ~target[flip]
    assert (reference & ~target).any() and (~reference & target).any()
    linear = ActiveSetSolver(contact, "cholmod")
    linear.solve(reference)
    linear.column_seconds, linear.refactorization_seconds = 1e-6, 1e3  # take the Schur route
    schur_u, schur_reaction = linear.solve(target)
    assert linear.forward and (linear.factorizations, linear.column_solves) == (1, 24)
    fresh = ActiveSetSolver(contact, "cholmod")
    fresh_u, fresh_reaction = fresh.solve(target)
    scale = np.abs(fresh_u).max()
    assert np.abs(schur_u - fresh_u).max() < 1e-10 * scale
    assert np.abs(schur_reaction - fresh_reaction).max() < 1e-8 * np.abs(fresh_reaction).max()
    assert linear.forward_store.nnz < 0.25 * linear.forward_store.shape[0] * linear.forward_store.shape[1]
    # Later sets add columns in batches; each batch's Schur blocks join the store, which
    # stays the product of all the stored columns, and the solves stay those of a fresh
    # factorisation of each set.
    for batch in range(3):
        flip = rng.choice(len(target), 10, replace=False)
        target[flip] = ~target[flip]
        batch_u, _ = linear.solve(target)
        fresh_u, _ = ActiveSetSolver(contact, "cholmod").solve(target)
        assert linear.factorizations == 1
        assert np.abs(batch_u - fresh_u).max() < 1e-10 * np.abs(fresh_u).max()
    count = linear.column_count
    assert count > 24 + 10
    stored = linear.gram_store[:count, :count]
    expected = linear.forward_store.toarray().T @ linear.scaled_store.toarray()
    assert np.abs(stored - expected).max() < 1e-12 * np.abs(expected).max()
    assert np.array_equal(stored, stored.T)
    assert (linear.scaled_store is linear.forward_store) == (route == "library")


@pytest.mark.parametrize("dense_bytes", [0, 2**29])
@pytest.mark.parametrize("scaled", [False, True])
def test_schur_blocks_from_forward_columns_are_their_dense_product(scaled, dense_bytes, monkeypatch):
    """Wᵀ S for sparse forward columns is the dense product to round-off, whether both are
    gathered densely over the rows the left-hand columns touch or, past the bound on dense
    blocks, multiplied as sparse matrices; for new columns against all of them (the rows a
    store of Schur blocks gains), and for columns whose rows the other side never touches."""
    import scipy.sparse as sp

    import contactfem.kernel.costs as costs
    from contactfem.kernel.columns import cross as _cross

    monkeypatch.setattr(costs, "COLUMN_BYTES", dense_bytes)

    rng = np.random.default_rng(11)
    n, k = 5000, 40
    own = sp.random(n, k, density=0.01, random_state=12, format="csc")
    top = sp.csc_matrix(np.vstack([rng.standard_normal((30, k)), np.zeros((n - 30, k))]))  # rows all share
    forward = sp.csc_matrix(own + top)
    other = sp.csc_matrix(forward.multiply(rng.uniform(0.5, 2.0, forward.shape))) if scaled else forward
    expected = forward.toarray().T @ other.toarray()
    scale = np.abs(expected).max()
    assert np.abs(_cross(forward, other) - expected).max() < 1e-12 * scale
    assert np.abs(_cross(forward[:, :3], other[:, :3]) - expected[:3, :3]).max() < 1e-12 * scale
    assert np.abs(_cross(forward[:, 35:], other) - expected[35:]).max() < 1e-12 * scale
    assert np.abs(_cross(own[:, 35:].tocsc(), sp.csc_matrix(own)) - own[:, 35:].toarray().T @ own.toarray()).max() \
        < 1e-12 * np.abs(own.toarray()).max() ** 2


@pytest.mark.skipif("cholmod" not in available_backends(), reason="CHOLMOD not installed")
@pytest.mark.parametrize("switch", [0, 2])
def test_forward_columns_start_lower_for_a_simplicial_factor(monkeypatch, switch):
    """A simplicial factor's pattern solves convert nothing, so its Schur columns are forward
    ones from SIMPLICIAL_FORWARD_COLUMNS_FROM unknowns; a supernodal factor's only from
    FORWARD_COLUMNS_FROM. Either way the contact solve converges to the same active set."""
    from test_sequencing import rough_polygon_case

    import contactfem.kernel.costs as costs
    from contactfem.kernel import ActiveSetSolver
    from contactfem.linalg import backend_provider, cholmod_ctypes
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    if backend_provider("cholmod") != "cvxopt" or cholmod_ctypes.cholmod_library() is None:
        pytest.skip("the kinds of factor are chosen in the library called directly")
    contact = prepare(rough_polygon_case(600)).contact_system(get_method("positive")).system
    reference = solve_contact(contact, backend="superlu")
    n = contact.stiffness.shape[0]
    monkeypatch.setattr(cholmod_ctypes, "_FACTOR_SWITCH", switch)
    monkeypatch.setattr(costs, "SIMPLICIAL_FORWARD_COLUMNS_FROM", n // 2)
    monkeypatch.setattr(costs, "FORWARD_COLUMNS_FROM", 2 * n)
    linear = ActiveSetSolver(contact, "cholmod")
    result = solve_contact(contact, backend="cholmod", linear=linear)
    assert linear.factor.simplicial is (switch == 0)
    assert linear.forward is (switch == 0)
    assert result.status is Status.CONVERGED
    np.testing.assert_array_equal(result.active, reference.active)


@pytest.mark.skipif("cholmod" not in available_backends(), reason="CHOLMOD not installed")
def test_forward_columns_only_where_the_elimination_trees_paths_are_short():
    """Below FORWARD_COLUMNS_FROM unknowns a simplicial factor goes on with forward columns
    only if they touch at most FORWARD_PATH_SHARE of the unknowns (the column of e_j is the
    elimination tree's path from j), measured on the first columns a Schur update takes: a
    block on a rough base (a 2D mesh: short paths) keeps them, a long strip of 800 x 4
    cells (its tree nearly a chain) goes on with full columns, and its next factorisation
    starts with them. A column touches more than its own unknown and fewer than all, and
    either Schur update gives a fresh factorisation's answer."""
    from conftest import case_from, square_case_dict
    from test_sequencing import rough_polygon_case

    import contactfem.kernel.costs as costs
    from contactfem.kernel import ActiveSetSolver
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    strip = square_case_dict(8)
    strip["geometry"]["rectangle"]["upper"] = [1, 1.0 / 200]
    strip["mesh"]["divisions"] = [800, 4]
    shares = {}
    for name, case in (("block", rough_polygon_case(1000)), ("strip", case_from(strip))):
        contact = prepare(case).contact_system(get_method("positive")).system
        n = contact.stiffness.shape[0]
        assert costs.SIMPLICIAL_FORWARD_COLUMNS_FROM <= n < costs.FORWARD_COLUMNS_FROM
        reference = solve_contact(contact, backend="cholmod").active.copy()
        target = reference.copy()
        target[np.random.default_rng(7).choice(len(target), 6, replace=False)] ^= True
        linear = ActiveSetSolver(contact, "cholmod")
        linear.solve(reference)
        if not callable(getattr(linear.factor, "forward_sparse", None)) or not linear.factor.simplicial:
            pytest.skip("this CHOLMOD's factor is not a simplicial one with forward solves")
        assert linear.forward and linear.path_share is None  # until a step takes columns
        free = linear.normal_dofs[~reference]
        probe = free[len(free) // 2]
        column, _ = linear.factor.forward_sparse(
            sp.csc_matrix((np.ones(1), ([probe], [0])), shape=(n, 1)))
        assert 1 < column.nnz < n
        linear.column_seconds, linear.refactorization_seconds = 1e-9, 1e3  # columns look free
        u, _ = linear.solve(target)
        assert linear.factorizations == 1 and linear.column_solves == 6
        shares[name] = linear.path_share
        assert linear.forward is (linear.path_share <= costs.FORWARD_PATH_SHARE)
        fresh = ActiveSetSolver(contact, "cholmod")
        fresh_u, _ = fresh.solve(target)
        # Two solves of the set, each within round-off times its condition estimate κ̂ (the
        # strip's is 1.5e11, and its columns' update and a fresh factor agreed to 1e-9 of
        # the largest entry; the block's 5e4, and the bound is 1e-10).
        bound = max(1e-10, fresh.condition * np.finfo(float).eps)
        assert np.abs(u - fresh_u).max() < bound * np.abs(fresh_u).max(), (name, fresh.condition)
        linear._factorize(target)
        assert linear.forward is (linear.path_share <= costs.FORWARD_PATH_SHARE)
    assert shares["block"] < costs.FORWARD_PATH_SHARE < shares["strip"]


@pytest.mark.skipif("cholmod" not in available_backends(), reason="CHOLMOD not installed")
@pytest.mark.parametrize("forward", [True, False])
def test_columns_past_the_memory_bound_are_not_kept(monkeypatch, forward):
    """A Schur update whose kept columns (full ones: 8 n bytes each) or kept Schur blocks
    (forward ones: their store grows to (2k)² entries) would pass COLUMN_BYTES factorises
    the set instead, however cheap the cost model finds the columns, with the same answer."""
    from test_sequencing import rough_polygon_case

    import contactfem.kernel.costs as costs
    from contactfem.kernel import ActiveSetSolver
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    monkeypatch.setattr(costs, "FORWARD_COLUMNS_FROM", 0 if forward else 10**9)
    monkeypatch.setattr(costs, "SIMPLICIAL_FORWARD_COLUMNS_FROM", 0 if forward else 10**9)
    contact = prepare(rough_polygon_case(600)).contact_system(get_method("positive")).system
    reference = solve_contact(contact, backend="cholmod").active.copy()
    target = reference.copy()
    flip = np.random.default_rng(6).choice(len(target), 24, replace=False)
    target[flip] = ~target[flip]
    n = contact.stiffness.shape[0]
    held = 8 * (2 * 24) ** 2 if forward else 8 * 24 * n
    for bound, factorizations, columns in ((held, 1, 24), (held - 1, 2, 0)):
        monkeypatch.setattr(costs, "COLUMN_BYTES", bound)
        linear = ActiveSetSolver(contact, "cholmod")
        linear.solve(reference)
        if forward and not linear.forward:
            pytest.skip("this CHOLMOD has no forward columns")
        assert linear.forward == forward
        linear.column_seconds, linear.refactorization_seconds = 1e-9, 1e3  # columns look free
        u, _ = linear.solve(target)
        assert (linear.factorizations, linear.column_solves) == (factorizations, columns)
        fresh_u, _ = ActiveSetSolver(contact, "cholmod").solve(target)
        assert np.abs(u - fresh_u).max() < 1e-10 * np.abs(fresh_u).max()


@pytest.mark.skipif("cholmod" not in available_backends(), reason="CHOLMOD not installed")
def test_a_first_schur_batch_is_costed_on_the_sampled_paths(monkeypatch):
    """From FORWARD_COLUMNS_FROM unknowns forward columns are taken without sampling their
    paths, and before any is stored the Schur blocks' cost was estimated with paths of √n
    unknowns. On a long strip they are ten times that and more, and a first batch of
    hundreds of columns so costed took seconds against a refactorisation's tenth of one.
    The estimate now samples the paths when they could decide it, and only then: with the
    strip's paths the large batch refactorises where √n would have updated, and a
    refactorisation costlier than the longest possible paths leaves them unsampled."""
    from conftest import case_from, square_case_dict

    import contactfem.kernel.costs as costs
    from contactfem.kernel import ActiveSetSolver
    from contactfem.linalg import MODEL
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    strip = square_case_dict(8)
    strip["geometry"]["rectangle"]["upper"] = [1, 1.0 / 200]
    strip["mesh"]["divisions"] = [800, 4]
    contact = prepare(case_from(strip)).contact_system(get_method("positive")).system
    n = contact.stiffness.shape[0]
    monkeypatch.setattr(costs, "FORWARD_COLUMNS_FROM", 0)  # as above it: no path check
    reference = solve_contact(contact, backend="cholmod").active.copy()
    target = reference.copy()
    target[np.random.default_rng(3).choice(len(target), 200, replace=False)] ^= True

    def prepared() -> ActiveSetSolver:
        linear = ActiveSetSolver(contact, "cholmod")
        linear.solve(reference)
        if not callable(getattr(linear.factor, "forward_seconds", None)):
            pytest.skip("this CHOLMOD has no forward solves")
        assert linear.forward and linear.path_share is None and linear.column_count == 0
        return linear

    linear = prepared()
    free = linear.normal_dofs[~reference]
    columns, _ = linear.factor.forward_sparse(
        sp.csc_matrix((np.ones(len(free)), (free, np.arange(len(free)))), shape=(n, len(free))))
    true_path = columns.nnz / len(free)
    assert true_path > 12 * np.sqrt(n), (true_path, np.sqrt(n))
    changed = int((target != reference).sum())
    base = linear.factor.forward_seconds(changed) + costs.dense_seconds(changed) + linear.solve_seconds
    blocks = 2.0 * changed * changed / MODEL.dense_flops
    # Between the √n estimate and the true paths' one: the sampled paths must decide.
    linear.refactorization_seconds = base + blocks * np.sqrt(3 * np.sqrt(n) * true_path)
    assert linear._refactorize_first(target) is True
    assert 0.5 < linear.path_share * n / true_path < 2.0
    # Costlier than even paths through every unknown: nothing to sample.
    linear = prepared()
    linear.refactorization_seconds = 2 * (base + blocks * n)
    assert linear._refactorize_first(target) is False and linear.path_share is None


def test_a_body_pushed_by_a_translation_starts_from_the_nodes_it_presses_in():
    """The rough block pushed down by its top, nothing loading it: the supports' own solution
    is that translation, so the cold start's first solve is known and its update (every node
    the push presses in) is where the iteration starts. The answer is the same to round-off,
    one step and one factorisation fewer; the first set solved is the old second one. A
    translation that is not the supports' solution (twice the push, or a load on the body)
    is checked and not used."""
    from dataclasses import replace

    from test_sequencing import rough_polygon_case

    from contactfem.kernel import ActiveSetSolver
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    problem = prepare(rough_polygon_case(400))
    for method in ("positive", "standard"):
        system_ = problem.contact_system(get_method(method)).system
        assert system_.translation is not None
        # Every changed set factorised (the kernel's choice between columns and a
        # refactorisation follows measured timings): factorisations count the sets solved.
        known = solve_contact(system_, linear=ActiveSetSolver(system_, "auto", max_changes=0))
        plain = replace(system_, translation=None)
        unknown = solve_contact(plain, linear=ActiveSetSolver(plain, "auto", max_changes=0))
        for result in (known, unknown):
            assert result.status is Status.CONVERGED, result.message
        np.testing.assert_array_equal(known.active, unknown.active)
        scale = np.abs(unknown.displacement).max()
        np.testing.assert_allclose(known.displacement, unknown.displacement, rtol=0, atol=1e-12 * scale)
        assert known.iterations == unknown.iterations - 1
        assert known.factorizations == unknown.factorizations - 1
        assert unknown.history[0].active == 0 and known.history[0].active == unknown.history[1].active > 0
        for wrong in (replace(system_, translation=2 * system_.translation),
                      replace(system_, load=np.where(np.arange(len(system_.load)) == 0, 1e-3, 0.0))):
            other = solve_contact(wrong)
            assert other.history[0].active == 0  # solved from the supports, as without a translation


def test_no_translation_is_claimed_where_the_data_are_not_one():
    """A translation is given to the kernel only when nothing loads the body and every
    prescribed value is a component of it: not under a traction (the square) or a platen's
    force (the Hertz disk held by contact alone); the pushed Hertz disk and a square whose
    top and left side each prescribe one component of a translation get one."""
    from conftest import case_from, shipped_case, square_case_dict

    from contactfem.methods import get_method
    from contactfem.solve import prepare

    method = get_method("positive")
    assert prepare(case_from(square_case_dict(8))).contact_system(method).system.translation is None
    assert prepare(shipped_case("hertz_platen")).contact_system(method).system.translation is None
    pushed = prepare(shipped_case("hertz")).contact_system(method).system  # its top pushed down by 4e-3
    assert pushed.translation is not None
    assert np.abs(pushed.translation[pushed.normal_dofs]).max() == pytest.approx(4e-3, rel=1e-12)
    # Two parts, each prescribing one component: together one translation, checked by the kernel.
    data = square_case_dict(8)
    data["boundary"] = {"top": {"displacement": [None, -1e-3]}, "left": {"displacement": [2e-4, None]},
                        "bottom": "contact"}
    system_ = prepare(case_from(data)).contact_system(method).system
    assert system_.translation is not None
    result = solve_contact(system_)
    assert result.status is Status.CONVERGED and result.history[0].active > 0  # started pressed in
    np.testing.assert_allclose(result.displacement[system_.fixed_dofs], system_.fixed_values, rtol=0, atol=1e-15)
