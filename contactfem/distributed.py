"""The contact solve on PETSc/MPI: each rank assembles its share of the stiffness, and the active-set
iteration of :mod:`contactfem.kernel` runs on distributed vectors, its linear solves done by PETSc.

Run under ``mpiexec -n P``; every rank calls :func:`solve_distributed` with the same
arguments, and rank 0 receives a :class:`contactfem.solve.SolveResult` for the writers.

What each rank holds:

- the whole mesh, the load vector and the supports (O(n) vectors, built by the serial
  code: meshing is deterministic, so every rank gets the same mesh without sending it);
- the rows of the stiffness it owns (nodes in contiguous blocks of a locality-preserving
  order, see :func:`node_order`), assembled from the triangles whose first vertex it owns,
  entries of rows owned elsewhere being sent by PETSc's assembly; and a copy of them with
  absolute values (|K|, for the round-off bound of the equations);
- the contact data (m ~ √n nodes): gathered on every rank, so that μ = B⁻¹Λ and every
  active-set decision is computed redundantly and identically, with no further message.

The linear solves: MUMPS Cholesky (distributed direct, the default) or CG with GAMG
(smoothed aggregation, the rigid motions as near-null space; O(n) memory, for the largest
meshes). Supports and active normals are imposed by zeroing rows and columns of a work
copy of K inside its own sparsity pattern, so that MUMPS keeps its ordering and symbolic
analysis across Newton steps and only refactorises.

The difference from the serial kernel, by design: every Newton step factorises its own
active set (no Schur updates from a reference set, which would need a distributed column
solve per changed node; only a set equal to the one factorised last, a load path's step
starting where the last settled, keeps its factorisation). The first active set (predicted from a coarser mesh, solved
across the ranks too, when that pays), the active-set updates, tolerance bands, cycling
safeguards and certificate are the serial kernel's.

Platens, and a pushed obstacle's advance, are assembled into the rotated unknowns as the
serial :class:`contactfem.discretize.ReducedSystem` does (the advance one more unknown, see
:mod:`contactfem.distributed_assembly`); curved obstacles give each contact node its own
frame, a moved one shifts the supports; a body held only by contact gives the kernel its
free rigid motions at the contact normals (every active set must hold them, as serially);
load paths run in :mod:`contactfem.distributed_path`, one distributed solver (its MUMPS
analysis, or GAMG's coarse spaces) carried across the steps.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from contactfem.case import Case
from contactfem.discretize import DiscreteProblem, build_mesh
from contactfem.discretize.meshing import MeshRequest
# Some names are re-exported: the assembly lived here.
from contactfem.distributed_assembly import (  # noqa: F401
    ELEMENT_CHUNK,
    _DistributedSystem,
    _Layout,
    element_stiffness,
    node_order,
)
from contactfem.distributed_mumps import mumps_figures, mumps_ordering
# The result and its way to the writers (re-exported: they lived here).
from contactfem.distributed_result import (  # noqa: F401
    DistributedResult,
    SolutionProduct,
    _peak_rss,
    _with_stiffness,
    distributed_report,
    gather_iterate,
    parallel_figures,
    step_solution,
)
from contactfem.errors import CaseError, SolverError
from contactfem.kernel import (
    EPS,
    REFINEMENT_STEPS,
    FORCE_RESOLUTION_LIMIT,
    ZERO_FORCE_STRAIN,
    Certificate,
    ContactSystem,
    Iteration,
    KernelResult,
    Scales,
    Status,
    build_certificate,
    solve_contact,
)
from contactfem.linalg import SINGULARITY_LIMIT, FactorCheck, probe_vector
from contactfem.methods import get_method
from contactfem.sequencing import starting_set
from contactfem.timings import clock

if TYPE_CHECKING:
    from contactfem.solve import SolveResult

Progress = Callable[[str], None]

#: The linear solvers of the petsc backend.
SOLVERS = ("mumps", "gamg")
#: CG + GAMG stops at this relative (unpreconditioned) residual; the kernel's iterative
#: refinement then brings the equations to their round-off bound as it does for a direct solve.
GAMG_RTOL = 1e-12
GAMG_MAX_ITERATIONS = 5000
#: CG's relative residual for the singularity probe (see :meth:`_DistributedSolver._probe`).
PROBE_RTOL = 1e-6

_INSTALL_HINT = ("the petsc backend needs petsc4py and mpi4py: pip install mpi4py, then "
                 "PETSC_DIR=<PETSc directory> pip install --no-build-isolation petsc4py (see README)")


def petsc_available() -> bool:
    """Whether petsc4py and mpi4py can be imported (without initialising MPI)."""
    import importlib.util

    return all(importlib.util.find_spec(name) is not None for name in ("petsc4py", "mpi4py"))


def mpi_world():
    """MPI_COMM_WORLD (mpi4py), for the caller's own decisions between ranks."""
    _, MPI = _petsc()
    return MPI.COMM_WORLD


