"""The switch-over of a result into its output directory (contactfem/io/atomic.py).

Whatever an output directory holds, a run never deletes or writes outside it (but for its own
exchange sibling), never removes a user's file, never trusts a name read from disk, never
writes through a directory or a lock swapped for a symbolic link, leaves no lock behind, and
switches a result in as one step: a reader sees the old result or the new one, never a mix,
whatever step a run is killed at.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import contactfem.io.atomic as atomic
from contactfem.io import dirfd, journal
from contactfem.errors import ExistingResultError, OutputError
from contactfem.io.atomic import (
    EXCHANGE_FILE,
    LOCK_FILE,
    STAGING_MARKER,
    SWITCH_FILE,
    TEMP_PREFIX,
    claimed_directory,
    is_output_name,
    remove_leftover_temporaries,
)

from conftest import make_runner

ROOT = Path(__file__).resolve().parents[1]
SQUARE = ROOT / "cases" / "square.yaml"

#: Two results of three and two files: a reader must see all of one or all of the other.
OLD = {"report.json": "old", "solution.h5": "old", "contact.csv": "old"}
NEW = {"report.json": "new", "solution.h5": "new"}
REPLACES = ("report.json", "solution.h5", "contact.csv", "solution.vtu")

needs_exchange = pytest.mark.skipif(dirfd.renameat2_function is None, reason="no renameat2 here")


def invoke(*args):
    result = make_runner().invoke(__import__("contactfem.cli", fromlist=["main"]).main, [str(a) for a in args])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result


def one_line(result, code: int) -> str:
    assert result.exit_code == code, (result.exit_code, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


def result_files(directory: Path) -> dict[str, str]:
    """What a reader listing the directory finds of a result: its visible files' contents."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        found = {}
        for name in os.listdir(fd):
            if name.startswith(".") or name not in REPLACES:
                continue
            file = os.open(name, os.O_RDONLY, dir_fd=fd)
            try:
                found[name] = os.read(file, 100).decode()
            finally:
                os.close(file)
        return found
    finally:
        os.close(fd)


def make_result(directory: Path, files: dict[str, str], **stage) -> None:
    with claimed_directory(directory) as claim:
        with claim.stage(replaces=REPLACES, last="report.json", **stage) as staging:
            for name, text in files.items():
                (staging / name).write_text(text, encoding="utf-8")


def everything(directory: Path) -> dict[str, bytes | None]:
    """Every entry under ``directory`` (None for directories), by relative path."""
    return {str(p.relative_to(directory)): (None if p.is_dir() else p.read_bytes())
            for p in sorted(directory.rglob("*"))}


def mechanism_leftovers(parent: Path) -> list[str]:
    return sorted(str(p.relative_to(parent)) for p in parent.rglob("*")
                  if p.name.startswith(TEMP_PREFIX) or p.name in (LOCK_FILE, EXCHANGE_FILE, STAGING_MARKER,
                                                                  SWITCH_FILE))


@pytest.fixture
def out(tmp_path) -> Path:
    directory = tmp_path / "out"
    directory.mkdir()
    (directory / "notes.txt").write_text("mine", encoding="utf-8")
    make_result(directory, OLD)
    return directory


@pytest.fixture(params=["exchange", "moves"])
def mode(request, monkeypatch) -> str:
    """Every behaviour holds whether the result is switched in by an exchange or by moves."""
    if request.param == "exchange" and dirfd.renameat2_function is None:
        pytest.skip("no renameat2 here")
    if request.param == "moves":
        monkeypatch.setattr(dirfd, "renameat2_function", None)
    return request.param


# ----------------------------------------------------------------------------- names read from disk


@pytest.mark.parametrize("name", ["report.json", "solution.h5", "path-01.vtu", "path-1-contact.vtu",
                                  "compare-positive.vtu", "convergence-standard-level0-contact.vtu",
                                  "convergence-positive.pvd", "sweep.png", "solution-xdmf.h5"])
def test_the_writers_names_are_output_names(name):
    assert is_output_name(name)


@pytest.mark.parametrize("name", ["../victim.txt", "/etc/passwd", "sub/report.json", "..", ".", "", "notes.txt",
                                  ".contactfem.lock", "report.json\x00", "report.json/", "path-../x.vtu",
                                  "path-a\nb.vtu", "a\\report.json", 5, None, ["report.json"]])
