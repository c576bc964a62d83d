"""``contactfem solve``: one case solved (across MPI ranks with the petsc backend) and its files written."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from contactfem.cli.common import _end_progress, _files_of, _load, _progress, _writable_by_vtk, _write_solution
from contactfem.cli.exits import _exit_code, _fail, _interruptible
from contactfem.cli.options import (
    _CheckedPath,
    _RelativeTarget,
    case_argument,
    json_option,
    overwrite_option,
    quiet_option,
    refine_option,
)
from contactfem.cli.summary import _summary
from contactfem.case import ACCURACY_LEVELS, ACCURACY_QUANTITIES
from contactfem.errors import CaseError, ContactFemError
from contactfem.io.registry import REPORT_JSON, RESULT_FILES, RESULT_MARKERS, shown_path, to_json
from contactfem.linalg import BACKEND_CHOICES, DISTRIBUTED_BACKENDS
from contactfem.methods import METHOD_NAMES


@click.command()
@case_argument
@click.option("--method", type=click.Choice(METHOD_NAMES), default=None,
              help="Contact method: positive = (4), standard = (5). Default: the case's.")
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Output directory. Default: the case's output.directory.")
@refine_option
@click.option("--backend", type=click.Choice(BACKEND_CHOICES), default=None,
              help="Sparse direct solver. Default: the case's (auto = fastest installed).")
@quiet_option
@json_option
@overwrite_option
@click.option("--plot", "make_plot", is_flag=True,
              help="Also write deformed.png and contact_profile.png (as `contactfem plot`).")
@click.option("--petsc-solver", type=click.Choice(("mumps", "gamg")), default="mumps", show_default=True,
              help="With --backend petsc (under mpiexec): MUMPS, distributed direct, or CG with GAMG "
                   "(the least memory per rank).")
@click.option("--accuracy", "accuracy", type=_RelativeTarget(), default=None,
              help="Refine (where the error estimator says) until the estimated relative error of "
                   "--accuracy-quantity is at most this, e.g. 0.5%. Default: the case's solver.accuracy.target.")
@click.option("--accuracy-quantity", type=click.Choice(ACCURACY_QUANTITIES), default=None,
              help="What --accuracy bounds: the energy norm (default), the contact width, the peak pressure "
                   "or the contact force.")
@click.option("--max-unknowns", type=click.IntRange(10, 10**9), default=None,
              help="With --accuracy: stop before a mesh of more unknowns. Default: the case's "
                   "solver.accuracy.budget.unknowns, else what memory holds.")
@click.option("--accuracy-levels", type=click.Choice(ACCURACY_LEVELS), default=None,
              help="The contact quantities' error estimates of a plain solve: reuse the coarser level "
                   "sequencing solved (free; the default) or solve coarser levels for them.")
@_interruptible
def solve(case_file: Path, method: str | None, out_dir: Path | None, refine: int | None,
          backend: str | None, quiet: bool, as_json: bool, overwrite: bool, make_plot: bool = False,
          petsc_solver: str = "mumps", accuracy: float | None = None, accuracy_quantity: str | None = None,
          max_unknowns: int | None = None, accuracy_levels: str | None = None) -> None:
    """Solve CASE and write solution.vtu/.pvd, solution.h5 and report.json.

    \b
    Examples:
      contactfem solve cases/square.yaml
      contactfem solve cases/square.yaml --method standard --json > report.json
      contactfem solve cases/square.yaml --overwrite      # replace results/square
      contactfem solve cases/square.yaml --plot           # and deformed.png, contact_profile.png
      mpiexec -n 4 contactfem solve cases/square.yaml --backend petsc   # across 4 MPI ranks
      contactfem solve cases/hertz_quarter.yaml --accuracy 0.5% --accuracy-quantity contact_width
    """
    from contactfem.io.atomic import claimed_directory
    from contactfem.io.path import PathWriter
    from contactfem.io.registry import PATH_PNG
    from contactfem.plots import plot_load_path
    from contactfem.report import build_report, load_path_figures, path_step_figures
    from contactfem.solve import solve_case, solve_load_path

    progress = _progress(quiet)
    try:
        case = _with_accuracy(_load(case_file, backend, distributed=True), accuracy, accuracy_quantity, max_unknowns,
                              accuracy_levels)
        targeted = case.solver.accuracy.target is not None
        if targeted:
            _refuse_target(case, method)
        if make_plot and "h5" not in case.output.files:
            raise CaseError(f"{case_file.name}: output.files: --plot reads solution.h5; keep h5 in output.files")
        directory = out_dir if out_dir is not None else case.output.directory
        if case.solver.backend in DISTRIBUTED_BACKENDS:
            _solve_distributed(case, method, refine, petsc_solver, directory, quiet, as_json, overwrite, make_plot,
                               progress)
            return
        with claimed_directory(directory, markers=RESULT_MARKERS, overwrite=overwrite) as claim:
            with (claim.stage(replaces=RESULT_FILES, last=REPORT_JSON) as staged,
                  _writable_by_vtk(staged) as staging):
                writer = None
                if case.load_path is not None:
                    # Each step's files go into the staging area as it is solved: a path
                    # holds one step in memory, and a failed one leaves nothing behind.
                    writer = PathWriter(staging, case.load_path.factors, case.text)
                    steps: list[dict] = []

                    def write_step(index: int, factor: float, step) -> None:
                        steps.append(path_step_figures(factor, step))
                        writer.add(index, step.solution)

                    try:
                        path = solve_load_path(case, method=method, refine=refine, progress=progress,
                                               accept_uncertified=True, on_step=write_step, keep_steps=False)
                    except BaseException:
                        writer.close()  # its half-written files go with the staging area
                        raise
                    result, extras = path.final, {"load_path": load_path_figures(path, steps)}
                elif targeted:
                    result, extras = _solve_to_target(case, refine, progress)
                else:
                    result = solve_case(case, method=method, refine=refine, progress=progress,
                                        accept_uncertified=True)
                    extras = {}
                report = _write_solution(staging, case, result, build_report(case, result, extras), progress,
                                         path_writer=writer)
                names = _files_of(case.output.files)
                if writer is not None:
                    names.append(plot_load_path(staging / PATH_PNG, report["load_path"]["curves"],
                                                case.units.to_dict(), title=case.title).name)
                if make_plot:
                    names += _pictures(staging, staging, progress)
    except ContactFemError as error:
        _fail(error)
        return
    _report_solve(case, result, report, [Path(directory) / name for name in names], directory, quiet, as_json)


def _with_accuracy(case, target: float | None, quantity: str | None, max_unknowns: int | None,
                   levels: str | None):
    """The case with the command line's accuracy options in place of its solver.accuracy keys."""
    from dataclasses import replace

    settings = case.solver.accuracy
    changes = {key: value for key, value in (("target", target), ("quantity", quantity),
                                             ("max_unknowns", max_unknowns), ("levels", levels)) if value is not None}
    if not changes:
        return case
    return replace(case, solver=replace(case.solver, accuracy=replace(settings, **changes)))


