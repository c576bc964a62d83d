"""ParaView output: body and contact boundary as VTU files, tied together by a PVD collection."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from contactfem.errors import OutputError
from contactfem.io.atomic import atomic_path, atomic_write_text, ensure_directory
from contactfem.result import Solution

__all__ = ["write_vtu", "SOLUTION_VTU", "CONTACT_VTU", "COLLECTION_PVD"]

SOLUTION_VTU = "solution.vtu"
CONTACT_VTU = "contact.vtu"
COLLECTION_PVD = "solution.pvd"


def _with_zero_z(xy: np.ndarray) -> np.ndarray:
    """(n, 2) -> (n, 3) with a zero third column: VTK points and vectors are 3D."""
    xy = np.asarray(xy, dtype=np.float64)
    return np.column_stack([xy, np.zeros(len(xy))])


@dataclass(frozen=True, eq=False)
class _Grid:
    """An unstructured grid of one cell type, as VTK stores it."""

    points: np.ndarray  # (n, 3)
    cells: np.ndarray  # (m, k) node indices
    cell_type: int  # VTK cell type: 5 triangle, 3 line
    point_data: dict[str, np.ndarray]
    cell_data: dict[str, np.ndarray]


def _body_mesh(solution: Solution) -> _Grid:
    """The triangulation with displacement and stresses."""
    mesh = solution.mesh
    stress = np.asarray(solution.stress, dtype=np.float64)
    xx, yy, xy, zz = stress.T  # Solution's column order
    zero = np.zeros(len(stress))
    # VTK's symmetric tensor order is XX, YY, ZZ, XY, YZ, XZ; ParaView shows a
    # 6-component array as a symmetric tensor (eigenvalues, Tensor Glyph...).
    tensor = np.column_stack([xx, yy, zz, xy, zero, zero])
    cell_data = {
        "stress": tensor,
        "stress_xx": xx,
        "stress_yy": yy,
        "stress_xy": xy,
        "stress_zz": zz,
        "von_mises": np.asarray(solution.von_mises, dtype=np.float64),
    }
    return _Grid(
        points=_with_zero_z(mesh.points),
        cells=np.asarray(mesh.triangles, dtype=np.int64),
        cell_type=VTK_TRIANGLE,
        point_data={"displacement": _with_zero_z(solution.displacement)},
        cell_data=cell_data,
    )


def _contact_mesh(solution: Solution) -> _Grid:
    """ΓC as line cells over its own, renumbered nodes, with the contact fields."""
    contact = solution.contact
    edges = np.asarray(contact.edges, dtype=np.int64).reshape(-1, 2)
    nodes = np.asarray(contact.nodes, dtype=np.int64)
    if len(edges) == 0:
        # A VTU needs at least one cell, and a solved case always has ΓC.
        raise OutputError(f"cannot write {CONTACT_VTU}: the solution has no contact edges")
    # The union equals the edge nodes when the contact fields are consistent; it only
    # guards against a contact node that no edge touches, which would otherwise make
    # the lookup below index the wrong point.
    mesh_node = np.union1d(edges.ravel(), nodes)
    local_edges = np.searchsorted(mesh_node, edges)
    where = np.searchsorted(mesh_node, nodes)

    def on_boundary(values: np.ndarray, dtype: type) -> np.ndarray:
        # Nodes of ΓC that are not contact nodes (Dirichlet corners) carry no
        # multiplier; 0 rather than NaN keeps ParaView's ranges and filters usable.
        full = np.zeros(len(mesh_node), dtype=dtype)
        full[where] = values
        return full

    point_data = {
        "mesh_node": mesh_node,
        "contact_pressure": on_boundary(contact.multiplier, np.float64),
        "nodal_force": on_boundary(contact.nodal_force, np.float64),
        "normal_displacement": on_boundary(contact.normal_displacement, np.float64),
        "gap": on_boundary(contact.gap, np.float64),
        "active": on_boundary(np.asarray(contact.active, dtype=bool), np.uint8),
        "contact_node": on_boundary(np.ones(len(nodes), dtype=np.uint8), np.uint8),
        "displacement": _with_zero_z(np.asarray(solution.displacement)[mesh_node]),
    }
    return _Grid(
        points=_with_zero_z(np.asarray(solution.mesh.points)[mesh_node]),
        cells=local_edges,
        cell_type=VTK_LINE,
        point_data=point_data,
        cell_data={},
    )


def _collection_xml(parts: list[tuple[str, str]]) -> str:
    """A PVD file listing ``(name, file)`` pairs as the parts of time step 0."""
    root = ET.Element(
        "VTKFile", type="Collection", version="0.1", byte_order="LittleEndian"
    )
    collection = ET.SubElement(root, "Collection")
    for part, (name, file) in enumerate(parts):
        ET.SubElement(
            collection,
            "DataSet",
            timestep="0",
            group="",
            part=str(part),
            file=file,
            name=name,
        )
    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


VTK_TRIANGLE, VTK_LINE = 5, 3
_VTK_TYPES = {"f8": "Float64", "f4": "Float32", "i8": "Int64", "i4": "Int32", "u1": "UInt8"}


def _write_grid(grid: _Grid, path: Path) -> None:
    """Write ``grid`` as VTK XML with raw appended binary data, atomically.

    Raw appended data behind UInt64 byte counts is what ParaView reads fastest and has no
    size limit; it also skips the base64 encoding that made meshio's writer cost 2–4 s
    on 2 M triangles (now about a tenth of that).
    """
    arrays: list[np.ndarray] = []
    offset = 0

    def entry(name: str, array: np.ndarray) -> str:
        nonlocal offset
        array = np.ascontiguousarray(array)
        array = array.astype(array.dtype.newbyteorder("<"), copy=False)
        # Scalars leave NumberOfComponents at VTK's default 1, so readers see them 1-D.
        components = "" if array.ndim == 1 else f' NumberOfComponents="{array.shape[1]}"'
        kind = _VTK_TYPES[f"{array.dtype.kind}{array.dtype.itemsize}"]
        text = f'<DataArray type="{kind}" Name="{name}"{components} format="appended" offset="{offset}"/>'
        arrays.append(array)
        offset += 8 + array.nbytes
        return text

    n_cells, per_cell = grid.cells.shape
    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">',
        "<UnstructuredGrid>",
        f'<Piece NumberOfPoints="{len(grid.points)}" NumberOfCells="{n_cells}">',
        "<Points>", entry("Points", np.asarray(grid.points, dtype=np.float64)), "</Points>",
        "<Cells>",
        entry("connectivity", np.asarray(grid.cells, dtype=np.int64).ravel()),
        entry("offsets", per_cell * np.arange(1, n_cells + 1, dtype=np.int64)),
        entry("types", np.full(n_cells, grid.cell_type, dtype=np.uint8)),
        "</Cells>",
        "<PointData>", *(entry(name, values) for name, values in grid.point_data.items()), "</PointData>",
        "<CellData>", *(entry(name, values) for name, values in grid.cell_data.items()), "</CellData>",
        "</Piece>",
        "</UnstructuredGrid>",
        '<AppendedData encoding="raw">',
    ]
    with atomic_path(path) as temp:
        _stream(temp, "\n".join(lines) + "\n_", arrays)


def _stream(path: Path, header: str, arrays: list[np.ndarray]) -> None:
    """The file itself: XML header, then each array behind its UInt64 byte count."""
    with open(path, "wb") as stream:
        stream.write(header.encode("ascii"))
        for array in arrays:
            stream.write(np.uint64(array.nbytes).tobytes())
            stream.write(array.data)
        stream.write(b"\n</AppendedData>\n</VTKFile>\n")


def write_vtu(solution: Solution, directory: Path | str) -> list[Path]:
    """Write the solution for ParaView: ``solution.vtu``, ``contact.vtu``, ``solution.pvd``.

    Each file is written atomically (see :func:`contactfem.io.atomic.atomic_path`); all
    arrays are built before the first file is touched, so an error in the data leaves
    the directory as it was. ``directory`` is created if missing.

    ``solution.vtu`` (VTK XML, raw appended binary data, UInt64 byte counts)
        Triangle cells; points with z = 0. Point data ``displacement`` (n, 3) with
        z = 0, so that Warp By Vector works. Cell data ``stress`` (n_tri, 6), a
        symmetric tensor in VTK's order xx, yy, zz, xy, yz, xz (yz = xz = 0), and the
        scalars ``stress_xx``, ``stress_yy``, ``stress_xy``, ``stress_zz``,
        ``von_mises``.
    ``contact.vtu``
        The contact boundary ΓC as line cells over the nodes of its edges only,
        renumbered. Point data ``mesh_node`` (int64, index in the full mesh),
        ``contact_pressure`` (the method's multiplier), ``nodal_force``,
        ``normal_displacement``, ``gap``, ``active`` (uint8 0/1), ``contact_node``
        (uint8, 1 at contact nodes) and ``displacement`` (3 columns, z = 0). Nodes of
        ΓC that are not contact nodes (Dirichlet corners, clamped) carry 0 in every
        contact array, including ``gap`` and ``active``; no NaN is written.
    ``solution.pvd``
        A collection with both files as parts 0 (``body``) and 1 (``contact``) of
        time step 0, so that ParaView opens them together.

    Parameters
    ----------
    solution : Solution
    directory : Path or str
        Where to write the three files.

    Returns
    -------
    list of Path
        The written files, in the order above.

    Raises
    ------
    OutputError
        If the directory cannot be created or a file cannot be written, or if the
        solution has no contact edges (a VTU needs at least one cell).
    """
    directory = Path(directory)
    body = _body_mesh(solution)
    boundary = _contact_mesh(solution)
    ensure_directory(directory)

    paths = [directory / SOLUTION_VTU, directory / CONTACT_VTU, directory / COLLECTION_PVD]
    _write_grid(body, paths[0])
    _write_grid(boundary, paths[1])
    atomic_write_text(
        paths[2], _collection_xml([("body", SOLUTION_VTU), ("contact", CONTACT_VTU)])
    )
    return paths
