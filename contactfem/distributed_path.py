"""A load path on PETSc/MPI: the case's load factors solved in turn across the ranks.

One distributed system is assembled and one distributed solver carries over the steps
(:class:`contactfem.kernel.PathSolver` given it as its linear solver): the stiffness and
the constraints do not change along a path, so MUMPS keeps its ordering and symbolic
analysis and GAMG its coarse spaces, and a step's new load factor scales the load and
the prescribed values only. Each step starts, as in the serial path, from the set a
coarser level's own path predicts at its factor (solved across the ranks too, where a
coarser level pays) or from the sets of the steps before extrapolated in the factor,
whichever predicted better; every rank takes the same decisions from the contact arrays
it holds whole.

Rank 0 receives a :class:`contactfem.solve.PathResult`, its steps the solutions the
serial :func:`contactfem.solve.solve_load_path` would give.
"""

from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

from contactfem.case import Case
from contactfem.discretize import build_mesh
from contactfem.distributed import (
    SOLVERS,
    Progress,
    _DistributedSolver,
    _Layout,
    _petsc,
    _problem_without_stiffness,
    gather_iterate,
    kernel_system,
    parallel_figures,
    step_solution,
)
from contactfem.distributed_assembly import _DistributedSystem
from contactfem.errors import CaseError, SolverError
from contactfem.kernel import Iteration, PathSolver, Status
from contactfem.methods import get_method
from contactfem.sequencing import PredictedStarts, predict_active_set
from contactfem.timings import clock

if TYPE_CHECKING:
    from contactfem.solve import PathResult, SolveResult


@dataclass(frozen=True, eq=False)
class DistributedPathResult:
    """What :func:`solve_distributed_path` returns on every rank: ``result`` the
    :class:`~contactfem.solve.PathResult` on rank 0 (None elsewhere), ``parallel`` the run's
    figures (as :class:`contactfem.distributed.DistributedResult`'s)."""

    result: "PathResult | None"
    parallel: dict
    rank: int = 0


