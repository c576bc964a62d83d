"""The outputs as ParaView itself reads them: pvpython (Debian's python3-paraview) opens the
VTU, PVD and XDMF files of a solved shipped case and of `compare`, and every array's name,
components, type and values are checked against solution.h5. Skipped without pvpython.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from test_cli import invoke
from test_writers import METADATA, _solution

from contactfem.io import read_hdf5, write_vtu

ROOT = Path(__file__).resolve().parents[1]
PROBE = Path(__file__).with_name("pvpython_probe.py")
PVPYTHON = shutil.which("pvpython")

CELL_FIELDS = {"error_indicator": np.linspace(0.0, 1.0, 8), "level": np.arange(8, dtype=np.int32),
               "marked": np.array([1, 0, 0, 1, 0, 1, 1, 0], dtype=np.uint8)}

pytestmark = pytest.mark.skipif(PVPYTHON is None, reason="pvpython not installed (apt-get install python3-paraview)")


@pytest.fixture(scope="module")
def probed(tmp_path_factory):
    """Solve cases/square.yaml and compare it, then let pvpython read every ParaView file."""
    import yaml

    tmp = tmp_path_factory.mktemp("paraview")
    case = ROOT / "cases" / "square.yaml"
    data = yaml.safe_load(case.read_text(encoding="utf-8"))
    data["output"] = {"files": ["vtu", "h5", "json", "xdmf"]}  # XDMF is an extra a case asks for
    with_xdmf = tmp / "square.yaml"
    with_xdmf.write_text(yaml.safe_dump(data), encoding="utf-8")
    assert invoke("solve", with_xdmf, "--out", tmp / "solve", "--quiet").exit_code == 0
    assert invoke("compare", case, "--out", tmp / "compare", "--quiet").exit_code == 0
    files = [tmp / "solve" / n for n in ("solution.vtu", "contact.vtu", "solution.pvd", "solution.xdmf")]
    files.append(tmp / "compare" / "compare.pvd")
    write_vtu(_solution(cell_fields=CELL_FIELDS), tmp / "direct", metadata=METADATA)
    files.append(tmp / "direct" / "solution.vtu")
    out = tmp / "probe.json"
    run = subprocess.run([PVPYTHON, str(PROBE), str(out), *map(str, files)], capture_output=True, text=True,
                         timeout=300, cwd=tmp)
    assert run.returncode == 0, run.stdout + run.stderr
    report = json.loads(out.read_text())
    return {Path(k).relative_to(tmp).as_posix(): v for k, v in report.items()}, tmp


def _values(info) -> np.ndarray:
    return np.reshape(info["values"], (-1, info["components"]))


def _check_body(block, data, source="vtu", displacement_components=3):
    """The body as ParaView reads it from ``source`` (vtu: solution.vtu, with the scalar stress
    components; xdmf: solution.xdmf over solution.h5). The stress has one layout everywhere:
    6 components in VTK's order xx yy zz xy yz xz, as solution.h5 stores it."""
    points, triangles = data["mesh"]["points"], data["mesh"]["triangles"]
    fields = data["fields"]
    assert block["points"] == len(points) and block["cells"] == len(triangles)
    assert block["cell_types"] == [5]  # VTK_TRIANGLE
    xyz = np.asarray(block["coordinates"])
    assert np.allclose(xyz[:, :2], points) and np.all(xyz[:, 2] == 0)
    assert set(block["point_data"]) == {"displacement"}
    scalars = {"stress_xx", "stress_yy", "stress_xy", "stress_zz"} if source == "vtu" else set()
    assert set(block["cell_data"]) == {"stress", "von_mises"} | scalars
    for kind in ("point_data", "cell_data"):
        assert all(info["type"] == "double" for info in block[kind].values())
    u = _values(block["point_data"]["displacement"])
    assert u.shape == (len(points), displacement_components)
    assert np.allclose(u[:, :2], fields["displacement"], rtol=1e-12, atol=0) and np.all(u[:, 2:] == 0)
    stored = fields["stress"]
    assert stored.shape == (len(triangles), 6) and fields["stress"].dtype == np.float64
    assert block["cell_data"]["stress"]["components"] == 6
    assert np.allclose(_values(block["cell_data"]["stress"]), stored, rtol=1e-12, atol=0)
    xx, yy, zz, xy = stored[:, 0], stored[:, 1], stored[:, 2], stored[:, 3]
    assert np.all(stored[:, 4:] == 0)
    columns = {"stress_xx": xx, "stress_yy": yy, "stress_xy": xy, "stress_zz": zz}
    for name, column in [*((n, columns[n]) for n in sorted(scalars)), ("von_mises", fields["von_mises"])]:
        assert block["cell_data"][name]["components"] == 1
        assert np.allclose(_values(block["cell_data"][name])[:, 0], column, rtol=1e-12, atol=0)