def test_a_name_that_is_not_a_plain_output_name_is_refused(name):
    assert not is_output_name(name)


def test_every_name_the_commands_write_is_an_output_name():
    """OUTPUT_NAMES is the list a journal is checked against: every file the registry, the
    studies and the sweep name must be on it (a new output file goes there too)."""
    from contactfem import sweep
    from contactfem.io import registry

    literals = [n for n in registry.RESULT_FILES if not journal.is_pattern(n)]
    literals += [registry.COMPARE_JSON, registry.COMPARE_PNG, registry.CONVERGENCE_JSON, registry.CONVERGENCE_CSV,
                 *registry.CONVERGENCE_PNGS, registry.ADAPT_JSON, *sweep.SWEEP_FILES, *registry.PICTURES,
                 "compare.pvd", "convergence-positive.pvd"]
    assert [n for n in literals if not is_output_name(n)] == []
    assert set(n for n in registry.RESULT_FILES if journal.is_pattern(n)) <= set(atomic.OUTPUT_NAMES)


def _leftover_staging(directory: Path, journal: dict, pid: int = 999999, token: str = "deadbeef") -> Path:
    staging = directory / f"{TEMP_PREFIX}{pid}-{token}.staging"
    staging.mkdir()
    (staging / SWITCH_FILE).write_text(json.dumps(journal), encoding="utf-8")
    return staging


@pytest.mark.parametrize("replaces", [["../victim.txt", "report.json"], ["/VICTIM", "report.json"],
                                      ["notes.txt"], [".."], ["sub/report.json"], "report.json", [5], None])
def test_a_journal_with_a_name_that_is_not_an_output_name_is_never_executed(out, tmp_path, replaces):
    """A leftover .switch.json listing ../victim.txt made the next solve delete it, and
    report.json, then refuse for lack of --overwrite. Now the journal is ignored: nothing is
    deleted, in the directory or outside it, and the refusal is the only effect."""
    victim = tmp_path / "victim.txt"
    victim.write_text("outside", encoding="utf-8")
    absolute = Path("/VICTIM")
    staging = _leftover_staging(out, {"files": [], "replaces": replaces})
    before = everything(out)
    with pytest.raises(ExistingResultError):
        with claimed_directory(out, markers=("report.json",), overwrite=False):
            pass
    assert victim.read_text(encoding="utf-8") == "outside" and not absolute.exists()
    del before[str(staging.relative_to(out))]
    del before[str((staging / SWITCH_FILE).relative_to(out))]
    assert everything(out) == before  # the ignored staging area of a dead run goes, nothing else


def test_a_journal_naming_a_file_outside_is_ignored_by_solve(tmp_path):
    """The case as reported, through the command line: exit 2 for lack of --overwrite, one
    line, and the victim, the report and the result all intact."""
    out = tmp_path / "results"
    assert invoke("solve", SQUARE, "--out", out, "--quiet").exit_code == 0
    victim = tmp_path / "victim.txt"
    victim.write_text("outside", encoding="utf-8")
    _leftover_staging(out, {"files": [], "replaces": ["../victim.txt", "report.json"]})
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    line = one_line(invoke("solve", SQUARE, "--out", out, "--quiet"), 2)
    assert str(out) in line and "--overwrite" in line
    assert victim.read_text(encoding="utf-8") == "outside"
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before


def test_a_journal_moving_a_file_from_outside_is_ignored(out, tmp_path):
    (tmp_path / "elsewhere.json").write_text("outside", encoding="utf-8")
    staging = _leftover_staging(out, {"files": ["../elsewhere.json"], "replaces": []})
    before = result_files(out)
    with claimed_directory(out):
        pass
    assert (tmp_path / "elsewhere.json").read_text(encoding="utf-8") == "outside"
    assert result_files(out) == before and not staging.exists()


def test_a_journal_whose_token_is_another_runs_is_ignored(out):
    staging = _leftover_staging(out, {"token": "1234-abcdef01", "files": [], "replaces": ["report.json"]})
    with claimed_directory(out):
        pass
    assert result_files(out) == OLD and not staging.exists()


