"""Semismooth Newton (primal–dual active set) kernel for a linear elastic system with nodal unilateral constraints.

The kernel sees arrays only. The discrete problem, in coordinates where each contact
node's normal displacement is one unknown (``normal_dofs``), is

    K u + P B μ = F,     B μ ≥ 0,   d − G ≤ 0,   (B μ)ᵀ (d − G) = 0   (row by row)

with d = u[normal_dofs], P the injection of the contact rows into the unknowns, and B
the multiplier mass of the method: the lumped D for the positive method, the consistent
M for the standard one. Newton's method on C(Bμ, d) = Bμ − max(0, Bμ + c (d − G)) is the
active set iteration: on A, d = G (a Dirichlet condition on one unknown); on I, (Bμ) = 0,
so each step is one SPD solve of the size of the linear problem, after which Bμ on A is
the reaction of the fixed normal unknowns and μ = B⁻¹(Bμ).

Plain Newton can revisit an active set on hard problems. The kernel detects the repeat
and continues with Murty's least-index rule (change only the lowest-numbered node whose
condition fails), which terminates for P-matrix complementarity problems like this one.
"""

from __future__ import annotations

import enum
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from contactfem.linalg import factorize

# Nodes whose active-set indicator lies within this fraction of the problem's force
# scale of zero are degenerate (no force and no gap, to round-off): they keep their
# current state, so that round-off cannot make the active set flicker.
DEGENERACY_TOLERANCE = 1e-12


class Status(enum.Enum):
    CONVERGED = "converged"
    MAX_ITERATIONS = "max_iterations"
    CYCLING = "cycling"
    INACCURATE = "inaccurate"


@dataclass(frozen=True, eq=False)
class ContactSystem:
    """The algebraic contact problem handed to the kernel.

    Attributes
    ----------
    stiffness : (n, n) sparse SPD
        Stiffness with Dirichlet unknowns eliminated and contact nodes in normal/tangent
        coordinates.
    load : (n,)
    normal_dofs : (m,) int
        Index of the normal unknown of each contact node.
    gap : (m,)
        Initial gap G of each contact node (negative: the body starts inside the obstacle).
    multiplier_mass : (m, m) sparse SPD
        B: how the method's multiplier μ becomes nodal forces Bμ.
    """

    stiffness: sp.spmatrix
    load: np.ndarray
    normal_dofs: np.ndarray
    gap: np.ndarray
    multiplier_mass: sp.spmatrix


@dataclass
class Iteration:
    active: int
    added: int
    removed: int
    equilibrium_residual: float
    complementarity_residual: float
    seconds: float


@dataclass(eq=False)
class KernelResult:
    """What the kernel returns; it never raises on non-convergence, the caller decides.

    ``displacement`` (n,), ``multiplier`` μ (m,), ``nodal_force`` Bμ (m,), ``active`` (m,) bool.
    """

    status: Status
    message: str
    displacement: np.ndarray
    multiplier: np.ndarray
    nodal_force: np.ndarray
    active: np.ndarray
    c: float
    history: list[Iteration] = field(default_factory=list)
    cycle_detected_at: int | None = None
    factorizations: int = 0
    column_solves: int = 0

    @property
    def iterations(self) -> int:
        return len(self.history)


def default_c(system: ContactSystem) -> float:
    """c of the order of the normal nodal stiffness, so that c (d − G) is a force like Bμ.

    Scaling K by any factor scales c with it, which keeps the iteration unit-free.
    """
    if len(system.normal_dofs) == 0:
        return 1.0
    return float(np.mean(system.stiffness.diagonal()[system.normal_dofs]))


