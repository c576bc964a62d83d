"""The process's C heap, kept for reuse: how the command line runs a solve.

glibc serves each allocation above a threshold (rising with what is freed, up to a
ceiling) with a mapping of its own and unmaps it when it is freed, and gives back what
stays free at the top of its heap. numpy asks for huge pages for its large arrays, but a C
library's blocks are faulted in page by page: CHOLMOD's factor and workspace are mapped
anew at every factorisation of every level and faulted in again. Keeping freed memory in
the heap turns those page faults and their system time into reuse, which shortens the
solves of a mesh-sequenced problem and lowers its peak (one heap for every thread);
below some hundred thousand unknowns it makes no measurable difference. Measured by
``benchmarks/rough.py --plain-heap``; see docs/performance.md#process-settings.

The policy belongs to the application, not the library: :func:`keep_freed_memory` is called
by the ``contactfem`` command before it does any work (and by ``benchmarks/rough.py``,
``performance.py`` and ``fragmented.py``, which time what the command does), never on
import. A user who tunes glibc's allocator through the
environment keeps their settings, and a sweep's Dask workers, other processes, keep Dask's
(memory handed back, which its per-worker memory limits need).
"""

from __future__ import annotations

import ctypes
import os
import platform

# mallopt parameters (glibc's malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_MAX = -4
_M_ARENA_MAX = -8

#: Free memory at the top of the heap beyond this goes back to the system (mallopt takes an int).
TRIM_THRESHOLD = 2**31 - 1


def _user_tuned() -> bool:
    """Whether the environment already sets glibc's allocator (its MALLOC_* variables or
    its malloc tunables)."""
    if any(name.startswith("MALLOC_") for name in os.environ):
        return True
    return "glibc.malloc." in os.environ.get("GLIBC_TUNABLES", "")


def keep_freed_memory() -> bool:
    """Serve large allocations from the heap and keep what is freed there for reuse:
    no separate mappings (M_MMAP_MAX = 0), no trimming below :data:`TRIM_THRESHOLD` of free
    memory, and one heap for every thread (the solver's worker threads allocate the fine
    level's system). Whether it was done: not on another C library, nor when the
    environment already tunes glibc's allocator."""
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc" or _user_tuned():
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    # mallopt returns 1 on success; the arena bound first, before any thread allocates.
    return all([mallopt(_M_ARENA_MAX, 1) == 1, mallopt(_M_MMAP_MAX, 0) == 1,
                mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1])