def test_a_staging_area_that_is_not_provably_a_runs_is_left_alone(out):
    """A directory named like a staging area, but holding a subdirectory and no marker, is not
    one this mechanism made: it stays, journal and all, and its journal is not executed."""
    staging = _leftover_staging(out, {"files": [], "replaces": ["notes.txt"]})
    (staging / "data").mkdir()
    (staging / "data" / "mine.txt").write_text("mine", encoding="utf-8")
    make_result(out, NEW)
    assert (staging / "data" / "mine.txt").read_text(encoding="utf-8") == "mine"
    assert (out / "notes.txt").read_text(encoding="utf-8") == "mine"


def test_an_exchange_journal_in_the_directory_never_removes_what_is_not_its_old_directory(out, tmp_path):
    """.contactfem-exchange.json names a sibling by its token; a sibling without that run's
    marked staging area inside (or a token that is not one) is never touched."""
    decoy = tmp_path / f"{TEMP_PREFIX}4242-abcdef01.out.exchange"
    decoy.mkdir()
    (decoy / "precious.txt").write_text("keep", encoding="utf-8")
    for token in ("4242-abcdef01", "../../x", "4242-abcdef01/.."):
        (out / EXCHANGE_FILE).write_text(json.dumps({"token": token, "files": ["report.json"], "replaces": []}),
                                         encoding="utf-8")
        with claimed_directory(out):
            pass
        assert (decoy / "precious.txt").read_text(encoding="utf-8") == "keep"
        assert not (out / EXCHANGE_FILE).exists()
    assert result_files(out) == OLD


def test_a_sibling_is_removed_only_when_its_journal_proves_it_and_its_process_is_gone(out, tmp_path):
    def sibling(pid: int, token: str, journal: dict | None) -> Path:
        path = tmp_path / f"{TEMP_PREFIX}{pid}-{token}.out.exchange"
        path.mkdir()
        (path / "report.json").write_text("new", encoding="utf-8")
        if journal is not None:
            (path / EXCHANGE_FILE).write_text(json.dumps(journal), encoding="utf-8")
        return path

    proven = sibling(999999, "abcdef01", {"token": "999999-abcdef01", "files": ["report.json"], "replaces": []})
    alive = sibling(os.getpid(), "abcdef02", {"token": f"{os.getpid()}-abcdef02", "files": [], "replaces": []})
    unproven = sibling(999999, "abcdef03", None)
    mismatched = sibling(999999, "abcdef04", {"token": "999999-abcdef05", "files": [], "replaces": []})
    other = tmp_path / f"{TEMP_PREFIX}999999-abcdef06.other.exchange"
    other.mkdir()
    (other / EXCHANGE_FILE).write_text(json.dumps({"token": "999999-abcdef06", "files": [], "replaces": []}),
                                       encoding="utf-8")
    with claimed_directory(out):
        pass
    assert not proven.exists()
    assert alive.exists() and unproven.exists() and mismatched.exists() and other.exists()
    assert result_files(out) == OLD


# ----------------------------------------------------------------------------- the user's files


def test_an_ordinary_solve_keeps_the_users_dot_tmp_files(tmp_path):
    """The clean-up removed everything named .tmp-*: .tmp-notes.txt and .tmp-data/ went with
    an ordinary solve. Only the mechanism's own leftovers go now."""
    out = tmp_path / "results"
    out.mkdir()
    mine = {".tmp-notes.txt": "notes", ".tmp-data/a.txt": "a", ".tmp-data/b/c.txt": "c",
            ".tmp-1-abcdef01.report.json": "pid 1 is alive", ".tmp-999999-XYZ.report.json": "not a token",
            ".tmp-999999-abcdef01.staging/sub/x.txt": "a directory inside: not a staging area",
            ".tmp-999999-abcdef01": "no name after the token"}
    for name, text in mine.items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(text, encoding="utf-8")
    (out / f"{TEMP_PREFIX}999999-0badf00d.solution.h5").write_bytes(b"a dead run's temporary")
    assert invoke("solve", SQUARE, "--out", out, "--quiet").exit_code == 0
    for name, text in mine.items():
        assert (out / name).read_text(encoding="utf-8") == text, name
    assert not (out / f"{TEMP_PREFIX}999999-0badf00d.solution.h5").exists()
    assert (out / "report.json").is_file() and not (out / LOCK_FILE).exists()


