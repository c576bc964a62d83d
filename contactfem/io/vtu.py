"""ParaView output: body and contact boundary as VTU files, tied together by a PVD collection.

Every VTU file of the package goes through :func:`write_grid`, which hands the arrays to
VTK's own ``vtkXMLUnstructuredGridWriter``: appended data encoded in base64, no
compression, UInt64 byte counts, little endian, 64-bit ids. ParaView and meshio read it
back as written (meshio misreads some raw appended files), and it has no 4 GB limit. VTK is imported only when a file is written.
"""

from __future__ import annotations

import errno
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from contactfem.errors import OutputError
from contactfem.io.atomic import atomic_path, atomic_write_text, ensure_directory
from contactfem.result import Solution

__all__ = [
    "COLLECTION_PVD",
    "CONTACT_VTU",
    "PIECE_VTU_PATTERN",
    "SOLUTION_PVTU",
    "SOLUTION_VTU",
    "VTK_LINE",
    "VTK_TRIANGLE",
    "Grid",
    "solution_grids",
    "write_grid",
    "write_vtu",
]

SOLUTION_VTU = "solution.vtu"
CONTACT_VTU = "contact.vtu"
COLLECTION_PVD = "solution.pvd"
#: A body kept in pieces (a distributed mesh, :mod:`contactfem.io.pieces`): the index of the
#: pieces, and the name pattern of the pieces themselves.
SOLUTION_PVTU = "solution.pvtu"
PIECE_VTU_PATTERN = "solution_*.vtu"

#: VTK cell types of the grids written here.
VTK_TRIANGLE, VTK_LINE = 5, 3


@dataclass(frozen=True, eq=False)
class Grid:
    """An unstructured grid of one cell type, as :func:`write_grid` writes it.

    Attributes
    ----------
    points : (n, 2) or (n, 3) float
        Coordinates; 2D points get z = 0 (VTK points are 3D).
    cells : (m, k) int
        Point indices of each cell, ``k`` the point count of ``cell_type``.
    cell_type : int
        VTK cell type, e.g. :data:`VTK_TRIANGLE` or :data:`VTK_LINE`.
    point_data, cell_data : dict of str to ndarray
        ``(n,)``/``(m,)`` scalars or ``(n, c)``/``(m, c)`` arrays of ``c`` components.
        Stored with their own dtype (float32/64, signed or unsigned integers of 8 to
        64 bits; bool becomes uint8).
    field_data : dict of str to str or ndarray
        Arrays of any length that belong to the whole grid. A ``str`` is stored as its
        UTF-8 bytes (a UInt8 array): meshio's VTU reader rejects VTK string arrays and
        would then not read the file at all.
    """

    points: np.ndarray
    cells: np.ndarray
    cell_type: int
    point_data: Mapping[str, np.ndarray] = field(default_factory=dict)
    cell_data: Mapping[str, np.ndarray] = field(default_factory=dict)
    field_data: Mapping[str, str | np.ndarray] = field(default_factory=dict)


def _with_zero_z(xy: np.ndarray) -> np.ndarray:
    """(n, 2) -> (n, 3) with a zero third column: VTK points and vectors are 3D."""
    xy = np.asarray(xy, dtype=np.float64)
    out = np.zeros((len(xy), 3))
    out[:, :2] = xy
    return out


def _body_grid(solution: Solution, metadata: Mapping[str, str]) -> Grid:
    """The triangulation with displacement, stresses and ``solution.cell_fields``."""
    return body_grid(solution.mesh.points, solution.mesh.triangles, solution.displacement, solution.stress,
                     solution.von_mises, metadata, solution.cell_fields)