def _petsc():
    """petsc4py's PETSc and mpi4py's MPI, imported on first use: the module itself imports without them."""
    try:
        import petsc4py

        petsc4py.init()
        from mpi4py import MPI
        from petsc4py import PETSc
    except ImportError as error:
        raise SolverError(f"{_INSTALL_HINT} ({error})") from None
    return PETSc, MPI


def solve_distributed(case: Case, method: str | None = None, refine: int | None = None, solver: str = "mumps",
                      progress: Progress | None = None, accept_uncertified: bool = False,
                      sequencing: bool = True, distributed_mesh: bool = True, gather: bool = True) -> DistributedResult:
    """Mesh, assemble and solve ``case`` on all the ranks of MPI_COMM_WORLD (call it on every rank).

    Parameters
    ----------
    case, method, refine, accept_uncertified
        As for :func:`contactfem.solve.solve_case`.
    solver : {"mumps", "gamg"}
        MUMPS Cholesky, or CG preconditioned by GAMG with the rigid motions as near-null space.
    progress : callable, optional
        Receives progress lines; called on rank 0 only.
    sequencing : bool
        Start from the active set a coarser mesh predicts, when that pays (as the serial
        solve does; the coarse levels are solved across the ranks too); False starts from
        the nodes inside the obstacle.
    distributed_mesh : bool
        Let each rank refine only its piece of the coarse mesh when the case allows it (see
        :mod:`contactfem.distributed_problem`); False meshes the whole case on every rank.
    gather : bool
        On a distributed mesh: gather the solution to rank 0 and mesh the whole case there for
        a whole :class:`~contactfem.solve.SolveResult` (True), or leave it in pieces, each rank
        with its share (False, :mod:`contactfem.distributed_output`: no rank holds the whole mesh).

    Raises
    ------
    SolverError
        Without petsc4py/mpi4py, for an unknown ``solver``, and as
        :func:`~contactfem.solve.solve_case` does when the kernel does not converge.
    Raised on every rank alike: every decision is taken from data all ranks share.
    """
    if solver not in SOLVERS:
        raise SolverError(f"unknown petsc solver {solver!r}; pick one of {', '.join(SOLVERS)}")
    PETSc, MPI = _petsc()
    comm = PETSc.COMM_WORLD
    mpi = comm.tompi4py()
    rank, ranks = mpi.Get_rank(), mpi.Get_size()
    say = (progress or (lambda message: None)) if rank == 0 else (lambda message: None)
    method_name = method or case.solver.method
    timings: dict[str, float] = {}

    from contactfem.distributed_problem import PieceProblem, gather_coordinates, piece_problem, whole_problem

    started = clock()
    refinements = case.mesh.refine if refine is None else refine
    # Each rank refines its own piece of the coarse mesh when the case allows it, else meshes it whole.
    problem = piece_problem(case, mpi, refine) if distributed_mesh else None
    say(f"meshing ({'a piece on each' if problem is not None else 'each'} of {ranks} ranks)")
    problem_seconds = 0.0
    if problem is None:
        mesh = build_mesh(case, refine=refine)
        timings["mesh"] = clock() - started
        started = clock()
        problem = _problem_without_stiffness(case, mesh, refinements)
        problem_seconds = clock() - started
    else:  # the piece, its boundary, loads, supports and contact
        timings["mesh"] = clock() - started

    level = _solve_level(PETSc, MPI, comm, case, problem, method_name, solver, say, sequencing, timings)
    timings["assemble"] += problem_seconds  # loads, supports and contact, as the serial stage counts them
    kernel, linear, system = level.kernel, level.linear, level.system
    accepted = (Status.CONVERGED, Status.NOT_CERTIFIED) if accept_uncertified else (Status.CONVERGED,)
    if kernel.status not in accepted:
        linear.destroy()
        raise SolverError(f"{case.source.name}: method {method_name}: {kernel.message}")

    if isinstance(problem, PieceProblem) and not gather:
        from contactfem.distributed_output import piece_outcome

        return piece_outcome(linear, level, case, problem, method_name, solver, timings)
    started = clock()
    linear.ksp.reset()  # the factors go before rank 0 gathers whole vectors
    gathered = gather_iterate(linear)
    coordinates = gather_coordinates(linear, problem) if isinstance(problem, PieceProblem) else None
    timings["gather"] = clock() - started
    parallel = parallel_figures(linear, solver, timings, kernel.factorizations)
    linear.destroy()
    if rank != 0:
        return DistributedResult(result=None, parallel=parallel, rank=rank)

    started = clock()
    from contactfem.solve import SolveResult

    if coordinates is not None:  # the mesh for the writers, now that the solver's memory is freed
        problem, system = whole_problem(case, refinements, coordinates)
    problem, solution = step_solution(gathered, system, problem, method_name, kernel)
    timings["postprocess"] = clock() - started
    first = parallel["per_rank"][0]
    first["solve_peak_rss_bytes"] = first["peak_rss_bytes"]
    first["peak_rss_bytes"] = _peak_rss()  # the mesh rank 0 built for the writers included
    parallel["max_peak_rss_bytes"] = max(entry["peak_rss_bytes"] for entry in parallel["per_rank"])
    result = SolveResult(method=method_name, problem=problem, solution=solution, kernel=kernel,
                         backend=f"petsc-{solver}", timings=timings, sequencing=level.sequencing)
    return DistributedResult(result=result, parallel=parallel, rank=rank)


