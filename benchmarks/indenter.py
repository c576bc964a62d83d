"""Rigid indenters against theory: a cylinder (plane-strain Hertz), a wedge, a rounded punch.

Usage: python benchmarks/indenter.py [--sizes 0.002 ...] [--baseline SRC] [--out FILE.json]

(a) A rigid circle R = 1 pressed 0.002 into an 8 x 4 block (bottom clamped), contact mesh
    graded to ``contact_size``: the half-width against plane-strain Hertz at the run's own
    force, a = sqrt(4 P R / (π E*)), E* = E / (1 − ν²) (rigid indenter), P the reaction
    along the motion. The discrete half-width is where p² extrapolates to zero at each end
    of the zone (contactfem.validation).
(b) A rigid wedge (faces at β = 0.5° to the surface) pressed 0.002 and 0.004: a wedge has no
    length of its own, so the contact width is proportional to the load; the table gives
    a / P at both loads, and the half-plane's a / P = 1 / (E* tan β) (Johnson, Contact
    Mechanics, 1985, §5.4: P = a E* cot α, α = 90° − β the wedge's semi-angle).
(c) A flat punch of half-width 0.5 with corners rounded to radius 0.2, pressed 0.002: the
    pressure stays bounded (the sharp punch's is singular at its edges) and the zone
    reaches onto the roundings.
(d) With ``--baseline SRC`` (a source tree of the code before indenters, e.g. from
    ``git archive``): the flat obstacle's results of the shipped flat cases, bit for bit.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from contactfem.case import parse_case
from contactfem.solve import solve_case
from contactfem.validation import _zone_end

ROOT = Path(__file__).resolve().parents[1]
E, NU = 1.0e6, 0.3
MODULUS = E / (1 - NU**2)
FLAT_CASES = ("square", "punch", "flat_punch", "hertz_quarter", "strip")


def block_case(obstacle: str, contact_size: float, size: float = 0.5) -> str:
    return f"""
title: indenter benchmark
geometry:
  polygon:
    vertices: [[-4, -4], [4, -4], [4, 0], [-4, 0]]
    edges: [base, side, surface, side]
mesh: {{size: {size}, contact_size: {contact_size}}}
material: {{E: {E}, nu: {NU}}}
boundary: {{base: clamped, side: free, surface: contact}}
obstacle:
{obstacle}
"""


def half_width(result) -> tuple[float, float, int]:
    """(discrete half-width, reaction along the motion, active nodes)."""
    problem, contact = result.problem, result.solution.contact
    s, pressure = problem.contact.abscissa, contact.multiplier
    active = np.flatnonzero(contact.active)
    left = _zone_end(s, pressure, active.min(), inward=+1)
    right = _zone_end(s, pressure, active.max(), inward=-1)
    force = problem.drive.reaction(contact.nodal_force, problem.contact.normals)
    return 0.5 * (right - left), force, int(len(active))


def cylinder(contact_size: float) -> dict:
    text = block_case("  circle: {center: [0, 1], radius: 1}\n"
                      "  motion: {direction: [0, -1], displacement: 0.002}", contact_size)
    started = time.perf_counter()
    result = solve_case(parse_case(text, source="cylinder.yaml"))
    seconds = time.perf_counter() - started
    a, force, n_active = half_width(result)
    hertz = float(np.sqrt(4 * force * 1.0 / (np.pi * MODULUS)))
    return {"contact_size": contact_size, "unknowns": result.problem.n_unknowns, "force": force,
            "half_width": a, "hertz_half_width": hertz, "half_width_error": a / hertz - 1,
            "active_nodes": n_active, "newton": result.kernel.iterations, "seconds": seconds}


def wedge(contact_size: float) -> dict:
    slope = float(np.tan(np.radians(0.5)))
    rows = []
    for depth in (0.002, 0.004):
        text = block_case(f"  polyline: [[3, {3 * slope}], [0, 0], [-3, {3 * slope}]]\n"
                          f"  motion: {{direction: [0, -1], displacement: {depth}}}", contact_size)
        result = solve_case(parse_case(text, source="wedge.yaml"))
        a, force, n_active = half_width(result)
        rows.append({"depth": depth, "force": force, "half_width": a, "half_width_per_force": a / force,
                     "half_plane_half_width_per_force": 1 / (MODULUS * slope),
                     "active_nodes": n_active, "unknowns": result.problem.n_unknowns})
    ratio = rows[1]["half_width_per_force"] / rows[0]["half_width_per_force"]
    return {"contact_size": contact_size, "faces_to_surface_degrees": 0.5, "loads": rows,
            "width_per_force_ratio": ratio}


def rounded_punch(contact_size: float) -> dict:
    radius, half = 0.2, 0.5
    angle = np.linspace(0.0, np.pi / 2, 33)
    right = np.stack([half + radius * np.sin(angle), radius * (1 - np.cos(angle))], axis=1)[::-1]
    left = right[::-1] * [-1, 1]
    # Walked from right to left over the face: the punch lies above.
    vertices = np.concatenate([right, left])
    shown = ", ".join(f"[{float(x)!r}, {float(y)!r}]" for x, y in vertices)
    text = block_case(f"  polyline: [{shown}]\n  motion: {{direction: [0, -1], displacement: 0.002}}", contact_size)
    result = solve_case(parse_case(text, source="rounded_punch.yaml"))
    a, force, n_active = half_width(result)
    pressure = result.solution.contact.multiplier
    return {"contact_size": contact_size, "corner_radius": radius, "flat_half_width": half, "force": force,
            "half_width": a, "peak_over_mean_pressure": float(pressure.max() / (force / (2 * a))),
            "active_nodes": n_active, "unknowns": result.problem.n_unknowns}


def flat_unchanged(baseline: Path) -> list[dict]:
    """Solve the shipped flat cases with this tree and with ``baseline``; compare the fields."""
    script = ("import sys, numpy as np; from contactfem.case import load_case; from contactfem.solve import solve_case;"
              "r = solve_case(load_case(sys.argv[1])); np.save(sys.argv[2], np.concatenate("
              "[r.solution.displacement.ravel(), r.solution.contact.multiplier]))")
    rows = []
    for name in FLAT_CASES:
        arrays = []
        for tree in (ROOT, baseline):
            out = Path(f"/tmp/indenter_flat_{name}_{tree.name}.npy")
            env = {**os.environ, "PYTHONPATH": str(tree)}
            subprocess.run([sys.executable, "-c", script, str(ROOT / "cases" / f"{name}.yaml"), str(out)], env=env,
                           check=True, cwd=tree)
            arrays.append(np.load(out))
        rows.append({"case": name, "values": int(arrays[0].size), "bit_identical": bool(np.array_equal(*arrays)),
                     "largest_difference": float(np.abs(arrays[0] - arrays[1]).max())})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", nargs="*", type=float, default=[0.004, 0.002])
    parser.add_argument("--baseline", type=Path, default=None)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "indenter.json")
    args = parser.parse_args()
    figures: dict = {"cylinder": []}
    for size in args.sizes:
        figures["cylinder"].append(cylinder(size))
        print(json.dumps(figures["cylinder"][-1]), flush=True)
    figures["wedge"] = wedge(0.004)
    print(json.dumps(figures["wedge"]), flush=True)
    figures["rounded_punch"] = rounded_punch(0.004)
    print(json.dumps(figures["rounded_punch"]), flush=True)
    if args.baseline is not None:
        figures["flat_unchanged"] = flat_unchanged(args.baseline)
        print(json.dumps(figures["flat_unchanged"]), flush=True)
    args.out.write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
