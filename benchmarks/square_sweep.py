"""Square case of the README at N x N divisions, both methods: time per stage, Newton iterations, contact.

Usage: python benchmarks/square_sweep.py [N ...] [--out FILE.json] [--workers W | --scheduler ADDRESS]
Writes a JSON list with one record per (N, method) and prints a markdown table. Each N runs
in a fresh subprocess (``--single N``), so that its peak RSS is its own; one after another,
or as tasks of a Dask cluster with --workers or --scheduler (benchmarks/sizes.py).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from contactfem.case import parse_case
from contactfem.io.registry import result_data, write_result
from contactfem.report import build_report
from contactfem.solve import prepare, solve_case

ROOT = Path(__file__).resolve().parents[1]
RECORD_PREFIX = "SQUARE-RECORDS "


def square_case(divisions: int):
    data = yaml.safe_load((ROOT / "cases" / "square.yaml").read_text())
    data["mesh"]["divisions"] = divisions
    return parse_case(yaml.safe_dump(data), source=ROOT / "cases" / f"square-{divisions}.yaml")


def run(divisions: int) -> list[dict]:
    case = square_case(divisions)
    timings: dict[str, float] = {}
    problem = prepare(case, timings=timings)
    records = []
    for method in ("positive", "standard"):
        started = time.perf_counter()
        outcome = solve_case(case, method=method, problem=problem)
        with tempfile.TemporaryDirectory() as directory:
            _, report = write_result(result_data(case, outcome, build_report(case, outcome)), Path(directory),
                                     case.output.files)
        records.append({
            "N": divisions,
            "method": method,
            "unknowns": report["unknowns"]["displacement"],
            "iterations": report["solver"]["iterations"],
            "active_per_iteration": [r["active"] for r in report["newton"]],
            "mesh_s": timings["mesh"],
            "assemble_s": timings["assemble"],
            "solve_s": outcome.timings["solve"],
            "postprocess_s": outcome.timings["postprocess"],
            "report_s": report["timings"]["report"],
            "write_s": report["timings"]["write"],
            "method_total_s": time.perf_counter() - started,
            "contact_force": report["contact_force"]["normal"],
            "contact_zone": [i["abscissa"] for i in report["contact_zone"]["intervals"]],
            "active_nodes": report["contact_zone"]["active_nodes"],
            "min_multiplier": report["sign_conditions"]["min_multiplier"],
            "backend": report["solver"]["backend"],
            "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
        })
        print(json.dumps(records[-1]), flush=True)
    return records


def run_subprocess(divisions: int) -> list[dict]:
    """:func:`run` in a fresh interpreter: the records of both methods at ``divisions``."""
    done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--single", str(divisions)],
                          capture_output=True, text=True, check=False, cwd=ROOT)
    for line in done.stdout.splitlines():
        if line.startswith(RECORD_PREFIX):
            return json.loads(line[len(RECORD_PREFIX):])
    tail = " | ".join((done.stderr or done.stdout).strip().splitlines()[-3:])
    raise RuntimeError(f"N = {divisions}: exit code {done.returncode}: {tail}")


def main() -> None:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from sizes import add_engine_options, run_sizes

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("sizes", nargs="*", type=int, default=[64, 256])
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--single", type=int, default=None, help=argparse.SUPPRESS)
    add_engine_options(parser)
    args = parser.parse_args()
    if args.single is not None:
        print(RECORD_PREFIX + json.dumps(run(args.single)), flush=True)
        return

    def lost(divisions: int, reason: str) -> list[dict]:
        raise SystemExit(f"square_sweep: N = {divisions} did not run: {reason}")

    records = [record for per_size in run_sizes(run_subprocess, args.sizes, scheduler=args.scheduler,
                                                workers=args.workers, lost=lost)
               for record in per_size]
    if args.out:
        args.out.write_text(json.dumps(records, indent=2) + "\n")
    print("| N | method | unknowns | Newton | mesh s | assemble s | solve s | write s | contact force | zone |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in records:
        zone = ", ".join(f"[{a:.4f}, {b:.4f}]" for a, b in r["contact_zone"])
        print(f"| {r['N']} | {r['method']} | {r['unknowns']} | {r['iterations']} | {r['mesh_s']:.2f} | "
              f"{r['assemble_s']:.2f} | {r['solve_s']:.2f} | {r['write_s']:.2f} | {r['contact_force']:.2f} | {zone} |")


if __name__ == "__main__":
    main()
