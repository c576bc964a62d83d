"""CHOLMOD called directly through ctypes in the library cvxopt's wheel bundles: the
``cholmod`` backend's fastest route, quarantined.

What it assumes, and where that is checked:

- a CHOLMOD shared library inside cvxopt's wheel (``cvxopt.libs/*cholmod*`` beside the
  package, or ``.libs`` / ``.dylibs`` inside it), loaded after ``cvxopt.cholmod`` has
  loaded its dependencies (:func:`~contactfem.linalg.cholmod_ctypes.cholmod_library`);
- CHOLMOD's C interface with 32-bit integer indices (``cholmod_start``, ``cholmod_analyze``,
  ``cholmod_factorize``, ``cholmod_solve``, ``cholmod_spsolve``, ``cholmod_solve2``,
  ``cholmod_copy_factor``, the ``cholmod_free_*``), so matrices of fewer than 2**31
  stored entries (:func:`serves`);
- the layout of cholmod_sparse and cholmod_dense declared in
  :mod:`contactfem.linalg.cholmod_ctypes`, and the byte offsets of the fields of
  cholmod_common and cholmod_factor read or written there, those of CHOLMOD 3 on a 64-bit
  machine (the wheel bundles CHOLMOD 3.0.6). Checked at load: cholmod_start's defaults must
  read back at the offsets written (``_COMMON_DEFAULTS``), else the library is never
  written into and every factorisation goes through cvxopt's interface; and each factor's
  size and kind must read back as this matrix's before its fields are trusted.

cvxopt's interface (:class:`~contactfem.linalg.cholmod_cvxopt.CvxoptCholmodFactor`) gives
the same factor and the same solves; it is the fallback wherever an assumption fails.
"""

from __future__ import annotations

import ctypes
import weakref

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.linalg.cholmod_ctypes import (
    _DENSE_P,
    _DTYPE_DOUBLE,
    _FACTOR_MINOR,
    _FACTOR_PERM,
    _SPARSE_P,
    _SYS_A,
    _SYS_L,
    _SYS_LT,
    _SYS_P,
    _SYS_PT,
    _XTYPE_REAL,
    CholmodLibrary,
    _c_array,
    _DenseStruct,
    _SparseStruct,
    cholmod_library,
    factor_counts,
)
from contactfem.linalg.costs import MODEL, FactorCost, cholesky_flops, estimated_flops
from contactfem.linalg.storage import canonical_csr
from contactfem.linalg.supernodal import _X as _SUPERNODAL_X
from contactfem.linalg.supernodal import SupernodalFactor


