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
    and μ1 = F1 − (K u)1 = 1 − 1/2 = 1/2 ≥ 0. The start (all touching nodes active) must
    drop node 2, whose force would be F2 − 0 = −1 < 0: two solves, then a repeat.
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
