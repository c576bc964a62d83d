"""SuperLU (SciPy's, always installed), in symmetric mode without pivoting.

It runs with the MMD_AT_PLUS_A ordering: SciPy's default COLAMD is an order of magnitude
slower and heavier on these matrices. It factorises afresh every time (reusing its column
ordering, by permuting the matrix and ordering NATURAL, was measured far slower: SciPy's
NATURAL skips the postorder supernodes need), and its integers are 32-bit in SciPy 1.17
(:func:`superlu_max_nonzeros`).
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from contactfem.errors import FactorCapacityError, SolverError
from contactfem.linalg.costs import FactorCost, estimated_flops, lu_flops
from contactfem.linalg.registry import register_backend
from contactfem.linalg.storage import symmetric_csc

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


class SuperLUFactor:
    """A SuperLU factorisation (see the module's docstring); ``analysis`` is always None:
    nothing is reused.

    Its counted cost (:attr:`cost`) needs L's column counts and U's row counts, which SciPy
    only gives through CSC copies of L and U that it then keeps with the factor (0.9 s and
    0.3 GB for a factorisation of 1.4 s at 132 000 unknowns): they are counted on request,
    once. :attr:`estimated_cost` is free: the stored entries, flops estimated from them.
    """

    analysis = None
    #: Whether :attr:`cost` is counted only on request (see :attr:`estimated_cost`).
    COUNTS_ON_REQUEST = True

    def __init__(self, matrix: sp.spmatrix, name: str, analysis: object | None = None) -> None:
        full = symmetric_csc(matrix)
        self._matrix_entries = int(full.nnz)
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

    @property
    def estimated_cost(self) -> FactorCost:
        """The factors' stored entries (counted), and flops estimated from them as those of a
        Cholesky factor of half of them (:func:`~contactfem.linalg.costs.estimated_flops`),
        twice over for L and U."""
        size, entries = self._lu.shape[0], int(self._lu.nnz)
        return FactorCost(size=size, entries=entries, flops=2.0 * estimated_flops((entries + size) // 2, size),
                          kind="superlu", matrix_entries=self._matrix_entries)

    @functools.cached_property
    def cost(self) -> FactorCost:
        """The counted cost: nnz(L) + nnz(U), and flops from L's column counts and U's row
        counts (:func:`~contactfem.linalg.costs.lu_flops`). Costs SciPy's copies of L and U
        the first time (see the class)."""
        lower, upper = self._lu.L, self._lu.U
        size = self._lu.shape[0]
        flops = lu_flops(np.diff(lower.indptr), np.bincount(upper.indices, minlength=size))
        return FactorCost(size=size, entries=int(lower.nnz + upper.nnz), flops=flops, kind="superlu",
                          matrix_entries=self._matrix_entries)


register_backend("superlu", SuperLUFactor)
