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
    /contact               attrs: obstacle_point (2,), obstacle_normal (2,) float64: the
                                  flat obstacle {p : (p − point)·normal ≥ 0}; and
                                  obstacle_ends (2, 2) float64 for a finite obstacle (a
                                  segment between those points), absent for an infinite one
    /newton/<key>          (n_iterations,) one dataset per key of Solution.newton

Every dataset is stored contiguous and uncompressed: writing and reading then cost no
more than the copy itself (gzip level 1 took several seconds for a 2 M triangle mesh),
and any HDF5 reader can open the file without filter plugins. Readers must check
``format`` and ``schema_version``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from contactfem.errors import OutputError
from contactfem.io.atomic import atomic_path, ensure_directory
from contactfem.result import Solution

__all__ = ["FORMAT", "SCHEMA_VERSION", "SOLUTION_H5", "STRESS_COMPONENTS", "read_hdf5", "vtk_stress", "write_hdf5"]

#: The archive's file name in a result directory.
SOLUTION_H5 = "solution.h5"
FORMAT = "contactfem-solution"
SCHEMA_VERSION = 3
#: The stress columns as stored (VTK's symmetric tensor order).
STRESS_COMPONENTS = ("xx", "yy", "zz", "xy", "yz", "xz")
_RESERVED_ATTRS = ("format", "schema_version", "method", "case_hash")
_ATTR_TYPES = (str, int, float, np.integer, np.floating, np.bool_)


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

    mesh = solution.mesh
    contact = solution.contact
    curves = np.array(
        [[c.center[0], c.center[1], c.radius] for c in mesh.curves], dtype=np.float64
    ).reshape(-1, 3)

    with atomic_path(path) as temp:
        with h5py.File(temp, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["schema_version"] = np.int64(SCHEMA_VERSION)
            f.attrs["method"] = solution.method
            f.attrs["case_hash"] = case_hash
            for key, value in attributes.items():
                f.attrs[key] = value

            f.create_dataset("case", data=case_text, dtype=h5py.string_dtype("utf-8"))

            g = f.create_group("mesh")
            _dataset(g, "points", mesh.points, np.float64)
            _dataset(g, "triangles", mesh.triangles, np.int64)
            _dataset(g, "boundary_edges", np.reshape(mesh.boundary_edges, (-1, 2)), np.int64)
            _dataset(g, "edge_parts", mesh.edge_parts, np.int64)
            _dataset(g, "edge_curves", mesh.edge_curves, np.int64)
            _dataset(g, "curves", curves, np.float64)
            g.attrs.create(
                "part_names", list(mesh.part_names), dtype=h5py.string_dtype("utf-8")
            )

            g = f.create_group("fields")
            _dataset(g, "displacement", solution.displacement, np.float64)
            _dataset(g, "stress", vtk_stress(solution.stress), np.float64).attrs["components"] = (
                " ".join(STRESS_COMPONENTS)
            )
            _dataset(g, "von_mises", solution.von_mises, np.float64)

            g = f.create_group("contact")
            _dataset(g, "nodes", contact.nodes, np.int64)
            _dataset(g, "edges", np.reshape(contact.edges, (-1, 2)), np.int64)
            _dataset(g, "multiplier", contact.multiplier, np.float64)
            _dataset(g, "nodal_force", contact.nodal_force, np.float64)
            _dataset(g, "normal_displacement", contact.normal_displacement, np.float64)
            _dataset(g, "gap", contact.gap, np.float64)
            _dataset(g, "active", np.asarray(contact.active, dtype=bool), np.uint8)
            _dataset(g, "abscissa", contact.abscissa, np.float64)
            if exact_pressure is not None:
                _dataset(g, "exact_pressure", exact_pressure, np.float64)
            g.attrs["obstacle_point"] = np.asarray(contact.obstacle_point, dtype=np.float64)
            g.attrs["obstacle_normal"] = np.asarray(contact.obstacle_normal, dtype=np.float64)
            if contact.obstacle_ends is not None:
                g.attrs["obstacle_ends"] = np.asarray(contact.obstacle_ends, dtype=np.float64)

            g = f.create_group("newton")
            for key, values in solution.newton.items():
                # The history keeps its own dtypes (counts are integers, residuals floats).
                _dataset(g, key, values, None)
    return path


def _attr_value(value: Any) -> Any:
    """HDF5 attribute -> plain Python value (str, int, float, bool or list)."""
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, np.ndarray):
        return [_attr_value(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _read_group(group: Any) -> dict[str, Any]:
    import h5py

    out: dict[str, Any] = {"attrs": {k: _attr_value(v) for k, v in group.attrs.items()}}
    for name, item in group.items():
        if isinstance(item, h5py.Group):
            out[name] = _read_group(item)
        elif h5py.check_string_dtype(item.dtype) is not None:
            # asstr() gives str instead of the bytes h5py 3 returns by default.
            out[name] = item.asstr()[()]
        else:
            out[name] = item[()]
    return out


def read_hdf5(path: Path | str) -> dict[str, Any]:
    """Read a file written by :func:`write_hdf5` back into nested dicts.

    Parameters
    ----------
    path : Path or str

    Returns
    -------
    dict
        One entry per dataset or group, nested by group: datasets as numpy arrays,
        string datasets (``case``) as str. Every dict has an ``"attrs"`` entry with that
        object's attributes as plain Python values (str, int, float, list of str),
        e.g. ``data["attrs"]["method"]``, ``data["mesh"]["attrs"]["part_names"]``,
        ``data["fields"]["displacement"]``.

    Raises
    ------
    OutputError
        If the file cannot be opened, is not a contactfem solution file, or was
        written with a newer schema than this version reads.
    """
    import h5py

    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            data = _read_group(f)
    except OSError as exc:
        raise OutputError(f"cannot read {path}: {exc.strerror or exc}") from exc
    attrs = data["attrs"]
    if attrs.get("format") != FORMAT:
        raise OutputError(f"cannot read {path}: not a {FORMAT} file")
    if attrs.get("schema_version", 0) > SCHEMA_VERSION:
        raise OutputError(
            f"cannot read {path}: schema version {attrs['schema_version']} is newer "
            f"than {SCHEMA_VERSION}, the one this contactfem reads"
        )
    return data
