"""Running a parser of untrusted bytes in a child process, with a deadline.

HDF5 is a C library that trusts a file's internal structure: one corrupted size in a
global heap (a single byte of solution.h5) sends HDF5 2.0 into an endless loop while it
reads a string attribute, and malformed files have crashed it outright. Python cannot
interrupt either from the same process. :func:`run_isolated` therefore runs the work in
a forked child: its answer (or its refusal) comes back through a pipe; a child that does
not answer in time is killed, and one that dies of a signal is reported; both become an
:class:`~contactfem.errors.ArchiveError` naming the file. Where ``fork`` is missing
(Windows), or other Python threads run (a fork would copy their locks held), the work
runs in this process.
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import threading
import warnings
from collections.abc import Callable
from typing import Any

from contactfem.errors import ArchiveError
from contactfem.timings import clock

__all__ = ["can_isolate", "run_isolated"]


def can_isolate() -> bool:
    """Whether :func:`run_isolated` runs its work in a child process here."""
    return hasattr(os, "fork") and threading.active_count() == 1


def _child(work: Callable[[], Any], write_end: int) -> None:
    """In the child: run ``work``, send its outcome, and end without running any cleanup of the parent's."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        try:
            import faulthandler

            faulthandler.disable()  # a crash is the parent's to report, in one line
        except Exception:  # noqa: BLE001
            pass
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        try:
            outcome: tuple[str, Any] = ("answer", work())
        except ArchiveError as error:
            outcome = ("refused", str(error))
        except MemoryError:
            outcome = ("memory", None)
        except BaseException as error:  # noqa: BLE001 - a bug: reported by the parent
            outcome = ("failed", f"{type(error).__name__}: {error}")
        data = pickle.dumps(outcome, protocol=pickle.HIGHEST_PROTOCOL)
        view = memoryview(data)
        while view:
            view = view[os.write(write_end, view[: 1 << 20]):]
    finally:
        os._exit(0)


def run_isolated(work: Callable[[], Any], seconds: float, shown: str) -> Any:
    """``work()``, run in a forked child that gets ``seconds`` to answer (see the module
    docstring); ``shown`` names the file in a refusal. An ArchiveError or MemoryError
    raised by the work is raised here again."""
    if not can_isolate():
        return work()
    read_end, write_end = os.pipe()
    with warnings.catch_warnings():
        # Python 3.12 warns about forking a process with native threads (OpenBLAS's): the
        # child only parses a file and exits, touching none of their state.
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:  # pragma: no cover - the child's coverage is not collected
        os.close(read_end)
        _child(work, write_end)
    os.close(write_end)
    received = bytearray()
    status = None
    try:
        deadline = clock() + seconds
        while True:
            left = deadline - clock()
            if left <= 0:
                raise ArchiveError(f"{shown}: HDF5 did not finish reading it within {seconds:.3g} s; "
                                   "the file is damaged")
            ready, _, _ = select.select([read_end], [], [], left)
            if ready:
                chunk = os.read(read_end, 1 << 20)
                if not chunk:
                    break
                received += chunk
        _, status = os.waitpid(pid, 0)
    finally:
        os.close(read_end)
        if status is None:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        number = os.WTERMSIG(status)
        try:
            name = signal.Signals(number).name
        except ValueError:
            name = str(number)
        raise ArchiveError(f"{shown}: HDF5 crashed reading it ({name}); the file is damaged")
    if not received:
        raise ArchiveError(f"{shown}: the process reading it ended without an answer; the file is damaged")
    kind, value = pickle.loads(received)
    if kind == "answer":
        return value
    if kind == "refused":
        raise ArchiveError(value)
    if kind == "memory":
        raise MemoryError(f"out of memory reading {shown}")
    raise RuntimeError(f"reading {shown} failed: {value}")
