"""Sparse direct factorisations of symmetric positive definite matrices, behind one small interface.

Backends, fastest first on 2D elasticity (see README): CHOLMOD (AMD ordering, supernodal;
the library bundled in cvxopt's wheel, a default dependency where it has a wheel, called
directly, or through cvxopt's interface, or through scikit-sparse), Pardiso (pypardiso, mtype=2), SuperLU
(scipy, always there). SuperLU runs with the MMD_AT_PLUS_A ordering: scipy's default
COLAMD is an order of magnitude slower and heavier on these matrices.

Matrices that share one sparsity pattern (the contact kernel's, masked differently for
each active set) are factorised through a :class:`Factorizer`, which keeps CHOLMOD's
ordering and symbolic analysis and redoes only the numeric factorisation: about 0.6 of a
first factorisation at 525 000 unknowns. SuperLU and Pardiso factorise afresh.

None of the backends can be trusted to notice a singular matrix: SuperLU in symmetric
mode without pivoting (``diag_pivot_thresh=0``) and CHOLMOD both complete with a tiny
round-off pivot where the exact one is zero, and the solves are then garbage. So every
factorisation is followed by a probe (:func:`check_factorization`): one solve with a
positive random right-hand side, whose residual and size tell a singular or numerically
singular matrix from a sound one whatever the backend.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import threading
import time
import warnings
import weakref
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from contactfem.errors import FactorCapacityError, SolverError

#: Bound on the probe's two figures, ‖b − A x‖∞ / ‖b‖∞ after one step of iterative
#: refinement and ε κ̂ with κ̂ = ‖A‖∞ ‖x‖∞ / ‖b‖∞, beyond which a matrix is reported
#: numerically singular. A backward-stable solve leaves a relative residual of about ε κ,
#: and κ̂ is a lower estimate of κ∞ (the positive probe loads the softest, smooth modes, so
#: it is typically within a factor of ten), so either figure above 0.1 means a generic load
#: is solved with no correct digit. An exactly singular matrix is far past it: the component
#: of the positive probe along a null vector (a rigid motion of an unheld part) lies outside
#: A's range, so no x can cancel it and the residual stays of the order of ‖b‖; and x grows
#: like ‖b‖ / (round-off pivot), κ̂ like 1/ε. For scale, measured ε κ̂: 3e-10 on the square
#: at 131 000 unknowns, 3e-4 at ν = 0.499999995, 7e-3 on a 1:1000 strip of 1000 × 4 cells.
SINGULARITY_LIMIT = 0.1
# The probe is reproducible: the same matrix always gets the same verdict.
_PROBE_SEED = 20050101


class Factorization(Protocol):
    def solve(self, rhs: np.ndarray) -> np.ndarray: ...


def solve_sparse_columns(factor: Factorization, rhs: sp.spmatrix) -> np.ndarray:
    """X (n, k), Fortran-ordered, with A X = ``rhs`` for a sparse block of right-hand sides
    (unit vectors, rows of the stiffness): through the backend's sparse solve when it has
    one (CHOLMOD), else densely."""
    sparse_solve = getattr(factor, "solve_sparse", None)
    if sparse_solve is not None:
        return sparse_solve(sp.csc_matrix(rhs))
    return np.asfortranarray(np.asarray(factor.solve(rhs.toarray())).reshape(rhs.shape))


@dataclass(frozen=True)
class FactorCheck:
    """What the probe of a factorisation measured (see :func:`check_factorization`).

    ``residual``: ‖b − A x‖∞ / ‖b‖∞ for the probe b (after refinement, if one was needed);
    ``condition``: κ̂ = ‖A‖∞ ‖x‖∞ / ‖b‖∞, a lower estimate of the condition number κ∞(A),
    so that ε κ̂ estimates the relative forward error of a solve; ``refined``: whether a step
    of iterative refinement was needed.
    """

    residual: float
    condition: float
    refined: bool = False

    @property
    def relative_precision(self) -> float:
        """ε κ̂: the relative accuracy a solve with this factor can be expected to reach."""
        return float(np.finfo(float).eps * self.condition)


def _symmetric_csc(matrix: sp.spmatrix) -> sp.csc_matrix:
    """CSC form of a symmetric matrix: a CSR matrix's transpose is one, without a copy."""
    if sp.isspmatrix_csr(matrix) or isinstance(matrix, sp.csr_array):
        return matrix.T.tocsc(copy=False)
    return sp.csc_matrix(matrix)


class _Cholmod:
    """CHOLMOD through scikit-sparse (which links the system's SuiteSparse and BLAS)."""

    @staticmethod
    def analyse(matrix: sp.spmatrix, name: str) -> object:
        """The ordering and symbolic analysis of ``matrix``'s pattern: the factor object a
        factorisation fills."""
        from sksparse.cholmod import analyze

        # Supernodal always: for small factors CHOLMOD's default picks a simplicial LDL^T,
        # which accepts a negative pivot without a word.
        return analyze(_symmetric_csc(matrix), ordering_method="amd", mode="supernodal")

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: object | None = None) -> None:
        from sksparse.cholmod import CholmodNotPositiveDefiniteError

        csc = _symmetric_csc(matrix)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                started = time.perf_counter()
                factor = self.analyse(csc, name) if analysis is None else analysis
                self.analysis_seconds = time.perf_counter() - started
                factor.cholesky_inplace(csc)
            except CholmodNotPositiveDefiniteError as error:
                raise SolverError(f"{name} is singular or not positive definite (CHOLMOD: {error})") from error
        # Some CHOLMOD builds only warn on a non-positive pivot and leave the factor partial.
        for warning in caught:
            if "positive definite" in str(warning.message):
                raise SolverError(f"{name} is singular or not positive definite (CHOLMOD: {warning.message})")
        for warning in caught:
            warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
        self._factor = factor
        #: What a later matrix of the same pattern can be refactorised with (the factor object,
        #: whose numeric part the next factorisation overwrites).
        self.analysis = factor

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._factor(rhs)


@dataclass
class _CvxoptAnalysis:
    """What a later matrix of the same pattern reuses: CHOLMOD's symbolic analysis, cvxopt's
    copy of the upper triangle (whose values are overwritten), and where its entries sit in
    the CSR matrix's data, for the pattern (indptr, indices) they were computed from."""

    symbolic: object
    stored: object
    positions: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray

    def matches(self, matrix: sp.csr_matrix) -> bool:
        if self.indptr is matrix.indptr and self.indices is matrix.indices:
            return True  # the kernel's masked matrices share their pattern's arrays
        return (np.array_equal(self.indptr, matrix.indptr) and np.array_equal(self.indices, matrix.indices))


