"""Stability at the extremes: every case solves within the iteration cap with its sign
conditions and equilibrium, writes only finite numbers, or is refused with a clear reason.

Usage: python benchmarks/extremes.py [--fast] [--largest N] [--out FILE.json]

Without --fast the full set runs (meshes up to h = 1/N, default N = 1024; 2048 needs
about 8M triangles and ~20 GB). Each case goes through ``contactfem solve`` (click's
CliRunner) into a temporary directory; report.json, solution.h5 and both VTU files are
read back and checked for NaN/inf. Writes JSON (per case: tried/solved/refused/failed,
Newton iterations, sign-condition and equilibrium figures) and prints the counts.
tests/test_extremes.py runs the fast subset (the ``FAST`` cases).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]

#: Relative tolerances of the checks of a solved case (against the data's own scales).
SIGN_TOLERANCE = 1e-8
EQUILIBRIUM_TOLERANCE = 1e-8
#: Iteration cap of every case (the default solver.max_iterations).
CAP = 50


def square(divisions: int = 8, E: float = 1.0e6, nu: float = 0.3, scale: float = 1.0, **changes) -> dict:
    """The square of cases/square.yaml: left clamped, top traction scale × (1e4, −1e4(1 − 1.5x))."""
    data = {
        "title": "square",
        "geometry": {"rectangle": {"lower": [0, 0], "upper": [1, 1]}},
        "mesh": {"divisions": divisions},
        "material": {"E": E, "nu": nu},
        "boundary": {
            "left": "clamped",
            "top": {"traction": [1.0e4 * scale, f"{-1.0e4 * scale!r}*(1-1.5*x)"]},
            "right": "free",
            "bottom": "contact",
        },
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }
    for key, value in changes.items():
        data[key] = value
    return data


def with_(data: dict, path: str, value) -> dict:
    data = copy.deepcopy(data)
    *parents, last = path.split(".")
    node = data
    for key in parents:
        node = node[key]
    node[last] = value
    return data


@dataclass
class Extreme:
    """One case: its data, and either what it must satisfy or the refusal it must get."""

    name: str
    group: str
    data: dict
    refuse: str | None = None          # a fragment of the expected one-line refusal (bad input, exit 2)
    #: A fragment of the expected one-line failure (exit 1): a system the kernel cannot certify
    #: or a numerically singular one; the answer is not called a success.
    unsolvable: str | None = None
    expect: dict = field(default_factory=dict)  # e.g. {"active": "all" | "none", "warning": True}
    mesh_file: dict | None = None      # {"n": .., "angle": ..}: a gmsh file written next to the case


def rotated_square_msh(path: Path, n: int, angle: float) -> Path:
    """The unit square's structured n × n mesh, rotated by ``angle`` about the origin (gmsh 2.2)."""
    from dataclasses import replace

    from contactfem.mesh import structured_rectangle, write_gmsh

    square = structured_rectangle((0.0, 0.0), (1.0, 1.0), n, n)
    c, s = math.cos(angle), math.sin(angle)
    rotated = square.points @ np.array([[c, s], [-s, c]])  # rows R p
    return write_gmsh(replace(square, points=rotated), path)


def rotated_case(n: int, angle: float) -> dict:
    """The square rotated by ``angle``: mesh, traction (a rotated vector of the rotated-back
    coordinates) and obstacle (normal R (0, −1)). angle = 0 is the plain square on the same mesh."""
    c, s = math.cos(angle), math.sin(angle)
    # Coordinates in the square's frame: X = c x + s y (Rᵀ x).
    X = f"({c!r}*x+{s!r}*y)"
    g1 = f"(-1e4*(1-1.5*{X}))"
    traction = [f"{c!r}*1e4-{s!r}*{g1}", f"{s!r}*1e4+{c!r}*{g1}"]
    data = square(0)
    data["geometry"] = {"mesh_file": "rotated.msh"}
    data.pop("mesh")
    data["boundary"]["top"] = {"traction": traction}
    data["obstacle"] = {"point": [0, 0], "normal": [s, -c]}
    return data


