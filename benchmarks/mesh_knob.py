"""One knob that converges: contact_size halved with no mesh.grading key (the grading then
follows it, 0.7 · sqrt(contact_size / size)), on Hertz, the flat punch and a rough profile.

Usage: python benchmarks/mesh_knob.py [--out FILE.json] [--levels N]
Quarter Hertz disk (cases/hertz_quarter.yaml without its grading key): the half-width
(p² extrapolated to zero past the last active node, contactfem.validation) against
plane-strain Hertz at the run's own force. Flat punch (cases/flat_punch.yaml without its
grading key): the contact force against the finest run's. Rough block (cases/rough.yaml
graded towards its base): the length in contact against the finest run's.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import yaml

from contactfem.case import parse_case
from contactfem.solve import prepare, solve_case
from contactfem.validation import hertz_comparison

ROOT = Path(__file__).resolve().parents[1]


def variant(name: str, **mesh) -> object:
    source = ROOT / "cases" / name
    data = yaml.safe_load(source.read_text())
    data["mesh"] = mesh
    return parse_case(yaml.safe_dump(data), source=source)


def contact_length(outcome) -> float:
    """Length of ΓC whose nodes are active: half of each active node's two edges."""
    contact = outcome.solution.contact
    s = outcome.problem.contact.abscissa
    order = np.argsort(s)
    s, active = s[order], contact.active[order]
    edges = np.diff(s)
    both = active[:-1] & active[1:]
    one = active[:-1] ^ active[1:]
    return float(edges[both].sum() + 0.5 * edges[one].sum())


def run(study: str, name: str, size: float, contact_size: float) -> dict:
    case = variant(name, size=size, contact_size=contact_size)
    started = time.perf_counter()
    problem = prepare(case)
    outcome = solve_case(case, problem=problem)
    seconds = time.perf_counter() - started
    row = {"study": study, "contact_size": contact_size, "grading": case.mesh.grading,
           "unknowns": problem.n_unknowns, "seconds": seconds,
           "force": float(outcome.solution.contact.nodal_force.sum())}
    if study == "hertz":
        figures = hertz_comparison(outcome, radius=1.0, symmetry_axis=0.0)
        row["error"] = figures["half_width_error"]
        row["zone_error"] = figures["zone_half_width_error"]
        row["peak_pressure_error"] = figures["peak_pressure_error"]
    elif study == "rough":
        row["contact_length"] = contact_length(outcome)
    print(json.dumps(row), flush=True)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "mesh_knob.json")
    parser.add_argument("--levels", type=int, default=4, help="the shipped contact_size and this many - 1 halvings")
    args = parser.parse_args()
    halvings = [2.0**-k for k in range(args.levels)]
    rows = [run("hertz", "hertz_quarter.yaml", 0.05, 0.002 * f) for f in halvings]
    punch = [run("punch", "flat_punch.yaml", 1.0, 0.04 * f) for f in halvings + [halvings[-1] / 2]]
    for r in punch:
        r["reference"] = punch[-1]["force"]
        r["error"] = r["force"] / punch[-1]["force"] - 1
    rough = [run("rough", "rough.yaml", 0.05, 0.002 * f) for f in halvings + [halvings[-1] / 2]]
    for r in rough:
        r["reference"] = rough[-1]["contact_length"]
        r["error"] = r["contact_length"] / rough[-1]["contact_length"] - 1
    rows += punch + rough
    args.out.write_text(json.dumps(rows, indent=2) + "\n")
    print("| case | contact_size | grading | unknowns | seconds | error |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['study']} | {r['contact_size']:g} | {r['grading']:.3g} | {r['unknowns']} | {r['seconds']:.2f} | "
              f"{r['error']:+.3%} |")


if __name__ == "__main__":
    main()