class _CvxoptCholmod:
    """CHOLMOD through cvxopt's interface, where its bundled library cannot be called
    directly (see :class:`_LibraryCholmod`).

    cvxopt takes its own sparse matrix of one triangle, built from triplets in its column
    order: the upper one, which CHOLMOD's supernodal factorisation takes 2x faster than
    the lower one (the numeric factorisation took 1.1 s against 2.2-2.4 s at 526 000
    unknowns, and 48 MB less at its peak). A refactorisation of the same pattern (the
    kernel's, masked differently for each active set) only gathers the new values into
    that matrix: rebuilding it took 0.5 s of each refactorisation at 694 000 unknowns. Keeping it costs no peak memory: it
    exists during every numeric factorisation anyway. A non-positive pivot raises
    ArithmeticError, reported as a SolverError.
    """

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: "_CvxoptAnalysis | None" = None) -> None:
        import cvxopt
        from cvxopt import cholmod

        csr = sp.csr_matrix(matrix)
        if not csr.has_canonical_format:
            csr = csr.copy()
            csr.sum_duplicates()
        started = time.perf_counter()
        if analysis is not None and analysis.matches(csr):
            stored, symbolic, positions = analysis.stored, analysis.symbolic, analysis.positions
            # ``stored.V`` reads a copy; assigning the attribute replaces the values in place.
            stored.V = cvxopt.matrix(np.ascontiguousarray(csr.data[positions], dtype=float))
        else:
            n = csr.shape[0]
            # cvxopt stores by column, then row: the upper triangle in CSC order. The matrix
            # is symmetric, so column j of its upper triangle is row j of the CSR matrix up
            # to the diagonal: the entries with column index ≤ row index, already in order.
            rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(csr.indptr))
            positions = np.flatnonzero(csr.indices <= rows)
            if csr.nnz < 2**31:
                positions = positions.astype(np.int32)  # kept for every refactorisation: half the bytes
            stored = cvxopt.spmatrix(cvxopt.matrix(np.ascontiguousarray(csr.data[positions], dtype=float)),
                                     cvxopt.matrix(csr.indices[positions].astype(np.int64)),
                                     cvxopt.matrix(rows[positions]), (n, n))
            del rows
            _release_freed_memory()
            # Always supernodal LLᵀ: CHOLMOD's default picks a simplicial LDLᵀ for small,
            # sparse factors, which passes a negative pivot silently.
            cholmod.options["supernodal"] = _CHOLMOD_SUPERNODAL  # cvxopt cannot ask for a simplicial LLᵀ
            symbolic = cholmod.symbolic(stored, uplo="U")
        self.analysis_seconds = time.perf_counter() - started
        try:
            cholmod.numeric(stored, symbolic)
        except ArithmeticError as error:
            raise SolverError(f"{name} is singular or not positive definite (CHOLMOD: pivot {error} is not positive)") from error
        self._cholmod, self._dense = cholmod, cvxopt.matrix
        self._factor = symbolic
        self.analysis = _CvxoptAnalysis(symbolic, stored, positions, csr.indptr, csr.indices)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        shape = rhs.shape
        block = self._dense(np.asfortranarray(rhs.reshape(shape[0], -1)))
        self._cholmod.solve(self._factor, block)
        return np.array(block).reshape(shape)

    def forward_sparse(self, rhs: sp.csc_matrix) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """W = L⁻¹ P B and D⁻¹ W for a sparse B (n, k), both sparse, so that
        Bᵀ A⁻¹ B = Wᵀ D⁻¹ W (D = I for CHOLMOD's supernodal LLᵀ, the diagonal of a
        simplicial LDLᵀ). L⁻¹ P e_j has nonzeros only on the elimination tree's path from
        j: about 600 of 418 000 on a rough profile's mesh, 9 000 of 526 000 on the square;
        a column costs 0.24 of a full solve (CHOLMOD solves in small dense blocks), against
        0.5–0.7 for a full sparse column."""
        import cvxopt

        n, k = rhs.shape
        block = rhs.tocoo()
        matrix = cvxopt.spmatrix(cvxopt.matrix(block.data.astype(float)), cvxopt.matrix(block.row.astype(np.int64)),
                                 cvxopt.matrix(block.col.astype(np.int64)), (n, k))
        forward = self._cholmod.spsolve(self._factor, self._cholmod.spsolve(self._factor, matrix, sys=7), sys=4)
        scaled = self._cholmod.spsolve(self._factor, forward, sys=6)

        def csc(m) -> sp.csc_matrix:
            return sp.csc_matrix((np.array(m.V).ravel(), (np.array(m.I).ravel(), np.array(m.J).ravel())),
                                 shape=(n, k))

        return csc(forward), csc(scaled)

    #: Columns per call of CHOLMOD's sparse solve: cvxopt's dense solve takes a block one
    #: column at a time, its sparse one in small dense blocks, measured 2x faster per column
    #: at 4 (247k unknowns: 26 against 51 ms); more columns cost more to convert back.
    SPARSE_BLOCK = 4

    def solve_sparse(self, rhs: sp.csc_matrix) -> np.ndarray:
        import cvxopt

        n, k = rhs.shape
        out = np.zeros((n, k), order="F")
        for start in range(0, k, self.SPARSE_BLOCK):
            block = rhs[:, start:start + self.SPARSE_BLOCK].tocoo()
            width = block.shape[1]
            matrix = cvxopt.spmatrix(cvxopt.matrix(block.data.astype(float)),
                                     cvxopt.matrix(block.row.astype(np.int64)),
                                     cvxopt.matrix(block.col.astype(np.int64)), (n, width))
            solved = self._cholmod.spsolve(self._factor, matrix)
            rows = np.array(solved.I, dtype=np.int64).ravel()
            columns = np.array(solved.J, dtype=np.int64).ravel()
            out[rows, start + columns] = np.array(solved.V).ravel()
        return out


class _SparseStruct(ctypes.Structure):
    """cholmod_sparse (the same layout in every CHOLMOD release)."""
    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("p", ctypes.c_void_p), ("i", ctypes.c_void_p), ("nz", ctypes.c_void_p), ("x", ctypes.c_void_p),
                ("z", ctypes.c_void_p), ("stype", ctypes.c_int), ("itype", ctypes.c_int), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int), ("sorted", ctypes.c_int), ("packed", ctypes.c_int)]


