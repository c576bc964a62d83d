"""Hertz validation of cases/hertz.yaml on its graded mesh refined 0, 1, 2 times, both methods.

Usage: python benchmarks/hertz.py [REFINE ...] [--out FILE.json]
Prints a markdown table of the relative errors of the half-width, the peak pressure
and the pressure profile against plane-strain Hertz theory.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from contactfem.case import load_case
from contactfem.solve import prepare, solve_case
from contactfem.validation import hertz_comparison

ROOT = Path(__file__).resolve().parents[1]




def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("refinements", nargs="*", type=int, default=[0, 1, 2])
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    rows = []
    case = load_case(ROOT / "cases" / "hertz.yaml")
    for refine in args.refinements:
        started = time.perf_counter()
        problem = prepare(case, refine=refine)
        setup = time.perf_counter() - started
        contact_size = case.mesh.contact_size / 2**refine
        for method in ("positive", "standard"):
            outcome = solve_case(case, method=method, problem=problem)
            rows.append({"contact_size": contact_size, "method": method, "nodes": problem.mesh.n_points,
                         "unknowns": problem.n_unknowns, "seconds": setup + outcome.timings["solve"],
                         **hertz_comparison(outcome, radius=1.0)})
            print(json.dumps(rows[-1]), flush=True)
    if args.out:
        args.out.write_text(json.dumps(rows, indent=2) + "\n")
    print("| contact h | method | nodes | P | a error | p0 error | profile error | seconds (mesh + assembly + solve) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['contact_size']:g} | {r['method']} | {r['nodes']} | {r['load_per_thickness']:.1f} | "
              f"{r['half_width_error']:+.2%} | {r['peak_pressure_error']:+.2%} | {r['profile_error']:.2%} | "
              f"{r['seconds']:.1f} |")


if __name__ == "__main__":
    main()
