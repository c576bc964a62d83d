"""Studies built on the pipeline: both methods side by side, and convergence with cost.

Nothing here prints or writes; the command line renders the returned dictionaries.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from contactfem.case import Case
from contactfem.discretize import DiscreteProblem
from contactfem.engines import in_order
from contactfem.errors import (
    ArchiveError,
    CaseError,
    ContactFemError,
    FactorCapacityError,
    MeshCapError,
    MeshError,
    OutputError,
    SolverError,
)
from contactfem.methods import METHOD_NAMES
from contactfem.norms import (
    NORM_NAMES,
    exact_errors,
    nested_errors,
    nodal_multiplier,
    observed_rates,
)
from contactfem.report import case_record, contact_zone, sign_conditions
from contactfem.result import Solution
from contactfem.solve import Progress, SolveResult, prepare, solve_case
from contactfem.timings import clock

#: Version of compare.json's layout (contactfem/schemas/compare.schema.json).
COMPARE_SCHEMA_VERSION = 1
#: Version of convergence.json's layout (contactfem/schemas/convergence.schema.json).
CONVERGENCE_SCHEMA_VERSION = 1


def compare_methods(case: Case, *, refine: int | None = None,
                    progress: Progress | None = None) -> tuple[dict, dict[str, SolveResult]]:
    """Solve ``case`` with both methods on one assembled system and measure how they differ.

    Returns the figures (JSON-ready) and the two outcomes.
    """
    timings: dict[str, float] = {}
    problem = prepare(case, refine=refine, progress=progress, timings=timings)
    # The coarse level that predicts the active set is the same for both methods: solved once.
    coarse_levels: dict = {}
    outcomes = {name: solve_case(case, method=name, problem=problem, progress=progress, coarse_levels=coarse_levels)
                for name in METHOD_NAMES}
    positive, standard = outcomes["positive"], outcomes["standard"]
    u, w = positive.solution.displacement, standard.solution.displacement
    lam, theta = positive.solution.contact.multiplier, standard.solution.contact.multiplier
    masses = problem.contact.masses
    pi_theta = (masses.consistent @ theta) / masses.lumped
    contact = problem.contact
    lift_off = ~positive.solution.contact.active
    negative = theta < 0
    scale_u = max(np.abs(u).max(), np.finfo(float).tiny)
    scale_p = max(np.abs(lam).max(), np.finfo(float).tiny)
    gap = contact.gap - positive.solution.contact.normal_displacement
    figures = {
        "schema_version": COMPARE_SCHEMA_VERSION,
        "case": case_record(case),
        "units": case.units.to_dict(),
        "mesh": {"nodes": problem.mesh.n_points, "triangles": problem.mesh.n_triangles,
                 "unknowns": problem.n_unknowns, "contact_nodes": int(len(contact.nodes))},
        "setup_seconds": timings,
        "max_displacement_difference": float(np.abs(u - w).max()),
        "relative_displacement_difference": float(np.abs(u - w).max() / scale_u),
        "max_lambda_minus_pi_theta": float(np.abs(lam - pi_theta).max()),
        "relative_lambda_minus_pi_theta": float(np.abs(lam - pi_theta).max() / scale_p),
        "min_lambda": float(lam.min()) if len(lam) else 0.0,
        "min_theta": float(theta.min()) if len(theta) else 0.0,
        "negative_theta_nodes": int(negative.sum()),
        "negative_theta_positions": problem.mesh.points[contact.nodes[negative]].tolist(),
        "lift_off_nodes": int(lift_off.sum()),
        "theta_total_variation_in_lift_off": _total_variation(theta, lift_off),
        "lambda_total_variation_in_lift_off": _total_variation(lam, lift_off),
        "methods": {name: _method_figures(o) for name, o in outcomes.items()},
        # Per contact node, sorted along ΓC: what compare.png draws (and `contactfem plot` redraws).
        "profiles": {
            "abscissa": contact.abscissa.tolist(),
            "x": problem.mesh.points[contact.nodes, 0].tolist(),
            "y": problem.mesh.points[contact.nodes, 1].tolist(),
            "lambda": lam.tolist(),
            "theta": theta.tolist(),
            "gap": gap.tolist(),
            "active": {name: o.solution.contact.active.astype(bool).tolist() for name, o in outcomes.items()},
        },
    }
    return figures, outcomes


def _method_figures(result: SolveResult) -> dict:
    contact = result.solution.contact
    return {
        "iterations": result.kernel.iterations,
        "solve_seconds": result.timings["solve"],
        "sign_conditions": sign_conditions(result.method, contact.gap, contact.normal_displacement,
                                           contact.multiplier, contact.nodal_force),
        "contact_zone": contact_zone(result.problem, contact.active),
        "contact_force": float(contact.nodal_force.sum()),
    }


def _total_variation(values: np.ndarray, mask: np.ndarray) -> float:
    """Σ |v_{i+1} − v_i| over consecutive contact nodes (along ΓC) that are both in ``mask``."""
    both = mask[:-1] & mask[1:]
    return float(np.abs(np.diff(values))[both].sum()) if len(values) > 1 else 0.0


@dataclass(frozen=True)
class Reference:
    """The nested reference of a convergence study, computed once and read by every level:
    per method its solution and the problem it solved (``solved``), the positive method's
    λ (``multiplier``, λ_ref for both methods) and its refinement of the case's mesh."""

    solved: dict[str, tuple[Solution, DiscreteProblem]]
    multiplier: np.ndarray
    refine: int


