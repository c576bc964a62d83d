"""Measure the rates of contactfem.linalg.costs: seconds per counted unit of work.

Usage:
    python benchmarks/linalg_costs.py        # the square at N = 32 ... 512, the rough profile at 1k ... 64k points
    python benchmarks/linalg_costs.py --squares 64 128 --rough 4000 --repeat 5

The package never reads a clock: it counts (factor entries, flops from column counts,
columns, the factor entries a forward column's path reaches) and divides by rates that
live in contactfem/linalg/costs.py. This script is where those rates come from. On the
kernel's own matrices (the square's stiffness and the rough profile's graded mesh, their
supports masked as the kernel factorises them), it times each operation (the fastest of
``--repeat`` runs), pairs it with its counts, and fits:

- the numeric factorisation: seconds = flops / factor_flops + entries / factor_entries
  (non-negative least squares on relative errors), per kind of factor (CHOLMOD
  supernodal or simplicial, as CHOLMOD chooses; cvxopt's interface; SuperLU);
- the ordering and symbolic analysis: m log2 m / seconds for m matrix entries (median; its
  time per entry grows with the matrix, by 2x from 25 000 to 6 million entries);
- a full solve, one right-hand side: factor entries / seconds (median); each further
  right-hand side of a block of 16: 15 entries / (its seconds less the single solve's);
- CHOLMOD's blocked sparse forward solve: factor entries / seconds per column (median);
- its pattern solve: seconds per column = reached entries / pattern_entries + fixed
  seconds (non-negative least squares per kind: a simplicial factor's, a converted
  supernodal one's);
- the conversion of a supernodal factor to a simplicial one: stored entries / seconds;
- a dense LU (the Schur complement's): 2 k³ / 3 / seconds.

Writes benchmarks/results/linalg_costs.json (the records and the fitted rates); the rates
are copied into costs.py by hand, with where they were measured. ``--refit FILE`` fits
again from the records of an earlier run, measuring nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "linalg_costs.json"
FORWARD_COLUMNS = 64


def best(function, repeat: int) -> float:
    """The fastest of ``repeat`` runs of ``function()``, in seconds."""
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        function()
        times.append(time.perf_counter() - started)
    return min(times)


def kernel_matrix(case) -> sp.csr_matrix:
    """The case's stiffness with its supports masked as the kernel factorises it."""
    from performance import linear_system

    from contactfem.methods import get_method
    from contactfem.solve import prepare

    matrix, _ = linear_system(prepare(case).contact_system(get_method("positive")).system)
    matrix.eliminate_zeros()
    return sp.csr_matrix(matrix)


def rough_case(points: int, directory: Path):
    import rough

    from contactfem.case import load_case

    csv = directory / f"profile-{points}.csv"
    rough.write_surface(csv, points)
    path = directory / f"rough-{points}.yaml"
    path.write_text(rough.case_text(csv), encoding="utf-8")
    return load_case(path)


def unit_columns(n: int, k: int, seed: int) -> sp.csc_matrix:
    """k unit vectors at rows spread over the unknowns (the kernel's columns are e_j and rows of K)."""
    rows = np.random.default_rng(seed).choice(n, size=min(k, n), replace=False)
    return sp.csc_matrix((np.ones(len(rows)), (rows, np.arange(len(rows)))), shape=(n, len(rows)))


def direct_record(matrix: sp.csr_matrix, repeat: int) -> dict:
    """CHOLMOD called directly: analysis, numeric factorisation, solves, both forward routes."""
    from contactfem.linalg.cholmod_direct import DirectCholmodFactor

    n = matrix.shape[0]
    analysis_s = best(lambda: DirectCholmodFactor.analyse(matrix, "m"), repeat)
    analysis = DirectCholmodFactor.analyse(matrix, "m")
    factor_s = best(lambda: DirectCholmodFactor(matrix, "m", analysis), repeat)
    factor = DirectCholmodFactor(matrix, "m", analysis)
    cost = factor.cost
    rhs = np.random.default_rng(1).standard_normal((n, 16))
    solve_s = best(lambda: factor.solve(rhs[:, 0]), 2 * repeat)
    block_s = best(lambda: factor.solve(rhs), repeat) / 16
    columns = unit_columns(n, FORWARD_COLUMNS, 2)
    k = columns.shape[1]
    blocked_s = best(lambda: factor._blocked_forward(columns), repeat) / k
    record = {"size": n, "matrix_entries": cost.matrix_entries, "entries": cost.entries, "flops": cost.flops,
              "kind": cost.kind, "spread": cost.flops * n / float(np.sum(analysis.column_counts, dtype=float)) ** 2,
              "analysis_s": analysis_s, "factor_s": factor_s, "solve_s": solve_s, "block_solve_s": block_s,
              "blocked_column_s": blocked_s, "forward_columns": k}
    if not analysis.simplicial:
        one = unit_columns(n, 1, 3)
        conversions = []
        for _ in range(repeat):
            fresh = DirectCholmodFactor(matrix, "m", analysis)  # numbers a fresh supernodal copy
            assert not fresh.simplicial
            started = time.perf_counter()
            fresh._pattern_forward(one)
            conversions.append(time.perf_counter() - started)
            factor = fresh
        record["conversion_s"] = min(conversions)
    pattern_s = best(lambda: factor._pattern_forward(columns), repeat) / k
    forward, _ = factor._pattern_forward(columns)
    record["pattern_column_s"] = pattern_s
    record["reached_entries"] = float(analysis.column_counts[forward.indices].sum(dtype=np.int64)) / k
    return record


