"""What a solve will cost, estimated before it runs from figures measured on a 2-core machine.

Measured on the square case at 2.1M unknowns (benchmarks/results/square_sweep.json and
FINDINGS): CHOLMOD (AMD, OpenBLAS) factorises in about 14 s, Pardiso in 11 s, SuperLU
(MMD_AT_PLUS_A) in about 50 s; a whole solve peaks near 5 GB with CHOLMOD, through
scikit-sparse or in cvxopt's wheel (the default install: 4.8 GB for the positive method,
5.0 GB for the standard one, benchmarks/square_sweep.py 1024). Sparse
factorisation of 2D meshes grows slightly faster than linearly (exponent ≈ 1.1 over
130k–2.1M unknowns). With mesh sequencing a contact solve costs about 1.3 factorisations;
assembly and writing add about 25%. Expect ±50% on other machines.
"""

from __future__ import annotations

import os

REFERENCE_UNKNOWNS = 2.1e6
# petsc: MUMPS on one rank (benchmarks/results/petsc_scaling.json: 26.6 s, 4.35 GB at 2.1M).
# The size guard uses the one-rank figure whatever the ranks: it cannot know how many of
# them share this machine's memory, and on one machine they need about as much in all.
FACTOR_SECONDS = {"cholmod": 14.0, "pardiso": 11.0, "superlu": 50.0, "petsc": 26.6}
PEAK_BYTES = {"cholmod": 5.0e9, "pardiso": 6.0e9, "superlu": 8.0e9, "petsc": 4.4e9}
GROWTH = 1.1


def estimate_cost(unknowns: int, backend: str) -> dict[str, float]:
    """Seconds and bytes a solve of ``unknowns`` is expected to take with ``backend``."""
    scale = max(unknowns, 1) / REFERENCE_UNKNOWNS
    seconds = 1.3 * FACTOR_SECONDS[backend] * scale**GROWTH * 1.25
    peak = PEAK_BYTES[backend] * scale + 0.15e9  # the interpreter and libraries
    return {"seconds": seconds, "bytes": peak}


def largest_mesh_points(backend: str, memory: int) -> int:
    """The most mesh nodes whose solve the model fits in ``memory`` bytes with ``backend``."""
    scale = max(memory - 0.15e9, 0.0) / PEAK_BYTES[backend]
    return int(scale * REFERENCE_UNKNOWNS / 2)


def unknowns_of_triangles(triangles: int) -> int:
    """Displacement unknowns of a P1 mesh of ``triangles`` triangles: a planar triangulation has
    about half as many nodes as triangles, with two unknowns each."""
    return int(triangles)


def machine_memory() -> int:
    """This machine's physical memory in bytes (16 GiB when the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 16 * 2**30
