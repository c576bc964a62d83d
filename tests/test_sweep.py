"""``contactfem sweep``: many independent solves of one base case, on Dask or one after another.

The points of a sweep give the figures of separate ``contactfem solve`` runs of the same
cases; a refused or failing point leaves the others intact; finished points are stored and
never solved again; a worker killed mid-sweep loses nothing; without Dask the points run in
this process. Meshes are tiny (at most 64 divisions) so that the file runs in seconds.
"""

from __future__ import annotations

import copy
import csv
import json
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import make_runner, square_case_dict

from contactfem import sweep as sweeps
from contactfem import sweep_plan
from contactfem.cli import main
from contactfem.errors import CaseError

try:
    import distributed  # noqa: F401

    HAVE_DASK = True
except ImportError:
    HAVE_DASK = False

needs_dask = pytest.mark.skipif(not HAVE_DASK, reason="Dask (distributed) is not installed: pip install -e '.[dask]'")
ROOT = Path(__file__).resolve().parents[1]
SCHEMA = Path(sweeps.__file__).parent / "schemas" / "sweep.schema.json"
#: 2 x 2 x 2 = 8 points, the last key varying fastest.
GRID = {"mesh.divisions": [6, 8], "solver.method": ["positive", "standard"], "material.nu": [0.3, 0.45]}


def invoke(*args):
    result = make_runner().invoke(main, [str(a) for a in args])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result


def write_sweep(directory: Path, body: dict, base: dict | None = None, name: str = "sweep.yaml") -> Path:
    (directory / "base.yaml").write_text(yaml.safe_dump(base or square_case_dict(6), sort_keys=False))
    path = directory / name
    path.write_text(yaml.safe_dump({"case": "base.yaml", **body}, sort_keys=False))
    return path


def point_case(values: dict) -> dict:
    """The base case with ``values`` set, built by hand (not by the sweep's dotted paths)."""
    data = copy.deepcopy(square_case_dict(6))
    data["mesh"]["divisions"] = values["mesh.divisions"]
    data.setdefault("solver", {})["method"] = values["solver.method"]
    data["material"]["nu"] = values["material.nu"]
    return data


@pytest.fixture
def no_dask(monkeypatch):
    """Dask as if not installed: importing it fails."""
    monkeypatch.setitem(sys.modules, "dask", None)
    monkeypatch.setitem(sys.modules, "distributed", None)


@pytest.fixture
def solves(monkeypatch):
    """Counts the solves of this process."""
    count = {"n": 0}
    real = sweeps.solve_case

    def counting(*args, **kwargs):
        count["n"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(sweeps, "solve_case", counting)
    return count


@pytest.fixture(scope="module")
def separate(tmp_path_factory):
    """The 8 points of GRID as 8 separate `contactfem solve` runs: report.json of each, by values."""
    directory = tmp_path_factory.mktemp("separate")
    reports = {}
    plan_values = [dict(zip(GRID, combination)) for combination in
                   __import__("itertools").product(*GRID.values())]
    for i, values in enumerate(plan_values):
        case = directory / f"point{i}.yaml"
        case.write_text(yaml.safe_dump(point_case(values), sort_keys=False))
        result = invoke("solve", case, "--out", directory / f"out{i}", "--quiet")
        assert result.exit_code == 0, result.stderr
        reports[json.dumps(values, sort_keys=True)] = json.loads((directory / f"out{i}" / "report.json").read_text())
    return reports


def assert_same_as_separate(table: dict, separate: dict) -> None:
    assert len(table["points"]) == 8
    for row in table["points"]:
        report = separate[json.dumps(row["values"], sort_keys=True)]
        assert row["status"] == "ok", row["message"]
        assert row["unknowns"] == report["unknowns"]["displacement"]
        assert row["iterations"] == report["solver"]["iterations"]
        assert row["contact_force"] == pytest.approx(report["contact_force"]["normal"], rel=1e-9)
        assert row["contact_zone"]["active_nodes"] == report["contact_zone"]["active_nodes"]
        assert row["method"] == report["method"]["name"]


# --- the same figures as separate solves -------------------------------------------------------------


@pytest.mark.parametrize("engine", [
    "serial",
    pytest.param("dask", marks=needs_dask),
])
def test_a_sweep_of_8_points_gives_the_figures_of_8_separate_solves(engine, separate, tmp_path, request):
    if engine == "serial":
        request.getfixturevalue("no_dask")
    path = write_sweep(tmp_path, {"grid": GRID})
    out = tmp_path / "out"
    result = invoke("sweep", path, "--out", out, *(["--workers", "2"] if engine == "dask" else []))
    assert result.exit_code == 0, result.stderr
    table = json.loads((out / "sweep.json").read_text())
    assert table["engine"]["kind"] == engine
    assert [row["index"] for row in table["points"]] == list(range(1, 9))
    assert table["points"][1]["values"] == {"mesh.divisions": 6, "solver.method": "positive", "material.nu": 0.45}
    assert_same_as_separate(table, separate)
    assert table["counts"] == {"points": 8, "solved": 8, "reused": 0, "ok": 8, "not_certified": 0,
                               "invalid": 0, "failed": 0, "error": 0}
    # One progress line per point on stderr: count, point, seconds.
    lines = [line for line in result.stderr.splitlines() if line.startswith("[")]
    assert len(lines) == 8 and lines[-1].startswith("[8/8] point ") and lines[0].rstrip().endswith("unknowns")
    assert sorted(p.name for p in (out / "points").iterdir()) == sorted(f"{r['digest']}.json"
                                                                      for r in table["points"])
    png = (out / "sweep.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    csv = (out / "sweep.csv").read_text().splitlines()
    assert len(csv) == 9 and csv[0].startswith("index,status,mesh.divisions,solver.method,material.nu,unknowns")


def test_quiet_prints_nothing_and_json_prints_the_table(tmp_path, no_dask):
    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [4, 6]}})
    result = invoke("sweep", path, "--out", tmp_path / "q", "--quiet")
    assert result.exit_code == 0 and result.stdout == "" and result.stderr == ""
    result = invoke("sweep", path, "--out", tmp_path / "j", "--json", "--quiet")
    assert json.loads(result.stdout) == json.loads((tmp_path / "j" / "sweep.json").read_text())


