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
as time, so that ParaView's time control steps along the path.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from contactfem.io.atomic import atomic_path, atomic_write_text
from contactfem.io.series import write_series
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


def write_path_series(directory: Path, factors: Sequence[float], solutions: Sequence[Solution]) -> list[Path]:
    """path.pvd and the steps' VTU files, the load factor as time."""
    entries = [(step_label(i, len(solutions)), solution) for i, solution in enumerate(solutions)]
    return write_series(directory, PATH_STEM, entries, times=[float(f) for f in factors])


def path_table(curves: Mapping[str, Sequence[float]]) -> str:
    """path.csv: the curves as columns, one row per step."""
    names = list(curves)
    rows = [",".join(names)]
    rows += [",".join(str(value) if isinstance(value, (int, np.integer)) else repr(float(value)) for value in values)
             for values in zip(*(curves[n] for n in names))]
    return "\n".join(rows) + "\n"


def write_path_csv(directory: Path, curves: Mapping[str, Sequence[float]]) -> Path:
    return atomic_write_text(Path(directory) / PATH_CSV, path_table(curves))


def write_path_h5(directory: Path, factors: Sequence[float], solutions: Sequence[Solution],
                  curves: Mapping[str, Sequence[float]], *, case_text: str,
                  attributes: Mapping[str, str]) -> Path:
    """path.h5 (see the module docstring), written atomically."""
    import h5py

    first = solutions[0]
    contact = first.contact
    path = Path(directory) / PATH_H5
    with atomic_path(path) as temporary, h5py.File(temporary, "w") as file:
        file.attrs["format"] = FORMAT
        file.attrs["schema_version"] = SCHEMA_VERSION
        for key, value in attributes.items():
            file.attrs[key] = value
        file.create_dataset("case", data=case_text, dtype=h5py.string_dtype("utf-8"))
        file.create_dataset("factors", data=np.asarray(factors, dtype=float))
        file.create_dataset("mesh/points", data=first.mesh.points)
        file.create_dataset("mesh/triangles", data=first.mesh.triangles.astype(np.int64))
        file.create_dataset("contact/nodes", data=contact.nodes.astype(np.int64))
        file.create_dataset("contact/abscissa", data=contact.abscissa)
        file.create_dataset("contact/gap", data=contact.gap)
        steps = len(solutions)
        fields = {
            "displacement": (first.displacement.shape, float, lambda s: s.displacement),
            "von_mises": (first.von_mises.shape, float, lambda s: s.von_mises),
            "multiplier": (contact.multiplier.shape, float, lambda s: s.contact.multiplier),
            "nodal_force": (contact.nodal_force.shape, float, lambda s: s.contact.nodal_force),
            "normal_displacement": (contact.normal_displacement.shape, float, lambda s: s.contact.normal_displacement),
            "active": (contact.active.shape, np.uint8, lambda s: s.contact.active.astype(np.uint8)),
        }
        for name, (shape, dtype, value) in fields.items():
            dataset = file.create_dataset(f"steps/{name}", shape=(steps, *shape), dtype=dtype)
            for index, solution in enumerate(solutions):
                dataset[index] = value(solution)
        for name, values in curves.items():
            file.create_dataset(f"curves/{name}", data=np.asarray(values, dtype=float))
    return path
