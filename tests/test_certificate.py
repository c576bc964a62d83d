"""The kernel certifies what it returns: CONVERGED only when the discrete problem's own
conditions hold on the returned iterate, otherwise NOT_CERTIFIED (or SolverError for a
singular stiffness), with the failed condition named.

Each class of wrong answer found by hostile testing is reproduced on a small hand-built
system and on the finite element system that exposed it:

- a tiny c (1e-6) let a penetrating iterate pass as converged;
- a body not held (singular stiffness) came back with a displacement of 1e13-1e15;
- a body 1 x 1e-6 returned a negative multiplier for the positive method;
- a prescribed motion of 1e45 with nothing resisting it returned forces that were all
  round-off.

A certified result is then checked here independently, from the system's arrays.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import yaml
from conftest import CASES, case_from, square_case_dict

from contactfem.errors import SolverError
from contactfem.kernel import (
    FORCE_RESOLUTION_LIMIT,
    ContactSystem,
    KernelResult,
    Status,
    solve_contact,
)
from contactfem.linalg import (
    SINGULARITY_LIMIT,
    available_backends,
    check_factorization,
    factorize,
)

TOLERANCE = 1e-10


def hand_built(k, f, g, normal, fixed=(), values=(), mass=None) -> ContactSystem:
    k = np.asarray(k, dtype=float)
    return ContactSystem(
        stiffness=sp.csr_matrix(k), load=np.asarray(f, dtype=float), normal_dofs=np.asarray(normal),
        gap=np.asarray(g, dtype=float),
        multiplier_mass=sp.csr_matrix(np.eye(len(normal)) if mass is None else np.asarray(mass, dtype=float)),
        fixed_dofs=np.asarray(fixed, dtype=np.int64), fixed_values=np.asarray(values, dtype=float),
    )


def chain(springs) -> np.ndarray:
    """Springs in series: nodes 0..len(springs), spring i between nodes i and i + 1."""
    n = len(springs) + 1
    k = np.zeros((n, n))
    for i, s in enumerate(springs):
        k[i:i + 2, i:i + 2] += s * np.array([[1.0, -1.0], [-1.0, 1.0]])
    return k


def floating_piece(n: int, seed: int) -> np.ndarray:
    """An n x n stiffness whose null vector is the translation (1, ..., 1): Q diag(0, λ) Qᵀ.

    Built in floating point it is singular only to round-off, as an assembled unheld part
    is: elimination without pivoting meets a tiny (or negative) pivot, not an exact zero.
    """
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(np.column_stack([np.ones(n), rng.standard_normal((n, n - 1))]))
    a = q @ np.diag(np.concatenate([[0.0], rng.uniform(1.0, 2.0, n - 1)])) @ q.T
    return 0.5 * (a + a.T)


def independent_conditions(system: ContactSystem, result: KernelResult) -> dict[str, float]:
    """The discrete conditions recomputed from the system's arrays, in the certificate's scales.

    Force scale ‖F‖∞ + ‖K u‖∞ + ‖Nᵀ Λ‖∞, displacement scale max(‖u‖∞, ‖G‖∞), Λ = Bμ.
    """
    k = sp.csr_matrix(system.stiffness)
    u = result.displacement
    forces = np.asarray(system.multiplier_mass @ result.multiplier)
    contact = np.zeros(len(u))
    contact[system.normal_dofs] = forces
    equations = np.ones(len(u), dtype=bool)
    equations[system.fixed_dofs] = False
    force = np.abs(system.load).max() + np.abs(k @ u).max() + np.abs(forces).max(initial=0.0)
    displacement = max(np.abs(u).max(), np.abs(system.gap).max(initial=0.0))
    slack = u[system.normal_dofs] - system.gap
    return {
        "equilibrium": np.abs((k @ u + contact - system.load)[equations]).max() / force,
        "force_sign": max(0.0, -forces.min(initial=0.0)) / force,
        "penetration": max(0.0, slack.max(initial=0.0)) / displacement,
        "complementarity": np.abs(forces * slack).max(initial=0.0) / (force * displacement),
        "prescribed": np.abs(u[system.fixed_dofs] - system.fixed_values).max(initial=0.0) / displacement,
    }


def assert_certified(system: ContactSystem, result: KernelResult, tolerance: float = TOLERANCE) -> None:
    """CONVERGED, a passed certificate, and the conditions hold when recomputed here: each
    below ``tolerance`` raised to the certificate's stated round-off bound, which must itself
    resolve the forces (≤ FORCE_RESOLUTION_LIMIT)."""
    assert result.status is Status.CONVERGED, result.message
    certificate = result.certificate
    assert certificate is not None and certificate.passed and certificate.failed == []
    roundoff = certificate.scales["roundoff"]
    assert roundoff <= FORCE_RESOLUTION_LIMIT
    measured = independent_conditions(system, result)
    bound = max(tolerance, roundoff)
    for name in ("equilibrium", "force_sign", "complementarity"):
        assert measured[name] <= bound, (name, measured[name], bound)
        np.testing.assert_allclose(certificate.checks[name].value, measured[name], rtol=1e-6, atol=1e-3 * bound)
    assert measured["penetration"] <= tolerance
    assert measured["prescribed"] <= 1e-15
    assert np.isfinite(result.displacement).all() and np.isfinite(result.multiplier).all()


# --- a tiny c ------------------------------------------------------------------------------

def test_tiny_c_hand_built():
    """Springs of stiffness 1e6 in a chain, F = 5e6 at the last node, gap 1 there: the free
    solution (1, 2, 3, 4) penetrates by 3. With c = 1e-6 the indicator c (d − G) = 3e-6 used
    to fall under an absolute threshold: one iteration, no active node, penetration 3, and
    CONVERGED. Now the answer u = (1/4, 1/2, 3/4, 1), μ4 = 3.75e6 for any c."""
    k = 1e6 * (2 * np.eye(4) - np.eye(4, k=1) - np.eye(4, k=-1))
    system = hand_built(k, [0, 0, 0, 5e6], [10, 10, 10, 1], [0, 1, 2, 3])
    for c in (1e-6, 1.0, 1e6):
        result = solve_contact(system, c=c)
        assert_certified(system, result)
        np.testing.assert_allclose(result.displacement, [0.25, 0.5, 0.75, 1.0], rtol=1e-12)
        np.testing.assert_allclose(result.multiplier[3], 3.75e6, rtol=1e-12)


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_tiny_c_on_the_square(method):
    """The square case with solver.c = 1e-6 used to stop after one iteration with no active
    node and a penetration equal to the whole displacement; it now gives c = auto's answer."""
    from contactfem.kernel import default_c
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    system = prepare(case_from(square_case_dict(16))).contact_system(get_method(method)).system
    reference = solve_contact(system, c=default_c(system))
    result = solve_contact(system, c=1e-6)
    assert_certified(system, result)
    np.testing.assert_array_equal(result.active, reference.active)
    assert result.active.any()
    np.testing.assert_allclose(result.displacement, reference.displacement, rtol=0,
                               atol=1e-10 * np.abs(reference.displacement).max())