def test_a_temporary_of_a_running_process_is_kept(out):
    live = out / f"{TEMP_PREFIX}{os.getppid()}-abcdef01.report.json"
    live.write_text("being written", encoding="utf-8")
    with claimed_directory(out):
        pass
    assert live.read_text(encoding="utf-8") == "being written"


def test_remove_leftover_temporaries_removes_only_dead_runs_files(tmp_path):
    names = {f"{TEMP_PREFIX}999999-abcdef01.p.json": False, f"{TEMP_PREFIX}{os.getpid()}-abcdef01.p.json": True,
             ".tmp-notes.txt": True, "p.json": True}
    for name in names:
        (tmp_path / name).write_text("x", encoding="utf-8")
    (tmp_path / f"{TEMP_PREFIX}999999-abcdef02.dir").mkdir()
    assert remove_leftover_temporaries(tmp_path) == [f"{TEMP_PREFIX}999999-abcdef01.p.json"]
    assert {n: (tmp_path / n).exists() for n in names} == names
    assert (tmp_path / f"{TEMP_PREFIX}999999-abcdef02.dir").is_dir()


def test_users_files_and_subdirectories_stay_as_they_were(out, mode):
    sub = out / "data" / "deeper"
    sub.mkdir(parents=True)
    (sub / "x.bin").write_bytes(b"\x00\x01")
    os.symlink("notes.txt", out / "link-to-notes")
    (out / "data").chmod(0o750)
    before = {name: os.stat(out / name, follow_symlinks=False).st_ino for name in ("notes.txt", "link-to-notes")}
    make_result(out, NEW)
    assert result_files(out) == NEW
    assert (out / "notes.txt").read_text(encoding="utf-8") == "mine"
    assert (sub / "x.bin").read_bytes() == b"\x00\x01"
    assert os.readlink(out / "link-to-notes") == "notes.txt"
    assert (out / "data").stat().st_mode & 0o7777 == 0o750
    assert {name: os.stat(out / name, follow_symlinks=False).st_ino for name in before} == before  # the same files
    assert mechanism_leftovers(out.parent) == []


def test_a_file_that_is_not_a_result_is_never_replaced_even_if_listed(out, mode):
    """A pattern deletes only files a writer could have made, and a directory is never deleted."""
    (out / "path-my notes.vtu").write_text("mine", encoding="utf-8")
    (out / "path-01.vtu").mkdir()
    with claimed_directory(out) as claim:
        with claim.stage(replaces=("path-*.vtu",)) as staging:
            (staging / "report.json").write_text("new", encoding="utf-8")
    assert (out / "path-my notes.vtu").read_text(encoding="utf-8") == "mine"
    assert (out / "path-01.vtu").is_dir()


# ----------------------------------------------------------------------------- the directory held


def _swap_for_link(out: Path, other: Path) -> None:
    os.rename(out, out.with_name("moved"))
    os.symlink(other, out)


@pytest.mark.parametrize("swap", ["link", "directory", "gone"])
def test_a_directory_swapped_during_the_run_is_refused(tmp_path, mode, swap):
    """The output directory renamed away and replaced by a symbolic link to another result
    during a run: the run exited 0 and replaced the other result's files. It is refused now,
    the other result untouched, nothing written through the link."""
    other = tmp_path / "other"
    other.mkdir()
    make_result(other, OLD)
    other_before = everything(other)
    out = tmp_path / "out"
    with pytest.raises(OutputError, match="moved or replaced during the run") as error:
        with claimed_directory(out) as claim:
            with claim.stage(replaces=REPLACES) as staging:
                (staging / "report.json").write_text("new", encoding="utf-8")
                if swap == "link":
                    _swap_for_link(out, other)
                elif swap == "directory":
                    os.rename(out, tmp_path / "moved")
                    out.mkdir()
                else:
                    os.rename(out, tmp_path / "moved")
    assert str(out) in str(error.value) and len(str(error.value).splitlines()) == 1
    assert everything(other) == other_before
    assert everything(tmp_path / "moved") == {}  # no staging area, no lock left in the held directory
    assert mechanism_leftovers(tmp_path) == []


