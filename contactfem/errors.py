"""The one error family of contactfem; only the command line turns these into messages and exit codes."""


class ContactFemError(Exception):
    """Base class of every error contactfem raises on purpose."""


class CaseError(ContactFemError):
    """The case file is unreadable, malformed or describes an ill-posed problem.

    The message names the file, the key, the offending value and what was expected.
    """


class MeshError(ContactFemError):
    """The mesh cannot be built, read or is unusable (degenerate, wrong boundary names)."""


class MeshCapError(MeshError):
    """Meshing stopped at the most nodes it may make (``max_points``, from the memory budget)
    before the triangles met the size asked for: the mesh left is coarser than the one asked
    for, and is refused rather than solved in its place.

    ``largest`` is the largest triangle's edge over the edge the size asks for there (the side
    of the equilateral triangle of the same area; 1 or less where the size was met)."""

    def __init__(self, message: str, max_points: int, nodes: int, largest: float):
        super().__init__(message)
        self.max_points = max_points
        self.nodes = nodes
        self.largest = largest


class SolverError(ContactFemError):
    """The discrete problem cannot be solved (singular system, no convergence)."""


class FactorCapacityError(ContactFemError, MemoryError):
    """A sparse factorisation ran out of room: memory, or a library's own size limit.

    A MemoryError too, so that what handles running out of memory (no retry, nothing
    written) handles it; its message says which limit and what to do."""


class ArchiveError(ContactFemError):
    """A file contactfem wrote and reads back (solution.h5, compare.json, a sweep's stored
    point) is missing a part, damaged, or not what contactfem writes: bad input.

    The message names the file, the dataset or key, and what was expected.
    """


class OutputError(ContactFemError):
    """An output file cannot be written."""


class ExistingResultError(OutputError):
    """The output directory holds a finished result and replacing it was not asked for."""


class Interrupted(BaseException):
    """SIGTERM arrived: unwind like KeyboardInterrupt (cleanups run, nothing is switched in)."""