# --- a singular stiffness --------------------------------------------------------------------

@pytest.mark.parametrize("backend", available_backends())
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("balanced", [False, True])
def test_a_part_not_held_is_a_solver_error(backend, seed, balanced):
    """A held chain (node 0 fixed) beside a floating 3-node piece, each with a contact node.

    The old kernel returned CONVERGED with the floating piece moved by ~1e15 (unbalanced
    load) or an arbitrary position (balanced load: the system is consistent but its solution
    is not unique). The probe of the factorisation sees the null space whatever the load."""
    k = np.zeros((6, 6))
    k[:3, :3] = chain([1.3, 1.7])
    k[3:, 3:] = floating_piece(3, seed)
    load = [0, 0, 1, 0.3, 0, -0.3] if balanced else [0, 0, 1, 0, 0.3, 0]
    system = hand_built(k, load, [1, 1], [2, 5], fixed=[0], values=[0.0])
    with pytest.raises(SolverError, match="singular"):
        solve_contact(system, backend=backend)


@pytest.mark.parametrize("backend", available_backends())
def test_factorize_reports_singular_matrices(backend):
    """For every backend: an exactly singular matrix, one singular to round-off, and one with
    κ ≈ 2e15 are reported with one line naming what was detected."""
    nearly = np.array([[1 + 1e-15, -1.0], [-1.0, 1 + 1e-15]])
    for matrix in (chain([1.0, 2.0]), floating_piece(4, 0), nearly):
        with pytest.raises(SolverError) as error:
            factorize(sp.csr_matrix(matrix), backend)
        assert "singular" in str(error.value) and "\n" not in str(error.value)
    good = factorize(sp.csr_matrix(chain([1.0, 2.0]) + np.eye(3)), backend)
    np.testing.assert_allclose(good.solve(np.ones(3)), np.linalg.solve(chain([1.0, 2.0]) + np.eye(3), np.ones(3)))