# --- failures stay in their point -------------------------------------------------------------------


def test_failing_points_leave_the_others_intact_and_are_reported(tmp_path, no_dask, solves):
    points = [
        {"mesh.divisions": 6},
        {"material.nu": 0.6},                                  # invalid: the case is refused
        {"solver.max_iterations": 1},                          # failed: no convergence
        {"mesh.divisions": 8, "solver.method": "standard"},
        {"boundary.top.traction[5]": 1.0},                     # invalid: no such list element
    ]
    path = write_sweep(tmp_path, {"points": points})
    out = tmp_path / "out"
    result = invoke("sweep", path, "--out", out)
    assert result.exit_code == 1
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("error: sweep.yaml: 3 of 5 points did not solve (2 invalid, 1 failed)")
    table = json.loads((out / "sweep.json").read_text())
    rows = table["points"]
    assert [r["status"] for r in rows] == ["ok", "invalid", "failed", "ok", "invalid"]
    assert rows[1]["message"] == "sweep.yaml point 2: material.nu = 0.6: must be in [0, 0.5)"
    assert rows[2]["message"].startswith("sweep.yaml point 3: method positive: no convergence")
    assert "boundary.top.traction[5]" in rows[4]["message"] and "cannot set element [5]" in rows[4]["message"]
    for row in (rows[0], rows[3]):
        assert row["unknowns"] > 0 and row["contact_force"] > 0 and row["certificate"] == "passed"
    for row in rows[1:3] + rows[4:]:
        assert row["unknowns"] is None and row["error"] is None and not row["pareto"]
    # The solved and the failed point are stored; the refused ones were never sent to a solver.
    assert solves["n"] == 3
    stored = {p.stem for p in (out / "points").iterdir()}
    assert stored == {rows[0]["digest"], rows[2]["digest"], rows[3]["digest"]}
    assert len((out / "sweep.csv").read_text().splitlines()) == 6
    # A rerun solves none of them again: the failure is deterministic, and stored as such.
    result = invoke("sweep", path, "--out", out, "--overwrite", "--quiet")
    assert result.exit_code == 1 and solves["n"] == 3
    again = json.loads((out / "sweep.json").read_text())["points"]
    assert [r["status"] for r in again] == [r["status"] for r in rows]
    assert [r["reused"] for r in again] == [True, False, True, True, False]


def test_a_point_that_could_not_run_is_not_stored_and_runs_again(tmp_path, no_dask, monkeypatch):
    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [4, 6]}})
    real = sweeps.solve_case

    def flaky(case, **kwargs):
        if case.mesh.divisions == (6, 6):
            raise RuntimeError("the machine hiccuped")
        return real(case, **kwargs)

    monkeypatch.setattr(sweeps, "solve_case", flaky)
    out = tmp_path / "out"
    result = invoke("sweep", path, "--out", out, "--quiet")
    assert result.exit_code == 1 and "(1 error)" in result.stderr
    rows = json.loads((out / "sweep.json").read_text())["points"]
    assert [r["status"] for r in rows] == ["ok", "error"]
    assert rows[1]["message"] == "sweep.yaml point 2: RuntimeError: the machine hiccuped"
    assert [p.stem for p in (out / "points").iterdir()] == [rows[0]["digest"]]
    monkeypatch.setattr(sweeps, "solve_case", real)
    assert invoke("sweep", path, "--out", out, "--quiet", "--overwrite").exit_code == 0
    rows = json.loads((out / "sweep.json").read_text())["points"]
    assert [(r["status"], r["reused"]) for r in rows] == [("ok", True), ("ok", False)]


