"""The iterative linear solver of the active set iteration: each set's system by CG with algebraic multigrid.

Where the stiffness's factorisation would not fit in memory, each Newton step solves the
system of its active set, K u = F with the supports and the active normals fixed,

    K_ff u_f = F_f − K_fc u_c,    u_c the prescribed values and the active nodes' gaps,

by CG preconditioned with smoothed aggregation (:mod:`contactfem.linalg.amg`), given the
body's rigid motions as near-null space. The fixed unknowns keep their rows and columns
in the operator, reduced to K's own diagonal entry, so that every set has the same
unknowns and the hierarchy built for one set preconditions the next ones (a new set
differs from the last by a few nodes); a set whose CG needs markedly more iterations than
the hierarchy's own set did gets a hierarchy of its own. Each solve starts from the last
set's displacement. There is no factorisation to update, so the Schur-complement updates
of :class:`contactfem.kernel.ActiveSetSolver` do not apply.

CG stops on the largest residual entry of the equations, at :data:`RESIDUAL_SHARE` of what
the certificate allows (its equilibrium tolerance times the force scale) or at the
round-off bound of evaluating the equations, whichever is larger: the certified iterate is
then as good as a direct solve's. The contact reactions are F − K u at the active normals,
exactly as with a factorisation.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.kernel.certificate import roundoff_bound
from contactfem.kernel.measures import IterateMeasures
from contactfem.kernel.system import ContactSystem
from contactfem.linalg import FactorCheck
from contactfem.linalg.amg import AmgSolver, CGRecord

#: CG's target: this share of the certificate's equilibrium bound (tolerance × force scale).
RESIDUAL_SHARE = 1e-2
#: A set whose CG took more than this many times the iterations of the set its hierarchy
#: was built for gets a hierarchy of its own (counted, never timed).
REBUILD_GROWTH = 1.5
#: CG restarts from its last iterate at most this many times when the residual computed
#: afresh (K u, not CG's running residual) misses the target.
RESTARTS = 2
#: What error messages call the system of an active set.
NAME = "the stiffness matrix with its supports and active contact normals fixed"


class IterativeSetSolver(IterateMeasures):
    """Solves K u = F with supports and the normal unknowns of an active set fixed, by CG
    with algebraic multigrid: the interface of :class:`contactfem.kernel.ActiveSetSolver`
    that :func:`contactfem.kernel.solve_contact` uses.

    Parameters
    ----------
    system : ContactSystem
    near_null : (n, j)
        The rigid motions of the body in the system's unknowns (two translations and a
        rotation in 2D): the near-null space of smoothed aggregation.
    tolerance : float
        The certificate's relative tolerance (see :data:`RESIDUAL_SHARE`).

    ``factorizations`` counts the hierarchies built (the set-ups that stand in for
    factorisations), ``records`` holds one :class:`~contactfem.linalg.amg.CGRecord` per solve.
    """

    #: The vectors are whole (not a rank's part): a known translation can be checked here.
    serial = True

    def __init__(self, system: ContactSystem, near_null: np.ndarray, tolerance: float = 1e-10) -> None:
        self.tolerance = tolerance
        k = sp.csr_matrix(system.stiffness)
        k.sort_indices()
        self.stiffness = k
        n = k.shape[0]
        self.load = np.asarray(system.load, dtype=float)
        self.normal_dofs = np.asarray(system.normal_dofs, dtype=np.int64)
        self.gap = np.asarray(system.gap, dtype=float)
        self.supported = np.zeros(n, dtype=bool)
        self.supported[np.asarray(system.fixed_dofs, dtype=np.int64)] = True
        self.support_values = np.zeros(n)
        self.support_values[np.asarray(system.fixed_dofs, dtype=np.int64)] = system.fixed_values
        self.near_null = np.asarray(near_null, dtype=float)
        if self.near_null.shape[0] != n:
            raise ValueError(f"near_null has {self.near_null.shape[0]} rows for {n} unknowns")
        self.absolute = sp.csr_matrix((np.abs(k.data), k.indices, k.indptr), shape=k.shape)
        self.gamma = roundoff_bound(int(np.diff(k.indptr).max(initial=0)) + 2)
        diagonal = k.diagonal()
        #: ‖K‖∞, at least that of every set's operator (for the condition estimate).
        self.norm = float((self.absolute @ np.ones(n)).max(initial=0.0))
        self.force_unit = (float(np.abs(diagonal).max(initial=0.0)) * float(system.length_scale)
                           if system.length_scale else 0.0)
        self.factorizations = 0
        self.column_solves = 0
        self.records: list[CGRecord] = []
        self.hierarchies: list[dict] = []
        self.checks: list[FactorCheck] = []
        self._amg: AmgSolver | None = None
        self._built_iterations: int | None = None
        self._rebuild = True
        self._solved: np.ndarray | None = None
        self._internal: np.ndarray | None = None
        self._absolute: np.ndarray | None = None

    def analyse(self) -> None:
        """Nothing to make ahead: the hierarchy depends on the first set."""
        return None

    def set_load_factor(self, factor: float) -> None:
        raise ValueError("load paths are not solved with the iterative solver")

    @property
    def figures(self) -> dict:
        """report.json's ``solver.linear``: every CG solve and every hierarchy built."""
        iterations = [record.iterations for record in self.records]
        return {"method": "cg with smoothed-aggregation algebraic multigrid (pyamg), rigid motions as near-null space",
                "residual_share": RESIDUAL_SHARE, "solves": [record.to_dict() for record in self.records],
                "iterations": int(sum(iterations)), "hierarchies": list(self.hierarchies)}

    def solve(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """u (n,) and the reactions (F − K u) at the normal unknowns of ``active``."""
        fixed = self.supported.copy()
        fixed[self.normal_dofs[active]] = True
        values = np.where(self.supported, self.support_values, 0.0)
        values[self.normal_dofs[active]] = self.gap[active]
        equations = ~fixed
        rhs = np.where(equations, self.load - self.stiffness @ values, 0.0)
        # The operator is handed over whole: the hierarchy keeps it in node blocks, and no
        # second copy, as large as the operator itself, stays referenced here.
        amg = self._hierarchy(self._operator(fixed), fixed)
        start = None if self._solved is None else np.where(equations, self._solved, 0.0)
        target = RESIDUAL_SHARE * self.tolerance * float(np.abs(rhs).max(initial=0.0))
        x, record = amg.solve(rhs, target, start)
        iterations = record.iterations
        for attempt in range(RESTARTS + 1):
            u = np.where(equations, x, values)
            internal = self.stiffness @ u
            with np.errstate(invalid="ignore", over="ignore"):
                absolute = self.absolute @ np.abs(u)
                reaction = self.load[~equations] - internal[~equations]
                force = (np.abs(self.load).max(initial=0.0) + np.abs(internal).max(initial=0.0)
                         + np.abs(reaction).max(initial=0.0))
                floor = self.gamma * (absolute + np.abs(self.load))[equations].max(initial=0.0)
                size = np.abs(self.load - internal)[equations].max(initial=0.0)
            wanted = max(RESIDUAL_SHARE * self.tolerance * force, floor)
            if not size > wanted or attempt == RESTARTS:  # also stops on NaN: the certificate reports it
                break
            x, again = amg.solve(rhs, 0.5 * wanted, x)
            iterations += again.iterations
        scale = float(np.abs(rhs).max(initial=0.0)) or 1.0
        self.records.append(CGRecord(iterations, record.initial_residual, float(size) / scale))
        self._after_solve(iterations, x, scale, float(size) / scale)
        u[self.normal_dofs[active]] = self.gap[active]
        self._solved, self._internal, self._absolute = u, internal, absolute
        return u, self.load[self.normal_dofs[active]] - internal[self.normal_dofs[active]]

    def _operator(self, fixed: np.ndarray) -> sp.csr_matrix:
        """K with the rows and columns of ``fixed`` reduced to K's diagonal entry."""
        k = self.stiffness
        n = k.shape[0]
        rows = np.repeat(np.arange(n, dtype=k.indices.dtype), np.diff(k.indptr))
        keep = (rows == k.indices) | ~(fixed[rows] | fixed[k.indices])
        keep &= k.data != 0.0
        indptr = np.zeros(n + 1, dtype=k.indptr.dtype)
        np.cumsum(np.bincount(rows[keep], minlength=n), out=indptr[1:])
        del rows
        return sp.csr_matrix((k.data[keep], k.indices[keep], indptr), shape=k.shape)

    def _hierarchy(self, matrix: sp.csr_matrix, fixed: np.ndarray) -> AmgSolver:
        """The hierarchy to precondition ``matrix`` with: the last one, or a new one built
        for it when there is none or the last set's CG took too many iterations."""
        if self._amg is not None and not self._rebuild:
            self._amg.set_operator(matrix)
            return self._amg
        self._amg = None  # free the old hierarchy before building the next
        near_null = np.where(fixed[:, None], 0.0, self.near_null)
        self._amg = AmgSolver(matrix, near_null, NAME)
        self.factorizations += 1
        self.hierarchies.append(self._amg.figures.to_dict())
        self._built_iterations = None
        self._rebuild = False
        return self._amg

    def _after_solve(self, iterations: int, x: np.ndarray, scale: float, residual: float) -> None:
        """Count the solve against its hierarchy's, and record the condition estimate
        ‖K‖∞ ‖x‖∞ / ‖b‖∞ of the solve (an estimate of κ∞ of the set's operator, as a
        factorisation's probe gives)."""
        if self._built_iterations is None:
            self._built_iterations = iterations
        elif iterations > REBUILD_GROWTH * max(self._built_iterations, 1):
            self._rebuild = True
        condition = max(self.norm * float(np.abs(x).max(initial=0.0)) / scale, 1.0)
        self.checks.append(FactorCheck(residual=residual, condition=condition))
        if not np.isfinite(condition):
            raise SolverError(f"{NAME} is singular: CG gives non-finite values")
