"""XDMF 3 description of ``solution.h5`` for ParaView (and VisIt), plus a small companion file.

``solution.xdmf`` (light data, XML) points into the HDF5 archive for everything ParaView
can read from it as stored:

=====================  ==========================================  ====================
XDMF                   heavy data                                  ParaView array
=====================  ==========================================  ====================
Geometry ``XY``        ``solution.h5:/mesh/points`` (n, 2)         points, z = 0
Topology ``Triangle``  ``solution.h5:/mesh/triangles`` (n_tri, 3)  triangle cells
Attribute (Cell)       ``solution.h5:/fields/von_mises``           ``von_mises``
Attribute (Node)       ``solution-xdmf.h5:/displacement`` (n, 3)   ``displacement``
Attribute (Cell)       ``solution-xdmf.h5:/stress`` (n_tri, 9)     ``stress`` (3×3 tensor)
Attribute (Cell)       ``solution-xdmf.h5:/stress_xx`` ...         ``stress_xx`` ...
=====================  ==========================================  ====================

Why a companion file: the archive stores the displacement as (n, 2) and the stress as
(n_tri, 4) in the order xx yy xy zz. ParaView's XDMF 3 readers (``Xdmf3ReaderS`` /
``Xdmf3ReaderT``, the default for ``.xdmf``) ignore HyperSlab and Function data items
("Skipping unrecognized array type"), and take an (n, 2) ``Vector`` as a 2-component
array that makes Warp By Vector abort ParaView 5.11. So the arrays that need
reshaping — the displacement with z = 0, the stress tensor and its scalar components,
under the names of ``solution.vtu`` — are stored once more, ready to read, in
``solution-xdmf.h5``; the mesh and von Mises stress are read from ``solution.h5`` itself.

The stress is a full ``Tensor`` (9 components, row-major xx xy xz yx yy yz zx zy zz),
not a ``Tensor6``: XDMF's Tensor6 order is xx xy xz yy yz zz, which the XDMF 2 reader
expands correctly but the XDMF 3 readers pass through unchanged, where ParaView reads
six components in VTK's order xx yy zz xy yz xz. Nine components read the same in
every reader.

The contact fields live on ΓC only; they are in ``contact.vtu`` and ``/contact`` of the
archive, not in the XDMF file.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from contactfem.errors import OutputError
from contactfem.io.atomic import atomic_path, atomic_write_text, ensure_directory
from contactfem.io.hdf5 import SOLUTION_H5
from contactfem.result import Solution

__all__ = ["write_xdmf", "XDMF_FILE", "COMPANION_H5"]

XDMF_FILE = "solution.xdmf"
COMPANION_H5 = "solution-xdmf.h5"
ARCHIVE_H5 = SOLUTION_H5


def _tensor(stress: np.ndarray) -> np.ndarray:
    """Solution's (xx, yy, xy, zz) columns -> the full 3×3 tensor, row-major (n, 9)."""
    xx, yy, xy, zz = np.asarray(stress, dtype=np.float64).T
    zero = np.zeros(len(xx))
    return np.column_stack([xx, xy, zero, xy, yy, zero, zero, zero, zz])


def _companion_arrays(solution: Solution) -> dict[str, np.ndarray]:
    displacement = np.asarray(solution.displacement, dtype=np.float64)
    tensor = _tensor(solution.stress)
    return {
        "displacement": np.column_stack([displacement, np.zeros(len(displacement))]),
        "stress": tensor,
        "stress_xx": tensor[:, 0].copy(),
        "stress_yy": tensor[:, 4].copy(),
        "stress_xy": tensor[:, 1].copy(),
        "stress_zz": tensor[:, 8].copy(),
    }


def _data_item(parent: ET.Element, array_shape: tuple[int, ...], number_type: str, reference: str) -> None:
    item = ET.SubElement(
        parent, "DataItem",
        Dimensions=" ".join(str(d) for d in array_shape),
        NumberType=number_type, Precision="8", Format="HDF",
    )
    item.text = reference


def _attribute(grid: ET.Element, name: str, kind: str, center: str, shape: tuple[int, ...], reference: str) -> None:
    attribute = ET.SubElement(grid, "Attribute", Name=name, AttributeType=kind, Center=center)
    _data_item(attribute, shape, "Float", reference)


def xdmf_text(solution: Solution, archive: str = ARCHIVE_H5, companion: str = COMPANION_H5) -> str:
    """The XML of ``solution.xdmf`` for ``solution`` (file names relative to the XDMF file)."""
    mesh = solution.mesh
    n, n_tri = int(mesh.n_points), int(mesh.n_triangles)
    root = ET.Element("Xdmf", Version="3.0")
    domain = ET.SubElement(root, "Domain")
    grid = ET.SubElement(domain, "Grid", Name="body", GridType="Uniform")
    ET.SubElement(grid, "Information", Name="contactfem",
                  Value=f"method {solution.method}; contact fields are in contact.vtu")
    topology = ET.SubElement(grid, "Topology", TopologyType="Triangle", NumberOfElements=str(n_tri))
    _data_item(topology, (n_tri, 3), "Int", f"{archive}:/mesh/triangles")
    geometry = ET.SubElement(grid, "Geometry", GeometryType="XY")
    _data_item(geometry, (n, 2), "Float", f"{archive}:/mesh/points")
    _attribute(grid, "displacement", "Vector", "Node", (n, 3), f"{companion}:/displacement")
    _attribute(grid, "stress", "Tensor", "Cell", (n_tri, 9), f"{companion}:/stress")
    for name in ("stress_xx", "stress_yy", "stress_xy", "stress_zz"):
        _attribute(grid, name, "Scalar", "Cell", (n_tri,), f"{companion}:/{name}")
    _attribute(grid, "von_mises", "Scalar", "Cell", (n_tri,), f"{archive}:/fields/von_mises")
    ET.indent(root)
    return ('<?xml version="1.0" encoding="utf-8"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n'
            + ET.tostring(root, encoding="unicode") + "\n")


def write_xdmf(solution: Solution, directory: Path | str) -> list[Path]:
    """Write ``solution-xdmf.h5`` and ``solution.xdmf`` next to ``solution.h5`` in ``directory``.

    Each file is written atomically, the companion first, so ``solution.xdmf`` never
    points at a missing dataset. ``solution.h5`` itself (written by
    :func:`contactfem.io.write_hdf5`) is referenced, not read: write it too.

    Returns
    -------
    list of Path
        ``[solution-xdmf.h5, solution.xdmf]``.

    Raises
    ------
    OutputError
        If a file cannot be written.
    """
    import h5py

    directory = ensure_directory(directory)
    arrays = _companion_arrays(solution)
    text = xdmf_text(solution)
    companion = directory / COMPANION_H5
    try:
        with atomic_path(companion) as temporary:
            with h5py.File(temporary, "w") as f:
                f.attrs["format"] = "contactfem-xdmf-companion"
                f.attrs["note"] = "arrays of solution.h5 reshaped for solution.xdmf (see contactfem/io/xdmf.py)"
                for name, values in arrays.items():
                    f.create_dataset(name, data=values)
    except OSError as exc:  # atomic_path wraps its own errors; h5py raises plain OSError
        raise OutputError(f"cannot write {companion}: {exc.strerror or exc}") from exc
    return [companion, atomic_write_text(directory / XDMF_FILE, text)]
