"""Sweeps: many independent solves of one base case, each with some of its keys changed.

A sweep file (YAML, read as boundedly as a case file) names a base case and the values to
give its keys, by dotted path::

    case: ../square.yaml                 # relative to the sweep file
    grid:                                # the cartesian product (the last key varies fastest)
      mesh.divisions: [16, 32, 64]
      solver.method: [positive, standard]
    # points:                            # or an explicit list
    #   - {mesh.divisions: 16, material.nu: 0.3}
    #   - {mesh.divisions: 32, boundary.top.traction: [1.0e4, 0]}
    output:
      directory: results/my-sweep        # optional; default results/<sweep file name>

A point is the base case's YAML mapping with its values set (a list element by
``key[i]``; missing mappings are created), dumped back to YAML: that text is the point's
case, validated by :func:`contactfem.case.parse_case` like any file, and its SHA-256 with
the data files it reads (the case's digest) names the point's stored record
(``points/<sha256>.json``), so that a sweep run again solves only what is not stored yet,
and a point whose profile, outline or mesh file changed anew.

Each point is solved by :func:`solve_point`, in this process one after another or on a
Dask cluster (:mod:`contactfem.engines`, Dask an optional dependency imported there). Nothing here
writes or prints: :func:`run_sweep` hands every finished point to the caller's callbacks
(the command line stores it at once and prints a line) and returns the table.

The error of a point is the energy norm of u − u_h when the case has an exact solution
(report.json's ``errors.displacement_energy``); without one, the residual estimator's η
(report.json's ``accuracy.energy.estimate``, the estimate every solve reports: reliable up
to a constant, so that the points of a group compare honestly, and falling with h where the
difference to the finest point did not), for every point of a group solved with method (4);
else |‖u_h‖_a − ‖u_ref‖_a|, u_ref the point with the most unknowns among those that share
every swept value outside ``mesh.*`` (its group): a lower bound of the energy norm of
u_h − u_ref that needs no interpolation between meshes. The Pareto front (no other point of the group is both faster
and more accurate) is marked per group.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from contactfem import __version__
from contactfem.case import parse_case
from contactfem.errors import ArchiveError, CaseError, ContactFemError, FactorCapacityError, MeshError
# Re-exported: the engines were first written for sweeps.
from contactfem.engines import (  # noqa: F401
    CONNECT_TIMEOUT,
    INSTALL_HINT,
    RETRIES,
    SINGLE_THREADED,
    DaskEngine,
    DaskMissing,
    SerialEngine,
    dask_setup,
    local_cluster_size,
    open_engine,
    worker_budget,
    worker_memory_limit,
)
from contactfem.report import build_report
from contactfem.solve import solve_case
# Re-exported: the plan and the table are part of this module's interface.
from contactfem.sweep_plan import (  # noqa: F401
    MAX_SWEEP_PLAN_BYTES,
    MAX_SWEEP_POINTS,
    SWEEP_KEYS,
    Sweep,
    SweepPoint,
    load_sweep,
)
from contactfem.sweep_table import (  # noqa: F401
    ERROR_NORMS,
    STAGES,
    _rank,
    _row,
    failed_rows,
    pareto_series,
    table_csv,
)
from contactfem.timings import clock

SCHEMA_VERSION = 1
#: The version of one stored point's JSON (points/<sha256>.json).
POINT_SCHEMA_VERSION = 2
SWEEP_JSON = "sweep.json"
SWEEP_CSV = "sweep.csv"
SWEEP_PNG = "sweep.png"
SWEEP_FILES = (SWEEP_JSON, SWEEP_CSV, SWEEP_PNG)
#: The output directory's folder of finished points, one JSON file each.
POINTS_DIR = "points"
#: ok: solved and certified; not_certified: solved, the certificate failed; invalid: the point's
#: case or mesh is refused; failed: the solver failed (no convergence, cycling); error: the
#: point could not be run (its worker died, memory ran out, an unexpected exception).
STATUSES = ("ok", "not_certified", "invalid", "failed", "error")
#: What a later run reuses: a deterministic outcome. An ``error`` is tried again.
STORED_STATUSES = ("ok", "not_certified", "invalid", "failed")


# --------------------------------------------------------------------------- one point


def solve_point(task: Mapping[str, Any]) -> dict:
    """Solve one point (``task``: its case ``text``, ``source`` and ``digest``) and return its record.

    Runs wherever the engine sends it (a Dask worker or this process) and never raises for a
    refused case or a failed solve: those are records with a status and a one-line message.
    """
    started = clock()
    record = {"schema_version": POINT_SCHEMA_VERSION, "contactfem_version": __version__,
              "digest": task["digest"], "case_text": task["text"]}
    with warnings.catch_warnings():
        # Overflow and 0/0 end in the finiteness checks below or in a refusal naming the key.
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            case = parse_case(task["text"], source=task["source"])
            if case.digest != task["digest"]:
                # Stored under the planned digest, this result would stand for data it was
                # not solved from: not stored ("error"), the next run plans it anew.
                files = ", ".join(path.name for path in case.data_files)
                record.update(failure("error", f"{Path(task['source']).name}: a data file it reads ({files}) "
                                               "changed since the sweep was planned; run the sweep again"))
            else:
                with worker_budget():
                    result = solve_case(case, accept_uncertified=True)
                report = build_report(case, result)
                record.update(_figures(case, result, report))
        except (CaseError, MeshError) as error:
            record.update(failure("invalid", str(error)))
        except FactorCapacityError as error:
            record.update(failure("error", f"{Path(task['source']).name}: {error}"))
        except ContactFemError as error:
            record.update(failure("failed", str(error)))
        except MemoryError:
            record.update(failure("error", f"{Path(task['source']).name}: out of memory while solving this "
                                           "point; give each worker more memory or use a coarser mesh"))
    record["seconds"] = {**record.get("seconds", {}), "total": clock() - started}
    return _finite(record)


def _finite(value: Any) -> Any:
    """``value`` with every non-finite float as None: records and tables are strict JSON."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def failure(status: str, message: str) -> dict:
    """The figures of a point that has none: its status and message."""
    return {"status": status, "message": " ".join(message.split()), "method": None, "backend": None,
            "unknowns": None, "contact_nodes": None, "iterations": None, "seconds": {}, "contact_force": None,
            "contact_zone": None, "certificate": None, "errors": None, "energy_norm": None, "accuracy": None,
            "warnings": []}