def _refuse_target(case, method: str | None) -> None:
    """A run towards a target refines with the residual estimator of method (4), one load."""
    name = case.source.name
    if (method or case.solver.method) != "positive":
        raise CaseError(f"{name}: solver.accuracy.target: refining to a target uses the residual estimator, "
                        "defined for method positive; drop --method standard (or solver.method) or the target")
    if case.load_path is not None:
        raise CaseError(f"{name}: solver.accuracy.target: a load path is solved on one mesh; drop the target "
                        "(each step still reports its estimates) or the load_path")
    if case.solver.backend in DISTRIBUTED_BACKENDS:
        raise CaseError(f"{name}: solver.accuracy.target: refining to a target runs in one process; "
                        "use a serial backend (auto, cholmod, pardiso or superlu)")


def _solve_to_target(case, refine: int | None, progress):
    """The solve refined to the case's accuracy target, and report.json's accuracy section."""
    from contactfem.accuracy_target import DEFAULT_STEPS, solve_to_accuracy

    settings = case.solver.accuracy
    run = solve_to_accuracy(case, target=settings.target, quantity=settings.quantity,
                            max_unknowns=settings.max_unknowns, max_steps=settings.max_steps or DEFAULT_STEPS,
                            refine=refine, progress=progress)
    return run.result, {"accuracy": {**run.accuracy, "target": run.record()}}


