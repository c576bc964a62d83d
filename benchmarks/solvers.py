"""The sparse direct solvers behind contactfem, side by side on the kernel's own matrix.

Usage:
    python benchmarks/solvers.py                      # N = 256 and 512 (131k, 525k unknowns), every provider installed
    python benchmarks/solvers.py --sizes 512 --providers cvxopt scikit-sparse

For each square size and each provider (CHOLMOD from cvxopt's wheel, the default install:
called directly in the library the wheel bundles, and through cvxopt's own interface, the
fallback where that library is not found; CHOLMOD through scikit-sparse; MKL Pardiso through pypardiso; SciPy's SuperLU), in a fresh
subprocess so that memory figures are its own: the square case's stiffness as the kernel
factorises it (supports masked to the identity, their couplings not stored), then

- ``factorize_s``: a first factorisation (ordering, symbolic analysis, numeric);
- ``refactorize_s``: the same matrix again through the same :class:`Factorizer` (CHOLMOD
  keeps its analysis; the others start over), as the kernel does for each active set;
- ``solve_s``: one solve;
- ``block_solve_s``: a solve of a block of 4 right-hand sides, per right-hand side (the
  kernel solves its load and its factorisation probe together, and Schur columns in blocks);
- ``added_peak_gb``: the peak resident memory during those steps less the resident memory
  before them (the matrix already built): what the factorisation costs the process;
- ``residual``: ‖b − A x‖∞ / ‖b‖∞ of the solve.

Writes benchmarks/results/solvers.json.
"""

from __future__ import annotations

import argparse
import gc
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "solvers.json"
#: Provider → (module of contactfem.linalg, its factory).
PROVIDERS = {"cvxopt": ("cholmod_cvxopt", "cvxopt_cholmod"),
             "cvxopt-interface": ("cholmod_cvxopt", "CvxoptCholmodFactor"),
             "scikit-sparse": ("cholmod_sksparse", "SksparseCholmodFactor"),
             "pypardiso": ("pardiso", "PardisoFactor"), "superlu": ("superlu", "SuperLUFactor")}
MODULES = {"cvxopt": "cvxopt", "cvxopt-interface": "cvxopt", "scikit-sparse": "sksparse", "pypardiso": "pypardiso",
           "superlu": None}
RECORD_PREFIX = "SOLVER-RECORD "


def _status(field: str) -> float:
    """A /proc/self/status memory figure in GB (VmRSS: resident now, VmHWM: its peak)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 2**20
    raise RuntimeError(f"no {field} in /proc/self/status")


def _reset_peak() -> None:
    """Linux: writing 5 to clear_refs resets the peak resident set (VmHWM) to the current one."""
    Path("/proc/self/clear_refs").write_text("5")


def kernel_matrix(divisions: int):
    """The square's stiffness with its supports masked as the kernel factorises it, and a load."""
    from performance import linear_system, square_case

    from contactfem.methods import get_method
    from contactfem.solve import prepare

    problem = prepare(square_case(divisions))
    matrix, rhs = linear_system(problem.contact_system(get_method("positive")).system)
    matrix.eliminate_zeros()  # the supports' couplings: the kernel does not store them
    return matrix, rhs


def single(divisions: int, provider: str) -> dict:
    import importlib

    from contactfem.linalg.storage import release_freed_memory

    matrix, rhs = kernel_matrix(divisions)
    module, factory = PROVIDERS[provider]
    implementation = getattr(importlib.import_module(f"contactfem.linalg.{module}"), factory)
    gc.collect()
    release_freed_memory()
    before = _status("VmRSS")
    _reset_peak()
    started = time.perf_counter()
    factor = implementation(matrix, "the square's stiffness")
    factorize_s = time.perf_counter() - started
    started = time.perf_counter()
    factor = implementation(matrix, "the square's stiffness", getattr(factor, "analysis", None))
    refactorize_s = time.perf_counter() - started
    started = time.perf_counter()
    x = np.asarray(factor.solve(rhs)).reshape(-1)
    solve_s = time.perf_counter() - started
    block = np.random.default_rng(0).standard_normal((len(rhs), 4))
    started = time.perf_counter()
    solved = np.asarray(factor.solve(block)).reshape(block.shape)
    block_solve_s = (time.perf_counter() - started) / block.shape[1]
    block_residual = float(np.abs(block - matrix @ solved).max() / np.abs(block).max())
    peak = _status("VmHWM")
    residual = float(np.abs(rhs - matrix @ x).max() / np.abs(rhs).max())
    return {"divisions": divisions, "unknowns": matrix.shape[0], "stored_entries": int(matrix.nnz),
            "provider": provider, "factorize_s": factorize_s, "refactorize_s": refactorize_s,
            "solve_s": solve_s, "block_solve_s": block_solve_s, "block_residual": block_residual, "rss_before_gb": before, "added_peak_gb": peak - before, "residual": residual}


def installed(provider: str) -> bool:
    import importlib.util

    module = MODULES[provider]
    return module is None or importlib.util.find_spec(module) is not None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 512])
    parser.add_argument("--providers", nargs="+", choices=list(PROVIDERS), default=list(PROVIDERS))
    parser.add_argument("--repeat", type=int, default=2, help="runs per provider and size; the fastest is kept")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--single", nargs=2, metavar=("DIVISIONS", "PROVIDER"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.single:
        record = single(int(args.single[0]), args.single[1])
        sys.stdout.write(RECORD_PREFIX + json.dumps(record) + "\n")
        return
    from performance import machine_info

    records = []
    for divisions in args.sizes:
        for provider in args.providers:
            if not installed(provider):
                print(f"N={divisions} {provider}: not installed", flush=True)
                continue
            runs = []
            for _ in range(args.repeat):
                done = subprocess.run([sys.executable, __file__, "--single", str(divisions), provider],
                                      capture_output=True, text=True, check=True)
                line = next(line for line in done.stdout.splitlines() if line.startswith(RECORD_PREFIX))
                runs.append(json.loads(line[len(RECORD_PREFIX):]))
            best = min(runs, key=lambda r: r["factorize_s"])
            best["added_peak_gb"] = min(r["added_peak_gb"] for r in runs)
            records.append(best)
            print(f"N={divisions} ({best['unknowns']} unknowns) {provider:14s} factorise {best['factorize_s']:.3f} s, "
                  f"refactorise {best['refactorize_s']:.3f} s, solve {best['solve_s']:.3f} s "
                  f"({best['block_solve_s']:.3f} s per column of 4), "
                  f"+{best['added_peak_gb']:.3f} GB, residual {best['residual']:.1e}", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"benchmark": "sparse direct solvers on the kernel's matrix",
                                    "started": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                                    "command": "python benchmarks/solvers.py " + " ".join(sys.argv[1:]),
                                    "machine": machine_info(), "records": records}, indent=1) + "\n")


if __name__ == "__main__":
    main()
