"""The ``contactfem`` command as a user's shell starts it: a separate process, the real entry
point, a locale of the user's. What a test runner inside the process would hide: Ctrl-C
while the command is still importing, and file names that are not UTF-8.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

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
