"""The HDF5 archive of a solved case; the docstring of this module is the reference layout.

Layout, schema version 3 (version 2 stored the stress as (n_tri, 4) in the order
xx yy xy zz and had no exact pressure; version 1 lacked ``/contact/abscissa`` and the
obstacle)::

    /                      attrs: format = "contactfem-solution", schema_version = 3 (int),
                                  method ("positive" | "standard"), case_hash,
                                  plus the caller's ``attributes`` (contactfem writes
                                  contactfem_version, title, case_file, plane, backend and
                                  the case's units: length_unit, force_unit, stress_unit)
    /case                  scalar UTF-8 string: the case file text
    /mesh/points           (n, 2) float64
    /mesh/triangles        (n_tri, 3) int64, counter-clockwise
    /mesh/boundary_edges   (n_be, 2) int64, body on the left
    /mesh/edge_parts       (n_be,) int64, index into part_names
    /mesh/edge_curves      (n_be,) int64, index into /mesh/curves, -1 if straight
    /mesh/curves           (n_curves, 3) float64: center x, center y, radius
    /mesh                  attrs: part_names (list of str)
    /fields/displacement   (n, 2) float64
    /fields/stress         (n_tri, 6) float64, attrs: components = "xx yy zz xy yz xz"
                           (VTK's symmetric tensor order, as in solution.vtu and
                           solution.xdmf; yz = xz = 0, zz = 0 in plane stress)
    /fields/von_mises      (n_tri,) float64
    /contact/nodes         (m,) int64 mesh node indices, sorted along ΓC
    /contact/edges         (k, 2) int64 mesh node indices
    /contact/multiplier    (m,) float64 (λh or θh)
    /contact/nodal_force   (m,) float64
    /contact/normal_displacement (m,) float64
    /contact/gap           (m,) float64
    /contact/active        (m,) uint8, 0/1
    /contact/abscissa      (m,) float64, position of each node along the obstacle
                           (coordinate along the tangent t = (−n_y, n_x))
    /contact/exact_pressure (m,) float64, only when the case has an exact solution: its
                           contact pressure −σ_nn at the contact nodes (NaN where the
                           exact stress is not finite)
    /contact/normals       (m, 2) float64, a curved obstacle only (circle, polyline,
                           profile): its unit normal at each node's closest point
    /contact/obstacle_points (m, 2) float64, a curved obstacle only: each node's closest
                           point on it (reference configuration); gap = (q − x)·n there,
                           and the abscissa is the arc length of q along the obstacle
    /contact/obstacle_vertices (v, 2) float64, a curved obstacle only: its surface as a
                           polyline (a circle sampled along its arc), to draw it
    /contact               attrs: obstacle_point (2,), obstacle_normal (2,) float64: the
                                  flat obstacle {p : (p − point)·normal ≥ 0} (a curved
                                  one's center or first vertex, and its mean normal); and
                                  obstacle_ends (2, 2) float64 for a finite obstacle (a
                                  segment between those points), absent for an infinite one;
                                  obstacle_shift (2,) float64 for a moving obstacle: how far
                                  it went from where the other attributes place it
    /newton/<key>          (n_iterations,) one dataset per key of Solution.newton

Every dataset is stored contiguous and uncompressed: writing and reading then cost no
more than the copy itself (gzip level 1 took several seconds for a 2 M triangle mesh),
and any HDF5 reader can open the file without filter plugins. A solve on a distributed mesh
writes the same layout rank after rank (:func:`create_piece_archive`,
:func:`write_piece_slices`): its nodes are then in PETSc's order (each rank's owned nodes one
block of rows) and its triangles in rank order, the same mesh as a serial run's up to those
two permutations. Readers must check
``format`` and ``schema_version``; :func:`read_hdf5` checks everything else as well
(:data:`SOLUTION_LAYOUT`), since a results directory is untrusted input.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from contactfem.io.archive import Array, Attribute, Layout, Series, TextData, read_hdf5_file
from contactfem.io.atomic import atomic_path, ensure_directory
from contactfem.result import Solution

__all__ = ["FORMAT", "SCHEMA_VERSION", "SOLUTION_H5", "SOLUTION_LAYOUT", "STRESS_COMPONENTS", "PieceShapes",
           "create_piece_archive", "read_hdf5", "vtk_stress", "write_hdf5", "write_piece_slices"]

#: The archive's file name in a result directory.
SOLUTION_H5 = "solution.h5"
FORMAT = "contactfem-solution"
SCHEMA_VERSION = 3
#: The stress columns as stored (VTK's symmetric tensor order).
STRESS_COMPONENTS = ("xx", "yy", "zz", "xy", "yz", "xz")
_RESERVED_ATTRS = ("format", "schema_version", "method", "case_hash")
_ATTR_TYPES = (str, int, float, np.integer, np.floating, np.bool_)
#: The stored case text is read back up to this size, a case file's own limit
#: (contactfem.case.limits.MAX_CASE_BYTES).
MAX_CASE_TEXT_BYTES = 1 << 20


def _dataset(group: Any, name: str, data: np.ndarray, dtype: Any) -> Any:
    # No copy when the array already has the dtype and C layout (the usual case).
    array = np.ascontiguousarray(data, dtype=dtype)
    return group.create_dataset(name, data=array)


def vtk_stress(stress: np.ndarray) -> np.ndarray:
    """A solution's stress (n_tri, 4), columns xx yy xy zz -> (n_tri, 6) in the order
    :data:`STRESS_COMPONENTS` (xx yy zz xy yz xz, yz = xz = 0)."""
    xx, yy, xy, zz = np.asarray(stress, dtype=np.float64).T
    zero = np.zeros(len(xx))
    return np.column_stack([xx, yy, zz, xy, zero, zero])


def _check_attributes(attributes: dict[str, str | int | float]) -> None:
    for key, value in attributes.items():
        if key in _RESERVED_ATTRS:
            raise ValueError(f"attribute {key!r} is set by write_hdf5 itself")
        if not isinstance(value, _ATTR_TYPES):
            raise TypeError(
                f"attribute {key!r} must be str, int or float, not {type(value).__name__}"
            )


def write_hdf5(
    solution: Solution,
    path: Path | str,
    *,
    case_text: str,
    case_hash: str,
    attributes: dict[str, str | int | float],
    exact_pressure: np.ndarray | None = None,
) -> Path:
    """Write the whole solution and its case file to one HDF5 file, atomically.

    See the module docstring for the layout. The parent directory is created if
    missing; an existing file at ``path`` is replaced only once the new one is
    complete.

    Parameters
    ----------
    solution : Solution
    path : Path or str
        The file to write (conventionally ``solution.h5``).
    case_text : str
        The case file exactly as read, stored so the result can be reproduced.
    case_hash : str
        Hash of the case (as computed by the caller), stored as a root attribute.
    attributes : dict of str to str, int or float
        Further root attributes (package version, plane, backend, units...).
    exact_pressure : (m,) ndarray, optional
        The exact contact pressure at the contact nodes, when the case has an exact
        solution: stored as ``/contact/exact_pressure``.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        If ``attributes`` uses a reserved name (format, schema_version, method,
        case_hash) or a Newton key cannot be a dataset name.
    TypeError
        If an attribute value is not a str, int or float.
    OutputError
        If the file cannot be written.
    """
    import h5py

    path = Path(path)
    _check_attributes(attributes)
    for key in solution.newton:
        if not key or "/" in key or key == "attrs":
            # "attrs" would collide with the attribute entry of read_hdf5's dicts.
            raise ValueError(f"Newton history key {key!r} cannot be an HDF5 dataset name")
    ensure_directory(path.parent)
    with atomic_path(path) as temp:
        with h5py.File(temp, "w") as f:
            _write_archive(f, solution, case_text=case_text, case_hash=case_hash, attributes=attributes,
                           exact_pressure=exact_pressure)
    return path


@dataclass(frozen=True, eq=False)
class PieceShapes:
    """A result kept in pieces, for :func:`create_piece_archive`: the whole mesh's counts and
    the whole mesh's number (row of /mesh/points) of each node of the boundary mesh."""

    n_points: int
    n_triangles: int
    numbers: np.ndarray