@dataclass(eq=False)
class _Level:
    """One solved level: the kernel's result (its ``displacement`` this rank's part), the
    normal displacement at the contact nodes (every rank) and the distributed objects."""

    kernel: KernelResult
    normal_displacement: np.ndarray
    linear: "_DistributedSolver"
    layout: _Layout
    system: "_DistributedSystem"
    sequencing: dict


def _solve_level(PETSc, MPI, comm, case: Case, problem: DiscreteProblem, method_name: str, solver: str,
                 say: Progress, sequencing: bool, timings: dict[str, float]) -> _Level:
    """Assemble ``problem`` across the ranks and run the active-set iteration on it, from the
    active set a coarser level predicts when that pays (as :func:`contactfem.solve.solve_case`)."""
    mpi = comm.tompi4py()
    contact_method = get_method(method_name)
    started = clock()
    say("assembling")
    from contactfem.distributed_problem import PieceProblem, assemble_piece_system

    if isinstance(problem, PieceProblem):
        system = assemble_piece_system(PETSc, comm, problem, contact_method)
        layout = system.layout
    else:
        layout = _Layout.build(problem.mesh.points, mpi.Get_size(), mpi.Get_rank())
        system = _DistributedSystem.assemble(PETSc, comm, problem, contact_method, layout)
    timings["assemble"] = clock() - started
    say(f"  {problem.n_unknowns} unknowns, {len(problem.contact.nodes)} contact nodes, "
        f"{mpi.Get_size()} ranks ({timings['assemble']:.2f} s)")

    started = clock()
    say(f"solving with method {contact_method.equation} ({method_name}), petsc {solver}")
    c = case.solver.c if case.solver.c is not None else system.default_c()
    # Every rank takes the same decision: the gaps are whole on every rank, and the coarse
    # levels (a second guess included) are solved by all of them together.
    initial_active, second_guess, predicted = (
        starting_set(problem.contact.gap, case.solver.tolerance,
                     lambda: _predict_from_coarser(PETSc, MPI, comm, case, problem, c, solver, say))
        if sequencing else (None, None, {}))
    numbers = itertools.count(1)

    def on_iteration(record: Iteration) -> None:
        say(f"  Newton {next(numbers)}: {record.summary()}")

    linear = _DistributedSolver(PETSc, MPI, comm, system, solver, tolerance=case.solver.tolerance)
    kernel, normal_displacement = _active_set_iteration(
        linear, c=c, tolerance=case.solver.tolerance, max_iterations=case.solver.max_iterations,
        initial_active=initial_active, on_iteration=on_iteration, second_guess=second_guess)
    timings["solve"] = clock() - started
    return _Level(kernel=kernel, normal_displacement=normal_displacement, linear=linear, layout=layout,
                  system=system, sequencing=predicted)


