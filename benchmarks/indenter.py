"""Rigid indenters against theory: a cylinder (plane-strain Hertz), a wedge, a rounded punch.

Usage: python benchmarks/indenter.py [--sizes 0.002 ...] [--punch-sizes 0.004 ...] [--only rounded_punch]
       [--baseline SRC] [--out FILE.json]

(a) A rigid circle R = 1 pressed 0.002 into an 8 x 4 block (bottom clamped), contact mesh
    graded to ``contact_size``: the half-width against plane-strain Hertz at the run's own
    force, a = sqrt(4 P R / (π E*)), E* = E / (1 − ν²) (rigid indenter), P the reaction
    along the motion. The discrete half-width is where p² extrapolates to zero at each end
    of the zone (contactfem.validation).
(b) A rigid wedge (faces at β = 0.5° to the surface) pressed 0.002 and 0.004: a wedge has no
    length of its own, so the contact width is proportional to the load; the table gives
    a / P at both loads, and the half-plane's a / P = 1 / (E* tan β) (Johnson, Contact
    Mechanics, 1985, §5.4: P = a E* cot α, α = 90° − β the wedge's semi-angle).
(c) A flat punch of half-width a = 0.5 with corners rounded to R = 0.2 (256 chords per quarter
    circle) pushed by P = 10 000 into the block, so the zone runs b − a ≈ 0.019 onto the
    roundings. Half-plane theory (Ciavarella, Hills & Monno, "The influence of rounded edges
    on indentation by a flat punch", Proc IMechE C 212 (1998) 319–328): a symmetric
    incomplete contact of the profile g has bounded pressure at x = ±b when
        P = (E*/2) ∫_{−b}^{b} x g′(x) / √(b² − x²) dx,
    and with g′(x) = sign(x)(|x| − a)/R beyond the flat, x = b sin φ,
        P = E* b² / (4R) · (π − 2φ0 − sin 2φ0),   φ0 = arcsin(a / b),
    which is plane-strain Hertz, P = π E* b² / (4R), at a = 0 (quadrature of the integral
    agrees to 4e-14). For the polyline actually meshed, g′ is each chord's slope s_k and the
    integral is exact: P = E* Σ s_k (√(b² − x_k²) − √(b² − x_{k+1}²)) over the chords below b;
    its b is compared (the arc's differs by 2e-5). Half-plane theory drops u_x · g′ from the
    gap; the nodal constraint along the punch's normal keeps it. Under the punch the surface
    slides inward by U (about (1 − 2ν)(1 + ν) P / (2E) on a half-plane), 10% of b − a here, so
    the zone ends U beyond where the material meets the punch: the table gives the error of
    b − a as measured and with the run's own U(b) removed, at several contact sizes and on
    8 x 4, 16 x 8 and 32 x 16 blocks.
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
from scipy.optimize import brentq

from contactfem.case import parse_case
from contactfem.solve import solve_case
from contactfem.validation import _zone_end

ROOT = Path(__file__).resolve().parents[1]
E, NU = 1.0e6, 0.3
MODULUS = E / (1 - NU**2)
FLAT_CASES = ("square", "punch", "flat_punch", "hertz_quarter", "strip")


def block_case(obstacle: str, contact_size: float, size: float = 0.5, extent: float = 4.0) -> str:
    return f"""
title: indenter benchmark
geometry:
  polygon:
    vertices: [[{-extent:g}, {-extent:g}], [{extent:g}, {-extent:g}], [{extent:g}, 0], [{-extent:g}, 0]]
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


PUNCH_FLAT, PUNCH_RADIUS, PUNCH_FORCE = 0.5, 0.2, 10_000.0
#: Chords per quarter circle of each rounding: chord sag R (1 − cos(π / 4n)) / 2 ≈ 4e-7 at 256.
PUNCH_CHORDS = 256


def punch_corner(chords: int = PUNCH_CHORDS) -> np.ndarray:
    """(chords + 1, 2): the right rounding's vertices, from the flat's edge outward."""
    angle = np.linspace(0.0, np.pi / 2, chords + 1)
    return np.stack([PUNCH_FLAT + PUNCH_RADIUS * np.sin(angle), PUNCH_RADIUS * (1 - np.cos(angle))], axis=1)


def punch_force(b: float, corner: np.ndarray | None = None) -> float:
    """The half-plane's force for contact over [−b, b]: the arc's closed form, or with
    ``corner`` the exact consistency integral of that polyline (g′ constant on each chord)."""
    if corner is None:
        phi = np.arcsin(PUNCH_FLAT / b)
        return float(MODULUS * b**2 / (4 * PUNCH_RADIUS) * (np.pi - 2 * phi - np.sin(2 * phi)))
    x, y = corner[:, 0], corner[:, 1]
    slope = np.diff(y) / np.diff(x)
    root = np.sqrt(np.clip(b**2 - x**2, 0.0, None))
    return float(MODULUS * np.sum(slope * (root[:-1] - root[1:])))


