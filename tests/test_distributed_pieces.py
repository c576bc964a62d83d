"""A solve on a distributed mesh writes its result in pieces, each rank its share, and the files say
what a serial run's say.

The manufactured case (body force, tractions, a prescribed displacement and an exact solution)
refined once on 2 MPI ranks, against the serial solve of the same mesh: solution.h5, read back
through its untrusted-input checks, holds the same mesh up to the order of nodes and triangles,
and the same fields to 1e-10 (the same discrete problem solved to round-off by two
solvers); report.json's figures, reduced over the pieces (the residual estimator's terms included),
agree to 1e-10; the PVTU index
and its pieces read back (VTK, pyvista, meshio) with the serial triangles, nodes (those on the
cut once merged) and fields. A write failing on rank 1 reaches every rank and leaves the
previous result as it was; what needs the whole mesh in one process (--plot) is refused first.

Skipped unless petsc4py and mpi4py import and an ``mpiexec`` is on the PATH.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

RANKS = 2
_mpiexec = shutil.which("mpiexec")
needs_mpi = pytest.mark.skipif(
    not (_mpiexec and all(importlib.util.find_spec(name) is not None for name in ("petsc4py", "mpi4py"))),
    reason="petsc4py, mpi4py or mpiexec not available (pip install 'contactfem[petsc]')")
CASES = Path(__file__).resolve().parent.parent / "cases"
#: Fields of one discrete problem solved twice to round-off, each solve certified far below this.
AGREEMENT = 1e-10

#: Rank 1's piece of solution.h5 cannot be written (a full disk), the others can.
FAILING = """
import errno
import sys

from mpi4py import MPI

import contactfem.io.hdf5 as hdf5

if MPI.COMM_WORLD.Get_rank() == 1:
    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    hdf5.write_piece_slices = full_disk
from contactfem.cli.cmd_solve import solve

solve.main(sys.argv[1:])
"""


def _mpi_environment() -> dict[str, str]:
    """Open MPI refuses root and more ranks than cores unless told (as tests/test_distributed.py)."""
    return {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
            "OMPI_MCA_rmaps_base_oversubscribe": "1", "OMP_NUM_THREADS": "1"}


def _solve_command(case_file: Path, out: Path, *extra: str) -> list[str]:
    return [_mpiexec, "-n", str(RANKS), sys.executable, "-m", "contactfem.cli", "solve", str(case_file),
            "--backend", "petsc", "--refine", "1", "--out", str(out), "--quiet", *extra]


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """The manufactured case (16 x 8 cells, refined once: 2 145 nodes) in pieces on 2 ranks, and serially."""
    from contactfem.cli import main as cli

    directory = tmp_path_factory.mktemp("pieces")
    data = yaml.safe_load((CASES / "manufactured.yaml").read_text(encoding="utf-8"))
    data["mesh"]["divisions"] = [16, 8]
    case_file = directory / "manufactured.yaml"
    case_file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    pieces, serial = directory / "pieces", directory / "serial"
    run = subprocess.run(_solve_command(case_file, pieces), capture_output=True, text=True, timeout=300,
                         env=_mpi_environment())
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    done = CliRunner().invoke(cli, ["solve", str(case_file), "--refine", "1", "--out", str(serial), "--quiet"])
    assert done.exit_code == 0, done.output
    return {"case": case_file, "pieces": pieces, "serial": serial}


def _node_map(points: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The row of ``reference`` holding each row of ``points`` (the same coordinates, bit for bit)."""
    mine, theirs = np.lexsort(points.T[::-1]), np.lexsort(reference.T[::-1])
    np.testing.assert_array_equal(points[mine], reference[theirs])
    where = np.empty(len(points), dtype=np.int64)
    where[mine] = theirs
    return where


def _close(value: np.ndarray, reference: np.ndarray) -> None:
    assert np.abs(np.asarray(value) - reference).max(initial=0.0) <= AGREEMENT * max(np.abs(reference).max(), 1e-300)


@needs_mpi
def test_the_pieces_write_the_files_of_a_serial_run(runs):
    written = {path.name for path in runs["pieces"].iterdir()}
    assert written == {"solution_0.vtu", "solution_1.vtu", "solution.pvtu", "solution.pvd", "contact.vtu",
                       "solution.h5", "contact.csv", "report.json"}
    from contactfem.io.journal import is_output_name

    assert all(is_output_name(name) for name in written) and is_output_name("solution_12.vtu")


