"""The adaptive loop SOLVE → ESTIMATE → MARK → REFINE for method (4), and errors against a
non-nested reference solution.

Each step solves the case on the current mesh (:func:`contactfem.solve.solve_case` with
a problem built by :func:`contactfem.discretize.build_problem`), computes the residual
estimator of :mod:`contactfem.estimator`, marks by Dörfler's bulk criterion with θ and
refines by newest-vertex bisection (:mod:`contactfem.mesh.adapt`), until η ≤ target, the
next mesh would exceed the unknowns budget, the time budget is spent or the step cap is hit.
Nothing here prints or writes; the command line renders :class:`AdaptiveRun`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from contactfem.case import Case
from contactfem.discretize import DiscreteProblem, build_mesh, build_problem
from contactfem.estimator import Estimate, estimate
from contactfem.mesh import Mesh
from contactfem.mesh.adapt import bisect, dorfler_mark, label_longest_edge, min_angle
from contactfem.mesh.core import coordinate_span
from contactfem.mesh.transfer import interpolate_p1
from contactfem.norms import exact_errors
from contactfem.report import case_record
from contactfem.result import Solution
from contactfem.solve import Progress, SolveResult, solve_case
from contactfem.timings import clock

#: Version of adapt.json's layout (contactfem/schemas/adapt.schema.json).
ADAPT_SCHEMA_VERSION = 1

#: error_of(problem, solution) -> {"displacement_energy": ..., ...}
ErrorFunction = Callable[[DiscreteProblem, Solution], dict]


@dataclass(frozen=True, eq=False)
class AdaptiveRun:
    """The history (one JSON-ready dict per step), the last solve and its estimate.

    ``result``'s solution carries η_T as the cell field ``error_indicator``.
    """

    case: Case
    steps: list[dict]
    result: SolveResult
    estimate: Estimate
    stop_reason: str
    settings: dict = field(default_factory=dict)

    def history(self) -> dict:
        """adapt.json's content."""
        case = self.case
        return {
            "schema_version": ADAPT_SCHEMA_VERSION,
            "case": case_record(case),
            "units": case.units.to_dict(),
            "method": "positive",
            "estimator": "residual (Hild & Nicaise), energy-norm scaled; see contactfem/estimator.py",
            "settings": self.settings,
            "stop_reason": self.stop_reason,
            "steps": self.steps,
        }


def with_estimator(result: SolveResult, estimated: Estimate) -> SolveResult:
    """The result whose solution carries η_T as the cell field ``error_indicator``."""
    solution = replace(result.solution, cell_fields={**result.solution.cell_fields,
                                                     "error_indicator": estimated.indicators})
    return replace(result, solution=solution)


def adapt(
    case: Case,
    *,
    theta: float = 0.5,
    target: float | None = None,
    max_unknowns: int | None = None,
    max_seconds: float | None = None,
    max_steps: int = 60,
    mesh: Mesh | None = None,
    error_of: ErrorFunction | None = None,
    on_step: Callable[[dict, DiscreteProblem, Solution], None] | None = None,
    converged: Callable[[dict], bool] | None = None,
    also_mark: Callable[[DiscreteProblem, Solution], np.ndarray] | None = None,
    theta_of: Callable[[dict], float] | None = None,
    progress: Progress | None = None,
) -> AdaptiveRun:
    """Adaptive refinement of ``case`` from ``mesh`` (default: the case's own mesh).

    Each step records unknowns, triangles, h_min/h_max, the smallest angle, η and its
    terms, the marked triangles, seconds (this step: assemble, solve, estimate, mark,
    refine; and cumulative) and, when the case has an exact solution or ``error_of`` is
    given, the true energy error and the effectivity index η / error. ``on_step(row,
    problem, solution)`` sees every step (e.g. to keep its mesh and solution).
    """
    say = progress or (lambda message: None)
    if not 0.0 < theta <= 1.0:
        raise ValueError(f"theta must be in (0, 1], got {theta!r}")
    started = clock()
    stage_started = clock()
    current = label_longest_edge(mesh if mesh is not None else build_mesh(case))
    problem = build_problem(case, current)
    pending = clock() - stage_started  # meshing/refining/assembling charged to the next step
    steps: list[dict] = []
    stop = "max_steps"
    for step in range(max_steps):
        stage_started = clock()
        outcome = solve_case(case, method="positive", problem=problem)
        estimated = estimate(problem, outcome.solution)
        seconds = pending + clock() - stage_started
        errors = _errors(outcome, error_of)
        energy = errors.get("displacement_energy") if errors else None
        mesh_now = problem.mesh
        diameters = mesh_now.triangle_diameters()
        row = {
            "step": step,
            "unknowns": problem.n_unknowns,
            "triangles": mesh_now.n_triangles,
            "contact_nodes": int(len(problem.contact.nodes)),
            "h_min": float(diameters.min()),
            "h_max": float(diameters.max()),
            "min_angle": min_angle(mesh_now),
            "newton_iterations": outcome.kernel.iterations,
            "eta": estimated.total,
            "eta_terms": estimated.summary()["terms"],
            "seconds": seconds,
            "cumulative_seconds": clock() - started,
            "errors": errors,
            "effectivity": (estimated.total / energy) if energy else None,
        }
        steps.append(row)
        if on_step is not None:
            on_step(row, problem, outcome.solution)
        say(f"step {step}: {row['unknowns']} unknowns, eta {estimated.total:.4g}"
            + (f", energy error {energy:.4g} (effectivity {row['effectivity']:.3g})" if energy else "")
            + f", {seconds:.2f} s")
        if (target is not None and estimated.total <= target) or (converged is not None and converged(row)):
            stop = "target"
            break
        if max_seconds is not None and clock() - started >= max_seconds:
            stop = "max_seconds"
            break
        if step == max_steps - 1:
            break
        stage_started = clock()
        # A run towards another quantity's target may mark a share of η² that depends on
        # where it stands (its row, after on_step): ``theta_of``.
        marked = dorfler_mark(estimated.indicators**2, theta if theta_of is None else theta_of(row))
        if also_mark is not None:
            marked = marked | also_mark(problem, outcome.solution)
        refined = bisect(mesh_now, marked)
        next_problem = build_problem(case, refined)
        if max_unknowns is not None and next_problem.n_unknowns > max_unknowns:
            stop = "max_unknowns"
            break
        row["marked"] = int(marked.sum())
        problem = next_problem
        pending = clock() - stage_started
    settings = {"theta": theta, "target": target, "max_unknowns": max_unknowns,
                "max_seconds": max_seconds, "max_steps": max_steps}
    return AdaptiveRun(case=case, steps=steps, result=with_estimator(outcome, estimated), estimate=estimated,
                       stop_reason=stop, settings=settings)


