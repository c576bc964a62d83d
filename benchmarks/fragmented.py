"""Contact solves whose active set is fragmented, against one linear solve of the same mesh.

Usage:
    python benchmarks/fragmented.py                  # every scene at its default sizes (minutes)
    python benchmarks/fragmented.py --quick          # the small sizes only (about a minute)
    python benchmarks/fragmented.py --scenes rough --sizes 4000 --methods positive
    python benchmarks/fragmented.py --scenes square --sizes 256 1024

Scenes (``--sizes`` means segments for rough, wavenumbers for wavy, divisions for square,
refinements for shipped and overlap):

- ``rough``: a 1 x 0.5 block whose base is a self-affine profile y = h(x) (Hurst 0.8,
  rms 2e-4, a seeded random-phase spectrum over 1 … segments/2 waves, one polygon vertex
  per segment), pushed down by 9e-4 at its top (u = (0, -9e-4)) onto the plane
  y <= min(h); sides free. Mesh size 28/segments (Triangle, min angle 30°), so the mesh
  grows with the profile. The polygon is built in Python: a case file holds at most
  2 000 vertices.
- ``light``: the same block pushed down by 1e-4 only (:data:`LIGHT_PUSH`): a few patches
  at the highest asperities, which a cold start finds in a few cheap Schur steps from its
  first solve, so that a coarse level has little to save.
- ``long``: a strip of length segments/1000 and depth 0.5 whose base is a rough profile
  of that length (spacing 1e-3, rms 2e-4), pushed down by 5e-4: hundreds of patches on a
  long, thin mesh whose elimination tree has long paths (:func:`long_case`).
- ``wavy``: a 1 x (1/k) strip clamped on its left, resting on y <= 0, under the top traction
  (0, -1e4 (0.1 + sin(k x))): a contact patch per period, k/2π of them; 16 cells per
  period along x, 4 across. At k = 2000 (aspect 2000) the strip held by its clamp alone is
  numerically singular: the kernel's first set is every touching node, and the baseline
  fixes their normals too.
- ``strip``: a 1 x 0.01 strip clamped on its left, resting on y <= 0, under the pressure
  0.5 + sin(10 x), which pulls it up on a fifth of its length (``--sizes``: cells along
  it, 4 across): a body in bending peeling off, whose zone creeps to its edges a node per
  edge per Newton step from a cold start (:func:`contactfem.kernel.default_max_iterations`).
- ``teeth``: a 0.5-deep block standing on ``--sizes`` teeth 0.006 wide, 0.016 apart and
  0.03 high (a tread), their tips up to 4e-4 off level, pushed down by 2e-4: a contact patch
  per tooth on separate contact edges, graded onto them (:func:`teeth_case`). The teeth
  cannot be decimated: a coarser level keeps 40% of the unknowns.
- ``square``: cases/square.yaml at N x N (one contact zone, for comparison).
- ``shipped``: every case of cases/ refined the given number of times.
- ``overlap``: bodies that start inside the obstacle (:func:`overlap_cases`), refined the
  given number of times: where the overlap is the answer, partly it, or no prediction.

Per scene, size and method, with mesh sequencing on (the pipeline's ``solve_case``) and
off (the same reduction and kernel from a cold start): unknowns, active nodes, patches
(runs of consecutive active nodes along ΓC), Newton steps, factorisations, column solves,
contact-solve seconds (reduction, sequencing and kernel), one linear solve (factorise the
kernel's stiffness without contact, with the same backend, and solve once) and their
ratio; the fastest of ``--repeat`` runs (cold and sequenced in alternation), in a process whose C heap is kept for reuse as the
``contactfem`` command keeps it (:mod:`contactfem.heap`; ``--plain-heap`` leaves glibc's
defaults). Writes benchmarks/results/fragmented.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

from contactfem.threads import one_blas_thread

one_blas_thread()  # as the command runs, before numpy loads (OPENBLAS_NUM_THREADS set in the environment wins)

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from performance import (
    add_heap_option,
    heap_as_the_command,
    linear_system,
    machine_info,
)

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "benchmarks" / "results" / "fragmented.json"
DEFAULT_SIZES = {"rough": [1000, 4000, 16000], "light": [1000, 4000, 16000], "long": [4000, 16000, 64000],
                 "wavy": [200], "strip": [400, 1600, 6400, 25600], "square": [256, 1024], "shipped": [3], "overlap": [2],
                 "teeth": [60, 300, 1000]}
QUICK_SIZES = {"rough": [1000, 4000], "light": [1000], "long": [4000], "wavy": [200], "strip": [400], "square": [256],
               "shipped": [2], "overlap": [1], "teeth": [60]}
#: The ``light`` scene's push: the rough block touches at its highest asperities only.
LIGHT_PUSH = 1e-4
#: The ``long`` scene's push: 200-450 patches at 4 000-16 000 segments.
LONG_PUSH = 5e-4
SEED = 20050101


# --------------------------------------------------------------------------- scenes


def rough_profile(segments: int, hurst: float = 0.8, rms: float = 2e-4, seed: int = SEED) -> tuple[np.ndarray, np.ndarray]:
    """x (segments + 1,) in [0, 1] and a self-affine height h(x) of standard deviation ``rms``:
    random phases, amplitude k^-(1/2 + H) for the k-th harmonic, k = 1 … segments/2."""
    rng = np.random.default_rng(seed)
    k = np.arange(1, segments // 2 + 1)
    phase = rng.uniform(0.0, 2 * np.pi, len(k))
    x = np.arange(segments + 1) / segments
    spectrum = np.zeros(segments, dtype=complex)
    spectrum[k] = k ** -(0.5 + hurst) * np.exp(1j * phase)
    h = np.fft.ifft(spectrum).real * segments
    h = np.append(h, h[0])
    h -= h.mean()
    return x, h * rms / h.std()


def rough_case(segments: int, seed: int = SEED, push: float = 9e-4, length: float = 1.0, rms: float = 2e-4):
    from contactfem.case import PolygonGeometry, parse_case
    from contactfem.mesh.polygon import Loop

    x, h = rough_profile(segments, seed=seed, rms=rms)
    x = length * x
    data = {
        "title": f"rough base, {segments} segments, pushed {push:g}",
        "geometry": {"polygon": {"vertices": [[0, 0], [length, 0], [length, 0.5], [0, 0.5]],
                                 "edges": ["base", "side", "top", "side"]}},
        "mesh": {"size": 28.0 * length / segments},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"top": {"displacement": [0, -push]}, "side": "free", "base": "contact"},
        "obstacle": {"point": [0, float(h.min())], "normal": [0, -1]},
    }
    case = parse_case(yaml.safe_dump(data), source=ROOT / "benchmarks" / f"rough-{segments}.yaml")
    vertices = np.vstack([np.column_stack([x, h]), [[length, 0.5], [0.0, 0.5]]])
    names = ("base",) * segments + ("side", "top", "side")
    return replace(case, geometry=PolygonGeometry(Loop(vertices, names), ()))


def long_case(segments: int, seed: int = SEED):
    """A rough strip segments/1000 long (profile spacing 1e-3) and 0.5 deep, its profile
    the rough block's synthesis over that window (rms 2e-4), pushed down by
    :data:`LONG_PUSH`: the block's push of 9e-4 flattens a strip this thin over its whole
    length (one patch from 64 000 segments)."""
    return rough_case(segments, seed=seed, push=LONG_PUSH, length=segments / 1000)


#: The ``teeth`` scene's tooth width, pitch and height, and the push on the block's top.
TOOTH_WIDTH, TOOTH_PITCH, TOOTH_HEIGHT, TEETH_PUSH = 0.006, 0.016, 0.03, 2e-4


def teeth_case(teeth: int, seed: int = SEED):
    """A block 0.5 deep standing on ``teeth`` teeth (a tread, a comb), each tip its own
    contact part's edge, the tips up to 4e-4 off level (seeded), pushed down by
    :data:`TEETH_PUSH`; graded onto the tips (size 0.05, contact_size 0.002). The teeth
    are not decimated, so a coarser level keeps every vertex and 40% of the unknowns."""
    from contactfem.case import PolygonGeometry, parse_case
    from contactfem.mesh.polygon import Loop

    rng = np.random.default_rng(seed)
    length = teeth * TOOTH_PITCH
    vertices, names = [], []
    for i in range(teeth):
        left = i * TOOTH_PITCH + (TOOTH_PITCH - TOOTH_WIDTH) / 2
        tip = -TOOTH_HEIGHT + rng.uniform(0.0, 4e-4)
        vertices += [(left, 0.0), (left, tip), (left + TOOTH_WIDTH, tip), (left + TOOTH_WIDTH, 0.0)]
        names += ["flank", "tip", "flank", "root"]
    vertices += [(length, 0.0), (length, 0.5), (0.0, 0.5), (0.0, 0.0)]
    names += ["side", "top", "side", "root"]
    data = {
        "title": f"a block on {teeth} teeth, pushed {TEETH_PUSH:g}",
        "geometry": {"polygon": {"vertices": [[0, 0], [length, 0], [length, 0.5], [0, 0.5]],
                                 "edges": ["tip", "side", "top", "side"]}},
        "mesh": {"size": 0.05, "contact_size": 0.002},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"top": {"displacement": [0, -TEETH_PUSH]}, "tip": "contact"},
        "obstacle": {"point": [0, -TOOTH_HEIGHT], "normal": [0, -1]},
    }
    case = parse_case(yaml.safe_dump(data), source=ROOT / "benchmarks" / f"teeth-{teeth}.yaml")
    return replace(case, geometry=PolygonGeometry(Loop(np.array(vertices), tuple(names)), ()))


def wavy_case(wavenumber: int):
    from contactfem.case import parse_case

    nx = int(16 * wavenumber // (2 * np.pi)) // 4 * 4 + 4
    data = {
        "title": f"strip under a traction of wavenumber {wavenumber}",
        "geometry": {"rectangle": {"lower": [0, 0], "upper": [1, 1.0 / wavenumber]}},
        "mesh": {"divisions": [nx, 4]},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"left": "clamped", "right": "free", "bottom": "contact",
                     "top": {"traction": [0, f"-1e4*(0.1 + sin({wavenumber}*x))"]}},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }
    return parse_case(yaml.safe_dump(data), source=ROOT / "benchmarks" / f"wavy-{wavenumber}.yaml")


def strip_case(cells: int):
    from contactfem.case import parse_case

    data = {
        "title": f"strip 1 x 0.01 peeling off, {cells} cells along it",
        "geometry": {"rectangle": {"lower": [0, 0], "upper": [1, 0.01]}},
        "mesh": {"divisions": [cells, 4]},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"left": "clamped", "right": "free", "bottom": "contact",
                     "top": {"traction": [0, "-1.0*(0.5 + sin(10*x))"]}},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }
    return parse_case(yaml.safe_dump(data), source=ROOT / "benchmarks" / f"strip-{cells}.yaml")


def square_case(divisions: int):
    from contactfem.case import parse_case

    data = yaml.safe_load((ROOT / "cases" / "square.yaml").read_text())
    data["mesh"]["divisions"] = divisions
    return parse_case(yaml.safe_dump(data), source=ROOT / "cases" / "square.yaml")


def overlap_cases() -> list[tuple[str, object]]:
    """Bodies that start inside the obstacle: a tilted flat face pressed into the block over
    part of its width (cases/flat_punch.yaml, the face from 3e-3 in at x = 1 to 1e-3 out at
    x = −1), the same face pressed in over all of it (4e-3 to 2e-4, about half of it
    releases), and the Hertz half-disk with its top held and the plane moved 4e-3 into it
    (the overlap twice as wide as the contact zone)."""
    from contactfem.case import parse_case

    punch_file = ROOT / "cases" / "flat_punch.yaml"
    cases = []
    for label, segment in (("tilted-partly-in", [[1.0, -3e-3], [-1.0, 1e-3]]),
                           ("tilted-all-in", [[1.05, -4e-3], [-1.05, -2e-4]])):
        data = yaml.safe_load(punch_file.read_text())
        data["obstacle"] = {"segment": segment}
        cases.append((label, parse_case(yaml.safe_dump(data), source=punch_file)))
    hertz_file = ROOT / "cases" / "hertz.yaml"
    data = yaml.safe_load(hertz_file.read_text())
    data["boundary"]["top"] = "clamped"
    data["obstacle"]["point"] = [0, 4e-3]
    cases.append(("hertz-pressed-in", parse_case(yaml.safe_dump(data), source=hertz_file)))
    return cases


def scenes(name: str, size: int) -> list[tuple[str, object, int | None]]:
    """(label, case, refine) of one scene at one size."""
    if name == "overlap":
        return [(f"{label}-refine{size}", case, size) for label, case in overlap_cases()]
    if name == "rough":
        return [(f"rough-{size}", rough_case(size), None)]
    if name == "light":
        return [(f"light-{size}", rough_case(size, push=LIGHT_PUSH), None)]
    if name == "long":
        return [(f"long-{size}", long_case(size), None)]
    if name == "wavy":
        return [(f"wavy-{size}", wavy_case(size), None)]
    if name == "teeth":
        return [(f"teeth-{size}", teeth_case(size), None)]
    if name == "strip":
        return [(f"strip-{size}", strip_case(size), None)]
    if name == "square":
        return [(f"square-{size}", square_case(size), None)]
    from contactfem.case import load_case

    return [(f"{path.stem}-refine{size}", load_case(path), size) for path in sorted((ROOT / "cases").glob("*.yaml"))]


# --------------------------------------------------------------------------- measuring


def contact_solve(case, problem, method: str, sequencing: bool) -> tuple[float, object, dict]:
    """Seconds of the contact solve, the kernel's result and the sequencing record."""
    from contactfem.kernel import default_c, solve_contact
    from contactfem.linalg import resolve_backend
    from contactfem.methods import get_method
    from contactfem.solve import solve_case

    if sequencing:
        outcome = solve_case(case, method=method, problem=problem)
        return outcome.timings["solve"], outcome.kernel, dict(outcome.sequencing)
    started = time.perf_counter()
    reduced = problem.contact_system(get_method(method))
    c = case.solver.c if case.solver.c is not None else default_c(reduced.system)
    kernel = solve_contact(reduced.system, c=c, tolerance=case.solver.tolerance,
                           max_iterations=case.solver.max_iterations, backend=resolve_backend(case.solver.backend))
    return time.perf_counter() - started, kernel, {}


