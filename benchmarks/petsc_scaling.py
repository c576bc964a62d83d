"""The petsc backend's cost per rank: the square of cases/square.yaml at --refine 4 (512 divisions,
525 000 unknowns) and --refine 5 (1024, 2.1 million), on 1 and 2 MPI ranks.

Usage:
    python benchmarks/petsc_scaling.py                          # refine 4 and 5, 1 and 2 ranks, MUMPS
    python benchmarks/petsc_scaling.py --refine 4 --ranks 1 2   # choose sizes and rank counts
    python benchmarks/petsc_scaling.py --solvers mumps gamg     # also CG + GAMG
    mpiexec -n 2 python benchmarks/petsc_scaling.py --single 4 --solver mumps   # one run: a JSON record on stdout
    python benchmarks/petsc_scaling.py --refine 5 --ranks 4 --write   # through `contactfem solve`, files written

Each (refine, ranks, solver) runs as its own ``mpiexec -n P`` job, so that each rank's peak
RSS (getrusage maxrss) is that run's. A run records, per rank: seconds of mesh (its piece,
or the whole case), assemble (loads, supports, contact and its share of the stiffness),
solve (mesh sequencing and the Newton steps), gather (solution and K u to rank 0), and on
rank 0 postprocess (stresses, contact fields; with ``--mesh pieces``, the default, each rank
refines only its piece of the coarse mesh and rank 0 meshes the case whole for the writers
after the solve, a memory peak its figure includes); the factorisation seconds of each Newton
step, the iterations of each linear solve (1 for MUMPS) and what MUMPS reports of its
factors (entries, flops, megabytes per rank); its peak RSS; and the totals: Newton steps,
factorisations, wall time. With ``--write`` a run is ``contactfem solve`` itself, its files
written into a temporary directory (on the pieces mesh, every rank its share, see
docs/outputs.md), and each rank's peak RSS includes the writing (``solve_peak_rss_gb`` is the
peak at the end of the solve); the record comes from its report.json. BLAS threads are pinned
to one per rank (OMP_NUM_THREADS=1) so that 1 and 2 ranks use the same cores' worth.

Writes JSON (--out, default benchmarks/results/petsc_scaling.json, rewritten after every
run) and prints a markdown table. Wall-clock seconds of single runs: on a busy machine
they are noisy.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE_FILE = ROOT / "cases" / "square.yaml"
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "petsc_scaling.json"
RECORD_PREFIX = "DISTRIBUTED-RECORD "
GB = 1024.0**3


def single(refine: int, solver: str, method: str, mesh: str = "pieces") -> None:
    """One run on the ranks of this mpiexec job; rank 0 prints the record."""
    from contactfem.case import load_case
    from contactfem.distributed import solve_distributed

    started = time.perf_counter()
    case = load_case(CASE_FILE)
    outcome = solve_distributed(case, method=method, refine=refine, solver=solver,
                                distributed_mesh=mesh == "pieces")
    wall = time.perf_counter() - started
    if outcome.result is None:
        return
    result = outcome.result
    kernel = result.kernel
    per_rank = outcome.parallel["per_rank"]
    record = {
        "refine": refine,
        "divisions": 32 * 2**refine,
        "ranks": outcome.parallel["ranks"],
        "mesh": outcome.parallel["mesh"],
        "solver": solver,
        "method": method,
        "unknowns": result.problem.n_unknowns,
        "contact_nodes": int(len(result.problem.contact.nodes)),
        "status": kernel.status.value,
        "newton_steps": kernel.iterations,
        "factorizations": kernel.factorizations,
        "sequencing": dict(result.sequencing),
        "active_nodes": int(kernel.active.sum()),
        "contact_force": float(kernel.nodal_force.sum()),
        "wall_s": wall,
        "stages_s": {stage: max(rank["seconds"].get(stage, 0.0) for rank in per_rank)
                     for stage in ("mesh", "assemble", "solve", "gather")},
        "postprocess_s": result.timings.get("postprocess", 0.0),
        "per_rank": [{"rank": rank["rank"], "owned_unknowns": rank["owned_unknowns"],
                      "owned_triangles": rank["owned_triangles"], "peak_rss_gb": rank["peak_rss_bytes"] / GB,
                      "factor_s": rank["factor_seconds"], "linear_iterations": rank["linear_iterations"],
                      "factor": rank["factor"], "seconds": rank["seconds"],
                      **({"solve_peak_rss_gb": rank["solve_peak_rss_bytes"] / GB}
                         if "solve_peak_rss_bytes" in rank else {})} for rank in per_rank],
        "max_peak_rss_gb": outcome.parallel["max_peak_rss_bytes"] / GB,
        "blas_libraries": blas_libraries(),
    }
    print(RECORD_PREFIX + json.dumps(record), flush=True)


def single_written(refine: int, solver: str, method: str, mesh: str = "pieces") -> None:
    """One run of ``contactfem solve`` on the ranks of this mpiexec job, its files written into a
    temporary directory; rank 0 prints the record (from report.json and the files' sizes)."""
    import tempfile

    from mpi4py import MPI

    from contactfem.cli.cmd_solve import solve

    if mesh != "pieces":
        raise SystemExit("--write measures the solve command, whose mesh is in pieces when the case allows")
    world = MPI.COMM_WORLD
    directory = world.bcast(tempfile.mkdtemp(prefix="petsc-scaling-") if world.Get_rank() == 0 else None, root=0)
    out = Path(directory) / "result"
    started = time.perf_counter()
    try:
        solve.main([str(CASE_FILE), "--backend", "petsc", "--petsc-solver", solver, "--method", method,
                    "--refine", str(refine), "--out", str(out), "--quiet"], standalone_mode=False)
    except SystemExit as stop:  # exit 1: not certified, the files written all the same
        if stop.code not in (0, 1, None):
            raise
    wall = time.perf_counter() - started
    world.Barrier()
    if world.Get_rank() != 0:
        return
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    parallel = report["parallel"]
    files = {path.name: path.stat().st_size for path in sorted(out.iterdir())}
    shutil.rmtree(directory)
    record = {
        "refine": refine, "divisions": 32 * 2**refine, "ranks": parallel["ranks"], "mesh": parallel["mesh"],
        "solver": solver, "method": method, "written": True, "unknowns": report["unknowns"]["displacement"],
        "contact_nodes": report["mesh"]["contact_nodes"], "status": report["solver"]["status"],
        "newton_steps": report["solver"]["iterations"], "factorizations": report["solver"]["factorizations"],
        "active_nodes": report["contact_zone"]["active_nodes"], "contact_force": report["contact_force"]["normal"],
        "wall_s": wall,
        "stages_s": {stage: max(rank["seconds"].get(stage, 0.0) for rank in parallel["per_rank"])
                     for stage in ("mesh", "assemble", "solve", "gather")},
        "write_s": report["timings"].get("write", 0.0),
        "files_bytes": files,
        "per_rank": [{"rank": rank["rank"], "owned_unknowns": rank["owned_unknowns"],
                      "owned_triangles": rank["owned_triangles"], "peak_rss_gb": rank["peak_rss_bytes"] / GB,
                      "solve_peak_rss_gb": rank.get("solve_peak_rss_bytes", rank["peak_rss_bytes"]) / GB,
                      "factor_s": rank["factor_seconds"], "linear_iterations": rank["linear_iterations"],
                      "factor": rank["factor"], "seconds": rank["seconds"]} for rank in parallel["per_rank"]],
        "max_peak_rss_gb": parallel["max_peak_rss_bytes"] / GB,
        "blas_libraries": blas_libraries(),
    }
    print(RECORD_PREFIX + json.dumps(record), flush=True)


def blas_libraries() -> list[str]:
    """The BLAS and LAPACK shared objects this process mapped (which of Debian's alternatives
    PETSc and MUMPS run on: the reference one or OpenBLAS), from /proc/self/maps."""
    try:
        maps = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return []
    paths = {line.split()[-1] for line in maps if line.split()[-1].startswith("/")}
    return sorted(os.path.realpath(path) for path in paths
                  if any(name in Path(path).name for name in ("libblas.so", "liblapack.so", "libopenblas")))


def _environment(extra: dict[str, str] | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env.update({"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                # Open MPI refuses root and more ranks than slots unless told; other MPIs ignore these.
                "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                "OMPI_MCA_rmaps_base_oversubscribe": "1"})
    env.update(extra or {})
    return env


def run(refine: int, ranks: int, solver: str, method: str, timeout: float, mesh: str = "pieces",
        environment: dict[str, str] | None = None, write: bool = False) -> dict:
    """One ``mpiexec -n ranks`` job; ``environment`` adds to its variables (PETSC_OPTIONS, a
    library path)."""
    mpiexec = shutil.which("mpiexec")
    if mpiexec is None:
        return {"refine": refine, "ranks": ranks, "solver": solver, "mesh": mesh, "error": "no mpiexec on the PATH"}
    command = [mpiexec, "-n", str(ranks), sys.executable, str(Path(__file__).resolve()), "--single", str(refine),
               "--solver", solver, "--method", method, "--mesh", mesh, *(["--write"] if write else [])]
    started = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=_environment(environment))
    except subprocess.TimeoutExpired:
        return {"refine": refine, "ranks": ranks, "solver": solver, "mesh": mesh, "error": f"timed out after {timeout:.0f} s"}
    for line in done.stdout.splitlines():
        if line.startswith(RECORD_PREFIX):
            record = json.loads(line[len(RECORD_PREFIX):])
            record["job_s"] = time.perf_counter() - started
            return record
    # The Python error, not mpiexec's epilogue: the last line naming an error, else the tail.
    lines = (done.stderr + done.stdout).strip().splitlines()
    errors = [line for line in lines if "Error" in line]
    return {"refine": refine, "ranks": ranks, "solver": solver, "mesh": mesh,
            "error": f"exit {done.returncode}: " + (errors[-1] if errors else " | ".join(lines[-5:]))}


def table(records: list[dict]) -> str:
    lines = ["| unknowns | ranks | solver | mesh | Newton | mesh s | assemble s | solve s | gather s | wall s "
             "| factor s (each) | peak RSS per rank GB |",
             "|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---|---|"]
    for r in records:
        if "error" in r:
            lines.append(f"| refine {r['refine']} | {r['ranks']} | {r['solver']} | {r.get('mesh', '')} | {r['error']} "
                         "|||||||")
            continue
        stages = r["stages_s"]
        factors = ", ".join(f"{s:.2f}" for s in r["per_rank"][0]["factor_s"])
        memory = " / ".join(f"{rank['peak_rss_gb']:.2f}" for rank in r["per_rank"])
        lines.append(f"| {r['unknowns']:,} | {r['ranks']} | {r['solver']} | {r.get('mesh', 'replicated')} | "
                     f"{r['newton_steps']} | "
                     f"{stages['mesh']:.2f} | {stages['assemble']:.2f} | {stages['solve']:.2f} | "
                     f"{stages['gather']:.2f} | {r['wall_s']:.2f} | {factors} | {memory} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--refine", type=int, nargs="+", default=[4, 5])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--solvers", nargs="+", default=["mumps"], choices=["mumps", "gamg"])
    parser.add_argument("--method", default="positive", choices=["positive", "standard"])
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    parser.add_argument("--mesh", default="pieces", choices=["pieces", "replicated"],
                        help="each rank refines its piece of the coarse mesh, or meshes the whole case")
    parser.add_argument("--write", action="store_true",
                        help="run `contactfem solve` with its files written (peak memory includes the writing)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--single", type=int, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--solver", default="mumps", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.single is not None:
        (single_written if args.write else single)(args.single, args.solver, args.method, args.mesh)
        return

    document = {"benchmark": "distributed", "case": str(CASE_FILE.relative_to(ROOT)),
                "command": " ".join(sys.argv), "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "machine": {"python": platform.python_version(), "platform": platform.platform(),
                            "cpus": os.cpu_count()},
                "records": []}
    # Runs of other sizes, rank counts, solvers or meshes stay: each (refine, ranks, solver,
    # mesh) has one record, the latest (records before the mesh option were replicated).
    kept = json.loads(args.out.read_text(encoding="utf-8"))["records"] if args.out.exists() else []
    planned = {(r, p, s, args.mesh, args.write) for r in args.refine for p in args.ranks for s in args.solvers}
    document["records"] = [r for r in kept if (r.get("refine"), r.get("ranks"), r.get("solver"),
                                               r.get("mesh", "replicated"), r.get("written", False)) not in planned]
    for refine in args.refine:
        for solver in args.solvers:
            for ranks in args.ranks:
                print(f"refine {refine}, {ranks} rank(s), {solver} ...", flush=True)
                record = run(refine, ranks, solver, args.method, args.timeout, args.mesh, write=args.write)
                document["records"].append(record)
                args.out.parent.mkdir(parents=True, exist_ok=True)
                args.out.write_text(json.dumps(document, indent=2, sort_keys=True) + "\n")
                print(table([record]).splitlines()[-1], flush=True)
    document["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    args.out.write_text(json.dumps(document, indent=2, sort_keys=True) + "\n")
    print(table(document["records"]))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