def interface_record(matrix: sp.csr_matrix, repeat: int) -> dict:
    """CHOLMOD through cvxopt's interface: a first factorisation and a refactorisation."""
    from contactfem.linalg.cholmod_cvxopt import CvxoptCholmodFactor

    first_s = best(lambda: CvxoptCholmodFactor(matrix, "m"), repeat)
    factor = CvxoptCholmodFactor(matrix, "m")
    again_s = best(lambda: CvxoptCholmodFactor(matrix, "m", factor.analysis), repeat)
    rhs = np.ones(matrix.shape[0])
    solve_s = best(lambda: factor.solve(rhs), 2 * repeat)
    return {"size": matrix.shape[0], "matrix_entries": int(matrix.nnz), "analysis_s": max(first_s - again_s, 1e-9),
            "factor_s": again_s, "solve_s": solve_s}


def superlu_record(matrix: sp.csr_matrix, repeat: int) -> dict:
    from contactfem.linalg.superlu import SuperLUFactor

    factor_s = best(lambda: SuperLUFactor(matrix, "m"), repeat)
    factor = SuperLUFactor(matrix, "m")
    rhs = np.random.default_rng(1).standard_normal((matrix.shape[0], 16))
    solve_s = best(lambda: factor.solve(rhs[:, 0]), 2 * repeat)
    block_s = best(lambda: factor.solve(rhs), repeat) / 16
    cost = factor.cost
    return {"size": cost.size, "matrix_entries": cost.matrix_entries, "entries": cost.entries, "flops": cost.flops,
            "factor_s": factor_s, "solve_s": solve_s, "block_solve_s": block_s}


def dense_records(repeat: int) -> list[dict]:
    import scipy.linalg

    records = []
    for k in (250, 500, 1000, 2000):
        matrix = np.random.default_rng(k).standard_normal((k, k)) + k * np.eye(k)
        seconds = best(lambda: scipy.linalg.lu_factor(matrix), repeat)
        records.append({"k": k, "seconds": seconds, "flops_per_s": 2.0 * k**3 / 3.0 / seconds})
    return records


def fit_two(work_a: list[float], work_b: list[float], seconds: list[float]) -> tuple[float, float]:
    """Rates (a, b) with seconds ≈ work_a / a + work_b / b: non-negative least squares on
    relative errors; a rate whose coefficient comes out zero is returned as infinity."""
    from scipy.optimize import nnls

    t = np.asarray(seconds)
    design = np.column_stack([np.asarray(work_a) / t, np.asarray(work_b) / t])
    coefficients, _ = nnls(design, np.ones(len(t)))
    return tuple(float(1.0 / c) if c > 0 else float("inf") for c in coefficients)


def analysis_work(matrix_entries: int) -> float:
    """The analysis's counted work, as costs.analysis_work counts it: m log2 m."""
    return float(matrix_entries) * np.log2(max(float(matrix_entries), 2.0))


def further_rate(group: list[dict]) -> float:
    """Factor entries per second of each right-hand side of a block of 16 after the first:
    15 entries over the block's seconds less a single solve's (median over the matrices)."""
    return float(np.median([15 * r["entries"] / max(16 * r["block_solve_s"] - r["solve_s"], 1e-9) for r in group]))


