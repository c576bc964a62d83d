"""The files the commands read back from a results directory, and what each must hold.

Every file contactfem reads back is read through :mod:`contactfem.io.archive`, as
untrusted input, against the layout declared here (solution.h5's is
:data:`contactfem.io.hdf5.SOLUTION_LAYOUT`, next to its description):

- ``plot``: solution.h5 (:func:`read_solution`), compare.json (:func:`read_compare`) and
  convergence.json (:func:`read_convergence`), all through :func:`read_results`; ``solve
  --plot`` reads the solution.h5 it has just written through :func:`read_solution` too;
- ``sweep``: its stored points, ``points/<sha256>.json`` (:func:`read_point_record`).

Only the keys the commands use are checked in the JSON files (the shipped JSON Schemas,
contactfem/schemas/, describe the rest); other keys are kept as they are. Nothing else is
read back: report.json, contact.csv and path.h5 are written for users and other programs.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from contactfem.io.hdf5 import read_hdf5
from contactfem.io.json_layout import (
    Boolean,
    Choice,
    Integer,
    Items,
    Mapping,
    Node,
    Number,
    Object,
    Text,
    read_json_file,
)
from contactfem.io.registry import COMPARE_JSON, CONVERGENCE_JSON, SOLUTION_H5

__all__ = ["COMPARE_LAYOUT", "MAX_COMPARE_BYTES", "MAX_CONVERGENCE_BYTES", "MAX_POINT_BYTES", "ResultFiles",
           "convergence_layout", "point_layout", "read_compare", "read_convergence", "read_point_record",
           "read_results", "read_solution"]

#: compare.json holds seven numbers per contact node: 256 MiB is millions of them.
MAX_COMPARE_BYTES = 256 << 20
#: convergence.json holds a row per level and method (and texts of any length: see _DRAWN).
MAX_CONVERGENCE_BYTES = 64 << 20
#: A sweep's stored point: its case text (at most 1 MiB) and its figures.
MAX_POINT_BYTES = 2 << 20
#: Longest message or warning a stored point may carry.
_MAX_MESSAGE_BYTES = 64 << 10

_METHODS = ("positive", "standard")
#: A text the pictures draw (a title, a unit, a method's name): any string, bounded only by the
#: file's size, since the pictures draw each cut to one line (contactfem.picture_text.shown).
_DRAWN = Text(max_bytes=MAX_COMPARE_BYTES)
_UNITS = Object({"length": _DRAWN, "stress": _DRAWN}, optional={"force": _DRAWN})
_TITLE = Object({"title": _DRAWN})


def read_solution(path: Path | str) -> dict[str, Any]:
    """solution.h5, checked against :data:`~contactfem.io.hdf5.SOLUTION_LAYOUT` (see
    :func:`~contactfem.io.hdf5.read_hdf5`)."""
    return read_hdf5(path)


#: What compare.png is drawn from: the profiles along ΓC, one entry per contact node (m),
#: the positive method's contact zone, the units and the title.
COMPARE_LAYOUT = Object(
    required={
        "profiles": Object(
            required={"abscissa": Items(Number(), size="m"), "lambda": Items(Number(), size="m"),
                      "gap": Items(Number(), size="m"),
                      "active": Object({"positive": Items(Boolean(), size="m")},
                                       optional={"standard": Items(Boolean(), size="m")})},
            optional={"theta": Items(Number(), size="m"), "x": Items(Number(), size="m"),
                      "y": Items(Number(), size="m")}),
        "methods": Object({"positive": Object({"contact_zone": Object({
            "intervals": Items(Object({"abscissa": Items(Number(), length=2)}))})})}),
        "units": _UNITS,
        "case": _TITLE,
        "schema_version": Choice((1,)),
    })


def read_compare(path: Path | str) -> dict[str, Any]:
    """compare.json (written by ``contactfem compare``), checked against :data:`COMPARE_LAYOUT`."""
    return read_json_file(path, COMPARE_LAYOUT, "compare.json as contactfem compare writes it", MAX_COMPARE_BYTES)


def convergence_layout() -> Node:
    """What the convergence PNGs are drawn from: a row per level and method (h > 0, seconds
    ≥ 0, each error norm ≥ 0 or null), the observed rates, the warnings, units and title."""
    from contactfem.norms import NORM_NAMES

    error = Number(minimum=0, nullable=True)
    row = Object({"method": _DRAWN, "h": Number(minimum=0, positive=True),
                  "total_seconds": Number(minimum=0), **{norm: error for norm in NORM_NAMES}})
    return Object({
        "schema_version": Choice((1,)),
        "case": _TITLE,
        "units": Object({"length": _DRAWN}, optional={"force": _DRAWN, "stress": _DRAWN}),
        "reference": _DRAWN,
        "reference_extra": Integer(minimum=1, nullable=True),
        "rows": Items(row, max_items=10_000),
        "rates": Mapping(Mapping(Items(Number(nullable=True), max_items=10_000), max_items=len(NORM_NAMES)),
                         max_items=10_000),
        "warnings": Items(_DRAWN, max_items=100),
    })


def read_convergence(path: Path | str) -> dict[str, Any]:
    """convergence.json (written by ``contactfem converge``), checked against :func:`convergence_layout`."""
    return read_json_file(path, convergence_layout(), "convergence.json as contactfem converge writes it",
                          MAX_CONVERGENCE_BYTES)


def point_layout() -> Node:
    """A sweep's stored point (``points/<sha256>.json``): the figures its row is made of.
    A point solved (ok, not_certified) gives its unknowns, which rank it in its group."""
    from contactfem.sweep import POINT_SCHEMA_VERSION, STATUSES

    def solved_have_unknowns(record: dict) -> tuple[str, str] | None:
        if record["status"] in ("ok", "not_certified") and record.get("unknowns") is None:
            return "unknowns", f"an integer for a point whose status is {record['status']}"
        return None

    message = Text(max_bytes=_MAX_MESSAGE_BYTES, nullable=True)
    count = Integer(minimum=0, nullable=True)
    return Object(
        required={"schema_version": Choice((POINT_SCHEMA_VERSION,)), "case_text": Text(max_bytes=MAX_POINT_BYTES),
                  "digest": Text(max_bytes=64), "status": Choice(STATUSES)},
        optional={
            "message": message, "method": Choice(_METHODS, nullable=True), "backend": Text(nullable=True),
            "unknowns": count, "contact_nodes": count, "iterations": count,
            "contact_force": Number(nullable=True),
            "contact_zone": Object({"active_nodes": Integer(minimum=0),
                                    "intervals": Items(Items(Number(), length=2))}, nullable=True),
            "certificate": Choice(("passed", "failed"), nullable=True),
            "errors": Mapping(Number(nullable=True), nullable=True),
            "energy_norm": Number(minimum=0, nullable=True),
            "accuracy": Mapping(Number(nullable=True), nullable=True),
            "seconds": Mapping(Number(minimum=0, nullable=True)),
            "warnings": Items(Text(max_bytes=_MAX_MESSAGE_BYTES), max_items=1000),
        },
        rule=solved_have_unknowns)


def read_point_record(path: Path | str) -> dict[str, Any]:
    """A sweep's stored point, checked against :func:`point_layout`."""
    return read_json_file(path, point_layout(), "a sweep point's record as contactfem sweep writes it",
                          MAX_POINT_BYTES)


@dataclass(frozen=True)
class ResultFiles:
    """What ``plot`` draws from, read and checked: each None when its file is not there."""

    solution: dict[str, Any] | None = None
    compare: dict[str, Any] | None = None
    convergence: dict[str, Any] | None = None


def read_results(result_dir: Path | str) -> ResultFiles:
    """Every file of ``result_dir`` that ``plot`` draws from (solution.h5, compare.json,
    convergence.json), each read and checked in full before anything is drawn. A name that
    is there but not a regular file is refused like a damaged file."""
    directory = Path(result_dir)

    def there(name: str) -> bool:
        return os.path.lexists(directory / name)

    return ResultFiles(
        solution=read_solution(directory / SOLUTION_H5) if there(SOLUTION_H5) else None,
        compare=read_compare(directory / COMPARE_JSON) if there(COMPARE_JSON) else None,
        convergence=read_convergence(directory / CONVERGENCE_JSON) if there(CONVERGENCE_JSON) else None,
    )
