"""Hertz half-disk: uniform versus graded meshes, error in a and p0 against unknowns.

Usage: python benchmarks/hertz_grading.py [--out FILE.json]
Uniform meshes use mesh.size h everywhere; graded ones keep the bulk at 0.05 and put
contact_size at ΓC, growing by 0.2 per unit distance (the shipped cases/hertz.yaml).
Prints a markdown table and, for each family, the fewest unknowns reaching 1% in both a
and p0 (positive method).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import yaml

from contactfem.case import parse_case
from contactfem.solve import prepare, solve_case
from contactfem.validation import hertz_comparison

ROOT = Path(__file__).resolve().parents[1]


def variant(**mesh) -> object:
    data = yaml.safe_load((ROOT / "cases" / "hertz.yaml").read_text())
    data["mesh"] = mesh
    return parse_case(yaml.safe_dump(data), source=ROOT / "cases" / "hertz.yaml")


def run(label: str, case) -> dict:
    started = time.perf_counter()
    problem = prepare(case)
    outcome = solve_case(case, problem=problem)
    figures = hertz_comparison(outcome, radius=1.0)
    row = {"mesh": label, "unknowns": problem.n_unknowns, "seconds": time.perf_counter() - started,
           "worst_error": max(abs(figures["zone_half_width_error"]), abs(figures["peak_pressure_error"])),
           **figures}
    print(json.dumps(row), flush=True)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "hertz_grading.json")
    args = parser.parse_args()
    rows = [run(f"uniform h={h:g}", variant(size=h)) for h in (0.02, 0.01, 0.005, 0.0025)]
    rows += [run(f"graded hc={hc:g}", variant(size=0.05, contact_size=hc, grading=0.2))
             for hc in (0.004, 0.002, 0.001, 0.0005, 0.00025)]
    args.out.write_text(json.dumps(rows, indent=2) + "\n")
    print("| mesh | unknowns | a from active nodes | a, sub-grid | p0 error | profile error | seconds |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['mesh']} | {r['unknowns']} | {r['zone_half_width_error']:+.2%} | {r['half_width_error']:+.2%} | "
              f"{r['peak_pressure_error']:+.2%} | {r['profile_error']:.2%} | {r['seconds']:.1f} |")
    for family in ("uniform", "graded"):
        ok = [r["unknowns"] for r in rows if r["mesh"].startswith(family) and r["worst_error"] <= 0.01]
        profile = [r["unknowns"] for r in rows if r["mesh"].startswith(family) and r["profile_error"] <= 0.01]
        print(f"{family}: fewest unknowns with a (active nodes) and p0 within 1%: {min(ok) if ok else 'not reached'}; "
              f"with the profile within 1%: {min(profile) if profile else 'not reached'}")


if __name__ == "__main__":
    main()
