"""The command's BLAS thread policy (contactfem.threads): one OpenBLAS thread, set before numpy loads.

The checks that load numpy run in a fresh interpreter: the policy is process-wide, must act
before numpy's OpenBLAS starts, and must not leak into the test process.
"""

import os
import subprocess
import sys
from importlib.metadata import entry_points

import pytest

from contactfem.threads import OPENBLAS_THREAD_VARIABLES, one_blas_thread

# Runs the command's entry up to its command line (a stand-in for it) and prints the threads
# each OpenBLAS numpy and SciPy loaded has, as OpenBLAS itself reports them.
ENTRY = """
import ctypes, sys, types
from contactfem.__main__ import main
sys.modules["contactfem.cli"] = types.SimpleNamespace(run=lambda: None)  # its imports would load numpy first
main()
import numpy, scipy.linalg, os
counts = []
for module in (numpy, scipy):
    libs = os.path.join(os.path.dirname(os.path.dirname(module.__file__)), module.__name__ + ".libs")
    for name in sorted(os.listdir(libs)) if os.path.isdir(libs) else []:
        if "openblas" in name:
            lib = ctypes.CDLL(os.path.join(libs, name))
            getter = next((getattr(lib, symbol) for symbol in ("scipy_openblas_get_num_threads64_",
                           "scipy_openblas_get_num_threads", "openblas_get_num_threads64_",
                           "openblas_get_num_threads") if hasattr(lib, symbol)), None)
            if getter is not None:
                counts.append(getter())
print(os.environ.get("OPENBLAS_NUM_THREADS"), *counts)
"""


def _clean_environment(**environment: str) -> dict:
    env = {name: value for name, value in os.environ.items() if name not in OPENBLAS_THREAD_VARIABLES}
    env.update(environment)
    return env


def test_the_variable_is_set_when_the_environment_says_nothing():
    environ = {}
    assert one_blas_thread(environ)
    assert environ == {"OPENBLAS_NUM_THREADS": "1"}


@pytest.mark.parametrize("name", OPENBLAS_THREAD_VARIABLES)
def test_a_thread_count_set_by_the_user_is_kept(name):
    environ = {name: "4"}
    assert not one_blas_thread(environ)
    assert environ == {name: "4"}


def test_this_process_is_left_alone_once_numpy_is_loaded(monkeypatch):
    import numpy  # noqa: F401  (loaded: its OpenBLAS has its threads already)

    for name in OPENBLAS_THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    assert not one_blas_thread()
    assert "OPENBLAS_NUM_THREADS" not in os.environ


def test_the_console_script_is_the_entry_that_sets_the_threads():
    scripts = {point.name: point.value for point in entry_points(group="console_scripts")}
    assert scripts.get("contactfem") == "contactfem.__main__:main"


def test_the_command_starts_numpy_and_scipy_with_one_openblas_thread():
    run = subprocess.run([sys.executable, "-c", ENTRY], capture_output=True, text=True, env=_clean_environment(),
                         timeout=120, check=True)
    variable, *counts = run.stdout.split()
    assert variable == "1"
    if not counts:
        pytest.skip("numpy and SciPy bundle no OpenBLAS to ask (not pip's wheels)")
    assert all(count == "1" for count in counts), run.stdout


def test_the_command_keeps_the_users_thread_count():
    run = subprocess.run([sys.executable, "-c", ENTRY], capture_output=True, text=True,
                         env=_clean_environment(OPENBLAS_NUM_THREADS="2"), timeout=120, check=True)
    variable, *counts = run.stdout.split()
    assert variable == "2"
    if not counts:
        pytest.skip("numpy and SciPy bundle no OpenBLAS to ask (not pip's wheels)")
    assert all(count == "2" for count in counts), run.stdout
