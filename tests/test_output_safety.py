"""Output safety: --overwrite, staged writing (all files land together), SIGINT.

A run never replaces an existing result without ``--overwrite`` (exit 2, one line); the
files of one run are written into a hidden sibling directory and moved into place
together, so a failure or an interrupt while writing leaves the old result complete;
Ctrl-C exits 130 with one line and no traceback.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from contactfem.cli import main
from contactfem.errors import OutputError

ROOT = Path(__file__).resolve().parents[1]
SQUARE = ROOT / "cases" / "square.yaml"


def run(*args):
    try:
        runner = CliRunner(mix_stderr=False)
    except TypeError:
        runner = CliRunner()
    result = runner.invoke(main, [str(a) for a in args])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result


def snapshot(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file()}


def leftovers(parent: Path) -> list[str]:
    return [p.name for p in parent.rglob(".tmp-*")]


@pytest.fixture
def solved(tmp_path) -> Path:
    out = tmp_path / "results"
    result = run("solve", SQUARE, "--out", out, "--quiet")
    assert result.exit_code == 0, result.stderr
    return out


def test_solving_into_existing_results_needs_overwrite(solved):
    before = snapshot(solved)
    result = run("solve", SQUARE, "--out", solved, "--quiet")
    assert result.exit_code == 2
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ")
    assert str(solved) in lines[0] and "--overwrite" in lines[0] and "report.json" in lines[0]
    assert snapshot(solved) == before


def test_overwrite_replaces_every_file_and_leaves_no_temporary(solved):
    before = snapshot(solved)
    result = run("solve", SQUARE, "--out", solved, "--quiet", "--overwrite", "--method", "standard")
    assert result.exit_code == 0, result.stderr
    after = snapshot(solved)
    assert set(after) == set(before)
    assert json.loads(after["report.json"])["method"]["name"] == "standard"
    assert leftovers(solved.parent) == []


def test_overwrite_removes_stale_files_of_the_earlier_run(solved, tmp_path):
    """A rerun writing only report.json must not leave the earlier run's VTU/HDF5 beside it."""
    import yaml

    data = yaml.safe_load(SQUARE.read_text(encoding="utf-8"))
    data["output"] = {"files": ["json"]}
    case = tmp_path / "json_only.yaml"
    case.write_text(yaml.safe_dump(data), encoding="utf-8")
    result = run("solve", case, "--out", solved, "--quiet", "--overwrite")
    assert result.exit_code == 0, result.stderr
    assert set(snapshot(solved)) == {"report.json"}


def test_a_directory_without_results_needs_no_flag(tmp_path):
    out = tmp_path / "results"
    out.mkdir()
    (out / "notes.txt").write_text("mine", encoding="utf-8")
    result = run("solve", SQUARE, "--out", out, "--quiet")
    assert result.exit_code == 0, result.stderr
    assert (out / "notes.txt").read_text(encoding="utf-8") == "mine"


def test_a_failure_while_writing_leaves_the_old_result_complete(solved, monkeypatch):
    """The HDF5 writer fails after the VTU files were written: nothing of the new run lands."""
    import contactfem.io

    before = snapshot(solved)

    def broken(*args, **kwargs):
        raise OutputError("cannot write solution.h5: disk full (simulated)")

    monkeypatch.setattr(contactfem.io, "write_hdf5", broken)
    result = run("solve", SQUARE, "--out", solved, "--overwrite", "--method", "standard")
    assert result.exit_code == 1
    assert len(result.stderr.splitlines()) == 1 and "disk full" in result.stderr
    assert snapshot(solved) == before
    assert leftovers(solved.parent) == []


@pytest.mark.parametrize(("command", "marker"), [(("compare",), "compare.json"),
                                                  (("converge", "--levels", "2", "--method", "positive"),
                                                   "convergence.json")])
def test_compare_and_converge_refuse_existing_results(tmp_path, command, marker):
    out = tmp_path / "study"
    out.mkdir()
    (out / marker).write_text("{}", encoding="utf-8")
    result = run(*command, SQUARE, "--out", out, "--quiet")
    assert result.exit_code == 2
    assert "--overwrite" in result.stderr and len(result.stderr.splitlines()) == 1
    assert (out / marker).read_text(encoding="utf-8") == "{}"


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigint_during_the_solve_exits_130_and_keeps_earlier_results(solved, tmp_path):
    """SIGINT about a second into a several-second solve (square refined 3 times, 131k triangles)."""
    before = snapshot(solved)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    process = subprocess.Popen(
        [sys.executable, "-c", "from contactfem.cli import main; main()", "solve", str(SQUARE),
         "--refine", "3", "--out", str(solved), "--overwrite", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
    )
    time.sleep(1.2)
    if process.poll() is not None:
        pytest.skip("the solve finished before the signal could be sent")
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "Traceback" not in stderr and stdout == ""
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: interrupted"), stderr
    assert snapshot(solved) == before
    assert leftovers(solved.parent) == []
