"""Where a rough profile's contact solve spends its time, part by part, in linear solves.

Usage:
    python benchmarks/rough_breakdown.py                    # 1 000, 4 000 and 8 000 points
    python benchmarks/rough_breakdown.py --sizes 1000 16000 --repeat 15

The case is benchmarks/rough.py's (cases/rough.yaml with a seeded self-affine profile of N
points). Each part of what ``solve_case`` does in its contact solve is run alone, the
fastest of ``--repeat`` runs, timed in *processor* seconds (``time.process_time``: all of
this process's threads), which a shared machine's other work inflates far less than the
wall clock; each is divided by one linear solve of the fine mesh timed the same way
(benchmarks/performance.py ``linear_system``):

- the coarser mesh request (:func:`contactfem.sequencing.coarser`: decimating the
  profile, estimating each level's triangles), meshing and assembling that level, its
  kernel system, its solve from the translation start (the cold start every coarse level
  makes) and from its own answer (what a perfect start would cost), and the prediction of
  the fine set from it (:func:`contactfem.sequencing.predict_active_set`, the half-plane
  correction included);
- the fine level's kernel system, its solver and analysis, and its solve from the
  predicted set and from its own answer, with a solver analysed beforehand;
- the whole contact solve (``timings["solve"]``).

The parts overlap in a real solve only where a worker thread runs beside the coarse levels
(:data:`contactfem.solve.BESIDE_COARSER_FROM`), so their sum exceeds the whole there. The
table goes to benchmarks/results/rough_breakdown.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from contactfem.threads import one_blas_thread

one_blas_thread()  # as the command runs, before numpy loads

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
OUT = ROOT / "benchmarks" / "results" / "rough_breakdown.json"
PARTS = ("coarse request", "coarse mesh and assembly", "coarse system", "coarse solve, cold",
         "coarse solve from its answer", "prediction", "fine system", "fine solver and analysis",
         "fine solve from the prediction", "fine solve from its answer", "contact solve")


def best_seconds(task, repeat: int) -> float:
    """The fewest processor seconds of ``repeat`` runs of ``task``."""
    best = float("inf")
    for _ in range(repeat):
        started = time.process_time()
        task()
        best = min(best, time.process_time() - started)
    return best


def breakdown(points: int, directory: Path, repeat: int) -> dict:
    """One size's parts, in processor seconds and in linear solves of the fine mesh."""
    from performance import linear_system
    from rough import case_text, write_surface

    from contactfem.case import load_case
    from contactfem.kernel import solve_contact
    from contactfem.kernel.schur import ActiveSetSolver
    from contactfem.linalg import factorize
    from contactfem.methods import get_method
    from contactfem.sequencing import coarser, predict_active_set
    from contactfem.solve import SEQUENCING_METHOD, _contact_fields, _contact_solve, prepare, solve_case

    csv = directory / f"profile-{points}.csv"
    write_surface(csv, points)
    path = directory / f"rough-{points}.yaml"
    path.write_text(case_text(csv), encoding="utf-8")
    case = load_case(path)
    problem = prepare(case)
    method = get_method("positive")
    solved = solve_case(case, method="positive", problem=problem)
    fine = problem.contact_system(method)
    matrix, rhs = linear_system(fine.system)
    backend = solved.backend
    baseline = best_seconds(lambda: factorize(matrix, backend, check=False).solve(rhs), repeat)

    request, refine = coarser(problem.mesh_request, problem.refinements)
    level = prepare(case, refine=refine, request=request)
    reduced = level.contact_system(get_method(SEQUENCING_METHOD))
    cold = solve_contact(reduced.system, backend=backend)
    fields = _contact_fields(level, reduced.displacement(cold.displacement), cold)
    c = solved.kernel.c
    predicted = predict_active_set(problem.contact, fields, c, problem.law)

    def fine_solve(start):
        linear = ActiveSetSolver(fine.system, backend, tolerance=case.solver.tolerance)
        linear.analyse()
        return lambda: solve_contact(fine.system, c=c, initial_active=start, linear=linear,
                                     tolerance=case.solver.tolerance)

    def fresh(make):
        # A solve that builds its solver inside the timed task would time the analysis too:
        # each run gets a solver analysed outside it.
        tasks = [make() for _ in range(repeat)]
        return min(best_seconds(task, 1) for task in tasks)

    seconds = {
        "coarse request": best_seconds(lambda: coarser(problem.mesh_request, problem.refinements), repeat),
        "coarse mesh and assembly": best_seconds(lambda: prepare(case, refine=refine, request=request), repeat),
        "coarse system": best_seconds(lambda: level.contact_system(get_method(SEQUENCING_METHOD)), repeat),
        "coarse solve, cold": best_seconds(lambda: solve_contact(reduced.system, backend=backend), repeat),
        "coarse solve from its answer": best_seconds(
            lambda: solve_contact(reduced.system, backend=backend, initial_active=cold.active), repeat),
        "prediction": best_seconds(lambda: predict_active_set(problem.contact, fields, c, problem.law), repeat),
        "fine system": best_seconds(lambda: problem.contact_system(method), repeat),
        "fine solver and analysis": best_seconds(
            lambda: ActiveSetSolver(fine.system, backend, tolerance=case.solver.tolerance).analyse(), repeat),
        "fine solve from the prediction": fresh(lambda: fine_solve(predicted)),
        "fine solve from its answer": fresh(lambda: fine_solve(solved.kernel.active)),
        # What solve_case times as its contact solve: coarse levels and every Newton step.
        "contact solve": best_seconds(lambda: _contact_solve(case, problem, method, backend, lambda _: None), repeat),
    }
    return {
        "points": points, "unknowns": int(problem.n_unknowns), "coarse_unknowns": int(level.n_unknowns),
        "coarse_iterations": cold.iterations, "coarse_factorizations": cold.factorizations,
        "fine_iterations": solved.kernel.iterations, "predicted_active": int(predicted.sum()),
        "active": int(solved.kernel.active.sum()), "baseline_s": baseline,
        "seconds": seconds, "linear_solves": {part: value / baseline for part, value in seconds.items()},
    }


def table(records: list[dict]) -> str:
    lines = ["| part | " + " | ".join(f"{r['points']} points ({r['unknowns']} unknowns)" for r in records) + " |",
             "|---|" + "---:|" * len(records)]
    for part in PARTS:
        lines.append(f"| {part} | " + " | ".join(f"{1e3 * r['seconds'][part]:.1f} ms, {r['linear_solves'][part]:.2f}"
                                              for r in records) + " |")
    lines.append("| one linear solve | " + " | ".join(f"{1e3 * r['baseline_s']:.1f} ms" for r in records) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", type=int, default=[1000, 4000, 8000], help="profile points")
    parser.add_argument("--repeat", type=int, default=9, help="runs of each part; the fastest counts")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    from performance import machine_info

    with tempfile.TemporaryDirectory(prefix="contactfem-breakdown-") as tmp:
        breakdown(200, Path(tmp), 1)  # warm-up: imports, Triangle, the first factorisation
        records = [breakdown(points, Path(tmp), args.repeat) for points in args.sizes]
    result = {"benchmark": "benchmarks/rough.py's profile, each part of the contact solve alone",
              "started": time.strftime("%Y-%m-%d %H:%M:%S %Z"), "command": " ".join(["python", *sys.argv]),
              "clock": "process_time, fastest of --repeat", "repeat": args.repeat, "machine": machine_info(),
              "records": records}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(table(records))


if __name__ == "__main__":
    main()
