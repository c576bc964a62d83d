"""The flat rigid punch against the half-space solution p(x) = P / (π √(a² − x²)).

A rigid flat punch of half-width a, pressed by δ into a block of width W and depth D
(bottom clamped, sides free), frictionless. For a half-space the pressure under the punch
is P / (π √(a² − x²)) whatever the elastic constants, P the force per unit thickness; it
is singular like 1/√r at the punch edges. The block is graded towards the punch face
(mesh.contact_size) and four times finer still at its edges. Measured: over the middle 80%
of the punch (|x| ≤ 0.8 a), the relative L² error of λh against the formula evaluated with
the computed P, and the largest relative error at a node, against the number of unknowns
(several contact sizes) and the block's size (the idealisation error of a finite block).

Usage: python benchmarks/punch.py [--quick] [--out benchmarks/results/punch.json]
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
HALF_WIDTH = 1.0
INDENTATION = 1e-3


def punch_case(width: float, depth: float, contact_size: float, size: float | None = None,
               grading: float = 0.15, method: str = "positive"):
    """The punch scene as a validated case (the surface split at the punch edges, so that a
    node sits exactly at each)."""
    from contactfem.case import parse_case

    a, w = HALF_WIDTH, width / 2
    data = {
        "title": f"flat punch, block {width:g} x {depth:g}, contact_size {contact_size:g}",
        "geometry": {"polygon": {
            "vertices": [[-w, -depth], [w, -depth], [w, 0], [a, 0], [-a, 0], [-w, 0]],
            "edges": ["bottom", "right", "surface", "surface", "surface", "left"]}},
        "mesh": {"size": size or width / 20, "contact_size": contact_size, "grading": grading},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"bottom": "clamped", "left": "free", "right": "free", "surface": "contact"},
        "obstacle": {"segment": [[a, -INDENTATION], [-a, -INDENTATION]]},
        "solver": {"method": method},
    }
    return parse_case(yaml.safe_dump(data), source=ROOT / "cases" / "punch-benchmark.yaml")


def punch_errors(result) -> dict:
    """The computed pressure against P / (π √(a² − x²)) over the middle 80% of the punch."""
    contact = result.solution.contact
    x = result.problem.mesh.points[contact.nodes, 0]
    force = float(contact.nodal_force.sum())
    middle = np.abs(x) <= 0.8 * HALF_WIDTH
    exact = force / (np.pi * np.sqrt(HALF_WIDTH**2 - x[middle] ** 2))
    computed = contact.multiplier[middle]
    order = np.argsort(x[middle])
    xs, difference = x[middle][order], (computed - exact)[order]
    l2 = np.sqrt(np.trapezoid(difference**2, xs) / np.trapezoid(exact[order] ** 2, xs))
    return {
        "force": force,
        "middle_nodes": int(middle.sum()),
        "relative_l2_error_middle_80": float(l2),
        "max_relative_error_middle_80": float(np.abs(computed - exact).max() / exact.min()),
        "active_nodes": int(contact.active.sum()),
        "contact_nodes": int(len(contact.nodes)),
    }


def measure(width: float, depth: float, contact_size: float, method: str = "positive") -> dict:
    from contactfem.solve import solve_case

    case = punch_case(width, depth, contact_size, method=method)
    started = time.perf_counter()
    result = solve_case(case)
    seconds = time.perf_counter() - started
    return {"width": width, "depth": depth, "contact_size": contact_size, "method": method,
            "unknowns": result.problem.n_unknowns, "seconds": seconds,
            "iterations": result.kernel.iterations, "certified": bool(result.kernel.certificate.passed),
            **punch_errors(result)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "punch.json")
    args = parser.parse_args()
    sizes = (0.08, 0.04, 0.02) if args.quick else (0.08, 0.04, 0.02, 0.01, 0.005, 0.0025)
    rows = []
    for width, depth in ((20.0, 10.0), (40.0, 20.0), (80.0, 40.0)):
        for contact_size in sizes:
            row = measure(width, depth, contact_size)
            rows.append(row)
            print(json.dumps(row), flush=True)
    for method in ("standard",):
        row = measure(40.0, 20.0, 0.01, method=method)
        rows.append(row)
        print(json.dumps(row), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"benchmark": "punch", "half_width": HALF_WIDTH, "indentation": INDENTATION,
                                    "machine": platform.platform(), "rows": rows}, indent=2) + "\n",
                        encoding="utf-8")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
