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
from contactfem.errors import Interrupted, OutputError
from contactfem.io.atomic import LOCK_FILE

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
    """The directory's files, but for the lock every writing command keeps there."""
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file() and p.name != LOCK_FILE}


def leftovers(parent: Path) -> list[str]:
    return [p.name for p in parent.rglob(".tmp-*")]


def started_command(args: list[str], ready: Path, **popen) -> subprocess.Popen:
    """``contactfem args`` in a child process, returned once its imports are done (it touches
    ``ready`` just before the command runs): a signal timed from then lands in the command,
    not in importing SciPy, however loaded the machine (1.2 s from the start was not enough
    beside another job)."""
    driver = f"from contactfem.cli import main; open({str(ready)!r}, 'w').close(); main()"
    process = subprocess.Popen([sys.executable, "-c", driver, *args], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, **popen)
    deadline = time.monotonic() + 120
    while not ready.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    return process


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
    import contactfem.io.registry

    before = snapshot(solved)

    def broken(*args, **kwargs):
        raise OutputError("cannot write solution.h5: disk full (simulated)")

    monkeypatch.setattr(contactfem.io.registry, "write_hdf5", broken)
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
    """SIGINT a second into a several-second solve (square refined 4 times, 525k unknowns:
    refined 3 times, the whole command could end within the second on a fast machine, and
    exit 0 between the check that it still runs and the signal)."""
    before = snapshot(solved)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    process = started_command(["solve", str(SQUARE), "--refine", "4", "--out", str(solved), "--overwrite",
                               "--quiet"], tmp_path / "ready", env=env, cwd=tmp_path)
    time.sleep(1.0)
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


@pytest.mark.parametrize(("signal_error", "code", "line"), [
    (KeyboardInterrupt, 130, "error: interrupted (SIGINT)"),
    (Interrupted, 143, "error: terminated (SIGTERM)"),
])
def test_a_signal_that_surfaces_as_another_error_still_exits_as_that_signal(capsys, signal_error, code, line):
    """A signal landing while a worker thread starts (Condition.wait inside Thread.start)
    unwinds into "RuntimeError: release unlocked lock", raised while handling it: the
    command still says one line and exits 130 or 143, with no traceback. Any other error
    goes on unchanged."""
    from contactfem.cli import _interruptible

    @_interruptible
    def command():
        try:
            raise signal_error()
        except BaseException:
            raise RuntimeError("release unlocked lock")  # its __context__ is the signal's error

    with pytest.raises(SystemExit) as exit_info:
        command()
    assert exit_info.value.code == code
    err = capsys.readouterr().err
    assert err.startswith(line) and len(err.splitlines()) == 1

    @_interruptible
    def failing():
        raise RuntimeError("a plain failure")

    with pytest.raises(RuntimeError, match="a plain failure"):
        failing()


def _writes_after(event, directory: Path):
    """A writing command that runs ``event`` while its result is staged, then switches it in."""
    from contactfem.cli import _interruptible
    from contactfem.io.atomic import claimed_directory

    @_interruptible
    def command():
        with claimed_directory(directory, overwrite=True) as claim:
            with claim.stage() as staging:
                (staging / "report.json").write_text('{"new": true}', encoding="utf-8")
                event()
        return "done"

    return command


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize(("signal_number", "code", "line"), [
    (signal.SIGINT, 130, "error: interrupted (SIGINT); no result was switched in"),
    (signal.SIGTERM, 143, "error: terminated (SIGTERM); no result was switched in"),
])
def test_a_signal_whose_exception_a_finalizer_swallows_still_stops_the_command(
        tmp_path, capsys, signal_number, code, line):
    """A signal that lands while the collector runs a finalizer (CI saw it in CHOLMOD's
    factor being freed) raises its exception there, where Python prints and drops it: the
    command must still switch nothing in, say one line and exit as that signal."""
    import weakref

    out = tmp_path / "results"
    out.mkdir()
    (out / "report.json").write_text("{}", encoding="utf-8")
    before = snapshot(out)
    swallowed = []

    def signal_inside_a_finalizer():
        def fire():
            signal.raise_signal(signal_number)
            swallowed.append("not reached")  # the handler raised above, inside the finalizer

        class Factor:
            pass

        factor = Factor()
        weakref.finalize(factor, fire)
        del factor  # the finalizer runs here; its exception goes to sys.unraisablehook

    with pytest.raises(SystemExit) as exit_info:
        _writes_after(signal_inside_a_finalizer, out)()
    assert swallowed == []
    assert exit_info.value.code == code
    err = capsys.readouterr().err
    assert err.startswith(line) and len(err.splitlines()) == 1, err
    assert snapshot(out) == before
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] in ([], [LOCK_FILE])


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_signal_after_the_switch_says_the_results_are_in(tmp_path, capsys):
    """Once the result is switched in, a signal still ends the command as that signal, but
    the line says the new results are complete rather than that none was switched in."""
    from contactfem.cli import _interruptible
    from contactfem.io.atomic import claimed_directory

    out = tmp_path / "results"

    @_interruptible
    def command():
        with claimed_directory(out) as claim:
            with claim.stage() as staging:
                (staging / "report.json").write_text('{"new": true}', encoding="utf-8")
        signal.raise_signal(signal.SIGINT)

    with pytest.raises(SystemExit) as exit_info:
        command()
    assert exit_info.value.code == 130
    err = capsys.readouterr().err
    assert err.startswith("error: interrupted (SIGINT); the results were switched in") and len(err.splitlines()) == 1
    assert json.loads((out / "report.json").read_text(encoding="utf-8")) == {"new": True}


