"""A series of solutions (the methods of ``compare``, the levels of ``converge``, the steps of a load path) as one PVD.

Each entry is written by :func:`contactfem.io.vtu.write_grid` with the grids of
:func:`contactfem.io.vtu.solution_grids` (same arrays as a solve's ``solution.vtu`` and
``contact.vtu``) and stored flat as ``<stem>-<label>.vtu`` and
``<stem>-<label>-contact.vtu``; ``<stem>.pvd`` lists them as the time steps 0, 1, 2 … of
one collection (part 0 the body, part 1 ΓC), so that ParaView's time control steps
through the methods or the levels (a load path's time steps are its load factors). The ``name`` attribute of each data set carries the
label. Files only, no subdirectories: a staged output directory moves files into place.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

from contactfem.io.atomic import atomic_write_text, ensure_directory
from contactfem.io.vtu import solution_grids, write_grid
from contactfem.result import Solution

__all__ = ["series_files", "series_xml", "write_series"]


def series_files(stem: str, label: str) -> tuple[str, str]:
    """The body and contact VTU files of entry ``label`` of the series ``stem``."""
    return f"{stem}-{label}.vtu", f"{stem}-{label}-contact.vtu"


def series_xml(stem: str, labels: Sequence[str], times: Sequence[float] | None = None) -> str:
    """The PVD text: time step i (``times[i]``, default i) holds the body and contact VTU files of ``labels[i]``."""
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    times = range(len(labels)) if times is None else times
    for time, label in zip(times, labels):
        for part, file in enumerate(series_files(stem, label)):
            ET.SubElement(collection, "DataSet", timestep=str(time) if isinstance(time, int) else repr(float(time)), group="", part=str(part),
                          file=file, name=f"{label} {('body', 'contact')[part]}")
    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def write_series(directory: Path | str, stem: str, entries: Sequence[tuple[str, Solution]],
                 times: Sequence[float] | None = None) -> list[Path]:
    """Write each ``(label, solution)`` as ``stem-label.vtu``, ``stem-label-contact.vtu``, then ``stem.pvd``
    (time steps ``times``, default 0, 1, 2 …).

    Labels must be plain names (no path separators). Each file is written atomically.
    Returns the written files, the collection last.
    """
    directory = ensure_directory(directory)
    labels = [label for label, _ in entries]
    for label in labels:
        if not label or "/" in label or "\\" in label or label in (".", ".."):
            raise ValueError(f"series label {label!r} is not a plain name")
    written = []
    for label, solution in entries:
        for grid, file in zip(solution_grids(solution), series_files(stem, label)):
            written.append(write_grid(directory / file, grid))
    written.append(atomic_write_text(directory / f"{stem}.pvd", series_xml(stem, labels, times)))
    return written