def fit(records: dict) -> dict:
    """The rates of costs.RATES (and DENSE_FLOPS) from the records."""
    rates: dict = {}
    for kind in ("cholmod-supernodal", "cholmod-simplicial"):
        group = [r for r in records["direct"] if r["kind"] == kind]
        if not group:
            continue
        flops_rate, entries_rate = fit_two([r["flops"] for r in group], [r["entries"] for r in group],
                                           [r["factor_s"] for r in group])
        reach_rate, column_rate = fit_two([r["reached_entries"] for r in group], [1.0 for _ in group],
                                          [r["pattern_column_s"] for r in group])
        rates[kind] = {
            "factor_flops": flops_rate, "factor_entries": entries_rate,
            "analysis_work": float(np.median([analysis_work(r["matrix_entries"]) / r["analysis_s"] for r in group])),
            "solve_entries": float(np.median([r["entries"] / r["solve_s"] for r in group])),
            "block_solve_entries": further_rate(group),
            "blocked_forward_entries": float(np.median([r["entries"] / r["blocked_column_s"] for r in group])),
            "pattern_entries": reach_rate, "pattern_column_seconds": 1.0 / column_rate,
        }
        conversions = [r["entries"] / r["conversion_s"] for r in group if "conversion_s" in r]
        if conversions:
            rates[kind]["conversion_entries"] = float(np.median(conversions))
    direct = records["direct"]
    interface = records["interface"]
    if interface:
        by_size = {r["size"]: r for r in direct}
        rates["cholmod-interface"] = {
            "analysis_work": float(np.median([analysis_work(r["matrix_entries"]) / r["analysis_s"]
                                             for r in interface])),
            # Its factor's entries are not shown: solve and factor rates per counted entry of
            # the same matrix's direct factor, for reference.
            "solve_entries_direct_counts": float(np.median([by_size[r["size"]]["entries"] / r["solve_s"]
                                                            for r in interface if r["size"] in by_size])),
            "factor_s_over_direct": float(np.median([r["factor_s"] / by_size[r["size"]]["factor_s"]
                                                     for r in interface if r["size"] in by_size])),
        }
    superlu = records["superlu"]
    if superlu:
        flops_rate, entries_rate = fit_two([r["flops"] for r in superlu], [r["entries"] for r in superlu],
                                           [r["factor_s"] for r in superlu])
        rates["superlu"] = {"factor_flops": flops_rate, "factor_entries": entries_rate,
                            "solve_entries": float(np.median([r["entries"] / r["solve_s"] for r in superlu])),
                            "block_solve_entries": further_rate(superlu)}
    rates["dense_flops"] = float(np.median([r["flops_per_s"] for r in records["dense"]]))
    rates["column_count_spread"] = [float(min(r["spread"] for r in direct)), float(max(r["spread"] for r in direct))]
    return rates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--squares", type=int, nargs="*", default=[32, 64, 128, 256, 512])
    parser.add_argument("--rough", type=int, nargs="*", default=[1000, 4000, 16000, 64000])
    parser.add_argument("--superlu-up-to", type=int, default=200_000, help="unknowns; SuperLU on smaller matrices only")
    parser.add_argument("--repeat", type=int, default=3, help="runs per figure; the fastest is kept")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--refit", type=Path, help="fit the rates again from this earlier output; measure nothing")
    args = parser.parse_args()
    if args.refit:
        result = json.loads(args.refit.read_text(encoding="utf-8"))
        result["rates"] = fit(result["records"])
        args.out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
        print(json.dumps(result["rates"], indent=2))
        return

    from performance import square_case

    from contactfem.linalg import cholmod_ctypes

    if cholmod_ctypes.cholmod_library() is None:
        sys.exit("needs cvxopt's bundled CHOLMOD (the direct route)")
    records: dict = {"direct": [], "interface": [], "superlu": []}
    with tempfile.TemporaryDirectory() as directory:
        cases = [(f"square N={n}", square_case(n)) for n in args.squares]
        cases += [(f"rough {p} points", rough_case(p, Path(directory))) for p in args.rough]
        for label, case in cases:
            matrix = kernel_matrix(case)
            record = direct_record(matrix, args.repeat)
            record["case"] = label
            records["direct"].append(record)
            records["interface"].append(dict(interface_record(matrix, args.repeat), case=label))
            if matrix.shape[0] <= args.superlu_up_to:
                records["superlu"].append(dict(superlu_record(matrix, args.repeat), case=label))
            print(json.dumps(record), file=sys.stderr)
    records["dense"] = dense_records(args.repeat)
    result = {
        "benchmark": "rates of contactfem.linalg.costs",
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "machine": {"cpu_count": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                    "numpy": np.__version__, "scipy": __import__("scipy").__version__,
                    "cholmod": cholmod_ctypes.library_version(cholmod_ctypes.cholmod_library().library),
                    "load_average": os.getloadavg()},
        "records": records,
        "rates": fit(records),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(json.dumps(result["rates"], indent=2))


if __name__ == "__main__":
    main()
