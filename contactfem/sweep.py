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
Dask cluster (an optional dependency, imported only by :func:`open_engine`). Nothing here
writes or prints: :func:`run_sweep` hands every finished point to the caller's callbacks
(the command line stores it at once and prints a line) and returns the table.

The error of a point is the energy norm of u − u_h when the case has an exact solution
(report.json's ``errors.displacement_energy``); without one it is |‖u_h‖_a − ‖u_ref‖_a|,
u_ref the point with the most unknowns among those that share every swept value outside
``mesh.*`` (its group): a lower bound of the energy norm of u_h − u_ref that needs no
interpolation between meshes. The Pareto front (no other point of the group is both faster
and more accurate) is marked per group.
"""

from __future__ import annotations

import copy
import csv
import hashlib
import io
import itertools
import json
import math
import os
import re
import signal
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from contactfem import __version__
from contactfem.case import (
    MAX_CASE_BYTES,
    OUTPUT_NAME_RESERVE,
    OUTPUT_PATH_RESERVE,
    parse_case,
    path_problem,
    read_text_file,
    shortened,
)
from contactfem.case.reader import Reader
from contactfem.case.yaml_loader import load_yaml
from contactfem.errors import CaseError, ContactFemError, FactorCapacityError, MeshError, SolverError
from contactfem.estimate import MemoryLimit, memory_budget
from contactfem.report import build_report
from contactfem.solve import solve_case

SCHEMA_VERSION = 1
#: The version of one stored point's JSON (points/<sha256>.json).
POINT_SCHEMA_VERSION = 1
SWEEP_JSON = "sweep.json"
SWEEP_CSV = "sweep.csv"
SWEEP_PNG = "sweep.png"
SWEEP_FILES = (SWEEP_JSON, SWEEP_CSV, SWEEP_PNG)
#: The output directory's folder of finished points, one JSON file each.
POINTS_DIR = "points"
#: The most points a sweep may have (the product of a grid's list lengths).
MAX_SWEEP_POINTS = 10_000
SWEEP_KEYS = ("title", "description", "case", "grid", "points", "output")
#: The report's timings, in order; ``total`` (the point's wall time in its worker) follows.
STAGES = ("mesh", "assemble", "solve", "postprocess", "report")
ERROR_NORMS = ("displacement_l2", "displacement_h1_semi", "displacement_h1", "displacement_energy",
               "multiplier_l2", "multiplier_h_minus_half")
#: ok: solved and certified; not_certified: solved, the certificate failed; invalid: the point's
#: case or mesh is refused; failed: the solver failed (no convergence, cycling); error: the
#: point could not be run (its worker died, memory ran out, an unexpected exception).
STATUSES = ("ok", "not_certified", "invalid", "failed", "error")
#: What a later run reuses: a deterministic outcome. An ``error`` is tried again.
STORED_STATUSES = ("ok", "not_certified", "invalid", "failed")
#: Dask re-runs a point whose task raised this many times (a worker that dies is handled by
#: the scheduler itself: it reschedules the point on another worker, up to
#: ``distributed.scheduler.allowed-failures`` deaths).
RETRIES = 2
#: Solves run one per worker process: BLAS and OpenMP threads would only compete.
SINGLE_THREADED = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                   "VECLIB_MAXIMUM_THREADS": "1", "NUMEXPR_NUM_THREADS": "1"}
INSTALL_HINT = "pip install -e '.[dask]'"
#: How long to wait for an existing scheduler to answer.
CONNECT_TIMEOUT = "10s"

_NAME = r"[^.\[\]\s][^.\[\]]*"
_KEY = re.compile(rf"{_NAME}(\[\d+\])*(\.{_NAME}(\[\d+\])*)*")
_STEP = re.compile(rf"({_NAME})|\[(\d+)\]")


# --------------------------------------------------------------------------- the sweep


@dataclass(frozen=True)
class SweepPoint:
    """One point: ``values`` by dotted key, its case ``text`` (None when the values could not
    be set) and its ``digest``, the case's (the text and the data files it reads), or the
    text's SHA-256 when it is refused; ``problem`` is its one-line refusal, if any."""

    index: int  # 1-based, in the order of the grid or the list
    values: dict[str, Any]
    label: str
    source: str  # what parse_case is given: names the point in messages
    text: str | None
    digest: str | None
    problem: str | None = None


@dataclass(frozen=True)
class Sweep:
    source: Path
    digest: str
    title: str
    base: Path
    base_title: str
    base_digest: str
    kind: str  # "grid" | "points"
    keys: tuple[str, ...]
    points: tuple[SweepPoint, ...]
    directory: Path

    def pending(self, finished: Mapping[str, dict]) -> list[dict]:
        """The tasks still to solve: one per distinct case text that is valid and not finished."""
        tasks: dict[str, dict] = {}
        for point in self.points:
            if point.problem is None and point.digest not in finished and point.digest not in tasks:
                tasks[point.digest] = {"index": point.index, "label": point.label, "source": point.source,
                                       "text": point.text, "digest": point.digest}
        return list(tasks.values())


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file and its base case, and build every point's case text.

    A point whose values make an invalid case is kept, with its refusal as ``problem``.

    Raises
    ------
    CaseError
        If the sweep file or the base case cannot be read or is malformed.
    """
    path = Path(path)
    text = read_text_file(path, what="sweep")
    r = Reader(shortened(path.name))
    data = load_yaml(text, r.filename)
    if data is None:
        raise CaseError(f"{r.filename}: the sweep file is empty (or only comments); expected a mapping with "
                        "case and grid or points")
    top = r.mapping(data, "", SWEEP_KEYS, required=("case",))
    for key in ("title", "description"):
        if key in top and not isinstance(top[key], str):
            raise r.fail(key, top[key], "expected a string")
    title = top.get("title", path.stem)
    if len(title) > 200 or not title.isprintable():
        raise r.fail("title", title, "expected one line of at most 200 printable characters")

    reference = top["case"]
    if not isinstance(reference, str) or not reference.strip():
        raise r.fail("case", reference, "expected the path of the base case file, relative to the sweep file")
    if path_problem(reference) is not None:
        raise r.fail("case", reference, f"the path {path_problem(reference)}")
    base = path.parent / reference
    try:
        base_text = read_text_file(base)
        base_case = parse_case(base_text, source=base)
    except CaseError as error:
        raise CaseError(f"{r.filename}: case: {error}") from None
    base_data = load_yaml(base_text, shortened(base.name))

    if ("grid" in top) == ("points" in top):
        raise CaseError(f"{r.filename}: grid, points: {'both are' if 'grid' in top else 'neither is'} given; "
                        "expected exactly one: grid (a cartesian product) or points (a list)")
    kind = "grid" if "grid" in top else "points"
    assignments = _grid(r, top["grid"]) if kind == "grid" else _point_list(r, top["points"])
    keys = tuple(dict.fromkeys(key for values in assignments for key in values))

    output = r.mapping(top.get("output") or {}, "output", ("directory",))
    directory = output.get("directory", f"results/{path.stem}")
    if not isinstance(directory, str) or not directory.strip():
        raise r.fail("output.directory", directory, "expected a directory path")
    problem = path_problem(directory, name_reserve=OUTPUT_NAME_RESERVE, path_reserve=OUTPUT_PATH_RESERVE)
    if problem is not None:
        raise r.fail("output.directory", directory, f"the path {problem}")

    name = shortened(path.name, 80)
    points = tuple(_point(base, base_data, values, index, f"{name} point {index}")
                   for index, values in enumerate(assignments, start=1))
    if all(point.problem is not None for point in points):
        # A mistyped key or a value outside the format refuses every point: the sweep file is wrong.
        raise CaseError(f"{r.filename}: {kind}: every point is refused, so nothing would be solved; "
                        f"{'the point' if len(points) == 1 else 'point 1'}: {points[0].problem}")
    return Sweep(source=path, digest=hashlib.sha256(text.encode("utf-8")).hexdigest(), title=title, base=base,
                 base_title=base_case.title, base_digest=base_case.digest, kind=kind, keys=keys, points=points,
                 directory=Path(directory))


def _grid(r: Reader, grid: Any) -> list[dict[str, Any]]:
    expected = "expected a mapping of dotted case keys (e.g. mesh.divisions) to non-empty lists of values"
    if not isinstance(grid, dict) or not grid:
        raise r.fail("grid", grid, expected)
    columns = []
    for key, values in grid.items():
        _check_key(r, key, "grid")
        where = f"grid.{key}"
        if not isinstance(values, list) or not values:
            raise r.fail(where, values, "expected a non-empty list of values")
        for i, value in enumerate(values):
            _check_value(r, value, f"{where}[{i}]")
        columns.append([(key, value) for value in values])
    count = math.prod(len(c) for c in columns)
    if count > MAX_SWEEP_POINTS:
        raise r.fail("grid", f"{' x '.join(str(len(c)) for c in columns)} = {count} points",
                     f"expected at most {MAX_SWEEP_POINTS} points")
    return [dict(combination) for combination in itertools.product(*columns)]


def _point_list(r: Reader, points: Any) -> list[dict[str, Any]]:
    if not isinstance(points, list) or not points:
        raise r.fail("points", points, "expected a non-empty list of mappings of dotted case keys to values")
    if len(points) > MAX_SWEEP_POINTS:
        raise r.fail("points", f"{len(points)} points", f"expected at most {MAX_SWEEP_POINTS}")
    for i, point in enumerate(points):
        where = f"points[{i}]"
        if not isinstance(point, dict) or not point:
            raise r.fail(where, point, "expected a non-empty mapping of dotted case keys to values")
        for key, value in point.items():
            _check_key(r, key, where)
            _check_value(r, value, f"{where}.{key}")
    return [dict(point) for point in points]


def _check_key(r: Reader, key: Any, where: str) -> None:
    if not isinstance(key, str) or len(key) > 200 or not key.isprintable() or not _KEY.fullmatch(key):
        shown = shortened(key if isinstance(key, str) else repr(key), 64)
        raise CaseError(f"{r.filename}: {where}.{shown}: expected a dotted case key such as mesh.divisions "
                        "or boundary.top.traction[1]")


def _check_value(r: Reader, value: Any, where: str) -> None:
    """Values are what a case file holds and JSON can carry: numbers, strings, booleans, null,
    lists and mappings of them."""
    if isinstance(value, float) and not math.isfinite(value):
        raise r.fail(where, value, "expected a finite number")
    if isinstance(value, list):
        for i, item in enumerate(value):
            _check_value(r, item, f"{where}[{i}]")
    elif isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise r.fail(where, value, "expected a mapping with string keys")
            _check_value(r, item, f"{where}.{key}")
    elif value is not None and not isinstance(value, (bool, int, float, str)):
        raise r.fail(where, str(value), "expected a number, a string, a boolean, null, a list or a mapping")


def _point(base: Path, base_data: dict, values: dict[str, Any], index: int, name: str) -> SweepPoint:
    label = ", ".join(f"{key}={_shown_value(value)}" for key, value in values.items())
    source = str(base.parent / name)
    data = _unshared(base_data)
    try:
        for key, value in values.items():
            _assign(data, key, _unshared(value))
    except _Unassignable as problem:
        return SweepPoint(index, values, label, source, None, None, f"{name}: {problem}")
    # The text must say which files it reads wherever it is solved (a worker elsewhere).
    _absolute_data_paths(data.get("geometry"), base.parent)
    text = yaml.safe_dump(data, sort_keys=False, allow_unicode=True, default_flow_style=None, width=100)
    try:
        case = parse_case(text, source=source)
    except CaseError as error:
        return SweepPoint(index, values, label, source, text, hashlib.sha256(text.encode("utf-8")).hexdigest(),
                          str(error))
    # The case's own digest covers the data files it reads (a profile, an outline, a mesh):
    # a point whose surface file changed is another point, never a stored one reused.
    return SweepPoint(index, values, label, source, text, case.digest)


def _absolute_data_paths(geometry: Any, directory: Path) -> None:
    """Make the data files a geometry names (mesh_file, a profile's or a polygon's or a
    hole's file) absolute against ``directory``, in place; values of other types are left
    to the case's validation."""
    if not isinstance(geometry, dict):
        return

    def absolute(holder: Any, key: str) -> None:
        if isinstance(holder, dict) and isinstance(holder.get(key), str) and holder[key]:
            holder[key] = str((directory / holder[key]).resolve())

    absolute(geometry, "mesh_file")
    absolute(geometry.get("profile"), "file")
    polygon = geometry.get("polygon")
    absolute(polygon, "file")
    if isinstance(polygon, dict) and isinstance(polygon.get("holes"), list):
        for hole in polygon["holes"]:
            absolute(hole, "file")


class _Unassignable(Exception):
    pass


def _assign(data: dict, key: str, value: Any) -> None:
    """Set ``data`` at the dotted ``key``: missing (or scalar) mappings on the way are created,
    list elements must exist."""
    steps: list[str | int] = [int(number) if number else name for name, number in _STEP.findall(key)]
    node: Any = data
    walked = ""
    for step, following in zip(steps, steps[1:] + [None]):
        last = following is None
        if isinstance(step, int):
            if not isinstance(node, list) or step >= len(node):
                size = f"a list of {len(node)}" if isinstance(node, list) else f"{_shown_value(node)}, not a list"
                raise _Unassignable(f"{key}: {walked} is {size}; cannot set element [{step}]")
            walked += f"[{step}]"
            if last:
                node[step] = value
            else:
                node = node[step]
            continue
        if not isinstance(node, dict):
            raise _Unassignable(f"{key}: {walked} is {_shown_value(node)}, not a mapping; cannot set {step}")
        walked = f"{walked}.{step}" if walked else step
        if last:
            node[step] = value
        else:
            child = node.get(step)
            if not isinstance(child, (dict, list)):
                if isinstance(following, int):
                    raise _Unassignable(f"{key}: {walked} is {_shown_value(child)}, not a list; "
                                        f"cannot set element [{following}]")
                child = node[step] = {}
            node = child


def _unshared(value: Any) -> Any:
    """A copy in which no container is shared: a YAML alias stands for a copy, so that setting a
    value reached through one use of an anchor leaves the others as they were."""
    if isinstance(value, dict):
        return {k: _unshared(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_unshared(v) for v in value]
    return copy.copy(value)


def _shown_value(value: Any) -> str:
    if isinstance(value, str):
        text = value
    else:
        try:
            text = json.dumps(value, separators=(",", ":"), ensure_ascii=False)
        except (TypeError, ValueError):
            text = str(value)
    return shortened(text, 60)


# --------------------------------------------------------------------------- one point


def worker_memory_limit() -> MemoryLimit | None:
    """The memory limit of the Dask worker running this point (None: not in a worker, or it
    has none). Its nanny kills a worker past it, so the size guard refuses against it: a
    point too large for its worker is recorded as invalid at once instead of killing three
    workers in turn."""
    try:
        from distributed import get_worker

        limit = get_worker().memory_manager.memory_limit
    except (ImportError, ValueError, AttributeError):
        return None
    if not limit:
        return None
    return MemoryLimit(int(limit), f"this sweep worker's memory limit of {limit / 2**30:.3g} GiB")


def solve_point(task: Mapping[str, Any]) -> dict:
    """Solve one point (``task``: its case ``text``, ``source`` and ``digest``) and return its record.

    Runs wherever the engine sends it (a Dask worker or this process) and never raises for a
    refused case or a failed solve: those are records with a status and a one-line message.
    """
    clock = time.perf_counter()
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
                with memory_budget(limit) if (limit := worker_memory_limit()) is not None else nullcontext():
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
    record["seconds"] = {**record.get("seconds", {}), "total": time.perf_counter() - clock}
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
            "contact_zone": None, "certificate": None, "errors": None, "energy_norm": None, "warnings": []}


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
        "warnings": list(report.get("warnings", [])),
    }


def point_json(record: dict) -> str:
    """A point's record as stored (points/<sha256>.json)."""
    return json.dumps(record, indent=1, sort_keys=True, allow_nan=False) + "\n"


def point_file(digest: str) -> str:
    return f"{digest}.json"


def storable(record: dict) -> bool:
    return record.get("status") in STORED_STATUSES


def finished_points(points_dir: Path, sweep: Sweep) -> dict[str, dict]:
    """The stored records of this sweep's points in ``points_dir`` (by digest). A file that is
    unreadable, too large, of another schema or of another case text is ignored: its point is
    solved again and the file replaced."""
    found: dict[str, dict] = {}
    for point in sweep.points:
        if point.digest is None or point.problem is not None or point.digest in found:
            continue
        path = Path(points_dir) / point_file(point.digest)
        try:
            if not path.is_file() or path.stat().st_size > 2 * MAX_CASE_BYTES:
                continue
            record = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if (isinstance(record, dict) and record.get("schema_version") == POINT_SCHEMA_VERSION
                and record.get("case_text") == point.text and storable(record)):
            found[point.digest] = record
    return found


# --------------------------------------------------------------------------- engines


class DaskMissing(ImportError):
    """Dask (distributed) is not installed."""


class SerialEngine:
    """The points one after another in this process."""

    kind = "serial"
    scheduler = None
    workers = 1
    note: str | None = None
    startup_seconds = 0.0

    def map(self, function: Callable[[dict], dict], tasks: list[dict]) -> Iterator[tuple[dict, dict]]:
        for task in tasks:
            try:
                record = function(task)
            except Exception as error:  # noqa: BLE001 - as on a Dask worker: the point's message
                record = _lost(task, "error", f"{type(error).__name__}: {error}")
            yield task, record


class DaskEngine:
    """The points as Dask tasks on ``client``'s cluster, yielded as they finish."""

    kind = "dask"
    note: str | None = None

    def __init__(self, client, scheduler: str | None = None, retries: int = RETRIES,
                 startup_seconds: float = 0.0) -> None:
        self.client = client
        self.scheduler = scheduler
        self.retries = retries
        self.startup_seconds = startup_seconds

    @property
    def workers(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))

    def map(self, function: Callable[[dict], dict], tasks: list[dict]) -> Iterator[tuple[dict, dict]]:
        from distributed import KilledWorker, as_completed

        token = os.urandom(4).hex()
        futures = {self.client.submit(function, task, key=f"contactfem-point-{task['index']}-{token}",
                                      retries=self.retries, pure=False): task for task in tasks}
        try:
            for future in as_completed(list(futures), loop=self.client.loop):
                task = futures.pop(future)
                try:
                    record = future.result()
                except KilledWorker:
                    record = _lost(task, "error", "every worker that ran this point died (killed, or over its "
                                                  "memory limit); it is tried again when the sweep is rerun")
                except Exception as error:  # noqa: BLE001 - any task exception becomes the point's message
                    record = _lost(task, "error", f"{type(error).__name__}: {error}")
                future.release()
                yield task, record
        finally:
            if futures:  # interrupted: nothing left should keep running on the cluster
                self.client.cancel(list(futures))