def _report_solve(case, result, report: dict, written: list[Path], directory: Path, quiet: bool,
                  as_json: bool) -> None:
    """A finished solve on stdout (the summary, or the report with --json); exit 1 when uncertified."""
    _end_progress()
    if as_json:
        click.echo(to_json(report), nl=False)
    elif not quiet:
        click.echo(_summary(report, written))
    _refuse_uncertified(case, result, directory)


def _solve_distributed(case, method: str | None, refine: int | None, petsc_solver: str, directory: Path,
                       quiet: bool, as_json: bool, overwrite: bool, make_plot: bool, progress) -> None:
    """``solve`` under mpiexec: every rank solves its share; rank 0 alone claims the output
    directory and prints. Its verdict on the directory is shared before the solve, so that a
    refusal stops every rank (the others would otherwise wait in a collective step). On a
    distributed mesh every rank writes its share into rank 0's staging directory
    (:mod:`contactfem.io.pieces`); otherwise rank 0 writes (a load path's steps as they are solved)."""
    import contextlib
    import os

    from contactfem.distributed import mpi_world
    from contactfem.io.atomic import claimed_directory

    world = mpi_world()
    root = world.Get_rank() == 0
    with contextlib.ExitStack() as stack:
        refusal = staged = None
        try:  # decided alike on every rank, before anything is written
            pieces = case.load_path is None and _refuse_in_pieces(case, refine, world.Get_size(), make_plot)
        except ContactFemError as error:
            if root:
                _fail(error)
            sys.exit(_exit_code(error))
        if root:
            try:
                claim = stack.enter_context(claimed_directory(directory, markers=RESULT_MARKERS, overwrite=overwrite))
                staged = stack.enter_context(claim.stage(replaces=RESULT_FILES, last=REPORT_JSON))
            except ContactFemError as error:
                refusal = error
        code = world.bcast(_exit_code(refusal) if refusal is not None else 0, root=0)
        if code:
            if root:
                _fail(refusal)
            sys.exit(code)
        # Every rank writes into the staging directory when the result stays in pieces.
        staged = world.bcast(os.fsencode(staged) if root else None, root=0) if pieces else staged
        staging = None if staged is None else stack.enter_context(_writable_by_vtk(Path(os.fsdecode(staged))))
        try:
            solved = _distributed_files(case, method, refine, petsc_solver, staging, progress if root else None,
                                        world)
        except ContactFemError as error:  # raised on every rank alike: decisions use shared data
            if root:
                _fail(error)
            sys.exit(_exit_code(error))
        if not root:
            return
        result, report, names = solved
        if make_plot:
            names += _pictures(staging, staging, progress)
    _report_solve(case, result, report, [Path(directory) / name for name in names], directory, quiet, as_json)


def _refuse_in_pieces(case, refine: int | None, ranks: int, make_plot: bool) -> bool:
    """Whether the solve runs on a distributed mesh (each rank refining its piece), whose
    result stays in pieces; what needs the whole mesh in one process is refused first."""
    from contactfem.distributed_problem import takes_pieces
    from contactfem.io.pieces import PIECE_FORMATS

    if not takes_pieces(case, refine, ranks):
        return False
    name = case.source.name
    if make_plot:
        raise CaseError(f"{name}: --plot: the pictures draw the whole mesh in one process, which a distributed mesh "
                        f"({ranks} ranks each refining a piece) never holds; drop --plot and run `contactfem plot` "
                        "on the result afterwards")
    refused = [format for format in case.output.files if format not in PIECE_FORMATS]
    if refused:
        raise CaseError(f"{name}: output.files: {', '.join(refused)} is not written on a distributed mesh "
                        f"({ranks} ranks each refining a piece); expected only {', '.join(PIECE_FORMATS)}")
    return True