def test_solve_refuses_a_directory_swapped_for_a_link_to_another_result(tmp_path, monkeypatch):
    import contactfem.solve

    other = tmp_path / "other"
    assert invoke("solve", SQUARE, "--out", other, "--quiet").exit_code == 0
    other_before = everything(other)
    out = tmp_path / "out"
    real = contactfem.solve.solve_case

    def swapping(*args, **kwargs):
        result = real(*args, **kwargs)
        _swap_for_link(out, other)
        return result

    monkeypatch.setattr(contactfem.solve, "solve_case", swapping)
    line = one_line(invoke("solve", SQUARE, "--out", out, "--quiet"), 1)
    assert str(out) in line and "moved or replaced" in line
    assert everything(other) == other_before


@pytest.mark.parametrize("kind", ["dangling", "to a file", "directory", "fifo"])
def test_a_lock_that_is_not_a_plain_file_is_refused(tmp_path, kind):
    """A dangling .contactfem.lock symlink made the run create its target outside the
    directory. A lock that is a link, a directory or a FIFO is refused in one line now."""
    out = tmp_path / "out"
    out.mkdir()
    target = tmp_path / "target"
    if kind == "dangling":
        os.symlink(target, out / LOCK_FILE)
    elif kind == "to a file":
        target.write_text("keep", encoding="utf-8")
        os.symlink(target, out / LOCK_FILE)
    elif kind == "directory":
        (out / LOCK_FILE).mkdir()
    else:
        os.mkfifo(out / LOCK_FILE)
    line = one_line(invoke("solve", SQUARE, "--out", out, "--quiet"), 1)
    assert str(out) in line and LOCK_FILE in line
    if kind == "dangling":
        assert not target.exists()
    elif kind == "to a file":
        assert target.read_text(encoding="utf-8") == "keep"
    assert [p.name for p in out.iterdir()] == [LOCK_FILE]


# ----------------------------------------------------------------------------- the lock


def test_the_lock_is_removed_on_every_way_out(tmp_path, mode):
    out = tmp_path / "out"
    make_result(out, OLD)
    assert not (out / LOCK_FILE).exists()
    for stop in (RuntimeError("failed"), KeyboardInterrupt(), OutputError("cannot write")):
        with pytest.raises(type(stop)):
            with claimed_directory(out) as claim:
                with claim.stage() as staging:
                    (staging / "report.json").write_text("new", encoding="utf-8")
                    raise stop
        assert not (out / LOCK_FILE).exists(), stop
    with pytest.raises(ExistingResultError):
        with claimed_directory(out, markers=("report.json",), overwrite=False):
            pass
    assert not (out / LOCK_FILE).exists()
    assert result_files(out) == OLD and mechanism_leftovers(tmp_path) == []