def test_a_sweep_whose_every_point_is_refused_is_bad_input(tmp_path, no_dask):
    path = write_sweep(tmp_path, {"grid": {"mesh.divisons": [4, 8]}})
    result = invoke("sweep", path, "--out", tmp_path / "out")
    assert result.exit_code == 2
    message = result.stderr.strip()
    assert len(message.splitlines()) == 1
    assert message.startswith("error: sweep.yaml: grid: every point is refused")
    assert "mesh.divisons: unknown key" in message
    assert not (tmp_path / "out").exists()


# --- resuming ---------------------------------------------------------------------------------------


def test_rerunning_does_not_solve_finished_points_again(tmp_path, no_dask, solves):
    path = write_sweep(tmp_path, {"grid": GRID})
    out = tmp_path / "out"
    assert invoke("sweep", path, "--out", out, "--quiet").exit_code == 0
    assert solves["n"] == 8
    first = json.loads((out / "sweep.json").read_text())

    # A finished table is only replaced with --overwrite, and then nothing is solved again.
    result = invoke("sweep", path, "--out", out)
    assert result.exit_code == 2 and "pass --overwrite" in result.stderr and solves["n"] == 8
    result = invoke("sweep", path, "--out", out, "--overwrite")
    assert result.exit_code == 0 and solves["n"] == 8
    assert "8 of 8 points are already solved" in result.stderr
    second = json.loads((out / "sweep.json").read_text())
    assert second["counts"]["solved"] == 0 and second["counts"]["reused"] == 8
    for a, b in zip(first["points"], second["points"]):
        assert b["reused"] and not a["reused"]
        assert (a["unknowns"], a["iterations"], a["contact_force"], a["seconds"]) == \
               (b["unknowns"], b["iterations"], b["contact_force"], b["seconds"])

    # A sweep killed after 5 points: its points/ hold them, the table was never written.
    (out / "sweep.json").unlink()
    for row in first["points"][5:]:
        (out / "points" / f"{row['digest']}.json").unlink()
    (out / "points" / ".tmp-999999-abcdef01.x.json").write_text("{")  # a write cut short
    (out / "points" / ".tmp-notes.txt").write_text("the user's")  # not the sweep's to delete
    assert invoke("sweep", path, "--out", out, "--quiet").exit_code == 0
    assert solves["n"] == 11
    third = json.loads((out / "sweep.json").read_text())
    assert [r["reused"] for r in third["points"]] == [True] * 5 + [False] * 3
    assert [p.name for p in (out / "points").glob(".tmp-*")] == [".tmp-notes.txt"]

    # A larger grid reuses the points it shares with the finished one.
    bigger = write_sweep(tmp_path, {"grid": {**GRID, "mesh.divisions": [6, 8, 4]}}, name="bigger.yaml")
    assert invoke("sweep", bigger, "--out", out, "--quiet", "--overwrite").exit_code == 0
    assert solves["n"] == 15


def test_a_stored_point_of_another_case_text_is_not_reused(tmp_path, no_dask, solves):
    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [4, 6]}})
    out = tmp_path / "out"
    assert invoke("sweep", path, "--out", out, "--quiet").exit_code == 0
    stored = sorted((out / "points").iterdir())
    record = json.loads(stored[0].read_text())
    record["case_text"] += "# changed\n"
    stored[0].write_text(json.dumps(record))
    stored[1].write_text("not json")
    assert invoke("sweep", path, "--out", out, "--quiet", "--overwrite").exit_code == 0
    assert solves["n"] == 4
    assert all(json.loads(p.read_text())["status"] == "ok" for p in stored)


# --- Dask ------------------------------------------------------------------------------------------


@needs_dask
def test_a_worker_killed_mid_sweep_loses_no_point(tmp_path):
    """SIGKILL one of two workers while it runs points: the scheduler runs them on a worker
    that lives (the nanny also starts a new one), and every point comes back solved."""
    grid = {"mesh.divisions": [40, 48, 56, 64], "solver.method": ["positive", "standard"]}
    plan = sweeps.load_sweep(write_sweep(tmp_path, {"grid": grid}))
    killed = []
    with sweeps.open_engine(workers=2, pending=8) as engine:
        client = engine.client
        environments = client.run(lambda: {k: os.environ.get(k) for k in sweeps.SINGLE_THREADED})
        assert len(environments) == 2
        assert all(env == sweeps.SINGLE_THREADED for env in environments.values())
        pids = client.run(os.getpid)

        def kill_a_busy_worker(row, done, total):
            if killed:
                return
            busy = {worker: keys for worker, keys in client.processing().items() if keys and worker in pids}
            if busy:
                worker = next(iter(busy))
                os.kill(pids[worker], signal.SIGKILL)
                killed.append((pids[worker], busy[worker]))

        table = sweeps.run_sweep(plan, engine, progress=kill_a_busy_worker)
    assert killed, "no worker was busy after the first point: nothing was killed mid-sweep"
    pid, running = killed[0]
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)
    assert running  # it held points when it died
    assert [row["status"] for row in table["points"]] == ["ok"] * 8
    serial = sweeps.run_sweep(plan, sweeps.SerialEngine())
    for a, b in zip(table["points"], serial["points"]):
        assert (a["unknowns"], a["iterations"]) == (b["unknowns"], b["iterations"])
        assert a["contact_force"] == pytest.approx(b["contact_force"], rel=1e-9)


