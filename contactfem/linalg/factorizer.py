"""Factorising SPD matrices of one sparsity pattern with one backend: :class:`Factorizer`
keeps what the backend can reuse between them (CHOLMOD's ordering and symbolic analysis:
a refactorisation then costs about 0.6 of a first factorisation at 525 000 unknowns), and
probes every factorisation for singularity (:func:`~contactfem.linalg.check_factorization`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.linalg.costs import MODEL, FactorCost
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
    (CHOLMOD overwrites the numeric factor in place): use only the latest.

    Attributes
    ----------
    costs : list of FactorCost
        The counted cost of each factorisation (for a backend that counts only on request,
        SuperLU and scikit-sparse's CHOLMOD, its free estimate: ``estimated_cost``).
    analysis_seconds : list of float
        Modelled seconds of the part of each factorisation that a refactorisation of the
        same pattern skips (the ordering, the symbolic analysis and the backend's copy of
        the pattern): 0 when an analysis was reused, and for a backend that reuses none.
    seconds : list of float
        Modelled seconds of each factorisation, its analysis included.
    ahead_seconds : float
        Modelled seconds of the analysis made ahead (:meth:`analyse`; 0 if none).

    Every figure in seconds is modelled: counted work divided by the rates in
    :mod:`contactfem.linalg.costs`; none is read from a clock.
    """

    def __init__(self, backend: str = "auto", *, name: str = "the matrix") -> None:
        self.backend = resolve_backend(backend)
        self.name = name
        self.costs: list[FactorCost] = []
        self.analysis_seconds: list[float] = []
        self._analysis: object | None = None
        self._pattern: tuple[int, int] | None = None
        self.ahead_seconds = 0.0

    @property
    def seconds(self) -> list[float]:
        """Modelled seconds of each factorisation so far, its analysis included."""
        return [analysis + MODEL.factorize_seconds(cost) for cost, analysis in zip(self.costs, self.analysis_seconds)]

    def analyse(self, matrix: sp.spmatrix) -> None:
        """Order and analyse ``matrix``'s pattern now, for the factorisations to come (a
        backend that reuses no analysis does nothing): the first then costs only its numbers.
        May run in another thread than this Factorizer's factorisations, not during one."""
        analyse = backend_entry(self.backend).analyse
        analysis = analyse(matrix, self.name) if analyse is not None else None
        if analysis is not None:
            self._analysis, self._pattern = analysis, (matrix.shape[0], matrix.nnz)
            cost = getattr(analysis, "cost", None)
            if not isinstance(cost, FactorCost):  # only the matrix's entries are needed
                cost = FactorCost(size=matrix.shape[0], entries=matrix.shape[0], flops=0.0,
                                  matrix_entries=int(matrix.nnz))
            self.ahead_seconds = MODEL.analysis_seconds(cost)

    def factorize(self, matrix: sp.spmatrix, *, check: bool = True,
                  equations: np.ndarray | None = None) -> Factorization:
        """Factorise ``matrix`` (see :func:`factorize`), reusing the analysis when its
        pattern is the one analysed (same shape and number of stored entries)."""
        if not np.isfinite(matrix.data).all():
            raise SolverError(
                f"{self.name} has non-finite entries ({int(np.sum(~np.isfinite(matrix.data)))} of them)")
        pattern = (matrix.shape[0], matrix.nnz)
        analysis = self._analysis if pattern == self._pattern else None
        factor = backend_entry(self.backend).factory(matrix, self.name, analysis)
        self.costs.append(factor.estimated_cost if getattr(factor, "COUNTS_ON_REQUEST", False) else factor.cost)
        self.analysis_seconds.append(float(getattr(factor, "analysis_seconds", 0.0)))
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
