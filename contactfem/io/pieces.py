"""The files of a result kept in pieces (a solve on a distributed mesh), written by every rank into
one staging directory: no rank holds the whole mesh.

- ``solution_<rank>.vtu``: each rank's piece (its triangles, the nodes they use, the fields), by
  :func:`contactfem.io.vtu.write_grid`; ``solution.pvtu`` (rank 0) names them, ParaView's
  parallel format, and ``solution.pvd`` lists ``solution.pvtu`` and ``contact.vtu`` as the
  serial one lists ``solution.vtu`` and ``contact.vtu``. Nodes on a cut between pieces appear
  in each piece that uses them (as in every PVTU without ghost cells).
- ``solution.h5``: one file of the serial layout, made by rank 0 at the whole shapes and filled
  rank after rank (:func:`contactfem.io.hdf5.write_piece_slices`), nodes in PETSc's order.
- ``contact.vtu``, ``contact.csv`` and ``report.json``: rank 0, from the contact arrays and the
  boundary it holds; the report last.

Every step ends with the ranks agreeing on whether it failed (an all-reduce), so a failure on
any rank reaches all of them as one :class:`OutputError` and none waits for another: the caller's
staging directory then goes, and the previous result stays.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from contactfem.errors import OutputError
from contactfem.io.atomic import atomic_write_text
from contactfem.io.vtu import SOLUTION_PVTU
from contactfem.timings import clock

#: The formats a result in pieces can be written in.
PIECE_FORMATS = ("vtu", "h5", "csv", "json")


def piece_vtu(rank: int) -> str:
    """The file name of rank ``rank``'s piece."""
    return f"solution_{int(rank)}.vtu"


@dataclass(frozen=True, eq=False)
class RootData:
    """What rank 0 adds to its piece: the :class:`~contactfem.io.registry.ResultData` of the
    boundary result (contact fields, report, metadata) and each boundary node's number in the
    whole mesh."""

    data: object
    numbers: np.ndarray


def write_pieces(directory: Path, fields, formats: tuple[str, ...], mpi, root: RootData | None,
                 progress: Callable[[str], None] | None = None,
                 per_rank: Callable[[], dict] | None = None) -> tuple[list[str], dict | None]:
    """Write a result kept in pieces into ``directory`` (every rank calls it; ``root`` given on
    rank 0 only; ``fields`` this rank's :class:`~contactfem.distributed_output.PieceFields`).

    Returns the names written and, on rank 0, the report as written (its timings gain ``write``).
    ``per_rank``: each rank's figures once the body's files are written (its peak memory),
    merged into its entry of the report's ``parallel.per_rank``.

    Raises
    ------
    OutputError
        On every rank, when writing failed on any (the message names the rank and its reason).
    """
    say = progress or (lambda message: None)
    rank, ranks = mpi.Get_rank(), mpi.Get_size()
    started = clock()
    metadata = mpi.bcast(None if root is None else root.data.attributes, root=0)
    names: list[str] = []
    if "vtu" in formats:
        say("writing VTU (a piece per rank)")
        _agree(mpi, _attempt(lambda: _write_vtu_piece(directory, fields, metadata, rank, ranks, root)))
        names += [piece_vtu(r) for r in range(ranks)] + ["contact.vtu", SOLUTION_PVTU, "solution.pvd"]
    if "h5" in formats:
        say("writing H5 (rank after rank)")
        _write_h5(directory, fields, mpi, root)
        names.append("solution.h5")
    figures = mpi.gather(per_rank(), root=0) if per_rank is not None else None
    if root is None:
        _agree(mpi, None)
        return names, None
    from contactfem.io.registry import CONTACT_CSV, REPORT_JSON, contact_table, to_json

    data = root.data
    report = {**data.report, "timings": {**data.report.get("timings", {}), "write": clock() - started}}
    if figures is not None:
        report["parallel"] = _merged(report["parallel"], figures)

    def finish() -> None:
        if "csv" in formats:
            atomic_write_text(directory / CONTACT_CSV, contact_table(data.solution))
        if "json" in formats:
            atomic_write_text(directory / REPORT_JSON, to_json(report))

    _agree(mpi, _attempt(finish))
    names += [name for name, format in ((CONTACT_CSV, "csv"), (REPORT_JSON, "json")) if format in formats]
    return names, report


def _merged(parallel: dict, figures: list[dict]) -> dict:
    """``parallel`` with each rank's ``figures`` in its ``per_rank`` entry, the largest peak anew."""
    per_rank = [{**entry, **extra} for entry, extra in zip(parallel["per_rank"], figures)]
    merged = {**parallel, "per_rank": per_rank}
    if all("peak_rss_bytes" in entry for entry in per_rank):
        merged["max_peak_rss_bytes"] = max(entry["peak_rss_bytes"] for entry in per_rank)
    return merged


def _write_vtu_piece(directory: Path, fields, metadata: dict, rank: int, ranks: int, root: RootData | None) -> None:
    from contactfem.io.vtu import CONTACT_VTU, COLLECTION_PVD, body_grid, collection_text, contact_grid, pvtu_text
    from contactfem.io.vtu import write_grid

    grid = body_grid(fields.points, fields.triangles, fields.displacement, fields.stress, fields.von_mises, metadata)
    write_grid(directory / piece_vtu(rank), grid)
    if root is None:
        return
    write_grid(directory / CONTACT_VTU, contact_grid(root.data.solution, metadata, root.numbers))
    atomic_write_text(directory / SOLUTION_PVTU, pvtu_text(grid, [piece_vtu(r) for r in range(ranks)]))
    atomic_write_text(directory / COLLECTION_PVD, collection_text([("body", SOLUTION_PVTU), ("contact", CONTACT_VTU)]))


def _write_h5(directory: Path, fields, mpi, root: RootData | None) -> None:
    """solution.h5: rank 0 makes it at the whole shapes, then each rank in turn writes its rows."""
    from contactfem.io.hdf5 import SOLUTION_H5, PieceShapes, create_piece_archive, write_piece_slices

    path = directory / SOLUTION_H5

    def create() -> None:
        data = root.data
        attributes = {k: v for k, v in data.attributes.items() if k not in ("method", "case_hash")}
        create_piece_archive(data.solution, path, PieceShapes(fields.n_points, fields.n_triangles, root.numbers),
                             case_text=data.case_text, case_hash=data.attributes.get("case_hash", ""),
                             attributes=attributes, exact_pressure=data.exact_pressure)

    _agree(mpi, _attempt(create) if root is not None else None)
    for turn in range(mpi.Get_size()):
        error = None
        if turn == mpi.Get_rank():
            owned = fields.owned
            error = _attempt(lambda: write_piece_slices(
                path, fields.node_range, fields.points[owned], fields.displacement[owned], fields.triangle_offset,
                fields.numbers[fields.triangles], fields.stress, fields.von_mises))
        _agree(mpi, error)  # the token: the next rank opens the file once this one has closed it


def _attempt(step: Callable[[], object]) -> str | None:
    """Run ``step``; the reason it failed (None when it did not)."""
    try:
        step()
    except Exception as error:  # any failure must reach the other ranks, which would wait otherwise
        return str(error) or type(error).__name__
    return None


def _agree(mpi, error: str | None) -> None:
    """Every rank learns whether any failed, and why (the lowest failing rank's reason)."""
    from mpi4py import MPI

    failed = mpi.allreduce(mpi.Get_rank() if error is not None else mpi.Get_size(), op=MPI.MIN)
    if failed == mpi.Get_size():
        return
    reason = mpi.bcast(error, root=failed)
    raise OutputError(f"writing the result in pieces failed on rank {failed}: {reason}")