def test_the_probe_catches_a_factorisation_that_returns_garbage():
    """A factor whose pivot is round-off instead of zero solves without complaint; the probe's
    residual (outside the range) and its condition estimate give it away."""
    matrix = floating_piece(5, 3)

    class TinyPivot:
        def solve(self, rhs):
            return np.linalg.solve(matrix + 1e-15 * np.eye(5), rhs)

    with pytest.raises(SolverError, match="probe residual"):
        check_factorization(sp.csr_matrix(matrix), TinyPivot(), name="the test matrix")
    sound = check_factorization(sp.csr_matrix(matrix + np.eye(5)), factorize(sp.csr_matrix(matrix + np.eye(5))))
    assert sound.residual < 1e-14 and 1.0 <= sound.condition < 10.0
    assert sound.relative_precision < SINGULARITY_LIMIT


def two_piece_mesh(directory: Path) -> Path:
    """Two unit squares 1 apart: the left one clamped, the right one held only by a traction."""
    from contactfem.mesh import structured_rectangle, write_gmsh
    from contactfem.mesh.core import Mesh

    names = ("floor", "free", "clamp", "push")
    left = structured_rectangle((0, 0), (1, 1), 4, 4, side_names={"bottom": "floor", "right": "free",
                                                                   "top": "free", "left": "clamp"})
    right = structured_rectangle((2, 0), (3, 1), 4, 4, side_names={"bottom": "floor", "right": "free",
                                                                    "top": "push", "left": "free"})

    def parts(mesh):
        return np.array([names.index(mesh.part_names[p]) for p in mesh.edge_parts])

    offset = left.n_points
    mesh = Mesh(points=np.vstack([left.points, right.points]),
                triangles=np.vstack([left.triangles, right.triangles + offset]),
                boundary_edges=np.vstack([left.boundary_edges, right.boundary_edges + offset]),
                edge_parts=np.concatenate([parts(left), parts(right)]), part_names=names)
    return write_gmsh(mesh, directory / "two.msh")


def test_a_mesh_of_two_pieces_one_held_by_a_traction_is_refused_naming_the_piece(tmp_path):
    """The finite element version: the old kernel moved the second piece by ~1e11 and said
    CONVERGED. Each connected piece must be held by its own supports: the case is refused
    before any solve, and the kernel alone would still call the system singular."""
    from contactfem.case import load_case
    from contactfem.errors import CaseError
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    two_piece_mesh(tmp_path)
    case = {"title": "two pieces", "geometry": {"mesh_file": "two.msh"}, "material": {"E": 1e6, "nu": 0.3},
            "boundary": {"clamp": "clamped", "push": {"traction": [1e3, -1e4]}, "free": "free", "floor": "contact"},
            "obstacle": {"point": [0, 0], "normal": [0, -1]}}
    path = tmp_path / "two.yaml"
    path.write_text(yaml.safe_dump(case), encoding="utf-8")
    with pytest.raises(CaseError, match=r"two.yaml: boundary: the mesh has 2 separate pieces .* not held"):
        prepare(load_case(path))
    import contactfem.discretize.supports as supports

    unchecked = pytest.MonkeyPatch()
    unchecked.setattr(supports, "_refuse_rigid_motion", lambda *args: None)
    try:
        system = prepare(load_case(path)).contact_system(get_method("positive")).system
    finally:
        unchecked.undo()
    with pytest.raises(SolverError, match="singular"):
        solve_contact(system)


# --- extreme aspect ratio ----------------------------------------------------------------------

def test_a_numerically_singular_stiffness_is_a_solver_error():
    """Two unknowns coupled by a stiff spring, grounded by springs 1e-15 as stiff: κ ≈ 2e15,
    a slender body in miniature. The old kernel returned CONVERGED."""
    k = np.array([[1 + 1e-15, -1.0], [-1.0, 1 + 1e-15]])
    with pytest.raises(SolverError, match="numerically singular"):
        solve_contact(hand_built(k, [1, -1], [10, 10], [0, 1]))


