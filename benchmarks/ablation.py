"""Ablation of the kernel's accelerators: what each saves of the contact solve at 100k unknowns and more.

Usage:
    python benchmarks/ablation.py                 # every scene, best of 3 (about 10 minutes on 2 cores)
    python benchmarks/ablation.py --repeat 5      # best of 5
    python benchmarks/ablation.py --scenes square rough

Each scene is solved with every accelerator on, then with one switched off at a time
(:class:`contactfem.kernel.Accelerators`: ``sequencing``, ``zone_fronts``,
``schur_updates``, and ``start_checks``, which only load paths use), and with the two
refinements of the coarse prediction switched off (the half-plane ``asperity`` correction and the fine ``layer`` correction, parts of
sequencing), the Schur solver's sparse ``forward columns`` (full columns instead) and the
``worker thread`` that builds a level's system beside its coarser levels. The contact solve's seconds (``timings["solve"]``: coarse levels and every
Newton step; for a load path the whole path) are the fastest of ``--repeat`` runs, in
alternation so that a slow phase of the machine hits every configuration alike. Every
run must converge to the same active set (the accelerators change the cost, never the
answer); the script checks it and records the Newton steps and factorisations.

An accelerator earns its keep when switching it off costs at least 10% of the contact
solve on some scene at 100k unknowns or more. The table goes to
benchmarks/results/ablation.json.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from contactfem.threads import one_blas_thread  # noqa: E402

one_blas_thread()

OUT = ROOT / "benchmarks" / "results" / "ablation.json"
CONFIGURATIONS = ("all", "no sequencing", "no zone fronts", "no schur updates", "no start checks",
                  "no asperity correction", "no layer correction", "no forward columns", "no worker thread")
#: The configurations that only switch parts of sequencing off: nothing to switch in a cold scene.
SEQUENCING_PARTS = ("no sequencing", "no asperity correction", "no layer correction", "no worker thread")
SCENES = ("square", "rough", "hertz", "punch", "strip", "strip_cold", "rough_loading", "hertz_tenfold")
#: Scenes solved without a coarser level in every configuration: a body whose mesh has no
#: coarser level (a mesh file), where the zone fronts alone shorten a creeping zone's path.
COLD = ("strip_cold",)


def scene_case(name: str, directory: Path):
    """The scene's case and its refinements: each at 100k unknowns or more."""
    from contactfem.case import load_case, parse_case

    if name == "square":
        data = yaml.safe_load((ROOT / "cases" / "square.yaml").read_text())
        data["mesh"]["divisions"] = 256
        return parse_case(yaml.safe_dump(data), source=ROOT / "cases" / "square.yaml"), 0
    if name == "rough":
        from rough import case_text, write_surface

        csv = directory / "profile.csv"
        write_surface(csv, 16_000)
        return parse_case(case_text(csv), source=directory / "rough.yaml"), 0
    if name == "hertz_tenfold":
        from load_path import scene  # the Hertz platen's zone growing ten-fold along 20 steps

        return scene(name, 20, 2), 2
    refinements = {"hertz": 1, "punch": 3, "strip": 3, "strip_cold": 3, "rough_loading": 1}[name]
    return load_case(ROOT / "cases" / f"{name.removesuffix('_cold')}.yaml"), refinements


@contextlib.contextmanager
def switched(configuration: str, cold: bool = False):
    """The accelerators of ``configuration``, and the sequencing parts it switches off."""
    import contactfem.kernel.costs as costs
    import contactfem.sequencing as sequencing
    import contactfem.solve as solve_module
    from contactfem.kernel import Accelerators

    saved = (sequencing.correct_at_asperities, sequencing.layer_pays, costs.FORWARD_COLUMNS_FROM,
             costs.SIMPLICIAL_FORWARD_COLUMNS_FROM, solve_module.ThreadPoolExecutor)
    if configuration == "no asperity correction":
        sequencing.correct_at_asperities = lambda fine, normal, force, law, active, spacing: active
    if configuration == "no layer correction":
        sequencing.layer_pays = lambda *args: False
    if configuration == "no forward columns":
        costs.FORWARD_COLUMNS_FROM = costs.SIMPLICIAL_FORWARD_COLUMNS_FROM = 2**62
    if configuration == "no worker thread":
        solve_module.ThreadPoolExecutor = lambda *args, **kwargs: solve_module._InPlace()
    try:
        yield Accelerators(sequencing=configuration != "no sequencing" and not cold,
                           zone_fronts=configuration != "no zone fronts",
                           schur_updates=configuration != "no schur updates",
                           start_checks=configuration != "no start checks")
    finally:
        (sequencing.correct_at_asperities, sequencing.layer_pays, costs.FORWARD_COLUMNS_FROM,
         costs.SIMPLICIAL_FORWARD_COLUMNS_FROM, solve_module.ThreadPoolExecutor) = saved