def create_piece_archive(solution: Solution, path: Path | str, pieces: PieceShapes, *, case_text: str,
                         case_hash: str, attributes: dict[str, str | int | float],
                         exact_pressure: np.ndarray | None = None) -> Path:
    """The archive of a result kept in pieces, but for the body: the layout of :func:`write_hdf5`
    with /mesh/points, /mesh/triangles and /fields/* created at the whole mesh's shapes, to be
    filled by :func:`write_piece_slices` (rank after rank: no parallel HDF5). ``solution`` holds
    the boundary mesh (its nodes numbered by ``pieces.numbers`` in the file) and the contact
    fields. Written in place: the caller's staging directory makes the result appear whole or not."""
    import h5py

    path = Path(path)
    _check_attributes(attributes)
    with h5py.File(path, "w") as f:
        _write_archive(f, solution, case_text=case_text, case_hash=case_hash, attributes=attributes,
                       exact_pressure=exact_pressure, pieces=pieces)
    return path


def write_piece_slices(path: Path | str, nodes: tuple[int, int], points: np.ndarray, displacement: np.ndarray,
                       triangles_from: int, triangles: np.ndarray, stress: np.ndarray, von_mises: np.ndarray) -> None:
    """One piece's rows of an archive made by :func:`create_piece_archive`: its owned nodes'
    points and displacements at rows [nodes[0], nodes[1]), its triangles (whole-mesh node
    numbers), stresses (n_tri, 4: xx yy xy zz) and von Mises from row ``triangles_from``."""
    import h5py

    first, last = nodes
    end = triangles_from + len(triangles)
    with h5py.File(Path(path), "r+") as f:
        f["mesh/points"][first:last] = np.asarray(points, dtype=np.float64)
        f["fields/displacement"][first:last] = np.asarray(displacement, dtype=np.float64)
        f["mesh/triangles"][triangles_from:end] = np.asarray(triangles, dtype=np.int64)
        f["fields/stress"][triangles_from:end] = vtk_stress(stress)
        f["fields/von_mises"][triangles_from:end] = np.asarray(von_mises, dtype=np.float64)