def slender(height: float, divisions: tuple[int, int], top) -> dict:
    data = square_case_dict()
    data["geometry"] = {"rectangle": {"lower": [0, 0], "upper": [1, height]}}
    data["mesh"] = {"divisions": list(divisions)}
    data["boundary"]["top"] = {"traction": top}
    return data


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_a_body_one_by_one_millionth_is_a_solver_error(method):
    """1 x 1e-6, 64 x 2 cells, clamped at one end: κ far beyond 1/ε. The old kernel returned
    CONVERGED with the positive method's λ down to −1e6 and a force residual of 1e-2."""
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    data = slender(1e-6, (64, 2), [1.0e4, "-1e4*(1-1.5*x)"])
    system = prepare(case_from(data)).contact_system(get_method(method)).system
    with pytest.raises(SolverError, match="numerically singular"):
        solve_contact(system)


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_a_body_one_by_one_thousandth_is_certified_to_its_stated_precision(method):
    """1 x 1e-3 (200 x 1 cells) is ill-conditioned but resolvable: certified, with the
    equilibrium tolerance raised to the round-off bound the certificate states, and the
    conditions hold when recomputed."""
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    data = slender(1e-3, (200, 1), [0.0, "-1.0*(1-1.5*x)"])
    system = prepare(case_from(data)).contact_system(get_method(method)).system
    result = solve_contact(system)
    assert_certified(system, result)
    assert result.certificate.scales["roundoff"] > TOLERANCE  # the bound is what certifies it
    assert result.certificate.scales["relative_precision"] < SINGULARITY_LIMIT


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_a_strip_that_only_contact_holds_is_solved_from_a_cold_start(method):
    """1 x 1e-6 (100 x 1 cells), clamped at one end, resting on the plane (every gap 0)
    under a wavy pressure that lifts it between patches. The cold start (the nodes inside
    the obstacle: none) leaves a cantilever of slenderness 1e6, numerically singular; the
    kernel then starts from every touching node and converges, certified, to the answer
    a start from the final set gives, within what each certificate states (ε κ̂ relative:
    two backward-stable solves of one system differ by at most twice that). The old kernel
    refused the case as singular."""
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    data = slender(1e-6, (100, 1), [0.0, "-1.0*(0.9 + sin(20*x))"])
    system = prepare(case_from(data)).contact_system(get_method(method)).system
    assert (np.asarray(system.gap) == 0.0).all()
    result = solve_contact(system)
    assert_certified(system, result)
    assert 0 < result.active.sum() < len(result.active)  # lifted between patches
    patches = int(result.active[0]) + int(np.count_nonzero(result.active[1:] & ~result.active[:-1]))
    assert patches >= 3
    again = solve_contact(system, initial_active=result.active)
    assert again.iterations == 1
    np.testing.assert_array_equal(again.active, result.active)
    precision = max(result.certificate.scales["relative_precision"], again.certificate.scales["relative_precision"])
    assert precision < SINGULARITY_LIMIT
    scale = np.abs(again.displacement).max()
    np.testing.assert_allclose(result.displacement, again.displacement, rtol=0, atol=2 * precision * scale)


def test_a_strip_peeling_off_in_bending_creeps_to_its_answer_within_the_default_cap():
    """1 x 0.01 (400 x 4 cells), clamped at one end, resting on the plane under a pressure
    that pulls it up on a third of its length: every release puts the next node in tension,
    so Newton's update alone (no ΓC order given, so no extrapolation of the creep) moves the
    zone's edges a node per edge per step. The default cap, one step per contact node (401
    here) and at least 50, lets it finish (51 steps: the old cap of 50 stopped it one
    short); the answer is certified and is the one a start from the final set gives. A cap
    that stops it says that the zone was creeping and what to raise."""
    from dataclasses import replace

    from contactfem.kernel import MIN_ITERATIONS, default_max_iterations
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    data = slender(1e-2, (400, 4), [0.0, "-1.0*(0.5 + sin(10*x))"])
    system = replace(prepare(case_from(data)).contact_system(get_method("positive")).system, contact_edges=None)
    m = len(system.normal_dofs)
    assert default_max_iterations(m) == m > MIN_ITERATIONS and default_max_iterations(10) == MIN_ITERATIONS
    result = solve_contact(system)
    assert_certified(system, result)
    assert result.iterations > MIN_ITERATIONS
    tail = result.history[-10:-1]
    assert all(0 < step.added + step.removed <= 4 for step in tail)  # a node per edge per step
    again = solve_contact(system, initial_active=result.active)
    assert again.iterations == 1
    scale = np.abs(again.displacement).max()
    np.testing.assert_allclose(result.displacement, again.displacement, rtol=0, atol=1e-10 * scale)
    stopped = solve_contact(system, max_iterations=20)
    assert stopped.status is Status.MAX_ITERATIONS
    assert "creeping" in stopped.message and "solver.max_iterations" in stopped.message
    assert "\n" not in stopped.message