def body_grid(points: np.ndarray, triangles: np.ndarray, displacement: np.ndarray, stress: np.ndarray,
              von_mises: np.ndarray, metadata: Mapping[str, str],
              cell_fields: Mapping[str, np.ndarray] | None = None) -> Grid:
    """The body's grid as ``solution.vtu`` holds it, of a whole mesh or of one rank's piece:
    triangles with the displacement (n, 2) as a 3-vector, the stress (n_tri, 4: xx yy xy zz)
    as VTK's symmetric tensor and its components, von Mises and the extra cell fields."""
    stress = np.asarray(stress, dtype=np.float64)
    n_triangles = len(stress)
    # VTK's symmetric tensor order is XX, YY, ZZ, XY, YZ, XZ; ParaView shows a
    # 6-component array as a symmetric tensor (eigenvalues, Tensor Glyph...).
    tensor = np.zeros((n_triangles, 6))
    tensor[:, [0, 1, 3, 2]] = stress  # Solution's columns are xx, yy, xy, zz
    cell_data = {
        "stress": tensor,
        "stress_xx": stress[:, 0],
        "stress_yy": stress[:, 1],
        "stress_xy": stress[:, 2],
        "stress_zz": stress[:, 3],
        "von_mises": np.asarray(von_mises, dtype=np.float64),
    }
    for name, values in (cell_fields or {}).items():
        if name in cell_data:
            raise ValueError(f"cell field {name!r} would replace the {SOLUTION_VTU} array of that name")
        values = np.asarray(values)
        if values.shape != (n_triangles,):
            raise ValueError(f"cell field {name!r} has shape {values.shape}, expected ({n_triangles},)")
        cell_data[name] = values
    for name, value in metadata.items():
        if not isinstance(value, str):
            raise ValueError(f"metadata {name!r} is {type(value).__name__}, not str")
    return Grid(
        points=points,
        cells=triangles,
        cell_type=VTK_TRIANGLE,
        point_data={"displacement": _with_zero_z(displacement)},
        cell_data=cell_data,
        field_data=dict(metadata),
    )


def _contact_grid(solution: Solution, metadata: Mapping[str, str], numbers: np.ndarray | None = None) -> Grid:
    """ΓC as line cells over its own, renumbered nodes, with the contact fields and the same
    metadata as the body (a contact.vtu opened alone still says its case, method and units).
    ``numbers``: each mesh node's number in the body's files, when ``solution.mesh`` is only
    the boundary of a mesh kept in pieces."""
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
        "mesh_node": mesh_node if numbers is None else np.asarray(numbers, dtype=np.int64)[mesh_node],
        "contact_pressure": on_boundary(contact.multiplier, np.float64),
        "nodal_force": on_boundary(contact.nodal_force, np.float64),
        "normal_displacement": on_boundary(contact.normal_displacement, np.float64),
        "gap": on_boundary(contact.gap, np.float64),
        "active": on_boundary(np.asarray(contact.active, dtype=bool), np.uint8),
        "contact_node": on_boundary(np.ones(len(nodes), dtype=np.uint8), np.uint8),
        "displacement": _with_zero_z(np.asarray(solution.displacement)[mesh_node]),
    }
    return Grid(
        points=np.asarray(solution.mesh.points)[mesh_node],
        cells=local_edges,
        cell_type=VTK_LINE,
        point_data=point_data,
        field_data=dict(metadata),
    )


def contact_grid(solution: Solution, metadata: Mapping[str, str], numbers: np.ndarray | None = None) -> Grid:
    """``contact.vtu``'s grid (:func:`write_vtu`); ``numbers``: each node of ``solution.mesh``
    (then the boundary of a mesh kept in pieces) by its number in the body's files."""
    return _contact_grid(solution, metadata, numbers)


def solution_grids(solution: Solution, metadata: Mapping[str, str] | None = None) -> tuple[Grid, Grid]:
    """The body and the contact boundary of ``solution``, as :func:`write_vtu` writes them.

    ``metadata`` becomes the field data of both grids.

    Raises
    ------
    OutputError
        If the solution has no contact edges.
    ValueError
        If a cell field has the wrong length or the name of a built-in array, or a
        metadata value is not a string.
    """
    return _body_grid(solution, metadata or {}), _contact_grid(solution, metadata or {})


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


#: VTK's names of the dtypes a VTU file stores.
_VTK_TYPES = {("f", 4): "Float32", ("f", 8): "Float64"} | {
    (kind, size): f"{'U' if kind == 'u' else ''}Int{8 * size}" for kind in "iu" for size in (1, 2, 4, 8)}


