"""The ``contactfem`` command as a user's shell starts it: a separate process, the real entry
point, a locale of the user's. What a test runner inside the process would hide: Ctrl-C
while the command is still importing, and file names that are not UTF-8.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from conftest import square_case_dict

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = shutil.which("contactfem", path=str(Path(sys.executable).parent))

# The command's entry, with a SIGINT sent to itself when a chosen module starts importing
# (argv[1]); the rest of argv is the command line.
STOP_AT_IMPORT = """
import os, signal, sys
target = sys.argv.pop(1)
class Stop:
    def find_spec(self, name, path=None, target_=None):
        if name == target:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Stop())
from contactfem.__main__ import main
sys.argv[0] = "contactfem"
main()
"""


def _environment(**extra: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("LC_") and k not in ("LANG", "PYTHONIOENCODING")}
    env.update(extra)
    return env


def _assert_one_interrupted_line(run: subprocess.CompletedProcess) -> None:
    assert run.returncode == 130, (run.returncode, run.stderr[-2000:])
    assert "Traceback" not in run.stderr and "KeyboardInterrupt" not in run.stderr, run.stderr[-2000:]
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: interrupted (SIGINT)"), run.stderr


# --------------------------------------------------------------------------- Ctrl-C early


@pytest.mark.parametrize("module", [
    "contactfem.threads",      # the first thing the entry imports
    "click",                   # the command line's own imports
    "numpy",
    "scipy.sparse",
    "yaml",
    "contactfem.cli.cmd_sweep",
    "contactfem.solve",        # inside the command: its own handler answers
])
def test_ctrl_c_while_importing_is_one_line_and_exit_130(module, tmp_path):
    case = ROOT / "cases" / "square.yaml"
    run = subprocess.run([sys.executable, "-c", STOP_AT_IMPORT, module, "check", str(case)], capture_output=True,
                         text=True, timeout=120, cwd=tmp_path, env=_environment(LC_ALL="C.UTF-8"))
    _assert_one_interrupted_line(run)


def _mapped(pid: int, library: str) -> bool:
    try:
        return library in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


@pytest.mark.skipif(SCRIPT is None or not Path("/proc/self/maps").exists(),
                    reason="needs the installed script and /proc")
@pytest.mark.parametrize("after", [0.0, 0.05, 0.2])
def test_ctrl_c_to_the_script_in_its_first_second_is_exit_130(after, tmp_path):
    """SIGINT to the real script once numpy is mapped (its import has begun: the command line
    is importing), then ``after`` seconds later: still importing, or just begun its work."""
    process = subprocess.Popen([SCRIPT, "check", str(ROOT / "cases" / "square.yaml")], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=_environment(LC_ALL="C"))
    try:
        deadline = time.monotonic() + 60
        while not _mapped(process.pid, "_multiarray_umath") and process.poll() is None:
            assert time.monotonic() < deadline, "numpy never loaded"
            time.sleep(0.002)
        time.sleep(after)
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    run = subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)
    if run.returncode == 0:  # finished before the signal: nothing to check
        pytest.skip("the check finished before the signal")
    _assert_one_interrupted_line(run)


# --------------------------------------------------------------------------- file names that are not UTF-8

LOCALES = ["C.UTF-8", "C"]
BYTE = os.fsdecode(b"\xfe")  # a file name byte that is not UTF-8, as Python holds it (a surrogate)


def _contactfem(*args, cwd: Path, locale: str = "C", **environment: str) -> subprocess.CompletedProcess:
    """The installed command in a separate process; stdout and stderr as bytes."""
    assert SCRIPT is not None, "the contactfem script is not installed beside this interpreter"
    return subprocess.run([SCRIPT, *map(str, args)], capture_output=True, timeout=300, cwd=cwd,
                          env=_environment(LC_ALL=locale, **environment))


def _text(stream: bytes) -> str:
    """A stream's bytes, which must be UTF-8 (paths shown as text: the byte as \\xNN)."""
    return stream.decode("utf-8")  # raises if a raw byte of a file name was printed


def _assert_one_error_line(run: subprocess.CompletedProcess, code: int, *fragments: str) -> str:
    stderr = _text(run.stderr)
    assert run.returncode == code, (run.returncode, stderr[-3000:])
    assert "Traceback" not in stderr, stderr[-3000:]
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def _assert_ok(run: subprocess.CompletedProcess) -> str:
    stderr = _text(run.stderr)
    assert run.returncode == 0 and "Traceback" not in stderr, (run.returncode, stderr[-3000:])
    return _text(run.stdout)