def _write_archive(f: Any, solution: Solution, *, case_text: str, case_hash: str, attributes: dict,
                   exact_pressure: np.ndarray | None, pieces: "PieceShapes | None" = None) -> None:
    """Everything :func:`write_hdf5` stores, into the open file ``f``; with ``pieces``, the
    body's datasets (points, triangles and their fields) are created at the whole mesh's shapes
    and left for the ranks to fill (:func:`write_piece_slices`), and ``solution`` holds the
    boundary mesh, whose node indices become the whole mesh's (``pieces.numbers``)."""
    import h5py

    mesh = solution.mesh
    contact = solution.contact
    curves = np.array(
        [[c.center[0], c.center[1], c.radius] for c in mesh.curves], dtype=np.float64
    ).reshape(-1, 3)
    numbers = (lambda nodes: np.asarray(nodes)) if pieces is None else (lambda nodes: pieces.numbers[nodes])

    def body(group: Any, name: str, data: Any, dtype: Any, shape: tuple[int, ...]) -> Any:
        if pieces is None:
            return _dataset(group, name, data() if callable(data) else data, dtype)
        return group.create_dataset(name, shape=shape, dtype=dtype)

    f.attrs["format"] = FORMAT
    f.attrs["schema_version"] = np.int64(SCHEMA_VERSION)
    f.attrs["method"] = solution.method
    f.attrs["case_hash"] = case_hash
    for key, value in attributes.items():
        f.attrs[key] = value

    f.create_dataset("case", data=case_text, dtype=h5py.string_dtype("utf-8"))

    g = f.create_group("mesh")
    body(g, "points", mesh.points, np.float64, (pieces and pieces.n_points, 2))
    body(g, "triangles", mesh.triangles, np.int64, (pieces and pieces.n_triangles, 3))
    _dataset(g, "boundary_edges", numbers(np.reshape(mesh.boundary_edges, (-1, 2))), np.int64)
    _dataset(g, "edge_parts", mesh.edge_parts, np.int64)
    _dataset(g, "edge_curves", mesh.edge_curves, np.int64)
    _dataset(g, "curves", curves, np.float64)
    g.attrs.create(
        "part_names", list(mesh.part_names), dtype=h5py.string_dtype("utf-8")
    )

    g = f.create_group("fields")
    body(g, "displacement", solution.displacement, np.float64, (pieces and pieces.n_points, 2))
    stress_shape = (pieces and pieces.n_triangles, len(STRESS_COMPONENTS))
    body(g, "stress", lambda: vtk_stress(solution.stress), np.float64, stress_shape).attrs["components"] = (
        " ".join(STRESS_COMPONENTS)
    )
    body(g, "von_mises", solution.von_mises, np.float64, (pieces and pieces.n_triangles,))

    g = f.create_group("contact")
    _dataset(g, "nodes", numbers(contact.nodes), np.int64)
    _dataset(g, "edges", numbers(np.reshape(contact.edges, (-1, 2))), np.int64)
    _dataset(g, "multiplier", contact.multiplier, np.float64)
    _dataset(g, "nodal_force", contact.nodal_force, np.float64)
    _dataset(g, "normal_displacement", contact.normal_displacement, np.float64)
    _dataset(g, "gap", contact.gap, np.float64)
    _dataset(g, "active", np.asarray(contact.active, dtype=bool), np.uint8)
    _dataset(g, "abscissa", contact.abscissa, np.float64)
    if exact_pressure is not None:
        _dataset(g, "exact_pressure", exact_pressure, np.float64)
    if contact.normals is not None:
        _dataset(g, "normals", np.reshape(contact.normals, (-1, 2)), np.float64)
        _dataset(g, "obstacle_points", np.reshape(contact.obstacle_points, (-1, 2)), np.float64)
        _dataset(g, "obstacle_vertices", np.reshape(contact.obstacle_outline, (-1, 2)), np.float64)
    g.attrs["obstacle_point"] = np.asarray(contact.obstacle_point, dtype=np.float64)
    g.attrs["obstacle_normal"] = np.asarray(contact.obstacle_normal, dtype=np.float64)
    if contact.obstacle_ends is not None:
        g.attrs["obstacle_ends"] = np.asarray(contact.obstacle_ends, dtype=np.float64)
    if contact.obstacle_shift is not None:
        g.attrs["obstacle_shift"] = np.asarray(contact.obstacle_shift, dtype=np.float64)

    g = f.create_group("newton")
    for key, values in solution.newton.items():
        # The history keeps its own dtypes (counts are integers, residuals floats).
        _dataset(g, key, values, None)


