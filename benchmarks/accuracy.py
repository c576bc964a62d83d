"""Ask for accuracy, get it at the least cost: a run towards a target against uniform refinement.

Usage: python benchmarks/accuracy.py [--out FILE.json] [--only NAME ...]

For each case, ``solve_to_accuracy`` (contactfem solve --accuracy) refines from the case's
mesh where the estimator says until the estimated relative error of the named quantity
meets the target; the table gives what it reached, estimated and true, its unknowns and
seconds. The true error is against a closed form (plane-strain Hertz's half-width at the
run's own force; the manufactured case's exact energy error, relative to the exact energy
norm) or against a reference value: the quantity Richardson-extrapolated from three uniform
refinements of the case's mesh (observed order). Uniform refinement (the case's mesh refined
by halving every edge, ``--refine K``, each level solved on its own with sequencing) is run
until its true error is at most the targeted run's, or its next level would pass
UNIFORM_MAX unknowns; the table gives the first level that reached it, or the last tried.
So is the one mesh knob on the graded cases: contact_size halved, the grading following it.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from contactfem.accuracy import observed_order, quantities
from contactfem.accuracy_target import solve_to_accuracy
from contactfem.case import load_case
from contactfem.norms import exact_errors
from contactfem.solve import prepare, solve_case
from contactfem.validation import hertz_comparison

ROOT = Path(__file__).resolve().parents[1]
#: Uniform refinement stops before a mesh of more unknowns.
UNIFORM_MAX = 1_200_000


def hertz_case():
    """The quarter Hertz disk without its grading key (the rule's grading) at contact_size 0.004."""
    case = load_case(ROOT / "cases" / "hertz_quarter.yaml")
    return replace(case, mesh=replace(case.mesh, grading_key=None, contact_size=0.004))


def hertz_truth(outcome) -> float:
    """Plane-strain Hertz's half-width at the solve's own force."""
    return hertz_comparison(outcome, radius=1.0, symmetry_axis=0.0)["half_width"]


def energy_truth(outcome) -> tuple[float, float]:
    """The exact energy error and the exact energy norm (‖u_h‖_a + error bounds it within 1%)."""
    problem = outcome.problem
    error = float(exact_errors(outcome.solution, problem, problem.exact)["displacement_energy"])
    u = outcome.solution.displacement.ravel()
    return error, float(np.sqrt(u @ (problem.stiffness @ u)))


STUDIES = {
    "hertz": {"case": hertz_case, "quantity": "contact_width", "target": 0.005, "truth": "closed form"},
    "flat_punch": {"case": lambda: load_case(ROOT / "cases" / "flat_punch.yaml"), "quantity": "contact_force",
                   "target": 0.005, "truth": "reference"},
    "rough": {"case": lambda: load_case(ROOT / "cases" / "rough.yaml"), "quantity": "contact_force",
              "target": 0.005, "truth": "reference"},
    "manufactured": {"case": lambda: load_case(ROOT / "cases" / "manufactured.yaml"), "quantity": "energy",
                     "target": 0.02, "truth": "closed form"},
}


def true_error(name: str, study: dict, outcome, reference: float | None) -> float:
    """The relative true error of the study's quantity on ``outcome``."""
    if study["quantity"] == "energy":
        error, norm = energy_truth(outcome)
        return error / norm
    value = quantities(outcome.problem, outcome.solution.contact)[study["quantity"]]
    exact = hertz_truth(outcome) if name == "hertz" else reference
    return abs(value - exact) / abs(exact)


def uniform(case, levels: range) -> list[dict]:
    """The case solved at each uniform refinement in ``levels`` (stopping before UNIFORM_MAX)."""
    rows = []
    for refine in levels:
        started = time.perf_counter()
        problem = prepare(case, refine=refine)
        if problem.n_unknowns > UNIFORM_MAX:
            break
        outcome = solve_case(case, problem=problem)
        rows.append({"refine": refine, "unknowns": problem.n_unknowns, "seconds": time.perf_counter() - started,
                     "outcome": outcome})
    return rows


def halved(case, count: int) -> list[dict]:
    """The case remeshed with contact_size halved 0 … count−1 times, without a grading key (the
    grading follows contact_size: the one mesh knob), stopping before UNIFORM_MAX."""
    rows = []
    for k in range(count):
        settings = replace(case.mesh, grading_key=None, contact_size=case.mesh.contact_size / 2**k)
        variant = replace(case, mesh=settings)
        started = time.perf_counter()
        problem = prepare(variant)
        if problem.n_unknowns > UNIFORM_MAX:
            break
        outcome = solve_case(variant, problem=problem)
        rows.append({"contact_size": settings.contact_size, "unknowns": problem.n_unknowns,
                     "seconds": time.perf_counter() - started, "outcome": outcome})
    return rows


def first_reaching(rows: list[dict], error_of, true: float, keys: tuple[str, ...]) -> dict:
    """The first of ``rows`` whose true error is at most ``true``, or the last tried."""
    levels = []
    for row in rows:
        levels.append({**{k: row[k] for k in keys}, "true": error_of(row["outcome"])})
        if levels[-1]["true"] <= true:
            break
    return {"reached": levels[-1]["true"] <= true, **levels[-1], "levels": levels}


def reference_value(case, quantity: str) -> dict:
    """The quantity extrapolated from the three finest uniform levels within UNIFORM_MAX."""
    rows = uniform(case, range(0, 8))[-3:]
    values = [quantities(r["outcome"].problem, r["outcome"].solution.contact)[quantity] for r in rows]
    order = observed_order(values[::-1], [1.0, 2.0, 4.0]) or 1.0
    extrapolated = values[-1] + (values[-1] - values[-2]) / (2.0**order - 1.0)
    return {"value": extrapolated, "order": order, "levels": [r["unknowns"] for r in rows], "values": values}


def study(name: str) -> dict:
    spec = STUDIES[name]
    case = spec["case"]()
    reference = None
    if spec["truth"] == "reference":
        reference = reference_value(case, spec["quantity"])
    started = time.perf_counter()
    run = solve_to_accuracy(case, target=spec["target"], quantity=spec["quantity"])
    seconds = time.perf_counter() - started
    true = true_error(name, spec, run.result, None if reference is None else reference["value"])
    row = {"case": name, "quantity": spec["quantity"], "target": spec["target"], "met": run.met,
           "stop_reason": run.stop_reason, "estimated": run.reached, "true": true, "truth": spec["truth"],
           "unknowns": run.result.problem.n_unknowns, "solves": len(run.steps), "seconds": seconds,
           "steps": run.steps, "reference": reference}
    def error_of(outcome) -> float:
        return true_error(name, spec, outcome, None if reference is None else reference["value"])

    row["uniform"] = first_reaching(uniform(case, range(0, 8)), error_of, true, ("refine", "unknowns", "seconds"))
    if case.mesh.contact_size is not None:
        row["contact_size_halved"] = first_reaching(halved(case, 8), error_of, true,
                                                    ("contact_size", "unknowns", "seconds"))
    levels = row["uniform"]["levels"]
    reached = row["uniform"]["reached"]
    print(f"{name}: {spec['quantity']} target {100 * spec['target']:.2g}%: estimated "
          f"{100 * (run.reached or float('nan')):.3g}%, true {100 * true:.3g}%, {row['unknowns']:,} unknowns, "
          f"{seconds:.2f} s; uniform {'reached' if reached else 'did not reach'} it: refine "
          f"{levels[-1]['refine']}, {levels[-1]['unknowns']:,} unknowns, {levels[-1]['seconds']:.2f} s, "
          f"true {100 * levels[-1]['true']:.3g}%"
          + ("" if "contact_size_halved" not in row else
             f"; contact_size halved: {row['contact_size_halved']['unknowns']:,} unknowns, "
             f"{row['contact_size_halved']['seconds']:.2f} s, true {100 * row['contact_size_halved']['true']:.3g}%"),
          flush=True)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "accuracy.json")
    parser.add_argument("--only", nargs="*", choices=tuple(STUDIES), default=None)
    args = parser.parse_args()
    rows = [study(name) for name in (args.only or STUDIES)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"uniform_max_unknowns": UNIFORM_MAX, "rows": rows}, indent=1, sort_keys=True)
                        + "\n")


if __name__ == "__main__":
    main()
