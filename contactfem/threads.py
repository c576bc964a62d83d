"""The process's BLAS threads: one per OpenBLAS library, how the command line runs a solve.

numpy and SciPy each load an OpenBLAS of their own, and each starts a pool of as many
threads as there are cores; CHOLMOD's (inside the cvxopt wheel) is built single-threaded.
A solve's dense work is small (the kernel's Schur columns, the coarse level's
corrections) and runs beside the fine level's symbolic analysis in a worker thread, so
idle pools' busy-waiting threads only take cores from that work: one thread per library
is faster, and the linear solves lose nothing. Limiting the pools once they have started
(threadpoolctl's limits) does not recover it, so the variable has to be set before numpy
loads. Measured by ``benchmarks/rough.py``; see docs/performance.md#process-settings.

The policy belongs to the application: :func:`one_blas_thread` is called by the
``contactfem`` command before it imports anything numerical (:mod:`contactfem.__main__`),
and by the benchmarks that time what the command does, never on import. A user who sets
the number of threads in the environment keeps it. This module imports nothing numerical.
"""

from __future__ import annotations

import os
import sys
from collections.abc import MutableMapping

#: The variables OpenBLAS reads for its number of threads, in its order of precedence.
OPENBLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def one_blas_thread(environ: MutableMapping[str, str] | None = None) -> bool:
    """Set OPENBLAS_NUM_THREADS=1 in ``environ`` (default: this process's, which then takes
    effect only if numpy is not loaded yet, and is inherited by the processes it starts),
    unless a variable of :data:`OPENBLAS_THREAD_VARIABLES` is set already. Whether it was set."""
    environ = os.environ if environ is None else environ
    if any(environ.get(name, "").strip() for name in OPENBLAS_THREAD_VARIABLES):
        return False
    if environ is os.environ and "numpy" in sys.modules:
        return False  # too late: its OpenBLAS has started its threads
    environ["OPENBLAS_NUM_THREADS"] = "1"
    return True