@needs_dask
def test_the_local_cluster_has_a_worker_per_core_at_most_one_per_point():
    from dask.system import CPU_COUNT
    from distributed.system import MEMORY_LIMIT

    assert sweeps.local_cluster_size(None, 1000) == (CPU_COUNT, MEMORY_LIMIT // CPU_COUNT)
    assert sweeps.local_cluster_size(None, 1) == (1, MEMORY_LIMIT)
    assert sweeps.local_cluster_size(3, 2) == (2, MEMORY_LIMIT // 2)
    assert sweeps.local_cluster_size(3, 10)[0] == 3


@needs_dask
def test_an_existing_cluster_through_scheduler(tmp_path):
    from distributed import LocalCluster

    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [4, 6], "solver.method": ["positive", "standard"]}})
    with LocalCluster(n_workers=1, threads_per_worker=1, dashboard_address=None) as cluster:
        result = invoke("sweep", path, "--out", tmp_path / "out", "--scheduler", cluster.scheduler_address)
    assert result.exit_code == 0, result.stderr
    table = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert table["engine"] == {"kind": "dask", "scheduler": cluster.scheduler_address, "workers": 1,
                               "startup_seconds": pytest.approx(table["engine"]["startup_seconds"])}
    assert [row["status"] for row in table["points"]] == ["ok"] * 4


@needs_dask
def test_a_scheduler_that_does_not_answer_is_refused_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr(sweeps, "CONNECT_TIMEOUT", "1s")
    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [4]}})
    for address, expected in (("tcp://127.0.0.1:1", "cannot connect"), ("nonsense", "missing port number")):
        result = invoke("sweep", path, "--out", tmp_path / "out", "--scheduler", address)
        assert result.exit_code == 2
        assert len(result.stderr.strip().splitlines()) == 1
        assert result.stderr.startswith(f"error: --scheduler {address}: ") and expected in result.stderr
        assert not (tmp_path / "out").exists()


# --- without Dask ----------------------------------------------------------------------------------


def test_without_dask_the_points_run_in_this_process_and_say_so_once(tmp_path, no_dask, solves):
    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [4, 6, 8]}})
    result = invoke("sweep", path, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.stderr
    assert result.stderr.count("Dask is not installed") == 1
    assert "pip install -e '.[dask]'" in result.stderr
    assert solves["n"] == 3
    table = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert table["engine"] == {"kind": "serial", "scheduler": None, "workers": 1, "startup_seconds": 0.0}
    result = invoke("sweep", path, "--out", tmp_path / "other", "--scheduler", "tcp://127.0.0.1:8786")
    assert result.exit_code == 2 and "Dask is not installed" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


# --- the sweep file -----------------------------------------------------------------------------


@pytest.mark.parametrize("body, expected", [
    ({"grid": GRID, "case": None}, "sweep.yaml: case = None: expected the path of the base case file"),
    ({"grid": GRID, "case": "missing.yaml"}, "sweep.yaml: case: "),
    ({"grid": GRID, "points": [{"mesh.divisions": 4}]}, "sweep.yaml: grid, points: both are given"),
    ({}, "sweep.yaml: grid, points: neither is given"),
    ({"grid": {"mesh.divisions": []}}, "sweep.yaml: grid.mesh.divisions = []: expected a non-empty list"),
    ({"grid": {"mesh.divisions": 8}}, "sweep.yaml: grid.mesh.divisions = 8: expected a non-empty list"),
    ({"grid": {"mesh..divisions": [8]}}, "sweep.yaml: grid.mesh..divisions: expected a dotted case key"),
    ({"grid": {"material.nu": [0.3, float("nan")]}}, "sweep.yaml: grid.material.nu[1] = nan: expected a finite"),
    ({"grid": {f"material.k{i}": list(range(10)) for i in range(5)}}, "expected at most 10000 points"),
    ({"grids": GRID}, "sweep.yaml: grids: unknown key"),
    ({"points": [{}]}, "sweep.yaml: points[0] = {}: expected a non-empty mapping"),
    ({"points": "mesh.divisions=8"}, "sweep.yaml: points = 'mesh.divisions=8': expected a non-empty list"),
    ({"grid": GRID, "output": {"directory": ""}}, "sweep.yaml: output.directory = '': expected a directory path"),
])
def test_a_bad_sweep_file_is_refused_in_one_line(tmp_path, no_dask, body, expected):
    path = write_sweep(tmp_path, body)
    if "case" in body:
        data = yaml.safe_load(path.read_text())
        data["case"] = body["case"]
        path.write_text(yaml.safe_dump(data))
    result = invoke("sweep", path, "--out", tmp_path / "out")
    assert result.exit_code == 2
    message = result.stderr.strip()
    assert len(message.splitlines()) == 1 and message.startswith("error: ")
    assert expected in message
    assert not (tmp_path / "out").exists()


def test_the_sweep_file_is_read_with_the_case_reader_bounds(tmp_path, no_dask):
    big = tmp_path / "big.yaml"
    big.write_text("case: base.yaml\n" + "#" * (1 << 20))
    result = invoke("sweep", big)
    assert result.exit_code == 2 and "the sweep file is larger than 1048576 bytes" in result.stderr
    bomb = tmp_path / "bomb.yaml"
    bomb.write_text("a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n" for p, c in zip("abcdef", "bcdefg")) + "case: base.yaml\n")
    result = invoke("sweep", bomb)
    assert result.exit_code == 2 and "more than 100000 values" in result.stderr
    result = invoke("sweep", tmp_path)
    assert result.exit_code == 2 and result.stderr.startswith("error: ")
    result = invoke("sweep", write_sweep(tmp_path, {"grid": GRID}), "--scheduler", "tcp://h:1", "--workers", "2")
    assert result.exit_code == 2 and "--workers 2" in result.stderr


