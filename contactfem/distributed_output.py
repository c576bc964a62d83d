"""The result of a solve on a distributed mesh, kept in pieces: each rank's share of the fields for
its own files, and on rank 0 the boundary (O(√n) nodes) and the contact arrays for the report.

No rank gathers the whole iterate. After the solve, every rank

- takes the displacement at its piece's nodes (its owned ones and the others its triangles
  use, fetched from their owners by one PETSc scatter), turned back from the rotated unknowns
  into the mesh frame, and the stresses of its triangles (:class:`PieceFields`);
- sends rank 0 the displacement, K u and the load at its owned boundary nodes (rank 0 then has
  them at every boundary node: the supports' reactions, the contact fields);
- reduces with the others what the report needs of the whole mesh (:class:`BodyFigures`):
  counts, the extreme triangle sizes, the nodes' centroid and span, the body force's resultant,
  the energy a(u, u), the residual estimator's terms and, for a case with an exact solution,
  the squared errors of its triangles.

Rank 0's :class:`~contactfem.solve.SolveResult` has the boundary mesh for its mesh: the report
and the contact files are built from it, the body's files from the pieces
(:mod:`contactfem.io.pieces`); the residual estimator is summed over the pieces
(:mod:`contactfem.distributed_estimator`). What needs the whole mesh at once is not computed:
the H^{-1/2} norm of an exact multiplier error (a solve with the whole mesh's Gram matrix); the
report says so where it would be.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from contactfem.assembly import stresses, von_mises
from contactfem.report import BodyFigures
from contactfem.timings import clock

#: Why the H^{-1/2} norm of an exact multiplier error is not.
NO_DUAL_NORM = ("errors.multiplier_h_minus_half is null: on a distributed mesh no rank holds the whole "
                "mesh's H1 Gram matrix that norm solves with")


@dataclass(frozen=True, eq=False)
class PieceFields:
    """One rank's share of the solution, as its files hold it.

    Attributes
    ----------
    points : (p, 2) float64
        The piece's nodes (owned and not), in the piece's local order.
    numbers : (p,) int64
        Each node's PETSc number, the node's row in solution.h5.
    triangles : (t, 3) int64
        The piece's triangles (each triangle on one rank), local node indices.
    displacement : (p, 2) float64
        Mesh frame (a moving obstacle's advance included, as serial solves write it).
    stress : (t, 4) float64
        Columns xx, yy, xy, zz.
    von_mises : (t,) float64
    owned : (o,) int64
        Local indices of the owned nodes, in PETSc order: rows node_range of solution.h5.
    node_range : (int, int)
        This rank's PETSc node numbers [first, last).
    triangle_offset : int
        The row of this rank's first triangle in solution.h5 (the ranks' triangles in rank order).
    n_points, n_triangles : int
        The whole mesh's counts.
    """

    points: np.ndarray
    numbers: np.ndarray
    triangles: np.ndarray
    displacement: np.ndarray
    stress: np.ndarray
    von_mises: np.ndarray
    owned: np.ndarray
    node_range: tuple[int, int]
    triangle_offset: int
    n_points: int
    n_triangles: int


def piece_outcome(linear, level, case, problem, method_name: str, solver: str, timings: dict):
    """:class:`contactfem.distributed.DistributedResult` of a solve on pieces (every rank calls
    it, once the kernel is done): every rank's :class:`PieceFields`, and on rank 0 a
    :class:`~contactfem.solve.SolveResult` over the boundary mesh with :class:`BodyFigures`."""
    from contactfem.distributed_estimator import piece_energy_estimate
    from contactfem.distributed_result import DistributedResult, SolutionProduct, _peak_rss, parallel_figures
    from contactfem.solve import SolveResult, _solution

    kernel, system = level.kernel, level.system
    mpi = linear.mpi
    started = clock()
    linear.ksp.reset()  # the factors go before the fields are made
    fields = _piece_fields(linear, system, problem, mpi)
    boundary = _boundary_vectors(linear, system, problem, mpi)
    energy = mpi.allreduce(float(linear.solution.getArray() @ linear.internal_force.getArray()))
    body = _body_figures(problem, fields, mpi)
    timings["gather"] = clock() - started
    parallel = parallel_figures(linear, solver, timings, kernel.factorizations)
    linear.destroy()
    if mpi.Get_rank() != 0:
        piece_energy_estimate(problem, fields, mpi)
        return DistributedResult(result=None, parallel=parallel, rank=mpi.Get_rank(), pieces=fields)
    started = clock()
    u_rotated, internal, load = boundary
    displacement = system.mesh_vector(u_rotated).reshape(-1, 2)
    moved = displacement if problem.drive is None else problem.drive.moved(displacement)
    force = system.mesh_force(internal)
    boundary_problem = replace(problem, stiffness=SolutionProduct(moved.ravel(), force),
                               load=system.mesh_force(load))
    solution = _solution(method_name, boundary_problem, displacement, kernel)
    if problem.exact is not None:
        body = replace(body, errors={**body.errors, "multiplier_l2": _multiplier_l2(solution, problem)},
                       warnings=(NO_DUAL_NORM,))
    estimate = piece_energy_estimate(problem, fields, mpi, solution, energy)
    timings["postprocess"] = clock() - started
    parallel["max_peak_rss_bytes"] = max(entry["peak_rss_bytes"] for entry in parallel["per_rank"])
    parallel["per_rank"][0]["peak_rss_bytes"] = max(parallel["per_rank"][0]["peak_rss_bytes"], _peak_rss())
    result = SolveResult(method=method_name, problem=boundary_problem, solution=solution, kernel=kernel,
                         backend=f"petsc-{solver}", timings=timings, sequencing=level.sequencing)
    return DistributedResult(result=result, parallel=parallel, rank=0, pieces=fields, body=body, estimate=estimate)


def _piece_fields(linear, system, problem, mpi) -> PieceFields:
    """This rank's :class:`PieceFields`: the solution at its piece's nodes (one scatter from
    their owners), in the mesh frame, and its triangles' stresses."""
    PETSc = linear.PETSc
    piece, numbers = problem.piece, problem.numbers
    slots = (2 * numbers[:, None] + np.arange(2)).ravel().astype(PETSc.IntType)
    target = PETSc.Vec().createSeq(len(slots), comm=PETSc.COMM_SELF)
    where = PETSc.IS().createGeneral(slots, comm=PETSc.COMM_SELF)
    scatter = PETSc.Scatter().create(linear.solution, where, target, None)
    scatter.scatter(linear.solution, target, addv=PETSc.InsertMode.INSERT_VALUES, mode=PETSc.ScatterMode.FORWARD)
    values = target.getArray().copy().reshape(-1, 2)
    for item in (scatter, where, target):
        item.destroy()
    # Framed boundary nodes hold Qᵀ u: turn them back (the pieces route has no platen).
    ids = problem.boundary_ids[system.frame_nodes]
    sorter = np.argsort(piece.node_ids)
    at = np.minimum(np.searchsorted(piece.node_ids, ids, sorter=sorter), max(len(sorter) - 1, 0))
    here = piece.node_ids[sorter[at]] == ids if len(sorter) else np.zeros(len(ids), dtype=bool)
    local = sorter[at[here]]
    values[local] = np.einsum("kab,kb->ka", system.frames[here], values[local])
    if problem.drive is not None:
        values = problem.drive.moved(values)
    stress = stresses(piece.points, piece.triangles, values, problem.law)
    owned = piece.owned
    owned = owned[np.argsort(numbers[owned])]
    counts = mpi.allgather(len(piece.triangles))
    rank = mpi.Get_rank()
    return PieceFields(points=piece.points, numbers=numbers, triangles=piece.triangles, displacement=values,
                       stress=stress, von_mises=von_mises(stress), owned=owned, node_range=problem.node_range,
                       triangle_offset=int(sum(counts[:rank])), n_points=int(problem.n_points_total),
                       n_triangles=int(sum(counts)))


