"""The command's heap policy (contactfem.heap): freed blocks are reused, not faulted in again.

Each check runs in a fresh interpreter: the policy is process-wide and must not leak into
the test process (the library never applies it on import).
"""

import os
import platform
import subprocess
import sys

import pytest

import contactfem.cli as cli

GLIBC = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"

# Fills and frees 64 MB through the C library's malloc twice, as CHOLMOD allocates a factor
# (above glibc's largest mapping threshold, 32 MB; numpy's own arrays ask for huge pages),
# and prints whether the policy was applied and the page faults of the second fill.
FILL_TWICE = """
import ctypes, resource, sys
from contactfem.heap import keep_freed_memory
kept = keep_freed_memory() if sys.argv[1] == "kept" else False
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, (ctypes.c_size_t,)
libc.free.argtypes = (ctypes.c_void_p,)
def faults_of_one_fill():
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    block = libc.malloc(64_000_000)
    ctypes.memset(block, 1, 64_000_000)
    libc.free(block)
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
faults_of_one_fill()
print(kept, faults_of_one_fill())
"""

PAGES = 64_000_000 // 4096


def _fill_twice(mode: str, **environment: str) -> tuple[bool, int]:
    env = {name: value for name, value in os.environ.items()
           if not name.startswith("MALLOC_") and name != "GLIBC_TUNABLES"}
    env.update(environment)
    run = subprocess.run([sys.executable, "-c", FILL_TWICE, mode], capture_output=True, text=True, env=env,
                         timeout=120, check=True)
    kept, faults = run.stdout.split()
    return kept == "True", int(faults)


@pytest.mark.skipif(not GLIBC, reason="the policy is glibc's (mallopt)")
def test_a_freed_block_is_reused_without_page_faults():
    plain_kept, plain_faults = _fill_twice("plain")
    if plain_faults < PAGES // 10:
        pytest.skip(f"this system maps large blocks without per-page faults ({plain_faults} for {PAGES} pages)")
    kept, faults = _fill_twice("kept")
    assert not plain_kept and kept
    # The second fill reuses the first one's pages: at most 1% of them faulted in again,
    # where glibc's default maps it anew (every page faulted: at least 10% above).
    assert faults < PAGES // 100, (faults, plain_faults)


@pytest.mark.skipif(not GLIBC, reason="the policy is glibc's (mallopt)")
@pytest.mark.parametrize("environment", [{"MALLOC_ARENA_MAX": "2"}, {"GLIBC_TUNABLES": "glibc.malloc.trim_threshold=0"}])
def test_an_allocator_tuned_by_the_user_is_left_alone(environment):
    kept, _ = _fill_twice("kept", **environment)
    assert not kept


def test_the_command_keeps_the_heap_before_any_work(monkeypatch):
    calls = []
    monkeypatch.setattr(cli, "keep_freed_memory", lambda: calls.append("heap"))
    monkeypatch.setattr(cli, "main", lambda: calls.append("main"))
    cli.run()
    assert calls == ["heap", "main"]