def catalogue(fast: bool, largest: int = 1024) -> list[Extreme]:
    """The cases; ``fast`` keeps the default-suite subset (small meshes)."""
    n = 8 if fast else 32
    cases: list[Extreme] = []
    add = cases.append
    # Poisson's ratio up to the locking limit (warning above nu = 0.4995 in plane strain).
    for nu in (0.0, 0.3, 0.49, 0.4995, 0.4999) if fast else (0.0, 0.1, 0.3, 0.45, 0.49, 0.499, 0.4995, 0.4999):
        add(Extreme(f"nu={nu}", "poisson", square(n, nu=nu), expect={"warning": nu > 0.4995}))
    add(Extreme("nu=0.4999(stress)", "poisson", with_(square(n, nu=0.4999), "material.plane", "stress"),
                expect={"warning": False}))
    add(Extreme("nu=0.5", "poisson", square(n, nu=0.5), refuse="material.nu"))
    add(Extreme("nu=0.49999999999", "poisson", square(n, nu=0.49999999999), refuse="material.nu"))
    # Young's modulus with proportional loads: the same normalised solution, the same iterations.
    for E in (1e-6, 1e-3, 1.0, 1e3, 1e6, 1e9, 1e12) if not fast else (1e-6, 1.0, 1e6, 1e12):
        add(Extreme(f"E={E:g}", "young", square(n, E=E, scale=E / 1e6), expect={"normalise": 1.0}))
    add(Extreme("E=1e-60", "young", square(n, E=1e-60), refuse="material.E"))
    add(Extreme("E=1e60", "young", square(n, E=1e60), refuse="material.E"))
    # Loads from 1e-12 to 1e12 (zero gap: the solution is positively homogeneous in the load).
    for scale in (1e-16, 1e-8, 1e-4, 1.0, 1e4, 1e8) if not fast else (1e-16, 1.0, 1e8):
        add(Extreme(f"load={1e4 * scale:g}", "load", square(n, scale=scale), expect={"normalise": scale}))
    add(Extreme("load=1e300", "load", square(n, scale=1e296), refuse="boundary.top.traction"))
    # Mesh sizes on the square.
    sizes = (4, 16, 64) if fast else tuple(2**k for k in range(2, 12) if 2**k <= largest)
    for divisions in sizes:
        add(Extreme(f"h=1/{divisions}", "mesh", square(divisions)))
    add(Extreme("h=1/100000", "mesh", square(100_000), refuse="mesh"))
    # A thin body, aspect 1:1000, and a tiny clamped part.
    thin = square(0)
    thin["geometry"] = {"rectangle": {"lower": [0, 0], "upper": [1, 1e-3]}}
    thin["mesh"] = {"divisions": [200 if fast else 1000, 1 if fast else 4]}
    thin["boundary"]["top"] = {"traction": [0.0, "-1.0*(1-1.5*x)"]}
    # The stiffness's condition number is κ ~ (L/t)² (L/h)² ≈ 1e12 on the 1000 x 4 mesh. The
    # kernel's convergence test is the normwise backward error (reached: ~3e-16), but force
    # balance measured against the applied loads can only reach ε κ ≈ 2e-16 · 1e12 ≈ 1e-4
    # (the loads are tiny beside ‖K‖ ‖u‖): that is this case's tolerance. Mesh sequencing
    # (500 x 2, 250 x 1) starts the fine iteration near its answer: 2 Newton steps.
    add(Extreme("thin 1:1000", "geometry", thin, expect={"sign_tolerance": 1e-4}))
    tiny = square(0)
    tiny["geometry"] = {"polygon": {
        "vertices": [[0, 0], [1, 0], [1, 1], [0, 1], [0, 0.5005], [0, 0.4995]],
        "edges": ["bottom", "right", "top", "left", "clamp", "left"]}}
    tiny["mesh"] = {"size": 0.125 if fast else 0.05}
    tiny["boundary"] = {"clamp": "clamped", "left": "free", "top": {"traction": [1.0e4, "-1e4*(1-1.5*x)"]},
                        "right": "free", "bottom": "contact"}
    add(Extreme("tiny clamp (1e-3)", "geometry", tiny))
    # Contact zones: full, none (lift-off), far away, overlapping.
    add(Extreme("full contact", "zone", with_(square(n), "boundary.top", {"traction": [0, -1.0e4]}),
                expect={"active": "all"}))
    add(Extreme("full lift-off", "zone", with_(square(n), "boundary.top", {"traction": [0, 1.0e4]}),
                expect={"active": "none"}))
    add(Extreme("far obstacle", "zone", with_(square(n), "obstacle.point", [0, -1.0]), expect={"active": "none"}))
    overlap = with_(with_(square(n), "obstacle.point", [0, 0.01]), "boundary.top", {"traction": [0, 0]})
    add(Extreme("overlap (g = -0.01)", "zone", overlap, expect={"active": "some"}))
    # The contact node at the corner shared with a support: clamped (no multiplier) or a roller.
    corner = with_(square(n), "boundary.left", {"displacement": [0, None]})
    corner["boundary"]["right"] = "clamped"
    add(Extreme("corner roller", "corner", corner, expect={"corner": "contact"}))
    add(Extreme("corner clamped", "corner", square(n), expect={"corner": "supported"}))
    # A slanted obstacle: the rotated square gives the rotated displacement (same mesh).
    for angle in (0.0, 0.3, 1.0) if fast else (0.0, 0.1, 0.3, 0.7, 1.0, 2.0):
        add(Extreme(f"rotated {angle}", "rotation", rotated_case(n, angle), mesh_file={"n": n, "angle": angle}))
    # Both methods and small/large c on an FE problem.
    add(Extreme("standard", "method", with_(square(n), "solver", {"method": "standard"})))
    for c in (1e-6, 1e-3, 1e6, 1e9):
        add(Extreme(f"c={c:g}", "method", with_(square(n), "solver", {"c": c})))
    # Hostile data: results that used to exit 0 as "converged" although wrong.
    add(Extreme("u_D = 1e45 (away)", "hostile", with_(square(n), "boundary.left", {"displacement": [1e45, 0]}),
                unsolvable="not certified"))
    add(Extreme("u_D = -1e45 (pressing)", "hostile",
                with_(square(n), "boundary.left", {"displacement": [0, -1e45]})))
    slender = square(0)
    slender["geometry"] = {"rectangle": {"lower": [0, 0], "upper": [1, 1e-6]}}
    slender["mesh"] = {"divisions": [64, 2]}
    slender["boundary"]["top"] = {"traction": [0.0, "-1.0*(1-1.5*x)"]}
    add(Extreme("body 1 x 1e-6", "hostile", slender, unsolvable="singular"))
    add(Extreme("sliver 1e-8 high", "hostile", {
        "geometry": {"polygon": {"vertices": [[0, 0], [1, 0], [0.5, 1.0e-8]], "edges": ["bottom", "right", "left"]}},
        "mesh": {"size": 0.05}, "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"bottom": "contact", "left": "clamped", "right": {"traction": [0, -1]}},
        "obstacle": {"point": [0, 0], "normal": [0, -1]}}, refuse="geometry.polygon"))
    add(Extreme("refine beyond memory", "hostile", with_(square(32), "mesh.refine", 7), refuse="mesh"))
    return cases