def test_dotted_keys_set_one_use_of_an_anchor_list_elements_and_missing_blocks(tmp_path):
    base = (
        "geometry: {rectangle: {lower: [0, 0], upper: [1, 1]}}\n"
        "mesh: {divisions: 4}\n"
        "material: {E: 1.0e6, nu: 0.3}\n"
        "boundary:\n"
        "  left: clamped\n"
        "  top: &load {traction: [0, -1.0e+4]}\n"
        "  right: *load\n"
        "  bottom: contact\n"
        "obstacle: {point: [0, 0], normal: [0, -1]}\n"
    )
    (tmp_path / "base.yaml").write_text(base)
    (tmp_path / "sweep.yaml").write_text(
        "case: base.yaml\n"
        "points:\n"
        "  - boundary.top.traction[1]: -2.0e+4   # in a {...} mapping, [ needs quotes\n"
        "    solver.method: standard\n"
        "  - {boundary.right: free}\n")
    plan = sweeps.load_sweep(tmp_path / "sweep.yaml")
    first, second = (yaml.safe_load(p.text) for p in plan.points)
    assert first["boundary"]["top"] == {"traction": [0, -2.0e+4]}
    assert first["boundary"]["right"] == {"traction": [0, -1.0e+4]}  # the alias's other use is unchanged
    assert first["solver"] == {"method": "standard"}
    assert second["boundary"]["right"] == "free"
    assert plan.points[0].problem is None and plan.points[1].problem is None
    assert plan.points[0].digest != plan.points[1].digest
    assert plan.keys == ("boundary.top.traction[1]", "solver.method", "boundary.right")


# --- the table --------------------------------------------------------------------------------------


def test_errors_groups_and_the_pareto_front(tmp_path, no_dask):
    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [4, 8, 16], "material.nu": [0.3, 0.4]}})
    table = sweeps.run_sweep(sweeps.load_sweep(path), sweeps.SerialEngine())
    rows = table["points"]
    groups = {row["group"] for row in rows}
    assert groups == {"material.nu=0.3", "material.nu=0.4"}
    for group in groups:
        members = sorted((row for row in rows if row["group"] == group), key=lambda row: row["unknowns"])
        # Every point's error is the estimate its report gives (η), which falls each time h
        # halves (O(h) asymptotically, 0.5; 0.66-0.76 measured on these 40-544 unknowns; the
        # difference to the finest point did not fall monotonically on a rough block).
        assert all(row["error_kind"] == "estimated" and row["error"] == row["accuracy"]["energy"] > 0
                   for row in members)
        assert all(fine["error"] < 0.85 * coarse["error"] for coarse, fine in zip(members, members[1:]))
        # On the front: no other point of the group is both faster and more accurate.
        measured = [row for row in members if row["error"] is not None]
        for row in measured:
            dominated = any(o["seconds"]["total"] <= row["seconds"]["total"] and o["error"] < row["error"]
                            for o in measured if o is not row)
            assert row["pareto"] == (not dominated)


def test_without_the_estimate_the_error_is_the_difference_to_the_finest_point(tmp_path, no_dask):
    """Method (5) has no residual estimate: its group falls back to |‖u_h‖ − ‖u_finest‖|."""
    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [4, 8, 16], "solver.method": ["standard"]}})
    members = sweeps.run_sweep(sweeps.load_sweep(path), sweeps.SerialEngine())["points"]
    finest = max(members, key=lambda row: row["unknowns"])
    assert all(row["error_kind"] == "finest" and row["error_reference"] == finest["index"] for row in members)
    assert finest["error"] is None
    for row in members:
        if row is not finest:
            assert row["error"] == pytest.approx(abs(row["energy_norm"] - finest["energy_norm"]))


