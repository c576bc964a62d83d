"""Performance harness: the square case of cases/square.yaml at N x N divisions, both methods.

Usage:
    python benchmarks/performance.py                    # N = 64 128 256 512 1024 (minutes; GBs of RAM at 1024)
    python benchmarks/performance.py --quick            # N = 32 64 128 256 (about a minute)
    python benchmarks/performance.py --sizes 64 256     # choose the sizes
    python benchmarks/performance.py --quick --getfem   # also GetFEM on the same problem (benchmarks/getfem_square.py)
    python benchmarks/performance.py --single 256       # one size in this process: JSON records on stdout

--getfem runs GetFEM (Debian's python3-getfem, for /usr/bin/python3) at the sweep's sizes
unless --getfem-sizes says otherwise: at N = 1024 it takes minutes and about 15 GB. It is
skipped, with the reason printed and recorded, when that Python cannot import getfem.

Each (N, method) runs in a fresh subprocess (``--single N --methods M``) so that its
peak RSS is its own and its memory goes back to the OS before the next run, with the C
heap kept for reuse as the ``contactfem`` command keeps it (:mod:`contactfem.heap`;
``--plain-heap`` leaves glibc's defaults). A run:
  1. warms up on an 8 x 8 square (imports, first factorisation, writers), untimed;
  2. times the pipeline: parse the case, mesh and assemble (contactfem.solve.prepare),
     solve_case (contact solve, postprocess, report), write_outputs (VTU + HDF5 + JSON
     into a temporary directory); end to end is the wall time of all of it;
  3. reads the peak RSS, then times the baseline: one linear elasticity solve on the same
     mesh with the same backend, i.e. factorise the kernel's stiffness (no contact
     constraint; supports the kernel keeps as fixed unknowns masked to the identity, as
     the kernel does, untimed) and solve once for its load.
The sweep writes JSON (--out, default benchmarks/results/performance.json, rewritten
after every run so an interrupted sweep keeps what it measured) and a markdown table
(--markdown, default beside the JSON), with the fitted exponents of time against
unknowns (log-log least squares over the sizes run).

Timings are wall-clock seconds (time.perf_counter) of single runs, or the fastest of
--repeat R runs per stage: on a busy machine they are noisy, so compare runs made on a
quiet one.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from contactfem.threads import one_blas_thread

one_blas_thread()  # as the command runs, before numpy loads (OPENBLAS_NUM_THREADS set in the environment wins)

import numpy as np
import yaml

from contactfem.methods import METHOD_NAMES

ROOT = Path(__file__).resolve().parents[1]
CASE_FILE = ROOT / "cases" / "square.yaml"
DEFAULT_SIZES = [64, 128, 256, 512, 1024]
QUICK_SIZES = [32, 64, 128, 256]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "performance.json"
GETFEM_SCRIPT = ROOT / "benchmarks" / "getfem_square.py"
RECORD_PREFIX = "PERFORMANCE-RECORDS "


# --------------------------------------------------------------------------- one run


def square_case(divisions: int):
    from contactfem.case import parse_case

    data = yaml.safe_load(CASE_FILE.read_text())
    data["mesh"]["divisions"] = divisions
    return parse_case(yaml.safe_dump(data), source=CASE_FILE)


def peak_rss_gb() -> float:
    # Linux reports ru_maxrss in KiB.
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def warm_up(methods: list[str]) -> None:
    """Run the whole pipeline once on a small square so that no timed stage pays for imports."""
    from contactfem.io.registry import result_data, write_result
    from contactfem.linalg import factorize
    from contactfem.methods import get_method
    from contactfem.report import build_report
    from contactfem.solve import prepare, solve_case

    case = square_case(8)
    problem = prepare(case)
    for method in methods:
        outcome = solve_case(case, method=method, problem=problem)
        with tempfile.TemporaryDirectory() as directory:
            write_result(result_data(case, outcome, build_report(case, outcome)), Path(directory), case.output.files)
    reduced = problem.contact_system(get_method("positive"))
    matrix, rhs = linear_system(reduced.system)
    factorize(matrix, outcome.backend).solve(rhs)


def linear_system(system):
    """The kernel's stiffness and load with the supports imposed and no contact constraint.

    Supports the kernel keeps as fixed unknowns (``system.fixed_dofs``, ``fixed_values``)
    are masked in place as the kernel does: their rows and columns become the identity and
    the right-hand side carries their values. A system without them (supports already
    eliminated) is returned as it is.
    """
    import scipy.sparse as sp

    matrix = sp.csr_matrix(system.stiffness)
    load = np.asarray(system.load, dtype=float)
    fixed_dofs = np.asarray(getattr(system, "fixed_dofs", ()), dtype=np.int64)
    if len(fixed_dofs) == 0:
        return matrix, load
    n = matrix.shape[0]
    fixed = np.zeros(n, dtype=bool)
    fixed[fixed_dofs] = True
    values = np.zeros(n)
    values[fixed_dofs] = np.asarray(getattr(system, "fixed_values", np.zeros(len(fixed_dofs))), dtype=float)
    rows = np.repeat(np.arange(n), np.diff(matrix.indptr))
    keep = ~fixed[rows] & ~fixed[matrix.indices]
    masked = sp.csr_matrix((np.where(keep, matrix.data, 0.0), matrix.indices, matrix.indptr), shape=matrix.shape)
    masked = (masked + sp.diags(fixed.astype(float))).tocsr()
    rhs = load - matrix @ values
    rhs[fixed] = values[fixed]
    return masked, rhs


def measure(divisions: int, method: str) -> dict:
    """Time one (N, method) pipeline end to end, then the linear-solve baseline."""
    from contactfem.io.registry import result_data, write_result
    from contactfem.linalg import factorize
    from contactfem.methods import get_method
    from contactfem.report import build_report
    from contactfem.solve import prepare, solve_case

    directory = Path(tempfile.mkdtemp(prefix="contactfem-perf-"))
    try:
        started = time.perf_counter()
        case = square_case(divisions)
        case_s = time.perf_counter() - started
        timings: dict[str, float] = {}
        problem = prepare(case, timings=timings)
        outcome = solve_case(case, method=method, problem=problem)
        _, report = write_result(result_data(case, outcome, build_report(case, outcome)), directory,
                                 case.output.files)
        end_to_end = time.perf_counter() - started
        output_bytes = sum(p.stat().st_size for p in directory.rglob("*") if p.is_file())
    finally:
        shutil.rmtree(directory, ignore_errors=True)
    peak = peak_rss_gb()

    stages = {
        "case_s": case_s,
        "mesh_s": timings["mesh"],
        "assemble_s": timings["assemble"],
        "solve_s": outcome.timings["solve"],
        "postprocess_s": outcome.timings["postprocess"],
        "report_s": report["timings"]["report"],
        "write_s": report["timings"]["write"],
    }
    record = {
        "N": divisions,
        "method": method,
        "unknowns": problem.n_unknowns,
        "contact_nodes": int(len(problem.contact.nodes)),
        "backend": outcome.backend,
        "iterations": int(outcome.kernel.iterations),
        "active_per_iteration": [int(r["active"]) for r in report["newton"]],
        "newton_seconds": [float(r["seconds"]) for r in report["newton"]],
        **stages,
        # what end to end spends outside the named stages
        "other_s": end_to_end - sum(stages.values()),
        "end_to_end_s": end_to_end,
        "output_bytes": output_bytes,
        "contact_force": float(report["contact_force"]["normal"]),
        "contact_zone": [i["abscissa"] for i in report["contact_zone"]["intervals"]],
        "active_nodes": int(report["contact_zone"]["active_nodes"]),
        "peak_rss_gb": peak,
    }
    backend = outcome.backend
    del outcome

    # The baseline: one linear elasticity solve (no contact) on the same mesh and backend.
    clock = time.perf_counter()
    reduced = problem.contact_system(get_method("positive"))
    record["baseline_reduce_s"] = time.perf_counter() - clock
    clock = time.perf_counter()
    matrix, rhs = linear_system(reduced.system)
    record["baseline_supports_s"] = time.perf_counter() - clock
    t0 = time.perf_counter()
    factor = factorize(matrix, backend)
    t1 = time.perf_counter()
    x = factor.solve(rhs)
    t2 = time.perf_counter()
    record["baseline_factorize_s"] = t1 - t0
    record["baseline_substitute_s"] = t2 - t1
    record["baseline_s"] = t2 - t0
    record["baseline_nnz"] = int(reduced.system.stiffness.nnz)
    record["baseline_solution_max"] = float(np.abs(x).max())
    record["peak_rss_gb_with_baseline"] = peak_rss_gb()
    record["solve_over_baseline"] = record["solve_s"] / record["baseline_s"]
    record["end_to_end_over_baseline"] = end_to_end / record["baseline_s"]
    return record


def best_of(samples: list[dict]) -> dict:
    """One record from repeated runs: each timing (``*_s``) is its minimum over the runs."""
    record = dict(samples[0])
    if len(samples) > 1:
        for key in record:
            if key.endswith("_s") and isinstance(record[key], float):
                record[key] = min(s[key] for s in samples)
        record["solve_over_baseline"] = record["solve_s"] / record["baseline_s"]
        record["end_to_end_over_baseline"] = record["end_to_end_s"] / record["baseline_s"]
        record["peak_rss_gb"] = max(s["peak_rss_gb"] for s in samples)
        record["samples"] = {key: [s[key] for s in samples] for key in ("solve_s", "baseline_s", "end_to_end_s")}
    record["repeats"] = len(samples)
    return record


def add_heap_option(parser: argparse.ArgumentParser) -> None:
    """``--plain-heap``, shared by the benchmarks that time what the command does."""
    parser.add_argument("--plain-heap", action="store_true",
                        help="leave glibc's allocator as it is (the command keeps freed memory: contactfem.heap)")


def heap_as_the_command(keep_heap: bool = True) -> bool:
    """This process's heap as the ``contactfem`` command keeps it (:mod:`contactfem.heap`),
    unless ``keep_heap`` is False (glibc's defaults); whether it is kept."""
    from contactfem.heap import keep_freed_memory

    return keep_freed_memory() if keep_heap else False


def single(divisions: int, methods: list[str], repeat: int = 1, keep_heap: bool = True) -> None:
    heap_kept = heap_as_the_command(keep_heap)
    warm_up(methods)
    records = [best_of([measure(divisions, method) for _ in range(repeat)]) for method in methods]
    for record in records:
        record["heap_kept"] = heap_kept
    sys.stdout.write(RECORD_PREFIX + json.dumps(records) + "\n")
    sys.stdout.flush()


# --------------------------------------------------------------------------- machine


def _first(path: str, key: str) -> str | None:
    try:
        for line in Path(path).read_text().splitlines():
            if line.startswith(key):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return None


def _blas() -> dict:
    info: dict = {}
    try:
        from threadpoolctl import threadpool_info

        info["threadpoolctl"] = threadpool_info()
    except ImportError:
        info["threadpoolctl"] = None
    try:
        config = np.show_config(mode="dicts")  # numpy >= 1.26
        deps = config.get("Build Dependencies", {})
        info["numpy"] = {k: {"name": deps.get(k, {}).get("name"), "version": deps.get(k, {}).get("version")}
                         for k in ("blas", "lapack")}
    except (TypeError, AttributeError):
        info["numpy"] = None
    # CHOLMOD links the system BLAS, not numpy's: name what its extension loads.
    try:
        import importlib.util

        spec = importlib.util.find_spec("sksparse.cholmod")
        if spec and spec.origin:
            ldd = subprocess.run(["ldd", spec.origin], capture_output=True, text=True, timeout=30).stdout
            libs = {}
            for line in ldd.splitlines():
                parts = line.split("=>")
                name = parts[0].strip()
                if len(parts) == 2 and any(k in name for k in ("blas", "lapack", "cholmod", "mkl")):
                    target = parts[1].split("(")[0].strip()
                    libs[name] = os.path.realpath(target) if target else None
            info["cholmod_links"] = libs
    except (OSError, subprocess.SubprocessError, ImportError, ValueError):
        pass
    return info


def _version(package: str) -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(package)
    except PackageNotFoundError:
        return None


def _git() -> dict:
    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, timeout=30)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    status = git("status", "--porcelain", "--", "contactfem")
    return {"commit": git("rev-parse", "HEAD"),
            "contactfem_modified": None if status is None else sorted(line[3:] for line in status.splitlines())}