def _lost(task: dict, status: str, reason: str) -> dict:
    return {"schema_version": POINT_SCHEMA_VERSION, "contactfem_version": __version__, "digest": task["digest"],
            "case_text": task["text"], **failure(status, f"{Path(task['source']).name}: {reason}")}


def dask_setup(worker) -> None:
    """Dask's preload hook, run in each worker of the local cluster as it starts (a restarted one
    too): Ctrl-C on a terminal reaches the whole process group, but stopping is the command's
    job (it cancels the points and closes the cluster); a worker that took it would print its
    own traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def local_cluster_size(workers: int | None, pending: int) -> tuple[int, int]:
    """Workers and bytes of memory each for a cluster on this machine: ``workers`` or one per
    core, at most one per point to solve, the machine's memory shared out among them."""
    from dask.system import CPU_COUNT
    from distributed.system import MEMORY_LIMIT

    count = max(1, min(workers if workers is not None else CPU_COUNT, pending))
    return count, int(MEMORY_LIMIT // count)


@contextmanager
def open_engine(scheduler: str | None = None, workers: int | None = None,
                pending: int = 1) -> Iterator[SerialEngine | DaskEngine]:
    """The engine a sweep runs on: a LocalCluster of ``workers`` processes by default (one thread
    each, single-threaded BLAS, a memory limit each), the cluster at ``scheduler`` if given,
    and this process if Dask is not installed (``engine.note`` then says how to install it).

    Raises
    ------
    CaseError
        ``scheduler`` is given but Dask is not installed or the scheduler does not answer.
    """
    try:
        import dask
        import distributed
    except ImportError:
        if scheduler is not None:
            raise CaseError(f"--scheduler {shortened(scheduler, 80)}: Dask is not installed; "
                            f"expected Dask for a cluster ({INSTALL_HINT})") from None
        engine = SerialEngine()
        engine.note = (f"Dask is not installed: the points run one after another in this process "
                       f"({INSTALL_HINT} runs them in parallel)")
        yield engine
        return
    import logging

    clock = time.perf_counter()
    if scheduler is not None:
        from distributed.comm.addressing import parse_address, parse_host_port

        try:
            scheme, location = parse_address(scheduler)
            if scheme in ("tcp", "tls", "ws", "wss"):
                parse_host_port(location)
        except (ValueError, TypeError) as error:
            raise CaseError(f"--scheduler {shortened(scheduler, 80)}: {' '.join(str(error).split())}; expected the "
                            "address of a running Dask scheduler, e.g. tcp://host:8786") from None
        try:
            client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError, ValueError, TypeError) as error:
            reason = " ".join(str(error).split()) or type(error).__name__
            raise CaseError(f"--scheduler {shortened(scheduler, 80)}: cannot connect ({shortened(reason, 160)}); "
                            "expected the address of a running Dask scheduler, e.g. tcp://host:8786") from None
        try:
            yield DaskEngine(client, scheduler=scheduler, startup_seconds=time.perf_counter() - clock)
        finally:
            client.close()
        return
    count, memory = local_cluster_size(workers, pending)
    environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **SINGLE_THREADED}
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
            cluster = distributed.LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                               memory_limit=memory, dashboard_address=None, env=SINGLE_THREADED,
                                               silence_logs=logging.ERROR, preload=[__name__])
    except (OSError, RuntimeError, TimeoutError) as error:
        reason = " ".join(str(error).split()) or type(error).__name__
        raise SolverError(f"cannot start a local Dask cluster of {count} worker(s) ({shortened(reason, 160)}); "
                          "a script that calls this must guard its entry point with if __name__ == '__main__'") from None
    try:
        client = distributed.Client(cluster, set_as_default=False)
        try:
            yield DaskEngine(client, startup_seconds=time.perf_counter() - clock)
        finally:
            client.close()
    finally:
        cluster.close()


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
    clock = time.perf_counter()
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
    for task, record in engine.map(solve_point, tasks):
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
        "keys": list(sweep.keys),
        "error_measure": {
            "exact": "energy norm of u - u_h against the case's exact solution (report.json errors."
                     "displacement_energy)",
            "finest": "|energy norm of u_h - energy norm of u_ref|, u_ref the point with the most unknowns of "
                      "the same group (every swept value outside mesh.* equal); a lower bound of the energy "
                      "norm of u_h - u_ref",
        },
        "engine": {"kind": engine.kind, "scheduler": engine.scheduler, "workers": engine.workers,
                   "startup_seconds": engine.startup_seconds},
        "counts": {"points": total, "solved": len(records), "reused": sum(row["reused"] for row in table_rows),
                   **counts},
        "wall_seconds": time.perf_counter() - clock,
        "points": table_rows,
    }