@dataclass
class Outcome:
    name: str
    group: str
    status: str            # solved | refused | failed
    detail: str = ""
    iterations: int | None = None
    figures: dict = field(default_factory=dict)
    displacement: np.ndarray | None = None
    report: dict | None = None


def _runner():
    from click.testing import CliRunner

    try:
        return CliRunner(mix_stderr=False)
    except TypeError:
        return CliRunner()


def _finite_outputs(out: Path) -> list[str]:
    """Names of the written arrays holding NaN/inf (read back from every file)."""
    import h5py
    import meshio

    bad = []
    text = (out / "report.json").read_text(encoding="utf-8")
    report = json.loads(text, parse_constant=lambda name: bad.append(f"report.json {name}"))
    with h5py.File(out / "solution.h5", "r") as h5:
        def visit(name, item):
            if isinstance(item, h5py.Dataset) and item.dtype.kind == "f" and not np.isfinite(item[()]).all():
                bad.append(f"solution.h5 /{name}")
        h5.visititems(visit)
    for vtu in ("solution.vtu", "contact.vtu"):
        mesh = meshio.read(out / vtu)
        arrays = {"points": mesh.points, **mesh.point_data,
                  **{k: v[0] for k, v in mesh.cell_data.items()}}
        bad += [f"{vtu} {k}" for k, v in arrays.items() if np.asarray(v).dtype.kind == "f" and not np.isfinite(v).all()]
    del report
    return bad


