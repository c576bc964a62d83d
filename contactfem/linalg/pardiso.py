"""Intel MKL Pardiso through pypardiso (mtype=2, real SPD), where it is installed
(``pip install 'contactfem[pardiso]'``). It factorises afresh every time."""

from __future__ import annotations

import weakref

import numpy as np
import scipy.sparse as sp

from contactfem.errors import SolverError
from contactfem.linalg.costs import FactorCost, estimated_flops
from contactfem.linalg.registry import register_backend


class PardisoFactor:
    """A Pardiso factorisation; ``analysis`` is always None: nothing is reused.

    Its factor is opaque: :attr:`cost` takes its stored entries from what Pardiso reports
    (iparm(18), the nonzeros of the factor, which pypardiso leaves on with MKL's defaults;
    the matrix's upper triangle where it reports none), and estimates its flops from them
    (:func:`~contactfem.linalg.costs.estimated_flops`).
    """

    analysis = None

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: object | None = None) -> None:
        import pypardiso

        self._solver = pypardiso.PyPardisoSolver(mtype=2)
        # MKL keeps a factor in its own memory until it is released (phase -1), which the
        # solver object does not do when collected: every factorisation would stay resident
        # to the end of the process, and a convergence study would hold all of its levels'.
        # Released with this object.
        weakref.finalize(self, self._solver.free_memory, True)
        # mtype=2 (real SPD) reads the upper triangle only.
        self._matrix = sp.triu(matrix, format="csr")
        try:
            self._solver.factorize(self._matrix)
        except Exception as error:  # pypardiso.PyPardisoError: zero or negative pivot, ...
            # Error -4 is a zero pivot: for mtype=2, a matrix that is singular or not positive definite.
            what = "is singular or not positive definite" if "-4" in str(error) else "cannot be factorised"
            raise SolverError(f"{name} {what} (Pardiso: {error})") from error
        size = self._matrix.shape[0]
        reported = int(self._solver.iparm[17]) if len(getattr(self._solver, "iparm", ())) > 17 else 0
        entries = reported if reported >= size else int(self._matrix.nnz)
        #: The counted cost (entries as Pardiso reports them, flops estimated).
        self.cost = FactorCost(size=size, entries=entries, flops=estimated_flops(entries, size), kind="pardiso",
                               matrix_entries=int(matrix.nnz))

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._solver.solve(self._matrix, rhs)


register_backend("pardiso", PardisoFactor, provider="pypardiso")
