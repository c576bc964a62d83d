"""What a solve will cost, estimated before it runs, from rates measured once per backend.

Each backend has one reference point, the square case at :data:`REFERENCE_UNKNOWNS`: the
seconds of one factorisation and the peak bytes of a whole solve. A solve of another size
scales the time by the factorisation's growth on 2D meshes (slightly faster than linear,
:data:`GROWTH`) and the memory linearly, counts a contact solve as a little more than one
factorisation (mesh sequencing) and adds assembly and writing. The estimate orders
backends and guards memory; it is not a promise of seconds on another machine. The
reference figures come from ``benchmarks/square_sweep.py``, ``benchmarks/petsc_scaling.py``
and ``benchmarks/amg.py`` (see docs/performance.md#measured-design-choices).
"""

from __future__ import annotations

import contextvars
import os
import resource
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

#: The size, in displacement unknowns, at which :data:`FACTOR_SECONDS` and :data:`PEAK_BYTES` hold.
REFERENCE_UNKNOWNS = 2.1e6
# Seconds of one factorisation and bytes of a whole solve's peak, per backend, at
# REFERENCE_UNKNOWNS (benchmarks/results/square_sweep.json, petsc_scaling.json, amg.json).
# petsc: MUMPS on one rank; on P ranks each needs (1 + RANK_OVERHEAD (P − 1)) / P of it
# (see :func:`estimate_cost`). amg: CG with smoothed aggregation, every Newton step an
# iterative solve; its "factorisation" is one step's set-up and CG.
FACTOR_SECONDS = {"cholmod": 14.0, "pardiso": 11.0, "superlu": 50.0, "petsc": 26.6, "amg": 60.0}
PEAK_BYTES = {"cholmod": 5.0e9, "pardiso": 6.0e9, "superlu": 8.0e9, "petsc": 4.4e9, "amg": 3.2e9}
GROWTH = 1.1
#: What each further rank adds to a distributed solve's memory, as a share of the one-rank
#: peak: the interfaces' rows and MUMPS's separators held twice, the libraries per process.
#: Fitted to the largest rank's peak on two and four ranks (benchmarks/petsc_scaling.py),
#: taking the larger of the two fits so that the guard errs on the safe side.
RANK_OVERHEAD = 0.18
#: ``auto`` keeps the fastest direct backend while its estimated peak is at most this share
#: of the memory the process may use; beyond, it solves iteratively (see :func:`choose_backend`).
#: The rest is the model's margin (its error between meshes of one kind, checked against
#: the square's measured peaks in benchmarks/amg.py) and room for whatever else the machine
#: runs. A larger share keeps factorising closer to the limit, at more risk of running out.
DIRECT_MEMORY_SHARE = 0.75
#: The size guard refuses a solve whose modelled peak exceeds this share of the memory the
#: process may use. The model errs by up to a quarter between meshes of one kind, so a peak
#: modelled at the whole limit may well pass it, and the kernel's out-of-memory killer ends
#: the process without a word: refusing at 1/1.25 of the limit keeps the margin.
GUARD_SHARE = 0.8


def guarded_bytes(limit: "MemoryLimit") -> float:
    """What the size guard lets a solve's modelled peak reach: :data:`GUARD_SHARE` of ``limit``."""
    return GUARD_SHARE * limit.bytes


def guard_text(limit: "MemoryLimit") -> str:
    """How refusals name the bound: the limit, and the share of it the guard allows."""
    return f"{limit.source} allows ({GUARD_SHARE:.0%} of it, the cost model's margin)"


def estimate_cost(unknowns: int, backend: str, ranks: int = 1) -> dict[str, float]:
    """Seconds and bytes a solve of ``unknowns`` is expected to take with ``backend``; with
    ``ranks`` > 1 (petsc, each rank holding its piece of the mesh), the bytes of one rank."""
    scale = max(unknowns, 1) / REFERENCE_UNKNOWNS
    seconds = 1.3 * FACTOR_SECONDS[backend] * scale**GROWTH * 1.25
    share = (1 + RANK_OVERHEAD * (ranks - 1)) / ranks
    peak = PEAK_BYTES[backend] * scale * share + 0.15e9  # the interpreter and libraries
    return {"seconds": seconds, "bytes": peak}


@dataclass(frozen=True)
class BackendChoice:
    """The backend a solve of a given size uses, and why (``reason``, for report.json and ``check``)."""

    name: str
    reason: str


