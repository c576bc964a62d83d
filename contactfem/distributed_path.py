"""A load path on PETSc/MPI: the case's load factors solved in turn across the ranks.

One distributed system is assembled and one distributed solver carries over the steps
(:class:`contactfem.kernel.PathSolver` given it as its linear solver): the stiffness and
the constraints do not change along a path, so MUMPS keeps its ordering and symbolic
analysis and GAMG its coarse spaces, and a step's new load factor scales the load and
the prescribed values only. Each step starts from the active sets of the steps before,
extrapolated in the factor, as the serial path does without coarser levels; every rank
takes the same decisions from the contact arrays it holds whole.

Rank 0 receives a :class:`contactfem.solve.PathResult`, its steps the solutions the
serial :func:`contactfem.solve.solve_load_path` would give.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
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

    clock = time.perf_counter()
    say(f"meshing (each of {mpi.Get_size()} ranks)")
    mesh = build_mesh(case, refine=refine)
    timings["mesh"] = time.perf_counter() - clock
    clock = time.perf_counter()
    problem = _problem_without_stiffness(case, mesh, case.mesh.refine if refine is None else refine)
    layout = _Layout.build(problem.mesh.points, mpi.Get_size(), rank)
    system = _DistributedSystem.assemble(PETSc, comm, problem, contact_method, layout)
    timings["assemble"] = time.perf_counter() - clock
    say(f"  {problem.n_unknowns} unknowns, {len(problem.contact.nodes)} contact nodes ({timings['assemble']:.2f} s)")

    linear = _DistributedSolver(PETSc, MPI, comm, system, solver, tolerance=case.solver.tolerance)
    c = case.solver.c if case.solver.c is not None else system.default_c()
    numbers = itertools.count(1)

    def on_iteration(record: Iteration) -> None:
        say(f"    Newton {next(numbers)}: {record.summary()}")

    # No Schur updates across the ranks: every Newton step factorises its own set.
    accelerators = dataclasses.replace(case_accelerators(case), schur_updates=False)
    path = PathSolver(kernel_system(linear), linear=linear, c=c, tolerance=case.solver.tolerance,
                      max_iterations=case.solver.max_iterations, accelerators=accelerators,
                      on_iteration=on_iteration)
    say(f"solving {len(factors)} load steps with method {contact_method.equation} ({method_name}), petsc {solver}")
    steps: list[SolveResult] = []
    factorizations = 0
    postprocess = handed_over = 0.0
    accepted = (Status.CONVERGED, Status.NOT_CERTIFIED) if accept_uncertified else (Status.CONVERGED,)
    clock = started = time.perf_counter()
    try:
        for index, factor in enumerate(factors):
            kernel = path.step(factor)
            seconds = time.perf_counter() - started
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
                post = time.perf_counter()
                scaled, solution = step_solution(gathered, system, problem.scaled(factor), method_name, kernel)
                step = SolveResult(method=method_name, problem=scaled, solution=solution, kernel=kernel,
                                   backend=f"petsc-{solver}",
                                   timings={"solve": seconds, "postprocess": time.perf_counter() - post})
                postprocess += step.timings["postprocess"]
                handed = time.perf_counter()
                try:
                    if on_step is not None:
                        on_step(index, factor, step)
                except Exception as error:  # (writing a step) shared below, so that no rank waits for the next
                    failure = error
                handed_over += time.perf_counter() - handed
                steps = [*steps, step] if keep_steps else [step]
            failure = mpi.bcast(failure, root=0)
            if failure is not None:
                raise failure
            started = time.perf_counter()
        seconds = time.perf_counter() - clock - handed_over
        timings.update({"solve": seconds - postprocess, "postprocess": postprocess,
                        **({"write_steps": handed_over} if on_step is not None else {})})
        parallel = parallel_figures(linear, solver, timings, factorizations)
    finally:
        linear.destroy()
    result = (PathResult(factors=tuple(factors), steps=tuple(steps), seconds=seconds, factorizations=factorizations,
                         timings=dict(timings)) if rank == 0 else None)
    return DistributedPathResult(result=result, parallel=parallel, rank=rank)
