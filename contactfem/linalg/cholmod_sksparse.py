"""CHOLMOD through scikit-sparse (which links the system's SuiteSparse and BLAS), where
cvxopt has no wheel (``pip install 'contactfem[cholmod]'``): AMD ordering, a supernodal
LLᵀ factor, the ordering and symbolic analysis kept for later matrices of the pattern."""

from __future__ import annotations

import functools
import warnings

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.linalg.costs import MODEL, FactorCost, cholesky_flops, estimated_flops
from contactfem.linalg.registry import register_backend
from contactfem.linalg.storage import symmetric_csc


class SksparseCholmodFactor:
    """CHOLMOD through scikit-sparse (which links the system's SuiteSparse and BLAS).

    scikit-sparse gives L's pattern only as a converted copy of the factor (``Factor.L()``),
    so :attr:`cost` is counted on request, once; :attr:`estimated_cost` is free (the
    matrix's upper triangle as a lower bound of the entries). ``analysis_seconds`` is
    modelled from the matrix's entries (:mod:`contactfem.linalg.costs`).
    """

    #: Whether :attr:`cost` is counted only on request (see :attr:`estimated_cost`).
    COUNTS_ON_REQUEST = True

    @staticmethod
    def analyse(matrix: sp.spmatrix, name: str) -> object:
        """The ordering and symbolic analysis of ``matrix``'s pattern: the factor object a
        factorisation fills."""
        from sksparse.cholmod import analyze

        # Supernodal always: for small factors CHOLMOD's default picks a simplicial LDL^T,
        # which accepts a negative pivot without a word.
        return analyze(symmetric_csc(matrix), ordering_method="amd", mode="supernodal")

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: object | None = None) -> None:
        from sksparse.cholmod import CholmodNotPositiveDefiniteError

        csc = symmetric_csc(matrix)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                factor = self.analyse(csc, name) if analysis is None else analysis
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
        self._size, self._matrix_entries = csc.shape[0], int(csc.nnz)
        #: Modelled seconds of the ordering and symbolic analysis made here (0 when reused).
        self.analysis_seconds = MODEL.analysis_seconds(self.estimated_cost) if analysis is None else 0.0

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._factor(rhs)

    @property
    def estimated_cost(self) -> FactorCost:
        """A lower estimate: the matrix's upper triangle for the factor's entries, flops from them."""
        entries = (self._matrix_entries + self._size) // 2
        return FactorCost(size=self._size, entries=entries, flops=estimated_flops(entries, self._size),
                          matrix_entries=self._matrix_entries)

    @functools.cached_property
    def cost(self) -> FactorCost:
        """The counted cost: L's stored entries and Σ c_j² over its column counts, from
        scikit-sparse's converted copy of L (made once, on request)."""
        counts = np.diff(self._factor.L().indptr)
        return FactorCost(size=self._size, entries=int(counts.sum()), flops=cholesky_flops(counts),
                          matrix_entries=self._matrix_entries)


register_backend("cholmod", SksparseCholmodFactor, provider="sksparse", analyse=SksparseCholmodFactor.analyse)