def _distributed_files(case, method: str | None, refine: int | None, petsc_solver: str, staging: Path | None,
                       progress, world):
    """The distributed solve (a load path's steps written into ``staging`` as they come) and,
    on rank 0, its files: (result, report, file names); None elsewhere. ``staging`` is given on
    rank 0, and on every rank when the result stays in pieces."""
    from contactfem.distributed import distributed_report, solve_distributed
    from contactfem.distributed_path import solve_distributed_path
    from contactfem.io.path import PathWriter
    from contactfem.io.registry import PATH_PNG
    from contactfem.plots import plot_load_path
    from contactfem.report import build_report, load_path_figures, path_step_figures

    root = world.Get_rank() == 0
    if case.load_path is None:
        outcome = solve_distributed(case, method=method, refine=refine, solver=petsc_solver, progress=progress,
                                    accept_uncertified=True, sequencing=case.solver.accelerators.sequencing,
                                    gather=False)
        if outcome.pieces is not None:
            return _write_in_pieces(case, outcome, staging, progress, world)
        if not root:
            return None
        report = _write_solution(staging, case, outcome.result, distributed_report(case, outcome), progress)
        return outcome.result, report, _files_of(case.output.files)
    writer = None if staging is None else PathWriter(staging, case.load_path.factors, case.text)
    steps: list[dict] = []

    def write_step(index: int, factor: float, step) -> None:
        steps.append(path_step_figures(factor, step))
        writer.add(index, step.solution)

    try:
        outcome = solve_distributed_path(case, method=method, refine=refine, solver=petsc_solver, progress=progress,
                                         accept_uncertified=True, on_step=write_step if writer else None,
                                         keep_steps=False)
    except BaseException:
        if writer is not None:
            writer.close()  # its half-written files go with the staging area
        raise
    if staging is None:
        return None
    result = outcome.result.final
    extras = {"load_path": load_path_figures(outcome.result, steps), "parallel": outcome.parallel}
    report = _write_solution(staging, case, result, build_report(case, result, extras), progress, path_writer=writer)
    names = _files_of(case.output.files)
    names.append(plot_load_path(staging / PATH_PNG, report["load_path"]["curves"], case.units.to_dict(),
                                title=case.title).name)
    return result, report, names


def _write_in_pieces(case, outcome, staging: Path, progress, world):
    """Every rank's share of a result kept in pieces into ``staging`` (:mod:`contactfem.io.pieces`);
    on rank 0 (result, report, file names), None elsewhere."""
    import numpy as np

    from contactfem.distributed_output import pieces_accuracy
    from contactfem.distributed_result import _peak_rss
    from contactfem.errors import SolverError
    from contactfem.io.pieces import RootData, write_pieces
    from contactfem.io.registry import result_data
    from contactfem.report import build_report

    fields, result, root = outcome.pieces, outcome.result, None
    finite = all(np.isfinite(values).all() for values in (fields.displacement, fields.stress, fields.von_mises))
    if result is not None:
        extras = {"parallel": outcome.parallel, "accuracy": pieces_accuracy(case, result, outcome.estimate)}
        report = build_report(case, result, extras, body=outcome.body)
        contact = result.solution.contact
        try:
            to_json(report)
        except ValueError:
            finite = False
        finite = finite and all(np.isfinite(v).all() for v in (contact.multiplier, contact.nodal_force))
        root = RootData(result_data(case, result, report), result.problem.boundary_numbers)
    if not all(world.allgather(finite)):  # every rank stops alike
        raise SolverError(f"{case.source.name}: the solution is not finite: the data's scales overflow float64; "
                          "rescale the units of lengths, moduli and loads")
    solve_peak = outcome.parallel["per_rank"][world.Get_rank()]["peak_rss_bytes"]

    def memory() -> dict:  # the peak so far (the body's files written) beside the solve's
        return {"solve_peak_rss_bytes": solve_peak, "peak_rss_bytes": max(solve_peak, _peak_rss())}

    names, written = write_pieces(staging, fields, case.output.files, world, root, progress, per_rank=memory)
    return None if result is None else (result, written, names)


def _refuse_uncertified(case, result, directory: Path) -> None:
    """Exit 1 for a result the kernel could not certify: its files are written (report.json
    says status not_certified, with each check) but it is not an answer."""
    from contactfem.errors import SolverError
    from contactfem.kernel import Status

    if result.kernel.status is Status.NOT_CERTIFIED:
        _fail(SolverError(f"{case.source.name}: method {result.method}: not certified, "
                          f"{result.kernel.message}; the files in {shown_path(directory)} say so "
                          "(report.json: solver.certificate)"))


def _pictures(result_dir: Path, out_dir: Path, progress, **options) -> list[str]:
    """The pictures of the result in ``result_dir`` (read from its solution.h5) into ``out_dir``."""
    from contactfem.render import make_pictures

    if progress is not None:
        progress("writing pictures")
    return [Path(p).name for p in make_pictures(result_dir, out_dir, **options)["files"]]