def solve_contact(
    system: ContactSystem,
    *,
    c: float | None = None,
    tolerance: float = 1e-10,
    max_iterations: int = 50,
    backend: str = "auto",
    initial_active: np.ndarray | None = None,
    on_iteration: Callable[[Iteration], None] | None = None,
    safeguard: bool = True,
) -> KernelResult:
    """Run the primal–dual active set iteration until the active set repeats.

    Parameters
    ----------
    system : ContactSystem
    c : float, optional
        Weight of the gap against the force in the active set indicator; default
        :func:`default_c`.
    tolerance : float
        Bound on the relative equilibrium and complementarity residuals at convergence.
    max_iterations : int
    backend : str
        Sparse direct solver backend (see :mod:`contactfem.linalg`).
    initial_active : (m,) bool, optional
        Starting active set; default: the nodes that touch or overlap the obstacle (G ≤ 0).
    on_iteration : callable, optional
        Called with each :class:`Iteration` record (progress reporting).
    safeguard : bool
        When the active set repeats, go on with least-index single changes (default);
        False stops with status CYCLING instead.
    """
    stiffness = sp.csr_matrix(system.stiffness)
    load = np.asarray(system.load, dtype=float)
    normal_dofs = np.asarray(system.normal_dofs, dtype=np.int64)
    gap = np.asarray(system.gap, dtype=float)
    mass = sp.csc_matrix(system.multiplier_mass)
    m = len(normal_dofs)
    c = default_c(system) if c is None else float(c)
    mass_solver = _mass_solver(mass) if m else None

    active = (gap <= 0.0) if initial_active is None else np.asarray(initial_active, dtype=bool).copy()
    linear = ActiveSetSolver(stiffness, load, normal_dofs, gap, backend)
    seen: dict[bytes, int] = {}
    cycle_detected_at: int | None = None
    history: list[Iteration] = []
    displacement = np.zeros(len(load))
    multiplier = np.zeros(m)
    nodal_force = np.zeros(m)
    status, message = Status.MAX_ITERATIONS, f"no convergence in {max_iterations} iterations"

    for iteration in range(1, max_iterations + 1):
        started = time.perf_counter()
        seen[np.packbits(active).tobytes()] = iteration
        displacement, reaction = linear.solve(active)
        reaction_at_contact = np.zeros(m)
        reaction_at_contact[active] = reaction
        multiplier = mass_solver(reaction_at_contact) if m else multiplier
        # The method's own complementarity rows: its multiplier times its mass.
        nodal_force = mass @ multiplier if m else nodal_force
        normal = displacement[normal_dofs]
        indicator = nodal_force + c * (normal - gap)

        force_scale = max(np.abs(load).max(initial=0.0), np.abs(nodal_force).max(initial=0.0),
                          np.abs(stiffness @ displacement).max(initial=0.0), np.finfo(float).tiny)
        threshold = DEGENERACY_TOLERANCE * max(force_scale, np.abs(indicator).max(initial=0.0))
        new_active = (indicator > threshold) | (active & (indicator >= -threshold))

        contact_load = np.zeros(len(load))
        np.add.at(contact_load, normal_dofs, nodal_force)
        equilibrium = np.abs(stiffness @ displacement + contact_load - load).max(initial=0.0) / force_scale
        complementarity = (
            np.abs(nodal_force - np.maximum(0.0, indicator)).max(initial=0.0) / force_scale
        )
        record = Iteration(
            active=int(active.sum()),
            added=int((new_active & ~active).sum()),
            removed=int((active & ~new_active).sum()),
            equilibrium_residual=float(equilibrium),
            complementarity_residual=float(complementarity),
            seconds=time.perf_counter() - started,
        )
        history.append(record)
        if on_iteration is not None:
            on_iteration(record)

        if np.array_equal(new_active, active):
            if equilibrium <= tolerance and complementarity <= tolerance:
                status = Status.CONVERGED
                message = f"converged in {iteration} iterations, {int(active.sum())} active nodes"
                if cycle_detected_at is not None:
                    message += (
                        f"; the active set cycled at iteration {cycle_detected_at}, "
                        "resolved by least-index single changes"
                    )
            else:
                status = Status.INACCURATE
                message = (
                    f"active set settled after {iteration} iterations but the residuals "
                    f"(equilibrium {equilibrium:.1e}, complementarity {complementarity:.1e}) "
                    f"exceed the tolerance {tolerance:.0e}: the linear solves are inaccurate"
                )
            break
        key = np.packbits(new_active).tobytes()
        if key in seen and not safeguard:
            status = Status.CYCLING
            message = (
                f"the active set cycles: iteration {iteration + 1} would repeat the set of "
                f"iteration {seen[key]}"
            )
            break
        if key in seen and cycle_detected_at is None:
            # Plain Newton revisits a set: from now on change one node at a time, the
            # lowest-numbered one whose sign condition fails (Murty's least-index rule),
            # which terminates on P-matrix problems such as ours (S = P K⁻¹ Pᵀ is SPD).
            cycle_detected_at = iteration
        if cycle_detected_at is not None:
            first_wrong = np.flatnonzero(new_active != active)[0]
            new_active = active.copy()
            new_active[first_wrong] = not active[first_wrong]
            if np.packbits(new_active).tobytes() in seen and iteration > cycle_detected_at:
                status = Status.CYCLING
                message = (
                    f"the active set cycles (first detected at iteration {cycle_detected_at}) "
                    "even under the least-index safeguard"
                )
                break
        active = new_active

    return KernelResult(
        status=status,
        message=message,
        displacement=displacement,
        multiplier=multiplier,
        nodal_force=nodal_force,
        active=active,
        c=c,
        history=history,
        cycle_detected_at=cycle_detected_at,
        factorizations=linear.factorizations,
        column_solves=linear.column_solves,
    )


