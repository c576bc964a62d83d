"""XDMF 3 description of ``solution.h5`` for ParaView (and VisIt): light XML over the archive's own arrays.

``solution.xdmf`` points into ``solution.h5`` for everything it shows; no array is stored
twice:

=====================  ==========================================  ==========================
XDMF                   heavy data in ``solution.h5``               ParaView array
=====================  ==========================================  ==========================
Geometry ``XY``        ``/mesh/points`` (n, 2)                     points, z = 0
Topology ``Triangle``  ``/mesh/triangles`` (n_tri, 3)              triangle cells
Attribute (Node)       ``/fields/displacement`` (n, 2)             ``displacement``
Attribute (Cell)       ``/fields/stress`` (n_tri, 6)               ``stress``: xx yy zz xy yz xz
Attribute (Cell)       ``/fields/von_mises`` (n_tri,)              ``von_mises``
=====================  ==========================================  ==========================

The stress is stored in VTK's symmetric tensor order and declared as a 6-column
``Matrix``: both ParaView readers (``Xdmf3ReaderS``, the default for ``.xdmf``, and the
XDMF 2 ``XDMFReader``) then pass the six components through unchanged, in the order of
``solution.vtu``. (A ``Tensor6`` would be reordered by the XDMF 2 reader only, from
XDMF's own order xx xy xz yy yz zz.)

The displacement is the archive's (n, 2) vector: the XDMF 2 reader pads it to three
components, the XDMF 3 readers keep two, and ParaView's Warp By Vector only offers
three-component arrays. To warp, open ``solution.pvd`` (or apply a Calculator
``displacement_X*iHat + displacement_Y*jHat``).

The contact fields live on ΓC only; they are in ``contact.vtu`` and ``/contact`` of the
archive, not in the XDMF file.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from contactfem.io.atomic import atomic_write_text, ensure_directory
from contactfem.io.hdf5 import SOLUTION_H5, STRESS_COMPONENTS
from contactfem.result import Solution

__all__ = ["COMPANION_H5", "XDMF_FILE", "write_xdmf"]

XDMF_FILE = "solution.xdmf"
#: The companion file of earlier versions (the reshaped arrays stored a second time); no longer
#: written, and removed from a directory whose result is replaced.
COMPANION_H5 = "solution-xdmf.h5"
ARCHIVE_H5 = SOLUTION_H5


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


def xdmf_text(solution: Solution, archive: str = ARCHIVE_H5) -> str:
    """The XML of ``solution.xdmf`` for ``solution`` (the archive's name relative to the XDMF file)."""
    mesh = solution.mesh
    n, n_tri = int(mesh.n_points), int(mesh.n_triangles)
    root = ET.Element("Xdmf", Version="3.0")
    domain = ET.SubElement(root, "Domain")
    grid = ET.SubElement(domain, "Grid", Name="body", GridType="Uniform")
    ET.SubElement(grid, "Information", Name="contactfem",
                  Value=f"method {solution.method}; stress components {' '.join(STRESS_COMPONENTS)}; "
                        "contact fields are in contact.vtu")
    topology = ET.SubElement(grid, "Topology", TopologyType="Triangle", NumberOfElements=str(n_tri))
    _data_item(topology, (n_tri, 3), "Int", f"{archive}:/mesh/triangles")
    geometry = ET.SubElement(grid, "Geometry", GeometryType="XY")
    _data_item(geometry, (n, 2), "Float", f"{archive}:/mesh/points")
    _attribute(grid, "displacement", "Vector", "Node", (n, 2), f"{archive}:/fields/displacement")
    _attribute(grid, "stress", "Matrix", "Cell", (n_tri, len(STRESS_COMPONENTS)), f"{archive}:/fields/stress")
    _attribute(grid, "von_mises", "Scalar", "Cell", (n_tri,), f"{archive}:/fields/von_mises")
    ET.indent(root)
    return ('<?xml version="1.0" encoding="utf-8"?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n'
            + ET.tostring(root, encoding="unicode") + "\n")


def write_xdmf(solution: Solution, directory: Path | str) -> list[Path]:
    """Write ``solution.xdmf`` next to ``solution.h5`` in ``directory``, atomically.

    ``solution.h5`` itself (written by :func:`contactfem.io.write_hdf5`) is referenced,
    not read: write it too.

    Returns
    -------
    list of Path
        ``[solution.xdmf]``.

    Raises
    ------
    OutputError
        If the file cannot be written.
    """
    directory = ensure_directory(directory)
    return [atomic_write_text(directory / XDMF_FILE, xdmf_text(solution))]