def pvtu_text(grid: Grid, sources: list[str]) -> str:
    """A ``.pvtu`` index (VTK's PUnstructuredGrid, ParaView's parallel format) naming the piece
    files ``sources``, each written by :func:`write_grid` with the point and cell arrays of
    ``grid`` (one piece's grid: the index declares their names, types and components)."""
    arrays = _checked(grid)
    root = ET.Element("VTKFile", type="PUnstructuredGrid", version="1.0", byte_order="LittleEndian",
                      header_type="UInt64")
    body = ET.SubElement(root, "PUnstructuredGrid", GhostLevel="0")

    def declare(parent: ET.Element, name: str, values: np.ndarray) -> None:
        ET.SubElement(parent, "PDataArray", type=_VTK_TYPES[(values.dtype.kind, values.dtype.itemsize)], Name=name,
                      NumberOfComponents=str(1 if values.ndim == 1 else values.shape[1]))

    for tag, where in (("PPointData", "point_data"), ("PCellData", "cell_data")):
        parent = ET.SubElement(body, tag)
        for name, values in arrays[where].items():
            declare(parent, name, values)
    declare(ET.SubElement(body, "PPoints"), "Points", arrays["points"])
    for source in sources:
        ET.SubElement(body, "Piece", Source=source)
    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def collection_text(parts: list[tuple[str, str]]) -> str:
    """A PVD collection of ``(name, file)`` pairs as the parts of time step 0 (as ``solution.pvd``)."""
    return _collection_xml(parts)


# ----------------------------------------------------------------- the one VTU writer

# Kind and item size of the dtypes VTK stores as they are (Float32/64, (U)Int8..64).
_STORABLE = {("f", 4), ("f", 8)} | {(kind, size) for kind in "iu" for size in (1, 2, 4, 8)}


def _array(name: str, values: np.ndarray, rows: int | None, where: str) -> np.ndarray:
    """``values`` as a C-contiguous native-endian 1-D or 2-D array VTK can wrap without a copy."""
    values = np.asarray(values)
    if values.dtype == np.bool_:
        values = values.view(np.uint8)
    if (values.dtype.kind, values.dtype.itemsize) not in _STORABLE:
        raise ValueError(f"{where} {name!r}: dtype {values.dtype} cannot be stored in a VTU file")
    if values.ndim not in (1, 2) or 0 in values.shape[1:] or (rows is not None and len(values) != rows):
        expected = "any number of" if rows is None else str(rows)
        raise ValueError(f"{where} {name!r} has shape {values.shape}, expected {expected} rows of 1 or more components")
    return np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("="))


def _checked(grid: Grid) -> dict:
    """Every array of ``grid`` in the form VTK wraps, after checking that they fit together."""
    points = np.asarray(grid.points)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise ValueError(f"points have shape {points.shape}, expected (n, 2) or (n, 3)")
    points = _with_zero_z(points) if points.shape[1] == 2 else np.ascontiguousarray(points, dtype=np.float64)
    cells = np.asarray(grid.cells)
    if cells.ndim != 2 or cells.dtype.kind not in "iu":
        raise ValueError(f"cells must be an (m, k) integer array, not {cells.dtype} of shape {cells.shape}")
    connectivity = np.ascontiguousarray(cells, dtype=np.int64).ravel()
    # An index outside the points would crash ParaView rather than be reported. Seen as
    # unsigned, a negative index is huge, so one pass checks both ends.
    if connectivity.size and connectivity.view(np.uint64).max() >= len(points):
        raise ValueError(f"cells refer to points outside 0..{len(points) - 1}")
    n_points, n_cells = len(points), len(cells)

    def field(values: str | np.ndarray, name: str) -> np.ndarray:
        if isinstance(values, str):
            return np.frombuffer(values.encode("utf-8"), dtype=np.uint8)
        return _array(name, values, None, "field data")

    return {
        "points": points,
        "connectivity": connectivity,
        "cell_size": cells.shape[1],
        "cell_type": int(grid.cell_type),
        "point_data": {n: _array(n, v, n_points, "point data") for n, v in grid.point_data.items()},
        "cell_data": {n: _array(n, v, n_cells, "cell data") for n, v in grid.cell_data.items()},
        "field_data": {n: field(v, n) for n, v in grid.field_data.items()},
    }