class DirectAnalysis:
    """What a later matrix of the same pattern reuses: CHOLMOD's symbolic factor and the
    cholmod_common it was made with, for the pattern (indptr, indices) it was computed
    from; and the latest numeric factor made from it. Each factorisation numbers a fresh
    copy of the symbolic factor after a solve with a sparse right-hand side, which converts
    its factor to a simplicial one in place (whose refactorisation would be a slow
    simplicial LDLᵀ), and refactorises the previous one in place otherwise; the previous
    one is freed first. Before the first such solve converts a supernodal factor, a copy
    of it is kept for the dense solves (:meth:`keep_supernodal`: a supernodal solve runs
    through BLAS, a simplicial one entry by entry), and serves as the next factorisation's
    factor. Freed with it."""

    def __init__(self, library: CholmodLibrary, common: ctypes.Array, symbolic: int,
                 indptr: np.ndarray, indices: np.ndarray) -> None:
        self.library, self.common, self.symbolic = library, common, symbolic
        self.indptr, self.indices = indptr, indices
        #: The numeric factor (0 when none) and how many have been made: a factorisation
        #: whose generation is not the latest was freed and may not be used.
        self.numeric, self.generation = ctypes.c_void_p(0), 0
        #: The supernodal copy of the numeric factor that the dense solves use once a
        #: pattern solve converted the factor (0 when none).
        self.solving = ctypes.c_void_p(0)
        weakref.finalize(self, _free_analysis, library, common, symbolic, self.numeric, self.solving)
        size = len(indptr) - 1
        counted = factor_counts(symbolic, size)
        if counted is None:  # fields that do not read back as this factor's: the matrix's own counts
            counts = np.bincount(np.repeat(np.arange(size), np.diff(indptr)), minlength=size).astype(np.int32)
            entries, supernodal = int(counts.sum()), True
            flops = estimated_flops(entries, size)
        else:
            counts, entries, supernodal = counted
            flops = cholesky_flops(counts)
        #: L's column counts (factor order): what a forward column reaching column j costs there.
        self.column_counts = counts
        #: The factor's counted cost, the same for every factorisation of the pattern.
        self.cost = FactorCost(size=size, entries=entries, flops=flops,
                               kind="cholmod-supernodal" if supernodal else "cholmod-simplicial",
                               matrix_entries=len(indices))
        #: Whether the numeric factor is simplicial (as analysed, or converted by a pattern
        #: solve), and whether a pattern solve converted it.
        self.analysed_simplicial = not supernodal
        self.simplicial, self.converted = self.analysed_simplicial, False
        #: The supernodal factor's structure (:class:`~contactfem.linalg.supernodal.SupernodalFactor`),
        #: read from the first numeric factor that needs it; False where it does not read back.
        self.supernodes: SupernodalFactor | None | bool = None
        #: Forward columns solved with this pattern's factors so far, and the factor entries
        #: on the elimination-tree paths they reached (Σ over each column's rows of L's
        #: column count there): counted, so the same columns always give the same figure.
        self.path_columns, self.path_entries_reached = 0, 0

    @property
    def path_entries(self) -> float | None:
        """Factor entries a forward column reaches, on average over the columns counted so
        far (None before any)."""
        return self.path_entries_reached / self.path_columns if self.path_columns else None

    def count_paths(self, forward: sp.csc_matrix) -> None:
        """Count the paths of solved forward columns W = L⁻¹ P B (rows in the factor's order)."""
        self.path_columns += forward.shape[1]
        self.path_entries_reached += int(self.column_counts[forward.indices].sum(dtype=np.int64))

    def matches(self, matrix: sp.csr_matrix) -> bool:
        if self.indptr is matrix.indptr and self.indices is matrix.indices:
            return True  # the kernel's masked matrices share their pattern's arrays
        return (np.array_equal(self.indptr, matrix.indptr) and np.array_equal(self.indices, matrix.indices))

    def fresh_numeric(self) -> int:
        """The factor to number next: the previous numeric one, refactorised in place, unless a
        sparse solve converted it to a simplicial one; then it is freed for a copy of the
        symbolic one (a fresh factor costs its memory's first touch: 0.3 s more at 526 000
        unknowns)."""
        functions = self.library.library
        self.generation += 1
        if self.numeric.value and not self.converted:
            return self.numeric.value
        if self.numeric.value:
            functions.cholmod_free_factor(ctypes.byref(self.numeric), self.common)
        if self.solving.value:  # the supernodal copy, already touched: numbered in place
            self.numeric.value, self.solving.value = self.solving.value, None
            self.simplicial, self.converted = False, False
            return self.numeric.value
        copy = functions.cholmod_copy_factor(self.symbolic, self.common)
        if not copy:
            raise MemoryError("CHOLMOD could not copy its symbolic factor")
        self.numeric.value, self.simplicial, self.converted = copy, self.analysed_simplicial, False
        return copy


    def keep_supernodal(self) -> None:
        """Keep a copy of the supernodal numeric factor that a pattern solve is about to
        convert, for the dense solves, where it fits in :data:`SUPERNODAL_COPY_BYTES`: a
        backward solve on the supernodal factor runs faster than on the converted one."""
        if self.simplicial or self.solving.value or not self.numeric.value \
                or 8 * self.cost.entries > SUPERNODAL_COPY_BYTES:
            return
        copy = self.library.library.cholmod_copy_factor(self.numeric.value, self.common)
        self.solving.value = copy or None


#: The largest supernodal factor (its stored entries' bytes) copied for the dense solves
#: before a pattern solve converts it (see DirectAnalysis.keep_supernodal): 180 MB at
#: 247 000 unknowns; a larger factor's solves go on with the converted one rather than
#: hold a second copy.
SUPERNODAL_COPY_BYTES = 2**28


def _free_analysis(library: CholmodLibrary, common: ctypes.Array, symbolic: int, numeric: ctypes.c_void_p,
                   solving: ctypes.c_void_p) -> None:
    functions = library.library
    for factor in (numeric, solving):
        if factor.value:
            functions.cholmod_free_factor(ctypes.byref(factor), common)
    functions.cholmod_free_factor(ctypes.byref(ctypes.c_void_p(symbolic)), common)
    functions.cholmod_finish(common)


