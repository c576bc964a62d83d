"""Tests of the VTU/PVD and HDF5 writers and of atomic file replacement."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest

from contactfem.errors import ArchiveError, OutputError
from contactfem.io import (
    atomic_path,
    atomic_write_text,
    read_hdf5,
    write_hdf5,
    write_vtu,
)
from contactfem.io.atomic import TEMP_PREFIX, atomic_write_bytes
from contactfem.io.series import write_series
from contactfem.io.vtu import VTK_LINE, VTK_TRIANGLE, Grid, write_grid
from contactfem.mesh.core import Circle, Mesh
from contactfem.result import ContactFields, Solution

# 3x3 nodes on the unit square, numbered row by row from the bottom:
#   6 7 8
#   3 4 5
#   0 1 2
# ΓC is the bottom side, the left side is clamped, so node 0 is a Dirichlet corner on
# ΓC and the contact nodes are 1 and 2.
CONTACT_NODES = np.array([1, 2])
CONTACT_EDGES = np.array([[0, 1], [1, 2]])


def _grid_mesh() -> Mesh:
    x, y = np.meshgrid(np.linspace(0.0, 1.0, 3), np.linspace(0.0, 1.0, 3))
    points = np.column_stack([x.ravel(), y.ravel()])
    i, j = np.meshgrid(np.arange(2), np.arange(2))
    a = (3 * j + i).ravel()
    b, c, d = a + 1, a + 4, a + 3
    triangles = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    boundary_edges = np.array(
        [[0, 1], [1, 2], [2, 5], [5, 8], [8, 7], [7, 6], [6, 3], [3, 0]], dtype=np.int64
    )
    edge_parts = np.array([0, 0, 1, 1, 2, 2, 3, 3], dtype=np.int64)
    edge_curves = np.array([-1, -1, -1, -1, 0, 0, -1, -1], dtype=np.int64)
    return Mesh(
        points=points,
        triangles=triangles.astype(np.int64),
        boundary_edges=boundary_edges,
        edge_parts=edge_parts,
        part_names=("contact", "right", "top", "clamp"),
        edge_curves=edge_curves,
        curves=(Circle((0.5, -1.0), 2.0),),
    )


def _solution(newton: dict[str, np.ndarray] | None = None,
              cell_fields: dict[str, np.ndarray] | None = None) -> Solution:
    mesh = _grid_mesh()
    rng = np.random.default_rng(7)
    n, n_tri = mesh.n_points, mesh.n_triangles
    stress = rng.normal(size=(n_tri, 4))
    contact = ContactFields(
        nodes=CONTACT_NODES.copy(),
        edges=CONTACT_EDGES.copy(),
        multiplier=np.array([2.5, 0.0]),
        nodal_force=np.array([1.25, 0.0]),
        normal_displacement=np.array([0.1, 0.05]),
        gap=np.array([0.1, 0.1]),  # (p − x)·n of the nodes (0.5, 0) and (1, 0): read_hdf5 checks it
        active=np.array([True, False]),
        abscissa=np.array([0.5, 1.0]),
        obstacle_point=np.array([0.0, -0.1]),
        obstacle_normal=np.array([0.0, -1.0]),
    )
    if newton is None:
        newton = {
            "active": np.array([2, 1, 1]),
            "added": np.array([2, 0, 0]),
            "removed": np.array([0, 1, 0]),
            "equilibrium_residual": np.array([1.0, 1e-3, 1e-12]),
            "complementarity_residual": np.array([0.5, 1e-4, 0.0]),
        }
    return Solution(
        method="positive",
        mesh=mesh,
        displacement=rng.normal(size=(n, 2)),
        stress=stress,
        von_mises=np.abs(rng.normal(size=n_tri)),
        contact=contact,
        newton=newton,
        cell_fields=cell_fields or {},
    )


def _temporaries(directory: Path) -> list[str]:
    return [p.name for p in directory.iterdir() if p.name.startswith(TEMP_PREFIX)]


# --------------------------------------------------------------------- VTU / PVD


def test_write_vtu_returns_the_three_files(tmp_path: Path) -> None:
    paths = write_vtu(_solution(), tmp_path / "out")
    assert paths == [
        tmp_path / "out" / "solution.vtu",
        tmp_path / "out" / "contact.vtu",
        tmp_path / "out" / "solution.pvd",
    ]
    assert all(p.is_file() for p in paths)
    assert _temporaries(tmp_path / "out") == []


def test_solution_vtu_arrays(tmp_path: Path) -> None:
    solution = _solution()
    write_vtu(solution, tmp_path)
    vtu = meshio.read(tmp_path / "solution.vtu")

    assert vtu.points.shape == (9, 3)
    np.testing.assert_array_equal(vtu.points[:, :2], solution.mesh.points)
    np.testing.assert_array_equal(vtu.points[:, 2], 0.0)
    assert [block.type for block in vtu.cells] == ["triangle"]
    np.testing.assert_array_equal(vtu.cells[0].data, solution.mesh.triangles)

    u = vtu.point_data["displacement"]
    assert u.shape == (9, 3)
    np.testing.assert_array_equal(u[:, :2], solution.displacement)
    np.testing.assert_array_equal(u[:, 2], 0.0)

    s = solution.stress  # xx yy xy zz
    tensor = vtu.cell_data["stress"][0]
    assert tensor.shape == (8, 6)
    # VTK order: xx, yy, zz, xy, yz, xz
    np.testing.assert_array_equal(tensor[:, 0], s[:, 0])
    np.testing.assert_array_equal(tensor[:, 1], s[:, 1])
    np.testing.assert_array_equal(tensor[:, 2], s[:, 3])
    np.testing.assert_array_equal(tensor[:, 3], s[:, 2])
    np.testing.assert_array_equal(tensor[:, 4:], 0.0)
    for name, column in [("stress_xx", 0), ("stress_yy", 1), ("stress_xy", 2), ("stress_zz", 3)]:
        assert vtu.cell_data[name][0].shape == (8,)
        np.testing.assert_array_equal(vtu.cell_data[name][0], s[:, column])
    np.testing.assert_array_equal(vtu.cell_data["von_mises"][0], solution.von_mises)


def _vtu_header(path: Path) -> ET.Element:
    """The XML part of a VTU before its appended data."""
    data = path.read_bytes()
    return ET.fromstring(data[: data.index(b"<AppendedData")] + b"</VTKFile>")


def test_vtu_files_hold_base64_appended_data_with_64_bit_counts(tmp_path: Path) -> None:
    """Appended arrays in base64 behind UInt64 byte counts: no compressor, and no 4 GB
    limit that would force one; meshio reads the values back exactly."""
    solution = _solution()
    write_vtu(solution, tmp_path)
    for name in ["solution.vtu", "contact.vtu"]:
        root = _vtu_header(tmp_path / name)
        assert root.tag == "VTKFile" and root.get("type") == "UnstructuredGrid"
        assert root.get("header_type") == "UInt64" and root.get("compressor") is None
        assert {a.get("format") for a in root.iter("DataArray")} == {"appended"}
        assert b'<AppendedData encoding="base64">' in (tmp_path / name).read_bytes()
    data = meshio.read(tmp_path / "solution.vtu")
    np.testing.assert_array_equal(data.cells[0].data, solution.mesh.triangles)
    np.testing.assert_array_equal(data.cell_data["von_mises"][0], solution.von_mises)
    np.testing.assert_array_equal(data.cell_data["stress"][0][:, 3], solution.stress[:, 2])


def test_contact_vtu(tmp_path: Path) -> None:
    solution = _solution()
    write_vtu(solution, tmp_path)
    vtu = meshio.read(tmp_path / "contact.vtu")

    assert [block.type for block in vtu.cells] == ["line"]
    mesh_node = vtu.point_data["mesh_node"]
    assert mesh_node.dtype == np.int64
    np.testing.assert_array_equal(mesh_node, [0, 1, 2])
    # Cells refer to the renumbered points, and map back to the mesh's edges.
    np.testing.assert_array_equal(mesh_node[vtu.cells[0].data], CONTACT_EDGES)
    np.testing.assert_array_equal(vtu.points[:, :2], solution.mesh.points[[0, 1, 2]])
    np.testing.assert_array_equal(vtu.points[:, 2], 0.0)

    # Node 0 is the clamped corner: zeros; nodes 1, 2 are the contact nodes.
    expected = {
        "contact_pressure": [0.0, 2.5, 0.0],
        "nodal_force": [0.0, 1.25, 0.0],
        "normal_displacement": [0.0, 0.1, 0.05],
        "gap": [0.0, 0.1, 0.1],
        "active": [0, 1, 0],
        "contact_node": [0, 1, 1],
    }
    for name, values in expected.items():
        assert vtu.point_data[name].shape == (3,), name
        np.testing.assert_array_equal(vtu.point_data[name], values, err_msg=name)
    assert vtu.point_data["active"].dtype == np.uint8

    u = vtu.point_data["displacement"]
    assert u.shape == (3, 3)
    np.testing.assert_array_equal(u[:, :2], solution.displacement[[0, 1, 2]])
    np.testing.assert_array_equal(u[:, 2], 0.0)

    for name, values in vtu.point_data.items():
        assert np.all(np.isfinite(values)), name


def test_contact_vtu_without_edges_is_an_output_error(tmp_path: Path) -> None:
    solution = _solution()
    empty = ContactFields(
        nodes=np.zeros(0, dtype=np.int64),
        edges=np.zeros((0, 2), dtype=np.int64),
        multiplier=np.zeros(0),
        nodal_force=np.zeros(0),
        normal_displacement=np.zeros(0),
        gap=np.zeros(0),
        active=np.zeros(0, dtype=bool),
        abscissa=np.zeros(0),
        obstacle_point=np.zeros(2),
        obstacle_normal=np.array([0.0, -1.0]),
    )
    broken = Solution(
        solution.method, solution.mesh, solution.displacement, solution.stress,
        solution.von_mises, empty, solution.newton,
    )
    with pytest.raises(OutputError, match="no contact edges"):
        write_vtu(broken, tmp_path)
    assert list(tmp_path.iterdir()) == []  # nothing written at all


def test_pvd_lists_both_files(tmp_path: Path) -> None:
    write_vtu(_solution(), tmp_path)
    root = ET.parse(tmp_path / "solution.pvd").getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    datasets = root.findall("./Collection/DataSet")
    assert [(d.get("timestep"), d.get("part"), d.get("file")) for d in datasets] == [
        ("0", "0", "solution.vtu"),
        ("0", "1", "contact.vtu"),
    ]
    assert all(d.get("name") for d in datasets)
    for d in datasets:
        assert (tmp_path / d.get("file")).is_file()


def test_write_vtu_into_a_file_is_an_output_error(tmp_path: Path) -> None:
    not_a_directory = tmp_path / "plain"
    not_a_directory.write_text("x")
    with pytest.raises(OutputError, match="cannot write"):
        write_vtu(_solution(), not_a_directory)
    with pytest.raises(OutputError, match="cannot write"):
        write_vtu(_solution(), not_a_directory / "sub")
    assert not_a_directory.read_text() == "x"


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() == 0,
    reason="permissions do not stop root",
)
def test_write_vtu_into_a_read_only_directory_is_an_output_error(tmp_path: Path) -> None:
    tmp_path.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="cannot write"):
            write_vtu(_solution(), tmp_path)
    finally:
        tmp_path.chmod(0o700)


def test_failed_vtu_write_keeps_the_old_file(tmp_path: Path, monkeypatch) -> None:
    from contactfem.io import vtu

    old = b"old solution, must survive\n"
    (tmp_path / "solution.vtu").write_bytes(old)
    real_write = vtu._vtk_write

    def write_then_fail(grid, path):
        real_write(grid, path)  # a complete temporary file...
        raise RuntimeError("disk on fire")  # ...then a failure before the rename

    monkeypatch.setattr(vtu, "_vtk_write", write_then_fail)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_vtu(_solution(), tmp_path)
    assert (tmp_path / "solution.vtu").read_bytes() == old
    assert _temporaries(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["solution.vtu"]


def test_oserror_during_vtu_write_becomes_output_error(tmp_path: Path, monkeypatch) -> None:
    from contactfem.io import vtu

    old = b"old"
    (tmp_path / "solution.vtu").write_bytes(old)

    def half_write(grid, path):
        Path(path).write_bytes(b"<VTKFile trunc")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(vtu, "_vtk_write", half_write)
    with pytest.raises(OutputError, match=r"cannot write .*solution\.vtu: No space left"):
        write_vtu(_solution(), tmp_path)
    assert (tmp_path / "solution.vtu").read_bytes() == old
    assert _temporaries(tmp_path) == []


@pytest.mark.skipif(sys.platform == "win32", reason="file size limits are POSIX")
def test_vtk_writer_failure_is_an_output_error(tmp_path: Path) -> None:
    """A real failure inside VTK's writer (the file size limit is hit mid-write) is reported
    as an OutputError, silently: VTK prints nothing, and the old file and no temporary stay."""
    (tmp_path / "grid.vtu").write_bytes(b"old")
    script = textwrap.dedent(f"""
        import resource, signal
        import numpy as np
        from contactfem.errors import OutputError
        from contactfem.io.vtu import VTK_TRIANGLE, Grid, write_grid

        grid = Grid(np.random.default_rng(0).random((30000, 2)),
                    np.arange(60000).reshape(-1, 3) % 30000, VTK_TRIANGLE,
                    cell_data={{"eta": np.ones(20000)}})
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a failing write() instead of a kill
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, resource.RLIM_INFINITY))
        try:
            write_grid({str(tmp_path / "grid.vtu")!r}, grid)
        except OutputError as exc:
            print(exc)
        """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "cannot write" in run.stdout and "grid.vtu: File too large" in run.stdout
    assert "ERROR" not in run.stderr and "vtkXML" not in run.stderr  # VTK printed nothing
    assert (tmp_path / "grid.vtu").read_bytes() == b"old"
    assert _temporaries(tmp_path) == []


@pytest.mark.parametrize("blocked, message", [
    ("vtkmodules.vtkIOXML", "cannot load VTK, which writes the VTU files"),
    ("h5py", "cannot load h5py (import of h5py halted; None in sys.modules); no result was switched in"),
])
def test_a_library_that_cannot_be_loaded_is_one_line_and_nothing_is_switched_in(tmp_path: Path, blocked,
                                                                               message) -> None:
    """The writers import their libraries (VTK, h5py) only to write, so one may fail late:
    missing from the install, or unmappable under an address-space limit (``ulimit -v`` of
    1.2 GiB on a 0.85 GiB solve printed VTK's ImportError with a traceback after the solve).
    `solve` exits 1 with one line naming it, and the earlier result in the directory stays
    whole."""
    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "out"
    first = subprocess.run([sys.executable, "-m", "contactfem", "solve", str(root / "cases" / "square.yaml"),
                            "--out", str(out), "--quiet"], capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    before = {path.name: path.read_bytes() for path in out.iterdir()}
    script = textwrap.dedent(f"""
        import sys
        sys.modules[{blocked!r}] = None  # its import now raises ImportError
        from contactfem.cli import main
        main(["solve", {str(root / "cases" / "square.yaml")!r}, "--out", {str(out)!r}, "--overwrite",
              "--method", "standard"], prog_name="contactfem")
        """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert run.returncode == 1, run.stderr
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in run.stderr, run.stderr
    assert message in lines[0], lines[0]
    assert {path.name: path.read_bytes() for path in out.iterdir()} == before


def _vtk_read(path: Path) -> dict:
    """The file as VTK's own XML reader (the one ParaView uses) gives it back."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0
    grid = reader.GetOutput()

    def arrays(data) -> dict:
        found = {}
        for i in range(data.GetNumberOfArrays()):
            array = data.GetAbstractArray(i)
            found[array.GetName()] = vtk_to_numpy(array)
        return found

    cells = grid.GetCells()
    return {
        "points": vtk_to_numpy(grid.GetPoints().GetData()),
        "cells": vtk_to_numpy(cells.GetConnectivityArray()).reshape(grid.GetNumberOfCells(), -1),
        "types": {grid.GetCellType(i) for i in range(grid.GetNumberOfCells())},
        "point_data": arrays(grid.GetPointData()),
        "cell_data": arrays(grid.GetCellData()),
        "field_data": arrays(grid.GetFieldData()),
    }


def _assert_same(found: np.ndarray, expected: np.ndarray, name: str) -> None:
    assert found.dtype == expected.dtype, name
    assert found.shape == expected.shape, name
    np.testing.assert_array_equal(found, expected, err_msg=name)


_DATA_TYPES = {
    "solution.vtu": {
        "Points": ("Float64", "3"), "connectivity": ("Int64", None), "offsets": ("Int64", None),
        "types": ("UInt8", None), "displacement": ("Float64", "3"), "stress": ("Float64", "6"),
        "stress_xx": ("Float64", None), "stress_yy": ("Float64", None), "stress_xy": ("Float64", None),
        "stress_zz": ("Float64", None), "von_mises": ("Float64", None),
    },
    "contact.vtu": {
        "Points": ("Float64", "3"), "connectivity": ("Int64", None), "offsets": ("Int64", None),
        "types": ("UInt8", None), "mesh_node": ("Int64", None), "contact_pressure": ("Float64", None),
        "nodal_force": ("Float64", None), "normal_displacement": ("Float64", None), "gap": ("Float64", None),
        "active": ("UInt8", None), "contact_node": ("UInt8", None), "displacement": ("Float64", "3"),
    },
}


def test_vtu_arrays_have_their_types_and_components(tmp_path: Path) -> None:
    """Every array's VTK type and component count, as written in the file: scalars carry
    no NumberOfComponents (VTK's default 1), so that readers see them 1-D."""
    write_vtu(_solution(), tmp_path)
    for name, expected in _DATA_TYPES.items():
        root = _vtu_header(tmp_path / name)
        found = {a.get("Name"): (a.get("type"), a.get("NumberOfComponents")) for a in root.iter("DataArray")}
        assert found == expected, name
        assert root.find("UnstructuredGrid/FieldData") is None, name  # no metadata given


def test_cell_fields_round_trip(tmp_path: Path) -> None:
    """Solution.cell_fields become cell data of solution.vtu, values and dtypes exact, as
    meshio and as VTK's reader read them."""
    rng = np.random.default_rng(3)
    fields = {
        "error_indicator": rng.random(8),
        "level": rng.integers(0, 5, size=8).astype(np.int32),
        "marked": (rng.random(8) > 0.5).astype(np.uint8),
    }
    solution = _solution(cell_fields=fields)
    write_vtu(solution, tmp_path)
    by_meshio = meshio.read(tmp_path / "solution.vtu").cell_data
    by_vtk = _vtk_read(tmp_path / "solution.vtu")["cell_data"]
    for name, values in fields.items():
        _assert_same(by_meshio[name][0], values, name)
        _assert_same(by_vtk[name], values, name)
    _assert_same(by_vtk["von_mises"], solution.von_mises, "von_mises")
    assert set(by_vtk) == set(_DATA_TYPES["solution.vtu"]) - {"Points", "connectivity", "offsets", "types",
                                                             "displacement"} | set(fields)
    assert "error_indicator" not in meshio.read(tmp_path / "contact.vtu").cell_data


@pytest.mark.parametrize("fields, message", [
    ({"error_indicator": np.ones(7)}, r"'error_indicator' has shape \(7,\), expected \(8,\)"),
    ({"error_indicator": np.ones((8, 2))}, r"expected \(8,\)"),
    ({"von_mises": np.ones(8)}, "would replace"),
])
def test_bad_cell_fields_write_nothing(tmp_path: Path, fields, message) -> None:
    with pytest.raises(ValueError, match=message):
        write_vtu(_solution(cell_fields=fields), tmp_path / "out")
    assert not (tmp_path / "out").exists()


METADATA = {
    "method": "positive",
    "case_title": "Hertz contact – ünïcode ✓",
    "case_sha256": "9f" * 32,
    "units": "SI: lengths in m, stresses in Pa",
    "version": "0.1.0",
    "empty": "",
}


def _text(values: np.ndarray) -> str:
    assert values.dtype == np.uint8 and values.ndim == 1
    return values.tobytes().decode("utf-8")


def test_metadata_round_trips_as_field_data(tmp_path: Path) -> None:
    """Each metadata entry is a field data array of solution.vtu and of contact.vtu holding the
    value's UTF-8 bytes; VTK's reader and meshio give back exactly the strings."""
    write_vtu(_solution(), tmp_path, metadata=METADATA)
    by_vtk = _vtk_read(tmp_path / "solution.vtu")["field_data"]
    assert {name: _text(values) for name, values in by_vtk.items()} == METADATA
    by_meshio = meshio.read(tmp_path / "solution.vtu").field_data
    assert {name: _text(values) for name, values in by_meshio.items()} == METADATA
    root = _vtu_header(tmp_path / "solution.vtu")
    assert [(a.get("Name"), a.get("type")) for a in root.iterfind("UnstructuredGrid/FieldData/DataArray")] == [
        (name, "UInt8") for name in METADATA]
    # contact.vtu carries the same (read by VTK: on this tiny grid meshio's raw-appended reader,
    # which finds arrays by offsets it rewrites as it goes, takes one array for another).
    by_vtk = _vtk_read(tmp_path / "contact.vtu")["field_data"]
    assert {name: _text(values) for name, values in by_vtk.items()} == METADATA
    # The rest of the file is unchanged by the metadata.
    _assert_same(meshio.read(tmp_path / "solution.vtu").cell_data["von_mises"][0], _solution().von_mises,
                 "von_mises")


def test_metadata_must_be_strings(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="metadata 'refine' is int, not str"):
        write_vtu(_solution(), tmp_path / "out", metadata={"refine": 2})
    assert not (tmp_path / "out").exists()


def test_write_grid_keeps_every_name_dtype_and_component_count(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    points = rng.random((6, 2))
    cells = np.array([[0, 1, 2], [2, 3, 4], [3, 4, 5]], dtype=np.int32)
    point_data = {
        "f32": rng.random(6).astype(np.float32),
        "i8": rng.integers(-100, 100, size=6).astype(np.int8),
        "u16_pairs": rng.integers(0, 60000, size=(6, 2)).astype(np.uint16),
        "i64_vectors": rng.integers(-(2**40), 2**40, size=(6, 3)),
    }
    cell_data = {"f64_tensor": rng.normal(size=(3, 6)), "u64": np.array([0, 2**63, 2**64 - 1], dtype=np.uint64),
                 "flag": np.array([True, False, True])}
    field_data = {"levels": np.array([0.5, 0.25]), "pairs": np.arange(4, dtype=np.int32).reshape(2, 2),
                  "note": "plane strain"}
    path = write_grid(tmp_path / "g.vtu", Grid(points, cells, VTK_TRIANGLE, point_data=point_data,
                                                cell_data=cell_data, field_data=field_data))
    assert path == tmp_path / "g.vtu" and _temporaries(tmp_path) == []
    expected_cells = {**cell_data, "flag": np.array([1, 0, 1], dtype=np.uint8)}
    expected_fields = {**field_data, "note": np.frombuffer(b"plane strain", dtype=np.uint8)}
    xyz = np.column_stack([points, np.zeros(6)])

    vtk = _vtk_read(path)
    _assert_same(vtk["points"], xyz, "points")
    _assert_same(vtk["cells"], cells.astype(np.int64), "cells")
    assert vtk["types"] == {VTK_TRIANGLE}
    for found, expected in ((vtk["point_data"], point_data), (vtk["cell_data"], expected_cells),
                            (vtk["field_data"], expected_fields)):
        assert list(found) == list(expected)
        for name, values in expected.items():
            _assert_same(found[name], values, name)

    mesh = meshio.read(path)
    _assert_same(mesh.points, xyz, "points")
    _assert_same(mesh.cells[0].data, cells.astype(np.int64), "cells")
    for name, values in point_data.items():
        _assert_same(mesh.point_data[name], values, name)
    for name, values in expected_cells.items():
        _assert_same(mesh.cell_data[name][0], values, name)
    for name, values in expected_fields.items():
        _assert_same(mesh.field_data[name], values, name)


def test_write_grid_of_lines_with_3d_points(tmp_path: Path) -> None:
    points = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 2.0], [2.0, 1.0, 3.0]])
    write_grid(tmp_path / "l.vtu", Grid(points, np.array([[0, 1], [1, 2]]), VTK_LINE))
    mesh = meshio.read(tmp_path / "l.vtu")
    assert [block.type for block in mesh.cells] == ["line"]
    _assert_same(mesh.points, points, "points")
    _assert_same(mesh.cells[0].data, np.array([[0, 1], [1, 2]]), "cells")