@needs_mpi
def test_solution_h5_agrees_with_the_serial_one_field_by_field(runs):
    from contactfem.io.hdf5 import read_hdf5

    pieces, serial = read_hdf5(runs["pieces"] / "solution.h5"), read_hdf5(runs["serial"] / "solution.h5")
    where = _node_map(pieces["mesh"]["points"], serial["mesh"]["points"])
    # The same triangles (as sets of nodes), boundary rows and contact nodes, renumbered.
    mine, theirs = np.sort(where[pieces["mesh"]["triangles"]], axis=1), np.sort(serial["mesh"]["triangles"], axis=1)
    rows, reference_rows = np.lexsort(mine.T[::-1]), np.lexsort(theirs.T[::-1])
    np.testing.assert_array_equal(mine[rows], theirs[reference_rows])
    for group, name in (("mesh", "boundary_edges"), ("contact", "nodes"), ("contact", "edges")):
        np.testing.assert_array_equal(where[pieces[group][name]], serial[group][name])
    for name in ("edge_parts", "edge_curves", "curves"):
        np.testing.assert_array_equal(pieces["mesh"][name], serial["mesh"][name])
    _close(pieces["fields"]["displacement"], serial["fields"]["displacement"][where])
    for name in ("stress", "von_mises"):
        _close(pieces["fields"][name][rows], serial["fields"][name][reference_rows])
    for name in ("multiplier", "nodal_force", "normal_displacement", "gap", "active", "abscissa", "exact_pressure"):
        _close(np.nan_to_num(pieces["contact"][name]), np.nan_to_num(serial["contact"][name]))
    assert pieces["case"] == serial["case"]
    assert {k: v for k, v in pieces["attrs"].items() if k != "backend"} == \
           {k: v for k, v in serial["attrs"].items() if k != "backend"}


@needs_mpi
def test_report_figures_agree_with_the_serial_run(runs):
    import jsonschema

    from contactfem.io.registry import schema_path

    pieces, serial = (json.loads((runs[name] / "report.json").read_text(encoding="utf-8"))
                      for name in ("pieces", "serial"))
    jsonschema.validate(pieces, json.loads(schema_path("report.json").read_text(encoding="utf-8")))
    assert pieces["parallel"]["mesh"] == "pieces" and pieces["parallel"]["ranks"] == RANKS
    assert all(entry["peak_rss_bytes"] >= entry["solve_peak_rss_bytes"] > 0 for entry in pieces["parallel"]["per_rank"])
    for section in ("mesh", "unknowns", "contact_zone", "obstacle"):
        assert pieces[section].keys() == serial[section].keys()
        for key, value in serial[section].items():
            if isinstance(value, (int, float)):
                _close(pieces[section][key], np.asarray(value, dtype=float))
    # From the contact arrays, the same on every rank as serially: the same intervals.
    assert pieces["contact_zone"]["intervals"] == serial["contact_zone"]["intervals"]
    _close(pieces["contact_force"]["vector"], np.asarray(serial["contact_force"]["vector"]))
    for name in ("applied", "contact", "reactions", "moment_about"):  # the body force reduced over the pieces
        _close(pieces["equilibrium"][name], np.asarray(serial["equilibrium"][name]))
    for part, entry in serial["boundary_forces"]["parts"].items():
        _close([*pieces["boundary_forces"]["parts"][part]["force"], pieces["boundary_forces"]["parts"][part]["moment"]],
               np.asarray([*entry["force"], entry["moment"]]))
    assert pieces["equilibrium"]["relative_force_residual"] < 1e-12
    for name, value in serial["errors"].items():  # the exact errors: triangles on their ranks, ΓC on rank 0
        if name == "multiplier_h_minus_half":  # needs the whole mesh's Gram matrix: null, and said so
            assert pieces["errors"][name] is None and any("h_minus_half" in w for w in pieces["warnings"])
        else:
            _close(pieces["errors"][name], np.asarray(value))
    # The residual estimator summed over the pieces, the jumps across the cut from both sides.
    energy, reference = pieces["accuracy"]["energy"], serial["accuracy"]["energy"]
    _close(energy["estimate"], np.asarray(reference["estimate"]))
    _close(energy["relative"], np.asarray(reference["relative"]))
    for name, value in reference["terms"].items():
        _close(energy["terms"][name], np.asarray(value))