def test_the_least_index_safeguard_counts_only_its_own_sets_as_a_cycle():
    """1 x 0.001 (200 x 2 cells), clamped at one end, under a pressure that lifts it in
    seven places: Newton alone creeps, then repeats a set at step 32 and the least-index rule
    takes over. Its single changes pass through a set that plain Newton had visited, which
    is no cycle of the rule (Murty's rule never repeats its own sets on a P-matrix
    problem); the old kernel stopped there as cycling. Now it settles, certified, on the
    answer a start from its final set gives."""
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    from dataclasses import replace

    data = slender(1e-3, (200, 2), [0.0, "-1.0*(0.3 + sin(20*x))"])
    # Newton's update alone (no ΓC order to extrapolate the creep along: with it this
    # strip settles in 33 steps, meeting a repeated set at step 22).
    system = replace(prepare(case_from(data)).contact_system(get_method("positive")).system, contact_edges=None)
    result = solve_contact(system)
    assert_certified(system, result)
    assert result.cycle_detected_at is not None and "least-index" in result.message
    again = solve_contact(system, initial_active=result.active)
    assert again.iterations == 1
    precision = max(result.certificate.scales["relative_precision"], again.certificate.scales["relative_precision"])
    scale = np.abs(again.displacement).max()
    np.testing.assert_allclose(result.displacement, again.displacement, rtol=0, atol=max(2 * precision, 1e-10) * scale)


# --- huge prescribed values ----------------------------------------------------------------------

def test_a_huge_rigid_motion_is_not_certified():
    """A chain held only by its first node, prescribed at 1e45, far from the obstacle: every
    force is round-off of terms 1e45 times the stiffness. The old kernel said CONVERGED."""
    k = chain([1.1, 1.3, 1.7, 1.9])
    system = hand_built(k, np.zeros(5), [1e46], [4], fixed=[0], values=[1e45])
    result = solve_contact(system)
    assert result.status is Status.NOT_CERTIFIED
    assert result.certificate.failed[0] == "force_resolution"
    assert "force_resolution" in result.message and "\n" not in result.message
    check = result.certificate.checks["force_resolution"]
    assert check.value > check.tolerance == FORCE_RESOLUTION_LIMIT
    np.testing.assert_allclose(result.displacement, 1e45, rtol=1e-14)


def test_a_body_lifted_off_the_obstacle_unloaded_is_certified_up_to_an_absurd_lift():
    """The square (size 1) with its top moved up and nothing else on it leaves the plane and
    moves rigidly: its exact forces are zero and the computed ones round-off, which has no
    scale of its own. They are measured against the force of a strain of ZERO_FORCE_STRAIN
    over the body: a lift of 1e-3 or 1e3 is certified, with no contact and forces zero to
    within 1e-10 of the body's force unit; a lift of 1e6 body sizes is not (its round-off
    is 1e-8 of that unit), nor is the 1e45 translation above, and the message says why. A
    hand-built system has no length scale, hence no such unit (the chain above)."""
    from contactfem.kernel import ZERO_FORCE_STRAIN
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    for lift, certified in ((1.0e-3, True), (1.0e3, True), (1.0e6, False)):
        data = square_case_dict(8)
        data["boundary"].update(left="free", top={"displacement": [0.0, lift]})
        system = prepare(case_from(data)).contact_system(get_method("positive")).system
        assert system.length_scale == 1.0
        result = solve_contact(system)
        assert not result.active.any()
        if certified:
            # Recomputed here: the equations' residual, in force, within the certificate's
            # bound of that unit; no node touching or inside the obstacle.
            assert result.status is Status.CONVERGED and result.certificate.passed, result.message
            unit = ZERO_FORCE_STRAIN * np.abs(system.stiffness.diagonal()).max() * system.length_scale
            assert result.certificate.scales["force"] == unit
            roundoff = result.certificate.scales["roundoff"]
            assert roundoff <= FORCE_RESOLUTION_LIMIT
            equations = np.setdiff1d(np.arange(len(system.load)), system.fixed_dofs)
            residual = np.abs(system.stiffness @ result.displacement - system.load)[equations].max()
            assert residual <= max(TOLERANCE, roundoff) * unit
            slack = result.displacement[system.normal_dofs] - system.gap
            assert (slack < 0).all() and np.isfinite(result.displacement).all()
        else:
            assert result.status is Status.NOT_CERTIFIED and result.certificate.failed[0] == "force_resolution"
            assert "moves rigidly, free of stress" in result.message and "\n" not in result.message