def _figures(case, result, report: dict) -> dict:
    solution = result.solution
    displacement = solution.displacement.ravel()
    force = report["contact_force"]["normal"]
    if not (np.isfinite(displacement).all() and np.isfinite(solution.contact.multiplier).all()
            and math.isfinite(force)):
        return failure("failed", f"{case.source.name}: the solution is not finite: the data's scales overflow "
                                 "float64; rescale the units of lengths, moduli and loads")
    certificate = report["solver"].get("certificate")
    zone = report["contact_zone"]
    energy = float(np.sqrt(max(displacement @ (result.problem.stiffness @ displacement), 0.0)))
    return {
        "status": "ok" if report["solver"]["status"] == "converged" else "not_certified",
        "message": None if report["solver"]["status"] == "converged" else " ".join(
            f"{case.source.name}: method {result.method}: not certified, {report['solver']['message']}".split()),
        "method": result.method,
        "backend": result.backend,
        "unknowns": report["unknowns"]["displacement"],
        "contact_nodes": zone["contact_nodes"],
        "iterations": report["solver"]["iterations"],
        "seconds": {stage: float(report["timings"][stage]) for stage in STAGES if stage in report["timings"]},
        "contact_force": float(force),
        "contact_zone": {"active_nodes": zone["active_nodes"],
                         "intervals": [list(interval["abscissa"]) for interval in zone["intervals"]]},
        "certificate": None if certificate is None else ("passed" if certificate["passed"] else "failed"),
        "errors": report["errors"],
        "energy_norm": energy if math.isfinite(energy) else None,
        "accuracy": accuracy_record(report.get("accuracy")),
        "warnings": list(report.get("warnings", [])),
    }


def accuracy_record(accuracy: dict | None) -> dict | None:
    """A point's estimated errors, as report.json's ``accuracy`` gives them (none a bound): the
    energy norm's (η) and each contact quantity's, absolute, None where there is none."""
    if not accuracy:
        return None
    energy = accuracy["energy"]
    return {"energy": energy.get("estimate"), "energy_relative": energy.get("relative"),
            **{name: entry.get("estimate") for name, entry in accuracy["quantities"].items()}}


def point_json(record: dict) -> str:
    """A point's record as stored (points/<sha256>.json)."""
    return json.dumps(record, indent=1, sort_keys=True, allow_nan=False) + "\n"


def point_file(digest: str) -> str:
    return f"{digest}.json"


def storable(record: dict) -> bool:
    return record.get("status") in STORED_STATUSES