def test_with_an_exact_solution_the_error_is_the_energy_norm_of_the_report(tmp_path, no_dask):
    from conftest import CASES

    base = yaml.safe_load((CASES / "manufactured.yaml").read_text())
    path = write_sweep(tmp_path, {"grid": {"mesh.divisions": [[8, 4], [16, 8]]}}, base=base)
    table = sweeps.run_sweep(sweeps.load_sweep(path), sweeps.SerialEngine())
    coarse, fine = table["points"]
    for row in (coarse, fine):
        assert row["error_kind"] == "exact"
        assert row["error"] == row["errors"]["displacement_energy"] > 0
    assert fine["error"] < coarse["error"]


def test_sweep_json_follows_its_schema(tmp_path, no_dask):
    path = write_sweep(tmp_path, {"points": [{"mesh.divisions": 4}, {"material.nu": 0.7}]})
    result = invoke("sweep", path, "--out", tmp_path / "out", "--quiet")
    assert result.exit_code == 1
    table = json.loads((tmp_path / "out" / "sweep.json").read_text())
    schema = json.loads(SCHEMA.read_text())
    try:
        import jsonschema
    except ImportError:
        jsonschema = None
    if jsonschema is not None:
        jsonschema.Draft202012Validator.check_schema(schema)
        jsonschema.validate(table, schema, cls=jsonschema.Draft202012Validator)
    # Without the validator, the keys the schema requires and allows at least.
    assert set(schema["required"]) == set(table)
    point = schema["$defs"]["point"]
    for row in table["points"]:
        assert set(point["required"]) == set(row)
        assert row["status"] in point["properties"]["status"]["enum"]
    assert table["schema_version"] == schema["properties"]["schema_version"]["const"]


def test_the_shipped_sweep_file_is_valid():
    root = Path(__file__).resolve().parents[1]
    plan = sweeps.load_sweep(root / "cases" / "sweeps" / "square.yaml")
    assert len(plan.points) == 32 and all(point.problem is None for point in plan.points)
    assert len({point.digest for point in plan.points}) == 32


# --- data files ---------------------------------------------------------------------------------------


PROFILE_BASE = {
    "geometry": {"profile": {"file": "surface.csv", "depth": 0.5}},
    "mesh": {"size": 0.1},
    "material": {"E": 1.0e6, "nu": 0.3},
    "boundary": {"top": {"displacement": [0, -1.0e-3]}, "base": "contact"},
    "obstacle": {"point": [0, 0], "normal": [0, -1]},
}


def test_a_point_whose_data_file_changed_is_solved_again(tmp_path, no_dask, solves):
    """A point is its case text and the data files it reads: rerun after the profile file
    changed, the sweep solves every point again (their stored records stand for the old
    surface) and its table holds the new surface's figures, those of a fresh sweep; the
    point's text names the file by its absolute path, for a worker elsewhere."""
    (tmp_path / "surface.csv").write_text("0,0\n0.5,1e-3\n1,0\n")
    path = write_sweep(tmp_path, {"grid": {"material.nu": [0.3, 0.4]}}, base=PROFILE_BASE)
    out = tmp_path / "out"
    assert invoke("sweep", path, "--out", out, "--quiet").exit_code == 0
    first = json.loads((out / "sweep.json").read_text())
    plan = sweeps.load_sweep(path)
    named = yaml.safe_load(plan.points[0].text)["geometry"]["profile"]["file"]
    assert named == str((tmp_path / "surface.csv").resolve())

    (tmp_path / "surface.csv").write_text("0,0\n0.5,2e-4\n1,0\n")
    assert invoke("sweep", path, "--out", out, "--quiet", "--overwrite").exit_code == 0
    assert solves["n"] == 4
    second = json.loads((out / "sweep.json").read_text())
    assert all(not row["reused"] for row in second["points"])
    fresh = tmp_path / "fresh"
    assert invoke("sweep", path, "--out", fresh, "--quiet").exit_code == 0
    expected = json.loads((fresh / "sweep.json").read_text())
    forces = [row["contact_force"] for row in second["points"]]
    # Equal to round-off: the kernel's choice between a Schur update and a refactorisation
    # follows measured times, and the two routes round differently.
    assert forces == pytest.approx([row["contact_force"] for row in expected["points"]], rel=1e-12)
    old = [row["contact_force"] for row in first["points"]]
    assert all(abs(a - b) > 0.1 * abs(b) for a, b in zip(forces, old))


def test_a_data_file_changed_after_planning_is_not_stored_under_the_plan(tmp_path):
    (tmp_path / "surface.csv").write_text("0,0\n0.5,1e-3\n1,0\n")
    path = write_sweep(tmp_path, {"points": [{"material.nu": 0.3}]}, base=PROFILE_BASE)
    point = sweeps.load_sweep(path).points[0]
    (tmp_path / "surface.csv").write_text("0,0\n0.5,2e-4\n1,0\n")
    record = sweeps.solve_point({"text": point.text, "source": point.source, "digest": point.digest})
    assert record["status"] == "error" and "surface.csv" in record["message"] and "changed" in record["message"]
    assert not sweeps.storable(record)


