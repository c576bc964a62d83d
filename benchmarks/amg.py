"""The iterative backend on the square of cases/square.yaml: time, peak memory, CG iterations
and the contact force against a direct factorisation, at N = 256, 512, 1024 divisions per
side (131 000 to 2.1 million unknowns) and N = 2048 (8.4 million) with the default install.

Usage:
    python benchmarks/amg.py                      # N = 256, 512, 1024: amg and the direct backend
    python benchmarks/amg.py --sizes 2048         # N = 2048: `auto` alone (which picks amg here)
    python benchmarks/amg.py --sizes 512 --repeat 3

Each run is `contactfem solve cases/square.yaml --refine R` end to end (meshing, assembly,
mesh sequencing, the Newton steps, post-processing and writing the files) in a process of
its own, whose peak RSS (resource.getrusage, RUSAGE_SELF) is that run's. N = 2048 runs
``auto`` only: its direct factorisation is the one that does not fit (about 18.7 GiB by the
cost model, 18.25 GB measured with CHOLMOD). Before it starts, the script reads
/proc/meminfo and refuses to run N = 2048 with less than 18 GiB available (the machine is
shared).

Writes JSON (--out, default benchmarks/results/amg.json): a run of some sizes keeps the
records of the others. Wall-clock seconds on a shared 2-core machine are noisy; CG
iterations and hierarchies are counts.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASE_FILE = ROOT / "cases" / "square.yaml"
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "amg.json"
BASE_DIVISIONS = 32
#: The memory a run of N = 2048 needs available before it starts, in GiB as `free -g` shows
#: it (the cost model's 12.9 GB peak and a margin).
LARGEST_NEEDS_GIB = 18.0
RECORD_PREFIX = "AMG-RECORD "
#: Sizes up to this run the direct backend too; above, the stored figures serve (a direct
#: solve at 2.1M unknowns peaks near 5 GB on a machine others share).
DIRECT_UP_TO = 512

WORKER = r"""
import json, resource, sys, time
started = time.perf_counter()
from contactfem.__main__ import main
sys.argv = ["contactfem", *sys.argv[1:]]
code = 0
try:
    main()
except SystemExit as exit:
    code = exit.code or 0
wall = time.perf_counter() - started
print("AMG-RECORD " + json.dumps({"wall_s": wall,
                                  "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}))
sys.exit(code)
"""


def available_gib() -> float:
    """MemAvailable of /proc/meminfo, in GiB."""
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) / 2**20
    return 0.0


def run(divisions: int, backend: str) -> dict:
    """One end-to-end solve in a process of its own; its record."""
    refine = (divisions // BASE_DIVISIONS).bit_length() - 1
    with tempfile.TemporaryDirectory(prefix="amg-bench-") as out:
        command = [sys.executable, "-c", WORKER, "solve", str(CASE_FILE), "--refine", str(refine),
                   "--backend", backend, "--out", out, "--quiet"]
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        done = subprocess.run(command, capture_output=True, text=True, env=env, cwd=ROOT)
        lines = [line for line in done.stdout.splitlines() if line.startswith(RECORD_PREFIX)]
        if done.returncode != 0 or not lines:
            raise SystemExit(f"N = {divisions}, {backend}: exit {done.returncode}\n{done.stderr[-2000:]}")
        measured = json.loads(lines[-1][len(RECORD_PREFIX):])
        report = json.loads((Path(out) / "report.json").read_text())
    solver = report["solver"]
    linear = solver.get("linear") or {}
    return {
        "divisions": divisions, "refine": refine, "requested": backend, "backend": solver["backend"],
        "backend_reason": solver.get("backend_reason"), "unknowns": report["unknowns"]["displacement"],
        "newton_steps": solver["iterations"], "hierarchies_or_factorizations": solver["factorizations"],
        "cg_iterations": [solve["iterations"] for solve in linear.get("solves", [])],
        "operator_complexity": [h["operator_complexity"] for h in linear.get("hierarchies", [])],
        "status": solver["status"], "certified": solver["certificate"]["passed"],
        "contact_force": report["contact_force"]["normal"], "active_nodes": report["contact_zone"].get("active_nodes"),
        "timings_s": report["timings"], **measured,
    }


def stored_forces(divisions: int) -> dict[str, float]:
    """The contact force of the square at ``divisions`` stored by other benchmarks: CHOLMOD
    (performance.json), MUMPS and GAMG on one rank (petsc_scaling.json)."""
    results, forces = ROOT / "benchmarks" / "results", {}
    performance = results / "performance.json"
    if performance.exists():
        for record in json.loads(performance.read_text())["records"]:
            if record.get("N") == divisions and record.get("method") == "positive":
                forces[f"{record['backend']} (performance.json)"] = record["contact_force"]
    scaling = results / "petsc_scaling.json"
    if scaling.exists():
        for record in json.loads(scaling.read_text())["records"]:
            if record.get("divisions") == divisions and record.get("ranks") == 1:
                forces[f"petsc {record['solver']}, 1 rank (petsc_scaling.json)"] = record["contact_force"]
    return forces


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 512, 1024])
    parser.add_argument("--repeat", type=int, default=1, help="runs of each size and backend (the best time is kept)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    data = json.loads(args.out.read_text()) if args.out.exists() else {"records": []}
    records = [r for r in data.get("records", []) if r["divisions"] not in args.sizes]
    for divisions in args.sizes:
        if divisions >= 2048 and available_gib() < LARGEST_NEEDS_GIB:
            raise SystemExit(f"N = {divisions}: only {available_gib():.1f} GiB available, "
                             f"{LARGEST_NEEDS_GIB:g} needed before it starts")
        backends = ["auto"] if divisions >= 2048 else ["amg", "auto"] if divisions <= DIRECT_UP_TO else ["amg"]
        for backend in backends:
            runs = [run(divisions, backend) for _ in range(args.repeat)]
            best = min(runs, key=lambda r: r["wall_s"])
            best["wall_s_all"] = [r["wall_s"] for r in runs]
            records.append(best)
            print(f"N = {divisions} {best['backend']:8s} {best['wall_s']:7.1f} s {best['peak_rss_gb']:6.2f} GB "
                  f"CG {best['cg_iterations']} force {best['contact_force']!r}", flush=True)
    records.sort(key=lambda r: (r["divisions"], r["backend"] != "amg"))
    by_size: dict[int, dict] = {}
    for record in records:
        by_size.setdefault(record["divisions"], {})[record["backend"]] = record["contact_force"]
    for record in records:
        if record["backend"] != "amg":
            continue
        force = record["contact_force"]
        direct = {f"{name} (this run)": value for name, value in by_size[record["divisions"]].items() if name != "amg"}
        references = {**direct, **stored_forces(record["divisions"])}
        record["force_vs"] = {name: abs(force - value) / abs(value) for name, value in references.items()}
    data.update({"benchmark": "benchmarks/amg.py", "case": "cases/square.yaml", "method": "positive",
                 "machine": {"python": platform.python_version(), "platform": platform.platform(),
                             "cpus": os.cpu_count()},
                 "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "records": records})
    args.out.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