class _DenseStruct(ctypes.Structure):
    """cholmod_dense."""
    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("d", ctypes.c_size_t), ("x", ctypes.c_void_p), ("z", ctypes.c_void_p),
                ("xtype", ctypes.c_int), ("dtype", ctypes.c_int)]


_SPARSE_P, _DENSE_P = ctypes.POINTER(_SparseStruct), ctypes.POINTER(_DenseStruct)
# CHOLMOD's constants: CHOLMOD_INT, CHOLMOD_REAL, CHOLMOD_DOUBLE; solve systems A, L and P.
_ITYPE_INT, _XTYPE_REAL, _DTYPE_DOUBLE = 0, 1, 0
_SYS_A, _SYS_L, _SYS_P = 0, 4, 7
#: cholmod_common is allocated here (CHOLMOD 3 needs 2 664 bytes) and filled by cholmod_start.
_COMMON_BYTES = 16384
#: Fields of cholmod_common read or written here: (offset, C type, the value cholmod_start
#: sets). The defaults are checked after cholmod_start before the library is used, so a
#: CHOLMOD whose layout differs is never written into: contactfem falls back to cvxopt's API.
_COMMON_DEFAULTS = ((0, ctypes.c_double, 0.0),      # dbound
                    (8, ctypes.c_double, 1.2),      # grow0
                    (40, ctypes.c_double, 40.0),    # supernodal_switch
                    (48, ctypes.c_int, 1),          # supernodal = CHOLMOD_AUTO
                    (52, ctypes.c_int, 1),          # final_asis
                    (60, ctypes.c_int, 0),          # final_ll
                    (144, ctypes.c_int, 3),         # print
                    (168, ctypes.c_int, 0))         # nmethods
_COMMON_PRINT, _COMMON_SUPERNODAL, _COMMON_FINAL_ASIS, _COMMON_FINAL_LL = 144, 48, 52, 60
#: Common->supernodal: CHOLMOD_AUTO (1), CHOLMOD's own choice by the factor's flops per
#: entry (supernodal from 40), or CHOLMOD_SUPERNODAL (2). With final_asis off and final_ll
#: on, a simplicial factor is an LLᵀ too (the default simplicial LDLᵀ passes a negative
#: pivot silently), so that W = L⁻¹ P B gives Bᵀ A⁻¹ B = Wᵀ W either way. The meshes here
#: have little fill, and CHOLMOD picks simplicial on graded and small ones, whose full
#: solves it runs 2-3x faster (15 ms against 36 ms at 418 000 unknowns under a rough
#: profile), whose analysis skips the supernodal one, and whose solves with a sparse
#: right-hand side need no conversion.
_CHOLMOD_AUTO, _CHOLMOD_SUPERNODAL = 1, 2
_FACTOR_SWITCH = _CHOLMOD_AUTO
#: cholmod_factor starts with n, minor (the column where a non-positive pivot stopped it),
#: Perm (the fill-reducing permutation) and ColCount (a simplicial factor's column counts);
#: further on, xsize (a supernodal factor's entries) and is_super, at the offsets of
#: CHOLMOD 3 to 5's layout on 64-bit machines (read only to guess a cost and to tell the
#: kinds apart; checked: n must match and is_super be 0 or 1).
_FACTOR_MINOR, _FACTOR_PERM = ctypes.sizeof(ctypes.c_size_t), 2 * ctypes.sizeof(ctypes.c_size_t)
_FACTOR_XSIZE, _FACTOR_IS_SUPER = 120, 184
_FACTOR_COLCOUNT = 3 * ctypes.sizeof(ctypes.c_size_t)


class _CholmodLibrary:
    """CHOLMOD's C interface (int indices) in the shared library that cvxopt's wheel bundles,
    called through ctypes.

    cvxopt's own interface copies the matrix twice (its sparse matrix, then a CHOLMOD copy
    of it at every factorisation, both with 64-bit indices) and solves a block of
    right-hand sides one column at a time. Called directly, CHOLMOD reads the kernel's CSR
    arrays in place as the upper triangle of a symmetric matrix (stype = 1: the entries
    below the diagonal are ignored, and the CSR matrix of a symmetric matrix is its own CSC
    one) and solves blocks at once. Measured at 526 338 unknowns (square N = 512, 2 cores,
    benchmarks/results/solvers.json): 0.69 GB added at the peak instead of 0.83
    (scikit-sparse's CHOLMOD: 0.70), a first factorisation of 1.29 s instead of 1.75, a
    block of 4 right-hand sides in 0.047 s per column instead of 0.097.
    """

    def __init__(self, library: ctypes.CDLL) -> None:
        self.library = library
        library.cholmod_start.argtypes = [ctypes.c_void_p]
        library.cholmod_finish.argtypes = [ctypes.c_void_p]
        library.cholmod_analyze.restype = ctypes.c_void_p
        library.cholmod_analyze.argtypes = [_SPARSE_P, ctypes.c_void_p]
        library.cholmod_factorize.argtypes = [_SPARSE_P, ctypes.c_void_p, ctypes.c_void_p]
        library.cholmod_solve.restype = _DENSE_P
        library.cholmod_solve.argtypes = [ctypes.c_int, ctypes.c_void_p, _DENSE_P, ctypes.c_void_p]
        library.cholmod_spsolve.restype = _SPARSE_P
        library.cholmod_spsolve.argtypes = [ctypes.c_int, ctypes.c_void_p, _SPARSE_P, ctypes.c_void_p]
        library.cholmod_solve2.restype = ctypes.c_int
        library.cholmod_solve2.argtypes = [ctypes.c_int, ctypes.c_void_p, _DENSE_P, _SPARSE_P, ctypes.POINTER(_DENSE_P),
                                           ctypes.POINTER(_SPARSE_P), ctypes.POINTER(_DENSE_P),
                                           ctypes.POINTER(_DENSE_P), ctypes.c_void_p]
        library.cholmod_free_dense.argtypes = [ctypes.POINTER(_DENSE_P), ctypes.c_void_p]
        library.cholmod_free_sparse.argtypes = [ctypes.POINTER(_SPARSE_P), ctypes.c_void_p]
        library.cholmod_free_factor.argtypes = [ctypes.POINTER(ctypes.c_void_p), ctypes.c_void_p]
        library.cholmod_copy_factor.restype = ctypes.c_void_p
        library.cholmod_copy_factor.argtypes = [ctypes.c_void_p, ctypes.c_void_p]

    def start(self) -> ctypes.Array | None:
        """A fresh cholmod_common with printing off, or None if its layout is not the known one."""
        common = ctypes.create_string_buffer(_COMMON_BYTES)
        self.library.cholmod_start(common)
        if any(kind.from_buffer(common, offset).value != value for offset, kind, value in _COMMON_DEFAULTS):
            self.library.cholmod_finish(common)
            return None
        # CHOLMOD would print its warnings (a non-positive pivot) on stdout; they are raised instead.
        ctypes.c_int.from_buffer(common, _COMMON_PRINT).value = 0
        ctypes.c_int.from_buffer(common, _COMMON_SUPERNODAL).value = _FACTOR_SWITCH
        ctypes.c_int.from_buffer(common, _COMMON_FINAL_ASIS).value = 0
        ctypes.c_int.from_buffer(common, _COMMON_FINAL_LL).value = 1
        return common

    @staticmethod
    def sparse(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, nrow: int, stype: int) -> _SparseStruct:
        """A cholmod_sparse over numpy arrays (int32 indices, float64 values), not copied:
        the arrays must outlive every call that is given it."""
        return _SparseStruct(nrow, len(indptr) - 1, len(indices), indptr.ctypes.data, indices.ctypes.data, None,
                             data.ctypes.data, None, stype, _ITYPE_INT, _XTYPE_REAL, _DTYPE_DOUBLE, 1, 1)


