"""What the PETSc install route's BLAS and MUMPS's ordering cost: the square of cases/square.yaml
(--refine 4: 512 divisions, 525 000 unknowns) with MUMPS on 1 and 2 MPI ranks, with Debian's
reference BLAS against OpenBLAS, and with MUMPS's automatic ordering (ICNTL(7) = 7) against
PORD (4, in every MUMPS) and the ordering contactfem chooses
(:func:`contactfem.distributed_mumps.mumps_ordering`: METIS, else SCOTCH, else the automatic one,
as the library has).

Usage:
    python benchmarks/petsc_install_route.py                       # refine 4, 1 and 2 ranks, twice
    python benchmarks/petsc_install_route.py --refine 3 --repeats 1

Each run is its own ``mpiexec`` job of benchmarks/petsc_scaling.py (one BLAS thread per rank).
The reference BLAS is selected for that job alone by putting the directories of Debian's
``libblas3``/``liblapack3`` first on LD_LIBRARY_PATH (the system's alternative, OpenBLAS at
priority 100 once ``libopenblas0-pthread`` is installed, is left as it is); every record names
the BLAS and LAPACK objects its process mapped. The ordering is passed as PETSc's option
``-mat_mumps_icntl_7``; MUMPS reports in each factorisation the ordering it used (INFOG(7)),
the factor entries and the flops, which do not depend on the machine's load. Seconds are the
fastest of ``--repeats`` runs. Writes benchmarks/results/petsc_install_route.json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from petsc_scaling import ROOT, run  # noqa: E402

OUT = ROOT / "benchmarks" / "results" / "petsc_install_route.json"
#: Debian's reference BLAS and LAPACK (packages libblas3, liblapack3).
REFERENCE_BLAS = "/usr/lib/x86_64-linux-gnu/blas:/usr/lib/x86_64-linux-gnu/lapack"
#: Debian's MUMPS orderings by name (ICNTL(7)).
ORDERING_NAMES = {0: "AMD", 2: "AMF", 3: "SCOTCH", 4: "PORD", 5: "METIS", 6: "QAMD", 7: "automatic"}


def chosen_ordering() -> int:
    """The ordering contactfem chooses on this machine, asked of its MUMPS."""
    from petsc4py import PETSc

    from contactfem.distributed_mumps import mumps_ordering

    return mumps_ordering(PETSc)


def summary(record: dict) -> dict:
    """The figures of one job: seconds of each factorisation on rank 0, what MUMPS reports."""
    factor = record["per_rank"][0]["factor"]
    return {"newton_steps": record["newton_steps"], "factorizations": record["factorizations"],
            "factor_s": record["per_rank"][0]["factor_s"], "solve_s": record["stages_s"]["solve"],
            "wall_s": record["wall_s"], "ordering_used": ORDERING_NAMES.get(factor.get("ordering"), factor.get("ordering")),
            "factor_entries": factor.get("factor_entries"), "flops": factor.get("flops"),
            "max_peak_rss_gb": record["max_peak_rss_gb"], "contact_force": record["contact_force"],
            "blas_libraries": record.get("blas_libraries", [])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--refine", type=int, default=4)
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=900.0)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    chosen = chosen_ordering()
    document = {"benchmark": "petsc_install_route", "case": "cases/square.yaml", "refine": args.refine,
                "command": " ".join(sys.argv), "started": time.strftime("%Y-%m-%dT%H:%M:%S"),
                "machine": {"python": platform.python_version(), "platform": platform.platform(),
                            "cpus": os.cpu_count()},
                "chosen_ordering": ORDERING_NAMES[chosen], "runs": []}
    for blas, library_path in (("reference", REFERENCE_BLAS), ("openblas", None)):
        for ordering in dict.fromkeys((7, 4, chosen)):
            for ranks in args.ranks:
                environment = {"PETSC_OPTIONS": f"-mat_mumps_icntl_7 {ordering}"}
                if library_path is not None:
                    environment["LD_LIBRARY_PATH"] = ":".join(filter(None, [library_path,
                                                                            os.environ.get("LD_LIBRARY_PATH")]))
                tries = []
                for _ in range(args.repeats):
                    record = run(args.refine, ranks, "mumps", "positive", args.timeout, environment=environment)
                    if "error" in record:
                        tries.append(record)
                        break
                    tries.append(summary(record))
                good = [t for t in tries if "error" not in t]
                best = min(good, key=lambda t: sum(t["factor_s"])) if good else tries[-1]
                entry = {"blas": blas, "ordering_asked": ORDERING_NAMES[ordering], "ranks": ranks,
                         "unknowns": record.get("unknowns"), "repeats": len(tries),
                         "factor_s_each_try": [sum(t["factor_s"]) for t in good], **best}
                document["runs"].append(entry)
                args.out.write_text(json.dumps(document, indent=2, sort_keys=True) + "\n")
                print(f"{blas:9} {ORDERING_NAMES[ordering]:9} {ranks} rank(s): "
                      + (entry.get("error") or f"factorisations {entry['factorizations']}, factor s "
                         f"{', '.join(f'{x:.2f}' for x in entry['factor_s'])}, used {entry['ordering_used']}, "
                         f"entries {entry['factor_entries']:,}, flops {entry['flops']:.3g}, "
                         f"peak {entry['max_peak_rss_gb']:.2f} GB"), flush=True)
    document["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S")
    args.out.write_text(json.dumps(document, indent=2, sort_keys=True) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