@needs_dask
def test_a_point_too_large_for_its_worker_is_refused_against_the_workers_limit(tmp_path):
    """A worker's nanny kills it past its memory limit, a limit no cgroup or rlimit of its
    process shows. The size guard refuses against it: in a worker of 1 GiB the square at
    768 x 768 (about 1.8 GiB estimated even with amg, which auto takes where a factorisation
    would not fit; less than this machine's memory) is an invalid point naming that limit,
    at once; the square at 6 x 6 solves there; outside a worker there is no such limit."""
    from distributed import Client, LocalCluster

    from contactfem.estimate import estimate_cost, memory_limit

    big_estimate = estimate_cost(2 * 768 * 768, "amg")["bytes"]
    assert 2**30 < big_estimate < memory_limit().bytes
    path = write_sweep(tmp_path, {"points": [{"mesh.divisions": 768}, {"mesh.divisions": 6}]})
    points = sweeps.load_sweep(path).points
    tasks = [{"text": p.text, "source": p.source, "digest": p.digest} for p in points]
    assert sweeps.worker_memory_limit() is None
    with LocalCluster(n_workers=1, threads_per_worker=1, memory_limit="1GiB", dashboard_address=None) as cluster, \
            Client(cluster) as client:
        assert client.submit(sweeps.worker_memory_limit).result().bytes == 2**30
        big, small = client.gather(client.map(sweeps.solve_point, tasks, pure=False))
    assert big["status"] == "invalid", big
    assert "more than this Dask worker's memory limit of 1 GiB" in big["message"]
    assert big["seconds"]["total"] < 30
    assert small["status"] == "ok", small


# --- the plan's size ----------------------------------------------------------------------------------


def _profile_case(heights: int, seed: int = 1) -> dict:
    """A block on a rough base of ``heights`` inline heights (the bulk of a large case file)."""
    rng = np.random.default_rng(seed)
    return {
        "title": "inline rough block",
        "geometry": {"profile": {"heights": [round(float(h), 6) for h in rng.random(heights) * 1e-3],
                                 "spacing": 1.0 / (heights - 1), "name": "base", "depth": 0.5,
                                 "sides": ["left", "right"], "top": "top"}},
        "mesh": {"size": 0.1},
        "material": {"E": 1.0e6, "nu": 0.3},
        "boundary": {"top": {"displacement": [0, -2.0e-4]}, "left": "free", "right": "free", "base": "contact"},
        "obstacle": {"point": [0, 0], "normal": [0, -1]},
    }


def test_a_plan_too_large_is_refused_at_once_naming_the_grid_and_the_bound(tmp_path, no_dask):
    """The issue's sweep scaled down: a base of 20 000 inline heights (about 0.2 MB) and a grid of
    100 x 50 points would make about 1 GB of case text: refused in one line before anything is
    built, in well under 2 s (the base case's own validation, seconds for a large one, included)."""
    path = write_sweep(tmp_path, {"grid": {"material.nu": [0.3 + 1e-4 * i for i in range(100)],
                                           "mesh.size": [0.1 + 1e-3 * i for i in range(50)]}},
                       base=_profile_case(20_000), name="big-sweep.yaml")
    clock = time.perf_counter()
    result = invoke("sweep", path, "--out", tmp_path / "out")
    seconds = time.perf_counter() - clock
    assert result.exit_code == 2, result.stderr
    message = result.stderr.strip()
    assert len(message.splitlines()) == 1 and message.startswith("error: big-sweep.yaml: grid: 100 x 50 = 5000 points")
    assert "base case (base.yaml)" in message and "expected at most 64 MiB" in message
    assert f"{sweeps.MAX_SWEEP_PLAN_BYTES >> 20} MiB" in message and "GB of case text" in message
    assert seconds < 2, seconds
    assert not (tmp_path / "out").exists()
    # The same as a list of points.
    points = [{"material.nu": 0.3 + 1e-5 * i} for i in range(5000)]
    result = invoke("sweep", write_sweep(tmp_path, {"points": points}, base=_profile_case(20_000)))
    assert result.exit_code == 2 and "sweep.yaml: points: 5000 points of a" in result.stderr


def test_the_bound_counts_the_case_as_dumped_when_that_is_larger(tmp_path, monkeypatch):
    """A base case written compactly ([1,2,3]) dumps longer than its file: the bound is checked
    again on the dumped text, still before the points are built."""
    path = write_sweep(tmp_path, {"grid": {"material.nu": [0.3, 0.31, 0.32, 0.33]}})
    base = tmp_path / "base.yaml"
    base.write_text(json.dumps(_profile_case(2000), separators=(",", ":")))  # JSON is YAML
    compact = len(base.read_bytes())
    built = []
    monkeypatch.setattr(sweep_plan, "_point", lambda *args: built.append(args))
    monkeypatch.setattr(sweep_plan, "MAX_SWEEP_PLAN_BYTES", 4 * compact + 200)
    with pytest.raises(CaseError, match=r"grid: 4 points of a .* make .* expected at most"):
        sweeps.load_sweep(path)
    assert built == []


