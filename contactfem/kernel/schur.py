"""The Schur-update linear solver of the active set iteration: one factorisation, many active sets."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.kernel import costs
from contactfem.kernel.certificate import roundoff_bound
from contactfem.kernel.columns import SchurColumns
from contactfem.kernel.masking import MaskedPattern, row_positions
from contactfem.kernel.measures import IterateMeasures
from contactfem.kernel.system import ContactSystem
from contactfem.linalg import FactorCheck, Factorizer, check_factorization, probe_vector

#: Iterative refinement of each linear solve: at most this many corrections, stopping once
#: the residual of the equations is within their round-off bound or stops decreasing.
REFINEMENT_STEPS = 3


class ActiveSetSolver(SchurColumns, IterateMeasures):
    """Solves K u = F with supports and the normal unknowns of an active set fixed,
    reusing one factorisation across active sets.

    Fixed unknowns are not sliced out: their rows and columns are masked to the identity
    inside K's own sparsity pattern (:class:`contactfem.kernel.masking.MaskedPattern`). The
    matrix is factorised once with the normals of a reference set A0 fixed. For another
    set A, the nodes of A0 ∖ A (released: their normal unknown becomes free) and of A ∖ A0
    (added: fixed through a Lagrange multiplier) are few, and the solve reduces to a dense
    system over them: with K00 the factorised matrix and Z = K00⁻¹ [K0r, E],

        [K_rr − K_r0 Z_r    −K_r0 Z_d] [u_r]   [b_r − K_r0 z0]
        [   −Eᵀ Z_r          −Eᵀ Z_d ] [ μ ] = [G_d − Eᵀ z0 ],   z0 = K00⁻¹ b0,

    then u = z0 − Z_r u_r − Z_d μ (:class:`contactfem.kernel.columns.SchurColumns`). The
    matrix is factorised anew, with the current set as reference, when the cost model
    (:mod:`contactfem.kernel.costs`: counted work at fixed rates, never the clock) finds
    that cheaper than the missing columns and the dense solve. ``schur_updates=False`` (or
    ``max_changes=0``) factorises every set; ``max_changes`` replaces the model by a fixed
    bound on the changed nodes. The columns never hold more than
    :data:`contactfem.kernel.costs.COLUMN_BYTES`; a Schur solve that cannot meet the
    certificate's equilibrium bound (``tolerance``) even after iterative refinement also
    refactorises. Every factorisation is probed for singularity
    (:func:`contactfem.linalg.check_factorization`), the probe's solve riding along with the
    first solve of the factor.
    """

    #: The vectors are whole (not a rank's part): a known translation can be checked here.
    serial = True

    def __init__(self, system: ContactSystem, backend: str, max_changes: int | None = None,
                 tolerance: float = 1e-10, scalable: bool = False, schur_updates: bool = True) -> None:
        self.tolerance = tolerance
        #: Whether the load and prescribed values will be scaled (:meth:`set_load_factor`):
        #: each factorisation then solves for the load and for the gaps separately.
        self.scalable = scalable
        self.load_factor = 1.0
        self.stiffness = sp.csr_matrix(system.stiffness)
        self.stiffness.sort_indices()
        self.load = np.asarray(system.load, dtype=float)
        self.normal_dofs = np.asarray(system.normal_dofs, dtype=np.int64)
        self.gap = np.asarray(system.gap, dtype=float)
        self.backend = backend
        self.max_changes = 0 if not schur_updates else max_changes
        n = self.stiffness.shape[0]
        self.supported = np.zeros(n, dtype=bool)
        self.fixed_dofs = np.asarray(system.fixed_dofs, dtype=np.int64)
        self.supported[self.fixed_dofs] = True
        self.support_values = np.zeros(n)
        self.support_values[self.fixed_dofs] = system.fixed_values
        self.unit_load, self.unit_support_values = self.load, self.support_values
        k = self.stiffness
        self.masking = MaskedPattern(k, self.supported)
        self.factorizations = 0
        self.column_solves = 0
        self.factorizer = Factorizer(
            backend, name="the stiffness matrix with its supports and active contact normals fixed")
        #: Modelled seconds of one column solve within a block (None before any factorisation).
        self.column_seconds: float | None = None
        #: The share of the unknowns a forward column touches (None until counted).
        self.path_share: float | None = None
        self.reference: np.ndarray | None = None
        self.factor = None
        self.checks: list[FactorCheck] = []
        self._solved: np.ndarray | None = None
        self._internal: np.ndarray | None = None
        self._absolute: np.ndarray | None = None
        # |K|, for the round-off bound of the equations: k products and the load and contact force.
        self.absolute = sp.csr_matrix((np.abs(k.data), k.indices, k.indptr), shape=k.shape)
        self.absolute_row_sums = self.absolute @ np.ones(n)
        self.gamma = roundoff_bound(int(np.diff(k.indptr).max(initial=0)) + 2)
        #: The force that strains the body by its whole size (largest stiffness entry times
        #: its size), the force scale of an iterate without any force (see measure); 0 without
        #: a length scale.
        self.force_unit = (self.masking.largest_diagonal * float(system.length_scale)
                           if system.length_scale else 0.0)
        self._probe: np.ndarray | None = None  # the singularity probe, restricted to each set's equations
        #: The last changed set's solution, an affine function of the load factor (see _changed_solution).
        self._affine: _AffineSolution | None = None

    def analyse(self) -> None:
        """Order and analyse the pattern every set is factorised in, ahead of the first set
        (:meth:`contactfem.linalg.Factorizer.analyse`): a caller with other work to do first
        may run this in another thread."""
        self.factorizer.analyse(self.masking.pattern)

    def set_load_factor(self, factor: float) -> None:
        """Multiply the system's load and prescribed values by ``factor`` (a step of a load
        path; the solver must be built with ``scalable=True``). The factorisation and the
        cached columns (K00⁻¹ K0j, K00⁻¹ e_j) depend on neither, and the factor's solution
        for the reference set is linear in the factor, f b_load + b_gap, both parts kept
        from the factorisation: a new factor costs no solve."""
        if not self.scalable:
            raise ValueError("set_load_factor needs an ActiveSetSolver built with scalable=True")
        self.load_factor = float(factor)
        self.load = self.load_factor * self.unit_load
        self.support_values = self.load_factor * self.unit_support_values
        self._solved = self._internal = self._absolute = None
        if self.factor is not None:
            self.values = self.support_values.copy()
            self.values[self.normal_dofs[self.reference]] = self.gap[self.reference]
            self.base = self.load_factor * self.base_parts[0] + self.base_parts[1]

    def solve(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """u (n,) and the reactions (F − K u) at the normal unknowns of ``active``."""
        if self.reference is None or self._refactorize_first(active):
            self._factorize(active)
        else:
            self.dense_spent += costs.dense_seconds(int(np.count_nonzero(active != self.reference)))
        u, reaction, accurate = self._solve_refined(active)
        if not accurate and np.any(active != self.reference):
            # The Schur update carries the errors of the reference factorisation, amplified
            # when that reference is much worse conditioned than the current set (a body held
            # by a tiny clamp until the contact takes hold): factorise the current set itself.
            self._factorize(active)
            u, reaction, _ = self._solve_refined(active)
        return u, reaction

    def _refactorize_first(self, active: np.ndarray) -> bool:
        """Whether factorising ``active`` itself is cheaper than the Schur update from the reference."""
        changed = np.flatnonzero(active != self.reference)
        if self.max_changes is not None:
            return len(changed) > self.max_changes
        missing = int((self.slot_of[changed] < 0).sum())
        stored = self.column_count + missing
        # The full columns, or the forward ones' Schur blocks (their store grows to twice
        # the columns each way).
        held = 8 * (2 * stored) ** 2 if self.forward else 8 * stored * self.stiffness.shape[0]
        if held > costs.COLUMN_BYTES:
            return True
        k = len(changed)
        if self.dense_spent + costs.dense_seconds(k) > self.refactorization_seconds:
            # The dense Schur solves since the factorisation have cost (modelled) as much as
            # another would: it makes every later one small again. Deciding step by step
            # alone, a zone that keeps growing away from its reference (a rough profile's,
            # to 1 900 changed nodes) kept paying ever larger dense solves once its new
            # columns became cheap.
            return True
        if self.forward and callable(getattr(self.factor, "forward_seconds", None)):
            # The backend models its own routes (a converted factor's pattern solve, a
            # blocked sparse solve).
            columns = self.factor.forward_seconds(missing) if missing else 0.0
        else:
            columns = missing * (self.column_seconds or 0.0)
        update = columns + costs.dense_seconds(k)
        if self.forward:
            # u itself: one full solve (its backward half alone where the backend has it);
            # the Schur blocks Wᵀ W of the missing columns against
            # every stored one, at most a column's length each: its elimination-tree path,
            # counted on a sample before any column is stored (on a long strip the paths are
            # many times √n).
            update += self.combine_seconds
            n = len(self.free)
            if self.column_count:
                path = self.forward_store.nnz / self.column_count
            else:
                longest = update + costs.cross_seconds(missing, stored, n)
                if self.path_share is None and longest > self.refactorization_seconds:
                    # Sampling costs a few columns (and, for a supernodal factor, its
                    # conversion): only when even the longest paths could change the answer.
                    self._sample_paths(self.reference)
                path = costs.typical_path(n, self.path_share)
            update += costs.cross_seconds(missing, stored, path)
        return bool(update > self.refactorization_seconds)


    def _solve_refined(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """u, the reactions at the active normals, and whether the equilibrium residual meets
        the certificate's bound (see :class:`Certificate`)."""
        released = np.flatnonzero(self.reference & ~active)
        added = np.flatnonzero(~self.reference & active)
        u = self._changed_solution(released, added)
        fixed = self.normal_dofs[active]
        # Active normals satisfy u_n = G through the Schur system only to round-off; they
        # are constraints, so they are set exactly first (complementarity holds exactly),
        # and K u and |K| |u| serve the refinement, the reactions and the step's scales.
        u[fixed] = self.gap[active]
        equations = ~self.supported
        equations[fixed] = False
        internal = self.stiffness @ u
        with np.errstate(invalid="ignore", over="ignore"):
            absolute = self.absolute @ np.abs(u)
            target = self.gamma * (absolute + np.abs(self.load))[equations].max(initial=0.0)
        residual = self.load - internal
        residual[~equations] = 0.0
        refined = False
        # Iterative refinement down to the round-off bound of the equations, for solves that
        # are not backward stable (SuperLU without pivoting, long chains of Schur updates); it
        # corrects with the same factor and Schur structure while the residual improves (a
        # correction is zero on every fixed unknown, so the active normals stay exact).
        for _ in range(REFINEMENT_STEPS):
            size = np.abs(residual).max(initial=0.0)
            if not size > target:  # also stops on NaN: the certificate reports it
                break
            correction_base = self.factor.solve(np.where(self.free, residual, 0.0))
            correction = self._solve_changed(
                released, added, correction_base, residual, np.zeros_like(u), np.zeros(len(added))
            )
            correction[fixed] = 0.0
            change = self.stiffness @ correction
            trial = np.where(equations, residual - change, 0.0)
            if not np.abs(trial).max(initial=0.0) < size:
                break
            u, residual, internal = u + correction, trial, internal + change
            absolute, refined = None, True
        with np.errstate(invalid="ignore", over="ignore"):
            if absolute is None:
                absolute = self.absolute @ np.abs(u)
            self._solved, self._internal, self._absolute = u, internal, absolute
            reaction = self.load[fixed] - internal[fixed]
            force = (np.abs(self.load).max(initial=0.0) + np.abs(internal).max(initial=0.0)
                     + np.abs(reaction).max(initial=0.0))
            # Unrefined, the residual is F − K u on the equations already (zero elsewhere).
            size = (np.abs(self.load - internal)[equations] if refined else np.abs(residual)).max(initial=0.0)
            accurate = bool(size <= max(self.tolerance * force, target))
        return u, reaction, accurate

    def _changed_solution(self, released: np.ndarray, added: np.ndarray) -> np.ndarray:
        """u for the reference set with ``released`` freed and ``added`` fixed at their gaps.

        Along a load path (``scalable``) u is affine in the load factor f: the Schur
        system's matrix does not depend on it, and its right-hand side is f (load and
        prescribed values) plus the gaps. So a changed set solved at one factor, u1 at f1,
        and met again at another is solved there for its gaps alone, U0; then u = f U1 + U0
        with U1 = (u1 − U0) / f1 serves every later step with that set at no cost. A zone
        that settles a few nodes off the reference (a square under traction, two nodes at
        its ends) would otherwise pay a Schur solve at every step."""
        if not self.scalable or (len(released) == 0 and len(added) == 0):
            return self._solve_changed(released, added, self.base, self.load, self.values, self.gap[added])
        key = (self.factorizations, released.tobytes(), added.tobytes())
        known = self._affine if self._affine is not None and self._affine.key == key else None
        if known is not None and known.at_gaps is not None:
            return self.load_factor * known.per_factor + known.at_gaps
        if known is not None and known.factor not in (self.load_factor, 0.0):
            gaps = self.values - self.support_values  # the reference's gaps, no prescribed values
            at_gaps = self._solve_changed(released, added, self.base_parts[1], np.zeros_like(self.load), gaps,
                                          self.gap[added])
            known.per_factor, known.at_gaps = (known.solution - at_gaps) / known.factor, at_gaps
            return self.load_factor * known.per_factor + at_gaps
        u = self._solve_changed(released, added, self.base, self.load, self.values, self.gap[added])
        self._affine = _AffineSolution(key, self.load_factor, u.copy())
        return u


    def _factorize(self, active: np.ndarray) -> None:
        try:
            self._factorize_set(active)
        except SolverError:
            self.reference = self.factor = None  # nothing to update from: the next set factorises
            raise

    def _factorize_set(self, active: np.ndarray) -> None:
        k = self.stiffness
        fixed = self.supported.copy()
        fixed[self.normal_dofs[active]] = True
        self.reference = active.copy()
        self.free = ~fixed
        self.values = self.support_values.copy()
        self.values[self.normal_dofs[active]] = self.gap[active]
        masked = self.masking.masked(fixed)
        name = self.factorizer.name
        self.factor = None  # a CHOLMOD refactorisation overwrites the previous factor
        self.factor = self.factorizer.factorize(masked, check=False)
        self.factorizations += 1
        #: Modelled seconds of the dense Schur solves taken with this factorisation (see _refactorize_first).
        self.dense_spent = 0.0
        # The fixed unknowns' values reach the equations through their columns of K, that is
        # (K symmetric) their rows: a few thousand rows instead of a product with all of K.
        fixed_dofs = np.flatnonzero(fixed)
        owner, column, value = self._row_entries(fixed_dofs)
        n = k.shape[0]

        def fixed_columns_times(values: np.ndarray) -> np.ndarray:
            return np.bincount(column, weights=value * values[fixed_dofs][owner], minlength=n)

        if self.scalable:
            # The right-hand side is f (F − K s) + (−K g) on the equations and f s + g on the
            # fixed unknowns (s the unit prescribed values, g the gaps of the reference set).
            gaps = self.values - self.support_values
            parts = [self.unit_load - fixed_columns_times(self.unit_support_values), -fixed_columns_times(gaps)]
            parts[0][fixed] = self.unit_support_values[fixed]
            parts[1][fixed] = gaps[fixed]
        else:
            parts = [self.load - fixed_columns_times(self.values)]
            parts[0][fixed] = self.values[fixed]
        # The singularity probe's solve rides along with the first solve of the factor.
        if self._probe is None:
            self._probe = probe_vector(len(parts[0]))
        probe = np.where(self.free, self._probe, 0.0)
        solved = np.asarray(self.factor.solve(np.column_stack([*parts, probe]))).reshape(len(probe), -1)
        #: Modelled seconds of one full solve with the factor, and of factorising another set
        #: of the pattern (the numeric factorisation, the masking, the probe and the first
        #: solves; not the analysis a refactorisation reuses).
        self.solve_seconds, factorize_seconds = costs.factor_figures(self.factorizer)
        self.refactorization_seconds = factorize_seconds + costs.FACTORIZATION_EXTRA_SOLVES * self.solve_seconds
        # With a backend that solves with L alone, the Schur complement comes from sparse
        # forward columns (see SchurColumns._slots), which are not capped; the backend
        # models what they cost when it can (forward_seconds: CHOLMOD called directly, which
        # has two routes), else they are taken as a fixed share of a full solve. Along a
        # load path too, from fewer unknowns whatever the factor (if the paths are short):
        # a set that two steps share costs no solve from the third on (see
        # _changed_solution), and under a rough profile, where thousands of nodes join along
        # the path, full columns made every step refactorise.
        forward_from = (costs.SIMPLICIAL_FORWARD_COLUMNS_FROM if getattr(self.factor, "simplicial", False)
                        or self.scalable else costs.FORWARD_COLUMNS_FROM)
        self.forward = callable(getattr(self.factor, "forward_sparse", None)) and n >= forward_from
        #: Whether the forward route stands only while its paths prove short (see _slots).
        self.checks_paths = self.forward and n < costs.FORWARD_COLUMNS_FROM
        if self.checks_paths and self.path_share is not None:
            self.forward = self.path_share <= costs.FORWARD_PATH_SHARE
        #: Whether u comes from the stored forward columns by a backward solve alone (see
        #: SchurColumns._solve_changed_forward), and the modelled seconds of that solve.
        self.backward = callable(getattr(self.factor, "backward", None))
        self.combine_seconds = (costs.backward_seconds(self.factorizer) if self.backward else self.solve_seconds)
        if self.column_seconds is None:
            self.column_seconds = self.solve_seconds * (costs.FORWARD_COLUMN_SHARE if self.forward else 1.0)
        if self.scalable:
            self.base_parts = (np.ascontiguousarray(solved[:, 0]), np.ascontiguousarray(solved[:, 1]))
            self.base = self.load_factor * self.base_parts[0] + self.base_parts[1]
        else:
            self.base = np.ascontiguousarray(solved[:, 0])
        # ‖K00‖∞ over its equations: the masked rows keep only their free columns, so each
        # row sum of |K| loses its fixed columns (|K| symmetric: the fixed rows).
        free_sums = self.absolute_row_sums - np.bincount(column, weights=np.abs(value), minlength=n)
        norm = float(free_sums[self.free].max(initial=0.0))
        self.checks.append(check_factorization(masked, self.factor, equations=self.free, probe=probe,
                                               solution=solved[:, -1], norm=norm, name=name))
        # The cached columns, side by side in one Fortran-ordered block (n, capacity), so
        # that products with any subset of them run over contiguous memory without copying
        # the columns out: slot_of[j] is node j's column, −1 when not computed yet.
        self.slot_of = np.full(len(self.normal_dofs), -1)
        self.column_count = 0
        if self.forward:
            self.forward_store = sp.csc_matrix((k.shape[0], 0))
            self.scaled_store = sp.csc_matrix((k.shape[0], 0))
            self.gram_store = np.empty((0, 0))
            #: The stored scaled columns, dense over the rows they touch (see _cross_stored).
            self.dense_rows, self.row_place, self.dense_row_count = np.zeros((0, 0)), None, 0
        elif getattr(self, "column_store", None) is None:
            self.column_store = np.empty((k.shape[0], 0), order="F")

    def _row_entries(self, dofs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The entries of K's rows ``dofs``: each one's row (its position in ``dofs``), column
        and value, row by row. Read from K's arrays: a step asks for a few rows, and SciPy's
        row indexing costs more in checks than in copying them."""
        k = self.stiffness
        positions, lengths = row_positions(k.indptr, dofs)
        return np.repeat(np.arange(len(dofs)), lengths), k.indices[positions], k.data[positions]

    def _free_entries(self, owner: np.ndarray, column: np.ndarray,
                      value: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Entries of :meth:`_row_entries` in the reference set's free columns, without zeros (K_r0)."""
        keep = self.free[column] & (value != 0.0)
        return owner[keep], column[keep], value[keep]



@dataclass(eq=False)
class _AffineSolution:
    """A changed set's solution along a load path (:meth:`ActiveSetSolver._changed_solution`):
    ``solution`` at ``factor``, and once met at a second factor u = f ``per_factor`` + ``at_gaps``.
    ``key`` names the reference factorisation and the change."""

    key: tuple
    factor: float
    solution: np.ndarray
    per_factor: np.ndarray | None = None
    at_gaps: np.ndarray | None = None