def punch_half_width(force: float, corner: np.ndarray | None = None) -> float:
    """The half-plane's b at ``force`` (punch_force inverted; it grows with b)."""
    return float(brentq(lambda b: punch_force(b, corner) - force, PUNCH_FLAT * (1 + 1e-12),
                        PUNCH_FLAT + PUNCH_RADIUS, xtol=1e-14))


def rounded_punch(contact_size: float, extent: float = 4.0) -> dict:
    """The punch pushed by PUNCH_FORCE into a 2·extent x extent block: b against the theory's b."""
    corner = punch_corner()
    right = corner[::-1]
    left = corner * [-1, 1]
    # Walked from right to left over the face: the punch lies above.
    vertices = np.concatenate([right, left])
    shown = ", ".join(f"[{float(x)!r}, {float(y)!r}]" for x, y in vertices)
    text = block_case(f"  polyline: [{shown}]\n  motion: {{direction: [0, -1], force: {PUNCH_FORCE}}}",
                      contact_size, extent=extent)
    started = time.perf_counter()
    result = solve_case(parse_case(text, source="rounded_punch.yaml"))
    seconds = time.perf_counter() - started
    b, force, n_active = half_width(result)
    theory = punch_half_width(force, corner)
    # The surface's inward slide at the zone's edge: the nodal constraint along the punch's
    # normal keeps u_x·slope in the gap, which half-plane theory drops.
    nodes = result.problem.contact.nodes
    x = result.problem.contact.positions[:, 0]
    order = np.argsort(x)
    slide = -float(np.interp(b, x[order], result.solution.displacement.reshape(-1, 2)[nodes[order], 0]))
    pressure = result.solution.contact.multiplier
    return {"contact_size": contact_size, "block": [2 * extent, extent], "unknowns": result.problem.n_unknowns,
            "force": force, "half_width": b, "theory_half_width": theory,
            "arc_theory_half_width": punch_half_width(force),
            "half_width_error": b / theory - 1, "overhang_error": (b - PUNCH_FLAT) / (theory - PUNCH_FLAT) - 1,
            "slide": slide, "half_plane_slide": (1 - 2 * NU) * (1 + NU) * force / (2 * E),
            "slid_overhang_error": (b - slide - PUNCH_FLAT) / (theory - PUNCH_FLAT) - 1,
            "peak_over_mean_pressure": float(pressure.max() / (force / (2 * b))),
            "active_nodes": n_active, "newton": result.kernel.iterations, "seconds": seconds}


def rounded_punch_study(sizes: list[float], large_size: float, extents: tuple[float, ...] = (8.0, 16.0)) -> dict:
    """The punch at each contact size on the 8 x 4 block, then on larger blocks at one size."""
    rows = []
    for size in sizes:
        rows.append(rounded_punch(size))
        print(json.dumps(rows[-1]), flush=True)
    blocks = [next(row for row in rows if row["contact_size"] == large_size)] if large_size in sizes else []
    for extent in extents:
        blocks.append(rounded_punch(large_size, extent=extent))
        print(json.dumps(blocks[-1]), flush=True)
    return {"corner_radius": PUNCH_RADIUS, "flat_half_width": PUNCH_FLAT, "chords_per_quarter": PUNCH_CHORDS,
            "force": PUNCH_FORCE, "theory_half_width": punch_half_width(PUNCH_FORCE, punch_corner()),
            "arc_theory_half_width": punch_half_width(PUNCH_FORCE), "sizes": rows, "blocks": blocks}


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
    parser.add_argument("--punch-sizes", nargs="*", type=float, default=[0.004, 0.002, 0.001])
    parser.add_argument("--only", choices=["rounded_punch"], default=None,
                        help="run only this part and merge it into the existing --out file")
    parser.add_argument("--baseline", type=Path, default=None)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "indenter.json")
    args = parser.parse_args()
    if args.only:
        figures = json.loads(args.out.read_text(encoding="utf-8")) if args.out.exists() else {}
        figures["rounded_punch"] = rounded_punch_study(args.punch_sizes, args.punch_sizes[0])
        args.out.write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")
        return
    figures: dict = {"cylinder": []}
    for size in args.sizes:
        figures["cylinder"].append(cylinder(size))
        print(json.dumps(figures["cylinder"][-1]), flush=True)
    figures["wedge"] = wedge(0.004)
    print(json.dumps(figures["wedge"]), flush=True)
    figures["rounded_punch"] = rounded_punch_study(args.punch_sizes, args.punch_sizes[0])
    if args.baseline is not None:
        figures["flat_unchanged"] = flat_unchanged(args.baseline)
        print(json.dumps(figures["flat_unchanged"]), flush=True)
    args.out.write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
