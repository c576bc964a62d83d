"""Rough contact surfaces: cases/rough.yaml with its profile at 1 000 to 100 000 points.

Usage:
    python benchmarks/rough.py                          # 1k ... 100k points, 3 rounds (about 10 minutes on 2 cores)
    python benchmarks/rough.py --rounds 1               # each size once
    python benchmarks/rough.py --sizes 1000 4000 16000  # choose the sizes
    python benchmarks/rough.py --single 4000            # one size in this process: a JSON record on stdout
    python benchmarks/rough.py --workers 2              # the sizes as tasks of a local Dask cluster
    python benchmarks/rough.py --write-surface          # rewrite cases/rough_surface.csv (4 001 points)
    python benchmarks/rough.py --scene outline          # a closed outline from a file instead (see below)
    python benchmarks/rough.py --write-outline          # rewrite cases/rough_rim.csv (2 001 vertices)

The body is the case's 1 x 0.5 block whose base is a seeded self-affine profile
(:func:`self_affine_profile`, Hurst exponent 0.8, 1e-3 from lowest to highest point),
pushed onto the flat obstacle by the displacement of its top. Every size draws the same
random phases, so the coarse shape is the same and finer sizes add shorter wavelengths.
Each size runs in a fresh subprocess (``--single N``), so its peak RSS is its own, with
the C heap kept for reuse as the ``contactfem`` command keeps it (:mod:`contactfem.heap`;
``--plain-heap`` leaves glibc's defaults). A run:

  1. warms up on a 200-point profile (imports, Triangle, the first factorisation) and
     records the peak RSS it leaves (the interpreter and libraries, about 0.1 GB): the
     peaks after each stage less this one are what the stages added;
  2. writes the profile to a CSV in a temporary directory and times, separately:
     validation (``load_case``: reading the CSV, building the outline, the O(k log k)
     simplicity sweep, ``polygon_problems`` alone recorded too), meshing (Triangle and the
     boundary bookkeeping), assembly, and the contact solve (``solve_case``: the coarse
     levels of mesh sequencing and every Newton step), with the peak RSS after each;
  3. times the baseline, one linear elasticity solve of the same mesh with the same
     backend (factorise the kernel's stiffness without contact, ``check=False``, and solve
     once; see benchmarks/performance.py ``linear_system``), in alternation with the
     contact solve again: 3 to 15 of each, as many as about 2 s of contact solves allow.
     The fastest of each counts (``solve_over_baseline``; all kept in ``solve_samples_s``
     and ``baseline_samples_s``, whose first contact solve pays for the process's first
     touch of its memory, up to 2x the solve on a virtual machine), and the ratio of their
     medians is kept too (``median_solve_over_baseline``).

``--scene outline`` sweeps cases/rough_rim.yaml instead: a half-disk of radius 1 whose rim
is a closed outline of N vertices read from a file (``geometry.polygon.file``: x, y,
part per line), roughened radially by the same synthesis (Hurst 0.3, 2e-3 high, largest
at the bottom, :func:`write_outline`), pressed 2e-3 onto the plane by its straight top:
an outline that is no graph h(x), validated, meshed and solved like any polygon. It
writes benchmarks/results/rough_outline.json.

The sweep runs ``--rounds`` rounds (3 by default), each size once per round in a fresh
process, the sizes taking turns, so that a slow phase of a shared machine hits every size
alike: a size's record is that of its round with the lowest ratio, and it keeps every
round's ratio (``round_ratios``) and their median (``round_median_ratio``).

The sweep writes benchmarks/results/rough.json (rewritten after every run, so an
interrupted sweep keeps what it measured) with each size's record and the fitted growth
exponents p of stage time (and peak memory) ~ points^p, by least squares on the logs.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from contactfem.threads import one_blas_thread

one_blas_thread()  # as the command runs, before numpy loads (OPENBLAS_NUM_THREADS set in the environment wins)

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
CASE_FILE = ROOT / "cases" / "rough.yaml"
SURFACE_FILE = ROOT / "cases" / "rough_surface.csv"
OUTLINE_CASE_FILE = ROOT / "cases" / "rough_rim.yaml"
OUTLINE_FILE = ROOT / "cases" / "rough_rim.csv"
SHIPPED_OUTLINE_POINTS = 2001
#: The outline's roughness, from the smooth circle to the highest asperity.
RIM_HEIGHT = 2.0e-3
#: Its Hurst exponent: rougher than the block's profile, so that the bottom touches in patches
#: (at 0.8 the disk's curvature hides the short wavelengths and the contact is one zone).
RIM_HURST = 0.3
DEFAULT_SIZES = [1000, 2000, 4000, 8000, 16000, 32000, 64000, 100000]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "rough.json"
RECORD_PREFIX = "ROUGH-RECORD "
#: Seconds of contact solves a size's timing aims at (its first solve sets how many), and
#: the most repeats: small sizes, whose single runs vary by 20-40% on this machine, are
#: repeated more.
REPEAT_SECONDS = 2.0
MAX_REPEAT = 15
#: The shipped surface: its seed, Hurst exponent, height and number of points.
SEED = 20240611
HURST = 0.8
HEIGHT = 1.0e-3
SHIPPED_POINTS = 4001


def self_affine_profile(points: int, *, hurst: float = HURST, height: float = HEIGHT, length: float = 1.0,
                        seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """A seeded self-affine profile h(x) on [0, length] at ``points`` equally spaced x.

    Spectral synthesis: Fourier modes of wavenumber q = 1 ... (points - 1) / 2 with
    amplitude q^-(1/2 + H) (a one-dimensional power spectrum ∝ q^-(1 + 2H)) and phases
    drawn from ``seed`` in order of q, so that every size shares its long wavelengths.
    Scaled to ``height`` from lowest to highest point and shifted so that min h = 0. The
    profile is periodic (h at both ends nearly equal), which keeps the block's corners
    out of the picture.
    """
    if points < 3:
        raise ValueError("a profile needs at least 3 points")
    modes = (points - 1) // 2
    phases = np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, modes)
    q = np.arange(1, modes + 1)
    spectrum = np.zeros(points - 1, dtype=complex)
    spectrum[1:modes + 1] = q ** -(0.5 + hurst) * np.exp(1j * phases)
    h = np.fft.ifft(spectrum).real * (points - 1)
    h = np.append(h, h[0])
    h = (h - h.min()) * (height / np.ptp(h))
    return np.linspace(0.0, length, points), h


def write_surface(path: Path, points: int, seed: int = SEED) -> None:
    x, h = self_affine_profile(points, seed=seed)
    header = (f"# self-affine profile: Hurst exponent {HURST}, {points} points on [0, 1], height {HEIGHT:g} "
              f"(lowest to highest), seed {seed}\n"
              f"# written by: python benchmarks/rough.py --write-surface\n")
    path.write_text(header + profile_text(x, h), encoding="utf-8")


def profile_text(x: np.ndarray | None, h: np.ndarray) -> str:
    """A profile file's CSV lines: a header and x, h per line, or h alone (``x`` None: the
    one-column form, whose case gives the spacing)."""
    if x is None:
        return "h\n" + "\n".join(f"{b:.17g}" for b in h) + "\n"
    return "x,h\n" + "\n".join(f"{a:.17g},{b:.17g}" for a, b in zip(x, h)) + "\n"


def rim_outline(points: int, seed: int = SEED, *, hurst: float = RIM_HURST,
                height: float = RIM_HEIGHT) -> tuple[np.ndarray, list[str]]:
    """The rough half-disk's outline, counter-clockwise from (-1, 1): ``points`` vertices on
    the rim r(θ) = 1 + h(t) sin²(πt), θ = π (1 + t), h a :func:`self_affine_profile` of
    ``height`` and Hurst exponent ``hurst`` (:data:`RIM_HEIGHT`, :data:`RIM_HURST` for the
    shipped case), then the straight top back; the rim's lower third is part ``rim``, the
    rest ``left`` and ``right``, the top ``top`` (the part of each vertex's edge)."""
    t, h = self_affine_profile(points, hurst=hurst, height=height, seed=seed)
    radius = 1.0 + h * np.sin(np.pi * t) ** 2
    theta = np.pi * (1.0 + t)
    vertices = np.stack([radius * np.cos(theta), 1.0 + radius * np.sin(theta)], axis=1)
    vertices[0], vertices[-1] = (-1.0, 1.0), (1.0, 1.0)
    lower, upper = np.searchsorted(t, [1 / 3, 2 / 3])
    parts = ["left"] * lower + ["rim"] * (upper - lower) + ["right"] * (points - 1 - upper) + ["top"]
    return vertices, parts


def write_outline(path: Path, points: int, seed: int = SEED) -> None:
    vertices, parts = rim_outline(points, seed)
    header = (f"# a rough half-disk's outline: {points} vertices, self-affine radial roughness (Hurst {RIM_HURST}, "
              f"{RIM_HEIGHT:g} high), seed {seed}\n"
              "# written by: python benchmarks/rough.py --write-outline\n"
              "# the part of the edge from each vertex to the next; empty: the part above\n")
    path.write_text(header + outline_text(vertices, parts), encoding="utf-8")


def outline_text(vertices: np.ndarray, parts: list[str]) -> str:
    """An outline file's CSV lines: a header and x, y, part per vertex, the part written only
    where it changes (the file says where each part starts)."""
    starts = [part if i == 0 or parts[i - 1] != part else "" for i, part in enumerate(parts)]
    return "x,y,part\n" + "\n".join(f"{x:.17g},{y:.17g},{part}" for (x, y), part in zip(vertices.tolist(), starts)) + "\n"


# --------------------------------------------------------------------------- one run


def peak_rss_gb() -> float:
    # Linux reports ru_maxrss in KiB.
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def case_text(csv: Path, scene: str = "profile") -> str:
    data = yaml.safe_load((CASE_FILE if scene == "profile" else OUTLINE_CASE_FILE).read_text(encoding="utf-8"))
    data["geometry"]["profile" if scene == "profile" else "polygon"]["file"] = str(csv)
    return yaml.safe_dump(data, sort_keys=False)


def measure(points: int, directory: Path, method: str, repeat: int = 3, scene: str = "profile") -> dict:
    from performance import linear_system

    from contactfem.case import load_case
    from contactfem.linalg import factorize
    from contactfem.mesh.polygon import polygon_problems
    from contactfem.methods import get_method
    from contactfem.sequencing import patch_count
    from contactfem.solve import prepare, solve_case

    csv = directory / f"{scene}-{points}.csv"
    (write_surface if scene == "profile" else write_outline)(csv, points)
    case_path = directory / f"rough-{scene}-{points}.yaml"
    case_path.write_text(case_text(csv, scene), encoding="utf-8")

    record: dict = {"points": points, "scene": scene, "method": method, "csv_bytes": csv.stat().st_size}
    clock = time.perf_counter()
    case = load_case(case_path)
    record["validation_s"] = time.perf_counter() - clock
    record["peak_rss_gb_validation"] = peak_rss_gb()
    outline = case.geometry.outer.vertices
    record["boundary_vertices"] = len(outline)
    clock = time.perf_counter()
    assert polygon_problems(outline) is None
    record["simplicity_check_s"] = time.perf_counter() - clock

    timings: dict[str, float] = {}
    problem = prepare(case, timings=timings)
    record["mesh_s"] = timings["mesh"]
    record["assemble_s"] = timings["assemble"]
    record["peak_rss_gb_mesh"] = peak_rss_gb()
    record["mesh_memory_gb"] = record["peak_rss_gb_mesh"] - record["peak_rss_gb_validation"]
    mesh = problem.mesh
    record.update(nodes=int(mesh.n_points), triangles=int(mesh.n_triangles), unknowns=int(problem.n_unknowns),
                  contact_nodes=len(problem.contact.nodes))

    outcome = solve_case(case, method=method, problem=problem)
    samples = [outcome.timings["solve"]]
    record["peak_rss_gb_solve"] = peak_rss_gb()
    kernel = outcome.kernel
    record["backend"] = outcome.backend
    record["newton_steps"] = int(kernel.iterations)
    record["factorizations"] = int(kernel.factorizations)
    record["sequencing"] = dict(outcome.sequencing)
    record["coarse_factorizations"] = int(outcome.sequencing.get("coarse_factorizations", 0))
    record["active_per_step"] = [int(step.active) for step in kernel.history]
    contact = outcome.solution.contact
    active = np.asarray(contact.active, dtype=bool)
    record["active_nodes"] = int(active.sum())
    record["contact_patches"] = patch_count(active)  # runs of active nodes along ΓC
    record["contact_force"] = float(np.sum(contact.nodal_force)) if hasattr(contact, "nodal_force") else None
    del outcome, kernel

    reduced = problem.contact_system(get_method(method))
    matrix, rhs = linear_system(reduced.system)
    del reduced

    def one_linear_solve() -> float:
        started = time.perf_counter()
        factor = factorize(matrix, record["backend"], check=False)
        factor.solve(rhs)
        return time.perf_counter() - started

    # The baseline and the contact solve again, in alternation, so that both see the
    # machine's same phases; as many pairs as take about REPEAT_SECONDS (at least
    # ``repeat``, at most MAX_REPEAT): the fastest of each counts, the medians are kept too.
    pairs = int(min(MAX_REPEAT, max(repeat, REPEAT_SECONDS / max(samples[0], 1e-3))))
    baseline = []
    for index in range(pairs):
        baseline.append(one_linear_solve())
        if index < pairs - 1:
            samples.append(solve_case(case, method=method, problem=problem).timings["solve"])
    record["solve_s"] = min(samples)
    record["solve_samples_s"] = samples
    record["baseline_s"] = min(baseline)
    record["baseline_samples_s"] = baseline
    record["solve_over_baseline"] = record["solve_s"] / record["baseline_s"]
    record["median_solve_over_baseline"] = float(np.median(samples) / np.median(baseline))
    record["peak_rss_gb"] = peak_rss_gb()
    return record


def single(points: int, method: str, keep_heap: bool = True, scene: str = "profile") -> None:
    from performance import heap_as_the_command

    heap_kept = heap_as_the_command(keep_heap)
    with tempfile.TemporaryDirectory(prefix="contactfem-rough-") as tmp:
        measure(200, Path(tmp), method, scene=scene)  # warm-up, untimed
        warm = peak_rss_gb()
        record = measure(points, Path(tmp), method, scene=scene)
        record["peak_rss_gb_warm"] = warm
        record["heap_kept"] = heap_kept
        # What each stage added above the interpreter and libraries.
        record["validation_memory_gb"] = record["peak_rss_gb_validation"] - warm
        record["net_peak_gb"] = record["peak_rss_gb"] - warm
        # The machine's 1, 5 and 15 minute load when the run ended: on a shared machine the
        # ratio moves with it.
        record["load_average"] = list(os.getloadavg())
    sys.stdout.write(RECORD_PREFIX + json.dumps(record) + "\n")
    sys.stdout.flush()


# --------------------------------------------------------------------------- sweep


def run_subprocess(points: int, method: str, timeout: float, keep_heap: bool = True, scene: str = "profile") -> dict:
    command = [sys.executable, str(Path(__file__).resolve()), "--single", str(points), "--method", method,
               "--scene", scene, *([] if keep_heap else ["--plain-heap"])]
    started = time.perf_counter()
    try:
        done = subprocess.run(command, check=False, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
    except subprocess.TimeoutExpired:
        return {"points": points, "method": method, "error": f"timed out after {timeout:.0f} s"}
    for line in done.stdout.splitlines():
        if line.startswith(RECORD_PREFIX):
            record = json.loads(line[len(RECORD_PREFIX):])
            record["subprocess_s"] = time.perf_counter() - started
            return record
    tail = (done.stderr or done.stdout).strip().splitlines()[-15:]
    return {"points": points, "method": method, "error": f"exit code {done.returncode}", "stderr_tail": tail}


STAGES = ("validation_s", "simplicity_check_s", "mesh_s", "assemble_s", "solve_s", "baseline_s", "peak_rss_gb",
          "net_peak_gb", "validation_memory_gb", "mesh_memory_gb", "triangles", "unknowns")


def fit_exponent(sizes: list[float], values: list[float]) -> float | None:
    pairs = [(s, v) for s, v in zip(sizes, values) if s and v and v > 0]
    if len({s for s, _ in pairs}) < 2:
        return None
    s, v = np.array(pairs, dtype=float).T
    return float(np.polyfit(np.log(s), np.log(v), 1)[0])


#: Memory increments below this are the allocator's arenas and page granularity, not the
#: stage (validation adds 0 to 2 MB up to 8 000 points): they are left out of the fits.
MEMORY_FLOOR_GB = 0.004


def scaling(records: list[dict]) -> dict:
    good = sorted((r for r in records if "error" not in r), key=lambda r: r["points"])
    sizes = [r["points"] for r in good]

    def values(stage: str) -> list:
        floor = MEMORY_FLOOR_GB if stage.endswith("_gb") else 0.0
        return [r.get(stage) if (r.get(stage) or 0.0) >= floor else None for r in good]

    return {stage: fit_exponent(sizes, values(stage)) for stage in STAGES}


def _median_ratio(record: dict) -> str:
    """The median ratio shown beside the best: over the rounds, or within the run for a sweep
    of one round (neither in records of earlier sweeps)."""
    ratio = record.get("round_median_ratio", record.get("median_solve_over_baseline"))
    return "-" if ratio is None else f"{ratio:.1f}"


def best_of_rounds(runs: list[dict]) -> dict:
    """One size's record from its runs in several rounds: the run with the lowest ratio of
    those that measured one, with every run's ratio and their median; the first failure if
    every run failed."""
    good = [run for run in runs if "error" not in run]
    if not good:
        return runs[0]
    ratios = [run["solve_over_baseline"] for run in good]
    best = dict(min(good, key=lambda run: run["solve_over_baseline"]))
    best["round_ratios"] = ratios
    best["round_median_ratio"] = float(np.median(ratios))
    return best


def table(records: list[dict]) -> str:
    lines = [("| points | triangles | unknowns | validation s | check s | mesh s | assembly s | solve s | Newton "
              "| factorisations (+ coarse) | baseline s | solve/baseline (median) | peak GB (warm, valid., mesh, all) |"),
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in records:
        if "error" in r:
            lines.append(f"| {r['points']} | failed: {r['error']} |" + " |" * 11)
            continue
        lines.append(
            f"| {r['points']} | {r['triangles']} | {r['unknowns']} | {r['validation_s']:.3f} | "
            f"{r['simplicity_check_s']:.3f} | {r['mesh_s']:.3f} | {r['assemble_s']:.3f} | {r['solve_s']:.2f} | "
            f"{r['newton_steps']} | {r['factorizations']} (+{r['coarse_factorizations']}) | {r['baseline_s']:.2f} | "
            f"{r['solve_over_baseline']:.1f} ({_median_ratio(r)}) | {r['peak_rss_gb_warm']:.3f}, "
            f"{r['peak_rss_gb_validation']:.3f}, "
            f"{r['peak_rss_gb_mesh']:.3f}, "
            f"{r['peak_rss_gb']:.3f} |")
    return "\n".join(lines)


def main() -> None:
    from performance import add_heap_option
    from sizes import add_engine_options, run_sizes

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", type=int, default=DEFAULT_SIZES, help="profile points per run")
    parser.add_argument("--method", default="positive", choices=("positive", "standard"))
    parser.add_argument("--scene", default="profile", choices=("profile", "outline"),
                        help="the rough block's profile (default) or the rough half-disk's outline file")
    parser.add_argument("--out", type=Path, help="default: benchmarks/results/rough.json, or rough_outline.json")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds allowed per size")
    parser.add_argument("--rounds", type=int, default=3, help="runs of each size, the sizes taking turns")
    parser.add_argument("--table", action="store_true", help="print the table of --out and stop")
    parser.add_argument("--single", type=int, metavar="N", help="measure N points in this process")
    add_heap_option(parser)
    add_engine_options(parser)
    parser.add_argument("--write-surface", action="store_true", help=f"rewrite {SURFACE_FILE.relative_to(ROOT)}")
    parser.add_argument("--write-outline", action="store_true", help=f"rewrite {OUTLINE_FILE.relative_to(ROOT)}")
    args = parser.parse_args()
    if args.out is None:
        args.out = DEFAULT_OUT if args.scene == "profile" else DEFAULT_OUT.with_name("rough_outline.json")
    if args.write_surface:
        write_surface(SURFACE_FILE, SHIPPED_POINTS)
        print(f"wrote {SURFACE_FILE}")
        return
    if args.write_outline:
        write_outline(OUTLINE_FILE, SHIPPED_OUTLINE_POINTS)
        print(f"wrote {OUTLINE_FILE}")
        return
    if args.single is not None:
        single(args.single, args.method, keep_heap=not args.plain_heap, scene=args.scene)
        return
    if args.table:
        print(table(json.loads(args.out.read_text())["records"]))
        return

    from performance import machine_info

    benchmark = ("cases/rough.yaml with a self-affine profile of N points" if args.scene == "profile" else
                 "cases/rough_rim.yaml with a rough outline of N vertices read from its file")
    result = {"benchmark": benchmark, "scene": args.scene, "started":
              time.strftime("%Y-%m-%d %H:%M:%S %Z"), "command": " ".join([Path(sys.executable).name, *sys.argv]),
              "hurst": HURST, "height": HEIGHT, "seed": SEED, "sizes": args.sizes, "method": args.method,
              "heap": "glibc defaults" if args.plain_heap else "kept for reuse, as the command runs (contactfem.heap)",
              "machine": machine_info(), "rounds": args.rounds, "records": []}
    runs: dict[int, list[dict]] = {points: [] for points in args.sizes}

    def finished(record: dict) -> None:
        runs[record["points"]].append(record)
        result["records"] = [best_of_rounds(done) for done in runs.values() if done]
        result["growth_exponents"] = scaling(result["records"])
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(result, indent=2) + "\n")
        report_run(record["points"], record)

    # Each size in its own subprocess, here one after another or as Dask tasks (--workers, --scheduler).
    for _ in range(max(args.rounds, 1)):
        run_sizes(functools.partial(run_subprocess, method=args.method, timeout=args.timeout,
                                    keep_heap=not args.plain_heap, scene=args.scene),
                  args.sizes, scheduler=args.scheduler, workers=args.workers, finished=finished,
                  lost=lambda points, reason: {"points": points, "method": args.method, "error": reason})
    print(table(result["records"]))
    print("growth exponents (time ~ points^p):", json.dumps(result["growth_exponents"]))


def report_run(points: int, record: dict) -> None:
    """One line of progress for a run of the sweep."""
    if "error" in record:
        print(f"{points:7d} points: FAILED: {record['error']}", flush=True)
    else:
        print(f"{points:7d} points: validation {record['validation_s']:.3f} s, mesh {record['mesh_s']:.3f} s "
              f"({record['triangles']} triangles), assembly {record['assemble_s']:.3f} s, solve "
              f"{record['solve_s']:.2f} s ({record['newton_steps']} Newton, {record['factorizations']} "
              f"factorisations), baseline {record['baseline_s']:.2f} s, ratio {record['solve_over_baseline']:.2f}, "
              f"peak {record['peak_rss_gb']:.2f} GB", flush=True)


if __name__ == "__main__":
    main()