@pytest.mark.parametrize("change, message", [
    ({"cells": np.array([[0, 1, 3]])}, r"cells refer to points outside 0\.\.2"),
    ({"cells": np.array([[0, 1, -1]])}, r"cells refer to points outside 0\.\.2"),
    ({"cells": np.array([[0.0, 1.0, 2.0]])}, "integer"),
    ({"points": np.zeros((3, 4))}, r"expected \(n, 2\) or \(n, 3\)"),
    ({"point_data": {"u": np.zeros(4)}}, r"point data 'u' has shape \(4,\), expected 3 rows"),
    ({"cell_data": {"s": np.zeros((1, 2, 2))}}, "cell data 's' has shape"),
    ({"cell_data": {"s": np.zeros((1, 0))}}, "cell data 's' has shape"),
    ({"cell_data": {"z": np.zeros(1, dtype=complex)}}, "cannot be stored"),
    ({"field_data": {"when": np.array(["today"])}}, "cannot be stored"),
])
def test_write_grid_rejects_arrays_that_do_not_fit(tmp_path: Path, change, message) -> None:
    base = {"points": np.zeros((3, 2)), "cells": np.array([[0, 1, 2]]), "cell_type": VTK_TRIANGLE}
    (tmp_path / "g.vtu").write_bytes(b"old")
    with pytest.raises(ValueError, match=message):
        write_grid(tmp_path / "g.vtu", Grid(**{**base, **change}))
    assert (tmp_path / "g.vtu").read_bytes() == b"old"
    assert _temporaries(tmp_path) == []


