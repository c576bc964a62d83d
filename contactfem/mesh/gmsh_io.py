"""Reading 2D linear triangle meshes with named boundary lines from Gmsh .msh files."""

from __future__ import annotations

import contextlib
import io
import os
from pathlib import Path

import meshio
import meshio.gmsh
import numpy as np

from contactfem.errors import MeshError
from contactfem.mesh.core import Mesh
from contactfem.mesh.quality import check_body, check_mesh
from contactfem.mesh.refine import _undirected_keys, boundary_edges

__all__ = ["read_gmsh", "write_gmsh", "UNNAMED_PART"]

#: Part name of boundary edges that no physical line covers.
UNNAMED_PART = "unnamed"
#: Cell types that may accompany the triangles (points and boundary lines).
_ACCEPTED_CELLS = {"vertex", "line", "triangle"}
#: A z coordinate below this times the mesh extent counts as zero.
_FLAT_TOLERANCE = 1e-12


def _physical_names(mesh: meshio.Mesh) -> dict[int, str]:
    """Names of the one-dimensional physical groups, by physical tag."""
    names: dict[int, str] = {}
    for name, value in (mesh.field_data or {}).items():
        tag_dim = np.asarray(value).reshape(-1)
        if tag_dim.size >= 2 and int(tag_dim[1]) == 1:
            names[int(tag_dim[0])] = str(name)
    return names


def _named_lines(mesh: meshio.Mesh) -> tuple[np.ndarray, np.ndarray]:
    """All line cells that carry a physical tag.

    Returns
    -------
    lines : (n_lines, 2) int64
        Node indices in the file's numbering.
    tags : (n_lines,) int64
        Physical tag of each line.
    """
    physical = mesh.cell_data.get("gmsh:physical")
    lines, tags = [], []
    for block_index, block in enumerate(mesh.cells):
        if block.type != "line" or physical is None:
            continue
        lines.append(np.asarray(block.data, dtype=np.int64).reshape(-1, 2))
        tags.append(np.asarray(physical[block_index], dtype=np.int64).reshape(-1))
    if not lines:
        return np.empty((0, 2), dtype=np.int64), np.empty(0, dtype=np.int64)
    return np.concatenate(lines), np.concatenate(tags)


def read_gmsh(path: str | os.PathLike[str]) -> Mesh:
    """Read a 2D mesh of linear triangles and its named boundary lines from a Gmsh file.

    Parameters
    ----------
    path : str or path-like
        A Gmsh ``.msh`` file (any version meshio reads, ASCII or binary).

    Returns
    -------
    Mesh
        The file's triangles, reoriented counter-clockwise, on the nodes they use
        (renumbered in file order, z dropped). A boundary edge covered by a line
        cell of a one-dimensional physical group gets that group's name (its tag as
        a string if the group has no name); other boundary edges get the part
        ``"unnamed"``. ``part_names`` lists physical groups by tag, then "unnamed";
        only parts with boundary edges appear. Named lines inside the domain are
        ignored.

    Raises
    ------
    MeshError
        If the file is missing or unreadable, has no triangles, has quadrilateral,
        higher-order or 3D cells, has points off the plane z = 0, or is not a valid
        mesh (see :func:`~contactfem.mesh.quality.check_mesh`).
    """
    path = Path(path)
    raw = _read_raw(path)
    _check_cells(raw, path)
    points, triangles, renumber = _planar_triangles(raw, path)
    edges = boundary_edges(triangles)
    edge_parts, part_names = _edge_parts(raw, edges, renumber, len(points))
    mesh = Mesh(
        points=points,
        triangles=triangles,
        boundary_edges=edges,
        edge_parts=edge_parts,
        part_names=part_names,
    )
    try:
        check_mesh(mesh)
        check_body(mesh)
    except MeshError as exc:
        raise MeshError(f"mesh {path}: {exc}") from None
    return mesh


def _read_raw(path: Path) -> meshio.Mesh:
    """The file as meshio reads it; a missing, irregular or unparsable file is a :class:`MeshError`."""
    if not path.exists():
        raise MeshError(f"cannot read mesh {path}: no such file")
    if not path.is_file():
        raise MeshError(f"cannot read mesh {path}: not a regular file")
    try:
        # The Gmsh reader itself, not meshio.read: on a ReadError meshio.read prints
        # the error and calls sys.exit(1).
        # meshio prints its warnings ("$MeshFormat not closed ...") on stderr: keep them
        # off, the refusal below or the checks after it say what is wrong in one line.
        with contextlib.redirect_stderr(io.StringIO()):
            return meshio.gmsh.read(path)
    except Exception as exc:  # noqa: BLE001 - meshio's parsers raise almost anything on bad input
        text = str(exc).strip()
        reason = text.splitlines()[0] if text else "not a Gmsh .msh file (no valid $MeshFormat header)"
        if isinstance(exc, KeyError) and exc.args:
            # A lookup of a tag the file never declared (an element's entity missing from
            # $Entities): the bare key alone ("np.int32(1)") says nothing.
            key = exc.args[0]
            reason = f"it refers to entity or tag {key.item() if hasattr(key, 'item') else key!r}, which it does not define"
        raise MeshError(f"cannot read mesh {path}: {reason} ({type(exc).__name__})") from exc