def one_linear_solve(problem, backend: str) -> float:
    """Seconds to factorise the kernel's stiffness with its supports and solve once. A body
    held by contact alone (a force-driven platen, a Hertz disk under its load) has no such
    solve: its normals at the contact nodes that start closest are fixed as well, as many
    as there are free rigid motions, which the kernel's every active set does too. A body
    its supports leave numerically free (a strip 1/3200 thick clamped at one end) has its
    touching normals fixed as well, as the kernel's first set then does."""
    from dataclasses import replace

    import numpy as np

    from contactfem.errors import SolverError
    from contactfem.linalg import factorize
    from contactfem.methods import get_method

    def fixing(system, nodes):
        """``system`` with the normals of ``nodes`` fixed at their gaps too (once each)."""
        dofs = np.concatenate([system.fixed_dofs, np.asarray(system.normal_dofs)[nodes]])
        values = np.concatenate([system.fixed_values, np.asarray(system.gap)[nodes]])
        dofs, first = np.unique(dofs, return_index=True)
        return replace(system, fixed_dofs=dofs, fixed_values=values[first], free_modes=None)

    system = problem.contact_system(get_method("positive")).system
    if system.free_modes is not None:
        system = fixing(system, np.argsort(system.gap, kind="stable")[:system.free_modes.shape[1]])
    try:
        matrix, _ = linear_system(system)
        factorize(matrix, backend)
    except SolverError:
        system = fixing(system, np.flatnonzero(np.asarray(system.gap) <= 0.0))
    matrix, rhs = linear_system(system)
    started = time.perf_counter()
    factorize(matrix, backend).solve(rhs)
    return time.perf_counter() - started