def _triangles_turn_left(data: dict) -> tuple[str, str] | None:
    """Every triangle counter-clockwise, of positive area (a mesh contactfem solved on)."""
    points, triangles = data["mesh"]["points"], data["mesh"]["triangles"]
    a, b, c = points[triangles[:, 0]], points[triangles[:, 1]], points[triangles[:, 2]]
    twice_area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    flat = ~(twice_area > 0)
    if flat.any():
        first = int(np.flatnonzero(flat)[0])
        return "/mesh/triangles", (f"row {first} {triangles[first].tolist()} has area {0.5 * twice_area[first]:.3g}; "
                                   "expected counter-clockwise triangles of positive area")
    return None


def _contact_on_the_obstacle(data: dict) -> tuple[str, str] | None:
    """The stored abscissae and initial gaps are those of the contact nodes' points against
    the stored obstacle (files of schema 2 on): s = x·t and g0 = (p − x)·n."""
    contact = data["contact"]
    attrs = contact["attrs"]
    if "abscissa" not in contact or "obstacle_normal" not in attrs:
        return None
    if "normals" in contact or "obstacle_points" in contact:
        return _contact_on_curved(data)
    x = data["mesh"]["points"][contact["nodes"]]
    point, normal = np.asarray(attrs["obstacle_point"]), np.asarray(attrs["obstacle_normal"])
    tangent = np.array([-normal[1], normal[0]])
    scale = max(float(np.abs(data["mesh"]["points"]).max()), float(np.abs(point).max()), 1e-300)
    for name, stored, expected, formula in (("abscissa", contact["abscissa"], x @ tangent, "x·t"),
                                            ("gap", contact["gap"], (point - x) @ normal, "(p − x)·n")):
        off = np.abs(stored - expected) > 1e-8 * scale
        if off.any():
            first = int(np.flatnonzero(off)[0])
            return f"/contact/{name}", (f"holds {stored[first]:.6g} at row {first} where the node's point and the "
                                        f"obstacle give {expected[first]:.6g}; expected {formula} of each contact node")
    return None


def _contact_on_curved(data: dict) -> tuple[str, str] | None:
    """A curved obstacle's stored normals are unit vectors and the gaps those of the nodes'
    closest points: g0 = (q − x)·n (the gap stored is the final one, shifted along the
    motion when the obstacle moves: only its bound |g0| ≤ |q − x| holds then)."""
    contact = data["contact"]
    for name in ("normals", "obstacle_points", "obstacle_vertices"):
        if name not in contact:
            return f"/contact/{name}", "missing; expected normals, obstacle_points and obstacle_vertices together"
    normals = contact["normals"]
    length = np.hypot(normals[:, 0], normals[:, 1])
    off = np.abs(length - 1.0) > 1e-9
    if off.any():
        first = int(np.flatnonzero(off)[0])
        return "/contact/normals", f"row {first} has length {length[first]:.6g}; expected unit normals"
    if len(contact["obstacle_vertices"]) < 2:
        return "/contact/obstacle_vertices", "expected at least 2 vertices"
    return None