def choose_backend(unknowns: int, requested: str, limit: "MemoryLimit", iterative: bool = True) -> BackendChoice:
    """The backend that solves ``unknowns`` unknowns when the case asks for ``requested``.

    A named backend is taken as named. ``auto`` takes the fastest direct backend installed
    while the cost model (:func:`estimate_cost`: counted unknowns at measured rates, never
    the clock) puts its peak within :data:`DIRECT_MEMORY_SHARE` of ``limit``; beyond, it
    takes ``amg`` (CG with algebraic multigrid, which holds no factor) when ``iterative``
    (a solve that can run iteratively: not a load path) and pyamg is installed.

    Raises
    ------
    SolverError
        For a backend that is not installed (from :func:`contactfem.linalg.resolve_backend`).
    """
    from contactfem.linalg import iterative_available, resolve_backend

    backend = resolve_backend(requested)
    if requested != "auto":
        return BackendChoice(backend, f"solver.backend = {requested}")
    direct = estimate_cost(unknowns, backend)["bytes"]
    share = f"{DIRECT_MEMORY_SHARE:.0%} of {limit.source}"
    if direct <= DIRECT_MEMORY_SHARE * limit.bytes:
        return BackendChoice(backend, f"auto: the fastest direct backend installed; its factorisation needs about "
                                      f"{direct / 2**30:.3g} GiB, within {share}")
    if not iterative or not iterative_available():
        why = "a load path is solved by factorisations" if not iterative else "pyamg is not installed"
        return BackendChoice(backend, f"auto: a factorisation with {backend} needs about {direct / 2**30:.3g} GiB, "
                                      f"more than {share}, but {why}")
    iterative_bytes = estimate_cost(unknowns, "amg")["bytes"]
    return BackendChoice("amg", f"auto: a factorisation with {backend} needs about {direct / 2**30:.3g} GiB, more "
                                f"than {share}; CG with algebraic multigrid needs about "
                                f"{iterative_bytes / 2**30:.3g} GiB")


#: The fewest stiffness nonzeros per displacement unknown of a P1 mesh: two unknowns per node,
#: each coupled to its node and at least four others (a strip one triangle across); most
#: meshes have about 14, so the bound refuses only what no mesh could factorise.
MIN_NONZEROS_PER_UNKNOWN = 10


def backend_refusal(unknowns: int, backend: str) -> str | None:
    """Why ``backend`` cannot factorise the stiffness matrix of ``unknowns`` unknowns whatever
    the memory, or None: SciPy's SuperLU past its 32-bit first guess, with the fewest
    nonzeros such a mesh can have (the factorisation checks the matrix's own count)."""
    if backend != "superlu":
        return None
    from contactfem.linalg import superlu_refusal

    return superlu_refusal(MIN_NONZEROS_PER_UNKNOWN * unknowns, unknowns, at_least=True)


def largest_mesh_points(backend: str, memory: int) -> int:
    """The most mesh nodes whose solve the model fits in ``memory`` bytes with ``backend``."""
    scale = max(memory - 0.15e9, 0.0) / PEAK_BYTES[backend]
    return int(scale * REFERENCE_UNKNOWNS / 2)


def unknowns_of_triangles(triangles: int) -> int:
    """Displacement unknowns of a P1 mesh of ``triangles`` triangles: a planar triangulation has
    about half as many nodes as triangles, with two unknowns each."""
    return int(triangles)