def machine_info() -> dict:
    import scipy

    import contactfem
    from contactfem.linalg import available_backends, resolve_backend

    mem_kib = _first("/proc/meminfo", "MemTotal")
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = None
    return {
        "cpu": _first("/proc/cpuinfo", "model name") or platform.processor(),
        "cores": os.cpu_count(),
        "cores_usable": affinity,
        "memory_gb": int(mem_kib.split()[0]) / 2**20 if mem_kib else None,
        "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "scikit-sparse": _version("scikit-sparse"),
        "pypardiso": _version("pypardiso"),
        "contactfem": contactfem.__version__,
        "backend": resolve_backend("auto"),
        "backends_available": available_backends(),
        "blas": _blas(),
        "thread_env": {k: os.environ[k] for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
                       if k in os.environ},
        "git": _git(),
    }


# --------------------------------------------------------------------------- sweep


def run_single_subprocess(divisions: int, method: str, timeout: float, repeat: int,
                          keep_heap: bool = True) -> list[dict]:
    command = [sys.executable, str(Path(__file__).resolve()), "--single", str(divisions), "--methods", method,
               "--repeat", str(repeat), *([] if keep_heap else ["--plain-heap"])]
    started = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return [{"N": divisions, "method": method, "error": f"timed out after {timeout:.0f} s"}]
    for line in done.stdout.splitlines():
        if line.startswith(RECORD_PREFIX):
            records = json.loads(line[len(RECORD_PREFIX):])
            for record in records:
                record["subprocess_s"] = time.perf_counter() - started
            return records
    tail = (done.stderr or done.stdout).strip().splitlines()[-15:]
    return [{"N": divisions, "method": method, "error": f"exit code {done.returncode}", "stderr_tail": tail}]


