"""Mesh sequencing's coarse levels as the pipeline uses them: which coarser level to make,
how its solution predicts the fine active set, and the correction of that prediction in a
layer along ΓC.

The decisions (:func:`contactfem.sequencing.coarse_level_pays` and its kin) count unknowns;
the levels are made and solved through callables, so that the same code serves a serial
solve (:mod:`contactfem.solve`) and one across MPI ranks (:mod:`contactfem.distributed`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from contactfem.discretize import DiscreteProblem
from contactfem.discretize.frames import ReducedSystem
from contactfem.discretize.meshing import MeshRequest, estimate_triangles
from contactfem.errors import ContactFemError, SolverError
from contactfem.kernel import KernelResult, Status, solve_contact
from contactfem.mesh import Mesh
from contactfem.mesh.transfer import interpolate_p1
from contactfem.result import ContactFields
from contactfem.sequencing import (
    LAYER_SAMPLES,
    coarse_level_pays,
    coarser,
    contact_layer,
    layer_depth,
    layer_pays,
    patch_count,
    predict_active_set,
    worth_sequencing,
)
from contactfem.timings import clock

Progress = Callable[[str], None]


@dataclass(frozen=True, eq=False)
class CoarseSolve:
    """What a coarse level hands the prediction: its contact fields and its solve's account,
    and its mesh and displacement where the fine level corrects the prediction in a layer
    along ΓC (a serial solve; None across MPI ranks)."""

    contact: ContactFields
    kernel: KernelResult
    sequencing: Mapping
    mesh: Mesh | None = None
    displacement: np.ndarray | None = None
    #: Whether an earlier solve of the same fine problem meshed and solved this level.
    reused: bool = False


def correct_in_layer(reduced: ReducedSystem, coarse: CoarseSolve, active: np.ndarray, c: float, tolerance: float,
                     max_iterations: int | None, backend: str) -> tuple[np.ndarray, dict]:
    """The predicted ``active`` set corrected on the fine mesh in a layer along ΓC, and what
    that cost; ``active`` itself (and an empty record) when the layer is not expected to
    pay (:func:`contactfem.sequencing.layer_pays`) or its solve fails.

    A coarse level that decimated a rough profile, or whose elements are wider than the
    asperities, misplaces the fine zone at asperity scale, while further from ΓC its
    solution is right. So the fine system is solved, with contact, on the nodes within
    :func:`contactfem.sequencing.layer_depth` of ΓC, every unknown outside fixed at the
    coarse displacement; its active set is the fine prediction.
    """
    started = clock()
    problem = reduced.problem
    fine_unknowns = problem.n_unknowns
    patches = patch_count(active)
    if coarse.mesh is None or coarse.displacement is None or not layer_pays(fine_unknowns, 0, patches):
        return active, {}
    points, boundary = problem.mesh.points, problem.mesh.points[problem.contact.nodes]
    depth = layer_depth(problem.mesh)
    # The layer's share from an even sample of the nodes first: on a mesh graded onto ΓC
    # it is most of the mesh, and finding every node of it would be wasted. Near an even
    # sample of the contact nodes is within the layer too: that lower bound refuses such a
    # mesh without a search among all of them.
    sample = points[::max(1, len(points) // LAYER_SAMPLES)]
    few = boundary[::max(1, len(boundary) // LAYER_SAMPLES)]
    for nearby in (few, boundary) if len(few) < len(boundary) else (boundary,):
        share = float(contact_layer(sample, nearby, depth).mean())
        if not layer_pays(fine_unknowns, int(0.9 * share * fine_unknowns), patches):
            return active, {}
    nodes = contact_layer(points, boundary, depth)
    keep = np.repeat(nodes, 2)
    if not layer_pays(fine_unknowns, int(keep.sum()), patches):
        return active, {}
    system = reduced.system
    outside = system.coupled_outside(keep)
    if len(outside) == 0:
        return active, {}  # the layer is the whole body: nothing to gain
    rim = np.unique(outside // 2)
    displacement = np.zeros((problem.mesh.n_points, 2))
    displacement[rim] = interpolate_p1(coarse.mesh, coarse.displacement, problem.mesh.points[rim])
    layer = system.restricted(keep, reduced.reduce(displacement.ravel()))
    try:
        result = solve_contact(layer, c=c, initial_active=active, tolerance=tolerance,
                               max_iterations=max_iterations, backend=backend)
    except SolverError:
        return active, {}
    # A set that settled is a prediction whether or not its iterate passes the certificate.
    if result.status not in (Status.CONVERGED, Status.NOT_CERTIFIED):
        return active, {}
    return result.active, {
        "layer_unknowns": int(keep.sum()),
        "layer_iterations": result.iterations,
        "layer_factorizations": result.factorizations,
        "layer_changes": int(np.count_nonzero(result.active != active)),
        "layer_seconds": clock() - started,
    }


def coarser_level(problem: DiscreteProblem, prepare_coarse: Callable[[MeshRequest, int], DiscreteProblem],
                  forced: bool = False, coarse: tuple[MeshRequest, int] | None = None) -> DiscreteProblem | None:
    """The coarser level that predicts ``problem``'s active set (its problem, from
    ``prepare_coarse`` on the coarser mesh request that :func:`contactfem.sequencing.coarser`
    derives from ``problem.mesh_request``), or None when the problem is small, no coarser
    mesh exists, the mesher or the contact checks refuse the decimated boundary, or the level
    is not expected to pay for itself (:func:`contactfem.sequencing.coarse_level_pays`,
    decided before it is meshed from an estimate of its unknowns, and again from them once
    it is). ``forced``: whatever the size and the cost model (a cold start that stalled), as
    long as the coarser mesh is smaller. ``coarse``: the coarser request and its
    refinements, when already made."""
    if not forced and not worth_sequencing(problem.n_unknowns):
        return None
    coarse = coarser(problem.mesh_request, problem.refinements) if coarse is None else coarse
    if coarse is None:
        return None
    request, coarse_refine = coarse
    if not forced and not meshing_pays(problem, request, coarse_refine):
        return None  # not worth meshing: a boundary that cannot be decimated (a tread's teeth)
    try:
        coarse_problem = prepare_coarse(request, coarse_refine)
    except ContactFemError:
        return None
    if not (coarse_level_pays(problem.n_unknowns, coarse_problem.n_unknowns)
            or forced and coarse_problem.n_unknowns < problem.n_unknowns):
        return None
    return coarse_problem


def meshing_pays(problem: DiscreteProblem, request: MeshRequest, coarse_refine: int) -> bool:
    """Whether the coarser level ``request`` is worth meshing: the cost model, meshing
    included, on its :func:`estimated_unknowns`."""
    return coarse_level_pays(problem.n_unknowns, estimated_unknowns(problem, request, coarse_refine), meshed=False)


def estimated_unknowns(problem: DiscreteProblem, request: MeshRequest, coarse_refine: int) -> int:
    """The coarser level's unknowns before it is meshed: ``problem``'s in the ratio of the two
    meshes' estimated triangles (:func:`contactfem.discretize.meshing.estimate_triangles`);
    a sixteenth where nothing is estimated."""
    fine = estimate_triangles(problem.mesh_request, problem.refinements)
    coarse = estimate_triangles(request, coarse_refine)
    if fine <= 0 or coarse <= 0:
        return problem.n_unknowns // 16
    return int(problem.n_unknowns * min(coarse / fine, 1.0))


def predict_from_coarser(problem: DiscreteProblem, c: Callable[[], float], say: Progress,
                         prepare_coarse: Callable[[MeshRequest, int], DiscreteProblem],
                         solve_coarse: Callable[[DiscreteProblem], CoarseSolve],
                         correct: Callable[[CoarseSolve, np.ndarray], tuple[np.ndarray, dict]] | None = None,
                         forced: bool = False, coarse: tuple[MeshRequest, int] | None = None,
                         ) -> tuple[np.ndarray | None, dict]:
    """Mesh sequencing with the given ways to assemble and solve the coarse level (in this
    process, or across MPI ranks), and optionally to ``correct`` its prediction on the
    fine mesh: the predicted active set and what it cost. ``c`` gives the fine kernel's c,
    asked for once the coarse level has solved.

    (None, {}) when there is no :func:`coarser_level` (``forced``: see there) or solving it
    fails: a prediction is only a starting point, and without one the kernel starts cold.
    ``coarse``: the coarser mesh request and its refinements, when already made (:func:`coarser`).
    """
    started = clock()
    coarse_problem = coarser_level(problem, prepare_coarse, forced, coarse)
    if coarse_problem is None:
        return None, {}
    try:
        coarse_result = solve_coarse(coarse_problem)
    except SolverError:
        return None, {}
    coarse_kernel = coarse_result.kernel
    settled = coarse_kernel.status is Status.CONVERGED
    # A coarse level that stopped unsettled (its own cap, a cycle) still predicts, if its last
    # iterate is finite: a prediction is only a start, which the fine level corrects and
    # certifies. A thin strip peeling off, whose one-cell-across level creeps past its own
    # cap, would otherwise go on cold, where its creeping zone takes a step per node.
    if not settled and not (forced and np.isfinite(coarse_kernel.displacement).all()
                            and np.isfinite(coarse_kernel.multiplier).all()):
        return None, {}
    active = predict_active_set(problem.contact, coarse_result.contact, c(), problem.law)
    say(f"  predicted {int(active.sum())} active nodes from {coarse_problem.n_unknowns} unknowns")
    corrected: dict = {}
    if correct is not None:
        active, corrected = correct(coarse_result, active)
        if corrected:
            say(f"  corrected {corrected['layer_changes']} of them in a layer of {corrected['layer_unknowns']} "
                "unknowns along the contact boundary")
    return active, {
        "coarse_unknowns": coarse_problem.n_unknowns,
        "coarse_iterations": coarse_result.kernel.iterations,
        "coarse_factorizations": coarse_result.kernel.factorizations,
        "predicted_active": int(active.sum()),
        "levels": 1 + coarse_result.sequencing.get("levels", 0),
        **({} if settled else {"coarse_status": coarse_kernel.status.value}),
        **({"coarse_reused": True} if coarse_result.reused else {}),
        **corrected,
        "seconds": clock() - started,
    }