def test_a_failed_solve_leaves_no_lock(tmp_path, monkeypatch):
    import contactfem.io.registry

    out = tmp_path / "results"
    assert invoke("solve", SQUARE, "--out", out, "--quiet").exit_code == 0

    def broken(*args, **kwargs):
        raise OutputError("cannot write solution.h5: disk full (simulated)")

    monkeypatch.setattr(contactfem.io.registry, "write_hdf5", broken)
    one_line(invoke("solve", SQUARE, "--out", out, "--quiet", "--overwrite"), 1)
    assert not (out / LOCK_FILE).exists() and mechanism_leftovers(tmp_path) == []


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigterm_during_a_solve_leaves_no_lock(tmp_path):
    out = tmp_path / "results"
    ready = tmp_path / "ready"
    driver = f"from contactfem.cli import main; open({str(ready)!r}, 'w').close(); main()"
    process = subprocess.Popen([sys.executable, "-c", driver, "solve", str(SQUARE), "--refine", "4", "--out",
                                str(out), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               cwd=tmp_path)
    deadline = time.monotonic() + 120
    while not ready.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(1.0)
    if process.poll() is not None:
        pytest.skip("the solve finished before the signal could be sent")
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 143, stderr
    assert not out.exists() or [p.name for p in out.iterdir()] == []
    assert mechanism_leftovers(tmp_path) == []


def test_a_stale_lock_of_a_dead_run_does_not_block(out):
    (out / LOCK_FILE).write_text("999999\n", encoding="utf-8")
    make_result(out, NEW)
    assert result_files(out) == NEW and not (out / LOCK_FILE).exists()


def test_a_lock_held_by_a_live_process_refuses_until_it_dies(out):
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import fcntl, os, sys, time
        fd = os.open({str(out / LOCK_FILE)!r}, os.O_RDWR | os.O_CREAT)
        fcntl.flock(fd, fcntl.LOCK_EX)
        print("held", flush=True)
        time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(OutputError, match="another contactfem run is writing into it") as error:
            make_result(out, NEW)
        assert str(out) in str(error.value)
        assert result_files(out) == OLD
    finally:
        holder.kill()
        holder.wait()
    make_result(out, NEW)  # its flock went with it
    assert result_files(out) == NEW and not (out / LOCK_FILE).exists()


# ----------------------------------------------------------------------------- one step


@needs_exchange
def test_the_switch_exchanges_the_directory_and_keeps_its_metadata(out):
    out.chmod(0o751)
    inode = out.stat().st_ino
    make_result(out, NEW)
    assert out.stat().st_ino != inode  # a new directory took the name in one step
    assert out.stat().st_mode & 0o7777 == 0o751
    assert result_files(out) == NEW and (out / "notes.txt").read_text(encoding="utf-8") == "mine"
    assert mechanism_leftovers(out.parent) == []


@needs_exchange
def test_solve_switches_by_exchange_and_removes_the_earlier_runs_files(tmp_path):
    import yaml

    out = tmp_path / "results"
    assert invoke("solve", SQUARE, "--out", out, "--quiet").exit_code == 0
    (out / "notes.txt").write_text("mine", encoding="utf-8")
    inode = out.stat().st_ino
    data = yaml.safe_load(SQUARE.read_text(encoding="utf-8"))
    data["output"] = {"files": ["json"]}
    case = tmp_path / "json_only.yaml"
    case.write_text(yaml.safe_dump(data), encoding="utf-8")
    assert invoke("solve", case, "--out", out, "--quiet", "--overwrite").exit_code == 0
    assert out.stat().st_ino != inode
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "report.json"]
    assert mechanism_leftovers(tmp_path) == []


@pytest.mark.parametrize("where", ["symlinked", "working directory"])
def test_where_no_exchange_can_be_made_the_files_are_moved_in(out, monkeypatch, where):
    """A symlinked output directory stays a link (the exchange would replace it), and a
    directory holding the working directory keeps its inode."""
    target = out
    if where == "symlinked":
        link = out.with_name("link")
        os.symlink(out, link)
        target = link
    else:
        monkeypatch.chdir(out)
    inode = out.stat().st_ino
    make_result(target, NEW)
    assert out.stat().st_ino == inode
    assert result_files(out) == NEW
    if where == "symlinked":
        assert target.is_symlink()
    assert mechanism_leftovers(out.parent) == []


@needs_exchange
def test_an_exchange_the_file_system_refuses_falls_back_to_moves(out, monkeypatch):
    def refused(*args):
        raise OSError(22, "Invalid argument")

    monkeypatch.setattr(dirfd, "exchange", refused)
    inode = out.stat().st_ino
    make_result(out, NEW)
    assert out.stat().st_ino == inode and result_files(out) == NEW
    assert mechanism_leftovers(out.parent) == []


@needs_exchange
@pytest.mark.parametrize("change", ["new file", "replaced file", "new file in a subdirectory"])
def test_what_another_program_writes_while_the_copy_is_built_is_carried_over(out, monkeypatch, change):
    (out / "data").mkdir()

    def meanwhile(step):
        if step != "sibling filled":
            return
        if change == "new file":
            (out / "late.txt").write_text("late", encoding="utf-8")
        elif change == "replaced file":
            (out / "notes.tmp").write_text("edited", encoding="utf-8")
            os.replace(out / "notes.tmp", out / "notes.txt")
        else:
            (out / "data" / "late.txt").write_text("late", encoding="utf-8")

    monkeypatch.setattr(dirfd, "reached", meanwhile)
    make_result(out, NEW)
    assert result_files(out) == NEW
    if change == "new file":
        assert (out / "late.txt").read_text(encoding="utf-8") == "late"
    elif change == "replaced file":
        assert (out / "notes.txt").read_text(encoding="utf-8") == "edited"
    else:
        assert (out / "data" / "late.txt").read_text(encoding="utf-8") == "late"
    assert mechanism_leftovers(out.parent) == []