def test_a_record_of_a_signal_never_reaches_library_callers(tmp_path):
    """Outside a command (the library used from Python), a signal recorded by an earlier
    command stops nothing: atomic writes go through."""
    from contactfem import interrupts
    from contactfem.io.atomic import atomic_write_text

    interrupts._received.append(signal.SIGINT)  # as an earlier command would have left it
    try:
        atomic_write_text(tmp_path / "a.txt", "written")
    finally:
        interrupts._received.clear()
    assert (tmp_path / "a.txt").read_text(encoding="utf-8") == "written"


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize(("signal_number", "code", "word"), [(signal.SIGTERM, 143, "terminated"),
                                                             (signal.SIGINT, 130, "interrupted")])
def test_a_signal_during_the_solve_of_every_writing_command_keeps_earlier_results(
        tmp_path, signal_number, code, word):
    """compare and adapt as well as solve: one line, 130 or 143, the old files intact."""
    for command in (["compare", "--refine", "3"], ["adapt", "--max-unknowns", "400000"]):
        out = tmp_path / command[0]
        out.mkdir()
        (out / "report.json").write_text("{}", encoding="utf-8")
        (out / "compare.json").write_text("{}", encoding="utf-8")
        (out / "adapt.json").write_text("{}", encoding="utf-8")
        before = snapshot(out)
        process = started_command([command[0], str(SQUARE), *command[1:], "--out", str(out), "--overwrite",
                                   "--quiet"], tmp_path / f"ready-{command[0]}", cwd=tmp_path)
        time.sleep(1.0)
        if process.poll() is not None:
            pytest.skip(f"{command[0]} finished before the signal could be sent")
        process.send_signal(signal_number)
        stdout, stderr = process.communicate(timeout=60)
        assert process.returncode == code, stderr
        lines = stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"error: {word}"), stderr
        assert snapshot(out) == before
        assert [p.name for p in out.iterdir() if p.name.startswith(".tmp-")] == []


def test_a_second_run_into_a_directory_being_written_is_refused_at_once(tmp_path):
    """The lock is held from before the work starts: the second run fails in one line, writes nothing."""
    from contactfem.io.atomic import claimed_directory

    out = tmp_path / "results"
    with claimed_directory(out):
        result = run("solve", SQUARE, "--out", out, "--quiet")
    assert result.exit_code == 1
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "another contactfem run is writing into it" in lines[0]
    assert snapshot(out) == {}