class DirectCholmodFactor:
    """CHOLMOD through the library cvxopt's wheel bundles (see :class:`CholmodLibrary`):
    AMD ordering, an LLᵀ factor (supernodal or simplicial, CHOLMOD's choice; see
    :data:`~contactfem.linalg.cholmod_ctypes._FACTOR_SWITCH`), the matrix read in place.
    A non-positive pivot is reported as a SolverError. Only the latest factorisation of a
    pattern may be used (see :class:`DirectAnalysis`); an earlier one refuses to solve.

    Its cost is counted (:attr:`cost`, the same for every factorisation of a pattern), and
    the figures named ``*_seconds`` are modelled seconds: counted work divided by the rates
    in :mod:`contactfem.linalg.costs`, never read from a clock.
    """

    #: Right-hand sides per dense block of a sparse solve (n × 16 doubles at a time).
    SPARSE_BLOCK = 16

    @staticmethod
    def _view(matrix: sp.spmatrix) -> tuple[sp.csr_matrix, _SparseStruct, tuple[np.ndarray, ...]]:
        """The canonical CSR of ``matrix``, CHOLMOD's view of it and the arrays the view reads."""
        csr = canonical_csr(matrix)
        arrays = (csr.indptr.astype(np.int32, copy=False), csr.indices.astype(np.int32, copy=False),
                  np.ascontiguousarray(csr.data, dtype=float))
        # Upper triangle (stype = 1) of the symmetric matrix whose CSC arrays are the CSR ones.
        return csr, CholmodLibrary.sparse(*arrays, csr.shape[0], 1), arrays

    @classmethod
    def analyse(cls, matrix: sp.spmatrix, name: str) -> DirectAnalysis:
        """The ordering and symbolic analysis of ``matrix``'s pattern (its values unread)."""
        csr, view, _arrays = cls._view(matrix)
        library = cholmod_library()
        common = library.start()
        symbolic = library.library.cholmod_analyze(ctypes.byref(view), common)
        if not symbolic:
            library.library.cholmod_finish(common)
            raise MemoryError(f"CHOLMOD could not analyse {name}")
        return DirectAnalysis(library, common, symbolic, csr.indptr, csr.indices)

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: "DirectAnalysis | None" = None) -> None:
        csr, view, _arrays = self._view(matrix)
        n = csr.shape[0]
        analysed = analysis is None or not analysis.matches(csr)
        if analysed:
            analysis = self.analyse(csr, name)
        library, common = analysis.library, analysis.common
        factor = analysis.fresh_numeric()
        self.analysis, self.generation, self.size = analysis, analysis.generation, n
        #: The counted cost of this factorisation (:class:`~contactfem.linalg.costs.FactorCost`).
        self.cost: FactorCost = analysis.cost
        #: Modelled seconds of the ordering and symbolic analysis made for this factorisation
        #: (0 when it reused one).
        self.analysis_seconds = MODEL.analysis_seconds(self.cost) if analysed else 0.0
        #: Modelled seconds of the conversion the latest :meth:`forward_sparse` made (0 if none),
        #: the route it took (``blocked`` or ``pattern``; None before any), and the inverse
        #: fill-reducing permutation once needed.
        self.setup_seconds = 0.0
        self.route: str | None = None
        self._iperm: np.ndarray | None = None
        if not library.library.cholmod_factorize(ctypes.byref(view), factor, common):
            raise MemoryError(f"CHOLMOD could not factorise {name}")
        minor = ctypes.c_size_t.from_address(factor + _FACTOR_MINOR).value
        if minor < n:
            raise SolverError(f"{name} is singular or not positive definite "
                              f"(CHOLMOD: a non-positive pivot at column {minor} of {n})")

    @property
    def factor(self) -> int:
        """The numeric factor's address, if this is still the latest factorisation."""
        if self.generation != self.analysis.generation:
            raise SolverError("a factorisation was used after a later one of its pattern replaced it")
        return self.analysis.numeric.value

    def _dense_solve(self, system: int, rhs: np.ndarray) -> np.ndarray:
        """X (n, k), Fortran-ordered, for one of CHOLMOD's systems and a dense block."""
        block = np.asfortranarray(rhs.reshape(self.size, -1), dtype=float)
        width = block.shape[1]
        view = _DenseStruct(self.size, width, self.size * width, self.size, block.ctypes.data, None,
                            _XTYPE_REAL, _DTYPE_DOUBLE)
        library, common = self.analysis.library, self.analysis.common
        factor = self.factor  # only the latest factorisation solves (raises otherwise)
        # The supernodal copy while a pattern solve has converted the factor.
        factor = self.analysis.solving.value or factor
        result = library.library.cholmod_solve(system, factor, ctypes.byref(view), common)
        if not result:
            raise MemoryError("CHOLMOD could not allocate a solve's result")
        values = _c_array(result.contents.x, ctypes.c_double, width * self.size).reshape(width, self.size)
        solved = values.T.copy(order="F")  # CHOLMOD's array is freed next
        library.library.cholmod_free_dense(ctypes.byref(result), common)
        return solved

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        return self._dense_solve(_SYS_A, rhs).reshape(rhs.shape)

    def backward(self, rhs: np.ndarray) -> np.ndarray:
        """x = Pᵀ L⁻ᵀ v for ``rhs`` v in the factor's order, (n,) or (n, k): with W = L⁻¹ P B
        from :meth:`forward_sparse`, A⁻¹ B y = backward(W y), half a full solve (one sweep of
        the factor instead of two)."""
        rhs = np.asarray(rhs, dtype=float)
        return self._dense_solve(_SYS_PT, self._dense_solve(_SYS_LT, rhs)).reshape(rhs.shape)

    def solve_sparse(self, rhs: sp.csc_matrix) -> np.ndarray:
        n, k = rhs.shape
        out = np.empty((n, k), order="F")
        for start in range(0, k, self.SPARSE_BLOCK):
            out[:, start:start + self.SPARSE_BLOCK] = self._dense_solve(
                _SYS_A, rhs[:, start:start + self.SPARSE_BLOCK].toarray(order="F"))
        return out

    @property
    def simplicial(self) -> bool:
        """Whether the factor is simplicial (its pattern solves then convert nothing)."""
        return self.analysis.simplicial

    @property
    def column_solve_seconds(self) -> float:
        """Modelled seconds of a full solve with one right-hand side (the scale of the
        pattern route's guess before any path is counted)."""
        return MODEL.solve_seconds(self.cost, 1)

    def _inverse_permutation(self) -> np.ndarray:
        """Where row r of a right-hand side goes in P b: the inverse of the factor's fill-reducing
        permutation (cholmod_factor's Perm, the third field)."""
        if self._iperm is None:
            perm = _c_array(ctypes.c_void_p.from_address(self.factor + _FACTOR_PERM).value, ctypes.c_int32, self.size)
            self._iperm = np.empty(self.size, dtype=np.int64)
            self._iperm[perm] = np.arange(self.size)
        return self._iperm

    def forward_sparse(self, rhs: sp.csc_matrix) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """W = L⁻¹ P B for a sparse B (n, k), sparse, so that Bᵀ A⁻¹ B = Wᵀ W (the factor is
        an LLᵀ), returned twice as (W, D⁻¹ W) with D = I.

        L⁻¹ P b has nonzeros only on the elimination tree's paths from b's nonzeros (about
        600 of 418 000 on a rough profile's mesh, 3 000 of 132 000 on the square). Three
        routes: the supernodal factor's own blocks on the supernodes the block reaches
        (:mod:`~contactfem.linalg.supernodal`: nothing converted, the whole block at once);
        CHOLMOD's solve with a sparse right-hand side's pattern (cholmod_solve2 with Bset),
        which visits only the paths, one column at a time, but converts a supernodal factor
        to a simplicial one first; its sparse solve in dense blocks of 4, which sweeps the
        whole factor for each block and converts nothing. The route is chosen by
        :meth:`_route_seconds`, from counts alone: the factor's entries, the k columns, the
        supernodes this block reaches, the paths of the columns solved before (``route``
        says which was taken, ``setup_seconds`` the modelled seconds of the conversion it
        made). The columns' paths are counted for the next choice.
        """
        k = rhs.shape[1]
        permuted = self._permuted(rhs)
        structure = self._supernodes()
        reach = structure.reach(permuted.indices) if structure is not None and permuted.nnz else None
        blocked, pattern, supernodal = self._route_seconds(k, reach)
        converting = not self.analysis.simplicial
        self.setup_seconds = 0.0
        if supernodal <= min(blocked, pattern):
            self.route = "supernodal"
            result = self._supernodal_forward(permuted, reach)
        elif blocked < pattern:
            self.route = "blocked"
            result = self._blocked_forward(rhs)
        else:
            self.route = "pattern"
            self.setup_seconds = MODEL.conversion_seconds(self.cost) if converting else 0.0
            result = self._pattern_forward(permuted)
        self.analysis.count_paths(result[0])
        return result

    def _supernodal_forward(self, permuted: sp.csc_matrix,
                            reach: np.ndarray | None = None) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """W through the supernodal blocks the right-hand sides reach (``reach``, computed
        when not given), for right-hand sides in the factor's order (:meth:`_permuted`)."""
        structure = self._supernodes()
        if structure is None:
            raise SolverError("no supernodal factor to solve forward columns with")
        if reach is None:
            reach = structure.reach(permuted.indices)
        forward = structure.forward(self._supernodal_values(), permuted, reach)
        return forward, forward

    def _supernodes(self) -> SupernodalFactor | None:
        """The supernodal structure of this pattern's factors, when a supernodal numeric
        factor is at hand (this one, or the copy kept when a pattern solve converted it)."""
        address = self._supernodal_address()
        if address is None:
            return None
        if self.analysis.supernodes is None:
            self.analysis.supernodes = SupernodalFactor.read(address, self.size) or False
        return self.analysis.supernodes or None

    def _supernodal_address(self) -> int | None:
        if self.analysis.simplicial:
            return self.analysis.solving.value or None
        return self.factor

    def _supernodal_values(self) -> int:
        """The address of the supernodal numeric factor's values (x)."""
        return ctypes.c_void_p.from_address(self._supernodal_address() + _SUPERNODAL_X).value

    def _route_seconds(self, k: int, reach: np.ndarray | None = None) -> tuple[float, float, float]:
        """Modelled seconds of k forward columns through the blocked sparse solve, the
        pattern solve (its conversion included while the factor is supernodal) and the
        supernodal blocks (inf without a supernodal factor): the factor's counted entries,
        the paths counted on this pattern's earlier columns (until there are some, the
        pattern route's guess from the factor's fill), and the entries and supernodes the
        block reaches (``reach``; until known, a leaf's path to the root), divided by the
        rates of :mod:`contactfem.linalg.costs`."""
        blocked, pattern = MODEL.forward_routes(self.cost, k, converted=self.analysis.simplicial,
                                                path_entries=self.analysis.path_entries)
        structure = self._supernodes()
        if structure is None:
            return blocked, pattern, np.inf
        if reach is None:
            entries, supernodes = structure.leaf_path_entries, structure.leaf_path_supernodes
        else:
            entries, supernodes = structure.reach_entries(reach), len(reach)
        return blocked, pattern, MODEL.supernodal_forward_seconds(self.cost, k, entries, supernodes)

    def forward_seconds(self, k: int) -> float:
        """Modelled seconds of k more forward columns (the cheapest route)."""
        return min(self._route_seconds(k))

    def _blocked_forward(self, rhs: sp.csc_matrix) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """W through CHOLMOD's sparse solve (x = P b, then L x = b in its dense blocks)."""
        forward = self._sparse_solve(_SYS_L, self._sparse_solve(_SYS_P, rhs))
        return forward, forward

    def _sparse_solve(self, system: int, rhs: sp.csc_matrix) -> sp.csc_matrix:
        rhs = sp.csc_matrix(rhs)
        rhs.sort_indices()
        indptr, indices = rhs.indptr.astype(np.int32), rhs.indices.astype(np.int32)
        data = np.ascontiguousarray(rhs.data, dtype=float)
        view = CholmodLibrary.sparse(indptr, indices, data, rhs.shape[0], 0)
        library, common = self.analysis.library.library, self.analysis.common
        result = library.cholmod_spsolve(system, self.factor, ctypes.byref(view), common)
        if not result:
            raise MemoryError("CHOLMOD could not solve with a sparse right-hand side")
        s = result.contents
        indptr = _c_array(s.p, ctypes.c_int32, s.ncol + 1).copy()
        count = int(indptr[-1])
        indices = _c_array(s.i, ctypes.c_int32, count).copy()
        values = _c_array(s.x, ctypes.c_double, count).copy()
        shape = (s.nrow, s.ncol)
        library.cholmod_free_sparse(ctypes.byref(result), common)
        return sp.csc_matrix((values, indices, indptr), shape=shape)

    def _permuted(self, rhs: sp.csc_matrix) -> sp.csc_matrix:
        """The right-hand sides in the factor's order (P b), each column's rows sorted."""
        n, k = rhs.shape
        permuted = sp.csc_matrix(rhs)
        permuted = sp.csc_matrix((permuted.data.copy(), self._inverse_permutation()[permuted.indices].astype(np.int32),
                                  permuted.indptr.copy()), shape=(n, k))  # sorted in place next: the caller's stay
        permuted.sort_indices()
        return permuted

    def _pattern_forward(self, permuted: sp.csc_matrix) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """W through CHOLMOD's solve with each column's pattern (converting the factor once),
        for right-hand sides already in the factor's order (:meth:`_permuted`)."""
        n, k = permuted.shape
        starts, all_rows, all_values = permuted.indptr, permuted.indices, permuted.data
        converting = not self.analysis.simplicial
        if converting:
            self.analysis.keep_supernodal()
        library, common = self.analysis.library.library, self.analysis.common
        dense = np.zeros(n)
        right = _DenseStruct(n, 1, n, n, dense.ctypes.data, None, _XTYPE_REAL, _DTYPE_DOUBLE)
        solution, pattern, work_y, work_e = _DENSE_P(), _SPARSE_P(), _DENSE_P(), _DENSE_P()
        # One cholmod_sparse for every column's pattern (Bset), pointed at each in turn: on a
        # graded mesh the per-column Python work weighs more than CHOLMOD's own.
        set_pointers = np.zeros(2, dtype=np.int32)
        ones = np.ones(max(int(np.diff(starts).max(initial=0)), 1))
        given = CholmodLibrary.sparse(set_pointers, all_rows, ones, n, 0)
        counts = np.zeros(k + 1, dtype=np.int64)
        rows_out: list[np.ndarray] = []
        values_out: list[np.ndarray] = []
        views: dict[tuple[int, type, int], np.ndarray] = {}  # CHOLMOD reuses its result arrays

        def view(address: int, kind: type, length: int) -> np.ndarray:
            key = (address, kind, length)
            if key not in views:
                views[key] = _c_array(address, kind, length)
            return views[key]

        row_bytes, first_row, factor = all_rows.itemsize, all_rows.ctypes.data, self.factor
        try:
            for column in range(k):
                start, stop = int(starts[column]), int(starts[column + 1])
                if start == stop:
                    continue
                rows = all_rows[start:stop]
                dense[rows] = all_values[start:stop]
                set_pointers[1] = stop - start
                given.nzmax = stop - start
                given.i = first_row + start * row_bytes
                if not library.cholmod_solve2(_SYS_L, factor, ctypes.byref(right), ctypes.byref(given),
                                              ctypes.byref(solution), ctypes.byref(pattern), ctypes.byref(work_y),
                                              ctypes.byref(work_e), common):
                    raise MemoryError("CHOLMOD could not solve with a sparse right-hand side")
                if converting:  # CHOLMOD made the factor simplicial in its first column's solve
                    self.analysis.simplicial = self.analysis.converted = True
                    converting = False
                dense[rows] = 0.0
                reach = pattern.contents
                count = int(view(reach.p, ctypes.c_int32, 2)[1])
                touched = view(reach.i, ctypes.c_int32, reach.nzmax)[:count].copy()
                rows_out.append(touched)
                values_out.append(view(solution.contents.x, ctypes.c_double, n)[touched])  # only the reach is valid
                counts[column + 1] = count
        finally:
            for handle in (solution, work_y, work_e):
                if handle:
                    library.cholmod_free_dense(ctypes.byref(handle), common)
            if pattern:
                library.cholmod_free_sparse(ctypes.byref(pattern), common)
        indptr = np.cumsum(counts)
        indices = np.concatenate(rows_out) if rows_out else np.zeros(0, dtype=np.int32)
        data = np.concatenate(values_out) if values_out else np.zeros(0)
        forward = sp.csc_matrix((data, indices, indptr), shape=(n, k))
        forward.sort_indices()
        return forward, forward


def serves(matrix: sp.spmatrix) -> bool:
    """Whether cvxopt's bundled CHOLMOD is called directly for ``matrix`` (found here, and
    the matrix within its int interface)."""
    return cholmod_library() is not None and matrix.nnz < 2**31
