"""The bounds on what a case may hold and what reading it may cost.

The modules of the case package read them from here when they run (``limits.NAME``),
so that lowering one (as the tests do) bounds every reader at once.
"""

from __future__ import annotations

import os

#: The most steps a load path may have (each is a solve and a time step of the outputs).
MAX_LOAD_STEPS = 1000
#: Bound on the magnitude of coordinates, moduli and solver.c (and below it, of the
#: smallest body extent and modulus): products of six such numbers, as in the stiffness
#: times a displacement times a length, stay far inside float64's 1e±308.
SCALE_LIMIT = 1e50
#: The finest uniform mesh: the same bound as mesh.divisions (100 000 per side).
MAX_DIVISIONS = 100_000
#: Largest lambda/mu (plane strain): beyond it, nu = lambda/(2(lambda + mu)) > 0.499999995,
#: the P1 stiffness is singular to round-off (its condition number grows like lambda/mu) and
#: the solution is pure locking. A warning starts far earlier (report.LOCKING_WARNING_RATIO).
MAX_LAME_RATIO = 1e8
#: The largest case file, in bytes. Cases are a few kB (a polygon of 2000 vertices is
#: under 100 kB; longer outlines come from an outline or profile file); the bound keeps a
#: mistaken argument (a log, /dev/zero) from being read whole.
MAX_CASE_BYTES = 1 << 20
#: The most YAML values (scalars, lists and mappings) a case may hold, each alias counted
#: at every use. A full-size polygon needs under 10 000.
MAX_YAML_VALUES = 100_000
#: The deepest nesting of YAML values; the deepest key of the format
#: (geometry.polygon.holes[i].edges[j].arc.center[k]) is 10 levels down.
MAX_YAML_DEPTH = 32
#: The most vertices of a polygon geometry, its holes included, or of a profile's outline.
#: The simplicity check is a sweep, O(k log k) in time and O(k) in memory (seconds and a
#: fraction of the memory of a solve at this bound); inline YAML lists stay far below it
#: (MAX_YAML_VALUES), a profile or an outline read from a file may reach it.
MAX_POLYGON_VERTICES = 1_000_000
#: The most bytes of data files (a profile, an outline and its holes) a case may read, all
#: of them together: room for MAX_POLYGON_VERTICES lines of two numbers written to full
#: precision; at most this many bytes plus one are read.
MAX_DATA_FILE_BYTES = 64 << 20


def _os_limit(name: str, fallback: int) -> int:
    try:
        value = os.pathconf("/", name)
    except (AttributeError, OSError, ValueError):
        return fallback
    return value if isinstance(value, int) and value > 0 else fallback


#: Longest file name (one path component), in bytes of the file-system encoding.
NAME_MAX = _os_limit("PC_NAME_MAX", 255)
#: Longest path, in bytes, including the terminating NUL of the system call.
PATH_MAX = _os_limit("PC_PATH_MAX", 4096)
#: Room kept in an output directory's path for what is written under it: the staging
#: sibling ``.tmp-<pid>-<8 hex>.<name>`` adds up to 22 bytes to the last component, and the
#: files inside it (``.tmp-<pid>-<8 hex>.solution-xdmf.h5`` and the like) about 64 bytes.
OUTPUT_NAME_RESERVE = 32
OUTPUT_PATH_RESERVE = 128