def test_a_huge_prescribed_motion_against_the_obstacle_is_certified():
    """The same chain pushed 1e45 into an obstacle at 0: the forces are 1e45 times the
    series stiffness and fully resolved."""
    springs = [1.1, 1.3, 1.7, 1.9]
    system = hand_built(chain(springs), np.zeros(5), [0.0], [4], fixed=[0], values=[1e45])
    result = solve_contact(system)
    assert_certified(system, result)
    series = 1.0 / sum(1.0 / s for s in springs)
    np.testing.assert_allclose(result.multiplier, [series * 1e45], rtol=1e-13)


@pytest.mark.parametrize("method", ["positive", "standard"])
def test_huge_prescribed_displacements_on_the_square(method):
    """The square translated by 1e45 (left side prescribed, nothing else): not certified,
    the forces are not resolved. Pushed 1e45 into the obstacle from the top: certified."""
    from contactfem.methods import get_method
    from contactfem.solve import prepare

    translated = square_case_dict(8)
    translated["boundary"]["left"] = {"displacement": [1e45, 0.0]}
    translated["boundary"]["top"] = "free"
    system = prepare(case_from(translated)).contact_system(get_method(method)).system
    result = solve_contact(system)
    assert result.status is Status.NOT_CERTIFIED
    assert result.certificate.failed[0] == "force_resolution"

    pressed = square_case_dict(8)
    pressed["boundary"] = {"top": {"displacement": [0.0, -1e45]}, "left": "free", "right": "free",
                           "bottom": "contact"}
    system = prepare(case_from(pressed)).contact_system(get_method(method)).system
    assert_certified(system, solve_contact(system))


# --- the certificate itself -----------------------------------------------------------------------

def test_non_finite_values_are_not_certified_and_not_raised():
    """A NaN load gives a NaN displacement: status NOT_CERTIFIED naming finiteness."""
    system = hand_built(chain([1.0, 1.0]) + np.eye(3), [1.0, np.nan, 0.0], [1.0], [2])
    result = solve_contact(system)
    assert result.status is Status.NOT_CERTIFIED
    assert result.certificate.failed[0] == "finite"


def test_a_stopped_iteration_carries_the_certificate_of_its_last_iterate():
    """Capped after one solve, the iterate u = (1, 2, 3, 4) still penetrates by 3: the
    certificate says so, relative to the displacement scale max(‖u‖∞, ‖G‖∞) = 10."""
    k = 2 * np.eye(4) - np.eye(4, k=1) - np.eye(4, k=-1)
    result = solve_contact(hand_built(k, [0, 0, 0, 5], [10, 10, 10, 1], [0, 1, 2, 3]), max_iterations=1)
    assert result.status is Status.MAX_ITERATIONS
    assert result.certificate.failed == ["penetration"]
    np.testing.assert_allclose(result.certificate.checks["penetration"].value, 3.0 / 10.0, rtol=1e-14)


def test_the_certificate_is_json_ready():
    k = 2 * np.eye(4) - np.eye(4, k=1) - np.eye(4, k=-1)
    result = solve_contact(hand_built(k, [0, 0, 0, 5], [10, 10, 10, 1], [0, 1, 2, 3]))
    figures = json.loads(json.dumps(result.certificate.to_dict(), allow_nan=False))
    assert figures["passed"] is True and figures["failed"] == []
    assert set(figures["checks"]["equilibrium"]) == {"value", "tolerance", "passed", "meaning"}
    assert {"force", "displacement", "roundoff", "condition_estimate", "relative_precision"} <= set(figures["scales"])


def test_the_consistent_mass_is_certified_on_its_nodal_forces():
    """Method (5)'s weak sign condition: μ2 = −1/3 < 0 is allowed, (Bμ) ≥ 0 is what is checked."""
    system = hand_built(np.eye(2), [1, -1], [0, 0], [0, 1], mass=[[2, 1], [1, 2]])
    result = solve_contact(system)
    assert_certified(system, result)
    assert result.multiplier.min() < 0


