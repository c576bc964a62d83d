"""The table of a sweep's points: each row's group, error and place on the Pareto front, and sweep.csv."""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable
from typing import Any

from contactfem.sweep_plan import SweepPoint, _shown_value

#: The report's timings, in order; ``total`` (the point's wall time in its worker) follows.
STAGES = ("mesh", "assemble", "solve", "postprocess", "report")
#: The units of a row's figures (the point's case's), the last columns of sweep.csv.
UNITS = ("length", "force", "stress")
UNIT_COLUMNS = tuple(f"{name}_unit" for name in UNITS)
ERROR_NORMS = ("displacement_l2", "displacement_h1_semi", "displacement_h1", "displacement_energy",
               "multiplier_l2", "multiplier_h_minus_half")


def _row(point: SweepPoint, record: dict, reused: bool) -> dict:
    figures = {key: record.get(key) for key in ("status", "message", "method", "backend", "unknowns",
                                                "contact_nodes", "iterations", "contact_force", "contact_zone",
                                                "certificate", "errors", "energy_norm", "accuracy")}
    return {"index": point.index, "values": point.values, "label": point.label, "digest": point.digest,
            "reused": reused, **figures, "seconds": dict(record.get("seconds") or {}),
            "warnings": list(record.get("warnings") or []), "units": point.units,
            "group": "", "error_kind": None, "error": None, "error_reference": None, "pareto": False}


def _rank(rows: list[dict], keys: tuple[str, ...]) -> None:
    """Each row's group, error (see :mod:`contactfem.sweep`) and place on its group's Pareto front."""
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
        # The estimate only where every point of the group has one: one measure per front.
        estimated = all((row["accuracy"] or {}).get("energy") is not None for row in solved)
        for row in solved:
            if row["errors"]:
                row["error_kind"] = "exact"
                row["error"] = row["errors"].get("displacement_energy")
            elif estimated:
                row["error_kind"] = "estimated"
                row["error"] = row["accuracy"]["energy"]
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
              "error_kind", "error", "error_reference", "pareto", "reused", "digest", "message",
              *UNIT_COLUMNS]
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
            *(_cell((row["units"] or {}).get(name)) for name in UNITS),
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