@needs_mpi
def test_the_pvtu_and_its_pieces_read_back_as_the_serial_vtu(runs):
    import meshio
    import pyvista
    from vtkmodules.vtkIOXML import vtkXMLPUnstructuredGridReader

    serial = pyvista.read(runs["serial"] / "solution.vtu")
    whole = pyvista.read(runs["pieces"] / "solution.pvtu")
    reader = vtkXMLPUnstructuredGridReader()
    reader.SetFileName(str(runs["pieces"] / "solution.pvtu"))
    reader.Update()
    assert reader.GetOutput().GetNumberOfCells() == whole.n_cells == serial.n_cells
    # Nodes on the cut belong to both pieces: merged, the serial nodes.
    merged = whole.clean(tolerance=0.0)
    assert merged.n_points == serial.n_points < whole.n_points
    assert set(whole.point_data) == set(serial.point_data) and set(whole.cell_data) == set(serial.cell_data)
    where = _node_map(np.asarray(merged.points), np.asarray(serial.points))
    _close(merged.point_data["displacement"], serial.point_data["displacement"][where])
    centres, reference = np.asarray(whole.cell_centers().points), np.asarray(serial.cell_centers().points)
    rows = _node_map(np.round(centres, 12), np.round(reference, 12))
    for name in serial.cell_data:
        _close(whole.cell_data[name], serial.cell_data[name][rows])
    pieces = [meshio.read(runs["pieces"] / f"solution_{rank}.vtu") for rank in range(RANKS)]
    assert sum(len(piece.cells_dict["triangle"]) for piece in pieces) == serial.n_cells
    assert all(set(piece.point_data) == {"displacement"} for piece in pieces)
    collection = pyvista.read(runs["pieces"] / "solution.pvd")
    assert collection[0].n_cells == serial.n_cells and collection[1].n_cells == pyvista.read(
        runs["serial"] / "contact.vtu").n_cells


@needs_mpi
@pytest.mark.skipif(shutil.which("pvpython") is None, reason="pvpython not installed (apt-get install python3-paraview)")
def test_paraview_reads_the_pvtu_and_the_pvd(runs, tmp_path):
    """ParaView's own readers (tests/pvpython_probe.py): the PVTU as one grid of the serial
    triangles and arrays, and the PVD's two parts, body and contact."""
    import pyvista

    out = tmp_path / "probe.json"
    probe = Path(__file__).with_name("pvpython_probe.py")
    files = [str(runs["pieces"] / "solution.pvtu"), str(runs["pieces"] / "solution.pvd")]
    done = subprocess.run([shutil.which("pvpython"), str(probe), str(out), *files], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    found = json.loads(out.read_text(encoding="utf-8"))
    serial = pyvista.read(runs["serial"] / "solution.vtu")
    (grid,) = found[files[0]]["XMLPartitionedUnstructuredGridReader"]["steps"]["none"]
    assert grid["cells"] == serial.n_cells and grid["cell_types"] == [5]
    assert set(grid["point_data"]) == set(serial.point_data) and set(grid["cell_data"]) == set(serial.cell_data)
    body, contact = found[files[1]]["PVDReader"]["steps"]["0.0"]
    assert body["cells"] == serial.n_cells and contact["cell_types"] == [3]


@needs_mpi
def test_plot_reads_the_pieces_archive(runs, tmp_path):
    from contactfem.cli import main as cli

    done = CliRunner().invoke(cli, ["plot", str(runs["pieces"]), "--out", str(tmp_path / "pictures")])
    assert done.exit_code == 0, done.output
    assert (tmp_path / "pictures" / "deformed.png").stat().st_size > 0


@needs_mpi
def test_a_failure_on_rank_1_leaves_the_previous_result(runs, tmp_path):
    """Rank 1 cannot write its rows of solution.h5: every rank stops (none waits), one line says
    why, and the directory keeps the previous result, byte for byte; a serial run replacing a
    result in pieces then removes the pieces."""
    from contactfem.cli import main as cli

    out = tmp_path / "out"
    shutil.copytree(runs["pieces"], out)  # the previous result: in pieces
    before = {path.name: path.read_bytes() for path in out.iterdir()}
    script = tmp_path / "failing.py"
    script.write_text(FAILING, encoding="utf-8")
    command = [_mpiexec, "-n", str(RANKS), sys.executable, str(script), str(runs["case"]), "--backend", "petsc",
               "--refine", "1", "--out", str(out), "--quiet", "--overwrite"]
    run = subprocess.run(command, capture_output=True, text=True, timeout=300, env=_mpi_environment())
    assert run.returncode not in (0, None)
    errors = [line for line in run.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "rank 1" in errors[0] and "No space left" in errors[0], run.stderr[-3000:]
    assert {path.name: path.read_bytes() for path in out.iterdir()} == before
    # The pieces' names are the journal's: a serial run over a result in pieces removes them.
    done = CliRunner().invoke(cli, ["solve", str(runs["case"]), "--refine", "1", "--out", str(out), "--quiet",
                                    "--overwrite"])
    assert done.exit_code == 0, done.output
    assert {path.name for path in out.iterdir()} == {path.name for path in runs["serial"].iterdir()}


@needs_mpi
def test_plot_is_refused_before_the_solve_on_a_distributed_mesh(runs, tmp_path):
    out = tmp_path / "never"
    run = subprocess.run(_solve_command(runs["case"], out, "--plot"), capture_output=True, text=True, timeout=300,
                         env=_mpi_environment())
    errors = [line for line in run.stderr.splitlines() if line.startswith("error: ")]
    assert run.returncode == 2 and len(errors) == 1 and "--plot" in errors[0], run.stderr[-3000:]
    assert not out.exists()