# --- the shipped cases ---------------------------------------------------------------------------

@pytest.mark.parametrize("path", sorted(CASES.glob("*.yaml")), ids=lambda p: p.stem)
def test_the_shipped_cases_are_certified_for_both_methods(path):
    from contactfem.case import load_case
    from contactfem.methods import get_method
    from contactfem.solve import prepare, solve_case

    case = load_case(path)
    problem = prepare(case)
    for method in ("positive", "standard"):
        outcome = solve_case(case, method=method, problem=problem)
        system = outcome.problem.contact_system(get_method(method)).system
        assert_certified(system, outcome.kernel, tolerance=case.solver.tolerance)


# --- through the command line -------------------------------------------------------------------

def _cli_case(tmp_path, change) -> Path:
    data = square_case_dict(8)
    change(data)
    path = tmp_path / "variant.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def test_an_uncertified_result_exits_1_in_one_line_and_its_files_say_so(tmp_path):
    """A prescribed displacement of 1e45 (inside the documented bounds): the forces are lost in
    cancellation. Exit 1, one line naming the failed condition and its value; report.json
    carries status not_certified and the failed check."""
    import json

    from conftest import make_runner

    from contactfem.cli import main

    path = _cli_case(tmp_path, lambda d: d["boundary"].update(left={"displacement": [1e45, 0]}))
    out = tmp_path / "out"
    result = make_runner().invoke(main, ["solve", str(path), "--out", str(out), "--quiet"])
    assert result.exit_code == 1
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "variant.yaml" in lines[0] and "not certified" in lines[0]
    assert "force_resolution" in lines[0] and "exceeds its tolerance" in lines[0]
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert report["solver"]["status"] == "not_certified"
    assert report["solver"]["certificate"]["failed"] == ["force_resolution"]


@pytest.mark.parametrize("c", [1e-6, 1e6])
def test_a_tiny_or_huge_c_gives_the_answer_of_c_one_through_the_command_line(tmp_path, c):
    """solver.c only starts the iteration: the certified answer is the same as with c = 1."""
    import json

    from conftest import make_runner

    from contactfem.cli import main

    reports = {}
    for value in (1.0, c):
        path = _cli_case(tmp_path, lambda d: d.update(solver={"c": value}))
        out = tmp_path / f"out-{value:g}"
        result = make_runner().invoke(main, ["solve", str(path), "--out", str(out), "--quiet"])
        assert result.exit_code == 0, result.stderr
        reports[value] = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert reports[c]["solver"]["certificate"]["passed"]
    assert reports[c]["contact_zone"] == reports[1.0]["contact_zone"]
    assert reports[c]["contact_force"]["normal"] == pytest.approx(reports[1.0]["contact_force"]["normal"], rel=1e-10)


def test_a_gap_crossed_under_a_force_too_small_to_resolve_is_refused_naming_the_rigid_motion():
    """A block that contact alone holds along the obstacle's normal (a symmetry side and a
    platen force on top), 1e-3 above the plane: it crosses the gap rigidly, then presses.
    Under 1e3 its strains are resolved and it is certified, pressing along its whole base.
    Under 1e-12 its strains are 1e-18 against a rigid motion of 1e-3, below double
    precision (forces of |K||u| are 1e15 times the body's): not certified, and the message
    says the displacement is mostly a rigid motion and what to do."""
    from contactfem.solve import solve_case

    for force, certified in ((1.0e3, True), (1.0e-12, False)):
        data = square_case_dict(8)
        data["boundary"] = {"left": "symmetry", "top": {"platen": {"force": force}}, "bottom": "contact"}
        data["obstacle"] = {"point": [0.0, -1.0e-3], "normal": [0.0, -1.0]}
        result = solve_case(case_from(data), accept_uncertified=True)
        kernel = result.kernel
        if certified:
            assert kernel.status is Status.CONVERGED, kernel.message
            assert kernel.active.all()
            assert result.solution.contact.nodal_force.sum() == pytest.approx(force, rel=1e-10)
        else:
            assert kernel.status is Status.NOT_CERTIFIED and kernel.certificate.failed[0] == "force_resolution"
            assert "mostly a rigid motion" in kernel.message and "close the gap in the geometry" in kernel.message
            assert "\n" not in kernel.message
