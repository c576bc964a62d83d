"""The output formats of a solve, by name: which files each writes and the function that writes them.

A case's ``output.files`` names formats from :data:`FORMATS`; the command line writes a
result through :func:`write_result`, which runs the writers in a fixed order and the
report last, so that its timings include the others. File names are defined here and
by the writer modules, and gathered here. Writers import their libraries (h5py, VTK) only
when called, so that reading the names costs nothing.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from contactfem.io.atomic import atomic_write_text
from contactfem.io.hdf5 import SOLUTION_H5, write_hdf5
from contactfem.io.path import PATH_CSV, PATH_H5, PATH_PVD, PATH_STEP_FILES, PathWriter
from contactfem.io.table import csv_table
from contactfem.io.vtu import COLLECTION_PVD, CONTACT_VTU, PIECE_VTU_PATTERN, SOLUTION_PVTU, SOLUTION_VTU, write_vtu
from contactfem.io.xdmf import COMPANION_H5, XDMF_FILE, write_xdmf
from contactfem.result import Solution
from contactfem.timings import clock

#: The report, a solve's only JSON file.
REPORT_JSON = "report.json"
#: The contact fields along ΓC as a table (position along the obstacle, x, y, pressure, ...).
CONTACT_CSV = "contact.csv"
#: The pictures of a result directory (``contactfem plot``, ``solve --plot``).
DEFORMED_PNG = "deformed.png"
PROFILE_PNG = "contact_profile.png"
PICTURES = (DEFORMED_PNG, PROFILE_PNG)
#: The curves of a load path against its load factor (written with the path's files).
PATH_PNG = "path.png"
#: The study commands' own files.
COMPARE_JSON = "compare.json"
COMPARE_PNG = "compare.png"
CONVERGENCE_JSON = "convergence.json"
CONVERGENCE_CSV = "convergence.csv"
CONVERGENCE_PNGS = ("convergence_h.png", "convergence_time.png")
ADAPT_JSON = "adapt.json"
#: The final mesh of `adapt` coloured by the error indicator η_T, and η step by step.
ADAPT_PNG = "adapt.png"
SWEEP_JSON = "sweep.json"
#: The JSON the commands print on stdout that is no file's copy: check's and plot's --json.
CHECK_OUTPUT = "check --json"
PLOT_OUTPUT = "plot --json"
#: The version of each of them (their "schema_version").
CHECK_SCHEMA_VERSION = 1
PLOT_SCHEMA_VERSION = 1
#: The JSON Schema of each JSON file the commands write, and of the JSON they print that is no
#: file's copy, shipped in contactfem/schemas/.
JSON_SCHEMAS = {REPORT_JSON: "report.schema.json", COMPARE_JSON: "compare.schema.json",
                CONVERGENCE_JSON: "convergence.schema.json", ADAPT_JSON: "adapt.schema.json",
                SWEEP_JSON: "sweep.schema.json", CHECK_OUTPUT: "check.schema.json",
                PLOT_OUTPUT: "plot.schema.json"}


def shown_text(text: str) -> str:
    """``text`` with every lone surrogate spelled out, so that it can be printed and written as
    UTF-8 (a message, JSON, an HDF5 or VTU attribute): a byte of a file name that is not UTF-8,
    which Python reads as a surrogate U+DC80..U+DCFF, as ``\\xNN`` (the byte), any other as
    ``\\udNNN``. Text without one is returned as it is."""
    if text.isascii():
        return text
    try:
        text.encode("utf-8")
        return text
    except UnicodeEncodeError:
        pass
    return "".join(f"\\x{ord(c) - 0xDC00:02x}" if 0xDC80 <= ord(c) <= 0xDCFF
                   else f"\\u{ord(c):04x}" if 0xD800 <= ord(c) <= 0xDFFF else c for c in text)


def shown_path(path: str | bytes | os.PathLike) -> str:
    """A path as messages, summaries and files show it: :func:`shown_text` of its name, the
    bytes that are not UTF-8 as ``\\xNN``."""
    return shown_text(os.fsdecode(path))


def schema_path(file_name: str) -> Path:
    """The JSON Schema (a file inside the installed package) of ``file_name``, e.g. ``report.json``,
    or of a command's printed JSON, ``check --json`` or ``plot --json``."""
    return Path(__file__).resolve().parents[1] / "schemas" / JSON_SCHEMAS[file_name]