def nested_reference(case: Case, refine: int, methods: tuple[str, ...],
                     progress: Progress | None = None) -> Reference:
    """The solutions of ``case`` on its mesh refined ``refine`` times, for each method."""
    problem = prepare(case, refine=refine, progress=progress)
    outcomes = {name: solve_case(case, method=name, problem=problem, progress=progress) for name in methods}
    positive = outcomes.get("positive") or solve_case(case, method="positive", problem=problem)
    # What nested_errors reads of a problem; the loads and the exact solution may hold
    # compiled expressions, which do not travel to other processes.
    solved = {name: (o.solution, replace(o.problem, loads=None, exact=None, mesh_request=None))
              for name, o in outcomes.items()}
    return Reference(solved=solved, multiplier=nodal_multiplier(positive.solution), refine=refine)


def study_level(task: dict, reference: Reference | None, progress: Progress | None = None) -> dict:
    """One level of a convergence study (``task``: the case's ``text``, ``source`` and
    ``digest``, the ``index`` of the level, its ``refine`` and the ``methods``), wherever the
    engine runs it: its rows without the estimates that need the other levels, the energy
    estimate and contact quantities of each method, and the solutions; or the ``failure``
    ``(kind, message)`` that stopped it (kind: the name of a ContactFemError class, or
    ``"memory"``), so that the caller raises the same kind of error naming the level.
    ``progress``: the stages of its mesh and solves, when it runs in the caller's process."""
    from contactfem.accuracy import energy_estimate, quantities
    from contactfem.case import parse_case
    from contactfem.engines import worker_budget

    level = task["index"]
    if progress is not None:
        progress(f"level {level} of {task['levels'] - 1}")
    detail = None if progress is None else (lambda message: progress("  " + message.strip()))
    try:
        case = parse_case(task["text"], source=task["source"])
        if case.digest != task["digest"]:
            files = ", ".join(path.name for path in case.data_files)
            raise CaseError(f"{Path(task['source']).name}: a data file it reads ({files}) changed during the study")
        timings: dict[str, float] = {}
        started = clock()
        with worker_budget():
            problem = prepare(case, refine=task["refine"], timings=timings, progress=detail)
            setup = clock() - started
            rows, energy, contact, solutions = [], {}, {}, {}
            for name in task["methods"]:
                outcome = solve_case(case, method=name, problem=problem, progress=detail)
                if problem.exact is not None:
                    errors = exact_errors(outcome.solution, problem, problem.exact)
                else:
                    solution, fine = reference.solved[name]
                    errors = nested_errors(outcome.solution, solution, fine, levels=reference.refine - task["refine"],
                                           reference_multiplier=reference.multiplier)
                rows.append({
                    "level": level,
                    "method": name,
                    "h": float(problem.mesh.triangle_diameters().max()),
                    "unknowns": problem.n_unknowns,
                    "contact_nodes": int(len(problem.contact.nodes)),
                    "iterations": outcome.kernel.iterations,
                    "mesh_seconds": timings["mesh"],
                    "assemble_seconds": timings["assemble"],
                    "solve_seconds": outcome.timings["solve"],
                    "total_seconds": setup + outcome.timings["solve"] + outcome.timings["postprocess"],
                    **errors,
                })
                energy[name] = energy_estimate(outcome)
                contact[name] = quantities(outcome.problem, outcome.solution.contact)
                solutions[name] = outcome.solution
    except ContactFemError as error:
        return {"level": level, "failure": (type(error).__name__, str(error))}
    except MemoryError:
        return {"level": level, "failure": ("memory", "out of memory while solving this level")}
    return {"level": level, "rows": rows, "energy": energy, "quantities": contact, "solutions": solutions}