def _errors(outcome: SolveResult, error_of: ErrorFunction | None) -> dict | None:
    """The true errors of a step: ``error_of``'s, or against the problem's exact solution."""
    if error_of is not None:
        return error_of(outcome.problem, outcome.solution)
    if outcome.problem.exact is None:
        return None
    errors = exact_errors(outcome.solution, outcome.problem, outcome.problem.exact)
    return {name: (float(value) if np.isfinite(value) else None) for name, value in errors.items()}


class Reference:
    """A fine reference solution to measure errors of solutions on other meshes.

    The error of u_h is measured on the reference mesh: u_h is evaluated at the
    reference nodes by point location in its own mesh (P1 interpolation, linear
    extrapolation from the nearest triangle for nodes outside it, e.g. on a curved part),
    e = u_ref − I u_h, and ‖e‖_a = (eᵀ K_ref e)^{1/2}, ‖e‖_{L²} with the reference mass
    matrix. This is exact when the reference mesh refines u_h's mesh (nested meshes,
    e.g. NVB meshes no deeper than an NVB-uniform reference of the same initial mesh);
    otherwise it adds the interpolation error of u_h on the reference mesh.
    """

    def __init__(self, problem: DiscreteProblem, solution: Solution) -> None:
        from contactfem.assembly import mass_matrix, vector_form

        self.problem = problem
        self.solution = solution
        mesh = problem.mesh
        self.mass = vector_form(mass_matrix(mesh.points, mesh.triangles))

    def errors(self, problem: DiscreteProblem, solution: Solution) -> dict:
        values = interpolate_p1(solution.mesh, solution.displacement, self.problem.mesh.points)
        error = (self.solution.displacement - values).ravel()
        energy = float(np.sqrt(max(error @ (self.problem.stiffness @ error), 0.0)))
        l2 = float(np.sqrt(max(error @ (self.mass @ error), 0.0)))
        return {"displacement_energy": energy, "displacement_l2": l2}

    def overlay_errors(self, problem: DiscreteProblem, solution: Solution) -> dict:
        """Like :meth:`errors`, exactly also where ``solution``'s mesh is finer than the reference.

        Both meshes must be NVB refinements of one labelled initial mesh: the reference mesh
        is bisected until it holds every node of the other (their common refinement), both
        P1 fields are interpolated exactly onto it and the norms are taken there.
        """
        from contactfem.assembly import mass_matrix, stiffness_matrix, vector_form

        common = common_refinement(self.problem.mesh, solution.mesh)
        if common.n_points == self.problem.mesh.n_points:
            return self.errors(problem, solution)
        fine = interpolate_p1(self.problem.mesh, self.solution.displacement, common.points)
        coarse = interpolate_p1(solution.mesh, solution.displacement, common.points)
        error = (fine - coarse).ravel()
        stiffness = stiffness_matrix(common.points, common.triangles, self.problem.law)
        mass = vector_form(mass_matrix(common.points, common.triangles))
        return {"displacement_energy": float(np.sqrt(max(error @ (stiffness @ error), 0.0))),
                "displacement_l2": float(np.sqrt(max(error @ (mass @ error), 0.0)))}


def common_refinement(mesh: Mesh, other: Mesh, *, max_rounds: int = 200) -> Mesh:
    """Bisect ``mesh`` until every node of ``other`` is one of its nodes (NVB meshes of one
    labelled initial mesh: the result is their coarsest common refinement)."""
    from matplotlib.tri import Triangulation
    from scipy.spatial import cKDTree

    scale = float(coordinate_span(mesh.points).max())
    for _ in range(max_rounds):
        distance, _ = cKDTree(mesh.points).query(other.points)
        missing = other.points[distance > 1e-12 * scale]
        if len(missing) == 0:
            return mesh
        triangulation = Triangulation(mesh.points[:, 0], mesh.points[:, 1], mesh.triangles)
        found = np.asarray(triangulation.get_trifinder()(missing[:, 0], missing[:, 1]))
        found = found[found >= 0]
        if found.size == 0:
            raise ValueError("the other mesh has nodes outside this one: not a common NVB family")
        marked = np.zeros(mesh.n_triangles, dtype=bool)
        marked[found] = True
        mesh = bisect(mesh, marked, check=False)
    raise ValueError("no common refinement found: the meshes are not NVB refinements of one mesh")