def _c_array(address: int, kind: type, count: int) -> np.ndarray:
    """A numpy view of ``count`` values of C type ``kind`` at ``address``."""
    if count == 0:
        return np.zeros(0, dtype=np.dtype(kind))
    return np.ctypeslib.as_array(ctypes.cast(address, ctypes.POINTER(kind)), (count,))


def _bundled_cholmod_files() -> list[str]:
    """CHOLMOD shared libraries shipped inside cvxopt's wheel (auditwheel puts them in
    cvxopt.libs beside the package, delvewheel and delocate inside it)."""
    import glob
    import os

    spec = importlib.util.find_spec("cvxopt")
    if spec is None or not spec.submodule_search_locations:
        return []
    package = list(spec.submodule_search_locations)[0]
    patterns = [os.path.join(os.path.dirname(package), "cvxopt.libs", "*cholmod*"),
                os.path.join(package, ".libs", "*cholmod*"), os.path.join(package, ".dylibs", "*cholmod*")]
    return sorted(path for pattern in patterns for path in glob.glob(pattern))


_LIBRARY_STATE: dict[str, _CholmodLibrary | None] = {}


_LIBRARY_LOCK = threading.Lock()


def _cholmod_library() -> _CholmodLibrary | None:
    """The bundled CHOLMOD, loaded once (by one thread: a solver analyses its pattern while
    coarser levels factorise); None where cvxopt has none or its layout is unknown."""
    with _LIBRARY_LOCK:
        return _load_cholmod_library()


def _load_cholmod_library() -> _CholmodLibrary | None:
    if "library" not in _LIBRARY_STATE:
        _LIBRARY_STATE["library"] = None
        try:
            import cvxopt.cholmod  # noqa: F401  (loads the bundled library and its dependencies)

            for path in _bundled_cholmod_files():
                candidate = _CholmodLibrary(ctypes.CDLL(path))
                common = candidate.start()
                if common is not None:
                    candidate.library.cholmod_finish(common)
                    _LIBRARY_STATE["library"] = candidate
                    break
        except (ImportError, OSError, AttributeError):
            pass
    return _LIBRARY_STATE["library"]


class _LibraryAnalysis:
    """What a later matrix of the same pattern reuses: CHOLMOD's symbolic factor and the
    cholmod_common it was made with, for the pattern (indptr, indices) it was computed
    from; and the latest numeric factor made from it. Each factorisation numbers a fresh
    copy of the symbolic factor after a solve with a sparse right-hand side, which converts
    its factor to a simplicial one in place (whose refactorisation would be a slow
    simplicial LDLᵀ), and refactorises the previous one in place otherwise; the previous
    one is freed first, so two never coexist. Freed with it."""

    def __init__(self, library: _CholmodLibrary, common: ctypes.Array, symbolic: int,
                 indptr: np.ndarray, indices: np.ndarray) -> None:
        import weakref

        self.library, self.common, self.symbolic = library, common, symbolic
        self.indptr, self.indices = indptr, indices
        #: The numeric factor (0 when none) and how many have been made: a factorisation
        #: whose generation is not the latest was freed and may not be used.
        self.numeric, self.generation = ctypes.c_void_p(0), 0
        #: Whether the numeric factor is simplicial (as analysed, or converted by a sparse
        #: solve), whether a sparse solve converted it, and what that conversion took (None
        #: until measured): 9.5 ms on a rough profile's graded mesh at 418 000 unknowns,
        #: 0.65 s on a uniform one at 695 000 (its factor has large dense supernodes, each
        #: entry of which gets its own row index).
        self.analysed_simplicial = ctypes.c_int.from_address(symbolic + _FACTOR_IS_SUPER).value == 0
        self.simplicial, self.converted = self.analysed_simplicial, False
        self.conversion_seconds: float | None = None
        #: Measured seconds per forward column through each route (None until measured).
        self.blocked_column_seconds: float | None = None
        self.pattern_column_seconds: float | None = None
        #: The pattern solve's cost per column guessed from the supernodal factor's fill.
        self.pattern_column_guess: float | None = None
        weakref.finalize(self, _free_analysis, library, common, symbolic, self.numeric)

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
        copy = functions.cholmod_copy_factor(self.symbolic, self.common)
        if not copy:
            raise MemoryError("CHOLMOD could not copy its symbolic factor")
        self.numeric.value, self.simplicial, self.converted = copy, self.analysed_simplicial, False
        return copy


def _free_analysis(library: _CholmodLibrary, common: ctypes.Array, symbolic: int, numeric: ctypes.c_void_p) -> None:
    functions = library.library
    if numeric.value:
        functions.cholmod_free_factor(ctypes.byref(numeric), common)
    functions.cholmod_free_factor(ctypes.byref(ctypes.c_void_p(symbolic)), common)
    functions.cholmod_finish(common)