def _predict_from_coarser(PETSc, MPI, comm, case: Case, problem: DiscreteProblem, c: float, solver: str,
                          say: Progress) -> tuple[np.ndarray | None, dict]:
    """:func:`contactfem.coarse_levels.predict_from_coarser` with the coarse levels solved across the
    ranks too (a serial coarse solve would put a quarter-size matrix on every rank). Every
    decision is taken from data all ranks share, so they all recurse alike."""
    from contactfem.result import ContactFields
    from contactfem.coarse_levels import CoarseSolve, predict_from_coarser
    from contactfem.solve import SEQUENCING_METHOD

    def prepare_coarse(request: MeshRequest, refine: int) -> DiscreteProblem:
        from contactfem.distributed_problem import PieceProblem, piece_problem

        # Fewer refinements of the same request: in pieces too (a rectangle's fewer divisions are not).
        if isinstance(problem, PieceProblem) and request is problem.mesh_request:
            pieces = piece_problem(case, comm.tompi4py(), refine)
            if pieces is not None:
                return pieces
        return _problem_without_stiffness(case, build_mesh(case, refine=refine, request=request), refine, request)

    def solve_coarse(coarse_problem: DiscreteProblem) -> CoarseSolve:
        level = _solve_level(PETSc, MPI, comm, case, coarse_problem, SEQUENCING_METHOD, solver,
                             lambda message: None, True, {})
        try:
            contact, kernel = coarse_problem.contact, level.kernel
            fields = ContactFields(
                nodes=contact.nodes, edges=contact.edges, multiplier=kernel.multiplier,
                nodal_force=kernel.nodal_force, normal_displacement=level.normal_displacement, gap=contact.gap,
                active=kernel.active, abscissa=contact.abscissa, obstacle_point=contact.obstacle.point,
                obstacle_normal=contact.obstacle.normal, obstacle_ends=contact.obstacle.ends)
            return CoarseSolve(fields, kernel, level.sequencing)
        finally:
            level.linear.destroy()

    return predict_from_coarser(problem, lambda: c, say, prepare_coarse, solve_coarse)


def _problem_without_stiffness(case: Case, mesh, refinements: int, request: MeshRequest | None = None) -> DiscreteProblem:
    """The discrete problem but for the stiffness, which no rank assembles whole (``stiffness``
    is None until rank 0 gets a :class:`SolutionProduct`)."""
    from contactfem.discretize import build_problem

    return build_problem(case, mesh, refinements=refinements, assemble_stiffness=False, request=request)