def _load_vtk() -> None:
    """Import the VTK modules the writer uses, or raise :class:`OutputError` saying why not.
    VTK is imported only to write (a solve that writes no VTU never loads it), so it may
    fail late: a library missing from the install, or one that cannot be mapped under an
    address-space limit (``ulimit -v``)."""
    try:
        import vtkmodules.util.misc  # noqa: F401
        import vtkmodules.util.numpy_support  # noqa: F401
        import vtkmodules.vtkCommonCore  # noqa: F401
        import vtkmodules.vtkCommonDataModel  # noqa: F401
        import vtkmodules.vtkCommonMisc  # noqa: F401
        import vtkmodules.vtkIOXML  # noqa: F401
    except ImportError as error:
        reason = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise OutputError(f"cannot load VTK, which writes the VTU files: {reason}") from None


def _vtk_grid(arrays: dict):
    """A vtkUnstructuredGrid over the numpy arrays themselves (no copies)."""
    _load_vtk()
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkUnstructuredGrid

    def wrap(name: str, values: np.ndarray):
        array = numpy_to_vtk(values, deep=False)
        array.SetName(name)
        return array

    grid = vtkUnstructuredGrid()
    points = vtkPoints()
    points.SetData(wrap("Points", arrays["points"]))
    grid.SetPoints(points)
    cells = vtkCellArray()
    # Cells of one size: VTK keeps the offsets implicit and the cell types as one constant.
    if not cells.SetData(arrays["cell_size"], numpy_to_vtkIdTypeArray(arrays["connectivity"], deep=False)):
        raise ValueError("VTK rejected the cells")
    grid.SetCells(arrays["cell_type"], cells)
    for where, data in (("point_data", grid.GetPointData()), ("cell_data", grid.GetCellData()),
                        ("field_data", grid.GetFieldData())):
        for name, values in arrays[where].items():
            data.AddArray(wrap(name, values))
    return grid


def _vtk_write(grid, path: Path) -> None:
    """Write the vtkUnstructuredGrid ``grid`` to ``path``; VTK's failures become :class:`OSError`."""
    from vtkmodules.util.misc import calldata_type
    from vtkmodules.util.vtkConstants import VTK_STRING
    from vtkmodules.vtkCommonCore import vtkCommand
    from vtkmodules.vtkCommonMisc import vtkErrorCode
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

    writer = vtkXMLUnstructuredGridWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(grid)
    writer.SetDataModeToAppended()
    # Base64: meshio turns a raw appended section into base64 itself, rewriting the offsets
    # in place, and mistakes a rewritten offset for a later array's (files that VTK and
    # ParaView read unharmed lost their point data in meshio, depending on string lengths).
    writer.EncodeAppendedDataOn()
    writer.SetCompressorTypeToNone()
    writer.SetHeaderTypeToUInt64()
    writer.SetIdTypeToInt64()
    writer.SetByteOrderToLittleEndian()
    # Uncompressed data is copied to the file in blocks of this size: fewer, larger writes.
    writer.SetBlockSize(1 << 20)
    errors: list[str] = []

    @calldata_type(VTK_STRING)
    def keep(caller, event, message):
        errors.append(str(message))

    # With an observer VTK hands its errors here instead of printing them on stderr.
    writer.AddObserver(vtkCommand.ErrorEvent, keep)
    writer.GetExecutive().AddObserver(vtkCommand.ErrorEvent, keep)
    written = writer.Write()
    code = writer.GetErrorCode()
    if written and code == vtkErrorCode.NoError and not errors:
        return
    # VTK keeps the errno of a failed system call as its error code.
    if 0 < code < vtkErrorCode.FirstVTKErrorCode:
        raise OSError(code, os.strerror(code))
    if code == vtkErrorCode.OutOfDiskSpaceError:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    raise OSError(f"VTK's writer failed: {_vtk_reason(errors) or vtkErrorCode.GetStringFromErrorCode(code)}")


def _vtk_reason(errors: list[str]) -> str:
    """The writer's own error messages, without VTK's source location and object address."""
    reasons = []
    for error in errors:
        lines = error.strip().splitlines()
        text = re.sub(r"^\w+ \(0x[0-9a-fA-F]+\): ", "", lines[1] if len(lines) > 1 else lines[0] if lines else "")
        if text and not text.startswith("Algorithm "):  # the pipeline's "returned failure" repeats it
            reasons.append(text)
    return "; ".join(reasons)