#: The layout :func:`read_hdf5` checks a file against (the module docstring in code). Named
#: sizes: n points, n_tri triangles, n_be boundary edges, n_curves curves, parts part names,
#: m contact nodes, k contact edges.
SOLUTION_LAYOUT = Layout(
    format=FORMAT,
    newest=SCHEMA_VERSION,
    sizes={"n": "the rows of /mesh/points", "n_tri": "the rows of /mesh/triangles",
           "n_be": "the rows of /mesh/boundary_edges", "n_curves": "the rows of /mesh/curves",
           "parts": "the names in /mesh/@part_names", "m": "the entries of /contact/nodes",
           "k": "the rows of /contact/edges", "n_ov": "the rows of /contact/obstacle_vertices"},
    arrays=(
        Array("/mesh/points", "f", ("n", 2), "float64", finite=True, at_least=3),
        Array("/mesh/triangles", "iu", ("n_tri", 3), "int64", index_of="n", at_least=1),
        Array("/mesh/boundary_edges", "iu", ("n_be", 2), "int64", index_of="n"),
        Array("/mesh/edge_parts", "iu", ("n_be",), "int64", index_of="parts"),
        Array("/mesh/curves", "f", ("n_curves", 3), "float64", finite=True),
        Array("/mesh/edge_curves", "iu", ("n_be",), "int64", index_of="n_curves", lowest=-1),
        Array("/fields/displacement", "f", ("n", 2), "float64", finite=True),
        Array("/fields/stress", "f", ("n_tri", len(STRESS_COMPONENTS)), "float64", finite=True, since=3),
        Array("/fields/stress", "f", ("n_tri", 4), "float64", finite=True, until=2),
        Array("/fields/von_mises", "f", ("n_tri",), "float64", finite=True),
        Array("/contact/nodes", "iu", ("m",), "int64", index_of="n"),
        Array("/contact/edges", "iu", ("k", 2), "int64", index_of="n"),
        Array("/contact/multiplier", "f", ("m",), "float64", finite=True),
        Array("/contact/nodal_force", "f", ("m",), "float64", finite=True),
        Array("/contact/normal_displacement", "f", ("m",), "float64", finite=True),
        Array("/contact/gap", "f", ("m",), "float64", finite=True),
        Array("/contact/active", "iub", ("m",), "uint8", flags=True),
        Array("/contact/abscissa", "f", ("m",), "float64", finite=True, since=2),
        # NaN where the exact stress is not finite.
        Array("/contact/exact_pressure", "f", ("m",), "float64", since=3, optional=True),
        Array("/contact/normals", "f", ("m", 2), "float64", finite=True, since=3, optional=True),
        Array("/contact/obstacle_points", "f", ("m", 2), "float64", finite=True, since=3, optional=True),
        Array("/contact/obstacle_vertices", "f", ("n_ov", 2), "float64", finite=True, since=3, optional=True),
    ),
    texts=(TextData("/case", MAX_CASE_TEXT_BYTES),),
    attributes=(
        Attribute("/", "method", "text", choices=("positive", "standard")),
        Attribute("/", "case_hash", "text"),
        Attribute("/mesh", "part_names", "texts", size="parts"),
        Attribute("/contact", "obstacle_point", "vector", shape=(2,), since=2),
        Attribute("/contact", "obstacle_normal", "vector", shape=(2,), unit=True, since=2),
        Attribute("/contact", "obstacle_ends", "vector", shape=(2, 2), since=2, optional=True),
        Attribute("/contact", "obstacle_shift", "vector", shape=(2,), since=3, optional=True),
    ),
    series=(Series("/newton", max_length=1_000_000),),
    rules=(_triangles_turn_left, _contact_on_the_obstacle),
)


def read_hdf5(path: Path | str) -> dict[str, Any]:
    """Read a file written by :func:`write_hdf5` back into nested dicts, as untrusted input.

    Everything is checked against :data:`SOLUTION_LAYOUT` before it is returned (see
    :mod:`contactfem.io.archive`): the format and schema version; each dataset's
    presence (no links followed), dtype, shape and storage, and the total declared size
    against the file's, before any data is read; then index ranges, finiteness and flags;
    attributes by name, strings bounded. Root attributes other than the layout's are
    returned when they are scalars; other groups, datasets and attributes are not read.

    Parameters
    ----------
    path : Path or str

    Returns
    -------
    dict
        One entry per dataset or group, nested by group: datasets as numpy arrays
        (float64, int64, ``/contact/active`` uint8, ``/newton`` as stored), the ``case``
        string as str. Every dict has an ``"attrs"`` entry with that object's attributes
        as plain Python values (str, int, float, list), e.g. ``data["attrs"]["method"]``,
        ``data["mesh"]["attrs"]["part_names"]``, ``data["fields"]["displacement"]``.

    Raises
    ------
    ArchiveError
        If the file cannot be opened, is not a contactfem solution file, was written with
        a newer schema than this version reads, or anything in it is not as the layout
        says: one line naming the file, the dataset or attribute and what was expected.
    """
    return read_hdf5_file(path, SOLUTION_LAYOUT, f"a {FORMAT} file (written by contactfem solve)")