#: A level's failure is raised as the nearest of these to its own kind (the exit code follows it).
_FAILURE_KINDS = (MeshCapError, MeshError, CaseError, ArchiveError, FactorCapacityError, SolverError, OutputError)


def _level_failure(level: int, refine: int, kind: str, message: str) -> ContactFemError:
    """The error of a level that did not solve, naming it; of the kind the level raised."""
    where = f"converge level {level} (refine {refine})"
    if kind == "memory":
        return FactorCapacityError(f"{where}: {message}; use fewer levels, or give each worker more memory")
    found = next((k for k in _FAILURE_KINDS if k.__name__ == kind), None)
    if found is MeshCapError or found is None:
        found = MeshError if found is MeshCapError else ContactFemError
    return found(f"{where}: {message}")


def _estimated(fine: dict, energy: dict, earlier: list) -> dict:
    """A level's estimated errors, as a solve's report.json gives them (none a bound): η and
    η / ‖u_h‖_a, and each contact quantity's Richardson estimate from the study's previous
    two levels (h twice and four times as large, for nothing); ``earlier`` gains this level
    (its unknowns and quantities: ``fine``)."""
    from contactfem.accuracy import Level, quantity_estimates

    levels = [Level(ratio=2.0 ** (len(earlier) - j), unknowns=unknowns, source="earlier step", quantities=values)
              for j, (unknowns, values) in reversed(list(enumerate(earlier)))][:2]
    estimates = quantity_estimates(fine["quantities"], levels, "no earlier mesh to compare with")
    earlier.append((fine["unknowns"], fine["quantities"]))
    return {"estimated_energy": energy["estimate"], "estimated_energy_relative": energy.get("relative"),
            **{f"estimated_{name}": entry["estimate"] for name, entry in estimates.items()}}


