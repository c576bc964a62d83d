"""Sparse direct factorisations of symmetric positive definite matrices, behind one small interface.

Backends, fastest first on 2D elasticity (see README), each in its own module and
registered by name (:mod:`~contactfem.linalg.registry`):

- ``cholmod``: CHOLMOD (AMD ordering; supernodal or simplicial LLᵀ). From cvxopt's wheel,
  a default dependency where it has a wheel: the library it bundles called directly
  (:mod:`~contactfem.linalg.cholmod_direct`), or cvxopt's own interface
  (:mod:`~contactfem.linalg.cholmod_cvxopt`); else through scikit-sparse
  (:mod:`~contactfem.linalg.cholmod_sksparse`);
- ``pardiso``: MKL Pardiso through pypardiso, mtype=2 (:mod:`~contactfem.linalg.pardiso`);
- ``superlu``: SciPy's SuperLU, always there (:mod:`~contactfem.linalg.superlu`).

Matrices that share one sparsity pattern (the contact kernel's, masked differently for
each active set) are factorised through a :class:`Factorizer`, which keeps CHOLMOD's
ordering and symbolic analysis and redoes only the numeric factorisation. Every
factorisation is probed for singularity (:func:`check_factorization`).

Every factorisation's cost is counted (``factor.cost``, a :class:`FactorCost`: its factor's
entries and its flops), and every figure in seconds the package gives is modelled from
such counts by the rates in :mod:`~contactfem.linalg.costs` (:data:`MODEL`): nothing here
reads a clock, so the same matrices always get the same choices.

The direct route to cvxopt's CHOLMOD reads the library's structs at fixed offsets (see
:mod:`~contactfem.linalg.cholmod_direct`); ``CONTACTFEM_CHOLMOD_DIRECT=0`` or
:func:`set_direct_cholmod` (``False``) sends ``cholmod`` through cvxopt's interface instead.
"""

from __future__ import annotations

# The backends register themselves on import; providers of one name are preferred in the
# order imported (cvxopt's CHOLMOD before scikit-sparse's).
from contactfem.linalg import cholmod_cvxopt, cholmod_sksparse, pardiso, superlu  # noqa: F401
from contactfem.linalg.cholmod_cvxopt import direct_cholmod, direct_cholmod_enabled, set_direct_cholmod
from contactfem.linalg.costs import MODEL, CostModel, FactorCost
from contactfem.linalg.factorizer import Factorizer, factorize, solve_sparse_columns
from contactfem.linalg.probe import (
    SINGULARITY_LIMIT,
    FactorCheck,
    Factorization,
    check_factorization,
    probe_vector,
)
from contactfem.linalg.registry import (
    DISTRIBUTED_BACKENDS,
    ITERATIVE_BACKENDS,
    available_backends,
    backend_choices,
    backend_names,
    backend_provider,
    iterative_available,
    register_backend,
    resolve_backend,
)
from contactfem.linalg.superlu import (
    SUPERLU_FILL_GUESS,
    SUPERLU_REMEDY,
    superlu_max_nonzeros,
    superlu_refusal,
)

#: The registered backend names, fastest first.
BACKEND_NAMES = backend_names()
#: What a case or the command line may ask for: a backend by name, or ``auto`` (the fastest installed).
BACKEND_CHOICES = backend_choices()

__all__ = [
    "BACKEND_CHOICES",
    "BACKEND_NAMES",
    "MODEL",
    "CostModel",
    "DISTRIBUTED_BACKENDS",
    "ITERATIVE_BACKENDS",
    "SINGULARITY_LIMIT",
    "SUPERLU_FILL_GUESS",
    "SUPERLU_REMEDY",
    "FactorCheck",
    "FactorCost",
    "Factorization",
    "Factorizer",
    "available_backends",
    "backend_provider",
    "check_factorization",
    "direct_cholmod",
    "direct_cholmod_enabled",
    "factorize",
    "iterative_available",
    "probe_vector",
    "register_backend",
    "resolve_backend",
    "set_direct_cholmod",
    "solve_sparse_columns",
    "superlu_max_nonzeros",
    "superlu_refusal",
]