@needs_exchange
@pytest.mark.parametrize("step", ["sibling made", "sibling filled"])
def test_an_error_while_the_copy_is_built_leaves_the_old_result_and_no_copy(out, monkeypatch, step):
    def failing(reached):
        if reached == step:
            raise KeyboardInterrupt

    monkeypatch.setattr(dirfd, "reached", failing)
    with pytest.raises(KeyboardInterrupt):
        make_result(out, NEW)
    assert result_files(out) == OLD and mechanism_leftovers(out.parent) == []


KILLED_RUN = """
import os, signal, sys
from pathlib import Path
import contactfem.io.atomic as atomic
from contactfem.io import dirfd, journal

out, step, mode = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
if mode == "moves":
    dirfd.renameat2_function = None

def reached(name):
    if name == step:
        os.kill(os.getpid(), signal.SIGKILL)

dirfd.reached = reached
with atomic.claimed_directory(out) as claim:
    with claim.stage(replaces={replaces!r}, last="report.json") as staging:
        for name, text in {new!r}.items():
            (staging / name).write_text(text)
"""

EXCHANGE_STEPS = ["sibling made", "sibling filled", "exchanged", "carried over", "removed the old directory"]
MOVE_STEPS = ["decided", "moved solution.h5", "moved report.json", "moved in"]


def _killed_at(out: Path, step: str, mode: str) -> None:
    script = KILLED_RUN.format(replaces=REPLACES, new=NEW)
    run = subprocess.run([sys.executable, "-c", script, str(out), step, mode], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == -signal.SIGKILL, run.stderr


@needs_exchange
@pytest.mark.parametrize("step", EXCHANGE_STEPS)
def test_a_run_killed_at_any_step_of_the_exchange_leaves_one_result(out, step):
    """SIGKILL at each step: a reader listing the directory sees the old result whole, or the
    new one whole, never a mix; the next claim tidies up and the result stays the same."""
    _killed_at(out, step, "exchange")
    seen = result_files(out)
    assert seen == (OLD if EXCHANGE_STEPS.index(step) < EXCHANGE_STEPS.index("exchanged") else NEW)
    assert (out / "notes.txt").read_text(encoding="utf-8") == "mine"
    with claimed_directory(out):
        pass
    assert result_files(out) == seen and (out / "notes.txt").read_text(encoding="utf-8") == "mine"
    assert mechanism_leftovers(out.parent) == []


@pytest.mark.parametrize("step", MOVE_STEPS)
def test_a_run_killed_during_the_moves_is_completed_by_the_next_claim(out, step):
    """Where no exchange can be made, a reader may see a mix while the files are moved, until
    the next claim completes the decided switch-over."""
    _killed_at(out, step, "moves")
    with claimed_directory(out):
        pass
    assert result_files(out) == NEW
    assert (out / "notes.txt").read_text(encoding="utf-8") == "mine"
    assert mechanism_leftovers(out.parent) == []


SWITCHING = """
import sys
from pathlib import Path
from contactfem.io.atomic import claimed_directory

out, rounds = Path(sys.argv[1]), int(sys.argv[2])
results = [{old!r}, {new!r}]
for index in range(rounds):
    with claimed_directory(out) as claim:
        with claim.stage(replaces={replaces!r}, last="report.json") as staging:
            for name, text in results[index % 2].items():
                (staging / name).write_text(text + str(index // 2 % 2))
"""


@needs_exchange
def test_a_reader_during_many_switches_never_sees_two_runs(out):
    """A reader opening the directory while results are switched in over and over: every
    listing holds the files of one run only (a run's files carry its tag)."""
    script = SWITCHING.format(old=OLD, new=NEW, replaces=REPLACES)
    writer = subprocess.Popen([sys.executable, "-c", script, str(out), "60"], stderr=subprocess.PIPE, text=True)
    seen, mixed = 0, []
    while writer.poll() is None:
        try:
            found = result_files(out)
        except (FileNotFoundError, NotADirectoryError):
            continue  # the old directory was removed while it was read
        seen += 1
        if len(set(found.values())) > 1:
            mixed.append(found)
    assert writer.wait() == 0, writer.stderr.read()
    assert mixed == [] and seen > 0
    assert mechanism_leftovers(out.parent) == []