def measure(label: str, case, refine: int | None, method: str, repeat: int) -> list[dict]:
    from contactfem.kernel import Status
    from contactfem.linalg import resolve_backend
    from contactfem.sequencing import patch_count
    from contactfem.solve import prepare

    backend = resolve_backend(case.solver.backend)
    problem = prepare(case, refine=refine)
    baseline = min(one_linear_solve(problem, backend) for _ in range(repeat))
    records = []
    # Cold and sequenced runs in alternation, so that both see the machine's same phases.
    taken: dict[bool, list] = {False: [], True: []}
    for _ in range(repeat):
        for sequencing in (False, True):
            taken[sequencing].append(contact_solve(case, problem, method, sequencing))
    for sequencing in (False, True):
        runs = taken[sequencing]
        seconds = min(r[0] for r in runs)
        _, kernel, record = runs[-1]
        records.append({
            "scene": label,
            "method": method,
            "sequencing": sequencing,
            "backend": backend,
            "unknowns": problem.n_unknowns,
            "contact_nodes": len(problem.contact.nodes),
            "status": kernel.status.value,
            "certified": bool(kernel.status is Status.CONVERGED),
            "active_nodes": int(kernel.active.sum()),
            "patches": patch_count(kernel.active),
            "newton_steps": kernel.iterations,
            "factorizations": kernel.factorizations,
            "column_solves": kernel.column_solves,
            "active_per_step": [r.active for r in kernel.history],
            "changes_per_step": [r.added + r.removed for r in kernel.history],
            "contact_solve_s": seconds,
            "contact_solve_samples_s": [r[0] for r in runs],
            "linear_solve_s": baseline,
            "ratio": seconds / baseline,
            "sequencing_record": record,
        })
    return records


