"""Studies built on the pipeline: both methods side by side, and convergence with cost.

Nothing here prints or writes; the command line renders the returned dictionaries.
"""

from __future__ import annotations

import time

import numpy as np

from contactfem.case import Case
from contactfem.methods import METHOD_NAMES
from contactfem.norms import (
    NORM_NAMES,
    exact_errors,
    nested_errors,
    nodal_multiplier,
    observed_rates,
)
from contactfem.report import case_record, contact_zone, sign_conditions
from contactfem.solve import Progress, SolveResult, prepare, solve_case

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


def _estimates(case: Case, outcome, earlier: list) -> dict:
    """A level's estimated errors, as a solve's report.json gives them (none a bound): η and
    η / ‖u_h‖_a, and each contact quantity's Richardson estimate from the study's previous
    two levels (h twice and four times as large, for nothing); ``earlier`` gains this level."""
    from contactfem.accuracy import Level, accuracy_figures, quantities

    levels = [Level(ratio=2.0 ** (len(earlier) - j), unknowns=unknowns, source="earlier step", quantities=values)
              for j, (unknowns, values) in reversed(list(enumerate(earlier)))][:2]
    figures = accuracy_figures(case, outcome, history=levels)
    earlier.append((outcome.problem.n_unknowns, quantities(outcome.problem, outcome.solution.contact)))
    energy = figures["energy"]
    return {"estimated_energy": energy["estimate"], "estimated_energy_relative": energy.get("relative"),
            **{f"estimated_{name}": entry["estimate"] for name, entry in figures["quantities"].items()}}


def convergence_study(
    case: Case,
    levels: int,
    *,
    extra: int = 1,
    methods: tuple[str, ...] = METHOD_NAMES,
    progress: Progress | None = None,
    on_outcome=None,
) -> dict:
    """Solve on ``levels`` nested meshes (the case's mesh refined 0 … levels−1 times).

    The reference is the case's exact solution when it has one, otherwise the solution on
    the mesh ``extra`` refinements finer than the last level (its positive-method λ is
    λ_ref for both methods). Each row carries h, unknowns, seconds per stage, Newton
    iterations and every error norm; ``rates`` holds the observed rate between levels.
    """
    say = progress or (lambda message: None)

    def detail(message: str) -> None:
        say("  " + message.strip())

    base_refine = case.mesh.refine
    reference = None
    if case.exact is None:  # no exact solution: the reference is a finer nested solve
        finest = base_refine + levels - 1 + extra
        say(f"reference: {extra} refinement(s) beyond the last level")
        reference_problem = prepare(case, refine=finest, progress=detail)
        reference = {
            name: solve_case(case, method=name, problem=reference_problem, progress=detail) for name in methods
        }
        reference_lambda = nodal_multiplier(
            (reference.get("positive") or solve_case(case, method="positive", problem=reference_problem)).solution
        )
    rows = []
    earlier: dict[str, list] = {name: [] for name in methods}  # (unknowns, quantities) per level
    for level in range(levels):
        timings: dict[str, float] = {}
        started = time.perf_counter()
        say(f"level {level} of {levels - 1}")
        problem = prepare(case, refine=base_refine + level, timings=timings, progress=detail)
        setup = time.perf_counter() - started
        for name in methods:
            outcome = solve_case(case, method=name, problem=problem, progress=detail)
            if on_outcome is not None:  # on_outcome(level, method, outcome), e.g. to keep the fields
                on_outcome(level, name, outcome)
            if problem.exact is not None:
                errors = exact_errors(outcome.solution, problem, problem.exact)
            else:
                errors = nested_errors(
                    outcome.solution, reference[name].solution, reference[name].problem,
                    levels=finest - base_refine - level, reference_multiplier=reference_lambda,
                )
            row = {
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
                **_estimates(case, outcome, earlier[name]),
            }
            rows.append(row)
            detail(f"level {level} {name}: h = {row['h']:.4g}, {row['unknowns']} unknowns, "
                   f"H1 error {row['displacement_h1']:.3e}, {row['total_seconds']:.2f} s")
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