def machine_memory() -> int:
    """This machine's physical memory in bytes (a default of 16 GiB when the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 16 * 2**30


#: Address space a solve maps beyond its resident peak: the shared libraries (VTK, CHOLMOD,
#: two OpenBLAS copies), thread stacks, and a buffer per BLAS thread: independent of the
#: mesh size, measured as VmPeak − VmHWM of `contactfem solve` (see
#: docs/performance.md#measured-design-choices). Under an address-space limit (``ulimit
#: -v``; Grid Engine's h_vmem) a solve needs its estimated peak plus this; short of it a
#: library's allocation fails where it cannot say so (OpenBLAS or CHOLMOD crash the
#: process, VTK fails to load), so the guard refuses first.
ADDRESS_SPACE_BASE = 0.50e9
ADDRESS_SPACE_PER_BLAS_THREAD = 0.08e9
#: A cgroup limit at or above this is no limit (cgroup v1 writes 2^63 rounded to a page).
_UNLIMITED = 2**60


@dataclass(frozen=True)
class MemoryLimit:
    """The memory a solve in this process may use, in bytes, and what sets it (``source``,
    for messages: "this machine's … GiB", "this process's cgroup limit of … GiB", ...)."""

    bytes: int
    source: str


#: A budget set by the code that runs the solve (a sweep's worker: its own memory limit,
#: which its nanny enforces by killing it, no cgroup or rlimit the process could read).
_BUDGET: contextvars.ContextVar[MemoryLimit | None] = contextvars.ContextVar("memory_budget", default=None)


@contextmanager
def memory_budget(limit: MemoryLimit) -> Iterator[None]:
    """Within the block, :func:`memory_limit` is at most ``limit``."""
    token = _BUDGET.set(limit)
    try:
        yield
    finally:
        _BUDGET.reset(token)


def memory_limit(proc: Path = Path("/proc/self"), cgroups: Path = Path("/sys/fs/cgroup")) -> MemoryLimit:
    """The tightest of this machine's physical memory, this process's cgroup memory limit
    (v2 ``memory.max`` or v1 ``memory.limit_in_bytes``, of its cgroup and every parent: a
    batch job's or a container's) and its address-space limit (``RLIMIT_AS``) less
    :func:`address_space_overhead`, and the budget of :func:`memory_budget` if one is set.
    What a solve is refused against before it starts."""
    physical = machine_memory()
    limits = [MemoryLimit(physical, f"this machine's {physical / 2**30:.3g} GiB")]
    cgroup = _cgroup_limit(proc, cgroups)
    if cgroup is not None and cgroup < physical:
        limits.append(MemoryLimit(cgroup, f"this process's cgroup memory limit of {cgroup / 2**30:.3g} GiB"))
    soft = _address_space_limit()
    if soft is not None:
        overhead = address_space_overhead()
        usable = max(int(soft - overhead), 0)
        limits.append(MemoryLimit(usable, f"the {usable / 2**30:.3g} GiB this process's address-space limit of "
                                          f"{soft / 2**30:.3g} GiB (ulimit -v) leaves beside "
                                          f"{overhead / 1e9:.2g} GB of libraries and threads"))
    budget = _BUDGET.get()
    if budget is not None:
        limits.append(budget)
    return min(limits, key=lambda limit: limit.bytes)


def _address_space_limit() -> int | None:
    """This process's soft address-space limit in bytes (None: unlimited)."""
    soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY else int(soft)


def address_space_overhead() -> float:
    """Bytes of address space a solve maps beyond its resident peak (:data:`ADDRESS_SPACE_BASE`
    and a buffer per BLAS thread: as many as OpenBLAS starts, the CPUs this process may run
    on unless OPENBLAS_NUM_THREADS or OMP_NUM_THREADS says fewer)."""
    try:
        threads = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        threads = os.cpu_count() or 1
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
        value = os.environ.get(name, "").strip()
        if value.isdigit() and int(value) > 0:
            threads = min(threads, int(value))
            break
    return ADDRESS_SPACE_BASE + ADDRESS_SPACE_PER_BLAS_THREAD * (max(threads, 1) - 1)


#: This process's own cgroup limit, read once (:func:`_cgroup_limit` of the default paths):
#: a solve reads it for every level it meshes, and the files behind it do not change while
#: a process runs; other paths (a test's tree) are read every time.
_OWN_CGROUP: dict[tuple[Path, Path], int | None] = {}
_OWN_PATHS = (Path("/proc/self"), Path("/sys/fs/cgroup"))


def _cgroup_limit(proc: Path, cgroups: Path) -> int | None:
    """The least memory limit of this process's cgroup and its parents, in bytes (None: none
    set, or no cgroup file system to read); this process's own (the default paths) is read
    once and kept."""
    key = (Path(proc), Path(cgroups))
    if key != _OWN_PATHS:
        return _read_cgroup_limit(proc, cgroups)
    if key not in _OWN_CGROUP:
        _OWN_CGROUP[key] = _read_cgroup_limit(proc, cgroups)
    return _OWN_CGROUP[key]


def _read_cgroup_limit(proc: Path, cgroups: Path) -> int | None:
    """:func:`_cgroup_limit`, read from the files."""
    try:
        lines = (proc / "cgroup").read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    found: list[int] = []
    for line in lines:
        fields = line.split(":", 2)
        if len(fields) != 3:
            continue
        _hierarchy, controllers, path = fields
        if controllers == "":  # v2: one unified hierarchy
            root, name = cgroups, "memory.max"
        elif "memory" in controllers.split(","):  # v1: the memory controller's own
            root, name = cgroups / "memory", "memory.limit_in_bytes"
        else:
            continue
        # The process's own cgroup and each parent up to the mount (inside a container the
        # mount is the container's cgroup, and the path seen from outside may not exist).
        directory = root / path.lstrip("/")
        while True:
            value = _limit_in(directory / name)
            if value is not None:
                found.append(value)
            if directory == root or root not in directory.parents:
                break
            directory = directory.parent
    return min(found) if found else None


def _limit_in(file: Path) -> int | None:
    """A cgroup limit file's bytes, or None for 'max', an unlimited value or no readable file."""
    try:
        text = file.read_text(encoding="ascii", errors="replace").strip()
    except OSError:
        return None
    if not text.isdigit():
        return None  # "max", or nothing usable
    value = int(text)
    return value if 0 < value < _UNLIMITED else None