def convergence_study(
    case: Case,
    levels: int,
    *,
    extra: int = 1,
    methods: tuple[str, ...] = METHOD_NAMES,
    progress: Progress | None = None,
    on_solution=None,
    engine=None,
) -> dict:
    """Solve on ``levels`` nested meshes (the case's mesh refined 0 … levels−1 times).

    The reference is the case's exact solution when it has one, otherwise the solution on
    the mesh ``extra`` refinements finer than the last level (its positive-method λ is
    λ_ref for both methods), computed once here and shared with every level. The levels are
    tasks of ``engine`` (:mod:`contactfem.engines`; default: this process, one after another)
    and are put back in level order, so the figures do not depend on where they ran. Each
    row carries h, unknowns, seconds per stage, Newton iterations and every error norm;
    ``rates`` holds the observed rate between levels. ``on_solution(level, method,
    solution)`` receives every level's solution, in order. Each level validates the case's
    text (``case.text``) again, as a worker must: a case changed after it was parsed is
    solved as its text says.

    Raises
    ------
    ContactFemError
        Of the kind the failing level raised, naming the level.
    """
    from contactfem.engines import SerialEngine

    engine = engine if engine is not None else SerialEngine()
    say = progress or (lambda message: None)
    base_refine = case.mesh.refine
    reference = None
    if case.exact is None:  # no exact solution: the reference is a finer nested solve
        say(f"reference: {extra} refinement(s) beyond the last level")
        reference = nested_reference(case, base_refine + levels - 1 + extra, methods,
                                     progress=lambda message: say("  " + message.strip()))
    tasks = [{"index": level, "levels": levels, "refine": base_refine + level, "methods": tuple(methods),
              "text": case.text,
              "source": str(Path(case.source).absolute()), "digest": case.digest} for level in range(levels)]

    def lost(task: dict, reason: str) -> dict:
        return {"level": task["index"], "failure": ("SolverError", reason)}

    finished_levels: dict[int, dict] = {}

    def finished(task: dict, value: dict, done: int, total: int) -> None:
        finished_levels[task["index"]] = value
        if "failure" in value:
            say(f"[{done}/{total}] level {task['index']}: failed, {value['failure'][1]}")
        else:
            # In this process the level's own stages came first: its rows are their details.
            where = "  " if engine.kind == "serial" else f"[{done}/{total}] "
            for row in value["rows"]:
                say(f"{where}level {row['level']} {row['method']}: h = {row['h']:.4g}, {row['unknowns']} "
                    f"unknowns, H1 error {row['displacement_h1']:.3e}, {row['total_seconds']:.2f} s")
        # The study stops at its lowest failing level, as one run after another would: once
        # every level below a failure has finished (the levels still running are cancelled).
        failed = min((level for level, v in finished_levels.items() if "failure" in v), default=None)
        if failed is not None and all(level in finished_levels for level in range(failed)):
            raise _level_failure(failed, base_refine + failed, *finished_levels[failed]["failure"])

    with engine.shared(reference) as shared:
        # Run here, a level reports its stages as it goes; a worker's would not reach this terminal.
        level = study_level if engine.kind != "serial" or progress is None else (
            lambda task, reference: study_level(task, reference, progress=say))
        results = in_order(engine, level, tasks, shared, lost=lost, name="level", progress=finished)
    rows = []
    earlier: dict[str, list] = {name: [] for name in methods}  # (unknowns, quantities) per level
    for result in results:
        for row in result["rows"]:
            name = row["method"]
            fine = {"unknowns": row["unknowns"], "quantities": result["quantities"][name]}
            rows.append({**row, **_estimated(fine, result["energy"][name], earlier[name])})
            if on_solution is not None:
                on_solution(result["level"], name, result["solutions"][name])
    rates = {}
    for name in methods:
        mine = [r for r in rows if r["method"] == name]
        h = [r["h"] for r in mine]
        rates[name] = {
            # A rate is undefined where an error is zero or not finite (an unloaded body: u = 0
            # on every mesh): null, not NaN.
            norm: [float(v) if np.isfinite(v) else None for v in observed_rates(h, [r[norm] for r in mine])]
            for norm in NORM_NAMES
        }
    warnings = []
    if case.exact is None and extra == 1 and levels > 1:
        # The reference's own error is then about 2^-p times the last level's: the last
        # level's error is underestimated and the rate ending there comes out too high.
        warnings.append("the reference is only one refinement finer than the last level, so the last level's "
                        "errors are underestimated and the last observed rates are biased high; rerun with "
                        "--extra 2 (or more) to check them")
    return {
        "schema_version": CONVERGENCE_SCHEMA_VERSION,
        "case": case_record(case),
        "units": case.units.to_dict(),
        "reference": "exact" if case.exact is not None else f"nested, {extra} refinement(s) finer",
        "reference_extra": None if case.exact is not None else extra,
        "levels": levels,
        "rows": rows,
        "rates": rates,
        "warnings": warnings,
    }