def _boundary_vectors(linear, system, problem, mpi) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The rotated u, K u and load at every boundary node (2 n_b,), on rank 0 (None elsewhere):
    each rank sends its owned boundary nodes' entries."""
    first, last = problem.node_range
    numbers = problem.boundary_numbers
    mine = np.flatnonzero((numbers >= first) & (numbers < last))
    slots = (2 * (numbers[mine] - first)[:, None] + np.arange(2)).ravel()
    sent = (mine, linear.solution.getArray()[slots], linear.internal_force.getArray()[slots],
            np.asarray(linear.load_local)[slots])
    gathered = mpi.gather(sent, root=0)
    if gathered is None:
        return None
    n = 2 * len(numbers)
    vectors = [np.zeros(n) for _ in range(3)]
    for nodes, *values in gathered:
        at = (2 * nodes[:, None] + np.arange(2)).ravel()
        for vector, part in zip(vectors, values):
            vector[at] = part
    return tuple(vectors)


def _body_figures(problem, fields: PieceFields, mpi) -> BodyFigures:
    """:class:`BodyFigures` reduced over the pieces (every rank gets them)."""
    from mpi4py import MPI

    piece = problem.piece
    owned_points = piece.points[fields.owned]
    n_total = fields.n_points
    centre = mpi.allreduce(owned_points.sum(axis=0)) / max(n_total, 1)
    extents = np.array(mpi.allgather((owned_points.min(axis=0, initial=np.inf),
                                      owned_points.max(axis=0, initial=-np.inf))))  # (ranks, 2, 2)
    low, high = extents[:, 0].min(axis=0), extents[:, 1].max(axis=0)
    p = piece.points[piece.triangles]
    diameters = np.stack([np.linalg.norm(p[:, (i + 1) % 3] - p[:, i], axis=1) for i in range(3)], axis=1).max(axis=1)
    h_min = mpi.allreduce(float(diameters.min(initial=np.inf)), op=MPI.MIN)
    h_max = mpi.allreduce(float(diameters.max(initial=0.0)), op=MPI.MAX)
    force, moment = np.zeros(2), 0.0
    if problem.body_load is not None:  # each triangle's load on its rank only: the sum is the whole body's
        f = problem.body_load.reshape(-1, 2)
        arm = piece.points - centre
        force, moment = f.sum(axis=0), float(np.sum(arm[:, 0] * f[:, 1] - arm[:, 1] * f[:, 0]))
    force = mpi.allreduce(force)
    moment = mpi.allreduce(moment)
    errors = None
    if problem.exact is not None:
        squares = mpi.allreduce(_squared_errors(fields, problem))
        l2, semi, energy = np.sqrt(squares[0]), np.sqrt(squares[1]), np.sqrt(max(squares[2], 0.0))
        errors = {"displacement_l2": float(l2), "displacement_h1_semi": float(semi),
                  "displacement_h1": float(np.hypot(l2, semi)), "displacement_energy": float(energy),
                  "multiplier_l2": None, "multiplier_h_minus_half": None}
    return BodyFigures(nodes=n_total, triangles=fields.n_triangles, h_min=h_min, h_max=h_max, centre=centre,
                       length=float(np.max(high - low)), body_force={"force": force.tolist(), "moment": moment},
                       errors=errors)