def run_case(case: Extreme, workdir: Path) -> Outcome:
    """Solve ``case`` through the CLI in ``workdir`` and check what must hold."""
    from contactfem.cli import main

    workdir.mkdir(parents=True, exist_ok=True)
    if case.mesh_file is not None:
        rotated_square_msh(workdir / "rotated.msh", case.mesh_file["n"], case.mesh_file["angle"])
    path = workdir / "case.yaml"
    path.write_text(yaml.safe_dump(case.data, sort_keys=False), encoding="utf-8")
    out = workdir / "out"
    result = _runner().invoke(main, ["solve", str(path), "--out", str(out), "--quiet"])
    crashed = result.exception is not None and not isinstance(result.exception, SystemExit)
    if crashed or "Traceback" in result.stderr:
        return Outcome(case.name, case.group, "failed", f"crash: {result.exception!r}")
    lines = result.stderr.splitlines()
    if case.refuse is not None:
        ok = result.exit_code == 2 and len(lines) == 1 and case.refuse in lines[0] and not out.exists()
        return Outcome(case.name, case.group, "refused" if ok else "failed",
                       lines[0] if lines else f"exit {result.exit_code}, expected a refusal naming {case.refuse}")
    if case.unsolvable is not None:
        ok = result.exit_code == 1 and len(lines) == 1 and case.unsolvable in lines[0]
        if ok and (out / "report.json").exists():  # files written for an uncertified result say so
            ok = json.loads((out / "report.json").read_text(encoding="utf-8"))["solver"]["status"] != "converged"
        return Outcome(case.name, case.group, "refused" if ok else "failed",
                       lines[0] if lines else f"exit {result.exit_code}, expected a failure naming {case.unsolvable}")
    if result.exit_code != 0:
        status = "refused" if result.exit_code == 2 and len(lines) == 1 else "failed"
        return Outcome(case.name, case.group, status if status == "failed" else "failed",
                       f"exit {result.exit_code}: {result.stderr.strip()}")
    problems = _finite_outputs(out)
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    signs, balance = report["sign_conditions"], report["equilibrium"]
    iterations = report["solver"]["iterations"]
    figures = {
        "relative_max_penetration": signs["relative_max_penetration"],
        "relative_min_nodal_force": signs["relative_min_nodal_force"],
        "relative_complementarity": signs["relative_complementarity"],
        "relative_force_residual": balance["relative_force_residual"],
        "relative_moment_residual": balance["relative_moment_residual"],
        "active_nodes": report["contact_zone"]["active_nodes"],
        "contact_nodes": report["contact_zone"]["contact_nodes"],
        "unknowns": report["unknowns"]["displacement"],
        "warnings": report.get("warnings", []),
    }
    cap = (case.data.get("solver") or {}).get("max_iterations", CAP)
    if report["solver"]["status"] != "converged" or iterations > cap:
        problems.append(f"status {report['solver']['status']} after {iterations} iterations")
    tolerance = case.expect.get("sign_tolerance", SIGN_TOLERANCE)
    for key in ("relative_max_penetration", "relative_complementarity"):
        if figures[key] > tolerance:
            problems.append(f"{key} {figures[key]:.2e}")
    if figures["relative_min_nodal_force"] < -tolerance:
        problems.append(f"relative_min_nodal_force {figures['relative_min_nodal_force']:.2e}")
    if report["method"]["name"] == "positive" and signs["min_multiplier"] < 0:
        problems.append(f"negative lambda {signs['min_multiplier']:.3g}")
    for key in ("relative_force_residual", "relative_moment_residual"):
        if figures[key] > max(tolerance, EQUILIBRIUM_TOLERANCE):
            problems.append(f"{key} {figures[key]:.2e}")
    expect = case.expect
    locking = [w for w in figures["warnings"] if w.startswith("nearly incompressible")]
    if "warning" in expect and bool(locking) != expect["warning"]:
        problems.append(f"warnings {figures['warnings']} (expected {'one' if expect['warning'] else 'none'})")
    untouched = [w for w in figures["warnings"] if w.startswith("no contact node touches")]
    if bool(untouched) != (figures["active_nodes"] == 0):
        problems.append(f"warnings {figures['warnings']} with {figures['active_nodes']} active nodes")
    if expect.get("active") == "all" and figures["active_nodes"] != figures["contact_nodes"]:
        problems.append(f"{figures['active_nodes']} of {figures['contact_nodes']} active, expected all")
    if expect.get("active") == "some" and figures["active_nodes"] == 0:
        problems.append("no active node, expected some")
    if expect.get("active") == "none":
        if figures["active_nodes"] != 0:
            problems.append(f"{figures['active_nodes']} active, expected none")
        import h5py

        with h5py.File(out / "solution.h5", "r") as h5:
            if np.abs(h5["contact/multiplier"][()]).max(initial=0.0) != 0.0:
                problems.append("non-zero multiplier with no active node")
    if "corner" in expect:
        import h5py

        with h5py.File(out / "solution.h5", "r") as h5:
            points, nodes = h5["mesh/points"][()], h5["contact/nodes"][()]
        corner = int(np.argmin(np.hypot(*points.T)))
        if (corner in nodes) != (expect["corner"] == "contact"):
            problems.append(f"corner node {'missing from' if corner not in nodes else 'among'} the contact nodes")
    import h5py

    with h5py.File(out / "solution.h5", "r") as h5:
        displacement = h5["fields/displacement"][()]
    outcome = Outcome(case.name, case.group, "failed" if problems else "solved", "; ".join(problems),
                      iterations, figures, displacement, report)
    return outcome


