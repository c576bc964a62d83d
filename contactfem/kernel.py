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
# Iterative refinement of each linear solve: at most this many corrections, stopping once
# the relative residual of the equations is below the target or stops decreasing.
REFINEMENT_STEPS = 3
REFINEMENT_TARGET = 1e-13


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
        Stiffness with contact nodes in normal/tangent coordinates; supports are given by
        ``fixed_dofs`` (or already eliminated).
    load : (n,)
    normal_dofs : (m,) int
        Index of the normal unknown of each contact node.
    gap : (m,)
        Initial gap G of each contact node (negative: the body starts inside the obstacle).
    multiplier_mass : (m, m) sparse SPD
        B: how the method's multiplier μ becomes nodal forces Bμ.
    fixed_dofs : (k,) int, optional
        Unknowns prescribed by supports, kept in the system (no slicing of K).
    fixed_values : (k,), optional
        Their values.
    """

    stiffness: sp.spmatrix
    load: np.ndarray
    normal_dofs: np.ndarray
    gap: np.ndarray
    multiplier_mass: sp.spmatrix
    fixed_dofs: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    fixed_values: np.ndarray = field(default_factory=lambda: np.zeros(0))


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
        Starting active set; default: the nodes that start inside the obstacle (G < 0).
    on_iteration : callable, optional
        Called with each :class:`Iteration` record (progress reporting).
    safeguard : bool
        When the active set repeats, go on with least-index single changes (default);
        False stops with status CYCLING instead.
    """
    normal_dofs = np.asarray(system.normal_dofs, dtype=np.int64)
    gap = np.asarray(system.gap, dtype=float)
    mass = sp.csc_matrix(system.multiplier_mass)
    m = len(normal_dofs)
    c = default_c(system) if c is None else float(c)
    mass_solver = _mass_solver(mass) if m else None

    # The textbook start u = 0, Bμ = 0 gives the indicator c (0 − G): only nodes starting
    # inside the obstacle. Starting from every touching node instead saves a step on
    # bodies pressed flat but makes bending-dominated ones (a slender beam lifting off)
    # release one node per step.
    active = (gap < 0.0) if initial_active is None else np.asarray(initial_active, dtype=bool).copy()
    linear = ActiveSetSolver(system, backend)
    stiffness, load = linear.stiffness, linear.load
    equations = linear.free_rows
    stiffness_norm = linear.norm
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

        # Normwise backward error: residuals are measured against ‖K‖ ‖u‖ + ‖F‖, what a
        # backward-stable direct solve can reach whatever the conditioning (slender bodies
        # have κ ~ (L/H)^4), and which scales with E and the loads like the residual.
        force_scale = max(np.abs(load[equations]).max(initial=0.0) + stiffness_norm * np.abs(displacement).max(initial=0.0),
                          np.abs(nodal_force).max(initial=0.0), np.finfo(float).tiny)
        threshold = DEGENERACY_TOLERANCE * max(force_scale, np.abs(indicator).max(initial=0.0))
        new_active = (indicator > threshold) | (active & (indicator >= -threshold))

        contact_load = np.zeros(len(load))
        np.add.at(contact_load, normal_dofs, nodal_force)
        residual = (stiffness @ displacement + contact_load - load)[equations]
        equilibrium = np.abs(residual).max(initial=0.0) / force_scale
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
    """Solves K u = F with supports and the normal unknowns of an active set fixed,
    reusing one factorisation across active sets.

    Fixed unknowns are not sliced out: their rows and columns are masked to the identity
    inside K's own sparsity pattern, which costs one pass over the nonzeros. The matrix is
    factorised once with the normals of a reference set A0 fixed. For another set A, the
    nodes of A0 ∖ A (released: their normal unknown becomes free) and of A ∖ A0 (added:
    fixed through a Lagrange multiplier) are few, and the solve reduces to a dense system
    over them: with K00 the factorised matrix and Z = K00⁻¹ [K0r, E],

        [K_rr − K_r0 Z_r    −K_r0 Z_d] [u_r]   [b_r − K_r0 z0]
        [   −Eᵀ Z_r          −Eᵀ Z_d ] [ μ ] = [G_d − Eᵀ z0 ],   z0 = K00⁻¹ b0,

    then u = z0 − Z_r u_r − Z_d μ. Each column of Z costs one solve with the factor and
    is kept for later iterations; beyond ``max_changes`` changed nodes the matrix is
    factorised anew with the current set as reference.
    """

    def __init__(self, system: ContactSystem, backend: str, max_changes: int = 64) -> None:
        self.stiffness = sp.csr_matrix(system.stiffness)
        self.stiffness.sort_indices()
        self.load = np.asarray(system.load, dtype=float)
        self.normal_dofs = np.asarray(system.normal_dofs, dtype=np.int64)
        self.gap = np.asarray(system.gap, dtype=float)
        self.backend = backend
        self.max_changes = max_changes
        n = self.stiffness.shape[0]
        self.supported = np.zeros(n, dtype=bool)
        self.supported[system.fixed_dofs] = True
        self.support_values = np.zeros(n)
        self.support_values[system.fixed_dofs] = system.fixed_values
        k = self.stiffness
        self.entry_rows = np.repeat(np.arange(n, dtype=k.indices.dtype), np.diff(k.indptr))
        self.diagonal = np.flatnonzero(self.entry_rows == k.indices)
        if len(self.diagonal) != n:
            raise ValueError("the stiffness matrix must store its whole diagonal")
        self.factorizations = 0
        self.column_solves = 0
        self.reference: np.ndarray | None = None
        self.factor = None
        # ‖K‖∞ over the equations: the scale of backward errors.
        row_sums = np.bincount(self.entry_rows, np.abs(k.data), minlength=n)
        self.norm = float(row_sums[~self.supported].max(initial=0.0))

    @property
    def free_rows(self) -> np.ndarray:
        """Rows of the residual that are equations (not supports), for residual checks."""
        return ~self.supported

    def solve(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """u (n,) and the reactions (F − K u) at the normal unknowns of ``active``."""
        changes = 0 if self.reference is None else np.count_nonzero(active != self.reference)
        if self.reference is None or changes > self.max_changes:
            self._factorize(active)
        released = np.flatnonzero(self.reference & ~active)
        added = np.flatnonzero(~self.reference & active)
        u = self._solve_changed(released, added, self.base, self.load, self.values, self.gap[added])
        # Iterative refinement towards a backward error of round-off, for solves that are not
        # backward stable (SuperLU without pivoting, long chains of Schur updates); it
        # corrects with the same factor and Schur structure while the residual improves.
        equations = ~self.supported
        equations[self.normal_dofs[active]] = False
        scale = max(np.abs(self.load[equations]).max(initial=0.0) + self.norm * np.abs(u).max(initial=0.0),
                    np.finfo(float).tiny)
        residual = np.where(equations, self.load - self.stiffness @ u, 0.0)
        for _ in range(REFINEMENT_STEPS):
            size = np.abs(residual).max(initial=0.0)
            if size <= REFINEMENT_TARGET * scale:
                break
            correction_base = self.factor.solve(np.where(self.free, residual, 0.0))
            correction = self._solve_changed(
                released, added, correction_base, residual, np.zeros_like(u), np.zeros(len(added))
            )
            trial = np.where(equations, residual - self.stiffness @ correction, 0.0)
            if np.abs(trial).max(initial=0.0) >= size:
                break
            u, residual = u + correction, trial
        fixed = self.normal_dofs[active]
        # Active normals satisfy u_n = G through the Schur system only to round-off; they
        # are constraints, so they are returned exactly (complementarity holds exactly).
        u[fixed] = self.gap[active]
        reaction = self.load[fixed] - self.stiffness[fixed] @ u
        return u, reaction

    def _factorize(self, active: np.ndarray) -> None:
        k = self.stiffness
        fixed = self.supported.copy()
        fixed[self.normal_dofs[active]] = True
        self.reference = active.copy()
        self.free = ~fixed
        self.values = self.support_values.copy()
        self.values[self.normal_dofs[active]] = self.gap[active]
        keep = self.free[self.entry_rows] & self.free[k.indices]
        data = np.where(keep, k.data, 0.0)
        data[self.diagonal[fixed]] = 1.0
        masked = sp.csr_matrix((data, k.indices, k.indptr), shape=k.shape)
        self.factor = factorize(masked, self.backend)
        self.factorizations += 1
        rhs = self.load - k @ self.values
        rhs[fixed] = self.values[fixed]
        self.base = self.factor.solve(rhs)
        self.columns: dict[int, np.ndarray] = {}

    def _columns(self, nodes: np.ndarray) -> np.ndarray:
        """K00⁻¹ K0j for released nodes and K00⁻¹ e_j for added ones, cached per node."""
        n = self.stiffness.shape[0]
        missing = [int(j) for j in nodes if int(j) not in self.columns]
        if missing:
            rhs = np.zeros((n, len(missing)))
            for k, j in enumerate(missing):
                dof = self.normal_dofs[j]
                if self.reference[j]:
                    row = self.stiffness[dof]  # = column dof, K being symmetric
                    rhs[row.indices, k] = row.data
                    rhs[~self.free, k] = 0.0
                else:
                    rhs[dof, k] = 1.0
            solved = np.asarray(self.factor.solve(rhs)).reshape(n, len(missing))
            self.column_solves += len(missing)
            for k, j in enumerate(missing):
                self.columns[j] = solved[:, k]
        if len(nodes) == 0:
            return np.zeros((n, 0))
        return np.stack([self.columns[int(j)] for j in nodes], axis=1)

    def _solve_changed(self, released: np.ndarray, added: np.ndarray, base: np.ndarray, load: np.ndarray,
                       fixed_values: np.ndarray, added_values: np.ndarray) -> np.ndarray:
        """Solve for ``load`` with the reference set's fixed unknowns at ``fixed_values``,
        ``released`` freed and ``added`` fixed to ``added_values``; ``base`` is the
        factor's solution for the reference set."""
        if len(released) == 0 and len(added) == 0:
            return base.copy()
        z_r, z_d = self._columns(released), self._columns(added)
        dofs_r = self.normal_dofs[released]
        dofs_d = self.normal_dofs[added]
        # Released normals lose their fixed value: b0 gains K_0r G_r, so z0 gains Z_r G_r.
        z0 = base + z_r @ fixed_values[dofs_r]
        values = fixed_values.copy()
        values[dofs_r] = 0.0
        rows_r = self.stiffness[dofs_r]
        k_r0 = rows_r.multiply(self.free[None, :]).tocsr()
        k_rr = rows_r[:, dofs_r].toarray()
        b_r = load[dofs_r] - rows_r @ values
        top = np.hstack([k_rr - k_r0 @ z_r, -(k_r0 @ z_d)])
        bottom = np.hstack([-z_r[dofs_d], -z_d[dofs_d]])
        rhs = np.concatenate([b_r - k_r0 @ z0, added_values - z0[dofs_d]])
        solution = np.linalg.solve(np.vstack([top, bottom]), rhs)
        u_r, mu = solution[: len(released)], solution[len(released):]
        u = z0 - z_r @ u_r - z_d @ mu
        u[dofs_r] = u_r
        return u


def _mass_solver(mass: sp.csc_matrix) -> Callable[[np.ndarray], np.ndarray]:
    """Solve B μ = Λ: a division for a diagonal B, a sparse LU otherwise (B is small)."""
    off_diagonal = mass - sp.diags(mass.diagonal())
    if off_diagonal.count_nonzero() == 0:
        diagonal = mass.diagonal()
        return lambda rhs: rhs / diagonal
    lu = spla.splu(mass)
    return lu.solve