def test_write_series_writes_every_entry_then_the_collection(tmp_path: Path) -> None:
    first, second = _solution(), _solution(cell_fields={"error_indicator": np.arange(8.0)})
    written = write_series(tmp_path, "cmp", [("positive", first), ("standard", second)])
    names = ["cmp-positive.vtu", "cmp-positive-contact.vtu", "cmp-standard.vtu", "cmp-standard-contact.vtu",
             "cmp.pvd"]
    assert written == [tmp_path / name for name in names]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)  # no temporaries, no scratch directory
    _assert_same(meshio.read(tmp_path / "cmp-positive.vtu").cell_data["von_mises"][0], first.von_mises,
                 "von_mises")
    _assert_same(_vtk_read(tmp_path / "cmp-standard.vtu")["cell_data"]["error_indicator"], np.arange(8.0),
                 "error_indicator")
    assert meshio.read(tmp_path / "cmp-standard-contact.vtu").cells[0].type == "line"
    # The series files are the very files write_vtu writes.
    write_vtu(second, tmp_path / "solve")
    assert (tmp_path / "solve" / "solution.vtu").read_bytes() == (tmp_path / "cmp-standard.vtu").read_bytes()
    assert (tmp_path / "solve" / "contact.vtu").read_bytes() == (tmp_path / "cmp-standard-contact.vtu").read_bytes()
    files = [d.get("file") for d in ET.parse(tmp_path / "cmp.pvd").getroot().iterfind("./Collection/DataSet")]
    assert files == names[:4]
    with pytest.raises(ValueError, match="not a plain name"):
        write_series(tmp_path, "cmp", [("../up", first)])