def _strict_json(path: Path) -> dict:
    """A JSON file read as strict UTF-8 JSON: no raw byte, and no lone surrogate escape either
    (which Python's json accepts and other readers refuse)."""
    content = json.loads(path.read_bytes().decode("utf-8"))
    json.dumps(content, ensure_ascii=False).encode("utf-8")
    return content


def _square(path: Path, divisions: int = 8, **extra) -> Path:
    """The square case at ``path``; without a title (``title=None``), it is the file's name."""
    data = square_case_dict(divisions=divisions)
    data.update(extra)
    if data["title"] is None:
        del data["title"]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


@pytest.mark.parametrize("locale", LOCALES)
@pytest.mark.parametrize("command", ["solve", "check", "compare", "converge", "adapt", "sweep"])
def test_a_missing_file_whose_name_is_not_utf8_is_one_line_and_exit_2(command, locale, tmp_path):
    run = _contactfem(command, tmp_path / os.fsdecode(b"\xff.yaml"), cwd=tmp_path, locale=locale)
    _assert_one_error_line(run, 2, "\\xff.yaml")


@pytest.mark.parametrize("locale", LOCALES)
def test_a_case_that_is_a_directory_named_with_such_bytes_is_one_line_and_exit_2(locale, tmp_path):
    (tmp_path / f"d{BYTE}.yaml").mkdir()
    _assert_one_error_line(_contactfem("check", f"d{BYTE}.yaml", cwd=tmp_path, locale=locale), 2, "d\\xfe.yaml")
    _assert_one_error_line(_contactfem("plot", f"d{BYTE}.yaml", cwd=tmp_path, locale=locale), 2, "d\\xfe.yaml")


@pytest.mark.parametrize("locale", LOCALES)
def test_solve_a_case_named_with_such_bytes_into_such_a_directory(locale, tmp_path):
    """The files are written where asked (VTK takes only UTF-8 paths: it is handed the
    directory's descriptor link), and every path they and the summary show is text."""
    import h5py
    import meshio

    _square(tmp_path / f"{BYTE}.yaml", units={"length": "mm", "force": "N"}, title=None, load_path={"steps": 2})
    out = tmp_path / f"o{BYTE}"
    stdout = _assert_ok(_contactfem("solve", f"{BYTE}.yaml", "--out", f"o{BYTE}", "--plot", cwd=tmp_path,
                                    locale=locale))
    assert stdout.startswith("\\xfe — method") and f"wrote        o\\xfe{os.sep}solution.vtu" in stdout
    names = {p.name for p in out.iterdir()}
    assert {"solution.vtu", "contact.vtu", "solution.pvd", "solution.h5", "contact.csv", "report.json",
            "deformed.png", "contact_profile.png", "path.pvd", "path-1.vtu", "path.png"} <= names, names
    assert not any(name.startswith(".tmp-") for name in names)
    report = _strict_json(out / "report.json")
    assert report["case"]["file"] == "\\xfe.yaml" and report["case"]["title"] == "\\xfe"
    for vtu in ("solution.vtu", "contact.vtu"):
        metadata = meshio.read(out / vtu).field_data
        assert bytes(metadata["case_file"]).decode("utf-8") == "\\xfe.yaml", vtu
    with h5py.File(out / "solution.h5", "r") as archive:
        assert archive.attrs["case_file"] == "\\xfe.yaml"
    # Again with --json: the report alone on stdout, strict JSON.
    stdout = _assert_ok(_contactfem("solve", f"{BYTE}.yaml", "--out", f"o{BYTE}", "--json", "--overwrite",
                                    cwd=tmp_path, locale=locale))
    assert json.loads(stdout)["case"]["file"] == "\\xfe.yaml"


@pytest.mark.parametrize("locale", LOCALES)
def test_check_shows_a_profile_file_under_such_a_directory_as_text(locale, tmp_path):
    directory = tmp_path / f"d{BYTE}"
    directory.mkdir()
    shutil.copy(ROOT / "cases" / "rough_surface.csv", directory / "surface.csv")
    case = yaml.safe_load((ROOT / "cases" / "rough.yaml").read_text(encoding="utf-8"))
    case["geometry"]["profile"]["file"] = "surface.csv"
    case["mesh"]["size"] = 0.2
    (directory / "rough.yaml").write_text(yaml.safe_dump(case), encoding="utf-8")
    stdout = _assert_ok(_contactfem("check", directory / "rough.yaml", cwd=tmp_path, locale=locale))
    assert "d\\xfe" in stdout.splitlines()[0]
    stdout = _assert_ok(_contactfem("check", directory / "rough.yaml", "--json", cwd=tmp_path, locale=locale))
    summary = json.loads(stdout)
    assert summary["case"].endswith("d\\xfe/rough.yaml")
    assert summary["geometry"]["files"] == [str(tmp_path) + "/d\\xfe/surface.csv"]
    # A missing profile file under such a directory: one line naming it as text.
    (directory / "surface.csv").unlink()
    _assert_one_error_line(_contactfem("solve", directory / "rough.yaml", "--out", "out", cwd=tmp_path,
                                       locale=locale), 2, "surface.csv")