def solve_distributed_path(case: Case, method: str | None = None, refine: int | None = None, solver: str = "mumps",
                           progress: Progress | None = None, accept_uncertified: bool = False,
                           on_step: Callable[[int, float, "SolveResult"], None] | None = None,
                           keep_steps: bool = True) -> DistributedPathResult:
    """Solve ``case`` at each factor of its load path across the ranks (call it on every rank).

    ``method``, ``refine``, ``accept_uncertified``, ``on_step`` and ``keep_steps`` as for
    :func:`contactfem.solve.solve_load_path` (``on_step`` is called on rank 0 only);
    ``solver`` and ``progress`` as for :func:`contactfem.distributed.solve_distributed`.

    Raises
    ------
    CaseError
        For a case without a load path.
    SolverError
        As :func:`~contactfem.solve.solve_load_path` does, on every rank alike.
    """
    from contactfem.solve import PathResult, SolveResult, case_accelerators

    if case.load_path is None:
        raise CaseError(f"{case.source.name}: load_path: the case has none; solve it with solve_distributed")
    if solver not in SOLVERS:
        raise SolverError(f"unknown petsc solver {solver!r}; pick one of {', '.join(SOLVERS)}")
    PETSc, MPI = _petsc()
    comm = PETSc.COMM_WORLD
    mpi = comm.tompi4py()
    rank = mpi.Get_rank()
    say = (progress or (lambda message: None)) if rank == 0 else (lambda message: None)
    method_name = method or case.solver.method
    contact_method = get_method(method_name)
    factors = case.load_path.factors
    timings: dict[str, float] = {}

    since = clock()
    say(f"meshing (each of {mpi.Get_size()} ranks)")
    mesh = build_mesh(case, refine=refine)
    timings["mesh"] = clock() - since
    since = clock()
    problem = _problem_without_stiffness(case, mesh, case.mesh.refine if refine is None else refine)
    if keep_steps:
        _refuse_oversized_path(mpi, case, problem)
    linear, c = _assembled(PETSc, MPI, comm, case, problem, method_name, solver)
    system = linear.system
    timings["assemble"] = clock() - since
    say(f"  {problem.n_unknowns} unknowns, {len(problem.contact.nodes)} contact nodes ({timings['assemble']:.2f} s)")
    numbers = itertools.count(1)

    def on_iteration(record: Iteration) -> None:
        say(f"    Newton {next(numbers)}: {record.summary()}")

    # No Schur updates across the ranks: every Newton step factorises its own set.
    accelerators = dataclasses.replace(case_accelerators(case), schur_updates=False)
    coarse = (_coarse_path(PETSc, MPI, comm, case, problem, c, solver, accelerators)
              if accelerators.sequencing else None)
    starts = None if coarse is None else PredictedStarts(coarse.predict)
    if coarse is not None:
        say(f"  each step starts from the same path on {coarse.problem.n_unknowns} unknowns (solved across "
            "the ranks) or from the last steps extrapolated, whichever predicted the step before better")
    path = PathSolver(kernel_system(linear), linear=linear, c=c, tolerance=case.solver.tolerance,
                      max_iterations=case.solver.max_iterations, accelerators=accelerators,
                      on_iteration=on_iteration, starts=starts)
    say(f"solving {len(factors)} load steps with method {contact_method.equation} ({method_name}), petsc {solver}")
    steps: list[SolveResult] = []
    factorizations = 0
    postprocess = handed_over = 0.0
    accepted = (Status.CONVERGED, Status.NOT_CERTIFIED) if accept_uncertified else (Status.CONVERGED,)
    since = started = clock()
    try:
        for index, factor in enumerate(factors):
            kernel = path.step(factor)
            seconds = clock() - started
            factorizations += kernel.factorizations
            say(f"  step {index + 1}/{len(factors)}, factor {factor:.4g}: {int(kernel.active.sum())} active, "
                f"{kernel.iterations} Newton, {kernel.factorizations} factorisations, {seconds:.2f} s")
            final = index + 1 == len(factors)
            if kernel.status not in (Status.CONVERGED,) and not (final and kernel.status in accepted):
                raise SolverError(f"{case.source.name}: method {method_name}: load step {index + 1} of "
                                  f"{len(factors)} (factor {factor:g}): {kernel.message}")
            linear.keep(kernel.displacement)
            gathered = gather_iterate(linear)
            failure = None
            if rank == 0:
                post = clock()
                scaled, solution = step_solution(gathered, system, problem.scaled(factor), method_name, kernel)
                step = SolveResult(method=method_name, problem=scaled, solution=solution, kernel=kernel,
                                   backend=f"petsc-{solver}",
                                   timings={"solve": seconds, "postprocess": clock() - post})
                postprocess += step.timings["postprocess"]
                handed = clock()
                try:
                    if on_step is not None:
                        on_step(index, factor, step)
                except Exception as error:  # (writing a step) shared below, so that no rank waits for the next
                    failure = error
                handed_over += clock() - handed
                steps = [*steps, step] if keep_steps else [step]
            failure = mpi.bcast(failure, root=0)
            if failure is not None:
                raise failure
            started = clock()
        seconds = clock() - since - handed_over
        timings.update({"solve": seconds - postprocess, "postprocess": postprocess,
                        **({"write_steps": handed_over} if on_step is not None else {})})
        parallel = parallel_figures(linear, solver, timings, factorizations)
    finally:
        linear.destroy()
        if coarse is not None:
            coarse.destroy()
    sequencing = {} if coarse is None else {**coarse.record(), "started_from": dict(starts.started)}
    result = (PathResult(factors=tuple(factors), steps=tuple(steps), seconds=seconds, factorizations=factorizations,
                         timings=dict(timings), sequencing=sequencing) if rank == 0 else None)
    return DistributedPathResult(result=result, parallel=parallel, rank=rank)


def _refuse_oversized_path(mpi, case: Case, problem) -> None:
    """:func:`contactfem.solve._refuse_oversized_path` for rank 0, which keeps the steps:
    decided there (the memory of its machine) and raised on every rank alike."""
    from contactfem.solve import _refuse_oversized_path as refuse

    refusal = None
    if mpi.Get_rank() == 0:
        try:
            refuse(case, problem)
        except CaseError as error:
            refusal = error
    refusal = mpi.bcast(refusal, root=0)
    if refusal is not None:
        raise refusal


