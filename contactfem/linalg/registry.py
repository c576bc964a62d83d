"""The solver backends by name: which are registered, which are installed here, which one a
name selects.

A backend is a name (what a case's ``solver.backend`` or ``--backend`` says) served by one
or more providers, each registered with :func:`register_backend`: the factory that
factorises a matrix, a test of whether its Python package is installed, the package's name,
and, for a backend that keeps the ordering and symbolic analysis of a pattern between
factorisations, the function that makes that analysis ahead (:meth:`Factorizer.analyse
<contactfem.linalg.Factorizer.analyse>`). Providers of one name are tried in the order
they were registered; names are ranked by :data:`PREFERENCE`, which is what ``auto``
follows.
"""

from __future__ import annotations

import functools
import importlib.util
from dataclasses import dataclass
from typing import Callable

import scipy.sparse as sp

from contactfem.errors import SolverError

#: Backend names, fastest first on 2D elasticity (README, benchmarks/results/solvers.json):
#: ``auto`` picks the first one installed. A name registered but not listed here comes after.
PREFERENCE = ("cholmod", "pardiso", "superlu")
#: Backends that run the whole solve across MPI ranks (:mod:`contactfem.distributed`, under
#: ``mpiexec ... contactfem solve``), not a :class:`~contactfem.linalg.Factorizer`.
DISTRIBUTED_BACKENDS = ("petsc",)
#: Python packages each distributed backend needs.
_DISTRIBUTED_MODULES = {"petsc": ("petsc4py", "mpi4py")}
#: Backends that solve each Newton step iteratively (CG with algebraic multigrid,
#: :class:`contactfem.kernel.iterative.IterativeSetSolver`), not a factorisation: what
#: ``auto`` turns to when a factorisation would not fit in memory
#: (:func:`contactfem.estimate.choose_backend`).
ITERATIVE_BACKENDS = ("amg",)
#: The Python package each iterative backend needs.
_ITERATIVE_MODULES = {"amg": "pyamg"}
#: The extra of contactfem's package that installs each optional backend.
EXTRAS = {"cholmod": "cholmod", "pardiso": "pardiso", "petsc": "petsc"}

#: A factory: ``factory(matrix, name, analysis=None)`` → a factorisation (see
#: :class:`~contactfem.linalg.Factorization`), raising SolverError for a matrix that is not
#: positive definite.
Factory = Callable[..., object]
#: An analysis made ahead: ``analyse(matrix, name)`` → what ``factory`` takes as ``analysis``,
#: or None when it makes none for this matrix.
Analyse = Callable[[sp.spmatrix, str], object]


@functools.lru_cache(maxsize=None)
def installed(module: str | None) -> bool:
    """Whether ``module`` can be imported (asked once: every factorisation resolves its backend)."""
    if module is None:
        return True
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


@dataclass(frozen=True)
class BackendEntry:
    """One provider of a backend: see :func:`register_backend`."""

    name: str
    factory: Factory
    available: Callable[[], bool]
    provider: str
    analyse: Analyse | None = None


_REGISTRY: dict[str, list[BackendEntry]] = {}


def register_backend(name: str, factory: Factory, *, available: Callable[[], bool] | None = None,
                     provider: str | None = None, analyse: Analyse | None = None) -> BackendEntry:
    """Register ``factory`` as a provider of backend ``name``.

    Parameters
    ----------
    name : str
        The backend's name, as a case or the command line gives it (``cholmod``).
    factory : callable
        ``factory(matrix, name, analysis=None)``: factorises the SPD ``matrix`` (``name`` is
        what error messages call it), reusing ``analysis`` (what an earlier factorisation's
        ``analysis`` attribute or ``analyse`` returned) when it is not None.
    available : callable, optional
        Whether this provider can run here (asked at every resolution; cheap). Default:
        the module named ``provider`` can be imported.
    provider : str, optional
        The Python package that provides the backend (reported by
        :func:`backend_provider`). Default: ``scipy``, always installed.
    analyse : callable, optional
        ``analyse(matrix, name)``: the ordering and symbolic analysis of ``matrix``'s
        pattern, made ahead of its factorisations; for backends that reuse one.

    Returns
    -------
    BackendEntry
        The entry made. Providers of one name are preferred in the order registered.
    """
    if provider is None:
        provider = "scipy"
        available = available or (lambda: True)
    elif available is None:
        available = functools.partial(installed, provider)
    entry = BackendEntry(name, factory, available, provider, analyse)
    _REGISTRY.setdefault(name, []).append(entry)
    return entry


def backend_names() -> tuple[str, ...]:
    """Every registered backend name, in :data:`PREFERENCE` order, then registration order."""
    ranked = [name for name in PREFERENCE if name in _REGISTRY]
    return (*ranked, *(name for name in _REGISTRY if name not in ranked))


def backend_entry(name: str) -> BackendEntry:
    """The provider that serves backend ``name`` here: the first registered that is available."""
    for entry in _REGISTRY.get(name, ()):
        if entry.available():
            return entry
    raise SolverError(f"solver backend {name!r} is not installed")


def backend_provider(name: str) -> str:
    """The Python package that provides backend ``name`` here (``scipy`` for SuperLU)."""
    return backend_entry(name).provider


def available_backends() -> list[str]:
    """Names of the backends whose libraries are importable, fastest first."""
    return [name for name in backend_names() if any(entry.available() for entry in _REGISTRY[name])]


def backend_choices() -> tuple[str, ...]:
    """What a case or the command line may ask for: ``auto``, a registered name, an iterative
    or a distributed backend."""
    return ("auto", *backend_names(), *ITERATIVE_BACKENDS, *DISTRIBUTED_BACKENDS)


def iterative_available(name: str = "amg") -> bool:
    """Whether the iterative backend ``name`` can run here (its package is installed)."""
    return installed(_ITERATIVE_MODULES[name])


def resolve_backend(name: str = "auto") -> str:
    """The backend that ``name`` selects: ``auto`` is the fastest available direct one (which
    :func:`contactfem.estimate.choose_backend` may replace by ``amg`` for a system whose
    factorisation would not fit in memory).

    Raises
    ------
    SolverError
        For a name that is not a backend (the message lists the valid ones) or one not
        installed here (the message lists those that are, and the extra to install).
    """
    available = available_backends()
    if name == "auto":
        return available[0]
    if name in DISTRIBUTED_BACKENDS:
        if not all(installed(module) for module in _DISTRIBUTED_MODULES[name]):
            raise SolverError(
                f"solver backend {name!r} is not installed (needs petsc4py and mpi4py built against an "
                "installed PETSc; see the README's section on PETSc)")
        return name
    if name in ITERATIVE_BACKENDS:
        if not iterative_available(name):
            raise SolverError(f"solver backend {name!r} is not installed (needs {_ITERATIVE_MODULES[name]}): "
                              f"pip install {_ITERATIVE_MODULES[name]}")
        return name
    if name not in _REGISTRY:
        raise SolverError(f"unknown solver backend {name!r}; pick one of {', '.join(backend_choices())}")
    if name not in available:
        raise SolverError(
            f"solver backend {name!r} is not installed (available: {', '.join(available)}); "
            f"install the extra: pip install 'contactfem[{EXTRAS.get(name, name)}]'"
        )
    return name
