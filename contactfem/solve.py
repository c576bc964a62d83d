"""The pipeline: validated case → mesh → discrete problem → contact kernel → a frozen :class:`SolveResult`.

Nothing here prints, formats or touches files: progress goes through an optional
callback, the report is built from the result by :mod:`contactfem.report`, and the
command line hands both to the writers of :mod:`contactfem.io`.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from contactfem.assembly import shape_gradients, stresses, von_mises
from contactfem.case import Case
from contactfem.discretize import DiscreteProblem, build_mesh, build_problem
from contactfem.discretize.meshing import MeshRequest
from contactfem.discretize.frames import ReducedSystem
from contactfem.estimate import choose_backend, memory_limit
from contactfem.errors import CaseError, FactorCapacityError, SolverError
from contactfem.kernel import (
    Accelerators,
    ActiveSetSolver,
    Iteration,
    IterativeSetSolver,
    KernelResult,
    STALL_ITERATIONS,
    PathSolver,
    Status,
    default_c,
    solve_contact,
)
from contactfem.linalg import DISTRIBUTED_BACKENDS, ITERATIVE_BACKENDS, resolve_backend
from contactfem.methods import get_method
from contactfem.result import ContactFields, Solution
from contactfem.coarse_levels import CoarseSolve, coarser_level, correct_in_layer, meshing_pays, predict_from_coarser
from contactfem.sequencing import (
    coarser,
    PredictedStarts,
    predict_active_set,
    prediction_first,
    starting_set,
    worth_sequencing,
)
from contactfem.timings import clock

Progress = Callable[[str], None]

#: The method mesh sequencing solves its coarse levels with: its λ ≥ 0 is the pressure
#: the fine indicator needs, whichever method the fine level uses.
SEQUENCING_METHOD = "positive"
#: Unknowns from which a level's kernel system, solver and analysis are made in a worker
#: thread beside its coarser levels (see :func:`_contact_solve`). Below, the system and
#: solver (a few milliseconds of Python, which would only take turns with the coarse
#: levels' own) are made first and only the analysis, which runs outside the interpreter's
#: lock, beside them.
BESIDE_COARSER_FROM = 20_000


@dataclass(frozen=True, eq=False)
class SolveResult:
    """A solved discrete problem, complete when returned.

    Attributes
    ----------
    method : str
        The contact method's name.
    problem : DiscreteProblem
    solution : Solution
        Displacement, stresses and contact fields.
    kernel : KernelResult
        The kernel's account: status, iterations, history, factorisations.
    backend : str
        The linear solver of the Newton steps: a sparse direct backend, or ``amg``.
    backend_reason : str
        Why that one (:func:`contactfem.estimate.choose_backend`).
    linear : mapping
        The iterative solver's account (CG iterations and residuals of each step, the
        hierarchies built; :attr:`IterativeSetSolver.figures`); empty for a direct backend.
    timings : mapping of str to float
        Seconds per stage: ``mesh`` and ``assemble`` (when this solve built the
        problem), ``solve`` (sequencing and kernel) and ``postprocess``.
    sequencing : mapping
        What predicting the active set from coarser meshes cost (empty without it):
        coarse unknowns and iterations, predicted active nodes, levels, seconds.
    coarse_levels : mapping
        What sequencing meshed and solved on the way (``problem``, ``solve``: a
        :class:`CoarseSolve`, ``coarser``: the request), for whatever reads a coarser
        solution of the same case afterwards (:mod:`contactfem.accuracy`); empty without it.
    """

    method: str
    problem: DiscreteProblem
    solution: Solution
    kernel: KernelResult
    backend: str
    timings: Mapping[str, float] = field(default_factory=dict)
    sequencing: Mapping = field(default_factory=dict)
    coarse_levels: Mapping = field(default_factory=dict, repr=False)
    backend_reason: str = ""
    linear: Mapping = field(default_factory=dict)


def prepare(
    case: Case,
    *,
    refine: int | None = None,
    progress: Progress | None = None,
    timings: dict[str, float] | None = None,
    request: MeshRequest | None = None,
) -> DiscreteProblem:
    """Mesh and assemble ``case`` (on a coarser level's mesh ``request``, when given);
    ``timings`` receives the seconds of ``mesh`` and ``assemble``."""
    say = progress or (lambda message: None)
    timings = {} if timings is None else timings
    refinements = (case.mesh if request is None else request.mesh).refine if refine is None else refine
    started = clock()
    say("meshing")
    mesh = build_mesh(case, refine=refine, request=request)
    timings["mesh"] = clock() - started
    say(f"  {mesh.n_points} nodes, {mesh.n_triangles} triangles ({timings['mesh']:.2f} s)")
    started = clock()
    say("assembling")
    problem = build_problem(case, mesh, refinements=refinements, request=request)
    timings["assemble"] = clock() - started
    say(f"  {problem.n_unknowns} unknowns, {len(problem.contact.nodes)} contact nodes ({timings['assemble']:.2f} s)")
    return problem


def _names_the_case(solve: Callable) -> Callable:
    """Make a solver's refusal start with the case file, as every other refusal does: the
    linear algebra's (a singular or not positive definite stiffness, a factorisation out of
    room) know only the matrix they were given (a 1 x 1e-6 block was refused as "the
    stiffness matrix ... is singular", naming no file)."""

    @functools.wraps(solve)
    def named(case: Case, *args, **kwargs):
        try:
            return solve(case, *args, **kwargs)
        except (SolverError, FactorCapacityError) as error:
            prefix = f"{case.source.name}: "
            if str(error).startswith(prefix):
                raise
            raise type(error)(prefix + str(error)) from None

    return named


@_names_the_case
def solve_case(
    case: Case,
    *,
    method: str | None = None,
    refine: int | None = None,
    progress: Progress | None = None,
    problem: DiscreteProblem | None = None,
    accept_uncertified: bool = False,
    coarse_levels: dict | None = None,
    accelerators: Accelerators | None = None,
) -> SolveResult:
    """Mesh, assemble and solve ``case`` with ``method`` (default: the case's).

    A ``problem`` already assembled for this case (see :func:`prepare`) skips meshing and
    assembly, which is how ``compare`` solves both methods on one system. With
    ``accept_uncertified``, a solve whose active set settled but whose iterate fails the
    kernel's certificate is returned (``result.kernel.status`` says so) rather than raised,
    so that its figures can be reported. ``coarse_levels``, a dict shared by solves of one
    ``problem`` (``compare``'s two methods), keeps the coarse level
    of mesh sequencing that the first of them meshes and solves, and the next reuse it: it
    is the same whatever the fine method (it is solved with :data:`SEQUENCING_METHOD`).
    ``accelerators`` overrides the case's ``solver.accelerators`` switches.

    Raises
    ------
    SolverError
        If the kernel does not converge (cycling, iteration cap, a singular system) or,
        unless accepted, its result is not certified.
    """
    say = progress or (lambda message: None)
    method_name = method or case.solver.method
    contact_method = get_method(method_name)
    _serial_backend(case)
    timings: dict[str, float] = {}
    kept = {} if coarse_levels is None else coarse_levels
    if problem is None:
        problem = prepare(case, refine=refine, progress=say, timings=timings)
    choice = choose_backend(problem.n_unknowns, case.solver.backend, memory_limit())
    backend = choice.name
    started = clock()
    say(f"solving with method {contact_method.equation} ({method_name}), backend {backend}")
    if backend in ITERATIVE_BACKENDS:
        say(f"  {choice.reason}")
    linear: dict = {}
    reduced, kernel, sequencing = _contact_solve(case, problem, contact_method, backend, say, kept, accelerators,
                                                 linear)
    timings["solve"] = clock() - started
    accepted = (Status.CONVERGED, Status.NOT_CERTIFIED) if accept_uncertified else (Status.CONVERGED,)
    if kernel.status not in accepted:
        raise SolverError(f"{case.source.name}: method {method_name}: {kernel.message}")

    started = clock()
    problem = reduced.settled(problem, kernel.displacement)  # a pushed obstacle at the advance found
    solution = _solution(method_name, problem, reduced.displacement(kernel.displacement), kernel)
    timings["postprocess"] = clock() - started
    return SolveResult(method=method_name, problem=problem, solution=solution, kernel=kernel, backend=backend,
                       timings=timings, sequencing=sequencing, coarse_levels=kept, backend_reason=choice.reason,
                       linear=linear)


def _contact_solve(case: Case, problem: DiscreteProblem, contact_method, backend: str, say: Progress,
                   coarse_levels: dict | None = None, accelerators: Accelerators | None = None,
                   linear_figures: dict | None = None) -> tuple[ReducedSystem, KernelResult, dict]:
    """The kernel's view of ``problem``, its contact solve (the active set predicted from
    coarser meshes, kept in or taken from ``coarse_levels``: see :func:`solve_case`) and
    what the prediction cost: what a fine solve and a coarse level share. An iterative
    ``backend`` writes its account into ``linear_figures``."""
    tolerance = case.solver.tolerance
    accelerators = case_accelerators(case) if accelerators is None else accelerators
    kept = {} if coarse_levels is None else coarse_levels
    # Without a coarse level to mesh and solve first there is nothing to overlap with: a
    # small problem, one whose coarser level is not worth meshing (a tread's teeth), one
    # pressed in everywhere (the coarse level is then a second guess, after the first
    # step), or a coarse level kept from an earlier solve.
    sequenced = accelerators.sequencing
    coarse_first = (sequenced and worth_sequencing(problem.n_unknowns)
                    and prediction_first(problem.contact.gap, tolerance)
                    and "solve" not in kept and _worth_meshing(problem, kept))
    with ThreadPoolExecutor(max_workers=1) if coarse_first else _InPlace() as pool:
        # This level's kernel system, its solver and that solver's ordering and symbolic
        # analysis are made while the coarser levels mesh and solve (the analysis runs
        # outside the interpreter's lock). From BESIDE_COARSER_FROM unknowns all three go to
        # the worker; below, the system and solver are made here first. Threads change
        # when work is done, never what is computed.
        def fine() -> tuple[ReducedSystem, float]:
            reduced = problem.contact_system(contact_method)
            return reduced, case.solver.c if case.solver.c is not None else default_c(reduced.system)

        def solver() -> ActiveSetSolver | IterativeSetSolver:
            reduced = fine_soon.result()[0]
            if backend in ITERATIVE_BACKENDS:
                return IterativeSetSolver(reduced.system, reduced.rigid_motions(), tolerance=tolerance)
            return ActiveSetSolver(reduced.system, backend, tolerance=tolerance,
                                   schur_updates=accelerators.schur_updates)

        if problem.n_unknowns >= BESIDE_COARSER_FROM:
            fine_soon = pool.submit(fine)
            solver_soon = pool.submit(lambda: _analysed(solver()))
        else:
            fine_soon = _InPlace.submit(fine)
            solver_soon = pool.submit(_analysed, solver())

        if sequenced:
            initial_active, second_guess, sequencing = starting_set(
                problem.contact.gap, tolerance,
                lambda: _predict_from_coarser(case, problem, fine_soon.result, say, kept))
        else:
            initial_active, second_guess, sequencing = None, None, {}
        reduced, c = fine_soon.result()
        linear = solver_soon.result()
    numbers = itertools.count(1)

    def stalled_guess() -> np.ndarray | None:
        # A start without a prediction (a small problem) that has not settled: a body in
        # bending peeling off creeps a node per edge per step, which a coarser level does
        # at a quarter of the size (kernel.STALL_ITERATIONS).
        say(f"  not settled after {STALL_ITERATIONS} steps: predicting from a coarser mesh")
        active, cost = _predict_from_coarser(case, problem, lambda: (reduced, c), say, kept, forced=True)
        if active is not None:
            sequencing["stalled"] = {"at": STALL_ITERATIONS, **cost}
        return active

    def on_iteration(record: Iteration) -> None:
        say(f"  Newton {next(numbers)}: {record.summary()}")

    kernel = solve_contact(
        reduced.system,
        c=c,
        initial_active=initial_active,
        tolerance=tolerance,
        max_iterations=case.solver.max_iterations,
        backend=backend,
        on_iteration=on_iteration,
        accelerators=accelerators,
        second_guess=second_guess,
        stalled_guess=stalled_guess if initial_active is None and sequenced else None,
        linear=linear,
    )
    if isinstance(linear, IterativeSetSolver) and linear_figures is not None:
        linear_figures.update(linear.figures)
    return reduced, kernel, sequencing


def case_accelerators(case: Case) -> Accelerators:
    """The kernel's accelerators as the case's ``solver.accelerators`` switches them."""
    switches = case.solver.accelerators
    return Accelerators(sequencing=switches.sequencing, zone_fronts=switches.zone_fronts,
                        schur_updates=switches.schur_updates, start_checks=switches.start_checks)


def _worth_meshing(problem: DiscreteProblem, kept: dict) -> bool:
    """Whether ``problem``'s coarser level is expected to pay for its meshing
    (:func:`contactfem.sequencing.coarse_level_pays` on its estimated unknowns); the level's
    case is kept in ``kept`` for :func:`coarser_level`."""
    if "coarser" not in kept:
        kept["coarser"] = coarser(problem.mesh_request, problem.refinements)
    return kept["coarser"] is not None and meshing_pays(problem, *kept["coarser"])


class _InPlace:
    """An executor that runs each task when it is submitted (what a small level's system,
    solver and analysis need: see :data:`BESIDE_COARSER_FROM`)."""

    def __enter__(self) -> "_InPlace":
        return self

    def __exit__(self, *exc_info) -> None:
        return None

    @staticmethod
    def submit(task: Callable, *args) -> Future:
        done: Future = Future()
        try:
            done.set_result(task(*args))
        except BaseException as error:  # the caller's result() raises it, as from a thread
            done.set_exception(error)
        return done


def _analysed(linear: ActiveSetSolver) -> ActiveSetSolver:
    """``linear`` with its pattern analysed, ready to factorise."""
    linear.analyse()
    return linear


@dataclass(frozen=True, eq=False)
class PathResult:
    """A load path solved step by step: ``steps[i]`` is the solve at ``factors[i]`` (its
    problem scaled by that factor, its timings its own), or ``steps`` holds the last step
    only when the caller took them one by one (``keep_steps=False``). ``seconds`` is the contact solve
    of the whole path, ``factorizations`` its factorisations, ``timings`` and
    ``sequencing`` those of the whole path (as a single solve reports them)."""

    factors: tuple[float, ...]
    steps: tuple[SolveResult, ...]
    seconds: float
    factorizations: int
    timings: Mapping[str, float] = field(default_factory=dict)
    sequencing: Mapping = field(default_factory=dict)

    @property
    def final(self) -> SolveResult:
        """The last step, with the whole path's timings: what report.json and the solution files describe."""
        return dataclasses.replace(self.steps[-1], timings=self.timings, sequencing=self.sequencing)


@_names_the_case
def solve_load_path(
    case: Case,
    *,
    method: str | None = None,
    refine: int | None = None,
    progress: Progress | None = None,
    accept_uncertified: bool = False,
    on_step: Callable[[int, float, SolveResult], None] | None = None,
    keep_steps: bool = True,
) -> PathResult:
    """Solve ``case`` at each factor of its load path (``case.load_path``) with one linear solver.

    ``on_step(index, factor, step)`` receives each step as it is solved (to write it out);
    with ``keep_steps`` false the result holds only the last step, so that a long path
    needs the memory of one step, not of all.

    Raises
    ------
    SolverError
        If a step does not converge (naming the step and its factor) or, unless accepted,
        the last step solved is not certified.
    """
    say = progress or (lambda message: None)
    method_name = method or case.solver.method
    contact_method = get_method(method_name)
    backend = _serial_backend(case)
    if case.solver.backend in ITERATIVE_BACKENDS:
        raise CaseError(f"{case.source.name}: solver.backend = {case.solver.backend}: a load path is solved by "
                        "factorisations carried from step to step, not iteratively; use auto or a direct backend")
    factors = case.load_path.factors
    timings: dict[str, float] = {}
    problem = prepare(case, refine=refine, progress=say, timings=timings)
    if keep_steps:
        _refuse_oversized_path(case, problem)
    path_started = clock()
    say(f"solving {len(factors)} load steps with method {contact_method.equation} ({method_name}), "
        f"backend {backend}")
    reduced = problem.contact_system(contact_method)
    c = case.solver.c if case.solver.c is not None else default_c(reduced.system)
    accelerators = case_accelerators(case)
    path = PathSolver(reduced.system, c=c, tolerance=case.solver.tolerance, max_iterations=case.solver.max_iterations,
                      backend=backend, accelerators=accelerators)
    # The fine level's ordering and symbolic analysis (outside the interpreter's lock) run
    # while the coarser levels mesh and assemble, as in a single solve.
    with ThreadPoolExecutor(max_workers=1) if accelerators.sequencing else _InPlace() as pool:
        analysed = pool.submit(path.linear.analyse)
        coarse_path = (_coarse_path(case, problem, c, case.solver.tolerance, case.solver.max_iterations)
                       if accelerators.sequencing else None)
        analysed.result()
    starts = None if coarse_path is None else PredictedStarts(coarse_path.predict)
    if starts is not None:
        path.starts = starts
    if coarse_path is not None:
        levels = coarse_path.record()["levels"]
        say(f"  each step starts from the same path on {coarse_path.problem.n_unknowns} unknowns "
            f"({levels} coarser level{'s' if levels > 1 else ''}) or from the last steps extrapolated, "
            "whichever predicted the step before better")
    gradients = shape_gradients(problem.mesh.points, problem.mesh.triangles)[0]
    steps: list[SolveResult] = []
    solved = factorizations = 0
    # What the caller's on_step took (writing each step's files) is its own, not the solve's.
    postprocess = handed_over = 0.0
    last: KernelResult | None = None
    started = path_started
    for index, (factor, kernel) in enumerate(zip(factors, path.walk(factors))):
        seconds = clock() - started
        solved, factorizations, last = index + 1, factorizations + kernel.factorizations, kernel
        say(f"  step {index + 1}/{len(factors)}, factor {factor:.4g}: {int(kernel.active.sum())} active, "
            f"{kernel.iterations} Newton, {kernel.factorizations} factorisations, {seconds:.2f} s")
        scaled = reduced.settled(problem.scaled(factor), kernel.displacement)
        post = clock()
        solution = _solution(method_name, scaled, reduced.displacement(kernel.displacement), kernel, gradients)
        step = SolveResult(method=method_name, problem=scaled, solution=solution, kernel=kernel, backend=backend,
                           timings={"solve": seconds, "postprocess": clock() - post})
        postprocess += step.timings["postprocess"]
        if on_step is not None:
            handed = clock()
            on_step(index, factor, step)
            handed_over += clock() - handed
        steps = [*steps, step] if keep_steps else [step]
        started = clock()
    seconds = clock() - path_started - handed_over
    accepted = (Status.CONVERGED, Status.NOT_CERTIFIED) if accept_uncertified else (Status.CONVERGED,)
    if solved < len(factors) or last.status not in accepted:
        raise SolverError(f"{case.source.name}: method {method_name}: load step {solved} of {len(factors)} "
                          f"(factor {factors[solved - 1]:g}): {last.message}")
    return PathResult(factors=tuple(factors), steps=tuple(steps), seconds=seconds, factorizations=factorizations,
                      timings={**timings, "solve": seconds - postprocess, "postprocess": postprocess,
                               **({"write_steps": handed_over} if on_step is not None else {})},
                      sequencing={} if coarse_path is None else {**coarse_path.record(),
                                                                  "started_from": dict(starts.started)})


class CoarsePath:
    """A load path's coarser level: the case on a coarser mesh (:func:`contactfem.sequencing.coarser`),
    solved with one linear solver at whichever factors the finer path asks for (:meth:`predict`),
    its own steps started from the level below it (:class:`contactfem.sequencing.PredictedStarts`)."""

    def __init__(self, fine: DiscreteProblem, problem: DiscreteProblem, reduced: ReducedSystem, path: PathSolver,
                 c: float, below: "CoarsePath | None", seconds: float) -> None:
        self.fine, self.problem, self.reduced, self.path, self.c, self.below = fine, problem, reduced, path, c, below
        self.failed = False
        self.iterations = self.factorizations = self.steps = 0
        #: This level's preparation and steps, the levels below included.
        self.seconds = seconds

    def predict(self, factor: float) -> np.ndarray | None:
        """The finer level's active set predicted from this level solved at ``factor``; None
        once a step of this level has failed (the finer path then extrapolates)."""
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
            fields = _contact_fields(self.problem, self.reduced.displacement(kernel.displacement), kernel)
            active = predict_active_set(self.fine.contact, fields, self.c, self.fine.law)
        self.seconds += clock() - started
        return active

    def record(self) -> dict:
        """What the coarser levels cost along the path, as a single solve's ``sequencing`` record."""
        return {"coarse_unknowns": self.problem.n_unknowns,
                "levels": 1 + (self.below.record()["levels"] if self.below is not None else 0),
                "coarse_steps": self.steps, "coarse_iterations": self.iterations,
                "coarse_factorizations": self.factorizations, "seconds": self.seconds}


def _coarse_path(case: Case, problem: DiscreteProblem, c: float, tolerance: float,
                 max_iterations: int | None) -> CoarsePath | None:
    """The coarser levels of a load path on ``problem`` (its contact indicator weighted by
    ``c``), or None where a single solve would not sequence either: a small problem, no
    coarser mesh, a level that does not pay for itself, one the mesher refuses."""
    started = clock()
    coarse_problem = coarser_level(problem, lambda request, refine: prepare(case, refine=refine, request=request))
    if coarse_problem is None:
        return None
    reduced = coarse_problem.contact_system(get_method(SEQUENCING_METHOD))
    coarse_c = case.solver.c if case.solver.c is not None else default_c(reduced.system)
    below = _coarse_path(case, coarse_problem, coarse_c, tolerance, max_iterations)
    path = PathSolver(reduced.system, backend=_serial_backend(case), c=coarse_c, tolerance=tolerance,
                      max_iterations=max_iterations, starts=None if below is None else PredictedStarts(below.predict))
    return CoarsePath(problem, coarse_problem, reduced, path, c, below, clock() - started)


#: The share of this machine's memory the steps of a load path kept whole may hold.
PATH_MEMORY_SHARE = 0.25


def _refuse_oversized_path(case: Case, problem: DiscreteProblem) -> None:
    """Refuse, before solving, a path whose steps' fields (displacement, stresses, von Mises,
    contact fields), all kept, would not fit in a quarter of memory (``contactfem solve``
    writes each step as it is solved and keeps none)."""
    mesh = problem.mesh
    per_step = 8 * (2 * mesh.n_points + 5 * mesh.n_triangles + 6 * len(problem.contact.nodes))
    steps = len(case.load_path.factors)
    limit = memory_limit()
    allowed = PATH_MEMORY_SHARE * limit.bytes
    if steps * per_step > allowed:
        raise CaseError(
            f"{case.source.name}: load_path: {steps} steps of this mesh ({problem.n_unknowns} unknowns) would hold "
            f"about {steps * per_step / 2**30:.3g} GiB of fields, more than a quarter ({allowed / 2**30:.3g} GiB) of "
            f"{limit.source}; use at most {max(1, int(allowed // per_step))} steps or a coarser mesh")


def _serial_backend(case: Case) -> str:
    """The case's direct backend, which must run in this process (petsc runs under mpiexec):
    what coarse levels, layers and load paths factorise with (``amg`` and ``auto`` give the
    fastest direct backend installed; the fine level's is :func:`contactfem.estimate.choose_backend`'s)."""
    backend = resolve_backend(case.solver.backend)
    if backend in DISTRIBUTED_BACKENDS:
        raise CaseError(f"{case.source.name}: solver.backend = {backend}: runs a solve across MPI ranks, as "
                        "`mpiexec -n P contactfem solve CASE --backend petsc`; this command solves in one "
                        "process (use auto, cholmod, pardiso, superlu or amg)")
    return resolve_backend("auto") if backend in ITERATIVE_BACKENDS else backend



def _predict_from_coarser(case: Case, problem: DiscreteProblem, fine: Callable[[], tuple[ReducedSystem, float]],
                          say: Progress, coarse_levels: dict | None = None,
                          forced: bool = False) -> tuple[np.ndarray | None, dict]:
    """The initial active set from the same case solved on a coarser mesh (recursively),
    corrected in a layer along ΓC of the fine kernel's system, and its cost. ``fine`` gives
    that system and its c once a coarse level has solved (they may be made meanwhile).

    ``coarse_levels`` keeps the coarse level's problem and solve, or gives them when an
    earlier solve of ``problem`` kept them (see :func:`solve_case`).
    """
    kept = {} if coarse_levels is None else coarse_levels

    def solve_coarse(coarse_problem: DiscreteProblem) -> CoarseSolve:
        if "solve" in kept:
            return dataclasses.replace(kept["solve"], reused=True)
        # Only the contact fields and the displacement are read: no stresses.
        coarse, kernel, sequencing = _contact_solve(case, coarse_problem, get_method(SEQUENCING_METHOD),
                                                    _serial_backend(case), lambda message: None)
        displacement = coarse.displacement(kernel.displacement)
        kept["solve"] = CoarseSolve(_contact_fields(coarse_problem, displacement, kernel), kernel, sequencing,
                                    coarse_problem.mesh, displacement)
        return kept["solve"]

    def prepare_coarse(request: MeshRequest, refine: int) -> DiscreteProblem:
        if "problem" not in kept:
            kept["problem"] = prepare(case, refine=refine, request=request)
        return kept["problem"]

    def correct(coarse: CoarseSolve, active: np.ndarray) -> tuple[np.ndarray, dict]:
        reduced, c = fine()
        return correct_in_layer(reduced, coarse, active, c, case.solver.tolerance, case.solver.max_iterations,
                                _serial_backend(case))

    return predict_from_coarser(problem, lambda: fine()[1], say, prepare_coarse, solve_coarse, correct, forced,
                                kept.get("coarser"))


def _solution(method: str, problem: DiscreteProblem, displacement: np.ndarray, kernel: KernelResult,
              gradients: np.ndarray | None = None) -> Solution:
    """The fields of a converged solve: stresses per triangle and the contact fields
    (``gradients``: the mesh's shape gradients, when the caller keeps them)."""
    mesh = problem.mesh
    if problem.drive is not None:  # the kernel's field is relative to the moving obstacle
        displacement = problem.drive.moved(displacement)
    stress = stresses(mesh.points, mesh.triangles, displacement, problem.law, gradients)
    return Solution(
        method=method,
        mesh=mesh,
        displacement=displacement,
        stress=stress,
        von_mises=von_mises(stress),
        contact=_contact_fields(problem, displacement, kernel, moved=True),
        newton=_history_arrays(kernel.history),
    )


def _contact_fields(problem: DiscreteProblem, displacement: np.ndarray, kernel: KernelResult,
                    moved: bool = False) -> ContactFields:
    """The contact fields of a solve (a fine one's output, a coarse level's prediction);
    ``moved``: ``displacement`` is the lab's, the gaps those to the advanced obstacle."""
    contact = problem.contact
    return ContactFields(
        nodes=contact.nodes,
        edges=contact.edges,
        multiplier=kernel.multiplier,
        nodal_force=kernel.nodal_force,
        normal_displacement=np.einsum("ij,ij->i", displacement[contact.nodes], contact.normals),
        gap=contact.gap if problem.drive is None or not moved else problem.drive.gap(contact.gap, contact.normals),
        active=kernel.active,
        abscissa=contact.abscissa,
        **contact.output_fields(),
        obstacle_shift=None if problem.drive is None or not moved else problem.drive.advance * problem.drive.direction,
    )


def _history_arrays(history: list[Iteration]) -> dict[str, np.ndarray]:
    names = ("active", "added", "removed", "proposed", "equilibrium_residual", "complementarity_residual",
             "seconds")
    return {name: np.array([getattr(r, name) for r in history]) for name in names}
