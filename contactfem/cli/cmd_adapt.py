"""``contactfem adapt``: adaptive refinement of a case driven by its residual error estimator."""

from __future__ import annotations

from pathlib import Path

import click

from contactfem.cli.common import _files_of, _load, _progress, _writable_by_vtk, _write_solution
from contactfem.cli.exits import _fail, _interruptible, _shown
from contactfem.cli.options import (
    _CheckedPath,
    _FiniteFloatRange,
    case_argument,
    json_option,
    overwrite_option,
    quiet_option,
)
from contactfem.errors import CaseError, ContactFemError
from contactfem.io.registry import ADAPT_JSON, ADAPT_PNG, RESULT_FILES, RESULT_MARKERS, to_json


@click.command()
@case_argument
@click.option("--target", type=_FiniteFloatRange(min=0, min_open=True), default=None,
              help="Stop once the estimate η is at most this (energy norm, the case's units).")
@click.option("--max-unknowns", type=click.IntRange(min=1), default=100_000, show_default=True,
              help="Do not solve a mesh with more displacement unknowns than this.")
@click.option("--max-seconds", type=_FiniteFloatRange(min=0, min_open=True), default=600.0, show_default=True,
              help="Stop after the step that passes this many seconds.")
@click.option("--theta", type=_FiniteFloatRange(0, 1, min_open=True), default=0.5, show_default=True,
              help="Dörfler bulk marking: refine a smallest set carrying θ of Σ η_T².")
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Output directory. Default: <output.directory>-adapt.")
@quiet_option
@json_option
@overwrite_option
@_interruptible
def adapt(case_file: Path, target: float | None, max_unknowns: int, max_seconds: float, theta: float,
          out_dir: Path | None, quiet: bool, as_json: bool, overwrite: bool) -> None:
    """Adaptive refinement of CASE with method (4) and its residual error estimator.

    Solve, estimate (Hild–Nicaise residual estimator, see contactfem/estimator.py), mark
    (Dörfler, θ) and refine (newest-vertex bisection) until η ≤ --target or a budget is
    reached. Writes the final solution like `solve` (report.json gains "estimator",
    solution.vtu the cell data error_indicator = η_T), adapt.json (per step: unknowns, η,
    seconds, and the true errors when the case has an exact solution) and adapt.png (the
    final mesh coloured by η_T, and η against the unknowns).

    \b
    Examples:
      contactfem adapt cases/square.yaml --max-unknowns 20000
      contactfem adapt cases/manufactured.yaml --target 2e-5 --theta 0.3
    """
    from contactfem.adapt_plot import plot_adapt
    from contactfem.adaptive import adapt as adaptive_loop
    from contactfem.io import atomic_write_text
    from contactfem.io.atomic import claimed_directory
    from contactfem.report import build_report

    progress = _progress(quiet)
    try:
        case = _load(case_file)
        _refuse_unknowns_beyond_memory(case, max_unknowns)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-adapt")
        with claimed_directory(directory, markers=(ADAPT_JSON, *RESULT_MARKERS), overwrite=overwrite) as claim:
            run = adaptive_loop(case, theta=theta, target=target, max_unknowns=max_unknowns,
                                max_seconds=max_seconds, progress=progress)
            report = build_report(case, run.result, extras={"estimator": run.estimate.summary()})
            with (claim.stage(replaces=(*RESULT_FILES, ADAPT_JSON), last=ADAPT_JSON) as staged,
                  _writable_by_vtk(staged) as staging):
                _write_solution(staging, case, run.result, report, progress)
                final = run.result.solution
                plot_adapt(staging / ADAPT_PNG, final.mesh.points, final.mesh.triangles, run.estimate.indicators,
                           run.history(), boundary_edges=final.mesh.boundary_edges, contact_edges=final.contact.edges)
                atomic_write_text(staging / ADAPT_JSON, to_json(run.history()))
        written = [directory / name for name in (*_files_of(case.output.files), ADAPT_PNG, ADAPT_JSON)]
    except ContactFemError as error:
        _fail(error)
        return
    if as_json:
        click.echo(to_json(run.history()), nl=False)
        return
    if quiet:
        return
    click.echo(f"{case.title} — adaptive, method (4), θ = {theta:g}; stopped: {run.stop_reason}")
    click.echo(f"  {'step':>4}{'unknowns':>10}{'eta':>12}{'energy error':>14}{'effectivity':>12}{'seconds':>9}")
    for row in run.steps:
        energy = (row["errors"] or {}).get("displacement_energy")
        cells = (f"{energy:>14.4e}{row['effectivity']:>12.3f}" if energy else f"{'-':>14}{'-':>12}")
        click.echo(f"  {row['step']:>4}{row['unknowns']:>10}{row['eta']:>12.4e}{cells}{row['seconds']:>9.2f}")
    click.echo(f"  wrote {', '.join(_shown(p) for p in written)}")


def _refuse_unknowns_beyond_memory(case, max_unknowns: int) -> None:
    """adapt grows its mesh up to --max-unknowns, meshes the size guard never sees: the budget
    itself must fit the memory this process may use, or nothing starts."""
    from contactfem.estimate import (backend_refusal, estimate_cost, guard_text, guarded_bytes, largest_mesh_points,
                                     memory_limit)
    from contactfem.linalg import resolve_backend

    backend = resolve_backend(case.solver.backend)
    needed = estimate_cost(max_unknowns, backend)["bytes"]
    limit = memory_limit()
    if needed > guarded_bytes(limit):
        raise CaseError(f"--max-unknowns {max_unknowns}: a mesh of that many unknowns needs about "
                        f"{needed / 2**30:.3g} GiB with {backend}, more than {guard_text(limit)}; at most "
                        f"{2 * largest_mesh_points(backend, guarded_bytes(limit))} fit")
    refusal = backend_refusal(max_unknowns, backend)
    if refusal is not None:
        raise CaseError(f"--max-unknowns {max_unknowns}: {refusal}")
