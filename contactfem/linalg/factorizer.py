"""Factorising SPD matrices of one sparsity pattern with one backend: :class:`Factorizer`
keeps what the backend can reuse between them (CHOLMOD's ordering and symbolic analysis:
a refactorisation then costs about 0.6 of a first factorisation at 525 000 unknowns), and
probes every factorisation for singularity (:func:`~contactfem.linalg.check_factorization`).
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.linalg.probe import Factorization, check_factorization
from contactfem.linalg.registry import backend_entry, resolve_backend


def solve_sparse_columns(factor: Factorization, rhs: sp.spmatrix) -> np.ndarray:
    """X (n, k), Fortran-ordered, with A X = ``rhs`` for a sparse block of right-hand sides
    (unit vectors, rows of the stiffness): through the backend's sparse solve when it has
    one (CHOLMOD), else densely."""
    sparse_solve = getattr(factor, "solve_sparse", None)
    if sparse_solve is not None:
        return sparse_solve(sp.csc_matrix(rhs))
    return np.asfortranarray(np.asarray(factor.solve(rhs.toarray())).reshape(rhs.shape))


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
        analyse = backend_entry(self.backend).analyse
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
        factor = backend_entry(self.backend).factory(matrix, self.name, analysis)
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
