"""The matrix forms the backends read, and handing freed memory back to the system."""

from __future__ import annotations

import ctypes

import scipy.sparse as sp


def symmetric_csc(matrix: sp.spmatrix) -> sp.csc_matrix:
    """CSC form of a symmetric matrix: a CSR matrix's transpose is one, without a copy."""
    if sp.isspmatrix_csr(matrix) or isinstance(matrix, sp.csr_array):
        return matrix.T.tocsc(copy=False)
    return sp.csc_matrix(matrix)


def canonical_csr(matrix: sp.spmatrix) -> sp.csr_matrix:
    """``matrix`` as CSR with sorted, unique column indices (copied only when it is not)."""
    csr = sp.csr_matrix(matrix)
    if not csr.has_canonical_format:
        csr = csr.copy()
        csr.sum_duplicates()
    return csr


def release_freed_memory() -> None:
    """Hand the conversion's freed buffers back to the system before the factor is allocated
    (glibc keeps them otherwise, and they would add to the peak: 0.1 GB at 525 000 unknowns)."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