class _DistributedSolver:
    """:class:`contactfem.kernel.ActiveSetSolver` on a distributed stiffness: solves K u = F with
    supports and the active normals fixed (rows and columns zeroed in a work copy of K, which
    keeps K's pattern so that MUMPS only refactorises), with iterative refinement to the
    equations' round-off bound, a singularity probe per factorisation, and the scales and
    certificate of the iterate, every norm taken over all ranks."""

    def __init__(self, PETSc, MPI, comm, system: _DistributedSystem, solver: str, tolerance: float) -> None:
        self.PETSc, self.MPI, self.comm, self.mpi = PETSc, MPI, comm, comm.tompi4py()
        self.system = system
        self.tolerance = tolerance
        self.solver_name = solver
        self.normal_dofs = system.normal_dofs
        self.gap = system.gap
        self.load_local = self.unit_load = system.load_local
        self.support_values_local = self.unit_support_values = system.support_values_local
        self._u: np.ndarray | None = None
        #: The active set of the current factorisation (None before the first).
        self._factorized: np.ndarray | None = None
        layout = system.layout
        self.first, self.last = layout.first, layout.last
        owned = (self.normal_dofs >= self.first) & (self.normal_dofs < self.last)
        #: Contact nodes whose normal unknown this rank owns, and where it sits in the local arrays.
        self.owned_contact = np.flatnonzero(owned)
        self.owned_normal_local = self.normal_dofs[owned] - self.first
        k = system.stiffness
        self.work = k.duplicate(copy=True)
        self.u, self.rhs = k.createVecs()
        self.scratch, self.product = k.createVecs()
        self.ksp = self._solver(solver)
        self.factorizations = 0
        self.column_solves = 0  # every step factorises its own active set: no Schur columns
        self.factor_seconds: list[float] = []
        #: MUMPS's account of the last factorisation (:func:`distributed_mumps.mumps_figures`); none for GAMG.
        self.factor_figures: dict = {}
        #: Iterations of each solve (1 for a direct solve: one substitution).
        self.linear_iterations: list[int] = []
        self.checks: list[FactorCheck] = []
        self.solution = self.u.duplicate()
        self.internal_force = self.u.duplicate()
        self.to_normals = self._normal_scatter()

    # ----- PETSc plumbing -----
    def _solver(self, solver: str):
        PETSc = self.PETSc
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(self.work)
        pc = ksp.getPC()
        if solver == "mumps":
            ksp.setType("preonly")
            pc.setType("cholesky")
            pc.setFactorSolverType("mumps")
            # PETSc 3.18 sets MUMPS's ICNTL from the options database at the symbolic
            # factorisation (a value set on the factor before is reset): the ordering goes there,
            # unless the user chose one (PETSC_OPTIONS="-mat_mumps_icntl_7 N").
            options = PETSc.Options()
            if not options.hasName("mat_mumps_icntl_7"):
                options["mat_mumps_icntl_7"] = mumps_ordering(PETSc)
            # PETSc options (PETSC_OPTIONS="-mat_mumps_icntl_14 50 ...") reach MUMPS from here.
            ksp.setFromOptions()
        else:
            ksp.setType("cg")
            ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)
            ksp.setTolerances(rtol=GAMG_RTOL, atol=0.0, max_it=GAMG_MAX_ITERATIONS)
            pc.setType("gamg")
            options = PETSc.Options()
            prefix = "contactfem_gamg_"
            ksp.setOptionsPrefix(prefix)
            # The Newton steps change only a few rows: the coarse spaces of the first set serve them all.
            options[f"{prefix}pc_gamg_reuse_interpolation"] = "true"
            ksp.setFromOptions()
            self.work.setNearNullSpace(self._near_null_space())
        return ksp

    def _near_null_space(self):
        PETSc = self.PETSc
        vectors = []
        for motion in self.system.rigid_motions_local:
            vector = self.u.duplicate()
            vector.setArray(motion)
            for previous in vectors:  # Gram–Schmidt: PETSc wants an orthonormal basis
                vector.axpy(-vector.dot(previous), previous)
            vector.normalize()
            vectors.append(vector)
        return PETSc.NullSpace().create(vectors=vectors, comm=self.comm)

    def _normal_scatter(self):
        PETSc = self.PETSc
        target = PETSc.Vec().createSeq(len(self.normal_dofs), comm=PETSc.COMM_SELF)
        where = PETSc.IS().createGeneral(np.asarray(self.normal_dofs, dtype=PETSc.IntType), comm=PETSc.COMM_SELF)
        scatter = PETSc.Scatter().create(self.u, where, target, None)
        where.destroy()
        return scatter, target

    def normals(self, local: np.ndarray) -> np.ndarray:
        """Entries at the contact normals (m,) of a distributed vector given by its local part, on every rank."""
        scatter, target = self.to_normals
        self.scratch.setArray(local)
        scatter.scatter(self.scratch, target, addv=self.PETSc.InsertMode.INSERT_VALUES,
                        mode=self.PETSc.ScatterMode.FORWARD)
        return target.getArray().copy()

    def multiply(self, matrix, local: np.ndarray) -> np.ndarray:
        self.scratch.setArray(local)
        matrix.mult(self.scratch, self.product)
        return self.product.getArray().copy()

    def linear_solve(self, local: np.ndarray, rtol: float = GAMG_RTOL) -> np.ndarray:
        """Solve with the factorised (or preconditioned) work matrix; ``rtol`` only matters to CG."""
        self.rhs.setArray(local)
        if self.solver_name == "gamg":
            self.ksp.setTolerances(rtol=rtol)
        self.ksp.solve(self.rhs, self.u)
        self.linear_iterations.append(int(self.ksp.getIterationNumber()))
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise SolverError(
                f"the stiffness matrix with its supports and active contact normals fixed could not be solved "
                f"(PETSc {self.solver_name}: {_reason_name(self.PETSc, reason)}); is part of the body held only by contact?")
        return self.u.getArray().copy()

    def maximum(self, local: np.ndarray) -> float:
        """max |local| over all ranks (inf if any entry is not finite)."""
        value = np.abs(local).max(initial=0.0) if len(local) else 0.0
        value = value if np.isfinite(value) else np.inf
        return float(self.mpi.allreduce(value, op=self.MPI.MAX))

    def gather_to_zero(self, vector) -> np.ndarray | None:
        """A whole distributed vector on rank 0 (PETSc order), None elsewhere."""
        scatter, whole = self.PETSc.Scatter.toZero(vector)
        scatter.scatter(vector, whole, addv=self.PETSc.InsertMode.INSERT_VALUES,
                        mode=self.PETSc.ScatterMode.FORWARD)
        values = whole.getArray().copy() if self.mpi.Get_rank() == 0 else None
        scatter.destroy()
        whole.destroy()
        return values

    def destroy(self) -> None:
        self.ksp.destroy()
        self.to_normals[0].destroy()
        self.to_normals[1].destroy()
        for item in (self.work, self.u, self.rhs, self.scratch, self.product, self.solution,
                     self.internal_force, self.system.stiffness, self.system.absolute):
            item.destroy()

    # ----- the kernel's linear algebra -----
    @property
    def condition(self) -> float:
        return self.checks[-1].condition if self.checks else 1.0

    def _factorize(self, active: np.ndarray) -> None:
        """Factorise the work matrix of ``active`` and solve for its base solution. The matrix
        depends on the set alone: a set factorised last (a load path's next step starting
        where the last settled) keeps its factorisation and check, and only its right-hand
        side, the load less the prescribed values' columns, is made anew."""
        PETSc = self.PETSc
        fixed = self.system.supported_local.copy()
        active_owned = active[self.owned_contact]
        fixed[self.owned_normal_local[active_owned]] = True
        values = self.support_values_local.copy()
        values[self.owned_normal_local[active_owned]] = self.gap[self.owned_contact[active_owned]]
        self.free = ~fixed
        if self._factorized is not None and np.array_equal(active, self._factorized):
            prescribed = np.where(fixed, values, 0.0)
            self.base = self.linear_solve(
                np.where(fixed, values, self.load_local - self.multiply(self.system.stiffness, prescribed)))
            return
        self.system.stiffness.copy(self.work, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        rows = (self.first + np.flatnonzero(fixed)).astype(PETSc.IntType)
        self.scratch.setArray(values)
        self.rhs.setArray(self.load_local)
        self.work.zeroRowsColumns(rows, diag=1.0, x=self.scratch, b=self.rhs)
        self.work.setOption(PETSc.Mat.Option.SPD, True)
        base_rhs = self.rhs.getArray().copy()
        started = clock()
        self.ksp.setOperators(self.work)
        self.ksp.setUp()
        self.factor_seconds.append(clock() - started)
        self.factorizations += 1
        if self.solver_name == "mumps":
            self.factor_figures = mumps_figures(self.ksp.getPC().getFactorMatrix())
        self.base = self.linear_solve(base_rhs)
        self.checks.append(self._probe(active))
        self._factorized = active.copy()

    def _probe(self, active: np.ndarray) -> FactorCheck:
        """:func:`contactfem.linalg.check_factorization` of the factorised work matrix: the same
        probe vector, residual and condition estimate."""
        # The probe is drawn over the mesh's unknowns in their own numbering, as the serial
        # kernel draws it, so that its entries depend neither on the ranks nor on their order.
        free_mesh = ~self.system.supported_mesh
        free_mesh[self.system.normal_slots[active]] = False
        b = self.system.layout.owned(probe_vector(self.system.n_dof, free_mesh))
        rows = self.free
        if not self.mpi.allreduce(bool(rows.any()), op=self.MPI.LOR):
            return FactorCheck(residual=0.0, condition=1.0)
        # Two or three correct digits of x decide the verdict and the condition estimate: CG
        # need not solve the probe to the equations' accuracy.
        x = self.linear_solve(b, rtol=PROBE_RTOL)
        scale = self.maximum(b[rows])
        norm = self.maximum(self.multiply(self.system.absolute, rows.astype(float))[rows])

        def measure(x: np.ndarray) -> tuple[np.ndarray, float]:
            residual = np.where(rows, b - self.multiply(self.work, x), 0.0)
            return residual, self.maximum(residual) / scale

        refined = False
        finite = self.mpi.allreduce(bool(np.isfinite(x).all()), op=self.MPI.LAND)
        relative = np.inf
        if finite:
            residual, relative = measure(x)
            if relative > SINGULARITY_LIMIT:
                refined = True
                x = x + self.linear_solve(residual, rtol=PROBE_RTOL)
                finite = self.mpi.allreduce(bool(np.isfinite(x).all()), op=self.MPI.LAND)
                residual, relative = measure(x) if finite else (residual, np.inf)
        name = "the stiffness matrix with its supports and active contact normals fixed"
        if not np.isfinite(relative):
            raise SolverError(f"{name} is singular: solving with its factorisation gives non-finite values")
        condition = float(norm * self.maximum(x[rows]) / scale)
        if relative > SINGULARITY_LIMIT or EPS * condition > SINGULARITY_LIMIT:
            raise SolverError(
                f"{name} is singular or numerically singular: probe residual {relative:.1e} after refinement, "
                f"condition estimate {condition:.1e} (eps*kappa {EPS * condition:.1e}), bound {SINGULARITY_LIMIT:g} "
                "(a part of the body not held, or too slender for double precision)")
        return FactorCheck(residual=relative, condition=condition, refined=refined)

    def solve(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """u (local part) and the reactions (F − K u) at the normal unknowns of ``active`` (on every rank)."""
        self._factorize(active)
        system = self.system
        active_owned = active[self.owned_contact]
        fixed_normals = self.owned_normal_local[active_owned]
        equations = ~system.supported_local
        equations[fixed_normals] = False
        u = self.base.copy()
        load = self.load_local
        target = system.gamma * self.maximum(
            np.where(equations, self.multiply(system.absolute, np.abs(u)) + np.abs(load), 0.0))
        residual = np.where(equations, load - self.multiply(system.stiffness, u), 0.0)
        for _ in range(REFINEMENT_STEPS):
            size = self.maximum(residual)
            if not size > target:
                break
            correction = self.linear_solve(np.where(self.free, residual, 0.0))
            trial = np.where(equations, residual - self.multiply(system.stiffness, correction), 0.0)
            if not self.maximum(trial) < size:
                break
            u, residual = u + correction, trial
        # Active normals are constraints: returned exactly (complementarity holds exactly).
        u[fixed_normals] = self.gap[self.owned_contact[active_owned]]
        self._u = u
        self._internal = self.multiply(system.stiffness, u)
        reaction = self.normals(load - self._internal)[active]
        return u, reaction

    def measure(self, u: np.ndarray, nodal_force: np.ndarray) -> Scales:
        """:meth:`contactfem.kernel.ActiveSetSolver.measure` over all ranks."""
        system = self.system
        contact = np.zeros(len(u))
        contact[self.owned_normal_local] = nodal_force[self.owned_contact]
        internal = self._internal if u is self._u else self.multiply(system.stiffness, u)
        equations = ~system.supported_local
        load = self.load_local
        with np.errstate(invalid="ignore", over="ignore"):
            residual = np.where(equations, internal + contact - load, 0.0)
            terms = np.where(equations, self.multiply(system.absolute, np.abs(u)) + np.abs(load) + np.abs(contact),
                             0.0)
            force = self.maximum(load) + self.maximum(internal) + float(np.abs(nodal_force).max(initial=0.0))
            roundoff = system.gamma * self.maximum(terms)
            if self.maximum(load) == 0.0 and force * FORCE_RESOLUTION_LIMIT < roundoff:
                # Nothing loads the body and its forces are round-off (as the serial solver measures).
                force = max(force, ZERO_FORCE_STRAIN * system.force_unit)
            force = max(force, np.finfo(float).tiny) if np.isfinite(force) else np.inf
            displacement = max(self.maximum(u), float(np.abs(self.gap).max(initial=0.0)))
            displacement = max(displacement, np.finfo(float).tiny) if np.isfinite(displacement) else np.inf
            return Scales(force=float(force), displacement=float(displacement),
                          roundoff=float(roundoff / force),
                          equilibrium=float(self.maximum(residual) / force))

    def analyse(self) -> None:
        """:meth:`contactfem.kernel.ActiveSetSolver.analyse`: nothing ahead of the first set
        (PETSc orders and analyses the pattern at the first factorisation, then keeps it)."""
        return None

    def set_load_factor(self, factor: float) -> None:
        """:meth:`contactfem.kernel.ActiveSetSolver.set_load_factor`: the load and prescribed
        values times ``factor`` (a step of a load path); the solver's set-up (MUMPS's ordering
        and analysis, GAMG's coarse spaces) carries over, the next set is factorised anew."""
        self.load_local = float(factor) * self.unit_load
        self.support_values_local = float(factor) * self.unit_support_values
        self._u = None

    def non_finite(self, u: np.ndarray) -> int:
        return int(self.mpi.allreduce(int(np.count_nonzero(~np.isfinite(u))), op=self.MPI.SUM))

    def keep(self, u: np.ndarray) -> None:
        """Store the iterate and its K u as the distributed vectors returned to rank 0."""
        self.solution.setArray(u)
        internal = self._internal if u is self._u else self.multiply(self.system.stiffness, u)
        self.internal_force.setArray(internal)

    @property
    def load(self) -> np.ndarray:
        """This rank's part of the load (what the kernel sizes its iterate by)."""
        return self.load_local

    def certify(self, u: np.ndarray, multiplier: np.ndarray, nodal_force: np.ndarray, scales: Scales,
                tolerance: float) -> Certificate:
        """:meth:`contactfem.kernel.ActiveSetSolver.certify` with u's non-finite entries counted over all ranks."""
        return build_certificate(self.non_finite(u), self.normals(u) - self.gap, multiplier, nodal_force, scales,
                                 tolerance, self.condition)


def _reason_name(PETSc, reason: int) -> str:
    names = {value: name for name, value in vars(PETSc.KSP.ConvergedReason).items() if isinstance(value, int)}
    return names.get(reason, str(reason))


def _active_set_iteration(linear: _DistributedSolver, *, c: float, tolerance: float, max_iterations: int | None,
                          initial_active: np.ndarray | None = None,
                          on_iteration: Callable[[Iteration], None] | None = None,
                          second_guess: Callable[[], np.ndarray | None] | None = None,
                          ) -> tuple[KernelResult, np.ndarray]:
    """:func:`contactfem.kernel.solve_contact` on the distributed solver: the contact arrays
    are whole on every rank, so every rank takes the same decisions. ``displacement`` of the
    result is this rank's part (PETSc order); the whole iterate is kept in
    ``linear.solution``. Also returns the normal displacement at the contact nodes (m,), on
    every rank."""
    kernel = solve_contact(kernel_system(linear), c=c, tolerance=tolerance, max_iterations=max_iterations,
                           initial_active=initial_active, on_iteration=on_iteration, linear=linear,
                           second_guess=second_guess)
    linear.keep(kernel.displacement)
    return kernel, linear.normals(kernel.displacement)


def kernel_system(linear: _DistributedSolver) -> ContactSystem:
    """The :class:`ContactSystem` the kernel is handed with the distributed solver: only its
    contact arrays (whole on every rank) are read, the rest being the solver's. A body held
    only by contact adds its free rigid motions at the contact normals, followed by a unit
    block, with a load whose work along them is the body's (all that
    :class:`contactfem.kernel.modes.ModeHolder` reads)."""
    system = linear.system
    m = len(linear.gap)
    modes, load = None, np.zeros(m)
    if system.free_modes_normal is not None:
        j = system.free_modes_normal.shape[1]
        modes = np.vstack([system.free_modes_normal, np.eye(j)])
        load = np.concatenate([np.zeros(m), system.free_modes_load])
    return ContactSystem(stiffness=None, load=load, normal_dofs=np.arange(m), gap=linear.gap,
                         multiplier_mass=system.multiplier_mass, contact_edges=system.contact_edges, free_modes=modes)
