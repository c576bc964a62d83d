"""The output formats of a solve, by name: which files each writes and the function that writes them.

A case's ``output.files`` names formats from :data:`FORMATS`; the command line writes a
result through :func:`write_result`, which runs the writers in a fixed order and the
report last, so that its timings include the others. File names are defined here and
by the writer modules, and gathered here. Writers import their libraries (h5py, VTK) only
when called, so that reading the names costs nothing.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from contactfem.io.atomic import atomic_write_text
from contactfem.io.hdf5 import SOLUTION_H5, write_hdf5
from contactfem.io.vtu import COLLECTION_PVD, CONTACT_VTU, SOLUTION_VTU, write_vtu
from contactfem.io.xdmf import COMPANION_H5, XDMF_FILE, write_xdmf
from contactfem.result import Solution

#: The report, a solve's only JSON file.
REPORT_JSON = "report.json"
#: The pictures of a result directory (``contactfem plot``, ``solve --plot``).
DEFORMED_PNG = "deformed.png"
PROFILE_PNG = "contact_profile.png"
PICTURES = (DEFORMED_PNG, PROFILE_PNG)
#: The study commands' own files.
COMPARE_JSON = "compare.json"
COMPARE_PNG = "compare.png"
CONVERGENCE_JSON = "convergence.json"
CONVERGENCE_CSV = "convergence.csv"
CONVERGENCE_PNGS = ("convergence_h.png", "convergence_time.png")
ADAPT_JSON = "adapt.json"


@dataclass(frozen=True, eq=False)
class ResultData:
    """What the writers of one result are given.

    ``attributes`` are the metadata every file that can carry them stores (package
    version, case title and hash, method, plane, backend); ``case_text`` the case file
    as read.
    """

    solution: Solution
    report: dict
    case_text: str
    attributes: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class OutputFormat:
    """A named output: the files it writes, what it needs written beside it, and its writer."""

    name: str
    files: tuple[str, ...]
    write: Callable[[ResultData, Path], list[Path]]
    needs: tuple[str, ...] = ()
    description: str = ""


def result_data(case, result, report: dict) -> ResultData:
    """The writers' input for ``result`` of ``case`` (a :class:`contactfem.solve.SolveResult`)
    with its ``report``: the metadata every file that can carry it stores."""
    from contactfem import __version__

    attributes = {"contactfem_version": __version__, "title": case.title, "case_file": str(case.source),
                  "case_hash": case.digest, "method": result.method, "plane": case.material.plane,
                  "backend": result.backend}
    return ResultData(solution=result.solution, report=report, case_text=case.text, attributes=attributes)


def to_json(data: dict) -> str:
    """Deterministic JSON: sorted keys, two-space indents, no NaN (a report with NaN is a bug)."""
    return json.dumps(data, indent=2, sort_keys=True, allow_nan=False) + "\n"


def _write_vtu(data: ResultData, directory: Path) -> list[Path]:
    return write_vtu(data.solution, directory, metadata=data.attributes)


def _write_h5(data: ResultData, directory: Path) -> list[Path]:
    attributes = {k: v for k, v in data.attributes.items() if k not in ("method", "case_hash")}
    return [write_hdf5(data.solution, directory / SOLUTION_H5, case_text=data.case_text,
                       case_hash=data.attributes.get("case_hash", ""), attributes=attributes)]


def _write_xdmf(data: ResultData, directory: Path) -> list[Path]:
    return write_xdmf(data.solution, directory)


def _write_json(data: ResultData, directory: Path) -> list[Path]:
    return [atomic_write_text(directory / REPORT_JSON, to_json(data.report))]


#: Every format, in the order written (the report last).
FORMATS: dict[str, OutputFormat] = {
    format.name: format for format in (
        OutputFormat("vtu", (SOLUTION_VTU, CONTACT_VTU, COLLECTION_PVD), _write_vtu,
                     description="ParaView: the body with its fields, ΓC with the contact fields, and a PVD of both"),
        OutputFormat("h5", (SOLUTION_H5,), _write_h5,
                     description="the whole result and the case text in one HDF5 archive (read by plot)"),
        OutputFormat("xdmf", (XDMF_FILE, COMPANION_H5), _write_xdmf, needs=("h5",),
                     description="an XDMF view of solution.h5 for ParaView and VisIt"),
        OutputFormat("json", (REPORT_JSON,), _write_json, description="the report"),
    )
}
FORMAT_NAMES = tuple(FORMATS)
#: Written unless the case lists its own; xdmf is an extra a case asks for.
DEFAULT_FORMATS = ("vtu", "h5", "json")
#: Every file a solve can leave in its directory (formats and pictures).
RESULT_FILES = tuple(name for format in FORMATS.values() for name in format.files) + PICTURES
#: Files whose presence marks a directory as holding a finished result.
RESULT_MARKERS = (REPORT_JSON, SOLUTION_H5)


def missing_needs(formats: tuple[str, ...]) -> list[tuple[str, str]]:
    """(format, needed) pairs of formats whose companion is not requested."""
    return [(name, need) for name in formats for need in FORMATS[name].needs if need not in formats]


def write_result(data: ResultData, directory: Path, formats: tuple[str, ...],
                 progress: Callable[[str], None] | None = None) -> tuple[list[Path], dict]:
    """Write ``formats`` of one result into ``directory`` (each file atomically), the report last.

    Returns the files written and the report as written, whose timings gain ``write``
    (the seconds of the other writers).
    """
    say = progress or (lambda message: None)
    clock = time.perf_counter()
    written: list[Path] = []
    for name, format in FORMATS.items():
        if name in formats and name != "json":
            say(f"writing {name.upper()}")
            written += format.write(data, Path(directory))
    report = {**data.report, "timings": {**data.report.get("timings", {}), "write": time.perf_counter() - clock}}
    if "json" in formats:
        written += FORMATS["json"].write(ResultData(data.solution, report, data.case_text, data.attributes),
                                         Path(directory))
    return written, report
