"""Residual estimator and adaptive refinement (method 4): effectivity, adaptive vs uniform.

    python benchmarks/adaptivity.py [--quick] [--out benchmarks/results]

Writes adaptivity.json and adaptivity_*.png into --out.

- manufactured (cases/manufactured.yaml from an 8×4 mesh): true errors are exact
  (report["errors"]); uniform = red refinement (the pipeline's --refine), adaptive = NVB
  with Dörfler θ = 0.5.
- square (cases/square.yaml from an 8×8 mesh): no exact solution. The reference is the
  last mesh of a long adaptive run (about 300k unknowns, η about 30× below the coarsest
  compared errors). Adaptive meshes of that run are nested in it, so their errors are
  exact nodal interpolation + the reference's stiffness. Uniform meshes are NVB-uniform
  (every triangle bisected twice per level: the same unknowns as red refinement, nested
  in the NVB family); their errors are taken on the common refinement of the uniform and
  reference meshes (exact for both P1 fields). Errors are compared only down to 3× the
  reference's own estimated error (η_ref / mean effectivity).
- Time: adaptive = cumulative seconds of the loop (assemble, solve, estimate, mark,
  refine, every step up to that one); uniform = assemble + solve + estimate of that level
  alone (mesh generation not charged), which favours uniform refinement.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from contactfem.adaptive import Reference, adapt  # noqa: E402
from contactfem.case import load_case  # noqa: E402
from contactfem.discretize import build_mesh, build_problem  # noqa: E402
from contactfem.estimator import estimate  # noqa: E402
from contactfem.mesh.adapt import bisect_uniform, label_longest_edge  # noqa: E402
from contactfem.report import exact_errors
from contactfem.solve import prepare, solve_case  # noqa: E402


def log(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


def manufactured(quick: bool) -> dict:
    case = load_case(ROOT / "cases" / "manufactured.yaml")
    case = replace(case, mesh=replace(case.mesh, divisions=(8, 4)))
    uniform = []
    for level in range(5 if quick else 6):
        started = time.perf_counter()
        problem = prepare(case, refine=level)
        outcome = solve_case(case, method="positive", problem=problem)
        result = estimate(problem, outcome.solution)
        seconds = time.perf_counter() - started
        error = exact_errors(problem, outcome.solution)["displacement_energy"]
        uniform.append({"level": level, "unknowns": problem.n_unknowns, "seconds": seconds, "eta": result.total,
                        "eta_terms": result.summary()["terms"], "energy_error": error,
                        "effectivity": result.total / error})
        log(f"manufactured uniform {level}: {problem.n_unknowns} unknowns, eta {result.total:.4g}, "
            f"error {error:.4g}, effectivity {result.total / error:.3f}")
    run = adapt(case, theta=0.5, max_unknowns=20_000 if quick else 70_000,
                progress=lambda m: log("manufactured adaptive " + m))
    adaptive = [{"step": r["step"], "unknowns": r["unknowns"], "seconds": r["seconds"],
                 "cumulative_seconds": r["cumulative_seconds"], "eta": r["eta"], "eta_terms": r["eta_terms"],
                 "energy_error": r["errors"]["displacement_energy"], "effectivity": r["effectivity"],
                 "min_angle": r["min_angle"]} for r in run.steps]
    return {"case": "cases/manufactured.yaml (divisions 8x4)", "reference": "exact", "uniform": uniform,
            "adaptive": adaptive, "effectivity_range": _range([r["effectivity"] for r in uniform + adaptive])}


def square(quick: bool) -> dict:
    case = load_case(ROOT / "cases" / "square.yaml")
    case = replace(case, mesh=replace(case.mesh, divisions=(8, 8)))
    initial = label_longest_edge(build_mesh(case))
    reference_unknowns = 60_000 if quick else 300_000
    kept: list[tuple[dict, object, object]] = []

    def keep(row, problem, solution):
        if row["unknowns"] <= reference_unknowns / 8:
            kept.append((row, problem, solution))

    run = adapt(case, theta=0.5, max_unknowns=reference_unknowns, mesh=initial, on_step=keep,
                progress=lambda m: log("square adaptive " + m))
    reference = Reference(run.result.problem, run.result.solution)
    adaptive = []
    for row, problem, solution in kept:
        error = reference.errors(problem, solution)["displacement_energy"]
        adaptive.append({"step": row["step"], "unknowns": row["unknowns"], "seconds": row["seconds"],
                         "cumulative_seconds": row["cumulative_seconds"], "eta": row["eta"],
                         "eta_terms": row["eta_terms"], "energy_error": error, "effectivity": row["eta"] / error,
                         "min_angle": row["min_angle"], "h_min": row["h_min"]})
    effectivity = float(np.mean([r["effectivity"] for r in adaptive]))
    floor = run.estimate.total / effectivity
    log(f"square reference: {run.result.problem.n_unknowns} unknowns, eta {run.estimate.total:.4g}, "
        f"estimated error {floor:.4g}")

    warm = build_problem(case, initial)
    estimate(warm, solve_case(case, method="positive", problem=warm).solution)  # first-call costs
    uniform = []
    mesh = initial
    for level in range(4 if quick else 6):
        if level:
            mesh = bisect_uniform(mesh, 2)
        started = time.perf_counter()
        problem = build_problem(case, mesh)
        outcome = solve_case(case, method="positive", problem=problem)
        result = estimate(problem, outcome.solution)
        seconds = time.perf_counter() - started
        error = reference.overlay_errors(problem, outcome.solution)["displacement_energy"]
        uniform.append({"level": level, "divisions": 8 * 2**level, "unknowns": problem.n_unknowns,
                        "seconds": seconds, "eta": result.total, "eta_terms": result.summary()["terms"],
                        "energy_error": error, "effectivity": result.total / error,
                        "above_reference_floor": error >= 3 * floor})
        log(f"square uniform {8 * 2**level}: {problem.n_unknowns} unknowns, eta {result.total:.4g}, "
            f"error {error:.4g}, effectivity {result.total / error:.3f}, {seconds:.2f} s")

    comparison = []
    for row in uniform:
        if not row["above_reference_floor"]:
            continue
        reached = [r for r in adaptive if r["energy_error"] <= row["energy_error"]]
        if not reached:
            continue
        first = reached[0]
        comparison.append({
            "energy_error": row["energy_error"],
            "uniform_unknowns": row["unknowns"], "uniform_seconds": row["seconds"],
            "adaptive_unknowns": first["unknowns"], "adaptive_cumulative_seconds": first["cumulative_seconds"],
            "adaptive_error": first["energy_error"],
            "unknowns_ratio": row["unknowns"] / first["unknowns"],
            "seconds_ratio": row["seconds"] / first["cumulative_seconds"],
        })
    return {
        "case": "cases/square.yaml (divisions 8x8)",
        "reference": {"kind": "last mesh of the adaptive run (NVB, nested with every adaptive step)",
                      "unknowns": run.result.problem.n_unknowns, "eta": run.estimate.total,
                      "estimated_energy_error": floor, "steps": len(run.steps),
                      "seconds": run.steps[-1]["cumulative_seconds"]},
        "uniform": uniform,
        "adaptive": adaptive,
        "comparison": comparison,
        "effectivity_range": _range([r["effectivity"] for r in adaptive]
                                    + [r["effectivity"] for r in uniform if r["above_reference_floor"]]),
    }, run


def _range(values) -> list[float]:
    return [float(min(values)), float(max(values))]


def plots(directory: Path, results: dict, square_run) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for key in ("manufactured", "square"):
        data = results[key]
        fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
        for label, rows, style in (("uniform", data["uniform"], "s-"), ("adaptive", data["adaptive"], "o-")):
            n = [r["unknowns"] for r in rows]
            err = [r["energy_error"] for r in rows]
            eta = [r["eta"] for r in rows]
            axes[0].loglog(n, err, style, label=f"{label}: energy error")
            axes[0].loglog(n, eta, style, mfc="none", alpha=0.5, label=f"{label}: η")
            t = [r.get("cumulative_seconds", r["seconds"]) for r in rows]
            axes[1].loglog(t, err, style, label=label)
            axes[2].semilogx(n, [r["effectivity"] for r in rows], style, label=label)
        n = np.array([r["unknowns"] for r in data["uniform"]], dtype=float)
        axes[0].loglog(n, data["uniform"][0]["energy_error"] * (n / n[0]) ** -0.5, "k:", label="N^(-1/2)")
        if key == "square":
            floor = data["reference"]["estimated_energy_error"]
            for ax in axes[:2]:
                ax.axhline(3 * floor, color="grey", lw=0.8, ls="--", label="3 × reference error")
        axes[0].set(xlabel="unknowns", ylabel="energy norm", title=f"{key}: error and estimator")
        axes[1].set(xlabel="seconds (adaptive: cumulative)", ylabel="energy error", title="error against time")
        axes[2].set(xlabel="unknowns", ylabel="η / energy error", title="effectivity index")
        axes[2].set_ylim(0, 1.3 * max(r["effectivity"] for r in data["uniform"] + data["adaptive"]))
        for ax in axes:
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
        fig.tight_layout()
        path = directory / f"adaptivity_{key}.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        written.append(str(path))
    return written


def mesh_plot(directory: Path, mesh, title: str) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 6))
    ax.triplot(mesh.points[:, 0], mesh.points[:, 1], mesh.triangles, lw=0.3, color="k")
    ax.set_aspect("equal")
    ax.set_title(title)
    path = directory / "adaptivity_square_mesh.png"
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return str(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller sizes (a minute)")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    warm = load_case(ROOT / "cases" / "square.yaml")
    solve_case(warm, problem=prepare(replace(warm, mesh=replace(warm.mesh, divisions=(8, 8)))))  # imports, first factorisation
    started = time.perf_counter()
    results = {"manufactured": manufactured(args.quick)}
    square_results, run = square(args.quick)
    results["square"] = square_results
    results["seconds"] = time.perf_counter() - started
    written = plots(args.out, results, run)
    # The adaptive mesh at about 5000 unknowns (a short rerun of the same loop).
    case = load_case(ROOT / "cases" / "square.yaml")
    case = replace(case, mesh=replace(case.mesh, divisions=(8, 8)))
    small = adapt(case, theta=0.5, max_unknowns=5000)
    written.append(mesh_plot(args.out, small.result.problem.mesh,
                             f"square, adaptive mesh ({small.result.problem.n_unknowns} unknowns)"))
    results["plots"] = written
    (args.out / "adaptivity.json").write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    log(f"wrote {args.out / 'adaptivity.json'} and {', '.join(written)}")


if __name__ == "__main__":
    main()
