"""``contactfem converge``: the convergence and cost study of a case on nested meshes."""

from __future__ import annotations

from pathlib import Path

import click

from contactfem.cli.common import (
    _check_engine_options,
    _end_progress,
    _engine,
    _load,
    _progress,
    _writable_by_vtk,
    _write_series,
)
from contactfem.cli.exits import _fail, _interruptible, _shown
from contactfem.cli.options import (
    _CheckedPath,
    case_argument,
    engine_options,
    json_option,
    overwrite_option,
    quiet_option,
)
from contactfem.errors import ContactFemError
from contactfem.io.registry import CONVERGENCE_CSV, CONVERGENCE_JSON, CONVERGENCE_PNGS, to_json
from contactfem.methods import METHOD_NAMES


@click.command()
@case_argument
@click.option("--levels", type=click.IntRange(2, 10), default=4, show_default=True,
              help="Number of nested meshes: the case's mesh refined 0 … levels−1 times.")
@click.option("--extra", type=click.IntRange(1, 4), default=1, show_default=True,
              help="Refinements beyond the last level for the reference, when the case has no exact solution.")
@click.option("--method", "methods", type=click.Choice(METHOD_NAMES), multiple=True,
              help="Method(s) to study; default both.")
@click.option("--out", "out_dir", type=_CheckedPath(file_okay=False, output=True), default=None,
              help="Where convergence.json/.csv and the PNGs go. Default: <output.directory>-convergence.")
@engine_options(default="this process, one level after another", tasks="levels")
@quiet_option
@json_option
@overwrite_option
@_interruptible
def converge(case_file: Path, levels: int, extra: int, methods: tuple[str, ...], out_dir: Path | None,
             scheduler: str | None, workers: int | None, quiet: bool, as_json: bool, overwrite: bool) -> None:
    """Convergence and cost study of CASE on nested meshes, both methods.

    For each level: h, unknowns, seconds per stage, Newton iterations, every error norm
    and the observed rate between levels; writes convergence.json, convergence.csv and
    PNGs of error against h (with the h^1 slope of the a priori estimate) and against time.
    With --workers or --scheduler the levels run as tasks on Dask (the reference is solved
    here once and handed to the workers); the figures are the same either way.

    \b
    Examples:
      contactfem converge cases/square.yaml --levels 4
      contactfem converge cases/square.yaml --levels 5 --workers 2
    """
    from contactfem.io import atomic_write_text
    from contactfem.io.atomic import claimed_directory
    from contactfem.plots import plot_convergence
    from contactfem.studies import convergence_study

    try:
        _check_engine_options(scheduler, workers, "levels")
        case = _load(case_file)
        directory = out_dir if out_dir is not None else Path(f"{case.output.directory}-convergence")
        kept: list = []  # (level, method, solution) of every level and method, for convergence-*.pvd
        with claimed_directory(directory, markers=(CONVERGENCE_JSON,), overwrite=overwrite) as claim:
            progress = _progress(quiet)
            say = progress or (lambda message: None)
            with _engine(scheduler, workers, levels, say, "levels", local=False) as engine:
                study = convergence_study(case, levels, extra=extra, methods=methods or METHOD_NAMES,
                                          progress=progress, engine=engine,
                                          on_solution=lambda level, name, field: kept.append((level, name, field)))
            with claim.stage(last=CONVERGENCE_JSON) as staged, _writable_by_vtk(staged) as staging:
                atomic_write_text(staging / CONVERGENCE_JSON, to_json(study))
                atomic_write_text(staging / CONVERGENCE_CSV, _csv(study["rows"]))
                plot_convergence(staging, study)
                for name in dict.fromkeys(name for _, name, _ in kept):
                    _write_series(staging, f"convergence-{name}",
                                  [(f"level{level}", s) for level, n, s in kept if n == name])
    except ContactFemError as error:
        _fail(error)
        return
    _end_progress()
    if as_json:
        click.echo(to_json(study), nl=False)
        return
    if quiet:
        return
    click.echo(f"{case.title} — reference: {study['reference']}")
    short = {"displacement_l2": "u L2", "displacement_h1": "u H1", "displacement_energy": "energy",
             "multiplier_l2": "mult L2", "multiplier_h_minus_half": "mult H-1/2"}
    header = f"  {'method':<9}{'h':>9}{'unknowns':>10}{'Newton':>7}{'seconds':>9}" + "".join(
        f"{short[n]:>21}" for n in short)
    click.echo(header)
    for row in study["rows"]:
        rates = study["rates"][row["method"]]
        index = row["level"] - 1
        cells = []
        for norm in short:
            value = rates[norm][index] if index >= 0 else None
            rate = "" if index < 0 else ("(n/a)" if value is None else f"({value:.2f})")
            cells.append(f"{row[norm]:.3e} {rate:>6}")
        click.echo(f"  {row['method']:<9}{row['h']:>9.4f}{row['unknowns']:>10}{row['iterations']:>7}"
                   f"{row['total_seconds']:>9.2f}" + "".join(f"{c:>21}" for c in cells).rstrip())
    click.echo("  (observed rates between consecutive levels in parentheses; the paper predicts "
               "h^(1/2+ν), ν ≤ 1/2, for the H1 and H-1/2 errors)")
    click.echo(f"  wrote {_shown(directory)}/{CONVERGENCE_JSON}, {CONVERGENCE_CSV}, {', '.join(CONVERGENCE_PNGS)}, "
               f"convergence-<method>.pvd (ParaView: one time step per level)")


def _csv(rows: list[dict]) -> str:
    keys = list(rows[0])
    lines = [",".join(keys)]
    lines += [",".join(str(row[k]) for k in keys) for row in rows]
    return "\n".join(lines) + "\n"