def getfem_available(python: str) -> str | None:
    """None when ``python`` can import getfem and the script is there, else why not."""
    if not GETFEM_SCRIPT.exists():
        return f"{GETFEM_SCRIPT} is missing"
    if not shutil.which(python) and not Path(python).exists():
        return f"{python} not found"
    try:
        done = subprocess.run([python, "-c", "import getfem"], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.SubprocessError) as error:
        return f"{python} -c 'import getfem' failed: {error}"
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["?"])[-1]
        return f"{python} cannot import getfem ({last}); on Debian: apt-get install -y python3-getfem"
    return None


def run_getfem(divisions: int, python: str, timeout: float, dirichlet: str) -> dict:
    command = [python, str(GETFEM_SCRIPT), str(divisions), "--dirichlet", dirichlet]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return {"N": divisions, "error": f"timed out after {timeout:.0f} s"}
    try:
        records = json.loads(done.stdout)
    except json.JSONDecodeError:
        records = None
    if done.returncode != 0 or not isinstance(records, list) or not records:
        tail = (done.stderr or done.stdout).strip().splitlines()[-15:]
        return {"N": divisions, "error": f"exit code {done.returncode}", "stderr_tail": tail}
    return records[0]


def fit_exponent(unknowns: list[float], seconds: list[float]) -> float | None:
    """Slope of log(seconds) against log(unknowns): time ~ unknowns ** slope."""
    pairs = [(u, s) for u, s in zip(unknowns, seconds) if u and s and s > 0]
    if len({u for u, _ in pairs}) < 2:
        return None
    u, s = np.array(pairs, dtype=float).T
    return float(np.polyfit(np.log(u), np.log(s), 1)[0])