@dataclass(frozen=True, eq=False)
class PathData:
    """A load path for its writer: the :class:`~contactfem.io.path.PathWriter` that wrote its
    steps as they were solved, and the curves (report.json's ``load_path.curves``)."""

    writer: PathWriter
    curves: dict[str, list[float]]


@dataclass(frozen=True, eq=False)
class ResultData:
    """What the writers of one result are given.

    ``attributes`` are the metadata every file that can carry them stores (package
    version, case title and hash, method, plane, backend, units); ``case_text`` the case
    file as read; ``exact_pressure`` (m,) the exact contact pressure at the contact nodes
    when the case has an exact solution (None otherwise).
    """

    solution: Solution
    report: dict
    case_text: str
    attributes: dict[str, str] = field(default_factory=dict)
    exact_pressure: np.ndarray | None = None
    path: PathData | None = None


@dataclass(frozen=True)
class OutputFormat:
    """A named output: the files it writes, what it needs written beside it, and its writer."""

    name: str
    files: tuple[str, ...]
    write: Callable[[ResultData, Path], list[Path]]
    needs: tuple[str, ...] = ()
    description: str = ""


def result_data(case, result, report: dict, path: PathData | None = None) -> ResultData:
    """The writers' input for ``result`` of ``case`` (a :class:`contactfem.solve.SolveResult`)
    with its ``report``: the metadata every file that can carry it stores, and the exact
    contact pressure at the contact nodes when the problem has an exact solution; ``path``
    the steps of a load path that ended in ``result``."""
    from contactfem import __version__

    units = case.units
    attributes = {"contactfem_version": __version__, "title": case.title, "case_file": shown_path(case.source),
                  "case_hash": case.digest, "method": result.method, "plane": case.material.plane,
                  "backend": result.backend, "length_unit": units.length, "force_unit": units.force,
                  "stress_unit": units.stress}
    exact_pressure = None
    exact = result.problem.exact
    if exact is not None:
        where = result.solution.mesh.points[result.solution.contact.nodes]
        with np.errstate(all="ignore"):  # a singular point (a crack tip) gives NaN, stored as such
            exact_pressure = np.asarray(exact.pressure(where[:, 0], where[:, 1]), dtype=float).reshape(-1)
    return ResultData(solution=result.solution, report=report, case_text=case.text, attributes=attributes,
                      exact_pressure=exact_pressure, path=path)


def to_json(data: dict) -> str:
    """Deterministic JSON: sorted keys, two-space indents, no NaN (a report with NaN is a bug),
    text as :func:`shown_text` (a path with bytes that are not UTF-8 would otherwise become a
    lone surrogate, which strict JSON readers refuse)."""
    return json.dumps(shown_data(data), indent=2, sort_keys=True, allow_nan=False) + "\n"


