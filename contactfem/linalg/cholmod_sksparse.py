"""CHOLMOD through scikit-sparse (which links the system's SuiteSparse and BLAS), where
cvxopt has no wheel (``pip install 'contactfem[cholmod]'``): AMD ordering, a supernodal
LLᵀ factor, the ordering and symbolic analysis kept for later matrices of the pattern."""

from __future__ import annotations

import time
import warnings

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.linalg.registry import register_backend
from contactfem.linalg.storage import symmetric_csc


class SksparseCholmodFactor:
    """CHOLMOD through scikit-sparse (which links the system's SuiteSparse and BLAS)."""

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


register_backend("cholmod", SksparseCholmodFactor, provider="sksparse", analyse=SksparseCholmodFactor.analyse)