def test_vtu_modules_import_vtk_only_when_writing() -> None:
    script = ("import sys, contactfem.io.vtu, contactfem.io.series; "
              "print(sorted(m for m in sys.modules if m.startswith(('vtk', 'vtkmodules'))))")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"


# --------------------------------------------------------------------- HDF5


def _write_h5(solution: Solution, path: Path) -> Path:
    return write_hdf5(
        solution,
        path,
        case_text="# case\nmethod: positive\nname: ünïcode ✓\n",
        case_hash="sha256:abc123",
        attributes={"version": "0.1.0", "plane": "strain", "backend": "superlu", "n_refine": 2,
                    "tolerance": 1e-10},
    )


def test_hdf5_round_trip(tmp_path: Path) -> None:
    solution = _solution()
    path = _write_h5(solution, tmp_path / "solution.h5")
    assert path == tmp_path / "solution.h5"
    data = read_hdf5(path)

    assert data["attrs"] == {
        "format": "contactfem-solution",
        "schema_version": 3,
        "method": "positive",
        "case_hash": "sha256:abc123",
        "version": "0.1.0",
        "plane": "strain",
        "backend": "superlu",
        "n_refine": 2,
        "tolerance": 1e-10,
    }
    assert data["case"] == "# case\nmethod: positive\nname: ünïcode ✓\n"

    mesh = solution.mesh
    np.testing.assert_array_equal(data["mesh"]["points"], mesh.points)
    np.testing.assert_array_equal(data["mesh"]["triangles"], mesh.triangles)
    np.testing.assert_array_equal(data["mesh"]["boundary_edges"], mesh.boundary_edges)
    np.testing.assert_array_equal(data["mesh"]["edge_parts"], mesh.edge_parts)
    np.testing.assert_array_equal(data["mesh"]["edge_curves"], mesh.edge_curves)
    np.testing.assert_array_equal(data["mesh"]["curves"], [[0.5, -1.0, 2.0]])
    assert data["mesh"]["attrs"]["part_names"] == list(mesh.part_names)
    assert data["mesh"]["triangles"].dtype == np.int64

    np.testing.assert_array_equal(data["fields"]["displacement"], solution.displacement)
    assert data["fields"]["displacement"].shape == (9, 2)
    # VTK's symmetric tensor order, as in solution.vtu: xx yy zz xy yz xz.
    xx, yy, xy, zz = solution.stress.T
    np.testing.assert_array_equal(data["fields"]["stress"], np.column_stack([xx, yy, zz, xy, 0 * xx, 0 * xx]))
    assert data["fields"]["stress"].shape == (8, 6)
    assert data["fields"]["attrs"] == {}
    with h5py.File(path, "r") as f:
        assert f["fields/stress"].attrs["components"] == "xx yy zz xy yz xz"
    np.testing.assert_array_equal(data["fields"]["von_mises"], solution.von_mises)

    c = solution.contact
    for name in ["nodes", "edges", "multiplier", "nodal_force", "normal_displacement", "gap", "abscissa"]:
        np.testing.assert_array_equal(data["contact"][name], getattr(c, name), err_msg=name)
    np.testing.assert_array_equal(data["contact"]["attrs"]["obstacle_point"], c.obstacle_point)
    np.testing.assert_array_equal(data["contact"]["attrs"]["obstacle_normal"], c.obstacle_normal)
    assert data["contact"]["active"].dtype == np.uint8
    np.testing.assert_array_equal(data["contact"]["active"], [1, 0])

    assert set(data["newton"]) - {"attrs"} == set(solution.newton)
    for key, values in solution.newton.items():
        np.testing.assert_array_equal(data["newton"][key], values, err_msg=key)
    assert data["newton"]["active"].dtype.kind == "i"
    assert _temporaries(tmp_path) == []


