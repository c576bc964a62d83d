"""The stiffness in one sparsity pattern for every active set, with fixed rows and columns masked to the identity."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def row_positions(indptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of the entries of CSR ``rows`` (in order) and each row's length."""
    starts, lengths = indptr[rows], indptr[rows + 1] - indptr[rows]
    return np.repeat(starts - np.cumsum(lengths) + lengths, lengths) + np.arange(int(lengths.sum())), lengths


class MaskedPattern:
    """K's pattern without the couplings of the supports, and K masked in it for a set of
    fixed unknowns.

    What is factorised for an active set lives in one pattern, so that a backend's ordering
    and symbolic analysis serve every set. The couplings of the supports are fixed for good
    and are left out of it: kept as stored zeros they would stay edges of the graph the
    ordering sees, and make every factorisation dearer. The contact normals are masked
    inside the pattern: their rows and columns become the identity's.
    """

    def __init__(self, stiffness: sp.csr_matrix, supported: np.ndarray) -> None:
        k = stiffness
        n = k.shape[0]
        row_lengths = np.diff(k.indptr)
        rows = np.repeat(np.arange(n, dtype=k.indices.dtype), row_lengths)
        on_diagonal = rows == k.indices
        if int(np.count_nonzero(on_diagonal)) != n:
            raise ValueError("the stiffness matrix must store its whole diagonal")
        #: The largest diagonal entry of K (a force scale).
        self.largest_diagonal = float(np.abs(k.data[on_diagonal]).max(initial=0.0))
        coupling = (np.repeat(supported, row_lengths) | supported[k.indices]) & ~on_diagonal
        del on_diagonal
        if coupling.any():
            removed = np.zeros(n + 1, dtype=k.indptr.dtype)
            np.cumsum(np.bincount(rows[coupling], minlength=n), out=removed[1:])
            kept = ~coupling
            rows = rows[kept]
            self.pattern = sp.csr_matrix((k.data[kept], k.indices[kept], k.indptr - removed), shape=k.shape)
        else:
            self.pattern = k
        self.entry_rows = rows
        self.diagonal = np.flatnonzero(rows == self.pattern.indices)
        self.longest_row = int(np.diff(self.pattern.indptr).max(initial=0))
        self._masked_matrix: sp.csr_matrix | None = None
        self._masked_fixed: np.ndarray | None = None

    def masked(self, fixed: np.ndarray) -> sp.csr_matrix:
        """K in the factorised pattern with the rows and columns of ``fixed`` masked to the
        identity. The matrix is kept: a new set rewrites only the entries in the rows and
        columns whose state changed (a few thousand against millions)."""
        pattern = self.pattern
        if self._masked_matrix is None:
            # The first set: K's values, then the rows and columns of its fixed unknowns (a
            # few thousand) rewritten like a change, instead of a pass over every entry.
            self._masked_matrix = sp.csr_matrix((pattern.data.copy(), pattern.indices, pattern.indptr),
                                                shape=pattern.shape)
            self._masked_fixed = np.zeros_like(fixed)
        changed = np.flatnonzero(fixed != self._masked_fixed)
        indptr = pattern.indptr
        # Finding the changed rows' mirrors scans up to a row's length per entry; once that
        # is the whole pattern's size (a coarse level's first sets change most contact
        # nodes), one pass over every entry costs less.
        searched = int((indptr[changed + 1] - indptr[changed]).sum()) * self.longest_row
        entries = self._entries_of(changed) if searched < len(pattern.indices) else None
        if entries is None:
            keep = ~fixed[self.entry_rows] & ~fixed[pattern.indices]
            data = np.where(keep, pattern.data, 0.0)
            data[self.diagonal[fixed]] = 1.0
            self._masked_matrix = sp.csr_matrix((data, pattern.indices, pattern.indptr), shape=pattern.shape)
        else:
            rows, columns = self.entry_rows[entries], pattern.indices[entries]
            data = self._masked_matrix.data
            data[entries] = np.where(~fixed[rows] & ~fixed[columns], pattern.data[entries], 0.0)
            data[entries[(rows == columns) & fixed[rows]]] = 1.0
        self._masked_fixed = fixed.copy()
        return self._masked_matrix

    def _entries_of(self, dofs: np.ndarray) -> np.ndarray | None:
        """Positions in the pattern of every entry in the rows and columns of ``dofs`` (the
        pattern is symmetric: an entry (d, j) of row d has its mirror (j, d) in row j);
        None if some mirror is not stored."""
        indptr, indices = self.pattern.indptr, self.pattern.indices
        in_rows, lengths = row_positions(indptr, dofs)
        owners = np.repeat(dofs, lengths)
        partners = indices[in_rows]
        # The mirror's offset in its (sorted) row: scan the at most max-row-length offsets.
        lo, length = indptr[partners], indptr[partners + 1] - indptr[partners]
        mirrors = np.full(len(partners), -1, dtype=np.int64)
        for offset in range(int(length.max(initial=0))):
            hit = (offset < length) & (indices[np.minimum(lo + offset, len(indices) - 1)] == owners)
            mirrors[hit] = lo[hit] + offset
        if (mirrors < 0).any():
            return None
        if 64 * len(in_rows) < len(indices):
            return np.unique(np.concatenate([in_rows, mirrors]))
        # Many rows (a first active set of thousands of nodes): marking beats sorting.
        marked = np.zeros(len(indices), dtype=bool)
        marked[in_rows] = True
        marked[mirrors] = True
        return np.flatnonzero(marked)