def _squared_errors(fields: PieceFields, problem) -> np.ndarray:
    """The squared L2, H1-seminorm and energy errors of this piece's triangles against the exact
    solution, by the quadrature of :func:`contactfem.norms.exact_errors`."""
    from contactfem.assembly import shape_gradients
    from contactfem.norms import _energy_density
    from contactfem.quadrature import TRIANGLE_POINTS, TRIANGLE_WEIGHTS

    exact = problem.exact
    gradients, area = shape_gradients(fields.points, fields.triangles)
    corners = fields.points[fields.triangles]
    u_corners = fields.displacement[fields.triangles]
    grad_h = np.einsum("tia,tib->tab", u_corners, gradients)
    totals = np.zeros(3)
    for weight, bary in zip(TRIANGLE_WEIGHTS, TRIANGLE_POINTS):
        q = np.einsum("i,tia->ta", bary, corners)
        e = exact.displacement(q[:, 0], q[:, 1]) - np.einsum("i,tia->ta", bary, u_corners)
        g = exact.gradient(q[:, 0], q[:, 1]) - grad_h
        totals += weight * np.array([np.sum(area * np.sum(e * e, axis=1)), np.sum(area * np.sum(g * g, axis=(1, 2))),
                                     np.sum(area * _energy_density(g, problem.law))])
    return totals


def _multiplier_l2(solution, problem) -> float:
    """‖λ_exact − λ_h‖ on ΓC (whole on rank 0), as :func:`contactfem.norms.exact_errors` computes it."""
    from contactfem.quadrature import gauss_on_unit_interval

    edges = problem.contact.edges
    points = problem.mesh.points
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    mu = np.zeros(len(points))
    mu[solution.contact.nodes] = solution.contact.multiplier
    total = 0.0
    for s, w in zip(*gauss_on_unit_interval()):
        q = (1 - s) * a + s * b
        difference = problem.exact.pressure(q[:, 0], q[:, 1]) - ((1 - s) * mu[edges[:, 0]] + s * mu[edges[:, 1]])
        total += w * np.sum(length * difference**2)
    return float(np.sqrt(total))


def pieces_accuracy(case, result, energy: dict) -> dict:
    """report.json's ``accuracy`` of a solve kept in pieces: the energy estimate reduced over the
    pieces (:mod:`contactfem.distributed_estimator`) and the contact quantities (from the
    boundary, whole on rank 0) with no coarser level to compare them with (none is kept)."""
    from contactfem.accuracy import quantities, quantity_estimates

    fine = quantities(result.problem, result.solution.contact)
    reason = ("no coarser level is kept on a distributed mesh; the contact quantities' estimates need a "
              "solve in one process (solver.accuracy.levels)")
    return {"energy": energy, "quantities": quantity_estimates(fine, [], reason), "levels": [],
            "cost": {"unknowns": 0, "share_of_unknowns": 0.0, "seconds": float(energy.get("seconds", 0.0)),
                     "share_of_seconds": None}}