def compare_groups(outcomes: list[Outcome], cases: list[Extreme]) -> list[str]:
    """Cross-case checks: normalised solutions equal across E and load scales, rotation invariance."""
    problems = []
    by_name = {o.name: o for o in outcomes}
    for group in ("young", "load"):
        members = [(c, by_name[c.name]) for c in cases if c.group == group and "normalise" in c.expect
                   and by_name[c.name].status == "solved"]
        if len(members) < 2:
            continue
        ref_case, ref = members[0]
        u_ref = ref.displacement / ref_case.expect["normalise"]
        for case, outcome in members[1:]:
            u = outcome.displacement / case.expect["normalise"]
            difference = np.abs(u - u_ref).max() / np.abs(u_ref).max()
            outcome.figures["normalised_difference"] = float(difference)
            if difference > 1e-8:
                problems.append(f"{case.name}: normalised displacement differs by {difference:.2e}")
            if outcome.iterations != ref.iterations:
                problems.append(f"{case.name}: {outcome.iterations} iterations, {ref.iterations} at {ref_case.name}")
    rotations = [(c, by_name[c.name]) for c in cases if c.group == "rotation" and by_name[c.name].status == "solved"]
    base = next(((c, o) for c, o in rotations if c.mesh_file["angle"] == 0.0), None)
    if base is not None:
        u_ref = base[1].displacement
        for case, outcome in rotations:
            a = case.mesh_file["angle"]
            c, s = math.cos(a), math.sin(a)
            back = outcome.displacement @ np.array([[c, -s], [s, c]])  # Rᵀ u, row by row
            difference = np.abs(back - u_ref).max() / np.abs(u_ref).max()
            outcome.figures["rotated_back_difference"] = float(difference)
            if difference > 1e-10:
                problems.append(f"{case.name}: rotated-back displacement differs by {difference:.2e}")
    return problems


def run(fast: bool, largest: int = 1024, progress=None) -> dict:
    cases = catalogue(fast, largest)
    outcomes = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, case in enumerate(cases):
            started = time.perf_counter()
            outcome = run_case(case, Path(tmp) / f"case{i}")
            outcome.figures["seconds"] = time.perf_counter() - started
            outcomes.append(outcome)
            if progress:
                progress(f"{case.name:28s} {outcome.status:8s} it={outcome.iterations} {outcome.detail}")
    cross = compare_groups(outcomes, cases)
    counts = {s: sum(o.status == s for o in outcomes) for s in ("solved", "refused", "failed")}
    counts["tried"] = len(outcomes)
    counts["cross_check_failures"] = len(cross)
    return {
        "counts": counts,
        "cross_checks": cross,
        "cases": [{"name": o.name, "group": o.group, "status": o.status, "detail": o.detail,
                   "iterations": o.iterations, **o.figures} for o in outcomes],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--fast", action="store_true", help="only the default-suite subset")
    parser.add_argument("--largest", type=int, default=1024, help="finest square mesh: h = 1/LARGEST")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "extremes.json")
    args = parser.parse_args()
    results = run(args.fast, args.largest, progress=lambda line: print(line, flush=True))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2, default=float) + "\n", encoding="utf-8")
    counts = results["counts"]
    print(f"tried {counts['tried']}, solved {counts['solved']}, refused {counts['refused']}, "
          f"failed {counts['failed']}, cross-check failures {counts['cross_check_failures']}")
    for line in results["cross_checks"]:
        print("  " + line)
    sys.exit(1 if counts["failed"] or counts["cross_check_failures"] else 0)


if __name__ == "__main__":
    main()
