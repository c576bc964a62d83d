"""Forward columns W = L⁻¹ P B from CHOLMOD's supernodal factor itself, over the supernodes they reach.

A sparse right-hand side b reaches, in L x = b, only the supernodes on the supernodal
elimination tree's paths from those holding its nonzeros up to the root: the rows of x
outside them stay zero. This module walks those supernodes in order (a parent is numbered
after its children) for a whole block of right-hand sides at once: each supernode's dense
diagonal block is a triangular solve and the rows below it one matrix product, both
through BLAS. CHOLMOD's own routes either convert the supernodal factor to a simplicial
one first (its solve with a pattern, which then reaches column by column) or sweep the
whole factor for each block of four (its sparse solve); this one converts nothing and
reads only the reached blocks.

It reads cholmod_factor's supernodal fields (nsuper, ssize, xsize, super, pi, px, s, x,
is_ll, is_super, itype, xtype, dtype) at the offsets of CHOLMOD 3 to 5's layout on 64-bit
machines, and serves only a factor whose fields read back consistently
(:meth:`SupernodalFactor.read`: an LLᵀ supernodal factor of ``size`` columns with int
indices and real double values, whose pointer arrays end where its sizes say).
"""

from __future__ import annotations

import ctypes

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from contactfem.linalg.cholmod_ctypes import _c_array

#: Byte offsets in cholmod_factor (CHOLMOD 3-5, 64-bit): x (the values), nsuper, ssize,
#: xsize, the pointers super, pi, px, s, and the ints is_ll, is_super, itype, xtype, dtype.
_X, _NSUPER, _SSIZE, _XSIZE = 64, 104, 112, 120
_SUPER, _PI, _PX, _S = 144, 152, 160, 168
_IS_LL, _IS_SUPER, _ITYPE, _XTYPE, _DTYPE = 180, 184, 192, 196, 200
_INT, _REAL, _DOUBLE = 0, 1, 0