def test_concurrent_solves_into_one_directory_never_mix(tmp_path):
    """Two processes racing for one directory: one writes, the other is refused; the files
    that land are all from one run (same method in report.json and solution.h5)."""
    from contactfem.io import read_hdf5

    out = tmp_path / "results"
    processes = [subprocess.Popen(
        [sys.executable, "-c", "from contactfem.cli import main; main()", "solve", str(SQUARE), "--refine", "1",
         "--method", method, "--out", str(out), "--overwrite", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path) for method in ("positive", "standard")]
    codes = [p.wait(timeout=120) for p in processes]
    assert sorted(codes) in ([0, 0], [0, 1]), codes
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert read_hdf5(out / "solution.h5")["attrs"]["method"] == report["method"]["name"]


def test_a_switch_over_cut_short_is_completed_by_the_next_command(solved, tmp_path):
    """A run killed after its files were decided but before all were moved: the next command
    that claims the directory finishes the move, so the directory holds one run, never a mix."""
    import shutil

    from contactfem.io.atomic import SWITCH_FILE, TEMP_PREFIX

    newer = tmp_path / "newer"
    assert run("solve", SQUARE, "--out", newer, "--method", "standard", "--quiet").exit_code == 0
    staging = solved / f"{TEMP_PREFIX}999999-deadbeef.staging"
    staging.mkdir()
    names = sorted(p.name for p in newer.iterdir() if p.is_file() and p.name != LOCK_FILE)
    for name in names:
        shutil.copy(newer / name, staging / name)
    (staging / SWITCH_FILE).write_text(json.dumps({"files": names, "replaces": []}), encoding="utf-8")
    # The killed run had moved the first two files already.
    for name in names[:2]:
        os.replace(staging / name, solved / name)
    result = run("plot", solved, "--quiet")
    assert result.exit_code == 0, result.stderr
    assert not staging.exists()
    for name in names:
        assert (solved / name).read_bytes() == (newer / name).read_bytes(), name


def test_an_undecided_staging_area_of_a_killed_run_is_removed(solved):
    """SIGKILL before the decision leaves a staging area without a switch file: it is discarded."""
    from contactfem.io.atomic import TEMP_PREFIX

    before = snapshot(solved)
    staging = solved / f"{TEMP_PREFIX}999999-cafebabe.staging"
    staging.mkdir()
    (staging / "report.json").write_text("{}", encoding="utf-8")
    (solved / f"{TEMP_PREFIX}999999-0badf00d.solution.h5").write_bytes(b"partial")
    result = run("solve", SQUARE, "--out", solved, "--quiet", "--overwrite")
    assert result.exit_code == 0, result.stderr
    assert not staging.exists() and leftovers(solved) == []
    assert set(snapshot(solved)) == set(before)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_a_writable_directory_inside_a_read_only_parent_is_written(tmp_path):
    """Staging happens inside the output directory, so its parent need not be writable."""
    parent = tmp_path / "locked"
    out = parent / "results"
    out.mkdir(parents=True)
    parent.chmod(0o555)
    try:
        result = run("solve", SQUARE, "--out", out, "--quiet")
    finally:
        parent.chmod(0o755)
    assert result.exit_code == 0, result.stderr
    assert "report.json" in snapshot(out)


def test_an_output_path_that_is_a_file_is_refused_before_solving(tmp_path, monkeypatch):
    import contactfem.solve

    target = tmp_path / "results"
    target.write_text("not a directory", encoding="utf-8")

    def no_solve(*args, **kwargs):
        raise AssertionError("the solve started")

    monkeypatch.setattr(contactfem.solve, "solve_case", no_solve)
    result = run("solve", SQUARE, "--out", target, "--quiet")
    assert result.exit_code == 2
    assert len(result.stderr.splitlines()) == 1 and "--out" in result.stderr and str(target) in result.stderr
    assert target.read_text(encoding="utf-8") == "not a directory"


def test_plot_without_h5_is_refused_before_anything_is_touched(solved, tmp_path):
    import yaml

    before = snapshot(solved)
    data = yaml.safe_load(SQUARE.read_text(encoding="utf-8"))
    data["output"] = {"files": ["vtu", "json"]}
    case = tmp_path / "no_h5.yaml"
    case.write_text(yaml.safe_dump(data), encoding="utf-8")
    result = run("solve", case, "--out", solved, "--overwrite", "--plot", "--quiet")
    assert result.exit_code == 2
    assert len(result.stderr.splitlines()) == 1 and "h5" in result.stderr
    assert snapshot(solved) == before


def test_xdmf_without_its_archive_is_refused_by_the_case_reader(tmp_path):
    import yaml

    data = yaml.safe_load(SQUARE.read_text(encoding="utf-8"))
    data["output"] = {"files": ["xdmf"]}
    case = tmp_path / "xdmf_only.yaml"
    case.write_text(yaml.safe_dump(data), encoding="utf-8")
    out = tmp_path / "out"
    result = run("solve", case, "--out", out, "--quiet")
    assert result.exit_code == 2
    line = result.stderr.strip()
    assert "xdmf_only.yaml" in line and "output.files" in line and "h5" in line
    assert not out.exists()


def test_adapt_refuses_existing_results_and_a_failure_leaves_them_whole(tmp_path, monkeypatch):
    import contactfem.io.registry

    out = tmp_path / "adapt"
    first = run("adapt", SQUARE, "--max-unknowns", "600", "--out", out, "--quiet")
    assert first.exit_code == 0, first.stderr
    before = snapshot(out)
    again = run("adapt", SQUARE, "--max-unknowns", "600", "--out", out, "--quiet")
    assert again.exit_code == 2 and "--overwrite" in again.stderr
    assert snapshot(out) == before

    def broken(*args, **kwargs):
        raise OutputError("cannot write solution.h5: disk full (simulated)")

    monkeypatch.setattr(contactfem.io.registry, "write_hdf5", broken)
    failed = run("adapt", SQUARE, "--max-unknowns", "900", "--out", out, "--quiet", "--overwrite")
    assert failed.exit_code == 1 and "disk full" in failed.stderr
    assert snapshot(out) == before


def test_the_directory_removal_after_a_refusal_needs_the_lock(tmp_path, monkeypatch):
    """A loser that believed it created the directory (the race) leaves it and the lock alone."""
    import contactfem.io.atomic as atomic

    out = tmp_path / "raced"
    with atomic.claimed_directory(out):
        monkeypatch.setattr(atomic, "_missing_ancestors", lambda directory: [directory])
        with pytest.raises(OutputError, match="another contactfem run"):
            with atomic.claimed_directory(out):
                pass
        assert out.is_dir() and (out / LOCK_FILE).exists()