def _write(path: Path, vtk_grid) -> Path:
    with atomic_path(path) as temp:
        _vtk_write(vtk_grid, temp)
    return path


def write_grid(path: Path | str, grid: Grid) -> Path:
    """Write ``grid`` to ``path`` as a VTU file, atomically.

    The package's one VTU writer: VTK's ``vtkXMLUnstructuredGridWriter`` with raw
    appended binary data, no compression, UInt64 byte counts (no size limit), Int64
    cell connectivity and offsets, little endian. Points are Float64; each data array
    keeps its name, dtype and component count. VTK writes into a temporary file next
    to ``path``, which then replaces ``path`` (see
    :func:`contactfem.io.atomic.atomic_path`); the numpy arrays are handed to VTK
    without copies where their dtype and layout allow.

    Parameters
    ----------
    path : Path or str
        The file to create or replace; its directory must exist.
    grid : Grid

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        If the arrays do not fit together (row counts, cell indices) or have a dtype
        a VTU file cannot hold; nothing is written then.
    OutputError
        If the file cannot be written.
    """
    return _write(Path(path), _vtk_grid(_checked(grid)))


def write_vtu(solution: Solution, directory: Path | str, metadata: dict[str, str] | None = None) -> list[Path]:
    """Write the solution for ParaView: ``solution.vtu``, ``contact.vtu``, ``solution.pvd``.

    Each file is written atomically (see :func:`contactfem.io.atomic.atomic_path`); all
    arrays are built before the first file is touched, so an error in the data leaves
    the directory as it was. ``directory`` is created if missing. Both VTU files are
    written by :func:`write_grid`.

    ``solution.vtu`` (VTK XML, base64 appended data, UInt64 byte counts)
        Triangle cells; points with z = 0. Point data ``displacement`` (n, 3) with
        z = 0, so that Warp By Vector works. Cell data ``stress`` (n_tri, 6), a
        symmetric tensor in VTK's order xx, yy, zz, xy, yz, xz (yz = xz = 0), and the
        scalars ``stress_xx``, ``stress_yy``, ``stress_xy``, ``stress_zz``,
        ``von_mises``, then every entry of ``solution.cell_fields`` (e.g.
        ``error_indicator``) with its own dtype. Field data: one array per
        ``metadata`` entry, its value's UTF-8 bytes as UInt8.
    ``contact.vtu``
        The contact boundary ΓC as line cells over the nodes of its edges only,
        renumbered. Point data ``mesh_node`` (int64, index in the full mesh),
        ``contact_pressure`` (the method's multiplier), ``nodal_force``,
        ``normal_displacement``, ``gap``, ``active`` (uint8 0/1), ``contact_node``
        (uint8, 1 at contact nodes) and ``displacement`` (3 columns, z = 0). Nodes of
        ΓC that are not contact nodes (Dirichlet corners, clamped) carry 0 in every
        contact array, including ``gap`` and ``active``; no NaN is written. Field data:
        the same ``metadata`` as ``solution.vtu``.
    ``solution.pvd``
        A collection with both files as parts 0 (``body``) and 1 (``contact``) of
        time step 0, so that ParaView opens them together.

    Parameters
    ----------
    solution : Solution
    directory : Path or str
        Where to write the three files.
    metadata : dict of str to str, optional
        Written as field data of ``solution.vtu`` and ``contact.vtu``, e.g. method,
        case title, case hash, units, package version.

    Returns
    -------
    list of Path
        The written files, in the order above.

    Raises
    ------
    OutputError
        If the directory cannot be created or a file cannot be written, or if the
        solution has no contact edges (a VTU needs at least one cell).
    ValueError
        If a cell field has the wrong length or a built-in array's name, or a metadata
        value is not a string.
    """
    directory = Path(directory)
    grids = [_vtk_grid(_checked(grid)) for grid in solution_grids(solution, metadata)]
    ensure_directory(directory)

    paths = [directory / SOLUTION_VTU, directory / CONTACT_VTU, directory / COLLECTION_PVD]
    for path, vtk_grid in zip(paths, grids):
        _write(path, vtk_grid)
    atomic_write_text(
        paths[2], _collection_xml([("body", SOLUTION_VTU), ("contact", CONTACT_VTU)])
    )
    return paths