def _assembled(PETSc, MPI, comm, case: Case, problem, method_name: str, solver: str) -> tuple[_DistributedSolver, float]:
    """``problem`` assembled across the ranks, its distributed solver and the indicator's c."""
    mpi = comm.tompi4py()
    layout = _Layout.build(problem.mesh.points, mpi.Get_size(), mpi.Get_rank())
    system = _DistributedSystem.assemble(PETSc, comm, problem, get_method(method_name), layout)
    linear = _DistributedSolver(PETSc, MPI, comm, system, solver, tolerance=case.solver.tolerance)
    return linear, case.solver.c if case.solver.c is not None else system.default_c()


class _CoarsePath:
    """:class:`contactfem.solve.CoarsePath` solved across the ranks: the case on a coarser
    mesh, its own path solver, asked at whichever factors the finer path asks for; every
    rank takes the same decisions from the contact arrays it holds whole."""

    def __init__(self, fine, problem, linear: _DistributedSolver, path: PathSolver, c: float,
                 below: "_CoarsePath | None", seconds: float) -> None:
        self.fine, self.problem, self.linear, self.path, self.c, self.below = fine, problem, linear, path, c, below
        self.failed = False
        self.iterations = self.factorizations = self.steps = 0
        #: This level's preparation and steps, the levels below included (reported only).
        self.seconds = seconds

    def predict(self, factor: float):
        """The finer level's active set predicted from this level solved at ``factor``; None
        once a step of this level has failed (the finer path then extrapolates)."""
        from contactfem.result import ContactFields

        if self.failed:
            return None
        started = clock()
        try:
            kernel = self.path.step(factor)
        except SolverError:
            kernel = None
        self.failed = kernel is None or kernel.status is not Status.CONVERGED
        active = None
        if not self.failed:
            self.steps += 1
            self.iterations += kernel.iterations
            self.factorizations += kernel.factorizations
            contact = self.problem.contact
            fields = ContactFields(
                nodes=contact.nodes, edges=contact.edges, multiplier=kernel.multiplier,
                nodal_force=kernel.nodal_force, normal_displacement=self.linear.normals(kernel.displacement),
                gap=contact.gap, active=kernel.active, abscissa=contact.abscissa,
                obstacle_point=contact.obstacle.point, obstacle_normal=contact.obstacle.normal,
                obstacle_ends=contact.obstacle.ends)
            active = predict_active_set(self.fine.contact, fields, self.c, self.fine.law)
        self.seconds += clock() - started
        return active

    def record(self) -> dict:
        """What the coarser levels cost along the path, as :meth:`contactfem.solve.CoarsePath.record`."""
        return {"coarse_unknowns": self.problem.n_unknowns,
                "levels": 1 + (self.below.record()["levels"] if self.below is not None else 0),
                "coarse_steps": self.steps, "coarse_iterations": self.iterations,
                "coarse_factorizations": self.factorizations, "seconds": self.seconds}

    def destroy(self) -> None:
        self.linear.destroy()
        if self.below is not None:
            self.below.destroy()


def _coarse_path(PETSc, MPI, comm, case: Case, problem, c: float, solver: str, accelerators) -> _CoarsePath | None:
    """The coarser levels of a distributed load path on ``problem`` (its indicator weighted
    by ``c``), as :func:`contactfem.solve._coarse_path` chooses them, or None."""
    from contactfem.coarse_levels import coarser_level
    from contactfem.solve import SEQUENCING_METHOD

    started = clock()
    coarse_problem = coarser_level(problem, lambda request, refine: _problem_without_stiffness(
        case, build_mesh(case, refine=refine, request=request), refine, request))
    if coarse_problem is None:
        return None
    linear, coarse_c = _assembled(PETSc, MPI, comm, case, coarse_problem, SEQUENCING_METHOD, solver)
    below = _coarse_path(PETSc, MPI, comm, case, coarse_problem, coarse_c, solver, accelerators)
    path = PathSolver(kernel_system(linear), linear=linear, c=coarse_c, tolerance=case.solver.tolerance,
                      max_iterations=case.solver.max_iterations, accelerators=accelerators,
                      starts=None if below is None else PredictedStarts(below.predict))
    return _CoarsePath(problem, coarse_problem, linear, path, c, below, clock() - started)