def _row(point: SweepPoint, record: dict, reused: bool) -> dict:
    figures = {key: record.get(key) for key in ("status", "message", "method", "backend", "unknowns",
                                                "contact_nodes", "iterations", "contact_force", "contact_zone",
                                                "certificate", "errors", "energy_norm")}
    return {"index": point.index, "values": point.values, "label": point.label, "digest": point.digest,
            "reused": reused, **figures, "seconds": dict(record.get("seconds") or {}),
            "warnings": list(record.get("warnings") or []),
            "group": "", "error_kind": None, "error": None, "error_reference": None, "pareto": False}


def _rank(rows: list[dict], keys: tuple[str, ...]) -> None:
    """Each row's group, error (see the module's docstring) and place on its group's Pareto front."""
    others = [key for key in keys if not key.startswith("mesh.")]
    groups: dict[str, list[dict]] = {}
    for row in rows:
        row["group"] = ", ".join(f"{key}={_shown_value(row['values'].get(key))}" for key in others
                                 if key in row["values"])
        groups.setdefault(row["group"], []).append(row)
    for members in groups.values():
        solved = [row for row in members if row["status"] == "ok"]
        reference = max((row for row in solved if row["energy_norm"] is not None and not row["errors"]),
                        key=lambda row: row["unknowns"], default=None)
        for row in solved:
            if row["errors"]:
                row["error_kind"] = "exact"
                row["error"] = row["errors"].get("displacement_energy")
            elif reference is not None and row["energy_norm"] is not None:
                row["error_kind"] = "finest"
                row["error_reference"] = reference["index"]
                if row is not reference:
                    row["error"] = abs(row["energy_norm"] - reference["energy_norm"])
        candidates = sorted((row for row in solved if row["error"] is not None and row["seconds"].get("total")),
                            key=lambda row: (row["seconds"]["total"], row["error"]))
        best = math.inf
        for row in candidates:
            if row["error"] < best:
                row["pareto"] = True
                best = row["error"]


