"""Progress off a terminal: plain lines on stderr (held for the first seconds), silenced by
--quiet, never on stdout; on a terminal the rich renderer (tested in test_pictures.py)."""

from __future__ import annotations

import io
import json
import time

import pytest
import yaml
from conftest import make_runner, square_case_dict

from contactfem.cli import main
from contactfem.progress import PlainProgress


def _run(*args):
    result = make_runner().invoke(main, [str(a) for a in args])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result


@pytest.fixture
def small_case(tmp_path):
    path = tmp_path / "small.yaml"
    path.write_text(yaml.safe_dump(square_case_dict(divisions=8)), encoding="utf-8")
    return path


@pytest.fixture
def no_hold(monkeypatch):
    """Progress lines written at once (the command line holds them for HOLD_SECONDS otherwise)."""
    monkeypatch.setattr("contactfem.progress.HOLD_SECONDS", 0.0)


def test_plain_lines_without_hold():
    stream = io.StringIO()
    progress = PlainProgress(stream, hold=0)
    for message in ("meshing", "  1089 nodes", "solving with method (4)"):
        progress(message)
    progress.close()
    progress("after close")
    lines = stream.getvalue().splitlines()
    assert len(lines) == 3
    assert lines[0].startswith("[") and lines[0].endswith("] meshing")
    assert lines[1].endswith("]   1089 nodes")  # a detail keeps its indentation


def test_plain_lines_are_held_then_written():
    """Nothing within the hold; when it has passed, the held lines and then every new one."""
    stream = io.StringIO()
    progress = PlainProgress(stream, hold=0.3)
    progress("meshing")
    assert stream.getvalue() == ""
    time.sleep(0.6)
    assert stream.getvalue().splitlines()[0].endswith("] meshing")
    progress("assembling")
    assert stream.getvalue().splitlines()[-1].endswith("] assembling")
    progress.close()


def test_a_run_ending_within_the_hold_writes_nothing():
    stream = io.StringIO()
    progress = PlainProgress(stream, hold=5.0)
    progress("meshing")
    progress.close()
    time.sleep(0.05)
    assert stream.getvalue() == ""


def test_solve_off_a_terminal_prints_stages_on_stderr(no_hold, small_case, tmp_path):
    result = _run("solve", small_case, "--out", tmp_path / "out")
    assert result.exit_code == 0, result.stderr
    stages = [line.split("] ", 1)[1] for line in result.stderr.splitlines()]
    assert stages[0] == "meshing" and "assembling" in stages
    assert any(s.startswith("solving with method (4)") for s in stages)
    assert any(s.strip().startswith("Newton 1:") for s in stages)
    assert "writing VTU" in stages and "writing H5" in stages
    assert "[" not in result.stdout.splitlines()[0]  # the summary alone on stdout


def test_quiet_silences_progress(no_hold, small_case, tmp_path):
    result = _run("solve", small_case, "--out", tmp_path / "out", "--quiet")
    assert result.exit_code == 0 and result.stderr == "" and result.stdout == ""


def test_json_keeps_stdout_clean(no_hold, small_case, tmp_path):
    """--json: stdout is the report alone (it parses), the progress goes to stderr."""
    result = _run("solve", small_case, "--out", tmp_path / "out", "--json")
    assert result.exit_code == 0, result.stderr
    assert json.loads(result.stdout)["schema_version"] >= 1
    assert "meshing" in result.stderr


def test_converge_reports_every_level(no_hold, small_case, tmp_path):
    """The study that runs longest says where it is: the reference, then each level, with the
    solves' own stages as details."""
    result = _run("converge", small_case, "--levels", "2", "--method", "positive", "--out", tmp_path / "cv")
    assert result.exit_code == 0, result.stderr
    stages = [line.split("] ", 1)[1] for line in result.stderr.splitlines()]
    assert stages[0].startswith("reference:")
    assert "level 0 of 1" in stages and "level 1 of 1" in stages
    assert any(s.startswith("  level 1 positive: h =") for s in stages)
    assert "  meshing" in stages


def test_plot_and_compare_print_progress_too(no_hold, small_case, tmp_path):
    compared = _run("compare", small_case, "--out", tmp_path / "cmp")
    assert compared.exit_code == 0 and "solving with method (5)" in compared.stderr
    plotted = _run("plot", tmp_path / "cmp")
    assert plotted.exit_code == 0 and "rendering pictures" in plotted.stderr


def test_a_quick_refusal_stays_one_line(small_case, tmp_path):
    """With the default hold, a run refused while meshing prints its one error line only."""
    data = yaml.safe_load(small_case.read_text(encoding="utf-8"))
    data["boundary"].update(top="contact", bottom="free")
    small_case.write_text(yaml.safe_dump(data), encoding="utf-8")
    result = _run("solve", small_case, "--out", tmp_path / "out")
    assert result.exit_code == 2
    assert len(result.stderr.splitlines()) == 1 and "faces away" in result.stderr