def scaling(records: list[dict], getfem: list[dict]) -> dict:
    good = [r for r in records if "error" not in r]
    result: dict = {}
    for method in METHOD_NAMES:
        rows = sorted((r for r in good if r["method"] == method), key=lambda r: r["N"])
        if not rows:
            continue
        unknowns = [r["unknowns"] for r in rows]
        result[method] = {
            "sizes": [r["N"] for r in rows],
            "contact_solve": fit_exponent(unknowns, [r["solve_s"] for r in rows]),
            "baseline": fit_exponent(unknowns, [r["baseline_s"] for r in rows]),
            "end_to_end": fit_exponent(unknowns, [r["end_to_end_s"] for r in rows]),
            "assemble": fit_exponent(unknowns, [r["assemble_s"] for r in rows]),
            "peak_rss": fit_exponent(unknowns, [r["peak_rss_gb"] for r in rows]),
            # slope between consecutive sizes, to see where the growth bends
            "contact_solve_local": [
                fit_exponent([a["unknowns"], b["unknowns"]], [a["solve_s"], b["solve_s"]])
                for a, b in zip(rows, rows[1:])
            ],
        }
    rows = sorted((g for g in getfem if "error" not in g), key=lambda g: g["N"])
    if rows:
        unknowns = [g["unknowns"] for g in rows]
        result["getfem"] = {
            "sizes": [g["N"] for g in rows],
            "contact_solve": fit_exponent(unknowns, [g["solve_s"] for g in rows]),
            "baseline": fit_exponent(unknowns, [g.get("linear_solve_s") for g in rows]),
        }
    return result