def failed_rows(table: dict) -> list[dict]:
    return [row for row in table["points"] if row["status"] != "ok"]


# --------------------------------------------------------------------------- the CSV


def table_csv(table: dict) -> str:
    """sweep.csv: one row per point, the swept values as columns (lists and mappings as JSON)."""
    keys = table["keys"]
    header = ["index", "status", *keys, "unknowns", "iterations", *(f"seconds_{s}" for s in (*STAGES, "total")),
              "contact_force", "active_nodes", "contact_zone", "certificate", *ERROR_NORMS, "energy_norm",
              "error_kind", "error", "error_reference", "pareto", "reused", "digest", "message"]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for row in table["points"]:
        zone = row["contact_zone"]
        errors = row["errors"] or {}
        writer.writerow([
            row["index"], row["status"],
            *(_cell(row["values"].get(key)) if key in row["values"] else "" for key in keys),
            _cell(row["unknowns"]), _cell(row["iterations"]),
            *(_cell(row["seconds"].get(stage)) for stage in (*STAGES, "total")),
            _cell(row["contact_force"]), _cell(zone["active_nodes"] if zone else None),
            " ".join(f"[{a:.6g}, {b:.6g}]" for a, b in zone["intervals"]) if zone else "",
            _cell(row["certificate"]), *(_cell(errors.get(norm)) for norm in ERROR_NORMS),
            _cell(row["energy_norm"]), _cell(row["error_kind"]), _cell(row["error"]),
            _cell(row["error_reference"]), _cell(row["pareto"]), _cell(row["reused"]), _cell(row["digest"]),
            _cell(row["message"]),
        ])
    return buffer.getvalue()


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, dict)):
        return json.dumps(value, separators=(",", ":"), ensure_ascii=False)
    return str(value)


def pareto_series(table: dict) -> Iterable[tuple[str, list[dict], list[dict]]]:
    """Per group: its plottable rows (a positive error and a time) and its Pareto front, by time."""
    groups: dict[str, list[dict]] = {}
    for row in table["points"]:
        if row["error"] is not None and row["error"] > 0 and row["seconds"].get("total"):
            groups.setdefault(row["group"], []).append(row)
    for group, members in groups.items():
        members.sort(key=lambda row: row["seconds"]["total"])
        yield group, members, [row for row in members if row["pareto"]]
