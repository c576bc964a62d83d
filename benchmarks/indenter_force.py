"""A rigid cylinder pushed by a force: one solve, and a load path of forces.

Usage: python benchmarks/indenter_force.py [--size 0.004] [--steps 10] [--out FILE.json]

The cylinder of benchmarks/indenter.py (R = 1 into an 8 x 4 block, bottom clamped, contact
mesh graded to ``--size``) is first pressed 0.002 by displacement; its reaction P is then
prescribed as a force. Theory: the two pose one problem, so the pushed run's advance is
0.002 and its reaction P to round-off. The table gives what each solve cost (kernel
solves, Newton steps, factorisations: counts, not seconds, on a shared machine), then a
path of ``--steps`` equal force steps up to P, each step against its own single solve
(advance and field), with the path's factorisations and Newton steps per step.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import contactfem.solve as solve_module
from contactfem.case import parse_case
from contactfem.solve import solve_case, solve_load_path

from indenter import MODULUS, block_case, half_width

ROOT = Path(__file__).resolve().parents[1]


def counted(run) -> tuple[object, dict]:
    """``run()``'s result and what its kernel calls cost."""
    calls = []
    kernel = solve_module.solve_contact

    def counting(*args, **kwargs):
        result = kernel(*args, **kwargs)
        calls.append(result)
        return result

    solve_module.solve_contact = counting
    try:
        started = time.perf_counter()
        result = run()
        seconds = time.perf_counter() - started
    finally:
        solve_module.solve_contact = kernel
    return result, {"kernel_solves": len(calls), "newton": sum(c.iterations for c in calls),
                    "factorizations": sum(c.factorizations for c in calls), "seconds": seconds}


def cylinder(motion: str, size: float, factors: list[float] | None = None):
    path = "" if factors is None else f"load_path: {{factors: {factors}}}\n"
    text = block_case(f"  circle: {{center: [0, 1], radius: 1}}\n  motion: {{direction: [0, -1], {motion}}}",
                      size) + path
    case = parse_case(text, source="cylinder.yaml")
    return counted(lambda: solve_case(case) if factors is None else solve_load_path(case))


def reaction(result) -> float:
    return float(result.problem.drive.reaction(result.kernel.nodal_force, result.problem.contact.normals))


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--size", type=float, default=0.004)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "indenter_force.json")
    args = parser.parse_args()
    driven, driven_cost = cylinder("displacement: 0.002", args.size)
    force = reaction(driven)
    pushed, pushed_cost = cylinder(f"force: {force!r}", args.size)
    a, _, n_active = half_width(pushed)
    hertz = float(np.sqrt(4 * force / (np.pi * MODULUS)))
    single = {"contact_size": args.size, "unknowns": pushed.problem.n_unknowns, "force": force,
              "displacement_control": driven_cost, "force_control": pushed_cost,
              "advance": pushed.problem.drive.advance, "advance_error": pushed.problem.drive.advance / 0.002 - 1,
              "reaction_error": reaction(pushed) / force - 1,
              "field_difference": relative(pushed.solution.displacement, driven.solution.displacement),
              "half_width_error": a / hertz - 1, "active_nodes": n_active}
    print(json.dumps(single), flush=True)
    factors = [round((i + 1) / args.steps, 12) for i in range(args.steps)]
    path, path_cost = cylinder(f"force: {force!r}", args.size, factors)
    steps = []
    for factor, step in zip(factors, path.steps):
        alone, alone_cost = cylinder(f"force: {factor * force!r}", args.size)
        steps.append({"factor": factor, "active_nodes": int(step.kernel.active.sum()),
                      "newton": step.kernel.iterations, "column_solves": step.kernel.column_solves,
                      "advance": step.problem.drive.advance,
                      "advance_difference": step.problem.drive.advance / alone.problem.drive.advance - 1,
                      "reaction_error": reaction(step) / (factor * force) - 1,
                      "field_difference": relative(step.solution.displacement, alone.solution.displacement),
                      "single_solve": alone_cost})
        print(json.dumps(steps[-1]), flush=True)
    figures = {"single": single, "path": {"steps": args.steps, "factorizations": path.factorizations,
                                          "seconds": path_cost["seconds"], "rows": steps}}
    args.out.write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