def test_every_command_writes_into_such_directories(tmp_path):
    """compare, converge, adapt, plot, init and sweep: results in directories whose names are
    not UTF-8, strict UTF-8 JSON and summaries, no traceback (LC_ALL=C)."""
    case = _square(tmp_path / f"{BYTE}.yaml", title=None)
    for command, written, extra in (("compare", "compare.json", ()),
                                    ("converge", "convergence.json", ("--levels", "2")),
                                    ("adapt", "adapt.json", ("--max-unknowns", "400"))):
        stdout = _assert_ok(_contactfem(command, case, "--out", f"{command}{BYTE}", *extra, cwd=tmp_path))
        assert f"{command}\\xfe" in stdout
        _strict_json(tmp_path / f"{command}{BYTE}" / written)
    _assert_ok(_contactfem("solve", case, "--out", f"o{BYTE}", "--quiet", cwd=tmp_path))
    made = json.loads(_assert_ok(_contactfem("plot", f"o{BYTE}", "--out", f"p{BYTE}", "--json", cwd=tmp_path)))
    assert made["files"] == [f"p\\xfe{os.sep}deformed.png", f"p\\xfe{os.sep}contact_profile.png"]
    assert (tmp_path / f"p{BYTE}" / "deformed.png").is_file()
    # init: a starter case whose name is not UTF-8 is a UTF-8 file that passes check.
    stdout = _assert_ok(_contactfem("init", f"i{BYTE}.yaml", cwd=tmp_path))
    assert stdout.startswith("wrote i\\xfe.yaml")
    starter = (tmp_path / f"i{BYTE}.yaml").read_bytes().decode("utf-8")
    assert "contactfem check i\\xfe.yaml" in starter and "results/i\\xfe" in starter
    _assert_ok(_contactfem("check", f"i{BYTE}.yaml", "--quiet", cwd=tmp_path))
    _assert_one_error_line(_contactfem("init", f"i{BYTE}.yaml", cwd=tmp_path), 2, "i\\xfe.yaml")
    # sweep: a sweep file and its base case in such a directory, the table into another.
    sweeps = tmp_path / f"s{BYTE}"
    _square(sweeps / "base.yaml")
    (sweeps / f"sw{BYTE}.yaml").write_text("case: base.yaml\ngrid:\n  material.nu: [0.3, 0.7]\n", encoding="utf-8")
    run = _contactfem("sweep", sweeps / f"sw{BYTE}.yaml", "--workers", "1", "--out", f"t{BYTE}", cwd=tmp_path)
    stderr = _text(run.stderr)
    assert run.returncode == 1 and "Traceback" not in stderr, stderr[-3000:]
    assert stderr.splitlines()[-1].startswith("error: sw\\xfe.yaml: 1 of 2 points did not solve"), stderr
    assert "t\\xfe/sweep.csv" in _text(run.stdout)
    table = _strict_json(tmp_path / f"t{BYTE}" / "sweep.json")
    assert table["sweep"]["file"].endswith("s\\xfe/sw\\xfe.yaml")
    assert table["case"]["file"].endswith("s\\xfe/base.yaml")
    assert table["points"][1]["message"].startswith("sw\\xfe.yaml point 2: material.nu")
    for record in (tmp_path / f"t{BYTE}" / "points").iterdir():
        _strict_json(record)


def test_stdout_that_cannot_encode_a_title_escapes_it(tmp_path):
    """PYTHONIOENCODING=latin-1 (strict): what the stream cannot carry (the summary's dash, a
    title's arrow) is escaped, not a traceback."""
    _square(tmp_path / f"{BYTE}.yaml", title="bloc pressé →")
    run = _contactfem("check", f"{BYTE}.yaml", cwd=tmp_path, PYTHONIOENCODING="latin-1")
    assert run.returncode == 0 and b"Traceback" not in run.stderr, run.stderr[-3000:]
    stdout = run.stdout.decode("latin-1")
    assert stdout.startswith("\\xfe.yaml: valid \\u2014 bloc pressé \\u2192"), stdout
