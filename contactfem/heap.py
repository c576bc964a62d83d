"""The process's C heap, kept for reuse: how the command line runs a solve.

glibc serves each allocation above a threshold (128 kB at first, rising with what is freed
to at most 32 MB) with a mapping of its own and unmaps it when it is freed, and gives back
what stays free at the top of its heap. numpy asks for huge pages for its large arrays, but
a C library's blocks are faulted in page by page: CHOLMOD's factor and workspace (about 200
MB at 650 000 unknowns) are mapped anew at every factorisation of every level and faulted
in again, 52 000 faults for one factorisation and solve there. On the 100 000-point rough
profile (650 000 unknowns, five levels) a process took 600 000-670 000 page faults and
11-17 s of system time, its contact solves 4.2-4.5 s at best and 7.0-7.1 by the median;
with the heap kept, 160 000-200 000 faults, 3-6 s, 3.4-3.7 s and 3.6-3.9 s, and a lower
peak (1.01-1.04 GB above the interpreter against 1.13-1.14: one heap for every thread).
At 32 000 points (209 000 unknowns, fresh processes taking turns) the first solve of a
process took 1.6-2.1 s against 1.9-2.4 and the later ones 0.95-1.2 against 1.0-1.9; from
1 000 to 16 000 points and at 64 000 the same either way within this machine's noise
(``benchmarks/rough.py --plain-heap``).

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
