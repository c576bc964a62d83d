"""The Schur columns of :class:`contactfem.kernel.schur.ActiveSetSolver`: the changed nodes' solves with the factor, kept across steps.

A changed node's column is K00⁻¹ K0j (a released node) or K00⁻¹ e_j (an added one), full
length, kept side by side in one Fortran-ordered block; or, with a backend that solves
with L alone (CHOLMOD), W = L⁻¹ P [K0r, E], sparse along the elimination tree's paths,
whose Schur blocks are Wᵀ D⁻¹ W and whose u costs one full solve.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.kernel import costs
from contactfem.linalg import solve_sparse_columns


class SchurColumns:
    """The column store and the Schur-complement solve of a changed active set (a mixin of
    :class:`contactfem.kernel.schur.ActiveSetSolver`, whose factor, reference set and row
    accessors it reads)."""

    def _sample_paths(self, active: np.ndarray) -> None:
        """Count :attr:`path_share` once from the columns of e_j at an even sample of the
        free contact normals (a fixed one's column is e_j itself): for a cost decision that
        needs it before any column is taken (:meth:`_slots` counts the first ones)."""
        free = self.normal_dofs[~active]
        if self.path_share is not None or len(free) == 0:
            return  # measured, or nothing to measure this time
        sample = np.unique(free[np.linspace(0, len(free) - 1, costs.PATH_SAMPLES).astype(np.int64)])
        n = self.stiffness.shape[0]
        rhs = sp.csc_matrix((np.ones(len(sample)), (sample, np.arange(len(sample)))), shape=(n, len(sample)))
        forward, _ = self.factor.forward_sparse(rhs)
        self.path_share = forward.nnz / len(sample) / n


    def _slots(self, nodes: np.ndarray) -> np.ndarray:
        """The slots of K00⁻¹ K0j (released nodes) and K00⁻¹ e_j (added ones) in the column
        block, computing the missing ones as one block of solves."""
        n = self.stiffness.shape[0]
        missing = np.unique(nodes[self.slot_of[nodes] < 0])
        if len(missing):
            # The right-hand sides are sparse: K0j (the row of a released normal, K being
            # symmetric, restricted to the free unknowns) or e_j (an added one).
            dofs = self.normal_dofs[missing]
            released = self.reference[missing]
            owner, column, value = self._free_entries(*self._row_entries(dofs[released]))
            columns = np.concatenate([np.flatnonzero(released)[owner], np.flatnonzero(~released)])
            entries = np.concatenate([column, dofs[~released]])
            values = np.concatenate([value, np.ones(int((~released).sum()))])
            rhs = sp.csc_matrix((values, (entries, columns)), shape=(n, len(missing)))
            count = self.column_count
            if self.forward:
                forward, scaled = self.factor.forward_sparse(rhs)
                if self.checks_paths and count == 0:
                    # The paths counted on the first columns a step asks for (unless a cost
                    # decision sampled them first), instead of a sample solved for them
                    # alone: a long thin mesh's columns go on as full ones.
                    if self.path_share is None:
                        self.path_share = forward.nnz / len(missing) / n
                    if self.path_share > costs.FORWARD_PATH_SHARE:
                        self.forward = False
                        self.column_store = np.empty((n, 0), order="F")
            if self.forward:
                self.forward_store = sp.hstack([self.forward_store, forward], format="csc")
                # An LLᵀ factor has D = I: the scaled columns are the forward ones, kept once.
                self.scaled_store = (self.forward_store if scaled is forward
                                     else sp.hstack([self.scaled_store, scaled], format="csc"))
                self._extend_gram(forward, scaled, count)
            else:
                solved = solve_sparse_columns(self.factor, rhs)
                if count + len(missing) > self.column_store.shape[1]:
                    grown = np.empty((n, max(16, 2 * (count + len(missing)))), order="F")
                    grown[:, :count] = self.column_store[:, :count]
                    self.column_store = grown
                self.column_store[:, count:count + len(missing)] = solved
            self.column_solves += len(missing)
            self.slot_of[missing] = np.arange(count, count + len(missing))
            self.column_count = count + len(missing)
        return self.slot_of[nodes]

    def _extend_gram(self, forward: sp.csc_matrix, scaled: sp.csc_matrix, count: int) -> None:
        """Add the new forward columns' rows and columns to the Schur blocks of every stored
        column, Wᵀ S (S = D⁻¹ W, W itself for an LLᵀ factor): a step then takes its blocks
        from the store instead of multiplying all its changed nodes' columns again (about
        as many as the last step's, with a handful new)."""
        total = count + forward.shape[1]
        if total > self.gram_store.shape[0]:
            grown = np.empty((2 * total, 2 * total))
            grown[:count, :count] = self.gram_store[:count, :count]
            self.gram_store = grown
        block = self._cross_stored(forward, scaled, count)  # (new, all): rows count ... total - 1
        block[:, count:] = 0.5 * (block[:, count:] + block[:, count:].T)  # symmetric to round-off
        self.gram_store[count:total, :total] = block
        self.gram_store[:count, count:total] = block[:, :count].T

    def _cross_stored(self, forward: sp.csc_matrix, scaled: sp.csc_matrix, count: int) -> np.ndarray:
        """Wᵀ S of the new forward columns against every stored scaled one, new ones included
        (:func:`cross`), from a dense copy of the stored columns over the rows any of them
        touches (:attr:`dense_rows`, row-major): the new columns' rows are gathered from it
        whole, instead of every stored entry being mapped onto them at every step (a Hertz
        platen's 123 columns along its path: 420 000 entries, over 3 300 rows a block). The
        copy goes while it would pass :data:`contactfem.kernel.costs.DENSE_ROWS_BYTES`."""
        k, total = forward.shape[1], count + forward.shape[1]
        if self.dense_rows is not None and not dense_pays(forward, self.scaled_store):
            self.dense_rows = self.row_place = None  # sparse blocks: the copy would not pay again
        if self.dense_rows is None:
            return cross(forward, self.scaled_store)
        if self.row_place is None:
            self.row_place = np.full(self.stiffness.shape[0], -1, dtype=np.int64)
        left_rows = np.unique(forward.indices)
        touched = left_rows if scaled is forward else np.union1d(left_rows, scaled.indices)
        fresh = touched[self.row_place[touched] < 0]
        stored_rows = self.dense_row_count
        rows, columns = stored_rows + len(fresh), total
        if rows > self.dense_rows.shape[0] or columns > self.dense_rows.shape[1]:
            shape = (max(rows, 2 * self.dense_rows.shape[0]) if rows > self.dense_rows.shape[0]
                     else self.dense_rows.shape[0],
                     max(columns, 2 * self.dense_rows.shape[1], 16) if columns > self.dense_rows.shape[1]
                     else self.dense_rows.shape[1])
            if 8 * shape[0] * shape[1] > costs.DENSE_ROWS_BYTES:
                self.dense_rows = self.row_place = None
                return cross(forward, self.scaled_store)
            grown = np.zeros(shape)
            grown[:self.dense_rows.shape[0], :self.dense_rows.shape[1]] = self.dense_rows
            self.dense_rows = grown
        self.row_place[fresh] = np.arange(stored_rows, rows)
        self.dense_row_count = rows
        self.dense_rows[self.row_place[scaled.indices], count + _entry_columns(scaled)] = scaled.data
        dense_left = np.zeros((len(left_rows), k))
        dense_left[np.searchsorted(left_rows, forward.indices), _entry_columns(forward)] = forward.data
        return dense_left.T @ self.dense_rows[self.row_place[left_rows], :total]

    def _combine(self, slots: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Σ_k weights[k] · column(slots[k]) (n,), one matrix-vector product over the block."""
        if len(slots) == 0:
            return np.zeros(self.stiffness.shape[0])
        if 4 * len(slots) < self.column_count:
            return self.column_store[:, slots] @ weights
        full = np.zeros(self.column_count)
        np.add.at(full, slots, weights)
        return self.column_store[:, :self.column_count] @ full

    def _rows(self, rows: np.ndarray, slots: np.ndarray) -> np.ndarray:
        """Entries ``rows`` of the columns ``slots`` (len(rows), len(slots))."""
        return self.column_store[rows][:, slots]


    def _solve_changed(self, released: np.ndarray, added: np.ndarray, base: np.ndarray, load: np.ndarray,
                       fixed_values: np.ndarray, added_values: np.ndarray) -> np.ndarray:
        """Solve for ``load`` with the reference set's fixed unknowns at ``fixed_values``,
        ``released`` freed and ``added`` fixed to ``added_values``; ``base`` is the
        factor's solution for the reference set."""
        if len(released) == 0 and len(added) == 0:
            return base.copy()
        slots = self._slots(np.concatenate([released, added]))
        if self.forward:
            return self._solve_changed_forward(released, added, slots, base, load, fixed_values, added_values)
        s_r, s_d = slots[:len(released)], slots[len(released):]
        dofs_r = self.normal_dofs[released]
        dofs_d = self.normal_dofs[added]
        # Released normals lose their fixed value: b0 gains K_0r G_r, so z0 gains Z_r G_r.
        z0 = base + self._combine(s_r, fixed_values[dofs_r])
        k_r0, k_rr, b_r = self._released_rows(dofs_r, load, fixed_values)
        # K_r0 Z touches only the rows of Z where K_r0 has entries: a few per released node.
        touched = np.unique(k_r0.indices)
        k_touched = k_r0[:, touched]
        top = np.hstack([k_rr - k_touched @ self._rows(touched, s_r), -(k_touched @ self._rows(touched, s_d))])
        bottom = np.hstack([-self._rows(dofs_d, s_r), -self._rows(dofs_d, s_d)])
        rhs = np.concatenate([b_r - k_r0 @ z0, added_values - z0[dofs_d]])
        u_r, mu = self._solve_schur(top, bottom, rhs, len(released), len(added))
        u = z0 - self._combine(slots, np.concatenate([u_r, mu]))
        u[dofs_r] = u_r
        return u

    def _released_rows(self, dofs_r: np.ndarray, load: np.ndarray,
                       fixed_values: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
        """The released normals' equations: K_r0 (their rows on the reference set's free
        unknowns), K_rr and b_r = F_r − K_r· (fixed values, the released ones now free)."""
        n, r = self.stiffness.shape[0], len(dofs_r)
        owner, column, value = self._row_entries(dofs_r)
        # Each entry's column among the released normals, if it is one (a search among the
        # r of them, not a map over all n unknowns: this runs at every step).
        order = np.argsort(dofs_r)
        in_order = dofs_r[order]
        at = np.minimum(np.searchsorted(in_order, column), r - 1)
        among = in_order[at] == column
        k_rr = np.zeros((r, r))
        k_rr[owner[among], order[at[among]]] = value[among]
        # The released normals' own values are unknowns now: only the others' enter b_r.
        known = np.where(among, 0.0, value * fixed_values[column])
        b_r = load[dofs_r] - np.bincount(owner, weights=known, minlength=r)
        owner, column, value = self._free_entries(owner, column, value)
        starts = np.zeros(r + 1, dtype=np.int64)
        np.cumsum(np.bincount(owner, minlength=r), out=starts[1:])
        return sp.csr_matrix((value, column, starts), shape=(r, n)), k_rr, b_r

    @staticmethod
    def _solve_schur(top: np.ndarray, bottom: np.ndarray, rhs: np.ndarray, released: int,
                     added: int) -> tuple[np.ndarray, np.ndarray]:
        """The Schur system [top; bottom] [u_r; μ] = rhs of ``released`` freed and ``added``
        fixed normals, split into u_r and μ."""
        try:
            solution = np.linalg.solve(np.vstack([top, bottom]), rhs)
        except np.linalg.LinAlgError as error:
            raise SolverError(
                f"the stiffness matrix is singular once {released} contact nodes are released and "
                f"{added} added (Schur complement: {error}); is part of the body held only by contact?"
            ) from error
        return solution[:released], solution[released:]

    def preview(self, active: np.ndarray, watched: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """What the set ``active`` would show Newton's update without its displacement:
        (reaction, slack) (m,) each, NaN where not known. Its Schur system alone (no
        backward solve, no product with K) gives the reactions of the nodes it adds to the
        reference set (their multipliers μ) and the slack of the nodes it releases (u_r);
        and the slack of ``watched`` nodes outside both sets, from their forward columns
        W_j = L⁻¹ P e_j: u_j = base_j + W_jᵀ D⁻¹ W y, read from the stored Schur blocks.
        A watched node's column is the one it needs once it joins. None where the update
        would refactorise, or the columns are full ones (no blocks to read)."""
        if self.factor is None or not self.forward or self._refactorize_first(active):
            return None
        m = len(self.normal_dofs)
        released = np.flatnonzero(self.reference & ~active)
        added = np.flatnonzero(~self.reference & active)
        watched = np.unique(watched)
        watched = watched[~self.reference[watched] & ~active[watched]]
        changed = len(released) + len(added)
        if self._preview_seconds(watched, changed) > costs.START_CHECK_SHARE * self.combine_seconds:
            return None
        slots = self._slots(np.concatenate([released, added, watched]))
        if not self.forward:  # the paths proved long: the columns went on as full ones
            return None
        reaction, slack = np.full(m, np.nan), np.full(m, np.nan)
        seen = self.base[self.normal_dofs[watched]]
        if changed:
            u_r, mu, weights, _ = self._schur_forward(released, added, slots[:changed], self.base, self.load,
                                                      self.values, self.gap[added])
            reaction[added], slack[released] = mu, u_r - self.gap[released]
            seen = seen + self.gram_store[np.ix_(slots[changed:], slots[:changed])] @ weights
        slack[watched] = seen - self.gap[watched]
        return reaction, slack

    def _preview_seconds(self, nodes: np.ndarray, changed: int) -> float:
        """Modelled seconds :meth:`preview` adds to a step watching ``nodes``, with
        ``changed`` nodes in its Schur system: the watched nodes' missing forward columns,
        their Schur blocks against the stored ones (each column its counted path) and the
        dense solve (the changed nodes' columns the step needs anyway)."""
        missing = int((self.slot_of[nodes] < 0).sum())
        if not missing:
            return costs.dense_seconds(changed)
        columns = (self.factor.forward_seconds(missing) if callable(getattr(self.factor, "forward_seconds", None))
                   else missing * (self.column_seconds or 0.0))
        path = (self.forward_store.nnz / self.column_count if self.column_count
                else costs.typical_path(self.stiffness.shape[0], self.path_share))
        return columns + costs.cross_seconds(missing, self.column_count + missing, path) + costs.dense_seconds(changed)

    def _solve_changed_forward(self, released: np.ndarray, added: np.ndarray, slots: np.ndarray, base: np.ndarray,
                               load: np.ndarray, fixed_values: np.ndarray, added_values: np.ndarray) -> np.ndarray:
        """:meth:`_solve_changed` from sparse forward columns: with C = [K0r, E_d] (the
        released nodes' columns of K on the free unknowns, the added nodes' unit vectors)
        and K00 = Pᵀ L D Lᵀ P, Cᵀ K00⁻¹ C = Wᵀ D⁻¹ W for W = L⁻¹ P C, whose columns are
        sparse; the Schur system is the same, and u = z0 − K00⁻¹ C [u_r; μ] costs one full
        solve instead of a product with full-length columns, or only its backward half where
        the backend solves with Lᵀ alone: K00⁻¹ C y = Pᵀ L⁻ᵀ (D⁻¹ W y), the forward half being
        the stored columns already."""
        dofs_r = self.normal_dofs[released]
        u_r, mu, weights, k_r0 = self._schur_forward(released, added, slots, base, load, fixed_values, added_values)
        if self.backward:
            u = base + self.factor.backward(self.scaled_store[:, slots] @ weights)
        else:
            combined = k_r0.T @ weights[:len(released)]
            combined[self.normal_dofs[added]] -= mu
            u = base + np.asarray(self.factor.solve(combined), dtype=float).reshape(len(base))
        u[dofs_r] = u_r
        return u

    def _schur_forward(self, released: np.ndarray, added: np.ndarray, slots: np.ndarray, base: np.ndarray,
                       load: np.ndarray, fixed_values: np.ndarray,
                       added_values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, sp.csr_matrix]:
        """The Schur system of :meth:`_solve_changed_forward` solved from the stored blocks:
        u_r, μ, the weights y = [G_r − u_r; −μ] with u = base + K00⁻¹ C y, and K_r0."""
        r = len(released)
        dofs_r = self.normal_dofs[released]
        dofs_d = self.normal_dofs[added]
        gram = self.gram_store[np.ix_(slots, slots)]
        released_values = fixed_values[dofs_r]
        k_r0, k_rr, b_r = self._released_rows(dofs_r, load, fixed_values)
        # z0 = base + K00⁻¹ K0r G_r: the released normals lose their fixed values.
        top = np.hstack([k_rr - gram[:r, :r], -gram[:r, r:]])
        bottom = np.hstack([-gram[r:, :r], -gram[r:, r:]])
        rhs = np.concatenate([b_r - (k_r0 @ base + gram[:r, :r] @ released_values),
                              added_values - (base[dofs_d] + gram[r:, :r] @ released_values)])
        u_r, mu = self._solve_schur(top, bottom, rhs, r, len(added))
        return u_r, mu, np.concatenate([released_values - u_r, -mu]), k_r0


def cross(left: sp.csc_matrix, right: sp.csc_matrix) -> np.ndarray:
    """leftᵀ right for sparse forward columns, dense (k_left, k_right).

    The columns share the rows near the elimination tree's root and little else: the rows
    that an eighth of the right-hand columns or more touch go through BLAS as dense blocks,
    the others through a sparse product. A row in the sparse product costs about its two
    counts' product, in the dense block the two column counts.
    """
    k = right.shape[1]
    if left.shape[1] * (left.shape[0] + right.nnz) <= costs.DENSE_CROSS_ENTRIES:
        # A few new columns: rightᵀ times them made dense, one pass over right's entries
        # per column.
        return np.asarray(right.T @ left.toarray()).T
    counts = np.bincount(right.indices, minlength=right.shape[0])
    shared = counts >= max(1, k // 8)
    if 8 * int(shared.sum()) * (k + left.shape[1]) > costs.COLUMN_BYTES:
        shared[:] = False
    heavy = np.flatnonzero(shared)
    product = left[heavy].toarray().T @ right[heavy].toarray()
    if len(heavy) < int(np.count_nonzero(counts)):
        # left without the shared rows' entries, selected from its arrays (cheaper than a
        # product with a diagonal mask).
        light_entries = ~shared[left.indices]
        kept_before = np.concatenate([[0], np.cumsum(light_entries)])
        light = sp.csc_matrix((left.data[light_entries], left.indices[light_entries], kept_before[left.indptr]),
                              shape=left.shape)
        product += (light.T @ right).toarray()
    return product


def dense_pays(left: sp.csc_matrix, right: sp.csc_matrix, rows: int | None = None) -> bool:
    """Whether leftᵀ right is cheaper densely over the ``rows`` left touches than as a sparse
    product, by counts: the dense flops against the sparse product's pairs of entries that
    share a row, weighed by :data:`contactfem.kernel.costs.DENSE_PRODUCT_SHARE`."""
    n = left.shape[0]
    rows = len(np.unique(left.indices)) if rows is None else rows
    pairs = float(np.bincount(left.indices, minlength=n).astype(float) @ np.bincount(right.indices, minlength=n))
    return 2.0 * rows * left.shape[1] * right.shape[1] <= costs.DENSE_PRODUCT_SHARE * pairs


def _entry_columns(matrix: sp.csc_matrix) -> np.ndarray:
    """The column of each stored entry of a CSC matrix, in storage order."""
    return np.repeat(np.arange(matrix.shape[1]), np.diff(matrix.indptr))