def test_hdf5_stores_every_dataset_contiguous_and_uncompressed(tmp_path: Path) -> None:
    big = np.linspace(0.0, 1.0, 150_000)
    path = _write_h5(_solution(newton={"equilibrium_residual": big}), tmp_path / "s.h5")
    with h5py.File(path, "r") as f:
        datasets = []
        f.visititems(lambda name, item: datasets.append(item) if isinstance(item, h5py.Dataset) else None)
        assert len(datasets) > 10
        for dataset in datasets:
            assert dataset.compression is None, dataset.name
            assert dataset.chunks is None, dataset.name  # contiguous layout
    np.testing.assert_array_equal(read_hdf5(path)["newton"]["equilibrium_residual"], big)


def test_hdf5_reserved_attribute_is_rejected(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="method"):
        write_hdf5(_solution(), tmp_path / "s.h5", case_text="", case_hash="h",
                   attributes={"method": "other"})
    with pytest.raises(TypeError, match="list"):
        write_hdf5(_solution(), tmp_path / "s.h5", case_text="", case_hash="h",
                   attributes={"bad": [1, 2]})  # type: ignore[dict-item]
    assert list(tmp_path.iterdir()) == []


def test_failed_hdf5_write_keeps_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "solution.h5"
    old = b"previous archive"
    target.write_bytes(old)
    # An object array has no HDF5 type: the writer fails after mesh, fields and contact
    # were already written to the temporary file.
    bad = _solution(newton={"active": np.array([object()], dtype=object)})
    with pytest.raises(TypeError):
        _write_h5(bad, target)
    assert target.read_bytes() == old
    assert _temporaries(tmp_path) == []