def finished_points(points_dir: Path, sweep: Sweep, read: Callable[[Path], dict]) -> dict[str, dict]:
    """The stored records of this sweep's points in ``points_dir`` (by digest), each read as
    untrusted input by ``read`` (the command line's is
    :func:`contactfem.io.readback.read_point_record`, which raises ArchiveError for a file it
    refuses). A file that is unreadable, too large, damaged, of another schema or of another
    case text is ignored: its point is solved again and the file replaced."""
    found: dict[str, dict] = {}
    for point in sweep.points:
        if point.digest is None or point.problem is not None or point.digest in found:
            continue
        path = Path(points_dir) / point_file(point.digest)
        if not os.path.lexists(path):
            continue
        try:
            record = read(path)
        except ArchiveError:
            continue
        if record["case_text"] == point.text and storable(record):
            found[point.digest] = record
    return found


def _lost(task: dict, reason: str) -> dict:
    """The record of a point whose task raised, or whose every worker died: tried again by the next run."""
    return {"schema_version": POINT_SCHEMA_VERSION, "contactfem_version": __version__, "digest": task["digest"],
            "case_text": task["text"], **failure("error", f"{Path(task['source']).name}: {reason}")}


# --------------------------------------------------------------------------- the sweep's run


def run_sweep(
    sweep: Sweep,
    engine: SerialEngine | DaskEngine,
    *,
    finished: Mapping[str, dict] | None = None,
    store: Callable[[dict], None] | None = None,
    progress: Callable[[dict, int, int], None] | None = None,
) -> dict:
    """Solve the points not in ``finished`` on ``engine`` and return the table (sweep.json's content).

    ``store(record)`` receives each newly solved point's record as soon as it arrives (a
    storable one: see :data:`STORED_STATUSES`); ``progress(row, done, total)`` each
    finished row of the table, reused and invalid points first.
    """
    started = clock()
    finished = dict(finished or {})
    records: dict[str, dict] = {}
    rows_of: dict[str, list[SweepPoint]] = {}
    for point in sweep.points:
        if point.problem is None:
            rows_of.setdefault(point.digest, []).append(point)
    total = len(sweep.points)
    done = 0
    rows: dict[int, dict] = {}

    def finish(point: SweepPoint, record: dict, reused: bool) -> None:
        nonlocal done
        done += 1
        rows[point.index] = _row(point, record, reused)
        if progress is not None:
            progress(rows[point.index], done, total)

    for point in sweep.points:
        if point.problem is not None:
            finish(point, {"digest": point.digest, **failure("invalid", point.problem)}, reused=False)
        elif point.digest in finished:
            finish(point, finished[point.digest], reused=True)
    tasks = sweep.pending(finished)
    for task, record in engine.map(solve_point, tasks, lost=_lost, name="point"):
        records[task["digest"]] = record
        if store is not None and storable(record):
            store(record)
        for point in rows_of[task["digest"]]:
            finish(point, record, reused=False)
    table_rows = [rows[index] for index in sorted(rows)]
    _rank(table_rows, sweep.keys)
    counts = {status: sum(row["status"] == status for row in table_rows) for status in STATUSES}
    return {
        "schema_version": SCHEMA_VERSION,
        "contactfem_version": __version__,
        "sweep": {"file": str(sweep.source), "title": sweep.title, "sha256": sweep.digest, "kind": sweep.kind},
        "case": {"file": str(sweep.base), "title": sweep.base_title, "sha256": sweep.base_digest},
        "units": dict(sweep.units),
        "keys": list(sweep.keys),
        "error_measure": {
            "exact": "energy norm of u - u_h against the case's exact solution (report.json errors."
                     "displacement_energy)",
            "finest": "|energy norm of u_h - energy norm of u_ref|, u_ref the point with the most unknowns of "
                      "the same group (every swept value outside mesh.* equal); a lower bound of the energy "
                      "norm of u_h - u_ref",
            "estimated": "the residual estimator's eta (report.json accuracy.energy.estimate), an estimate of "
                         "the energy norm of u - u_h reliable up to an unknown constant, not a bound",
        },
        "engine": {"kind": engine.kind, "scheduler": engine.scheduler, "workers": engine.workers,
                   "startup_seconds": engine.startup_seconds},
        "counts": {"points": total, "solved": len(records), "reused": sum(row["reused"] for row in table_rows),
                   **counts},
        "wall_seconds": clock() - started,
        "points": table_rows,
    }