def warm_up() -> None:
    """Imports and a first factorisation, untimed."""
    from contactfem.solve import prepare

    case = square_case(16)
    contact_solve(case, prepare(case), "positive", True)


# --------------------------------------------------------------------------- output


def table(records: list[dict]) -> str:
    lines = ["| scene | method | seq | unknowns | active | patches | Newton | fact. | columns | solve s | linear s | ratio |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in records:
        lines.append(
            f"| {r['scene']} | {r['method']} | {'on' if r['sequencing'] else 'off'} | {r['unknowns']} | "
            f"{r['active_nodes']} | {r['patches']} | {r['newton_steps']} | {r['factorizations']} | "
            f"{r['column_solves']} | {r['contact_solve_s']:.3f} | {r['linear_solve_s']:.3f} | {r['ratio']:.2f} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", nargs="+", choices=list(DEFAULT_SIZES),
                        default=["rough", "light", "long", "wavy", "strip", "square", "shipped", "teeth"])
    parser.add_argument("--sizes", nargs="+", type=int, help="sizes for every scene chosen (default: per scene)")
    parser.add_argument("--quick", action="store_true", help="the small sizes only")
    parser.add_argument("--methods", nargs="+", choices=["positive", "standard"], default=["positive", "standard"])
    parser.add_argument("--repeat", type=int, default=2, help="runs per measurement, the fastest kept (default 2)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    add_heap_option(parser)
    args = parser.parse_args()
    heap_kept = heap_as_the_command(not args.plain_heap)

    result = {
        "benchmark": "fragmented contact: rough profiles, wavy tractions, the square, the shipped cases",
        "started": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "repeat": args.repeat,
        "heap_kept": heap_kept,
        "machine": machine_info(),
        "records": [],
    }
    warm_up()
    for name in args.scenes:
        sizes = args.sizes or (QUICK_SIZES if args.quick else DEFAULT_SIZES)[name]
        for size in sizes:
            for label, case, refine in scenes(name, size):
                for method in args.methods:
                    for record in measure(label, case, refine, method, args.repeat):
                        result["records"].append(record)
                        print(f"{label:24s} {method:9s} seq {'on ' if record['sequencing'] else 'off'} "
                              f"unknowns {record['unknowns']:8d} active {record['active_nodes']:6d} "
                              f"patches {record['patches']:5d} Newton {record['newton_steps']:3d} "
                              f"fact {record['factorizations']:2d} columns {record['column_solves']:4d} "
                              f"solve {record['contact_solve_s']:7.3f} s linear {record['linear_solve_s']:7.3f} s "
                              f"ratio {record['ratio']:5.2f}", flush=True)
                    args.out.parent.mkdir(parents=True, exist_ok=True)
                    args.out.write_text(json.dumps(result, indent=2) + "\n")
    result["finished"] = time.strftime("%Y-%m-%d %H:%M:%S %Z")
    result["table"] = table(result["records"])
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(result["table"])
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
