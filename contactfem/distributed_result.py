"""What a solve across MPI ranks returns, and how its solution reaches the writers: gathered whole to
rank 0 (:func:`gather_iterate`, :func:`step_solution`), or kept in pieces
(:mod:`contactfem.distributed_output`); the run's figures per rank (:func:`parallel_figures`)."""

from __future__ import annotations

import resource
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from contactfem.case import Case
from contactfem.discretize import DiscreteProblem
from contactfem.errors import SolverError
from contactfem.kernel import KernelResult

if TYPE_CHECKING:
    from contactfem.distributed import _DistributedSolver
    from contactfem.distributed_assembly import _DistributedSystem
    from contactfem.distributed_output import PieceFields
    from contactfem.report import BodyFigures
    from contactfem.solve import SolveResult


@dataclass(frozen=True, eq=False)
class DistributedResult:
    """What :func:`solve_distributed` returns on every rank.

    ``result`` is the :class:`~contactfem.solve.SolveResult` on rank 0 (None elsewhere);
    ``parallel`` the figures of the run, the same on every rank: ranks, solver, per rank
    its owned unknowns and triangles, peak resident memory (bytes) and seconds per stage.
    """

    result: "SolveResult | None"
    parallel: dict
    rank: int = 0
    #: A solve left in pieces (``gather=False`` on a distributed mesh): this rank's fields, and on
    #: rank 0 the whole mesh's reduced figures and report.json's ``accuracy.energy`` (see
    #: :mod:`contactfem.distributed_output`); ``result`` then holds the boundary mesh only.
    pieces: "PieceFields | None" = None
    body: "BodyFigures | None" = None
    estimate: dict | None = None


class SolutionProduct:
    """Stands for the global stiffness on rank 0, which no rank holds: it knows K u for the
    solution u only (computed distributedly), which is all that
    :func:`contactfem.report.contact_and_reactions` asks of ``problem.stiffness``.

    Any other product raises :class:`SolverError`: estimators or energy norms that need the
    matrix itself cannot run on a distributed result.
    """

    def __init__(self, displacement: np.ndarray, internal_force: np.ndarray) -> None:
        self._displacement = np.asarray(displacement, dtype=float).ravel()
        self._internal = np.asarray(internal_force, dtype=float).ravel()
        self.shape = (len(self._internal), len(self._internal))

    def __matmul__(self, vector: np.ndarray) -> np.ndarray:
        vector = np.asarray(vector, dtype=float)
        if vector.shape == self._displacement.shape and np.array_equal(vector, self._displacement):
            return self._internal.copy()
        raise SolverError("the stiffness of a distributed solve is held by no rank: only K u of its "
                          "solution is known on rank 0")


def gather_iterate(linear: "_DistributedSolver") -> tuple[np.ndarray, np.ndarray] | None:
    """The kept iterate and its K u (see :meth:`_DistributedSolver.keep`), whole on rank 0 in
    PETSc order (None elsewhere); every rank calls it."""
    slots = linear.gather_to_zero(linear.solution)
    internal = linear.gather_to_zero(linear.internal_force)
    return None if slots is None else (slots, internal)


def parallel_figures(linear: "_DistributedSolver", solver: str, timings: dict, factorizations: int) -> dict:
    """The run's figures, the same on every rank (a collective step): per rank its owned
    unknowns and triangles, factorisations, linear iterations, peak memory and seconds."""
    mpi, system = linear.mpi, linear.system
    per_rank = mpi.gather({"rank": mpi.Get_rank(), "owned_unknowns": (linear.last - linear.first),
                           "owned_triangles": system.owned_triangles,
                           "factor_seconds": linear.factor_seconds, "linear_iterations": linear.linear_iterations,
                           "factor": linear.factor_figures,
                           "peak_rss_bytes": _peak_rss(),
                           "seconds": dict(timings)}, root=0)
    per_rank = mpi.bcast(per_rank, root=0)
    mesh = "replicated" if hasattr(system.layout, "order") else "pieces"
    return {"ranks": mpi.Get_size(), "solver": solver, "mesh": mesh, "per_rank": per_rank,
            "max_peak_rss_bytes": max(entry["peak_rss_bytes"] for entry in per_rank),
            "factorizations": factorizations}


def step_solution(gathered: tuple[np.ndarray, np.ndarray], system: "_DistributedSystem", problem: DiscreteProblem,
                  method_name: str, kernel: KernelResult):
    """On rank 0: ``problem`` with its :class:`SolutionProduct` and the solution's fields,
    from the gathered iterate; ``kernel.displacement`` becomes the whole rotated unknowns."""
    from contactfem.solve import _solution

    slots, internal = gathered
    layout = system.layout
    kernel.displacement = layout.to_mesh(slots)
    pushed = getattr(system, "pushed", None)
    if pushed is not None:  # the pushed obstacle at the advance found
        problem = problem.advanced(pushed.advance(kernel.displacement, problem.dirichlet_values))
    displacement = system.mesh_vector(kernel.displacement)
    force = system.mesh_force(layout.to_mesh(internal))
    # A moving obstacle's field is moved back by its advance (a rigid translation: K u stays).
    moved = displacement if problem.drive is None else problem.drive.moved(displacement.reshape(-1, 2)).ravel()
    problem = _with_stiffness(problem, SolutionProduct(moved, force))
    return problem, _solution(method_name, problem, displacement.reshape(-1, 2), kernel)


def distributed_report(case: Case, outcome: DistributedResult, extras: dict | None = None) -> dict:
    """report.json's content for a distributed result (rank 0), with the run's figures under ``parallel``."""
    from contactfem.report import build_report

    if outcome.result is None:
        raise ValueError("the report of a distributed solve is built on rank 0")
    return build_report(case, outcome.result, extras={"parallel": outcome.parallel, **(extras or {})})


def _peak_rss() -> int:
    """This process's peak resident memory in bytes (Linux reports kilobytes)."""
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def _with_stiffness(problem: DiscreteProblem, stiffness) -> DiscreteProblem:
    from dataclasses import replace

    return replace(problem, stiffness=stiffness)
