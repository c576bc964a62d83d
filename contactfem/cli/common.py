"""What several commands share: loading the case, progress lines on stderr and writing a result's files."""

from __future__ import annotations

import dataclasses
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import click

from contactfem.errors import CaseError, OutputError
from contactfem.io.registry import shown_path, shown_text, to_json
from contactfem.linalg import DISTRIBUTED_BACKENDS


def _progress(quiet: bool):
    """Stage messages on stderr unless --quiet: live lines (rich) on a terminal, plain lines
    otherwise (a pipe, a log, CI, a notebook; see contactfem/progress.py). stdout is left to
    the command's result (the summary, or the JSON of --json)."""
    if quiet:
        return None
    from contactfem.progress import PlainProgress, StageProgress

    reporter = StageProgress() if sys.stderr.isatty() else PlainProgress(sys.stderr)
    context = click.get_current_context(silent=True)
    if context is not None:
        context.meta.setdefault("contactfem.progress", []).append(reporter)
        context.call_on_close(reporter.close)
    return reporter


def _end_progress() -> None:
    """Stop the live progress lines before a command prints its summary on stdout."""
    context = click.get_current_context(silent=True)
    for reporter in (context.meta.get("contactfem.progress", []) if context is not None else []):
        reporter.close()


def _check_engine_options(scheduler: str | None, workers: int | None, tasks: str) -> None:
    """--scheduler and --workers together are bad input."""
    if scheduler is not None and workers is not None:
        raise CaseError(f"--workers {workers}: sizes the local cluster; expected no --workers with --scheduler "
                        f"(the cluster's own workers run the {tasks})")


@contextmanager
def _engine(scheduler: str | None, workers: int | None, pending: int, say, tasks: str, local: bool = True):
    """Where a command's ``pending`` independent ``tasks`` (points, levels) run
    (:func:`contactfem.engines.open_engine`): the cluster of --scheduler, a local cluster of
    --workers processes (by default too when ``local``), else this process; ``say`` is told
    once how to install Dask when it is missing, and where the tasks run. Check the two
    options first with :func:`_check_engine_options`, before anything is written."""
    from contactfem import engines

    if not pending or not (local or scheduler is not None or workers is not None):
        yield engines.SerialEngine()
        return
    with engines.open_engine(scheduler, workers, pending) as engine:
        if engine.note:
            say(f"note: {engine.note}")
        if engine.kind == "dask":
            where = f"the cluster at {scheduler}" if scheduler else "a local cluster"
            say(f"solving {pending} {tasks} on {engine.workers} Dask workers of {where}")
        yield engine


def _load(case_file: Path, backend: str | None = None, distributed: bool = False):
    """The validated case, with --backend applied; a backend that is not installed is bad input,
    and so is one that runs across MPI ranks for a command that does not (all but ``solve``)."""
    from contactfem.case import load_case
    from contactfem.errors import SolverError
    from contactfem.linalg import resolve_backend

    case = load_case(case_file)
    title = shown_text(case.title)
    if title != case.title:
        # The default title is the file's name: a byte of it that is not UTF-8 is drawn, printed
        # and stored as \xNN (matplotlib, HDF5 and VTK take only encodable text).
        case = dataclasses.replace(case, title=title)
    if backend is not None:
        case = case.with_solver(backend=backend)
    key = "--backend" if backend is not None else "solver.backend"
    try:
        resolve_backend(case.solver.backend)
    except SolverError as error:
        raise CaseError(f"{case_file.name}: {key} = {case.solver.backend}: {error}") from None
    if case.solver.backend in DISTRIBUTED_BACKENDS and not distributed:
        raise CaseError(f"{case_file.name}: {key} = {case.solver.backend}: only `contactfem solve` runs across MPI "
                        "ranks (mpiexec -n P contactfem solve CASE --backend petsc); this command solves in one "
                        "process: use auto, cholmod, pardiso or superlu")
    return case


def _files_of(formats: tuple[str, ...]) -> list[str]:
    """The files the ``formats`` write, in the order they are written (the report last)."""
    from contactfem.io.registry import FORMATS

    return [name for format, output in FORMATS.items() if format in formats for name in output.files]


def _write_solution(staging: Path, case, result, report: dict, progress, path_writer=None) -> dict:
    """Write one result's files (the case's formats) into a staging directory, and finish the
    files of the load path that ended in it (``path_writer``, which wrote its steps there).
    Returns the report as written (its timings include the writing)."""
    from contactfem.io.registry import PathData, result_data, write_result

    _refuse_non_finite(case, result.solution, report)
    path = None
    if path_writer is not None:
        path = PathData(writer=path_writer, curves=report["load_path"]["curves"])
    _, written_report = write_result(result_data(case, result, report, path), staging, case.output.files,
                                     progress=progress)
    return written_report


def _refuse_non_finite(case, solution, report: dict) -> None:
    """A solve whose fields or report hold NaN/inf is a failure, never an output."""
    import numpy as np

    from contactfem.errors import SolverError

    contact = solution.contact
    arrays = {"displacement": solution.displacement, "stress": solution.stress, "von_mises": solution.von_mises,
              "multiplier": contact.multiplier, "nodal_force": contact.nodal_force}
    bad = [name for name, values in arrays.items() if not np.isfinite(values).all()]
    try:
        to_json(report)
    except ValueError:
        bad.append("report")
    if bad:
        raise SolverError(f"{case.source.name}: the solution is not finite ({', '.join(bad)}): the "
                          "data's scales overflow float64; rescale the units of lengths, moduli and loads")


def _write_series(directory: Path, stem: str, entries: list) -> list[Path]:
    """compare/converge: every solution as VTU files and one series PVD (io/series.py)."""
    from contactfem.io.series import write_series

    return write_series(directory, stem, entries)


@contextmanager
def _writable_by_vtk(directory: Path) -> Iterator[Path]:
    """``directory`` under a name VTK's writers can open. They take the path as UTF-8 text, so a
    path with bytes that are not UTF-8 (``--out $'\\xfe'``, a case file whose name or directory
    has such bytes) would fail to encode; such a directory is reached through the link of an
    open descriptor of it, ``/proc/self/fd/N``, whose name is ASCII. Where there is no /proc,
    the path is refused (OutputError) rather than written through a traceback."""
    name = os.fsdecode(directory)
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        pass
    else:
        yield Path(directory)
        return
    if not os.path.isdir("/proc/self/fd"):
        raise OutputError(f"cannot write {shown_path(directory)}: the path is not UTF-8 and VTK, which writes "
                          "the VTU files, opens only UTF-8 paths; choose another output directory (--out)")
    try:
        descriptor = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as exc:
        raise OutputError(f"cannot write {shown_path(directory)}: {exc.strerror or exc}") from None
    try:
        yield Path(f"/proc/self/fd/{descriptor}")
    finally:
        os.close(descriptor)