def _check_cells(raw: meshio.Mesh, path: Path) -> None:
    """Refuse cells other than points, lines and triangles, and a file without triangles."""
    found: dict[str, int] = {}
    for block in raw.cells:
        found[block.type] = found.get(block.type, 0) + len(block.data)
    summary = ", ".join(f"{count} {kind}" for kind, count in found.items()) or "no cells"
    unsupported = sorted(set(found) - _ACCEPTED_CELLS)
    if unsupported:
        raise MeshError(
            f"mesh {path} has unsupported cells ({summary}); "
            "only linear triangles (with boundary lines) are supported"
        )
    if found.get("triangle", 0) == 0:
        raise MeshError(
            f"mesh {path} contains no triangles ({summary}); is the surface in a physical group?"
        )


def _planar_triangles(raw: meshio.Mesh, path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangles' nodes (n, 2), renumbered in file order, and the triangles (t, 3)
    counter-clockwise on them; and the new number of each file node (-1: no triangle uses it).

    Raises
    ------
    MeshError
        For points of the wrong shape, off the plane z = 0 or not finite, and for
        triangles referring to missing nodes.
    """
    points = np.asarray(raw.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"mesh {path} has points of shape {points.shape}, expected (n, 2) or (n, 3)")
    triangles = np.concatenate(
        [np.asarray(b.data, dtype=np.int64).reshape(-1, 3) for b in raw.cells if b.type == "triangle"]
    )
    if np.any(triangles < 0) or np.any(triangles >= len(points)):
        raise MeshError(f"mesh {path} has triangles referring to missing nodes")

    # Only the nodes of triangles matter: Gmsh also stores geometry points and nodes
    # of lower-dimensional entities that no element uses.
    used, triangles = np.unique(triangles, return_inverse=True)
    triangles = triangles.reshape(-1, 3)
    if points.shape[1] == 3:
        extent = float(np.max(np.abs(points[used, :2]))) if used.size else 0.0
        z = points[used, 2]
        if np.any(np.abs(z) > _FLAT_TOLERANCE * max(extent, 1.0)):
            raise MeshError(
                f"mesh {path} is not planar: z ranges over [{z.min():.6g}, {z.max():.6g}], expected 0"
            )
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    points = np.ascontiguousarray(points[used, :2])
    if not np.all(np.isfinite(points)):
        raise MeshError(f"mesh {path} has non-finite node coordinates")

    # Gmsh keeps the orientation of the CAD surface, which may be clockwise.
    corners = points[triangles]
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    flip = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    triangles[flip] = triangles[flip][:, [0, 2, 1]]
    return points, triangles, renumber


def _edge_parts(raw: meshio.Mesh, edges: np.ndarray, renumber: np.ndarray,
                n: int) -> tuple[np.ndarray, tuple[str, ...]]:
    """Each boundary edge's part (e,) and the part names: the physical group of a named line
    on it, else :data:`UNNAMED_PART`."""
    names = _physical_names(raw)
    lines, tags = _named_lines(raw)
    lines = renumber[lines] if lines.size else lines
    on_mesh = np.all(lines >= 0, axis=1)
    lines, tags = lines[on_mesh], tags[on_mesh]

    # Match lines to boundary edges by undirected key; the first line wins if an edge
    # is in several groups (the stable sort keeps file order). Gmsh tags are positive.
    edge_keys = _undirected_keys(edges, n)
    edge_tag = np.full(len(edges), -1, dtype=np.int64)
    if len(lines):
        line_keys = _undirected_keys(lines, n)
        order = np.argsort(line_keys, kind="stable")
        sorted_keys = line_keys[order]
        slot = np.minimum(np.searchsorted(sorted_keys, edge_keys), len(sorted_keys) - 1)
        hit = sorted_keys[slot] == edge_keys
        edge_tag[hit] = tags[order][slot[hit]]
    named = edge_tag >= 0

    present = np.unique(edge_tag[named])
    part_names = [names.get(int(t), str(int(t))) for t in present]
    # Two groups with the same name (or a name equal to another's tag) share a part.
    distinct = list(dict.fromkeys(part_names))
    tag_part = {int(t): distinct.index(name) for t, name in zip(present, part_names)}
    edge_parts = np.empty(len(edges), dtype=np.int64)
    if present.size:
        lookup = np.array([tag_part[int(t)] for t in present], dtype=np.int64)
        edge_parts[named] = lookup[np.searchsorted(present, edge_tag[named])]
    if not np.all(named):
        if UNNAMED_PART not in distinct:
            distinct.append(UNNAMED_PART)
        edge_parts[~named] = distinct.index(UNNAMED_PART)
    return edge_parts, tuple(distinct)


def write_gmsh(mesh: Mesh, path: str | os.PathLike[str]) -> Path:
    """Write ``mesh`` as a Gmsh 2.2 ASCII file that :func:`read_gmsh` reads back.

    The triangles form one physical surface; the boundary edges of each part form a
    physical line named after the part (tags 1, 2, … in the order of ``part_names``).
    """
    surface = len(mesh.part_names) + 1
    cells = [("triangle", np.asarray(mesh.triangles, dtype=np.int64))]
    physical = [np.full(mesh.n_triangles, surface)]
    field_data = {"body": np.array([surface, 2])}
    for tag, name in enumerate(mesh.part_names, start=1):
        edges = mesh.edges_of(name)
        cells.append(("line", np.asarray(edges, dtype=np.int64)))
        physical.append(np.full(len(edges), tag))
        field_data[name] = np.array([tag, 1])
    points = np.column_stack([mesh.points, np.zeros(mesh.n_points)])
    out = meshio.Mesh(points, cells, cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical},
                      field_data=field_data)
    meshio.write(path, out, file_format="gmsh22", binary=False)
    return Path(path)