def test_vtu_metadata_names_the_units(probed):
    report, _ = probed
    (body,) = report["solve/solution.vtu"]["XMLUnstructuredGridReader"]["steps"]["none"]
    found = _metadata(body)
    assert (found["length_unit"], found["force_unit"], found["stress_unit"]) == ("m", "N", "Pa")


def _metadata(block) -> dict[str, str]:
    """The field data of a body block as text: each array holds the UTF-8 bytes of one entry."""
    found = {}
    for name, info in block["field_data"].items():
        if name == "Name" and info["type"] == "char":
            continue  # the PVD reader's own: the data set's name
        assert info["type"] == "unsigned char" and info["components"] == 1, name
        found[name] = bytes(int(v) for v in info["values"]).decode("utf-8")
    return found


def _check_contact(block, data):
    contact = data["contact"]
    assert block["cell_types"] == [3]  # VTK_LINE
    assert block["cells"] == len(contact["edges"])
    names = block["point_data"]
    assert set(names) == {"mesh_node", "contact_pressure", "nodal_force", "normal_displacement", "gap",
                          "active", "contact_node", "displacement"}
    assert names["active"]["type"] == names["contact_node"]["type"] == "unsigned char"
    assert names["displacement"]["components"] == 3
    node = _values(names["mesh_node"])[:, 0].astype(int)
    where = {n: i for i, n in enumerate(node)}
    rows = [where[n] for n in contact["nodes"]]
    for vtu_name, h5_name in (("contact_pressure", "multiplier"), ("nodal_force", "nodal_force"),
                              ("normal_displacement", "normal_displacement"), ("gap", "gap"),
                              ("active", "active")):
        assert np.allclose(_values(names[vtu_name])[rows, 0], contact[h5_name], rtol=1e-12, atol=0), vtu_name
    assert np.allclose(np.asarray(block["coordinates"])[:, :2], data["mesh"]["points"][node])


def test_vtu_files_as_paraview_reads_them(probed):
    report, tmp = probed
    data = read_hdf5(tmp / "solve" / "solution.h5")
    (body,) = report["solve/solution.vtu"]["XMLUnstructuredGridReader"]["steps"]["none"]
    _check_body(body, data)
    _metadata(body)
    (contact,) = report["solve/contact.vtu"]["XMLUnstructuredGridReader"]["steps"]["none"]
    _check_contact(contact, data)


def test_pvd_groups_body_and_contact(probed):
    report, tmp = probed
    data = read_hdf5(tmp / "solve" / "solution.h5")
    found = report["solve/solution.pvd"]["PVDReader"]
    assert found["times"] == [0.0]
    body, contact = found["steps"]["0.0"]
    _check_body(body, data)
    _metadata(body)
    _check_contact(contact, data)


@pytest.mark.parametrize("reader, components", [("Xdmf3ReaderS", 2), ("XDMFReader", 3)])
def test_xdmf_reads_the_hdf5_archive(probed, reader, components):
    """solution.xdmf reads everything from solution.h5 (no companion file): the XDMF 3 reader
    keeps the stored 2-component displacement, the XDMF 2 reader pads it with z = 0."""
    report, tmp = probed
    data = read_hdf5(tmp / "solve" / "solution.h5")
    assert sorted(p.name for p in (tmp / "solve").glob("*.h5")) == ["solution.h5"]
    (body,) = report["solve/solution.xdmf"][reader]["steps"]["none"]
    _check_body(body, data, source="xdmf", displacement_components=components)


def test_compare_series_has_one_time_step_per_method(probed):
    report, tmp = probed
    found = report["compare/compare.pvd"]["PVDReader"]
    assert found["times"] == [0.0, 1.0]
    figures = json.loads((tmp / "compare" / "compare.json").read_text())
    pressures = {}
    for step, method in (("0.0", "positive"), ("1.0", "standard")):
        body, contact = found["steps"][step]
        assert body["cell_types"] == [5] and contact["cell_types"] == [3]
        pressures[method] = _values(contact["point_data"]["contact_pressure"])[:, 0]
    assert pressures["positive"].min() >= 0
    assert np.isclose(pressures["standard"].min(), min(figures["min_theta"], 0.0), rtol=1e-12)


def test_cell_fields_and_metadata_as_paraview_reads_them(probed):
    report, _ = probed
    (body,) = report["direct/solution.vtu"]["XMLUnstructuredGridReader"]["steps"]["none"]
    cells = body["cell_data"]
    for name, values, vtk_type in (("error_indicator", CELL_FIELDS["error_indicator"], "double"),
                                   ("level", CELL_FIELDS["level"], "int"),
                                   ("marked", CELL_FIELDS["marked"], "unsigned char")):
        assert cells[name]["type"] == vtk_type and cells[name]["components"] == 1, name
        assert np.array_equal(_values(cells[name])[:, 0], values), name
    assert cells["stress"]["components"] == 6
    assert _metadata(body) == METADATA