def run(case, refine: int, configuration: str, problem, cold: bool = False) -> dict:
    import dataclasses

    import contactfem.solve as solve_module

    with switched(configuration, cold) as accelerators:
        if case.load_path is not None:
            original = solve_module.case_accelerators
            solve_module.case_accelerators = lambda _case: accelerators
            try:
                path = solve_module.solve_load_path(case, refine=refine, keep_steps=False)
            finally:
                solve_module.case_accelerators = original
            last = path.final.kernel
            return {"seconds": path.timings["solve"], "factorizations": path.factorizations,
                    "iterations": sum(1 for _ in path.factors), "active": last.active}
        started = time.perf_counter()
        result = solve_module.solve_case(case, problem=problem, accelerators=accelerators)
        seconds = time.perf_counter() - started
        kernel = result.kernel
        return {"seconds": seconds, "factorizations": kernel.factorizations, "iterations": kernel.iterations,
                "coarse_factorizations": result.sequencing.get("coarse_factorizations", 0), "active": kernel.active}


def measure(name: str, repeat: int, directory: Path) -> dict:
    from contactfem.solve import prepare

    case, refine = scene_case(name, directory)
    problem = None if case.load_path is not None else prepare(case, refine=refine)
    unknowns = problem.n_unknowns if problem is not None else prepare(case, refine=refine).n_unknowns
    cold = name in COLD
    configurations = [c for c in CONFIGURATIONS if not (cold and c in SEQUENCING_PARTS)]
    runs: dict[str, list[dict]] = {c: [] for c in configurations}
    run(case, refine, "all", problem, cold)  # warm-up: the process's first touch of this size's memory
    for _ in range(repeat):
        for configuration in configurations:
            runs[configuration].append(run(case, refine, configuration, problem, cold))
    reference = runs["all"][0]["active"]
    record = {"unknowns": unknowns, "configurations": {}}
    for configuration, samples in runs.items():
        assert all(np.array_equal(s["active"], reference) for s in samples), (name, configuration)
        best = min(samples, key=lambda s: s["seconds"])
        record["configurations"][configuration] = {
            "seconds": best["seconds"], "samples_s": [s["seconds"] for s in samples],
            **{k: v for k, v in best.items() if k not in ("seconds", "active")}}
    base = record["configurations"]["all"]["seconds"]
    for configuration, figures in record["configurations"].items():
        figures["cost_when_off"] = figures["seconds"] / base - 1.0
    return record


def table(results: dict) -> str:
    lines = ["| scene | unknowns | all (s) | " + " | ".join(c for c in CONFIGURATIONS[1:]) + " |",
             "|---|---|---|" + "---|" * (len(CONFIGURATIONS) - 1)]
    for name, record in results["scenes"].items():
        figures = record["configurations"]
        cells = [f"{figures[c]['seconds']:.3g} ({figures[c]['cost_when_off']:+.0%})" if c in figures else "—"
                 for c in CONFIGURATIONS[1:]]
        lines.append(f"| {name} | {record['unknowns']} | {figures['all']['seconds']:.3g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES))
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    results = {"date": time.strftime("%Y-%m-%d"), "repeat": args.repeat, "scenes": {}}
    with tempfile.TemporaryDirectory() as directory:
        for name in args.scenes:
            results["scenes"][name] = measure(name, args.repeat, Path(directory))
            print(f"{name}: done", file=sys.stderr, flush=True)
            args.out.write_text(json.dumps(results, indent=1) + "\n")
    results["table"] = table(results)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    print(results["table"])


if __name__ == "__main__":
    main()
