"""The files of a load path: every step in one HDF5 file, the curves as a table, and a PVD series.

path.h5, schema version 1 (S steps on one mesh)::

    /                      attrs: format = "contactfem-path", schema_version = 1 (int),
                                  plus the caller's ``attributes`` (as solution.h5's)
    /case                  scalar UTF-8 string: the case file text
    /factors               (S,) float64, the load factor of each step
    /mesh/points           (n, 2) float64
    /mesh/triangles        (n_tri, 3) int64
    /contact/nodes         (m,) int64, sorted along ΓC
    /contact/abscissa      (m,) float64, position of each node along the obstacle
    /contact/gap           (m,) float64, the initial gap (does not change along the path)
    /steps/displacement    (S, n, 2) float64
    /steps/von_mises       (S, n_tri) float64
    /steps/multiplier      (S, m) float64
    /steps/nodal_force     (S, m) float64
    /steps/normal_displacement (S, m) float64
    /steps/active          (S, m) uint8, 0/1
    /curves/<name>         (S,) float64, the columns of path.csv (report.json's load_path.curves)

path.csv has one row per step and the columns of ``/curves``; path.pvd lists the steps'
VTU files (``path-<k>.vtu`` and ``path-<k>-contact.vtu``, k from 1) with the load factor
as time, so that ParaView's time control steps along the path. :class:`PathWriter` writes
them all as the steps are solved.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from contactfem.io.atomic import atomic_write_text
from contactfem.io.series import series_files, series_xml
from contactfem.io.table import csv_table
from contactfem.io.vtu import solution_grids, write_grid
from contactfem.result import Solution

FORMAT = "contactfem-path"
SCHEMA_VERSION = 1
PATH_STEM = "path"
PATH_H5 = "path.h5"
PATH_CSV = "path.csv"
PATH_PVD = "path.pvd"
#: The steps' VTU files, as a pattern: their number changes with the path.
PATH_STEP_FILES = "path-*.vtu"


def step_label(index: int, count: int) -> str:
    """The label of step ``index`` (from 0) in file names: 1-based, zero-padded to sort."""
    return f"{index + 1:0{len(str(count))}d}"


class PathWriter:
    """Writes a load path's files step by step, as the steps are solved, into a staging
    directory (see :func:`contactfem.io.atomic.claimed_directory`), so that a path of any
    length holds one step in memory: :meth:`add` writes the step's two VTU files and its
    rows of path.h5; :meth:`finish` adds the curves and the attributes, and writes path.csv
    and path.pvd. A failed path leaves only files the staging area discards.
    """

    def __init__(self, directory: Path | str, factors: Sequence[float], case_text: str) -> None:
        self.directory = Path(directory)
        self.factors = [float(f) for f in factors]
        self.case_text = case_text
        self.labels: list[str] = []
        self.written: list[Path] = []
        self._file = None

    def add(self, index: int, solution: Solution) -> None:
        """Write step ``index`` (from 0, in order)."""
        if index != len(self.labels):
            raise ValueError(f"path step {index} written after {len(self.labels)} steps")
        label = step_label(index, len(self.factors))
        for grid, file in zip(solution_grids(solution), series_files(PATH_STEM, label)):
            self.written.append(write_grid(self.directory / file, grid))
        self.labels.append(label)
        if self._file is None:
            self._open(solution)
        contact = solution.contact
        values = {"displacement": solution.displacement, "von_mises": solution.von_mises,
                  "multiplier": contact.multiplier, "nodal_force": contact.nodal_force,
                  "normal_displacement": contact.normal_displacement, "active": contact.active.astype(np.uint8)}
        for name, value in values.items():
            self._file[f"steps/{name}"][index] = value

    def _open(self, first: Solution) -> None:
        import h5py

        self._file = h5py.File(self.directory / PATH_H5, "w")
        file, contact, steps = self._file, first.contact, len(self.factors)
        file.attrs["format"] = FORMAT
        file.attrs["schema_version"] = SCHEMA_VERSION
        file.create_dataset("case", data=self.case_text, dtype=h5py.string_dtype("utf-8"))
        file.create_dataset("factors", data=np.asarray(self.factors))
        file.create_dataset("mesh/points", data=first.mesh.points)
        file.create_dataset("mesh/triangles", data=first.mesh.triangles.astype(np.int64))
        file.create_dataset("contact/nodes", data=contact.nodes.astype(np.int64))
        file.create_dataset("contact/abscissa", data=contact.abscissa)
        file.create_dataset("contact/gap", data=contact.gap)
        shapes = {"displacement": (first.displacement.shape, float), "von_mises": (first.von_mises.shape, float),
                  "multiplier": (contact.multiplier.shape, float), "nodal_force": (contact.nodal_force.shape, float),
                  "normal_displacement": (contact.normal_displacement.shape, float),
                  "active": (contact.active.shape, np.uint8)}
        for name, (shape, dtype) in shapes.items():
            file.create_dataset(f"steps/{name}", shape=(steps, *shape), dtype=dtype)

    def finish(self, curves: Mapping[str, Sequence[float]], attributes: Mapping[str, str]) -> list[Path]:
        """Complete path.h5 with the curves and ``attributes``, write path.csv and path.pvd;
        returns every file of the path."""
        if len(self.labels) != len(self.factors):
            raise ValueError(f"a path of {len(self.factors)} steps finished after {len(self.labels)}")
        try:
            for key, value in attributes.items():
                self._file.attrs[key] = value
            for name, values in curves.items():
                self._file.create_dataset(f"curves/{name}", data=np.asarray(values, dtype=float))
        finally:
            self.close()
        self.written.append(self.directory / PATH_H5)
        self.written.append(atomic_write_text(self.directory / PATH_CSV, csv_table(curves)))
        self.written.append(atomic_write_text(self.directory / PATH_PVD,
                                              series_xml(PATH_STEM, self.labels, self.factors)))
        return self.written

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