class _LibraryCholmod:
    """CHOLMOD through the library cvxopt's wheel bundles (see :class:`_CholmodLibrary`):
    AMD ordering, an LLᵀ factor (supernodal or simplicial, CHOLMOD's choice; see
    :data:`_FACTOR_SWITCH`), the matrix read in place. A non-positive pivot is
    reported as a SolverError. Only the latest factorisation of a pattern may be used
    (see :class:`_LibraryAnalysis`); an earlier one refuses to solve."""

    #: Right-hand sides per dense block of a sparse solve (n × 16 doubles at a time).
    SPARSE_BLOCK = 16
    #: Columns from which a batch's time per column is recorded for its route: a smaller
    #: batch measures the call's fixed cost more than its columns' (a probe of 8 columns at
    #: 13 000 unknowns measured 0.15 ms a pattern column, twice a batch of 78's, and sent
    #: that batch through the blocked route at 0.23 ms a column).
    MEASURED_FROM = 16
    #: A column through CHOLMOD's sparse solve in dense blocks (no conversion), in full
    #: solves: 9 ms of 30 ms on a rough profile's mesh at 418 000 unknowns.
    BLOCKED_COLUMN_SHARE = 0.3
    #: What the conversion to a simplicial factor is taken to cost, in full solves, until
    #: it is measured for the pattern: 0.3–0.7 on a rough profile's graded mesh at 418 000
    #: unknowns, 1.0–1.2 on the square (33k–526k), 3.5–6.5 on a uniform mesh under a rough
    #: base at 695 000.
    CONVERSION_GUESS = 3.0

    @staticmethod
    def _view(matrix: sp.spmatrix) -> tuple[sp.csr_matrix, _SparseStruct, tuple[np.ndarray, ...]]:
        """The canonical CSR of ``matrix``, CHOLMOD's view of it and the arrays the view reads."""
        csr = sp.csr_matrix(matrix)
        if not csr.has_canonical_format:
            csr = csr.copy()
            csr.sum_duplicates()
        arrays = (csr.indptr.astype(np.int32, copy=False), csr.indices.astype(np.int32, copy=False),
                  np.ascontiguousarray(csr.data, dtype=float))
        # Upper triangle (stype = 1) of the symmetric matrix whose CSC arrays are the CSR ones.
        return csr, _CholmodLibrary.sparse(*arrays, csr.shape[0], 1), arrays

    @classmethod
    def analyse(cls, matrix: sp.spmatrix, name: str) -> _LibraryAnalysis:
        """The ordering and symbolic analysis of ``matrix``'s pattern (its values unread)."""
        csr, view, _arrays = cls._view(matrix)
        library = _cholmod_library()
        common = library.start()
        symbolic = library.library.cholmod_analyze(ctypes.byref(view), common)
        if not symbolic:
            library.library.cholmod_finish(common)
            raise MemoryError(f"CHOLMOD could not analyse {name}")
        return _LibraryAnalysis(library, common, symbolic, csr.indptr, csr.indices)

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: "_LibraryAnalysis | None" = None) -> None:
        csr, view, _arrays = self._view(matrix)
        n = csr.shape[0]
        started = time.perf_counter()
        if analysis is None or not analysis.matches(csr):
            analysis = self.analyse(csr, name)
        self.analysis_seconds = time.perf_counter() - started
        library, common = analysis.library, analysis.common
        factor = analysis.fresh_numeric()
        self.analysis, self.generation, self.size = analysis, analysis.generation, n
        #: Seconds per right-hand side of the latest dense solve (the scale of the route
        #: estimates), what the latest forward_sparse spent converting the factor, and the
        #: inverse fill-reducing permutation once needed.
        self.column_solve_seconds, self.setup_seconds = 0.0, 0.0
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
        started = time.perf_counter()
        result = library.library.cholmod_solve(system, self.factor, ctypes.byref(view), common)
        self.column_solve_seconds = (time.perf_counter() - started) / width
        if not result:
            raise MemoryError("CHOLMOD could not allocate a solve's result")
        values = _c_array(result.contents.x, ctypes.c_double, width * self.size).reshape(width, self.size)
        solved = values.T.copy(order="F")  # CHOLMOD's array is freed next
        library.library.cholmod_free_dense(ctypes.byref(result), common)
        return solved

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        return self._dense_solve(_SYS_A, rhs).reshape(rhs.shape)

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

    def _inverse_permutation(self) -> np.ndarray:
        """Where row r of a right-hand side goes in P b: the inverse of the factor's fill-reducing
        permutation (cholmod_factor's Perm, the third field)."""
        if self._iperm is None:
            perm = _c_array(ctypes.c_void_p.from_address(self.factor + _FACTOR_PERM).value, ctypes.c_int32, self.size)
            self._iperm = np.empty(self.size, dtype=np.int64)
            self._iperm[perm] = np.arange(self.size)
        return self._iperm

    def _pattern_column_guess(self) -> float:
        """A column through the pattern solve, in full solves, until measured: it follows the
        factor's fill (its entries per column, xsize / n), which sets how long the columns
        on a path are. Measured: 0.003 at 31 entries per column (a rough profile's graded
        mesh, 418 000 unknowns), 0.05–0.07 at 98–145 (the square), 0.08 at 105 (a uniform
        mesh under a rough base): about 0.003 (fill / 31)^2.2, at most 0.1."""
        address = self.factor
        size = ctypes.c_size_t.from_address(address).value
        supernodal = ctypes.c_int.from_address(address + _FACTOR_IS_SUPER).value
        if size != self.size or supernodal not in (0, 1):
            return 0.1  # not the layout these offsets assume: the costly end
        if supernodal:
            entries = ctypes.c_size_t.from_address(address + _FACTOR_XSIZE).value
        else:  # a simplicial factor's entries: its column counts
            counts = ctypes.c_void_p.from_address(address + _FACTOR_COLCOUNT).value
            entries = int(_c_array(counts, ctypes.c_int32, size).sum()) if counts else 0
        if not size <= entries < 2**40:
            return 0.1
        return min(0.1, 0.003 * (entries / size / 31.0) ** 2.2)

    def forward_sparse(self, rhs: sp.csc_matrix) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """W = L⁻¹ P B for a sparse B (n, k), sparse, so that Bᵀ A⁻¹ B = Wᵀ W (the factor is
        an LLᵀ), returned twice as (W, D⁻¹ W) with D = I.

        L⁻¹ P b has nonzeros only on the elimination tree's paths from b's nonzeros (about
        600 of 418 000 on a rough profile's mesh, 3 000 of 132 000 on the square). CHOLMOD's
        solve with a sparse right-hand side (cholmod_solve2 with its pattern, Bset) visits
        only those, one column at a time, but converts a supernodal factor to a simplicial
        one first; its sparse solve in dense blocks of 4 sweeps the whole factor for each
        block and converts nothing. The cheaper route for these k columns is taken, with
        the conversion's measured cost once it is known for the pattern (``setup_seconds``:
        what this call spent converting).
        """
        self.setup_seconds = 0.0
        k = rhs.shape[1]
        blocked, pattern = self._route_seconds(k)
        started = time.perf_counter()
        if blocked < pattern:
            result = self._blocked_forward(rhs)
            if k >= self.MEASURED_FROM:
                self.analysis.blocked_column_seconds = (time.perf_counter() - started) / k
        else:
            result = self._pattern_forward(rhs)
            if k >= self.MEASURED_FROM:
                self.analysis.pattern_column_seconds = (time.perf_counter() - started - self.setup_seconds) / k
        return result

    def _route_seconds(self, k: int) -> tuple[float, float]:
        """What k forward columns are expected to cost through the blocked sparse solve and
        through the pattern solve (its conversion included while the factor is supernodal),
        from the pattern's measured figures, or from one full solve's until measured."""
        analysis = self.analysis
        solve = self.column_solve_seconds
        blocked = k * (analysis.blocked_column_seconds if analysis.blocked_column_seconds is not None
                       else self.BLOCKED_COLUMN_SHARE * solve)
        conversion = 0.0 if analysis.simplicial else (
            analysis.conversion_seconds if analysis.conversion_seconds is not None else self.CONVERSION_GUESS * solve)
        if analysis.pattern_column_seconds is not None:
            column = analysis.pattern_column_seconds
        else:
            if analysis.pattern_column_guess is None:
                analysis.pattern_column_guess = self._pattern_column_guess()
            column = analysis.pattern_column_guess * solve
        pattern = conversion + k * column
        return blocked, pattern

    def forward_seconds(self, k: int) -> float:
        """What k more forward columns are expected to cost (the cheaper route)."""
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
        view = _CholmodLibrary.sparse(indptr, indices, data, rhs.shape[0], 0)
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

    def _pattern_forward(self, rhs: sp.csc_matrix) -> tuple[sp.csc_matrix, sp.csc_matrix]:
        """W through CHOLMOD's solve with each column's pattern (converting the factor once)."""
        n, k = rhs.shape
        # The right-hand sides in the factor's order (P b), each column's rows sorted, at once.
        permuted = sp.csc_matrix(rhs)
        permuted = sp.csc_matrix((permuted.data.copy(), self._inverse_permutation()[permuted.indices].astype(np.int32),
                                  permuted.indptr.copy()), shape=(n, k))  # sorted in place next: the caller's stay
        permuted.sort_indices()
        starts, all_rows, all_values = permuted.indptr, permuted.indices, permuted.data
        converting = not self.analysis.simplicial
        library, common = self.analysis.library.library, self.analysis.common
        dense = np.zeros(n)
        right = _DenseStruct(n, 1, n, n, dense.ctypes.data, None, _XTYPE_REAL, _DTYPE_DOUBLE)
        solution, pattern, work_y, work_e = _DENSE_P(), _SPARSE_P(), _DENSE_P(), _DENSE_P()
        # One cholmod_sparse for every column's pattern (Bset), pointed at each in turn; the
        # per-column Python work is most of a column's cost on a graded mesh (26 µs in CHOLMOD).
        set_pointers = np.zeros(2, dtype=np.int32)
        ones = np.ones(max(int(np.diff(starts).max(initial=0)), 1))
        given = _CholmodLibrary.sparse(set_pointers, all_rows, ones, n, 0)
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
                started = time.perf_counter()
                if not library.cholmod_solve2(_SYS_L, factor, ctypes.byref(right), ctypes.byref(given),
                                              ctypes.byref(solution), ctypes.byref(pattern), ctypes.byref(work_y),
                                              ctypes.byref(work_e), common):
                    raise MemoryError("CHOLMOD could not solve with a sparse right-hand side")
                if converting:  # CHOLMOD made the factor simplicial: its first column's solve, near enough
                    self.setup_seconds = self.analysis.conversion_seconds = time.perf_counter() - started
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


