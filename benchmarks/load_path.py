"""What a load path costs against one solve of the same mesh.

A path of S steps solves the case at S load factors with one linear solver
(:func:`contactfem.kernel.solve_path`): the factorisation and the Schur columns of the
contact nodes carry over from step to step, a new load costs no solve while the set is
one two steps have shared, and each step starts from the coarser levels' path solved at
its factor or from the previous steps' set extrapolated, whichever missed fewer nodes of
the last step (:class:`contactfem.sequencing.PredictedStarts`). What it still pays for is
the contact zone's change: every node that becomes active after the first step costs one
column, or the kernel refactorises when that is cheaper; and the coarser levels' steps.

Scenes (each at one or more mesh sizes, ≥ 100 000 unknowns for the headline):
- ``square``: cases/square.yaml (traction on the top, no initial gap): the solution is
  proportional to the load, the active set the same at every factor;
- ``hertz_platen``: cases/hertz_platen.yaml (a platen force on the quarter disk): the
  contact zone grows like √P, so most of its nodes join along the path;
- ``hertz_tenfold``: the same platen loaded in equal steps of the contact width from 0.09
  of it (factors (0.09 + 0.91 i / (S − 1))², the first 0.0081): the zone grows ten-fold and
  more, a few nodes joining at every step;
- ``punch``: a flat punch pressed by a platen force into a block: the zone is the punch
  face from the first step on, the pressure grows;
- ``rough``: cases/rough.yaml (a block whose base is a 4 001-point rough profile, its top
  pushed down): asperities come into contact step by step, from tens of active nodes in a
  few patches to hundreds in a hundred and more, and the zone stiffens as they do.

Measured per scene: the path's contact solve (seconds, factorisations, solves with the
factor, Newton steps), one solve of the final load on the same mesh (as ``contactfem
solve`` runs it, with mesh sequencing), and their ratio; the best of ``--repeat`` runs.

Usage: python benchmarks/load_path.py [--quick] [--steps 20] [--out benchmarks/results/load_path.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import time
from pathlib import Path

from contactfem.threads import one_blas_thread

one_blas_thread()  # as the command runs a solve, before numpy loads

import yaml  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def scene(name: str, steps: int, refine: int):
    from contactfem.case import parse_case

    if name == "punch":
        data = {
            "title": "flat punch pressed by a platen force",
            "geometry": {"polygon": {"vertices": [[-1, 0], [1, 0], [1, 1], [-1, 1]],
                                     "edges": ["face", "right", "top", "left"]}},
            "mesh": {"size": 0.05, "contact_size": 0.004, "grading": 0.2},
            "material": {"E": 1.0e6, "nu": 0.3},
            "boundary": {"face": "contact", "top": {"platen": {"force": 2.0e3}}, "left": "symmetry",
                         "right": "free"},
            "obstacle": {"segment": [[-0.5, 0], [0.5, 0]]},
        }
    elif name == "hertz_tenfold":
        data = yaml.safe_load((ROOT / "cases" / "hertz_platen.yaml").read_text(encoding="utf-8"))
    else:
        data = yaml.safe_load((ROOT / "cases" / f"{name}.yaml").read_text(encoding="utf-8"))
    data["load_path"] = {"steps": steps}
    if name == "hertz_tenfold":
        # Equal steps of the zone's width (a ~ √P) from 0.09 of it: the zone grows eleven-fold.
        data["load_path"] = {"factors": [round((0.09 + 0.91 * i / (steps - 1)) ** 2, 6) for i in range(steps)]}
    data.setdefault("mesh", {})["refine"] = refine
    data.pop("output", None)
    return parse_case(yaml.safe_dump(data, sort_keys=False), source=ROOT / "cases" / f"{name}-path.yaml")


def measure(name: str, steps: int, refine: int, backend: str, repeat: int) -> dict:
    from contactfem.solve import solve_case, solve_load_path

    case = scene(name, steps, refine).with_solver(backend=backend)
    single = dataclasses.replace(case, load_path=None)
    best_path = best_one = None
    for _ in range(repeat):
        started = time.perf_counter()
        path = solve_load_path(case)
        path_total = time.perf_counter() - started
        started = time.perf_counter()
        one = solve_case(single)
        one_total = time.perf_counter() - started
        if best_path is None or path.timings["solve"] < best_path[0].timings["solve"]:
            best_path = (path, path_total)
        if best_one is None or one.timings["solve"] < best_one[0].timings["solve"]:
            best_one = (one, one_total)
    path, path_total = best_path
    one, one_total = best_one
    final = path.steps[-1]
    return {
        "scene": name,
        "refine": refine,
        "unknowns": final.problem.n_unknowns,
        "contact_nodes": int(len(final.problem.contact.nodes)),
        "steps": len(path.steps),
        "backend": one.backend,
        "active_first_last": [int(path.steps[0].kernel.active.sum()), int(final.kernel.active.sum())],
        "path": {
            "contact_solve_seconds": path.timings["solve"],
            "postprocess_seconds": path.timings["postprocess"],
            "end_to_end_seconds": path_total,
            "factorizations": path.factorizations,
            "solves_with_the_factor": sum(s.kernel.column_solves for s in path.steps),
            "newton_steps": sum(s.kernel.iterations for s in path.steps),
            "coarse_levels": dict(path.sequencing),
        },
        "one_solve": {
            "contact_solve_seconds": one.timings["solve"],
            "end_to_end_seconds": one_total,
            "factorizations": one.kernel.factorizations,
            "newton_steps": one.kernel.iterations,
        },
        "ratio_contact_solve": path.timings["solve"] / one.timings["solve"],
        "ratio_end_to_end": path_total / one_total,
        "agrees_with_one_solve": bool(
            abs(final.solution.contact.nodal_force.sum() - one.solution.contact.nodal_force.sum())
            <= 1e-8 * abs(one.solution.contact.nodal_force.sum())),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small meshes only (a smoke test)")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--backend", default="auto")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "load_path.json")
    args = parser.parse_args()
    from contactfem.linalg import resolve_backend

    plan = ([("square", 0), ("hertz_platen", 0), ("punch", 0), ("rough", 0)] if args.quick else
            [("square", 3), ("hertz_platen", 1), ("hertz_platen", 2), ("hertz_tenfold", 1), ("hertz_tenfold", 2),
             ("punch", 2), ("rough", 0), ("rough", 1), ("rough", 2)])
    rows = []
    for name, refine in plan:
        row = measure(name, args.steps, refine, args.backend, args.repeat)
        rows.append(row)
        print(f"{name:13s} refine {refine}: {row['unknowns']:8d} unknowns, active {row['active_first_last']}, "
              f"path {row['path']['contact_solve_seconds']:.2f} s ({row['path']['factorizations']} fact., "
              f"{row['path']['solves_with_the_factor']} solves), one solve {row['one_solve']['contact_solve_seconds']:.2f} s"
              f" -> ratio {row['ratio_contact_solve']:.2f} (end to end {row['ratio_end_to_end']:.2f})", flush=True)
    result = {"benchmark": "load_path", "steps": args.steps, "backend": resolve_backend(args.backend),
              "machine": {"python": platform.python_version(), "platform": platform.platform()}, "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