def compare_getfem(records: list[dict], getfem: list[dict]) -> list[dict]:
    rows = []
    for g in getfem:
        if "error" in g:
            continue
        for r in records:
            if r.get("N") != g["N"] or "error" in r:
                continue
            compute = r["mesh_s"] + r["assemble_s"] + r["solve_s"]
            rows.append({
                "N": g["N"],
                "method": r["method"],
                "solve_ratio": r["solve_s"] / g["solve_s"],
                "compute_ratio": compute / g["total_s"],
                "baseline_ratio": r["baseline_s"] / g["linear_solve_s"] if g.get("linear_solve_s") else None,
                "contact_force": r["contact_force"],
                "getfem_contact_force": g["contact_force"],
                "force_relative_difference": abs(r["contact_force"] - g["contact_force"]) / abs(g["contact_force"]),
                "iterations": r["iterations"],
                "getfem_iterations": g["iterations"],
                # the same linear elasticity solved by both: max |u| agrees when the problems do
                "linear_max_u_relative_difference": (
                    abs(r["baseline_solution_max"] - g["linear_solution_max"]) / g["linear_solution_max"]
                    if g.get("linear_solution_max") else None),
            })
    return rows


# --------------------------------------------------------------------------- output


def _f(value: float | None, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _e(value: float | None) -> str:
    return "–" if value is None else f"{value:.2f}"


def markdown(result: dict) -> str:
    m = result["machine"]
    lines = [
        "# contactfem performance: square case",
        "",
        f"{result['started']}; {m['cpu']}, {m['cores']} cores, {_f(m['memory_gb'], 1)} GB; Python {m['python']}, "
        f"numpy {m['numpy']}, scipy {m['scipy']}; backend {m['backend']}; "
        f"load average at start {', '.join(f'{x:.2f}' for x in m['load_average'] or [])}.",
        "",
        f"Seconds of wall time, {'one run each' if result.get('repeat', 1) == 1 else 'fastest of ' + str(result['repeat']) + ' runs per stage'}. *solve* is the contact solve (solve_case's \"solve\": "
        "the reduction and every Newton iteration); *baseline* is one linear elasticity solve on the "
        "same mesh with the same backend (factorise the kernel's stiffness without contact, solve once); "
        "*ratio* = solve / baseline, *e2e/base* = total / baseline; *total* = end to end (parse, mesh, "
        "assemble, solve, postprocess, report, write VTU + HDF5 + JSON); *peak GB* is the run's peak RSS.",
        "",
        "| N | unknowns | method | Newton | mesh s | assembly s | solve s | write s | total s "
        "| baseline s | ratio | e2e/base | peak GB |",
        "|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in result["records"]:
        if "error" in r:
            lines.append(f"| {r['N']} | | {r['method']} | failed: {r['error']} | | | | | | | | | |")
            continue
        lines.append(
            f"| {r['N']} | {r['unknowns']} | {r['method']} | {r['iterations']} | {_f(r['mesh_s'], 3)} | "
            f"{_f(r['assemble_s'], 3)} | {_f(r['solve_s'], 3)} | {_f(r['write_s'], 3)} | "
            f"{_f(r['end_to_end_s'], 3)} | {_f(r['baseline_s'], 3)} | {_f(r['solve_over_baseline'], 1)} | "
            f"{_f(r['end_to_end_over_baseline'], 1)} | {_f(r['peak_rss_gb'], 3)} |"
        )
    lines += ["", "Fitted exponent p of time ~ unknowns^p (least squares on log-log over the sizes run):", ""]
    for name, fit in result["scaling"].items():
        if name == "getfem":
            continue
        local = ", ".join(_e(x) for x in fit["contact_solve_local"])
        lines.append(
            f"- {name} (N = {', '.join(map(str, fit['sizes']))}): contact solve {_e(fit['contact_solve'])} "
            f"(between consecutive sizes: {local}), baseline {_e(fit['baseline'])}, "
            f"end to end {_e(fit['end_to_end'])}, assembly {_e(fit['assemble'])}, peak memory {_e(fit['peak_rss'])}"
        )
    lines.append("")
    lines.append("Active set size per Newton iteration:")
    lines.append("")
    for r in result["records"]:
        if "error" not in r:
            lines.append(f"- N = {r['N']}, {r['method']}: {r['active_per_iteration']}")

    gf = result.get("getfem")
    if gf is not None:
        lines += ["", "## GetFEM side by side", ""]
        if gf.get("skipped"):
            lines.append(f"Skipped: {gf['skipped']}")
        else:
            lines += [
                "GetFEM 5.4 (Debian python3-getfem, MUMPS sequential) on the same discrete problem "
                "(benchmarks/getfem_square.py): nodal contact with a rigid obstacle, GetFEM's Newton, "
                f"clamp imposed with {gf.get('dirichlet', 'multipliers')}. "
                "*setup* = mesh, FEM and model bricks; *solve* = md.solve (assembly and MUMPS in each "
                "Newton iteration); *linear* = one MUMPS solve of the assembled linear elasticity.",
                "",
                "| N | unknowns | Newton | setup s | solve s | linear s | contact force | zone | peak GB |",
                "|---:|---:|---:|---:|---:|---:|---:|---|---:|",
            ]
            for g in gf["records"]:
                if "error" in g:
                    lines.append(f"| {g['N']} | failed: {g['error']} | | | | | | | |")
                    continue
                zone = "–" if g["contact_zone"] is None else f"[{g['contact_zone'][0]:.4f}, {g['contact_zone'][1]:.4f}]"
                lines.append(
                    f"| {g['N']} | {g['unknowns']} | {g['iterations']} | {_f(g['setup_s'], 3)} | "
                    f"{_f(g['solve_s'], 3)} | {_f(g.get('linear_solve_s'), 3)} | {g['contact_force']:.4f} | "
                    f"{zone} | {_f(g.get('peak_rss_gb_with_linear', g['peak_rss_gb']), 3)} |"
                )
            lines += [
                "",
                "contactfem / GetFEM: *solve* = contact solve / md.solve; *compute* = (mesh + assembly + "
                "solve) / (setup + md.solve); *baseline* = our linear solve / GetFEM's MUMPS linear solve; "
                "*max u* = relative difference of max |u| between the two linear solutions.",
                "",
                "| N | method | Newton (ours / GetFEM) | solve ratio | compute ratio | baseline ratio "
                "| contact force (ours) | contact force (GetFEM) | rel. difference | max u rel. diff. |",
                "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|",
            ]
            for c in gf["comparison"]:
                lines.append(
                    f"| {c['N']} | {c['method']} | {c['iterations']} / {c['getfem_iterations']} | "
                    f"{_f(c['solve_ratio'])} | {_f(c['compute_ratio'])} | {_f(c['baseline_ratio'])} | "
                    f"{c['contact_force']:.6f} | {c['getfem_contact_force']:.6f} | "
                    f"{c['force_relative_difference']:.1e} | "
                    f"{'–' if c['linear_max_u_relative_difference'] is None else format(c['linear_max_u_relative_difference'], '.1e')} |"
                )
            fit = result["scaling"].get("getfem")
            if fit:
                lines += ["", f"GetFEM fitted exponents: contact solve {_e(fit['contact_solve'])}, "
                              f"linear solve {_e(fit['baseline'])}."]
    return "\n".join(lines) + "\n"


def save(result: dict, out: Path, md_path: Path) -> None:
    result["scaling"] = scaling(result["records"], (result.get("getfem") or {}).get("records", []))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    md_path.parent.mkdir(parents=True, exist_ok=True)
    md_path.write_text(markdown(result))


def summary_line(r: dict) -> str:
    if "error" in r:
        return f"N={r['N']:5d} {r['method']:9s} FAILED: {r['error']}"
    return (f"N={r['N']:5d} {r['method']:9s} unknowns {r['unknowns']:8d}  Newton {r['iterations']:2d}  "
            f"solve {r['solve_s']:8.3f} s  baseline {r['baseline_s']:7.3f} s  ratio {r['solve_over_baseline']:5.1f}  "
            f"total {r['end_to_end_s']:8.3f} s  peak {r['peak_rss_gb']:.2f} GB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", type=int, help=f"divisions per side (default {DEFAULT_SIZES})")
    parser.add_argument("--quick", action="store_true", help=f"N = {QUICK_SIZES}, about a minute")
    parser.add_argument("--methods", nargs="+", choices=METHOD_NAMES, default=list(METHOD_NAMES))
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON file (default %(default)s)")
    parser.add_argument("--markdown", type=Path, help="markdown file (default: the JSON's path with .md)")
    parser.add_argument("--single", type=int, metavar="N",
                        help="measure N in this process and print the records as JSON (used by the sweep)")
    parser.add_argument("--repeat", type=int, default=1,
                        help="time each (N, method) this many times in its process and keep the fastest "
                             "of each stage (default 1; the peak RSS is the largest)")
    parser.add_argument("--timeout", type=float, default=3600.0, help="seconds allowed per subprocess run")
    add_heap_option(parser)
    parser.add_argument("--getfem", action="store_true", help="also run benchmarks/getfem_square.py")
    parser.add_argument("--getfem-sizes", nargs="+", type=int, help="sizes for GetFEM (default: the sweep's)")
    parser.add_argument("--getfem-python", default="/usr/bin/python3", help="the Python that has getfem")
    parser.add_argument("--getfem-dirichlet", choices=("multipliers", "simplification"), default="multipliers",
                        help="how GetFEM imposes the clamp (see benchmarks/getfem_square.py)")
    args = parser.parse_args()

    if args.single is not None:
        single(args.single, args.methods, args.repeat, keep_heap=not args.plain_heap)
        return

    if args.sizes and args.quick:
        parser.error("--sizes and --quick exclude each other")
    sizes = args.sizes or (QUICK_SIZES if args.quick else DEFAULT_SIZES)
    out = args.out.resolve()
    md_path = (args.markdown or out.with_suffix(".md")).resolve()

    result = {
        "benchmark": "square case of cases/square.yaml at N x N divisions",
        "started": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "sizes": sizes,
        "methods": args.methods,
        "repeat": args.repeat,
        "machine": machine_info(),
        "records": [],
    }
    print(f"{result['machine']['cpu']}, {result['machine']['cores']} cores, backend {result['machine']['backend']}; "
          f"sizes {sizes}", flush=True)
    for n in sizes:
        for method in args.methods:
            for record in run_single_subprocess(n, method, args.timeout, args.repeat, keep_heap=not args.plain_heap):
                result["records"].append(record)
                print(summary_line(record), flush=True)
            save(result, out, md_path)

    if args.getfem:
        gsizes = args.getfem_sizes or sizes
        reason = getfem_available(args.getfem_python)
        if reason:
            print(f"GetFEM side by side skipped: {reason}", flush=True)
            result["getfem"] = {"skipped": reason}
        else:
            result["getfem"] = {"python": args.getfem_python, "sizes": gsizes, "dirichlet": args.getfem_dirichlet,
                                "records": [], "comparison": []}
            for n in gsizes:
                g = run_getfem(n, args.getfem_python, args.timeout, args.getfem_dirichlet)
                result["getfem"]["records"].append(g)
                if "error" in g:
                    print(f"GetFEM N={n}: FAILED: {g['error']}", flush=True)
                    continue
                print(f"GetFEM N={n:5d} Newton {g['iterations']:2d}  setup {g['setup_s']:.3f} s  "
                      f"solve {g['solve_s']:.3f} s  linear {g.get('linear_solve_s', float('nan')):.3f} s  "
                      f"force {g['contact_force']:.6f}  peak {g['peak_rss_gb']:.2f} GB", flush=True)
                result["getfem"]["comparison"] = compare_getfem(result["records"], result["getfem"]["records"])
                for c in result["getfem"]["comparison"]:
                    if c["N"] == n:
                        print(f"  contactfem/GetFEM {c['method']:9s}: solve {c['solve_ratio']:.2f}, "
                              f"compute {c['compute_ratio']:.2f}, baseline {_f(c['baseline_ratio'])}; "
                              f"force {c['contact_force']:.6f} vs {c['getfem_contact_force']:.6f} "
                              f"(rel. diff {c['force_relative_difference']:.1e})", flush=True)
                save(result, out, md_path)
    result["finished"] = time.strftime("%Y-%m-%d %H:%M:%S %Z")
    save(result, out, md_path)

    for name, fit in result["scaling"].items():
        print(f"exponent ({name}, N = {fit['sizes']}): contact solve {_e(fit['contact_solve'])}, "
              f"baseline {_e(fit['baseline'])}")
    print(f"wrote {out} and {md_path}")
    if any("error" in r for r in result["records"]):
        sys.exit(1)


if __name__ == "__main__":
    main()