def _library_serves(matrix: sp.spmatrix) -> bool:
    """Whether cvxopt's bundled CHOLMOD is called directly for ``matrix`` (found here, and
    the matrix within its int interface)."""
    return _cholmod_library() is not None and matrix.nnz < 2**31


def _cvxopt_cholmod(matrix: sp.spmatrix, name: str, analysis: object | None = None) -> Factorization:
    """CHOLMOD from cvxopt's wheel: called directly where its bundled library is found,
    through cvxopt's interface otherwise."""
    if _library_serves(matrix):
        return _LibraryCholmod(matrix, name, analysis if isinstance(analysis, _LibraryAnalysis) else None)
    return _CvxoptCholmod(matrix, name, analysis if isinstance(analysis, _CvxoptAnalysis) else None)


def _cvxopt_cholmod_analysis(matrix: sp.spmatrix, name: str) -> _LibraryAnalysis | None:
    """The bundled library's analysis, where :func:`_cvxopt_cholmod` calls the library; None
    through cvxopt's interface, which analyses with its own copy of the matrix."""
    return _LibraryCholmod.analyse(matrix, name) if _library_serves(matrix) else None


#: What each factorisation that reuses an analysis can make of it ahead (Factorizer.analyse).
_ANALYSES: dict[Callable[..., Factorization], Callable[[sp.spmatrix, str], object | None]] = {
    _cvxopt_cholmod: _cvxopt_cholmod_analysis,
    _Cholmod: _Cholmod.analyse,
}


class _Pardiso:
    analysis = None

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: object | None = None) -> None:
        import pypardiso

        self._solver = pypardiso.PyPardisoSolver(mtype=2)
        # MKL keeps a factor in its own memory until it is released (phase -1), which the
        # solver object does not do when collected: every factorisation stayed resident to the
        # end of the process (0.3 GB each at 490 000 unknowns; a convergence study peaked at
        # 13.7 GB against 8.2 for one solve of its finest mesh). Released with this object.
        weakref.finalize(self, self._solver.free_memory, True)
        # mtype=2 (real SPD) reads the upper triangle only.
        self._matrix = sp.triu(matrix, format="csr")
        try:
            self._solver.factorize(self._matrix)
        except Exception as error:  # pypardiso.PyPardisoError: zero or negative pivot, ...
            # Error -4 is a zero pivot: for mtype=2, a matrix that is singular or not positive definite.
            what = "is singular or not positive definite" if "-4" in str(error) else "cannot be factorised"
            raise SolverError(f"{name} {what} (Pardiso: {error})") from error

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._solver.solve(self._matrix, rhs)


