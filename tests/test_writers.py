"""Tests of the VTU/PVD and HDF5 writers and of atomic file replacement."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest

from contactfem.errors import OutputError
from contactfem.io import atomic_path, atomic_write_text, read_hdf5, write_hdf5, write_vtu
from contactfem.io.atomic import TEMP_PREFIX, atomic_write_bytes
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


def _solution(newton: dict[str, np.ndarray] | None = None) -> Solution:
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
        gap=np.array([0.1, 0.2]),
        active=np.array([True, False]),
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
    """The XML part of a VTU with raw appended data (the binary tail is not XML)."""
    data = path.read_bytes()
    return ET.fromstring(data[: data.index(b"<AppendedData")] + b"</VTKFile>")


def test_vtu_files_hold_raw_appended_data_with_64_bit_counts(tmp_path: Path) -> None:
    """Raw appended arrays behind UInt64 byte counts: no encoding, no compressor, and no
    4 GB limit that would force one; meshio reads the values back exactly."""
    solution = _solution()
    write_vtu(solution, tmp_path)
    for name in ["solution.vtu", "contact.vtu"]:
        root = _vtu_header(tmp_path / name)
        assert root.tag == "VTKFile" and root.get("type") == "UnstructuredGrid"
        assert root.get("header_type") == "UInt64" and root.get("compressor") is None
        assert {a.get("format") for a in root.iter("DataArray")} == {"appended"}
        assert b'<AppendedData encoding="raw">' in (tmp_path / name).read_bytes()
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
        "gap": [0.0, 0.1, 0.2],
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
    real_stream = vtu._stream

    def write_then_fail(path, header, arrays):
        real_stream(path, header, arrays)  # a complete temporary file...
        raise RuntimeError("disk on fire")  # ...then a failure before the rename

    monkeypatch.setattr(vtu, "_stream", write_then_fail)
    with pytest.raises(RuntimeError, match="disk on fire"):
        write_vtu(_solution(), tmp_path)
    assert (tmp_path / "solution.vtu").read_bytes() == old
    assert _temporaries(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["solution.vtu"]


def test_oserror_during_vtu_write_becomes_output_error(tmp_path: Path, monkeypatch) -> None:
    from contactfem.io import vtu

    old = b"old"
    (tmp_path / "solution.vtu").write_bytes(old)

    def half_write(path, header, arrays):
        Path(path).write_bytes(b"<VTKFile trunc")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(vtu, "_stream", half_write)
    with pytest.raises(OutputError, match=r"cannot write .*solution\.vtu: No space left"):
        write_vtu(_solution(), tmp_path)
    assert (tmp_path / "solution.vtu").read_bytes() == old
    assert _temporaries(tmp_path) == []


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
        "schema_version": 1,
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
    np.testing.assert_array_equal(data["fields"]["stress"], solution.stress)
    assert data["fields"]["stress"].shape == (8, 4)
    assert data["fields"]["attrs"] == {}
    with h5py.File(path, "r") as f:
        assert f["fields/stress"].attrs["components"] == "xx yy xy zz"
    np.testing.assert_array_equal(data["fields"]["von_mises"], solution.von_mises)

    c = solution.contact
    for name in ["nodes", "edges", "multiplier", "nodal_force", "normal_displacement", "gap"]:
        np.testing.assert_array_equal(data["contact"][name], getattr(c, name), err_msg=name)
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
    with pytest.raises(OutputError, match="cannot read"):
        read_hdf5(tmp_path / "missing.h5")
    (tmp_path / "text.h5").write_text("not hdf5")
    with pytest.raises(OutputError, match="cannot read"):
        read_hdf5(tmp_path / "text.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f.attrs["format"] = "something-else"
    with pytest.raises(OutputError, match="not a contactfem-solution file"):
        read_hdf5(tmp_path / "other.h5")
    path = _write_h5(_solution(), tmp_path / "future.h5")
    with h5py.File(path, "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(OutputError, match="schema version 99"):
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