def test_planning_dumps_the_base_case_once(tmp_path, monkeypatch):
    """Planning is linear in the plan's size: the base's sections are dumped once, and a point
    dumps anew only the sections its values change (never the profile's heights again)."""
    dumped = []
    real = sweep_plan._dump
    monkeypatch.setattr(sweep_plan, "_dump", lambda data: dumped.append(real(data)) or dumped[-1])
    path = write_sweep(tmp_path, {"grid": {"material.nu": [0.3, 0.32, 0.34, 0.36, 0.38, 0.4],
                                           "solver.method": ["positive", "standard"]}},
                       base=_profile_case(5000))
    plan = sweeps.load_sweep(path)
    base_bytes = len(plan.points[0].text)
    assert len(plan.points) == 12 and all(point.problem is None for point in plan.points)
    assert sum(map(len, dumped)) < base_bytes + 12 * 200


@pytest.mark.parametrize("case, grid", [
    ("square", {"material.nu": [0.3, 0.35], "solver.method": ["standard"], "mesh.divisions": [[8, 4]]}),
    ("rough", {"geometry.profile.depth": [0.4, 0.6], "output.files": [["vtu", "json"]]}),
    ("hertz_platen", {"boundary.top.platen.force": [1000.0], "load_path.steps": [2], "title": ["a: b", "x"]}),
    ("hole", {"geometry.polygon.holes[0].circle.center[0]": [0.9, 1.1], "units.length": ["mm"]}),
])
def test_a_points_text_is_its_whole_case_dumped(case, grid, tmp_path):
    """Sections dumped apart and joined make the same text as the whole mapping dumped at once
    (so a stored point keeps its name, the SHA-256 of its text, from one version to the next)."""
    from contactfem.case.yaml_loader import load_yaml

    source = ROOT / "cases" / f"{case}.yaml"
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"case": str(source), "grid": grid}, sort_keys=False))
    plan = sweeps.load_sweep(path)
    for point in plan.points:
        data = sweep_plan._unshared(load_yaml(source.read_text(encoding="utf-8"), source.name))
        for key, value in point.values.items():
            sweep_plan._assign(data, key, value)
        sweep_plan._absolute_data_paths(data.get("geometry"), source.parent)
        assert point.text == yaml.safe_dump(data, sort_keys=False, allow_unicode=True, default_flow_style=None,
                                            width=100), point.label


def test_a_sweep_of_a_large_inline_case_within_the_bound_plans_and_runs(tmp_path, no_dask, monkeypatch):
    """A base of 2 000 inline heights, 3 points: planned (a large plan says so first), solved, tabled."""
    monkeypatch.setattr(sweep_plan, "PLAN_NOTE_BYTES", 1000)
    path = write_sweep(tmp_path, {"grid": {"material.nu": [0.25, 0.3, 0.35]}}, base=_profile_case(2000))
    result = invoke("sweep", path, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.stderr
    assert result.stderr.startswith("planning 3 points: ") and "kB of case text" in result.stderr.splitlines()[0]
    table = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert [row["status"] for row in table["points"]] == ["ok", "ok", "ok"]


def test_sweep_json_and_csv_say_the_units_of_each_row(tmp_path, no_dask):
    """The base case's units, and each row's, its case's: a sweep may set units.*, and a
    refused point has none."""
    base = square_case_dict(4)
    base["units"] = {"length": "mm", "force": "N"}
    path = write_sweep(tmp_path, {"points": [{"material.nu": 0.3}, {"units.length": "m"}, {"material.nu": 0.7}]},
                       base=base)
    result = invoke("sweep", path, "--out", tmp_path / "out", "--quiet")
    assert result.exit_code == 1, result.stderr  # the third point is refused
    table = json.loads((tmp_path / "out" / "sweep.json").read_text())
    jsonschema = pytest.importorskip("jsonschema")
    jsonschema.validate(table, json.loads(SCHEMA.read_text()), cls=jsonschema.Draft202012Validator)
    assert table["units"] == {"length": "mm", "force": "N", "stress": "MPa"}
    assert [row["units"] for row in table["points"]] == [
        {"length": "mm", "force": "N", "stress": "MPa"}, {"length": "m", "force": "N", "stress": "Pa"}, None]
    rows = list(csv.DictReader((tmp_path / "out" / "sweep.csv").read_text().splitlines()))
    assert [(r["length_unit"], r["force_unit"], r["stress_unit"]) for r in rows] == [
        ("mm", "N", "MPa"), ("m", "N", "Pa"), ("", "", "")]