#: SciPy's SuperLU sizes its first guess of the factor as this many times the matrix's
#: nonzeros, in a C int (SRC/dmemory.c, scipy/scipy#15688): past (2**31 - 1) // 30 nonzeros
#: the guess overflows and splu reports running out of memory at once, whatever the machine
#: holds. Measured: a band matrix of 71.30 million nonzeros factorises (9.5 s), one of 71.99
#: million fails in 0.3 s; a holed strip at 5.2 million unknowns (72.8 million) failed so.
SUPERLU_FILL_GUESS = 30
#: What lifts SuperLU's 32-bit limits, for the messages that meet them.
SUPERLU_REMEDY = ("use a solver with 64-bit counts (solver.backend: cholmod, pip install 'contactfem[cholmod]', "
                  "or pardiso) or fewer unknowns")


@functools.cache
def superlu_max_nonzeros() -> int | None:
    """The most matrix nonzeros SciPy's SuperLU factorises, or None when its integers are
    64-bit (its permutations come back as int64 then; they are int32 in SciPy 1.17)."""
    lu = spla.splu(sp.identity(2, format="csc"))
    if np.asarray(lu.perm_c).dtype.itemsize >= 8:
        return None
    return (2**31 - 1) // SUPERLU_FILL_GUESS


def superlu_refusal(nonzeros: int, unknowns: int, at_least: bool = False) -> str | None:
    """Why SciPy's SuperLU cannot factorise a matrix of ``nonzeros`` (``at_least`` that many)
    and ``unknowns`` rows, or None."""
    limit = superlu_max_nonzeros()
    if limit is None or nonzeros <= limit:
        return None
    return (f"SciPy's SuperLU cannot factorise a matrix of {'at least ' if at_least else ''}"
            f"{nonzeros / 1e6:.4g} million nonzeros ({unknowns} unknowns): it sizes its first guess of the factor as {SUPERLU_FILL_GUESS} times them in a "
            f"32-bit integer, which overflows past {limit / 1e6:.4g} million; {SUPERLU_REMEDY}")


