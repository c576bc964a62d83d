"""Sparse direct factorisations of symmetric positive definite matrices, behind one small interface.

Backends, fastest first on 2D elasticity (see README): CHOLMOD (scikit-sparse, AMD
ordering), Pardiso (pypardiso, mtype=2), SuperLU (scipy, always there). SuperLU runs
with the MMD_AT_PLUS_A ordering: scipy's default COLAMD is an order of magnitude
slower and heavier on these matrices.
"""

from __future__ import annotations

import importlib.util
from typing import Callable, Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from contactfem.errors import SolverError


class Factorization(Protocol):
    def solve(self, rhs: np.ndarray) -> np.ndarray: ...


def _symmetric_csc(matrix: sp.spmatrix) -> sp.csc_matrix:
    """CSC form of a symmetric matrix: a CSR matrix's transpose is one, without a copy."""
    if sp.isspmatrix_csr(matrix) or isinstance(matrix, sp.csr_array):
        return matrix.T.tocsc(copy=False)
    return sp.csc_matrix(matrix)


class _Cholmod:
    def __init__(self, matrix: sp.spmatrix) -> None:
        from sksparse.cholmod import CholmodNotPositiveDefiniteError, cholesky

        try:
            self._factor = cholesky(_symmetric_csc(matrix), ordering_method="amd")
        except CholmodNotPositiveDefiniteError as error:
            raise SolverError(f"the stiffness matrix is not positive definite ({error})") from error

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._factor(rhs)


class _Pardiso:
    def __init__(self, matrix: sp.spmatrix) -> None:
        import pypardiso

        self._solver = pypardiso.PyPardisoSolver(mtype=2)
        # mtype=2 (real SPD) reads the upper triangle only.
        self._matrix = sp.triu(matrix, format="csr")
        self._solver.factorize(self._matrix)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._solver.solve(self._matrix, rhs)


class _SuperLU:
    def __init__(self, matrix: sp.spmatrix) -> None:
        try:
            self._lu = spla.splu(
                _symmetric_csc(matrix),
                permc_spec="MMD_AT_PLUS_A",
                diag_pivot_thresh=0.0,
                options={"SymmetricMode": True},
            )
        except RuntimeError as error:  # "Factor is exactly singular"
            raise SolverError(f"the stiffness matrix is singular ({error})") from error

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._lu.solve(rhs)


_BACKENDS: dict[str, tuple[str | None, Callable[[sp.spmatrix], Factorization]]] = {
    "cholmod": ("sksparse", _Cholmod),
    "pardiso": ("pypardiso", _Pardiso),
    "superlu": (None, _SuperLU),
}

BACKEND_NAMES = tuple(_BACKENDS)
#: What a case or the command line may ask for: a backend by name, or ``auto`` (the fastest installed).
BACKEND_CHOICES = ("auto", *BACKEND_NAMES)


def available_backends() -> list[str]:
    """Names of the backends whose libraries are importable, fastest first."""
    return [
        name for name, (module, _) in _BACKENDS.items()
        if module is None or importlib.util.find_spec(module) is not None
    ]


def resolve_backend(name: str = "auto") -> str:
    """The backend that ``name`` selects: ``auto`` is the fastest available one."""
    available = available_backends()
    if name == "auto":
        return available[0]
    if name not in _BACKENDS:
        raise SolverError(f"unknown solver backend {name!r}; pick one of {', '.join(BACKEND_CHOICES)}")
    if name not in available:
        raise SolverError(
            f"solver backend {name!r} is not installed (available: {', '.join(available)}); "
            f"install the extra: pip install 'contactfem[{name}]'"
        )
    return name


def factorize(matrix: sp.spmatrix, backend: str = "auto") -> Factorization:
    """Factorise an SPD sparse matrix with the named backend (already resolved or ``auto``)."""
    return _BACKENDS[resolve_backend(backend)][1](matrix)