def test_write_hdf5_under_a_file_is_an_output_error(tmp_path: Path) -> None:
    blocker = tmp_path / "plain"
    blocker.write_text("x")
    with pytest.raises(OutputError, match="cannot write"):
        _write_h5(_solution(), blocker / "solution.h5")
    target = tmp_path / "dir.h5"
    target.mkdir()  # the target itself is a directory: the final rename fails
    with pytest.raises(OutputError, match=r"cannot write .*dir\.h5"):
        _write_h5(_solution(), target)
    assert _temporaries(tmp_path) == []


def test_read_hdf5_errors(tmp_path: Path) -> None:
    """What read_hdf5 cannot use is bad input (ArchiveError, exit 2), one line naming the file."""
    with pytest.raises(ArchiveError, match="missing.h5: cannot be opened"):
        read_hdf5(tmp_path / "missing.h5")
    (tmp_path / "text.h5").write_text("not hdf5")
    with pytest.raises(ArchiveError, match="text.h5: is not an HDF5 file"):
        read_hdf5(tmp_path / "text.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(ArchiveError, match="not a contactfem-solution file"):
        read_hdf5(tmp_path / "other.h5")
    path = _write_h5(_solution(), tmp_path / "future.h5")
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(ArchiveError, match="schema_version: is 99, newer than 3"):
        read_hdf5(path)


# --------------------------------------------------------------------- atomic


def test_atomic_path_replaces_on_success(tmp_path: Path) -> None:
    final = tmp_path / "solution.vtu"
    final.write_text("old")
    with atomic_path(final) as temp:
        assert temp.parent == tmp_path
        assert temp.name.startswith(TEMP_PREFIX)
        assert temp.name.endswith(".solution.vtu")  # suffix kept for format sniffing
        assert temp.exists() and final.read_text() == "old"
        temp.write_text("new")
    assert final.read_text() == "new"
    assert _temporaries(tmp_path) == []


def test_atomic_path_cleans_up_on_error(tmp_path: Path) -> None:
    final = tmp_path / "a.txt"
    final.write_text("old")
    with pytest.raises(KeyError):
        with atomic_path(final) as temp:
            temp.write_text("half")
            raise KeyError("boom")
    assert final.read_text() == "old"
    assert _temporaries(tmp_path) == []


def test_atomic_path_when_body_removed_the_temporary(tmp_path: Path) -> None:
    final = tmp_path / "a.txt"
    with pytest.raises(OutputError, match="cannot write"):
        with atomic_path(final) as temp:
            temp.unlink()
    assert not final.exists()


def test_atomic_write_text_and_bytes(tmp_path: Path) -> None:
    assert atomic_write_text(tmp_path / "t.txt", "héllo\r\n") == tmp_path / "t.txt"
    assert (tmp_path / "t.txt").read_bytes() == "héllo\r\n".encode()
    atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01")
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    with pytest.raises(OutputError, match=r"cannot write .*missing.*t\.txt"):
        atomic_write_text(tmp_path / "missing" / "t.txt", "x")
    assert _temporaries(tmp_path) == []


def test_forces_of_every_boundary_part_balance_and_name_their_condition(tmp_path):
    """report.json's boundary_forces: the traction part carries exactly ∫ g (the square's top:
    (1e4, −2500)), the contact part exactly the contact force, and all parts with the body
    force balance to round-off."""
    import json

    from click.testing import CliRunner

    from contactfem.cli import main

    root = Path(__file__).resolve().parents[1]
    for name in ("square", "hertz_quarter", "hole", "flat_punch", "manufactured"):
        out = tmp_path / name
        result = CliRunner().invoke(main, ["solve", str(root / "cases" / f"{name}.yaml"), "--out", str(out), "--quiet"])
        assert result.exit_code == 0, result.output
        report = json.loads((out / "report.json").read_text(encoding="utf-8"))
        forces = report["boundary_forces"]
        assert forces["total"]["relative_force_residual"] < 1e-10, (name, forces["total"])
        assert forces["total"]["relative_moment_residual"] < 1e-10, (name, forces["total"])
        contact = [entry for entry in forces["parts"].values() if entry["condition"] == "contact"]
        pushed = np.sum([entry["force"] for entry in contact], axis=0)
        np.testing.assert_allclose(pushed, report["contact_force"]["vector"], rtol=1e-12, atol=1e-12 * abs(pushed).max())
        if name == "square":
            np.testing.assert_allclose(forces["parts"]["top"]["force"], [1.0e4, -2500.0], rtol=1e-13)
        table = (out / "contact.csv").read_text(encoding="utf-8").splitlines()
        assert table[0] == "abscissa,x,y,pressure,nodal_force,gap,normal_displacement,active"
        assert len(table) - 1 == report["mesh"]["contact_nodes"]


def test_a_body_that_touches_nothing_reports_its_balance_against_the_force_unit_and_warns(tmp_path):
    """A body lifted off the plane (the square's top moved up) or pushed short of it
    (a star-shaped polygon whose lowest point stays above a tilted plane) moves rigidly:
    nothing loads it and its forces are round-off. The balances in report.json are then
    relative to the certificate's force scale (the force of a strain of 1e-7 over the
    body): within the nodes' count times its round-off bound, not 1.0 (round-off over
    itself); and a warning says that no
    node touched, naming the nearest one and its remaining gap."""
    import json

    import yaml
    from click.testing import CliRunner

    from contactfem.cli import main

    star = {"title": "a star short of a tilted plane",
            "geometry": {"polygon": {"vertices": [[0, 0.5], [1, 0.9], [0.8, 2.0], [0, 2.5], [-1.2, 2.2], [-1, 0.9]],
                                     "edges": ["base", "rim", "rim", "rim", "rim", "base"]}},
            "mesh": {"size": 0.1}, "material": {"E": 1.0e10, "nu": 0.0, "plane": "stress"},
            "boundary": {"base": "contact", "rim": {"displacement": [0, -1.0e-3]}},
            "obstacle": {"point": [0, 0], "normal": [0.1, -0.994987437]}}
    square = yaml.safe_load((Path(__file__).resolve().parents[1] / "cases" / "square.yaml").read_text(encoding="utf-8"))
    square["boundary"] = {"bottom": "contact", "top": {"displacement": [0.0, 1.0e-2]}}
    for name, data in (("star", star), ("lifted", square)):
        case = tmp_path / f"{name}.yaml"
        case.write_text(yaml.safe_dump(data), encoding="utf-8")
        out = tmp_path / name
        result = CliRunner().invoke(main, ["solve", str(case), "--out", str(out), "--quiet"])
        assert result.exit_code == 0, result.output
        report = json.loads((out / "report.json").read_text(encoding="utf-8"))
        assert report["contact_zone"]["active_nodes"] == 0
        assert report["solver"]["certificate"]["passed"]
        scales = report["solver"]["certificate"]["scales"]
        total = report["boundary_forces"]["total"]
        # A sum over the nodes of forces each within the certificate's round-off bound of the unit.
        bound = report["mesh"]["nodes"] * scales["roundoff"]
        assert np.hypot(*total["force"]) <= bound * scales["force"]
        assert report["equilibrium"]["relative_force_residual"] <= bound < 1e-6
        assert total["relative_force_residual"] <= bound
        warning = [w for w in report["warnings"] if w.startswith("no contact node touches the obstacle")]
        assert len(warning) == 1, report["warnings"]
        gaps = np.loadtxt(out / "contact.csv", delimiter=",", skiprows=1, usecols=(5, 6))
        nearest = (gaps[:, 0] - gaps[:, 1]).min()
        assert nearest > 0 and f"stays {nearest:.3g} from it" in warning[0]


def test_hdf5_stores_the_exact_pressure_only_when_given(tmp_path: Path) -> None:
    solution = _solution()
    assert "exact_pressure" not in read_hdf5(_write_h5(solution, tmp_path / "plain.h5"))["contact"]
    path = write_hdf5(solution, tmp_path / "exact.h5", case_text="", case_hash="h", attributes={},
                      exact_pressure=np.array([2.0, np.nan]))
    stored = read_hdf5(path)["contact"]["exact_pressure"]
    assert stored[0] == 2.0 and np.isnan(stored[1])


def test_xdmf_points_into_the_archive_only(tmp_path: Path) -> None:
    """solution.xdmf stores nothing itself: every DataItem names a dataset of solution.h5
    that exists with the declared shape (no companion file)."""
    from contactfem.io.xdmf import COMPANION_H5, write_xdmf

    solution = _solution()
    _write_h5(solution, tmp_path / "solution.h5")
    assert write_xdmf(solution, tmp_path) == [tmp_path / "solution.xdmf"]
    assert not (tmp_path / COMPANION_H5).exists()
    root = ET.parse(tmp_path / "solution.xdmf").getroot()
    items = list(root.iter("DataItem"))
    assert len(items) == 5
    with h5py.File(tmp_path / "solution.h5", "r") as f:
        for item in items:
            file_name, dataset = item.text.strip().split(":")
            assert file_name == "solution.h5"
            shape = tuple(int(v) for v in item.get("Dimensions").split())
            assert f[dataset].shape == shape, dataset
    kinds = {a.get("Name"): (a.get("AttributeType"), a.get("Center")) for a in root.iter("Attribute")}
    assert kinds == {"displacement": ("Vector", "Node"), "stress": ("Matrix", "Cell"), "von_mises": ("Scalar", "Cell")}


def test_result_data_carries_units_and_the_exact_pressure() -> None:
    """The writers' input: units in every file's metadata, the exact pressure at the contact
    nodes when the case has an exact solution (the manufactured case: 3a(λ+μ)√(−x) for x < 0)."""
    from conftest import shipped_case

    from contactfem.io.registry import result_data
    from contactfem.solve import solve_case

    case = shipped_case("manufactured")
    result = solve_case(case)
    data = result_data(case, result, {})
    assert {k: data.attributes[k] for k in ("length_unit", "force_unit", "stress_unit")} == {
        "length_unit": "m", "force_unit": "N", "stress_unit": "Pa"}
    x = result.solution.mesh.points[result.solution.contact.nodes, 0]
    law = result.problem.law
    expected = np.where(x < 0, 3e-3 * (law.lam + law.mu) * np.sqrt(np.abs(x)), 0.0)
    finite = np.isfinite(data.exact_pressure)
    assert finite.sum() >= len(x) - 1
    np.testing.assert_allclose(data.exact_pressure[finite], expected[finite], rtol=1e-9, atol=1e-12)



@pytest.mark.parametrize("lengths", [(23, 5), (11, 1), (41, 17), (7, 64)])
def test_meshio_reads_every_array_whatever_the_lengths_of_the_metadata(tmp_path: Path, lengths) -> None:
    """meshio converts a raw appended section to base64 itself, rewriting the offsets in
    place, and took a rewritten offset for a later array's: with metadata strings of these
    lengths (a case path of 41 characters among them) the point data of a raw file read back
    as one value. The files are base64 now; every array reads back exactly."""
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    grid = Grid(points=points, cells=np.array([[0, 1, 2]]), cell_type=VTK_TRIANGLE,
                point_data={"d": np.arange(9.0).reshape(3, 3)}, cell_data={"v": np.array([2.5])},
                field_data={"a": "x" * lengths[0], "b": "y" * lengths[1]})
    write_grid(tmp_path / "g.vtu", grid)
    data = meshio.read(tmp_path / "g.vtu")
    np.testing.assert_array_equal(data.point_data["d"], np.arange(9.0).reshape(3, 3))
    np.testing.assert_array_equal(data.cell_data["v"][0], [2.5])
    assert bytes(data.field_data["a"]).decode() == "x" * lengths[0]