class _SuperLU:
    # Reusing SuperLU's column ordering (permuting the matrix, then NATURAL) was measured
    # far slower than ordering afresh: scipy's NATURAL skips the postorder supernodes need.
    analysis = None

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: object | None = None) -> None:
        full = _symmetric_csc(matrix)
        refusal = superlu_refusal(full.nnz, full.shape[0])
        if refusal is not None:
            raise FactorCapacityError(f"{name}: {refusal}")
        try:
            self._lu = spla.splu(
                full,
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        except RuntimeError as error:  # "Factor is exactly singular"
            raise SolverError(f"{name} is singular (SuperLU: {error})") from error
        except MemoryError as error:
            # Its factor's later growth is counted in 32-bit integers too, and their overflow is
            # reported the same way: say both causes, and what lifts either.
            raise FactorCapacityError(
                f"SuperLU could not hold the factor of {name} ({full.shape[0]} unknowns): memory ran out "
                f"or its 32-bit entry counts overflowed, which SciPy's SuperLU reports alike; {SUPERLU_REMEDY}"
            ) from error

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._lu.solve(rhs)


def _release_freed_memory() -> None:
    """Hand the conversion's freed buffers back to the system before the factor is allocated
    (glibc keeps them otherwise, and they would add to the peak: 0.1 GB at 525 000 unknowns)."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


#: Backend name → (modules, any of which provides it, in order of preference; class per module).
_BACKENDS: dict[str, tuple[tuple[str | None, Callable[..., Factorization]], ...]] = {
    "cholmod": (("cvxopt", _cvxopt_cholmod), ("sksparse", _Cholmod)),
    "pardiso": (("pypardiso", _Pardiso),),
    "superlu": ((None, _SuperLU),),
}

BACKEND_NAMES = tuple(_BACKENDS)
#: Backends that run the whole solve across MPI ranks (:mod:`contactfem.distributed`, under
#: ``mpiexec ... contactfem solve``), not a :class:`Factorizer`.
DISTRIBUTED_BACKENDS = ("petsc",)
#: What a case or the command line may ask for: a backend by name, or ``auto`` (the fastest installed).
BACKEND_CHOICES = ("auto", *BACKEND_NAMES, *DISTRIBUTED_BACKENDS)
#: The extra that installs each optional backend.
_EXTRAS = {"cholmod": "cholmod", "pardiso": "pardiso", "petsc": "petsc"}


@functools.lru_cache(maxsize=None)
def _installed(module: str | None) -> bool:
    """Whether ``module`` can be imported (asked once: every factorisation resolves its backend)."""
    if module is None:
        return True
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def _implementation(name: str) -> Callable[..., Factorization]:
    for module, implementation in _BACKENDS[name]:
        if _installed(module):
            return implementation
    raise SolverError(f"solver backend {name!r} is not installed")


def backend_provider(name: str) -> str:
    """The Python package that provides backend ``name`` here (``scipy`` for SuperLU)."""
    for module, _ in _BACKENDS[name]:
        if _installed(module):
            return module or "scipy"
    raise SolverError(f"solver backend {name!r} is not installed")


def available_backends() -> list[str]:
    """Names of the backends whose libraries are importable, fastest first."""
    return [name for name, providers in _BACKENDS.items() if any(_installed(m) for m, _ in providers)]


def resolve_backend(name: str = "auto") -> str:
    """The backend that ``name`` selects: ``auto`` is the fastest available one."""
    available = available_backends()
    if name == "auto":
        return available[0]
    if name in DISTRIBUTED_BACKENDS:
        if not all(_installed(module) for module in ("petsc4py", "mpi4py")):
            raise SolverError(
                f"solver backend {name!r} is not installed (needs petsc4py and mpi4py built against an "
                "installed PETSc; see the README's section on PETSc)")
        return name
    if name not in _BACKENDS:
        raise SolverError(f"unknown solver backend {name!r}; pick one of {', '.join(BACKEND_CHOICES)}")
    if name not in available:
        raise SolverError(
            f"solver backend {name!r} is not installed (available: {', '.join(available)}); "
            f"install the extra: pip install 'contactfem[{_EXTRAS.get(name, name)}]'"
        )
    return name


class Factorizer:
    """Factorises SPD matrices of one sparsity pattern with one backend, keeping what the
    backend can reuse between them (CHOLMOD's ordering and symbolic analysis).

    A factorisation returned by :meth:`factorize` may share its storage with the next one
    (CHOLMOD overwrites the numeric factor in place): use only the latest. ``seconds``
    holds the wall time of each factorisation, the first one with its analysis, and
    ``analysis_seconds`` the part of it a refactorisation of the same pattern skips (the
    ordering, the symbolic analysis and the backend's copy of the pattern; 0 when reused,
    and the whole time for a backend that reuses nothing).
    """

    def __init__(self, backend: str = "auto", *, name: str = "the matrix") -> None:
        self.backend = resolve_backend(backend)
        self.name = name
        self.seconds: list[float] = []
        self.analysis_seconds: list[float] = []
        self._analysis: object | None = None
        self._pattern: tuple[int, int] | None = None
        #: Seconds of the analysis made ahead of the factorisations (:meth:`analyse`).
        self.ahead_seconds = 0.0

    def analyse(self, matrix: sp.spmatrix) -> None:
        """Order and analyse ``matrix``'s pattern now, for the factorisations to come (a
        backend that reuses no analysis does nothing): the first then costs only its numbers.
        May run in another thread than this Factorizer's factorisations, not during one."""
        started = time.perf_counter()
        analyse = _ANALYSES.get(_implementation(self.backend))
        analysis = analyse(matrix, self.name) if analyse is not None else None
        if analysis is not None:
            self._analysis, self._pattern = analysis, (matrix.shape[0], matrix.nnz)
            self.ahead_seconds = time.perf_counter() - started

    def factorize(self, matrix: sp.spmatrix, *, check: bool = True,
                  equations: np.ndarray | None = None) -> Factorization:
        """Factorise ``matrix`` (see :func:`factorize`), reusing the analysis when its
        pattern is the one analysed (same shape and number of stored entries)."""
        if not np.isfinite(matrix.data).all():
            raise SolverError(
                f"{self.name} has non-finite entries ({int(np.sum(~np.isfinite(matrix.data)))} of them)")
        pattern = (matrix.shape[0], matrix.nnz)
        analysis = self._analysis if pattern == self._pattern else None
        started = time.perf_counter()
        factor = _implementation(self.backend)(matrix, self.name, analysis)
        self.seconds.append(time.perf_counter() - started)
        self.analysis_seconds.append(getattr(factor, "analysis_seconds", 0.0))
        self._analysis = getattr(factor, "analysis", None)
        self._pattern = pattern if self._analysis is not None else None
        if check:
            check_factorization(matrix, factor, equations=equations, name=self.name)
        return factor


def factorize(matrix: sp.spmatrix, backend: str = "auto", *, check: bool = True,
              equations: np.ndarray | None = None, name: str = "the matrix") -> Factorization:
    """Factorise an SPD sparse matrix with the named backend (already resolved or ``auto``).

    Raises :class:`SolverError` (one line naming what was detected) for non-finite
    entries, a factorisation the backend refuses, and, with ``check`` (the default), a
    matrix the probe of :func:`check_factorization` finds singular or numerically singular.
    ``equations`` (bool mask) and ``name`` are passed to the probe; a caller that wants to
    fold the probe's solve into one of its own passes ``check=False`` and calls
    :func:`check_factorization` itself.
    """
    return Factorizer(backend, name=name).factorize(matrix, check=check, equations=equations)


def probe_vector(size: int, equations: np.ndarray | None = None) -> np.ndarray:
    """The probe's right-hand side: uniform in [0.5, 1.5] on ``equations``, zero elsewhere.

    Positive entries give every rigid motion of a part (and every smooth soft mode) a
    component of the order of ‖b‖, which is what makes the probe see them.
    """
    probe = np.random.default_rng(_PROBE_SEED).uniform(0.5, 1.5, size)
    if equations is not None:
        probe[~np.asarray(equations, dtype=bool)] = 0.0
    return probe


def check_factorization(matrix: sp.spmatrix, factor: Factorization, *, equations: np.ndarray | None = None,
                        probe: np.ndarray | None = None, solution: np.ndarray | None = None,
                        norm: float | None = None, name: str = "the matrix") -> FactorCheck:
    """Probe ``factor`` of ``matrix`` with one solve; raise :class:`SolverError` if it is singular.

    Solves A x = b for b = :func:`probe_vector` (or ``probe``, with ``solution`` its solve if
    the caller already has it), and measures ‖b − A x‖∞ / ‖b‖∞ and κ̂ = ‖A‖∞ ‖x‖∞ / ‖b‖∞
    over the rows of ``equations`` (default all; rows outside it must be decoupled
    identity rows, such as masked supports, which would only blur the norms; ``norm``, their
    ‖A‖∞, if the caller has it). A residual
    above :data:`SINGULARITY_LIMIT` gets one step of iterative refinement, so that a solve
    that is merely not backward stable is not mistaken for a singular matrix. Costs one
    solve and two products with A (one more of each when refining).
    """
    size = matrix.shape[0]
    rows = np.ones(size, dtype=bool) if equations is None else np.asarray(equations, dtype=bool)
    if not rows.any():
        return FactorCheck(residual=0.0, condition=1.0)
    b = probe_vector(size, rows) if probe is None else np.asarray(probe, dtype=float)
    x = np.asarray(factor.solve(b) if solution is None else solution, dtype=float).reshape(size)
    scale = np.abs(b[rows]).max()
    matrix = sp.csr_matrix(matrix)
    if norm is None:
        absolute = sp.csr_matrix((np.abs(matrix.data), matrix.indices, matrix.indptr), shape=matrix.shape)
        norm = float((absolute @ np.ones(size))[rows].max())

    def measure(x: np.ndarray) -> tuple[np.ndarray, float]:
        residual = np.where(rows, b - matrix @ x, 0.0)
        return residual, float(np.abs(residual).max() / scale)

    refined = False
    if np.isfinite(x).all():
        residual, relative = measure(x)
        if relative > SINGULARITY_LIMIT:
            refined = True
            x = x + np.asarray(factor.solve(residual), dtype=float).reshape(size)
            residual, relative = measure(x) if np.isfinite(x).all() else (residual, np.inf)
    else:
        relative = np.inf
    if not np.isfinite(relative):
        raise SolverError(f"{name} is singular: solving with its factorisation gives non-finite values")
    condition = float(norm * np.abs(x[rows]).max() / scale)
    eps = np.finfo(float).eps
    if relative > SINGULARITY_LIMIT or eps * condition > SINGULARITY_LIMIT:
        raise SolverError(
            f"{name} is singular or numerically singular: probe residual {relative:.1e} after refinement, "
            f"condition estimate {condition:.1e} (eps*kappa {eps * condition:.1e}), bound {SINGULARITY_LIMIT:g} "
            "(a part of the body not held, or too slender for double precision)"
        )
    return FactorCheck(residual=relative, condition=condition, refined=refined)