class SupernodalFactor:
    """The structure of a supernodal LLᵀ factor (its supernodes' columns, rows and value
    offsets, and their tree), read once per symbolic analysis; the values are read from
    the numeric factor at each solve (a refactorisation numbers them in place).

    Counted for the cost model: :meth:`reach_entries` (the stored entries of the
    supernodes a block reaches), and :attr:`leaf_path_entries` and
    :attr:`leaf_path_supernodes` (the entries and supernodes on the median path from a
    leaf supernode to the root: a block's guess before its columns are known).
    """

    def __init__(self, size: int, first_column: np.ndarray, row_start: np.ndarray, value_start: np.ndarray,
                 rows: np.ndarray) -> None:
        self.size = size
        self.first_column, self.row_start, self.value_start = first_column, row_start, value_start
        self.rows = rows
        nsuper = len(first_column) - 1
        self.columns = np.diff(first_column)
        self.heights = np.diff(row_start)
        self.entries = self.columns.astype(np.int64) * self.heights
        self.owner = np.repeat(np.arange(nsuper), self.columns)
        self.parent = np.full(nsuper, -1, dtype=np.int64)
        below = self.heights > self.columns
        self.parent[below] = self.owner[rows[row_start[:-1][below] + self.columns[below]]]
        path = _root_sums(self.entries, self.parent)
        leaves = np.ones(nsuper, dtype=bool)
        leaves[self.parent[self.parent >= 0]] = False
        self.leaf_path_entries = float(np.median(path[leaves])) if nsuper else 0.0
        self.leaf_path_supernodes = float(np.median(_root_sums(np.ones(nsuper), self.parent)[leaves])) if nsuper else 0.0
        self._place = np.full(size, -1, dtype=np.int64)

    @classmethod
    def read(cls, address: int, size: int) -> "SupernodalFactor | None":
        """The structure of the cholmod_factor at ``address`` (``size`` columns), copied; None
        where it is not a supernodal LLᵀ factor with int indices and real doubles, or its
        fields do not read back as one."""
        def field(offset: int, kind=ctypes.c_size_t):
            return kind.from_address(address + offset).value

        if ctypes.c_size_t.from_address(address).value != size or size == 0:
            return None
        flags = [field(offset, ctypes.c_int) for offset in (_IS_LL, _IS_SUPER, _ITYPE, _XTYPE, _DTYPE)]
        if flags != [1, 1, _INT, _REAL, _DOUBLE]:
            return None
        nsuper, ssize, xsize = field(_NSUPER), field(_SSIZE), field(_XSIZE)
        pointers = [field(offset, ctypes.c_void_p) for offset in (_SUPER, _PI, _PX, _S, _X)]
        if not (0 < nsuper <= size and size <= ssize < 2**31 and xsize < 2**40) or not all(pointers):
            return None
        first_column, row_start, value_start = (_c_array(pointer, ctypes.c_int32, nsuper + 1).astype(np.int64)
                                                for pointer in pointers[:3])
        if (first_column[0], first_column[-1], row_start[0], row_start[-1], value_start[0], value_start[-1]) \
                != (0, size, 0, ssize, 0, xsize) or np.any(np.diff(first_column) < 1):
            return None
        rows = _c_array(pointers[3], ctypes.c_int32, ssize).astype(np.int64)
        if rows.min() < 0 or rows.max() >= size:
            return None
        return cls(size, first_column, row_start, value_start, rows)

    def reach(self, rows: np.ndarray) -> np.ndarray:
        """The supernodes reached from factor rows ``rows``, in ascending (solving) order."""
        reached = np.zeros(len(self.columns), dtype=bool)
        frontier = np.unique(self.owner[rows])
        while len(frontier):
            reached[frontier] = True
            parents = self.parent[frontier]
            parents = np.unique(parents[parents >= 0])
            frontier = parents[~reached[parents]]
        return np.flatnonzero(reached)

    def reach_entries(self, supernodes: np.ndarray) -> int:
        """Stored factor entries of ``supernodes``: what a block reaching them reads."""
        return int(self.entries[supernodes].sum())

    def forward(self, values_address: int, rhs: sp.csc_matrix, supernodes: np.ndarray) -> sp.csc_matrix:
        """W = L⁻¹ b for each column of ``rhs`` (rows already in the factor's order), whose
        nonzeros all lie in ``supernodes`` (:meth:`reach` of its rows), as a CSC matrix
        without the zeros outside each column's own path. ``values_address``: the numeric
        factor's x."""
        k = rhs.shape[1]
        values = _c_array(values_address, ctypes.c_double, int(self.value_start[-1]))
        starts, stops = self.first_column[supernodes], self.first_column[supernodes + 1]
        counts = stops - starts
        offsets = np.cumsum(counts) - counts
        factor_rows = np.repeat(starts - offsets, counts) + np.arange(int(counts.sum()))
        place = self._place
        place[factor_rows] = np.arange(len(factor_rows))
        try:
            x = np.zeros((len(factor_rows), k))
            x[place[rhs.indices], np.repeat(np.arange(k), np.diff(rhs.indptr))] = rhs.data
            for s, top in zip(supernodes.tolist(), offsets.tolist()):
                width, height = int(self.columns[s]), int(self.heights[s])
                first = int(self.value_start[s])
                # Column-major (height × width) block, read row-major as its transpose.
                block = values[first:first + width * height].reshape(width, height)
                solved = sla.solve_triangular(block[:, :width], x[top:top + width], trans="T", lower=False,
                                              check_finite=False)
                x[top:top + width] = solved
                if height > width:
                    below = place[self.rows[self.row_start[s] + width:self.row_start[s + 1]]]
                    x[below] -= block[:, width:].T @ solved
        finally:
            place[factor_rows] = -1
        # Column by column (x transposed), each column's rows ascending, its zeros dropped:
        # the block's other columns' paths are not this one's.
        kept = (x != 0.0).T
        indptr = np.concatenate([[0], np.cumsum(kept.sum(axis=1))])
        indices = np.broadcast_to(factor_rows, kept.shape)[kept]
        return sp.csc_matrix((x.T[kept], indices, indptr), shape=(self.size, k))


def _root_sums(entries: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """Σ of ``entries`` over each node's path to its tree's root (a node's parent numbered
    after it), one pass per level of the tree."""
    total = entries.astype(np.float64).copy()
    above = parent.copy()
    while True:
        has = above >= 0
        if not has.any():
            return total
        total[has] += entries[above[has]]
        above[has] = parent[above[has]]