def shown_data(value):
    """JSON-ready ``value`` with every text (keys too) as :func:`shown_text`."""
    if isinstance(value, str):
        return shown_text(value)
    if isinstance(value, dict):
        return {shown_text(k) if isinstance(k, str) else k: shown_data(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [shown_data(v) for v in value]
    return value


def _write_vtu(data: ResultData, directory: Path) -> list[Path]:
    return write_vtu(data.solution, directory, metadata=data.attributes)


def _write_h5(data: ResultData, directory: Path) -> list[Path]:
    attributes = {k: v for k, v in data.attributes.items() if k not in ("method", "case_hash")}
    return [write_hdf5(data.solution, directory / SOLUTION_H5, case_text=data.case_text,
                       case_hash=data.attributes.get("case_hash", ""), attributes=attributes,
                       exact_pressure=data.exact_pressure)]


def _write_xdmf(data: ResultData, directory: Path) -> list[Path]:
    return write_xdmf(data.solution, directory)


def contact_table(solution: Solution) -> str:
    """contact.csv: one row per contact node along ΓC, sorted by its position along the obstacle."""
    contact = solution.contact
    points = solution.mesh.points[contact.nodes]
    columns = {
        "abscissa": contact.abscissa, "x": points[:, 0], "y": points[:, 1],
        "pressure": contact.multiplier, "nodal_force": contact.nodal_force, "gap": contact.gap,
        "normal_displacement": contact.normal_displacement, "active": contact.active.astype(int),
    }
    if contact.normals is not None:  # a curved obstacle: each node's closest point and normal there
        q, n = np.reshape(contact.obstacle_points, (-1, 2)), np.reshape(contact.normals, (-1, 2))
        columns.update({"obstacle_x": q[:, 0], "obstacle_y": q[:, 1], "normal_x": n[:, 0], "normal_y": n[:, 1]})
    return csv_table(columns)


def _write_csv(data: ResultData, directory: Path) -> list[Path]:
    return [atomic_write_text(directory / CONTACT_CSV, contact_table(data.solution))]


def _write_path(data: ResultData, directory: Path) -> list[Path]:
    # The steps are written as they are solved, into the same staging directory.
    if data.path is None:
        return []
    if data.path.writer.directory != Path(directory):
        raise ValueError("a load path's files are finished where its steps were written")
    return data.path.writer.finish(data.path.curves, data.attributes)


def _write_json(data: ResultData, directory: Path) -> list[Path]:
    return [atomic_write_text(directory / REPORT_JSON, to_json(data.report))]


#: Every format, in the order written (the report last).
FORMATS: dict[str, OutputFormat] = {
    format.name: format for format in (
        OutputFormat("vtu", (SOLUTION_VTU, CONTACT_VTU, COLLECTION_PVD), _write_vtu,
                     description="ParaView: the body with its fields, ΓC with the contact fields, and a PVD of both"),
        OutputFormat("h5", (SOLUTION_H5,), _write_h5,
                     description="the whole result and the case text in one HDF5 archive (read by plot)"),
        OutputFormat("xdmf", (XDMF_FILE,), _write_xdmf, needs=("h5",),
                     description="an XDMF view of solution.h5 for ParaView and VisIt"),
        OutputFormat("csv", (CONTACT_CSV,), _write_csv,
                     description="the contact fields along ΓC: position along the obstacle, x, y, pressure, "
                                 "nodal force, gap, normal displacement, active"),
        OutputFormat("path", (PATH_PVD, PATH_STEP_FILES, PATH_H5, PATH_CSV), _write_path,
                     description="a load path's steps: a PVD series with the load factor as time, every step in "
                                 "path.h5, and the curves against the factor in path.csv (written when the case "
                                 "has a load_path)"),
        OutputFormat("json", (REPORT_JSON,), _write_json, description="the report"),
    )
}
FORMAT_NAMES = tuple(FORMATS)
#: Written unless the case lists its own; xdmf is an extra a case asks for.
DEFAULT_FORMATS = ("vtu", "h5", "csv", "json")
#: Every file a solve can leave in its directory (formats and pictures; a distributed mesh's
#: pieces and their index, :mod:`contactfem.io.pieces`), and the XDMF companion earlier versions
#: wrote, so that replacing such a result removes it.
RESULT_FILES = (tuple(name for format in FORMATS.values() for name in format.files) + PICTURES
                + (PATH_PNG, COMPANION_H5, SOLUTION_PVTU, PIECE_VTU_PATTERN))
#: Files whose presence marks a directory as holding a finished result.
RESULT_MARKERS = (REPORT_JSON, SOLUTION_H5)


def write_result(data: ResultData, directory: Path, formats: tuple[str, ...],
                 progress: Callable[[str], None] | None = None) -> tuple[list[Path], dict]:
    """Write ``formats`` of one result into ``directory`` (each file atomically), the report last.

    Returns the files written and the report as written, whose timings gain ``write``
    (the seconds of the other writers).
    """
    say = progress or (lambda message: None)
    started = clock()
    written: list[Path] = []
    for name, format in FORMATS.items():
        if name in formats and name != "json":
            say(f"writing {name.upper()}")
            written += format.write(data, Path(directory))
    report = {**data.report, "timings": {**data.report.get("timings", {}), "write": clock() - started}}
    if "json" in formats:
        written += FORMATS["json"].write(ResultData(data.solution, report, data.case_text, data.attributes),
                                         Path(directory))
    return written, report