class ActiveSetSolver:
    """Solves K u = F with the normal unknowns of an active set fixed to their gaps,
    reusing one factorisation across active sets.

    The matrix is factorised once with the normals of a reference set A0 fixed. For
    another set A, the nodes of A0 ∖ A (released: their normal unknown becomes free) and
    of A ∖ A0 (added: fixed through a Lagrange multiplier) are few, and the solve reduces
    to a dense system over them: with K00 the factorised block and Z = K00⁻¹ [K0r, E],

        [K_rr − K_r0 Z_r    −K_r0 Z_d] [u_r]   [b_r − K_r0 z0]
        [   −Eᵀ Z_r          −Eᵀ Z_d ] [ μ ] = [G_d − Eᵀ z0 ],   z0 = K00⁻¹ b0,

    then u_0 = z0 − Z_r u_r − Z_d μ. Each column of Z costs one solve with the factor
    and is kept for later iterations; beyond ``max_changes`` changed nodes the matrix is
    factorised anew with the current set as reference.
    """

    def __init__(self, stiffness: sp.csr_matrix, load: np.ndarray, normal_dofs: np.ndarray,
                 gap: np.ndarray, backend: str, max_changes: int = 64) -> None:
        self.stiffness = stiffness
        self.load = load
        self.normal_dofs = normal_dofs
        self.gap = gap
        self.backend = backend
        self.max_changes = max_changes
        self.factorizations = 0
        self.column_solves = 0
        self.reference: np.ndarray | None = None

    def solve(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """u (n,) and the reactions (F − K u) at the normal unknowns of ``active``."""
        changes = 0 if self.reference is None else np.count_nonzero(active != self.reference)
        if self.reference is None or changes > self.max_changes or (changes and self.factor is None):
            self._factorize(active)
        released = np.flatnonzero(self.reference & ~active)
        added = np.flatnonzero(~self.reference & active)
        u = self._solve_changed(released, added)
        fixed = self.normal_dofs[active]
        reaction = self.load[fixed] - self.stiffness[fixed] @ u
        return u, reaction

    def _factorize(self, active: np.ndarray) -> None:
        n = self.stiffness.shape[0]
        fixed = self.normal_dofs[active]
        free = np.ones(n, dtype=bool)
        free[fixed] = False
        self.reference = active.copy()
        self.free = np.flatnonzero(free)
        self.position = np.full(n, -1, dtype=np.int64)
        self.position[self.free] = np.arange(len(self.free))
        rows = self.stiffness[self.free]
        self.rows_free = rows  # K[free, :], reused for the columns of released nodes
        self.factor = factorize(rows[:, self.free], self.backend) if len(self.free) else None
        self.factorizations += 1
        self.fixed_values = np.zeros(n)
        self.fixed_values[fixed] = self.gap[active]
        rhs = self.load[self.free] - rows @ self.fixed_values
        self.base = self.factor.solve(rhs) if self.factor is not None else np.zeros(0)
        self.columns: dict[int, np.ndarray] = {}

    def _columns(self, nodes: np.ndarray) -> np.ndarray:
        """K00⁻¹ K0j for released nodes and K00⁻¹ e_j for added ones, cached per node."""
        missing = [int(j) for j in nodes if int(j) not in self.columns]
        if missing:
            rhs = np.zeros((len(self.free), len(missing)))
            for k, j in enumerate(missing):
                dof = self.normal_dofs[j]
                if self.reference[j]:
                    rhs[:, k] = self.rows_free[:, dof].toarray().ravel()
                else:
                    rhs[self.position[dof], k] = 1.0
            solved = self.factor.solve(rhs)
            solved = solved.reshape(len(self.free), len(missing))
            self.column_solves += len(missing)
            for k, j in enumerate(missing):
                self.columns[j] = solved[:, k]
        if len(nodes) == 0:
            return np.zeros((len(self.free), 0))
        return np.stack([self.columns[int(j)] for j in nodes], axis=1)

    def _solve_changed(self, released: np.ndarray, added: np.ndarray) -> np.ndarray:
        n = self.stiffness.shape[0]
        u = self.fixed_values.copy()
        if self.factor is None:
            return u
        z_r, z_d = self._columns(released), self._columns(added)
        dofs_r = self.normal_dofs[released]
        slots_d = self.position[self.normal_dofs[added]]
        # Released normals lose their fixed value: b0 gains K_0r G_r, so z0 gains Z_r G_r.
        gap_r = self.fixed_values[dofs_r]
        z0 = self.base + z_r @ gap_r
        values = self.fixed_values.copy()
        values[dofs_r] = 0.0
        if len(released) or len(added):
            rows_r = self.stiffness[dofs_r]
            k_r0 = rows_r[:, self.free]
            k_rr = rows_r[:, dofs_r].toarray()
            b_r = self.load[dofs_r] - rows_r @ values
            top = np.hstack([k_rr - k_r0 @ z_r, -(k_r0 @ z_d)])
            bottom = np.hstack([-z_r[slots_d], -z_d[slots_d]])
            rhs = np.concatenate([b_r - k_r0 @ z0, self.gap[added] - z0[slots_d]])
            solution = np.linalg.solve(np.vstack([top, bottom]), rhs)
            u_r, mu = solution[: len(released)], solution[len(released):]
            x0 = z0 - z_r @ u_r - z_d @ mu
            u = values
            u[dofs_r] = u_r
        else:
            x0 = z0
            u = values
        u[self.free] = x0
        return u


def _mass_solver(mass: sp.csc_matrix) -> Callable[[np.ndarray], np.ndarray]:
    """Solve B μ = Λ: a division for a diagonal B, a sparse LU otherwise (B is small)."""
    off_diagonal = mass - sp.diags(mass.diagonal())
    if off_diagonal.count_nonzero() == 0:
        diagonal = mass.diagonal()
        return lambda rhs: rhs / diagonal
    lu = spla.splu(mass)
    return lu.solve
