"""CHOLMOD from cvxopt's wheel (a default dependency where cvxopt publishes one): the
``cholmod`` backend's first provider.

A factorisation goes to the CHOLMOD library the wheel bundles, called directly through
ctypes (:mod:`contactfem.linalg.cholmod_direct`), where that library is found and its
layout is the known one, and through cvxopt's own interface (:class:`CvxoptCholmodFactor`)
otherwise. The direct route can be switched off: ``CONTACTFEM_CHOLMOD_DIRECT=0`` in the
environment, or :func:`set_direct_cholmod` / :func:`direct_cholmod` in the program. Switched
off, every factorisation goes through cvxopt's interface, and the direct route's modules
are not even imported (nothing is loaded through ctypes).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.linalg.costs import MODEL, FactorCost, estimated_flops
from contactfem.linalg.registry import register_backend
from contactfem.linalg.storage import canonical_csr, release_freed_memory

#: CHOLMOD's Common->supernodal value that always asks for a supernodal factor.
_CHOLMOD_SUPERNODAL = 2
#: The environment variable that switches the direct route off when it is 0 (or false, no, off).
DIRECT_ENVIRONMENT = "CONTACTFEM_CHOLMOD_DIRECT"
_OFF = ("0", "false", "no", "off")
#: The program's setting (:func:`set_direct_cholmod`), None to follow the environment.
_direct_setting: bool | None = None
_SETTING_LOCK = threading.Lock()


def direct_cholmod_enabled() -> bool:
    """Whether CHOLMOD from cvxopt's wheel may be called directly through ctypes: the
    setting of :func:`set_direct_cholmod`, or else the environment variable
    ``CONTACTFEM_CHOLMOD_DIRECT`` (on unless it is ``0``, ``false``, ``no`` or ``off``)."""
    if _direct_setting is not None:
        return _direct_setting
    return os.environ.get(DIRECT_ENVIRONMENT, "1").strip().lower() not in _OFF


def set_direct_cholmod(enabled: bool | None) -> None:
    """Switch the direct route to cvxopt's bundled CHOLMOD on or off for this process.

    Parameters
    ----------
    enabled : bool or None
        False: every later factorisation goes through cvxopt's interface, and the library
        is never loaded through ctypes (unless it was already); True: the direct route
        where the library is found; None: back to the environment variable
        ``CONTACTFEM_CHOLMOD_DIRECT``. A :class:`~contactfem.linalg.Factorizer` whose
        analysis was made by the other route analyses its pattern afresh.
    """
    global _direct_setting
    with _SETTING_LOCK:
        _direct_setting = None if enabled is None else bool(enabled)


@contextmanager
def direct_cholmod(enabled: bool) -> Iterator[None]:
    """:func:`set_direct_cholmod` for a ``with`` block; the previous setting is restored after it.

    Examples
    --------
    >>> from contactfem.linalg import direct_cholmod, factorize
    >>> with direct_cholmod(False):          # doctest: +SKIP
    ...     factor = factorize(matrix, "cholmod")  # through cvxopt's interface
    """
    previous = _direct_setting
    set_direct_cholmod(enabled)
    try:
        yield
    finally:
        set_direct_cholmod(previous)


@dataclass
class CvxoptAnalysis:
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


class CvxoptCholmodFactor:
    """CHOLMOD through cvxopt's interface, where its bundled library cannot be called
    directly (see :mod:`contactfem.linalg.cholmod_direct`).

    cvxopt takes its own sparse matrix of one triangle, built from triplets in its column
    order: the upper one, which CHOLMOD's supernodal factorisation takes about twice as
    fast as the lower one, with a lower peak. A refactorisation of the same pattern (the
    kernel's, masked differently for each active set) only gathers the new values into
    that matrix rather than rebuilding it. Keeping it costs no peak memory: it
    exists during every numeric factorisation anyway. A non-positive pivot raises
    ArithmeticError, reported as a SolverError.
    """

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: "CvxoptAnalysis | None" = None) -> None:
        import cvxopt
        from cvxopt import cholmod

        csr = canonical_csr(matrix)
        reused = analysis is not None and analysis.matches(csr)
        if reused:
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
            release_freed_memory()
            # Always supernodal LLᵀ: CHOLMOD's default picks a simplicial LDLᵀ for small,
            # sparse factors, which passes a negative pivot silently.
            cholmod.options["supernodal"] = _CHOLMOD_SUPERNODAL  # cvxopt cannot ask for a simplicial LLᵀ
            symbolic = cholmod.symbolic(stored, uplo="U")
        n = csr.shape[0]
        entries = (csr.nnz + n) // 2
        #: A lower estimate of the cost: cvxopt's interface does not show its factor (reading
        #: it converts it to a pattern), so the matrix's upper triangle stands for its entries.
        self.cost = FactorCost(size=n, entries=entries, flops=estimated_flops(entries, n), kind="cholmod-interface",
                               matrix_entries=int(csr.nnz))
        #: Modelled seconds of the ordering, symbolic analysis and copy made here (0 when reused).
        self.analysis_seconds = 0.0 if reused else MODEL.analysis_seconds(self.cost)
        try:
            cholmod.numeric(stored, symbolic)
        except ArithmeticError as error:
            raise SolverError(f"{name} is singular or not positive definite (CHOLMOD: pivot {error} is not positive)") from error
        self._cholmod, self._dense = cholmod, cvxopt.matrix
        self._factor = symbolic
        self.analysis = CvxoptAnalysis(symbolic, stored, positions, csr.indptr, csr.indices)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        shape = rhs.shape
        block = self._dense(np.asfortranarray(rhs.reshape(shape[0], -1)))
        self._cholmod.solve(self._factor, block)
        return np.array(block).reshape(shape)

    def backward(self, rhs: np.ndarray) -> np.ndarray:
        """x = Pᵀ L⁻ᵀ v for ``rhs`` v in the factor's order, (n,) or (n, k): with the scaled
        columns D⁻¹ W of :meth:`forward_sparse`, A⁻¹ B y = backward(D⁻¹ W y), half a full solve."""
        rhs = np.asarray(rhs, dtype=float)
        shape = rhs.shape
        block = self._dense(np.asfortranarray(rhs.reshape(shape[0], -1)))
        self._cholmod.solve(self._factor, block, sys=5)
        self._cholmod.solve(self._factor, block, sys=8)
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
    #: column at a time, its sparse one in small dense blocks, about twice as fast per column
    #: at 4; more columns cost more to convert back (docs/performance.md#measured-design-choices).
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


def _direct_serves(matrix: sp.spmatrix) -> bool:
    """Whether cvxopt's bundled CHOLMOD is called directly for ``matrix``: the route is
    switched on (:func:`direct_cholmod_enabled`), and the library found and the matrix
    within its int interface (:func:`contactfem.linalg.cholmod_direct.serves`)."""
    if not direct_cholmod_enabled():
        return False
    from contactfem.linalg import cholmod_direct

    return cholmod_direct.serves(matrix)


def cvxopt_cholmod(matrix: sp.spmatrix, name: str, analysis: object | None = None) -> object:
    """CHOLMOD from cvxopt's wheel: called directly where its bundled library is found,
    through cvxopt's interface otherwise."""
    if _direct_serves(matrix):
        from contactfem.linalg.cholmod_direct import DirectAnalysis, DirectCholmodFactor

        return DirectCholmodFactor(matrix, name, analysis if isinstance(analysis, DirectAnalysis) else None)
    return CvxoptCholmodFactor(matrix, name, analysis if isinstance(analysis, CvxoptAnalysis) else None)


def cvxopt_cholmod_analysis(matrix: sp.spmatrix, name: str) -> object | None:
    """The bundled library's analysis, where :func:`cvxopt_cholmod` calls the library; None
    through cvxopt's interface, which analyses with its own copy of the matrix."""
    if _direct_serves(matrix):
        from contactfem.linalg.cholmod_direct import DirectCholmodFactor

        return DirectCholmodFactor.analyse(matrix, name)
    return None


register_backend("cholmod", cvxopt_cholmod, provider="cvxopt", analyse=cvxopt_cholmod_analysis)
